"""Scheme B's accuracy (issue 32.6): how stiff the facet-follows-its-cell reconstruction makes a body,
how it converges, and whether scheme B on the contact candidates only (method ``dem-AB``) keeps the
contact's behaviour and removes the stiffness.

- **cantilever, static**: the built-in scene's beam (1 x 0.1 m, E = 1000 Pa, nu = 0.3, plane strain,
  clamped at x = 0, body force (0, -0.1) N/m^2) at rest under its load, solved by
  ``statics.minimise_energy`` on the crossed meshes 40n x 4n (n = ``--levels``); the tip deflection at
  (1, 0.05) (probe ``tip_uy``) for dem-A and dem-B, against DOLFINx P2 FEM on the same kind of mesh
  at n = 8 and 16 (the reference: n = 16). The cantilever has no contact candidates, so dem-AB is
  dem-A there.
- **two-disks, dynamic**: the built-in scene (paper §5.3) at h = ``--disk-h`` for dem-A, dem-B,
  dem-AB: the contact duration (first to last step with a nonzero pair force), the largest pair
  force, the kinetic energy at T = 1 s over the initial one (what the impact leaves as vibration),
  the largest penetration over the facet size and the pseudo-energy drift.
- **hertz, static**: the built-in scene for dem-A, dem-B, dem-AB at h = ``--hertz-h``: the top
  displacement and the contact half-width against the P2 FEM reference of
  docs/validation/hertz.json (h = 0.0015 m).

    .venv/bin/python validation/scheme_b.py [--levels 1 2 4 8] [--disk-h 0.04 0.02 0.01 0.005]
        [--hertz-h 0.015 0.0075] [--out docs/validation/scheme_b.json]
    .venv/bin/python validation/scheme_b.py --quick --out OUT.json   # n = 1, 2; h = 0.04, 0.02; hertz 0.015

It writes the JSON and, next to it, the Markdown page (``--out``'s stem + .md).
"""

import argparse
import json
import pathlib
import tempfile
import time

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, meshes, model, scenes, simulation, statics
from dolfinx_dem.errors import UnresolvedContactError
from dolfinx_dem.fem.common import clamped_bc, evaluate_at_points, lu_solver, stiffness_and_mass

ROOT = pathlib.Path(__file__).resolve().parents[1]
METHODS = ("dem-A", "dem-B", "dem-AB")
TIP = (1.0, 0.05)


def cantilever_scene(n: int, method: str) -> dict:
    scene = {k: v for k, v in scenes.load("cantilever").items() if k not in ("time", "output")}
    scene["mesh"]["n"] = [40 * n, 4 * n]
    return scenes.validate(scene | {"method": method, "statics": {"time": 0.0}})


def dem_tip(n: int, method: str) -> dict:
    start = time.perf_counter()
    scene = cantilever_scene(n, method)
    problem = model.build(scene, MPI.COMM_WORLD)
    u = statics.minimise_energy(problem).u
    tip = model.Probes(problem, scene["probes"]).values(u, 0.0)[0]
    return {"n": n, "cells": problem.dem.geometry.num_cells_global, "tip_uy": float(tip),
            "thin_bodies": problem.dem.thin_scheme_b_bodies, "wall_s": time.perf_counter() - start}


def fem_tip(n: int) -> float:
    """The P2 FEM static tip deflection on the crossed mesh 40n x 4n."""
    mesh, _, tags = meshes.create_rectangle(MPI.COMM_WORLD, [0.0, 0.0], [1.0, 0.1], [40 * n, 4 * n], "crossed")
    V = _compat.create_vector_space(mesh, "Lagrange", 2)
    k, _ = stiffness_and_mass(V, 1000.0, 0.3, 1.0, False)
    bc = clamped_bc(V, tags.find(meshes.XMIN))
    a = dolfinx.fem.form(k)
    A = dolfinx.fem.petsc.assemble_matrix(a, bcs=[bc])
    A.assemble()
    f = dolfinx.fem.Constant(mesh, np.array([0.0, -0.1], dtype=PETSc.ScalarType))
    b = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(ufl.inner(f, ufl.TestFunction(V)) * ufl.dx))
    dolfinx.fem.petsc.apply_lifting(b, [a], [[bc]])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(b, [bc])
    u = dolfinx.fem.Function(V)
    lu_solver(mesh.comm, A).solve(b, _compat.petsc_vec(u))
    u.x.scatter_forward()
    return float(evaluate_at_points(u, [TIP])[0, 1])


def run_scene(name: str, method: str, h: float, work: pathlib.Path) -> dict:
    scene = scenes.load(name)
    scene["mesh"]["h"] = h
    if "refine_h" in scene["mesh"]:
        scene["mesh"]["refine_h"] = min(scene["mesh"]["refine_h"], h)
    out = work / f"{name}-{method}-{h:g}"
    start = time.perf_counter()
    summary = simulation.run(scenes.validate(scene | {"method": method}), out, quiet=True, overwrite=True)
    summary["wall_s"] = time.perf_counter() - start
    return summary, out


def two_disks(method: str, h: float, work: pathlib.Path) -> dict:
    try:
        summary, out = run_scene("two-disks", method, h, work)
    except UnresolvedContactError as err:  # the contact surfaces interpenetrate beyond contact.max_penetration
        return {"h": h, "error": str(err)}
    series = np.genfromtxt(out / "series.csv", delimiter=",", names=True)
    force = series["contact_force_0_1_x"]
    on = np.flatnonzero(force != 0.0)
    return {"h": h, "cells": summary["n_cells"], "steps": summary["n_steps"],
            "contact_duration": float(series["t"][on[-1]] - series["t"][on[0]]),
            "max_force": float(np.abs(force).max()), "kinetic_end_over_start": float(series["kinetic"][-1]
                                                                                     / series["kinetic"][0]),
            "max_penetration_over_facet_size": summary["max_penetration_over_facet_size"],
            "drift": summary["pseudo_energy_rel_drift"], "wall_s": summary["wall_s"]}


def hertz(method: str, h: float, work: pathlib.Path) -> dict:
    summary, _ = run_scene("hertz", method, h, work)
    return {"h": h, "cells": summary["n_cells"], "u_top": summary["top_vertical_displacement"],
            "a": summary["contact_half_width"], "a_fit": summary["contact_half_width_fit"],
            "wall_s": summary["wall_s"]}


def page(results: dict, command: str) -> str:
    """The Markdown page of ``results``."""
    ref = results["cantilever"]["fem_reference"]
    lines = ["# Scheme B's accuracy", "", f"Made by `{command}` (validation/scheme_b.py; one process).", "",
             "## Cantilever, static tip deflection", "",
             f"P2 FEM reference (n = 16): {ref:.6e} m (n = 8: {results['cantilever']['fem_n8']:.6e} m). "
             "Thickness in boundary facets t/h (t = 2A/P) as the set-up check computes it (empty: no warning).", "",
             "| n | cells | dem-A tip (m) | error | dem-B tip (m) | error | dem-B stiffening | t/h (dem-B) |",
             "|---|---|---|---|---|---|---|---|"]
    for a, b in zip(results["cantilever"]["dem-A"], results["cantilever"]["dem-B"]):
        thin = ", ".join(f"{x[1]:.3g}" for x in b["thin_bodies"])
        lines.append(f"| {a['n']} | {a['cells']} | {a['tip_uy']:.5e} | {a['tip_uy'] / ref - 1:+.3%} | "
                     f"{b['tip_uy']:.5e} | {b['tip_uy'] / ref - 1:+.2%} | {ref / b['tip_uy']:.3g} | {thin} |")
    lines += ["", "## two-disks (dynamic, T = 1 s)", "",
              "| method | h (m) | cells | steps | contact duration (s) | max pair force (N/m) | KE(T)/KE(0) | "
              "max penetration / facet | drift | wall (s) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for m in METHODS:
        for r in results["two-disks"][m]:
            if "error" in r:
                lines.append(f"| {m} | {r['h']:g} | stopped: {r['error']} |||||||| ")
                continue
            lines.append(f"| {m} | {r['h']:g} | {r['cells']} | {r['steps']} | {r['contact_duration']:.5f} | "
                         f"{r['max_force']:.4f} | {r['kinetic_end_over_start']:.4f} | "
                         f"{r['max_penetration_over_facet_size']:.3f} | {r['drift']:.1e} | {r['wall_s']:.1f} |")
    fem = results["hertz"]["fem_reference"]
    lines += ["", "## hertz (static)", "",
              f"Against the P2 FEM reference of hertz.json (h = {fem['h']:g} m): u_top = "
              f"{fem['top_vertical_displacement']:.6e} m, a = {fem['contact_half_width']:.5e} m.", "",
              "| method | h (m) | cells | u_top (m) | du_top | a (m) | da | a fit (m) | da fit |",
              "|---|---|---|---|---|---|---|---|---|"]
    for m in METHODS:
        for r in results["hertz"][m]:
            lines.append(f"| {m} | {r['h']:g} | {r['cells']} | {r['u_top']:.5e} | "
                         f"{r['u_top'] / fem['top_vertical_displacement'] - 1:+.3%} | {r['a']:.5e} | "
                         f"{r['a'] / fem['contact_half_width'] - 1:+.2%} | {r['a_fit']:.5e} | "
                         f"{r['a_fit'] / fem['contact_half_width_fit'] - 1:+.2%} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", type=int, nargs="*", default=[1, 2, 4, 8])
    parser.add_argument("--disk-h", type=float, nargs="*", default=[0.04, 0.02, 0.01, 0.005])
    parser.add_argument("--hertz-h", type=float, nargs="*", default=[0.015, 0.0075])
    parser.add_argument("--quick", action="store_true", help="n = 1, 2; h = 0.04, 0.02; hertz 0.015")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "docs" / "validation" / "scheme_b.json")
    args = parser.parse_args(argv)
    if args.quick:
        args.levels, args.disk_h, args.hertz_h = [1, 2], [0.04, 0.02], [0.015]
    fem_hertz = json.loads((ROOT / "docs" / "validation" / "hertz.json").read_text())["runs"]["fem-P2"][-1]
    results = {"cantilever": {"fem_reference": fem_tip(16) if not args.quick else fem_tip(4),
                              "fem_n8": fem_tip(8) if not args.quick else fem_tip(2)},
               "two-disks": {}, "hertz": {"fem_reference": fem_hertz}}
    for m in ("dem-A", "dem-B"):
        results["cantilever"][m] = [dem_tip(n, m) for n in args.levels]
    with tempfile.TemporaryDirectory() as work:
        for m in METHODS:
            results["two-disks"][m] = [two_disks(m, h, pathlib.Path(work)) for h in args.disk_h]
            results["hertz"][m] = [hertz(m, h, pathlib.Path(work)) for h in args.hertz_h]
    if MPI.COMM_WORLD.rank == 0:
        args.out.write_text(json.dumps(results, indent=1) + "\n")
        command = "python validation/scheme_b.py" + (" --quick" if args.quick else "")
        args.out.with_suffix(".md").write_text(page(results, command))
    return results


if __name__ == "__main__":
    main()
