"""Fracture along facets, first brick (dolfinx_dem/fracture/): the split geometry, the operator
of a crack set and G_h at fixed displacements, against the closed forms of the design note
§6 and against meshes whose vertices are duplicated along the crack."""

import types

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC, Traction
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import InputError
from dolfinx_dem.fracture import Conditions, CrackState, break_facets, compute_operator, energy_release
from dolfinx_dem.fracture.operator import potential, row_values
from dolfinx_dem.fracture.rebuild import break_facets_with_changes
from dolfinx_dem.fracture.release import release_bound, trial_breaks
from dolfinx_dem.geometry import geometry_from_arrays
from dolfinx_dem.material import CellMaterials, ElasticMaterial

pytestmark = pytest.mark.skip_in_parallel
SELF = MPI.COMM_SELF
E, H, N = 7.0, 0.05, 20


def bar(n, h, cut=None, jitter=0.0):
    """A 1D bar of n cells of length h (each vertex moved by up to ``jitter`` h, randomly); with
    ``cut`` (a cell count) the vertex after cell ``cut`` - 1 is duplicated: two bodies, cells
    numbered as in the intact bar."""
    x = np.arange(n + 1) * h
    x[1:-1] += jitter * h * np.random.default_rng(0).uniform(-1, 1, n - 1)
    ids = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    if cut is not None:
        ids[cut:] += 1
    return geometry_from_arrays(np.stack([x[:-1], x[1:]], axis=1)[:, :, None], ids, ids[:, ::-1])


def grid(nx, ny, cut, cut_to=1.0, hole=False, jitter=0.0, duplicate=False):
    """Right-diagonal triangles on [0, 1] x [0, 1], the vertices inside moved by up to ``jitter``
    times the spacing (randomly), without the cells in [1/3, 2/3]^2 if ``hole``, and the crack
    along the vertices of column ``cut`` up to height ``cut_to``: (geometry, the interior facets
    on the crack). With ``duplicate`` the crack's vertices are duplicated instead (the cells on
    their right get the copies), cells numbered as without."""
    X, Y = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1), indexing="ij")
    grid_points = np.c_[X.ravel(), Y.ravel()]
    inside = np.all((grid_points > 0) & (grid_points < 1), axis=1)
    points = grid_points.copy()
    points[inside] += jitter / max(nx, ny) * np.random.default_rng(0).uniform(-1, 1, (inside.sum(), 2))
    v = lambda i, j: i * (ny + 1) + j  # noqa: E731
    cells = np.array([c for i in range(nx) for j in range(ny) for c in
                      [(v(i, j), v(i + 1, j), v(i + 1, j + 1)), (v(i, j), v(i + 1, j + 1), v(i, j + 1))]])
    if hole:
        centre = grid_points[cells].mean(axis=1)
        cells = cells[~np.all((centre > 1 / 3) & (centre < 2 / 3), axis=1)]
    on_cut = np.isclose(grid_points[:, 0], cut / nx) & (grid_points[:, 1] <= cut_to + 1e-12)
    ids = cells.copy()
    if duplicate:
        right = grid_points[cells].mean(axis=1)[:, 0] > cut / nx
        ids[right[:, None] & on_cut[cells]] += len(points)
    return simplices(points, cells, ids, on_cut)


def simplices(points, cells, ids, on_cut):
    """The geometry of the simplices ``cells`` (indices into ``points``) with vertex numbers
    ``ids`` (facets identified by their vertex numbers), and its interior facets whose vertices
    are all ``on_cut`` (per point)."""
    nv = cells.shape[1]
    opposite = [[k for k in range(nv) if k != j] for j in range(nv)]  # the vertices of facet j
    tuples = np.sort(ids[:, opposite], axis=2).reshape(-1, nv - 1)
    facet_ids = np.unique(tuples, axis=0, return_inverse=True)[1].reshape(-1, nv)
    geom = geometry_from_arrays(points[cells], ids, facet_ids)
    crack = np.unique(geom.cell_facets[on_cut[cells][:, opposite].all(axis=2)])
    return geom, crack[geom.facet_cells[crack, 1] >= 0]


def cube(n, duplicate=False):
    """The unit cube in n^3 cubes of 6 tetrahedra each (Kuhn's conforming subdivision), with the
    crack through it along x = 1/2 (as ``grid``)."""
    g = np.linspace(0, 1, n + 1)
    points = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    v = lambda i: (i[..., 0] * (n + 1) + i[..., 1]) * (n + 1) + i[..., 2]  # noqa: E731
    corner = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), axis=-1).reshape(-1, 1, 3)
    paths = [np.cumsum(np.r_[[[0, 0, 0]], np.eye(3, dtype=int)[list(p)]], axis=0)
             for p in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))]
    cells = np.concatenate([v(corner + p) for p in paths])
    on_cut = np.isclose(points[:, 0], 0.5)
    ids = cells.copy()
    if duplicate:
        ids[(points[cells].mean(axis=1)[:, 0] > 0.5)[:, None] & on_cut[cells]] += len(points)
    return simplices(points, cells, ids, on_cut)


def material(eta):
    return ElasticMaterial(E=E, nu=0.3, rho=1.0, eta=eta)


def facet_at(geom, x):
    return int(np.flatnonzero(np.all(np.isclose(geom.facet_centres, x), axis=1))[0])


def forces(op, u, g, t):
    """-dV/du of the crack-dependent potential, -Q^T a (no tractions where this is used)."""
    return -(op.rows.Q.T @ row_values(op, u, g, t))


@pytest.mark.parametrize("scheme, eta", [("A", E), ("A", 3.0), ("B", E), ("B", 3.0)])
def test_release_1d_uniform_strain(scheme, eta):
    """Design note §6: for a uniform strain eps, G_h = (E - eta/4) h eps^2 with scheme A lips and
    (3/4 E - eta/16) h eps^2 with scheme B lips."""
    geom = bar(N, H)
    op = compute_operator(geom, Conditions(CellMaterials.uniform(material(eta), N), scheme),
                          CrackState.intact(geom), SELF)
    eps = 0.01
    G = energy_release(op, [facet_at(geom, [N * H / 2])], eps * geom.cell_centres[:, 0], SELF)[0]
    expected = (E - eta / 4) * H * eps**2 if scheme == "A" else (0.75 * E - eta / 16) * H * eps**2
    assert abs(G / expected - 1) < 1e-13


def test_release_1d_random_displacements():
    """Design note §6 on random u, eta != E, scheme A, from an intact bar and from a bar already
    cracked elsewhere: Delta V = 1/2 (E - eta/4) h (a^2 + b^2) + eta/(2h) J_f^2 + eta/2 (a J_l + b J_r),
    with the gradients and jumps of eq. (8) and (12) written out for the uniform bar."""
    eta = 3.0
    geom = bar(N, H)
    rng = np.random.default_rng(34)
    u = rng.standard_normal(N) * 1e-3
    G = (np.roll(u, -1) - np.roll(u, 1)) / (2 * H)  # cell gradients, valid away from the ends
    jump = lambda l: u[l] - u[l + 1] + H / 2 * (G[l] + G[l + 1])  # noqa: E731  facet between l and l + 1
    intact = compute_operator(geom, Conditions(CellMaterials.uniform(material(eta), N), "A"),
                              CrackState.intact(geom), SELF)
    cracked = break_facets(intact, [facet_at(geom, [4 * H])], 1, SELF)  # far enough: cells 3, 4 only
    for op, i in ((intact, 9), (intact, 12), (cracked, 9)):
        a, b = G[i], G[i + 1]
        expected = 0.5 * (E - eta / 4) * H * (a**2 + b**2) + eta / (2 * H) * jump(i)**2 \
            + eta / 2 * (a * jump(i - 1) + b * jump(i + 1))
        released = energy_release(op, [facet_at(geom, [(i + 1) * H])], u, SELF)[0]
        assert abs(released / expected - 1) < 1e-13, (i, released, expected)


@pytest.mark.parametrize("scheme", ["A", "B"])
def test_split_1d_is_the_duplicated_vertex(scheme):
    """The bar with its centre facet broken has the energy rows of the bar whose centre vertex is
    duplicated (two bodies): S rows identical, jump rows identical up to order and the broken
    facet's zero rows; energies and forces at random u, with a Dirichlet value at x = 0 and a
    traction at x = L, to 1e-13."""
    geom, dup = bar(N, H, jitter=0.3), bar(N, H, cut=N // 2, jitter=0.3)
    mat = CellMaterials.uniform(material(3.0), N)
    conditions = lambda g: Conditions(mat, scheme, np.array([facet_at(g, [0.0])]),  # noqa: E731
                                      traction_facets=np.array([facet_at(g, [N * H])]))
    centre = geom.cell_facets[N // 2 - 1, 0]  # the facet opposite the cell's vertex 0: its right end
    op = compute_operator(geom, conditions(geom), CrackState.intact(geom).broken(geom, [centre], 0), SELF)
    ref = compute_operator(dup, conditions(dup), CrackState.intact(dup), SELF)
    assert (op.geometry.num_bodies, ref.geometry.num_bodies) == (2, 2)
    assert np.array_equal(op.geometry.cell_bodies, ref.geometry.cell_bodies)
    assert np.array_equal(np.sort(op.geometry.facet_diameters), np.sort(dup.facet_diameters))
    m = op.rows.num_elastic
    assert (op.rows.Q[:m] != ref.rows.Q[:m]).nnz == 0
    live = np.abs(op.rows.Q[m:]).sum(axis=1).A1 > 0
    assert live.sum() == ref.rows.Q.shape[0] - m == N - 2
    assert (op.rows.Q[m:][live] != ref.rows.Q[m:]).nnz == 0  # both ordered by the cells' numbers
    rng = np.random.default_rng(1)
    u, g, t = rng.standard_normal(N), rng.standard_normal(1), rng.standard_normal(1)
    V, V_ref = potential(op, u, g, t), potential(ref, u, g, t)
    assert abs(V - V_ref) < 1e-13 * abs(V_ref)
    F, F_ref = forces(op, u, g, t), forces(ref, u, g, t)
    assert np.abs(F - F_ref).max() < 1e-13 * np.abs(F_ref).max()


def test_release_next_to_a_traction():
    """Breaking the facet next to a loaded end leaves the end cell with two open facets (scheme B,
    reconstruction.py), which changes its traction facet's value and so the tractions' work:
    G_h is still the drop of the whole potential, V(intact) - V(the bar with that vertex
    duplicated), here with a Dirichlet value at x = 0 and a traction at x = L."""
    geom, dup = bar(N, H), bar(N, H, cut=N - 1)
    mat = CellMaterials.uniform(material(3.0), N)
    conditions = lambda g: Conditions(mat, "A", np.array([facet_at(g, [0.0])]),  # noqa: E731
                                      traction_facets=np.array([facet_at(g, [N * H])]))
    op = compute_operator(geom, conditions(geom), CrackState.intact(geom), SELF)
    ref = compute_operator(dup, conditions(dup), CrackState.intact(dup), SELF)
    rng = np.random.default_rng(5)
    u, g, t = rng.standard_normal(N), rng.standard_normal(1), rng.standard_normal(1)
    drop = potential(op, u, g, t) - potential(ref, u, g, t)
    G = energy_release(op, [facet_at(geom, [(N - 1) * H])], u, SELF, g, t)[0]
    assert abs(G - drop) < 1e-13 * abs(potential(op, u, g, t))


@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("hole, cut_to, bodies", [(False, 1.0, 2), (True, 1 / 3, 1)])
def test_split_2d_through_crack_is_the_duplicated_mesh(scheme, hole, cut_to, bodies):
    """A crack along a column of vertices with no tip, on a jittered mesh: through the plate (two
    bodies), or from the edge to the hole of a square ring (one body: only the vertex numbers
    per sector keep the stencils on their side). The operator equals that of the mesh with the
    crack's vertices duplicated: energies and forces at random u to 1e-13."""
    geom, crack = grid(6, 6, 3, cut_to, hole, jitter=0.3)
    dup, _ = grid(6, 6, 3, cut_to, hole, jitter=0.3, duplicate=True)
    mat = CellMaterials.uniform(material(3.0), geom.num_cells)
    op = compute_operator(geom, Conditions(mat, scheme), CrackState.intact(geom).broken(geom, crack, 0), SELF)
    ref = compute_operator(dup, Conditions(mat, scheme), CrackState.intact(dup), SELF)
    assert len(crack) == 6 * cut_to
    assert op.geometry.num_facets == dup.num_facets == geom.num_facets + len(crack)
    assert op.geometry.num_bodies == ref.geometry.num_bodies == bodies
    u, empty = np.random.default_rng(2).standard_normal(geom.num_cells * 2), np.empty(0)
    V, V_ref = potential(op, u, empty, empty), potential(ref, u, empty, empty)
    assert abs(V - V_ref) < 1e-13 * abs(V_ref)
    F, F_ref = forces(op, u, empty, empty), forces(ref, u, empty, empty)
    assert np.abs(F - F_ref).max() < 1e-13 * np.abs(F_ref).max()


@pytest.mark.parametrize("scheme", ["A", "B"])
def test_split_3d_through_crack_is_the_duplicated_mesh(scheme):
    """The same in 3D: a cube cut through along x = 1/2 (4 x 4 x 4 x 6 tetrahedra)."""
    (geom, crack), (dup, _) = cube(4), cube(4, duplicate=True)
    mat = CellMaterials.uniform(material(3.0), geom.num_cells)
    op = compute_operator(geom, Conditions(mat, scheme), CrackState.intact(geom).broken(geom, crack, 0), SELF)
    ref = compute_operator(dup, Conditions(mat, scheme), CrackState.intact(dup), SELF)
    assert len(crack) == 32 and op.geometry.num_bodies == ref.geometry.num_bodies == 2
    u, empty = np.random.default_rng(6).standard_normal(geom.num_cells * 3), np.empty(0)
    V, V_ref = potential(op, u, empty, empty), potential(ref, u, empty, empty)
    assert abs(V - V_ref) < 1e-13 * abs(V_ref)
    F, F_ref = forces(op, u, empty, empty), forces(ref, u, empty, empty)
    assert np.abs(F - F_ref).max() < 1e-13 * np.abs(F_ref).max()


def test_release_2d_corner_fragment():
    """G_h of a 2D facet whose break has no tip (both vertices on the boundary: it cuts off the
    corner cell at (1, 0)) is the drop of the whole potential, and positive."""
    geom, _ = grid(4, 4, 0)
    op = compute_operator(geom, Conditions(CellMaterials.uniform(material(E), geom.num_cells), "A"),
                          CrackState.intact(geom), SELF)
    f = facet_at(geom, [0.875, 0.125])
    u = np.random.default_rng(3).standard_normal(geom.num_cells * 2)
    G = energy_release(op, [f], u, SELF)[0]
    after = break_facets(op, [f], 0, SELF)
    assert after.geometry.num_bodies == 2
    drop = potential(op, u, np.empty(0), np.empty(0)) - potential(after, u, np.empty(0), np.empty(0))
    assert G > 0 and abs(G * geom.facet_areas[f] - drop) < 1e-13 * potential(op, u, np.empty(0), np.empty(0))


def test_crack_tip_refused_in_2d():
    """One broken interior facet of a plate has two tips: refused, naming the issue's stage."""
    geom, _ = grid(4, 4, 0)
    op = compute_operator(geom, Conditions(CellMaterials.uniform(material(E), geom.num_cells), "A"),
                          CrackState.intact(geom), SELF)
    with pytest.raises(InputError, match="tip.*issue 34"):
        break_facets(op, [facet_at(geom, [0.5, 0.375])], 0, SELF)


def test_refusals():
    """More than one process (a stand-in communicator of size 2), boundary facets, facets broken twice."""
    geom = bar(N, H)
    op = compute_operator(geom, Conditions(CellMaterials.uniform(material(E), N), "A"),
                          CrackState.intact(geom), SELF)
    with pytest.raises(InputError, match="issue 34.*one process"):
        break_facets(op, [3], 0, types.SimpleNamespace(size=2))
    with pytest.raises(InputError, match="not an interior facet"):
        break_facets(op, [facet_at(geom, [0.0])], 0, SELF)
    with pytest.raises(InputError, match="broken already"):
        break_facets(break_facets(op, [3], 0, SELF), [3], 1, SELF)


def test_intact_operator_is_the_discretisations():
    """With nothing broken the operator's potential is DEMDiscretisation's (body force 0), with a
    Dirichlet condition and a traction: the fracture operator is the discretisation's operator."""
    mesh = meshes.create_interval(SELF, N, 0.0, N * H)[0]
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    right = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], N * H))
    dem = DEMDiscretisation(mesh, material(3.0), "A", [DirichletBC(left, [0.3])], tractions=[Traction(right, [2.0])])
    rec = dem.reconstruction
    conditions = Conditions(dem.materials, rec.scheme, rec.dirichlet_facets, rec.fixed, rec.traction_facets)
    op = compute_operator(dem.geometry, conditions, CrackState.intact(dem.geometry), SELF)
    u = np.random.default_rng(4).standard_normal(N)
    V = potential(op, u, dem.data.dirichlet_values(0.0).ravel(), dem.data.traction_values(0.0).ravel())
    V_dem = dem.energies(dem.vector(u), 0.0)["potential"]
    assert abs(V - V_dem) < 1e-13 * abs(V_dem)


def test_intact_rows_are_the_discretisations_rows():
    """With nothing broken, the operator's energy rows are DEMDiscretisation's, bit for bit
    (same layout on one process, entries sorted by column), so a MEMM hook can install the
    rows of a crack set in place of the discretisation's."""
    mesh = meshes.create_rectangle(SELF, [0.0, 0.0], [1.0, 1.0], [6, 6])[0]
    dem = DEMDiscretisation(mesh, material(3.0), "A")
    op = compute_operator(dem.geometry, Conditions(dem.materials, "A"), CrackState.intact(dem.geometry), SELF)
    Q = op.rows.Q.copy()
    Q.sort_indices()
    assert all(np.array_equal(getattr(Q, a), getattr(dem.rows.Q, a)) for a in ("indptr", "indices", "data"))


def _identical(a, b):
    """Two sparse matrices with the same shape, pattern and bits (entries sorted by column)."""
    a, b = a.tocsr().copy(), b.tocsr().copy()
    a.sort_indices()
    b.sort_indices()
    return a.shape == b.shape and all(np.array_equal(getattr(a, k), getattr(b, k))
                                      for k in ("indptr", "indices", "data"))


def _check_local_rebuild(geom, conditions, batches):
    """Break ``batches`` one after the other with the local rebuild; after each, every matrix and
    list of the operator is the from-scratch operator's, bit for bit. Returns the changed rows."""
    op = compute_operator(geom, conditions, CrackState.intact(geom), SELF)
    changes = []
    for step, facets in enumerate(batches):
        op, changed = break_facets_with_changes(op, facets, step, SELF)
        ref = compute_operator(geom, conditions, op.crack, SELF)
        for name in "RDN":
            assert _identical(getattr(op.reconstruction, name), getattr(ref.reconstruction, name)), (step, name)
        for name in ("Q", "Q_dirichlet", "QF"):
            assert _identical(getattr(op.rows, name), getattr(ref.rows, name)), (step, name)
        for name in ("neumann_facets", "scheme_a_facets", "multi_neumann_cells", "extrapolated_facets"):
            assert np.array_equal(getattr(op.reconstruction, name), getattr(ref.reconstruction, name)), (step, name)
        assert np.array_equal(op.lips, ref.lips) and np.array_equal(op.geometry.facet_cells, ref.geometry.facet_cells)
        changes.append((len(changed.facets), len(changed.cells), len(changed.jump_facets)))
    return changes


@pytest.mark.parametrize("scheme", ["A", "B"])
def test_local_rebuild_1d_successive_breaks(scheme):
    """Design note §3: breaking facets one step after the other (a jittered bar with a Dirichlet
    end and a loaded end; the last batch breaks two adjacent facets, leaving a cell with two
    open facets), the locally rebuilt operator is the from-scratch operator bit for bit, and a
    single break changes 2 R rows (the facet and its lip), 2 S cells and 3 J facets."""
    geom = bar(N, H, jitter=0.3)
    conditions = Conditions(CellMaterials.uniform(material(3.0), N), scheme, np.array([facet_at(geom, [0.0])]),
                            traction_facets=np.array([facet_at(geom, [geom.facet_centres[:, 0].max()])]))
    f = [geom.cell_facets[i, 0] for i in (9, 4, 17, 18)]
    changes = _check_local_rebuild(geom, conditions, [[f[0]], [f[1]], [f[2], f[3]]])
    assert changes[:2] == [(2, 2, 3), (2, 2, 3)]


@pytest.mark.parametrize("scheme", ["A", "B"])
def test_local_rebuild_2d(scheme):
    """The same for the 2D cuts the split admits: a plate cut through, a ring cut from the edge to
    the hole, and two corner cells cut off one step after the other."""
    for geom, batches in ((grid(6, 6, 3, 1.0, False, jitter=0.3)[0], [grid(6, 6, 3, 1.0, False, jitter=0.3)[1]]),
                          (grid(6, 6, 3, 1 / 3, True, jitter=0.3)[0], [grid(6, 6, 3, 1 / 3, True, jitter=0.3)[1]])):
        _check_local_rebuild(geom, Conditions(CellMaterials.uniform(material(3.0), geom.num_cells), scheme), batches)
    geom, _ = grid(4, 4, 0)
    corners = [[facet_at(geom, [0.875, 0.125])], [facet_at(geom, [0.125, 0.875])]]
    changes = _check_local_rebuild(geom, Conditions(CellMaterials.uniform(material(3.0), geom.num_cells), scheme),
                                   corners)
    assert changes[0][1:] == (2, 3)


def test_break_before_the_latest_refused():
    """Lips are numbered by break step: a break at an earlier step than the latest is refused."""
    geom = bar(N, H)
    op = compute_operator(geom, Conditions(CellMaterials.uniform(material(E), N), "A"), CrackState.intact(geom), SELF)
    with pytest.raises(InputError, match="before the latest break"):
        break_facets(break_facets(op, [3], 5, SELF), [7], 4, SELF)


@pytest.mark.parametrize("scheme", ["A", "B"])
def test_release_bound_is_an_upper_bound(scheme):
    """release_bound (the screen) >= Delta V_f for every candidate of a cracked bar (a two-cell
    fragment, a Dirichlet end, a loaded end) at rough random u, eta != E: the energy of the rows
    next to f bounds what its break releases; the bound is reached by the facet that splits the
    two-cell fragment into one-cell fragments, and is infinite next to the loaded end."""
    geom = bar(N, H, jitter=0.3)
    conditions = Conditions(CellMaterials.uniform(material(3.0), N), scheme, np.array([facet_at(geom, [0.0])]),
                            traction_facets=np.array([facet_at(geom, [geom.facet_centres[:, 0].max()])]))
    op = compute_operator(geom, conditions, CrackState.intact(geom), SELF)
    op = break_facets(op, [geom.cell_facets[i, 0] for i in (5, 7, 12)], 0, SELF)  # right ends of the cells
    candidates = np.setdiff1d(geom.interior_facets, op.broken)
    rng = np.random.default_rng(8)
    for _ in range(3):
        u, g, t = rng.standard_normal(N) * 1e-3, rng.standard_normal(1) * 1e-3, rng.standard_normal(1)
        drop = trial_breaks(op, candidates, u, SELF, g, t)[0] * geom.facet_areas[candidates]
        bound = release_bound(op, candidates, u, g, t)
        assert np.all(bound >= drop * (1 - 1e-12))
        finite = np.isfinite(bound)
        exact = np.abs(bound[finite] / drop[finite] - 1) < 1e-12
        assert (~finite).sum() == 1 and candidates[finite][exact].tolist() == [geom.cell_facets[6, 0]]
