"""Method ``fem-P1``: a dynamic scene run by the explicit P1 FEM peer instead of the DEM.

``FEMP1Run(scene, comm)`` reads the same scene as ``dynamics.DynamicRun`` and runs it on the
scene's own mesh with :class:`~dolfinx_dem.fem.penalty.PenaltyCentralDifference`: P1 Lagrange,
lumped mass, central differences, node-on-obstacle penalty contact with the ``[[obstacles]]`` and
node-to-facet penalty contact between the bodies of ``[contact]`` (fem/pair_penalty.py).
It writes the DEM's outputs (``summary.json``, ``series.csv``, ``solution.xdmf``, ``final.png``)
with the DEM's column names, so that a scene is compared by changing one word:

- ``kinetic`` ``1/2 v.m v`` at the step, ``elastic`` ``1/2 u.K u``, ``stabilisation`` 0 (the FEM
  has none), ``external`` ``-F.u``, ``pseudo_energy`` the central-difference scheme's modified
  energy ``1/2 v_{n-1/2}.m v_{n+1/2} + 1/2 u.K u - F.u`` plus the penalty energy, conserved to
  rounding without contact (not exactly with it: fem/penalty.py);
- with obstacles, a ``penalty`` column (the penalty energy, included in ``pseudo_energy``) and
  the rigid contact's columns (``contact_gap``, ``contact_pressure``, ``tip_position`` in 1D,
  ``contact_force_obstacle<k>_<x|y|z>``) measured at the candidate nodes;
- with ``[contact]``, the ``penalty`` column and the DEM's columns of contact between bodies
  (``contact_force``, ``penetration``, ``contact_force_<i>_<j>_<x|y|z>``, ``momentum_<x|y|z>``);
- ``reaction_<i>_<x|y|z>`` of the Dirichlet conditions, then the probes: the P1 displacement at
  the probe's point;
- the solution's DG0 fields (cell averages of the P1 fields, the von Mises stress of the cell).

What the FEM peer does not do is a ``SceneError`` naming the key (``check_scene``). A fem-P1 run
writes no checkpoint.
"""

from __future__ import annotations

import math
import pathlib
import sys
import time
from collections.abc import Mapping

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, io, model, plotting, runcontrol, scenes
from dolfinx_dem.dynamics import round_time_step
from dolfinx_dem.errors import InputError, SceneError
from dolfinx_dem.fem.common import evaluate_at_points
from dolfinx_dem.fem.pair_penalty import PAIR_PENALTY_FACTOR
from dolfinx_dem.fem.penalty import PENALTY_FACTOR, PenaltyCentralDifference
from dolfinx_dem.material import CellMaterials
from dolfinx_dem.run_statistics import Statistics, peak_rss_mb


def check_scene(scene: Mapping) -> None:
    """A SceneError naming the first key of a validated scene that ``fem-P1`` does not run."""
    def refuse(key, why):
        raise SceneError(f"scene key '{key}': {why} (method 'fem-P1')")

    contact = scene.get("contact", {})
    if contact.get("self_contact"):
        refuse("contact.self_contact", "self-contact is not implemented for the FEM peer")
    if contact.get("friction", 0.0) > 0:
        refuse("contact.friction", "friction is not implemented for the FEM peer")
    for key in ("skin", "max_penetration"):
        if key in contact:
            refuse(f"contact.{key}", "a key of the DEM's pair list (the FEM peer's search and depth limit follow "
                   "its facets, fem/pair_penalty.py)")
    if "surface" in contact:
        refuse("contact.surface", "the kinematics of the DEM's candidate facets (the FEM peer's facets are its "
               "P1 element's)")
    for key in ("materials", "prescribed"):
        if key in scene:
            refuse(key, "not implemented for the FEM peer (one material, no prescribed bodies)")
    if "eta" in scene["material"]:
        refuse("material.eta", "the DEM's stabilisation; the FEM has none")
    for key in ("quadrature", "stable_step"):
        if key in scene["time"]:
            refuse(f"time.{key}", "a key of the DEM's time stepping (MEMM)")
    for k, ob in enumerate(scene.get("obstacles", [])):
        if ob.get("friction", 0.0) > 0:
            refuse(f"obstacles[{k}].friction", "friction is not implemented for the FEM peer")
    for section in ("dirichlet", "tractions"):
        for i, bc in enumerate(scene.get(section, [])):
            if bc.get("time_dependent"):
                refuse(f"{section}[{i}].time_dependent", "time-dependent data is not implemented for the FEM peer")
            if "components" in bc:
                refuse(f"{section}[{i}].components", "rollers are not implemented for the FEM peer")
            value = bc.get("value", [0.0])
            if isinstance(value[0], str):
                refuse(f"{section}[{i}].value", "expressions are not implemented for the FEM peer (constant values)")
            if section == "dirichlet" and any(v != 0.0 for v in value):
                refuse(f"{section}[{i}].value", "the FEM peer clamps (value 0 only)")


class FEMP1Run:
    """A dynamic scene set up for ``fem-P1``; see the module docstring. Every input error is
    raised here, before ``run`` touches the output folder."""

    def __init__(self, scene: Mapping, comm: MPI.Comm = MPI.COMM_WORLD, quiet: bool = False):
        self.wall = time.perf_counter()
        self.comm, self.quiet = comm, quiet
        mesh, _, tags, names = model.create_mesh(comm, scene["mesh"])
        self.scene = scene = scenes.validate(scene, mesh.topology.dim)
        check_scene(scene)
        self.mesh, self.d = mesh, mesh.topology.dim
        d = self.d
        self.material = material = scenes.materials(scene)
        dirichlet = [model.boundary_facets(mesh, tags, names, bc.get("boundary", "all"), f"dirichlet[{i}].boundary")
                     for i, bc in enumerate(scene.get("dirichlet", []))]
        tractions = [(model.boundary_facets(mesh, tags, names, bc["boundary"], f"tractions[{i}].boundary"),
                      bc["value"]) for i, bc in enumerate(scene.get("tractions", []))]
        obstacles = [(ob["point"], ob["normal"],
                      model.boundary_facets(mesh, tags, names, ob["boundary"], f"obstacles[{k}].boundary"),
                      ob.get("tolerance", 0.0)) for k, ob in enumerate(scene.get("obstacles", []))]
        pairs = None
        if "contact" in scene:
            if self.d == 1:
                raise SceneError("scene key 'contact': contact between bodies is implemented in 2D and 3D, not 1D "
                                 "(method 'fem-P1')")
            pairs = (np.unique(np.concatenate([
                model.boundary_facets(mesh, tags, names, b, f"contact.boundary[{k}]")
                for k, b in enumerate(scene["contact"]["boundary"])])), scene["contact"].get("tolerance", 0.0))
        loads = scene.get("loads", {})
        body_force = [material.rho * g for g in loads["gravity"]] if "gravity" in loads else loads.get("body_force")
        initial = scene.get("initial", {})
        fields = {
            name: (lambda x, spec=initial[name], key=f"initial.{name}": scenes.evaluate_field(spec, x[:d], 0.0, key))
            for name in ("displacement", "velocity") if name in initial
        }
        time_spec = scene["time"]
        self.solver = PenaltyCentralDifference(
            mesh, material.E, material.nu, material.rho, np.concatenate([np.empty(0, np.int32), *dirichlet]),
            lambda limit: time_step(time_spec, limit), body_force=body_force, obstacles=obstacles,
            tractions=tractions, pairs=pairs, initial_displacement=fields.get("displacement"),
            initial_velocity=fields.get("velocity"), plane_stress=material.plane == "stress")
        self.dt = self.solver.dt
        self.n_steps = max(1, round(time_spec["end"] / self.dt))
        self.groups = self._reaction_groups(dirichlet)
        self.probes = self._probes(scene.get("probes", []))
        self.obstacles = bool(obstacles)
        self.pairs = self.solver._pairs
        self._p0 = None  # the momentum at t = 0 (``_record_pairs``)
        self.first_contact = None  # the time a pair first touched (``NodeFacetPenalty.touch_time``)
        self._u_before = None  # ``_before_step``'s vector
        self.p_scale = self.solver.momentum(absolute=True).sum()
        reactions = tuple(f"reaction_{bc.get('name', i)}_{c}" for i, bc in enumerate(scene.get("dirichlet", []))
                          for c in "xyz"[:d])
        contact = ((("contact_gap", "contact_pressure") + (("tip_position",) if d == 1 else ())
                    + tuple(f"contact_force_obstacle{k}_{c}" for k in range(len(obstacles)) for c in "xyz"[:d]))
                   if obstacles else ())
        if self.pairs is not None:
            contact += self.pairs.output_columns() + tuple(f"momentum_{c}" for c in "xyz"[:d])
        self.columns = (model.SERIES_COLUMNS + (("penalty",) if obstacles or pairs else ()) + reactions + contact
                        + tuple(p["name"] for p in scene.get("probes", [])))
        if len(set(self.columns)) != len(self.columns):
            raise SceneError(f"probe names clash with the series columns of this scene: {self.columns}")
        output = scene.get("output", {})
        self.every = output.get("every", max(1, self.n_steps // 50))
        self.series_every = output.get("series_every", 1)
        self.n_cells = mesh.topology.index_map(d).size_local
        self._vector = _compat.create_vector_space(mesh, "DG", 0)
        self._scalar = _compat.create_scalar_space(mesh, "DG", 0)
        self._tensor = _compat.create_tensor_space(mesh, "DG", 0)
        self.step = 0
        self.first = self._energies()
        self.stats = Statistics(self.first[4], scale=self.first[5])
        self.stepping_seconds = 0.0
        self.setup_seconds = comm.allreduce(time.perf_counter() - self.wall, op=MPI.MAX)

    @property
    def t(self) -> float:
        """The time of the current step, n dt (as the DEM's, rather than the solver's sum of steps)."""
        return self.step * self.dt

    # -- set-up ----------------------------------------------------------------------------------
    def _reaction_groups(self, dirichlet) -> list[np.ndarray]:
        """Owned nodes of each Dirichlet condition; a node in several goes to the first."""
        V, fdim = self.solver.V, self.d - 1
        n_owned = V.dofmap.index_map.size_local
        taken = np.zeros(n_owned, dtype=bool)
        marker = dolfinx.fem.Function(V)
        groups = []
        for facets in dirichlet:
            # a node of the condition whose facets another process holds is marked by a reverse scatter
            marker.x.array[:] = 0.0
            marker.x.array.reshape(-1, self.d)[dolfinx.fem.locate_dofs_topological(V, fdim, facets), 0] = 1.0
            vec = _compat.petsc_vec(marker)
            vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            mine = (vec.array_r.reshape(-1, self.d)[:, 0] > 0) & ~taken
            taken |= mine
            groups.append(np.flatnonzero(mine))
        return groups

    def _probes(self, specs) -> np.ndarray:
        for i, p in enumerate(specs):
            if p["component"] >= self.d:
                raise SceneError(f"scene key 'probes[{i}].component' must be < {self.d}, got {p['component']}")
        points = np.array([p["point"] for p in specs], dtype=float).reshape(len(specs), self.d)
        if len(specs):
            try:
                evaluate_at_points(self.solver.u, points)
            except InputError as err:
                raise SceneError(f"scene key 'probes': {err}") from None
        self.probe_components = np.array([p["component"] for p in specs], dtype=int)
        return points

    # -- values ----------------------------------------------------------------------------------
    def _energies(self) -> tuple[float, ...]:
        """(kinetic, elastic, external, penalty, pseudo_energy, mechanical) at the current step."""
        s = self.solver
        kinetic, elastic = s.energies()
        u, a = _compat.petsc_vec(s.u), _compat.petsc_vec(s.a)
        external = -s._F.dot(u) if s._F is not None else 0.0
        w = s._work
        w.pointwiseMult(a, s.lumped_mass)
        modified_kinetic = kinetic - s.dt**2 / 8.0 * a.dot(w)
        penalty = s.penalty_energy()
        return (kinetic, elastic, external, penalty, modified_kinetic + elastic + external + penalty,
                kinetic + elastic + penalty)

    def _row(self, energies) -> list[float]:
        kinetic, elastic, external, penalty, pseudo, _ = energies
        s = self.solver
        row = [self.t, kinetic, elastic, 0.0, external, pseudo] + ([penalty] if self.obstacles or self.pairs else [])
        row += list(s.reactions(self.groups).ravel()) if self.groups else []
        if self.obstacles:
            contact = s.contact_outputs()
            self.stats.min_gap = min(self.stats.min_gap, contact[0])
            row += contact
        if self.pairs is not None:
            contact = self.pairs.outputs(_compat.petsc_vec(s.u))
            momentum = s.momentum()
            self._record_pairs(contact, momentum)
            row += contact + list(momentum)
        if len(self.probes):
            values = evaluate_at_points(s.u, self.probes)
            row += list(values[np.arange(len(self.probes)), self.probe_components])
        return row

    def _record_pairs(self, contact: list[float], momentum: np.ndarray) -> None:
        """The pair contact's summary figures at a series row: the largest penetration, and the
        largest change of the total momentum over sum |m v| at t = 0."""
        if self._p0 is None:
            self._p0 = momentum
            self.penetration, self.momentum_change = 0.0, 0.0
        self.penetration = max(self.penetration, contact[1])
        self.momentum_change = max(self.momentum_change, float(np.abs(momentum - self._p0).max()))

    def _before_step(self) -> PETSc.Vec | None:
        """The displacements before a step while no pair has touched (for ``touch_time``), in one
        vector kept for the run (petsc4py frees a vector of a parallel run only at garbage
        collection: a copy per step would keep one per step)."""
        if self.pairs is None or self.first_contact is not None:
            return None
        u = _compat.petsc_vec(self.solver.u)
        if self._u_before is None:
            self._u_before = u.duplicate()
        u.copy(self._u_before)
        return self._u_before

    def _cell_values(self, function, space) -> np.ndarray:
        """The owned cells' DG0 values of ``function`` interpolated into ``space``, in cell order."""
        f = dolfinx.fem.Function(space)
        if isinstance(function, dolfinx.fem.Function):
            f.interpolate(function)
        else:
            _compat.interpolate_expression(f, function)
        bs = space.dofmap.index_map_bs
        return f.x.array.reshape(-1, bs)[_compat.cell_dofs(space)[: self.n_cells]]

    def _dg0(self, space, cell_values, name) -> dolfinx.fem.Function:
        f = dolfinx.fem.Function(space, name=name)
        bs = space.dofmap.index_map_bs
        f.x.array.reshape(-1, bs)[_compat.cell_dofs(space)[: self.n_cells]] = cell_values.reshape(self.n_cells, bs)
        f.x.scatter_forward()
        return f

    def fields(self) -> dict:
        """DG0 displacement, velocity, von Mises stress (1D: also ``stress_xx``) of the owned cells."""
        s, d = self.solver, self.d
        grads = self._cell_values(ufl.grad(s.u), self._tensor).reshape(-1, d, d)
        materials = CellMaterials.uniform(self.material, self.n_cells)
        out = {name: self._dg0(self._vector, self._cell_values(f, self._vector), name)
               for name, f in (("displacement", s.u), ("velocity", s.v))}
        out["von_mises"] = self._dg0(self._scalar, materials.von_mises(grads), "von_mises")
        if d == 1:
            out["stress_xx"] = self._dg0(self._scalar, materials.stress(grads)[:, 0, 0], "stress_xx")
        return out

    # -- running ---------------------------------------------------------------------------------
    def run(self, output: io.OutputDirectory) -> dict:
        """Integrate to ``time.end`` into ``output``; returns the summary."""
        with runcontrol.Interrupts(self.comm) as interrupts, output as directory:
            status = "completed"
            with (io.SeriesWriter(self.comm, directory / "series.csv", self.columns) as series,
                  io.SolutionWriter(self.comm, directory, self.mesh) as solution):
                series.write(self._row(self.first))
                solution.write(0.0, self.fields())
                progress = runcontrol.Progress(self.comm, self.n_steps, self.quiet)
                while self.step < self.n_steps:
                    before = self._before_step()
                    tic = time.process_time()
                    self.solver.step()
                    self.stepping_seconds += time.process_time() - tic
                    self.step += 1
                    if before is not None:
                        tau = self.pairs.touch_time(before, _compat.petsc_vec(self.solver.u), self.dt)
                        self.first_contact = None if tau is None else self.t - self.dt + tau
                    energies = self._energies()
                    if not all(math.isfinite(e) for e in energies):
                        raise InputError(f"fem-P1 blew up at step {self.step} (t = {self.t:.6g})")
                    self.stats.drift = max(self.stats.drift, abs(energies[4] - self.stats.pseudo_energy_initial))
                    self.stats.scale = max(self.stats.scale, energies[5])
                    last = self.step == self.n_steps
                    if self.step % self.series_every == 0 or last:
                        series.write(self._row(energies))
                    if self.step % self.every == 0 or last:
                        solution.write(self.t, self.fields())
                    progress.update(self.step, self.t, self.stats.relative_drift, True)
                    if interrupts.requested(now=self.step % self.every == 0):
                        status = "interrupted"
                        break
                progress.finish()
            if status == "interrupted":
                output.keep_incomplete(f"interrupted by {interrupts.name} at step {self.step}: a fem-P1 run "
                                       "writes no checkpoint and cannot be resumed")
                if self.comm.rank == 0 and not self.quiet:
                    print(f"dolfinx-dem: interrupted by {interrupts.name}", file=sys.stderr, flush=True)
            self._pictures(directory, animation=status != "interrupted")
            summary = self._summary(status)
            io.write_summary(directory / "summary.json", self.comm, summary)
        return summary

    def _pictures(self, directory: pathlib.Path, animation: bool):
        """``final.png``, and with ``output.animation`` ``animation.gif`` (as the DEM's runs)."""
        output = self.scene.get("output", {})
        scale = output.get("picture_scale", 1.0)
        obstacles = [(ob["point"], ob["normal"]) for ob in self.scene.get("obstacles", [])]
        fields = self.fields()
        u = fields["displacement"].x.array.reshape(-1, self.d)[_compat.cell_dofs(self._vector)[: self.n_cells]]
        scalar = _compat.cell_dofs(self._scalar)[: self.n_cells]
        if self.d == 1:
            plotting.plot_bar(self.mesh, u, fields["stress_xx"].x.array[scalar], directory / "final.png",
                              self.t, obstacles)
        else:
            plotting.plot_cell_field(self.mesh, u, fields["von_mises"].x.array[scalar], directory / "final.png",
                                     "von Mises stress (Pa)", scale, obstacles, None,
                                     plotting.picture_caption(self.scene["name"], self.t, scale))
        if animation and output.get("animation") and not plotting.too_large(self.mesh):
            xdmf, gif = directory / "solution.xdmf", directory / "animation.gif"
            if self.d == 1:
                io.call_on_root(self.comm, plotting.animate_bar, xdmf, gif, obstacles)
            else:
                io.call_on_root(self.comm, plotting.animate_solution, xdmf, gif, "von_mises",
                                "von Mises stress (Pa)", scale, obstacles)

    def _summary(self, status: str) -> dict:
        s = self.solver
        summary = {
            "scene": self.scene["name"],
            "method": "fem-P1",
            "status": status,
            "n_cells": self.mesh.topology.index_map(self.d).size_global,
            "n_nodes": s.V.dofmap.index_map.size_global,
            "n_steps": self.step,
            "dt": self.dt,
            "dt_stable": s.dt_stable,
            "t_end": self.t,
            "wall_time_s": time.perf_counter() - self.wall,
            "setup_time_s": self.setup_seconds,
            "stepping_time_s": self.comm.allreduce(self.stepping_seconds, op=MPI.MAX),
            "peak_rss_mb": peak_rss_mb(self.comm),
            "pseudo_energy_rel_drift": self.stats.relative_drift,
            "pseudo_energy_initial": self.stats.pseudo_energy_initial,
            "max_mechanical_energy": self.stats.scale,
            "stable": True,
            "conservative": True,
            "processes": self.comm.size,
        }
        if self.obstacles:
            summary["contact_candidate_facets"] = s.num_facets
            summary["min_contact_gap"] = self.stats.min_gap
            summary["penalty_factor"] = PENALTY_FACTOR
            summary["dt_stable_contact"] = s.dt_stable_contact
        if self.pairs is not None:
            summary.update({
                "contact_candidate_facets": self.pairs.num_facets,
                "contact_pairs_listed": self.pairs.num_pairs(),
                "contact_list_rebuilds": self.pairs.builds,
                "first_contact_time": self.first_contact,
                "max_penetration": self.penetration,
                "pair_penalty_factor": PAIR_PENALTY_FACTOR,
            })
            if not self.groups:  # momentum is conserved without Dirichlet conditions
                summary["momentum_rel_change"] = self.momentum_change / self.p_scale if self.p_scale > 0 else 0.0
        return summary


def time_step(time_spec: Mapping, limit: float) -> float:
    """``time.dt``, or for ``time.cfl`` the fraction cfl of the stable step ``limit`` of the lumped
    P1 scheme without contact, rounded as the DEM's (``dynamics.round_time_step``)."""
    if "dt" in time_spec:
        return time_spec["dt"]
    return round_time_step(time_spec["cfl"] * limit, time_spec["end"])

