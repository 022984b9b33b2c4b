"""Vectorised mesh geometry of the DEM (paper §3.1): barycentres, volumes, facets, normals, h_f.

Each process holds the geometry of the cells it owns and of a halo of ``halo.HALO_LAYERS``
vertex-neighbour layers around them (``halo.build_halo``): the d+1 interpolation cells of a facet
lie in the vertex neighbourhood of the facet, widened once (reconstruction.py), and a jump row of
eq. (12) uses the gradients of both cells of its facet. So a process computes

- the stencils and reconstructions of the facets of its cells in layers 0 and 1 (their
  neighbourhoods reach layer 3),
- the gradients of its cells in layers 0 and 1, hence the elastic rows of its owned cells and the
  jump rows of every facet of its owned cells,

from local data only. Memory and work per process follow its owned cells plus the halo, never the
global mesh.

Cells are numbered locally: the owned cells first, in the order of their global number (the
global index of their DG0 dof, so that PETSc vectors share the layout of ``Function.vector``),
then the halo by layer. Facets are numbered locally too; ``facet_global`` holds DOLFINx's global
facet index. A facet with one cell is a boundary facet (``facet_cells[f, 1] == -1``) unless its
cell is in the outermost halo layer (``halo.HALO_LAYERS``), whose outer neighbours are not held
(``-2``, unknown).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, halo
from dolfinx_dem.errors import InputError

#: facet_cells[f, 1] of a facet whose second cell is outside the halo (not a boundary facet).
OUTSIDE = -2


@dataclasses.dataclass(frozen=True)
class MeshGeometry:
    """Geometry of the cells a process holds (module docstring): n cells, F facets, dimension d.

    Facet j of a cell is opposite its vertex j. Cells [0, num_owned) are owned.
    """

    d: int
    num_owned: int
    cell_global: np.ndarray  # (n,) global cell number (global DG0 dof index)
    cell_owner: np.ndarray  # (n,) int32: rank owning the cell
    cell_layer: np.ndarray  # (n,) int8: 0 owned, k in the k-th halo layer
    cell_vertices: np.ndarray  # (n, d+1, d) vertex coordinates
    cell_vertex_ids: np.ndarray  # (n, d+1) global vertex numbers (the mesh topology's), same order
    cell_bodies: np.ndarray  # (n,) int32: body of each cell (``compute_bodies``)
    cell_facets: np.ndarray  # (n, d+1) int32: local facet index of facet j
    cell_centres: np.ndarray  # (n, d) barycentres x_c
    cell_volumes: np.ndarray  # (n,) |c|
    facet_area_normals: np.ndarray  # (n, d+1, d) |f| n_{f,c}, outward from c
    facet_global: np.ndarray  # (F,) DOLFINx's global facet index
    facet_centres: np.ndarray  # (F, d) barycentres x_f
    facet_areas: np.ndarray  # (F,) |f| (1 for the points of a 1D mesh)
    facet_diameters: np.ndarray  # (F,) h_f of eq. (13)
    facet_cells: np.ndarray  # (F, 2) int32: adjacent cells; second -1 on the boundary, OUTSIDE if not held
    facet_local: np.ndarray  # (F, 2) int8: local index of the facet in each adjacent cell
    num_cells_global: int
    num_bodies: int

    @property
    def num_cells(self) -> int:
        """Cells held by this process (owned and halo)."""
        return self.cell_volumes.shape[0]

    @property
    def num_facets(self) -> int:
        return self.facet_areas.shape[0]

    @property
    def owned_range(self) -> tuple[int, int]:
        """Global numbers [start, stop) of the owned cells."""
        start = int(self.cell_global[0]) if self.num_owned else 0
        return start, start + self.num_owned

    @property
    def boundary_facets(self) -> np.ndarray:
        """Local indices of the facets with a single adjacent cell (the domain's boundary)."""
        return np.flatnonzero(self.facet_cells[:, 1] == -1)

    @property
    def interior_facets(self) -> np.ndarray:
        """Local indices of the facets with both adjacent cells held."""
        return np.flatnonzero(self.facet_cells[:, 1] >= 0)

    def facets_of_layers(self, layers: int) -> np.ndarray:
        """Local indices of the facets of the cells in halo layers 0 .. ``layers``."""
        return np.unique(self.cell_facets[self.cell_layer <= layers])


def compute_geometry(comm: MPI.Comm, mesh, V, marks=None, layers: int = halo.HALO_LAYERS) -> tuple[MeshGeometry, dict]:
    """The geometry of this process's cells and a halo of ``layers`` layers, and the halo cells'
    facet markers.

    ``V`` is the DG0 vector space whose dof numbering becomes the global cell numbering;
    ``marks`` maps names to (n_owned, d+1) facet markers of the owned cells
    (``halo.owned_facet_marks``), returned for all held cells as (n, d+1) arrays.
    """
    dofs, start, stop = _compat.dg0_cell_dofs(V)
    cells = halo.build_halo(mesh, dofs, (start, stop), marks or {}, layers)
    geom = geometry_from_arrays(
        cells.vertices, cells.vertex_ids, cells.facet_ids, cell_global=cells.global_index,
        cell_owner=cells.owner, cell_layer=cells.layer, num_owned=cells.num_owned,
        num_cells_global=cells.num_cells_global, comm=comm, halo_layers=layers)
    return geom, dict(cells.marks)


def _components(num_cells: int, facet_cells: np.ndarray) -> np.ndarray:
    """Connected components of the held cells through their shared (held) facets."""
    pairs = facet_cells[facet_cells[:, 1] >= 0]
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(num_cells,) * 2)
    return scipy.sparse.csgraph.connected_components(graph, directed=False)[1]


def compute_bodies(comm: MPI.Comm, facet_cells: np.ndarray, centres: np.ndarray, cell_global: np.ndarray,
                   num_owned: int) -> tuple[np.ndarray, int]:
    """Body of each held cell (the components of the global mesh through shared facets), and the
    number of bodies.

    Label propagation: each held cell starts with its global number; each round, every local
    component takes the smallest label of its cells, and the halo cells take their owners'
    labels (a PETSc ghost update), until no label changes on any process. Bodies are then
    numbered 0, 1, ... in the lexicographic order (x, then y, then z) of their first barycentre,
    a geometric order: the numbers do not depend on the cell numbering or the process count. The
    one collective that grows is a gather of one barycentre per body present on a process.
    """
    n = len(cell_global)
    component = _components(n, facet_cells)
    label = cell_global.astype(np.float64)
    ghosts = np.asarray(cell_global[num_owned:], dtype=PETSc.IntType)
    vec = PETSc.Vec().createGhost(ghosts, size=(num_owned, PETSc.DECIDE), comm=comm)
    while True:
        smallest = np.full(component.max() + 1 if n else 0, np.inf)
        np.minimum.at(smallest, component, label)
        new = smallest[component]
        with vec.localForm() as local:
            local.array[:num_owned] = new[:num_owned]
        vec.ghostUpdate(PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        with vec.localForm() as local:
            new[num_owned:] = local.array[num_owned:]
        changed = comm.allreduce(bool(np.any(new != label)), op=MPI.LOR)
        label = new
        if not changed:
            break
    vec.destroy()
    label = label.astype(np.int64)
    # The lexicographically first owned barycentre of each body present here, gathered.
    order = np.lexsort(centres[:num_owned].T[::-1])
    present, first = np.unique(label[:num_owned][order], return_index=True)
    keys = np.concatenate(comm.allgather(np.c_[present, centres[:num_owned][order][first]]))
    keys = keys[np.lexsort(keys[:, 1:].T[::-1])]  # by position
    labels, first = np.unique(keys[:, 0], return_index=True)
    number = np.empty(len(labels), dtype=np.int64)
    number[np.argsort(first)] = np.arange(len(labels))  # rank of each body's first barycentre
    return number[np.searchsorted(labels, label)], len(labels)


def geometry_from_arrays(
    vertices: np.ndarray,
    vertex_ids: np.ndarray,
    facet_ids: np.ndarray,
    cell_global: np.ndarray | None = None,
    cell_owner: np.ndarray | None = None,
    cell_layer: np.ndarray | None = None,
    num_owned: int | None = None,
    num_cells_global: int | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
    halo_layers: int = halo.HALO_LAYERS,
) -> MeshGeometry:
    """The geometry of eq. (6)-(13) from the held cells' vertex coordinates (N, d+1, d), global
    vertex numbers (N, d+1) and global facet numbers (N, d+1), facet j opposite vertex j. Without
    the ownership arguments the cells are a whole mesh owned by one process. ``halo_layers``: the
    depth the halo was built to; only cells of that layer may have neighbours that are not held
    (a halo that stopped growing earlier holds every neighbour of its cells)."""
    N, nv, d = vertices.shape
    if cell_global is None:
        cell_global, cell_owner = np.arange(N), np.zeros(N, dtype=np.int64)
        cell_layer, num_owned, num_cells_global = np.zeros(N, dtype=np.int64), N, N
    facet_global, cell_facets = np.unique(facet_ids, return_inverse=True)
    cell_facets = cell_facets.reshape(N, nv).astype(np.int32)  # local numbers (int32: memory)
    num_facets = len(facet_global)
    x0 = vertices[:, 0, :]
    Jt = vertices[:, 1:, :] - x0[:, None, :]  # (N, d, d), rows are edge vectors
    det = np.linalg.det(Jt)
    volumes = np.abs(det) / math.factorial(d)
    if np.any(volumes <= 0):
        bad = np.flatnonzero(volumes <= 0)[:5]
        raise InputError(f"degenerate cells (zero volume) in the mesh, e.g. cells {bad.tolist()}")
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
    if np.any(counts > 2):
        raise InputError("inconsistent mesh: every facet must belong to one or two cells")
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    facet_cells = np.full((num_facets, 2), -1, dtype=np.int32)  # local numbers (int32: memory)
    facet_local = np.full((num_facets, 2), -1, dtype=np.int8)  # 0 .. d
    facet_cells[:, 0], facet_local[:, 0] = np.divmod(order[first], nv)
    two = counts == 2
    facet_cells[two, 1], facet_local[two, 1] = np.divmod(order[first[two] + 1], nv)
    facet_cells[~two & (cell_layer[facet_cells[:, 0]] == halo_layers), 1] = OUTSIDE

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
    bodies, num_bodies = compute_bodies(comm, facet_cells, centres, np.asarray(cell_global), num_owned)
    return MeshGeometry(
        d=d,
        num_owned=int(num_owned),
        cell_global=np.asarray(cell_global, dtype=np.int64),
        cell_owner=np.asarray(cell_owner, dtype=np.int32),
        cell_layer=np.asarray(cell_layer, dtype=np.int8),
        cell_vertices=vertices,
        cell_vertex_ids=np.asarray(vertex_ids, dtype=np.int64),
        cell_bodies=bodies.astype(np.int32),
        num_bodies=num_bodies,
        cell_facets=cell_facets,
        cell_centres=centres,
        cell_volumes=volumes,
        facet_area_normals=area_normals,
        facet_global=facet_global,
        facet_centres=facet_centres,
        facet_areas=facet_areas,
        facet_diameters=diam,
        facet_cells=facet_cells,
        facet_local=facet_local,
        num_cells_global=int(num_cells_global),
    )
