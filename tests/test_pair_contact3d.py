"""Contact between bodies in 3D and in parallel: exact gradients, the compiled state and force
integral over flights with events, the screen, restored states and the patch gathering (the list
rounds and the exchanges between processes: test_pair_list_exchange.py)."""

import dataclasses

import numpy as np
import pytest
from helpers import cell_vector, gmsh_mesh
from mpi4py import MPI
from pair_scenes import SOFT, approach, two_discs

from dolfinx_dem import meshes
from dolfinx_dem.contact import PairContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem


def two_boxes(comm=MPI.COMM_WORLD, scheme="B", surface="facet"):
    """Two 0.2 m tetrahedral cubes 0.01 apart along x, the right one shifted by (0.07, 0.04) in
    (y, z): their facing sides (the contact boundary) do not match, pairs overlap partially.
    ``surface``: the pairs' kinematics (contact/surface.py)."""

    def build(gmsh):
        for k, corner in enumerate([(0.0, 0.0, 0.0), (0.21, 0.07, 0.04)]):
            box = gmsh.model.occ.addBox(*corner, 0.2, 0.2, 0.2)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(3, [box], k + 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.1)
        gmsh.model.mesh.generate(3)

    mesh = gmsh_mesh(comm, build, gdim=3)
    dem = DEMDiscretisation(mesh, SOFT, scheme)
    problem = DEMProblem(
        dem, [PairContact(dem, meshes.locate_boundary_facets(mesh, lambda x: (x[0] > 0.19) & (x[0] < 0.22)),
                          surface=surface)]
    )
    return problem


def oblique(x, speed=0.3):
    """The left cube moves right, the right one left, both also sideways (sliding)."""
    left = (x[:, 0] < 0.205)[:, None]
    return speed * np.where(left, [1.0, 0.3, -0.2], [-1.0, -0.2, 0.4])


@pytest.mark.parametrize("surface", ["facet", "vertex"])
@pytest.mark.parametrize("scheme", ["A", "B"])
def test_force_is_the_gradient_of_the_energy_in_contact_in_3d(scheme, surface):
    """Central differences of the potential against the force, tetrahedral cubes with
    triangular facets in partial overlap: the overlap areas, their gradients (the sliding
    force) and the scheme A directions in 3D, with either surface (the vertex surface's force
    goes through K^T)."""
    problem = two_boxes(scheme=scheme, surface=surface)
    dem = problem.dem
    c = problem.find(PairContact)
    rng = np.random.default_rng(5)
    u = cell_vector(dem, lambda x: oblique(x, 0.043) + 1e-3 * rng.standard_normal(x.shape))
    c.prepare(u)
    up = c.patch_values(u)
    gap, overlap = c.outputs.pair_states(up)
    on = (gap < 0) & (overlap > 0)
    areas = np.minimum(c.facets_all.length[c.listed.i], c.facets_all.length[c.listed.j])
    assert on.sum() >= 20 and (overlap[on] < 0.99 * areas[on]).sum() >= 10
    F, free = dem.create_vector(), dem.create_vector()
    problem.force(u, 0.0, F)
    dem.force(u, 0.0, free)
    h, errors = 1e-7, []
    patch = c.scatter.dofs
    for k in patch[rng.permutation(len(patch))[:60]]:
        up_, um_ = u.copy(), u.copy()
        up_.array[k] += h
        um_.array[k] -= h
        diff = (problem.energies(up_, 0.0)["potential"] - problem.energies(um_, 0.0)["potential"]) / (2 * h)
        errors.append(abs(diff + F.array[k]))
    assert max(errors) < 1e-6 * np.abs(F.array).max()  # measured 3.5e-10 (B), 4.9e-10 (A)
    assert np.abs(F.array - free.array).max() > 1e-2 * np.abs(F.array).max()


def _cubes_impact(comm, steps, surface="facet"):
    """Run the oblique impact of ``two_boxes`` for ``steps`` MEMM steps: (largest relative
    pseudo-energy drift, total momentum change, the left cube's momentum, the pair force,
    the largest number of force evaluations of a step)."""
    problem = two_boxes(comm, surface=surface)
    dem = problem.dem
    c = problem.find(PairContact)
    dt = 0.3 * dem.stable_time_step()
    stepper = MEMM(problem, dt)
    first = stepper.initialise(dem.create_vector(), cell_vector(dem, oblique))
    mass = dem.mass.array_r.reshape(-1, 3)
    left = dem.geometry.cell_centres[: dem.n_owned, 0] < 0.205

    def momenta():
        mv = mass * 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, 3)
        return comm.allreduce(mv.sum(axis=0), op=MPI.SUM), comm.allreduce(mv[left].sum(axis=0), op=MPI.SUM)

    p0 = momenta()[0]
    drift = 0.0
    for _ in range(steps):
        diag = stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy) / first.mechanical)
    p, p_left = momenta()
    force = comm.allreduce(c.outputs.pair_forces(c.patch_values(stepper.u)), op=MPI.SUM)[0]
    return drift, np.abs(p - p0).max(), p_left, force, comm.allreduce(stepper.max_step_evaluations, op=MPI.MAX)


def test_the_compiled_contact_state_is_its_definition_by_sparse_products():
    """``PairState``, the contact state in one compiled call (``dem_pair_end_state``), against its definition
    by numpy and scipy: its closed pairs hold every touching pair (g < 0, w > 0), and there g, w,
    dw/du_j (``gaps_and_overlaps``), c = w g^-, mu_p = z_p . (Q u + q + Z c) and the energy change
    sum (a delta + delta^2 / 2) of the own rows, elastic and stabilisation rows apart."""
    problem = two_boxes(MPI.COMM_SELF)
    dem = problem.dem
    c = problem.find(PairContact)
    u = cell_vector(dem, lambda x: oblique(x, 0.01))  # the cubes 0.01 m into each other
    up, _ = c.prepare(u)
    at, L = c.state(up).pairs, c.listed
    p, uc = at.closed, c.free_displacements(up)
    g, w, dw = c.gaps_and_overlaps(p, uc[L.i[p]], uc[L.j[p]])
    g_all, w_all = c.outputs.pair_states(up)
    touching = np.flatnonzero((g_all < 0) & (w_all > 0))
    assert len(touching) > 20 and np.isin(touching, p).all()
    assert np.array_equal(at.g, g)
    assert np.abs(at.w - w).max() <= 1e-14 * w.max() and np.abs(at.dw - dw).max() <= 1e-14 * np.abs(dw).max()
    assert np.array_equal(at.c, at.w * np.minimum(at.g, 0.0))
    full = np.zeros(len(L))
    full[p] = at.c
    a, delta = L.Q @ up + c.row_lift, L.Z @ full
    mu = (L.ZT @ (a + delta))[p]
    assert np.abs(at.mu - mu).max() <= 1e-12 * np.abs(mu).max()
    change, elastic = a * delta + 0.5 * delta**2, c._c_patch.arrays["elastic"].astype(bool)
    expected = np.array([change[elastic].sum(), change[~elastic].sum()])
    assert np.abs(np.array(at.energy) - expected).max() <= 1e-12 * np.abs(expected).max()
    assert expected[0] > 0 and expected[1] > 0


@pytest.mark.parametrize("surface", ["facet", "vertex"])
def test_the_force_integral_over_a_flight_with_events_is_exact(surface):
    """``dem_pair_force_integral`` over a flight of sliding cubes whose gaps close and whose
    overlaps change topology inside it: the integral over [0, dt] is the sum of those over
    [0, t1] and [t1, dt] to rounding (a piece missed or misplaced breaks this at the size of the
    quadrature error), and agrees with a composite 3-point Gauss rule of 200 pieces of the
    force correction (whose error comes from the kinks inside its pieces). The vertex surface
    reads a fixed linear map of u: its gaps stay affine in the flight's time, the rule exact."""
    problem = two_boxes(MPI.COMM_SELF, surface=surface)
    dem = problem.dem
    c = problem.find(PairContact)
    u, v = cell_vector(dem, lambda x: oblique(x, 0.01)), cell_vector(dem, oblique)
    dt, t1 = 0.02, 0.0073

    def at(tau):
        x = u.copy()
        x.axpy(tau, v)
        return x

    def integral(start, length):
        out = dem.create_vector()
        up, vp = c.prepare(at(start), v, length)
        return out, c.force_integral(up, vp, length, out)

    whole, evaluations = integral(0.0, dt)
    assert evaluations >= 9  # events: some component cut into three pieces at least
    first, second = integral(0.0, t1)[0], integral(t1, dt - t1)[0]
    scale = np.abs(whole.array).max()
    assert scale > 0 and np.abs(whole.array - first.array - second.array).max() < 1e-12 * scale  # measured 3.6e-15
    reference = dem.create_vector()
    x, weights = np.polynomial.legendre.leggauss(3)
    pieces = 200
    c.prepare(u, v, dt)
    for k in range(pieces):
        for xk, wk in zip(x, weights):
            tau = (k + 0.5 + 0.5 * xk) * dt / pieces
            c.add(c.force_correction(c.patch_values(at(tau))), reference, scale=0.5 * wk * dt / pieces)
    assert np.abs(whole.array - reference.array).max() < 1e-6 * scale  # measured 3.5e-8


def test_the_screen_keeps_every_pair_that_touches_during_a_flight_and_few_others():
    """``_free_flight``'s screen (``dem_pair_flight``: the gaps at the ends and the separating
    axes of the projected triangles along the flight) against the pairs touching (g < 0, w > 0)
    at 801 sampled times of a flight of sliding cubes: it holds all of them, and few pairs more
    (those touching between the samples or within the margin); the projections' bounding boxes,
    the screen before the separating axes, held 204 pairs for the 131 touching."""
    problem = two_boxes(MPI.COMM_SELF)
    dem = problem.dem
    c = problem.find(PairContact)
    u, v = cell_vector(dem, lambda x: oblique(x, 0.01)), cell_vector(dem, oblique)
    dt = 0.02
    up, vp = c.prepare(u, v, dt)
    uc = c.free_displacements(up)
    vc, _, screened = c.free_flight(uc, vp, dt)
    L, touched = c.listed, np.zeros(len(c.listed), dtype=bool)
    for tau in np.linspace(0.0, dt, 801):
        x = uc + tau * vc
        g, w, _ = c.gaps_and_overlaps(np.arange(len(L)), x[L.i], x[L.j])
        touched |= (g < 0) & (w > 0)
    assert touched.sum() > 20 and np.isin(np.flatnonzero(touched), screened).all()
    assert len(screened) <= 1.02 * touched.sum()  # measured: 131 screened, 131 touching


def test_the_state_at_a_steps_end_screens_the_flights_candidates_only_where_they_hold():
    """The contact state at the end of a flight (``PairState``) screens only the pairs that the
    flight's screen found near closing there (``PairState.candidates``): bit-identical to the state
    that screens every listed pair; at a displacement away from the flight's end it screens
    every pair again."""
    from dolfinx_dem.contact.events import PairState

    problem = two_boxes(MPI.COMM_SELF)

    dem = problem.dem
    c = problem.find(PairContact)
    u, v = cell_vector(dem, lambda x: oblique(x, 0.01)), cell_vector(dem, oblique)
    dt = 0.004
    out = dem.create_vector()
    c.force_integral(*c.prepare(u, v, dt), dt, out)
    end, far = u.copy(), u.copy()
    end.axpy(dt, v)
    far.axpy(0.5 * dt, v)
    for x, reused in ((end, True), (far, False)):
        up = c.patch_values(x)
        at = PairState(c.pair_list, c._c_patch, c._work, c._end, up)
        assert not at.moved and (at.candidates is not None) == reused
        assert np.array_equal(at.uc, c.free_displacements(up))
        if reused:
            assert 0 < len(at.candidates) < len(c.listed) / 4
        state = dataclasses.astuple(at.pairs)
        full = dataclasses.astuple(PairState(c.pair_list, c._c_patch, c._work, None, up).pairs)  # every pair screened
        assert len(state[0]) > 20
        for a, b in zip(state, full):
            assert np.array_equal(np.asarray(a), np.asarray(b))


def test_the_step_arrays_of_a_list_are_reused_and_a_stale_use_raises():
    """A pair list's flight screen and contact state live in arrays made once per list
    (``events.StepWork``): a later state takes the state arrays (the earlier state's closed pairs,
    copies, stay; its kernel arrays raise, and the reused struct's count and sums start again), a
    later flight the screen's (the force integral of the earlier one raises; ``prepare`` again and
    it runs)."""
    from dolfinx_dem.contact.events import PairState
    from dolfinx_dem.errors import StateError

    problem = two_boxes(MPI.COMM_SELF)
    dem = problem.dem
    c = problem.find(PairContact)
    u, v = cell_vector(dem, lambda x: oblique(x, 0.01)), cell_vector(dem, oblique)
    dt, out = 0.004, dem.create_vector()
    up, vp = c.prepare(u, v, dt)
    first = c.state(up)
    closed = dataclasses.astuple(first.pairs)
    assert len(closed[0]) > 20 and closed[6][0] > 0  # closed pairs, a positive elastic energy change
    rest = PairState(c.pair_list, c._c_patch, c._work, None, c.patch_values(dem.create_vector()))
    assert len(rest.pairs.closed) == 0 and rest.pairs.energy == (0.0, 0.0) and rest.pairs.mu_w == 0.0
    assert rest.kernel_state.c.n == 0
    for a, b in zip(closed, dataclasses.astuple(first.pairs)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    with pytest.raises(StateError, match="later state"):
        assert first.kernel_state is None  # raises before
    c.free_flight(first.uc, vp, dt)  # a later flight of the same list
    with pytest.raises(StateError, match="later one"):
        c.force_integral(up, vp, dt, out)
    up, vp = c.prepare(u, v, dt)
    assert c.force_integral(up, vp, dt, out) > 0 and out.norm() > 0


@pytest.mark.mpi
@pytest.mark.parametrize("surface", ["facet", "vertex"])
def test_cubes_collide_obliquely_with_exact_energy_on_any_number_of_processes(surface):
    """Two tetrahedral cubes meet obliquely and slide against each other (the overlaps change
    topology: events split the steps): the pseudo-energy and the momentum are conserved to
    rounding, the contact pushes the cubes apart with a sliding (tangential) force component,
    and the run on COMM_WORLD (1, 2, 3 processes) matches the serial one, with either surface."""
    steps = 12  # contact from step 5
    drift, dp, p_left, force, evaluations = _cubes_impact(MPI.COMM_WORLD, steps, surface)
    assert drift < 1e-13
    assert dp < 1e-13
    assert evaluations >= 9  # some step split into 3 pieces at least
    assert force[0] < 0 and np.abs(force[1:]).max() > 1e-3 * -force[0]  # normal push, sliding force
    if MPI.COMM_WORLD.size == 1:
        return
    serial = _cubes_impact(MPI.COMM_SELF, steps, surface)
    assert np.abs(p_left - serial[2]).max() < 1e-12 * np.abs(serial[2]).max()
    assert np.abs(force - serial[3]).max() < 1e-10 * np.abs(serial[3]).max()


@pytest.mark.mpi
def test_self_contact_closes_a_slot_in_3d():
    """A tetrahedral slab with a 0.01 m slot whose arms close on each other (and slide along z):
    the slot walls, facets of one body, touch with exact energy (measured drift 1.5e-15)."""

    def build(gmsh):
        outer = gmsh.model.occ.addBox(0.0, 0.0, 0.0, 0.2, 0.2, 0.06)
        slot = gmsh.model.occ.addBox(0.095, 0.06, -0.01, 0.01, 0.2, 0.08)
        body, _ = gmsh.model.occ.cut([(3, outer)], [(3, slot)])
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [body[0][1]], 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.07)
        gmsh.model.mesh.generate(3)

    dem = DEMDiscretisation(gmsh_mesh(MPI.COMM_WORLD, build, gdim=3), SOFT, "B")
    walls = meshes.locate_boundary_facets(dem.mesh, lambda x: (x[0] > 0.09) & (x[0] < 0.11) & (x[1] > 0.059))
    problem = DEMProblem(dem, [PairContact(dem, walls, self_contact=True)])
    c = problem.find(PairContact)
    assert c.num_pairs > 0 and c.body_pairs == []
    dt = 0.3 * dem.stable_time_step()
    stepper = MEMM(problem, dt)

    def closing(x):
        """The arms close (x velocity growing with height) and slide along z."""
        sign = np.where(x[:, 0] < 0.1, 1.0, -1.0)
        return np.stack([0.3 * sign * x[:, 1] / 0.2, np.zeros(len(x)), 0.05 * sign], axis=1)

    first = stepper.initialise(dem.create_vector(), cell_vector(dem, closing))
    touched, drift = 0, 0.0
    for _ in range(int(0.03 / dt)):
        diag = stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy) / first.mechanical)
        touched += c.outputs.touching(c.patch_values(stepper.u))
    assert touched >= 5 and drift < 1e-12


@pytest.mark.mpi
def test_a_restored_state_steps_as_the_first_time():
    """``MEMM.restore`` and ``PairContact.restore_state`` on the same model, in mid-impact (the
    benchmark's replays): the steps after the restore are bit-identical to the first pass. The
    facets known stay those of the last exchange; the restore does not force an exchange, the
    drift from the last exchange's places decides (none here after a short window)."""
    dem, facets = two_discs(h=0.03)
    problem = DEMProblem(dem, [PairContact(dem, facets)])
    c = problem.find(PairContact)
    stepper = MEMM(problem, 0.2 * dem.stable_time_step())
    stepper.initialise(dem.create_vector(), cell_vector(dem, approach))
    for _ in range(25):  # contact from step 14
        stepper.step()
    saved = stepper.state()
    vectors = {k: saved[k].array_r.copy() for k in ("u", "v_prev", "v_next")}
    scalars = {
        k: saved[k]
        for k in ("t0", "n", "budget", "work", "data_potential", "force_evaluations", "max_step_evaluations")
    }
    recurrence, contact_state = saved["recurrence"], c.checkpoint_state()
    first, exchanges = [], c.exchanges
    for _ in range(10):
        first.append(stepper.step().pseudo_energy)
    u_first = stepper.u.array_r.copy()
    stepper.restore(**vectors, **scalars, recurrence={k: a.copy() for k, a in recurrence.items()})
    c.restore_state(contact_state)
    again = [stepper.step().pseudo_energy for _ in range(10)]
    assert again == first and np.array_equal(stepper.u.array_r, u_first)
    assert c.outputs.touching(c.patch_values(stepper.u))
    assert c.exchanges == exchanges  # restored with the counters, and no exchange since


def test_memm_gathers_the_patch_values_once_per_step():
    """MEMM's patch values of u^n are those of a fresh gather, shared read only by the step's
    end, the outputs and the next step's ``prepare``, gathered again after a step; ``prepare``
    refuses patch values of another patch."""
    dem, facets = two_discs(h=0.03)
    problem = DEMProblem(dem, [PairContact(dem, facets)])
    c = problem.find(PairContact)
    stepper = MEMM(problem, 0.2 * dem.stable_time_step())
    stepper.initialise(dem.create_vector(), cell_vector(dem, approach))
    for _ in range(3):
        up = stepper.contact_patch_values()[0]
        assert stepper.contact_patch_values()[0] is up and not up.flags.writeable
        assert np.array_equal(up, c.patch_values(stepper.u))
        stepper.step()
        assert stepper.contact_patch_values()[0] is not up
    with pytest.raises(ValueError, match="patch values of u given for a patch of"):
        c.prepare(stepper.u, up=np.zeros(len(c.scatter) + 1))
