"""Input checks and helpers shared by the DOLFINx FEM references of this package (fem/)."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError


def check_positive(name: str, value) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise InputError(f"{name} must be finite and > 0, got {value!r}")
    return value


def check_elastic(E, nu) -> tuple[float, float]:
    E = check_positive("E (Young's modulus)", E)
    nu = float(nu)
    if not (-1.0 < nu < 0.5):
        raise InputError(f"nu (Poisson's ratio) must satisfy -1 < nu < 0.5, got {nu!r}")
    return E, nu


def check_degree(degree) -> int:
    is_int = isinstance(degree, (int, np.integer)) and not isinstance(degree, bool)
    if not is_int or degree not in (1, 2):
        raise InputError(f"degree must be 1 or 2 (Lagrange), got {degree!r}")
    return int(degree)


def check_int(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def lame(E: float, nu: float, plane_stress: bool = False, gdim: int = 3) -> tuple[float, float]:
    """Lame parameters (lambda, mu) in Pa: 3D, and plane strain in 2D; plane stress uses the
    reduced lambda in 2D."""
    mu = E / (2.0 * (1.0 + nu))
    lmbda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    if gdim == 2 and plane_stress:
        lmbda = 2.0 * lmbda * mu / (lmbda + 2.0 * mu)
    return lmbda, mu


def global_min(comm, values: np.ndarray) -> float:
    local = float(np.min(values)) if values.size > 0 else np.inf
    return comm.allreduce(local, op=MPI.MIN)


def owned_facets(mesh, facets: np.ndarray) -> np.ndarray:
    return facets[facets < mesh.topology.index_map(mesh.topology.dim - 1).size_local]


def gather_sorted(comm, *arrays):
    gathered = [np.concatenate(comm.allgather(a)) for a in arrays]
    order = np.argsort(gathered[0], kind="stable")
    return [a[order] for a in gathered]


def evaluate_at_points(function, points: npt.ArrayLike) -> np.ndarray:
    """Values of a (vector) Function at points, gathered on every rank (collective).

    Args:
        function: A DOLFINx Function on a mesh with geometric dimension gdim.
        points: Shape (n, gdim) (or (gdim,) for one point).

    Returns:
        Shape (n, value_size); each value comes from the lowest rank that holds the point.
    """
    mesh = function.function_space.mesh
    comm = mesh.comm
    gdim = mesh.geometry.dim
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 1 and pts.shape[0] == gdim:
        pts = pts[None, :]
    if pts.ndim != 2 or pts.shape[1] != gdim:
        raise InputError(f"points must have shape (n, {gdim}), got {np.shape(points)}")
    n = pts.shape[0]
    x = np.zeros((n, 3), dtype=np.float64)
    x[:, :gdim] = pts

    cells = _compat.colliding_cells(mesh, x)
    found = cells >= 0
    owner = np.where(found, comm.rank, comm.size).astype(np.int32)
    comm.Allreduce(MPI.IN_PLACE, owner, op=MPI.MIN)
    if np.any(owner == comm.size):
        missing = pts[owner == comm.size]
        raise InputError(f"points outside the mesh: {missing.tolist()}")

    value_size = function.function_space.dofmap.index_map_bs
    values = np.zeros((n, value_size), dtype=np.float64)
    mine = owner == comm.rank
    if np.any(mine):
        values[mine] = np.real(function.eval(x[mine], cells[mine])).reshape(-1, value_size)
    comm.Allreduce(MPI.IN_PLACE, values, op=MPI.SUM)
    return values


# --- eigenfrequencies ---------------------------------------------------------------------------


SIMPLICES = (
    dolfinx.mesh.CellType.interval,
    dolfinx.mesh.CellType.triangle,
    dolfinx.mesh.CellType.tetrahedron,
)


# --- validation ---------------------------------------------------------------------------------


def check_simplex_mesh(mesh) -> None:
    if mesh.topology.cell_type not in SIMPLICES:
        raise InputError(f"mesh must be a simplex mesh, got cell type {mesh.topology.cell_type}")
    if mesh.geometry.dim != mesh.topology.dim:
        raise InputError(
            f"mesh must have geometric dimension equal to its topological dimension, got "
            f"gdim={mesh.geometry.dim}, tdim={mesh.topology.dim}"
        )


def check_material(E, nu, rho) -> tuple[float, float, float]:
    E, nu = check_elastic(E, nu)
    return E, nu, check_positive("rho (density)", rho)


def check_facets(mesh, clamped_facets) -> np.ndarray:
    facets = np.asarray(clamped_facets)
    if facets.ndim != 1 or (facets.size > 0 and not np.issubdtype(facets.dtype, np.integer)):
        raise InputError("clamped_facets must be a 1D array of process-local facet indices")
    fdim = mesh.topology.dim - 1
    mesh.topology.create_entities(fdim)
    imap = mesh.topology.index_map(fdim)
    num_facets = imap.size_local + imap.num_ghosts
    if facets.size > 0 and (facets.min() < 0 or facets.max() >= num_facets):
        raise InputError(
            f"clamped_facets must be process-local facet indices in [0, {num_facets}), got "
            f"values in [{facets.min()}, {facets.max()}]"
        )
    return facets.astype(np.int32)


def stiffness_and_mass(V, E: float, nu: float, rho: float, plane_stress: bool):
    """UFL bilinear forms of the stiffness K (N/m) and the consistent mass M (kg)."""
    gdim = V.mesh.geometry.dim
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)

    def eps(z):
        return ufl.sym(ufl.grad(z))

    if gdim == 1:
        sigma = E * eps(u)
    else:
        lmbda, mu = lame(E, nu, plane_stress, gdim)
        sigma = lmbda * ufl.tr(eps(u)) * ufl.Identity(gdim) + 2.0 * mu * eps(u)
    k = ufl.inner(sigma, eps(w)) * ufl.dx
    m = rho * ufl.inner(u, w) * ufl.dx
    return k, m


def clamped_bc(V, facets: np.ndarray):
    mesh = V.mesh
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
    zero = np.zeros(mesh.geometry.dim, dtype=PETSc.ScalarType)
    return dolfinx.fem.dirichletbc(zero, dofs, V)


def configure_lu(ksp: PETSc.KSP) -> None:
    """Direct solve: one LU factorization (MUMPS if PETSc has it; needed in parallel)."""
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.LU)
    if PETSc.Sys.hasExternalPackage("mumps"):
        pc.setFactorSolverType("mumps")


def lu_solver(comm: MPI.Comm, A: PETSc.Mat) -> PETSc.KSP:
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(A)
    configure_lu(ksp)
    ksp.setUp()
    return ksp


# --- time integration ---------------------------------------------------------------------------


def facet_nodes(V, facets: np.ndarray) -> np.ndarray:
    """The P1 nodes (blocks) of process-local facets, (n, tdim): a cell's P1 dofs follow the
    order of its vertices (the topology's cell-vertex list), and a facet of a 1D mesh is a vertex.
    Local (not collective, unlike ``locate_dofs_topological``)."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    c2v = mesh.topology.connectivity(tdim, 0).array
    node_of_vertex = np.empty(c2v.max(initial=-1) + 1, dtype=np.int32)
    node_of_vertex[c2v] = _compat.cell_dofs(V)
    if tdim == 1:
        return node_of_vertex[np.asarray(facets)].reshape(-1, 1)
    mesh.topology.create_connectivity(tdim - 1, 0)
    f2v = mesh.topology.connectivity(tdim - 1, 0).array.reshape(-1, tdim)
    return node_of_vertex[f2v[np.asarray(facets)]]


def node_coordinates(V) -> np.ndarray:
    """Coordinates (n_nodes_local, gdim) of the nodes (blocks) of a vector P1 space on an affine mesh:
    a cell's P1 dofs and its geometry nodes follow the same reference vertex order."""
    mesh = V.mesh
    n = mesh.topology.dim + 1
    x = np.empty((V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts, mesh.geometry.dim))
    nodes = _compat.cell_geometry_nodes(mesh)
    x[_compat.cell_dofs(V).reshape(-1, n)] = mesh.geometry.x[nodes, : mesh.geometry.dim]
    return x
