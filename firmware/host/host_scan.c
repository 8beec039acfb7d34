/* E(T)'s scan of a triangle's samples for the host's library, in AVX2 (firmware/src/tri_error.c's
 * scan_any hands it every triangle through the hook the board's FPGA engine uses, WM_TRI_ENGINE: the
 * shared library is built so; the static one, the C runner's, keeps the C scan).  The same result as the
 * C scan: Vmax = the largest |S - D h| over the samples in the closed triangle (S = sum E_k z_k, D the
 * doubled area), the first sample reaching it in row order (rows top down, each left to right; the first
 * corner when no sample beats 0), or, as soon as a sample's V exceeds limit, that V and that sample.
 *
 * Each row's span is the C scan's: for each edge k with A_k != 0 its bound floor(u / a) on the row, u
 * stepped from row to row with the quotient and its remainder (no division a row); a level edge (A_k = 0)
 * empties the rows outside it.  The row's samples go 8 (32-bit lanes, where the C scan's scan32 takes
 * the triangle: V is exact modulo 2^32 there) or 4 (64-bit lanes) at a time: each lane's V against the
 * largest so far, and only a block holding a larger one is taken again one sample at a time, which finds
 * the first one and stops at the limit as the C scan does.  scan32's small triangles are taken on every
 * grid in lanes without a branch a row instead (scan_lanes; a triangle at most 8 samples wide over its
 * box's rows, scan_box; each without the worst sample's place when the caller asks for none), and on
 * grids under 2^20 samples (below) the other triangles are left to the C scan.  Processors without AVX2
 * (and other compilers) answer 0: the C scan runs.
 * wm_host_scan(0) turns both off, (2) puts the blocks on every triangle of every grid, (3) leaves every
 * triangle the lanes do not take to the C scan (the tests compare each with the C scan). */
#define _POSIX_C_SOURCE 200809L
#include "wm_host.h"
#include "wm_internal.h"

#include <math.h>
#include <stdint.h>

/* floor(sqrt(x)) for fixed.c's wm_isqrt64 (its hook WM_ROOT_ENGINE, the board's slope unit's, in the shared
 * library): the processor's square root of x rounded to a double is within one of it, and the integer
 * steps after it make it exact, the same root as the C's three dependent divisions (the reduction's unit
 * normals take one each; tests/host/test_host_stages.py compares them with math.isqrt). */
uint32_t wm_tri_engine_root(uint64_t x)
{
    uint64_t r = (uint64_t)sqrt((double)x);
    if (r > 0xFFFFFFFFu) r = 0xFFFFFFFFu;
    while (r * r > x) r--;
    while (r < 0xFFFFFFFFu && (r + 1) * (r + 1) <= x) r++;
    return (uint32_t)r;
}

/* Grids of fewer samples keep the C scan for the triangles the lanes do not take (wm_host_scan(1)): their
 * samples stay in a core's cache, where the blocks' set-up costs more than their lanes and prefetches save
 * (in-process refine and check, CPU, against the C scan: Jacksboro 403 x 344 1.08 - 1.10 x, terrain 724^2
 * 1.04 x, 1024^2 0.97 x, 2048^2 0.72 x).  The small triangles go to the lanes on every grid: on a tile of
 * 1025^2 they take 0.8 x the blocks' CPU. */
#define SCAN_MIN_SAMPLES ((int64_t)1 << 20)

/* 0: off, 1: the lanes for scan32's triangles, the blocks for the others on grids of SCAN_MIN_SAMPLES or
 * more, 2: the blocks for every triangle, 3: the lanes for scan32's triangles and nothing else */
static int32_t enabled = 1;

int32_t wm_host_scan(int32_t on)
{
    int32_t old = enabled;
    if (on >= 0) enabled = on > 3 ? 3 : on;
    return old;
}

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#include <immintrin.h>

#define AVX2 __attribute__((target("avx2")))

#define PREFETCH_LINES 16 /* of the next row's span: 512 samples */

/* floor(u / a) and its remainder for a > 0, and the step of both when u grows by s every row. */
struct bound {
    int64_t q, r, dq, dr, a;
};

static int64_t floor_div64(int64_t u, int64_t a) /* a > 0 */
{
    if (u == (int32_t)u && a == (int32_t)a) { /* most: a 32-bit division is several times faster */
        int32_t q = (int32_t)u / (int32_t)a;
        return ((int32_t)u % (int32_t)a != 0 && u < 0) ? q - 1 : q;
    }
    int64_t q = u / a;
    return (u % a != 0 && u < 0) ? q - 1 : q;
}

static void bound_start(struct bound *b, int64_t u, int64_t s, int64_t a)
{
    b->a = a;
    b->q = floor_div64(u, a);
    b->r = u - b->q * a;
    b->dq = floor_div64(s, a);
    b->dr = s - b->dq * a;
}

static inline AVX2 void bound_step(struct bound *b)
{
    b->q += b->dq;
    b->r += b->dr;
    if (b->r >= b->a) b->r -= b->a, b->q++;
}

struct best {
    uint64_t vm, limit;
    int32_t bx, by, over; /* over: a V above limit was found (the scan stops) */
};

/* The C scan's loop over samples [lo, hi] of row py from S at lo: new maxima, the first one kept. */
static inline AVX2 void tail64(struct best *b, const uint16_t *row, int64_t lo, int64_t hi, int32_t py, int64_t S,
                               int64_t dS, int64_t D)
{
    for (int64_t px = lo; px <= hi; px++, S += dS) {
        int64_t v = S - D * (int64_t)row[px];
        uint64_t av = (uint64_t)(v < 0 ? -v : v);
        if (av > b->vm) {
            b->vm = av;
            b->bx = (int32_t)px;
            b->by = py;
            if (av > b->limit) {
                b->over = 1;
                return;
            }
        }
    }
}

/* scan32's loop (modulo 2^32, its row_max32), for the 32-bit lanes' blocks. */
static inline AVX2 void tail32(struct best *b, const uint16_t *row, int64_t lo, int64_t hi, int32_t py, uint32_t S,
                               uint32_t dS, uint32_t d)
{
    for (int64_t px = lo; px <= hi; px++, S += dS) {
        uint32_t u = S - d * row[px], v = u >> 31 ? 0u - u : u;
        if (v > b->vm) {
            b->vm = v;
            b->bx = (int32_t)px;
            b->by = py;
            if (v > b->limit) {
                b->over = 1;
                return;
            }
        }
    }
}

/* Rows in blocks of 4 samples (64-bit lanes) or 8 (32-bit), the last block of a row less than full, its
 * lanes past the row's end cleared (V = 0 never beats the largest so far), except where its load would
 * pass the end of the samples (end): that one sample by sample. */
static inline AVX2 __attribute__((always_inline)) void row64(struct best *b, const uint16_t *row,
                                                             const uint16_t *end, int64_t lo, int64_t hi,
                                                             int32_t py, int64_t S, int64_t dS, int64_t D)
{
    const __m256i zero = _mm256_setzero_si256(), Dv = _mm256_set1_epi64x(D), lane = _mm256_set_epi64x(3, 2, 1, 0);
    const __m256i step = _mm256_set1_epi64x(4 * dS);
    __m256i Sv = _mm256_add_epi64(_mm256_set1_epi64x(S), _mm256_set_epi64x(3 * dS, 2 * dS, dS, 0));
    __m256i vmv = _mm256_set1_epi64x((int64_t)b->vm);
    int64_t px = lo;
    for (; px <= hi; px += 4) {
        int64_t n = hi - px + 1;
        if (n < 4 && row + px + 4 > end) break;
        __m256i h = _mm256_cvtepu16_epi64(_mm_loadl_epi64((const __m128i *)(row + px)));
        __m256i v = _mm256_sub_epi64(Sv, _mm256_mul_epu32(h, Dv)); /* D < 2^32, h < 2^16 */
        __m256i sg = _mm256_cmpgt_epi64(zero, v);
        v = _mm256_sub_epi64(_mm256_xor_si256(v, sg), sg); /* |V| < 2^63 */
        if (n < 4) v = _mm256_and_si256(v, _mm256_cmpgt_epi64(_mm256_set1_epi64x(n), lane));
        __m256i gt = _mm256_cmpgt_epi64(v, vmv);
        if (!_mm256_testz_si256(gt, gt)) {
            tail64(b, row, px, n < 4 ? hi : px + 3, py, S + (px - lo) * dS, dS, D);
            if (b->over) return;
            vmv = _mm256_set1_epi64x((int64_t)b->vm);
        }
        Sv = _mm256_add_epi64(Sv, step);
    }
    if (px <= hi) tail64(b, row, px, hi, py, S + (px - lo) * dS, dS, D);
}

static inline AVX2 __attribute__((always_inline)) void row32(struct best *b, const uint16_t *row,
                                                             const uint16_t *end, int64_t lo, int64_t hi,
                                                             int32_t py, uint32_t S, uint32_t dS, uint32_t d)
{
    const __m256i lane = _mm256_set_epi32(7, 6, 5, 4, 3, 2, 1, 0);
    const __m256i dv = _mm256_set1_epi32((int32_t)d), step = _mm256_set1_epi32((int32_t)(8 * dS));
    __m256i Sv =
        _mm256_add_epi32(_mm256_set1_epi32((int32_t)S), _mm256_mullo_epi32(_mm256_set1_epi32((int32_t)dS), lane));
    __m256i vmv = _mm256_set1_epi32((int32_t)(uint32_t)b->vm);
    const __m256i Lv = _mm256_set1_epi32((int32_t)(b->limit > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)b->limit));
    int64_t px = lo;
    for (; px <= hi; px += 8) {
        int64_t n = hi - px + 1;
        if (n < 8 && row + px + 8 > end) break;
        __m256i h = _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)(row + px)));
        __m256i v = _mm256_abs_epi32(_mm256_sub_epi32(Sv, _mm256_mullo_epi32(h, dv))); /* as unsigned */
        if (n < 8) v = _mm256_and_si256(v, _mm256_cmpgt_epi32(_mm256_set1_epi32((int32_t)n), lane));
        __m256i same = _mm256_cmpeq_epi32(_mm256_max_epu32(v, vmv), vmv); /* v <= vm */
        if (_mm256_movemask_epi8(same) != -1) { /* a V above vm: the block's new maximum in the vector */
            __m256i over = _mm256_cmpeq_epi32(_mm256_max_epu32(v, Lv), Lv); /* v <= limit */
            uint32_t lanes[8];
            _mm256_storeu_si256((__m256i *)lanes, v);
            int out = ~_mm256_movemask_ps(_mm256_castsi256_ps(over)) & 0xFF;
            if (out) { /* the first sample above limit: the C scan stops there (vm <= limit before it) */
                int i = __builtin_ctz((unsigned)out);
                b->vm = lanes[i], b->bx = (int32_t)(px + i), b->by = py, b->over = 1;
                return;
            }
            __m256i m = _mm256_max_epu32(v, _mm256_permute2x128_si256(v, v, 1)); /* every lane the max */
            m = _mm256_max_epu32(m, _mm256_shuffle_epi32(m, _MM_SHUFFLE(1, 0, 3, 2)));
            m = _mm256_max_epu32(m, _mm256_shuffle_epi32(m, _MM_SHUFFLE(2, 3, 0, 1)));
            int i = __builtin_ctz((unsigned)_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(v, m))));
            b->vm = lanes[i], b->bx = (int32_t)(px + i), b->by = py; /* where the C scan's last rise is */
            vmv = _mm256_set1_epi32((int32_t)lanes[i]);
        }
        Sv = _mm256_add_epi32(Sv, step);
    }
    if (px <= hi) tail32(b, row, px, hi, py, S + (uint32_t)(px - lo) * dS, dS, d);
}

static int have_avx2(void)
{
    static int known = -1;
    if (known < 0) known = __builtin_cpu_supports("avx2") ? 1 : 0;
    return known;
}

static AVX2 __attribute__((noinline)) int scan(const wm_field *f, const int32_t x[3], const int32_t y[3],
                                               uint64_t limit, uint64_t *vmax, int32_t *wx, int32_t *wy)
{
    const uint16_t *h = f->samples, *end = h + (int64_t)f->width * f->height;
    int64_t A[3], B[3], C[3], z[3], dS = 0, D;
    int32_t ymin = y[0], ymax = y[0];
    struct bound lo_b[3], hi_b[3];
    int n_lo = 0, n_hi = 0, n_level = 0, level[3];
    struct best b = {0, limit, x[0], y[0], 0};
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        z[k] = h[(int64_t)y[k] * f->width + x[k]];
        A[k] = -((int64_t)y[k2] - y[k1]); /* E_k(px, py) = A px + B py + C, as the C scan's */
        B[k] = (int64_t)x[k2] - x[k1];
        C[k] = -(B[k] * y[k1]) - A[k] * x[k1];
        dS += A[k] * z[k];
        if (y[k] < ymin) ymin = y[k];
        if (y[k] > ymax) ymax = y[k];
    }
    D = A[0] * x[0] + B[0] * y[0] + C[0]; /* E_0 at its own corner: the doubled area */
    if (D <= 0 || D >= ((int64_t)1 << 32)) return 0;
    int narrow = f->width <= (1 << 14) && f->height <= (1 << 14) && D < (1 << 15); /* scan32's */
    for (int k = 0; k < 3; k++) {
        int64_t num = B[k] * ymin + C[k]; /* E_k = A x + num >= 0 on the row */
        if (A[k] > 0) /* x >= ceil(-num / A) = floor((A - 1 - num) / A) */
            bound_start(&lo_b[n_lo++], A[k] - 1 - num, -B[k], A[k]);
        else if (A[k] < 0) /* x <= floor(num / -A) */ bound_start(&hi_b[n_hi++], num, B[k], -A[k]);
        else level[n_level++] = k;
    }
    for (int32_t py = ymin; py <= ymax && !b.over; py++) {
        int64_t lo = 0, hi = f->width - 1;
        int empty = 0;
        for (int i = 0; i < n_lo; i++) {
            if (lo_b[i].q > lo) lo = lo_b[i].q;
            bound_step(&lo_b[i]);
        }
        for (int i = 0; i < n_hi; i++) {
            if (hi_b[i].q < hi) hi = hi_b[i].q;
            bound_step(&hi_b[i]);
        }
        for (int i = 0; i < n_level; i++)
            if (B[level[i]] * py + C[level[i]] < 0) empty = 1;
        if (py < ymax) { /* the next row's span (the bounds stepped to it) on its way into the cache */
            int64_t nlo = 0, nhi = f->width - 1;
            for (int i = 0; i < n_lo; i++)
                if (lo_b[i].q > nlo) nlo = lo_b[i].q;
            for (int i = 0; i < n_hi; i++)
                if (hi_b[i].q < nhi) nhi = hi_b[i].q;
            if (nlo <= nhi) { /* offsets, not pointers past the span: those could leave the samples */
                const char *p = (const char *)(h + (int64_t)(py + 1) * f->width + nlo);
                size_t span = (size_t)(nhi - nlo) * sizeof *h, off = 0;
                int i = 0;
                for (; i < PREFETCH_LINES && off < span; i++, off += 64) __builtin_prefetch(p + off);
                if (i < PREFETCH_LINES) __builtin_prefetch(p + span); /* the line of the span's end */
            }
        }
        if (empty || lo > hi) continue;
        const uint16_t *row = h + (int64_t)py * f->width;
        int64_t S = 0;
        for (int k = 0; k < 3; k++) S += (A[k] * lo + B[k] * py + C[k]) * z[k];
        if (narrow) row32(&b, row, end, lo, hi, py, (uint32_t)S, (uint32_t)dS, (uint32_t)D);
        else row64(&b, row, end, lo, hi, py, S, dS, D);
    }
    *vmax = b.vm;
    if (wx) *wx = b.bx;
    if (wy) *wy = b.by;
    return 1;
}
/* The small triangles' scan (tri_error.c's scan32: D < 2^15 on a grid of at most 2^14 a side, V exact
 * modulo 2^32) with each row's samples in 32-bit lanes, 8 a block: most rows are a few samples, so a row
 * is one block, and neither the end of a row nor a new largest V is a branch (each a guess that missed
 * about as often as it held in the C scan's loop).  The spans are scan32's: the rows from the top corner
 * to the middle one between the long edge and the upper short edge, the rest between the long edge and
 * the lower one, each end floor(u / a) stepped row by row as a pointer with its remainder (the carry
 * without a branch too).  Each lane keeps its largest V and the place of its first sample (lanes past
 * the row's end cleared), with no horizontal step a row: at the end the largest of all and the least
 * place holding it, the first sample in row order.  A block with a V above the limit gives its first
 * such lane, where the C scan stops. */
/* The end on the next row; the carry (1: the quotient one more than its step), without a branch. */
static WM_ALWAYS_INLINE uint32_t end_step(struct wm_end32 *e)
{
    int32_t r = e->r + e->dr; /* both below a < 2^15 */
    uint32_t c = r >= e->a;
    e->r = r - (e->a & -(int32_t)c);
    e->p += e->st + (int32_t)c;
    return c;
}

/* The 8 samples from q as 32-bit lanes; at the grid's end none read past its last sample (lanes past it
 * are zero, and outside every span). */
static inline AVX2 __attribute__((always_inline)) __m256i load8(const uint16_t *q, const uint16_t *end)
{
    if (q + 8 <= end) return _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)q));
    uint16_t buf[8] = {0};
    for (int j = 0; j < 8 && q + j < end; j++) buf[j] = q[j];
    return _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)buf));
}

/* The lanes' largest V (each lane's in best) and, when above 0 and at is given, its first sample into *at:
 * the least place (sample number, in place) among the lanes that hold it, a larger place a later sample
 * in row order (no at: a scan whose caller asks for no worst sample, its lanes without places). */
static inline AVX2 __attribute__((always_inline)) uint32_t lanes_first(__m256i best, __m256i place,
                                                                       const uint16_t *h, const uint16_t **at)
{
    __m256i mv = _mm256_max_epi32(best, _mm256_permute2x128_si256(best, best, 1)); /* every lane the max */
    uint32_t vm;
    mv = _mm256_max_epi32(mv, _mm256_shuffle_epi32(mv, _MM_SHUFFLE(1, 0, 3, 2)));
    mv = _mm256_max_epi32(mv, _mm256_shuffle_epi32(mv, _MM_SHUFFLE(2, 3, 0, 1)));
    vm = (uint32_t)_mm256_cvtsi256_si32(mv);
    if (vm && at) {
        __m256i pl = _mm256_blendv_epi8(_mm256_set1_epi32(INT32_MAX), place, _mm256_cmpeq_epi32(best, mv));
        pl = _mm256_min_epi32(pl, _mm256_permute2x128_si256(pl, pl, 1));
        pl = _mm256_min_epi32(pl, _mm256_shuffle_epi32(pl, _MM_SHUFFLE(1, 0, 3, 2)));
        pl = _mm256_min_epi32(pl, _mm256_shuffle_epi32(pl, _MM_SHUFFLE(2, 3, 0, 1)));
        *at = h + _mm256_cvtsi256_si32(pl);
    }
    return vm;
}

/* scan_lanes for a triangle whose box is at most 8 samples wide (most of a fine mesh's: on Jacksboro at
 * 10 m, bench/refine_time.py, the native call 0.88 - 0.95 x scan_lanes' time, MRI 0.91 - 0.93 x): each
 * row of the box one block from the box's left column, its samples inside the closed triangle by the
 * three edge functions (all >= 0: the spans' very samples, no division), the edge functions and S
 * stepped row by row in the lanes; each lane's largest V and first place as scan_lanes keeps them.  S is
 * the triangle's S at the box's top left sample (modulo 2^32, as V is taken). */
static inline AVX2 __attribute__((always_inline)) int box_body(const wm_field *f, const int32_t x[3],
                                                               const int32_t y[3], uint32_t d, int32_t x0,
                                                               uint64_t limit, uint64_t *vmax, int32_t *wx,
                                                               int32_t *wy, const int placed)
{
    const uint16_t *h = f->samples, *end = h + (int64_t)f->width * f->height, *at = NULL;
    int32_t A[3], B[3], t = 0, b = 0, width = f->width, y0, y1;
    uint32_t z[3], dS = 0, dSy = 0, S, lim = limit >> 32 ? 0xFFFFFFFFu : (uint32_t)limit, vm;
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        z[k] = h[y[k] * width + x[k]];
        A[k] = y[k1] - y[k2];
        B[k] = x[k2] - x[k1];
        dS += (uint32_t)A[k] * z[k];
        dSy += (uint32_t)B[k] * z[k];
        if (y[k] < y[t]) t = k;
        if (y[k] > y[b]) b = k;
    }
    y0 = y[t], y1 = y[b];
    S = d * z[t] + dS * (uint32_t)(x0 - x[t]); /* at (x0, y0): S is D z_t at corner t, dS a column on */
    const __m256i Lv = _mm256_set1_epi32((int32_t)(lim > 0x7FFFFFFFu ? 0x7FFFFFFFu : lim));
    const __m256i lane = _mm256_set_epi32(7, 6, 5, 4, 3, 2, 1, 0), dv = _mm256_set1_epi32((int32_t)d);
    const __m256i none = _mm256_set1_epi32(-1), dSyv = _mm256_set1_epi32((int32_t)dSy);
    const __m256i Wv = _mm256_set1_epi32(width);
    __m256i E[3], Bv[3], best = _mm256_setzero_si256(), place = _mm256_setzero_si256();
    __m256i Sv =
        _mm256_add_epi32(_mm256_set1_epi32((int32_t)S), _mm256_mullo_epi32(_mm256_set1_epi32((int32_t)dS), lane));
    __m256i P = _mm256_add_epi32(_mm256_set1_epi32(y0 * width + x0), lane);
    const uint16_t *q = h + y0 * width + x0;
    for (int k = 0; k < 3; k++) { /* E_k = A (px - x_k1) + B (py - y_k1), below 2^29 in size in the box */
        int k1 = wm_k1(k);
        E[k] = _mm256_add_epi32(_mm256_set1_epi32(A[k] * (x0 - x[k1]) + B[k] * (y0 - y[k1])),
                                _mm256_mullo_epi32(_mm256_set1_epi32(A[k]), lane));
        Bv[k] = _mm256_set1_epi32(B[k]);
    }
    for (int32_t py = y0; py <= y1; py++, q += width) {
        __m256i hv = load8(q, end);
        __m256i in = _mm256_cmpgt_epi32(_mm256_or_si256(_mm256_or_si256(E[0], E[1]), E[2]), none); /* all >= 0 */
        __m256i v = _mm256_and_si256(_mm256_abs_epi32(_mm256_sub_epi32(Sv, _mm256_mullo_epi32(hv, dv))), in);
        __m256i over = _mm256_cmpgt_epi32(v, Lv);
        if (!_mm256_testz_si256(over, over)) { /* the first sample above the limit: the C scan stops */
            uint32_t lanes[8];
            int i = __builtin_ctz((unsigned)_mm256_movemask_ps(_mm256_castsi256_ps(over)));
            _mm256_storeu_si256((__m256i *)lanes, v);
            at = q + i;
            vm = lanes[i];
            goto stop;
        }
        if (placed) place = _mm256_blendv_epi8(place, P, _mm256_cmpgt_epi32(v, best));
        best = _mm256_max_epi32(best, v);
        for (int k = 0; k < 3; k++) E[k] = _mm256_add_epi32(E[k], Bv[k]);
        Sv = _mm256_add_epi32(Sv, dSyv);
        P = _mm256_add_epi32(P, Wv);
    }
    vm = lanes_first(best, place, h, placed ? &at : NULL);
stop:
    *vmax = vm;
    wm_place_at(f, at, x, y, wx, wy);
    return 1;
}

/* The scan of scan32's triangles in lanes, the rows' spans as scan32's (its head comment). */
static inline AVX2 __attribute__((always_inline)) int lanes_body(const wm_field *f, const int32_t x[3],
                                                                 const int32_t y[3], uint32_t d, uint64_t limit,
                                                                 uint64_t *vmax, int32_t *wx, int32_t *wy,
                                                                 const int placed)
{
    const uint16_t *h = f->samples, *end = h + (int64_t)f->width * f->height;
    int32_t A[3], B[3], t = 0, b = 0, m, py, lm;
    uint32_t z[3], dS = 0, dSy = 0, Sl, dSl, vm = 0;
    const uint16_t *at = NULL; /* the first sample of the largest V so far (none while V = 0) */
    uint32_t lim = limit >> 32 ? 0xFFFFFFFFu : (uint32_t)limit;
    struct wm_end32 lo, hi;
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        z[k] = h[y[k] * f->width + x[k]];
        A[k] = y[k1] - y[k2];
        B[k] = x[k2] - x[k1];
        if (y[k] < y[t]) t = k;
        if (y[k] >= y[b]) b = k;
    }
    if (t == b) b = wm_k1(t);
    m = 3 - t - b;
    for (int k = 0; k < 3; k++) {
        dS += (uint32_t)A[k] * z[k];
        dSy += (uint32_t)B[k] * z[k];
    }
    const __m256i lane = _mm256_set_epi32(7, 6, 5, 4, 3, 2, 1, 0), dv = _mm256_set1_epi32((int32_t)d);
    const __m256i Ld = _mm256_mullo_epi32(_mm256_set1_epi32((int32_t)dS), lane);
    const __m256i S8 = _mm256_set1_epi32((int32_t)(8 * dS)), eight = _mm256_set1_epi32(8);
    /* V < 2^31: a limit at or above 2^31 - 1 stops no scan */
    const __m256i Lv = _mm256_set1_epi32((int32_t)(lim > 0x7FFFFFFFu ? 0x7FFFFFFFu : lim));
    /* each lane's largest V and the place (sample number) of its first sample: the largest of all is then
     * the lanes' largest, its first sample the least place among the lanes that hold it (a larger place is
     * a later sample in row order) */
    __m256i best = _mm256_setzero_si256(), place = _mm256_setzero_si256();
    /* the span walk is scan32's, written out again (tri_error.c says why): keep the two in step */
    lm = A[m] > 0;
    py = y[t];
    {
        int32_t ks = y[t] == y[m] ? t : b, c = y[t] == y[m] ? m : t;
        int32_t kl = lm ? m : ks, kh = lm ? ks : m, cl = lm ? t : c, ch = lm ? c : t;
        const uint16_t *row = h + py * f->width;
        /* at a corner's row u = a x_c + r0, 0 <= r0 < a: quotient x_c, remainder r0, no division */
        wm_end_at(&lo, row, f->width, x[cl], A[kl] - 1, -B[kl], A[kl]);
        wm_end_at(&hi, row, f->width, x[ch], 0, B[kh], -A[kh]);
        Sl = d * z[t] - dS * (uint32_t)x[t] + (uint32_t)lo.q * dS;
        dSl = dSy + (uint32_t)lo.dq * dS;
    }
    for (int half = 0; half < 2; half++) {
        int32_t last = half == 0 ? (y[m] == y[b] ? y[b] : y[m] - 1) : y[b], rows;
        if (half == 0 && py > last) continue;
        if (half == 1) {
            if (y[m] == y[b]) break;
            if (y[t] != y[m]) {
                const uint16_t *row = h + py * f->width;
                if (lm) {
                    Sl += dSl + (dS & (0u - end_step(&lo)));
                    wm_end_at(&hi, row, f->width, x[m], 0, B[t], -A[t]);
                } else {
                    end_step(&hi);
                    wm_end_at(&lo, row, f->width, x[m], A[t] - 1, -B[t], A[t]);
                    Sl = d * z[m] - dS * (uint32_t)x[m] + (uint32_t)lo.q * dS;
                    dSl = dSy + (uint32_t)lo.dq * dS;
                }
            }
        }
        rows = last - py + 1;
        py = last + 1;
        for (;;) {
            /* the row's samples lo.p .. hi.p (none when n <= 0: every lane cleared); a block's S, the
             * samples left from its first (a lane past them is cleared) and its places stepped in the
             * lanes from block to block */
            int32_t n = (int32_t)(hi.p - lo.p) + 1;
            const uint16_t *q = lo.p;
            __m256i Sv = _mm256_add_epi32(_mm256_set1_epi32((int32_t)Sl), Ld), Nv = _mm256_set1_epi32(n);
            __m256i Pv = _mm256_add_epi32(_mm256_set1_epi32((int32_t)(q - h)), lane);
            do {
                __m256i hv = load8(q, end);
                __m256i v = _mm256_abs_epi32(_mm256_sub_epi32(Sv, _mm256_mullo_epi32(hv, dv))); /* |V| < 2^31 */
                v = _mm256_and_si256(v, _mm256_cmpgt_epi32(Nv, lane));
                __m256i over = _mm256_cmpgt_epi32(v, Lv);
                if (!_mm256_testz_si256(over, over)) { /* the first sample above the limit: the C scan stops */
                    uint32_t lanes[8];
                    int i = __builtin_ctz((unsigned)_mm256_movemask_ps(_mm256_castsi256_ps(over)));
                    _mm256_storeu_si256((__m256i *)lanes, v);
                    vm = lanes[i];
                    at = q + i;
                    goto stop;
                }
                if (placed) /* each lane's first sample of its largest V */
                    place = _mm256_blendv_epi8(place, Pv, _mm256_cmpgt_epi32(v, best));
                best = _mm256_max_epi32(best, v);
                q += 8;
                n -= 8;
                Sv = _mm256_add_epi32(Sv, S8);
                Nv = _mm256_sub_epi32(Nv, eight);
                Pv = _mm256_add_epi32(Pv, eight);
            } while (n > 0);
            if (--rows == 0) break;
            Sl += dSl + (dS & (0u - end_step(&lo)));
            end_step(&hi);
        }
    }
    vm = lanes_first(best, place, h, placed ? &at : NULL);
stop:
    *vmax = vm;
    wm_place_at(f, at, x, y, wx, wy);
    return 1;
}

/* Each of scan_box and scan_lanes twice: with the worst sample's place, and without it for a caller that
 * asks for none (the decimation's candidates, wm_tri_error_upto: the same Vmax and the same stop), whose
 * blocks then keep no place (a compare, a broadcast, an add and a blend a block fewer: the native call
 * 0.985x in the median of the quality benchmark's 52 pairs, bench/refine_time.py).  Each starts on a cache
 * line: where it lands otherwise moves with every change elsewhere in the library, and so its loop's
 * place in the lines the processor fetches (bench/refine_time.py: one such move cost f2 and Box 4-5 %, the
 * median pair 1.3 %). */
static AVX2 __attribute__((noinline, aligned(64))) int scan_box(const wm_field *f, const int32_t x[3],
                                                                const int32_t y[3], uint32_t d, int32_t x0,
                                                                uint64_t limit, uint64_t *vmax, int32_t *wx,
                                                                int32_t *wy)
{
    return box_body(f, x, y, d, x0, limit, vmax, wx, wy, 1);
}

static AVX2 __attribute__((noinline, aligned(64))) int scan_box_max(const wm_field *f, const int32_t x[3],
                                                                    const int32_t y[3], uint32_t d, int32_t x0,
                                                                    uint64_t limit, uint64_t *vmax)
{
    return box_body(f, x, y, d, x0, limit, vmax, NULL, NULL, 0);
}

static AVX2 __attribute__((noinline, aligned(64))) int scan_lanes(const wm_field *f, const int32_t x[3],
                                                                  const int32_t y[3], uint32_t d, uint64_t limit,
                                                                  uint64_t *vmax, int32_t *wx, int32_t *wy)
{
    return lanes_body(f, x, y, d, limit, vmax, wx, wy, 1);
}

static AVX2 __attribute__((noinline, aligned(64))) int scan_lanes_max(const wm_field *f, const int32_t x[3],
                                                                      const int32_t y[3], uint32_t d,
                                                                      uint64_t limit, uint64_t *vmax)
{
    return lanes_body(f, x, y, d, limit, vmax, NULL, NULL, 0);
}

int wm_tri_engine_scan(const wm_field *f, const int32_t x[3], const int32_t y[3], uint64_t limit, uint64_t *vmax,
                       int32_t *wx, int32_t *wy)
{
    if (!enabled || !have_avx2()) return 0;
    if (enabled != 2) {
        /* scan32's triangles in lanes; the others in the blocks on a large grid (mode 1), else the C scan */
        int64_t D =
            ((int64_t)y[1] - y[2]) * ((int64_t)x[0] - x[1]) + ((int64_t)x[2] - x[1]) * ((int64_t)y[0] - y[1]);
        if (f->width > (1 << 14) || f->height > (1 << 14) || D <= 0 || D >= (1 << 15))
            return enabled == 1 && (int64_t)f->width * f->height >= SCAN_MIN_SAMPLES
                       ? scan(f, x, y, limit, vmax, wx, wy)
                       : 0;
        int32_t x0 = x[0] < x[1] ? x[0] : x[1], x1 = x[0] < x[1] ? x[1] : x[0];
        x0 = x[2] < x0 ? x[2] : x0;
        x1 = x[2] > x1 ? x[2] : x1;
        if (wx == NULL && wy == NULL)
            return x1 - x0 < 8 ? scan_box_max(f, x, y, (uint32_t)D, x0, limit, vmax)
                               : scan_lanes_max(f, x, y, (uint32_t)D, limit, vmax);
        if (x1 - x0 < 8) return scan_box(f, x, y, (uint32_t)D, x0, limit, vmax, wx, wy); /* a row a block */
        return scan_lanes(f, x, y, (uint32_t)D, limit, vmax, wx, wy);
    }
    return scan(f, x, y, limit, vmax, wx, wy);
}
#else
int wm_tri_engine_scan(const wm_field *f, const int32_t x[3], const int32_t y[3], uint64_t limit, uint64_t *vmax,
                       int32_t *wx, int32_t *wy)
{
    (void)f, (void)x, (void)y, (void)limit, (void)vmax, (void)wx, (void)wy;
    return 0;
}
#endif
