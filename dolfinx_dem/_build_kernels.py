"""cffi builder of ``dolfinx_dem._kernels`` from ``kernels.c``; run at install (setup.py's
``cffi_modules``), or by hand: ``python dolfinx_dem/_build_kernels.py`` (builds in place)."""

import pathlib

import cffi

SOURCE = pathlib.Path(__file__).with_name("kernels.c")

ffibuilder = cffi.FFI()
ffibuilder.cdef(
    """
    void dem_gram_apply(int64_t n_rows, int64_t n_elastic, const int32_t *rowptr, const int32_t *cols,
                        const double *vals, const double *x, const int32_t *shift_index,
                        const double *shift, double *y, double alpha, double scale, double *z,
                        double *sums);
    void dem_lift_sums(int64_t n, const int32_t *rows, const double *q, const double *y, double scale,
                       int64_t n_elastic, double *sums);
    void dem_memm_update(int64_t n_blocks, int32_t bs, double dt, double c, double *z_old,
                         const double *z_new, const double *load, const double *mass,
                         const double *minv, double *u, const double *v_next, double *v_prev,
                         const double *f, int32_t advance, const int32_t *body, double *momentum,
                         double *total, double *sums);
    void dem_row_column_range(int64_t n_rows, const int32_t *rowptr, const int32_t *cols, int32_t n_cols,
                              int32_t *lo, int32_t *hi);
    void dem_transpose_pattern(const int64_t *ranges, int32_t n_ranges, const int32_t *rowptr, const int32_t *cols,
                               int32_t first, int32_t n_cols, int32_t *ptr, int32_t *rows);
    void dem_gram_abs_rowsums(int64_t first, int64_t n_out, const int32_t *qt_ptr, const int32_t *qt_rows,
                              const int32_t *rowptr, const int32_t *cols, const double *vals,
                              const int64_t *key, const int32_t *qt2_ptr, const int32_t *qt2_rows,
                              const int32_t *rowptr2, const int32_t *cols2, const double *vals2,
                              const int64_t *key2, const double *x, double *r, double *acc);
    void dem_overlap(int64_t n, int32_t dim, const int64_t *p, const double *XA, const double *mA,
                     const double *nuA, const double *sizeA, const double *XB, const double *mB,
                     const double *nuB, const double *sizeB, const double *s, double *w, double *dw);
    void dem_csr_apply(int64_t n_rows, const int32_t *ptr, const int32_t *idx, const double *val, const double *x,
                       const double *lift, double *out);
    int64_t dem_pair_worst_motion(int64_t n, int32_t d, const double *uc, const double *vc, double tau,
                                  const double *reference, const double *half_skin2, double *ratio);
    void dem_pair_project(int64_t n, int32_t d, const int64_t *f, const int64_t *origin, const double *ends,
                          const double *centre, const double *t, double *X);
    void dem_simplices(int64_t n, int32_t d, const double *X, double *end, double *m, double *nu, double *size);
    void dem_pair_separations(int64_t n, int32_t d, const double *XA, const double *mA, const double *XB,
                              const double *mB, double margin, double *out);
    int64_t dem_pair_flight(int64_t n_rows, const int32_t *ptr, const int32_t *idx, const double *val,
                            const double *vp, const double *uc, double dt, const double *reference,
                            const double *half_skin2, int32_t do_screen, int64_t n_pairs, int32_t d, const int64_t *i,
                            const int64_t *j, const double *n, const double *t, const double *d0, const double *sep,
                            const double *mA, const double *mB, double slack, double *vc, double *ratio, int8_t *out,
                            int64_t *touching, int64_t *candidates, int64_t *counts);
    void dem_piecewise_midpoints(int64_t n_times, const int64_t *rows, const double *times, int64_t n, int64_t k,
                                 double dt, int64_t *counts, double *points, double *mid, double *length);
    void dem_pair_facet_corrections(int64_t n, int32_t d, const int64_t *p, const int64_t *i, const int64_t *j,
                                    const double *e_i, const double *e_j, const double *c, const double *length,
                                    int64_t n_facets, double *work, double *out);
    int64_t dem_pair_rows(int64_t n_pairs, int32_t d, const int64_t *i, const int64_t *j, int64_t n_local,
                          const double *e_i, const double *e_j, const double *length, const int32_t *qf_ptr,
                          const int32_t *qf_rows, const double *qf_vals, double *sums, int32_t *mark,
                          int32_t *touched, int32_t *indptr, int32_t *indices, double *data);
    void dem_pair_facet_forces(int64_t n_entries, int32_t d, const int64_t *p, const int64_t *i, const int64_t *j,
                               const double *normal, const double *mu, const double *g, const double *w,
                               const double *dw, double *out);
    int64_t dem_pair_force_integral(int64_t n, int32_t d, const int64_t *p, const int64_t *i, const int64_t *j,
                                    const double *normal, const double *t, const double *d0, const double *XA,
                                    const double *mA, const double *nuA, const double *sizeA, const double *XB,
                                    const double *mB, const double *nuB, const double *sizeB, const double *uc,
                                    const double *vc, double dt, int32_t n_gauss, const double *xi, const double *wq,
                                    const int32_t *z_ptr, const int32_t *z_idx, const double *z_val,
                                    const int32_t *q_ptr, const int32_t *q_idx, const double *q_val, const double *q,
                                    const double *up, const double *vp, int32_t *slot, int64_t n_facet_rows,
                                    const int32_t *r_ptr, const int32_t *r_idx, const double *r_val, int64_t n_patch,
                                    double *result);
    int64_t dem_pair_end_state(int64_t n_rows, const int32_t *r_ptr, const int32_t *r_idx, const double *r_val,
                               const double *lift, double *uc, const double *reference, const double *half_skin2,
                               const double *end, const double *vc, double tau, double slack2, int64_t n_candidates,
                               const int64_t *candidates, double *ratio, int32_t *used, int64_t n_pairs, int32_t d,
                               const int64_t *i, const int64_t *j, const double *normal, const double *t,
                               const double *d0, const double *sep, const double *XA, const double *mA,
                               const double *nuA, const double *sizeA, const double *XB, const double *mB,
                               const double *nuB, const double *sizeB, const int32_t *z_ptr, const int32_t *z_idx,
                               const double *z_val, const int32_t *q_ptr, const int32_t *q_idx, const double *q_val,
                               const double *q, const double *up, const int8_t *elastic, int32_t *slot,
                               int64_t *closed, double *g, double *w, double *dw, double *c, double *mu,
                               double *sums);
    int64_t dem_pair_body_forces(int64_t n, int32_t d, const int64_t *p, const int64_t *i, const int64_t *j,
                              const double *normal, const int64_t *body, int64_t n_bodies, const int64_t *index,
                              const double *mu, const double *g, const double *w, const double *dw, const double *c,
                              double *out);
    double dem_pair_penetration(int64_t n, int32_t d, const int64_t *p, const int64_t *i, const int64_t *j,
                                const double *normal, const double *centre, const double *uf, const double *w,
                                int64_t n_own, double *weight, double *mean);
    """
)
# -O3, no -march=native: the module must run on any x86-64 the package is installed for.
ffibuilder.set_source("dolfinx_dem._kernels", SOURCE.read_text(), extra_compile_args=["-O3", "-std=c99"])

if __name__ == "__main__":
    ffibuilder.compile(tmpdir=str(SOURCE.parent.parent), verbose=True)
