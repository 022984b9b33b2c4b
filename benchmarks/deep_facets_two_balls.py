"""The deepest facets of a `two-balls` run: at given times, the three facets of largest
`penetration` (the overlap-weighted mean of their touching partners' corrected gaps), with their
partners' free gaps g and overlaps w / |f| and the coverage sum w / |f| (1 for a facet its
partners cover once). Scene overrides as JSON (a uniform skin keeps a deep run going; the
sinking run of docs/validation/contact3d.md: a uniform mesh and the paper's eta = E).

    .venv/bin/python benchmarks/deep_facets_two_balls.py '{"mesh.h": 0.02, "mesh.refine_h": 0.02, "material.eta": 100.0, "contact.skin": 0.05, "contact.max_penetration": 100}' 0.2 0.25 0.28
"""

import json
import sys

import numpy as np
from mpi4py import MPI

from dolfinx_dem import pair_contact, scenes
from dolfinx_dem.dynamics import DynamicRun


def main():
    overrides, times = json.loads(sys.argv[1]), [float(t) for t in sys.argv[2:]]
    run = DynamicRun(scenes.load("two-balls", {**overrides, "time.end": 1.0}), MPI.COMM_SELF, quiet=True)
    stepper, c = run.stepper, run.dem.pair_contact
    for T in times:
        while stepper.t < T:
            stepper.step()
        up = c.patch_values(stepper.u)
        uc = c.free_displacements(up)
        L, F = c.listed, c.facets_all
        g, w, _ = c._state(np.arange(len(L)), uc[L.i], uc[L.j], closed=True)
        uf = uc + c._corrections_everywhere(up)
        touching = np.flatnonzero((w > 0) & (g < 0))
        i, j, ww = L.i[touching], L.j[touching], w[touching]
        gap = np.einsum("pi,pi->p", F.centre[j] + uf[j] - F.centre[i] - uf[i], L.n[touching])
        weight = np.bincount(i, ww, len(F)) + np.bincount(j, ww, len(F))
        mean = np.bincount(i, ww * gap, len(F)) + np.bincount(j, ww * gap, len(F))
        depth = np.where(weight > 0, -mean / np.where(weight > 0, weight, 1.0), 0.0)
        reach = pair_contact._reach(F)
        print(f"t = {stepper.t:.4f} s: contact force {c.contact_force(up):.3f} N, penetration {depth.max():.4f} m")
        for f in np.argsort(depth)[::-1][:3]:
            mine = (i == f) | (j == f)
            print(f"  facet at {np.round(F.centre[f], 4)} (reach {reach[f]:.4f} m): penetration {depth[f]:.4f} m, "
                  f"coverage {weight[f] / F.length[f]:.3f}; partners' free gaps {np.round(g[touching][mine], 4)}, "
                  f"w/|f| {np.round(ww[mine] / F.length[f], 3)}")


if __name__ == "__main__":
    main()
