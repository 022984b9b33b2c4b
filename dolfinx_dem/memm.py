"""The explicit pseudo-energy conserving two-step scheme MEMM (paper §4, eq. (35a)-(35b)).

    u^{n+1}   = u^n + dt v^{n+1/2}                                              (35a)
    v^{n+3/2} = v^{n-1/2} + 2 M^{-1} int_0^dt F(u^n + tau v^{n+1/2}) dtau        (35b)

conserves the pseudo-energy E^n = 1/2 (v^{n-1/2})^T M v^{n+1/2} + V(u^n) exactly when the force
integral is exact (Marazzato, Ern, Mariotti, Monasse, CMAME 2019): the midpoint rule is exact for
linear elasticity, whose force is affine in tau. Velocities live at half steps; the two sequences
(even and odd) are started consistently, v^{+-1/2} = v^0 +- dt/2 M^{-1} F(u^0), so that the
parasitic (-1)^n mode is not excited.

A step costs one pass over the energy rows. The elastic force is F(w, t) = -Q^T (Q w + q(t)) + f
(discretisation.py), and the energy rows r = Q w + q give the elastic and stabilisation energies
1/2 |r|^2, split by rows. The stepper keeps y^n = Q u^n (the homogeneous rows; u minus the mean
translation of each free body). Along the flight u^n + tau v^{n+1/2} they are affine in tau:

    y^{n+1} = y^n + dt Q v^{n+1/2},    int_0^dt -Q^T Q (u^n + tau v^{n+1/2}) dtau = -dt/2 Q^T (y^n + y^{n+1}),

which is r^{n+1} = 2 r_mid - r^n for the midpoint residual r_mid, written as an increment. One
pass over Q (factored.py) gives y^{n+1} and z^{n+1} = Q^T y^{n+1}, z^n is kept from the step
before, and the energies at t_{n+1} are 1/2 |y^{n+1} + q(t_{n+1})|^2: no further product. (y is
stored divided by dt, so that its increment is Q v^{n+1/2} with no scaling pass.) The recurrence
adds the rounding of each step: every ``refresh_every`` steps y^{n+1} is recomputed from u^{n+1}
by a true product instead. All other terms of the integral, the loads f - Q^T q(t) at the
quadrature nodes and the contact corrections, are the step's ``impulse``. One compiled kernel
then updates u and v and sums the kinetic, pseudo-kinetic and external terms, and a single
Allreduce reduces them with the energies: a step synchronises three times (the ghost updates of
v^{n+1/2} and of Q^T y, and the reduction); contact adds the gathers of its patch values (u^n
once per step, ``contact_patch_values``, and v^{n+1/2}) and the sum of its forces. The
kernel also sums the momentum of each free body: the pass over Q subtracts its mean velocity
from v^{n+1/2} at the next step (for rounding, as ``relative_displacement`` does for u).

Work. Time-dependent data and prescribed bodies change E^n; ``work`` counts W^n, the work done
since t0, so that E^n - W^n (``Diagnostics.balance``) is constant in exact arithmetic. A
prescribed body (discretisation.PrescribedBody) has M^-1 = 0 and M = 0 on its dofs p: (35b)
leaves its velocity (a constant one moves on exactly), or the step sets v_p^{n+1/2} =
(U(t_{n+1}) - u_p^n)/dt. With I^n = int_0^dt F(u^n + tau v^{n+1/2}) dtau (exact, events included)
and F = -grad V, V(u^{n+1}) - V(u^n) = -v^{n+1/2} . I^n, while (35b) on the other dofs gives the
pseudo-kinetic change v^{n+1/2} . I^n - v_p^{n+1/2} . I_p^n: so

    W^{n+1} - W^n = -I_p^n . (u_p^{n+1} - u_p^n) / dt,

the work of the force -I_p^n/dt that the body exerts on the rest, exact to rounding.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import InputError, InstabilityError, StateError
from dolfinx_dem.memm_state import (
    CONTACT_J,
    CONTACT_S,
    DATA_POTENTIAL,
    DISSIPATION,
    EXTERNAL,
    KINETIC,
    LIFT_J,
    LIFT_S,
    LOAD_POWER,
    MOMENTUM,
    PSEUDO,
    ROWS_J,
    ROWS_S,
    StepState,
)
from dolfinx_dem.problem import DEMProblem

#: Default number of steps between true products for the energy rows (see the module docstring
#: and docs/bench/README.md for the drift with and without).
REFRESH_EVERY = 1000

@dataclasses.dataclass(frozen=True)
class GaussLegendre:
    """Gauss-Legendre rule with ``points`` nodes on [0, 1]; 1 point is the midpoint rule."""

    points: int

    def __post_init__(self):
        if self.points not in (1, 2, 3, 4, 5):
            raise InputError(f"Gauss-Legendre quadrature needs 1 to 5 points, got {self.points}")

    @property
    def nodes_weights(self) -> tuple[np.ndarray, np.ndarray]:
        x, w = np.polynomial.legendre.leggauss(self.points)
        return (x + 1) / 2, w / 2


#: Quadrature names accepted by ``MEMM`` and scene files.
QUADRATURES = {"midpoint": GaussLegendre(1)} | {f"gauss-legendre-{q}": GaussLegendre(q) for q in (1, 2, 3, 5)}


@dataclasses.dataclass(frozen=True)
class Diagnostics:
    """Energies at t_n (J, or J/m in 2D); the kinetic energy uses vbar = (v^{n-1/2} + v^{n+1/2})/2,
    and so does the total linear momentum sum_c m_c vbar_c (kg m/s, or kg/s in 2D), shape (d,)."""

    step: int
    t: float
    kinetic: float
    elastic: float
    stabilisation: float
    external: float
    pseudo_kinetic: float  # 1/2 (v^{n-1/2})^T M v^{n+1/2}
    pseudo_energy: float  # pseudo_kinetic + the potential the force derives from (energies()["potential"])
    work: float = 0.0  # the work W^n done by time-dependent data and prescribed bodies since t0 (MEMM's docstring)
    momentum: np.ndarray | None = None
    dissipation: float = 0.0  # D^n, the energy friction dissipated since t0 (contact/friction.py)
    fracture: float = 0.0  # Gamma^n, the energy broken facets took from the potential since t0 (fracture/)

    @property
    def balance(self) -> float:
        """E^n + D^n + Gamma^n - W^n: constant in exact arithmetic (the pseudo-energy itself with
        constant data, without friction and without fracture)."""
        return self.pseudo_energy + self.dissipation + self.fracture - self.work

    @property
    def mechanical(self) -> float:
        """Kinetic + elastic + stabilisation: the scale against which drifts are measured."""
        return self.kinetic + self.elastic + self.stabilisation


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


class MEMM:
    """The MEMM stepper of a ``problem.DEMProblem``: its discretisation's energy rows, mass,
    data and prescribed bodies, and its contact models.

    Parameters
    ----------
    problem : a ``DEMProblem`` (a discretisation and its contact models).
    dt : time step (s), > 0 (any real number type: numpy scalars too).
    quadrature : name in ``QUADRATURES`` (default "midpoint").
    growth_limit : the stability monitor's bound on the mechanical energy relative to the
        conserved budget (see ``check_stability``).
    refresh_every : steps between true products for the energy rows; 0 never refreshes them.

    ``u``, ``v_prev`` (v^{n-1/2}) and ``v_next`` (v^{n+1/2}) are the state, with ghost dofs (their
    global form has the layout of ``problem.create_vector()``); change them only through
    ``initialise``, which also recomputes the energy rows.
    """

    def __init__(self, problem, dt: float, quadrature: str = "midpoint", growth_limit: float = 10.0,
                 refresh_every: int = REFRESH_EVERY):
        if not isinstance(problem, DEMProblem):
            raise InputError(f"MEMM integrates a DEMProblem, got {type(problem).__name__} (wrap a discretisation "
                             "as DEMProblem(dem) or DEMProblem(dem, contacts))")
        if not (isinstance(dt, numbers.Real) and not isinstance(dt, bool) and math.isfinite(dt) and dt > 0):
            raise InputError(f"time step dt must be a positive finite real number, got {dt!r} "
                             f"({type(dt).__name__})")
        if quadrature not in QUADRATURES:
            raise InputError(f"unknown quadrature {quadrature!r}; choose from {sorted(QUADRATURES)}")
        if not growth_limit > 1:
            raise InputError(f"growth_limit must be > 1, got {growth_limit}")
        if not (isinstance(refresh_every, numbers.Integral) and not isinstance(refresh_every, bool)
                and refresh_every >= 0):
            raise InputError(f"refresh_every must be an integer >= 0, got {refresh_every!r}")
        self.problem = problem
        self.dt = float(dt)
        self.quadrature = quadrature
        self.nodes, self.weights = QUADRATURES[quadrature].nodes_weights
        self.growth_limit = growth_limit
        self.refresh_every = int(refresh_every)
        self.t0 = 0.0
        self.n = 0
        self.force_evaluations = 0
        self.max_step_evaluations = 0
        self.budget = 0.0
        self.work = 0.0  # W^n, see the module docstring
        self.dissipation = 0.0  # D^n, contact/friction.py
        self._data_potential = 0.0  # phi(u^n, t_n), global
        self._load_power = 0.0  # this process's v^{n+1/2} . int L dt of the step
        self._patches: list = []  # (scatter, patch values of u^n) of each contact model, see contact_patch_values

        self.dem = problem.dem
        self._state = StepState(problem.dem, self.dt)
        #: the contact models with friction (``add_friction``)
        self._frictional = [c for c in problem.contacts if c.friction is not None]
        self._initialised = False

    @property
    def u(self) -> PETSc.Vec:
        """u^n (with ghost dofs)."""
        return self._state.u

    @property
    def v_prev(self) -> PETSc.Vec:
        """v^{n-1/2} (with ghost dofs)."""
        return self._state.v_prev

    @property
    def v_next(self) -> PETSc.Vec:
        """v^{n+1/2} (with ghost dofs)."""
        return self._state.v_next

    @property
    def does_work(self) -> bool:
        """Whether time-dependent data or prescribed bodies do work on the system: then E^n is not
        conserved, and ``work`` counts W^n (module docstring)."""
        return self.dem.data.time_dependent or bool(self.dem.prescribed)

    @property
    def t(self) -> float:
        return self.t0 + self.n * self.dt

    def initialise(self, u0, v0, t0: float = 0.0) -> Diagnostics:
        """Start from u^0, v^0: v^{-1/2} = v^0 - dt/2 M^-1 F(u^0), v^{1/2} = v^0 + dt/2 M^-1 F(u^0),
        and the energy rows y^0 = Q u^0 by a true product. On prescribed bodies u^0 = U(t0) and
        v^0 is their velocity (``impose``), whatever u0 and v0 hold there. u0 and v0: PETSc vectors
        of the dof layout, DOLFINx Functions of the mesh (interpolated into DG0) or arrays of the
        owned values (``DEMDiscretisation.vector``); they are copied."""
        self.t0, self.n = float(t0), 0
        self._patches = []
        if self.problem.fracture is not None:
            self.problem.fracture.check_intact()
        f = self._state.impulse  # free until the first step: no vector of the mesh's size more
        u0, v0 = self.dem.vector(u0), self.dem.vector(v0)
        for contact in self.problem.contacts:
            contact.prepare(u0)
        self.dem.prescribed.impose(u0, v0, self.t0, self.dt)  # u = U(t0) and its velocity on prescribed bodies
        self.problem.force(u0, self.t0, f)
        self.force_evaluations += 1
        f.pointwiseMult(f, self.dem.inverse_mass)
        u0.copy(self.u)
        v0.copy(self.v_prev)
        self.v_prev.axpy(-0.5 * self.dt, f)
        v0.copy(self.v_next)
        self.v_next.axpy(0.5 * self.dt, f)
        u0.destroy()
        v0.destroy()
        self._state.restart(self.t0)
        self.work, self._load_power, self._data_potential = 0.0, 0.0, None
        self.dissipation = 0.0
        self._initialised = True
        diag = self._diagnostics()
        self.budget = diag.mechanical
        return diag

    def step(self) -> Diagnostics:
        """Advance one step (eq. (35a)-(35b)) and return the diagnostics at the new time."""
        if not self._initialised:
            raise StateError("MEMM.step() before MEMM.initialise(u0, v0) (or restore): the stepper has no state")
        refresh = self.refresh_every > 0 and (self.n + 1) % self.refresh_every == 0
        if self.dem.prescribed.moving:  # v^{n+1/2} = (U(t_{n+1}) - u^n)/dt on their dofs
            self.dem.prescribed.impose(self.u, self.v_next, self.t, self.dt, position=False)
        impulse = self.impulse()  # from u^n and v^{n+1/2}
        if refresh:
            self.u.axpy(self.dt, self.v_next)  # (35a) here: y^{n+1} from u^{n+1} by a true product
        self._state.advance_rows(refresh)
        for contact in self._frictional:  # T^n into the impulse, its dissipation (contact/friction.py)
            self._state.sums[DISSIPATION] += contact.add_friction(self._state, impulse)
        self._state.update(impulse, advance=not refresh)  # (35a), (35b)
        self._patches = []  # u^{n+1}: gathered again
        self.n += 1
        diag = self._diagnostics()
        if self.problem.fracture is not None:  # breaks at t_{n+1}, between two flights (fracture/dynamics.py)
            diag = self.problem.fracture.update(self, diag)
        self.check_stability(diag)
        return diag

    def rows_changed(self) -> Diagnostics:
        """After the discretisation's operator changed at t_n, between two flights (fracture/, a
        break: ``DEMDiscretisation.replace_operator``): a new ``StepState`` on its rows with the
        same u^n, v^{n-1/2}, v^{n+1/2}, restarted (y^n and z^n = Q^T y^n of the new rows by a true
        product, the new bodies' means), and the diagnostics at t_n with the new potential. The
        pseudo-energy then jumps by -Delta V(u^n) and is conserved from there on (design note
        ``docs/design/fracture.md`` §2): the caller books the jump."""
        old, self._state = self._state, StepState(self.dem, self.dt)
        for a, b in ((old.u, self._state.u), (old.v_prev, self._state.v_prev), (old.v_next, self._state.v_next)):
            a.copy(b)
        old.destroy()
        self._state.restart(self.t)
        self._patches = []
        return self._diagnostics()

    def impulse(self) -> PETSc.Vec | None:
        """The part of int_0^dt F(u^n + tau v^{n+1/2}, t_n + tau) dtau (eq. (35b)) that ``step``
        does not take from the energy rows: the load f - Q^T q(t) and the contact corrections
        (None when both are zero). Gauss-Legendre rules evaluate them at their nodes (a
        time-dependent load costs a Q^T product per node). The midpoint rule, with a problem
        that has contact, integrates each contact correction piecewise between its events
        (paper §4): exactly, so the pseudo-energy is conserved through impacts.
        ``force_evaluations`` counts the quadrature nodes (the affine part is evaluated there
        through y) and a step's patch-only evaluations beyond the first as evaluations too.
        Every contact model is first prepared for the step's free flight (``prepare``: e.g. the
        pair list), whatever the rule.
        """
        contacts = self.problem.contacts
        patch = [contact.prepare(self.u, self.v_next, self.dt, up)
                 for contact, up in zip(contacts, self.contact_patch_values())]
        split = bool(contacts) and self.quadrature == "midpoint"
        evaluations = len(self.nodes)
        load = self._state.load
        if self.dem.data.time_dependent:
            out = self._state.impulse
            out.set(0.0)
            for x, w in zip(self.nodes, self.weights):
                out.axpy(w * self.dt, self.dem.data.load(self.t + x * self.dt))
            self._load_power = self.v_next.array_r @ out.array_r
        elif contacts:
            out = self._state.impulse
            if load is None:
                out.set(0.0)
            else:
                load.copy(out)
        else:
            out = load
        for contact, (up, vp) in zip(contacts, patch):
            if split:
                evaluations += max(contact.force_integral(up, vp, self.dt, out) - 1, 0)
            else:
                for x, w in zip(self.nodes, self.weights):
                    contact.add(contact.force_correction(up + x * self.dt * vp), out, scale=w * self.dt)
        self.force_evaluations += evaluations
        self.max_step_evaluations = max(self.max_step_evaluations, evaluations)
        return out

    def _diagnostics(self) -> Diagnostics:
        """Diagnostics at t_n from the sums of the step's kernels and of the contact models'
        energy changes (each process's part), reduced together by one Allreduce."""
        sums = self._state.sums
        for c, up in zip(self.problem.contacts, self.contact_patch_values()):
            de, ds = c.energy_correction(up)
            sums[CONTACT_S] += de
            sums[CONTACT_J] += ds
        if self.dem.data.time_dependent:
            sums[LOAD_POWER] += self._load_power
        s = self._state.reduce(self.t)
        self.dissipation += s[DISSIPATION]
        if self.does_work:
            if self._data_potential is not None:
                self.work += s[LOAD_POWER] + s[DATA_POTENTIAL] - self._data_potential
            self._data_potential = s[DATA_POTENTIAL]
        elastic = 0.5 * (self.dt**2 * s[ROWS_S] + s[LIFT_S]) + s[CONTACT_S]
        stabilisation = 0.5 * (self.dt**2 * s[ROWS_J] + s[LIFT_J]) + s[CONTACT_J]
        external = -s[EXTERNAL]
        return Diagnostics(step=self.n, t=self.t, kinetic=s[KINETIC], elastic=elastic, stabilisation=stabilisation,
                           external=external, pseudo_kinetic=s[PSEUDO],
                           pseudo_energy=s[PSEUDO] + elastic + stabilisation + external, work=self.work,
                           momentum=s[MOMENTUM : MOMENTUM + self.problem.d].copy(), dissipation=self.dissipation,
                           fracture=self._fracture_energy)

    def contact_patch_values(self) -> list[np.ndarray]:
        """The patch values of u^n of each contact model (``problem.contacts``), gathered once
        per step: the energy at the step's end, the outputs there and the next step's
        ``prepare`` read the same values (u changes only in ``step``, ``initialise`` and
        ``restore``). A model whose list round made a new patch scatter since is gathered again
        (collective: a round makes it on every process). The arrays are shared: read only."""
        contacts = self.problem.contacts
        kept = self._patches if len(self._patches) == len(contacts) else [(None, None)] * len(contacts)
        self._patches = [(s, up) if c.scatter is s else (c.scatter, _read_only(c.patch_values(self.u)))
                         for c, (s, up) in zip(contacts, kept)]
        return [up for _, up in self._patches]

    def energy_rows(self) -> np.ndarray:
        """The homogeneous energy rows Q u^n (free bodies' mean translations removed) that the
        recurrence carries, the process's rows of Q (a copy): the energies are 1/2 |rows + q|^2."""
        return self.dt * self._state.y

    def diagnostics(self) -> Diagnostics:
        """Energies at t_n recomputed from u^n by true products (``problem.energies``), reduced
        over all processes: a check of the values ``step`` returns, not used by it."""
        e = self.problem.energies(self.u, self.t)
        M = self.dem.mass
        w, m = self.dem.create_vector(), self.dem.create_vector()
        self.v_prev.copy(w)
        w.axpy(1.0, self.v_next)
        w.scale(0.5)
        m.pointwiseMult(w, M)
        kinetic = 0.5 * m.dot(w)
        momentum = self.problem.comm.allreduce(m.array_r.reshape(-1, self.problem.d).sum(axis=0), op=MPI.SUM)
        m.pointwiseMult(self.v_prev, M)
        pseudo_kinetic = 0.5 * m.dot(self.v_next)
        return Diagnostics(
            step=self.n,
            t=self.t,
            kinetic=kinetic,
            elastic=e["elastic"],
            stabilisation=e["stabilisation"],
            external=e["external"],
            pseudo_kinetic=pseudo_kinetic,
            pseudo_energy=pseudo_kinetic + e["potential"],
            work=self.work,
            momentum=momentum,
            dissipation=self.dissipation,
            fracture=self._fracture_energy,
        )

    @property
    def _fracture_energy(self) -> float:
        """Gamma^n (fracture/dynamics.py), 0 without fracture."""
        return 0.0 if self.problem.fracture is None else self.problem.fracture.gamma

    def check_stability(self, diag: Diagnostics):
        """The a-posteriori stability monitor.

        Conservation of E^n alone does not bound the solution: E^n = K_pseudo + V, and an
        unstable mode grows while its pseudo-kinetic term 1/2 (v^{n-1/2})^T M v^{n+1/2} turns
        negative (its velocity alternates sign) and cancels the growth of V. The run is declared
        unstable when the pseudo-kinetic term is negative and larger in magnitude than the
        budget, or when the mechanical energy exceeds ``growth_limit`` times the budget. The
        budget is the running maximum of the initial mechanical energy and of
        |E^n - V_ext(u^n)|, the energy the conserved pseudo-energy makes available to the
        elastic and kinetic terms (it grows when external forces do work).
        """
        if not all(math.isfinite(x) for x in (diag.pseudo_energy, diag.kinetic, diag.elastic)):
            self._unstable(diag, "energies are no longer finite")
        available = abs(diag.pseudo_energy - diag.external)
        self.budget = max(self.budget, available)
        if diag.pseudo_kinetic < -self.budget:
            self._unstable(diag, f"pseudo-kinetic energy {diag.pseudo_kinetic:.3e} is negative "
                                 f"beyond the energy budget {self.budget:.3e}")
        if diag.mechanical > self.growth_limit * self.budget:
            self._unstable(diag, f"mechanical energy {diag.mechanical:.3e} exceeds "
                                 f"{self.growth_limit:g} x the energy budget {self.budget:.3e}")

    def _unstable(self, diag: Diagnostics, reason: str):
        suggested = self.suggested_dt()
        raise InstabilityError(
            f"MEMM is unstable at step {diag.step} (t = {diag.t:.6g}, dt = {self.dt:.6g}): {reason}. "
            f"Reduce the time step, e.g. dt = {suggested:.4g} (half the stable time step of the elastic "
            f"operator, 2/sqrt(lambda_max(M^-1 K)) with a guaranteed bound on lambda_max)",
            diag.step, diag.t, self.dt, suggested, reason,
        )

    # -- checkpoint -------------------------------------------------------------------------------
    def state(self) -> dict:
        """The complete state of the stepper: the vectors u^n, v^{n-1/2}, v^{n+1/2} (this
        process's entries), t0, n, dt, the stability budget, the work W^n and
        the data potential it continues from (global), the evaluation counters, and
        ``recurrence``, what the energy-row recurrence carries on this process (memm_state.py)."""
        if self.problem.fracture is not None:
            raise InputError("checkpoints of runs with fracture are not implemented yet (issue 34, design stage S3)")
        return {
            "u": self.u, "v_prev": self.v_prev, "v_next": self.v_next,
            "t0": self.t0, "n": self.n, "dt": self.dt, "budget": self.budget,
            "work": self.work, "data_potential": self._data_potential, "dissipation": self.dissipation,
            "force_evaluations": self.force_evaluations, "max_step_evaluations": self.max_step_evaluations,
            "recurrence": self._state.recurrence(),
        }

    def restore(self, u: np.ndarray, v_prev: np.ndarray, v_next: np.ndarray, t0: float, n: int,
                budget: float, work: float, data_potential: float | None, force_evaluations: int,
                max_step_evaluations: int, dissipation: float = 0.0,
                recurrence: dict[str, np.ndarray] | None = None) -> None:
        """Continue from a ``state()``: this process's entries of the vectors (arrays), the
        scalars as stored. With the ``recurrence`` of the same rows (same partition) the next
        ``step`` computes bit for bit what it would have without the stop; without it the energy
        rows are recomputed from u^n by a true product (as at a refresh: a difference in the last
        bits)."""
        if self.problem.fracture is not None:
            raise InputError("restoring runs with fracture is not implemented yet (issue 34, design stage S3)")
        self.u.array[:], self.v_prev.array[:], self.v_next.array[:] = u, v_prev, v_next
        self._patches = []
        self.t0, self.n, self.budget = float(t0), int(n), float(budget)
        self.work, self._data_potential, self.dissipation = float(work), data_potential, float(dissipation)
        self.force_evaluations, self.max_step_evaluations = int(force_evaluations), int(max_step_evaluations)
        self._initialised = True
        if recurrence is not None:
            self._state.restore_recurrence(self.t, **recurrence)
        else:
            self._state.restart(self.t)
            self._state.reduce(self.t)  # the free bodies' mean velocities of v^{n+1/2}

    def suggested_dt(self) -> float:
        """Half the discretisation's ``stable_time_step()`` (a bound: cheap, and cached)."""
        return 0.5 * self.dem.stable_time_step()
