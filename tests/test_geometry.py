"""DEM mesh geometry (paper §3.1-3.2): volumes, facet areas and normals, h_f, numbering."""

import math

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
from dolfinx.mesh import DiagonalType
from mpi4py import MPI

from dolfinx_dem import _compat, meshes
from dolfinx_dem.geometry import compute_geometry


def _geometry(mesh):
    V = _compat.create_vector_space(mesh, "DG", 0)
    return compute_geometry(mesh.comm, mesh, V)[0], V


def _meshes(comm):
    """(mesh, |domain|, |boundary|) in 1D, 2D and 3D."""
    return [
        (dolfinx.mesh.create_interval(comm, 7, [-0.5, 1.5]), 2.0, 2.0),  # |boundary| = 2 points
        (dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [5, 3]), 2.0, 6.0),
        (dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [4, 3],
                                       diagonal=DiagonalType.crossed), 2.0, 6.0),
        (dolfinx.mesh.create_box(comm, [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]], [2, 3, 4]), 6.0, 22.0),
    ]


@pytest.mark.mpi
@pytest.mark.parametrize("case", range(4))
def test_volumes_areas_normals(case):
    comm = MPI.COMM_WORLD
    mesh, volume, perimeter = _meshes(comm)[case]
    geom, _ = _geometry(mesh)
    d = geom.d
    N = mesh.topology.index_map(d).size_global
    assert comm.allreduce(geom.num_owned, op=MPI.SUM) == N == geom.num_cells_global
    owned = slice(0, geom.num_owned)

    assert np.all(geom.cell_volumes > 0)
    assert comm.allreduce(geom.cell_volumes[owned].sum(), op=MPI.SUM) == pytest.approx(volume, rel=1e-13)
    # Closed cells: sum_f |f| n_{f,c} = 0.
    scale = geom.facet_areas.max()
    assert np.abs(geom.facet_area_normals.sum(axis=1)).max() < 1e-13 * scale
    # |f| n_{f,c} has length |f|, and is the same facet area seen from both cells.
    lengths = np.linalg.norm(geom.facet_area_normals, axis=2)
    assert np.allclose(lengths, geom.facet_areas[geom.cell_facets], rtol=1e-13, atol=0)
    # Outward: n_{f,c} . (x_f - x_c) > 0 for every cell and local facet.
    xf = geom.facet_centres[geom.cell_facets]  # (N, d+1, d)
    outward = np.einsum("nkd,nkd->nk", geom.facet_area_normals, xf - geom.cell_centres[:, None, :])
    assert np.all(outward > 0)
    # Discrete Stokes formula: sum_f |f| n_{f,c} (x) x_f = |c| I (exactness of eq. (8) on affine u).
    stokes = np.einsum("nki,nkj->nij", geom.facet_area_normals, xf)
    assert np.allclose(stokes, geom.cell_volumes[:, None, None] * np.eye(d), rtol=0, atol=1e-13)

    interior, boundary = geom.interior_facets, geom.boundary_facets
    c = geom.facet_cells[interior]
    k = geom.facet_local[interior]
    a1 = geom.facet_area_normals[c[:, 0], k[:, 0]]
    a2 = geom.facet_area_normals[c[:, 1], k[:, 1]]
    assert np.abs(a1 + a2).max() < 1e-14 * scale
    assert np.all(geom.cell_facets[c[:, 0], k[:, 0]] == interior)
    assert np.all(geom.cell_facets[c[:, 1], k[:, 1]] == interior)
    # Every facet of a cell below the outermost halo layer is known to be interior or boundary.
    inner = geom.facets_of_layers(geom.cell_layer.max() - 1) if comm.size > 1 else np.arange(geom.num_facets)
    assert np.all(geom.facet_cells[inner, 1] >= -1)
    # Boundary facets of the owned cells: the ones DOLFINx calls exterior; their areas sum to the
    # perimeter.
    mine = np.intersect1d(boundary, geom.facets_of_layers(0))
    found = np.unique(np.concatenate(comm.allgather(geom.facet_global[mine])))
    exterior = np.unique(np.concatenate(comm.allgather(
        _compat.local_facet_global_indices(mesh, meshes.exterior_facets(mesh)))))
    assert np.array_equal(found, exterior)
    areas = dict(zip(geom.facet_global[mine].tolist(), geom.facet_areas[mine].tolist()))
    areas = {k: v for a in comm.allgather(areas) for k, v in a.items()}
    assert sum(areas.values()) == pytest.approx(perimeter, rel=1e-13)

    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
    geom, _ = _geometry(mesh)
    h = geom.facet_diameters
    assert np.all(np.isclose(h, math.sqrt(2)) | np.isclose(h, math.sqrt(3)))
    assert np.allclose(h[geom.boundary_facets], math.sqrt(2))
    assert geom.facet_areas[geom.boundary_facets].sum() == pytest.approx(6.0, rel=1e-14)


@pytest.mark.mpi
@pytest.mark.parametrize("case", range(4))
def test_cell_numbering_is_dg0_numbering(case):
    """Cell c of the geometry is the cell of DG0 block dof c: interpolating x gives x_c."""
    mesh = _meshes(MPI.COMM_WORLD)[case][0]
    geom, V = _geometry(mesh)
    start, stop = geom.owned_range
    assert (start, stop) == tuple(V.dofmap.index_map.local_range)
    assert np.array_equal(geom.cell_global[: geom.num_owned], np.arange(start, stop))
    f = dolfinx.fem.Function(V)
    f.interpolate(lambda x: x[: geom.d])
    owned = _compat.petsc_vec(f).array_r[: (stop - start) * geom.d].reshape(-1, geom.d)
    assert np.allclose(owned, geom.cell_centres[: geom.num_owned], rtol=0, atol=1e-14)


def _sorted_rows(a):
    a = np.round(a, 10)
    return a[np.lexsort(a.T[::-1])]


@pytest.mark.mpi
@pytest.mark.parametrize("case", range(4))
def test_parallel_geometry_equals_serial(case):
    """The geometry a process holds (owned cells and halo) is the serial geometry of the same
    cells, up to numbering; and every facet below the outermost halo layer has the serial cells."""
    comm = MPI.COMM_WORLD
    par = _meshes(comm)[case][0]
    ser = _meshes(MPI.COMM_SELF)[case][0]
    gp, _ = _geometry(par)
    gs, _ = _geometry(ser)
    d = gp.d
    key = lambda g, rows: {tuple(np.round(r, 10)) for r in rows}  # noqa: E731
    rows = lambda g: np.column_stack([g.cell_centres, g.cell_volumes])  # noqa: E731
    assert key(gp, rows(gp)) <= key(gs, rows(gs))
    inner = gp.facets_of_layers(max(gp.cell_layer.max() - 1, 0))
    frows = lambda g, f: np.column_stack(  # noqa: E731
        [g.facet_centres[f], g.facet_areas[f], g.facet_diameters[f], g.facet_cells[f, 1] < 0])
    assert key(gp, frows(gp, inner)) <= key(gs, frows(gs, np.arange(gs.num_facets)))
    # Per-cell facet normals, keyed by cell barycentre then outward normal.
    keyed = lambda g: np.concatenate([  # noqa: E731
        np.repeat(g.cell_centres, d + 1, axis=0), g.facet_area_normals.reshape(-1, d)], axis=1)
    assert key(gp, keyed(gp)) <= key(gs, keyed(gs))
    # The owned cells partition the mesh.
    owned = comm.allgather(gp.cell_global[: gp.num_owned])
    assert np.array_equal(np.sort(np.concatenate(owned)), np.arange(gs.num_cells))
    assert np.all(gp.cell_owner[: gp.num_owned] == comm.rank)
