"""run_statistics.py: the running figures of a run for its summary: the energy drift, and with
contact between bodies the first contact time, the penetration limit and the momentum change."""

import math
import warnings

import numpy as np
import pytest
from helpers import cell_vector
from mpi4py import MPI

from dolfinx_dem import meshes, scenes, simulation
from dolfinx_dem.contact import PairContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import AccuracyWarning, UnresolvedContactError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.run_statistics import MAX_CROSSING_ANGLE, MAX_PENETRATION, PairContactStatistics, Statistics


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
        stats.record(t - dt, stepper, (0.0, 0.0, 0.0), np.zeros(2))  # apart: remembers the state
        assert stats.first_contact is None
        stepper.u.array.reshape(-1, 2)[:, 0] = np.where(left, s, -s)
        stats.record(t, stepper, (0.0, 0.0, 0.0), np.array([0.5, -2.0]))
        return stats

    slow, fast = (statistics(s).first_contact - (1.0 - dt) for s in (0.016, 0.02))
    assert 0.5 * dt < fast < slow < dt and 0.016 * slow == pytest.approx(0.02 * fast, rel=1e-9)
    assert statistics(0.005).first_contact is None  # still apart
    stats = statistics(0.02)
    assert stats.free and stats.p_scale == pytest.approx(0.3 * mass, rel=1e-12)
    assert stats.momentum_change == 2.0
    stats.record(1.0 + dt, stepper, (0.004, 0.4, 10.0), np.array([0.0, 1.0]))
    assert stats.penetration == 0.004 and stats.penetration_ratio == 0.4 and stats.momentum_change == 2.0
    state = stats.state()
    with pytest.raises(UnresolvedContactError, match=r"interpenetrate by 0.6 of a candidate facet's diameter "
                                                     r"\(deepest: 0.006 m\)"):
        stats.record(1.0 + 2 * dt, stepper, (0.006, 0.6, 10.0), np.zeros(2))
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
    stats.record(0.0, stepper, (0.0, 0.0, 0.0), np.zeros(2))
    kept = stats.previous
    for k, s in enumerate((0.001, 0.002, 0.003)):  # still apart
        stepper.u.array.reshape(-1, 2)[:, 0] = np.where(left, s, -s)
        stats.record((k + 1) * stepper.dt, stepper, (0.0, 0.0, 0.0), np.zeros(2))
        assert stats.first_contact is None and stats.previous is kept
        assert kept is not stepper.u and np.array_equal(kept.array_r, stepper.u.array_r)


@pytest.mark.mpi
def test_touching_facets_crossing_beyond_45_degrees_warn_once():
    """The touching pairs' largest crossing angle (``PairOutputs.penetration``'s third figure) is
    the largest angle between the planes of a touching pair's facets, -n_i . n_j = cos theta,
    over every process: here against the pairs' states and the facets' normals, at the discs
    pushed into each other by 2 x 0.02 m. The statistics keep its largest value for the summary
    (and a checkpoint) and warn on rank 0 once, when it first exceeds MAX_CROSSING_ANGLE (45
    degrees: the gap then varies across a facet by more than its size)."""
    problem, stepper = two_discs()
    dem, c = problem.dem, problem.find(PairContact)
    left = dem.geometry.cell_centres[: dem.n_owned, 0] < 0.25
    stepper.u.array.reshape(-1, 2)[:, 0] = np.where(left, 0.02, -0.02)
    up = c.patch_values(stepper.u)
    g, w = c.outputs.pair_states(up)
    touching = (g < 0) & (w > 0)
    n, L = c.facets_all.normal, c.listed
    cos = -np.einsum("pi,pi->p", n[L.i[touching]], n[L.j[touching]])
    expected = np.degrees(np.arccos(dem.comm.allreduce(float(cos.min(initial=1.0)), op=MPI.MIN)))
    assert dem.comm.allreduce(int(touching.sum()), op=MPI.SUM) > 2
    crossing = c.outputs.penetration(up)[2]
    assert crossing == pytest.approx(expected, abs=1e-9) and 5.0 < crossing < 45.0
    assert MAX_CROSSING_ANGLE == 45.0

    stats = PairContactStatistics(problem, stepper, np.zeros(2), 0.5)
    stats.first_contact = 0.0  # the first contact is not what this test is about
    with warnings.catch_warnings():
        warnings.simplefilter("error", AccuracyWarning)
        stats.record(0.1, stepper, (0.001, 0.1, crossing), np.zeros(2))
        stats.record(0.2, stepper, (0.001, 0.1, 45.0), np.zeros(2))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        stats.record(0.3, stepper, (0.001, 0.1, 60.0), np.zeros(2))
        stats.record(0.4, stepper, (0.001, 0.1, 70.0), np.zeros(2))
        stats.record(0.5, stepper, (0.001, 0.1, 50.0), np.zeros(2))
    warned = [str(x.message) for x in caught if issubclass(x.category, AccuracyWarning)]
    assert len(warned) == (dem.comm.rank == 0)
    assert all(m.startswith("at t = 0.3 touching facets of two bodies cross at 60 degrees (more than 45)")
               for m in warned)
    assert stats.crossing_angle == 70.0 and stats.summary(1.0)["max_contact_crossing_angle"] == 70.0
    again = PairContactStatistics(problem, stepper, np.zeros(2), 0.5)
    again.restore(stats.state(), stepper)
    assert again.crossing_angle == 70.0


@pytest.mark.parametrize("speed, warns", [(0.3, True), (0.03, False)])
def test_two_disks_warn_at_the_papers_speed_not_at_a_small_strain_one(tmp_path, speed, warns):
    """Paper §5.3's disks (h = 0.02 m) meet at v / c = 0.3 each: the contact patch flattens the
    disks so far that touching facets cross at 79 degrees (89 on the shipped mesh), and the
    penetration over the facet size stays about 0.06-0.08 under refinement (h = 0.02 ... 0.0025 m,
    docs/validation/contact3d.md); at a tenth of the speed they cross at 22 degrees and the run
    does not warn. Before, neither said anything."""
    velocity = [f"where(x < 0.25, {speed}, {-speed})", "0"]
    scene = scenes.load("two-disks", {"mesh.h": 0.02, "initial.velocity": velocity, "output.every": 100000,
                                      "time.end": 1.0 if warns else 1.6})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        summary = simulation.run(scene, tmp_path, MPI.COMM_SELF, quiet=True)
    warned = [str(x.message) for x in caught if issubclass(x.category, AccuracyWarning)]
    assert summary["status"] == "completed" and summary["first_contact_time"] is not None
    angle = summary["max_contact_crossing_angle"]
    if warns:
        assert 70.0 < angle < 90.0 and len(warned) == 1 and "touching facets of two bodies cross at" in warned[0]
    else:
        assert 15.0 < angle < 30.0 and warned == []
