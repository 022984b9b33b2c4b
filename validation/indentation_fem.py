"""Mesh convergence of the FEM reference of a rigid cylinder indenting an elastic block.

Runs :func:`dolfinx_dem.fem.indentation.solve_indentation` (P2, Nitsche, gamma0 = 20, theta = 1;
block [-0.5, 0.5] x [-0.5, 0] m clamped at the bottom, cylinder R = 0.2 m, E = 1e4 Pa, nu = 0.3,
plane strain) on meshes whose size in the contact zone halves from one to the next, for the
indentations delta = 0.005, 0.01, 0.02 m (one mesh per h, the indentations solved in turn).

Recorded per delta and mesh: the vertical contact force P (N/m) and the clamp's reaction, the
moment half-width a, the Hertz-fit half-width, the largest pressure p_max, Newton iterations and
wall times; per delta, the differences between successive meshes (relative to the finer one) and
the ratio of successive differences; and the half-space estimates a_H = sqrt(4 P R / (pi E*)),
p0_H = 2 P / (pi a_H) (indicative only: the block is finite). Serial. Usage::

    .venv/bin/python validation/indentation_fem.py --out docs/validation/indentation_fem.json  # ~3.5 min
    .venv/bin/python validation/indentation_fem.py --quick --out OUT.json     # --meshes 0.004: seconds
"""

from __future__ import annotations

import argparse
import datetime
import json
import pathlib
import shlex
import subprocess
import sys
import time

from mpi4py import MPI

from dolfinx_dem.fem.indentation import solve_indentation

ROOT = pathlib.Path(__file__).resolve().parent.parent
KEYS = ("P", "a", "a_fit", "p_max")


def differences(rows: list[dict]) -> dict:
    """Per quantity: relative differences between successive meshes, (coarse - fine) / fine, and
    the ratios of successive differences (~4 for second-order convergence)."""
    out = {}
    for key in KEYS:
        diff = [(c[key] - f[key]) / f[key] for c, f in zip(rows, rows[1:])]
        ratio = [d0 / d1 if d1 != 0.0 else None for d0, d1 in zip(diff, diff[1:])]
        out[key] = {"relative_difference": diff, "ratio": ratio}
    return out


def table(results: dict) -> str:
    lines = ["| delta (m) | h (m) | cells | dofs | P (N/m) | reaction - P | a (m) | a fit (m) | p_max (Pa) "
             "| a_H (m) | p0_H (Pa) | iterations | solve (s) |", "|" + "---|" * 13]
    for delta, block in results["deltas"].items():
        for r in block["rows"]:
            lines.append(f"| {delta} | {r['h']:g} | {r['num_cells']} | {r['num_dofs']} | {r['P']:.6g} "
                         f"| {r['reaction'] - r['P']:.1e} | {r['a']:.6g} | {r['a_fit']:.6g} | {r['p_max']:.6g} "
                         f"| {r['hertz_a']:.6g} | {r['hertz_p0']:.6g} | {r['iterations']} "
                         f"| {r['times']['solve']:.1f} |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", type=float, nargs="+", default=[0.004, 0.002, 0.001],
                        help="mesh sizes h in the contact zone (m), coarse to fine")
    parser.add_argument("--deltas", type=float, nargs="+", default=[0.005, 0.01, 0.02], help="indentations (m)")
    parser.add_argument("--out", default=None, help="JSON file to write")
    parser.add_argument("--quick", action="store_true", help="--meshes 0.004 (seconds)")
    args = parser.parse_args()
    if args.quick:
        args.meshes = [0.004]
    comm = MPI.COMM_WORLD
    started = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    per_delta = {d: [] for d in args.deltas}
    meshes = []
    for h in args.meshes:
        t0 = time.perf_counter()
        for r in solve_indentation(comm, h, args.deltas):
            per_delta[r.delta].append(r.summary())
        meshes.append({"h": h, "wall_s": comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)})
        if comm.rank == 0:
            print(f"h = {h:g}: {meshes[-1]['wall_s']:.1f} s", file=sys.stderr, flush=True)
    results = {
        "description": "FEM P2 Nitsche reference, rigid cylinder (R = 0.2 m) indenting the block [-0.5, 0.5] x "
                       "[-0.5, 0] m clamped at the bottom, E = 1e4 Pa, nu = 0.3, plane strain, frictionless "
                       "(dolfinx_dem.fem.indentation; half model); P, a, p_max are for the whole block",
        "date": started,
        "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                 cwd=ROOT, check=False).stdout.strip(),
        "command": " ".join(shlex.quote(a) for a in ["python", *sys.argv]),
        "processes": comm.size,
        "meshes": meshes,
        "deltas": {str(d): {"rows": rows, "convergence": differences(rows)} for d, rows in per_delta.items()},
    }
    if comm.rank == 0:
        print(table(results))
        if args.out:
            pathlib.Path(args.out).write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
