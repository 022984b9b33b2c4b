"""The pair list of the contact between bodies across processes: list rounds that rebuild only the
lists near moving facets, facets exchanged between processes as discs travel, what each process
knows of the others' facets, and the bisection of the list round's summaries; each against one
process's run where it applies."""

import numpy as np
import pytest
from helpers import cell_vector
from mpi4py import MPI
from pair_scenes import SOFT, approach

from dolfinx_dem import meshes, model
from dolfinx_dem.contact import PairContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem


@pytest.mark.mpi
def test_a_list_round_rebuilds_only_the_lists_near_moving_facets():
    """Two discs collide while two more rest 1.2 m below them (farther than any pair radius),
    every boundary a candidate: the rounds of the Verlet lists that the moving facets start
    rebuild the lists of the processes that know a moving facet only; the others keep theirs
    (on 2 and 3 processes the deterministic partition leaves one with resting discs alone). The
    motion equals that of one process to rounding: a kept list is complete."""

    def run(comm):
        centres = [(0.14, 2.27), (0.36, 2.27), (0.14, 1.07), (0.36, 1.07)]
        mesh = meshes.create_discs(comm, [(c, 0.1) for c in centres], 0.04)[0]
        dem = DEMDiscretisation(mesh, SOFT, "B")
        problem = DEMProblem(dem, [PairContact(dem, meshes.exterior_facets(mesh))])
        stepper = MEMM(problem, 0.2 * dem.stable_time_step())
        velocity = lambda x: approach(x) * (x[:, 1] > 1.67)[:, None]  # noqa: E731
        stepper.initialise(dem.create_vector(), cell_vector(dem, velocity))
        for n in range(150):
            stepper.step()
            if n % 30 == 0:
                model.contact_values(problem, stepper.u)  # outputs after rounds that kept some lists
        c = problem.find(PairContact)
        moving = c.facets_all.centre[:, 1] > 1.67
        assert moving.any() or c.rebuilds == 1  # a process that knows no moving facet never rebuilt
        assert not moving.any() or c.rebuilds > 3
        # rounds between exchanges rebuild the list from the facets known
        assert (
            c.exchanges == 0 if comm.size == 1 else 1 <= c.exchanges and (not moving.any() or c.rebuilds > c.exchanges)
        )
        x = dem.geometry.cell_centres[: dem.n_owned]
        return dem, stepper, c, x

    dem, stepper, c, x = run(MPI.COMM_WORLD)
    comm = dem.comm
    if comm.size > 1:
        assert comm.allreduce(c.rebuilds == 1, op=MPI.LOR)  # some process kept its list throughout
    serial_dem, serial, serial_c, serial_x = run(MPI.COMM_SELF)
    assert serial_c.rebuilds > 3
    # the same cells by their barycentres: the displacements agree to rounding
    import scipy.spatial

    distance, found = scipy.spatial.cKDTree(serial_x).query(x)
    assert distance.max(initial=0.0) < 1e-12
    u_serial = serial.u.array_r.reshape(-1, 2)
    scale = np.abs(u_serial).max()
    assert scale > 1e-3  # the moving discs moved
    assert np.abs(stepper.u.array_r.reshape(-1, 2) - u_serial[found]).max(initial=0.0) < 1e-12 * scale


@pytest.mark.mpi
def test_discs_that_travel_far_between_exchanges_move_as_on_one_process():
    """Three discs crossing the partition at 0.4 m/s, the outer ones towards the middle
    one, every boundary a candidate: their facets drift farther than r - s/2 (r the largest
    pair radius, s the largest skin), so the processes exchange facets again in mid-run (and
    rebuild their lists from the facets they know in between); the displacements equal those
    of one process to rounding through the impacts, so no exchange missed a facet that came
    near. (Without ``_drifted`` the first exchange would stand and the impacts would be
    missed.)"""
    centres = [(0.14, 0.0), (0.6, 0.03), (1.06, 0.0)]  # gaps of 0.26 m, wider than the exchange radius

    def run(comm):
        mesh = meshes.create_discs(comm, [(c, 0.1) for c in centres], 0.04)[0]
        dem = DEMDiscretisation(mesh, SOFT, "B")
        problem = DEMProblem(dem, [PairContact(dem, meshes.exterior_facets(mesh))])
        stepper = MEMM(problem, 0.2 * dem.stable_time_step())
        stepper.initialise(
            dem.create_vector(),
            cell_vector(
                dem,
                lambda x: np.stack(
                    [np.where(x[:, 0] < 0.3, 0.4, np.where(x[:, 0] > 0.9, -0.4, 0.0)), np.zeros(len(x))], axis=1
                ),
            ),
        )
        for _ in range(320):  # 0.89 s: contact from 0.65 s
            stepper.step()
        return dem, stepper, problem.find(PairContact)

    dem, stepper, c = run(MPI.COMM_WORLD)
    comm = dem.comm
    serial_dem, serial, serial_c = run(MPI.COMM_SELF)
    assert serial_c.exchanges == 0
    if comm.size > 1:
        assert c.exchanges >= 3 and comm.allreduce(c.rebuilds, op=MPI.MAX) > c.exchanges
    assert c.pair_list.exchange_radius < 0.25
    touched = comm.allreduce(c.outputs.touching(c.patch_values(stepper.u)), op=MPI.LOR)
    import scipy.spatial

    x = dem.geometry.cell_centres[: dem.n_owned]
    distance, found = scipy.spatial.cKDTree(serial_dem.geometry.cell_centres[: serial_dem.n_owned]).query(x)
    assert distance.max(initial=0.0) < 1e-12
    u_serial = serial.u.array_r.reshape(-1, 2)
    scale = np.abs(u_serial).max()
    assert scale > 0.15 and serial_c.rebuilds > 10  # the discs travelled and met
    assert np.abs(stepper.u.array_r.reshape(-1, 2) - u_serial[found]).max(initial=0.0) < 1e-12 * scale
    assert touched


@pytest.mark.mpi
def test_a_process_knows_only_the_facets_of_other_processes_near_its_own():
    """Eight discs on a ring, 0.56 m apart (far beyond the exchange radius): an exchange keeps
    the facets received from other processes that lie within the exchange radius of a local
    facet, not all those in the boxes of its local facets (on 2 and 3 processes the box of all
    spans a half or a third of the ring and holds discs of other processes). Bodies at rest:
    each facet is at its reference place."""
    angles = np.arange(8) * np.pi / 4
    discs = [((np.cos(a), np.sin(a)), 0.1) for a in angles]
    mesh = meshes.create_discs(MPI.COMM_WORLD, discs, 0.03)[0]
    dem = DEMDiscretisation(mesh, SOFT, "B")
    problem = DEMProblem(dem, [PairContact(dem, meshes.exterior_facets(mesh))])
    c = problem.find(PairContact)
    F, nl = c.facets_all, len(c.facets)
    import scipy.spatial

    distance = scipy.spatial.cKDTree(F.centre[:nl]).query(F.centre[nl:])[0] if nl else np.full(len(F) - nl, np.inf)
    assert c.pair_list.exchange_radius < 0.5
    far = MPI.COMM_WORLD.allreduce(int((distance > c.pair_list.exchange_radius).sum()), op=MPI.SUM)  # on every process
    assert far == 0
    assert c.num_pairs == 0  # no facing facets of two discs are near each other


def test_bisection_groups_nearby_facets_for_the_list_round_summaries():
    """``_bisection`` (the boxes a list round gathers from each process): a permutation into
    at most k groups of equal size (to one point), each group's box much smaller than the
    whole; ``_box`` bounds its points column by column, and is empty without points."""
    from dolfinx_dem.contact.pair_list import _bisection, _box

    angle = np.linspace(0.0, 2.0 * np.pi, 1001)[:-1]
    x = np.column_stack([np.cos(angle), np.sin(angle)]) + 0.01 * np.random.default_rng(3).random((1000, 2))
    perm, starts = _bisection(x, 16)
    assert np.array_equal(np.sort(perm), np.arange(1000)) and len(starts) == 16 and starts[0] == 0
    sizes = np.diff(np.append(starts, 1000))
    assert sizes.min() >= 62 and sizes.max() <= 63
    for group in np.split(perm, starts[1:]):
        box = _box(x[group])
        assert np.array_equal(box, np.concatenate([x[group].min(axis=0), x[group].max(axis=0)]))
        assert np.linalg.norm(box[2:] - box[:2]) < 0.5  # an arc of about 1/16 of the circle (chord 0.39)
    assert np.array_equal(_box(np.zeros((0, 3))), [np.inf] * 3 + [-np.inf] * 3)
    assert len(_bisection(np.zeros((0, 2)), 16)[0]) == 0 and len(_bisection(x[:3], 16)[1]) == 3
