"""Coulomb friction on a rigid plane (contact/friction.py): an elastic block on a slope, against the
rigid-body law, and a block held by friction.

The block [0, 1] x [0, 0.5] m (E = 1e4 Pa, nu = 0.3, rho = 1 kg/m^3, plane strain, scheme A, a
"crossed" mesh of nx x nx/2 squares) lies on the plane y = 0 under gravity g = 10 m/s^2 tilted by
the slope's angle t, from rest at zero height (so it also vibrates normally, its weight
suddenly applied).

- Sliding (tan t > mu): the mean velocity along the slope against the rigid body's
  g (sin t - mu cos t) (a line fitted after 0.1 s, to 0.6 s); the spread of the bottom cells'
  velocity along the slope about the mean (the standard deviation of vbar - mean over the last
  half); the energy balance max |E + D - E0| over the largest mechanical energy (or D if larger);
  the smallest increment of D.
- Held (tan t < mu): the block starts in its frictionless static equilibrium under the normal
  part of gravity (``minimise_energy``), then the load along the slope is applied: how far the
  contact cells move along the plane after the first step, and the first step with a facet at
  the Coulomb limit.
- Rolling: a disc (R = 0.1 m, E = 1e6 Pa, mesh size h) settled on the plane by frictionless
  statics, launched at v0 = 0.05 m/s without spin, mu = 0.5: when its contact point stops
  slipping (the rigid-body slip v + omega R below 1 % of v0) against t* = v0 / (3 mu g), and its
  speed at t* against 2/3 v0 (the disc turns by a few mrad: small strain).
- 3D: a block [0, 1]^2 x [0, 0.5] on z = 0 (6 x 6 x 3 cubes of six tetrahedra), gravity tilted
  by 30 degrees towards a direction 30 degrees from x: its acceleration against the rigid law.
- The stable step: the sliding block (tan t = 0.577) run for 0.5 s at dt = f times the bound
  ``stable_time_step()``, f = 1, 1.04, ..., 1.16, without friction and with mu = 0.1 and 0.3:
  the largest f the stability monitor let complete.
- A ball (R = 0.1 m, E = 1e6 Pa, tetrahedra of size h) standing on z = 0 on one facet's centre
  (``ball``), settled by frictionless statics, launched at v0 = 0.05 m/s along x without spin,
  mu = 0.5: when its contact point stops slipping (as the disc's) against t* = 2 v0 / (7 mu g),
  its speed at t* and after it against 5/7 v0; the same against the rigid law with the lever of
  the contact cell's centre (on which friction acts); the balance and the smallest D increment at
  every step, the facets at the Coulomb limit.
- The 3D stable step: that ball over 2 t* at dt = f times the bound, f = 1, 1.01, ..., 1.08,
  without friction and with mu = 0.5: the monitor's verdict and the largest mechanical energy
  over the initial one; and the elastic operator's limit over the bound.

    .venv/bin/python validation/friction_slide.py --out docs/validation/friction.json
    .venv/bin/python validation/friction_slide.py --quick --out OUT.json   # mu = 0.1 on 16 x 8 squares,
                                                                           # the ball at h = 0.02 m
    .venv/bin/python validation/friction_slide.py --scheme B --out docs/validation/friction_scheme_b.json

``--scheme B`` (or ``AB``): the sliding block (mu = 0.1, 0.3 on 16 x 8 to 64 x 32 squares) and the
held block with scheme B candidates, each sliding run with the law (the spread bound) and with the
per-facet bound of scheme A; the sum of the facets' normal impulses' positive parts over their sum,
and the friction impulse over mu times the normal one; the 3D block (mu = 0.1, 0.3 on 6 x 6 x 3 and
12 x 12 x 6 cubes) with both bounds and with scheme A; the stable step (``stable_factor``, mu = 0,
0.1, 0.3 on the first mesh) and the disc (``roll``, h = 0.01, 0.005 m, both bounds; also its speed
and slip at 2 t*) with the same method. ``--quick``: mu = 0.3 on 16 x 8 squares, held at
tan t = 0.05, the 3D block at mu = 0.3 on 6 x 6 x 3 cubes (no stable step, no disc).

It writes the JSON and, next to it, the Markdown page (``--out``'s stem + .md). One process.
"""

import argparse
import json
import pathlib
import sys
import time

import numpy as np
from mpi4py import MPI

from dolfinx_dem import _compat, meshes
from dolfinx_dem.contact import HalfSpace, RigidContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import InstabilityError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.statics import minimise_energy

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import friction_slide_pages  # noqa: E402

R_DISC, V0 = 0.1, 0.05

G, MASS = 10.0, 0.5
BLOCK = ElasticMaterial(E=1e4, nu=0.3, rho=1.0)


def block(mu: float, gravity, nx: int, scheme: str = "A") -> DEMProblem:
    mesh, _, tags = meshes.create_rectangle(MPI.COMM_WORLD, [0.0, 0.0], [1.0, 0.5], [nx, nx // 2], "crossed")
    base = tags.find(meshes.YMIN)  # "AB": scheme A, scheme B on the candidates (method dem-AB)
    dem = DEMDiscretisation(mesh, BLOCK, scheme[0], body_force=list(BLOCK.rho * np.asarray(gravity)),
                            scheme_b_facets=base if scheme == "AB" else None)
    return DEMProblem(dem, [RigidContact(dem, [HalfSpace([0.0, 0.0], [0.0, 1.0], tags.find(meshes.YMIN),
                                                         friction=mu)])])


def run(mu: float, tan: float, nx: int, t_end: float, settled: bool, scheme: str = "A", per_facet: bool = False) -> dict:
    """The block (``block``); with ``per_facet`` scheme B's candidates take the bound of their own
    normal impulses, as scheme A's (the law before ``Spread``, for comparison)."""
    start = time.perf_counter()
    t = np.arctan(tan)
    problem = block(mu, [G * np.sin(t), -G * np.cos(t)], nx, scheme)
    dem, contact = problem.dem, problem.contacts[0]
    if per_facet and contact.friction is not None:
        contact.friction.spread = None
    u0 = (minimise_energy(block(0.0, [0.0, -G * np.cos(t)], nx, scheme), fixed_mean=[0]).u if settled
          else dem.create_vector())
    stepper = MEMM(problem, 0.5 * dem.stable_time_step())
    first = stepper.initialise(u0, dem.create_vector())
    cells = contact.cells[: contact.num_own]
    n = round(t_end / stepper.dt)
    times, mean, balance, dissipation = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    largest = first.mechanical
    bottom, bottom_x = np.empty((n, len(cells))), np.empty((n, len(cells)))
    first_slip = None
    normal = np.zeros(3)  # sum N_f^+, sum N_f over the facets and steps, the friction impulse along x
    late_sums = np.zeros(3)  # sum N_f, the friction impulse and the time after 0.1 s (the fit's window)
    for k in range(n):
        diag = stepper.step()
        impulse = contact._normal_impulse
        normal += [np.maximum(impulse, 0.0).sum(), impulse.sum(),
                   0.0 if contact.friction is None else -contact.friction.forces[0, 0] * stepper.dt]
        if diag.t > 0.1:
            late_sums += [impulse.sum(), 0.0 if contact.friction is None else -contact.friction.forces[0, 0]
                          * stepper.dt, stepper.dt]
        times[k], mean[k], balance[k], dissipation[k] = diag.t, diag.momentum[0] / MASS, diag.balance, diag.dissipation
        largest = max(largest, diag.mechanical)
        bottom[k] = stepper.v_next.array_r.reshape(-1, 2)[cells, 0]
        bottom_x[k] = stepper.u.array_r.reshape(-1, 2)[cells, 0]
        if first_slip is None and contact.friction is not None and contact.friction.slipping:
            first_slip = k + 1
    scale = max(largest, dissipation[-1])  # the largest mechanical energy, or D
    out = {"mu": mu, "tan": tan, "nx": nx, "cells": dem.geometry.num_cells_global, "steps": n, "dt": stepper.dt,
           "balance_error": float(np.abs(balance - first.balance).max() / scale),
           "min_dissipation_increment": float(np.diff(np.r_[0.0, dissipation]).min()),
           "dissipation": float(dissipation[-1]), "first_slip_step": first_slip, "scheme": scheme,
           "per_facet": per_facet, "normal_positive_ratio": float(normal[0] / normal[1]),
           "friction_over_mu_n": float(normal[2] / (mu * normal[1])) if mu > 0 else 0.0,
           "friction_over_mu_n_late": float(late_sums[1] / (mu * late_sums[0])) if mu > 0 else 0.0,
           "normal_over_weight_late": float(late_sums[0] / (MASS * G * np.cos(t) * late_sums[2])),
           "wall_time_s": time.perf_counter() - start}
    if settled:
        out["drift_after_first_step"] = float(np.abs(bottom_x - bottom_x[0]).max())
    else:
        late = times > 0.1
        a = np.polyfit(times[late], mean[late], 1)[0]
        exact = G * (np.sin(t) - mu * np.cos(t))  # mu = 0: frictionless
        vbar = 0.5 * (bottom[1:] + bottom[:-1]) - 0.5 * (mean[1:] + mean[:-1])[:, None]
        out |= {"acceleration": float(a), "exact": float(exact), "relative_error": float(a / exact - 1),
                "bottom_velocity_spread": float(vbar[n // 2:].std())}
    return out


def roll(h: float, mu: float = 0.5, scheme: str = "A", per_facet: bool = False) -> dict:
    """The disc (R_DISC) settled by frictionless statics, launched at V0 without spin; ``scheme``
    "B" or "AB": its lower half scheme B candidates (dem-B, dem-AB), ``per_facet`` as ``run``'s.
    The slip stops: None if it stays above 1 % of V0 up to 2 t*."""
    start = time.perf_counter()
    mesh, _, tags = meshes.create_disc(MPI.COMM_WORLD, [0.0, R_DISC], R_DISC, h)
    material = ElasticMaterial(E=1e6, nu=0.3, rho=1.0)
    boundary = tags.find(1)
    lower = boundary[DEMDiscretisation(mesh, material, "A").geometry.facet_centres[boundary, 1] <= R_DISC]

    def disc(friction):
        dem = DEMDiscretisation(mesh, material, scheme[0], body_force=[0.0, -G],
                                scheme_b_facets=lower if scheme == "AB" else None)
        return DEMProblem(dem, [RigidContact(dem, [HalfSpace([0.0, 0.0], [0.0, 1.0], lower, tolerance=1e-9,
                                                             friction=friction)])])

    u0 = minimise_energy(disc(0.0), fixed_mean=[0], fixed_rotation=True).u
    problem = disc(mu)
    dem = problem.dem
    if per_facet and problem.contacts[0].friction is not None:
        problem.contacts[0].friction.spread = None
    stepper = MEMM(problem, 0.5 * dem.stable_time_step())
    v = dem.create_vector()
    v.array.reshape(-1, 2)[:, 0] = V0
    first = stepper.initialise(u0, v)
    m = dem.mass.array_r[::2]
    x0 = dem.geometry.cell_centres[: dem.n_owned, :2]
    t_star = V0 / (3 * mu * G)
    times, speed, slip, balance, dissipation = [], [], [], 0.0, []
    for _ in range(round(2 * t_star / stepper.dt)):
        diag = stepper.step()
        vbar = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, 2)
        x = x0 + stepper.u.array_r.reshape(-1, 2)
        r = x - m @ x / m.sum()
        omega = (m * (r[:, 0] * vbar[:, 1] - r[:, 1] * vbar[:, 0])).sum() / (m * (r**2).sum(axis=1)).sum()
        times.append(diag.t)
        speed.append(m @ vbar[:, 0] / m.sum())
        slip.append(speed[-1] + omega * R_DISC)
        balance = max(balance, abs(diag.balance - first.balance) / max(diag.mechanical, diag.dissipation))
        dissipation.append(diag.dissipation)
    times, speed, slip = map(np.array, (times, speed, slip))
    stops = float(times[np.argmax(slip < 0.01 * V0)]) if (slip < 0.01 * V0).any() else None
    at_t_star = float(np.interp(t_star, times, speed))
    return {"h": h, "mu": mu, "cells": dem.geometry.num_cells_global, "t_star": t_star, "slip_stops": stops,
            "slip_stops_error": None if stops is None else stops / t_star - 1, "speed_at_t_star": at_t_star,
            "speed_error": at_t_star / (2 / 3 * V0) - 1, "balance_error": balance, "dissipation": diag.dissipation,
            "rigid_dissipation": float(0.5 * m.sum() * V0**2 / 3),
            "min_dissipation_increment": float(np.diff(np.r_[0.0, dissipation]).min()), "steps": len(times),
            "speed_at_end": float(speed[-1]), "slip_at_end": float(slip[-1]), "scheme": scheme,
            "per_facet": per_facet, "wall_time_s": time.perf_counter() - start}


def slide3d(mu: float, nx: int = 6, scheme: str = "A", per_facet: bool = False) -> dict:
    start = time.perf_counter()
    t, phi = np.radians(30.0), np.radians(30.0)
    along = np.array([np.cos(phi), np.sin(phi), 0.0])
    mesh, _, tags = meshes.create_box(MPI.COMM_WORLD, [0.0, 0.0, 0.0], [1.0, 1.0, 0.5], [nx, nx, nx // 2])
    base = tags.find(meshes.ZMIN)
    dem = DEMDiscretisation(mesh, BLOCK, scheme[0], body_force=list(G * np.sin(t) * along + [0.0, 0.0, -G * np.cos(t)]),
                            scheme_b_facets=base if scheme == "AB" else None)
    contact = RigidContact(dem, [HalfSpace([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], base, friction=mu)])
    if per_facet:
        contact.friction.spread = None
    stepper = MEMM(DEMProblem(dem, [contact]), 0.5 * dem.stable_time_step())
    first = stepper.initialise(dem.create_vector(), dem.create_vector())
    times, velocity, balance, dissipation, scale = [], [], [], [], first.mechanical
    for _ in range(round(0.4 / stepper.dt)):
        diag = stepper.step()
        times.append(diag.t)
        velocity.append(diag.momentum / MASS)
        balance.append(diag.balance)
        dissipation.append(diag.dissipation)
        scale = max(scale, diag.mechanical, diag.dissipation)
    times, velocity = np.array(times), np.array(velocity)
    late = times > 0.1
    a = np.array([np.polyfit(times[late], velocity[late, i], 1)[0] for i in range(3)])
    exact = G * (np.sin(t) - mu * np.cos(t)) * along
    return {"mu": mu, "cells": dem.geometry.num_cells_global, "acceleration": a.tolist(), "exact": exact.tolist(),
            "relative_error": float(np.linalg.norm(a - exact) / np.linalg.norm(exact)),
            "along_error": float(a @ along / np.linalg.norm(exact) - 1), "nx": nx,
            "balance_error": float(np.abs(np.array(balance) - first.balance).max() / scale),
            "min_dissipation_increment": float(np.diff(np.r_[0.0, dissipation]).min()),
            "scheme": scheme, "per_facet": per_facet, "wall_time_s": time.perf_counter() - start}


def ball(h: float):
    """A ball of radius R_DISC (tetrahedra of size ~h) standing on the floor z = 0 on the centre of
    one boundary facet right below its centroid, and how deep its vertices reach below the floor
    (the contact's tolerance).

    Scheme A's contact acts at the facets' centres. The ball is turned so that a boundary facet
    centre lies right below its centroid, the nearest to it that is then lower than all the others
    (the nearest can have a neighbour further out but lower): gravity has no moment about that point,
    the one the ball stands on, as the disc stands on its lowest facet's centre. Standing on three
    facet centres instead, the ball would roll over the leading one, off its centroid's foot, and
    climb: its normal force, and friction, would rise with h. Frictionless statics holds its mean
    x and y; its rotations about that point cost nothing and gravity does not load them, so CG,
    from u = 0, leaves them out."""
    mesh, _, tags = meshes.create_balls(MPI.COMM_WORLD, [([0.0, 0.0, R_DISC], R_DISC)], h)
    centres = _compat.facet_cell_and_vertices(mesh, tags.find(1))[1].mean(axis=1)
    cells = _compat.owned_cell_nodes(mesh)[1]
    volumes = np.abs(np.linalg.det(cells[:, 1:] - cells[:, :1]))
    centroid = volumes @ cells.mean(axis=1) / volumes.sum()
    arms = centres - centroid
    distances = np.linalg.norm(arms, axis=1)
    for k in np.argsort(distances):  # the nearest centre that is the only lowest one seen from the centroid
        lowest = distances[k] - arms @ arms[k] / distances[k]  # heights over the floor through centre k
        if np.sum(lowest <= 1e-9 * R_DISC) == 1:
            break
    else:
        raise RuntimeError(f"no boundary facet centre of the ball (h = {h}) is its only lowest one below its centroid")
    n, down = arms[k] / distances[k], np.array([0.0, 0.0, -1.0])
    v, c = np.cross(n, down), n @ down  # the rotation taking n to down (Rodrigues)
    cross = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    turn = np.eye(3) + cross + cross @ cross / (1.0 + c)
    x = mesh.geometry.x
    x[:] = (x - centroid) @ turn.T
    x[:, 2] += distances[k]
    return mesh, tags, -x[:, 2].min()


def ball_problem(mesh, tags, tolerance: float, friction: float) -> DEMProblem:
    """The ball (``ball``) of E = 1e6 Pa under gravity, its lower half a candidate on the floor."""
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=1e6, nu=0.3, rho=1.0), "A", body_force=[0.0, 0.0, -G])
    boundary = tags.find(1)
    lower = boundary[dem.geometry.facet_centres[boundary, 2] <= R_DISC]
    return DEMProblem(dem, [RigidContact(dem, [HalfSpace([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], lower,
                                                         tolerance=tolerance, friction=friction)])])


def roll3d(h: float, mu: float = 0.5) -> dict:
    """The ball (``ball``) settled by frictionless statics, launched at V0 along x without spin."""
    start = time.perf_counter()
    mesh, tags, tolerance = ball(h)
    u0 = minimise_energy(ball_problem(mesh, tags, tolerance, 0.0), fixed_mean=[0, 1]).u
    problem = ball_problem(mesh, tags, tolerance, mu)
    dem, contact = problem.dem, problem.contacts[0]
    stepper = MEMM(problem, 0.5 * dem.stable_time_step())
    v = dem.create_vector()
    v.array.reshape(-1, 3)[:, 0] = V0
    first = stepper.initialise(u0, v)
    m = dem.mass.array_r[::3]
    x0 = dem.geometry.cell_centres[: dem.n_owned]
    r0 = x0 - m @ x0 / m.sum()
    height = m @ x0[:, 2] / m.sum()  # the centroid over the floor: the contact point's lever
    standing = np.argmin(dem.geometry.facet_centres[contact.facets[: contact.num_own], 2])
    lever = height - x0[contact.cells[standing], 2]  # the contact cell's, on which friction acts
    inertia_ratio = (m * (r0[:, 0]**2 + r0[:, 2]**2)).sum() / (m.sum() * lever**2)  # I_yy / (m lever^2)
    t_star, t_star_cell = 2 * V0 / (7 * mu * G), V0 / (mu * G * (1 + 1 / inertia_ratio))
    times, speed, slip, cell_slip, slipping, dissipation, balance = [], [], [], [], [], [], 0.0
    for _ in range(round(2 * t_star / stepper.dt)):
        diag = stepper.step()
        vbar = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, 3)
        x = x0 + stepper.u.array_r.reshape(-1, 3)
        r = x - m @ x / m.sum()
        inertia = (m * (r**2).sum(axis=1)).sum() * np.eye(3) - np.einsum("c,ci,cj->ij", m, r, r)
        omega = np.linalg.solve(inertia, (m[:, None] * np.cross(r, vbar)).sum(axis=0))
        times.append(diag.t)
        speed.append(m @ vbar[:, 0] / m.sum())
        slip.append(speed[-1] - omega[1] * height)  # v + omega x (0, 0, -height), along x
        cell_slip.append(speed[-1] - omega[1] * lever)
        slipping.append(contact.friction.slipping)
        dissipation.append(diag.dissipation)
        balance = max(balance, abs(diag.balance - first.balance) / max(diag.mechanical, diag.dissipation))
    times, speed, slip, cell_slip, slipping = map(np.array, (times, speed, slip, cell_slip, slipping))
    stop, cell_stop = int(np.argmax(slip < 0.01 * V0)), int(np.argmax(cell_slip < 0.01 * V0))
    at_t_star = float(np.interp(t_star, times, speed))
    after = speed[times > t_star]
    rolling = float(after.mean())
    return {"h": h, "mu": mu, "cells": dem.geometry.num_cells_global, "steps": len(times), "dt": stepper.dt,
            "t_star": t_star, "slip_stops": float(times[stop]), "slip_stops_error": float(times[stop] / t_star - 1),
            "speed_at_t_star": at_t_star, "speed_error": at_t_star / (5 / 7 * V0) - 1,
            "rolling_speed": rolling, "rolling_speed_error": rolling / (5 / 7 * V0) - 1,
            "rolling_speed_range": [float(after.min()), float(after.max())],
            "lever": float(lever), "height": float(height), "t_star_cell": t_star_cell,
            "cell_slip_stops": float(times[cell_stop]), "cell_slip_stops_error": float(times[cell_stop] / t_star_cell - 1),
            "rolling_speed_cell": V0 / (1 + inertia_ratio),
            "balance_error": balance, "min_dissipation_increment": float(np.diff(np.r_[0.0, dissipation]).min()),
            "dissipation": diag.dissipation, "rigid_dissipation": float(0.5 * m.sum() * V0**2 * 2 / 7),
            "slipping_while_sliding": int(slipping[:stop].max()),
            "steps_slipping_after_stop": int(np.count_nonzero(slipping[stop:])), "wall_time_s": time.perf_counter() - start}


def stability_runs(build, t_end: float, factors) -> list[dict]:
    """MEMM on ``build()``'s (problem, u0, v0) for t_end with dt = f times the stable-step bound,
    for each f of ``factors`` until the stability monitor stops one: f, whether it completed, and
    the initial and the largest mechanical energy of a run that did."""
    runs = []
    for f in factors:
        problem, u0, v0 = build()
        stepper = MEMM(problem, f * problem.dem.stable_time_step())
        largest = initial = stepper.initialise(u0, v0).mechanical
        try:
            for _ in range(round(t_end / stepper.dt)):
                largest = max(largest, stepper.step().mechanical)
        except InstabilityError:
            runs.append({"f": f, "stable": False})
            break
        runs.append({"f": f, "stable": True, "initial_mechanical": initial, "largest_mechanical": largest})
    return runs


def stable_factor(mu: float, nx: int, scheme: str = "A") -> float:
    """The largest f of 1, 1.04, ..., 1.16 at which the block (``block``, ``scheme``) slides for
    0.5 s down the 30 degree slope with dt = f times the bound (``stability_runs``)."""
    t = np.radians(30.0)

    def build():
        problem = block(mu, [G * np.sin(t), -G * np.cos(t)], nx, scheme)
        return problem, problem.dem.create_vector(), problem.dem.create_vector()

    return max((r["f"] for r in stability_runs(build, 0.5, (1.0, 1.04, 1.08, 1.12, 1.16)) if r["stable"]), default=0.0)


def ball_stability(h: float, factors) -> dict:
    """``stability_runs`` of the settled ball launched at V0 without spin, over 2 t* (mu = 0.5),
    with dt = f times the bound for f in ``factors``, without friction and with mu = 0.5; and the
    elastic operator's limit (SLEPc) over the bound."""
    mesh, tags, tolerance = ball(h)
    u0 = minimise_energy(ball_problem(mesh, tags, tolerance, 0.0), fixed_mean=[0, 1]).u
    out = {"h": h}
    for mu in (0.0, 0.5):
        def build(mu=mu):
            problem = ball_problem(mesh, tags, tolerance, mu)
            v = problem.dem.create_vector()
            v.array.reshape(-1, 3)[:, 0] = V0
            return problem, u0.copy(), v

        out[f"{mu:g}"] = stability_runs(build, 4 * V0 / (7 * 0.5 * G), factors)
    dem = ball_problem(mesh, tags, tolerance, 0.0).dem
    out["eigenvalue_over_bound"] = dem.stable_time_step("eigenvalue") / dem.stable_time_step()
    return out


def scheme_b(args) -> dict:
    """The sliding block with the law and the per-facet bound, the held block, the 3D block, the
    stable step and the disc, on scheme B candidates (``--scheme B`` or ``AB``)."""
    results = {"command": f"validation/friction_slide.py --scheme {args.scheme} --mus "
               + " ".join(f"{m:g}" for m in args.mus) + " --meshes " + " ".join(str(n) for n in args.meshes),
               "scheme": args.scheme, "sliding": [], "held": []}
    for nx in args.meshes:
        for mu in args.mus:
            for per_facet in (False, True):
                results["sliding"].append(run(mu, np.tan(np.radians(30.0)), nx, 0.6, False, args.scheme, per_facet))
                print(json.dumps(results["sliding"][-1]), flush=True)
    for tan in (0.05,) if args.quick else (0.05, 0.2):
        results["held"].append(run(0.5, tan, args.meshes[0], 0.3, True, args.scheme))
        print(json.dumps(results["held"][-1]), flush=True)
    results["sliding3d"] = [slide3d(mu, nx, scheme, per_facet) for nx in ((6,) if args.quick else (6, 12))
                            for mu in ((0.3,) if args.quick else (0.1, 0.3))
                            for scheme, per_facet in ((args.scheme, False), (args.scheme, True), ("A", False))]
    print(json.dumps(results["sliding3d"]), flush=True)
    if not args.quick:
        results["stable_factor"] = {f"{mu:g}": stable_factor(mu, args.meshes[0], args.scheme) for mu in (0.0, 0.1, 0.3)}
        print(results["stable_factor"], flush=True)
        results["rolling"] = [roll(h, 0.5, args.scheme, per_facet) for h in (0.01, 0.005) for per_facet in (False, True)]
        print(json.dumps(results["rolling"]), flush=True)
    return results


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mus", type=float, nargs="+", default=None,
                        help="default 0 0.05 0.1 0.2 0.3 (scheme A), 0.1 0.3 (scheme B)")
    parser.add_argument("--meshes", type=int, nargs="+", default=None,
                        help="squares along the block; default 16 32 (scheme A), 16 32 64 (scheme B)")
    parser.add_argument("--scheme", choices=("A", "B", "AB"), default="A",
                        help="B, AB: the sliding and held blocks, the 3D block, the stable step and the disc with "
                             "dem-B / dem-AB (scheme B candidates), the law and the per-facet bound")
    parser.add_argument("--quick", action="store_true",
                        help="mu = 0.1 on 16 x 8 squares, one disc, mu = 0.1 in 3D; the stable step for 0, 0.1; "
                             "the ball at h = 0.02 m, stable at the bound at h = 0.03 m (scheme B: mu = 0.3 on "
                             "16 x 8 squares, held at tan t = 0.05)")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args()
    b = args.scheme != "A"
    args.mus = args.mus or ([0.1, 0.3] if b else [0.0, 0.05, 0.1, 0.2, 0.3])
    args.meshes = args.meshes or ([16, 32, 64] if b else [16, 32])
    if args.quick:
        args.mus, args.meshes = [0.3 if b else 0.1], [16]
    if b:
        results = scheme_b(args)
        args.out.write_text(json.dumps(results, indent=1) + "\n")
        args.out.with_suffix(".md").write_text(friction_slide_pages.page_b(results, V0))
        return
    results = {"command": "validation/friction_slide.py --mus " + " ".join(f"{m:g}" for m in args.mus)
               + " --meshes " + " ".join(str(n) for n in args.meshes), "sliding": [], "held": []}
    for nx in args.meshes:
        for mu in args.mus:
            results["sliding"].append(run(mu, np.tan(np.radians(30.0)), nx, 0.6, settled=False))
            print(json.dumps(results["sliding"][-1]), flush=True)
    for tan in (0.05, 0.2):
        results["held"].append(run(0.5, tan, args.meshes[0], 0.3, settled=True))
        print(json.dumps(results["held"][-1]), flush=True)
    results["rolling"] = [roll(h) for h in ((0.01,) if args.quick else (0.01, 0.005))]
    results["sliding3d"] = [slide3d(mu) for mu in ((0.1,) if args.quick else (0.1, 0.2))]
    print(results["rolling"], results["sliding3d"], flush=True)
    results["stable_factor"] = {f"{mu:g}": stable_factor(mu, args.meshes[0])
                                for mu in ((0.0, 0.1) if args.quick else (0.0, 0.1, 0.3))}
    print(results["stable_factor"], flush=True)
    results["rolling3d"] = [roll3d(h) for h in ((0.02,) if args.quick else (0.02, 0.015, 0.01))]
    print(results["rolling3d"], flush=True)
    factors = (1.0,) if args.quick else np.round(np.arange(1.0, 1.085, 0.01), 2)
    results["stability3d"] = [ball_stability(h, factors) for h in ((0.03,) if args.quick else (0.03, 0.02))]
    print(results["stability3d"], flush=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    args.out.with_suffix(".md").write_text(friction_slide_pages.page(results, V0))


if __name__ == "__main__":
    main()
