# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: light
#       format_version: '1.5'
#       jupytext_version: 1.13.6
# ---

# # Dynamic Signorini problem: an elastic bar hitting a rigid obstacle
#
# This demo is implemented in a single Python file, `demo_signorini_bar.py`. It reproduces the
# one-dimensional benchmarks of the DEM paper (§5.1, Figures 5 to 9), which are benchmarks 1 and
# 2 of Doyen, Ern & Piperno (SIAM J. Sci. Comput. 33, 2011): an elastic bar that falls on a
# rigid obstacle, stays in contact while a compression wave runs up and down it, and bounces off.
# Both have exact solutions (`dolfinx_dem.exact`).
#
# This demo illustrates how to:
#
# - run the built-in scenes `bar-impact` and `bar-bounce` with boundary schemes A and B, and
#   change their mesh, time step and force quadrature through dotted-key overrides;
# - read a run's time series (`series.csv`: energies, contact gap, contact pressure, tip
#   position) and compare it with the exact solutions;
# - check that the MEMM time integrator with contact-event splitting conserves its pseudo-energy
#   to round-off through impacts and lift-offs, where Gauss-Legendre quadratures do not;
# - measure convergence orders in time-integrated norms;
# - find the stability limit of the explicit scheme, and see how the stability monitor stops an
#   unstable run.
#
# It runs in serial and in parallel, e.g. `mpirun -n 2 python3 demo_signorini_bar.py`. With the
# environment variable `DOLFINX_DEM_DEMO_QUICK=1` it runs a few short versions of each study
# (the tests do); the full run takes about a quarter of an hour and also writes the validation
# figures and numbers into `docs/validation/signorini_*`.
#
# ## The problem
#
# A bar of length $L = 10$ m, density $\rho = 1$ kg/m$^3$ and Young's modulus $E = 900$ Pa
# (wave speed $c = \sqrt{E/\rho} = 30$ m/s) occupies $[h_0, h_0 + L]$, $h_0 = 5$ m, above a rigid
# obstacle at $x = 0$. With $X \in (0, L)$ the reference coordinate, $u(t, X)$ the displacement
# and $g$ the gravity,
#
# $$
# \rho\, \ddot{u} - E\, u_{XX} = -\rho g \quad \text{in } (0, L), \qquad
# E\, u_X(t, L) = 0 ,
# $$
#
# and the lower end obeys the Signorini conditions: with the gap $x_\mathrm{tip} = h_0 + u(t, 0)$
# (the tip position) and the contact pressure $p = -E\, u_X(t, 0)$,
#
# $$
# x_\mathrm{tip} \ge 0, \qquad p \ge 0, \qquad x_\mathrm{tip}\, p = 0 .
# $$
#
# - Benchmark 1 (`bar-impact`): $g = 0$, initial velocity $v_0 = -10$ m/s. The bar flies
#   rigidly until $t_1 = h_0 / |v_0| = 0.5$ s, stays in contact with
#   $p = \rho c |v_0| = 300$ Pa for the round trip $2L/c = 2/3$ s of the compression wave, and
#   leaves at $t_2 = 7/6$ s with velocity $+10$ m/s, unstressed.
# - Benchmark 2 (`bar-bounce`): released at rest, $g = 10$ m/s$^2$. It lands at $t = 1$ s and
#   bounces forever: the exact solution (by characteristics, `exact.bounce_tip_position`) is
#   periodic with period $16/3$ s and two contacts per period. The first flight reaches only
#   4.44 m, because the bar leaves the first contact vibrating; the second contact takes the
#   vibration out again and the bar comes back to rest at 5 m at $t = 16/3$ s.
#
# ## The discretisation
#
# The DEM has one displacement $u_c$ per cell (a mass $\rho |c|$), and reconstructs the facet
# values from them; the elastic energy is that of the reconstructed gradients. Contact only
# changes the reconstruction of the candidate facet (here: the lower end): while its gap
# $g_f(u)$, affine in the cell displacements, is negative, the facet value is moved back onto the
# obstacle, $u_f = u_f^\mathrm{free} - g_f\, e_f$. Scheme A picks $e_f$ so that the facet is a
# Neumann facet ($\sigma n = 0$) out of contact and carries no tangential traction in contact;
# scheme B uses the cell value out of contact (a rigid boundary cell) and $e_f = n$. Both
# reconstructions coincide at $g_f = 0$, so the energy is continuous and piecewise quadratic, and
# the force is piecewise affine.
#
# Time is integrated with the explicit MEMM scheme (paper eq. (35)),
#
# $$
# u^{n+1} = u^n + \Delta t\, v^{n+1/2}, \qquad
# v^{n+3/2} = v^{n-1/2} + \frac{2}{\rho |c|} \int_0^{\Delta t} F_c(u^n + \tau v^{n+1/2})\, d\tau ,
# $$
#
# which conserves the pseudo-energy
# $\mathcal{E}^n = \frac12 (v^{n-1/2})^T M v^{n+1/2} + V(u^n)$ exactly when the force integral
# is exact. Along the straight path $u^n + \tau v^{n+1/2}$ every gap is affine in $\tau$, so the
# integral is split at the times $\tau_k$ where a gap changes sign, and the midpoint rule is
# exact on every piece (paper §4):
#
# $$
# \int_0^{\Delta t} F(u^n + \tau v^{n+1/2})\, d\tau
# = \sum_k (\tau_{k+1} - \tau_k)\, F\Big(u^n + \frac{\tau_k + \tau_{k+1}}{2} v^{n+1/2}\Big) .
# $$
#
# This is the default (`time.quadrature = "midpoint"`). The alternatives `gauss-legendre-q`
# (q = 1, 2, 3, 5 points) evaluate the whole force at their nodes without splitting.
#
# The outputs compared with the exact solution are the series columns `tip_position` (the
# reconstructed, contact-aware position of the lower facet), `contact_gap` (the same minus the
# obstacle position) and `contact_pressure` (the obstacle's force on the bar per unit contact area,
# the exact derivative of the energy with respect to the obstacle's position; 0 with the gap open).

# +
import json
import math
import os
import pathlib
import time

import matplotlib
import numpy as np
from mpi4py import MPI

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from dolfinx_dem import exact, memm, scenes, simulation  # noqa: E402

comm = MPI.COMM_WORLD
wall_start = time.perf_counter()
# -

# ## Settings
#
# The paper's discretisation is $N = 100$ cells ($\Delta x = 0.1$ m) and
# $\Delta t = 0.0025$ s, a CFL number $\nu = c \Delta t / \Delta x = 0.75$. The quick setting
# shortens benchmark 1 to 1.25 s (just after the lift-off at 7/6 s) and benchmark 2 to 4 s (one
# contact and one flight, on 20 and 40 cells at CFL 0.75), and uses two meshes for each
# convergence study.

# +
QUICK = os.environ.get("DOLFINX_DEM_DEMO_QUICK") == "1"

L, rho, E, h0, v0 = 10.0, 1.0, 900.0, 5.0, -10.0
c = math.sqrt(E / rho)
t_impact, t_release = h0 / abs(v0), h0 / abs(v0) + 2.0 * L / c  # 0.5 s and 7/6 s
p_impact = rho * c * abs(v0)  # 300 Pa

GAP_TOL = 1e-12  # m: a sample is "in contact" when its gap is at most this

T_impact = 1.25 if QUICK else 2.0
n_base, dt_base = 100, 0.0025
quadratures = ["gauss-legendre-2"] if QUICK else ["gauss-legendre-1", "gauss-legendre-2",
                                                  "gauss-legendre-3", "gauss-legendre-5"]
n_convergence = [50, 100] if QUICK else [50, 100, 200, 400, 800]

T_bounce = 4.0 if QUICK else 20.0
n_bounce, dt_bounce = (40, 0.00625) if QUICK else (100, 0.0025)
# The paper's common time step 0.0003125 s is CFL 0.75 on N = 800 but CFL 1.5 on N = 1600,
# beyond the stability limit (CFL 1, measured below): N = 1600 gets half of it.
refinement = ([(20, 0.0125), (40, 0.00625)] if QUICK else
              [(100, 0.0003125), (200, 0.0003125), (400, 0.0003125), (800, 0.0003125),
               (1600, 0.00015625)])

cfl_sweep = [1.05, 1.2] if QUICK else [0.1, 0.25, 0.5, 0.75, 0.9, 1.0, 1.01, 1.05, 1.1, 1.2]

out_folder = pathlib.Path("results") / "demo_signorini_bar"
# -

# ## Running a scene
#
# `scenes.load` reads a built-in scene and applies dotted-key overrides; `simulation.run` runs it
# on `comm` and writes `series.csv` (one row per step, written by rank 0) and `summary.json` into
# its folder. We read the series back on rank 0 and broadcast it. Identical runs are done once.
# A run that the stability monitor stops raises `memm.InstabilityError` (after writing its
# outputs); only the stability sweep expects that.

# +
_runs = {}


def run(name, overrides, allow_unstable=False):
    """Run scene ``name`` with ``overrides`` in a folder of results/demo_signorini_bar/ named
    after them.

    Returns ``(summary, series, error)``: the summary dict, the series as a numpy record array
    (the same on every process) and the ``InstabilityError`` that stopped the run, or None.
    """
    key = (name, tuple(sorted(overrides.items())))
    if key in _runs:
        return _runs[key]
    scene = scenes.load(name, overrides={"output.every": 10**6, **overrides})
    folder = out_folder / "_".join([name] + [f"{k.rsplit('.', 1)[-1]}{v:g}" if isinstance(v, float)
                                             else f"{k.rsplit('.', 1)[-1]}{v}" for k, v in key[1]])
    error = None
    try:
        summary = simulation.run(scene, folder, comm, quiet=True, overwrite=True)
    except memm.InstabilityError as err:
        if not allow_unstable:
            raise
        error = err
        summary = json.loads((folder / "summary.json").read_text()) if comm.rank == 0 else None
        summary = comm.bcast(summary, root=0)
    series = None
    if comm.rank == 0:
        series = np.genfromtxt(folder / "series.csv", delimiter=",", names=True)
    series = comm.bcast(series, root=0)
    _runs[key] = (summary, series, error)
    return _runs[key]


def impact_overrides(scheme, n=n_base, dt=dt_base, quadrature="midpoint"):
    """Overrides of ``bar-impact``: scheme "A" or "B", n cells, time step, force quadrature."""
    return {"method": f"dem-{scheme}", "mesh.n": n, "time.dt": dt, "time.end": T_impact,
            "time.quadrature": quadrature}


def l2_in_time(t, e):
    """sqrt(int e^2 dt) by the trapezoid rule on the samples."""
    return float(np.sqrt(np.trapz(e**2, t)))


def fitted_order(h, errors):
    """Slope of the least-squares line through (log h, log error)."""
    return float(np.polyfit(np.log(h), np.log(errors), 1)[0])


def energy_variation(series, signed=False):
    """|E^n - E^0| / max_n (kinetic + elastic + stabilisation)^n: the pseudo-energy variation."""
    mechanical = series["kinetic"] + series["elastic"] + series["stabilisation"]
    variation = (series["pseudo_energy"] - series["pseudo_energy"][0]) / mechanical.max()
    return variation if signed else np.abs(variation)


def energy_steps(series):
    """Root mean square and largest change of the relative pseudo-energy over one step."""
    change = np.diff(energy_variation(series, signed=True))
    return {"pseudo_energy_step_rms": float(np.sqrt(np.mean(change**2))),
            "pseudo_energy_step_max": float(np.abs(change).max())}
# -

# ## Benchmark 1: impact
#
# The contact interval of a run is read off its gap: it starts at the first sample with gap
# $\le 10^{-12}$ m and ends at the first sample after that with a positive gap. We also measure
# the penetration (minus the smallest gap), the mean pressure over the exact contact interval
# $[1/2, 7/6]$ (trapezoid rule, the end points interpolated), and the largest pressure after the
# lift-off.


# +
def contact_metrics(series, dt):
    """Contact interval, penetration and pressures of a benchmark 1 series (time step ``dt``)."""
    t, gap, p = series["t"], series["contact_gap"], series["contact_pressure"]
    touching = gap <= GAP_TOL
    if not touching.any():
        raise RuntimeError("the bar never touches the obstacle")
    i0 = int(np.argmax(touching))
    i1 = i0 + int(np.argmax(~touching[i0:])) if not touching[i0:].all() else len(t)
    inside = (t > t_impact) & (t < t_release)
    tt = np.concatenate([[t_impact], t[inside], [t_release]])
    mean_pressure = np.trapz(np.interp(tt, t, p), tt) / (t_release - t_impact)
    release = float(t[i1]) if i1 < len(t) else math.inf
    return {
        "contact_start": float(t[i0]),
        "contact_end": release,
        "contact_start_error_steps": (float(t[i0]) - t_impact) / dt,
        "contact_end_error_rel_duration": (release - t_release) / (t_release - t_impact),
        "contact_samples_after_release": int(touching[i1:].sum()),
        "penetration": float(-gap.min()),
        "mean_pressure": float(mean_pressure),
        "mean_pressure_rel_error": float(mean_pressure / p_impact - 1.0),
        "max_abs_pressure_after_release": float(np.abs(p[i1:]).max()) if i1 < len(t) else 0.0,
        "max_pressure": float(p.max()),
    }


def run_summary(summary):
    """The numbers of a summary we report for every run."""
    return {k: summary[k] for k in ("n_cells", "n_steps", "dt", "quadrature", "pseudo_energy_rel_drift",
                                    "force_evaluations", "max_force_evaluations_per_step",
                                    "wall_time_s", "stable")}


impact = {}
for scheme in "AB":
    summary, series, _ = run("bar-impact", impact_overrides(scheme))
    t = series["t"]
    tip_error = series["tip_position"] - exact.impact_tip_position(t)
    impact[scheme] = {"summary": summary, "series": series,
                      "numbers": {**run_summary(summary), **energy_steps(series),
                                  **contact_metrics(series, dt_base),
                                  "tip_l2_error": l2_in_time(t, tip_error)}}
# -

# Figure 5 of the paper: the tip position and the contact pressure of both schemes against the
# exact solution.

# +
t_fine = np.linspace(0.0, T_impact, 4001)
if comm.rank == 0:
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 4.5))
    ax0.plot(t_fine, exact.impact_tip_position(t_fine), "k-", lw=2.5, alpha=0.35, label="exact")
    ax1.plot(t_fine, exact.impact_contact_pressure(t_fine), "k-", lw=2.5, alpha=0.35, label="exact")
    for scheme, style in (("A", "-"), ("B", "--")):
        s = impact[scheme]["series"]
        ax0.plot(s["t"], s["tip_position"], style, lw=1, label=f"scheme {scheme}")
        ax1.plot(s["t"], s["contact_pressure"], style, lw=1, label=f"scheme {scheme}")
    ax0.set(xlabel="t (s)", ylabel="tip position (m)", title="Benchmark 1: tip position")
    ax1.set(xlabel="t (s)", ylabel="contact pressure (Pa)", title="Benchmark 1: contact pressure")
    for ax in (ax0, ax1):
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(f"N = {n_base}, $\\Delta t$ = {dt_base} s (CFL 0.75), MEMM with event splitting")
    fig.tight_layout()
    out_folder.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_folder / "signorini_impact.png", dpi=120)
    figure_impact = fig
# -

# ## Conservation: event splitting against Gauss-Legendre quadratures
#
# Figure 6 of the paper: the pseudo-energy variation $|\mathcal{E}^n - \mathcal{E}^0|$ relative
# to the largest mechanical energy of the run, for scheme A with the split midpoint rule and
# with Gauss-Legendre rules of 1 to 5 points. We also count the force evaluations: one per
# quadrature point and step, plus, with splitting, one more (of the contact patch only) for every
# extra piece of a step that contains an event.

# +
quadrature_runs = {"midpoint-split": impact["A"]}
for q in quadratures:
    summary, series, _ = run("bar-impact", impact_overrides("A", quadrature=q))
    quadrature_runs[q] = {"summary": summary, "series": series}

energy = {}
for q, r in quadrature_runs.items():
    s, summary = r["series"], r["summary"]
    variation = energy_variation(s)
    points = 1 if q == "midpoint-split" else int(q.rsplit("-", 1)[1])
    energy[q] = {
        "max_rel_variation": float(variation.max()),
        "max_rel_variation_before_release": float(variation[s["t"] < t_release - dt_base].max()),
        "force_evaluations": summary["force_evaluations"],
        "n_steps": summary["n_steps"],
        "evaluations_per_step": summary["force_evaluations"] / summary["n_steps"],
        "extra_evaluations": summary["force_evaluations"] - 1 - points * summary["n_steps"],
        "max_force_evaluations_per_step": summary["max_force_evaluations_per_step"],
        "wall_time_s": summary["wall_time_s"],
    }

if comm.rank == 0:
    fig, ax = plt.subplots(figsize=(8, 4.5))
    floor = 1e-17  # exact zeros drawn at the floor of the log scale
    for q, r in quadrature_runs.items():
        label = "midpoint, event splitting" if q == "midpoint-split" else q.replace("gauss-legendre-", "GL ")
        ax.semilogy(r["series"]["t"], np.maximum(energy_variation(r["series"]), floor), lw=1, label=label)
    for x in (t_impact, t_release):
        ax.axvline(x, color="k", lw=0.6, ls=":")
    ax.set(xlabel="t (s)", ylabel="|pseudo-energy variation| / max mechanical energy",
           title="Benchmark 1, scheme A: pseudo-energy conservation", ylim=(floor / 2, None))
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(out_folder / "signorini_energy.png", dpi=120)
    figure_energy = fig
# -

# ## Convergence on benchmark 1
#
# Figure 7 of the paper: errors against the exact solution at fixed CFL number 0.75,
# $\Delta t = 0.25 / N$ s, which divides $T$ and puts the impact at $t = 0.5$ s on a step. The
# error of the tip position is measured in $L^2(0, T)$, that of the pressure in $L^1(0, T)$ and
# $L^2(0, T)$ (it jumps at the impact and the lift-off), all by the trapezoid rule on the steps.
# The fitted order is the slope of the least-squares line in log-log coordinates.

# +
dx_convergence = np.array([L / n for n in n_convergence])
convergence = {"n": n_convergence, "dx": dx_convergence.tolist(),
               "dt": [0.25 / n for n in n_convergence]}  # 0.75 dx / c
for scheme in "AB":
    tip_l2, p_l1, p_l2, drifts, walls = [], [], [], [], []
    for n, dt in zip(n_convergence, convergence["dt"]):
        summary, s, _ = run("bar-impact", impact_overrides(scheme, n, dt))
        t = s["t"]
        tip_l2.append(l2_in_time(t, s["tip_position"] - exact.impact_tip_position(t)))
        e_p = s["contact_pressure"] - exact.impact_contact_pressure(t)
        p_l1.append(float(np.trapz(np.abs(e_p), t)))
        p_l2.append(l2_in_time(t, e_p))
        drifts.append(summary["pseudo_energy_rel_drift"])
        walls.append(summary["wall_time_s"])
    convergence[scheme] = {
        "tip_l2": tip_l2, "pressure_l1": p_l1, "pressure_l2": p_l2,
        "order_tip_l2": fitted_order(dx_convergence, tip_l2),
        "order_pressure_l1": fitted_order(dx_convergence, p_l1),
        "order_pressure_l2": fitted_order(dx_convergence, p_l2),
        "pseudo_energy_rel_drift": drifts, "wall_time_s": walls,
    }

if comm.rank == 0:
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.5))
    for ax, key, title in zip(axes, ("tip_l2", "pressure_l1", "pressure_l2"),
                              ("tip position, $L^2(0,T)$", "contact pressure, $L^1(0,T)$",
                               "contact pressure, $L^2(0,T)$")):
        for scheme, marker in (("A", "o-"), ("B", "s--")):
            order = convergence[scheme][f"order_{key}"]
            ax.loglog(dx_convergence, convergence[scheme][key], marker, label=f"scheme {scheme} (order {order:.2f})")
        ax.set(xlabel="$\\Delta x$ (m)", ylabel="error", title=f"Benchmark 1: {title}")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3, which="both")
    fig.suptitle(f"CFL 0.75, N = {', '.join(map(str, n_convergence))}, T = {T_impact} s")
    fig.tight_layout()
    fig.savefig(out_folder / "signorini_convergence.png", dpi=120)
    figure_convergence = fig
# -

# ## Benchmark 2: bounces
#
# A bounce peak is the highest tip position during a flight: a maximal run of samples with a
# positive gap, after the first contact, lasting more than 1/3 s (the exact flights last 2 s;
# the bound skips the short separations of a coarse run chattering at the end of a contact).
# The exact peaks are found the same way on a fine sampling of the exact solution.


# +
def flight_peaks(t, touching, x, count=2, min_flight=1.0 / 3.0):
    """Highest ``x`` and its time in each of the first ``count`` complete flights."""
    edges = np.flatnonzero(np.diff(touching.astype(int))) + 1
    bounds = np.concatenate([[0], edges, [len(t)]])
    peaks, times = [], []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if a == 0 or b == len(t) or touching[a] or t[b - 1] - t[a] <= min_flight:
            continue  # the initial fall, the unfinished last flight, a contact, a chatter
        k = a + int(np.argmax(x[a:b]))
        peaks.append(float(x[k]))
        times.append(float(t[k]))
        if len(peaks) == count:
            break
    return peaks, times


t_exact = np.linspace(0.0, T_bounce, int(round(T_bounce * 3600)) + 1)  # holds every k/3 s
x_exact = exact.bounce_tip_position(t_exact)
exact_peaks, exact_peak_times = flight_peaks(t_exact, x_exact <= 0.0, x_exact)


def bounce_numbers(summary, s):
    t = s["t"]
    peaks, times = flight_peaks(t, s["contact_gap"] <= GAP_TOL, s["tip_position"])
    return {**run_summary(summary), **energy_steps(s),
            "tip_l2_error": l2_in_time(t, s["tip_position"] - exact.bounce_tip_position(t)),
            "penetration": float(-s["contact_gap"].min()),
            "peaks": peaks, "peak_times": times,
            "peak_rel_errors": [p / q - 1.0 for p, q in zip(peaks, exact_peaks)]}


bounce = {}
for scheme in "AB":
    summary, s, _ = run("bar-bounce", {"method": f"dem-{scheme}", "mesh.n": n_bounce,
                                       "time.dt": dt_bounce, "time.end": T_bounce})
    bounce[scheme] = {"series": s, "numbers": bounce_numbers(summary, s)}
# -

# Figure 8 of the paper: the tip position with the paper's coarse discretisation.

# +
if comm.rank == 0:
    fig, axes = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True)
    for ax, scheme in zip(axes, "AB"):
        s = bounce[scheme]["series"]
        ax.plot(t_exact, x_exact, "k-", lw=2.5, alpha=0.35, label="exact")
        ax.plot(s["t"], s["tip_position"], "-", lw=1, color="C0" if scheme == "A" else "C1",
                label=f"scheme {scheme}")
        ax.set(ylabel="tip position (m)", title=f"Benchmark 2, scheme {scheme}: N = {n_bounce}, "
               f"$\\Delta t$ = {dt_bounce} s")
        ax.legend(fontsize=8, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(out_folder / "signorini_bounce.png", dpi=120)
    figure_bounce = fig
# -

# Figure 9 of the paper: refining the mesh at a (nearly) fixed small time step. The paper's
# reading is that the loss of bounce height is a space-discretisation effect (energy stored in
# unresolved vibrations of the bar), so it should go away under refinement.

# +
refined = {"n": [n for n, _ in refinement], "dt": [dt for _, dt in refinement]}
for scheme in "AB":
    rows = []
    for n, dt in refinement:
        summary, s, _ = run("bar-bounce", {"method": f"dem-{scheme}", "mesh.n": n, "time.dt": dt,
                                           "time.end": T_bounce})
        rows.append((bounce_numbers(summary, s), s))
    refined[scheme] = {
        "runs": [r for r, _ in rows],
        "tip_l2": [r["tip_l2_error"] for r, _ in rows],
        "order_tip_l2": fitted_order(np.array([L / n for n in refined["n"]]), [r["tip_l2_error"] for r, _ in rows]),
        "series": [s for _, s in rows],
    }

if comm.rank == 0:
    fig = plt.figure(figsize=(14, 7.5))
    grid = fig.add_gridspec(2, 3)
    for i, scheme in enumerate("AB"):
        ax = fig.add_subplot(grid[i, :2])
        ax.plot(t_exact, x_exact, "k-", lw=2.5, alpha=0.35, label="exact")
        for n, dt, s in zip(refined["n"], refined["dt"], refined[scheme]["series"]):
            ax.plot(s["t"][::4], s["tip_position"][::4], lw=0.9, label=f"N = {n}, $\\Delta t$ = {dt:g}")
        ax.set(ylabel="tip position (m)", title=f"Benchmark 2, scheme {scheme}")
        ax.grid(alpha=0.3)
        if i == 1:
            ax.set_xlabel("t (s)")
            ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=3)
    ax = fig.add_subplot(grid[:, 2])
    for scheme, marker in (("A", "o-"), ("B", "s--")):
        ax.loglog([L / n for n in refined["n"]], refined[scheme]["tip_l2"], marker,
                  label=f"scheme {scheme} (order {refined[scheme]['order_tip_l2']:.2f})")
    ax.set(xlabel="$\\Delta x$ (m)", ylabel=f"tip position error in $L^2(0, {T_bounce:g})$",
           title="Benchmark 2: convergence")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(out_folder / "signorini_bounce_refinement.png", dpi=120)
    figure_bounce_refinement = fig
# -

# ## Stability of the explicit scheme
#
# MEMM is explicit: like the leapfrog scheme, it is stable for
# $\Delta t \le 2 / \sqrt{\lambda_\max(M^{-1} K)}$, which `DEMDiscretisation.stable_time_step("eigenvalue")`
# computes with SLEPc (by default `stable_time_step()` bounds $\lambda_\max$ from above, which
# is cheap and safe but not the limit itself). Contact does not lower the limit here (the contact reconstruction only
# changes the boundary facet). We run benchmark 1 with scheme A at CFL numbers from 0.1 to 1.2,
# the time step rounded down so that it divides $T$. Beyond the limit the monitor stops the run
# once the unstable mode, excited by the impact, has grown (the pseudo-kinetic energy
# $\frac12 (v^{n-1/2})^T M v^{n+1/2}$ turns negative beyond the energy budget), before anything
# overflows: we check that the series it leaves holds no NaN.

# +
dx_base = L / n_base
dem_base = simulation.build(scenes.load("bar-impact", overrides={"method": "dem-A"}), comm).dem
cfl_limit = c * dem_base.stable_time_step("eigenvalue") / dx_base
stability = []
for cfl in cfl_sweep:
    n_steps = math.ceil(T_impact * c / (cfl * dx_base) - 1e-9)
    dt = T_impact / n_steps
    summary, s, error = run("bar-impact", impact_overrides("A", dt=dt), allow_unstable=True)
    stability.append({
        "cfl_requested": cfl, "cfl": c * dt / dx_base, "dt": dt, "n_steps": n_steps,
        "stable": error is None and summary["stable"],
        "summary_stable_flag": summary["stable"],
        "pseudo_energy_rel_drift": summary["pseudo_energy_rel_drift"] if error is None else None,
        "failure_step": None if error is None else error.step,
        "failure_t": None if error is None else error.t,
        "suggested_dt": None if error is None else error.suggested_dt,
        "series_rows": int(len(s)),
        "series_finite": bool(all(np.isfinite(s[k]).all() for k in s.dtype.names)),
        "wall_time_s": summary["wall_time_s"],
    })

if comm.rank == 0:
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 4.5))
    ok = [r for r in stability if r["stable"]]
    bad = [r for r in stability if not r["stable"]]
    ax0.semilogy([r["cfl"] for r in ok], [max(r["pseudo_energy_rel_drift"], 1e-17) for r in ok], "o",
                 label="stable: pseudo-energy relative drift")
    ax0.semilogy([r["cfl"] for r in bad], [1e-10] * len(bad), "rx", ms=10, mew=2,
                 label="stopped by the stability monitor")
    ax1.plot([r["cfl"] for r in bad], [r["failure_t"] for r in bad], "rx-", ms=10, mew=2,
             label="time the monitor stopped the run")
    ax1.axhline(t_impact, color="k", lw=0.8, ls=":", label="impact, t = 0.5 s")
    for ax in (ax0, ax1):
        ax.axvline(cfl_limit, color="k", ls="--", lw=0.8,
                   label=f"limit $2/\\sqrt{{\\lambda_{{max}}}}$: CFL {cfl_limit:.4f}")
        ax.set_xlabel("CFL number $c \\Delta t / \\Delta x$")
        ax.legend(fontsize=8, loc="upper left")
        ax.grid(alpha=0.3, which="both")
    ax0.set(ylabel="|pseudo-energy variation| / max mechanical", ylim=(1e-17, 1e-8),
            title=f"Benchmark 1, scheme A, N = {n_base}: energy drift")
    ax1.set(ylabel="t (s)", title="Unstable runs: where the monitor stopped them",
            xlim=ax0.get_xlim(), ylim=(0.45, max([r["failure_t"] for r in bad] + [0.6]) + 0.05))
    fig.tight_layout()
    fig.savefig(out_folder / "signorini_stability.png", dpi=120)
    figure_stability = fig
# -

# ## The numbers
#
# The acceptance criteria below are those of the validation note
# (`docs/validation/signorini.md`); each is recorded with its measured value, pass or fail.

# +
paper_drifts = {f"impact-{k}": impact[k]["numbers"]["pseudo_energy_rel_drift"] for k in "AB"}
paper_drifts |= {f"bounce-{k}": bounce[k]["numbers"]["pseudo_energy_rel_drift"] for k in "AB"}
refined_drifts = {f"bounce-{k}-n{n}": r["pseudo_energy_rel_drift"] for k in "AB"
                  for n, r in zip(refined["n"], refined[k]["runs"])}
refined_drifts |= {f"impact-{k}-n{n}": drift for k in "AB"
                   for n, drift in zip(n_convergence, convergence[k]["pseudo_energy_rel_drift"])}
gl_drifts = {q: energy[q]["max_rel_variation"] for q in quadratures}
gl_before = {q: energy[q]["max_rel_variation_before_release"] for q in quadratures}
split_evaluations = [r["max_force_evaluations_per_step"] for r in
                     [impact[k]["numbers"] for k in "AB"] + [bounce[k]["numbers"] for k in "AB"]
                     + refined["A"]["runs"] + refined["B"]["runs"]]
finest = {k: refined[k]["runs"][-1] for k in "AB"}


def criterion(value, passed, rule):
    return {"value": value, "pass": bool(passed), "criterion": rule}


acceptance = {
    "split_drift": criterion(paper_drifts, max(paper_drifts.values()) <= 1e-12,
                             "pseudo-energy relative variation with event splitting <= 1e-12, both "
                             f"benchmarks, both schemes, N = {n_base} / {n_bounce}"),
    "split_drift_refinement": criterion(refined_drifts, max(refined_drifts.values()) <= 1e-12,
                                        "the same for every run of the two refinement studies"),
    "gl_worse_at_liftoff": criterion(
        {"min_gl_over_split": min(gl_drifts.values()) / max(energy["midpoint-split"]["max_rel_variation"], 1e-16),
         "max_gl_before_liftoff": max(gl_before.values())},
        min(gl_drifts.values()) > 100 * max(energy["midpoint-split"]["max_rel_variation"], 1e-16)
        and max(gl_before.values()) <= 1e-12,
        "every GL rule: variation > 100 x the split one, and <= 1e-12 before the lift-off"),
    "contact_start": criterion([impact[k]["numbers"]["contact_start"] for k in "AB"],
                               all(abs(impact[k]["numbers"]["contact_start_error_steps"]) <= 1 for k in "AB"),
                               "first contact within one step of 0.5 s (A, B)"),
    "contact_end": criterion([impact[k]["numbers"]["contact_end"] for k in "AB"],
                             all(abs(impact[k]["numbers"]["contact_end_error_rel_duration"]) <= 0.02 for k in "AB"),
                             "lift-off within 2 % of the contact duration 2/3 s of 7/6 s (A, B)"),
    "penetration": criterion(max(impact[k]["numbers"]["penetration"] for k in "AB"),
                             max(impact[k]["numbers"]["penetration"] for k in "AB") <= 1e-12,
                             "-min contact gap <= 1e-12 m (A, B)"),
    "mean_pressure": criterion([impact[k]["numbers"]["mean_pressure"] for k in "AB"],
                               all(abs(impact[k]["numbers"]["mean_pressure_rel_error"]) <= 0.02 for k in "AB"),
                               "mean contact pressure over [0.5, 7/6] within 2 % of 300 Pa (A, B)"),
    "zero_pressure_after_liftoff": criterion(
        [impact[k]["numbers"]["max_abs_pressure_after_release"] for k in "AB"],
        all(impact[k]["numbers"]["max_abs_pressure_after_release"] == 0.0 for k in "AB"),
        "contact pressure exactly 0 after the lift-off (A, B)"),
    "split_evaluations_per_step": criterion(max(split_evaluations), max(split_evaluations) <= 3,
                                            "force evaluations per step with splitting <= 3 (1 + at most 2)"),
    "impact_tip_order": criterion([convergence[k]["order_tip_l2"] for k in "AB"],
                                  all(convergence[k]["order_tip_l2"] >= 0.5 for k in "AB"),
                                  "fitted order of the tip L2(0,T) error >= 0.5 (A, B)"),
    "bounce_error_decreasing": criterion([refined[k]["tip_l2"] for k in "AB"],
                                         all(np.all(np.diff(refined[k]["tip_l2"]) < 0) for k in "AB"),
                                         "tip L2(0,T) error decreasing under refinement (A, B)"),
}
if len(exact_peaks) == 2:
    errors = [abs(e) for k in "AB" for e in finest[k]["peak_rel_errors"]]
    acceptance["bounce_peaks_finest"] = criterion(
        {k: finest[k]["peaks"] for k in "AB"}, len(errors) == 4 and max(errors) <= 0.02,
        f"N = {refined['n'][-1]}: the first two bounce peaks within 2 % of the exact ones (A, B)")

numbers = {
    "quick": QUICK,
    "processes": comm.size,
    "exact": {"contact_start": t_impact, "contact_end": t_release, "pressure": p_impact,
              "bounce_peaks": exact_peaks, "bounce_peak_times": exact_peak_times},
    "impact": {k: impact[k]["numbers"] for k in "AB"},
    "energy": energy,
    "convergence": convergence,
    "bounce": {k: bounce[k]["numbers"] for k in "AB"},
    "bounce_refinement": {"n": refined["n"], "dt": refined["dt"],
                          **{k: {"tip_l2": refined[k]["tip_l2"], "order_tip_l2": refined[k]["order_tip_l2"],
                                 "runs": refined[k]["runs"]} for k in "AB"}},
    "stability": {"cfl_limit": cfl_limit, "runs": stability},
    "acceptance": acceptance,
    "wall_time_s": time.perf_counter() - wall_start,
}

# module-level results, for the tests and for a notebook
impact_numbers = numbers["impact"]
pseudo_energy_split = energy["midpoint-split"]["max_rel_variation"]
pseudo_energy_gl = gl_drifts
order_tip = {k: convergence[k]["order_tip_l2"] for k in "AB"}
bounce_tip_l2 = {k: refined[k]["tip_l2"] for k in "AB"}
bounce_peaks = {k: finest[k]["peaks"] for k in "AB"}

if comm.rank == 0:
    print(f"Signorini bar ({'quick' if QUICK else 'full'}, {comm.size} process{'es' if comm.size > 1 else ''})")
    for k in "AB":
        n = impact[k]["numbers"]
        print(f"  impact {k}: contact [{n['contact_start']:.4f}, {n['contact_end']:.4f}] s, penetration "
              f"{n['penetration']:.1e} m, mean pressure {n['mean_pressure']:.2f} Pa, |p| after lift-off "
              f"{n['max_abs_pressure_after_release']:.3g} Pa, drift {n['pseudo_energy_rel_drift']:.1e}")
    for q, e in energy.items():
        print(f"  {q:18s} variation {e['max_rel_variation']:.2e} (before lift-off "
              f"{e['max_rel_variation_before_release']:.1e}), {e['evaluations_per_step']:.4f} evaluations/step, "
              f"max {e['max_force_evaluations_per_step']}")
    for k in "AB":
        print(f"  impact convergence {k}: tip L2 {np.round(convergence[k]['tip_l2'], 5).tolist()} order "
              f"{convergence[k]['order_tip_l2']:.2f}; pressure L1 order {convergence[k]['order_pressure_l1']:.2f}")
        b = bounce[k]["numbers"]
        print(f"  bounce {k}, N = {n_bounce}: tip L2 {b['tip_l2_error']:.4f}, peaks {np.round(b['peaks'], 4).tolist()}"
              f" (exact {np.round(exact_peaks, 4).tolist()}), drift {b['pseudo_energy_rel_drift']:.1e}")
        for n, r in zip(refined["n"], refined[k]["runs"]):
            print(f"  bounce {k}, N = {n:4d}, dt = {r['dt']:g}: tip L2 {r['tip_l2_error']:.4f}, peaks "
                  f"{np.round(r['peaks'], 4).tolist()}, drift {r['pseudo_energy_rel_drift']:.1e} (step rms "
                  f"{r['pseudo_energy_step_rms']:.1e}), {r['wall_time_s']:.0f} s")
        print(f"  bounce refinement {k}: order {refined[k]['order_tip_l2']:.2f}")
    for r in stability:
        state = (f"drift {r['pseudo_energy_rel_drift']:.1e}" if r["stable"] else
                 f"stopped at step {r['failure_step']}, t = {r['failure_t']:.4f} s")
        print(f"  CFL {r['cfl']:.4f}: {state}")
    for name, a in acceptance.items():
        print(f"  [{'pass' if a['pass'] else 'FAIL'}] {name}: {a['criterion']}")
    print(f"  wall time {numbers['wall_time_s']:.1f} s")

    with open(out_folder / "signorini.json", "w") as f:
        json.dump(numbers, f, indent=2)
    if not QUICK:
        validation = pathlib.Path(__file__).resolve().parent.parent / "docs" / "validation"
        validation.mkdir(parents=True, exist_ok=True)
        for name, fig in (("impact", figure_impact), ("energy", figure_energy),
                          ("convergence", figure_convergence), ("bounce", figure_bounce),
                          ("bounce_refinement", figure_bounce_refinement), ("stability", figure_stability)):
            fig.savefig(validation / f"signorini_{name}.png", dpi=120)
        with open(validation / "signorini.json", "w") as f:
            json.dump(numbers, f, indent=2)
    plt.close("all")
# -

# ## What we see
#
# Numbers of the full run, serial (`docs/validation/signorini.json`; the quick setting gives the
# same numbers on 1 and 2 processes, which the tests check).
#
# - Benchmark 1 (Figure 5). Both schemes touch down exactly at $t = 0.5$ s (a step), never
#   penetrate (the reconstructed gap is exactly 0 in contact), keep the contact for 0.675 s
#   instead of 2/3 s (lift-off at 1.175 s, 1.3 % of the duration late) and carry a mean pressure
#   of 296.6 Pa (-1.1 %). The pressure overshoots to 432 Pa at the impact (a Gibbs oscillation
#   that dies out in 0.1 s) and falls to 0 over the last 0.05 s before the lift-off. With the gap
#   open the pressure (the obstacle's force per contact area) is exactly 0 for both schemes. The
#   bar rebounds at 9.6 m/s instead of 10 m/s: part of the energy stays in vibrations of the bar.
# - Conservation (Figure 6). With event splitting the pseudo-energy varies by 1.6e-15 of the
#   mechanical energy over the run, at the cost of 2 extra evaluations (of the contact patch
#   only) in 800 steps. Every Gauss-Legendre rule is as good until the lift-off, then jumps to
#   2e-6 (1 and 2 points), 2.6e-6 (3 points) or 5.6e-7 (5 points) in the one step where the
#   lift-off falls, at about 0.8 of the step: the rules whose nodes all lie before it integrate
#   the same affine contact force exactly, and give the same wrong answer. More points cost
#   proportionally more and do not help. (The paper reports jumps to about 1e-9.)
# - Convergence (Figure 7). The tip error converges at order 0.68 for both schemes in
#   $L^2(0, T)$, as in the paper (0.7); the pressure at order 0.82 in $L^1(0, T)$ and 0.42 in
#   $L^2(0, T)$ (it is discontinuous), for both schemes, whose pressure errors agree to 0.5 %
#   (L1 5.2 Pa s, L2 24.7 Pa s$^{1/2}$ at $N = 100$).
# - Benchmark 2 (Figures 8 and 9). With $N = 100$ both schemes follow the first bounces and then
#   lose height and phase, as in the paper, while the pseudo-energy is conserved to 1e-14: the
#   energy goes into vibrations of the bar that a coarse mesh does not resolve. Refining the mesh
#   at a small time step removes the loss: the $L^2(0, 20)$ error falls from 5.1 (A) and 5.8 (B)
#   at $N = 100$ to 0.99 at $N = 1600$ (order 0.62 and 0.66), and the first two bounce peaks go
#   from 4.38 and 4.77 m to 4.436 and 4.962 m (exact 4.444 and 5: -0.2 % and -0.8 %).
# - Stability. The limit is CFL 1.0002 (from $\lambda_\max$); every run up to CFL 1 conserves
#   the pseudo-energy to 6e-14, every run beyond it (from CFL 1.008) is stopped by the monitor
#   24 to 75 ms after the impact, which is what excites the unstable mode (the free flight is a
#   rigid translation), with no NaN in its outputs.
# - Round-off. Every run with event splitting, up to 1600 cells and 128000 steps, conserves the
#   pseudo-energy to 1e-13 or better, and no step changes it by more than 6e-14. This needs the
#   force to be the exact gradient of the energy that is evaluated, also in floating point: with
#   the force computed as $-K w$ from the assembled $K = S^T S + J^T J$ and the energy as
#   $\frac12 |S w|^2 + \frac12 |J w|^2$, the two quadratic forms differ by rounding errors that
#   grow with the conditioning of $K$ and the variation reached 1e-11 on 1600 cells.
