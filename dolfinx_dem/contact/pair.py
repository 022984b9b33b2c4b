"""Frictionless contact between deformable bodies (paper §3.4, eq. (22)-(34)), 2D and 3D, distributed.

Candidate facets are declared boundary facets; out of contact they keep their free
reconstruction u_f^free = R_f u (+ D_f g): u_c for scheme B facets (the facet translates with its
cell), the traction-free value of eq. (19)-(21) for scheme A facets. For two candidate facets f
and f' of facing orientation, the common normal and the normal penetration (eq. (22), (30)) are

    n = (|f| n_f - |f'| n_f') / || |f| n_f - |f'| n_f' ||   (normalised; n_f, n_f' outward),
    g = (x_f' + u_f'^free - x_f - u_f^free) . n,             affine in u,

(|f| a length in 2D, an area in 3D) and the overlap w = |f cap f'| is the measure of the
intersection of the two facets, displaced by their free values and projected on the plane normal
to n (basis t): segments in 2D, triangles in 3D. Each facet translates, so w depends on u through
the tangential offset s = t (u_f' - u_f) only; it is piecewise affine (2D) or quadratic (3D) in s,
computed with its exact gradient by clipping each facet's boundary by the other (``_overlap``:
dw/ds = sum over the faces of f' of their outward normals times their measures inside f). The
contact reconstruction (eq. (31)) is, with g^- = min(g, 0),

    u_f = u_f^free + sum_{f'} (w / |f|) g^- e_f,      u_f' = u_f'^free + sum_f (w / |f'|) g^- e_f',

with e_f = n/2, e_f' = -n/2 for scheme B (eq. (26)-(27), theta = 1/2), and for two scheme A
facets the directions of eq. (23)-(24) where they are well posed (equal normal changes of the two
tractions on n; the scheme B rule otherwise, counted; see ``_directions``); against a facet of a
prescribed (rigid) body, e = 0 on it and the whole correction on the other facet. It equals the free
one when g = 0 or w = 0, so the energy is continuous (§3.4.3). Writing the energy rows
a = Q u + q (Q = [S; J]) and z_p = Q_f e_f / |f| + Q_f' e_f' / |f'| for a pair p, the rows
change by delta_a = sum_p c_p z_p with c_p = w_p g_p^-, so that

    V = 1/2 |a + delta_a|^2,     -dV/du = -Q^T (a + delta_a) - sum_p (z_p . (a + delta_a)) dc_p/du,
    dc_p/du = w_p dg_p/du + g_p dw_p/du      (on pairs with g_p < 0),

the exact gradient; g_p dw_p/du is the sliding force F^G of eq. (34).

Distributed (patch.py). Every process owns the candidate facets of its owned cells and knows those
of its first halo layer that touch its own energy rows (its *local* facets). Its pair list holds
every pair with a local facet (partners anywhere: the *ghost* facets are copies of the candidate
facets of other processes near its own, received when the list is built). Each process sums the
energy change over its own rows, and the force terms -Q^T delta_a of its own rows and
-(z_p . (a + delta_a)) dc_p/du restricted to the z_p entries of its own rows: the processes' parts
add up to the exact gradient, since z_p . (a + delta_a) is a sum over rows. Forces reach the
distributed force vector by a reverse scatter of the patch dofs.

Events (paper §4). Along a MEMM free flight u + tau v, g_p and the side of each vertex of one
projected facet with respect to each face (end point, edge line) of the other are affine in tau;
their roots are the events (in 3D only where the vertex crosses the edge itself, within a margin:
the overlap of two translated triangles has kinks there, not where a vertex crosses an edge's line
beyond the edge); between them w is a polynomial of degree d - 1 in tau, c_p of degree d and a pair's force
term of degree 2 d - 1, exactly integrated by d-point Gauss-Legendre (``_gauss_legendre``). A
pair's term involves the c_p' of the pairs sharing an own row with it: the pairs of each
connected component of that relation are integrated on common pieces cut at all the
component's events (an impact in another component does not split them), and so is the rows'
term -Q^T delta_a: exact, so the pseudo-energy is conserved to rounding. A pair's overlap is
clipped only at the Gauss nodes of its own pieces and interpolated at the component's nodes.

Broad phase: the Verlet list of the pairs and the exchange of candidate facets between processes
are pair_list.py's; the overlap geometry overlap.py's, the correction directions directions.py's,
the state at a displacement and the flight events.py's, the outputs pair_outputs.py's, the
vertex surface (``surface``: K_f for R_f) surface.py's, friction between the bodies pair_friction.py's.
``prepare`` checks both ends of the coming step (the flight is affine); every evaluation checks
that the list is valid for its displacements and raises otherwise (never a silently incomplete
list); so does a step that moves a facet by more than half its skin.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import bodies as _bodies
from dolfinx_dem.conditions import facet_indices
from dolfinx_dem.contact import candidates
from dolfinx_dem.contact.events import Flight, PairState, gauss_legendre, integrate_flight, screen_flight
from dolfinx_dem.contact.facets import FacetRows, candidate_records
from dolfinx_dem.contact.overlap import overlap
from dolfinx_dem.contact.pair_friction import PairFriction, frictional
from dolfinx_dem.contact.pair_list import PairList
from dolfinx_dem.contact.pair_outputs import PairOutputs
from dolfinx_dem.contact.pair_statics import PairStatics
from dolfinx_dem.contact.surface import check_surface, vertex_surface
from dolfinx_dem.errors import InputError, StateError, UnresolvedContactError
from dolfinx_dem.kernels import Struct, arena, csr_of, lib, pointer


def _timed(method):
    """A method whose processor time counts in ``PairContact.seconds`` (the contact work of the
    steps: the list rounds, the patch gathers, the force integrals and the energies), once: a
    timed method called by another adds nothing of its own."""

    @functools.wraps(method)
    def timed(self, *args, **kwargs):
        if self._timing:
            return method(self, *args, **kwargs)
        self._timing, start = True, time.process_time()
        try:
            return method(self, *args, **kwargs)
        finally:
            self.seconds += time.process_time() - start
            self._timing = False

    return timed


class PairContact:
    """Contact between candidate facets of a 2D or 3D DEMDiscretisation; see the module docstring.

    Parameters
    ----------
    dem : DEMDiscretisation (2D or 3D); the candidate facets must be Neumann (boundary) facets.
    facets : the candidate boundary facets (the contact boundaries): process-local facet indices or a
        DOLFINx MeshTags (with ``tag``, its facets of that value; conditions.facet_indices).
    self_contact : also pair facets of the same body (never facets that share a vertex).
    skin : one Verlet-list margin (m) for every facet; default each facet's own diameter about its
        barycentre (its length in 2D).
    tolerance : how far facets may interpenetrate at t = 0 (m).
    friction : the Coulomb coefficient mu >= 0 between the bodies (pair_friction.py; 0: frictionless).
    surface : what the pairs read: "facet" (free reconstructions) or "vertex" (their vertex average, surface.py).
    The pair list is ``pair_list`` (pair_list.py), the outputs ``outputs`` (pair_outputs.py)."""

    tracks_momentum = True

    def __init__(self, dem, facets, self_contact: bool = False, skin: float | None = None,
                 tolerance: float = 0.0, tag: int | None = None, friction: float = 0.0, surface: str = "facet"):
        geom, d = dem.geometry, dem.d
        if d not in (2, 3):
            raise InputError(f"contact between deformable bodies is implemented in 2D and 3D, not {d}D")
        check_surface(surface, friction)
        self.dem, self.comm, self.d = dem, dem.comm, d
        if not (np.isfinite(tolerance) and tolerance >= 0):
            raise InputError(f"the penetration tolerance must be >= 0, got {tolerance}")
        facets = facet_indices(facets, tag, "the contact boundary", d)
        found = candidates.select(dem, facets, np.zeros(len(facets), dtype=np.int64), "contact boundaries")
        cell, j, f, owned = found.cell, found.j, found.facet, found.owned
        if self.comm.allreduce(int(owned.sum()), op=MPI.SUM) == 0:
            raise InputError("the contact boundary has no facet (check its tag)")
        candidates.check(dem, found, "the contact boundary")
        _bodies.check_share_no_vertex(geom, self.comm)
        _bodies.check_do_not_overlap(geom, self.comm)
        self.self_contact = bool(self_contact)
        rigid = np.zeros(geom.num_bodies, dtype=bool)  # the prescribed bodies, by body number
        rigid[dem.prescribed.body_numbers] = True
        self.tolerance = float(tolerance)

        # The energy rows this process owns that candidate facets touch, and the local facets:
        # the own ones, then the first-layer ones that touch an own row.
        rows = dem.rows
        dofs = (f[:, None] * d + np.arange(d)).ravel()
        QF = rows.QF[: rows.num_owned][:, dofs]  # CSC
        touches = np.diff(QF.indptr).reshape(-1, d).sum(axis=1) > 0
        keep = owned | touches
        order = np.lexsort((geom.facet_global[f], ~owned))
        order = order[keep[order]]
        self.num_own = int(owned.sum())
        self.facets, self.cells = f[order], cell[order]  # the local facets, own first
        # Candidate numbers: the own facets of rank r after those of ranks < r; the first-layer
        # ones get their owners' numbers through the halo.
        first = self.comm.exscan(self.num_own) or 0
        numbers = np.full((geom.num_cells, d + 1), -1, dtype=np.int64)
        numbers[cell[order][: self.num_own], j[order][: self.num_own]] = first + np.arange(self.num_own)
        numbers = dem.halo_exchange(numbers[: dem.n_owned])[cell[order], j[order]]
        local = candidate_records(dem, self.facets, self.cells, numbers)
        if surface == "vertex":
            local = vertex_surface(dem, found, local, self.facets, self.num_own)
        dofs = (self.facets[:, None] * d + np.arange(d)).ravel()
        QF = rows.QF[: rows.num_owned][:, dofs]  # CSC
        touched = np.unique(QF.indices)  # the own rows touched
        Q = rows.Q[touched]  # held-dof columns
        # the global dofs these rows read (sorted), the patch's first dofs whatever the list, and
        # Q on them (the list rounds widen it to the patch)
        row_dofs, entry_dof = np.unique(dem.columns[Q.indices], return_inverse=True)
        Q = scipy.sparse.csr_matrix((Q.data, entry_dof.astype(np.int32), Q.indptr), shape=(len(touched), len(row_dofs)))
        #: q of the energy rows a = Q u + q that candidate facets touch (own rows)
        self.row_lift = dem.data.row_lift(touched)
        # the kernels' structs of what stays (``dem_patch``: Q on the patch's first dofs, its
        # rows' dofs), and their work memory
        self._c_patch = Struct("dem_patch", Q=csr_of(Q), q=self.row_lift,
                               elastic=(touched < rows.num_elastic).astype(np.int8))
        self._work = arena()
        an = geom.facet_area_normals[self.cells, geom.facet_local[self.facets, 0]]
        self.outputs = PairOutputs(self, an / geom.cell_volumes[self.cells, None])
        self._gauss = gauss_legendre(d)
        self._c_gauss = Struct("dem_gauss", n=len(self._gauss[0]), xi=self._gauss[0], wq=self._gauss[1])

        # The body pairs (i < j) whose force is an output (both bodies hold candidate facets), and
        # the index in ``body_pairs`` of each pair of body numbers (-1: none)
        self.body_pairs, self.body_pair_index = _bodies.body_pairs(self.comm, local.body[: self.num_own],
                                                                   geom.num_bodies)

        self.evaluations, self._statics = 0, None  # the statics interface, made on first use (``statics``)
        self.seconds = 0.0  # processor time of the contact work of the steps (``_timed``)
        self._timing = False  # inside a ``_timed`` method
        self._state = None  # the PairState of the last displacement (a step's end is the next one's start)
        self._flight = None  # the Flight ``prepare`` checked last
        self._end = None  # the last flight's screen (``ScreenedFlight``)
        #: the Verlet list, built at u = 0
        self.pair_list = PairList(self.comm, local, self.num_own, Q, row_dofs, FacetRows(QF[touched], d),
                                  dem.create_vector(), self.self_contact, rigid, skin)
        self._check_no_overlap_at_rest()
        #: Coulomb friction between the bodies (None: frictionless), contact/pair_friction.py
        self.friction = PairFriction(self, friction) if frictional(friction, dem, local.body[: self.num_own]) else None

    def _check_no_overlap_at_rest(self) -> None:
        """Bodies that interpenetrate at u = 0 by more than ``tolerance`` are an input error."""
        up = self.patch_values(self.pair_list.template)
        g, w = self.gaps_and_overlaps(np.arange(len(self.listed)), *self.pair_displacements(up))[:2]
        deep = (g < -self.tolerance) & (w > 0)
        found = None
        if deep.any():
            k = int(np.argmin(np.where(deep, g, np.inf)))
            F, L = self.facets_all, self.listed
            found = (float(g[k]), int(F.body[L.i[k]]), int(F.body[L.j[k]]), F.centre[L.i[k]].tolist(),
                     F.centre[L.j[k]].tolist())
        found = [x for x in self.comm.allgather(found) if x is not None]
        if found:
            g, bi, bj, xi, xj = min(found)
            raise InputError(f"bodies {bi} and {bj} overlap at t = 0: facets at {xi} and {xj} interpenetrate by "
                             f"{-g:.3e} m (tolerance {self.tolerance:g} m)")

    # -- what the list holds ---------------------------------------------------------------------
    listed = property(lambda self: self.pair_list.pairs, doc="The listed pairs (``pair_list.Pairs``).")
    facets_all = property(lambda self: self.pair_list.known, doc="The known facets: the local ones, then ghosts.")
    scatter = property(lambda self: self.pair_list.scatter, doc="The patch scatter (a list round may remake it).")
    skin = property(lambda self: self.pair_list.skin, doc="The smallest Verlet skin (m).")
    rebuilds = property(lambda self: self.pair_list.rebuilds, doc="List builds on this process.")
    exchanges = property(lambda self: self.pair_list.exchanges, doc="Exchanges of facets between processes.")

    def pair_keys(self) -> np.ndarray:
        """The listed pairs' keys (``PairList.pair_keys``): statics keys its active sets by them."""
        return self.pair_list.pair_keys()

    @property
    def num_pairs(self) -> int:
        """Listed pairs, each counted once (by the owner of its first facet); collective."""
        first = self.listed.i < self.num_own
        return self.comm.allreduce(int(first.sum()), op=MPI.SUM)

    @property
    def scheme_b_pairs(self) -> int:
        """How many distinct pairs of scheme A facets listed so far use the scheme B rule
        because eq. (23)-(24) are not well posed for them (directions.py); collective."""
        return self.comm.allreduce(len(self.pair_list.scheme_b_rule), op=MPI.SUM)

    # -- the list's rounds, the flight ---------------------------------------------------------
    @_timed
    def prepare(self, u: PETSc.Vec, v: PETSc.Vec | None = None, dt: float = 0.0,
                up: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Make the Verlet list valid for the states u + tau v, 0 <= tau <= dt (u alone without
        v): if a candidate facet known to some process would move more than half its skin from
        where it was at that process's last build, a round of the lists at u (``PairList.build``), which
        rebuilds the list of that process; if a local facet would drift more than r - s/2 since
        the last exchange (``PairList.drifted``; r the largest pair radius, s the largest skin), the
        round exchanges facets between the processes first, and those that receive a facet new
        to them rebuild too.
        The free facet displacements are affine in tau, so checking both ends covers the whole
        flight. ``MEMM`` calls this before every
        step's force integral, whatever the quadrature, and at ``initialise``; call it before
        evaluating forces or energies at displacements of your own. Collective (one logical
        reduction, and the round's exchanges). ``up``: the patch values of u if the caller has them
        (gathered by the current ``scatter``: MEMM keeps those of the step's end), else they are
        gathered. Returns the patch values of u and v (None without v), gathered again after any
        rebuild: arrays of patch values gathered before a rebuild are invalid after it."""
        if up is None:
            up = self.patch_values(u)
        elif len(up) != len(self.scatter):
            raise InputError(f"prepare: {len(up)} patch values of u given for a patch of {len(self.scatter)} dofs "
                             "(gathered before a list round?)")
        vp = None if v is None else self.patch_values(v)
        at = self.state(up)
        uc, stale = at.uc, at.moved
        moving = v is not None and dt != 0.0
        # The flight's screen (``_free_flight``) before the reduction where the list stands, so that the
        # reduction also tells whether a pair anywhere may touch during the step: if none does
        # (and no list changes), ``force_integral`` adds nothing on every process.
        vc = screen = None
        if moving:
            vc, (_, ratio), screen = self.free_flight(uc, vp, dt, screen=not stale)
            stale = stale or ratio > 1.0
        drifted = self.pair_list.drifted(uc, vc, dt)
        flags = np.array([stale, drifted, screen is None or len(screen) > 0], dtype=np.int32)
        self.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        stale_anywhere, drifted_anywhere, may_touch = flags.tolist()
        if stale_anywhere or drifted_anywhere:
            touching = self._touching_keys(at)
            scatter = self.scatter
            self.pair_list.build(uc, stale, exchange=bool(drifted_anywhere))
            if self.scatter is not scatter:
                up = self.patch_values(u)
                vp = None if v is None else self.patch_values(v)
            dropped = np.setdiff1d(touching, self.pair_keys())
            if self.comm.allreduce(len(dropped), op=MPI.SUM):
                raise UnresolvedContactError(
                    "contact between bodies: touching pairs interpenetrate deeper than the pair list radius "
                    "(their facets' reaches plus their mean skin: facet centres farther apart are not listed), so a "
                    "list rebuild would drop them and the energy would jump. The bodies are too soft for their load "
                    "or speed, or, in 3D, the contact is not resolved: on fine meshes the facets of the two bodies "
                    "slide into each other's holes (contact.surface = 'vertex' holds them; docs/theory.md). A larger "
                    "skin lists deeper pairs but does not stop the interpenetration")
            if moving:  # the flight again from the new list (and reconstructions)
                uc = self.state(up).uc
                vc, (k, ratio), screen = self.free_flight(uc, vp, dt)
                worst = (ratio, float(dt * np.linalg.norm(vc[k])), float(2.0 * np.sqrt(self.pair_list.half_skin2[k]))) \
                    if k >= 0 else (0.0, 0.0, 0.0)
                ratio, motion, skin = self.comm.allreduce(worst, op=MPI.MAX)  # the worst facet's
                if ratio > 1.0:
                    raise UnresolvedContactError(
                        f"contact between bodies: a candidate facet moves {motion:.3e} m in one step, more than half "
                        f"the Verlet skin ({skin:.3e} m): no pair list covers the step; reduce the time step or "
                        "pass a larger skin")
        # the flight checked valid at both ends, kept for ``force_integral`` with its screen's
        # struct (the last ``free_flight`` screened, the list standing: ``_end``; the free facet
        # velocities and the screen are computed once per step), and whether no pair touches
        # anywhere during it
        quiet = not (drifted_anywhere or may_touch)
        self._flight = Flight(up, vp, float(dt), self._end, quiet) if moving else None
        return up, vp

    def _touching_keys(self, at: PairState) -> np.ndarray:
        """Keys of the listed pairs in contact (g < 0, w > 0) in the state ``at`` (none if the list
        is stale there: the keys a rebuild must list again). The state the last step's energy
        left: its screen holds every touching pair."""
        if at.moved:
            return np.empty(0, dtype=np.int64)
        closed = at.pairs
        return self.pair_keys()[closed.closed[(closed.g < 0) & (closed.w > 0)]]

    # -- energy and force ----------------------------------------------------------------------
    @_timed
    def patch_values(self, vec: PETSc.Vec) -> np.ndarray:
        """The values of ``vec`` at the patch dofs (collective); valid until the next rebuild."""
        return self.scatter.gather(vec)

    def state(self, up: np.ndarray) -> PairState:
        """The contact state at patch values ``up`` (``PairState``), kept for the next call: the energy
        at the end of a step, the per-step outputs and the next step's flight start at the same
        displacement. Reused only for the same list and the same array, or bit-identical values
        of a writeable one (a caller's own; MEMM's read-only arrays are new with each state)."""
        last = self._state
        if last is None or last.listed is not self.listed or not (
                last.up is up or (up.flags.writeable and np.array_equal(last.up, up))):
            last = self._state = PairState(self.pair_list, self._c_patch, self._work, self._end, up)
        return last

    def free_displacements(self, up: np.ndarray) -> np.ndarray:
        """The known facets' free reconstructions (``PairList.free_displacements``)."""
        return self.pair_list.free_displacements(up)

    def pair_displacements(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The free displacements of the listed pairs' facets (i, j) at patch values ``up``;
        raises where the list is stale."""
        uc = self.free_displacements(up)
        self.pair_list.check_listed(uc)
        return uc[self.listed.i], uc[self.listed.j]

    def gaps_and_overlaps(self, p, ui, uj, closed: bool = False):
        """Gap g, overlap w and its gradient dw/du_j = -dw/du_i (d-vectors) of the pairs ``p``
        for their facets' free displacements ui, uj (one row per entry). Each facet translates,
        so w depends on the tangential offset s = t (u_j - u_i) only (``overlap.overlap``). ``closed``:
        w and dw only where g < 0 (0 elsewhere), all that the natural piece c_p = w_p g_p^- reads:
        the open pairs, most of the list, are not clipped."""
        L = self.listed
        g = self.gaps(p, ui, uj)
        w, dw = np.zeros(len(g)), np.zeros((len(g), self.d))
        e = np.flatnonzero(g < 0) if closed else np.arange(len(g))
        t = L.t[p[e]]
        w[e], dw_t = overlap(L.si, L.sj, p[e], np.einsum("eki,ei->ek", t, uj[e] - ui[e]))
        dw[e] = np.einsum("ek,eki->ei", dw_t, t)
        return g, w, dw

    def free_flight(self, uc: np.ndarray, vp: np.ndarray, dt: float,
                    screen: bool = True) -> tuple[np.ndarray, tuple[int, float], np.ndarray | None]:
        """A step's free flight from the free facet displacements ``uc`` and the patch values
        ``vp`` of the velocity (``events.screen_flight``): (vc, (k, ratio), the screened pairs or
        None); the screen is kept for the state at the flight's end (``PairState``)."""
        vc, k, ratio, touching, flight = screen_flight(self.pair_list, uc, vp, dt, screen)
        if touching is not None:
            self._end = flight
        return vc, (k, ratio), touching

    def gaps(self, p, ui, uj) -> np.ndarray:
        """Gap g of the pairs ``p`` (eq. (22), (30)) for their facets' free displacements ui, uj."""
        L = self.listed
        return L.d0[p] + np.einsum("ei,ei->e", uj - ui, L.n[p])

    @_timed
    def energy_correction(self, up: np.ndarray) -> tuple[float, float]:
        """(elastic, stabilisation) energy changes of this process's own rows (not reduced)."""
        return self.state(up).pairs.energy

    def force_correction(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """This process's part of F - F_free at the patch dofs: the terms of its own rows (the
        exact negative gradient of the energy change, summed over processes). ``active`` (statics:
        sorted ``pair_keys``) imposes the piece: c_p = w_p g_p on those pairs whatever the sign of
        g_p, 0 on the others; default the natural one, c_p = w_p g_p^-."""
        L = self.listed
        ui, uj = self.pair_displacements(up)
        p = np.arange(len(L))
        self.evaluations += 1
        g, w, dw = self.gaps_and_overlaps(p, ui, uj, closed=active is None)
        on = g < 0 if active is None else np.isin(self.pair_keys(), active)
        c = np.where(on, w * g, 0.0)
        if not (c != 0).any():
            return np.zeros_like(up)
        a = L.Q @ up + self.row_lift
        delta = L.Z @ c
        mu = np.where(on, L.ZT @ (a + delta), 0.0)
        return -(L.QT @ delta) + self._facet_force(p, mu, g, w, dw)

    def _facet_force(self, p, mu, g, w, dw):
        """R^T of the facet forces -mu dc_p/du of the entries (pairs p): dc/du_f' = w n + g dw,
        dc/du_f = -(that)."""
        facet_force = np.zeros(len(self.facets_all) * self.d)
        lib.dem_pair_facet_forces(self.pair_list.c_pairs.c, len(p), pointer(p), pointer(mu), pointer(g), pointer(w),
                                  pointer(dw), pointer(facet_force))  # compiled: ``dem_pair_facet_forces``
        return self.pair_list.RT @ facet_force

    def add(self, correction: np.ndarray, out: PETSc.Vec, scale: float = 1.0) -> None:
        """out += scale * correction (patch values; a reverse scatter, collective)."""
        self.scatter.add(correction, out, scale)

    def add_force(self, u: PETSc.Vec, out: PETSc.Vec, active: np.ndarray | None = None) -> None:
        """out += F - F_free at u (collective); ``active`` as in ``force_correction``."""
        self.scatter.add(self.force_correction(self.patch_values(u), active), out)
    # -- events --------------------------------------------------------------------------------
    @_timed
    def force_integral(self, up: np.ndarray, vp: np.ndarray, dt: float, out: PETSc.Vec) -> int:
        """out += int_0^dt (F - F_free)(u + tau v) dtau, split at the events and integrated by
        d-point Gauss-Legendre on each piece (module docstring), for the patch values up, vp of
        u and v that ``prepare`` returned; returns the number of force evaluations of the pair
        integral with the most pieces (collective)."""
        flight = self._flight
        if flight is None or flight.up is not up or flight.vp is not vp or flight.dt != dt:
            raise StateError("force_integral needs the patch values that prepare(u, v, dt) returned for this step")
        normal = None if self.friction is None else self.friction.start(len(self.listed), flight.quiet)
        if flight.quiet:  # no pair touches during the step, on any process
            return 0
        # The pairs whose c_p may not vanish during the step (``free_flight``, in ``prepare``): the
        # others add exact zeros, and splitting their neighbours at their events would only cost.
        result = self.scatter.zeroed()  # the kernel sums into the scatter's own array
        pieces = 0
        screen = flight.screen.flight  # raises if a later flight of the list was screened since
        if screen.c.n_touching:
            if len(result) != self.pair_list.Rc.c.n_cols:
                raise StateError("the force integral's patch and the facets' reconstructions disagree")
            pieces = integrate_flight(self.pair_list, self._c_patch, self._c_gauss, self._work, up, screen,
                                      result, normal)
        self.scatter.add_zeroed(out)
        self.evaluations += len(self._gauss[0]) * pieces
        return len(self._gauss[0]) * pieces

    def add_friction(self, state, impulse: PETSc.Vec) -> float:
        """impulse += the step's frictional impulses; returns this process's dissipation (>= 0;
        ``PairFriction.apply``, collective). Frictionless: 0, nothing added."""
        return 0.0 if self.friction is None else self.friction.apply(state, impulse)

    # -- outputs (pair_outputs.py) ------------------------------------------------------------------
    def gradient_correction(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(owned cells, change of their gradient (eq. (8))) (``PairOutputs.gradient_correction``)."""
        return self.outputs.gradient_correction(up)

    def output_columns(self) -> tuple[str, ...]:
        """The series columns of the outputs (``PairOutputs.output_columns``)."""
        return self.outputs.output_columns()

    def output_sums(self, up: np.ndarray) -> np.ndarray:
        """This process's parts of the outputs' sums (``PairOutputs.output_sums``)."""
        return self.outputs.output_sums(up)

    def output_values(self, up: np.ndarray, sums: np.ndarray) -> list[float]:
        """The outputs from the reduced sums (``PairOutputs.output_values``; collective)."""
        return self.outputs.output_values(up, sums)

    def statics(self) -> PairStatics:
        """The statics interface (contact/pair_statics.py), made once."""
        if self._statics is None:
            self._statics = PairStatics(self)
        return self._statics

    # -- checkpoint (ContactModel) ----------------------------------------------------------------
    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """This process's counters and the keys of the pairs that used the scheme B rule. The
        list itself is not stored: the restored model rebuilds it at the restored displacements,
        which changes the forces by nothing (pairs that are listed but do not touch add exact
        zeros, and the directions e_f depend on the reference geometry only)."""
        return {"scheme_b_rule": self.pair_list.scheme_b_rule,
                "counters": np.array([self.rebuilds, self.evaluations, self.exchanges], dtype=np.int64),
                "seconds": np.array([self.seconds])}

    def cell_state(self) -> dict[str, np.ndarray]:
        """With friction, the pairs' lagged normal forces as ``friction_pairs`` at their facet i's
        cell (``PairLag.table``; collective); the model's other states are functions of u or kept
        by the same partition only."""
        return {} if self.friction is None else {"friction_pairs": self.friction.lag.table()}

    def restore_cell_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Friction's lagged normal forces from ``cell_state``."""
        if self.friction is not None:
            self.friction.lag.restore(state["friction_pairs"])

    def restore_state(self, state: Mapping[str, np.ndarray] | None) -> None:
        """The list is rebuilt at the next ``prepare``; the counters and the scheme B pairs are
        those of the same partition's ``checkpoint_state``, or start again (None: another
        partition). The facets known stay those of the last exchange, and so does its
        reference: the next ``prepare`` exchanges again if the restored displacements are
        farther from it than any step may drift (a resumed run's model exchanged at u = 0)."""
        self.pair_list.reference.fill(np.inf)  # in place: the list's struct (``c_pairs``) points to it
        if state is not None:
            self.pair_list.scheme_b_rule = np.asarray(state["scheme_b_rule"], dtype=np.int64)
            self.pair_list.rebuilds, self.evaluations, self.pair_list.exchanges = (int(x) for x in state["counters"])
            self.seconds = float(state["seconds"][0])

