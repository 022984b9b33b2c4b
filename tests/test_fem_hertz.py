"""The DOLFINx FEM reference of the static Hertz problem (disc on a rigid plane, Nitsche contact).

The coarse-mesh solution (h = 1.2e-2 m, P2) is computed once per process. Reference numbers from
the fine mesh (h = 1.5e-3 m, P2, gamma0 = 20, theta = 1): top vertical displacement
-1.3892e-2 m, contact half-width 0.976 of Hertz's.
"""

import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from dolfinx_dem.fem.elastodynamics import evaluate_at_points
from dolfinx_dem.fem.hertz import contact_half_width_fit, contact_half_width_last, hertz_analytic, solve_hertz
from dolfinx_dem.hertz import (
    contact_half_width_moments,
    contact_radius_moments,
    facet_pressure_moments,
    hertz_analytic_3d,
    point_force_moments,
    triangle_pressure_moments,
)

H_COARSE = 1.2e-2
U_TOP_FINE = -1.3892e-2  # m, h = 1.5e-3 P2 (measured)


@pytest.fixture(scope="module")
def coarse():
    return solve_hertz(MPI.COMM_WORLD, H_COARSE)


def test_hertz_analytic_values():
    hz = hertz_analytic(0.2, 25e6, 0.25, 2e6)
    assert hz.load == pytest.approx(2e6 * np.pi * 0.04)
    assert hz.E_star == pytest.approx(25e6 / 0.9375)
    assert hz.a == pytest.approx(np.sqrt(4 * hz.load * 0.2 / (np.pi * hz.E_star)))
    assert hz.a == pytest.approx(0.0489898, rel=1e-5)
    assert hz.p0 == pytest.approx(3.265986e6, rel=1e-5)
    # the pressure profile carries the load
    x = np.linspace(-hz.a, hz.a, 20001)
    assert np.trapz(hz.pressure(x), x) == pytest.approx(hz.load, rel=1e-4)
    assert hz.pressure(1.01 * hz.a) == 0.0


def test_half_width_measures_on_synthetic_hertz_profile():
    a, p0, xc = 0.05, 3e6, 1e-3
    x = np.linspace(-0.08, 0.08, 321)
    p = p0 * np.sqrt(np.clip(1 - ((x - xc) / a) ** 2, 0, None))
    a_fit, p0_fit, xc_fit = contact_half_width_fit(x, p, 0.2)
    assert a_fit == pytest.approx(a, rel=1e-10)
    assert p0_fit == pytest.approx(p0, rel=1e-10)
    assert xc_fit == pytest.approx(xc, abs=1e-12)
    # the outermost samples in contact are within one sample spacing of the edge
    assert a - 5e-4 <= contact_half_width_last(x, p) <= a
    with pytest.raises(ValueError):
        contact_half_width_fit(x, np.zeros_like(x))
    with pytest.raises(ValueError):
        contact_half_width_fit(x, p, 0.0)


def test_moment_half_width_of_hertz_profile_on_facets():
    """Uniform pressures on facets: exact moments; a Hertz profile gives a (to O(h^2))."""
    a, p0, xc = 0.05, 3e6, 1e-3
    edges = np.linspace(-0.06, 0.07, 2601)
    mid = 0.5 * (edges[:-1] + edges[1:])
    p = p0 * np.sqrt(np.clip(1 - ((mid - xc) / a) ** 2, 0, None))
    moments = facet_pressure_moments(edges[:-1], edges[1:], p * np.diff(edges))
    a_m, xc_m = contact_half_width_moments(*moments)
    assert a_m == pytest.approx(a, rel=1e-5)
    assert xc_m == pytest.approx(xc, abs=1e-8)
    # one facet [0, 1] with force 2: m1 = 1, m2 = 2 / 3 exactly; a = 2 sqrt(1/3 - 1/4)
    assert facet_pressure_moments([0.0], [1.0], [2.0]) == pytest.approx((2.0, 1.0, 2.0 / 3.0))
    assert contact_half_width_moments(2.0, 1.0, 2.0 / 3.0)[0] == pytest.approx(2 * np.sqrt(1 / 12))
    with pytest.raises(ValueError, match="no contact"):
        contact_half_width_moments(0.0, 0.0, 0.0)


@pytest.mark.mpi
def test_newton_converges_with_zero_mean_ux(coarse):
    assert 1 <= coarse.iterations <= 10
    assert coarse.residual < 1e-9
    u = coarse.u.x.array
    max_ux = MPI.COMM_WORLD.allreduce(np.max(np.abs(u[0::2])), op=MPI.MAX)
    assert max_ux > 1e-4
    assert abs(coarse.mean_ux) <= 1e-12 * max_ux


@pytest.mark.mpi
def test_contact_conditions_and_equilibrium(coarse):
    hz = coarse.analytic
    lam, p, g = coarse.contact_pressure, coarse.traction_pressure, coarse.contact_gap
    assert np.all(lam >= 0.0)
    in_contact = lam > 0
    # the FE traction is compressive in the contact zone; just outside it, it dips below 0 (FE
    # error at the edge: -0.125 p0 on this mesh, -0.06 p0 on h = 3e-3)
    assert np.all(p[in_contact] > 0.0)
    assert np.min(p) > -0.2 * hz.p0
    # Nitsche allows a penetration of order p0 h / (gamma0 E)
    assert np.min(g) > -0.5 * hz.p0 * H_COARSE / (coarse.gamma0 * 25e6)
    # equilibrium: the multiplier carries exactly the body force on the mesh, ~ f pi R^2
    assert coarse.contact_force == pytest.approx(coarse.applied_load, rel=1e-10)
    assert coarse.contact_force == pytest.approx(hz.load, rel=1e-2)
    # the sampled multiplier integrates to the load too
    assert np.trapz(lam, coarse.contact_x) == pytest.approx(hz.load, rel=2e-2)


@pytest.mark.mpi
def test_hertz_numbers(coarse):
    hz = coarse.analytic
    assert coarse.contact_half_width == pytest.approx(hz.a, rel=0.15)
    assert coarse.contact_half_width_last == pytest.approx(hz.a, rel=0.15)
    assert coarse.contact_half_width_last <= coarse.contact_half_width + H_COARSE
    assert coarse.max_contact_pressure == pytest.approx(hz.p0, rel=0.15)
    assert coarse.top_vertical_displacement == pytest.approx(U_TOP_FINE, rel=0.02)


def _mean_rotation(u) -> float:
    """Area-mean infinitesimal rotation 1/2 (du_y/dx - du_x/dy) (rad), collective."""
    mesh = u.function_space.mesh
    one = dolfinx.fem.Constant(mesh, 1.0)
    curl = ufl.grad(u)[1, 0] - ufl.grad(u)[0, 1]
    area, total = (
        mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(f * ufl.dx)), op=MPI.SUM)
        for f in (one, curl)
    )
    return 0.5 * total / area


@pytest.mark.mpi
def test_solution_is_symmetric(coarse):
    """u_x antisymmetric and u_y symmetric in x, up to a small rigid rotation.

    The rotation about the centre is a soft mode (only the tilt of the contact zone resists it),
    excited by the asymmetry of the unstructured mesh: 2.7e-4 rad on this mesh, below 1.2e-5 rad
    on h = 6e-3 and 3e-3.
    """
    R = 0.2
    phi = np.linspace(0.1, np.pi / 2 - 0.1, 7)
    points = np.concatenate(
        [np.stack([r * np.cos(phi), R + r * np.sin(phi)], axis=1) for r in (0.5 * R, 0.9 * R)]
        + [np.stack([r * np.cos(phi), R - r * np.sin(phi)], axis=1) for r in (0.5 * R, 0.9 * R)]
    )
    mirrored = points * np.array([-1.0, 1.0])
    u, u_m = evaluate_at_points(coarse.u, points), evaluate_at_points(coarse.u, mirrored)
    scale_x, scale_y = np.max(np.abs(u[:, 0])), np.max(np.abs(u[:, 1]))
    assert scale_x > 1e-4
    assert np.max(np.abs(u[:, 0] + u_m[:, 0])) < 0.1 * scale_x
    assert np.max(np.abs(u[:, 1] - u_m[:, 1])) < 0.02 * scale_y

    rotation = _mean_rotation(coarse.u)
    assert abs(rotation) * R < 0.05 * scale_x

    def without_rotation(x, values):
        return values - rotation * np.stack([-(x[:, 1] - R), x[:, 0]], axis=1)

    u, u_m = without_rotation(points, u), without_rotation(mirrored, u_m)
    assert np.max(np.abs(u[:, 0] + u_m[:, 0])) < 0.02 * scale_x
    assert np.max(np.abs(u[:, 1] - u_m[:, 1])) < 0.02 * scale_y
    assert abs(coarse.fit_centre) < 0.01 * coarse.contact_half_width
    # the moment measure of the multiplier and of the traction agree within 2 %, near the fit
    assert coarse.contact_half_width_moment == pytest.approx(coarse.contact_half_width, rel=0.01)
    traction = coarse.contact_half_width_moment_traction
    assert traction == pytest.approx(coarse.contact_half_width_moment, rel=0.02)
    assert abs(coarse.moment_centre) < 1e-6 * coarse.contact_half_width


@pytest.mark.mpi
def test_parallel_matches_serial(coarse, tempdir):
    """COMM_WORLD (1 or 2 ranks) against COMM_SELF on every rank: the same numbers."""
    comm = MPI.COMM_WORLD
    serial = solve_hertz(MPI.COMM_SELF, H_COARSE)
    for name in (
        "top_vertical_displacement",
        "contact_half_width",
        "contact_half_width_last",
        "contact_half_width_moment",
        "max_contact_pressure",
        "contact_force",
    ):
        assert getattr(coarse, name) == pytest.approx(getattr(serial, name), rel=1e-8), name
    assert coarse.iterations == serial.iterations
    assert coarse.num_dofs == serial.num_dofs
    np.testing.assert_allclose(coarse.contact_x, serial.contact_x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        coarse.contact_pressure, serial.contact_pressure, rtol=0, atol=1e-6 * serial.analytic.p0
    )
    coarse.write_xdmf(tempdir / "hertz.xdmf")
    if comm.rank == 0:
        assert (tempdir / "hertz.xdmf").is_file()


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_p1_converges():
    res = solve_hertz(MPI.COMM_WORLD, H_COARSE, degree=1)
    assert res.contact_force == pytest.approx(res.applied_load, rel=1e-10)
    assert res.contact_half_width == pytest.approx(res.analytic.a, rel=0.15)
    assert res.top_vertical_displacement == pytest.approx(U_TOP_FINE, rel=0.03)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"R": 0.0},
        {"R": -0.2},
        {"h": 0.0},
        {"h": -1e-2},
        {"h": float("nan")},
        {"h": 0.3},  # h >= R
        {"degree": 3},
        {"degree": 0},
        {"degree": 2.0},
        {"degree": True},
        {"E": 0.0},
        {"nu": 0.5},
        {"body_force": 0.0},
        {"gamma0": 0.0},
        {"theta": 2.0},
        {"load_steps": 0},
        {"fit_fraction": 0.0},
        {"dim": 1},
        {"refine": (0.1, 0.05)},  # h_min > h
    ],
)
def test_bad_input(kwargs):
    args = {"h": H_COARSE} | kwargs
    with pytest.raises(ValueError):
        solve_hertz(MPI.COMM_WORLD, **args)


def test_contact_radius_of_hertz_profile_on_triangles():
    """3D moment measure: exact moments of uniform pressures on triangles (tilted, off the
    axis), and a = sqrt(5/2 m2/m0) recovers the a of a Hertz profile on a quarter of the zone."""
    # one triangle, force 3, axis z through (1, 0, 0): over the projection (0,0), (1,0), (0,1) of
    # the tilted triangle r^2 = (x-1)^2 + y^2 averages 1/3
    tri = np.array([[[1.0, 0.0, 0.0], [2.0, 0.0, 5.0], [1.0, 1.0, 7.0]]])
    assert triangle_pressure_moments(tri, [3.0], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]) == pytest.approx((3.0, 1.0))
    # the quarter zone x, y >= 0 of p0 sqrt(1 - r^2/a^2) on a polar grid of small triangles
    a, n = 0.04, 400
    r, t = np.meshgrid(np.linspace(0, 1.1 * a, n + 1), np.linspace(0, np.pi / 2, n + 1), indexing="ij")
    x = np.stack([r * np.cos(t), r * np.sin(t), np.zeros_like(r)], axis=-1)
    quads = [x[:-1, :-1], x[1:, :-1], x[1:, 1:], x[:-1, 1:]]
    tris = np.concatenate([np.stack(quads[:3], axis=2), np.stack([quads[0], quads[2], quads[3]], axis=2)])
    tris = tris.reshape(-1, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    rc = np.linalg.norm(tris.mean(axis=1), axis=1)
    force = 3e6 * np.sqrt(np.clip(1 - (rc / a) ** 2, 0, None)) * area
    assert contact_radius_moments(*triangle_pressure_moments(tris, force, [0, 0, 0], [0, 0, 1])) == \
        pytest.approx(a, rel=1e-3)
    # the same forces at the barycentres: smaller m2, by the triangles' own second moments
    centres = tris.mean(axis=1)
    m0, m2 = point_force_moments(centres, force, [0, 0, 0], [0, 0, 1])
    e = tris - centres[:, None, :]
    assert m2 == pytest.approx(triangle_pressure_moments(tris, force, [0, 0, 0], [0, 0, 1])[1]
                               - force @ np.sum(e**2, axis=(1, 2)) / 12, rel=1e-12)
    assert contact_radius_moments(m0, m2) == pytest.approx(a, rel=1e-3)
    # off the axis: the force 2 at (4, 3, 9) about the axis z through (1, -1, 0), r^2 = 9 + 16
    assert point_force_moments([[4.0, 3.0, 9.0]], [2.0], [1.0, -1.0, 0.0], [0.0, 0.0, 3.0]) == (2.0, 50.0)
    with pytest.raises(ValueError, match="shape"):
        point_force_moments([[0.0, 0.0]], [1.0], [0, 0, 0], [0, 0, 1])
    with pytest.raises(ValueError, match="no contact"):
        contact_radius_moments(0.0, 1.0)
    hz = hertz_analytic_3d(0.2, 25e6, 0.25, 3e5)  # P = f 4/3 pi R^3, a^3 = 3 P R / (4 E*)
    assert hz.a**3 == pytest.approx(3 * 3e5 * 4 / 3 * np.pi * 0.2**4 / (4 * 25e6 / (1 - 0.25**2)))
    assert hz.approach == pytest.approx(hz.a**2 / 0.2) and hz.p0 == pytest.approx(1.5 * hz.load / (np.pi * hz.a**2))


@pytest.mark.mpi
def test_quarter_ball_equilibrium_and_contact_radius():
    """3D (the quarter ball, symmetry conditions): the Nitsche multiplier balances the body force
    on the mesh exactly (v = e_z is admissible: the conditions hold u_x, u_y only), and the
    contact radius is near Hertz's on a coarse mesh (0.0381 m at h = 0.04, h_c = 0.01)."""
    res = solve_hertz(MPI.COMM_WORLD, 0.06, R=0.2, body_force=3e5, dim=3, refine=(0.015, 0.05))
    assert res.dim == 3 and res.residual < 1e-8
    assert res.contact_force == pytest.approx(res.applied_load, rel=1e-8)
    assert res.applied_load == pytest.approx(3e5 * np.pi * 0.2**3 / 3, rel=0.08)  # quarter ball, inscribed
    assert res.contact_radius == pytest.approx(res.analytic.a, rel=0.05)
    assert -res.top_vertical_displacement == pytest.approx(0.0068, rel=0.05)
    assert np.isnan(res.contact_half_width_moment) and res.contact_x.size == 0  # 2D measures only
