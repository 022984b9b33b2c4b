"""The DEM energy as squared norms of sparse operators (paper §3.2-3.3, eq. (8)-(17)).

With u_F = R u_C + D g (reconstruction.py):

- gradient, eq. (8):   G_c = sum_{f in dc} |f|/|c| u_f (x) n_{f,c}, i.e. grad = Gf (R u + D g);
- elastic energy, eq. (9), (11): E_P = 1/2 sum_c |c| eps_c : C : eps_c = 1/2 |S u + s|^2 with
  S = diag(sqrt|c| L^T P) Gf R, C_M = L L^T the Mandel elasticity matrix, P grad -> Mandel strain;
- jump, eq. (10), (12): [R u]_f = u_c1 - u_c2 + G_c1 (x_f - x_c1) - G_c2 (x_f - x_c2);
- stabilisation, eq. (13): E_S = 1/2 |J u + j|^2, J = diag(sqrt(eta |f|/h_f)) (jump operator);
- stiffness K = S^T S + J^T J and forces F = -(K u + S^T s + J^T j) + f: the exact gradient of
  E_P + E_S, which is eq. (15)-(17) written as matrix products.

Rows: S has m = d(d+1)/2 rows per cell, J has d rows per interior facet, Grad d*d rows per cell.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse

from dolfinx_dem.geometry import MeshGeometry
from dolfinx_dem.material import ElasticMaterial
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
class EnergyOperators:
    """Sparse operators of the cells and facets a process holds. ``DEMDiscretisation`` stacks
    S, J and their parts into its ``rows`` and keeps only ``grad``, ``grad_dirichlet`` and
    ``jump_facets`` here (the others are None there)."""

    grad: scipy.sparse.csr_matrix  # (n d d, N d): cell gradients G_c (homogeneous part)
    grad_dirichlet: scipy.sparse.csr_matrix  # (n d d, n_D d): G_c from the Dirichlet values g
    S: scipy.sparse.csr_matrix  # (n m, N d), n = num_cells of compute_energy_operators
    S_dirichlet: scipy.sparse.csr_matrix  # (n m, n_D d)
    J: scipy.sparse.csr_matrix  # (Fi d, N d), rows ordered as ``jump_facets``
    J_dirichlet: scipy.sparse.csr_matrix  # (Fi d, n_D d)
    jump_facets: np.ndarray  # (Fi,) interior facets, in the row order of J
    S_facet: scipy.sparse.csr_matrix  # (n m, F d): S = S_facet (R u + D g)
    J_facet: scipy.sparse.csr_matrix  # (Fi d, F d): gradient part of J, J = J_facet (R u + D g) + jumps of u_C


def facet_gradient(geom: MeshGeometry) -> scipy.sparse.csr_matrix:
    """Gf of eq. (8): (N d d, F d), row c*d*d + i*d + j, column f*d + i, value |f| n_j / |c|."""
    d, N = geom.d, geom.num_cells
    a = geom.facet_area_normals / geom.cell_volumes[:, None, None]  # (N, d+1, d)
    c, k, i, j = np.meshgrid(np.arange(N), np.arange(d + 1), np.arange(d), np.arange(d), indexing="ij")
    rows = c * d * d + i * d + j
    cols = geom.cell_facets[c, k] * d + i
    vals = a[c, k, j]
    return scipy.sparse.coo_matrix(
        (vals.ravel(), (rows.ravel(), cols.ravel())), shape=(N * d * d, geom.num_facets * d)
    ).tocsr()


def compute_energy_operators(
    geom: MeshGeometry, material: ElasticMaterial, rec: Reconstruction, num_cells: int, jump_facets: np.ndarray
) -> EnergyOperators:
    """S and the gradient for the first ``num_cells`` cells, J for ``jump_facets`` (in that row
    order), as in the module docstring. Columns: the held cells' dofs."""
    d, N = geom.d, geom.num_cells
    Gf = facet_gradient(geom)
    cell_rows = np.arange(num_cells * d * d)
    grad = (Gf[cell_rows] @ rec.R).tocsr()
    grad_D = (Gf[cell_rows] @ rec.D).tocsr()

    L = np.linalg.cholesky(mandel_stiffness(material, d))
    block = L.T @ mandel(d)  # (m, d*d)
    W = scipy.sparse.kron(
        scipy.sparse.diags(np.sqrt(geom.cell_volumes[:num_cells])), scipy.sparse.csr_matrix(block)
    ).tocsr()

    # Jump of the P1 reconstructions (10) at x_f, eq. (12): direct part + gradient part.
    c1, c2 = geom.facet_cells[jump_facets, 0], geom.facet_cells[jump_facets, 1]
    n = len(jump_facets)
    xf = geom.facet_centres[jump_facets]
    r1, r2 = xf - geom.cell_centres[c1], xf - geom.cell_centres[c2]
    f, i, j = np.meshgrid(np.arange(n), np.arange(d), np.arange(d), indexing="ij")
    X = scipy.sparse.coo_matrix(
        (
            np.concatenate([r1[f, j].ravel(), -r2[f, j].ravel()]),
            (
                np.tile((f * d + i).ravel(), 2),
                np.concatenate([(c1[f] * d * d + i * d + j).ravel(), (c2[f] * d * d + i * d + j).ravel()]),
            ),
        ),
        shape=(n * d, N * d * d),
    ).tocsr()
    fi, ii = np.meshgrid(np.arange(n), np.arange(d), indexing="ij")
    delta = scipy.sparse.coo_matrix(
        (
            np.concatenate([np.ones(n * d), -np.ones(n * d)]),
            (np.tile((fi * d + ii).ravel(), 2), np.concatenate([(c1[fi] * d + ii).ravel(), (c2[fi] * d + ii).ravel()])),
        ),
        shape=(n * d, N * d),
    ).tocsr()
    weight = material.stabilisation * geom.facet_areas[jump_facets] / geom.facet_diameters[jump_facets]
    sqrt_w = scipy.sparse.diags(np.repeat(np.sqrt(weight), d))
    S_facet = (W @ Gf[cell_rows]).tocsr()
    J_facet = (sqrt_w @ X @ Gf).tocsr()
    return EnergyOperators(
        S_facet=S_facet,
        J_facet=J_facet,
        grad=grad,
        grad_dirichlet=grad_D,
        S=(S_facet @ rec.R).tocsr(),
        S_dirichlet=(S_facet @ rec.D).tocsr(),
        J=(sqrt_w @ delta + J_facet @ rec.R).tocsr(),
        J_dirichlet=(J_facet @ rec.D).tocsr(),
        jump_facets=np.asarray(jump_facets),
    )
