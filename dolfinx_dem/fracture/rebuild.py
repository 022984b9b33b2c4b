"""The local rebuild of the operator when facets break (issue 34; design note §1.4 and §3, rows
"R rows" and "Q rows"): only the rows that a break can change are recomputed, and the result is
the operator ``compute_operator`` forms from scratch for the same crack set (tested bit for bit).

A break of the facets B changes (design note §1.1):

1. R rows (eq. (6)-(7), (19)-(21)): the broken facets, now lips (scheme A, or B where a cell gets
   a second open facet), and their new lips; the interior facets whose stencil can change, those
   with a vertex in a cell that touches a vertex of B (the vertex star of eq. (7) and its
   widening read the vertex numbers, which the split changes at the vertices of B: crack.py);
   the scheme A facets of every cell next to a changed row (``R = R0 + T R0`` reads the cell's
   other facets). These candidate rows are recomputed, closed under "all facets of their cells"
   (what ``compute_reconstruction`` needs to form a scheme A row), and compared with the old
   ones: the rows that differ are the changed R rows.
2. S rows (eq. (11)): the cells with a facet whose R row changed (their gradient, eq. (8)).
3. J rows (eq. (12)-(13)): the unbroken interior facets of those cells; the broken facets' J rows
   become zero rows (the intact row layout, operator.py).

The split geometry and the bodies are formed from scratch (crack.py, O(mesh) numpy, no rows);
the sparse matrices are copied once with their changed rows replaced (O(nnz)). Serial, one
material (an interface facet reads its neighbours' rows: not handled here).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse
from mpi4py import MPI

from dolfinx_dem.errors import InputError
from dolfinx_dem.fracture.crack import split_geometry
from dolfinx_dem.fracture.operator import CrackedOperator
from dolfinx_dem.operators import EnergyRows, compute_energy_rows
from dolfinx_dem.reconstruction import compute_reconstruction


@dataclasses.dataclass(frozen=True)
class ChangedRows:
    """What a break changed: the split geometry's facets whose R rows changed (the new lips
    included), the cells whose S rows were recomputed, and the intact interior facets whose J
    rows were (the broken ones, now zero rows, included)."""

    facets: np.ndarray
    cells: np.ndarray
    jump_facets: np.ndarray


def break_facets(op: CrackedOperator, facets: np.ndarray, step: int, comm: MPI.Comm) -> CrackedOperator:
    """The operator with the intact geometry's interior ``facets`` broken too, at time step
    ``step`` (not before the latest break of ``op``: the lips are numbered by step), rebuilt
    locally (module docstring). Equal to ``compute_operator`` of the same crack set."""
    return break_facets_with_changes(op, facets, step, comm)[0]


def break_facets_with_changes(op: CrackedOperator, facets: np.ndarray, step: int,
                              comm: MPI.Comm) -> tuple[CrackedOperator, ChangedRows]:
    """``break_facets`` and the rows it changed (``ChangedRows``)."""
    intact, c = op.intact, op.conditions
    if len(c.materials.materials) > 1:
        raise InputError("fracture with several materials (issue 34): an interface facet's row reads its "
                         "neighbours' rows, which the local rebuild does not follow yet")
    if step < op.crack.last_step:
        raise InputError(f"facets break at step {step}, before the latest break (step {op.crack.last_step})")
    crack = op.crack.broken(intact, facets, step)
    new = np.setdiff1d(crack.facets(intact), op.crack.facets(intact))
    geom, lips = split_geometry(intact, crack, comm)
    d, F_old, F = intact.d, op.geometry.num_facets, geom.num_facets

    # 1. candidate R rows, closed under "all facets of their cells"
    ids = intact.cell_vertex_ids
    pair = intact.facet_cells[new]
    shared = np.any(ids[pair[:, 0]][:, :, None] == ids[pair[:, 1]][:, None, :], axis=2)
    crack_vertices = ids[pair[:, 0]][shared]
    ring = np.unique(ids[np.isin(ids, crack_vertices).any(axis=1)])
    near = np.flatnonzero(np.isin(ids, ring).any(axis=1))
    neighbours = geom.facet_cells[geom.cell_facets[near].ravel()].ravel()
    candidates = np.unique(geom.cell_facets[np.unique(neighbours[neighbours >= 0])].ravel())
    rec_new = compute_reconstruction(geom, c.materials, c.dirichlet_facets, c.scheme, facets=candidates,
                                     fixed=c.fixed, traction_facets=c.traction_facets,
                                     scheme_b_facets=c.scheme_b_facets)
    rec_old = op.reconstruction
    dofs = (candidates[:, None] * d + np.arange(d)).ravel()
    differ = np.zeros(F * d, bool)
    for old, now in ((rec_old.R, rec_new.R), (rec_old.D, rec_new.D), (rec_old.N, rec_new.N)):
        old = _replace_rows(old, np.empty(0, np.int64), old[:0], (F * d, old.shape[1]))
        differ[dofs] |= np.diff((old[dofs] != now[dofs]).tocsr().indptr) > 0
    changed_facets = np.unique(np.flatnonzero(differ) // d)
    R, D, N = (_replace_rows(old, dofs, now[dofs], (F * d, old.shape[1]))
               for old, now in ((rec_old.R, rec_new.R), (rec_old.D, rec_new.D), (rec_old.N, rec_new.N)))
    rec = dataclasses.replace(
        rec_old, R=R.tocsr(), D=D.tocsc(), N=N.tocsc(),
        neumann_facets=np.union1d(rec_old.neumann_facets, rec_new.neumann_facets),
        scheme_a_facets=np.union1d(rec_old.scheme_a_facets[~np.isin(rec_old.scheme_a_facets, candidates)],
                                   rec_new.scheme_a_facets),
        multi_neumann_cells=np.union1d(rec_old.multi_neumann_cells, rec_new.multi_neumann_cells),
        extrapolated_facets=np.union1d(
            rec_old.extrapolated_facets[~np.isin(rec_old.extrapolated_facets, candidates)],
            rec_new.extrapolated_facets))

    # 2.-3. S rows of the cells next to a changed R row, J rows of their unbroken facets
    touching = geom.facet_cells[changed_facets].ravel()
    cells = np.unique(np.concatenate([touching[touching >= 0], pair.ravel()]))
    cell_jumps = np.unique(intact.cell_facets[cells].ravel())
    position = np.full(F_old, -1, dtype=np.int64)
    position[op.jump_facets] = np.arange(len(op.jump_facets))
    jumps = cell_jumps[position[cell_jumps] >= 0]
    live = jumps[geom.facet_cells[jumps, 1] >= 0]
    part = compute_energy_rows(geom, c.materials, rec, len(cells), live, len(live), elastic_cells=cells)
    m = d * (d + 1) // 2
    n_elastic = op.rows.num_elastic
    targets = np.concatenate([(cells[:, None] * m + np.arange(m)).ravel(),
                              (n_elastic + position[live][:, None] * d + np.arange(d)).ravel()])
    zero = (n_elastic + position[new][:, None] * d + np.arange(d)).ravel()
    targets = np.concatenate([targets, zero])
    n_rows = op.rows.Q.shape[0]

    def placed(old, now, n_cols):
        now = scipy.sparse.vstack([now.tocsr(), scipy.sparse.csr_matrix((len(zero), now.shape[1]))]).tocsr()
        return _replace_rows(old, targets, now, (n_rows, n_cols))

    rows = EnergyRows(Q=placed(op.rows.Q, part.Q, op.rows.Q.shape[1]),
                      Q_dirichlet=placed(op.rows.Q_dirichlet, part.Q_dirichlet, part.Q_dirichlet.shape[1]).tocsc(),
                      QF=placed(op.rows.QF, part.QF, F * d).tocsc(),
                      num_owned=op.rows.num_owned, num_elastic=n_elastic)
    result = dataclasses.replace(op, crack=crack, geometry=geom, lips=lips, reconstruction=rec, rows=rows)
    return result, ChangedRows(changed_facets, cells, np.union1d(live, new))


def _replace_rows(old: scipy.sparse.spmatrix, rows: np.ndarray, new: scipy.sparse.spmatrix,
                  shape: tuple[int, int]) -> scipy.sparse.csr_matrix:
    """``old`` enlarged to ``shape`` (empty rows and columns appended) with its rows ``rows``
    replaced by the rows of ``new`` (row i of ``new`` is row rows[i]), as CSR: each row's entries
    are copied in their order, so an unchanged row keeps its bits and its entry order."""
    old, new = old.tocsr(), new.tocsr()
    rows = np.asarray(rows, dtype=np.int64)
    if len(np.unique(rows)) != len(rows) or new.shape[0] != len(rows):
        raise ValueError("replace_rows: one new row per distinct target row")
    length = np.zeros(shape[0], dtype=np.int64)
    length[: old.shape[0]] = np.diff(old.indptr)
    length[rows] = np.diff(new.indptr)
    indptr = np.concatenate([[0], np.cumsum(length)])
    keep = np.ones(old.shape[0], dtype=bool)
    keep[rows[rows < old.shape[0]]] = False
    data, indices = np.empty(indptr[-1]), np.empty(indptr[-1], dtype=np.int32)
    for matrix, target, take in ((old, np.arange(old.shape[0]), keep), (new, rows, np.ones(len(rows), bool))):
        count = np.diff(matrix.indptr)
        row = np.repeat(np.arange(matrix.shape[0]), count)
        entries = np.flatnonzero(take[row])
        at = indptr[target[row[entries]]] + entries - matrix.indptr[row[entries]]
        data[at], indices[at] = matrix.data[entries], matrix.indices[entries]
    return scipy.sparse.csr_matrix((data, indices, indptr), shape=shape)
