"""The cells a process holds: its owned cells and a halo of ``layers`` vertex-neighbour layers.

The DEM rows of a process reach past its owned cells: the d+1 interpolation cells of a facet come
from the vertex neighbourhood of the facet, widened once (reconstruction.py), and the jump rows of
eq. (12) use the gradients of both cells of a facet. With ``HALO_LAYERS`` = 3 layers of cells
sharing a vertex with the previous layer, a process holds every cell that the rows of its owned
cells and facets need (see ``geometry.py``).

DOLFINx 0.5 ghosts at most the cells that share a facet with an owned cell, so the halo is built
here, by a rendezvous on the vertex owners of DOLFINx's vertex index map:

1. every process sends, for each vertex of each owned cell, the pair (vertex, cell) to the owner
   of the vertex, which so learns the cells around each vertex it owns (its *stars*);
2. each layer: a process asks the owners of the vertices of its newest cells for their stars,
   then asks the owners of the cells it does not hold yet for their records.

Every message goes to a process that shares vertices with the sender's cells; no process ever
holds an array of the global size. A cell record carries everything the DEM needs: the global
cell number (the global index of its DG0 dof), its owner, the vertex coordinates, the global
vertex and facet numbers (facet j opposite vertex j), the owner of each vertex, and one integer
per facet and per named facet marker (Dirichlet condition, contact candidates; -1 when unmarked).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError

#: Vertex-neighbour layers around the owned cells (reconstruction.py, geometry.py: why 3).
HALO_LAYERS = 3


@dataclasses.dataclass(frozen=True)
class LocalCells:
    """The cells a process holds, owned first (in global order), then the halo by layer.

    ``n`` cells, dimension ``d``. ``marks[name]`` is (n, d+1): the marker value of facet j of each
    cell, -1 where the facet is unmarked.
    """

    num_owned: int
    global_index: np.ndarray  # (n,) global cell number = global index of the cell's DG0 dof
    owner: np.ndarray  # (n,) owning rank
    layer: np.ndarray  # (n,) 0 for owned cells, k for the k-th vertex-neighbour layer
    vertices: np.ndarray  # (n, d+1, d) vertex coordinates
    vertex_ids: np.ndarray  # (n, d+1) global vertex numbers
    facet_ids: np.ndarray  # (n, d+1) global facet numbers, facet j opposite vertex j
    marks: Mapping[str, np.ndarray]
    owned_range: tuple[int, int]  # global numbers of the owned cells: [start, stop)
    num_cells_global: int


def alltoall(comm: MPI.Comm, destination: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Send row i of ``rows`` (n, ...) to rank ``destination[i]``; returns (received rows, their
    source ranks), in rank order. Only the counts go to every process (one integer each)."""
    size = comm.size
    order = np.argsort(destination, kind="stable")
    rows = np.ascontiguousarray(rows[order])
    send_counts = np.bincount(destination, minlength=size).astype(np.int64)
    recv_counts = np.empty(size, dtype=np.int64)
    comm.Alltoall(send_counts, recv_counts)
    width = int(np.prod(rows.shape[1:], dtype=np.int64))
    received = np.empty((int(recv_counts.sum()),) + rows.shape[1:], dtype=rows.dtype)
    if width:
        mpi_type = {np.dtype(np.int64): MPI.INT64_T, np.dtype(np.float64): MPI.DOUBLE}[rows.dtype]
        send = [rows.reshape(-1), (send_counts * width, _displacements(send_counts * width)), mpi_type]
        recv = [received.reshape(-1), (recv_counts * width, _displacements(recv_counts * width)), mpi_type]
        comm.Alltoallv(send, recv)
    return received, np.repeat(np.arange(size), recv_counts)


def _displacements(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


def owned_facet_marks(mesh, facets: np.ndarray, values: np.ndarray, what: str = "markers") -> np.ndarray:
    """(n_owned, d+1) marks of the facets of the owned cells: ``values[i]`` on the process-local
    facet ``facets[i]``, -1 elsewhere. A facet marked on a process that does not own its cell (a
    ghost cell there) is sent to the owner of the cell; two different values on one facet raise a
    ValueError on every process, "two {what} share a facet"."""
    comm = mesh.comm
    local = _compat.local_mesh_data(mesh)
    facets = np.asarray(facets, dtype=np.int32)
    values = np.asarray(values, dtype=np.int64)
    which, owners = _compat.facet_cell_owners(mesh, facets)  # one entry per (facet, local cell)
    rows = np.stack([_compat.local_facet_global_indices(mesh, facets)[which], values[which]], axis=1)
    mine = owners == comm.rank
    received, _ = alltoall(comm, owners[~mine], rows[~mine])
    rows = np.unique(np.concatenate([rows[mine], received]), axis=0)
    twice = rows[1:, 0][rows[1:, 0] == rows[:-1, 0]]
    twice = [f for part in comm.allgather(twice[:1].tolist()) for f in part]
    if twice:
        raise InputError(f"two {what} share a facet (global facet {twice[0]})")
    out = np.full(local.cell_facet_global.shape, -1, dtype=np.int64)
    position = np.minimum(np.searchsorted(rows[:, 0], local.cell_facet_global), max(len(rows) - 1, 0))
    hit = (rows[position, 0] == local.cell_facet_global) if len(rows) else np.zeros(out.shape, bool)
    out[hit] = rows[position[hit], 1]
    return out


def build_halo(mesh, dofs: np.ndarray, owned_range: tuple[int, int],
               marks: Mapping[str, np.ndarray], layers: int = HALO_LAYERS) -> LocalCells:
    """The owned cells of ``mesh`` and ``layers`` layers of cells around them (module docstring).

    ``dofs`` (n_owned,) is the global DG0 dof of each owned cell (DOLFINx's process-local cell
    order), ``owned_range`` the global dof range of this process, ``marks`` the (n_owned, d+1)
    facet markers of the owned cells (``owned_facet_marks``).
    """
    comm = mesh.comm
    local = _compat.local_mesh_data(mesh)
    n, nv, d = local.cell_vertex_x.shape
    start, stop = owned_range
    order = np.argsort(dofs)  # owned cells in global order
    names = sorted(marks)
    # A record is one float row (coordinates) and one integer row per cell:
    # [global, owner, vertex ids (nv), vertex owners (nv), facet ids (nv), marks (nv each)].
    ints = np.concatenate(
        [dofs[order, None], np.full((n, 1), comm.rank), local.cell_vertex_global[order],
         local.cell_vertex_owner[order], local.cell_facet_global[order]]
        + [np.asarray(marks[name], dtype=np.int64)[order] for name in names], axis=1).astype(np.int64)
    floats = local.cell_vertex_x[order].reshape(n, nv * d)
    vertex_columns = slice(2, 2 + nv)
    owner_columns = slice(2 + nv, 2 + 2 * nv)

    # 1. Stars of the vertices this process owns: (vertex, cell, cell owner), sorted by vertex.
    pairs = np.stack([ints[:, vertex_columns].ravel(), np.repeat(ints[:, 0], nv),
                      np.full(n * nv, comm.rank)], axis=1)
    stars, _ = alltoall(comm, ints[:, owner_columns].ravel(), pairs)
    stars = stars[np.lexsort((stars[:, 1], stars[:, 0]))]

    held_ints, held_floats, held_layer = [ints], [floats], [np.zeros(n, dtype=np.int64)]
    held = ints[:, 0]
    newest = ints
    expanded = np.empty(0, dtype=np.int64)
    for layer in range(1, layers + 1):
        # 2a. Ask the owners of the newest cells' vertices for their stars.
        v = np.stack([newest[:, vertex_columns].ravel(), newest[:, owner_columns].ravel()], axis=1)
        v = np.unique(v, axis=0)
        v = v[~np.isin(v[:, 0], expanded)]
        expanded = np.union1d(expanded, v[:, 0])
        asked, source = alltoall(comm, v[:, 1], v[:, :1])
        lo = np.searchsorted(stars[:, 0], asked[:, 0], side="left")
        counts = np.searchsorted(stars[:, 0], asked[:, 0], side="right") - lo
        take = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts - lo, counts)
        reply, _ = alltoall(comm, np.repeat(source, counts), stars[take][:, 1:])
        new = np.unique(reply, axis=0)
        new = new[~np.isin(new[:, 0], held)]
        # 2b. Ask the owners of the new cells for their records.
        asked, source = alltoall(comm, new[:, 1], new[:, :1])
        rows = asked[:, 0] - start
        record_ints, _ = alltoall(comm, source, ints[rows])
        record_floats, _ = alltoall(comm, source, floats[rows])
        o = np.argsort(record_ints[:, 0])
        newest = record_ints[o]
        held_ints.append(newest)
        held_floats.append(record_floats[o])
        held_layer.append(np.full(len(o), layer, dtype=np.int64))
        held = np.concatenate([held, newest[:, 0]])

    ints = np.concatenate(held_ints)
    floats = np.concatenate(held_floats)
    mark_columns = {name: slice(2 + 3 * nv + k * nv, 2 + 3 * nv + (k + 1) * nv) for k, name in enumerate(names)}
    # copies of the columns, not views: a view would keep the whole record array (14 integers
    # per 2D cell) alive in the geometry
    column = lambda columns: np.ascontiguousarray(ints[:, columns])  # noqa: E731
    return LocalCells(
        num_owned=n,
        global_index=column(0),
        owner=column(1),
        layer=np.concatenate(held_layer),
        vertices=floats.reshape(-1, nv, d),
        vertex_ids=column(vertex_columns),
        facet_ids=column(slice(2 + 2 * nv, 2 + 3 * nv)),
        marks={name: column(mark_columns[name]) for name in names},
        owned_range=(int(start), int(stop)),
        num_cells_global=local.num_cells_global,
    )
