"""Coulomb friction between bodies (contact/pair_friction.py): the energy balance E + D - W and a
non-negative dissipation at every step, the total momentum, a block sliding on a clamped body at
mu g, the same results on 1, 2 and 3 processes, mu = 0 as frictionless, and the errors."""

import signal

import numpy as np
import pytest
from mpi4py import MPI
from pair_scenes import SOFT, two_discs

from dolfinx_dem import meshes, model, runcontrol, scenes, simulation
from dolfinx_dem.conditions import DirichletBC
from dolfinx_dem.contact import PairContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import InputError, SceneError, StateError
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


def block_on_base(mu, gravity, comm=MPI.COMM_WORLD):
    """A 0.4 x 0.2 block (body 1) on a 1 x 0.2 base (body 0) clamped at its bottom, E = 1e4,
    nu = 0.3, rho = 1, h = 0.05 (non-matching: the block's facets straddle the base's), contact on
    the interface y = 0 with friction ``mu``, the body force ``gravity`` per unit mass."""
    mesh, _, _ = meshes.create_discs(comm, [], 0.05, rectangles=[[-0.5, -0.2, 0.5, 0.0], [-0.215, 0.0, 0.185, 0.2]])
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
    problem = DEMProblem(dem, [PairContact(dem, facets, friction=0.3)])
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
    the bodies and the slipping pairs; interrupted during the impact and resumed, the run writes
    the same bytes."""
    scene = scenes.load("two-disks")
    scene["mesh"]["h"] = 0.03
    scene["contact"]["friction"] = 0.3
    scene["initial"]["velocity"] = ["where(x < 0.25, 0.3, -0.3)", "where(x < 0.25, 0.1, -0.1)"]
    scene["time"]["end"] = 0.1
    scene["output"]["every"] = 1
    full = simulation.run(scene, tmp_path / "full", MPI.COMM_WORLD, quiet=True)
    series = np.genfromtxt(tmp_path / "full" / "series.csv", delimiter=",", names=True)
    assert {"dissipation", "balance", "friction_force_0_1_x", "friction_force_0_1_y",
            "slipping_pairs"} <= set(series.dtype.names)
    assert np.abs(series["balance"] - series["balance"][0]).max() < 1e-13 * series["kinetic"][0]
    assert np.diff(series["dissipation"]).min() >= 0.0 and full["dissipation"] == series["dissipation"][-1] > 0
    # body 1 slides down past body 0: the force on body 0 points down the y axis
    assert series["friction_force_0_1_y"].min() < 0.0 and series["friction_force_0_1_y"].max() == 0.0
    assert full["friction_negative_normal_fraction"] == 0.0

    calls, stop = [0], full["n_steps"] // 2
    assert series["dissipation"][stop] > 0  # interrupted while the disks slide

    def requested(self):
        calls[0] += 1
        self.signal = signal.SIGINT if calls[0] >= stop else 0
        return calls[0] >= stop

    monkeypatch.setattr(runcontrol.Interrupts, "requested", requested)
    assert simulation.run(scene, tmp_path / "parts", MPI.COMM_WORLD, quiet=True)["status"] == "interrupted"
    monkeypatch.undo()
    assert simulation.resume(tmp_path / "parts", MPI.COMM_WORLD, quiet=True)["status"] == "completed"
    assert (tmp_path / "parts" / "series.csv").read_bytes() == (tmp_path / "full" / "series.csv").read_bytes()


def test_friction_between_balls_in_3d_balances_the_energy(tmp_path):
    """The two-balls scene (h = 0.05, refined to 0.02 at the contact) meeting obliquely with mu = 0.3:
    E + D within 1e-13 of the kinetic energy at every step (measured 2.8e-15 at h = 0.05), D never
    decreasing, pairs slipping, the momentum kept to rounding."""
    scene = scenes.load("two-balls")
    scene["mesh"].update(h=0.05, refine_h=0.02)
    scene["contact"]["friction"] = 0.3
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
