"""Contact between bodies in 3D: the contact share of a step and what the contact work grows with.

1. `cradle` (five balls, h = 0.04 m) over its first 0.3 s, the first impacts included: the
   summary's `contact_fraction` (processor time of the contact work, in `PairContact` and in the
   contact outputs computed at every step, over the MEMM stepping time plus those outputs;
   target below 40 %).
2. `two-balls` (h = 0.04 m uniform, eta = E, the facet surface, contact boundary "all") with N idle balls of the same size, 0.2 m
   from each other and 0.4 m from the pair (farther than the pair list radius), all of whose
   facets are contact candidates: the contact work per step during the impact
   (0.04 to 0.16 s; processor time in `PairContact.force_integral` and `energy_correction`,
   the cheapest of three equal chunks: the machine is shared) should follow the touching pairs,
   not the candidate facets.

    .venv/bin/python benchmarks/bench_contact3d.py [--quick] [--out docs/bench/contact3d.json]

Serial (the timings are of one process).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import tempfile
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import scenes, simulation
from dolfinx_dem.dynamics import DynamicRun


def cradle(t_end: float) -> dict:
    with tempfile.TemporaryDirectory() as out:
        s = simulation.run(scenes.load("cradle", {"time.end": t_end}), out, MPI.COMM_SELF, quiet=True)
    return {k: s[k] for k in ("n_cells", "n_steps", "contact_candidate_facets", "contact_pairs_listed",
                              "contact_seconds", "contact_output_seconds", "contact_fraction", "wall_time_s")}


def idle_balls(n_idle: int, h: float, t0: float, t1: float) -> dict:
    balls = [[0.14, 0.0, 0.0, 0.1], [0.36, 0.0, 0.0, 0.1]] + [[0.4 * k, 0.6, 0.0, 0.1] for k in range(n_idle)]
    # a uniform mesh, eta = E and the facet surface (the scene refines its contact point and takes the
    # vertex surface): the same configuration as the figures of CHANGELOG.md, so that they compare
    scene = scenes.load("two-balls", {"mesh.h": h, "mesh.refine_h": h, "material.eta": 100.0, "mesh.balls": balls,
                                      "contact.surface": "facet",
                                      "contact.boundary": ["all"], "time.end": t1})
    run = DynamicRun(scene, MPI.COMM_SELF, quiet=True)
    stepper, contact = run.stepper, run.pairs
    while stepper.t < t0:
        stepper.step()
    steps = (run.n_steps - stepper.n) // 3
    chunks, touching = [], []
    for _ in range(3):
        contact.seconds = 0.0
        start = time.process_time()
        for _ in range(steps):
            stepper.step()
            g, w = contact.outputs.pair_states(contact.patch_values(stepper.u))
            touching.append(int(((g < 0) & (w > 0)).sum()))
        chunks.append((time.process_time() - start, contact.seconds))
    total, seconds = min(chunks, key=lambda c: c[1])
    return {"idle_balls": n_idle, "cells": run.dem.geometry.num_cells_global,
            "contact_candidate_facets": contact.pair_list.num_facets, "pairs_listed": contact.num_pairs,
            "touching_pairs_mean": float(np.mean(touching)), "steps_per_chunk": steps,
            "contact_ms_per_step": 1e3 * seconds / steps, "step_ms": 1e3 * total / steps}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs, fewer idle balls")
    parser.add_argument("--out", type=pathlib.Path)
    args = parser.parse_args()
    result = {"cradle": cradle(0.1 if args.quick else 0.3),
              "idle_balls": [idle_balls(n, 0.04, 0.04, 0.08 if args.quick else 0.16)
                             for n in ((0, 2) if args.quick else (0, 2, 6))]}
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
