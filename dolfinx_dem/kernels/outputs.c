/* Outputs of the contact between bodies at a contact state (pair_contact.PairContact): the
 * facet corrections of eq. (31), the forces between bodies and the interpenetration left by the
 * reconstructions. */
#include "internal.h"

/* A facet whose touching partners cover at least this fraction of it is covered: no hole test. */
#define DEM_COVERED (1.0 - 1e-9)

/* The facet corrections of pair_contact.PairContact.facet_corrections (eq. (31)): for the closed
 * pairs p of the state (facets (i, j), c_p = w g^-), out[f] = sum over the pairs with i = f of
 * (c_p / |f|) e_i plus sum over those with j = f of (c_p / |f|) e_j, each sum in the order of
 * the pairs and the two added last (the bits of two bincounts). length: the known facets'
 * measures |f|; out and work: n_facets x d, overwritten. */
void dem_pair_facet_corrections(const dem_pairs *pairs, const dem_pair_state *state, const double *restrict length,
                                double *restrict work, double *restrict out)
{
  const int32_t d = pairs->d;
  memset(out, 0, (size_t)(pairs->n_facets * d) * sizeof *out);
  memset(work, 0, (size_t)(pairs->n_facets * d) * sizeof *work);
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j, *restrict p = state->closed;
  const double *restrict e_i = pairs->e_i, *restrict e_j = pairs->e_j, *restrict c = state->c;
  for (int64_t k = 0; k < state->n; ++k)
  {
    const int64_t q = p[k];
    const double a = c[k] / length[i[q]], b = c[k] / length[j[q]];
    for (int32_t x = 0; x < d; ++x)
    {
      out[i[q] * d + x] += a * e_i[q * d + x];
      work[j[q] * d + x] += b * e_j[q * d + x];
    }
  }
  for (int64_t f = 0; f < pairs->n_facets * d; ++f)
    out[f] += work[f];
}

/* The forces between bodies of pair_contact.PairContact.pair_forces: for the closed pairs p of
 * the state (facets (i, j), normals) with c_p != 0 whose facets lie on different bodies bi =
 * body[i], bj = body[j], the force mu_p (w_p n + g_p dw_p) on bi (d components; dw = dw/du_j),
 * added to out[index[bi n_bodies + bj]] with the sign of the force on the lower-numbered body,
 * in the order of the pairs (out: body pairs x d, accumulated into). Returns the number of
 * such pairs whose body pair has no index (< 0: none is added; the caller raises). */
int64_t dem_pair_body_forces(const dem_pairs *pairs, const dem_pair_state *state, const int64_t *restrict body,
                             int64_t n_bodies, const int64_t *restrict index, double *restrict out)
{
  const int32_t d = pairs->d;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j, *restrict p = state->closed;
  const double *restrict normal = pairs->normal, *restrict mu = state->mu, *restrict g = state->g;
  const double *restrict w = state->w, *restrict dw = state->dw, *restrict c = state->c;
  int64_t missing = 0;
  for (int64_t k = 0; k < state->n; ++k)
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

/* The hole depths of dem_pair_penetration's facets f < n_own not fully covered (cover[f] < 1 -
 * 1e-9; nearest, depth: INFINITY on entry), through their listed partners o, the pairs taken in
 * order, facet i then facet j of each. Pass 0: the nearest partner (squared distances: sqrt is
 * monotone, so the nearest distance is the same) and the depth behind it, which is one of those
 * the least is taken over (the nearest lies around itself): where it is not positive the facet's
 * hole depth is 0 whatever the others, and pass 1 skips it; pass 1: the least depth behind the
 * partners around the nearest and the largest reach among them and f (around: reach[f] on entry). */
DEM_INLINE void behind_partners(const int32_t d, const dem_pairs *pairs, const double *restrict centre,
                                const double *restrict uf, const double *restrict facet_normal,
                                const double *restrict reach, int64_t n_own, const double *restrict cover,
                                double *restrict nearest, double *restrict depth, double *restrict around)
{
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j;
  for (int32_t pass = 0; pass < 2; ++pass)
  {
    for (int64_t q = 0; q < pairs->n; ++q)
      for (int32_t side = 0; side < 2; ++side)
      {
        const int64_t f = side == 0 ? i[q] : j[q], o = side == 0 ? j[q] : i[q];
        if (f >= n_own || cover[f] >= DEM_COVERED || (pass == 1 && !(depth[f] > 0)))
          continue;
        double r2 = 0.0, behind = 0.0;
        for (int32_t x = 0; x < d; ++x)
        {
          const double r = (centre[f * d + x] + uf[f * d + x]) - (centre[o * d + x] + uf[o * d + x]);
          r2 += r * r;
          behind -= r * facet_normal[o * d + x];
        }
        if (pass == 0 && r2 < nearest[f])
        {
          nearest[f] = r2;
          depth[f] = behind;
        }
        else if (pass == 1 && sqrt(r2) <= nearest[f] + 2 * (reach[f] + reach[o]))
        {
          if (behind < depth[f])
            depth[f] = behind;
          if (reach[o] > around[f])
            around[f] = reach[o];
        }
      }
    if (pass == 0)
      for (int64_t f = 0; f < n_own; ++f)
        nearest[f] = sqrt(nearest[f]);
  }
}

/* pair_outputs.PairOutputs.penetration after the scatter of the facet corrections: the depth of
 * each of the first n_own known facets inside the other body (depth, n_own), from their
 * reconstructed barycentres y = x + u (centre: x, uf: u, n_facets x d; facet_normal: the outward
 * normals, n_facets x d; length: the measures |f|, n_facets). Each part of a facet's area carries
 * the depth of what lies over it, and the facet's depth is their area-weighted mean: depth_f =
 * kappa_f max(m_f, 0) + (1 - kappa_f) max(h_f, 0) (the larger of the two parts alone would halve
 * the depth of a half-covered facet sunk as deep under its partner as under the hole).
 * - Its touching partners, the closed pairs p of the state (g < 0) with w_p > 0: m_f is the
 *   overlap-weighted mean over them of the reconstructed gap (y_j - y_i) . n_p, negated, and the
 *   coverage kappa_f = min(1, sum_p w_p / (|f| |n_f . n_p|)), the fraction of f they cover (w_p is
 *   the overlap of the projections on the plane normal to n_p, where f's measure is |f| |n_f .
 *   n_p|), taken as 1 from 1 - 1e-9 (fully covered).
 * - A facet not fully covered (kappa_f < 1; 0 without touching partners): h_f, the least of its
 *   depths -(y_f - y_o) . n_o behind the planes of its listed partners o around the nearest one
 *   (those within the nearest's distance plus twice their two reaches; reach: the largest
 *   distance from each barycentre to its vertices, n_facets): behind all of them, f lies in a
 *   hole of the other body's mosaic; beside a convex body, in front of one. A fully covered
 *   facet's depth is max(m_f, 0), one without touching partners max(h_f, 0).
 * Each part is compared with the largest reach of f and of the partners it reads (its touching
 * partners, those around the nearest): ratio_f = (kappa_f max(m_f, 0) / s_touching + (1 -
 * kappa_f) max(h_f, 0) / s_around) / 2, so that a sliver of hole does not compare the whole depth
 * with the coarse facets around it. scale (n_own): depth_f / (2 ratio_f), the size its depth is
 * compared with (the reach of f where its depth is 0). work: 3 n_facets + 2 n_own, overwritten: the sums sum_p w_p, the weighted gaps and the
 * covered fractions (before the min) of each facet, then the distance to the nearest partner and
 * the largest reach around it of each own facet. worst: the largest depth and the largest ratio,
 * each >= 0 (the run's two figures, in one pass), and the largest n_i . n_j of the touching pairs, -1
 * without one: minus the cosine of the largest angle at which the planes of two touching facets
 * cross (pair_outputs.PairOutputs.penetration). */
void dem_pair_penetration(const dem_pairs *pairs, const dem_pair_state *state, const double *restrict centre,
                          const double *restrict uf, const double *restrict facet_normal,
                          const double *restrict reach, const double *restrict length, int64_t n_own,
                          double *restrict work, double *restrict depth, double *restrict scale,
                          double *restrict worst)
{
  const int32_t d = pairs->d;
  const int64_t n = pairs->n_facets;
  double *restrict weight = work, *restrict mean = work + n, *restrict cover = work + 2 * n;
  double *restrict nearest = work + 3 * n, *restrict around = work + 3 * n + n_own;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j, *restrict p = state->closed;
  const double *restrict normal = pairs->normal, *restrict w = state->w;
  memset(work, 0, (size_t)(3 * n) * sizeof *work);
  worst[2] = -1.0;
  for (int64_t k = 0; k < state->n; ++k)
  {
    if (!(w[k] > 0))
      continue;
    const int64_t q = p[k];
    double gap = 0.0, cos_i = 0.0, cos_j = 0.0, facing = 0.0;
    for (int32_t x = 0; x < d; ++x)
    {
      gap += ((centre[j[q] * d + x] + uf[j[q] * d + x]) - centre[i[q] * d + x] - uf[i[q] * d + x]) *
             normal[q * d + x];
      cos_i += facet_normal[i[q] * d + x] * normal[q * d + x];
      cos_j += facet_normal[j[q] * d + x] * normal[q * d + x];
      facing += facet_normal[i[q] * d + x] * facet_normal[j[q] * d + x];
    }
    worst[2] = facing > worst[2] ? facing : worst[2];
    weight[i[q]] += w[k];
    weight[j[q]] += w[k];
    mean[i[q]] += w[k] * gap;
    mean[j[q]] += w[k] * gap;
    cover[i[q]] += w[k] / (length[i[q]] * fabs(cos_i));
    cover[j[q]] += w[k] / (length[j[q]] * fabs(cos_j));
  }
  for (int64_t f = 0; f < n_own; ++f)
  {
    nearest[f] = INFINITY; /* the squared distance to the nearest partner, then the distance */
    depth[f] = INFINITY;   /* the depth behind the nearest partner, then the least behind those around it */
    scale[f] = around[f] = reach[f];
  }
  for (int64_t k = 0; k < state->n; ++k)
  {
    const int64_t q = p[k];
    if (!(w[k] > 0))
      continue;
    if (i[q] < n_own && reach[j[q]] > scale[i[q]])
      scale[i[q]] = reach[j[q]];
    if (j[q] < n_own && reach[i[q]] > scale[j[q]])
      scale[j[q]] = reach[i[q]];
  }
  if (d == 3) /* a constant d: the loops unrolled */
    behind_partners(3, pairs, centre, uf, facet_normal, reach, n_own, cover, nearest, depth, around);
  else
    behind_partners(2, pairs, centre, uf, facet_normal, reach, n_own, cover, nearest, depth, around);
  worst[0] = worst[1] = 0.0;
  for (int64_t f = 0; f < n_own; ++f)
  {
    const double kappa = cover[f] < DEM_COVERED ? cover[f] : 1.0;
    const double covered = weight[f] > 0 ? -kappa * mean[f] / weight[f] : 0.0;
    const double hole = kappa < DEM_COVERED && depth[f] > 0 && isfinite(depth[f]) ? (1.0 - kappa) * depth[f] : 0.0;
    const double part = covered > 0 ? covered : 0.0, ratio = (part / scale[f] + hole / around[f]) / 2;
    depth[f] = part + hole;
    if (hole > 0) /* each part over the size of what it reads; one of them alone: that size, bit for bit */
      scale[f] = part > 0 ? depth[f] / (2 * ratio) : around[f];
    worst[0] = depth[f] > worst[0] ? depth[f] : worst[0];
    worst[1] = ratio > worst[1] ? ratio : worst[1];
  }
}
