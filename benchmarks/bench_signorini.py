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


def charts(results, series, out_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dolfinx_dem import exact

    conv = results["convergence"]
    files = {}
    # work-precision
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(13, 5))
    for method, rows in conv["methods"].items():
        err = [r["tip_l2"] for r in rows]
        ax0.loglog([r["wall_time_s"] for r in rows], err, STYLES[method], label=LABELS[method])
        ax1.loglog([r["unknowns"] for r in rows], err, STYLES[method],
                   label=f"{LABELS[method]} (order {conv['order_tip_l2'][method]:.2f})")
        if method in DEM:
            ax0.loglog([r["runner_wall_time_s"] for r in rows], err, STYLES[method][0] + ":", mfc="none",
                       color=ax0.lines[-1].get_color(), label=f"{method}: scene runner incl. output")
    ax0.set(xlabel="wall time (s): set-up + time stepping", ylabel="tip position error, L2(0, 2) (m s$^{1/2}$)",
            title="bar-impact: error against wall time")
    ax1.set(xlabel="unknowns (FEM dofs N+1, DEM cells N)", ylabel="tip position error, L2(0, 2) (m s$^{1/2}$)",
            title="bar-impact: error against unknowns")
    for ax in (ax0, ax1):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle(f"CFL {CFL}, N = {', '.join(map(str, conv['n']))}, serial")
    fig.tight_layout()
    files["work_precision"] = out_dir / "signorini_work_precision.png"
    fig.savefig(files["work_precision"], dpi=110)
    plt.close(fig)

    # stability
    stab = results["stability"]
    fig, ax = plt.subplots(figsize=(8, 5))
    floor = 1e-16
    for method, rows in stab["runs"].items():
        ok = [r for r in rows if r["stable"]]
        bad = [r for r in rows if not r["stable"]]
        line, = ax.semilogy([r["cfl"] for r in ok], [max(r["energy_rel_error_max"], floor) for r in ok],
                            STYLES[method], label=LABELS[method], ms=5)
        if bad:
            ax.semilogy([r["cfl"] for r in bad], [max(r["energy_rel_error_max"], floor) for r in bad], "x",
                        color=line.get_color(), ms=11, mew=2.5)
    ax.plot([], [], "kx", ms=11, mew=2.5, label="failed (blow-up / DEM monitor stop), energy error before the stop")
    for method in ("projection", "modified-mass", "dem-A"):
        if method in stab["cfl_limit"]:
            ax.axvline(stab["cfl_limit"][method], color="k", lw=0.6, ls=":")
    ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
    ax.set(xlabel="CFL = c dt / dx", ylabel="max |E - E0| / E_exact over the run",
           title=f"bar-impact, N = {stab['n']}: energy error against CFL (dotted: linear limit)")
    ax.set_xscale("log")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    files["stability"] = out_dir / "signorini_stability.png"
    fig.savefig(files["stability"], dpi=110)
    plt.close(fig)

    # energy against time, N = 100 (or the second mesh)
    n = 100 if 100 in conv["n"] else conv["n"][-1]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for method in FEM + DEM:
        s = series[method, n]
        if method in FEM:
            t, e = s.t, s.energy
        else:
            t, e = s["t"], s["pseudo_energy"]
        ax.semilogy(t, np.maximum(np.abs(e - e[0]) / E_REF["impact"], floor), lw=1, label=LABELS[method])
    for x in (T1, T2):
        ax.axvline(x, color="k", lw=0.6, ls=":")
    ax.set(xlabel="t (s)", ylabel="|E - E0| / E0", title=f"bar-impact, N = {n}, CFL {CFL}: energy error",
           ylim=(floor / 2, 1.0))
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    files["energy"] = out_dir / "signorini_energy.png"
    fig.savefig(files["energy"], dpi=110)
    plt.close(fig)

    # tip and pressure, N = 100
    fig, (ax0, ax1, ax2) = plt.subplots(1, 3, figsize=(16, 4.5))
    tf = np.linspace(0.0, 2.0, 4001)
    ax0.plot(tf, exact.impact_tip_position(tf), "k-", lw=2.5, alpha=0.3, label="exact")
    for ax in (ax1, ax2):
        ax.plot(tf, exact.impact_contact_pressure(tf), "k-", lw=2.5, alpha=0.3, label="exact")
    for k, method in enumerate(FEM + DEM):
        s = series[method, n]
        t, tip, p = ((s.t, s.tip_position, s.contact_pressure) if method in FEM
                     else (s["t"], s["tip_position"], s["contact_pressure"]))
        color = f"C{k}"
        ax0.plot(t, tip, lw=0.9, color=color, label=LABELS[method])
        (ax2 if method == "newmark-penalty" else ax1).plot(t, p, lw=0.9, color=color, label=LABELS[method])
    ax0.set(xlabel="t (s)", ylabel="tip position (m)", xlim=(0.3, 2.0), ylim=(-0.2, 8.5))
    ax1.set(xlabel="t (s)", ylabel="contact pressure (Pa)", xlim=(0.4, 1.4), title="contact pressure")
    ax2.set(xlabel="t (s)", ylabel="contact pressure (Pa)", xlim=(0.4, 1.4),
            title="contact pressure, Newmark + penalty (kappa = 100 E/h)")
    for ax in (ax0, ax1, ax2):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"bar-impact, N = {n}, CFL {CFL}")
    fig.tight_layout()
    files["impact"] = out_dir / "signorini_impact.png"
    fig.savefig(files["impact"], dpi=110)
    plt.close(fig)
    return {k: v.name for k, v in files.items()}


# --- report ---------------------------------------------------------------------------------------


def _f(x, fmt="{:.3g}"):
    return "-" if x is None else fmt.format(x)


def markdown(results, command) -> str:
    conv, stab = results["convergence"], results["stability"]
    ns = conv["n"]
    lines = [
        "# Signorini bar: DEM against the FEM peers of Doyen, Ern & Piperno (2011)",
        "",
        "Written by `benchmarks/bench_signorini.py` (all numbers and figures below come from one run",
        "of it, serial, on the shared 2-core development machine; wall times are noisy, roughly",
        "+-20 %). Command, from the repository root:",
        "",
        "```",
        command,
        "```",
        "",
        f"Run: {results['date']}, commit {results['commit']}, total {results['wall_time_s']:.0f} s"
        + (" (quick mode)" if results["quick"] else "") + "."
        + ("" if pathlib.Path(results["package_path"]) == ROOT / "dolfinx_dem" else
           f" The package was imported from `{results['package_path']}` (PYTHONPATH), not from this"
           " working tree."),
        "",
        "Methods (details in `dolfinx_dem/fem/signorini.py`): P1 finite elements on a DOLFINx interval",
        "mesh (K, M and the load assembled by DOLFINx, time stepping in numpy/scipy):",
        "",
        "- **(a) projection**: explicit central differences, lumped mass, the contact node projected onto",
        "  x_tip >= 0 after each displacement update, its half-step velocity reset consistently;",
        "- **(b) modified mass**: the contact node's lumped mass moved to its neighbour; explicit central",
        "  differences on the other nodes, the contact node from its static Signorini problem each step;",
        "- **(c) Newmark + penalty**: trapezoidal rule (beta = 1/4, gamma = 1/2), consistent mass, penalty",
        "  kappa = 100 E / h, semi-smooth Newton per step;",
        "- **DEM A / B**: MEMM with contact-event splitting (the scenes `bar-impact`, `bar-bounce`).",
        "",
        "Energies: E0 = 500 J/m^2 (benchmark 1), 1000 J/m^2 (benchmark 2, gravity potential zero at",
        "the obstacle). The explicit FEM schemes and the DEM report their pseudo-energy",
        "1/2 v^{n-1/2}.M v^{n+1/2} + V(u^n), which central differences conserve exactly for a linear",
        "problem; Newmark reports 1/2 v.M v + 1/2 u.K u + penalty energy.",
        "",
        f"## Benchmark 1 (`bar-impact`), CFL {CFL}, T = 2 s",
        "",
        "Wall time = set-up (mesh, assembly / DEM discretisation) + time stepping, no output. For the",
        "DEM, `runner` is `simulation.run` (the scene runner, which writes series.csv every step, the",
        "XDMF solution and a picture). FEM wall times are the best of 3 runs, bare DEM loops of 2, runner 1.",
        "",
        "![work-precision](signorini_work_precision.png)",
        "",
        "### Tip-position error L2(0, 2) (m s^1/2)",
        "",
        "| N | " + " | ".join(LABELS[m] for m in conv["methods"]) + " |",
        "|---|" + "---|" * len(conv["methods"]),
    ]
    for i, n in enumerate(ns):
        lines.append(f"| {n} | " + " | ".join(f"{conv['methods'][m][i]['tip_l2']:.4f}" for m in conv["methods"]) + " |")
    lines.append("| fitted order | " + " | ".join(f"**{_f(conv['order_tip_l2'][m], '{:.2f}')}**"
                                                   for m in conv["methods"]) + " |")
    lines.append("| pairwise orders | " + " | ".join(", ".join(f"{o:.2f}" for o in conv["order_tip_l2_pairwise"][m])
                                                      for m in conv["methods"]) + " |")
    lines += ["", "### Wall time (s)", "",
              "| N | " + " | ".join(conv["methods"]) + " | DEM-A runner | DEM-B runner |",
              "|---|" + "---|" * (len(conv["methods"]) + 2)]
    for i, n in enumerate(ns):
        lines.append(f"| {n} | " + " | ".join(f"{conv['methods'][m][i]['wall_time_s']:.3f}" for m in conv["methods"])
                     + f" | {conv['methods']['dem-A'][i]['runner_wall_time_s']:.2f}"
                     + f" | {conv['methods']['dem-B'][i]['runner_wall_time_s']:.2f} |")
    lines.append("| time per step at the largest N (ms) | " + " | ".join(
        f"{1e3 * conv['methods'][m][-1]['solve_time_s'] / conv['methods'][m][-1]['steps']:.3f}"
        for m in conv["methods"]) + " | | |")
    bd = results.get("dem_step_breakdown")
    if bd:
        fem_b = conv["methods"]["modified-mass"][-1]
        lines += ["", f"Where a DEM step goes (scheme A, N = {bd['n']}, in the contact phase, medians of 200): "
                  f"a MEMM step {1e3 * bd['step']:.3f} ms, of which the contact: its force integral split at "
                  f"events {1e3 * bd['impulse']:.3f} ms and its energy {1e3 * bd['contact_energy']:.3f} ms (the rest "
                  f"is one pass over Q, one vector update and the stability monitor; for comparison the elastic "
                  f"force by true products {1e3 * bd['elastic_force']:.3f} ms); the tip probe of the "
                  f"loop {1e3 * bd['tip_probe']:.3f} ms. FEM (b) step: "
                  f"{1e3 * fem_b['solve_time_s'] / fem_b['steps']:.3f} ms (numpy on {bd['n'] + 1} dofs)."]
    lines += ["", "### Time to reach a tip error (s), log-log interpolated between meshes", "",
              "| target L2 error | " + " | ".join(conv["methods"]) + " | best explicit FEM | DEM-A / best | DEM-B / best |",
              "|---|" + "---|" * (len(conv["methods"]) + 3)]
    for target, row in results["time_to_error"].items():
        lines.append(f"| {target} | " + " | ".join(_f(row[m], "{:.3f}") for m in conv["methods"])
                     + f" | {row['best_explicit_fem'] or '-'} | {_f(row['dem-A_over_best_explicit_fem'], '{:.1f}')}"
                     + f" | {_f(row['dem-B_over_best_explicit_fem'], '{:.1f}')} |")
    lines += ["", "Why the DEM takes that long (the factors of the ratio, dispersion, the variants the paper allows): "
              "[signorini_tte.md](signorini_tte.md) (`bench_signorini_tte.py`)."]
    n_show = 100 if 100 in ns else ns[-1]
    i_show = ns.index(n_show)
    lines += ["", f"### Contact pressure, energy, N = {n_show}", "",
              "![tip and pressure](signorini_impact.png)", "",
              "![energy](signorini_energy.png)", "",
              "| | mean p on [1/2, 7/6] (Pa, exact 300) | RMS(p - 300) / 300 on the contact | max p (Pa) "
              "| max \\|p\\| after 7/6 + 0.05 s (Pa) | p error L1 (Pa s) | penetration (m) | energy max \\|E-E0\\|/E_exact "
              "| energy final (E-E0)/E_exact |",
              "|---|---|---|---|---|---|---|---|---|"]
    for m in conv["methods"]:
        r = conv["methods"][m][i_show]
        lines.append(f"| {LABELS[m]} | {r['pressure_mean_contact']:.2f} | {r['pressure_rms_oscillation_contact']:.3f} "
                     f"| {r['pressure_max']:.1f} | {r['pressure_max_after_release']:.3g} | {r['pressure_l1']:.3g} "
                     f"| {r['penetration']:.2e} | {r['energy_rel_error_max']:.2e} | {r['energy_rel_error_final']:+.2e} |")
    lines += ["", "Energy error (final (E - E0) / E_exact) against N:", "",
              "| N | " + " | ".join(conv["methods"]) + " |", "|---|" + "---|" * len(conv["methods"])]
    for i, n in enumerate(ns):
        lines.append(f"| {n} | " + " | ".join(f"{conv['methods'][m][i]['energy_rel_error_final']:+.2e}"
                                               for m in conv["methods"]) + " |")
    lines += ["", "Pressure RMS oscillation on the contact (relative to 300 Pa) against N:", "",
              "| N | " + " | ".join(conv["methods"]) + " |", "|---|" + "---|" * len(conv["methods"])]
    for i, n in enumerate(ns):
        lines.append(f"| {n} | " + " | ".join(f"{conv['methods'][m][i]['pressure_rms_oscillation_contact']:.3f}"
                                               for m in conv["methods"]) + " |")
    lines += ["", "### Notes", "",
              "- (a) loses exactly the contact node's kinetic energy m_0 v0^2 / 2 = E0 / (2 N) at the impact step",
              "  (its velocity is set to 0 by the projection) and nothing at the lift-off; (b) conserves its",
              "  pseudo-energy to round-off through the impact and changes it only at the lift-off step; (c)",
              "  conserves its energy to round-off on every step without a contact switch, but with the stiff",
              "  penalty the contact node rattles on and off the obstacle through the contact phase (the",
              "  pressure spikes above) and each switch changes the energy. `tests/test_fem_signorini.py`",
              "  asserts these.",
              "- The DEM's pseudo-energy is conserved to round-off, but at equal N its tip error is larger than",
              "  that of the FEM schemes, and its step costs more (see above): the time to reach a tip error",
              "  is the product of both.",
              ]
    lines += ["", f"## Stability sweep (benchmark 1, N = {stab['n']}, T = {stab['t_end']:g} s)", "",
              "![stability](signorini_stability.png)", "",
              "Linear limits (CFL): " + ", ".join(f"{m} {v:.6g}" for m, v in stab["cfl_limit"].items()) + "."
              + (f" The DEM's stable step from the bound on lambda_max (`stable_time_step()`, what `time.cfl` "
                 f"uses): CFL {stab['cfl_bound_dem-A']:.6g}." if "cfl_bound_dem-A" in stab else ""),
              "A failed FEM run is one whose kinetic + elastic energy exceeded 10 x E0 (stopped there); a failed",
              "DEM run is one stopped by the MEMM stability monitor (`InstabilityError`).", "",
              "| CFL | " + " | ".join(stab["runs"]) + " |", "|---|" + "---|" * len(stab["runs"])]
    all_cfl = sorted({r["cfl_requested"] for rows in stab["runs"].values() for r in rows})
    for cfl in all_cfl:
        cells = []
        for rows in stab["runs"].values():
            r = next((r for r in rows if r["cfl_requested"] == cfl), None)
            if r is None:
                cells.append("")
            elif r["stable"]:
                cells.append(f"{r['energy_rel_error_max']:.1e}")
            else:
                cells.append(f"**failed** t = {r['stopped_at_t']:.3g} s")
        actual = next(r["cfl"] for rows in stab["runs"].values() for r in rows if r["cfl_requested"] == cfl)
        lines.append(f"| {actual:.4g} | " + " | ".join(cells) + " |")
    lines += ["", "Entries: max |E - E0| / E_exact (500 J/m^2) of a completed run, or the time of the stop.",
              "Newmark is never stopped (no blow-up criterion is applied to it); its energy error is listed.", ""]
    if "penalty" in results:
        pen = results["penalty"]
        lines += ["## Penalty parameter of method (c) (benchmark 1, CFL 0.75)", "",
                  "kappa = factor x E / h. Tip L2 error / final energy error / penetration:", "",
                  "| factor | " + " | ".join(f"N = {n}" for n in pen["n"]) + " |", "|---|" + "---|" * len(pen["n"])]
        for f, rows in pen["runs"].items():
            lines.append(f"| {f} | " + " | ".join(f"{r['tip_l2']:.4f} / {r['energy_rel_error_final']:+.1e} / {r['penetration']:.1e}"
                                                 for r in rows) + " |")
        lines.append("")
    if "bounce" in results:
        b = results["bounce"]
        lines += [f"## Benchmark 2 (`bar-bounce`), N = {b['n']}, CFL {b['cfl']}, T = 20 s", "",
                  "| | tip L2(0, 20) | first peak (m, exact 4.444) | second peak (m, exact 5) | energy max \\|E-E0\\|/E0 "
                  "| energy final | penetration (m) | wall (s) |", "|---|---|---|---|---|---|---|---|"]
        lines[-2] = lines[-2].replace("\\|E-E0\\|/E0", "\\|E-E0\\|/E_exact")
        for m, r in b["methods"].items():
            lines.append(f"| {LABELS[m]} | {r['tip_l2']:.3f} | {r['peaks'][0]:.4f} ({100 * r['peaks_rel_error'][0]:+.1f} %) "
                         f"| {r['peaks'][1]:.4f} ({100 * r['peaks_rel_error'][1]:+.1f} %) | {r['energy_rel_error_max']:.2e} "
                         f"| {r['energy_rel_error_final']:+.2e} | {r['penetration']:.2e} | {r['wall_time_s']:.2f} |")
        lines += ["", "Peaks: highest tip position in the exact first two flights, (5/3, 11/3) and (13/3, 19/3) s.",
                  "DEM wall times here are the scene runner's.", ""]
    return "\n".join(lines) + "\n"


def started(out_dir: str):
    """The folder ``out_dir`` (made), the start time, and a log that prints the time since it."""
    folder = pathlib.Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    wall = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - wall:7.1f} s] {msg}", flush=True)

    return folder, wall, log


def main(argv=None) -> int:
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
