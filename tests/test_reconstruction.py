"""Facet reconstruction (paper eq. (6)-(7), scheme A eq. (19)-(21), scheme B)."""

import dolfinx.mesh
import numpy as np
import pytest
from dolfinx.mesh import DiagonalType
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, meshes
from dolfinx_dem.conditions import DirichletBC
from dolfinx_dem.contact.patch import PatchScatter
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.geometry import compute_geometry, geometry_from_arrays
from dolfinx_dem.material import CellMaterials, ElasticMaterial
from dolfinx_dem.reconstruction import compute_interior_stencils, compute_reconstruction

MATERIAL = ElasticMaterial(E=1.0, nu=0.3, rho=1.0)


def gmsh_mesh(comm, kind, h):
    """Unstructured gmsh meshes: "disc" (unit disc), "graded" ([0,2]x[0,1], size h/8 -> 2h) and
    "box" (unit cube)."""
    import gmsh

    gdim = {"disc": 2, "graded": 2, "box": 3}[kind]
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(kind)
        occ = gmsh.model.occ
        if kind == "disc":
            s = occ.addDisk(0.0, 0.0, 0.0, 1.0, 1.0)
        elif kind == "graded":
            s = occ.addRectangle(0.0, 0.0, 0.0, 2.0, 1.0)
        else:
            s = occ.addBox(0.0, 0.0, 0.0, 1.0, 1.0, 1.0)
        occ.synchronize()
        gmsh.model.addPhysicalGroup(gdim, [s], 1)
        if kind == "graded":
            field = gmsh.model.mesh.field
            field.add("MathEval", 1)
            field.setString(1, "F", f"{h / 8} + {h} * x")
            field.setAsBackgroundMesh(1)
            for option in ("ExtendFromBoundary", "FromPoints", "FromCurvature"):
                gmsh.option.setNumber(f"Mesh.MeshSize{option}", 0)
        else:
            gmsh.option.setNumber("Mesh.MeshSizeMin", h)
            gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(gdim)
    try:
        mesh, _, _ = _compat.mesh_from_gmsh_model(gmsh.model, comm, gdim)
    finally:
        if comm.rank == 0:
            gmsh.finalize()
    return mesh


def _geometry(mesh):
    return compute_geometry(mesh.comm, mesh, _compat.create_vector_space(mesh, "DG", 0))[0]


def _check_stencils(geom, stencils, allow_extrapolation):
    d = geom.d
    assert np.array_equal(stencils.facets, geom.interior_facets)
    alpha, cells = stencils.alpha, stencils.cells
    assert alpha.shape == cells.shape == (len(stencils.facets), d + 1)
    assert np.allclose(alpha.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    # d+1 distinct cells
    assert np.all(np.diff(np.sort(cells, axis=1), axis=1) > 0)
    # eq. (7): sum_i alpha_i x_i = x_f, exactly (also on extrapolated facets)
    xf = geom.facet_centres[stencils.facets]
    recon = np.einsum("fi,fid->fd", alpha, geom.cell_centres[cells])
    assert np.abs(recon - xf).max() < 1e-12 * np.abs(geom.cell_centres).max()
    inside = ~np.isin(stencils.facets, stencils.extrapolated)
    assert np.all(alpha[inside] >= 0.0) and np.all(alpha[inside] <= 1.0)
    if not allow_extrapolation:
        assert stencils.extrapolated.size == 0
    return inside


@pytest.mark.parametrize(
    "kind, h", [("disc", 0.15), ("graded", 0.15), ("box", 0.3)], ids=["disc", "graded", "box"]
)
def test_interior_stencils_unstructured(kind, h):
    mesh = gmsh_mesh(MPI.COMM_SELF, kind, h)
    geom = _geometry(mesh)
    assert geom.num_cells > 250
    if kind == "graded":  # the mesh really is graded
        assert geom.cell_volumes.max() > 30 * geom.cell_volumes.min()
    stencils = compute_interior_stencils(geom)
    inside = _check_stencils(geom, stencils, allow_extrapolation=(kind != "disc"))
    assert inside.mean() > 0.95
    if kind == "graded":
        # Only at the 4 corners of the rectangle (within one local cell size) does no simplex of barycentres contain x_f
        # (measured: 4 facets; an exhaustive search over 30 neighbours finds none either).
        xf = geom.facet_centres[stencils.extrapolated]
        corners = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0], [2.0, 1.0]])
        assert len(xf) <= 4
        assert np.all(np.linalg.norm(xf[:, None] - corners[None], axis=2).min(axis=1) < 0.15)


def test_extrapolated_facets_unit_cube():
    """At the edges of a box some facet barycentres lie outside the hull of the barycentres: the
    rule picks the least extrapolating simplex; weights still sum to 1 and reproduce x_f, so
    affine fields stay exact through R."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 3)
    geom = _geometry(mesh)
    stencils = compute_interior_stencils(geom)
    inside = _check_stencils(geom, stencils, allow_extrapolation=True)
    assert stencils.extrapolated.size > 0
    assert np.all(np.isin(stencils.extrapolated, geom.interior_facets))
    assert stencils.alpha[~inside].min() < -1e-10  # really extrapolated
    assert stencils.alpha[~inside].min() >= -1.0  # the documented bound
    # Affine field through R (all boundary facets Dirichlet so that only eq. (7) acts).
    rec = compute_reconstruction(geom, CellMaterials.uniform(MATERIAL, geom.num_cells), geom.boundary_facets, "A")
    A = np.array([[0.3, -1.2, 0.5], [2.0, 0.1, -0.7], [0.4, 0.9, 1.1]])
    b = np.array([0.2, -0.3, 0.5])
    uc = geom.cell_centres @ A.T + b
    g = geom.facet_centres[rec.dirichlet_facets] @ A.T + b
    uf = (rec.R @ uc.ravel() + rec.D @ g.ravel()).reshape(-1, 3)
    assert np.allclose(uf, geom.facet_centres @ A.T + b, rtol=0, atol=1e-12)


def _square(diagonal, n=4, comm=MPI.COMM_SELF):
    return dolfinx.mesh.create_unit_square(comm, n, n, diagonal=diagonal)


@pytest.mark.mpi
def test_multi_neumann_cells_scheme_a():
    """A "right" unit square has exactly two corner cells with two Neumann facets."""
    mesh = _square(DiagonalType.right, comm=MPI.COMM_WORLD)
    dem = DEMDiscretisation(mesh, MATERIAL, scheme="A")
    geom = dem.geometry
    multi = dem.multi_neumann_cells  # the owned ones
    assert dem.num_multi_neumann_cells == 2
    for c in multi:
        assert np.isin(geom.cell_facets[c], geom.boundary_facets).sum() == 2
    corners = np.concatenate(MPI.COMM_WORLD.allgather(geom.cell_centres[multi]))
    corners = np.sort(np.round(corners * 12).astype(int), axis=0)
    assert np.array_equal(corners, [[1, 1], [11, 11]])  # barycentres (1/12, 11/12), (11/12, 1/12)
    # Clamping x = 0 leaves one of them with a single Neumann facet.
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    dem = DEMDiscretisation(mesh, MATERIAL, scheme="A", dirichlet=[DirichletBC(left, [0.0, 0.0])])
    assert dem.num_multi_neumann_cells == 1
    corners = np.concatenate(MPI.COMM_WORLD.allgather(dem.geometry.cell_centres[dem.multi_neumann_cells]))
    assert np.allclose(corners, [[11 / 12, 1 / 12]])


@pytest.mark.mpi
def test_multi_neumann_cells_crossed_and_scheme_b():
    crossed = DEMDiscretisation(_square(DiagonalType.crossed, comm=MPI.COMM_WORLD), MATERIAL, "A")
    assert crossed.num_multi_neumann_cells == 0
    right_b = DEMDiscretisation(_square(DiagonalType.right, comm=MPI.COMM_WORLD), MATERIAL, "B")
    assert right_b.num_multi_neumann_cells == 0


def test_scheme_b_neumann_facets_follow_their_cell():
    mesh = _square(DiagonalType.crossed)
    geom = _geometry(mesh)
    rec = compute_reconstruction(geom, CellMaterials.uniform(MATERIAL, geom.num_cells), np.empty(0, np.int64), "B")
    d = 2
    u = np.random.default_rng(0).normal(size=(geom.num_cells, d))
    uf = (rec.R @ u.ravel()).reshape(-1, d)
    b = geom.boundary_facets
    assert np.array_equal(rec.neumann_facets, b)
    assert np.allclose(uf[b], u[geom.facet_cells[b, 0]], rtol=0, atol=1e-15)


def test_scheme_a_neumann_facets_are_traction_free():
    """Scheme A, eq. (19): the reconstructed u_f makes sigma_c n_f = 0 on each Neumann facet of a
    cell with one Neumann facet, for any cell values."""
    mesh = _square(DiagonalType.crossed)
    geom = _geometry(mesh)
    rec = compute_reconstruction(geom, CellMaterials.uniform(MATERIAL, geom.num_cells), np.empty(0, np.int64), "A")
    d = 2
    u = np.random.default_rng(1).normal(size=(geom.num_cells, d))
    uf = (rec.R @ u.ravel()).reshape(-1, d)
    C = MATERIAL.elasticity_tensor(d)
    for f in rec.neumann_facets:
        c, k = geom.facet_cells[f, 0], geom.facet_local[f, 0]
        G = np.einsum("ki,kj->ij", uf[geom.cell_facets[c]], geom.facet_area_normals[c]) / geom.cell_volumes[c]
        sigma = np.einsum("ijkl,kl->ij", C, G)
        n = geom.facet_area_normals[c, k] / geom.facet_areas[f]
        assert np.abs(sigma @ n).max() < 1e-11 * np.abs(sigma).max()


def _stencil_keys(geom, stencils, decimals=10):
    """{facet barycentre: sorted tuple of the barycentres of its stencil cells}."""
    out = {}
    for f, cells in zip(stencils.facets, stencils.cells):
        key = tuple(np.round(geom.facet_centres[f], decimals))
        out[key] = tuple(sorted(tuple(np.round(x, decimals)) for x in geom.cell_centres[cells]))
    return out


def _permuted(geom, rng):
    """The same geometry with cells, facets and each cell's vertices renumbered."""
    N, F, d = geom.num_cells, geom.num_facets, geom.d
    cperm, fperm = rng.permutation(N), rng.permutation(F)
    vperm = np.array([rng.permutation(d + 1) for _ in range(N)])
    vertices = np.take_along_axis(geom.cell_vertices[cperm], vperm[:, :, None], axis=1)
    renumber = rng.permutation(geom.cell_vertex_ids.max() + 1)
    vertex_ids = renumber[np.take_along_axis(geom.cell_vertex_ids[cperm], vperm, axis=1)]
    new_facet = np.empty(F, dtype=np.int64)
    new_facet[fperm] = np.arange(F)
    cell_facets = new_facet[np.take_along_axis(geom.cell_facets[cperm], vperm, axis=1)]
    return geometry_from_arrays(vertices, vertex_ids, cell_facets)


@pytest.mark.parametrize("kind", ["graded", "box", "square", "cube"])
def test_stencils_independent_of_numbering(kind):
    """Renumbering cells, facets and vertices changes no stencil. The structured cube has exact
    ties (mirror-image simplices with the same centroid, e.g. at the facet (7/9, 2/9, 2/9)); a
    tie-break on round-off or on a linear form of the centroid fails here."""
    if kind == "square":
        mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 6, 6)
    elif kind == "cube":
        mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 3)
    else:
        mesh = gmsh_mesh(MPI.COMM_SELF, kind, 0.3)
    geom = _geometry(mesh)
    ref = _stencil_keys(geom, compute_interior_stencils(geom))
    perm = _permuted(geom, np.random.default_rng(3))
    assert _stencil_keys(perm, compute_interior_stencils(perm)) == ref


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["disc", "box", "cube", "anisotropic", "two-bodies"])
def test_stencils_equal_serial_and_parallel(kind):
    """Stencils built from the gathered geometry of the distributed mesh select the same cells
    (keyed by barycentres) as a serial run on the same mesh."""
    comm = MPI.COMM_WORLD
    if kind == "cube":
        par = dolfinx.mesh.create_unit_cube(comm, 3, 3, 3)
        ser = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 3)
    elif kind == "anisotropic":
        par, ser = (dolfinx.mesh.create_unit_square(c, 3, 30, diagonal=DiagonalType.crossed)
                    for c in (comm, MPI.COMM_SELF))
    elif kind == "two-bodies":
        par, ser = _gmsh_squares(comm, 1e-3), _gmsh_squares(MPI.COMM_SELF, 1e-3)
    else:
        h = 0.2 if kind == "disc" else 0.3
        par, ser = gmsh_mesh(comm, kind, h), gmsh_mesh(MPI.COMM_SELF, kind, h)
    gp, gs = _geometry(par), _geometry(ser)
    # A process computes the stencils of the facets of its cells in halo layers 0 and 1.
    rows = gp.facets_of_layers(1)
    sp, ss = compute_interior_stencils(gp, rows), compute_interior_stencils(gs)
    kp, ks = _stencil_keys(gp, sp), _stencil_keys(gs, ss)
    assert {k: ks[k] for k in kp} == kp
    covered = set().union(*comm.allgather(set(kp)))
    assert covered == set(ks)
    # and the same facets are extrapolated
    key = lambda g, f: {tuple(np.round(x, 10)) for x in g.facet_centres[f]}  # noqa: E731
    assert key(gp, sp.extrapolated) == key(gs, ss.extrapolated) & set(kp)
    # R reconstructs an affine field (x) exactly on those facets.
    rec = compute_reconstruction(gp, CellMaterials.uniform(MATERIAL, gp.num_cells), gp.boundary_facets, "A", rows)
    uf = (rec.R @ gp.cell_centres.ravel() + rec.D @ gp.facet_centres[rec.dirichlet_facets].ravel())
    assert np.allclose(uf.reshape(-1, gp.d)[rows], gp.facet_centres[rows], atol=1e-12)


# --- Stencils follow the mesh graph (issue: no silent wrong results) ---------------------------


def _structured_squares(comm, gap, n=10, size=0.2, diagonal="crossed"):
    """Two size x size squares side by side along x, ``gap`` apart, each a structured n x n grid
    (4 triangles per square with a centre vertex if ``diagonal == "crossed"``, else 2)."""
    xs = np.linspace(0.0, size, n + 1)
    grid = np.stack(np.meshgrid(xs, xs, indexing="ij"), axis=-1).reshape(-1, 2)
    centres = (grid.reshape(n + 1, n + 1, 2)[:-1, :-1] + size / (2 * n)).reshape(-1, 2)
    index = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = index[:-1, :-1].ravel(), index[1:, :-1].ravel()
    c, e = index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    if diagonal == "crossed":
        m = len(grid) + np.arange(n * n)
        cells = np.concatenate([np.stack(t, axis=1) for t in ((a, b, m), (b, c, m), (c, e, m), (e, a, m))])
        points = np.concatenate([grid, centres])
    else:
        cells = np.concatenate([np.stack((a, b, c), axis=1), np.stack((a, c, e), axis=1)])
        points = grid
    x = np.concatenate([points, points + [size + gap, 0.0]])
    cells = np.concatenate([cells, cells + len(points)])
    if comm.rank != 0:
        x, cells = np.zeros((0, 2)), np.zeros((0, 3), dtype=np.int64)
    return _compat.create_simplex_mesh(comm, x, cells)


def _gmsh_squares(comm, gap, h=0.02):
    """Two 0.2 x 0.2 squares meshed separately (unstructured, size h), ``gap`` apart along x."""
    import gmsh

    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        for k, x0 in enumerate((0.0, 0.2 + gap)):
            s = gmsh.model.occ.addRectangle(x0, 0.0, 0.0, 0.2, 0.2)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(2, [s], k + 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(2)
    try:
        return _compat.mesh_from_gmsh_model(gmsh.model, comm, 2)[0]
    finally:
        if comm.rank == 0:
            gmsh.finalize()


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["structured", "unstructured"])
def test_separate_bodies_are_not_coupled(kind):
    """Two bodies 1e-3 m apart (mesh size 0.02 m): no stencil uses a cell of the other body, the
    stiffness has no entry between them, and turning one body rigidly along the other costs no
    energy. (Stencils from the nearest barycentres coupled them: |K| = 4.6 and 7.5 summed over
    280 and 248 entries between the bodies, structured and unstructured.)"""
    comm = MPI.COMM_WORLD
    mesh = _structured_squares(comm, 1e-3) if kind == "structured" else _gmsh_squares(comm, 1e-3)
    dem = DEMDiscretisation(mesh, MATERIAL, "A")
    geom = dem.geometry
    body = geom.cell_bodies  # of the held cells (a process may hold cells of one body only)
    assert comm.allreduce(int(body.max()), op=MPI.MAX) == 1
    assert np.array_equal(body, (geom.cell_centres[:, 0] > 0.2).astype(int))
    R = dem.reconstruction.R.tocoo()  # facet dof f*2 + i reads cell dofs c*2 + i of its stencil
    assert len(R.row) and np.all(body[R.col // 2] == body[geom.facet_cells[R.row // 2, 0]])
    # No stiffness entry couples the bodies (rows: the owned dofs of K; the bodies of the
    # column dofs come from their owners by a scatter).
    K = dem.K
    start, stop = K.getOwnershipRange()
    ai, aj, av = K.getValuesCSR()
    rows = np.repeat(np.arange(start, stop), np.diff(ai))
    labels = dem.create_vector()
    labels.array[:] = np.repeat(body[: dem.n_owned], 2)
    columns = np.unique(aj)
    body_of_column = PatchScatter(labels, columns).gather(labels)
    cross = labels.array[rows - start] != body_of_column[np.searchsorted(columns, aj)]
    assert comm.allreduce(int(np.count_nonzero(av[cross])), op=MPI.SUM) == 0
    # Body 1 turns rigidly (a linearised rotation by 0.05 about its centre; its facets slide
    # along the gap): zero elastic and stabilisation energy. A pure translation would not do:
    # each free body's mean translation is subtracted before the operators act.
    u = dem.create_vector()
    x = geom.cell_centres[: dem.n_owned] - [0.3 + 1e-3, 0.1]
    u.array.reshape(-1, 2)[:] = np.where(body[: dem.n_owned, None] == 1, 0.05 * np.stack([-x[:, 1], x[:, 0]], 1), 0.0)
    e = dem.energies(u, 0.0)
    assert abs(e["elastic"]) + abs(e["stabilisation"]) < 1e-14 * MATERIAL.E * 0.05**2 * 0.04


def _slot_mesh(comm, h, width):
    """A 0.3 x 0.2 block with a vertical slot of the given width from y = 0.05 to the top."""
    import gmsh

    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        outer = gmsh.model.occ.addRectangle(0.0, 0.0, 0.0, 0.3, 0.2)
        slot = gmsh.model.occ.addRectangle(0.15 - width / 2, 0.05, 0.0, width, 0.2)
        body, _ = gmsh.model.occ.cut([(2, outer)], [(2, slot)])
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [body[0][1]], 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(2)
    try:
        return _compat.mesh_from_gmsh_model(gmsh.model, comm, 2)[0]
    finally:
        if comm.rank == 0:
            gmsh.finalize()


def _segments_enter_box(p, q, lo, hi):
    """Whether each segment p -> q (n, 2) passes through the open box (lo, hi) (Liang-Barsky)."""
    t0, t1 = np.zeros(len(p)), np.ones(len(p))
    dp = q - p
    for i in range(2):
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = (lo[i] - p[:, i]) / dp[:, i], (hi[i] - p[:, i]) / dp[:, i]
        inside = (p[:, i] > lo[i]) & (p[:, i] < hi[i])
        parallel = dp[:, i] == 0
        t0 = np.maximum(t0, np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(a, b)))
        t1 = np.minimum(t1, np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(a, b)))
    return t0 < t1 - 1e-12


@pytest.mark.parametrize("width", [0.01, 0.002, 0.001], ids=["h/2", "h/10", "h/20"])
def test_no_stencil_crosses_a_slot(width):
    """The interpolation of eq. (7) never reaches across a slot in one body: no segment from a
    facet barycentre to one of its stencil barycentres enters the slot. (Nearest barycentres:
    2, 5 and 5 such stencils for the three widths, mesh size h = 0.02 m.)"""
    mesh = _slot_mesh(MPI.COMM_SELF, 0.02, width)
    geom = _geometry(mesh)
    st = compute_interior_stencils(geom)
    xf = np.repeat(geom.facet_centres[st.facets], 3, axis=0)
    xc = geom.cell_centres[st.cells].reshape(-1, 2)
    slot = np.array([0.15 - width / 2, 0.05]), np.array([0.15 + width / 2, 0.3])
    assert not _segments_enter_box(xf, xc, *slot).any()
    # the check itself finds a segment across the slot
    assert _segments_enter_box(np.array([[0.1, 0.1]]), np.array([[0.2, 0.1]]), *slot).all()


def test_stencils_stay_in_a_two_ring_neighbourhood():
    """Every stencil cell shares a vertex with the facet or with a cell that does: a stencil is
    computable from a bounded halo of cells (graph distance <= 2 through shared vertices)."""
    for mesh in (gmsh_mesh(MPI.COMM_SELF, "graded", 0.15), dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 3)):
        geom = _geometry(mesh)
        st = compute_interior_stencils(geom)
        d = geom.d
        ids = geom.cell_vertex_ids
        c, j = geom.facet_cells[st.facets, 0], geom.facet_local[st.facets, 0]
        facet_vertices = [set(np.delete(ids[ci], ji)) for ci, ji in zip(c, j)]
        vertex_cells = {}
        for cell, vs in enumerate(ids):
            for v in vs:
                vertex_cells.setdefault(v, set()).add(cell)
        for fv, cells in zip(facet_vertices, st.cells):
            ring1 = set().union(*(vertex_cells[v] for v in fv))
            ring2 = set().union(*(vertex_cells[v] for cell in ring1 for v in ids[cell]))
            assert set(cells) <= ring2
        assert len(st.cells) == len(geom.interior_facets) and d in (2, 3)


@pytest.mark.mpi
@pytest.mark.parametrize("n, diagonal", [((3, 30), "crossed"), ((3, 60), "crossed"), ((60, 3), "crossed"),
                                         ((3, 60), "right"), ((3, 60), "left"), ((2, 40), "right_left")])
def test_anisotropic_meshes_pass_the_patch_test(n, diagonal):
    """Cells of aspect ratio 10 and 20 set up (the nearest-barycentre stencils failed on the
    crossed [3, 30] square: "no simplex ... 81 facets"), and an affine displacement with its
    Dirichlet data on the whole boundary gives the exact uniform stress and no jump."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, *n, diagonal=getattr(DiagonalType, diagonal))
    A = np.array([[0.3, -1.2], [2.0, 0.1]])
    b = np.array([0.2, -0.3])
    boundary = meshes.exterior_facets(mesh)
    dem = DEMDiscretisation(mesh, MATERIAL, "A", [DirichletBC(boundary, lambda x, t: A @ x + b[:, None])])
    u = dem.create_vector()
    xc = dem.geometry.cell_centres[: dem.n_owned]
    u.array[:] = (xc @ A.T + b).ravel()
    sigma = dem.stress(u, 0.0)
    exact = MATERIAL.stress(A[None])[0]
    assert np.abs(sigma - exact).max() < 1e-11 * np.abs(exact).max()
    e = dem.energies(u, 0.0)
    assert e["stabilisation"] < 1e-22
    force = dem.force(u, 0.0, dem.create_vector())
    assert force.norm(PETSc.NormType.NORM_INFINITY) < 1e-11 * np.abs(exact).max()
