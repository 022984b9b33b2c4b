"""The kinematics the pairs of the contact between bodies read (pair.py): the "facet" surface
(each candidate facet with its own free reconstruction u_f = R_f u + lift_f, eq. (19)-(21)) or the
"vertex" surface (issue 32 §3, design C1).

The vertex surface replaces, in the candidate records only, each facet's rows by

    u_f^K = K_f u + sum_{f'} beta_{ff'} lift_{f'},   K_f = sum_{f'} beta_{ff'} R_{f'},
    beta_{ff'} = (1/d) sum_{v in f, v in f'} |f'| / sum_{f'' contains v} |f''|,

f', f'' the candidate facets of the facet's body containing the vertex v (bodies share no
vertex: ``bodies.check_share_no_vertex``): each vertex takes the area-weighted mean of the free
reconstructions around it, each facet the mean of its d vertices. beta is fixed, non-negative and
its rows sum to 1 (a rigid translation is reproduced exactly). K is a fixed linear map, so the
gaps and tangential offsets of eq. (22), (30) stay affine in the step's time: the overlaps, the
events, the exact force integral and the kernels are unchanged, and the force -K^T (...) is the
exact gradient of eq. (31)'s energy (the correction still acts on the facet's own energy rows).
Why: with u_f = u_c (scheme B) the sliding force of eq. (34) can lower the energy by opening
holes between neighbouring facets (a cell-to-cell mode resisted only by the jump term, eq. (13));
averaging along the surface filters those modes, so a hole needs a tangential strain that E
resists. The weights must be convex: linear-exact (least squares) vertex weights are negative
somewhere and amplify the rough modes instead (measured: a two-balls run at eta = E sinks faster
and blows up at a larger step; docs/theory.md).

Distributed: a process computes K for its own facets, whose vertex stars lie in halo layers 0
and 1 (where the candidates and their reconstructions are held). The stars are sorted by their
facets' barycentres and each facet's vertices by their coordinates, which (unlike DOLFINx's
global facet and vertex numbers) do not depend on the partition: the sums of K run in the same
order on any partition, and K is bit-identical wherever the R_f' are (scheme B). The first-layer
local facets receive their rows from their owners.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse
from mpi4py import MPI

from dolfinx_dem.contact.candidates import Candidates
from dolfinx_dem.contact.facets import CandidateFacets, padded_rows
from dolfinx_dem.errors import InputError, StateError
from dolfinx_dem.geometry import OUTSIDE
from dolfinx_dem.halo import alltoall

#: The values of ``PairContact(surface=...)`` (scene key ``contact.surface``).
SURFACES = ("facet", "vertex")


def check_surface(surface: str, friction: float) -> None:
    """An InputError for an unknown surface, or the vertex surface with friction between bodies
    (pair_friction.py slips at the cells, which K would contradict)."""
    if surface not in SURFACES:
        raise InputError(f"contact.surface must be one of {', '.join(map(repr, SURFACES))}, got {surface!r}")
    if surface == "vertex" and friction > 0:
        raise InputError("contact.surface = 'vertex' with contact.friction > 0: friction between bodies slips at "
                         "the facets' cells, not at the vertex surface; use surface 'facet' or friction 0")


def facet_vertex_ids(geom, cell: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The global vertex numbers of facet j of each cell, (n, d), each row in the lexicographic
    order of the vertices' coordinates (the same on any partition, unlike the numbers)."""
    n, d = len(cell), geom.d
    keep = np.arange(d + 1) != np.asarray(j)[:, None]
    ids = geom.cell_vertex_ids[cell][keep].reshape(n, d)
    x = geom.cell_vertices[cell][keep].reshape(n * d, d)
    order = np.lexsort((*x.T[::-1], np.repeat(np.arange(n), d)))  # by facet, then x, y, z
    return ids.ravel()[order].reshape(n, d)


def vertex_weights(star_ids: np.ndarray, star_area: np.ndarray, ids: np.ndarray) -> scipy.sparse.csr_matrix:
    """beta (n, m) of the facets with vertices ``ids`` (n, d) over the star facets with vertices
    ``star_ids`` (m, d) and measures ``star_area`` (m,) (module docstring); every vertex of ``ids``
    must be one of the star's. Sums run in the order of the star facets and of each row of
    ``ids``: inputs in an order that does not depend on the partition give the same beta on any."""
    (n, d), m = ids.shape, len(star_area)
    vertices, at = np.unique(star_ids, return_inverse=True)
    at = at.reshape(m, d)
    total = np.bincount(at.ravel(), weights=np.repeat(star_area, d), minlength=len(vertices))
    W = scipy.sparse.csr_matrix((np.repeat(star_area, d) / total[at.ravel()], (at.ravel(), np.repeat(np.arange(m), d))),
                                shape=(len(vertices), m))
    mine = np.searchsorted(vertices, ids)
    mean = scipy.sparse.csr_matrix((np.full(n * d, 1.0 / d), mine.ravel(), np.arange(0, n * d + 1, d)),
                                   shape=(n, len(vertices)))  # a facet's mean over its vertices
    beta = (mean @ W).tocsr()
    beta.sort_indices()
    return beta


def vertex_surface(dem, found: Candidates, local: CandidateFacets, facets: np.ndarray, num_own: int) -> CandidateFacets:
    """The records ``local`` (of the local facets ``facets``, own ones first) with the rows and
    lifts of the vertex surface (module docstring), from the candidates ``found`` of halo layers 0
    and 1. Collective."""
    geom, rec, d, comm = dem.geometry, dem.reconstruction, dem.d, dem.comm
    order = np.lexsort(geom.facet_centres[found.facet].T[::-1])  # by barycentre: x, then y, z
    star, cell, j = found.facet[order], found.cell[order], found.j[order]
    star_ids = facet_vertex_ids(geom, cell, j)
    own = facets[:num_own]
    ids = facet_vertex_ids(geom, geom.facet_cells[own, 0], geom.facet_local[own, 0])
    # every cell around an own facet's vertex is held: no held facet through it borders an unheld cell
    rim = np.flatnonzero(geom.facet_cells[:, 1] == OUTSIDE)
    rim_ids = facet_vertex_ids(geom, geom.facet_cells[rim, 0], geom.facet_local[rim, 0])
    dofs = (star[:, None] * d + np.arange(d)).ravel()
    R = rec.R[dofs].tocsr()
    bad = np.isin(ids, rim_ids).any() or (np.diff(R.indptr) == 0).any()
    if comm.allreduce(bool(bad), op=MPI.LOR):
        raise StateError("contact.surface = 'vertex': the vertex star of a candidate facet is not held on its "
                         "process (the halo is too thin)")
    beta = vertex_weights(star_ids, np.linalg.norm(geom.facet_area_normals[cell, j], axis=1), ids)
    K = (scipy.sparse.kron(beta, scipy.sparse.identity(d), format="csr") @ R).tocsr()
    R_dofs, R_values = padded_rows(K, dem.columns, d, comm)
    width = R_dofs.shape[2]
    lift = beta @ dem.data.facet_lift(star)
    # the first-layer local facets: their owners' rows
    floats = np.concatenate([R_values.reshape(len(own), d * width), lift], axis=1)
    ints = np.concatenate([local.key[:num_own, None], R_dofs.reshape(len(own), d * width)], axis=1)
    floats, ints = _from_owners(comm, local.key[:num_own], local.key[num_own:], local.owner[num_own:], floats, ints)
    return dataclasses.replace(
        local, R_dofs=np.concatenate([R_dofs, ints[:, 1:].reshape(-1, d, width)]),
        R_values=np.concatenate([R_values, floats[:, : d * width].reshape(-1, d, width)]),
        lift=np.concatenate([lift, floats[:, d * width:]]))


def _from_owners(comm, own_keys, keys, owners, floats, ints):
    """The rows ``floats``, ``ints`` (one per own facet, keys ``own_keys``, sorted) of the facets
    ``keys`` from their ``owners``, in the order of ``keys``. Collective."""
    asked, source = alltoall(comm, np.asarray(owners, dtype=np.int64), np.asarray(keys, dtype=np.int64))
    at = np.searchsorted(own_keys, asked)
    if comm.allreduce(not np.array_equal(np.append(own_keys, -1)[at], asked), op=MPI.LOR):
        raise StateError("contact.surface = 'vertex': a first-layer candidate facet is not its owner's")
    got_floats, got_ints = alltoall(comm, source, floats[at])[0], alltoall(comm, source, ints[at])[0]
    order = np.argsort(got_ints[:, 0])
    back = order[np.searchsorted(got_ints[order, 0], keys)]  # each asked key's row
    return got_floats[back], got_ints[back]
