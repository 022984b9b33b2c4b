"""The candidate facets of the contact between bodies (pair.py): their records, exchanged between
processes, and the matrices built from them.

A candidate facet f carries what a pair needs without its cell: its barycentre, outward normal,
measure |f|, vertices, the scheme A tensor of eq. (23)-(24), and its free reconstruction
u_f = R_f u + lift (eq. (19)-(21)) as rows of (global dof, value) entries, so that a process that
receives it from another (pair_list.py) reconstructs it from the patch dofs alone.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse
from mpi4py import MPI

from dolfinx_dem.kernels import Struct, csr, lib, pointer


@dataclasses.dataclass
class CandidateFacets:
    """Candidate facets (local ones first, then ghosts): global facet number ``key``, owner,
    body, the global dof of its cell's first component (``cell_dof``, for the pair friction),
    barycentre, outward unit normal, measure |f| (``length``: an area in 3D), vertex coordinates
    (``ends``), global vertex numbers, scheme A data (the tensor C a_f / |c| of
    ``directions.correction_directions``), and the free reconstruction u_f = R_f u + lift as d rows
    of M (global dof, value) entries (dof -1: padding)."""

    key: np.ndarray  # (n,)
    index: np.ndarray  # (n,) the facet's number among all candidates (own facets numbered by rank)
    owner: np.ndarray  # (n,)
    body: np.ndarray  # (n,)
    cell_dof: np.ndarray  # (n,)
    centre: np.ndarray  # (n, d)
    normal: np.ndarray  # (n, d)
    length: np.ndarray  # (n,)
    ends: np.ndarray  # (n, d, d) vertex coordinates
    vertex_ids: np.ndarray  # (n, d)
    scheme_a: np.ndarray  # (n,) bool
    Ca: np.ndarray  # (n, d, d, d)
    R_dofs: np.ndarray  # (n, d, M) global dofs, -1 padding
    R_values: np.ndarray  # (n, d, M)
    lift: np.ndarray  # (n, d)

    FLOATS = ("centre", "normal", "length", "ends", "Ca", "R_values", "lift")
    INTS = ("key", "index", "owner", "body", "cell_dof", "vertex_ids", "scheme_a", "R_dofs")

    def __len__(self) -> int:
        return len(self.key)

    def take(self, k: np.ndarray) -> CandidateFacets:
        return CandidateFacets(**{f.name: getattr(self, f.name)[k] for f in dataclasses.fields(self)})

    def records(self) -> tuple[np.ndarray, np.ndarray]:
        """(float rows, integer rows): one row per facet, to send to other processes."""
        n = len(self)
        flat = lambda a: a.reshape(n, int(np.prod(a.shape[1:], dtype=np.int64)))  # noqa: E731
        floats = np.concatenate([flat(getattr(self, name)) for name in self.FLOATS], axis=1)
        ints = np.concatenate([flat(getattr(self, name)).astype(np.int64) for name in self.INTS], axis=1)
        return floats, ints

    def from_records(self, floats: np.ndarray, ints: np.ndarray) -> CandidateFacets:
        """Facets from ``records`` rows, shaped like this instance's arrays."""
        out, k = {}, 0
        for name in self.FLOATS:
            shape = getattr(self, name).shape[1:]
            width = int(np.prod(shape, dtype=np.int64))
            out[name] = floats[:, k : k + width].reshape((-1,) + shape)
            k += width
        k = 0
        for name in self.INTS:
            template = getattr(self, name)
            width = int(np.prod(template.shape[1:], dtype=np.int64))
            out[name] = ints[:, k : k + width].reshape((-1,) + template.shape[1:]).astype(template.dtype)
            k += width
        return CandidateFacets(**out)

    @staticmethod
    def concatenate(parts: list[CandidateFacets]) -> CandidateFacets:
        return CandidateFacets(**{f.name: np.concatenate([getattr(p, f.name) for p in parts])
                                  for f in dataclasses.fields(CandidateFacets)})


def candidate_records(dem, f: np.ndarray, cell: np.ndarray, numbers: np.ndarray) -> CandidateFacets:
    """The candidate records of the facets ``f`` of the local cells ``cell``, their candidate
    numbers ``numbers`` (collective: the reconstructions' widest row)."""
    geom, rec, d = dem.geometry, dem.reconstruction, dem.d
    n = len(f)
    an = geom.facet_area_normals[cell, geom.facet_local[f, 0]]
    length = np.linalg.norm(an, axis=1)
    mask = np.ones((n, d + 1), dtype=bool)
    mask[np.arange(n), geom.facet_local[f, 0]] = False
    R_dofs, R_values = padded_rows(rec.R[(f[:, None] * d + np.arange(d)).ravel()].tocsr(), dem.columns, d, dem.comm)
    scheme_a = np.isin(f, rec.scheme_a_facets)
    C = dem.materials.elasticity_tensor(d, cell)
    # A_f x = (C_c : (x (x) a_f)) n / |c| for the pair's normal n: einsum with the cell's C and a_f.
    Ca = np.einsum("nijkl,nl->nijk", C, an) / geom.cell_volumes[cell, None, None, None]
    return CandidateFacets(
        key=geom.facet_global[f], index=numbers, owner=geom.cell_owner[cell], body=geom.cell_bodies[cell],
        cell_dof=dem.columns[cell * d],
        centre=geom.facet_centres[f], normal=an / length[:, None], length=length,
        ends=geom.cell_vertices[cell][mask].reshape(n, d, d),
        vertex_ids=geom.cell_vertex_ids[cell][mask].reshape(n, d), scheme_a=scheme_a,
        Ca=np.where(scheme_a[:, None, None, None], Ca, 0.0),
        R_dofs=R_dofs, R_values=R_values, lift=dem.data.facet_lift(f),
    )


def padded_rows(R: scipy.sparse.csr_matrix, columns: np.ndarray, d: int, comm: MPI.Comm) -> tuple[np.ndarray, ...]:
    """The rows of R (n d, held dofs) as the records' (global dof, value) entries, (n, d, M),
    padded (dof -1, value 0) to the widest row of all processes (collective)."""
    n = R.shape[0] // d
    width = comm.allreduce(int(np.diff(R.indptr).max(initial=0)), op=MPI.MAX)
    R_dofs = np.full((n * d, width), -1, dtype=np.int64)
    R_values = np.zeros((n * d, width))
    counts = np.diff(R.indptr)
    rank = np.arange(R.nnz) - np.repeat(R.indptr[:-1], counts)
    rows = np.repeat(np.arange(n * d), counts)
    R_dofs[rows, rank] = columns[R.indices]
    R_values[rows, rank] = R.data
    return R_dofs.reshape(n, d, width), R_values.reshape(n, d, width)


def reach(F: CandidateFacets) -> np.ndarray:
    """The largest distance from each facet's barycentre to its vertices (half the length in 2D)."""
    return np.linalg.norm(F.ends - F.centre[:, None], axis=2).max(axis=1, initial=0.0)


def find_sorted(a: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each entry of ``x`` in the sorted array ``a`` of non-negative numbers: its position there
    (np.searchsorted) and whether it is there (np.isin without sorting ``a``)."""
    index = np.searchsorted(a, x)
    return index, np.append(a, -1)[index] == x  # (-1, no entry: past the end of a)


def reconstruction_matrix(F: CandidateFacets, first: np.ndarray) -> tuple[scipy.sparse.csr_matrix, np.ndarray]:
    """R of the facets ``F`` on the patch dofs ``first`` (sorted global dofs) then ``extra``, the
    other dofs F's reconstructions read (sorted): (R, (n d, len(first) + len(extra)), each row's
    columns sorted; extra)."""
    n, d, width = F.R_dofs.shape
    dofs = F.R_dofs.reshape(-1)
    keep = dofs >= 0
    dofs = dofs[keep]
    column, found = find_sorted(first, dofs)
    extra, at = np.unique(dofs[~found], return_inverse=True)
    column[~found] = len(first) + at
    indptr = np.zeros(n * d + 1, dtype=np.int32)
    np.cumsum(keep.reshape(n * d, width).sum(axis=1), out=indptr[1:])
    R = scipy.sparse.csr_matrix((F.R_values.reshape(-1)[keep], column.astype(np.int32), indptr),
                                shape=(n * d, len(first) + len(extra)))
    R.sort_indices()
    return R, extra


class FacetRows:
    """A CSC matrix's arrays for the compiled kernel ``dem_pair_rows`` (QF: the own rows touched
    by the local facets' dofs), with its work arrays (``dem_facet_rows``)."""

    def __init__(self, A: scipy.sparse.csc_matrix, d: int):
        self.shape, self.d = A.shape, d
        self.indptr = np.ascontiguousarray(A.indptr, dtype=np.int32)
        self.indices = np.ascontiguousarray(A.indices, dtype=np.int32)
        self.data = np.ascontiguousarray(A.data, dtype=np.float64)
        self._facet_counts = np.diff(self.indptr).reshape(-1, d).sum(axis=1)  # the entries of each facet's d columns
        self._sums = np.zeros(self.shape[0])  # zero between calls
        self._mark = np.full(self.shape[0], -1, dtype=np.int32)  # -1 between calls
        self._touched = np.empty(2 * self.shape[0], dtype=np.int32)
        self._struct = Struct("dem_facet_rows", columns=csr(self.indptr, self.indices, self.data, self.shape[0]),
                              sums=self._sums, mark=self._mark, touched=self._touched)

    def pair_rows(self, i, j, e_i, e_j, length) -> scipy.sparse.csr_matrix:
        """Z^T = E^T A^T for the pairs (i, j) of facets (the local ones: those with columns
        here, d each): row p = sum over its local facets f of A's columns of f's dofs times
        e_f / |f| (sorted, no explicit zeros)."""
        P, d, n_local = len(i), self.d, len(self._facet_counts)
        i, j = np.ascontiguousarray(i, dtype=np.int64), np.ascontiguousarray(j, dtype=np.int64)
        e_i, e_j = np.ascontiguousarray(e_i, dtype=np.float64), np.ascontiguousarray(e_j, dtype=np.float64)
        length = np.ascontiguousarray(length, dtype=np.float64)
        counts = self._facet_counts
        bound = int(counts[i[i < n_local]].sum() + counts[j[j < n_local]].sum())
        indptr, indices, data = np.empty(P + 1, dtype=np.int32), np.empty(bound, dtype=np.int32), np.empty(bound)
        nnz = lib.dem_pair_rows(self._struct.c, P, d, pointer(i), pointer(j), pointer(e_i), pointer(e_j),
                                pointer(length), pointer(indptr), pointer(indices), pointer(data))
        # copies of the entries: the list keeps them, and the bound exceeds them (a facet's d
        # columns share rows)
        return scipy.sparse.csr_matrix((data[:nnz].copy(), indices[:nnz].copy(), indptr), shape=(P, self.shape[0]))
