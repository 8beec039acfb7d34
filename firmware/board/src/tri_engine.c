/* The triangle error engine on the board (rtl/soc_engine.v, the ENGINE registers): E(T)'s scan of a
 * triangle's samples in the FPGA, for tri_error.c's scan_any, its slope unit (rtl/tri_slope.v) for
 * tri_error.c's slope_square, its angle unit (rtl/tri_angle.v) for fixed.c's wm_angle_q16 and its
 * point-error unit (rtl/tri_point.v) for tri_error.c's wm_point_error (built into the board's refiner with
 * WM_TRI_ENGINE, WM_SLOPE_ENGINE, WM_ANGLE_ENGINE, WM_POINT_ENGINE: firmware/board/CMakeLists.txt; the
 * native build keeps the C).
 *
 * The engine reads HEIGHT, so it takes the triangles of a field whose samples are the height memory
 * (the board job's: app/board_job.c) on a grid of at most 2^WM_ENGINE_COORD_BITS a side; for any other it
 * answers 0 and the C scans.  One triangle at a time: the corners, their heights (read here through the
 * cache, as the C scan reads them) and the limit into the staging registers, PUSH, then the result once
 * STATUS says it is there.  The result is the C scan's, Vmax and the first sample reaching it (or the
 * first V above limit): tests/rtl/test_tri_engine.py.
 *
 * The registers keep what was written (rtl/soc_engine.v), so each job's calls write only what changed:
 * the field (which the refiner keeps for the job: its width into WIDTH) and the params (the slope scales
 * into SLOPE_X, SLOPE_Y) when a call gives others than the last, the corners and their heights when
 * they are not the triangle staged last (the slope factor after the scan of the same triangle, or the
 * scan after it, the point errors of one triangle).  `held` says what the registers hold; a job starts
 * with it cleared (wm_tri_engine_forget, app/board_job.c: HEIGHT and the refiner's storage are new), so
 * no state carries from one job to the next and a job's cycles depend on it alone. */
#include "wm_internal.h"
#include "wm_memmap.h"

/* What the registers hold in this job: the field and the params the last call gave (pointers into the
 * refiner's storage, whose field and params stay for the job) and what they told (the width; whether
 * the units take the field, ON, and without a holes mask, BARE; the vertical metric, VERTICAL; WIDTH,
 * SLOPE_X and SLOPE_Y written from them) and the corners V0..V2 hold (their heights in Z01, Z2), V0's
 * with bit 31 set (STAGED; none when clear: no place word has it, y < 2^15).  All zeros is nothing known
 * (and keeps it out of .data); one cache line (a call's first load brings the rest). */
#define STAGED 0x80000000u
#define ON 1
#define BARE 2
#define VERTICAL 4
static struct {
    const wm_field *f;
    const wm_params *p;
    int32_t w;
    uint32_t flags;
    uint32_t v0, v1, v2;
} held __attribute__((aligned(32)));

void wm_tri_engine_forget(void)
{
    held.f = NULL;
    held.p = NULL;
    held.v0 = 0;
}

/* Whether the units read this field's samples: the height memory's (HEIGHT), on a grid of at most
 * 2^WM_ENGINE_COORD_BITS a side (the coordinate registers' width); a new field's width into WIDTH. */
static WM_ALWAYS_INLINE int on_engine(const wm_field *f)
{
    if (f != held.f) {
        held.f = f;
        held.w = f->width;
        held.flags &= ~(uint32_t)(ON | BARE);
        if (f->samples == (const uint16_t *)WM_HEIGHT_BASE && f->width <= (1 << WM_ENGINE_COORD_BITS) &&
            f->height <= (1 << WM_ENGINE_COORD_BITS)) {
            held.flags |= ON | (f->mask ? 0 : BARE);
            WM_ENGINE_WIDTH = (uint32_t)f->width;
        }
    }
    return held.flags & ON;
}

/* A grid place as the V0..V2 and POINT_P words hold it. */
static WM_ALWAYS_INLINE uint32_t place_word(int32_t x, int32_t y)
{
    return (uint32_t)x << WM_ENGINE_V0_X_SHIFT | (uint32_t)y << WM_ENGINE_V0_Y_SHIFT;
}

/* The params' slope scales (wm_slope_scale) into SLOPE_X, SLOPE_Y, which the slope unit takes (and the
 * point-error unit's mode 2), and their metric, when they are not the last call's params; the scales'
 * exponents fit 7 bits. */
static WM_ALWAYS_INLINE void scales(const wm_params *p)
{
    uint32_t mx, my;
    int32_t ex, ey;
    if (p == held.p) return;
    held.p = p;
    held.flags = (held.flags & ~(uint32_t)VERTICAL) | (p->metric == WM_METRIC_VERTICAL ? VERTICAL : 0);
    wm_slope_scale(p, 0, &mx, &ex);
    wm_slope_scale(p, 1, &my, &ey);
    WM_ENGINE_SLOPE_X = mx | (uint32_t)ex << WM_ENGINE_SLOPE_X_E_SHIFT;
    WM_ENGINE_SLOPE_Y = my | (uint32_t)ey << WM_ENGINE_SLOPE_X_E_SHIFT;
}

/* The triangle's corners and their heights (read here through the cache, as the C reads them) into the
 * staging registers V0, V1, V2, Z01 and Z2, which every unit takes, unless they hold them already. */
static WM_ALWAYS_INLINE void stage(int32_t w, const int32_t x[3], const int32_t y[3])
{
    const uint16_t *h = (const uint16_t *)WM_HEIGHT_BASE; /* on_engine's */
    uint32_t v0 = place_word(x[0], y[0]), v1 = place_word(x[1], y[1]), v2 = place_word(x[2], y[2]);
    if ((v0 | STAGED) == held.v0 && v1 == held.v1 && v2 == held.v2) {
#if WM_CHECK
        WM_ASSERT(WM_ENGINE_V0 == v0 && WM_ENGINE_V1 == v1 && WM_ENGINE_V2 == v2 &&
                  WM_ENGINE_Z2 == h[y[2] * w + x[2]] &&
                  WM_ENGINE_Z01 == (((uint32_t)h[y[0] * w + x[0]] << WM_ENGINE_Z01_Z0_SHIFT) |
                                    ((uint32_t)h[y[1] * w + x[1]] << WM_ENGINE_Z01_Z1_SHIFT)));
#endif
        return;
    }
    held.v0 = v0 | STAGED;
    held.v1 = v1;
    held.v2 = v2;
    WM_ENGINE_V0 = v0;
    WM_ENGINE_V1 = v1;
    WM_ENGINE_V2 = v2;
    WM_ENGINE_Z01 = ((uint32_t)h[y[0] * w + x[0]] << WM_ENGINE_Z01_Z0_SHIFT) |
                    ((uint32_t)h[y[1] * w + x[1]] << WM_ENGINE_Z01_Z1_SHIFT);
    WM_ENGINE_Z2 = h[y[2] * w + x[2]];
}

int wm_tri_engine_scan(const wm_field *f, const int32_t x[3], const int32_t y[3], uint64_t limit, uint64_t *vmax,
                       int32_t *wx, int32_t *wy)
{
    uint32_t at, lo, hi;
    if (!on_engine(f)) return 0;
    WM_ENGINE_LIMIT_LO = (uint32_t)limit;
    WM_ENGINE_LIMIT_HI = (uint32_t)(limit >> 32);
    stage(held.w, x, y);
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
 * scales (wm_slope_scale) into the staging registers (what they do not hold already), SLOPE_GO, then
 * floor(sqrt(X)) and k once SLOPE_STATUS says DONE: the C's slope_square and wm_isqrt64
 * (tests/rtl/test_tri_slope.py).  The same fields as the scan (HEIGHT, at most 2^WM_ENGINE_COORD_BITS a
 * side).  In two halves, so that the CPU works beside the unit (tri_error.c: the division for ev): _go
 * starts it (0: it cannot take the field, and the C computes the slope factor), _take waits for its
 * root, and no other command starts the slope unit between them (SLOPE_GO is ignored while it is busy). */
int wm_tri_engine_slope_go(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3])
{
    if (!on_engine(f)) return 0;
    scales(p);
    stage(held.w, x, y);
    WM_ENGINE_SLOPE_GO = 1;
    return 1;
}

uint32_t wm_tri_engine_slope_take(int *k)
{
    uint32_t st;
    do {
        st = WM_ENGINE_SLOPE_STATUS; /* the unit divides and takes the root */
    } while (!(st & WM_ENGINE_SLOPE_STATUS_DONE));
    *k = (int)((st & WM_ENGINE_SLOPE_STATUS_K_MASK) >> WM_ENGINE_SLOPE_STATUS_K_SHIFT);
    return WM_ENGINE_SLOPE_ROOT;
}

int wm_tri_engine_slope(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                        uint32_t *root, int *k)
{
    if (!wm_tri_engine_slope_go(f, p, x, y)) return 0;
    *root = wm_tri_engine_slope_take(k);
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
    const uint16_t *h = (const uint16_t *)WM_HEIGHT_BASE; /* on_engine's */
    int32_t w;
    uint32_t mode, st;
    if (!on_engine(f) || !(held.flags & BARE)) return 0;
    w = held.w;
    scales(p);
    stage(w, x, y);
    WM_ENGINE_POINT_P = place_word(px, py);
    if (held.flags & VERTICAL) {
        mode = 0;
    } else if (kept && *kept) {
        WM_ENGINE_POINT_R_LO = (uint32_t)*kept;
        WM_ENGINE_POINT_R_HI = (uint32_t)(*kept >> 32);
        mode = 1;
    } else {
        mode = 2; /* SLOPE_X, SLOPE_Y: scales() */
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
