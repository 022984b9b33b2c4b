"""The distributed data of the pair penalty of method ``fem-P1`` (fem/pair_penalty.py): the
bodies of the P1 nodes, the owned candidate nodes, and the candidate facets a process tests its
nodes against, with the scatters that read those facets' displacements and return their forces.

A process owns the candidate facets of its owned facets and the candidate nodes of its owned
nodes (the slaves it tests). The facets near its nodes may lie on any process (the other body
of a contact is anywhere in the partition): at each list build every process sends the box of
its nodes (2 d numbers per process, the one gather), and each owner sends the facets whose
centroid lies in a box, with the global numbers of their nodes, to that box's process (an
all-to-all of the facets near each process's nodes: it grows with the contact surface a process
holds, not with the mesh). The nodes' displacements and masses then come by a PETSc scatter
from the global vectors, and the forces on them go back by the same scatter, reversed (ADD).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.fem.common import node_coordinates


def node_bodies(V) -> tuple[np.ndarray, int]:
    """Body of each process-local P1 node (block), owned and ghost, and the number of bodies: the
    connected components of the mesh, numbered as the DEM's (``geometry.compute_bodies``: in the
    lexicographic order of each body's first cell barycentre, so that the numbers depend neither
    on the numbering nor on the process count). Label propagation: each node starts with its
    global number, each component of this process's cells takes its smallest, and the owners and
    ghosts of a node take the smallest of theirs (PETSc scatters), until no label changes."""
    mesh, comm = V.mesh, V.mesh.comm
    tdim = mesh.topology.dim
    imap = V.dofmap.index_map
    n_own, n = imap.size_local, imap.size_local + imap.num_ghosts
    cell_nodes = _compat.cell_dofs(V).reshape(-1, tdim + 1)
    edges = np.concatenate([cell_nodes[:, [0, k]] for k in range(1, tdim + 1)])
    graph = scipy.sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    component = scipy.sparse.csgraph.connected_components(graph, directed=False)[1]
    label = imap.local_to_global(np.arange(n, dtype=np.int32)).astype(np.float64)
    vec = PETSc.Vec().createGhost(np.asarray(imap.ghosts, dtype=PETSc.IntType), size=(n_own, PETSc.DECIDE),
                                  comm=comm)
    while True:
        smallest = np.full(component.max() + 1 if n else 0, np.inf)
        np.minimum.at(smallest, component, label)
        with vec.localForm() as local:
            local.array[:] = -smallest[component]  # MAX of the negated labels: their MIN
        vec.ghostUpdate(PETSc.InsertMode.MAX_VALUES, PETSc.ScatterMode.REVERSE)
        vec.ghostUpdate(PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        with vec.localForm() as local:
            new = -local.array.copy()
        changed = comm.allreduce(bool(np.any(new != label)), op=MPI.LOR)
        label = new
        if not changed:
            break
    vec.destroy()
    x = node_coordinates(V)
    n_cells = mesh.topology.index_map(tdim).size_local
    centres = x[cell_nodes[:n_cells]].mean(axis=1)
    cell_label = label[cell_nodes[:n_cells, 0]]
    order = np.lexsort(centres.T[::-1])
    present, first = np.unique(cell_label[order], return_index=True)
    keys = np.concatenate(comm.allgather(np.c_[present, centres[order][first]]))
    keys = keys[np.lexsort(keys[:, 1:].T[::-1])]  # by position
    labels, first = np.unique(keys[:, 0], return_index=True)
    number = np.empty(len(labels), dtype=np.int64)
    number[np.argsort(first)] = np.arange(len(labels))
    return number[np.searchsorted(labels, label)], len(labels)


def owned_candidate_nodes(V, facet_nodes: np.ndarray) -> np.ndarray:
    """The owned nodes of the process-local candidate facets' ``facet_nodes`` of all processes
    (a reverse scatter marks a node whose facets another process holds)."""
    marker = np.zeros(V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts)
    marker[facet_nodes.ravel()] = 1.0
    imap = V.dofmap.index_map
    vec = PETSc.Vec().createGhost(np.asarray(imap.ghosts, dtype=PETSc.IntType), size=(imap.size_local, PETSc.DECIDE),
                                  comm=V.mesh.comm)
    with vec.localForm() as local:
        local.array[:] = marker
    vec.ghostUpdate(PETSc.InsertMode.ADD_VALUES, PETSc.ScatterMode.REVERSE)
    nodes = np.flatnonzero(vec.array_r > 0)
    vec.destroy()
    return nodes


class KnownFacets:
    """The candidate facets a process tests its nodes against (its own and other processes'),
    made by ``exchange``: their nodes ``nodes`` (indices into the known nodes, whose global
    numbers are ``global_nodes``), ``body``,
    ``sign`` (of the normal), and the known nodes' reference positions ``x0`` and masses ``mass``;
    ``displacements(u)`` reads the known nodes' displacements, ``add_forces(f, out)`` adds the
    forces ``f`` on the known nodes to the global vector ``out``."""

    def __init__(self, V, own_nodes: np.ndarray, own_body: np.ndarray, own_sign: np.ndarray, x0: np.ndarray,
                 mass: PETSc.Vec):
        self.comm, self.d = V.mesh.comm, V.mesh.geometry.dim
        imap = V.dofmap.index_map
        self._own = own_nodes  # (n_own_facets, d) local nodes
        self._own_global = imap.local_to_global(own_nodes.ravel().astype(np.int32)).reshape(own_nodes.shape)
        self._own_body, self._own_sign, self._x0 = own_body, own_sign, x0
        self._mass = mass
        self._coordinates = mass.duplicate()  # the owned nodes' reference positions, to scatter
        self._coordinates.array[:] = x0[: imap.size_local].ravel()
        self._scatter = self._seq = None

    def _own_positions(self, u: PETSc.Vec) -> np.ndarray:
        """The vertex positions of this process's own candidate facets at ``u``, (n, d, d)."""
        with u.localForm() as local:
            return self._x0[self._own] + local.array_r.reshape(-1, self.d)[self._own]

    def largest_own_reach(self, u: PETSc.Vec) -> float:
        """The largest centroid-vertex distance of this process's own candidate facets at ``u``."""
        X = self._own_positions(u)
        return float(np.linalg.norm(X - X.mean(axis=1)[:, None], axis=2).max(initial=0.0))

    def exchange(self, u: PETSc.Vec, box: np.ndarray, radius: float) -> None:
        """Collective: each process receives the candidate facets whose centroid (at ``u``) lies
        within ``radius`` of its ``box`` (2, d): lower and upper corners of its nodes (empty:
        +inf, -inf)."""
        d = self.d
        centroid = self._own_positions(u).mean(axis=1)
        boxes = self.comm.allgather(box)
        sends = []
        for lo, hi in boxes:
            near = np.flatnonzero(((centroid >= lo - radius) & (centroid <= hi + radius)).all(axis=1))
            sends.append((self._own_global[near], self._own_body[near], self._own_sign[near]))
        received = self.comm.alltoall(sends)
        nodes = np.concatenate([r[0] for r in received]).reshape(-1, d)
        self.body = np.concatenate([r[1] for r in received])
        self.sign = np.concatenate([r[2] for r in received])
        known, inverse = np.unique(nodes, return_inverse=True)
        self.nodes = inverse.reshape(-1, d)
        self.global_nodes = known
        if self._scatter is not None:
            self._scatter.destroy()
            self._seq.destroy()
        index = PETSc.IS().createBlock(d, known.astype(PETSc.IntType), comm=MPI.COMM_SELF)
        self._seq = PETSc.Vec().createSeq(len(known) * d, bsize=d, comm=MPI.COMM_SELF)
        self._scatter = PETSc.Scatter().create(u, index, self._seq, None)
        index.destroy()
        self.x0 = self._read(self._coordinates).copy()
        self.mass = self._read(self._mass)[:, 0].copy()

    def _read(self, vec: PETSc.Vec) -> np.ndarray:
        self._scatter.scatter(vec, self._seq, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        return self._seq.array_r.reshape(-1, self.d)

    def displacements(self, u: PETSc.Vec) -> np.ndarray:
        """The known nodes' displacements (collective), (n_known, d), valid until the next read."""
        return self._read(u)

    def add_to(self, values: np.ndarray, out: PETSc.Vec) -> None:
        """out (a global vector, owned entries) += ``values`` (n_known, d) on the known nodes
        (collective: a reverse scatter that adds)."""
        self._seq.array[:] = values.ravel()
        self._scatter.scatter(self._seq, out, PETSc.InsertMode.ADD_VALUES, PETSc.ScatterMode.REVERSE)
