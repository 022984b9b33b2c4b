"""The directions of the contact corrections of a pair of candidate facets (paper §3.4.3, eq.
(23)-(24) for scheme A, eq. (26)-(27) for scheme B), with the rule that keeps them well posed.
"""

from __future__ import annotations

import numpy as np

from dolfinx_dem.contact.facets import CandidateFacets
from dolfinx_dem.contact.overlap import adjugate_times


def correction_directions(F: CandidateFacets, i: np.ndarray, j: np.ndarray, n: np.ndarray, rigid: np.ndarray,
                          rank: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The directions (e_i, e_j) of the contact corrections of the pairs (i, j) of facets ``F`` of
    common normals ``n``, and the keys of the pairs that use the scheme B rule below and whose
    first facet this process (``rank``) owns: u_f += (w/|f|) g^- e_f, u_f' += (w/|f'|) g^- e_f'.
    ``rigid``: whether each body is prescribed.

    Scheme B (eq. (26)-(27), theta = 1/2): e_f = n/2, e_f' = -n/2. Scheme A (eq. (23)-(24)),
    when both facets are scheme A facets: with A_f x = (C : (x (x) a_f)) n / |c| the change
    of cell c's traction on n when u_f changes by x, e_f = A_f^-1 n / D, e_f' = A_f'^-1 n / D,
    D = n . A_f^-1 n - n . A_f'^-1 n: the corrections change both cells' tractions on n by
    the same normal vector, and n . (e_f - e_f') = 1 closes the gap of a fully overlapping
    pair. (The tractions on n themselves are normal and equal only where the free ones
    vanish on n, i.e. when n = n_f = -n_f': the free facets carry zero traction on their
    own normals.)

    A facet of a prescribed body (``rigid``) moves rigidly with it:
    e = 0 on it and the other facet takes the whole correction, e_f' = -n (or e_f = n), as a
    facet on a rigid obstacle does; a pair of two prescribed bodies is not listed.

    When eq. (23)-(24) are not well posed the pair uses the scheme B rule; ``PairContact.scheme_b_pairs``
    counts such pairs (``summary.json``: ``contact_pairs_scheme_b_rule``). For isotropic C,
    n . A_f^-1 n = cos t_f / (alpha_f (2 cos^2 t_f (lambda + mu) - lambda)), alpha_f = |f|/|c|,
    t_f the angle between n and n_f: a cell's normal compliance has the sign of its facet
    normal's side only if cos^2 t_f > kappa = lambda / (2 (lambda + mu)) (nu in 3D and plane
    strain, nu/(1+nu) in plane stress; A_f maps the plane of n and n_f to itself, so the
    formula holds in 2D and 3D). The rule of eq. (23)-(24) is used when both cells'
    compliances have their sign (n . A_f^-1 n > 0 > n . A_f'^-1 n): then 0 < n . e_f < 1,
    0 < -n . e_f' < 1 and |e_f| = n . e_f / cos t_f < 1/sqrt(kappa), bounded. Otherwise
    D may vanish (unbounded corrections, an arbitrarily stiff pair), be negative (no
    solution: the correction would open the penetration further), or be positive with one
    facet moved further into the other body. Facing facets of equal length have
    t_f = t_f' < 45 deg, and kappa < 1/2, so only pairs of unequal facets whose normals are
    far from antiparallel (the longer facet tilts n towards its own normal) are affected.
    A set-up check cannot replace this rule: every pair of facing candidate facets could
    meet, and a curved boundary has facets of every orientation. The directions depend on
    the pair only, so the energy stays continuous and the force its exact gradient."""
    e_i, e_j = 0.5 * n, -0.5 * n
    keys = np.empty(0, dtype=np.int64)
    both_a = F.scheme_a[i] & F.scheme_a[j]
    if both_a.any():
        k = np.flatnonzero(both_a)
        # A_f^-1 n = adj(A_f) n / det(A_f), so that a singular A_f is no error.
        y, compliance = [], []
        for f in (i, j):
            A = np.einsum("nijk,nj->nik", F.Ca[f[k]], n[k])
            adj_n, det = adjugate_times(A, n[k])
            y.append(np.divide(adj_n, det[:, None], out=np.zeros_like(adj_n), where=det[:, None] != 0))
            compliance.append(np.where(det != 0, np.einsum("pi,pi->p", n[k], y[-1]), 0.0))
        posed = (compliance[0] > 0) & (compliance[1] < 0)
        D = compliance[0] - compliance[1]
        a = k[posed]
        e_i[a], e_j[a] = y[0][posed] / D[posed, None], y[1][posed] / D[posed, None]
        counted = k[~posed][F.owner[i[k[~posed]]] == rank]  # the first facet's owner counts it
        keys = F.key[i[counted]] * (2**31) + F.key[j[counted]]
    # A prescribed (rigid) body's facet keeps its imposed motion: the deformable facet takes
    # the whole correction (theta = 0 or 1 in eq. (26)-(27), as on a rigid obstacle).
    rigid_i, rigid_j = rigid[F.body[i]], rigid[F.body[j]]
    e_i[rigid_i], e_j[rigid_i] = 0.0, -n[rigid_i]
    e_i[rigid_j], e_j[rigid_j] = n[rigid_j], 0.0
    return e_i, e_j, keys
