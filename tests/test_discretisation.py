"""DEMDiscretisation: forces are the exact gradient of the potential (eq. (15)-(17)); bad inputs."""

import dolfinx.mesh
import numpy as np
import pytest
from dolfinx.mesh import CellType, DiagonalType
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC, Traction
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial

MATERIAL = ElasticMaterial(E=2.0, nu=0.25, rho=1.5, eta=0.7)
#: two materials, tagged 3 (x < 0.6) and 8: different E, nu, rho and eta (the second's eta is E)
MATERIALS = {3: MATERIAL, 8: ElasticMaterial(E=9.0, nu=0.35, rho=0.4)}


def _material_tags(mesh):
    """Cell tags 3 (barycentre x < 0.6) and 8 (the others) of all process-local cells."""
    d = mesh.topology.dim
    cells = np.arange(mesh.topology.index_map(d).size_local + mesh.topology.index_map(d).num_ghosts, dtype=np.int32)
    x = dolfinx.mesh.compute_midpoints(mesh, d, cells)[:, 0]
    return dolfinx.mesh.meshtags(mesh, d, cells, np.where(x < 0.6, 3, 8).astype(np.int32))


def _problem(d, scheme, comm, time_dependent=False, loaded=False, shift=None, two=False):
    """A mesh with Dirichlet values on x = 0 (callable), a body force and free other sides
    (``two``: of the two ``MATERIALS``);
    ``loaded``: also a roller (u_y = 0) on the bottom and a traction (callable, time dependent
    with the Dirichlet values) on the right. ``shift`` (two vectors): the Dirichlet values of the
    two conditions move by t times them (time dependent), for derivatives in g."""
    if d == 2:
        mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [1.5, 1.0]], [4, 3], diagonal=DiagonalType.right)
    else:
        mesh = dolfinx.mesh.create_box(comm, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.5]], [2, 2, 2])
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    a, b = (np.zeros(d), np.zeros(d)) if shift is None else shift

    def g(x, t):
        value = np.stack([0.1 * np.sin(x[1] + t)] + [0.2 * x[0] + 0.3 * x[1] * (1 + t)] * (d - 1))
        return value if shift is None else np.stack([0.1 * np.sin(x[1])] + [0.2 * x[0] + 0.3 * x[1]] * (d - 1)) \
            + t * a[:, None]

    bc = DirichletBC(left, g, time_dependent=time_dependent or shift is not None)
    body = [0.5, -1.0, 0.25][:d]
    material = dict(material=MATERIALS, cell_tags=_material_tags(mesh)) if two else dict(material=MATERIAL)
    if not loaded:
        return DEMDiscretisation(mesh, scheme=scheme, dirichlet=[bc], body_force=body, **material)
    bottom = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[1], 0.0) & (x[0] > 1e-12))
    right = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 1.5 if d == 2 else 1.0))
    roller = DirichletBC(bottom, lambda x, t: np.stack([0.0 * x[0] + 0.05] * d) + t * b[:, None],
                         time_dependent=shift is not None, components=[1])

    def traction(x, t):
        return np.stack([0.7 + 0.2 * x[1] * (1 + t), 0.0 * x[0] - 0.3 + 0.1 * t] + [0.4 * x[1]] * (d - 2))

    tractions = [Traction(right, traction, time_dependent=time_dependent)]
    return DEMDiscretisation(mesh, scheme=scheme, dirichlet=[bc, roller], body_force=body, tractions=tractions,
                             **material)


def _potential(dem, u, t):
    e = dem.energies(u, t)
    return e["elastic"] + e["stabilisation"] + e["external"]


def _random_field(dem, seed):
    u = dem.create_vector()
    x = dem.geometry.cell_centres[: dem.n_owned]
    u.array[:] = (np.cos(np.arange(dem.d) + 3 * x) + 0.1 * np.random.default_rng(seed).normal(size=x.shape)).ravel()
    return u


@pytest.mark.parametrize("loaded, two", [(False, False), (True, False), (True, True)])
@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("d", [2, 3])
def test_force_is_minus_gradient_full(d, scheme, loaded, two):
    """Every component of F against central differences of E_P + E_S - f.u (- the tractions'
    work with ``loaded``, and a roller; ``two`` materials) (exact for a quadratic potential up to
    round-off)."""
    dem = _problem(d, scheme, MPI.COMM_SELF, loaded=loaded, two=two)
    if two:
        assert set(dem.materials.index) == {0, 1}
    if d == 2 and scheme == "A":
        assert dem.reconstruction.multi_neumann_cells.size > 0  # the fallback is covered too
    u = _random_field(dem, 0)
    F = dem.create_vector()
    dem.force(u, 0.0, F)
    h = 1e-4
    fd = np.empty(u.getSize())
    w = u.copy()
    for i in range(u.getSize()):
        w.array[:] = u.array
        w.array[i] += h
        plus = _potential(dem, w, 0.0)
        w.array[i] -= 2 * h
        minus = _potential(dem, w, 0.0)
        fd[i] = -(plus - minus) / (2 * h)
    assert np.abs(fd - F.array).max() < 1e-6 * np.abs(F.array).max()


@pytest.mark.mpi
@pytest.mark.parametrize("loaded, two", [(False, False), (True, False), (True, True)])
@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("d", [2, 3])
def test_force_is_minus_gradient_directional(d, scheme, loaded, two):
    """Directional derivatives along random directions, also in parallel, with time-dependent
    Dirichlet values (and tractions, with ``loaded``; ``two`` materials) evaluated at t = 0.7."""
    comm = MPI.COMM_WORLD
    dem = _problem(d, scheme, comm, time_dependent=True, loaded=loaded, two=two)
    t = 0.7
    u = _random_field(dem, comm.rank)
    F = dem.create_vector()
    dem.force(u, t, F)
    h = 1e-3
    w = dem.create_vector()
    rng = np.random.default_rng(100 + comm.rank)
    for _ in range(4):
        direction = dem.create_vector()
        direction.array[:] = rng.normal(size=direction.array.shape)
        u.copy(w)
        w.axpy(h, direction)
        plus = _potential(dem, w, t)
        w.axpy(-2 * h, direction)
        minus = _potential(dem, w, t)
        slope = (plus - minus) / (2 * h)
        assert abs(slope + F.dot(direction)) < 1e-6 * F.norm() * direction.norm()
    # The Dirichlet lifting really is time dependent: F(u, 0) != F(u, t).
    F0 = dem.create_vector()
    dem.force(u, 0.0, F0)
    F0.axpy(-1.0, F)
    assert F0.norm() > 1e-3 * F.norm()


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("d", [2, 3])
def test_reactions_are_the_derivative_in_the_imposed_values(d, scheme):
    """reactions() against the central difference of V(u, g + s a) in s, for a clamp and a roller
    moved along a and b (as t): dV/ds = R_clamp . a + R_roller . b; the free x component of the
    roller has no reaction."""
    comm = MPI.COMM_WORLD
    a, b = np.array([0.3, -0.7, 0.2][:d]), np.array([0.4, 0.9, -0.5][:d])
    dem = _problem(d, scheme, comm, loaded=True, shift=(a, b))
    u = _random_field(dem, comm.rank)
    R = dem.reactions(u, 0.0)
    assert R.shape == (2, d) and R[1, 0] == 0.0 and np.abs(R).max() > 1e-2
    h = 1e-3
    slope = (_potential(dem, u, h) - _potential(dem, u, -h)) / (2 * h)
    assert abs(slope - (R[0] @ a + R[1] @ b)) < 1e-9 * np.abs(R).max()


@pytest.mark.mpi
def test_mass_and_body_force():
    comm = MPI.COMM_WORLD
    dem = _problem(2, "A", comm)
    volume = comm.allreduce(dem.geometry.cell_volumes[: dem.n_owned].sum())
    assert volume == pytest.approx(1.5)
    assert dem.mass.sum() == pytest.approx(2 * MATERIAL.rho * 1.5, rel=1e-13)
    prod = dem.create_vector()
    prod.pointwiseMult(dem.mass, dem.inverse_mass)
    assert np.allclose(prod.array, 1.0, rtol=1e-15)
    # F(0) with g = 0 is the body force alone: sum over cells is |Omega| f.
    mesh = dolfinx.mesh.create_unit_square(comm, 3, 3)
    dem = DEMDiscretisation(mesh, MATERIAL, body_force=[0.5, -1.0])
    F = dem.create_vector()
    dem.force(dem.create_vector(), 0.0, F)
    total = comm.allreduce(F.array.reshape(-1, 2).sum(axis=0))
    assert np.allclose(total, [0.5, -1.0], rtol=1e-13)


# --- bad inputs ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(E=1.0, nu=0.5, rho=1.0), "Poisson"),
        (dict(E=1.0, nu=0.7, rho=1.0), "Poisson"),
        (dict(E=1.0, nu=-1.0, rho=1.0), "Poisson"),
        (dict(E=0.0, nu=0.3, rho=1.0), "Young"),
        (dict(E=-2.0, nu=0.3, rho=1.0), "Young"),
        (dict(E=1.0, nu=0.3, rho=0.0), "density"),
        (dict(E=1.0, nu=0.3, rho=-1.0), "density"),
        (dict(E=float("nan"), nu=0.3, rho=1.0), "finite"),
        (dict(E=1.0, nu=0.3, rho=1.0, plane="shell"), "plane"),
        (dict(E=1.0, nu=0.3, rho=1.0, eta=0.0), "eta"),
    ],
)
def test_bad_material(kwargs, word):
    with pytest.raises(ValueError, match=word):
        ElasticMaterial(**kwargs)


@pytest.fixture
def square():
    return dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 3, 3)


@pytest.mark.mpi
def test_bad_scheme(square):
    with pytest.raises(ValueError, match="'A' or 'B'"):
        DEMDiscretisation(square, MATERIAL, scheme="C")


@pytest.mark.mpi
def test_dirichlet_on_interior_facet(square):
    tdim = square.topology.dim
    square.topology.create_connectivity(tdim - 1, tdim)
    num = square.topology.index_map(tdim - 1).size_local
    interior = np.setdiff1d(np.arange(num, dtype=np.int32), meshes.exterior_facets(square))
    assert MPI.COMM_WORLD.allreduce(interior.size) > 0
    with pytest.raises(ValueError, match="interior"):
        DEMDiscretisation(square, MATERIAL, dirichlet=[DirichletBC(interior[:1], [0.0, 0.0])])


@pytest.mark.mpi
def test_dirichlet_selecting_nothing(square):
    nothing = meshes.locate_boundary_facets(square, lambda x: x[0] > 5.0)
    with pytest.raises(ValueError, match="no facet"):
        DEMDiscretisation(square, MATERIAL, dirichlet=[DirichletBC(nothing, [0.0, 0.0])])
    with pytest.raises(ValueError, match="no facet"):
        DEMDiscretisation(square, MATERIAL, dirichlet=[DirichletBC(np.empty(0, np.int32), [0.0, 0.0])])


@pytest.mark.mpi
def test_dirichlet_bad_value_and_overlap(square):
    left = meshes.locate_boundary_facets(square, lambda x: np.isclose(x[0], 0.0))
    with pytest.raises(ValueError, match="2 components"):
        DEMDiscretisation(square, MATERIAL, dirichlet=[DirichletBC(left, [0.0, 0.0, 0.0])])
    with pytest.raises(ValueError, match="share a facet"):
        DEMDiscretisation(square, MATERIAL, dirichlet=[DirichletBC(left, [0.0, 0.0])] * 2)


@pytest.mark.mpi
@pytest.mark.parametrize("force", [[1.0], [1.0, 2.0, 3.0], [[1.0, 2.0]]])
def test_body_force_wrong_length(square, force):
    with pytest.raises(ValueError, match="body_force"):
        DEMDiscretisation(square, MATERIAL, body_force=force)


@pytest.mark.mpi
@pytest.mark.parametrize("cell_type", [CellType.quadrilateral, CellType.hexahedron])
def test_non_simplex_mesh(cell_type):
    if cell_type == CellType.quadrilateral:
        mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 3, 3, cell_type=cell_type)
    else:
        mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2, cell_type=cell_type)
    with pytest.raises(ValueError, match="simplex"):
        DEMDiscretisation(mesh, MATERIAL)


def test_potential_is_the_sum_of_the_energies_up_to_rounding():
    """energies()["potential"] (the form the force derives from) equals elastic + stabilisation +
    external up to the rounding of K = S^T S + J^T J."""
    from dolfinx_dem import meshes

    mesh, _, tags = meshes.create_rectangle(MPI.COMM_WORLD, [0.0, 0.0], [1.0, 0.5], [8, 4], "crossed")
    dem = DEMDiscretisation(mesh, MATERIAL, "A", [DirichletBC(tags.find(1), [0.01, -0.02])], body_force=[0.0, -1.0])
    e = dem.energies(_random_field(dem, 5), 0.0)
    total = e["elastic"] + e["stabilisation"] + e["external"]
    assert e["potential"] == pytest.approx(total, rel=1e-11)


def _cell_keys(dem):
    return [tuple(np.round(x, 10)) for x in dem.geometry.cell_centres[: dem.n_owned]]


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("kind", ["square", "cube", "discs", "square-two", "cube-two"])
def test_operators_are_the_same_on_any_number_of_processes(kind, scheme):
    """The force -Q^T (Q u + q) + f, the energies and the cell stresses of a generic field, cell
    by cell (matched by barycentre), agree between this run's processes and one process to
    rounding: the distributed set-up (owned cells plus halo) builds the serial operators; with
    two materials (``-two``) too, so that the halo cells carry their materials."""
    from dolfinx_dem import meshes

    def make(comm):
        if kind.startswith("square"):
            mesh = dolfinx.mesh.create_unit_square(comm, 9, 7, diagonal=dolfinx.mesh.DiagonalType.crossed)
        elif kind.startswith("cube"):
            mesh = dolfinx.mesh.create_unit_cube(comm, 3, 4, 3)
        else:
            mesh = meshes.create_discs(comm, [((0.0, 0.0), 1.0), ((2.5, 0.0), 1.0)], 0.25)[0]
        left = meshes.locate_boundary_facets(mesh, lambda x: x[0] < -0.9 if kind == "discs" else np.isclose(x[0], 0.0))
        material = dict(material=MATERIALS, cell_tags=_material_tags(mesh)) if kind.endswith("two") else \
            dict(material=MATERIAL)
        return DEMDiscretisation(mesh, scheme=scheme, dirichlet=[DirichletBC(left, lambda x, t: 0.01 * x[::-1] ** 2)],
                                 body_force=[0.3] * mesh.topology.dim, **material)

    results = []
    for comm in (MPI.COMM_WORLD, MPI.COMM_SELF):
        dem = make(comm)
        x = dem.geometry.cell_centres[: dem.n_owned]
        u = dem.create_vector()
        u.array[:] = (0.01 * np.sin(3 * x + 1.0)).ravel()
        F = dem.force(u, 0.0, dem.create_vector()).array.reshape(-1, dem.d)
        sigma = dem.stress(u, 0.0)
        results.append((dict(zip(_cell_keys(dem), zip(F, sigma))), dem.energies(u, 0.0)))
    (par, e_par), (ser, e_ser) = results
    assert set(par) <= set(ser)
    scale = max(np.abs(f).max() for f, _ in ser.values())
    s_scale = max(np.abs(s).max() for _, s in ser.values())
    assert max(np.abs(par[k][0] - ser[k][0]).max() for k in par) < 1e-12 * scale
    assert max(np.abs(par[k][1] - ser[k][1]).max() for k in par) < 1e-12 * s_scale
    for key in ("elastic", "stabilisation", "external"):
        assert e_par[key] == pytest.approx(e_ser[key], rel=1e-12, abs=1e-14)


def _held_bytes(obj, seen=None) -> int:
    """Bytes of the numpy arrays and scipy sparse matrices reachable from ``obj`` through
    attributes, dataclass fields, lists, tuples and dicts (each array counted once)."""
    import dataclasses

    import scipy.sparse

    seen = set() if seen is None else seen
    if id(obj) in seen:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return obj.nbytes if obj.base is None or id(obj.base) not in seen else 0
    if scipy.sparse.issparse(obj):
        return sum(_held_bytes(getattr(obj, n), seen) for n in ("data", "indices", "indptr", "row", "col")
                   if hasattr(obj, n))
    if isinstance(obj, (list, tuple)):
        return sum(_held_bytes(x, seen) for x in obj)
    if isinstance(obj, dict):
        return sum(_held_bytes(x, seen) for x in obj.values())
    if dataclasses.is_dataclass(obj):
        return sum(_held_bytes(getattr(obj, f.name), seen) for f in dataclasses.fields(obj))
    if hasattr(obj, "__dict__") and type(obj).__module__.startswith("dolfinx_dem"):
        return sum(_held_bytes(x, seen) for x in vars(obj).values())
    return 0


def test_set_up_keeps_one_copy_of_the_energy_rows():
    """The memory a discretisation keeps: Q once (the step reads its rows in place), no PETSc
    matrix and no gradient operator; per 2D cell, the arrays it holds (geometry, reconstruction,
    rows) stay below 1.6 kB, where a second copy of Q (0.66 kB) would exceed it."""
    from petsc4py import PETSc

    mesh = dolfinx.mesh.create_rectangle(MPI.COMM_SELF, [[0.0, 0.0], [1.0, 1.0]], [40, 40],
                                         diagonal=DiagonalType.crossed)
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    dem = DEMDiscretisation(mesh, MATERIAL, dirichlet=[DirichletBC(left, [0.0, 0.0])])
    dem.stable_time_step()
    assert not [k for k, v in vars(dem).items() if isinstance(v, PETSc.Mat)]
    assert dem.factored.vals is dem.rows.Q.data and dem.factored.cols is dem.rows.Q.indices
    per_cell = _held_bytes(dem) / dem.n_owned
    assert 700 < per_cell < 1600, per_cell


@pytest.mark.parametrize("d", [2, 3])
def test_scheme_a_uses_each_cells_material(d):
    """Scheme A's local solve (eq. (20)-(21)) with two materials: on every traction-free scheme A
    facet, sigma_c n_f = 0 with the stress of the facet's cell's own material (cells without a
    facet on the interface, whose value is set after scheme A's, reconstruction.py)."""
    dem = _problem(d, "A", MPI.COMM_SELF, two=True)
    rec, geom = dem.reconstruction, dem.geometry
    u = _random_field(dem, 1)
    sigma = dem.stress(u, 0.0)
    index = dem.materials.index
    cells = geom.facet_cells[rec.scheme_a_facets, 0]
    c = geom.facet_cells[geom.cell_facets[cells]]  # (n, d+1, 2): the cells of each cell's facets
    at_interface = ((c[..., 1] >= 0) & (index[c[..., 0]] != index[np.maximum(c[..., 1], 0)])).any(axis=1)
    assert 0 < at_interface.sum() < len(cells)
    cells = cells[~at_interface]
    normals = geom.facet_area_normals[cells, geom.facet_local[rec.scheme_a_facets[~at_interface], 0]]
    assert set(dem.materials.index[cells]) == {0, 1}
    assert np.abs(np.einsum("nij,nj->ni", sigma[cells], normals)).max() < 1e-12 * np.abs(sigma).max()


def test_several_materials_mass():
    """The lumped mass is rho_c |c| with each cell's density."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 3)
    dem = DEMDiscretisation(mesh, MATERIALS, cell_tags=_material_tags(mesh))
    x = dem.geometry.cell_centres[: dem.n_owned, 0]
    rho = np.where(x < 0.6, MATERIALS[3].rho, MATERIALS[8].rho)
    assert np.allclose(dem.mass.array_r, np.repeat(rho * dem.geometry.cell_volumes[: dem.n_owned], 2), rtol=1e-14)


@pytest.mark.parametrize("values, word", [
    ({3: MATERIAL, 8: MATERIALS[8], 5: MATERIAL}, "cell tag 5 selects no cell"),
    ({3: MATERIAL}, "carry none of the material tags"),
    ({3: MATERIAL, 8: ElasticMaterial(E=1.0, nu=0.3, rho=1.0, plane="stress")}, "share 'plane'"),
])
def test_several_materials_bad_input(values, word):
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 3)
    with pytest.raises(ValueError, match=word):
        DEMDiscretisation(mesh, values, cell_tags=_material_tags(mesh))


def test_several_materials_overlap_and_missing_tags():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 3)
    tags = _material_tags(mesh)
    cells = np.concatenate([tags.indices, tags.indices[:3]])
    values = np.concatenate([tags.values, np.full(3, 5, dtype=np.int32)])
    order = np.argsort(cells, kind="stable")
    overlapping = dolfinx.mesh.meshtags(mesh, 2, cells[order], values[order])
    with pytest.raises(ValueError, match="several material tags"):
        DEMDiscretisation(mesh, {3: MATERIAL, 8: MATERIALS[8], 5: MATERIAL}, cell_tags=overlapping)
    with pytest.raises(ValueError, match="need cell_tags"):
        DEMDiscretisation(mesh, MATERIALS)
    with pytest.raises(ValueError, match="only used with several materials"):
        DEMDiscretisation(mesh, MATERIAL, cell_tags=tags)


@pytest.mark.mpi
def test_springs_in_series_are_exact():
    """A bar of two materials (E = 1 on [0, 0.4], 4 on [0.4, 1]), clamped at x = 0, traction
    sigma at x = 1, scheme A: the exact displacement, piecewise linear, is in equilibrium (force
    0) and every cell stress is sigma, as the interface facet is reconstructed by traction
    continuity (reconstruction.py; with eq. (7)'s interpolation the stress error was 0.32 sigma)."""
    comm, n, sigma = MPI.COMM_WORLD, 20, 0.5
    mesh = dolfinx.mesh.create_interval(comm, n, [0.0, 1.0], ghost_mode=dolfinx.mesh.GhostMode.shared_facet)
    cells = np.arange(mesh.topology.index_map(1).size_local + mesh.topology.index_map(1).num_ghosts, dtype=np.int32)
    x = dolfinx.mesh.compute_midpoints(mesh, 1, cells)[:, 0]
    tags = dolfinx.mesh.meshtags(mesh, 1, cells, np.where(x < 0.4, 1, 2).astype(np.int32))
    materials = {1: ElasticMaterial(E=1.0, nu=0.0, rho=1.0), 2: ElasticMaterial(E=4.0, nu=0.0, rho=3.0, eta=2.0)}
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    right = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 1.0))
    dem = DEMDiscretisation(mesh, materials, "A", [DirichletBC(left, [0.0])], tractions=[Traction(right, [sigma])],
                            cell_tags=tags)
    xc = dem.geometry.cell_centres[: dem.n_owned, 0]
    u = dem.create_vector()
    u.array[:] = np.where(xc < 0.4, sigma * xc, sigma * (0.4 + (xc - 0.4) / 4))
    F = dem.force(u, 0.0, dem.create_vector())
    assert F.norm(PETSc.NormType.NORM_INFINITY) < 1e-13 * sigma
    error = np.abs(dem.stress(u, 0.0)[:, 0, 0] - sigma).max(initial=0.0)
    assert comm.allreduce(error, op=MPI.MAX) < 1e-13 * sigma
