"""Facet reconstruction u_F = R u_C + D g (paper §3.1 eq. (6)-(7), §3.4 eq. (19)-(21), scheme B).

- Interior facets: barycentric interpolation from d+1 cells whose barycentres form a simplex
  containing the facet barycentre (eq. (7)), coefficients in [0, 1].
- Dirichlet facets: the imposed value, u_f = g_f (the columns of D).
- Neumann facets, scheme B: u_f = u_c, the facet follows its cell.
- Neumann facets, scheme A: u_f solves sigma_c n_f = 0 (eq. (19)-(21)) given the cell's other
  facets. A cell with more than one Neumann facet has no unique local solution (every rectangle
  corner); dolfinx_dem applies scheme B to the Neumann facets of such cells and reports them in
  ``Reconstruction.multi_neumann_cells``.

Matrices act on flattened vectors: cell dof ``c*d + i``, facet dof ``f*d + i``, Dirichlet value
``k*d + i`` for the k-th Dirichlet facet.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import scipy.sparse
import scipy.spatial

from dolfinx_dem.geometry import MeshGeometry
from dolfinx_dem.material import ElasticMaterial

#: Number of nearest barycentres searched for an interior stencil, by dimension.
_NEIGHBOURS = {1: 2, 2: 10, 3: 14}
#: Barycentric coordinates above -_INSIDE_TOL count as inside the simplex.
_INSIDE_TOL = 1e-10
#: Smallest barycentric coordinate accepted when a facet must be extrapolated (see below).
_MAX_EXTRAPOLATION = -1.0


@dataclasses.dataclass(frozen=True)
class InteriorStencils:
    """Eq. (7): for interior facet ``facets[k]``, x_f = sum_i alpha[k, i] x_{cells[k, i]}."""

    facets: np.ndarray  # (Fi,)
    cells: np.ndarray  # (Fi, d+1)
    alpha: np.ndarray  # (Fi, d+1), rows sum to 1; in [0, 1] except on ``extrapolated``
    extrapolated: np.ndarray  # facets with no containing simplex (rule in compute_interior_stencils)


@dataclasses.dataclass(frozen=True)
class Reconstruction:
    """u_F = R u_C + D g with R of shape (F d, N d) and D of shape (F d, n_D d)."""

    R: scipy.sparse.csr_matrix
    D: scipy.sparse.csr_matrix
    dirichlet_facets: np.ndarray  # (n_D,) global facet indices, the order of g
    neumann_facets: np.ndarray  # (n_N,) global facet indices
    scheme_a_facets: np.ndarray  # the Neumann facets reconstructed by scheme A (eq. (20))
    scheme: str
    multi_neumann_cells: np.ndarray  # cells where scheme A fell to scheme B (rule above)
    stencils: InteriorStencils


def _barycentric(points: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates of x (..., d) in simplices ``points`` (..., d+1, d).

    Returns (alpha (..., d+1), valid (...)); degenerate simplices are not valid.
    """
    d = x.shape[-1]
    edges = points[..., 1:, :] - points[..., :1, :]  # (..., d, d)
    det = np.linalg.det(edges)
    scale = np.prod(np.linalg.norm(edges, axis=-1), axis=-1)
    valid = np.abs(det) > 1e-8 * scale
    safe = np.where(valid[..., None, None], edges, np.eye(d))
    beta = np.linalg.solve(np.swapaxes(safe, -1, -2), (x - points[..., 0, :])[..., None])[..., 0]
    alpha = np.concatenate([1 - beta.sum(axis=-1, keepdims=True), beta], axis=-1)
    return alpha, valid


def _best_combination(geom: MeshGeometry, facets, combos):
    """Among candidate cell tuples ``combos`` (n, m, d+1) pick the most central containing simplex.

    The key is the smallest barycentric coordinate (largest wins), then the compactness of the
    simplex, then the lexicographic order of its sorted barycentre positions. Every key is
    geometric and rounded, so the choice does not depend on the cell numbering or on summation
    order: serial and parallel runs pick the same simplices.
    """
    n, m, k = combos.shape
    d = geom.d
    xc = geom.cell_centres
    xf = geom.facet_centres[facets]
    h = geom.facet_diameters[facets, None, None, None]
    alpha, valid = _barycentric(xc[combos], xf[:, None, :])
    distinct = np.all(np.diff(np.sort(combos, axis=-1), axis=-1) > 0, axis=-1)
    valid &= distinct & (combos >= 0).all(axis=-1)
    min_alpha = np.where(valid, alpha.min(axis=-1), -np.inf)
    rel = np.round((xc[combos] - xf[:, None, None, :]) / h, 9)  # (n, m, k, d)
    spread = np.round(np.sum(rel**2, axis=(-1, -2)), 7)
    flat = rel.reshape(n * m, k, d)
    point_order = np.lexsort([flat[:, :, i] for i in reversed(range(d))], axis=-1)
    canonical = np.take_along_axis(flat, point_order[:, :, None], axis=1).reshape(n * m, k * d)
    keys = [canonical[:, i] for i in reversed(range(k * d))]
    keys += [spread.ravel(), -np.round(min_alpha, 9).ravel(), np.repeat(np.arange(n), m)]
    best = np.lexsort(keys).reshape(n, m)[:, 0] % m
    rows = np.arange(n)
    return combos[rows, best], alpha[rows, best], min_alpha[rows, best]


def compute_interior_stencils(geom: MeshGeometry) -> InteriorStencils:
    """Eq. (7) for every interior facet.

    First the two adjacent cells plus d-1 of the nearest barycentres are tried (the segment
    between the adjacent barycentres crosses the facet), then any d+1 of the nearest.

    Near the boundary a facet barycentre can lie outside the convex hull of the barycentres (in
    3D at the edges of a box, for instance). Rule: such a facet is reconstructed from the least
    extrapolating simplex, the one whose smallest barycentric coordinate is largest; the
    reconstruction stays exact for affine fields, and the facet is listed in ``extrapolated``.
    If even that coordinate is below -1, a ValueError names the facet.
    """
    d = geom.d
    facets = geom.interior_facets
    pair = geom.facet_cells[facets]
    k = min(_NEIGHBOURS[d], geom.num_cells)
    # Equidistant barycentres abound on structured meshes: query more than k and keep the k
    # nearest by (distance, position), a geometric order, so the choice is numbering-independent.
    k_query = min(2 * k, geom.num_cells)
    dist, near = scipy.spatial.cKDTree(geom.cell_centres).query(geom.facet_centres[facets], k=k_query)
    dist, near = dist.reshape(len(facets), k_query), near.reshape(len(facets), k_query)
    position = geom.cell_centres[near] @ np.array([1.0, np.pi, np.e][:d])
    order = np.lexsort((position, np.round(dist / geom.facet_diameters[facets, None], 9)), axis=-1)
    near = np.take_along_axis(near, order[:, :k], axis=1)

    extra = [list(c) for c in itertools.combinations(range(k), d - 1)]
    combos = np.concatenate(
        [np.repeat(pair[:, None, :], len(extra), axis=1), near[:, extra]], axis=2
    )
    cells, alpha, min_alpha = _best_combination(geom, facets, combos)

    retry = np.flatnonzero(min_alpha < -_INSIDE_TOL)
    if retry.size:
        full = [list(c) for c in itertools.combinations(range(k), d + 1)]
        c2, a2, m2 = _best_combination(geom, facets[retry], near[retry][:, full])
        better = m2 > min_alpha[retry]
        cells[retry[better]], alpha[retry[better]], min_alpha[retry[better]] = c2[better], a2[better], m2[better]
    if np.any(min_alpha < _MAX_EXTRAPOLATION):
        bad = facets[min_alpha < _MAX_EXTRAPOLATION]
        raise ValueError(
            f"no simplex of {d + 1} cell barycentres near interior facet {bad[0]} at "
            f"{geom.facet_centres[bad[0]].tolist()} interpolates its barycentre ({bad.size} such "
            "facets); the mesh is too distorted there for the DEM reconstruction of eq. (7)"
        )
    inside = min_alpha >= -_INSIDE_TOL
    alpha[inside] = np.clip(alpha[inside], 0.0, 1.0)
    alpha /= alpha.sum(axis=1, keepdims=True)
    return InteriorStencils(facets=facets, cells=cells, alpha=alpha, extrapolated=facets[~inside])


def _block_coo(rows: np.ndarray, cols: np.ndarray, blocks: np.ndarray, d: int):
    """COO triplets of d x d blocks ``blocks`` (n, d, d) at block positions (rows, cols)."""
    i, j = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
    r = (rows[:, None, None] * d + i).ravel()
    c = (cols[:, None, None] * d + j).ravel()
    return r, c, blocks.ravel()


def compute_reconstruction(
    geom: MeshGeometry,
    material: ElasticMaterial,
    dirichlet_facets: np.ndarray,
    scheme: str,
) -> Reconstruction:
    """Assemble R and D (eq. (6)) for the given Dirichlet facets and Neumann scheme "A" or "B"."""
    if scheme not in ("A", "B"):
        raise ValueError(f"boundary scheme must be 'A' or 'B', got {scheme!r}")
    d, N, F = geom.d, geom.num_cells, geom.num_facets
    dirichlet_facets = np.unique(np.asarray(dirichlet_facets, dtype=np.int64))
    boundary = geom.boundary_facets
    if not np.isin(dirichlet_facets, boundary).all():
        bad = dirichlet_facets[~np.isin(dirichlet_facets, boundary)]
        raise ValueError(f"Dirichlet facets must lie on the boundary; facet {bad[0]} is interior")
    neumann = np.setdiff1d(boundary, dirichlet_facets)
    eye = np.broadcast_to(np.eye(d), (max(len(neumann), len(dirichlet_facets), 1), d, d))

    stencils = compute_interior_stencils(geom)
    fi = np.repeat(stencils.facets, d + 1)
    ci = stencils.cells.ravel()
    blocks = stencils.alpha.ravel()[:, None, None] * np.eye(d)
    r_int = _block_coo(fi, ci, blocks, d)

    # Scheme A applies to the Neumann facets of cells with exactly one Neumann facet.
    ncell = geom.facet_cells[neumann, 0]
    per_cell = np.bincount(ncell, minlength=N)
    multi = np.flatnonzero(per_cell > 1)
    is_a = np.full(neumann.shape, scheme == "A") & (per_cell[ncell] == 1)
    b_facets = neumann[~is_a]
    r_b = _block_coo(b_facets, geom.facet_cells[b_facets, 0], eye[: len(b_facets)], d)

    nD = len(dirichlet_facets)
    d_rows = _block_coo(dirichlet_facets, np.arange(nD), eye[:nD], d)
    R0 = scipy.sparse.coo_matrix(
        (np.concatenate([r_int[2], r_b[2]]), (np.concatenate([r_int[0], r_b[0]]),
         np.concatenate([r_int[1], r_b[1]]))), shape=(F * d, N * d)).tocsr()
    D0 = scipy.sparse.coo_matrix((d_rows[2], (d_rows[0], d_rows[1])), shape=(F * d, nD * d)).tocsr()

    a_facets = neumann[is_a]
    if len(a_facets):
        T = _scheme_a_operator(geom, material, a_facets)
        R = R0 + T @ R0
        D = D0 + T @ D0
    else:
        R, D = R0, D0
    return Reconstruction(
        R=R.tocsr(),
        D=D.tocsr(),
        dirichlet_facets=dirichlet_facets,
        neumann_facets=neumann,
        scheme_a_facets=a_facets,
        scheme=scheme,
        multi_neumann_cells=multi if scheme == "A" else np.empty(0, dtype=np.int64),
        stencils=stencils,
    )


def _scheme_a_operator(geom: MeshGeometry, material: ElasticMaterial, facets: np.ndarray):
    """Facet-to-facet map of eq. (20)-(21): u_f = sum_{f' in dc, f' != f} T_{f f'} u_{f'}.

    sigma_c n_f = sum_{f'} (1/|c|) C : (u_{f'} (x) a_{f'}) n_f with a_{f'} = |f'| n_{f',c}; the
    term of f itself is A u_f with A = (1/|c|) C[n_f, a_f] invertible, so T_{f f'} = -A^{-1} B_{f'}.
    """
    d = geom.d
    C = material.elasticity_tensor(d)
    c = geom.facet_cells[facets, 0]
    j = geom.facet_local[facets, 0]
    a = geom.facet_area_normals[c]  # (n, d+1, d)
    n_f = a[np.arange(len(c)), j] / geom.facet_areas[facets, None]
    # B[k]_{ik} = sum_{jl} C_ijkl n_j a_l / |c|, for every local facet of the cell
    B = np.einsum("ijkl,nj,nml->nmik", C, n_f, a) / geom.cell_volumes[c, None, None, None]
    A = B[np.arange(len(c)), j]
    Ainv_B = np.linalg.solve(A[:, None], B)  # (n, d+1, d, d)
    rows, cols, blocks = [], [], []
    for k in range(d + 1):
        other = k != j
        rows.append(facets[other])
        cols.append(geom.cell_facets[c[other], k])
        blocks.append(-Ainv_B[other, k])
    r, cc, v = _block_coo(np.concatenate(rows), np.concatenate(cols), np.concatenate(blocks), d)
    F = geom.num_facets
    return scipy.sparse.coo_matrix((v, (r, cc)), shape=(F * d, F * d)).tocsr()
