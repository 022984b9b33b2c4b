/* Events and the exact force integral of a step (paper §4; pair_contact.PairContact.force_integral):
 * each touching pair's events along the free flight, the pieces of [0, dt] they cut (also
 * patch.piecewise_midpoints), the overlaps at the Gauss nodes of the pieces and the integrals of
 * the contact force corrections; the facet forces -mu dc/du. */
#include "internal.h"

/* Relative margin of the edge tests of pair_events (of the edge length): far above rounding,
 * far below any configuration that matters. */
#define EDGE_MARGIN 1e-9

/* patch.piecewise_midpoints: the times (n_times, each in (0, dt)) of rows ``rows`` (0 <= row < n)
 * cut each row's [0, dt] into pieces; points (n x (k + 2), k the largest count per row): 0, the
 * row's times sorted, then dt; mid and length (n x (k + 1)) of the pieces between them (empty
 * ones at the end). counts: each row's number of times (consumed: zero on return). */
void dem_piecewise_midpoints(int64_t n_times, const int64_t *restrict rows, const double *restrict times, int64_t n,
                             int64_t k, double dt, int64_t *restrict counts, double *restrict points,
                             double *restrict mid, double *restrict length)
{
  const int64_t width = k + 2;
  for (int64_t r = 0; r < n; ++r)
  {
    points[r * width] = 0.0;
    for (int64_t a = 1; a < width; ++a)
      points[r * width + a] = dt;
  }
  for (int64_t e = 0; e < n_times; ++e)
  {
    /* a row's times fill its slots count, count - 1, ..., 1, kept sorted: each new one moves up
     * past the smaller ones placed before it (the dt that follow them are not smaller) */
    double *row = points + rows[e] * width;
    int64_t b = counts[rows[e]]--;
    row[b] = times[e];
    for (; b + 1 < width && row[b + 1] < row[b]; ++b)
    {
      const double y = row[b + 1];
      row[b + 1] = row[b];
      row[b] = y;
    }
  }
  for (int64_t r = 0; r < n; ++r)
    for (int64_t a = 0; a + 1 < width; ++a)
    {
      const double p0 = points[r * width + a], p1 = points[r * width + a + 1];
      mid[r * (k + 1) + a] = 0.5 * (p0 + p1);
      length[r * (k + 1) + a] = p1 - p0;
    }
}

/* The events of dem_pair_force_integral for the listed pairs p[e] along the flight uc + tau vc
 * (n_facets x d): the times in (0, dt) where the gap, or the side m_k . (x - X_k) of a vertex x
 * of one projected simplex to the line of face k of the other (B moved by the tangential offset
 * s0 + tau s1), changes sign; INFINITY where none. tau: n x (1 + 2 d^2), columns [gap, (vertex a
 * of A, face k of B) at 1 + a d + k, (vertex a of B, face k of A) at 1 + d^2 + a d + k]. */
static void pair_events(int64_t n, const int64_t *restrict p, const dem_pairs *pairs, const double *restrict uc,
                        const double *restrict vc, double dt, double *restrict tau)
{
  const int32_t d = pairs->d, dim = d - 1, stride = d * dim, width = 1 + 2 * d * d;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j;
  const double *restrict normal = pairs->normal, *restrict t = pairs->t, *restrict d0 = pairs->d0;
  const double *restrict XA = pairs->si.X, *restrict mA = pairs->si.m, *restrict XB = pairs->sj.X;
  const double *restrict mB = pairs->sj.m;
  for (int64_t e = 0; e < n; ++e)
  {
    const int64_t q = p[e];
    double du[3], dv[3], g0 = 0.0, gs = 0.0, s0[2], s1[2];
    for (int32_t k = 0; k < d; ++k)
    {
      du[k] = uc[j[q] * d + k] - uc[i[q] * d + k];
      dv[k] = vc[j[q] * d + k] - vc[i[q] * d + k];
      g0 += du[k] * normal[q * d + k];
      gs += dv[k] * normal[q * d + k];
    }
    g0 = d0[q] + g0;
    for (int32_t c = 0; c < dim; ++c)
    {
      s0[c] = s1[c] = 0.0;
      for (int32_t k = 0; k < d; ++k)
      {
        s0[c] += t[(q * dim + c) * d + k] * du[k];
        s1[c] += t[(q * dim + c) * d + k] * dv[k];
      }
    }
    const double *xa = XA + q * stride, *ma = mA + q * stride, *xb = XB + q * stride, *mb = mB + q * stride;
    double v0[19], rate[19];
    v0[0] = g0;
    rate[0] = gs;
    for (int32_t a = 0; a < d; ++a)
      for (int32_t k = 0; k < d; ++k)
      {
        double side_ab = 0.0, side_ba = 0.0, speed_b = 0.0, speed_a = 0.0;
        for (int32_t c = 0; c < dim; ++c)
        {
          side_ab += (xa[a * dim + c] - (xb[k * dim + c] + s0[c])) * mb[k * dim + c];
          side_ba += ((xb[a * dim + c] + s0[c]) - xa[k * dim + c]) * ma[k * dim + c];
          speed_b += mb[k * dim + c] * s1[c];
          speed_a += ma[k * dim + c] * s1[c];
        }
        v0[1 + a * d + k] = side_ab;
        rate[1 + a * d + k] = -speed_b;
        v0[1 + d * d + a * d + k] = side_ba;
        rate[1 + d * d + a * d + k] = speed_a;
      }
    for (int32_t k = 0; k < width; ++k)
    {
      const double v1 = v0[k] + dt * rate[k];
      const double root = -v0[k] / rate[k];
      tau[e * width + k] = (v0[k] * v1 < 0 && root > 0 && root < dt) ? root : INFINITY;
    }
    /* In 3D, w (and dw) has kinks only where a vertex crosses an edge of the other triangle, not
     * its line beyond the edge (the pieces of the overlap area of two translated convex polygons
     * are cut by the segments vertex - edge in the offset plane): the crossings outside the edge
     * are dropped, by a margin (a spare event costs, a missing one breaks the exact integration). */
    if (dim == 2)
      for (int32_t a = 0; a < d; ++a)
        for (int32_t k = 0; k < d; ++k)
          for (int32_t side = 0; side < 2; ++side)
          {
            double *root = tau + e * width + 1 + side * d * d + a * d + k;
            if (!isfinite(*root))
              continue;
            /* the vertex x and the edge from y0 to y1 at the root, in A's frame */
            const double *x = side ? xb + a * dim : xa + a * dim, *y0 = side ? xa + k * dim : xb + k * dim;
            const double *y1 = side ? xa + ((k + 1) % d) * dim : xb + ((k + 1) % d) * dim;
            double along = 0.0, norm2 = 0.0;
            for (int32_t c = 0; c < dim; ++c)
            {
              const double shift = s0[c] + *root * s1[c]; /* B's offset: on x (side 1) or on y (side 0) */
              const double rel = side ? (x[c] + shift) - y0[c] : x[c] - (y0[c] + shift);
              along += rel * (y1[c] - y0[c]);
              norm2 += (y1[c] - y0[c]) * (y1[c] - y0[c]);
            }
            if (!(along > -EDGE_MARGIN * norm2 && along < (1.0 + EDGE_MARGIN) * norm2))
              *root = INFINITY;
          }
  }
}

/* A pair's overlap on its own pieces (dem_pair_force_integral, before interpolate_own): for the
 * listed pairs p[e] moving along uc + tau vc (n_facets x d), with their events tau (n_tau per
 * pair, INFINITY: none; in (0, dt)), the own pieces of [0, dt] cut at the sorted events (padded
 * with empty pieces up to n_tau + 1: start, length, as dem_piecewise_midpoints and
 * dem_pair_force_integral's nodes compute them), and at the n_gauss nodes xi of each non-empty
 * piece w and dw/du_j (pair_overlap); 0 on the pieces where the gap g0 + tau rate is not negative
 * (not clipped: nothing reads w there); nothing on empty pieces (nothing reads them). */
DEM_INLINE void overlap_own(int64_t n, const int32_t d, const int64_t *restrict p, const dem_pairs *pairs,
                            const double *restrict uc, const double *restrict vc, int32_t n_tau,
                            const double *restrict tau, double dt, int32_t n_gauss, const double *restrict xi,
                            const double *restrict g0, const double *restrict rate, double *restrict start,
                            double *restrict length, double *restrict w, double *restrict dw)
{
  const int32_t n_own = n_tau + 1;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j;
  for (int64_t e = 0; e < n; ++e)
  {
    const int64_t q = p[e];
    double points[40];
    int32_t k = 0;
    points[k++] = 0.0;
    for (int32_t m = 0; m < n_tau; ++m)
    {
      const double x = tau[e * n_tau + m];
      if (!isfinite(x))
        continue;
      int32_t at = k; /* insertion sort */
      while (at > 1 && points[at - 1] > x)
      {
        points[at] = points[at - 1];
        --at;
      }
      points[at] = x;
      ++k;
    }
    while (k < n_own + 1)
      points[k++] = dt;
    for (int32_t piece = 0; piece < n_own; ++piece)
    {
      const double mid = 0.5 * (points[piece] + points[piece + 1]), len = points[piece + 1] - points[piece];
      const double first = mid - 0.5 * len;
      const int64_t row = e * n_own + piece;
      start[row] = first;
      length[row] = len;
      /* the gap is affine and its root an event: its sign on the piece is that at the middle,
       * and where it is not negative c = w g^- and the force term vanish whatever w is */
      const int32_t open = !(g0[e] + mid * rate[e] < 0.0);
      if (!(len > 0))
        continue; /* an empty piece: never read (interpolate_own) */
      for (int32_t g = 0; g < n_gauss; ++g)
      {
        const int64_t node = row * n_gauss + g;
        if (open)
        {
          w[node] = 0.0;
          for (int32_t c = 0; c < d; ++c)
            dw[node * d + c] = 0.0;
          continue;
        }
        const double time = first + xi[g] * len;
        double du[3];
        for (int32_t c = 0; c < d; ++c)
          du[c] = (uc[j[q] * d + c] + time * vc[j[q] * d + c]) - (uc[i[q] * d + c] + time * vc[i[q] * d + c]);
        pair_overlap(d, q, pairs, du, w + node, dw + node * d);
      }
    }
  }
}

/* Lagrange interpolation of overlap_own's values (dem_pair_force_integral), for n_rows pairs: each has
 * n_own pieces (start, length; empty ones of length 0) with values w_own (n_gauss per piece, at
 * the nodes xi of [0, 1] scaled to the piece) and gradients dw_own (width components each), and
 * the times nodes[offsets[r] .. offsets[r + 1]) (increasing). At each time x: the last non-empty
 * piece starting at or before it (the first piece if none), and the Lagrange interpolation of its
 * values, summed in the order of the nodes. w (offsets[n_rows]) and dw (offsets[n_rows] width)
 * are overwritten. cache_x (NAN on entry) and cache_basis (n_gauss each): work arrays of the
 * largest number of times of a row. */
static void interpolate_own(int64_t n_rows, int32_t n_own, const int64_t *restrict offsets, int32_t n_gauss,
                            int32_t width, const double *restrict start, const double *restrict length,
                            const double *restrict nodes, const double *restrict xi,
                            const double *restrict w_own, const double *restrict dw_own,
                            double *restrict w, double *restrict dw, double *restrict cache_x,
                            double *restrict cache_basis)
{
  for (int64_t r = 0; r < n_rows; ++r)
  {
    const double *s = start + r * n_own, *len = length + r * n_own;
    int32_t piece = 0; /* the row's times increase: its piece only moves forward */
    for (int64_t out = offsets[r]; out < offsets[r + 1]; ++out)
    {
      const double t = nodes[out];
      for (int32_t j = piece + 1; j < n_own && s[j] <= t; ++j)
        if (len[j] > 0)
          piece = j;
      const double x = (t - s[piece]) / len[piece];
      const int64_t at = (r * n_own + piece) * n_gauss;
      /* the basis at x, kept per node position: the rows of a component share their nodes, and
       * those with one own piece their x */
      double *cached = cache_basis + (out - offsets[r]) * n_gauss;
      if (!(cache_x[out - offsets[r]] == x))
      {
        cache_x[out - offsets[r]] = x;
        for (int32_t m = 0; m < n_gauss; ++m)
        {
          double basis = 1.0;
          int32_t first = 1;
          for (int32_t l = 0; l < n_gauss; ++l)
            if (l != m)
            {
              const double factor = (x - xi[l]) / (xi[m] - xi[l]);
              basis = first ? factor : basis * factor;
              first = 0;
            }
          cached[m] = basis;
        }
      }
      double wsum = 0.0, dsum[3] = {0.0, 0.0, 0.0};
      for (int32_t m = 0; m < n_gauss; ++m)
      {
        const double basis = cached[m];
        wsum = m == 0 ? basis * w_own[at + m] : wsum + basis * w_own[at + m];
        for (int32_t c = 0; c < width; ++c)
          dsum[c] = m == 0 ? basis * dw_own[(at + m) * width + c] : dsum[c] + basis * dw_own[(at + m) * width + c];
      }
      w[out] = wsum;
      for (int32_t c = 0; c < width; ++c)
        dw[out * width + c] = dsum[c];
    }
  }
}

/* The range [lo, hi) of the m values g (a pair's gaps at its nodes, in time order: affine, so
 * those below 0 are contiguous) where g < 0 (lo = hi if none). */
static void closed_range(const double *g, int64_t m, int64_t *lo, int64_t *hi)
{
  int64_t a = 0, b = m;
  while (a < b && !(g[a] < 0))
    ++a;
  while (b > a && !(g[b - 1] < 0))
    --b;
  *lo = a;
  *hi = b;
}

static int64_t find_root(int64_t *parent, int64_t k)
{
  while (parent[k] != k)
  {
    parent[k] = parent[parent[k]];
    k = parent[k];
  }
  return k;
}

/* The facet forces of pair_contact.PairContact._facet_force: for the entries k (listed pairs
 * p[k] of facets (i, j), normals n), dc = mu_k (w_k n + g_k dw_k) (d components) is added to
 * facet i's row of out and subtracted from facet j's (out: n_facets x d, accumulated into, in
 * the order of the entries). */
void dem_pair_facet_forces(const dem_pairs *pairs, int64_t n, const int64_t *restrict p, const double *restrict mu,
                           const double *restrict g, const double *restrict w, const double *restrict dw,
                           double *restrict out)
{
  const int32_t d = pairs->d;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j;
  const double *restrict normal = pairs->normal;
  for (int64_t k = 0; k < n; ++k)
  {
    if (mu[k] == 0.0)
      continue; /* adds exact zeros */
    const int64_t q = p[k];
    for (int32_t c = 0; c < d; ++c)
    {
      const double dc = mu[k] * (w[k] * normal[q * d + c] + g[k] * dw[k * d + c]);
      out[i[q] * d + c] += dc;
      out[j[q] * d + c] -= dc;
    }
  }
}

/* The own rows the touching pairs p[0..n) touch (numbered through slot by number_columns: n_rows
 * of them) link the pairs into connected components (two pairs are linked by a common column
 * of their Z^T rows): union-find, the smaller index the root, the components numbered by first
 * appearance (label). first (n_rows) and parent (n): work. Returns the number of components. */
static int64_t components(int64_t n, const int64_t *restrict p, const dem_csr *z, const int32_t *restrict slot,
                          int64_t n_rows, int64_t *restrict first, int64_t *restrict parent, int64_t *restrict label)
{
  const int32_t *restrict z_ptr = z->indptr, *restrict z_idx = z->indices;
  int64_t n_comp = 0;
  for (int64_t s = 0; s < n_rows; ++s)
    first[s] = -1; /* the first pair met in each row */
  for (int64_t k = 0; k < n; ++k)
    parent[k] = k;
  for (int64_t k = 0; k < n; ++k)
  {
    int64_t x = find_root(parent, k); /* k's root, kept as the unions below change it */
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
    {
      const int32_t r = slot[z_idx[e]];
      if (first[r] < 0)
        first[r] = k;
      if (first[r] == k)
        continue;
      const int64_t y = find_root(parent, first[r]);
      if (x != y)
      {
        parent[x > y ? x : y] = x < y ? x : y;
        x = x < y ? x : y;
      }
    }
  }
  for (int64_t k = 0; k < n; ++k)
  {
    const int64_t root = find_root(parent, k);
    label[k] = root == k ? n_comp++ : label[root];
  }
  return n_comp;
}

/* The nodes of the touching pairs in dem_pair_force_integral: pair k's are offsets[k] ..
 * offsets[k + 1] (stride: the most of a pair), at the times ``time`` of its component's pieces
 * with the quadrature weights ``weight``; there the pair (``entry``), its gap g, overlap w,
 * dw/du_j (d each) and c = w g^-. */
typedef struct
{
  int64_t *offsets, *entry;
  double *time, *weight, *g, *w, *dw, *c;
  int64_t stride;
} node_set;

/* The rows' term of dem_pair_force_integral: result -= Q^T (Z int c dtau) over the n_rows
 * touched rows (zc: their Z int c dtau, zero on entry). */
static void rows_term(int64_t n, const int64_t *restrict p, const dem_csr *z, const int32_t *restrict slot,
                      int64_t n_rows, const int32_t *restrict rows, const dem_csr *Q, const node_set *nodes,
                      double *restrict zc, double *restrict result)
{
  const int32_t *restrict z_ptr = z->indptr, *restrict z_idx = z->indices;
  const double *restrict z_val = z->data, *restrict weights = nodes->weight, *restrict c = nodes->c;
  const int64_t *restrict offsets = nodes->offsets;
  for (int64_t k = 0; k < n; ++k)
  {
    double integral = 0.0;
    for (int64_t e = offsets[k]; e < offsets[k + 1]; ++e)
      integral = e == offsets[k] ? weights[e] * c[e] : integral + weights[e] * c[e];
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
      zc[slot[z_idx[e]]] += z_val[e] * integral;
  }
  for (int64_t s = 0; s < n_rows; ++s)
    for (int32_t e = Q->indptr[rows[s]]; e < Q->indptr[rows[s] + 1]; ++e)
      result[Q->indices[e]] -= Q->data[e] * zc[s];
}

/* The pairs' term of dem_pair_force_integral: mu = z_p . a(tau) + z_p . (Z c)(tau) at the nodes
 * (the pairs of a component share their nodes; za: z_p . a at 0 and its rate, 2 per pair),
 * where g < 0, times the weights; then the facet forces -mu dc/du (dem_pair_facet_forces) and
 * result += R^T of them (summed as scipy's R.T @ f, then added). work (n_rows x stride),
 * facet_force (R's rows) and pairs_term (R's columns): zero on entry; mu: one per node. */
static void pairs_term(int64_t n, const int64_t *restrict p, const dem_pairs *pairs, const double *restrict za,
                       const node_set *nodes, double *restrict mu, double *restrict work,
                       double *restrict facet_force, double *restrict pairs_term, double *restrict result)
{
  const int32_t *restrict z_ptr = pairs->z.indptr, *restrict z_idx = pairs->z.indices, *restrict slot = pairs->slot;
  const double *restrict z_val = pairs->z.data, *restrict g = nodes->g, *restrict c = nodes->c;
  const int64_t *restrict offsets = nodes->offsets, stride = nodes->stride;
  for (int64_t k = 0; k < n; ++k)
  {
    int64_t lo, hi; /* c and mu only where g < 0: elsewhere c = 0 adds nothing, mu is 0 */
    closed_range(g + offsets[k], offsets[k + 1] - offsets[k], &lo, &hi);
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
      for (int64_t x = lo; x < hi; ++x)
        work[slot[z_idx[e]] * stride + x] += z_val[e] * c[offsets[k] + x];
  }
  for (int64_t k = 0; k < n; ++k)
  {
    const int64_t m = offsets[k + 1] - offsets[k];
    int64_t lo, hi;
    closed_range(g + offsets[k], m, &lo, &hi);
    for (int64_t x = 0; x < m; ++x)
      mu[offsets[k] + x] = 0.0;
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
      for (int64_t x = lo; x < hi; ++x)
        mu[offsets[k] + x] += z_val[e] * work[slot[z_idx[e]] * stride + x];
    for (int64_t x = lo; x < hi; ++x)
    {
      const int64_t node = offsets[k] + x;
      const double value = (za[2 * k] + nodes->time[node] * za[2 * k + 1]) + mu[node];
      mu[node] = value * nodes->weight[node];
    }
  }
  dem_pair_facet_forces(pairs, offsets[n], nodes->entry, mu, g, nodes->w, nodes->dw, facet_force);
  const dem_csr *R = &pairs->R;
  for (int64_t r = 0; r < R->n_rows; ++r)
    for (int32_t e = R->indptr[r]; e < R->indptr[r + 1]; ++e)
      pairs_term[R->indices[e]] += R->data[e] * facet_force[r];
  for (int64_t k = 0; k < R->n_cols; ++k)
    result[k] += pairs_term[k];
}

/* pair_contact.PairContact.force_integral after its screen, in one call: for the touching pairs
 * p of the flight (flight->touching: facets (i, j), normal, tangents t, reference gap d0,
 * projections si, sj) along its free facet displacements uc + tau vc, 0 <= tau <= dt, the
 * integrals of the contact force corrections (eq. (34), paper §4):
 *   result -= Q^T Z int c dtau            (the rows' term; result: patch values, accumulated),
 *   result += R^T int -mu dc/du_f dtau    (the pairs' term at the facets, through the facets'
 *                                          reconstruction R; summed as scipy's R.T @ f, then
 *                                          added),
 * with c_p = w_p g_p^-, mu_p = z_p . (a + Z c) and a = Q u + q + tau Q v on the own rows the
 * z_p touch (Z^T: pairs->z; Q, q: the patch; up, flight->vp: the patch values of u and v).
 *
 * The pairs sharing an own row form connected components (two pairs are linked by a common
 * column of their Z^T rows). Each component's [0, dt] is cut at all its pairs' events
 * (pair_events: gap sign changes and clipped-polygon topology changes), every c_p is a
 * polynomial of degree d on each piece and each force term one of degree 2 d - 1: the n = d
 * point Gauss rule integrates them exactly. A pair's w and dw are clipped at the nodes of its
 * own pieces only (overlap_own) and interpolated at its component's nodes (interpolate_own).
 * The sums run in the order of the pairs, of each CSR row's entries and of the nodes (the rows
 * in the order the pairs first touch them). impulse (one per listed pair, or NULL): += this
 * process's part of each touching pair's normal impulse int -mu_p w_p dtau, the integral of the
 * normal force facet i exerts on facet j along n (its own rows' share of mu_p: the parts add up
 * to the pair's impulse over the processes; the pair friction's N_p). Returns the largest number
 * of non-empty pieces of a component, or -1 if memory ran out. */
int64_t dem_pair_force_integral(const dem_pairs *pairs, const dem_patch *patch, const double *restrict up,
                                const dem_flight *flight, const dem_gauss *gauss, dem_arena *arena,
                                double *restrict result, double *restrict impulse)
{
  const int32_t d = pairs->d, n_tau = 1 + 2 * d * d, n_own = n_tau + 1, n_gauss = gauss->n;
  const int64_t n = flight->n_touching, *restrict p = flight->touching;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j;
  const double *restrict normal = pairs->normal, *restrict d0 = pairs->d0;
  const double *restrict uc = flight->uc, *restrict vc = flight->vc;
  const double dt = flight->dt;
  const double *restrict xi = gauss->xi, *restrict wq = gauss->wq;
  const int32_t *restrict z_ptr = pairs->z.indptr, *restrict z_idx = pairs->z.indices;
  const double *restrict z_val = pairs->z.data;
  int32_t *restrict slot = pairs->slot;
  int64_t bound = 0, n_rows = 0, n_comp = 0, n_times = 0, k_max = 0, pieces = 0, stride = 0, status = -1;
  for (int64_t k = 0; k < n; ++k)
    bound += z_ptr[p[k] + 1] - z_ptr[p[k]];
  arena_start(arena);
  int32_t *rows = arena_take(arena, bound, sizeof *rows);
  int64_t *first = arena_take(arena, bound, sizeof *first), *parent = arena_take(arena, n, sizeof *parent);
  int64_t *label = arena_take(arena, n, sizeof *label), *offsets = arena_take(arena, n + 1, sizeof *offsets);
  double *a = arena_take(arena, 2 * bound, sizeof *a), *za = arena_take(arena, 2 * n, sizeof *za);
  double *tau = arena_take(arena, n * n_tau, sizeof *tau), *zc = arena_zeros(arena, bound, sizeof *zc);
  int64_t *time_rows = arena_take(arena, n * n_tau, sizeof *time_rows);
  double *times = arena_take(arena, n * n_tau, sizeof *times);
  double *g0 = arena_zeros(arena, n, sizeof *g0), *rate = arena_zeros(arena, n, sizeof *rate);
  double *start_own = arena_take(arena, n * n_own, sizeof *start_own);
  double *length_own = arena_take(arena, n * n_own, sizeof *length_own);
  double *w_own = arena_take(arena, n * n_own * n_gauss, sizeof *w_own);
  double *dw_own = arena_take(arena, n * n_own * n_gauss * d, sizeof *dw_own);
  double *facet_force = arena_zeros(arena, pairs->R.n_rows, sizeof *facet_force);
  double *pairs_sum = arena_zeros(arena, pairs->R.n_cols, sizeof *pairs_sum);
  if (!rows || !first || !parent || !label || !offsets || !a || !za || !tau || !zc || !time_rows || !times ||
      !start_own || !length_own || !w_own || !dw_own || !g0 || !rate || !facet_force || !pairs_sum)
    goto done;

  /* the own rows the pairs touch (slot: their numbers, by first appearance) and the components
   * of pairs sharing one */
  n_rows = number_columns(n, p, &pairs->z, slot, rows, 0);
  n_comp = components(n, p, &pairs->z, slot, n_rows, first, parent, label);

  /* a = (Q u + q, Q v) on the touched rows, and z_p . a of each pair */
  rows_apply(n_rows, rows, &patch->Q, up, patch->q, a, flight->vp, a + n_rows);
  for (int64_t k = 0; k < n; ++k)
  {
    double y[2] = {0.0, 0.0};
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
    {
      y[0] += z_val[e] * a[slot[z_idx[e]]];
      y[1] += z_val[e] * a[n_rows + slot[z_idx[e]]];
    }
    za[2 * k] = y[0];
    za[2 * k + 1] = y[1];
  }

  /* each pair's events; each component's pieces (dem_piecewise_midpoints) and their nodes */
  pair_events(n, p, pairs, uc, vc, dt, tau);
  int64_t *counts = arena_zeros(arena, n_comp, sizeof *counts);
  int64_t *n_pieces = arena_zeros(arena, n_comp, sizeof *n_pieces);
  if (!counts || !n_pieces)
    goto done;
  for (int64_t k = 0; k < n; ++k)
    for (int32_t m = 0; m < n_tau; ++m)
      if (isfinite(tau[k * n_tau + m]))
      {
        time_rows[n_times] = label[k];
        times[n_times++] = tau[k * n_tau + m];
        k_max = ++counts[label[k]] > k_max ? counts[label[k]] : k_max;
      }
  double *points = arena_take(arena, n_comp * (k_max + 2), sizeof *points);
  double *mid = arena_take(arena, n_comp * (k_max + 1), sizeof *mid);
  double *length = arena_take(arena, n_comp * (k_max + 1), sizeof *length);
  if (!points || !mid || !length)
    goto done;
  dem_piecewise_midpoints(n_times, time_rows, times, n_comp, k_max, dt, counts, points, mid, length);
  for (int64_t comp = 0; comp < n_comp; ++comp)
  {
    for (int64_t piece = 0; piece <= k_max; ++piece)
      n_pieces[comp] += length[comp * (k_max + 1) + piece] > 0;
    pieces = n_pieces[comp] > pieces ? n_pieces[comp] : pieces;
  }
  offsets[0] = 0;
  for (int64_t k = 0; k < n; ++k)
  {
    offsets[k + 1] = offsets[k] + n_pieces[label[k]] * n_gauss;
    stride = offsets[k + 1] - offsets[k] > stride ? offsets[k + 1] - offsets[k] : stride;
  }
  const int64_t n_nodes = offsets[n];
  double *nodes = arena_take(arena, n_nodes, sizeof *nodes), *weights = arena_take(arena, n_nodes, sizeof *weights);
  double *g = arena_take(arena, n_nodes, sizeof *g), *w = arena_take(arena, n_nodes, sizeof *w);
  double *dw = arena_take(arena, n_nodes * d, sizeof *dw), *c = arena_take(arena, n_nodes, sizeof *c);
  double *mu = arena_take(arena, n_nodes, sizeof *mu);
  int64_t *entry = arena_take(arena, n_nodes, sizeof *entry);
  const node_set at = {offsets, entry, nodes, weights, g, w, dw, c, stride};
  double *work = arena_zeros(arena, n_rows * stride, sizeof *work);
  double *cache_x = arena_take(arena, stride, sizeof *cache_x);
  double *cache_basis = arena_take(arena, stride * n_gauss, sizeof *cache_basis);
  if (!nodes || !weights || !g || !w || !dw || !c || !mu || !entry || !work || !cache_x || !cache_basis)
    goto done;
  for (int64_t k = 0; k < n; ++k)
  {
    int64_t node = offsets[k];
    const double *piece_mid = mid + label[k] * (k_max + 1), *piece_length = length + label[k] * (k_max + 1);
    for (int64_t piece = 0; piece <= k_max; ++piece)
    {
      const double size = piece_length[piece];
      if (!(size > 0))
        continue;
      const double from = piece_mid[piece] - 0.5 * size;
      for (int32_t x = 0; x < n_gauss; ++x, ++node)
      {
        nodes[node] = from + xi[x] * size;
        weights[node] = wq[x] * size;
      }
    }
    /* the gap, affine along the flight */
    const int64_t pk = p[k];
    double gap = 0.0, speed = 0.0;
    for (int32_t x = 0; x < d; ++x)
    {
      gap += (uc[j[pk] * d + x] - uc[i[pk] * d + x]) * normal[pk * d + x];
      speed += (vc[j[pk] * d + x] - vc[i[pk] * d + x]) * normal[pk * d + x];
    }
    g0[k] = d0[pk] + gap;
    rate[k] = speed;
    for (int64_t e = offsets[k]; e < offsets[k + 1]; ++e)
    {
      g[e] = g0[k] + nodes[e] * rate[k];
      entry[e] = pk;
    }
  }

  /* w and dw at the nodes: clipped on the pairs' own pieces, interpolated */
  if (d == 3) /* a constant d: the clipping unrolled */
    overlap_own(n, 3, p, pairs, uc, vc, n_tau, tau, dt, n_gauss, xi, g0, rate, start_own, length_own, w_own, dw_own);
  else
    overlap_own(n, 2, p, pairs, uc, vc, n_tau, tau, dt, n_gauss, xi, g0, rate, start_own, length_own, w_own, dw_own);
  for (int64_t x = 0; x < stride; ++x)
    cache_x[x] = NAN;
  interpolate_own(n, n_own, offsets, n_gauss, d, start_own, length_own, nodes, xi, w_own, dw_own, w, dw, cache_x,
                  cache_basis);
  for (int64_t e = 0; e < n_nodes; ++e)
    c[e] = w[e] * (g[e] < 0.0 ? g[e] : 0.0);

  rows_term(n, p, &pairs->z, slot, n_rows, rows, &patch->Q, &at, zc, result);
  pairs_term(n, p, pairs, za, &at, mu, work, facet_force, pairs_sum, result);
  if (impulse) /* mu holds the weights: the Gauss sums of -mu w */
    for (int64_t e = 0; e < n_nodes; ++e)
      impulse[entry[e]] -= mu[e] * w[e];
  status = pieces;

done:
  for (int64_t s = 0; s < n_rows; ++s)
    slot[rows[s]] = -1;
  return status;
}

/* Releases the work memory of the contact kernels (the arena stays usable: it grows again). */
void dem_arena_free(dem_arena *work)
{
  arena_free_spill(work);
  free(work->block);
  work->block = NULL;
  work->size = work->used = work->wanted = 0;
}
