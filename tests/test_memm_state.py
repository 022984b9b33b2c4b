"""memm_state.py: the sums of a MEMM step's state against the energies of the discretisation,
the update of the energy rows by the velocity against a true product, and the momenta."""

import dolfinx.mesh
import numpy as np
import pytest
from helpers import cell_vector
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import InputError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm_state import (
    EXTERNAL,
    KINETIC,
    LIFT_J,
    LIFT_S,
    MOMENTA,
    MOMENTUM,
    PSEUDO,
    ROWS_J,
    ROWS_S,
    StepState,
)

MATERIAL = ElasticMaterial(E=5.0, nu=0.3, rho=2.0)
DT = 0.01


def discretisation(clamped):
    """The unit square, clamped on its left side with u = (0.01, -0.02) (a lift), or free, under
    a body force."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    dirichlet = [DirichletBC(left, [0.01, -0.02])] if clamped else []
    return DEMDiscretisation(mesh, MATERIAL, "A", dirichlet, body_force=[0.3, -1.0])


def start(dem):
    """A state with smooth u, v^{n-1/2} and v^{n+1/2}, restarted at t = 0 and reduced."""
    state = StepState(dem, DT)
    cell_vector(dem, lambda x: 0.01 * np.stack([np.sin(x[:, 0] + x[:, 1]), x[:, 0] * x[:, 1]], axis=1)).copy(state.u)
    cell_vector(dem, lambda x: np.stack([x[:, 1], 1.0 + 0 * x[:, 0]], axis=1)).copy(state.v_prev)
    cell_vector(dem, lambda x: np.stack([x[:, 1] + 0.1, 0.5 - x[:, 0]], axis=1)).copy(state.v_next)
    state.restart(0.0)
    state.reduce(0.0)
    return state


@pytest.mark.mpi
@pytest.mark.parametrize("clamped", [True, False])
def test_the_reduced_sums_are_the_energies_and_the_momentum(clamped):
    comm = MPI.COMM_WORLD
    dem = discretisation(clamped)
    state = start(dem)
    s = state.sums
    e = dem.energies(state.u, 0.0)
    assert 0.5 * (DT**2 * s[ROWS_S] + s[LIFT_S]) == pytest.approx(e["elastic"], rel=1e-12)
    assert 0.5 * (DT**2 * s[ROWS_J] + s[LIFT_J]) == pytest.approx(e["stabilisation"], rel=1e-12)
    assert e["elastic"] > 1e-6 and e["stabilisation"] > 1e-9
    assert -s[EXTERNAL] == pytest.approx(e["external"], rel=1e-12) and abs(e["external"]) > 1e-5
    M = dem.mass.array_r
    vp, vn = state.v_prev.array_r, state.v_next.array_r
    assert s[KINETIC] == pytest.approx(comm.allreduce(0.125 * M @ (vp + vn) ** 2, op=MPI.SUM), rel=1e-13)
    assert s[PSEUDO] == pytest.approx(comm.allreduce(0.5 * M @ (vp * vn), op=MPI.SUM), rel=1e-13)
    # by hand: rho |Omega| times the mean of vbar = (y + 0.05, 0.75 - x / 2) (affine: its values
    # at the barycentres have the exact mean), i.e. (0.55, 0.5)
    assert np.allclose(s[MOMENTUM:MOMENTUM + 2], [2.0 * 0.55, 2.0 * 0.5], rtol=1e-13)
    if not clamped:  # one free body: its momentum at v^{n+1/2} = (y + 0.1, 0.5 - x), mean (0.6, 0)
        assert np.allclose(s[MOMENTA:MOMENTA + 2], [2.0 * 0.6, 0.0], rtol=0, atol=1e-13)


@pytest.mark.mpi
@pytest.mark.parametrize("clamped", [True, False])
def test_rows_advanced_by_the_velocity_are_the_rows_of_the_moved_state(clamped):
    """y^n + Q (v^{n+1/2} - its free body's mean) = Q rel(u + dt v^{n+1/2}) / dt: the update of
    the rows (``advance_rows``) against a true product (``restart``)."""
    dem = discretisation(clamped)
    state = start(dem)
    state.advance_rows(refresh=False)
    moved = start(dem)
    moved.u.axpy(DT, moved.v_next)
    moved.restart(0.0)
    scale = np.abs(moved.y).max()
    assert MPI.COMM_WORLD.allreduce(scale, op=MPI.MAX) > 0.1
    assert np.abs(state.y - moved.y).max(initial=0.0) < 1e-12 * scale


def test_a_recurrence_of_other_rows_is_refused():
    state = start(discretisation(True))
    saved = state.recurrence()
    with pytest.raises(InputError, match="the stored recurrence belongs to other energy rows"):
        state.restore_recurrence(0.0, saved["y"][:-1], saved["z"], saved["means"])
    state.restore_recurrence(0.0, 2.0 * saved["y"], saved["z"], saved["means"])  # not the rows of u: kept
    assert np.array_equal(state.y, 2.0 * saved["y"]) and np.abs(saved["y"]).max() > 0.1
