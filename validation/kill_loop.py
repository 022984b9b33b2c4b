"""Kill a run at random moments, many times: every kill leaves a solution.xdmf whose listed times all
read back, and a resume that continues bit-identically (issue 32.4; io.SolutionWriter).

Each round starts ``dolfinx-dem run bar-wave`` (100 cells; an output time every 2 steps and a
checkpoint every 25, so that kills land in HDF5 writes and closes as often as between them),
waits for its first output time, sends SIGKILL after a random delay, then (1) reads every time that
solution.xdmf lists with VTK's XDMF reader in a process of its own (the displacement of each of the
100 cells, finite), and (2) when the run had written a checkpoint, resumes it to the end and
compares series.csv and the listed times with an uninterrupted run's, byte for byte.

    .venv/bin/python validation/kill_loop.py [--kills 200] [--seed 1] [--out docs/validation/kill_loop.json]
    .venv/bin/python validation/kill_loop.py --quick --out OUT.json     # 10 kills, for the tests
"""

import argparse
import json
import os
import pathlib
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from xml.etree import ElementTree

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")
RUN = ["run", "bar-wave", "--set", "time.end=1.6", "--set", "output.every=2", "--checkpoint-every", "25", "--quiet"]
#: Where the folders of failed rounds are kept, as the kill left them.
KEPT = pathlib.Path(tempfile.gettempdir()) / "kill_loop_failures"
READ = """
import sys
import numpy as np
from dolfinx_dem.plotting import pyvista
reader = pyvista.get_reader(sys.argv[1])
for t in reader.time_values:
    reader.set_active_time_value(t)
    u = np.asarray(reader.read()["displacement"].cell_data["displacement"])
    assert len(u) == 100 and np.isfinite(u).all(), t
print(len(reader.time_values))
"""


def env():
    return dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1")


def listed_times(xdmf: pathlib.Path) -> list[float]:
    root = ElementTree.parse(xdmf).getroot()
    return [float(t.get("Value")) for g in root.iter("Grid") if g.get("CollectionType") == "Temporal"
            for t in g.iter("Time")]


def round_trip(out: pathlib.Path, rng: random.Random, reference: pathlib.Path) -> dict:
    """One kill of a run into the new folder ``out``, its read and its resume."""
    process = subprocess.Popen([CLI, *RUN, "--out", str(out)], env=env())
    xdmf = out / "solution.xdmf"
    while process.poll() is None and not (xdmf.exists() and listed_times(xdmf)):
        time.sleep(0.01)
    time.sleep(rng.uniform(0.0, 1.5))
    process.send_signal(signal.SIGKILL)
    finished = process.wait() == 0
    read = subprocess.run([sys.executable, "-c", READ, str(xdmf)], capture_output=True, text=True, env=env())
    row = {"finished": finished, "read": read.returncode == 0, "times": int(read.stdout or 0),
           "error": read.stderr[-300:] if read.returncode else ""}
    row["resumed"] = (out / "checkpoint" / "checkpoint.json").exists() and not finished
    if row["resumed"]:
        killed = out.with_name(out.name + "-killed")
        shutil.copytree(out, killed, symlinks=True)  # the folder as the kill left it, for a failure's record
        resume = subprocess.run([CLI, "resume", str(out), "--quiet"], env=env(), capture_output=True, text=True)
        row["identical"] = (resume.returncode == 0
                            and (out / "series.csv").read_bytes() == (reference / "series.csv").read_bytes()
                            and listed_times(xdmf) == listed_times(reference / "solution.xdmf"))
        if not row["identical"]:
            row["error"] += resume.stderr[-2000:]
            row["kept"] = str(KEPT / out.name)
            shutil.copytree(killed, KEPT / out.name, symlinks=True)
        shutil.rmtree(killed)
    return row


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--kills", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--quick", action="store_true", help="10 kills")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args(argv)
    kills = 10 if args.quick else args.kills
    rng = random.Random(args.seed)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        work = pathlib.Path(work)
        subprocess.run([CLI, *RUN, "--out", str(work / "reference")], check=True, env=env())
        rows = [round_trip(work / f"run{k}", rng, work / "reference") for k in range(kills)]
    result = {
        "kills": kills, "seed": args.seed, "command": " ".join(["dolfinx-dem", *RUN]),
        "read": sum(r["read"] for r in rows), "resumed": sum(r["resumed"] for r in rows),
        "identical": sum(r.get("identical", False) for r in rows),
        "finished_before_the_kill": sum(r["finished"] for r in rows),
        "listed_times": [r["times"] for r in rows], "failures": [r for r in rows if not r["read"] or
                                                                 (r["resumed"] and not r["identical"])],
        "wall_s": time.perf_counter() - start,
    }
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    return result


if __name__ == "__main__":
    main()
