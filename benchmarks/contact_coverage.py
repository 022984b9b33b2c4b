"""How well the facets of a contact zone cover each other, from ``contact_states.py`` dumps
(docs/validation/contact3d.md, "Why the refined meshes sink"). Analyses:

    deepest FILE...      the 5 deepest facets (overlap-weighted mean free gap of their touching partners):
                         coverage sum w / |f| by the listed partners, and by brute force over every
                         facet of the other body (facing ones, then the ones the facing test leaves
                         out), with the same ``_overlap`` and pair normal rule
    facing FILE...       over every touching facet, the coverage the facing test n_f . n_f' < 0 leaves out
    tiling FILE...       each body's facets facing the other (|n_x| > 0.3) projected on the plane normal
                         to x (contact axis y = z = 0 in 3D), translated by their free displacements: the fraction of the inner contact
                         disc (0.7 times the touching radius) covered 0 times (holes), once, twice or
                         more, and by both bodies (the only places eq. (31) corrects anything)
    roughness FILE...    the free displacement of each facet near the axis (r < 0.05 m, |n_x| > 0.5)
                         minus the mean of its edge neighbours (same body), tangential (yz) and
                         normal (x), over sqrt(|f|): a smooth field gives ~0, facets moving apart more
    sliding A B          between two dumps with the same list, the touching pairs of A: their total
                         overlap at A and B (w depends on the tangential offset only), and the
                         fraction whose overlap fell
    matching SHIFT FILE  the reference facets, body 1 translated by -SHIFT along x: for the facets of
                         body 0 within SHIFT of the axis, the best single partner's and the total w/|f|
"""

import sys
import types

import numpy as np

from dolfinx_dem.pair_contact import _overlap, _project, _Simplices, _tangents


def pairs(D, i, j, uc=None):
    """Pair normal n, gap g and overlap w of the facet pairs (i, j) as ``PairContact._build`` and
    ``_state`` make them, at the free displacements ``uc`` (default the dump's)."""
    uc = D["uc"] if uc is None else uc
    L, N, C, E = D["length"], D["normal"], D["centre"], D["ends"]
    n = L[i, None] * N[i] - L[j, None] * N[j]
    n /= np.linalg.norm(n, axis=1)[:, None]
    t = _tangents(n)
    F = types.SimpleNamespace(ends=E, centre=C)
    g = np.einsum("pi,pi->p", C[j] + uc[j] - C[i] - uc[i], n)
    w, _ = _overlap(_Simplices.of(_project(F, i, i, t)), _Simplices.of(_project(F, j, i, t)), np.arange(len(i)),
                    np.einsum("pki,pi->pk", t, uc[j] - uc[i]))
    return n, g, w


def brute(D, f):
    """Coverage of facet f (g < 0, w > 0) by every facet of the other body: facing ones, and
    the others (n_f . n_f' >= 0, where the pair normal is defined)."""
    A = D["length"]
    other = np.flatnonzero(D["body"] != D["body"][f])
    facing = np.einsum("i,pi->p", D["normal"][f], D["normal"][other]) < 0
    out = []
    for q in (other[facing], other[~facing]):
        q = q[np.linalg.norm(A[f] * D["normal"][f] - A[q, None] * D["normal"][q], axis=1) > 1e-3 * A[f]]
        if len(q) == 0:
            out.append((q, np.zeros(0), np.zeros(0)))
            continue
        _, g, w = pairs(D, np.full(len(q), f), q)
        on = (g < 0) & (w > 0)
        out.append((q[on], g[on], w[on]))
    return out


def deepest(D, top=5):
    i, j, g, w, A = D["i"], D["j"], D["g"], D["w"], D["length"]
    nf = len(A)
    on = (g < 0) & (w > 0)
    ii, jj, ww, gg = i[on], j[on], w[on], g[on]
    weight = np.bincount(ii, ww, nf) + np.bincount(jj, ww, nf)
    depth = -(np.bincount(ii, ww * gg, nf) + np.bincount(jj, ww * gg, nf)) / np.where(weight > 0, weight, 1.0)
    for f in np.argsort(depth)[::-1][:top]:
        (qf, gf, wf), (_, _, wn) = brute(D, f)
        listed = set(j[i == f]) | set(i[j == f])
        print(f"  facet {f} (body {D['body'][f]}, at {np.round(D['centre'][f] + D['uc'][f], 4)}): free gap "
              f"{depth[f]:.4f} m; coverage: listed {weight[f] / A[f]:.3f} ({np.sum(ii == f) + np.sum(jj == f)} "
              f"partners), brute force {wf.sum() / A[f]:.3f} ({len(qf)}, unlisted {sum(q not in listed for q in qf)}),"
              f" left out by the facing test {wn.sum() / A[f]:.3f}; w/|f| {np.round(np.sort(wf)[::-1][:4] / A[f], 3)}")


def facing(D):
    on = (D["g"] < 0) & (D["w"] > 0)
    fs = np.union1d(D["i"][on], D["j"][on])
    lost = np.array([brute(D, f)[1][2].sum() / D["length"][f] for f in fs])
    x = D["centre"][fs] + D["uc"][fs]
    r = np.hypot(x[:, 1], x[:, 2])
    out = r[lost > 0.05]
    print(f"  {len(fs)} touching facets (r up to {r.max():.3f} m); the facing test leaves out > 5 % of |f| on "
          f"{len(out)} (largest {lost.max():.3f})" + (f", at r = {out.min():.3f} to {out.max():.3f} m" if len(out) else ""))


def touching_radius(D):
    on = (D["g"] < 0) & (D["w"] > 0)
    f = np.union1d(D["i"][on], D["j"][on])
    x = D["centre"][f] + D["uc"][f]
    return np.hypot(x[:, 1], x[:, 2] if x.shape[1] == 3 else 0.0 * x[:, 1]).max()


def tiling(D):
    d = D["centre"].shape[1]
    # the contact axis: y = z = 0 in 3D (two-balls, two_cubes_impact.py), the bodies' mid height in 2D
    axis = np.zeros(2) if d == 3 else np.array([np.median(D["centre"][:, 1])])
    r = 0.7 * touching_radius(D) if d == 3 else 0.7 * np.abs(
        (D["centre"] + D["uc"])[np.union1d(D["i"][D["g"] < 0], D["j"][D["g"] < 0]), 1] - axis[0]).max()
    if d == 3:
        s = np.linspace(-r, r, 301)
        P = np.stack([a.ravel() for a in np.meshgrid(s, s)], 1)
        P = P[np.hypot(P[:, 0], P[:, 1]) < r] + axis
    else:
        P = np.linspace(-r, r, 4001)[:, None] + axis
    count = []
    for b in (0, 1):
        sel = np.flatnonzero((D["body"] == b) & (np.abs(D["normal"][:, 0]) > 0.3))
        X = D["ends"][sel][:, :, 1:] + D["uc"][sel][:, None, 1:]
        m = np.zeros(len(P), dtype=int)
        for T in X:
            if d == 2:
                m += (P[:, 0] >= T[:, 0].min()) & (P[:, 0] <= T[:, 0].max())
                continue
            a, b_, c = T
            det = (b_[0] - a[0]) * (c[1] - a[1]) - (b_[1] - a[1]) * (c[0] - a[0])
            l1 = ((b_[0] - P[:, 0]) * (c[1] - P[:, 1]) - (b_[1] - P[:, 1]) * (c[0] - P[:, 0])) / det
            l2 = ((c[0] - P[:, 0]) * (a[1] - P[:, 1]) - (c[1] - P[:, 1]) * (a[0] - P[:, 0])) / det
            m += (l1 >= 0) & (l2 >= 0) & (1 - l1 - l2 >= 0)
        count.append(m)
    print("  " + ", ".join(f"body {b}: holes {np.mean(m == 0):.3f}, once {np.mean(m == 1):.3f}, twice or more "
                           f"{np.mean(m >= 2):.3f}" for b, m in enumerate(count))
          + f"; both bodies {np.mean((count[0] >= 1) & (count[1] >= 1)):.3f} (disc radius {r:.4f} m)")


def roughness(D):
    V, body, uc, A = D["vids"], D["body"], D["uc"], D["length"]
    n = len(V)
    shared = (V[:, None, :, None] == V[None, :, None, :]).sum(axis=(2, 3))
    I, J = np.nonzero((shared == 2) & (body[:, None] == body[None, :]))
    x = D["centre"] + uc
    zone = (np.hypot(x[:, 1], x[:, 2]) < 0.05) & (np.abs(D["normal"][:, 0]) > 0.5)
    mean = np.stack([np.bincount(I, uc[J, k], n) for k in range(3)], 1) / np.maximum(np.bincount(I, minlength=n), 1)[:, None]
    res = (uc - mean)[zone] / np.sqrt(A[zone])[:, None]
    tan, nor = np.hypot(res[:, 1], res[:, 2]), np.abs(res[:, 0])
    print(f"  {zone.sum()} facets: tangential mean {tan.mean():.3f} (max {tan.max():.3f}), normal mean "
          f"{nor.mean():.3f} (max {nor.max():.3f})")


def sliding(A, B):
    assert np.array_equal(A["i"], B["i"]) and np.array_equal(A["j"], B["j"]), "the lists differ"
    on = (A["g"] < 0) & (A["w"] > 0)
    i, j = A["i"][on], A["j"][on]
    wa, wb = pairs(A, i, j)[2], pairs(A, i, j, B["uc"])[2]
    weight = -A["g"][on] * wa
    print(f"  {float(A['t']):.3f} -> {float(B['t']):.3f} s: {on.sum()} touching pairs, total overlap "
          f"{wa.sum():.5f} -> {wb.sum():.5f} m^2; fell on {np.mean(wb < wa):.2f} of them "
          f"({np.sum(weight * (wb < wa)) / weight.sum():.2f} weighted by |g| w)")


def matching(D, shift):
    uc = np.zeros_like(D["uc"])
    uc[D["body"] == 1, 0] = -shift
    x = D["centre"]
    f0 = np.flatnonzero((D["body"] == 0) & (D["normal"][:, 0] > 0.5) & (np.hypot(x[:, 1], x[:, 2]) < shift))
    f1 = np.flatnonzero((D["body"] == 1) & (D["normal"][:, 0] < -0.5))
    best, total = [], []
    for f in f0:
        w = pairs(D, np.full(len(f1), f), f1, uc)[2] / D["length"][f]
        best.append(w.max())
        total.append(w.sum())
    print(f"  {len(f0)} facets: best single partner w/|f| median {np.median(best):.3f} (> 0.9 on "
          f"{np.mean(np.array(best) > 0.9):.2f}), total median {np.median(total):.3f} "
          f"(range {min(total):.3f} to {max(total):.3f})")


def main():
    what, args = sys.argv[1], sys.argv[2:]
    load = lambda p: dict(np.load(p))  # noqa: E731
    if what == "sliding":
        sliding(load(args[0]), load(args[1]))
        return
    if what == "matching":
        for p in args[1:]:
            print(p)
            matching(load(p), float(args[0]))
        return
    for p in args:
        D = load(p)
        print(f"{p}: t = {float(D['t']):.4f} s, penetration {float(D['pen']):.5f} m, force {float(D['force']):.3f} N")
        {"deepest": deepest, "facing": facing, "tiling": tiling, "roughness": roughness}[what](D)


if __name__ == "__main__":
    main()
