"""Frictionless contact with rigid obstacles (paper §3.4.1-3.4.2 with a rigid counterpart, §4).

An obstacle is a half-space {x : (x - p) . n < 0}; the body stays where (x - p) . n >= 0. Only
declared candidate facets are tested. With the free (non-contact) reconstruction u_f^free of a
candidate facet f, its gap is affine in the cell displacements,

    g_f(u) = n . (x_f + u_f^free - p) = r_f . u + g0_f.

When g_f < 0 the reconstruction switches to the contact one, u_f = u_f^free - g_f e_f:
- scheme B (eq. (25)-(27) with a rigid counterpart, theta = 1): e_f = n, so the normal gap is
  closed and the facet keeps its cell's tangential motion;
- scheme A (eq. (23)-(24) against a rigid body): e_f = A^-1 n / (n . A^-1 n) with A the matrix
  of eq. (20), so that the gap is closed and the tangential traction (I - n n) sigma_c n stays 0.
Both coincide with the free reconstruction at g_f = 0: the energy is continuous, and piecewise
quadratic in u. Writing the energy rows a = Q u + q (Q = [S; J], operators.py), the contact adds
delta_a = -sum_f g_f^- y_f with y_f = Q_F e_f the rows facet f's value enters, so

    V = 1/2 |a + delta_a|^2 (+ external),   -dV/du = -Q^T (a + delta_a) + sum_{g_f<0} (y_f . (a + delta_a)) r_f,

the exact gradient. Everything is local to the contact patch (the cells of the gaps' stencils and
of the rows y_f): it is computed from gathered patch values on every process, and each process
adds the entries of its owned cells. Along a MEMM free flight u + tau v each gap is affine in tau,
so the force integral is split at the sign changes of the gaps and the midpoint rule is exact on
every piece (paper §4); only the patch is sub-integrated.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.conditions import facet_indices
from dolfinx_dem.contact import candidates
from dolfinx_dem.contact.friction import cell_friction
from dolfinx_dem.contact.patch import PatchScatter
from dolfinx_dem.contact.rigid_statics import RigidStatics
from dolfinx_dem.errors import InputError
from dolfinx_dem.kernels import Struct, arena, csr_of, lib, pointer

#: Patch operators with at most this many entries are stored as dense arrays: a sparse
#: product costs microseconds of Python overhead even for the three dofs of a 1D bar.
_DENSE_ENTRIES = 4096


#: The largest angle between a scheme A candidate's inward normal and the obstacle's normal for
#: which the contact uses eq. (23)-(24) (``scheme_a_posed``).
SCHEME_A_MAX_ANGLE = np.pi / 4


def scheme_a_posed(n: np.ndarray, area_normals: np.ndarray) -> np.ndarray:
    """Whether eq. (23)-(24) against a rigid obstacle of normal ``n`` are used for facets of outward
    area normals ``area_normals`` (|f| n_f): the angle t between n and -n_f is at most 45 degrees.

    Against a rigid body, e_f = A^-1 n / (n . A^-1 n) closes the gap (n . e_f = 1) and, for an
    isotropic C, moves the facet along its own normal: |e_f| = 1 / cos t (2D and 3D). Its contact
    stiffness grows as 1 / cos^2 t and escapes the elastic stable-step bound: lambda_max of the
    contact-active stiffness over the bound's is 0.80 at t <= 45 deg (as without contact), 0.97 at
    60, 10 at 80 and 43 at 85 on a plate, nu = 0.3 (tests/test_contact.py), and A is singular at 90
    for nu = 0. Up to 45 deg, |e_f| <= sqrt(2). Beyond, the facet uses the scheme B rule e_f = n
    (its normal gap closed, its cell's tangential motion): stiffness as without contact at every
    angle. The rule depends on the facet and the obstacle only: the energy stays continuous and the
    force its exact gradient. Counted in ``RigidContact.scheme_b_rule``."""
    cos_t = -np.einsum("pi,pi->p", n, area_normals) / np.linalg.norm(area_normals, axis=1)
    return cos_t >= np.cos(SCHEME_A_MAX_ANGLE) * (1.0 - 1e-12)


def _compact(A: scipy.sparse.spmatrix):
    """A as a dense array if small (see ``_DENSE_ENTRIES``), else as CSR; both support ``@``."""
    return A.toarray() if A.shape[0] * A.shape[1] <= _DENSE_ENTRIES else A.tocsr()


def _csr(A) -> Struct:
    """The ``dem_csr`` of a ``_compact`` operator: a dense one's nonzeros row by row (its
    products skip only zero terms: the same sums)."""
    return csr_of(scipy.sparse.csr_matrix(A) if isinstance(A, np.ndarray) else A)


@dataclasses.dataclass(frozen=True)
class HalfSpace:
    """Rigid obstacle {x : (x - point) . normal < 0}; ``normal`` points from the obstacle into the
    free space. ``facets`` are the candidate facets of the body: process-local facet indices or
    a DOLFINx MeshTags (with ``tag``, its facets of that value; conditions.facet_indices);
    ``tolerance`` (m, >= 0) is how far a body vertex may lie inside at t = 0; ``friction`` the
    Coulomb coefficient mu >= 0 (contact/friction.py; 0: frictionless)."""

    point: Sequence[float]
    normal: Sequence[float]
    facets: np.ndarray
    tolerance: float = 0.0
    tag: int | None = None
    friction: float = 0.0


class RigidContact:
    """Contact of a DEMDiscretisation with rigid half-spaces; see the module docstring.

    Distributed (patch.py): a process handles the candidate facets of its owned cells (its
    *own* facets) and knows those of its first halo layer; it sums the energy change over its
    own rows, computes the force terms of its own rows (Q^T delta) and own facets
    (coefficient times r_f), and adds them into the distributed force by a reverse scatter.
    """

    tracks_momentum = False

    def __init__(self, dem, obstacles: Sequence[HalfSpace]):
        geom, rec, d = dem.geometry, dem.reconstruction, dem.d
        self.dem, self.comm, self.d = dem, dem.comm, d
        obstacles = tuple(obstacles)
        if not obstacles:
            raise InputError("RigidContact needs at least one obstacle (HalfSpace)")
        normals, points = [], []
        for k, ob in enumerate(obstacles):
            n = np.asarray(ob.normal, dtype=float)
            p = np.asarray(ob.point, dtype=float)
            if n.shape != (d,) or p.shape != (d,) or not np.isfinite(n).all() or not np.isfinite(p).all():
                raise InputError(f"obstacle {k}: point and normal need {d} finite components")
            if np.linalg.norm(n) == 0:
                raise InputError(f"obstacle {k}: the normal is zero")
            if not (np.isfinite(ob.tolerance) and ob.tolerance >= 0):
                raise InputError(f"obstacle {k}: the gap tolerance must be >= 0, got {ob.tolerance}")
            mu = ob.friction
            if not (isinstance(mu, (int, float)) and not isinstance(mu, bool) and np.isfinite(mu) and mu >= 0):
                raise InputError(f"obstacle {k}: the friction coefficient must be a finite number >= 0, "
                                 f"got {ob.friction!r}")
            if ob.friction > 0 and d == 1:
                raise InputError(f"obstacle {k}: friction acts along the obstacle's plane, which a 1D body "
                                 "does not have (friction = 0 in 1D)")
            normals.append(n / np.linalg.norm(n))
            points.append(p)
            inside = (geom.cell_vertices[: dem.n_owned].reshape(-1, d) - p) @ normals[-1]
            deepest = self.comm.allreduce(-inside.min(initial=np.inf), op=MPI.MAX)
            if deepest > ob.tolerance:
                raise InputError(f"obstacle {k} intersects the body at t = 0: a vertex lies "
                                 f"{deepest:.3e} m inside it (tolerance {ob.tolerance:g} m)")

        # Candidate facets: the marked facets of the cells in halo layers 0 and 1.
        facets = [facet_indices(ob.facets, ob.tag, f"obstacle {k}", d) for k, ob in enumerate(obstacles)]
        found = candidates.select(
            dem,
            np.concatenate(facets),
            np.repeat(np.arange(len(facets)), [len(f) for f in facets]),
            "obstacles (a facet is a contact candidate of two obstacles)",
        )
        cell, j, f, owned, mark = found.cell, found.j, found.facet, found.owned, found.mark
        counts = self.comm.allreduce(np.bincount(mark[owned], minlength=len(obstacles)), op=MPI.SUM)
        for k in np.flatnonzero(counts == 0)[:1]:
            raise InputError(f"obstacle {k}: its contact candidate boundary has no facet")
        candidates.check(dem, found, "obstacles")
        order = np.lexsort((f, ~owned))  # own facets first
        self.facets, self.cells, obstacle = f[order], cell[order], mark[order]
        self.num_obstacles, self._obstacle = len(obstacles), obstacle
        self._facet_j = j[order]  # local index of each candidate in its cell
        self.num_own = int(owned.sum())
        self.num_facets = self.comm.allreduce(self.num_own, op=MPI.SUM)
        self.normals = np.array(normals)[obstacle].reshape(-1, d)
        self.points = np.array(points)[obstacle].reshape(-1, d)
        nc = len(self.facets)

        # e_f: the direction the contact moves u_f in (scheme A or B, as the facet's free rows);
        # scheme A's where it is well posed (``scheme_a_posed``), scheme B's elsewhere.
        e = self.normals.copy()
        is_a = np.isin(self.facets, rec.scheme_a_facets)
        jj = self._facet_j
        is_a &= scheme_a_posed(self.normals, geom.facet_area_normals[self.cells, jj])
        if is_a.any():
            c = self.cells[is_a]
            C = dem.materials.elasticity_tensor(d, c)
            a = geom.facet_area_normals[c, jj[is_a]]
            n = self.normals[is_a]
            A = np.einsum("nijkl,nj,nl->nik", C, n, a) / geom.cell_volumes[c, None, None]
            Ainv_n = np.linalg.solve(A, n[..., None])[..., 0]
            e[is_a] = Ainv_n / np.einsum("ni,ni->n", n, Ainv_n)[:, None]
        self.directions = e
        #: own scheme A candidates that use the scheme B rule (``scheme_a_posed``), all processes
        self.scheme_b_rule = self.comm.allreduce(
            int((np.isin(self.facets, rec.scheme_a_facets) & ~is_a)[: self.num_own].sum()), op=MPI.SUM)

        # Gaps g = Rn u + g0 (g0 from the geometry and the data's lift).
        dofs = (self.facets[:, None] * d + np.arange(d)).ravel()
        normal_rows = scipy.sparse.csr_matrix(
            (self.normals.ravel(), (np.repeat(np.arange(nc), d), np.arange(nc * d))), shape=(nc, nc * d)
        )
        R_free = rec.R[dofs]
        self._D_free = dem.data.facet_lift(self.facets).ravel()
        self._g0 = np.einsum("ni,ni->n", self.normals, geom.facet_centres[self.facets] - self.points)
        self._g0 += normal_rows @ self._D_free

        # The energy rows the candidates touch (y_f = Q_F e_f), among this process's rows.
        rows = dem.rows
        e_cols = scipy.sparse.csr_matrix(
            (e.ravel(), (np.arange(nc * d), np.repeat(np.arange(nc), d))), shape=(nc * d, nc)
        )
        Y = (rows.QF[:, dofs] @ e_cols).tocsc()
        touched = np.unique(Y.indices)
        Y, Q = Y[touched].tocsr(), rows.Q[touched]
        # The patch: the held dofs these rows and the gaps read.
        patch = np.unique(np.concatenate([Q.indices, R_free.indices]))
        self.scatter = PatchScatter(dem.create_vector(), dem.columns[patch])
        Q, R_free = Q[:, patch], R_free[:, patch]
        Rn = normal_rows @ R_free
        own_rows = touched < rows.num_owned
        self._q = dem.data.row_lift(touched)
        self._is_elastic_row = touched < rows.num_elastic
        self._own_rows = own_rows
        self._Q, self._Y, self._Rn = _compact(Q), _compact(Y), _compact(Rn)
        Y_own = Y[:, : self.num_own]
        self._Z = _compact(Q[own_rows].T @ Y[own_rows])  # Q^T delta on the own rows = Z w
        self._YQ = _compact(Y_own.T @ Q)  # coefficient: y_f . a = YQ u + Yq
        self._Yq = Y_own.T @ self._q
        G = (Y_own.T @ Y).tocsr()  # y_f . y_f' for the own facets f
        self._G = _compact(G)
        self._RnT_own = _compact(Rn[: self.num_own].T)
        self._R_free = _compact(R_free)
        self._kernel = Struct(
            "dem_rigid", Rn=_csr(self._Rn), g0=self._g0, n_own=self.num_own, Z=_csr(self._Z), YQ=_csr(self._YQ),
            G=_csr(G), RnT=_csr(self._RnT_own), Q=_csr(self._Q), Y=_csr(self._Y), Yq=self._Yq, q=self._q,
            own_row=own_rows.astype(np.int8), elastic=self._is_elastic_row.astype(np.int8))
        self._arena = arena()
        self._patch_force = np.zeros(len(self.scatter))
        #: Coulomb friction on the own facets' cells (None: frictionless), contact/friction.py
        self.friction = cell_friction(self, [float(ob.friction) for ob in obstacles], obstacle)
        self._normal_impulse = np.zeros(self.num_own)  # of the last force integral, for the friction
        self._grad_weights = (
            geom.facet_area_normals[self.cells, geom.facet_local[self.facets, 0]] / geom.cell_volumes[self.cells, None]
        )
        self.evaluations = 0
        self._statics = None  # the statics interface, made on first use (``statics``)

    # -- patch data ----------------------------------------------------------------------------
    def prepare(
        self, u: PETSc.Vec, v: PETSc.Vec | None = None, dt: float = 0.0, up: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Nothing to prepare (every candidate facet is tested at every evaluation): the patch
        values of u (``up`` if given) and v (collective)."""
        return self.patch_values(u) if up is None else up, None if v is None else self.patch_values(v)

    def patch_values(self, vec: PETSc.Vec) -> np.ndarray:
        """The values of ``vec`` at the patch dofs (collective)."""
        return self.scatter.gather(vec)

    def gaps(self, up: np.ndarray) -> np.ndarray:
        """g_f of the free reconstructions of the candidates (own first) for patch values ``up`` (m)."""
        return self._Rn @ up + self._g0

    def _state(self, up, active=None, g=None):
        if g is None:
            g = self.gaps(up)
        if active is None:
            active = g < 0
        w = np.where(active, g, 0.0)  # g^- for the natural active set
        a = self._Q @ up + self._q
        delta = self._Y @ w
        return active, w, a, delta

    def force_correction(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """This process's part of F - F_free at the patch dofs: the terms of its own rows and own
        facets (the exact negative gradient of the energy change, summed over processes).
        ``active`` imposes the set of candidates in contact (default: those with g < 0)."""
        self.evaluations += 1
        g = self.gaps(up)
        if active is None and not (g < 0).any():
            return np.zeros_like(up)  # no facet in contact: the correction is exactly 0
        active, w, a, delta = self._state(up, active, g)
        own = slice(0, self.num_own)
        coefficient = np.where(active[own], self._YQ @ up + self._Yq - self._G @ w, 0.0)
        return self._Z @ w + self._RnT_own @ coefficient

    def add(self, correction: np.ndarray, out: PETSc.Vec, scale: float = 1.0) -> None:
        """out += scale * correction (patch values; a reverse scatter, collective)."""
        self.scatter.add(correction, out, scale)

    def add_force(self, u: PETSc.Vec, out: PETSc.Vec, active: np.ndarray | None = None) -> None:
        """out += F - F_free at u (collective). ``active``, a bool array over the own facets,
        imposes the set of facets in contact (statics); default: those with g < 0."""
        if active is not None:
            active = self._local_activity(active)
        self.scatter.add(self.force_correction(self.patch_values(u), active), out)

    # -- statics: active sets of the own facets (contact/rigid_statics.py) ----------------------
    def _local_activity(self, active: np.ndarray) -> np.ndarray:
        """The activity of all local candidates from that of the own ones (their owners')."""
        table = np.zeros((self.dem.n_owned, self.d + 1))
        table[self.cells[: self.num_own], self._facet_j[: self.num_own]] = active
        return self.dem.halo_exchange(table)[self.cells, self._facet_j] > 0

    def own_gaps(self, u: PETSc.Vec) -> np.ndarray:
        """Gaps of the own candidate facets at u (collective: the patch scatter)."""
        return self.gaps(self.patch_values(u))[: self.num_own]

    def own_gap_rates(self, v: PETSc.Vec) -> np.ndarray:
        """grad g_f . v of the own candidate facets (the gaps' rates along v; collective)."""
        return (self._Rn @ self.patch_values(v))[: self.num_own]

    def reactions(self, u: PETSc.Vec, active: np.ndarray | None = None) -> np.ndarray:
        """The normal force the obstacle exerts on each own facet (N, or N/m in 2D; 0 out of
        contact): y_f . (a + delta_a) on the active set (default g < 0; collective). This is facet
        f's share of the contact force, (y_f . a') r_f (plus a term that sums to zero over a free
        body's translations); r_f reproduces translations, so its resultant is (y_f . a') n. The
        reactions of all facets add up to the total reaction, which balances the load at
        equilibrium. The row values a' come from every row the facet touches, owned here or not."""
        up = self.patch_values(u)
        local = None if active is None else self._local_activity(active)
        return self._reactions(up, local)

    def _reactions(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """``reactions`` of the own facets for patch values ``up`` (local)."""
        active, w, a, delta = self._state(up, active)
        own = slice(0, self.num_own)
        return np.where(active[own], self._YQ @ up + self._Yq - self._G @ w, 0.0)

    def add_hessian(self, H: PETSc.Mat, active: np.ndarray) -> None:
        """H += d^2 V / du^2 - K for the own facets' active set (statics; collective):
        with Q' = Q - Y_A Rn_A on the touched rows, Q'^T Q' - Q^T Q, summed over the own rows.
        ``H`` must accept new nonzeros; the caller assembles it."""
        local = self._local_activity(active)
        own_rows = self._own_rows
        Q = scipy.sparse.csr_matrix(self._Q)[own_rows]
        D = scipy.sparse.csr_matrix(self._Y)[own_rows][:, local] @ scipy.sparse.csr_matrix(self._Rn)[local]
        C = (D.T @ D - Q.T @ D - D.T @ Q).tocsr()
        C.eliminate_zeros()
        dofs = self.scatter.dofs
        for i in np.flatnonzero(np.diff(C.indptr)):
            lo, hi = C.indptr[i], C.indptr[i + 1]
            H.setValues([int(dofs[i])], dofs[C.indices[lo:hi]], C.data[lo:hi], addv=PETSc.InsertMode.ADD_VALUES)

    def gap_gradient(self, rank: int, k: int) -> PETSc.Vec:
        """grad g of own facet ``k`` of process ``rank``, as a distributed vector (collective)."""
        vec = self.dem.create_vector()
        row = np.zeros(len(self.scatter))
        if self.comm.rank == rank:
            r = self._Rn[[k]]
            row = (r.toarray() if scipy.sparse.issparse(r) else np.asarray(r)).ravel()
        self.scatter.add(row, vec)
        return vec

    def gap_gradient_dot(self, k: int, up: np.ndarray) -> float:
        """grad g_k . v for own facet k and the patch values ``up`` of v (local)."""
        r = self._Rn[[k]]
        return float(np.asarray(r @ up).ravel()[0])

    def _check_patch(self, *values: np.ndarray) -> None:
        """Patch values for the kernels: one float64 per patch dof (they read that many)."""
        for x in values:
            if x.shape != (len(self.scatter),) or x.dtype != np.float64:
                raise ValueError(f"patch values of shape {x.shape} and type {x.dtype}: the rigid contact's patch has "
                                 f"{len(self.scatter)} float64 dofs")

    def energy_correction(self, up: np.ndarray) -> tuple[float, float]:
        """(elastic, stabilisation) energy changes of this process's own rows (not reduced):
        sum of -a delta + delta^2 / 2 over them (compiled: ``dem_rigid_energy``)."""
        self._check_patch(up)
        energy = np.zeros(2)
        if lib.dem_rigid_energy(self._kernel.c, pointer(up), self._arena, pointer(energy)) < 0:
            raise MemoryError("the rigid contact's energy kernel ran out of memory")
        return float(energy[0]), float(energy[1])

    # -- events --------------------------------------------------------------------------------
    def force_integral(self, up: np.ndarray, vp: np.ndarray, dt: float, out: PETSc.Vec) -> int:
        """out += int_0^dt (F - F_free)(u + tau v) dtau, exactly (collective), for the patch
        values up, vp of u and v (``prepare``); returns the largest number of pieces a facet's
        integral is split into.

        Along the flight every gap is affine, g_f(tau) = g_f + tau s_f. The rows' part,
        Q^T delta, is linear in the g_f^-, whose integrals are exact in closed form. The facet
        part, coefficient_f(tau) r_f with coefficient_f = y_f . (a - delta) on facet f's
        contact, is affine in tau between the events (sign changes) of the candidates that share
        rows with f, so it is split there, and only there (paper §4: an impact elsewhere does not
        split it), and integrated by the midpoint rule on each piece: exact (compiled:
        ``dem_rigid_force_integral``)."""
        self._check_patch(up, vp)
        pieces = lib.dem_rigid_force_integral(self._kernel.c, pointer(up), pointer(vp), float(dt), self._arena,
                                              pointer(self._patch_force), pointer(self._normal_impulse))
        if pieces < 0:
            raise MemoryError("the rigid contact's force integral kernel ran out of memory")
        self.scatter.add(self._patch_force, out)
        self.evaluations += pieces
        return pieces

    def add_friction(self, state, impulse: PETSc.Vec) -> float:
        """impulse += the step's frictional impulses T^n on this process's owned dofs, from the
        normal impulses of the step's ``force_integral`` and the velocities of ``state`` (a
        memm_state.StepState after its ``advance_rows``); returns this process's dissipation
        -v^{n+1/2} . T^n >= 0 (contact/friction.py). Frictionless: 0, nothing added."""
        return 0.0 if self.friction is None else self.friction.apply(self._normal_impulse, state, impulse)

    # -- outputs -------------------------------------------------------------------------------
    def facet_displacements(self, up: np.ndarray) -> np.ndarray:
        """Reconstructed (contact-aware) displacements of the candidates (own first), (n, d)."""
        free = (self._R_free @ up + self._D_free).reshape(-1, self.d)
        return free - np.minimum(self.gaps(up), 0.0)[:, None] * self.directions

    def gradient_correction(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(owned cells, change of their gradient (eq. (8))) of the own candidates, (n, d, d)."""
        own = slice(0, self.num_own)
        delta = -np.minimum(self.gaps(up)[own], 0.0)[:, None] * self.directions[own]
        return self.cells[own], np.einsum("ni,nj->nij", delta, self._grad_weights[own])

    def contact_gap(self, up: np.ndarray) -> tuple[float, float]:
        """Smallest gap n . (x_f + u_f - p) over all candidates (m) with the contact-aware u_f,
        and the first coordinate of that facet's displaced barycentre (collective)."""
        own = slice(0, self.num_own)
        uf = self.facet_displacements(up)[own]
        x = self.dem.geometry.facet_centres[self.facets[own]] + uf
        gap = np.einsum("ni,ni->n", self.normals[own], x - self.points[own])
        k = int(np.argmin(gap)) if len(gap) else -1
        best = (float(gap[k]), float(x[k, 0])) if k >= 0 else (np.inf, np.inf)
        return min(self.comm.allgather(best))

    def force_sums(self, up: np.ndarray) -> np.ndarray:
        """This process's part (sum over processes) of [F_0, ..., F_{K-1}, N, A]: F_k (d,) the
        force obstacle k exerts on the body (N, N/m in 2D), N its normal part summed over the
        obstacles (the sum of ``reactions``), A the area of the facets in contact (g < 0).

        F_k = dV/dp_k, the derivative of the energy with respect to the obstacle's position: a
        shift dp changes every gap of obstacle k by -n . dp and dV/dg_f = -y_f . (a + delta_a),
        so F_k = sum_f (y_f . (a + delta_a)) n over its facets in contact. It is exact (no
        quadrature), exactly 0 with every gap open, and equals the sum over the cells of the
        contact forces F - F_free, i.e. the contact's share of the rate of change of the
        momentum, when no Dirichlet condition enters the candidates' rows and stencils."""
        own = slice(0, self.num_own)
        g = self.gaps(up)[own]
        forces, normal, area = np.zeros((self.num_obstacles, self.d)), 0.0, 0.0
        if (g < 0).any():
            reactions = self._reactions(up)
            np.add.at(forces, self._obstacle[own], reactions[:, None] * self.normals[own])
            normal = reactions.sum()
            area = self.dem.geometry.facet_areas[self.facets[own]][g < 0].sum()
        return np.append(forces.ravel(), [normal, area])

    def output_columns(self) -> tuple[str, ...]:
        """The smallest gap ``contact_gap`` (``contact_gap``), ``contact_pressure`` (the obstacles'
        total normal force over the area of the facets in contact, exactly 0 with every gap
        open), in 1D the position ``tip_position`` of the contact end, and the force of each
        obstacle k on the body, ``contact_force_obstacle<k>_<x|y|z>`` (``force_sums``). With
        friction, the mean tangential force of each obstacle over the last step,
        ``friction_force_obstacle<k>_<x|y|z>`` (its impulse T^n over dt), and ``slipping_facets``,
        the facets at the Coulomb limit in that step (0 at the first row)."""
        xyz = "xyz"[: self.d]
        friction = () if self.friction is None else (
            tuple(f"friction_force_obstacle{k}_{c}" for k in range(self.num_obstacles) for c in xyz)
            + ("slipping_facets",))
        return (
            ("contact_gap", "contact_pressure")
            + (("tip_position",) if self.d == 1 else ())
            + tuple(f"contact_force_obstacle{k}_{c}" for k in range(self.num_obstacles) for c in xyz)
            + friction
        )

    def output_sums(self, up: np.ndarray) -> np.ndarray:
        """This process's part of the sums of the outputs: ``force_sums``, then with friction the
        last step's tangential forces and slipping facets."""
        sums = self.force_sums(up)
        if self.friction is not None:
            sums = np.concatenate([sums, self.friction.forces.ravel(), [self.friction.slipping]])
        return sums

    def output_values(self, up: np.ndarray, sums: np.ndarray) -> list[float]:
        """The values of ``output_columns`` from the reduced ``output_sums`` (collective)."""
        n = self.num_obstacles * self.d
        forces, normal, area = sums[:n], sums[n], sums[n + 1]
        gap, x = self.contact_gap(up)
        return ([gap, normal / area if area > 0 else 0.0] + ([x] if self.d == 1 else []) + list(forces)
                + list(sums[n + 2:]))

    def statics(self) -> RigidStatics:
        """The statics interface (contact/rigid_statics.py), made once."""
        if self._statics is None:
            self._statics = RigidStatics(self)
        return self._statics

    # -- checkpoint (contact.protocol.ContactModel) ----------------------------------------------------------------
    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """Only a counter: every candidate is tested at every evaluation; friction's state is a
        ``cell_state``."""
        return {"evaluations": np.array([self.evaluations], dtype=np.int64)}

    def restore_state(self, state: Mapping[str, np.ndarray] | None) -> None:
        if state is not None:
            self.evaluations = int(state["evaluations"][0])

    def cell_state(self) -> dict[str, np.ndarray]:
        """With friction, the lagged normal forces Ntilde_f (contact/friction.py) of the own facets
        as ``friction_normal_force`` (n_owned, d + 1): row c, column j for the facet j of cell c
        (the cell's own numbering, which does not depend on the partition); 0 elsewhere."""
        if self.friction is None:
            return {}
        own = slice(0, self.num_own)
        table = np.zeros((self.dem.n_owned, self.d + 1))
        table[self.cells[own], self._facet_j[own]] = self.friction.normal_force
        return {"friction_normal_force": table}

    def restore_cell_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Friction's lagged normal forces from ``cell_state`` (a step has set them: ``started``)."""
        if self.friction is not None:
            own = slice(0, self.num_own)
            self.friction.normal_force[:] = state["friction_normal_force"][self.cells[own], self._facet_j[own]]
            self.friction.started = True
