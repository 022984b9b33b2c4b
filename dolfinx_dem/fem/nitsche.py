"""The nonlinear solver of the Nitsche contact references (fem/hertz.py): Newton with the rigid
motions of a body held only by contact (a null space, or the mean of u_x pinned), the assembled
residual norms, and the contact pressure and gap sampled on the contact facets.
"""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, meshes
from dolfinx_dem.errors import SolverError
from dolfinx_dem.fem.common import owned_facets


def top_displacement(u, R: float) -> tuple[float, float]:
    """(y_top, u_y) at the top of the mesh at x = 0 (m): on the polygon, not the circle.

    2D: evaluated in the cell of the owned boundary facet that crosses x = 0 (no point
    location). 3D: at the pole (0, 0, 2R), a vertex of the mesh (``create_balls``).
    """
    mesh = u.function_space.mesh
    if mesh.topology.dim == 3:
        point = np.array([[0.0, 0.0, 2.0 * R]])
        cell = _compat.colliding_cells(mesh, point)
        value = np.real(u.eval(point, cell)).reshape(-1)[2] if cell[0] >= 0 else -np.inf
        found = mesh.comm.allreduce(value, op=MPI.MAX)  # any process holding the pole
        if not np.isfinite(found):
            raise SolverError("the top of the ball (0, 0, 2R) is in no cell")
        return 2.0 * R, float(found)
    facets = owned_facets(mesh, meshes.locate_boundary_facets(mesh, lambda x: x[1] > R))
    cells, facet_x, _ = _compat.facet_cell_and_vertices(mesh, facets)
    best = (-np.inf, 0.0)
    for cell, ((x0, y0, _), (x1, y1, _)) in zip(cells, facet_x):
        if min(x0, x1) <= 0.0 <= max(x0, x1) and x0 != x1:
            y = y0 + (y1 - y0) * (0.0 - x0) / (x1 - x0)
            if y > best[0]:
                point = np.array([[0.0, y, 0.0]])
                value = np.real(u.eval(point, np.array([cell], dtype=np.int32))).reshape(-1)
                best = (y, float(value[1]))
    return mesh.comm.allreduce(best, op=MPI.MAX)


def sample_contact(u, sigma_h, facets, y_plane, gamma0, E, samples_per_facet, R, exact_gap):
    """(x, lambda, p, g) at equispaced interior points of the given owned boundary facets.

    Same quantities as in the forms: p = e_y . sigma_h n, g the gap, lambda = [p - gamma g]_+
    with gamma = gamma0 E / h_K (h_K the largest vertex distance of the facet's cell, as
    ufl.CellDiameter on an affine simplex).
    """
    if facets.size == 0:
        empty = np.zeros(0)
        return empty, empty, empty, empty
    mesh = u.function_space.mesh
    cells, facet_x, cell_x = _compat.facet_cell_and_vertices(mesh, facets)
    s = (np.arange(samples_per_facet) + 0.5) / samples_per_facet
    points = facet_x[:, :1, :] + s[None, :, None] * (facet_x[:, 1:2, :] - facet_x[:, :1, :])
    points = points.reshape(-1, 3)
    point_cells = np.repeat(cells, samples_per_facet)
    # outward unit normal of each facet, and the cell diameter (max vertex distance)
    t = facet_x[:, 1, :2] - facet_x[:, 0, :2]
    normal = np.stack([t[:, 1], -t[:, 0]], axis=1) / np.linalg.norm(t, axis=1)[:, None]
    inward = cell_x[:, :, :2].mean(axis=1) - facet_x[:, :, :2].mean(axis=1)
    normal *= -np.sign(np.sum(normal * inward, axis=1))[:, None]
    diffs = cell_x[:, :, None, :2] - cell_x[:, None, :, :2]
    h_cell = np.sqrt(np.max(np.sum(diffs**2, axis=-1), axis=(1, 2)))

    u_val = np.real(u.eval(points, point_cells)).reshape(-1, 2)
    sig = np.real(sigma_h.eval(points, point_cells)).reshape(-1, 2, 2)
    n_pt = np.repeat(normal, samples_per_facet, axis=0)
    p = np.einsum("ij,ij->i", sig[:, 1, :], n_pt)  # e_y . sigma n
    if exact_gap:
        g = R - np.sqrt(np.clip(R**2 - points[:, 0] ** 2, 0.0, None)) + u_val[:, 1]
    else:
        g = points[:, 1] + u_val[:, 1] - y_plane
    gamma = gamma0 * E / np.repeat(h_cell, samples_per_facet)
    lam = np.maximum(p - gamma * g, 0.0)
    return points[:, 0].copy(), lam, p, g


class MeanUx:
    """The constraint "mass-weighted mean of u_x = 0" (uniform density: area-weighted).

    ``m . u = integral of u_x dx`` with ``m_i = integral of phi_i . e_x dx``; ``e_x`` holds the
    coefficients of the constant field (1, 0), the null vector of the Jacobian.
    """

    def __init__(self, V):
        v = ufl.TestFunction(V)
        self.m = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(v[0] * ufl.dx))
        self.m.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self._e_x_function = dolfinx.fem.Function(V)
        self._e_x_function.interpolate(lambda x: np.stack([np.ones(x.shape[1]), np.zeros(x.shape[1])]))
        self.e_x = _compat.petsc_vec(self._e_x_function)
        self.area = self.m.dot(self.e_x)

    def mean(self, vec: PETSc.Vec) -> float:
        """Mean x-component (m) of the field with coefficients ``vec``."""
        return self.m.dot(vec) / self.area

    def remove(self, vec: PETSc.Vec) -> None:
        """Subtract the mean x-translation from ``vec`` (owned entries; ghosts untouched)."""
        vec.axpy(-self.mean(vec), self.e_x)


def rigid_motions(V) -> PETSc.NullSpace:
    """The rigid motions of the vector space V (3 in 2D, 6 in 3D) as an orthonormal PETSc
    NullSpace, the near null space of elasticity for the AMG."""
    d = V.mesh.geometry.dim
    modes = [lambda x, i=i: np.stack([np.full(x.shape[1], float(i == k)) for k in range(d)]) for i in range(d)]
    for i, j in ((0, 1), (1, 2), (2, 0))[: 1 if d == 2 else 3]:  # rotation in the (x_i, x_j) plane
        modes.append(lambda x, i=i, j=j: np.stack([-x[j] if k == i else x[i] if k == j else 0.0 * x[0]
                                                   for k in range(d)]))
    vectors = []
    for mode in modes:
        w = dolfinx.fem.Function(V)
        w.interpolate(mode)
        vec = _compat.petsc_vec(w).copy()
        for other in vectors:  # Gram-Schmidt
            vec.axpy(-vec.dot(other), other)
        vec.normalize()
        vectors.append(vec)
    return PETSc.NullSpace().create(vectors=vectors, comm=V.mesh.comm)


class NewtonSolver:
    """DOLFINx's NewtonSolver with MUMPS LU and updates free of the mean x-translation.

    The Jacobian is singular (its null vector is e_x). ``method`` makes the linear solves well
    posed:

    * "regularise": solve with ``J + eps M_x``, ``M_x`` the mass matrix of the x-components
      (``(du_x, v_x)``, eps = ``regularisation`` in Pa/m^2). The residual is unchanged, so the
      converged solution is exact; every update satisfies ``m . du = 0`` exactly (e_x is a left
      null vector of J and ``M_x e_x = m``), and Newton's convergence is slowed by a factor
      ~ eps / (smallest nonzero eigenvalue of J relative to M) only.
    * "nullspace": e_x as a PETSc MatNullSpace of J and MUMPS with null-pivot detection
      (ICNTL(24) = 1). MUMPS's default threshold does not always see the (round-off) null pivot.

    In both cases the update is projected onto zero mean u_x. With ``mean_ux=None`` (3D: the
    symmetry conditions ``bcs`` fix the horizontal motions) J is nonsingular: GMRES + GAMG.
    """

    _METHODS = ("regularise", "nullspace")

    def __init__(self, comm, F, u, mean_ux, rtol, atol, max_it, method, regularisation, bcs=()):
        V = u.function_space
        du, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        J = ufl.derivative(F, u, du)
        options = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
        if mean_ux is None:
            # 3D: the LU's fill makes MUMPS minutes slow from ~40k dofs (300 s against 36 s at
            # 40k). GMRES, not CG: on coarse meshes the Nitsche term -theta/gamma (p(du), p(v))
            # makes J slightly indefinite (CG stopped with an indefinite matrix at h = 0.06 m).
            # Smoothed aggregation AMG with the rigid motions as near null space; updates to
            # 1e-10 relative residual keep Newton's convergence.
            method = None
            options = {"ksp_type": "gmres", "pc_type": "gamg", "ksp_rtol": 1e-10, "ksp_max_it": 5000}
        elif method == "regularise":
            J = J + regularisation * du[0] * v[0] * ufl.dx
        else:
            options["mat_mumps_icntl_24"] = 1
        self.solver, self._problem = _compat.newton_solver(comm, F, u, J, bcs)
        # DOLFINx 0.5's "residual" criterion divides by the first update's norm, not by the first
        # residual's; the incremental criterion ||du_k|| <= rtol ||du_1|| is used instead (the
        # caller checks the final residual).
        self.solver.convergence_criterion = "incremental"
        self.solver.rtol = rtol
        self.solver.atol = atol
        self.solver.max_it = max_it
        self.solver.error_on_nonconvergence = False

        self._null_space = self._near_null_space = None
        if mean_ux is None:
            self._near_null_space = rigid_motions(V)
            self.solver.A.setNearNullSpace(self._near_null_space)
        if method == "nullspace":
            e_x = self.solver.A.createVecRight()
            e_x.array[:] = mean_ux.e_x.array_r[: e_x.getLocalSize()]
            e_x.normalize()
            self._null_space = PETSc.NullSpace().create(vectors=[e_x], comm=comm)
            self.solver.A.setNullSpace(self._null_space)

        # MUMPS reads its options when the factor is created (first solve): keep them till close()
        self.ksp = self.solver.krylov_solver
        self._prefix = f"dolfinx_dem_hertz_{id(self)}_"
        self.ksp.setOptionsPrefix(self._prefix)
        self._options = options
        database = PETSc.Options()
        for key, value in options.items():
            database[self._prefix + key] = value
        self.ksp.setFromOptions()

        if mean_ux is not None:
            def update(_solver, dx: PETSc.Vec, x: PETSc.Vec) -> None:
                mean_ux.remove(dx)  # the update keeps the mean of u_x (zero) unchanged
                x.axpy(-1.0, dx)

            self.solver.set_update(update)

    def solve(self, u) -> tuple[int, bool]:
        result = self.solver.solve(u)
        if self.ksp.getConvergedReason() < 0:
            raise SolverError(f"the linear solve of the last Newton iteration failed (KSP reason "
                               f"{self.ksp.getConvergedReason()})")
        return result

    def null_pivots(self) -> int:
        """Null pivots MUMPS detected in the last factorisation (0 unless "nullspace")."""
        if self._null_space is None:
            return 0
        return int(self.ksp.getPC().getFactorMatrix().getMumpsInfog(28))

    def close(self) -> None:
        database = PETSc.Options()
        for key in self._options:
            database.delValue(self._prefix + key)
        if self._null_space is not None:
            self._null_space.destroy()
        if self._near_null_space is not None:
            self._near_null_space.destroy()


def assembled_norm(form, bcs=()) -> float:
    """Euclidean norm of the assembled vector, without the entries of the Dirichlet dofs (there
    the residual is the reaction)."""
    vec = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(form))
    vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(vec, list(bcs), None, 0.0)  # x0 = None, scale (0.9: alpha) 0
    norm = vec.norm()
    vec.destroy()
    return norm
