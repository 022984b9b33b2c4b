/* Compiled kernels of dolfinx_dem (built at install by cffi, see _build_kernels.py).
 *
 * They work on process-local arrays only; communication (ghost updates, reductions) is the
 * caller's. Q is held as a CSR matrix of its local rows with local column numbers (owned dofs
 * first, then ghosts); "sums" arguments are accumulated into (+=), never overwritten.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* (Q x)_i for the CSR row [a, b): two accumulators break the dependency chain of the sum. */
static inline double row_dot(int32_t a, int32_t b, const int32_t *restrict cols,
                             const double *restrict vals, const double *restrict x)
{
  double t0 = 0.0, t1 = 0.0;
  int32_t k = a;
  for (; k + 1 < b; k += 2)
  {
    t0 += vals[k] * x[cols[k]];
    t1 += vals[k + 1] * x[cols[k + 1]];
  }
  if (k < b)
    t0 += vals[k] * x[cols[k]];
  return t0 + t1;
}

/* The same for x_j - shift[shift_index[j]] (x shifted by a value per group of columns). */
static inline double row_dot_shifted(int32_t a, int32_t b, const int32_t *restrict cols,
                                     const double *restrict vals, const double *restrict x,
                                     const int32_t *restrict shift_index,
                                     const double *restrict shift)
{
  double t0 = 0.0, t1 = 0.0;
  int32_t k = a;
  for (; k + 1 < b; k += 2)
  {
    const int32_t j0 = cols[k], j1 = cols[k + 1];
    t0 += vals[k] * (x[j0] - shift[shift_index[j0]]);
    t1 += vals[k + 1] * (x[j1] - shift[shift_index[j1]]);
  }
  if (k < b)
    t0 += vals[k] * (x[cols[k]] - shift[shift_index[cols[k]]]);
  return t0 + t1;
}

/* K = Q^T Q applied in one pass over the rows of Q:
 *   y_i <- alpha y_i + scale (Q x)_i   for every local row i,
 *   z   += Q^T y                        (z has the local columns, ghosts included),
 *   sums[0] += sum of y_i^2 over the rows i < n_elastic, sums[1] over the others.
 * With shift_index (NULL: none), x_j - shift[shift_index[j]] replaces x_j (a translation per
 * free body, removed for rounding: Q annihilates it). */
void dem_gram_apply(int64_t n_rows, int64_t n_elastic, const int32_t *restrict rowptr,
                    const int32_t *restrict cols, const double *restrict vals,
                    const double *restrict x, const int32_t *restrict shift_index,
                    const double *restrict shift, double *restrict y, double alpha, double scale,
                    double *restrict z, double *restrict sums)
{
  double s0 = 0.0, s1 = 0.0;
  for (int64_t i = 0; i < n_rows; ++i)
  {
    const int32_t a = rowptr[i], b = rowptr[i + 1];
    const double qx = shift_index ? row_dot_shifted(a, b, cols, vals, x, shift_index, shift)
                                  : row_dot(a, b, cols, vals, x);
    const double yi = alpha * y[i] + scale * qx;
    y[i] = yi;
    for (int32_t k = a; k < b; ++k)
      z[cols[k]] += vals[k] * yi;
    if (i < n_elastic)
      s0 += yi * yi;
    else
      s1 += yi * yi;
  }
  sums[0] += s0;
  sums[1] += s1;
}

/* The sums of dem_gram_apply for the rows scale y + q instead of scale y, given the n entries of
 * q that are not zero (local rows ``rows``, values ``q``): adds q (2 scale y_r + q) to sums[0]
 * (rows r < n_elastic) or sums[1]. */
void dem_lift_sums(int64_t n, const int32_t *restrict rows, const double *restrict q,
                   const double *restrict y, double scale, int64_t n_elastic,
                   double *restrict sums)
{
  for (int64_t k = 0; k < n; ++k)
  {
    const int32_t r = rows[k];
    sums[r >= n_elastic] += q[k] * (2.0 * scale * y[r] + q[k]);
  }
}

/* One MEMM step on n_blocks blocks of bs dofs (a cell's d components share its mass):
 *   impulse_i = load_i - c (z_old_i + z_new_i)          (load may be NULL: zero)
 *   v_new_i   = v_prev_i + 2 minv_b impulse_i             (35b)
 *   u_i      += dt v_next_i                               (35a), if advance
 *   sums[0]  += 1/2 m_b ((v_next_i + v_new_i) / 2)^2      kinetic energy of vbar
 *   sums[1]  += 1/2 m_b v_next_i v_new_i                  pseudo-kinetic energy
 *   sums[2]  += f_i u_i                                   (f may be NULL)
 *   momentum[body_b bs + j] += m_b v_new_i                (body may be NULL)
 *   total[j] += m_b (v_next_i + v_new_i) / 2              the momentum of vbar (bs <= 3)
 * then v_prev_i <- v_new_i and z_old_i <- 0 (ready to accumulate the next Q^T y). */
void dem_memm_update(int64_t n_blocks, int32_t bs, double dt, double c, double *restrict z_old,
                     const double *restrict z_new, const double *restrict load,
                     const double *restrict mass, const double *restrict minv,
                     double *restrict u, const double *restrict v_next,
                     double *restrict v_prev, const double *restrict f, int32_t advance,
                     const int32_t *restrict body, double *restrict momentum,
                     double *restrict total, double *restrict sums)
{
  double kinetic = 0.0, pseudo = 0.0, external = 0.0, p[3] = {0.0, 0.0, 0.0};
  for (int64_t b = 0; b < n_blocks; ++b)
  {
    const double two_minv = 2.0 * minv[b];
    double k2 = 0.0, p2 = 0.0;
    for (int32_t j = 0; j < bs; ++j)
    {
      const int64_t i = b * bs + j;
      double impulse = -c * (z_old[i] + z_new[i]);
      if (load)
        impulse += load[i];
      const double vn = v_next[i];
      const double v_new = v_prev[i] + two_minv * impulse;
      const double vbar = vn + v_new;
      k2 += vbar * vbar;
      p2 += vn * v_new;
      p[j] += mass[b] * vbar;
      if (advance)
        u[i] += dt * vn;
      if (f)
        external += f[i] * u[i];
      v_prev[i] = v_new;
      z_old[i] = 0.0;
      if (body)
        momentum[body[b] * bs + j] += mass[b] * v_new;
    }
    kinetic += mass[b] * k2;
    pseudo += mass[b] * p2;
  }
  sums[0] += 0.125 * kinetic;
  sums[1] += 0.5 * pseudo;
  sums[2] += external;
  for (int32_t j = 0; j < bs; ++j)
    total[j] += 0.5 * p[j];
}

/* The smallest and largest column below n_cols of each row of a CSR (rowptr, cols) of n_rows
 * rows: lo[i] = n_cols and hi[i] = -1 for a row without such a column. */
void dem_row_column_range(int64_t n_rows, const int32_t *restrict rowptr, const int32_t *restrict cols,
                          int32_t n_cols, int32_t *restrict lo, int32_t *restrict hi)
{
  for (int64_t i = 0; i < n_rows; ++i)
  {
    int32_t a = n_cols, b = -1;
    for (int32_t q = rowptr[i]; q < rowptr[i + 1]; ++q)
      if (cols[q] < n_cols)
      {
        a = cols[q] < a ? cols[q] : a;
        b = cols[q] > b ? cols[q] : b;
      }
    lo[i] = a;
    hi[i] = b;
  }
}

/* The pattern of the columns first <= j < first + n_cols of a CSR (rowptr, cols), scanning the
 * rows of the n_ranges increasing ranges [ranges[2k], ranges[2k + 1]) (they must hold every row
 * with an entry in those columns): the rows with an entry in column j, increasing, are
 * rows[ptr[j - first] .. ptr[j - first + 1]). With rows NULL only ptr (n_cols + 1 entries) is
 * computed; then, with rows of ptr[n_cols] entries, the rows (ptr is used as the cursor and
 * restored). A transpose without values: 4 bytes per entry. */
void dem_transpose_pattern(const int64_t *restrict ranges, int32_t n_ranges, const int32_t *restrict rowptr,
                           const int32_t *restrict cols, int32_t first, int32_t n_cols,
                           int32_t *restrict ptr, int32_t *restrict rows)
{
  if (!rows)
  {
    for (int32_t j = 0; j <= n_cols; ++j)
      ptr[j] = 0;
    for (int32_t k = 0; k < n_ranges; ++k)
      for (int64_t i = ranges[2 * k]; i < ranges[2 * k + 1]; ++i)
        for (int32_t q = rowptr[i]; q < rowptr[i + 1]; ++q)
          if (cols[q] >= first && cols[q] - first < n_cols)
            ++ptr[cols[q] - first + 1];
    for (int32_t j = 0; j < n_cols; ++j)
      ptr[j + 1] += ptr[j];
    return;
  }
  for (int32_t k = 0; k < n_ranges; ++k)
    for (int64_t i = ranges[2 * k]; i < ranges[2 * k + 1]; ++i)
      for (int32_t q = rowptr[i]; q < rowptr[i + 1]; ++q)
        if (cols[q] >= first && cols[q] - first < n_cols)
          rows[ptr[cols[q] - first]++] = (int32_t)i;
  for (int32_t j = n_cols; j > 0; --j) /* ptr[j] is now the old ptr[j + 1]: shift back */
    ptr[j] = ptr[j - 1];
  ptr[0] = 0;
}

/* Row sums of |Q^T Q| weighted by x, for the stable time step bound:
 *   r_i = sum_j |(Q^T Q)_ij| x_j   for the n_out owned dofs i = first, first + 1, ...
 * (x NULL: r_i = (Q^T Q)_ii = sum_k Q_ki^2; r is indexed from first). The rows of Q through dof i
 * come from two sets, each a CSR (rowptr, cols, vals) with a key per row: this process's rows,
 * listed for dof i by (qt_ptr, qt_rows) at i - first in increasing key (``dem_transpose_pattern``
 * of the same columns), and rows of other processes (set 2, listed by qt2_ptr at i); both are visited merged in increasing key, a numbering of the rows
 * that does not depend on the partition, and each row's columns in the order of the global dof
 * numbering: the same sums, to the bit, on any number of processes. Column numbers index x and
 * acc (zeros of the length of x, left zero); owned dof i is column i in both sets, and Q_ki is
 * read from row k (no transposed values are stored). Row i of Q^T Q is accumulated in acc,
 * then harvested: the first visit of a column j adds |acc_j| x_j and zeroes acc_j, so later
 * visits add 0. */
typedef struct
{
  const int32_t *qt_ptr, *qt_rows, *rowptr, *cols;
  const double *vals;
  const int64_t *key;
} dem_row_set;

/* Q_ki: the entry of column i in row k of a set (each column appears once in a row). */
static inline double row_entry(const dem_row_set *set, int32_t k, int64_t i)
{
  for (int32_t q = set->rowptr[k]; q < set->rowptr[k + 1]; ++q)
    if (set->cols[q] == i)
      return set->vals[q];
  return 0.0;
}

void dem_gram_abs_rowsums(int64_t first, int64_t n_out, const int32_t *restrict qt_ptr,
                          const int32_t *restrict qt_rows, const int32_t *restrict rowptr,
                          const int32_t *restrict cols, const double *restrict vals,
                          const int64_t *restrict key, const int32_t *restrict qt2_ptr,
                          const int32_t *restrict qt2_rows, const int32_t *restrict rowptr2,
                          const int32_t *restrict cols2, const double *restrict vals2,
                          const int64_t *restrict key2, const double *restrict x,
                          double *restrict r, double *restrict acc)
{
  const dem_row_set sets[2] = {{qt_ptr, qt_rows, rowptr, cols, vals, key},
                               {qt2_ptr, qt2_rows, rowptr2, cols2, vals2, key2}};
  for (int64_t i = first; i < first + n_out; ++i)
  {
    double s = 0.0;
    for (int pass = (x ? 0 : 1); pass < 2; ++pass) /* 0: accumulate, 1: harvest (or diagonal) */
    {
      int32_t p[2] = {qt_ptr[i - first], qt2_ptr[i]};
      const int32_t end[2] = {qt_ptr[i - first + 1], qt2_ptr[i + 1]};
      while (p[0] < end[0] || p[1] < end[1])
      {
        int which = 0;
        if (p[0] >= end[0])
          which = 1;
        else if (p[1] < end[1] && key2[qt2_rows[p[1]]] < key[qt_rows[p[0]]])
          which = 1;
        const dem_row_set *set = &sets[which];
        const int32_t k = set->qt_rows[p[which]];
        ++p[which];
        if (!x)
        {
          const double a = row_entry(set, k, i);
          s += a * a;
        }
        else if (pass == 0)
        {
          const double a = row_entry(set, k, i);
          for (int32_t q = set->rowptr[k]; q < set->rowptr[k + 1]; ++q)
            acc[set->cols[q]] += a * set->vals[q];
        }
        else
          for (int32_t q = set->rowptr[k]; q < set->rowptr[k + 1]; ++q)
          {
            const int32_t j = set->cols[q];
            s += fabs(acc[j]) * x[j];
            acc[j] = 0.0;
          }
      }
    }
    r[i] = s;
  }
}

/* Clipping of pair_contact._overlap, for one face f of a simplex F (nv vertices X of dim
 * components; face f runs from X[f] to X[next[f]]) against the simplex O (vertices Y, outward
 * face normals m): the part [lower, lower + length] of the face inside O (the half-planes
 * m_k . (x - Y_k) <= 0, Liang-Barsky). With ties, a face lying on a face of O with the same
 * outward normal (mF: its own normal) is out. The same operations in the same order as numpy's. */
static inline __attribute__((always_inline)) void clip_face(int32_t nv, int32_t dim, const int32_t *next, const double *X, int32_t f,
                      const double *mF, const double *Y, const double *m, int32_t ties,
                      double *lower, double *length)
{
  double e[2];
  for (int32_t c = 0; c < dim; ++c)
    e[c] = X[next[f] * dim + c] - X[f * dim + c];
  double lo = 0.0, up = 1.0;
  int32_t out = 0;
  for (int32_t k = 0; k < nv; ++k)
  {
    double h0 = (X[f * dim] - Y[k * dim]) * m[k * dim], h1 = e[0] * m[k * dim];
    for (int32_t c = 1; c < dim; ++c)
    {
      h0 = h0 + (X[f * dim + c] - Y[k * dim + c]) * m[k * dim + c];
      h1 = h1 + e[c] * m[k * dim + c];
    }
    const double r = -h0 / h1;
    const double l = h1 < 0 ? r : 0.0, u = h1 > 0 ? r : 1.0;
    lo = k == 0 ? l : (l > lo ? l : lo);
    up = k == 0 ? u : (u < up ? u : up);
    if (h1 == 0 && h0 > 0)
      out = 1;
    if (ties && h1 == 0 && h0 == 0)
    {
      double mm = mF[f * dim] * m[k * dim];
      for (int32_t c = 1; c < dim; ++c)
        mm = mm + mF[f * dim + c] * m[k * dim + c];
      if (mm > 0)
        out = 1;
    }
  }
  const double span = up - lo;
  *lower = lo;
  *length = out ? 0.0 : (span > 0.0 ? span : 0.0);
}

/* The smallest and largest coordinates (lo, hi: dim each) of nv points X of dim components. */
static inline __attribute__((always_inline)) void box(int32_t nv, int32_t dim, const double *X, double *lo, double *hi)
{
  for (int32_t c = 0; c < dim; ++c)
  {
    lo[c] = hi[c] = X[c];
    for (int32_t k = 1; k < nv; ++k)
    {
      const double x = X[k * dim + c];
      lo[c] = x < lo[c] ? x : lo[c];
      hi[c] = x > hi[c] ? x : hi[c];
    }
  }
}

/* Whether the bounding boxes of the simplices X and Y are strictly apart (a gap on some axis):
 * then their intersection is empty. */
static inline __attribute__((always_inline)) int32_t boxes_apart(int32_t nv, int32_t dim, const double *X, const double *Y)
{
  double lx[2], hx[2], ly[2], hy[2];
  box(nv, dim, X, lx, hx);
  box(nv, dim, Y, ly, hy);
  for (int32_t c = 0; c < dim; ++c)
    if (ly[c] > hx[c] || hy[c] < lx[c])
      return 1;
  return 0;
}

/* w = |A_q cap (B_q + s)| and dw/ds (dim components) of one simplex pair q; see dem_overlap. */
static inline __attribute__((always_inline)) void overlap_one(int32_t dim, int64_t q, const double *XA, const double *mA, const double *nuA,
                        const double *sizeA, const double *XB, const double *mB, const double *nuB,
                        const double *sizeB, const double *s, double *w, double *dw)
{
  const int32_t nv = dim + 1, stride = nv * dim;
  const int32_t next[3] = {dim == 1 ? 0 : 1, dim == 1 ? 1 : 2, 0};  /* a face's end vertex */
  const double *X = XA + q * stride, *m = mA + q * stride, *nu = nuA + q * stride;
  const double *mb = mB + q * stride, *nub = nuB + q * stride;
  double Y[6];
  for (int32_t k = 0; k < nv; ++k)
    for (int32_t c = 0; c < dim; ++c)
      Y[k * dim + c] = XB[q * stride + k * dim + c] + s[c];
  if (boxes_apart(nv, dim, X, Y))
  {
    *w = 0.0;
    for (int32_t c = 0; c < dim; ++c)
      dw[c] = 0.0;
    return;
  }
  double total = 0.0, grad[2] = {0.0, 0.0};
  for (int32_t side = 0; side < 2; ++side)
  {
    const double *F = side ? Y : X, *mF = side ? mb : m, *nuF = side ? nub : nu;
    const double *size = side ? sizeB + q * nv : sizeA + q * nv;
    double sum = 0.0;
    for (int32_t f = 0; f < nv; ++f)
    {
      double lower, length;
      clip_face(nv, dim, next, F, f, mF, side ? X : Y, side ? m : mb, side, &lower, &length);
      const double at = lower + 0.5 * length, measure = length * size[f];
      double x = (F[f * dim] + at * (F[next[f] * dim] - F[f * dim])) * nuF[f * dim];
      for (int32_t c = 1; c < dim; ++c)
        x = x + (F[f * dim + c] + at * (F[next[f] * dim + c] - F[f * dim + c])) * nuF[f * dim + c];
      sum = f == 0 ? x * measure : sum + x * measure;
      if (side)
        for (int32_t c = 0; c < dim; ++c)
          grad[c] = f == 0 ? nuF[f * dim + c] * measure : grad[c] + nuF[f * dim + c] * measure;
    }
    total = total + sum;
  }
  total = total / dim;
  const int32_t inside = total > 0;
  *w = inside ? total : 0.0;
  for (int32_t c = 0; c < dim; ++c)
    dw[c] = inside ? grad[c] : 0.0;
}

/* w = |A_q cap (B_q + s_i)| and dw/ds (see pair_contact._overlap) for n offsets s_i (dim
 * components, dim = 1 or 2) of the simplex pairs q = p[i]: vertices X (nv = dim + 1 per simplex,
 * dim components each), outward face normals m and their unit vectors nu (one per face), face
 * measures size. w (n) and dw (n dim) are overwritten; both are 0 where the bounding boxes of
 * A_q and B_q + s_i are apart (no clipping). */
void dem_overlap(int64_t n, int32_t dim, const int64_t *restrict p, const double *restrict XA,
                 const double *restrict mA, const double *restrict nuA, const double *restrict sizeA,
                 const double *restrict XB, const double *restrict mB, const double *restrict nuB,
                 const double *restrict sizeB, const double *restrict s, double *restrict w,
                 double *restrict dw)
{
  for (int64_t i = 0; i < n; ++i)
    overlap_one(dim, p[i], XA, mA, nuA, sizeA, XB, mB, nuB, sizeB, s + i * dim, w + i, dw + i * dim);
}

/* w and dw/du_j = t^T dw/ds (d components) of the simplex pair q (see dem_overlap) at the
 * relative displacement du = u_j - u_i (d components) of its facets: overlap_one at the
 * tangential offset s = t du (t: the pair's d - 1 tangent rows of d). */
static inline __attribute__((always_inline)) void pair_overlap(int32_t d, int64_t q, const double *t, const double *du, const double *XA,
                         const double *mA, const double *nuA, const double *sizeA, const double *XB,
                         const double *mB, const double *nuB, const double *sizeB, double *w, double *dw)
{
  const int32_t dim = d - 1;
  double s[2], dws[2];
  for (int32_t r = 0; r < dim; ++r)
  {
    s[r] = 0.0;
    for (int32_t c = 0; c < d; ++c)
      s[r] += t[(q * dim + r) * d + c] * du[c];
  }
  overlap_one(dim, q, XA, mA, nuA, sizeA, XB, mB, nuB, sizeB, s, w, dws);
  for (int32_t c = 0; c < d; ++c)
  {
    dw[c] = 0.0;
    for (int32_t r = 0; r < dim; ++r)
      dw[c] += dws[r] * t[(q * dim + r) * d + c];
  }
}

/* A pair's overlap on its own pieces (dem_pair_force_integral, before interpolate_own): for the
 * pairs p[e] of facets (i, j) moving along uc + tau vc (n_facets x d), with their events tau
 * (n_tau per pair, INFINITY: none; in (0, dt)), the own pieces of [0, dt] cut at the sorted
 * events (padded with empty pieces up to n_tau + 1: start, length, as dem_piecewise_midpoints
 * and dem_pair_force_integral's nodes compute them), and at the n_gauss nodes xi of each non-empty piece w and
 * dw/du_j = t^T dw/ds (d components) at the tangential offset s = t (u_j - u_i)
 * (overlap_one); 0 on the pieces where the gap g0 + tau rate is not negative (not clipped:
 * nothing reads w there); nothing on empty pieces (nothing reads them). t: the pairs' tangent
 * bases (d - 1 rows of d). */
static inline __attribute__((always_inline)) void
overlap_own(int64_t n, const int32_t d, const int64_t *restrict p, const int64_t *restrict i,
            const int64_t *restrict j, const double *restrict t, const double *restrict uc,
            const double *restrict vc, int32_t n_tau, const double *restrict tau, double dt,
            int32_t n_gauss, const double *restrict xi, const double *restrict XA,
            const double *restrict mA, const double *restrict nuA, const double *restrict sizeA,
            const double *restrict XB, const double *restrict mB, const double *restrict nuB,
            const double *restrict sizeB, const double *restrict g0, const double *restrict rate,
            double *restrict start, double *restrict length, double *restrict w, double *restrict dw)
{
  const int32_t n_own = n_tau + 1;
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
        pair_overlap(d, q, t, du, XA, mA, nuA, sizeA, XB, mB, nuB, sizeB, w + node, dw + node * d);
      }
    }
  }
}

/* out = R x + lift (lift may be NULL) for the CSR matrix R (n_rows rows): each row's sum in the
 * order of its entries (as scipy's product), then the lift added. The free facet displacements
 * of pair_contact.PairContact. */
void dem_csr_apply(int64_t n_rows, const int32_t *restrict ptr, const int32_t *restrict idx,
                   const double *restrict val, const double *restrict x, const double *restrict lift,
                   double *restrict out)
{
  for (int64_t r = 0; r < n_rows; ++r)
  {
    double sum = 0.0;
    for (int32_t e = ptr[r]; e < ptr[r + 1]; ++e)
      sum += val[e] * x[idx[e]];
    out[r] = lift ? sum + lift[r] : sum;
  }
}

/* The facet that moved farthest since the list was built, relative to half its skin, at the free
 * displacements uc + tau vc (n facets x d; vc NULL: uc): the k maximising |x_k - reference_k|^2 /
 * half_skin2_k (half_skin2 NULL: 1) (returned; -1 if n = 0) and that ratio (*ratio; 0 if n = 0). */
int64_t dem_pair_worst_motion(int64_t n, int32_t d, const double *restrict uc, const double *restrict vc, double tau,
                              const double *restrict reference, const double *restrict half_skin2,
                              double *restrict ratio)
{
  int64_t worst = -1;
  double largest = 0.0;
  for (int64_t k = 0; k < n; ++k)
  {
    double moved2 = 0.0;
    for (int32_t c = 0; c < d; ++c)
    {
      const double x = vc ? uc[k * d + c] + tau * vc[k * d + c] : uc[k * d + c];
      moved2 += (x - reference[k * d + c]) * (x - reference[k * d + c]);
    }
    const double r = half_skin2 ? moved2 / half_skin2[k] : moved2;
    if (worst < 0 || r > largest)
    {
      worst = k;
      largest = r;
    }
  }
  *ratio = largest;
  return worst;
}

/* dem_pair_end_state's two motion checks: dem_pair_worst_motion of uc against the
 * list's reference (returned, ratio[0]), and (end != NULL) the largest |end + tau vc - uc|^2
 * (ratio[1]): how far uc lies from the end of the last flight (end, vc, tau). */
static int64_t state_motion(int64_t n, int32_t d, const double *restrict uc, const double *restrict reference,
                            const double *restrict half_skin2, const double *restrict end,
                            const double *restrict vc, double tau, double *restrict ratio)
{
  if (end)
    dem_pair_worst_motion(n, d, end, vc, tau, uc, NULL, ratio + 1);
  return dem_pair_worst_motion(n, d, uc, NULL, 0.0, reference, half_skin2, ratio);
}

/* pair_contact._project: the vertices of facets f[p] (ends: n_facets x d x d) relative to the
 * barycentre of facet origin[p] (centre: n_facets x d), on the tangents of pair p (t: n x (d - 1) x
 * d): X (n x d x (d - 1)), each coordinate's d products summed in the order of numpy's einsum, which
 * made them before (x = 0, 1 in 2D; (x = 0 + x = 2) + x = 1 in 3D): the same bits. */
void dem_pair_project(int64_t n, int32_t d, const int64_t *restrict f, const int64_t *restrict origin,
                      const double *restrict ends, const double *restrict centre, const double *restrict t,
                      double *restrict X)
{
  for (int64_t p = 0; p < n; ++p)
    for (int32_t k = 0; k < d; ++k)
      for (int32_t a = 0; a < d - 1; ++a)
      {
        double q[3];
        for (int32_t x = 0; x < d; ++x)
          q[x] = (ends[(f[p] * d + k) * d + x] - centre[origin[p] * d + x]) * t[(p * (d - 1) + a) * d + x];
        X[(p * d + k) * (d - 1) + a] = d == 3 ? (q[0] + q[2]) + q[1] : q[0] + q[1];
      }
}

/* pair_contact._Simplices.of: for n (d-1)-simplices with vertices X (n x d x (d - 1)), face k's
 * end (the next vertex in 3D, X_k in 2D), outward normal m_k (unnormalised: in 3D the edge turned
 * by the orientation's sign, in 2D X_k - X_other), nu_k = m_k / |m_k| (0 if m_k = 0) and size (the
 * edge's length in 3D, 1 in 2D); every norm sqrt(sum of squares) in order, as numpy's. */
void dem_simplices(int64_t n, int32_t d, const double *restrict X, double *restrict end, double *restrict m,
                   double *restrict nu, double *restrict size)
{
  for (int64_t p = 0; p < n; ++p)
  {
    const double *x = X + p * d * (d - 1);
    double *e_ = end + p * d * (d - 1), *m_ = m + p * d * (d - 1), *nu_ = nu + p * d * (d - 1);
    if (d == 2)
    {
      for (int32_t k = 0; k < 2; ++k)
      {
        e_[k] = x[k];
        m_[k] = x[k] - x[1 - k];
        size[p * 2 + k] = 1.0;
        const double norm = sqrt(m_[k] * m_[k]);
        nu_[k] = norm > 0 ? m_[k] / norm : 0.0;
      }
      continue;
    }
    const double c = (x[2] - x[0]) * (x[5] - x[1]) - (x[3] - x[1]) * (x[4] - x[0]);
    const double sign = c > 0 ? 1.0 : c < 0 ? -1.0 : 0.0; /* +1: counter-clockwise */
    for (int32_t k = 0; k < 3; ++k)
    {
      const int32_t next = (k + 1) % 3;
      e_[2 * k] = x[2 * next], e_[2 * k + 1] = x[2 * next + 1];
      const double e0 = x[2 * next] - x[2 * k], e1 = x[2 * next + 1] - x[2 * k + 1];
      m_[2 * k] = sign * e1, m_[2 * k + 1] = sign * -e0;
      size[p * 3 + k] = sqrt(e0 * e0 + e1 * e1);
      const double norm = sqrt(m_[2 * k] * m_[2 * k] + m_[2 * k + 1] * m_[2 * k + 1]);
      nu_[2 * k] = norm > 0 ? m_[2 * k] / norm : 0.0;
      nu_[2 * k + 1] = norm > 0 ? m_[2 * k + 1] / norm : 0.0;
    }
  }
}

/* The separations of flight_screen for n pairs of simplices A, B (d vertices of dim = d - 1
 * components each, face k from vertex k, outward face normals mA, mB unnormalised): out (n x 2 d)
 * = for each face k of A, then of B, min over the other's vertices Y_b of m_k . (Y_b - X_k),
 * less margin |m_k| times the pair's size (the largest |coordinate| of its vertices). */
void dem_pair_separations(int64_t n, int32_t d, const double *restrict XA, const double *restrict mA,
                          const double *restrict XB, const double *restrict mB, double margin,
                          double *restrict out)
{
  const int32_t dim = d - 1, stride = d * dim;
  for (int64_t p = 0; p < n; ++p)
  {
    double size = 0.0;
    for (int32_t k = 0; k < stride; ++k)
      size = fmax(size, fmax(fabs(XA[p * stride + k]), fabs(XB[p * stride + k])));
    for (int32_t side = 0; side < 2; ++side)
    {
      const double *X = (side ? XB : XA) + p * stride, *m = (side ? mB : mA) + p * stride;
      const double *Y = (side ? XA : XB) + p * stride;
      for (int32_t k = 0; k < d; ++k)
      {
        double low = INFINITY, norm2 = 0.0;
        for (int32_t b = 0; b < d; ++b)
        {
          double h = 0.0;
          for (int32_t c = 0; c < dim; ++c)
            h += m[k * dim + c] * (Y[b * dim + c] - X[k * dim + c]);
          low = h < low ? h : low;
        }
        for (int32_t c = 0; c < dim; ++c)
          norm2 += m[k * dim + c] * m[k * dim + c];
        out[p * 2 * d + side * d + k] = low - margin * sqrt(norm2) * size;
      }
    }
  }
}

/* The pairs p of facets (i[p], j[p]) (d components, d = 2 or 3) whose c_p = w_p g_p^- may not
 * vanish for the free facet displacements uc + tau vc, 0 <= tau <= dt (uc, vc: n_facets x d):
 * the gap g = d0 + (u_j - u_i) . n negative at an end, and the projected simplices A and B +
 * s(tau), s = t (u_j - u_i) (t: d - 1 rows of d), not separated by the line of a face at some
 * tau. The faces' outward normals mA, mB (d per simplex, dim = d - 1 components) are the
 * separating axes of two simplices in the plane (the line in 2D): B lies beyond A's face k while
 * sep[k] + mA_k . s > 0, A beyond B's face k while sep[d + k] - mB_k . s > 0 (sep: 2 d per
 * pair, pair_contact._separations: the smallest distance of the other's vertices beyond each
 * face at s = 0 times |m_k|, less a margin), each affine in tau along the flight. out[p] bit 0:
 * such a pair. Without vc (NULL): at uc, bit 0 only. With vc, bit 1: the pair may be screened in
 * (bit 0 of a screen without vc) at a displacement whose facets lie within slack / 2 of the
 * flight's end, uc + dt vc: its gap there below slack, and no separation there above slack
 * |m_k| (pair_contact._At screens those pairs only). The pairs subset[0 .. count) (subset
 * NULL: the pairs 0 .. count), out[p] for those only. */
static inline __attribute__((always_inline)) void
screen_pairs(int64_t count, const int32_t d, const int64_t *restrict subset, const int64_t *restrict i,
             const int64_t *restrict j, const double *restrict n, const double *restrict t,
             const double *restrict d0, const double *restrict sep, const double *restrict mA,
             const double *restrict mB, const double *restrict uc, const double *restrict vc, double dt, double slack,
             int8_t *restrict out)
{
  const int32_t dim = d - 1, stride = d * dim;
  for (int64_t e = 0; e < count; ++e)
  {
    const int64_t p = subset ? subset[e] : e;
    double du[3], dv[3], g0 = 0.0, g1 = 0.0;
    for (int32_t k = 0; k < d; ++k)
    {
      du[k] = uc[j[p] * d + k] - uc[i[p] * d + k];
      g0 += du[k] * n[p * d + k];
    }
    g0 = d0[p] + g0;
    for (int32_t k = 0; k < d; ++k)
    {
      dv[k] = vc ? vc[j[p] * d + k] - vc[i[p] * d + k] : 0.0;
      g1 += (du[k] + dt * dv[k]) * n[p * d + k];
    }
    g1 = d0[p] + g1;
    const int32_t closing = g0 < 0 || g1 < 0, near = vc && g1 < slack;
    if (!closing && !near)
    {
      out[p] = 0;
      continue;
    }
    double s0[2], s1[2];
    for (int32_t c = 0; c < dim; ++c)
    {
      s0[c] = s1[c] = 0.0;
      for (int32_t k = 0; k < d; ++k)
      {
        s0[c] += t[(p * dim + c) * d + k] * du[k];
        s1[c] += t[(p * dim + c) * d + k] * dv[k];
      }
    }
    /* the separations h0 + tau h1 along the flight (span = dt; 0 without one): a pair is out if
     * one stays non-negative at both ends (affine: all along), in if all are negative at an end,
     * else if they are all negative at some time between (an interval: rarely computed) */
    const double span = vc ? dt : 0.0;
    double h0[6], h1[6];
    int32_t apart = 0, in0 = 1, in1 = 1, end_near = near;
    for (int32_t axis = 0; axis < 2 * d; ++axis)
    {
      const double *m = axis < d ? mA + p * stride + axis * dim : mB + p * stride + (axis - d) * dim;
      const double sign = axis < d ? 1.0 : -1.0;
      double a = 0.0, b = 0.0, m2 = 0.0;
      for (int32_t c = 0; c < dim; ++c)
      {
        a += m[c] * s0[c];
        b += m[c] * s1[c];
        m2 += m[c] * m[c];
      }
      h0[axis] = sep[p * 2 * d + axis] + sign * a;
      h1[axis] = sign * b;
      const double end = h0[axis] + span * h1[axis];
      apart = apart || (h0[axis] >= 0 && end >= 0);
      in0 = in0 && h0[axis] < 0;
      in1 = in1 && end < 0;
      end_near = end_near && (end < 0 || end * end < m2 * slack * slack);
    }
    int32_t touch = closing && !apart && (in0 || in1);
    if (closing && !apart && !in0 && !in1)
    {
      double start = 0.0, stop = span;
      for (int32_t axis = 0; axis < 2 * d; ++axis)
      {
        if (h0[axis] < 0 && h0[axis] + span * h1[axis] < 0)
          continue; /* negative all along */
        const double root = -h0[axis] / h1[axis]; /* h1 != 0: the two ends differ in sign */
        if (h1[axis] > 0)
          stop = root < stop ? root : stop;
        else
          start = root > start ? root : start;
      }
      touch = start <= stop;
    }
    out[p] = (int8_t)(touch | (end_near << 1));
  }
}

/* screen_pairs with a constant d (its loops unrolled) */
static void screen(int64_t count, int32_t d, const int64_t *restrict subset, const int64_t *restrict i,
                   const int64_t *restrict j, const double *restrict n, const double *restrict t,
                   const double *restrict d0, const double *restrict sep, const double *restrict mA,
                   const double *restrict mB, const double *restrict uc, const double *restrict vc, double dt,
                   double slack, int8_t *restrict out)
{
  if (d == 3)
    screen_pairs(count, 3, subset, i, j, n, t, d0, sep, mA, mB, uc, vc, dt, slack, out);
  else
    screen_pairs(count, 2, subset, i, j, n, t, d0, sep, mA, mB, uc, vc, dt, slack, out);
}

/* screen_pairs over the list, and its two sets as sorted indices: touching (bit 0) and
 * candidates (bit 1), n_pairs each at most, counts[0] and counts[1] their numbers (out: n_pairs,
 * work). */
static void flight_screen(int64_t n_pairs, int32_t d, const int64_t *restrict i, const int64_t *restrict j,
                          const double *restrict n, const double *restrict t, const double *restrict d0,
                          const double *restrict sep, const double *restrict mA, const double *restrict mB,
                          const double *restrict uc, const double *restrict vc, double dt, double slack,
                          int8_t *restrict out, int64_t *restrict touching, int64_t *restrict candidates,
                          int64_t *restrict counts)
{
  screen(n_pairs, d, NULL, i, j, n, t, d0, sep, mA, mB, uc, vc, dt, slack, out);
  counts[0] = counts[1] = 0;
  for (int64_t p = 0; p < n_pairs; ++p)
  {
    if (out[p] & 1)
      touching[counts[0]++] = p;
    if (out[p] & 2)
      candidates[counts[1]++] = p;
  }
}

/* pair_contact.PairContact._flight, a step's free flight uc + tau vc (0 <= tau <= dt) in one call:
 * vc = R vp (dem_csr_apply: R n_rows = n_facets d rows), the facet farthest from the list's
 * reference at the flight's end relative to half its skin (dem_pair_worst_motion: returned, and
 * *ratio), and, if do_screen and *ratio <= 1, flight_screen (else counts = -1). */
int64_t dem_pair_flight(int64_t n_rows, const int32_t *restrict ptr, const int32_t *restrict idx,
                        const double *restrict val, const double *restrict vp, const double *restrict uc, double dt,
                        const double *restrict reference, const double *restrict half_skin2, int32_t do_screen,
                        int64_t n_pairs, int32_t d, const int64_t *restrict i, const int64_t *restrict j,
                        const double *restrict n, const double *restrict t, const double *restrict d0,
                        const double *restrict sep, const double *restrict mA, const double *restrict mB,
                        double slack, double *restrict vc, double *restrict ratio, int8_t *restrict out,
                        int64_t *restrict touching, int64_t *restrict candidates, int64_t *restrict counts)
{
  dem_csr_apply(n_rows, ptr, idx, val, vp, NULL, vc);
  const int64_t worst = dem_pair_worst_motion(n_rows / d, d, uc, vc, dt, reference, half_skin2, ratio);
  if (do_screen && !(*ratio > 1.0))
    flight_screen(n_pairs, d, i, j, n, t, d0, sep, mA, mB, uc, vc, dt, slack, out, touching, candidates, counts);
  else
    counts[0] = counts[1] = -1;
  return worst;
}

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

/* Relative margin of the edge tests of pair_events (of the edge length) and of the separating
 * axes of flight_screen (of the pair's projected size): far above rounding, far below any
 * configuration that matters. */
#define EDGE_MARGIN 1e-9

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

/* The events of dem_pair_force_integral for the pairs p[e] of facets (i, j) (n, t, d0 per
 * pair; XA, mA, XB, mB the projected simplices, d vertices of dim = d - 1 coordinates and their
 * faces' normals m) along the flight uc + tau vc (n_facets x d): the times in (0, dt) where the
 * gap, or the side m_k . (x - X_k) of a vertex x of one simplex to the line of face k of the
 * other (B moved by the tangential offset s0 + tau s1), changes sign; INFINITY where none.
 * tau: n x (1 + 2 d^2), columns [gap, (vertex a of A, face k of B) at 1 + a d + k, (vertex a of
 * B, face k of A) at 1 + d^2 + a d + k]. */
static void pair_events(int64_t n, int32_t d, const int64_t *restrict p, const int64_t *restrict i,
                        const int64_t *restrict j, const double *restrict normal, const double *restrict t,
                        const double *restrict d0, const double *restrict XA, const double *restrict mA,
                        const double *restrict XB, const double *restrict mB, const double *restrict uc,
                        const double *restrict vc, double dt, double *restrict tau)
{
  const int32_t dim = d - 1, stride = d * dim, width = 1 + 2 * d * d;
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

/* The facet corrections of pair_contact.PairContact.facet_corrections (eq. (31)): for the pairs
 * p[k] of facets (i, j) with c_k = w g^-, out[f] = sum over the pairs with i = f of (c_k / |f|)
 * e_i plus sum over those with j = f of (c_k / |f|) e_j, each sum in the order of the pairs and
 * the two added last (the bits of two bincounts). out and work: n_facets x d, zero on entry. */
void dem_pair_facet_corrections(int64_t n, int32_t d, const int64_t *restrict p, const int64_t *restrict i,
                                const int64_t *restrict j, const double *restrict e_i, const double *restrict e_j,
                                const double *restrict c, const double *restrict length, int64_t n_facets,
                                double *restrict work, double *restrict out)
{
  for (int64_t k = 0; k < n; ++k)
  {
    const int64_t q = p[k];
    const double a = c[k] / length[i[q]], b = c[k] / length[j[q]];
    for (int32_t x = 0; x < d; ++x)
    {
      out[i[q] * d + x] += a * e_i[q * d + x];
      work[j[q] * d + x] += b * e_j[q * d + x];
    }
  }
  for (int64_t f = 0; f < n_facets * d; ++f)
    out[f] += work[f];
}

/* The facet forces of pair_contact.PairContact._facet_force: for the entries k (pairs p[k] of
 * facets (i, j), normals n), dc = mu_k (w_k n + g_k dw_k) (d components) is added to facet i's
 * row of out and subtracted from facet j's (out: n_facets x d, accumulated into, in the order of
 * the entries). */
void dem_pair_facet_forces(int64_t n_entries, int32_t d, const int64_t *restrict p, const int64_t *restrict i,
                           const int64_t *restrict j, const double *restrict normal, const double *restrict mu,
                           const double *restrict g, const double *restrict w, const double *restrict dw,
                           double *restrict out)
{
  for (int64_t k = 0; k < n_entries; ++k)
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

/* Insertion sort of a[0..n) (nearly sorted runs: few moves). */
static void sort_small(int32_t *a, int32_t n)
{
  for (int32_t k = 1; k < n; ++k)
  {
    const int32_t r = a[k];
    int32_t b = k - 1;
    while (b >= 0 && a[b] > r)
    {
      a[b + 1] = a[b];
      --b;
    }
    a[b + 1] = r;
  }
}

/* Z^T of a pair list build (pair_contact.PairContact._build): row k, for the pair (i[k], j[k]),
 * is sum over its local facets f (f < n_local; in increasing f) and their components x of
 * (e_f[x] / |f|) times column f d + x of QF (CSC: qf_ptr, qf_rows, qf_vals), the columns' entries
 * accumulated in their order; exact zeros are dropped and each row's columns sorted: the bits
 * and the pattern of scipy's (E^T @ QF^T).sort_indices(), E the facet dofs' directions, without
 * forming E^T. sums (n_cols) must be zero and mark (n_cols) -1 on entry, and are left so;
 * touched: 2 n_cols. indices and data must hold the sum over the rows of their columns' entries.
 * Returns the number of entries. */
int64_t dem_pair_rows(int64_t n_pairs, int32_t d, const int64_t *restrict i, const int64_t *restrict j,
                      int64_t n_local, const double *restrict e_i, const double *restrict e_j,
                      const double *restrict length, const int32_t *restrict qf_ptr,
                      const int32_t *restrict qf_rows, const double *restrict qf_vals, double *restrict sums,
                      int32_t *restrict mark, int32_t *restrict touched, int32_t *restrict indptr,
                      int32_t *restrict indices, double *restrict data)
{
  int64_t nnz = 0;
  indptr[0] = 0;
  for (int64_t k = 0; k < n_pairs; ++k)
  {
    /* the rows each facet touches first, each facet's sorted (its d columns share most rows) */
    int32_t n_side[2] = {0, 0}, n_touched = 0;
    const int64_t first = i[k] < j[k] ? i[k] : j[k];
    for (int32_t side = 0; side < 2; ++side)
    {
      const int64_t f = side == 0 ? first : (first == i[k] ? j[k] : i[k]);
      if (f < n_local)
      {
        const double *e = (f == i[k] ? e_i : e_j) + k * d;
        for (int32_t x = 0; x < d; ++x)
        {
          const double v = e[x] / length[f];
          const int64_t col = f * d + x;
          for (int32_t q = qf_ptr[col]; q < qf_ptr[col + 1]; ++q)
          {
            const int32_t r = qf_rows[q];
            sums[r] += v * qf_vals[q];
            if (mark[r] < 0)
            {
              mark[r] = 1;
              touched[n_touched++] = r;
            }
          }
        }
      }
      n_side[side] = n_touched - (side == 0 ? 0 : n_side[0]);
      sort_small(touched + (side == 0 ? 0 : n_side[0]), n_side[side]);
    }
    /* merge the two sorted runs into the row, dropping exact zeros */
    int32_t *merged = touched + n_touched;
    int32_t a = 0, b = n_side[0], m = 0;
    while (a < n_side[0] || b < n_touched)
      merged[m++] = (b >= n_touched || (a < n_side[0] && touched[a] < touched[b])) ? touched[a++] : touched[b++];
    for (int32_t c = 0; c < m; ++c)
    {
      const int32_t r = merged[c];
      if (sums[r] != 0.0)
      {
        indices[nnz] = r;
        data[nnz] = sums[r];
        ++nnz;
      }
      sums[r] = 0.0;
      mark[r] = -1;
    }
    indptr[k + 1] = (int32_t)nnz;
  }
  return nnz;
}

/* malloc of n items of the given size (at least one byte: NULL means out of memory). */
static void *alloc(int64_t n, size_t size)
{
  return malloc(n > 0 ? (size_t)n * size : 1);
}

/* Numbers the columns of the rows p[0..n) of a CSR pattern (z_ptr, z_idx) by first appearance,
 * from n_rows on: slot[column] (-1 for a column not numbered yet) = its number, rows[number] =
 * the column. Returns the new count. The own rows the pairs' z_p touch, for the kernels below. */
static int64_t number_columns(int64_t n, const int64_t *restrict p, const int32_t *restrict z_ptr,
                              const int32_t *restrict z_idx, int32_t *restrict slot, int32_t *restrict rows,
                              int64_t n_rows)
{
  for (int64_t k = 0; k < n; ++k)
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
      if (slot[z_idx[e]] < 0)
      {
        slot[z_idx[e]] = (int32_t)n_rows;
        rows[n_rows++] = z_idx[e];
      }
  return n_rows;
}

/* y[s] = sum over row rows[s] of the CSR matrix (q_ptr, q_idx, q_val) of its entries times x at
 * their columns, in the order of the entries, plus shift[rows[s]]; with x2 (may be NULL), y2[s]
 * the same sum of x2 without the shift, in the same pass. */
static void rows_apply(int64_t n_rows, const int32_t *restrict rows, const int32_t *restrict q_ptr,
                       const int32_t *restrict q_idx, const double *restrict q_val, const double *restrict x,
                       const double *restrict shift, double *restrict y, const double *restrict x2,
                       double *restrict y2)
{
  for (int64_t s = 0; s < n_rows; ++s)
  {
    double sum = 0.0, sum2 = 0.0;
    for (int32_t e = q_ptr[rows[s]]; e < q_ptr[rows[s] + 1]; ++e)
    {
      sum += q_val[e] * x[q_idx[e]];
      if (x2)
        sum2 += q_val[e] * x2[q_idx[e]];
    }
    y[s] = sum + shift[rows[s]];
    if (x2)
      y2[s] = sum2;
  }
}

/* pair_contact.PairContact.force_integral after its screen, in one call: for the n touching
 * pairs p (facets (i, j), normal, tangents t, reference gap d0, projected simplices XA.. and
 * XB..) along the flight uc + tau vc of the free facet displacements (n_facets x d), 0 <= tau
 * <= dt, the integrals of the contact force corrections (eq. (34), paper §4):
 *   result -= Q^T Z int c dtau            (the rows' term; result: patch values, accumulated),
 *   result += R^T int -mu dc/du_f dtau    (the pairs' term at the facets, n_facet_rows = n_facets
 *                                          d, through the facets' reconstruction R: r_ptr, r_idx,
 *                                          r_val, patch columns; summed as scipy's R.T @ f, then
 *                                          added),
 * with c_p = w_p g_p^-, mu_p = z_p . (a + Z c) and a = Q u + q + tau Q v on the own rows the
 * z_p touch (Z^T: z_ptr, z_idx, z_val, one row per listed pair, columns the own rows; Q: q_ptr,
 * q_idx, q_val, own rows x patch dofs; up, vp: the patch values of u and v).
 *
 * The pairs sharing an own row form connected components (two pairs are linked by a common
 * column of their Z^T rows). Each component's [0, dt] is cut at all its pairs' events
 * (pair_events: gap sign changes and clipped-polygon topology changes), every c_p is a
 * polynomial of degree d on each piece and each force term one of degree 2 d - 1: the n_gauss
 * = d point rule (xi, wq on [0, 1]) integrates them exactly. A pair's w and dw are clipped at
 * the nodes of its own pieces only (overlap_own) and interpolated at its component's nodes
 * (interpolate_own). The sums run in the order of the pairs, of each CSR row's entries and of
 * the nodes (the rows in the order the pairs first touch them).
 *
 * slot: one entry per own row, -1 on entry and left so (the touched rows are numbered through
 * it). Returns the largest number of non-empty pieces of a component, or -1 if memory ran out. */
int64_t dem_pair_force_integral(int64_t n, int32_t d, const int64_t *restrict p, const int64_t *restrict i,
                                const int64_t *restrict j, const double *restrict normal, const double *restrict t,
                                const double *restrict d0, const double *restrict XA, const double *restrict mA,
                                const double *restrict nuA, const double *restrict sizeA, const double *restrict XB,
                                const double *restrict mB, const double *restrict nuB, const double *restrict sizeB,
                                const double *restrict uc, const double *restrict vc, double dt, int32_t n_gauss,
                                const double *restrict xi, const double *restrict wq, const int32_t *restrict z_ptr,
                                const int32_t *restrict z_idx, const double *restrict z_val,
                                const int32_t *restrict q_ptr, const int32_t *restrict q_idx,
                                const double *restrict q_val, const double *restrict q, const double *restrict up,
                                const double *restrict vp, int32_t *restrict slot, int64_t n_facet_rows,
                                const int32_t *restrict r_ptr, const int32_t *restrict r_idx,
                                const double *restrict r_val, int64_t n_patch, double *restrict result)
{
  const int32_t n_tau = 1 + 2 * d * d, n_own = n_tau + 1;
  int64_t bound = 0, n_rows = 0, n_comp = 0, n_times = 0, k_max = 0, pieces = 0, stride = 0;
  for (int64_t k = 0; k < n; ++k)
    bound += z_ptr[p[k] + 1] - z_ptr[p[k]];
  int32_t *rows = alloc(bound, sizeof *rows);
  int64_t *first = alloc(bound, sizeof *first), *parent = alloc(n, sizeof *parent);
  int64_t *label = alloc(n, sizeof *label), *offsets = alloc(n + 1, sizeof *offsets);
  double *a = alloc(2 * bound, sizeof *a), *za = alloc(2 * n, sizeof *za), *tau = alloc(n * n_tau, sizeof *tau);
  double *zc = calloc(bound > 0 ? bound : 1, sizeof *zc);
  int64_t *time_rows = alloc(n * n_tau, sizeof *time_rows), *counts = NULL, *n_pieces = NULL;
  double *times = alloc(n * n_tau, sizeof *times), *points = NULL, *mid = NULL, *length = NULL;
  double *g0 = calloc(n > 0 ? n : 1, sizeof *g0), *rate = calloc(n > 0 ? n : 1, sizeof *rate);
  double *nodes = NULL, *weights = NULL, *g = NULL, *w = NULL, *dw = NULL, *c = NULL, *mu = NULL, *work = NULL;
  double *cache_x = NULL, *cache_basis = NULL;
  double *start_own = alloc(n * n_own, sizeof *start_own), *length_own = alloc(n * n_own, sizeof *length_own);
  double *w_own = alloc(n * n_own * n_gauss, sizeof *w_own), *dw_own = alloc(n * n_own * n_gauss * d, sizeof *dw_own);
  int64_t *entry = NULL;
  double *facet_force = calloc(n_facet_rows > 0 ? n_facet_rows : 1, sizeof *facet_force);
  double *pairs_term = calloc(n_patch > 0 ? n_patch : 1, sizeof *pairs_term);
  int64_t status = -1;
  if (!rows || !first || !parent || !label || !offsets || !a || !za || !tau || !zc || !time_rows ||
      !times || !start_own || !length_own || !w_own || !dw_own || !g0 || !rate || !facet_force || !pairs_term)
    goto done;

  /* the own rows the pairs touch (slot: their numbers, by first appearance) and the components
   * of pairs sharing one (union-find, the smaller index the root; numbered by first appearance) */
  n_rows = number_columns(n, p, z_ptr, z_idx, slot, rows, 0);
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

  /* a = (Q u + q, Q v) on the touched rows, and z_p . a of each pair */
  rows_apply(n_rows, rows, q_ptr, q_idx, q_val, up, q, a, vp, a + n_rows);
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
  pair_events(n, d, p, i, j, normal, t, d0, XA, mA, XB, mB, uc, vc, dt, tau);
  counts = calloc(n_comp > 0 ? n_comp : 1, sizeof *counts);
  n_pieces = calloc(n_comp > 0 ? n_comp : 1, sizeof *n_pieces);
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
  points = alloc(n_comp * (k_max + 2), sizeof *points);
  mid = alloc(n_comp * (k_max + 1), sizeof *mid);
  length = alloc(n_comp * (k_max + 1), sizeof *length);
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
  nodes = alloc(n_nodes, sizeof *nodes);
  weights = alloc(n_nodes, sizeof *weights);
  g = alloc(n_nodes, sizeof *g);
  w = alloc(n_nodes, sizeof *w);
  dw = alloc(n_nodes * d, sizeof *dw);
  c = alloc(n_nodes, sizeof *c);
  mu = alloc(n_nodes, sizeof *mu);
  entry = alloc(n_nodes, sizeof *entry);
  work = calloc(n_rows * stride > 0 ? n_rows * stride : 1, sizeof *work);
  cache_x = alloc(stride, sizeof *cache_x);
  cache_basis = alloc(stride * n_gauss, sizeof *cache_basis);
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
    overlap_own(n, 3, p, i, j, t, uc, vc, n_tau, tau, dt, n_gauss, xi, XA, mA, nuA, sizeA, XB, mB, nuB, sizeB, g0,
                rate, start_own, length_own, w_own, dw_own);
  else
    overlap_own(n, 2, p, i, j, t, uc, vc, n_tau, tau, dt, n_gauss, xi, XA, mA, nuA, sizeA, XB, mB, nuB, sizeB, g0,
                rate, start_own, length_own, w_own, dw_own);
  for (int64_t x = 0; x < stride; ++x)
    cache_x[x] = NAN;
  interpolate_own(n, n_own, offsets, n_gauss, d, start_own, length_own, nodes, xi, w_own, dw_own, w, dw, cache_x,
                  cache_basis);
  for (int64_t e = 0; e < n_nodes; ++e)
    c[e] = w[e] * (g[e] < 0.0 ? g[e] : 0.0);

  /* the rows' term: result -= Q^T (Z int c dtau), over the touched rows */
  for (int64_t k = 0; k < n; ++k)
  {
    double integral = 0.0;
    for (int64_t e = offsets[k]; e < offsets[k + 1]; ++e)
      integral = e == offsets[k] ? weights[e] * c[e] : integral + weights[e] * c[e];
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
      zc[slot[z_idx[e]]] += z_val[e] * integral;
  }
  for (int64_t s = 0; s < n_rows; ++s)
    for (int32_t e = q_ptr[rows[s]]; e < q_ptr[rows[s] + 1]; ++e)
      result[q_idx[e]] -= q_val[e] * zc[s];

  /* the pairs' term: mu = z_p . a(tau) + z_p . (Z c)(tau) at the nodes (the pairs of a component
   * share their nodes), where g < 0, times the weights; then the facet forces */
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
      const double value = (za[2 * k] + nodes[node] * za[2 * k + 1]) + mu[node];
      mu[node] = value * weights[node];
    }
  }
  dem_pair_facet_forces(n_nodes, d, entry, i, j, normal, mu, g, w, dw, facet_force);
  for (int64_t r = 0; r < n_facet_rows; ++r)
    for (int32_t e = r_ptr[r]; e < r_ptr[r + 1]; ++e)
      pairs_term[r_idx[e]] += r_val[e] * facet_force[r];
  for (int64_t k = 0; k < n_patch; ++k)
    result[k] += pairs_term[k];
  status = pieces;

done:
  for (int64_t s = 0; s < n_rows; ++s)
    slot[rows[s]] = -1;
  free(rows), free(first), free(parent), free(label), free(offsets), free(a), free(za), free(tau);
  free(zc), free(time_rows), free(counts), free(n_pieces), free(times), free(points), free(mid), free(length);
  free(nodes), free(weights), free(g), free(w), free(dw), free(c), free(mu), free(entry), free(work);
  free(cache_x), free(cache_basis);
  free(start_own), free(length_own), free(w_own), free(dw_own), free(g0), free(rate), free(facet_force);
  free(pairs_term);
  return status;
}

/* The contact state of dem_pair_end_state at one displacement: the listed pairs
 * (facets (i, j), normal, tangents t, reference gap d0, projected simplices XA.., XB..) whose
 * c_p = w_p g_p^- may not vanish at the free facet displacements uc (n_facets x d), in order
 * (closed: flight_screen's test without a flight, separations sep), their gap g, overlap w, dw/du_j (d per pair; see
 * dem_overlap), c = w g^-, and, over the own rows their z_p touch (Z^T: z_ptr, z_idx, z_val),
 * a = Q u + q (Q: q_ptr, q_idx, q_val on the patch values up), delta = Z c and mu_p = z_p . (a +
 * delta); sums[0], sums[1] += the sums of a delta + delta^2 / 2 over the touched elastic rows
 * (elastic[row] != 0) and the others, in the order the pairs first touch them (the energy change),
 * sums[2] += the sum of mu_p w_p over the closed pairs (-contact_force_part). closed, g, w, c, mu: n_pairs,
 * dw: n_pairs d (the first n_closed written); slot as in dem_pair_force_integral. candidates
 * (sorted, n_candidates; NULL: all pairs): the only pairs that may be closed (pair_contact._At:
 * bit 1 of the last flight's screen). Returns n_closed, or -1 if memory ran out. */
static int64_t pair_state(int64_t n_pairs, int64_t n_candidates, const int64_t *restrict candidates, int32_t d,
                          const int64_t *restrict i, const int64_t *restrict j,
                          const double *restrict normal, const double *restrict t, const double *restrict d0,
                          const double *restrict sep, const double *restrict XA, const double *restrict mA, const double *restrict nuA,
                          const double *restrict sizeA, const double *restrict XB, const double *restrict mB,
                          const double *restrict nuB, const double *restrict sizeB, const double *restrict uc,
                          const int32_t *restrict z_ptr, const int32_t *restrict z_idx, const double *restrict z_val,
                          const int32_t *restrict q_ptr, const int32_t *restrict q_idx, const double *restrict q_val,
                          const double *restrict q, const double *restrict up, const int8_t *restrict elastic,
                          int32_t *restrict slot, int64_t *restrict closed, double *restrict g, double *restrict w,
                          double *restrict dw, double *restrict c, double *restrict mu, double *restrict sums)
{
  int64_t n = 0, bound = 0, n_rows = 0, status = -1;
  int8_t *closed_mark = alloc(n_pairs, sizeof *closed_mark);
  int32_t *rows = NULL;
  double *a = NULL, *delta = NULL;
  if (!closed_mark)
    goto done;
  screen(candidates ? n_candidates : n_pairs, d, candidates, i, j, normal, t, d0, sep, mA, mB, uc, NULL, 0.0, 0.0,
         closed_mark);
  const int64_t n_screened = candidates ? n_candidates : n_pairs;
  for (int64_t k = 0; k < n_screened; ++k)
  {
    const int64_t p = candidates ? candidates[k] : k;
    if (closed_mark[p])
    {
      closed[n++] = p;
      bound += z_ptr[p + 1] - z_ptr[p];
    }
  }
  rows = alloc(bound, sizeof *rows);
  a = alloc(bound, sizeof *a);
  delta = calloc(bound > 0 ? bound : 1, sizeof *delta);
  if (!rows || !a || !delta)
    goto done;
  for (int64_t k = 0; k < n; ++k)
  {
    const int64_t p = closed[k];
    double du[3], gap = 0.0;
    for (int32_t x = 0; x < d; ++x)
    {
      du[x] = uc[j[p] * d + x] - uc[i[p] * d + x];
      gap += du[x] * normal[p * d + x];
    }
    g[k] = d0[p] + gap;
    if (d == 3) /* a constant d: the clipping unrolled */
      pair_overlap(3, p, t, du, XA, mA, nuA, sizeA, XB, mB, nuB, sizeB, w + k, dw + k * d);
    else
      pair_overlap(2, p, t, du, XA, mA, nuA, sizeA, XB, mB, nuB, sizeB, w + k, dw + k * d);
    c[k] = w[k] * (g[k] < 0.0 ? g[k] : 0.0);
  }
  /* a and delta = Z c on the touched rows; mu; the energy change */
  n_rows = number_columns(n, closed, z_ptr, z_idx, slot, rows, 0);
  rows_apply(n_rows, rows, q_ptr, q_idx, q_val, up, q, a, NULL, NULL);
  for (int64_t k = 0; k < n; ++k)
    for (int32_t e = z_ptr[closed[k]]; e < z_ptr[closed[k] + 1]; ++e)
      delta[slot[z_idx[e]]] += z_val[e] * c[k];
  for (int64_t k = 0; k < n; ++k)
  {
    double y = 0.0;
    for (int32_t e = z_ptr[closed[k]]; e < z_ptr[closed[k] + 1]; ++e)
      y += z_val[e] * (a[slot[z_idx[e]]] + delta[slot[z_idx[e]]]);
    mu[k] = y;
    sums[2] += y * w[k];
  }
  for (int64_t s = 0; s < n_rows; ++s)
    sums[elastic[rows[s]] ? 0 : 1] += a[s] * delta[s] + 0.5 * delta[s] * delta[s];
  status = n;

done:
  for (int64_t s = 0; s < n_rows; ++s)
    slot[rows[s]] = -1;
  free(closed_mark), free(rows), free(a), free(delta);
  return status;
}

/* pair_contact._At in one call: the free facet displacements uc = R up + lift (dem_csr_apply; R
 * n_rows = n_facets d rows); state_motion (ratio[0], ratio[1]): if the list is stale at uc
 * (ratio[0] > 1) returns -2 and nothing more; else the contact state (pair_state, its arguments
 * after uc), screening only the candidates (n_candidates, sorted) if end != NULL and ratio[1] <=
 * slack2 (*used = 1; none closed if there are none), every listed pair otherwise (*used = 0).
 * Returns n_closed, -2 (stale) or -1 (out of memory). */
int64_t dem_pair_end_state(int64_t n_rows, const int32_t *restrict r_ptr, const int32_t *restrict r_idx,
                           const double *restrict r_val, const double *restrict lift, double *restrict uc,
                           const double *restrict reference, const double *restrict half_skin2,
                           const double *restrict end, const double *restrict vc, double tau, double slack2,
                           int64_t n_candidates, const int64_t *restrict candidates, double *restrict ratio,
                           int32_t *restrict used, int64_t n_pairs, int32_t d, const int64_t *restrict i,
                           const int64_t *restrict j, const double *restrict normal, const double *restrict t,
                           const double *restrict d0, const double *restrict sep, const double *restrict XA,
                           const double *restrict mA, const double *restrict nuA, const double *restrict sizeA,
                           const double *restrict XB, const double *restrict mB, const double *restrict nuB,
                           const double *restrict sizeB, const int32_t *restrict z_ptr,
                           const int32_t *restrict z_idx, const double *restrict z_val,
                           const int32_t *restrict q_ptr, const int32_t *restrict q_idx,
                           const double *restrict q_val, const double *restrict q, const double *restrict up,
                           const int8_t *restrict elastic, int32_t *restrict slot, int64_t *restrict closed,
                           double *restrict g, double *restrict w, double *restrict dw, double *restrict c,
                           double *restrict mu, double *restrict sums)
{
  dem_csr_apply(n_rows, r_ptr, r_idx, r_val, up, lift, uc);
  state_motion(n_rows / d, d, uc, reference, half_skin2, end, vc, tau, ratio);
  *used = end && ratio[1] <= slack2;
  if (ratio[0] > 1.0)
    return -2;
  if (*used && n_candidates == 0)
    return 0;
  return pair_state(n_pairs, *used ? n_candidates : 0, *used ? candidates : NULL, d, i, j, normal, t, d0, sep, XA, mA,
                    nuA, sizeA, XB, mB, nuB, sizeB, uc, z_ptr, z_idx, z_val, q_ptr, q_idx, q_val, q, up, elastic, slot,
                    closed, g, w, dw, c, mu, sums);
}

/* The forces between bodies of pair_contact.PairContact.pair_forces: for the entries k (pairs
 * p[k] of facets (i, j), normals) with c[k] != 0 whose facets lie on different bodies bi =
 * body[i], bj = body[j], the force mu_k (w_k n + g_k dw_k) on bi (d components; dw = dw/du_j),
 * added to out[index[bi n_bodies + bj]] with the sign of the force on the lower-numbered body,
 * in the order of the entries (out: body pairs x d, accumulated into). Returns the number of
 * such entries whose body pair has no index (< 0: none is added; the caller raises). */
int64_t dem_pair_body_forces(int64_t n, int32_t d, const int64_t *restrict p, const int64_t *restrict i,
                             const int64_t *restrict j, const double *restrict normal, const int64_t *restrict body,
                             int64_t n_bodies, const int64_t *restrict index, const double *restrict mu,
                             const double *restrict g, const double *restrict w, const double *restrict dw,
                             const double *restrict c, double *restrict out)
{
  int64_t missing = 0;
  for (int64_t k = 0; k < n; ++k)
  {
    const int64_t q = p[k], bi = body[i[q]], bj = body[j[q]];
    if (c[k] == 0.0 || bi == bj)
      continue;
    const int64_t at = index[bi * n_bodies + bj];
    if (at < 0)
    {
      ++missing;
      continue;
    }
    const double sign = bi < bj ? 1.0 : -1.0;
    for (int32_t x = 0; x < d; ++x)
      out[at * d + x] += sign * (mu[k] * (w[k] * normal[q * d + x] + g[k] * dw[k * d + x]));
  }
  return missing;
}

/* pair_contact.PairContact.penetration after the scatter of the facet corrections: for the
 * entries k (pairs p[k] of facets (i, j), normals) with w[k] > 0, the reconstructed gap
 * (x_j + u_j - x_i - u_i) . n (centre: the facets' barycentres x, uf: their reconstructions u,
 * n_facets x d), and for each of the first n_own facets touched the overlap-weighted mean of its
 * pairs' gaps; returns the largest of their negatives, or 0. weight and mean: n_facets, zero
 * on entry (work). */
double dem_pair_penetration(int64_t n, int32_t d, const int64_t *restrict p, const int64_t *restrict i,
                            const int64_t *restrict j, const double *restrict normal, const double *restrict centre,
                            const double *restrict uf, const double *restrict w, int64_t n_own,
                            double *restrict weight, double *restrict mean)
{
  for (int64_t k = 0; k < n; ++k)
  {
    if (!(w[k] > 0))
      continue;
    const int64_t q = p[k];
    double gap = 0.0;
    for (int32_t x = 0; x < d; ++x)
      gap += ((centre[j[q] * d + x] + uf[j[q] * d + x]) - centre[i[q] * d + x] - uf[i[q] * d + x]) *
             normal[q * d + x];
    weight[i[q]] += w[k];
    weight[j[q]] += w[k];
    mean[i[q]] += w[k] * gap;
    mean[j[q]] += w[k] * gap;
  }
  double worst = 0.0;
  for (int64_t f = 0; f < n_own; ++f)
    if (weight[f] > 0 && -mean[f] / weight[f] > worst)
      worst = -mean[f] / weight[f];
  return worst;
}
