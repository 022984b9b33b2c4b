"""The linear algebra of statics: the subspace of the steps and the Krylov solves.

Rigid translations that neither a Dirichlet condition nor contact fixes (the horizontal motion of
a disc on a frictionless plane) are removed by holding the mass-weighted mean displacement in
those components at zero (and, for a disc that could roll, the mean rotation), for each body
without a Dirichlet condition (``rigid_mode_constraints``): the Krylov solver (CG, GAMG) works in
the subspace of these linear constraints, where the Hessian is positive definite.

Prescribed bodies (``conditions.PrescribedBody``) are held at their translation U(t): the steps
are zero on their dofs. The projector of the linear constraints is extended by the coordinate
projector onto d_p = 0, which commutes with it (the constraint normals vanish on prescribed
bodies), the constrained operator is the identity on them, and the gradient norm leaves them out.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import InputError, StaticsError


@dataclasses.dataclass(frozen=True)
class Constraints:
    """The subspace of the steps: w . d = 0 for the orthonormal ``normals`` w (``rigid_mode_constraints``)
    and d = 0 on the ``held`` dofs (owned, local: the prescribed bodies'), on which the normals
    vanish. ``holds``: whether any process holds dofs (the same everywhere:
    collective calls depend on it)."""

    normals: list
    held: np.ndarray
    holds: bool

    def __bool__(self) -> bool:
        return bool(self.normals) or self.holds


def rigid_mode_constraints(dem, components, rotation) -> Constraints:
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
    return Constraints(normals, dem.prescribed.dofs, bool(dem.prescribed))


def project(x: PETSc.Vec, constraints: Constraints) -> None:
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

    def __init__(self, H, constraints: Constraints):
        self.H, self.constraints = H, constraints
        self.work = H.createVecRight()

    def mult(self, mat, x, y):
        x.copy(self.work)
        project(self.work, self.constraints)
        self.H.mult(self.work, y)
        project(y, self.constraints)
        y.axpy(1.0, x)
        y.axpy(-1.0, self.work)


def _constrained(H, constraints: Constraints):
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


class LinearSolver:
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

    def set_operator(self, H, constraints: Constraints) -> None:
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
