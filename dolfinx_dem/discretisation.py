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
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem

from dolfinx_dem import _compat, halo, stability
from dolfinx_dem.factored import FactoredStiffness
from dolfinx_dem.geometry import compute_geometry
from dolfinx_dem.halo import owned_facet_marks
from dolfinx_dem.material import CellMaterials, ElasticMaterial
from dolfinx_dem.operators import EnergyRows, compute_energy_rows
from dolfinx_dem.reconstruction import Reconstruction, compute_reconstruction
from dolfinx_dem.errors import InputError, SolverError


@dataclasses.dataclass(frozen=True)
class DirichletBC:
    """u_f = value on the given process-local boundary facets, in the components ``components``
    (default: all d; a roller or a symmetry plane fixes some). The free components of the facets
    carry no traction (scheme A solves (sigma_c n_f)_i = 0 for them, reconstruction.py).

    ``value`` is a constant vector of length d, or a callable ``value(x, t)`` with x of shape
    (d, n) (facet barycentres) returning shape (d, n); its free components are ignored. Pass
    ``time_dependent=True`` when the callable depends on t; otherwise it is evaluated once.
    ``name`` names the condition's reaction (``DEMDiscretisation.reactions``) in outputs.
    """

    facets: np.ndarray
    value: Sequence[float] | Callable
    time_dependent: bool = False
    components: Sequence[int] | None = None
    name: str | None = None


@dataclasses.dataclass(frozen=True)
class Traction:
    """A surface traction t (force per unit area, Pa; per unit length in 2D) on the given
    process-local boundary facets, which must carry no Dirichlet condition. ``value`` as for
    ``DirichletBC``: a constant vector of length d or a callable ``value(x, t)``."""

    facets: np.ndarray
    value: Sequence[float] | Callable
    time_dependent: bool = False


@dataclasses.dataclass(frozen=True)
class PrescribedBody:
    """A body whose motion is imposed, a rigid translation U(t) (m): the cells of cell tag ``tag``,
    which must form whole bodies (``DEMDiscretisation``). Exactly one of ``velocity``, a constant
    vector of length d (U(t) = velocity t), and ``displacement``, a callable ``displacement(t)``
    returning d numbers (U(t) itself). ``name`` names its reaction and displacement columns in
    outputs (default: its number after the Dirichlet conditions, model.prescribed_columns). It
    acts as an indenter, a punch or a moving wall in contact between bodies (pair_contact.py);
    MEMM counts the work it does (memm.py)."""

    tag: int
    velocity: Sequence[float] | None = None
    displacement: Callable[[float], Sequence[float]] | None = None
    name: str | None = None

    def translation(self, t: float, d: int) -> np.ndarray:
        """U(t), shape (d,)."""
        if self.displacement is None:
            return t * np.asarray(self.velocity, dtype=float)
        U = np.asarray(self.displacement(t), dtype=float).reshape(-1)
        if U.shape != (d,) or not np.isfinite(U).all():
            raise InputError(f"prescribed body {self.tag}: displacement({t:.9g}) must be {d} finite numbers, "
                             f"got {U.tolist()}")
        return U


def _facet_values(what: str, conditions, facet_order: np.ndarray, centres: np.ndarray, d: int, t: float):
    """The values at time t of ``conditions`` (pairs (facets, condition with ``value`` and
    ``time_dependent``)) at their facets, (len(facet_order), d) in the order of ``facet_order``;
    a condition that is not time dependent is evaluated at t = 0."""
    values = np.zeros((len(facet_order), d))
    for facets, bc in conditions:
        index = np.searchsorted(facet_order, facets)
        if callable(bc.value):
            values[index] = np.asarray(bc.value(centres[facets].T, t if bc.time_dependent else 0.0), dtype=float).reshape(d, -1).T
        else:
            value = np.asarray(bc.value, dtype=float)
            if value.shape != (d,):
                raise InputError(f"a constant {what} value needs {d} components, got {value.shape}")
            values[index] = value
    if not np.isfinite(values).all():
        k = int(np.argmax(~np.isfinite(values).all(axis=1)))
        raise InputError(f"the {what} value at t = {t:.9g} is not finite: {values[k].tolist()} on the facet at "
                         f"{centres[facet_order[k]].tolist()}")
    return values


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


class DEMDiscretisation:
    """Cell-centred DEM for linear elasticity on a DOLFINx simplex mesh (1D, 2D, 3D).

    Parameters
    ----------
    mesh : DOLFINx mesh; ghost mode ``shared_facet`` or ``none``.
    material : ElasticMaterial, or several materials ``{cell tag: ElasticMaterial}``, which then
        need ``cell_tags``: every cell must carry exactly one of the tags (``materials``).
    scheme : "A" or "B", the Neumann boundary reconstruction (§3.4).
    dirichlet : DirichletBC conditions.
    tractions : Traction conditions; all other boundary facets are traction-free.
    body_force : force per unit volume (N/m^d), a vector of length d, e.g. rho * g.
    cell_tags : DOLFINx MeshTags of the cells, with ``material`` given per tag or ``prescribed``.
    prescribed : PrescribedBody bodies (2D), whose translation is imposed: their dofs have mass 0
        (no kinetic energy, inverse mass 0 in MEMM's update), see ``_setup_prescribed``.

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
    ):
        self.mesh = mesh
        self.comm = mesh.comm
        self.d = d = mesh.topology.dim
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
        facets = [np.asarray(bc.facets, dtype=np.int32) for bc in conditions]
        marks = {"conditions": owned_facet_marks(
            mesh, np.concatenate(facets) if facets else np.empty(0, np.int32),
            np.repeat(np.arange(len(facets)), [len(f) for f in facets]),
            "boundary conditions (Dirichlet conditions or tractions)")}
        # several materials: one more halo layer, as an interface facet of a layer-1 cell reads the
        # reconstructions of the facets of its layer-2 cell (reconstruction.py)
        layers = halo.HALO_LAYERS + (not isinstance(material, ElasticMaterial))
        self.geometry, facet_marks = compute_geometry(self.comm, mesh, self.V, marks, layers)
        geom = self.geometry
        self.n_owned = geom.num_owned
        #: the material of each held cell
        self.materials = self._cell_materials(material, cell_tags, bool(prescribed))
        materials = self.materials

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
        self._dirichlet = [(marked_facets[condition == k], bc) for k, bc in enumerate(dirichlet)]
        self._tractions = [(marked_facets[condition == len(dirichlet) + k], bc) for k, bc in enumerate(tractions)]
        is_dirichlet = condition < len(dirichlet)
        dirichlet_facets = marked_facets[is_dirichlet]
        fixed = np.zeros((len(dirichlet_facets), d), bool)
        for k, bc in enumerate(dirichlet):
            fixed[np.ix_(condition[is_dirichlet] == k, range(d) if bc.components is None else list(bc.components))] = True
        self.reconstruction: Reconstruction = compute_reconstruction(
            geom, materials, dirichlet_facets, scheme, geom.facets_of_layers(1), self.comm, fixed,
            marked_facets[~is_dirichlet])

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
        self._jump_cells = c[order[: len(mine)]]  # (own jump rows' facets, 2) int32 local cells: row keys
        rec = self.reconstruction
        #: owned cells whose Neumann facets use scheme B under scheme A (reconstruction.py)
        self.multi_neumann_cells = rec.multi_neumann_cells[rec.multi_neumann_cells < self.n_owned]
        self.num_multi_neumann_cells = self.comm.allreduce(len(self.multi_neumann_cells), op=MPI.SUM)
        #: extrapolated interior facets (reconstruction.py), counted once: by the owner of their jump row
        self.num_extrapolated_facets = self.comm.allreduce(
            int(np.isin(rec.extrapolated_facets, mine).sum()), op=MPI.SUM)
        n_own_jumps = len(mine)
        del mark, marked, facet_marks, interior, c, touches, g, first_cell, owned_jumps, order, mine  # before Q

        # The energy rows a = Q u + q this process holds: S rows of the owned cells, then J rows of
        # the interior facets of the owned cells; the first ``n_own_jumps`` J rows are its own. Its
        # own rows, a prefix of rows.Q, are its part of Q: the force is -Q^T (Q w + q) + f (see
        # ``force``), applied in one pass over them (``factored``). Q is stored once, with the
        # held dofs as columns (``columns`` maps them to global dofs); a PETSc copy is made only
        # on demand (``assemble_Q``).
        self.rows: EnergyRows = compute_energy_rows(geom, materials, rec, self.n_owned, jump_facets, n_own_jumps)
        _sort_rows_globally(self.rows.Q, self.columns)
        self._n_elastic_rows = self.n_owned * d * (d + 1) // 2  # local rows of Q that belong to S
        self._n_own_rows = self.rows.num_owned
        Q_dirichlet = self.rows.Q_dirichlet[: self._n_own_rows]
        Q_traction = (self.rows.QF[: self._n_own_rows] @ rec.N).tocsc()  # the traction lift's rows
        # the own rows that the data reach (a boundary layer), and their rows of Q_D and Q_N only
        self._lift_rows = np.unique(np.concatenate([Q_dirichlet.indices, Q_traction.indices])).astype(np.int32)
        self._Q_dirichlet = Q_dirichlet[self._lift_rows].tocsr()
        self._Q_traction = Q_traction[self._lift_rows].tocsr()
        del Q_dirichlet, Q_traction
        self._q = np.zeros(len(self._lift_rows))  # q(t) on ``_lift_rows`` (zero on the other own rows)
        self._dirichlet_condition = condition[is_dirichlet]  # of each Dirichlet facet
        self.factored = FactoredStiffness(self.comm, self.rows.Q, self._n_own_rows, self._n_elastic_rows,
                                          self.n_owned * d, self.columns[self.n_owned * d:])
        self._setup_tractions()
        self._K = None
        self._stable_dt = {}

        volumes = geom.cell_volumes[: self.n_owned]
        self.mass = self.create_vector()
        self.mass.array[:] = np.repeat(materials.rho(slice(0, self.n_owned)) * volumes, d)
        self.inverse_mass = self.create_vector()
        self.inverse_mass.array[:] = 1.0 / self.mass.array
        self.body_force = self.create_vector()
        if body_force is not None:
            f = np.asarray(body_force, dtype=float)
            if f.shape != (d,):
                raise InputError(f"body_force must have {d} components, got {f.shape}")
            self.body_force.array[:] = (volumes[:, None] * f).ravel()

        self.external_force = self.create_vector()  # f(t): the body force and the tractions' (P^T t_w)
        self._rhs = self.create_vector()  # f(t) - Q^T q(t)
        self._held = None  # u at the held dofs (``gradient``, ``reactions``), made on first use
        self._work = None  # a work vector of ``energies`` and ``prescribed_values``, made on first use
        self._lift_time = None
        self._time_dependent = any(bc.time_dependent for _, bc in self._dirichlet + self._tractions)
        self._update_data(0.0)
        self.contact = None  # contact.RigidContact, see set_obstacles
        self.pair_contact = None  # pair_contact.PairContact, see set_contact_boundary
        self._setup_prescribed(tuple(prescribed), cell_tags)
        self._setup_free_bodies()

    def _cell_materials(self, material, cell_tags, prescribed: bool) -> CellMaterials:
        """The ``CellMaterials`` of the held cells: one material, or one per cell tag (the owned
        cells' tags, extended to the halo by ``halo_exchange``). Every cell needs exactly one tag
        of ``material`` and every tag a cell; errors are raised on every process."""
        if isinstance(material, ElasticMaterial):
            if cell_tags is not None and not prescribed:
                raise InputError("cell_tags are only used with several materials ({cell tag: ElasticMaterial}) "
                                 "or prescribed bodies")
            return CellMaterials.uniform(material, self.geometry.num_cells)
        if cell_tags is None:
            raise InputError("several materials ({cell tag: ElasticMaterial}) need cell_tags")
        tags = [int(t) for t in material]
        n = self.n_owned
        count = np.zeros(n, dtype=np.int64)  # tags of each owned cell (dolfinx_dem's cell order)
        index = np.full(n, -1, dtype=np.int64)
        selected = np.zeros(len(tags), dtype=np.int64)
        for k, tag in enumerate(tags):
            cells = self._tagged_cells(cell_tags, tag)
            count[cells] += 1
            index[cells] = k
            selected[k] = len(cells)
        selected = self.comm.allreduce(selected, op=MPI.SUM)
        counts = np.array([(count > 1).sum(), (count == 0).sum()])
        counts = self.comm.allreduce(counts, op=MPI.SUM)
        if np.any(selected == 0):
            raise InputError(f"the material of cell tag {tags[int(np.argmin(selected))]} selects no cell")
        if counts[0]:
            raise InputError(f"{counts[0]} cells carry several material tags (materials overlap); tags {tags}")
        if counts[1]:
            raise InputError(f"{counts[1]} cells carry none of the material tags {tags}: give every cell a material")
        held = self.halo_exchange(index[:, None])[:, 0]
        return CellMaterials(tuple(material[t] for t in material), held.astype(np.int32))

    def _setup_tractions(self):
        """The work of the tractions on the facets of the owned cells (each boundary facet counted
        once, by its cell's owner), W = sum_f |f| t_f . u_f with u_f = R_f u + D_f g + N_f t:
        W = t_w . (P u) + t_w . (D_T g + N_T t), t_w = |f| t_f, so that the force it adds is P^T t_w
        (assembled on the held dofs, summed on the owners) and the rest is a constant of u."""
        rec, geom, d = self.reconstruction, self.geometry, self.d
        own = rec.traction_facets[geom.facet_cells[rec.traction_facets, 0] < self.n_owned]
        self._own_tractions = np.searchsorted(rec.traction_facets, own)
        self._traction_weights = np.repeat(geom.facet_areas[own], d)  # |f| per own traction dof
        dofs = (own[:, None] * d + np.arange(d)).ravel()
        self._P_traction = rec.R[dofs].T  # (held dofs, own traction dofs); CSC: no pointer per held dof
        self._DN_traction = (rec.D[dofs], rec.N[dofs])
        self._traction_force = self.factored.create_vector() if len(self._tractions) else None

    def _tagged_cells(self, cell_tags, tag: int) -> np.ndarray:
        """The owned cells (dolfinx_dem's numbering) that carry cell tag ``tag``."""
        block = _compat.cell_dofs(self.V)[: self.mesh.topology.index_map(self.d).size_local]
        cells = cell_tags.indices[cell_tags.values == tag]
        return np.sort(block[cells[cells < len(block)]])

    def _setup_prescribed(self, prescribed: tuple[PrescribedBody, ...], cell_tags):
        """The bodies of imposed translation: their owned cells, and mass and inverse mass 0 on
        their dofs, so that MEMM's update leaves their velocity as set (memm.py) and the kinetic
        energy and momenta leave them out. A rigid translation gives their own energy rows zero
        energy; their dofs also drop out of the stable step bound (M^-1 = 0: they do not
        vibrate). Errors, raised on every process: no cell tags, a tag that selects no cell or
        not whole bodies (a cell of the same body without the tag, or a vertex shared with
        another body), a body selected twice, a Dirichlet condition or a traction on the body,
        not exactly one of velocity and displacement, a velocity of the wrong length (and 3D,
        checked first, in ``__init__``)."""
        self.prescribed = prescribed
        self._prescribed_cells = []
        self._prescribed_dofs = np.empty(0, dtype=np.int64)
        if not prescribed:
            return
        d, geom = self.d, self.geometry
        if cell_tags is None:
            raise InputError("prescribed bodies are selected by cell tag: cell_tags are needed")
        owned_bodies = geom.cell_bodies[: self.n_owned]
        mine = np.zeros(geom.num_bodies, dtype=np.int64)  # bodies of prescribed cells (any body)
        for k, body in enumerate(prescribed):
            what = f"prescribed body {k if body.name is None else body.name!r} (cell tag {body.tag})"
            if (body.velocity is None) == (body.displacement is None):
                raise InputError(f"{what} needs exactly one of velocity and displacement")
            if body.velocity is not None and np.shape(body.velocity) != (d,):
                raise InputError(f"{what}: velocity must have {d} components, got {list(np.ravel(body.velocity))}")
            cells = self._tagged_cells(cell_tags, body.tag)
            if self.comm.allreduce(len(cells), op=MPI.SUM) == 0:
                raise InputError(f"{what} selects no cell")
            bodies = np.zeros(geom.num_bodies, dtype=np.int64)
            bodies[owned_bodies[cells]] = 1
            self.comm.Allreduce(MPI.IN_PLACE, bodies, op=MPI.MAX)
            untagged = np.isin(owned_bodies, np.flatnonzero(bodies))
            untagged[cells] = False
            if self.comm.allreduce(int(untagged.sum()), op=MPI.SUM):
                raise InputError(f"{what} is not a whole body: it shares facets with cells without the tag "
                                 "(a prescribed body must be meshed separately)")
            if mine[bodies > 0].any():
                raise InputError(f"{what} overlaps another prescribed body")
            mine += bodies
            self._prescribed_cells.append(cells)
        rec = self.reconstruction
        for what, facets in (("a Dirichlet condition", rec.dirichlet_facets), ("a traction", rec.traction_facets)):
            cells = geom.facet_cells[facets, 0]
            if self.comm.allreduce(bool(mine[geom.cell_bodies[cells[cells < self.n_owned]]].any()), op=MPI.LOR):
                raise InputError(f"a prescribed body carries {what}: its motion is imposed already")
        from dolfinx_dem.pair_contact import _check_bodies_share_no_vertex
        try:
            _check_bodies_share_no_vertex(self, np.flatnonzero(mine))
        except ValueError as err:
            raise InputError(f"a prescribed body is not a whole body: {err}") from None
        self._prescribed_bodies = mine > 0
        dofs = (np.concatenate(self._prescribed_cells)[:, None] * d + np.arange(d)).ravel()
        self.mass.array[dofs] = 0.0
        self.inverse_mass.array[dofs] = 0.0
        self._prescribed_dofs = dofs

    def impose(self, u: PETSc.Vec, v: PETSc.Vec, t: float, dt: float, position: bool = True) -> None:
        """On the prescribed bodies' dofs: u = U(t) if ``position``, and v = the constant velocity,
        or (U(t + dt) - u)/dt for a displacement: the velocity v^{n+1/2} of MEMM's step from
        u^n = u at t_n to U(t + dt) (the flight is affine within the step, and u follows U(t)
        without accumulating rounding)."""
        d = self.d
        if position:
            self.hold(u, t)
        for body, cells in zip(self.prescribed, self._prescribed_cells):
            v.array.reshape(-1, d)[cells] = body.velocity if body.velocity is not None else \
                (body.translation(t + dt, d) - u.array_r.reshape(-1, d)[cells]) / dt

    def hold(self, u: PETSc.Vec, t: float) -> None:
        """u = U(t) on the prescribed bodies' dofs (the other dofs untouched)."""
        for body, cells in zip(self.prescribed, self._prescribed_cells):
            u.array.reshape(-1, self.d)[cells] = body.translation(t, self.d)

    @property
    def moving_prescribed(self) -> bool:
        """Whether some prescribed body follows a displacement U(t) (MEMM sets its velocity each step)."""
        return any(body.displacement is not None for body in self.prescribed)

    def prescribed_values(self, u: PETSc.Vec, t: float, force: PETSc.Vec | None = None) -> np.ndarray:
        """For each prescribed body, its reaction, the force it exerts on the other bodies,
        -(sum of the force on its dofs) = dV/dU, the exact derivative of the potential with
        respect to its translation U, and its translation (its cells' mean u): (n, 2, d), global.
        ``force``: the force vector to sum instead of ``force(u, t)`` (statics: the Lagrangian's,
        whose multipliers carry the pairs held on a contact switch). Collective (a force evaluation)."""
        d = self.d
        f = self.force(u, t, self._work_vector()) if force is None else force
        out = np.zeros((len(self.prescribed), 2, d))
        counts = np.zeros(len(self.prescribed))
        for k, cells in enumerate(self._prescribed_cells):
            out[k, 0] = -f.array_r.reshape(-1, d)[cells].sum(axis=0)
            out[k, 1] = u.array_r.reshape(-1, d)[cells].sum(axis=0)
            counts[k] = len(cells)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        out[:, 1] /= self.comm.allreduce(counts, op=MPI.SUM)[:, None]
        return out

    @property
    def prescribed_dofs(self) -> np.ndarray:
        """The owned dofs of the prescribed bodies (empty without)."""
        return self._prescribed_dofs

    @property
    def prescribed_cells(self) -> np.ndarray | None:
        """Whether each owned cell belongs to a prescribed body, (n_owned,) booleans; None without."""
        if not self.prescribed:
            return None
        return np.isin(self.body_labels[: self.n_owned], self.prescribed_body_numbers)

    @property
    def prescribed_body_numbers(self) -> np.ndarray:
        """The numbers of the prescribed bodies (``body_labels``; empty without)."""
        return np.flatnonzero(self._prescribed_bodies) if self.prescribed else np.empty(0, dtype=np.int64)

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
        if self.prescribed:  # a prescribed body translates exactly: no mean to remove
            clamped[self._prescribed_bodies] = 1
        clamped = clamped > 0
        self.body_labels = labels
        owned = labels[: self.n_owned]
        self._free = free = ~clamped
        body_mass = np.bincount(owned, weights=self.mass.array_r[::d], minlength=n_bodies)
        self.comm.Allreduce(MPI.IN_PLACE, body_mass, op=MPI.SUM)
        # Mean translations of the free bodies, (n_free, d) = mean_operator @ u.reshape(-1, d)
        # summed over ranks; row n_free of ``_means`` stays 0 for the cells of clamped bodies.
        n_free = int(free.sum())
        index = np.where(free, np.cumsum(free) - 1, n_free)  # body -> its row in _means
        self._body_of_cell = index[owned].astype(np.int32)
        self._free_body_mass = body_mass[free]
        cells = np.flatnonzero(free[owned])
        weights = self.mass.array_r[::d][cells] / body_mass[owned[cells]]
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

    def set_contact_boundary(self, facets, self_contact: bool = False, tolerance: float = 0.0,
                             skin: float | None = None) -> None:
        """Frictionless contact between the bodies of the mesh on the given (process-local)
        boundary facets (``pair_contact.PairContact``, paper §3.4.3): the rule of eq. (31) for
        scheme B facets, of eq. (23)-(24) for pairs of scheme A facets."""
        from dolfinx_dem.pair_contact import PairContact

        self.pair_contact = PairContact(self, facets, self_contact=self_contact, tolerance=tolerance, skin=skin)

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
        g = np.sort(self.geometry.cell_global[self._jump_cells], axis=1)  # global numbers, smaller first
        J = 2**62 + ((g[:, 0] * n_global + g[:, 1])[:, None] * d + np.arange(d)).ravel()
        return np.concatenate([S, J]).astype(np.int64)

    def ghost_owners(self) -> np.ndarray:
        """The rank owning each ghost dof of ``factored`` (the held dofs of other processes)."""
        return np.repeat(self.geometry.cell_owner[self.n_owned:], self.d)

    @property
    def columns(self) -> np.ndarray:
        """The global dof of each local dof (the held cells' dofs, owned first), the columns of
        ``rows.Q`` (made on each call: 16 bytes per cell not held)."""
        return (self.geometry.cell_global[:, None] * self.d + np.arange(self.d)).ravel()

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

    def row_lift(self, rows: np.ndarray) -> np.ndarray:
        """The data's part q of the energy rows ``rows`` (indices into ``rows.Q``: any row this
        process holds), Q_D g + Q_N t at the data's current time (contact models: constant data)."""
        rows = np.asarray(rows)
        return self.rows.Q_dirichlet[rows] @ self._g + (self.rows.QF[rows] @ self.reconstruction.N) @ self._t

    def facet_lift(self, facets: np.ndarray) -> np.ndarray:
        """The data's part D g + N t of the reconstructions of the local ``facets``, (n, d), at
        the data's current time (contact models: constant data)."""
        rec, d = self.reconstruction, self.d
        dofs = (np.asarray(facets)[:, None] * d + np.arange(d)).ravel()
        return (rec.D[dofs] @ self._g + rec.N[dofs] @ self._t).reshape(-1, d)

    def dirichlet_values(self, t: float) -> np.ndarray:
        """g(t) of shape (n_D, d), in the order of ``reconstruction.dirichlet_facets`` (the free
        components of a partly fixed facet are read by nothing)."""
        return _facet_values("Dirichlet", self._dirichlet, self.reconstruction.dirichlet_facets,
                             self.geometry.facet_centres, self.d, t)

    def traction_values(self, t: float) -> np.ndarray:
        """t(t) of shape (n_T, d), in the order of ``reconstruction.traction_facets``."""
        return _facet_values("traction", self._tractions, self.reconstruction.traction_facets,
                             self.geometry.facet_centres, self.d, t)

    def _update_data(self, t: float):
        """The boundary data at t: the lift q(t) = Q_D g(t) + Q_N t(t) of the energy rows, the
        external force f(t) = f_body + P^T t_w (``_setup_tractions``), the load f(t) - Q^T q(t)
        and this process's share of the tractions' work at u = 0."""
        if self._lift_time is not None and (not self._time_dependent or self._lift_time == t):
            return
        g, tr = self.dirichlet_values(t).ravel(), self.traction_values(t).ravel()
        self._g, self._t = g, tr
        self._q = self._Q_dirichlet @ g + self._Q_traction @ tr  # a new array: ``lift`` hands it out
        self.body_force.copy(self.external_force)
        self._traction_constant = 0.0
        if self._traction_force is not None:
            tw = self._traction_weights * tr.reshape(-1, self.d)[self._own_tractions].ravel()
            D, N = self._DN_traction
            self._traction_constant = float(tw @ (D @ g + N @ tr))
            self.factored.local_array(self._traction_force)[:] = self._P_traction @ tw
            self._traction_force.ghostUpdate(PETSc.InsertMode.ADD_VALUES, PETSc.ScatterMode.REVERSE)
            self.external_force.array[:] += self._traction_force.array_r
        self.factored.residual(None, (self._lift_rows, self._q), self._rhs)
        self._rhs.aypx(-1.0, self.external_force)
        self._lift_time = t

    def external_potential(self, u: PETSc.Vec, t: float) -> float:
        """This process's share of the external potential -f(t) . u - sum_f |f| t_f . (D g + N t)_f
        (owned dofs, own traction facets; sum it over ranks)."""
        self._update_data(t)
        return -(self.external_force.array_r @ u.array_r + self._traction_constant)

    def data_potential(self, u: PETSc.Vec, t: float) -> float:
        """This process's share of the part of V(u, t) that the data change, V - 1/2 |Q w|^2 =
        -u . L(t) + 1/2 |q(t)|^2 - sum_f |f| t_f . (D g + N t)_f, L = ``load(t)``: with it MEMM
        counts the work that time-dependent data do (memm.py)."""
        self._update_data(t)
        return -(self._rhs.array_r @ u.array_r) + 0.5 * (self._q @ self._q) - self._traction_constant

    def external_constant(self, t: float) -> float:
        """This process's share of the tractions' work at u = 0, sum_f |f| t_f . (D g + N t)_f: the
        part of the external potential that ``external_force`` does not carry."""
        self._update_data(t)
        return self._traction_constant

    @property
    def dirichlet_conditions(self) -> tuple[DirichletBC, ...]:
        """The Dirichlet conditions, in the order of ``reactions``."""
        return tuple(bc for _, bc in self._dirichlet)

    @property
    def time_dependent(self) -> bool:
        """Whether some Dirichlet or traction data depend on time (then q(t), f(t) and ``load`` do)."""
        return self._time_dependent

    def load(self, t: float) -> PETSc.Vec:
        """f(t) - Q^T q(t): the force at u = 0 without contact (body force, tractions and the lift),
        the owned dofs. The returned vector is the discretisation's own: read it before the next call
        with another t. A time-dependent lift costs a Q^T product per new t."""
        self._update_data(t)
        return self._rhs

    def lift(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q(t) = [s(t); j(t)], the boundary data's part of the energy rows Q w + q(t), on the local
        rows that Dirichlet values or traction lifts reach: (local row indices (int32), values); q
        is zero elsewhere."""
        self._update_data(t)
        return self._lift_rows, self._q

    # -- forces and energies -----------------------------------------------------------------
    def force(self, u: PETSc.Vec, t: float, out: PETSc.Vec, contact: bool = True) -> PETSc.Vec:
        """out = -Q^T (Q w + q(t)) + f(t) = -(S^T (S w + s(t)) + J^T (J w + j(t))) + f(t), plus the
        contact correction unless ``contact=False``: the exact negative gradient of the potential
        of ``energies``.

        The force is applied in factored form rather than as -K w: in floating point Q^T Q w and
        K w differ by the rounding of K, of relative size eps (omega_max / omega_1)^2 for smooth
        fields, which showed as pseudo-energy drifts of 8e-12 (1D bar, 800 cells) and 8e-13
        (cantilever) against 2e-14 and 5e-15 in factored form. One pass over the local rows of Q
        (``factored``); a MEMM step does not call this: it keeps the rows from step to step.
        """
        self._update_data(t)
        self.factored.residual(self.relative_displacement(u), (self._lift_rows, self._q), out)
        out.aypx(-1.0, self.external_force)
        if contact:
            for c in self.contacts:
                c.add_force(u, out)
        return out

    def energies(self, u: PETSc.Vec, t: float) -> dict[str, float]:
        """Elastic (eq. (11)), stabilisation (eq. (13)) and external potential -f.u - sum_f |f| t_f.u_f,
        global sums, and ``potential``, their total: the potential whose exact gradient ``force``
        computes."""
        self._update_data(t)
        squares = self.factored.residual(self.relative_displacement(u), (self._lift_rows, self._q), self._work_vector())
        local = np.array([0.5 * squares[0], 0.5 * squares[1], -self.external_potential(u, t)])
        for c in self.contacts:  # this process's part of the contact energy changes
            local[:2] += c.energy_correction(c.patch_values(u))
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        e = {"elastic": local[0], "stabilisation": local[1], "external": -local[2]}
        e["potential"] = e["elastic"] + e["stabilisation"] + e["external"]
        return e

    def gradient(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell gradients G_c of eq. (8) for the owned cells, shape (n_owned, d, d), formed from
        the facet reconstructions u_F = R u + D g + N t (outputs: no gradient operator is stored)."""
        self._update_data(t)
        d, geom, rec = self.d, self.geometry, self.reconstruction
        held = self._held_values(u)
        uF = (rec.R @ held + rec.D @ self._g + rec.N @ self._t).reshape(-1, d)
        cells = slice(0, self.n_owned)
        a = geom.facet_area_normals[cells] / geom.cell_volumes[cells, None, None]  # (n, d+1, d)
        G = np.einsum("nki,nkj->nij", uF[geom.cell_facets[cells]], a)
        for c in self.contacts:
            cells, change = c.gradient_correction(c.patch_values(u))
            np.add.at(G, cells, change)
        return G

    def _work_vector(self) -> PETSc.Vec:
        """A work vector of the dof layout (``energies``, ``prescribed_values``), made on first use."""
        if self._work is None:
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

    def reactions(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """The force each Dirichlet condition exerts on the body, (n_conditions, d), global sums:
        the exact derivative dV/dg of the potential (class docstring) with respect to the
        condition's imposed values, summed over its facets,

            dV/dg = Q_D^T (Q w + q(t)) - D_T^T t_w     (t_w = |f| t_f on the own traction facets),

        from the own rows of Q (each row counted once), reduced over processes. A free component
        of a roller has no column in D: its reaction is 0. Contact corrections of rows near a
        Dirichlet facet are not included. At equilibrium the reactions balance the loads."""
        self._update_data(t)
        if not hasattr(self, "_reaction_rows"):
            fixed = np.diff(self._Q_dirichlet.indptr) > 0  # of the lift rows
            self._reaction_rows = fixed, self.rows.Q[self._lift_rows[fixed]], self._Q_dirichlet[fixed].T.tocsr()
        fixed, Q, QD_T = self._reaction_rows
        dVdg = QD_T @ (Q @ self._held_values(u) + self._q[fixed])
        if self._traction_force is not None:
            tw = self._traction_weights * self._t.reshape(-1, self.d)[self._own_tractions].ravel()
            dVdg -= self._DN_traction[0].T @ tw
        out = np.zeros((len(self._dirichlet), self.d))
        np.add.at(out, self._dirichlet_condition, dVdg.reshape(-1, self.d))
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out

    def stress(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell stresses sigma_c of eq. (9), shape (n_owned, d, d) (in-plane part in 2D)."""
        return self.materials.stress(self.gradient(u, t))

    def von_mises(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Von Mises stress of the owned cells (Pa); the out-of-plane stress of plane strain counts."""
        G = self.gradient(u, t)
        sigma = self.materials.stress(G)
        d = self.d
        if d == 1:
            return np.abs(sigma[:, 0, 0])
        s = np.zeros((self.n_owned, 3, 3))
        s[:, :d, :d] = sigma
        if d == 2 and self.materials.plane == "strain":
            lmbda = np.array([m.lame(2)[0] for m in self.materials.materials])[self.materials.index[: self.n_owned]]
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
            raise SolverError(f"SLEPc converged only {eps.getConverged()} of {n} eigenvalues of M^-1 K")
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
            raise InputError(f"unknown stable time step method {method!r}; choose 'bound' or 'eigenvalue'")
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
