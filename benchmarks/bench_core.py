"""Core cost of the DEM: set-up, force evaluation and MEMM step against a bare PETSc MatMult.

For unit-square meshes ("right" diagonals, 2 n^2 triangles, clamped on x = 0, scheme A) of about
1e4, 5e4 and 2e5 cells this measures

* set-up time of ``DEMDiscretisation``, split from the outside by calling the module functions in
  sequence: ``compute_geometry``, ``compute_reconstruction``, ``compute_energy_operators``, then
  what the constructor does with their result (``stiffness_product`` K = S^T S + J^T J with scipy,
  ``petsc_matrices``: the PETSc AIJ copies of S, J, grad and K), then the full constructor. Each
  number is the best of 3 such sequences (2 for 2e5 cells); ``rest`` = constructor - parts (Dirichlet
  handling, vectors; +- timing noise). ``constructor_cold`` is the first constructor call of the
  process, which also builds the DOLFINx connectivities and the DG0 space;
* one ``force`` evaluation and one ``MEMM.step`` against ``K.mult`` with the same matrix (medians
  of 50 interleaved repetitions; the ratios are what matter);
* memory per cell: the rise of the peak RSS (``resource.getrusage``) during the first constructor
  call, divided by the number of cells.

Each size runs in its own subprocess so that peak-RSS measurements do not see earlier sizes.
Serial only. Usage::

    python benchmarks/bench_core.py            # 1e4, 5e4, 2e5 cells -> docs/bench/core.json
    python benchmarks/bench_core.py --quick    # 1e4 cells only
    python benchmarks/bench_core.py --out /tmp/core.json
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import resource
import statistics
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: unit-square divisions n: 2 n^2 cells ~ 1e4, 5e4, 2e5
SIZES = {"1e4": 71, "5e4": 158, "2e5": 316}
REPEATS = 50


def _rss_now_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB on Linux


def _median_times(fns, repeats) -> list[float]:
    """Median wall time of each of ``fns``, called in turn ``repeats`` times (after a warm-up)."""
    for fn in fns:
        fn()
    times = [[] for _ in fns]
    for _ in range(repeats):
        for fn, record in zip(fns, times):
            t = time.perf_counter()
            fn()
            record.append(time.perf_counter() - t)
    return [statistics.median(record) for record in times]


def measure(n: int, setup_repeats: int = 3) -> dict:
    """All measurements for one unit-square mesh of 2 n^2 cells (run in a fresh process)."""
    import numpy as np
    from mpi4py import MPI

    import dolfinx.mesh

    from dolfinx_dem import _compat
    from dolfinx_dem.discretisation import DEMDiscretisation, DirichletBC, _petsc_matrix
    from dolfinx_dem.geometry import compute_geometry
    from dolfinx_dem.material import ElasticMaterial
    from dolfinx_dem.memm import MEMM
    from dolfinx_dem.operators import compute_energy_operators
    from dolfinx_dem.reconstruction import compute_reconstruction

    comm = MPI.COMM_WORLD
    material = ElasticMaterial(E=1.0, nu=0.3, rho=1.0)
    mesh = dolfinx.mesh.create_unit_square(comm, n, n, diagonal=dolfinx.mesh.DiagonalType.right)
    left = _compat.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    bcs = [DirichletBC(left, [0.0, 0.0])]

    # Memory: rise of the peak RSS during the first (cold) constructor call.
    rss_before = _rss_now_bytes()
    t = time.perf_counter()
    dem = DEMDiscretisation(mesh, material, scheme="A", dirichlet=bcs)
    constructor_cold = time.perf_counter() - t
    peak_rise = _peak_rss_bytes() - rss_before
    cells = dem.geometry.num_cells

    # Set-up split, from the outside; best of ``repeats`` runs of the whole sequence (the machine
    # may be shared: minima are the reproducible numbers).
    V = _compat.create_vector_space(mesh, "DG", 0)
    dirichlet = np.unique(_compat.local_facet_global_indices(mesh, left))
    best = {}
    for _ in range(setup_repeats):
        t0 = time.perf_counter()
        geom = compute_geometry(comm, mesh, V)
        t1 = time.perf_counter()
        rec = compute_reconstruction(geom, material, dirichlet, "A")
        t2 = time.perf_counter()
        ops = compute_energy_operators(geom, material, rec, geom.interior_facets)
        t3 = time.perf_counter()
        # What the constructor does next (serial: every row is owned): K = S^T S + J^T J, then
        # the PETSc matrices S, J, grad, K.
        K = (ops.S.tocsc().T @ ops.S + ops.J.tocsc().T @ ops.J).tocsr()
        t4 = time.perf_counter()
        cols = ops.S.shape[1]
        for A in (ops.S, ops.J, ops.grad, K):
            _petsc_matrix(comm, A, A.shape[0], cols).destroy()
        t5 = time.perf_counter()
        del ops, rec, geom, dem, K
        t6 = time.perf_counter()
        dem = DEMDiscretisation(mesh, material, scheme="A", dirichlet=bcs)
        t7 = time.perf_counter()
        for key, value in (("geometry", t1 - t0), ("reconstruction", t2 - t1), ("operators", t3 - t2),
                           ("stiffness_product", t4 - t3), ("petsc_matrices", t5 - t4),
                           ("constructor", t7 - t6)):
            best[key] = min(best.get(key, float("inf")), value)
    parts = ("geometry", "reconstruction", "operators", "stiffness_product", "petsc_matrices")
    setup = {key: best[key] for key in parts}
    setup["constructor"] = best["constructor"]
    setup["constructor_cold"] = constructor_cold
    setup["rest"] = best["constructor"] - sum(best[key] for key in parts)  # +- timing noise
    setup["repeats"] = setup_repeats

    # Force and MEMM step against K.mult.
    rng = np.random.default_rng(0)
    u = dem.create_vector()
    u.array[:] = 1e-3 * rng.normal(size=u.array.shape)
    out = dem.create_vector()
    c = material.wave_speed(2)
    memm = MEMM(dem, 0.3 / (n * c))  # stable: the limit measured on n = 71 is 0.61 / (n c)
    memm.initialise(u, dem.create_vector())
    # Interleaved, so that the three see the same machine load; medians of REPEATS.
    matmult, force, step = _median_times(
        [lambda: dem.K.mult(u, out), lambda: dem.force(u, 0.0, out), memm.step], REPEATS)
    return {
        "n": n,
        "cells": cells,
        "dofs": 2 * cells,
        "K_nonzeros": int(dem.K.getInfo()["nz_used"]),
        "setup_seconds": setup,
        "matmult_seconds": matmult,
        "force_seconds": force,
        "step_seconds": step,
        "force_vs_matmult_ratio": force / matmult,
        "step_vs_matmult_ratio": step / matmult,
        "peak_rss_rise_bytes": peak_rise,
        "memory_bytes_per_cell": peak_rise / cells,
    }


def _run_child(n: int) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.run(
        [sys.executable, str(pathlib.Path(__file__).resolve()), "--child", str(n)],
        capture_output=True, text=True, env=env, check=False,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark child for n = {n} failed:\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _table(results: dict) -> str:
    head = (f"{'cells':>8} {'geom':>7} {'recon':>7} {'ops':>7} {'K=StS':>7} {'petsc':>7} {'ctor':>7} {'cold':>7}"
            f" {'K.mult':>9} {'force/mm':>9} {'step/mm':>8} {'B/cell':>7}")
    lines = [head, "-" * len(head)]
    for r in results.values():
        s = r["setup_seconds"]
        lines.append(
            f"{r['cells']:>8} {s['geometry']:>7.3f} {s['reconstruction']:>7.3f} {s['operators']:>7.3f}"
            f" {s['stiffness_product']:>7.3f} {s['petsc_matrices']:>7.3f} {s['constructor']:>7.3f}"
            f" {s['constructor_cold']:>7.3f}"
            f" {r['matmult_seconds'] * 1e6:>7.0f}us {r['force_vs_matmult_ratio']:>9.2f}"
            f" {r['step_vs_matmult_ratio']:>8.2f} {r['memory_bytes_per_cell']:>7.0f}"
        )
    return "\n".join(lines)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="1e4 cells only")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "docs" / "bench" / "core.json")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        print(json.dumps(measure(args.child, setup_repeats=2 if args.child > 200 else 3)))
        return {}

    sizes = {"1e4": SIZES["1e4"]} if args.quick else SIZES
    results = {}
    for label, n in sizes.items():
        results[label] = _run_child(n)
        print(f"  {label}: {results[label]['cells']} cells done", flush=True)
    data = {
        "description": "DEMDiscretisation set-up and per-step cost, unit square, 'right' mesh, "
                       "scheme A, clamped x = 0, serial; times in s; ratios are medians of "
                       f"{REPEATS} over the median of {REPEATS} K.mult",
        "sizes": {label: r["cells"] for label, r in results.items()},
        "setup_seconds": {label: r["setup_seconds"] for label, r in results.items()},
        "force_vs_matmult_ratio": {label: r["force_vs_matmult_ratio"] for label, r in results.items()},
        "step_vs_matmult_ratio": {label: r["step_vs_matmult_ratio"] for label, r in results.items()},
        "memory_bytes_per_cell": {label: r["memory_bytes_per_cell"] for label, r in results.items()},
        "raw": results,
        "environment": {"python": platform.python_version(), "machine": platform.machine(),
                        "cpus": os.cpu_count(), "quick": args.quick},
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(data, indent=2) + "\n")
    print(_table(results))
    print(f"written {args.out}")
    return data


if __name__ == "__main__":
    main()
