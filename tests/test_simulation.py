"""Scenes, the runner and the command line: the output contract, bad input, MPI agreement."""

import json
import os
import pathlib
import sys

import numpy as np
import pytest
from helpers import run_command
from mpi4py import MPI

from dolfinx_dem import io, model, scenes, simulation

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")
SHORT = {"bar-wave": 0.5, "cantilever": 0.05, "block": 0.05, "bar-impact": 0.2, "bar-bounce": 0.25,
         "two-disks": 0.1, "billiard": 0.5, "two-balls": 0.05, "cradle": 0.05, "ball-drop": 0.05}
#: Coarser meshes for the tests of the multi-body scenes.
COARSE = {"two-disks": {"mesh.h": 0.03}, "billiard": {"mesh.h": 0.25}, "two-balls": {"mesh.h": 0.06},
          "cradle": {"mesh.h": 0.08}, "ball-drop": {"mesh.h": 0.07}}
SUMMARY_KEYS = {"scene", "method", "n_cells", "n_steps", "dt", "wall_time_s", "pseudo_energy_rel_drift", "stable"}


def _series(path):
    return np.genfromtxt(path, delimiter=",", names=True)


@pytest.mark.slow
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
        assert {p.name for p in out.iterdir()} <= set(io.RUN_FILES)  # what --overwrite removes
        assert summary["status"] == "completed" and (out / "checkpoint" / "checkpoint.json").is_file()
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


@pytest.mark.slow
@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("name", ["cantilever", "block", "bar-impact", "two-disks"])
def test_two_processes_give_the_same_series(name, tmp_path):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none")
    sets = [f"time.end={SHORT[name] * 4}"] + [f"{k}={v}" for k, v in COARSE.get(name, {}).items()]
    options = [x for s in sets for x in ("--set", s)]
    run_command([CLI, "run", name, *options, "--out", str(tmp_path / "1"), "--quiet"], check=True, env=env)
    run_command(["mpirun", "-n", "2", "--oversubscribe", CLI, "run", name, *options, "--out",
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
        if column.startswith("reaction_"):  # to the largest reaction component (one can be pure rounding)
            scale = max(np.abs(a[c]).max() for c in a.dtype.names if c.startswith("reaction_"))
        if column.startswith("momentum_"):
            scale = max(scale, 1.0)
        assert np.abs(a[column] - b[column]).max() <= 1e-12 * scale, column
    assert json.loads((tmp_path / "2" / "summary.json").read_text())["processes"] == 2


# -- the output folder, and the command line around a run ----------------------------------------

@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_the_first_form_compilation_prints_no_compiler_output(tmp_path):
    """A fresh JIT cache (HOME) makes DOLFINx compile its forms (the FEM reference's; DOLFINx 0.5
    also compiles the DEM's DG0 elements), which printed pages of ``INFO:root:running build_ext``
    and gcc command lines."""
    env = dict(os.environ, HOME=str(tmp_path / "home"))
    r = run_command([CLI, "run", "hertz", "--set", 'method="fem-P2"', "--set", "mesh.h=0.02", "--out",
                        str(tmp_path / "out")], capture_output=True, text=True, env=env, check=True)
    assert list((tmp_path / "home" / ".cache" / "fenics").iterdir())  # it did compile
    assert r.stderr == "", r.stderr[:500]
    assert r.stdout.startswith("hertz (fem-P2, static)")

