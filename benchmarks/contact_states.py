"""The pair-contact state of a run at given times, saved for ``contact_coverage.py``: every known
candidate facet (reference geometry, free displacement u_f^free, corrected u_f), the pair list
and its free gaps g and overlaps w (serial), one ``<tag>_<t>.npz`` per time in OUTDIR.

    .venv/bin/python benchmarks/contact_states.py two-balls '{"mesh.h": 0.02, "mesh.refine_h": 0.02, "material.eta": 100.0, "contact.skin": 0.05}' OUT/h02 0.1 0.2 0.25
    .venv/bin/python benchmarks/contact_states.py two-disks '{"mesh.h": 0.005}' OUT/d005 0.1 0.2 0.25

``--no-sliding`` (a DIAGNOSTIC, not the method: the force is then not the gradient of the energy)
drops the sliding force g dw/du of eq. (34) (``_overlap`` returns dw = 0), to test whether it
drives the facets of a contact zone apart (docs/validation/contact3d.md, "Why the refined
meshes sink").
"""

import json
import sys

import numpy as np
from mpi4py import MPI

from dolfinx_dem import pair_contact, scenes
from dolfinx_dem.dynamics import DynamicRun


def save(c, u, t, path):
    """The state of the PairContact ``c`` at displacements ``u`` (time ``t``) into ``path``."""
    up = c.patch_values(u)
    uc = c.free_displacements(up)
    L, F = c.listed, c.facets_all
    g, w, _ = c._state(np.arange(len(L)), uc[L.i], uc[L.j], closed=True)
    pen, force = c.penetration(up), c.contact_force(up)
    np.savez(path, uc=uc, uf=uc + c._corrections_everywhere(up), centre=F.centre, ends=F.ends, normal=F.normal,
             length=F.length, body=F.body, vids=F.vertex_ids, key=F.key, i=L.i, j=L.j, n=L.n, g=g, w=w,
             pen=pen, force=force, t=t)
    print(f"t = {t:.4f} s: penetration {pen:.5f} m, contact force {force:.3f} N, {len(L)} pairs listed", flush=True)


def without_sliding():
    """Replace ``pair_contact._overlap`` by one returning dw = 0 (diagnostic only)."""
    overlap = pair_contact._overlap

    def no_slide(A, B, p, s):
        w, dw = overlap(A, B, p, s)
        return w, np.zeros_like(dw)

    pair_contact._overlap = no_slide


def main():
    args = [a for a in sys.argv[1:] if a != "--no-sliding"]
    if "--no-sliding" in sys.argv:
        without_sliding()
    name, overrides, out, times = args[0], json.loads(args[1]), args[2], [float(t) for t in args[3:]]
    run = DynamicRun(scenes.load(name, {**overrides, "time.end": 1.0}), MPI.COMM_SELF, quiet=True)
    stepper, c = run.stepper, run.dem.pair_contact
    print(f"{name} {overrides}: dt {run.dt:.4e} s", flush=True)
    for T in times:
        while stepper.t < T:
            stepper.step()
        save(c, stepper.u, stepper.t, f"{out}_{stepper.t:.4f}.npz")


if __name__ == "__main__":
    main()
