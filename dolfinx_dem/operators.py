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

import numpy as np
import scipy.sparse

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
    elastic rows of its owned cells, then the jump rows of ``jump_facets`` (every interior facet
    of its owned cells, its own ones first). Columns of Q: the held cells' dofs; ``QF`` gives the
    rows' dependence on the values u_F of the boundary facets (the only facets whose
    reconstruction contact changes; its interior-facet columns are empty)."""

    Q: scipy.sparse.csr_matrix  # (rows, n_cells d)
    Q_dirichlet: scipy.sparse.csr_matrix  # (rows, n_D d)
    QF: scipy.sparse.csr_matrix  # (rows, n_facets d), boundary facet columns only
    owned: np.ndarray  # (rows,) bool: the rows of this process's part of Q
    elastic: np.ndarray  # (rows,) bool: an S row (else a J row)
    jump_facets: np.ndarray  # (Fi,) interior facets, in the row order of J


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


def compute_energy_rows(
    geom: MeshGeometry, materials: CellMaterials, rec: Reconstruction, num_cells: int, jump_facets: np.ndarray,
    num_own_jumps: int,
) -> EnergyRows:
    """S for the first ``num_cells`` cells, then J for ``jump_facets`` (in that row order), as in
    the module docstring; the rows of S and of the first ``num_own_jumps`` jump facets are
    ``owned``. Q is formed by one sparse product (below), so that no second copy of Q is made."""
    d, N, F = geom.d, geom.num_cells, geom.num_facets
    m = d * (d + 1) // 2
    # Only the cells whose gradients the rows read: the owned ones (S) and both cells of each jump facet.
    c1, c2 = geom.facet_cells[jump_facets, 0], geom.facet_cells[jump_facets, 1]
    cells = np.unique(np.concatenate([np.arange(num_cells), c1, c2]))
    Gf = facet_gradient(geom, cells)  # rows of cell cells[k]: k d d + ...

    # sqrt|c| L_c^T P of each owned cell, (num_cells, m, d*d): one Cholesky factor per material
    blocks = np.stack([np.linalg.cholesky(mandel_stiffness(mat, d)).T @ mandel(d) for mat in materials.materials])
    # the owned cells are the first ones of ``cells``: row i of cell k reads columns k d d + (0..d d - 1)
    W = scipy.sparse.csr_matrix(
        ((np.sqrt(geom.cell_volumes[:num_cells])[:, None, None] * blocks[materials.index[:num_cells]]).ravel(),
         np.repeat(np.arange(num_cells * d * d, dtype=np.int32).reshape(num_cells, 1, d * d), m, axis=1).ravel(),
         np.arange(0, num_cells * m * d * d + 1, d * d, dtype=np.int32)),
        shape=(num_cells * m, num_cells * d * d))
    W.eliminate_zeros()

    # Jump of the P1 reconstructions (10) at x_f, eq. (12): direct part + gradient part.
    n = len(jump_facets)
    k1, k2 = np.searchsorted(cells, c1), np.searchsorted(cells, c2)
    xf = geom.facet_centres[jump_facets]
    r1, r2 = xf - geom.cell_centres[c1], xf - geom.cell_centres[c2]
    weight = materials.facet_stabilisation(c1, c2) * geom.facet_areas[jump_facets] / geom.facet_diameters[jump_facets]
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
    # the direct part of the jump, sqrt(w) (u_c1 - u_c2), in the columns after the gradients'
    fi, ii = np.meshgrid(np.arange(n), np.arange(d), indexing="ij")
    delta = scipy.sparse.coo_matrix(
        (np.concatenate([sqrt_w, -sqrt_w]),
         (np.tile((fi * d + ii).ravel(), 2),
          len(cells) * d * d + np.concatenate([(c1[fi] * d + ii).ravel(), (c2[fi] * d + ii).ravel()]))),
        shape=(n * d, len(cells) * d * d + N * d),
    ).tocsr()
    del f, i, j, fi, ii, r1, r2, xf, k1, k2, c1, c2
    X.resize(n * d, len(cells) * d * d + N * d)
    W.resize(num_cells * m, len(cells) * d * d + N * d)
    # a = M [G; u_C], [G; u_C] = blockdiag(Gf, I) [u_F; u_C], [u_F; u_C] = [R; I] u_C (+ [D; 0] g):
    # QF_ext = M blockdiag(Gf, I), then Q = QF_ext [R; I], each one product; CSR stacks only
    # (conversions through COO would double the memory of the operands).
    M = scipy.sparse.vstack([W, X + delta], format="csr")
    del W, X, delta
    Gf.resize(Gf.shape[0], F * d + N * d)
    identity = scipy.sparse.csr_matrix((np.ones(N * d), np.arange(F * d, F * d + N * d, dtype=np.int32),
                                        np.arange(N * d + 1, dtype=np.int32)), shape=(N * d, F * d + N * d))
    QF_ext = (M @ scipy.sparse.vstack([Gf, identity], format="csr")).tocsr()
    del M, Gf, identity
    R_ext = scipy.sparse.vstack([rec.R, scipy.sparse.identity(N * d)], format="csr")
    Q = (QF_ext @ R_ext).tocsr()
    del R_ext
    Q_dirichlet = (QF_ext @ scipy.sparse.vstack([rec.D, scipy.sparse.csr_matrix((N * d, rec.D.shape[1]))])).tocsr()
    # QF: the boundary-facet columns only (QF_ext's memory is reused)
    interior = np.ones(F * d + N * d, dtype=bool)
    interior[(np.flatnonzero(geom.facet_cells[:, 1] == -1)[:, None] * d + np.arange(d)).ravel()] = False
    QF_ext.data[interior[QF_ext.indices]] = 0.0
    QF_ext.eliminate_zeros()
    QF_ext.resize(QF_ext.shape[0], F * d)
    S_rows = num_cells * m
    own = np.zeros(Q.shape[0], dtype=bool)
    own[: S_rows + num_own_jumps * d] = True
    return EnergyRows(Q=Q, Q_dirichlet=Q_dirichlet, QF=QF_ext, owned=own,
                      elastic=np.arange(Q.shape[0]) < S_rows, jump_facets=np.asarray(jump_facets))
