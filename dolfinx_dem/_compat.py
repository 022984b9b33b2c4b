"""The only module that asks which DOLFINx it runs on.

Everything DOLFINx-version dependent (C++ mesh handles, AdjacencyList accessors, function-space
constructors, the PETSc vector of a Function, the cell partitioner and its ghost mode, mesh
creation, gmsh and XDMF adapters, point location) is wrapped here, keyed by ``DOLFINX``, the
(major, minor) of ``dolfinx.__version__``. Tested: 0.5 (Debian 12) and 0.9 (Debian 13); written
for 0.10 and 0.11 from their sources where their API differs (``create_mesh``'s argument order,
``dolfinx.io.gmsh``). Every function returns plain numpy arrays or DOLFINx objects; all data are
process-local.
"""

from __future__ import annotations

import re
from typing import NamedTuple

import dolfinx
import dolfinx.cpp
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.io
import dolfinx.mesh
import numpy as np

from dolfinx_dem.errors import InputError

#: (major, minor) of the DOLFINx release in use
DOLFINX = tuple(int(p) for p in re.match(r"(\d+)\.(\d+)", dolfinx.__version__).groups())
if DOLFINX < (0, 5) or (0, 5) < DOLFINX < (0, 9):
    raise ImportError(f"dolfinx_dem runs on DOLFINx 0.5 and 0.9 or later, not {dolfinx.__version__}")

class LocalMeshData(NamedTuple):
    """Process-local topology and geometry of the owned cells of a simplex mesh.

    Shapes: ``n`` owned cells, ``d`` topological (= geometric) dimension.
    """

    cell_global: np.ndarray  # (n,) global cell indices of the owned cells
    cell_vertex_x: np.ndarray  # (n, d+1, d) vertex coordinates, topology vertex order
    cell_vertex_global: np.ndarray  # (n, d+1) global (topology) vertex indices, same order
    cell_vertex_owner: np.ndarray  # (n, d+1) rank owning each vertex (DOLFINx's vertex index map)
    cell_facet_global: np.ndarray  # (n, d+1) global facet index, facet j opposite vertex j
    num_cells_global: int
    num_facets_global: int


def _cpp(mesh):
    """The C++ mesh behind the Python wrapper (Debian's 0.5 patch names it ``_mesh``)."""
    return getattr(mesh, "_mesh", mesh) if DOLFINX < (0, 9) else mesh._cpp_object


def _adjacency(topology, d0: int, d1: int) -> tuple[np.ndarray, np.ndarray]:
    topology.create_connectivity(d0, d1)
    c = topology.connectivity(d0, d1)
    return c.array, c.offsets


def _vertex_nodes(mesh) -> np.ndarray:
    """The geometry node of each process-local vertex (DOLFINx >= 0.9 needs the vertex-to-cell
    connectivity for it)."""
    tdim = mesh.topology.dim
    if DOLFINX >= (0, 9):
        mesh.topology.create_connectivity(0, tdim)
    num_vertices = mesh.topology.index_map(0).size_local + mesh.topology.index_map(0).num_ghosts
    return dolfinx.cpp.mesh.entities_to_geometry(_cpp(mesh), 0, np.arange(num_vertices, dtype=np.int32),
                                                 False).reshape(-1)


def local_mesh_data(mesh) -> LocalMeshData:
    """Extract the owned cells' vertex coordinates and global facet numbering."""
    topology = mesh.topology
    tdim = topology.dim
    gdim = mesh.geometry.dim
    if gdim != tdim:
        raise InputError(
            f"dolfinx_dem needs a mesh whose geometric dimension equals its topological "
            f"dimension; got tdim={tdim}, gdim={gdim} (manifold meshes are not supported)"
        )
    if mesh.geometry.cmap.degree != 1:
        raise InputError("dolfinx_dem needs an affine (degree-1) mesh geometry")
    cell_map = topology.index_map(tdim)
    n = cell_map.size_local
    nv = tdim + 1

    c2v, off = _adjacency(topology, tdim, 0)
    if not np.all(np.diff(off) == nv):
        raise InputError(f"dolfinx_dem needs a simplex mesh (every cell with {nv} vertices)")
    c2v = c2v.reshape(-1, nv)[:n]
    c2f, _ = _adjacency(topology, tdim, tdim - 1)
    c2f = c2f.reshape(-1, nv)[:n]
    f2v, f2v_off = _adjacency(topology, tdim - 1, 0)
    f2v = f2v.reshape(-1, tdim)

    # Order each cell's facets so that facet j is opposite vertex j (the vertex not in the facet).
    opposite = c2v.sum(axis=1)[:, None] - f2v[c2f].sum(axis=2)  # (n, d+1) local vertex index
    order = np.argmax(opposite[:, None, :] == c2v[:, :, None], axis=2)  # (n, d+1)
    c2f = np.take_along_axis(c2f, order, axis=1)

    v2x = _vertex_nodes(mesh)
    x = mesh.geometry.x[:, :tdim]
    cell_vertex_x = x[v2x[c2v]]

    facet_map = topology.index_map(tdim - 1)
    cell_facet_global = facet_map.local_to_global(c2f.reshape(-1).astype(np.int32)).reshape(n, nv)
    cell_global = cell_map.local_to_global(np.arange(n, dtype=np.int32))
    vertex_map = topology.index_map(0)
    vertex_global = vertex_map.local_to_global(c2v.reshape(-1).astype(np.int32)).reshape(n, nv)
    vertex_owner = np.concatenate([np.full(vertex_map.size_local, mesh.comm.rank), vertex_map.owners])[c2v]
    return LocalMeshData(
        cell_global=np.asarray(cell_global, dtype=np.int64),
        cell_vertex_x=np.ascontiguousarray(cell_vertex_x, dtype=np.float64),
        cell_vertex_global=np.asarray(vertex_global, dtype=np.int64),
        cell_vertex_owner=np.asarray(vertex_owner, dtype=np.int64),
        cell_facet_global=np.asarray(cell_facet_global, dtype=np.int64),
        num_cells_global=cell_map.size_global,
        num_facets_global=facet_map.size_global,
    )


def dg0_cell_dofs(V) -> tuple[np.ndarray, int, int]:
    """Global block index of the DG0 dof of each owned cell, and the owned block range.

    DOLFINx reorders dofs, so cell ``c`` does not carry dof ``c``. dolfinx_dem numbers cells by
    their DG0 dof, so that its PETSc operators share the layout of ``Function.vector``.
    """
    n = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    local = cell_dofs(V)[:n]
    imap = V.dofmap.index_map
    start, stop = imap.local_range
    return np.asarray(imap.local_to_global(local), dtype=np.int64), int(start), int(stop)


def owned_original_cells(V) -> np.ndarray:
    """Index in the input mesh (DOLFINx's original cell index) of each owned cell, in the order
    of the owned DG0 dofs (dolfinx_dem's cell order), shape (n_owned,): the same cell has the
    same index on any number of processes."""
    n = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    out = np.empty(n, dtype=np.int64)
    out[cell_dofs(V)[:n]] = np.asarray(V.mesh.topology.original_cell_index[:n], dtype=np.int64)
    return out


def cell_dofs(V) -> np.ndarray:
    """The (block) dof of each process-local cell in a DG0 space, shape (n_cells_local,)."""
    dofs = V.dofmap.list.array if DOLFINX < (0, 9) else np.asarray(V.dofmap.list).reshape(-1)
    return np.asarray(dofs, dtype=np.int32)


def facet_cell_owners(mesh, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each process-local facet in ``facets`` and each of its process-local cells (one or
    two): (position of the facet in ``facets``, rank owning the cell), as two arrays."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    counts = f2c.offsets[facets + 1] - f2c.offsets[facets]
    which = np.repeat(np.arange(len(facets)), counts)
    cells = f2c.array[np.repeat(f2c.offsets[facets], counts) + np.arange(counts.sum()) -
                      np.repeat(np.cumsum(counts) - counts, counts)]
    cell_map = mesh.topology.index_map(tdim)
    owner = np.concatenate([np.full(cell_map.size_local, mesh.comm.rank), cell_map.owners])[cells]
    return which, np.asarray(owner, dtype=np.int64)


def local_facet_global_indices(mesh, facets: np.ndarray) -> np.ndarray:
    """Global indices of process-local facets."""
    facet_map = mesh.topology.index_map(mesh.topology.dim - 1)
    return np.asarray(facet_map.local_to_global(np.asarray(facets, dtype=np.int32)), dtype=np.int64)


def create_vector_space(mesh, family: str, degree: int):
    """A vector-valued function space (DG0 for DEM cell displacements, P1/P2 for FEM)."""
    if DOLFINX < (0, 9):
        return dolfinx.fem.VectorFunctionSpace(mesh, (family, degree))
    return dolfinx.fem.functionspace(mesh, (family, degree, (mesh.geometry.dim,)))


def create_scalar_space(mesh, family: str, degree: int):
    if DOLFINX < (0, 9):
        return dolfinx.fem.FunctionSpace(mesh, (family, degree))
    return dolfinx.fem.functionspace(mesh, (family, degree))


def petsc_vec(function):
    """The PETSc vector that holds a Function's degrees of freedom (ghosted)."""
    return function.vector if DOLFINX < (0, 9) else function.x.petsc_vec


def mesh_from_gmsh_model(model, comm, gdim: int):
    """(mesh, cell_tags, facet_tags) from a gmsh model held on rank 0, distributed by
    ``partitioner()`` (DOLFINx 0.5's model_to_mesh takes no partitioner: its create_mesh is
    given one for the call)."""
    import functools

    if DOLFINX >= (0, 10):
        data = dolfinx.io.gmsh.model_to_mesh(model, comm, 0, gdim=gdim, partitioner=partitioner())
        return data.mesh, data.cell_tags, data.facet_tags
    if DOLFINX >= (0, 9):
        return dolfinx.io.gmshio.model_to_mesh(model, comm, 0, gdim=gdim, partitioner=partitioner())
    gmshio = dolfinx.io.gmshio
    default = gmshio.create_mesh
    gmshio.create_mesh = functools.partial(default, partitioner=partitioner())
    try:
        return gmshio.model_to_mesh(model, comm, 0, gdim=gdim)
    finally:
        gmshio.create_mesh = default


def read_xdmf_mesh(xdmf, name: str = "mesh"):
    """The mesh ``name`` of an open ``dolfinx.io.XDMFFile``, distributed by ``partitioner()``,
    ghost mode ``shared_facet`` (XDMFFile.read_mesh of DOLFINx 0.5 with another partitioner)."""
    import ufl

    cell_shape, cell_degree = xdmf.read_cell_type(name)
    cells = xdmf.read_topology_data(name)
    x = xdmf.read_geometry_data(name)
    if DOLFINX >= (0, 9):
        import basix.ufl

        element = basix.ufl.element("Lagrange", cell_shape.name, cell_degree, basix.LagrangeVariant.equispaced,
                                    shape=(x.shape[1],))
        mesh = _create_mesh(xdmf.comm, cells, x, ufl.Mesh(element))
        mesh.name = name
        return mesh
    cell = ufl.Cell(cell_shape.name, geometric_dimension=x.shape[1])
    cmap = dolfinx.cpp.fem.CoordinateElement(cell_shape, cell_degree)
    mesh = dolfinx.cpp.mesh.create_mesh(xdmf.comm(), dolfinx.cpp.graph.AdjacencyList_int64(cells), cmap, x,
                                        dolfinx.mesh.GhostMode.shared_facet, partitioner())
    mesh.name = name
    return dolfinx.mesh.Mesh(mesh, ufl.Mesh(ufl.VectorElement("Lagrange", cell, cell_degree)))


def create_simplex_mesh(comm, x: np.ndarray, cells: np.ndarray):
    """An affine simplex mesh from vertex coordinates ``x`` (n, d) and cells ``cells`` (m, d+1)
    given on rank 0 (other ranks pass empty arrays), distributed by ``partitioner()``, with
    ghost mode ``shared_facet``."""
    import ufl

    d = x.shape[1]
    cells, x = np.asarray(cells, dtype=np.int64), np.asarray(x, dtype=np.float64)
    if DOLFINX >= (0, 9):
        import basix.ufl

        name = {1: "interval", 2: "triangle", 3: "tetrahedron"}[d]
        return _create_mesh(comm, cells, x, ufl.Mesh(basix.ufl.element("Lagrange", name, 1, shape=(d,))))
    cell = {1: ufl.interval, 2: ufl.triangle, 3: ufl.tetrahedron}[d]
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", cell, 1))
    return dolfinx.mesh.create_mesh(comm, cells, x, domain, ghost_mode=dolfinx.mesh.GhostMode.shared_facet,
                                    partitioner=partitioner())


def _create_mesh(comm, cells: np.ndarray, x: np.ndarray, domain):
    """``dolfinx.mesh.create_mesh`` (DOLFINx >= 0.9) with ``partitioner()``: its element and
    coordinates swapped places in 0.10."""
    if DOLFINX >= (0, 10):
        return dolfinx.mesh.create_mesh(comm, cells, domain, x, partitioner())
    return dolfinx.mesh.create_mesh(comm, cells, x, domain, partitioner())


def partitioner():
    """The cell partitioner of every mesh dolfinx_dem makes or reads: deterministic.

    DOLFINx 0.5's default (SCOTCH, the only graph partitioner of Debian's build) returns a
    different partition from call to call (measured: 1 in 8 calls on 2 processes for the same
    80 x 8 rectangle, and every call on one process); the sums of a run then differ in their
    last bits from run to run, and a run resumed from a checkpoint could not continue bit for
    bit. Here the cells' dual graph is gathered on rank 0 (a one-off step of mesh creation, as
    DOLFINx's own built-in meshes are generated on rank 0: 8 bytes per graph edge), numbered by
    the Gibbs-Poole-Stockmeyer ordering (``reorder_gps``, bandwidth-reducing: consecutive cells
    are neighbours), and cut into P consecutive blocks of equal size: slabs across the mesh,
    the same for the same mesh and P. With ghosting (``shared_facet``) a cell is also sent to
    the owners of its facet neighbours: the DEM reads its facet neighbours' cells. From DOLFINx
    0.6 the ghost mode is the partitioner's (and its default is none)."""
    if DOLFINX < (0, 9):
        return dolfinx.cpp.mesh.create_cell_partitioner(_partition_dual_graph)
    return dolfinx.cpp.mesh.create_cell_partitioner(_partition_dual_graph, dolfinx.mesh.GhostMode.shared_facet)


def _partition_dual_graph(comm, nparts: int, graph, ghosting: bool):
    """The graph partition function of ``partitioner``: destinations of the local nodes of the
    distributed dual graph ``graph`` (global node numbers, in rank order)."""
    parts = comm.gather((np.asarray(graph.array), np.asarray(graph.offsets)), root=0)
    split = None
    if comm.rank == 0:
        sizes = np.array([len(o) - 1 for _, o in parts])
        starts = np.cumsum([0] + [len(a) for a, _ in parts[:-1]])
        links = np.concatenate([a for a, _ in parts]).astype(np.int32)
        offsets = np.concatenate([[0]] + [o[1:] + s for (_, o), s in zip(parts, starts)]).astype(np.int32)
        n = int(sizes.sum())
        position = np.asarray(dolfinx.cpp.graph.reorder_gps(dolfinx.cpp.graph.AdjacencyList_int32(links, offsets)))
        owner = (position.astype(np.int64) * nparts // max(n, 1)).astype(np.int32)
        if ghosting:
            # owner first, then the other owners of the facet neighbours, ascending
            node = np.repeat(np.arange(n), np.diff(offsets))
            pairs = np.unique(np.stack([node, owner[links]], axis=1), axis=0)
            pairs = pairs[pairs[:, 1] != owner[pairs[:, 0]]]
            count = 1 + np.bincount(pairs[:, 0], minlength=n)
            dest_offsets = np.concatenate([[0], np.cumsum(count)]).astype(np.int32)
            dest = np.empty(dest_offsets[-1], dtype=np.int32)
            dest[dest_offsets[:-1]] = owner
            slot = dest_offsets[pairs[:, 0]] + 1 + (np.arange(len(pairs)) - np.searchsorted(pairs[:, 0], pairs[:, 0]))
            dest[slot] = pairs[:, 1]
        else:
            dest, dest_offsets = owner, np.arange(n + 1, dtype=np.int32)
        bounds = np.cumsum(np.concatenate([[0], sizes]))
        split = [(dest[dest_offsets[a]:dest_offsets[b]], dest_offsets[a:b + 1] - dest_offsets[a])
                 for a, b in zip(bounds[:-1], bounds[1:])]
    dest, dest_offsets = comm.scatter(split, root=0)
    return dolfinx.cpp.graph.AdjacencyList_int32(np.ascontiguousarray(dest, dtype=np.int32),
                                                 np.ascontiguousarray(dest_offsets, dtype=np.int32))


def meshtags_comm(tags):
    """The communicator of a MeshTags' mesh (from DOLFINx 0.9 a MeshTags holds its topology)."""
    return tags.mesh.comm if DOLFINX < (0, 9) else tags.topology.index_map(tags.dim).comm


def locate_boundary_facets(mesh, marker) -> np.ndarray:
    """Process-local boundary facets whose vertices all satisfy ``marker(x)``, x of shape (3, n)."""
    return dolfinx.mesh.locate_entities_boundary(mesh, mesh.topology.dim - 1, marker)


def exterior_facets(mesh) -> np.ndarray:
    """Process-local indices of the facets on the boundary of the domain."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    return dolfinx.mesh.exterior_facet_indices(mesh.topology)


# --- FEM reference helpers ---


def colliding_cells(mesh, points: np.ndarray) -> np.ndarray:
    """For each point, one process-local (owned or ghost) cell containing it, else -1.

    ``points`` has shape (n, 3); returns an int32 array of shape (n,).
    """
    import dolfinx.geometry

    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    tdim = mesh.topology.dim
    if DOLFINX < (0, 9):
        tree = dolfinx.geometry.BoundingBoxTree(mesh, tdim)
        candidates = dolfinx.geometry.compute_collisions(tree, points)
    else:
        tree = dolfinx.geometry.bb_tree(mesh, tdim)
        candidates = dolfinx.geometry.compute_collisions_points(tree, points)
    colliding = dolfinx.geometry.compute_colliding_cells(mesh, candidates, points)
    cells = np.full(points.shape[0], -1, dtype=np.int32)
    for i in range(points.shape[0]):
        links = colliding.links(i)
        if len(links) > 0:
            cells[i] = links[0]
    return cells


# --- meshes / io helpers ---

# `dolfinx.io` does not import its gmsh submodule; mesh_from_gmsh_model needs it.
if DOLFINX < (0, 10):
    import dolfinx.io.gmshio  # noqa: E402
else:
    import dolfinx.io.gmsh  # noqa: E402


def write_meshtags(xdmf, tags, mesh) -> None:
    """Write the MeshTags ``tags`` of ``mesh`` into the open XDMFFile ``xdmf`` (from DOLFINx 0.9
    with the mesh's geometry)."""
    if DOLFINX < (0, 9):
        xdmf.write_meshtags(tags)
    else:
        xdmf.write_meshtags(tags, mesh.geometry)


def cell_geometry_nodes(mesh) -> np.ndarray:
    """Local geometry node indices (cells, k) of every local cell, owned and ghost."""
    if DOLFINX < (0, 9):
        return mesh.geometry.dofmap.array.reshape(-1, mesh.geometry.cmap.create_dof_layout().num_dofs)
    return np.asarray(mesh.geometry.dofmap)


def owned_cell_nodes(mesh) -> tuple[np.ndarray, np.ndarray]:
    """Geometry nodes of the owned cells: global node indices (n, k) int64, coordinates (n, k, 3).

    ``n`` owned cells with ``k`` geometry nodes each (the vertices of an affine simplex mesh).
    Global node indices are the same on every process, so shared vertices can be matched.
    """
    nodes = cell_geometry_nodes(mesh)[: mesh.topology.index_map(mesh.topology.dim).size_local]
    node_global = mesh.geometry.index_map().local_to_global(nodes.reshape(-1).astype(np.int32))
    return (
        np.asarray(node_global, dtype=np.int64).reshape(nodes.shape),
        np.asarray(mesh.geometry.x[nodes], dtype=np.float64),
    )


def import_pyvista():
    """Import pyvista so that VTK keeps its own C++ template instances; returns the module.

    Debian's DOLFINx 0.5 leaves ``sys.setdlopenflags(RTLD_NOW | RTLD_GLOBAL)`` set, so its
    libraries' std::regex instances (other std::string ABI) interpose VTK's, and VTK aborts with
    std::bad_alloc when it draws a scalar bar. Loading VTK with RTLD_DEEPBIND makes it bind to its
    own. This only helps if pyvista was not imported after DOLFINx elsewhere before. Without an X
    display, VTK renders with EGL (instead of warning that the X connection failed first).
    """
    import os
    import sys

    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    flags = sys.getdlopenflags()
    sys.setdlopenflags(os.RTLD_NOW | os.RTLD_DEEPBIND)
    try:
        import pyvista
        import vtkmodules.vtkRenderingAnnotation  # noqa: F401
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401
    finally:
        sys.setdlopenflags(flags)
    return pyvista


# --- Hertz FEM helpers ---


def create_tensor_space(mesh, family: str, degree: int):
    """A (gdim, gdim) tensor-valued function space, e.g. DG(k) for stresses."""
    if DOLFINX < (0, 9):
        return dolfinx.fem.TensorFunctionSpace(mesh, (family, degree))
    gdim = mesh.geometry.dim
    return dolfinx.fem.functionspace(mesh, (family, degree, (gdim, gdim)))


def interpolation_points(V) -> np.ndarray:
    """The reference points at which V's element interpolates (a method before DOLFINx 0.10)."""
    points = V.element.interpolation_points
    return points() if DOLFINX < (0, 10) else points


def interpolate_expression(function, expr) -> None:
    """Interpolate a UFL expression into ``function`` (exact if it lies in the space)."""
    function.interpolate(dolfinx.fem.Expression(expr, interpolation_points(function.function_space)))


def newton_solver(comm, F, u, J, bcs=()):
    """(NewtonSolver, NonlinearProblem) for the residual form F(u; v) = 0 with Jacobian form J
    and the Dirichlet conditions ``bcs`` (``dolfinx.fem.DirichletBC``).

    The solver's Jacobian matrix is ``solver.A``, its linear solver ``solver.krylov_solver``;
    ``solver.solve(u)`` returns (iterations, converged) and scatters u forward.
    """
    import dolfinx.fem.petsc
    import dolfinx.nls.petsc

    problem = dolfinx.fem.petsc.NonlinearProblem(F, u, bcs=list(bcs), J=J)
    return dolfinx.nls.petsc.NewtonSolver(comm, problem), problem


def facet_cell_and_vertices(mesh, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For boundary facets: their one cell, the facet's vertex and the cell's vertex coordinates.

    Returns cells (n,) int32, facet vertex coordinates (n, tdim, 3) and cell vertex coordinates
    (n, tdim + 1, 3), for an affine simplex mesh; ``facets`` are process-local indices.
    """
    tdim = mesh.topology.dim
    facets = np.asarray(facets, dtype=np.int32)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    mesh.topology.create_connectivity(tdim - 1, 0)
    mesh.topology.create_connectivity(tdim, 0)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    cells = np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)
    v2x = _vertex_nodes(mesh)
    x = mesh.geometry.x
    f2v = mesh.topology.connectivity(tdim - 1, 0)
    c2v = mesh.topology.connectivity(tdim, 0)
    facet_x = np.array([x[v2x[f2v.links(f)]] for f in facets]).reshape(-1, tdim, 3)
    cell_x = np.array([x[v2x[c2v.links(c)]] for c in cells]).reshape(-1, tdim + 1, 3)
    return cells, facet_x, cell_x


def zero_dirichletbc(V, facets: np.ndarray, component=None):
    """u = 0 (``component=None``) or u_component = 0 on the process-local ``facets`` of the vector
    space V (a clamp, or a symmetry plane / roller)."""
    import dolfinx.fem
    from petsc4py import PETSc

    mesh = V.mesh
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    if component is None:
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
        return dolfinx.fem.dirichletbc(np.zeros(mesh.geometry.dim, dtype=PETSc.ScalarType), dofs, V)
    sub = V.sub(int(component))
    dofs = dolfinx.fem.locate_dofs_topological(sub, fdim, facets)
    return dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, sub)
