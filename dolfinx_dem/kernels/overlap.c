/* Overlap geometry of the pairs of candidate facets (pair_contact.py): the facets projected on
 * their pair's plane, the simplices made of them, the separations the screen starts from, and
 * the overlap w = |A cap (B + s)| with its gradient (the clipping: internal.h, overlap_one). */
#include "internal.h"

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

/* overlap.Simplices.of: for n (d-1)-simplices with vertices X (n x d x (d - 1)), face k's
 * outward normal m_k (unnormalised: in 3D the edge X_k X_k+1 turned by the orientation's sign, in
 * 2D X_k - X_other), nu_k = m_k / |m_k| (0 if m_k = 0) and size (the edge's length in 3D, 1 in
 * 2D); every norm sqrt(sum of squares) in order, as numpy's. */
void dem_simplices_of(int64_t n, int32_t d, const double *restrict X, double *restrict m, double *restrict nu,
                      double *restrict size)
{
  for (int64_t p = 0; p < n; ++p)
  {
    const double *x = X + p * d * (d - 1);
    double *m_ = m + p * d * (d - 1), *nu_ = nu + p * d * (d - 1);
    if (d == 2)
    {
      for (int32_t k = 0; k < 2; ++k)
      {
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
      const double e0 = x[2 * next] - x[2 * k], e1 = x[2 * next + 1] - x[2 * k + 1];
      m_[2 * k] = sign * e1, m_[2 * k + 1] = sign * -e0;
      size[p * 3 + k] = sqrt(e0 * e0 + e1 * e1);
      const double norm = sqrt(m_[2 * k] * m_[2 * k] + m_[2 * k + 1] * m_[2 * k + 1]);
      nu_[2 * k] = norm > 0 ? m_[2 * k] / norm : 0.0;
      nu_[2 * k + 1] = norm > 0 ? m_[2 * k + 1] / norm : 0.0;
    }
  }
}

/* The separations of the flight's screen for n pairs of simplices A, B (d vertices of dim = d - 1
 * components each, face k from vertex k, outward face normals m unnormalised): out (n x 2 d)
 * = for each face k of A, then of B, min over the other's vertices Y_b of m_k . (Y_b - X_k),
 * less margin |m_k| times the pair's size (the largest |coordinate| of its vertices). */
void dem_pair_separations(int64_t n, int32_t d, const dem_simplices *A, const dem_simplices *B, double margin,
                          double *restrict out)
{
  const int32_t dim = d - 1, stride = d * dim;
  const double *restrict XA = A->X, *restrict mA = A->m, *restrict XB = B->X, *restrict mB = B->m;
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

/* w = |A_q cap (B_q + s_i)| and dw/ds (see pair_contact._overlap) for n offsets s_i (dim
 * components, dim = 1 or 2) of the simplex pairs q = p[i] (nv = dim + 1 vertices each). w (n) and
 * dw (n dim) are overwritten; both are 0 where the bounding boxes of A_q and B_q + s_i are apart
 * (no clipping). */
void dem_overlap(int64_t n, int32_t dim, const int64_t *restrict p, const dem_simplices *A, const dem_simplices *B,
                 const double *restrict s, double *restrict w, double *restrict dw)
{
  for (int64_t i = 0; i < n; ++i)
    overlap_one(dim, p[i], A, B, s + i * dim, w + i, dw + i * dim);
}
