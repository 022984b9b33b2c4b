/* Helpers shared by several .c files of the kernels (static inline: each file gets its own
 * copy, nothing is exported). Not read by the cffi build. */
#ifndef DEM_KERNELS_INTERNAL_H
#define DEM_KERNELS_INTERNAL_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "dem_kernels.h"

#define DEM_INLINE static inline __attribute__((always_inline))

/* ---- overlap of projected simplices (overlap.c, flight.c, integral.c) ------------------- */

/* Clipping of pair_contact._overlap, for one face f of a simplex F (nv vertices X of dim
 * components; face f runs from X[f] to X[next[f]]) against the simplex O (vertices Y, outward
 * face normals m): the part [lower, lower + length] of the face inside O (the half-planes
 * m_k . (x - Y_k) <= 0, Liang-Barsky). With ties, a face lying on a face of O with the same
 * outward normal (mF: its own normal) is out. The same operations in the same order as numpy's. */
DEM_INLINE void clip_face(int32_t nv, int32_t dim, const int32_t *next, const double *X, int32_t f,
                          const double *mF, const double *Y, const double *m, int32_t ties, double *lower,
                          double *length)
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
DEM_INLINE void box(int32_t nv, int32_t dim, const double *X, double *lo, double *hi)
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
DEM_INLINE int32_t boxes_apart(int32_t nv, int32_t dim, const double *X, const double *Y)
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
DEM_INLINE void overlap_one(int32_t dim, int64_t q, const dem_simplices *A, const dem_simplices *B,
                            const double *s, double *w, double *dw)
{
  const int32_t nv = dim + 1, stride = nv * dim;
  const int32_t next[3] = {dim == 1 ? 0 : 1, dim == 1 ? 1 : 2, 0}; /* a face's end vertex */
  const double *X = A->X + q * stride, *m = A->m + q * stride, *nu = A->nu + q * stride;
  const double *mb = B->m + q * stride, *nub = B->nu + q * stride;
  double Y[6];
  for (int32_t k = 0; k < nv; ++k)
    for (int32_t c = 0; c < dim; ++c)
      Y[k * dim + c] = B->X[q * stride + k * dim + c] + s[c];
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
    const double *size = side ? B->size + q * nv : A->size + q * nv;
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

/* w and dw/du_j = t^T dw/ds (d components) of the listed pair q at the relative displacement
 * du = u_j - u_i (d components) of its facets: overlap_one of its projections at the tangential
 * offset s = t du (t: the pair's d - 1 tangent rows of d). */
DEM_INLINE void pair_overlap(int32_t d, int64_t q, const dem_pairs *pairs, const double *du, double *w, double *dw)
{
  const int32_t dim = d - 1;
  const double *t = pairs->t;
  double s[2], dws[2];
  for (int32_t r = 0; r < dim; ++r)
  {
    s[r] = 0.0;
    for (int32_t c = 0; c < d; ++c)
      s[r] += t[(q * dim + r) * d + c] * du[c];
  }
  overlap_one(dim, q, &pairs->si, &pairs->sj, s, w, dws);
  for (int32_t c = 0; c < d; ++c)
  {
    dw[c] = 0.0;
    for (int32_t r = 0; r < dim; ++r)
      dw[c] += dws[r] * t[(q * dim + r) * d + c];
  }
}

/* ---- the own rows the pairs touch (flight.c, integral.c) -------------------------------- */

/* Numbers the columns of the rows p[0..n) of a CSR pattern z by first appearance, from n_rows
 * on: slot[column] (-1 for a column not numbered yet) = its number, rows[number] = the column.
 * Returns the new count. The own rows the pairs' z_p touch. */
static inline int64_t number_columns(int64_t n, const int64_t *restrict p, const dem_csr *z,
                                     int32_t *restrict slot, int32_t *restrict rows, int64_t n_rows)
{
  const int32_t *restrict z_ptr = z->indptr, *restrict z_idx = z->indices;
  for (int64_t k = 0; k < n; ++k)
    for (int32_t e = z_ptr[p[k]]; e < z_ptr[p[k] + 1]; ++e)
      if (slot[z_idx[e]] < 0)
      {
        slot[z_idx[e]] = (int32_t)n_rows;
        rows[n_rows++] = z_idx[e];
      }
  return n_rows;
}

/* y[s] = sum over row rows[s] of Q of its entries times x at their columns, in the order of the
 * entries, plus shift[rows[s]]; with x2 (may be NULL), y2[s] the same sum of x2 without the
 * shift, in the same pass. */
static inline void rows_apply(int64_t n_rows, const int32_t *restrict rows, const dem_csr *Q,
                              const double *restrict x, const double *restrict shift, double *restrict y,
                              const double *restrict x2, double *restrict y2)
{
  const int32_t *restrict q_ptr = Q->indptr, *restrict q_idx = Q->indices;
  const double *restrict q_val = Q->data;
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

/* ---- work memory (dem_arena) ------------------------------------------------------------ */

/* Frees the blocks taken from the heap while the arena's block was full. */
static inline void arena_free_spill(dem_arena *a)
{
  while (a->spill)
  {
    void *next = *(void **)a->spill;
    free(a->spill);
    a->spill = next;
  }
}

/* A call's start: the memory its predecessor spilled is freed, and the block grown to what the
 * predecessor asked for in all (the largest call so far), so that calls of the same size take
 * no memory from the heap. */
static inline void arena_start(dem_arena *a)
{
  arena_free_spill(a);
  if (a->wanted > a->size)
  {
    free(a->block);
    a->block = malloc(a->wanted);
    a->size = a->block ? a->wanted : 0;
  }
  a->used = a->wanted = 0;
}

/* n items of the given size from the block (16-byte aligned), or, if the block is full, from
 * the heap (freed at the next start); NULL if memory ran out. */
static inline void *arena_take(dem_arena *a, int64_t n, size_t size)
{
  const size_t bytes = ((n > 0 ? (size_t)n * size : 1) + 15) & ~(size_t)15;
  a->wanted += bytes;
  if (a->used + bytes <= a->size)
  {
    void *p = (char *)a->block + a->used;
    a->used += bytes;
    return p;
  }
  void **spilled = malloc(16 + bytes);
  if (!spilled)
    return NULL;
  *spilled = a->spill;
  a->spill = spilled;
  return (char *)spilled + 16;
}

/* arena_take of n zeros. */
static inline void *arena_zeros(dem_arena *a, int64_t n, size_t size)
{
  void *p = arena_take(a, n, size);
  if (p)
    memset(p, 0, n > 0 ? (size_t)n * size : 0);
  return p;
}

#endif
