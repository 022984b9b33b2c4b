"""Quasi-static DEM: minimise the potential energy (paper §5.2).

With rigid-obstacle contact the potential V(u) = E_P + E_S + external is continuous and piecewise
quadratic: quadratic for every fixed set A of facets in contact (contact.py). dolfinx_dem
minimises it by an active-set Newton iteration, exact on each piece:

    A_0 = the facets touching the obstacle at u_0 = 0,
    solve H_A d = F_A(u_k)        (H_A = K + contact correction, F_A = -grad V_A; one linear solve),
    u_{k+1} = u_k + alpha d        (alpha from backtracking on V: 1 unless d overshoots a switch),
    A_{k+1} = {f : g_f(u_{k+1}) < 0}, until a full step leaves A unchanged.

At the end u minimises V_A and every facet is on the side of the switch that A says, so the
gradient of V vanishes to the accuracy of the linear solve. The line search on the continuous
potential makes the iteration a descent method: it cannot cycle between contact sets. The paper uses BFGS;
PETSc TAO's LMVM (BFGS) was measured on the Hertz disc (h = 1.5e-2, 1,300 cells) and stalled at a
gradient reduction of 7e-7 (More-Thuente line search failure after 5,000 iterations) or 9e-8
(BLMVM, 100,000 iterations): the kinks of V at the contact switches and the rounding of V near
the minimum defeat its line search. The exact Newton iteration needs a handful of solves.

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
        xc = dem.geometry.cell_centres[dem.cell_range[0] : dem.cell_range[1]]
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
    """K plus the contact correction for the active set, as a new PETSc matrix."""
    H = dem.K.copy()
    c = dem.contact
    if c is None or not active.any():
        return H
    H.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    C = c.hessian_correction(active).tocsr()
    C.eliminate_zeros()
    owned = np.flatnonzero(c._owned)
    for i in owned:
        lo, hi = C.indptr[i], C.indptr[i + 1]
        if hi > lo:
            H.setValues([int(c.patch[i])], c.patch[C.indices[lo:hi]].astype(PETSc.IntType), C.data[lo:hi],
                        addv=PETSc.InsertMode.ADD_VALUES)
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
    dem : DEMDiscretisation, with obstacles if any.
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
    if len(dem.reconstruction.dirichlet_facets) == 0 and dem.contact is None:
        raise StaticsError("the body is free: with neither a Dirichlet condition nor an obstacle its "
                           "rigid motions are unconstrained (unconstrained rigid mode)")
    start = time.perf_counter()
    c = dem.contact
    directions = _constraints(dem, fixed_mean, fixed_rotation)

    zero, rhs, u = dem.create_vector(), dem.create_vector(), dem.create_vector()  # u starts at 0
    force = dem.create_vector()
    dem.force(zero, 0.0, force)
    for w in directions:
        force.axpy(-force.dot(w), w)
    norm0 = force.norm()

    if c is not None:
        # Start from the facets touching the obstacle at u = 0 (smallest gap); the iteration
        # adds the facets the solution pushes into it and releases those it lifts off.
        g = c.gaps(c.patch_values(zero))
        active = g <= g.min() + 1e-9 * dem.geometry.facet_diameters[c.facets].min()
    ksp = PETSc.KSP().create(dem.comm)
    ksp.setType(PETSc.KSP.Type.CG)
    ksp.getPC().setType(PETSc.PC.Type.GAMG)
    ksp.setTolerances(rtol=rtol, atol=0.0, max_it=10000)
    ksp.setOptionsPrefix("dolfinx_dem_statics_")
    ksp.setFromOptions()
    linear_iterations = 0
    step, trial = dem.create_vector(), dem.create_vector()

    def potential(vec):
        return dem.energies(vec, 0.0)["potential"]

    for iteration in range(1, max_iterations + 1):
        # Newton step of the quadratic piece A at u: H_A d = F_A(u).
        H = _hessian(dem, active) if c is not None else dem.K
        dem.force(u, 0.0, rhs, contact=False)
        if c is not None:
            c.add(c.force_correction(c.patch_values(u), active), rhs)
        operator, preconditioner = _constrained(H, directions)
        _project(rhs, directions)
        ksp.setOperators(operator, preconditioner)
        step.set(0.0)
        ksp.solve(rhs, step)
        linear_iterations += ksp.getIterationNumber()
        if ksp.getConvergedReason() < 0:
            raise StaticsError(f"the linear solve of active-set iteration {iteration} failed "
                               f"(KSP reason {ksp.getConvergedReason()}): a rigid mode may be unconstrained "
                               "(missing Dirichlet condition, obstacle contact or fixed_mean component)")
        if c is None:
            step.copy(u)
            break
        # Backtracking (Armijo) on the continuous potential: the full step when the contact set
        # does not change, a shorter one when it overshoots a switch (no cycling between sets).
        slope, v0, alpha = -rhs.dot(step), potential(u), 1.0
        while True:
            u.copy(trial)
            trial.axpy(alpha, step)
            if potential(trial) <= v0 + 1e-4 * alpha * slope or alpha < 1e-8:
                break
            alpha *= 0.5
        trial.copy(u)
        new = c.gaps(c.patch_values(u)) < 0
        if not new.any():
            raise StaticsError("no facet is in contact at the solution: the obstacle does not hold the "
                               "body (check the contact candidate boundary and the load direction)")
        converged = alpha == 1.0 and np.array_equal(new, active)
        active = new
        if converged:
            break
    else:
        raise StaticsError(f"the active set did not settle in {max_iterations} iterations (cycling between "
                           "contact states: the load may be too large or the contact tag wrong)")
    ksp.destroy()

    dem.force(u, 0.0, force)
    for w in directions:
        force.axpy(-force.dot(w), w)
    return StaticResult(
        u=u,
        iterations=iteration,
        linear_iterations=linear_iterations,
        gradient_norm_initial=norm0,
        gradient_norm=force.norm(),
        energy=dem.energies(u, 0.0)["potential"],
        contact_facets=int(active.sum()) if c is not None else 0,
        wall_time_s=time.perf_counter() - start,
    )
