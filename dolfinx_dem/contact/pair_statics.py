"""The statics interface of contact between bodies (``contact.protocol.StaticContact``).

On a piece A (the pairs in contact and the overlap configuration fixed) the gaps g_p and the
overlaps w_p of the pairs are affine in u (2D), c_p = w_p g_p quadratic and the potential
V = 1/2 |a + delta_a|^2 quartic (contact/pair.py): the iteration is a damped Newton method on
the pieces, with the exact Hessian

    d^2 V/du^2 = J^T J + sum_p mu_p (grad w_p grad g_p^T + grad g_p grad w_p^T),
    J = Q + sum_p z_p grad c_p^T,  grad c_p = w_p grad g_p + g_p grad w_p,  mu_p = z_p . (a + delta_a),

or its Gauss-Newton part J^T J. A piece is a sorted array of pair keys (``pair_keys``: the
pairs' global facet numbers, which neither the partition nor a list rebuild changes), the same on
every process: each pair is decided by the owner of its first facet, and the keys of the contact
zone are gathered. In 3D the overlaps are quadratic on a piece and this Hessian does not hold:
statics with contact between bodies is 2D.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import InputError, StaticsError


class PairStatics:
    """The statics interface of a ``contact.pair.PairContact`` (module docstring)."""

    quadratic = False
    local_pieces = False
    no_contact_message = ("no pair is in contact: contact between bodies does not hold them (check the contact "
                          "boundary and the load direction)")

    def __init__(self, contact):
        if contact.d != 2:
            raise InputError("statics with contact between bodies is implemented in 2D, not 3D")
        self.contact = contact
        #: the smallest Verlet skin (m): the scale of the gaps
        self.length_scale = contact.skin

    def prepare(self, u: PETSc.Vec) -> None:
        """A trial point may move facets by more than half their skins: the list is rebuilt."""
        self.contact.prepare(u)

    def start_piece(self, u: PETSc.Vec) -> np.ndarray:
        """The overlapping pairs of smallest gap (as for obstacles): the piece that holds a body
        which only contact holds; or the pairs in contact at the start, where a prescribed body
        held at U(t) penetrates another."""
        up = self.contact.patch_values(u)
        active = self.touching_pairs(up, max(0.0, self.contact.outputs.smallest_gap(up) + 1e-9 * self.length_scale))
        if len(active) == 0:
            raise StaticsError("no pair of contact candidate facets faces another: contact between bodies cannot "
                               "hold them (check the contact boundary)")
        return active

    def touching(self, u: PETSc.Vec) -> np.ndarray:
        return self.touching_pairs(self.contact.patch_values(u))

    def add_force(self, u: PETSc.Vec, out: PETSc.Vec, piece: np.ndarray) -> None:
        self.contact.add_force(u, out, piece)

    def add_hessian(self, H: PETSc.Mat, u: PETSc.Vec, piece: np.ndarray, exact: bool) -> None:
        self._add_piece_hessian(H, self.contact.patch_values(u), piece, exact)

    def step_ratio(self, step: PETSc.Vec) -> float:
        """No facet may move more than half its skin in one step: the pairs it would meet are then
        all in the list built at u, and a long step (a piece that holds a body weakly, e.g. by a
        pair of small overlap) cannot carry one body through another."""
        return self.contact.pair_list.motion_ratio(self.contact.patch_values(step))

    def switches_crossed(self, u: PETSc.Vec, step: PETSc.Vec, alpha: float, piece: np.ndarray) -> np.ndarray:
        up = self.contact.prepare(u)[0]  # the line search may have rebuilt the list elsewhere
        return self._switches_crossed(up, self.contact.patch_values(step), alpha, piece)

    def constraint_gradients(self, u: PETSc.Vec, pinned: np.ndarray) -> list[PETSc.Vec]:
        return [self.gap_gradient(self.contact.patch_values(u), key) for key in pinned]

    def constraint_products(self, u: PETSc.Vec, pinned: np.ndarray, gradients: list[PETSc.Vec],
                            vectors: list[PETSc.Vec]) -> np.ndarray:
        return np.array([[b.dot(v) for v in vectors] for b in gradients])

    def constraint_gaps(self, u: PETSc.Vec, pinned: np.ndarray) -> np.ndarray:
        return self.pinned_values(self.contact.patch_values(u), np.zeros(0, dtype=np.int64), pinned)[0]

    def constraint_reactions(self, u: PETSc.Vec, piece: np.ndarray, pinned: np.ndarray) -> np.ndarray:
        return self.pinned_values(self.contact.patch_values(u), piece, pinned)[1]

    def touching_pairs(self, up: np.ndarray, below: float = 0.0) -> np.ndarray:
        """Sorted keys of the pairs with g < ``below`` and w > 0, on every process (collective).
        Each pair is decided by the owner of its first facet alone, so that every process holds
        the same set even where g rounds differently on two processes. The keys of the contact
        zone are gathered, not mesh-sized data."""
        g, w = self.contact.outputs.pair_states(up)
        mine = (self.contact.listed.i < self.contact.num_own) & (g < below) & (w > 0)
        return np.sort(np.concatenate(self.contact.comm.allgather(self.contact.pair_keys()[mine])))

    def _piece_derivatives(self, up: np.ndarray, active: np.ndarray):
        """On the piece ``active`` (sorted keys) at patch values ``up``: the patch-dof gradients
        of g_p and w_p of the listed pairs ((P, patch) CSR; w and g are affine on a piece), the
        pairs in the piece (w_p > 0), g_p, w_p and mu_p = z_p . (a + delta_a) (own rows' part)."""
        L, d = self.contact.listed, self.contact.d
        g, w, dw = self.contact.gaps_and_overlaps(np.arange(len(L)), *self.contact.pair_displacements(up))
        on = np.isin(self.contact.pair_keys(), active) & (w > 0)
        c = np.where(on, w * g, 0.0)
        mu = np.where(on, L.ZT @ (L.Q @ up + self.contact.row_lift + L.Z @ c), 0.0)
        # dg/du_j = n = -dg/du_i, dw/du_j = dw = -dw/du_i (facet displacements), then R.
        P, nf = len(L), len(self.contact.facets_all)
        rows = np.repeat(np.arange(P), 2 * d)
        cols = np.concatenate([L.i[:, None] * d + np.arange(d), L.j[:, None] * d + np.arange(d)], axis=1).ravel()
        Dg = scipy.sparse.csr_matrix((np.concatenate([-L.n, L.n], axis=1).ravel(), (rows, cols)), shape=(P, nf * d))
        Dw = scipy.sparse.csr_matrix((np.concatenate([-dw, dw], axis=1).ravel(),
                                      (rows, cols)), shape=(P, nf * d))
        return (Dg @ self.contact.pair_list.R).tocsr(), (Dw @ self.contact.pair_list.R).tocsr(), on, g, w, mu

    def _add_piece_hessian(self, H: PETSc.Mat, up: np.ndarray, active: np.ndarray, curvature: bool = False) -> None:
        """H += d^2 V/du^2 - K on this process's own rows for the piece ``active`` (sorted
        ``pair_keys``) at patch values ``up`` (collective: the processes' rows add up; ``H`` must
        accept new nonzeros, the caller assembles it). With J = Q + sum_p z_p grad c_p^T, the
        Jacobian of the rows a + delta_a (grad c_p = w_p grad g_p + g_p grad w_p, w and g affine on
        the piece),

            d^2 V/du^2 = J^T J + sum_p mu_p (grad w_p grad g_p^T + grad g_p grad w_p^T),

        mu_p = z_p . (a + delta_a). The Gauss-Newton part J^T J (positive semi-definite) always;
        the second term, which may make it indefinite, with ``curvature`` (mu_p summed over the
        own rows: the processes' parts add up)."""
        Gg, Gw, on, g, w, mu = self._piece_derivatives(up, active)
        L = self.contact.listed
        C = scipy.sparse.diags(np.where(on, w, 0.0)) @ Gg + scipy.sparse.diags(np.where(on, g, 0.0)) @ Gw
        QZC = L.QT @ (L.Z @ C)
        change = QZC + QZC.T + C.T @ (L.N @ C)
        if curvature:
            M = Gw.T @ scipy.sparse.diags(mu) @ Gg
            change = change + M + M.T
        self._add_to(H, change)

    def pinned_values(self, up: np.ndarray, active: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For the pairs ``keys`` (sorted, held on a contact switch by statics) at patch values
        ``up`` with the piece ``active``: their gaps g_p and the normal force r_p = -w_p z_p .
        (a + delta_a) each would carry in contact (the jump of -dV/dg_p across g_p = 0), on every
        process (collective: g from the owner of the pair's first facet, r summed over rows)."""
        c = self.contact
        g, w, _ = c.gaps_and_overlaps(np.arange(len(c.listed)), *c.pair_displacements(up))
        on = np.isin(self.contact.pair_keys(), active) & (w > 0)
        L = self.contact.listed
        m = L.ZT @ (L.Q @ up + self.contact.row_lift + L.Z @ np.where(on, w * g, 0.0))
        k = np.searchsorted(keys, self.contact.pair_keys())
        listed = (k < len(keys)) & (keys[np.minimum(k, len(keys) - 1)] == self.contact.pair_keys())
        decider = listed & (L.i < self.contact.num_own)
        out = np.zeros((2, len(keys)))
        out[0, k[decider]] = g[decider]
        np.add.at(out[1], k[listed], -(w * m)[listed])
        self.contact.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out[0], out[1]

    def _switches_crossed(self, up: np.ndarray, dp: np.ndarray, alpha: float, piece: np.ndarray) -> np.ndarray:
        """Sorted keys (every process; collective) of the overlapping pairs whose gap, affine
        along the step u + tau d (patch values ``up``, ``dp``), reaches its switch g = 0 for some
        tau in [0, 2 alpha], leaving its side: closing if out of ``piece``, opening if in it."""
        g, w, _ = self.contact.gaps_and_overlaps(
            np.arange(len(self.contact.listed)), *self.contact.pair_displacements(up)
        )
        L, d = self.contact.listed, self.contact.d
        dd = (self.contact.pair_list.R @ dp).reshape(-1, d)
        rate = np.einsum("pi,pi->p", dd[L.j] - dd[L.i], L.n)
        inside = np.isin(self.contact.pair_keys(), piece)
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = np.where(rate != 0, -g / rate, np.inf)
        leaving = np.where(inside, rate > 0, rate < 0)
        mine = (L.i < self.contact.num_own) & (w > 0) & leaving & (tau >= 0) & (tau <= 2 * alpha)
        return np.sort(np.concatenate(self.contact.comm.allgather(self.contact.pair_keys()[mine])))

    def kink_forces(self, keys: np.ndarray, forces: np.ndarray) -> np.ndarray:
        """This process's part (sum over processes) of the force between each pair of
        ``body_pairs`` (as ``pair_forces``) carried by the pairs ``keys`` that statics holds on
        their switch g = 0 with the normal contact forces ``forces`` (-mu_p >= 0): -mu_p n on the
        first facet's body, whose gap gradient is -n for its rigid shift."""
        L, F = self.contact.listed, self.contact.facets_all
        k = np.searchsorted(keys, self.contact.pair_keys())
        mine = (k < len(keys)) & (L.i < self.contact.num_own)
        mine[mine] = keys[k[mine]] == self.contact.pair_keys()[mine]
        out = np.zeros((len(self.contact.body_pairs), self.contact.d))
        body_i, body_j = F.body[L.i[mine]], F.body[L.j[mine]]
        force_i = -forces[k[mine], None] * L.n[mine]
        sign = np.where(body_i < body_j, 1.0, -1.0)
        np.add.at(out, self.contact.body_pair_index[body_i, body_j], sign[:, None] * force_i)
        return out

    def gap_gradient(self, up: np.ndarray, key: int) -> PETSc.Vec:
        """grad g_p of the pair ``key`` as a distributed vector (collective: added by the owner
        of its first facet; g_p is affine in u, its gradient the same everywhere)."""
        vec = self.contact.dem.create_vector()
        row = np.zeros(len(self.contact.scatter))
        p = np.flatnonzero((self.contact.pair_keys() == key) & (self.contact.listed.i < self.contact.num_own))
        if len(p):
            Gg = self._piece_derivatives(up, np.zeros(0, dtype=np.int64))[0]
            row = Gg[p[0]].toarray().ravel()
        self.contact.scatter.add(row, vec)
        return vec

    def _add_to(self, H: PETSc.Mat, C) -> None:
        """H += C, C a (patch, patch) sparse matrix, at the patch's global dofs."""
        C = scipy.sparse.csr_matrix(C)
        C.eliminate_zeros()
        dofs = self.contact.scatter.dofs
        for i in np.flatnonzero(np.diff(C.indptr)):
            lo, hi = C.indptr[i], C.indptr[i + 1]
            H.setValues([int(dofs[i])], dofs[C.indices[lo:hi]], C.data[lo:hi], addv=PETSc.InsertMode.ADD_VALUES)
