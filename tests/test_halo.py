"""The halo of a process (halo.py): owned cells plus three vertex-neighbour layers, built by a
rendezvous on vertex owners; nothing of global size on any process."""

import dolfinx.mesh
import numpy as np
import pytest
import scipy.sparse
from mpi4py import MPI

from dolfinx_dem import _compat, halo, meshes
from dolfinx_dem.geometry import compute_geometry


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["square", "cube"])
def test_halo_is_the_vertex_rings_of_the_owned_cells(kind):
    """Every process holds exactly the cells within three vertex rings of its owned cells, with
    the right layer, geometry and facet markers (compared with the serial mesh by barycentre)."""
    comm = MPI.COMM_WORLD
    make = {"square": lambda c: dolfinx.mesh.create_unit_square(c, 12, 9),
            "cube": lambda c: dolfinx.mesh.create_unit_cube(c, 4, 3, 5)}[kind]
    mesh = make(comm)
    V = _compat.create_vector_space(mesh, "DG", 0)
    dofs, start, stop = _compat.dg0_cell_dofs(V)
    exterior = meshes.exterior_facets(mesh)
    marks = {"boundary": halo.owned_facet_marks(mesh, exterior, np.full(len(exterior), 7))}
    cells = halo.build_halo(mesh, dofs, (start, stop), marks)
    assert cells.num_owned == stop - start
    assert np.array_equal(cells.global_index[: cells.num_owned], np.arange(start, stop))

    serial = make(MPI.COMM_SELF)
    ref = compute_geometry(MPI.COMM_SELF, serial, _compat.create_vector_space(serial, "DG", 0))[0]
    key = {tuple(np.round(x, 10)): i for i, x in enumerate(ref.cell_centres)}
    mine = np.array([key[tuple(np.round(x, 10))] for x in cells.vertices.mean(axis=1)])
    N, d = ref.num_cells, ref.d
    vertex_cells = scipy.sparse.csr_matrix(
        (np.ones(N * (d + 1)), (ref.cell_vertex_ids.ravel(), np.repeat(np.arange(N), d + 1))))
    adjacency = (vertex_cells.T @ vertex_cells).tocsr()
    level = np.full(N, -1)
    level[mine[: cells.num_owned]] = 0
    front = mine[: cells.num_owned]
    for layer in range(1, halo.HALO_LAYERS + 1):
        near = np.unique(adjacency[front].indices)
        near = near[level[near] < 0]
        level[near] = layer
        front = near
    assert sorted(mine.tolist()) == sorted(np.flatnonzero(level >= 0).tolist())
    assert np.array_equal(cells.layer, level[mine])
    # Boundary facets are marked on every held cell, halo cells included.
    boundary = np.isin(ref.cell_facets[mine], ref.boundary_facets)
    assert np.array_equal(cells.marks["boundary"] == 7, boundary)
    assert np.all(cells.marks["boundary"][~boundary] == -1)


@pytest.mark.mpi
def test_halo_is_bounded_on_a_strip():
    """A long strip split among the processes: each halo is a few layers at the cuts, not a
    share of the global mesh (no process holds more than its owned cells plus one more share)."""
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [30.0, 1.0]], [240, 8])
    geom = compute_geometry(comm, mesh, _compat.create_vector_space(mesh, "DG", 0))[0]
    halo_cells = geom.num_cells - geom.num_owned
    assert geom.num_cells_global == 2 * 240 * 8
    if comm.size == 1:
        assert halo_cells == 0
    else:
        assert halo_cells <= geom.num_owned
        assert geom.num_cells <= 2 * geom.num_cells_global / comm.size


@pytest.mark.mpi
def test_conflicting_facet_markers_are_an_error_on_every_process():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    exterior = meshes.exterior_facets(mesh)
    facets = np.concatenate([exterior, exterior])
    values = np.concatenate([np.zeros(len(exterior)), np.ones(len(exterior))]).astype(int)
    with pytest.raises(ValueError, match="two Dirichlet conditions share a facet"):
        halo.owned_facet_marks(mesh, facets, values, "Dirichlet conditions")
