"""Meshes for dolfinx_dem scenes: boxes with named sides, gmsh discs, and mesh files.

Every function returns ``(mesh, cell_tags, facet_tags)`` (``read_mesh_named`` adds the tags' names):

* ``create_interval``, ``create_rectangle``, ``create_box``: ``cell_tags`` is None (one body);
  ``facet_tags`` marks the boundary facets with 1..2d for the sides x=min, x=max, y=min, y=max,
  z=min, z=max (constants ``XMIN`` ... ``ZMAX``).
* ``create_disc``, ``create_discs``: cell tag and boundary facet tag = 1-based disc number (the
  body tag). The discs are separate connected bodies that share no vertex; ``create_discs`` can
  add rectangles (tags after the discs') and a frame around them (the billiard table), see its
  docstring.
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

import numpy as np
from mpi4py import MPI

import dolfinx.io
import dolfinx.mesh
import gmsh

from dolfinx_dem import _compat
from dolfinx_dem.io import call_on_root

XMIN, XMAX, YMIN, YMAX, ZMIN, ZMAX = 1, 2, 3, 4, 5, 6
SIDE_NAMES = {"xmin": XMIN, "xmax": XMAX, "ymin": YMIN, "ymax": YMAX, "zmin": ZMIN, "zmax": ZMAX}

_DIAGONALS = tuple(dolfinx.mesh.DiagonalType.__members__)


def _check_counts(n, d: int) -> list[int]:
    counts = np.atleast_1d(np.asarray(n))
    if counts.shape != (d,) or not all(float(c).is_integer() and c >= 1 for c in counts):
        raise ValueError(f"n must be {d} integer(s) >= 1 (cells per direction), got {n!r}")
    return [int(c) for c in counts]


def _check_corners(p0, p1, d: int) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(p0, dtype=np.float64).reshape(-1)
    b = np.asarray(p1, dtype=np.float64).reshape(-1)
    if a.shape != (d,) or b.shape != (d,):
        raise ValueError(f"corners must have {d} coordinate(s), got p0={p0!r}, p1={p1!r}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(b > a)):
        raise ValueError(
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
        raise ValueError(f"diagonal must be one of {', '.join(_DIAGONALS)}; got {diagonal!r}")
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


def create_discs(comm: MPI.Comm, discs: Sequence[tuple[Sequence[float], float]], h: float,
                 frame: tuple[Sequence[float], Sequence[float], float] | None = None,
                 rectangles: Sequence[Sequence[float]] = ()):
    """Separate discs and rectangles, optionally inside a rectangular frame, meshed with triangles
    of size ~h (m).

    ``discs`` is a sequence of ``(centre (2,), radius)``; discs may touch but not overlap. Disc
    ``i`` (1-based) has cell tag ``i`` and boundary facet tag ``i``. ``rectangles`` is a sequence
    of ``[x0, y0, x1, y1]`` (x0 < x1, y0 < y1), which must not overlap the discs or each other:
    rectangle ``j`` (1-based) has cell and boundary facet tag ``n + j`` for n discs (e.g. a block
    under an indenter). ``frame = (p0, p1, width)`` adds the frame [p0 - width, p1 + width] minus
    the open rectangle (p0, p1) (the billiard table of paper §5.4): cell tag ``m + 1``, inner
    boundary tag ``m + 1``, outer boundary tag ``m + 2`` for m discs and rectangles. The discs
    must lie inside (p0, p1). No two bodies share a vertex.
    """
    if len(discs) == 0 and len(rectangles) == 0:
        raise ValueError("discs must hold at least one (centre, radius) pair (or give rectangles)")
    centres, radii = [], []
    for i, disc in enumerate(discs, start=1):
        if len(disc) != 2:
            raise ValueError(f"disc {i} must be a (centre, radius) pair, got {disc!r}")
        centre = np.asarray(disc[0], dtype=np.float64).reshape(-1)
        radius = float(disc[1])
        if centre.shape != (2,) or not np.all(np.isfinite(centre)):
            raise ValueError(f"disc {i}: centre must be 2 finite coordinates, got {disc[0]!r}")
        if not (math.isfinite(radius) and radius > 0):
            raise ValueError(f"disc {i}: radius must be > 0, got {disc[1]!r}")
        centres.append(centre)
        radii.append(radius)
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"mesh size h must be > 0, got {h!r}")
    for i in range(len(discs)):
        for j in range(i):
            gap = np.linalg.norm(centres[i] - centres[j]) - radii[i] - radii[j]
            if gap < -1e-12 * (radii[i] + radii[j]):
                raise ValueError(f"discs {j + 1} and {i + 1} overlap (gap {gap:g} m)")
    boxes = []
    for j, rect in enumerate(rectangles, start=1):
        r = np.asarray(rect, dtype=np.float64).reshape(-1)
        if r.shape != (4,) or not np.all(np.isfinite(r)) or r[2] <= r[0] or r[3] <= r[1]:
            raise ValueError(f"rectangle {j} must be [x0, y0, x1, y1] with x0 < x1 and y0 < y1, got {rect!r}")
        for i, (c, radius) in enumerate(zip(centres, radii), start=1):
            if np.linalg.norm(c - np.clip(c, r[:2], r[2:])) < radius * (1 - 1e-12):
                raise ValueError(f"rectangle {j} overlaps disc {i}")
        for k, b in enumerate(boxes, start=1):
            if np.all(np.minimum(r[2:], b[2:]) > np.maximum(r[:2], b[:2])):
                raise ValueError(f"rectangles {k} and {j} overlap")
        boxes.append(r)
    if frame is not None:
        if len(frame) != 3:
            raise ValueError(f"frame must be (p0, p1, width), got {frame!r}")
        p0, p1 = _check_corners(frame[0], frame[1], 2)
        width = float(frame[2])
        if not (math.isfinite(width) and width > 0):
            raise ValueError(f"frame width must be > 0, got {frame[2]!r}")
        for i, (c, r) in enumerate(zip(centres, radii), start=1):
            if np.any(c - r <= p0) or np.any(c + r >= p1):
                raise ValueError(f"disc {i} (centre {c.tolist()}, radius {r:g}) is not strictly inside "
                                 f"the frame's opening {p0.tolist()} - {p1.tolist()}")

    def build() -> int:
        gmsh.model.add("discs")
        surfaces = [gmsh.model.occ.addDisk(c[0], c[1], 0.0, r, r) for c, r in zip(centres, radii)]
        surfaces += [gmsh.model.occ.addRectangle(b[0], b[1], 0.0, b[2] - b[0], b[3] - b[1]) for b in boxes]
        if frame is not None:
            outer = gmsh.model.occ.addRectangle(p0[0] - width, p0[1] - width, 0.0,
                                                p1[0] - p0[0] + 2 * width, p1[1] - p0[1] + 2 * width)
            hole = gmsh.model.occ.addRectangle(p0[0], p0[1], 0.0, p1[0] - p0[0], p1[1] - p0[1])
            cut, _ = gmsh.model.occ.cut([(2, outer)], [(2, hole)])
        gmsh.model.occ.synchronize()
        for tag, surface in enumerate(surfaces, start=1):
            gmsh.model.addPhysicalGroup(2, [surface], tag)
            curves = [c for _, c in gmsh.model.getBoundary([(2, surface)], oriented=False)]
            gmsh.model.addPhysicalGroup(1, curves, tag)
        if frame is not None:
            n = len(surfaces)
            gmsh.model.addPhysicalGroup(2, [cut[0][1]], n + 1)
            inner, outer_curves = [], []
            for _, c in gmsh.model.getBoundary(cut, oriented=False):
                x = gmsh.model.occ.getCenterOfMass(1, c)
                on_hole = (p0[0] - 1e-9 <= x[0] <= p1[0] + 1e-9) and (p0[1] - 1e-9 <= x[1] <= p1[1] + 1e-9)
                (inner if on_hole else outer_curves).append(c)
            gmsh.model.addPhysicalGroup(1, inner, n + 1)
            gmsh.model.addPhysicalGroup(1, outer_curves, n + 2)
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(2)
        return 2

    return _mesh_from_gmsh(comm, build)


def create_disc(comm: MPI.Comm, centre: Sequence[float], radius: float, h: float):
    """One disc of the given centre (2,) and radius (m), triangles of size ~h; tags 1."""
    return create_discs(comm, [(centre, radius)], h)


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
        raise ValueError(f"unknown mesh file type {path.suffix!r} of {path} (use .msh or .xdmf)")
    if not comm.bcast(path.is_file() if comm.rank == 0 else None, root=0):
        raise FileNotFoundError(f"mesh file {path} does not exist (looked for {path.resolve()})")

    if suffix == ".msh":
        names = {}

        def build() -> int:
            gmsh.merge(str(path))
            dim = gmsh.model.getDimension()
            if not gmsh.model.getPhysicalGroups(dim):
                raise ValueError(f"{path} has no physical groups of dimension {dim} to read")
            for _, tag in gmsh.model.getPhysicalGroups(dim - 1):
                name = gmsh.model.getPhysicalName(dim - 1, tag)
                if name:
                    names[name] = None if name in names else int(tag)
            return dim

        mesh, cell_tags, facet_tags = _mesh_from_gmsh(comm, build)
        return mesh, cell_tags, facet_tags, comm.bcast(names, root=0)

    names = call_on_root(comm, _xdmf_grid_names, path)
    if "mesh" not in names:
        raise ValueError(f"{path} holds no mesh named 'mesh' (grids: {sorted(names)})")
    with dolfinx.io.XDMFFile(comm, str(path), "r") as xdmf:
        mesh = _compat.read_xdmf_mesh(xdmf, "mesh")
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        cell_tags = xdmf.read_meshtags(mesh, "cell_tags") if "cell_tags" in names else None
        facet_tags = xdmf.read_meshtags(mesh, "facet_tags") if "facet_tags" in names else None
    return mesh, cell_tags, facet_tags, {}
