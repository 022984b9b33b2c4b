"""The performance study of issues 6 and 12: cost growth, a step against a bare MatMult, MPI,
contact share, the stable time step, the drift of the energy rows.

Run from the repository root (``make bench``)::

    .venv/bin/python benchmarks/bench_study.py            # ~25 min; writes docs/bench/results.json + charts
    .venv/bin/python benchmarks/bench_study.py --quick    # ~1 min, small sizes (run by the tests)
    .venv/bin/python benchmarks/bench_study.py --out DIR

What is measured (each size in a fresh subprocess, so peak-RSS figures do not see earlier sizes):

* **cost growth** (serial; unit square, "right" diagonals, 2 n^2 triangles, scheme A, clamped on
  x = 0; 1e3 .. 1e6 cells): set-up (``DEMDiscretisation`` constructor, wall and CPU time), peak
  RSS rise during set-up, the stable time step (``stable_time_step()``: the bound, with the
  one-pass operator it builds) against the set-up, SLEPc's eigenvalue solve up to 1e4 cells, and
  per evaluation: a bare ``K.mult``, ``Q.mult`` + ``Q^T.mult``, the elastic ``force`` (true
  products) and a whole ``MEMM.step`` (the pass over Q, the update kernel, one reduction, the
  stability monitor). Timings are CPU time (``time.process_time``, the machine is shared and the
  code is serial), the minimum (and median) over interleaved rounds, so that the load of other
  jobs enters the ratios as little as possible;
* **MPI**: wall time per ``MEMM.step`` on 1 and 2 processes (``mpirun``), the best of several
  batches of steps, barrier-synchronised; set-up time and peak RSS per process;
* **contact share** on the contact-heavy ``billiard`` scene: ``dolfinx-dem run billiard`` and its
  summary.json keys ``contact_fraction`` and ``contact_seconds``;
* **DEM step on bar-impact** (scheme A, N = 800): a MEMM step in and out of the contact phase,
  its contact part, and the step of the same bar clamped without contact (MEMM alone);
* **bound tightness**: the bound's lambda against SLEPc's lambda_max on the built-in scenes;
* **residual refresh**: pseudo-energy drift and the distance of the recurrence's energy rows
  from a true product, with and without the refresh;
* **work-precision on bar-impact**: the (wall time, tip-position L2 error) pairs of every method,
  read from ``docs/bench/signorini.json`` (written by ``bench_signorini.py``, not re-run here).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: unit-square divisions n, 2 n^2 cells: about 1e3, 1e4, 1e5, 1e6 cells (2e5 for the MPI quick check)
SIZES = {"1e3": 22, "1e4": 71, "1e5": 224, "1e6": 707}
QUICK_SIZES = {"1e3": 22, "4e3": 45}
MPI_SIZE, QUICK_MPI_SIZE = 707, 45
BILLIARD_QUICK_END = 3.5  # s: the first contact is at 2.93 s
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_btl_vader_single_copy_mechanism": "none", "OMP_NUM_THREADS": "1"}


def _rss_now_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB on Linux


def _square(comm, n):
    """The benchmark problem: unit square, 2 n^2 cells, clamped on x = 0, scheme A, and a stable MEMM."""
    import dolfinx.mesh
    import numpy as np

    from dolfinx_dem import DEMDiscretisation, DirichletBC, ElasticMaterial, meshes

    material = ElasticMaterial(E=1.0, nu=0.3, rho=1.0)
    mesh = dolfinx.mesh.create_unit_square(comm, n, n, diagonal=dolfinx.mesh.DiagonalType.right)
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    comm.Barrier()
    rss = _rss_now_bytes()
    wall, cpu = time.perf_counter(), time.process_time()
    dem = DEMDiscretisation(mesh, material, scheme="A", dirichlet=[DirichletBC(left, [0.0, 0.0])])
    comm.Barrier()
    setup = {"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu,
             "peak_rss_rise_bytes": _peak_rss_bytes() - rss}
    return dem, material.wave_speed(2), setup


def _smooth_state(dem):
    """u = 1e-3 (sin(pi x) y, x y) at the barycentres of the owned cells, v = 0."""
    import numpy as np

    x = dem.geometry.cell_centres[: dem.n_owned]
    u = dem.create_vector()
    u.array[:] = 1e-3 * np.stack([np.sin(np.pi * x[:, 0]) * x[:, 1], x[:, 0] * x[:, 1]], axis=1).ravel()
    return u


def measure_size(n: int, rounds: int) -> dict:
    """Serial set-up, memory and per-evaluation costs for 2 n^2 cells (run in a fresh process)."""
    from mpi4py import MPI

    from dolfinx_dem import MEMM, DEMProblem

    dem, c, setup = _square(MPI.COMM_WORLD, n)
    u = _smooth_state(dem)
    wall = time.perf_counter()
    dt_bound = dem.stable_time_step()
    stable = {"bound_seconds": time.perf_counter() - wall, "dt_bound": dt_bound}
    stable["fraction_of_setup"] = stable["bound_seconds"] / setup["wall"]
    if n <= 100:  # SLEPc's time grows about quadratically: 220 s at 8e4 cells
        wall = time.perf_counter()
        stable["dt_eigenvalue"] = dem.stable_time_step("eigenvalue")
        stable["eigenvalue_seconds"] = time.perf_counter() - wall
        stable["lambda_bound_over_lambda_max"] = (stable["dt_eigenvalue"] / dt_bound) ** 2
    memm = MEMM(DEMProblem(dem), 0.3 / (n * c))  # the limit measured on n = 71 is 0.61 / (n c)
    memm.initialise(u, dem.create_vector())
    K, Q = dem.K, dem.assemble_Q()  # built after the memory measurement: time stepping needs neither
    out, a = dem.create_vector(), Q.createVecLeft()
    fns = {
        "matmult": lambda: K.mult(u, out),
        "q_qt": lambda: (Q.mult(u, a), Q.multTranspose(a, out)),
        "force": lambda: dem.force(u, 0.0, out),
        "step": memm.step,
    }
    times = {key: [] for key in fns}
    for fn in fns.values():
        fn()
    for _ in range(rounds):  # interleaved: every function sees the same machine load
        for key, fn in fns.items():
            t = time.process_time()
            fn()
            times[key].append(time.process_time() - t)
    best = {key: min(v) for key, v in times.items()}
    cells = dem.geometry.num_cells_global
    return {
        "n": n, "cells": cells, "dofs": 2 * cells, "rounds": rounds,
        "setup": setup,
        "stable_time_step": stable,
        "memory_bytes_per_cell": setup["peak_rss_rise_bytes"] / cells,
        "nnz_K": int(K.getInfo()["nz_used"]), "nnz_Q": int(Q.getInfo()["nz_used"]),
        "seconds": best,
        "seconds_median": {key: statistics.median(v) for key, v in times.items()},
        "force_vs_matmult_ratio": best["force"] / best["matmult"],
        "q_qt_vs_matmult_ratio": best["q_qt"] / best["matmult"],
        "step_vs_matmult_ratio": best["step"] / best["matmult"],
        "step_vs_matmult_ratio_median": statistics.median(times["step"]) / statistics.median(times["matmult"]),
    }


def measure_mpi(n: int, batches: int, steps: int) -> dict | None:
    """Wall time per MEMM step on the processes of COMM_WORLD (best batch, barrier-synchronised),
    with the elastic force by PETSc's two MatMults and a bare ``K.mult`` (the memory-bandwidth
    reference: its speed-up is what a bandwidth-bound step can reach) in the same batches."""
    from mpi4py import MPI

    from dolfinx_dem import MEMM, DEMProblem

    comm = MPI.COMM_WORLD
    dem, c, setup = _square(comm, n)
    memm = MEMM(DEMProblem(dem), 0.3 / (n * c))
    memm.initialise(_smooth_state(dem), dem.create_vector())
    out = dem.create_vector()
    per_step, per_force, cpu_step, per_matmult = [], [], [], []
    K = dem.K  # after the set-up's memory measurement
    load_before = os.getloadavg()[0]
    for _ in range(batches):
        comm.Barrier()
        t, cpu = time.perf_counter(), time.process_time()
        for _ in range(steps):
            memm.step()
        cpu_step.append((time.process_time() - cpu) / steps)
        comm.Barrier()
        per_step.append((time.perf_counter() - t) / steps)
        t = time.perf_counter()
        for _ in range(steps):
            dem.force(memm.u, 0.0, out)
        comm.Barrier()
        per_force.append((time.perf_counter() - t) / steps)
        t = time.perf_counter()
        for _ in range(steps):
            K.mult(memm.u, out)
        comm.Barrier()
        per_matmult.append((time.perf_counter() - t) / steps)
    peak = comm.allreduce(_peak_rss_bytes(), op=MPI.MAX)
    cpu_step = comm.allreduce(min(cpu_step), op=MPI.MAX)  # CPU seconds of the slowest rank
    if comm.rank != 0:
        return None
    return {"processes": comm.size, "n": n, "cells": dem.geometry.num_cells_global, "steps_per_batch": steps,
            "batches": batches, "step_seconds": min(per_step), "force_seconds": min(per_force),
            "matmult_seconds": min(per_matmult), "matmult_seconds_median": statistics.median(per_matmult),
            "force_seconds_median": statistics.median(per_force), "load_average_before": load_before,
            "step_seconds_median": statistics.median(per_step), "step_cpu_seconds_slowest_rank": cpu_step,
            "load_average_after": os.getloadavg()[0], "setup_wall_seconds": setup["wall"],
            "peak_rss_bytes_per_process": peak}


def bar_impact_step(n: int = 800, repeats: int = 300) -> dict:
    """CPU time (min and median of ``repeats``) of a MEMM step, DEM-A on bar-impact, in the contact
    phase (t > 0.6 s, as in bench_signorini's breakdown) and out of it (t < 0.5 s), with the
    contact part of each (``impulse``: the contact force integral, and the contact energy); and
    the step of the same bar clamped at both ends, without contact (MEMM alone)."""
    from mpi4py import MPI

    from dolfinx_dem import memm, scenes, simulation

    length, speed = 10.0, 30.0  # bar length (m) and wave speed sqrt(E / rho) (m/s) of the scene
    dt = 0.75 * (length / n) / speed  # CFL 0.75, as in bench_signorini
    scene = scenes.load("bar-impact", overrides={"method": "dem-A", "mesh.n": n, "time.dt": dt, "time.end": 2.0,
                                                  "output.every": 10**6})
    problem = simulation.build(scene, MPI.COMM_WORLD)
    dem, contact = problem.dem, problem.contacts[0]  # the rigid obstacle
    stepper = memm.MEMM(problem, dt)
    u0, v0 = dem.create_vector(), dem.create_vector()
    v0.array[:] = -10.0
    stepper.initialise(u0, v0)

    def timed(fn, count):
        times = []
        for _ in range(count):
            t = time.process_time()
            fn()
            times.append(time.process_time() - t)
        return min(times), statistics.median(times)

    def phase(name):
        step = timed(stepper.step, repeats)  # advances the state by `repeats` steps
        parts = {"impulse": timed(stepper.impulse, repeats),
                 "contact_energy": timed(lambda: contact.energy_correction(contact.patch_values(stepper.u)), repeats)}
        in_contact = bool((contact.gaps(contact.patch_values(stepper.u)) < 0).any())
        out = {f"{name}_in_contact": in_contact, f"{name}_step_seconds": step[0], f"{name}_step_seconds_median": step[1]}
        for key, (lo, med) in parts.items():
            out[f"{name}_{key}_seconds"], out[f"{name}_{key}_seconds_median"] = lo, med
        return out

    result = {"n": n, "method": "dem-A"}
    result.update(phase("free_flight"))  # from t = 0: out of contact until t = 0.5 s
    while stepper.t < 0.6:
        stepper.step()
    result.update(phase("contact"))
    # the same bar clamped at both ends, no contact: the MEMM step alone
    clamped = scenes.load("bar-wave", overrides={"mesh.n": n, "time.end": 1.0})
    problem = simulation.build(clamped, MPI.COMM_WORLD)
    dem = problem.dem
    stepper = memm.MEMM(problem, 0.5 * dem.stable_time_step())
    stepper.initialise(dem.create_vector(), v0.copy())
    result["clamped_no_contact_step_seconds"], result["clamped_no_contact_step_seconds_median"] = timed(stepper.step,
                                                                                                      repeats)
    # compatibility with the keys of the issue-6 study
    result["in_contact"], result["step_seconds"] = result["contact_in_contact"], result["contact_step_seconds"]
    result["step_seconds_median"] = result["contact_step_seconds_median"]
    return result


def bound_tightness(names) -> dict:
    """lambda of the bound (``stable_time_step()``) against SLEPc's lambda_max (to rtol 1e-8) on
    built-in scenes, with the time of each."""
    from mpi4py import MPI

    from dolfinx_dem import scenes, simulation

    out = {}
    for name in names:
        dem = simulation.build(scenes.load(name), MPI.COMM_WORLD).dem
        wall = time.perf_counter()
        bound = dem.stable_time_step()
        t_bound = time.perf_counter() - wall
        wall = time.perf_counter()
        exact = dem.stable_time_step("eigenvalue")
        t_exact = time.perf_counter() - wall
        out[name] = {"cells": dem.geometry.num_cells_global, "dimension": dem.d, "dt_bound": bound, "dt_eigenvalue": exact,
                     "dt_bound_over_dt_eigenvalue": bound / exact, "lambda_bound_over_lambda_max": (exact / bound) ** 2,
                     "bound_seconds": t_bound, "eigenvalue_seconds": t_exact}
    return out


def residual_refresh(steps: int) -> dict:
    """Pseudo-energy drift (max |E^n - E^0| / max mechanical energy) and the largest distance of
    the recurrence's energy rows from a true product, relative to the rows' largest entry, over
    ``steps`` steps, without refresh and with ``MEMM`` refreshing every 1000 and 100 steps."""
    import numpy as np
    from mpi4py import MPI

    from dolfinx_dem import MEMM, DEMProblem, scenes, simulation

    comm = MPI.COMM_WORLD
    cases = {}
    problem = simulation.build(scenes.load("cantilever"), comm)
    dem = problem.dem
    x = dem.geometry.cell_centres[: dem.n_owned]
    v0 = dem.create_vector()
    v0.array[:] = np.stack([0.1 * x[:, 1], x[:, 0] ** 2], axis=1).ravel()
    cases["cantilever"] = (problem, 0.5 * dem.stable_time_step(), dem.create_vector(), v0, steps)
    dem, c, _ = _square(comm, 71)
    cases["unit square, 1e4 cells"] = (DEMProblem(dem), 0.3 / (71 * c), _smooth_state(dem), dem.create_vector(), steps)
    dt = 0.75 * (10.0 / 800) / 30.0
    problem = simulation.build(scenes.load("bar-impact", overrides={"mesh.n": 800, "time.dt": dt, "time.end": 2.0}),
                               comm)
    v0 = problem.create_vector()
    v0.array[:] = -10.0
    cases["bar-impact (800 cells, contact, free body)"] = (problem, dt, problem.create_vector(), v0, round(2.0 / dt))
    out = {}
    for name, (problem, dt, u0, v0, n_steps) in cases.items():
        dem = problem.dem
        Q = dem.assemble_Q()
        a = Q.createVecLeft()
        rows = {}
        for refresh in (0, 1000, 100):
            memm = MEMM(problem, dt, refresh_every=refresh)
            first = memm.initialise(u0, v0)
            drift, mechanical, distance = 0.0, first.mechanical, 0.0
            for k in range(n_steps):
                diag = memm.step()
                drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy))
                mechanical = max(mechanical, diag.mechanical)
                if (k + 1) % max(1, n_steps // 20) == 0:
                    Q.mult(dem.bodies.relative_displacement(memm.u), a)
                    scale = comm.allreduce(np.abs(a.array).max(), op=MPI.MAX)
                    gap = comm.allreduce(np.abs(memm.energy_rows() - a.array).max(), op=MPI.MAX)
                    if scale > 1e-10:  # a body in free flight has no deformation to compare with
                        distance = max(distance, gap / scale)
            rows[str(refresh)] = {"pseudo_energy_drift": drift / mechanical, "energy_rows_distance": distance}
        out[name] = {"steps": n_steps, "refresh_every": rows}
    return out


# --- driver ---------------------------------------------------------------------------------------


def _environment() -> dict:
    """This environment without the variables of an MPI start-up of the caller (a test run under
    mpi4py's singleton, say), so that a nested ``mpirun`` starts cleanly; plus ``MPI_ENV``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "ORTE_"))}
    return dict(env, **MPI_ENV)


def _child(args: list[str], mpi: int = 0, timeout: float = 3600) -> dict:
    command = [sys.executable, str(pathlib.Path(__file__).resolve()), *args]
    if mpi:
        command = ["mpirun", "-n", str(mpi), "--oversubscribe", *command]
    proc = subprocess.run(command, capture_output=True, text=True, env=_environment(),
                          timeout=timeout, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark child {' '.join(command)} failed:\n{proc.stderr[-4000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run_billiard(end: float | None) -> dict:
    """``dolfinx-dem run billiard`` (to ``end`` seconds if given): its contact share and timings."""
    cli = shutil.which("dolfinx-dem", path=str(pathlib.Path(sys.executable).parent)) or "dolfinx-dem"
    with tempfile.TemporaryDirectory() as tmp:
        command = [cli, "run", "billiard", "--out", tmp]
        if end is not None:
            command += ["--set", f"time.end={end}"]
        proc = subprocess.run(command, capture_output=True, text=True, env=_environment(), check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} failed:\n{proc.stderr[-4000:]}")
        summary = json.loads((pathlib.Path(tmp) / "summary.json").read_text())
    keys = ("contact_fraction", "contact_seconds", "n_cells", "n_steps", "t_end", "wall_time_s", "setup_time_s",
            "pseudo_energy_rel_drift", "first_contact_time")
    return {key: summary[key] for key in keys}


def signorini_pairs(path: pathlib.Path) -> dict:
    """(wall time s, tip-position L2 error) per method and N on bar-impact, from bench_signorini."""
    data = json.loads(path.read_text())
    methods = data["convergence"]["methods"]
    return {
        "source": f"{path.relative_to(ROOT)} (bench_signorini.py, commit {data.get('commit')}, {data.get('date')})",
        "methods": {m: [{"n": r["n"], "wall_time_s": r["wall_time_s"], "tip_l2": r["tip_l2"]} for r in rows]
                    for m, rows in methods.items()},
    }


def _loglog_slope(x, y) -> float:
    import numpy as np

    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def charts(results: dict, out: pathlib.Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    growth = results["cost_growth"]
    cells = np.array([r["cells"] for r in growth])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
    for key, label, style in (("matmult", "bare K.mult", "k--o"), ("force", "elastic force (Q^T (Q w + q))", "C0-o"),
                              ("step", "MEMM step (one pass over Q, update, reduction)", "C1-s")):
        ax.loglog(cells, [r["seconds"][key] for r in growth], style, label=label)
    ax.loglog(cells, cells * growth[-1]["seconds"]["step"] / cells[-1], ":", color="grey", label="slope 1")
    ax.set(xlabel="cells (2D)", ylabel="CPU time per evaluation (s)", title="time per step")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    bx.loglog(cells, [r["setup"]["wall"] for r in growth], "C2-o", label="set-up (constructor, wall)")
    bx.loglog(cells, [r["setup"]["cpu"] for r in growth], "C2--^", label="set-up (CPU)")
    bx.loglog(cells, [r["stable_time_step"]["bound_seconds"] for r in growth], "C3-s",
              label="stable_time_step() (bound, wall)")
    slepc = [(r["cells"], r["stable_time_step"]["eigenvalue_seconds"]) for r in growth
             if "eigenvalue_seconds" in r["stable_time_step"]]
    if slepc:
        bx.loglog(*zip(*slepc), "C3:x", label="stable_time_step('eigenvalue') (SLEPc, wall)")
    bx.loglog(cells, cells * growth[-1]["setup"]["cpu"] / cells[-1], ":", color="grey", label="slope 1")
    bx.set(xlabel="cells (2D)", ylabel="seconds", title="set-up")
    bx.grid(True, which="both", alpha=0.3)
    bx.legend(fontsize=8)
    fig.tight_layout()
    names = ["cost_growth.png"]
    fig.savefig(out / names[0], dpi=110)
    plt.close(fig)

    mpi = results["mpi"]
    fig, ax = plt.subplots(figsize=(5, 4))
    procs = [r["processes"] for r in mpi["runs"]]
    ax.bar([str(p) for p in procs], [1e3 * r["step_seconds"] for r in mpi["runs"]], color="C0", label="MEMM step")
    ax.bar([str(p) for p in procs], [1e3 * r["force_seconds"] for r in mpi["runs"]], color="C1", width=0.5,
           label="elastic force")
    ax.set(xlabel="MPI processes", ylabel="wall time (ms)",
           title=f"{mpi['runs'][0]['cells']:,} cells: speed-up {mpi['speedup_2']:.2f}")
    ax.legend()
    fig.tight_layout()
    names.append("mpi.png")
    fig.savefig(out / names[-1], dpi=110)
    plt.close(fig)
    return names


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only, short billiard run")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "docs" / "bench")
    parser.add_argument("--child-size", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--child-mpi", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--child-bar", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--child-tightness", nargs="+", help=argparse.SUPPRESS)
    parser.add_argument("--child-refresh", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--rounds", type=int, default=30, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_size is not None:
        print(json.dumps(measure_size(args.child_size, args.rounds)))
        return {}
    if args.child_mpi is not None:
        result = measure_mpi(args.child_mpi, batches=5, steps=args.rounds)
        if result is not None:
            print(json.dumps(result))
        return {}
    if args.child_bar:
        print(json.dumps(bar_impact_step(repeats=args.rounds)))
        return {}
    if args.child_tightness:
        print(json.dumps(bound_tightness(args.child_tightness)))
        return {}
    if args.child_refresh:
        print(json.dumps(residual_refresh(args.child_refresh)))
        return {}

    started = time.perf_counter()

    def log(message):
        print(f"[{time.perf_counter() - started:7.1f} s] {message}", flush=True)

    sizes = QUICK_SIZES if args.quick else SIZES
    growth = []
    for _label, n in sizes.items():
        rounds = 10 if n > 500 else 30
        load = os.getloadavg()[0]
        growth.append(_child(["--child-size", str(n), "--rounds", str(rounds)]))
        r = growth[-1]
        r["load_average"] = [load, os.getloadavg()[0]]  # before and after: other jobs on the machine
        log(f"{r['cells']} cells: set-up {r['setup']['wall']:.2f} s, force/K.mult {r['force_vs_matmult_ratio']:.2f}, "
            f"step/K.mult {r['step_vs_matmult_ratio']:.2f}, step {1e3 * r['seconds']['step']:.2f} ms, "
            f"stable dt {r['stable_time_step']['bound_seconds']:.2f} s, {r['memory_bytes_per_cell']:.0f} B/cell")
    mpi_n = QUICK_MPI_SIZE if args.quick else MPI_SIZE
    steps = 5 if mpi_n > 500 else 20
    mpi_runs = [_child(["--child-mpi", str(mpi_n), "--rounds", str(steps)], mpi=p) for p in (1, 2)]
    log(f"MPI: {[round(1e3 * r['step_seconds'], 2) for r in mpi_runs]} ms per step on 1, 2 processes")
    billiard = run_billiard(BILLIARD_QUICK_END if args.quick else None)
    log(f"billiard: contact fraction {billiard['contact_fraction']:.3f}")
    bar = _child(["--child-bar", "--rounds", "50" if args.quick else "300"])
    log(f"bar-impact DEM-A N=800 step {1e6 * bar['contact_step_seconds']:.0f} us in contact, "
        f"{1e6 * bar['free_flight_step_seconds']:.0f} us out of it, {1e6 * bar['clamped_no_contact_step_seconds']:.0f} us "
        "clamped without contact")
    tightness = _child(["--child-tightness", *(("bar-wave", "cantilever") if args.quick else
                                               ("bar-wave", "cantilever", "two-disks", "billiard", "block"))])
    log("bound / lambda_max: " + ", ".join(f"{k} {v['lambda_bound_over_lambda_max']:.3f}" for k, v in tightness.items()))
    refresh = _child(["--child-refresh", "300" if args.quick else "5000"])
    log("drift without / with refresh: " + ", ".join(
        f"{k}: {v['refresh_every']['0']['pseudo_energy_drift']:.1e} / {v['refresh_every']['1000']['pseudo_energy_drift']:.1e}"
        for k, v in refresh.items()))

    largest = growth[-1]
    cells = [r["cells"] for r in growth]
    results = {
        "description": "issues 6 and 12 performance study (benchmarks/bench_study.py); serial times are CPU "
                       "seconds (process_time), minima over interleaved rounds; MPI times are wall "
                       "seconds, best batch",
        "date": datetime.datetime.now().strftime("%Y-%m-%d %H:%M"),
        "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                 cwd=ROOT, check=False).stdout.strip(),
        "quick": args.quick,
        "force_vs_matmult_ratio": largest["force_vs_matmult_ratio"],
        "force_vs_matmult_ratio_by_cells": {r["cells"]: r["force_vs_matmult_ratio"] for r in growth},
        "nnz_Q_over_nnz_K": largest["nnz_Q"] / largest["nnz_K"],
        "step_vs_matmult_ratio": largest["step_vs_matmult_ratio"],
        "step_vs_matmult_ratio_by_cells": {r["cells"]: r["step_vs_matmult_ratio"] for r in growth},
        "step_vs_matmult_ratio_median_by_cells": {r["cells"]: r["step_vs_matmult_ratio_median"] for r in growth},
        "stable_time_step_fraction_of_setup": largest["stable_time_step"]["fraction_of_setup"],
        "stable_time_step_seconds_by_cells": {r["cells"]: r["stable_time_step"]["bound_seconds"] for r in growth},
        "setup_seconds_per_million_cells": 1e6 * largest["setup"]["wall"] / largest["cells"],
        "setup_cpu_seconds_per_million_cells": 1e6 * largest["setup"]["cpu"] / largest["cells"],
        "setup_loglog_slope": _loglog_slope(cells, [r["setup"]["cpu"] for r in growth]),
        "step_loglog_slope": _loglog_slope(cells, [r["seconds"]["step"] for r in growth]),
        "memory_bytes_per_cell": largest["memory_bytes_per_cell"],
        "mpi_speedup_2": mpi_runs[0]["step_seconds"] / mpi_runs[1]["step_seconds"],
        "mpi": {"runs": mpi_runs, "speedup_2": mpi_runs[0]["step_seconds"] / mpi_runs[1]["step_seconds"],
                "force_speedup_2": mpi_runs[0]["force_seconds"] / mpi_runs[1]["force_seconds"],
                "matmult_speedup_2": mpi_runs[0]["matmult_seconds"] / mpi_runs[1]["matmult_seconds"],
                "speedup_2_median": mpi_runs[0]["step_seconds_median"] / mpi_runs[1]["step_seconds_median"]},
        "contact_fraction_billiard": billiard["contact_fraction"],
        "billiard": billiard,
        "bar_impact_dem_step": bar,
        "bound_tightness": tightness,
        "residual_refresh": refresh,
        "bar_impact_work_precision": signorini_pairs(ROOT / "docs" / "bench" / "signorini.json"),
        "cost_growth": growth,
        "environment": {"python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count(),
                        "load_average": os.getloadavg()},
    }
    args.out.mkdir(parents=True, exist_ok=True)
    results["charts"] = charts(results, args.out)
    (args.out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    log(f"written {args.out / 'results.json'} and {', '.join(results['charts'])}")
    return results


if __name__ == "__main__":
    main()
