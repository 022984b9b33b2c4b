/* Energy rows: K = Q^T Q applied in one pass over Q (factored.py), the MEMM update
 * (memm_state.py), the row sums of |Q^T Q| of the stability bound (stability.py) and the pairs'
 * rows Z^T = E^T QF^T of a pair list build (pair_contact.py). Q is held as a CSR matrix of its
 * local rows with local column numbers (owned dofs first, then ghosts). */
#include "internal.h"

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
void dem_gram_apply(const dem_csr *Q, int64_t n_elastic, const double *restrict x,
                    const int32_t *restrict shift_index, const double *restrict shift, double *restrict y,
                    double alpha, double scale, double *restrict z, double *restrict sums)
{
  const int64_t n_rows = Q->n_rows;
  const int32_t *restrict rowptr = Q->indptr, *restrict cols = Q->indices;
  const double *restrict vals = Q->data;
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

/* One MEMM step on the cells (a cell's bs = d components share its mass m_b):
 *   impulse_i = load_i - c (z_old_i + z_new_i)          (load may be NULL: zero)
 *   v_new_i   = v_prev_i + 2 minv_b impulse_i             (35b)
 *   u_i      += dt v_next_i                               (35a), if advance
 *   sums[0]  += 1/2 m_b ((v_next_i + v_new_i) / 2)^2      kinetic energy of vbar
 *   sums[1]  += 1/2 m_b v_next_i v_new_i                  pseudo-kinetic energy
 *   sums[2]  += f_i u_i                                   (f may be NULL)
 *   momentum[body_b bs + j] += m_b v_new_i                (body may be NULL)
 *   total[j] += m_b (v_next_i + v_new_i) / 2              the momentum of vbar (bs <= 3)
 * then v_prev_i <- v_new_i and z_old_i <- 0 (ready to accumulate the next Q^T y). */
void dem_memm_update(const dem_memm_cells *cells, double *restrict z_old, const double *restrict z_new,
                     const double *restrict load, double *restrict u, const double *restrict v_next,
                     double *restrict v_prev, int32_t advance)
{
  const int64_t n_blocks = cells->n_blocks;
  const int32_t bs = cells->bs;
  const double dt = cells->dt, c = cells->c;
  const double *restrict mass = cells->mass, *restrict minv = cells->minv, *restrict f = cells->f;
  const int32_t *restrict body = cells->body;
  double *restrict momentum = cells->momentum;
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
  cells->sums[0] += 0.125 * kinetic;
  cells->sums[1] += 0.5 * pseudo;
  cells->sums[2] += external;
  for (int32_t j = 0; j < bs; ++j)
    cells->total[j] += 0.5 * p[j];
}

/* The smallest and largest column below n_cols of each row of Q: lo[i] = n_cols and hi[i] = -1
 * for a row without such a column. */
void dem_row_column_range(const dem_csr *Q, int32_t n_cols, int32_t *restrict lo, int32_t *restrict hi)
{
  const int32_t *restrict rowptr = Q->indptr, *restrict cols = Q->indices;
  for (int64_t i = 0; i < Q->n_rows; ++i)
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

/* The pattern of the columns first <= j < first + n_cols of Q, scanning the rows of the n_ranges
 * increasing ranges [ranges[2k], ranges[2k + 1]) (they must hold every row with an entry in
 * those columns): the rows with an entry in column j, increasing, are rows[ptr[j - first] ..
 * ptr[j - first + 1]). With rows NULL only ptr (n_cols + 1 entries) is computed; then, with
 * rows of ptr[n_cols] entries, the rows (ptr is used as the cursor and restored). A transpose
 * without values: 4 bytes per entry. */
void dem_transpose_pattern(const dem_csr *Q, const int64_t *restrict ranges, int32_t n_ranges, int32_t first,
                           int32_t n_cols, int32_t *restrict ptr, int32_t *restrict rows)
{
  const int32_t *restrict rowptr = Q->indptr, *restrict cols = Q->indices;
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

/* Q_ki: the entry of column i in row k of a set (each column appears once in a row). */
static inline double row_entry(const dem_row_set *set, int32_t k, int64_t i)
{
  for (int32_t q = set->rows.indptr[k]; q < set->rows.indptr[k + 1]; ++q)
    if (set->rows.indices[q] == i)
      return set->rows.data[q];
  return 0.0;
}

/* Row sums of |Q^T Q| weighted by x, for the stable time step bound:
 *   r_i = sum_j |(Q^T Q)_ij| x_j   for the n_out owned dofs i = first, first + 1, ...
 * (x NULL: r_i = (Q^T Q)_ii = sum_k Q_ki^2; r is indexed from first). The rows of Q through dof i
 * come from two sets: this process's rows (own), listed for dof i by own->qt_ptr at i - first
 * (``dem_transpose_pattern`` of the same columns), and rows of other processes (other, listed at
 * i); both are visited merged in increasing key, a numbering of the rows that does not depend
 * on the partition, and each row's columns in the order of the global dof numbering: the same
 * sums, to the bit, on any number of processes. Column numbers index x and acc (zeros of the
 * length of x, left zero); owned dof i is column i in both sets, and Q_ki is read from row k (no
 * transposed values are stored). Row i of Q^T Q is accumulated in acc, then harvested: the
 * first visit of a column j adds |acc_j| x_j and zeroes acc_j, so later visits add 0. */
void dem_gram_abs_rowsums(int64_t first, int64_t n_out, const dem_row_set *own, const dem_row_set *other,
                          const double *restrict x, double *restrict r, double *restrict acc)
{
  const dem_row_set *sets[2] = {own, other};
  const int32_t *restrict qt_ptr = own->qt_ptr, *restrict qt2_ptr = other->qt_ptr;
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
        else if (p[1] < end[1] && other->key[other->qt_rows[p[1]]] < own->key[own->qt_rows[p[0]]])
          which = 1;
        const dem_row_set *set = sets[which];
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
          for (int32_t q = set->rows.indptr[k]; q < set->rows.indptr[k + 1]; ++q)
            acc[set->rows.indices[q]] += a * set->rows.data[q];
        }
        else
          for (int32_t q = set->rows.indptr[k]; q < set->rows.indptr[k + 1]; ++q)
          {
            const int32_t j = set->rows.indices[q];
            s += fabs(acc[j]) * x[j];
            acc[j] = 0.0;
          }
      }
    }
    r[i] = s;
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

/* Z^T of a pair list build (pair_contact.PairContact._list): row k, for the pair (i[k], j[k]),
 * is sum over its local facets f (f < n_local = QF's columns / d; in increasing f) and their
 * components x of (e_f[x] / |f|) times column f d + x of QF, the columns' entries accumulated in
 * their order; exact zeros are dropped and each row's columns sorted: the bits and the pattern
 * of scipy's (E^T @ QF^T).sort_indices(), E the facet dofs' directions, without forming E^T.
 * indices and data must hold the sum over the rows of their columns' entries. Returns the
 * number of entries. */
int64_t dem_pair_rows(const dem_facet_rows *QF, int64_t n_pairs, int32_t d, const int64_t *restrict i,
                      const int64_t *restrict j, const double *restrict e_i, const double *restrict e_j,
                      const double *restrict length, int32_t *restrict indptr, int32_t *restrict indices,
                      double *restrict data)
{
  const int64_t n_local = QF->columns.n_rows / d;
  const int32_t *restrict qf_ptr = QF->columns.indptr, *restrict qf_rows = QF->columns.indices;
  const double *restrict qf_vals = QF->columns.data;
  double *restrict sums = QF->sums;
  int32_t *restrict mark = QF->mark, *restrict touched = QF->touched;
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
