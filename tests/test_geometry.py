"""DEM mesh geometry (paper §3.1-3.2): volumes, facet areas and normals, h_f, numbering."""

import math

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
from dolfinx.mesh import DiagonalType

from dolfinx_dem import _compat
from dolfinx_dem.geometry import compute_geometry, geometry_from_arrays


def _geometry(mesh):
    V = _compat.create_vector_space(mesh, "DG", 0)
    return compute_geometry(mesh.comm, mesh, V), V


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
    mesh, volume, perimeter = _meshes(MPI.COMM_WORLD)[case]
    geom, _ = _geometry(mesh)
    d = geom.d
    N = mesh.topology.index_map(d).size_global
    assert geom.num_cells == N
    assert geom.owned_ranges[0] == 0 and geom.owned_ranges[-1] == N
    assert geom.num_facets == mesh.topology.index_map(d - 1).size_global

    assert np.all(geom.cell_volumes > 0)
    assert geom.cell_volumes.sum() == pytest.approx(volume, rel=1e-13)
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
    # Boundary facets: the ones DOLFINx calls exterior; their areas sum to the perimeter.
    exterior = np.unique(np.concatenate(MPI.COMM_WORLD.allgather(
        _compat.local_facet_global_indices(mesh, _compat.exterior_facets(mesh)))))
    assert np.array_equal(boundary, exterior)
    assert geom.facet_areas[boundary].sum() == pytest.approx(perimeter, rel=1e-13)
    # Euler-type count: (d+1) N = 2 F_interior + F_boundary.
    assert (d + 1) * N == 2 * len(interior) + len(boundary)


def test_facet_diameters_unit_square_right():
    """h_f of eq. (13): 0.25 on the 40 axis-aligned edges, 0.25 sqrt(2) on the 16 diagonals."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4, diagonal=DiagonalType.right)
    geom, _ = _geometry(mesh)
    h = np.sort(geom.facet_diameters)
    assert h.shape == (56,)
    assert np.allclose(h[:40], 0.25, rtol=1e-14)
    assert np.allclose(h[40:], 0.25 * math.sqrt(2), rtol=1e-14)
    assert np.allclose(geom.facet_areas, geom.facet_diameters, rtol=1e-14)  # segments
    assert np.allclose(geom.cell_volumes, 1 / 32, rtol=1e-13)
    # Facet barycentres are edge midpoints: on the grid lines of spacing 1/8.
    assert np.allclose(np.round(geom.facet_centres * 8), geom.facet_centres * 8, atol=1e-12)


def test_facet_diameters_1d_and_3d():
    # 1D: distance between the neighbouring barycentres, twice the half-cell at the boundary.
    x = np.array([0.0, 0.1, 0.4, 0.5, 1.0])
    vertices = np.stack([x[:-1], x[1:]], axis=1)[:, :, None]
    cell_facets = np.stack([np.arange(1, 5), np.arange(0, 4)], axis=1)  # facet j opposite vertex j
    vertex_ids = np.stack([np.arange(4), np.arange(1, 5)], axis=1)
    geom = geometry_from_arrays(vertices, vertex_ids, cell_facets, 5, np.array([0, 4]))
    centres = (x[:-1] + x[1:]) / 2
    assert np.allclose(geom.cell_volumes, np.diff(x))
    assert np.allclose(geom.facet_centres[:, 0], x)
    expected = np.concatenate([[2 * (centres[0] - x[0])], np.diff(centres), [2 * (x[-1] - centres[-1])]])
    assert np.allclose(geom.facet_diameters, expected, rtol=1e-14)
    # 3D: the longest edge of each triangular face; a unit cube's faces have edges 1, 1, sqrt 2
    # or 1, sqrt 2, sqrt 3 (interior), h = sqrt 2 or sqrt 3.
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
    start, stop = geom.owned_ranges[mesh.comm.rank], geom.owned_ranges[mesh.comm.rank + 1]
    assert (start, stop) == tuple(V.dofmap.index_map.local_range)
    f = dolfinx.fem.Function(V)
    f.interpolate(lambda x: x[: geom.d])
    owned = f.vector.array_r[: (stop - start) * geom.d].reshape(-1, geom.d)
    assert np.allclose(owned, geom.cell_centres[start:stop], rtol=0, atol=1e-14)


def _sorted_rows(a):
    a = np.round(a, 10)
    return a[np.lexsort(a.T[::-1])]


@pytest.mark.mpi
@pytest.mark.parametrize("case", range(4))
def test_parallel_geometry_equals_serial(case):
    """The gathered geometry of a distributed mesh is the serial geometry, up to numbering."""
    par, volume, perimeter = _meshes(MPI.COMM_WORLD)[case]
    ser = _meshes(MPI.COMM_SELF)[case][0]
    gp, _ = _geometry(par)
    gs, _ = _geometry(ser)
    assert gp.num_cells == gs.num_cells and gp.num_facets == gs.num_facets
    assert gp.cell_volumes.sum() == pytest.approx(gs.cell_volumes.sum(), rel=1e-14)
    d = gp.d
    rows = lambda g: np.column_stack([g.cell_centres, g.cell_volumes])  # noqa: E731
    assert np.allclose(_sorted_rows(rows(gp)), _sorted_rows(rows(gs)), atol=1e-12)
    frows = lambda g: np.column_stack(  # noqa: E731
        [g.facet_centres, g.facet_areas, g.facet_diameters, g.facet_cells[:, 1] < 0])
    assert np.allclose(_sorted_rows(frows(gp)), _sorted_rows(frows(gs)), atol=1e-12)
    # Per-cell facet normals, keyed by cell barycentre then outward normal.
    keyed = lambda g: np.concatenate([  # noqa: E731
        np.repeat(g.cell_centres, d + 1, axis=0), g.facet_area_normals.reshape(-1, d)], axis=1)
    assert np.allclose(_sorted_rows(keyed(gp)), _sorted_rows(keyed(gs)), atol=1e-12)
    # The owned ranges partition the cells.
    assert np.all(np.diff(gp.owned_ranges) >= 0)
    assert len(gp.owned_ranges) == MPI.COMM_WORLD.size + 1
    assert np.array_equal(gp.owner_of_cells(np.arange(gp.num_cells)),
                          np.repeat(np.arange(MPI.COMM_WORLD.size), np.diff(gp.owned_ranges)))
