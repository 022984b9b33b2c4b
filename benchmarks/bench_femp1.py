"""A bar-impact step of the DEM (dem-A) against a step of the FEM peer (fem-P1) on the same scene.

Both run the built-in `bar-impact` (100 cells, dt = 0.0025 s, 800 steps, contact on
[0.5, 7/6] s) on one process: `DynamicRun.stepper.step()` (MEMM with the rigid contact) against
`FEMP1Run.solver.step()` (lumped P1 central differences with the penalty), without the outputs.
Rounds alternate the two methods; each round times every step of a whole run. Reported: the
median wall time of a step over all steps and over the steps in contact, and the ratio DEM / FEM
(issue 33's target: at most 2).

    .venv/bin/python benchmarks/bench_femp1.py [--quick] [--out docs/bench/femp1.json]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import subprocess
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import scenes
from dolfinx_dem.dynamics import DynamicRun
from dolfinx_dem.fem.scene_run import FEMP1Run

CONTACT = (0.5, 7.0 / 6.0)


def step_times(method: str, end: float) -> tuple[np.ndarray, np.ndarray]:
    """(wall seconds of each step, time at its start) of a bar-impact run to ``end``."""
    scene = scenes.load("bar-impact", {"method": method, "time.end": end})
    if method == "fem-P1":
        run = FEMP1Run(scene, MPI.COMM_SELF, quiet=True)
        step, clock, n = run.solver.step, (lambda: run.solver.t), run.n_steps
    else:
        run = DynamicRun(scene, MPI.COMM_SELF, quiet=True)
        step, clock, n = run.stepper.step, (lambda: run.stepper.t), run.n_steps
    times, starts = np.empty(n), np.empty(n)
    for k in range(n):
        starts[k] = clock()
        tic = time.perf_counter()
        step()
        times[k] = time.perf_counter() - tic
    return times, starts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 rounds to t = 1 s")
    parser.add_argument("--out", default="docs/bench/femp1.json")
    args = parser.parse_args()
    rounds, end = (2, 1.0) if args.quick else (7, 2.0)
    samples = {"dem-A": [], "fem-P1": []}
    for _ in range(rounds):
        for method in samples:
            samples[method].append(step_times(method, end))
    results = {}
    for method, runs in samples.items():
        times = np.concatenate([t for t, _ in runs])
        starts = np.concatenate([s for _, s in runs])
        contact = (starts >= CONTACT[0]) & (starts < CONTACT[1])
        results[method] = {"median_step_us": 1e6 * float(np.median(times)),
                           "median_contact_step_us": 1e6 * float(np.median(times[contact])),
                           "median_free_step_us": 1e6 * float(np.median(times[~contact])),
                           "steps": int(times.size)}
    dem, fem = results["dem-A"], results["fem-P1"]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    report = {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="minutes"),
        "commit": commit,
        "load_average": os.getloadavg(),
        "rounds": rounds,
        "t_end": end,
        "results": results,
        "ratio_dem_over_fem": dem["median_step_us"] / fem["median_step_us"],
        "ratio_dem_over_fem_in_contact": dem["median_contact_step_us"] / fem["median_contact_step_us"],
    }
    pathlib.Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pathlib.Path(args.out).write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
