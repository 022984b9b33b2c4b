"""The DOLFINx FEM elastodynamics reference: energy conservation, eigenfrequencies, convergence."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from dolfinx_dem import _compat
from dolfinx_dem.fem.elastodynamics import FEMElastodynamics, first_eigenfrequency


def _facets_at_x(mesh, *x0):
    return _compat.locate_boundary_facets(
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
