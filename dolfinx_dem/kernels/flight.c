/* A step's free flight and its screen, and the contact state at one displacement
 * (pair_contact.PairContact._free_flight and _At): the free facet displacements and velocities
 * (R up + lift, R vp), the Verlet list's validity, the pairs whose c_p = w_p g_p^- may not
 * vanish, and their state. */
#include "internal.h"

/* out = R x + lift (lift may be NULL): each row's sum in the order of its entries (as scipy's
 * product), then the lift added. The free facet displacements of pair_contact.PairContact. */
void dem_csr_apply(const dem_csr *R, const double *restrict x, const double *restrict lift, double *restrict out)
{
  const int32_t *restrict ptr = R->indptr, *restrict idx = R->indices;
  const double *restrict val = R->data;
  for (int64_t r = 0; r < R->n_rows; ++r)
  {
    double sum = 0.0;
    for (int32_t e = ptr[r]; e < ptr[r + 1]; ++e)
      sum += val[e] * x[idx[e]];
    out[r] = lift ? sum + lift[r] : sum;
  }
}

/* The facet that moved farthest from ``reference``, relative to half its skin, at the
 * displacements uc + tau vc (n facets x d; vc NULL: uc): the k maximising |x_k - reference_k|^2
 * / half_skin2_k (half_skin2 NULL: 1) (returned; -1 if n = 0) and that ratio (*ratio; 0 if n = 0). */
static int64_t worst_motion(int64_t n, int32_t d, const double *restrict uc, const double *restrict vc, double tau,
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

/* The known facet that moved farthest since the list was built, relative to half its skin, at
 * the free displacements uc (returned; -1 if none), and that ratio (*ratio): the list is stale
 * at uc if it exceeds 1. */
int64_t dem_pair_worst_motion(const dem_pairs *pairs, const double *restrict uc, double *restrict ratio)
{
  return worst_motion(pairs->n_facets, pairs->d, uc, NULL, 0.0, pairs->reference, pairs->half_skin2, ratio);
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
DEM_INLINE void screen_pairs(int64_t count, const int32_t d, const int64_t *restrict subset, const dem_pairs *pairs,
                             const double *restrict uc, const double *restrict vc, double dt, double slack,
                             int8_t *restrict out)
{
  const int32_t dim = d - 1, stride = d * dim;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j;
  const double *restrict n = pairs->normal, *restrict t = pairs->t, *restrict d0 = pairs->d0;
  const double *restrict sep = pairs->sep, *restrict mA = pairs->si.m, *restrict mB = pairs->sj.m;
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
static void screen(int64_t count, const int64_t *restrict subset, const dem_pairs *pairs, const double *restrict uc,
                   const double *restrict vc, double dt, double slack, int8_t *restrict out)
{
  if (pairs->d == 3)
    screen_pairs(count, 3, subset, pairs, uc, vc, dt, slack, out);
  else
    screen_pairs(count, 2, subset, pairs, uc, vc, dt, slack, out);
}

/* pair_contact.PairContact._free_flight, a step's free flight uc + tau vc (0 <= tau <= dt) in
 * one call: vc = R vp (dem_csr_apply), the known facet farthest from the list's reference at the
 * flight's end relative to half its skin (returned, and flight->ratio), and, if do_screen and
 * that ratio is at most 1, the screen (screen_pairs over the list: flight->screen, and its two
 * sets as sorted indices, touching (bit 0) and candidates (bit 1), n pairs each at most); else
 * n_touching = n_candidates = -1. */
int64_t dem_pair_flight(const dem_pairs *pairs, int32_t do_screen, dem_flight *flight)
{
  dem_csr_apply(&pairs->R, flight->vp, NULL, flight->vc);
  const int64_t worst = worst_motion(pairs->n_facets, pairs->d, flight->uc, flight->vc, flight->dt,
                                     pairs->reference, pairs->half_skin2, &flight->ratio);
  if (!do_screen || flight->ratio > 1.0)
  {
    flight->n_touching = flight->n_candidates = -1;
    return worst;
  }
  int8_t *restrict out = flight->screen;
  screen(pairs->n, NULL, pairs, flight->uc, flight->vc, flight->dt, pairs->slack, out);
  int64_t n_touching = 0, n_candidates = 0;
  for (int64_t p = 0; p < pairs->n; ++p)
  {
    if (out[p] & 1)
      flight->touching[n_touching++] = p;
    if (out[p] & 2)
      flight->candidates[n_candidates++] = p;
  }
  flight->n_touching = n_touching;
  flight->n_candidates = n_candidates;
  return worst;
}

/* The contact state of dem_pair_end_state at the free facet displacements uc (patch values up):
 * the listed pairs whose c_p may not vanish there, in order (screen_pairs without a flight),
 * their gap g, overlap w, dw/du_j (pair_overlap), c = w g^-, and, over the own rows their z_p
 * touch, a = Q u + q, delta = Z c and mu_p = z_p . (a + delta); the energy change sum (a delta +
 * delta^2 / 2) over the touched elastic rows and the others, in the order the pairs first touch
 * them, and the sum of mu_p w_p over the closed pairs (-contact_force_part). state's arrays: one
 * entry per listed pair, the first n written. candidates (sorted, n_candidates; NULL: all pairs):
 * the only pairs that may be closed. Returns n, or -1 if memory ran out. */
static int64_t pair_state(const dem_pairs *pairs, const dem_patch *patch, const double *restrict up,
                          int64_t n_candidates, const int64_t *restrict candidates, const double *restrict uc,
                          dem_arena *arena, dem_pair_state *state)
{
  const int32_t d = pairs->d;
  const int64_t n_pairs = pairs->n;
  const int64_t *restrict i = pairs->i, *restrict j = pairs->j;
  const double *restrict normal = pairs->normal, *restrict d0 = pairs->d0;
  const int32_t *restrict z_ptr = pairs->z.indptr, *restrict z_idx = pairs->z.indices;
  const double *restrict z_val = pairs->z.data;
  int32_t *restrict slot = pairs->slot;
  int64_t *restrict closed = state->closed;
  double *restrict g = state->g, *restrict w = state->w, *restrict dw = state->dw, *restrict c = state->c;
  int64_t n = 0, bound = 0, n_rows = 0, status = -1;
  int32_t *rows = NULL;
  double *a = NULL, *delta = NULL;
  arena_start(arena);
  int8_t *closed_mark = arena_take(arena, n_pairs, sizeof *closed_mark);
  if (!closed_mark)
    goto done;
  screen(candidates ? n_candidates : n_pairs, candidates, pairs, uc, NULL, 0.0, 0.0, closed_mark);
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
  rows = arena_take(arena, bound, sizeof *rows);
  a = arena_take(arena, bound, sizeof *a);
  delta = arena_zeros(arena, bound, sizeof *delta);
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
      pair_overlap(3, p, pairs, du, w + k, dw + k * d);
    else
      pair_overlap(2, p, pairs, du, w + k, dw + k * d);
    c[k] = w[k] * (g[k] < 0.0 ? g[k] : 0.0);
  }
  /* a and delta = Z c on the touched rows; mu; the energy change */
  n_rows = number_columns(n, closed, &pairs->z, slot, rows, 0);
  rows_apply(n_rows, rows, &patch->Q, up, patch->q, a, NULL, NULL);
  for (int64_t k = 0; k < n; ++k)
    for (int32_t e = z_ptr[closed[k]]; e < z_ptr[closed[k] + 1]; ++e)
      delta[slot[z_idx[e]]] += z_val[e] * c[k];
  for (int64_t k = 0; k < n; ++k)
  {
    double y = 0.0;
    for (int32_t e = z_ptr[closed[k]]; e < z_ptr[closed[k] + 1]; ++e)
      y += z_val[e] * (a[slot[z_idx[e]]] + delta[slot[z_idx[e]]]);
    state->mu[k] = y;
    state->mu_w += y * w[k];
  }
  for (int64_t s = 0; s < n_rows; ++s)
    state->energy[patch->elastic[rows[s]] ? 0 : 1] += a[s] * delta[s] + 0.5 * delta[s] * delta[s];
  status = n;

done:
  for (int64_t s = 0; s < n_rows; ++s)
    slot[rows[s]] = -1;
  state->n = status < 0 ? 0 : status;
  return status;
}

/* pair_contact._At in one call: the free facet displacements uc = R up + lift (dem_csr_apply);
 * if the list is stale at uc (dem_pair_worst_motion's ratio above 1) returns -2 and nothing
 * more; else the contact state (pair_state), screening only the last flight's candidates if
 * every facet lies within slack / 2 of its end (uc + dt vc of ``last``; pairs->end_slack2;
 * state->from_flight = 1; none closed if there are none), every listed pair otherwise (last
 * NULL: no flight). state may hold an earlier state (its count and sums are reset). Returns the
 * number of closed pairs, -2 (stale) or -1 (out of memory). */
int64_t dem_pair_end_state(const dem_pairs *pairs, const dem_patch *patch, const double *restrict up,
                           const dem_flight *last, dem_arena *work, double *restrict uc, dem_pair_state *state)
{
  const int64_t n_facets = pairs->n_facets;
  const int32_t d = pairs->d;
  double ratio[2];
  state->n = 0; /* the struct may hold an earlier state: its sums start again */
  state->energy[0] = state->energy[1] = state->mu_w = 0.0;
  dem_csr_apply(&pairs->R, up, pairs->lift, uc);
  if (last) /* how far uc lies from the end of the last flight */
    worst_motion(n_facets, d, last->uc, last->vc, last->dt, uc, NULL, ratio + 1);
  worst_motion(n_facets, d, uc, NULL, 0.0, pairs->reference, pairs->half_skin2, ratio);
  state->from_flight = last && ratio[1] <= pairs->end_slack2;
  if (ratio[0] > 1.0)
    return -2;
  if (state->from_flight && last->n_candidates == 0)
    return 0;
  return pair_state(pairs, patch, up, state->from_flight ? last->n_candidates : 0,
                    state->from_flight ? last->candidates : NULL, uc, work, state);
}
