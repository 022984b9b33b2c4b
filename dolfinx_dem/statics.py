"""Quasi-static DEM: minimise the potential energy (paper §5.2).

With rigid-obstacle contact the potential V(u) = E_P + E_S + external is continuous and piecewise
quadratic: quadratic for every fixed set A of facets in contact (contact.py). Its gradient jumps
across a contact switch g_f = 0 (by the force r_f the facet would carry in contact), so V has a
kink there. dolfinx_dem minimises it by an active-set Newton iteration, exact on each piece:

    A_0 = the facets touching the obstacle at u_0 = 0,
    solve H_A d = F_A(u_k)        (H_A = K + contact correction, F_A = -grad V_A; one linear solve),
    u_{k+1} = u_k + alpha d        (alpha from backtracking on V: 1 unless d overshoots a switch),
    A_{k+1} = {f : g_f(u_{k+1}) < 0}, until a full step leaves A unchanged.

At the end u minimises V_A and every facet is on the side of the switch that A says, so the
gradient of V vanishes to the accuracy of the linear solve. The line search on the continuous
potential makes the iteration a descent method.

Kinks. The minimum of V can sit on a switch: then no point has a zero gradient, and the iteration
returns to an earlier contact set (measured: scheme B on the Hertz disc, h = 3.75e-3 m, three
facets at the edge of the contact zone). When the set repeats, the facets that switched since its
first occurrence are pinned, g_f = 0 for f in C, and the Newton step becomes the equality-
constrained one, with Lagrange multipliers mu (|C| extra solves, a |C| x |C| Schur complement):

    H_A z_0 = F_A,   H_A z_f = P grad g_f,   (grad g_C . Z) mu = g_C(u) + grad g_C . z_0,   d = z_0 - Z mu.

At its solution the directional derivatives of V must be >= 0 on both sides of each pinned
facet's switch: towards lifting off (g_f > 0) it is -mu_f, towards pressing in mu_f + r_f, so
-r_f <= mu_f <= 0. The pinned facet then carries the contact force -mu_f, between 0 and r_f. A facet
with mu_f > 0 is released, one with mu_f + r_f < 0 is put in contact, and the iteration goes on.
The reported gradient norm is that of the Lagrangian (grad V_A + sum mu_f grad g_f), the
gradient of V itself when nothing is pinned.

The issue asks for a BFGS-type solver of PETSc TAO. Measured on the Hertz disc: LMVM (BFGS)
stalled at a gradient reduction of 7e-7 (More-Thuente line search failure after 5,000
iterations) or 9e-8 (BLMVM, 100,000 iterations) on h = 1.5e-2; the kinks of V and the rounding
of V near the minimum defeat its line search. TAO's NLS (Newton line search) with this module's
exact active-set Hessian (shell P H_A P + (I - P), CG + GAMG) reaches the 1e-8 reduction for
scheme A (h = 1.5e-2 to 1.875e-3 m: 3, 4, 6, 8 iterations, reductions 1.7e-9 to 1.0e-10) but
stops with a line search failure on the kink of scheme B (h = 3.75e-3 m, gradient norm 2.3e3,
no reduction, after 12 iterations): an unconstrained TAO solver has no stationary point to find
there. The active-set iteration above, with the kink treatment, is kept for both schemes.

Rigid translations that neither a Dirichlet condition nor contact fixes (the horizontal motion of
a disc on a frictionless plane) are removed by holding the mass-weighted mean displacement in
those components at zero (and, for a disc that could roll, the mean rotation), for each body
without a Dirichlet condition: the Krylov solver (CG, GAMG) works in the subspace of these
linear constraints, where H_A is positive definite.

Contact between bodies (``pair_contact.PairContact``, paper §3.4.3, eq. (30)-(34)). The
potential is that of the dynamics, V = 1/2 |a + delta_a|^2 + external, delta_a = sum_p c_p z_p,
c_p = w_p g_p^-. On a piece A (the pairs in contact and the overlap configuration fixed) g_p and
w_p are affine, c_p = w_p g_p is quadratic and V quartic, so the iteration is a damped Newton
method on the pieces rather than one solve per piece:

    H d = F_A(u)   with H = J^T J + sum_p mu_p (grad w_p grad g_p^T + grad g_p grad w_p^T),
                   J = Q + sum_p z_p grad c_p^T, mu_p = z_p . (a + delta_a)   (exact Hessian),
    or H = J^T J (Gauss-Newton part, positive semi-definite) when CG breaks down on the exact
    one or its step is not a descent direction; u += alpha d, alpha by backtracking on V;
    A = {g_p(u) < 0, w_p > 0}, until the gradient has fallen by ``gradient_rtol``.

Active sets are sorted arrays of pair keys (the pairs' global facet numbers): the Verlet list is
rebuilt at any trial point where facets moved more than half their skins, and no step may move a
facet by more than half its skin (bodies must not pass through each other, where V is unbounded below). The
kinks at g_p = 0 get the treatment above, pairs in place of facets: pairs that keep switching
(the set of pairs in contact returns to an earlier one), or against whose switch the line search
stalls, are pinned on g_p = 0 by multipliers, with the same kink conditions (-mu_p between 0 and
the force r_p = -w_p z_p . (a + delta_a) the pair would carry in contact).

Prescribed bodies (``discretisation.PrescribedBody``, paper eq. (35b) for their dynamics). The
potential is minimised at a load time t: the Dirichlet and traction data are those of time t and
each prescribed body is held at its translation U(t). The iteration starts from u holding U(t)
on their dofs p and works in the subspace {d_p = 0}: ``_Constraints`` zeroes those dofs in every
right-hand side, step and gap gradient (the projector of the linear constraints above is extended
by the coordinate projector onto d_p = 0, which commutes with it: the constraint normals vanish on
prescribed bodies), the constrained operator is the identity on them, and the gradient norm leaves
them out. The force on their dofs is the reaction: a prescribed body's reaction
(``DEMDiscretisation.prescribed_values``) is dV/dU, the force it exerts on the other bodies, as in
the dynamics.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc
from dolfinx_dem.contact import PairContact, RigidContact
from dolfinx_dem.errors import InputError, StaticsError
from dolfinx_dem.problem import DEMProblem


@dataclasses.dataclass(frozen=True)
class StaticResult:
    u: PETSc.Vec
    iterations: int  # active-set (Newton) iterations
    linear_iterations: int  # CG iterations, summed
    gradient_norm_initial: float
    gradient_norm: float
    energy: float
    contact_facets: int  # facets in contact (obstacles), or pairs in contact (between bodies), pinned ones included
    wall_time_s: float
    # Obstacles: own candidate facets held at g_f = 0 on a kink of V (bool, per own candidate) and
    # the contact force (N/m) of each, -mu_f (0 elsewhere). Contact between bodies: the sorted
    # keys (PairContact.pair_keys) of the pairs held at g_p = 0, the same on every process, and
    # the normal contact force of each, -mu_p.
    pinned: np.ndarray
    kink_forces: np.ndarray
    # -grad of the Lagrangian at u, not projected: zero on the free dofs up to the tolerance, and on
    # a prescribed body's dofs minus its reaction (DEMDiscretisation.prescribed_values(u, t, force))
    force: PETSc.Vec
    gauss_newton_steps: int = 0  # contact between bodies: Newton steps taken with the Gauss-Newton H
    contact_pairs: np.ndarray | None = None  # contact between bodies: keys of the pairs in contact (not pinned)

    @property
    def gradient_reduction(self) -> float:
        return self.gradient_norm / self.gradient_norm_initial


@dataclasses.dataclass(frozen=True)
class _Constraints:
    """The subspace of the steps: w . d = 0 for the orthonormal ``normals`` w (``_constraints``)
    and d = 0 on the ``held`` dofs (owned, local: the prescribed bodies'), on which the normals
    vanish (module docstring). ``holds``: whether any process holds dofs (the same everywhere:
    collective calls depend on it)."""

    normals: list
    held: np.ndarray
    holds: bool

    def __bool__(self) -> bool:
        return bool(self.normals) or self.holds


def _constraints(dem, components, rotation) -> _Constraints:
    """The normals w of the linear constraints w . u = 0 (orthonormal), for each body (connected
    component) without a Dirichlet condition or a prescribed motion: its mass-weighted mean displacement in
    ``components`` and, if ``rotation``, its mass-weighted mean rotation sum_c m_c (x_c - x_G) x
    u_c (2D). Bodies held by a Dirichlet condition get none: a constraint there would add a
    spurious force (a body pressed on a clamped one must not share its constraints)."""
    d, geom = dem.d, dem.geometry
    if rotation and d != 2:
        raise InputError("fixed_rotation is implemented for 2D bodies")
    m = dem.mass.array_r.reshape(-1, d)
    body = geom.cell_bodies[: dem.n_owned]
    held = np.zeros(geom.num_bodies, dtype=np.int64)
    held[geom.cell_bodies[geom.facet_cells[dem.reconstruction.dirichlet_facets, 0]]] = 1
    held[dem.prescribed.body_numbers] = 1
    comm = dem.comm
    comm.Allreduce(MPI.IN_PLACE, held, op=MPI.MAX)
    normals = []
    for b in np.flatnonzero(held == 0):
        mine = body == b
        for i in components:
            w = dem.create_vector()
            w.array.reshape(-1, d)[mine, i] = m[mine, i]
            normals.append(w)
        if rotation:
            xc = geom.cell_centres[: dem.n_owned]
            mb = np.where(mine, m[:, 0], 0.0)
            xg = comm.allreduce(mb @ xc, op=MPI.SUM) / comm.allreduce(mb.sum(), op=MPI.SUM)
            w = dem.create_vector()
            w.array.reshape(-1, d)[:] = mb[:, None] * np.stack([-(xc[:, 1] - xg[1]), xc[:, 0] - xg[0]], axis=1)
            normals.append(w)
    for k, w in enumerate(normals):  # Gram-Schmidt
        for v in normals[:k]:
            w.axpy(-w.dot(v), v)
        w.scale(1.0 / w.norm())
    return _Constraints(normals, dem.prescribed.dofs, bool(dem.prescribed))


def _hessian(dem, c, active):
    """K plus the correction of the rigid contact ``c`` for the own facets' active set, as a new
    PETSc matrix."""
    H = dem.K.copy()
    if c is None or not dem.comm.allreduce(bool(active.any()), op=MPI.LOR):
        return H
    H.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    c.add_hessian(H, active)
    H.assemble()
    return H


def _project(x: PETSc.Vec, constraints: _Constraints) -> None:
    """x <- P x, P the orthogonal projector onto the subspace of ``constraints``: x_p = 0 on the
    held dofs, and w . x = 0 for the orthonormal normals w, with one reduction for all the normals
    (CG applies P twice per iteration; in parallel the latency of the reductions dominated)."""
    x.array[constraints.held] = 0.0
    normals = constraints.normals
    if normals:
        dots = np.array([w.array_r @ x.array_r for w in normals])
        x.getComm().tompi4py().Allreduce(MPI.IN_PLACE, dots, op=MPI.SUM)
        x.maxpy(-dots, normals)


class _ConstrainedOperator:
    """P H P + (I - P): symmetric positive definite when H is positive definite on range(P), and
    equal to H on it (the identity on the held dofs and the normals), so CG on range(P) solves the
    constrained minimisation."""

    def __init__(self, H, constraints: _Constraints):
        self.H, self.constraints = H, constraints
        self.work = H.createVecRight()

    def mult(self, mat, x, y):
        x.copy(self.work)
        _project(self.work, self.constraints)
        self.H.mult(self.work, y)
        _project(y, self.constraints)
        y.axpy(1.0, x)
        y.axpy(-1.0, self.work)


def _constrained(H, constraints: _Constraints):
    """(operator, preconditioning matrix) for the constrained solve; without constraints H itself.
    The preconditioner is built from H with the held rows and columns replaced by the identity's
    (exactly P H P + (I - P) for them) and, with normals, a tiny diagonal shift, which keeps it
    definite when the constrained directions are in (or near) the null space of H."""
    if not constraints:
        return H, H
    shell = PETSc.Mat().createPython(H.getSizes(), _ConstrainedOperator(H, constraints), comm=H.getComm())
    shell.setUp()
    P = H.copy()
    if constraints.holds:
        P.zeroRowsColumns((constraints.held + H.getOwnershipRange()[0]).astype(PETSc.IntType), diag=1.0)
    if constraints.normals:
        diagonal = P.getDiagonal()
        P.shift(1e-8 * diagonal.max()[1])
    return shell, P


class _Linear:
    """The linear solves of the minimisation: CG + GAMG on the constrained operator of H
    (options prefix ``dolfinx_dem_statics_``); counts the iterations, and a failed solve is a
    StaticsError."""

    def __init__(self, dem, rtol: float):
        self.ksp = ksp = PETSc.KSP().create(dem.comm)
        ksp.setType(PETSc.KSP.Type.CG)
        ksp.getPC().setType(PETSc.PC.Type.GAMG)
        ksp.setTolerances(rtol=rtol, atol=0.0, max_it=10000)
        ksp.setOptionsPrefix("dolfinx_dem_statics_")
        ksp.setFromOptions()
        self.iterations = 0

    def set_operator(self, H, constraints: _Constraints) -> None:
        self.ksp.setOperators(*_constrained(H, constraints))
        self.held = constraints.held

    def solve(self, b, x, iteration: int, check: bool = False) -> None:
        """x = A^-1 b; ``check``: also fail when the true residual exceeds 1e3 rtol |b| (CG
        preconditioned by an indefinite matrix can report convergence in its preconditioned norm
        and be far off)."""
        x.set(0.0)
        self.ksp.solve(b, x)
        x.array[self.held] = 0.0  # the step leaves the prescribed bodies where they are
        self.iterations += self.ksp.getIterationNumber()
        reason = self.ksp.getConvergedReason()
        if check and reason >= 0:
            r = b.duplicate()
            self.ksp.getOperators()[0].mult(x, r)
            r.axpy(-1.0, b)
            if r.norm() > 1e3 * self.ksp.getTolerances()[0] * b.norm():
                reason = -100
        if reason < 0:
            raise StaticsError(f"the linear solve of iteration {iteration} failed (KSP reason {reason}): a rigid "
                               "mode may be unconstrained (missing Dirichlet condition, contact or fixed_mean "
                               "component), or the Hessian is indefinite")

    def destroy(self) -> None:
        self.ksp.destroy()


def _gap_gradient(c, facet: tuple[int, int], directions) -> PETSc.Vec:
    """P grad g_f for the candidate ``facet`` = (owner rank, own index): the gradient of its gap
    projected onto the subspace of the linear constraints (collective)."""
    vec = c.gap_gradient(*facet)
    _project(vec, directions)
    return vec


def _global(comm, mask: np.ndarray) -> list[tuple[int, int]]:
    """The (rank, own index) of the own facets set in ``mask``, on every process, in rank order."""
    return [(r, int(k)) for r, ks in enumerate(comm.allgather(np.flatnonzero(mask))) for k in ks]


def minimise_energy(
    problem: DEMProblem,
    fixed_mean: Sequence[int] = (),
    fixed_rotation: bool = False,
    rtol: float = 1e-12,
    max_iterations: int = 50,
    gradient_rtol: float = 1e-10,
    curvature: bool = True,
    t: float = 0.0,
) -> StaticResult:
    """Minimise the DEM potential energy at the load time t (see the module docstring).

    Parameters
    ----------
    problem : a DEMProblem, with rigid obstacles or contact between bodies (not both) if any.
    fixed_mean : displacement components whose mass-weighted mean is held at zero (e.g. (0,) for
        the horizontal translation of a body on a frictionless horizontal plane).
    fixed_rotation : hold the mass-weighted mean rotation at zero (2D): a disc on a frictionless
        plane can roll at almost no energy cost (exactly none for a true circle).
    rtol : relative residual of each linear solve (CG).
    max_iterations : active-set (Newton) iterations allowed.
    gradient_rtol : contact between bodies only: the iteration stops when the gradient norm of V
        has fallen by this factor (its pieces are quartic: Newton takes several steps).
    curvature : contact between bodies only: try the exact Hessian of the piece first, falling
        back to its Gauss-Newton part for an iteration where CG breaks down or the step is not a
        descent direction (default); False: the Gauss-Newton part always (module docstring).
    t : the load time (s): the Dirichlet and traction values of time t (those declared time
        dependent), and the prescribed bodies held at their translation U(t).
    """
    dem, d = problem.dem, problem.d
    c, pc = problem.find(RigidContact), problem.find(PairContact)
    if any(not (0 <= i < d) for i in fixed_mean):
        raise InputError(f"fixed_mean components must be in [0, {d}), got {list(fixed_mean)}")
    if not 0 < rtol < 1:
        raise InputError(f"rtol must lie in (0, 1), got {rtol}")
    if not np.isfinite(t):
        raise InputError(f"the load time t must be finite, got {t}")
    if pc is not None and d != 2:
        # In 3D the overlaps are quadratic in u on a piece: the Hessian below assumes them affine.
        raise InputError("statics with contact between bodies is implemented in 2D, not 3D")
    if pc is not None and c is not None:
        raise InputError("minimise_energy takes rigid obstacles or contact between bodies, not both")
    if not 0 < gradient_rtol < 1:
        raise InputError(f"gradient_rtol must lie in (0, 1), got {gradient_rtol}")
    comm = dem.comm
    if comm.allreduce(len(dem.reconstruction.dirichlet_facets), op=MPI.SUM) == 0 and not problem.contacts:
        raise StaticsError("the body is free: with neither a Dirichlet condition nor an obstacle its "
                           "rigid motions are unconstrained (unconstrained rigid mode)")
    start = time.perf_counter()
    directions = _constraints(dem, fixed_mean, fixed_rotation)
    same = lambda x, y: comm.allreduce(bool(np.array_equal(x, y)), op=MPI.LAND)  # noqa: E731

    # u starts at 0, the prescribed bodies at U(t)
    rhs, u, force = dem.create_vector(), dem.create_vector(), dem.create_vector()
    dem.prescribed.hold(u, t)
    if pc is not None:
        pc.prepare(u)
    problem.force(u, t, force)
    _project(force, directions)
    norm0 = force.norm()
    if pc is not None:
        return _minimise_pairs(problem, u, t, directions, norm0, _Linear(dem, rtol), gradient_rtol, curvature,
                               max_iterations, start)

    pinned = np.zeros(0, dtype=bool)
    if c is not None:
        # Start from the facets touching the obstacle at u = 0 (smallest gap); the iteration
        # adds the facets the solution pushes into it and releases those it lifts off.
        g = c.own_gaps(u)
        h = comm.allreduce(dem.geometry.facet_diameters[c.facets[: c.num_own]].min(initial=np.inf), op=MPI.MIN)
        active = g <= comm.allreduce(g.min(initial=np.inf), op=MPI.MIN) + 1e-9 * h
        pinned = np.zeros_like(active)
        history = [active.copy()]
    linear = _Linear(dem, rtol)
    step, trial = dem.create_vector(), dem.create_vector()
    multipliers, facets = np.zeros(0), []

    def potential(vec):
        return problem.energies(vec, t)["potential"]

    def pinned_values(values: np.ndarray) -> np.ndarray:
        """Per-facet values of the own facets -> the pinned facets' values, in ``facets`` order."""
        return np.concatenate(comm.allgather(values[pinned])) if facets else np.zeros(0)

    for iteration in range(1, max_iterations + 1):
        # Newton step of the quadratic piece A at u: H_A d = F_A(u), with the pinned facets (if
        # any) held on the obstacle, g_C(u + d) = 0, by Lagrange multipliers mu:
        # d = z_0 - Z mu, H_A z_0 = F_A, H_A Z = P grad g_C, (grad g_C . Z) mu = g_C(u) + grad g_C . z_0.
        H = _hessian(dem, c, active) if c is not None else dem.K
        dem.force(u, t, rhs)
        if c is not None:
            c.add_force(u, rhs, active)
        _project(rhs, directions)
        linear.set_operator(H, directions)
        linear.solve(rhs, step, iteration)
        if c is None:
            u.axpy(1.0, step)
            break
        facets = _global(comm, pinned)
        if facets:
            gradients = [_gap_gradient(c, f, directions) for f in facets]
            Z = [dem.create_vector() for _ in facets]
            for b, z in zip(gradients, Z):
                linear.solve(b, z, iteration)
            own = np.flatnonzero(pinned)
            # patch values are gathered collectively: once per vector on every process
            zp, sp = [c.patch_values(z) for z in Z], c.patch_values(step)
            S = np.concatenate(comm.allgather(np.array(
                [[c.gap_gradient_dot(k, p) for p in zp] for k in own]).reshape(len(own), len(Z))))
            step_dot = pinned_values(np.array([c.gap_gradient_dot(k, sp) if p else 0.0 for k, p in enumerate(pinned)]))
            multipliers = np.linalg.solve(S, pinned_values(c.own_gaps(u)) + step_dot)
            for m, z in zip(multipliers, Z):
                step.axpy(-m, z)
            for m, b in zip(multipliers, gradients):
                rhs.axpy(-m, b)  # the gradient of the Lagrangian: d is a descent direction on g_C = 0
        # Backtracking (Armijo) on the continuous potential: the full step when the contact set
        # does not change, a shorter one when it overshoots a switch. The first step onto newly
        # pinned facets is taken in full (it moves them onto the obstacle).
        slope, v0, alpha = -rhs.dot(step), potential(u), 1.0
        entering = bool(facets) and np.abs(pinned_values(c.own_gaps(u))).max() > 1e-12 * h
        while not entering:
            u.copy(trial)
            trial.axpy(alpha, step)
            if potential(trial) <= v0 + 1e-4 * alpha * slope or alpha < 1e-8:
                break
            alpha *= 0.5
        u.axpy(alpha, step)
        new = (c.own_gaps(u) < 0) & ~pinned
        if not comm.allreduce(bool((new | pinned).any()), op=MPI.LOR):
            raise StaticsError("no facet is in contact at the solution: the obstacle does not hold the "
                               "body (check the contact candidate boundary and the load direction)")
        converged = alpha == 1.0 and same(new, active)
        if converged and facets:
            # Kink conditions of the pinned facets (g_f = 0): the directional derivatives of V
            # towards lifting off (-mu_f) and towards pressing in (mu_f + r_f, r_f the force the
            # facet would carry in contact) must both be >= 0.
            reaction = pinned_values(c.reactions(u, active | pinned))
            lift, press = multipliers > 0, multipliers + reaction < 0
            if lift.any() or press.any():
                converged = False
                own = np.flatnonzero(pinned)
                mine = np.array([r == comm.rank for r, _ in facets])
                pinned[own[(lift | press)[mine]]] = False
                new[own[press[mine]]] = True
        elif not converged and any(same(new, old) for old in history):
            # The active set returns to an earlier state: V has its minimum on (or across) a
            # contact switch. Hold the facets that keep switching on the obstacle (g_f = 0).
            first = next(k for k, old in enumerate(history) if same(new, old))
            switching = np.zeros_like(new)
            for old in history[first:]:
                switching |= old != new
            pinned |= switching
            new &= ~pinned
            history = []
        active = new
        history.append(active.copy())
        if converged:
            break
    else:
        raise StaticsError(f"the active set did not settle in {max_iterations} iterations (cycling between "
                           "contact states: the load may be too large or the contact tag wrong)")
    linear.destroy()

    # Gradient of the Lagrangian at the end: grad V of the active piece minus the pinned facets'
    # multiplier forces (= grad V itself when no facet is pinned).
    dem.force(u, t, force)
    if c is not None:
        c.add_force(u, force, active)
    kink_forces = np.zeros(c.num_own) if c is not None else np.zeros(0)
    facets = _global(comm, pinned) if c is not None else []
    for (r, k), m in zip(facets, multipliers if facets else []):
        force.axpy(-m, c.gap_gradient(r, k))
        if r == comm.rank:
            kink_forces[k] = -m
    gradient = force.copy()
    _project(gradient, directions)
    return StaticResult(
        u=u,
        iterations=iteration,
        linear_iterations=linear.iterations,
        gradient_norm_initial=norm0,
        gradient_norm=gradient.norm(),
        energy=problem.energies(u, t)["potential"],
        contact_facets=comm.allreduce(int((active | pinned).sum()), op=MPI.SUM) if c is not None else 0,
        wall_time_s=time.perf_counter() - start,
        pinned=pinned.copy() if c is not None else np.zeros(0, dtype=bool),
        kink_forces=kink_forces,
        force=force,
    )


def _minimise_pairs(problem: DEMProblem, u, t: float, directions, norm0: float, linear: _Linear, gradient_rtol: float,
                    curvature: bool, max_iterations: int, start: float) -> StaticResult:
    """Damped Newton on the pieces of the potential with contact between bodies from ``u`` (the
    start, updated in place) at the load time t, pairs keyed by ``PairContact.pair_keys``, kinks
    held by multipliers (module docstring, "Contact between bodies")."""
    dem, comm, pc = problem.dem, problem.comm, problem.find(PairContact)
    rhs, step, trial = (dem.create_vector() for _ in range(3))
    up = pc.prepare(u)[0]
    # Start from the overlapping pairs of smallest gap (as for obstacles): the piece that holds
    # a body which only contact holds; or from the pairs in contact at the start, where a
    # prescribed body held at U(t) penetrates another.
    active = pc.touching_pairs(up, max(0.0, pc.smallest_gap(up) + 1e-9 * pc.skin))
    if len(active) == 0:
        raise StaticsError("no pair of contact candidate facets faces another: contact between bodies cannot "
                           "hold them (check the contact boundary)")
    pinned, multipliers = np.zeros(0, dtype=np.int64), np.zeros(0)
    history = [active]

    def potential(vec) -> float:
        pc.prepare(vec)  # a trial point may move facets by more than skin/2: rebuild the list
        return problem.energies(vec, t)["potential"]

    def lagrangian_force(vec, out, project: bool = True) -> None:
        """out = -grad V_A(vec) - sum_C mu_p grad g_p, projected unless not ``project`` (-grad V
        without pinned pairs)."""
        dem.force(vec, t, out)
        pc.add_force(vec, out, active)
        for key, m in zip(pinned, multipliers):
            out.axpy(-m, pc.gap_gradient(pc.patch_values(vec), key))
        if project:
            _project(out, directions)

    norm, gauss_newton_steps = norm0, 0
    for iteration in range(1, max_iterations + 1):
        # Newton step on the piece A: H d = F_A(u) (H its Gauss-Newton or exact Hessian), with
        # the pinned pairs C held on their switch, g_C(u + d) = 0 (g is affine), as for obstacles:
        # d = z_0 - Z mu, H z_0 = F_A, H Z = P grad g_C, (grad g_C . Z) mu = g_C(u) + grad g_C . z_0.
        up = pc.patch_values(u)
        for exact in (True, False) if curvature else (False,):
            multipliers = np.zeros(0)
            lagrangian_force(u, rhs)
            try:
                multipliers, gaps = _newton_step(dem, directions, linear, pc, up, active, pinned, exact, rhs, step,
                                                 iteration)
            except StaticsError:
                if exact:
                    continue  # CG broke down on the indefinite exact Hessian: Gauss-Newton
                raise
            if not exact or rhs.dot(step) > 0:
                break  # a descent direction (always, with the positive semi-definite Gauss-Newton H)
        gauss_newton_steps += not exact
        # Backtracking (Armijo) on the potential of the dynamics. A decrease predicted below the
        # rounding of V (the last Newton steps) cannot be measured: the full step is taken, and
        # so is the first step onto newly pinned pairs (it moves them onto their switch).
        slope, v0, alpha = -rhs.dot(step), potential(u), 1.0
        # No facet may move more than half its skin in one step: the pairs it would meet are then all in
        # the list built at u, and a long step (a piece that holds a body weakly, e.g. by a pair
        # of small overlap) cannot carry one body through another, where V is not bounded below.
        ratio = pc.motion_ratio(pc.patch_values(step))
        if ratio > 1.0:
            step.scale(1.0 / ratio)
            slope /= ratio
        entering = len(pinned) and np.abs(gaps).max() > 1e-12 * pc.skin
        while -slope > 1e-13 * abs(v0) and not entering:
            u.copy(trial)
            trial.axpy(alpha, step)
            if potential(trial) <= v0 + 1e-4 * alpha * slope:
                break
            alpha *= 0.5
            if alpha < 1e-10:
                raise StaticsError(f"iteration {iteration}: the line search found no decrease of the potential")
        # The pairs whose switch the full step crosses before alpha: a step cut this short sits
        # against one (a kink of V), to be pinned if the iteration stalls there.
        up = pc.prepare(u)[0]  # the line search may have rebuilt the list elsewhere
        crossed = pc.switches_crossed(up, pc.patch_values(step), alpha, np.union1d(active, pinned))
        u.axpy(alpha, step)
        up = pc.prepare(u)[0]
        new = np.setdiff1d(pc.touching_pairs(up), pinned)
        lagrangian_force(u, rhs)
        norm = rhs.norm()

        if len(new) + len(pinned) == 0:
            raise StaticsError("no pair is in contact: contact between bodies does not hold them (check the "
                               "contact boundary and the load direction)")
        if norm <= gradient_rtol * norm0 and np.array_equal(new, active):
            if len(pinned) == 0:
                break
            # Kink conditions of the pinned pairs (g_p = 0): the directional derivatives of V
            # towards lifting off (-mu_p) and towards pressing in (mu_p + r_p) must be >= 0.
            reaction = pc.pinned_values(up, active, pinned)[1]
            lift, press = multipliers > 0, multipliers + reaction < 0
            if not (lift.any() or press.any()):
                break
            new = np.union1d(new, pinned[press])
            pinned = pinned[~(lift | press)]
        elif not np.array_equal(new, active):
            if any(np.array_equal(new, old) for old in history):
                # The pieces cycle: V has its minimum on (or across) a contact switch. Hold the
                # pairs that keep switching on it (g_p = 0).
                first = next(k for k, old in enumerate(history) if np.array_equal(new, old))
                switching = np.setxor1d(new, history[first])
                for old in history[first:]:
                    switching = np.union1d(switching, np.setxor1d(old, new))
                pinned = np.union1d(pinned, switching)
                new = np.setdiff1d(new, pinned)
                history = []
            history.append(new)
        elif alpha < 2**-6 and len(crossed):
            # Stalled against a switch (the set does not change, the step is cut ever shorter).
            pinned = np.union1d(pinned, crossed)
            new = np.setdiff1d(new, pinned)
        active = new
    else:
        raise StaticsError(f"no convergence in {max_iterations} iterations (gradient reduction {norm / norm0:.2e}, "
                           f"target {gradient_rtol:g}, {len(pinned)} pairs held on a contact switch)")
    linear.destroy()
    force = dem.create_vector()
    lagrangian_force(u, force, project=False)
    return StaticResult(
        u=u,
        iterations=iteration,
        linear_iterations=linear.iterations,
        gradient_norm_initial=norm0,
        gradient_norm=norm,
        energy=problem.energies(u, t)["potential"],
        contact_facets=len(active) + len(pinned),
        wall_time_s=time.perf_counter() - start,
        pinned=pinned,
        kink_forces=-multipliers,
        force=force,
        gauss_newton_steps=gauss_newton_steps,
        contact_pairs=active,
    )


def _newton_step(dem, directions, linear, pc, up, active, pinned, exact, rhs, step, iteration):
    """The (constrained) Newton step of ``_minimise_pairs`` into ``step``; ``rhs`` becomes the
    force of the Lagrangian. Returns (multipliers, gaps) of the pinned pairs."""
    H = dem.K.copy()
    H.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    pc.add_hessian(H, up, active, exact)
    H.assemble()
    linear.set_operator(H, directions)
    try:
        linear.solve(rhs, step, iteration, check=exact)
        if len(pinned) == 0:
            return np.zeros(0), np.zeros(0)
        gradients = [_projected(pc.gap_gradient(up, key), directions) for key in pinned]
        Z = [dem.create_vector() for _ in pinned]
        for b, z in zip(gradients, Z):
            linear.solve(b, z, iteration, check=exact)
    finally:
        H.destroy()
    S = np.array([[b.dot(z) for z in Z] for b in gradients])
    gaps = pc.pinned_values(up, active, pinned)[0]
    multipliers = np.linalg.solve(S, gaps + np.array([b.dot(step) for b in gradients]))
    for m, z, b in zip(multipliers, Z, gradients):
        step.axpy(-m, z)
        rhs.axpy(-m, b)  # the force of the Lagrangian: d is a descent direction on g_C = 0
    return multipliers, gaps


def _projected(vec: PETSc.Vec, constraints: _Constraints) -> PETSc.Vec:
    """``vec`` after ``_project``."""
    _project(vec, constraints)
    return vec
