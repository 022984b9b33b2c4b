"""The static runner (a scene with a ``statics`` table): DEM energy minimisation, or the DOLFINx P2
FEM reference for the Hertz disc and ball (method ``fem-P2``). ``StaticRun(scene, comm)`` sets up and
checks the model before any folder is touched, ``run(output)`` solves and writes. Same output contract
as a dynamic run (status ``completed``), with one state at the load time t = ``statics.time``
(default 0; prescribed bodies held at U(t), their reactions in ``reactions``), plus
``contact_pressure.csv`` (facet or boundary positions and pressures; not for the 3D FEM, which
samples no pressure) and the summary keys ``contact_half_width``, ``contact_half_width_last`` (1D,
2D), ``top_vertical_displacement``, ``max_contact_pressure``, ``h`` and ``iterations``; in 3D with
one obstacle ``contact_radius``, the moment measure
``a = sqrt(5/2 integral r^2 p / integral p)`` about the axis through the obstacle's point along its
normal (``hertz.contact_radius_moments``; exactly a for a Hertz profile, also on a symmetric part
of the zone such as a quarter: put the point under the ball's centre), with each facet's pressure
uniform on its triangle, and ``contact_radius_barycentre``, the same moments of the facet forces
at the facets' barycentres (``hertz.point_force_moments``: where the DEM measures the gaps; smaller
by the triangles' own second moments, O(h^2), docs/validation/hertz3d_diagnostics.md).

The contact half-width ``contact_half_width`` is the moment measure of the contact pressure,
``a = 2 sqrt(integral (x - xc)^2 p / integral p)`` (``hertz.contact_half_width_moments``; exactly a
for a Hertz profile): for the DEM the facet pressures are uniform on their facets
(``hertz.facet_pressure_moments``), for the FEM the Nitsche multiplier is integrated by quadrature.
An integral of the pressure, it converges smoothly under refinement and has no threshold.
``contact_half_width_fit`` is the a of the Hertz profile fitted to the pressure samples
(``hertz.contact_half_width_fit``, the same for DEM and FEM) and ``contact_half_width_last`` half
the extent of the facets in contact. Facets that the minimisation holds on a kink of the potential
(g_f = 0, ``kink_facets``) carry their Lagrange multiplier as contact force.
"""

from __future__ import annotations

import pathlib
import time
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem import hertz, io, model, plotting
from dolfinx_dem.contact import PairContact, RigidContact
from dolfinx_dem.errors import InputError, SceneError
from dolfinx_dem.run_statistics import peak_rss_mb
from dolfinx_dem.statics import check_held, minimise_energy
from dolfinx_dem.statics.friction import check_load_path, load_tangentially


def _top_point(dem) -> list[float]:
    """The highest vertex of the body (largest last coordinate), the one nearest to the middle of
    the highest vertices' first-coordinate range: the point whose vertical displacement the
    summary reports. Reductions over the owned cells' vertices; nothing is gathered."""
    comm = dem.comm
    x = dem.geometry.cell_vertices[: dem.n_owned].reshape(-1, dem.d)
    top = comm.allreduce(x[:, -1].max(initial=-np.inf), op=MPI.MAX)
    lo = comm.allreduce(x[:, -1].min(initial=np.inf), op=MPI.MIN)
    x = x[x[:, -1] >= top - 1e-12 * (top - lo)]
    middle = 0.5 * (comm.allreduce(x[:, 0].min(initial=np.inf), op=MPI.MIN)
                    + comm.allreduce(x[:, 0].max(initial=-np.inf), op=MPI.MAX))
    best = x[np.lexsort((x[:, 0], np.abs(x[:, 0] - middle)))[0]] if len(x) else None
    candidates = [c for c in comm.allgather(best) if c is not None]
    return min(candidates, key=lambda c: (abs(c[0] - middle), c[0])).tolist()


def _facet_vertices(geom, facets: np.ndarray) -> np.ndarray:
    """The vertex coordinates of each facet, (n, d, d): the cell's vertices but the opposite one."""
    cells, local = geom.facet_cells[facets, 0], geom.facet_local[facets, 0]
    nv = geom.cell_vertices.shape[1]
    others = (local[:, None] + np.arange(1, nv)[None, :]) % nv  # the vertices other than j
    return geom.cell_vertices[cells[:, None], others]


def _write_pressure(path: pathlib.Path, comm, x: np.ndarray, p: np.ndarray):
    if comm.rank == 0:
        order = np.argsort(x[:, 0])
        header = ",".join([f"x{i}" for i in range(x.shape[1])] + ["pressure"])
        np.savetxt(path, np.c_[x[order], p[order]], delimiter=",", header=header, comments="", fmt="%.17g")


class StaticRun:
    """A static scene, set up (the DEM model, or the check of a ``fem-P2`` scene) and ready to run."""

    def __init__(self, scene: Mapping, comm: MPI.Comm = MPI.COMM_WORLD):
        self.wall = time.perf_counter()
        self.scene, self.comm = scene, comm
        if scene["method"] == "fem-P2":
            self.fem = _fem_problem(scene)
            self.dem = None
            return
        self.problem = problem = model.build(scene, comm)
        self.dem = dem = problem.dem
        self.pairs, self.obstacles = problem.find(PairContact), problem.find(RigidContact)
        if self.pairs is not None and dem.d != 2:
            raise SceneError("a static scene with contact between bodies ('contact' table) is implemented "
                                    "in 2D, not 3D")
        statics = scene["statics"]
        if not problem.contacts:  # a free rigid motion is an error before the output folder is touched
            check_held(dem, statics.get("fixed_mean", ()), statics.get("fixed_rotation", False))
        if "tangential_body_force" in statics:  # so is a load path of statics with friction it cannot take
            try:
                check_load_path(problem, statics["tangential_body_force"], statics.get("increments", 10))
            except InputError as err:
                raise SceneError(f"scene key 'statics.tangential_body_force': {err}") from None
        self.top = model.Probes(problem, [{"name": "top", "point": _top_point(dem), "component": dem.d - 1}])
        self.probes = model.Probes(problem, scene.get("probes", []))
        self.setup_seconds = comm.allreduce(time.perf_counter() - self.wall, op=MPI.MAX)

    def run(self, output: io.OutputDirectory) -> dict:
        """Solve and write into ``output``; returns the summary."""
        with output as directory:
            summary = self._run_dem(directory) if self.dem is not None else self._run_fem(directory)
            summary["wall_time_s"] = time.perf_counter() - self.wall
            summary["peak_rss_mb"] = peak_rss_mb(self.comm)
            io.write_summary(directory / "summary.json", self.comm, summary)
        return summary

    def _run_dem(self, directory) -> dict:
        """DEM energy minimisation (statics.minimise_energy)."""
        scene, comm, dem, problem = self.scene, self.comm, self.dem, self.problem
        options = scene["statics"]
        t = options.get("time", 0.0)
        friction = None
        if "tangential_body_force" in options:  # the load path of statics with friction (statics/friction.py)
            friction = load_tangentially(problem, options["tangential_body_force"], options.get("increments", 10),
                                         options.get("fixed_mean", ()), options.get("fixed_rotation", False),
                                         options.get("rtol", 1e-12), t=t)
            result = friction.static
        else:
            result = minimise_energy(problem, options.get("fixed_mean", ()), options.get("fixed_rotation", False),
                                     options.get("rtol", 1e-12), gradient_rtol=options.get("gradient_rtol", 1e-10),
                                     t=t)
        u = result.u
        probes = self.probes
        energies = problem.energies(u, t)
        reactions = dem.reactions(u, t)
        prescribed = model.prescribed_values(problem, u, t, result.force)  # kinks' multipliers included
        columns = (model.SERIES_COLUMNS + model.reaction_columns(dem) + model.prescribed_columns(dem)
                   + model.contact_columns(problem) + tuple(probes.names))
        momenta = [0.0] * dem.d if any(c.tracks_momentum for c in problem.contacts) else []  # at rest
        with io.SeriesWriter(comm, directory / "series.csv", columns) as series:
            series.write([t, 0.0, energies["elastic"], energies["stabilisation"], energies["external"],
                          energies["potential"], *reactions.ravel(), *prescribed, *model.contact_values(problem, u),
                          *momenta, *probes.values(u, t)])
        with io.SolutionWriter(comm, directory, dem.mesh) as solution:
            solution.write(t, {"displacement": dem.function(u, "displacement"),
                               "von_mises": dem.scalar_function(problem.von_mises(u, t), "von_mises")})
        summary = {
            "scene": scene["name"],
            "method": scene["method"],
            "analysis": "static",
            "status": "completed",
            "n_cells": dem.geometry.num_cells_global,
            "h": scene["mesh"].get("h", float(dem.geometry.facet_diameters.max())),
            "iterations": result.iterations,
            "linear_iterations": result.linear_iterations,
            "gradient_norm_reduction": result.gradient_reduction,
            "scheme_b_thin_bodies": [k for k, _, _ in dem.thin_scheme_b_bodies],
            "time": t,
            "top_vertical_displacement": float(self.top.values(u, t)[0]),
            "setup_time_s": self.setup_seconds,
            "processes": comm.size,
        }
        if reactions.size or prescribed.size:  # the force each Dirichlet condition and prescribed body exerts
            names = model.reaction_columns(dem) + model.prescribed_columns(dem)[: prescribed.size // 2]
            values = reactions.ravel().tolist() + prescribed[: prescribed.size // 2].tolist()
            summary["reactions"] = dict(zip(names, values))
        if self.pairs is not None:
            summary.update(_pair_summary(self.pairs, u, result))
        obstacles = [(ob["point"], ob["normal"]) for ob in scene.get("obstacles", [])]
        if self.obstacles is not None:
            axis = obstacles[0] if dem.d == 3 and len(obstacles) == 1 else None
            summary.update(_contact_summary(self.obstacles, u, result, directory / "contact_pressure.csv", axis))
        if friction is not None and self.pairs is not None:
            summary["friction"] = _pair_friction_summary(self.pairs, friction, directory / "contact_traction.csv")
        elif friction is not None:
            summary["friction"] = _friction_summary(self.obstacles, friction, directory / "contact_traction.csv")
        if dem.d == 1:
            plotting.plot_bar(
                dem.mesh,
                u.array_r.reshape(-1, 1),
                problem.stress(u, t)[:, 0, 0],
                directory / "final.png",
                t,
                obstacles,
            )
        else:
            plotting.plot_cell_field(
                dem.mesh,
                u.array_r.reshape(-1, dem.d),
                problem.von_mises(u, t),
                directory / "final.png",
                "von Mises stress (Pa)",
                scene.get("output", {}).get("picture_scale", 1.0),
                obstacles,
                model.prescribed_cells(dem),
                plotting.picture_caption(scene["name"], t, scene.get("output", {}).get("picture_scale", 1.0), True),
            )
        return summary

    def _run_fem(self, directory) -> dict:
        """The DOLFINx P2 FEM reference (fem/hertz.py: Nitsche contact, Newton) for the hertz
        scenes: the paper's disc (centre (0, R), plane y = 0, vertical body force) or the quarter
        ball (centre (0, 0, R), plane z = 0), with the scene's radius, mesh and material."""
        from dolfinx_dem.fem.hertz import solve_hertz

        scene, comm = self.scene, self.comm
        mesh, m = scene["mesh"], scene["material"]
        result = solve_hertz(comm, mesh["h"], degree=2, E=m["E"], nu=m["nu"], **self.fem)
        result.write_xdmf(directory / "solution.xdmf")
        summary = {
            "scene": scene["name"],
            "method": "fem-P2",
            "analysis": "static",
            "status": "completed",
            "h": mesh["h"],
            "n_cells": result.num_cells,
            "n_dofs": result.num_dofs,
            "iterations": result.iterations,
            "residual": result.residual,
            "top_vertical_displacement": result.top_vertical_displacement,
            "contact_force": result.contact_force,
            "processes": comm.size,
        }
        if result.dim == 2:
            _write_pressure(
                directory / "contact_pressure.csv", comm, result.contact_x[:, None], result.traction_pressure
            )
            summary.update(
                {
                    "contact_half_width": result.contact_half_width_moment,
                    "contact_half_width_fit": result.contact_half_width,
                    "contact_half_width_traction_moment": result.contact_half_width_moment_traction,
                    "contact_half_width_last": result.contact_half_width_last,
                    "max_contact_pressure": result.max_contact_pressure,
                    "fitted_max_pressure": result.fit_peak_pressure,
                }
            )
        else:
            summary["contact_radius"] = result.contact_radius
        displacement, von_mises = _fem_cell_fields(result.u, m["E"], m["nu"])
        plotting.plot_cell_field(
            result.mesh,
            displacement,
            von_mises,
            directory / "final.png",
            "von Mises stress (Pa)",
            scene.get("output", {}).get("picture_scale", 1.0),
            [(ob["point"], ob["normal"]) for ob in scene.get("obstacles", [])],
        )
        return summary


def _fem_problem(scene: Mapping) -> dict:
    """The ``solve_hertz`` arguments (R, body_force, dim, refine) of a ``fem-P2`` scene, which
    must be one of the Hertz problems of fem/hertz.py."""
    frictional = [k for k, obstacle in enumerate(scene.get("obstacles", [])) if obstacle.get("friction", 0.0) > 0]
    if frictional:
        raise SceneError(f"scene key 'obstacles[{frictional[0]}].friction': method 'fem-P2' (the Hertz reference) "
                         "is frictionless; statics with friction takes method dem-A")
    mesh, loads = scene["mesh"], scene.get("loads", {})
    force = loads.get("body_force", [0.0, 0.0, 0.0])
    horizontal, f = force[:-1], -force[-1]
    if mesh["type"] == "disc" and mesh["centre"] == [0.0, mesh["radius"]]:
        R, dim = mesh["radius"], 2
    elif (
        mesh["type"] == "balls"
        and len(mesh["balls"]) == 1
        and mesh["balls"][0][:3] == [0.0, 0.0, mesh["balls"][0][3]]
        and mesh.get("cut") == ["x", "y"]
        and "frame" not in mesh
    ):
        R, dim = mesh["balls"][0][3], 3
    else:
        R = dim = None
    refine_point = mesh.get("refine_point", [0.0] * (dim or 3))
    if dim is None or any(horizontal) or not f > 0 or any(refine_point):
        raise SceneError(
            "method 'fem-P2' solves the Hertz problems only: a 'disc' mesh centred at (0, radius) on the plane "
            "y = 0, or a 'balls' mesh of one ball centred at (0, 0, radius) with cut = ['x', 'y'] on the plane "
            "z = 0, with a downward 'loads.body_force' (and refinement, if any, at the origin)"
        )
    refine = (mesh["refine_h"], mesh["refine_radius"]) if "refine_point" in mesh else None
    return {"R": R, "body_force": f, "dim": dim, "refine": refine}


def _contact_summary(c: RigidContact, u, result, path: pathlib.Path, axis=None) -> dict:
    """The contact figures of a static DEM solution and the file of facet pressures. The own
    facets' pressures are gathered on rank 0 for the file and the half-width fits: output of a
    static contact zone, not a step of the computation. In 3D with ``axis = (point, normal)``
    (the one obstacle's) the contact radius is the moment measure about that axis
    (``hertz.contact_radius_moments``)."""
    dem, comm, geom = c.dem, c.comm, c.dem.geometry
    own = c.facets[: c.num_own]
    areas = geom.facet_areas[own]
    pressure = c.reactions(u) / areas
    # facets held on a kink of the potential (statics.minimise_energy) carry their multiplier
    pressure[result.pinned] = (
        c.statics().own_values(result.kink_forces, result.pinned)[result.pinned] / areas[result.pinned]
    )
    x = geom.facet_centres[own]
    parts = comm.gather((x, pressure, areas, _facet_vertices(geom, own)), root=0)

    def figures():
        x, p, areas, vertices = (np.concatenate(a) for a in zip(*parts))
        _write_pressure(path, comm, x, p)
        touching = p > 0
        out = {
            "max_contact_pressure": float(p.max()),
            "contact_facets": int(touching.sum()),
            "contact_force": float((p * areas).sum()),
        }
        if dem.d <= 2:
            out["contact_half_width_last"] = hertz.contact_half_width_last(x[:, 0], p)
        if dem.d == 2 and touching.sum() >= 3:
            moments = hertz.facet_pressure_moments(
                vertices[..., 0].min(axis=1), vertices[..., 0].max(axis=1), p * areas
            )
            out["contact_half_width"] = hertz.contact_half_width_moments(*moments)[0]
            a, p0, _ = hertz.contact_half_width_fit(x[:, 0], p)
            out["contact_half_width_fit"], out["fitted_max_pressure"] = a, p0
        if axis is not None and touching.sum() >= 3:
            forces = (p * areas)[touching]
            out["contact_radius"] = hertz.contact_radius_moments(
                *hertz.triangle_pressure_moments(vertices[touching], forces, *axis)
            )
            out["contact_radius_barycentre"] = hertz.contact_radius_moments(
                *hertz.point_force_moments(x[touching], forces, *axis)
            )
        return out

    summary = io.call_on_root(comm, figures)
    summary["kink_facets"] = comm.allreduce(len(result.pinned), op=MPI.SUM)
    return summary


def _friction_summary(c: RigidContact, result, path: pathlib.Path) -> dict:
    """The figures of statics with friction (statics/friction.py) and the file of the frictional
    facets' positions, pressures p, tangential tractions q (along the tangent axis) and states.
    ``stick_half_width`` is the moment measure (``hertz.contact_half_width_moments``) of the
    traction deficit mu p - |q| (q taken against the load), zero on the slip zone: in the
    Cattaneo-Mindlin solution it is mu p0 (c / a) sqrt(1 - x^2 / c^2) on the stick zone |x| < c,
    whose moment measure is exactly c. ``stick_half_width_extent`` is half the extent of the stick
    facets, ``slip_traction_ratio`` the range of |q| / (mu p) over the slip facets (1 by the law,
    to the iteration's tolerance)."""
    comm, geom = c.comm, c.dem.geometry
    own = c.facets[: c.num_own][result.facets]
    areas = geom.facet_areas[own]
    along = geom.facet_centres[own][:, result.axis]
    ends = _facet_vertices(geom, own)[..., result.axis]
    direction = np.sign(result.tangential_load[result.axis])
    parts = comm.gather((along, ends.min(axis=1), ends.max(axis=1), areas, result.normal, result.tangential,
                         result.stick, result.mu), root=0)

    def figures():
        x, x0, x1, area, N, T, stick, mu = (np.concatenate(a) for a in zip(*parts))
        touching = N > 0
        order = np.argsort(x)
        np.savetxt(path, np.c_[x, N / area, T / area, stick][order], delimiter=",", header="x,pressure,traction,stick",
                   comments="", fmt="%.17g")
        deficit = np.where(touching, mu * N + direction * T, 0.0)
        slip = touching & ~stick
        ratio = -direction * T[slip] / (mu[slip] * N[slip])
        out = {
            "stick_facets": int((touching & stick).sum()),
            "slip_facets": int(slip.sum()),
            "stick_half_width_extent": float(0.5 * (x1[stick].max() - x0[stick].min())) if stick.any() else 0.0,
            "slip_traction_ratio": [float(ratio.min()), float(ratio.max())] if slip.any() else [],
        }
        if (deficit > 0).sum() >= 3:
            moments = hertz.facet_pressure_moments(x0, x1, deficit)
            out["stick_half_width"] = hertz.contact_half_width_moments(*moments)[0]
        return out

    summary = io.call_on_root(comm, figures)
    summary.update({
        "increments": len(result.increments),
        "state_iterations": [k.state_iterations for k in result.increments],
        "tangential_load": result.tangential_load.tolist(),
        "friction_force": result.increments[-1].friction_force,
    })
    return summary


def _pair_friction_summary(pc: PairContact, result, path: pathlib.Path) -> dict:
    """The figures of statics with friction between bodies (statics/pair_friction.py) and the file
    of the frictional pairs: their positions s along the load from the centre of pressure X, normal
    forces N_p, friction forces T_p on the loaded body (along the pair's tangent, counted positive
    along the load) and states (N/m: a pair's forces, not tractions). ``stick_half_width`` is the
    moment measure of the deficit mu N_p - |T_p| (as on obstacles, _friction_summary, with point
    forces at the pairs' positions), ``contact_half_width`` that of N_p, ``slip_traction_ratio`` the
    range of |T_p| / (mu N_p) on the slip pairs, ``friction_force`` the friction on the loaded
    bodies along the load and ``contact_tangential_force`` all their contact forces along it (the
    frictionless pair forces' part too: -Q at equilibrium). The pairs are the same on every
    process: rank 0 writes the file."""
    along = (result.positions - result.centre) @ result.direction
    tangential = result.side * np.sign(result.tangents @ result.direction) * result.tangential
    touching = result.normal > 0
    loaded = result.side != 0
    stick, slip = result.stick & loaded, touching & ~result.stick & loaded
    forces = pc.outputs.pair_forces(pc.patch_values(result.u), result.static.active) + pc.statics().kink_forces(
        result.static.pinned, result.static.kink_forces)
    forces = pc.comm.allreduce(forces, op=MPI.SUM)  # the force body j exerts on body i, (i, j) in body_pairs
    frictionless = sum((float(result.loaded[i]) - float(result.loaded[j])) * forces[k] @ result.direction
                       for k, (i, j) in enumerate(pc.body_pairs))
    io.call_on_root(pc.comm, lambda: np.savetxt(
        path, np.c_[along, result.normal, tangential, result.stick][np.argsort(along)], delimiter=",",
        header="s,normal_force,tangential_force,stick", comments="", fmt="%.17g"))
    deficit = np.where(touching & loaded, result.mu * result.normal - np.abs(tangential), 0.0)
    ratio = np.abs(tangential[slip]) / (result.mu * result.normal[slip])
    out = {
        "stick_pairs": int(stick.sum()),
        "slip_pairs": int(slip.sum()),
        "stick_half_width_extent": float(0.5 * np.ptp(along[stick])) if stick.any() else 0.0,
        "slip_traction_ratio": [float(ratio.min()), float(ratio.max())] if slip.any() else [],
        "contact_force": float(result.normal[loaded].sum()),
        "increments": len(result.increments),
        "state_iterations": [k.state_iterations for k in result.increments],
        "tangential_load": result.tangential_load.tolist(),
        "friction_force": result.increments[-1].friction_force,
        "contact_tangential_force": result.increments[-1].friction_force + frictionless,
    }
    for name, weights in (("stick_half_width", deficit), ("contact_half_width", np.where(loaded, result.normal, 0.0))):
        if (weights > 0).sum() >= 3:
            mean = weights @ along / weights.sum()
            out[name] = float(2.0 * np.sqrt(weights @ (along - mean) ** 2 / weights.sum()))
    return out


def _pair_summary(pc: PairContact, u, result) -> dict:
    """The contact figures of a static solution with contact between bodies: the force body j
    exerts on body i for each pair of bodies i < j with candidate facets (the pairs in contact
    and the multipliers of the pairs held on a contact switch, ``kink_pairs``), and the number of
    pairs in contact. The series' ``contact_force_<i>_<j>_*`` columns are the dynamics' outputs,
    which count a pinned pair by the sign its gap rounds to: the summary's are the ones to use."""
    comm = pc.comm
    forces = pc.outputs.pair_forces(pc.patch_values(u), result.active) + pc.statics().kink_forces(
        result.pinned, result.kink_forces
    )
    forces = comm.allreduce(forces, op=MPI.SUM)
    return {
        "contact_forces": {f"{i}_{j}": forces[k].tolist() for k, (i, j) in enumerate(pc.body_pairs)},
        "contact_pairs": result.in_contact,
        "kink_pairs": len(result.pinned),
        "gauss_newton_steps": result.gauss_newton_steps,
    }


def _fem_cell_fields(u, E: float, nu: float):
    """Cell-midpoint displacement and von Mises stress (plane strain in 2D) of a FEM displacement,
    in the owned DG0 dof order that plotting expects."""
    import dolfinx.fem
    import ufl

    from dolfinx_dem import _compat

    mesh = u.function_space.mesh
    d = mesh.topology.dim
    lmbda, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    eps = ufl.sym(ufl.grad(u))
    sigma = 2 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(d)
    if d == 2:  # plane strain: the out-of-plane stress szz enters the deviator
        szz = lmbda * ufl.tr(eps)
        mean = (ufl.tr(sigma) + szz) / 3
        s = sigma - mean * ufl.Identity(2)
        vm = ufl.sqrt(1.5 * (ufl.inner(s, s) + (szz - mean) ** 2))
    else:
        vm = ufl.sqrt(1.5 * ufl.inner(ufl.dev(sigma), ufl.dev(sigma)))
    Q = _compat.create_scalar_space(mesh, "DG", 0)
    V0 = _compat.create_vector_space(mesh, "DG", 0)
    q, w = dolfinx.fem.Function(Q), dolfinx.fem.Function(V0)
    q.interpolate(dolfinx.fem.Expression(vm, _compat.interpolation_points(Q)))
    w.interpolate(u)
    n = mesh.topology.index_map(d).size_local
    cells = np.arange(n)
    blocks = _compat.cell_dofs(V0)[:n]
    order = np.empty(n, dtype=np.int64)
    order[blocks] = cells  # local cell of each owned DG0 vector block
    return w.x.array[: d * n].reshape(n, d), q.x.array[_compat.cell_dofs(Q)[order]]
