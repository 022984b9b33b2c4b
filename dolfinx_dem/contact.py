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
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse
from petsc4py import PETSc


#: Patch operators with at most this many entries are stored as dense arrays: a sparse
#: product costs microseconds of Python overhead even for the three dofs of a 1D bar.
_DENSE_ENTRIES = 4096


def _compact(A: scipy.sparse.spmatrix):
    """A as a dense array if small (see ``_DENSE_ENTRIES``), else as CSR; both support ``@``."""
    return A.toarray() if A.shape[0] * A.shape[1] <= _DENSE_ENTRIES else A.tocsr()


def gather_patch(comm, vec: PETSc.Vec, owned_local: np.ndarray) -> np.ndarray:
    """The values of ``vec`` at a patch of global dofs, on every process: each process gives its
    owned patch entries (local indices ``owned_local``, in ascending global order), and ranks own
    ascending dof ranges, so the concatenation is in patch order."""
    mine = vec.array_r[owned_local]
    if comm.size == 1:
        return mine.copy()
    return np.concatenate(comm.allgather(mine))


@runtime_checkable
class ContactModel(Protocol):
    """The interface of a contact model (``RigidContact``, ``pair_contact.PairContact``) that
    ``DEMDiscretisation``, ``MEMM``, ``statics`` and the checkpoints use; nothing else of a model
    is called from outside but its outputs (the series columns and summary figures of a run).
    All methods are collective. ``up`` are patch values (``patch_values``), valid until the
    next ``prepare``.

    Three groups: the dynamics (``prepare`` ... ``force_integral``), the statics of a piecewise
    quadratic potential (``gaps`` ... ``add_hessian_correction``: rigid obstacles; contact
    between bodies raises ``NotImplementedError`` there, its energy is quartic), and the
    checkpoint (``checkpoint_state``, ``restore_state``)."""

    facets: np.ndarray  # candidate facets (global numbers), (n_facets,)
    cells: np.ndarray  # cells of the candidate facets (global numbers), (n_facets,)

    def prepare(self, u: PETSc.Vec, v: PETSc.Vec | None = None, dt: float = 0.0) -> None:
        """Make the model valid for the states u + tau v, 0 <= tau <= dt (MEMM: every step)."""

    def patch_values(self, vec: PETSc.Vec) -> np.ndarray:
        """The values of ``vec`` at the patch dofs, on every process."""

    def force_correction(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """F - F_free at the patch dofs (the exact negative gradient of ``energy_correction``);
        ``active`` imposes the candidate facets in contact (statics), default: those with g < 0."""

    def energy_correction(self, up: np.ndarray) -> tuple[float, float]:
        """(elastic, stabilisation) energy changes of the contact reconstruction."""

    def gradient_correction(self, up: np.ndarray) -> np.ndarray:
        """Change of the gradient of each candidate's cell, (n_facets, d, d)."""

    def add(self, correction: np.ndarray, out: PETSc.Vec, scale: float = 1.0) -> None:
        """out += scale * correction on the owned patch dofs."""

    def force_integral(self, u: PETSc.Vec, v: PETSc.Vec, dt: float, out: PETSc.Vec) -> int:
        """out += int_0^dt (F - F_free)(u + tau v) dtau, exactly; returns the evaluations."""

    def gaps(self, up: np.ndarray) -> np.ndarray:
        """Gap g_f of each candidate facet (m), affine in u: g = r . u + g0."""

    def gap_gradients(self, facets: np.ndarray) -> np.ndarray:
        """The rows r_f = dg_f/du of the candidates ``facets`` (indices into ``facets``) on the
        patch dofs, shape (len(facets), n_patch); ``add`` puts a row into a vector."""

    def reactions(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Normal contact force (N) on each candidate facet with the set ``active`` in contact
        (default g < 0); 0 on the other facets."""

    def add_hessian_correction(self, active: np.ndarray, H: PETSc.Mat) -> None:
        """H += d^2 V/du^2 - K on this process's rows, for the set ``active`` in contact; H is
        left unassembled (call ``H.assemble()``)."""

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """The model's state that is not a function of u (e.g. the pair list) and its counters,
        as numpy arrays, the same on every process (``checkpoint.py``)."""

    def restore_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore ``checkpoint_state`` of a model of the same scene, possibly set up on another
        number of processes (facets are matched by position)."""


@dataclasses.dataclass(frozen=True)
class HalfSpace:
    """Rigid obstacle {x : (x - point) . normal < 0}; ``normal`` points from the obstacle into the
    free space. ``facets`` are the process-local candidate facets of the body (e.g. from a
    MeshTags); ``tolerance`` (m, >= 0) is how far a body vertex may lie inside at t = 0."""

    point: Sequence[float]
    normal: Sequence[float]
    facets: np.ndarray
    tolerance: float = 0.0


class RigidContact:
    """Contact of a DEMDiscretisation with rigid half-spaces; see the module docstring."""

    def __init__(self, dem, obstacles: Sequence[HalfSpace]):
        from dolfinx_dem import _compat

        geom, rec, ops, d = dem.geometry, dem.reconstruction, dem.operators, dem.d
        self.dem, self.comm, self.d = dem, dem.comm, d
        facets, normals, points = [], [], []
        for k, ob in enumerate(obstacles):
            n = np.asarray(ob.normal, dtype=float)
            p = np.asarray(ob.point, dtype=float)
            if n.shape != (d,) or p.shape != (d,) or not np.isfinite(n).all() or not np.isfinite(p).all():
                raise ValueError(f"obstacle {k}: point and normal need {d} finite components")
            if np.linalg.norm(n) == 0:
                raise ValueError(f"obstacle {k}: the normal is zero")
            if not (np.isfinite(ob.tolerance) and ob.tolerance >= 0):
                raise ValueError(f"obstacle {k}: the gap tolerance must be >= 0, got {ob.tolerance}")
            n = n / np.linalg.norm(n)
            f = np.unique(np.concatenate(self.comm.allgather(
                _compat.local_facet_global_indices(dem.mesh, np.asarray(ob.facets, dtype=np.int32)))))
            if f.size == 0:
                raise ValueError(f"obstacle {k}: its contact candidate boundary has no facet")
            interior = geom.facet_cells[f, 1] >= 0
            if interior.any():
                raise ValueError(f"obstacle {k}: contact candidates must be boundary facets; facet "
                                 f"{f[interior][0]} at {geom.facet_centres[f[interior][0]].tolist()} is interior")
            if np.isin(f, rec.dirichlet_facets).any():
                raise ValueError(f"obstacle {k}: contact candidate facets must not carry a Dirichlet condition")
            inside = (geom.cell_vertices.reshape(-1, d) - p) @ n
            if inside.min() < -ob.tolerance:
                raise ValueError(f"obstacle {k} intersects the body at t = 0: a vertex lies "
                                 f"{-inside.min():.3e} m inside it (tolerance {ob.tolerance:g} m)")
            facets.append(f)
            normals.append(np.repeat(n[None], len(f), axis=0))
            points.append(np.repeat(p[None], len(f), axis=0))
        self.facets = np.concatenate(facets)
        if len(np.unique(self.facets)) != len(self.facets):
            raise ValueError("a facet is a contact candidate of two obstacles")
        self.normals, self.points = np.concatenate(normals), np.concatenate(points)
        nc = len(self.facets)
        cells = geom.facet_cells[self.facets, 0]
        self.cells = cells

        # e_f: the direction the contact moves u_f in (scheme A or B, as the facet's free rows).
        e = self.normals.copy()
        is_a = np.isin(self.facets, rec.scheme_a_facets)
        if is_a.any():
            C = dem.material.elasticity_tensor(d)
            j = geom.facet_local[self.facets[is_a], 0]
            c = cells[is_a]
            a = geom.facet_area_normals[c, j]
            n = self.normals[is_a]
            A = np.einsum("ijkl,nj,nl->nik", C, n, a) / geom.cell_volumes[c, None, None]
            Ainv_n = np.linalg.solve(A, n[..., None])[..., 0]
            e[is_a] = Ainv_n / np.einsum("ni,ni->n", n, Ainv_n)[:, None]
        self.directions = e

        # Gaps g = Rn u + g0 (g0 from the geometry and the Dirichlet lift, static here).
        dofs = (self.facets[:, None] * d + np.arange(d)).ravel()
        normal_rows = scipy.sparse.csr_matrix(
            (self.normals.ravel(), (np.repeat(np.arange(nc), d), np.arange(nc * d))), shape=(nc, nc * d))
        Rn = (normal_rows @ rec.R[dofs]).tocsr()
        self._g0 = np.einsum("ni,ni->n", self.normals, geom.facet_centres[self.facets] - self.points)
        self._g0 += normal_rows @ (rec.D[dofs] @ dem.dirichlet_values(0.0).ravel())
        if dem._time_dependent:
            raise ValueError("contact with time-dependent Dirichlet conditions is not supported")

        # Rows y_f = Q_F e_f of the energy vector a = [S u + s; J u + j] touched by each facet.
        e_cols = scipy.sparse.csr_matrix((e.ravel(), (np.arange(nc * d), np.repeat(np.arange(nc), d))),
                                         shape=(nc * d, nc))
        QF = scipy.sparse.vstack([ops.S_facet[:, dofs], ops.J_facet[:, dofs]]).tocsr()
        Y = (QF @ e_cols).tocsc()
        rows = np.unique(Y.indices)
        Q = scipy.sparse.vstack([ops.S, ops.J]).tocsr()
        nS = ops.S.shape[0]
        g = dem.dirichlet_values(0.0).ravel()
        q = np.concatenate([ops.S_dirichlet @ g, ops.J_dirichlet @ g])
        Q_rows = Q[rows]
        R_rows = rec.R[dofs]
        self.patch = np.unique(np.concatenate([Q_rows.indices, R_rows.indices]))  # global dofs
        Rn, Q_patch, Y = Rn[:, self.patch], Q_rows[:, self.patch], Y[rows]
        self._Rn, self._RnT = _compact(Rn), _compact(Rn.T)
        self._Q = _compact(Q_patch)
        self._q = q[rows]
        self._Y, self._YT = _compact(Y), _compact(Y.T)
        self._Z = _compact(Q_patch.T @ Y)
        self._is_elastic_row = rows < nS
        self._R_free = _compact(R_rows[:, self.patch])
        self._D_free = rec.D[dofs] @ g
        # G_c += delta_f (x) a_{f,c} / |c| for the candidate's cell (eq. (8)).
        cell_rows = (cells[:, None] * d * d + np.arange(d * d)).ravel()
        self._grad_rows = _compact(ops.grad[cell_rows][:, self.patch])
        self._grad_lift = ops.grad_dirichlet[cell_rows] @ g
        self._grad_weights = geom.facet_area_normals[cells, geom.facet_local[self.facets, 0]] / \
            geom.cell_volumes[cells, None]

        start, stop = dem.cell_range
        self._owned = (self.patch >= start * d) & (self.patch < stop * d)
        self._owned_local = (self.patch[self._owned] - start * d).astype(np.int32)
        self.evaluations = 0

    # -- patch data ----------------------------------------------------------------------------
    def prepare(self, u: PETSc.Vec, v: PETSc.Vec | None = None, dt: float = 0.0) -> None:
        """Nothing to prepare: every candidate facet is tested at every evaluation."""

    def patch_values(self, vec: PETSc.Vec) -> np.ndarray:
        """Values of a distributed vector at the patch dofs, on every process."""
        return gather_patch(self.comm, vec, self._owned_local)

    def gaps(self, up: np.ndarray) -> np.ndarray:
        """g_f of the free reconstructions for patch values ``up`` (m)."""
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
        """F - F_free at the patch dofs (N): the exact negative gradient of the energy change.
        ``active`` imposes the set of facets in contact (default: those with g < 0)."""
        self.evaluations += 1
        g = self.gaps(up)
        if active is None and not (g < 0).any():
            return np.zeros_like(up)  # no facet in contact: the correction is exactly 0
        active, w, a, delta = self._state(up, active, g)
        coefficient = np.where(active, self._YT @ (a - delta), 0.0)
        return self._Z @ w + self._RnT @ coefficient

    def reaction_pressures(self, up: np.ndarray) -> np.ndarray:
        """Normal pressure the obstacle exerts on each candidate facet (Pa, 0 out of contact).

        Facet f's share of the contact force is (y_f . a') r_f (+ a term that sums to zero over a
        free body's translations); r_f reproduces translations, so its resultant is
        (y_f . a') n and the pressure (y_f . a') / |f|. The pressures of all facets add up to
        the total reaction, which balances the load at equilibrium."""
        return self.reactions(up) / self.dem.geometry.facet_areas[self.facets]

    def hessian_correction(self, active: np.ndarray) -> scipy.sparse.csr_matrix:
        """d^2 V / du^2 - K on the patch (patch x patch) for a fixed set of facets in contact:
        with Q' = Q - Y_A Rn_A on the touched rows, Q'^T Q' - Q^T Q."""
        Rn = scipy.sparse.csr_matrix(self._Rn)[active]
        Y = scipy.sparse.csc_matrix(self._Y)[:, active]
        ZR = scipy.sparse.csc_matrix(self._Z)[:, active] @ Rn
        return (Rn.T @ ((Y.T @ Y) @ Rn) - ZR - ZR.T).tocsr()

    def energy_correction(self, up: np.ndarray) -> tuple[float, float]:
        """(elastic, stabilisation) energy changes from the contact reconstructions."""
        g = self.gaps(up)
        if not (g < 0).any():
            return 0.0, 0.0
        _, _, a, delta = self._state(up, g=g)
        change = -a * delta + 0.5 * delta**2
        return float(change[self._is_elastic_row].sum()), float(change[~self._is_elastic_row].sum())

    def add(self, correction: np.ndarray, out: PETSc.Vec, scale: float = 1.0):
        """out += scale * correction on the owned patch dofs."""
        out.array[self._owned_local] += scale * correction[self._owned]

    # -- events --------------------------------------------------------------------------------
    def event_times(self, up: np.ndarray, vp: np.ndarray, dt: float) -> np.ndarray:
        """Times tau in (0, dt) where a gap along u + tau v changes sign, sorted."""
        g0 = self.gaps(up)
        slope = self._Rn @ vp
        tau = np.divide(-g0, slope, out=np.full_like(g0, np.inf), where=slope != 0)
        tau = tau[(tau > 0) & (tau < dt)]
        return np.unique(tau)

    def force_integral(self, u: PETSc.Vec, v: PETSc.Vec, dt: float, out: PETSc.Vec) -> int:
        """out += int_0^dt (F - F_free)(u + tau v) dtau, split at the events; returns the pieces.
        The gaps are affine along the step: with none negative at either end it adds nothing,
        with none changing sign the step is one piece."""
        up, vp = self.patch_values(u), self.patch_values(v)
        g0 = self.gaps(up)
        g1 = g0 + dt * (self._Rn @ vp)
        if min(g0.min(), g1.min()) >= 0:
            return 1
        if not (g0 * g1 < 0).any():
            self.add(self.force_correction(up + 0.5 * dt * vp), out, scale=dt)
            return 1
        tau = np.concatenate([[0.0], self.event_times(up, vp, dt), [dt]])
        total = np.zeros_like(up)
        for a, b in zip(tau[:-1], tau[1:]):
            total += (b - a) * self.force_correction(up + 0.5 * (a + b) * vp)
        self.add(total, out)
        return len(tau) - 1

    # -- outputs -------------------------------------------------------------------------------
    def facet_displacements(self, up: np.ndarray) -> np.ndarray:
        """Reconstructed (contact-aware) displacements of the candidate facets, (n_facets, d)."""
        free = (self._R_free @ up + self._D_free).reshape(-1, self.d)
        return free - np.minimum(self.gaps(up), 0.0)[:, None] * self.directions

    def gradient_correction(self, up: np.ndarray) -> np.ndarray:
        """Change of the gradient (eq. (8)) of each candidate's cell, shape (n_facets, d, d)."""
        delta = -np.minimum(self.gaps(up), 0.0)[:, None] * self.directions
        return np.einsum("ni,nj->nij", delta, self._grad_weights)

    def contact_gap(self, up: np.ndarray) -> tuple[float, int]:
        """Smallest gap n . (x_f + u_f - p) over the candidates (m) with the contact-aware u_f."""
        uf = self.facet_displacements(up)
        gap = np.einsum("ni,ni->n", self.normals, self.dem.geometry.facet_centres[self.facets] + uf - self.points)
        k = int(np.argmin(gap))
        return float(gap[k]), k

    def contact_pressure(self, up: np.ndarray) -> float:
        """Area-weighted mean over the candidate facets of -n . sigma_c n of their cells (Pa,
        compression > 0), with the contact-aware gradients. Scheme A's free facets carry
        sigma_c n = 0, so this is exactly 0 out of contact in 1D; scheme B's are not."""
        G = (self._grad_rows @ up + self._grad_lift).reshape(-1, self.d, self.d) + self.gradient_correction(up)
        stress = self.dem.material.stress(G)
        area = self.dem.geometry.facet_areas[self.facets]
        snn = np.einsum("ni,nij,nj->n", self.normals, stress, self.normals)
        return float(-(area * snn).sum() / area.sum())

    # -- statics (ContactModel): thin wrappers over the patch operators --------------------------
    def reactions(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Normal contact force (N) on each candidate facet, y_f . (a + delta_a) for the facets
        of ``active`` (default g < 0), 0 elsewhere (see ``reaction_pressures``)."""
        active, _, a, delta = self._state(up, active)
        return np.where(active, self._YT @ (a - delta), 0.0)

    def gap_gradients(self, facets: np.ndarray) -> np.ndarray:
        """Rows r_f = dg_f/du of the candidates ``facets`` on the patch, (len(facets), n_patch)."""
        rows = self._Rn[np.asarray(facets, dtype=np.int64)]
        return rows.toarray() if scipy.sparse.issparse(rows) else np.array(rows)

    def add_hessian_correction(self, active: np.ndarray, H: PETSc.Mat) -> None:
        """H += ``hessian_correction(active)`` on the owned patch rows (global dof numbers);
        H must accept new nonzeros and is left unassembled."""
        C = self.hessian_correction(active).tocsr()
        C.eliminate_zeros()
        for i in np.flatnonzero(self._owned):
            lo, hi = C.indptr[i], C.indptr[i + 1]
            if hi > lo:
                H.setValues([int(self.patch[i])], self.patch[C.indices[lo:hi]].astype(PETSc.IntType),
                            C.data[lo:hi], addv=PETSc.InsertMode.ADD_VALUES)

    # -- checkpoint (ContactModel) -----------------------------------------------------------------
    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """Only a counter: every candidate is tested at every evaluation, nothing else persists."""
        return {"evaluations": np.array([self.evaluations], dtype=np.int64)}

    def restore_state(self, state: Mapping[str, np.ndarray]) -> None:
        self.evaluations = int(state["evaluations"][0])
