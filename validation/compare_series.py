"""Compare the series.csv of two runs of one scene (e.g. on 1 and on 2 processes), column by column
over all rows: the largest difference relative to (a) the column's own largest |value| and (b)
the scale of its family: energies to the initial kinetic energy, forces to the largest contact
force, momenta to sum m |v0| (= 2 K0 / speed for bodies all launched at one speed), penetration to
its largest value. With --growth, the family-relative difference of every column, largest over
windows of the run, shows how a difference grows with time.

    .venv/bin/python validation/compare_series.py results/two-balls results/two-balls-2 --speed 0.3
"""

import argparse
import json
import pathlib

import numpy as np

ENERGIES = ("kinetic", "elastic", "stabilisation", "external", "pseudo_energy")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", type=pathlib.Path)
    parser.add_argument("b", type=pathlib.Path)
    parser.add_argument("--speed", type=float, required=True, help="the bodies' initial speed (m/s)")
    parser.add_argument("--growth", type=int, default=0, help="windows of the run for the growth table")
    args = parser.parse_args()
    a, b = (np.genfromtxt(p / "series.csv", delimiter=",", names=True) for p in (args.a, args.b))
    if a.shape != b.shape or a.dtype.names != b.dtype.names or not np.array_equal(a["t"], b["t"]):
        raise SystemExit(f"the runs differ in their rows or columns: {a.shape} {b.shape}")
    forces = [c for c in a.dtype.names if c.startswith("contact_force")]
    scales = {"energy": a["kinetic"][0], "force": max(np.abs(a[c]).max() for c in forces),
              "momentum": 2.0 * a["kinetic"][0] / args.speed, "penetration": np.abs(a["penetration"]).max()}

    def family(column):
        if column in ENERGIES:
            return "energy"
        if column in forces:
            return "force"
        if column.startswith("momentum_"):
            return "momentum"
        if column == "penetration":
            return "penetration"
        raise SystemExit(f"no family for column {column!r}")

    columns = [c for c in a.dtype.names if c != "t"]
    report = {}
    for c in columns:
        diff = np.abs(a[c] - b[c])
        k = int(np.argmax(diff))
        own = np.abs(a[c]).max()
        report[c] = {"max_abs_diff": float(diff[k]), "at_t": float(a["t"][k]),
                     "rel_own_max": float(diff[k] / own) if own > 0 else None, "own_max": float(own),
                     "family": family(c), "rel_family": float(diff[k] / scales[family(c)])}
    print(json.dumps({"scales": {k: float(v) for k, v in scales.items()}, "columns": report}, indent=1))
    if args.growth:
        edges = np.linspace(0, len(a), args.growth + 1).astype(int)
        print("t_end " + " ".join(f"{c[:14]:>14}" for c in columns))
        for lo, hi in zip(edges[:-1], edges[1:]):
            row = [np.abs(a[c][lo:hi] - b[c][lo:hi]).max() / scales[family(c)] for c in columns]
            print(f"{a['t'][hi - 1]:.3f} " + " ".join(f"{x:14.2e}" for x in row))


if __name__ == "__main__":
    main()
