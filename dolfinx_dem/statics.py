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
those components at zero (and, for a disc that could roll, the mean rotation): the Krylov solver
(CG, GAMG) works in the subspace of these linear constraints, where H_A is positive definite.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


class StaticsError(RuntimeError):
    """The minimisation failed; the message names the likely cause."""


@dataclasses.dataclass(frozen=True)
class StaticResult:
    u: PETSc.Vec
    iterations: int  # active-set (Newton) iterations
    linear_iterations: int  # CG iterations, summed
    gradient_norm_initial: float
    gradient_norm: float
    energy: float
    contact_facets: int
    wall_time_s: float
    pinned: np.ndarray  # own candidate facets held at g_f = 0 on a kink of V (bool, per own candidate)
    kink_forces: np.ndarray  # contact force (N/m) of each own pinned facet, -mu_f; 0 elsewhere

    @property
    def gradient_reduction(self) -> float:
        return self.gradient_norm / self.gradient_norm_initial


def _constraints(dem, components, rotation):
    """Orthonormal normals w of the linear constraints w . u = 0: the mass-weighted mean
    displacement in ``components`` and, if ``rotation``, the mass-weighted mean rotation
    sum_c m_c (x_c - x_G) x u_c (2D)."""
    d = dem.d
    m = dem.mass.array_r.reshape(-1, d)
    normals = []
    for i in components:
        w = dem.create_vector()
        w.array.reshape(-1, d)[:, i] = m[:, i]
        normals.append(w)
    if rotation:
        if d != 2:
            raise ValueError("fixed_rotation is implemented for 2D bodies")
        xc = dem.geometry.cell_centres[: dem.n_owned]
        mass = dem.comm.allreduce(m[:, 0].sum(), op=MPI.SUM)
        xg = dem.comm.allreduce(m[:, 0] @ xc, op=MPI.SUM) / mass
        w = dem.create_vector()
        w.array.reshape(-1, d)[:] = m * np.stack([-(xc[:, 1] - xg[1]), xc[:, 0] - xg[0]], axis=1)
        normals.append(w)
    for k, w in enumerate(normals):  # Gram-Schmidt
        for v in normals[:k]:
            w.axpy(-w.dot(v), v)
        w.scale(1.0 / w.norm())
    return normals


def _hessian(dem, active):
    """K plus the contact correction for the own facets' active set, as a new PETSc matrix."""
    H = dem.K.copy()
    c = dem.contact
    if c is None or not dem.comm.allreduce(bool(active.any()), op=MPI.LOR):
        return H
    H.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    c.add_hessian(H, active)
    H.assemble()
    return H


def _project(x: PETSc.Vec, normals) -> None:
    """x <- P x, P the orthogonal projector onto {w . x = 0 for the orthonormal normals w}."""
    for w in normals:
        x.axpy(-x.dot(w), w)


class _ConstrainedOperator:
    """P H P + (I - P): symmetric positive definite when H is positive definite on range(P), and
    equal to H on it, so CG on range(P) solves the constrained minimisation."""

    def __init__(self, H, normals):
        self.H, self.normals = H, normals
        self.work = H.createVecRight()

    def mult(self, mat, x, y):
        x.copy(self.work)
        _project(self.work, self.normals)
        self.H.mult(self.work, y)
        _project(y, self.normals)
        y.axpy(1.0, x)
        y.axpy(-1.0, self.work)


def _constrained(H, normals):
    """(operator, preconditioning matrix) for the constrained solve; without constraints H itself.
    The preconditioner is built from H with a tiny diagonal shift, which keeps it definite when
    the constrained directions are in (or near) the null space of H."""
    if not normals:
        return H, H
    shell = PETSc.Mat().createPython(H.getSizes(), _ConstrainedOperator(H, normals), comm=H.getComm())
    shell.setUp()
    P = H.copy()
    diagonal = P.getDiagonal()
    P.shift(1e-8 * diagonal.max()[1])
    return shell, P


def _gap_gradient(dem, facet: tuple[int, int], directions) -> PETSc.Vec:
    """P grad g_f for the candidate ``facet`` = (owner rank, own index): the gradient of its gap
    projected onto the subspace of the linear constraints (collective)."""
    vec = dem.contact.gap_gradient(*facet)
    _project(vec, directions)
    return vec


def _global(comm, mask: np.ndarray) -> list[tuple[int, int]]:
    """The (rank, own index) of the own facets set in ``mask``, on every process, in rank order."""
    return [(r, int(k)) for r, ks in enumerate(comm.allgather(np.flatnonzero(mask))) for k in ks]


def minimise_energy(
    dem,
    fixed_mean: Sequence[int] = (),
    fixed_rotation: bool = False,
    rtol: float = 1e-12,
    max_iterations: int = 50,
) -> StaticResult:
    """Minimise the DEM potential energy at t = 0 (see the module docstring).

    Parameters
    ----------
    dem : DEMDiscretisation, with obstacles if any; contact between bodies is rejected.
    fixed_mean : displacement components whose mass-weighted mean is held at zero (e.g. (0,) for
        the horizontal translation of a body on a frictionless horizontal plane).
    fixed_rotation : hold the mass-weighted mean rotation at zero (2D): a disc on a frictionless
        plane can roll at almost no energy cost (exactly none for a true circle).
    rtol : relative residual of each linear solve (CG).
    max_iterations : active-set iterations allowed.
    """
    d = dem.d
    if any(not (0 <= i < d) for i in fixed_mean):
        raise ValueError(f"fixed_mean components must be in [0, {d}), got {list(fixed_mean)}")
    if not 0 < rtol < 1:
        raise ValueError(f"rtol must lie in (0, 1), got {rtol}")
    if dem.prescribed:
        raise NotImplementedError("minimise_energy does not handle prescribed bodies (a translation imposed "
                                  "in time): use a dynamic run (MEMM)")
    if dem.pair_contact is not None:
        # Its energy is not piecewise quadratic (the overlaps make it quartic in u), so the
        # active-set Newton iteration below does not apply; ignoring it would be a wrong answer.
        raise ValueError("minimise_energy handles rigid obstacles only, not contact between bodies "
                         "(set_contact_boundary): use a dynamic run (MEMM) for contact between bodies")
    comm = dem.comm
    if comm.allreduce(len(dem.reconstruction.dirichlet_facets), op=MPI.SUM) == 0 and dem.contact is None:
        raise StaticsError("the body is free: with neither a Dirichlet condition nor an obstacle its "
                           "rigid motions are unconstrained (unconstrained rigid mode)")
    start = time.perf_counter()
    c = dem.contact
    directions = _constraints(dem, fixed_mean, fixed_rotation)
    same = lambda x, y: comm.allreduce(bool(np.array_equal(x, y)), op=MPI.LAND)  # noqa: E731

    zero, rhs, u = dem.create_vector(), dem.create_vector(), dem.create_vector()  # u starts at 0
    force = dem.create_vector()
    dem.force(zero, 0.0, force)
    _project(force, directions)
    norm0 = force.norm()

    pinned = np.zeros(0, dtype=bool)
    if c is not None:
        # Start from the facets touching the obstacle at u = 0 (smallest gap); the iteration
        # adds the facets the solution pushes into it and releases those it lifts off.
        g = c.own_gaps(zero)
        h = comm.allreduce(dem.geometry.facet_diameters[c.facets[: c.num_own]].min(initial=np.inf), op=MPI.MIN)
        active = g <= comm.allreduce(g.min(initial=np.inf), op=MPI.MIN) + 1e-9 * h
        pinned = np.zeros_like(active)
        history = [active.copy()]
    ksp = PETSc.KSP().create(dem.comm)
    ksp.setType(PETSc.KSP.Type.CG)
    ksp.getPC().setType(PETSc.PC.Type.GAMG)
    ksp.setTolerances(rtol=rtol, atol=0.0, max_it=10000)
    ksp.setOptionsPrefix("dolfinx_dem_statics_")
    ksp.setFromOptions()
    linear_iterations = 0
    step, trial = dem.create_vector(), dem.create_vector()
    multipliers, facets = np.zeros(0), []

    def potential(vec):
        return dem.energies(vec, 0.0)["potential"]

    def solve(b, x, iteration):
        nonlocal linear_iterations
        x.set(0.0)
        ksp.solve(b, x)
        linear_iterations += ksp.getIterationNumber()
        if ksp.getConvergedReason() < 0:
            raise StaticsError(f"the linear solve of active-set iteration {iteration} failed "
                               f"(KSP reason {ksp.getConvergedReason()}): a rigid mode may be unconstrained "
                               "(missing Dirichlet condition, obstacle contact or fixed_mean component)")

    def pinned_values(values: np.ndarray) -> np.ndarray:
        """Per-facet values of the own facets -> the pinned facets' values, in ``facets`` order."""
        return np.concatenate(comm.allgather(values[pinned])) if facets else np.zeros(0)

    for iteration in range(1, max_iterations + 1):
        # Newton step of the quadratic piece A at u: H_A d = F_A(u), with the pinned facets (if
        # any) held on the obstacle, g_C(u + d) = 0, by Lagrange multipliers mu:
        # d = z_0 - Z mu, H_A z_0 = F_A, H_A Z = P grad g_C, (grad g_C . Z) mu = g_C(u) + grad g_C . z_0.
        H = _hessian(dem, active) if c is not None else dem.K
        dem.force(u, 0.0, rhs, contact=False)
        if c is not None:
            c.add_force(u, rhs, active)
        operator, preconditioner = _constrained(H, directions)
        _project(rhs, directions)
        ksp.setOperators(operator, preconditioner)
        solve(rhs, step, iteration)
        if c is None:
            step.copy(u)
            break
        facets = _global(comm, pinned)
        if facets:
            gradients = [_gap_gradient(dem, f, directions) for f in facets]
            Z = [dem.create_vector() for _ in facets]
            for b, z in zip(gradients, Z):
                solve(b, z, iteration)
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
    ksp.destroy()

    # Gradient of the Lagrangian at the end: grad V of the active piece minus the pinned facets'
    # multiplier forces (= grad V itself when no facet is pinned).
    dem.force(u, 0.0, force, contact=False)
    if c is not None:
        c.add_force(u, force, active)
    _project(force, directions)
    kink_forces = np.zeros(c.num_own) if c is not None else np.zeros(0)
    facets = _global(comm, pinned) if c is not None else []
    for (r, k), m in zip(facets, multipliers if facets else []):
        force.axpy(-m, _gap_gradient(dem, (r, k), directions))
        if r == comm.rank:
            kink_forces[k] = -m
    return StaticResult(
        u=u,
        iterations=iteration,
        linear_iterations=linear_iterations,
        gradient_norm_initial=norm0,
        gradient_norm=force.norm(),
        energy=dem.energies(u, 0.0)["potential"],
        contact_facets=comm.allreduce(int((active | pinned).sum()), op=MPI.SUM) if c is not None else 0,
        wall_time_s=time.perf_counter() - start,
        pinned=pinned.copy() if c is not None else np.zeros(0, dtype=bool),
        kink_forces=kink_forces,
    )
