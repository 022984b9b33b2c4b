"""The 3D contact scenes (two-balls, cradle, ball-drop) on coarse meshes, a few steps each (two-balls
keeps its refinement at the contact point and its vertex surface at eta = E: at h = 0.06 m, 691 cells)."""

import json

import numpy as np
import pytest
from helpers import cell_vector
from mpi4py import MPI

from dolfinx_dem import model, scenes, simulation
from dolfinx_dem.contact import PairContact
from dolfinx_dem.errors import AccuracyWarning


def test_closed_pairs_state_is_the_full_state_where_gaps_are_negative():
    """``PairContact._state(closed=True)`` clips only the pairs with g < 0 and gives the same
    g, w, dw/du there as clipping every listed pair (w = dw = 0 elsewhere)."""
    problem = model.build(scenes.load("two-balls", {"mesh.h": 0.05}), MPI.COMM_SELF)
    dem = problem.dem
    c = problem.find(PairContact)
    u = cell_vector(dem, lambda x: np.stack([np.where(x[:, 0] < 0.25, 0.02, -0.02), 0.002 * x[:, 1],
                                             np.zeros(len(x))], axis=1))
    c.prepare(u)
    p = np.arange(c.num_pairs)
    ui, uj = c.pair_displacements(c.patch_values(u))
    g, w, dw = c.gaps_and_overlaps(p, ui, uj)
    gc, wc, dwc = c.gaps_and_overlaps(p, ui, uj, closed=True)
    closed = g < 0
    assert (closed & (w > 0)).sum() > 10
    assert np.array_equal(gc, g)
    assert np.array_equal(wc[closed], w[closed]) and np.array_equal(dwc[closed], dw[closed])
    assert not wc[~closed].any() and not dwc[~closed].any()


@pytest.mark.slow
def test_two_balls_conserve_energy_and_momentum_through_first_contact(tmp_path):
    """Coarse two-balls, the steps through the first contact: 0.02 m between the spheres closing
    at 0.6 m/s, a little more between the polyhedra (their facets' gaps along the pair normals
    at t = 0, at least the gap of the spheres, set the bounds)."""
    scene = scenes.load("two-balls", {"mesh.h": 0.06, "time.end": 0.05, "time.cfl": 0.5})
    c = model.build(scene, MPI.COMM_SELF).find(PairContact)
    gap = c.outputs.smallest_gap(c.patch_values(c.dem.create_vector()))
    assert 0.02 < gap < 0.03
    summary = simulation.run(scene, tmp_path, MPI.COMM_SELF, quiet=True)
    assert gap / 0.6 <= summary["first_contact_time"] < 0.03 / 0.6
    assert summary["pseudo_energy_rel_drift"] <= 1e-12
    assert summary["momentum_rel_change"] <= 1e-12
    header = (tmp_path / "series.csv").read_text().splitlines()[0].split(",")
    for column in ("contact_force", "penetration", "contact_force_0_1_z", "momentum_z"):
        assert column in header


@pytest.mark.slow
def test_two_balls_first_contact_within_a_step_and_no_sinking(tmp_path):
    """The scene as shipped (refined at the contact point, the vertex surface at the paper's eta = E),
    to 0.3 s: the first contact within one step of the spheres' 0.02 / 0.6 s, and the contact surfaces
    held (0.073 facet sizes to 0.3 s, 0.074 over the whole run). With the facet surface at eta = E the
    same mesh sinks and the run stops at 0.227 s (touching pairs deeper than the list radius, at 0.496
    facet sizes); at eta = 10 E it holds at 0.124 (docs/validation/contact3d.md)."""
    with pytest.warns(AccuracyWarning, match="touching facets of two bodies cross at"):
        summary = simulation.run(scenes.load("two-balls", {"time.end": 0.3, "output.every": 10000}), tmp_path,
                                 MPI.COMM_SELF, quiet=True)
    assert summary["status"] == "completed" and summary["max_contact_crossing_angle"] > 80.0  # paper §5.3's speed
    assert abs(summary["first_contact_time"] - 0.02 / 0.6) < summary["dt"]
    # well below the limit 0.5 where facets sink into each other's holes, and below the facet
    # surface's 0.124 at eta = 10 E (0.073 on gmsh 4.8's mesh)
    assert 0.05 < summary["max_penetration_over_facet_size"] < 0.1
    assert summary["pseudo_energy_rel_drift"] <= 1e-12 and summary["momentum_rel_change"] <= 1e-12


def test_ball_drop_acts_with_the_floor_and_the_ball_in_the_same_steps():
    """Coarse ball-drop started just above the slab and moving down: the floor (an obstacle)
    and the ball (contact between bodies) both act in the same steps, and the pseudo-energy,
    gravity's potential included, is conserved."""
    from dolfinx_dem.dynamics import DynamicRun

    scene = scenes.load("ball-drop", {"mesh.h": 0.07, "time.end": 0.06, "time.cfl": 0.5,
                                      "initial.velocity": ["0", "0", "where(z > 0.045, -0.5, 0.0)"]})
    run = DynamicRun(scene, MPI.COMM_SELF, quiet=True)
    stepper = run.stepper
    first, both, drift = run.first, 0, 0.0
    for _ in range(run.n_steps):
        diag = stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy) / max(first.mechanical, diag.mechanical))
        floor = (run.obstacles.gaps(run.obstacles.patch_values(stepper.u)) < 0).any()
        both += bool(floor and run.pairs.outputs.touching(run.pairs.patch_values(stepper.u)))
    assert both >= 3
    assert drift <= 1e-12


def test_a_rebuild_that_would_drop_touching_pairs_is_an_error():
    """Balls driven into each other deeper than the pair list radius: the pairs listed while
    they were shallow would be dropped by a rebuild (an energy jump): ``prepare`` raises."""
    problem = model.build(scenes.load("two-balls", {"mesh.h": 0.06}), MPI.COMM_SELF)
    dem = problem.dem
    c = problem.find(PairContact)
    step = 0.2 * c.skin
    v = cell_vector(dem, lambda x: np.stack([np.where(x[:, 0] < 0.25, 1.0, -1.0), 0 * x[:, 1], 0 * x[:, 2]], axis=1))
    u = dem.create_vector()
    with pytest.raises(RuntimeError, match="deeper than the pair list radius"):
        while u.array.max() < 0.3:
            c.prepare(u, v, step)
            u.axpy(step, v)


def test_a_static_3d_scene_with_contact_between_bodies_is_refused_before_the_run(tmp_path):
    """Statics with contact between bodies is 2D (its Hessian takes the overlaps as affine on a
    piece): a 3D static scene with a 'contact' table is a clear error, and no folder is made."""
    scene = scenes.load("two-balls", {"mesh.h": 0.06})
    for key in ("time", "initial", "output"):
        scene.pop(key)
    scene["statics"] = {}
    with pytest.raises(scenes.SceneError, match="contact between bodies .* in 2D, not 3D"):
        simulation.run(scenes.validate(scene), tmp_path / "out", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "out").exists()


def test_contact_skin_is_a_scene_key():
    """``contact.skin``: one Verlet skin for every facet (> 0), passed to the pair list."""
    with pytest.raises(scenes.SceneError, match="contact.skin' must be > 0"):
        scenes.load("two-balls", {"mesh.h": 0.06, "contact.skin": 0.0})
    problem = model.build(scenes.load("two-balls", {"mesh.h": 0.06, "contact.skin": 0.05}), MPI.COMM_SELF)
    assert problem.find(PairContact).skin == 0.05


@pytest.mark.slow
def test_contact_surfaces_interpenetrating_beyond_the_limit_stop_the_run(tmp_path, capsys):
    """Contact surfaces that interpenetrate by more than ``contact.max_penetration`` candidate
    facet sizes stop the run with a clear error (the command exits 1), the summary says
    ``unresolved`` and keeps the penetration, and the folder is marked INCOMPLETE; with the
    default limit (0.5) the same impact goes on (two-balls at h = 0.06 m: 0.082 by 0.2 s, the
    limit 0.05 stops it at 0.129 s); pairs
    deeper than the list radius stop a run the same way."""
    from dolfinx_dem import cli, io

    with pytest.raises(scenes.SceneError, match="max_penetration' must be > 0"):
        scenes.load("two-balls", {"contact.max_penetration": 0.0})
    coarse = ["--set", "mesh.h=0.06", "--set", "time.end=0.2", "--set", "output.every=1000"]
    assert cli.main(["run", "two-balls", *coarse, "--set", "contact.max_penetration=0.05",
                     "--out", str(tmp_path / "stopped")]) == 1
    assert "contact between bodies is not resolved at t = " in capsys.readouterr().err
    stopped = json.loads((tmp_path / "stopped" / "summary.json").read_text())
    assert stopped["status"] == "unresolved" and "checkpoint" not in stopped
    assert 0.05 < stopped["max_penetration_over_facet_size"] < 0.06 and stopped["t_end"] < 0.2
    assert "more than contact.max_penetration = 0.05" in stopped["error"]
    assert (tmp_path / "stopped" / io.INCOMPLETE).exists()
    assert cli.main(["run", "two-balls", *coarse, "--quiet", "--out", str(tmp_path / "default")]) == 0
    default = json.loads((tmp_path / "default" / "summary.json").read_text())
    assert default["status"] == "completed" and 0.05 < default["max_penetration_over_facet_size"] < 0.5
    # with the limit lifted, balls at 3 m/s go deeper than the pair list radius: the same stop
    fast = ["--set", 'initial.velocity=["where(x < 0.25, 3.0, -3.0)", "0", "0"]',
            "--set", "contact.max_penetration=100"]
    assert cli.main(["run", "two-balls", *coarse, *fast, "--quiet", "--out", str(tmp_path / "deep")]) == 1
    deep = json.loads((tmp_path / "deep" / "summary.json").read_text())
    assert deep["status"] == "unresolved" and "deeper than the pair list radius" in deep["error"]
