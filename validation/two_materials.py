"""Two materials in 1D: springs in series, and a pulse crossing the interface.

Material 1 (E1 = 1, rho1 = 1, Z1 = 1) for x < a, material 2 (E2 = 4, rho2 = 1, Z2 = 2) after.

- static: the bar [0, 1], a = 0.4, clamped at x = 0 with a traction sigma at x = 1 (springs in
  series): the exact stress is sigma in every cell, u(1) = sigma (a / E1 + (1 - a) / E2);
- dynamic: the bar [0, 3.5], a = 1.5, clamped at x = 0; a stress pulse sigma_0(x - c1 t),
  sigma_0 = A E1 cos^4(pi (x - 0.75) / 0.5) on |x - 0.75| < 0.25, travels to the right. At
  t = 1.25 it has split into a reflected pulse in [0.75, 1.25] and a transmitted one in [2, 3],
  whose peak stresses are R = (Z2 - Z1)/(Z1 + Z2) = 1/3 and T = 2 Z2/(Z1 + Z2) = 4/3 times the
  incident peak A E1. Reported: the errors of the measured ratios (signed extremum of the cell
  stresses on each side over A E1), the relative L2 error of the cell stresses against the
  d'Alembert solution, and the MEMM pseudo-energy drift (relative to the energy).

Each is run with the facet weight eta_f of eq. (13) between the two materials as the library
computes it (``CellMaterials.facet_stabilisation``: harmonic mean) and, for comparison, as the
arithmetic mean and the minimum of the two cells' eta (substituted here, for this measurement only).

    .venv/bin/python validation/two_materials.py [--meshes 350 700 1400 2800] [--out docs/validation/two_materials.json]
    .venv/bin/python validation/two_materials.py --quick     # 350 and 700 cells (seconds), for the tests
"""

import argparse
import json

import dolfinx.mesh
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC, Traction
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import CellMaterials, ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem

MATERIALS = {1: ElasticMaterial(E=1.0, nu=0.0, rho=1.0), 2: ElasticMaterial(E=4.0, nu=0.0, rho=1.0)}
Z1, Z2 = (np.sqrt(m.rho * m.E) for m in MATERIALS.values())
R, T = (Z2 - Z1) / (Z1 + Z2), 2 * Z2 / (Z1 + Z2)
SIGMA, A, X0, W, T_END, CFL = 0.5, 1e-3, 0.75, 0.25, 1.25, 0.5
HARMONIC = CellMaterials.facet_stabilisation
WEIGHTS = {
    "harmonic": HARMONIC,
    "arithmetic": lambda self, c1, c2: 0.5 * (self.stabilisation(c1) + self.stabilisation(c2)),
    "min": lambda self, c1, c2: np.minimum(self.stabilisation(c1), self.stabilisation(c2)),
}


def bar(comm, n, length, a, scheme, traction=None):
    mesh, _, tags = meshes.create_interval(comm, n, 0.0, length)
    cells = np.arange(mesh.topology.index_map(1).size_local + mesh.topology.index_map(1).num_ghosts, dtype=np.int32)
    x = dolfinx.mesh.compute_midpoints(mesh, 1, cells)[:, 0]
    cell_tags = dolfinx.mesh.meshtags(mesh, 1, cells, np.where(x < a, 1, 2).astype(np.int32))
    tractions = [] if traction is None else [Traction(tags.find(meshes.XMAX), [traction])]
    return DEMDiscretisation(mesh, MATERIALS, scheme, [DirichletBC(tags.find(meshes.XMIN), [0.0])],
                             tractions=tractions, cell_tags=cell_tags)


def static(comm, n, scheme):
    a = 0.4
    dem = bar(comm, n, 1.0, a, scheme, SIGMA)
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(dem.K)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    u = dem.create_vector()
    ksp.solve(dem.data.load(0.0), u)
    ksp.destroy()
    stress = dem.stress(u, 0.0)[:, 0, 0]
    G = dem.gradient(u, 0.0)[:, 0, 0]
    x = dem.geometry.cell_centres[: dem.n_owned, 0]
    last = np.isclose(x, 1.0 - 0.5 / n)
    tip = comm.allreduce(float((u.array_r[last] + G[last] * 0.5 / n).sum()), op=MPI.SUM)
    exact_tip = SIGMA * (a / MATERIALS[1].E + (1 - a) / MATERIALS[2].E)
    near = np.abs(x - a) < 1.5 / n  # the cells at the interface
    return {"n": n, "scheme": scheme,
            "stress_max_error_rel": comm.allreduce(float(np.abs(stress / SIGMA - 1).max()), op=MPI.MAX),
            "stress_max_error_rel_away_from_interface": comm.allreduce(
                float(np.abs(stress[~near] / SIGMA - 1).max(initial=0.0)), op=MPI.MAX),
            "tip_error_rel": abs(tip / exact_tip - 1),
            "reaction_error_rel": abs(dem.reactions(u, 0.0)[0, 0] / SIGMA + 1)}


def pulse(s):
    """sigma_0(s) / (A E1): the cos^4 bump around X0."""
    return np.where(np.abs(s - X0) < W, np.cos(np.pi * (s - X0) / (2 * W)) ** 4, 0.0)


def exact_stress(x, t, a=1.5):
    c1, c2 = (np.sqrt(m.E / m.rho) for m in MATERIALS.values())
    left = pulse(x - c1 * t) + R * pulse(2 * a - x - c1 * t)
    right = T * pulse(a - c1 * (t - (x - a) / c2))
    return A * MATERIALS[1].E * np.where(x < a, left, right)


def dynamic(comm, n, scheme):
    a, length = 1.5, 3.5
    dem = bar(comm, n, length, a, scheme)
    h = length / n
    x = dem.geometry.cell_centres[: dem.n_owned, 0]
    # u0 with u0' = sigma_0 / E1 (exact cell averages of the primitive, Simpson on 64 sub-cells),
    # v0 = -c1 u0' (cell averages): a right-going wave
    s = np.linspace(0.0, length, 64 * n + 1)
    du = A * pulse(s)
    prim = np.concatenate([[0.0], np.cumsum(0.5 * (du[1:] + du[:-1]) * np.diff(s))])
    u0, v0 = dem.create_vector(), dem.create_vector()
    k = np.rint((x - 0.5 * h) / h).astype(int) * 64
    idx = k[:, None] + np.arange(65)
    u0.array[:] = np.trapz(prim[idx], s[idx], axis=1) / h
    v0.array[:] = -np.trapz(du[idx], s[idx], axis=1) / h
    steps = int(np.ceil(T_END / (CFL * dem.stable_time_step())))
    stepper = MEMM(DEMProblem(dem), T_END / steps)
    first = stepper.initialise(u0, v0)
    drift, scale = 0.0, first.mechanical
    for _ in range(steps):
        diag = stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy))
        scale = max(scale, diag.mechanical)
    stress = dem.stress(stepper.u, T_END)[:, 0, 0] / (A * MATERIALS[1].E)
    exact = exact_stress(x, T_END) / (A * MATERIALS[1].E)

    def extremum(mask):
        values = stress[mask]
        local = (float(np.abs(values).max()), float(values[np.argmax(np.abs(values))])) if len(values) else (0.0, 0.0)
        return max(comm.allgather(local))[1]

    r, t = extremum(x < a), extremum(x > a)
    sq = comm.allreduce(np.array([float(((stress - exact) ** 2).sum()), float((exact ** 2).sum())]), op=MPI.SUM)
    return {"n": n, "h": h, "scheme": scheme, "dt": stepper.dt, "steps": steps,
            "R": r, "R_error": abs(r - R), "T": t, "T_error": abs(t - T),
            "stress_l2_error_rel": float(np.sqrt(sq[0] / sq[1])), "pseudo_energy_drift_rel": drift / scale}


def orders(rows, key):
    return [float(np.log2(a[key] / b[key])) for a, b in zip(rows, rows[1:])]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--meshes", type=int, nargs="+", default=[350, 700, 1400])
    parser.add_argument("--quick", action="store_true", help="--meshes 350 700")
    args = parser.parse_args()
    if args.quick:
        args.meshes = [350, 700]
    comm = MPI.COMM_WORLD
    results = {"R_exact": R, "T_exact": T, "weights": {}}
    for name, weight in WEIGHTS.items():
        CellMaterials.facet_stabilisation = weight
        out = results["weights"][name] = {"static": [static(comm, n, s) for s in "AB" for n in (10, 13, 40, 160)]}
        for scheme in "AB":
            rows = [dynamic(comm, n, scheme) for n in args.meshes]
            out[f"dynamic_{scheme}"] = {"rows": rows, "order_R": orders(rows, "R_error"),
                                        "order_T": orders(rows, "T_error"), "order_l2": orders(rows, "stress_l2_error_rel")}
    CellMaterials.facet_stabilisation = HARMONIC
    if comm.rank == 0:
        text = json.dumps(results, indent=1)
        print(text)
        if args.out:
            with open(args.out, "w") as f:
                f.write(text + "\n")


if __name__ == "__main__":
    main()
