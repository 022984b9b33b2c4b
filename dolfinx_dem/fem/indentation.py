"""DOLFINx finite-element reference: a rigid cylinder indenting an elastic block (plane strain).

The elastic block [-L, L] x [-D, 0] (m; L = D = 0.5), Young's modulus E (Pa), Poisson's ratio nu,
plane strain, is clamped at the bottom (u = 0 on y = -D); its sides and its top are free. A rigid
cylinder of radius R (m), centre ``c = (0, R - delta)``, is pushed into the top by the
indentation ``delta > 0`` (its lowest point is at y = -delta). Contact is frictionless. The
problem is symmetric about x = 0: only the half block x >= 0 is meshed, with the symmetry
condition u_x = 0 on x = 0; forces and moments are reported for the whole block.

Gap and normal (small strain, but the exact geometry of the obstacle): a point x of the top
moves to ``X = x + u``; its gap is the exact signed distance from the circle,

    g(u) = |x + u - c| - R    (> 0 outside the cylinder),

and ``nu(u) = (x + u - c) / |x + u - c|`` is the cylinder's outward unit normal at the closest
point (pointing into the block, nu ~ (0, -1) under the cylinder); its derivative in the direction
v is ``g'(u)[v] = nu(u) . v``. The exact distance is used rather than the vertical gap
``y + u_y - (c_y - sqrt(R^2 - x^2))`` because a/R reaches 0.26 at delta = 0.02 m: the obstacle's normal
is tilted by up to 15 degrees at the edge of the contact (its vertical component 0.97), more than
the accuracy sought, and the exact form costs nothing (UFL differentiates it for Newton).

With n = e_y the outward normal of the top, the contact pressure is
``p(u) = nu(u) . sigma(u) n`` (Pa, >= 0 in compression) and the frictionless traction on the block
is ``p nu``. Signorini: ``g >= 0, p >= 0, p g = 0``, i.e. ``p = [p - gamma g]_+``.

Nitsche's method (Chouly, Hild & Renard, Math. Comp. 84, 2015; the obstacle's normal taken at the
current point), ``P(u) = p(u) - gamma g(u)``, ``gamma = gamma0 E / h_K``: find u, u = 0 on the
bottom, u_x = 0 on x = 0, such that for all admissible v

    (sigma(u), eps(v)) - theta/gamma (p(u), p_u(v))_Gc
        + 1/gamma ([P(u)]_+, theta p_u(v) - gamma nu(u) . v)_Gc = 0,

``p_u(v) = nu(u) . sigma(v) n``, theta = 1 (symmetric), 0 or -1. It is consistent for any theta
(where ``[P(u)]_+ = p(u)`` the theta terms cancel). The Nitsche multiplier ``lambda = [P(u)]_+``
is the contact pressure in equilibrium with the block: the vertical contact force is

    P = integral_Gc lambda (-nu_y) ds    (N/m, whole block),

which equals the reaction of the clamp, ``integral_bottom e_y . sigma n ds``. The reaction is
computed as ``(sigma(u_h), eps(w))`` with w the Lagrange function equal to e_y at the bottom's nodes
and 0 at all others: since the residual vanishes on every admissible v (e_y - w is one), this
is the discrete balance of the solution, equal to P to the solver's tolerance
(``IndentationResult.reaction``).

Measured quantities (the DEM measures the same from its facet pressures):

* ``a``: the moment measure of the contact half-width, ``a = 2 sqrt(int x^2 lambda / int
  lambda)`` over the top (by quadrature, undeformed x; the centre is 0 by symmetry), the primary
  measure of :mod:`dolfinx_dem.fem.hertz` (``hertz.contact_half_width_moments``): exactly a for
  an elliptic (Hertz) profile, the half-width of the Hertz profile with the same force and
  second moment otherwise;
* ``a_fit``: the half-width of the Hertz profile fitted to the FE traction ``p(u_h)`` sampled on
  the facets in contact (``hertz.contact_half_width_fit``), ``a_last``: the outermost sample with
  lambda > 0;
* ``p_max``: the largest sampled FE traction ``p(u_h)`` where lambda > 0 (``max_contact_pressure``
  of :mod:`dolfinx_dem.fem.hertz`).

The half-space (Hertz) estimate for the same load, ``a_H = sqrt(4 P R / (pi E*))``,
``p0_H = 2 P / (pi a_H)``, ``E* = E / (1 - nu^2)``, is only indicative: the block is finite
(a / D up to 0.1) and a / R is not small (up to 0.26).

Mesh (gmsh, :func:`create_indentation_mesh`): triangles of size h in the box
[0, 0.08] x [-0.06, 0] m around the contact zone (a = 0.053 m at delta = 0.02 m; a solve whose
contact zone reaches x > 0.08 - 2 h is refused), growing linearly over 0.15 m to 16 h outside,
so that halving h halves the mesh size everywhere. Newton (MUMPS LU, consistent Jacobian by UFL)
starts from u = 0 for the first indentation (the initial active set is the geometric overlap)
and from the previous solution scaled by the ratio of the indentations for the next ones (P and
the displacements grow about linearly with delta). It takes 9-15 iterations on h = 4e-3 to 1e-3
m, most of them spent settling the active set at the quadrature points.

Units are SI throughout. The solvers are collective on ``comm``.
"""

from __future__ import annotations

import dataclasses
import time
import typing

import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError, SolverError
from dolfinx_dem.fem.common import (
    check_degree,
    check_elastic,
    check_int,
    check_positive,
    gather_sorted,
    lame,
    owned_facets,
)
from dolfinx_dem.hertz import contact_half_width_fit, contact_half_width_last, contact_half_width_moments

__all__ = ["IndentationResult", "create_indentation_mesh", "indentation_reference", "solve_indentation"]

HALF_WIDTH = 0.5  # L (m): the block is [-L, L] x [-DEPTH, 0]
DEPTH = 0.5  # D (m)
FINE_BOX = (0.08, 0.06)  # (x extent, depth) of the zone meshed with size h (m): a <= 0.053 m here
TRANSITION = 0.15  # width over which the size grows from h to COARSE_RATIO h (m)
COARSE_RATIO = 16.0

# facet tags of the half block [0, L] x [-D, 0]
SYMMETRY, SIDE, BOTTOM, TOP = 1, 2, 3, 4


def create_indentation_mesh(comm: MPI.Comm, h: float):
    """The half block [0, L] x [-D, 0], triangles of size h (m) near the contact (module doc).

    Returns (mesh, facet_tags): facets tagged SYMMETRY (x = 0), SIDE (x = L), BOTTOM (y = -D),
    TOP (y = 0).
    """
    import gmsh

    from dolfinx_dem.meshes import _mesh_from_gmsh

    h = check_positive("h (mesh size)", h)
    if h > FINE_BOX[1] / 2:
        raise InputError(f"h (mesh size) must be <= {FINE_BOX[1] / 2} m (the refined zone), got {h}")

    def build() -> int:
        gmsh.model.add("indentation")
        surface = gmsh.model.occ.addRectangle(0.0, -DEPTH, 0.0, HALF_WIDTH, DEPTH)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [surface], 1)
        curves = {SYMMETRY: [], SIDE: [], BOTTOM: [], TOP: []}
        for _, curve in gmsh.model.getBoundary([(2, surface)], oriented=False):
            x, y, _ = gmsh.model.occ.getCenterOfMass(1, curve)
            tag = (SYMMETRY if abs(x) < 1e-9 else SIDE if abs(x - HALF_WIDTH) < 1e-9
                   else BOTTOM if abs(y + DEPTH) < 1e-9 else TOP)
            curves[tag].append(curve)
        for tag, group in curves.items():
            gmsh.model.addPhysicalGroup(1, group, tag)
        box = gmsh.model.mesh.field.add("Box")
        for name, value in (("VIn", h), ("VOut", COARSE_RATIO * h), ("XMin", -1.0), ("XMax", FINE_BOX[0]),
                            ("YMin", -FINE_BOX[1]), ("YMax", 1.0), ("Thickness", TRANSITION)):
            gmsh.model.mesh.field.setNumber(box, name, value)
        gmsh.model.mesh.field.setAsBackgroundMesh(box)
        for option in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints", "MeshSizeFromCurvature"):
            gmsh.option.setNumber(f"Mesh.{option}", 0)
        gmsh.model.mesh.generate(2)
        return 2

    mesh, _, facet_tags = _mesh_from_gmsh(comm, build)
    return mesh, facet_tags


@dataclasses.dataclass
class IndentationResult:
    """The FEM solution for one indentation and the measured quantities (SI units, whole block).

    Samples are on the owned top facets (gathered on every rank, sorted by x >= 0):
    ``samples_per_facet`` equispaced interior points per facet.
    """

    mesh: typing.Any  # dolfinx.mesh.Mesh (the half block)
    u: typing.Any  # displacement Function (m), a copy for this indentation
    delta: float  # indentation (m)
    h: float  # mesh size in the contact zone (m)
    degree: int
    gamma0: float
    theta: float
    num_dofs: int  # global number of scalar displacement dofs (half block)
    num_cells: int  # global number of triangles (half block)
    iterations: int  # Newton iterations
    P: float  # vertical contact force, integral of lambda (-nu_y) (N/m)
    reaction: float  # vertical reaction of the clamp (N/m)
    normal_force: float  # integral of lambda (N/m)
    a: float  # moment half-width of lambda (m)
    a_fit: float  # Hertz fit to the FE traction in contact (m)
    a_last: float  # outermost sample with lambda > 0 (m)
    p_max: float  # largest FE traction p(u_h) where lambda > 0 (Pa)
    max_multiplier: float  # largest lambda sample (Pa)
    min_gap: float  # smallest sampled gap (m), negative = penetration
    contact_x: np.ndarray  # (n,) sample x (m)
    contact_pressure: np.ndarray  # (n,) lambda (Pa)
    traction_pressure: np.ndarray  # (n,) p(u_h) (Pa)
    contact_gap: np.ndarray  # (n,) g(u_h) (m)
    hertz_a: float  # sqrt(4 P R / (pi E*)) (m)
    hertz_p0: float  # 2 P / (pi hertz_a) (Pa)
    times: dict  # wall times (s): solve, postprocess (max over ranks)

    def summary(self) -> dict:
        """The scalar results, as plain floats and ints (for JSON)."""
        keys = ("delta", "h", "degree", "gamma0", "theta", "num_dofs", "num_cells", "iterations", "P",
                "reaction", "normal_force", "a", "a_fit", "a_last", "p_max", "max_multiplier", "min_gap",
                "hertz_a", "hertz_p0")
        return {**{k: getattr(self, k) for k in keys}, "times": dict(self.times)}


class _Indentation:
    """Forms, boundary conditions and Newton solver of the half block on one mesh."""

    def __init__(self, comm, h, degree, R, E, nu, gamma0, theta, rtol, max_it, quadrature_degree):
        self.comm, self.R, self.E, self.gamma0, self.theta = comm, R, E, gamma0, theta
        mesh, tags = create_indentation_mesh(comm, h)
        self.mesh = mesh
        self.top_facets = np.sort(tags.find(TOP))
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags, metadata={"quadrature_degree": quadrature_degree})
        self.ds_c = ds(TOP)

        V = _compat.create_vector_space(mesh, "Lagrange", degree)
        self.V = V
        self.u = dolfinx.fem.Function(V, name="displacement")
        u, v = self.u, ufl.TestFunction(V)
        lmbda, mu = lame(E, nu)

        def eps(w):
            return ufl.sym(ufl.grad(w))

        def sigma(w):
            return lmbda * ufl.tr(eps(w)) * ufl.Identity(2) + 2.0 * mu * eps(w)

        self.sigma = sigma
        x = ufl.SpatialCoordinate(mesh)
        self.x = x
        self.delta = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
        centre = ufl.as_vector((0.0, R - self.delta))
        d = x + u - centre
        distance = ufl.sqrt(ufl.dot(d, d))
        normal = d / distance  # nu(u): the cylinder's normal, into the block
        self.normal = normal
        gap = distance - R
        n = ufl.FacetNormal(mesh)

        def pressure(w):
            return ufl.dot(normal, ufl.dot(sigma(w), n))

        gamma = gamma0 * E / ufl.CellDiameter(mesh)
        P = pressure(u) - gamma * gap
        self.multiplier = ufl.conditional(ufl.gt(P, 0.0), P, 0.0)
        F = (ufl.inner(sigma(u), eps(v)) * ufl.dx
             - theta / gamma * pressure(u) * pressure(v) * self.ds_c
             + 1.0 / gamma * self.multiplier * (theta * pressure(v) - gamma * ufl.dot(normal, v)) * self.ds_c)
        self.F = F

        bcs = [_compat.zero_dirichletbc(V, tags.find(BOTTOM)),
               _compat.zero_dirichletbc(V, tags.find(SYMMETRY), component=0)]
        J = ufl.derivative(F, u, ufl.TrialFunction(V))
        self.solver, self._problem = _compat.newton_solver(comm, F, u, J, bcs)
        # DOLFINx 0.5's "residual" criterion divides by the first update's norm: the incremental
        # criterion ||du_k|| <= rtol ||du_1|| is used (as in fem/hertz.py)
        self.solver.convergence_criterion = "incremental"
        self.solver.rtol = rtol
        self.solver.atol = 1e-16 * R
        self.solver.max_it = max_it
        self.solver.error_on_nonconvergence = False
        ksp = self.solver.krylov_solver
        ksp.setType("preonly")
        ksp.getPC().setType("lu")
        ksp.getPC().setFactorSolverType("mumps")

        # w = e_y at the bottom's nodes, 0 elsewhere: (sigma(u), eps(w)) is the clamp's reaction
        w = dolfinx.fem.Function(V)
        w.interpolate(lambda x: np.stack([np.zeros(x.shape[1]), np.isclose(x[1], -DEPTH).astype(np.float64)]))
        self.reaction_form = dolfinx.fem.form(ufl.inner(sigma(u), eps(w)) * ufl.dx)
        self.W = _compat.create_tensor_space(mesh, "DG", degree - 1)

    def integral(self, expr) -> float:
        local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr))
        return self.comm.allreduce(local, op=MPI.SUM)

    def sample(self, samples_per_facet: int):
        """(x, lambda, p, g) at equispaced interior points of the owned top facets (gathered)."""
        sigma_h = dolfinx.fem.Function(self.W)
        _compat.interpolate_expression(sigma_h, self.sigma(self.u))  # exact: sigma(u_h) in DG(k-1)
        facets = owned_facets(self.mesh, self.top_facets)
        cells, facet_x, cell_x = _compat.facet_cell_and_vertices(self.mesh, facets)
        s = (np.arange(samples_per_facet) + 0.5) / samples_per_facet
        points = (facet_x[:, :1, :] + s[None, :, None] * (facet_x[:, 1:2, :] - facet_x[:, :1, :])).reshape(-1, 3)
        point_cells = np.repeat(cells, samples_per_facet)
        diffs = cell_x[:, :, None, :2] - cell_x[:, None, :, :2]
        h_cell = np.repeat(np.sqrt(np.max(np.sum(diffs**2, axis=-1), axis=(1, 2))), samples_per_facet)
        u_val = np.real(self.u.eval(points, point_cells)).reshape(-1, 2)
        sig = np.real(sigma_h.eval(points, point_cells)).reshape(-1, 2, 2)
        d = points[:, :2] + u_val - np.array([0.0, self.R - float(self.delta.value)])
        distance = np.linalg.norm(d, axis=1)
        normal = d / distance[:, None]
        p = np.einsum("ij,ij->i", normal, sig[:, :, 1])  # nu . sigma e_y (n = e_y on the top)
        g = distance - self.R
        lam = np.maximum(p - self.gamma0 * self.E / h_cell * g, 0.0)
        return gather_sorted(self.comm, points[:, 0].copy(), lam, p, g)


def _check_deltas(deltas, R: float) -> list[float]:
    values = [check_positive("delta (indentation)", d) for d in np.atleast_1d(deltas)]
    if len(values) == 0:
        raise InputError("deltas must hold at least one indentation")
    if any(b <= a for a, b in zip(values, values[1:])):
        raise InputError(f"deltas must be increasing (each solve starts from the previous one), got {values}")
    if values[-1] > 0.5 * R:
        raise InputError(f"delta must be <= R / 2 = {0.5 * R} m (a / R would exceed 0.87), got {values[-1]}")
    return values


def solve_indentation(
    comm: MPI.Comm,
    h: float,
    deltas: typing.Sequence[float],
    degree: int = 2,
    R: float = 0.2,
    E: float = 1e4,
    nu: float = 0.3,
    gamma0: float = 20.0,
    theta: float = 1.0,
    *,
    rtol: float = 1e-10,
    max_it: int = 30,
    samples_per_facet: int = 8,
    quadrature_degree: int | None = None,
) -> list[IndentationResult]:
    """Solve the indentation problem (module docstring) for increasing indentations on one mesh.

    Args:
        comm: MPI communicator (collective).
        h: Mesh size in the contact zone (m), 0 < h <= 0.03.
        deltas: Indentations (m), increasing, each in (0, R / 2].
        degree: Lagrange degree of the displacement, 1 or 2.
        R: Cylinder radius (m), > 0.
        E: Young's modulus (Pa), > 0.
        nu: Poisson's ratio, -1 < nu < 0.5 (plane strain).
        gamma0: Nitsche parameter, gamma = gamma0 E / h_K, > 0.
        theta: Nitsche variant in [-1, 1] (1 symmetric, 0, -1 skew-symmetric).
        rtol: Newton stops when the update's norm is <= rtol times the first update's.
        max_it: Maximum Newton iterations per indentation.
        samples_per_facet: Pressure samples per top facet (>= 1).
        quadrature_degree: Quadrature degree on the top (default 4 * degree: the contact
            integrand has a kink at the edge of the contact zone).

    Returns:
        One :class:`IndentationResult` per indentation; the numbers and samples are identical on
        every rank.

    Raises:
        ValueError: bad input. RuntimeError: Newton did not converge, or no contact.
    """

    R = check_positive("R (radius)", R)
    deltas = _check_deltas(deltas, R)
    degree = check_degree(degree)
    E, nu = check_elastic(E, nu)
    gamma0 = check_positive("gamma0 (Nitsche parameter)", gamma0)
    theta = float(theta)
    if not -1.0 <= theta <= 1.0:
        raise InputError(f"theta must be in [-1, 1] (1, 0, -1 are the usual variants), got {theta}")
    rtol = check_positive("rtol", rtol)
    max_it = check_int("max_it", max_it, 1)
    samples_per_facet = check_int("samples_per_facet", samples_per_facet, 1)
    quadrature_degree = check_int("quadrature_degree", 4 * degree if quadrature_degree is None
                                   else quadrature_degree, 1)
    problem = _Indentation(comm, h, degree, R, E, nu, gamma0, theta, rtol, max_it, quadrature_degree)
    E_star = E / (1.0 - nu**2)
    num_cells = problem.mesh.topology.index_map(2).size_global
    num_dofs = problem.V.dofmap.index_map.size_global * problem.V.dofmap.index_map_bs
    ds_c, lam, x = problem.ds_c, problem.multiplier, problem.x

    results = []
    for k, delta in enumerate(deltas):
        t0 = time.perf_counter()
        if k > 0:
            problem.u.x.array[:] *= delta / deltas[k - 1]  # Dirichlet values are 0: kept
        problem.delta.value = delta
        iterations, converged = problem.solver.solve(problem.u)
        if not converged:
            raise SolverError(f"Newton did not converge in {max_it} iterations (delta = {delta} m, h = {h} m)")
        t1 = time.perf_counter()
        # whole block = 2 x half block (the moments' ratios are the same)
        P = 2.0 * problem.integral(-lam * problem.normal[1] * ds_c)
        if not P > 0.0:
            raise SolverError(f"no contact force at delta = {delta} m")
        reaction = 2.0 * comm.allreduce(dolfinx.fem.assemble_scalar(problem.reaction_form), op=MPI.SUM)
        m0, m2 = (2.0 * problem.integral(lam * x[0] ** k * ds_c) for k in (0, 2))
        a, _ = contact_half_width_moments(m0, 0.0, m2)
        xs, lam_s, p_s, g_s = problem.sample(samples_per_facet)
        edge = float(np.max(xs[lam_s > 0.0], initial=0.0))
        if edge > FINE_BOX[0] - 2.0 * h:
            raise SolverError(f"the contact zone at delta = {delta} m reaches x = {edge:.3g} m, beyond the "
                               f"refined zone x < {FINE_BOX[0] - 2.0 * h:.3g} m: use a smaller delta")
        traction_in_contact = np.where(lam_s > 0.0, p_s, 0.0)
        # the fit needs both sides of the (symmetric) profile
        a_fit = contact_half_width_fit(np.concatenate([-xs[::-1], xs]),
                                       np.concatenate([traction_in_contact[::-1], traction_in_contact]))[0]
        hertz_a = np.sqrt(4.0 * P * R / (np.pi * E_star))
        u_copy = dolfinx.fem.Function(problem.V, name="displacement")
        u_copy.x.array[:] = problem.u.x.array
        t2 = time.perf_counter()
        times = {"solve": t1 - t0, "postprocess": t2 - t1}
        results.append(IndentationResult(
            mesh=problem.mesh, u=u_copy, delta=delta, h=float(h), degree=degree, gamma0=gamma0, theta=theta,
            num_dofs=num_dofs, num_cells=num_cells, iterations=int(iterations), P=float(P),
            reaction=float(reaction), normal_force=float(m0), a=a, a_fit=a_fit,
            a_last=contact_half_width_last(np.concatenate([-xs[::-1], xs]), np.concatenate([lam_s[::-1], lam_s])),
            p_max=float(np.max(traction_in_contact)), max_multiplier=float(np.max(lam_s)),
            min_gap=float(np.min(g_s)), contact_x=xs, contact_pressure=lam_s, traction_pressure=p_s,
            contact_gap=g_s, hertz_a=float(hertz_a), hertz_p0=float(2.0 * P / (np.pi * hertz_a)),
            times={k: comm.allreduce(t, op=MPI.MAX) for k, t in times.items()}))
    return results


def indentation_reference(delta: float, h: float, comm: MPI.Comm = MPI.COMM_SELF, **kwargs) -> dict:
    """The FEM reference numbers for one indentation delta (m) on the mesh of size h (m).

    Returns ``dict(P=..., a=..., p_max=...)`` (N/m, m, Pa: the whole block's vertical contact
    force, moment half-width and peak pressure) plus the other scalars of
    :meth:`IndentationResult.summary`. ``kwargs`` go to :func:`solve_indentation`.
    """
    return solve_indentation(comm, h, [delta], **kwargs)[0].summary()
