"""Penalty contact between bodies for method ``fem-P1``: symmetric node-to-segment (2D) and
node-to-facet (3D) penalty, the scheme of explicit FEM codes.

Every node of a candidate facet (the scene's ``[contact] boundary``, selected as the DEM selects
its candidates, ``model.boundary_facets``) is a *slave* node against the candidate facets of the
other bodies, and every candidate facet is a *master* facet against the other bodies' nodes: the
two passes are the same loop over (node, facet) pairs, so the contact is symmetric (neither body
is preferred) without a second code path.

* **Gap.** For a node s at x_s and a facet f with nodes x_a, outward unit normal n (of its body),
  the projection ``x_c = sum_a N_a x_a`` of x_s on the facet's plane (N_a its barycentric
  coordinates, the P1 shape functions there) and the gap ``g = n . (x_s - x_c)``, the signed
  distance to the facet. The node's facet is, among the listed facets of the other bodies whose
  projection lies inside (every N_a >= 0), the one of largest g: for a node inside a convex body
  the nearest surface, and a node in front of some facet (g >= 0) is not in contact.
* **Energy and force.** ``1/2 kappa_p min(g, 0)^2`` per node. With the projection inside, the
  gradient of the distance is ``dg/dx_s = n`` and ``dg/dx_a = -N_a n`` (the rotation of the normal
  adds nothing at the closest point), so the node receives ``-kappa g n`` and the facet's nodes
  ``kappa g N_a n``: the forces sum to zero, momentum is conserved to rounding, and the force
  is the exact negative gradient of the energy while the node keeps its facet.
* **Stiffness.** In the spirit of the obstacles' ``kappa_i = m_i / dt^2`` (fem/penalty.py), a
  pair's spring ``kappa_p b b^T`` (b = (n, -N_a n)) on the lumped masses has the frequency
  ``kappa_p (1/m_s + sum_a N_a^2 / m_a) <= kappa_p (1/m_s + 1/min_a m_a)``; so
  ``kappa_p = PAIR_PENALTY_FACTOR / (dt^2 (1/m_s + 1/min_a m_a))``, a constant of the pair (no
  derivative of kappa in the force), about s m / (2 dt^2) between equal masses. With s = 1/2 a
  node pair in contact through both passes is about as stiff as an obstacle's node (s = 1).
* **Stable step.** The scheme is stable while ``dt^2 lambda_max(m^-1 (K + K_c)) < 4`` with K_c the
  active springs (their normals held). By Weyl, lambda_max <= 4 / dt_stable^2 + lambda_max of
  ``sum_p kappa_p c_p c_p^T`` (c_p = m^-1/2 b), and by Cauchy-Schwarz with the weights |c_{p,i}|,
  that is at most ``max_i sum_{p at i} kappa_p |c_{p,i}| sum_j |c_{p,j}|`` (i over the nodes,
  |c_{p,i}| = N_i / sqrt(m_i), N_s = 1). The bound is checked at every force evaluation with
  contact; a step it does not prove stable is an InputError naming ``time.cfl`` (like the
  obstacles' set-up check, which knows its springs in advance; the pairs' are known only when
  they touch).
* **Search.** A broad phase bounded and correct: the pairs are those of a node and a facet of
  another body whose centroid lies within ``reach_f + depth + 2 skin`` of the node (a cKDTree of
  the facet centroids), reach_f the facet's largest centroid-vertex distance, depth the largest
  reach, skin half of it; the list is rebuilt when a candidate node has moved by more than
  skin / 2 since it was made. Between builds every facet whose closest point is within ``depth``
  of a node is listed, so a node deeper than ``depth`` behind its nearest listed facet is an
  error (contact no longer resolved by the mesh), never a missed facet. What it cannot see is a
  node that crosses more than about two facet sizes of the other body within one step
  (tunnelling, v dt > h: a speed above the wave speed times the CFL number).

Distributed (fem/pair_exchange.py): a process tests its owned candidate nodes against the
candidate facets near them, received from their owners at each list build; the forces on
another process's facet nodes go back by a reverse scatter, and the sums of the outputs are
reduced. Every decision (a rebuild, an error) is taken on reduced values, the same on every
process.
"""

from __future__ import annotations

import numpy as np
import scipy.spatial
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError
from dolfinx_dem.fem.common import facet_nodes, node_coordinates, owned_facets
from dolfinx_dem.fem.pair_exchange import KnownFacets, node_bodies, owned_candidate_nodes

#: s of kappa_p = s / (dt^2 (1/m_s + 1/min_a m_a)) (module docstring).
PAIR_PENALTY_FACTOR = 0.5


def _normals(X: np.ndarray) -> np.ndarray:
    """Unit normals (unoriented) of facets with vertex positions X, (n, d, d)."""
    if X.shape[2] == 2:
        t = X[:, 1] - X[:, 0]
        n = np.stack([t[:, 1], -t[:, 0]], axis=1)
    else:
        n = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
    return n / np.linalg.norm(n, axis=1)[:, None]


def _shape_values(X: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The P1 shape values (barycentric coordinates) of the projections of the points
    ``X[:, 0] + r`` on the planes of the facets X, (n, d)."""
    e1 = X[:, 1] - X[:, 0]
    if X.shape[2] == 2:
        xi = np.einsum("pi,pi->p", e1, r) / np.einsum("pi,pi->p", e1, e1)
        return np.stack([1.0 - xi, xi], axis=1)
    e2 = X[:, 2] - X[:, 0]
    a, b, c = (np.einsum("pi,pi->p", *v) for v in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.einsum("pi,pi->p", e1, r), np.einsum("pi,pi->p", e2, r)
    det = a * c - b * b  # the Gram determinant, 4 area^2 > 0
    xi1, xi2 = (c * r1 - b * r2) / det, (a * r2 - b * r1) / det
    return np.stack([1.0 - xi1 - xi2, xi1, xi2], axis=1)


class NodeFacetPenalty:
    """The pair penalty of the process-local candidate ``facets`` of the P1 space ``V``; the module
    docstring gives the scheme. ``mass``: the lumped mass (a vector of V's layout); ``held``:
    the owned nodes that are clamped (no force); ``dt``, ``dt_stable``: the step and the stable
    step without contact between bodies (with the obstacles' springs, if any). The
    displacements ``u`` of every method are V's PETSc vector, ghosts up to date; the methods
    are collective."""

    def __init__(self, V, facets: np.ndarray, mass: PETSc.Vec, held: np.ndarray, dt: float, dt_stable: float):
        mesh = V.mesh
        self.comm, self.d = mesh.comm, mesh.geometry.dim
        self.dt, self.dt_stable = dt, dt_stable
        facets = owned_facets(mesh, np.asarray(facets, dtype=np.int32))
        self.num_facets = self.comm.allreduce(len(facets), op=MPI.SUM)
        if self.num_facets == 0:
            raise InputError("contact.boundary selects no facet")
        x0 = node_coordinates(V)
        body, num_bodies = node_bodies(V)
        own = facet_nodes(V, facets)
        sign = self._orientation(V, facets, x0, own)
        self.known = KnownFacets(V, own, body[own[:, 0]], sign, x0, mass)
        nodes = owned_candidate_nodes(V, own)
        self.slaves = nodes[~held[nodes]]
        self.x_slaves, self.body_slaves = x0[self.slaves], body[self.slaves]
        self.m_slaves = mass.array_r.reshape(-1, self.d)[self.slaves, 0]
        self.held = held
        present = np.zeros(num_bodies, dtype=np.int64)
        present[body[own[:, 0]]] = 1
        self.comm.Allreduce(MPI.IN_PLACE, present, op=MPI.SUM)
        bodies = np.flatnonzero(present)
        #: pairs (i, j), i < j, of the bodies with candidate facets (as the DEM's ``body_pairs``)
        self.body_pairs = [(int(a), int(b)) for k, a in enumerate(bodies) for b in bodies[k + 1:]]
        self.pair_index = np.full((num_bodies, num_bodies), -1, dtype=np.int64)
        for k, (a, b) in enumerate(self.body_pairs):
            self.pair_index[a, b] = self.pair_index[b, a] = k
        self.builds = 0
        self._forces = mass.duplicate()  # the forces on the known facets' nodes, summed at their owners
        self._list_u = None  # the slaves' displacements when the list was made
        self._last = (None, None)  # (the slaves' and known nodes' displacements, their ``state``)

    @staticmethod
    def _orientation(V, facets: np.ndarray, x0: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """+1 or -1 per owned facet: the sign that makes ``_normals`` point out of its cell."""
        mesh = V.mesh
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        f2c = mesh.topology.connectivity(tdim - 1, tdim)
        cells = f2c.array[f2c.offsets[facets]]
        inner = x0[_compat.cell_dofs(V).reshape(-1, tdim + 1)[cells]].mean(axis=1)  # inside the body
        n = _normals(x0[nodes])
        return np.where(np.einsum("ni,ni->n", n, inner - x0[nodes[:, 0]]) < 0, 1.0, -1.0)

    def num_pairs(self) -> int:
        """The node-facet pairs listed, summed over the processes."""
        return self.comm.allreduce(len(self.s) if self._list_u is not None else 0, op=MPI.SUM)

    # -- broad phase -----------------------------------------------------------------------------
    def _build(self, u: PETSc.Vec, us: np.ndarray) -> None:
        """The pairs of the slaves (displacements ``us``) and the known facets near them."""
        d = self.d
        k = self.known
        self.depth = self.comm.allreduce(k.largest_own_reach(u), op=MPI.MAX)
        self.skin = 0.5 * self.depth
        xs = self.x_slaves + us
        radius = 2.0 * self.depth + 2.0 * self.skin  # the largest reach + depth + 2 skin
        box = np.array([xs.min(axis=0), xs.max(axis=0)]) if len(xs) else np.array([[np.inf] * d, [-np.inf] * d])
        k.exchange(u, box, radius)
        X = k.x0[k.nodes] + k.displacements(u)[k.nodes]
        centroid = X.mean(axis=1)
        reach = np.linalg.norm(X - centroid[:, None], axis=2).max(axis=1, initial=0.0)
        near = scipy.spatial.cKDTree(centroid).query_ball_point(xs, radius) if len(centroid) else [[] for _ in xs]
        i = np.repeat(np.arange(len(xs)), [len(f) for f in near])
        f = np.fromiter((j for part in near for j in part), dtype=np.int64, count=len(i))
        # each facet's own reach: its closest point within depth of the node puts its centroid within
        # reach_f + depth, and the list holds while nothing moved by more than skin / 2
        keep = (self.body_slaves[i] != k.body[f]) & (
            np.linalg.norm(xs[i] - centroid[f], axis=1) <= reach[f] + self.depth + 2.0 * self.skin)
        self.s, self.f = i[keep], f[keep]
        self.kappa = PAIR_PENALTY_FACTOR / (self.dt**2 * (1.0 / self.m_slaves[self.s]
                                                          + 1.0 / k.mass[k.nodes[self.f]].min(axis=1)))
        self._list_u = us.copy()
        self.builds += 1

    # -- narrow phase ----------------------------------------------------------------------------
    def state(self, u: PETSc.Vec) -> dict:
        """The active pairs of this process at the displacements ``u``: slave ``s`` (index into
        ``slaves``), facet ``f`` (into the known facets) with nodes ``a`` (into the known nodes),
        shape values ``N``, normal ``n``, gap ``g`` < 0, stiffness ``kappa``, and the known nodes'
        displacements ``uk`` (kept for the next call at the same displacements: a step's force,
        energy and outputs)."""
        us = u.array_r.reshape(-1, self.d)[self.slaves]
        same = self._last[0] is not None and np.array_equal(us, self._last[0])
        if self.comm.allreduce(same, op=MPI.LAND):  # no slave moved, so no candidate node (each is a slave
            return self._last[1]                     # of its owner, or clamped)
        moved = self._list_u is None or np.linalg.norm(us - self._list_u, axis=1).max(initial=0.0) > 0.5 * self.skin
        if self.comm.allreduce(moved, op=MPI.LOR):
            self._build(u, us)
        k = self.known
        uk = k.displacements(u).copy()
        s, fa = self.s, k.nodes[self.f]
        X = k.x0[fa] + uk[fa]
        n = k.sign[self.f, None] * _normals(X)
        r = self.x_slaves[s] + us[s] - X[:, 0]
        N = _shape_values(X, r)
        g = np.einsum("pi,pi->p", n, r)
        inside = np.flatnonzero((N >= 0).all(axis=1))
        # per slave, its inside facet of largest g: sort by slave, then g descending
        order = inside[np.lexsort((-g[inside], s[inside]))]
        _, first = np.unique(s[order], return_index=True)
        chosen = order[first]
        p = chosen[g[chosen] < 0]
        deepest = self.comm.allreduce(float(-g[p].min(initial=0.0)), op=MPI.MAX)
        if deepest > self.depth:
            raise InputError(f"contact between bodies is no longer resolved: a node lies {deepest:.4g} m behind the "
                             f"nearest facet of another body, more than the largest facet's reach ({self.depth:.4g} "
                             "m, centroid to vertex): lower time.cfl")
        state = {"s": s[p], "f": self.f[p], "a": fa[p], "N": N[p], "n": n[p], "g": g[p], "kappa": self.kappa[p],
                 "uk": uk}
        self._last = (us.copy(), state)
        return state

    def touch_time(self, u0: PETSc.Vec, u1: PETSc.Vec, dt: float) -> float | None:
        """For a step of length dt from the displacements ``u0`` (no pair active) to ``u1``: the
        time in [0, dt] at which the first pair active at ``u1`` closed its gap (the gap taken
        affine along the step, as the DEM's ``touch_time``); None if no pair is active anywhere."""
        st = self.state(u1)
        k = self.known
        uk0 = k.displacements(u0)
        s, fa = st["s"], k.nodes[st["f"]]
        X = k.x0[fa] + uk0[fa]
        n = k.sign[st["f"], None] * _normals(X)
        us0 = u0.array_r.reshape(-1, self.d)[self.slaves[s]]
        g0 = np.maximum(np.einsum("pi,pi->p", n, self.x_slaves[s] + us0 - X[:, 0]), 0.0)
        first = self.comm.allreduce(float(dt * (g0 / (g0 - st["g"])).min(initial=np.inf)), op=MPI.MIN)
        return None if first == np.inf else first

    def energy(self, u: PETSc.Vec) -> float:
        """``sum_p 1/2 kappa_p g_p^2`` over the active pairs (J; J/m in 2D), this process's part."""
        st = self.state(u)
        return float(0.5 * np.dot(st["kappa"], st["g"] ** 2))

    def add_forces(self, u: PETSc.Vec, out: np.ndarray) -> None:
        """out (n_owned, d) += the penalty forces on the owned nodes (minus the energy's gradient),
        none on held nodes; checks the stable-step bound (module docstring)."""
        st = self.state(u)
        if self.comm.allreduce(len(st["g"]), op=MPI.SUM) == 0:
            return
        self._check_step(st)
        d = self.d
        kg = (st["kappa"] * st["g"])[:, None] * st["n"]
        on_facets = np.zeros((len(st["uk"]), d))
        np.add.at(on_facets, st["a"].ravel(), (st["N"][..., None] * kg[:, None, :]).reshape(-1, d))
        self._forces.zeroEntries()
        self.known.add_to(on_facets, self._forces)
        force = self._forces.array_r.reshape(-1, d).copy()
        np.add.at(force, self.slaves[st["s"]], -kg)
        force[self.held] = 0.0
        out += force

    def eigenvalue_bound(self, st: dict) -> float:
        """An upper bound of lambda_max(m^-1 (K + K_c)), K_c the springs of the active pairs of every
        process (their normals held): ``4 / dt_stable^2 + max_i sum_{p at i} kappa_p |c_{p,i}|
        sum_j |c_{p,j}|`` (module docstring)."""
        d, k = self.d, self.known
        c_s = 1.0 / np.sqrt(self.m_slaves[st["s"]])
        c_a = st["N"] / np.sqrt(k.mass[st["a"]])
        total = st["kappa"] * (c_s + c_a.sum(axis=1))
        rows = np.zeros((len(st["uk"]), d))
        np.add.at(rows[:, 0], st["a"].ravel(), (c_a * total[:, None]).ravel())
        self._forces.zeroEntries()
        self.known.add_to(rows, self._forces)
        on_owned = self._forces.array_r.reshape(-1, d)[:, 0].copy()
        np.add.at(on_owned, self.slaves[st["s"]], c_s * total)
        return 4.0 / self.dt_stable**2 + self.comm.allreduce(float(on_owned.max(initial=0.0)), op=MPI.MAX)

    def _check_step(self, st: dict) -> None:
        bound = self.eigenvalue_bound(st)
        if self.dt**2 * bound >= 4.0:
            raise InputError(f"the time step dt = {self.dt:.6g} s is not proved stable with the contact between bodies "
                             f"(kappa = {PAIR_PENALTY_FACTOR:g} / (dt^2 (1/m_s + 1/m_a)) per node-facet pair: the "
                             f"step must stay below {2.0 / np.sqrt(bound):.6g} s); lower time.cfl")

    def outputs(self, u: PETSc.Vec) -> list[float]:
        """The DEM's pair columns: ``contact_force`` (the sum of the pairs' normal forces),
        ``penetration`` (the deepest node, m), and the force of body j on body i,
        ``contact_force_<i>_<j>_<x|y|z>`` for each pair i < j of ``body_pairs``; reduced."""
        st = self.state(u)
        f = -(st["kappa"] * st["g"])[:, None] * st["n"]  # on the slave's body, from the facet's
        bs, bf = self.body_slaves[st["s"]], self.known.body[st["f"]]
        sums = np.zeros(len(self.body_pairs) * self.d + 1)
        forces = sums[:-1].reshape(-1, self.d)
        np.add.at(forces, self.pair_index[bs, bf], np.where((bs < bf)[:, None], f, -f))
        sums[-1] = -np.sum(st["kappa"] * st["g"])
        self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        depth = self.comm.allreduce(0.0 - float(st["g"].min(initial=0.0)), op=MPI.MAX)
        return [0.0 + sums[-1], depth, *sums[:-1]]

    def output_columns(self) -> tuple[str, ...]:
        xyz = "xyz"[: self.d]
        return ("contact_force", "penetration") + tuple(f"contact_force_{i}_{j}_{c}" for i, j in self.body_pairs
                                                          for c in xyz)
