"""Frictionless contact between deformable bodies (paper §3.4, eq. (22)-(34)), 2D.

Candidate facets are declared boundary facets; out of contact they keep their free
reconstruction u_f^free = R_f u (+ D_f g): u_c for scheme B facets (the facet translates with its
cell), the traction-free value of eq. (19)-(21) for scheme A facets. For two candidate facets f
and f' of facing orientation, the common normal and the normal penetration (eq. (22), (30)) are

    n = (|f| n_f - |f'| n_f') / || |f| n_f - |f'| n_f' ||   (normalised; n_f, n_f' outward),
    g = (x_f' + u_f'^free - x_f - u_f^free) . n,             affine in u,

and the overlap w = |f cap f'| is the length of the intersection of the two facets, displaced by
their free values and projected on the tangent t of n: piecewise affine in u. The contact
reconstruction (eq. (31)) is, with g^- = min(g, 0),

    u_f = u_f^free + sum_{f'} (w / |f|) g^- e_f,      u_f' = u_f'^free + sum_f (w / |f'|) g^- e_f',

with e_f = n/2, e_f' = -n/2 for scheme B (eq. (26)-(27), theta = 1/2), and for two scheme A
facets the directions of eq. (23)-(24) where they are well posed (equal normal changes of the two
tractions on n; the scheme B rule otherwise, counted; see ``PairContact._directions``). It equals
the free one when g = 0 or w = 0, so the energy is continuous (§3.4.3). Writing the energy rows a = Q u + q (Q = [S; J]) and
z_p = Q_f e_f / |f| + Q_f' e_f' / |f'| for a pair p, the rows change by delta_a = sum_p c_p z_p
with c_p = w_p g_p^-, so that

    V = 1/2 |a + delta_a|^2,     -dV/du = -Q^T (a + delta_a) - sum_p (z_p . (a + delta_a)) dc_p/du,
    dc_p/du = w_p dg_p/du + g_p dw_p/du      (on pairs with g_p < 0),

the exact gradient; g_p dw_p/du is the sliding force F^G of eq. (34). Along a MEMM free flight
u + tau v, g_p and the four facet-end projections are affine in tau: c_p is a quadratic and the
force correction a cubic between the events where a gap changes sign or a facet end crosses the
end of the other facet's projection (paper §4). The force integral is split at those events and
integrated by 2-point Gauss-Legendre on each piece, which is exact for cubics: the pseudo-energy
is conserved to rounding.

Broad phase: pairs are listed (a Verlet list built with a k-d tree on the displaced facet
centres) when the centres are closer than r = max|f| + skin; the list is rebuilt when a candidate
facet has moved more than skin/2 since the last build, so a pair that is not listed cannot touch.
The check is ``prepare(u, v, dt)``, which MEMM calls before every step's force integral whatever
its quadrature (both ends of the affine flight); every evaluation checks that the list is valid
for its displacements and raises otherwise (never a silently incomplete list); so does a step
that moves a facet by more than skin/2. Cost per step: the gaps of the listed pairs, and on
steps with contact the energy rows those pairs touch (the listed patch), not all boundary
facets. Everything is local to the contact patch and computed from gathered patch values on
every process (as contact.RigidContact).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse
import scipy.spatial
from petsc4py import PETSc

from dolfinx_dem.contact import gather_patch

#: Gauss-Legendre 2-point nodes on [0, 1]: exact for the cubic force correction on each piece.
_GL2 = 0.5 + np.array([-0.5, 0.5]) / np.sqrt(3.0)


class PairContact:
    """Contact between candidate facets of a 2D DEMDiscretisation; see the module docstring.

    Parameters
    ----------
    dem : DEMDiscretisation (2D); the candidate facets must be Neumann (boundary) facets.
    facets : process-local indices of the candidate boundary facets (the contact boundaries).
    self_contact : also pair facets of the same body (never facets that share a vertex).
    skin : Verlet-list margin (m), default the largest candidate facet length.
    tolerance : how far facets may interpenetrate at t = 0 (m).
    """

    def __init__(self, dem, facets, self_contact: bool = False, skin: float | None = None,
                 tolerance: float = 0.0):
        from dolfinx_dem import _compat

        geom, rec, ops, d = dem.geometry, dem.reconstruction, dem.operators, dem.d
        if d != 2:
            raise ValueError(f"contact between deformable bodies is implemented in 2D, not {d}D")
        self.dem, self.comm, self.d = dem, dem.comm, d
        f = np.unique(np.concatenate(self.comm.allgather(
            _compat.local_facet_global_indices(dem.mesh, np.asarray(facets, dtype=np.int32)))))
        if f.size == 0:
            raise ValueError("the contact boundary has no facet (check its tag)")
        if (geom.facet_cells[f, 1] >= 0).any():
            bad = f[geom.facet_cells[f, 1] >= 0][0]
            raise ValueError(f"contact facets must be boundary facets; facet {bad} at "
                             f"{geom.facet_centres[bad].tolist()} is interior")
        if np.isin(f, rec.dirichlet_facets).any():
            raise ValueError("contact facets must not carry a Dirichlet condition")
        if dem._time_dependent:
            raise ValueError("contact with time-dependent Dirichlet conditions is not supported")
        if not (np.isfinite(tolerance) and tolerance >= 0):
            raise ValueError(f"the penetration tolerance must be >= 0, got {tolerance}")
        _check_bodies_share_no_vertex(geom, dem.body_labels)
        _check_bodies_do_not_overlap(geom, dem.body_labels)
        self.facets = f
        self.cells = cells = geom.facet_cells[f, 0]
        self.bodies = dem.body_labels[cells]
        self.self_contact = bool(self_contact)
        self.tolerance = float(tolerance)
        an = geom.facet_area_normals[cells, geom.facet_local[f, 0]]
        self.lengths = np.linalg.norm(an, axis=1)
        self.normals = an / self.lengths[:, None]
        self.centres = geom.facet_centres[f]
        mask = np.ones((len(f), d + 1), dtype=bool)
        mask[np.arange(len(f)), geom.facet_local[f, 0]] = False
        self.vertices = geom.cell_vertices[cells][mask].reshape(len(f), d, d)  # (nf, 2 ends, d)
        self.skin = float(self.lengths.max() if skin is None else skin)
        if not self.skin > 0:
            raise ValueError(f"the Verlet skin must be > 0, got {skin}")
        self.radius = float(self.lengths.max()) + self.skin

        # Energy rows touched by the candidate facets' values, and the contact patch.
        nf = len(f)
        dofs = (f[:, None] * d + np.arange(d)).ravel()
        QF = scipy.sparse.vstack([ops.S_facet[:, dofs], ops.J_facet[:, dofs]]).tocsr()
        rows = np.unique(QF.tocoo().row)
        Q = scipy.sparse.vstack([ops.S, ops.J]).tocsr()
        g = dem.dirichlet_values(0.0).ravel()
        q = np.concatenate([ops.S_dirichlet @ g, ops.J_dirichlet @ g])
        R = rec.R[dofs]
        # The dofs any contact of these facets can involve (global dof numbers); a step only
        # gathers the part of it it needs (the patch, see _set_patch).
        self._universe = np.unique(np.concatenate([Q[rows].indices, R.indices]))
        self._Q = Q[rows][:, self._universe].tocsr()
        self._q = q[rows]
        self._QF = QF[rows].tocsc()  # (rows, nf d); columns are sliced at list builds
        self._is_elastic_row = rows < ops.S.shape[0]
        # Free reconstructions u_f = R_f u + D_f g of the candidates (u_c for scheme B facets).
        self._R_universe = R[:, self._universe].tocsr()
        self._kinematic = np.unique(self._R_universe.indices)  # positions in the universe
        self._R_lift = (rec.D[dofs] @ g).reshape(nf, d)
        self._grad_weights = an / geom.cell_volumes[cells, None]
        self.is_scheme_a = np.isin(f, rec.scheme_a_facets)
        if self.is_scheme_a.any():
            C = dem.material.elasticity_tensor(d)
            # A_f x = (C : (x (x) a_f)) n / |c| for the pair's normal n: einsum with C and a_f.
            self._Ca = np.einsum("ijkl,nl->nijk", C, an) / geom.cell_volumes[cells, None, None, None]
        self.evaluations = 0
        self.rebuilds = 0
        self._scheme_b_rule = np.empty(0, dtype=np.int64)  # pair keys i * n_facets + j, see _directions
        self.seconds = 0.0  # processor time of the contact work in force integrals and energies
        self._reference = None  # candidate cell displacements at the last list build
        zero = np.zeros((len(f), d))
        self._build_pairs(zero)
        g0, w0 = self.listed.gaps(zero), self.listed.overlaps(zero)[0]
        deep = (g0 < -self.tolerance) & (w0 > 0)
        if deep.any():
            k = int(np.argmin(np.where(deep, g0, np.inf)))
            i, j = self.listed.i[k], self.listed.j[k]
            raise ValueError(f"bodies {self.bodies[i]} and {self.bodies[j]} overlap at t = 0: facets at "
                             f"{self.centres[i].tolist()} and {self.centres[j].tolist()} interpenetrate by "
                             f"{-g0[k]:.3e} m (tolerance {self.tolerance:g} m)")

    # -- broad phase ---------------------------------------------------------------------------
    def _build_pairs(self, uc: np.ndarray):
        """The Verlet list of facing facet pairs with centres closer than ``radius``, for the
        candidate cell displacements ``uc`` (n_facets, d)."""
        tree = scipy.spatial.cKDTree(self.centres + uc)
        pairs = tree.query_pairs(self.radius, output_type="ndarray")
        i, j = pairs[:, 0], pairs[:, 1]
        keep = np.einsum("pi,pi->p", self.normals[i], self.normals[j]) < 0  # facing facets only
        same = self.bodies[i] == self.bodies[j]
        if self.self_contact:
            shared = (np.abs(self.vertices[i][:, :, None] - self.vertices[j][:, None]).sum(-1) == 0).any((1, 2))
            keep &= ~(same & shared)
        else:
            keep &= ~same
        i, j = i[keep], j[keep]
        n = self.lengths[i, None] * self.normals[i] - self.lengths[j, None] * self.normals[j]
        n /= np.linalg.norm(n, axis=1)[:, None]
        t = np.stack([-n[:, 1], n[:, 0]], axis=1)
        e_i, e_j = self._directions(i, j, n)
        # z_p = Q_f e_f / |f| + Q_f' e_f' / |f'|: columns of a sparse (rows, P) matrix.
        P, d = len(i), self.d
        cols = np.repeat(np.arange(P), 2 * d)
        rows = np.concatenate([i[:, None] * d + np.arange(d), j[:, None] * d + np.arange(d)], axis=1).ravel()
        vals = np.concatenate([e_i / self.lengths[i, None], e_j / self.lengths[j, None]], axis=1).ravel()
        facets = np.unique(np.concatenate([i, j]))
        facet_dofs = (facets[:, None] * d + np.arange(d)).ravel()
        N = scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(len(self.facets) * d, P))[facet_dofs]
        Z = (self._QF[:, facet_dofs] @ N).tocsr()  # only the listed facets' columns: O(listed)
        # The listed patch: the energy rows the pairs touch and the patch dofs those rows and
        # the pairs' cells read. Contact work per step only involves these.
        rows = np.unique(Z.tocoo().row)
        Q = self._Q[rows]
        columns = np.unique(np.concatenate([Q.indices, self._R_universe[facet_dofs].indices]))
        self._set_patch(np.union1d(self._kinematic, columns))
        Q = Q[:, columns].tocsr()
        R = self._R_universe[:, columns].tocsr()
        columns = np.searchsorted(self._patch_in_universe, columns)  # now positions in the patch
        self.listed = _Pairs(
            i=i, j=j, n=n, t=t, e_i=e_i, e_j=e_j,
            d0=np.einsum("pi,pi->p", self.centres[j] - self.centres[i], n),
            si=np.sort(np.einsum("pki,pi->pk", self.vertices[i], t), axis=1),  # (P, 2): lo, hi
            sj=np.sort(np.einsum("pki,pi->pk", self.vertices[j], t), axis=1),
            patch=_ListedPatch(
                columns=columns, Z=Z[rows], ZT=Z[rows].T.tocsr(), Q=Q, QT=Q.T.tocsr(), q=self._q[rows],
                elastic=self._is_elastic_row[rows], RT=R.T.tocsr(), local=self._patch_local[columns]),
        )
        self._reference = uc.copy()
        self.rebuilds += 1

    def _set_patch(self, positions: np.ndarray):
        """The patch: the universe dofs at ``positions`` (the free reconstructions' dofs and the
        listed pairs' patch). ``patch_values`` gathers these; arrays of patch values are valid
        until the next list build."""
        self._patch_in_universe = positions
        self.patch = self._universe[positions]
        self._R = self._R_universe[:, positions].tocsr()
        start, stop = self.dem.cell_range
        d = self.d
        self._owned = (self.patch >= start * d) & (self.patch < stop * d)
        self._owned_local = (self.patch[self._owned] - start * d).astype(np.int32)
        self._patch_local = np.full(len(self.patch), -1, dtype=np.int32)  # patch -> local dof
        self._patch_local[self._owned] = self._owned_local

    def _directions(self, i: np.ndarray, j: np.ndarray, n: np.ndarray):
        """The contact corrections of a pair are u_f += (w/|f|) g^- e_f, u_f' += (w/|f'|) g^- e_f'.

        Scheme B (eq. (26)-(27), theta = 1/2): e_f = n/2, e_f' = -n/2. Scheme A (eq. (23)-(24)),
        when both facets are scheme A facets: with A_f x = (C : (x (x) a_f)) n / |c| the change
        of cell c's traction on n when u_f changes by x, e_f = A_f^-1 n / D, e_f' = A_f'^-1 n / D,
        D = n . A_f^-1 n - n . A_f'^-1 n: the corrections change both cells' tractions on n by
        the same normal vector, and n . (e_f - e_f') = 1 closes the gap of a fully overlapping
        pair. (The tractions on n themselves are normal and equal only where the free ones
        vanish on n, i.e. when n = n_f = -n_f': the free facets carry zero traction on their
        own normals.)

        When eq. (23)-(24) are not well posed the pair uses the scheme B rule; ``scheme_b_pairs``
        counts such pairs (``summary.json``: ``contact_pairs_scheme_b_rule``). For isotropic C,
        n . A_f^-1 n = cos t_f / (alpha_f (2 cos^2 t_f (lambda + mu) - lambda)), alpha_f = |f|/|c|,
        t_f the angle between n and n_f: a cell's normal compliance has the sign of its facet
        normal's side only if cos^2 t_f > kappa = lambda / (2 (lambda + mu)) (nu in plane
        strain, nu/(1+nu) in plane stress). The rule of eq. (23)-(24) is used when both cells'
        compliances have their sign (n . A_f^-1 n > 0 > n . A_f'^-1 n): then 0 < n . e_f < 1,
        0 < -n . e_f' < 1 and |e_f| = n . e_f / cos t_f < 1/sqrt(kappa), bounded. Otherwise
        D may vanish (unbounded corrections, an arbitrarily stiff pair), be negative (no
        solution: the correction would open the penetration further), or be positive with one
        facet moved further into the other body. Facing facets of equal length have
        t_f = t_f' < 45 deg, and kappa < 1/2, so only pairs of unequal facets whose normals are
        far from antiparallel (the longer facet tilts n towards its own normal) are affected.
        A set-up check cannot replace this rule: every pair of facing candidate facets could
        meet, and a curved boundary has facets of every orientation. The directions depend on
        the pair only, so the energy stays continuous and the force its exact gradient."""
        e_i, e_j = 0.5 * n, -0.5 * n
        both_a = self.is_scheme_a[i] & self.is_scheme_a[j]
        if both_a.any():
            k = np.flatnonzero(both_a)
            # A_f^-1 n = adj(A_f) n / det(A_f) (2D), so that a singular A_f is no error.
            y, compliance = [], []
            for f in (i, j):
                A = np.einsum("nijk,nj->nik", self._Ca[f[k]], n[k])
                adj_n = np.stack([A[:, 1, 1] * n[k, 0] - A[:, 0, 1] * n[k, 1],
                                  A[:, 0, 0] * n[k, 1] - A[:, 1, 0] * n[k, 0]], axis=1)
                det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
                y.append(np.divide(adj_n, det[:, None], out=np.zeros_like(adj_n), where=det[:, None] != 0))
                compliance.append(np.where(det != 0, np.einsum("pi,pi->p", n[k], y[-1]), 0.0))
            posed = (compliance[0] > 0) & (compliance[1] < 0)
            D = compliance[0] - compliance[1]
            a = k[posed]
            e_i[a], e_j[a] = y[0][posed] / D[posed, None], y[1][posed] / D[posed, None]
            self._scheme_b_rule = np.union1d(self._scheme_b_rule, i[k[~posed]] * len(self.facets) + j[k[~posed]])
        return e_i, e_j

    @property
    def scheme_b_pairs(self) -> int:
        """How many distinct pairs of scheme A facets listed so far use the scheme B rule
        because eq. (23)-(24) are not well posed for them (see ``_directions``)."""
        return len(self._scheme_b_rule)

    def prepare(self, u: PETSc.Vec, v: PETSc.Vec | None = None, dt: float = 0.0) -> None:
        """Make the Verlet list valid for the states u + tau v, 0 <= tau <= dt (u alone without
        v): rebuild it at u if a candidate facet would move more than skin/2 from where it was
        at the last build. The free facet displacements are affine in tau, so checking both ends
        covers the whole flight. ``MEMM`` calls this before every step's force integral,
        whatever the quadrature, and at ``initialise``; call it before evaluating forces or
        energies at displacements of your own. Collective. Arrays of patch values gathered
        before a rebuild are invalid after it."""
        start = time.process_time()
        up = self.patch_values(u)
        uc = self.free_displacements(up)
        stale = self._stale(uc)
        moving = v is not None and dt != 0.0
        if moving:
            step = dt * (self._R @ self.patch_values(v)).reshape(-1, self.d)
            stale = stale or self._stale(uc + step)
        if stale:
            self._build_pairs(uc)
            if moving and self._stale(uc + step):
                raise RuntimeError(
                    f"contact between bodies: a candidate facet moves {np.linalg.norm(step, axis=1).max():.3e} m "
                    f"in one step, more than half the Verlet skin ({self.skin:.3e} m): no pair list covers the "
                    "step; reduce the time step or pass a larger skin")
        self.seconds += time.process_time() - start

    def _stale(self, uc: np.ndarray) -> bool:
        """Whether a candidate facet with free displacements ``uc`` has moved more than skin/2
        since the last list build (a pair not listed might then touch)."""
        moved = uc - self._reference
        return bool(np.einsum("ni,ni->n", moved, moved).max() > 0.25 * self.skin**2)

    def _check_listed(self, uc: np.ndarray):
        if self._stale(uc):
            raise RuntimeError("contact between bodies: the candidate pair list is stale for these displacements "
                               "(a facet moved more than skin/2 since it was built); call prepare(u) first "
                               "(MEMM does it every step)")

    # -- energy and force ----------------------------------------------------------------------
    def patch_values(self, vec: PETSc.Vec) -> np.ndarray:
        """Values of a distributed vector at the patch dofs, on every process."""
        return gather_patch(self.comm, vec, self._owned_local)

    def free_displacements(self, up: np.ndarray) -> np.ndarray:
        """Free reconstructions u_f of the candidates (their cells' u_c in scheme B), (n_facets, d),
        from patch values ``up``."""
        return (self._R @ up).reshape(-1, self.d) + self._R_lift

    def _touching(self, up: np.ndarray) -> _Pairs:
        """The listed pairs with g < 0."""
        L = self.listed
        uc = self.free_displacements(up)
        self._check_listed(uc)
        return L.subset(np.flatnonzero(L.gaps(uc) < 0))

    def energy_correction(self, up: np.ndarray) -> tuple[float, float]:
        """(elastic, stabilisation) energy changes from the contact reconstructions."""
        start = time.process_time()
        L, P = self.listed, self.listed.patch
        uc = self.free_displacements(up)
        self._check_listed(uc)
        g = np.minimum(L.gaps(uc), 0.0)
        elastic = stabilisation = 0.0
        if (g < 0).any():
            a = P.Q @ up[P.columns] + P.q
            delta = P.Z @ (L.overlaps(uc)[0] * g)
            change = a * delta + 0.5 * delta**2
            elastic, stabilisation = float(change[P.elastic].sum()), float(change[~P.elastic].sum())
        self.seconds += time.process_time() - start
        return elastic, stabilisation

    def force_correction(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """F - F_free at the patch dofs (N): the exact negative gradient of the energy change.
        An imposed ``active`` set belongs to statics, which this model does not support."""
        if active is not None:
            self._no_statics()
        out = np.zeros_like(up)
        P = self.listed.patch
        uc = self.free_displacements(up)
        self._check_listed(uc)
        out[P.columns] = self._correction(uc[..., None], up[P.columns, None])[:, 0]
        return out

    def _correction(self, uc: np.ndarray, U: np.ndarray) -> np.ndarray:
        """F - F_free on the listed patch for K states: free facet reconstructions uc
        (nf, d, K) and the listed patch's values U (n_columns, K); returns (n_columns, K)."""
        self.evaluations += U.shape[1]
        L, P = self.listed, self.listed.patch
        g = np.minimum(L.gaps(uc), 0.0)  # (P, K)
        out = np.zeros_like(U)
        if (g < 0).any():
            w, ds = L.overlaps(uc)
            a = P.Q @ U + P.q[:, None]
            delta = P.Z @ (w * g)
            mu = np.where(g < 0, P.ZT @ (a + delta), 0.0)
            out -= P.QT @ delta
            # dc/du_f' = w n - g ds_i t, dc/du_f = -(that); F -= R^T (mu dc/du_F).
            dc = mu[:, None] * (w[:, None] * L.n[..., None] - (g * ds)[:, None] * L.t[..., None])
            facet_force = np.zeros(uc.shape)
            np.add.at(facet_force, L.i, dc)
            np.add.at(facet_force, L.j, -dc)
            out += P.RT @ facet_force.reshape(-1, U.shape[1])
        return out

    def add(self, correction: np.ndarray, out: PETSc.Vec, scale: float = 1.0):
        """out += scale * correction on the owned patch dofs."""
        out.array[self._owned_local] += scale * correction[self._owned]

    # -- events --------------------------------------------------------------------------------
    def force_integral(self, u: PETSc.Vec, v: PETSc.Vec, dt: float, out: PETSc.Vec) -> int:
        """out += int_0^dt (F - F_free)(u + tau v) dtau, split at the events and integrated by
        2-point Gauss-Legendre on each piece; returns the number of patch force evaluations.

        Events (paper §4): for the pairs with g < 0 somewhere in the step, the times where g
        changes sign or a facet end crosses an end of the other facet (the kinks of w); all are
        roots of affine functions of tau."""
        start = time.process_time()
        up, vp = self.patch_values(u), self.patch_values(v)
        uc0, uc1 = self.free_displacements(up), self.free_displacements(up + dt * vp)
        self._check_listed(uc0)
        self._check_listed(uc1)
        L = self.listed
        g0, g1 = L.gaps(uc0), L.gaps(uc1)
        p = np.flatnonzero((g0 < 0) | (g1 < 0))
        if len(p) == 0:
            self.seconds += time.process_time() - start
            return 0
        pairs = L.subset(p)
        e0, e1 = pairs.crossings(uc0), pairs.crossings(uc1)
        values0, values1 = np.concatenate([g0[p], e0]), np.concatenate([g1[p], e1])
        crossing = values0 * values1 < 0
        tau = dt * values0[crossing] / (values0[crossing] - values1[crossing])
        tau = np.concatenate([[0.0], np.unique(tau[(tau > 0) & (tau < dt)]), [dt]])
        # All Gauss points of all pieces at once, as columns, on the listed patch.
        length = np.diff(tau)
        nodes = (tau[:-1, None] + _GL2[None, :] * length[:, None]).ravel()
        weights = np.repeat(0.5 * length, len(_GL2))
        P = L.patch
        U = up[P.columns, None] + vp[P.columns, None] * nodes
        UC = uc0[..., None] + (self._R @ vp).reshape(-1, self.d)[..., None] * nodes
        F = self._correction(UC, U) @ weights
        mine = P.local >= 0
        out.array[P.local[mine]] += F[mine]
        self.seconds += time.process_time() - start
        return 2 * (len(tau) - 1)

    # -- outputs -------------------------------------------------------------------------------
    def facet_corrections(self, up: np.ndarray) -> np.ndarray:
        """u_f - u_f^free of every candidate facet (eq. (31), directions of ``_directions``),
        shape (n_facets, d)."""
        pairs = self._touching(up)
        uc = self.free_displacements(up)
        c = pairs.overlaps(uc)[0] * pairs.gaps(uc)
        delta = np.zeros((len(self.facets), self.d))
        np.add.at(delta, pairs.i, (c / self.lengths[pairs.i])[:, None] * pairs.e_i)
        np.add.at(delta, pairs.j, (c / self.lengths[pairs.j])[:, None] * pairs.e_j)
        return delta

    def gradient_correction(self, up: np.ndarray) -> np.ndarray:
        """Change of the gradient (eq. (8)) of each candidate's cell, shape (n_facets, d, d)."""
        return np.einsum("ni,nj->nij", self.facet_corrections(up), self._grad_weights)

    def penetration(self, up: np.ndarray) -> float:
        """Largest interpenetration (m, >= 0) of the contact-aware facet reconstructions: over the
        candidate facets, the overlap-weighted mean over their partners of the reconstructed gap
        (x_f' + u_f' - x_f - u_f) . n, negated. Eq. (31) makes it zero when each facet has one
        partner covering it exactly; partial overlaps (facets sliding against each other) leave a
        gap of the order of the cell gap times the uncovered fraction."""
        uc = self.free_displacements(up)
        self._check_listed(uc)
        w = self.listed.overlaps(uc)[0]
        if not (w > 0).any():
            return 0.0
        pairs = self.listed.subset(np.flatnonzero(w > 0))
        w = w[w > 0]
        uf = uc + self.facet_corrections(up)
        i, j = pairs.i, pairs.j
        gap = np.einsum("pi,pi->p", self.centres[j] + uf[j] - self.centres[i] - uf[i], pairs.n)
        nf = len(self.facets)
        weight = np.bincount(i, w, nf) + np.bincount(j, w, nf)
        mean = np.bincount(i, w * gap, nf) + np.bincount(j, w * gap, nf)
        touched = weight > 0
        return float(max(0.0, -(mean[touched] / weight[touched]).min()))

    def touching(self, up: np.ndarray) -> bool:
        """Whether some pair is in contact (g < 0 with a positive overlap)."""
        uc = self.free_displacements(up)
        self._check_listed(uc)
        return bool(((self.listed.gaps(uc) < 0) & (self.listed.overlaps(uc)[0] > 0)).any())

    def touch_time(self, uc0: np.ndarray, uc1: np.ndarray, dt: float) -> float | None:
        """For a step between the free facet displacements ``uc0`` (no contact) and ``uc1``
        (``free_displacements``): the time tau in [0, dt] at which the first pair touching at
        the end closed its gap (gaps are affine along the step); None if no pair touches."""
        L = self.listed
        g0, g1 = L.gaps(uc0), L.gaps(uc1)
        touching = (g1 < 0) & (L.overlaps(uc1)[0] > 0)
        if not touching.any():
            return None
        g0, g1 = np.maximum(g0[touching], 0.0), g1[touching]
        return float(dt * (g0 / (g0 - g1)).min())

    def contact_force(self, up: np.ndarray) -> float:
        """Sum over touching pairs of the normal contact force magnitude (N, per unit thickness):
        |(z_p . (a + delta_a)) w_p|, the force one facet of the pair exerts on the other."""
        L, P = self.listed, self.listed.patch
        uc = self.free_displacements(up)
        self._check_listed(uc)
        g = np.minimum(L.gaps(uc), 0.0)
        w = L.overlaps(uc)[0]
        a = P.Q @ up[P.columns] + P.q
        return float(np.abs(np.where(g < 0, P.ZT @ (a + P.Z @ (w * g)), 0.0) * w).sum())

    # -- statics (ContactModel): not supported --------------------------------------------------
    def _no_statics(self):
        raise NotImplementedError("statics with contact between bodies is not supported: its energy is not "
                                  "piecewise quadratic (the overlaps make it quartic in u)")

    def gaps(self, up: np.ndarray) -> np.ndarray:
        self._no_statics()

    def gap_gradients(self, facets: np.ndarray) -> np.ndarray:
        self._no_statics()

    def reactions(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        self._no_statics()

    def add_hessian_correction(self, active: np.ndarray, H: PETSc.Mat) -> None:
        self._no_statics()

    # -- checkpoint (ContactModel) ----------------------------------------------------------------
    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """The pair list, as the candidate displacements it was built at (``reference``, rows in
        the order of ``centres``, the facet barycentres), the pairs of scheme A facets that used
        the scheme B rule (rows of two facet positions), and the counters."""
        nf = len(self.facets)
        return {
            "centres": self.centres,
            "reference": self._reference,
            "scheme_b_rule": np.stack([self._scheme_b_rule // nf, self._scheme_b_rule % nf], axis=1),
            "counters": np.array([self.rebuilds, self.evaluations], dtype=np.int64),
            "seconds": np.array([self.seconds]),
        }

    def restore_state(self, state) -> None:
        """Rebuild the list at the stored ``reference`` (the same list on the same facets), the
        facets matched by barycentre (another process count numbers them differently)."""
        from dolfinx_dem.matching import match_points

        index = match_points(state["centres"], self.centres, 1e-9 * self.lengths.min())
        position = np.empty_like(index)
        position[index] = np.arange(len(index))  # stored facet -> this model's facet
        self._build_pairs(np.asarray(state["reference"])[index])
        pairs = np.sort(position[np.asarray(state["scheme_b_rule"], dtype=np.int64)], axis=1)
        self._scheme_b_rule = np.unique(pairs[:, 0] * len(self.facets) + pairs[:, 1])
        self.rebuilds, self.evaluations = (int(x) for x in state["counters"])
        self.seconds = float(state["seconds"][0])


@dataclasses.dataclass(frozen=True)
class _ListedPatch:
    """The part of the contact patch the listed pairs touch: patch dofs ``columns``, the energy
    rows (Q, QT = Q^T, q, which are elastic rows) restricted to them, the columns z_p of
    Z (and ZT), RT = R^T of the candidates' free reconstructions on ``columns``, and the
    process-local dof of each column (-1 if another process owns it)."""

    columns: np.ndarray
    Z: scipy.sparse.csr_matrix
    ZT: scipy.sparse.csr_matrix
    Q: scipy.sparse.csr_matrix
    QT: scipy.sparse.csr_matrix
    q: np.ndarray
    elastic: np.ndarray
    RT: scipy.sparse.csr_matrix
    local: np.ndarray


@dataclasses.dataclass(frozen=True)
class _Pairs:
    """Facet pairs (f_i, f_j) of the Verlet list, vectorised: the common normal n and tangent t,
    the correction directions e_i, e_j (``PairContact._directions``), the reference gap d0, the
    tangential facet ends si, sj (lo, hi), and (for the whole list) the listed patch."""

    i: np.ndarray
    j: np.ndarray
    n: np.ndarray
    t: np.ndarray
    e_i: np.ndarray
    e_j: np.ndarray
    d0: np.ndarray
    si: np.ndarray
    sj: np.ndarray
    patch: _ListedPatch | None = None

    def __len__(self) -> int:
        return len(self.i)

    def subset(self, p: np.ndarray) -> _Pairs:
        """The pairs ``p`` (without Z)."""
        return _Pairs(self.i[p], self.j[p], self.n[p], self.t[p], self.e_i[p], self.e_j[p], self.d0[p],
                      self.si[p], self.sj[p])

    def gaps(self, uc: np.ndarray) -> np.ndarray:
        """g = d0 + (u_c' - u_c) . n for candidate cell displacements uc, shape (nf, d) or
        (nf, d, K) for K states; returns (P,) or (P, K)."""
        x = np.einsum("pi...,pi->p...", uc[self.j] - uc[self.i], self.n)
        return (self.d0 if x.ndim == 1 else self.d0[:, None]) + x

    def ends(self, uc: np.ndarray):
        """Tangential facet ends (lo_i, hi_i, lo_j, hi_j), displaced by their cells."""
        ti = np.einsum("pi...,pi->p...", uc[self.i], self.t)
        tj = np.einsum("pi...,pi->p...", uc[self.j], self.t)
        si, sj = (self.si, self.sj) if ti.ndim == 1 else (self.si[:, None], self.sj[:, None])
        return si[..., 0] + ti, si[..., 1] + ti, sj[..., 0] + tj, sj[..., 1] + tj

    def overlaps(self, uc: np.ndarray):
        """w and its slope ds_i: dw/du_c = ds_i t, dw/du_c' = -ds_i t (0 without overlap)."""
        lo_i, hi_i, lo_j, hi_j = self.ends(uc)
        w = np.minimum(hi_i, hi_j) - np.maximum(lo_i, lo_j)
        ds_i = (hi_i <= hi_j).astype(float) - (lo_i >= lo_j).astype(float)
        inside = w > 0
        return np.where(inside, w, 0.0), np.where(inside, ds_i, 0.0)

    def crossings(self, uc: np.ndarray) -> np.ndarray:
        """The differences of facet ends whose sign changes are the kinks of w, (4 P,)."""
        lo_i, hi_i, lo_j, hi_j = self.ends(uc)
        return np.concatenate([hi_i - hi_j, lo_i - lo_j, hi_i - lo_j, hi_j - lo_i])


def _check_bodies_do_not_overlap(geom, labels: np.ndarray):
    """No boundary vertex of a body may lie strictly inside a cell of another body (in the
    reference configuration): point-in-simplex tests against the cells near each vertex."""
    d = geom.d
    bf = geom.boundary_facets
    cells, local = geom.facet_cells[bf, 0], geom.facet_local[bf, 0]
    mask = np.ones((len(bf), d + 1), dtype=bool)
    mask[np.arange(len(bf)), local] = False
    points = geom.cell_vertices[cells][mask].reshape(-1, d)
    bodies = np.repeat(labels[cells], d)
    radius = np.linalg.norm(geom.cell_vertices - geom.cell_centres[:, None], axis=2).max()
    near = scipy.spatial.cKDTree(points).sparse_distance_matrix(
        scipy.spatial.cKDTree(geom.cell_centres), radius, output_type="ndarray")
    k, c = near["i"], near["j"]
    other = labels[c] != bodies[k]
    k, c = k[other], c[other]
    if len(k) == 0:
        return
    v = geom.cell_vertices[c]  # (m, d+1, d)
    lam = np.linalg.solve(np.swapaxes(v[:, 1:] - v[:, :1], 1, 2), (points[k] - v[:, 0])[..., None])[..., 0]
    lam = np.concatenate([1 - lam.sum(axis=1, keepdims=True), lam], axis=1)
    inside = lam.min(axis=1) > 1e-10
    if inside.any():
        m = int(np.flatnonzero(inside)[0])
        raise ValueError(f"bodies {bodies[k[m]]} and {labels[c[m]]} overlap at t = 0: a boundary vertex of body "
                         f"{bodies[k[m]]} at {points[k[m]].tolist()} lies inside body {labels[c[m]]}")


def _check_bodies_share_no_vertex(geom, labels: np.ndarray):
    """Separate bodies (connected through facets) must not share a vertex: contact between them
    would be undefined at the shared point."""
    d = geom.d
    x = geom.cell_vertices.reshape(-1, d)
    body = np.repeat(labels, d + 1)
    _, vertex = np.unique(x, axis=0, return_inverse=True)
    pairs = np.unique(np.stack([vertex.ravel(), body], axis=1), axis=0)
    counts = np.bincount(pairs[:, 0])
    if (counts > 1).any():
        k = int(np.flatnonzero(counts > 1)[0])
        point = x[np.flatnonzero(vertex.ravel() == k)[0]]
        raise ValueError(f"bodies share the vertex {point.tolist()}: bodies in contact must be meshed "
                         "separately (no common vertex)")
