"""Cattaneo-Mindlin partial slip between two elastic bodies (statics with friction between bodies,
statics/pair_friction.py).

The hertz scene's disc (R = 0.2 m, E = 25 MPa, nu = 0.25, plane strain, body force 2 MN/m^3 down:
the normal load P) on an elastic block [-0.3, 0.3] x [-0.2, 0] of the same material clamped at its
base, friction mu = 0.3 between them: the normal load on the frictionless contact, then the
tangential load Q = r mu P on the disc (``statics.tangential_body_force``, its line of action moved
through the centre of pressure) in n increments. Two identical bodies have Dundurs' beta = 0: the
normal and tangential problems uncouple and Cattaneo and Mindlin's line contact holds exactly in
the half-plane limit, a stick zone |x| < c with c = a sqrt(1 - Q / (mu P)).

Measured per run (the static run's summary, static_simulation._pair_friction_summary): c, the
moment measure of the deficit mu N_p - |T_p| over the pairs (point forces at the pairs'
positions), against c_exact with a the moment measure of the N_p of the same solution; the pairs
in contact, stick and slip; the disc's friction force and all its contact forces along the load
over Q (the frictionless pair forces' tangential part, eq. (34)'s sliding force among them, is
the difference); the range of |T_p| / (mu N_p) on the slip pairs.

    .venv/bin/python validation/cattaneo_mindlin_bodies.py --out docs/validation/cattaneo_mindlin_bodies.json
    .venv/bin/python validation/cattaneo_mindlin_bodies.py --quick --out OUT.json   # h = 0.04 only

It writes the JSON and, next to it, the Markdown page (``--out``'s stem + .md). One process.
"""

import argparse
import json
import pathlib
import tempfile
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import scenes, simulation

MU, LOAD = 0.3, 2e6


def scene(h: float, refine_h: float | None, ratio: float, increments: int) -> dict:
    """The disc on the block (module docstring)."""
    mesh = {"type": "discs", "discs": [[0.0, 0.200001, 0.2]], "rectangles": [[-0.3, -0.2, 0.3, 0.0]], "h": h}
    if refine_h is not None:
        mesh.update({"refine_point": [0.0, 0.0], "refine_h": refine_h, "refine_radius": 0.07})
    return scenes.validate({
        "name": "disc-on-block",
        "method": "dem-A",
        "mesh": mesh,
        "material": {"E": 25e6, "nu": 0.25, "rho": 1.0, "plane": "strain"},
        "loads": {"body_force": [0.0, -LOAD]},
        "dirichlet": [{"boundary": "y <= -0.2", "name": "base"}],
        "contact": {"boundary": ["(y >= -0.1) & (y <= 0.05)"], "friction": MU},
        "statics": {"fixed_mean": [0], "fixed_rotation": True,
                    "tangential_body_force": [ratio * MU * LOAD, 0.0], "increments": increments},
    })


def run(h: float, refine_h: float | None, ratio: float, increments: int) -> dict:
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        summary = simulation.run(scene(h, refine_h, ratio, increments), pathlib.Path(folder) / "run", MPI.COMM_SELF)
    friction = summary["friction"]
    P, Q = friction["contact_force"], friction["tangential_load"][0]
    c_exact = friction["contact_half_width"] * np.sqrt(1 - Q / (MU * P))
    return {
        "h": h, "refine_h": refine_h, "ratio": ratio, "increments": increments, "cells": summary["n_cells"],
        "contact_pairs": summary["contact_pairs"], "stick_pairs": friction["stick_pairs"],
        "slip_pairs": friction["slip_pairs"], "a": friction["contact_half_width"], "c": friction["stick_half_width"],
        "c_over_exact": friction["stick_half_width"] / c_exact, "Q_over_muP": Q / (MU * P),
        "friction_over_load": -friction["friction_force"] / Q,
        "contact_over_load": -friction["contact_tangential_force"] / Q,
        "slip_traction_ratio": friction["slip_traction_ratio"], "state_iterations": friction["state_iterations"],
        "wall_time_s": time.perf_counter() - start,
    }


def page(data: dict) -> str:
    lines = [
        "# Cattaneo-Mindlin partial slip between two elastic bodies (statics with friction)",
        "",
        "The hertz scene's disc on an elastic block of its material clamped at its base, friction mu = 0.3",
        "between them (statics/pair_friction.py, docs/theory.md \"Statics with friction\"): the normal load P,",
        "then the tangential load Q = r mu P on the disc in n increments, each the incremental Coulomb",
        "solution. Identical bodies uncouple the normal and tangential problems (Dundurs' beta = 0):",
        "Cattaneo-Mindlin's stick zone |x| < c, c = a sqrt(1 - Q / (mu P)). `c / c_ex` is the moment measure",
        "of the deficit mu N_p - |T_p| over c_ex with a the moment measure of the pairs' normal forces N_p.",
        "`F / Q` is the friction on the disc along the load over Q, `C / Q` all its contact forces along it",
        "(equilibrium: 1), so 1 - F / Q is what the frictionless pair forces carry. Meshes: uniform h, or",
        "refined to h_r within 0.07 m of the contact.",
        "",
        "| h (m) | h_r (m) | r | n | cells | pairs in contact | stick / slip | c / c_ex | F / Q | C / Q - 1 "
        "| T / (mu N) on slip | state iterations | wall (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["runs"]:
        ratio = r["slip_traction_ratio"]
        lines.append(
            f"| {r['h']} | {r['refine_h'] or '-'} | {r['ratio']} | {r['increments']} | {r['cells']} "
            f"| {r['contact_pairs']} | {r['stick_pairs']} / {r['slip_pairs']} | {r['c_over_exact']:.4f} "
            f"| {r['friction_over_load']:.4f} | {r['contact_over_load'] - 1:.1e} "
            f"| {min(ratio):.10f} - {max(ratio):.10f} | {max(r['state_iterations'])} (max) "
            f"| {r['wall_time_s']:.1f} |")
    lines += ["", *findings(data["runs"]), "", "Reproduce:", "",
              "    .venv/bin/python validation/cattaneo_mindlin_bodies.py --out "
              "docs/validation/cattaneo_mindlin_bodies.json", ""]
    return "\n".join(lines)


def findings(runs: list[dict]) -> list[str]:
    """The page's reading of the table (the full study's rows; the quick run has only the first)."""
    uniform = [r for r in runs if r["refine_h"] is None]
    refined = [r for r in runs if r["refine_h"] is not None and r["ratio"] == 0.5]
    loads = [r for r in runs if r["refine_h"] == 0.01]
    if not refined:
        return []

    def listed(rows, key, form="{}"):
        return ", ".join(form.format(r[key]) for r in rows)

    share = [1 - r["friction_over_load"] for r in runs]
    balance = max(abs(r["contact_over_load"] - 1) for r in runs)
    law = max(abs(x - 1) for r in runs for x in r["slip_traction_ratio"])
    return [
        f"On uniform meshes (h = {listed(uniform, 'h')} m: {listed(uniform, 'contact_pairs')} pairs in contact) "
        f"c / c_ex = {listed(uniform, 'c_over_exact', '{:.4f}')}: not monotone, the contact zone's few pairs and "
        "their overlaps with the other body's facets vary from mesh to mesh. Refined near the contact (h_r = "
        f"{listed(refined, 'refine_h')} m: {listed(refined, 'contact_pairs')} pairs) c / c_ex = "
        f"{listed(refined, 'c_over_exact', '{:.4f}')}, and at h_r = 0.01 m for Q / (mu P) = "
        f"{listed(loads, 'ratio')}: {listed(loads, 'c_over_exact', '{:.4f}')}. The friction alone does not "
        "balance Q: the frictionless pair forces have a tangential part (eq. (34)'s sliding force, proportional "
        "to the gap, which reaches a tenth of the overlap at the hertz scene's strain), carrying "
        f"{100 * min(share):+.0f} to {100 * max(share):+.0f} % of Q here; all the disc's contact forces balance "
        f"it to {balance:.0e}, and the slip pairs carry mu N_p to {law:.0e} (the iteration's bound tolerance "
        "1e-10). The cost is the pair statics' (its Hessian assembled pair by pair in Python): "
        f"{max(r['wall_time_s'] for r in runs):.0f} s for the largest run.",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="h = 0.04 uniform (the first row of the full study)")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args()
    cases = [(0.04, None, 0.5, 5)]
    if not args.quick:
        cases += [(0.02, None, 0.5, 5), (0.01, None, 0.5, 5), (0.04, 0.01, 0.5, 5), (0.04, 0.005, 0.5, 5),
                  (0.04, 0.01, 0.25, 5), (0.04, 0.01, 0.75, 5)]
    data = {"mu": MU, "runs": [run(*case) for case in cases]}
    args.out.write_text(json.dumps(data, indent=1))
    args.out.with_suffix(".md").write_text(page(data))


if __name__ == "__main__":
    main()
