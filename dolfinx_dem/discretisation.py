"""The DEM space discretisation on a DOLFINx mesh: set up once, then forces and energies in PETSc.

``DEMDiscretisation`` is the object at the API edge (paper §3): it computes the geometry, the
reconstruction and the energy rows Q = [S; J] of its owned cells and facets once (the only
operator of the mesh's size it keeps), with vectors in the layout of the DG0 ``Function.vector``,
and then offers

- ``force(u, t, out)``: F = -dV/du (eq. (15)-(17)) plus the body force;
- ``energies(u, t)``: elastic (11), stabilisation (13) and external potential, summed over ranks;
- ``stress(u, t)``, ``von_mises(u, t)``: cellwise stress of eq. (9) for the owned cells;
- ``mass``: the lumped mass rho |c| of each owned dof;
- ``factored``: K = Q^T Q applied in one pass over Q, for time stepping (factored.py);
- ``stable_time_step()``: from a guaranteed bound on lambda_max(M^-1 K) (stability.py).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem

from dolfinx_dem import _compat, stability
from dolfinx_dem.factored import FactoredStiffness
from dolfinx_dem.geometry import compute_geometry
from dolfinx_dem.halo import owned_facet_marks
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.operators import EnergyRows, compute_energy_rows
from dolfinx_dem.reconstruction import Reconstruction, compute_reconstruction


@dataclasses.dataclass(frozen=True)
class DirichletBC:
    """u_f = value on the given process-local boundary facets.

    ``value`` is a constant vector of length d, or a callable ``value(x, t)`` with x of shape
    (d, n) (facet barycentres) returning shape (d, n). Pass ``time_dependent=True`` when the
    callable depends on t; otherwise it is evaluated once.
    """

    facets: np.ndarray
    value: Sequence[float] | Callable
    time_dependent: bool = False


def _petsc_matrix(comm, rows: scipy.sparse.spmatrix, columns: np.ndarray, local_cols: int):
    """A distributed PETSc AIJ matrix from this process's ``rows``, whose local column j is the
    global column ``columns[j]``; ``local_cols`` is the size of the owned column block."""
    sub = rows.tocsr()
    # copies: sorting must not permute the data of ``rows``, which stays in use
    sub = scipy.sparse.csr_matrix((sub.data.copy(), columns[sub.indices], sub.indptr.copy()),
                                  shape=(sub.shape[0], int(columns.max(initial=-1)) + 1))
    sub.sort_indices()
    M = PETSc.Mat().createAIJ(
        size=((sub.shape[0], PETSc.DECIDE), (local_cols, PETSc.DECIDE)),
        csr=(sub.indptr.astype(PETSc.IntType), sub.indices.astype(PETSc.IntType), sub.data),
        comm=comm,
    )
    M.assemble()
    return M


def _sort_rows_globally(Q: scipy.sparse.csr_matrix, columns: np.ndarray) -> None:
    """Orders the entries of each row of Q by global column ``columns[j]`` (in place): every
    process then sums a row's products in the same order, as one process does."""
    order = np.argsort(columns, kind="stable").astype(np.int32)  # local column of each global rank
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order), dtype=np.int32)
    Q.indices[:] = rank[Q.indices]
    Q.has_sorted_indices = False
    Q.sort_indices()
    Q.indices[:] = order[Q.indices]


class DEMDiscretisation:
    """Cell-centred DEM for linear elasticity on a DOLFINx simplex mesh (1D, 2D, 3D).

    Parameters
    ----------
    mesh : DOLFINx mesh; ghost mode ``shared_facet`` or ``none``.
    material : ElasticMaterial.
    scheme : "A" or "B", the Neumann boundary reconstruction (§3.4).
    dirichlet : DirichletBC conditions; all other boundary facets are traction-free.
    body_force : force per unit volume (N/m^d), a vector of length d, e.g. rho * g.
    """

    def __init__(
        self,
        mesh,
        material: ElasticMaterial,
        scheme: str = "A",
        dirichlet: Sequence[DirichletBC] = (),
        body_force: Sequence[float] | None = None,
    ):
        self.mesh = mesh
        self.comm = mesh.comm
        self.material = material
        self.d = d = mesh.topology.dim
        self.V = _compat.create_vector_space(mesh, "DG", 0)
        dirichlet = tuple(dirichlet)
        facets = [np.asarray(bc.facets, dtype=np.int32) for bc in dirichlet]
        marks = {"dirichlet": owned_facet_marks(
            mesh, np.concatenate(facets) if facets else np.empty(0, np.int32),
            np.repeat(np.arange(len(facets)), [len(f) for f in facets]), "Dirichlet conditions")}
        self.geometry, facet_marks = compute_geometry(self.comm, mesh, self.V, marks)
        geom = self.geometry
        self.n_owned = geom.num_owned

        # Dirichlet facets held here, and the condition of each (owned cells' marks decide).
        mark = facet_marks["dirichlet"]
        marked = mark >= 0
        dirichlet_facets, first = np.unique(geom.cell_facets[marked], return_index=True)
        condition = mark[marked][first]
        selected = np.bincount(mark[: self.n_owned][marked[: self.n_owned]], minlength=len(dirichlet))
        selected = self.comm.allreduce(selected, op=MPI.SUM)
        if np.any(selected == 0):
            raise ValueError(f"Dirichlet condition {int(np.argmin(selected))} selects no facet "
                             "(check its tag or marker)")
        self._dirichlet = [(dirichlet_facets[condition == k], bc) for k, bc in enumerate(dirichlet)]
        self.reconstruction: Reconstruction = compute_reconstruction(
            geom, material, dirichlet_facets, scheme, geom.facets_of_layers(1), self.comm)

        # The jump row of an interior facet belongs to the owner of its cell with the smaller
        # global number. This process builds the jump rows of every interior facet of its owned
        # cells: its own ones first (they enter Q), then the others (contact corrections need
        # every row that a facet of an owned cell touches, see ``rows``).
        interior = geom.interior_facets
        c = geom.facet_cells[interior]
        touches = (c < self.n_owned).any(axis=1)
        g = np.sort(geom.cell_global[c], axis=1)  # the global numbers of the facet's two cells
        first_cell = np.where(geom.cell_global[c[:, 0]] < geom.cell_global[c[:, 1]], c[:, 0], c[:, 1])
        owned_jumps = first_cell < self.n_owned
        # in the order of their cells' global numbers, which does not depend on the partition
        order = np.lexsort((g[:, 1], g[:, 0]))
        order = np.concatenate([order[owned_jumps[order]], order[touches[order] & ~owned_jumps[order]]])
        mine, jump_facets = interior[owned_jumps], interior[order]
        self._jump_cells_global = g[order[: len(mine)]]  # (own jump rows' facets, 2), row keys
        rec = self.reconstruction
        #: owned cells whose Neumann facets use scheme B under scheme A (reconstruction.py)
        self.multi_neumann_cells = rec.multi_neumann_cells[rec.multi_neumann_cells < self.n_owned]
        self.num_multi_neumann_cells = self.comm.allreduce(len(self.multi_neumann_cells), op=MPI.SUM)
        #: extrapolated interior facets (reconstruction.py), counted once: by the owner of their jump row
        self.num_extrapolated_facets = self.comm.allreduce(
            int(np.isin(rec.stencils.extrapolated, mine).sum()), op=MPI.SUM)

        # The energy rows a = Q u + q this process holds: S rows of the owned cells, then J rows of
        # the interior facets of the owned cells; the first ``len(mine)`` J rows are its own. Its
        # own rows, a prefix of rows.Q, are its part of Q: the force is -Q^T (Q w + q) + f (see
        # ``force``), applied in one pass over them (``factored``). Q is stored once, with the
        # held dofs as columns (``columns`` maps them to global dofs); a PETSc copy is made only
        # on demand (``assemble_Q``).
        self.columns = (geom.cell_global[:, None] * d + np.arange(d)).ravel()  # local dof -> global dof
        self.rows: EnergyRows = compute_energy_rows(geom, material, rec, self.n_owned, jump_facets, len(mine))
        _sort_rows_globally(self.rows.Q, self.columns)
        self._n_elastic_rows = self.n_owned * d * (d + 1) // 2  # local rows of Q that belong to S
        self._n_own_rows = int(self.rows.owned.sum())
        self._Q_dirichlet = self.rows.Q_dirichlet[: self._n_own_rows]
        self.factored = FactoredStiffness(self.comm, self.rows.Q, self._n_own_rows, self._n_elastic_rows,
                                          self.n_owned * d, self.columns[self.n_owned * d:])
        self._K = None
        self._stable_dt = {}

        volumes = geom.cell_volumes[: self.n_owned]
        self.mass = self.create_vector()
        self.mass.array[:] = np.repeat(material.rho * volumes, d)
        self.inverse_mass = self.create_vector()
        self.inverse_mass.array[:] = 1.0 / self.mass.array
        self.body_force = self.create_vector()
        if body_force is not None:
            f = np.asarray(body_force, dtype=float)
            if f.shape != (d,):
                raise ValueError(f"body_force must have {d} components, got {f.shape}")
            self.body_force.array[:] = (volumes[:, None] * f).ravel()

        self._rhs = self.create_vector()  # f - Q^T q(t)
        self._held = self.factored.create_vector()  # u at the held dofs (``gradient``)
        self._work = self.create_vector()
        self._lift_time = None
        self._time_dependent = any(bc.time_dependent for _, bc in self._dirichlet)
        self._update_dirichlet(0.0)
        self.contact = None  # contact.RigidContact, see set_obstacles
        self.pair_contact = None  # pair_contact.PairContact, see set_contact_boundary
        self._setup_free_bodies()

    def _setup_free_bodies(self):
        """Bodies (connected components) without Dirichlet facets move freely, and K annihilates
        their translations only up to rounding of order eps |K| |u|, which would spoil the energy
        balance of a fast-moving body. The elastic operators are therefore applied to u minus each
        free body's mean (mass-weighted) translation: the same result in exact arithmetic, with
        rounding relative to the deformation instead of the displacement."""
        geom, d = self.geometry, self.d
        labels = geom.cell_bodies
        n_bodies = geom.num_bodies
        rec = self.reconstruction
        clamped = np.zeros(n_bodies, dtype=np.int64)
        clamped[labels[geom.facet_cells[rec.dirichlet_facets, 0]]] = 1
        self.comm.Allreduce(MPI.IN_PLACE, clamped, op=MPI.MAX)
        clamped = clamped > 0
        self.body_labels = labels
        owned = labels[: self.n_owned]
        self._free = free = ~clamped
        body_mass = np.bincount(owned, weights=self.material.rho * geom.cell_volumes[: self.n_owned], minlength=n_bodies)
        self.comm.Allreduce(MPI.IN_PLACE, body_mass, op=MPI.SUM)
        # Mean translations of the free bodies, (n_free, d) = mean_operator @ u.reshape(-1, d)
        # summed over ranks; row n_free of ``_means`` stays 0 for the cells of clamped bodies.
        n_free = int(free.sum())
        index = np.where(free, np.cumsum(free) - 1, n_free)  # body -> its row in _means
        self._body_of_cell = index[owned].astype(np.int32)
        self._free_body_mass = body_mass[free]
        cells = np.flatnonzero(free[owned])
        weights = self.material.rho * geom.cell_volumes[cells] / body_mass[owned[cells]]
        mean_operator = scipy.sparse.csr_matrix((weights, (index[owned[cells]], cells)), shape=(n_free, self.n_owned))
        # one free body (a bar, a disc): a dense row, as a sparse product costs ~8 us of overhead
        self._mean_operator = mean_operator.toarray() if n_free == 1 else mean_operator
        self._means = np.zeros((n_free + 1, d))
        self._shifted = self.create_vector()

    @property
    def free_bodies(self) -> tuple[np.ndarray, np.ndarray]:
        """The bodies without Dirichlet facets (see ``_setup_free_bodies``): for each owned cell
        the number of its free body, n_free for the cells of clamped bodies, (n_owned,) int32;
        and the mass of each free body (kg, kg/m in 2D), (n_free,)."""
        return self._body_of_cell, self._free_body_mass

    def relative_displacement(self, u: PETSc.Vec, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """u minus the mean translation of each free body (see ``_setup_free_bodies``), written
        into ``out`` (default: a vector of the discretisation's own); u itself if no body is free."""
        n_free = self._mean_operator.shape[0]
        if n_free == 0:
            return u
        ua = u.array_r.reshape(-1, self.d)
        means = self._mean_operator @ ua
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, means, op=MPI.SUM)
        self._means[:n_free] = means
        out = self._shifted if out is None else out
        np.subtract(ua, self._means[self._body_of_cell], out=out.array.reshape(-1, self.d))
        return out

    def set_obstacles(self, obstacles) -> None:
        """Frictionless contact with rigid half-spaces (``contact.HalfSpace``), see contact.py."""
        from dolfinx_dem.contact import RigidContact

        self.contact = RigidContact(self, obstacles) if obstacles else None

    def set_contact_boundary(self, facets, self_contact: bool = False, tolerance: float = 0.0) -> None:
        """Frictionless contact between the bodies of the mesh on the given (process-local)
        boundary facets (``pair_contact.PairContact``, paper §3.4.3): the rule of eq. (31) for
        scheme B facets, of eq. (23)-(24) for pairs of scheme A facets."""
        from dolfinx_dem.pair_contact import PairContact

        self.pair_contact = PairContact(self, facets, self_contact=self_contact, tolerance=tolerance)

    @property
    def contacts(self) -> tuple:
        """The contact models in use: rigid obstacles and contact between bodies."""
        return tuple(c for c in (self.contact, self.pair_contact) if c is not None)

    def row_keys(self) -> np.ndarray:
        """A number for each own row of Q, increasing along them, that orders the rows of all
        processes independently of the partition: the elastic rows by cell, then the jump rows
        by the global numbers of their facet's two cells (then by component)."""
        d, m = self.d, self.d * (self.d + 1) // 2
        n_global = self.geometry.num_cells_global
        S = (self.geometry.cell_global[: self.n_owned, None] * m + np.arange(m)).ravel()
        g = self._jump_cells_global.astype(np.int64)
        J = 2**62 + ((g[:, 0] * n_global + g[:, 1])[:, None] * d + np.arange(d)).ravel()
        return np.concatenate([S, J]).astype(np.int64)

    def ghost_owners(self) -> np.ndarray:
        """The rank owning each ghost dof of ``factored`` (the held dofs of other processes)."""
        return np.repeat(self.geometry.cell_owner[self.n_owned:], self.d)

    def assemble_Q(self) -> PETSc.Mat:
        """A PETSc copy of Q = [S; J] (rows: this process's own rows; columns: the dofs), for
        PETSc products and studies; the caller destroys it. Forces and energies do not need it:
        they apply Q in one pass over ``rows`` (``factored``)."""
        return _petsc_matrix(self.comm, self.rows.Q[: self._n_own_rows], self.columns, self.n_owned * self.d)

    @property
    def K(self) -> PETSc.Mat:
        """The stiffness K = Q^T Q = S^T S + J^T J (PETSc, rows of the owned dofs), built on first
        use by a PETSc product: time stepping applies Q^T Q in factored form and never needs it."""
        if self._K is None:
            Q = self.assemble_Q()
            self._K = Q.transposeMatMult(Q)
            Q.destroy()
        return self._K

    # -- vectors -----------------------------------------------------------------------------
    def create_vector(self) -> PETSc.Vec:
        """A PETSc vector with the layout of the owned DG0 dofs (cell-major, d per cell)."""
        v = PETSc.Vec().createMPI((self.n_owned * self.d, PETSc.DECIDE), comm=self.comm)
        v.set(0.0)
        return v

    def dirichlet_values(self, t: float) -> np.ndarray:
        """g(t) of shape (n_D, d), in the order of ``reconstruction.dirichlet_facets``."""
        rec, d = self.reconstruction, self.d
        g = np.zeros((len(rec.dirichlet_facets), d))
        for facets, bc in self._dirichlet:
            index = np.searchsorted(rec.dirichlet_facets, facets)
            if callable(bc.value):
                x = self.geometry.facet_centres[facets].T
                g[index] = np.asarray(bc.value(x, t), dtype=float).reshape(d, -1).T
            else:
                value = np.asarray(bc.value, dtype=float)
                if value.shape != (d,):
                    raise ValueError(f"a constant Dirichlet value needs {d} components, got {value.shape}")
                g[index] = value
        if not np.isfinite(g).all():
            k = int(np.argmax(~np.isfinite(g).all(axis=1)))
            raise ValueError(f"the Dirichlet value at t = {t:.9g} is not finite: {g[k].tolist()} on the facet at "
                             f"{self.geometry.facet_centres[rec.dirichlet_facets[k]].tolist()}")
        return g

    def _update_dirichlet(self, t: float):
        if self._lift_time is not None and (not self._time_dependent or self._lift_time == t):
            return
        g = self.dirichlet_values(t).ravel()
        self._g = g
        self._q = self._Q_dirichlet @ g  # (local rows of Q,)
        self.factored.residual(None, self._q, self._rhs)
        self._rhs.aypx(-1.0, self.body_force)
        self._lift_time = t

    @property
    def time_dependent(self) -> bool:
        """Whether some Dirichlet data depend on time (then the lift q(t) and ``load`` do)."""
        return self._time_dependent

    def load(self, t: float) -> PETSc.Vec:
        """f - Q^T q(t): the force at u = 0 without contact (body force and Dirichlet lift), the
        owned dofs. The returned vector is the discretisation's own: read it before the next call
        with another t. A time-dependent lift costs a Q^T product per new t."""
        self._update_dirichlet(t)
        return self._rhs

    def lift(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q(t) = [s(t); j(t)], the Dirichlet part of the energy rows Q w + q(t), on the local rows
        that Dirichlet values reach: (local row indices (int32), values); q is zero elsewhere."""
        self._update_dirichlet(t)
        if not hasattr(self, "_lift_rows"):
            self._lift_rows = np.flatnonzero(np.diff(self._Q_dirichlet.indptr)).astype(np.int32)
        return self._lift_rows, self._q[self._lift_rows]

    # -- forces and energies -----------------------------------------------------------------
    def force(self, u: PETSc.Vec, t: float, out: PETSc.Vec, contact: bool = True) -> PETSc.Vec:
        """out = -Q^T (Q w + q(t)) + f = -(S^T (S w + s(t)) + J^T (J w + j(t))) + f, plus the
        contact correction unless ``contact=False``: the exact negative gradient of the potential
        of ``energies``.

        The force is applied in factored form rather than as -K w: in floating point Q^T Q w and
        K w differ by the rounding of K, of relative size eps (omega_max / omega_1)^2 for smooth
        fields, which showed as pseudo-energy drifts of 8e-12 (1D bar, 800 cells) and 8e-13
        (cantilever) against 2e-14 and 5e-15 in factored form. One pass over the local rows of Q
        (``factored``); a MEMM step does not call this: it keeps the rows from step to step.
        """
        self._update_dirichlet(t)
        self.factored.residual(self.relative_displacement(u), self._q, out)
        out.aypx(-1.0, self.body_force)
        if contact:
            for c in self.contacts:
                c.add_force(u, out)
        return out

    def energies(self, u: PETSc.Vec, t: float) -> dict[str, float]:
        """Elastic (eq. (11)), stabilisation (eq. (13)) and external potential -f.u, global sums,
        and ``potential``, their total: the potential whose exact gradient ``force`` computes."""
        self._update_dirichlet(t)
        squares = self.factored.residual(self.relative_displacement(u), self._q, self._work)
        local = np.array([0.5 * squares[0], 0.5 * squares[1], self.body_force.array_r @ u.array_r])
        for c in self.contacts:  # this process's part of the contact energy changes
            local[:2] += c.energy_correction(c.patch_values(u))
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        e = {"elastic": local[0], "stabilisation": local[1], "external": -local[2]}
        e["potential"] = e["elastic"] + e["stabilisation"] + e["external"]
        return e

    def gradient(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell gradients G_c of eq. (8) for the owned cells, shape (n_owned, d, d), formed from
        the facet reconstructions u_F = R u + D g (outputs: no gradient operator is stored)."""
        self._update_dirichlet(t)
        d, geom, rec = self.d, self.geometry, self.reconstruction
        held = self.factored.local_array(self._held)
        held[: self.n_owned * d] = u.array_r
        self._held.ghostUpdate(PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        uF = (rec.R @ held + rec.D @ self._g).reshape(-1, d)
        cells = slice(0, self.n_owned)
        a = geom.facet_area_normals[cells] / geom.cell_volumes[cells, None, None]  # (n, d+1, d)
        G = np.einsum("nki,nkj->nij", uF[geom.cell_facets[cells]], a)
        for c in self.contacts:
            cells, change = c.gradient_correction(c.patch_values(u))
            np.add.at(G, cells, change)
        return G

    def stress(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell stresses sigma_c of eq. (9), shape (n_owned, d, d) (in-plane part in 2D)."""
        return self.material.stress(self.gradient(u, t))

    def von_mises(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Von Mises stress of the owned cells (Pa); the out-of-plane stress of plane strain counts."""
        G = self.gradient(u, t)
        sigma = self.material.stress(G)
        d = self.d
        if d == 1:
            return np.abs(sigma[:, 0, 0])
        s = np.zeros((self.n_owned, 3, 3))
        s[:, :d, :d] = sigma
        if d == 2 and self.material.plane == "strain":
            lmbda, _ = self.material.lame(2)
            s[:, 2, 2] = lmbda * (G[:, 0, 0] + G[:, 1, 1])
        dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
        return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))

    def eigenvalues(self, n: int = 1, largest: bool = False, rtol: float = 1e-10) -> np.ndarray:
        """The n largest or smallest eigenvalues omega^2 of M^-1 K (rad^2/s^2), ascending.

        SLEPc on the symmetric M^-1/2 K M^-1/2 (M is diagonal); the smallest by shift-and-invert
        around 0 with a direct LU solve (MUMPS where PETSc has it).
        """
        from slepc4py import SLEPc

        A = self.K.copy()
        scale = self.inverse_mass.copy()
        scale.sqrtabs()
        A.diagonalScale(scale, scale)
        eps = SLEPc.EPS().create(self.comm)
        eps.setOperators(A)
        eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
        eps.setDimensions(n, max(2 * n + 1, 32))
        eps.setTolerances(rtol, 20000)
        if largest:
            eps.setWhichEigenpairs(SLEPc.EPS.Which.LARGEST_REAL)
        else:
            eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
            eps.setTarget(0.0)
            st = eps.getST()
            st.setType(SLEPc.ST.Type.SINVERT)
            ksp = st.getKSP()
            ksp.setType(PETSc.KSP.Type.PREONLY)
            ksp.getPC().setType(PETSc.PC.Type.LU)
            if PETSc.Sys.hasExternalPackage("mumps"):
                ksp.getPC().setFactorSolverType("mumps")
        eps.solve()
        if eps.getConverged() < n:
            raise RuntimeError(f"SLEPc converged only {eps.getConverged()} of {n} eigenvalues of M^-1 K")
        values = np.array([eps.getEigenvalue(i).real for i in range(eps.getConverged())])
        eps.destroy()
        A.destroy()
        return np.sort(values)[-n:] if largest else np.sort(values)[:n]

    def stable_time_step(self, method: str = "bound") -> float:
        """The linear stability limit of MEMM (leapfrog), dt_max = 2 / sqrt(lambda_max(M^-1 K)) (s),
        of the elastic operator without contact; computed once per method.

        method "bound": lambda_max replaced by a guaranteed upper bound (stability.py), so the
        step is at most the limit (0.85-1 times it on the built-in scenes) and costs a few
        passes over Q (seconds at 1e6 cells). "eigenvalue": SLEPc's lambda_max to rtol 1e-8, the
        limit itself, for stability studies (minutes at 1e5 cells: its time grows about
        quadratically with the cells).
        """
        if method not in ("bound", "eigenvalue"):
            raise ValueError(f"unknown stable time step method {method!r}; choose 'bound' or 'eigenvalue'")
        if method not in self._stable_dt:
            if method == "bound":
                lam = stability.largest_eigenvalue_bound(self.factored, self.row_keys(), self.ghost_owners(),
                                                         self.inverse_mass)
            else:
                lam = self.eigenvalues(1, largest=True, rtol=1e-8)[0]
            self._stable_dt[method] = 2.0 / np.sqrt(lam)
        return self._stable_dt[method]

    def halo_exchange(self, owned: np.ndarray) -> np.ndarray:
        """Per-cell values of the owned cells, (n_owned, k), extended to the held cells (n_cells, k)
        by their owners' values (a ghost update of a PETSc vector with block size k). Integer
        values come back exact (they travel as float64). Collective."""
        owned = np.asarray(owned)
        k = owned.shape[1]
        geom = self.geometry
        vec = PETSc.Vec().createGhost(np.asarray(geom.cell_global[self.n_owned:], dtype=PETSc.IntType),
                                      size=(self.n_owned * k, PETSc.DECIDE), bsize=k, comm=self.comm)
        with vec.localForm() as local:
            local.array[: self.n_owned * k] = owned.ravel()
        vec.ghostUpdate(PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        with vec.localForm() as local:
            out = local.array.reshape(-1, k).astype(owned.dtype)
        vec.destroy()
        return out

    # -- DOLFINx functions -------------------------------------------------------------------
    def scalar_function(self, values: np.ndarray, name: str) -> dolfinx.fem.Function:
        """A DG0 scalar Function from per-cell ``values`` (n_owned,) in dolfinx_dem's cell order."""
        if not hasattr(self, "_Q"):
            self._Q = _compat.create_scalar_space(self.mesh, "DG", 0)
            n = self.mesh.topology.index_map(self.d).size_local
            block = _compat.cell_dofs(self.V)[:n]  # dolfinx_dem's local cell order
            self._q_of_block = np.empty(n, dtype=np.int32)
            self._q_of_block[block] = _compat.cell_dofs(self._Q)[:n]
        f = dolfinx.fem.Function(self._Q, name=name)
        f.x.array[self._q_of_block] = values
        f.x.scatter_forward()
        return f

    def function(self, values: PETSc.Vec | None = None, name: str = "u") -> dolfinx.fem.Function:
        """A DG0 vector Function holding ``values`` (owned dofs), ghosts updated."""
        f = dolfinx.fem.Function(self.V, name=name)
        if values is not None:
            _compat.petsc_vec(f).array_w[: self.n_owned * self.d] = values.array_r
            f.x.scatter_forward()
        return f
