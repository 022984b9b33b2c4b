"""Compare the series.csv of every built-in scene run on two platforms (e.g. Debian 12 with
DOLFINx 0.5.2 and Debian 13 with 0.9.0): for each scene the largest difference of the energy
columns relative to the run's energy scale (its largest kinetic + elastic + stabilisation
energy), and of every other column relative to its family's largest |value| (momenta, forces
and reactions, the rest: positions, gaps, probes); a markdown table.
Scenes whose meshes differ (their cell counts, or their mesh generator's version) are listed
apart: their runs are not the same discrete problem.

    .venv/bin/python validation/compare_platforms.py DIR_A DIR_B [--out docs/platforms.json]

DIR_A and DIR_B hold one output folder per scene (``dolfinx-dem run SCENE --out DIR/SCENE``).
"""

import argparse
import json
import pathlib

import numpy as np

ENERGIES = ("kinetic", "elastic", "stabilisation", "external", "pseudo_energy", "work", "balance")


def compare(a_dir: pathlib.Path, b_dir: pathlib.Path) -> dict:
    a, b = (np.genfromtxt(d / "series.csv", delimiter=",", names=True) for d in (a_dir, b_dir))
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a_dir, b_dir))
    out = {"cells": [sa.get("n_cells"), sb.get("n_cells")]}
    if a.shape != b.shape or a.dtype.names != b.dtype.names:
        out["comparable"] = False
        return out
    energy = max(np.abs(a["kinetic"] + a["elastic"] + a["stabilisation"]).max(), 1e-300)
    columns = [c for c in a.dtype.names if c != "t"]

    def family(c):
        if c in ENERGIES:
            return "energy"
        if c in ("contact_gap", "penetration"):  # zero in contact: compared in metres
            return "gap"
        return "momentum" if c.startswith("momentum_") else "force" if c.startswith(
            ("contact_force", "reaction_", "contact_pressure")) else "other"

    scale = {}
    for c in columns:
        scale[family(c)] = max(scale.get(family(c), 0.0), float(np.abs(a[c]).max()))
    worst_energy, worst_other, worst_gap = (0.0, "-"), (0.0, "-"), (0.0, "-")
    for c in columns:
        diff = float(np.abs(a[c] - b[c]).max())
        if family(c) == "energy":
            worst_energy = max(worst_energy, (diff / energy, c))
        elif family(c) == "gap":
            worst_gap = max(worst_gap, (diff, c))
        else:
            worst_other = max(worst_other, (diff / scale[family(c)] if scale[family(c)] > 0 else diff, c))
    out.update(comparable=sa.get("n_cells") == sb.get("n_cells"), energy=worst_energy, other=worst_other, gap=worst_gap,
               time=float(np.abs(a["t"] - b["t"]).max()))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", type=pathlib.Path)
    parser.add_argument("b", type=pathlib.Path)
    parser.add_argument("--out", type=pathlib.Path)
    args = parser.parse_args()
    rows = {d.name: compare(d, args.b / d.name) for d in sorted(args.a.iterdir()) if (args.b / d.name).is_dir()}
    print("| scene | cells (A / B) | energies: max diff / energy scale | other columns: max diff / family scale "
          "| gap, penetration: max diff (m) |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        if not r["comparable"]:
            print(f"| {name} | {r['cells'][0]} / {r['cells'][1]} | (different meshes) | | |")
            continue
        (e, ec), (o, oc), (g, gc) = r["energy"], r["other"], r["gap"]
        gap = f"{g:.1e} ({gc})" if gc != "-" else "-"
        print(f"| {name} | {r['cells'][0]} | {e:.1e} ({ec}) | {o:.1e} ({oc}) | {gap} |")
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
