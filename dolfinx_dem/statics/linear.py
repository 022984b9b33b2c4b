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
    collective calls depend on it). ``rows``: the normals are not null directions of the Hessian
    (the stick pairs of statics/pair_friction.py), and these are the sparse constraints w they
    orthonormalise, this process's, as (global dofs (m, k), values (m, k)). Then each solution is
    projected onto the subspace, since CG's residual in the I - P block, a displacement along a
    normal, would carry the force H (I - P) d (a floor of 1e-8 of the load on the Newton
    iteration), and the solve is preconditioned by H + s W W^T with the I - P block scaled by s
    (``_constrained``). The rigid modes' solutions are projected too: a free body's mean
    translation and rotation carry no force without contact, but contact between bodies resists
    them (they move the body's facets against the other body's), and CG's part along them (1e-13
    to 1e-12 of each solution, measured) then carried a force of 1e-10 of the initial gradient
    (3e-9 on 3 processes, GAMG): the floor of the Newton iteration, above its gradient_rtol."""

    normals: list
    held: np.ndarray
    holds: bool
    rows: tuple[np.ndarray, np.ndarray] | None = None

    def __bool__(self) -> bool:
        return bool(self.normals) or self.holds


def check_held(dem, components=(), rotation: bool = False) -> None:
    """A StaticsError naming a body and a rigid motion of it (a translation or a rotation) that
    its Dirichlet conditions (their fixed components: rollers fix some only) and the constraints
    ``components`` / ``rotation`` of ``rigid_mode_constraints`` leave free, for each body without
    a prescribed motion, when no contact holds the bodies. Such a problem has no unique minimum:
    before, a body held only by rollers solved without a word. The rigid motions r_k about the
    body's centroid are evaluated at its Dirichlet facets: the Gram matrix of their fixed
    components (and of the constraints) is singular exactly when a combination of them is free.
    Collective; (bodies, modes, modes) arrays only."""
    d, geom, rec, comm = dem.d, dem.geometry, dem.reconstruction, dem.comm
    modes = d + {1: 0, 2: 1, 3: 3}[d]
    own = geom.facet_cells[rec.dirichlet_facets, 0] < dem.n_owned
    facets, fixed = rec.dirichlet_facets[own], rec.fixed[own]
    body = geom.cell_bodies[geom.facet_cells[facets, 0]]
    cells = geom.cell_bodies[: dem.n_owned]
    sums = np.zeros((geom.num_bodies, 1 + d + 2 * d))  # volume, first moments, lower and upper corners
    sums[:, 0] = np.bincount(cells, geom.cell_volumes[: dem.n_owned], geom.num_bodies)
    for i in range(d):
        sums[:, 1 + i] = np.bincount(cells, geom.cell_volumes[: dem.n_owned] * geom.cell_centres[: dem.n_owned, i],
                                     geom.num_bodies)
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    centre = sums[:, 1 : 1 + d] / sums[:, :1]
    size = np.maximum(np.sqrt(sums[:, 0]) if d == 2 else np.cbrt(sums[:, 0]) if d == 3 else sums[:, 0], 1e-300)
    x = (geom.facet_centres[facets] - centre[body]) / size[body, None]  # dimensionless arms
    r = np.zeros((len(facets), modes, d))  # the rigid motions at the facets
    r[:, np.arange(d), np.arange(d)] = 1.0
    if d == 2:
        r[:, 2] = np.stack([-x[:, 1], x[:, 0]], axis=1)
    elif d == 3:
        for k, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):  # rotations about x, y, z
            r[:, 3 + k, a], r[:, 3 + k, b] = -x[:, b], x[:, a]
    rows = r * fixed[:, None, :]
    gram = np.zeros((geom.num_bodies, modes, modes))
    np.add.at(gram, body, np.einsum("fki,fli->fkl", rows, rows))
    comm.Allreduce(MPI.IN_PLACE, gram, op=MPI.SUM)
    extra = np.zeros(modes)  # the constraints of rigid_mode_constraints, on every body without Dirichlet facets
    extra[list(components)] = 1.0
    if rotation and d == 2:
        extra[2] = 1.0
    names = ["translation along " + "xyz"[i] for i in range(d)] + (
        ["rotation"] if d == 2 else ["rotation about x", "rotation about y", "rotation about z"] if d == 3 else [])
    held = set(np.asarray(dem.prescribed.body_numbers).tolist())
    for b in range(geom.num_bodies):
        if b in held:
            continue
        g = gram[b] + (np.diag(extra) if not gram[b].any() else 0.0)
        values, vectors = np.linalg.eigh(g)
        null = vectors[:, values <= 1e-10 * max(values[-1], 1.0)]  # the free combinations
        if null.shape[1]:
            parts = [n for n, c in zip(names, np.linalg.norm(null, axis=1)) if c > 0.1]
            free = " and ".join([", ".join(parts[:-1]), parts[-1]] if len(parts) > 1 else parts)
            raise StaticsError(f"body {b} has a free rigid motion ({free}): its Dirichlet conditions (with their "
                               "fixed components) do not hold it, so the static problem has no unique solution; fix "
                               "more components, add a Dirichlet condition, or hold the mean with statics.fixed_mean"
                               + (" / fixed_rotation" if d == 2 else ""))


def held_bodies(dem) -> np.ndarray:
    """Whether each body has a Dirichlet condition or a prescribed motion (collective)."""
    geom = dem.geometry
    held = np.zeros(geom.num_bodies, dtype=np.int64)
    held[geom.cell_bodies[geom.facet_cells[dem.reconstruction.dirichlet_facets, 0]]] = 1
    held[dem.prescribed.body_numbers] = 1
    dem.comm.Allreduce(MPI.IN_PLACE, held, op=MPI.MAX)
    return held == 1


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
    comm = dem.comm
    normals = []
    for b in np.flatnonzero(~held_bodies(dem)):
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
    """P H P + s (I - P): symmetric positive definite when H is positive definite on range(P), and
    equal to H on it (s times the identity on the held dofs and the normals), so CG on range(P)
    solves the constrained minimisation; s = 1 but for ``Constraints.rows``."""

    def __init__(self, H, constraints: Constraints, s: float):
        self.H, self.constraints, self.s = H, constraints, s
        self.work = H.createVecRight()

    def mult(self, mat, x, y):
        x.copy(self.work)
        project(self.work, self.constraints)
        self.H.mult(self.work, y)
        project(y, self.constraints)
        y.axpy(self.s, x)
        y.axpy(-self.s, self.work)


def _constrained(H, constraints: Constraints):
    """(operator, preconditioning matrix) for the constrained solve; without constraints H itself.
    The preconditioner is built from H with the held rows and columns replaced by the identity's
    (exactly P H P + (I - P) for them) and, with normals, a tiny diagonal shift, which keeps it
    definite when the constrained directions are in (or near) the null space of H. With
    ``rows`` (constraints that H resists) it is H + s W W^T, s the largest diagonal entry of H,
    and the operator's I - P block is s (I - P): both then treat the constrained directions alike
    (with H's shifted preconditioner CG took ~1000 iterations a solve)."""
    if not constraints:
        return H, H
    s = 1.0
    P = H.copy()
    if constraints.rows is not None:
        s = P.getDiagonal().max()[1]
        P.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        for dofs, values in zip(*constraints.rows):
            P.setValues(dofs, dofs, s * np.outer(values, values), addv=PETSc.InsertMode.ADD_VALUES)
        P.assemble()
    shell = PETSc.Mat().createPython(H.getSizes(), _ConstrainedOperator(H, constraints, s), comm=H.getComm())
    shell.setUp()
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
        self.constraints = constraints

    def solve(self, b, x, iteration: int, check: bool = False) -> None:
        """x = A^-1 b; ``check``: also fail when the true residual exceeds 1e3 rtol |b| (CG
        preconditioned by an indefinite matrix can report convergence in its preconditioned norm
        and be far off)."""
        x.set(0.0)
        self.ksp.solve(b, x)
        project(x, self.constraints)  # the step leaves the prescribed bodies where they are (Constraints)
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
