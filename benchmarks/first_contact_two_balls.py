"""The first contact of the polyhedral balls of `two-balls`, computed without a run.

Until they touch the balls translate rigidly at +-0.3 m/s, so each pair's gap is affine in time:
the first contact is the earliest time at which a pair's gap closes with a positive overlap,
among the pairs listed with a skin that covers the flight until HORIZON. A run's
`first_contact_time` (interpolated within its step) should equal it; the spheres touch at
0.02 / 0.6 s, the polyhedra later (their facets lie inside the spheres): `late_steps` is the
delay in time steps of the scene.

    .venv/bin/python benchmarks/first_contact_two_balls.py ['{"mesh.h": 0.06}']
"""

import json
import sys

import numpy as np
from mpi4py import MPI

from dolfinx_dem import dynamics, model, scenes

HORIZON = 0.05  # s: the pairs listed are all those that can touch before (1.5 times 0.02 / 0.6)


def main():
    overrides = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
    scene = scenes.load("two-balls", overrides)
    dem = model.build(scene, MPI.COMM_SELF)
    # list every pair that can touch before HORIZON: the facets approach at 0.6 m/s, so a pair
    # closer than its reaches plus 0.6 HORIZON (one uniform skin) at t = 0
    dem.set_contact_boundary(dem.pair_contact.facets, skin=0.6 * HORIZON)
    c = dem.pair_contact
    x = dem.geometry.cell_centres[: dem.n_owned]
    v = dem.create_vector()
    v.array.reshape(-1, 3)[:, 0] = np.where(x[:, 0] < 0.25, 0.3, -0.3)
    vf = c.free_displacements(c.patch_values(v))
    vi, vj = vf[c.listed.i], vf[c.listed.j]
    ui, uj = c._pair_displacements(c.patch_values(dem.create_vector()))
    p = np.arange(c.num_pairs)
    g0 = c._gap(p, ui, uj)
    rate = c._gap(p, ui + vi, uj + vj) - g0  # the gaps' rates (1 s of flight)
    closing = np.where(rate < 0, g0 / np.where(rate < 0, -rate, 1.0), np.inf)
    first = np.inf
    for k in np.argsort(closing):
        if closing[k] >= first:
            break
        t = closing[k] * (1 + 1e-12)  # just after the closure: the overlap there
        if c._state(p[[k]], ui[[k]] + t * vi[[k]], uj[[k]] + t * vj[[k]])[1][0] > 0:
            first = closing[k]
    spheres = 0.02 / 0.6
    if not first < HORIZON:
        raise RuntimeError(f"no contact before {HORIZON} s: the listed pairs do not cover it")
    dt = dynamics.time_step(dem, scene["time"])
    print(json.dumps({"first_contact_polyhedra": first, "first_contact_spheres": spheres, "dt": dt,
                      "late_steps": (first - spheres) / dt, "cells": dem.n_owned,
                      "candidate_facets": c.num_facets, "listed_pairs": c.num_pairs}))


if __name__ == "__main__":
    main()
