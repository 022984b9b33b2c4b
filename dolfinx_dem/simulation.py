"""Run a scene: build the mesh and the DEM, integrate with MEMM, write the output contract.

Outputs in the run directory (see ``io.py`` for the INCOMPLETE-marker contract):
``summary.json``, ``series.csv`` (t, kinetic, elastic, stabilisation, external, pseudo_energy,
then the probes), ``solution.xdmf`` (+ .h5: DG0 displacement, velocity, von Mises stress) and
``final.png`` (deformed state coloured by von Mises stress), and with ``output.animation`` the
GIF ``animation.gif`` of the von Mises stress on the deformed bodies at the XDMF output times.
"""

from __future__ import annotations

import math
import pathlib
import sys
import time
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem import _compat, io, meshes, plotting, scenes
from dolfinx_dem.contact import HalfSpace
from dolfinx_dem.discretisation import DEMDiscretisation, DirichletBC
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM, InstabilityError

SERIES_COLUMNS = ("t", "kinetic", "elastic", "stabilisation", "external", "pseudo_energy")


def create_mesh(comm: MPI.Comm, spec: Mapping):
    """(mesh, facet_tags, names) from the scene's mesh table; ``names`` maps the boundary names
    the mesh defines to facet tags: the side names of the generated interval, rectangle and box
    meshes (``scenes.SIDES`` for the mesh's dimension), a gmsh file's physical-group names, none
    for discs and XDMF files."""
    kind = spec["type"]
    required = {"interval": ("x0", "x1", "n"), "rectangle": ("p0", "p1", "n"), "box": ("p0", "p1", "n"),
                "disc": ("centre", "radius", "h"), "discs": ("discs", "h"), "file": ("path",)}[kind]
    for key in required:
        if key not in spec:
            raise scenes.SceneError(f"scene key 'mesh.{key}' is missing for a mesh of type {kind!r}")
    names = {}
    if kind == "interval":
        mesh, _, tags = meshes.create_interval(comm, spec["n"], spec["x0"], spec["x1"])
    elif kind == "rectangle":
        mesh, _, tags = meshes.create_rectangle(comm, spec["p0"], spec["p1"], spec["n"], spec.get("diagonal", "right"))
    elif kind == "box":
        mesh, _, tags = meshes.create_box(comm, spec["p0"], spec["p1"], spec["n"])
    elif kind == "disc":
        mesh, _, tags = meshes.create_disc(comm, spec["centre"], spec["radius"], spec["h"])
    elif kind == "discs":
        if ("frame" in spec) != ("frame_width" in spec):
            raise scenes.SceneError("scene keys 'mesh.frame' and 'mesh.frame_width' go together")
        frame = (spec["frame"][:2], spec["frame"][2:], spec["frame_width"]) if "frame" in spec else None
        try:
            mesh, _, tags = meshes.create_discs(comm, [(c[:2], c[2]) for c in spec["discs"]], spec["h"], frame)
        except ValueError as err:
            raise scenes.SceneError(f"scene table 'mesh': {err}") from None
    else:
        mesh, _, tags, names = meshes.read_mesh_named(comm, spec["path"])
    if kind in ("interval", "rectangle", "box"):
        names = {name: tag for name, tag in scenes.SIDES.items() if tag <= 2 * mesh.topology.dim}
    return mesh, tags, names


def _boundary_facets(mesh, tags, names, boundary, key="dirichlet.boundary") -> np.ndarray:
    """Process-local boundary facets of a scene's ``boundary`` entry: "all", a condition on the
    coordinates, an integer facet tag, or a name of ``names`` (see ``create_mesh``)."""
    if boundary == "all":
        return _compat.exterior_facets(mesh)
    if isinstance(boundary, str) and any(op in boundary for op in "<>="):
        # A condition on x, y, z that every vertex of the boundary facet satisfies.
        d = mesh.topology.dim
        facets = _compat.locate_boundary_facets(
            mesh, lambda x: np.asarray(scenes.evaluate_condition(boundary, x[:d], key), dtype=bool))
        if mesh.comm.allreduce(len(facets), op=MPI.SUM) == 0:
            raise scenes.SceneError(f"scene key '{key}': boundary condition {boundary!r} selects no facet")
        return facets
    if isinstance(boundary, int):
        tag = boundary
    elif names.get(boundary) is not None:
        tag = names[boundary]
    else:
        what = "ambiguous boundary (it names several facet groups of the mesh file)" if boundary in names \
            else "unknown boundary"
        known = f"one of this mesh's names: {', '.join(sorted(names))}" if names else \
            "no name: this mesh defines none (side names belong to the interval, rectangle and box meshes)"
        raise scenes.SceneError(
            f"scene key '{key}': {what} {boundary!r} (use 'all', an integer facet tag, a condition "
            f"such as 'y <= 0.2', or {known})")
    if tags is None:
        raise scenes.SceneError(f"the mesh has no facet tags, so boundary {boundary!r} cannot be found")
    facets = tags.find(tag)
    if mesh.comm.allreduce(len(facets), op=MPI.SUM) == 0:
        raise scenes.SceneError(f"scene key '{key}': boundary {boundary!r} (tag {tag}) has no facet")
    return facets


def build(scene: Mapping, comm: MPI.Comm = MPI.COMM_WORLD) -> DEMDiscretisation:
    """The DEM discretisation a scene describes."""
    mesh, tags, names = create_mesh(comm, scene["mesh"])
    scene = scenes.validate(scene, mesh.topology.dim)
    m = scene["material"]
    material = ElasticMaterial(E=m["E"], nu=m["nu"], rho=m["rho"], plane=m.get("plane", "strain"), eta=m.get("eta"))
    dirichlet = []
    for i, bc in enumerate(scene.get("dirichlet", [])):
        value = bc.get("value", [0.0] * mesh.topology.dim)
        field = (lambda x, t, v=value, key=f"dirichlet[{i}].value": scenes.evaluate_field(v, x, t, key)) \
            if isinstance(value[0], str) else value
        facets = _boundary_facets(mesh, tags, names, bc.get("boundary", "all"), f"dirichlet[{i}].boundary")
        dirichlet.append(DirichletBC(facets, field, bc.get("time_dependent", False)))
    loads = scene.get("loads", {})
    body_force = loads.get("body_force")
    if "gravity" in loads:
        body_force = [material.rho * g for g in loads["gravity"]]
    scheme = scene["method"].split("-")[1]
    dem = DEMDiscretisation(mesh, material, scheme, dirichlet, body_force)
    obstacles = [HalfSpace(ob["point"], ob["normal"],
                           _boundary_facets(mesh, tags, names, ob["boundary"], f"obstacles[{k}].boundary"),
                           ob.get("tolerance", 0.0)) for k, ob in enumerate(scene.get("obstacles", []))]
    dem.set_obstacles(obstacles)
    if "contact" in scene:
        c = scene["contact"]
        facets = np.unique(np.concatenate([_boundary_facets(mesh, tags, names, b, f"contact.boundary[{k}]")
                                           for k, b in enumerate(c["boundary"])]))
        dem.set_contact_boundary(facets, c.get("self_contact", False), c.get("tolerance", 0.0))
    return dem


def contact_columns(dem: DEMDiscretisation) -> tuple[str, ...]:
    """Series columns of contact: with obstacles the smallest gap and the mean contact pressure
    (and in 1D the position of the contact end); with contact between bodies the summed normal
    contact force, the largest interpenetration of the contact reconstructions, and the total
    linear momentum."""
    columns = ()
    if dem.contact is not None:
        columns += ("contact_gap", "contact_pressure") + (("tip_position",) if dem.d == 1 else ())
    if dem.pair_contact is not None:
        columns += ("contact_force", "penetration") + tuple(f"momentum_{'xyz'[i]}" for i in range(dem.d))
    return columns


def contact_values(dem: DEMDiscretisation, u) -> list[float]:
    """The values of ``contact_columns`` but the momenta, for the displacement ``u``."""
    values = []
    if dem.contact is not None:
        c = dem.contact
        up = c.patch_values(u)
        gap, k = c.contact_gap(up)
        values += [gap, c.contact_pressure(up)]
        if dem.d == 1:
            values.append(float(dem.geometry.facet_centres[c.facets[k], 0] + c.facet_displacements(up)[k, 0]))
    if dem.pair_contact is not None:
        c = dem.pair_contact
        up = c.patch_values(u)
        values += [c.contact_force(up), c.penetration(up)]
    return values


def momentum(dem: DEMDiscretisation, stepper: MEMM) -> np.ndarray:
    """Total linear momentum sum_c m_c vbar_c at t_n (vbar the mean of the two half-step
    velocities), shape (d,)."""
    m = dem.mass.array_r.reshape(-1, dem.d)
    v = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, dem.d)
    return dem.comm.allreduce((m * v).sum(axis=0), op=MPI.SUM)


class Probes:
    """Displacement components at points: the P1 reconstruction (eq. (10)) of the cell whose
    barycentre is nearest to the point (ties broken by position, so any process count agrees)."""

    def __init__(self, dem: DEMDiscretisation, specs):
        self.dem = dem
        self.names = [p["name"] for p in specs]
        if len(set(self.names)) != len(self.names) or set(self.names) & set(SERIES_COLUMNS):
            raise scenes.SceneError(f"probe names must be unique and differ from {SERIES_COLUMNS}: {self.names}")
        if any(p["component"] >= dem.d for p in specs):
            raise scenes.SceneError(f"probe components must be < {dem.d}")
        points = np.zeros((len(specs), 3))
        for i, p in enumerate(specs):
            points[i, : dem.d] = p["point"]
        inside = _compat.colliding_cells(dem.mesh, points) >= 0 if specs else np.empty(0, bool)
        inside = dem.comm.allreduce(inside.astype(int), op=MPI.SUM) > 0 if specs else inside
        if not np.all(inside):
            bad = int(np.argmin(inside))
            raise scenes.SceneError(f"probe {self.names[bad]!r} at {specs[bad]['point']} is outside the mesh")
        xc = dem.geometry.cell_centres
        cells = []
        for x in points[:, : dem.d]:
            dist = np.round(np.linalg.norm(xc - x, axis=1) / np.ptp(xc, axis=0).max(), 9)
            cells.append(np.lexsort([xc[:, i] for i in reversed(range(dem.d))] + [dist])[0])
        cells = np.asarray(cells, dtype=np.int64)
        start, stop = dem.cell_range
        self.mine = np.flatnonzero((cells >= start) & (cells < stop))
        self.blocks = cells[self.mine] - start
        self.offsets = points[self.mine, : dem.d] - xc[cells[self.mine]]
        self.components = np.array([specs[i]["component"] for i in self.mine], dtype=int)

    def values(self, u, t) -> np.ndarray:
        out = np.zeros(len(self.names))
        if len(self.names) == 0:
            return out
        G = self.dem.gradient(u, t)  # collective
        if len(self.mine):
            uc = u.array_r.reshape(-1, self.dem.d)[self.blocks]
            rec = uc + np.einsum("nij,nj->ni", G[self.blocks], self.offsets)
            out[self.mine] = rec[np.arange(len(self.mine)), self.components]
        return self.dem.comm.allreduce(out, op=MPI.SUM)


class Progress:
    """One line on a terminal: step, t, energy drift, time left."""

    def __init__(self, comm, n_steps: int, quiet: bool):
        self.enabled = comm.rank == 0 and not quiet and sys.stderr.isatty()
        self.n_steps, self.start, self.last = n_steps, time.perf_counter(), 0.0

    def update(self, n, t, drift):
        now = time.perf_counter()
        if not self.enabled or (now - self.last < 0.5 and n < self.n_steps):
            return
        self.last = now
        left = (now - self.start) / n * (self.n_steps - n)
        sys.stderr.write(f"\rstep {n}/{self.n_steps}  t = {t:.5g}  energy drift {drift:.2e}  {left:5.0f} s left ")
        if n == self.n_steps:
            sys.stderr.write("\n")
        sys.stderr.flush()


def run(scene: Mapping, out: str | pathlib.Path, comm: MPI.Comm = MPI.COMM_WORLD, quiet: bool = False) -> dict:
    """Run a validated scene and write its outputs into ``out``; returns the summary."""
    if "statics" in scene:
        from dolfinx_dem.static_simulation import run_static

        return run_static(scene, out, comm)
    wall = time.perf_counter()
    with io.OutputDirectory(out, comm) as directory:
        dem = build(scene, comm)
        t_setup = time.perf_counter() - wall
        time_spec = scene["time"]
        if "dt" in time_spec:
            dt = time_spec["dt"]
            n_steps = max(1, round(time_spec["end"] / dt))
        else:
            # cfl * stable step (by default from a bound on lambda_max, the same to the bit on any
            # number of processes; SLEPc's eigenvalue differs in the last digits), floored to 4
            # significant digits, then shortened to divide the end time.
            limit = time_spec["cfl"] * dem.stable_time_step(time_spec.get("stable_step", "bound"))
            exponent = math.floor(math.log10(limit)) - 3
            n_steps = math.ceil(time_spec["end"] / (math.floor(limit / 10.0**exponent) * 10.0**exponent))
            dt = time_spec["end"] / n_steps
        stepper = MEMM(dem, dt, time_spec.get("quadrature", "midpoint"))
        probes = Probes(dem, scene.get("probes", []))

        xc = dem.geometry.cell_centres[dem.cell_range[0]:dem.cell_range[1]].T
        u0, v0 = dem.create_vector(), dem.create_vector()
        initial = scene.get("initial", {})
        if "displacement" in initial:
            u0.array[:] = scenes.evaluate_field(initial["displacement"], xc, 0.0, "initial.displacement").T.ravel()
        if "velocity" in initial:
            v0.array[:] = scenes.evaluate_field(initial["velocity"], xc, 0.0, "initial.velocity").T.ravel()
        diag = stepper.initialise(u0, v0)

        output = scene.get("output", {})
        every, series_every = output.get("every", max(1, n_steps // 50)), output.get("series_every", 1)
        E0, drift, scale, stable, error = diag.pseudo_energy, 0.0, diag.mechanical, True, None
        min_gap = math.inf
        pair_stats = PairContactStatistics(dem, stepper)
        animation = plotting.Animation(dem.mesh, directory / "animation.gif", "von Mises stress (Pa)",
                                       output.get("picture_scale", 1.0)) if output.get("animation") else None
        progress = Progress(comm, n_steps, quiet)
        columns = SERIES_COLUMNS + contact_columns(dem) + tuple(probes.names)
        with io.SeriesWriter(comm, directory / "series.csv", columns) as series, \
                io.SolutionWriter(comm, directory, dem.mesh) as solution:

            def record(diag, force_fields):
                nonlocal min_gap
                contact = contact_values(dem, stepper.u)
                if dem.pair_contact is not None:
                    contact += list(momentum(dem, stepper))
                    pair_stats.record(diag.t, stepper, dict(zip(contact_columns(dem), contact)))
                if dem.contact is not None:
                    min_gap = min(min_gap, contact[0])
                if diag.step % series_every == 0 or force_fields:
                    series.write([diag.t, diag.kinetic, diag.elastic, diag.stabilisation, diag.external,
                                  diag.pseudo_energy, *contact, *probes.values(stepper.u, diag.t)])
                if diag.step % every == 0 or force_fields:
                    f = fields(dem, stepper)
                    solution.write(diag.t, f)
                    if animation is not None:
                        animation.write(diag.t, stepper.u.array_r.reshape(-1, dem.d),
                                        f["von_mises"].x.array[: dem.n_owned])

            record(diag, False)
            t_stepping = 0.0  # processor time in MEMM steps (forces, events, energies), without outputs
            try:
                for _ in range(n_steps):
                    tic = time.process_time()
                    diag = stepper.step()
                    t_stepping += time.process_time() - tic
                    drift = max(drift, abs(diag.pseudo_energy - E0))
                    scale = max(scale, diag.mechanical)
                    record(diag, diag.step == n_steps)
                    progress.update(diag.step, diag.t, drift / scale if scale > 0 else 0.0)
            except InstabilityError as err:
                stable, error = False, scene_instability(err, time_spec)
            if animation is not None:
                animation.close()

        vm = dem.von_mises(stepper.u, stepper.t)
        plotting.plot_cell_field(dem.mesh, stepper.u.array_r.reshape(-1, dem.d), vm, directory / "final.png",
                                 "von Mises stress (Pa)", output.get("picture_scale", 1.0))
        summary = {
            "scene": scene["name"],
            "method": scene["method"],
            "n_cells": dem.geometry.num_cells,
            "n_steps": stepper.n,
            "dt": dt,
            "t_end": stepper.t,
            "quadrature": stepper.quadrature,
            "wall_time_s": time.perf_counter() - wall,
            "setup_time_s": t_setup,
            "pseudo_energy_rel_drift": drift / scale if scale > 0 else 0.0,
            "pseudo_energy_initial": E0,
            "max_mechanical_energy": scale,
            "force_evaluations": stepper.force_evaluations,
            "max_force_evaluations_per_step": stepper.max_step_evaluations,
            "stable": stable,
            # With time-dependent Dirichlet data the boundary does work: no conservation then.
            "conservative": not any(bc.get("time_dependent", False) for bc in scene.get("dirichlet", [])),
            "processes": comm.size,
            "multi_neumann_cells": int(len(dem.reconstruction.multi_neumann_cells)),
            "extrapolated_facets": int(len(dem.reconstruction.stencils.extrapolated)),
        }
        if dem.contact is not None:
            summary["contact_candidate_facets"] = int(len(dem.contact.facets))
            summary["min_contact_gap"] = min_gap
        if dem.pair_contact is not None:
            summary.update(pair_stats.summary(t_stepping))
        if error is not None:
            summary["error"] = str(error)
            summary["suggested_dt"] = error.suggested_dt
        io.write_summary(directory / "summary.json", comm, summary)
        if error is not None:
            raise error
    return summary


def dividing_time_step(end: float, at_most: float) -> float:
    """A time step dt <= ``at_most`` that divides ``end`` as a scene's ``time.dt`` must (to a
    relative 1e-9), written with as few significant digits as possible: the step counts n from
    end / at_most up to 25 % (at most 1000) more are tried, e.g. end = 1, at_most = 0.0005508
    gives 0.0005 (2000 steps) rather than 1/1816."""
    first = max(1, math.ceil(end / at_most - 1e-9))
    best = None
    for n in range(first, first + min(first // 4, 1000) + 1):
        for digits in range(1, 18):
            dt = float(f"{end / n:.{digits}g}")
            if dt <= at_most and abs(end / dt - round(end / dt)) <= 1e-9 * end / dt:
                break
        if best is None or digits < best[0]:
            best = (digits, dt)
    return best[1]


def scene_instability(error: InstabilityError, time_spec: Mapping) -> InstabilityError:
    """The stability monitor's error with advice a scene can take: a ``time.cfl``, or a
    ``time.dt`` that divides ``time.end`` (MEMM's own suggestion need not)."""
    end = time_spec["end"]
    if "cfl" in time_spec:
        cfl = min(0.5, 0.5 * time_spec["cfl"])
        advice = f"set time.cfl = {cfl:g}"
        suggested = end / math.ceil(end / (cfl / time_spec["cfl"] * error.dt))
    else:
        suggested = dividing_time_step(end, min(error.suggested_dt, 0.5 * error.dt))
        advice = (f"set time.dt = {suggested!r} ({round(end / suggested)} steps to time.end = {end:g}; "
                  f"MEMM suggests at most {error.suggested_dt:.4g}, half the stability limit "
                  "2/sqrt(lambda_max(M^-1 K)) of the elastic operator), or replace time.dt by time.cfl = 0.5")
    return InstabilityError(f"MEMM is unstable at step {error.step} (t = {error.t:.6g}, dt = {error.dt:.6g}): "
                            f"{error.reason}. Reduce the time step: {advice}",
                            error.step, error.t, error.dt, suggested, error.reason)


def fields(dem: DEMDiscretisation, stepper: MEMM) -> dict:
    """DG0 displacement, velocity (vbar at t_n) and von Mises stress for XDMF output, and with
    several bodies the body number of each cell (``body``: 1-based connected component)."""
    v = stepper.v_prev.copy()
    v.axpy(1.0, stepper.v_next)
    v.scale(0.5)
    out = {
        "displacement": dem.function(stepper.u, "displacement"),
        "velocity": dem.function(v, "velocity"),
        "von_mises": dem.scalar_function(dem.von_mises(stepper.u, stepper.t), "von_mises"),
    }
    if dem.body_labels.max() > 0:
        start, stop = dem.cell_range
        out["body"] = dem.scalar_function(dem.body_labels[start:stop] + 1.0, "body")
    return out


class PairContactStatistics:
    """Running figures of contact between bodies for ``summary.json``: first contact time (when
    the first gap closed, interpolated within the step), largest interpenetration, momentum
    change, and the processor time spent in contact work."""

    def __init__(self, dem: DEMDiscretisation, stepper: MEMM):
        self.first_contact, self.penetration = None, 0.0
        self.p0 = momentum(dem, stepper) if dem.pair_contact is not None else None
        m = dem.mass.array_r.reshape(-1, dem.d)
        v = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, dem.d)
        self.p_scale = dem.comm.allreduce(float(np.abs(m * v).sum()), op=MPI.SUM)
        self.momentum_change = 0.0
        self.free = len(dem.reconstruction.dirichlet_facets) == 0
        self.dem = dem
        self.previous = None  # free facet displacements of the previous step

    def record(self, t: float, stepper: MEMM, values: Mapping[str, float]):
        """Update with the state at ``t`` and its series ``values`` (``contact_columns``)."""
        contact = self.dem.pair_contact
        free = contact.free_displacements(contact.patch_values(stepper.u))
        if self.first_contact is None and self.previous is not None:
            tau = contact.touch_time(self.previous, free, stepper.dt)
            if tau is not None:
                self.first_contact = t - stepper.dt + tau
        self.previous = free
        self.penetration = max(self.penetration, values["penetration"])
        if self.free:
            p = np.array([values[f"momentum_{'xyz'[i]}"] for i in range(self.dem.d)])
            self.momentum_change = max(self.momentum_change, np.abs(p - self.p0).max())

    def summary(self, stepping_seconds: float) -> dict:
        c = self.dem.pair_contact
        out = {
            "contact_candidate_facets": int(len(c.facets)),
            "contact_pairs_listed": int(len(c.listed)),
            "contact_list_rebuilds": c.rebuilds,
            "contact_pairs_scheme_b_rule": c.scheme_b_pairs,
            "first_contact_time": self.first_contact,
            "max_penetration": self.penetration,
            "contact_seconds": c.seconds,
            "contact_fraction": c.seconds / stepping_seconds if stepping_seconds > 0 else 0.0,
        }
        if self.free:
            out["momentum_rel_change"] = self.momentum_change / self.p_scale if self.p_scale > 0 else 0.0
        return out
