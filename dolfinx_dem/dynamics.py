"""The dynamic runner: a scene integrated in time by MEMM, with its outputs, interrupts and checkpoints.

``DynamicRun(scene, comm)`` sets everything up (mesh, discretisation, contacts, time step, initial
state, probes) and so finds every error of the input before a folder is touched; ``run(output)``
then integrates into the output folder (``io.OutputDirectory``) and ends with one of the statuses

- ``completed``: every step done;
- ``interrupted``: SIGINT or SIGTERM (``runcontrol.Interrupts``) stopped it after a step, on every
  process; outputs closed, checkpoint written, ``INCOMPLETE`` kept with a note;
- ``unstable``: the stability monitor stopped it (``memm.InstabilityError``, raised after the
  outputs and the summary are written);
- ``unresolved``: contact between bodies no longer resolved: the contact surfaces
  interpenetrated by more than ``contact.max_penetration`` local candidate facet diameters, or deeper than
  the pair list radius, or a facet outran its skin (``pair_contact.UnresolvedContactError``,
  raised the same way).

A checkpoint (``checkpoint.py``) is written every ``checkpoint_every`` steps, when interrupted and
at the end; ``DynamicRun.resume`` continues from it, appending to the same series and solution,
and computes exactly what the uninterrupted run would have (bit-identical on the same processes).
"""

from __future__ import annotations

import dataclasses
import math
import pathlib
import sys
import time
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem import _compat, checkpoint, io, model, plotting, runcontrol, scenes
from dolfinx_dem.contact import PairContact, RigidContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import CheckpointError, InputError, InstabilityError, UnresolvedContactError
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.run_statistics import MAX_PENETRATION, PairContactStatistics, Statistics, peak_rss_mb


class DynamicRun:
    """A dynamic scene, set up and ready to run; see the module docstring.

    ``dt``: the time step of a resumed run (otherwise from ``time.dt`` or ``time.cfl``).
    ``checkpoint_every``: steps between checkpoints (None: only when interrupted and at the end).
    """

    def __init__(self, scene: Mapping, comm: MPI.Comm = MPI.COMM_WORLD, quiet: bool = False,
                 checkpoint_every: int | None = None, dt: float | None = None):
        if checkpoint_every is not None and not (isinstance(checkpoint_every, int) and checkpoint_every >= 1):
            raise InputError(f"checkpoint_every must be an integer >= 1, got {checkpoint_every!r}")
        self.wall = time.perf_counter()
        self.scene, self.comm, self.quiet, self.checkpoint_every = scene, comm, quiet, checkpoint_every
        self.problem = problem = model.build(scene, comm)
        self.fracture = problem.fracture
        if self.fracture is not None and checkpoint_every is not None:
            raise InputError("checkpoints of runs with fracture are not implemented yet (issue 34, design stage S3)")
        self.dem = dem = problem.dem
        self.pairs, self.obstacles = problem.find(PairContact), problem.find(RigidContact)
        time_spec = scene["time"]
        self.dt = time_step(dem, time_spec) if dt is None else dt
        self.n_steps = max(1, round(time_spec["end"] / self.dt))
        self.stepper = MEMM(problem, self.dt, time_spec.get("quadrature", "midpoint"))
        self.probes = model.Probes(problem, scene.get("probes", []))
        # with time-dependent data or prescribed bodies, the work W^n they do (memm.py), with
        # friction the dissipation D^n (contact/friction.py), and the balance E^n + D^n - W^n
        self.frictional = any(c.friction is not None for c in problem.contacts)
        does_work = self.stepper.does_work
        # with fracture Gamma^n's parts (fracture/dynamics.py), and the balance E^n + D^n + Gamma^n - W^n
        self.fracture_columns = () if self.fracture is None else self.fracture.COLUMNS
        self.work_columns = ((("work",) if does_work else ()) + (("dissipation",) if self.frictional else ())
                             + (("balance",) if does_work or self.frictional or self.fracture is not None else ()))
        self.columns = (model.SERIES_COLUMNS + self.fracture_columns + self.work_columns + model.reaction_columns(dem)
                        + model.prescribed_columns(dem) + model.contact_columns(problem) + tuple(self.probes.names))
        output = scene.get("output", {})
        self.every = output.get("every", max(1, self.n_steps // 50))
        self.series_every = output.get("series_every", 1)
        # Time-dependent data and prescribed bodies do work: no conservation then, but an energy
        # balance E^n - W^n.
        self.conservative = not self.stepper.does_work
        self.resumed = None  # the checkpoint header of a resumed run
        diag = self.stepper.initialise(*model.initial_state(dem, scene))
        self.first = diag
        self.stats = Statistics(diag.balance, scale=diag.mechanical)
        self.pair_stats = PairContactStatistics(problem, self.stepper, diag.momentum,
                                                scene.get("contact", {}).get("max_penetration", MAX_PENETRATION))
        columns = model.contact_columns(problem)
        self._penetration_column = columns.index("penetration") if self.pairs is not None else None
        self._gap_column = columns.index("contact_gap") if self.obstacles is not None else None
        self.setup_seconds = comm.allreduce(time.perf_counter() - self.wall, op=MPI.MAX)

    # -- resume ----------------------------------------------------------------------------------
    @classmethod
    def resume(cls, folder: str | pathlib.Path, comm: MPI.Comm = MPI.COMM_WORLD,
               overrides: Mapping[str, object] | None = None, quiet: bool = False,
               checkpoint_every: int | None = None) -> DynamicRun:
        """The run of ``folder`` set up again and restored from its checkpoint. ``overrides``
        may only change ``time.end`` (to a multiple of the run's dt after the checkpoint, or at it
        for a run that did not finish: killed after its last step); any other change of the
        scene is a ``CheckpointError`` naming the keys."""
        header = checkpoint.read_header(folder, comm)
        scene = scenes.override(header["scene"], overrides)
        if checkpoint.scene_hash(scene) != header["scene_hash"]:
            changed = checkpoint.scene_differences(header["scene"], scene)
            changed = [k for k in changed if k != "time.end"] or ["mesh.path (the mesh file's content)"]
            raise CheckpointError(
                f"the scene differs from the checkpoint's in {', '.join(changed)}: a resumed run may only change "
                "time.end (start a new run for another scene)")
        end, dt, t = scene["time"]["end"], header["dt"], header["t"]
        steps = end / dt
        if abs(steps - round(steps)) > 1e-9 * steps:
            raise CheckpointError(f"time.end = {end!r} is not a multiple of the run's time step dt = {dt!r}")
        # a run killed after its last step (during its pictures) is finished by a resume without steps
        unfinished = io.call_on_root(comm, (pathlib.Path(folder) / io.INCOMPLETE).exists)
        if round(steps) < header["step"] or (round(steps) == header["step"] and not unfinished):
            raise CheckpointError(
                f"the checkpoint is at step {header['step']} (t = {t:.9g}), not before time.end = {end:.9g}: "
                "pass a later --set time.end=... to go further")
        run = cls(scene, comm, quiet, checkpoint_every or header["checkpoint_every"], dt)
        run._restore(pathlib.Path(folder), header)
        return run

    def _restore(self, folder: pathlib.Path, header: Mapping):
        dem = self.dem
        keys = _compat.owned_original_cells(dem.V)
        centres = dem.geometry.cell_centres[: dem.n_owned]
        tolerance = 1e-9 * float(dem.geometry.facet_diameters.min())
        # the shapes of the stored cell arrays: a model's may depend on its state (pair friction's slots)
        vectors = checkpoint.read_state(folder, self.comm, header, keys, centres, tolerance,
                                        {name: tuple(shape) for name, shape in header["cell_arrays"].items()})
        local = checkpoint.read_local(folder, self.comm, header, keys)  # None: another partition
        m = header["memm"]
        # the evaluation counters differ between processes (contact work is split per process):
        # this process's own on the same partition, else the largest of the writing run's
        counters = local["memm_counters"] if local else (m["force_evaluations"], m["max_step_evaluations"])
        self.stepper.restore(
            *(vectors[name].ravel() for name in checkpoint.VECTORS),
            m["t0"],
            m["n"],
            m["budget"],
            m["work"],
            m["data_potential"],
            *counters,
            m["dissipation"],
            local and {name: local[name] for name in ("y", "z", "means")},
        )
        for k, contact in enumerate(self.problem.contacts):
            prefix = f"contact{k}_"
            contact.restore_state(
                local and {name[len(prefix) :]: a for name, a in local.items() if name.startswith(prefix)}
            )
            contact.restore_cell_state({name[len(prefix):]: a for name, a in vectors.items()
                                        if name.startswith(prefix)})
        self.stats = Statistics(**header["statistics"])
        self.stats.resumes += 1
        self.pair_stats.restore(header["pair_statistics"], self.stepper)
        self.every, self.series_every = header["every"], header["series_every"]
        self.resumed = header

    # -- running ---------------------------------------------------------------------------------
    def run(self, output: io.OutputDirectory) -> dict:
        """Integrate to ``time.end`` into ``output``; returns the summary (``status``)."""
        with runcontrol.Interrupts(self.comm) as interrupts, output as directory:
            status, error = self._integrate(directory, interrupts)
            if status == "interrupted":
                # Under mpirun, SIGKILL follows SIGTERM within a second or so: the summary and the
                # note before the pictures (the summary is written again after them).
                io.write_summary(directory / "summary.json", self.comm, self._summary(status, error))
                note = (
                    f"interrupted by {interrupts.name} at step {self.stepper.n} (t = {self.stepper.t:.9g}); "
                    f"outputs closed and checkpoint written; continue with: dolfinx-dem resume {directory}"
                    if self.fracture is None else
                    f"interrupted by {interrupts.name} at step {self.stepper.n} (t = {self.stepper.t:.9g}); "
                    "outputs closed; no checkpoint: runs with fracture cannot resume yet (issue 34)"
                )
                output.keep_incomplete(note)
                if self.comm.rank == 0 and not self.quiet:
                    print(f"dolfinx-dem: {note}", file=sys.stderr, flush=True)
            self._pictures(directory, animation=status != "interrupted")
            summary = self._summary(status, error)
            io.write_summary(directory / "summary.json", self.comm, summary)
            if error is not None:
                raise error
        return summary

    def _integrate(self, directory: pathlib.Path, interrupts: runcontrol.Interrupts):
        """The step loop with its outputs; returns (status, error)."""
        resumed = self.resumed
        with (
            io.SeriesWriter(
                self.comm, directory / "series.csv", self.columns, append_at=resumed and resumed["series_bytes"]
            ) as self.series,
            io.SolutionWriter(
                self.comm, directory, self.dem.mesh, resume_writes=resumed and resumed["xdmf_writes"]
            ) as self.solution,
        ):
            if resumed is None:
                self._record(self.first, False)
            progress = runcontrol.Progress(self.comm, self.n_steps, self.quiet, first=self.stepper.n)
            status, error = "completed", None
            try:
                while self.stepper.n < self.n_steps:
                    tic = time.process_time()
                    diag = self.stepper.step()
                    self.stats.stepping_seconds += time.process_time() - tic
                    self.stats.drift = max(self.stats.drift, abs(diag.balance - self.stats.pseudo_energy_initial))
                    self.stats.scale = max(self.stats.scale, diag.mechanical)
                    self._record(diag, diag.step == self.n_steps)
                    progress.update(diag.step, diag.t, self.stats.relative_drift, self.conservative)
                    if self.checkpoint_every and diag.step % self.checkpoint_every == 0 and diag.step < self.n_steps:
                        self._checkpoint(directory)
                    if interrupts.requested(now=diag.step % self.every == 0):
                        status = "interrupted"
                        break
            except InstabilityError as err:
                status, error = "unstable", scene_instability(err, self.scene["time"])
            except UnresolvedContactError as err:
                status, error = "unresolved", err
            progress.finish()
            if error is None and self.fracture is None:  # no checkpoint with fracture yet (issue 34)
                self._checkpoint(directory)
        return status, error

    def _record(self, diag, force_fields: bool):
        dem, stepper = self.dem, self.stepper
        tic = time.process_time()
        contact = model.contact_values(self.problem, stepper.u, stepper.contact_patch_values())
        if self.pairs is not None:
            contact += list(diag.momentum)
            outputs = self.pairs.outputs
            penetration = (contact[self._penetration_column], outputs.penetration_ratio, outputs.crossing_angle)
            self.pair_stats.record(diag.t, stepper, penetration, diag.momentum)
            # contact work done at every step for its outputs: part of the contact share
            self.pair_stats.output_seconds += time.process_time() - tic
        if self.obstacles is not None:
            self.stats.min_gap = min(self.stats.min_gap, contact[self._gap_column])
        if diag.step % self.series_every == 0 or force_fields:
            work = [getattr(diag, name) for name in self.work_columns]  # Diagnostics' attributes
            self.series.write(
                [
                    diag.t,
                    diag.kinetic,
                    diag.elastic,
                    diag.stabilisation,
                    diag.external,
                    diag.pseudo_energy,
                    *([] if self.fracture is None else self.fracture.values()),
                    *work,
                    *dem.reactions(stepper.u, diag.t).ravel(),
                    *model.prescribed_values(self.problem, stepper.u, diag.t),
                    *contact,
                    *self.probes.values(stepper.u, diag.t),
                ]
            )
        if diag.step % self.every == 0 or force_fields:
            self.solution.write(diag.t, fields(self.problem, stepper))

    def _checkpoint(self, directory: pathlib.Path):
        dem, stepper = self.dem, self.stepper
        state = stepper.state()
        cell_arrays = self._cell_state()
        header = {
            "format": checkpoint.FORMAT,
            "version": checkpoint.package_version(),
            "scene_hash": checkpoint.scene_hash(self.scene),
            "scene": self.scene,
            "step": stepper.n,
            "t": stepper.t,
            "dt": self.dt,
            "memm": {k: state[k] for k in ("t0", "n", "budget", "work", "data_potential", "dissipation")}
            | {k: self.comm.allreduce(state[k], op=MPI.MAX) for k in ("force_evaluations", "max_step_evaluations")},
            "statistics": dataclasses.asdict(self.stats) | {"wall_seconds": self._wall_seconds()},
            "pair_statistics": self.pair_stats.state(),
            "every": self.every,
            "series_every": self.series_every,
            "checkpoint_every": self.checkpoint_every,
            "series_bytes": self.series.position(),
            "xdmf_writes": self.solution.writes,  # on disk (sync below)
            "cell_arrays": {name: list(a.shape[1:]) for name, a in cell_arrays.items()},
        }
        local = state["recurrence"] | {
            f"contact{k}_{name}": a
            for k, c in enumerate(self.problem.contacts)
            for name, a in c.checkpoint_state().items()
        }
        local["memm_counters"] = np.array([state["force_evaluations"], state["max_step_evaluations"]], dtype=np.int64)
        vectors = {name: state[name].array_r.reshape(-1, dem.d) for name in checkpoint.VECTORS} | cell_arrays
        self.solution.sync()
        checkpoint.write(
            directory,
            self.comm,
            header,
            _compat.owned_original_cells(dem.V),
            dem.geometry.cell_centres[: dem.n_owned],
            vectors,
            local,
        )

    def _cell_state(self) -> dict[str, np.ndarray]:
        """The contact models' ``cell_state`` arrays as ``contact<k>_<name>``."""
        contacts = enumerate(self.problem.contacts)
        return {f"contact{k}_{name}": a for k, c in contacts for name, a in c.cell_state().items()}

    def _wall_seconds(self) -> float:
        """Wall time of the run so far, the earlier parts of a resumed run included."""
        return self.stats.wall_seconds + time.perf_counter() - self.wall

    def _pictures(self, directory: pathlib.Path, animation: bool):
        dem, output, stepper = self.dem, self.scene.get("output", {}), self.stepper
        scale = output.get("picture_scale", 1.0)
        obstacles = [(ob["point"], ob["normal"]) for ob in self.scene.get("obstacles", [])]
        u = stepper.u.array_r.reshape(-1, dem.d)
        if dem.d == 1:
            plotting.plot_bar(
                dem.mesh,
                u,
                self.problem.stress(stepper.u, stepper.t)[:, 0, 0],
                directory / "final.png",
                stepper.t,
                obstacles,
            )
        else:
            plotting.plot_cell_field(
                dem.mesh,
                u,
                self.problem.von_mises(stepper.u, stepper.t),
                directory / "final.png",
                "von Mises stress (Pa)",
                scale,
                obstacles,
                model.prescribed_cells(dem),
                plotting.picture_caption(self.scene["name"], stepper.t, scale),
            )
        if animation and output.get("animation") and not plotting.too_large(dem.mesh):
            if dem.d == 1:
                io.call_on_root(
                    self.comm, plotting.animate_bar, directory / "solution.xdmf", directory / "animation.gif", obstacles
                )
            else:
                io.call_on_root(
                    self.comm,
                    plotting.animate_solution,
                    directory / "solution.xdmf",
                    directory / "animation.gif",
                    "von_mises",
                    "von Mises stress (Pa)",
                    scale,
                    obstacles,
                    dem.prescribed.body_numbers + 1,
                )  # the ``body`` field is 1-based

    def _summary(self, status: str, error: InstabilityError | UnresolvedContactError | None) -> dict:
        dem, stepper, stats = self.dem, self.stepper, self.stats
        summary = {
            "scene": self.scene["name"],
            "method": self.scene["method"],
            "status": status,
            "n_cells": dem.geometry.num_cells_global,
            "n_steps": stepper.n,
            "dt": self.dt,
            "t_end": stepper.t,
            "quadrature": stepper.quadrature,
            "wall_time_s": self._wall_seconds(),
            "setup_time_s": self.setup_seconds,
            "peak_rss_mb": peak_rss_mb(self.comm),
            "pseudo_energy_rel_drift": stats.relative_drift,
            "pseudo_energy_initial": stats.pseudo_energy_initial,
            "max_mechanical_energy": stats.scale,
            # contact work is split per process (its pairs' events): the busiest process counts
            "force_evaluations": self.comm.allreduce(stepper.force_evaluations, op=MPI.MAX),
            "max_force_evaluations_per_step": self.comm.allreduce(stepper.max_step_evaluations, op=MPI.MAX),
            "stable": status != "unstable",
            "conservative": self.conservative,
            "processes": self.comm.size,
            "resumes": stats.resumes,
            "multi_neumann_cells": dem.num_multi_neumann_cells,
            "scheme_b_thin_bodies": [k for k, _, _ in dem.thin_scheme_b_bodies],
            "extrapolated_facets": dem.num_extrapolated_facets,
        }
        if error is None and self.fracture is None:
            summary["checkpoint"] = checkpoint.DIRECTORY
        if self.fracture is not None:
            f = self.fracture
            summary["fracture"] = {"Gc": f.Gc, "gamma": f.gamma, "fracture_energy": f.fracture_energy,
                                   "cracked_area": f.cracked_area, "excess": f.excess,
                                   "breaks": [{"step": b.step, "facets": len(b.facets), "energy": b.energy}
                                              for b in f.breaks]}
        if self.frictional:
            summary["dissipation"] = stepper.dissipation  # D at the end (contact/friction.py)
        if self.obstacles is not None:
            summary["contact_candidate_facets"] = self.obstacles.num_facets
            summary["obstacle_facets_scheme_b_rule"] = self.obstacles.scheme_b_rule
            summary["min_contact_gap"] = stats.min_gap
        if self.pairs is not None:
            summary.update(self.pair_stats.summary(stats.stepping_seconds))
        if error is not None:
            summary["error"] = str(error)
        if isinstance(error, InstabilityError):
            summary["suggested_dt"] = error.suggested_dt
        return summary


def time_step(dem: DEMDiscretisation, time_spec: Mapping) -> float:
    """The scene's time step: ``time.dt``, or for ``time.cfl`` the fraction cfl of the stable
    step (``time.stable_step``: by default from a bound on lambda_max, the same to the bit on any
    number of processes; SLEPc's eigenvalue differs in the last digits), floored to 4
    significant digits so that every process count takes the same steps, then shortened to
    divide the end time. A step beyond the stability limit whatever the modes
    (``DEMDiscretisation.unstable_time_step``) is an error at set-up (before, the monitor stopped
    the run after its folder was written)."""
    if "dt" in time_spec:
        dt, key = time_spec["dt"], f"time.dt = {time_spec['dt']:g}"
    else:
        dt = round_time_step(time_spec["cfl"] * dem.stable_time_step(time_spec.get("stable_step", "bound")),
                             time_spec["end"])
        key = f"time.cfl = {time_spec['cfl']:g} (dt = {dt:.4g} s)"
    if dt > dem.unstable_time_step():
        raise InputError(f"{key} is beyond MEMM's stability limit 2 / sqrt(lambda_max(M^-1 K)): it exceeds "
                         f"2 / sqrt(max_i (M^-1 K)_ii) = {dem.unstable_time_step():.4g} s, which is above that limit. "
                         f"Set time.dt = {dividing_time_step(time_spec['end'], 0.5 * dem.stable_time_step())}, or "
                         "time.cfl <= 1")
    return dt


def round_time_step(limit: float, end: float) -> float:
    """The step ``limit`` floored to 4 significant digits (so that every process count takes the
    same steps), then shortened to divide ``end``."""
    exponent = math.floor(math.log10(limit)) - 3
    return end / math.ceil(end / (math.floor(limit / 10.0**exponent) * 10.0**exponent))


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
        advice = (
            f"set time.dt = {suggested!r} ({round(end / suggested)} steps to time.end = {end:g}; "
            f"MEMM suggests at most {error.suggested_dt:.4g}, half the stability limit "
            "2/sqrt(lambda_max(M^-1 K)) of the elastic operator), or replace time.dt by time.cfl = 0.5"
        )
    return InstabilityError(
        f"MEMM is unstable at step {error.step} (t = {error.t:.6g}, dt = {error.dt:.6g}): "
        f"{error.reason}. Reduce the time step: {advice}",
        error.step,
        error.t,
        error.dt,
        suggested,
        error.reason,
    )


def fields(problem: DEMProblem, stepper: MEMM) -> dict:
    """DG0 displacement, velocity (vbar at t_n) and von Mises stress for XDMF output, in 1D the
    stress sigma_xx (``stress_xx``, signed, for ``plotting.animate_bar``), and with several
    bodies the body number of each cell (``body``: 1-based connected component); with fracture
    ``body`` from the start and ``broken``, the number of broken facets of each cell."""
    dem = problem.dem
    v = stepper.v_prev.copy()
    v.axpy(1.0, stepper.v_next)
    v.scale(0.5)
    out = {
        "displacement": dem.function(stepper.u, "displacement"),
        "velocity": dem.function(v, "velocity"),  # a copy of v's values
        "von_mises": dem.scalar_function(problem.von_mises(stepper.u, stepper.t), "von_mises"),
    }
    v.destroy()  # petsc4py frees a vector not on COMM_SELF only at PETSc.garbage_cleanup
    if dem.d == 1:
        out["stress_xx"] = dem.scalar_function(problem.stress(stepper.u, stepper.t)[:, 0, 0], "stress_xx")
    if dem.geometry.num_bodies > 1 or problem.fracture is not None:
        out["body"] = dem.scalar_function(dem.geometry.cell_bodies[: dem.n_owned] + 1.0, "body")
    if problem.fracture is not None:
        broken = (problem.fracture.operator.crack.broken_step[: dem.n_owned] >= 0).sum(axis=1)
        out["broken"] = dem.scalar_function(broken.astype(float), "broken")
    return out
