"""Quasi-static DEM: minimise the potential energy (paper §5.2), with or without contact.

The paper minimises the DEM potential with BFGS. With contact the potential has kinks at the
contact switches, where a BFGS line search stalls (docs/validation/hertz.md), so dolfinx_dem
minimises it by an active-set Newton iteration, exact on each piece of the potential and with
the kinks held by Lagrange multipliers (active_set.py), in the subspace that removes the free
rigid motions and the prescribed bodies' dofs (linear.py). Without contact the potential is
quadratic: one linear solve.

The potential is minimised at a load time t: the Dirichlet and traction data are those of time t
and each prescribed body is held at its translation U(t). The force on its dofs at the solution,
without the loads on the body itself, is its reaction, the force it exerts on the other bodies
(``DEMProblem.prescribed_values`` with ``StaticResult.force``).
"""

from __future__ import annotations

import dataclasses
import numbers
import time
from collections.abc import Sequence

import numpy as np
from petsc4py import PETSc

from dolfinx_dem.errors import InputError
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.statics.active_set import ActiveSetNewton, Iterate
from dolfinx_dem.statics.linear import LinearSolver, check_held, project, rigid_mode_constraints

__all__ = ["StaticResult", "minimise_energy"]


@dataclasses.dataclass(frozen=True)
class StaticResult:
    """The minimiser of the potential and how it was found.

    ``active`` and ``pinned`` are pieces in the contact model's form
    (``contact.protocol.StaticContact``): the candidates in contact at the solution, and those
    held on their switch g = 0 on a kink of the potential; ``kink_forces`` the normal contact
    force -mu of each pinned candidate (N, N/m in 2D), their global order, on every process.
    ``force`` is -grad of the Lagrangian at u, not projected: zero on the free dofs up to the
    tolerance, and on a prescribed body's dofs minus its reaction."""

    u: PETSc.Vec
    iterations: int  # active-set (Newton) iterations
    linear_iterations: int  # CG iterations, summed
    gradient_norm_initial: float
    gradient_norm: float
    energy: float
    in_contact: int  # candidates in contact (facets on obstacles, pairs between bodies), pinned ones included
    wall_time_s: float
    active: np.ndarray
    pinned: np.ndarray
    kink_forces: np.ndarray
    force: PETSc.Vec
    gauss_newton_steps: int = 0  # Newton steps taken with the Gauss-Newton Hessian (contact between bodies)

    @property
    def gradient_reduction(self) -> float:
        return self.gradient_norm / self.gradient_norm_initial


def minimise_energy(
    problem: DEMProblem,
    fixed_mean: Sequence[int] = (),
    fixed_rotation: bool = False,
    rtol: float = 1e-12,
    max_iterations: int = 50,
    gradient_rtol: float = 1e-10,
    curvature: bool = True,
    t: float = 0.0,
    normal_step: bool = False,
) -> StaticResult:
    """Minimise the potential energy of ``problem`` at the load time t (module docstring).

    Parameters
    ----------
    problem : a DEMProblem, with at most one contact model (rigid obstacles or contact between
        bodies).
    fixed_mean : displacement components whose mass-weighted mean is held at zero (e.g. (0,) for
        the horizontal translation of a body on a frictionless horizontal plane).
    fixed_rotation : hold the mass-weighted mean rotation at zero (2D): a disc on a frictionless
        plane can roll at almost no energy cost (exactly none for a true circle).
    rtol : relative residual of each linear solve (CG).
    max_iterations : active-set (Newton) iterations allowed.
    gradient_rtol : on pieces that are not quadratic (contact between bodies), the iteration stops
        when the gradient norm of V has fallen by this factor.
    curvature : on such pieces, try the exact Hessian first, falling back to its Gauss-Newton part
        for an iteration where CG breaks down or the step is not a descent direction (default);
        False: the Gauss-Newton part always.
    t : the load time (s): the Dirichlet and traction values of time t (those declared time
        dependent), and the prescribed bodies held at their translation U(t).
    normal_step : the first step of statics with friction (statics/friction.py): the obstacles'
        friction does not act (the normal load is applied on frictionless obstacles).
    """
    if not isinstance(problem, DEMProblem):
        raise InputError(f"minimise_energy takes a DEMProblem, got {type(problem).__name__} (wrap a discretisation "
                         "as DEMProblem(dem) or DEMProblem(dem, contacts))")
    dem, d = problem.dem, problem.d
    if any(not (isinstance(i, numbers.Integral) and 0 <= i < d) for i in fixed_mean):
        raise InputError(f"fixed_mean components must be integers in [0, {d}), got {list(fixed_mean)}")
    if not 0 < rtol < 1:
        raise InputError(f"rtol must lie in (0, 1), got {rtol}")
    if not np.isfinite(t):
        raise InputError(f"the load time t must be finite, got {t}")
    if not 0 < gradient_rtol < 1:
        raise InputError(f"gradient_rtol must lie in (0, 1), got {gradient_rtol}")
    if len(problem.contacts) > 1:
        raise InputError("minimise_energy takes rigid obstacles or contact between bodies, not both")
    if not normal_step and any(c.friction is not None for c in problem.contacts):
        raise InputError("minimise_energy: friction is path dependent: statics with friction (obstacles, bodies) "
                         "takes a load path (statics.friction.load_tangentially), or integrate it in time with MEMM")
    models = [c.statics() for c in problem.contacts]
    if not models:
        check_held(dem, fixed_mean, fixed_rotation)
    start = time.perf_counter()
    constraints = rigid_mode_constraints(dem, fixed_mean, fixed_rotation)

    # u starts at 0, the prescribed bodies at U(t)
    u, force = dem.create_vector(), dem.create_vector()
    dem.prescribed.hold(u, t)
    for model in models:
        model.prepare(u)
    problem.force(u, t, force)
    project(force, constraints)
    norm0 = force.norm()
    linear = LinearSolver(dem, rtol)
    if models:
        newton = ActiveSetNewton(problem, models[0], t, constraints, linear, gradient_rtol, curvature)
        it = newton.run(u, norm0, max_iterations)[0]
        newton.lagrangian_force(u, it, force, project_it=False)
        in_contact = newton.count(it.active) + newton.count(it.pinned)
    else:  # a quadratic potential: one linear solve
        rhs, step = dem.create_vector(), dem.create_vector()
        dem.force(u, t, rhs)
        project(rhs, constraints)
        linear.set_operator(dem.K, constraints)
        linear.solve(rhs, step, 1)
        u.axpy(1.0, step)
        dem.force(u, t, force)
        it, in_contact = Iterate(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0),
                                 iterations=1), 0
    linear.destroy()
    gradient = force.copy()
    project(gradient, constraints)
    return StaticResult(
        u=u,
        iterations=it.iterations,
        linear_iterations=linear.iterations,
        gradient_norm_initial=norm0,
        gradient_norm=gradient.norm(),
        energy=problem.energies(u, t)["potential"],
        in_contact=in_contact,
        wall_time_s=time.perf_counter() - start,
        active=it.active,
        pinned=it.pinned,
        kink_forces=-it.multipliers,
        force=force,
        gauss_newton_steps=it.gauss_newton_steps,
    )
