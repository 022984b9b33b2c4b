"""DOLFINx finite-element reference for the static Hertz problem (DEM paper, section 5.2), in 2D
and 3D.

``dim=2``: a disc of radius R (m), centre (0, R), in plane strain (Young's modulus E in Pa,
Poisson's ratio nu), loaded by the body force (0, -f) (N/m^3), rests on the rigid plane y = 0.
Contact is frictionless on the lower half of the boundary (y < R); there is no Dirichlet
condition. ``dim=3``: a ball of radius R, centre (0, 0, R), body force (0, 0, -f), on the plane
z = 0; by symmetry only the quarter x >= 0, y >= 0 is meshed (``meshes.create_balls`` with
``cut``), with u_x = 0 on x = 0 and u_y = 0 on y = 0, which also fix every rigid motion but the
vertical one (held by the contact). Below, y stands for the vertical coordinate x_{d-1} and e_y
for its unit vector; the potential contact boundary is the lower half of the sphere (not the
flat symmetry faces).

Sign conventions (the plane's normal e_y = (0, 1) points into the body's side; ``n`` is the
outward unit normal of the body, n ~ (0, -1) in the contact zone):

* gap ``g(u) = (x + u) . e_y - y_plane >= 0`` (m), the distance of the displaced boundary point
  from the plane, measured along e_y;
* contact pressure ``p(u) = e_y . sigma(u) n`` (Pa), the e_y-component of the boundary traction
  exerted by the plane on the body: ``p >= 0`` in compression (``p = -sigma_nn`` where n = -e_y);
* frictionless: the traction has no component along the plane, ``sigma(u) n = p e_y``;
* Signorini: ``g >= 0, p >= 0, p g = 0``, equivalently ``p = [p - gamma g]_+`` for any gamma > 0.

Nitsche's method (Chouly, Hild & Renard, Math. Comp. 84, 2015) with ``P(u) = p(u) - gamma g(u)``
and ``gamma = gamma0 E / h_K`` (h_K the diameter of the facet's cell): find u such that for all v

    a(u, v) - theta/gamma (p(u), p(v))_Gc + 1/gamma ([P(u)]_+, theta p(v) - gamma v . e_y)_Gc = L(v)

with ``a(u, v) = (sigma(u), eps(v))``, ``L(v) = (f, v)``; theta = 1 (symmetric, the default: the
Euler-Lagrange equation of an energy, symmetric Jacobian), 0 or -1 (skew-symmetric). The Nitsche
multiplier ``lambda = [P(u)]_+`` (Pa) is the contact pressure that enters the equilibrium: with
the rigid translation v = e_y, ``integral_Gc lambda ds = f |Omega_h|`` exactly
(``HertzResult.contact_pressure``).

In 2D the horizontal rigid translation is free (frictionless contact, no Dirichlet condition): the
residual is exactly invariant under ``u -> u + c e_x`` (F(u; e_x) = 0 for every u), so e_x is a
right and a left null vector of the Jacobian J. It is fixed by the constraint "mass-weighted mean
of u_x = 0" (as in the DEM; uniform density, so the area-weighted mean), ``m . u = 0`` with
``m_i = (phi_i . e_x, 1)``. Newton's linear solves use ``J + eps M_x`` (MUMPS LU), ``M_x`` the
mass matrix of the x-components and eps = 1e-10 E / R^2: nonsingular, and since e_x^T J = 0,
e_x^T F = 0 and ``M_x e_x = m``, every update satisfies ``m . du = 0`` exactly. The residual is
not modified, so the converged solution is the exact one; the perturbed Jacobian only leaves a
relative error ~ 20 eps R^2 / E = 2e-9 per iteration (no extra iteration in practice). Each update is
also projected onto ``m . du = 0`` against round-off. The alternative
``singular_method="nullspace"`` attaches e_x to J as a PETSc MatNullSpace and lets MUMPS detect
the null pivot (ICNTL(24) = 1); with MUMPS's default threshold it sees the null pivot on coarse meshes
but not on h <= 3e-3, where the LU of the numerically singular J still works thanks to the
projection (same results), but less safely.

The mesh polygon of :func:`dolfinx_dem.meshes.create_disc` does not, in general, have a vertex at
the origin; the plane is put at ``y_plane = min_y`` of the mesh so that the discrete disc touches
it (the difference is at most h^2 / (8 R)). With ``exact_gap=True`` the gap uses the circle
instead of the polygon, ``g = R - sqrt(R^2 - x^2) + u_y`` with the plane at y = 0: this removes
the pressure peaks of the multiplier at the polygon's vertices (pressed flat onto the plane).
Newton starts from the rigid translation ``u = (0, -a_H^2 / (2 R))`` (a_H the Hertz
half-width), which gives a contact zone of about the right size; it converges in 3-5 iterations
(semi-smooth Newton: the active set settles, then one exact step), so load stepping is optional.

In 2D, pressures are sampled at equispaced interior points of the contact facets. Two estimates:

* the Nitsche multiplier ``lambda = [p(u_h) - gamma g(u_h)]_+``: >= 0 and in exact equilibrium
  with the load, but it oscillates within each facet (+-10 % on h = 1.2e-2, polygon gap);
* the FE traction ``p(u_h) = e_y . sigma(u_h) n``: smooth inside the contact zone, slightly
  negative just outside it.

The contact half-width ``a`` is measured by a least-squares fit of the Hertz profile to the
traction on the samples in contact (:func:`contact_half_width_fit`: p^2 is quadratic in x),
which resolves the edge below the mesh size and hardly depends on gamma0; the outermost samples
with lambda > 0 (:func:`contact_half_width_last`) and the fit to lambda are reported as well.
In 3D the contact radius is the moment measure of lambda about the z axis,
``a = sqrt(5/2 integral r^2 lambda / integral lambda)`` (:func:`contact_radius_moments`), and the
approach is u_z at the top of the ball (0, 0, 2R), a mesh vertex; the samples are 2D only.

Units are SI throughout. :func:`solve_hertz` is collective on ``comm``.
"""

from __future__ import annotations

import dataclasses
import time
import typing

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, meshes
from dolfinx_dem.errors import InputError, SolverError
from dolfinx_dem.fem.common import (
    check_degree,
    check_elastic,
    check_int,
    check_positive,
    gather_sorted,
    global_min,
    lame,
    owned_facets,
)
from dolfinx_dem.fem.nitsche import MeanUx, NewtonSolver, assembled_norm, sample_contact, top_displacement
from dolfinx_dem.hertz import (
    HertzAnalytic,
    contact_half_width_fit,
    contact_half_width_last,
    contact_half_width_moments,
    contact_radius_moments,
    hertz_analytic,
    hertz_analytic_3d,
)

__all__ = [
    "HertzAnalytic",
    "HertzResult",
    "contact_half_width_fit",
    "contact_half_width_last",
    "hertz_analytic",
    "solve_hertz",
]

_CONTACT = 1  # facet tag of the potential contact boundary (lower half of the disc)


# --- result -------------------------------------------------------------------------------------


@dataclasses.dataclass
class HertzResult:
    """The FEM solution of the Hertz problem and the measured quantities (SI units).

    Pressure samples (2D only; empty arrays and NaN in 3D) are on the owned facets of the lower
    half of the boundary (gathered on every rank, sorted by x): ``samples_per_facet`` equispaced
    interior points per facet (facet vertices excluded, where the stress jumps between cells).
    In 3D the forces and the load are those of the quarter ball.
    """

    mesh: typing.Any  # dolfinx.mesh.Mesh
    u: typing.Any  # displacement Function (m), Lagrange P1/P2 vector
    h: float  # requested mesh size (m)
    dim: int  # 2 (disc) or 3 (quarter ball)
    num_cells: int  # global number of cells
    degree: int
    gamma0: float
    theta: float
    exact_gap: bool
    y_plane: float  # height of the rigid plane (m): the lowest mesh node (0 with exact_gap)
    num_dofs: int  # global number of scalar displacement dofs
    iterations: int  # Newton iterations (sum over load steps)
    null_pivots: int  # MUMPS's null pivots in the last LU ("nullspace" method only; 1 = e_x)
    contact_x: np.ndarray  # (n,) sample x positions (m)
    contact_pressure: np.ndarray  # (n,) Nitsche multiplier lambda = [p - gamma g]_+ (Pa)
    traction_pressure: np.ndarray  # (n,) p(u_h) = e_y . sigma(u_h) n of the FE stress (Pa)
    contact_gap: np.ndarray  # (n,) g(u_h) (m), negative = penetration
    contact_half_width: float  # a (m): Hertz fit to the traction in contact (fit_fraction)
    contact_half_width_multiplier: float  # a (m): Hertz fit to the multiplier lambda
    contact_half_width_last: float  # a (m): half the span of the samples with lambda > 0
    contact_half_width_moment: float  # a (m): moment measure of lambda, 2 sqrt(2nd central moment / force)
    contact_half_width_moment_traction: float  # a (m): moment measure of the traction where lambda > 0
    moment_centre: float  # centre of lambda, integral x lambda / integral lambda (m); 2D
    contact_radius: float  # a (m), 3D: moment measure of lambda about the z axis (NaN in 2D)
    fit_peak_pressure: float  # p0 of the fit to the traction (Pa)
    fit_centre: float  # centre of the fitted profile (m)
    max_contact_pressure: float  # max of the traction over the samples with lambda > 0 (Pa)
    max_multiplier: float  # max of lambda (Pa)
    top_vertical_displacement: float  # u_y at the top of the disc, x = 0 (m); u_z at (0, 0, 2R)
    contact_force: float  # integral of lambda over the contact boundary (N/m; N in 3D)
    applied_load: float  # f |Omega_h| (N/m; N in 3D), the body force on the mesh
    mean_ux: float  # mass-weighted mean of u_x (m); 0 in 3D (symmetry)
    residual: float  # final ||F(u_h)|| / ||(f, v)||, Euclidean norms of the assembled vectors (free dofs)
    analytic: typing.Any  # HertzAnalytic (2D) or HertzAnalytic3D (whole ball)
    times: dict  # wall times (s): mesh, setup, solve, postprocess, total (max over ranks)

    def write_xdmf(self, path) -> None:
        """Write the displacement, interpolated to P1 (Debian's XDMF keeps vertex values only)."""
        import dolfinx.io

        V1 = _compat.create_vector_space(self.mesh, "Lagrange", 1)
        u1 = dolfinx.fem.Function(V1, name="displacement")
        u1.interpolate(self.u)
        with dolfinx.io.XDMFFile(self.mesh.comm, str(path), "w") as xdmf:
            xdmf.write_mesh(self.mesh)
            xdmf.write_function(u1)


# --- the solver ---------------------------------------------------------------------------------


def solve_hertz(
    comm: MPI.Comm,
    h: float,
    degree: int = 2,
    R: float = 0.2,
    E: float = 25e6,
    nu: float = 0.25,
    body_force: float = 2e6,
    gamma0: float = 20.0,
    theta: float = 1.0,
    *,
    exact_gap: bool = False,
    singular_method: str = "regularise",
    regularisation: float = 1e-10,
    load_steps: int = 1,
    rtol: float = 1e-10,
    max_it: int = 30,
    fit_fraction: float = 0.2,
    samples_per_facet: int = 8,
    quadrature_degree: int | None = None,
    dim: int = 2,
    refine: tuple[float, float] | None = None,
) -> HertzResult:
    """Solve the static Hertz problem with P1/P2 FEM and Nitsche frictionless contact.

    Args:
        comm: MPI communicator (collective).
        h: Mesh size (m) passed to :func:`dolfinx_dem.meshes.create_discs` (``create_balls``
            in 3D), 0 < h < R.
        degree: Lagrange degree of the displacement, 1 or 2.
        R: Disc (ball) radius (m), > 0; centre (0, R) (in 3D (0, 0, R)).
        E: Young's modulus (Pa), > 0.
        nu: Poisson's ratio, -1 < nu < 0.5 (plane strain in 2D).
        body_force: Magnitude f (N/m^3) > 0 of the downward body force (0, -f) or (0, 0, -f).
        gamma0: Nitsche parameter, gamma = gamma0 E / h_K, > 0.
        theta: Nitsche variant, 1 (symmetric), 0 or -1 (skew-symmetric); any value in [-1, 1].
        exact_gap: Measure the gap from the circle (sphere) instead of the mesh (see above).
        singular_method: How the linear solves handle the free x-translation (2D): "regularise"
            (default) or "nullspace" (see the module docstring).
        regularisation: eps / (E / R^2) of the "regularise" method (2D), > 0.
        load_steps: Number of equal load increments (>= 1), each solved by Newton.
        rtol: Newton stops when the update's norm is <= rtol times the first update's.
        max_it: Maximum Newton iterations per load step.
        fit_fraction: Threshold of :func:`contact_half_width_fit`, in (0, 1).
        samples_per_facet: Pressure samples per contact facet (>= 1).
        quadrature_degree: Quadrature degree on the contact boundary (default 4 * degree: the
            contact integrand has a kink at the edge of the contact zone).
        dim: 2 (the disc) or 3 (the quarter ball, see the module docstring).
        refine: (h_min, radius): mesh size h_min within ``radius`` of the contact point (the
            ``refine`` of ``create_discs``/``create_balls``); None: uniform h.

    Returns:
        A :class:`HertzResult`; its numbers and sample arrays are identical on every rank (the
        mesh and the Function are distributed).

    Raises:
        ValueError: bad input. RuntimeError: Newton did not converge.
    """
    from dolfinx_dem.meshes import create_balls, create_discs

    t_start = time.perf_counter()
    h = check_positive("h (mesh size)", h)
    degree = check_degree(degree)
    R = check_positive("R (radius)", R)
    if h >= R:
        raise InputError(f"h (mesh size) must be smaller than R, got h={h}, R={R}")
    E, nu = check_elastic(E, nu)
    f = check_positive("body_force", body_force)
    gamma0 = check_positive("gamma0 (Nitsche parameter)", gamma0)
    theta = float(theta)
    if not -1.0 <= theta <= 1.0:
        raise InputError(f"theta must be in [-1, 1] (1, 0, -1 are the usual variants), got {theta}")
    if singular_method not in NewtonSolver._METHODS:
        raise InputError(
            f"singular_method must be one of {', '.join(NewtonSolver._METHODS)}, got {singular_method!r}"
        )
    regularisation = check_positive("regularisation", regularisation)
    load_steps = check_int("load_steps", load_steps, 1)
    max_it = check_int("max_it", max_it, 1)
    samples_per_facet = check_int("samples_per_facet", samples_per_facet, 1)
    rtol = check_positive("rtol", rtol)
    if not 0.0 < fit_fraction < 1.0:
        raise InputError(f"fit_fraction must be in (0, 1), got {fit_fraction!r}")
    if quadrature_degree is None:
        quadrature_degree = 4 * degree
    quadrature_degree = check_int("quadrature_degree", quadrature_degree, 1)
    if dim not in (2, 3):
        raise InputError(f"dim must be 2 (disc) or 3 (quarter ball), got {dim!r}")
    d = dim
    if refine is not None:
        refine = ((0.0,) * d, *refine)  # at the contact point; create_* check the values
    analytic = (hertz_analytic if d == 2 else hertz_analytic_3d)(R, E, nu, f)

    centre = (0.0,) * (d - 1) + (R,)
    if d == 2:
        mesh, _, _ = create_discs(comm, [(centre, R)], h, refine=refine)
    else:
        mesh, _, _ = create_balls(comm, [(centre, R)], h, cut=["x", "y"], refine=refine)
    t_mesh = time.perf_counter()

    # potential contact boundary: the lower half of the circle or sphere (every vertex on it: not
    # the flat symmetry faces of the quarter ball)
    fdim = d - 1
    contact_facets = np.sort(meshes.locate_boundary_facets(
        mesh, lambda x: (x[d - 1] < R) & (np.sum((x[:d].T - centre) ** 2, axis=1) >= R**2 * (1 - 1e-9))))
    tags = dolfinx.mesh.meshtags(
        mesh, fdim, contact_facets, np.full(contact_facets.size, _CONTACT, dtype=np.int32)
    )
    ds_c = ufl.Measure(
        "ds",
        domain=mesh,
        subdomain_data=tags,
        subdomain_id=_CONTACT,
        metadata={"quadrature_degree": quadrature_degree},
    )
    y_plane = 0.0 if exact_gap else global_min(comm, mesh.geometry.x[:, d - 1])

    # Nitsche residual (module docstring)
    V = _compat.create_vector_space(mesh, "Lagrange", degree)
    u = dolfinx.fem.Function(V, name="displacement")
    v = ufl.TestFunction(V)
    lmbda, mu = lame(E, nu)

    def eps(w):
        return ufl.sym(ufl.grad(w))

    def sigma(w):
        return lmbda * ufl.tr(eps(w)) * ufl.Identity(d) + 2.0 * mu * eps(w)

    n = ufl.FacetNormal(mesh)
    e_y = ufl.unit_vector(d - 1, d)  # the vertical direction, normal of the plane
    x = ufl.SpatialCoordinate(mesh)
    r2 = sum(x[i] ** 2 for i in range(d - 1))  # squared distance from the vertical axis

    def pressure(w):
        return ufl.dot(e_y, ufl.dot(sigma(w), n))

    gamma = gamma0 * E / ufl.CellDiameter(mesh)
    if exact_gap:
        gap = R - ufl.sqrt(R**2 - r2) + u[d - 1]  # r <= R on the polygon
    else:
        gap = x[d - 1] + u[d - 1] - y_plane
    P = pressure(u) - gamma * gap
    multiplier = ufl.conditional(ufl.gt(P, 0.0), P, 0.0)
    load_factor = dolfinx.fem.Constant(mesh, PETSc.ScalarType(1.0))
    force = -f * load_factor * e_y
    load_form = ufl.inner(force, v) * ufl.dx
    F = (
        ufl.inner(sigma(u), eps(v)) * ufl.dx
        - theta / gamma * pressure(u) * pressure(v) * ds_c
        + 1.0 / gamma * multiplier * (theta * pressure(v) - gamma * v[d - 1]) * ds_c
        - load_form
    )

    if d == 2:
        mean_ux, bcs = MeanUx(V), []
    else:  # symmetry: u_x = 0 on x = 0, u_y = 0 on y = 0
        mean_ux, bcs = None, []
        for i in range(2):
            facets = meshes.locate_boundary_facets(mesh, lambda x, i=i: np.abs(x[i]) <= 1e-10 * R)
            dofs = dolfinx.fem.locate_dofs_topological(V.sub(i), fdim, facets)
            bcs.append(dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, V.sub(i)))
    newton = NewtonSolver(
        comm, F, u, mean_ux, rtol, 1e-14 * R, max_it, singular_method, regularisation * E / R**2, bcs
    )
    t_setup = time.perf_counter()
    try:
        iterations = 0
        for step in range(1, load_steps + 1):
            load_factor.value = step / load_steps
            if step == 1:
                # rigid downward translation: a contact zone of about the Hertz width
                delta = analytic.a**2 / (2.0 * R) / load_steps
                u.interpolate(lambda x, delta=delta: np.stack([np.zeros(x.shape[1])] * (d - 1)
                                                              + [np.full(x.shape[1], -delta)]))
            it, converged = newton.solve(u)
            iterations += int(it)
            if not converged:
                raise SolverError(
                    f"Newton did not converge in {max_it} iterations (load step {step} of "
                    f"{load_steps}); try load_steps > 1 or another gamma0"
                )
        null_pivots = newton.null_pivots()
    finally:
        newton.close()
    u_vec = _compat.petsc_vec(u)
    if mean_ux is not None:
        mean_ux.remove(u_vec)  # round-off only
    u_vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    t_solve = time.perf_counter()

    # --- postprocessing
    residual = assembled_norm(F, bcs) / assembled_norm(load_form, bcs)

    def integral(expr) -> float:
        return comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr)), op=MPI.SUM)

    contact_force = integral(multiplier * ds_c)
    in_contact = ufl.conditional(ufl.gt(P, 0.0), pressure(u), 0.0)
    nan, empty = float("nan"), np.zeros(0)
    if d == 2:
        W = _compat.create_tensor_space(mesh, "DG", degree - 1)
        sigma_h = dolfinx.fem.Function(W)
        _compat.interpolate_expression(sigma_h, sigma(u))  # exact: sigma(u_h) is in DG(degree-1)
        samples = sample_contact(
            u, sigma_h, owned_facets(mesh, contact_facets), y_plane, gamma0, E, samples_per_facet, R,
            exact_gap,
        )
        xs, lam, p, g = gather_sorted(comm, *samples)
        traction_in_contact = np.where(lam > 0.0, p, 0.0)
        a_fit, p0_fit, fit_centre = contact_half_width_fit(xs, traction_in_contact, fit_fraction)
        a_fit_multiplier = contact_half_width_fit(xs, lam, fit_fraction)[0]
        # moment measure of the half-width (hertz.contact_half_width_moments), by quadrature on Gc
        a_moment, moment_centre = contact_half_width_moments(
            *(integral(multiplier * x[0] ** k * ds_c) for k in range(3)))
        a_moment_traction, _ = contact_half_width_moments(
            *(integral(in_contact * x[0] ** k * ds_c) for k in range(3)))
        a_radius = nan
    else:
        xs = lam = p = g = traction_in_contact = empty
        a_fit = p0_fit = fit_centre = a_fit_multiplier = a_moment = moment_centre = a_moment_traction = nan
        a_radius = contact_radius_moments(contact_force, integral(multiplier * r2 * ds_c))
    applied = f * integral(dolfinx.fem.Constant(mesh, PETSc.ScalarType(1.0)) * ufl.dx)
    _, u_top = top_displacement(u, R)
    t_end = time.perf_counter()

    times = {
        "mesh": t_mesh - t_start,
        "setup": t_setup - t_mesh,
        "solve": t_solve - t_setup,
        "postprocess": t_end - t_solve,
        "total": t_end - t_start,
    }
    return HertzResult(
        mesh=mesh,
        u=u,
        h=h,
        dim=d,
        num_cells=mesh.topology.index_map(d).size_global,
        degree=degree,
        gamma0=gamma0,
        theta=theta,
        exact_gap=bool(exact_gap),
        y_plane=y_plane,
        num_dofs=V.dofmap.index_map.size_global * V.dofmap.index_map_bs,
        iterations=iterations,
        null_pivots=null_pivots,
        contact_x=xs,
        contact_pressure=lam,
        traction_pressure=p,
        contact_gap=g,
        contact_half_width=a_fit,
        contact_half_width_multiplier=a_fit_multiplier,
        contact_half_width_last=contact_half_width_last(xs, lam) if d == 2 else nan,
        contact_half_width_moment=a_moment,
        contact_half_width_moment_traction=a_moment_traction,
        moment_centre=moment_centre,
        contact_radius=a_radius,
        fit_peak_pressure=p0_fit,
        fit_centre=fit_centre,
        max_contact_pressure=float(np.max(traction_in_contact)) if d == 2 else nan,
        max_multiplier=float(np.max(lam)) if d == 2 else nan,
        top_vertical_displacement=float(u_top),
        contact_force=contact_force,
        applied_load=applied,
        mean_ux=float(mean_ux.mean(u_vec)) if mean_ux is not None else 0.0,
        residual=float(residual),
        analytic=analytic,
        times={k: comm.allreduce(t, op=MPI.MAX) for k, t in times.items()},
    )
