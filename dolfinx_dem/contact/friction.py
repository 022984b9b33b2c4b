"""Coulomb friction on the cells of contact facets, with an exact energy balance (docs/theory.md,
"Friction on rigid obstacles").

MEMM with a frictional impulse T^n over the step [t_n, t_{n+1}],

    v^{n+3/2} = v^{n-1/2} + 2 M^-1 (I^n + T^n),

changes the pseudo-energy by E^{n+1} - E^n = v^{n+1/2} . T^n (memm.py: I^n is the exact integral
of the conservative force). With the dissipation D^{n+1} = D^n - v^{n+1/2} . T^n, E^n + D^n - W^n
is conserved to rounding, whatever T^n is; Coulomb's law is a choice of T^n that makes every
increment of D non-negative. Each candidate facet f in contact with an obstacle of unit normal n
over the step carries a normal impulse N_f (the integral of its reaction, ``force_integral``; a
facet with N_f <= 0 gives none) and gives its cell c a tangential impulse tau_f in the set

    K_f = {tau : tau . n = 0, |tau| <= mu N_f, tau . w_c <= 0},

w_c the tangential part of the cell's velocity over the step, v_c^{n+1/2}: its dissipation
-w_c . tau_f is non-negative by construction (the slip is measured at the cell: scheme B's facet
follows it; with scheme A the facet's reconstruction moves O(h) differently). tau_f is the point
of K_f closest to the stick impulse, the one that leaves the cell without tangential velocity
after the step, tau*_f = -(m_c / 2) P_n v_c^{n+3/2, free} (``StepState.velocities``): if tau*
lies in K_f the cell sticks (v^{n+3/2} tangential 0, exactly 0 dissipation: a body held by
friction does not creep), otherwise it slips with |tau| <= mu N_f. K_f is a half-disc through its
centre: the projection onto it is the projection onto the half-space, then onto the disc. A cell
with several facets in contact takes them one after the other (rounds), each seeing the impulses
of the rounds before.

The law uses only a cell's own values: it is computed where the cell is owned and does not depend
on the partition.
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc

#: Slip speeds up to this fraction of the sum of a cell's velocities' sizes are rounding (a stuck
#: cell's tangential velocity is the rounding of v + 2 M^-1 (I + tau) = 0): the cell counts as stuck.
STICK_ROUNDING = 1e-12


def project(tau: np.ndarray, w: np.ndarray, n: np.ndarray, limit: np.ndarray, rounding: np.ndarray) -> np.ndarray:
    """tau (k, d) := its projection onto K = {tau . n = 0, |tau| <= limit, tau . w <= 0} (in place),
    a half-disc through its centre: onto the half-space (only where the slip speed |w| exceeds
    ``rounding``: a stuck contact has no direction to oppose), its plane, then the disc. Returns
    where the disc bound acted (slip at the Coulomb limit)."""
    speed = np.linalg.norm(w, axis=1)
    slipping = speed > rounding
    unit = np.divide(w, speed[:, None], out=np.zeros_like(w), where=slipping[:, None])
    tau -= np.maximum(np.einsum("ki,ki->k", tau, unit), 0.0)[:, None] * unit  # tau . w <= 0
    tau -= np.einsum("ki,ki->k", tau, n)[:, None] * n
    size = np.linalg.norm(tau, axis=1)
    slip = size > limit
    tau[slip] *= (limit[slip] / size[slip])[:, None]
    return slip


class CellFriction:
    """Coulomb friction (module docstring) of the own candidate facets of a contact model: their
    cells ``cells`` (owned, local), the obstacles' unit normals ``normals`` (n, d), the friction
    coefficients ``mu`` (n,) and each facet's obstacle ``group`` (n,) for the outputs."""

    def __init__(self, d: int, cells: np.ndarray, normals: np.ndarray, mu: np.ndarray, group: np.ndarray,
                 n_groups: int):
        self.d, self.n_groups = d, n_groups
        self.mu, self.normals, self.group = mu, normals, group
        self.dofs = cells[:, None] * d + np.arange(d)
        frictional = np.flatnonzero(mu > 0)
        order = frictional[np.argsort(cells[frictional], kind="stable")]
        rank = np.zeros(len(order), dtype=np.int64)  # each facet's place among its cell's
        if len(order):
            first = np.r_[True, cells[order][1:] != cells[order][:-1]]
            start = np.maximum.accumulate(np.where(first, np.arange(len(order)), 0))
            rank = np.arange(len(order)) - start
        self.rounds = [order[rank == r] for r in range(int(rank.max(initial=-1)) + 1)]
        self.forces = np.zeros((n_groups, d))  # the last step's tangential impulses per obstacle / dt
        self.slipping = 0  # facets at the Coulomb limit at the last step

    def apply(self, normal: np.ndarray, state, impulse: PETSc.Vec) -> float:
        """Adds the step's tangential impulses to ``impulse`` (this process's owned entries), from
        the facets' normal impulses ``normal`` and the step's velocities (``state``: a
        memm_state.StepState after ``advance_rows``); returns the step's dissipation on this
        process, -v^{n+1/2} . T^n (non-negative, summed over facets)."""
        self.forces[:] = 0.0
        self.slipping = 0
        dissipation = 0.0
        values = impulse.array
        for facets in self.rounds:
            facets = facets[normal[facets] > 0]
            if not len(facets):
                continue
            dofs = self.dofs[facets].ravel()
            v_prev, v_flight, v_free, mass = (a.reshape(-1, self.d) for a in state.velocities(dofs, impulse))
            n = self.normals[facets]
            tau = -0.5 * mass * (v_free - np.einsum("ki,ki->k", v_free, n)[:, None] * n)
            w = v_flight - np.einsum("ki,ki->k", v_flight, n)[:, None] * n
            # a stuck cell keeps a slip speed of the rounding of its velocities' sums: 0 for the law
            rounding = STICK_ROUNDING * (np.linalg.norm(v_prev, axis=1) + np.linalg.norm(v_flight, axis=1)
                                         + np.linalg.norm(v_free, axis=1))
            slip = project(tau, w, n, self.mu[facets] * normal[facets], rounding)
            values[dofs] += tau.ravel()
            dissipation += float(np.maximum(-np.einsum("ki,ki->k", v_flight, tau), 0.0).sum())
            np.add.at(self.forces, self.group[facets], tau)
            self.slipping += int(slip.sum())
        self.forces /= state.dt
        return dissipation
