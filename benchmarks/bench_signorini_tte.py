"""Why the DEM takes longer than the best explicit FEM to reach a tip error on ``bar-impact``.

Three parts, all on benchmark 1 of Doyen, Ern & Piperno (2011) (see bench_signorini.py):

1. **Dispersion** of the DEM's 1D operator: the eigenfrequencies of M^-1 K (K = Q^T Q of the
   assembled discretisation, free bar, N = 100) against the exact ones (j pi c / L) and those of
   the P1 lumped-mass stiffness (tridiagonal E/h [-1 2 -1], masses rho h, rho h / 2 at the ends).
   For small theta = j pi h / L, omega_h / omega = 1 - beta theta^2; central differences (and
   MEMM, which on a linear problem is central differences) at CFL nu add + nu^2 / 24, so the
   fully discrete coefficient is beta - nu^2 / 24 (both fitted from the eigenvalues). Also the
   linear stability limit in CFL units, 2 / (sqrt(lambda_max) dt/CFL), for each eta.
2. **Decomposition** of the time-to-error ratio of bench_signorini.py's run (its JSON): at each
   target error, the mesh N each method needs (log-log interpolated, as ``time_to_error``), the
   steps per cell, and the wall time per step; the ratio is exactly their product.
3. **Variants** the paper and the scene allow: eta, scheme A/B, CFL up to the stable limit; each
   measured as bench_signorini.py measures (bare MEMM loop, set-up + stepping, best of
   ``REPEATS``, N = 50 ... 800, ``time_to_error`` at 0.05, 0.03, 0.025), against the explicit
   FEM schemes (a), (b) run in the same process at CFL 0.75 (the benchmark's) and at 0.99.

Writes ``signorini_tte.json`` and the page ``signorini_tte.md`` in the output folder (the text:
signorini_tte_report.py). Serial. Usage::

    python benchmarks/bench_signorini_tte.py                  # -> docs/bench/ (~2 min)
    python benchmarks/bench_signorini_tte.py --quick --out-dir /tmp/tte   # ~15 s
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import time

import bench_signorini as bs
import numpy as np
from signorini_tte_report import _f, section
from work_precision import time_to_error  # benchmarks/ is on sys.path when a script runs

ROOT = pathlib.Path(__file__).resolve().parent.parent
L, E, C = bs.L, bs.E, bs.C
TARGETS = (0.05, 0.03, 0.025)
REPEATS = 5  # rounds; in each, every case ceil(400 / N) times (the machine is shared); the fastest kept
#: (label, method, eta / E, CFL): the benchmark's case first; CFLs below each eta's linear limit
#: (1.0002 for eta = E, 1.732 for E/3, 1.90 for E/6, 0.707 for 2 E; part 1 measures them)
VARIANTS = (
    ("A, eta = E, CFL 0.75 (benchmark)", "dem-A", 1.0, 0.75),
    ("B, eta = E, CFL 0.75", "dem-B", 1.0, 0.75),
    ("A, eta = 2 E, CFL 0.7", "dem-A", 2.0, 0.7),
    ("A, eta = E, CFL 0.99", "dem-A", 1.0, 0.99),
    ("A, eta = E/3, CFL 0.75", "dem-A", 1.0 / 3.0, 0.75),
    ("A, eta = E/3, CFL 1.7", "dem-A", 1.0 / 3.0, 1.7),
    ("A, eta = E/6, CFL 1.85", "dem-A", 1.0 / 6.0, 1.85),
    ("B, eta = E/6, CFL 1.85", "dem-B", 1.0 / 6.0, 1.85),
)
FEM_CFLS = (0.75, 0.99)
#: coarser meshes for the FEM at CFL 0.99, whose error at N = 50 is already below the targets
FEM_COARSE = (10, 20)


# --- 1. dispersion ----------------------------------------------------------------------------------


def dem_frequencies(method, n, eta_over_e):
    """Sorted eigenfrequencies (rad/s) of M^-1 K of the DEM bar (free, no contact)."""
    import scipy.linalg
    from mpi4py import MPI

    from dolfinx_dem import scenes, simulation

    scene = scenes.load("bar-impact", overrides={"method": method, "mesh.n": n, "material.eta": eta_over_e * E})
    dem = simulation.build(scene, MPI.COMM_SELF).dem
    Q = dem.rows.Q[: dem.rows.num_owned].toarray()
    lam = scipy.linalg.eigh(Q.T @ Q, np.diag(dem.mass.array), eigvals_only=True)
    return np.sqrt(np.abs(lam))


def p1_lumped_frequencies(n):
    """Sorted eigenfrequencies of the P1 lumped-mass free bar."""
    import scipy.linalg

    h = L / n
    K = np.zeros((n + 1, n + 1))
    for i in range(n):
        K[i:i + 2, i:i + 2] += E / h * np.array([[1.0, -1.0], [-1.0, 1.0]])
    m = np.full(n + 1, bs.RHO * h)
    m[[0, -1]] *= 0.5
    return np.sqrt(np.abs(scipy.linalg.eigh(K, np.diag(m), eigvals_only=True)))


def dispersion_coefficient(omega, n, cfl=0.0, modes=slice(1, 9)):
    """beta of omega_h / omega = 1 - beta theta^2, fitted on the lowest modes (j = 1 ... 8;
    mode 0 is the rigid one); with ``cfl`` > 0 the fully discrete (central differences)
    frequency (2 / dt) arcsin(omega_h dt / 2), dt = cfl h / c."""
    h = L / n
    j = np.arange(len(omega))[modes]
    theta = j * math.pi * h / L
    w = omega[modes]
    if cfl > 0:
        dt = cfl * h / C
        w = 2.0 / dt * np.arcsin(w * dt / 2.0)
    ratio = w / (j * math.pi * C / L)
    return float(np.polyfit(theta**2, ratio - 1.0, 2)[1] * -1.0)


def dispersion_study(n, etas, cfls):
    out = {"n": n, "p1_lumped": {}, "dem": []}
    w = p1_lumped_frequencies(n)
    j = np.array([n // 4, n // 2])  # theta = pi/4, pi/2
    out["p1_lumped"] = {"beta": dispersion_coefficient(w, n), "cfl_limit": 2.0 * C / (w.max() * L / n),
                        "ratio_quarter_half": (w[j] / (j * math.pi * C / L)).tolist(),
                        "beta_full": {f"{c:g}": dispersion_coefficient(w, n, c) for c in cfls}}
    for method in ("dem-A", "dem-B"):
        for eta in etas:
            w = dem_frequencies(method, n, eta)
            out["dem"].append({
                "method": method, "eta_over_E": eta, "beta": dispersion_coefficient(w, n),
                "cfl_limit": 2.0 * C / (w.max() * L / n),
                "ratio_quarter_half": (w[j] / (j * math.pi * C / L)).tolist(),
                "beta_full": {f"{c:g}": dispersion_coefficient(w, n, c) for c in cfls
                              if c < 2.0 * C / (w.max() * L / n)}})
    return out


# --- 2. decomposition ---------------------------------------------------------------------------------


def _at_error(rows, key, target):
    """``key`` of ``rows`` log-log interpolated at the error ``target`` (as time_to_error)."""
    return time_to_error([r["tip_l2"] for r in rows], [r[key] for r in rows], target)


def decomposition(methods, targets, fem=("projection", "modified-mass"), dem=("dem-A", "dem-B")):
    """For each target and DEM method: N, steps, wall at the target (DEM and best explicit FEM)
    and the factors N_D/N_F x (steps_D/N_D)/(steps_F/N_F) x (wall per step D / F) = wall ratio."""
    out = {}
    for target in targets:
        walls = {m: _at_error(methods[m], "wall_time_s", target) for m in fem}
        walls = {m: w for m, w in walls.items() if w is not None}
        if not walls:
            continue
        best = min(walls, key=walls.get)
        f = {k: _at_error(methods[best], k, target) for k in ("n", "steps", "wall_time_s", "setup_time_s")}
        for d in dem:
            g = {k: _at_error(methods[d], k, target) for k in ("n", "steps", "wall_time_s", "setup_time_s")}
            if g["n"] is None:
                continue
            row = {"best_fem": best, "n_fem": f["n"], "n_dem": g["n"], "steps_fem": f["steps"], "steps_dem": g["steps"],
                   "wall_fem": f["wall_time_s"], "wall_dem": g["wall_time_s"],
                   "setup_share_fem": f["setup_time_s"] / f["wall_time_s"],
                   "setup_share_dem": g["setup_time_s"] / g["wall_time_s"],
                   "n_ratio": g["n"] / f["n"],
                   "steps_per_cell_ratio": (g["steps"] / g["n"]) / (f["steps"] / f["n"]),
                   "cost_per_step_ratio": (g["wall_time_s"] / g["steps"]) / (f["wall_time_s"] / f["steps"])}
            row["product"] = row["n_ratio"] * row["steps_per_cell_ratio"] * row["cost_per_step_ratio"]
            row["ratio"] = g["wall_time_s"] / f["wall_time_s"]
            out[f"{target:g}/{d}"] = row
    return out


def error_ratio_at_equal_n(methods, dem="dem-A", fems=("projection", "modified-mass")):
    """DEM error / FEM error on each mesh, and the N ratio it implies at the DEM's order."""
    e_d = np.array([r["tip_l2"] for r in methods[dem]])
    n = np.array([r["n"] for r in methods[dem]], dtype=float)
    order = -float(np.polyfit(np.log(n), np.log(e_d), 1)[0])
    out = {"n": n.astype(int).tolist(), "dem_order": order}
    for m in fems:
        ratio = e_d / np.array([r["tip_l2"] for r in methods[m]])
        out[m] = {"error_ratio": ratio.tolist(), "n_ratio_at_dem_order": (ratio ** (1.0 / order)).tolist(),
                  "stepping_per_step_ratio": [(d["solve_time_s"] / d["steps"]) / (f["solve_time_s"] / f["steps"])
                                              for d, f in zip(methods[dem], methods[m])],
                  "setup_ratio": [d["setup_time_s"] / f["setup_time_s"] for d, f in zip(methods[dem], methods[m])],
                  "stepping_per_step_ms": [1e3 * f["solve_time_s"] / f["steps"] for f in methods[m]]}
    out["dem_stepping_per_step_ms"] = [1e3 * d["solve_time_s"] / d["steps"] for d in methods[dem]]
    return out


# --- 3. variants ----------------------------------------------------------------------------------------


def _steps_dt(n, cfl, t_end=2.0):
    steps = math.ceil(t_end * C * n / (cfl * L) - 1e-9)
    return steps, t_end / steps


def run_dem(method, n, eta_over_e, cfl):
    """One DEM run of a variant on one mesh: tip L2 error and wall time, or the failure."""
    from dolfinx_dem import exact, memm

    steps, dt = _steps_dt(n, cfl)
    try:
        setup, solve, t, tip = bs.run_dem_loop(method, n, dt, 2.0, overrides={"material.eta": eta_over_e * E})
    except memm.InstabilityError as err:
        return {"n": n, "steps": steps, "failed": str(err).split(":")[0]}
    return {"n": n, "steps": steps, "tip_l2": bs.l2_in_time(t, tip - exact.impact_tip_position(t)),
            "wall_time_s": setup + solve, "setup_time_s": setup, "solve_time_s": solve}


def run_fem(method, n, cfl):
    r = bs.run_fem(method, n, cfl=cfl, repeats=1)
    m = bs.impact_metrics(r.t, r.tip_position, r.contact_pressure, r.energy)
    return {"n": n, "steps": r.n_steps, "tip_l2": m["tip_l2"], "wall_time_s": r.wall_time_s,
            "setup_time_s": r.setup_time_s, "solve_time_s": r.solve_time_s}


def _fastest(run, method, n, *args):
    """The fastest of ceil(400 / n) calls of ``run(method, n, *args)`` (N = 50: 8, N >= 400: 1): every
    mesh gets about the same time, the short runs, most exposed to the load of a shared machine, more
    tries."""
    runs = (run(method, n, *args) for _ in range(math.ceil(400 / n)))
    return min(runs, key=lambda r: r.get("wall_time_s", math.inf))


def contact_quality(method, n, eta_over_e, cfl, workdir):
    """Pressure oscillation and pseudo-energy of one scene-runner run (N = ``n``)."""
    steps, dt = _steps_dt(n, cfl)
    summary, s, _ = bs.run_dem_runner(method, n, dt, 2.0, workdir, overrides={"material.eta": eta_over_e * E})
    m = bs.impact_metrics(s["t"], s["tip_position"], s["contact_pressure"], s["pseudo_energy"])
    return {k: m[k] for k in ("pressure_rms_oscillation_contact", "pressure_max", "pressure_max_after_release",
                              "pressure_l1", "energy_rel_error_max")}


def variant_study(ns, targets, log, variants=VARIANTS):
    import tempfile

    # the repeats interleaved (every FEM and DEM case in each of REPEATS rounds; the fastest run of
    # each kept), so that a burst of load on the shared machine slows one round, not one method
    fem_cases = {f"{m} CFL {cfl:g}": (m, cfl, (*FEM_COARSE, *ns) if cfl != 0.75 else ns)
                 for cfl in FEM_CFLS for m in ("projection", "modified-mass")}
    fem_runs, dem_runs = {k: [] for k in fem_cases}, {v[0]: [] for v in variants}
    for _ in range(REPEATS):
        for key, (m, cfl, fem_ns) in fem_cases.items():
            fem_runs[key].append([_fastest(run_fem, m, n, cfl) for n in fem_ns])
        for label, method, eta, cfl in variants:
            dem_runs[label].append([_fastest(run_dem, method, n, eta, cfl) for n in ns])

    def _best_of(runs):
        return [min(rows, key=lambda r: r.get("wall_time_s", math.inf)) for rows in zip(*runs)]

    fem = {key: _best_of(runs) for key, runs in fem_runs.items()}
    for key, rows in fem.items():
        log(f"{key}: " + ", ".join(f"{r['tip_l2']:.4f} / {r['wall_time_s']:.3f} s" for r in rows))
    out = {"n": list(ns), "fem_cfls": list(FEM_CFLS), "fem": fem, "variants": []}
    for label, method, eta, cfl in variants:
        rows = _best_of(dem_runs[label])
        v = {"label": label, "method": method, "eta_over_E": eta, "cfl": cfl, "rows": rows, "time_to_error": {}}
        with tempfile.TemporaryDirectory(prefix="tte_") as workdir:
            v["contact_n100"] = contact_quality(method, 100, eta, cfl, workdir)
        ok = [r for r in rows if "failed" not in r]
        for target in targets:
            t = time_to_error([r["tip_l2"] for r in ok], [r["wall_time_s"] for r in ok], target) if len(ok) > 1 else None
            steps = _at_error(ok, "steps", target) if len(ok) > 1 else None
            entry = {"dem": t, "n_dem": _at_error(ok, "n", target) if len(ok) > 1 else None, "steps_dem": steps}
            for cfl_f in FEM_CFLS:
                fem_s = [(_at_error(fem[f"{m} CFL {cfl_f:g}"], "steps", target),
                          _at_error(fem[f"{m} CFL {cfl_f:g}"], "n", target)) for m in ("projection", "modified-mass")]
                fem_s = [x for x in fem_s if x[0] is not None]
                entry[f"step_ratio_cfl_{cfl_f:g}"] = steps / min(fem_s)[0] if (steps and fem_s) else None
                entry[f"n_fem_cfl_{cfl_f:g}"] = min(fem_s)[1] if fem_s else None
                fem_t = {m: time_to_error([r["tip_l2"] for r in fem[f"{m} CFL {cfl_f:g}"]],
                                          [r["wall_time_s"] for r in fem[f"{m} CFL {cfl_f:g}"]], target)
                         for m in ("projection", "modified-mass")}
                fem_t = [x for x in fem_t.values() if x is not None]
                entry[f"best_fem_cfl_{cfl_f:g}"] = min(fem_t) if fem_t else None
                entry[f"ratio_cfl_{cfl_f:g}"] = t / min(fem_t) if (t and fem_t) else None
            v["time_to_error"][f"{target:g}"] = entry
        out["variants"].append(v)
        log(f"{label}: " + ", ".join(f"{r['tip_l2']:.4f} / {r['wall_time_s']:.3f} s" if "failed" not in r
                                     else "failed" for r in rows)
            + "; ratios " + ", ".join(_f(e["ratio_cfl_0.75"]) for e in v["time_to_error"].values()))
    return out


def estimate_with_benchmark_timings(var, conv, targets):
    """The variants' ratio against the FEM at CFL 0.75 with the wall times of bench_signorini.py's
    run instead of this run's: on each mesh, the benchmark's DEM set-up + its stepping time x the
    variant's steps / the benchmark's steps (eta and CFL do not change the cost of a step), then
    ``time_to_error`` against the benchmark's best explicit FEM (insensitive to this run's load)."""
    for v in var["variants"]:
        bench = {r["n"]: r for r in conv[v["method"]]}
        ok = [r for r in v["rows"] if "failed" not in r and r["n"] in bench]
        walls = [bench[r["n"]]["setup_time_s"] + bench[r["n"]]["solve_time_s"] * r["steps"] / bench[r["n"]]["steps"]
                 for r in ok]
        for target in targets:
            fem = [time_to_error([r["tip_l2"] for r in conv[m]], [r["wall_time_s"] for r in conv[m]], target)
                   for m in ("projection", "modified-mass")]
            fem = [x for x in fem if x is not None]
            t = time_to_error([r["tip_l2"] for r in ok], walls, target) if len(ok) > 1 else None
            v["time_to_error"][f"{target:g}"]["estimate_cfl_0.75"] = t / min(fem) if (t and fem) else None


def main(argv=None) -> int:
    import subprocess

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="N = 50, 100, 200, three variants, one repeat")
    parser.add_argument("--out-dir", default=str(ROOT / "docs" / "bench"))
    parser.add_argument("--signorini-json", default=str(ROOT / "docs" / "bench" / "signorini.json"),
                        help="bench_signorini.py's results, for part 2")
    args = parser.parse_args(argv)
    out_dir, wall, log = bs.started(args.out_dir)

    global REPEATS
    if args.quick:
        REPEATS = 1
    res = {"quick": args.quick, "date": time.strftime("%Y-%m-%d %H:%M"), "repeats": REPEATS, "targets": list(TARGETS)}
    res["commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                   text=True).stdout.strip() or "unknown"
    res["dispersion"] = dispersion_study(100, (1.0 / 6.0, 1.0 / 3.0, 1.0, 2.0),
                                         sorted({*FEM_CFLS, *(v[3] for v in VARIANTS)}))
    log("dispersion: P1 beta {:.4f}; ".format(res["dispersion"]["p1_lumped"]["beta"]) + ", ".join(
        f"{d['method']} eta {d['eta_over_E']:.3g}E beta {d['beta']:.4f} CFL limit {d['cfl_limit']:.4f}"
        for d in res["dispersion"]["dem"]))
    conv = json.loads(pathlib.Path(args.signorini_json).read_text())["convergence"]["methods"]
    res["decomposition"] = decomposition(conv, TARGETS)
    res["equal_n"] = error_ratio_at_equal_n(conv)
    bs.run_dem_loop("dem-A", 10, 0.025, 0.05)  # warm-up
    bs.run_fem("projection", 10, repeats=1)
    ns = [50, 100, 200] if args.quick else [50, 100, 200, 400, 800]
    targets = (0.1, 0.07) if args.quick else TARGETS
    variants = (VARIANTS[0], VARIANTS[5], VARIANTS[6]) if args.quick else VARIANTS
    res["targets"] = list(targets)
    res["variants"] = variant_study(ns, targets, log, variants)
    estimate_with_benchmark_timings(res["variants"], conv, targets)
    res["wall_time_s"] = time.perf_counter() - wall
    (out_dir / "signorini_tte.json").write_text(json.dumps(res, indent=1) + "\n")
    command = ".venv/bin/python benchmarks/bench_signorini_tte.py" + (" --quick" if args.quick else "")
    text = section(res, command)
    (out_dir / "signorini_tte.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
