"""What a killed run keeps: SIGKILL at random moments (validation/kill_loop.py, whose docstring
lists the checks made after every kill), and kill -9 at chosen points of a checkpoint.

The random kills: 20 on one process here, 10 on two and 10 on three in the slow lane;
``validation/kill_loop.py --processes 1 2 3 --kills 140 30 30`` makes 200
(docs/validation/kill_loop.json).
"""

import json
import pathlib
import re
import signal
import subprocess
import sys
import time

import pytest
from helpers import CLI, import_script, mpi_env, run_command

from dolfinx_dem import cli

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCENE = ["bar-impact", "--set", "time.end=0.6", "--set", "output.every=4", "--checkpoint-every", "50", "--quiet"]


def _kill_loop(tmp_path, processes, kills):
    out = tmp_path / "kills.json"
    proc = run_command([sys.executable, str(ROOT / "validation" / "kill_loop.py"), "--processes", *processes,
                           "--kills", *kills, "--work", str(tmp_path), "--out", str(out)],
                          capture_output=True, text=True, timeout=800, env=mpi_env(PYVISTA_OFF_SCREEN="true"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(out.read_text())


@pytest.mark.skip_in_parallel
def test_random_kills_keep_every_listed_output_time_and_resume_bit_identical(tmp_path):
    assert _kill_loop(tmp_path, ["1"], ["20"])["total"]["kills"] == 20


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_random_kills_on_two_and_three_processes(tmp_path):
    counts = _kill_loop(tmp_path, ["2", "3"], ["10", "10"])
    assert counts["processes"]["2"]["kills"] == 10 and counts["processes"]["3"]["kills"] == 10


#: a stand-in for mpirun: starts three "ranks" (sleeping processes), then never exits by itself
HANGING_MPIRUN = """
import subprocess, sys, time
ranks = [subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"]) for _ in range(3)]
print("started", flush=True)
time.sleep(600)
"""


def test_the_kill_loop_kills_an_mpirun_that_hangs_after_its_ranks(monkeypatch):
    """kill_loop.kill SIGKILLs every rank, and an mpirun still there MPIRUN_EXIT_LIMIT after them
    (Open MPI 4.1.4 did not return once in CI) is killed and reported, not waited on forever."""
    kill_loop = import_script(ROOT / "validation" / "kill_loop.py", monkeypatch)
    monkeypatch.setattr(kill_loop, "MPIRUN_EXIT_LIMIT", 1)
    process = subprocess.Popen([sys.executable, "-c", HANGING_MPIRUN], stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline() == "started\n"
    ranks = kill_loop.children(process.pid)
    assert len(ranks) == 3 and all(map(kill_loop.alive, ranks))
    start = time.monotonic()
    assert kill_loop.kill(process, 3)
    assert process.returncode == -signal.SIGKILL and time.monotonic() - start < 30
    assert not any(map(kill_loop.alive, ranks))


#: a run that SIGKILLs one of its processes at the ``at``-th call of ``checkpoint.<function>``
#: there: ``_save`` writes one file of a process, ``fsync`` is rank 0's first step of the commit
#: (all data written, header not yet) and its third the one after the header's rename
KILLER = """
import os, signal, sys
from mpi4py import MPI
from dolfinx_dem import checkpoint, cli
function, at, rank = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
original, calls = getattr(checkpoint, function), [0]
def killing(*args):
    calls[0] += 1
    if calls[0] == at and MPI.COMM_WORLD.rank == rank:
        os.kill(os.getpid(), signal.SIGKILL)
    return original(*args)
setattr(checkpoint, function, killing)
sys.exit(cli.main(sys.argv[4:]))
"""


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("processes, function, at, rank, kept", [
    (1, "_save", 6, 0, 100),  # the 3rd checkpoint (step 150) half written: cells, not local
    (1, "fsync", 7, 0, 100),  # its data written, the header not yet
    pytest.param(1, "fsync", 9, 0, 150, marks=pytest.mark.slow),  # its header in place, the previous data not
    # yet removed
    pytest.param(2, "_save", 6, 1, 100, marks=pytest.mark.slow),  # process 1 killed after writing its cells
    # (then mpirun kills process 0)
])
def test_a_kill_during_a_checkpoint_keeps_the_previous_one(processes, function, at, rank, kept, tmp_path):
    """kill -9 inside checkpoint.write (checkpoints every 50 steps): the last complete checkpoint
    is in force, and the resumed run's series.csv is the uninterrupted run's, byte for byte."""
    out = tmp_path / "killed"
    mpirun = ["mpirun", "-n", str(processes), "--oversubscribe"] if processes > 1 else []
    killed = run_command([*mpirun, sys.executable, "-c", KILLER, function, str(at), str(rank), "run", *SCENE,
                             "--out", str(out)], env=mpi_env(), capture_output=True, text=True, timeout=300)
    assert killed.returncode != 0
    header = json.loads((out / "checkpoint" / "checkpoint.json").read_text())
    assert header["step"] == kept
    assert len([p for p in (out / "checkpoint").iterdir() if p.is_dir()]) == 2  # the kill's leftover beside it
    run_command([*mpirun, CLI, "resume", str(out), "--quiet"], env=mpi_env(), check=True)
    assert [p.name for p in (out / "checkpoint").iterdir() if p.is_dir()] == [
        json.loads((out / "checkpoint" / "checkpoint.json").read_text())["data"]]  # the leftover removed
    full = tmp_path / "full"
    run_command([*mpirun, CLI, "run", *SCENE, "--out", str(full)], env=mpi_env(), check=True)
    assert (out / "series.csv").read_bytes() == (full / "series.csv").read_bytes()
    times = [re.findall(r'<Time Value="([^"]+)"', (folder / "solution.xdmf").read_text()) for folder in (out, full)]
    assert times[0] == times[1] and len(set(times[0])) == 61


@pytest.mark.skip_in_parallel
def test_a_run_killed_after_its_last_step_is_finished_by_resume(tmp_path):
    """Killed during its pictures (mpirun's SIGKILL a second after Ctrl-C, say): the checkpoint is
    at time.end and INCOMPLETE is there; resume writes the summary and pictures without a step."""
    out = tmp_path / "run"
    assert cli.main(["run", "bar-wave", "--set", "time.end=0.05", "--out", str(out), "--quiet"]) == 0
    series, xdmf = (out / "series.csv").read_bytes(), (out / "solution.xdmf").read_text()
    for name in ("summary.json", "final.png"):
        (out / name).unlink()
    (out / "INCOMPLETE").write_text("dolfinx_dem run in progress or failed\n")
    assert cli.main(["resume", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["resumes"] == 1 and (out / "final.png").exists()
    assert not (out / "INCOMPLETE").exists()
    assert (out / "series.csv").read_bytes() == series and (out / "solution.xdmf").read_text() == xdmf
