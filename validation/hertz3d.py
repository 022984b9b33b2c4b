"""3D static Hertz contact: a ball on a rigid plane, DEM against the DOLFINx P2 FEM.

The built-in scene ``hertz3d``: a ball of radius R = 0.2 m, centre (0, 0, R), E = 25 MPa,
nu = 0.25, body force f = 0.3 MN/m^3 downwards, on the rigid plane z = 0; the quarter x, y >= 0
with u_x = 0 on x = 0 and u_y = 0 on y = 0, the mesh refined at the contact point (size h_c
within 0.05 m of the origin, growing to h). Each level s of ``--scales`` divides both sizes by s
(h = 0.04 / s, h_c = 0.01 / s). The DEM (scheme A, ``statics.minimise_energy``) and the FEM
(P2, Nitsche, ``fem.hertz.solve_hertz`` with ``dim=3``) run the same scene (``method = dem-A``
or ``fem-P2``), the FEM on one more level than the DEM; its finest run is the reference.

Reported per run: the contact radius a (moment measure about the z axis,
a = sqrt(5/2 int r^2 p / int p), ``hertz.contact_radius_moments``: for the DEM the facet
pressures are uniform on their triangles, for the FEM the Nitsche multiplier is integrated by
quadrature; for the DEM also ``a_barycentre``, the same moments of its facet forces at the
facets' barycentres, summary key ``contact_radius_barycentre``), the approach -u_z at the top (0, 0, 2R), the contact force on the quarter (in the
JSON), the relative differences against the finest FEM and against Hertz
(a_H = (3 P R / (4 E*))^(1/3), P = f 4/3 pi R^3, delta_H = a_H^2 / R), and the wall times.
Hertz's delta is the approach of points far from the contact; the top of a ball loaded by its
own weight also moves by the compression of the whole ball, so delta_H is a rough scale only.

    .venv/bin/python validation/hertz3d.py [--scales 1 1.41 2] [--fem-extra 2.83]
        [--out docs/validation/hertz3d.json] [--render] [--quick]

writes the JSON and, next to it, hertz3d.md (the table; the command, date and commit); with
``--render`` it runs nothing and rewrites hertz3d.md from the JSON (and from
hertz3d_diagnostics.json, of hertz3d_diagnostics.py, when it is there). ``--quick``: the DEM on
the coarsest level s = 0.5 and the FEM on it and on s = 0.71 and 1 (seconds), for the tests.
"""

import argparse
import datetime
import json
import pathlib
import subprocess
import sys
import time

from mpi4py import MPI

from dolfinx_dem import scenes, simulation
from dolfinx_dem.hertz import hertz_analytic_3d

ROOT = pathlib.Path(__file__).resolve().parents[1]
H, H_CONTACT = 0.04, 0.01


def run(method: str, scale: float, work: pathlib.Path) -> dict:
    scene = scenes.load("hertz3d", {"method": method, "mesh.h": H / scale, "mesh.refine_h": H_CONTACT / scale})
    start = time.perf_counter()
    summary = simulation.run(scene, work / f"{method}-{scale:g}", overwrite=True, quiet=True)
    return {"method": method, "scale": scale, "h": H / scale, "h_contact": H_CONTACT / scale,
            "cells": summary["n_cells"], "a": summary["contact_radius"],
            "a_barycentre": summary.get("contact_radius_barycentre"),  # the DEM's only
            "approach": -summary["top_vertical_displacement"], "contact_force": summary["contact_force"],
            "iterations": summary["iterations"], "wall_s": time.perf_counter() - start}


def table(results: dict) -> str:
    ref = results["fem"][-1]
    hz = results["hertz"]
    lines = ["| method | h (m) | h_c (m) | cells | a (m) | approach (m) | a - FEM | approach - FEM | a - Hertz "
             "| approach - Hertz | iterations | wall (s) |", "|" + "---|" * 12]
    for row in results["dem"] + results["fem"]:
        rel = lambda key, r, row=row: f"{100 * (row[key] / r - 1):+.2f}%"  # noqa: E731
        lines.append(f"| {'DEM, scheme A' if row['method'] == 'dem-A' else 'FEM P2'} | {row['h']:.4g} "
                     f"| {row['h_contact']:.4g} | {row['cells']} | {row['a']:.5e} | {row['approach']:.5e} "
                     f"| {rel('a', ref['a'])} | {rel('approach', ref['approach'])} | {rel('a', hz['a'])} "
                     f"| {rel('approach', hz['approach'])} | {row['iterations']} | {row['wall_s']:.1f} |")
    lines.append(f"| Hertz | - | - | - | {hz['a']:.5e} | {hz['approach']:.5e} | - | - | - | - | - | - |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scales", type=float, nargs="+", default=[1.0, 1.41, 2.0])
    parser.add_argument("--fem-extra", type=float, nargs="*", default=[2.83],
                        help="further levels for the FEM only (its finest is the reference)")
    parser.add_argument("--out", default=str(ROOT / "docs" / "validation" / "hertz3d.json"))
    parser.add_argument("--work", default="results/validation-hertz3d", help="folder of the runs' outputs")
    parser.add_argument("--render", action="store_true",
                        help="no runs: rewrite the markdown (and the derived figures) from the JSON --out")
    parser.add_argument("--quick", action="store_true", help="--scales 0.5 --fem-extra 0.71 1 (seconds)")
    args = parser.parse_args()
    if args.quick:
        args.scales, args.fem_extra = [0.5], [0.71, 1.0]
    if args.render:
        out = pathlib.Path(args.out)
        write(json.loads(out.read_text()), out)
        return
    comm = MPI.COMM_WORLD
    work = pathlib.Path(args.work)
    scene = scenes.load("hertz3d")
    m, (*_, R) = scene["material"], scene["mesh"]["balls"][0]
    hz = hertz_analytic_3d(R, m["E"], m["nu"], -scene["loads"]["body_force"][2])
    results = {
        **stamp(sys.argv[1:]),
        "processes": comm.size,
        "hertz": {"a": hz.a, "approach": hz.approach, "load": hz.load, "p0": hz.p0},
        "dem": [run("dem-A", s, work) for s in args.scales],
        "fem": [run("fem-P2", s, work) for s in args.scales + args.fem_extra],
    }
    if comm.rank == 0:
        write(results, pathlib.Path(args.out))


def stamp(argv: list) -> dict:
    """The command, date and commit of this invocation."""
    return {"command": " ".join([".venv/bin/python", "validation/hertz3d.py"] + argv),
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                     text=True).stdout.strip()}


def write(results: dict, out: pathlib.Path) -> None:
    """Add the derived figures (Aitken, a at the exact load, the barycentre measure of runs made
    before the summary had it, criteria) and write the JSON and the markdown."""
    results["fem_aitken"] = {key: aitken([r[key] for r in results["fem"][-3:]]) for key in ("a", "approach")}
    quarter = results["hertz"]["load"] / 4.0
    diagnostics = out.with_name("hertz3d_diagnostics.json")
    diagnostics = json.loads(diagnostics.read_text())["rows"] if diagnostics.exists() else []
    for row in results["dem"]:
        if row.get("a_barycentre") is None:
            # the same mesh and solution in hertz3d_diagnostics.json: its uniform a must be this a
            same = [d for d in diagnostics if d["method"] == row["method"] and d["scale"] == row["scale"]
                    and abs(d["a_uniform"] / row["a"] - 1) < 1e-9]
            if same:
                row["a_barycentre"], row["a_barycentre_source"] = same[0]["a_point"], "hertz3d_diagnostics.json"
    for row in results["dem"] + results["fem"]:
        row["a_exact_load"] = row["a"] * (quarter / row["contact_force"]) ** (1.0 / 3.0)
    ref = results["fem"][-1]
    dem_a = [abs(r["a"] / ref["a"] - 1) for r in results["dem"]]
    dem_d = [abs(r["approach"] / ref["approach"] - 1) for r in results["dem"]]
    results["criteria"] = {
        "dem_finest_a_within_5pct_of_fem": dem_a[-1] < 0.05,
        "dem_finest_approach_within_5pct_of_fem": dem_d[-1] < 0.05,
        "dem_a_difference_decreasing": all(x > y for x, y in zip(dem_a, dem_a[1:])),
        "dem_approach_difference_decreasing": all(x > y for x, y in zip(dem_d, dem_d[1:])),
    }
    results["diagnostics"] = {key: {"values": values, "holds": all(abs(x) > abs(y) for x, y in zip(values, values[1:]))}
                              for key, values in error_terms(results).items()}
    force = max(abs(f) for f in same_mesh(results)["contact_force"])
    results["diagnostics"]["dem_contact_force_over_fem_minus_1"] = {"values": [force], "holds": force < 1e-9}
    out.write_text(json.dumps(results, indent=2) + "\n")
    out.with_suffix(".md").write_text(markdown(results))


def same_mesh(results: dict) -> dict:
    """Ratios DEM / FEM - 1 on the same mesh (the FEM run of the same level) of a, the approach
    and the contact force."""
    fem = {r["scale"]: r for r in results["fem"]}
    return {key: [r[key] / fem[r["scale"]][key] - 1 for r in results["dem"]]
            for key in ("a", "approach", "contact_force")}


def error_terms(results: dict) -> dict:
    """The DEM's a against the FEM per level (relative): of the finest FEM run; both at the exact
    load P (a (P/4 / F)^(1/3)); the FEM on the same mesh; the barycentre measure, raw and at P."""
    ref, quarter = results["fem"][-1], results["hertz"]["load"] / 4.0
    dem = results["dem"]
    terms = {
        "a_minus_fem": [r["a"] / ref["a"] - 1 for r in dem],
        "a_at_P_minus_fem_at_P": [r["a_exact_load"] / ref["a_exact_load"] - 1 for r in dem],
        "a_minus_fem_on_the_same_mesh": same_mesh(results)["a"],
    }
    if all(r.get("a_barycentre") is not None for r in dem):
        terms["a_barycentre_minus_fem"] = [r["a_barycentre"] / ref["a"] - 1 for r in dem]
        terms["a_barycentre_at_P_minus_fem_at_P"] = [
            r["a_barycentre"] * (quarter / r["contact_force"]) ** (1 / 3) / ref["a_exact_load"] - 1 for r in dem]
    return terms


def error_table(results: dict) -> str:
    quarter = results["hertz"]["load"] / 4.0
    terms = error_terms(results)
    names = list(terms)
    lines = ["| method | s | cells | F / (P/4) - 1 | " + " | ".join(n.replace("_", " ") for n in names) + " |",
             "|" + "---|" * (4 + len(names))]
    for k, r in enumerate(results["dem"]):
        lines.append(f"| DEM, scheme A | {r['scale']:g} | {r['cells']} | {100 * (r['contact_force'] / quarter - 1):+.3f}% | "
                     + " | ".join(f"{100 * terms[n][k]:+.3f}%" for n in names) + " |")
    ref = results["fem"][-1]
    for r in results["fem"]:
        lines.append(f"| FEM P2 | {r['scale']:g} | {r['cells']} | {100 * (r['contact_force'] / quarter - 1):+.3f}% "
                     f"| {100 * (r['a'] / ref['a'] - 1):+.3f}% | {100 * (r['a_exact_load'] / ref['a_exact_load'] - 1):+.3f}% "
                     + "| - " * (len(names) - 2) + "|")
    return "\n".join(lines)


def markdown(results: dict) -> str:
    criteria = "\n".join(f"| {k.replace('_', ' ')} | **{'holds' if v else 'fails'}** |"
                         for k, v in results["criteria"].items())
    diagnostics = "\n".join(f"| {k.replace('_', ' ')} | {values(v['values'])} | {'yes' if v['holds'] else 'no'} |"
                             for k, v in results["diagnostics"].items())
    return f"""# 3D static Hertz contact: a ball on a rigid plane, DEM against P2 FEM

Made by `{results['command']}` ({results['processes']} process{'es' if results['processes'] > 1 else ''}; run on {results['date']},
commit {results['commit']}); the numbers are in [`hertz3d.json`](hertz3d.json). The same command
with `--render` rewrites this page from the JSON without running anything.

{__doc__.split(chr(10) + chr(10), 1)[1].rsplit(chr(10) + chr(10) + "    ", 1)[0]}

Hertz: P = {results['hertz']['load']:.5g} N (the whole ball), a = {results['hertz']['a']:.5e} m,
delta = {results['hertz']['approach']:.5e} m. The relative differences are against the finest FEM
run and against Hertz. `wall` is the wall time of the whole run (mesh, solve, output files and
picture) on a shared 2-core machine: orders of magnitude, not careful benchmarks.

## Results

{table(results)}

The FEM reference converges: successive changes of a {changes(results['fem'], 'a')}, of the
approach {changes(results['fem'], 'approach')} (relative to the finer run). Aitken's extrapolation of
its three finest runs: a = {results['fem_aitken']['a']:.5e} m, approach =
{results['fem_aitken']['approach']:.5e} m; the finest DEM run differs from these by
{100 * (results['dem'][-1]['a'] / results['fem_aitken']['a'] - 1):+.2f}% (a) and
{100 * (results['dem'][-1]['approach'] / results['fem_aitken']['approach'] - 1):+.2f}% (approach).

DEM differences from the finest FEM run, a: {diffs(results['dem'], results['fem'][-1], 'a')}; approach:
{diffs(results['dem'], results['fem'][-1], 'approach')}. The approach differences change by the ratios
{ratios(results['dem'], results['fem'][-1], 'approach')} between successive levels; the a differences
{'decrease as well' if results['criteria']['dem_a_difference_decreasing'] else 'do not'}.

## The contact radius: error terms

Why the a difference is not monotone is measured in
[`hertz3d_diagnostics.md`](hertz3d_diagnostics.md) (more levels, between and below these). The
terms, per level (P/4 = f pi R^3 / 3 the weight of the quarter ball, F the contact force of the
run, equal to the weight f |mesh| of the meshed quarter in both methods: the largest relative
difference between the DEM's and the FEM's F on the same mesh is
{results['diagnostics']['dem_contact_force_over_fem_minus_1']['values'][0]:.1e}):

- the meshed quarter, a polyhedron inscribed in the ball, is lighter than the ball (F / (P/4) - 1);
  a ~ P^(1/3), so this lowers a by a third of that in both methods. "at P" is a (P/4 / F)^(1/3),
  for the DEM and the FEM: the difference without this shared term;
- "a barycentre" is the moment measure of the DEM's facet forces put at the facets' barycentres
  (where the DEM measures the gaps; summary key ``contact_radius_barycentre``) instead of spread
  uniformly over their triangles{barycentre_note(results)}.

{error_table(results)}

## Criteria

| criterion | verdict |
|---|---|
{criteria}
{verdict_note(results)}

Measured alongside (not criteria): whether the magnitude of each error term above
decreases from level to level, and whether the DEM's contact force equals the FEM's on every mesh
(to 1e-9; both equal the weight f |mesh|, the check of the statics).

| term | values | holds |
|---|---|---|
{diagnostics}

A "yes" here holds on these four levels only: on the levels between them
(hertz3d_diagnostics.md) none of these differences decreases monotonically, because of the
scatter of the facet forces with where the facets fall (up to 0.17 % of a on h_c of 0.007 to
0.01 m).
"""


def verdict_note(results: dict) -> str:
    if results["criteria"]["dem_a_difference_decreasing"]:
        return ""
    return ("\nThe a criterion is not met: the difference from the finest FEM run does not decrease from "
            "level to level. Why, and what the DEM's a converges to, is measured in "
            "[`hertz3d_diagnostics.md`](hertz3d_diagnostics.md) (its conclusion).\n")


def values(v: list) -> str:
    return ", ".join(f"{100 * x:+.3f}%" for x in v) if len(v) > 1 else f"{v[0]:.1e}"


def barycentre_note(results: dict) -> str:
    if any(r.get("a_barycentre_source") for r in results["dem"]):
        return (" (these runs predate the key: their values are those of hertz3d_diagnostics.json, which "
                "solves the same meshes again; its uniform a agrees with this table's to 1e-9)")
    return ""


def aitken(x: list) -> float:
    """Aitken's extrapolation x2 - (x2 - x1)^2 / ((x2 - x1) - (x1 - x0)) of three successive values
    of a geometrically converging sequence (the FEM runs, one refinement factor apart)."""
    x0, x1, x2 = x
    return x2 - (x2 - x1) ** 2 / ((x2 - x1) - (x1 - x0))


def diffs(rows: list, ref: dict, key: str) -> str:
    return ", ".join(f"{100 * (r[key] / ref[key] - 1):+.3f}%" for r in rows)


def ratios(rows: list, ref: dict, key: str) -> str:
    d = [abs(r[key] / ref[key] - 1) for r in rows]
    return ", ".join(f"{b / a:.2f}" for a, b in zip(d, d[1:]))


def changes(rows: list, key: str) -> str:
    return ", ".join(f"{100 * (a[key] / b[key] - 1):+.3f}%" for a, b in zip(rows, rows[1:]))


if __name__ == "__main__":
    main()
