"""The crack state and the split geometry of fracture along facets (issue 34; design note
``docs/design/fracture.md`` §3, rows "crack state" and "geometry").

A broken interior facet f between cells c_a and c_b (c_a the one with the smaller global number)
becomes two boundary facets, the crack lips: f itself, now with ``facet_cells[f] = (c_a, -1)``,
and a new facet F + k (appended after the F facets of the intact geometry, k the rank of f among
the broken facets by break step, then index) with ``facet_cells = (c_b, -1)``, which replaces f
in c_b's ``cell_facets``.
Both lips keep f's barycentre and area; a 1D lip takes the boundary facet's length scale
(geometry.py: twice the distance to its cell's barycentre), a 2D or 3D lip keeps f's diameter.
Everything that tests "boundary" (``facet_cells[:, 1] == -1``) then sees the lips: scheme A or
B reconstructs them (eq. (19)-(21)), no jump row of eq. (12) is made for them, and ``QF`` gets
their columns.

Stencils (eq. (7)) are chosen in the vertex star of a facet (reconstruction.py), so the split
also gives each vertex of a broken facet one number per *sector*: the cells around the vertex
that are still connected through unbroken facets containing it. The sector holding the cell of
smallest global number keeps the vertex's number, the others get ``number + s * stride``
(s = 1, 2, ... by the smallest global cell number in the sector). The split geometry is then
the geometry of the mesh whose vertices are duplicated along the crack, which the stencil rules
already handle (they never reach across a slot), and the bodies are re-labelled on it
(``geometry.compute_bodies``). This is exact for cracks that run through: every vertex of every
broken facet separates the facet's two cells. At a crack tip (a vertex around which the two
cells are still connected) stencils could reach across the crack: that needs the visibility
rule of the design note §3, row "stencils" (stage S2), which is not implemented, so such crack
sets are refused. In 1D a facet is a vertex, which a break always separates: every crack set is
admitted.

Serial only: a facet on a process boundary must break on both sides (design note §4, stage S3).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from mpi4py import MPI

from dolfinx_dem.errors import InputError
from dolfinx_dem.geometry import MeshGeometry, compute_bodies


@dataclasses.dataclass(frozen=True)
class CrackState:
    """The broken facets, per cell of the intact geometry: ``broken_step[c, j]`` is the time step
    at which local facet j of cell c broke, -1 while it is intact (design note §3: one array
    keyed by cells, the source of truth for the split, the checkpoint and the outputs). Both
    cells of a broken facet carry the same step."""

    broken_step: np.ndarray  # (n_cells, d+1) int64

    @classmethod
    def intact(cls, geom: MeshGeometry) -> CrackState:
        """No facet broken."""
        return cls(np.full(geom.cell_facets.shape, -1, dtype=np.int64))

    def facets(self, geom: MeshGeometry) -> np.ndarray:
        """The broken facets (indices into the intact geometry ``geom``), sorted."""
        return np.unique(geom.cell_facets[self.broken_step >= 0])

    def lip_order(self, geom: MeshGeometry) -> np.ndarray:
        """The broken facets in the order of their lips (``split_geometry``): by the step at which
        they broke, then by index. A later break appends its lips, so the local rebuild
        (rebuild.py) keeps the facet numbers of the earlier lips."""
        facets = self.facets(geom)
        step = self.broken_step[geom.facet_cells[facets, 0], geom.facet_local[facets, 0]]
        return facets[np.lexsort((facets, step))]

    @property
    def last_step(self) -> int:
        """The latest step at which a facet broke, -1 if none did."""
        return int(self.broken_step.max(initial=-1))

    def broken(self, geom: MeshGeometry, facets: np.ndarray, step: int) -> CrackState:
        """A new state with the interior ``facets`` of the intact geometry ``geom`` broken at ``step``."""
        facets = np.unique(np.asarray(facets, dtype=np.int64))
        if np.any((facets < 0) | (facets >= geom.num_facets)):
            raise InputError(f"facet indices must lie in [0, {geom.num_facets}), got {facets.tolist()}")
        if np.any(geom.facet_cells[facets, 1] < 0):
            bad = facets[geom.facet_cells[facets, 1] < 0][0]
            raise InputError(f"facet {bad} at {geom.facet_centres[bad].tolist()} is not an interior facet: "
                             "only interior facets break")
        cells, local = geom.facet_cells[facets], geom.facet_local[facets]
        if np.any(self.broken_step[cells, local] >= 0):
            raise InputError(f"facets {facets[(self.broken_step[cells, local] >= 0).any(axis=1)].tolist()} "
                             "are broken already")
        step_array = self.broken_step.copy()
        step_array[cells, local] = step
        return CrackState(step_array)


def split_geometry(intact: MeshGeometry, crack: CrackState, comm: MPI.Comm) -> tuple[MeshGeometry, np.ndarray]:
    """The geometry of ``intact`` with the facets broken in ``crack`` split into lips (module
    docstring), and the new lip of each broken facet: (geometry, ``lips`` (k,)). The k-th broken
    facet in ``crack.lip_order(intact)`` (by break step, then index) keeps its index for its cell
    of smaller global number; ``lips[k] = F + k`` is the other cell's lip. Vertex numbers of the split geometry
    may exceed the mesh's vertex count (module docstring). ``intact`` must be a whole mesh
    held by one process.

    Raises InputError under MPI (``comm.size > 1``) and for crack sets with a tip in 2D or 3D.
    """
    if comm.size > 1:
        raise InputError(f"fracture (issue 34) runs on one process only for now, not {comm.size}: a facet on a "
                         "process boundary must break on both sides (stage S3 of the design)")
    if intact.num_owned != intact.num_cells:
        raise InputError("fracture needs the intact geometry of the whole mesh (no halo cells)")
    facets = crack.lip_order(intact)
    F, k = intact.num_facets, len(facets)
    lips = F + np.arange(k, dtype=np.int64)
    cells, local = intact.facet_cells[facets].copy(), intact.facet_local[facets].copy()
    if np.any(cells[:, 1] < 0):
        raise InputError("the crack state breaks a facet that is not interior in the given geometry")
    # c_a = the cell with the smaller global number keeps the facet index
    swap = intact.cell_global[cells[:, 0]] > intact.cell_global[cells[:, 1]]
    cells[swap], local[swap] = cells[swap, ::-1], local[swap, ::-1]

    facet_cells = np.concatenate([intact.facet_cells, np.c_[cells[:, 1], np.full(k, -1)].astype(np.int32)])
    facet_local = np.concatenate([intact.facet_local, np.c_[local[:, 1], np.full(k, -1)].astype(np.int8)])
    facet_cells[facets] = np.c_[cells[:, 0], np.full(k, -1)]
    facet_local[facets] = np.c_[local[:, 0], np.full(k, -1)]
    cell_facets = intact.cell_facets.copy()
    cell_facets[cells[:, 1], local[:, 1]] = lips
    centres = np.concatenate([intact.facet_centres, intact.facet_centres[facets]])
    diameters = np.concatenate([intact.facet_diameters, intact.facet_diameters[facets]])
    if intact.d == 1:
        lip_cells = np.concatenate([cells[:, 0], cells[:, 1]])
        lip_facets = np.concatenate([facets, lips])
        diameters[lip_facets] = 2 * np.abs(centres[lip_facets, 0] - intact.cell_centres[lip_cells, 0])

    vertex_ids = _sector_vertex_ids(intact, facet_cells, facets, cells)
    bodies, num_bodies = compute_bodies(MPI.COMM_SELF, facet_cells, intact.cell_centres, intact.cell_global,
                                        intact.num_owned)
    split = dataclasses.replace(
        intact,
        cell_vertex_ids=vertex_ids,
        cell_bodies=bodies.astype(np.int32),
        num_bodies=num_bodies,
        cell_facets=cell_facets,
        # a distinct key for each lip, independent of the numbering (design note §3)
        facet_global=np.concatenate([intact.facet_global, intact.facet_global[facets] + F]),
        facet_centres=centres,
        facet_areas=np.concatenate([intact.facet_areas, intact.facet_areas[facets]]),
        facet_diameters=diameters,
        facet_cells=facet_cells,
        facet_local=facet_local,
    )
    return split, lips


def _sector_vertex_ids(intact: MeshGeometry, facet_cells: np.ndarray, broken: np.ndarray,
                       broken_cells: np.ndarray) -> np.ndarray:
    """The vertex numbers of the split geometry (module docstring), (n, d+1): one per sector of
    each vertex. Nodes are the (cell, local vertex) pairs; two nodes are joined when their cells
    share a facet containing the vertex. Sectors are the components through the facets that
    are interior after the split, within the components through the intact geometry's interior
    facets (so a vertex already pinched in the intact mesh keeps its numbers). Raises
    InputError if a broken facet's two cells are in one sector of one of its vertices (a tip)."""
    n, nv = intact.cell_vertex_ids.shape
    ids = intact.cell_vertex_ids

    def edges(facets):
        """Node pairs (cell c1's vertex k1, cell c2's vertex k2) for the shared vertices of ``facets``."""
        c = intact.facet_cells[facets]
        f, k1, k2 = np.nonzero(ids[c[:, 0]][:, :, None] == ids[c[:, 1]][:, None, :])
        return c[f, 0] * nv + k1, c[f, 1] * nv + k2

    def components(a, b):
        graph = scipy.sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(n * nv, n * nv))
        return scipy.sparse.csgraph.connected_components(graph, directed=False)[1]

    before = components(*edges(intact.interior_facets))
    after = components(*edges(np.flatnonzero(facet_cells[:, 1] >= 0)))
    a, b = edges(broken)
    tip = after[a] == after[b]
    if np.any(tip):
        node = a[np.argmax(tip)]
        raise InputError(
            f"{intact.d}D crack with a tip at the vertex {intact.cell_vertices[node // nv, node % nv].tolist()}: "
            "the cells on both sides of a broken facet are still connected around it, so stencils could reach "
            "across the crack; the visibility rule that handles tips (issue 34, design stage S2) is not "
            "implemented: only cracks that run through (no tip) can be split")
    # rank each sector (``after``) within its intact component (``before``) by its smallest global cell number
    cell_global = np.repeat(intact.cell_global, nv)
    first = np.full(after.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(first, after, cell_global)
    parent = np.empty(after.max() + 1, dtype=np.int64)
    parent[after] = before
    order = np.lexsort((first, parent))
    start = np.searchsorted(parent[order], parent[order])  # first sector of each intact component
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order)) - start
    stride = int(ids.max()) + 1
    return ids + (rank[after] * stride).reshape(n, nv)
