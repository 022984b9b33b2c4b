"""What a killed run keeps: runs killed with SIGKILL at random moments, again and again, and resumed.

A small fast scene (bar-impact to t = 0.6: 240 steps of ~1.5 ms, 100 cells) writes an output time
every 2 steps (121 in all) and a checkpoint every 4 steps. An attempt (``run``, then ``resume``
after each kill) is killed at a random delay (uniform, up to ``--max-delay``) after it began
writing (its ``solution.xdmf`` replaced), on 1, 2 or 3 processes (every process at once under
mpirun): during a step, an output time, a checkpoint, a resume's start or the run's end. After
every kill:

- every output time listed in ``solution.xdmf`` reads back (VTK's reader, as ParaView) and its
  fields equal, bit for bit, those of the uninterrupted run at that time;
- ``series.csv`` up to the checkpoint's position is the uninterrupted run's, byte for byte.

An attempt that ends before its kill must exit 0 with the uninterrupted run's ``series.csv``
(bytes) and every output time's fields: the resumes after every kill of that chain of attempts
continued bit-identically. A new chain then starts (``run --overwrite``). Counted: the kills, the
completed chains, the kills that left a checkpoint or an output time half written (its
files are left behind), and the mpiruns that did not exit once their ranks had (see ``kill``). Any failed check stops the script with an error.

    .venv/bin/python validation/kill_loop.py --processes 1 2 3 --kills 140 30 30 \\
        --out docs/validation/kill_loop.json
"""

import argparse
import contextlib
import json
import os
import pathlib
import random
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree

import numpy as np

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")
SCENE = ["bar-impact", "--set", "time.end=0.6", "--set", "output.every=2", "--checkpoint-every", "4", "--quiet"]
FIELDS = ("displacement", "velocity", "stress_xx")
#: wall time (s) an attempt that is not killed may take to finish (the whole run takes a few seconds)
ATTEMPT_LIMIT = 300
#: wall time (s) the ranks may take to exit after their SIGKILL, and mpirun after its ranks
RANK_EXIT_LIMIT, MPIRUN_EXIT_LIMIT = 60, 30
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_btl_vader_single_copy_mechanism="none", OMP_NUM_THREADS="1", PYVISTA_OFF_SCREEN="true")


def command(processes: int, args: list[str]) -> list[str]:
    prefix = ["mpirun", "-n", str(processes), "--oversubscribe"] if processes > 1 else []
    return [*prefix, CLI, *args]


def read_fields(xdmf: pathlib.Path) -> dict[float, dict[str, np.ndarray]]:
    """Every output time of a solution.xdmf read back by VTK's XDMF reader: t -> field -> cell data."""
    import pyvista
    from vtkmodules.vtkCommonCore import vtkObject

    vtkObject.GlobalWarningDisplayOff()  # a 1D vector field has one component: VTK warns at every read
    if "<Time " not in xdmf.read_text():  # killed before its first output time: the mesh alone
        check(ElementTree.parse(xdmf).find("Domain/Grid[@Name='mesh']") is not None, f"{xdmf} lists no mesh")
        return {}
    reader = pyvista.get_reader(str(xdmf))
    out = {}
    for t in reader.time_values:
        reader.set_active_time_value(t)
        blocks = reader.read()
        out[t] = {name: np.asarray(blocks[name].cell_data[name]) for name in FIELDS}
    return out


def check(condition: bool, message: str) -> None:
    if not condition:
        raise SystemExit(f"kill_loop: {message}")


def same_fields(read: dict, reference: dict, where: str) -> None:
    for t, fields in read.items():
        check(t in reference, f"{where}: output time {t} is not one of the uninterrupted run's")
        for name in FIELDS:
            check(np.array_equal(fields[name], reference[t][name]), f"{where}: {name} differs at t = {t}")


def complete(out: pathlib.Path, series: bytes, fields: dict, where: str) -> None:
    """Check a completed run against the uninterrupted one."""
    check((out / "series.csv").read_bytes() == series, f"{where}: series.csv differs from the uninterrupted run's")
    read = read_fields(out / "solution.xdmf")
    check(list(read) == list(fields), f"{where}: other output times than the uninterrupted run's")
    same_fields(read, fields, where)


def stamp(path: pathlib.Path):
    try:
        stat = os.stat(path)
    except FileNotFoundError:
        return None
    return stat.st_ino, stat.st_mtime_ns


def children(pid: int) -> list[int]:
    """Process ids of the children of ``pid`` (Linux /proc): the ranks mpirun started."""
    try:
        return [int(c) for task in pathlib.Path(f"/proc/{pid}/task").iterdir()
                for c in (task / "children").read_text().split()]
    except (FileNotFoundError, ProcessLookupError):  # mpirun has exited
        return []


def alive(pid: int) -> bool:
    """Whether ``pid`` still runs (neither gone nor exited and waiting to be reaped)."""
    try:
        stat = pathlib.Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat[stat.rindex(")") + 2] not in "ZX"


def kill(process: subprocess.Popen, processes: int) -> bool:
    """SIGKILL the run: the process, or every rank of mpirun at once. Returns whether mpirun hung.

    Once no rank runs (each gone or exited), nothing more reaches the run's files, and mpirun
    normally exits at once; one that has not after MPIRUN_EXIT_LIMIT (a CI run saw mpirun 4.1.4
    not return within 60 s on 3 processes of a loaded 2-core machine) is killed and counted:
    Open MPI's hang, not the run's. A rank that still runs RANK_EXIT_LIMIT after its SIGKILL is an
    error."""
    if processes == 1:
        process.kill()
        process.communicate(timeout=60)
        return False
    deadline = time.monotonic() + RANK_EXIT_LIMIT
    while process.poll() is None and (left := [pid for pid in children(process.pid) if alive(pid)]):
        check(time.monotonic() < deadline, f"ranks {left} of mpirun still run {RANK_EXIT_LIMIT} s after their "
              "SIGKILL")
        for pid in left:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.01)
    try:
        process.communicate(timeout=MPIRUN_EXIT_LIMIT)
        return False
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate(timeout=60)
        return True


def kill_loop(folder: pathlib.Path, kills: int, processes: int, seed: int, max_delay: float) -> dict:
    """Kill ``kills`` attempts of SCENE on ``processes`` processes, checking after each (see the
    module docstring); returns the counts and the wall time."""
    start = time.perf_counter()
    reference = folder / "reference"
    subprocess.run(command(processes, ["run", *SCENE, "--out", str(reference), "--overwrite"]), check=True, env=ENV,
                   stdout=subprocess.DEVNULL)
    series = (reference / "series.csv").read_bytes()
    fields = read_fields(reference / "solution.xdmf")
    rng = random.Random(seed)
    out = folder / "killed"
    counts = {"kills": 0, "completed": 0, "in_checkpoint": 0, "in_output": 0, "mpirun_hangs": 0}
    fresh = True
    while counts["kills"] < kills:
        args = ["run", *SCENE, "--out", str(out), "--overwrite"] if fresh else ["resume", str(out), "--quiet"]
        before = stamp(out / "solution.xdmf")
        process = subprocess.Popen(command(processes, args), env=ENV, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.PIPE, text=True)
        while stamp(out / "solution.xdmf") in (before, None) and process.poll() is None:
            time.sleep(0.001)
        time.sleep(rng.uniform(0.0, max_delay))
        where = f"{processes} process(es), kill {counts['kills'] + 1}"
        if process.poll() is None:
            if kill(process, processes):
                print(f"{where}: mpirun had not exited {MPIRUN_EXIT_LIMIT} s after its ranks: killed", flush=True)
                counts["mpirun_hangs"] += 1
            counts["kills"] += 1
            if not (out / "INCOMPLETE").exists():  # killed on its way out, the run complete
                complete(out, series, fields, where)
                counts["completed"] += 1
                fresh = True
                continue
            read = read_fields(out / "solution.xdmf")
            same_fields(read, fields, where)
            header = out / "checkpoint" / "checkpoint.json"
            fresh = not header.exists()  # killed before its first checkpoint: start again
            if not fresh:
                header = json.loads(header.read_text())
                n = header["series_bytes"]
                check((out / "series.csv").read_bytes()[:n] == series[:n], f"{where}: series.csv differs before "
                      "the checkpoint's position")
                check(len(read) >= header["xdmf_writes"], f"{where}: fewer output times than the checkpoint's")
                counts["in_checkpoint"] += [p.name for p in (out / "checkpoint").iterdir() if p.is_dir()] != [
                    header["data"]]
            counts["in_output"] += any(p.name.startswith(".") for p in (out / "solution").iterdir())
        else:
            stderr = process.communicate(timeout=ATTEMPT_LIMIT)[1]
            check(process.returncode == 0, f"{where}: the attempt failed (exit {process.returncode}): {stderr}")
            complete(out, series, fields, where)
            counts["completed"] += 1
            fresh = True
    counts["seconds"] = round(time.perf_counter() - start, 1)
    return counts


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--kills", type=int, nargs="+", default=[140, 30, 30], help="per number of processes")
    parser.add_argument("--max-delay", type=float, default=0.8, help="largest delay of a kill (s)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--work", type=pathlib.Path, help="folder of the runs (default: a temporary one)")
    parser.add_argument("--out", type=pathlib.Path, help="JSON file of the counts")
    args = parser.parse_args()
    if len(args.kills) != len(args.processes):
        parser.error("give one --kills count per --processes count")
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or pathlib.Path(tmp)
        results = {}
        for processes, kills in zip(args.processes, args.kills):
            (work / str(processes)).mkdir(parents=True, exist_ok=True)
            results[str(processes)] = kill_loop(work / str(processes), kills, processes, args.seed + processes,
                                                args.max_delay)
            print(f"{processes} process(es): {results[str(processes)]}", flush=True)
    total = {k: sum(r[k] for r in results.values()) for k in ("kills", "completed", "in_checkpoint", "in_output", "mpirun_hangs")}
    total["seconds"] = round(sum(r["seconds"] for r in results.values()), 1)
    print(f"total: {total}")
    if args.out:
        args.out.write_text(json.dumps({"scene": SCENE, "max_delay_s": args.max_delay, "seed": args.seed,
                                        "processes": results, "total": total}, indent=1) + "\n")


if __name__ == "__main__":
    main()
