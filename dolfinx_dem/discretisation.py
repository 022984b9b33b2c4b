"""The DEM space discretisation on a DOLFINx mesh: set up once, then forces and energies in PETSc.

``DEMDiscretisation`` (paper §3) computes the geometry, the reconstruction and the energy rows
Q = [S; J] of its owned cells and facets once (the only operator of the mesh's size it keeps),
with vectors in the layout of the DG0 ``Function.vector``, and then offers

- ``force(u, t, out)``: F = -dV/du (eq. (15)-(17)) plus the body force and the tractions;
- ``energies(u, t)``: elastic (11), stabilisation (13) and external potential, summed over ranks;
- ``gradient``, ``stress``, ``von_mises``: the cellwise gradient of eq. (8) and stress of eq. (9);
- ``mass``: the lumped mass rho |c| of each owned dof;
- ``factored``: K = Q^T Q applied in one pass over Q, for time stepping (factored.py);
- ``stable_time_step()``: from a guaranteed bound on lambda_max(M^-1 K) (stability.py).

It knows nothing of contact: ``problem.DEMProblem(dem, contacts)`` adds the contact models'
corrections to these (paper §3.4), and the contact models read the public members here. Its
parts: the boundary data (``data``, boundary_data.py), the prescribed bodies (``prescribed``,
prescribed.py) and the free bodies' mean translations (``bodies``, bodies.py).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import dolfinx.fem
import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, halo, stability
from dolfinx_dem import bodies as _bodies
from dolfinx_dem.boundary_data import BoundaryData
from dolfinx_dem.conditions import DirichletBC, PrescribedBody, Traction, facet_indices
from dolfinx_dem.errors import InputError
from dolfinx_dem.factored import FactoredStiffness
from dolfinx_dem.geometry import MeshGeometry, compute_geometry
from dolfinx_dem.halo import owned_facet_marks
from dolfinx_dem.material import ElasticMaterial, cell_materials
from dolfinx_dem.operators import EnergyRows, compute_energy_rows
from dolfinx_dem.prescribed import PrescribedMotion
from dolfinx_dem.reconstruction import Reconstruction, compute_reconstruction


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
    _renumber(Q.indices, rank)
    Q.has_sorted_indices = False
    Q.sort_indices()
    _renumber(Q.indices, order)


def _renumber(indices: np.ndarray, new: np.ndarray, block: int = 2**22) -> None:
    """indices[k] = new[indices[k]] in place, a block at a time (no temporary of the size of Q)."""
    for a in range(0, len(indices), block):
        indices[a : a + block] = new[indices[a : a + block]]


def _jump_facets(geom: MeshGeometry, n_owned: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The interior facets whose jump rows this process builds, and their order. The jump row
    of an interior facet belongs to the owner of its cell with the smaller global number. This
    process builds the jump rows of every interior facet of its owned cells: its own ones first
    (they enter Q), then the others (contact corrections need every row that a facet of an
    owned cell touches), in the order of their cells' global numbers, which does not depend on
    the partition. Returns (its own jump facets, all its jump facets in row order, the two local
    cells of each own jump row)."""
    interior = geom.interior_facets
    c = geom.facet_cells[interior]
    touches = (c < n_owned).any(axis=1)
    g = np.sort(geom.cell_global[c], axis=1)  # the global numbers of the facet's two cells
    first_cell = np.where(geom.cell_global[c[:, 0]] < geom.cell_global[c[:, 1]], c[:, 0], c[:, 1])
    owned_jumps = first_cell < n_owned
    order = np.lexsort((g[:, 1], g[:, 0]))
    order = np.concatenate([order[owned_jumps[order]], order[touches[order] & ~owned_jumps[order]]])
    mine = interior[owned_jumps]
    return mine, interior[order], c[order[: len(mine)]]


class DEMDiscretisation:
    """Cell-centred DEM for linear elasticity on a DOLFINx simplex mesh (1D, 2D, 3D).

    Parameters
    ----------
    mesh : DOLFINx mesh; ghost mode ``shared_facet`` or ``none``.
    material : ElasticMaterial, or several materials ``{cell tag: ElasticMaterial}``, which then
        need ``cell_tags``: every cell must carry exactly one of the tags.
    scheme : "A" or "B", the Neumann boundary reconstruction (§3.4).
    dirichlet : DirichletBC conditions.
    body_force : force per unit volume (N/m^d), a vector of length d, e.g. rho * g.
    tractions : Traction conditions; all other boundary facets are traction-free.
    cell_tags : DOLFINx MeshTags of the cells, with ``material`` given per tag or ``prescribed``.
    prescribed : PrescribedBody bodies (2D), whose translation is imposed (prescribed.py).
    scheme_b_facets : with scheme "A", boundary facets (indices or a MeshTags) reconstructed by
        scheme B instead, e.g. the contact candidates (method "dem-AB" of the scenes): the bulk of
        the body keeps scheme A's accuracy and the contact scheme B's simple rule (docs/theory.md).

    The potential is V(u, t) = E_P + E_S - f.u - sum_f |f| t_f . u_f (eq. (11), (13) and the
    work of the body force f and of the tractions on the reconstructed facet values u_f), and
    the force is its exact negative gradient.
    """

    def __init__(
        self,
        mesh,
        material: ElasticMaterial | Mapping[int, ElasticMaterial],
        scheme: str = "A",
        dirichlet: Sequence[DirichletBC] = (),
        body_force: Sequence[float] | None = None,
        tractions: Sequence[Traction] = (),
        cell_tags=None,
        prescribed: Sequence[PrescribedBody] = (),
        scheme_b_facets=None,
    ):
        self.mesh = mesh
        self.comm = mesh.comm
        self.d = d = mesh.topology.dim
        if scheme not in ("A", "B"):
            raise InputError(f"scheme must be 'A' or 'B', got {scheme!r}")
        if not (isinstance(material, ElasticMaterial) or isinstance(material, Mapping)):
            raise InputError(f"material must be an ElasticMaterial or {{cell tag: ElasticMaterial}}, got "
                             f"{type(material).__name__}")
        prescribed = tuple(prescribed)
        if prescribed and d != 2:
            raise InputError(f"prescribed bodies take part in contact between bodies, implemented in 2D, not {d}D")
        self.V = _compat.create_vector_space(mesh, "DG", 0)
        dirichlet, tractions = tuple(dirichlet), tuple(tractions)
        for k, bc in enumerate(dirichlet):
            components = range(d) if bc.components is None else bc.components
            if len(components) == 0 or any(not 0 <= int(i) < d for i in components):
                raise InputError(f"Dirichlet condition {k}: components must be a nonempty list of integers in "
                                 f"[0, {d - 1}], got {list(components)}")
        # Dirichlet conditions are marked 0..n_D-1, tractions n_D.. (one condition per facet)
        conditions = dirichlet + tractions
        facets = [facet_indices(bc.facets, bc.tag, f"Dirichlet condition {k}" if k < len(dirichlet) else
                                f"traction {k - len(dirichlet)}", d) for k, bc in enumerate(conditions)]
        marks = {"conditions": owned_facet_marks(
            mesh, np.concatenate(facets) if facets else np.empty(0, np.int32),
            np.repeat(np.arange(len(facets)), [len(f) for f in facets]),
            "boundary conditions (Dirichlet conditions or tractions)")}
        if scheme_b_facets is not None:
            if scheme != "A":
                raise InputError("scheme_b_facets selects scheme B facets under scheme 'A'; with scheme 'B' every "
                                 "Neumann facet is a scheme B facet already")
            b_facets = facet_indices(scheme_b_facets, None, "scheme_b_facets", d)
            marks["scheme_b"] = owned_facet_marks(mesh, b_facets, np.zeros(len(b_facets)), "scheme B facets")
        # several materials: one more halo layer, as an interface facet of a layer-1 cell reads the
        # reconstructions of the facets of its layer-2 cell (reconstruction.py)
        layers = halo.HALO_LAYERS + (not isinstance(material, ElasticMaterial))
        self.geometry, facet_marks = compute_geometry(self.comm, mesh, self.V, marks, layers)
        geom = self.geometry
        self.n_owned = geom.num_owned
        #: the material of each held cell
        self.materials = materials = cell_materials(self, material, cell_tags, bool(prescribed))

        # Facets held here and the condition of each (owned cells' marks decide).
        mark = facet_marks["conditions"]
        marked = mark >= 0
        marked_facets, first = np.unique(geom.cell_facets[marked], return_index=True)
        condition = mark[marked][first]
        selected = np.bincount(mark[: self.n_owned][marked[: self.n_owned]], minlength=len(conditions))
        selected = self.comm.allreduce(selected, op=MPI.SUM)
        if np.any(selected == 0):
            k = int(np.argmin(selected))
            what = f"Dirichlet condition {k}" if k < len(dirichlet) else f"traction {k - len(dirichlet)}"
            raise InputError(f"{what} selects no facet (check its tag or marker)")
        is_dirichlet = condition < len(dirichlet)
        dirichlet_facets = marked_facets[is_dirichlet]
        fixed = np.zeros((len(dirichlet_facets), d), bool)
        for k, bc in enumerate(dirichlet):
            components = range(d) if bc.components is None else list(bc.components)
            fixed[np.ix_(condition[is_dirichlet] == k, components)] = True
        b_facets = None if scheme_b_facets is None else np.unique(geom.cell_facets[facet_marks["scheme_b"] >= 0])
        #: the held facets reconstructed by scheme B under scheme A (None: none; fracture/ rebuilds with them)
        self.scheme_b_facets = b_facets
        self.reconstruction: Reconstruction = compute_reconstruction(
            geom, materials, dirichlet_facets, scheme, geom.facets_of_layers(1), self.comm, fixed,
            marked_facets[~is_dirichlet], b_facets)
        rec = self.reconstruction
        #: slender bodies too thin for their scheme B facets (``bodies.thin_scheme_b_bodies``), warned about
        self.thin_scheme_b_bodies = _bodies.thin_scheme_b_bodies(
            geom, self.comm, rec.neumann_facets if scheme == "B" else np.empty(0) if b_facets is None else b_facets)

        mine, jump_facets, self._jump_cells = _jump_facets(geom, self.n_owned)
        #: owned cells whose Neumann facets use scheme B under scheme A (reconstruction.py)
        self.multi_neumann_cells = rec.multi_neumann_cells[rec.multi_neumann_cells < self.n_owned]
        self.num_multi_neumann_cells = self.comm.allreduce(len(self.multi_neumann_cells), op=MPI.SUM)
        #: extrapolated interior facets (reconstruction.py), counted once: by the owner of their jump row
        self.num_extrapolated_facets = self.comm.allreduce(
            int(np.isin(rec.extrapolated_facets, mine).sum()), op=MPI.SUM)
        n_own_jumps = len(mine)
        del mark, marked, facet_marks, mine  # before Q

        # The energy rows a = Q u + q this process holds: S rows of the owned cells, then J rows of
        # the interior facets of the owned cells; the first ``n_own_jumps`` J rows are its own. Its
        # own rows, a prefix of rows.Q, are its part of Q: the force is -Q^T (Q w + q) + f (see
        # ``force``), applied in one pass over them (``factored``). Q is stored once, with the
        # held dofs as columns (``columns`` maps them to global dofs); a PETSc copy is made only
        # on demand (``assemble_Q``).
        self.rows: EnergyRows = compute_energy_rows(geom, materials, rec, self.n_owned, jump_facets, n_own_jumps)
        _sort_rows_globally(self.rows.Q, self.columns)
        self.factored = FactoredStiffness(self.comm, self.rows.Q, self.rows.num_owned, self.n_owned * d * (d + 1) // 2,
                                          self.n_owned * d, self.columns[self.n_owned * d:])
        self._K = None
        self._stable_dt = {}

        volumes = geom.cell_volumes[: self.n_owned]
        self.mass = self.create_vector()
        self.mass.array[:] = np.repeat(materials.rho(slice(0, self.n_owned)) * volumes, d)
        self.inverse_mass = self.create_vector()
        self.inverse_mass.array[:] = 1.0 / self.mass.array
        force = self.create_vector()
        if body_force is not None:
            f = np.asarray(body_force, dtype=float)
            if f.shape != (d,) or not np.isfinite(f).all():
                raise InputError(f"body_force must be {d} finite numbers, got {f.tolist()}")
            force.array[:] = (volumes[:, None] * f).ravel()
        #: the boundary data: Dirichlet values, tractions and the body force (boundary_data.py)
        self.data = BoundaryData(self, [(marked_facets[condition == k], bc) for k, bc in enumerate(dirichlet)],
                                 [(marked_facets[condition == len(dirichlet) + k], bc)
                                  for k, bc in enumerate(tractions)], condition[is_dirichlet], force)
        self._held = None  # u at the held dofs (``gradient``, ``reactions``), made on first use
        #: the bodies of imposed translation (prescribed.py): mass and inverse mass 0 on their dofs
        self.prescribed = PrescribedMotion(self, prescribed, cell_tags)
        self.mass.array[self.prescribed.dofs] = 0.0
        self.inverse_mass.array[self.prescribed.dofs] = 0.0
        #: the free bodies' mean translations (bodies.py); a prescribed body translates exactly
        self.bodies = self._free_bodies(self.prescribed.flags)

    def _free_bodies(self, prescribed: np.ndarray) -> _bodies.FreeBodies:
        """The bodies of ``geometry``; clamped: those with a Dirichlet facet, and the ``prescribed``
        ones (per body)."""
        geom = self.geometry
        clamped = np.zeros(geom.num_bodies, dtype=np.int64)
        clamped[geom.cell_bodies[geom.facet_cells[self.reconstruction.dirichlet_facets, 0]]] = 1
        self.comm.Allreduce(MPI.IN_PLACE, clamped, op=MPI.MAX)
        return _bodies.FreeBodies(self.comm, geom.cell_bodies, geom.num_bodies,
                                  (clamped > 0) | prescribed, self.n_owned, self.mass, self.d)

    def replace_operator(self, geometry: MeshGeometry, reconstruction: Reconstruction, rows: EnergyRows) -> None:
        """Install another operator on the same cells, with the row layout of the one it replaces
        (fracture/: the split geometry, reconstruction and energy rows of a crack set, design note
        ``docs/design/fracture.md`` §2-3): the rows are sorted globally and factored again, the
        boundary data's lifts, the free bodies and the cached stable steps are made again; the
        mass does not change. One process, no prescribed body (fracture refuses both)."""
        if self.comm.size > 1 or self.prescribed.flags.any():
            raise InputError("replace_operator: one process and no prescribed body (issue 34)")
        if rows.Q.shape != self.rows.Q.shape or rows.num_owned != self.rows.num_owned:
            raise InputError(f"replace_operator: rows of shape {rows.Q.shape}, not the layout {self.rows.Q.shape}")
        d = self.d
        self.geometry, self.reconstruction = geometry, reconstruction
        Q = rows.Q.copy()  # sorted here, the caller's rows stay as they are
        _sort_rows_globally(Q, self.columns)
        self.rows = EnergyRows(Q=Q, Q_dirichlet=rows.Q_dirichlet, QF=rows.QF, num_owned=rows.num_owned,
                               num_elastic=rows.num_elastic)
        self.factored = FactoredStiffness(self.comm, Q, rows.num_owned, self.n_owned * d * (d + 1) // 2,
                                          self.n_owned * d, self.columns[self.n_owned * d:])
        self._K, self._held, self._stable_dt = None, None, {}
        self.multi_neumann_cells = reconstruction.multi_neumann_cells
        self.num_multi_neumann_cells = len(self.multi_neumann_cells)
        self.num_extrapolated_facets = len(reconstruction.extrapolated_facets)
        self.data = self.data.rebuilt()
        self.bodies = self._free_bodies(np.zeros(geometry.num_bodies, dtype=bool))

    # -- forces and energies -----------------------------------------------------------------
    def force(self, u: PETSc.Vec, t: float, out: PETSc.Vec) -> PETSc.Vec:
        """out = -Q^T (Q w + q(t)) + f(t) = -(S^T (S w + s(t)) + J^T (J w + j(t))) + f(t), w = u
        minus the free bodies' mean translations: the exact negative gradient of the potential
        of ``energies``.

        The force is applied in factored form rather than as -K w: in floating point Q^T Q w and
        K w differ by the rounding of K, of relative size eps (omega_max / omega_1)^2 for smooth
        fields, which showed as pseudo-energy drifts orders of magnitude above those of the
        factored form (docs/bench). One pass over the local rows of Q (``factored``); a MEMM step
        does not call this: it keeps the rows from step to step.
        """
        lift = self.data.lift(t)
        self.factored.residual(self.bodies.relative_displacement(u), lift, out)
        out.aypx(-1.0, self.data.forcing(t))
        return out

    def local_energies(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """This process's parts of the elastic and stabilisation energies (its own rows) and of
        the external potential's negative, [E_P, E_S, -V_ext] (sum them over the processes)."""
        squares = self.factored.residual(self.bodies.relative_displacement(u), self.data.lift(t), self._work_vector())
        return np.array([0.5 * squares[0], 0.5 * squares[1], -self.data.external_potential(u, t)])

    def energies(self, u: PETSc.Vec, t: float) -> dict[str, float]:
        """Elastic (eq. (11)), stabilisation (eq. (13)) and external potential -f.u - sum_f |f| t_f.u_f,
        global sums, and ``potential``, their total: the potential whose exact gradient ``force``
        computes."""
        return energies_of(self.comm, self.local_energies(u, t))

    def gradient(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell gradients G_c of eq. (8) for the owned cells, shape (n_owned, d, d), formed from
        the facet reconstructions u_F = R u + D g + N t (outputs: no gradient operator is stored)."""
        self.data.lift(t)  # the data at t
        d, geom, rec = self.d, self.geometry, self.reconstruction
        held = self._held_values(u)
        g, tr = self.data.facet_data()
        uF = (rec.R @ held + rec.D @ g + rec.N @ tr).reshape(-1, d)
        cells = slice(0, self.n_owned)
        a = geom.facet_area_normals[cells] / geom.cell_volumes[cells, None, None]  # (n, d+1, d)
        return np.einsum("nki,nkj->nij", uF[geom.cell_facets[cells]], a)

    def stress(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell stresses sigma_c of eq. (9), shape (n_owned, d, d) (in-plane part in 2D)."""
        return self.materials.stress(self.gradient(u, t))

    def von_mises(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Von Mises stress of the owned cells (Pa); the out-of-plane stress of plane strain counts."""
        return self.materials.von_mises(self.gradient(u, t))

    def reactions(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """The force each Dirichlet condition exerts on the body, (n_conditions, d), global sums:
        the exact derivative dV/dg of the potential (class docstring) with respect to the
        condition's imposed values, summed over its facets (boundary_data.py). A free component
        of a roller has no column in D: its reaction is 0. Contact corrections of rows near a
        Dirichlet facet are not included. At equilibrium the reactions balance the loads."""
        return self.data.reactions(self._held_values(u), t)

    def _work_vector(self) -> PETSc.Vec:
        """A work vector of the dof layout (``local_energies``), made on first use."""
        if getattr(self, "_work", None) is None:
            self._work = self.create_vector()
        return self._work

    def _held_values(self, u: PETSc.Vec) -> np.ndarray:
        """u at the held dofs (owned, then ghosts), a view of ``_held``. Collective."""
        if self._held is None:
            self._held = self.factored.create_vector()
        held = self.factored.local_array(self._held)
        held[: self.n_owned * self.d] = u.array_r
        self._held.ghostUpdate(PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        return held

    # -- stability -----------------------------------------------------------------------------
    def stable_time_step(self, method: str = "bound") -> float:
        """The linear stability limit of MEMM (leapfrog), dt_max = 2 / sqrt(lambda_max(M^-1 K)) (s),
        of the elastic operator without contact; computed once per method.

        method "bound": lambda_max replaced by a guaranteed upper bound (stability.py), so the
        step is at most the limit and costs a few passes over Q. "eigenvalue": SLEPc's
        lambda_max to rtol 1e-8, the limit itself, for stability studies (its time grows about
        quadratically with the cells).
        """
        if method not in ("bound", "eigenvalue"):
            raise InputError(f"unknown stable time step method {method!r}; choose 'bound' or 'eigenvalue'")
        if method not in self._stable_dt:
            if method == "bound":
                lower, lam = stability.eigenvalue_bounds(self.factored, self._row_keys(),
                                                         np.repeat(self.geometry.cell_owner[self.n_owned:], self.d),
                                                         self.inverse_mass)
                self._stable_dt["unstable"] = 2.0 / np.sqrt(lower)
            else:
                lam = stability.eigenvalues(self.K, self.inverse_mass, 1, largest=True, rtol=1e-8)[0]
            self._stable_dt[method] = 2.0 / np.sqrt(lam)
        return self._stable_dt[method]

    def unstable_time_step(self) -> float:
        """A step beyond which MEMM is unstable whatever the modes (s): 2 / sqrt(max_i (M^-1 K)_ii),
        the diagonal being a lower bound on lambda_max (stability.eigenvalue_bounds). Collective."""
        self.stable_time_step("bound")
        return self._stable_dt["unstable"]

    def _row_keys(self) -> np.ndarray:
        """A number for each own row of Q, increasing along them, that orders the rows of all
        processes independently of the partition: the elastic rows by cell, then the jump rows
        by the global numbers of their facet's two cells (then by component)."""
        d, m = self.d, self.d * (self.d + 1) // 2
        n_global = self.geometry.num_cells_global
        S = (self.geometry.cell_global[: self.n_owned, None] * m + np.arange(m)).ravel()
        g = np.sort(self.geometry.cell_global[self._jump_cells], axis=1)  # global numbers, smaller first
        J = 2**62 + ((g[:, 0] * n_global + g[:, 1])[:, None] * d + np.arange(d)).ravel()
        return np.concatenate([S, J]).astype(np.int64)

    # -- parallel layout ------------------------------------------------------------------------
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

    @property
    def columns(self) -> np.ndarray:
        """The global dof of each local dof (the held cells' dofs, owned first), the columns of
        ``rows.Q`` (made on each call: 16 bytes per cell not held)."""
        return (self.geometry.cell_global[:, None] * self.d + np.arange(self.d)).ravel()

    def assemble_Q(self) -> PETSc.Mat:
        """A PETSc copy of Q = [S; J] (rows: this process's own rows; columns: the dofs), for
        PETSc products and studies; the caller destroys it. Forces and energies do not need it:
        they apply Q in one pass over ``rows`` (``factored``)."""
        return _petsc_matrix(self.comm, self.rows.Q[: self.rows.num_owned], self.columns, self.n_owned * self.d)

    @property
    def K(self) -> PETSc.Mat:
        """The stiffness K = Q^T Q = S^T S + J^T J (PETSc, rows of the owned dofs), built on first
        use by a PETSc product: time stepping applies Q^T Q in factored form and never needs it."""
        if self._K is None:
            Q = self.assemble_Q()
            self._K = Q.transposeMatMult(Q)
            Q.destroy()
        return self._K

    # -- vectors and DOLFINx functions ----------------------------------------------------------
    def create_vector(self) -> PETSc.Vec:
        """A PETSc vector with the layout of the owned DG0 dofs (cell-major, d per cell)."""
        v = PETSc.Vec().createMPI((self.n_owned * self.d, PETSc.DECIDE), comm=self.comm)
        v.set(0.0)
        return v

    def vector(self, values) -> PETSc.Vec:
        """A new vector of the dof layout (``create_vector``) holding ``values``: a PETSc vector of
        that layout, a DOLFINx Function of the mesh (interpolated into the DG0 space ``V``: the
        values at the cell barycentres for a continuous field), or an array of the owned
        values, (n_owned * d,) or (n_owned, d)."""
        out = self.create_vector()
        if isinstance(values, PETSc.Vec):
            if values.getSizes() != out.getSizes():
                raise InputError(f"the vector's sizes {values.getSizes()} are not those of the DEM dofs "
                                 f"{out.getSizes()} (use DEMDiscretisation.create_vector)")
            values.copy(out)
        elif isinstance(values, dolfinx.fem.Function):
            f = values
            if f.function_space.mesh is not self.mesh:
                raise InputError("the DOLFINx Function lives on another mesh than the discretisation's")
            if f.function_space is not self.V:
                f = dolfinx.fem.Function(self.V)
                f.interpolate(values)
            out.array[:] = _compat.petsc_vec(f).array_r[: self.n_owned * self.d]
        else:
            array = np.asarray(values, dtype=float)
            if array.size != self.n_owned * self.d:
                raise InputError(f"{array.size} values given for the {self.n_owned} owned cells x {self.d} components")
            out.array[:] = array.ravel()
        return out

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


def energies_of(comm: MPI.Comm, local: np.ndarray) -> dict[str, float]:
    """The energies of ``DEMDiscretisation.energies`` from this process's parts ``local`` =
    [E_P, E_S, -V_ext] (``local_energies``, plus any contact corrections), reduced over ``comm``."""
    if comm.size > 1:
        comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
    e = {"elastic": local[0], "stabilisation": local[1], "external": -local[2]}
    e["potential"] = e["elastic"] + e["stabilisation"] + e["external"]
    return e
