"""DEM against the finite-element peers of Doyen, Ern & Piperno (2011) on the Signorini bar.

On benchmark 1 (scene ``bar-impact``: L = 10 m, rho = 1, E = 900, v0 = -10 m/s, gap 5 m, T = 2 s)
this runs, at CFL 0.75 (dt = 0.25 / N s) and N = 50, 100, 200, 400, 800 cells:

* the three FEM schemes of :mod:`dolfinx_dem.fem.signorini` (P1, DOLFINx-assembled operators):
  (a) ``projection`` explicit central differences + lumped mass + contact by projection,
  (b) ``modified-mass`` explicit with a massless contact node, (c) ``newmark-penalty`` implicit
  trapezoidal Newmark with penalty contact (kappa = 100 E / h);
* the DEM, schemes A and B, MEMM with event splitting, through the scene runner
  (``simulation.run``, which also writes series.csv, XDMF and a picture: its wall time includes
  that output) and through a bare stepping loop (``simulation.build`` + ``memm.MEMM``, recording
  the tip position each step, no output): the "solver" time used in the charts.

Recorded per method and N: tip-position error in L2(0, T) against ``exact.impact_tip_position``
(trapezoid rule on the steps), contact-pressure errors (L1, L2) and oscillation (RMS of p - 300
over the exact contact interval, relative to 300; largest pressure 0.05 s after the exact
lift-off), energy error (max and final |E - E0| / E0; the explicit schemes and the DEM report
their pseudo-energy 1/2 v^{n-1/2}.M v^{n+1/2} + V), wall times (set-up and stepping), unknowns,
fitted orders, and the wall time at which each method reaches given tip errors (log-log
interpolation between meshes), as a ratio DEM / best explicit FEM.

Plus: a stability sweep (N = 100, CFL 0.1 to 1.2; dt = T / ceil(T c / (CFL dx)) so that it
divides T) of the energy error of each explicit method, the DEM (its stability monitor stops
failing runs) and Newmark (no limit; also CFL 2 and 4); a penalty sweep of method (c); and
benchmark 2 (``bar-bounce``, N = 100, T = 20 s) for every method.

Writes ``signorini.json``, ``signorini_work_precision.png``, ``signorini_stability.png``,
``signorini_energy.png``, ``signorini_impact.png`` and ``signorini.md`` into the output folder.
Serial. Usage::

    python benchmarks/bench_signorini.py                 # full study -> docs/bench/ (~5 min)
    python benchmarks/bench_signorini.py --quick --out-dir /tmp/sig   # < 60 s
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np
from work_precision import time_to_error  # benchmarks/ is on sys.path when a script runs

ROOT = pathlib.Path(__file__).resolve().parent.parent

L, RHO, E, H0, V0 = 10.0, 1.0, 900.0, 5.0, -10.0
C = math.sqrt(E / RHO)
T1, T2 = H0 / abs(V0), H0 / abs(V0) + 2.0 * L / C  # exact contact interval [0.5, 7/6)
P_EXACT = RHO * C * abs(V0)  # 300 Pa
#: energy scales of the relative energy errors: the exact total energies (J/m^2) of benchmarks 1
#: and 2 (gravity potential zero at the obstacle). The DEM's pseudo-energy puts the zero of the
#: gravity potential elsewhere, so errors are (E - E0) / E_REF, not (E - E0) / E0.
E_REF = {"impact": 0.5 * RHO * L * V0**2, "bounce": RHO * 10.0 * (H0 * L + 0.5 * L * L)}
DEM_LOOP_REPEATS = 2  # bare DEM loops: best of 2 wall times
FEM = ("projection", "modified-mass", "newmark-penalty")
DEM = ("dem-A", "dem-B")
LABELS = {
    "projection": "FEM (a) central diff. + projection",
    "modified-mass": "FEM (b) modified mass",
    "newmark-penalty": "FEM (c) Newmark + penalty",
    "dem-A": "DEM scheme A (MEMM, split)",
    "dem-B": "DEM scheme B (MEMM, split)",
}
STYLES = {"projection": "o-", "modified-mass": "s-", "newmark-penalty": "^-", "dem-A": "D-", "dem-B": "v-"}
CFL = 0.75
FEM_REPEATS = 3  # FEM runs take < 1 s: best of 3 wall times (shared machine)


# --- metrics --------------------------------------------------------------------------------------


def l2_in_time(t, e) -> float:
    return float(np.sqrt(np.trapz(e**2, t)))


def fitted_order(h, errors) -> float:
    return float(np.polyfit(np.log(h), np.log(errors), 1)[0])


def impact_metrics(t, tip, p, energy) -> dict:
    """Errors of one benchmark 1 run against the exact solution."""
    from dolfinx_dem import exact

    t, tip, p, energy = (np.asarray(a, dtype=float) for a in (t, tip, p, energy))
    e_p = p - exact.impact_contact_pressure(t)
    inside = (t > T1 + 1e-9) & (t < T2 - 1e-9)
    tt = np.concatenate([[T1], t[inside], [T2]])
    variation = (energy - energy[0]) / E_REF["impact"]
    after = t >= T2 + 0.05
    return {
        "tip_l2": l2_in_time(t, tip - exact.impact_tip_position(t)),
        "tip_max": float(np.abs(tip - exact.impact_tip_position(t)).max()),
        "pressure_l1": float(np.trapz(np.abs(e_p), t)),
        "pressure_l2": l2_in_time(t, e_p),
        "pressure_mean_contact": float(np.trapz(np.interp(tt, t, p), tt) / (T2 - T1)) if t[-1] >= T2 else None,
        "pressure_rms_oscillation_contact": (float(np.sqrt(np.mean((p[inside] - P_EXACT) ** 2)) / P_EXACT)
                                             if inside.any() else None),
        "pressure_max": float(p.max()),
        "pressure_max_after_release": float(np.abs(p[after]).max()) if after.any() else 0.0,
        "penetration": float(max(0.0, -tip.min())),
        "energy_rel_error_max": float(np.abs(variation).max()),
        "energy_rel_error_final": float(variation[-1]),
    }


# --- runs -----------------------------------------------------------------------------------------


def run_fem(method, n, cfl=CFL, benchmark="impact", repeats=FEM_REPEATS, **kwargs):
    from dolfinx_dem.fem import signorini

    best = None
    for _ in range(repeats):
        r = signorini.solve_signorini_bar(method, benchmark, n, cfl, **kwargs)
        if best is None or r.wall_time_s < best.wall_time_s:
            best = r
    return best


def _dem_scene(method, n, dt, t_end, name="bar-impact", overrides=None):
    from dolfinx_dem import scenes

    return scenes.load(name, overrides={"method": method, "mesh.n": n, "time.dt": dt, "time.end": t_end,
                                        "output.every": 10**6, **(overrides or {})})


def run_dem_runner(method, n, dt, t_end, workdir, name="bar-impact", allow_unstable=False, overrides=None):
    """The scene runner; returns (summary, series record array, error or None). ``overrides``: more
    scene keys, as in :func:`run_dem_loop`."""
    from mpi4py import MPI

    from dolfinx_dem import memm, simulation

    folder = pathlib.Path(workdir) / f"{name}-{method}-n{n}-dt{dt:.6g}"
    error = None
    try:
        summary = simulation.run(_dem_scene(method, n, dt, t_end, name, overrides), folder, MPI.COMM_WORLD,
                                 quiet=True, overwrite=True)
    except memm.InstabilityError as err:
        if not allow_unstable:
            raise
        error = err
        summary = json.loads((folder / "summary.json").read_text())
    series = np.genfromtxt(folder / "series.csv", delimiter=",", names=True)
    return summary, series, error


def tip_probe(problem):
    """The tip position x_f + u_f of the bar's contact facet (as ``simulation.contact_values``,
    without the gap search and the contact pressure it also computes), for the bare loop."""
    from dolfinx_dem import RigidContact

    dem, c = problem.dem, problem.find(RigidContact)
    x_tip = float(dem.geometry.facet_centres[c.facets[0], 0])
    return lambda u: x_tip + float(c.facet_displacements(c.patch_values(u))[0, 0])


def run_dem_loop(method, n, dt, t_end, overrides=None):
    """Bare MEMM loop (no output): (setup s, stepping s, t, tip position). ``overrides``: more
    scene keys (e.g. ``{"material.eta": 300.0}``, bench_signorini_tte.py)."""
    from mpi4py import MPI

    from dolfinx_dem import memm, simulation

    t0 = time.perf_counter()
    scene = _dem_scene(method, n, dt, t_end, overrides=overrides)
    problem = simulation.build(scene, MPI.COMM_WORLD)
    dem = problem.dem
    n_steps = round(t_end / dt)
    stepper = memm.MEMM(problem, dt)
    u0, v0 = dem.create_vector(), dem.create_vector()
    v0.array[:] = V0
    stepper.initialise(u0, v0)
    probe = tip_probe(problem)
    tip = np.empty(n_steps + 1)
    tip[0] = probe(stepper.u)
    t1 = time.perf_counter()
    for k in range(n_steps):
        stepper.step()
        tip[k + 1] = probe(stepper.u)
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1, dt * np.arange(n_steps + 1), tip


def dem_step_breakdown(method, n, repeats=200) -> dict:
    """Median wall times (s) of one MEMM step and of its parts, DEM on bar-impact in contact."""
    import statistics

    from mpi4py import MPI

    from dolfinx_dem import memm, simulation

    dt = CFL * (L / n) / C
    from dolfinx_dem import RigidContact

    problem = simulation.build(_dem_scene(method, n, dt, 2.0), MPI.COMM_WORLD)
    dem = problem.dem
    stepper = memm.MEMM(problem, dt)
    u0, v0 = dem.create_vector(), dem.create_vector()
    v0.array[:] = V0
    stepper.initialise(u0, v0)
    for _ in range(round(0.6 / dt)):  # into the contact phase
        stepper.step()
    f = dem.create_vector()
    c = problem.find(RigidContact)
    probe = tip_probe(problem)
    parts = {
        "step": stepper.step,
        "impulse": stepper.impulse,  # the contact force integral, split at events
        "contact_energy": lambda: c.energy_correction(c.patch_values(stepper.u)),
        "elastic_force": lambda: dem.force(stepper.u, stepper.t, f),  # without contact, by true products
        "tip_probe": lambda: probe(stepper.u),
    }
    times = {k: [] for k in parts}
    for _ in range(repeats):
        for k, fn in parts.items():
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    return {"n": n, "method": method, **{k: statistics.median(v) for k, v in times.items()}}


# --- the study ------------------------------------------------------------------------------------


def convergence_study(ns, workdir, log) -> dict:
    """Benchmark 1 at CFL 0.75 for every method and N."""
    from dolfinx_dem import exact

    out = {"n": list(ns), "dx": [L / n for n in ns], "dt": [CFL * (L / n) / C for n in ns], "methods": {}}
    series = {}
    for method in FEM:
        rows = []
        for n in ns:
            r = run_fem(method, n)
            m = impact_metrics(r.t, r.tip_position, r.contact_pressure, r.energy)
            m.update(n=n, unknowns=r.n_dofs, steps=r.n_steps, dt=r.dt, cfl=r.cfl,
                     wall_time_s=r.wall_time_s, setup_time_s=r.setup_time_s, solve_time_s=r.solve_time_s,
                     rebound_velocity=float(r.mean_velocity[-1]))
            if method == "newmark-penalty":
                m.update(penalty_parameter=r.penalty_parameter,
                         newton_iterations_max=int(r.newton_iterations.max()),
                         newton_iterations_total=int(r.newton_iterations.sum()))
            rows.append(m)
            series[method, n] = r
            log(f"{method:16s} N={n:4d} tip L2 {m['tip_l2']:.4e}  energy {m['energy_rel_error_final']:+.2e}  "
                f"wall {m['wall_time_s']:.3f} s")
        out["methods"][method] = rows
    for method in DEM:
        rows = []
        for n in ns:
            dt = CFL * (L / n) / C
            summary, s, _ = run_dem_runner(method, n, dt, 2.0, workdir)
            m = impact_metrics(s["t"], s["tip_position"], s["contact_pressure"], s["pseudo_energy"])
            setup, solve, t_loop, tip_loop = min((run_dem_loop(method, n, dt, 2.0) for _ in range(DEM_LOOP_REPEATS)),
                                                 key=lambda x: x[0] + x[1])
            loop_l2 = l2_in_time(t_loop, tip_loop - exact.impact_tip_position(t_loop))
            m.update(n=n, unknowns=n, steps=int(summary["n_steps"]), dt=dt, cfl=CFL,
                     wall_time_s=setup + solve, setup_time_s=setup, solve_time_s=solve,
                     runner_wall_time_s=summary["wall_time_s"], runner_setup_time_s=summary["setup_time_s"],
                     tip_l2_loop=loop_l2, force_evaluations=summary["force_evaluations"],
                     pseudo_energy_rel_drift=summary["pseudo_energy_rel_drift"])
            if abs(loop_l2 - m["tip_l2"]) > 1e-9 * m["tip_l2"]:
                raise RuntimeError(f"{method} N={n}: loop and runner disagree ({loop_l2} vs {m['tip_l2']})")
            rows.append(m)
            series[method, n] = s
            log(f"{method:16s} N={n:4d} tip L2 {m['tip_l2']:.4e}  energy {m['energy_rel_error_final']:+.2e}  "
                f"wall {m['wall_time_s']:.3f} s (runner {m['runner_wall_time_s']:.2f} s)")
        out["methods"][method] = rows
    for method, rows in out["methods"].items():
        errs = [r["tip_l2"] for r in rows]
        out.setdefault("order_tip_l2", {})[method] = fitted_order(out["dx"], errs) if len(ns) > 1 else None
        out.setdefault("order_tip_l2_pairwise", {})[method] = [
            float(math.log(errs[i] / errs[i + 1]) / math.log(ns[i + 1] / ns[i])) for i in range(len(ns) - 1)]
        out.setdefault("order_pressure_l1", {})[method] = (
            fitted_order(out["dx"], [r["pressure_l1"] for r in rows]) if len(ns) > 1 else None)
    return out, series


def time_to_error_table(conv, targets) -> dict:
    table = {}
    for target in targets:
        row = {m: time_to_error([r["tip_l2"] for r in rows], [r["wall_time_s"] for r in rows], target)
               for m, rows in conv["methods"].items()}
        explicit = {m: row[m] for m in ("projection", "modified-mass") if row[m] is not None}
        best = min(explicit, key=explicit.get) if explicit else None
        row["best_explicit_fem"] = best
        for d in DEM:
            row[f"{d}_over_best_explicit_fem"] = (row[d] / explicit[best]) if best and row[d] else None
        table[f"{target:g}"] = row
    return table


def stability_sweep(cfls, workdir, log, n=100, t_end=2.0, dem=True) -> dict:
    from mpi4py import MPI

    from dolfinx_dem import simulation
    from dolfinx_dem.fem import signorini

    dx = L / n
    out = {"n": n, "t_end": t_end, "cfl_limit": {m: signorini.stability_limit_cfl(m, n) for m in FEM}, "runs": {}}
    if dem:  # the DEM's true limit (SLEPc) next to the bound that time.cfl uses, in CFL units
        d = simulation.build(_dem_scene("dem-A", n, 0.25 / n, t_end), MPI.COMM_WORLD).dem
        out["cfl_limit"]["dem-A"] = C * d.stable_time_step("eigenvalue") / dx
        out["cfl_bound_dem-A"] = C * d.stable_time_step() / dx
    for method in FEM + (("dem-A",) if dem else ()):
        rows = []
        for cfl in cfls + ([2.0, 4.0] if method == "newmark-penalty" else []):
            n_steps = math.ceil(t_end * C / (cfl * dx) - 1e-9)
            dt = t_end / n_steps
            if method in FEM:
                r = signorini.solve_signorini_bar(method, "impact", n, cfl, allow_unstable=True)
                m = impact_metrics(r.t, r.tip_position, r.contact_pressure, r.energy)
                row = {"stable": r.stable, "stopped_at_t": None if r.stable else float(r.t[-1]),
                       "message": r.message}
            else:
                summary, s, err = run_dem_runner(method, n, dt, t_end, workdir, allow_unstable=True)
                m = impact_metrics(s["t"], s["tip_position"], s["contact_pressure"], s["pseudo_energy"])
                row = {"stable": err is None, "stopped_at_t": None if err is None else float(err.t),
                       "message": "" if err is None else str(err).split(":")[0]}
            row.update(cfl_requested=cfl, cfl=C * dt / dx, dt=dt, steps=n_steps,
                       energy_rel_error_max=m["energy_rel_error_max"],
                       tip_l2=m["tip_l2"] if row["stable"] else None)
            rows.append(row)
            log(f"stability {method:16s} CFL {row['cfl']:.4f}: "
                f"{'stable' if row['stable'] else 'FAILED at t = {:.4g}'.format(row['stopped_at_t'])}, "
                f"energy error {row['energy_rel_error_max']:.2e}")
        out["runs"][method] = rows
        ok = [r["cfl"] for r in rows if r["stable"]]
        bad = [r["cfl"] for r in rows if not r["stable"]]
        out.setdefault("largest_stable_cfl", {})[method] = max(ok) if ok else None
        out.setdefault("smallest_failing_cfl", {})[method] = min(bad) if bad else None
    return out


def penalty_sweep(ns, penalties, log) -> dict:
    out = {"n": list(ns), "penalty": list(penalties), "runs": {}}
    for pen in penalties:
        rows = []
        for n in ns:
            r = run_fem("newmark-penalty", n, repeats=1, penalty=pen)
            m = impact_metrics(r.t, r.tip_position, r.contact_pressure, r.energy)
            m.update(n=n, kappa=r.penalty_parameter, wall_time_s=r.wall_time_s)
            rows.append(m)
        out["runs"][f"{pen:g}"] = rows
        finals = ", ".join("{:+.1e}".format(r["energy_rel_error_final"]) for r in rows)
        log(f"penalty {pen:g} E/h: tip L2 {[round(r['tip_l2'], 5) for r in rows]}, final energy [{finals}]")
    return out


def bounce_study(n, workdir, log) -> dict:
    from dolfinx_dem import exact

    t_end = 20.0
    exact_peaks = [40.0 / 9.0, 5.0]
    windows = [(5.0 / 3.0, 11.0 / 3.0), (13.0 / 3.0, 19.0 / 3.0)]  # the exact first two flights
    out = {"n": n, "t_end": t_end, "cfl": CFL, "exact_peaks": exact_peaks, "methods": {}}
    for method in FEM + DEM:
        if method in FEM:
            r = run_fem(method, n, benchmark="bounce", repeats=1)
            t, tip, energy, wall = r.t, r.tip_position, r.energy, r.wall_time_s
        else:
            summary, s, _ = run_dem_runner(method, n, CFL * (L / n) / C, t_end, workdir, name="bar-bounce")
            t, tip, energy, wall = s["t"], s["tip_position"], s["pseudo_energy"], summary["wall_time_s"]
        variation = (energy - energy[0]) / E_REF["bounce"]
        peaks = [float(tip[(t > a) & (t < b)].max()) for a, b in windows]
        row = {"tip_l2": l2_in_time(t, tip - exact.bounce_tip_position(t)),
               "energy_rel_error_max": float(np.abs(variation).max()),
               "energy_rel_error_final": float(variation[-1]), "peaks": peaks,
               "peaks_rel_error": [p / q - 1.0 for p, q in zip(peaks, exact_peaks)],
               "penetration": float(max(0.0, -tip.min())), "wall_time_s": float(wall)}
        out["methods"][method] = row
        log(f"bounce {method:16s} tip L2(0,20) {row['tip_l2']:.3f}  peaks {peaks[0]:.4f} {peaks[1]:.4f}  "
            f"energy max {row['energy_rel_error_max']:.2e}")
    return out


# --- charts -----------------------------------------------------------------------------------------


def started(out_dir: str):
    """The folder ``out_dir`` (made), the start time, and a log that prints the time since it."""
    folder = pathlib.Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    wall = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - wall:7.1f} s] {msg}", flush=True)

    return folder, wall, log


def main(argv=None) -> int:
    from signorini_report import charts, markdown
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="N = 50, 100, a short sweep: < 60 s")
    parser.add_argument("--out-dir", default=str(ROOT / "docs" / "bench"), help="folder for the JSON, PNGs, md")
    args = parser.parse_args(argv)
    out_dir, wall, log = started(args.out_dir)

    from dolfinx_dem.fem import signorini

    # warm-up: JIT-compile the forms (FEM, DEM) so no timed run pays for it
    signorini.solve_signorini_bar("projection", "impact", 10, 0.5, t_end=0.1)
    ns = [50, 100] if args.quick else [50, 100, 200, 400, 800]
    cfls = [0.5, 0.9, 1.05] if args.quick else [0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 0.999, 1.0, 1.01, 1.05, 1.1, 1.2]
    import dolfinx_dem

    package = pathlib.Path(dolfinx_dem.__file__).resolve().parent
    results = {"quick": args.quick, "package_path": str(package), "machine": platform.processor() or platform.machine(),
               "python": sys.version.split()[0], "date": time.strftime("%Y-%m-%d %H:%M")}
    try:
        results["commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                           text=True).stdout.strip()
    except OSError:
        results["commit"] = "unknown"
    with tempfile.TemporaryDirectory(prefix="bench_signorini_") as workdir:
        run_dem_runner("dem-A", 10, 0.025, 0.05, workdir)  # warm-up
        conv, series = convergence_study(ns, workdir, log)
        results["convergence"] = conv
        targets = [0.1, 0.07] if args.quick else [0.1, 0.05, 0.03, 0.025]
        results["time_to_error"] = time_to_error_table(conv, targets)
        results["dem_step_breakdown"] = dem_step_breakdown("dem-A", ns[-1])
        log(f"DEM step breakdown: {results['dem_step_breakdown']}")
        results["stability"] = stability_sweep(cfls, workdir, log, n=50 if args.quick else 100,
                                                t_end=1.0 if args.quick else 2.0, dem=not args.quick)
        if not args.quick:
            results["penalty"] = penalty_sweep(ns, [1.0, 10.0, 100.0, 1000.0], log)
            results["bounce"] = bounce_study(100, workdir, log)
    results["wall_time_s"] = time.perf_counter() - wall
    results["figures"] = charts(results, series, out_dir)
    (out_dir / "signorini.json").write_text(json.dumps(results, indent=1) + "\n")
    command = ".venv/bin/python benchmarks/bench_signorini.py" + (" --quick" if args.quick else "")
    text = markdown(results, command)
    (out_dir / "signorini.md").write_text(text)
    log(f"wrote {out_dir / 'signorini.json'}, {out_dir / 'signorini.md'} and {len(results['figures'])} figures")
    print(markdown(results, command))
    return 0


if __name__ == "__main__":
    sys.exit(main())
