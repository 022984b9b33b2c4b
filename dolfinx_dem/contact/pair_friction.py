"""Coulomb friction between bodies (pair.py), with an exact energy balance (docs/theory.md,
"Friction between bodies").

As on rigid obstacles (friction.py), a frictional impulse T^n over the step changes the MEMM
pseudo-energy by v^{n+1/2} . T^n, and D^{n+1} = D^n - v^{n+1/2} . T^n keeps E + D - W constant to
rounding whatever T^n is. Each listed pair p (facet i of cell c, facet j of cell c', the pair's
unit normal n from i to j) carries the normal impulse N_p = int -mu_p w_p dtau that facet i exerts
on facet j over the step (the normal part of the pair's force term, from the step's exact force
integral) and a lagged normal force Ntilde_p, which follows N_p^+ / dt with the time scale 2 h_i /
c_i as the obstacles' does (pair_lag.py: the bound does not see the step's own N_p, and a pair
that separated for a few steps keeps a decaying one). It gives +tau_p to cell c and -tau_p to cell
c' (the total linear momentum is unchanged), tau_p in

    K_p = {tau : tau . n = 0, |tau| <= mu Ntilde_p dt, tau . w_p <= 0},   w_p = P_n (v_c - v_c')^{n+1/2},

so that the pair's dissipation -w_p . tau_p is non-negative and sum_p -w_p . tau_p = -v^{n+1/2} . T^n.
The impulses are those of K = prod K_p closest to sticking: they minimise the cells' kinetic
energy after the step over K, up to a constant twice the quadratic
q(tau) = sum_p tau_p . (r_p + w_p^{after}(tau)) / 2, r_p = P_n (v_c - v_c')^{n+3/2, free},
whose gradient is each pair's relative tangential velocity after the step w_p^{after} = P_n (v_c
- v_c')^{n+3/2} (its Hessian is the pairs' Delassus operator A = 2 P B^T M^-1 B P, T = B tau the
cells' summed impulses). The minimiser's T is unique (q is strictly convex in T), and a pair
strictly inside K_p has w_p^{after} = 0: it sticks. They come from
accelerated projected gradient rounds (APGD: Nesterov's method with adaptive restart, Mazhar,
Heyn, Negrut and Tasora, ACM TOG 34(3), 2015) in the metric of the split masses (Tonge,
Benevolenski and Voroshilov, ACM TOG 31, 2012), from tau = x = y = 0:

    x' = proj_K(y - w^{after}(y) / D),   D_p = 2 (k_c / m_c + k_c' / m_c'),
    y = x' + beta (x' - x),   beta from Nesterov's sequence theta, reset to 0 (theta = 1) when
    sum_p D_p (y_p - x'_p) . (x'_p - x_p) > 0 (the gradient restart of O'Donoghue and Candes,
    Found. Comput. Math. 15, 2015: the step turns against the last move),

k_c the number of touching pairs of cell c. D_p majorises A (Gershgorin: its rows' sums of
|2 P_n P_n' / m| are at most D_p), so 1/D is a safe step and the projection in the metric of D is
each pair's own projection onto K_p. Plain projected Jacobi rounds (beta = 0) contract by 1 -
lambda_min(D^-1 A) per round, about 0.96 on a non-matching interface (a chain of pairs along it
whose Delassus operator is a path graph's); the acceleration makes that about 1 - sqrt(lambda_min)
(docs/theory.md measures the rounds). Every round is a function of the previous ones' impulses and
of global sums of scalars: no Gauss-Seidel order of the pairs (which would need a
partition-independent colouring), so the result does not depend on the partition beyond rounding
(the restart's sum is formed in a partition-dependent order: a decision at a sum within rounding of
0 can differ, which moves the impulses by the tolerance below). The returned impulses are the last
projection x', in K: every pair's dissipation is non-negative whatever the rounds did.

The rounds stop when every pair's projected gradient step from x', D_p |proj_{K_p}(x'_p -
w_p^{after}(x') / D_p) - x'_p| (for a stuck pair its relative velocity after the step), is below
``CONVERGED`` times the pair's stick threshold, ``STICK_ROUNDING`` times the sum of its cells'
velocities' sizes (one Allreduce per round sums the pairs above it, exactly, and the restart's sum;
the stop is then exact stick: the next step, whose threshold is of the same size, sees the pair's
relative velocity w_p below it, and the half-space tau . w_p <= 0 does not act on it;
a looser stop leaves stuck pairs a residual w_p above it, and the half-space then releases those
whose stick impulse points along it, measured as a creep in docs/theory.md), or after
``MAX_ROUNDS`` (counted: ``unconverged``; the balance holds all the same, the stick is then not
exact). A pair alone on its cells gets the obstacle law's answer in the first round, and the
rounds stop there when all pairs are alone.

Distributed: the pair is handled by the owner of its facet i (the facet of the smaller global
number); the processes that list it send their own rows' parts of N_p there. The velocities of the
cells of the known facets come by a scatter (``PatchScatter``) remade with the pair list's, the
rounds' impulses reach the cells' owners by its reverse scatter and come back by its forward one.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from dolfinx_dem.contact.friction import STICK_ROUNDING, project, scheme_b_candidates, warn_scheme_b_spin
from dolfinx_dem.contact.pair_lag import PairLag
from dolfinx_dem.contact.patch import PatchScatter
from dolfinx_dem.errors import InputError, StateError

#: Rounds stop when every pair's projected gradient step (its relative velocity left, if stuck) is below
#: this fraction of its stick threshold (``STICK_ROUNDING`` times its cells' speeds).
CONVERGED = 1e-2
#: At most this many rounds a step (``PairFriction.unconverged`` counts the steps that reach it).
MAX_ROUNDS = 1000


def frictional(mu, dem, bodies: np.ndarray) -> bool:
    """Whether the contact between bodies has friction (mu > 0); an InputError for a bad mu or
    friction on a prescribed body's facets (``bodies``: the own candidates'; collective)."""
    if not (isinstance(mu, (int, float)) and not isinstance(mu, bool) and np.isfinite(mu) and mu >= 0):
        raise InputError(f"contact between bodies: the friction coefficient must be a finite number >= 0, got {mu!r}")
    prescribed = np.isin(bodies, dem.prescribed.body_numbers).any()
    if mu > 0 and dem.comm.allreduce(bool(prescribed), op=MPI.LOR):  # its cells have no mass for the law to stop
        raise InputError("contact between bodies: friction on a prescribed body's facets is not implemented (its "
                         "motion is given; remove its facets from the contact boundary or the friction)")
    return mu > 0


def _tangential(x: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The rows of ``x`` projected on the planes normal to the rows of ``n`` (unit normals)."""
    return x - np.einsum("ki,ki->k", x, n)[:, None] * n


class PairFriction:
    """Coulomb friction of coefficient ``mu`` > 0 between the bodies of a ``PairContact``
    ``contact`` (module docstring)."""

    def __init__(self, contact, mu: float):
        self.contact, self.mu, self.d = contact, float(mu), contact.d
        self.comm = contact.comm
        self._made_for = None  # the pair list's patch scatter the cells' scatter was made with
        self._normal = None  # this process's parts of the listed pairs' normal impulses, of the step
        self._quiet = False  # no pair touches during the step, on any process
        self.forces = np.zeros((len(contact.body_pairs), self.d))  # the last step's per body pair / dt
        self.slipping = 0  # handled pairs at the Coulomb limit at the last step
        self.rounds = 0  # the most rounds of a step so far
        self.round_counts = np.zeros(MAX_ROUNDS + 1, dtype=np.int64)  # the steps with friction by their rounds
        self.unconverged = 0  # steps that reached MAX_ROUNDS
        #: this process's sums of the handled pairs' N_p > 0 and of -N_p < 0 (what the positive part drops)
        self.normal_sums = np.zeros(2)
        self.lag = PairLag(contact)  # the pairs' lagged normal forces, whose mu-multiples bound the impulses
        own = slice(0, contact.num_own)
        scheme_b = scheme_b_candidates(contact.dem.reconstruction, contact.facets[own], contact.cells[own])
        warn_scheme_b_spin(self.comm, scheme_b.any(), "contact between bodies")

    def start(self, n_listed: int, quiet: bool) -> np.ndarray:
        """The zeroed array the step's force integral adds the listed pairs' normal impulses to;
        ``quiet``: no pair touches during the step anywhere (then ``apply`` adds nothing)."""
        self._normal, self._quiet = np.zeros(n_listed), quiet
        return self._normal

    def _cells(self) -> None:
        """The scatter of the known facets' cells' dofs, made again with the pair list's (collective:
        a list round remakes that on every process)."""
        pc = self.contact
        if self._made_for is pc.scatter:
            return
        dem, d = pc.dem, self.d
        F = pc.facets_all
        dofs = np.unique(F.cell_dof)
        self._slot = np.searchsorted(dofs, F.cell_dof)  # each known facet's cell in the scatter
        self._scatter = PatchScatter(dem.create_vector(), (dofs[:, None] + np.arange(d)).ravel())
        self._work = dem.create_vector()
        self._mass = self._scatter.gather(dem.mass)[::d]
        self._scatter.add(np.ones(len(self._scatter)), self._work)
        self._needed = np.flatnonzero(self._work.array_r > 0).astype(np.int32)  # owned dofs read somewhere
        self._made_for = pc.scatter

    def _sum_at_cells(self, values: np.ndarray) -> np.ndarray:
        """The sums over all processes of per-cell ``values`` (n_cells, d) at the scatter's cells."""
        self._work.set(0.0)
        self._scatter.add(values.ravel(), self._work)
        return self._scatter.gather(self._work).reshape(-1, self.d)

    def _handled_normals(self, part: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the listed pairs this process handles, their N_p): its own parts and those the other
        processes that list them send (one alltoall of the nonzero parts; ``keys``: the listed
        pairs' keys)."""
        pc = self.contact
        L, F = pc.listed, pc.facets_all
        owner = F.owner[L.i]
        handled = np.flatnonzero(owner == self.comm.rank)
        normal = part[handled].copy()
        if self.comm.size > 1:
            send = np.flatnonzero((part != 0) & (owner != self.comm.rank))
            outgoing = [(keys[send[owner[send] == r]], part[send[owner[send] == r]]) for r in range(self.comm.size)]
            mine = keys[handled]
            order = np.argsort(mine, kind="stable")
            for got_keys, got in self.comm.alltoall(outgoing):
                at = np.searchsorted(mine[order], got_keys)
                if not (np.append(mine[order], -1)[at] == got_keys).all():
                    raise StateError("pair friction: a process sent a normal impulse of a pair its handler does "
                                     "not list")
                np.add.at(normal, order[at], got)
        return handled, normal

    def apply(self, state, impulse) -> float:
        """Adds the step's tangential impulses to ``impulse`` (collective), from the normal impulses
        of its force integral and the velocities of ``state`` (memm_state.StepState after
        ``advance_rows``); returns this process's dissipation -v^{n+1/2} . T^n (>= 0)."""
        pc, d = self.contact, self.d
        if self._normal is None or len(self._normal) != len(pc.listed):
            raise StateError("pair friction needs the normal impulses of the step's force integral (the midpoint "
                             "quadrature's exact integral, MEMM)")
        part, self._normal = self._normal, None
        L, keys = pc.listed, pc.pair_keys()
        if self._quiet:  # no pair touches during the step on any process: every N_p is 0
            handled = np.flatnonzero(pc.facets_all.owner[L.i] == self.comm.rank)
            normal = np.zeros(len(handled))
        else:
            handled, normal = self._handled_normals(part, keys)
            self.normal_sums += [normal[normal > 0].sum(), -normal[normal < 0].sum()]
        lagged = self.lag.update(keys[handled], L.i[handled], normal, state.dt)
        if self._quiet and not self.lag.active:  # on every process
            self.forces[:], self.slipping = 0.0, 0
            return 0.0
        self._cells()
        bounded = lagged > 0
        a = handled[bounded]
        limit = self.mu * lagged[bounded] * state.dt
        ci, cj, n = self._slot[L.i[a]], self._slot[L.j[a]], L.n[a]
        v_prev, v_next = (self._scatter.gather(v).reshape(-1, d) for v in (state.v_prev, state.v_next))
        self._work.set(0.0)
        self._work.array[self._needed] = state.velocities(self._needed, impulse)[2]
        v_free = self._scatter.gather(self._work).reshape(-1, d)
        counts = np.zeros((len(self._mass), d))
        np.add.at(counts[:, 0], ci, 1.0)
        np.add.at(counts[:, 0], cj, 1.0)
        k = self._sum_at_cells(counts)[:, 0]
        m = self._mass
        D = 2.0 * (k[ci] / m[ci] + k[cj] / m[cj]) if len(a) else np.zeros(0)
        w = _tangential(v_next[ci] - v_next[cj], n)
        speeds = [np.linalg.norm(x, axis=1) for x in (v_prev, v_next, v_free)]
        rounding = STICK_ROUNDING * sum(s[ci] + s[cj] for s in speeds)
        relative = _tangential(v_free[ci] - v_free[cj], n)
        tau, slip, rounds, converged = self._rounds(relative, D, w, n, limit, rounding, ci, cj)
        self.rounds = max(self.rounds, rounds)
        self.round_counts[rounds] += 1
        self.unconverged += not converged
        self._scatter.add(self._cell_impulses(tau, ci, cj, reduce=False).ravel(), impulse)
        self._outputs(a, tau, slip & (normal[bounded] > 0), state.dt)  # the pairs at the limit in contact
        return float(np.maximum(-np.einsum("ki,ki->k", w, tau), 0.0).sum())

    def median_rounds(self) -> float:
        """The median of the rounds over the steps that ran them so far (0 without any)."""
        counts = np.repeat(np.arange(MAX_ROUNDS + 1), self.round_counts)
        return float(np.median(counts)) if len(counts) else 0.0

    def _rounds(self, relative, D, w, n, limit, rounding, ci, cj) -> tuple[np.ndarray, np.ndarray, int, bool]:
        """The impulses of K closest to sticking (module docstring): Nesterov-accelerated projected
        gradient rounds in the metric of the split masses D (APGD), restarted where the step from
        the extrapolated point turns against the last move; (the impulses, where they are at the
        Coulomb limit, the rounds, whether they converged). ``relative``: the pairs' r_p (module
        docstring), the gradient at tau = 0."""
        d, m = self.d, self._mass
        after = lambda T: relative + 2.0 * _tangential(T[ci] / m[ci, None] - T[cj] / m[cj, None], n)  # noqa: E731
        x, g_x = np.zeros((len(D), d)), relative  # the iterate (in K) and its gradient w^{after}
        y, g_y, theta, rounds = x, g_x, 1.0, 0  # the extrapolated point and its gradient (linear in it)
        while True:
            rounds += 1
            step = y - g_y / D[:, None]
            slip = project(step, w, n, limit, rounding)
            g_step = after(self._cell_impulses(step, ci, cj, reduce=True))
            trial = step - g_step / D[:, None]  # the projected gradient step from the iterate: its size is
            project(trial, w, n, limit, rounding)  # the relative velocity a stuck pair keeps after the step
            unsettled = D * np.linalg.norm(trial - step, axis=1) > CONVERGED * rounding
            # with O'Donoghue and Candes' gradient restart's sum: the step from y turns against the move from x
            local = [float(unsettled.sum()), float(np.einsum("k,ki,ki->", D, y - step, step - x))]
            count, turn = self.comm.allreduce(np.array(local), op=MPI.SUM)
            converged = count == 0.0
            if converged or rounds == MAX_ROUNDS:
                return step, slip, rounds, converged
            if turn > 0.0:
                beta, theta = 0.0, 1.0
            else:
                following = 0.5 * theta * (np.sqrt(theta**2 + 4.0) - theta)
                beta, theta = theta * (1.0 - theta) / (theta**2 + following), following
            y, g_y = step + beta * (step - x), g_step + beta * (g_step - g_x)
            x, g_x = step, g_step

    def _cell_impulses(self, tau: np.ndarray, ci: np.ndarray, cj: np.ndarray, reduce: bool) -> np.ndarray:
        """+tau on the cells ci, -tau on cj, at the scatter's cells (summed over the processes if
        ``reduce``)."""
        T = np.zeros((len(self._mass), self.d))
        np.add.at(T, ci, tau)
        np.add.at(T, cj, -tau)
        return self._sum_at_cells(T) if reduce else T

    def _outputs(self, a: np.ndarray, tau: np.ndarray, slip: np.ndarray, dt: float) -> None:
        """The per body pair tangential forces of the step (the force body j exerts on body i,
        i < j, as ``PairOutputs.pair_forces``) and the slipping pairs, on this process."""
        pc = self.contact
        L, F = pc.listed, pc.facets_all
        bi, bj = F.body[L.i[a]], F.body[L.j[a]]
        index = pc.body_pair_index[bi, bj]
        keep = index >= 0  # self-contact: internal to a body
        sign = np.where(bi < bj, 1.0, -1.0)[keep, None]
        self.forces[:] = 0.0
        np.add.at(self.forces, index[keep], sign * tau[keep] / dt)
        self.slipping = int(slip.sum())
