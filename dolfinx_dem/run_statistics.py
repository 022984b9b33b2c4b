"""Running figures of a dynamic run for ``summary.json``, kept in its checkpoints: the energy
balance (``Statistics``) and, with contact between bodies, first contact, penetration and
momentum (``PairContactStatistics``)."""

from __future__ import annotations

import dataclasses
import math
import resource
import warnings
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem.contact import PairContact
from dolfinx_dem.errors import AccuracyWarning, UnresolvedContactError
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem


@dataclasses.dataclass
class Statistics:
    """Running figures of a run for ``summary.json`` (kept in checkpoints)."""

    pseudo_energy_initial: float
    drift: float = 0.0  # max |E^n - E^0|
    scale: float = 0.0  # max mechanical energy
    min_gap: float = math.inf  # smallest obstacle gap
    stepping_seconds: float = 0.0  # processor time in MEMM steps, without outputs
    wall_seconds: float = 0.0  # wall time of the earlier parts of a resumed run
    resumes: int = 0

    @property
    def relative_drift(self) -> float:
        return self.drift / self.scale if self.scale > 0 else 0.0


#: The default of ``contact.max_penetration`` (local candidate facet diameters): above every built-in
#: scene's largest penetration over its whole run, below what a contact surface that does not hold
#: reaches (facets sliding into each other's holes on fine 3D meshes with eta = E; the figures are
#: in docs/validation/contact3d.md).
MAX_PENETRATION = 0.5

#: The crossing angle of touching facets (degrees) above which a run warns: each facet keeps its
#: reference normal and moves by one translation (eq. (31)), so the gap of a pair whose planes cross
#: at theta varies across the facet by about |f| tan theta, which no translation closes; at 45
#: degrees by the facet's own size, and the penetration over the facet size then no longer falls
#: under refinement (docs/validation/contact3d.md, "The crossing angle").
MAX_CROSSING_ANGLE = 45.0


class PairContactStatistics:
    """Running figures of contact between bodies for ``summary.json``: first contact time (when
    the first gap closed, interpolated within the step), largest interpenetration, momentum
    change, and the processor time spent in contact work: in the steps (``PairContact.seconds``)
    and in the contact outputs computed at every step (``output_seconds``: the series' contact
    columns, the penetration and first-contact statistics)."""

    def __init__(self, problem: DEMProblem, stepper: MEMM, momentum: np.ndarray, max_penetration: float):
        """``momentum``: the total momentum of the initial state (``memm.Diagnostics``);
        ``max_penetration``: the largest interpenetration a run accepts, in local candidate facet
        diameters (``contact.max_penetration``)."""
        dem = problem.dem
        self.contact = problem.find(PairContact)
        self.first_contact, self.penetration, self.penetration_ratio = None, 0.0, 0.0
        self.crossing_angle = 0.0  # the largest crossing angle of touching pairs (degrees)
        self.max_penetration = max_penetration
        # floats: on a 3-vector, numpy's operations cost more than a loop, at every step
        self.p0 = momentum.tolist() if self.contact is not None else None
        m = dem.mass.array_r.reshape(-1, dem.d)
        v = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, dem.d)
        self.p_scale = dem.comm.allreduce(float(np.abs(m * v).sum()), op=MPI.SUM)
        self.momentum_change = 0.0
        # momentum is conserved without Dirichlet conditions and prescribed bodies (their impulse)
        self.free = dem.comm.allreduce(len(dem.reconstruction.dirichlet_facets), op=MPI.SUM) == 0 and not dem.prescribed
        self.previous = None  # the displacement of the previous step, until the first contact (one vector)
        self.output_seconds = 0.0  # processor time of the per-step contact outputs (this process)

    def record(self, t: float, stepper: MEMM, penetration: tuple[float, float, float], momentum: np.ndarray):
        """Update with the state at ``t``: its ``penetration`` (depth in m, the series column, depth
        over the local facet diameter and the touching pairs' largest crossing angle in degrees:
        ``PairOutputs.penetration``) and ``momentum``. Warns (``AccuracyWarning``, once) when the
        crossing angle first exceeds ``MAX_CROSSING_ANGLE``."""
        contact = self.contact
        if self.first_contact is None:
            if self.previous is None:
                self.previous = stepper.u.copy()
            else:
                tau = contact.outputs.touch_time(self.previous, stepper.u, stepper.dt)
                if tau is not None:
                    self.first_contact = t - stepper.dt + tau
                # in place: petsc4py frees a vector not on COMM_SELF only at
                # PETSc.garbage_cleanup, so a new copy per step would keep every one (a vector
                # of the mesh's size per step until the first contact)
                stepper.u.copy(self.previous)
        penetration, ratio, crossing = penetration
        self.penetration = max(self.penetration, penetration)
        self.penetration_ratio = max(self.penetration_ratio, ratio)
        if crossing > MAX_CROSSING_ANGLE >= self.crossing_angle and self.contact.comm.rank == 0:  # reduced values
            warnings.warn(AccuracyWarning(
                f"at t = {t:.6g} touching facets of two bodies cross at {crossing:.3g} degrees (more than "
                f"{MAX_CROSSING_ANGLE:g}): the bodies have turned their surfaces against each other, by a "
                "deformation beyond small displacements or at a corner. Each facet keeps its reference normal "
                "and moves by one translation (eq. (31)), so the gap of such a pair varies across a facet by "
                "more than its size: the penetration over the facet size no longer falls under refinement "
                "there (docs/validation/contact3d.md). A slower approach or stiffer bodies keep the "
                "contact of smooth bodies in the method's range"), stacklevel=2)
        self.crossing_angle = max(self.crossing_angle, crossing)
        if ratio > self.max_penetration:  # the same on every process (a reduced value)
            raise UnresolvedContactError(
                f"contact between bodies is not resolved at t = {t:.6g}: the contact surfaces interpenetrate by "
                f"{ratio:.3g} of a candidate facet's diameter (deepest: {penetration:.3g} m), more than "
                f"contact.max_penetration = {self.max_penetration:g}. Eq. (31) corrects a gap only where "
                "the facets of the two bodies overlap: the bodies are too soft for their load or speed, or, in 3D, "
                "the facets slide into holes of each other's mosaic on a mesh too fine for the stabilisation: "
                "contact.surface = 'vertex' or, with the facet surface, a larger material.eta (10 E) keeps the "
                "mosaic tiled (docs/theory.md, docs/validation/contact3d.md). The "
                "results from here on would be wrong; raise "
                "contact.max_penetration only to look at them")
        if self.free:
            self.momentum_change = max(
                self.momentum_change, *(abs(p - p0) for p, p0 in zip(momentum.tolist(), self.p0))
            )

    def state(self) -> dict:
        """The running figures for a checkpoint (``previous`` follows from the state u)."""
        return {
            "first_contact": self.first_contact,
            "penetration": self.penetration,
            "penetration_ratio": self.penetration_ratio,
            "crossing_angle": self.crossing_angle,
            "momentum_change": self.momentum_change,
            "p_scale": self.p_scale,
            "output_seconds": self.output_seconds,
            "p0": self.p0,
            "friction": self._friction_state(),
        }

    def _friction_state(self) -> dict | None:
        """The friction model's counters (contact/pair_friction.py): its most rounds, its steps at
        the cap, the sums of N_p's positive and negative parts over every process (collective) and
        the steps by their rounds (nonzero counts as [rounds, steps])."""
        f = self.contact.friction if self.contact is not None else None
        if f is None:
            return None
        sums = self.contact.comm.allreduce(f.normal_sums, op=MPI.SUM).tolist()
        counts = [[int(r), int(f.round_counts[r])] for r in np.flatnonzero(f.round_counts)]
        return {"rounds": f.rounds, "unconverged": f.unconverged, "normal_sums": sums, "round_counts": counts}

    def restore(self, state: Mapping, stepper: MEMM):
        self.first_contact, self.penetration = state["first_contact"], state["penetration"]
        self.penetration_ratio, self.crossing_angle = state["penetration_ratio"], state["crossing_angle"]
        self.momentum_change, self.p_scale = state["momentum_change"], state["p_scale"]
        self.output_seconds = state["output_seconds"]
        self.p0 = state["p0"]
        if state["friction"] is not None:  # the sums continue on one process, they are reduced in the summary
            f, saved = self.contact.friction, state["friction"]
            f.rounds, f.unconverged = saved["rounds"], saved["unconverged"]
            f.normal_sums = np.array(saved["normal_sums"]) if self.contact.comm.rank == 0 else np.zeros(2)
            f.round_counts[:] = 0
            for r, steps in saved["round_counts"]:
                f.round_counts[r] = steps
        if self.contact is not None and self.first_contact is None:
            self.previous = stepper.u.copy()

    def summary(self, stepping_seconds: float) -> dict:
        c = self.contact
        comm = c.comm
        out = {
            "contact_candidate_facets": c.pair_list.num_facets,
            "contact_pairs_listed": c.num_pairs,
            "contact_list_rebuilds": comm.allreduce(c.rebuilds, op=MPI.MAX),  # the busiest process
            "contact_exchanges": c.exchanges,  # the same on every process
            "contact_pairs_scheme_b_rule": c.scheme_b_pairs,
            "first_contact_time": self.first_contact,
            "max_penetration": self.penetration,
            "max_penetration_over_facet_size": self.penetration_ratio,
            "max_contact_crossing_angle": self.crossing_angle,
            # all contact work of the steps, outputs included, over the steps and those outputs
            "contact_seconds": comm.allreduce(c.seconds + self.output_seconds, op=MPI.MAX),
            "contact_output_seconds": comm.allreduce(self.output_seconds, op=MPI.MAX),
            "contact_fraction": comm.allreduce(
                (c.seconds + self.output_seconds) / (stepping_seconds + self.output_seconds)
                if stepping_seconds > 0
                else 0.0,
                op=MPI.MAX,
            ),
        }
        if c.friction is not None:  # contact/pair_friction.py: its rounds, and what N_p's positive part drops
            f = c.friction
            positive, negative = comm.allreduce(f.normal_sums, op=MPI.SUM)
            out.update(friction_max_rounds=f.rounds, friction_median_rounds=f.median_rounds(),
                       friction_unconverged_steps=f.unconverged,
                       friction_negative_normal_fraction=negative / positive if positive > 0 else 0.0)
        if self.free:
            out["momentum_rel_change"] = self.momentum_change / self.p_scale if self.p_scale > 0 else 0.0
        return out


def peak_rss_mb(comm: MPI.Comm) -> float:
    """The largest peak resident memory of the processes so far (MB)."""
    return comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, op=MPI.MAX)
