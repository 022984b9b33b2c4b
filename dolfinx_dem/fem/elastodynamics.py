"""DOLFINx finite-element reference for linear elastodynamics.

Small-strain isotropic linear elasticity on a simplex mesh (1D, 2D, 3D), Lagrange P1/P2 vector
displacements, clamped (``u = 0``) facets:

    M a + K u = F

* :class:`FEMElastodynamics` integrates in time with the implicit Newmark average-acceleration
  scheme (beta = 1/4, gamma = 1/2) and the consistent mass: unconditionally stable, second-order
  accurate and, without external forces, exactly conserving ``1/2 v.M v + 1/2 u.K u``.
* :class:`FEMCentralDifference` integrates P1 explicitly with central differences and the lumped
  (row-sum) mass: no solve, second-order accurate, stable below ``2 / sqrt(lambda_max(m^-1 K))``.
* :func:`first_eigenfrequency` returns the lowest natural angular frequencies from the generalized
  eigenproblem ``K x = omega^2 M x`` (SLEPc, shift-and-invert around 0).

Units are SI: E in Pa, rho in kg/m^3, body force in N/m^3, lengths in m, time in s. In 2D the
default is plane strain (``plane_stress=True`` for plane stress); in 1D ``sigma = E u'`` and nu is
unused. All collective methods must be called on every rank of ``mesh.comm``.
"""

from __future__ import annotations

import typing

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError, SolverError
from dolfinx_dem.fem.common import (
    check_degree,
    check_facets,
    check_material,
    check_positive,
    check_simplex_mesh,
    clamped_bc,
    configure_lu,
    evaluate_at_points,
    lu_solver,
    node_coordinates,
    stiffness_and_mass,
)

__all__ = ["FEMCentralDifference", "FEMElastodynamics", "evaluate_at_points", "first_eigenfrequency"]

VectorField = typing.Callable[[np.ndarray], npt.ArrayLike]
"""A callable ``x -> values``, x of shape (gdim, n) in m, values of shape (gdim, n)."""

class _FEMSolver:
    """Set-up shared by the time integrators: checks, space, fields, clamp, forms, body force.

    Builds ``V``, the Functions ``u``, ``v``, ``a`` (displacement, velocity, acceleration at
    ``t``), the clamp ``_bcs``, the UFL forms ``_k``, ``_m`` and the body-force vector ``_F``
    (``None`` without one), and interpolates the initial fields (0 on the clamped dofs).
    Subclasses assemble their operators and then call ``_start()``.
    """

    def __init__(self, mesh, degree, E, nu, rho, clamped_facets, body_force, initial_displacement,
                 initial_velocity, plane_stress):
        check_simplex_mesh(mesh)
        degree = check_degree(degree)
        E, nu, rho = check_material(E, nu, rho)
        facets = check_facets(mesh, clamped_facets)
        gdim = mesh.geometry.dim
        if body_force is not None:
            body_force = np.asarray(body_force, dtype=PETSc.ScalarType)
            if body_force.shape != (gdim,):
                raise InputError(f"body_force must have shape ({gdim},), got {body_force.shape}")

        self.mesh = mesh
        self.comm: MPI.Comm = mesh.comm
        self.t = 0.0
        self.V = _compat.create_vector_space(mesh, "Lagrange", degree)
        self.u = dolfinx.fem.Function(self.V, name="displacement")
        self.v = dolfinx.fem.Function(self.V, name="velocity")
        self.a = dolfinx.fem.Function(self.V, name="acceleration")
        self._bcs = [clamped_bc(self.V, facets)]
        self._k, self._m = stiffness_and_mass(self.V, E, nu, rho, plane_stress)

        u_vec = _compat.petsc_vec(self.u)
        self._F = None
        if body_force is not None and np.any(body_force != 0.0):
            w = ufl.TestFunction(self.V)
            f = dolfinx.fem.Constant(mesh, body_force)
            self._F = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(ufl.inner(f, w) * ufl.dx))
            self._F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self._b = u_vec.copy()
        self._work = u_vec.copy()
        for func, field, name in (
            (self.u, initial_displacement, "initial_displacement"),
            (self.v, initial_velocity, "initial_velocity"),
        ):
            if field is not None:
                wrapped = _vector_field(field, gdim, name)
                if degree == 1:  # at the mesh's own node coordinates: interpolate() pushes the reference
                    # vertices forward with a rounding that differs from cell to cell, so a field that jumps
                    # on a mesh line (billiard's velocity at its frame) would depend on the partition
                    x = node_coordinates(self.V)
                    func.x.array[:] = wrapped(np.pad(x, ((0, 0), (0, 3 - x.shape[1]))).T).T.ravel()
                else:
                    func.interpolate(wrapped)
                self._apply_clamp(func)

    def _apply_clamp(self, func) -> None:
        vec = _compat.petsc_vec(func)
        dolfinx.fem.petsc.set_bc(vec, self._bcs)
        vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def _residual(self, out: PETSc.Vec) -> PETSc.Vec:
        """``out = F - K u``, zero on the clamped rows (K: the subclass's ``_K``)."""
        self._K.mult(_compat.petsc_vec(self.u), out)
        out.scale(-1.0)
        if self._F is not None:
            out.axpy(1.0, self._F)
        dolfinx.fem.petsc.set_bc(out, self._bcs)
        return out

    def _mass_mult(self, x: PETSc.Vec, out: PETSc.Vec) -> None:
        raise NotImplementedError

    def energies(self) -> tuple[float, float]:
        """(kinetic, elastic) energy in J, ``1/2 v.M v`` and ``1/2 u.K u``, summed over ranks.

        ``M`` is the scheme's mass matrix (consistent for Newmark, lumped for central differences).
        """
        u, v = _compat.petsc_vec(self.u), _compat.petsc_vec(self.v)
        w = self._work
        self._mass_mult(v, w)
        kinetic = 0.5 * v.dot(w)
        self._K.mult(u, w)
        elastic = 0.5 * u.dot(w)
        return float(kinetic), float(elastic)

    def point_values(self, points: npt.ArrayLike) -> np.ndarray:
        """Displacement (m) at points, shape (n, gdim), from points of shape (n, gdim) in m.

        Collective: every rank must pass the same points and gets all values. Raises ValueError
        if a point is outside the mesh.
        """
        return evaluate_at_points(self.u, points)


class FEMElastodynamics(_FEMSolver):
    """Newmark average-acceleration FEM solver for linear elastodynamics.

    Each step solves ``(K + 4/dt^2 M) u_{n+1} = F + M (4/dt^2 u_n + 4/dt v_n + a_n)`` with an LU
    factorization computed once at construction, then updates ``a`` and ``v``.

    Args:
        mesh: DOLFINx simplex mesh with gdim == tdim (1, 2 or 3), lengths in m.
        degree: Lagrange degree of the displacement, 1 or 2.
        E: Young's modulus (Pa), > 0.
        nu: Poisson's ratio, -1 < nu < 0.5 (unused in 1D).
        rho: Density (kg/m^3), > 0.
        dt: Time step (s), > 0.
        clamped_facets: Process-local indices of the facets where ``u = 0``, shape (k,).
        body_force: Constant body force (N/m^3), shape (gdim,); ``None`` for none.
        initial_displacement: ``x -> u0(x)`` (m), x of shape (gdim, n), returns (gdim, n).
        initial_velocity: ``x -> v0(x)`` (m/s), same shapes.
        plane_stress: In 2D, plane stress instead of plane strain.

    Initial fields are interpolated and then set to 0 on the clamped dofs; the initial
    acceleration solves ``M a_0 = F - K u_0``. Without external forces the energy
    ``1/2 v.M v + 1/2 u.K u`` (:meth:`energies`) is conserved up to round-off.
    """

    def __init__(
        self,
        mesh,
        degree: int,
        E: float,
        nu: float,
        rho: float,
        dt: float,
        clamped_facets: npt.ArrayLike,
        *,
        body_force: npt.ArrayLike | None = None,
        initial_displacement: VectorField | None = None,
        initial_velocity: VectorField | None = None,
        plane_stress: bool = False,
    ):
        self.dt = check_positive("dt (time step)", dt)
        super().__init__(mesh, degree, E, nu, rho, clamped_facets, body_force,
                         initial_displacement, initial_velocity, plane_stress)
        dt = self.dt
        k, m = self._k, self._m
        self._c0, self._c1 = 4.0 / dt**2, 4.0 / dt
        # Unconstrained K and M for energies and right-hand sides; A with the clamped rows.
        self._K = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(k))
        self._K.assemble()
        self._M = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(m))
        self._M.assemble()
        A = dolfinx.fem.petsc.assemble_matrix(
            dolfinx.fem.form(k + self._c0 * m), bcs=self._bcs, diagonal=1.0
        )
        A.assemble()
        self._solver = lu_solver(self.comm, A)
        self._u_old = self._work.copy()
        if initial_displacement is not None or self._F is not None:
            self._initial_acceleration()

    def _mass_mult(self, x: PETSc.Vec, out: PETSc.Vec) -> None:
        self._M.mult(x, out)

    def _initial_acceleration(self) -> None:
        """Solve ``M a_0 = F - K u_0`` with a_0 = 0 on the clamped dofs."""
        Mbc = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(self._m), bcs=self._bcs, diagonal=1.0)
        Mbc.assemble()
        solver = lu_solver(self.comm, Mbc)
        a_vec = _compat.petsc_vec(self.a)
        solver.solve(self._residual(self._b), a_vec)
        a_vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        solver.destroy()
        Mbc.destroy()

    def step(self) -> None:
        """Advance ``u``, ``v``, ``a`` and ``t`` by one time step ``dt`` (collective)."""
        u, v, a = (_compat.petsc_vec(f) for f in (self.u, self.v, self.a))
        b, w, u_old = self._b, self._work, self._u_old
        c0, c1, half_dt = self._c0, self._c1, 0.5 * self.dt

        # b = F + M (c0 u_n + c1 v_n + a_n), zero on clamped rows
        u.copy(w)
        w.scale(c0)
        w.axpy(c1, v)
        w.axpy(1.0, a)
        self._M.mult(w, b)
        if self._F is not None:
            b.axpy(1.0, self._F)
        dolfinx.fem.petsc.set_bc(b, self._bcs)

        u.copy(u_old)
        self._solver.solve(b, u)
        if self._solver.getConvergedReason() < 0:
            raise SolverError(f"LU solve failed: {self._solver.getConvergedReason()}")

        # a_{n+1} = c0 (u_{n+1} - u_n) - c1 v_n - a_n ;  v_{n+1} = v_n + dt/2 (a_n + a_{n+1})
        a.copy(w)  # w = a_n
        a.scale(-1.0)
        a.axpy(c0, u)
        a.axpy(-c0, u_old)
        a.axpy(-c1, v)
        v.axpy(half_dt, w)
        v.axpy(half_dt, a)
        for vec in (u, v, a):
            vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        self.t += self.dt


class FEMCentralDifference(_FEMSolver):
    """Explicit central-difference P1 FEM solver with lumped (row-sum) mass.

    The lumped mass ``m`` is the row sum of the consistent P1 mass matrix (positive for P1
    simplices), so the scheme needs no solve. Each step is velocity Verlet, i.e. central
    differences ``m (u_{n+1} - 2 u_n + u_{n-1}) / dt^2 = F - K u_n`` written with velocities::

        v_{n+1/2} = v_n + dt/2 a_n,   u_{n+1} = u_n + dt v_{n+1/2},
        a_{n+1} = m^-1 (F - K u_{n+1}),   v_{n+1} = v_{n+1/2} + dt/2 a_{n+1}

    with ``a = 0`` on the clamped dofs. It is second-order accurate and stable for
    ``dt < dt_stable = 2 / sqrt(lambda_max(m^-1 K))`` (the clamped dofs removed), computed at
    construction with SLEPc (:attr:`dt_stable`). Without external forces it conserves exactly
    the modified energy ``1/2 v_{n-1/2}.m v_{n+1/2} + 1/2 u_n.K u_n``
    (:meth:`modified_energy`); the energy of :meth:`energies` oscillates by O(dt^2) about it.

    Args:
        mesh, E, nu, rho, clamped_facets, body_force, initial_displacement, initial_velocity,
            plane_stress: As for :class:`FEMElastodynamics` (the degree is 1).
        dt: Time step (s), > 0; or
        cfl: Time step as a fraction of ``dt_stable``, > 0 (exactly one of dt, cfl).
        allow_unstable: Accept ``dt >= dt_stable`` (the run then blows up; for stability
            studies). Otherwise such a time step raises ValueError.
    """

    def __init__(
        self,
        mesh,
        E: float,
        nu: float,
        rho: float,
        clamped_facets: npt.ArrayLike,
        *,
        dt: float | None = None,
        cfl: float | None = None,
        body_force: npt.ArrayLike | None = None,
        initial_displacement: VectorField | None = None,
        initial_velocity: VectorField | None = None,
        plane_stress: bool = False,
        allow_unstable: bool = False,
    ):
        if (dt is None) == (cfl is None):
            raise InputError("give exactly one of dt (time step) and cfl (fraction of dt_stable)")
        step = check_positive("dt (time step)" if cfl is None else "cfl", dt if cfl is None else cfl)
        super().__init__(mesh, 1, E, nu, rho, clamped_facets, body_force,
                         initial_displacement, initial_velocity, plane_stress)
        # K with the clamped rows and columns zeroed: u stays 0 there, and 1/2 u.K u is unchanged.
        self._K = dolfinx.fem.petsc.assemble_matrix(
            dolfinx.fem.form(self._k), bcs=self._bcs, diagonal=0.0
        )
        self._K.assemble()
        M = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(self._m))
        M.assemble()
        self.lumped_mass = self._work.copy()
        M.getRowSum(self.lumped_mass)
        M.destroy()
        self._inverse_mass = self.lumped_mass.copy()
        self._inverse_mass.reciprocal()
        self.dt_stable = 2.0 / np.sqrt(_largest_eigenvalue(self.comm, self._K, self._inverse_mass))
        self.dt = step if cfl is None else step * self.dt_stable
        if self.dt >= self.dt_stable and not allow_unstable:
            raise InputError(
                f"dt (time step) = {self.dt:.6g} s is not below the stability limit "
                f"dt_stable = 2/sqrt(lambda_max(m^-1 K)) = {self.dt_stable:.6g} s of central "
                f"differences (pass allow_unstable=True to run it anyway)"
            )
        if self._F is not None:
            dolfinx.fem.petsc.set_bc(self._F, self._bcs)
        self._acceleration()

    def _mass_mult(self, x: PETSc.Vec, out: PETSc.Vec) -> None:
        out.pointwiseMult(x, self.lumped_mass)

    def _acceleration(self) -> None:
        """``a = m^-1 (F - K u)``, 0 on the clamped dofs."""
        a = _compat.petsc_vec(self.a)
        a.pointwiseMult(self._residual(self._b), self._inverse_mass)
        a.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def step(self) -> None:
        """Advance ``u``, ``v``, ``a`` and ``t`` by one time step ``dt`` (collective)."""
        u, v, a = (_compat.petsc_vec(f) for f in (self.u, self.v, self.a))
        half_dt = 0.5 * self.dt
        v.axpy(half_dt, a)
        u.axpy(self.dt, v)
        u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        self._acceleration()
        v.axpy(half_dt, a)
        v.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        self.t += self.dt

    def modified_energy(self) -> float:
        """``1/2 v_{n-1/2}.m v_{n+1/2} + 1/2 u.K u - F.u`` (J), summed over ranks.

        Equal to ``kinetic + elastic - dt^2/8 a.m a - F.u`` (:meth:`energies`); conserved by the
        scheme up to round-off while it is stable.
        """
        kinetic, elastic = self.energies()
        a = _compat.petsc_vec(self.a)
        w = self._work
        w.pointwiseMult(a, self.lumped_mass)
        energy = kinetic + elastic - self.dt**2 / 8.0 * a.dot(w)
        if self._F is not None:
            energy -= self._F.dot(_compat.petsc_vec(self.u))
        return float(energy)


def _largest_eigenvalue(comm: MPI.Comm, K: PETSc.Mat, inverse_mass: PETSc.Vec) -> float:
    """lambda_max(m^-1 K) (1/s^2) for a diagonal mass, from the symmetric m^-1/2 K m^-1/2 (SLEPc)."""
    from slepc4py import SLEPc

    A = K.copy()
    scale = inverse_mass.copy()
    scale.sqrtabs()
    A.diagonalScale(scale, scale)
    eps = SLEPc.EPS().create(comm)
    eps.setOperators(A)
    eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
    eps.setDimensions(nev=1)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.LARGEST_REAL)
    eps.setTolerances(tol=1e-8, max_it=20000)
    eps.solve()
    if eps.getConverged() < 1:
        raise SolverError("SLEPc did not converge the largest eigenvalue of m^-1 K")
    lam = max(eps.getEigenvalue(i).real for i in range(eps.getConverged()))
    eps.destroy()
    A.destroy()
    scale.destroy()
    return float(lam)


def _vector_field(field: VectorField, gdim: int, name: str):
    """Wrap a user callable (gdim, n) -> (gdim, n) for DOLFINx interpolation (x is (3, n))."""
    if not callable(field):
        raise InputError(f"{name} must be a callable x -> values, got {type(field).__name__}")

    def wrapped(x: np.ndarray) -> np.ndarray:
        values = np.asarray(field(x[:gdim]), dtype=PETSc.ScalarType)
        if values.shape != (gdim, x.shape[1]):
            raise InputError(
                f"{name} must return an array of shape (gdim, n) = ({gdim}, {x.shape[1]}), got "
                f"{values.shape}"
            )
        return values

    return wrapped


def first_eigenfrequency(
    mesh,
    degree: int,
    E: float,
    nu: float,
    rho: float,
    clamped_facets: npt.ArrayLike,
    n: int = 1,
    *,
    plane_stress: bool = False,
) -> np.ndarray:
    """The ``n`` lowest natural angular frequencies omega (rad/s) of the clamped body.

    Solves ``K x = omega^2 M x`` with SLEPc (generalized Hermitian, shift-and-invert around 0,
    LU). The clamped rows carry 1 on the diagonal of K and 0 on that of M, so their eigenvalues
    are infinite and never returned.

    Args:
        mesh, degree, E, nu, rho, clamped_facets, plane_stress: As for :class:`FEMElastodynamics`;
            ``clamped_facets`` must be non-empty on some rank (else K is singular).
        n: Number of frequencies, >= 1.

    Returns:
        Ascending omega, shape (n,), identical on every rank.
    """
    from slepc4py import SLEPc

    check_simplex_mesh(mesh)
    degree = check_degree(degree)
    E, nu, rho = check_material(E, nu, rho)
    facets = check_facets(mesh, clamped_facets)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"n (number of frequencies) must be an integer >= 1, got {n!r}")
    comm = mesh.comm
    if comm.allreduce(facets.size, op=MPI.SUM) == 0:
        raise InputError("clamped_facets is empty on every rank: the free body has zero modes")

    V = _compat.create_vector_space(mesh, "Lagrange", degree)
    bcs = [clamped_bc(V, facets)]
    k, m = stiffness_and_mass(V, E, nu, rho, plane_stress)
    K = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(k), bcs=bcs, diagonal=1.0)
    K.assemble()
    M = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(m), bcs=bcs, diagonal=0.0)
    M.assemble()

    eps = SLEPc.EPS().create(comm)
    eps.setOperators(K, M)
    eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
    eps.setDimensions(nev=int(n))
    eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
    eps.setTarget(0.0)
    eps.setTolerances(tol=1e-12, max_it=1000)
    st = eps.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    st.setShift(0.0)
    configure_lu(st.getKSP())
    eps.solve()

    lam = np.array([eps.getEigenvalue(i).real for i in range(eps.getConverged())])
    eps.destroy()
    K.destroy()
    M.destroy()
    lam = np.sort(lam[np.isfinite(lam) & (lam > 0.0)])
    if lam.size < n:
        raise SolverError(f"SLEPc converged only {lam.size} of the {n} requested eigenvalues")
    return np.sqrt(lam[:n])
