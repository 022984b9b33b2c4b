"""Scenes, the runner and the command line: the output contract, bad input, MPI agreement."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import io, model, scenes, simulation
from dolfinx_dem.memm import InstabilityError

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")
SHORT = {"bar-wave": 0.5, "cantilever": 0.05, "block": 0.05, "bar-impact": 0.2, "bar-bounce": 0.25,
         "two-disks": 0.1, "billiard": 0.5}
#: Coarser meshes for the tests of the multi-body scenes.
COARSE = {"two-disks": {"mesh.h": 0.03}, "billiard": {"mesh.h": 0.25}}
SUMMARY_KEYS = {"scene", "method", "n_cells", "n_steps", "dt", "wall_time_s", "pseudo_energy_rel_drift", "stable"}


def _series(path):
    return np.genfromtxt(path, delimiter=",", names=True)


@pytest.mark.mpi
@pytest.mark.parametrize("name", sorted(SHORT))
def test_builtin_scene_output_contract(name, tempdir):
    scene = scenes.load(name, {"time.end": SHORT[name], **COARSE.get(name, {})})
    out = pathlib.Path(tempdir) / name
    summary = simulation.run(scene, out, MPI.COMM_WORLD, quiet=True)
    assert SUMMARY_KEYS <= set(summary)
    assert summary["stable"] and summary["pseudo_energy_rel_drift"] < 1e-12
    assert summary["n_steps"] * summary["dt"] == pytest.approx(SHORT[name], rel=1e-12)
    if MPI.COMM_WORLD.rank == 0:
        assert not (out / io.INCOMPLETE).exists()
        for f in ("summary.json", "series.csv", "solution.xdmf", "solution.h5", "final.png"):
            assert (out / f).stat().st_size > 0, f
        data = _series(out / "series.csv")
        assert data.dtype.names[:6] == model.SERIES_COLUMNS
        assert len(data) == summary["n_steps"] + 1
        assert json.loads((out / "summary.json").read_text())["n_cells"] == summary["n_cells"]
        xdmf = (out / "solution.xdmf").read_text()
        for field in ("displacement", "velocity", "von_mises"):
            assert f'Name="{field}"' in xdmf
        assert ('Name="body"' in xdmf) == (name in COARSE)  # body numbers with several bodies


def test_bar_wave_matches_the_exact_standing_wave(tempdir):
    """bar-wave is the first mode of a clamped-free bar: tip u = 0.01 cos(pi t / 2)."""
    scene = scenes.load("bar-wave", {"time.end": 4.0})
    summary = simulation.run(scene, pathlib.Path(tempdir) / "bar", MPI.COMM_WORLD, quiet=True)
    data = _series(pathlib.Path(tempdir) / "bar" / "series.csv")
    exact = 0.01 * np.cos(np.pi * data["t"] / 2)
    error = np.abs(data["tip_u"] - exact).max() / 0.01
    assert error < 2e-3, error  # N = 100; a wrong mass or stiffness scale shifts the period by O(1)
    assert summary["pseudo_energy_rel_drift"] < 1e-12


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("name", ["cantilever", "block", "bar-impact", "two-disks"])
def test_two_processes_give_the_same_series(name, tmp_path):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none")
    sets = [f"time.end={SHORT[name] * 4}"] + [f"{k}={v}" for k, v in COARSE.get(name, {}).items()]
    options = [x for s in sets for x in ("--set", s)]
    subprocess.run([CLI, "run", name, *options, "--out", str(tmp_path / "1"), "--quiet"], check=True, env=env)
    subprocess.run(["mpirun", "-n", "2", "--oversubscribe", CLI, "run", name, *options, "--out",
                    str(tmp_path / "2"), "--quiet"], check=True, env=env)
    a, b = _series(tmp_path / "1" / "series.csv"), _series(tmp_path / "2" / "series.csv")
    assert a.shape == b.shape
    energy = max(np.abs(a[c]).max() for c in ("kinetic", "elastic", "stabilisation"))
    for column in a.dtype.names:
        # Energies relative to the mechanical energy scale (the pseudo-energy of a body released
        # from rest is ~0, the stabilisation energy of a smooth field tiny), probes to their own.
        # Momenta of colliding bodies are ~0 (rounding): compare them to 1 kg m/s, the order
        # of the momentum of each disc of two-disks.
        scale = energy if column in model.SERIES_COLUMNS[1:] else np.abs(a[column]).max()
        if column.startswith("momentum_"):
            scale = max(scale, 1.0)
        assert np.abs(a[column] - b[column]).max() <= 1e-12 * scale, column
    assert json.loads((tmp_path / "2" / "summary.json").read_text())["processes"] == 2


def test_instability_stops_the_run_with_a_clear_error(tempdir):
    scene = scenes.load("bar-wave", {"time.cfl": 1.2, "time.end": 20.0})
    out = pathlib.Path(tempdir) / "unstable"
    with pytest.raises(InstabilityError, match=r"unstable at step \d+ .*dt = .*Reduce the time step"):
        simulation.run(scene, out, MPI.COMM_WORLD, quiet=True)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stable"] is False and summary["suggested_dt"] < summary["dt"]
    assert (out / io.INCOMPLETE).exists() and (out / io.ERROR).exists()
    assert np.all(np.isfinite(_series(out / "series.csv")["pseudo_energy"]))


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"mesh.foo": 1}, "'mesh.foo' is unknown"),
        ({"material.nu": 0.5}, "Poisson ratio nu"),
        ({"material.E": -1.0}, "Young.s modulus E must be > 0"),
        ({"initial.velocity": ["foo * x"]}, "unknown names \\[.foo.\\]"),
        ({"probes": [{"name": "p"}]}, "probes\\[0\\].point. is missing"),
        ({"time": {"end": 1.0, "dt": 0.03}}, "must be a multiple"),
        ({"material.rho": 0.0}, "density rho must be > 0"),
        ({"time.dt": -0.1}, "'time.dt' must be > 0"),
        ({"method": "dem-C"}, "'method' must be a string"),
        ({"mesh.n": "many"}, "'mesh.n' must be a list"),
        ({"initial.velocity": ["sin(x"]}, "not a valid expression"),
    ],
)
def test_bad_scene_values_are_rejected(overrides, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        scene = scenes.load("bar-wave", overrides)
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)


def test_both_dt_and_cfl_or_an_unknown_boundary_are_rejected(tmp_path):
    with pytest.raises(scenes.SceneError, match="exactly one of 'time.dt' and 'time.cfl'"):
        scenes.load("bar-wave", {"time.dt": 0.01})
    scene = scenes.load("cantilever", {"dirichlet": [{"boundary": "nowhere"}]})
    with pytest.raises(scenes.SceneError, match="unknown boundary 'nowhere'"):
        simulation.run(scene, tmp_path / "b", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "b").exists()  # checked before the output folder is made


@pytest.mark.skip_in_parallel
def test_cli(tmp_path):
    listing = subprocess.run([CLI, "list"], capture_output=True, text=True, check=True).stdout
    assert {"bar-wave", "cantilever", "block", "bar-impact", "bar-bounce"} <= {
        line.split()[0] for line in listing.splitlines()}

    missing = tmp_path / "scene.toml"
    missing.write_text('[mesh]\ntype = "file"\npath = "nope.msh"\n[material]\nE = 1.0\nnu = 0.3\n'
                       'rho = 1.0\n[time]\nend = 1.0\ndt = 0.1\n')
    r = subprocess.run([CLI, "run", str(missing), "--out", str(tmp_path / "m")], capture_output=True, text=True)
    assert r.returncode == 2 and "nope.msh" in r.stderr

    r = subprocess.run([CLI, "run", "no-such-scene"], capture_output=True, text=True)
    assert r.returncode == 2 and "unknown scene 'no-such-scene'" in r.stderr

    r = subprocess.run([CLI, "run", "bar-wave", "--set", "mesh.n=20", "--set", "time.end=0.2",
                        "--out", str(tmp_path / "ok")], capture_output=True, text=True, check=True)
    assert "results in" in r.stdout
    assert json.loads((tmp_path / "ok" / "summary.json").read_text())["n_cells"] == 20
    r = subprocess.run([CLI, "show", str(tmp_path / "ok")], capture_output=True, text=True, check=True)
    assert (tmp_path / "ok" / "energies.png").stat().st_size > 0
    assert (tmp_path / "ok" / "probes.png").stat().st_size > 0


@pytest.mark.parametrize(
    "obstacle, message",
    [
        ({"point": [6.0], "normal": [1.0], "boundary": "left"}, "intersects the body at t = 0"),
        ({"point": [0.0], "normal": [1.0], "boundary": "left", "tolerance": -1.0}, "must be >= 0"),
        ({"point": [0.0], "normal": [1.0]}, "'obstacles\\[0\\].boundary' is missing"),
        ({"point": [0.0], "normal": [1.0], "boundary": "nowhere"}, "unknown boundary 'nowhere'"),
    ],
)
def test_bad_obstacles_are_rejected_before_the_run(obstacle, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        scene = scenes.load("bar-impact", {"obstacles": [obstacle]})
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "bad" / "series.csv").exists()
