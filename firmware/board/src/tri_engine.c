/* The triangle error engine on the board (rtl/soc_engine.v, the ENGINE registers): E(T)'s scan of a
 * triangle's samples in the FPGA, for tri_error.c's scan_any, its slope unit (rtl/tri_slope.v) for
 * tri_error.c's slope_square, its angle unit (rtl/tri_angle.v) for fixed.c's wm_angle_q16 and its
 * point-error unit (rtl/tri_point.v) for tri_error.c's wm_point_error (built into the board's refiner with
 * WM_TRI_ENGINE, WM_SLOPE_ENGINE, WM_ANGLE_ENGINE, WM_POINT_ENGINE: firmware/board/CMakeLists.txt; the
 * native build keeps the C).
 *
 * The engine reads HEIGHT, so it takes the triangles of a field whose samples are the height memory
 * (the board job's: app/board_job.c) on a grid of at most 2^WM_ENGINE_COORD_BITS a side; for any other it
 * answers 0 and the C scans.  One triangle at a time: the grid's width, the corners, their heights (read
 * here through the cache, as the C scan reads them) and the limit into the staging registers (all of
 * them each time: no state carries from one job to the next, so a job's cycles depend on it alone),
 * PUSH, then the result once STATUS says it is there.  The result is the C scan's,
 * Vmax and the first sample reaching it (or the first V above limit): tests/rtl/test_tri_engine.py. */
#include "wm_internal.h"
#include "wm_memmap.h"

/* Whether the units read this field's samples: the height memory's (HEIGHT), on a grid of at most
 * 2^WM_ENGINE_COORD_BITS a side (the coordinate registers' width). */
static int on_engine(const wm_field *f)
{
    return f->samples == (const uint16_t *)WM_HEIGHT_BASE && f->width <= (1 << WM_ENGINE_COORD_BITS) &&
           f->height <= (1 << WM_ENGINE_COORD_BITS);
}

/* A grid place as the V0..V2 and POINT_P words hold it. */
static WM_ALWAYS_INLINE uint32_t place_word(int32_t x, int32_t y)
{
    return (uint32_t)x << WM_ENGINE_V0_X_SHIFT | (uint32_t)y << WM_ENGINE_V0_Y_SHIFT;
}

/* The triangle's corners and their heights (read here through the cache, as the C reads them) into the
 * staging registers V0, V1, V2, Z01 and Z2, which every unit takes. */
static WM_ALWAYS_INLINE void stage(const uint16_t *h, int32_t w, const int32_t x[3], const int32_t y[3])
{
    WM_ENGINE_V0 = place_word(x[0], y[0]);
    WM_ENGINE_V1 = place_word(x[1], y[1]);
    WM_ENGINE_V2 = place_word(x[2], y[2]);
    WM_ENGINE_Z01 = ((uint32_t)h[y[0] * w + x[0]] << WM_ENGINE_Z01_Z0_SHIFT) |
                    ((uint32_t)h[y[1] * w + x[1]] << WM_ENGINE_Z01_Z1_SHIFT);
    WM_ENGINE_Z2 = h[y[2] * w + x[2]];
}

int wm_tri_engine_scan(const wm_field *f, const int32_t x[3], const int32_t y[3], uint64_t limit, uint64_t *vmax,
                       int32_t *wx, int32_t *wy)
{
    const uint16_t *h = f->samples;
    int32_t w = f->width;
    uint32_t at, lo, hi;
    if (!on_engine(f)) return 0;
    WM_ENGINE_WIDTH = (uint32_t)w;
    WM_ENGINE_LIMIT_LO = (uint32_t)limit;
    WM_ENGINE_LIMIT_HI = (uint32_t)(limit >> 32);
    stage(h, w, x, y);
    WM_ENGINE_PUSH = 1;
    while (!(WM_ENGINE_STATUS & WM_ENGINE_STATUS_RES_VALID)) {
        /* the engine scans */
    }
    lo = WM_ENGINE_RES_VMAX_LO;
    hi = WM_ENGINE_RES_VMAX_HI;
    at = WM_ENGINE_RES_AT; /* takes the result */
    *vmax = (uint64_t)hi << 32 | lo;
    if (wx) *wx = (int32_t)(at & WM_ENGINE_RES_AT_X_MASK);
    if (wy) *wy = (int32_t)((at & WM_ENGINE_RES_AT_Y_MASK) >> WM_ENGINE_RES_AT_Y_SHIFT);
    return 1;
}

/* The slope unit: the corners, their heights (through the cache, as the C reads them) and the two slope
 * scales (wm_slope_scale) into the staging registers, SLOPE_GO, then floor(sqrt(X)) and k once
 * SLOPE_STATUS says DONE: the C's slope_square and wm_isqrt64 (tests/rtl/test_tri_slope.py).  The same
 * fields as the scan (HEIGHT, at most 2^WM_ENGINE_COORD_BITS a side); the scales' exponents fit 7 bits. */
int wm_tri_engine_slope(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                        uint32_t *root, int *k)
{
    const uint16_t *h = f->samples;
    int32_t w = f->width, ex, ey;
    uint32_t mx, my, st;
    if (!on_engine(f)) return 0;
    wm_slope_scale(p, 0, &mx, &ex);
    wm_slope_scale(p, 1, &my, &ey);
    stage(h, w, x, y);
    WM_ENGINE_SLOPE_X = mx | (uint32_t)ex << WM_ENGINE_SLOPE_X_E_SHIFT;
    WM_ENGINE_SLOPE_Y = my | (uint32_t)ey << WM_ENGINE_SLOPE_X_E_SHIFT;
    WM_ENGINE_SLOPE_GO = 1;
    do {
        st = WM_ENGINE_SLOPE_STATUS; /* the unit divides and takes the root */
    } while (!(st & WM_ENGINE_SLOPE_STATUS_DONE));
    *root = WM_ENGINE_SLOPE_ROOT;
    *k = (int)((st & WM_ENGINE_SLOPE_STATUS_K_MASK) >> WM_ENGINE_SLOPE_STATUS_K_SHIFT);
    return 1;
}

/* The angle unit: x and y into ANGLE_X and ANGLE_Y, the ANGLE_Y write starting it, then the angle once
 * ANGLE says DONE (one register: the result and its state): fixed.c's wm_angle_q16 of 32-bit arguments
 * (the same CORDIC: tests/rtl/test_tri_angle.py). */
int32_t wm_tri_engine_angle(int32_t x, uint32_t y)
{
    uint32_t v;
    WM_ENGINE_ANGLE_X = (uint32_t)x;
    WM_ENGINE_ANGLE_Y = y;
    do {
        v = WM_ENGINE_ANGLE; /* the unit rotates */
    } while (!(v & WM_ENGINE_ANGLE_DONE));
    return (int32_t)(v & WM_ENGINE_ANGLE_Z_MASK);
}

/* The slope unit's root command: floor(sqrt(x)) of {SQRT_HI, SQRT_LO}, the SQRT_HI write starting it, for
 * fixed.c's wm_isqrt64 (the reduction's unit normals and rotations; the same root: tests/rtl). */
uint32_t wm_tri_engine_root(uint64_t x)
{
    WM_ENGINE_SQRT_LO = (uint32_t)x;
    WM_ENGINE_SQRT_HI = (uint32_t)(x >> 32);
    while (!(WM_ENGINE_SLOPE_STATUS & WM_ENGINE_SLOPE_STATUS_DONE)) {
        /* the unit takes the root */
    }
    return WM_ENGINE_SLOPE_ROOT;
}

/* The point-error unit: the corners, their heights and the sample into the staging registers, the
 * sample's height and the mode with POINT_GO, then e once POINT_STATUS says DONE: tri_error.c's
 * wm_point_error (tests/rtl/test_tri_point.py).  The vertical metric takes ev (mode 0); the normal one
 * divides by the kept slope factor when there is one (mode 1), else by the one the slope unit computes
 * for the same command (mode 2), which is then kept as slope_factor keeps it (when e > 0: ev > 0).  The
 * same fields as the scan, and no holes mask (wm_hole_at runs first in the C). */
int wm_tri_engine_point(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t px,
                        int32_t py, uint64_t *kept, uint32_t *e)
{
    const uint16_t *h = f->samples;
    int32_t w = f->width, ex, ey;
    uint32_t mode, mx, my, st;
    if (!on_engine(f) || f->mask) return 0;
    stage(h, w, x, y);
    WM_ENGINE_POINT_P = place_word(px, py);
    if (p->metric == WM_METRIC_VERTICAL) {
        mode = 0;
    } else if (kept && *kept) {
        WM_ENGINE_POINT_R_LO = (uint32_t)*kept;
        WM_ENGINE_POINT_R_HI = (uint32_t)(*kept >> 32);
        mode = 1;
    } else {
        wm_slope_scale(p, 0, &mx, &ex);
        wm_slope_scale(p, 1, &my, &ey);
        WM_ENGINE_SLOPE_X = mx | (uint32_t)ex << WM_ENGINE_SLOPE_X_E_SHIFT;
        WM_ENGINE_SLOPE_Y = my | (uint32_t)ey << WM_ENGINE_SLOPE_X_E_SHIFT;
        mode = 2;
    }
    WM_ENGINE_POINT_GO = (uint32_t)h[py * w + px] | mode << WM_ENGINE_POINT_GO_MODE_SHIFT;
    while (!(WM_ENGINE_POINT_STATUS & WM_ENGINE_POINT_STATUS_DONE)) {
        /* the unit measures */
    }
    *e = WM_ENGINE_POINT;
    if (mode == 2 && kept && *e) {
        st = WM_ENGINE_SLOPE_STATUS;
        *kept = (uint64_t)WM_ENGINE_SLOPE_ROOT
                << ((st & WM_ENGINE_SLOPE_STATUS_K_MASK) >> WM_ENGINE_SLOPE_STATUS_K_SHIFT);
    }
    return 1;
}
