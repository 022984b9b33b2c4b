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

Broad phase: a pair is listed (a Verlet list built with a k-d tree on the displaced facet
centres) when its centres are closer than r_p = rho_f + rho_f' + (s_f + s_f')/2, rho the largest
distance from a facet's barycentre to its vertices (half the length in 2D) and s its Verlet skin,
by default its own diameter 2 rho (or one uniform skin given by the user): the list follows the
local facet size, so a contact zone refined far below the rest of the boundary lists few pairs.
In an exchange each process sends the records of its own candidate facets to the processes
they come within the exchange radius R = 3 max r_p of: those within R of one of the boxes that
summarise the other process's local facets (at most 16 boxes of nearby facets per process, all
gathered); the receiver keeps those within R of one of its local facets (every facet known
costs at each step). A process's list is stale when a facet it knows (local or ghost) has moved
more than half its skin since it built the list: an unlisted pair's centres are then still
farther apart than rho_f + rho_f', so its facets cannot touch. When a process is stale (one
logical reduction per step in ``prepare``), a round of the lists (``_build``) rebuilds its list
from the facets it knows; the others keep theirs: a fast facet does not rebuild the lists far
from it. The round exchanges facets first only when a local facet has drifted more than
max r_p - max s/2 since the last exchange (the same reduction): every list is then built where
the drifts are below that, a valid list's facets stay within s/2 of where it was built, and a
facet a process does not know stays farther than max r_p from its local facets. After an
exchange the processes that receive a facet new to them rebuild too.
``prepare`` checks both ends of the coming step (the flight is affine); every evaluation checks
that the list is valid for its displacements and raises otherwise (never a silently incomplete
list); so does a step that moves a facet by more than half its skin.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
import time

import numpy as np
import scipy.sparse
import scipy.spatial
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import bodies as _bodies
from dolfinx_dem.conditions import facet_indices
from dolfinx_dem.contact import candidates
from dolfinx_dem.kernels import Struct, arena, csr, csr_of, ffi, lib, pointer
from dolfinx_dem.contact.pair_statics import PairStatics
from dolfinx_dem.contact.patch import PatchScatter
from dolfinx_dem.errors import InputError, KernelMemoryError, StateError, UnresolvedContactError



@dataclasses.dataclass
class _Facets:
    """Candidate facets (local ones first, then ghosts): global facet number ``key``, owner,
    body, barycentre, outward unit normal, measure |f| (``length``: an area in 3D), vertex
    coordinates (``ends``), global vertex numbers, scheme A
    data (the tensor C a_f / |c| of ``PairContact._directions``), and the free reconstruction
    u_f = R_f u + lift as d rows of M (global dof, value) entries (dof -1: padding)."""

    key: np.ndarray  # (n,)
    index: np.ndarray  # (n,) the facet's number among all candidates (own facets numbered by rank)
    owner: np.ndarray  # (n,)
    body: np.ndarray  # (n,)
    centre: np.ndarray  # (n, d)
    normal: np.ndarray  # (n, d)
    length: np.ndarray  # (n,)
    ends: np.ndarray  # (n, d, d) vertex coordinates
    vertex_ids: np.ndarray  # (n, d)
    scheme_a: np.ndarray  # (n,) bool
    Ca: np.ndarray  # (n, d, d, d)
    R_dofs: np.ndarray  # (n, d, M) global dofs, -1 padding
    R_values: np.ndarray  # (n, d, M)
    lift: np.ndarray  # (n, d)

    FLOATS = ("centre", "normal", "length", "ends", "Ca", "R_values", "lift")
    INTS = ("key", "index", "owner", "body", "vertex_ids", "scheme_a", "R_dofs")

    def __len__(self) -> int:
        return len(self.key)

    def take(self, k: np.ndarray) -> _Facets:
        return _Facets(**{f.name: getattr(self, f.name)[k] for f in dataclasses.fields(self)})

    def records(self) -> tuple[np.ndarray, np.ndarray]:
        """(float rows, integer rows): one row per facet, to send to other processes."""
        n = len(self)
        flat = lambda a: a.reshape(n, int(np.prod(a.shape[1:], dtype=np.int64)))  # noqa: E731
        floats = np.concatenate([flat(getattr(self, name)) for name in self.FLOATS], axis=1)
        ints = np.concatenate([flat(getattr(self, name)).astype(np.int64) for name in self.INTS], axis=1)
        return floats, ints

    def from_records(self, floats: np.ndarray, ints: np.ndarray) -> _Facets:
        """Facets from ``records`` rows, shaped like this instance's arrays."""
        out, k = {}, 0
        for name in self.FLOATS:
            shape = getattr(self, name).shape[1:]
            width = int(np.prod(shape, dtype=np.int64))
            out[name] = floats[:, k : k + width].reshape((-1,) + shape)
            k += width
        k = 0
        for name in self.INTS:
            template = getattr(self, name)
            width = int(np.prod(template.shape[1:], dtype=np.int64))
            out[name] = ints[:, k : k + width].reshape((-1,) + template.shape[1:]).astype(template.dtype)
            k += width
        return _Facets(**out)

    @staticmethod
    def concatenate(parts: list[_Facets]) -> _Facets:
        return _Facets(**{f.name: np.concatenate([getattr(p, f.name) for p in parts])
                          for f in dataclasses.fields(_Facets)})


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
    """

    tracks_momentum = True

    def __init__(self, dem, facets, self_contact: bool = False, skin: float | None = None,
                 tolerance: float = 0.0, tag: int | None = None):
        geom, rec, d = dem.geometry, dem.reconstruction, dem.d
        if d not in (2, 3):
            raise InputError(f"contact between deformable bodies is implemented in 2D and 3D, not {d}D")
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
        self._rigid = np.zeros(geom.num_bodies, dtype=bool)  # the prescribed bodies, by body number
        self._rigid[dem.prescribed.body_numbers] = True
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
        self._facets = self._local_records(order, f, cell, numbers)
        self._own_records = self._facets.take(np.arange(self.num_own)).records()  # what a list round sends
        self._local_keys = np.sort(self._facets.key)
        # a list round summarises the local facets' places by the boxes of at most _SUMMARY_BOXES
        # groups of nearby facets (``_bisection`` of the reference barycentres, fixed)
        self._groups = _bisection(self._facets.centre, _SUMMARY_BOXES)
        self.num_facets = self.comm.allreduce(self.num_own, op=MPI.SUM)
        self._facet_vector = PETSc.Vec().createMPI((self.num_own * d, PETSc.DECIDE), comm=self.comm)
        dofs = (self.facets[:, None] * d + np.arange(d)).ravel()
        QF = rows.QF[: rows.num_owned][:, dofs]  # CSC
        touched = np.unique(QF.indices)  # the own rows touched
        self._QF = _CSC(QF[touched], d)  # (own rows touched, local facet dofs)
        self._Q = rows.Q[touched]  # held-dof columns
        # the global dofs these rows read (sorted), the patch's first dofs whatever the list, and
        # Q on them (``_build`` widens it to the patch)
        self._row_dofs, entry_dof = np.unique(dem.columns[self._Q.indices], return_inverse=True)
        self._Q_entry_dof = entry_dof.astype(np.int32)
        self._q = dem.data.row_lift(touched)
        self._is_elastic_row = (touched < rows.num_elastic).astype(np.int8)
        # the kernels' structs of what stays (``dem_patch``: Q on the patch's first dofs, its
        # rows' dofs), and their work memory
        Q = csr(self._Q.indptr, self._Q_entry_dof, self._Q.data, len(self._row_dofs))
        self._c_patch = Struct("dem_patch", Q=Q, q=self._q, elastic=self._is_elastic_row)
        self._work = arena()
        an = geom.facet_area_normals[self.cells, geom.facet_local[self.facets, 0]]
        self._grad_weights = an / geom.cell_volumes[self.cells, None]
        # Verlet skins: each facet's own diameter about its barycentre (the length in 2D) unless
        # one uniform skin is given; the list radius of a pair is its facets' reaches plus their
        # mean skin (``_build``), so a refined contact zone lists few pairs.
        if skin is not None and not skin > 0:
            raise InputError(f"the Verlet skin must be > 0, got {skin}")
        self._uniform_skin = None if skin is None else float(skin)
        self._local_reach = reach = _reach(self._facets)
        skins = self._skins(reach)
        # the mean diameter of the candidate facets (about their barycentres): the scale of the
        # penetration the reconstructions may leave (``penetration``)
        self.facet_size = 2.0 * self.comm.allreduce(float(reach[: self.num_own].sum()), op=MPI.SUM) / self.num_facets
        # the smallest skin (a length scale for tolerances) and the largest pair radius (the
        # reach of the broad phase's exchange between processes)
        self.skin = self.comm.allreduce(float(skins.min(initial=np.inf)), op=MPI.MIN)
        self.radius = self.comm.allreduce(float((2.0 * reach + skins).max(initial=0.0)), op=MPI.MAX)
        # how far (relative gap, separations) the screen of a flight looks beyond its end for the
        # pairs that may be closed there (``_At``): far above rounding
        self._slack = 1e-9 * self.radius
        # A list round exchanges facets between processes only when a local facet has drifted
        # more than r - s/2 since the last exchange (r the largest pair radius, s the largest
        # skin: ``_drifted``), and then each process learns the other processes' facets within
        # the exchange radius 3 r of its local facets. Every list is built where the drifts are
        # at most r - s/2, and a valid list's facets are within s/2 of where it was built, so
        # the drifts stay below r and the facets a process does not know farther than r from
        # its own; its rounds in between rebuild its list from the facets it knows, alone.
        self.exchange_radius = 3.0 * self.radius
        self._exchange_drift = self.radius - 0.5 * self.comm.allreduce(float(skins.max(initial=0.0)), op=MPI.MAX)
        self._exchanged = None  # the local facets' free displacements at the last exchange (``_build``)
        self._gauss = _gauss_legendre(d)
        self._c_gauss = Struct("dem_gauss", n=len(self._gauss[0]), xi=self._gauss[0], wq=self._gauss[1])

        # The body pairs (i < j) whose force is an output: both bodies hold candidate facets.
        held = np.bincount(self._facets.body[: self.num_own], minlength=geom.num_bodies).astype(np.int64)
        self.comm.Allreduce(MPI.IN_PLACE, held, op=MPI.SUM)
        bodies = np.flatnonzero(held)
        self.body_pairs = [(int(a), int(b)) for k, a in enumerate(bodies) for b in bodies[k + 1:]]
        self._body_pair_index = np.full((geom.num_bodies, geom.num_bodies), -1, dtype=np.int64)
        for k, (a, b) in enumerate(self.body_pairs):
            self._body_pair_index[a, b] = self._body_pair_index[b, a] = k

        self.evaluations = 0
        self.rebuilds = 0  # list builds on this process
        self.exchanges = 0  # exchanges of facets between processes (list rounds that make the ghosts)
        self._scheme_b_rule = np.empty(0, dtype=np.int64)  # keys of pairs under the B rule (own ones)
        self._statics = None  # the statics interface, made on first use (``statics``)
        self.seconds = 0.0  # processor time of the contact work of the steps (``_timed``)
        self._timing = False  # inside a ``_timed`` method
        self._template = zero = dem.create_vector()  # the layout of the scatters' source vectors
        self.scatter = None  # the patch scatter, made by the list rounds (``_remake_scatters``)
        self._facet_values = None  # the scatter of the facet corrections (outputs), made on first use
        self._last = None  # the _At of the last displacement evaluated (a step's end is the next one's start)
        self._flight = None  # (up, vp, dt, free facet velocities) of the flight ``prepare`` checked last
        self._end = None  # (list, uc, vc, dt, candidates) of the last flight's screen (``_At``)
        self._build(self._facets.lift.copy())  # the free facet displacements at u = 0: R 0 + lift
        up = self.patch_values(zero)
        g, w = self._state(np.arange(len(self.listed)), *self._pair_displacements(up))[:2]
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

    def _local_records(self, order, f, cell, numbers) -> _Facets:
        """The candidate records of the local facets ``f[order]`` (cells ``cell[order]``,
        candidate numbers ``numbers``)."""
        dem, geom, rec, d = self.dem, self.dem.geometry, self.dem.reconstruction, self.d
        f, cell = f[order], cell[order]
        n = len(f)
        an = geom.facet_area_normals[cell, geom.facet_local[f, 0]]
        length = np.linalg.norm(an, axis=1)
        mask = np.ones((n, d + 1), dtype=bool)
        mask[np.arange(n), geom.facet_local[f, 0]] = False
        R = rec.R[(f[:, None] * d + np.arange(d)).ravel()].tocsr()
        width = self.comm.allreduce(int(np.diff(R.indptr).max(initial=0)), op=MPI.MAX)
        R_dofs = np.full((n * d, width), -1, dtype=np.int64)
        R_values = np.zeros((n * d, width))
        counts = np.diff(R.indptr)
        rank = np.arange(R.nnz) - np.repeat(R.indptr[:-1], counts)
        rows = np.repeat(np.arange(n * d), counts)
        R_dofs[rows, rank] = dem.columns[R.indices]
        R_values[rows, rank] = R.data
        scheme_a = np.isin(f, rec.scheme_a_facets)
        C = dem.materials.elasticity_tensor(d, cell)
        # A_f x = (C_c : (x (x) a_f)) n / |c| for the pair's normal n: einsum with the cell's C and a_f.
        Ca = np.einsum("nijkl,nl->nijk", C, an) / geom.cell_volumes[cell, None, None, None]
        return _Facets(
            key=geom.facet_global[f], index=numbers, owner=geom.cell_owner[cell], body=geom.cell_bodies[cell],
            centre=geom.facet_centres[f], normal=an / length[:, None], length=length,
            ends=geom.cell_vertices[cell][mask].reshape(n, d, d),
            vertex_ids=geom.cell_vertex_ids[cell][mask].reshape(n, d), scheme_a=scheme_a,
            Ca=np.where(scheme_a[:, None, None, None], Ca, 0.0),
            R_dofs=R_dofs.reshape(n, d, width), R_values=R_values.reshape(n, d, width),
            lift=dem.data.facet_lift(f),
        )

    # -- broad phase ---------------------------------------------------------------------------
    def _build(self, uc: np.ndarray, stale: bool = True, exchange: bool = True):
        """A round of the Verlet lists at displacements u, the known facets' free displacements
        there ``uc`` (n_known, d) (collective if ``exchange``, and then on every process): with
        an ``exchange`` every process sends the records of its own candidate facets to the
        processes whose local facets they come within ``exchange_radius`` of (``_exchange``);
        then a process rebuilds its list (the facing pairs with a local facet whose displaced
        centres are closer than their radius) if it is ``stale`` or received a facet it did not
        know, and the others keep theirs: a fast facet rebuilds the lists of the processes near it
        only. Without an exchange a stale process rebuilds its list from the facets it knows,
        and its patch and scatters stand.

        Why a list stays valid: each process checks its known facets against the places they had
        at its last rebuild (``_moved``), so its pairs of known facets are safe; a facet it does
        not know was farther than ``exchange_radius`` = r + 2 r from each of its local facets at
        the last exchange (r the largest pair radius), and each of the two has drifted less than
        r since (``prepare`` exchanges beyond r - s/2 at a list build, s the largest skin, and a
        valid list's facets are within s/2 of where it was built): they are farther apart than
        any pair radius."""
        comm, local = self.comm, self._facets
        nl = len(local)
        if not exchange:
            if stale:  # the same known facets, patch and reconstructions: the list only
                self._list(self.facets_all, uc)
            return
        self._exchanged = uc[:nl].copy()
        self.exchanges += comm.size > 1
        ghosts, uc_ghosts = self._exchange(uc[:nl])  # none on one process
        if not stale and np.isin(ghosts.key, self.facets_all.key[nl:]).all():
            # nothing new near this process: its list stands, and so do its scatters' dofs
            self._remake_scatters(self.scatter.dofs, self.facets_all)
            return
        F = _Facets.concatenate([local, ghosts])
        ucF = np.concatenate([uc[:nl], uc_ghosts])
        # The patch: the own rows' held dofs and the reconstruction dofs of every known facet
        # (the ghosts' too: their motion decides when the list is stale), and its scatters, first:
        # every process reaches this collective soon after the exchange, and the list's work
        # below, however unequal between processes, is waited for once (at the next gather).
        # The patch is the rows' dofs, then the facets' other reconstruction dofs (sorted; often
        # none: scheme B, R_f u = u_c): Q's columns are the rows' dofs' fixed numbers.
        R, extra = _reconstruction_matrix(F, self._row_dofs)  # (n_facets d, patch)
        patch = np.concatenate([self._row_dofs, extra]) if len(extra) else self._row_dofs
        self._remake_scatters(patch, F)
        self.facets_all = F
        self._facet_bodies = np.ascontiguousarray(F.body, dtype=np.int64)  # for ``dem_pair_body_forces``
        self._R = R
        self._Rc = csr_of(R)  # for the compiled products (``free_displacements``)
        self._RT = self._R.T  # CSC: its products sum in the order of R^T as CSR, without the copy
        self._lift = np.ascontiguousarray(F.lift, dtype=np.float64).reshape(-1, self.d)
        self._p_lift = pointer(self._lift)
        self._known_reach = np.concatenate([self._local_reach, _reach(ghosts)])
        self._list(F, ucF)

    def _list(self, F: _Facets, ucF: np.ndarray) -> None:
        """The Verlet list of the known facets ``F`` at free displacements ``ucF`` (``_build``)."""
        d, nl = self.d, len(self._facets)
        x = F.centre + ucF
        reach = self._known_reach
        skins = self._skins(reach)
        tree = scipy.spatial.cKDTree(x)
        pairs = tree.query_pairs(self.radius, output_type="ndarray")
        i, j = pairs[:, 0], pairs[:, 1]
        # The tests keep the same pairs in any order: the cheap and selective ones first (within
        # the largest radius, most pairs are neighbours on one body's boundary).
        if not self.self_contact:
            i, j = _where(F.body[i] != F.body[j], i, j)
        # with a local facet; not two imposed motions
        i, j = _where(((i < nl) | (j < nl)) & ~(self._rigid[F.body[i]] & self._rigid[F.body[j]]), i, j)
        i, j = _where(np.einsum("pi,pi->p", F.normal[i], F.normal[j]) < 0, i, j)  # facing facets only
        # a pair's own radius: its facets' reaches plus their mean skin. Until a facet moves
        # more than half its skin (``_moved``) an unlisted pair's centres stay farther apart
        # than its reaches: the facets cannot touch.
        dx = x[j] - x[i]
        i, j = _where(np.einsum("pi,pi->p", dx, dx) < (reach[i] + reach[j] + 0.5 * (skins[i] + skins[j]))**2, i, j)
        if self.self_contact:  # never two facets of one body that share a vertex
            shared = (F.vertex_ids[i][:, :, None] == F.vertex_ids[j][:, None]).any(axis=(1, 2))
            i, j = _where(~((F.body[i] == F.body[j]) & shared), i, j)
        swap = F.key[i] > F.key[j]  # the facet with the smaller global number first: one order
        i, j = np.where(swap, j, i), np.where(swap, i, j)  # on every process
        o = np.lexsort((F.key[j], F.key[i]))
        i, j = i[o], j[o]
        n = F.length[i, None] * F.normal[i] - F.length[j, None] * F.normal[j]
        n /= np.linalg.norm(n, axis=1)[:, None]
        t = _tangents(n)
        e_i, e_j = self._directions(F, i, j, n)

        # z_p restricted to the own rows: the local facets' entries only, Z^T = E^T QF^T with E
        # the facet dofs' directions (``dem_pair_rows``).
        ZT = self._QF.pair_rows(i, j, e_i, e_j, F.length)  # (P, own rows touched)
        Qp = scipy.sparse.csr_matrix((self._Q.data, self._Q_entry_dof, self._Q.indptr),
                                     shape=(self._Q.shape[0], len(self.scatter)))
        # the facets projected on the plane normal to n, origin at f_i's barycentre; n . n_f >
        # |f| / (|f| + |f'|) for facing facets, so no projection degenerates
        si, sj = _Simplices.of(_project(F, i, i, t)), _Simplices.of(_project(F, j, i, t))
        self.listed = _Pairs(
            i=i, j=j, n=n, t=t, e_i=e_i, e_j=e_j,
            d0=np.einsum("pi,pi->p", F.centre[j] - F.centre[i], n),
            si=si, sj=sj, sep=_separations(si, sj),
            ZT=ZT, Q=Qp,
        )
        self._reference = ucF.copy()
        self._half_skin2 = 0.25 * skins**2  # of the known facets
        self._c_pairs = self.listed.struct(self._Rc, self._lift, self._reference, self._half_skin2, self._slack)
        self.rebuilds += 1

    def _exchange(self, uc: np.ndarray) -> tuple[_Facets, np.ndarray]:
        """The ghost facets of an exchange (collective) and their free displacements, for the
        local facets' free displacements ``uc``: every process summarises its local facets'
        places by the boxes of its facet groups (``_groups``) and its own facets' box, all
        gathered (a fixed size per process); it sends each other process the own facets within
        the exchange radius R of one of that process's boxes, and keeps of the facets it
        receives those new to it that come within R of one of its local facets. The boxes cut
        what is sent (one box per process would hold most of another part's boundary with a
        graph partition), the last test what is kept: every ghost costs at each step (its
        motion, its dofs in the patch)."""
        comm, d, r, local = self.comm, self.d, self.exchange_radius, self._facets
        x = local.centre + uc
        own = x[: self.num_own]
        summary = np.empty((1 + _SUMMARY_BOXES, 2 * d))
        summary[:] = np.concatenate([np.full(d, np.inf), np.full(d, -np.inf)])  # empty boxes
        summary[0] = _box(own)
        perm, starts = self._groups
        if len(perm):
            y = x[perm]
            summary[1 : 1 + len(starts), :d] = np.minimum.reduceat(y, starts)
            summary[1 : 1 + len(starts), d:] = np.maximum.reduceat(y, starts)
        summaries = np.empty((comm.size,) + summary.shape)
        comm.Allgather(summary, summaries)
        lo, hi = summaries[:, 1:, :d] - r, summaries[:, 1:, d:] + r  # the other processes' boxes, widened
        mine = summary[0]
        meets = np.all((lo <= mine[d:]) & (mine[:d] <= hi), axis=2)  # (process, box) against the own box
        meets[comm.rank] = False
        send, sent = [None] * comm.size, np.zeros(self.num_own, dtype=bool)
        for q in np.flatnonzero(meets.any(axis=1)):
            b = np.flatnonzero(meets[q])
            # the own facets in the union of q's boxes, then those in one of them
            k = np.flatnonzero(np.all((own >= lo[q, b].min(axis=0)) & (own <= hi[q, b].max(axis=0)), axis=1))
            k = k[np.all((own[k, None] >= lo[q, b]) & (own[k, None] <= hi[q, b]), axis=2).any(axis=1)]
            send[q] = k
            sent[k] = True
        if sent.any():
            floats, ints = self._own_records
            k = np.flatnonzero(sent)
            rows = np.full(self.num_own, -1, dtype=np.int64)
            rows[k] = np.arange(len(k))
            floats = np.concatenate([floats[k], uc[k]], axis=1)  # with the sender's displacements
            ints = ints[k]
            send = [None if s is None else (floats[rows[s]], ints[rows[s]]) for s in send]
        received = [m for m in comm.alltoall(send) if m is not None]
        if not received:
            return local.take(np.empty(0, dtype=np.int64)), np.zeros((0, d))
        rf = np.concatenate([m[0] for m in received])
        ri = np.concatenate([m[1] for m in received])
        new = ~_find_sorted(self._local_keys, ri[:, 0])[1]
        ghosts, uc_ghosts = local.from_records(rf[new, :-d], ri[new]), rf[new, -d:]
        there = ghosts.centre + uc_ghosts
        if len(there):
            # the local facets near the new ones' box only: the rest are farther than R from all
            X = x[np.all((x >= there.min(axis=0) - r) & (x <= there.max(axis=0) + r), axis=1)]
            near = _near(X, there, r) if len(X) else np.zeros(len(there), dtype=bool)
            ghosts, uc_ghosts = ghosts.take(np.flatnonzero(near)), uc_ghosts[near]
        return ghosts, uc_ghosts

    def _remake_scatters(self, patch: np.ndarray, F: _Facets) -> None:
        """After a round of the lists (every process calls it): the patch scatter of the dofs
        ``patch``, and the scatter of the facet corrections of the known facets ``F`` from their
        owners (outputs; made on first use, ``_corrections_everywhere``). Making a scatter is
        collective and, in parallel, costs as much as the rest of a list build: each is kept
        when no process's dofs changed (one reduction), as a round with slow bodies mostly
        leaves them."""
        facet_dofs = (F.index[:, None] * self.d + np.arange(self.d)).ravel()
        keep = np.array([self.scatter is not None and np.array_equal(self.scatter.dofs, patch),
                         self._facet_values is not None and np.array_equal(self._facet_values.dofs, facet_dofs)],
                        dtype=np.int32)
        self.comm.Allreduce(MPI.IN_PLACE, keep, op=MPI.MIN)
        if not keep[0]:
            self.scatter = PatchScatter(self._template, patch)
        if not keep[1]:
            self._facet_values = None

    def _directions(self, F: _Facets, i: np.ndarray, j: np.ndarray, n: np.ndarray):
        """The contact corrections of a pair are u_f += (w/|f|) g^- e_f, u_f' += (w/|f'|) g^- e_f'.

        Scheme B (eq. (26)-(27), theta = 1/2): e_f = n/2, e_f' = -n/2. Scheme A (eq. (23)-(24)),
        when both facets are scheme A facets: with A_f x = (C : (x (x) a_f)) n / |c| the change
        of cell c's traction on n when u_f changes by x, e_f = A_f^-1 n / D, e_f' = A_f'^-1 n / D,
        D = n . A_f^-1 n - n . A_f'^-1 n: the corrections change both cells' tractions on n by
        the same normal vector, and n . (e_f - e_f') = 1 closes the gap of a fully overlapping
        pair. (The tractions on n themselves are normal and equal only where the free ones
        vanish on n, i.e. when n = n_f = -n_f': the free facets carry zero traction on their
        own normals.)

        A facet of a prescribed body (``DEMDiscretisation.prescribed``) moves rigidly with it:
        e = 0 on it and the other facet takes the whole correction, e_f' = -n (or e_f = n), as a
        facet on a rigid obstacle does; a pair of two prescribed bodies is not listed.

        When eq. (23)-(24) are not well posed the pair uses the scheme B rule; ``scheme_b_pairs``
        counts such pairs (``summary.json``: ``contact_pairs_scheme_b_rule``). For isotropic C,
        n . A_f^-1 n = cos t_f / (alpha_f (2 cos^2 t_f (lambda + mu) - lambda)), alpha_f = |f|/|c|,
        t_f the angle between n and n_f: a cell's normal compliance has the sign of its facet
        normal's side only if cos^2 t_f > kappa = lambda / (2 (lambda + mu)) (nu in 3D and plane
        strain, nu/(1+nu) in plane stress; A_f maps the plane of n and n_f to itself, so the
        formula holds in 2D and 3D). The rule of eq. (23)-(24) is used when both cells'
        compliances have their sign (n . A_f^-1 n > 0 > n . A_f'^-1 n): then 0 < n . e_f < 1,
        0 < -n . e_f' < 1 and |e_f| = n . e_f / cos t_f < 1/sqrt(kappa), bounded. Otherwise
        D may vanish (unbounded corrections, an arbitrarily stiff pair), be negative (no
        solution: the correction would open the penetration further), or be positive with one
        facet moved further into the other body. Facing facets of equal length have
        t_f = t_f' < 45 deg, and kappa < 1/2, so only pairs of unequal facets whose normals are
        far from antiparallel (the longer facet tilts n towards its own normal) are affected.
        A set-up check cannot replace this rule: every pair of facing candidate facets could
        meet, and a curved boundary has facets of every orientation. The directions depend on
        the pair only, so the energy stays continuous and the force its exact gradient."""
        e_i, e_j = 0.5 * n, -0.5 * n
        both_a = F.scheme_a[i] & F.scheme_a[j]
        if both_a.any():
            k = np.flatnonzero(both_a)
            # A_f^-1 n = adj(A_f) n / det(A_f), so that a singular A_f is no error.
            y, compliance = [], []
            for f in (i, j):
                A = np.einsum("nijk,nj->nik", F.Ca[f[k]], n[k])
                adj_n, det = _adjugate_times(A, n[k])
                y.append(np.divide(adj_n, det[:, None], out=np.zeros_like(adj_n), where=det[:, None] != 0))
                compliance.append(np.where(det != 0, np.einsum("pi,pi->p", n[k], y[-1]), 0.0))
            posed = (compliance[0] > 0) & (compliance[1] < 0)
            D = compliance[0] - compliance[1]
            a = k[posed]
            e_i[a], e_j[a] = y[0][posed] / D[posed, None], y[1][posed] / D[posed, None]
            counted = k[~posed][F.owner[i[k[~posed]]] == self.comm.rank]  # the first facet's owner counts it
            keys = F.key[i[counted]] * (2**31) + F.key[j[counted]]
            self._scheme_b_rule = np.union1d(self._scheme_b_rule, keys)
        # A prescribed (rigid) body's facet keeps its imposed motion: the deformable facet takes
        # the whole correction (theta = 0 or 1 in eq. (26)-(27), as on a rigid obstacle).
        rigid_i, rigid_j = self._rigid[F.body[i]], self._rigid[F.body[j]]
        e_i[rigid_i], e_j[rigid_i] = 0.0, -n[rigid_i]
        e_i[rigid_j], e_j[rigid_j] = n[rigid_j], 0.0
        return e_i, e_j

    @property
    def num_pairs(self) -> int:
        """Listed pairs, each counted once (by the owner of its first facet); collective."""
        first = self.listed.i < self.num_own
        return self.comm.allreduce(int(first.sum()), op=MPI.SUM)

    @property
    def scheme_b_pairs(self) -> int:
        """How many distinct pairs of scheme A facets listed so far use the scheme B rule
        because eq. (23)-(24) are not well posed for them (see ``_directions``); collective."""
        return self.comm.allreduce(len(self._scheme_b_rule), op=MPI.SUM)

    @_timed
    def prepare(self, u: PETSc.Vec, v: PETSc.Vec | None = None, dt: float = 0.0,
                up: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Make the Verlet list valid for the states u + tau v, 0 <= tau <= dt (u alone without
        v): if a candidate facet known to some process would move more than half its skin from
        where it was at that process's last build, a round of the lists at u (``_build``), which
        rebuilds the list of that process; if a local facet would drift more than r - s/2 since
        the last exchange (``_drifted``; r the largest pair radius, s the largest skin), the
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
        at = self._at(up)
        uc, stale = at.uc, at.moved
        moving = v is not None and dt != 0.0
        # The flight's screen (``_free_flight``) before the reduction where the list stands, so that the
        # reduction also tells whether a pair anywhere may touch during the step: if none does
        # (and no list changes), ``force_integral`` adds nothing on every process.
        vc = screen = None
        if moving:
            vc, (_, ratio), screen = self._free_flight(uc, vp, dt, screen=not stale)
            stale = stale or ratio > 1.0
        drifted = self._drifted(uc, vc, dt)
        flags = np.array([stale, drifted, screen is None or len(screen) > 0], dtype=np.int32)
        self.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        stale_anywhere, drifted_anywhere, may_touch = flags.tolist()
        if stale_anywhere or drifted_anywhere:
            touching = self._touching_keys(at)
            R, scatter = self._R, self.scatter
            self._build(uc, stale, exchange=bool(drifted_anywhere))
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
                    "slide into each other's holes (docs/validation/contact3d.md). A larger skin lists deeper pairs "
                    "but does not stop the interpenetration")
            if moving:  # the flight again from the new list (and reconstructions)
                uc = self._at(up).uc
                vc, (k, ratio), screen = self._free_flight(uc, vp, dt)
                worst = (ratio, float(dt * np.linalg.norm(vc[k])), float(2.0 * np.sqrt(self._half_skin2[k]))) \
                    if k >= 0 else (0.0, 0.0, 0.0)
                ratio, motion, skin = self.comm.allreduce(worst, op=MPI.MAX)  # the worst facet's
                if ratio > 1.0:
                    raise UnresolvedContactError(
                        f"contact between bodies: a candidate facet moves {motion:.3e} m in one step, more than half "
                        f"the Verlet skin ({skin:.3e} m): no pair list covers the step; reduce the time step or "
                        "pass a larger skin")
        # the flight checked valid at both ends, kept for ``force_integral`` (the free facet
        # velocities and the screen too: none is computed twice per step), and whether no pair
        # touches anywhere during it
        quiet = not (drifted_anywhere or may_touch)
        self._flight = (up, vp, float(dt), vc, screen, quiet) if moving else None
        return up, vp

    def _touching_keys(self, at: _At) -> np.ndarray:
        """Keys of the listed pairs in contact (g < 0, w > 0) in the state ``at`` (none if the list
        is stale there: the keys a rebuild must list again). The state the last step's energy
        left: its screen holds every touching pair."""
        if at.moved:
            return np.empty(0, dtype=np.int64)
        return self.pair_keys()[at.closed[(at.g < 0) & (at.w > 0)]]

    def _skins(self, reach: np.ndarray) -> np.ndarray:
        """The Verlet skins of facets of reaches ``reach``: the uniform skin if one was given,
        else each facet's diameter about its barycentre, 2 reach."""
        return 2.0 * reach if self._uniform_skin is None else np.full(len(reach), self._uniform_skin)

    def _moved(self, uc: np.ndarray) -> bool:
        """Whether a facet known here (local or ghost) with free displacements ``uc`` has moved
        more than half its skin since the last list build (a pair not listed might then touch;
        the compiled ``dem_pair_worst_motion``)."""
        if len(uc) != self._c_pairs.c.n_facets:
            raise InputError(f"{len(uc)} free facet displacements for the {self._c_pairs.c.n_facets} known facets")
        ratio = np.zeros(1)
        lib.dem_pair_worst_motion(self._c_pairs.c, pointer(uc), pointer(ratio))
        return ratio[0] > 1.0

    def _drifted(self, uc: np.ndarray, vc: np.ndarray | None, dt: float) -> bool:
        """Whether a local facet with free displacements ``uc`` (those of the known facets), or
        ``uc`` + ``dt`` ``vc`` with ``vc``, has moved more than ``_exchange_drift`` since the last
        exchange; never on one process."""
        if self.comm.size == 1:
            return False
        ends = [uc] if vc is None else [uc, uc + dt * vc]
        moved = [x[: len(self._exchanged)] - self._exchanged for x in ends]
        return any(bool((np.einsum("ni,ni->n", m, m) > self._exchange_drift**2).any()) for m in moved)

    def motion_ratio(self, dp: np.ndarray) -> float:
        """The largest motion of a candidate facet's free reconstruction for the patch values
        ``dp`` of a displacement change, relative to half its skin (collective): a change with a
        ratio up to 1 meets no pair that the list built before it misses."""
        motion2 = np.einsum("ni,ni->n", *2 * ((self._R @ dp).reshape(-1, self.d),))
        ratio = np.sqrt((motion2 / self._half_skin2).max(initial=0.0))
        return self.comm.allreduce(float(ratio), op=MPI.MAX)

    def _check_listed(self, uc: np.ndarray):
        if self._moved(uc):
            raise StateError("contact between bodies: the candidate pair list is stale for these displacements "
                               "(a facet moved more than skin/2 since it was built); call prepare(u) first "
                               "(MEMM does it every step)")

    # -- energy and force ----------------------------------------------------------------------
    @_timed
    def patch_values(self, vec: PETSc.Vec) -> np.ndarray:
        """The values of ``vec`` at the patch dofs (collective); valid until the next rebuild."""
        return self.scatter.gather(vec)

    def _at(self, up: np.ndarray) -> _At:
        """The contact state at patch values ``up`` (``_At``), kept for the next call: the energy
        at the end of a step, the per-step outputs and the next step's flight start at the same
        displacement. Reused only for the same list and the same array, or bit-identical values
        of a writeable one (a caller's own; MEMM's read-only arrays are new with each state)."""
        last = self._last
        if last is None or last.listed is not self.listed or not (
                last.up is up or (up.flags.writeable and np.array_equal(last.up, up))):
            last = self._last = _At(self, up)
        return last

    def free_displacements(self, up: np.ndarray) -> np.ndarray:
        """Free reconstructions u_f = R_f u + lift_f of the known candidate facets (local, then
        ghosts), (n, d), from patch values ``up`` (the compiled ``dem_csr_apply``)."""
        uc = np.empty((len(self._lift), self.d))
        lib.dem_csr_apply(self._Rc.c, pointer(up), self._p_lift, pointer(uc))
        return uc

    def _pair_displacements(self, up: np.ndarray):
        uc = self.free_displacements(up)
        self._check_listed(uc)
        return uc[self.listed.i], uc[self.listed.j]

    def _state(self, p, ui, uj, closed: bool = False):
        """Gap g, overlap w and its gradient dw/du_j = -dw/du_i (d-vectors) of the pairs ``p``
        for their facets' free displacements ui, uj (one row per entry). Each facet translates,
        so w depends on the tangential offset s = t (u_j - u_i) only (``_overlap``). ``closed``:
        w and dw only where g < 0 (0 elsewhere), all that the natural piece c_p = w_p g_p^- reads:
        the open pairs, most of the list, are not clipped."""
        L = self.listed
        g = self._gap(p, ui, uj)
        w, dw = np.zeros(len(g)), np.zeros((len(g), self.d))
        e = np.flatnonzero(g < 0) if closed else np.arange(len(g))
        t = L.t[p[e]]
        w[e], dw_t = _overlap(L.si, L.sj, p[e], np.einsum("eki,ei->ek", t, uj[e] - ui[e]))
        dw[e] = np.einsum("ek,eki->ei", dw_t, t)
        return g, w, dw

    def _free_flight(self, uc: np.ndarray, vp: np.ndarray, dt: float,
                     screen: bool = True) -> tuple[np.ndarray, tuple[int, float], np.ndarray | None]:
        """A step's free flight uc + tau vc, 0 <= tau <= dt, from the free facet displacements
        ``uc`` (known facets' rows) and the patch values ``vp`` of the velocity, in one compiled
        call (``dem_pair_flight``): the free facet velocities vc = R_f v, (n, d); the known facet
        that moves farthest from where the list was built, at the flight's end, relative to half
        its skin: its index (-1 if none) and (|motion| / (s/2))^2; and, if ``screen`` and that
        ratio is at most 1 (else None), the screen: the listed pairs whose c_p = w_p g_p^- may
        not vanish during the flight, their gap negative at an end and their projections not
        separated by the line of a face at some tau (``_separations``: exact, less a margin; one
        pass over the list; ``dem_pair_end_state`` screens a state with it). The screen keeps those
        near closing at the flight's end for the state there (``_At``)."""
        L, n = self.listed, len(self.listed)
        if uc.shape != (self._c_pairs.c.n_facets, self.d):
            raise InputError(f"free facet displacements of shape {uc.shape} for {self._c_pairs.c.n_facets} known facets")
        flight = Struct("dem_flight", uc=uc, vp=vp, vc=np.empty(uc.shape), dt=float(dt), screen=np.empty(n, np.int8),
                        touching=np.empty(n, np.int64), candidates=np.empty(n, np.int64))
        k = lib.dem_pair_flight(self._c_pairs.c, int(screen), flight.c)
        vc, ratio, found = flight.arrays["vc"], float(flight.c.ratio), flight.c.n_touching
        if found < 0:
            return vc, (int(k), ratio), None
        self._end = (L, flight)  # its candidates, for the state at its end (``_At``)
        return vc, (int(k), ratio), flight.arrays["touching"][:found]

    def _gap(self, p, ui, uj):
        """Gap g of the pairs ``p`` (eq. (22), (30)) for their facets' free displacements ui, uj."""
        L = self.listed
        return L.d0[p] + np.einsum("ei,ei->e", uj - ui, L.n[p])

    @_timed
    def energy_correction(self, up: np.ndarray) -> tuple[float, float]:
        """(elastic, stabilisation) energy changes of this process's own rows (not reduced)."""
        return self._at(up).energy

    def force_correction(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """This process's part of F - F_free at the patch dofs: the terms of its own rows (the
        exact negative gradient of the energy change, summed over processes). ``active`` (statics:
        sorted ``pair_keys``) imposes the piece: c_p = w_p g_p on those pairs whatever the sign of
        g_p, 0 on the others; default the natural one, c_p = w_p g_p^-."""
        L = self.listed
        ui, uj = self._pair_displacements(up)
        p = np.arange(len(L))
        self.evaluations += 1
        g, w, dw = self._state(p, ui, uj, closed=active is None)
        on = g < 0 if active is None else np.isin(self.pair_keys(), active)
        c = np.where(on, w * g, 0.0)
        if not (c != 0).any():
            return np.zeros_like(up)
        a = L.Q @ up + self._q
        delta = L.Z @ c
        mu = np.where(on, L.ZT @ (a + delta), 0.0)
        return -(L.QT @ delta) + self._facet_force(p, mu, g, w, dw)

    def _facet_force(self, p, mu, g, w, dw):
        """R^T of the facet forces -mu dc_p/du of the entries (pairs p): dc/du_f' = w n + g dw,
        dc/du_f = -(that)."""
        facet_force = np.zeros(len(self.facets_all) * self.d)
        lib.dem_pair_facet_forces(self._c_pairs.c, len(p), pointer(p), pointer(mu), pointer(g), pointer(w),
                                  pointer(dw), pointer(facet_force))  # compiled: ``dem_pair_facet_forces``
        return self._RT @ facet_force

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
        if flight is None or flight[0] is not up or flight[1] is not vp or flight[2] != dt:
            raise StateError("force_integral needs the patch values that prepare(u, v, dt) returned for this step")
        uc, vc, touching, quiet = self._at(up).uc, flight[3], flight[4], flight[5]
        if quiet:  # no pair touches during the step, on any process
            return 0
        # The pairs whose c_p may not vanish during the step (``_free_flight``, in ``prepare``): the
        # others add exact zeros, and splitting their neighbours at their events would only cost.
        result = self.scatter.zeroed()  # the kernel sums into the scatter's own array
        pieces = 0
        if touching.size:
            # The rest in one compiled call (``dem_pair_force_integral``): each touching pair's
            # events (its gap's and its overlap's kinks); the pairs sharing an own row (N_pp' != 0)
            # integrated on common pieces, those cut by the events of their connected component of
            # that relation (an impact in another component does not split them), where every c_p
            # is a polynomial of degree d and each pair's force term one of degree 2 d - 1: the
            # d-point rule is exact; a pair's overlap clipped at the nodes of its own pieces only and
            # interpolated at its component's; the rows' term -Q^T Z int c dtau on the own rows the
            # touching pairs' z_p touch (a = Q u + q + tau Q v there: no sliced Q or Z) and the
            # pairs' term -int (z_p . (a + delta_a)) dc_p/du dtau at the facets.
            if len(result) != self._Rc.c.n_cols:
                raise StateError("the force integral's patch and the facets' reconstructions disagree")
            c_flight = Struct("dem_flight", uc=uc, vp=vp, vc=vc, dt=float(dt), touching=touching,
                              n_touching=len(touching))
            pieces = lib.dem_pair_force_integral(self._c_pairs.c, self._c_patch.c, pointer(up), c_flight.c,
                                                 self._c_gauss.c, self._work, pointer(result))
            if pieces < 0:
                raise KernelMemoryError("contact between bodies: out of memory in the force integral of a step")
        self.scatter.add_zeroed(out)
        self.evaluations += len(self._gauss[0]) * pieces
        return len(self._gauss[0]) * pieces

    # -- outputs -------------------------------------------------------------------------------
    def facet_corrections(self, up: np.ndarray) -> np.ndarray:
        """u_f - u_f^free of the local facets (eq. (31), directions of ``_directions``), (n_local, d):
        complete for the own facets (every pair of an own facet is listed here)."""
        F, at = self.facets_all, self._at(up)
        delta, work = np.zeros((len(F), self.d)), np.zeros((len(F), self.d))  # c = 0 off the closed pairs
        lib.dem_pair_facet_corrections(self._c_pairs.c, at.kernel_state.c, pointer(F.length), pointer(work),
                                       pointer(delta))
        return delta[: len(self.facets)]

    def gradient_correction(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(owned cells, change of their gradient (eq. (8))) of the own candidates, (n, d, d)."""
        own = slice(0, self.num_own)
        return self.cells[own], np.einsum("ni,nj->nij", self.facet_corrections(up)[own], self._grad_weights[own])

    def penetration(self, up: np.ndarray) -> float:
        """Largest interpenetration (m, >= 0) of the contact-aware facet reconstructions: over the
        own facets, the overlap-weighted mean over their touching partners (g < 0) of the reconstructed gap
        (x_f' + u_f' - x_f - u_f) . n, negated (collective). Eq. (31) makes it zero when each
        facet has one partner covering it exactly; partial overlaps (facets sliding against each
        other) leave a gap of the order of the cell gap times the uncovered fraction. The
        corrections of the partners come from their owners (a scatter over the candidates)."""
        F, at = self.facets_all, self._at(up)
        uf = at.uc + self._corrections_everywhere(up)
        weight, mean = np.zeros(len(F)), np.zeros(len(F))
        worst = np.array([lib.dem_pair_penetration(self._c_pairs.c, at.kernel_state.c, pointer(F.centre), pointer(uf),
                                                   self.num_own, pointer(weight), pointer(mean))])
        self.comm.Allreduce(MPI.IN_PLACE, worst, op=MPI.MAX)
        return float(worst[0])

    def _corrections_everywhere(self, up: np.ndarray) -> np.ndarray:
        """Facet corrections of every known facet (local and ghost), each from its owner (a
        scatter of the candidates' vector; collective)."""
        if self._facet_values is None:  # (re)made after a round that changed the known facets somewhere
            F, d = self.facets_all, self.d
            self._facet_values = PatchScatter(self._facet_vector, (F.index[:, None] * d + np.arange(d)).ravel())
        self._facet_vector.array[:] = self.facet_corrections(up)[: self.num_own].ravel()
        return self._facet_values.gather(self._facet_vector).reshape(-1, self.d)

    def pair_states(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gap g and overlap w of the pairs listed on this process (``listed``; indices into
        ``facets_all``: the local facets, then the ghosts)."""
        g, w, _ = self._state(np.arange(len(self.listed)), *self._pair_displacements(up))
        return g, w

    def touching_cells(self, up: np.ndarray) -> np.ndarray:
        """The local cells with a local facet in a touching pair (g < 0, w > 0)."""
        g, w = self.pair_states(up)
        on = (g < 0) & (w > 0)
        facets = np.concatenate([self.listed.i[on], self.listed.j[on]])
        return np.unique(self.cells[facets[facets < len(self.facets)]])

    def touching(self, up: np.ndarray) -> bool:
        """Whether some pair is in contact (g < 0 with a positive overlap), anywhere (collective)."""
        L = self.listed
        g, w, _ = self._state(np.arange(len(L)), *self._pair_displacements(up), closed=True)
        return self.comm.allreduce(bool(((g < 0) & (w > 0)).any()), op=MPI.LOR)

    def touch_time(self, u0: PETSc.Vec, u1: PETSc.Vec, dt: float) -> float | None:
        """For a step from displacements ``u0`` (no contact) to ``u1``: the time tau in [0, dt]
        at which the first pair touching at the end closed its gap (gaps are affine along the
        step); None if no pair touches (collective)."""
        L = self.listed
        uc0 = self.free_displacements(self.patch_values(u0))
        self._check_listed(uc0)
        at = self._at(self.patch_values(u1))
        touching = at.w > 0  # of the closed pairs (g < 0)
        first = np.inf
        if touching.any():
            p = at.closed[touching]
            g0, g1 = np.maximum(self._gap(p, uc0[L.i[p]], uc0[L.j[p]]), 0.0), at.g[touching]
            first = float(dt * (g0 / (g0 - g1)).min())
        first = self.comm.allreduce(first, op=MPI.MIN)
        return None if first == np.inf else first

    def contact_force(self, up: np.ndarray) -> float:
        """Total normal contact force (N; N/m in 2D): the signed sum over touching
        pairs of -(z_p . (a + delta_a)) w_p, the normal force one facet of the pair exerts on
        the other, compression positive (z_p . a' < 0 in compression), so that a pair pulling
        (z_p . a' > 0) lowers it. Between two bodies i, j whose contact facets share one outward
        normal n_i (on i) it is -n_i . F_ij of ``pair_forces`` (collective: the sum over the
        processes of ``contact_force_part``)."""
        return self.comm.allreduce(self.contact_force_part(up), op=MPI.SUM)

    def closed_count(self, up: np.ndarray) -> int:
        """How many listed pairs of this process may have c_p != 0 at ``up`` (the closed pairs:
        g_p < 0, projections not apart). Summed over the processes it is 0 when no pair touches
        anywhere, and then ``penetration`` is 0 (``model.contact_values`` skips it)."""
        return len(self._at(up).closed)

    def contact_force_part(self, up: np.ndarray) -> float:
        """This process's part of ``contact_force`` (its own rows' parts of mu_p), over the closed
        pairs (g < 0) alone: the sum must not depend on the pairs listed around them (w = 0 adds
        nothing)."""
        return 0.0 - self._at(up).mu_w

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
        L = self.listed
        if active is None:  # the natural piece: the closed pairs of the step's state
            state = self._at(up).kernel_state
        else:
            p = np.arange(len(L))
            g, w, dw = self._state(p, *self._pair_displacements(up))
            c = np.where(np.isin(self.pair_keys(), active), w * g, 0.0)
            mu = L.ZT @ (L.Q @ up + self._q + L.Z @ c)
            state = Struct("dem_pair_state", n=len(p), closed=p, g=g, w=w, dw=dw, c=c, mu=mu)
        out = np.zeros((len(self.body_pairs), self.d))
        if state.c.n == 0:
            return out
        missing = lib.dem_pair_body_forces(self._c_pairs.c, state.c, pointer(self._facet_bodies),
                                           len(self._body_pair_index), pointer(self._body_pair_index), pointer(out))
        if missing:  # every body with a candidate facet is in ``body_pairs``: a broken invariant
            raise StateError(f"contact between bodies: {missing} touching pairs join bodies that have no body pair "
                               "(bodies without candidate facets?)")
        return out

    def output_columns(self) -> tuple[str, ...]:
        """The summed normal contact force ``contact_force`` (``contact_force``), the largest
        interpenetration ``penetration`` of the contact reconstructions (``penetration``), and the
        force of body j on body i for each pair i < j of bodies with candidate facets,
        ``contact_force_<i>_<j>_<x|y|z>`` (``pair_forces``; bodies numbered as
        ``geometry.compute_bodies``, from 0)."""
        xyz = "xyz"[: self.d]
        return ("contact_force", "penetration") + tuple(f"contact_force_{i}_{j}_{c}" for i, j in self.body_pairs
                                                        for c in xyz)

    def output_sums(self, up: np.ndarray) -> np.ndarray:
        """This process's part of the sums of the outputs: the pair forces, the contact force and
        the count of closed pairs (``closed_count``)."""
        return np.concatenate([self.pair_forces(up).ravel(), [self.contact_force_part(up), self.closed_count(up)]])

    def output_values(self, up: np.ndarray, sums: np.ndarray) -> list[float]:
        """The values of ``output_columns`` from the reduced ``output_sums``: the penetration's
        scatter and reduction only where some process has a closed pair (collective)."""
        return [sums[-2], self.penetration(up) if sums[-1] > 0 else 0.0, *sums[:-2]]

    def pair_keys(self) -> np.ndarray:
        """A number for each listed pair that neither the partition nor a list rebuild changes:
        its two facets' global numbers (the smaller first). Statics keys its active sets by it."""
        F, L = self.facets_all, self.listed
        return F.key[L.i].astype(np.int64) * 2**31 + F.key[L.j]

    def smallest_gap(self, up: np.ndarray) -> float:
        """The smallest gap of the pairs that overlap (w > 0), over all processes (m; inf if none)."""
        g, w = self.pair_states(up)
        return self.comm.allreduce(float(g[w > 0].min(initial=np.inf)), op=MPI.MIN)

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
        return {"scheme_b_rule": self._scheme_b_rule,
                "counters": np.array([self.rebuilds, self.evaluations, self.exchanges], dtype=np.int64),
                "seconds": np.array([self.seconds])}

    def restore_state(self, state: Mapping[str, np.ndarray] | None) -> None:
        """The list is rebuilt at the next ``prepare``; the counters and the scheme B pairs are
        those of the same partition's ``checkpoint_state``, or start again (None: another
        partition). The facets known stay those of the last exchange, and so does its
        reference: the next ``prepare`` exchanges again if the restored displacements are
        farther from it than any step may drift (a resumed run's model exchanged at u = 0)."""
        self._reference.fill(np.inf)  # in place: the list's struct (``_c_pairs``) points to it
        if state is not None:
            self._scheme_b_rule = np.asarray(state["scheme_b_rule"], dtype=np.int64)
            self.rebuilds, self.evaluations, self.exchanges = (int(x) for x in state["counters"])
            self.seconds = float(state["seconds"][0])


def _where(keep: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The entries ``keep`` of each array."""
    return tuple(a[keep] for a in arrays)


def _find_sorted(a: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each entry of ``x`` in the sorted array ``a`` of non-negative numbers: its position there
    (np.searchsorted) and whether it is there (np.isin without sorting ``a``)."""
    index = np.searchsorted(a, x)
    return index, np.append(a, -1)[index] == x  # (-1, no entry: past the end of a)


_SUMMARY_BOXES = 16  # boxes per process summarising its local facets in a list round (``PairContact._exchange``)


def _bisection(x: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """At most k groups of nearby points of x (n, d): the largest group is halved at the median
    of its longest side until there are k (or groups of one point). Returns a permutation of
    the points, group by group, and each group's start in it (for ``ufunc.reduceat``)."""
    groups = [np.arange(len(x))] if len(x) else []
    while 0 < len(groups) < k:
        big = int(np.argmax([len(g) for g in groups]))
        g = groups[big]
        if len(g) < 2:
            break
        y = x[g]
        side = int(np.argmax(y.max(axis=0) - y.min(axis=0)))
        part = np.argpartition(y[:, side], len(g) // 2)
        groups[big : big + 1] = [g[part[: len(g) // 2]], g[part[len(g) // 2 :]]]
    perm = np.concatenate(groups) if groups else np.empty(0, dtype=np.int64)
    return perm, np.cumsum([0] + [len(g) for g in groups[:-1]]).astype(np.int64)


def _box(y: np.ndarray) -> np.ndarray:
    """The bounding box [min, max] (2 d) of the points y (n, d); empty (inf, -inf) without
    points. Column by column: numpy 1.24 reduces an (n, d) array along its first axis ten times
    slower."""
    return np.array([y[:, k].min(initial=np.inf) for k in range(y.shape[1])]
                    + [y[:, k].max(initial=-np.inf) for k in range(y.shape[1])])


def _near(x: np.ndarray, y: np.ndarray, r: float) -> np.ndarray:
    """Whether each point of y is within r of a point of x."""
    tree = scipy.spatial.cKDTree(x, balanced_tree=False, compact_nodes=False)  # built once, queried once
    bound = np.nextafter(r, np.inf)  # the query keeps distances < bound
    return np.isfinite(tree.query(y, distance_upper_bound=bound)[0])


def _reach(F: _Facets) -> np.ndarray:
    """The largest distance from each facet's barycentre to its vertices (half the length in 2D)."""
    return np.linalg.norm(F.ends - F.centre[:, None], axis=2).max(axis=1, initial=0.0)


def _gauss_legendre(d: int) -> tuple[np.ndarray, np.ndarray]:
    """d-point Gauss-Legendre nodes and weights on [0, 1]: exact to degree 2 d - 1, the degree
    of a pair's force term between events in dimension d (w of degree d - 1 in tau, c_p and
    z_p . (a + delta_a) of degree d, dc_p/du of degree d - 1)."""
    x, weights = np.polynomial.legendre.leggauss(d)
    return 0.5 + 0.5 * x, 0.5 * weights


def _tangents(n: np.ndarray) -> np.ndarray:
    """An orthonormal basis (P, d - 1, d) of the plane normal to each unit vector n (P, d)."""
    if n.shape[1] == 2:
        return np.stack([-n[:, 1], n[:, 0]], axis=1)[:, None]
    axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]  # the axis farthest from n
    t1 = np.cross(n, axis)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(n, t1)], axis=1)


@dataclasses.dataclass(frozen=True)
class _Simplices:
    """Facets projected on their pair's plane: (d-1)-simplices (segments in 2D, triangles in 3D)
    with vertices X (P, d, d-1). Face k (a vertex in 2D, the edge X_k X_k+1 in 3D) runs from X_k
    to ``end`` (X_k itself in 2D); m_k is its outward normal in the plane, unnormalised so
    that m_k . (X_k+1 - X_k) is exactly 0 (ties are detected exactly), nu_k = m_k / |m_k|, and
    ``size`` its measure (1 for a vertex)."""

    X: np.ndarray
    end: np.ndarray
    m: np.ndarray
    nu: np.ndarray
    size: np.ndarray

    @staticmethod
    def of(X: np.ndarray) -> _Simplices:
        """The simplices of vertices X (the compiled ``dem_simplices_of``; segments: the faces are
        the vertices, each facing away from the other)."""
        X = np.ascontiguousarray(X, dtype=np.float64)  # the layout of the kernel ``dem_overlap``
        end, m, nu, size = np.empty_like(X), np.empty_like(X), np.empty_like(X), np.empty(X.shape[:2])
        lib.dem_simplices_of(len(X), X.shape[1], pointer(X), pointer(end), pointer(m), pointer(nu), pointer(size))
        return _Simplices(X, end, m, nu, size)

    @functools.cached_property
    def struct(self) -> Struct:
        """X, m, nu, size for the kernels (``dem_simplices``; made once)."""
        return Struct("dem_simplices", X=self.X, m=self.m, nu=self.nu, size=self.size)


def _project(F: _Facets, f: np.ndarray, origin: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The vertices of the facets ``f`` relative to the barycentres of the facets ``origin``, on
    the tangents ``t`` (P, d-1, d) of their pairs' planes: (P, d, d-1) (the compiled
    ``dem_pair_project``)."""
    d = t.shape[2]
    X = np.empty((len(f), d, d - 1))
    lib.dem_pair_project(len(f), d, pointer(np.ascontiguousarray(f, dtype=np.int64)),
                         pointer(np.ascontiguousarray(origin, dtype=np.int64)), pointer(np.ascontiguousarray(F.ends)),
                         pointer(np.ascontiguousarray(F.centre)), pointer(np.ascontiguousarray(t)), pointer(X))
    return X


def _separations(A: _Simplices, B: _Simplices) -> np.ndarray:
    """The separations of the compiled screen (``PairContact._free_flight``), (P, 2d) (the compiled
    ``dem_pair_separations``): for each face k of A, then of B, how far the other simplex's
    nearest vertex lies beyond the face's line (times |m_k|) at zero offset, min_b m_k . (Y_b - X_k)
    and min_a m'_k . (X_a - Y_k). At offset s, A and B (moved by s) are separated by that line
    while the first plus m_k . s, or the second minus m'_k . s, is positive: the face normals are
    the separating axes of two simplices in the plane, so a pair with none positive overlaps. Less
    a margin of 1e-9 |m_k| times the pair's size, far above rounding: the screen keeps a pair that
    touches within it (then clipped: its w may be 0), and drops only pairs whose overlap is 0."""
    out = np.empty((len(A.X), 2 * A.X.shape[1]))
    lib.dem_pair_separations(len(A.X), A.X.shape[1], A.struct.c, B.struct.c, 1e-9, pointer(out))
    return out


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """sum_k a[..., k] b[..., k] over the few components k of the last axis (term by term:
    faster than a reduction over a short axis, and m . e exactly 0 when m is e turned)."""
    return _last(np.add, a * b)


def _last(op, a: np.ndarray) -> np.ndarray:
    """The binary ``op`` folded over the (short) last axis of ``a``."""
    out = a[..., 0]
    for k in range(1, a.shape[-1]):
        out = op(out, a[..., k])
    return out


def _overlap(A: _Simplices, B: _Simplices, p: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """w = |A_p cap (B_p + s)| and its gradient dw/ds (E, d-1) for the simplex pairs p (E,) and
    the offsets s (E, d-1): the compiled kernel ``dem_overlap`` (kernels/overlap.c).

    The divergence theorem, div x = d - 1 in the plane: w = 1/(d-1) int over the boundary of
    A cap (B + s) of x . nu, whose pieces are the faces of A clipped by B + s and the faces of
    B + s clipped by A (a face counts nu_k . x at its clipped centre times its clipped measure).
    Each face is clipped by the half-planes m_k . (x - X_k) <= 0 of the other simplex's faces
    (Liang-Barsky); a face of B + s lying on a face of A with the same outward normal is left
    out, so that a boundary piece common to both simplices is counted once (by A). Translating
    B + s by ds moves only its own boundary pieces inside A: dw/ds = sum_k nu_k
    |face_k(B + s) cap A|. Both are exact where w is smooth (off the events of ``_events``)."""
    p = np.ascontiguousarray(p, dtype=np.int64)
    s = np.ascontiguousarray(s, dtype=np.float64)
    w, dw = np.empty(len(p)), np.empty(s.shape)
    lib.dem_overlap(len(p), s.shape[1], pointer(p), A.struct.c, B.struct.c, pointer(s), pointer(w), pointer(dw))
    return w, dw


def _adjugate_times(A: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """adj(A) x and det(A) for matrices A (n, d, d), d = 2 or 3, and vectors x (n, d)."""
    if A.shape[1] == 2:
        adj_x = np.stack([A[:, 1, 1] * x[:, 0] - A[:, 0, 1] * x[:, 1],
                          A[:, 0, 0] * x[:, 1] - A[:, 1, 0] * x[:, 0]], axis=1)
        return adj_x, A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    c0, c1, c2 = A[:, :, 0], A[:, :, 1], A[:, :, 2]  # the rows of adj(A) are c1 x c2, c2 x c0, c0 x c1
    rows = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)
    return np.einsum("nij,nj->ni", rows, x), np.einsum("ni,ni->n", c0, rows[:, 0])


def _reconstruction_matrix(F: _Facets, first: np.ndarray) -> tuple[scipy.sparse.csr_matrix, np.ndarray]:
    """R of the facets ``F`` on the patch dofs ``first`` (sorted global dofs) then ``extra``, the
    other dofs F's reconstructions read (sorted): (R, (n d, len(first) + len(extra)), each row's
    columns sorted; extra)."""
    n, d, width = F.R_dofs.shape
    dofs = F.R_dofs.reshape(-1)
    keep = dofs >= 0
    dofs = dofs[keep]
    column, found = _find_sorted(first, dofs)
    extra, at = np.unique(dofs[~found], return_inverse=True)
    column[~found] = len(first) + at
    indptr = np.zeros(n * d + 1, dtype=np.int32)
    np.cumsum(keep.reshape(n * d, width).sum(axis=1), out=indptr[1:])
    R = scipy.sparse.csr_matrix((F.R_values.reshape(-1)[keep], column.astype(np.int32), indptr),
                                shape=(n * d, len(first) + len(extra)))
    R.sort_indices()
    return R, extra


@dataclasses.dataclass(frozen=True)
class _Pairs:
    """Facet pairs (f_i, f_j) of the Verlet list (indices into ``PairContact.facets_all``),
    vectorised: the common normal n and an orthonormal basis t (P, d-1, d) of its plane, the
    correction directions e_i, e_j (``PairContact._directions``), the reference gap d0, the
    facets projected on the plane, si, sj (``_Simplices``, origin at f_i's barycentre); Z^T = the
    z_p on the own rows touched (P, rows) and the own rows Q on the patch dofs. Z, Q^T and
    N = Z^T Z are made on first use (a step needs Z^T and Q only; statics the others): N alone
    cost 40 % of a list build on ``cradle``."""

    i: np.ndarray
    j: np.ndarray
    n: np.ndarray
    t: np.ndarray
    e_i: np.ndarray
    e_j: np.ndarray
    d0: np.ndarray
    si: _Simplices
    sj: _Simplices
    sep: np.ndarray
    ZT: scipy.sparse.csr_matrix
    Q: scipy.sparse.csr_matrix

    def __len__(self) -> int:
        return len(self.i)

    @functools.cached_property
    def Z(self) -> scipy.sparse.csr_matrix:
        return self.ZT.T.tocsr()

    @functools.cached_property
    def N(self) -> scipy.sparse.csr_matrix:
        return (self.Z.T @ self.Z).tocsr()

    @functools.cached_property
    def QT(self) -> scipy.sparse.csr_matrix:
        return self.Q.T.tocsr()

    @functools.cached_property
    def slot(self) -> np.ndarray:
        """One int32 per own row, -1 between the calls of ``dem_pair_force_integral`` and
        ``dem_pair_end_state`` (which number the rows their pairs touch through it)."""
        return np.full(self.Q.shape[0], -1, dtype=np.int32)

    def struct(self, R: Struct, lift: np.ndarray, reference: np.ndarray, half_skin2: np.ndarray,
               slack: float) -> Struct:
        """The list for the kernels (``dem_pairs``), with its known facets' free reconstructions
        (R, ``lift``), their free displacements when it was built (``reference``) and half their
        skins squared, and how far a flight's screen looks beyond its end (``slack``)."""
        return Struct("dem_pairs", d=self.n.shape[1], n_facets=len(reference), R=R, lift=lift, reference=reference,
                      half_skin2=half_skin2, slack=slack, end_slack2=(0.5 * slack)**2, n=len(self), i=self.i,
                      j=self.j, normal=self.n, t=self.t, d0=self.d0, e_i=self.e_i, e_j=self.e_j, sep=self.sep,
                      si=self.si.struct, sj=self.sj.struct, z=csr_of(self.ZT), slot=self.slot)


class _At:
    """The contact state of a ``PairContact`` at one displacement (patch values ``up``), on first
    use, in one compiled call (``dem_pair_end_state``): the free facet displacements ``uc``,
    whether the list is stale there (``moved``), and, if it is not, the listed pairs ``closed``
    whose c_p = w_p g_p^- may not vanish (the screen of ``PairContact._free_flight``: g_p < 0,
    projections not apart), their g, w, dw/du_j, c = w g^- and mu_p = z_p . (a + delta) (own
    rows' part), with a = Q u + q and delta = Z c on the own rows, the energy change of those
    rows (``energy``: elastic, stabilisation) and the sum of mu_p w_p (``mu_w``:
    ``contact_force_part``). The energy of a step's end, the outputs there and the next step's
    flight share it (``PairContact._at``)."""

    def __init__(self, contact: PairContact, up: np.ndarray):
        # a read-only array (MEMM's shared patch values) is kept as it is: ``PairContact._at`` then
        # knows it by identity; another is copied, since its caller may change it
        self.contact, self.listed = contact, contact.listed
        self.up = up if not up.flags.writeable else up.copy()

    @functools.cached_property
    def _state(self) -> tuple:
        """(uc, moved, candidates, the state or None if moved, the state's struct) in one compiled
        call (``dem_pair_end_state``): the free facet displacements (``free_displacements``), whether
        the list is stale there (``PairContact._moved``), the last flight's candidates if they
        hold here (bit 1 of its screen: the only pairs that may be closed, when every facet lies
        within half the slack of the flight's end, as at the step's end, where uc = R u^{n+1}
        and the flight's end uc^n + dt vc differ by rounding; else None: every pair screened).
        The state computed right away: a step's end needs it for its energy."""
        contact, L, d = self.contact, self.listed, self.contact.d
        end = contact._end if contact._end is not None and contact._end[0] is L else None
        flight = None if end is None else end[1]
        n = len(L)
        uc = np.empty((len(contact._lift), d))
        state = Struct("dem_pair_state", closed=np.empty(n, dtype=np.int64), g=np.empty(n), w=np.empty(n),
                       dw=np.empty((n, d)), c=np.empty(n), mu=np.empty(n))
        k = lib.dem_pair_end_state(contact._c_pairs.c, contact._c_patch.c, pointer(self.up),
                                   ffi.NULL if flight is None else flight.c, contact._work, pointer(uc), state.c)
        if k == -1:
            raise KernelMemoryError("contact between bodies: out of memory in the contact state")
        a, s = state.arrays, state.c
        values = None if k == -2 else (a["closed"][:k], a["g"][:k], a["w"][:k], a["dw"][:k], a["c"][:k], a["mu"][:k],
                                       (float(s.energy[0]), float(s.energy[1])), float(s.mu_w))
        candidates = flight.arrays["candidates"][: flight.c.n_candidates] if s.from_flight else None
        return uc, k == -2, candidates, values, state

    uc = property(lambda self: self._state[0], doc="The free facet displacements (``free_displacements``).")
    moved = property(lambda self: self._state[1], doc="Whether the list is stale here (``PairContact._moved``).")
    candidates = property(lambda self: self._state[2], doc="The pairs screened (None: every listed pair).")

    @functools.cached_property
    def _values(self) -> tuple:  # raises (caching nothing) where the list is stale
        if self.moved:
            self.contact._check_listed(self.uc)  # raises
        return self._state[3]

    @property
    def kernel_state(self) -> Struct:
        """The state for the kernels (``dem_pair_state``; raises where the list is stale)."""
        if self.moved:
            self.contact._check_listed(self.uc)  # raises
        return self._state[4]

    closed = property(lambda self: self._values[0])
    g = property(lambda self: self._values[1])
    w = property(lambda self: self._values[2])
    dw = property(lambda self: self._values[3])
    c = property(lambda self: self._values[4])
    mu = property(lambda self: self._values[5])
    energy = property(lambda self: self._values[6])
    mu_w = property(lambda self: self._values[7])  # the sum of mu_p w_p over the closed pairs


class _CSC:
    """A CSC matrix's arrays for the compiled kernel ``dem_pair_rows`` (QF: the own rows touched
    by the local facets' dofs), with its work arrays (``dem_facet_rows``)."""

    def __init__(self, A: scipy.sparse.csc_matrix, d: int):
        self.shape, self.d = A.shape, d
        self.indptr = np.ascontiguousarray(A.indptr, dtype=np.int32)
        self.indices = np.ascontiguousarray(A.indices, dtype=np.int32)
        self.data = np.ascontiguousarray(A.data, dtype=np.float64)
        self._facet_counts = np.diff(self.indptr).reshape(-1, d).sum(axis=1)  # the entries of each facet's d columns
        self._sums = np.zeros(self.shape[0])  # zero between calls
        self._mark = np.full(self.shape[0], -1, dtype=np.int32)  # -1 between calls
        self._touched = np.empty(2 * self.shape[0], dtype=np.int32)
        self._struct = Struct("dem_facet_rows", columns=csr(self.indptr, self.indices, self.data, self.shape[0]),
                              sums=self._sums, mark=self._mark, touched=self._touched)

    def pair_rows(self, i, j, e_i, e_j, length) -> scipy.sparse.csr_matrix:
        """Z^T = E^T A^T for the pairs (i, j) of facets (the local ones: those with columns
        here, d each): row p = sum over its local facets f of A's columns of f's dofs times
        e_f / |f| (sorted, no explicit zeros)."""
        P, d, n_local = len(i), self.d, len(self._facet_counts)
        i, j = np.ascontiguousarray(i, dtype=np.int64), np.ascontiguousarray(j, dtype=np.int64)
        e_i, e_j = np.ascontiguousarray(e_i, dtype=np.float64), np.ascontiguousarray(e_j, dtype=np.float64)
        length = np.ascontiguousarray(length, dtype=np.float64)
        counts = self._facet_counts
        bound = int(counts[i[i < n_local]].sum() + counts[j[j < n_local]].sum())
        indptr, indices, data = np.empty(P + 1, dtype=np.int32), np.empty(bound, dtype=np.int32), np.empty(bound)
        nnz = lib.dem_pair_rows(self._struct.c, P, d, pointer(i), pointer(j), pointer(e_i), pointer(e_j),
                                pointer(length), pointer(indptr), pointer(indices), pointer(data))
        return scipy.sparse.csr_matrix((data[:nnz], indices[:nnz], indptr), shape=(P, self.shape[0]))


