"""Checkpoint and resume: a stopped run, resumed, writes the series the uninterrupted run writes.

For a plain scene (cantilever), a rigid-contact scene (bar-impact, stopped during the impact)
and a pair-contact scene (two-disks, stopped while the discs touch):

- on the same number of processes (1, 2, 3 under ``make test``): bit-identical ``series.csv``,
  the same summary figures and XDMF output times, through a crash after a periodic checkpoint
  (the outputs written after it are dropped), an interrupt, and two resumes;
- on another number of processes (1 -> 2, 2 -> 1): within 1e-12 of the energy scale;
- after ``kill -9``: bit-identical again.

Stops are made deterministic by replacing ``Interrupts.requested`` (signals themselves are
tested in test_runcontrol.py).
"""

import json
import os
import pathlib
import re
import signal
import subprocess

import numpy as np
import pytest
from helpers import CLI, children, mpi_env, run_command, series_rows, stop_after, wait_for
from mpi4py import MPI

from dolfinx_dem import checkpoint, cli, io, model, scenes, simulation

#: scene -> (overrides, number of steps)
SCENES = {
    "cantilever": ({"time": {"end": 0.02, "dt": 1e-4}}, 200),
    "bar-impact": ({"time.end": 0.6}, 240),  # contact from step 200
    "two-disks": ({"mesh.h": 0.03, "time": {"end": 0.15, "dt": 0.0025}}, 60),  # contact from step 14
}
#: summary keys that differ between an interrupted-and-resumed run and an uninterrupted one (costs;
#: a resumed run's contact model exchanges facets between processes at its first step)
TIMINGS = {"wall_time_s", "setup_time_s", "peak_rss_mb", "resumes", "contact_seconds", "contact_output_seconds",
           "contact_fraction", "contact_exchanges"}


def xdmf_times(path):
    text = pathlib.Path(path).read_text()
    return [float(t) for t in re.findall(r'<Time Value="([^"]+)"', text)]


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.parametrize("name", sorted(SCENES))
def test_a_stopped_run_resumes_bit_identical(name, tempdir, monkeypatch):
    comm = MPI.COMM_WORLD
    overrides, n = SCENES[name]
    scene = scenes.load(name, overrides)
    full = simulation.run(scene, tempdir / "full", comm, quiet=True)
    every = n // 5
    crash, interrupt = int(0.35 * n), int(0.7 * n)  # the last checkpoint before the crash: `every`

    parts = tempdir / "parts"
    stop_after(monkeypatch, crash, crash=True)
    with pytest.raises(RuntimeError, match="crash after step"):
        simulation.run(scene, parts, comm, quiet=True, checkpoint_every=every)
    comm.barrier()  # a failing run makes no collective call on its way out: rank 0 may still be closing
    assert (parts / "INCOMPLETE").exists() and series_rows(parts / "series.csv") == crash + 1
    assert json.loads((parts / "checkpoint" / "checkpoint.json").read_text())["step"] == every

    stop_after(monkeypatch, interrupt, first=every)
    first = simulation.resume(parts, comm, quiet=True)
    assert first["status"] == "interrupted" and first["n_steps"] == interrupt and first["resumes"] == 1
    assert (parts / "INCOMPLETE").exists() and not (parts / "error.txt").exists()

    monkeypatch.undo()
    last = simulation.resume(parts, comm, quiet=True)
    assert last["status"] == "completed" and last["resumes"] == 2 and not (parts / "INCOMPLETE").exists()
    assert {k: v for k, v in last.items() if k not in TIMINGS} == {k: v for k, v in full.items() if k not in TIMINGS}
    comm.barrier()
    if comm.rank == 0:
        assert (parts / "series.csv").read_bytes() == (tempdir / "full" / "series.csv").read_bytes()
        assert xdmf_times(parts / "solution.xdmf") == xdmf_times(tempdir / "full" / "solution.xdmf")
        assert sorted(p.name for p in parts.iterdir()) == sorted(p.name for p in (tempdir / "full").iterdir())


def _close(a: np.ndarray, b: np.ndarray):
    """Columns of two series agree to 1e-12 of the scale: energies to the largest mechanical
    energy, momenta to max(their largest value, 1 kg m/s), reactions to the largest reaction
    component, others to their largest value."""
    assert a.shape == b.shape
    energy = max(np.abs(a[c]).max() for c in ("kinetic", "elastic", "stabilisation"))
    reactions = [c for c in a.dtype.names if c.startswith("reaction_")]
    reaction = max((np.abs(a[c]).max() for c in reactions), default=0.0)
    for column in a.dtype.names:
        scale = energy if column in model.SERIES_COLUMNS[1:] else np.abs(a[column]).max()
        if column in reactions:
            scale = reaction
        if column.startswith("momentum_"):
            scale = max(scale, 1.0)
        assert np.abs(a[column] - b[column]).max() <= 1e-12 * scale, column


def _series(path):
    return np.genfromtxt(path, delimiter=",", names=True)


@pytest.mark.slow
@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("name", sorted(SCENES))
def test_a_run_stopped_on_one_process_resumes_on_two(name, tmp_path, monkeypatch):
    overrides, n = SCENES[name]
    scene = scenes.load(name, overrides)
    simulation.run(scene, tmp_path / "full", MPI.COMM_SELF, quiet=True)
    stop_after(monkeypatch, n // 2)
    assert simulation.run(scene, tmp_path / "parts", MPI.COMM_SELF, quiet=True)["status"] == "interrupted"
    run_command(["mpirun", "-n", "2", "--oversubscribe", CLI, "resume", str(tmp_path / "parts"), "--quiet"],
                   check=True, env=mpi_env())
    _close(_series(tmp_path / "full" / "series.csv"), _series(tmp_path / "parts" / "series.csv"))
    assert json.loads((tmp_path / "parts" / "summary.json").read_text())["processes"] == 2


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_a_run_stopped_on_two_processes_resumes_on_one(tmp_path):
    """SIGTERM to both processes at some step of a 1200-step bar-impact run, resumed serially."""
    args = ["run", "bar-impact", "--set", "time.end=3.0", "--quiet"]
    process = subprocess.Popen(["mpirun", "-n", "2", "--oversubscribe", CLI, *args, "--out", str(tmp_path / "parts")],
                               env=mpi_env())
    wait_for(lambda: series_rows(tmp_path / "parts" / "series.csv") >= 50 or process.poll() is not None)
    for pid in children(process.pid):
        os.kill(pid, signal.SIGTERM)
    assert process.wait(timeout=120) == 130
    stopped = json.loads((tmp_path / "parts" / "summary.json").read_text())["n_steps"]
    assert 50 <= stopped < 1200
    run_command([CLI, "resume", str(tmp_path / "parts"), "--quiet"], check=True, env=mpi_env())
    run_command([CLI, *args, "--out", str(tmp_path / "full")], check=True, env=mpi_env())
    _close(_series(tmp_path / "full" / "series.csv"), _series(tmp_path / "parts" / "series.csv"))


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_a_killed_run_resumes_from_its_last_checkpoint_bit_identical(tmp_path):
    """kill -9 after some checkpoints: the rows and output times written after the last one
    are dropped and written again, to a later time.end than the checkpoint's."""
    out = tmp_path / "parts"
    sets = ["--set", "output.every=10"]
    process = subprocess.Popen([CLI, "run", "bar-impact", "--set", "time.end=100.0", *sets, "--checkpoint-every",
                                "50", "--out", str(out), "--quiet"], env=mpi_env())
    header = out / "checkpoint" / "checkpoint.json"

    def between_checkpoints():  # rows on disk well past the last checkpoint (series flushes every 10 rows)
        try:
            step = json.loads(header.read_text())["step"]
        except (FileNotFoundError, json.JSONDecodeError):
            return False
        return step >= 100 and series_rows(out / "series.csv") >= step + 21

    wait_for(lambda: between_checkpoints() or process.poll() is not None)
    process.kill()
    assert process.wait(timeout=60) == -signal.SIGKILL
    step = json.loads(header.read_text())["step"]
    rows = series_rows(out / "series.csv")
    assert step % 50 == 0 and rows >= step + 1  # (usually rows after the checkpoint, to be dropped)
    end = f"time.end={(rows + 40) * 0.0025!r}"  # past the rows the killed run wrote
    run_command([CLI, "resume", str(out), "--set", end, "--quiet"], check=True, env=mpi_env())
    run_command([CLI, "run", "bar-impact", "--set", end, *sets, "--out", str(tmp_path / "full"), "--quiet"],
                   check=True, env=mpi_env())
    assert (out / "series.csv").read_bytes() == (tmp_path / "full" / "series.csv").read_bytes()
    assert xdmf_times(out / "solution.xdmf") == xdmf_times(tmp_path / "full" / "solution.xdmf")
    assert not (out / "INCOMPLETE").exists() and not (out / "solution.xdmf.tmp").exists()


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_the_checkpoint_format(tmp_path):
    scene = scenes.load("two-disks", {"mesh.h": 0.03, "time": {"end": 0.05, "dt": 0.0025}})
    summary = simulation.run(scene, tmp_path / "run", MPI.COMM_SELF, quiet=True)
    assert summary["checkpoint"] == "checkpoint"
    root = tmp_path / "run" / "checkpoint"
    header = json.loads((root / "checkpoint.json").read_text())
    assert header["format"] == checkpoint.FORMAT and header["version"] == checkpoint.package_version()
    assert header["scene_hash"] == checkpoint.scene_hash(scene) and header["scene"] == scene
    assert header["step"] == 20 and header["t"] == 0.05 and header["processes"] == 1
    assert header["series_bytes"] == (tmp_path / "run" / "series.csv").stat().st_size
    assert [p.name for p in root.iterdir() if p.is_dir()] == [header["data"]]  # older data removed
    with np.load(root / header["data"] / "cells-0.npz") as cells:
        assert sorted(cells) == ["centre", "key", "u", "v_next", "v_prev"]
        assert sorted(cells["key"]) == list(range(summary["n_cells"])) and cells["u"].shape == (summary["n_cells"], 2)
    with np.load(root / header["data"] / "local-0.npz") as local:
        assert {"y", "z", "means", "contact0_scheme_b_rule", "contact0_counters"} <= set(local)
    # the hash ignores time.end, nothing else
    assert checkpoint.scene_hash(scenes.override(scene, {"time.end": 1.0})) == header["scene_hash"]
    assert checkpoint.scene_hash(scenes.override(scene, {"material.E": 101.0})) != header["scene_hash"]


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_resume_errors_name_the_problem(tmp_path, capsys):
    """Every refusal of ``resume``, through the command line: exit 2, one clear line, and
    nothing written."""
    out = tmp_path / "run"
    simulation.run(scenes.load("bar-wave", {"time.end": 0.05}), out, MPI.COMM_SELF, quiet=True)  # time.cfl
    stored = json.loads((out / "checkpoint" / "checkpoint.json").read_text())
    dt, steps = stored["dt"], stored["step"]
    assert steps == round(0.05 / dt) >= 10
    (tmp_path / "empty").mkdir()

    def refused(args, message):
        before = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
        assert cli.main(["resume", *args, "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("dolfinx-dem: error: ") and message in err, err
        assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == before

    refused([str(tmp_path / "empty")], f"{tmp_path / 'empty'} has no checkpoint")
    refused([str(out), "--set", "material.E=1000"],
            "the scene differs from the checkpoint's in material.E: a resumed run may only change time.end")
    refused([str(out), "--set", "time.end=0.051"],
            f"time.end = 0.051 is not a multiple of the run's time step dt = {dt!r}")
    refused([str(out), "--set", "time.end=0.05"],
            f"the checkpoint is at step {steps} (t = 0.05), not before time.end = 0.05")
    refused([str(out), "--set", "time.quadrature=gauss-legendre-2"], "the scene differs from the checkpoint's in "
            "time.quadrature")
    refused([str(out), "--set", "time.cfl=0.25"], "the scene differs from the checkpoint's in time.cfl")

    header = out / "checkpoint" / "checkpoint.json"
    data = json.loads(header.read_text())
    cells = out / "checkpoint" / data["data"] / "cells-0.npz"
    with np.load(cells) as f:
        arrays = dict(f)
    np.savez(cells, **(arrays | {"centre": arrays["centre"] + 1e-3}))
    refused([str(out), "--set", "time.end=0.1"], "it belongs to another mesh")
    header.write_text(json.dumps(data | {"format": 99}))
    refused([str(out), "--set", "time.end=0.1"], "has checkpoint format 99; this dolfinx-dem")


@pytest.mark.skip_in_parallel
def test_an_unstable_run_has_no_checkpoint_and_a_static_run_cannot_resume(tmp_path, capsys):
    with pytest.raises(Exception, match="unstable"):
        simulation.run(scenes.load("bar-wave", {"time.cfl": 1.2, "time.end": 20.0}), tmp_path / "u", MPI.COMM_SELF,
                       quiet=True)
    assert not (tmp_path / "u" / "checkpoint").exists()
    summary = json.loads((tmp_path / "u" / "summary.json").read_text())
    assert summary["status"] == "unstable"
    assert cli.run_state(tmp_path / "u", summary).startswith(
        "UNSTABLE: the stability monitor stopped the run: MEMM is unstable at step")
    assert cli.main(["run", "hertz", "--checkpoint-every", "5", "--out", str(tmp_path / "h"), "--quiet"]) == 2
    assert "a static scene has no time steps to checkpoint" in capsys.readouterr().err
    assert not (tmp_path / "h").exists()
    with pytest.raises(SystemExit, match="2"):
        cli.main(["run", "bar-wave", "--checkpoint-every", "0", "--quiet"])
    with pytest.raises(checkpoint.CheckpointError, match="has no checkpoint"):
        simulation.resume(tmp_path / "u", MPI.COMM_SELF)
    assert io.INCOMPLETE in {p.name for p in (tmp_path / "u").iterdir()}


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_resume_refuses_a_changed_mesh_file(tmp_path, capsys):
    """A scene of mesh type "file" is hashed with the file's content."""
    import dolfinx.io

    from dolfinx_dem import meshes

    def write_mesh(n):
        mesh, _, _ = meshes.create_rectangle(MPI.COMM_SELF, [0.0, 0.0], [1.0, 0.1], [n, 2])
        with dolfinx.io.XDMFFile(MPI.COMM_SELF, str(tmp_path / "beam.xdmf"), "w") as f:
            f.write_mesh(mesh)

    write_mesh(10)
    (tmp_path / "beam.toml").write_text(
        '[mesh]\ntype = "file"\npath = "beam.xdmf"\n[material]\nE = 1000.0\nnu = 0.3\nrho = 1.0\n'
        '[[dirichlet]]\nboundary = "x <= 0.0"\n[loads]\nbody_force = [0.0, -0.1]\n[time]\nend = 0.01\ndt = 0.001\n')
    assert cli.main(["run", str(tmp_path / "beam.toml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert cli.main(["resume", str(tmp_path / "out"), "--set", "time.end=0.02", "--quiet"]) == 0
    write_mesh(12)
    assert cli.main(["resume", str(tmp_path / "out"), "--set", "time.end=0.03", "--quiet"]) == 2
    assert ("the scene differs from the checkpoint's in mesh.path (the mesh file's content)"
            in capsys.readouterr().err)
