"""The charts and the page docs/bench/signorini.md of bench_signorini.py, from its results."""

from __future__ import annotations

import pathlib

import numpy as np
from bench_signorini import CFL, DEM, E_REF, FEM, LABELS, ROOT, STYLES, T1, T2


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
