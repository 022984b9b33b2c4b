"""Coulomb friction on the cells of contact facets, with an exact energy balance (docs/theory.md,
"Friction on rigid obstacles").

MEMM with a frictional impulse T^n over the step [t_n, t_{n+1}],

    v^{n+3/2} = v^{n-1/2} + 2 M^-1 (I^n + T^n),

changes the pseudo-energy by E^{n+1} - E^n = v^{n+1/2} . T^n (memm.py: I^n is the exact integral
of the conservative force). With the dissipation D^{n+1} = D^n - v^{n+1/2} . T^n, E^n + D^n - W^n
is conserved to rounding, whatever T^n is; Coulomb's law is a choice of T^n that makes every
increment of D non-negative. Each candidate facet f on an obstacle of unit normal n carries over
the step a normal impulse N_f (the integral of its reaction, ``force_integral``) and a lagged
normal force Ntilde_f, which follows the step's mean normal force N_f^+ / dt with the time scale
T_f = LAG h_f / c_f (h_f the facet's diameter, c_f its cell's P-wave speed):

    Ntilde_f^{n+1} = Ntilde_f^n + (1 - exp(-dt / T_f)) (N_f^+ / dt - Ntilde_f^n),

the exact step of dNtilde/dt = (N^+ - Ntilde) / T_f for a normal force constant over the step
(Prakash and Clifton's lagged shear strength with a fixed time scale; the first step sets
Ntilde_f = N_f^+ / dt: the initial state's history). A bound mu N_f taken from the same step's
N_f feeds the friction back into the normal impulse and opens the contact at the mesh scale
(docs/theory.md); the lag removes that feedback and vanishes under refinement (T_f ~ h_f), so the
law tends to Coulomb's. The facet gives its cell c a tangential impulse tau_f in the set

    K_f = {tau : tau . n = 0, |tau| <= mu Ntilde_f dt, tau . w_c <= 0},

w_c the tangential part of the cell's velocity over the step, v_c^{n+1/2}: its dissipation
-w_c . tau_f is non-negative by construction (the slip is measured at the cell: scheme B's facet
follows it; with scheme A the facet's reconstruction moves O(h) differently). tau_f is the point
of K_f closest to the stick impulse, the one that leaves the cell without tangential velocity
after the step, tau*_f = -(m_c / 2) P_n v_c^{n+3/2, free} (``StepState.velocities``): if tau*
lies in K_f the cell sticks (v^{n+3/2} tangential 0, exactly 0 dissipation: a body held by
friction does not creep), otherwise it slips with |tau| <= mu Ntilde_f dt. K_f is a half-disc through its
centre: the projection onto it is the projection onto the half-space, then onto the disc. A cell
with several facets with a bound takes them one after the other (rounds), each seeing the
impulses of the rounds before. A facet that leaves contact keeps a bound that decays as
exp(-t / T_f): after its last contact step it can give at most mu Ntilde_f T_f more impulse.

Scheme B candidates (dem-B, dem-AB): their reactions y_f . a' alternate from one facet to the
next, and the bound of each facet's own N_f^+ over-counts the normal force. Their Ntilde_f follow
instead the signed N'_f / dt, N'_f their neighbourhood's normal impulses spread over it
(``Spread``, conservative), and the bound is mu max(Ntilde_f, 0): the positive part after the
spreading and after the lag, so alternations in space and in time cancel. Any bound >= 0 keeps the
balance and the dissipation's sign.

The law uses only a cell's own values and its facets' Ntilde_f (updated from their own N_f, or for
scheme B from their neighbours', brought by a ghost update): it is computed where the cell is owned
and does not depend on the partition. Ntilde_f is state: the contact model checkpoints it with the
cells (rigid.RigidContact.cell_state).
"""

from __future__ import annotations

import warnings

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import AccuracyWarning, InputError

#: Slip speeds up to this fraction of the sum of a cell's velocities' sizes are rounding (a stuck
#: cell's tangential velocity is the rounding of v + 2 M^-1 (I + tau) = 0): the cell counts as stuck.
STICK_ROUNDING = 1e-12

#: The lag of the friction bound behind the normal force, in the times h_f / c_f a P wave takes to
#: cross the facet (``CellFriction``; docs/theory.md, Friction on rigid obstacles)
LAG = 2.0


def scheme_b_candidates(rec, facets: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Which candidate ``facets`` (of ``cells``) have scheme B chosen for them (dem-B, dem-AB) in the
    reconstruction ``rec``; scheme A's own fallback to scheme B on cells with several Neumann
    facets (corners and edges, reconstruction.py) does not count."""
    return ~np.isin(facets, rec.scheme_a_facets) & ~np.isin(cells, rec.multi_neumann_cells)


def warn_scheme_b_spin(comm: MPI.Comm, scheme_b: bool, what: str) -> None:
    """The AccuracyWarning of friction on scheme B candidates (``scheme_b`` on some process; rank 0
    warns; collective): scheme B does not keep a body's spin (docs/theory.md, Scheme B's accuracy),
    so friction's torques do not turn bodies as they should."""
    if comm.allreduce(bool(scheme_b), op=MPI.LOR) and comm.rank == 0:
        warnings.warn(AccuracyWarning(
            f"{what}: friction on scheme B candidates (method dem-B or dem-AB). Scheme B moves a boundary facet "
            "with its cell, so a rigid rotation strains the body and its spin is not kept (a free disc spinning at "
            "0.5 rad/s turns at 0.09 rad/s 0.8 ms later; dem-A keeps its spin): friction's torques do not turn "
            "bodies as they should (a disc launched sliding on a floor keeps sliding where it should roll). Use "
            "method dem-A where bodies roll or spin (docs/theory.md#scheme-bs-accuracy)"), stacklevel=4)


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
    coefficients ``mu`` (n,), the lags T_f ``lag`` (n,) (s) and each facet's obstacle ``group``
    (n,) for the outputs. Its state: ``normal_force``, the lagged normal forces Ntilde_f (n,)
    (N, N/m in 2D), and ``started`` (whether a step has set them)."""

    def __init__(self, d: int, cells: np.ndarray, normals: np.ndarray, mu: np.ndarray, lag: np.ndarray,
                 group: np.ndarray, n_groups: int):
        if not (np.isfinite(lag).all() and (lag > 0).all()):
            raise ValueError("the friction bound's lags must be finite and > 0")
        self.d, self.n_groups = d, n_groups
        self.mu, self.normals, self.group, self.lag = mu, normals, group, lag
        self.normal_force = np.zeros(len(mu))
        self.started = False
        self.slip = np.zeros(len(mu), dtype=bool)  # the facets at their bound in the last step
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
        self.spread = None  # scheme B candidates: their normal impulses spread over neighbours (``Spread``)

    def apply(self, normal: np.ndarray, state, impulse: PETSc.Vec) -> float:
        """Adds the step's tangential impulses to ``impulse`` (this process's owned entries), from
        the facets' normal impulses ``normal`` (which update the lagged normal forces, ``lagged``)
        and the step's velocities (``state``: a memm_state.StepState after ``advance_rows``);
        returns the step's dissipation on this process, -v^{n+1/2} . T^n (non-negative, summed
        over facets)."""
        dissipation = self.bounded(self.mu * self.lagged(normal, state.dt) * state.dt, state, impulse)
        # the slipping facets are those in contact over the step: a facet that left contact keeps a
        # decaying bound, which its cell's tangential motion reaches at once
        self.slipping = int((self.slip & (normal > 0)).sum())
        return dissipation

    def lagged(self, normal: np.ndarray, dt: float) -> np.ndarray:
        """The lagged normal forces Ntilde_f after a step of normal impulses ``normal`` (module
        docstring; updated in place, the first step sets them), as bounds: the facets of
        ``spread`` (scheme B) lag their spread normal impulses N'_f / dt before the positive part
        and give max(Ntilde_f, 0) (collective when ``spread`` is set)."""
        force = np.maximum(normal, 0.0) / dt
        if self.spread is not None:
            force[self.spread.rows] = self.spread(normal) / dt
        if self.started:
            self.normal_force -= np.expm1(-dt / self.lag) * (force - self.normal_force)
        else:
            self.normal_force[:], self.started = force, True
        if self.spread is None:
            return self.normal_force
        bound = self.normal_force.copy()
        bound[self.spread.rows] = np.maximum(bound[self.spread.rows], 0.0)
        return bound

    def bounded(self, bound: np.ndarray, state, impulse: PETSc.Vec) -> float:
        """``apply`` with the facets' bounds on |tau_f| ``bound`` (n,) (impulses; 0: no friction)."""
        self.forces[:] = 0.0
        self.slip[:] = False
        dissipation = 0.0
        values = impulse.array
        for facets in self.rounds:
            facets = facets[bound[facets] > 0]
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
            slip = project(tau, w, n, bound[facets], rounding)
            values[dofs] += tau.ravel()
            dissipation += float(np.maximum(-np.einsum("ki,ki->k", v_flight, tau), 0.0).sum())
            np.add.at(self.forces, self.group[facets], tau)
            self.slip[facets] = slip
        self.slipping = int(self.slip.sum())
        self.forces /= state.dt
        return dissipation


class Spread:
    """The normal impulses of a group of scheme B candidate facets spread over their neighbours
    (docs/theory.md, Friction on rigid obstacles: the bound of a group of facets): with nb(g) the
    group's facets on g's obstacle that share a vertex with g (g included) and
    A_g = sum_{h in nb(g)} |h|, facet f of the group gets

        N'_f = |f| sum_{g in nb(f)} N_g / A_g,

    each N_g shared among its neighbourhood in proportion to the facets' sizes: sum_f N'_f =
    sum_g N_g over the group (conservative), and a normal force that alternates from one facet to
    the next, N_g = m + (-1)^g delta on equal facets, gives N' = m +- delta / 3 in 2D (not
    delta). The others keep their own N_f. Built from the candidates ``contact`` knows (its own
    and its first halo layer's, which hold every neighbour of an own facet) and ``group``, the
    local candidates in the group (collective); ``__call__`` brings the neighbours' N_g from their
    owners by a ghost update (collective) and sums them in the order of their global numbers, so
    N'_f does not depend on the partition beyond the rounding of N_g."""

    def __init__(self, contact, group: np.ndarray, obstacle: np.ndarray):
        dem, comm, d, own = contact.dem, contact.comm, contact.d, contact.num_own
        geom, cells, j = dem.geometry, contact.cells, contact._facet_j
        n = len(cells)
        first = comm.exscan(own) or 0

        def exchange(values):  # own candidates' values -> every local candidate's (its owner's)
            table = np.zeros((dem.n_owned, d + 1))
            table[cells[:own], j[:own]] = values
            return dem.halo_exchange(table)[cells, j]

        # the group and the global numbers of the candidates, as their owners have them
        number = exchange(np.where(group[:own], first + np.arange(own), -1)).astype(np.int64)
        member = number >= 0
        vertices = geom.cell_vertex_ids[cells][np.arange(d + 1) != j[:, None]].reshape(n, d)
        # pairs (f, g) of group members of one obstacle sharing a vertex (f itself included)
        entry = np.flatnonzero(np.repeat(member, d))
        keys = vertices.ravel()[entry]
        order = np.argsort(keys, kind="stable")
        keys, owners = keys[order], entry[order] // d
        lo, hi = np.searchsorted(keys, keys, "left"), np.searchsorted(keys, keys, "right")
        counts = hi - lo
        rows = np.repeat(owners, counts)
        cols = owners[np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(lo, counts)]
        keep = obstacle[rows] == obstacle[cols]
        pairs = np.unique(np.stack([rows[keep], cols[keep]], axis=1), axis=0)
        area = geom.facet_areas[contact.facets]
        mine = pairs[pairs[:, 0] < own]  # the own facets' neighbourhoods: complete here
        sizes = np.bincount(mine[:, 0], area[mine[:, 1]], own)
        share = exchange(np.divide(1.0, sizes, out=np.zeros(own), where=sizes > 0))  # 1 / A_g
        # N'_f for the own members: |f| sum_g N_g / A_g, g in the order of the global numbers
        mine = mine[np.lexsort((number[mine[:, 1]], mine[:, 0]))]
        self.rows = np.flatnonzero(member[:own])
        halo = np.unique(mine[:, 1][mine[:, 1] >= own])
        position = np.arange(n)
        position[halo] = own + np.arange(len(halo))  # their places after the owned values
        self._entry = np.searchsorted(self.rows, mine[:, 0])  # each term's row among ``rows``
        self._column = position[mine[:, 1]]
        self._weight = area[mine[:, 0]] * share[mine[:, 1]]
        self.vec = PETSc.Vec().createGhost(np.asarray(number[halo], dtype=PETSc.IntType), size=(own, PETSc.DECIDE),
                                           comm=comm)

    def __call__(self, normal: np.ndarray) -> np.ndarray:
        """N'_f of the own facets ``rows`` from the own facets' normal impulses ``normal``
        (collective)."""
        self.vec.array[:] = normal
        self.vec.ghostUpdate(PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        with self.vec.localForm() as local:
            values = local.array_r.copy()
        return np.bincount(self._entry, self._weight * values[self._column], len(self.rows))


def cell_friction(contact, mu: list[float], obstacle: np.ndarray) -> CellFriction | None:
    """The friction of a rigid contact model ``contact`` (its candidates ``facets``, ``cells``,
    ``normals``, the first ``num_own`` its own) whose obstacles have the coefficients ``mu``,
    ``obstacle`` the obstacle of each candidate; None without friction. An InputError where the
    law does not apply: a prescribed body's facets. Scheme B candidates take their bounds from
    their normal impulses spread over their neighbours (``Spread``; collective)."""
    dem, comm, d, n = contact.dem, contact.comm, contact.d, len(mu)
    rec, geom = dem.reconstruction, dem.geometry
    mu = np.asarray(mu)[obstacle]
    # their bounds from ``Spread``; scheme A's fallback keeps the facets' own N_f, as with scheme A
    scheme_b = (mu > 0) & scheme_b_candidates(rec, contact.facets, contact.cells)
    own = slice(0, contact.num_own)
    prescribed = (mu[own] > 0) & np.isin(contact.cells[own] * d, dem.prescribed.dofs)
    k = comm.allreduce(int(obstacle[own][prescribed].min(initial=n)), op=MPI.MIN)
    if k < n:  # their cells have no mass for the law to stop: an error, not no friction
        raise InputError(f"obstacle {k}: friction on a prescribed body's facets is not implemented (its motion is "
                         "given; remove the facets from the candidates or the friction)")
    if not comm.allreduce(bool((mu > 0).any()), op=MPI.LOR):
        return None
    lag = LAG * geom.facet_diameters[contact.facets[own]] / dem.materials.wave_speed(d, contact.cells[own])
    friction = CellFriction(d, contact.cells[own], contact.normals[own], mu[own], lag, obstacle[own], n)
    if comm.allreduce(bool(scheme_b.any()), op=MPI.LOR):  # on every process
        friction.spread = Spread(contact, scheme_b, obstacle)
        warn_scheme_b_spin(comm, True, "rigid obstacles")
    return friction
