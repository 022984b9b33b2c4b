"""DEM gradient, energies and stiffness (paper §3.2-3.4): patch tests, rigid motions, spectrum of K."""

import dolfinx.mesh
import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
from dolfinx.mesh import DiagonalType
from helpers import cell_vector, gmsh_mesh, owned_centres
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial

MATERIAL = ElasticMaterial(E=3.0, nu=0.3, rho=1.0)


def gmsh_disc(comm, h=0.2):
    """Unstructured unit disc (about 250 triangles for h = 0.2)."""

    def build(gmsh):
        s = gmsh.model.occ.addDisk(0.0, 0.0, 0.0, 1.0, 1.0)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [s], 1)
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(2)

    return gmsh_mesh(comm, build)


def global_max(comm, a):
    return comm.allreduce(float(np.max(np.abs(a))) if np.size(a) else 0.0, op=MPI.MAX)


def dense_K(dem):
    ai, aj, av = dem.K.getValuesCSR()
    return scipy.sparse.csr_matrix((av, aj, ai), shape=dem.K.getSize()).toarray()


# --- patch tests --------------------------------------------------------------------------------


def _patch_mesh(d, comm):
    if d == 1:
        return dolfinx.mesh.create_interval(comm, 11, [-0.3, 1.2])
    if d == 2:
        return gmsh_disc(comm)
    return dolfinx.mesh.create_unit_cube(comm, 3, 3, 3)  # has extrapolated interior facets


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("d", [1, 2, 3])
def test_affine_patch_test(d, scheme):
    """u = A x + b on the cells and (Dirichlet) on the whole boundary: G_c = A exactly, constant
    stress, zero force, E_P = |Omega|/2 sigma:eps and E_S = 0."""
    comm = MPI.COMM_WORLD
    mesh = _patch_mesh(d, comm)
    rng = np.random.default_rng(7)
    A = rng.uniform(-1, 1, size=(d, d))
    b = rng.uniform(-1, 1, size=d)
    bc = DirichletBC(meshes.exterior_facets(mesh), lambda x, t: A @ x + b[:, None])
    dem = DEMDiscretisation(mesh, MATERIAL, scheme=scheme, dirichlet=[bc])
    u = cell_vector(dem, lambda x: x @ A.T + b)
    G = dem.gradient(u, 0.0)
    assert global_max(comm, G - A) < 1e-12
    sigma = MATERIAL.stress(A)
    assert global_max(comm, dem.stress(u, 0.0) - sigma) < 1e-11
    F, F0 = dem.create_vector(), dem.create_vector()
    dem.force(u, 0.0, F)
    dem.force(dem.create_vector(), 0.0, F0)  # the lifting alone sets the scale of K u
    assert F0.norm(3) > 0.1
    assert F.norm(3) < 1e-12 * F0.norm(3)
    e = dem.energies(u, 0.0)
    volume = comm.allreduce(dem.geometry.cell_volumes[: dem.n_owned].sum())
    eps = 0.5 * (A + A.T)
    assert e["elastic"] == pytest.approx(0.5 * volume * np.sum(sigma * eps), rel=1e-12)
    assert e["stabilisation"] < 1e-25 * e["elastic"]


def _uniaxial_setup(scheme, comm, s=0.02):
    """[0,2]x[0,1], crossed: u_x = s/E' x, u_y = -nu' s/E' y on x = 0 and x = 2, free top/bottom."""
    mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [8, 4], diagonal=DiagonalType.crossed)
    E, nu = MATERIAL.E, MATERIAL.nu
    Ep, nup = E / (1 - nu**2), nu / (1 - nu)  # plane strain
    A = np.array([[s / Ep, 0.0], [0.0, -nup * s / Ep]])
    ends = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 2.0))
    bc = DirichletBC(ends, lambda x, t: A @ x)
    dem = DEMDiscretisation(mesh, MATERIAL, scheme=scheme, dirichlet=[bc])
    return dem, A, cell_vector(dem, lambda x: x @ A.T)


@pytest.mark.mpi
def test_uniaxial_tension_scheme_a_exact():
    comm = MPI.COMM_WORLD
    s = 0.02
    dem, A, u = _uniaxial_setup("A", comm, s)
    assert dem.num_multi_neumann_cells == 0
    assert global_max(comm, dem.gradient(u, 0.0) - A) < 1e-10 * np.abs(A).max()
    sigma = dem.stress(u, 0.0)
    assert global_max(comm, sigma - np.diag([s, 0.0])) < 1e-10 * s
    F, F0 = dem.create_vector(), dem.create_vector()
    dem.force(u, 0.0, F)
    dem.force(dem.create_vector(), 0.0, F0)
    assert F.norm(3) < 1e-12 * F0.norm(3)
    e = dem.energies(u, 0.0)
    Ep = MATERIAL.E / (1 - MATERIAL.nu**2)
    assert e["elastic"] == pytest.approx(0.5 * 2.0 * s**2 / Ep, rel=1e-10)
    assert e["stabilisation"] < 1e-20 * e["elastic"]


@pytest.mark.mpi
def test_uniaxial_tension_scheme_b_not_exact():
    """Scheme B (u_f = u_c on Neumann facets) misses the lateral contraction: not a patch test."""
    comm = MPI.COMM_WORLD
    dem, A, u = _uniaxial_setup("B", comm)
    error = global_max(comm, dem.gradient(u, 0.0) - A) / np.abs(A).max()
    assert error > 1e-3
    F, F0 = dem.create_vector(), dem.create_vector()
    dem.force(u, 0.0, F)
    dem.force(dem.create_vector(), 0.0, F0)
    assert F.norm(3) > 1e-3 * F0.norm(3)  # out of equilibrium


# --- rigid motions and the kernel of K ---------------------------------------------------------


def _free_energy(dem, field):
    e = dem.energies(cell_vector(dem, field), 0.0)
    return e["elastic"] + e["stabilisation"]


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("mesh_kind", ["crossed", "disc", "cube"])
def test_rigid_motions(scheme, mesh_kind):
    comm = MPI.COMM_WORLD
    if mesh_kind == "crossed":
        mesh = dolfinx.mesh.create_unit_square(comm, 4, 4, diagonal=DiagonalType.crossed)
    elif mesh_kind == "disc":
        mesh = gmsh_disc(comm, 0.3)
    else:
        mesh = dolfinx.mesh.create_unit_cube(comm, 2, 2, 2)
    dem = DEMDiscretisation(mesh, MATERIAL, scheme=scheme)
    d = dem.d
    rng = np.random.default_rng(11)
    reference = _free_energy(dem, lambda x: np.sin(3 * x + 1.0))  # a generic field of size ~1
    assert reference > 1e-2
    t = rng.normal(size=d)
    assert _free_energy(dem, lambda x: np.broadcast_to(t, x.shape)) < 1e-26 * reference
    W = rng.normal(size=(d, d))
    W = W - W.T  # infinitesimal rotation
    rotation = _free_energy(dem, lambda x: x @ W.T) / reference
    multi = dem.num_multi_neumann_cells
    if scheme == "A" and multi == 0:
        # eq. (19) is solved exactly by the rotation, whose stress vanishes
        assert rotation < 1e-26
    else:
        # scheme B (and the scheme-B fallback at multi-Neumann cells) strains a rotation
        assert rotation > 1e-4
    if mesh_kind == "cube" and scheme == "A":
        assert multi > 0  # the cube's corners


@pytest.mark.parametrize(
    "mesh_kind, scheme, zeros",
    [
        ("interval", "A", 1),
        ("interval", "B", 1),
        ("crossed", "A", 3),  # 2 translations + the rotation
        ("crossed", "B", 2),  # the rotation is strained by scheme B
        ("right", "A", 2),  # the two multi-Neumann corners fall back to scheme B
        ("right", "B", 2),
        ("cube", "A", 3),  # 12 multi-Neumann cells: rotations are not free
        ("cube", "B", 3),
    ],
)
def test_stiffness_spectrum_free_body(mesh_kind, scheme, zeros):
    """K = S^T S + J^T J: symmetric, positive semi-definite, kernel = the measured rigid modes."""
    comm = MPI.COMM_SELF
    mesh = {
        "interval": lambda: dolfinx.mesh.create_interval(comm, 12, [0.0, 1.0]),
        "crossed": lambda: dolfinx.mesh.create_unit_square(comm, 4, 4, diagonal=DiagonalType.crossed),
        "right": lambda: dolfinx.mesh.create_unit_square(comm, 4, 4, diagonal=DiagonalType.right),
        "cube": lambda: dolfinx.mesh.create_unit_cube(comm, 2, 2, 2),
    }[mesh_kind]()
    dem = DEMDiscretisation(mesh, MATERIAL, scheme=scheme)
    K = dense_K(dem)
    assert np.abs(K - K.T).max() <= 1e-14 * np.abs(K).max()
    ev, vec = scipy.linalg.eigh(K)
    assert ev[0] >= -1e-10 * ev[-1]
    assert np.sum(ev < 1e-10 * ev[-1]) == zeros
    assert ev[zeros] > 1e-5 * ev[-1]  # a clear gap above the kernel
    # The translations are in the kernel (K t = 0 for every constant field).
    d = dem.d
    for i in range(d):
        t = np.zeros((dem.geometry.num_cells_global, d))
        t[:, i] = 1.0
        assert np.abs(K @ t.ravel()).max() < 1e-12 * ev[-1]


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
def test_stiffness_symmetric_and_parallel_equals_serial(scheme):
    """K is symmetric in PETSc, and the distributed operators give the serial energies and
    forces (same mesh built on COMM_SELF), up to the cell numbering."""

    def setup(comm):
        mesh = gmsh_disc(comm, 0.25)
        left = meshes.locate_boundary_facets(mesh, lambda x: x[0] < -0.5)
        bc = DirichletBC(left, lambda x, t: np.stack([0.1 * x[1], 0.05 + 0 * x[0]]))
        dem = DEMDiscretisation(mesh, MATERIAL, scheme=scheme, dirichlet=[bc], body_force=[0.3, -1.0])
        u = cell_vector(dem, lambda x: np.stack([np.sin(2 * x[:, 1]), x[:, 0] ** 2], axis=1))
        F = dem.create_vector()
        dem.force(u, 0.0, F)
        # force per cell keyed by barycentre, gathered
        rows = np.column_stack([owned_centres(dem), F.array.reshape(-1, 2)])
        rows = np.concatenate(comm.allgather(rows))
        return dem, dem.energies(u, 0.0), rows[np.lexsort(np.round(rows[:, :2], 10).T[::-1])]

    dem, e_par, f_par = setup(MPI.COMM_WORLD)
    assert dem.K.isSymmetric(1e-10)
    _, e_ser, f_ser = setup(MPI.COMM_SELF)
    for key in ("elastic", "stabilisation", "external"):
        assert e_par[key] == pytest.approx(e_ser[key], rel=1e-12)
    assert np.allclose(f_par, f_ser, rtol=0, atol=1e-12 * np.abs(f_ser[:, 2:]).max())


@pytest.mark.parametrize("scheme", ["A", "B"])
@pytest.mark.parametrize("d", [1, 2, 3])
def test_stiffness_positive_definite_when_clamped(d, scheme):
    comm = MPI.COMM_SELF
    mesh = {
        1: lambda: dolfinx.mesh.create_interval(comm, 12, [0.0, 1.0]),
        2: lambda: dolfinx.mesh.create_unit_square(comm, 4, 4, diagonal=DiagonalType.right),
        3: lambda: dolfinx.mesh.create_unit_cube(comm, 2, 2, 2),
    }[d]()
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    dem = DEMDiscretisation(mesh, MATERIAL, scheme=scheme, dirichlet=[DirichletBC(left, np.zeros(d))])
    ev = scipy.linalg.eigvalsh(dense_K(dem))
    assert ev[0] > 1e-5 * ev[-1]
