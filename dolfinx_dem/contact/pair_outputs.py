"""The outputs of the contact between bodies (pair.py): the facet corrections and the cell
gradients they change (eq. (8), (31)), the largest interpenetration, the contact force, the force
between each pair of bodies (with the sliding force of eq. (34)), the first touch of a step, and
the series columns of a run (``contact.protocol.ContactModel``).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.contact.facets import reach
from dolfinx_dem.errors import StateError
from dolfinx_dem.kernels import Struct, lib, pointer


class PairOutputs:
    """The outputs of a ``PairContact`` ``contact``, read through its public members; ``up`` are
    its patch values (``PairContact.patch_values``)."""

    def __init__(self, contact, grad_weights: np.ndarray):
        self.contact = contact
        self._grad_weights = grad_weights  # a_f / |c| of the local facets' cells (eq. (8))
        self.penetration_ratio = 0.0  # of the last output_values
        self.crossing_angle = 0.0  # of the last output_values (degrees)
        self._facets = (None, None)  # (the known facets, their ``_FacetWork``): remade with each list build

    def _work(self) -> _FacetWork:
        """The outputs' arrays of the known facets (their C pointers made once per list build)."""
        pc = self.contact
        F = pc.facets_all
        if self._facets[0] is not F:  # the known facets change with each list build
            self._facets = (F, _FacetWork(F, pc.num_own, pc.d))
        return self._facets[1]

    def _corrections(self, up: np.ndarray) -> np.ndarray:
        """``facet_corrections`` of every known facet, in the outputs' own array (valid until the
        next call)."""
        pc, work = self.contact, self._work()
        lib.dem_pair_facet_corrections(pc.pair_list.c_pairs.c, pc.state(up).kernel_state.c, work.p_length,
                                       work.p_spare, work.p_corrections)
        return work.corrections

    def facet_corrections(self, up: np.ndarray) -> np.ndarray:
        """u_f - u_f^free of the local facets (eq. (31), directions of
        ``directions.correction_directions``), (n_local, d): complete for the own facets (every
        pair of an own facet is listed here)."""
        return self._corrections(up)[: len(self.contact.facets)].copy()

    def gradient_correction(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(owned cells, change of their gradient (eq. (8))) of the own candidates, (n, d, d)."""
        pc = self.contact
        own = slice(0, pc.num_own)
        return pc.cells[own], np.einsum("ni,nj->nij", self._corrections(up)[own], self._grad_weights[own])

    def penetration(self, up: np.ndarray) -> tuple[float, float, float]:
        """Largest interpenetration of the contact-aware facet reconstructions, as (depth in m, depth over the local
        facet diameter), each >= 0 and the largest over the own facets, and the largest angle theta_p at
        which the planes of two touching facets cross (degrees; 0 face to face, cos theta_p = -n_i . n_j;
        collective). Each facet keeps its reference normal and moves by one translation (eq. (31)), so a
        touching pair's gap varies across the facet by about |f| tan theta_p, which no translation closes:
        the penetration over the facet size then stays of the order of tan theta_p under refinement. Each
        part of a facet's area carries the depth of what lies over it (``dem_pair_penetration``): its
        touching partners (g < 0, w > 0) cover a fraction kappa of it and carry the overlap-weighted mean
        over them of the reconstructed gap (x_f' + u_f' - x_f - u_f) . n, negated; eq. (31) makes it zero
        when each facet has one partner covering it exactly, and partial overlaps (facets sliding against
        each other) leave a gap of the order of the cell gap times the uncovered fraction. The uncovered
        fraction 1 - kappa (all of a facet that overlaps no partner, as one that slid into a hole of the
        other body's mosaic) carries the least of its depths behind the planes of its listed partners around
        the nearest one: in a hole it lies behind all of them, beside a convex body in front of one. The
        facet's depth is the area-weighted sum of the two parts: a sliver of overlap at the rim of a contact
        patch counts as a sliver, a facet half over a hole counts the hole's half. Its ratio: each part over
        the local diameter of what it reads, the largest of the facet's own and those of its touching
        partners or of the partners around the nearest (a fine facet against a coarse mosaic sits as deep as
        the coarse facets allow). The corrections of the partners come from their owners (a scatter over the
        candidates)."""
        pc, work = self.contact, self._work()
        at, n = pc.state(up), pc.num_own
        np.add(at.uc, pc.pair_list.candidate_values(self._corrections(up)[:n]), out=work.uf)
        lib.dem_pair_penetration(pc.pair_list.c_pairs.c, at.kernel_state.c, work.p_centre, work.p_uf, work.p_normal,
                                 work.p_reach, work.p_length, n, work.p_work, work.p_depth, work.p_scale,
                                 work.p_worst)
        worst = work.worst.copy()
        pc.comm.Allreduce(MPI.IN_PLACE, worst, op=MPI.MAX)
        return float(worst[0]), float(worst[1]), float(np.degrees(np.arccos(min(-worst[2], 1.0))))

    def pair_states(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gap g and overlap w of the pairs listed on this process (``listed``; indices into
        ``facets_all``: the local facets, then the ghosts)."""
        pc = self.contact
        g, w, _ = pc.gaps_and_overlaps(np.arange(len(pc.listed)), *pc.pair_displacements(up))
        return g, w

    def touching(self, up: np.ndarray) -> bool:
        """Whether some pair is in contact (g < 0 with a positive overlap), anywhere (collective)."""
        pc = self.contact
        L = pc.listed
        g, w, _ = pc.gaps_and_overlaps(np.arange(len(L)), *pc.pair_displacements(up), closed=True)
        return pc.comm.allreduce(bool(((g < 0) & (w > 0)).any()), op=MPI.LOR)

    def touch_time(self, u0: PETSc.Vec, u1: PETSc.Vec, dt: float) -> float | None:
        """For a step from displacements ``u0`` (no contact) to ``u1``: the time tau in [0, dt]
        at which the first pair touching at the end closed its gap (gaps are affine along the
        step); None if no pair touches (collective)."""
        pc = self.contact
        L = pc.listed
        uc0 = pc.free_displacements(pc.patch_values(u0))
        pc.pair_list.check_listed(uc0)
        at = pc.state(pc.patch_values(u1))
        touching = at.pairs.w > 0  # of the closed pairs (g < 0)
        first = np.inf
        if touching.any():
            p = at.pairs.closed[touching]
            g0, g1 = np.maximum(pc.gaps(p, uc0[L.i[p]], uc0[L.j[p]]), 0.0), at.pairs.g[touching]
            first = float(dt * (g0 / (g0 - g1)).min())
        first = pc.comm.allreduce(first, op=MPI.MIN)
        return None if first == np.inf else first

    def contact_force(self, up: np.ndarray) -> float:
        """Total normal contact force (N; N/m in 2D): the signed sum over touching
        pairs of -(z_p . (a + delta_a)) w_p, the normal force one facet of the pair exerts on
        the other, compression positive (z_p . a' < 0 in compression), so that a pair pulling
        (z_p . a' > 0) lowers it. Between two bodies i, j whose contact facets share one outward
        normal n_i (on i) it is -n_i . F_ij of ``pair_forces`` (collective: the sum over the
        processes of ``contact_force_part``)."""
        pc = self.contact
        return pc.comm.allreduce(self.contact_force_part(up), op=MPI.SUM)

    def closed_count(self, up: np.ndarray) -> int:
        """How many listed pairs of this process may have c_p != 0 at ``up`` (the closed pairs:
        g_p < 0, projections not apart). Summed over the processes it is 0 when no pair touches
        anywhere, and then ``penetration`` is 0 (``model.contact_values`` skips it)."""
        pc = self.contact
        return len(pc.state(up).pairs.closed)

    def contact_force_part(self, up: np.ndarray) -> float:
        """This process's part of ``contact_force`` (its own rows' parts of mu_p), over the closed
        pairs (g < 0) alone: the sum must not depend on the pairs listed around them (w = 0 adds
        nothing)."""
        pc = self.contact
        return 0.0 - pc.state(up).pairs.mu_w

    def pair_forces(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """This process's part (sum over processes) of the contact force between each pair of
        ``body_pairs`` (i, j), i < j: the force body j exerts on body i, (n_body_pairs, d) (N; N/m in 2D);
        the force on j is its opposite. Self-contact forces are internal to a body: not counted.

        The force on body i is -dV/ds_i, the derivative of the energy with respect to a rigid
        shift s_i of body i's candidate facets (their free displacements), a fixed: for each
        touching pair p with facet f of body i, -mu_p dc_p/du_f = mu_p (w_p n + g_p dw_p/du_f'), the
        normal force and the sliding force F^G of eq. (34). A common shift of both bodies changes
        no gap or overlap, so the forces on i and j are exactly opposite. Without Dirichlet
        conditions on body i it is the sum over its cells of the contact forces F - F_free, the
        rate of change of its momentum. mu_p = z_p . (a + delta_a) summed over this process's
        own rows, as in ``force_correction``; ``active`` imposes the piece as there (statics: a
        pair held on its switch g = 0 carries its multiplier, ``kink_forces``, instead)."""
        pc = self.contact
        L = pc.listed
        if active is None:  # the natural piece: the closed pairs of the step's state
            state = pc.state(up).kernel_state
        else:
            p = np.arange(len(L))
            g, w, dw = pc.gaps_and_overlaps(p, *pc.pair_displacements(up))
            cp = np.where(np.isin(pc.pair_keys(), active), w * g, 0.0)
            mu = L.ZT @ (L.Q @ up + pc.row_lift + L.Z @ cp)
            state = Struct("dem_pair_state", n=len(p), closed=p, g=g, w=w, dw=dw, c=cp, mu=mu)
        out = np.zeros((len(pc.body_pairs), pc.d))
        self._body_forces(state, out)
        return out

    def _body_forces(self, state: Struct, out: np.ndarray) -> None:
        """out (n_body_pairs d, C-contiguous) += the forces between the bodies of the pairs of
        ``state`` (``dem_pair_body_forces``; ``pair_forces``)."""
        pc = self.contact
        if state.c.n == 0:
            return
        missing = lib.dem_pair_body_forces(pc.pair_list.c_pairs.c, state.c, pointer(pc.pair_list.facet_bodies),
                                           len(pc.body_pair_index), pointer(pc.body_pair_index), pointer(out))
        if missing:  # every body with a candidate facet is in ``body_pairs``: a broken invariant
            raise StateError(
                f"contact between bodies: {missing} touching pairs join bodies that have no body pair "
                "(bodies without candidate facets?)"
            )

    def output_columns(self) -> tuple[str, ...]:
        """The summed normal contact force ``contact_force`` (``contact_force``), the largest
        interpenetration ``penetration`` of the contact reconstructions (``penetration``), and the
        force of body j on body i for each pair i < j of bodies with candidate facets,
        ``contact_force_<i>_<j>_<x|y|z>`` (``pair_forces``; bodies numbered as
        ``geometry.compute_bodies``, from 0). With friction, the mean tangential force of body j on
        body i over the last step, ``friction_force_<i>_<j>_<x|y|z>`` (its impulse over dt), and
        ``slipping_pairs``, the touching pairs at the Coulomb limit in that step (0 at the first row)."""
        pc = self.contact
        xyz = "xyz"[: pc.d]
        friction = () if pc.friction is None else (
            tuple(f"friction_force_{i}_{j}_{c}" for i, j in pc.body_pairs for c in xyz) + ("slipping_pairs",))
        return ("contact_force", "penetration") + tuple(
            f"contact_force_{i}_{j}_{c}" for i, j in pc.body_pairs for c in xyz
        ) + friction

    def output_sums(self, up: np.ndarray) -> np.ndarray:
        """This process's part of the sums of the outputs: the pair forces, the contact force and
        the count of closed pairs (``closed_count``); with friction the last step's tangential forces
        and slipping pairs after the pair forces. One array, the pair forces summed into it."""
        pc = self.contact
        friction, at, m = pc.friction, pc.state(up), len(pc.body_pairs) * pc.d
        sums = np.zeros(m + (0 if friction is None else m + 1) + 2)
        self._body_forces(at.kernel_state, sums[:m])
        if friction is not None:
            sums[m : 2 * m] = friction.forces.ravel()
            sums[2 * m] = friction.slipping
        sums[-2:] = self.contact_force_part(up), self.closed_count(up)
        return sums

    def output_values(self, up: np.ndarray, sums: np.ndarray) -> list[float]:
        """The values of ``output_columns`` from the reduced ``output_sums``: the penetration's
        scatter and reduction only where some process has a closed pair (collective). Its depth
        over the local facet diameter is kept as ``penetration_ratio`` (the run's check), the touching
        pairs' largest crossing angle as ``crossing_angle``."""
        depth, self.penetration_ratio, self.crossing_angle = self.penetration(up) if sums[-1] > 0 else (0.0, 0.0, 0.0)
        return [sums[-2], depth, *sums[:-2]]

    def smallest_gap(self, up: np.ndarray) -> float:
        """The smallest gap of the pairs that overlap (w > 0), over all processes (m; inf if none)."""
        pc = self.contact
        g, w = self.pair_states(up)
        return pc.comm.allreduce(float(g[w > 0].min(initial=np.inf)), op=MPI.MIN)


class _FacetWork:
    """The per-step outputs' arrays of one set of known facets ``F`` (``n_own`` own ones first)
    and their C pointers, made once per list build: each step's outputs then allocate nothing
    (the kernels overwrite them)."""

    def __init__(self, F, n_own: int, d: int):
        n = len(F)
        self.corrections, self.spare = np.empty((n, d)), np.empty((n, d))  # dem_pair_facet_corrections
        self.uf, self.worst = np.empty((n, d)), np.empty(3)  # dem_pair_penetration's
        self.reach = reach(F)
        arrays = {"length": F.length, "corrections": self.corrections, "spare": self.spare, "centre": F.centre,
                  "uf": self.uf, "normal": F.normal, "reach": self.reach, "work": np.empty(3 * n + 2 * n_own),
                  "depth": np.empty(n_own), "scale": np.empty(n_own), "worst": self.worst}
        self._arrays = arrays  # kept alive with their pointers
        for name, array in arrays.items():
            setattr(self, "p_" + name, pointer(array))
