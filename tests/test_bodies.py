"""The bodies of a mesh (bodies.py): the free bodies' masses and the displacement relative to
each free body's mean translation, on any number of processes."""

import warnings

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import scenes, simulation


@pytest.mark.mpi
def test_free_bodies_masses_and_relative_displacement():
    """Two free discs: each body's mass is rho times its meshed area; a translation of each
    body (different ones) is removed exactly up to rounding, and for any field the relative
    displacement differs from it by one translation per body."""
    comm = MPI.COMM_WORLD
    scene = scenes.load("two-disks", {"mesh.h": 0.03})
    dem = simulation.build(scene, comm).dem
    rho = scene["material"]["rho"]
    bodies, n, d = dem.bodies, dem.n_owned, dem.d
    owned = dem.geometry.cell_bodies[:n]
    area = np.bincount(owned, weights=dem.geometry.cell_volumes[:n], minlength=2)
    comm.Allreduce(MPI.IN_PLACE, area, op=MPI.SUM)
    assert np.allclose(bodies.mass, rho * area, rtol=1e-14, atol=0)
    shift = np.array([[0.3, -0.2], [-1.5, 0.7]])
    u = dem.create_vector()
    u.array[:] = shift[owned].ravel()
    assert np.abs(bodies.relative_displacement(u).array_r).max() < 1e-15
    x = dem.geometry.cell_centres[:n, :2]
    u.array[:] = (np.sin(3 * x) + shift[owned]).ravel()
    rel = bodies.relative_displacement(u).array_r.reshape(-1, d)
    offset = u.array_r.reshape(-1, d) - rel
    for b in range(2):  # one translation per body: the body's mean of u
        mine = offset[owned == b]
        spread = comm.allreduce(float(np.ptp(mine, axis=0).max()) if len(mine) else 0.0, op=MPI.MAX)
        assert spread < 1e-15
        mass = dem.mass.array_r.reshape(-1, d)[:, 0]
        mean = comm.allreduce((mass[owned == b, None] * u.array_r.reshape(-1, d)[owned == b]).sum(axis=0), op=MPI.SUM)
        mean = mean / bodies.mass[b]
        if len(mine):
            assert np.abs(mine[0] - mean).max() < 1e-14


@pytest.mark.mpi
@pytest.mark.parametrize(
    ("name", "overrides", "thin"),
    [
        ("cantilever", {"method": "dem-B"}, [(0, 3.636, 11.05)]),  # 2A/P = 0.0909 m over facets of 0.025 m
        ("cantilever", {"method": "dem-B", "mesh.n": [160, 16]}, [(0, 14.55, 11.05)]),
        ("cantilever", {"method": "dem-A"}, []),  # scheme A: its corner cells' scheme B facets do not count
        ("two-disks", {}, []),  # discs: 2.8 thicknesses long, not slender
        ("billiard", {"mesh.h": 0.2}, [(0, 5.0, 14.14)]),  # the frame, 1 m wide
    ],
)
def test_slender_bodies_too_thin_for_scheme_b_are_found_and_warned_about(name, overrides, thin):
    """``thin_scheme_b_bodies``: (body, t / h, L / t), with an AccuracyWarning (rank 0) at set-up. Before,
    the cantilever under dem-B was 9.6 times too stiff (tip deflection -90 %) without a word."""
    from dolfinx_dem.errors import AccuracyWarning

    scene = scenes.load(name, overrides)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dem = simulation.build(scene, MPI.COMM_WORLD).dem
    assert [k for k, _, _ in dem.thin_scheme_b_bodies] == [k for k, _, _ in thin]
    for (_, across, slender), (_, a, s) in zip(dem.thin_scheme_b_bodies, thin):
        rel = 1e-3 if scene["mesh"]["type"] == "rectangle" else 3e-2  # another gmsh meshes the frame otherwise
        assert across == pytest.approx(a, rel=rel) and slender == pytest.approx(s, rel=rel)
    accuracy = [w for w in caught if issubclass(w.category, AccuracyWarning)]
    assert len(accuracy) == (bool(thin) and MPI.COMM_WORLD.rank == 0)
    if accuracy:
        assert "body 0 (" in str(accuracy[0].message) and "dem-AB" in str(accuracy[0].message)
