"""The overlap geometry of a pair of candidate facets (paper §3.4.3, eq. (31)-(34)).

The two facets of a pair are projected on the plane normal to their common normal n (basis t):
segments in 2D, triangles in 3D (``Simplices``). Their overlap w = |A cap (B + s)| depends on the
tangential offset s = t (u_f' - u_f) only, and is computed with its exact gradient by clipping
each simplex's boundary by the other (``overlap``); ``separations`` screens the pairs whose
projections cannot meet during a flight. The compiled kernels are in kernels/overlap.c.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from dolfinx_dem.contact.facets import CandidateFacets
from dolfinx_dem.kernels import Struct, lib, pointer


def gauss_legendre(d: int) -> tuple[np.ndarray, np.ndarray]:
    """d-point Gauss-Legendre nodes and weights on [0, 1]: exact to degree 2 d - 1, the degree
    of a pair's force term between events in dimension d (w of degree d - 1 in tau, c_p and
    z_p . (a + delta_a) of degree d, dc_p/du of degree d - 1)."""
    x, weights = np.polynomial.legendre.leggauss(d)
    return 0.5 + 0.5 * x, 0.5 * weights


def tangents(n: np.ndarray) -> np.ndarray:
    """An orthonormal basis (P, d - 1, d) of the plane normal to each unit vector n (P, d)."""
    if n.shape[1] == 2:
        return np.stack([-n[:, 1], n[:, 0]], axis=1)[:, None]
    axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]  # the axis farthest from n
    t1 = np.cross(n, axis)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(n, t1)], axis=1)


@dataclasses.dataclass(frozen=True)
class Simplices:
    """Facets projected on their pair's plane: (d-1)-simplices (segments in 2D, triangles in 3D)
    with vertices X (P, d, d-1). Face k is the vertex X_k in 2D, the edge X_k X_k+1 in 3D; m_k is
    its outward normal in the plane, unnormalised so that m_k . (X_k+1 - X_k) is exactly 0 (ties
    are detected exactly), nu_k = m_k / |m_k|, and ``size`` its measure (1 for a vertex)."""

    X: np.ndarray
    m: np.ndarray
    nu: np.ndarray
    size: np.ndarray

    @staticmethod
    def of(X: np.ndarray) -> Simplices:
        """The simplices of vertices X (the compiled ``dem_simplices_of``; segments: the faces are
        the vertices, each facing away from the other)."""
        X = np.ascontiguousarray(X, dtype=np.float64)  # the layout of the kernel ``dem_overlap``
        m, nu, size = np.empty_like(X), np.empty_like(X), np.empty(X.shape[:2])
        lib.dem_simplices_of(len(X), X.shape[1], pointer(X), pointer(m), pointer(nu), pointer(size))
        return Simplices(X, m, nu, size)

    @functools.cached_property
    def struct(self) -> Struct:
        """X, m, nu, size for the kernels (``dem_simplices``; made once)."""
        return Struct("dem_simplices", X=self.X, m=self.m, nu=self.nu, size=self.size)


def project(F: CandidateFacets, f: np.ndarray, origin: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The vertices of the facets ``f`` relative to the barycentres of the facets ``origin``, on
    the tangents ``t`` (P, d-1, d) of their pairs' planes: (P, d, d-1) (the compiled
    ``dem_pair_project``)."""
    d = t.shape[2]
    X = np.empty((len(f), d, d - 1))
    lib.dem_pair_project(len(f), d, pointer(np.ascontiguousarray(f, dtype=np.int64)),
                         pointer(np.ascontiguousarray(origin, dtype=np.int64)), pointer(np.ascontiguousarray(F.ends)),
                         pointer(np.ascontiguousarray(F.centre)), pointer(np.ascontiguousarray(t)), pointer(X))
    return X


def separations(A: Simplices, B: Simplices) -> np.ndarray:
    """The separations of the compiled screen (``PairContact.free_flight``), (P, 2d) (the compiled
    ``dem_pair_separations``): for each face k of A, then of B, how far the other simplex's
    nearest vertex lies beyond the face's line (times |m_k|) at zero offset, min_b m_k . (Y_b - X_k)
    and min_a m'_k . (X_a - Y_k). At offset s, A and B (moved by s) are separated by that line
    while the first plus m_k . s, or the second minus m'_k . s, is positive: the face normals are
    the separating axes of two simplices in the plane, so a pair with none positive overlaps. Less
    a margin of 1e-9 |m_k| times the pair's size, far above rounding: the screen keeps a pair that
    touches within it (then clipped: its w may be 0), and drops only pairs whose overlap is 0."""
    out = np.empty((len(A.X), 2 * A.X.shape[1]))
    lib.dem_pair_separations(len(A.X), A.X.shape[1], A.struct.c, B.struct.c, 1e-9, pointer(out))
    return out


def overlap(A: Simplices, B: Simplices, p: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """w = |A_p cap (B_p + s)| and its gradient dw/ds (E, d-1) for the simplex pairs p (E,) and
    the offsets s (E, d-1): the compiled kernel ``dem_overlap`` (kernels/overlap.c).

    The divergence theorem, div x = d - 1 in the plane: w = 1/(d-1) int over the boundary of
    A cap (B + s) of x . nu, whose pieces are the faces of A clipped by B + s and the faces of
    B + s clipped by A (a face counts nu_k . x at its clipped centre times its clipped measure).
    Each face is clipped by the half-planes m_k . (x - X_k) <= 0 of the other simplex's faces
    (Liang-Barsky); a face of B + s lying on a face of A with the same outward normal is left
    out, so that a boundary piece common to both simplices is counted once (by A). Translating
    B + s by ds moves only its own boundary pieces inside A: dw/ds = sum_k nu_k
    |face_k(B + s) cap A|. Both are exact where w is smooth (off the events of the events)."""
    p = np.ascontiguousarray(p, dtype=np.int64)
    s = np.ascontiguousarray(s, dtype=np.float64)
    w, dw = np.empty(len(p)), np.empty(s.shape)
    lib.dem_overlap(len(p), s.shape[1], pointer(p), A.struct.c, B.struct.c, pointer(s), pointer(w), pointer(dw))
    return w, dw


def adjugate_times(A: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """adj(A) x and det(A) for matrices A (n, d, d), d = 2 or 3, and vectors x (n, d)."""
    if A.shape[1] == 2:
        adj_x = np.stack([A[:, 1, 1] * x[:, 0] - A[:, 0, 1] * x[:, 1],
                          A[:, 0, 0] * x[:, 1] - A[:, 1, 0] * x[:, 0]], axis=1)
        return adj_x, A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    c0, c1, c2 = A[:, :, 0], A[:, :, 1], A[:, :, 2]  # the rows of adj(A) are c1 x c2, c2 x c0, c0 x c1
    rows = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)
    return np.einsum("nij,nj->ni", rows, x), np.einsum("ni,ni->n", c0, rows[:, 0])
