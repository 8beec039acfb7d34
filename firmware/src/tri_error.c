/* E(T): the largest distance from the samples in the closed triangle to the triangle's plane
 * (dissertation 2.6.2-2.6.3, L-infinity), in integers.
 *
 * With D = twice the area (> 0) and the edge functions E_k(p) = orient(p_k+1, p_k+2, p) (E_k >= 0
 * inside, E_0 + E_1 + E_2 = D), the plane at sample p is (E_0 z_0 + E_1 z_1 + E_2 z_2) / D, so
 *
 *     V(p) = | E_0 z_0 + E_1 z_1 + E_2 z_2 - D h(p) |       (exact, < 2^16 D < 2^47)
 *
 * is D times the vertical distance in sample counts.  Vertical E(T) = Vmax / D; normal E(T) =
 * Vmax / D / sqrt(1 + g^2) where g = |(s Na / dx, s Nb / dy)| / D is the plane's slope in height
 * units per ground unit (s the height scale; dx, dy the cell size, 1 by default; Na, Nb the exact
 * gradient numerators).  Rounding (docs/refiner.md):
 *
 *     ev = ceil(2^16 Vmax / D)                           Q16.16 samples, exact ceiling
 *     ga = floor(2^16 (s / dx) |Na| / D)                 Q16.16, rounded down (g smaller), gb alike
 *     r  = floor(sqrt(2^32 + ga^2 + gb^2))              Q16.16 sqrt(1 + g^2), rounded down
 *          (for ga or gb >= 2^31 both are shifted right by k first and r back left by k)
 *     en = ceil(2^16 ev / r)                             Q16.16, rounded up
 *
 * Every rounding makes the result larger, never smaller: the firmware never calls a triangle
 * within zeta when the exact distance is above it.  The slack is below 2^-15 relative + 2^-16. */
#include "wm_internal.h"

#define GCAP ((uint64_t)1 << 62)

const int32_t *wm_detail_at(const wm_field *f, int32_t m, int32_t x, int32_t y)
{
    int32_t cw = (f->width + (1 << m) - 1) >> m;
    int64_t off = wm_details_offset(f->width, f->height, m);
    return f->details + off + 3 * ((int64_t)(y >> m) * cw + (x >> m));
}

/* Scans the closed triangle row by row; returns Vmax and the first sample reaching it. */
static uint64_t scan(const wm_field *f, const int32_t x[3], const int32_t y[3], int64_t D, int32_t *wx,
                     int32_t *wy)
{
    const uint16_t *h = f->samples;
    int64_t z[3], A[3], B[3], C[3], dS;
    int32_t ymin = y[0], ymax = y[0], xmin = x[0], xmax = x[0];
    uint64_t vmax = 0;
    int32_t bx = x[0], by = y[0];
    for (int k = 0; k < 3; k++) {
        int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
        z[k] = h[(int64_t)y[k] * f->width + x[k]];
        /* E_k(px, py) = (x_k2 - x_k1)(py - y_k1) - (y_k2 - y_k1)(px - x_k1) = A px + B py + C */
        A[k] = -((int64_t)y[k2] - y[k1]);
        B[k] = (int64_t)x[k2] - x[k1];
        C[k] = -(B[k] * y[k1]) - A[k] * x[k1];
        if (y[k] < ymin) ymin = y[k];
        if (y[k] > ymax) ymax = y[k];
        if (x[k] < xmin) xmin = x[k];
        if (x[k] > xmax) xmax = x[k];
    }
    dS = A[0] * z[0] + A[1] * z[1] + A[2] * z[2];
    for (int32_t py = ymin; py <= ymax; py++) {
        int64_t lo = xmin, hi = xmax, S;
        const uint16_t *row = h + (int64_t)py * f->width;
        int empty = 0;
        for (int k = 0; k < 3; k++) {
            int64_t num = B[k] * py + C[k]; /* E_k = A x + num >= 0 */
            if (A[k] > 0) {
                int64_t l = wm_ceil_div(-num, A[k]);
                if (l > lo) lo = l;
            } else if (A[k] < 0) {
                int64_t r = wm_floor_div(num, -A[k]);
                if (r < hi) hi = r;
            } else if (num < 0) {
                empty = 1;
            }
        }
        if (empty || lo > hi) continue;
        S = 0;
        for (int k = 0; k < 3; k++) S += (A[k] * lo + B[k] * py + C[k]) * z[k];
        for (int64_t px = lo; px <= hi; px++, S += dS) {
            int64_t v = S - D * (int64_t)row[px];
            uint64_t av = (uint64_t)(v < 0 ? -v : v);
            if (av > vmax) {
                vmax = av;
                bx = (int32_t)px;
                by = py;
            }
        }
    }
    if (wx) *wx = bx;
    if (wy) *wy = by;
    return vmax;
}

/* E(T) from Vmax (the rounding of the file's head comment): monotone in vmax. */
static uint32_t finish(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int64_t D,
                       uint64_t vmax)
{
    uint64_t ev, ga, gb, r, en;
    int64_t z0, dz1, dz2, Na, Nb;
    uint32_t sm;
    int32_t se;
    ev = (vmax * 65536u + (uint64_t)D - 1) / (uint64_t)D; /* vmax < 2^47 */
    if (ev > 0xFFFFFFFFu) ev = 0xFFFFFFFFu;
    if (p->metric == WM_METRIC_VERTICAL || ev == 0) return (uint32_t)ev;
    z0 = f->samples[(int64_t)y[0] * f->width + x[0]];
    dz1 = (int64_t)f->samples[(int64_t)y[1] * f->width + x[1]] - z0;
    dz2 = (int64_t)f->samples[(int64_t)y[2] * f->width + x[2]] - z0;
    Na = dz1 * ((int64_t)y[2] - y[0]) - dz2 * ((int64_t)y[1] - y[0]);
    Nb = ((int64_t)x[1] - x[0]) * dz2 - ((int64_t)x[2] - x[0]) * dz1;
    wm_slope_scale(p, 0, &sm, &se);
    ga = wm_frac_mul((uint64_t)(Na < 0 ? -Na : Na), (uint64_t)D, sm, se, 16, GCAP);
    wm_slope_scale(p, 1, &sm, &se);
    gb = wm_frac_mul((uint64_t)(Nb < 0 ? -Nb : Nb), (uint64_t)D, sm, se, 16, GCAP);
    /* sqrt(1 + g^2) in Q16.16, rounded down: steep slopes are shifted right by k first (ga, gb
     * keep >= 30 significant bits), and the root shifted back. */
    {
        int k = 0;
        uint64_t one;
        while ((ga >> k) >= ((uint64_t)1 << 31) || (gb >> k) >= ((uint64_t)1 << 31)) k++;
        one = 2 * k >= 33 ? 0 : ((uint64_t)1 << 32) >> (2 * k);
        ga >>= k;
        gb >>= k;
        r = wm_isqrt64(one + ga * ga + gb * gb) << k;
    }
    en = (ev * 65536u + r - 1) / r;
    return (uint32_t)en;
}

uint32_t wm_tri_error(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                      int32_t *wx, int32_t *wy)
{
    int64_t D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    WM_ASSERT(D > 0);
    if (D <= 0) return 0xFFFFFFFFu;
    return finish(f, p, x, y, D, scan(f, x, y, D, wx, wy));
}

uint32_t wm_point_error(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t px,
                        int32_t py)
{
    int64_t D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]), S = 0, v;
    if (D <= 0) return 0xFFFFFFFFu;
    for (int k = 0; k < 3; k++) {
        int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
        S += wm_orient(x[k1], y[k1], x[k2], y[k2], px, py) * (int64_t)f->samples[(int64_t)y[k] * f->width + x[k]];
    }
    v = S - D * (int64_t)f->samples[(int64_t)py * f->width + px];
    return finish(f, p, x, y, D, (uint64_t)(v < 0 ? -v : v));
}
