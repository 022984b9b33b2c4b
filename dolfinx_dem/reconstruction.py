"""Facet reconstruction u_F = R u_C + D g + N t (paper §3.1 eq. (6)-(7), §3.4 eq. (19)-(21), scheme B).

- Interior facets: barycentric interpolation from d+1 cells whose barycentres form a simplex
  containing the facet barycentre (eq. (7)), coefficients in [0, 1].
- Dirichlet facets: the imposed value, u_f = g_f (the columns of D), in the fixed components of
  the facet's condition; the other (free) components are reconstructed as on a Neumann facet.
- Interior facets between two materials (``CellMaterials``): u_f makes the tractions of the two
  cells equal, sigma_c1 n_f = sigma_c2 n_f, given the cells' other facets (eq. (19)-(21) written
  for the pair of cells), so that a piecewise affine field whose tractions are continuous is
  reconstructed exactly (springs in series); eq. (7)'s interpolation does not see the materials.
- Neumann facets, scheme B: u_f = u_c, the facet follows its cell (free components likewise).
- Neumann facets, scheme A: u_f solves sigma_c n_f = t_f (eq. (19)-(21), t_f = 0 on a traction-free
  facet) given the cell's other facets; on a partly fixed Dirichlet facet the free components
  solve (sigma_c n_f)_i = 0 for the free i (zero traction conjugate to the free displacement,
  e.g. zero tangential traction on a roller). The traction enters as the affine term N t. A cell
  with more than one such open facet has no unique local solution (every rectangle corner);
  dolfinx_dem applies scheme B to the open facets of such cells and reports them in
  ``Reconstruction.multi_neumann_cells``.

Matrices act on flattened vectors: cell dof ``c*d + i``, facet dof ``f*d + i``, Dirichlet value
``k*d + i`` for the k-th Dirichlet facet, traction ``k*d + i`` for the k-th traction facet.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import scipy.sparse

from dolfinx_dem.errors import InputError
from dolfinx_dem.geometry import MeshGeometry
from dolfinx_dem.material import CellMaterials

#: Number of candidate cells (the nearest of the facet's mesh neighbourhood), by dimension.
_NEIGHBOURS = {1: 2, 2: 10, 3: 14}
#: Candidate simplices per block of facets (memory bound of the stencil search).
_CHUNK = 2**22
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
    """u_F = R u_C + D g + N t with R of shape (F d, N d), D of shape (F d, n_D d) and N of shape
    (F d, n_T d)."""

    R: scipy.sparse.csr_matrix
    D: scipy.sparse.csc_matrix  # CSC: entries on the Dirichlet facets' neighbourhood only, no pointer per row
    N: scipy.sparse.csc_matrix  # traction lift of scheme A, nonzero on scheme A traction facets only; CSC as D
    dirichlet_facets: np.ndarray  # (n_D,) global facet indices, the order of g
    fixed: np.ndarray  # (n_D, d) bool: the components each Dirichlet facet fixes
    traction_facets: np.ndarray  # (n_T,) the order of t
    neumann_facets: np.ndarray  # (n_N,) global facet indices
    scheme_a_facets: np.ndarray  # the Neumann facets reconstructed by scheme A (eq. (20))
    scheme: str
    multi_neumann_cells: np.ndarray  # cells where scheme A fell to scheme B (rule above)
    # interior facets with no containing simplex (``compute_interior_stencils``); the stencils
    # themselves are the interior rows of R (not kept twice)
    extrapolated_facets: np.ndarray


def _barycentric(points: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates of x (..., d) in simplices ``points`` (..., d+1, d), d <= 3.

    Returns (alpha (..., d+1), valid (...)); degenerate simplices (|det| <= 1e-8 times the
    product of the edge lengths) are not valid. Cramer's rule, vectorised: a batched LAPACK
    solve costs a call per 3 x 3 system.
    """
    d = x.shape[-1]
    e = points[..., 1:, :] - points[..., :1, :]  # (..., d, d), rows are edges
    r = x - points[..., 0, :]
    if d == 1:
        det = e[..., 0, 0]
        numerators = [r[..., 0]]
    elif d == 2:
        cross = lambda a, b: a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]  # noqa: E731
        det = cross(e[..., 0, :], e[..., 1, :])
        numerators = [cross(r, e[..., 1, :]), cross(e[..., 0, :], r)]
    else:
        triple = lambda a, b, c: np.einsum("...i,...i->...", a, np.cross(b, c))  # noqa: E731
        det = triple(e[..., 0, :], e[..., 1, :], e[..., 2, :])
        numerators = [triple(r, e[..., 1, :], e[..., 2, :]), triple(e[..., 0, :], r, e[..., 2, :]),
                      triple(e[..., 0, :], e[..., 1, :], r)]
    scale = np.prod(np.linalg.norm(e, axis=-1), axis=-1)
    valid = np.abs(det) > 1e-8 * scale
    safe = np.where(valid, det, 1.0)
    beta = np.stack([num / safe for num in numerators], axis=-1)
    alpha = np.concatenate([1 - beta.sum(axis=-1, keepdims=True), beta], axis=-1)
    return alpha, valid


def _best_combination(geom: MeshGeometry, facets, combos, alpha, valid):
    """Among candidate cell tuples ``combos`` (n, m, d+1), with the barycentric coordinates
    ``alpha`` (n, m, d+1) of the facet barycentres in them and their validity (n, m), pick the
    most central containing simplex.

    The key is the smallest barycentric coordinate (largest wins, rounded to 9 digits), then the
    compactness of the simplex, then the lexicographic order of its sorted barycentre positions.
    Every key is geometric and rounded, so the choice does not depend on the cell numbering or
    on summation order: serial and parallel runs pick the same simplices. The secondary keys are
    only computed for the simplices tied on the first.
    """
    n, m, k = combos.shape
    d = geom.d
    xc = geom.cell_centres
    xf = geom.facet_centres[facets]
    distinct = np.all(np.diff(np.sort(combos, axis=-1), axis=-1) > 0, axis=-1)
    valid = valid & distinct & (combos >= 0).all(axis=-1)
    min_alpha = np.where(valid, alpha.min(axis=-1), -np.inf)
    key = np.round(min_alpha, 9)
    tied_row, tied = np.nonzero(key == key.max(axis=1, keepdims=True))  # row-major: grouped by row
    diameters = geom.facet_diameters[facets[tied_row], None, None]
    rel = np.round((xc[combos[tied_row, tied]] - xf[tied_row, None, :]) / diameters, 9)
    spread = np.round(np.sum(rel**2, axis=(-1, -2)), 7)
    point_order = np.lexsort([rel[:, :, i] for i in reversed(range(d))], axis=-1)
    canonical = np.take_along_axis(rel, point_order[:, :, None], axis=1).reshape(len(tied), k * d)
    order = np.lexsort([canonical[:, i] for i in reversed(range(k * d))] + [spread, tied_row])
    first = order[np.searchsorted(tied_row[order], np.arange(n))]
    rows, best = tied_row[first], tied[first]
    return combos[rows, best], alpha[rows, best], min_alpha[rows, best]


def _facet_vertex_ids(geom: MeshGeometry, facets: np.ndarray) -> np.ndarray:
    """Vertex numbers of the given facets, (n, d): their first cell's vertices but the opposite one."""
    c, j = geom.facet_cells[facets, 0], geom.facet_local[facets, 0]
    mask = np.ones((len(facets), geom.d + 1), dtype=bool)
    mask[np.arange(len(facets)), j] = False
    return geom.cell_vertex_ids[c][mask].reshape(len(facets), geom.d)


def _incidence(rows: np.ndarray, cols: np.ndarray, shape) -> scipy.sparse.csr_matrix:
    """The 0/1 matrix with ones at (rows[i], cols[i, j]) for an (n, k) array ``cols``."""
    data = np.ones(cols.size, dtype=np.int32)
    M = scipy.sparse.csr_matrix((data, (np.repeat(rows, cols.shape[1]), cols.ravel())), shape=shape)
    M.data[:] = 1
    return M


class _MeshGraph:
    """Vertex-to-cell incidence of the mesh, for neighbourhoods in the mesh graph."""

    def __init__(self, geom: MeshGeometry):
        ids, inverse = np.unique(geom.cell_vertex_ids, return_inverse=True)
        self.geom = geom
        self.ids = ids
        N = geom.num_cells
        # (V, N): vertex v belongs to cell c
        self.vertex_cells = _incidence(np.arange(N), inverse.reshape(N, -1), (N, len(ids))).T.tocsr()

    def vertex_star(self, vertex_ids: np.ndarray) -> scipy.sparse.csr_matrix:
        """(n, N): the cells containing some vertex of row i of ``vertex_ids`` (n, k)."""
        n = vertex_ids.shape[0]
        rows = _incidence(np.arange(n), np.searchsorted(self.ids, vertex_ids), (n, len(self.ids)))
        return (rows @ self.vertex_cells).tocsr()

    def widen(self, cells: scipy.sparse.csr_matrix) -> scipy.sparse.csr_matrix:
        """(n, N): the cells sharing a vertex with a cell of row i of ``cells`` (n, N)."""
        return ((cells @ self.vertex_cells.T) @ self.vertex_cells).tocsr()


def _nearest_in(geom: MeshGeometry, facets: np.ndarray, neighbourhood: scipy.sparse.csr_matrix, k: int):
    """The k cells of each facet's neighbourhood (row i for ``facets[i]``) inside the facet's body
    nearest to its barycentre, (n, k), padded with -1. Ordered by distance / h_f (rounded to 9
    digits), then by x + pi y + e z: a geometric order, independent of the numbering."""
    coo = neighbourhood.tocoo()
    row, cell = coo.row, coo.col.astype(np.int64)
    same = geom.cell_bodies[cell] == geom.cell_bodies[geom.facet_cells[facets[row], 0]]
    row, cell = row[same], cell[same]
    x = geom.cell_centres[cell]
    dist = np.linalg.norm(x - geom.facet_centres[facets[row]], axis=1) / geom.facet_diameters[facets[row]]
    position = x @ np.array([1.0, np.pi, np.e][: geom.d])
    order = np.lexsort((position, np.round(dist, 9), row))
    row, cell = row[order], cell[order]
    first = np.searchsorted(row, np.arange(len(facets)))
    rank = np.arange(len(row)) - first[row]
    near = np.full((len(facets), k), -1, dtype=np.int64)
    keep = rank < k
    near[row[keep], rank[keep]] = cell[keep]
    return near


def compute_interior_stencils(geom: MeshGeometry, facets: np.ndarray | None = None) -> InteriorStencils:
    """Eq. (7) for the interior facets among ``facets`` (default: all), with candidate cells from
    the mesh graph.

    The candidates of facet f are the cells of its body nearest to x_f (k = 2, 10, 14 in 1D, 2D,
    3D, see ``_nearest_in``) among its neighbourhood in the mesh: first the cells that share a
    vertex with f, then, for facets with no containing simplex among those, the cells that share
    a vertex with them. A stencil therefore never reaches across a gap between two bodies or
    across a slot in one body, whatever the distances, and it is computable from a bounded halo
    of cells around the facet.

    First the two adjacent cells plus d-1 of the candidates are tried (the segment between the
    adjacent barycentres crosses the facet), then any d+1 of them, then any d+1 of the wider
    neighbourhood's nearest.

    Near the boundary a facet barycentre can lie outside the convex hull of the barycentres (in
    3D at the edges of a box, for instance). Rule: such a facet is reconstructed from the least
    extrapolating simplex, the one whose smallest barycentric coordinate is largest; the
    reconstruction stays exact for affine fields, and the facet is listed in ``extrapolated``.
    If even that coordinate is below -1, a ValueError names the facet.
    """
    graph = _MeshGraph(geom)
    facets = geom.interior_facets if facets is None else np.intersect1d(geom.interior_facets, facets)
    m = math.comb(_NEIGHBOURS[geom.d], geom.d - 1) * (geom.d + 1)
    chunk = max(1, _CHUNK // m)  # facets per block: bounds the memory of the candidate arrays
    parts = [_stencils_of(geom, graph, facets[i : i + chunk]) for i in range(0, len(facets), chunk)]
    cells, alpha, min_alpha = (np.concatenate(x) for x in zip(*parts)) if parts else (
        np.empty((0, geom.d + 1), np.int64), np.empty((0, geom.d + 1)), np.empty(0))
    if np.any(min_alpha < _MAX_EXTRAPOLATION):
        bad = facets[min_alpha < _MAX_EXTRAPOLATION]
        raise InputError(
            f"no simplex of {geom.d + 1} cell barycentres near interior facet {bad[0]} at "
            f"{geom.facet_centres[bad[0]].tolist()} interpolates its barycentre ({bad.size} such "
            "facets); the mesh is too distorted there for the DEM reconstruction of eq. (7)"
        )
    inside = min_alpha >= -_INSIDE_TOL
    alpha[inside] = np.clip(alpha[inside], 0.0, 1.0)
    alpha /= alpha.sum(axis=1, keepdims=True)
    return InteriorStencils(facets=facets, cells=cells, alpha=alpha, extrapolated=facets[~inside])


def _stencils_of(geom: MeshGeometry, graph: _MeshGraph, facets: np.ndarray):
    """(cells (n, d+1), alpha (n, d+1), smallest coordinate (n,)) of the best simplex of each of
    the interior ``facets``, by the passes of ``compute_interior_stencils``."""
    d, k = geom.d, _NEIGHBOURS[geom.d]
    pair = geom.facet_cells[facets]
    star = graph.vertex_star(_facet_vertex_ids(geom, facets))
    near = _nearest_in(geom, facets, star, k)
    cells, alpha, min_alpha = _best_combination(geom, facets, *_pair_simplices(geom, facets, pair, near))

    full = np.array(list(itertools.combinations(range(k), d + 1)))
    for widen in (False, True):
        retry = np.flatnonzero(min_alpha < -_INSIDE_TOL)
        if not retry.size:
            break
        near_retry = _nearest_in(geom, facets[retry], graph.widen(star[retry]), k) if widen else near[retry]
        combos = near_retry[:, full]
        xf = geom.facet_centres[facets[retry]]
        c2, a2, m2 = _best_combination(geom, facets[retry], combos,
                                       *_barycentric(geom.cell_centres[combos], xf[:, None, :]))
        better = m2 > min_alpha[retry]
        cells[retry[better]], alpha[retry[better]], min_alpha[retry[better]] = c2[better], a2[better], m2[better]
    return cells, alpha, min_alpha


def _pair_simplices(geom: MeshGeometry, facets: np.ndarray, pair: np.ndarray, near: np.ndarray):
    """The simplices made of each facet's two cells ``pair`` (n, 2) and d-1 of its candidates
    ``near`` (n, k): (cells (n, m, d+1), alpha (n, m, d+1), valid (n, m)), m = C(k, d-1).

    Cramer's rule as in ``_barycentric`` with the origin at the first cell, x_1: with e = x_2 - x_1,
    e_a = x_a - x_1 and r = x_f - x_1, every determinant is a dot product of per-candidate
    vectors (in 3D det(e, e_a, e_b) = (e x e_a) . e_b), so the m simplices cost O(k^2) small
    products instead of m solves.
    """
    d = geom.d
    xc = geom.cell_centres
    x1 = xc[pair[:, 0]]
    e, r = xc[pair[:, 1]] - x1, geom.facet_centres[facets] - x1
    if d == 1:
        alpha, valid = _barycentric(xc[pair][:, None], geom.facet_centres[facets][:, None])
        return pair[:, None, :], alpha, valid
    ea = xc[near] - x1[:, None, :]  # (n, k, d)
    norm_e, norm_a = np.linalg.norm(e, axis=1), np.linalg.norm(ea, axis=2)
    if d == 2:
        cross = lambda a, b: a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]  # noqa: E731
        det = cross(e[:, None, :], ea)  # (n, k)
        numerators = [cross(r[:, None, :], ea), np.broadcast_to(cross(e, r)[:, None], det.shape)]
        scale = norm_e[:, None] * norm_a
        combos = np.concatenate([np.repeat(pair[:, None, :], near.shape[1], axis=1), near[:, :, None]], axis=2)
    else:
        a, b = np.triu_indices(near.shape[1], 1)
        e_x_a = np.cross(e[:, None, :], ea)  # (n, k, 3)
        r_x_a = np.cross(r[:, None, :], ea)
        dot_b = lambda u: np.einsum("nai,nbi->nab", u, ea)[:, a, b]  # noqa: E731
        det = dot_b(e_x_a)  # det(e, e_a, e_b)
        numerators = [dot_b(r_x_a),  # det(r, e_a, e_b)
                      (np.cross(e, r)[:, None, :] * ea).sum(axis=2)[:, b],  # det(e, r, e_b)
                      np.einsum("nai,ni->na", e_x_a, r)[:, a]]  # det(e, e_a, r)
        scale = norm_e[:, None] * norm_a[:, a] * norm_a[:, b]
        combos = np.concatenate([np.repeat(pair[:, None, :], len(a), axis=1), near[:, a, None], near[:, b, None]],
                                axis=2)
    valid = np.abs(det) > 1e-8 * scale
    safe = np.where(valid, det, 1.0)
    beta = np.stack([num / safe for num in numerators], axis=-1)
    alpha = np.concatenate([1 - beta.sum(axis=-1, keepdims=True), beta], axis=-1)
    return combos, alpha, valid


def _block_coo(rows: np.ndarray, cols: np.ndarray, blocks: np.ndarray, d: int):
    """COO triplets of d x d blocks ``blocks`` (n, d, d) at block positions (rows, cols)."""
    i, j = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
    r = (rows[:, None, None] * d + i).ravel()
    c = (cols[:, None, None] * d + j).ravel()
    return r, c, blocks.ravel()


def compute_reconstruction(
    geom: MeshGeometry,
    materials: CellMaterials,
    dirichlet_facets: np.ndarray,
    scheme: str,
    facets: np.ndarray | None = None,
    comm=None,
    fixed: np.ndarray | None = None,
    traction_facets: np.ndarray | None = None,
    scheme_b_facets: np.ndarray | None = None,
) -> Reconstruction:
    """Assemble R, D and N (eq. (6)) for the given Dirichlet facets and Neumann scheme "A" or "B".

    ``fixed`` (n_D, d) bool, in the order of ``dirichlet_facets``: the components each Dirichlet
    facet fixes (default: all). ``traction_facets``: the Neumann facets that carry a traction
    (default: none); they must not be Dirichlet facets. ``scheme_b_facets``: facets reconstructed
    by scheme B under scheme A (the contact candidates of method "dem-AB"). Only the rows of ``facets`` (default:
    all held facets; in parallel the facets of the cells in halo layers 0 and 1, see
    geometry.py) are computed; the others stay empty. ``comm``, if given, makes the input checks
    collective, so that every process raises the same error.
    """
    if scheme not in ("A", "B"):
        raise InputError(f"boundary scheme must be 'A' or 'B', got {scheme!r}")
    d, N, F = geom.d, geom.num_cells, geom.num_facets
    rows = np.arange(F) if facets is None else np.asarray(facets, dtype=np.int64)
    # an interface facet reads the reconstructions of its two cells' other facets
    requested, interface = rows, _interface_facets(geom, materials, rows)
    rows = np.union1d(rows, geom.cell_facets[geom.facet_cells[interface]].ravel())
    dirichlet_facets, first = np.unique(np.asarray(dirichlet_facets, dtype=np.int64), return_index=True)
    fixed = np.ones((len(dirichlet_facets), d), bool) if fixed is None else np.asarray(fixed, bool)[first]
    traction_facets = np.unique(np.asarray([] if traction_facets is None else traction_facets, dtype=np.int64))
    interior = dirichlet_facets[geom.facet_cells[dirichlet_facets, 1] >= 0]
    bad = geom.facet_global[interior[:1]].tolist()
    if comm is not None:
        bad = [f for b in comm.allgather(bad) for f in b]
    if bad:
        raise InputError(f"Dirichlet facets must lie on the boundary; facet {bad[0]} is interior")
    if np.isin(traction_facets, dirichlet_facets).any() or (geom.facet_cells[traction_facets, 1] >= 0).any():
        raise InputError("traction facets must be boundary facets without a Dirichlet condition")
    boundary = np.intersect1d(geom.boundary_facets, rows)
    neumann = np.setdiff1d(boundary, dirichlet_facets)

    stencils = compute_interior_stencils(geom, rows)
    # interior facets: alpha I blocks, stored by their diagonals only
    component = np.arange(d)
    r_int = ((np.repeat(stencils.facets, d + 1)[:, None] * d + component).ravel(),
             (stencils.cells.ravel()[:, None] * d + component).ravel(),
             np.repeat(stencils.alpha.ravel(), d))

    # Open facets: Neumann facets and partly fixed Dirichlet facets, with their free components.
    # Scheme A applies to the open facets of cells with exactly one open facet.
    partial = np.flatnonzero(~fixed.all(axis=1) & np.isin(dirichlet_facets, boundary))
    open_facets = np.concatenate([neumann, dirichlet_facets[partial]])
    free = np.concatenate([np.ones((len(neumann), d), bool), ~fixed[partial]])
    ocell = geom.facet_cells[open_facets, 0]
    per_cell = np.bincount(ocell, minlength=N)
    multi = np.flatnonzero(per_cell > 1)
    is_a = np.full(open_facets.shape, scheme == "A") & (per_cell[ocell] == 1)
    if scheme_b_facets is not None:
        is_a &= ~np.isin(open_facets, scheme_b_facets)
    # scheme B: the free components follow the cell
    b_free = free[~is_a]
    b_facets = np.repeat(open_facets[~is_a], b_free.sum(axis=1))
    b_comp = np.nonzero(b_free)[1]
    r_b = (b_facets * d + b_comp, geom.facet_cells[b_facets, 0] * d + b_comp, np.ones(len(b_facets)))

    nD, nT = len(dirichlet_facets), len(traction_facets)
    k_fix, i_fix = np.nonzero(fixed)
    R0 = scipy.sparse.coo_matrix(
        (np.concatenate([r_int[2], r_b[2]]), (np.concatenate([r_int[0], r_b[0]]),
         np.concatenate([r_int[1], r_b[1]]))), shape=(F * d, N * d)).tocsr()
    D0 = scipy.sparse.coo_matrix((np.ones(len(k_fix)), (dirichlet_facets[k_fix] * d + i_fix, k_fix * d + i_fix)),
                                 shape=(F * d, nD * d)).tocsr()

    a_facets = open_facets[is_a]
    lift = scipy.sparse.csr_matrix((F * d, nT * d))
    if len(a_facets):
        T, solve = _scheme_a_operator(geom, materials, a_facets, free[is_a])
        R = R0 + T @ R0
        D = D0 + T @ D0
        # traction lift: u_f += A^-1 t_f on the scheme A traction facets
        on = np.isin(a_facets, traction_facets)
        if on.any():
            r, c, v = _block_coo(a_facets[on], np.searchsorted(traction_facets, a_facets[on]), solve[on], d)
            lift = scipy.sparse.coo_matrix((v, (r, c)), shape=(F * d, nT * d)).tocsr()
            lift.eliminate_zeros()
    else:
        R, D = R0, D0
    if len(interface):
        # interface rows from the other facets' final rows; only the requested rows are kept
        keep = np.zeros(F * d)
        keep[(requested[:, None] * d + np.arange(d)).ravel()] = 1.0
        keep[(interface[:, None] * d + np.arange(d)).ravel()] = 0.0
        T = scipy.sparse.diags(keep) + _interface_operator(geom, materials, interface)
        R, D, lift = T @ R, T @ D, T @ lift
        neumann, a_facets = np.intersect1d(neumann, requested), np.intersect1d(a_facets, requested)
    return Reconstruction(
        R=R.tocsr(),
        D=D.tocsc(),
        N=lift.tocsc(),
        dirichlet_facets=dirichlet_facets,
        fixed=fixed,
        traction_facets=traction_facets,
        neumann_facets=neumann,
        scheme_a_facets=a_facets,
        scheme=scheme,
        multi_neumann_cells=multi if scheme == "A" else np.empty(0, dtype=np.int64),
        extrapolated_facets=stencils.extrapolated,
    )


def _interface_facets(geom: MeshGeometry, materials: CellMaterials, facets: np.ndarray) -> np.ndarray:
    """The interior facets among ``facets`` whose two cells are of different materials."""
    facets = np.intersect1d(geom.interior_facets, facets)
    c = geom.facet_cells[facets]
    return facets[materials.index[c[:, 0]] != materials.index[c[:, 1]]]


def _interface_operator(geom: MeshGeometry, materials: CellMaterials, facets: np.ndarray) -> scipy.sparse.csr_matrix:
    """Facet-to-facet map of the interface ``facets`` (module docstring), (F d, F d):
    with n = n_{f,c1} and B^c_{f'} = (1/|c|) C_c[s_c n, a_{f'}] (s_c1 = 1, s_c2 = -1, as in
    ``_scheme_a_operator``), sigma_c1 n - sigma_c2 n = sum_c sum_{f' in dc} B^c_{f'} u_{f'} = 0
    gives u_f = -(A_1 + A_2)^-1 sum_c sum_{f' != f} B^c_{f'} u_{f'}, A_c = B^c_f symmetric
    positive definite."""
    d = geom.d
    an = geom.facet_area_normals[geom.facet_cells[facets, 0], geom.facet_local[facets, 0]]
    n = an / geom.facet_areas[facets, None]
    sides = []
    for side, sign in ((0, 1.0), (1, -1.0)):
        c, j = geom.facet_cells[facets, side], geom.facet_local[facets, side]
        B = np.einsum("nijkl,nj,nml->nmik", materials.elasticity_tensor(d, c), sign * n,
                      geom.facet_area_normals[c]) / geom.cell_volumes[c, None, None, None]
        sides.append((c, j, B))
    inverse = np.linalg.inv(sum(B[np.arange(len(facets)), j] for _, j, B in sides))
    rows, cols, blocks = [], [], []
    for c, j, B in sides:
        for k in range(d + 1):
            other = k != j
            rows.append(facets[other])
            cols.append(geom.cell_facets[c[other], k])
            blocks.append(-inverse[other] @ B[other, k])
    r, cc, v = _block_coo(np.concatenate(rows), np.concatenate(cols), np.concatenate(blocks), d)
    F = geom.num_facets
    return scipy.sparse.coo_matrix((v, (r, cc)), shape=(F * d, F * d)).tocsr()


def _scheme_a_operator(geom: MeshGeometry, materials: CellMaterials, facets: np.ndarray, free: np.ndarray):
    """Facet-to-facet map of eq. (20)-(21) for the free components ``free`` (n, d) of ``facets``:
    u_f = sum_{f' in dc} T_{f f'} u_{f'} + A_hat^-1 E t_f in the free components of u_f.

    sigma_c n_f = sum_{f'} B_{f'} u_{f'} with B_{f'} = (1/|c|) C_c[n_f, a_{f'}], a_{f'} = |f'| n_{f',c},
    C_c the elasticity tensor of the cell's material;
    A = B_f is the facet's own (symmetric positive definite) block. With E the projection on the
    free components, E (sigma_c n_f - t_f) = 0 and the fixed components (I - E) u_f given, the free
    ones solve A_hat x = E (t_f - sum_{f' != f} B_{f'} u_{f'} - A (I - E) u_f), A_hat = E A E + I - E:
    T_{f f'} = -A_hat^-1 E B_{f'}, T_{f f} = -A_hat^-1 E A (I - E) (zero on a Neumann facet).
    Returns (T (F d, F d), A_hat^-1 E (n, d, d)).
    """
    d = geom.d
    c = geom.facet_cells[facets, 0]
    C = materials.elasticity_tensor(d, c)
    j = geom.facet_local[facets, 0]
    a = geom.facet_area_normals[c]  # (n, d+1, d)
    n_f = a[np.arange(len(c)), j] / geom.facet_areas[facets, None]
    # B[k]_{ik} = sum_{jl} C_ijkl n_j a_l / |c|, for every local facet of the cell
    B = np.einsum("nijkl,nj,nml->nmik", C, n_f, a) / geom.cell_volumes[c, None, None, None]
    A = B[np.arange(len(c)), j]
    E = np.einsum("ni,ij->nij", free.astype(float), np.eye(d))
    A_hat = E @ A @ E + (np.eye(d) - E)
    solve = np.linalg.solve(A_hat, E)  # (n, d, d); its rows of fixed components are 0
    rows, cols, blocks = [], [], []
    for k in range(d + 1):
        other = k != j
        rows.append(facets[other])
        cols.append(geom.cell_facets[c[other], k])
        blocks.append(-solve[other] @ B[other, k])
    partial = ~free.all(axis=1)
    rows.append(facets[partial])
    cols.append(facets[partial])
    blocks.append(-solve[partial] @ A[partial] @ (np.eye(d) - E[partial]))
    r, cc, v = _block_coo(np.concatenate(rows), np.concatenate(cols), np.concatenate(blocks), d)
    F = geom.num_facets
    T = scipy.sparse.coo_matrix((v, (r, cc)), shape=(F * d, F * d)).tocsr()
    T.eliminate_zeros()
    return T, solve
