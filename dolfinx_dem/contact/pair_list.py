"""The pair list of the contact between bodies: broad phase, Verlet skins and the exchange of
candidate facets between processes (paper §3.4.3; pair.py holds the contact itself).

A pair is listed (a Verlet list built with a k-d tree on the displaced facet centres) when its
centres are closer than r_p = rho_f + rho_f' + (s_f + s_f')/2, rho the largest distance from a
facet's barycentre to its vertices (half the length in 2D) and s its Verlet skin, by default its
own diameter 2 rho (or one uniform skin given by the user): the list follows the local facet
size, so a contact zone refined far below the rest of the boundary lists few pairs.
In an exchange each process sends the records of its own candidate facets (facets.py) to the
processes they come within the exchange radius R = 3 max r_p of: those within R of one of the
boxes that summarise the other process's local facets (at most 16 boxes of nearby facets per
process, all gathered); the receiver keeps those within R of one of its local facets (every
facet known costs at each step). A process's list is stale when a facet it knows (local or
ghost) has moved more than half its skin since it built the list: an unlisted pair's centres are
then still farther apart than rho_f + rho_f', so its facets cannot touch. When a process is stale,
a round of the lists (``PairList.build``) rebuilds its list from the facets it knows; the others
keep theirs: a fast facet does not rebuild the lists far from it. The round exchanges facets
first only when a local facet has drifted more than max r_p - max s/2 since the last exchange:
every list is then built where the drifts are below that, a valid list's facets stay within s/2
of where it was built, and a facet a process does not know stays farther than max r_p from its
local facets. After an exchange the processes that receive a facet new to them rebuild too.

The list is built from candidate records: the local facets (``local``) and the ghosts an exchange
brings. Facets that appear during a run (a crack's lips) are new local records followed by a
round with an exchange; nothing else here assumes the candidates fixed.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import scipy.sparse
import scipy.spatial
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.contact.directions import correction_directions
from dolfinx_dem.contact.facets import CandidateFacets, FacetRows, find_sorted, reach, reconstruction_matrix
from dolfinx_dem.contact.overlap import Simplices, project, separations, tangents
from dolfinx_dem.contact.patch import PatchScatter
from dolfinx_dem.errors import InputError, StateError
from dolfinx_dem.kernels import Struct, csr_of, lib, pointer


class PairList:
    """The Verlet list of the candidate pairs of one process and the facets it knows (module
    docstring), with the patch of dofs the pairs read and its scatter.

    Parameters
    ----------
    local : the local candidate facets (the own ones first, ``num_own`` of them).
    rows_Q, row_dofs : the own energy rows that candidate facets touch, on the patch's first
        dofs: the sorted global dofs ``row_dofs`` they read.
    facet_rows : those rows' columns of the local facets' dofs (``FacetRows``).
    template : a vector of the dof layout (the scatters' source).
    self_contact, rigid, skin : as ``PairContact``'s; ``rigid`` per body number.
    """

    def __init__(self, comm: MPI.Comm, local: CandidateFacets, num_own: int, rows_Q: scipy.sparse.csr_matrix,
                 row_dofs: np.ndarray, facet_rows: FacetRows, template: PETSc.Vec, self_contact: bool,
                 rigid: np.ndarray, skin: float | None):
        self.comm, self.d, self.local, self.num_own = comm, local.centre.shape[1], local, num_own
        self.rows_Q, self.row_dofs, self.facet_rows = rows_Q, row_dofs, facet_rows
        self.self_contact, self.rigid = self_contact, rigid
        self._local_keys = np.sort(local.key)
        # a list round summarises the local facets' places by the boxes of at most _SUMMARY_BOXES
        # groups of nearby facets (``_bisection`` of the reference barycentres, fixed)
        self._groups = _bisection(local.centre, _SUMMARY_BOXES)
        self.num_facets = comm.allreduce(num_own, op=MPI.SUM)
        self._candidate_vector = PETSc.Vec().createMPI((num_own * self.d, PETSc.DECIDE), comm=comm)
        # Verlet skins: each facet's own diameter about its barycentre (the length in 2D) unless
        # one uniform skin is given; the list radius of a pair is its facets' reaches plus their
        # mean skin (``_list``), so a refined contact zone lists few pairs.
        if skin is not None and not skin > 0:
            raise InputError(f"the Verlet skin must be > 0, got {skin}")
        self._uniform_skin = None if skin is None else float(skin)
        self.local_reach = reaches = reach(local)
        skins = self.skins(reaches)
        # the smallest skin (a length scale for tolerances) and the largest pair radius (the
        # reach of the broad phase's exchange between processes)
        self.skin = comm.allreduce(float(skins.min(initial=np.inf)), op=MPI.MIN)
        self.radius = comm.allreduce(float((2.0 * reaches + skins).max(initial=0.0)), op=MPI.MAX)
        # how far (relative gap, separations) the screen of a flight looks beyond its end for the
        # pairs that may be closed there (pair_state.py): far above rounding
        self.slack = 1e-9 * self.radius
        # A list round exchanges facets between processes only when a local facet has drifted
        # more than r - s/2 since the last exchange (r the largest pair radius, s the largest
        # skin: ``drifted``), and then each process learns the other processes' facets within
        # the exchange radius 3 r of its local facets (module docstring).
        self.exchange_radius = 3.0 * self.radius
        self._exchange_drift = self.radius - 0.5 * comm.allreduce(float(skins.max(initial=0.0)), op=MPI.MAX)
        self._exchanged = None  # the local facets' free displacements at the last exchange (``build``)
        self.rebuilds = 0  # list builds on this process
        self.exchanges = 0  # exchanges of facets between processes (list rounds that make the ghosts)
        self.scheme_b_rule = np.empty(0, dtype=np.int64)  # keys of pairs under the B rule (own ones)
        self.template = template  # a zero vector of the dof layout (the scatters' source)
        self.scatter = None  # the patch scatter, made by the list rounds (``_remake_scatters``)
        self._candidate_scatter = None  # the scatter of values of the known facets (``candidate_values``)
        self.step_work = None  # the per-step arrays of the current list (``events.StepWork``), made on first use
        self.build(local.lift.copy())  # the free facet displacements at u = 0: R 0 + lift

    def build(self, uc: np.ndarray, stale: bool = True, exchange: bool = True):
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
        at its last rebuild (``moved``), so its pairs of known facets are safe; a facet it does
        not know was farther than ``exchange_radius`` = r + 2 r from each of its local facets at
        the last exchange (r the largest pair radius), and each of the two has drifted less than
        r since (``PairContact.prepare`` exchanges beyond r - s/2 at a list build, s the largest skin, and a
        valid list's facets are within s/2 of where it was built): they are farther apart than
        any pair radius."""
        comm, local = self.comm, self.local
        nl = len(local)
        if not exchange:
            if stale:  # the same known facets, patch and reconstructions: the list only
                self._list(self.known, uc)
            return
        self._exchanged = uc[:nl].copy()
        self.exchanges += comm.size > 1
        ghosts, uc_ghosts = self._exchange(uc[:nl])  # none on one process
        if not stale and np.isin(ghosts.key, self.known.key[nl:]).all():
            # nothing new near this process: its list stands, and so do its scatters' dofs
            self._remake_scatters(self.scatter.dofs, self.known)
            return
        # the known facets: the local ones (the same arrays without ghosts, as on one process), then the ghosts
        F = CandidateFacets.concatenate([local, ghosts]) if len(ghosts) else local
        ucF = np.concatenate([uc[:nl], uc_ghosts])
        # The patch: the own rows' held dofs and the reconstruction dofs of every known facet
        # (the ghosts' too: their motion decides when the list is stale), and its scatters, first:
        # every process reaches this collective soon after the exchange, and the list's work
        # below, however unequal between processes, is waited for once (at the next gather).
        # The patch is the rows' dofs, then the facets' other reconstruction dofs (sorted; often
        # none: scheme B, R_f u = u_c): Q's columns are the rows' dofs' fixed numbers.
        R, extra = reconstruction_matrix(F, self.row_dofs)  # (n_facets d, patch)
        patch = np.concatenate([self.row_dofs, extra]) if len(extra) else self.row_dofs
        self._remake_scatters(patch, F)
        self.known = F
        self.facet_bodies = np.ascontiguousarray(F.body, dtype=np.int64)  # for ``dem_pair_body_forces``
        self.R = R
        self.Rc = csr_of(R)  # for the compiled products (``free_displacements``)
        self.RT = self.R.T  # CSC: its products sum in the order of R^T as CSR, without the copy
        self.lift = np.ascontiguousarray(F.lift, dtype=np.float64).reshape(-1, self.d)
        self.p_lift = pointer(self.lift)
        self.known_reach = np.concatenate([self.local_reach, reach(ghosts)])
        self._list(F, ucF)

    def _list(self, F: CandidateFacets, ucF: np.ndarray) -> None:
        """The Verlet list of the known facets ``F`` at free displacements ``ucF`` (``build``)."""
        nl = len(self.local)
        x = F.centre + ucF
        reach = self.known_reach
        skins = self.skins(reach)
        tree = scipy.spatial.cKDTree(x)
        pairs = tree.query_pairs(self.radius, output_type="ndarray")
        i, j = pairs[:, 0], pairs[:, 1]
        # The tests keep the same pairs in any order: the cheap and selective ones first (within
        # the largest radius, most pairs are neighbours on one body's boundary).
        if not self.self_contact:
            i, j = _where(F.body[i] != F.body[j], i, j)
        # with a local facet; not two imposed motions
        i, j = _where(((i < nl) | (j < nl)) & ~(self.rigid[F.body[i]] & self.rigid[F.body[j]]), i, j)
        i, j = _where(np.einsum("pi,pi->p", F.normal[i], F.normal[j]) < 0, i, j)  # facing facets only
        # a pair's own radius: its facets' reaches plus their mean skin. Until a facet moves
        # more than half its skin (``moved``) an unlisted pair's centres stay farther apart
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
        t = tangents(n)
        e_i, e_j, keys = correction_directions(F, i, j, n, self.rigid, self.comm.rank)
        if len(keys):
            self.scheme_b_rule = np.union1d(self.scheme_b_rule, keys)

        # z_p restricted to the own rows: the local facets' entries only, Z^T = E^T QF^T with E
        # the facet dofs' directions (``dem_pair_rows``).
        ZT = self.facet_rows.pair_rows(i, j, e_i, e_j, F.length)  # (P, own rows touched)
        Qp = scipy.sparse.csr_matrix((self.rows_Q.data, self.rows_Q.indices, self.rows_Q.indptr),
                                     shape=(self.rows_Q.shape[0], len(self.scatter)))  # on the whole patch
        # the facets projected on the plane normal to n, origin at f_i's barycentre; n . n_f >
        # |f| / (|f| + |f'|) for facing facets, so no projection degenerates
        si, sj = Simplices.of(project(F, i, i, t)), Simplices.of(project(F, j, i, t))
        self.pairs = Pairs(
            i=i, j=j, n=n, t=t, e_i=e_i, e_j=e_j,
            d0=np.einsum("pi,pi->p", F.centre[j] - F.centre[i], n),
            si=si, sj=sj, sep=separations(si, sj),
            ZT=ZT, Q=Qp,
        )
        self.reference = ucF.copy()
        self.half_skin2 = 0.25 * skins**2  # of the known facets
        self.c_pairs = self.pairs.struct(self.Rc, self.lift, self.reference, self.half_skin2, self.slack)
        self.rebuilds += 1

    def _exchange(self, uc: np.ndarray) -> tuple[CandidateFacets, np.ndarray]:
        """The ghost facets of an exchange (collective) and their free displacements, for the
        local facets' free displacements ``uc``: every process summarises its local facets'
        places by the boxes of its facet groups (``_groups``) and its own facets' box, all
        gathered (a fixed size per process); it sends each other process the own facets within
        the exchange radius R of one of that process's boxes, and keeps of the facets it
        receives those new to it that come within R of one of its local facets. The boxes cut
        what is sent (one box per process would hold most of another part's boundary with a
        graph partition), the last test what is kept: every ghost costs at each step (its
        motion, its dofs in the patch)."""
        comm, d, r, local = self.comm, self.d, self.exchange_radius, self.local
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
            k = np.flatnonzero(sent)
            floats, ints = local.take(k).records()  # own facets: the first of the local ones
            rows = np.full(self.num_own, -1, dtype=np.int64)
            rows[k] = np.arange(len(k))
            floats = np.concatenate([floats, uc[k]], axis=1)  # with the sender's displacements
            send = [None if s is None else (floats[rows[s]], ints[rows[s]]) for s in send]
        received = [m for m in comm.alltoall(send) if m is not None]
        if not received:
            return local.take(np.empty(0, dtype=np.int64)), np.zeros((0, d))
        rf = np.concatenate([m[0] for m in received])
        ri = np.concatenate([m[1] for m in received])
        new = ~find_sorted(self._local_keys, ri[:, 0])[1]
        ghosts, uc_ghosts = local.from_records(rf[new, :-d], ri[new]), rf[new, -d:]
        there = ghosts.centre + uc_ghosts
        if len(there):
            # the local facets near the new ones' box only: the rest are farther than R from all
            X = x[np.all((x >= there.min(axis=0) - r) & (x <= there.max(axis=0) + r), axis=1)]
            near = _near(X, there, r) if len(X) else np.zeros(len(there), dtype=bool)
            ghosts, uc_ghosts = ghosts.take(np.flatnonzero(near)), uc_ghosts[near]
        return ghosts, uc_ghosts

    def _remake_scatters(self, patch: np.ndarray, F: CandidateFacets) -> None:
        """After a round of the lists (every process calls it): the patch scatter of the dofs
        ``patch``, and the scatter of the facet corrections of the known facets ``F`` from their
        owners (outputs; made on first use, ``candidate_values``). Making a scatter is
        collective and, in parallel, costs as much as the rest of a list build: each is kept
        when no process's dofs changed (one reduction), as a round with slow bodies mostly
        leaves them."""
        facet_dofs = (F.index[:, None] * self.d + np.arange(self.d)).ravel()
        keep = np.array(
            [
                self.scatter is not None and np.array_equal(self.scatter.dofs, patch),
                self._candidate_scatter is not None and np.array_equal(self._candidate_scatter.dofs, facet_dofs),
            ],
            dtype=np.int32,
        )
        self.comm.Allreduce(MPI.IN_PLACE, keep, op=MPI.MIN)
        if not keep[0]:
            self.scatter = PatchScatter(self.template, patch)
        if not keep[1]:
            self._candidate_scatter = None

    def skins(self, reach: np.ndarray) -> np.ndarray:
        """The Verlet skins of facets of reaches ``reach``: the uniform skin if one was given,
        else each facet's diameter about its barycentre, 2 reach."""
        return 2.0 * reach if self._uniform_skin is None else np.full(len(reach), self._uniform_skin)

    def moved(self, uc: np.ndarray) -> bool:
        """Whether a facet known here (local or ghost) with free displacements ``uc`` has moved
        more than half its skin since the last list build (a pair not listed might then touch;
        the compiled ``dem_pair_worst_motion``)."""
        if len(uc) != self.c_pairs.c.n_facets:
            raise InputError(f"{len(uc)} free facet displacements for the {self.c_pairs.c.n_facets} known facets")
        ratio = np.zeros(1)
        lib.dem_pair_worst_motion(self.c_pairs.c, pointer(uc), pointer(ratio))
        return ratio[0] > 1.0

    def drifted(self, uc: np.ndarray, vc: np.ndarray | None, dt: float) -> bool:
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
        motion2 = np.einsum("ni,ni->n", *2 * ((self.R @ dp).reshape(-1, self.d),))
        ratio = np.sqrt((motion2 / self.half_skin2).max(initial=0.0))
        return self.comm.allreduce(float(ratio), op=MPI.MAX)

    def check_listed(self, uc: np.ndarray):
        if self.moved(uc):
            raise StateError(
                "contact between bodies: the candidate pair list is stale for these displacements "
                "(a facet moved more than skin/2 since it was built); call prepare(u) first "
                "(MEMM does it every step)"
            )

    def free_displacements(self, up: np.ndarray) -> np.ndarray:
        """Free reconstructions u_f = R_f u + lift_f of the known candidate facets (local, then
        ghosts), (n, d), from patch values ``up`` (the compiled ``dem_csr_apply``)."""
        uc = np.empty((len(self.lift), self.d))
        lib.dem_csr_apply(self.Rc.c, pointer(up), self.p_lift, pointer(uc))
        return uc

    def candidate_values(self, own: np.ndarray) -> np.ndarray:
        """Values (n_known, d) of every known facet (local and ghost), each from its owner's
        ``own`` (n_own, d) (a scatter of the candidates' vector, made after a round that changed
        the known facets somewhere; collective)."""
        if self._candidate_scatter is None:
            F, d = self.known, self.d
            self._candidate_scatter = PatchScatter(
                self._candidate_vector, (F.index[:, None] * d + np.arange(d)).ravel()
            )
        self._candidate_vector.array[:] = own.ravel()
        return self._candidate_scatter.gather(self._candidate_vector).reshape(-1, self.d)

    def pair_keys(self) -> np.ndarray:
        """A number for each listed pair that neither the partition nor a list rebuild changes:
        its two facets' global numbers (the smaller first). Statics keys its active sets by it."""
        F, L = self.known, self.pairs
        return F.key[L.i].astype(np.int64) * 2**31 + F.key[L.j]


def _where(keep: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The entries ``keep`` of each array."""
    return tuple(a[keep] for a in arrays)


_SUMMARY_BOXES = 16  # boxes per process summarising its local facets in a list round (``PairList._exchange``)


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
    return np.array(
        [y[:, k].min(initial=np.inf) for k in range(y.shape[1])]
        + [y[:, k].max(initial=-np.inf) for k in range(y.shape[1])]
    )


def _near(x: np.ndarray, y: np.ndarray, r: float) -> np.ndarray:
    """Whether each point of y is within r of a point of x."""
    tree = scipy.spatial.cKDTree(x, balanced_tree=False, compact_nodes=False)  # built once, queried once
    bound = np.nextafter(r, np.inf)  # the query keeps distances < bound
    return np.isfinite(tree.query(y, distance_upper_bound=bound)[0])


@dataclasses.dataclass(frozen=True)
class Pairs:
    """Facet pairs (f_i, f_j) of the Verlet list (indices into ``PairList.known``),
    vectorised: the common normal n and an orthonormal basis t (P, d-1, d) of its plane, the
    correction directions e_i, e_j (``directions.correction_directions``), the reference gap d0, the
    facets projected on the plane, si, sj (``overlap.Simplices``, origin at f_i's barycentre); Z^T = the
    z_p on the own rows touched (P, rows) and the own rows Q on the patch dofs. Z, Q^T and
    N = Z^T Z are made on first use (a step needs Z^T and Q only; statics the others)."""

    i: np.ndarray
    j: np.ndarray
    n: np.ndarray
    t: np.ndarray
    e_i: np.ndarray
    e_j: np.ndarray
    d0: np.ndarray
    si: Simplices
    sj: Simplices
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

    def struct(
        self, R: Struct, lift: np.ndarray, reference: np.ndarray, half_skin2: np.ndarray, slack: float
    ) -> Struct:
        """The list for the kernels (``dem_pairs``), with its known facets' free reconstructions
        (R, ``lift``), their free displacements when it was built (``reference``) and half their
        skins squared, and how far a flight's screen looks beyond its end (``slack``)."""
        return Struct(
            "dem_pairs",
            d=self.n.shape[1],
            n_facets=len(reference),
            R=R,
            lift=lift,
            reference=reference,
            half_skin2=half_skin2,
            slack=slack,
            end_slack2=(0.5 * slack) ** 2,
            n=len(self),
            i=self.i,
            j=self.j,
            normal=self.n,
            t=self.t,
            d0=self.d0,
            e_i=self.e_i,
            e_j=self.e_j,
            sep=self.sep,
            si=self.si.struct,
            sj=self.sj.struct,
            z=csr_of(self.ZT),
            slot=self.slot,
        )
