"""Many impacts (issue 33): the Signorini bar of Doyen, Ern & Piperno (2011, benchmark 2, the scene
``bar-bounce``) bouncing for ``--periods`` periods, the DEM against the FEM peers of the bar.

The bar (L = 10 m, rho = 1, E = 900, c = 30 m/s) is released at rest 5 m above a rigid obstacle
under gravity g = 10; each impact lasts 2 L / c = 2/3 s and the bar flies for 2 s between them, so a
period is 8/3 s. The exact solution (``exact.bounce_tip_position``, characteristics) is not
periodic: each impact leaves the bar vibrating, and the flights' heights vary. After many impacts,
the tip error of a method grows with the phase error its dispersion and its contact treatment
accumulate, and its energy error with what its scheme dissipates or gains per impact.

Per method: the energy error max |E(t) - E0| / E_ref up to each period (E_ref = 1000 J/m^2, the
exact total energy, gravity potential zero at the obstacle; the DEM's E is its MEMM pseudo-energy,
the explicit FEM's the central differences' pseudo-energy, Newmark's the total energy with the
penalty's) and the tip error over each period, RMS(tip - exact) on [(k - 1) T_p, k T_p]. Methods:
FEM (a) central differences + projection, (b) modified mass, (c) Newmark + penalty
(``dolfinx_dem.fem.signorini``), DEM schemes A and B (MEMM with contact events, bare loop: no
output). All at N cells and CFL 0.75 (the benchmark's), one process.

    .venv/bin/python validation/long_bounce.py --n 100 200 400 --out docs/validation/long_bounce.json
    .venv/bin/python validation/long_bounce.py --quick --out OUT.json   # 3 periods, N = 50

It writes the JSON and, next to it, the Markdown page and the chart (``--out``'s stem + .md, .png);
``--render`` rewrites the page and the chart from the JSON.
"""

import argparse
import math
import pathlib
import sys
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import exact, memm, model, scenes
from dolfinx_dem.contact import RigidContact
from dolfinx_dem.fem import signorini

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import long_runs  # noqa: E402  (its command line: --render and --out)

L, C, CFL = 10.0, 30.0, 0.75
PERIOD = 8.0 / 3.0  # 1 s falling, 2/3 s in contact, 1 s rising: the exact first flight's period
E_REF = 1000.0  # J/m^2: 1/2 rho g L^2 + rho g h0 L
FEM = ("projection", "modified-mass", "newmark-penalty")
DEM = ("dem-A", "dem-B")
LABELS = {"projection": "FEM (a) central diff. + projection", "modified-mass": "FEM (b) modified mass",
          "newmark-penalty": "FEM (c) Newmark + penalty", "dem-A": "DEM scheme A", "dem-B": "DEM scheme B"}
REPORTED = (1, 5, 10, 25, 50)  # periods in the tables


def run_dem(method: str, n: int, t_end: float) -> dict:
    """The DEM's bare MEMM loop on ``bar-bounce``: times, tip positions, pseudo-energies, wall time."""
    start = time.perf_counter()
    dt = t_end / math.ceil(t_end / (CFL * (L / n) / C))  # CFL 0.75 at most, dividing t_end (as the FEM's)
    scene = scenes.load("bar-bounce", overrides={"method": method, "mesh.n": n, "time.dt": dt, "time.end": t_end})
    problem = model.build(scene, MPI.COMM_WORLD)
    dem, contact = problem.dem, problem.find(RigidContact)
    facet = contact.facets[0]
    x_tip = float(dem.geometry.facet_centres[facet, 0])
    stepper = memm.MEMM(problem, dt)
    n_steps = round(t_end / dt)
    tip, energy = np.empty(n_steps + 1), np.empty(n_steps + 1)
    diag = stepper.initialise(*model.initial_state(dem, scene))
    for k in range(n_steps + 1):
        if k:
            diag = stepper.step()
        tip[k] = x_tip + float(contact.facet_displacements(contact.patch_values(stepper.u))[0, 0])
        energy[k] = diag.pseudo_energy
    return {"t": dt * np.arange(n_steps + 1), "tip": tip, "energy": energy, "wall": time.perf_counter() - start}


def run_fem(method: str, n: int, t_end: float) -> dict:
    r = signorini.solve_signorini_bar(method, "bounce", n, CFL, t_end=t_end)
    return {"t": r.t, "tip": r.tip_position, "energy": r.energy, "wall": r.wall_time_s}


def metrics(run: dict, periods: int) -> dict:
    """Per period k = 1..periods: RMS tip error over it, largest energy error up to its end."""
    t, tip, energy = run["t"], run["tip"], run["energy"]
    error = tip - exact.bounce_tip_position(t)
    variation = np.abs(energy - energy[0]) / E_REF
    rms, energy_max = [], []
    for k in range(1, periods + 1):
        inside = (t >= (k - 1) * PERIOD) & (t <= k * PERIOD)
        rms.append(float(math.sqrt(np.trapz(error[inside] ** 2, t[inside]) / PERIOD)))
        energy_max.append(float(variation[t <= k * PERIOD].max()))
    return {"tip_rms": rms, "energy_error": energy_max, "wall_time_s": run["wall"], "steps": len(t) - 1,
            "dt": float(t[1] - t[0])}


def chart(results: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    levels = list(results["levels"])
    fig, axes = plt.subplots(len(levels), 2, figsize=(11, 3.6 * len(levels)), squeeze=False)
    k = np.arange(1, results["periods"] + 1)
    for (ax1, ax2), n in zip(axes, levels):
        for method, row in results["levels"][n].items():
            ax1.semilogy(k, np.maximum(row["energy_error"], 1e-17), "o-", ms=2, label=LABELS[method])
            ax2.semilogy(k, row["tip_rms"], "o-", ms=2, label=LABELS[method])
        ax1.set(xlabel="period", ylabel="max |E - E0| / E_ref so far", title=f"N = {n}: energy error")
        ax2.set(xlabel="period", ylabel="RMS tip error over the period (m)", title=f"N = {n}: trajectory error")
        ax1.grid(True, which="both", alpha=0.3)
        ax2.grid(True, which="both", alpha=0.3)
    axes[0, 1].legend(fontsize=8)
    fig.suptitle(f"bar-bounce, CFL {CFL}, {results['periods']} periods of 8/3 s")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def page(results: dict, png: str) -> str:
    periods = results["periods"]
    shown = [k for k in REPORTED if k < periods] + [periods]
    lines = [
        "# Many impacts: the Signorini bar bouncing, DEM against FEM",
        "",
        f"Written by `validation/long_bounce.py` (one process). Command: `{results['command']}`.",
        "",
        f"Benchmark 2 of Doyen, Ern & Piperno (`bar-bounce`), CFL {CFL}, {periods} periods of 8/3 s against the "
        "exact solution (characteristics). Energy error: max |E - E0| / 1000 J/m^2 up to the period's end; tip "
        "error: RMS of tip - exact over the period (m). Wall time: set-up and steps, no output (DEM: the bare MEMM "
        "loop with the tip read every step; the time step divides the run's end, CFL <= 0.75, as the FEM's).",
        "",
        f"![many impacts]({png})",
    ]
    for n, rows in results["levels"].items():
        lines += ["", f"## N = {n} cells", "",
                  "| method | " + " | ".join(f"tip error, period {k}" for k in shown) + " | first period with a "
                  "tip error over 1 m | " + " | ".join(f"energy error, period {k}" for k in shown) + " | wall (s) |",
                  "|---" * (2 * len(shown) + 3) + "|"]
        for method, row in rows.items():
            lost = next((k + 1 for k, e in enumerate(row["tip_rms"]) if e > 1.0), None)
            lines.append(f"| {LABELS[method]} | " + " | ".join(f"{row['tip_rms'][k - 1]:.3f}" for k in shown)
                         + f" | {lost or 'none'} | " + " | ".join(f"{row['energy_error'][k - 1]:.1e}" for k in shown)
                         + f" | {row['wall_time_s']:.2f} |")
    return "\n".join(lines) + "\n"


def measure(args: argparse.Namespace) -> dict:
    """The study of the command line ``args``."""
    if args.quick:
        args.n, args.periods = [50], 3
    t_end = args.periods * PERIOD
    results = {"periods": args.periods, "cfl": CFL, "levels": {},
               "command": "validation/long_bounce.py " + ("--quick" if args.quick else
                                                          f"--n {' '.join(map(str, args.n))} --periods {args.periods}")
               + f" --methods {' '.join(args.methods)}"}
    for n in args.n:
        results["levels"][n] = {}
        for method in args.methods:
            run = run_dem(method, n, t_end) if method in DEM else run_fem(method, n, t_end)
            row = results["levels"][n][method] = metrics(run, args.periods)
            print(f"N {n} {method:16s} tip rms first {row['tip_rms'][0]:.3f} last {row['tip_rms'][-1]:.3f}  energy "
                  f"{row['energy_error'][-1]:.1e}  wall {row['wall_time_s']:.2f} s", flush=True)
    return results


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, nargs="+", default=[100], help="cells (one level each)")
    parser.add_argument("--periods", type=int, default=50)
    parser.add_argument("--methods", nargs="+", default=list(FEM + DEM), choices=FEM + DEM)
    parser.add_argument("--quick", action="store_true", help="N = 50, 3 periods")
    long_runs.run_or_render(parser, measure, chart, page)


if __name__ == "__main__":
    main()
