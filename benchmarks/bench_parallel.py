"""Parallel scaling of the set-up, the memory and the contact work (issue 11).

Each measurement is a child run under ``mpirun -n P`` that prints one JSON line:

* ``scaling``: a 2D unit square of crossed triangles (4 n^2 cells) or a 3D unit cube (6 n^3
  tetrahedra), clamped on x = 0, under gravity; set up (mesh, then ``DEMDiscretisation``), the
  stable time step from the bound, then ``--steps`` MEMM steps. Reported: the wall times of
  the mesh, of the set-up (slowest process), of the stable step and per step (median), the
  processor time of the set-up (the largest of the processes: a loaded machine disturbs it
  less; it includes Open MPI's busy waiting), and for every process its peak resident memory
  (``ru_maxrss``) and its resident memory before the mesh (Python, DOLFINx, PETSc: the baseline).
* ``pile``: 64 discs of radius 0.1 m in an 8 x 8 grid with 2 mm gaps, every boundary a contact
  boundary, moving towards the centre (v = -0.5 (x - x_c) 1/s). The first pairs touch at about
  0.045 s (h = 0.005 m); from 0.065 s (``--start``) every disc presses on its neighbours (840
  touching pair entries at 0.06 s, 2,250 at 0.095 s on one process), and the ``--steps`` steps
  after it are measured. The contact work per step is the processor time of ``PairContact``
  (detection, events, forces, energies), the largest over the processes (the one the others
  wait for); the rest of the step's processor time (the elastic pass, MEMM's update and
  reductions) is reported too: its ratio on two processes against one is what this machine
  gives for work that divides exactly. P = 1 and 2 are run ``--repeat`` times, interleaved, and
  the median of the ratios is reported. Within a run the window is replayed ``--replays`` times
  from the state at its start (``MEMM.restore``): a run reports its median replay, and the sum
  over steps of each step's cheapest replay ("undisturbed": the host slows its cores at times, by
  up to 1.8 x for seconds to minutes, docs/parallel.md, and a slowdown only adds time).

    .venv/bin/python benchmarks/bench_parallel.py [--quick] [--out docs/bench/parallel.json]

The full run takes about 20 minutes and ~20 GB of memory (the 1e6-cell 3D scene on 2 processes);
``--quick`` runs small sizes only. Results: docs/bench/parallel.json and docs/parallel.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import resource
import statistics
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_btl_vader_single_copy_mechanism": "none", "OMP_NUM_THREADS": "1"}


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) / 1024.0
    return 0.0


def _available_mb() -> float:
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable"):
                return int(line.split()[1]) / 1024.0
    return 0.0


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child_scaling(cells: int, dim: int, steps: int) -> dict:
    import numpy as np
    from mpi4py import MPI

    from dolfinx_dem import MEMM, DEMDiscretisation, DEMProblem, DirichletBC, ElasticMaterial, meshes

    comm = MPI.COMM_WORLD
    baseline = _rss_mb()
    comm.barrier()
    wall = time.perf_counter()
    if dim == 2:
        n = max(1, round((cells / 4) ** 0.5))
        mesh, _, tags = meshes.create_rectangle(comm, [0, 0], [1, 1], [n, n], "crossed")
    else:
        n = max(1, round((cells / 6) ** (1 / 3)))
        mesh, _, tags = meshes.create_box(comm, [0, 0, 0], [1, 1, 1], [n, n, n])
    comm.barrier()
    t_mesh = time.perf_counter() - wall
    material = ElasticMaterial(E=1.0e4, nu=0.3, rho=1.0)
    wall, cpu = time.perf_counter(), time.process_time()
    dem = DEMDiscretisation(mesh, material, "A", [DirichletBC(tags.find(meshes.XMIN), [0.0] * dim)],
                            body_force=[0.0] * (dim - 1) + [-1.0])
    t_setup = comm.allreduce(time.perf_counter() - wall, op=MPI.MAX)
    cpu_setup = comm.allreduce(time.process_time() - cpu, op=MPI.MAX)
    wall = time.perf_counter()
    dt = 0.5 * dem.stable_time_step()
    t_stable = comm.allreduce(time.perf_counter() - wall, op=MPI.MAX)
    memm = MEMM(DEMProblem(dem), dt)
    memm.initialise(dem.create_vector(), dem.create_vector())
    times = []
    for _ in range(steps):
        comm.barrier()
        wall = time.perf_counter()
        memm.step()
        times.append(comm.allreduce(time.perf_counter() - wall, op=MPI.MAX))
    per_process = comm.gather({"peak_mb": _peak_mb(), "baseline_mb": baseline, "rss_mb": _rss_mb(),
                               "owned_cells": dem.n_owned, "held_cells": dem.geometry.num_cells}, root=0)
    return {"kind": "scaling", "dim": dim, "cells": dem.geometry.num_cells_global, "processes": comm.size,
            "mesh_seconds": t_mesh, "setup_seconds": t_setup, "setup_cpu_seconds": cpu_setup,
            "stable_step_seconds": t_stable,
            "step_seconds_median": float(np.median(times)) if times else None, "steps": steps,
            "per_process": per_process}


def child_pile(h: float, steps: int, start: float, replays: int) -> dict:
    import numpy as np
    from mpi4py import MPI

    from dolfinx_dem import MEMM, DEMDiscretisation, DEMProblem, ElasticMaterial, PairContact, meshes

    comm = MPI.COMM_WORLD
    r, gap = 0.1, 0.002
    discs = [((i * (2 * r + gap), j * (2 * r + gap)), r) for j in range(8) for i in range(8)]
    centre = 3.5 * (2 * r + gap)
    wall = time.perf_counter()
    mesh, _, _ = meshes.create_discs(comm, discs, h)
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=100.0, nu=0.2, rho=100.0), "B")
    contact = PairContact(dem, meshes.exterior_facets(mesh))
    t_setup = comm.allreduce(time.perf_counter() - wall, op=MPI.MAX)
    dt = 0.5 * dem.stable_time_step()
    x = dem.geometry.cell_centres[: dem.n_owned]
    v0 = dem.create_vector()
    v0.array[:] = (-0.5 * (x - centre)).ravel()
    memm = MEMM(DEMProblem(dem, [contact]), dt)
    memm.initialise(dem.create_vector(), v0)

    def touching() -> int:  # each touching pair counted by both owners of its facets
        g, w = contact.outputs.pair_states(contact.patch_values(memm.u))
        return comm.allreduce(int(((g < 0) & (w > 0)).sum()), op=MPI.SUM)

    for _ in range(int(start / dt) + 1):
        memm.step()
    touching_at_start = touching()
    # the window is replayed from this state (MEMM.restore, bit for bit; the list is rebuilt at
    # the first step of each replay)
    saved = memm.state()
    vectors = {k: saved[k].array_r.copy() for k in ("u", "v_prev", "v_next")}
    scalars = {k: saved[k] for k in ("t0", "n", "budget", "work", "data_potential", "force_evaluations",
                                     "max_step_evaluations")}
    recurrence, contact_state = saved["recurrence"], contact.checkpoint_state()
    work = np.zeros((2, replays, steps))  # this process's contact work and rest of each step (processor s)
    wall = np.zeros(replays)
    for k in range(replays):
        memm.restore(**vectors, **scalars, recurrence={name: a.copy() for name, a in recurrence.items()})
        contact.restore_state(contact_state)
        comm.Barrier()
        start_wall = time.perf_counter()
        for n in range(steps):
            seconds, cpu = contact.seconds, time.process_time()
            memm.step()
            work[0, k, n] = contact.seconds - seconds
            work[1, k, n] = time.process_time() - cpu - work[0, k, n]
        wall[k] = time.perf_counter() - start_wall
    touching_at_end = touching()
    # per replay, the busiest process's window (the others wait for it), and the processes' sum;
    # "undisturbed": each process's window made of each step's cheapest replay, the busiest
    busiest, summed, undisturbed = work.sum(axis=2), work[0].sum(axis=1), work.min(axis=1).sum(axis=1)
    for a, op in ((busiest, MPI.MAX), (summed, MPI.SUM), (undisturbed, MPI.MAX), (wall, MPI.MAX)):
        comm.Allreduce(MPI.IN_PLACE, a, op=op)
    if comm.rank != 0:
        return {}
    return {"kind": "pile", "cells": dem.geometry.num_cells_global, "processes": comm.size, "discs": len(discs),
            "h": h, "dt": dt, "setup_seconds": t_setup, "start": start, "steps": steps, "replays": replays,
            "touching_pair_entries_at_start": touching_at_start, "touching_pair_entries": touching_at_end,
            "contact_seconds_per_step_max": float(np.median(busiest[0])) / steps,
            "contact_seconds_per_step_undisturbed": float(undisturbed[0]) / steps,
            "contact_seconds_per_step_sum": float(np.median(summed)) / steps,
            "rest_cpu_seconds_per_step_max": float(np.median(busiest[1])) / steps,
            "rest_cpu_seconds_per_step_undisturbed": float(undisturbed[1]) / steps,
            "step_wall_seconds": float(np.median(wall)) / steps}


def _median_ratio(pairs: list[tuple[dict, dict]], key: str) -> float:
    """The median over pairs of runs (P = 1, P = 2) of run(2)[key] / run(1)[key]."""
    return statistics.median([b[key] / a[key] for a, b in pairs])


def _child(args: list[str], processes: int) -> dict:
    command = ["mpirun", "-n", str(processes), "--oversubscribe", sys.executable, str(pathlib.Path(__file__).resolve()),
               *args]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "ORTE_"))} | MPI_ENV
    load = os.getloadavg()[0]
    started = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    proc = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{proc.stderr[-4000:]}")
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    result.update(date=started, load_average_at_start=load, commit=_commit())
    return result


def _commit() -> str:
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT,
                          check=False).stdout.strip()


def _memory_summary(run: dict) -> dict:
    peaks = [p["peak_mb"] for p in run["per_process"]]
    return {"peak_mb_max": max(peaks), "peak_mb_sum": sum(peaks),
            "bytes_per_cell_summed": 1e6 * sum(peaks) / run["cells"] * 1.048576,
            "bytes_per_cell_above_baseline": 1e6 * sum(p["peak_mb"] - p["baseline_mb"] for p in run["per_process"])
            / run["cells"] * 1.048576,
            "held_over_owned_max": max(p["held_cells"] / max(p["owned_cells"], 1) for p in run["per_process"])}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only")
    parser.add_argument("--only", nargs="+", choices=("scaling", "large", "pile"),
                        help="run these parts only and replace them in an existing --out file (e.g. the timed "
                             "parts again on an idle machine)")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "docs" / "bench" / "parallel.json")
    parser.add_argument("--child", choices=("scaling", "pile"), help=argparse.SUPPRESS)
    parser.add_argument("--cells", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--dim", type=int, default=2, help=argparse.SUPPRESS)
    parser.add_argument("--steps", type=int, default=10, help=argparse.SUPPRESS)
    parser.add_argument("--h", type=float, default=0.005, help=argparse.SUPPRESS)
    parser.add_argument("--start", type=float, default=0.065, help=argparse.SUPPRESS)
    parser.add_argument("--repeat", type=int, default=3, help="pairs of pile runs (P = 1, 2), interleaved")
    parser.add_argument("--replays", type=int, default=5, help="replays of the pile's window in a run")
    args = parser.parse_args(argv)
    if args.child == "scaling":
        result = child_scaling(args.cells, args.dim, args.steps)
    elif args.child == "pile":
        result = child_pile(args.h, args.steps, args.start, args.replays)
    if args.child is not None:
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(json.dumps(result))
        return result

    def log(text):
        print(text, flush=True)

    load = os.getloadavg()[0]

    big, big3, huge = (20_000, 6_000, 40_000) if args.quick else (1_000_000, 1_000_000, 4_000_000)
    parts = set(args.only or ("scaling", "large", "pile"))
    previous = json.loads(args.out.read_text()) if args.only else {}
    scaling = [] if "scaling" in parts else previous["scaling"]
    for P in (1, 2, 4) if "scaling" in parts else ():
        run = _child(["--child", "scaling", "--cells", str(big), "--dim", "2", "--steps", "20"], P)
        run.update(_memory_summary(run))
        scaling.append(run)
        log(f"2D {run['cells']:,} cells, P = {P}: set-up {run['setup_seconds']:.1f} s, peak {run['peak_mb_max']:.0f} MB "
            f"per process ({run['bytes_per_cell_summed']:.0f} B/cell summed), step {run['step_seconds_median']*1e3:.1f} ms")
    one = scaling[0]
    large = [] if "large" in parts else previous["large"]
    for cells, dim in ((big3, 3), (huge, 2)) if "large" in parts else ():
        # Predicted from the 2-process 2D run (a 3D cell costing ~3 x a 2D one): a run that
        # would not fit in the memory available now is recorded as skipped, and the largest
        # half, quarter, ... of it that fits is run instead.
        per_cell = scaling[1]["bytes_per_cell_summed"] * (3.0 if dim == 3 else 1.0)
        available = _available_mb()
        while cells * per_cell / 2**20 > 0.85 * available:
            large.append({"dim": dim, "cells": cells, "processes": 2, "skipped": True,
                          "predicted_mb": cells * per_cell / 2**20, "available_mb": available})
            log(f"{dim}D {cells:,} cells, P = 2: skipped, predicted {cells * per_cell / 2**20:.0f} MB > 0.85 x "
                f"available {available:.0f} MB")
            cells //= 2
        run = _child(["--child", "scaling", "--cells", str(cells), "--dim", str(dim), "--steps", "5"], 2)
        run.update(_memory_summary(run))
        large.append(run)
        log(f"{dim}D {run['cells']:,} cells, P = 2: set-up {run['setup_seconds']:.1f} s, peak {run['peak_mb_max']:.0f} MB "
            f"per process, step {run['step_seconds_median']*1e3:.1f} ms")
    pile = [] if "pile" in parts else previous["pile"]
    for _ in range(args.repeat) if "pile" in parts else ():
        for P in (1, 2):
            run = _child(["--child", "pile", "--h", "0.02" if args.quick else "0.005", "--steps", "20",
                          "--replays", str(args.replays)], P)
            pile.append(run)
            log(f"pile {run['cells']:,} cells, P = {P}: contact {run['contact_seconds_per_step_max']*1e3:.2f} ms per "
                f"step (max over processes; undisturbed {run['contact_seconds_per_step_undisturbed']*1e3:.2f}), the "
                f"rest of the step {run['rest_cpu_seconds_per_step_max']*1e3:.1f} ms "
                f"({run['rest_cpu_seconds_per_step_undisturbed']*1e3:.1f}), "
                f"{run['touching_pair_entries_at_start']} -> {run['touching_pair_entries']} touching pair entries")
    pairs = list(zip(pile[0::2], pile[1::2]))
    two, four = scaling[1], scaling[2]
    results = {
        "description": "issue 11 parallel study (benchmarks/bench_parallel.py); wall seconds, slowest process; "
                       "each run records its date, commit and load average",
        "date": datetime.datetime.now().strftime("%Y-%m-%d %H:%M"),
        "parts_run_at_this_date": sorted(parts),
        "commit": _commit(),
        "load_average_at_start": load,
        "quick": args.quick,
        "memory_ratio_to_target": {  # peak per process / (1.3 peak(1) / P + 300 MB): <= 1 meets the target
            str(r["processes"]): r["peak_mb_max"] / (1.3 * one["peak_mb_max"] / r["processes"] + 300.0)
            for r in scaling},
        "setup_2_over_1": two["setup_seconds"] / one["setup_seconds"],
        "setup_4_over_1": four["setup_seconds"] / one["setup_seconds"],
        # the median over the interleaved pairs of runs (one process, then two) of the ratios of the
        # median replays, and of each step's cheapest replay (``child_pile``)
        "contact_2_over_1": _median_ratio(pairs, "contact_seconds_per_step_max"),
        "contact_2_over_1_undisturbed": _median_ratio(pairs, "contact_seconds_per_step_undisturbed"),
        "rest_of_step_2_over_1": _median_ratio(pairs, "rest_cpu_seconds_per_step_max"),
        "rest_of_step_2_over_1_undisturbed": _median_ratio(pairs, "rest_cpu_seconds_per_step_undisturbed"),
        "scaling": scaling, "large": large, "pile": pile,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    log(json.dumps({k: v for k, v in results.items() if k not in ("scaling", "large", "pile")}, indent=1))
    return results


if __name__ == "__main__":
    main()
