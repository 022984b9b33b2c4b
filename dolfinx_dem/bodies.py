"""The bodies of a mesh (its connected components, ``geometry.compute_bodies``): cells selected
by tag, the free bodies' mean translations, and the checks that separate bodies share no vertex
and do not overlap.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse
import scipy.spatial
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.errors import AccuracyWarning, InputError

#: A body is slender when the diagonal of its bounding box exceeds this many thicknesses t = d |body| / |boundary|
#: (a disc, a ball or a square: 2.8-3.5; the cantilever 1 x 0.1: 11).
SLENDER = 4.0
#: A slender body with scheme B facets is too thin for its mesh below this many boundary facet sizes across
#: its thickness: scheme B stiffens the cantilever's bending 9.6 times at 3.6 facets, 2.3 times at 29
#: (docs/validation/scheme_b.md).
SCHEME_B_MIN_FACETS_ACROSS = 100.0


def tagged_cells(V, cell_tags, tag: int) -> np.ndarray:
    """The owned cells (dolfinx_dem's numbering: the order of the DG0 space ``V``'s dofs) that
    carry cell tag ``tag`` of the DOLFINx MeshTags ``cell_tags``."""
    mesh = V.mesh
    block = _compat.cell_dofs(V)[: mesh.topology.index_map(mesh.topology.dim).size_local]
    cells = cell_tags.indices[cell_tags.values == tag]
    return np.sort(block[cells[cells < len(block)]])


def check_share_no_vertex(geom, comm: MPI.Comm, bodies: np.ndarray | None = None) -> None:
    """Separate bodies (connected through facets) must not share a vertex: contact between them
    would be undefined at the shared point (``bodies``: only the vertices of these bodies). The
    boundary vertices of the owned cells meet at the process their coordinates hash to.
    Collective; raises an InputError on every process."""
    d = geom.d
    bf = np.intersect1d(geom.boundary_facets, geom.facets_of_layers(0))
    cells, local = geom.facet_cells[bf, 0], geom.facet_local[bf, 0]
    mask = np.ones((len(bf), d + 1), dtype=bool)
    mask[np.arange(len(bf)), local] = False
    x = geom.cell_vertices[cells][mask].reshape(-1, d) + 0.0  # + 0.0: no -0.0
    body = np.repeat(geom.cell_bodies[cells], d)
    rows = np.unique(np.concatenate([x, body[:, None]], axis=1), axis=0)
    bits = np.ascontiguousarray(rows[:, :d]).view(np.uint64)
    mixed = np.zeros(len(rows), dtype=np.uint64)
    for k in range(d):
        mixed = (mixed * np.uint64(1000003)) ^ bits[:, k]
    home = (mixed % np.uint64(comm.size)).astype(np.int64)
    received = comm.alltoall([rows[home == q] for q in range(comm.size)])
    rows = np.unique(np.concatenate(received), axis=0)
    same = np.all(rows[1:, :d] == rows[:-1, :d], axis=1)
    if bodies is not None:
        same &= np.isin(rows[1:, d], bodies) | np.isin(rows[:-1, d], bodies)
    point = rows[1:][same][0, :d].tolist() if same.any() else None
    shared = [p for p in comm.allgather(point) if p is not None]
    if shared:
        raise InputError(f"bodies share the vertex {min(shared)}: bodies in contact must be meshed "
                         "separately (no common vertex)")


def check_do_not_overlap(geom, comm: MPI.Comm) -> None:
    """No boundary vertex of a body may lie strictly inside a cell of another body (in the
    reference configuration). Each process sends the boundary vertices of its owned cells to the
    processes whose box of owned cells contains them, which test them against their owned cells
    near them (point in simplex). Collective; raises an InputError on every process."""
    d = geom.d
    owned = slice(0, geom.num_owned)
    bf = np.intersect1d(geom.boundary_facets, geom.facets_of_layers(0))
    cells, local = geom.facet_cells[bf, 0], geom.facet_local[bf, 0]
    mask = np.ones((len(bf), d + 1), dtype=bool)
    mask[np.arange(len(bf)), local] = False
    points = geom.cell_vertices[cells][mask].reshape(-1, d)
    body = np.repeat(geom.cell_bodies[cells], d)
    x = geom.cell_vertices[owned].reshape(-1, d)
    empty = np.array([np.inf] * d + [-np.inf] * d)
    box = np.concatenate([x.min(axis=0), x.max(axis=0)]) if len(x) else empty
    boxes = np.array(comm.allgather(box))
    send = []
    for q in range(comm.size):
        inside = np.all((points >= boxes[q, :d]) & (points <= boxes[q, d:]), axis=1)
        send.append((points[inside], body[inside]))
    received = comm.alltoall(send)
    points = np.concatenate([r[0] for r in received])
    body = np.concatenate([r[1] for r in received])
    found = None
    if len(points) and geom.num_owned:
        centres = geom.cell_centres[owned]
        radius = np.linalg.norm(geom.cell_vertices[owned] - centres[:, None], axis=2).max()
        near = scipy.spatial.cKDTree(points).sparse_distance_matrix(
            scipy.spatial.cKDTree(centres), radius, output_type="ndarray")
        k, c = near["i"], near["j"]
        other = geom.cell_bodies[c] != body[k]
        k, c = k[other], c[other]
        if len(k):
            v = geom.cell_vertices[c]  # (m, d+1, d)
            lam = np.linalg.solve(np.swapaxes(v[:, 1:] - v[:, :1], 1, 2), (points[k] - v[:, 0])[..., None])[..., 0]
            lam = np.concatenate([1 - lam.sum(axis=1, keepdims=True), lam], axis=1)
            inside = lam.min(axis=1) > 1e-10
            if inside.any():
                m = int(np.flatnonzero(inside)[0])
                found = (int(body[k[m]]), int(geom.cell_bodies[c[m]]), points[k[m]].tolist())
    found = [f for f in comm.allgather(found) if f is not None]
    if found:
        a, b, point = min(found)
        raise InputError(f"bodies {a} and {b} overlap at t = 0: a boundary vertex of body {a} at {point} "
                         f"lies inside body {b}")


class FreeBodies:
    """The bodies without Dirichlet facets or an imposed motion (``clamped``: a flag per body)
    move freely, and K annihilates their translations only up to rounding of order
    eps |K| |u|, which would spoil the energy balance of a fast-moving body. The elastic
    operators are therefore applied to u minus each free body's mean (mass-weighted)
    translation (``relative_displacement``): the same result in exact arithmetic, with rounding
    relative to the deformation instead of the displacement.

    ``labels``: the body of each held cell; ``mass``: the lumped mass per owned dof (PETSc)."""

    def __init__(self, comm: MPI.Comm, labels: np.ndarray, n_bodies: int, clamped: np.ndarray, n_owned: int,
                 mass: PETSc.Vec, d: int):
        self.comm, self.d = comm, d
        free = ~clamped
        owned = labels[:n_owned]
        body_mass = np.bincount(owned, weights=mass.array_r[::d], minlength=n_bodies)
        comm.Allreduce(MPI.IN_PLACE, body_mass, op=MPI.SUM)
        # Mean translations of the free bodies, (n_free, d) = mean_operator @ u.reshape(-1, d)
        # summed over ranks; row n_free of ``_means`` stays 0 for the cells of clamped bodies.
        n_free = int(free.sum())
        index = np.where(free, np.cumsum(free) - 1, n_free)  # body -> its row in _means
        #: for each owned cell the number of its free body, n_free for the cells of clamped bodies
        self.body_of_cell = index[owned].astype(np.int32)
        #: the mass of each free body (kg, kg/m in 2D), (n_free,)
        self.mass = body_mass[free]
        cells = np.flatnonzero(free[owned])
        weights = mass.array_r[::d][cells] / body_mass[owned[cells]]
        mean_operator = scipy.sparse.csr_matrix((weights, (index[owned[cells]], cells)), shape=(n_free, n_owned))
        # one free body (a bar, a disc): a dense row, as a sparse product costs ~8 us of overhead
        self._mean_operator = mean_operator.toarray() if n_free == 1 else mean_operator
        self._means = np.zeros((n_free + 1, d))
        self._shifted = mass.duplicate()

    def relative_displacement(self, u: PETSc.Vec, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """u minus the mean translation of each free body, written into ``out`` (default: a
        vector of this object's own); u itself if no body is free."""
        n_free = self._mean_operator.shape[0]
        if n_free == 0:
            return u
        ua = u.array_r.reshape(-1, self.d)
        means = self._mean_operator @ ua
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, means, op=MPI.SUM)
        self._means[:n_free] = means
        out = self._shifted if out is None else out
        np.subtract(ua, self._means[self.body_of_cell], out=out.array.reshape(-1, self.d))
        return out


def thin_scheme_b_bodies(geom, comm: MPI.Comm, scheme_b_facets: np.ndarray) -> list[tuple[int, float, float]]:
    """The slender bodies too thin for scheme B: (body, t / h, L / t) of each body with scheme B
    facets (``scheme_b_facets``, held facet indices) whose thickness t = d |body| / |boundary| (2A/P in
    2D, 3V/S in 3D: the thickness of a beam, the radius of a disc) is below
    ``SCHEME_B_MIN_FACETS_ACROSS`` mean boundary facet sizes h, and whose bounding-box diagonal L
    exceeds ``SLENDER`` t. Scheme B moves each boundary cell's facet with its barycentre, which
    stiffens bending by an amount that falls only as h / t (docs/theory.md#scheme-bs-accuracy).
    Warns about them (``AccuracyWarning``, rank 0). Collective; arrays of the number of bodies only."""
    n, d, own = geom.num_bodies, geom.d, geom.num_owned
    bf = geom.boundary_facets
    bf = bf[geom.facet_cells[bf, 0] < own]  # each boundary facet once: by its cell's owner
    cells = geom.facet_cells[bf, 0]
    body, fb = geom.cell_bodies[:own], geom.cell_bodies[cells]
    area = np.linalg.norm(geom.facet_area_normals[cells, geom.facet_local[bf, 0]], axis=1)
    sums = np.stack([np.bincount(body, geom.cell_volumes[:own], n), np.bincount(fb, area, n),
                     np.bincount(fb, geom.facet_diameters[bf], n), np.bincount(fb, minlength=n),
                     np.bincount(fb, np.isin(bf, scheme_b_facets), n)])
    x = geom.cell_vertices[:own].reshape(own, -1, d)
    lo, hi = np.full((n, d), np.inf), np.full((n, d), -np.inf)
    np.minimum.at(lo, body, x.min(axis=1))
    np.maximum.at(hi, body, x.max(axis=1))
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    volume, boundary, diameters, count, b = sums
    t = d * volume / boundary
    across, slender = t / (diameters / count), np.linalg.norm(hi - lo, axis=1) / t
    thin = [(int(k), float(across[k]), float(slender[k]))
            for k in np.flatnonzero((b > 0) & (across < SCHEME_B_MIN_FACETS_ACROSS) & (slender > SLENDER))]
    if thin and comm.rank == 0:
        listed = ", ".join(f"body {k} ({a:.3g} facets across, {s:.3g} thicknesses long)" for k, a, s in thin)
        warnings.warn(AccuracyWarning(
            f"scheme B on slender bodies thinner than {SCHEME_B_MIN_FACETS_ACROSS:g} boundary facets: {listed}. "
            "Scheme B moves each boundary facet with its cell, which stiffens bending (the cantilever 3.6 facets "
            "across: 9.6 times too stiff); use scheme A (method dem-A, or dem-AB to keep scheme B on the contact "
            "candidates only) or refine (docs/theory.md#scheme-bs-accuracy)"), stacklevel=3)
    return thin


def body_pairs(comm: MPI.Comm, bodies: np.ndarray, num_bodies: int) -> tuple[list[tuple[int, int]], np.ndarray]:
    """The pairs (a, b), a < b, of the bodies that appear in some process's ``bodies`` (collective),
    and the index of each pair of body numbers among them, (num_bodies, num_bodies) (-1: none)."""
    held = np.bincount(bodies, minlength=num_bodies).astype(np.int64)
    comm.Allreduce(MPI.IN_PLACE, held, op=MPI.SUM)
    present = np.flatnonzero(held)
    pairs = [(int(a), int(b)) for k, a in enumerate(present) for b in present[k + 1:]]
    index = np.full((num_bodies, num_bodies), -1, dtype=np.int64)
    for k, (a, b) in enumerate(pairs):
        index[a, b] = index[b, a] = k
    return pairs, index
