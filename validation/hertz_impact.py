"""Hertz impact of two elastic balls (issue 33): the DEM's and the FEM peer's contact duration, largest approach,
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
h = 0.03 m elsewhere; each level is run with schemes A and B and eta = E and 10 E (``--etas``), and with
the DEM's contact surface ``--surfaces`` (scene key ``contact.surface``, default "facet", set on every
DEM run: the scene's own is "vertex"; "vertex": contact/surface.py, docs/theory.md). Each row records its ``surface`` (None for fem-P1, which has its
own); the rows made before it was recorded have none and are facet-surface runs. The comparisons
between runs (scheme A and B, eta = E and 10 E, the levels of a variant) pair runs of the same
surface, and the page compares, at each level, each vertex-surface run with the facet-surface runs
of its method at eta = E and 10 E.
The energy error ``energy_end`` is the pseudo-energy's relative change from the first to the last
row (the DEM rows made before it was measured show "-"; their drift, the largest change over the
run relative to the largest mechanical energy, bounds it).

The FEM peer (``--methods fem-P1``, one row per level, no eta: the scene's ``material.eta`` and
``contact.surface`` are dropped) runs the same scene on the same mesh (P1 tetrahedra, lumped mass, central differences,
symmetric node-to-facet penalty between the balls, dolfinx_dem/fem/) and writes the same
columns, measured the same way, with two differences of meaning: the pair force is the sum of
the penalty forces of ball 1 on ball 0 (nonzero while a node of either ball is behind a facet of
the other), and the probes are the P1 displacement at the centre point, not a cell's. Its
pseudo-energy (central differences' modified energy plus the penalty energy) is not conserved
with contact (fem/penalty.py): its drift and ``energy_end`` are its energy error.

The page compares the FEM and the DEM at equal refine_h, tabulates each run against the finest
fem-P1 level as well as against Hertz, and the chart ``<out stem>_work_precision.png`` plots
|duration error| and |approach error| against Hertz versus the wall time of each run (log-log),
a line per method and eta through its levels. The wall times are those of the runs as made (one
process, a 2-core machine shared with other jobs): the DEM and fem-P1 rows were made in
different processes at different times.

    .venv/bin/python validation/hertz_impact.py --out docs/validation/hertz_impact.json
    .venv/bin/python validation/hertz_impact.py --quick --out OUT.json   # refine_h 0.01: dem-B eta = 10 E, fem-P1
    .venv/bin/python validation/hertz_impact.py --levels 0.006 0.004 --methods fem-P1 --append \\
        --out docs/validation/hertz_impact.json                   # the FEM peer's rows
    .venv/bin/python validation/hertz_impact.py --page-only --out docs/validation/hertz_impact.json
    .venv/bin/python validation/hertz_impact.py --levels 0.006 --methods dem-A --etas 100 --radius 0.06 \\
        --append --out docs/validation/hertz_impact.json          # more runs in the same tables
    .venv/bin/python validation/hertz_impact.py --levels 0.006 0.004 --methods dem-B dem-A --etas 100 \\
        --surfaces vertex --append --out docs/validation/hertz_impact.json   # the vertex surface

It writes the JSON and, next to it, the Markdown page (``--out``'s stem + .md) and the chart;
``--page-only`` rewrites the page and the chart from the JSON without running. One process per run.
"""

import argparse
import itertools
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
        radius: float = 0.03, surface: str = "facet") -> dict:
    reference = hertz(v)
    end = GAP / v + 1.5 * reference["duration"]
    fem = method.startswith("fem")  # fem-P1 has no stabilisation: the scene's material.eta dropped, eta None
    eta, surface = (None, None) if fem else (eta, surface)  # fem-P1 has its own facets: the scene's surface dropped
    scene = scenes.load("two-balls", ({} if fem else {"material.eta": eta, "contact.surface": surface}) | {
        "method": method, "mesh.balls": [[LEFT, 0.0, 0.0, R], [RIGHT, 0.0, 0.0, R]],
        "mesh.h": h, "mesh.refine_h": refine_h, "mesh.refine_radius": radius, "initial.velocity": [
            f"where(x < 0.25, {v / 2!r}, {-v / 2!r})", "0", "0"], "time.cfl": cfl, "time.end": end,
        "output.every": 100000, "probes": [{"name": "left", "point": [LEFT, 0.0, 0.0], "component": 0},
                                           {"name": "right", "point": [RIGHT, 0.0, 0.0], "component": 0}]})
    if fem:
        scene["material"].pop("eta", None)
        scene["contact"].pop("surface", None)
    out = work / f"{method}-{eta}-{surface}-{refine_h:g}-{h:g}-{radius:g}"
    start = time.perf_counter()
    row = {"h": h, "refine_h": refine_h, "refine_radius": radius, "method": method, "eta": eta, "surface": surface}
    try:
        summary = simulation.run(scene, out, quiet=True, overwrite=True)
    except UnresolvedContactError as err:
        return row | {"error": str(err).split(". Eq.")[0]}
    if summary["status"] != "completed":  # a signal stops a run cleanly: not a result
        return row | {"error": f"run {summary['status']} at step {summary['n_steps']}"}
    series = np.genfromtxt(out / "series.csv", delimiter=",", names=True)
    t, force = series["t"], series["contact_force_0_1_x"]
    on = np.flatnonzero(force != 0.0)
    impulse = float(np.trapz(np.abs(force), t))
    return row | ({"nodes": summary["n_nodes"]} if "n_nodes" in summary else {}) | {
        "cells": summary["n_cells"], "candidates": summary["contact_candidate_facets"], "steps": summary["n_steps"],
        "dt": summary["dt"], "duration": float(t[on[-1]] - t[on[0]]), "force": float(np.abs(force).max()),
        "approach": float((series["left"] - series["right"]).max() - GAP),
        "restitution": impulse / (reference["m_star"] * v) - 1.0, "drift": summary["pseudo_energy_rel_drift"],
        "energy_end": float(series["pseudo_energy"][-1] / series["pseudo_energy"][0] - 1), "wall_s": time.perf_counter() - start}


def surface(r: dict) -> str | None:
    """A DEM run's contact.surface ("facet" for the rows made before it was recorded); None for fem-P1."""
    return None if r["method"].startswith("fem") else r.get("surface") or "facet"


def series_label(r: dict) -> str:
    """The chart's series of a run: its method and eta, its surface where not the default facet one, and h or
    radius where not the study's 0.03 m."""
    label = r["method"] + ("" if r["eta"] is None else f", eta = {r['eta'] / E:g} E") + (
        "" if surface(r) in (None, "facet") else f", {surface(r)} surface")
    extra = [f"{k} {r[k]:g}" for k in ("h", "refine_radius") if r.get(k, 0.03) != 0.03]
    return label + (f" ({', '.join(extra)})" if extra else "")


def chart(results: dict, path: pathlib.Path) -> None:
    """|duration error| and |approach error| against Hertz versus the wall time, log-log, a line per
    method and eta through its levels, each point labelled with its refine_h."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref = results["hertz"]
    groups: dict[str, list[dict]] = {}
    for r in results["runs"]:
        if "error" not in r:
            groups.setdefault(series_label(r), []).append(r)
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.4))
    markers = "osD^v<>ph*"
    for i, (label, rows) in enumerate(groups.items()):
        rows = sorted(rows, key=lambda r: r["wall_s"])
        wall = [r["wall_s"] for r in rows]
        for ax, key in zip(axes, ("duration", "approach")):
            err = [abs(r[key] / ref[key] - 1) for r in rows]
            ax.loglog(wall, err, marker=markers[i % len(markers)], ls="-" if len(rows) > 1 else "none",
                      label=label, **({"color": "k", "lw": 2} if label.startswith("fem") else {}))
            for x, y, r in zip(wall, err, rows):
                ax.annotate(f"{r['refine_h']:g}", (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
    for ax, key in zip(axes, ("duration", "approach")):
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel(f"|{key} / Hertz - 1|")
        ax.set_title("largest approach" if key == "approach" else "contact duration")
        ax.grid(True, which="both", alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle(f"Hertz impact, v/c = {results['speed']:g}: error against wall time (labels: refine_h, m; "
                 "DEM contact surface facet unless named)")
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def rel(r: dict, ref: dict, key: str) -> float:
    return r[key] / ref[key] - 1


def study(r: dict) -> bool:
    """A run of the refinement study (h = radius = 0.03 m) that finished."""
    return "error" not in r and r.get("h", 0.03) == 0.03 and r.get("refine_radius", 0.03) == 0.03


def head(r: dict, ref: dict) -> str:
    eta = "-" if r["eta"] is None else f"{r['eta'] / E:g}"
    return (f"| {r.get('h', 0.03):g}, {r['refine_h']:g}, {r.get('refine_radius', 0.03):g} | "
            f"{ref['contact_radius'] / r['refine_h']:.2g} | {r['method']} | {eta} | {surface(r) or '-'} |")


def fem_tables(results: dict) -> list[str]:
    """The runs against the finest fem-P1 level of the study, and fem-P1 against the DEM at equal levels."""
    ref, runs = results["hertz"], results["runs"]
    fem = sorted((r for r in runs if study(r) and r["method"] == "fem-P1"), key=lambda r: r["refine_h"])
    if not fem:
        return []
    best = fem[0]
    lines = ["", f"## Against the finest fem-P1 level (refine_h = {best['refine_h']:g} m)", ""]
    if len(fem) > 1:
        lines += [f"Between its two finest levels (refine_h = {fem[1]['refine_h']:g} and {best['refine_h']:g} m) "
                  f"fem-P1's duration changed by {best['duration'] / fem[1]['duration'] - 1:+.2%}, its approach by "
                  f"{best['approach'] / fem[1]['approach'] - 1:+.2%} and its force by "
                  f"{best['force'] / fem[1]['force'] - 1:+.2%}: the reference is not converged to better than "
                  "that.", ""]
    lines += ["| h, refine_h, radius (m) | a / refine_h | method | eta / E | surface | duration | approach | force | "
              "restitution - fem's |", "|---|---|---|---|---|---|---|---|---|"]
    lines += [f"{head(r, ref)} {rel(r, best, 'duration'):+.2%} | {rel(r, best, 'approach'):+.2%} | "
              f"{rel(r, best, 'force'):+.2%} | {r['restitution'] - best['restitution']:+.4f} |"
              for r in runs if "error" not in r]
    lines += ["", "## fem-P1 and the DEM against Hertz at equal levels", ""]
    for f in fem[::-1]:
        dem = [r for r in runs if study(r) and r["method"] != "fem-P1" and r["refine_h"] == f["refine_h"]]
        if not dem:
            continue
        text = [f"At refine_h = {f['refine_h']:g} m fem-P1 is at"]
        for key in ("duration", "approach", "force"):
            errors = sorted(rel(r, ref, key) for r in dem)
            text.append(f"{rel(f, ref, key):+.2%} in the {key} (the DEM's {len(dem)} runs {errors[0]:+.2%} to "
                        f"{errors[-1]:+.2%}){',' if key != 'force' else ';'}")
        text.append(f"its restitution is {f['restitution']:.4f} (the DEM's {min(r['restitution'] for r in dem):.4f}"
                    f" to {max(r['restitution'] for r in dem):.4f}), its energy error {f['energy_end']:+.1e} "
                    f"(largest drift {f['drift']:.1e}; the DEM's drift at most "
                    f"{max(r['drift'] for r in dem):.0e}); it took {f['steps']} steps in {f['wall_s']:.0f} s (the "
                    f"DEM {min(r['steps'] for r in dem)} to {max(r['steps'] for r in dem)} steps in "
                    f"{min(r['wall_s'] for r in dem):.0f} to {max(r['wall_s'] for r in dem):.0f} s).")
        lines += [" ".join(text), ""]
    return lines


def variant(r: dict) -> str:
    """A run's method and eta, and its surface where not the default facet one."""
    eta = "" if r["eta"] is None else f" eta = {r['eta'] / E:g} E"
    return r["method"] + eta + ("" if surface(r) in (None, "facet") else f" ({surface(r)} surface)")


def spread(pairs: list[tuple[dict, dict]], ref: dict, key: str) -> str:
    """The range of |error(a)| - |error(b)| in percentage points over the pairs (a, b)."""
    d = sorted(100 * (abs(rel(a, ref, key)) - abs(rel(b, ref, key))) for a, b in pairs)
    return f"{d[0]:+.1f} to {d[-1]:+.1f}" if d else "(not run)"


def findings(results: dict) -> list[str]:
    """Which DEM runs are farther from Hertz than fem-P1 at their level, and the differences between the
    DEM's variants that the table measures (the only reasons this page can support)."""
    ref = results["hertz"]
    runs = [r for r in results["runs"] if study(r)]
    fem = {r["refine_h"]: r for r in runs if r["method"] == "fem-P1"}
    dem = [r for r in runs if r["method"] != "fem-P1" and r["refine_h"] in fem]
    if not dem:
        return []
    farther = [r for r in dem if any(abs(rel(r, ref, k)) > abs(rel(fem[r["refine_h"]], ref, k))
                                     for k in ("duration", "approach"))]
    nearer = [r for r in dem if r not in farther]
    key = {(r["method"], r["eta"], r["refine_h"], surface(r)): r for r in dem}
    scheme = [(b, key[("dem-A", b["eta"], b["refine_h"], surface(b))]) for b in dem
              if b["method"] == "dem-B" and ("dem-A", b["eta"], b["refine_h"], surface(b)) in key]
    eta = [(r, key[(r["method"], E, r["refine_h"], surface(r))]) for r in dem
           if r["eta"] == 10 * E and (r["method"], E, r["refine_h"], surface(r)) in key]
    name = lambda r: f"{variant(r)} at {r['refine_h']:g} m"  # noqa: E731
    lines = ["**Where the DEM is farther from Hertz than fem-P1.** " + (
        f"In the duration or the approach: {', '.join(name(r) for r in farther)}; nearer in both: "
        f"{', '.join(name(r) for r in nearer) or 'none'}. " if farther else
        "Nowhere in the duration and the approach at the levels run. ")
        + "What the table measures about them: scheme B's |error| exceeds scheme A's at the same level and "
        f"eta by {spread(scheme, ref, 'duration')} points in the duration and {spread(scheme, ref, 'approach')} "
        f"in the approach; eta = 10 E's exceeds eta = E's by {spread(eta, ref, 'duration')} and "
        f"{spread(eta, ref, 'approach')} points."
        + (" So the DEM runs farther from Hertz than fem-P1 are all scheme B's, the stiffer scheme "
           "(docs/validation/scheme_b.md attributes its stiffer contact to its boundary cells moving rigidly; not "
           "measured here), and scheme A is nearer to Hertz than fem-P1 at every level run."
           if farther and all(r["method"] == "dem-B" for r in farther)
           and all(r["method"] == "dem-B" for r in dem if r not in nearer) and any(
               r["method"] == "dem-A" for r in nearer) and all(r in nearer for r in dem if r["method"] == "dem-A")
           else ""), ""]
    levels = sorted(fem, reverse=True)
    variants: dict[tuple, list[dict]] = {}
    for r in runs:
        variants.setdefault((r["method"], r["eta"], surface(r)), []).append(r)
    change = max(100 * abs(rel(a, ref, k) - rel(b, ref, k)) for rows in variants.values() for a in rows
                 for b in rows for k in ("duration", "approach"))
    bulk = [r for r in results["runs"] if "error" not in r and r.get("h", 0.03) != 0.03
            and r.get("refine_radius", 0.03) == 0.03]
    coarse = {(r["method"], r["eta"], r["refine_h"], surface(r)): r for r in runs}

    def finer(r: dict) -> str:
        c = coarse.get((r["method"], r["eta"], r["refine_h"], surface(r)))
        text = (f"; with h = {r['h']:g} m (refine_h {r['refine_h']:g} m) {variant(r)}'s restitution is "
                f"{r['restitution']:.4f}, its duration and approach errors {rel(r, ref, 'duration'):+.2%} and "
                f"{rel(r, ref, 'approach'):+.2%}")
        return text + (f" (with h = 0.03 m {c['restitution']:.4f}, {rel(c, ref, 'duration'):+.2%} and "
                       f"{rel(c, ref, 'approach'):+.2%})" if c else "")

    fem_bulk = any(r["method"] == "fem-P1" for r in bulk)
    lines += ["**What both share.** On the same meshes fem-P1 and every DEM variant end the contact early "
              "and approach less than Hertz (fem-P1's duration and approach errors: "
              + ", ".join(f"{rel(fem[h], ref, 'duration'):+.2%} and {rel(fem[h], ref, 'approach'):+.2%} at {h:g} m"
                          for h in levels)
              + f"), and refining the contact zone changes no variant's duration or approach error by more than "
              f"{change:.1f} points between the levels run. Their restitutions are alike (fem-P1 "
              + ", ".join(f"{fem[h]['restitution']:.4f}" for h in levels)
              + f", the DEM {min(r['restitution'] for r in dem):.4f} to {max(r['restitution'] for r in dem):.4f} at "
              "the same levels) on the same bulk mesh (h = 0.03 m)" + "".join(finer(r) for r in bulk)
              + ("" if fem_bulk else "; fem-P1 with a finer bulk is not measured")
              + ". Whether the shortfall both share is Hertz's half-space and parabolic-profile assumptions (a / R "
              f"= {ref['contact_radius'] / R:.2f}) or the discretisation is not settled by these runs"
              + ("" if fem_bulk else " (fem-P1 with a finer bulk is not measured)")
              + "; hertz_impact_slow.md has runs at half the speed, discussed in contact3d.md.", "",
              "**Energy.** fem-P1 is not energy-exact: its pseudo-energy changed by "
              + ", ".join(f"{fem[h]['energy_end']:+.1e} at {h:g} m" for h in levels if "energy_end" in fem[h])
              + f" from before to after the impact; the DEM's largest drift is {max(r['drift'] for r in dem):.0e}. "
              "fem-P1's largest force changes most between its levels: "
              + ", ".join(f"{rel(fem[h], ref, 'force'):+.2%} at {h:g} m" for h in levels) + ".", ""]
    return lines


def vertex_sentences(results: dict) -> list[str]:
    """At each level of the study with vertex-surface runs, each such run against the facet-surface runs of
    its method at eta = E and 10 E: duration, approach and force against Hertz and the finest fem-P1 level."""
    ref, runs = results["hertz"], [r for r in results["runs"] if study(r)]
    vertex = [r for r in runs if surface(r) == "vertex"]
    if not vertex:
        return []
    fem = sorted((r for r in runs if r["method"] == "fem-P1"), key=lambda r: r["refine_h"])
    keys = ("duration", "approach", "force")

    def errors(r: dict) -> str:
        text = f"{' / '.join(f'{rel(r, ref, k):+.2%}' for k in keys)} against Hertz"
        return text + (f", {' / '.join(f'{rel(r, fem[0], k):+.2%}' for k in keys)} against fem-P1" if fem else "")

    lines = ["**The vertex surface.** Duration / approach / force against Hertz" + (
        f" and against the finest fem-P1 level (refine_h = {fem[0]['refine_h']:g} m)" if fem else "")
        + ", each vertex-surface run against the facet-surface runs of its method at eta = E and 10 E."]
    for level in sorted({r["refine_h"] for r in vertex}, reverse=True):
        text = []
        for v in (r for r in vertex if r["refine_h"] == level):
            facet = [r for r in runs if r["refine_h"] == level and r["method"] == v["method"]
                     and surface(r) == "facet" and r["eta"] in (E, 10 * E)]
            text.append(f"{variant(v)}: {errors(v)}; "
                        + ("; ".join(f"facet eta = {r['eta'] / E:g} E: {errors(r)}"
                                     for r in sorted(facet, key=lambda r: r["eta"])) or "no facet run"))
        lines.append(f"At refine_h = {level:g} m, " + "; ".join(text) + ".")
    return [" ".join(lines), ""]


def page(results: dict, chart_name: str | None = None) -> str:
    ref = results["hertz"]
    made = ", then ".join(f"`{c}`" for c in results["commands"])
    lines = ["# Hertz impact of two balls", "",
             f"Made by {made} (validation/hertz_impact.py, one process per run; its docstring says what is "
             "measured and how).", "",
             f"Approach speed v = {results['speed']:g} m/s (v/c = {results['speed']:g}), CFL {results['cfl']:g}. "
             f"Hertz: duration {ref['duration']:.4g} s, largest approach {ref['approach']:.4g} m, largest force "
             f"{ref['force']:.4g} N, contact radius a = {ref['contact_radius']:.4g} m, restitution 1.", "",
             "| h, refine_h, radius (m) | a / refine_h | method | eta / E | surface | cells | steps | duration | "
             "approach | force | restitution | drift | energy | wall (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["runs"]:
        if "error" in r:
            lines.append(f"{head(r, ref)} stopped: {r['error']} |||||||||")
            continue
        energy = f"{r['energy_end']:+.1e}" if "energy_end" in r else "-"
        lines.append(f"{head(r, ref)} {r['cells']} | {r['steps']} | {rel(r, ref, 'duration'):+.2%} | "
                     f"{rel(r, ref, 'approach'):+.2%} | {rel(r, ref, 'force'):+.2%} | "
                     f"{r['restitution']:.4f} | {r['drift']:.1e} | {energy} | {r['wall_s']:.0f} |")
    lines += ["", "Duration, approach and force: relative differences from Hertz. Drift: the largest change of the "
              "pseudo-energy over the run relative to the largest mechanical energy; energy: its relative change "
              "from the first to the last step (\"-\": not recorded for that run)."]
    lines += fem_tables(results) + findings(results) + vertex_sentences(results)
    if chart_name:
        lines += [""] * (lines[-1] != "") + [f"![work-precision]({chart_name})", "",
                                              work_precision_sentence(results, chart_name)]
    return "\n".join(lines) + "\n"


def work_precision_sentence(results: dict, chart_name: str) -> str:
    """What the chart shows, from the study's finest level common to the methods."""
    ref, runs = results["hertz"], [r for r in results["runs"] if study(r)]
    runs = runs or [r for r in results["runs"] if "error" not in r]  # no run of the study: every run
    common = min(r["refine_h"] for r in runs if r["method"] == "fem-P1") if any(
        r["method"] == "fem-P1" for r in runs) else min(r["refine_h"] for r in runs)
    at = sorted((r for r in runs if r["refine_h"] == common), key=lambda r: r["wall_s"])
    points = "; ".join(f"{series_label(r)} {abs(rel(r, ref, 'duration')):.1%} and {abs(rel(r, ref, 'approach')):.1%}"
                       f" in {r['wall_s']:.0f} s" for r in at)
    return (f"[{chart_name}]({chart_name}): |duration error| and |approach error| against Hertz versus each run's "
            f"wall time (one process each, on the shared 2-core machine; the DEM's and fem-P1's rows were "
            f"made at different times), a line per method and eta through its refine_h levels; at refine_h = "
            f"{common:g} m: "
            f"{points}.")


def write(results: dict, out: pathlib.Path) -> None:
    """The page and the chart next to ``out`` (the JSON is written by ``main``)."""
    png = out.with_name(out.stem + "_work_precision.png")
    chart(results, png)
    out.with_suffix(".md").write_text(page(results, png.name))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", type=float, nargs="+", default=[0.006, 0.004, 0.0027], help="refine_h (m)")
    parser.add_argument("--methods", nargs="+", default=["dem-B", "dem-A"])
    parser.add_argument("--etas", type=float, nargs="+", default=[E, 10 * E], help="material.eta (Pa)")
    parser.add_argument("--surfaces", nargs="+", default=["facet"], choices=["facet", "vertex"],
                        help="contact.surface of the DEM runs (fem-P1 has none)")
    parser.add_argument("--h", type=float, default=0.03, help="mesh.h away from the contact zone (m)")
    parser.add_argument("--radius", type=float, default=0.03, help="mesh.refine_radius (m)")
    parser.add_argument("--speed", type=float, default=0.02, help="approach speed (m/s)")
    parser.add_argument("--cfl", type=float, default=0.5)
    parser.add_argument("--quick", action="store_true", help="refine_h 0.01: dem-B eta = 10 E, fem-P1")
    parser.add_argument("--append", action="store_true", help="add the runs to those of --out (same speed, cfl)")
    parser.add_argument("--page-only", action="store_true", help="rewrite the page and chart from --out, no run")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args()
    if args.page_only:
        results = json.loads(args.out.read_text())
        write(results, args.out)
        return
    if args.quick:
        args.levels, args.methods, args.etas = [0.01], ["dem-B", "fem-P1"], [10 * E]
    results = {"speed": args.speed, "cfl": args.cfl, "hertz": hertz(args.speed), "runs": [], "commands": []}
    if args.append:
        results = json.loads(args.out.read_text())
        if (results["speed"], results["cfl"]) != (args.speed, args.cfl):
            raise SystemExit(f"{args.out} has speed {results['speed']} and cfl {results['cfl']}: append the same")
    with tempfile.TemporaryDirectory() as work:
        for h in args.levels:
            for method in args.methods:
                fem = method.startswith("fem")
                for eta, surface in itertools.product(*([[None]] * 2 if fem else [args.etas, args.surfaces])):
                    results["runs"].append(run(h, method, eta, args.speed, args.cfl, pathlib.Path(work), args.h,
                                               args.radius, surface))
                    print(json.dumps(results["runs"][-1]), flush=True)
    results["commands"].append("validation/hertz_impact.py " + ("--quick" if args.quick else " ".join(
        [f"--levels {' '.join(f'{h:g}' for h in args.levels)}", f"--methods {' '.join(args.methods)}",
         *([f"--etas {' '.join(f'{e:g}' for e in args.etas)}"] if any(m.startswith("dem") for m in args.methods)
           else []), *([f"--surfaces {' '.join(args.surfaces)}"] if any(m.startswith("dem") for m in args.methods)
                       and args.surfaces != ["facet"] else []), f"--h {args.h:g}", f"--radius {args.radius:g}",
         f"--speed {args.speed:g}", f"--cfl {args.cfl:g}"])) + (" --append" if args.append else ""))
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    write(results, args.out)


if __name__ == "__main__":
    main()
