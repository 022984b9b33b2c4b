"""Method fem-P1, the explicit P1 FEM peer (fem/penalty.py, fem/scene_run.py): the bar impact
against the exact Signorini bar, the same numbers as FEMCentralDifference without contact, the
same series on 1, 2 and 3 processes, and a clear error for what it does not run."""

import os
import pathlib
import re
import sys

import numpy as np
import pytest
from helpers import run_command
from mpi4py import MPI

from dolfinx_dem import exact, meshes, model, scenes, simulation
from dolfinx_dem.errors import InputError, SceneError
from dolfinx_dem.fem.common import node_coordinates
from dolfinx_dem.fem.elastodynamics import FEMCentralDifference, evaluate_at_points
from dolfinx_dem.fem.penalty import PENALTY_FACTOR

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")


def _series(path):
    return np.genfromtxt(path, delimiter=",", names=True)


def _run(scene, tempdir, name):
    out = pathlib.Path(tempdir) / name
    summary = simulation.run(scene, out, MPI.COMM_WORLD, quiet=True)
    return summary, _series(out / "series.csv")


@pytest.mark.mpi
def test_bar_impact_matches_the_exact_signorini_bar(tempdir):
    """Benchmark 1 (contact on [0.5, 7/6] at pressure 300, then rigid rebound at 10 m/s): the
    penalty lets the tip in by about p dt^2 / (s m_0) = 0.0375 m and releases it a few steps late."""
    scene = scenes.load("bar-impact", {"method": "fem-P1", "output.every": 400})
    summary, data = _run(scene, tempdir, "bar")
    t = data["t"]
    dt = summary["dt"]
    assert summary["method"] == "fem-P1" and summary["n_steps"] == 800
    assert list(data.dtype.names) == ["t", "kinetic", "elastic", "stabilisation", "external", "pseudo_energy",
                                      "penalty", "contact_gap", "contact_pressure", "tip_position",
                                      "contact_force_obstacle0_x"]
    assert np.array_equal(t, np.arange(801) * dt)  # t = n dt, as the DEM's
    contact = t[data["contact_pressure"] > 0]
    assert abs(contact[0] - 0.5) <= 1.01 * dt and abs(contact[-1] - 7.0 / 6.0) <= 4 * dt, (contact[0], contact[-1])
    assert np.abs(data["tip_position"] - exact.impact_tip_position(t)).max() < 0.12
    assert -0.05 < summary["min_contact_gap"] < -0.03  # p dt^2 / (s m_0) = 0.0375
    steady = (t > 0.6) & (t < 1.1)
    assert np.median(data["contact_pressure"][steady]) == pytest.approx(300.0, rel=0.02)
    assert np.allclose(data["contact_force_obstacle0_x"], data["contact_pressure"])  # 1D: area 1
    assert data["kinetic"][-1] == pytest.approx(500.0, rel=5e-3)  # the rebound keeps the energy
    assert data["stabilisation"].max() == 0.0
    # the penalty energy is not conserved exactly by central differences
    assert 1e-5 < summary["pseudo_energy_rel_drift"] < 2e-3


@pytest.mark.mpi
def test_without_contact_fem_p1_is_fem_central_difference(tempdir):
    """A 2D cantilever (clamped, body force, initial velocity expression, probe): the scene run
    gives the numbers of FEMCentralDifference driven directly."""
    scene = {
        "name": "beam", "method": "fem-P1",
        "mesh": {"type": "rectangle", "p0": [0.0, 0.0], "p1": [1.0, 0.1], "n": [20, 2], "diagonal": "crossed"},
        "material": {"E": 1000.0, "nu": 0.3, "rho": 1.0, "plane": "stress"},
        "dirichlet": [{"boundary": "left"}],
        "loads": {"gravity": [0.0, -0.5]},
        "initial": {"velocity": ["0", "0.1 * x**2"]},
        "time": {"end": 0.2, "cfl": 0.5},
        "probes": [{"name": "tip_uy", "point": [1.0, 0.05], "component": 1}],
    }
    summary, data = _run(scene, tempdir, "beam")
    assert summary["dt"] == pytest.approx(0.2 / round(0.2 / summary["dt"]), rel=1e-14)
    assert summary["dt"] <= 0.5 * summary["dt_stable"]
    mesh, _, tags, _ = model.create_mesh(MPI.COMM_WORLD, scene["mesh"])
    solver = FEMCentralDifference(
        mesh, 1000.0, 0.3, 1.0, tags.find(scenes.SIDES["left"]), dt=summary["dt"], body_force=[0.0, -0.5],
        initial_velocity=lambda x: np.stack([0 * x[0], 0.1 * x[0] ** 2]), plane_stress=True)
    assert solver.dt_stable == pytest.approx(summary["dt_stable"], rel=1e-10)
    rows = []
    for _ in range(summary["n_steps"] + 1):
        kinetic, elastic = solver.energies()
        rows.append((kinetic, elastic, solver.modified_energy(), evaluate_at_points(solver.u, [1.0, 0.05])[0, 1]))
        solver.step()
    rows = np.array(rows)
    scale = rows[:, :2].sum(axis=1).max()
    for k, column in enumerate(("kinetic", "elastic", "pseudo_energy")):
        assert np.abs(data[column] - rows[:, k]).max() <= 1e-12 * scale, column
    assert np.abs(data["tip_uy"] - rows[:, 3]).max() <= 1e-12 * np.abs(rows[:, 3]).max()
    assert np.abs(data["tip_uy"]).max() > 1e-4  # the beam moved
    assert summary["pseudo_energy_rel_drift"] < 1e-12  # the modified energy, exactly conserved
    # the clamp holds the beam's weight and its inertia: reaction_y = -(weight + m a_y) on average
    assert data["reaction_0_y"].mean() > 0


@pytest.mark.mpi
def test_the_penalty_stable_step_lies_between_the_bound_and_the_elastic_limit(tempdir):
    scene = scenes.load("bar-impact", {"method": "fem-P1", "time.end": 0.01})
    summary, _ = _run(scene, tempdir, "bar")
    assert np.sqrt(1 - PENALTY_FACTOR / 4) * summary["dt_stable"] <= summary["dt_stable_contact"] < summary["dt_stable"]
    assert summary["dt_stable"] == pytest.approx(0.1 / 30.0, rel=1e-8)  # h / c for the lumped P1 bar
    scene = scenes.load("bar-impact", {"method": "fem-P1", "time.dt": 0.0033, "time.end": 0.0066})
    with pytest.raises(InputError, match="stability limit .* with the penalty contact"):
        _run(scene, tempdir, "bar2")


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("name, end", [("bar-impact", 1.2), ("block", 0.2)])
def test_one_two_and_three_processes_give_the_same_series(name, end, tmp_path):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none", OMP_NUM_THREADS="1")
    options = ["--set", "method=fem-P1", "--set", f"time.end={end}", "--set", "output.every=1000", "--quiet"]
    data = []
    for n in (1, 2, 3):
        prefix = [] if n == 1 else ["mpirun", "-n", str(n), "--oversubscribe"]
        run_command([*prefix, CLI, "run", name, *options, "--out", str(tmp_path / str(n))], check=True, env=env)
        data.append(_series(tmp_path / str(n) / "series.csv"))
    a = data[0]
    energy = max(np.abs(a[c]).max() for c in ("kinetic", "elastic"))
    for b in data[1:]:
        assert a.shape == b.shape
        for column in a.dtype.names:
            scale = energy if column in model.SERIES_COLUMNS[1:] + ("penalty",) else np.abs(a[column]).max()
            assert np.abs(a[column] - b[column]).max() <= 1e-12 * max(scale, 1e-300), column


@pytest.mark.parametrize("name, overrides, key", [
    ("two-disks", {"contact.self_contact": True}, "contact.self_contact"),
    ("two-disks", {"contact.friction": 0.3}, "contact.friction"),
    ("two-disks", {"contact.skin": 0.01}, "contact.skin"),
    ("two-disks", {"contact.max_penetration": 0.5}, "contact.max_penetration"),
    ("bar-impact", {"material.eta": 900.0}, "material.eta"),
    ("bar-impact", {"time.quadrature": "gauss-legendre-2"}, "time.quadrature"),
    ("bar-impact", {"obstacles[0].friction": 0.3}, "obstacles[0].friction"),
    ("cantilever", {"dirichlet[0].components": [0]}, "dirichlet[0].components"),
    ("cantilever", {"dirichlet[0].value": [0.0, 0.01]}, "dirichlet[0].value"),
])
def test_what_fem_p1_does_not_run_is_an_error_naming_the_key(name, overrides, key, tmp_path):
    scene = scenes.load(name)
    scene["method"] = "fem-P1"
    for dotted, value in overrides.items():
        section, _, rest = dotted.partition(".")
        if section.endswith("[0]"):
            scene[section[:-3]][0][rest] = value
        else:
            scene.setdefault(section, {})[rest] = value
    key = re.escape(f"'{key}'")
    with pytest.raises(SceneError, match=f"{key}.*fem-P1|fem-P1.*{key}"):
        simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_fem_p1_is_for_dynamic_scenes_without_checkpoints(tmp_path):
    with pytest.raises(SceneError, match="fem-P1.*dynamic scenes only"):
        scenes.load("hertz", {"method": "fem-P1"})
    with pytest.raises(InputError, match="fem-P1.*no checkpoints"):
        simulation.run(scenes.load("bar-impact", {"method": "fem-P1"}), tmp_path / "b", MPI.COMM_SELF,
                       quiet=True, checkpoint_every=10)
    simulation.run(scenes.load("bar-impact", {"method": "fem-P1", "time.end": 0.01}), tmp_path / "c", MPI.COMM_SELF,
                   quiet=True)
    with pytest.raises(InputError, match="fem-P1 run.*cannot be resumed"):
        simulation.resume(tmp_path / "c", MPI.COMM_SELF, {"time.end": 0.02}, quiet=True)


def test_a_node_inside_the_obstacle_at_the_start_is_an_error(tmp_path):
    scene = scenes.load("bar-impact", {"method": "fem-P1"})
    scene["obstacles"][0]["point"] = [5.5]
    with pytest.raises(InputError, match="inside its obstacle"):
        simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)


def test_facet_nodes_are_the_facet_vertices():
    """The local facet -> P1 node map (fem/penalty.py) agrees with the mesh geometry."""
    from dolfinx_dem import _compat
    from dolfinx_dem.fem.common import facet_nodes, node_coordinates

    mesh, _, _ = meshes.create_box(MPI.COMM_SELF, [0, 0, 0], [1, 2, 3], [2, 3, 2])
    V = _compat.create_vector_space(mesh, "Lagrange", 1)
    facets = meshes.exterior_facets(mesh)
    x = node_coordinates(V)[facet_nodes(V, facets)]  # (n, 3, 3)
    _, facet_x, _ = _compat.facet_cell_and_vertices(mesh, facets)
    assert np.allclose(np.sort(x, axis=1), np.sort(facet_x, axis=1))


@pytest.mark.mpi
def test_a_suddenly_applied_traction_on_a_clamped_bar(tempdir):
    """Traction T at the free end of a clamped bar (L = c = E = 1) from rest: the tip swings
    between 0 and 2 T L / E with period 4 and mean T L / E; the clamp's reaction is 0, -2 T, 0
    (arrival of the wave at t = 1, its return at t = 3), of mean -T. With output.animation."""
    T = 0.01
    scene = {
        "name": "pulled", "method": "fem-P1",
        "mesh": {"type": "interval", "x0": 0.0, "x1": 1.0, "n": 50},
        "material": {"E": 1.0, "nu": 0.0, "rho": 1.0},
        "dirichlet": [{"boundary": "left", "name": "clamp"}],
        "tractions": [{"boundary": "right", "value": [T]}],
        "time": {"end": 4.0, "cfl": 0.5},
        "probes": [{"name": "tip", "point": [1.0], "component": 0}],
        "output": {"every": 100, "animation": True},
    }
    summary, data = _run(scene, tempdir, "pulled")
    t, tip, reaction = data["t"], data["tip"], data["reaction_clamp_x"]
    mean = np.trapz(tip, t) / 4.0
    assert mean == pytest.approx(T, rel=0.01)
    assert tip.max() == pytest.approx(2 * T, rel=0.1) and t[np.argmax(tip)] == pytest.approx(2.0, abs=0.1)
    assert np.trapz(reaction, t) / 4.0 == pytest.approx(-T, rel=0.02)
    assert np.abs(reaction[t < 0.8]).max() < 1e-3 * T  # the wave has not reached the clamp
    assert summary["pseudo_energy_rel_drift"] < 1e-12  # -F.u counted in the energy
    if MPI.COMM_WORLD.rank == 0:
        assert (pathlib.Path(tempdir) / "pulled" / "animation.gif").stat().st_size > 0


@pytest.mark.mpi
@pytest.mark.parametrize("d", [2, 3])
def test_a_block_falling_flat_on_a_plane_is_the_bar_impact(d, tempdir):
    """A unit square or cube (nu = 0, E = rho = c = 1) at 0.1 m/s onto a plane from a gap of 0.05:
    with nu = 0 the motion is the 1D bar's, contact on [0.5, 2.5] s at pressure rho c v = 0.1 Pa,
    then a rebound at 0.1 m/s; the obstacle pushes along its normal only. The lumped masses of the
    tetrahedra of a box differ from node to node, so the 3D block is only near the 1D motion: it
    leaves the plane at 2.61 s (dem-A on the same mesh: 2.55 s)."""
    up = [0.0] * (d - 1) + [1.0]
    mesh = ({"type": "rectangle", "p0": [0.0, 0.05], "p1": [1.0, 1.05], "n": [4, 20], "diagonal": "crossed"}
            if d == 2 else {"type": "box", "p0": [0.0, 0.0, 0.05], "p1": [1.0, 1.0, 1.05], "n": [2, 2, 20]})
    scene = {
        "name": "block-drop", "method": "fem-P1", "mesh": mesh,
        "material": {"E": 1.0, "nu": 0.0, "rho": 1.0},
        "obstacles": [{"point": [0.0] * d, "normal": [2.0 * c for c in up], "boundary": "ymin" if d == 2 else "zmin"}],
        "initial": {"velocity": [-0.1 * c for c in up]},
        "time": {"end": 3.0, "cfl": 0.5},
    }
    summary, data = _run(scene, tempdir, f"drop{d}")
    t, dt, normal = data["t"], summary["dt"], "xyz"[d - 1]
    contact = t[data["contact_pressure"] > 0]
    rel = 0.02 if d == 2 else 0.03
    assert abs(contact[0] - 0.5) <= 1.01 * dt, contact[0]
    assert abs(contact[-1] - 2.5) <= (5 * dt if d == 2 else 0.15), contact[-1]
    steady = (t > 0.7) & (t < 2.3)
    assert np.median(data["contact_pressure"][steady]) == pytest.approx(0.1, rel=rel)
    assert np.median(data[f"contact_force_obstacle0_{normal}"][steady]) == pytest.approx(0.1, rel=rel)  # area 1
    for c in "xyz"[: d - 1]:
        assert np.abs(data[f"contact_force_obstacle0_{c}"]).max() < 1e-12
    assert summary["contact_candidate_facets"] == (4 if d == 2 else 8)
    assert data["kinetic"][-1] == pytest.approx(0.005, rel=0.02)  # 1/2 m v^2 after the rebound


@pytest.mark.mpi
def test_an_initial_field_that_jumps_on_a_mesh_line_takes_its_value_at_the_nodes():
    """Billiard's initial velocity jumps on the frame's inner boundary, a line of mesh nodes: every
    node takes the value of the expression at its own coordinates, on any partition.
    Interpolation at pushed-forward reference vertices rounds differently in each cell, and gave
    billiard under fem-P1 an initial kinetic energy of 2.7313 J on one process, 2.9248 on two and
    3.0764 on three."""
    scene = scenes.load("billiard")
    mesh, _, _, _ = model.create_mesh(MPI.COMM_WORLD, scene["mesh"])
    field = lambda x: scenes.evaluate_field(scene["initial"]["velocity"], x[:2], 0.0, "initial.velocity")  # noqa: E731
    solver = FEMCentralDifference(mesh, 1e6, 0.3, 1.0, np.zeros(0, dtype=np.int32), dt=1e-5, initial_velocity=field)
    x = node_coordinates(solver.V)
    assert np.array_equal(solver.v.x.array.reshape(-1, 2), field(x.T).T)
    on_frame = np.isclose(x[: solver.V.dofmap.index_map.size_local], 10.0, rtol=0.0, atol=1e-9).any(axis=1)
    assert MPI.COMM_WORLD.allreduce(int(on_frame.sum())) > 50  # nodes on the jump
