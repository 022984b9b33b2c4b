"""Oblique impact of an elastic disc (2D) or ball (3D) on a rigid wall with Coulomb friction
(contact/friction.py; issue 35, validation 3), against the rigid-body impulse law and the elastic
theory of Maw, Barber and Fawcett (Wear 38 (1976) 101-114; J. Lubr. Technol. 103 (1981) 74-80).

The body (R = 0.1 m, E = 100 Pa, nu = 0.3, rho = 100 kg/m^3, so c = sqrt(E/rho) = 1 m/s; scheme A;
plane strain in 2D) starts a gap of 0.005 R above the wall y = 0 (2D) or z = 0 (3D), without
spin, at the normal speed V_n (``--vn``, 0.001 m/s: V_n / c = 0.001, small strain and a small
rotation during the contact, which the small-displacement kinematics needs: the page's speed
table) and a tangential speed V_t = psi1 mu V_n along x; the facets of its lower half are the
wall's candidates, friction mu. The mesh has size h = 5 h_min (at most 0.01 m in 2D, 0.025 m in
3D), refined to h_min within 2 h_min + 0.3 R of the first contact point. The run
ends 0.25 contact durations after the last facet left the wall. Measured from the body's rigid
motion after the impact: the centre of mass velocity (the total momentum over the mass, exact)
and the spin omega = I^-1 L, L = sum_c m_c r_c x v_c about the centre of mass and I the cells'
inertia tensor (averaged over the steps after the impact: the body vibrates). With the rebound
normal speed e V_n:

- gross slip (psi1 large): the rigid-body Coulomb impulse gives dv_t = -mu dv_n whatever e, and
  the spin change dw R = (m R^2 / I) |dv_t|, m R^2 / I = 2 for the disc, 5/2 for the ball;
- the normalised incidence psi1 = V_t / (mu V_n) and the contact point's normalised rebound
  psi2 = v_cp' / (mu e V_n) (v_cp' its tangential velocity after the impact, + along the
  incidence), and the normalised spin Omega = |omega'| R / (mu V_n): Chung and Ooi's benchmark
  test 5 (Granular Matter 13 (2011) 643-656), Maw's angles psi_Maw = kappa psi with kappa =
  2 (1 - nu) / (2 - nu) (the Mindlin tangential-to-normal stiffness ratio). The rigid body in
  gross slip: psi2 = (psi1 - (1 + e) k) / e, k = 1 + m R^2 / I; below, rigid theory sticks
  (psi2 = 0, rolling); Maw's elastic theory (3D, e = 1) has the contact point spring back
  (psi2 < 0, at least -1 / kappa, where gross slip sets in: psi1 = 7 - 1 / kappa).
- at every step: the balance E + D - W drift over the largest mechanical energy, and the
  smallest increment of the dissipation D (0 or more).

    .venv/bin/python validation/oblique_impact.py --out docs/validation/oblique_impact.json
    .venv/bin/python validation/oblique_impact.py --quick --out OUT.json   # one 2D gross-slip impact

The disc: gross slip on four contact meshes, on the finest with mu = 0.1 and 0.2 too, at other
speeds, and a sweep of psi1; the ball: gross slip on two contact meshes and a sweep on the first.
It writes the JSON, the Markdown page and the figure next to it (``--out``'s stem + .md, .png).
One process.
"""

import argparse
import json
import pathlib
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.contact import HalfSpace, RigidContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem

R, VN, GAP, NU = 0.1, 0.01, 0.0005, 0.3
MATERIAL = ElasticMaterial(E=100.0, nu=NU, rho=100.0)
KAPPA = 2 * (1 - NU) / (2 - NU)  # Mindlin's tangential / normal contact stiffness (Maw's normalisation)
K = {2: 3.0, 3: 3.5}  # k = 1 + m R^2 / I of the rigid disc and ball
H = {2: 0.01, 3: 0.025}  # the mesh size away from the contact (m)


def impact(d: int, psi1: float, mu: float, h: float, h_min: float, cfl: float = 0.5, vn: float = VN) -> dict:
    """One impact at the normalised incidence psi1 = V_t / (mu V_n) (module docstring)."""
    start = time.perf_counter()
    centre = [0.0] * (d - 1) + [R + GAP]
    contact_point = [0.0] * d
    create = meshes.create_discs if d == 2 else meshes.create_balls
    mesh, _, tags = create(MPI.COMM_WORLD, [(centre, R)], h, refine=(contact_point, h_min, 2 * h_min + 0.3 * R))
    dem = DEMDiscretisation(mesh, MATERIAL, "A")
    boundary = tags.find(1)
    lower = boundary[dem.geometry.facet_centres[boundary, d - 1] <= R]
    normal = np.eye(d)[d - 1]
    contact = RigidContact(dem, [HalfSpace(contact_point, normal, lower, friction=mu)])
    stepper = MEMM(DEMProblem(dem, [contact]), cfl * dem.stable_time_step())
    v0 = np.zeros(d)
    v0[0], v0[d - 1] = psi1 * mu * vn, -vn
    v = dem.create_vector()
    v.array.reshape(-1, d)[:] = v0
    first = stepper.initialise(dem.create_vector(), v)
    m = dem.mass.array_r[::d]
    mass = m.sum()
    x0 = dem.geometry.cell_centres[: dem.n_owned, :d]

    def spin() -> np.ndarray:
        """omega = I^-1 L about the centre of mass (the midpoint velocities of the step)."""
        vbar = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, d)
        x = x0 + stepper.u.array_r.reshape(-1, d)
        r = x - m @ x / mass
        if d == 2:
            return np.array([(m * (r[:, 0] * vbar[:, 1] - r[:, 1] * vbar[:, 0])).sum() / (m * (r**2).sum(axis=1)).sum()])
        inertia = np.einsum("c,cij->ij", m, (r**2).sum(axis=1)[:, None, None] * np.eye(3) - r[:, :, None] * r[:, None, :])
        return np.linalg.solve(inertia, (m[:, None] * np.cross(r, vbar)).sum(axis=0))

    balance, scale, dissipation, omegas = [], first.mechanical, [0.0], []
    touched = left = None
    steps = 0
    while left is None or steps < left + 0.25 * (left - touched):
        diag = stepper.step()
        steps += 1
        balance.append(diag.balance - first.balance)
        dissipation.append(diag.dissipation)
        scale = max(scale, diag.mechanical)
        on = (contact.own_gaps(stepper.u) < 0).any()
        if on:
            touched, left, omegas = touched or steps, None, []
        elif touched is not None:
            left = left or steps
            omegas.append(spin())
        if steps > 200000:
            raise RuntimeError("the body did not leave the wall in 200000 steps")
    # the rigid motion after the impact: the momentum is constant (no force), omega averaged
    velocity = diag.momentum / mass
    omega = np.mean(omegas, axis=0)
    dv = velocity - v0
    e = velocity[d - 1] / vn
    # the contact point's velocity v + omega x (-R n), tangential part along x
    arm = -R * normal
    cp = velocity[0] + (omega[0] * (-arm[1]) if d == 2 else np.cross(omega, arm)[0])
    inertia_rigid = 1 / (K[d] - 1)  # I / (m R^2)
    return {"d": d, "psi1": psi1, "mu": mu, "vn": vn, "h": h, "h_min": h_min, "cells": dem.geometry.num_cells_global,
            "steps": steps, "dt": stepper.dt, "contact_steps": left - touched,
            "contact_duration": (left - touched) * stepper.dt, "restitution": float(e),
            "tangential_ratio": float(-dv[0] / (mu * dv[d - 1])),  # 1 in gross slip
            "spin_ratio": float(np.linalg.norm(omega) * R * inertia_rigid / abs(dv[0])),  # 1: the rigid body's
            "tangential_restitution": float(velocity[0] / v0[0]),
            "psi2": float(cp / (mu * e * vn)), "Omega": float(np.linalg.norm(omega) * R / (mu * vn)),
            "omega_spread": float(np.std([np.linalg.norm(w) for w in omegas]) / np.linalg.norm(omega)),
            "balance_error": float(np.abs(balance).max() / scale),
            "min_dissipation_increment": float(np.diff(dissipation).min()),
            "dissipation": float(dissipation[-1]), "wall_time_s": time.perf_counter() - start}


#: Chung and Ooi's benchmark test 5 (Granular Matter 13 (2011) 643-656; a sphere, e = 1, mu = 0.3):
#: the finite-element points of their figure, psi1 = V_t / (mu V_n) against psi2 = v_cp' / (mu V_n')
#: and Omega = |omega'| R / (mu V_n), as digitised in the Kratos Multiphysics DEMApplication's
#: benchmark data (benchmark5_graph1.dat, benchmark5_graph2.dat, series "FEM"), rounded to 0.01.
REFERENCE_3D = {
    "psi2": [(0.01, -0.03), (0.27, -0.03), (0.59, -0.03), (0.88, -0.08), (1.19, -0.21), (1.55, -0.37),
             (1.92, -0.63), (2.31, -0.95), (2.79, -1.25), (3.32, -1.52), (3.97, -1.72), (4.76, -1.71),
             (5.76, -1.20), (7.12, 0.13), (9.12, 2.15), (12.36, 5.43), (12.96, 6.01)],
    "Omega": [(0.01, 0.0), (0.32, 0.19), (0.60, 0.41), (0.89, 0.67), (1.18, 0.98), (1.53, 1.36), (1.90, 1.79),
              (2.28, 2.32), (2.76, 2.86), (3.30, 3.44), (3.89, 4.04), (4.69, 4.57), (5.66, 4.94), (7.03, 4.94),
              (9.04, 4.97), (12.34, 4.97), (18.80, 4.97)],
}


def rigid(k: float, e: float, psi1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid body's psi2 and Omega (k = 1 + m R^2 / I, restitution e): sliding throughout
    for psi1 >= (1 + e) k, else the contact point stops (rolling, psi2 = 0)."""
    slide = psi1 >= (1 + e) * k
    psi2 = np.where(slide, (psi1 - (1 + e) * k) / e, 0.0)
    omega = np.where(slide, (k - 1) * (1 + e), (k - 1) / k * psi1)
    return psi2, omega


def chart(results: dict, path: pathlib.Path) -> None:
    """psi2 and Omega against psi1, each scaled by the rigid body's gross-slip onset (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.linspace(0.0, 2.2, 400)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key in ((axes[0], "psi2"), (axes[1], "Omega")):
        for d, label, style in ((2, "DEM disc (2D)", "o-"), (3, "DEM ball (3D)", "^-")):
            rows, k = results[f"sweep{d}d"], K[d]
            if rows:
                scale = 2 * k if key == "psi2" else 2 * (k - 1)
                ax.plot([r["psi1"] / (2 * k) for r in rows], [r[key] / scale for r in rows], style, label=label)
        ref = np.array(REFERENCE_3D[key])
        ax.plot(ref[:, 0] / 7, ref[:, 1] / (7 if key == "psi2" else 5), "s", mfc="none",
                label="sphere, FEM (Chung & Ooi 2011, test 5)")
        ax.plot(x, np.maximum(x - 1, 0.0) if key == "psi2" else np.minimum(x, 1.0), "k--", lw=1,
                label="rigid body, e = 1")
        ax.set(xlabel="psi1 / (2k):  V_t / (2 k mu V_n),  k = 1 + m R^2 / I", xlim=(0, 2.2))
        ax.grid(True, alpha=0.3)
    onset = (7 - 1 / KAPPA) / 7
    axes[0].axvline(onset, color="grey", lw=0.8, ls=":", label=f"Maw et al.: sphere's gross slip from here (nu = {NU:g})")
    axes[0].set(ylabel="psi2 / (2k): contact point's rebound", ylim=(-0.5, 1.2),
                title="tangential rebound of the contact point")
    axes[1].set(ylabel="Omega / (2 (k - 1)): spin", title="spin after the impact")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Oblique impact on a rigid wall, mu = {results['mu']:g}, V_n / c = {results['vn']:g}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _row(r: dict) -> str:
    return (f"| {r['h']:g}, {r['h_min']:g} | {r['cells']} | {r['mu']:g} | {r['psi1']:g} | {r['vn']:g} | "
            f"{r['dt']:.3g} | "
            f"{r['contact_steps']} | {r['restitution']:.4f} | {r['tangential_ratio']:.5f} | {r['spin_ratio']:.4f} | "
            f"{r['balance_error']:.1e} | {r['min_dissipation_increment']:.1e} | {r['wall_time_s']:.1f} |")


HEAD = ("| h, h_min (m) | cells | mu | psi1 | V_n (m/s) | dt (s) | contact steps | e | -dv_t / (mu dv_n) | spin / rigid | "
        "balance error | smallest D increment | wall (s) |")


GROSS_TEXT = """In gross slip the disc's tangential impulse is mu times the normal one, the rigid body's Coulomb
impulse, on every contact mesh, friction coefficient, approach speed and time step of these tables (to
1.1e-7 or better). The spin misses the
rigid disc's (for the measured impulse) by an amount that shrinks with the approach speed, not with
the mesh (the speed table): the DEM's kinematics is small-displacement, and the disc's linearised
rotation during the contact, about theta = omega T / 2, moves the contact's reference points off the
vertical through the centre, a torque of about N theta R against the friction's mu N R.

With the bound mu N_f of each step's own normal impulse (the law before its lag) it was not so: 0.82
mu N on the finest mesh at mu = 0.3 (0.83 with the smaller step), 0.92 at mu = 0.2, 0.85 and 0.91 at
V_n = 0.01 and 0.003 m/s, friction opening the contact at the mesh scale (friction_chatter.md); the
lagged bound of the law (docs/theory.md, Friction on rigid obstacles) keeps the contact closed. The
balance and the sign of every dissipation increment hold throughout."""

BALL_TEXT = """The ball slides by the Coulomb impulse too (-dv_t / (mu dv_n) within a few 1e-5 of 1) and spins as
the rigid ball within 1.2 to 1.5 %. Its normal restitution exceeds 1 by less than 1 %, growing with the
spin (the sweep's e): with the small-displacement kinematics a linearised rotation by theta is free of
strain but stretches the body radially by about theta^2 R / 2, against the wall (a reading)."""

SWEEP_TEXT = """The rigid body (dashed) rolls off the wall below the gross-slip onset psi1 = (1 + e) k, k = 1 + m R^2 / I
(3 disc, 7/2 ball), its contact point at rest (psi2 = 0). The elastic bodies do what Maw, Barber and
Fawcett's theory predicts for a sphere: the contact point springs back (psi2 < 0) at moderate incidence,
most near 2/3 of the onset, the spin exceeds the rolling value, and gross slip (-dv_t / (mu dv_n) = 1)
sets in near the rigid onset (their onset for the sphere, psi1 = 7 - 1 / kappa = 5.79 at nu = 0.3, the
dotted line), after which psi2 and Omega follow the rigid body's lines.

The reference: the finite-element points for a sphere of Chung and Ooi's benchmark test 5 (Granular
Matter 13 (2011) 643-656; mu = 0.3, e = 1), as digitised in the Kratos Multiphysics DEMApplication's
benchmark data (benchmark5_graph1.dat and benchmark5_graph2.dat, series "FEM"), rounded to 0.01, with
this page's normalisation: psi1 = V_t / (mu V_n), psi2 = v_cp' / (mu V_n'), Omega = R |omega'| / (mu V_n).
The ball's table interpolates them at its psi1 (within their range). Maw, Barber and Fawcett's own
curves (their figures) were not available as numbers. The ball follows the reference from psi1 = 3 on,
through the spring-back and the onset of gross slip; below, its contact zone (a few cells across on
this coarse mesh) cannot resolve the stick zone and its micro-slip annulus, and the ball's contact
point springs back less than the reference's.

No closed form holds for a disc: its line-contact compliances depend (logarithmically) on the body's
size, so there is no constant tangential-to-normal ratio kappa. The disc's curve is compared by its
shape, both axes scaled by the rigid body's onset 2k: it nearly coincides with the sphere's. A reading,
not a theory: the plane-strain Flamant kernels of a normal and a tangential line load have the same
coefficient 2 (1 - nu^2) / (pi E), so the disc's compliance ratio is about 1 and its k times that
ratio, 3, is near the sphere's 7/2 kappa = 2.88 (nu = 0.3), the parameter that sets the shape of
Maw's curves."""


def page(results: dict, png: str) -> str:
    lines = ["# Oblique impact of an elastic disc and ball on a rigid wall with Coulomb friction", "",
             f"Written by `validation/oblique_impact.py` (one process). Command: `{results['command']}`.", "",
             "The bodies, the measures and the theory: the script's docstring. Scheme A, CFL "
             f"{results['cfl']:g} of the bound, mu = {results['mu']:g} unless a table says otherwise, V_n / c = "
             f"{results['vn']:g}. -dv_t / (mu dv_n): the tangential over mu times the normal change of the centre "
             "of mass velocity (1: the rigid-body Coulomb impulse of gross slip); spin / rigid: |omega'| R I_rigid / "
             "(m R^2 |dv_t|), I_rigid = m R^2 / 2 (disc), 2/5 m R^2 (ball) (1: the rigid body's spin for the "
             "measured tangential impulse); balance error: max |(E + D - W) - (E + D - W)_0| over the largest "
             "mechanical energy, at every step.", ""]
    for d, name in ((2, "Disc (2D, plane strain)"), (3, "Ball (3D)")):
        sections = [("gross slip under refinement", results[f"gross{d}d"], GROSS_TEXT if d == 2 else BALL_TEXT),
                    ("gross slip on the finest mesh against the friction coefficient", results.get(f"friction{d}d"), ""),
                    ("gross slip on the finest mesh with a smaller time step", results.get(f"cfl{d}d"), ""),
                    ("gross slip against the approach speed (small-displacement kinematics)", results.get(f"speeds{d}d"),
                     "")]
        if not any(rows for _, rows, _ in sections) and not results[f"sweep{d}d"]:
            continue
        lines += [f"## {name}", ""]
        for title, rows, text in sections:
            if rows:
                lines += [f"### {title[0].upper() + title[1:]}", "", HEAD, "|---" * 13 + "|"]
                lines += [_row(r) for r in rows] + [""] + ([text, ""] if text else [])
        rows = results[f"sweep{d}d"]
        if rows:
            lines += ["### Against the normalised incidence", "",
                      "| psi1 | e | -dv_t / (mu dv_n) | tangential restitution v_t' / V_t | psi2 | rigid psi2 | Omega | "
                      "rigid Omega | " + ("sphere FEM psi2 | sphere FEM Omega | " if d == 3 else "")
                      + "balance error | smallest D increment |", "|---" * (12 if d == 3 else 10) + "|"]
            for r in rows:
                p2, om = rigid(K[d], r["restitution"], np.array(r["psi1"]))
                ref = ""
                if d == 3:  # the reference's points interpolated at psi1, within their range
                    points = (np.array(REFERENCE_3D[key]).T for key in ("psi2", "Omega"))
                    ref = "".join(f"{np.interp(r['psi1'], x, y):.2f} | " if x[0] <= r["psi1"] <= x[-1] else "- | "
                                  for x, y in points)
                lines.append(f"| {r['psi1']:g} | {r['restitution']:.4f} | {r['tangential_ratio']:.4f} | "
                             f"{r['tangential_restitution']:.4f} | {r['psi2']:.3f} | {float(p2):.3f} | "
                             f"{r['Omega']:.3f} | {float(om):.3f} | {ref}{r['balance_error']:.1e} | "
                             f"{r['min_dissipation_increment']:.1e} |")
            lines.append("")
    if results["sweep2d"] or results["sweep3d"]:
        lines += ["## Against the normalised incidence: the figure", "", f"![oblique impact]({png})", "", SWEEP_TEXT]
    return "\n".join(lines).rstrip("\n") + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mu", type=float, default=0.3)
    parser.add_argument("--vn", type=float, default=0.001, help="normal approach speed (m/s; c = 1 m/s)")
    parser.add_argument("--gross", type=float, default=30.0, help="psi1 of the gross-slip runs")
    parser.add_argument("--levels", type=float, nargs="*", default=[0.004, 0.002, 0.001, 0.0005],
                        help="h_min (m) of the disc's gross-slip runs; h = 5 h_min, at most 0.01")
    parser.add_argument("--levels3d", type=float, nargs="*", default=[0.005, 0.0035],
                        help="h_min (m) of the ball's gross-slip runs; h = 5 h_min, at most 0.025")
    parser.add_argument("--mus", type=float, nargs="*", default=[0.1, 0.2],
                        help="other friction coefficients for the disc's gross-slip run on the finest mesh")
    parser.add_argument("--cfls", type=float, nargs="*", default=[0.2],
                        help="other CFL numbers for the disc's gross-slip run on the finest mesh")
    parser.add_argument("--speeds", type=float, nargs="*", default=[0.01, 0.003, 0.0003],
                        help="other normal speeds for the disc's gross-slip run on the sweep's mesh")
    parser.add_argument("--sweep", type=float, nargs="*",
                        default=[0.5, 1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 15, 20], help="psi1 of the disc's sweep")
    parser.add_argument("--sweep-level", type=float, default=0.002, help="h_min of the disc's sweep (m)")
    parser.add_argument("--sweep3d", type=float, nargs="*", default=[1, 2, 3, 4, 5, 6, 7, 8, 10, 14],
                        help="psi1 of the ball's sweep, on the first of --levels3d")
    parser.add_argument("--cfl", type=float, default=0.5)
    parser.add_argument("--quick", action="store_true", help="one gross-slip impact of the disc on h_min = 0.004")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args()
    if args.quick:
        args.levels, args.levels3d, args.mus, args.cfls, args.speeds, args.sweep, args.sweep3d = [0.004], [], [], [], [], [], []
    if args.sweep3d and not args.levels3d:
        parser.error("--sweep3d runs on the first of --levels3d: give one")
    listed = {name: " ".join(f"{x:g}" for x in getattr(args, name)) for name in
              ("levels", "levels3d", "mus", "cfls", "speeds", "sweep", "sweep3d")}
    results = {"command": "validation/oblique_impact.py " + ("--quick" if args.quick else " ".join(
        [f"--mu {args.mu:g} --vn {args.vn:g} --gross {args.gross:g}"]
        + [f"--{name} {value}" for name, value in listed.items()]
        + [f"--sweep-level {args.sweep_level:g} --cfl {args.cfl:g}"])),
        "mu": args.mu, "vn": args.vn, "cfl": args.cfl, "nu": NU, "R": R}

    def run(d, psi1, h_min, vn=args.vn, mu=args.mu, cfl=args.cfl):
        out = impact(d, psi1, mu, min(H[d], 5 * h_min), h_min, cfl, vn)
        print(json.dumps(out), flush=True)
        return out

    results["gross2d"] = [run(2, args.gross, h) for h in args.levels]
    results["friction2d"] = [run(2, args.gross, args.levels[-1], mu=mu) for mu in args.mus]
    results["cfl2d"] = [run(2, args.gross, args.levels[-1], cfl=cfl) for cfl in args.cfls]
    results["speeds2d"] = [run(2, args.gross, args.sweep_level, v) for v in args.speeds]
    results["sweep2d"] = [run(2, p, args.sweep_level) for p in args.sweep]
    results["gross3d"] = [run(3, args.gross, h) for h in args.levels3d]
    results["sweep3d"] = [run(3, p, args.levels3d[0]) for p in args.sweep3d]
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    png = args.out.with_suffix(".png")
    if results["sweep2d"] or results["sweep3d"]:
        chart(results, png)
    args.out.with_suffix(".md").write_text(page(results, png.name))


if __name__ == "__main__":
    main()
