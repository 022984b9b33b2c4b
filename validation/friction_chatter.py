"""Friction on fine contact meshes (docs/theory.md, "Friction on rigid obstacles"): the bound
mu N_f of the step's own normal impulse ("instantaneous", the law before its lag) opens the
contact at the mesh scale and falls short of mu N; the law's lagged bound mu Ntilde_f
(contact/friction.py) delivers mu N.

- The block of validation/friction_slide.py on a 30 degree slope at mu = 0.3 (from rest at zero
  height, scheme A) on 16 x 8, 32 x 16 and 64 x 32 squares, with the law and the instantaneous
  bound, and at mu = 1e-9 (the law called, its impulses negligible: the frictionless contact):
  the acceleration against g (sin t - mu cos t); over the last half of the run (0.3 - 0.6 s) the
  fraction of the base's facet-steps in contact (normal impulse N_f > 0), the spread of the base
  cells' velocities along the slope about their mean, the friction delivered along the slide over
  mu sum N_f^+, and how the bound used (sum over facets and steps) splits: at the Coulomb limit,
  stuck (the stick impulse inside the set K_f), held back by the half-space tau . w <= 0 (the
  cell's free velocity v^{n+3/2,free} opposite to its velocity over the step w: it would
  reverse), and the part on facets out of contact (N_f <= 0: the lagged bound's decay).
- On 32 x 16: mu = 0.1 and 0.2; mu = 0.3 with a quarter of the time step (both bounds); the law
  with other lags ("lag X": T_f = X h_f / c_f, X = 0.5 and 8; the law's is 2) and with its
  friction only on the facets in contact ("in contact", also on 64 x 32). The diagnostic
  replacements of the law (not energy-consistent, for the diagnosis only): a friction -mu N_f e_x
  on every facet in contact, whatever the cell's velocity (no stick/slip decision, no half-space),
  given to the cell as the law does or through the facet's free reconstruction (R_f^T tau, the
  rows of the normal reaction); the instantaneous law moved to the facet (``Recorded.facet_law``)
  on the three meshes; a friction -mu e_x times the weight's share of each facet (m g cos t over
  the number of base facets), in contact or not ("constant": no dependence on N_f); the bound mu
  times a running mean of N_f^+ over k steps ("memory k": Nt += (N_f^+ - Nt) / k, on every facet,
  in contact or not), k = 10 and 50 (and 10 on 64 x 32).
- The disc's oblique impact of validation/oblique_impact.py (psi1 = 30, mu = 0.3, h_min =
  0.002 m, V_n = 0.01 m/s) with the law, the instantaneous bound, "in contact", "memory 10" and
  at mu = 1e-9: -dv_t / (mu dv_n), the facets in contact per step of the contact, and the holes
  (facets out of contact between two in contact); the law and the instantaneous bound on the
  finest mesh of the validation (h_min = 0.0005 m, V_n = 0.001 m/s).
- The continuum: steady sliding of an elastic half-plane (plane strain, nu = 0.3) on a rigid flat
  with Coulomb friction, u_n = 0 and sigma_nt = -+ mu sigma_nn on the surface: the smallest mu
  with a growing surface wave exp(i k (x - xi c_s t)), Im xi > 0 (decaying into the body).

    .venv/bin/python validation/friction_chatter.py --out docs/validation/friction_chatter.json
    .venv/bin/python validation/friction_chatter.py --quick --out OUT.json   # the block on 16 x 8, mu = 0.3
                                                                             # (law, instantaneous) and 1e-9;
                                                                             # the continuum

Writes the JSON and the Markdown page next to it. One process.
"""

import argparse
import json
import pathlib
import sys
import time

import numpy as np
from scipy.optimize import fsolve

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import friction_slide  # noqa: E402
import oblique_impact  # noqa: E402

from dolfinx_dem.contact.friction import LAG, STICK_ROUNDING, CellFriction  # noqa: E402
from dolfinx_dem.contact.rigid import RigidContact  # noqa: E402
from dolfinx_dem.memm import MEMM  # noqa: E402

NU = 0.3


class Recorded(CellFriction):
    """The law (``replace`` None), or a diagnostic replacement, recording per step each facet's N_f
    and its cell's w_c, free velocity and tau_f along x (tau_f: the law's only)."""

    def __init__(self, base: CellFriction, replace: str | None = None, contact=None):
        self.__dict__.update(base.__dict__)
        self.replace, self.contact, self.log = replace, contact, []
        if replace is not None and replace.startswith("lag"):  # "lag X": T_f = X h_f / c_f
            self.lag = self.lag * float(replace.split()[1]) / LAG
        self.mean, self.share = None, 0.0  # "memory k": the running mean of N_f^+; "constant": m g cos t / n
        if contact is not None:  # the x rows (the floor's tangent) of the own facets' free reconstruction
            R = contact._R_free
            self.rows = (R if isinstance(R, np.ndarray) else R.toarray())[: 2 * contact.num_own: 2]

    def apply(self, normal, state, impulse):
        dofs = self.dofs.ravel()
        _, w, free, _ = (a.reshape(-1, self.d) for a in state.velocities(dofs, impulse))
        before = impulse.array[dofs].copy()
        dissipation, bound = 0.0, np.full(len(normal), np.nan)  # the bound on |tau_f|: the law's and its variants'
        if self.replace is None or self.replace.startswith("lag"):  # the law (its lag LAG, or the one given)
            bound = self.mu * self.lagged(normal, state.dt) * state.dt
        elif self.replace == "in contact":  # the law, its friction only on the facets in contact (N_f > 0)
            bound = np.where(normal > 0, self.mu * self.lagged(normal, state.dt) * state.dt, 0.0)
        elif self.replace == "instantaneous":  # the bound mu N_f^+ of the same step (no lag)
            bound = self.mu * np.maximum(normal, 0.0)
        elif self.replace.startswith("memory"):  # the bound from the running mean of N_f^+ over k steps
            self.mean = np.maximum(normal, 0.0) if self.mean is None else self.mean
            self.mean += (np.maximum(normal, 0.0) - self.mean) / float(self.replace.split()[1])
            bound = self.mu * self.mean
        elif self.replace == "constant":  # -mu e_x times the weight's share of each facet, in contact or not
            impulse.array[dofs[::2]] -= self.mu * self.share * state.dt
        elif self.replace == "facet law":
            dissipation = self.facet_law(normal, state, impulse)
        else:  # -mu N_f e_x on the facets in contact
            tau = -self.mu * np.maximum(normal, 0.0)
            if self.replace == "cell":
                impulse.array[dofs[::2]] += tau
            else:
                self.contact.scatter.add(self.rows.T @ tau, impulse)
        if not np.isnan(bound).any():
            dissipation = self.bounded(bound, state, impulse)
        tau = (impulse.array[dofs] - before).reshape(-1, self.d)
        self.log.append(np.c_[normal, w[:, 0], free[:, 0], tau[:, 0], bound])
        return dissipation

    def facet_law(self, normal, state, impulse) -> float:
        """The law at the facet (one process): slip w_f = R_f v^{n+1/2} . e_x, impulse R_f^T e_x tau_f,
        the stick impulse with the facet's effective mass (R_f M^-1 R_f^T)^-1, the facets one after
        the other (Gauss-Seidel), each seeing the impulses before."""
        patch = self.contact.scatter.dofs
        v_prev, v_flight, v_free, mass = state.velocities(patch, impulse)
        v_free, total, dissipation = v_free.copy(), np.zeros(len(patch)), 0.0
        for f in np.flatnonzero(normal > 0):
            row = self.rows[f]
            w, tau = row @ v_flight, -0.5 * (row @ v_free) / (row @ (row / mass))
            rounding = STICK_ROUNDING * (np.abs(row) @ (np.abs(v_prev) + np.abs(v_flight) + np.abs(v_free)))
            if abs(w) > rounding and tau * w > 0:
                tau = 0.0
            tau = float(np.clip(tau, -self.mu[f] * normal[f], self.mu[f] * normal[f]))
            v_free += 2.0 * row / mass * tau
            total += row * tau
            dissipation += -w * tau
        impulse.array[patch] += total
        return dissipation


def block(mu: float, nx: int, cfl: float = 0.5, replace: str | None = None) -> dict:
    start = time.perf_counter()
    t = np.radians(30.0)
    problem = friction_slide.block(mu, [friction_slide.G * np.sin(t), -friction_slide.G * np.cos(t)], nx)
    dem, contact = problem.dem, problem.contacts[0]
    contact.friction = Recorded(contact.friction, replace, contact)
    contact.friction.share = friction_slide.MASS * friction_slide.G * np.cos(t) / contact.num_own
    stepper = MEMM(problem, cfl * dem.stable_time_step())
    stepper.initialise(dem.create_vector(), dem.create_vector())
    times, mean = [], []
    for _ in range(round(0.6 / stepper.dt)):
        diag = stepper.step()
        times.append(diag.t)
        mean.append(diag.momentum[0] / friction_slide.MASS)
    times, mean, log = np.array(times), np.array(mean), np.array(contact.friction.log)
    late = times > 0.1
    a = np.polyfit(times[late], mean[late], 1)[0]
    exact = friction_slide.G * (np.sin(t) - mu * np.cos(t))
    half = log[len(log) // 2:]
    normal, w, free, tau, bound = (half[..., k] for k in range(5))
    touching = normal > 0
    acting = bound > 0
    limit = acting & (np.abs(tau) >= (1 - 1e-9) * bound)
    reversing = acting & ~limit & (w * free < 0)
    stuck = acting & ~limit & ~reversing
    return {"mu": mu, "nx": nx, "cfl": cfl, "law": replace or "law", "dt": stepper.dt,
            "acceleration": float(a), "exact": float(exact), "relative_error": float(a / exact - 1),
            "in_contact": float(touching.mean()),
            "velocity_spread": float((w - w.mean(axis=1, keepdims=True)).std()),
            "delivered": float(-tau.sum() / (mu * np.maximum(normal, 0.0).sum())),
            **({} if np.isnan(bound).any() else {  # the split of the bound used (the law and its variants)
                "bound_at_limit": float(bound[limit].sum() / bound.sum()),
                "bound_stuck": float(bound[stuck].sum() / bound.sum()),
                "bound_reversing": float(bound[reversing].sum() / bound.sum()),
                "bound_out_of_contact": float(bound[~touching].sum() / bound.sum())}),
            "wall_time_s": time.perf_counter() - start}


def impact(mu: float, replace: str | None = None, h_min: float = 0.002, vn: float = 0.01) -> dict:
    """The disc's gross-slip impact (psi1 = 30) with the law or ``replace`` (``Recorded``): its
    tangential impulse over mu N and its contact facets per step."""
    start = time.perf_counter()
    logs = []

    class Recording(RigidContact):
        def __init__(self, dem, obstacles):
            super().__init__(dem, obstacles)
            self.friction = Recorded(self.friction, replace, self)
            logs.append((self.friction, dem.geometry.cell_centres[self.cells[: self.num_own], 0]))

    oblique_impact.RigidContact = Recording
    try:
        out = oblique_impact.impact(2, 30.0, mu, min(0.01, 5 * h_min), h_min, 0.5, vn)
    finally:
        oblique_impact.RigidContact = RigidContact
    friction, x = logs[0]
    touching = np.array(friction.log)[..., 0][:, np.argsort(x)] > 0
    steps = touching.any(axis=1)
    first = np.argmax(touching, axis=1)
    last = touching.shape[1] - 1 - np.argmax(touching[:, ::-1], axis=1)
    holes = (last - first + 1 - touching.sum(axis=1))[steps]
    return {"mu": mu, "law": replace or "law", "h_min": h_min, "vn": vn, "tangential_ratio": out["tangential_ratio"],
            "contact_steps": int(steps.sum()),
            "facets_in_contact": float(touching[steps].sum(axis=1).mean()),
            "largest_in_contact": int(touching.sum(axis=1).max()),
            "steps_with_holes": int((holes > 0).sum()), "holes": float(holes.mean()),
            "wall_time_s": time.perf_counter() - start}


def growing_wave(mu: float) -> float:
    """The largest Im xi of the surface waves of the half-plane sliding on a rigid flat (module
    docstring), 0 if none grows: the roots of
    i p xi^2 + m (-(cp^2 - 2) xi^2 / cp^2 + 2 p (p - q)) = 0, m = +-mu, p = sqrt(1 - xi^2/cp^2),
    q = sqrt(1 - xi^2) (Re p, Re q > 0), in units k = c_s = mu_s = rho = 1."""
    cp2 = 2 * (1 - NU) / (1 - 2 * NU)

    def root(z):
        r = np.sqrt(z + 0j)
        return -r if r.real < 0 else r

    def f(xi, m):
        p, q = root(1 - xi**2 / cp2), root(1 - xi**2)
        return 1j * p * xi**2 + m * (-(cp2 - 2) * xi**2 / cp2 + 2 * p * (p - q))

    largest = 0.0
    for m in (mu, -mu):
        for re in np.linspace(-3.0, 3.0, 25):
            for im in np.linspace(0.01, 2.0, 10):
                s, _, ier, _ = fsolve(lambda x, m=m: [f(x[0] + 1j * x[1], m).real, f(x[0] + 1j * x[1], m).imag],
                                      [re, im], full_output=True)
                xi = s[0] + 1j * s[1]
                if ier == 1 and abs(f(xi, m)) < 1e-10 and abs(xi) > 1e-4:
                    largest = max(largest, xi.imag)
    return float(largest) if largest > 1e-6 else 0.0


def page(results: dict) -> str:
    lines = ["# Friction on fine contact meshes: the instantaneous bound opens the contact, the lagged one gives mu N",
             "",
             f"Written by `validation/friction_chatter.py` (one process). Command: `{results['command']}`.", "",
             "The cases and the measures: the script's docstring. The acceleration fitted over 0.1 - 0.6 s, the "
             "other columns over 0.3 - 0.6 s.", "",
             "## The block on a 30 degree slope", "",
             "| mu | squares | dt / bound | law | acceleration error | facet-steps in contact | cells' velocity "
             "spread (m/s) | friction / mu N | bound: at the limit | stuck | would reverse | out of contact |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["block"]:
        split = (f"| {r['delivered']:.3f} | - | - | - | - |" if "bound_stuck" not in r else
                 f"| {r['delivered']:.3f} | {r['bound_at_limit']:.3f} | {r['bound_stuck']:.3f} | "
                 f"{r['bound_reversing']:.3f} | {r['bound_out_of_contact']:.3f} |")
        lines.append(f"| {r['mu']:g} | {r['nx']} x {r['nx'] // 2} | {r['cfl']:g} | {r['law']} | "
                     f"{100 * r['relative_error']:+.2f} % | {r['in_contact']:.3f} | {r['velocity_spread']:.3f} " + split)
    if results["impact"]:
        lines += ["", "## The disc's oblique impact (psi1 = 30)", "",
                  "| mu | h_min (m) | V_n (m/s) | law | -dv_t / (mu dv_n) | contact steps | facets in contact (mean) "
                  "| largest | steps with holes | holes (mean) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["impact"]:
        ratio = f"{r['tangential_ratio']:.4f}" if r["mu"] > 1e-6 else "-"
        lines.append(f"| {r['mu']:g} | {r['h_min']:g} | {r['vn']:g} | {r['law']} | {ratio} | {r['contact_steps']} | "
                     f"{r['facets_in_contact']:.2f} | {r['largest_in_contact']} | {r['steps_with_holes']} | "
                     f"{r['holes']:.2f} |")
    lines += ["", "## The continuum (plane strain, nu = 0.3)", "",
              "| mu | largest growth Im xi (0: steady sliding stable) |", "|---|---|"]
    lines += [f"| {mu} | {g:.4f} |" for mu, g in results["continuum"].items()]
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, required=True)
    parser.add_argument("--quick", action="store_true", help="the block at mu = 0.3 (the law, the instantaneous bound) and 1e-9 on 16 x 8 squares, "
                        "the continuum at mu = 0.3 and 1.2")
    args = parser.parse_args()
    results = {"command": "validation/friction_chatter.py" + (" --quick" if args.quick else ""),
               "block": [], "impact": [], "continuum": {}}
    if args.quick:
        results["block"] = [block(0.3, 16), block(0.3, 16, replace="instantaneous"), block(1e-9, 16)]
        results["continuum"] = {str(mu): growing_wave(mu) for mu in (0.3, 1.2)}
    else:
        for replace in (None, "instantaneous"):
            for nx in (16, 32, 64):
                results["block"].append(block(0.3, nx, replace=replace))
        for mu in (0.1, 0.2):
            results["block"].append(block(mu, 32))
        results["block"].append(block(1e-9, 32))
        for replace in (None, "instantaneous"):
            results["block"].append(block(0.3, 32, cfl=0.125, replace=replace))
        for replace in ("lag 0.5", "lag 8", "in contact"):
            results["block"].append(block(0.3, 32, replace=replace))
        results["block"].append(block(0.3, 64, replace="in contact"))
        results["block"].append(block(0.3, 32, replace="cell"))
        results["block"].append(block(0.3, 32, replace="facet"))
        for nx in (16, 32, 64):
            results["block"].append(block(0.3, nx, replace="facet law"))
        results["block"].append(block(0.3, 32, replace="constant"))
        for replace, nx in (("memory 10", 32), ("memory 50", 32), ("memory 10", 64)):
            results["block"].append(block(0.3, nx, replace=replace))
        results["impact"] = [impact(0.3), impact(0.3, "instantaneous"), impact(1e-9), impact(0.3, "in contact"),
                             impact(0.3, "memory 10"), impact(0.3, h_min=0.0005, vn=0.001),
                             impact(0.3, "instantaneous", h_min=0.0005, vn=0.001)]
        results["continuum"] = {str(mu): growing_wave(mu) for mu in (0.3, 0.5, 0.9, 1.0, 1.1, 1.2, 1.5)}
    args.out.write_text(json.dumps(results, indent=1))
    args.out.with_suffix(".md").write_text(page(results))


if __name__ == "__main__":
    main()
