"""run_statistics.py: the running figures of a run for its summary: the energy drift, and with
contact between bodies the first contact time, the penetration limit and the momentum change."""

import math

import numpy as np
import pytest
from helpers import cell_vector
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.contact import PairContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import UnresolvedContactError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.run_statistics import MAX_PENETRATION, PairContactStatistics, Statistics


def test_the_relative_drift_is_the_drift_over_the_largest_energy():
    assert Statistics(1.0, drift=2e-12, scale=4.0).relative_drift == 5e-13
    assert Statistics(0.0, drift=1e-20).relative_drift == 0.0  # nothing moves: no scale
    assert Statistics(0.0).min_gap == math.inf and MAX_PENETRATION == 0.5


def two_discs(comm=MPI.COMM_WORLD):
    """Two discs of radius 0.1, 0.02 apart along x, the facing halves candidates, approaching at
    0.3 each: (problem, stepper)."""
    mesh, _, _ = meshes.create_discs(comm, [((0.14, 2.27), 0.1), ((0.36, 2.27), 0.1)], 0.05)
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=100.0, nu=0.2, rho=100.0), "B")
    facets = meshes.locate_boundary_facets(mesh, lambda x: (x[0] >= 0.14) & (x[0] <= 0.36))
    problem = DEMProblem(dem, [PairContact(dem, facets)])
    stepper = MEMM(problem, 1e-3)
    stepper.initialise(dem.create_vector(), cell_vector(
        dem, lambda x: np.stack([np.where(x[:, 0] < 0.25, 0.3, -0.3), np.zeros(len(x))], axis=1)))
    return problem, stepper


@pytest.mark.mpi
def test_first_contact_penetration_limit_and_momentum_change():
    """The discs moved by +-s in one 'step' from rest: the first contact is the step's start plus
    the time their gap took to close, affine along the step, so inversely proportional to s (s
    small enough for the pair list); a penetration above max_penetration facet sizes stops the
    run; the momentum change is the largest change of a component from the initial momentum
    (0: the discs' momenta cancel)."""
    problem, stepper = two_discs()
    dem, dt = problem.dem, stepper.dt
    left = dem.geometry.cell_centres[: dem.n_owned, 0] < 0.25
    mass = dem.comm.allreduce(float(dem.mass.array_r.sum()) / 2, op=MPI.SUM)

    def statistics(s, t=1.0):
        stepper.u.set(0.0)
        stats = PairContactStatistics(problem, stepper, np.zeros(2), 0.5)
        stats.record(t - dt, stepper, (0.0, 0.0), np.zeros(2))  # apart: remembers the state
        assert stats.first_contact is None
        stepper.u.array.reshape(-1, 2)[:, 0] = np.where(left, s, -s)
        stats.record(t, stepper, (0.0, 0.0), np.array([0.5, -2.0]))
        return stats

    slow, fast = (statistics(s).first_contact - (1.0 - dt) for s in (0.016, 0.02))
    assert 0.5 * dt < fast < slow < dt and 0.016 * slow == pytest.approx(0.02 * fast, rel=1e-9)
    assert statistics(0.005).first_contact is None  # still apart
    stats = statistics(0.02)
    assert stats.free and stats.p_scale == pytest.approx(0.3 * mass, rel=1e-12)
    assert stats.momentum_change == 2.0
    stats.record(1.0 + dt, stepper, (0.004, 0.4), np.array([0.0, 1.0]))
    assert stats.penetration == 0.004 and stats.penetration_ratio == 0.4 and stats.momentum_change == 2.0
    state = stats.state()
    with pytest.raises(UnresolvedContactError, match=r"interpenetrate by 0.6 of a candidate facet's diameter "
                                                     r"\(deepest: 0.006 m\)"):
        stats.record(1.0 + 2 * dt, stepper, (0.006, 0.6), np.zeros(2))
    again = PairContactStatistics(problem, stepper, np.zeros(2), 0.5)
    again.restore(state, stepper)
    assert again.state() == state and again.previous is None  # contact already found


@pytest.mark.mpi
def test_the_state_before_the_first_contact_is_one_vector_written_in_place():
    """Until the first contact the statistics keep the previous step's displacement in one vector,
    overwritten at each step: petsc4py frees a dropped vector not on COMM_SELF only at
    PETSc.garbage_cleanup, so a new copy per step kept a vector of the mesh's size per step (the
    pair contact's memory grew with the cells times the steps before the first contact)."""
    problem, stepper = two_discs()
    dem = problem.dem
    left = dem.geometry.cell_centres[: dem.n_owned, 0] < 0.25
    stats = PairContactStatistics(problem, stepper, np.zeros(2), 0.5)
    stepper.u.set(0.0)
    stats.record(0.0, stepper, (0.0, 0.0), np.zeros(2))
    kept = stats.previous
    for k, s in enumerate((0.001, 0.002, 0.003)):  # still apart
        stepper.u.array.reshape(-1, 2)[:, 0] = np.where(left, s, -s)
        stats.record((k + 1) * stepper.dt, stepper, (0.0, 0.0), np.zeros(2))
        assert stats.first_contact is None and stats.previous is kept
        assert kept is not stepper.u and np.array_equal(kept.array_r, stepper.u.array_r)
