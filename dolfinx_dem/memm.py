"""The explicit pseudo-energy conserving two-step scheme MEMM (paper §4, eq. (35a)-(35b)).

    u^{n+1}   = u^n + dt v^{n+1/2}                                              (35a)
    v^{n+3/2} = v^{n-1/2} + 2 M^{-1} int_0^dt F(u^n + tau v^{n+1/2}) dtau        (35b)

conserves the pseudo-energy E^n = 1/2 (v^{n-1/2})^T M v^{n+1/2} + V(u^n) exactly when the force
integral is exact (Marazzato, Ern, Mariotti, Monasse, CMAME 2019): the midpoint rule is exact for
linear elasticity, whose force is affine in tau. Velocities live at half steps; the two sequences
(even and odd) are started consistently, v^{+-1/2} = v^0 +- dt/2 M^{-1} F(u^0), so that the
parasitic (-1)^n mode is not excited.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from petsc4py import PETSc


@dataclasses.dataclass(frozen=True)
class GaussLegendre:
    """Gauss-Legendre rule with ``points`` nodes on [0, 1]; 1 point is the midpoint rule."""

    points: int

    def __post_init__(self):
        if self.points not in (1, 2, 3, 4, 5):
            raise ValueError(f"Gauss-Legendre quadrature needs 1 to 5 points, got {self.points}")

    @property
    def nodes_weights(self) -> tuple[np.ndarray, np.ndarray]:
        x, w = np.polynomial.legendre.leggauss(self.points)
        return (x + 1) / 2, w / 2


#: Quadrature names accepted by ``MEMM`` and scene files.
QUADRATURES = {"midpoint": GaussLegendre(1)} | {f"gauss-legendre-{q}": GaussLegendre(q) for q in (1, 2, 3, 5)}


class InstabilityError(RuntimeError):
    """Raised by the stability monitor; carries the step, time, a suggested time step and the
    monitor's reason (the message without the advice)."""

    def __init__(self, message: str, step: int, t: float, dt: float, suggested_dt: float, reason: str = ""):
        super().__init__(message)
        self.step, self.t, self.dt, self.suggested_dt, self.reason = step, t, dt, suggested_dt, reason


@dataclasses.dataclass(frozen=True)
class Diagnostics:
    """Energies at t_n (J, or J/m in 2D); the kinetic energy uses vbar = (v^{n-1/2} + v^{n+1/2})/2."""

    step: int
    t: float
    kinetic: float
    elastic: float
    stabilisation: float
    external: float
    pseudo_kinetic: float  # 1/2 (v^{n-1/2})^T M v^{n+1/2}
    pseudo_energy: float  # pseudo_kinetic + the potential the force derives from (energies()["potential"])

    @property
    def mechanical(self) -> float:
        """Kinetic + elastic + stabilisation: the scale against which drifts are measured."""
        return self.kinetic + self.elastic + self.stabilisation


class MEMM:
    """The MEMM stepper for a problem offering ``force``, ``energies``, ``mass``, ``create_vector``.

    Parameters
    ----------
    problem : e.g. ``DEMDiscretisation``.
    dt : time step (s), > 0.
    quadrature : name in ``QUADRATURES`` (default "midpoint").
    growth_limit : the stability monitor's bound on the mechanical energy relative to the
        conserved budget (see ``check_stability``).
    """

    def __init__(self, problem, dt: float, quadrature: str = "midpoint", growth_limit: float = 10.0):
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"time step dt must be a positive number, got {dt!r}")
        if quadrature not in QUADRATURES:
            raise ValueError(f"unknown quadrature {quadrature!r}; choose from {sorted(QUADRATURES)}")
        if not growth_limit > 1:
            raise ValueError(f"growth_limit must be > 1, got {growth_limit}")
        self.problem = problem
        self.dt = float(dt)
        self.quadrature = quadrature
        self.nodes, self.weights = QUADRATURES[quadrature].nodes_weights
        self.growth_limit = growth_limit
        self.u = problem.create_vector()
        self.v_prev = problem.create_vector()  # v^{n-1/2}
        self.v_next = problem.create_vector()  # v^{n+1/2}
        self._w = problem.create_vector()
        self._f = problem.create_vector()
        self._integral = problem.create_vector()
        self.t0 = 0.0
        self.n = 0
        self.force_evaluations = 0
        self.max_step_evaluations = 0
        self.budget = 0.0

    @property
    def t(self) -> float:
        return self.t0 + self.n * self.dt

    def initialise(self, u0: PETSc.Vec, v0: PETSc.Vec, t0: float = 0.0) -> Diagnostics:
        """Start from u^0, v^0: v^{-1/2} = v^0 - dt/2 M^-1 F(u^0), v^{1/2} = v^0 + dt/2 M^-1 F(u^0)."""
        self.t0, self.n = float(t0), 0
        u0.copy(self.u)
        for contact in getattr(self.problem, "contacts", ()):
            contact.prepare(self.u)
        self.problem.force(self.u, self.t0, self._f)
        self.force_evaluations += 1
        self._f.pointwiseMult(self._f, self.problem.inverse_mass)
        v0.copy(self.v_prev)
        self.v_prev.axpy(-0.5 * self.dt, self._f)
        v0.copy(self.v_next)
        self.v_next.axpy(0.5 * self.dt, self._f)
        diag = self.diagnostics()
        self.budget = diag.mechanical
        return diag

    def force_integral(self, out: PETSc.Vec) -> PETSc.Vec:
        """int_0^dt F(u^n + tau v^{n+1/2}, t_n + tau) dtau (eq. (35b)).

        Gauss-Legendre rules evaluate the whole force at their nodes. The midpoint rule, with a
        problem that has contact, integrates the smooth (affine) part at the midpoint and each
        contact correction piecewise between its events (paper §4): exactly, so the
        pseudo-energy is conserved through impacts. ``force_evaluations`` counts a step's
        patch-only evaluations beyond the first as evaluations too. Every contact model is first
        prepared for the step's free flight (``prepare``: e.g. the pair list), whatever the rule.
        """
        out.set(0.0)
        contacts = getattr(self.problem, "contacts", ())
        for contact in contacts:
            contact.prepare(self.u, self.v_next, self.dt)
        split = bool(contacts) and self.quadrature == "midpoint"
        evaluations = 0
        for x, w in zip(self.nodes, self.weights):
            tau = x * self.dt
            self.u.copy(self._w)
            self._w.axpy(tau, self.v_next)
            self.problem.force(self._w, self.t + tau, self._f, contact=not split)
            evaluations += 1
            out.axpy(w * self.dt, self._f)
        if split:
            for contact in contacts:
                evaluations += max(contact.force_integral(self.u, self.v_next, self.dt, out) - 1, 0)
        self.force_evaluations += evaluations
        self.max_step_evaluations = max(self.max_step_evaluations, evaluations)
        return out

    def step(self) -> Diagnostics:
        """Advance one step (eq. (35a)-(35b)) and return the diagnostics at the new time."""
        self.force_integral(self._integral)
        self.u.axpy(self.dt, self.v_next)  # (35a)
        self._integral.pointwiseMult(self._integral, self.problem.inverse_mass)
        self.v_prev.axpy(2.0, self._integral)  # (35b): v_prev becomes v^{n+3/2}
        self.v_prev, self.v_next = self.v_next, self.v_prev
        self.n += 1
        diag = self.diagnostics()
        self.check_stability(diag)
        return diag

    def diagnostics(self) -> Diagnostics:
        """Energies at t_n, reduced over all processes."""
        e = self.problem.energies(self.u, self.t)
        M = self.problem.mass
        self.v_prev.copy(self._w)
        self._w.axpy(1.0, self.v_next)
        self._w.scale(0.5)
        self._f.pointwiseMult(self._w, M)
        kinetic = 0.5 * self._f.dot(self._w)
        self._f.pointwiseMult(self.v_prev, M)
        pseudo_kinetic = 0.5 * self._f.dot(self.v_next)
        return Diagnostics(
            step=self.n,
            t=self.t,
            kinetic=kinetic,
            elastic=e["elastic"],
            stabilisation=e["stabilisation"],
            external=e["external"],
            pseudo_kinetic=pseudo_kinetic,
            pseudo_energy=pseudo_kinetic + e["potential"],
        )

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
            f"Reduce the time step, e.g. dt = {suggested:.4g} (half the stability limit "
            f"2/sqrt(lambda_max(M^-1 K)) of the elastic operator)",
            diag.step, diag.t, self.dt, suggested, reason,
        )

    # -- checkpoint -------------------------------------------------------------------------------
    def state(self) -> dict:
        """The complete state of the stepper: the vectors u^n, v^{n-1/2}, v^{n+1/2} (this
        process's entries) and t0, n, dt, the stability budget and the evaluation counters."""
        return {
            "u": self.u, "v_prev": self.v_prev, "v_next": self.v_next,
            "t0": self.t0, "n": self.n, "dt": self.dt, "budget": self.budget,
            "force_evaluations": self.force_evaluations, "max_step_evaluations": self.max_step_evaluations,
        }

    def restore(self, u: np.ndarray, v_prev: np.ndarray, v_next: np.ndarray, t0: float, n: int,
                budget: float, force_evaluations: int, max_step_evaluations: int) -> None:
        """Continue from a ``state()``: this process's entries of the vectors (arrays), the
        scalars as stored. The next ``step`` then computes what it would have without the stop."""
        self.u.array[:], self.v_prev.array[:], self.v_next.array[:] = u, v_prev, v_next
        self.t0, self.n, self.budget = float(t0), int(n), float(budget)
        self.force_evaluations, self.max_step_evaluations = int(force_evaluations), int(max_step_evaluations)

    def suggested_dt(self) -> float:
        stable = getattr(self.problem, "stable_time_step", None)
        return 0.5 * stable() if stable is not None else 0.5 * self.dt
