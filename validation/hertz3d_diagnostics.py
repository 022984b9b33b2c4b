"""What the DEM's contact radius of the 3D Hertz ball converges to: the error terms of
``hertz3d.py``'s a, measured per mesh level.

For each level s of ``--scales`` (the scene ``hertz3d`` of hertz3d.py, h = 0.04 / s,
h_c = 0.01 / s) the DEM statics (scheme A, ``statics.minimise_energy``, as the static runner
calls it, no output files) and, with ``--fem``, the P2 FEM reference are solved, and written:

* the statics check: the total contact force (facet reactions plus the kink facets'
  multipliers) against the weight of the meshed quarter, f |mesh|, and both against the quarter
  of the exact ball, P/4 = f pi R^3 / 3 (the inscribed polyhedron is lighter: a ~ P^(1/3));
* a_uniform, the moment measure of hertz3d.py (each facet's force spread uniformly over its
  triangle, ``hertz.triangle_pressure_moments``), and a_point, the same moments of the facet
  forces put at the facets' barycentres, where the DEM measures the gap; they differ by the
  triangles' own second moments, sum F_f (mean r^2 over f - r_f^2) = sum F_f sum |e_i|^2 / 12
  (e_i the vertices about the barycentre), reported as ``spread`` relative to 2 a^2 / 5;
* both at the exact load, a (P / 4 / F)^(1/3) with F the contact force of the run;
* the facets in contact, the kink facets (held on g_f = 0 by a multiplier between 0 and the force
  r_f they would carry in contact), and how far a_uniform moves when each kink facet's force
  is set to 0 or to r_f (the others fixed): the scale of the quantisation by facets at the edge;
* the facet size in the contact zone, sqrt of the force-weighted mean of 4 |f| / sqrt(3) (the
  side of an equilateral triangle of the same area);
* the approach -u_z at the top, the iterations and the processor time of the minimisation.

    .venv/bin/python validation/hertz3d_diagnostics.py --dem --fem --scales 0.5 0.71 1
        [--load-factors 0.9 1.1] [--out docs/validation/hertz3d_diagnostics.json] [--render] [--quick]

adds its rows to the JSON (replacing those of the same method, level and load factor) and writes,
next to it, hertz3d_diagnostics.md (the tables; the commands, dates and commits), using the
FEM reference of hertz3d.json (hertz3d.py) next to it; ``--render`` only rewrites the markdown.
``--quick``: ``--dem --fem --scales 0.5`` (seconds; the markdown needs the other levels in the JSON), for the tests.
"""

import argparse
import datetime
import json
import pathlib
import subprocess
import sys
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import hertz, model, scenes
from dolfinx_dem.static_simulation import _facet_vertices, _top_point
from dolfinx_dem.statics import minimise_energy

ROOT = pathlib.Path(__file__).resolve().parents[1]
H, H_CONTACT = 0.04, 0.01
GROUPS = ((0.9, 1.45), (1.5, 2.25), (2.4, 3.1))  # nearby levels s, for the scatter of a


def moments(vertices, centres, force, axis):
    """(a_uniform, a_point, spread): the moment measures of the facet forces spread over their
    triangles and put at their barycentres, and the triangles' own second moment relative to
    2 a_point^2 / 5."""
    m0, m2 = hertz.triangle_pressure_moments(vertices, force, *axis)
    m2_point = hertz.point_force_moments(centres, force, *axis)[1]
    a_point = hertz.contact_radius_moments(m0, m2_point)
    return hertz.contact_radius_moments(m0, m2), a_point, (m2 - m2_point) / m0 / (0.4 * a_point**2)


def dem_level(scale: float) -> dict:
    scene = scenes.load("hertz3d", {"method": "dem-A", "mesh.h": H / scale, "mesh.refine_h": H_CONTACT / scale})
    comm = MPI.COMM_SELF
    problem = model.build(scene, comm)
    dem, (c,) = problem.dem, problem.contacts  # the rigid plane
    top = model.Probes(problem, [{"name": "top", "point": _top_point(dem), "component": 2}])
    cpu = time.process_time()
    result = minimise_energy(problem)
    cpu = time.process_time() - cpu
    u, geom = result.u, dem.geometry
    own = c.facets[: c.num_own]
    force = c.reactions(u)
    # facets held on a kink of the potential carry their multiplier
    force[result.pinned] = c.statics().own_values(result.kink_forces, result.pinned)[result.pinned]
    touching = force > 0
    vertices, centres, areas = _facet_vertices(geom, own), geom.facet_centres[own], geom.facet_areas[own]
    axis = (scene["obstacles"][0]["point"], scene["obstacles"][0]["normal"])
    f = -scene["loads"]["body_force"][2]
    R = scene["mesh"]["balls"][0][3]
    weight = f * float(geom.cell_volumes[: dem.n_owned].sum())
    quarter = f * np.pi * R**3 / 3.0
    total = float(force.sum())
    a_u, a_p, spread = moments(vertices[touching], centres[touching], force[touching], axis)
    # kink facets: a_uniform with each one's force at the ends of its admissible interval [0, r_f]
    active = c.own_gaps(u) < 0
    active[result.pinned] = True  # (the pinned facets: indices of own facets)
    r_kink = c.reactions(u, active)
    kinks = []
    for k in result.pinned:
        ends = []
        for value in (0.0, r_kink[k]):
            trial = force.copy()
            trial[k] = value
            t = trial > 0
            ends.append(hertz.contact_radius_moments(*hertz.triangle_pressure_moments(vertices[t], trial[t], *axis)))
        kinks.append({"radius": float(np.hypot(*centres[k, :2])), "force": float(force[k]), "r_f": float(r_kink[k]),
                      "a_at_0": ends[0], "a_at_r_f": ends[1]})
    side = np.sqrt(float(force[touching] @ (4.0 * areas[touching] / np.sqrt(3.0))) / total)
    return {"method": "dem-A", "scale": scale, "cells": geom.num_cells_global, "h_contact": H_CONTACT / scale,
            "facet_side": side, "contact_facets": int(touching.sum()), "kink_facets": kinks,
            "contact_force": total, "weight": weight, "exact_quarter_load": quarter,
            "a_uniform": a_u, "a_point": a_p, "spread": spread,
            "a_uniform_exact_load": a_u * (quarter / total) ** (1 / 3),
            "a_point_exact_load": a_p * (quarter / total) ** (1 / 3),
            "approach": -float(top.values(u, 0.0)[0]), "iterations": result.iterations,
            "gradient_reduction": result.gradient_reduction, "cpu_s": cpu}


def fem_level(scale: float, load_factor: float = 1.0) -> dict:
    from dolfinx_dem.fem.hertz import solve_hertz

    scene = scenes.load("hertz3d")
    m = scene["material"]
    R = scene["mesh"]["balls"][0][3]
    f = -scene["loads"]["body_force"][2] * load_factor
    cpu = time.process_time()
    res = solve_hertz(MPI.COMM_SELF, H / scale, degree=2, R=R, E=m["E"], nu=m["nu"], body_force=f, dim=3,
                      refine=(H_CONTACT / scale, scene["mesh"]["refine_radius"]))
    cpu = time.process_time() - cpu
    quarter = f * np.pi * R**3 / 3.0
    return {"method": "fem-P2", "scale": scale, "load_factor": load_factor, "cells": res.num_cells,
            "contact_force": res.contact_force, "exact_quarter_load": quarter, "a": res.contact_radius,
            "a_exact_load": res.contact_radius * (quarter / res.contact_force) ** (1 / 3),
            "approach": -res.top_vertical_displacement, "iterations": res.iterations, "cpu_s": cpu}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scales", type=float, nargs="+", default=[0.5, 0.71, 1.0])
    parser.add_argument("--dem", action="store_true", help="the DEM on these levels")
    parser.add_argument("--fem", action="store_true", help="the FEM on these levels")
    parser.add_argument("--load-factors", type=float, nargs="*", default=[],
                        help="also FEM runs with the body force times these factors (the exponent of a(P))")
    parser.add_argument("--out", default=str(ROOT / "docs" / "validation" / "hertz3d_diagnostics.json"))
    parser.add_argument("--render", action="store_true", help="no runs: rewrite the markdown from the JSON")
    parser.add_argument("--quick", action="store_true", help="--dem --fem --scales 0.5")
    args = parser.parse_args()
    if args.quick:
        args.dem, args.fem, args.scales = True, True, [0.5]
    out = pathlib.Path(args.out)
    data = json.loads(out.read_text()) if out.exists() else {"runs": [], "rows": []}
    if args.render:
        out.with_suffix(".md").write_text(markdown(data, json.loads(out.with_name("hertz3d.json").read_text())))
        return
    data["runs"].append({
        "command": " ".join([".venv/bin/python", "validation/hertz3d_diagnostics.py"] + sys.argv[1:]),
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                 text=True).stdout.strip(),
        "load": open("/proc/loadavg").read().split()[0]})
    rows = []
    for s in args.scales:
        if args.dem:
            rows.append(dem_level(s))
            print(json.dumps(rows[-1]), flush=True)
        if args.fem:
            for lf in [1.0] + args.load_factors:
                rows.append(fem_level(s, lf))
                print(json.dumps(rows[-1]), flush=True)
    key = lambda r: (r["method"], r["scale"], r.get("load_factor", 1.0))  # noqa: E731
    new = {key(r) for r in rows}
    data["rows"] = sorted([r for r in data["rows"] if key(r) not in new] + rows, key=key)
    out.write_text(json.dumps(data, indent=1) + "\n")
    out.with_suffix(".md").write_text(markdown(data, json.loads(out.with_name("hertz3d.json").read_text())))


def groups(rows: list, key: str, reference: float) -> list:
    """Per group of nearby levels (``GROUPS``, ranges of s): (levels, mean facet side, mean and
    sample standard deviation of rows[key] / reference - 1)."""
    out = []
    for lo, hi in GROUPS:
        g = [r for r in rows if lo <= r["scale"] <= hi]
        if len(g) >= 2:
            x = np.array([r[key] / reference - 1 for r in g])
            out.append((len(g), float(np.mean([r["facet_side"] for r in g])), float(x.mean()), float(x.std(ddof=1))))
    return out


def markdown(data: dict, bench: dict) -> str:
    ref = bench["fem"][-1]
    a_ref = ref["a"] * (bench["hertz"]["load"] / 4.0 / ref["contact_force"]) ** (1 / 3)  # at the exact load
    pct = lambda x: f"{100 * x:+.3f}%"  # noqa: E731
    dem = [r for r in data["rows"] if r["method"] == "dem-A"]
    fem = [r for r in data["rows"] if r["method"] == "fem-P2" and r["load_factor"] == 1.0]
    lines = ["| s | h_c (m) | cells | facet side (m) | facets in contact | kink facets | F / f\\|mesh\\| - 1 "
             "| F / (P/4) - 1 | a uniform (m) | a barycentre (m) | spread | a uniform at P - ref "
             "| a barycentre at P - ref | kink range of a | approach (m) | iterations | cpu (s) |",
             "|" + "---|" * 17]
    for r in dem:
        kink = max((abs(k["a_at_r_f"] - k["a_at_0"]) / r["a_uniform"] for k in r["kink_facets"]), default=0.0)
        lines.append(
            f"| {r['scale']:g} | {r['h_contact']:.4g} | {r['cells']} | {r['facet_side']:.4g} | {r['contact_facets']} "
            f"| {len(r['kink_facets'])} | {r['contact_force'] / r['weight'] - 1:.1e} "
            f"| {pct(r['contact_force'] / r['exact_quarter_load'] - 1)} | {r['a_uniform']:.5e} | {r['a_point']:.5e} "
            f"| {100 * r['spread']:.2f}% | {pct(r['a_uniform_exact_load'] / a_ref - 1)} "
            f"| {pct(r['a_point_exact_load'] / a_ref - 1)} | {100 * kink:.2f}% | {r['approach']:.5e} "
            f"| {r['iterations']} | {r['cpu_s']:.0f} |")
    dem_table = "\n".join(lines)
    lines = ["| s | cells | F / (P/4) - 1 | a (m) | a at P - ref | approach (m) | cpu (s) |", "|" + "---|" * 7]
    for r in fem:
        lines.append(f"| {r['scale']:g} | {r['cells']} | {pct(r['contact_force'] / r['exact_quarter_load'] - 1)} "
                     f"| {r['a']:.5e} | {pct(r['a_exact_load'] / a_ref - 1)} | {r['approach']:.5e} | {r['cpu_s']:.0f} |")
    fem_table = "\n".join(lines)
    loads = sorted((r for r in data["rows"] if r["method"] == "fem-P2" and r["scale"] == 2.0),
                   key=lambda r: r["load_factor"])
    exponent = (np.log(loads[-1]["a"] / loads[0]["a"]) / np.log(loads[-1]["contact_force"] / loads[0]["contact_force"])
                if len(loads) >= 2 else float("nan"))
    fine = [r for r in dem if r["scale"] >= GROUPS[0][0]]
    sides = {r["scale"]: r["facet_side"] for r in dem}
    uniform = groups(dem, "a_uniform_exact_load", a_ref)
    barycentre = groups(dem, "a_point_exact_load", a_ref)
    fem_groups = groups([r | {"facet_side": sides[r["scale"]]} for r in fem if r["scale"] in sides], "a_exact_load", a_ref)
    scatter = "\n".join(
        f"| {n} | {side:.4g} | {pct(mu)} | {100 * su:.3f}% | {pct(mb)} | {100 * sb:.3f}% | {pct(mf)} | {100 * sf:.3f}% |"
        for (n, side, mu, su), (_, _, mb, sb), (_, _, mf, sf) in zip(uniform, barycentre, fem_groups))
    errors = [g[3] / np.sqrt(g[0]) for g in barycentre]  # standard errors of the group means
    group_means = ", ".join(f"{pct(g[2])} +- {100 * e:.3f}%" for g, e in zip(barycentre, errors))
    within = all(abs(g[2]) <= 2 * e for g, e in zip(barycentre, errors))
    scatters = ", ".join(f"{100 * g[3]:.3f}% (facet side {1e3 * g[1]:.1f} mm)" for g in barycentre)
    values = np.array([r["a_point_exact_load"] / a_ref - 1 for r in fine])
    mean, error = values.mean(), values.std(ddof=1) / np.sqrt(len(values))
    first, finest = dem[0], max(dem, key=lambda r: r["cells"])
    weight = {r["scale"]: r["contact_force"] / r["exact_quarter_load"] - 1 for r in dem}
    fem_pair = bench["fem"][-2]["a_exact_load"] / bench["fem"][-1]["a_exact_load"] - 1
    fem_within = max(abs(r["a_exact_load"] / a_ref - 1) for r in fem if r["scale"] >= 1.8)
    kink = max(max((abs(k["a_at_r_f"] - k["a_at_0"]) / r["a_uniform"] for k in r["kink_facets"]), default=0.0)
               for r in dem if r["scale"] >= 2.4)
    issue = ", ".join(pct(r["a"] / bench["fem"][-1]["a"] - 1) for r in bench["dem"])
    force = max(abs(r["contact_force"] / r["weight"] - 1) for r in dem)
    # the issue's difference a / a_FEM - 1 (the finest FEM run, raw) = (1 + systematic) (1 + forces) - 1:
    # systematic = the spread of the uniform measure and the meshed balls' weights (this run's and
    # the reference's), forces = a barycentre at P / ref - 1, what the facet forces give
    parts = []
    for r in dem:
        systematic = np.sqrt(1 + r["spread"]) * (r["contact_force"] / ref["contact_force"]) ** (1 / 3) - 1
        parts.append((r, r["a_uniform"] / ref["a"] - 1, systematic, r["a_point_exact_load"] / a_ref - 1))
    decomposition = "\n".join(f"| {r['scale']:g} | {pct(total)} | {pct(systematic)} | {pct(forces)} |"
                              for r, total, systematic, forces in parts)
    levels = [p for p in parts if p[0]["scale"] in {b["scale"] for b in bench["dem"]}]
    monotone = all(abs(x[2]) > abs(y[2]) for x, y in zip(levels, levels[1:]))
    runs = "\n".join(f"{r['command']}" for r in data["runs"])
    dates = sorted({r["date"][:10] for r in data["runs"]})
    commits = ", ".join(sorted({r["commit"] for r in data["runs"]}))
    return f"""# 3D static Hertz: what the DEM's contact radius converges to

Made by these commands (1 process; run on {", ".join(dates)}, commit {commits}; the numbers are in
[`hertz3d_diagnostics.json`](hertz3d_diagnostics.json); `--render` alone rewrites this page from it):

```
{runs}
```

The scene of [`hertz3d.md`](hertz3d.md) (R = 0.2 m, h = 0.04 / s, h_c = 0.01 / s at the contact
point) on more levels s, between and below those of hertz3d.py: the levels close to each
other (0.9, 1, 1.1, ...) show how much a moves with where the facets fall, at nearly the same
resolution. ``ref`` is the FEM reference of hertz3d.md (s = {ref['scale']:g}, {ref['cells']} cells) at the
exact load, a = {a_ref:.6e} m.

Definitions (`hertz3d_diagnostics.py`): F the total contact force (facet reactions plus the kink
facets' multipliers), f |mesh| the weight of the meshed quarter, P/4 = f pi R^3 / 3 that of the
quarter ball; "a uniform" the moment measure of hertz3d.md (each facet's force spread uniformly
over its triangle), "a barycentre" the same moments with each facet's force at its barycentre
(where the DEM measures the facet's gap), "spread" their difference in m2 / m0 relative to
2 a^2 / 5 (the triangles' own second moments: a uniform / a barycentre = sqrt(1 + spread)); "at P"
means scaled to the exact load, a (P / 4 / F)^(1/3); "kink range" how far a uniform moves when a
kink facet's force goes over its admissible interval [0, r_f], the others fixed (the largest
over the kink facets); the facet side is that of the equilateral triangle of the force-weighted
mean area of the facets in contact.

## DEM, scheme A

{dem_table}

## FEM P2 (Nitsche)

{fem_table}

The exponent of a(P) measured on the FEM at s = 2 with the body force times
{", ".join(f"{r['load_factor']:g}" for r in loads)}: d ln a / d ln P = {exponent:.4f} (Hertz: 1/3).

## The scatter with where the facets fall

Levels close to each other have nearly the same resolution; how far a moves between them is the
part of the error that depends on where the facets fall relative to the edge of the contact zone
(mean and sample standard deviation of the differences from ref, at P, per group of levels):

| levels | mean facet side (m) | DEM a uniform, mean | std | DEM a barycentre, mean | std | FEM a, mean | std |
|---|---|---|---|---|---|---|---|
{scatter}

## What the DEM's a converges to

- Statics: the contact force equals the weight of the meshed quarter on every DEM run, to
  {force:.1e} (relative); the FEM's is the same on the same mesh (hertz3d.md).
- The meshed ball's weight: F / (P/4) - 1 from {pct(weight[first['scale']])} (s = {first['scale']:g}) to
  {pct(weight[finest['scale']])} (s = {finest['scale']:g}); with the measured exponent {exponent:.3f} of a(P) it lowers a by
  a third of that in both methods. At P, the FEM's two finest runs (hertz3d.md, s =
  {bench['fem'][-2]['scale']:g} and {bench['fem'][-1]['scale']:g}) agree to {pct(fem_pair)}, and its levels s >= 1.8 here lie within {100 * fem_within:.3f}%
  of ref: the FEM's raw a converges from below because its mesh's weight does; at P it is
  converged to a few 0.01 %.
- The two DEM measures differ by the triangles' own second moments, a uniform / a barycentre =
  sqrt(1 + spread): about {50 * first['spread']:.2f}% of a (s = {first['scale']:g}) down to {50 * finest['spread']:.3f}% (s = {finest['scale']:g}),
  smoothly, like the facet side squared. Their difference is smooth from level to level, so the
  scatter between nearby levels (table above, of the same size for both; a uniform's includes
  the change of the spread within a group) is in the facet forces, not in the measure.
- At P, a barycentre shows no offset from ref above the scatter: its group means (table above)
  are {group_means} (+- the standard error){", each within two standard errors of 0" if within else ""};
  over all {len(fine)} levels s >= {GROUPS[0][0]:g} the mean is {pct(mean)} +- {100 * error:.3f}%. a uniform carries in
  addition the spread (previous item).
- Kink facets (held on g_f = 0 with a force between 0 and r_f) are 0 to 2 per level; one of them
  moves a by up to {100 * kink:.2f}% over its admissible interval on the levels s >= 2.4.

## The difference of hertz3d.md, decomposed

The difference of hertz3d.md, a uniform / a of the finest FEM run - 1 (both raw), is exactly
(1 + systematic) (1 + forces) - 1 with systematic = sqrt(1 + spread) (F / F_ref)^(1/3) - 1 (the
spread of the uniform measure, and the meshed balls' weights, this run's and the reference's)
and forces = a barycentre at P / ref - 1 (what the facet forces give):

| s | a uniform - FEM (hertz3d.md's) | systematic | forces |
|---|---|---|---|
{decomposition}

## Conclusion

The DEM's contact radius converges to the FEM's. The difference of hertz3d.md is the sum of two parts.
The systematic part ({", ".join(pct(p[2]) for p in levels)} on the levels of hertz3d.md) is the
spread of the uniform measure over the triangles, which is not in the DEM's facet forces, less a
third of the meshed ball's missing weight; both are O(h^2) and the part
{"decreases monotonically" if monotone else "does not decrease monotonically"} on those levels. The part of the facet forces
({", ".join(pct(p[3]) for p in levels)}) has no offset from the FEM above its scatter between
nearby levels (standard deviation {scatters});
on the coarser levels the scatter is larger than the systematic part's change from one level to
the next, and the sum ({issue}) is not monotone: the criterion fails for that reason, not for a
lack of convergence. At the same load, the moment measure of the DEM's facet forces (at the
barycentres, where the method measures the gaps) differs from the converged FEM by {pct(mean)} on
average over {len(fine)} levels; on the finest levels, s >= {GROUPS[-1][0]:g}, by {pct(barycentre[-1][2])} (standard deviation
{100 * barycentre[-1][3]:.3f}%), where hertz3d.md's measure is {pct(uniform[-1][2])} above the FEM, nearly all of it the spread.
"""


if __name__ == "__main__":
    main()
