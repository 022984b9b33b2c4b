"""Contact work follows the facets near contact, not all contact boundary facets (issue 6).

Two disks collide (the `two-disks` set-up of paper §5.3, h = 0.02 m) while N idle disks of the
same size rest far away; every disk boundary is a contact boundary. The contact work per step
(processor time in `PairContact.force_integral` and `energy_correction`, i.e. detection,
events, contact forces and energies; the cheapest of three equal chunks of the run, whose
steps all lie in the contact phase for t_end = 0.3 s) is measured for growing N: it should stay nearly constant,
because the Verlet list only holds pairs near contact and the contact patch of a step is the one
of the listed pairs. The elastic part of the step grows with the number of cells.

    .venv/bin/python benchmarks/bench_contact_scaling.py [--quick] [--out docs/bench/contact_scaling.json]

Serial (the timings are of one process).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import MEMM, DEMDiscretisation, DEMProblem, ElasticMaterial, PairContact, meshes

SOFT = ElasticMaterial(E=100.0, nu=0.2, rho=100.0)


def measure(n_idle: int, h: float, t_end: float) -> dict:
    """Run the colliding pair with ``n_idle`` idle disks; per-step processor times."""
    idle = [((1.0 + 0.3 * (k % 32), 2.0 + 0.3 * (k // 32)), 0.1) for k in range(n_idle)]
    mesh, _, _ = meshes.create_discs(MPI.COMM_SELF, [((0.14, 2.27), 0.1), ((0.36, 2.27), 0.1)] + idle, h)
    dem = DEMDiscretisation(mesh, SOFT, "B")
    contact = PairContact(dem, meshes.exterior_facets(mesh))
    dt = 0.2 * dem.stable_time_step()
    stepper = MEMM(DEMProblem(dem, [contact]), dt)
    v0 = dem.create_vector()
    x = dem.geometry.cell_centres
    v0.array.reshape(-1, 2)[:, 0] = np.where(x[:, 0] < 0.25, 0.3, np.where(x[:, 0] < 0.5, -0.3, 0.0))
    stepper.initialise(dem.create_vector(), v0)
    # The contact phase in three equal chunks; the cheapest chunk counts (the machine is shared).
    steps = int(round(t_end / dt)) // 3
    totals = []
    for _ in range(3):
        contact.seconds = 0.0
        start = time.process_time()
        for _ in range(steps):
            stepper.step()
        totals.append((time.process_time() - start, contact.seconds))
    total, contact_seconds = min(totals)
    return {
        "idle_disks": n_idle,
        "cells": dem.geometry.num_cells_global,
        "contact_facets": int(len(contact.facets)),
        "pairs_listed": int(len(contact.listed)),
        "steps": steps,
        "step_ms": 1e3 * total / steps,
        "contact_ms_per_step": 1e3 * contact_seconds / steps,
        "contact_fraction": contact_seconds / total,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer disks and steps (for the tests)")
    parser.add_argument("--out", type=pathlib.Path, default=None, help="JSON file for the results")
    args = parser.parse_args()
    counts = [0, 8] if args.quick else [0, 8, 32, 128, 512, 2048]
    t_end = 0.05 if args.quick else 0.3
    rows = [measure(n, 0.02, t_end) for n in counts]
    print(f"{'idle':>5} {'cells':>7} {'facets':>7} {'pairs':>6} {'step ms':>8} {'contact ms':>10} {'share':>6}")
    for r in rows:
        print(f"{r['idle_disks']:5d} {r['cells']:7d} {r['contact_facets']:7d} {r['pairs_listed']:6d} "
              f"{r['step_ms']:8.3f} {r['contact_ms_per_step']:10.3f} {100 * r['contact_fraction']:5.1f}%")
    facets = rows[-1]["contact_facets"] / rows[0]["contact_facets"]
    contact = rows[-1]["contact_ms_per_step"] / rows[0]["contact_ms_per_step"]
    print(f"contact facets x{facets:.1f}: contact work per step x{contact:.2f}")
    if args.out is not None:
        args.out.write_text(json.dumps({"rows": rows, "contact_facets_ratio": facets,
                                        "contact_work_ratio": contact, "quick": args.quick}, indent=1))
        chart(rows, args.out.with_suffix(".png"))
    return rows


def chart(rows: list[dict], filename: pathlib.Path):
    """Log-log: step and contact work per step against the number of cells."""
    import matplotlib.figure

    cells = np.array([r["cells"] for r in rows])
    figure = matplotlib.figure.Figure(figsize=(5.5, 4))
    ax = figure.subplots()
    ax.loglog(cells, [r["step_ms"] for r in rows], "C0-o", label="MEMM step")
    ax.loglog(cells, [r["contact_ms_per_step"] for r in rows], "C1-s", label="contact work")
    ax.loglog(cells, cells * rows[-1]["step_ms"] / cells[-1], ":", color="grey", label="slope 1")
    ax.set(xlabel="cells (2 colliding disks + idle disks)", ylabel="processor time per step (ms)",
           title="contact work follows the contact")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    figure.tight_layout()
    figure.savefig(filename, dpi=110)


if __name__ == "__main__":
    main()
