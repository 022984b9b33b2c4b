"""Hertz impact of two elastic balls (issue 33): the DEM's contact duration, largest approach, largest
force and restitution against Hertz's quasi-static theory, under refinement of the contact zone.

The built-in ``two-balls`` (R = 0.1 m, E = 100 Pa, nu = 0.2, rho = 100 kg/m^3, so c = sqrt(E/rho)
= 1 m/s) with its balls 0.002 m apart at t = 0 and an approach speed ``--speed`` (default 0.02 m/s,
v/c = 0.02, where Hertz's theory holds: the contact lasts ~100 wave transits of the contact radius).
With R* = R/2, E* = E / (2 (1 - nu^2)), m* = m/2 (Johnson, Contact Mechanics, §11.4):

    duration  T = 2.87 (m*^2 / (R* E*^2 v))^(1/5)
    approach  delta = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5)
    force     F = 4/3 E* sqrt(R*) delta^(3/2),   restitution 1

Measured from ``series.csv`` (a row every step): the duration, from the first to the last step with
a nonzero pair force ``contact_force_0_1_x``; the largest force; the approach of the ball centres
(probes ``left`` and ``right``, the x displacement of the cells at the centres) minus the initial
gap; the restitution, from the impulse J = int |F| dt (trapezoids) on the left ball, e = J / (m* v) - 1
(its velocity after the impact is v/2 - J/m); the pseudo-energy drift. The contact zone is meshed
at ``refine_h`` within 0.03 m of the contact point (the Hertz contact radius is a = sqrt(R* delta)),
h = 0.03 m elsewhere; each level is run with schemes A and B and eta = E and 10 E (``--etas``).

    .venv/bin/python validation/hertz_impact.py --out docs/validation/hertz_impact.json
    .venv/bin/python validation/hertz_impact.py --quick --out OUT.json   # one coarse level, scheme B, eta = 10 E
    .venv/bin/python validation/hertz_impact.py --levels 0.006 --methods dem-A --etas 100 --radius 0.06 \\
        --append --out docs/validation/hertz_impact.json          # more runs in the same tables

It writes the JSON and, next to it, the Markdown page (``--out``'s stem + .md). One process per run.
"""

import argparse
import json
import math
import pathlib
import tempfile
import time

import numpy as np

from dolfinx_dem import scenes, simulation
from dolfinx_dem.errors import UnresolvedContactError

R, E, NU, RHO, GAP = 0.1, 100.0, 0.2, 100.0, 0.002
LEFT, RIGHT = 0.25 - GAP / 2 - R, 0.25 + GAP / 2 + R  # the balls' centres


def hertz(v: float) -> dict:
    """Hertz's duration, largest approach and force for the approach speed v (module docstring)."""
    r_star, e_star, m_star = R / 2, E / (2 * (1 - NU**2)), RHO * 4 / 3 * math.pi * R**3 / 2
    delta = (15 * m_star * v**2 / (16 * e_star * math.sqrt(r_star))) ** 0.4
    return {"duration": 2.87 * (m_star**2 / (r_star * e_star**2 * v)) ** 0.2, "approach": delta,
            "force": 4 / 3 * e_star * math.sqrt(r_star) * delta**1.5, "contact_radius": math.sqrt(r_star * delta),
            "m_star": m_star}


def run(refine_h: float, method: str, eta: float, v: float, cfl: float, work: pathlib.Path, h: float = 0.03,
        radius: float = 0.03) -> dict:
    reference = hertz(v)
    end = GAP / v + 1.5 * reference["duration"]
    scene = scenes.load("two-balls", {
        "method": method, "material.eta": eta, "mesh.balls": [[LEFT, 0.0, 0.0, R], [RIGHT, 0.0, 0.0, R]],
        "mesh.h": h, "mesh.refine_h": refine_h, "mesh.refine_radius": radius, "initial.velocity": [
            f"where(x < 0.25, {v / 2!r}, {-v / 2!r})", "0", "0"], "time.cfl": cfl, "time.end": end,
        "output.every": 100000, "probes": [{"name": "left", "point": [LEFT, 0.0, 0.0], "component": 0},
                                           {"name": "right", "point": [RIGHT, 0.0, 0.0], "component": 0}]})
    out = work / f"{method}-{eta:g}-{refine_h:g}-{h:g}-{radius:g}"
    start = time.perf_counter()
    row = {"h": h, "refine_h": refine_h, "refine_radius": radius, "method": method, "eta": eta}
    try:
        summary = simulation.run(scene, out, quiet=True, overwrite=True)
    except UnresolvedContactError as err:
        return row | {"error": str(err).split(". Eq.")[0]}
    series = np.genfromtxt(out / "series.csv", delimiter=",", names=True)
    t, force = series["t"], series["contact_force_0_1_x"]
    on = np.flatnonzero(force != 0.0)
    impulse = float(np.trapz(np.abs(force), t))
    return row | {
        "cells": summary["n_cells"], "candidates": summary["contact_candidate_facets"], "steps": summary["n_steps"],
        "dt": summary["dt"], "duration": float(t[on[-1]] - t[on[0]]), "force": float(np.abs(force).max()),
        "approach": float((series["left"] - series["right"]).max() - GAP),
        "restitution": impulse / (reference["m_star"] * v) - 1.0, "drift": summary["pseudo_energy_rel_drift"], "wall_s": time.perf_counter() - start}


def page(results: dict) -> str:
    ref = results["hertz"]
    made = ", then ".join(f"`{c}`" for c in results["commands"])
    lines = ["# Hertz impact of two balls", "",
             f"Made by {made} (validation/hertz_impact.py, one process per run; its docstring says what is "
             "measured and how).", "",
             f"Approach speed v = {results['speed']:g} m/s (v/c = {results['speed']:g}), CFL {results['cfl']:g}. "
             f"Hertz: duration {ref['duration']:.4g} s, largest approach {ref['approach']:.4g} m, largest force "
             f"{ref['force']:.4g} N, contact radius a = {ref['contact_radius']:.4g} m, restitution 1.", "",
             "| h, refine_h, radius (m) | a / refine_h | method | eta / E | cells | steps | duration | approach | "
             "force | restitution | drift | wall (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["runs"]:
        head = (f"| {r.get('h', 0.03):g}, {r['refine_h']:g}, {r.get('refine_radius', 0.03):g} | "
                f"{ref['contact_radius'] / r['refine_h']:.2g} | {r['method']} | {r['eta'] / E:g} |")
        if "error" in r:
            lines.append(f"{head} stopped: {r['error']} ||||||||")
            continue
        lines.append(f"{head} {r['cells']} | {r['steps']} | {r['duration'] / ref['duration'] - 1:+.2%} | "
                     f"{r['approach'] / ref['approach'] - 1:+.2%} | {r['force'] / ref['force'] - 1:+.2%} | "
                     f"{r['restitution']:.4f} | {r['drift']:.1e} | {r['wall_s']:.0f} |")
    lines += ["", "Duration, approach and force: relative differences from Hertz."]
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", type=float, nargs="+", default=[0.006, 0.004, 0.0027], help="refine_h (m)")
    parser.add_argument("--methods", nargs="+", default=["dem-B", "dem-A"])
    parser.add_argument("--etas", type=float, nargs="+", default=[E, 10 * E], help="material.eta (Pa)")
    parser.add_argument("--h", type=float, default=0.03, help="mesh.h away from the contact zone (m)")
    parser.add_argument("--radius", type=float, default=0.03, help="mesh.refine_radius (m)")
    parser.add_argument("--speed", type=float, default=0.02, help="approach speed (m/s)")
    parser.add_argument("--cfl", type=float, default=0.5)
    parser.add_argument("--quick", action="store_true", help="one coarse level, dem-B, eta = 10 E")
    parser.add_argument("--append", action="store_true", help="add the runs to those of --out (same speed, cfl)")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args()
    if args.quick:
        args.levels, args.methods, args.etas = [0.01], ["dem-B"], [10 * E]
    results = {"speed": args.speed, "cfl": args.cfl, "hertz": hertz(args.speed), "runs": [], "commands": []}
    if args.append:
        results = json.loads(args.out.read_text())
        if (results["speed"], results["cfl"]) != (args.speed, args.cfl):
            raise SystemExit(f"{args.out} has speed {results['speed']} and cfl {results['cfl']}: append the same")
    with tempfile.TemporaryDirectory() as work:
        for h in args.levels:
            for method in args.methods:
                for eta in args.etas:
                    results["runs"].append(run(h, method, eta, args.speed, args.cfl, pathlib.Path(work), args.h,
                                               args.radius))
                    print(json.dumps(results["runs"][-1]), flush=True)
    results["commands"].append("validation/hertz_impact.py " + ("--quick" if args.quick else " ".join(
        [f"--levels {' '.join(f'{h:g}' for h in args.levels)}", f"--methods {' '.join(args.methods)}",
         f"--etas {' '.join(f'{e:g}' for e in args.etas)}", f"--h {args.h:g}", f"--radius {args.radius:g}",
         f"--speed {args.speed:g}", f"--cfl {args.cfl:g}"])) + (" --append" if args.append else ""))
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    args.out.with_suffix(".md").write_text(page(results))


if __name__ == "__main__":
    main()
