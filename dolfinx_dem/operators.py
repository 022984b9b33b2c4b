"""The DEM energy as squared norms of sparse operators (paper §3.2-3.3, eq. (8)-(17)).

With u_F = R u_C + D g (reconstruction.py):

- gradient, eq. (8):   G_c = sum_{f in dc} |f|/|c| u_f (x) n_{f,c}, i.e. grad = Gf (R u + D g);
- elastic energy, eq. (9), (11): E_P = 1/2 sum_c |c| eps_c : C : eps_c = 1/2 |S u + s|^2 with
  S = diag(sqrt|c| L_c^T P) Gf R, C_M = L_c L_c^T the Mandel elasticity matrix of cell c's material,
  P grad -> Mandel strain;
- jump, eq. (10), (12): [R u]_f = u_c1 - u_c2 + G_c1 (x_f - x_c1) - G_c2 (x_f - x_c2);
- stabilisation, eq. (13): E_S = 1/2 |J u + j|^2, J = diag(sqrt(eta_f |f|/h_f)) (jump operator),
  eta_f the harmonic mean of the two cells' eta (``CellMaterials.facet_stabilisation``);
- stiffness K = S^T S + J^T J and forces F = -(K u + S^T s + J^T j) + f: the exact gradient of
  E_P + E_S, which is eq. (15)-(17) written as matrix products.

Rows: S has m = d(d+1)/2 rows per cell, J has d rows per interior facet. Q = [S; J] is the only
operator of the size of the mesh that a process keeps; cell gradients (outputs) are formed on
demand from the reconstruction (``DEMDiscretisation.gradient``).
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import scipy.sparse

from dolfinx_dem.errors import InputError
from dolfinx_dem.geometry import MeshGeometry
from dolfinx_dem.material import CellMaterials, ElasticMaterial
from dolfinx_dem.reconstruction import Reconstruction


def mandel(d: int) -> np.ndarray:
    """P of shape (m, d*d): Mandel strain vector of a gradient, e.g. (e11, e22, sqrt2 e12) in 2D."""
    pairs = [(i, i) for i in range(d)] + [(i, j) for i in range(d) for j in range(i + 1, d)]
    P = np.zeros((len(pairs), d * d))
    for row, (i, j) in enumerate(pairs):
        if i == j:
            P[row, i * d + i] = 1.0
        else:
            P[row, i * d + j] = P[row, j * d + i] = np.sqrt(2) / 2
    return P


def mandel_stiffness(material: ElasticMaterial, d: int) -> np.ndarray:
    """C_M with eps : C : eps = e^T C_M e for the Mandel vector e = P vec(grad)."""
    P = mandel(d)
    C = material.elasticity_tensor(d).reshape(d * d, d * d)
    # P P^T = I and C maps symmetric gradients to symmetric stresses, so C_M = P C P^T.
    return P @ C @ P.T


@dataclasses.dataclass(frozen=True)
class EnergyRows:
    """The energy rows a = Q u + Q_dirichlet g a process holds (``DEMDiscretisation.rows``): the
    elastic rows of its owned cells, then the jump rows of every interior facet of its owned
    cells, its own ones first. Columns of Q: the held cells' dofs; ``QF`` gives the
    rows' dependence on the values u_F of the boundary facets (the only facets whose
    reconstruction contact changes; its interior-facet columns are empty)."""

    Q: scipy.sparse.csr_matrix  # (rows, n_cells d)
    Q_dirichlet: scipy.sparse.csc_matrix  # (rows, n_D d); CSC: few entries, no pointer per row
    QF: scipy.sparse.csc_matrix  # (rows, n_facets d), boundary facet columns only; CSC as Q_dirichlet
    num_owned: int  # rows [0, num_owned): this process's part of Q
    num_elastic: int  # rows [0, num_elastic): S rows (the others J rows)


def facet_gradient(geom: MeshGeometry, cells: np.ndarray) -> scipy.sparse.csr_matrix:
    """Gf of eq. (8) for ``cells``: (n d d, F d), row k*d*d + i*d + j for cells[k], column
    f*d + i, value |f| n_j / |c|: d+1 entries per row (the cell's facets), built as CSR."""
    d = geom.d
    cells = np.asarray(cells)
    a = geom.facet_area_normals[cells] / geom.cell_volumes[cells, None, None]  # (n, d+1, d): [c, k, j]
    facets = geom.cell_facets[cells].astype(np.int32)  # (n, d+1)
    shape = (len(cells), d, d, d + 1)  # entry [c, i, j, k]
    indices = np.broadcast_to(facets[:, None, None, :] * d + np.arange(d, dtype=np.int32)[None, :, None, None], shape)
    data = np.broadcast_to(a.transpose(0, 2, 1)[:, None, :, :], shape)
    indptr = np.arange(0, len(cells) * d * d * (d + 1) + 1, d + 1, dtype=np.int32)
    return scipy.sparse.csr_matrix((data.ravel(), indices.ravel(), indptr),
                                   shape=(len(cells) * d * d, geom.num_facets * d))


#: Rows of Q formed at a time (``compute_energy_rows``): bounds the set-up's intermediate products.
BLOCK_ROWS = 2**18


def _stack_rows(blocks: list, n_cols: int) -> scipy.sparse.csr_matrix:
    """The CSR blocks stacked (vstack), int32 indices. The list is emptied while the blocks are
    copied, each block freed once copied: with the result's arrays filled as they are touched,
    the blocks and the result never both exist in full."""
    n_rows, nnz = sum(b.shape[0] for b in blocks), sum(b.nnz for b in blocks)
    if nnz >= 2**31:
        raise InputError(f"{nnz} entries in the rows of one process: more than int32 indices address")
    indptr = np.empty(n_rows + 1, dtype=np.int32)
    indices, data = np.empty(nnz, dtype=np.int32), np.empty(nnz)
    indptr[0] = row = at = 0
    while blocks:
        b = blocks.pop(0)
        indptr[row + 1 : row + 1 + b.shape[0]] = b.indptr[1:] + at
        indices[at : at + b.nnz], data[at : at + b.nnz] = b.indices, b.data
        row, at = row + b.shape[0], at + b.nnz
        del b
    return scipy.sparse.csr_matrix((data, indices, indptr), shape=(n_rows, n_cols))


def _stack_columns(blocks: list, n_cols: int) -> scipy.sparse.csc_matrix:
    """The CSR blocks stacked (vstack) as CSC: for the operators with few entries (QF, Q_dirichlet),
    whose row pointers would outweigh their entries."""
    first = np.cumsum([0] + [b.shape[0] for b in blocks])
    coo = [b.tocoo() for b in blocks]
    rows = np.concatenate([c.row + a for c, a in zip(coo, first)] + [np.empty(0, dtype=np.int32)])
    cols = np.concatenate([c.col for c in coo] + [np.empty(0, dtype=np.int32)])
    data = np.concatenate([c.data for c in coo] + [np.empty(0)])
    return scipy.sparse.csc_matrix((data, (rows, cols)), shape=(int(first[-1]), n_cols))


def compute_energy_rows(
    geom: MeshGeometry, materials: CellMaterials, rec: Reconstruction, num_cells: int, jump_facets: np.ndarray,
    num_own_jumps: int, elastic_cells: np.ndarray | None = None,
) -> EnergyRows:
    """S for the first ``num_cells`` cells, then J for ``jump_facets`` (in that row order), as in
    the module docstring; the rows of S and of the first ``num_own_jumps`` jump facets are
    this process's. ``elastic_cells`` (an index array, in row order) replaces the first
    ``num_cells`` cells when given (``num_cells`` is then its length): the rows of a subset
    of cells, as fracture's local rebuild needs (fracture/rebuild.py). Q is formed in blocks of
    ``BLOCK_ROWS`` rows by sparse products (below) and the blocks copied into it: no second
    copy of Q and no intermediate product of its size.
    Each row of a product depends on the same row of its left factor only, so the rows do not
    depend on the blocks."""
    d, N, F = geom.d, geom.num_cells, geom.num_facets
    m = d * (d + 1) // 2
    # a = M_G G + M_C u_C with G = Gf u_F and u_F = R u_C + D g: for each block of rows of M,
    # QF = M_G Gf (the rows' dependence on the facet values), Q = QF R + M_C, Q_dirichlet = QF D,
    # with Gf formed for the block's cells only: no operator of the size of the mesh besides R
    # and the result (CSR products only: conversions through COO would double the operands).
    boundary = np.zeros(F * d, dtype=bool)  # QF keeps the boundary-facet columns only
    boundary[(np.flatnonzero(geom.facet_cells[:, 1] == -1)[:, None] * d + np.arange(d)).ravel()] = True

    # sqrt|c| L_c^T P of each owned cell, (num_cells, m, d*d): one Cholesky factor per material
    factors = np.stack([np.linalg.cholesky(mandel_stiffness(mat, d)).T @ mandel(d) for mat in materials.materials])

    def elastic(cells: np.ndarray):
        """(M_G, its cells, M_C) of the rows of S for the owned ``cells``: row i of cells[k]
        reads the gradient entries k d d + (0..d d - 1); no direct part."""
        n = len(cells)
        W = scipy.sparse.csr_matrix(
            ((np.sqrt(geom.cell_volumes[cells])[:, None, None] * factors[materials.index[cells]]).ravel(),
             np.repeat(np.arange(n * d * d, dtype=np.int32).reshape(n, 1, d * d), m, axis=1).ravel(),
             np.arange(0, n * m * d * d + 1, d * d, dtype=np.int32)),
            shape=(n * m, n * d * d))
        W.eliminate_zeros()
        return W, cells, None

    def jump(facets: np.ndarray):
        """(M_G, its cells, M_C) of the rows of J for ``facets``: the jump of the P1
        reconstructions (10) at x_f, eq. (12): its gradient part (M_G) and its direct part
        sqrt(w) (u_c1 - u_c2) (M_C)."""
        n = len(facets)
        c1, c2 = geom.facet_cells[facets, 0], geom.facet_cells[facets, 1]
        cells = np.unique(np.concatenate([c1, c2]))
        k1, k2 = np.searchsorted(cells, c1), np.searchsorted(cells, c2)
        xf = geom.facet_centres[facets]
        r1, r2 = xf - geom.cell_centres[c1], xf - geom.cell_centres[c2]
        weight = materials.facet_stabilisation(c1, c2) * geom.facet_areas[facets] / geom.facet_diameters[facets]
        sqrt_w = np.repeat(np.sqrt(weight), d)
        f, i, j = np.meshgrid(np.arange(n), np.arange(d), np.arange(d), indexing="ij")
        X = scipy.sparse.coo_matrix(
            (
                np.concatenate([(sqrt_w.reshape(n, d)[f, i] * r1[f, j]).ravel(),
                                (-sqrt_w.reshape(n, d)[f, i] * r2[f, j]).ravel()]),
                (np.tile((f * d + i).ravel(), 2),
                 np.concatenate([(k1[f] * d * d + i * d + j).ravel(), (k2[f] * d * d + i * d + j).ravel()])),
            ),
            shape=(n * d, len(cells) * d * d),
        ).tocsr()
        fi, ii = np.meshgrid(np.arange(n), np.arange(d), indexing="ij")
        delta = scipy.sparse.coo_matrix(
            (np.concatenate([sqrt_w, -sqrt_w]),
             (np.tile((fi * d + ii).ravel(), 2),
              np.concatenate([(c1[fi] * d + ii).ravel(), (c2[fi] * d + ii).ravel()]))),
            shape=(n * d, N * d),
        ).tocsr()
        return X, cells, delta

    s_cells = np.arange(num_cells) if elastic_cells is None else np.asarray(elastic_cells, dtype=np.int64)
    num_cells = len(s_cells)
    Q, Q_dirichlet, QF = [], [], []
    cell_block, facet_block = max(1, BLOCK_ROWS // m), max(1, BLOCK_ROWS // d)
    M_blocks = itertools.chain(
        (elastic(s_cells[a : a + cell_block]) for a in range(0, num_cells, cell_block)),
        (jump(jump_facets[a : a + facet_block]) for a in range(0, len(jump_facets), facet_block)))
    for M_G, cells, M_C in M_blocks:
        QF_block = (M_G @ facet_gradient(geom, cells)).tocsr()
        del M_G
        Q_block = (QF_block @ rec.R).tocsr()
        Q.append(Q_block if M_C is None else (Q_block + M_C).tocsr())
        del Q_block, M_C
        Q_dirichlet.append((QF_block @ rec.D).tocsr())
        QF_block.data[~boundary[QF_block.indices]] = 0.0
        QF_block.eliminate_zeros()
        QF.append(QF_block)
        del QF_block
    Q = _stack_rows(Q, N * d)
    S_rows = num_cells * m
    return EnergyRows(Q=Q, Q_dirichlet=_stack_columns(Q_dirichlet, rec.D.shape[1]), QF=_stack_columns(QF, F * d),
                      num_owned=S_rows + num_own_jumps * d, num_elastic=S_rows)
