"""The active-set Newton iteration of statics: one loop for every contact kind.

The potential V of a problem with contact is continuous, and smooth on each *piece*: a fixed set
A of candidates in contact (facets on an obstacle, pairs of facets between bodies). Its gradient
jumps across a contact switch g = 0, so V has a kink there. The iteration is Newton's method on
the pieces with a line search on V itself:

    H_A d = F_A(u)        (H_A = K + the contact's Hessian of the piece, F_A = -grad V_A),
    u <- u + alpha d      (alpha by Armijo backtracking on V: 1 unless d overshoots a switch),
    A <- the candidates in contact at u,

until the piece settles: on a quadratic piece (rigid obstacles) a full step minimises V_A, so a
full step that leaves A unchanged ends it; on other pieces (contact between bodies: quartic) it
goes on until the gradient has fallen by ``gradient_rtol``, with the exact Hessian first and
its Gauss-Newton part J^T J where CG breaks down on the exact one or its step is no descent
direction. The contact model says which (``contact.protocol.StaticContact``). The line search
makes the iteration a descent method; a step is shortened so that no candidate moves further
than the model can follow (``step_ratio``: bodies must not pass through each other, where V is
unbounded below).

Kinks. The minimum of V can sit on a switch: no point then has a zero gradient, and the pieces
cycle (or the step is cut ever shorter against the switch). The candidates that keep switching
(or whose switch a stalled step crosses) are pinned on it, g = 0, by Lagrange multipliers mu
(one extra solve each, and a small Schur complement):

    H_A z_0 = F_A,   H_A z_c = P grad g_c,   (grad g_C . Z) mu = g_C(u) + grad g_C . z_0,   d = z_0 - Z mu,

solved as an update of the last step's multipliers where the pinned candidates are the same
(``_solve``: the error of CG then shrinks with the gradient of the Lagrangian).

At the solution the directional derivatives of V must be >= 0 on both sides of each pinned
switch: towards lifting off (g > 0) it is -mu_c, towards pressing in mu_c + r_c (r_c the force the
candidate would carry in contact), so -r_c <= mu_c <= 0, and the pinned candidate carries the
contact force -mu_c. One with mu_c > 0 is released, one with mu_c + r_c < 0 put in contact, and
the iteration goes on. The gradient norm reported is that of the Lagrangian (grad V_A + sum
mu_c grad g_c), the gradient of V itself when nothing is pinned.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import StaticsError
from dolfinx_dem.statics.linear import Constraints, LinearSolver, project


@dataclasses.dataclass
class Iterate:
    """The state of the iteration: the piece ``active``, the ``pinned`` candidates, their
    ``multipliers`` and ``gaps`` (global order) of the last Newton step, the iterations done and
    the Newton steps taken with the Gauss-Newton Hessian; ``solved``: the pinned candidates the
    multipliers belong to (None before the first Newton step)."""

    active: np.ndarray
    pinned: np.ndarray
    multipliers: np.ndarray
    gaps: np.ndarray
    iterations: int = 0
    gauss_newton_steps: int = 0
    solved: np.ndarray | None = None


class ActiveSetNewton:
    """Minimises the potential of ``problem`` (a DEMProblem) with the contact model's statics
    interface ``model`` at the load time t, from u (updated in place), in the subspace
    ``constraints``, with the linear solver ``linear`` (module docstring); ``load``: a constant
    force added to the problem's (statics with friction: the tangential load and the slip forces)."""

    def __init__(self, problem, model, t: float, constraints: Constraints, linear: LinearSolver,
                 gradient_rtol: float, curvature: bool, load: PETSc.Vec | None = None):
        self.problem, self.model, self.t = problem, model, t
        self.load = load  # an extra constant external force f (V gains -f . u; statics/friction.py)
        self.dem, self.comm = problem.dem, problem.comm
        self.constraints, self.linear = constraints, linear
        self.gradient_rtol = gradient_rtol
        self.tries = (True, False) if curvature and not model.quadratic else (False,)

    # -- pieces as sets --------------------------------------------------------------------------
    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether two pieces are equal (collective)."""
        return self.comm.allreduce(bool(np.array_equal(a, b)), op=MPI.LAND)

    def count(self, piece: np.ndarray) -> int:
        """The candidates of a piece, over all processes."""
        return self.comm.allreduce(len(piece), op=MPI.SUM) if self.model.local_pieces else len(piece)

    def local(self, values: np.ndarray, pinned: np.ndarray) -> np.ndarray:
        """The entries of ``values`` (global order of the pinned candidates) that belong to this
        process's ``pinned``."""
        offset = (self.comm.exscan(len(pinned)) or 0) if self.model.local_pieces else 0
        return values[offset : offset + len(pinned)]

    # -- the potential and its force -------------------------------------------------------------
    def potential(self, u: PETSc.Vec) -> float:
        self.model.prepare(u)
        potential = self.problem.energies(u, self.t)["potential"]
        return potential if self.load is None else potential - self.load.dot(u)

    def lagrangian_force(self, u: PETSc.Vec, it: Iterate, out: PETSc.Vec, project_it: bool = True) -> None:
        """out = -grad V_A(u) - sum_C mu_c grad g_c, projected unless not ``project_it``."""
        self.dem.force(u, self.t, out)
        self.model.add_force(u, out, it.active)
        if self.load is not None:
            out.axpy(1.0, self.load)
        if len(it.multipliers):
            for m, g in zip(it.multipliers, self.model.constraint_gradients(u, it.pinned)):
                out.axpy(-m, g)
        if project_it:
            project(out, self.constraints)

    # -- the iteration -------------------------------------------------------------------------------
    def run(self, u: PETSc.Vec, norm0: float, max_iterations: int,
            piece: np.ndarray | None = None) -> tuple[Iterate, float]:
        """Iterate from u to the minimum, from the model's ``start_piece`` or ``piece`` (the
        candidates touching at a u in contact: statics/friction.py); returns the final iterate and
        its gradient norm."""
        model, dem = self.model, self.dem
        rhs, step, trial = (dem.create_vector() for _ in range(3))
        it = Iterate(model.start_piece(u) if piece is None else piece, np.empty(0, dtype=np.int64), np.zeros(0),
                     np.zeros(0))
        history, norm = [it.active], norm0
        for iteration in range(1, max_iterations + 1):
            it.iterations = iteration
            exact = self.newton_step(u, it, rhs, step, iteration)
            it.gauss_newton_steps += not exact
            alpha = self.line_search(u, it, rhs, step, trial, iteration)
            crossed = model.switches_crossed(u, step, alpha, np.union1d(it.active, it.pinned))
            u.axpy(alpha, step)
            model.prepare(u)
            new = np.setdiff1d(model.touching(u), it.pinned)
            if not model.quadratic:
                self.lagrangian_force(u, it, rhs)
                norm = rhs.norm()
            if self.count(new) + self.count(it.pinned) == 0:
                raise StaticsError(model.no_contact_message)
            settled = self.same(new, it.active)
            if settled and alpha == 1.0 and (model.quadratic or norm <= self.gradient_rtol * norm0):
                if self.count(it.pinned) == 0:
                    return it, norm
                # Kink conditions of the pinned candidates (g = 0): the directional derivatives of
                # V towards lifting off (-mu) and towards pressing in (mu + r) must be >= 0.
                reaction = model.constraint_reactions(u, it.active, it.pinned)
                lift, press = it.multipliers > 0, it.multipliers + reaction < 0
                if not (lift.any() or press.any()):
                    return it, norm
                new = np.union1d(new, it.pinned[self.local(press, it.pinned)])
                it.pinned = it.pinned[~self.local(lift | press, it.pinned)]
            elif not settled:
                first = next((k for k, old in enumerate(history) if self.same(new, old)), None)
                if first is not None:
                    # The pieces cycle: V has its minimum on (or across) a switch. Hold the
                    # candidates that keep switching on it (g = 0).
                    switching = np.setxor1d(new, history[first])
                    for old in history[first:]:
                        switching = np.union1d(switching, np.setxor1d(old, new))
                    it.pinned = np.union1d(it.pinned, switching)
                    new = np.setdiff1d(new, it.pinned)
                    history = []
                history.append(new)
            elif alpha < 2**-6 and self.count(crossed):
                # Stalled against a switch (the piece does not change, the step is cut ever shorter).
                it.pinned = np.union1d(it.pinned, crossed)
                new = np.setdiff1d(new, it.pinned)
            it.active = new
        raise StaticsError(f"no convergence in {max_iterations} iterations (gradient reduction {norm / norm0:.2e}, "
                           f"target {self.gradient_rtol:g}, {self.count(it.pinned)} candidates held on a contact "
                           "switch): the active set does not settle (the load may be too large or the contact "
                           "boundary wrong)")

    def newton_step(self, u: PETSc.Vec, it: Iterate, rhs: PETSc.Vec, step: PETSc.Vec, iteration: int) -> bool:
        """The (constrained) Newton step of the piece into ``step``, ``rhs`` the force of the
        Lagrangian; sets the multipliers and gaps of the pinned candidates. Returns whether the
        exact Hessian made it (else its Gauss-Newton part). The multipliers are updated from
        those of the last step where the pinned candidates are the same (``_solve``)."""
        same = it.solved is not None and self.same(it.pinned, it.solved)
        previous = it.multipliers if same else np.zeros(self.count(it.pinned))
        it.solved = it.pinned
        for exact in self.tries:
            it.multipliers = np.zeros(0)
            self.dem.force(u, self.t, rhs)
            self.model.add_force(u, rhs, it.active)
            if self.load is not None:
                rhs.axpy(1.0, self.load)
            project(rhs, self.constraints)
            try:
                self._solve(u, it, exact, rhs, step, iteration, previous)
            except StaticsError:
                if exact:
                    continue  # CG broke down on the indefinite exact Hessian: Gauss-Newton
                raise
            if not exact or rhs.dot(step) > 0:
                return exact  # a descent direction (always, with the Gauss-Newton Hessian)
        return False

    def _solve(self, u, it: Iterate, exact: bool, rhs, step, iteration: int, previous: np.ndarray) -> None:
        """H d = F_A with the pinned candidates held on their switch, g_C(u + d) = 0 (g is affine
        along a step), as an update of the multipliers ``previous`` (mu_0, global order):
        d = z_0 - Z delta, H z_0 = F_A - grad g_C^T mu_0 (the force of the Lagrangian at mu_0),
        H Z = P grad g_C, (grad g_C . Z) delta = g_C(u) + grad g_C . z_0, mu = mu_0 + delta.
        The same step as from mu_0 = 0, but each solve's error is relative to its right-hand
        side: near the solution F_A is the pinned candidates' force (O(1)), the Lagrangian's force
        and delta are small, and so is the error they carry into the gradient."""
        dem, model, linear = self.dem, self.model, self.linear
        H = dem.K.copy()
        H.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        model.add_hessian(H, u, it.active, exact)
        H.assemble()
        linear.set_operator(H, self.constraints)
        try:
            if self.count(it.pinned) == 0:
                linear.solve(rhs, step, iteration, check=exact)
                it.gaps = np.zeros(0)
                return
            gradients = model.constraint_gradients(u, it.pinned)
            for g in gradients:
                project(g, self.constraints)
            for m, b in zip(previous, gradients):
                rhs.axpy(-m, b)
            linear.solve(rhs, step, iteration, check=exact)
            Z = [dem.create_vector() for _ in gradients]
            for b, z in zip(gradients, Z):
                linear.solve(b, z, iteration, check=exact)
        finally:
            H.destroy()
        products = model.constraint_products(u, it.pinned, gradients, Z + [step])
        it.gaps = model.constraint_gaps(u, it.pinned)
        delta = np.linalg.solve(products[:, :-1], it.gaps + products[:, -1])
        it.multipliers = previous + delta
        for m, z in zip(delta, Z):
            step.axpy(-m, z)
        for m, b in zip(delta, gradients):
            rhs.axpy(-m, b)  # the force of the Lagrangian: d is a descent direction on g_C = 0

    def line_search(self, u, it: Iterate, rhs, step, trial, iteration: int) -> float:
        """Backtracking (Armijo) on the potential. A decrease predicted below the rounding of V
        (the last Newton steps) cannot be measured: the full step is taken, and so is the first
        step onto newly pinned candidates (it moves them onto their switch). The step is first
        shortened to what the model can follow (``step_ratio``)."""
        slope, v0, alpha = -rhs.dot(step), self.potential(u), 1.0
        ratio = self.model.step_ratio(step)
        if ratio > 1.0:
            step.scale(1.0 / ratio)
            slope /= ratio
        entering = len(it.gaps) and np.abs(it.gaps).max() > 1e-12 * self.model.length_scale
        while -slope > 1e-13 * abs(v0) and not entering:
            u.copy(trial)
            trial.axpy(alpha, step)
            if self.potential(trial) <= v0 + 1e-4 * alpha * slope:
                break
            alpha *= 0.5
            if alpha < 1e-10:
                raise StaticsError(f"iteration {iteration}: the line search found no decrease of the potential")
        return alpha
