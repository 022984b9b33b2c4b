"""The force-indentation curve of the built-in scene ``indentation``: a rigid disc
(a prescribed body) pushed at constant speed into a clamped elastic block, against the DEM
statics solution and the P2 FEM Nitsche reference (docs/validation/indentation_fem.json).

Dynamic runs (``--h``, at each of ``--speeds``; the ``--slow-h`` meshes also at ``--slow-speeds``:
the quasi-static check): for each mesh size h the reaction of the disc on the block,
-reaction_disc_y (N/m), at the indentations 0.005, 0.01 and 0.02 m (indentation =
max(0, speed t - 0.002); linear interpolation between the two steps around each), the curve every
``--curve-every`` steps, the energy balance max |E^n - W^n - E^0| / max E_mech (memm.py), the
steps, cells and wall time. The block's inertia adds waves (they cross it in about 5 ms) to the
quasi-static force: halving the speed halves their amplitude.

Static solutions (``--static-h``): ``statics.minimise_energy`` at the load time t of each
indentation (the disc held at U(t) = velocity t), the disc's reaction and the base's (their sum is
the discrete equilibrium residual), Newton iterations and wall time.

    .venv/bin/python validation/indentation.py [--h 0.04 0.02] [--speeds 0.5 0.25] [--slow-h 0.04]
        [--slow-speeds 0.125 0.0625] [--static-h 0.04 0.02] [--out indentation.json]
    .venv/bin/python validation/indentation.py --merge a.json b.json --out indentation.json
    .venv/bin/python validation/indentation.py --quick --out OUT.json    # h = 0.04 m, 0.5 m/s and statics

``--merge``: one file of the runs of several (e.g. concurrent) invocations, in their order, with the
FEM reference (the finest mesh of docs/validation/indentation_fem.json) and the table of
docs/validation/indentation.md printed: force per indentation and DEM mesh, dynamic (each speed)
and static, and their relative differences from the FEM force.
"""

import argparse
import json
import pathlib
import time

from mpi4py import MPI

from dolfinx_dem import dynamics, model, scenes
from dolfinx_dem.statics import minimise_energy

INDENTATIONS = (0.005, 0.01, 0.02)
GAP = 0.002
FEM = pathlib.Path(__file__).resolve().parents[1] / "docs" / "validation" / "indentation_fem.json"


def scene(h: float, speed: float, method: str) -> dict:
    """The built-in scene with mesh size h and ``method``, the disc moving down at ``speed`` until
    the last indentation."""
    s = scenes.load("indentation", {"mesh.h": h, "time.end": (INDENTATIONS[-1] + GAP) / speed, "method": method})
    s["prescribed"][0]["velocity"] = [0.0, -speed]
    return s


def run(h: float, speed: float, curve_every: int, method: str) -> dict:
    tic = time.perf_counter()
    r = dynamics.DynamicRun(scene(h, speed, method), MPI.COMM_WORLD, quiet=True)
    dem, stepper = r.dem, r.stepper

    def force() -> float:  # -reaction_disc_y: the block pushed down counts positive
        return -float(r.problem.prescribed_values(stepper.u, stepper.t)[0, 0, 1])

    targets = {d: (d + GAP) / speed for d in INDENTATIONS}
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
            curve.append((max(0.0, speed * diag.t - GAP), f))
        previous = f
    return {"h": h, "method": method, "speed": speed, "cells": dem.geometry.num_cells_global, "steps": r.n_steps, "dt": r.dt,
            "force_at_indentation": {str(d): at[d] for d in INDENTATIONS},
            "energy_balance": drift / scale, "wall_time_s": time.perf_counter() - tic, "curve": curve}


def static(h: float, method: str) -> dict:
    """DEM statics at the three indentations on the mesh of size h (one model, three load times)."""
    tic = time.perf_counter()
    s = scene(h, 1.0, method)  # U(t) = (0, -t): the load time of indentation d is t = d + GAP
    for key in ("time", "output"):
        del s[key]
    s["statics"] = {}
    problem = model.build(scenes.override(s), MPI.COMM_WORLD)
    dem = problem.dem
    rows = {}
    for d in INDENTATIONS:
        t = d + GAP
        result = minimise_energy(problem, t=t)
        disc = problem.prescribed_values(result.u, t, result.force)[0, 0, 1]  # the kinks' multipliers included
        base = float(dem.reactions(result.u, t).ravel()[1])
        rows[str(d)] = {"force": -float(disc), "base_reaction_y": base, "balance": (base + disc) / base,
                        "iterations": result.iterations, "gradient_reduction": result.gradient_reduction,
                        "wall_time_s": result.wall_time_s}
    return {"h": h, "method": method, "cells": dem.geometry.num_cells_global, "indentations": rows,
            "wall_time_s": time.perf_counter() - tic}


def fem_forces() -> dict:
    """The FEM reference force P (N/m) per indentation, on its finest mesh."""
    deltas = json.loads(FEM.read_text())["deltas"]
    return {str(d): min(deltas[str(d)]["rows"], key=lambda r: r["h"])["P"] for d in INDENTATIONS}


def table(data: dict) -> str:
    """The markdown table of ``data`` (this script's output with ``fem``)."""
    fem = data["fem"]
    static = {row["h"]: row["indentations"] for row in data["static"]}
    lines = ["| delta (m) | h (m) | run | force (N/m) | vs FEM | vs DEM static |", "|---|---|---|---|---|---|"]
    for d in map(str, INDENTATIONS):
        lines.append(f"| {d} | | FEM P2 (converged) | {fem[d]:.4g} | | |")
        for h in sorted({row["h"] for row in data["dynamic"]} | set(static), reverse=True):
            s = static[h][d]["force"] if h in static else None
            rows = [("static", s)] if s is not None else []
            rows += [(f"dynamic {r['speed']:g} m/s", r["force_at_indentation"][d])
                     for r in data["dynamic"] if r["h"] == h]
            for name, f in rows:
                versus = "" if s is None or name == "static" else f"{(f - s) / s:+.1%}"
                lines.append(f"| {d} | {h:g} | {name} | {f:.4g} | {(f - fem[d]) / fem[d]:+.1%} | {versus} |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, nargs="*", default=[0.04, 0.02])
    parser.add_argument("--speeds", type=float, nargs="+", default=[0.5, 0.25])
    parser.add_argument("--slow-h", type=float, nargs="*", default=[0.04])
    parser.add_argument("--slow-speeds", type=float, nargs="*", default=[0.125, 0.0625])
    parser.add_argument("--static-h", type=float, nargs="*", default=[0.04, 0.02])
    parser.add_argument("--method", default="dem-B", choices=["dem-A", "dem-B"])
    parser.add_argument("--curve-every", type=int, default=20)
    parser.add_argument("--out", default="indentation.json")
    parser.add_argument("--merge", nargs="+", help="files of earlier invocations to merge into --out, nothing run")
    parser.add_argument("--quick", action="store_true", help="--h 0.04 --speeds 0.5 --slow-h --static-h 0.04")
    args = parser.parse_args()
    if args.quick:
        args.h, args.speeds, args.slow_h, args.static_h = [0.04], [0.5], [], [0.04]
    if args.merge:
        parts = [json.load(open(path)) for path in args.merge]
        with open(args.out, "w") as f:
            data = {"scene": "indentation", "processes": parts[0]["processes"], "fem": fem_forces(),
                    "dynamic": [r for p in parts for r in p["dynamic"]],
                    "static": [r for p in parts for r in p["static"]]}
            json.dump(data, f, indent=1)
        print(table(data))
        return
    root = MPI.COMM_WORLD.rank == 0
    dynamic, statics = [], []
    for h in args.h:
        for speed in args.speeds + (args.slow_speeds if h in args.slow_h else []):
            dynamic.append(row := run(h, speed, args.curve_every, args.method))
            if root:
                print(f"dynamic h = {h:g}, speed {speed:g} m/s: {row['cells']} cells, {row['steps']} steps, "
                      f"{row['wall_time_s']:.1f} s; force (N/m) at "
                      + ", ".join(f"{d} m: {f:.4g}" for d, f in row["force_at_indentation"].items())
                      + f"; energy balance {row['energy_balance']:.1e}", flush=True)
    for h in args.static_h:
        statics.append(row := static(h, args.method))
        if root:
            print(f"static h = {h:g}: {row['cells']} cells, {row['wall_time_s']:.1f} s; force (N/m) at "
                  + ", ".join(f"{d} m: {r['force']:.4g} (balance {r['balance']:.1e}, {r['iterations']} it)"
                              for d, r in row["indentations"].items()), flush=True)
    if root:
        with open(args.out, "w") as f:
            json.dump({"scene": "indentation", "processes": MPI.COMM_WORLD.size, "dynamic": dynamic,
                       "static": statics}, f, indent=1)


if __name__ == "__main__":
    main()
