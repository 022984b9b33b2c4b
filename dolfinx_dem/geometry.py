"""Vectorised mesh geometry of the DEM (paper §3.1): barycentres, volumes, facets, normals, h_f.

The DEM stencils reach past a facet's two cells (the d+1 interpolation cells of eq. (7), then the
gradient and jump of both neighbours' P1 reconstructions), beyond the single layer of ghost cells
DOLFINx 0.5 provides. dolfinx_dem therefore gathers the global cell geometry on every process
once, builds the operators' rows for the owned cells from it, and hands them to PETSc. The cost is
O(N) memory and set-up work per process (measured in ``benchmarks/``); a time step only uses the
distributed PETSc operators.

Cells are numbered by the global index of their DG0 dof, facets by DOLFINx's global facet index.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from mpi4py import MPI

from dolfinx_dem import _compat


@dataclasses.dataclass(frozen=True)
class MeshGeometry:
    """Global geometry of a simplex mesh, replicated on every process.

    N cells, F facets, dimension d. Facet j of a cell is opposite its vertex j.
    """

    d: int
    cell_vertices: np.ndarray  # (N, d+1, d) vertex coordinates
    cell_vertex_ids: np.ndarray  # (N, d+1) vertex numbers (the mesh topology's), same order
    cell_bodies: np.ndarray  # (N,) body of each cell (``compute_bodies``)
    cell_facets: np.ndarray  # (N, d+1) global facet index of local facet j
    cell_centres: np.ndarray  # (N, d) barycentres x_c
    cell_volumes: np.ndarray  # (N,) |c|
    facet_area_normals: np.ndarray  # (N, d+1, d) |f| n_{f,c}, outward from c
    facet_centres: np.ndarray  # (F, d) barycentres x_f
    facet_areas: np.ndarray  # (F,) |f| (1 for the points of a 1D mesh)
    facet_diameters: np.ndarray  # (F,) h_f of eq. (13)
    facet_cells: np.ndarray  # (F, 2) adjacent cells, second = -1 on the boundary
    facet_local: np.ndarray  # (F, 2) local index of the facet in each adjacent cell
    owned_ranges: np.ndarray  # (P+1,) cells [owned_ranges[p], owned_ranges[p+1]) on process p

    @property
    def num_cells(self) -> int:
        return self.cell_volumes.shape[0]

    @property
    def num_facets(self) -> int:
        return self.facet_areas.shape[0]

    @property
    def boundary_facets(self) -> np.ndarray:
        """Global indices of the facets with a single adjacent cell."""
        return np.flatnonzero(self.facet_cells[:, 1] < 0)

    @property
    def interior_facets(self) -> np.ndarray:
        return np.flatnonzero(self.facet_cells[:, 1] >= 0)

    def owner_of_cells(self, cells: np.ndarray) -> np.ndarray:
        """Rank owning each cell."""
        return np.searchsorted(self.owned_ranges, cells, side="right") - 1


def compute_geometry(comm: MPI.Comm, mesh, V) -> MeshGeometry:
    """Gather the owned cells of every process and compute the global DEM geometry.

    ``V`` is the DG0 vector space whose dof numbering becomes the cell numbering.
    """
    local = _compat.local_mesh_data(mesh)
    dofs, start, stop = _compat.dg0_cell_dofs(V)
    d = local.cell_vertex_x.shape[2]
    N, F = local.num_cells_global, local.num_facets_global

    ranges = np.array([0] + [r[1] for r in comm.allgather((start, stop))], dtype=np.int64)
    cells = np.concatenate(comm.allgather(dofs))
    vertices = np.empty((N, d + 1, d))
    vertices[cells] = np.concatenate(comm.allgather(local.cell_vertex_x))
    vertex_ids = np.empty((N, d + 1), dtype=np.int64)
    vertex_ids[cells] = np.concatenate(comm.allgather(local.cell_vertex_global))
    cell_facets = np.empty((N, d + 1), dtype=np.int64)
    cell_facets[cells] = np.concatenate(comm.allgather(local.cell_facet_global))
    return geometry_from_arrays(vertices, vertex_ids, cell_facets, F, ranges)


def compute_bodies(facet_cells: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Body of each cell: the connected components of the cells through their shared facets.

    ``facet_cells`` (F, 2) as in ``MeshGeometry`` (-1 on the boundary), ``centres`` (N, d).
    Bodies are numbered 0, 1, ... in the lexicographic order (x, then y, then z) of their first
    barycentre, a geometric order: the numbers do not depend on the cell numbering, hence not on
    the number of processes either.
    """
    N = centres.shape[0]
    pairs = facet_cells[facet_cells[:, 1] >= 0]
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(N, N))
    n_bodies, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    order = np.lexsort(centres.T[::-1])  # x first, then y, then z
    _, first = np.unique(labels[order], return_index=True)  # first cell of each body in that order
    rank = np.empty(n_bodies, dtype=np.int64)
    rank[np.argsort(first)] = np.arange(n_bodies)
    return rank[labels]


def geometry_from_arrays(
    vertices: np.ndarray,
    vertex_ids: np.ndarray,
    cell_facets: np.ndarray,
    num_facets: int,
    owned_ranges: np.ndarray,
) -> MeshGeometry:
    """The geometry of eq. (6)-(13) from cell vertex coordinates (N, d+1, d), the cells' vertex
    numbers (N, d+1) and their facet numbers (N, d+1), facet j opposite vertex j."""
    N, nv, d = vertices.shape
    x0 = vertices[:, 0, :]
    Jt = vertices[:, 1:, :] - x0[:, None, :]  # (N, d, d), rows are edge vectors
    det = np.linalg.det(Jt)
    volumes = np.abs(det) / math.factorial(d)
    if np.any(volumes <= 0):
        bad = np.flatnonzero(volumes <= 0)[:5]
        raise ValueError(f"degenerate cells (zero volume) in the mesh, e.g. cells {bad.tolist()}")
    # Barycentric gradients: grad(lambda_j) for j >= 1 are the columns of Jt^{-1}; their sum is
    # -grad(lambda_0). The outward area normal of the facet opposite vertex j is -d |c| grad(lambda_j).
    grad_lambda = np.empty((N, nv, d))
    grad_lambda[:, 1:, :] = np.swapaxes(np.linalg.inv(Jt), 1, 2)
    grad_lambda[:, 0, :] = -grad_lambda[:, 1:, :].sum(axis=1)
    area_normals = -d * volumes[:, None, None] * grad_lambda

    # Facet -> cells (one or two) and the facet's local index in each.
    flat = cell_facets.reshape(-1)
    order = np.argsort(flat, kind="stable")
    counts = np.bincount(flat, minlength=num_facets)
    if np.any(counts == 0) or np.any(counts > 2):
        raise ValueError("inconsistent mesh: every facet must belong to one or two cells")
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    facet_cells = np.full((num_facets, 2), -1, dtype=np.int64)
    facet_local = np.full((num_facets, 2), -1, dtype=np.int64)
    facet_cells[:, 0], facet_local[:, 0] = np.divmod(order[first], nv)
    two = counts == 2
    facet_cells[two, 1], facet_local[two, 1] = np.divmod(order[first[two] + 1], nv)

    c0, j0 = facet_cells[:, 0], facet_local[:, 0]
    mask = np.ones((num_facets, nv), dtype=bool)
    mask[np.arange(num_facets), j0] = False
    facet_vertices = vertices[c0][mask].reshape(num_facets, d, d)
    facet_centres = facet_vertices.mean(axis=1)
    facet_areas = np.linalg.norm(area_normals[c0, j0], axis=1)

    centres = vertices.mean(axis=1)
    if d == 1:
        # A point has no diameter: use the distance between the two barycentres (cell length on
        # the boundary), the 1D analogue of the length scale in eq. (13).
        other = np.where(two, facet_cells[:, 1], c0)
        diam = np.where(
            two,
            np.abs(centres[c0, 0] - centres[other, 0]),
            2 * np.abs(facet_centres[:, 0] - centres[c0, 0]),
        )
    else:
        pairs = [(a, b) for a in range(d) for b in range(a + 1, d)]
        diam = np.max(
            [np.linalg.norm(facet_vertices[:, a] - facet_vertices[:, b], axis=1) for a, b in pairs],
            axis=0,
        )
    return MeshGeometry(
        d=d,
        cell_vertices=vertices,
        cell_vertex_ids=np.asarray(vertex_ids, dtype=np.int64),
        cell_bodies=compute_bodies(facet_cells, centres),
        cell_facets=cell_facets,
        cell_centres=centres,
        cell_volumes=volumes,
        facet_area_normals=area_normals,
        facet_centres=facet_centres,
        facet_areas=facet_areas,
        facet_diameters=diam,
        facet_cells=facet_cells,
        facet_local=facet_local,
        owned_ranges=np.asarray(owned_ranges, dtype=np.int64),
    )
