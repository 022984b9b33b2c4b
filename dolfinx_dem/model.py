"""The model of a scene (scene -> model -> runner -> writers): its mesh and boundaries, the DEM
discretisation with its contact models, the probes, the initial state, and what a time series
records of them (``SERIES_COLUMNS``, ``contact_columns``, ``contact_values``, ``momentum``).

Everything here is built and checked before a run touches its output folder: a missing mesh file,
a quadrilateral mesh, an empty boundary, an obstacle that overlaps the body, contact between 3D
bodies or a probe outside the mesh is an error with the folder left as it was.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem import _compat, meshes, scenes
from dolfinx_dem.conditions import DirichletBC, PrescribedBody, Traction
from dolfinx_dem.contact import HalfSpace, PairContact, RigidContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import InputError, SceneError
from dolfinx_dem.fracture import Fracture
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.problem import DEMProblem

SERIES_COLUMNS = ("t", "kinetic", "elastic", "stabilisation", "external", "pseudo_energy")


def create_mesh(comm: MPI.Comm, spec: Mapping):
    """(mesh, cell_tags, facet_tags, names) from the scene's mesh table (``cell_tags``: None for
    the generated interval, rectangle and box meshes, the body numbers for discs and balls);
    ``names`` maps the boundary names the mesh defines to facet tags: the side names of the
    generated interval, rectangle and box meshes (``scenes.SIDES`` for the mesh's dimension), a
    gmsh file's physical-group names, none for discs, balls and XDMF files."""
    kind = spec["type"]
    required = {
        "interval": ("x0", "x1", "n"),
        "rectangle": ("p0", "p1", "n"),
        "box": ("p0", "p1", "n"),
        "disc": ("centre", "radius", "h"),
        "discs": ("h",),
        "balls": ("h",),
        "file": ("path",),
    }[kind]
    for key in required:
        if key not in spec:
            raise SceneError(f"scene key 'mesh.{key}' is missing for a mesh of type {kind!r}")
    names = {}
    if kind == "interval":
        mesh, cell_tags, tags = meshes.create_interval(comm, spec["n"], spec["x0"], spec["x1"])
    elif kind == "rectangle":
        mesh, cell_tags, tags = meshes.create_rectangle(
            comm, spec["p0"], spec["p1"], spec["n"], spec.get("diagonal", "right")
        )
    elif kind == "box":
        mesh, cell_tags, tags = meshes.create_box(comm, spec["p0"], spec["p1"], spec["n"])
    elif kind == "disc":
        mesh, cell_tags, tags = meshes.create_disc(comm, spec["centre"], spec["radius"], spec["h"])
    elif kind in ("discs", "balls"):
        d = 2 if kind == "discs" else 3
        for a, b in (("frame", "frame_width"), ("refine_point", "refine_h"), ("refine_point", "refine_radius")):
            if (a in spec) != (b in spec):
                raise SceneError(f"scene keys 'mesh.{a}' and 'mesh.{b}' go together")
        frame = (spec["frame"][:d], spec["frame"][d:], spec["frame_width"]) if "frame" in spec else None
        refine = (spec["refine_point"], spec["refine_h"], spec["refine_radius"]) if "refine_point" in spec else None
        create = meshes.create_discs if kind == "discs" else meshes.create_balls
        try:
            blocks = spec.get("rectangles" if kind == "discs" else "boxes", [])
            mesh, cell_tags, tags = create(
                comm, [(c[:d], c[d]) for c in spec.get(kind, [])], spec["h"], frame, spec.get("cut"), refine, blocks
            )
        except ValueError as err:
            raise SceneError(f"scene table 'mesh': {err}") from None
    else:
        mesh, cell_tags, tags, names = meshes.read_mesh_named(comm, spec["path"])
    if kind in ("interval", "rectangle", "box"):
        names = {name: tag for name, tag in scenes.SIDES.items() if tag <= 2 * mesh.topology.dim}
    return mesh, cell_tags, tags, names


def boundary_facets(mesh, tags, names, boundary, key="dirichlet.boundary") -> np.ndarray:
    """Process-local boundary facets of a scene's ``boundary`` entry: "all", a condition on the
    coordinates, an integer facet tag, or a name of ``names`` (see ``create_mesh``)."""
    if boundary == "all":
        return meshes.exterior_facets(mesh)
    if isinstance(boundary, str) and any(op in boundary for op in "<>="):
        # A condition on x, y, z that every vertex of the boundary facet satisfies.
        d = mesh.topology.dim
        facets = meshes.locate_boundary_facets(
            mesh, lambda x: np.asarray(scenes.evaluate_condition(boundary, x[:d], key), dtype=bool)
        )
        if mesh.comm.allreduce(len(facets), op=MPI.SUM) == 0:
            raise SceneError(f"scene key '{key}': boundary condition {boundary!r} selects no facet")
        return facets
    if isinstance(boundary, int):
        tag = boundary
    elif names.get(boundary) is not None:
        tag = names[boundary]
    else:
        what = (
            "ambiguous boundary (it names several facet groups of the mesh file)"
            if boundary in names
            else "unknown boundary"
        )
        known = (
            f"one of this mesh's names: {', '.join(sorted(names))}"
            if names
            else "no name: this mesh defines none (side names belong to the interval, rectangle and box meshes)"
        )
        raise SceneError(
            f"scene key '{key}': {what} {boundary!r} (use 'all', an integer facet tag, a condition "
            f"such as 'y <= 0.2', or {known})"
        )
    if tags is None:
        raise SceneError(f"the mesh has no facet tags, so boundary {boundary!r} cannot be found")
    facets = tags.find(tag)
    if mesh.comm.allreduce(len(facets), op=MPI.SUM) == 0:
        raise SceneError(f"scene key '{key}': boundary {boundary!r} (tag {tag}) has no facet")
    return facets


def build(scene: Mapping, comm: MPI.Comm = MPI.COMM_WORLD) -> DEMProblem:
    """The DEM problem a scene describes: its discretisation and contact models."""
    mesh, cell_tags, tags, names = create_mesh(comm, scene["mesh"])
    scene = scenes.validate(scene, mesh.topology.dim)
    material = scenes.materials(scene)
    d = mesh.topology.dim
    prescribed = [
        PrescribedBody(
            b["tag"],
            b.get("velocity"),
            None
            if "velocity" in b
            else (
                lambda t, e=b["displacement"], key=f"prescribed[{i}].displacement": scenes.evaluate_field(
                    e, np.zeros((d, 1)), t, key
                )[:, 0]
            ),
            b.get("name"),
        )
        for i, b in enumerate(scene.get("prescribed", []))
    ]
    for key in ("materials", "prescribed"):
        if key in scene and cell_tags is None:
            raise SceneError(
                f"scene key '{key}' selects cells by tag, and this mesh has no cell tags (use "
                "a mesh of type 'discs' or a mesh file with cell tags)"
            )
    if isinstance(material, ElasticMaterial) and not prescribed:
        cell_tags = None

    def data(section, i, bc):
        value = bc.get("value", [0.0] * mesh.topology.dim)
        field = (
            (lambda x, t, v=value, key=f"{section}[{i}].value": scenes.evaluate_field(v, x, t, key))
            if isinstance(value[0], str)
            else value
        )
        facets = boundary_facets(mesh, tags, names, bc.get("boundary", "all"), f"{section}[{i}].boundary")
        return facets, field, bc.get("time_dependent", False)

    dirichlet = [
        DirichletBC(*data("dirichlet", i, bc), bc.get("components"), bc.get("name"))
        for i, bc in enumerate(scene.get("dirichlet", []))
    ]
    tractions = [Traction(*data("tractions", i, bc)) for i, bc in enumerate(scene.get("tractions", []))]
    loads = scene.get("loads", {})
    body_force = loads.get("body_force")
    if "gravity" in loads:
        body_force = [material.rho * g for g in loads["gravity"]]  # one material (scenes.materials)
    obstacle_facets = [boundary_facets(mesh, tags, names, ob["boundary"], f"obstacles[{k}].boundary")
                       for k, ob in enumerate(scene.get("obstacles", []))]
    pair_facets = None
    if "contact" in scene:
        pair_facets = np.unique(np.concatenate([boundary_facets(mesh, tags, names, b, f"contact.boundary[{k}]")
                                                for k, b in enumerate(scene["contact"]["boundary"])]))
    # dem-AB: scheme A, but scheme B on the contact candidates
    scheme = scene["method"].split("-")[1]
    candidates = None
    if scheme == "AB":
        scheme = "A"
        candidates = np.unique(np.concatenate([np.empty(0, np.int32), *obstacle_facets,
                                               *([] if pair_facets is None else [pair_facets])])).astype(np.int32)
    dem = DEMDiscretisation(mesh, material, scheme, dirichlet, body_force, tractions, cell_tags, prescribed, candidates)
    contacts = []
    if obstacle_facets:
        contacts.append(RigidContact(dem, [HalfSpace(ob["point"], ob["normal"], facets, ob.get("tolerance", 0.0),
                                                     friction=ob.get("friction", 0.0))
                                           for ob, facets in zip(scene["obstacles"], obstacle_facets)]))
    if pair_facets is not None:
        c = scene["contact"]
        contacts.append(PairContact(dem, pair_facets, c.get("self_contact", False), c.get("skin"),
                                    c.get("tolerance", 0.0), friction=c.get("friction", 0.0),
                                    surface=c.get("surface", "facet")))
    fracture = None
    if "Gc" in scene.get("material", {}):
        points = scene.get("fracture", {}).get("breakable")
        breakable = None if points is None else nearest_interior_facets(dem, points)
        fracture = Fracture(dem, scene["material"]["Gc"], breakable)
    return DEMProblem(dem, contacts, fracture)


def nearest_interior_facets(dem: DEMDiscretisation, points) -> np.ndarray:
    """The interior facet whose barycentre is nearest each of ``points`` (``fracture.breakable``),
    indices of ``dem``'s geometry (one process: fracture refuses more)."""
    geom = dem.geometry
    interior = geom.interior_facets
    x = geom.facet_centres[interior]
    return np.unique([interior[np.argmin(np.linalg.norm(x - np.asarray(p), axis=1))] for p in points])


def reaction_columns(dem: DEMDiscretisation) -> tuple[str, ...]:
    """Series columns ``reaction_<i>_<x|y|z>`` of the Dirichlet conditions' reactions
    (``DEMDiscretisation.reactions``), i the condition's ``name`` or its index."""
    return tuple(
        f"reaction_{i if bc.name is None else bc.name}_{'xyz'[k]}"
        for i, bc in enumerate(dem.data.dirichlet_conditions)
        for k in range(dem.d)
    )


def prescribed_columns(dem: DEMDiscretisation) -> tuple[str, ...]:
    """Series columns of the prescribed bodies (``DEMProblem.prescribed_values``): for each,
    named by its ``name`` or else its number after the Dirichlet conditions (whose reactions
    come first), its reaction ``reaction_<name>_<x|y>`` (the force it exerts on the other
    bodies) and its translation ``prescribed_<name>_displacement_<x|y>``: together a
    force-indentation curve."""
    first = len(dem.data.dirichlet_conditions)
    names = [first + i if body.name is None else body.name for i, body in enumerate(dem.prescribed)]
    xyz = "xyz"[: dem.d]
    return tuple(f"reaction_{n}_{c}" for n in names for c in xyz) + tuple(
        f"prescribed_{n}_displacement_{c}" for n in names for c in xyz
    )


def prescribed_values(problem: DEMProblem, u, t: float, force=None) -> np.ndarray:
    """The values of ``prescribed_columns`` (collective; ``force`` as in
    ``DEMProblem.prescribed_values``)."""
    if not problem.dem.prescribed:
        return np.empty(0)
    values = problem.prescribed_values(u, t, force)
    return np.concatenate([values[:, 0].ravel(), values[:, 1].ravel()])


def contact_columns(problem: DEMProblem) -> tuple[str, ...]:
    """Series columns of contact: each contact model's ``output_columns`` (contact/), then, if a
    model tracks it (contact between bodies), the total linear momentum ``momentum_<x|y|z>``."""
    columns = tuple(name for c in problem.contacts for name in c.output_columns())
    if any(c.tracks_momentum for c in problem.contacts):
        columns += tuple(f"momentum_{c}" for c in "xyz"[: problem.d])
    return columns


def sum_over_processes(comm: MPI.Comm, a: np.ndarray) -> np.ndarray:
    """The sum over the processes of the float array ``a`` (MPI's Allreduce on the buffer: the
    pickled ``allreduce`` costs 20 x more for the few numbers of a step's outputs)."""
    out = np.array(a, dtype=np.float64)
    comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
    return out


def contact_values(problem: DEMProblem, u, patches: list[np.ndarray] | None = None) -> list[float]:
    """The values of ``contact_columns`` but the momenta, for the displacement ``u``
    (collective: the output sums of all models are reduced by one Allreduce); ``patches``: the
    patch values of u of ``problem.contacts`` if the caller has them (``MEMM.contact_patch_values``)."""
    contacts = problem.contacts
    if not contacts:
        return []
    if patches is None:
        patches = [c.patch_values(u) for c in contacts]
    local = [c.output_sums(up) for c, up in zip(contacts, patches)]
    sums = sum_over_processes(problem.comm, np.concatenate(local))
    values, k = [], 0
    for c, up, part in zip(contacts, patches, local):
        values += c.output_values(up, sums[k : k + len(part)])
        k += len(part)
    return values


def prescribed_cells(dem: DEMDiscretisation) -> np.ndarray | None:
    """Whether each owned cell belongs to a prescribed body, (n_owned,) booleans; None without
    (the pictures draw them apart)."""
    if not dem.prescribed:
        return None
    return np.isin(dem.geometry.cell_bodies[: dem.n_owned], dem.prescribed.body_numbers)


#: How far outside the mesh a probe may lie, in heights of its nearest cell: a point on a curved
#: boundary lies up to about h / (8 R) of them outside the polygonal mesh of facets h.
PROBE_TOLERANCE = 0.1


def _depth_outside(dem: DEMDiscretisation, x: np.ndarray, nearest: int = 8) -> float:
    """How far ``x`` lies outside the nearest of this process's owned cells, in heights of that cell:
    -min of its barycentric coordinates there, least over the ``nearest`` cells of nearest barycentre
    (inf without owned cells)."""
    geom = dem.geometry
    if dem.n_owned == 0:
        return np.inf
    cells = np.argsort(np.linalg.norm(geom.cell_centres[: dem.n_owned] - x, axis=1))[:nearest]
    v = geom.cell_vertices[cells]  # (k, d+1, d)
    lam = np.linalg.solve(np.swapaxes(v[:, 1:] - v[:, :1], 1, 2), (x - v[:, 0])[..., None])[..., 0]
    lam = np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)
    return float(-lam.min(axis=1).max())


class Probes:
    """Displacement components at points: the P1 reconstruction (eq. (10)) of the cell whose
    barycentre is nearest to the point (ties broken by position, so any process count agrees),
    with the contact-aware cell gradients of the problem."""

    def __init__(self, problem: DEMProblem, specs):
        if not isinstance(problem, DEMProblem):
            raise InputError(
                f"Probes read a DEMProblem, got {type(problem).__name__} (wrap a discretisation as DEMProblem(dem))"
            )
        self.problem = problem
        dem = problem.dem
        self.names = [p["name"] for p in specs]
        if len(set(self.names)) != len(self.names):
            raise SceneError(f"probe names must be unique: {self.names}")
        columns = SERIES_COLUMNS + reaction_columns(dem) + prescribed_columns(dem) + contact_columns(problem)
        clash = [name for name in self.names if name in columns]
        if clash:
            raise SceneError(f"probe names {clash} are series columns of this scene; the columns: {columns}")
        for i, p in enumerate(specs):
            if p["component"] >= dem.d:
                raise SceneError(f"scene key 'probes[{i}].component' must be < {dem.d} (0 = x, 1 = y, 2 = z in "
                                 f"{dem.d}D), got {p['component']}")
        points = np.zeros((len(specs), 3))
        for i, p in enumerate(specs):
            points[i, : dem.d] = p["point"]
        inside = _compat.colliding_cells(dem.mesh, points) >= 0 if specs else np.empty(0, bool)
        inside = dem.comm.allreduce(inside.astype(int), op=MPI.SUM) > 0 if specs else inside
        # a point of a curved boundary lies a little outside the polygonal mesh: accepted within
        # PROBE_TOLERANCE of a cell's height beyond its nearest cells (barycentric coordinates)
        depth = np.array([_depth_outside(dem, x[: dem.d]) if not ok else 0.0 for x, ok in zip(points, inside)])
        dem.comm.Allreduce(MPI.IN_PLACE, depth, op=MPI.MIN)
        if np.any(depth > PROBE_TOLERANCE):
            bad = int(np.argmax(depth))
            raise SceneError(f"probe {self.names[bad]!r} at {specs[bad]['point']} is outside the mesh (beyond "
                             f"{PROBE_TOLERANCE:g} of a cell's height from its nearest cells)")
        # Each process proposes its nearest owned cell (key: distance rounded relative to the
        # mesh extent, then position); the smallest key over the processes wins.
        xc = dem.geometry.cell_centres[: dem.n_owned]
        lo, hi = xc.min(axis=0, initial=np.inf), xc.max(axis=0, initial=-np.inf)
        dem.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        dem.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        keys = np.full((len(specs), 1 + dem.d), np.inf)
        cells = np.zeros(len(specs), dtype=np.int64)
        for i, x in enumerate(points[:, : dem.d]):
            if dem.n_owned:
                dist = np.round(np.linalg.norm(xc - x, axis=1) / (hi - lo).max(), 9)
                cells[i] = np.lexsort([xc[:, k] for k in reversed(range(dem.d))] + [dist])[0]
                keys[i] = [dist[cells[i]], *xc[cells[i]]]
        proposals = np.array(dem.comm.allgather(keys))  # (P, n_probes, 1 + d): a few numbers per probe
        winner = np.array([np.lexsort(proposals[:, i].T[::-1])[0] for i in range(len(specs))], dtype=int)
        self.mine = np.flatnonzero(winner == dem.comm.rank)
        self.blocks = cells[self.mine]
        self.offsets = points[self.mine, : dem.d] - xc[self.blocks]
        self.components = np.array([specs[i]["component"] for i in self.mine], dtype=int)

    def values(self, u, t) -> np.ndarray:
        out = np.zeros(len(self.names))
        if len(self.names) == 0:
            return out
        G = self.problem.gradient(u, t)  # collective
        if len(self.mine):
            uc = u.array_r.reshape(-1, self.problem.d)[self.blocks]
            rec = uc + np.einsum("nij,nj->ni", G[self.blocks], self.offsets)
            out[self.mine] = rec[np.arange(len(self.mine)), self.components]
        return sum_over_processes(self.problem.comm, out)


def initial_state(dem: DEMDiscretisation, scene: Mapping):
    """(u0, v0): the scene's initial displacement and velocity at the owned cell barycentres
    (zero by default), as PETSc vectors; a field that is not finite is a ``SceneError``."""
    xc = dem.geometry.cell_centres[: dem.n_owned].T
    u0, v0 = dem.create_vector(), dem.create_vector()
    initial = scene.get("initial", {})
    if "displacement" in initial:
        u0.array[:] = scenes.evaluate_field(initial["displacement"], xc, 0.0, "initial.displacement").T.ravel()
    if "velocity" in initial:
        v0.array[:] = scenes.evaluate_field(initial["velocity"], xc, 0.0, "initial.velocity").T.ravel()
    return u0, v0
