"""Coulomb friction between bodies (pair.py), with an exact energy balance (docs/theory.md,
"Friction between bodies").

As on rigid obstacles (friction.py), a frictional impulse T^n over the step changes the MEMM
pseudo-energy by v^{n+1/2} . T^n, and D^{n+1} = D^n - v^{n+1/2} . T^n keeps E + D - W constant to
rounding whatever T^n is. Each touching pair p (facet i of cell c, facet j of cell c', the pair's
unit normal n from i to j) carries the normal impulse N_p = int -mu_p w_p dtau that facet i exerts
on facet j over the step (the normal part of the pair's force term, from the step's exact force
integral; a pair with N_p <= 0 gives no friction), and gives +tau_p to cell c and -tau_p to cell
c' (the total linear momentum is unchanged), tau_p in

    K_p = {tau : tau . n = 0, |tau| <= mu N_p, tau . w_p <= 0},   w_p = P_n (v_c - v_c')^{n+1/2},

so that the pair's dissipation -w_p . tau_p is non-negative and sum_p -w_p . tau_p = -v^{n+1/2} . T^n.
The impulses are those of K = prod K_p closest to sticking: they minimise the kinetic energy of
the relative tangential velocities after the step, |P_n (v_c - v_c')^{n+3/2}|, over K, by projected
Jacobi rounds with split masses (Tonge, Benevolenski and Voroshilov, ACM TOG 31, 2012): from tau = 0,

    tau_p <- proj_{K_p}(tau_p - w_p^{after} / D_p),   D_p = 2 (k_c / m_c + k_c' / m_c'),

with w_p^{after} = P_n (v_c - v_c')^{n+3/2} for the current impulses and k_c the number of
touching pairs of cell c. D_p majorises the pairs' Delassus operator (its rows' sums of
|2 P_n P_n' / m| are at most D_p), so the rounds converge; a pair alone on its cells sticks (or
slips at mu N_p) in the first round, exactly as the obstacle law. Every round is a function of the
previous one's impulses only (Gauss-Seidel sweeps would need a partition-independent order of the
pairs, a global colouring): the result does not depend on the partition beyond rounding. They stop
when no cell's summed impulse changes by more than ``CONVERGED`` times the largest bound mu N_p
(an Allreduce per round; the impulses' components that move no cell do not count), or after
``MAX_ROUNDS`` (counted: ``unconverged``; the balance holds all the same, the stick is then not
exact). Pairs alone on their cells converge in one round; a non-matching interface, whose cells
have several partners, takes hundreds (docs/theory.md).

Distributed: the pair is handled by the owner of its facet i (the facet of the smaller global
number); the processes that list it send their own rows' parts of N_p there. The velocities of the
cells of the known facets come by a scatter (``PatchScatter``) remade with the pair list's, the
rounds' impulses reach the cells' owners by its reverse scatter and come back by its forward one.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from dolfinx_dem.contact.friction import STICK_ROUNDING, project
from dolfinx_dem.contact.patch import PatchScatter
from dolfinx_dem.errors import InputError, StateError

#: Rounds stop when no cell's summed impulse changes by more than this fraction of the largest bound mu N_p.
CONVERGED = 1e-13
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
        self.unconverged = 0  # steps that reached MAX_ROUNDS
        #: this process's sums of the handled pairs' N_p > 0 and of -N_p < 0 (what the positive part drops)
        self.normal_sums = np.zeros(2)

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

    def _handled_normals(self, part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the listed pairs this process handles, their N_p): its own parts and those the other
        processes that list them send (one alltoall of the nonzero parts)."""
        pc = self.contact
        L, F = pc.listed, pc.facets_all
        owner = F.owner[L.i]
        handled = np.flatnonzero(owner == self.comm.rank)
        normal = part[handled].copy()
        if self.comm.size > 1:
            keys = pc.pair_keys()
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
        if self._quiet:  # on every process
            self.forces[:], self.slipping = 0.0, 0
            return 0.0
        self._cells()
        L = pc.listed
        handled, normal = self._handled_normals(part)
        self.normal_sums += [normal[normal > 0].sum(), -normal[normal < 0].sum()]
        a = handled[normal > 0]
        limit = self.mu * normal[normal > 0]
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
        tangential = lambda x: x - np.einsum("ki,ki->k", x, n)[:, None] * n  # noqa: E731
        w = tangential(v_next[ci] - v_next[cj])
        speeds = [np.linalg.norm(x, axis=1) for x in (v_prev, v_next, v_free)]
        rounding = STICK_ROUNDING * sum(s[ci] + s[cj] for s in speeds)
        scale = self.comm.allreduce(float(limit.max(initial=0.0)), op=MPI.MAX)
        relative = tangential(v_free[ci] - v_free[cj])
        tau, T, rounds = np.zeros((len(a), d)), np.zeros_like(v_free), 0
        while True:  # T: the impulses' sums at the cells, over all processes
            rounds += 1
            tau = tau - (relative + 2.0 * tangential(T[ci] / m[ci, None] - T[cj] / m[cj, None])) / D[:, None]
            slip = project(tau, w, n, limit, rounding)
            last, T = T, self._cell_impulses(tau, ci, cj, reduce=True)
            change = self.comm.allreduce(float(np.abs(T - last).max(initial=0.0)), op=MPI.MAX)
            if change <= CONVERGED * scale or rounds == MAX_ROUNDS:
                break
        self.rounds = max(self.rounds, rounds)
        self.unconverged += change > CONVERGED * scale
        self._scatter.add(self._cell_impulses(tau, ci, cj, reduce=False).ravel(), impulse)
        self._outputs(a, tau, slip, state.dt)
        return float(np.maximum(-np.einsum("ki,ki->k", w, tau), 0.0).sum())

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
