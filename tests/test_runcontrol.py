"""Stopping runs cleanly: SIGINT and SIGTERM on 1 and 2 processes, Ctrl-C on mpirun, kill -9, and
the progress lines.

A long bar-impact run (1D, 100 cells, ~1.5 ms a step) is started as a subprocess and signalled
once it has written some rows; the run must exit 130 with ``status: interrupted`` in its
summary, a checkpoint, and a solution.xdmf/.h5 pair that reads back (VTK's reader, and DOLFINx's
for the mesh) up to its last output time.
"""

import io
import json
import os
import re
import signal
import subprocess

import dolfinx.io
import numpy as np
import pytest
from helpers import CLI, children, mpi_env, read_solution, run_command, series_rows, wait_for
from mpi4py import MPI

from dolfinx_dem import cli, runcontrol

LONG_RUN = ["run", "bar-impact", "--set", "time.end=400.0", "--set", "output.every=20"]


def _check_interrupted(out, processes, signal_name):
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["processes"] == processes
    assert 100 <= summary["n_steps"] < 160000 and summary["t_end"] == pytest.approx(summary["n_steps"] * 0.0025)
    assert (out / "INCOMPLETE").read_text().startswith(f"interrupted by {signal_name} at step {summary['n_steps']}")
    assert (out / "checkpoint" / "checkpoint.json").is_file()
    assert json.loads((out / "checkpoint" / "checkpoint.json").read_text())["step"] == summary["n_steps"]
    assert series_rows(out / "series.csv") == summary["n_steps"] + 1  # every row flushed, none lost
    times, data = read_solution(out / "solution.xdmf")
    assert times == pytest.approx(0.05 * np.arange(len(times))) and len(times) == summary["n_steps"] // 20 + 1
    assert all(len(d) == 100 and np.isfinite(d).all() for d in data)  # (a 1D vector has one component)
    with dolfinx.io.XDMFFile(MPI.COMM_SELF, str(out / "solution.xdmf"), "r") as xdmf:
        assert xdmf.read_mesh(name="mesh").topology.index_map(1).size_global == 100
    assert not [p.name for p in (out / "solution").iterdir() if p.name.startswith(".")]  # no write in progress
    return summary


@pytest.mark.slow
@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_a_serial_run_cleanly(signum, tmp_path):
    """The run imports gmsh (meshes.py), which resets SIGINT to its default action: before,
    Ctrl-C killed the process at once (rc -2) and left a corrupt solution.h5."""
    out = tmp_path / "run"
    process = subprocess.Popen([CLI, *LONG_RUN, "--out", str(out)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=mpi_env())
    wait_for(lambda: series_rows(out / "series.csv") >= 120 or process.poll() is not None, what="100 rows")
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    summary = _check_interrupted(out, 1, signal.Signals(signum).name)
    assert f"continue with: dolfinx-dem resume {out}" in stderr and "(interrupted)" in stdout
    shown = run_command([CLI, "show", str(out)], capture_output=True, text=True, check=True).stdout
    assert shown.startswith(f"INTERRUPTED: the run stopped at step {summary['n_steps']}")


@pytest.mark.slow
@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_to_the_processes_stops_an_mpi_run_cleanly(signum, tmp_path):
    """As a batch system does (SLURM's scancel signals every task): every process stops after
    the same step and exits 130, and so does mpirun."""
    out = tmp_path / "run"
    process = subprocess.Popen(["mpirun", "-n", "2", "--oversubscribe", CLI, *LONG_RUN, "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=mpi_env())
    wait_for(lambda: series_rows(out / "series.csv") >= 120 or process.poll() is not None, what="100 rows")
    ranks = children(process.pid)
    assert len(ranks) == 2
    for pid in ranks:
        os.kill(pid, signum)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    _check_interrupted(out, 2, signal.Signals(signum).name)


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_ctrl_c_on_mpirun_writes_the_checkpoint(tmp_path):
    """mpirun answers SIGINT with SIGCONT, then SIGTERM to the processes, then SIGKILL, and exits 1
    itself. Open MPI 4 waits one second before each (odls_base_sigkill_timeout): the processes
    stop cleanly on the SIGTERM within it. Open MPI 5.0.7 waits 0.25 s, which no setting changed
    (docs/scenes.md): the processes stop cleanly in it when the machine keeps up (checkpoint on
    disk 0.03-0.15 s after the SIGTERM, measured), but a stalled disk or CPU can outlast it; the
    run then keeps what a killed run keeps (every listed output time readable, no checkpoint
    claimed that is not complete)."""
    out = tmp_path / "run"
    process = subprocess.Popen(["mpirun", "-n", "2", "--oversubscribe", CLI, *LONG_RUN, "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=mpi_env())
    wait_for(lambda: series_rows(out / "series.csv") >= 120 or process.poll() is not None, what="100 rows")
    process.send_signal(signal.SIGINT)
    process.communicate(timeout=120)
    assert process.returncode == 1  # mpirun's own status after SIGINT, whatever the processes return
    version = run_command(["mpirun", "--version"], capture_output=True, text=True, check=True).stdout
    if int(re.search(r"Open MPI\)? (\d+)\.", version).group(1)) < 5 or (out / "summary.json").is_file():
        _check_interrupted(out, 2, "SIGTERM")
        return
    assert (out / "INCOMPLETE").is_file() and not (out / "checkpoint" / "checkpoint.json").exists()
    times, data = read_solution(out / "solution.xdmf")  # killed: what a killed run keeps
    assert len(times) >= 120 // 20 and all(len(d) == 100 and np.isfinite(d).all() for d in data)


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_a_killed_run_reads_back_up_to_its_last_output(tmp_path):
    """kill -9: no handler runs. Before, solution.h5 failed to open (H5Fopen: incorrect metadata
    checksum) and, with frequent outputs, solution.xdmf could be empty (DOLFINx rewrites it in
    place at every write). Outputs every 5 steps make a kill during a write likely."""
    out = tmp_path / "run"
    process = subprocess.Popen([CLI, "run", "cantilever", "--set", "output.every=5", "--out", str(out), "--quiet"],
                               env=mpi_env())
    wait_for(lambda: series_rows(out / "series.csv") >= 400 or process.poll() is not None, what="400 rows")
    process.kill()
    process.wait(timeout=60)
    assert process.returncode == -signal.SIGKILL
    times, data = read_solution(out / "solution.xdmf")
    assert len(times) >= 400 // 5 - 10 and times == sorted(times)
    assert all(d.shape == (640, 3) and np.isfinite(d).all() for d in data)
    velocity = read_solution(out / "solution.xdmf", "velocity")[1]
    assert len(velocity) == len(times)
    with dolfinx.io.XDMFFile(MPI.COMM_SELF, str(out / "solution.xdmf"), "r") as xdmf:
        assert xdmf.read_mesh(name="mesh").topology.index_map(2).size_global == 640
    shown = run_command([CLI, "show", str(out)], capture_output=True, text=True, check=True).stdout
    assert shown.startswith("INCOMPLETE: this run did not finish (it is still running, or was killed)")


# -- the pieces -------------------------------------------------------------------------------------

def test_interrupts_win_over_a_library_that_resets_the_handler():
    """``import gmsh`` sets SIGINT to SIG_DFL; the run's handler is put back at the next check
    (here every step: interval 0), and the handlers found on entry are restored on exit."""
    before = [signal.getsignal(s) for s in runcontrol.SIGNALS]
    with runcontrol.Interrupts(MPI.COMM_SELF, interval=0.0) as interrupts:
        assert not interrupts.requested()
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # what gmsh.py does at import
        assert not interrupts.requested()
        os.kill(os.getpid(), signal.SIGINT)  # would kill the process with SIG_DFL
        assert interrupts.requested() and interrupts.name == "SIGINT"
        with pytest.raises(KeyboardInterrupt, match="second signal SIGTERM"):
            os.kill(os.getpid(), signal.SIGTERM)
    assert [signal.getsignal(s) for s in runcontrol.SIGNALS] == before


@pytest.mark.mpi
@pytest.mark.parametrize("interval", [0.0, 60.0])
def test_every_process_stops_after_the_same_step(interval):
    """One process is signalled after step 5; all stop after the same step. With checks at
    every step (interval 0): at the next check, one later under MPI (the reduction is
    non-blocking). With checks far apart in time (60 s) the steps between checks double, so
    the stop comes later, but at the same step everywhere (rank 0's count, agreed)."""
    comm = MPI.COMM_WORLD
    answers = []
    with runcontrol.Interrupts(comm, interval) as interrupts:
        for step in range(40):
            if step == 5 and comm.rank == comm.size - 1:
                os.kill(os.getpid(), signal.SIGTERM)
            answers.append(interrupts.requested())
    first = answers.index(True)
    if interval == 0.0:
        assert first == (5 if comm.size == 1 else 6)
    else:
        assert 5 <= first <= 4 * 6
    assert comm.allgather(first) == [first] * comm.size


@pytest.mark.mpi
def test_a_check_after_an_output_time_agrees_at_once():
    """``requested(now=True)`` (after a step that wrote an output time, on every process) checks at
    that call, whatever the count, and agrees at once: with checks 60 s apart (after step 30 the
    next is at step 62), the signal received at step 31 stops every process at the output step 33."""
    comm = MPI.COMM_WORLD
    answers = []
    with runcontrol.Interrupts(comm, 60.0) as interrupts:
        for step in range(40):
            if step == 31 and comm.rank == comm.size - 1:
                os.kill(os.getpid(), signal.SIGTERM)
            answers.append(interrupts.requested(now=step == 33))
            if answers[-1]:
                break
    assert answers.index(True) == 33 and comm.allgather(len(answers)) == [34] * comm.size


class _Stream(io.StringIO):
    def __init__(self, tty):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


def test_progress_lines_without_a_terminal():
    stream = _Stream(tty=False)
    progress = runcontrol.Progress(MPI.COMM_SELF, 100, quiet=False, interval=0.0, stream=stream)
    progress.update(10, 0.25, 1e-15)
    progress.update(20, 0.5, 2e-15, conservative=False)
    progress.finish()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2 and "\r" not in stream.getvalue()
    assert lines[0].startswith("step 10/100  t = 0.25  energy drift 1.00e-15  ") and lines[0].endswith(" s left")
    assert "energy balance 2.00e-15 (work counted)" in lines[1]
    quiet = _Stream(tty=False)
    runcontrol.Progress(MPI.COMM_SELF, 100, quiet=True, interval=0.0, stream=quiet).update(10, 0.25, 0.0)
    assert quiet.getvalue() == ""
    terminal = _Stream(tty=True)
    progress = runcontrol.Progress(MPI.COMM_SELF, 100, quiet=False, stream=terminal)
    progress.update(100, 2.5, 0.0)
    progress.finish()
    assert terminal.getvalue().startswith("\rstep 100/100") and terminal.getvalue().count("\n") == 1


def test_the_summary_line_says_when_a_scene_is_not_conservative():
    summary = {"scene": "s", "status": "completed", "n_steps": 10, "dt": 0.1, "n_cells": 4, "wall_time_s": 1.0,
               "pseudo_energy_rel_drift": 1.0, "conservative": False}
    assert cli.summary_line(summary).endswith(
        "not conservative (time-dependent data): energy balance error (work counted) 1.00e+00")
    line = cli.summary_line(summary | {"conservative": True, "status": "interrupted", "pseudo_energy_rel_drift": 1e-15})
    assert line.startswith("s (interrupted): 10 steps") and line.endswith("pseudo-energy drift 1.00e-15")
