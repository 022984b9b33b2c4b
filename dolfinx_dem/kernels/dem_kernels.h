/* The compiled kernels of dolfinx_dem: every exported type and function, declared once.
 *
 * The cffi build (kernels/_build.py) reads this header for its declarations (the preprocessor
 * lines dropped), and every .c file of the package includes it. The kernels work on
 * process-local arrays only; communication (ghost updates, reductions) is the caller's. Arrays
 * of n x d values are row-major; "accumulated" outputs are added to (+=), never overwritten.
 * Python builds each struct once where its arrays are made (kernels/__init__.py: ``Struct``,
 * ``csr``) and passes its pointer per call.
 */
#ifndef DEM_KERNELS_H
#define DEM_KERNELS_H

#include <stddef.h>
#include <stdint.h>

/* ---- types ------------------------------------------------------------------------------ */

/* A CSR matrix: row r has the entries data[k] in columns indices[k], indptr[r] <= k <
 * indptr[r + 1]. A pattern has data NULL. */
typedef struct
{
  const int32_t *indptr;
  const int32_t *indices;
  const double *data;
  int64_t n_rows;
  int64_t n_cols;
} dem_csr;

/* Rows of Q with a key each and the transposed pattern of their columns (the stability bound's
 * row sums, stability.py): qt_ptr, qt_rows list for each column the rows through it, in
 * increasing key. */
typedef struct
{
  dem_csr rows;
  const int64_t *key;
  const int32_t *qt_ptr;
  const int32_t *qt_rows;
} dem_row_set;

/* The cells of a MEMM step (memm_state.StepState): n_blocks cells of bs dofs that share a
 * mass, the time step and what dem_memm_update sums. */
typedef struct
{
  int64_t n_blocks;
  int32_t bs;
  double dt;
  double c;             /* dt^2 / 2 */
  const double *mass;   /* n_blocks */
  const double *minv;   /* n_blocks */
  const double *f;      /* a constant external force, for f . u (NULL: none) */
  const int32_t *body;  /* the free body of each cell (NULL: none) */
  double *sums;         /* kinetic, pseudo-kinetic, f . u (accumulated) */
  double *total;        /* the momentum of vbar, bs components (accumulated) */
  double *momentum;     /* the momentum of each free body, bs components each (accumulated) */
} dem_memm_cells;

/* QF, the own energy rows that the local candidate facets' dofs touch, by columns (a CSC: its
 * columns, facet f's dofs f d + x, are the rows of ``columns``), with the work arrays of
 * dem_pair_rows (pair_contact._CSC). */
typedef struct
{
  dem_csr columns;
  double *sums;      /* one per own row: zero between the calls */
  int32_t *mark;     /* one per own row: -1 between the calls */
  int32_t *touched;  /* two per own row */
} dem_facet_rows;

/* Facets projected on their pair's plane (pair_contact._Simplices), P simplices of d vertices
 * of dim = d - 1 coordinates: vertices X, their faces' outward normals m (unnormalised) and
 * unit normals nu (P x d x dim each), the faces' measures size (P x d). */
typedef struct
{
  const double *X;
  const double *m;
  const double *nu;
  const double *size;
} dem_simplices;

/* A Verlet list of pairs of candidate facets (pair_contact._Pairs) over the known facets
 * (local, then ghosts), made when the list is built. */
typedef struct
{
  int32_t d;
  /* the known facets */
  int64_t n_facets;
  dem_csr R;                 /* free reconstructions: n_facets d rows, patch dofs as columns */
  const double *lift;        /* uc = R up + lift (n_facets x d) */
  const double *reference;   /* uc when the list was built (n_facets x d) */
  const double *half_skin2;  /* (skin / 2)^2 of each (n_facets) */
  double slack;              /* how far a flight's screen looks beyond its end */
  double end_slack2;         /* (slack / 2)^2: a state this close to a flight's end reads its screen */
  /* the pairs (i, j) of facets */
  int64_t n;
  const int64_t *i, *j;
  const double *normal;      /* n x d */
  const double *t;           /* tangents: n x (d - 1) x d */
  const double *d0;          /* reference gaps */
  const double *e_i, *e_j;   /* correction directions: n x d each */
  const double *sep;         /* separations of the projections: n x 2 d */
  dem_simplices si, sj;      /* the facets projected, origin at facet i's barycentre */
  dem_csr z;                 /* Z^T: z_p, one row per pair, the own rows touched as columns */
  int32_t *slot;             /* one per own row touched: -1 between the calls */
} dem_pairs;

/* The own energy rows a = Q u + q that candidate facets touch (pair_contact.PairContact): Q on
 * the patch dofs, the rows' lift q and whether each is an elastic row (else stabilisation). */
typedef struct
{
  dem_csr Q;
  const double *q;
  const int8_t *elastic;
} dem_patch;

/* A Gauss rule on [0, 1]: n nodes xi, weights wq. */
typedef struct
{
  int32_t n;
  const double *xi;
  const double *wq;
} dem_gauss;

/* A step's free flight uc + tau vc, 0 <= tau <= dt, of the known facets (n_facets x d each;
 * pair_contact.PairContact._free_flight), and its screen: screen (one per listed pair) bit 0
 * if c_p may not vanish during the flight, bit 1 if the pair may be closed at its end; the
 * pairs touching (bit 0) and candidates (bit 1), increasing (n_touching = -1: not screened). */
typedef struct
{
  const double *uc;
  const double *vp;          /* the patch values of the velocity */
  double *vc;                /* R vp */
  double dt;
  double ratio;              /* the largest motion from the list's reference at the end, / (skin/2)^2 */
  int8_t *screen;
  int64_t *touching;
  int64_t *candidates;
  int64_t n_touching;
  int64_t n_candidates;
} dem_flight;

/* A contact state (pair_contact._At): the n listed pairs closed[k] whose c_p = w_p g_p^- may
 * not vanish, their gap g, overlap w, dw/du_j (d each), c and mu_p = z_p . (a + delta), the
 * own rows' energy change (elastic, stabilisation) and the sum of mu_p w_p; from_flight: only
 * the last flight's candidates were screened. */
typedef struct
{
  int64_t n;
  int64_t *closed;
  double *g, *w, *dw, *c, *mu;
  double energy[2];
  double mu_w;
  int32_t from_flight;
} dem_pair_state;

/* Contact with rigid obstacles on a process's patch (rigid.RigidContact): the candidates' gaps
 * g = Rn up + g0 (own candidates first), the rows' part Z (patch x candidates: Q^T Y on the own
 * rows), the own facets' coefficients y_f . a = YQ up + Yq and Gram rows G (own x candidates),
 * RnT (patch x own: Rn's own rows transposed), and the touched rows a = Q up + q, delta = Y g^-
 * with whether each is own and elastic. */
typedef struct
{
  dem_csr Rn;
  const double *g0;
  int64_t n_own;
  dem_csr Z, YQ, G, RnT, Q, Y;
  const double *Yq;
  const double *q;
  const int8_t *own_row;
  const int8_t *elastic;
} dem_rigid;

/* Work memory of the contact kernels, kept between their calls (zero-initialised; released by
 * dem_arena_free). */
typedef struct
{
  void *block;
  size_t size;
  size_t used;
  size_t wanted;
  void *spill;
} dem_arena;

/* ---- energy rows and MEMM update (rows.c) ----------------------------------------------- */

void dem_gram_apply(const dem_csr *Q, int64_t n_elastic, const double *x, const int32_t *shift_index,
                    const double *shift, double *y, double alpha, double scale, double *z, double *sums);
void dem_lift_sums(int64_t n, const int32_t *rows, const double *q, const double *y, double scale,
                   int64_t n_elastic, double *sums);
void dem_memm_update(const dem_memm_cells *cells, double *z_old, const double *z_new, const double *load,
                     double *u, const double *v_next, double *v_prev, int32_t advance);
void dem_row_column_range(const dem_csr *Q, int32_t n_cols, int32_t *lo, int32_t *hi);
void dem_transpose_pattern(const dem_csr *Q, const int64_t *ranges, int32_t n_ranges, int32_t first,
                           int32_t n_cols, int32_t *ptr, int32_t *rows);
void dem_gram_abs_rowsums(int64_t first, int64_t n_out, const dem_row_set *own, const dem_row_set *other,
                          const double *x, double *r, double *acc);
int64_t dem_pair_rows(const dem_facet_rows *QF, int64_t n_pairs, int32_t d, const int64_t *i, const int64_t *j,
                      const double *e_i, const double *e_j, const double *length, int32_t *indptr,
                      int32_t *indices, double *data);

/* ---- overlap geometry (overlap.c) ------------------------------------------------------- */

void dem_pair_project(int64_t n, int32_t d, const int64_t *f, const int64_t *origin, const double *ends,
                      const double *centre, const double *t, double *X);
void dem_simplices_of(int64_t n, int32_t d, const double *X, double *m, double *nu, double *size);
void dem_pair_separations(int64_t n, int32_t d, const dem_simplices *A, const dem_simplices *B, double margin,
                          double *out);
void dem_overlap(int64_t n, int32_t dim, const int64_t *p, const dem_simplices *A, const dem_simplices *B,
                 const double *s, double *w, double *dw);

/* ---- flight and screen (flight.c) ------------------------------------------------------- */

void dem_csr_apply(const dem_csr *R, const double *x, const double *lift, double *out);
int64_t dem_pair_worst_motion(const dem_pairs *pairs, const double *uc, double *ratio);
int64_t dem_pair_flight(const dem_pairs *pairs, int32_t do_screen, dem_flight *flight);
int64_t dem_pair_end_state(const dem_pairs *pairs, const dem_patch *patch, const double *up,
                           const dem_flight *last, dem_arena *work, double *uc, dem_pair_state *state);

/* ---- events and exact force integral (integral.c) --------------------------------------- */

void dem_piecewise_midpoints(int64_t n_times, const int64_t *rows, const double *times, int64_t n, int64_t k,
                             double dt, int64_t *counts, double *points, double *mid, double *length);
void dem_pair_facet_forces(const dem_pairs *pairs, int64_t n, const int64_t *p, const double *mu, const double *g,
                           const double *w, const double *dw, double *out);
int64_t dem_pair_force_integral(const dem_pairs *pairs, const dem_patch *patch, const double *up,
                                const dem_flight *flight, const dem_gauss *gauss, dem_arena *work, double *result,
                                double *impulse);
void dem_arena_free(dem_arena *work);

/* ---- contact with rigid obstacles (rigid.c) --------------------------------------------- */

int64_t dem_rigid_force_integral(const dem_rigid *c, const double *up, const double *vp, double dt, dem_arena *arena,
                                 double *out, double *normal);
int64_t dem_rigid_energy(const dem_rigid *c, const double *up, dem_arena *arena, double *energy);

/* ---- outputs (outputs.c) ---------------------------------------------------------------- */

void dem_pair_facet_corrections(const dem_pairs *pairs, const dem_pair_state *state, const double *length,
                                double *work, double *out);
int64_t dem_pair_body_forces(const dem_pairs *pairs, const dem_pair_state *state, const int64_t *body,
                             int64_t n_bodies, const int64_t *index, double *out);
void dem_pair_penetration(const dem_pairs *pairs, const dem_pair_state *state, const double *centre,
                          const double *uf, const double *facet_normal, const double *reach, const double *length,
                          int64_t n_own, double *work, double *depth, double *scale, double *worst);

#endif
