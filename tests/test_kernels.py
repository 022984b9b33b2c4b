"""The compiled kernels (``dolfinx_dem.kernels``) against their numpy formulas, and the means of
calling them: C pointers to numpy arrays, the structs of ``dem_kernels.h``, the build's single
declaration of every kernel. The kernels that need a mesh (the flight, the contact state, the
force integral, the overlap, the pairs' rows) are tested through ``PairContact`` in
test_pair_contact.py, test_pair_contact3d.py and test_overlap.py."""

import gc
import pathlib

import numpy as np
import pytest
import scipy.sparse

from dolfinx_dem.kernels import Struct, _build, csr, csr_of, ffi, lib, pointer


def _random_csr(rng, n_rows, n_cols, density=0.3) -> scipy.sparse.csr_matrix:
    A = scipy.sparse.random(n_rows, n_cols, density=density, format="csr", random_state=rng)
    A.indptr, A.indices = A.indptr.astype(np.int32), A.indices.astype(np.int32)
    return A


def test_pointer_reads_the_arrays_data_and_refuses_what_a_kernel_cannot_read():
    """A pointer to a contiguous array reads its data (also read-only arrays, also past an
    offset), None is NULL; a non-contiguous array or another dtype raises instead of handing a
    kernel the wrong memory."""
    a = np.arange(6.0)
    a.flags.writeable = False
    p = pointer(a)
    assert p[0] == 0.0 and (p + 4)[0] == 4.0 and ffi.typeof(p + 4) is ffi.typeof("double *")
    assert pointer(np.array([3, 7], dtype=np.int32))[1] == 7 and pointer(np.array([-2], dtype=np.int8))[0] == -2
    assert pointer(None) == ffi.NULL
    with pytest.raises(ValueError, match="not C-contiguous"):
        pointer(np.zeros((3, 2)).T)
    with pytest.raises(ValueError, match="not C-contiguous"):
        pointer(np.arange(6.0)[::2])
    with pytest.raises(TypeError, match="float64, int32, int64 or int8 arrays, not float32"):
        pointer(np.zeros(3, dtype=np.float32))


def test_a_struct_keeps_its_arrays_alive_and_refuses_the_wrong_types():
    """A ``Struct`` points into the arrays it is given and keeps them alive (the only reference
    left); None is NULL, fields not given are zero, a nested struct is copied; an array of the
    wrong dtype for a field raises, and so does a CSR matrix too large for int32 indices."""
    s = Struct("dem_gauss", n=2, xi=np.array([0.25, 0.75]))
    gc.collect()
    assert s.c.n == 2 and s.c.xi[1] == 0.75 and s.c.wq == ffi.NULL
    A = csr(np.array([0, 1, 3]), np.array([2, 0, 1]), np.array([1.0, 2.0, 3.0]), 3)
    assert A.arrays["indices"].dtype == np.int32 and A.c.n_rows == 2 and A.c.n_cols == 3
    patch = Struct("dem_patch", Q=A, q=None)
    del A
    gc.collect()
    assert patch.c.Q.indices[2] == 1 and patch.c.Q.data[1] == 2.0 and patch.c.q == ffi.NULL
    with pytest.raises(TypeError):
        Struct("dem_gauss", xi=np.zeros(2, dtype=np.int64))
    with pytest.raises(TypeError):
        Struct("dem_pairs", i=np.zeros(2, dtype=np.int32))
    with pytest.raises(ValueError, match="at most 2147483647"):
        csr(np.array([0, 2**31]), np.zeros(0), np.zeros(0), 1)
    with pytest.raises(ValueError, match="at most 2147483647"):
        csr(np.array([0, 0]), np.zeros(0), np.zeros(0), 2**31)
    with pytest.raises(TypeError, match="scipy CSR matrix"):
        csr_of(scipy.sparse.csc_matrix(np.eye(2)))


def test_every_kernel_is_declared_once_and_takes_at_most_12_parameters():
    """The module's functions are those of dem_kernels.h (the cffi build reads it), each with
    at most 12 parameters (structs instead of long argument lists)."""
    header = (pathlib.Path(_build.__file__).parent / "dem_kernels.h").read_text()
    declared = set(dir(lib))
    assert len(declared) > 20 and all(f" {name}(" in header for name in declared)
    assert all(len(ffi.typeof(getattr(lib, name)).args) <= 12 for name in declared)
    assert "#" not in _build.declarations(header)


# -- rows.c ---------------------------------------------------------------------------------
def test_gram_apply_and_lift_sums_are_their_formulas():
    """dem_gram_apply: y <- alpha y + scale Q (x - shift[shift_index]), z += Q^T y, the squares
    of y summed over the elastic rows and the others; dem_lift_sums: the sums of scale y + q."""
    rng = np.random.default_rng(1)
    Q = _random_csr(rng, 30, 12)
    x, y0, z0 = rng.standard_normal(12), rng.standard_normal(30), rng.standard_normal(12)
    index, shift = rng.integers(0, 3, 12).astype(np.int32), rng.standard_normal(3)
    n_elastic, alpha, scale = 17, 0.5, 3.0
    for shifted in (False, True):
        y, z, sums = y0.copy(), z0.copy(), np.zeros(2)
        lib.dem_gram_apply(csr_of(Q).c, n_elastic, pointer(x), pointer(index if shifted else None),
                           pointer(shift if shifted else None), pointer(y), alpha, scale, pointer(z), pointer(sums))
        expected = alpha * y0 + scale * (Q @ (x - shift[index] if shifted else x))
        assert np.allclose(y, expected, rtol=1e-14, atol=1e-14)
        assert np.allclose(z, z0 + Q.T @ expected, rtol=1e-14, atol=1e-14)
        squares = expected**2
        assert np.allclose(sums, [squares[:n_elastic].sum(), squares[n_elastic:].sum()], rtol=1e-14)
    rows, q = np.array([1, 20, 25], dtype=np.int32), rng.standard_normal(3)
    sums = np.array([1.0, 2.0])
    lib.dem_lift_sums(3, pointer(rows), pointer(q), pointer(y0), scale, n_elastic, pointer(sums))
    lifted = scale * y0
    lifted[rows] += q
    change = lifted**2 - (scale * y0) ** 2
    assert np.allclose(sums, [1.0 + change[:n_elastic].sum(), 2.0 + change[n_elastic:].sum()], rtol=1e-13)


def test_memm_update_is_its_formula():
    """dem_memm_update: v_new = v_prev + 2 M^-1 (load - c (z_old + z_new)), u += dt v_next,
    the kinetic and pseudo-kinetic energies, f . u, the momenta of vbar and of the free bodies;
    z_old is zeroed."""
    rng = np.random.default_rng(2)
    n, bs, dt = 7, 2, 0.1
    c = 0.5 * dt**2
    mass = rng.random(n) + 1.0
    body = rng.integers(0, 2, n).astype(np.int32)
    z_old, z_new, load, u, v_next, v_prev, f = (rng.standard_normal(n * bs) for _ in range(7))
    sums = np.zeros(3 + bs + 2 * bs)
    p_sums = pointer(sums)
    cells = Struct("dem_memm_cells", n_blocks=n, bs=bs, dt=dt, c=c, mass=mass, minv=1.0 / mass, f=f, body=body,
                   sums=p_sums, total=p_sums + 3, momentum=p_sums + 3 + bs)
    u0, v_prev0, z0 = u.copy(), v_prev.copy(), z_old.copy()
    lib.dem_memm_update(cells.c, pointer(z_old), pointer(z_new), pointer(load), pointer(u), pointer(v_next),
                        pointer(v_prev), 1)
    m = np.repeat(mass, bs)
    v_new = v_prev0 + 2.0 / m * (load - c * (z0 + z_new))
    vbar = 0.5 * (v_next + v_new)
    assert np.allclose(v_prev, v_new, rtol=1e-14) and np.allclose(u, u0 + dt * v_next, rtol=1e-14)
    assert not z_old.any()
    assert np.allclose(sums[:3], [0.5 * m @ vbar**2, 0.5 * m @ (v_next * v_new), f @ u], rtol=1e-13)
    assert np.allclose(sums[3 : 3 + bs], (m * vbar).reshape(n, bs).sum(axis=0), rtol=1e-13)
    momentum = np.zeros((2, bs))
    np.add.at(momentum, body, (m * v_new).reshape(n, bs))
    assert np.allclose(sums[3 + bs :], momentum.ravel(), rtol=1e-13)


def test_transposed_pattern_and_column_ranges_are_scipys():
    """dem_transpose_pattern: the rows through each column of a block, as scipy's transpose
    (counts first, then the rows); dem_row_column_range: each row's smallest and largest column
    below a bound."""
    rng = np.random.default_rng(3)
    Q = _random_csr(rng, 40, 15)
    A = csr_of(Q)
    lo, hi = np.empty(40, dtype=np.int32), np.empty(40, dtype=np.int32)
    lib.dem_row_column_range(A.c, 10, pointer(lo), pointer(hi))
    for r in range(40):
        cols = Q.indices[Q.indptr[r] : Q.indptr[r + 1]]
        cols = cols[cols < 10]
        assert (lo[r], hi[r]) == ((cols.min(), cols.max()) if len(cols) else (10, -1))
    first, n_cols, ranges = 4, 8, np.array([0, 40], dtype=np.int64)
    ptr = np.empty(n_cols + 1, dtype=np.int32)
    lib.dem_transpose_pattern(A.c, pointer(ranges), 1, first, n_cols, pointer(ptr), ffi.NULL)
    rows = np.empty(ptr[-1], dtype=np.int32)
    lib.dem_transpose_pattern(A.c, pointer(ranges), 1, first, n_cols, pointer(ptr), pointer(rows))
    T = Q[:, first : first + n_cols].tocsc()
    T.sort_indices()
    assert np.array_equal(ptr, T.indptr) and np.array_equal(rows, T.indices)


def test_abs_gram_rowsums_are_those_of_the_matrix_whatever_the_split_of_the_rows():
    """dem_gram_abs_rowsums: r_i = sum_j |(Q^T Q)_ij| x_j (x NULL: the diagonal), with the rows
    of Q split between the own set and the other set in any way: the same bits."""
    rng = np.random.default_rng(4)
    n_rows, n = 50, 20
    Q = _random_csr(rng, n_rows, n, density=0.2)
    x = rng.random(n)
    K = abs((Q.T @ Q).toarray())

    def rowsums(own_rows: np.ndarray, x):
        other_rows = np.setdiff1d(np.arange(n_rows), own_rows)
        sets = []
        for rows in (own_rows, other_rows):
            A = Q[rows]
            T = A.tocsc()
            sets.append(Struct("dem_row_set", rows=csr_of(A), key=rows.astype(np.int64),
                               qt_ptr=T.indptr.astype(np.int32), qt_rows=T.indices.astype(np.int32)))
        r, acc = np.empty(n), np.zeros(n)
        lib.dem_gram_abs_rowsums(0, n, sets[0].c, sets[1].c, pointer(x), pointer(r), pointer(acc))
        assert not acc.any()
        return r

    every = rowsums(np.arange(n_rows), x)
    assert np.allclose(every, K @ x, rtol=1e-13)
    assert np.array_equal(rowsums(np.flatnonzero(rng.random(n_rows) < 0.5), x), every)
    assert np.allclose(rowsums(np.arange(0, n_rows, 3), None), np.diag(K), rtol=1e-13)


# -- overlap.c, flight.c ---------------------------------------------------------------------
def test_separations_and_csr_products_are_their_formulas():
    """dem_pair_separations: for each face k of A (then of B) the smallest m_k . (Y_b - X_k) over
    the other's vertices, less margin |m_k| times the largest |coordinate|; dem_csr_apply: R x +
    lift."""
    from dolfinx_dem.contact.overlap import Simplices

    rng = np.random.default_rng(5)
    A, B = Simplices.of(rng.standard_normal((6, 3, 2))), Simplices.of(rng.standard_normal((6, 3, 2)))
    out = np.empty((6, 6))
    lib.dem_pair_separations(6, 3, A.struct.c, B.struct.c, 1e-3, pointer(out))
    size = np.maximum(np.abs(A.X).max(axis=(1, 2)), np.abs(B.X).max(axis=(1, 2)))
    for side, (S, T) in enumerate(((A, B), (B, A))):
        h = np.einsum("pkc,pbc->pkb", S.m, T.X) - np.einsum("pkc,pkc->pk", S.m, S.X)[..., None]
        expected = h.min(axis=2) - 1e-3 * np.linalg.norm(S.m, axis=2) * size[:, None]
        assert np.allclose(out[:, 3 * side : 3 * side + 3], expected, rtol=1e-13, atol=1e-14)
    R = _random_csr(rng, 9, 5)
    x, lift, y = rng.standard_normal(5), rng.standard_normal(9), np.empty(9)
    lib.dem_csr_apply(csr_of(R).c, pointer(x), pointer(lift), pointer(y))
    assert np.array_equal(y, R @ x + lift)


def _pairs(rng, n_facets=6, n=5, d=3):
    """A list of n pairs of n_facets facets (no geometry: what the outputs read)."""
    i, j = rng.integers(0, n_facets, n), rng.integers(0, n_facets, n)
    normal = rng.standard_normal((n, d))
    e_i, e_j = 0.5 * normal, -0.5 * normal
    reference, half_skin2 = rng.standard_normal((n_facets, d)), rng.random(n_facets) + 0.5
    return Struct("dem_pairs", d=d, n_facets=n_facets, reference=reference, half_skin2=half_skin2, n=n, i=i, j=j,
                  normal=normal, e_i=e_i, e_j=e_j)


def _penetration(pairs, state, centre, normals, reach, length, n_own, uf=None):
    """dem_pair_penetration's (depth, scale, worst) of the first n_own facets (2D pairs)."""
    n = len(centre)
    depth, scale, worst = np.zeros(n_own), np.zeros(n_own), np.empty(2)
    uf = np.zeros_like(centre) if uf is None else uf
    lib.dem_pair_penetration(pairs.c, state.c, pointer(centre), pointer(uf), pointer(normals), pointer(reach),
                             pointer(length), n_own, pointer(np.empty(3 * n + 2 * n_own)), pointer(depth),
                             pointer(scale), pointer(worst))
    return depth, scale, worst


def test_penetration_of_a_facet_without_partner_over_it():
    """dem_pair_penetration for own facets that overlap no partner (no closed pair): facet 0 sits 0.1
    below the plane y = 0 of its neighbours 2 and 3 (a hole between them): 0.1 (the far facet 4
    facing the other way is not around it); facet 1, beside a convex body, is behind the plane of 5
    but in front of that of its nearest partner 6: 0."""
    i, j = np.array([0, 0, 0, 1, 1]), np.array([2, 3, 4, 5, 6])
    pairs = Struct("dem_pairs", d=2, n_facets=7, n=5, i=i, j=j, normal=np.tile([0.0, 1.0], (5, 1)))
    state = Struct("dem_pair_state", n=0, closed=np.zeros(0, dtype=np.int64), g=np.zeros(0), w=np.zeros(0),
                   dw=np.zeros((0, 2)), c=np.zeros(0), mu=np.zeros(0))
    centre = np.array([[0.0, -0.1], [0.9, -0.05], [-0.5, 0.0], [0.5, 0.0], [5.0, 0.0], [0.0, 0.0], [1.0, -0.2]])
    normals = np.array([[0.0, -1.0], [0.0, -1.0], [0.0, 1.0], [0.0, 1.0], [0.0, -1.0], [0.0, 1.0], [0.8, 0.6]])
    reach = np.array([0.3, 0.3, 0.3, 0.5, 0.9, 0.3, 0.3])
    depth, scale, worst = _penetration(pairs, state, centre, normals, reach, 2 * reach, 2)
    assert depth[0] == pytest.approx(0.1, rel=1e-14) and depth[1] == 0.0
    assert list(scale) == [0.5, 0.3]  # the largest reach of the facet and the partners around it (not 4's)
    assert list(worst) == [depth[0], depth[0] / (2 * 0.5)]  # the largest depth and depth / (2 scale)


def test_penetration_counts_each_part_of_a_facet_by_what_lies_over_it():
    """dem_pair_penetration for facets of unit length (facing down, y = 0 unless said) partly
    covered by touching partners (facing up): depth = kappa m + (1 - kappa) h, kappa the covered
    fraction, m the partners' mean depth, h the depth in the hole under the rest.
    - Facet 0 at the rim of a contact patch: partner 4 (gap -x) covers 0.01 of it, and beyond the
      rim the other body's surface falls away (partner 5, slope -0.75): 0.01 x, not x (the mean gap
      as if 4 covered all of it).
    - Facet 1 sits D = 0.2 below the plane y = 0 of partners 6 and 7, over the hole between them;
      6 covers half of it along the common normal of tilted facets, where its gap is only -0.048:
      0.5 (0.048 + D) (the hole's half counted), not 0.048 (the partner's mean gap alone).
    - Facet 2, covered by 8 and 9 (gaps -0.01, -0.03) which overlap each other (0.6 of it each),
      keeps the overlap-weighted mean gap 0.02 (fully covered: today's number).
    - Facet 3 sits D below partners 10 and 11, 10 covering half of it with gap -D: D, as deep under
      the partner as under the hole (the larger of the two halves alone would say D / 2)."""
    x, D = 0.05, 0.2
    n1 = np.array([0.3, -1.0]) / np.hypot(0.3, 1.0)  # the common normal of facet 1 and partner 6
    i, j = np.array([0, 0, 1, 1, 2, 2, 3, 3]), np.array([4, 5, 6, 7, 8, 9, 10, 11])
    normal = np.tile([0.0, -1.0], (8, 1))
    normal[2] = n1
    pairs = Struct("dem_pairs", d=2, n_facets=12, n=8, i=i, j=j, normal=normal)
    centre = np.array([[0.0, 0.0], [10.0, -D], [20.0, 0.0], [30.0, -D], [-0.99, x], [0.01, x - 0.375], [10.5, 0.0],
                       [8.5, 0.0], [19.75, 0.01], [20.25, 0.03], [30.5, 0.0], [28.5, 0.0]])
    normals = np.tile([0.0, 1.0], (12, 1))
    normals[:4] = [0.0, -1.0]
    normals[5] = [0.6, 0.8]
    gap = np.einsum("pi,pi->p", centre[j] - centre[i], normal)
    assert gap[0] == -x and gap[2] == pytest.approx(-0.048, abs=1e-3) and gap[6] == -D
    closed = np.array([0, 2, 4, 5, 6], dtype=np.int64)
    w = np.array([0.01, 0.5 * -n1[1], 0.6, 0.6, 0.5])  # projected on the pair's plane: 6 covers half of 1
    state = Struct("dem_pair_state", n=5, closed=closed, g=gap[closed], w=w, dw=np.zeros((5, 2)),
                   c=w * gap[closed], mu=np.zeros(5))
    reach = np.full(12, 0.5)
    reach[7] = 0.7
    depth, scale, worst = _penetration(pairs, state, centre, normals, reach, np.ones(12), 4)
    assert depth[0] == pytest.approx(0.01 * x, rel=1e-12)
    assert depth[1] == pytest.approx(0.5 * (-gap[2] + D), rel=1e-12) and depth[1] > 2 * -gap[2]
    assert depth[2] == -(w[2] * gap[4] + w[3] * gap[5]) / (w[2] + w[3])  # as before: the mean
    assert depth[3] == pytest.approx(D, rel=1e-12)
    # each part over the size of what it reads: facet 1's hole over partner 7's
    assert scale[[0, 2]].tolist() == [0.5, 0.5]
    assert scale[1] == pytest.approx(depth[1] / (0.5 * -gap[2] / 0.5 + 0.5 * D / 0.7), rel=1e-12)
    assert worst[0] == depth.max() and worst[1] == pytest.approx((depth / (2 * scale)).max(), rel=1e-14)


def test_worst_motion_is_the_largest_motion_relative_to_half_the_skin():
    """dem_pair_worst_motion: the facet maximising |uc - reference|^2 / (skin/2)^2, and that ratio."""
    rng = np.random.default_rng(6)
    pairs = _pairs(rng)
    a = pairs.arrays
    uc, ratio = rng.standard_normal((6, 3)), np.zeros(1)
    k = lib.dem_pair_worst_motion(pairs.c, pointer(uc), pointer(ratio))
    r = ((uc - a["reference"]) ** 2).sum(axis=1) / a["half_skin2"]
    assert k == np.argmax(r) and np.isclose(ratio[0], r.max(), rtol=1e-14)


# -- integral.c, outputs.c ---------------------------------------------------------------------
def test_facet_forces_corrections_body_forces_and_penetration_are_their_formulas():
    """The outputs at a contact state of closed pairs p: dem_pair_facet_forces (mu (w n + g dw)
    on facet i, its opposite on j), dem_pair_facet_corrections (c / |f| e_f on each facet),
    dem_pair_body_forces (the forces between bodies, signed for the lower-numbered body) and
    dem_pair_penetration (each facet's overlap-weighted reconstructed gap, or its least depth behind the
    partners around its nearest). Their work and output arrays are overwritten (NaN on entry here):
    the outputs reuse them from step to step."""
    rng = np.random.default_rng(7)
    d, n_facets = 3, 6
    pairs = _pairs(rng, n_facets, 5, d)
    a = pairs.arrays
    i, j, normal = a["i"], a["j"], a["normal"]
    closed = np.array([0, 2, 3, 4], dtype=np.int64)
    g, w, mu = np.array([-0.3, -0.1, -0.2, -0.4]), np.abs(rng.standard_normal(4)), rng.standard_normal(4)
    w[1] = 0.0
    dw = rng.standard_normal((4, d))
    c = w * np.minimum(g, 0.0)
    state = Struct("dem_pair_state", n=4, closed=closed, g=g, w=w, dw=dw, c=c, mu=mu)
    force = mu[:, None] * (w[:, None] * normal[closed] + g[:, None] * dw)

    out = np.zeros((n_facets, d))
    lib.dem_pair_facet_forces(pairs.c, 4, pointer(closed), pointer(mu), pointer(g), pointer(w), pointer(dw),
                              pointer(out))
    expected = np.zeros((n_facets, d))
    np.add.at(expected, i[closed], force)
    np.add.at(expected, j[closed], -force)
    assert np.allclose(out, expected, rtol=1e-13, atol=1e-15)

    length = rng.random(n_facets) + 0.5
    out, work = np.full((n_facets, d), np.nan), np.full((n_facets, d), np.nan)  # overwritten by the kernel
    lib.dem_pair_facet_corrections(pairs.c, state.c, pointer(length), pointer(work), pointer(out))
    expected = np.zeros((n_facets, d))
    np.add.at(expected, i[closed], (c / length[i[closed]])[:, None] * a["e_i"][closed])
    np.add.at(expected, j[closed], (c / length[j[closed]])[:, None] * a["e_j"][closed])
    assert np.count_nonzero(expected.any(axis=1)) >= 4 and np.allclose(out, expected, rtol=1e-13, atol=1e-15)

    body = np.array([0, 0, 1, 1, 2, 2], dtype=np.int64)
    index = np.array([[-1, 0, 1], [0, -1, 2], [1, 2, -1]], dtype=np.int64)
    out = np.zeros((3, d))
    missing = lib.dem_pair_body_forces(pairs.c, state.c, pointer(body), 3, pointer(index), pointer(out))
    expected = np.zeros((3, d))
    for k, p in enumerate(closed):
        bi, bj = body[i[p]], body[j[p]]
        if c[k] != 0 and bi != bj:
            expected[index[bi, bj]] += (1.0 if bi < bj else -1.0) * force[k]
    assert missing == 0 and np.count_nonzero(expected.any(axis=1)) == 2
    assert np.allclose(out, expected, rtol=1e-13, atol=1e-15)

    centre, uf = rng.standard_normal((n_facets, d)), rng.standard_normal((n_facets, d))
    work = np.full(3 * n_facets + 2 * 4, np.nan)  # overwritten by the kernel
    weight, mean, cover = work[: 3 * n_facets].reshape(3, n_facets)
    normals, reach = rng.standard_normal((n_facets, d)), 0.2 * rng.random(n_facets)
    depth, scale, worst = np.zeros(4), np.zeros(4), np.empty(2)
    lib.dem_pair_penetration(pairs.c, state.c, pointer(centre), pointer(uf), pointer(normals), pointer(reach),
                             pointer(length), 4, pointer(work), pointer(depth), pointer(scale), pointer(worst))
    x = centre + uf
    gap = np.einsum("pi,pi->p", x[j[closed]] - x[i[closed]], normal[closed])
    on = w > 0
    W, M, C = np.zeros(n_facets), np.zeros(n_facets), np.zeros(n_facets)
    for f in (i[closed][on], j[closed][on]):
        np.add.at(W, f, w[on])
        np.add.at(M, f, (w * gap)[on])
        np.add.at(C, f, w[on] / (length[f] * np.abs(np.einsum("pi,pi->p", normals[f], normal[closed][on]))))
    assert np.allclose(weight, W, rtol=1e-13, atol=0) and np.allclose(mean, M, rtol=1e-13, atol=0)
    assert np.allclose(cover, C, rtol=1e-13, atol=0)
    kappa = np.where(C < 1 - 1e-9, C, 1.0)
    assert ((kappa[:4] > 0) & (kappa[:4] < 1)).any() and (kappa[:4] == 1).any()  # partly and fully covered
    expected, expected_scale, ratio = np.zeros(4), reach[:4].copy(), np.zeros(4)
    for f in range(4):
        touching = [o for k, p in enumerate(closed) if w[k] > 0 for g, o in ((i[p], j[p]), (j[p], i[p])) if g == f]
        covered = -kappa[f] * M[f] / W[f] if W[f] > 0 else 0.0
        partners = [o for a, b in zip(i, j) for g, o in ((a, b), (b, a)) if g == f]
        hole, around = 0.0, []
        if partners and kappa[f] < 1:  # the least depth behind the partners around the nearest one
            r = [np.linalg.norm(x[f] - x[o]) for o in partners]
            around = [o for o, ro in zip(partners, r) if ro <= min(r) + 2 * (reach[f] + reach[o])]
            hole = (1 - kappa[f]) * max(min(-np.dot(x[f] - x[o], normals[o]) for o in around), 0.0)
        expected[f] = max(covered, 0.0) + hole
        s_touching, s_around = (max(reach[o] for o in [f] + partners) for partners in (touching, around))
        ratio[f] = (max(covered, 0.0) / s_touching + hole / s_around) / 2
        expected_scale[f] = s_touching if hole == 0 else s_around if covered <= 0 else expected[f] / (2 * ratio[f])
    assert np.allclose(scale, expected_scale, rtol=1e-13, atol=0)
    assert np.allclose(depth, expected, rtol=1e-13, atol=1e-15)
    assert worst[0] == depth.max(initial=0.0) and worst[1] == pytest.approx(ratio.max(initial=0.0), rel=1e-13)
