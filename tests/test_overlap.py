"""The overlap of projected facets (eq. (31)'s w and its gradient) against clipping, the pair rows
Z^T, and the projection of facets on their pairs' planes."""


import numpy as np
import pytest


def _clipped_area(P, Q):
    """|P cap Q| of two triangles (3, 2) by Sutherland-Hodgman clipping (the reference)."""

    def ccw(T):
        a, b = T[1] - T[0], T[2] - T[0]
        return T if a[0] * b[1] - a[1] * b[0] > 0 else T[::-1]

    polygon, Q = list(ccw(P)), ccw(Q)
    for k in range(3):
        a, e = Q[k], Q[(k + 1) % 3] - Q[k]
        side = [e[0] * (x[1] - a[1]) - e[1] * (x[0] - a[0]) for x in polygon]  # >= 0 inside
        clipped = []
        for m in range(len(polygon)):
            x, y, sx, sy = polygon[m], polygon[(m + 1) % len(polygon)], side[m], side[(m + 1) % len(polygon)]
            if sx >= 0:
                clipped.append(x)
            if sx * sy < 0:
                clipped.append(x + sx / (sx - sy) * (y - x))
        polygon = clipped
        if not polygon:
            return 0.0
    x = np.array(polygon)
    return 0.5 * abs(np.sum(x[:, 0] * np.roll(x[:, 1], -1) - np.roll(x[:, 0], -1) * x[:, 1]))


UNIT = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])


@pytest.mark.parametrize(
    "B, s, kind",
    [
        ([[0.2, 0.3], [1.5, -0.2], [1.5, 0.5]], [0.0, 0.0], "smooth"),  # a vertex of each inside the other
        (-UNIT + [0.7, 0.7], [0.0, 0.0], "smooth"),  # edges crossing: a hexagon
        (UNIT * 0.3, [0.1, 0.2], "smooth"),  # B inside A
        (UNIT * 3.0, [-1.0, -0.5], "smooth"),  # A inside B
        (UNIT + [0.3, -0.8], [0.05, 0.1], "smooth"),  # partial overlap, a vertex of B inside A
        (UNIT, [2.0, 0.3], "smooth"),  # disjoint
        (UNIT, [0.0, 0.0], "kink"),  # identical: every edge on an edge of the other
        (UNIT[::-1], [0.5, 0.0], "kink"),  # an edge on an edge of the other, B clockwise
        (UNIT, [1.0, 0.0], "touching"),  # at a vertex
        (-UNIT + [1.0, 1.0], [0.0, 0.0], "touching"),  # along the hypotenuse
    ],
)
def test_overlap_of_triangles_and_its_gradient(B, s, kind):
    """w = |A cap (B + s)| (boundary clipping, ``overlap.overlap``) against Sutherland-Hodgman
    clipping in every configuration, and its gradient against central differences where w is
    smooth; touching triangles have w = 0 exactly. (At kinks, events split the steps.)"""
    from dolfinx_dem.contact.overlap import Simplices, overlap

    A, B, s = UNIT[None], np.asarray(B, float)[None], np.asarray(s, float)[None]
    pair = np.zeros(1, dtype=np.int64)
    w, dw = overlap(Simplices.of(A), Simplices.of(B), pair, s)
    assert w[0] == pytest.approx(_clipped_area(A[0], B[0] + s[0]), abs=1e-15)
    if kind == "smooth":
        h = 1e-6
        fd = [
            (
                overlap(Simplices.of(A), Simplices.of(B), pair, s + h * e)[0][0]
                - overlap(Simplices.of(A), Simplices.of(B), pair, s - h * e)[0][0]
            )
            / (2 * h)
            for e in np.eye(2)
        ]
        assert np.abs(dw[0] - fd).max() < 1e-9
    if kind == "touching":
        assert w[0] == 0.0 and not dw.any()


def test_pair_rows_are_the_product_of_the_directions_and_the_facet_columns():
    """Z^T of a list build, row p = sum over the pair's local facets f of QF's columns of f's dofs
    times e_f / |f| (the kernel ``dem_pair_rows``), has the bits and the pattern of scipy's
    E^T @ QF^T with sorted indices: the exact zeros of cancelling entries dropped, pairs with a
    ghost facet (no columns here) taking their local facet's columns only."""
    import scipy.sparse

    from dolfinx_dem.contact.facets import FacetRows

    rng = np.random.default_rng(3)
    d, n_local, n_known, rows = 2, 60, 80, 150
    QF = scipy.sparse.random(rows, n_local * d, density=0.04, format="csc", random_state=rng)
    QF.data = np.round(QF.data * 4) / 4  # exact cancellations below
    P = 200
    i, j = rng.integers(0, n_known, P), rng.integers(0, n_known, P)
    j = np.where(j == i, (j + 1) % n_known, j)
    e_i, e_j = rng.standard_normal((P, d)), rng.standard_normal((P, d))
    length = rng.uniform(0.5, 2.0, n_known)
    # two pairs whose columns cancel exactly: one facet twice with opposite directions is not a
    # pair, so take two facets with equal columns and opposite e / |f|
    QF = QF.tolil()
    QF[:, 2 * d : 3 * d] = QF[:, 1 * d : 2 * d]
    QF = QF.tocsc()
    length[1] = length[2] = 1.0
    i[:2], j[:2] = [1, 2], [2, 1]
    e_i[:2], e_j[:2] = [[1.0, 0.5], [1.0, 0.5]], [[-1.0, -0.5], [-1.0, -0.5]]

    ZT = FacetRows(QF, d).pair_rows(i, j, e_i, e_j, length)
    pairs, dofs, vals = [], [], []
    for side, e in ((i, e_i), (j, e_j)):
        mine = side < n_local
        dofs.append((side[mine, None] * d + np.arange(d)).ravel())
        pairs.append(np.repeat(np.flatnonzero(mine), d))
        vals.append((e[mine] / length[side[mine], None]).ravel())
    ET = scipy.sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(pairs), np.concatenate(dofs))), shape=(P, n_local * d)
    )
    expected = ET @ QF.T
    expected.sort_indices()
    assert ZT.has_sorted_indices and (ZT.data != 0).all()
    assert np.array_equal(ZT.indptr, expected.indptr) and np.array_equal(ZT.indices, expected.indices)
    assert np.array_equal(ZT.data, expected.data)
    assert ZT.indptr[1] == 0 and ZT.indptr[2] == 0  # the cancelling pairs: empty rows
    assert (np.diff(ZT.indptr)[2:] > 0).sum() > 50  # and many rows that are not empty


def test_overlap_of_random_triangles():
    """Random triangles of both orientations: area against clipping, gradient against central
    differences."""
    from dolfinx_dem.contact.overlap import Simplices, overlap

    rng = np.random.default_rng(0)
    A, B = rng.random((400, 3, 2)), rng.random((400, 3, 2)) - 0.3
    s = 0.3 * rng.standard_normal((400, 2))
    pairs = np.arange(400)
    w, dw = overlap(Simplices.of(A), Simplices.of(B), pairs, s)
    reference = [_clipped_area(A[k], B[k] + s[k]) for k in range(len(A))]
    assert np.abs(w - reference).max() < 1e-14 and (w > 0).sum() > 100
    h = 1e-7
    fd = np.stack(
        [
            (
                overlap(Simplices.of(A), Simplices.of(B), pairs, s + h * e)[0]
                - overlap(Simplices.of(A), Simplices.of(B), pairs, s - h * e)[0]
            )
            / (2 * h)
            for e in np.eye(2)
        ],
        axis=1,
    )
    assert np.abs(dw - fd).max() < 1e-7


@pytest.mark.parametrize("d", [2, 3])
def test_projected_simplices_by_their_formulas(d):
    """The compiled projection of facets on their pairs' planes (``_project``) and the simplices
    made of them (``Simplices.of``) against their formulas in numpy, on random facets and planes:
    vertices, faces' ends, outward normals (both orientations in 3D), unit normals and sizes."""
    import types

    from dolfinx_dem.contact.overlap import Simplices, project

    rng = np.random.default_rng(d)
    F = types.SimpleNamespace(ends=rng.random((50, d, d)) - 0.5, centre=rng.random((50, d)))
    i, j, t = rng.integers(0, 50, 300), rng.integers(0, 50, 300), rng.random((300, d - 1, d)) - 0.5
    X = np.einsum("pkx,pax->pka", F.ends[j] - F.centre[i][:, None], t)
    assert np.allclose(project(F, j, i, t), X, rtol=0, atol=1e-15)
    S = Simplices.of(X)
    if d == 2:  # the faces are the vertices, each facing away from the other
        m, size = X - X[:, ::-1], np.ones((300, 2))
    else:
        e = X[:, [1, 2, 0]] - X  # the edges, each from its vertex to the next
        a, b = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
        sign = np.sign(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])[:, None, None]
        assert (sign > 0).sum() > 100 and (sign < 0).sum() > 100
        m, size = sign * np.stack([e[..., 1], -e[..., 0]], axis=2), np.linalg.norm(e, axis=2)
    nu = m / np.linalg.norm(m, axis=2)[..., None]
    for got, want in ((S.m, m), (S.nu, nu), (S.size, size)):
        assert np.allclose(got, want, rtol=0, atol=1e-15)
    # outward: each face's normal points away from the opposite vertex (3D) or the other one (2D)
    opposite = X[:, [2, 0, 1]] if d == 3 else X[:, ::-1]
    assert (np.einsum("pka,pka->pk", S.m, opposite - X) < 0).all()
