"""Many impacts between bodies (issue 33): the built-in scenes ``billiard`` (2D, seven discs in a
deformable frame, to 50 s) and ``cradle`` (3D, Newton's cradle of five balls, 3 s) run by the DEM
(the scenes' own method, dem-B) and by the FEM peer (``method = fem-P1``: P1, lumped mass, central
differences, node-to-segment / node-to-facet penalty contact; docs/scenes.md "method fem-P1") on
the same meshes, at several mesh sizes ``mesh.h``, everything else the scene's own (its CFL, its
material, its contact boundary).

Per run, on a common time grid (``interval``: 0.5 s billiard, 0.025 s cradle):

- the energy error: max |E(s) - E(0)| / E(0) over s <= t, E the ``pseudo_energy`` column of
  ``series.csv`` (a row every step): for the DEM its MEMM pseudo-energy, which it conserves through
  contact, so this is its drift; for fem-P1 the central differences' modified energy plus the
  penalty energy, which contact does not conserve (fem/penalty.py): its energy error as it reports
  it. E(0) is the initial kinetic energy (nothing is strained at t = 0).
- the trajectory error: the largest over the balls of |X_i(t) - X_i(0) - (X_i^ref(t) - X_i^ref(0))|,
  X_i the centre of mass of ball i, the volume-weighted mean of x + u over its cells (one density)
  in ``solution.xdmf`` (DG0 fields: the DEM's cell values, fem-P1's cell averages of its P1 field,
  whose mass-weighted mean is its lumped-mass centre of mass exactly). The reference is the run of
  the same method on the finest mesh of the study (``--billiard-h``'s and ``--cradle-h``'s last
  size). The centre of mass moves only by the contact impulses, so its error after many contacts
  is the accumulated error of the impulses (their timing, size and direction) and it carries none
  of the balls' internal vibration, which a material point would. Displacements rather than
  positions: the centroid of a meshed ball is off its sphere's centre by the mesh (up to 6e-4 m at
  the cradle's h = 0.04), which is the mesh's, the same for both methods. The frames are written
  about every ``interval`` and interpolated to the grid by cubic Hermite splines through the
  centres' positions and velocities. Each run is also compared with the other method's finest run,
  and the distance between the two finest runs is given: where the errors fall below it, the
  references do not resolve them.
- ``cradle`` only: the lateral drift, the largest distance of a ball's centre of mass from the x axis,
  against the exact value 0 (the balls start on the axis and only the first moves, along it), and
  the axial error, the x part of the trajectory error.
- the balls' centre displacements at the tables' times (``displacements_shown``, for the tests).
- contact episodes: per pair of bodies, the stretches with a nonzero pair force
  (``contact_force_<i>_<j>_*``), gaps shorter than ``interval`` merged, summed over the pairs.
- the wall time of the run (set-up, steps and the output of the frames, one process).

    .venv/bin/python validation/long_runs.py --out docs/validation/long_runs.json
    .venv/bin/python validation/long_runs.py --quick --out OUT.json   # billiard h 0.2, 0.1 to 20 s; cradle h 0.04, 0.028 to 1 s

It writes the JSON and, next to it, the Markdown page and the chart (``--out``'s stem + .md, .png);
``--render`` rewrites the page and the chart from the JSON.
"""

import argparse
import datetime
import json
import math
import pathlib
import subprocess
import tempfile
import time

import numpy as np

METHODS = ("dem-B", "fem-P1")
SCENES = {
    # ball centres and radius (from the scene files), the grid's interval, the tolerance on the trajectory
    # (a tenth of the radius), the times the tables show, the estimated dt / h of each method (for the
    # output's step count only: the frames' times are read back)
    "billiard": {"centres": [[4.0, 5.0], [5.0, 4.0], [8.0, 4.0], [7.0, 6.0], [5.0, 7.0], [4.0, 8.0], [7.0, 8.0]],
                 "radius": 0.5, "end": 50.0, "interval": 0.5, "tolerance": 0.05, "shown": (10.0, 25.0, 50.0),
                 "dt_over_h": {"dem-B": 0.19, "fem-P1": 0.30}, "h": (0.2, 0.1, 0.05, 0.025), "axis": None},
    "cradle": {"centres": [[0.1, 0.0, 0.0], [0.31, 0.0, 0.0], [0.52, 0.0, 0.0], [0.73, 0.0, 0.0], [0.94, 0.0, 0.0]],
               "radius": 0.1, "end": 3.0, "interval": 0.025, "tolerance": 0.01, "shown": (1.0, 2.0, 3.0),
               "dt_over_h": {"dem-B": 0.037, "fem-P1": 0.079}, "h": (0.04, 0.028, 0.02, 0.014), "axis": 0},
}
QUICK = {"billiard": {"h": (0.2, 0.1), "end": 20.0, "shown": (10.0, 20.0)},
         "cradle": {"h": (0.04, 0.028), "end": 1.0, "shown": (0.5, 1.0)}}
COLOURS = {"dem-B": "tab:blue", "fem-P1": "tab:red"}
STYLES = ("-", "--", ":", "-.")


def centres_of_mass(folder: pathlib.Path, centres: np.ndarray, radius: float):
    """Times, centres of mass (frames, balls, d) and their velocities from ``folder/solution.xdmf``:
    the cells of ball i are those whose barycentre lies within the radius of its centre."""
    import pyvista as pv

    reader = pv.XdmfReader(str(folder / "solution.xdmf"))
    d = centres.shape[1]
    times, positions, velocities, weights = [], [], [], None
    for t in reader.time_values:
        reader.set_active_time_value(t)
        blocks = reader.read()
        fields = {name: blocks[k].cell_data[name][:, :d] for k in range(blocks.n_blocks)
                  for name in blocks[k].cell_data.keys() if name in ("displacement", "velocity")}
        if weights is None:
            grid = blocks[0]
            sizes = grid.compute_cell_sizes(length=False, area=d == 2, volume=d == 3)
            volume = np.abs(sizes.cell_data["Area" if d == 2 else "Volume"])
            x0 = grid.cell_centers().points[:, :d]
            owners = [np.flatnonzero(np.linalg.norm(x0 - c, axis=1) < radius) for c in centres]
            assert len(np.unique(np.concatenate(owners))) == sum(map(len, owners)) and all(map(len, owners))
            weights = [volume[o] / volume[o].sum() for o in owners]
        u, v = fields["displacement"], fields["velocity"]
        times.append(float(t))
        positions.append([w @ (x0[o] + u[o]) for w, o in zip(weights, owners)])
        velocities.append([w @ v[o] for w, o in zip(weights, owners)])
    return np.array(times), np.array(positions), np.array(velocities)


def contact_episodes(series: np.ndarray, gap: float) -> int:
    """Stretches of nonzero force of each pair of bodies (gaps shorter than ``gap`` merged), summed."""
    t = series["t"]
    pairs = sorted({n.rsplit("_", 1)[0] for n in series.dtype.names
                    if n.startswith("contact_force_") and n.count("_") == 4 and "obstacle" not in n})
    count = 0
    for pair in pairs:
        force = np.sqrt(sum(series[n] ** 2 for n in series.dtype.names if n.rsplit("_", 1)[0] == pair))
        on = t[force > 0]
        if len(on):
            count += 1 + int(np.count_nonzero(np.diff(on) > gap))
    return count


def run(name: str, method: str, h: float, end: float, work: pathlib.Path, keep: bool) -> dict:
    from scipy.interpolate import CubicHermiteSpline

    from dolfinx_dem import scenes, simulation

    spec = SCENES[name]
    every = max(1, round(spec["interval"] / (spec["dt_over_h"][method] * h)))
    scene = scenes.load(name, {"method": method, "mesh.h": h, "time.end": end, "output.every": every})
    out = work / f"{name}-{method}-{h:g}"
    start = time.perf_counter()
    summary = simulation.run(scene, out, quiet=True, overwrite=True)
    wall = time.perf_counter() - start
    assert summary["status"] == "completed", summary["status"]
    series = np.genfromtxt(out / "series.csv", delimiter=",", names=True)
    energy = series["pseudo_energy"]
    error = np.maximum.accumulate(np.abs(energy - energy[0]) / energy[0])
    grid = grid_times(spec["interval"], end)
    rows = np.searchsorted(series["t"], grid * (1 + 1e-12), side="right") - 1
    times, positions, velocities = centres_of_mass(out, np.array(spec["centres"]), spec["radius"])
    spline = CubicHermiteSpline(times, positions, velocities, axis=0)
    if not keep:
        import shutil

        shutil.rmtree(out)
    return {"method": method, "h": h, "cells": summary["n_cells"], "steps": summary["n_steps"], "dt": summary["dt"],
            "frames": len(times), "wall_s": wall, "energy_error": error[rows].tolist(),
            "energy_error_end": float(error[-1]), "drift": summary["pseudo_energy_rel_drift"],
            "contact_episodes": contact_episodes(series, spec["interval"]),
            "max_penetration": summary.get("max_penetration"),
            "offset": float(np.linalg.norm(positions[0] - np.array(spec["centres"]), axis=1).max()),
            "displacement": (spline(grid) - positions[0]).tolist()}


def grid_times(interval: float, end: float) -> np.ndarray:
    return np.linspace(0.0, end, round(end / interval) + 1)


def distance(a: dict, b: dict) -> np.ndarray:
    """The largest over the balls of the distance between the centres' displacements, on the grid."""
    return np.linalg.norm(np.array(a["displacement"]) - np.array(b["displacement"]), axis=2).max(axis=1)


def study(name: str, levels: tuple, end: float, shown: tuple, work: pathlib.Path, keep: bool) -> dict:
    spec = SCENES[name]
    runs = []
    for h in levels:
        for method in METHODS:
            r = run(name, method, h, end, work, keep)
            runs.append(r)
            print(f"{name} {method} h {h:g}: {r['cells']} cells, {r['steps']} steps, energy error "
                  f"{r['energy_error_end']:.1e}, {r['contact_episodes']} contact episodes, {r['wall_s']:.1f} s",
                  flush=True)
    finest = {m: next(r for r in runs if r["method"] == m and r["h"] == levels[-1]) for m in METHODS}
    for r in runs:
        other = METHODS[1 - METHODS.index(r["method"])]
        r["trajectory_error"] = distance(r, finest[r["method"]]).tolist()
        r["trajectory_error_other"] = distance(r, finest[other]).tolist()
    grid, axis = grid_times(spec["interval"], end), spec["axis"]
    u = [np.array(r["displacement"]) for r in runs]
    u_ref = {m: np.array(finest[m]["displacement"]) for m in METHODS}
    for r, u_r in zip(runs, u):  # the displacements are kept at the times shown only
        del r["displacement"]
        r["displacements_shown"] = {f"{t:g}": u_r[int(np.argmin(np.abs(grid - t)))].tolist() for t in shown}
        if axis is not None:  # in the exact solution the balls move along the axis only (symmetry)
            r["axial_error"] = np.abs(u_r[:, :, axis] - u_ref[r["method"]][:, :, axis]).max(axis=1).tolist()
            r["lateral"] = np.linalg.norm(np.delete(u_r, axis, axis=2), axis=2).max(axis=1).tolist()
    return {"end": end, "interval": spec["interval"], "tolerance": spec["tolerance"], "shown": list(shown),
            "levels": list(levels), "reference_h": levels[-1], "grid": grid_times(spec["interval"], end).tolist(),
            "reference_distance": finest["dem-B"]["trajectory_error_other"], "runs": runs}


def at(data: dict, values: list, t: float) -> float:
    return values[int(np.argmin(np.abs(np.array(data["grid"]) - t)))]


def first_above(data: dict, values: list, tolerance: float):
    """The first grid time at which ``values`` exceeds ``tolerance`` (None if never)."""
    above = np.flatnonzero(np.array(values) > tolerance)
    return data["grid"][above[0]] if len(above) else None


def chart(results: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results["scenes"])
    fig, axes = plt.subplots(len(names), 2, figsize=(12, 4.2 * len(names)), squeeze=False)
    for (ax1, ax2), name in zip(axes, names):
        data = results["scenes"][name]
        t = np.array(data["grid"])
        for r in data["runs"]:
            style = STYLES[data["levels"].index(r["h"]) % len(STYLES)]
            label = f"{r['method']}, h = {r['h']:g}" + (" (reference)" if r["h"] == data["reference_h"] else "")
            ax1.semilogy(t[1:], np.maximum(r["energy_error"][1:], 1e-16), style, color=COLOURS[r["method"]],
                         label=label)
            if r["h"] != data["reference_h"]:
                ax2.semilogy(t[1:], np.maximum(r["trajectory_error"][1:], 1e-8), style, color=COLOURS[r["method"]],
                             label=label)
        ax2.semilogy(t[1:], np.maximum(data["reference_distance"][1:], 1e-8), "k-", lw=2,
                     label=f"dem-B against fem-P1, both h = {data['reference_h']:g}")
        ax2.axhline(data["tolerance"], color="grey", lw=0.8)
        ax1.set(xlabel="t (s)", ylabel="max |E - E(0)| / E(0) up to t", title=f"{name}: energy error")
        ax2.set(xlabel="t (s)", ylabel="largest centre-of-mass error of a ball (m)",
                title=f"{name}: trajectory error against the method's h = {data['reference_h']:g} run")
        for ax in (ax1, ax2):
            ax.grid(True, which="both", alpha=0.3)
        ax1.legend(fontsize=7, ncol=2)
        ax2.legend(fontsize=7, ncol=2)
    fig.suptitle("Many impacts: dem-B (blue) and fem-P1 (red) on the same meshes (grey line: a tenth of the radius)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def verdict(data: dict, h: float) -> str:
    """One table row comparing the two methods on the mesh h: energy, trajectory at the end, wall time."""
    dem, fem = (next(r for r in data["runs"] if r["method"] == m and r["h"] == h) for m in METHODS)

    def better(key_dem: float, key_fem: float, small: bool = True) -> str:
        if key_dem == key_fem:
            return "tie"
        return "dem-B" if (key_dem < key_fem) == small else "fem-P1"

    end = data["end"]
    e_dem, e_fem = dem["energy_error_end"], fem["energy_error_end"]
    cells = [f"{h:g}", f"{better(e_dem, e_fem)} ({e_dem:.1e} / {e_fem:.1e})"]
    if h != data["reference_h"]:
        x_dem, x_fem = at(data, dem["trajectory_error"], end), at(data, fem["trajectory_error"], end)
        o_dem, o_fem = at(data, dem["trajectory_error_other"], end), at(data, fem["trajectory_error_other"], end)
        cells += [f"{better(x_dem, x_fem)} ({x_dem:.2e} / {x_fem:.2e})",
                  f"{better(o_dem, o_fem)} ({o_dem:.2e} / {o_fem:.2e})"]
    else:
        cells += ["(reference)", f"distance {at(data, data['reference_distance'], end):.2e}"]
    cells.append(f"{better(dem['wall_s'], fem['wall_s'])} ({dem['wall_s']:.1f} / {fem['wall_s']:.1f})")
    return "| " + " | ".join(cells) + " |"


def page(results: dict, png: str) -> str:
    lines = [
        "# Many impacts between bodies: billiard and cradle, DEM against the FEM peer",
        "",
        f"Written by `validation/long_runs.py` (one process) on {results['date']} at commit {results['commit']}. "
        f"Command: `{results['command']}`.",
        "",
        "The built-in scenes `billiard` (2D: seven discs of radius 0.5 m at 0.1 m/s in a deformable frame, to 50 s) "
        "and `cradle` (3D: five balls of radius 0.1 m in a row, the first at 0.3 m/s, 3 s) run by the DEM (dem-B, "
        "the scenes' own method) and by the FEM peer fem-P1 (P1, lumped mass, central differences, penalty "
        "contact between the bodies; [scenes.md](../scenes.md#method-fem-p1-the-explicit-fem-peer)) on the same "
        "meshes, each scene's CFL, at the mesh sizes h below.",
        "",
        "- **Energy error**: max |E(s) - E(0)| / E(0) over s <= t, E the `pseudo_energy` column (every step): the "
        "DEM's MEMM pseudo-energy, which it conserves through contact (its drift), fem-P1's modified energy plus "
        "penalty energy, which contact does not conserve; E(0) the initial kinetic energy.",
        "- **Trajectory error**: the largest over the balls of the distance between the displacements of the ball's "
        "centre of mass and of the reference's, on a grid of times (every "
        + " s, ".join(f"{d['interval']:g}" for d in results["scenes"].values()) + " s; the fields are written about "
        "that often and interpolated by cubic Hermite splines through the centres' positions and velocities). "
        "**Reference: the same method on the finest mesh of the study.** The centre of mass of a ball moves only "
        "by the contact impulses it receives, so its error after many contacts is what the impulses' errors "
        "(timing, size, direction) have accumulated, without the balls' internal vibration, which a material point "
        "(a probe) would carry; the conservation of momentum makes it a quantity both methods compute exactly from "
        "their own forces. No exact solution exists for these scenes; the column *against the other method's finest* "
        "and the distance between the two finest runs (the black line of the chart) show how far the two "
        "references agree: an error below that distance is not resolved by either reference.",
        "- **Lateral drift** (`cradle`): the balls start on the x axis and only the first moves, along x, so in the "
        "exact solution they move along x only; the largest distance of a ball's centre of mass from the x axis "
        "(its y, z displacement) is an error against an exact reference, made by the faceted contact surfaces of "
        "the meshed balls. The *axial error* is the x part of the trajectory error. Why the DEM's drifts more than "
        "fem-P1's (neither the crossing angle nor eta nor the time step; the contact surface in part): "
        "[cradle_drift.md](cradle_drift.md).",
        "- **Contact episodes**: per pair of bodies, the stretches of nonzero pair force (gaps shorter than the grid's "
        "interval merged), summed over the pairs (the billiard's frame is a body).",
        "- **Wall time**: the whole run (set-up, steps, the series every step and the fields about every interval), "
        "one process on a 2-core machine shared with other jobs.",
        "",
        f"![energy and trajectory errors]({png})",
    ]
    for name, data in results["scenes"].items():
        shown, axial = data["shown"], "lateral" in data["runs"][0]
        lines += ["", f"## `{name}`, to {data['end']:g} s", "",
                  "| method | h (m) | cells | steps | dt (s) | contact episodes | "
                  + " | ".join(f"energy error, t = {t:g} s" for t in shown) + " | "
                  + " | ".join(f"trajectory error (m), t = {t:g} s" for t in shown)
                  + f" | first t with a trajectory error over {data['tolerance']:g} m | trajectory error against the "
                  "other method's finest (m), end | "
                  + ("axial (x) error against the method's finest (m), end | lateral drift (m), end (exact: 0) | "
                     if axial else "") + "wall (s) |",
                  "|---" * (9 + 2 * len(shown) + 2 * axial) + "|"]
        for r in sorted(data["runs"], key=lambda r: (r["method"], -r["h"])):
            ref = r["h"] == data["reference_h"]
            first = first_above(data, r["trajectory_error"], data["tolerance"])
            lines.append(
                f"| {r['method']} | {r['h']:g} | {r['cells']} | {r['steps']} | {r['dt']:.3g} | {r['contact_episodes']} | "
                + " | ".join(f"{at(data, r['energy_error'], t):.1e}" for t in shown) + " | "
                + " | ".join("reference" if ref else f"{at(data, r['trajectory_error'], t):.2e}" for t in shown)
                + f" | {'-' if ref else ('none' if first is None else f'{first:g}')} | "
                + f"{at(data, r['trajectory_error_other'], data['end']):.2e} | "
                + (f"{'reference' if ref else format(at(data, r['axial_error'], data['end']), '.2e')} | "
                   f"{at(data, r['lateral'], data['end']):.2e} | " if axial else "") + f"{r['wall_s']:.1f} |")
        d = data["reference_distance"]
        first = first_above(data, d, data["tolerance"])
        over = f"over {data['tolerance']:g} m from t = {first:g} s" if first is not None else "never over the tolerance"
        lines += ["", f"Distance between the two finest runs (dem-B and fem-P1, h = {data['reference_h']:g}): "
                  + ", ".join(f"{at(data, d, t):.2e} m at t = {t:g} s" for t in shown) + f"; {over}. "
                  f"Largest offset of a meshed ball's centroid from its sphere's centre: "
                  + ", ".join(f"{r['offset']:.1e} m (h = {r['h']:g})" for r in data["runs"] if r["method"] == "dem-B")
                  + "."]
    lines += ["", "## Where each method wins", "",
              "On the same mesh, the smaller error (dem-B / fem-P1) at the end of the run, and the shorter wall time:",
              "", "| scene | h (m) | energy error | trajectory error, against the method's finest | trajectory error, "
              "against the other's finest | wall (s) |", "|---|---|---|---|---|---|"]
    for name, data in results["scenes"].items():
        for h in data["levels"]:
            lines.append(f"| `{name}` " + verdict(data, h))
    for name, data in results["scenes"].items():
        lines += ["", *summary(name, data)]
    return "\n".join(lines) + "\n"


def summary(name: str, data: dict) -> list[str]:
    """The measured answer per scene: energy, trajectory (same mesh, equal wall time), cost, what the references resolve."""
    runs = {m: sorted((r for r in data["runs"] if r["method"] == m), key=lambda r: -r["h"]) for m in METHODS}
    coarse = {m: [r for r in rows if r["h"] != data["reference_h"]] for m, rows in runs.items()}
    end, d_end = data["end"], at(data, data["reference_distance"], data["end"])

    def listed(rows, key):
        return ", ".join(f"{at(data, r[key], end):.2g}" for r in rows)

    hs = ", ".join(f"{h:g}" for h in data["levels"])
    wins = {m: sum(1 for a, b in zip(coarse["dem-B"], coarse["fem-P1"])
                   if (at(data, a["trajectory_error"], end) < at(data, b["trajectory_error"], end)) == (m == "dem-B"))
            for m in METHODS}
    pairs = []
    for f in coarse["fem-P1"]:
        d = min(coarse["dem-B"], key=lambda r: abs(math.log(r["wall_s"] / f["wall_s"])))
        pairs.append(f"fem-P1 h = {f['h']:g} ({f['wall_s']:.1f} s) {at(data, f['trajectory_error'], end):.2g} m against "
                     f"dem-B h = {d['h']:g} ({d['wall_s']:.1f} s) {at(data, d['trajectory_error'], end):.2g} m")
    episodes = sorted({r["contact_episodes"] for r in data["runs"]})
    fem_energy = ", ".join(f"{r['energy_error_end']:.1e}" for r in runs["fem-P1"])
    coarse_h = ", ".join(f"{r['h']:g}" for r in coarse["dem-B"])
    steps = ", ".join(f"{a['steps'] / b['steps']:.2f}" for a, b in zip(runs["dem-B"], runs["fem-P1"]))
    walls = ", ".join(f"{a['wall_s'] / b['wall_s']:.2f}" for a, b in zip(runs["dem-B"], runs["fem-P1"]))
    return [
        f"**`{name}`** ({episodes[0]}-{episodes[-1]} contact episodes per run). *Energy*: dem-B's error stays below "
        f"{max(r['energy_error_end'] for r in runs['dem-B']):.1e} on every mesh (h = {hs}); fem-P1's ends at "
        f"{fem_energy}. *Trajectory at t = {end:g} s*, against each method's finest run: dem-B "
        f"{listed(coarse['dem-B'], 'trajectory_error')} m, fem-P1 {listed(coarse['fem-P1'], 'trajectory_error')} m on "
        f"h = {coarse_h}: smaller for dem-B on {wins['dem-B']} of the {len(coarse['dem-B'])} meshes, for fem-P1 on "
        f"{wins['fem-P1']}; against the other method's finest run: dem-B {listed(coarse['dem-B'], 'trajectory_error_other')}"
        f" m, fem-P1 {listed(coarse['fem-P1'], 'trajectory_error_other')} m. The two finest runs are {d_end:.2g} m apart at "
        f"the end: smaller errors are not resolved. *Cost*: on each mesh dem-B takes {steps} times fem-P1's steps and "
        f"{walls} times its wall time. *At about equal wall time*: {'; '.join(pairs)}."
        + ("" if "lateral" not in runs["dem-B"][0] else
           f" *Lateral drift at the end* (exact: 0, by symmetry; h = {hs}): dem-B {listed(runs['dem-B'], 'lateral')} m, "
           f"fem-P1 {listed(runs['fem-P1'], 'lateral')} m; *axial error* against the method's finest: dem-B "
           f"{listed(coarse['dem-B'], 'axial_error')} m, fem-P1 {listed(coarse['fem-P1'], 'axial_error')} m.")]


def run_or_render(parser: argparse.ArgumentParser, measure, chart, page) -> None:
    """The command line of a many-impacts study (this one and long_bounce.py): ``parser``, with the
    study's own arguments, gets ``--render`` and ``--out``; ``measure(args)`` runs the study and returns
    its results, written as JSON to ``--out`` and next to it as the page ``page(results, png name)``
    and the chart ``chart(results, png)`` (``--out``'s stem + .md, .png). With ``--render`` nothing
    runs: the page and the chart are rewritten from ``--out``'s JSON."""
    parser.add_argument("--render", action="store_true", help="rewrite the page and chart from --out's JSON")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args()
    if args.render:
        results = json.loads(args.out.read_text())
    else:
        results = measure(args)
        args.out.write_text(json.dumps(results, indent=1) + "\n")
    png = args.out.with_suffix(".png")
    chart(results, png)
    args.out.with_suffix(".md").write_text(page(results, png.name))


def measure(args: argparse.Namespace) -> dict:
    """The study of the command line ``args``."""
    levels = {"billiard": tuple(args.billiard_h), "cradle": tuple(args.cradle_h)}
    command = "validation/long_runs.py " + ("--quick" if args.quick else " ".join(
        [f"--scenes {' '.join(args.scenes)}"] + [f"--{n}-h {' '.join(f'{h:g}' for h in levels[n])}" for n in args.scenes]))
    root = pathlib.Path(__file__).resolve().parents[1]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=root).stdout
    results = {"command": command, "date": datetime.date.today().isoformat(), "commit": commit.strip() or "unknown",
               "scenes": {}}
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or pathlib.Path(tmp)
        for name in args.scenes:
            spec = QUICK[name] if args.quick else {"h": levels[name], "end": SCENES[name]["end"],
                                                   "shown": SCENES[name]["shown"]}
            results["scenes"][name] = study(name, tuple(spec["h"]), spec["end"], tuple(spec["shown"]), work,
                                            args.keep and args.work is not None)
    return results


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--billiard-h", type=float, nargs="+", default=list(SCENES["billiard"]["h"]),
                        help="mesh sizes, coarse to fine; the last is the reference")
    parser.add_argument("--cradle-h", type=float, nargs="+", default=list(SCENES["cradle"]["h"]),
                        help="mesh sizes, coarse to fine; the last is the reference")
    parser.add_argument("--quick", action="store_true", help="billiard h 0.2, 0.1 to 20 s; cradle h 0.04, 0.028 to 1 s")
    parser.add_argument("--work", type=pathlib.Path, help="folder of the runs (default: a temporary one)")
    parser.add_argument("--keep", action="store_true", help="keep the runs' folders (with --work)")
    run_or_render(parser, measure, chart, page)


if __name__ == "__main__":
    main()
