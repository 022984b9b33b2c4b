"""Coulomb friction between bodies (contact/pair_friction.py): the energy balance E + D - W and a
non-negative dissipation at every step, the total momentum, a block sliding on a clamped body at
mu g, a block held by friction on it without creep, the rounds (a lone pair, a chain, the cap), the
same results on 1, 2 and 3 processes, mu = 0 as frictionless, and the errors."""


import warnings

import numpy as np
import pytest
from helpers import stop_after
from mpi4py import MPI
from pair_scenes import SOFT, two_discs

from dolfinx_dem import meshes, model, scenes, simulation
from dolfinx_dem.conditions import DirichletBC
from dolfinx_dem.contact import PairContact, pair_friction
from dolfinx_dem.contact.pair_friction import PairFriction
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import AccuracyWarning, InputError, SceneError, StateError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.statics import minimise_energy

G = 10.0
BLOCK = ElasticMaterial(E=1e4, nu=0.3, rho=1.0)


def oblique(x):
    """The disks meet head-on at 0.3 m/s each and pass each other at 0.1 m/s each: they slide."""
    left = x[:, 0] < 0.25
    return np.stack([np.where(left, 0.3, -0.3), np.where(left, 0.1, -0.1)], axis=1)


def oblique_scene() -> dict:
    """The two-disks scene (h = 0.03, to 0.1 s, every step written) with the disks meeting obliquely
    and mu = 0.3 between them."""
    scene = scenes.load("two-disks")
    scene["mesh"]["h"] = 0.03
    scene["contact"]["friction"] = 0.3
    scene["initial"]["velocity"] = ["where(x < 0.25, 0.3, -0.3)", "where(x < 0.25, 0.1, -0.1)"]
    scene["time"]["end"] = 0.1
    scene["output"]["every"] = 1
    return scene


def run_discs(mu, steps, comm=MPI.COMM_WORLD, scheme="B"):
    """The two disks of paper §5.3 (h = 0.03) meeting obliquely with friction ``mu``: the
    diagnostics of every step, and the stepper."""
    dem, facets = two_discs(comm=comm, scheme=scheme)
    problem = DEMProblem(dem, [PairContact(dem, facets, friction=mu)])
    stepper = MEMM(problem, 0.2 * dem.stable_time_step())
    v0 = oblique(dem.geometry.cell_centres[: dem.n_owned]).ravel()
    first = stepper.initialise(dem.create_vector(), v0)
    return first, [stepper.step() for _ in range(steps)], stepper


@pytest.mark.mpi
def test_friction_between_disks_balances_the_energy_at_every_step_and_keeps_the_momentum():
    """The disks slide on each other through their impact (from step 16 of 0.2 dt_stable): D grows
    (to 1.6 % of the kinetic energy at step 90, measured), never decreases, E + D stays within 1e-13 of the
    energy scale at every step, and the total momentum (no obstacle, no Dirichlet condition, no
    load) stays 0 to rounding."""
    first, rows, stepper = run_discs(0.3, 90)
    scale = first.kinetic
    balance = np.array([r.balance for r in rows])
    dissipation = np.array([r.dissipation for r in rows])
    assert np.abs(balance - first.balance).max() < 1e-13 * scale
    assert np.diff(np.r_[0.0, dissipation]).min() >= 0.0
    assert dissipation[-1] > 1e-3 * scale
    assert np.abs(np.array([r.momentum for r in rows])).max() < 1e-13 * np.sqrt(scale)
    friction = stepper.problem.contacts[0].friction
    assert friction.unconverged == 0


@pytest.mark.mpi
def test_friction_between_disks_is_the_same_on_any_partition():
    """The run on all processes against the one on each process alone: the dissipation and the
    kinetic energy at every step agree to 1e-12 of the energy scale. (Over longer runs of the
    sliding contact the difference grows by about 10 every 15 steps: docs/theory.md.)"""
    comm = MPI.COMM_WORLD
    first, rows, _ = run_discs(0.3, 90, comm)
    _, alone, _ = run_discs(0.3, 90, MPI.COMM_SELF)
    scale = first.kinetic
    for key in ("dissipation", "kinetic"):
        a, b = (np.array([getattr(r, key) for r in x]) for x in (rows, alone))
        assert np.abs(a - b).max() < 1e-12 * scale, key


def test_mu_0_is_frictionless_bit_for_bit():
    """friction = 0 makes no friction model, and the run is that of the default contact."""
    _, rows, stepper = run_discs(0.0, 60)
    assert stepper.problem.contacts[0].friction is None
    dem, facets = two_discs()
    problem = DEMProblem(dem, [PairContact(dem, facets)])
    stepper2 = MEMM(problem, 0.2 * dem.stable_time_step())
    stepper2.initialise(dem.create_vector(), oblique(dem.geometry.cell_centres[: dem.n_owned]).ravel())
    for row in rows:
        diag = stepper2.step()
        assert (diag.kinetic, diag.pseudo_energy) == (row.kinetic, row.pseudo_energy)
    assert np.array_equal(stepper2.u.array_r, stepper.u.array_r)


def block_on_base(mu, gravity, comm=MPI.COMM_WORLD, h=0.05, left=-0.215):
    """A 0.4 x 0.2 block (body 1) on a 1 x 0.2 base (body 0) clamped at its bottom, E = 1e4,
    nu = 0.3, rho = 1, mesh size ``h``, the block's left end at x = ``left`` (non-matching: its
    facets straddle the base's),
    contact on the interface y = 0 with friction ``mu``, the body force ``gravity`` per unit mass."""
    mesh, _, _ = meshes.create_discs(comm, [], h, rectangles=[[-0.5, -0.2, 0.5, 0.0], [left, 0.0, left + 0.4, 0.2]])
    base = meshes.locate_boundary_facets(mesh, lambda x: x[1] <= -0.2 + 1e-9)
    dem = DEMDiscretisation(mesh, BLOCK, "A", dirichlet=[DirichletBC(base, [0.0, 0.0])],
                            body_force=list(BLOCK.rho * np.asarray(gravity)))
    facets = meshes.locate_boundary_facets(mesh, lambda x: np.abs(x[1]) < 1e-9)
    return DEMProblem(dem, [PairContact(dem, facets, friction=mu)])


def test_a_block_sliding_on_a_clamped_body_slows_at_mu_g():
    """The block settled on the base (frictionless statics), then launched at 0.5 m/s along it
    with mu = 0.3: its mean velocity decreases at mu g = 3 m/s^2 (a fit over 0.02-0.12 s: measured
    -0.4 %), D grows by the kinetic energy lost and E + D stays within 1e-13 of the scale."""
    u0 = minimise_energy(block_on_base(0.0, [0.0, -G]), fixed_mean=[0]).u
    problem = block_on_base(0.3, [0.0, -G])
    dem = problem.dem
    block = dem.geometry.cell_centres[: dem.n_owned, 1] > 0
    v0 = np.zeros((dem.n_owned, 2))
    v0[block, 0] = 0.5
    stepper = MEMM(problem, 0.5 * dem.stable_time_step())
    first = stepper.initialise(u0, v0.ravel())
    mass = dem.comm.allreduce(float(dem.mass.array_r[::2][block].sum()), op=MPI.SUM)
    t, v, balance, dissipation = [], [], [], []
    while stepper.t < 0.12:
        diag = stepper.step()
        vx = stepper.v_next.array_r.reshape(-1, 2)[: dem.n_owned][block, 0] @ dem.mass.array_r[::2][block]
        t.append(diag.t)
        v.append(dem.comm.allreduce(float(vx), op=MPI.SUM) / mass)
        balance.append(diag.balance)
        dissipation.append(diag.dissipation)
    t, v = np.array(t), np.array(v)
    scale = first.kinetic
    assert np.abs(np.array(balance) - first.balance).max() < 1e-13 * scale
    assert np.diff(np.r_[0.0, dissipation]).min() >= 0.0
    late = t > 0.02
    a = np.polyfit(t[late], v[late], 1)[0]
    assert abs(-a / (0.3 * G) - 1) < 0.03, a


def interface_pairs(dem):
    """The (block cell, base cell) pairs whose facets on y = 0 overlap (one process)."""
    x = dem.geometry.cell_vertices[: dem.n_owned]
    on = np.abs(x[:, :, 1]) < 1e-9
    cells = np.flatnonzero(on.sum(axis=1) == 2)
    ends = np.sort(np.where(on[cells], x[cells, :, 0], np.nan), axis=1)[:, :2]
    block = dem.geometry.cell_centres[cells, 1] > 0
    overlap = np.minimum(ends[block, None, 1], ends[None, ~block, 1]) - np.maximum(ends[block, None, 0],
                                                                                    ends[None, ~block, 0])
    a, b = np.nonzero(overlap > 1e-9)
    return cells[block][a], cells[~block][b]


def tilted_block(mu, tan, steps):
    """The block (its left end at x = -0.25: each of its facets straddles two of the base's) settled
    on the base under gravity G along -y (frictionless statics), then from rest under gravity tilted
    by theta (tan theta = ``tan``) towards +x, with friction ``mu``, h = 0.1: the largest change of
    the touching cells' relative x-displacement over the steps, the diagnostics and the stepper."""
    u0 = minimise_energy(block_on_base(0.0, [0.0, -G], h=0.1, left=-0.25), fixed_mean=[0]).u
    problem = block_on_base(mu, G * np.array([tan, -1.0]) / np.hypot(1.0, tan), h=0.1, left=-0.25)
    stepper = MEMM(problem, 0.5 * problem.dem.stable_time_step())
    first = stepper.initialise(u0, np.zeros(2 * problem.dem.n_owned))
    c, c2 = interface_pairs(problem.dem)
    slip = lambda: (lambda u: u[c, 0] - u[c2, 0])(stepper.u.array_r.reshape(-1, 2))  # noqa: E731
    start, drift, rows = slip(), 0.0, []
    for _ in range(steps):
        rows.append(stepper.step())
        drift = max(drift, np.abs(slip() - start).max())
    return drift, first, rows, stepper


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the interface's cells on one process")
def test_a_block_held_by_friction_on_an_elastic_body_does_not_creep_and_slides_above_mu():
    """The block settled on the elastic base, then loaded along it at once by gravity tilted by
    tan theta = 0.05 < mu = 0.5 (no damping: it vibrates; its 8 pairs stay in contact with |tau_p| at
    most 0.6 mu N_p, measured):
    its touching cells' tangential motion relative to the base's stays below 1e-10 of its size over
    200 steps (measured 3.1e-12 m, all in the first steps: the frictionless start's v^{1/2} moves
    them before the rounds stick them; 1.9e-7 m with the Jacobi rounds stopped at 1e-13 of the
    largest mu N_p). With tan theta = 0.7 > mu it slides (measured 1.2e-3 m in 150 steps). E + D
    within 1e-13 of the energy scale and D non-decreasing at every step in both; the rounds converge
    in fewer than 200 (measured 131); D stays at 1e-13 of the scale (the first steps).
    """
    for tan, steps in ((0.05, 200), (0.7, 150)):
        drift, first, rows, stepper = tilted_block(0.5, tan, steps)
        scale = max(r.elastic for r in rows)
        assert np.abs(np.array([r.balance for r in rows]) - first.balance).max() < 1e-13 * scale
        assert np.diff(np.r_[0.0, [r.dissipation for r in rows]]).min() >= 0.0
        friction = stepper.problem.contacts[0].friction
        assert friction.unconverged == 0 and friction.rounds < 200, friction.rounds
        if tan < 0.5:
            assert drift < 1e-10 * 0.4 and rows[-1].dissipation < 1e-12 * scale, (drift, rows[-1].dissipation)
        else:
            assert drift > 1e-4 and rows[-1].dissipation > 1e-3 * scale, (drift, rows[-1].dissipation)


def rounds_on(mass, ci, cj, relative, w, limit):
    """PairFriction's rounds alone, on one process, for the pairs (ci[k], cj[k]) of cells of masses
    ``mass`` with normal e_y (2D): (the impulses, slipping, the rounds, converged)."""
    friction = PairFriction.__new__(PairFriction)
    friction.comm, friction.d, friction._mass = MPI.COMM_SELF, 2, np.asarray(mass, dtype=float)

    def cell_impulses(tau, ci, cj, reduce):
        T = np.zeros((len(mass), 2))
        np.add.at(T, ci, tau)
        np.add.at(T, cj, -tau)
        return T

    friction._cell_impulses = cell_impulses
    k = np.bincount(np.r_[ci, cj], minlength=len(mass)).astype(float)
    D = 2.0 * (k[ci] / friction._mass[ci] + k[cj] / friction._mass[cj])
    n = np.tile([0.0, 1.0], (len(ci), 1))
    rounding = np.full(len(ci), 1e-12)
    return friction._rounds(relative, D, w, n, np.asarray(limit, dtype=float), rounding, ci, cj)


def test_the_rounds_give_a_lone_pair_the_obstacle_law_in_one_round_and_solve_a_chain(monkeypatch):
    """A pair alone on its cells: its stick impulse -m_red/2 r (or its projection on the disc) in
    the first round, where the rounds stop. A chain of 16 pairs along a non-matching interface (17
    cells, alternately on either side, masses 0.5 to 2): the stick impulses of the linear system
    A tau = -r to 1e-13, in fewer than 400 rounds (measured 320; plain Jacobi rounds, beta = 0, need
    4262 to the same stop: lambda_min(D^-1 A) = 0.0072);
    with bounds that bind, the fixed point of the projected gradient (every pair's step at most
    1e-2 of its threshold), inside every K_p (|tau_p| <= mu N_p, tau_p . w_p <= 0). Stopped at
    MAX_ROUNDS, the rounds say so and their impulses are in K all the same."""
    one = np.array([0]), np.array([1])
    for limit, expected in ((1.0, [0.15, 0.0]), (0.1, [0.1, 0.0])):  # m_red / 2 = 1 / 3
        tau, slip, rounds, converged = rounds_on([1.0, 2.0], *one, np.array([[-0.45, 0.0]]), np.zeros((1, 2)),
                                                 [limit])
        assert rounds == 1 and converged and slip[0] == (limit < 0.15)
        assert np.allclose(tau[0], expected, rtol=1e-15, atol=0.0)
    rng = np.random.default_rng(3)
    cells = np.arange(17)
    even = np.arange(16) % 2 == 0  # the block's cells even, the base's odd: pair k joins cells k and k + 1
    ci, cj = np.where(even, cells[:16], cells[1:]), np.where(even, cells[1:], cells[:16])
    mass = rng.uniform(0.5, 2.0, 17)
    relative = np.c_[rng.uniform(-1.0, 1.0, 16), np.zeros(16)]
    tau, slip, rounds, converged = rounds_on(mass, ci, cj, relative, np.zeros((16, 2)), np.full(16, 1e3))
    B = np.zeros((17, 16))
    B[ci, np.arange(16)], B[cj, np.arange(16)] = 1.0, -1.0
    A = 2.0 * B.T @ (B / mass[:, None])
    assert converged and not slip.any() and rounds < 400, rounds
    assert np.abs(tau[:, 0] - np.linalg.solve(A, -relative[:, 0])).max() < 1e-13 * np.abs(tau).max()
    w = np.c_[rng.uniform(-1e-3, 1e-3, 16), np.zeros(16)]
    limit = rng.uniform(0.05, 0.5, 16)
    tau, slip, rounds, converged = rounds_on(mass, ci, cj, relative, w, limit)
    assert converged and slip.any() and rounds < 400, rounds
    assert (np.linalg.norm(tau, axis=1) <= limit * (1 + 1e-15)).all() and (np.einsum("ki,ki->k", w, tau) <= 0).all()
    gradient = relative[:, 0] + A @ tau[:, 0]
    inside = ~slip & (np.abs(tau[:, 0]) > 0)
    assert inside.sum() > 3 and np.abs(gradient[inside]).max() < 1e-14
    monkeypatch.setattr(pair_friction, "MAX_ROUNDS", 5)
    tau, slip, rounds, converged = rounds_on(mass, ci, cj, relative, w, limit)
    assert rounds == 5 and not converged
    assert (np.linalg.norm(tau, axis=1) <= limit * (1 + 1e-15)).all() and (np.einsum("ki,ki->k", w, tau) <= 0).all()


def test_errors():
    """A bad coefficient, friction on a prescribed body, statics with friction (Python and
    scene), a quadrature other than the midpoint rule's exact integral."""
    dem, facets = two_discs()
    for mu in (-0.1, float("nan"), "0.3", True):
        with pytest.raises(InputError, match="friction coefficient"):
            PairContact(dem, facets, friction=mu)
    with pytest.raises(InputError, match="implemented in 2D and 3D"):  # no pair contact (nor friction) in 1D
        mesh, _, _ = meshes.create_interval(MPI.COMM_WORLD, 4, 0.0, 1.0)
        PairContact(DEMDiscretisation(mesh, SOFT, "A"), np.array([0], dtype=np.int32), friction=0.3)
    with pytest.warns(AccuracyWarning, match="contact between bodies: friction on scheme B candidates") as caught:
        problem = DEMProblem(dem, [PairContact(dem, facets, friction=0.3)])  # two_discs: scheme B
    assert len(caught) == (MPI.COMM_WORLD.rank == 0)
    with warnings.catch_warnings():  # scheme A's candidates, or no friction: no warning
        warnings.simplefilter("error", AccuracyWarning)
        PairContact(*two_discs(scheme="A"), friction=0.3)
        PairContact(dem, facets)
    with pytest.raises(InputError, match="friction is path dependent"):
        minimise_energy(problem)
    stepper = MEMM(problem, 0.2 * dem.stable_time_step(), quadrature="gauss-legendre-2")
    stepper.initialise(dem.create_vector(), oblique(dem.geometry.cell_centres[: dem.n_owned]).ravel())
    with pytest.raises(StateError, match="midpoint"):  # the normal impulses come from the exact integral
        stepper.step()
    scene = scenes.load("indentation")
    scene["contact"]["friction"] = 0.3
    with pytest.raises(InputError, match="prescribed body"):
        model.build(scene)
    scene = scenes.load("hertz")
    del scene["obstacles"]
    scene["contact"] = {"boundary": ["y <= 0.2"], "friction": 0.3}
    with pytest.raises(SceneError, match="contact.friction"):
        scenes.validate(scene)


def test_a_scene_with_friction_between_bodies_reports_it_and_resumes_bit_identical(tmp_path, monkeypatch):
    """The oblique two-disks scene (h = 0.03) with ``contact.friction``: the series has
    ``dissipation``, ``balance`` (to 1e-13 of the kinetic energy), the tangential force between
    the bodies and the slipping pairs; interrupted while they slide and resumed, the run writes
    the same bytes and its summary the whole run's friction counters."""
    scene = oblique_scene()
    full = simulation.run(scene, tmp_path / "full", MPI.COMM_WORLD, quiet=True)
    series = np.genfromtxt(tmp_path / "full" / "series.csv", delimiter=",", names=True)
    assert {"dissipation", "balance", "friction_force_0_1_x", "friction_force_0_1_y",
            "slipping_pairs"} <= set(series.dtype.names)
    assert np.abs(series["balance"] - series["balance"][0]).max() < 1e-13 * series["kinetic"][0]
    assert np.diff(series["dissipation"]).min() >= 0.0 and full["dissipation"] == series["dissipation"][-1] > 0
    # body 1 slides down past body 0: the force on body 0 points down the y axis
    assert series["friction_force_0_1_y"].min() < 0.0 and series["friction_force_0_1_y"].max() == 0.0
    assert full["friction_negative_normal_fraction"] == 0.0

    # interrupted while the disks still slide, after the steps of the most rounds
    stop = full["n_steps"] - 3
    assert series["dissipation"][stop] > series["dissipation"][stop - 1]
    stop_after(monkeypatch, stop)
    assert simulation.run(scene, tmp_path / "parts", MPI.COMM_WORLD, quiet=True)["status"] == "interrupted"
    monkeypatch.undo()
    resumed = simulation.resume(tmp_path / "parts", MPI.COMM_WORLD, quiet=True)
    assert resumed["status"] == "completed"
    assert (tmp_path / "parts" / "series.csv").read_bytes() == (tmp_path / "full" / "series.csv").read_bytes()
    # the friction counters of the whole run, not of its resumed part (rounds peak at the first impact)
    for key in ("friction_max_rounds", "friction_median_rounds", "friction_unconverged_steps",
                "friction_negative_normal_fraction"):
        assert resumed[key] == full[key], key


def test_friction_between_balls_in_3d_balances_the_energy(tmp_path):
    """The two-balls scene (h = 0.05, refined to 0.02 at the contact) meeting obliquely with mu = 0.3:
    E + D within 1e-13 of the kinetic energy at every step (measured 2.8e-15 at h = 0.05), D never
    decreasing, pairs slipping, the momentum kept to rounding. Friction between bodies needs the facet
    surface (the scene's own is the vertex surface), with the scene's former eta = 10 E."""
    scene = scenes.load("two-balls")
    scene["mesh"].update(h=0.05, refine_h=0.02)
    scene["material"]["eta"] = 1000.0
    scene["contact"].update(surface="facet", friction=0.3)
    scene["initial"]["velocity"] = ["where(x < 0.25, 0.3, -0.3)", "where(x < 0.25, 0.1, -0.1)",
                                    "where(x < 0.25, 0.05, -0.05)"]
    scene["time"]["end"] = 0.15
    scene["output"] = {"every": 10**9}
    summary = simulation.run(scene, tmp_path / "balls", MPI.COMM_WORLD, quiet=True)
    series = np.genfromtxt(tmp_path / "balls" / "series.csv", delimiter=",", names=True)
    assert np.abs(series["balance"] - series["balance"][0]).max() < 1e-13 * series["kinetic"][0]
    assert np.diff(series["dissipation"]).min() >= 0.0 and summary["dissipation"] > 0.0
    assert series["slipping_pairs"].max() > 0 and summary["momentum_rel_change"] < 1e-13
    assert {"friction_force_0_1_x", "friction_force_0_1_y", "friction_force_0_1_z"} <= set(series.dtype.names)
