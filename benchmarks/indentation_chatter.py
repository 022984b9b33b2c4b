"""The high-frequency part of the dynamic indentation force (docs/validation/indentation.md).

Runs the built-in scene ``indentation`` at mesh size h, CFL number and disc speed V up to an
indentation of 0.012 m, samples -reaction_disc_y every other step, and prints, over the window
|delta - target| < 1 mm around delta = 0.005 and 0.01 m, the force's mean, its range, and the
largest second difference of the samples (a chatter at the scale of a few steps shows there,
the block's slow modes do not).

    .venv/bin/python benchmarks/indentation_chatter.py 0.02 0.5 0.25
"""

import sys

import numpy as np
from mpi4py import MPI

from dolfinx_dem import dynamics, scenes

GAP = 0.002


def main(h: float, cfl: float, speed: float) -> None:
    scene = scenes.load("indentation", {"mesh.h": h, "time.cfl": cfl, "time.end": (0.012 + GAP) / speed})
    scene["prescribed"][0]["velocity"] = [0.0, -speed]
    run = dynamics.DynamicRun(scenes.validate(scene), MPI.COMM_WORLD, quiet=True)
    dem, stepper = run.dem, run.stepper
    force, t = [], []
    for k in range(run.n_steps):
        stepper.step()
        if k % 2 == 0:
            force.append(-float(dem.prescribed_values(stepper.u, stepper.t)[0, 0, 1]))
            t.append(stepper.t)
    force, delta = np.array(force), speed * np.array(t) - GAP
    for target in (0.005, 0.01):
        w = np.abs(delta - target) < 1e-3
        print(f"h = {h}, CFL {cfl}, V = {speed} m/s, dt = {run.dt:.3e} s, delta {target} m +- 1 mm: force mean "
              f"{force[w].mean():.2f}, min {force[w].min():.2f}, max {force[w].max():.2f} N/m; largest second "
              f"difference of the samples {np.abs(np.diff(force[w], 2)).max():.2f} N/m")


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:4]))
