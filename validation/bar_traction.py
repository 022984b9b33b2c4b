"""1D bar under a suddenly applied end traction: DEM/MEMM against the exact wave solution.

Bar [0, L], clamped at x = 0, at rest, traction sigma on x = L from t = 0 on. The exact tip
displacement is piecewise linear in time: u(L, t) = sigma c s / E for s = t mod 4L/c <= 2L/c, then
back to 0 at s = 4L/c (peak 2 sigma L / E, period 4L/c). Reported: the L2-in-time error of the tip
displacement (the P1 reconstruction of eq. (10) at x = L) relative to the L2 norm of the exact one,
its order between meshes, and the pseudo-energy drift (the traction is constant: conserved).

    .venv/bin/python validation/bar_traction.py [--out docs/validation/bar_traction.json] [--quick]

``--quick``: 50 and 100 cells (seconds), for the tests.
"""

import argparse
import json
import sys

import numpy as np
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC, Traction
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem

L, E, RHO, SIGMA, PERIODS, CFL = 1.0, 1.0, 1.0, 0.01, 2, 0.5


def exact_tip(t):
    c = np.sqrt(E / RHO)
    s = np.mod(t, 4 * L / c)
    return SIGMA * c / E * np.where(s <= 2 * L / c, s, 4 * L / c - s)


def run(n: int, scheme: str = "A") -> dict:
    comm = MPI.COMM_WORLD
    mesh, _, tags = meshes.create_interval(comm, n, 0.0, L)
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=E, nu=0.0, rho=RHO), scheme,
                            [DirichletBC(tags.find(meshes.XMIN), [0.0])],
                            tractions=[Traction(tags.find(meshes.XMAX), [SIGMA])])
    end = PERIODS * 4 * L / np.sqrt(E / RHO)
    steps = int(np.ceil(end / (CFL * dem.stable_time_step())))
    stepper = MEMM(DEMProblem(dem), end / steps)
    first = stepper.initialise(dem.create_vector(), dem.create_vector())
    last = np.flatnonzero(np.isclose(dem.geometry.cell_centres[: dem.n_owned, 0], L - L / (2 * n)))

    def tip():
        G = dem.gradient(stepper.u, stepper.t)
        value = float(stepper.u.array_r[last[0]] + G[last[0], 0, 0] * L / (2 * n)) if len(last) else 0.0
        return comm.allreduce(value, op=MPI.SUM)

    times, values, drift, scale = [0.0], [tip()], 0.0, first.mechanical
    for _ in range(steps):
        diag = stepper.step()
        times.append(diag.t)
        values.append(tip())
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy))
        scale = max(scale, diag.mechanical)
    t, u = np.array(times), np.array(values)
    exact = exact_tip(t)
    return {"n": n, "scheme": scheme, "dt": stepper.dt, "steps": steps,
            "tip_l2_rel_error": float(np.sqrt(np.trapz((u - exact) ** 2, t) / np.trapz(exact**2, t))),
            "tip_max_error_rel_peak": float(np.abs(u - exact).max() / (2 * SIGMA * L / E)),
            "tip_peak_rel": float(u.max() / (2 * SIGMA * L / E)),
            "pseudo_energy_rel_drift": drift / scale}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--n", type=int, nargs="+", default=[50, 100, 200])
    parser.add_argument("--quick", action="store_true", help="--n 50 100")
    args = parser.parse_args()
    if args.quick:
        args.n = [50, 100]
    results = []
    for scheme in ("A", "B"):
        rows = [run(n, scheme) for n in args.n]
        for coarse, fine in zip(rows, rows[1:]):
            fine["order"] = float(np.log(coarse["tip_l2_rel_error"] / fine["tip_l2_rel_error"])
                                  / np.log(fine["n"] / coarse["n"]))
        results += rows
    if MPI.COMM_WORLD.rank == 0:
        for r in results:
            print(json.dumps(r))
        if args.out:
            with open(args.out, "w") as f:
                json.dump({"command": " ".join([".venv/bin/python", "validation/bar_traction.py"] + sys.argv[1:]), "L": L, "E": E, "rho": RHO,
                           "sigma": SIGMA, "periods": PERIODS, "cfl": CFL, "results": results}, f, indent=1)


if __name__ == "__main__":
    main()
