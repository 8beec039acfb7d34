/* Selective triangulation (dissertation 5.6): a region of interest (ROI) the error measure keeps to.
 *
 * The dissertation masks the wavelet details outside the region so that "no refinement takes place in
 * that region"; the host does that to the details it hands in (wavemesh/model/roi.py).  This file does the
 * rest for the refiner, which also refines wherever E(T) > zeta (the candidates of 4.3, the error
 * bound, the reduction's and the regularisation's tests): with an ROI, E(T) is the largest distance
 * over the triangle's samples that lie in the ROI, and 0 for a triangle with none.
 *
 *     +-----------+            a triangle wholly outside:  E(T) = 0, never refined
 *     |  . . .    |            wholly inside:              E(T) as without an ROI (tri_error.c)
 *     |  . ###### |            across the ROI's edge:      the ROI samples alone, and the worst of
 *     |  . ###### |                                        them is where the error bound splits
 *     +-----------+
 *
 * So the error bound puts its vertices at ROI samples and ends with every ROI sample within zeta of
 * the mesh (each lies in a triangle that holds it); outside, the mesh keeps what the templates and the
 * refinement next to the ROI made.  The ROI is a table of row prefix counts, so that a triangle's
 * share of it costs one subtraction per row. */
#include "wm_internal.h"

uint32_t wm_roi_error(const wm_refiner *r, const int32_t x[3], const int32_t y[3], int32_t *wx, int32_t *wy)
{
    const wm_field *f = &r->field;
    const int32_t *rows = r->roi;
    int64_t A[3], B[3], C[3], z[3], dS = 0, n_in = 0, n_all = 0;
    uint64_t vmax = 0;
    int32_t ymin = y[0], ymax = y[0], xmin = x[0], xmax = x[0], bx = x[0], by = y[0];
    int64_t D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    if (D <= 0) return 0xFFFFFFFFu;
    int32_t box[4];
    wm_tri_edges(x, y, A, B, C, box);
    xmin = box[0], xmax = box[1], ymin = box[2], ymax = box[3];
    for (int k = 0; k < 3; k++) {
        z[k] = f->samples[(int64_t)y[k] * f->width + x[k]];
        dS += A[k] * z[k];
    }
    /* First the share of the ROI: none and all need no scan here. */
    for (int32_t py = ymin; py <= ymax; py++) {
        int64_t lo = xmin, hi = xmax;
        const int32_t *row = rows + (int64_t)py * (f->width + 1);
        if (!wm_row_span(A, B, C, py, &lo, &hi)) continue;
        n_in += row[hi + 1] - row[lo];
        n_all += hi - lo + 1;
    }
    if (n_in == n_all) return wm_tri_error(f, &r->params, x, y, wx, wy);
    if (n_in > 0) {
        for (int32_t py = ymin; py <= ymax; py++) {
            int64_t lo = xmin, hi = xmax, S = 0;
            const int32_t *row = rows + (int64_t)py * (f->width + 1);
            const uint16_t *h = f->samples + (int64_t)py * f->width;
            if (!wm_row_span(A, B, C, py, &lo, &hi) || row[hi + 1] == row[lo]) continue;
            for (int k = 0; k < 3; k++) S += (A[k] * lo + B[k] * py + C[k]) * z[k];
            for (int64_t px = lo; px <= hi; px++, S += dS) {
                int64_t v = S - D * (int64_t)h[px];
                uint64_t av = (uint64_t)(v < 0 ? -v : v);
                if (row[px + 1] != row[px] && av > vmax) {
                    vmax = av;
                    bx = (int32_t)px;
                    by = py;
                }
            }
        }
    }
    if (wx) *wx = bx;
    if (wy) *wy = by;
    /* E(T)'s rounding of the largest distance, which the worst sample has (0 at a corner). */
    return vmax ? wm_point_error(f, &r->params, x, y, bx, by, NULL) : 0;
}

int wm_refine_set_roi(wm_refiner *r, const int32_t *rows)
{
    wm_mesh *me;
    int32_t w;
    if (r == NULL || rows == NULL) return WM_ERR_ARG;
    if (r->done || r->level != r->field.levels - 1) return WM_ERR_STATE;
    me = &r->mesh;
    w = r->field.width;
    for (int32_t py = 0; py < r->field.height; py++) {
        const int32_t *row = rows + (int64_t)py * (w + 1);
        if (row[0] != 0) return WM_ERR_ARG;
        for (int32_t px = 0; px < w; px++)
            if (row[px + 1] - row[px] != 0 && row[px + 1] - row[px] != 1) return WM_ERR_ARG;
    }
    r->roi = rows;
    wm_reduce_forget_refusals(r);
    for (int32_t t = 0; t < me->tri_end; t++) {
        int32_t x[3], y[3], wx, wy;
        if (me->he[3 * t].v < 0) continue;
        wm_tri_xy(me, t, x, y);
        r->err[t] = wm_roi_error(r, x, y, &wx, &wy);
        r->worst[t] = wy * w + wx;
    }
    return WM_OK;
}
