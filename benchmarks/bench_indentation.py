"""The force-indentation curve of the built-in scene ``indentation`` (issue 15): a rigid disc
(a prescribed body) pushed at 0.5 m/s into a clamped elastic block, for a P2 FEM Nitsche
reference (static) to compare against.

For each mesh size h: the reaction of the disc on the block, -reaction_disc_y (N/m), at the
indentations 0.005, 0.01 and 0.02 m (indentation = max(0, 0.5 t - 0.002); linear interpolation
between the two steps around each), the curve every ``--curve-every`` steps, the energy balance
max |E^n - W^n - E^0| / max E_mech, the steps, cells and wall time. The run is dynamic: the
block's inertia adds waves (they cross it in about 5 ms) to the quasi-static force.

    .venv/bin/python benchmarks/bench_indentation.py [--h 0.04 0.02 0.01] [--out indentation.json]
"""

import argparse
import json
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import dynamics, scenes

INDENTATIONS = (0.005, 0.01, 0.02)
GAP, SPEED = 0.002, 0.5


def run(h: float, curve_every: int) -> dict:
    tic = time.perf_counter()
    r = dynamics.DynamicRun(scenes.load("indentation", {"mesh.h": h}), MPI.COMM_WORLD, quiet=True)
    dem, stepper = r.dem, r.stepper

    def force() -> float:  # -reaction_disc_y: the block pushed down counts positive
        return -float(dem.prescribed_values(stepper.u, stepper.t)[0, 0, 1])

    targets = {d: (d + GAP) / SPEED for d in INDENTATIONS}
    slack = 1e-9 * r.dt

    def crossed(t0: float, t1: float) -> list:  # the indentations reached in (t0, t1]
        return [d for d, t in targets.items() if t0 + slack < t <= t1 + slack]

    at, curve = {}, []
    scale, first, drift = r.first.mechanical, r.first.balance, 0.0
    previous = force() if crossed(0.0, r.dt) else None
    for _ in range(r.n_steps):
        t0 = stepper.t
        diag = stepper.step()
        scale, drift = max(scale, diag.mechanical), max(drift, abs(diag.balance - first))
        due, ahead, record = crossed(t0, diag.t), crossed(diag.t, diag.t + r.dt), diag.step % curve_every == 0
        f = force() if due or ahead or record else None
        for d in due:
            w = (targets[d] - t0) / r.dt
            at[d] = (1 - w) * previous + w * f
        if record:
            curve.append((max(0.0, SPEED * diag.t - GAP), f))
        previous = f
    return {"h": h, "cells": dem.geometry.num_cells_global, "steps": r.n_steps, "dt": r.dt,
            "force_at_indentation": {str(d): at[d] for d in INDENTATIONS},
            "energy_balance": drift / scale, "wall_time_s": time.perf_counter() - tic, "curve": curve}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, nargs="+", default=[0.04, 0.02])
    parser.add_argument("--curve-every", type=int, default=20)
    parser.add_argument("--out", default="indentation.json")
    args = parser.parse_args()
    results = []
    for h in args.h:
        results.append(run(h, args.curve_every))
        if MPI.COMM_WORLD.rank == 0:
            row = results[-1]
            print(f"h = {h:g}: {row['cells']} cells, {row['steps']} steps, {row['wall_time_s']:.1f} s; force (N/m) at "
                  + ", ".join(f"{d} m: {f:.4g}" for d, f in row["force_at_indentation"].items())
                  + f"; energy balance {row['energy_balance']:.1e}", flush=True)
    if MPI.COMM_WORLD.rank == 0:
        with open(args.out, "w") as f:
            json.dump({"scene": "indentation", "runs": results}, f, indent=1)


if __name__ == "__main__":
    main()
