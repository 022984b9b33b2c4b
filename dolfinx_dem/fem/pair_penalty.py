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

One process only: the list is local and serial (a node and its facets on one process); a run
on more processes is refused by fem/scene_run.py naming the key ``contact``.
"""

from __future__ import annotations

import numpy as np
import scipy.spatial

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError
from dolfinx_dem.fem.common import facet_nodes, node_coordinates
from dolfinx_dem.geometry import compute_bodies

#: s of kappa_p = s / (dt^2 (1/m_s + 1/min_a m_a)) (module docstring).
PAIR_PENALTY_FACTOR = 0.5


def node_bodies(V) -> tuple[np.ndarray, int]:
    """Body of each P1 node (block) of a one-process mesh, numbered as the DEM's
    (``geometry.compute_bodies``: the lexicographic order of their first barycentre), and the
    number of bodies."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    n_cells = mesh.topology.index_map(tdim).size_local
    mesh.topology.create_connectivity(tdim - 1, tdim)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    counts = np.diff(f2c.offsets)
    facet_cells = np.full((len(counts), 2), -1, dtype=np.int32)
    facet_cells[:, 0] = f2c.array[f2c.offsets[:-1]]
    two = counts == 2
    facet_cells[two, 1] = f2c.array[f2c.offsets[:-1][two] + 1]
    x = node_coordinates(V)
    cell_nodes = _compat.cell_dofs(V).reshape(n_cells, tdim + 1)
    centres = x[cell_nodes].mean(axis=1)
    cell_body, num = compute_bodies(mesh.comm, facet_cells, centres, np.arange(n_cells), n_cells)
    body = np.empty(len(x), dtype=np.int64)
    body[cell_nodes] = cell_body[:, None]
    return body, num


class NodeFacetPenalty:
    """The pair penalty of the process-local candidate ``facets`` of the P1 space ``V``; the module
    docstring gives the scheme. ``mass``: lumped mass per node; ``held``: clamped nodes (no
    force); ``dt``, ``dt_stable``: the step and the stable step without contact."""

    def __init__(self, V, facets: np.ndarray, mass: np.ndarray, held: np.ndarray, dt: float, dt_stable: float):
        mesh = V.mesh
        self.d = mesh.geometry.dim
        self.dt, self.dt_stable = dt, dt_stable
        self.x0 = node_coordinates(V)
        self.body, num_bodies = node_bodies(V)
        self.facets = facet_nodes(V, np.asarray(facets, dtype=np.int32))  # (nf, d) nodes of each facet
        if len(self.facets) == 0:
            raise InputError("contact.boundary selects no facet")
        self.facet_body = self.body[self.facets[:, 0]]
        self.sign = self._orientation(V, np.asarray(facets, dtype=np.int32))
        self.nodes = np.unique(self.facets)
        self.mass, self.held = mass, held
        bodies = np.unique(self.facet_body)
        #: pairs (i, j), i < j, of the bodies with candidate facets (as the DEM's ``body_pairs``)
        self.body_pairs = [(int(a), int(b)) for k, a in enumerate(bodies) for b in bodies[k + 1:]]
        self.pair_index = np.full((num_bodies, num_bodies), -1, dtype=np.int64)
        for k, (a, b) in enumerate(self.body_pairs):
            self.pair_index[a, b] = self.pair_index[b, a] = k
        self.builds = 0
        self._list_u = None  # the candidate nodes' displacements when the list was made
        self._last = (None, None)  # (the candidate nodes' displacements, their ``state``)

    def _orientation(self, V, facets: np.ndarray) -> np.ndarray:
        """+1 or -1 per facet: the sign that makes ``_normals`` point out of the facet's cell."""
        mesh = V.mesh
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        f2c = mesh.topology.connectivity(tdim - 1, tdim)
        cells = f2c.array[f2c.offsets[facets]]
        cell_nodes = _compat.cell_dofs(V).reshape(-1, tdim + 1)[cells]
        inner = self.x0[cell_nodes].mean(axis=1)  # the cell's barycentre lies inside
        n = self._normals(self.x0[self.facets])
        return np.where(np.einsum("ni,ni->n", n, inner - self.x0[self.facets[:, 0]]) < 0, 1.0, -1.0)

    def _normals(self, X: np.ndarray) -> np.ndarray:
        """Unit normals (unoriented) of facets with vertex positions X, (n, d, d)."""
        if self.d == 2:
            t = X[:, 1] - X[:, 0]
            n = np.stack([t[:, 1], -t[:, 0]], axis=1)
        else:
            n = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
        return n / np.linalg.norm(n, axis=1)[:, None]

    # -- broad phase -----------------------------------------------------------------------------
    def _build(self, u: np.ndarray) -> None:
        X = self.x0[self.facets] + u[self.facets]
        centroid = X.mean(axis=1)
        reach = np.linalg.norm(X - centroid[:, None], axis=2).max(axis=1)
        self.depth = float(reach.max())
        self.skin = 0.5 * self.depth
        tree = scipy.spatial.cKDTree(centroid)
        slaves = self.nodes[~self.held[self.nodes]]
        xs = self.x0[slaves] + u[slaves]
        near = tree.query_ball_point(xs, float(reach.max()) + self.depth + 2.0 * self.skin)
        k = np.repeat(np.arange(len(slaves)), [len(f) for f in near])
        f = np.fromiter((j for part in near for j in part), dtype=np.int64, count=len(k))
        s = slaves[k]
        # each facet's own reach: its closest point within depth of the node puts its centroid within
        # reach_f + depth, and the list holds while nothing moved by more than skin / 2
        keep = (self.body[s] != self.facet_body[f]) & (
            np.linalg.norm(xs[k] - centroid[f], axis=1) <= reach[f] + self.depth + 2.0 * self.skin)
        self.s, self.f = s[keep], f[keep]
        m = self.mass
        self.kappa = PAIR_PENALTY_FACTOR / (self.dt**2 * (1.0 / m[self.s] + 1.0 / m[self.facets[self.f]].min(axis=1)))
        self._list_u = u[self.nodes].copy()
        self.builds += 1

    # -- narrow phase ----------------------------------------------------------------------------
    def state(self, u: np.ndarray) -> dict:
        """The active pairs at the node displacements ``u`` (n_nodes, d): slave ``s``, facet nodes
        ``a`` (n, d) of facet ``f``, shape values ``N``, normal ``n``, gap ``g`` < 0, stiffness ``kappa`` (kept for
        the next call at the same displacements: a step's force, energy and outputs)."""
        un = u[self.nodes]
        if self._last[0] is not None and np.array_equal(un, self._last[0]):
            return self._last[1]
        if self._list_u is None or np.linalg.norm(u[self.nodes] - self._list_u, axis=1).max() > 0.5 * self.skin:
            self._build(u)
        s, fa = self.s, self.facets[self.f]
        X = self.x0[fa] + u[fa]
        n = self.sign[self.f, None] * self._normals(X)
        r = self.x0[s] + u[s] - X[:, 0]
        N = self._shape_values(X, r)
        g = np.einsum("pi,pi->p", n, r)
        inside = np.flatnonzero((N >= 0).all(axis=1))
        # per slave, its inside facet of largest g: sort by slave, then g descending
        order = inside[np.lexsort((-g[inside], s[inside]))]
        _, first = np.unique(s[order], return_index=True)
        chosen = order[first]
        p = chosen[g[chosen] < 0]
        deepest = float(-g[p].min(initial=0.0))
        if deepest > self.depth:
            raise InputError(f"contact between bodies is no longer resolved: a node lies {deepest:.4g} m behind the "
                             f"nearest facet of another body, more than the largest facet's reach ({self.depth:.4g} "
                             "m, centroid to vertex): lower time.cfl")
        state = {"s": s[p], "f": self.f[p], "a": fa[p], "N": N[p], "n": n[p], "g": g[p], "kappa": self.kappa[p]}
        self._last = (un.copy(), state)
        return state

    def touch_time(self, u0: np.ndarray, u1: np.ndarray, dt: float) -> float | None:
        """For a step of length dt from the displacements ``u0`` (no pair active) to ``u1``: the
        time in [0, dt] at which the first pair active at ``u1`` closed its gap (the gap taken
        affine along the step, as the DEM's ``touch_time``); None if no pair is active."""
        st = self.state(u1)
        if len(st["g"]) == 0:
            return None
        s, fa = st["s"], self.facets[st["f"]]
        X = self.x0[fa] + u0[fa]
        n = self.sign[st["f"], None] * self._normals(X)
        g0 = np.maximum(np.einsum("pi,pi->p", n, self.x0[s] + u0[s] - X[:, 0]), 0.0)
        return float(dt * (g0 / (g0 - st["g"])).min())

    def _shape_values(self, X: np.ndarray, r: np.ndarray) -> np.ndarray:
        """The P1 shape values (barycentric coordinates) of the projections of the points
        ``X[:, 0] + r`` on the planes of the facets X, (n, d)."""
        e1 = X[:, 1] - X[:, 0]
        if self.d == 2:
            xi = np.einsum("pi,pi->p", e1, r) / np.einsum("pi,pi->p", e1, e1)
            return np.stack([1.0 - xi, xi], axis=1)
        e2 = X[:, 2] - X[:, 0]
        a, b, c = (np.einsum("pi,pi->p", *v) for v in ((e1, e1), (e1, e2), (e2, e2)))
        r1, r2 = np.einsum("pi,pi->p", e1, r), np.einsum("pi,pi->p", e2, r)
        det = a * c - b * b  # the Gram determinant, 4 area^2 > 0
        xi1, xi2 = (c * r1 - b * r2) / det, (a * r2 - b * r1) / det
        return np.stack([1.0 - xi1 - xi2, xi1, xi2], axis=1)

    def energy(self, u: np.ndarray) -> float:
        """``sum_p 1/2 kappa_p g_p^2`` over the active pairs (J; J/m in 2D)."""
        st = self.state(u)
        return float(0.5 * np.dot(st["kappa"], st["g"] ** 2))

    def add_forces(self, u: np.ndarray, out: np.ndarray) -> None:
        """out (n_nodes, d) += the penalty forces (minus the energy's gradient), none on held
        nodes; checks the stable-step bound (module docstring)."""
        st = self.state(u)
        if len(st["g"]) == 0:
            return
        self._check_step(st)
        kg = (st["kappa"] * st["g"])[:, None] * st["n"]
        force = np.zeros_like(out)
        np.add.at(force, st["s"], -kg)
        np.add.at(force, st["a"].ravel(), (st["N"][..., None] * kg[:, None, :]).reshape(-1, self.d))
        force[self.held] = 0.0
        out += force

    def eigenvalue_bound(self, st: dict) -> float:
        """An upper bound of lambda_max(m^-1 (K + K_c)), K_c the springs of the active pairs ``st``
        (their normals held): ``4 / dt_stable^2 + max_i sum_{p at i} kappa_p |c_{p,i}| sum_j |c_{p,j}|``
        (module docstring)."""
        m = self.mass
        nodes = np.concatenate([st["s"][:, None], st["a"]], axis=1)
        c = np.concatenate([np.ones((len(st["s"]), 1)), st["N"]], axis=1) / np.sqrt(m[nodes])
        rows = np.bincount(nodes.ravel(), (st["kappa"][:, None] * c * c.sum(axis=1, keepdims=True)).ravel(),
                           minlength=len(m))
        return 4.0 / self.dt_stable**2 + rows.max()

    def _check_step(self, st: dict) -> None:
        bound = self.eigenvalue_bound(st)
        if self.dt**2 * bound >= 4.0:
            raise InputError(f"the time step dt = {self.dt:.6g} s is not proved stable with the contact between bodies "
                             f"(kappa = {PAIR_PENALTY_FACTOR:g} / (dt^2 (1/m_s + 1/m_a)) per node-facet pair: the "
                             f"step must stay below {2.0 / np.sqrt(bound):.6g} s); lower time.cfl")

    def outputs(self, u: np.ndarray) -> list[float]:
        """The DEM's pair columns: ``contact_force`` (the sum of the pairs' normal forces),
        ``penetration`` (the deepest node, m), and the force of body j on body i,
        ``contact_force_<i>_<j>_<x|y|z>`` for each pair i < j of ``body_pairs``."""
        st = self.state(u)
        f = -(st["kappa"] * st["g"])[:, None] * st["n"]  # on the slave's body, from the facet's
        bs, bf = self.body[st["s"]], self.facet_body[st["f"]]
        forces = np.zeros((len(self.body_pairs), self.d))
        k = self.pair_index[bs, bf]
        np.add.at(forces, k, np.where((bs < bf)[:, None], f, -f))
        return [0.0 - float(np.sum(st["kappa"] * st["g"])), 0.0 - float(st["g"].min(initial=0.0)), *forces.ravel()]

    def output_columns(self) -> tuple[str, ...]:
        xyz = "xyz"[: self.d]
        return ("contact_force", "penetration") + tuple(f"contact_force_{i}_{j}_{c}" for i, j in self.body_pairs
                                                          for c in xyz)
