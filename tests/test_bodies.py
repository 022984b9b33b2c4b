"""The bodies of a mesh (bodies.py): the free bodies' masses and the displacement relative to
each free body's mean translation, on any number of processes."""

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
