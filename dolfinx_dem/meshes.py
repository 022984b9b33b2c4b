"""Meshes for dolfinx_dem scenes: boxes with named sides, gmsh discs and balls, and mesh files.

Every function returns ``(mesh, cell_tags, facet_tags)`` (``read_mesh_named`` adds the tags' names):

* ``create_interval``, ``create_rectangle``, ``create_box``: ``cell_tags`` is None (one body);
  ``facet_tags`` marks the boundary facets with 1..2d for the sides x=min, x=max, y=min, y=max,
  z=min, z=max (constants ``XMIN`` ... ``ZMAX``).
* ``create_disc``, ``create_discs``, ``create_balls``: cell tag and boundary facet tag = 1-based
  disc (ball) number (the body tag). The bodies are separate and share no vertex; rectangles
  (boxes) can be added after them (tags after the discs', e.g. a block under an indenter) and a
  frame around them (the billiard table), see the docstrings.
* ``read_mesh``, ``read_mesh_named``: whatever tags the file holds (see the docstrings), and
  the names of the facet tags (a gmsh file's physical-group names).

Meshes use ``dolfinx.mesh.GhostMode.shared_facet``. Lengths are in metres (any consistent unit).
gmsh runs on rank 0 only; its terminal output is switched off and it is always finalised, so
these functions must not be called inside a caller's own gmsh session.
"""

from __future__ import annotations

import math
import pathlib
import xml.etree.ElementTree as ElementTree
from collections.abc import Callable, Sequence

import dolfinx.io
import dolfinx.mesh
import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError, MissingFileError
from dolfinx_dem.io import call_on_root

XMIN, XMAX, YMIN, YMAX, ZMIN, ZMAX = 1, 2, 3, 4, 5, 6
SIDE_NAMES = {"xmin": XMIN, "xmax": XMAX, "ymin": YMIN, "ymax": YMAX, "zmin": ZMIN, "zmax": ZMAX}

_DIAGONALS = tuple(dolfinx.mesh.DiagonalType.__members__)


def _check_counts(n, d: int) -> list[int]:
    counts = np.atleast_1d(np.asarray(n))
    if counts.shape != (d,) or not all(float(c).is_integer() and c >= 1 for c in counts):
        raise InputError(f"n must be {d} integer(s) >= 1 (cells per direction), got {n!r}")
    return [int(c) for c in counts]


def _check_corners(p0, p1, d: int) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(p0, dtype=np.float64).reshape(-1)
    b = np.asarray(p1, dtype=np.float64).reshape(-1)
    if a.shape != (d,) or b.shape != (d,):
        raise InputError(f"corners must have {d} coordinate(s), got p0={p0!r}, p1={p1!r}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(b > a)):
        raise InputError(
            f"need finite corners with p1 > p0 componentwise, got p0={p0!r}, p1={p1!r}"
        )
    return a, b


def _tag_sides(mesh, p0: np.ndarray, p1: np.ndarray):
    """MeshTags of the boundary facets: 2i+1 on x_i = p0[i], 2i+2 on x_i = p1[i]."""
    tol = 1e-10 * float(np.max(p1 - p0))
    indices, values = [], []
    for i in range(p0.shape[0]):
        for tag, coordinate in ((2 * i + 1, p0[i]), (2 * i + 2, p1[i])):
            facets = _compat.locate_boundary_facets(
                mesh, lambda x, i=i, c=coordinate: np.abs(x[i] - c) <= tol
            )
            indices.append(facets)
            values.append(np.full(facets.shape, tag, dtype=np.int32))
    indices = np.concatenate(indices).astype(np.int32)
    order = np.argsort(indices)
    tags = dolfinx.mesh.meshtags(
        mesh, mesh.topology.dim - 1, indices[order], np.concatenate(values)[order]
    )
    tags.name = "facet_tags"
    return tags


def locate_boundary_facets(mesh, marker) -> np.ndarray:
    """Process-local boundary facets (int32) whose vertices all satisfy ``marker(x)``, x of shape
    (3, n): what ``DirichletBC``, ``Traction``, ``HalfSpace`` and ``PairContact`` take."""
    return _compat.locate_boundary_facets(mesh, marker)


def exterior_facets(mesh) -> np.ndarray:
    """Process-local indices (int32) of the facets on the boundary of the domain."""
    return _compat.exterior_facets(mesh)


def create_interval(comm: MPI.Comm, n: int, x0: float, x1: float):
    """Interval [x0, x1] (m) with n >= 1 equal cells; facet tags XMIN (x0) and XMAX (x1)."""
    (n,) = _check_counts(n, 1)
    p0, p1 = _check_corners([x0], [x1], 1)
    mesh = dolfinx.mesh.create_interval(
        comm, n, [p0[0], p1[0]], ghost_mode=dolfinx.mesh.GhostMode.shared_facet, partitioner=_compat.partitioner()
    )
    return mesh, None, _tag_sides(mesh, p0, p1)


def create_rectangle(
    comm: MPI.Comm,
    p0: Sequence[float],
    p1: Sequence[float],
    n: Sequence[int],
    diagonal: str = "right",
):
    """Rectangle [p0, p1] (m) of 2 n[0] n[1] triangles; facet tags XMIN, XMAX, YMIN, YMAX.

    ``diagonal`` is a ``dolfinx.mesh.DiagonalType`` name: right, left, crossed (4 triangles per
    rectangle), left_right, right_left.
    """
    a, b = _check_corners(p0, p1, 2)
    counts = _check_counts(n, 2)
    if diagonal not in _DIAGONALS:
        raise InputError(f"diagonal must be one of {', '.join(_DIAGONALS)}; got {diagonal!r}")
    mesh = dolfinx.mesh.create_rectangle(
        comm,
        [a, b],
        counts,
        cell_type=dolfinx.mesh.CellType.triangle,
        ghost_mode=dolfinx.mesh.GhostMode.shared_facet,
        partitioner=_compat.partitioner(),
        diagonal=getattr(dolfinx.mesh.DiagonalType, diagonal),
    )
    return mesh, None, _tag_sides(mesh, a, b)


def create_box(comm: MPI.Comm, p0: Sequence[float], p1: Sequence[float], n: Sequence[int]):
    """Box [p0, p1] (m) of 6 n[0] n[1] n[2] tetrahedra; facet tags XMIN ... ZMAX."""
    a, b = _check_corners(p0, p1, 3)
    counts = _check_counts(n, 3)
    mesh = dolfinx.mesh.create_box(
        comm,
        [a, b],
        counts,
        cell_type=dolfinx.mesh.CellType.tetrahedron,
        ghost_mode=dolfinx.mesh.GhostMode.shared_facet,
        partitioner=_compat.partitioner(),
    )
    return mesh, None, _tag_sides(mesh, a, b)


def _mesh_from_gmsh(comm: MPI.Comm, build: Callable[[], int]):
    """Run ``build`` on rank 0 in a fresh gmsh session, then distribute the mesh.

    ``build`` fills the gmsh model (with physical groups) and returns the geometric dimension.
    Its exceptions are raised on every rank. The tags are named "cell_tags" and "facet_tags".
    """
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
    try:
        gdim = call_on_root(comm, build)
        mesh, cell_tags, facet_tags = _compat.mesh_from_gmsh_model(gmsh.model, comm, gdim)
    finally:
        if comm.rank == 0:
            gmsh.finalize()
    cell_tags.name, facet_tags.name = "cell_tags", "facet_tags"
    return mesh, cell_tags, facet_tags


def _check_round_bodies(word: str, d: int, bodies, h: float, frame, cut, refine, blocks, block_word):
    """Checked (centres, radii, frame, cut axes, refine, blocks) of ``create_discs``/``create_balls``."""
    plural = {"rectangle": "rectangles", "box": "boxes"}[block_word]
    if len(bodies) == 0 and len(blocks) == 0:
        raise InputError(f"{word}s must hold at least one (centre, radius) pair (or give {plural})")
    centres, radii = [], []
    for i, body in enumerate(bodies, start=1):
        if len(body) != 2:
            raise InputError(f"{word} {i} must be a (centre, radius) pair, got {body!r}")
        centre = np.asarray(body[0], dtype=np.float64).reshape(-1)
        radius = float(body[1])
        if centre.shape != (d,) or not np.all(np.isfinite(centre)):
            raise InputError(f"{word} {i}: centre must be {d} finite coordinates, got {body[0]!r}")
        if not (math.isfinite(radius) and radius > 0):
            raise InputError(f"{word} {i}: radius must be > 0, got {body[1]!r}")
        centres.append(centre)
        radii.append(radius)
    if not (math.isfinite(h) and h > 0):
        raise InputError(f"mesh size h must be > 0, got {h!r}")
    for i in range(len(bodies)):
        for j in range(i):
            gap = np.linalg.norm(centres[i] - centres[j]) - radii[i] - radii[j]
            if gap < -1e-12 * (radii[i] + radii[j]):
                raise InputError(f"{word}s {j + 1} and {i + 1} overlap (gap {gap:g} m)")
    corners = [("x0", "x1"), ("y0", "y1"), ("z0", "z1")][:d]
    shape = "[" + ", ".join([c[0] for c in corners] + [c[1] for c in corners]) + "] with " + \
        ", ".join(f"{a} < {b}" for a, b in corners)
    boxes = []
    for j, block in enumerate(blocks, start=1):
        b = np.asarray(block, dtype=np.float64).reshape(-1)
        if b.shape != (2 * d,) or not np.all(np.isfinite(b)) or np.any(b[d:] <= b[:d]):
            raise InputError(f"{block_word} {j} must be {shape}, got {block!r}")
        for i, (c, radius) in enumerate(zip(centres, radii), start=1):
            if np.linalg.norm(c - np.clip(c, b[:d], b[d:])) < radius * (1 - 1e-12):
                raise InputError(f"{block_word} {j} overlaps {word} {i}")
        for k, other in enumerate(boxes, start=1):
            if np.all(np.minimum(b[d:], other[d:]) > np.maximum(b[:d], other[:d])):
                raise InputError(f"{plural} {k} and {j} overlap")
        boxes.append(b)
    if frame is not None:
        if len(frame) != 3:
            raise InputError(f"frame must be (p0, p1, width), got {frame!r}")
        p0, p1 = _check_corners(frame[0], frame[1], d)
        width = float(frame[2])
        if not (math.isfinite(width) and width > 0):
            raise InputError(f"frame width must be > 0, got {frame[2]!r}")
        for i, (c, r) in enumerate(zip(centres, radii), start=1):
            if np.any(c - r <= p0) or np.any(c + r >= p1):
                raise InputError(f"{word} {i} (centre {c.tolist()}, radius {r:g}) is not strictly inside "
                                 f"the frame's opening {p0.tolist()} - {p1.tolist()}")
        for j, b in enumerate(boxes, start=1):
            if np.any(b[:d] <= p0) or np.any(b[d:] >= p1):
                raise InputError(f"{block_word} {j} {b.tolist()} is not strictly inside the frame's opening "
                                 f"{p0.tolist()} - {p1.tolist()}")
        frame = (p0, p1, width)
    axes = "xyz"[:d]
    cut = list(cut or [])
    if any(a not in axes for a in cut) or len(set(cut)) != len(cut) or len(cut) == d:
        raise InputError(f"cut must be distinct axes among {', '.join(axes)}, fewer than {d}, got {cut!r}")
    cut = [axes.index(a) for a in cut]
    if refine is not None:
        if len(refine) != 3:
            raise InputError(f"refine must be (point, h_min, radius), got {refine!r}")
        point = np.asarray(refine[0], dtype=np.float64).reshape(-1)
        h_min, distance = float(refine[1]), float(refine[2])
        if point.shape != (d,) or not np.all(np.isfinite(point)):
            raise InputError(f"refine point must be {d} finite coordinates, got {refine[0]!r}")
        if not (math.isfinite(h_min) and 0 < h_min <= h):
            raise InputError(f"refine h_min must satisfy 0 < h_min <= h = {h:g}, got {refine[1]!r}")
        if not (math.isfinite(distance) and distance > 0):
            raise InputError(f"refine radius must be > 0, got {refine[2]!r}")
        # h_min = h asks for size h everywhere: the uniform mesh (turns a scene's refinement off)
        refine = (point, h_min, distance) if h_min < h else None
    return centres, radii, frame, cut, refine, boxes


#: Growth of the mesh size per unit distance outside a refined zone: gradual enough for
#: well-shaped simplices between the fine and the coarse size.
_GRADING = 0.5


def _create_round_bodies(comm, d, word, bodies, h, frame, cut, refine, blocks, block_word):
    """``create_discs`` (d = 2) and ``create_balls`` (d = 3): see their docstrings."""
    centres, radii, frame, cut, refine, boxes = _check_round_bodies(word, d, bodies, h, frame, cut, refine,
                                                                    blocks, block_word)

    def box(lo, hi) -> int:  # a rectangle (z = 0) or a box, of corners lo < hi
        return (gmsh.model.occ.addRectangle(lo[0], lo[1], 0.0, *(hi - lo)) if d == 2
                else gmsh.model.occ.addBox(*lo, *(hi - lo)))

    def build() -> int:
        occ = gmsh.model.occ
        gmsh.model.add(word + "s")
        bodies = []
        for c, r in zip(centres, radii):
            body = occ.addDisk(c[0], c[1], 0.0, r, r) if d == 2 else occ.addSphere(*c, r)
            if cut:
                # keep x_i >= c_i for the cut axes: intersect with a box past the body elsewhere
                lo, hi = c - 1.5 * r, c + 1.5 * r
                lo[cut] = c[cut]
                kept, _ = occ.intersect([(d, body)], [(d, box(lo, hi))])
                body = kept[0][1]
            bodies.append(body)
        for b in boxes:
            lo, hi = b[:d].copy(), b[d:]
            lo[cut] = (lo[cut] + hi[cut]) / 2  # the cut keeps the half past the block's centre too
            bodies.append(box(lo, hi))
        if frame is not None:
            p0, p1, width = frame
            walls, _ = occ.cut([(d, box(p0 - width, p1 + width))], [(d, box(p0, p1))])
        occ.synchronize()
        for tag, body in enumerate(bodies, start=1):
            gmsh.model.addPhysicalGroup(d, [body], tag)
            faces = [f for _, f in gmsh.model.getBoundary([(d, body)], oriented=False)]
            gmsh.model.addPhysicalGroup(d - 1, faces, tag)
        if frame is not None:
            n = len(bodies)
            gmsh.model.addPhysicalGroup(d, [walls[0][1]], n + 1)
            inner, outer = [], []
            tol = 1e-9 * float(np.max(p1 - p0))
            for _, f in gmsh.model.getBoundary(walls, oriented=False):
                x = np.array(occ.getCenterOfMass(d - 1, f))[:d]
                (inner if np.all((p0 - tol <= x) & (x <= p1 + tol)) else outer).append(f)
            gmsh.model.addPhysicalGroup(d - 1, inner, n + 1)
            gmsh.model.addPhysicalGroup(d - 1, outer, n + 2)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        if refine is None:
            gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        else:
            # size h_min within the refined zone, then growing by _GRADING per unit distance up to h
            point, h_min, distance = refine
            # float(): the reprs of numpy 2 scalars (np.float64(...)) are no gmsh expressions
            big, small, reach = float(h), float(h_min), float(distance)
            dist = "Sqrt(" + "+".join(f"({a}-({float(p)!r}))^2" for a, p in zip("xyz", point)) + ")"
            field = gmsh.model.mesh.field.add("MathEval")
            gmsh.model.mesh.field.setString(
                field, "F", f"Min({big!r}, Max({small!r}, {small!r} + {_GRADING!r}*({dist} - {reach!r})))")
            gmsh.model.mesh.field.setAsBackgroundMesh(field)
            gmsh.option.setNumber("Mesh.MeshSizeMin", h_min)
            for option in ("MeshSizeFromPoints", "MeshSizeFromCurvature", "MeshSizeExtendFromBoundary"):
                gmsh.option.setNumber(f"Mesh.{option}", 0)
        gmsh.model.mesh.generate(d)
        return d

    return _mesh_from_gmsh(comm, build)


def create_discs(comm: MPI.Comm, discs: Sequence[tuple[Sequence[float], float]], h: float,
                 frame: tuple[Sequence[float], Sequence[float], float] | None = None,
                 cut: Sequence[str] | None = None,
                 refine: tuple[Sequence[float], float, float] | None = None,
                 rectangles: Sequence[Sequence[float]] = ()):
    """Separate discs and rectangles, optionally inside a rectangular frame, meshed with triangles
    of size ~h (m).

    ``discs`` is a sequence of ``(centre (2,), radius)``; discs may touch but not overlap. Disc
    ``i`` (1-based) has cell tag ``i`` and boundary facet tag ``i``. ``rectangles`` is a sequence
    of ``[x0, y0, x1, y1]`` (x0 < x1, y0 < y1), which must not overlap the discs or each other:
    rectangle ``j`` (1-based) has cell and boundary facet tag ``n + j`` for n discs (e.g. a block
    under an indenter). ``frame = (p0, p1, width)`` adds the frame [p0 - width, p1 + width] minus
    the open rectangle (p0, p1) (the billiard table of paper §5.4): cell tag ``m + 1``, inner
    boundary tag ``m + 1``, outer boundary tag ``m + 2`` for m discs and rectangles. The bodies
    must lie inside (p0, p1). No two bodies share a vertex.

    ``cut`` (axes "x", "y") keeps the half x_i >= c_i of every disc (a symmetric problem's half
    disc; the cut edge is part of the boundary tag i). ``refine = (point, h_min, radius)`` sets
    the size h_min within ``radius`` of ``point``, growing as h_min + 0.5 (distance - radius) up
    to h further away (e.g. at a contact point); h_min = h gives the uniform mesh of ``refine = None``.
    """
    return _create_round_bodies(comm, 2, "disc", discs, h, frame, cut, refine, rectangles, "rectangle")


def create_disc(comm: MPI.Comm, centre: Sequence[float], radius: float, h: float):
    """One disc of the given centre (2,) and radius (m), triangles of size ~h; tags 1."""
    return create_discs(comm, [(centre, radius)], h)


def create_balls(comm: MPI.Comm, balls: Sequence[tuple[Sequence[float], float]], h: float,
                 frame: tuple[Sequence[float], Sequence[float], float] | None = None,
                 cut: Sequence[str] | None = None,
                 refine: tuple[Sequence[float], float, float] | None = None,
                 boxes: Sequence[Sequence[float]] = ()):
    """Separate balls and boxes, optionally inside a box frame, meshed with tetrahedra of size ~h (m).

    The 3D ``create_discs``: ``balls`` is a sequence of ``(centre (3,), radius)``, touching but
    not overlapping; ball ``i`` (1-based) has cell tag ``i`` and boundary facet tag ``i``;
    ``boxes`` (``[x0, y0, z0, x1, y1, z1]``, e.g. a slab under a ball) come after them, tags
    ``n + j``; ``frame = (p0, p1, width)`` adds the walls [p0 - width, p1 + width] minus the open
    box (p0, p1), cell tag ``m + 1``, inner boundary tag ``m + 1``, outer boundary tag ``m + 2``
    for m balls and boxes; no two bodies share a vertex. ``cut`` (axes among "x", "y", "z", at most two) keeps the part
    x_i >= c_i of every ball: ``cut = ["x", "y"]`` is the quarter ball of a problem symmetric
    about the planes x = c_x and y = c_y, whose flat faces belong to boundary tag i (select them
    by a condition such as "x <= 0"). ``refine = (point, h_min, radius)``: size h_min within
    ``radius`` of ``point``, growing as h_min + 0.5 (distance - radius) up to h; h_min = h gives
    the uniform mesh of ``refine = None``.
    """
    return _create_round_bodies(comm, 3, "ball", balls, h, frame, cut, refine, boxes, "box")


def _xdmf_grid_names(path: pathlib.Path) -> set[str]:
    return {grid.get("Name") for grid in ElementTree.parse(path).getroot().iter("Grid")}


def read_mesh(comm: MPI.Comm, path: str | pathlib.Path):
    """Read a mesh file: ``(mesh, cell_tags or None, facet_tags or None)``.

    * ``.msh`` (gmsh): cells are the elements of the physical groups of the highest dimension,
      tagged with their physical tag; facet tags come from the physical groups one dimension
      lower (an empty MeshTags if there are none). The geometric dimension is the model's.
    * ``.xdmf``: the mesh named ``"mesh"`` and, when the file holds them, the MeshTags named
      ``"cell_tags"`` and ``"facet_tags"`` (None otherwise).

    ``read_mesh_named`` also returns the names of the facet tags.
    """
    return read_mesh_named(comm, path)[:3]


def read_mesh_named(comm: MPI.Comm, path: str | pathlib.Path):
    """``read_mesh`` plus the facet tags' names: ``(mesh, cell_tags, facet_tags, names)`` with
    ``names`` {name: tag} from the names of a ``.msh`` file's physical groups one dimension below
    the cells (unnamed groups are left out; a name given to several groups maps to None); empty
    for ``.xdmf``. A relative ``path`` is relative to the working directory."""
    path = pathlib.Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".msh", ".xdmf"):
        raise InputError(f"unknown mesh file type {path.suffix!r} of {path} (use .msh or .xdmf)")
    if not comm.bcast(path.is_file() if comm.rank == 0 else None, root=0):
        raise MissingFileError(f"mesh file {path} does not exist (looked for {path.resolve()})")

    if suffix == ".msh":
        names = {}

        def build() -> int:
            gmsh.merge(str(path))
            dim = gmsh.model.getDimension()
            if not gmsh.model.getPhysicalGroups(dim):
                raise InputError(f"{path} has no physical groups of dimension {dim} to read")
            for _, tag in gmsh.model.getPhysicalGroups(dim - 1):
                name = gmsh.model.getPhysicalName(dim - 1, tag)
                if name:
                    names[name] = None if name in names else int(tag)
            return dim

        mesh, cell_tags, facet_tags = _mesh_from_gmsh(comm, build)
        return mesh, cell_tags, facet_tags, comm.bcast(names, root=0)

    names = call_on_root(comm, _xdmf_grid_names, path)
    if "mesh" not in names:
        raise InputError(f"{path} holds no mesh named 'mesh' (grids: {sorted(names)})")
    with dolfinx.io.XDMFFile(comm, str(path), "r") as xdmf:
        mesh = _compat.read_xdmf_mesh(xdmf, "mesh")
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        cell_tags = xdmf.read_meshtags(mesh, "cell_tags") if "cell_tags" in names else None
        facet_tags = xdmf.read_meshtags(mesh, "facet_tags") if "facet_tags" in names else None
    return mesh, cell_tags, facet_tags, {}
