/* Contact with rigid obstacles (contact/rigid.py, paper §3.4 with a rigid counterpart, §4): a
 * step's exact force integral and the energy change of a state, on the contact patch. The
 * operations are numpy's and scipy's, in their order (a CSR product sums its row's entries in
 * order from 0; numpy's sums are pairwise_sum's): the results are the same bits. */
#include "internal.h"

/* numpy's pairwise summation of n values a[0], a[stride], ... (the sum of a contiguous array or
 * of a row of a C-contiguous one: 0 + pairwise_sum): blocks of 128 are summed with eight
 * partial sums, longer runs split in two halves (multiples of 8). */
static double pairwise_sum(const double *a, int64_t n, int64_t stride)
{
  if (n < 8)
  {
    double res = 0.0;
    for (int64_t i = 0; i < n; ++i)
      res += a[i * stride];
    return res;
  }
  if (n <= 128)
  {
    double r[8];
    for (int32_t j = 0; j < 8; ++j)
      r[j] = a[j * stride];
    int64_t i = 8;
    for (; i < n - (n % 8); i += 8)
      for (int32_t j = 0; j < 8; ++j)
        r[j] += a[(i + j) * stride];
    double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
    for (; i < n; ++i)
      res += a[i * stride];
    return res;
  }
  int64_t n2 = n / 2;
  n2 -= n2 % 8;
  return pairwise_sum(a, n2, stride) + pairwise_sum(a + n2 * stride, n - n2, stride);
}

/* y[r] = (row r of A) . x, from 0 in the order of the row's entries (scipy's csr_matvec), plus
 * shift[r] if shift is not NULL. */
static void csr_apply(const dem_csr *A, const double *restrict x, const double *restrict shift, double *restrict y)
{
  for (int64_t r = 0; r < A->n_rows; ++r)
  {
    double sum = 0.0;
    for (int32_t e = A->indptr[r]; e < A->indptr[r + 1]; ++e)
      sum += A->data[e] * x[A->indices[e]];
    y[r] = shift ? sum + shift[r] : sum;
  }
}

/* numpy's clip(x, 0, dt): minimum(maximum(x, 0), dt) with its comparisons. */
DEM_INLINE double clip(double x, double dt)
{
  const double y = x > 0.0 ? x : 0.0;
  return y < dt ? y : dt;
}

/* patch.negative_part_integral of one gap g0 + slope tau over [0, dt]. */
DEM_INLINE double negative_part_integral(double g0, double slope, double dt)
{
  const double end = g0 + slope * dt;
  const double root = slope != 0 ? -g0 / slope : INFINITY;
  const double a = g0 < 0 ? 0.0 : clip(root, dt);
  double b = end < 0 ? dt : clip(root, dt);
  b = (g0 >= 0 && end >= 0) ? a : b;
  return (b - a) * (g0 + slope * 0.5 * (a + b));
}

/* RigidContact.force_integral without the scatter: out (the patch's values, overwritten) =
 * int_0^dt (F - F_free)(up + tau vp) dtau of this process's own rows and facets. The gaps are
 * affine along the flight; the rows' part Z g^- is integrated in closed form, each touching own
 * facet's coefficient y_f . (a - delta) on the pieces cut by the events of the candidates it
 * shares rows with (G's columns), by the midpoint rule: exact. normal (n_own values, or NULL):
 * each own facet's normal impulse, the integral of its coefficient (0 out of contact). Returns
 * the largest number of pieces of a facet, or -1 if memory ran out. */
int64_t dem_rigid_force_integral(const dem_rigid *c, const double *restrict up, const double *restrict vp, double dt,
                                 dem_arena *arena, double *restrict out, double *restrict normal)
{
  const int64_t nc = c->Rn.n_rows, n_own = c->n_own;
  arena_start(arena);
  double *g0 = arena_take(arena, nc, sizeof *g0), *s = arena_take(arena, nc, sizeof *s);
  double *nint = arena_take(arena, nc, sizeof *nint);
  int64_t *touching = arena_take(arena, n_own, sizeof *touching), *position = arena_take(arena, n_own, sizeof *position);
  if (!g0 || !s || !nint || !touching || !position)
    return -1;
  csr_apply(&c->Rn, up, c->g0, g0);
  csr_apply(&c->Rn, vp, NULL, s);
  int64_t nt = 0;
  for (int64_t f = 0; f < nc; ++f)
  {
    nint[f] = negative_part_integral(g0[f], s[f], dt);
    const double g1 = g0[f] + dt * s[f];
    if (f < n_own)
    {
      position[f] = -1;
      if (g0[f] < 0 || g1 < 0)
      {
        position[f] = nt;
        touching[nt++] = f;
      }
    }
  }
  csr_apply(&c->Z, nint, NULL, out);
  if (normal)
    for (int64_t f = 0; f < n_own; ++f)
      normal[f] = 0.0;
  if (nt == 0)
    return 1;

  /* the events: the sign changes in (0, dt) of the gaps of the candidates each touching facet
   * shares rows with (G's row), one per candidate */
  const dem_csr *G = &c->G;
  double *tau = arena_take(arena, nc, sizeof *tau);
  int64_t n_entries = 0;
  for (int64_t t = 0; t < nt; ++t)
    n_entries += G->indptr[touching[t] + 1] - G->indptr[touching[t]];
  int64_t *rows = arena_take(arena, n_entries, sizeof *rows), *counts = arena_zeros(arena, nt, sizeof *counts);
  double *times = arena_take(arena, n_entries, sizeof *times);
  if (!tau || !rows || !counts || !times)
    return -1;
  for (int64_t f = 0; f < nc; ++f)
  {
    const double g1 = g0[f] + dt * s[f];
    tau[f] = g0[f] * g1 < 0 ? -g0[f] / s[f] : INFINITY;
  }
  int64_t n_times = 0, k = 0;
  for (int64_t t = 0; t < nt; ++t)
  {
    for (int32_t e = G->indptr[touching[t]]; e < G->indptr[touching[t] + 1]; ++e)
      if (isfinite(tau[G->indices[e]]))
      {
        rows[n_times] = t;
        times[n_times++] = tau[G->indices[e]];
        ++counts[t];
      }
    k = counts[t] > k ? counts[t] : k;
  }
  const int64_t width = k + 1;
  double *points = arena_take(arena, nt * (k + 2), sizeof *points), *mid = arena_take(arena, nt * width, sizeof *mid);
  double *length = arena_take(arena, nt * width, sizeof *length), *sums = arena_take(arena, width, sizeof *sums);
  double *terms = arena_take(arena, width, sizeof *terms), *integral = arena_take(arena, nt, sizeof *integral);
  if (!points || !mid || !length || !sums || !terms || !integral)
    return -1;
  dem_piecewise_midpoints(n_times, rows, times, nt, k, dt, counts, points, mid, length);

  /* each piece's coefficient y_f . a - sum_f' G_ff' min(g_f', 0) at its midpoint, times its
   * length where f is in contact there */
  const dem_csr *YQ = &c->YQ;
  for (int64_t t = 0; t < nt; ++t)
  {
    const int64_t f = touching[t];
    double base = 0.0, rate = 0.0;
    for (int32_t e = YQ->indptr[f]; e < YQ->indptr[f + 1]; ++e)
    {
      base += YQ->data[e] * up[YQ->indices[e]];
      rate += YQ->data[e] * vp[YQ->indices[e]];
    }
    base = base + c->Yq[f];
    const double *m = mid + t * width;
    for (int64_t a = 0; a < width; ++a)
      sums[a] = 0.0;
    for (int32_t e = G->indptr[f]; e < G->indptr[f + 1]; ++e)
    {
      const int32_t col = G->indices[e];
      const double minus = -G->data[e];
      for (int64_t a = 0; a < width; ++a)
      {
        const double x = g0[col] + m[a] * s[col];
        sums[a] += minus * (x <= 0.0 ? x : 0.0);
      }
    }
    for (int64_t a = 0; a < width; ++a)
    {
      const double coefficient = (base + m[a] * rate) + sums[a];
      const double active = g0[f] + m[a] * s[f] < 0 ? 1.0 : 0.0;
      terms[a] = length[t * width + a] * coefficient * active;
    }
    integral[t] = pairwise_sum(terms, width, 1);
    if (normal)
      normal[f] = integral[t];
  }
  /* out += RnT_own[:, touching] integral */
  const dem_csr *RnT = &c->RnT;
  for (int64_t r = 0; r < RnT->n_rows; ++r)
  {
    double sum = 0.0;
    for (int32_t e = RnT->indptr[r]; e < RnT->indptr[r + 1]; ++e)
      if (position[RnT->indices[e]] >= 0)
        sum += RnT->data[e] * integral[position[RnT->indices[e]]];
    out[r] = out[r] + sum;
  }
  return width;
}

/* RigidContact.energy_correction: energy[0], energy[1] = the elastic and stabilisation energy
 * changes of this process's own rows at the patch values up, sum over the own rows of
 * -a delta + delta^2 / 2 (delta = Y g^-, a = Q up + q). Returns the number of candidates in
 * contact (g < 0; energy untouched if none), or -1 if memory ran out. */
int64_t dem_rigid_energy(const dem_rigid *c, const double *restrict up, dem_arena *arena, double *restrict energy)
{
  const int64_t nc = c->Rn.n_rows, n_rows = c->Q.n_rows;
  arena_start(arena);
  double *w = arena_take(arena, nc, sizeof *w);
  if (!w)
    return -1;
  csr_apply(&c->Rn, up, c->g0, w);
  int64_t closed = 0;
  for (int64_t f = 0; f < nc; ++f)
  {
    closed += w[f] < 0;
    w[f] = w[f] < 0 ? w[f] : 0.0;
  }
  if (closed == 0)
    return 0;
  double *a = arena_take(arena, n_rows, sizeof *a), *delta = arena_take(arena, n_rows, sizeof *delta);
  double *elastic = arena_take(arena, n_rows, sizeof *elastic), *other = arena_take(arena, n_rows, sizeof *other);
  if (!a || !delta || !elastic || !other)
    return -1;
  csr_apply(&c->Q, up, c->q, a);
  csr_apply(&c->Y, w, NULL, delta);
  int64_t ne = 0, no = 0;
  for (int64_t r = 0; r < n_rows; ++r)
  {
    const double change = c->own_row[r] ? -a[r] * delta[r] + 0.5 * (delta[r] * delta[r]) : 0.0;
    if (c->elastic[r])
      elastic[ne++] = change;
    else
      other[no++] = change;
  }
  energy[0] = pairwise_sum(elastic, ne, 1);
  energy[1] = pairwise_sum(other, no, 1);
  return closed;
}
