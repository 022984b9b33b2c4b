"""DEM against P1 explicit (lumped mass) and P2 implicit Newmark FEM on a 2D elastic wave.

The scene: a plane-strain strip ``[0, L] x [0, H]`` (L = 1 m, H = 0.5 m), E = 1 Pa, nu = 0,
rho = 1 kg/m^3 (c = sqrt(E / rho) = 1 m/s), clamped (u = 0) at x = 0 and x = L, traction-free
at y = 0 and y = H, ``u(0) = (A sin(pi x / L), 0)`` (A = 0.01 m), ``v(0) = 0``. With nu = 0 the
Lamé lambda is 0, so the standing x-wave

    u_x = A sin(pi x / L) cos(pi c t / L),  u_y = 0

is exact (sigma = E eps: sigma_xy = sigma_yy = 0 on the top and bottom). Period 2 L / c = 2 s;
the runs stop at the first step at or after T = 1.25 s (5/8 of a period, where u is not at an
extremum in time, so phase errors show at first order) and are compared there.

Meshes: ``meshes.create_rectangle(..., [N, N/2], "crossed")`` (each rectangle cut into four
triangles: 2 N^2 cells, vertices of valence 4 and 8), the same meshes for every method.

Methods:

* ``dem``: DEM scheme A (``DEMDiscretisation``, DirichletBC on both x-ends) with MEMM (midpoint
  rule), dt = CFL * ``dem.stable_time_step()`` (from the guaranteed bound on lambda_max, what a
  scene with ``time.cfl`` uses); cell displacements, 2 unknowns per cell.
* ``p1-explicit``: ``FEMCentralDifference``, P1, lumped (row-sum) mass, central differences,
  dt = CFL * its own limit 2 / sqrt(lambda_max(m^-1 K)); 2 unknowns per vertex.
* ``p2-newmark``: ``FEMElastodynamics`` with degree 2, consistent mass, implicit Newmark
  (average acceleration, one LU factorisation at set-up); 2 unknowns per P2 node. It has no
  stability limit, so dt is chosen for accuracy: on each mesh dt = T / n for n = 20, 40, 80, ...
  until the error changes by less than 5 % (the spatial error is reached) or n reaches 5120
  (quick: 640); the reported run is the cheapest of the ladder whose error is within 10 % of the
  last one (``ladder_converged`` says whether the ladder settled).

Work-precision runs use CFL 0.9 for both explicit methods (each of its own limit).

Error (the same for every method): the L2(Omega) error at the final time with the barycentre
(one-point) quadrature, ``sqrt(sum_c |c| |u_h(x_c) - u(x_c, t)|^2)``, relative to
``||u(0)||_L2 = A sqrt(L H / 2)``. For the DEM u_h(x_c) is its cell value; for the FEM it is the
finite-element function evaluated at the barycentre.

Times are CPU times of this process (``time.process_time``; OpenMP/BLAS threads set to 1), so that
the other jobs on the shared 2-core machine affect them less than wall times; each run is repeated
(up to 3 times, while the repeats take under 3 s) and the best set-up and best stepping time are
kept. Set-up: DEM = ``DEMDiscretisation`` + ``stable_time_step`` (the bound) + ``MEMM`` and its
``initialise``; P1 = the
constructor (assembly, row sums, SLEPc lambda_max); P2 = the constructor (assembly, LU
factorisation, initial acceleration). Stepping: the step loop alone; a MEMM step always evaluates
the energies (its stability monitor), the FEM loops do not.

Stability sweep (one mesh, N = 16; 5 periods): the relative energy error max_t |E(t) - E(0)| /
E(0) (E = kinetic + elastic, + stabilisation for the DEM; kinetic energy from v^n, the DEM's from
(v^{n-1/2} + v^{n+1/2}) / 2) and the drift of each scheme's invariant (DEM pseudo-energy,
central-difference modified energy, Newmark energy) against dt / dt_stable, dt_stable being each
explicit scheme's true limit (the DEM's from SLEPc, ``stable_time_step("eigenvalue")``; its bound
is reported next to it). Explicit methods at
CFL 0.5 ... 1.2 (P1 run with ``allow_unstable=True`` at and above 1); a run fails when the MEMM
monitor raises ``memm.InstabilityError`` (DEM) or when E exceeds 10 E(0) (P1, the MEMM default
growth limit). Newmark at dt = 0.5 ... 16 times the P1 limit of the same mesh.

Writes ``wave2d.json``, ``wave2d_work_precision.png``, ``wave2d_stability.png``,
``wave2d_energy.png`` and ``wave2d.md`` into the output folder. Serial. Usage::

    python benchmarks/bench_wave2d.py                                  # full study -> docs/bench/
    python benchmarks/bench_wave2d.py --quick --out-dir /tmp/wave2d    # < 60 s
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pathlib  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402
from work_precision import time_to_error  # noqa: E402  (benchmarks/ is on sys.path when a script runs)

ROOT = pathlib.Path(__file__).resolve().parent.parent

L, H, E, NU, RHO, A = 1.0, 0.5, 1.0, 0.0, 1.0, 0.01
C = math.sqrt(E / RHO)
T_END = 1.25
NORM0 = A * math.sqrt(L * H / 2.0)  # ||u(0)||_L2
CFL_WP = 0.9
GROWTH_LIMIT = 10.0
METHODS = ("dem", "p1-explicit", "p2-newmark")
LABELS = {
    "dem": "DEM scheme A + MEMM (CFL 0.9)",
    "p1-explicit": "P1 FEM, lumped mass, central diff. (CFL 0.9)",
    "p2-newmark": "P2 FEM, Newmark (dt for accuracy)",
}
STYLES = {"dem": "D-", "p1-explicit": "o-", "p2-newmark": "^-"}


# --- the problem ---------------------------------------------------------------------------------


def exact(x: np.ndarray, t: float) -> np.ndarray:
    """Exact displacement (m) at points x of shape (n, 2): shape (n, 2)."""
    ux = A * np.sin(np.pi * x[:, 0] / L) * math.cos(math.pi * C * t / L)
    return np.stack([ux, np.zeros_like(ux)], axis=1)


def initial_displacement(x: np.ndarray) -> np.ndarray:
    """u(0) for DOLFINx interpolation: x of shape (2, n), returns (2, n)."""
    return np.stack([A * np.sin(np.pi * x[0] / L), np.zeros_like(x[0])])


def create_mesh(n: int):
    """The crossed strip mesh [n, n/2] (2 n^2 triangles) and its clamped facets (x = 0, x = L)."""
    from dolfinx_dem import meshes

    mesh, _, tags = meshes.create_rectangle(MPI.COMM_SELF, [0.0, 0.0], [L, H], [n, n // 2], "crossed")
    return mesh, tags.find(meshes.XMIN), tags.find(meshes.XMAX)


def barycentre_error(values: np.ndarray, centres: np.ndarray, volumes: np.ndarray, t: float) -> float:
    """sqrt(sum_c |c| |u_h(x_c) - u(x_c, t)|^2) / ||u(0)||; values, centres (n, 2), volumes (n,)."""
    diff = values - exact(centres, t)
    return float(np.sqrt(np.sum(volumes[:, None] * diff**2)) / NORM0)


def fem_barycentre_error(solver) -> float:
    from dolfinx_dem import _compat

    mesh = solver.mesh
    _, nodes = _compat.owned_cell_nodes(mesh)
    centres = nodes.mean(axis=1)
    e1, e2 = nodes[:, 1, :2] - nodes[:, 0, :2], nodes[:, 2, :2] - nodes[:, 0, :2]
    volumes = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    cells = np.arange(len(centres), dtype=np.int32)
    values = np.real(solver.u.eval(centres, cells)).reshape(-1, 2)
    return barycentre_error(values, centres[:, :2], volumes, solver.t)


# --- runs ----------------------------------------------------------------------------------------


class Timer:
    """Best-of CPU times of the set-up and the stepping over the repeats."""

    def __init__(self):
        self.setup, self.stepping = math.inf, math.inf

    def record(self, setup: float, stepping: float) -> None:
        self.setup, self.stepping = min(self.setup, setup), min(self.stepping, stepping)


def repeated(run, budget: float = 3.0, repeats: int = 3) -> dict:
    """Run ``run(timer)`` up to ``repeats`` times while the total CPU time stays under ``budget``."""
    timer, spent = Timer(), 0.0
    for _ in range(repeats):
        start = time.process_time()
        result = run(timer)
        spent += time.process_time() - start
        if spent > budget:
            break
    result.update(setup_s=timer.setup, stepping_s=timer.stepping, total_s=timer.setup + timer.stepping)
    return result


def build_dem(mesh, left, right):
    from dolfinx_dem.conditions import DirichletBC
    from dolfinx_dem.discretisation import DEMDiscretisation
    from dolfinx_dem.material import ElasticMaterial

    zero = [0.0, 0.0]
    return DEMDiscretisation(mesh, ElasticMaterial(E=E, nu=NU, rho=RHO), scheme="A",
                             dirichlet=[DirichletBC(left, zero), DirichletBC(right, zero)])


def start_dem(dem, cfl: float, growth_limit: float = GROWTH_LIMIT, method: str = "bound"):
    """MEMM at dt = cfl * dem.stable_time_step(method), started from u(0), v(0) = 0."""
    from dolfinx_dem import MEMM, DEMProblem

    dt_stable = dem.stable_time_step(method)
    memm = MEMM(DEMProblem(dem), cfl * dt_stable, growth_limit=growth_limit)
    u0 = dem.create_vector()
    u0.array[:] = exact(dem.geometry.cell_centres[: dem.n_owned], 0.0).ravel()
    return memm, dt_stable, memm.initialise(u0, dem.create_vector())


def dem_error(dem, memm) -> float:
    owned = slice(0, dem.n_owned)
    return barycentre_error(memm.u.array_r.reshape(-1, 2), dem.geometry.cell_centres[owned],
                            dem.geometry.cell_volumes[owned], memm.t)


def run_dem(n: int, cfl: float = CFL_WP) -> dict:
    def run(timer):
        mesh, left, right = create_mesh(n)
        t0 = time.process_time()
        dem = build_dem(mesh, left, right)
        memm, dt_stable, d0 = start_dem(dem, cfl)
        t1 = time.process_time()
        n_steps = math.ceil(T_END / memm.dt - 1e-9)
        drift = 0.0
        for _ in range(n_steps):
            diag = memm.step()
            drift = max(drift, abs(diag.pseudo_energy - d0.pseudo_energy))
        t2 = time.process_time()
        timer.record(t1 - t0, t2 - t1)
        return dict(n=n, cells=dem.geometry.num_cells_global, unknowns=2 * dem.geometry.num_cells_global, dt=memm.dt,
                    dt_stable=dt_stable, n_steps=n_steps, t_final=memm.t, error=dem_error(dem, memm),
                    energy_rel_error_final=abs(diag.mechanical - d0.mechanical) / d0.mechanical,
                    invariant_drift_max=drift / d0.mechanical)

    return repeated(run)


def run_p1(n: int, cfl: float = CFL_WP) -> dict:
    from dolfinx_dem.fem.elastodynamics import FEMCentralDifference

    def run(timer):
        mesh, left, right = create_mesh(n)
        t0 = time.process_time()
        solver = FEMCentralDifference(mesh, E, NU, RHO, np.concatenate([left, right]), cfl=cfl,
                                      initial_displacement=initial_displacement)
        t1 = time.process_time()
        e0, m0 = sum(solver.energies()), solver.modified_energy()
        n_steps = math.ceil(T_END / solver.dt - 1e-9)
        for _ in range(n_steps):
            solver.step()
        t2 = time.process_time()
        timer.record(t1 - t0, t2 - t1)
        return dict(n=n, cells=mesh.topology.index_map(2).size_local, unknowns=solver.V.dofmap.index_map.size_global * 2,
                    dt=solver.dt, dt_stable=solver.dt_stable, n_steps=n_steps, t_final=solver.t,
                    error=fem_barycentre_error(solver),
                    energy_rel_error_final=abs(sum(solver.energies()) - e0) / e0,
                    invariant_drift_final=abs(solver.modified_energy() - m0) / e0)

    return repeated(run)


def run_p2(n: int, n_steps: int) -> dict:
    from dolfinx_dem.fem.elastodynamics import FEMElastodynamics

    def run(timer):
        mesh, left, right = create_mesh(n)
        t0 = time.process_time()
        solver = FEMElastodynamics(mesh, 2, E, NU, RHO, T_END / n_steps, np.concatenate([left, right]),
                                   initial_displacement=initial_displacement)
        t1 = time.process_time()
        e0 = sum(solver.energies())
        for _ in range(n_steps):
            solver.step()
        t2 = time.process_time()
        timer.record(t1 - t0, t2 - t1)
        return dict(n=n, cells=mesh.topology.index_map(2).size_local, unknowns=solver.V.dofmap.index_map.size_global * 2,
                    dt=solver.dt, n_steps=n_steps, t_final=solver.t, error=fem_barycentre_error(solver),
                    energy_rel_error_final=abs(sum(solver.energies()) - e0) / e0)

    return repeated(run)


def run_p2_ladder(n: int, max_steps: int) -> tuple[dict, list[dict]]:
    """Newmark runs with n_steps = 20, 40, 80, ... (at most ``max_steps``) until the error settles;
    returns (chosen run, ladder)."""
    ladder, n_steps = [], 20
    while n_steps <= max_steps:
        ladder.append(run_p2(n, n_steps))
        if len(ladder) >= 2 and abs(ladder[-1]["error"] / ladder[-2]["error"] - 1.0) < 0.05:
            break
        n_steps *= 2
    best = ladder[-1]["error"]
    chosen = next(r for r in ladder if r["error"] <= 1.1 * best)
    return dict(chosen, ladder_converged=len(ladder) >= 2 and
                abs(ladder[-1]["error"] / ladder[-2]["error"] - 1.0) < 0.05), ladder


# --- stability sweep ------------------------------------------------------------------------------


def sweep_dem(n: int, cfl: float, t_end: float, history: bool = False) -> dict:
    from dolfinx_dem.errors import InstabilityError

    mesh, left, right = create_mesh(n)
    dem = build_dem(mesh, left, right)
    memm, dt_stable, d0 = start_dem(dem, cfl, method="eigenvalue")
    e_err = drift = 0.0
    failure, series = None, []
    for _ in range(math.ceil(t_end / memm.dt - 1e-9)):
        try:
            diag = memm.step()
        except InstabilityError as err:
            failure = dict(step=err.step, t=err.t, reason=str(err).split(": ", 1)[1].split(". Reduce")[0])
            break
        e_err = max(e_err, abs(diag.mechanical - d0.mechanical) / d0.mechanical)
        drift = max(drift, abs(diag.pseudo_energy - d0.pseudo_energy) / d0.mechanical)
        if history:
            series.append((diag.t, (diag.mechanical - d0.mechanical) / d0.mechanical))
    return dict(cfl=cfl, dt=memm.dt, dt_stable=dt_stable, dt_bound=dem.stable_time_step(), energy_rel_error_max=e_err,
                invariant_drift_max=drift, failed=failure is not None, failure=failure, series=series)


def sweep_fem(method: str, n: int, cfl: float, t_end: float, dt_p1: float | None = None,
              history: bool = False) -> dict:
    """P1 explicit at cfl * its limit, or Newmark P2 at dt = cfl * dt_p1 (the P1 limit)."""
    from dolfinx_dem.fem.elastodynamics import FEMCentralDifference, FEMElastodynamics

    mesh, left, right = create_mesh(n)
    clamped = np.concatenate([left, right])
    if method == "p1-explicit":
        solver = FEMCentralDifference(mesh, E, NU, RHO, clamped, cfl=cfl, allow_unstable=cfl >= 1.0,
                                      initial_displacement=initial_displacement)
        invariant = solver.modified_energy
        dt_stable = solver.dt_stable
    else:
        solver = FEMElastodynamics(mesh, 2, E, NU, RHO, cfl * dt_p1, clamped,
                                   initial_displacement=initial_displacement)
        invariant = lambda: sum(solver.energies())  # noqa: E731
        dt_stable = dt_p1
    e0, i0 = sum(solver.energies()), invariant()
    e_err = drift = 0.0
    failure, series = None, []
    for k in range(math.ceil(t_end / solver.dt - 1e-9)):
        solver.step()
        e = sum(solver.energies())
        if not math.isfinite(e) or e > GROWTH_LIMIT * e0:
            failure = dict(step=k + 1, t=solver.t, reason=f"energy {e:.3e} > {GROWTH_LIMIT:g} x E(0)")
            break
        e_err = max(e_err, abs(e - e0) / e0)
        drift = max(drift, abs(invariant() - i0) / e0)
        if history:
            series.append((solver.t, (e - e0) / e0))
    return dict(cfl=cfl, dt=solver.dt, dt_stable=dt_stable, energy_rel_error_max=e_err,
                invariant_drift_max=drift, failed=failure is not None, failure=failure, series=series)


# --- analysis -------------------------------------------------------------------------------------


def fitted_order(x, errors) -> float:
    """Slope of log(error) against log(x)."""
    return float(np.polyfit(np.log(x), np.log(errors), 1)[0])


def time_to_error_table(runs: dict) -> list[dict]:
    """CPU times (total and stepping only) to reach errors 1, 2, 5 x 10^k of every method, and the
    DEM / FEM ratios where both reach the error within their measured ranges."""
    lo = min(r["error"] for rows in runs.values() for r in rows)
    hi = max(r["error"] for rows in runs.values() for r in rows)
    targets = sorted((f * 10.0**k for k in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)))
                      for f in (1.0, 2.0, 5.0) if lo <= f * 10.0**k <= hi), reverse=True)
    table = []
    for target in targets:
        row = {"error": target}
        for key in ("total_s", "stepping_s"):
            times = {m: time_to_error([r["error"] for r in runs[m]], [r[key] for r in runs[m]], target)
                     for m in METHODS}
            row[key] = times
            row[key + "_ratio"] = {f"dem_over_{m}": times["dem"] / times[m] if times["dem"] and times[m] else None
                                   for m in METHODS[1:]}
        if any(v is not None for v in row["total_s_ratio"].values()):
            table.append(row)
    return table


# --- charts and report ----------------------------------------------------------------------------


def plot_work_precision(runs: dict, ladders: dict, path: pathlib.Path) -> None:
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.4))
    for m in METHODS:
        err = [r["error"] for r in runs[m]]
        ax1.loglog([r["total_s"] for r in runs[m]], err, STYLES[m], label=LABELS[m])
        ax2.loglog([r["unknowns"] for r in runs[m]], err, STYLES[m], label=LABELS[m])
    ladder = [r for rows in ladders.values() for r in rows]
    ax1.loglog([r["total_s"] for r in ladder], [r["error"] for r in ladder], "^", color="C2", alpha=0.3,
               mfc="none", label="P2 Newmark, all dt of the ladder")
    ax1.set_xlabel("CPU time, set-up + stepping (s)")
    ax2.set_xlabel("unknowns")
    for ax in (ax1, ax2):
        ax.set_ylabel("relative L2 error at t = 1.25 s (barycentres)")
        ax.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=7)
    fig.suptitle("2D standing wave, crossed meshes N = " + ", ".join(str(r["n"]) for r in runs["dem"]))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_stability(sweep: dict, path: pathlib.Path) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    keys = (("energy_rel_error_max", "max |E(t) - E(0)| / E(0)"),
            ("invariant_drift_max", "drift of the scheme's invariant / E(0)"))
    for ax, (key, label) in zip(axes, keys):
        for m, y_fail in zip(METHODS, (3e1, 3.0, 3e-1)):
            ok = [r for r in sweep["runs"][m] if not r["failed"]]
            bad = [r for r in sweep["runs"][m] if r["failed"]]
            ax.semilogy([r["cfl"] for r in ok], [max(r[key], 1e-17) for r in ok], STYLES[m],
                        label=LABELS[m].split(" (")[0])
            if bad:
                ax.semilogy([r["cfl"] for r in bad], [y_fail] * len(bad), "x", color=ax.lines[-1].get_color(),
                            ms=10, mew=2, label=f"{m}: failed (run stopped)")
        ax.axvline(1.0, color="k", lw=0.8, ls=":")
        ax.set_xscale("log")
        ticks = sorted({r["cfl"] for rows in sweep["runs"].values() for r in rows} & {0.5, 1.0, 1.2, 2.0, 4.0, 8.0, 16.0})
        ax.set_xticks(ticks)
        ax.set_xticklabels([f"{t:g}" for t in ticks])
        ax.minorticks_off()
        ax.set_xlabel("dt / dt_stable (own explicit limit; Newmark: the P1 limit)")
        ax.set_ylabel(label)
        ax.set_ylim(1e-17, 1e2)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(f"Stability sweep, N = {sweep['n']} ({sweep['cells']} cells), {sweep['t_end']:g} s; "
                 "x = run stopped (DEM: MEMM InstabilityError; P1: E > 10 E(0))", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_energy(histories: dict, path: pathlib.Path) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for m, series in histories.items():
        t, e = np.array(series).T
        ax.plot(t, e, label=LABELS[m].split(" (")[0] + f" ({histories_cfl_label(m)})")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("(E(t) - E(0)) / E(0)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def histories_cfl_label(m: str) -> str:
    return "dt = 0.9 x P1 limit" if m == "p2-newmark" else "CFL 0.9"


def failure_text(failure) -> str:
    if failure is None:
        return "-"
    return f"step {failure['step']}, t = {failure['t']:.3g} s: {failure['reason']}"


def fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


def write_markdown(res: dict, path: pathlib.Path) -> None:
    lines = [
        "# 2D elastic wave: DEM against P1 explicit and P2 Newmark FEM",
        "",
        f"Written by `{res['command']}` ({res['wall_time_s']:.0f} s wall, serial, on the shared "
        "2-core machine). The problem, the methods, the error and the timing are described in the "
        "docstring of `benchmarks/bench_wave2d.py`; in short: plane-strain strip [0, 1] x [0, 0.5], "
        "E = 1, nu = 0, rho = 1, clamped at both x-ends, exact standing x-wave "
        "u_x = A sin(pi x) cos(pi t), compared at the first step at or after t = 1.25 s; crossed "
        "meshes [N, N/2] (2 N^2 triangles), the same for every method. Error: relative L2(Omega) "
        "error with barycentre quadrature (DEM: cell values; FEM: the FE function at the "
        "barycentres). Times: CPU seconds of the process (`time.process_time`), best of up to 3 "
        "repeats.",
        "",
        "## Work-precision",
        "",
        "![work-precision](wave2d_work_precision.png)",
        "",
        "| method | N | cells | unknowns | dt (s) | steps | error | set-up (s) | stepping (s) | total (s) | energy error at end |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for m in METHODS:
        for r in res["runs"][m]:
            capped = "" if r.get("ladder_converged", True) else " (ladder capped)"
            lines.append(f"| {m} | {r['n']} | {r['cells']} | {r['unknowns']} | {r['dt']:.4g} | {r['n_steps']}{capped} | "
                         f"{r['error']:.3e} | {r['setup_s']:.3g} | {r['stepping_s']:.3g} | {r['total_s']:.3g} | "
                         f"{r['energy_rel_error_final']:.2e} |")
    lines += ["", "Fitted orders (slope of log error against log h = L/N; against log unknowns):", "",
              "| method | order in h | order in unknowns | stepping time per step and unknown (us), finest |",
              "|---|---|---|---|"]
    for m in METHODS:
        o = res["orders"][m]
        r = res["runs"][m][-1]
        lines.append(f"| {m} | {o['h']:.2f} | {o['unknowns']:.2f} | "
                     f"{1e6 * r['stepping_s'] / r['n_steps'] / r['unknowns']:.3g} |")
    lines += ["", "P2 Newmark dt ladders (n steps: error):", ""]
    for n, rows in res["p2_ladders"].items():
        lines.append(f"- N = {n}: " + ", ".join(f"{r['n_steps']}: {r['error']:.2e}" for r in rows))
    lines += ["", "Time to reach a given error (CPU s, log-log interpolation between meshes; '-': outside the "
              "measured range) and the DEM / FEM ratios (< 1: the DEM is faster), on the total time and on "
              "the stepping time alone:", "",
              "| error | DEM | P1 explicit | P2 Newmark | DEM / P1 | DEM / P2 | DEM / P1, stepping | DEM / P2, stepping |",
              "|---|---|---|---|---|---|---|---|"]
    for row in res["time_to_error"]:
        tot, rt, rs = row["total_s"], row["total_s_ratio"], row["stepping_s_ratio"]
        lines.append(f"| {row['error']:.0e} | {fmt(tot['dem'])} | {fmt(tot['p1-explicit'])} | "
                     f"{fmt(tot['p2-newmark'])} | {fmt(rt['dem_over_p1-explicit'], '.2f')} | "
                     f"{fmt(rt['dem_over_p2-newmark'], '.2f')} | {fmt(rs['dem_over_p1-explicit'], '.2f')} | "
                     f"{fmt(rs['dem_over_p2-newmark'], '.2f')} |")
    sw = res["stability"]
    lines += ["", "## Stability and energy", "", "![stability](wave2d_stability.png)", "",
              "![energy](wave2d_energy.png)", "",
              f"Sweep on N = {sw['n']} ({sw['cells']} cells) over {sw['t_end']:g} s. dt_stable (the true "
              f"limits): DEM {sw['dt_stable']['dem']:.4g} s (SLEPc), P1 {sw['dt_stable']['p1-explicit']:.4g} s. "
              f"The DEM's bound (`stable_time_step()`, used by the work-precision runs and by `time.cfl`): "
              f"{sw['dt_bound_dem']:.4g} s, {sw['dt_bound_dem'] / sw['dt_stable']['dem']:.3f} x the limit.", "",
              "| method | dt / dt_stable | dt (s) | max energy error | invariant drift | failed at (step, t) |",
              "|---|---|---|---|---|---|"]
    for m in METHODS:
        for r in sw["runs"][m]:
            lines.append(f"| {m} | {r['cfl']:g} | {r['dt']:.4g} | {r['energy_rel_error_max']:.2e} | "
                         f"{r['invariant_drift_max']:.1e} | {failure_text(r['failure'])} |")
    lines += ["", "## Observations", ""] + [f"- {s}" for s in res["observations"]] + [
        "",
        "Notes:",
        "",
        "- A DEM step is one pass over the rectangular energy operator Q = [S; J] (y += Q v, Q^T y in "
        "the same pass; the energies of the stability monitor are the squares of y, no further "
        "product) plus one vector update (memm.py, factored.py). Q has about 21 nonzeros per "
        "unknown against about 14 for P1's K, and the DEM has twice the unknowns of P1 on a mesh.",
        "- The DEM's set-up bounds lambda_max of M^-1 K in a few passes over Q (stability.py); P1's "
        "constructor still asks SLEPc for its lambda_max, which dominates its set-up on the finer "
        "meshes (N = 128: 6.2 s of 6.3 s before this run).",
        "- At CFL 0.9 the P1 lumped-mass (too soft) and central-difference (too fast) phase errors "
        "partly cancel; the P1 error at CFL 0.5 is about the same (N = 32: 2.0e-4 against 2.4e-4), "
        "and so is the DEM's (N = 32: 7.2e-4 at 0.5, 6.3e-4 at 0.9): both are dominated by space.",
        "- Newmark is second order in time while P2 is about third order in space at the barycentres, so "
        "its dt must shrink like h^1.5 to keep up: on N = 32 and 64 the ladder stopped at its cap "
        "(5120 steps) before reaching the spatial error, so those P2 points are time-step limited.",
        "",
    ]
    path.write_text("\n".join(lines))


def observations(res: dict) -> list[str]:
    runs, sw = res["runs"], res["stability"]
    obs = []
    o = res["orders"]
    obs.append(f"Orders in h: DEM {o['dem']['h']:.2f}, P1 explicit {o['p1-explicit']['h']:.2f}, "
               f"P2 Newmark {o['p2-newmark']['h']:.2f} (barycentre L2 error).")
    d, p = runs["dem"][-1], runs["p1-explicit"][-1]
    obs.append(f"On the finest common mesh (N = {d['n']}) the DEM has {d['unknowns'] / p['unknowns']:.2f} x the "
               f"unknowns of P1, a stable step {d['dt_stable'] / p['dt_stable']:.2f} x as large, and an error "
               f"{d['error'] / p['error']:.2f} x that of P1; its stepping costs "
               f"{d['stepping_s'] / p['stepping_s']:.2f} x and its set-up {d['setup_s'] / p['setup_s']:.2f} x.")
    for m in ("dem", "p1-explicit"):
        fails = [r["cfl"] for r in sw["runs"][m] if r["failed"]]
        stable = [r["cfl"] for r in sw["runs"][m] if not r["failed"]]
        values = ", ".join(format(r["cfl"], "g") for r in sw["runs"][m])
        obs.append(f"{m}: stable up to dt / dt_stable = {max(stable):g}, stopped from "
                   f"{min(fails) if fails else 'never'} (sweep values {values}; dt_stable = the true limit).")
    nm = sw["runs"]["p2-newmark"]
    obs.append(f"P2 Newmark never fails (dt up to {max(r['cfl'] for r in nm):g} x the P1 limit); its energy error "
               f"stays below {max(r['energy_rel_error_max'] for r in nm):.1e}.")
    return obs


# --- main -----------------------------------------------------------------------------------------


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="coarse meshes, short sweep (< 60 s)")
    parser.add_argument("--out-dir", type=pathlib.Path, default=ROOT / "docs" / "bench")
    args = parser.parse_args(argv)
    if MPI.COMM_WORLD.size != 1:
        raise SystemExit("bench_wave2d.py runs serially")
    out = args.out_dir
    out.mkdir(parents=True, exist_ok=True)
    wall = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - wall:7.1f} s] {msg}", flush=True)

    sizes = (8, 16, 32) if args.quick else (8, 16, 32, 64, 128)
    p2_sizes = sizes if args.quick else sizes[:-1]
    max_steps = 640 if args.quick else 5120
    sweep_n, sweep_t = (8, 4.0) if args.quick else (16, 10.0)
    cfls = (0.5, 0.9, 1.0, 1.05, 1.2) if args.quick else (0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99, 1.0, 1.01,
                                                           1.02, 1.05, 1.1, 1.2)
    newmark_factors = (0.5, 2.0, 8.0) if args.quick else (0.5, 0.9, 2.0, 4.0, 8.0, 16.0)

    # warm-up: JIT-compile the forms and import everything before timing
    run_dem(4), run_p1(4), run_p2(4, 2)
    runs = {m: [] for m in METHODS}
    ladders = {}
    for n in sizes:
        runs["dem"].append(run_dem(n))
        runs["p1-explicit"].append(run_p1(n))
        log(f"N = {n}: DEM error {runs['dem'][-1]['error']:.3e} ({runs['dem'][-1]['total_s']:.3g} s), "
            f"P1 {runs['p1-explicit'][-1]['error']:.3e} ({runs['p1-explicit'][-1]['total_s']:.3g} s)")
        if n in p2_sizes:
            chosen, ladders[n] = run_p2_ladder(n, max_steps)
            runs["p2-newmark"].append(chosen)
            log(f"N = {n}: P2 Newmark error {chosen['error']:.3e} with {chosen['n_steps']} steps "
                f"({chosen['total_s']:.3g} s)")

    orders = {m: {"h": fitted_order([L / r["n"] for r in runs[m]], [r["error"] for r in runs[m]]),
                  "unknowns": fitted_order([r["unknowns"] for r in runs[m]], [r["error"] for r in runs[m]])}
              for m in METHODS}
    tte = time_to_error_table(runs)

    log(f"stability sweep on N = {sweep_n}")
    sweep_runs = {"dem": [sweep_dem(sweep_n, c, sweep_t, history=c == 0.9) for c in cfls],
                  "p1-explicit": [sweep_fem("p1-explicit", sweep_n, c, sweep_t, history=c == 0.9) for c in cfls]}
    dt_p1 = sweep_runs["p1-explicit"][0]["dt_stable"]
    sweep_runs["p2-newmark"] = [sweep_fem("p2-newmark", sweep_n, f, sweep_t, dt_p1=dt_p1, history=f == 0.9)
                                for f in newmark_factors]
    histories = {m: next(r["series"] for r in sweep_runs[m] if r["series"]) for m in METHODS
                 if any(r["series"] for r in sweep_runs[m])}
    for rows in sweep_runs.values():
        for r in rows:
            r.pop("series")
    stability = {"n": sweep_n, "cells": 2 * sweep_n**2, "t_end": sweep_t, "runs": sweep_runs,
                 "dt_stable": {"dem": sweep_runs["dem"][0]["dt_stable"], "p1-explicit": dt_p1},
                 "dt_bound_dem": sweep_runs["dem"][0]["dt_bound"]}

    command = "python benchmarks/bench_wave2d.py" + (" --quick" if args.quick else "")
    res = {"quick": args.quick, "command": command, "machine": platform.machine(),
           "timing": "CPU time of the process (time.process_time), best of up to 3 repeats, threads = 1",
           "problem": {"L": L, "H": H, "E": E, "nu": NU, "rho": RHO, "A": A, "t_end": T_END,
                       "mesh": "create_rectangle [N, N/2] crossed", "error": "relative barycentre L2 at t_final"},
           "cfl_work_precision": CFL_WP, "runs": runs, "p2_ladders": {str(k): v for k, v in ladders.items()},
           "orders": orders, "time_to_error": tte, "stability": stability,
           "charts": ["wave2d_work_precision.png", "wave2d_stability.png", "wave2d_energy.png"]}
    res["observations"] = observations(res)
    plot_work_precision(runs, ladders, out / "wave2d_work_precision.png")
    plot_stability(stability, out / "wave2d_stability.png")
    plot_energy(histories, out / "wave2d_energy.png")
    res["wall_time_s"] = time.perf_counter() - wall
    (out / "wave2d.json").write_text(json.dumps(res, indent=1))
    write_markdown(res, out / "wave2d.md")
    for s in res["observations"]:
        log(s)
    log(f"wrote {out / 'wave2d.json'}, {out / 'wave2d.md'} and the charts")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
