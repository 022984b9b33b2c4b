"""The DOLFINx FEM elastodynamics references (implicit Newmark, explicit central differences with
lumped mass): energy conservation, eigenfrequencies, convergence, stability limit."""

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.fem.elastodynamics import FEMCentralDifference, FEMElastodynamics, first_eigenfrequency


def _facets_at_x(mesh, *x0):
    return meshes.locate_boundary_facets(
        mesh, lambda x: np.logical_or.reduce([np.isclose(x[0], a) for a in x0])
    )


@pytest.mark.mpi
def test_newmark_conserves_energy_cantilever():
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 0.1]], [20, 2])
    solver = FEMElastodynamics(
        mesh, 2, E=1.0, nu=0.3, rho=1.0, dt=0.01, clamped_facets=_facets_at_x(mesh, 0.0),
        initial_velocity=lambda x: np.stack([np.zeros_like(x[0]), x[0] ** 2]),
    )
    e0 = sum(solver.energies())
    assert e0 > 0.0
    energies = []
    for _ in range(200):
        solver.step()
        energies.append(solver.energies())
    energies = np.array(energies)
    drift = np.max(np.abs(energies.sum(axis=1) - e0)) / e0
    assert drift < 1e-10
    # energy is really exchanged between kinetic and elastic
    assert energies[:, 1].max() > 0.01 * e0
    assert solver.t == pytest.approx(2.0)


@pytest.mark.slow
@pytest.mark.mpi
def test_eigenfrequency_clamped_free_bar():
    mesh = dolfinx.mesh.create_interval(MPI.COMM_WORLD, 20, [0.0, 1.0])
    omega = first_eigenfrequency(mesh, 2, 1.0, 0.0, 1.0, _facets_at_x(mesh, 0.0), n=3)
    exact = np.pi / 2 * np.array([1.0, 3.0, 5.0])
    assert abs(omega[0] - exact[0]) < 1e-4
    # no spurious eigenvalue from the clamped rows among the next ones either
    assert np.allclose(omega, exact, rtol=1e-3)


@pytest.mark.mpi
def test_eigenfrequency_cantilever_beam_euler_bernoulli():
    L, h, E, rho = 1.0, 0.05, 1.0, 1.0
    mesh = dolfinx.mesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [L, h]], [80, 4])
    omega = first_eigenfrequency(
        mesh, 2, E, 0.0, rho, _facets_at_x(mesh, 0.0), plane_stress=True
    )
    I, A = h**3 / 12.0, h
    omega_eb = 1.8751**2 * np.sqrt(E * I / (rho * A * L**4))
    assert abs(omega[0] / omega_eb - 1.0) < 0.03


@pytest.mark.slow
@pytest.mark.mpi
def test_standing_wave_second_order_in_time():
    L, E, rho, T = 1.0, 1.0, 1.0, 0.5
    c = np.sqrt(E / rho)
    mesh = dolfinx.mesh.create_interval(MPI.COMM_WORLD, 40, [0.0, L])
    facets = _facets_at_x(mesh, 0.0, L)
    exact = np.cos(np.pi * c * T / L)
    errors = []
    for nsteps in (10, 20, 40):
        solver = FEMElastodynamics(
            mesh, 2, E, 0.0, rho, T / nsteps, facets,
            initial_displacement=lambda x: np.sin(np.pi * x[:1] / L),
        )
        for _ in range(nsteps):
            solver.step()
        errors.append(abs(solver.point_values([[L / 2]])[0, 0] - exact))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 1.7) & (orders < 2.3)), (errors, orders)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(nu=0.5), "nu"),
        (dict(nu=0.7), "nu"),
        (dict(E=0.0), "E"),
        (dict(E=-1.0), "E"),
        (dict(rho=0.0), "rho"),
        (dict(dt=0.0), "dt"),
        (dict(dt=-0.1), "dt"),
        (dict(degree=3), "degree"),
        (dict(degree=0), "degree"),
    ],
)
def test_bad_input_raises(kwargs, name):
    mesh = dolfinx.mesh.create_interval(MPI.COMM_WORLD, 4, [0.0, 1.0])
    args = dict(degree=1, E=1.0, nu=0.3, rho=1.0, dt=0.1, clamped_facets=_facets_at_x(mesh, 0.0))
    args.update(kwargs)
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        FEMElastodynamics(mesh, **args)
    if "dt" not in kwargs:
        args.pop("dt")
        with pytest.raises(ValueError, match=rf"\b{name}\b"):
            first_eigenfrequency(mesh, **args)


# --- explicit central differences, P1 with lumped mass ----------------------------------------


def _strip_wave(n, **kwargs):
    """The x-standing wave in the clamped strip [0, 1] x [0, 0.5], nu = 0, c = 1: with lambda = 0
    ``u = (A sin(pi x) cos(pi t), 0)`` is exact (top and bottom are traction-free)."""
    mesh, _, tags = meshes.create_rectangle(MPI.COMM_WORLD, [0.0, 0.0], [1.0, 0.5], [n, n // 2],
                                            "crossed")
    clamped = np.concatenate([tags.find(meshes.XMIN), tags.find(meshes.XMAX)])
    return FEMCentralDifference(
        mesh, 1.0, 0.0, 1.0, clamped,
        initial_displacement=lambda x: np.stack([0.01 * np.sin(np.pi * x[0]), np.zeros_like(x[0])]),
        **kwargs,
    )


def _l2_error_strip_wave(solver):
    x = ufl.SpatialCoordinate(solver.mesh)
    exact = ufl.as_vector([0.01 * ufl.sin(np.pi * x[0]) * np.cos(np.pi * solver.t), 0.0])
    e = solver.u - exact
    form = dolfinx.fem.form(ufl.inner(e, e) * ufl.dx(metadata={"quadrature_degree": 6}))
    return np.sqrt(solver.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM))


@pytest.mark.mpi
def test_central_difference_second_order_strip_wave():
    errors, steps = [], []
    for n in (8, 16):
        solver = _strip_wave(n, cfl=0.5)
        n_steps = int(np.ceil(1.25 / solver.dt))
        for _ in range(n_steps):
            solver.step()
        errors.append(_l2_error_strip_wave(solver))
        steps.append(n_steps)
    ratio = errors[0] / errors[1]
    # measured: 4.01 (errors 2.02e-5, 5.03e-6 against ||u_0|| = 5e-3; 8 -> 16 -> 32: 4.01, 4.08);
    # at cfl 0.9 the lumped-mass and central-difference phase errors partly cancel (3.50, 4.06)
    assert 3.7 < ratio < 4.3, (errors, ratio)
    assert steps[1] in (2 * steps[0] - 1, 2 * steps[0], 2 * steps[0] + 1)


@pytest.mark.mpi
def test_central_difference_modified_energy_conserved():
    solver = _strip_wave(8, cfl=0.95)
    e0, mech0 = solver.modified_energy(), sum(solver.energies())
    modified, mechanical = [], []
    for _ in range(300):
        solver.step()
        modified.append(solver.modified_energy())
        mechanical.append(sum(solver.energies()))
    assert np.max(np.abs(np.array(modified) - e0)) / e0 < 1e-12
    # the energy itself oscillates by O(dt^2) about the modified energy, and stays bounded
    assert 1e-4 < np.max(np.abs(np.array(mechanical) - mech0)) / mech0 < 0.1


@pytest.mark.slow
def test_central_difference_stability_limit_1d_bar():
    """Clamped-clamped uniform P1 bar, lumped mass: lambda_max(m^-1 K) = 4 c^2/h^2 sin^2((n-1) pi/2n)."""
    n, L, E, rho = 10, 2.0, 4.0, 1.0
    mesh = dolfinx.mesh.create_interval(MPI.COMM_SELF, n, [0.0, L])
    facets = _facets_at_x(mesh, 0.0, L)
    h, c = L / n, np.sqrt(E / rho)
    exact = h / c / np.sin((n - 1) * np.pi / (2 * n))
    solver = FEMCentralDifference(mesh, E, 0.0, rho, facets, cfl=0.5)
    assert solver.dt_stable == pytest.approx(exact, rel=1e-7)
    assert solver.dt == pytest.approx(0.5 * exact, rel=1e-7)
    for kwargs in (dict(cfl=1.0), dict(dt=1.01 * exact)):
        with pytest.raises(ValueError, match="stability limit"):
            FEMCentralDifference(mesh, E, 0.0, rho, facets, **kwargs)
    with pytest.raises(ValueError, match="exactly one"):
        FEMCentralDifference(mesh, E, 0.0, rho, facets)
    with pytest.raises(ValueError, match="exactly one"):
        FEMCentralDifference(mesh, E, 0.0, rho, facets, dt=0.1, cfl=0.5)
    with pytest.raises(ValueError, match=r"\bcfl\b"):
        FEMCentralDifference(mesh, E, 0.0, rho, facets, cfl=-0.5)


def test_central_difference_blows_up_beyond_limit():
    """Just above the limit the highest mode grows (allow_unstable); just below it does not."""
    mesh = dolfinx.mesh.create_interval(MPI.COMM_SELF, 20, [0.0, 1.0])
    facets = _facets_at_x(mesh, 0.0, 1.0)
    growth = {}
    for cfl in (0.99, 1.05):
        solver = FEMCentralDifference(
            mesh, 1.0, 0.0, 1.0, facets, cfl=cfl, allow_unstable=True,
            initial_displacement=lambda x: np.sin(np.pi * x[:1]),
        )
        e0 = sum(solver.energies())
        for _ in range(400):
            solver.step()
        growth[cfl] = sum(solver.energies()) / e0
    assert growth[0.99] < 1.1, growth
    assert growth[1.05] > 1e6, growth
