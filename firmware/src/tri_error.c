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
/* scan_lattice in the native builds; the board's small triangles are its engine's (WM_TRI_ENGINE on a
 * 32-bit CPU: the board, whose firmware RAM has no room for it), and the profile build counts the
 * samples the engine visits (the spans of scan32) */
#if (defined(WM_TRI_ENGINE) && UINTPTR_MAX <= 0xFFFFFFFFu) || WM_PROFILE
#define WM_SCAN_LATTICE 0
#else
#define WM_SCAN_LATTICE 1
#endif
/* upto_normal takes the slope factor after the scan for triangles of D below this; a larger one's
 * scan, which a looser limit would make longer, takes it before (Jacksboro at 10 m, the held-out
 * lidar_dem: each within 0.15 % from 64 to 1024). */
#define WM_SLOPE_LATER_D 256

#if WM_PROFILE
int wm_prof_phase;
uint64_t wm_prof_count[WM_PH_COUNT][WM_PC_COUNT];
#endif

const int32_t *wm_detail_at(const wm_field *f, int32_t m, int32_t x, int32_t y)
{
    int32_t cw = (f->width + (1 << m) - 1) >> m;
    int64_t off = wm_details_offset(f->width, f->height, m);
    return f->details + off + 3 * ((int64_t)(y >> m) * cw + (x >> m));
}

void wm_tri_edges(const int32_t x[3], const int32_t y[3], int64_t A[3], int64_t B[3], int64_t C[3], int32_t box[4])
{
    box[0] = box[1] = x[0], box[2] = box[3] = y[0];
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        A[k] = (int64_t)y[k1] - y[k2];
        B[k] = (int64_t)x[k2] - x[k1];
        C[k] = -(B[k] * y[k1]) - A[k] * x[k1];
        if (x[k] < box[0]) box[0] = x[k];
        if (x[k] > box[1]) box[1] = x[k];
        if (y[k] < box[2]) box[2] = y[k];
        if (y[k] > box[3]) box[3] = y[k];
    }
}

int wm_row_span(const int64_t A[3], const int64_t B[3], const int64_t C[3], int32_t py, int64_t *lo, int64_t *hi)
{
    for (int k = 0; k < 3; k++) {
        int64_t num = B[k] * py + C[k]; /* E_k = A x + num >= 0 */
        if (A[k] > 0) {
            int64_t l = wm_ceil_div(-num, A[k]);
            if (l > *lo) *lo = l;
        } else if (A[k] < 0) {
            int64_t r = wm_floor_div(num, -A[k]);
            if (r < *hi) *hi = r;
        } else if (num < 0) {
            return 0;
        }
    }
    return *lo <= *hi;
}

/* The edge functions and heights of a triangle, for the scans. */
struct tri_setup {
    int64_t z[3], A[3], B[3], C[3], dS;
    int32_t xmin, xmax, ymin, ymax;
};

static void setup(const wm_field *f, const int32_t x[3], const int32_t y[3], struct tri_setup *t)
{
    t->ymin = t->ymax = y[0];
    t->xmin = t->xmax = x[0];
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        t->z[k] = f->samples[(int64_t)y[k] * f->width + x[k]];
        /* E_k(px, py) = (x_k2 - x_k1)(py - y_k1) - (y_k2 - y_k1)(px - x_k1) = A px + B py + C */
        t->A[k] = -((int64_t)y[k2] - y[k1]);
        t->B[k] = (int64_t)x[k2] - x[k1];
        t->C[k] = -(t->B[k] * y[k1]) - t->A[k] * x[k1];
        if (y[k] < t->ymin) t->ymin = y[k];
        if (y[k] > t->ymax) t->ymax = y[k];
        if (x[k] < t->xmin) t->xmin = x[k];
        if (x[k] > t->xmax) t->xmax = x[k];
    }
    t->dS = t->A[0] * t->z[0] + t->A[1] * t->z[1] + t->A[2] * t->z[2];
}

/* One row of the 32-bit path (scan): the largest V = |S - d h| over the samples [q, end) with S
 * growing by dS per sample, above vm, and where it is first reached (*at; untouched when no sample
 * beats vm); it stops at the first sample above limit.  A function of its own so that the few values of
 * the loop stay in registers on the soft CPU.  Without the absolute value: for |u| < 2^31 and
 * vm < 2^31, |u| > vm iff u + vm > 2 vm modulo 2^32 (u in [-vm, vm] maps to [0, 2 vm], the rest of
 * (-2^31, 2^31) above it), so the loop steps T = S + vm and compares T - d h with 2 vm. */
WM_NOINLINE_32 static uint32_t row_max32(const uint16_t *q, const uint16_t *end, uint32_t S, uint32_t dS,
                                         uint32_t d, uint32_t vm, uint32_t limit, const uint16_t **at)
{
    uint32_t T = S + vm, twice = 2 * vm;
    for (; q < end; q++, T += dS) {
        uint32_t w = T - d * *q;
        if (w > twice) {
            uint32_t u = w - vm, v = u >> 31 ? 0u - u : u;
            T += v - vm;
            vm = v;
            twice = 2 * v;
            *at = q;
            if (vm > limit) break;
        }
    }
    return vm;
}

/* Scans the closed triangle row by row; returns Vmax and the first sample reaching it, or, as soon as
 * a sample's V exceeds limit, that V (the caller only learns that E(T) is above its bound).  64-bit
 * arithmetic (the span of each row from 32-bit divisions on grids of at most 2^14 a side, where every
 * E_k fits 30 bits); scan32 below is the same scan for small triangles.  Out of line: the few large
 * triangles take it, and inlined in scan_any it cost every scan32 registers and saves. */
WM_NEVER_INLINE WM_ENGINE_FALLBACK static uint64_t scan(const wm_field *f, const int32_t x[3], const int32_t y[3],
                                                        int64_t D, uint64_t limit, int32_t *wx, int32_t *wy)
{
    const uint16_t *h = f->samples;
    struct tri_setup t;
    uint64_t vmax = 0;
    int32_t bx = x[0], by = y[0];
    int small = f->width <= (1 << 14) && f->height <= (1 << 14);
    setup(f, x, y, &t);
    for (int32_t py = t.ymin; py <= t.ymax; py++) {
        int64_t lo = t.xmin, hi = t.xmax, S = 0;
        const uint16_t *row = h + (int64_t)py * f->width;
        int empty = 0;
        for (int k = 0; k < 3; k++) {
            int64_t num = t.B[k] * py + t.C[k]; /* E_k = A x + num >= 0 */
            if (t.A[k] > 0) {
                int64_t l = small ? wm_ceil_div32((int32_t)-num, (int32_t)t.A[k]) : wm_ceil_div(-num, t.A[k]);
                if (l > lo) lo = l;
            } else if (t.A[k] < 0) {
                int64_t r = small ? wm_floor_div32((int32_t)num, (int32_t)-t.A[k]) : wm_floor_div(num, -t.A[k]);
                if (r < hi) hi = r;
            } else if (num < 0) {
                empty = 1;
            }
        }
        if (empty || lo > hi) continue;
        for (int k = 0; k < 3; k++) S += (t.A[k] * lo + t.B[k] * py + t.C[k]) * t.z[k];
        for (int64_t px = lo; px <= hi; px++, S += t.dS) {
            int64_t v = S - D * (int64_t)row[px];
            uint64_t av = (uint64_t)(v < 0 ? -v : v);
            if (av > vmax) {
                vmax = av;
                bx = (int32_t)px;
                by = py;
                if (av > limit) break;
            }
        }
        WM_PROF_ADD(WM_PC_ROWS, 1);
        WM_PROF_ADD(WM_PC_SAMPLES, vmax > limit ? bx - lo + 1 : hi - lo + 1);
        if (vmax > limit) break;
    }
    if (wx) *wx = bx;
    if (wy) *wy = by;
    return vmax;
}

/* row_max32 without the stop: the largest V of the row (the rows of scan32; a row whose V goes above
 * the limit is scanned again by row_max32 for the first sample that does, its stop). */
WM_NOINLINE_32 static uint32_t row_max32_all(const uint16_t *q, const uint16_t *end, uint32_t S, uint32_t dS,
                                             uint32_t d, uint32_t vm, const uint16_t **at)
{
    /* with U = S + vm + 1: ~(S + vm - d h) = d h - U, and x > 2 vm iff ~x < ~(2 vm) (no copy of U a
     * sample for the subtraction) */
    uint32_t U = S + vm + 1, nt = ~(2 * vm);
    for (; q < end; q++, U += dS) {
        uint32_t w = d * *q - U;
        if (w < nt) {
            uint32_t u = ~w - vm, v = u >> 31 ? 0u - u : u;
            U += v - vm;
            vm = v;
            nt = ~(2 * v);
            *at = q;
        }
    }
    return vm;
}

/* The end on the next row; 1 when the remainder carried (the quotient one more than its step). */
static WM_ALWAYS_INLINE int end_step(struct wm_end32 *e)
{
    e->p += e->st;
    e->r += e->dr;
    if (e->r < e->a) return 0;
    e->r -= e->a;
    e->p++;
    return 1;
}

/* scan in 32-bit arithmetic, exact on grids of at most 2^14 a side for D < 2^15: every E_k and its row
 * part B y + C fit 30 bits, and S = sum E_k z_k <= D (2^16 - 1) and D h lie in [0, 2^31) at every
 * sample of a span, so S - D h taken modulo 2^32 (unsigned: no overflow) is V with its sign.  Most
 * triangles of a board job and of a fine mesh take this path.
 *
 * The rows from the top corner to the middle one (by y) lie between the long edge (top to bottom) and
 * the upper short edge, the rest between the long edge and the lower short edge: on each row the span
 * is bounded by those two edges alone (the third one's half-plane holds the whole row of the triangle,
 * so its bound, like the bounding box's, never binds, rounded or not).  Each bound is floor(u / a):
 * the left end ceil(-E / A) for A > 0 with u = A - 1 - E(0, py), a = A, the right end floor(E / -A)
 * for A < 0 with u = E(0, py), a = -A; u moves by the same step every row, so the quotient and its
 * remainder are stepped (a carry when the remainder reaches a) instead of divided: two divisions an
 * edge (the long edge's carried from the upper half to the lower), exactly the spans of a division per
 * edge and row.
 *
 * host_scan.c's scan_lanes walks the same spans and writes the walk out again (the set-up, the top row's
 * ends, the switch to the lower half); keep the two in step.  Shared through a struct of the ends and
 * always-inlined start and lower-half functions, the walk cost this function instructions (register
 * allocation and spills in its set-up; bench/refiner_instructions.py, callgrind, against the copies:
 * JACKSBORO --zeta 10 +0.05 % to +0.5 % in three forms, ball.npy --decimate 2 +0.2 %), so each keeps
 * its copy. */
WM_NEVER_INLINE WM_ENGINE_FALLBACK static uint64_t scan32(const wm_field *f, const int32_t x[3],
                                                          const int32_t y[3], uint32_t d, uint64_t limit,
                                                          int32_t *wx, int32_t *wy)
{
    const uint16_t *h = f->samples;
    int32_t A[3], B[3], t = 0, b = 0, m, py, lm;
    uint32_t z[3], dS = 0, dSy = 0, Sl = 0, dSl = 0, vm = 0;
    const uint16_t *at = NULL; /* the first sample of the largest V so far (none while V = 0) */
    uint32_t lim = limit >> 32 ? 0xFFFFFFFFu : (uint32_t)limit; /* the same stops: V < 2^31 */
    struct wm_end32 lo, hi; /* the left and right ends */
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        z[k] = h[y[k] * f->width + x[k]];
        A[k] = y[k1] - y[k2]; /* E_k(px, py) = A (px - x_k1) + B (py - y_k1), as setup's */
        B[k] = x[k2] - x[k1];
        if (y[k] < y[t]) t = k;
        if (y[k] >= y[b]) b = k;
    }
    if (t == b) b = wm_k1(t); /* all on one row: D = 0, not called */
    m = 3 - t - b;
    /* S = dS px + dSy py + S0 modulo 2^32 (V is taken modulo 2^32 anyway): one product a row */
    for (int k = 0; k < 3; k++) {
        dS += (uint32_t)A[k] * z[k];
        dSy += (uint32_t)B[k] * z[k];
    }
    /* The long edge (opposite the middle corner) bounds every row on one side, the left when A > 0;
     * the upper short edge (opposite the bottom corner) the other side down to the middle corner's
     * row, the lower one (opposite the top corner) from there.  Each bound is floor(u / a): the left
     * end ceil(-E / A) for A > 0 with u = A - 1 - E(0, py), a = A, the right end floor(E / -A) for A < 0
     * with u = E(0, py), a = -A; u moves by the same step every row (-B, B).  At the row of a corner c
     * on the edge, E(0, py) = -A x_c, and S(0, py) = D z_c - dS x_c (S at c is D z_c). */
    lm = A[m] > 0;
    py = y[t];
    {
        /* both ends on the top row: the long edge's from the top corner, the upper short edge's from
         * there too, or with a level upper edge (no upper half) the lower one's from the middle corner */
        int32_t ks = y[t] == y[m] ? t : b, c = y[t] == y[m] ? m : t;
        int32_t kl = lm ? m : ks, kh = lm ? ks : m, cl = lm ? t : c, ch = lm ? c : t;
        const uint16_t *row = h + py * f->width;
        wm_end_start(&lo, row, f->width, A[kl] - 1 + A[kl] * x[cl], -B[kl], A[kl]);
        wm_end_start(&hi, row, f->width, -A[kh] * x[ch], B[kh], -A[kh]);
        Sl = d * z[t] - dS * (uint32_t)x[t] + (uint32_t)lo.q * dS;
        dSl = dSy + (uint32_t)lo.dq * dS;
    }
    for (int half = 0; half < 2; half++) {
        int32_t last, rows;
        last = half == 0 ? (y[m] == y[b] ? y[b] : y[m] - 1) : y[b];
        if (half == 0 && py > last) continue; /* a level upper edge: no upper half */
        if (half == 1) {
            if (y[m] == y[b]) break; /* a level lower edge: no lower half */
            if (y[t] != y[m]) { /* after the upper half: the long edge's end a row on, the lower short
                                 * edge's from the middle corner */
                const uint16_t *row = h + py * f->width;
                if (lm) {
                    Sl += dSl + (end_step(&lo) ? dS : 0);
                    wm_end_start(&hi, row, f->width, -A[t] * x[m], B[t], -A[t]);
                } else {
                    end_step(&hi);
                    wm_end_start(&lo, row, f->width, A[t] - 1 + A[t] * x[m], -B[t], A[t]);
                    Sl = d * z[m] - dS * (uint32_t)x[m] + (uint32_t)lo.q * dS;
                    dSl = dSy + (uint32_t)lo.dq * dS;
                }
            }
        }
        rows = last - py + 1;
        py = last + 1;
        /* Every row lies within the triangle's rows, and its ends within [x_min - 1, x_max + 1] (a row
         * without a sample has lo = hi + 1 within [x_min, x_max]; a corner's row holds the corner): in
         * the samples' array (no pointer before its start or past its end is formed). */
        for (;;) {
            WM_ASSERT(hi.p + 1 >= h && lo.p <= h + (int64_t)f->width * f->height);
            if (lo.p <= hi.p) {
                vm = row_max32_all(lo.p, hi.p + 1, Sl, dS, d, vm, &at);
                /* above the limit: the row again, for its first sample above it (any V of the row
                 * above the limit is above the V_max before the row, so from 0 the same stop) */
                if (vm > lim) vm = row_max32(lo.p, hi.p + 1, Sl, dS, d, 0, lim, &at);
                WM_PROF_ADD(WM_PC_ROWS, 1);
                WM_PROF_ADD(WM_PC_SAMPLES, vm > lim ? at - lo.p + 1 : hi.p - lo.p + 1);
                if (vm > lim) goto done;
            }
            if (--rows == 0) break;
            Sl += dSl + (end_step(&lo) ? dS : 0);
            end_step(&hi);
        }
    }
done:
    /* the sample's place from its address, once (not at each row that raised V), when asked */
    if (wx == NULL && wy == NULL) return vm;
    wm_place_at(f, at, x, y, wx, wy);
    return vm;
}

/* The samples of a small triangle (scan_tiny) in row order, at most three: each one's place and
 * V = |S - d h| (S = sum E_k z_k there). */
struct tiny {
    int32_t n, x[3], y[3];
    uint32_t v[3];
};

static WM_ALWAYS_INLINE void tiny_add(struct tiny *s, const wm_field *f, int32_t px, int32_t py, uint32_t S,
                                      uint32_t d)
{
    uint32_t dh = d * f->samples[py * f->width + px];
    int32_t i = s->n++;
    for (; i > 0 && (s->y[i - 1] > py || (s->y[i - 1] == py && s->x[i - 1] > px)); i--) {
        s->x[i] = s->x[i - 1];
        s->y[i] = s->y[i - 1];
        s->v[i] = s->v[i - 1];
    }
    s->x[i] = px;
    s->y[i] = py;
    s->v[i] = S > dh ? S - dh : dh - S;
}

/* The points j / g of the way along the edge a -> b (g = 2, 3, 4: a constant once inlined), whose
 * coordinate differences are multiples of g, for j = 1 .. g - 1: E_a = (d / g) (g - j), E_b = (d / g) j. */
static WM_ALWAYS_INLINE void tiny_edge(struct tiny *s, const wm_field *f, const int32_t x[3], const int32_t y[3],
                                       const uint32_t z[3], int a, uint32_t d, int32_t g)
{
    int b = wm_k1(a);
    int32_t sx = (x[b] - x[a]) / g, sy = (y[b] - y[a]) / g;
    for (int32_t j = 1; j < g; j++)
        tiny_add(s, f, x[a] + j * sx, y[a] + j * sy,
                 d / (uint32_t)g * ((uint32_t)(g - j) * z[a] + (uint32_t)j * z[b]), d);
}

/* E(T)'s scan of a triangle of D <= 4, without the scan's set-up.  By Pick (D = 2I + B - 2, B >= 3; an
 * edge's gcd divides D) its samples besides the corners, with their edge functions:
 *   D = 1: none;
 *   D = 2: the middle of its one edge whose coordinate differences are both even (gcds 2, 1, 1);
 *   D = 3: the centroid (E = 1, 1, 1) when it is a sample (I = 1), else the thirds of its one edge whose
 *          differences are multiples of 3 (gcds 3, 1, 1);
 *   D = 4: with three even edges their middles (gcds 2, 2, 2); with one, a -> b opposite c, its quarters
 *          when its differences are multiples of 4 (gcds 4, 1, 1), else its middle and
 *          (a + b + 2 c) / 4 (E_a = E_b = 1, E_c = 2: I = 1; gcds 2, 1, 1).
 * V is 0 at a corner (S = D z_k).  The samples in row order, each V above the largest so far taking its
 * place, the first above the limit stopping: the scan's Vmax and sample, (x[0], y[0]) for Vmax = 0.
 * Checked builds compare it with the scan (scan_any). */
WM_NEVER_INLINE static uint64_t scan_tiny(const wm_field *f, const int32_t x[3], const int32_t y[3], int32_t d,
                                          uint64_t limit, int32_t *wx, int32_t *wy)
{
    const uint16_t *h = f->samples;
    struct tiny s;
    uint32_t z[3], vm = 0;
    int32_t bx = x[0], by = y[0];
    int c = 0, n_even = 0; /* the edges c -> c + 1 whose differences are both even */
    s.n = 0;
    if (d > 1) {
        for (int k = 0; k < 3; k++) {
            int k1 = wm_k1(k);
            z[k] = h[y[k] * f->width + x[k]];
            if ((((x[k1] - x[k]) | (y[k1] - y[k])) & 1) == 0) c = k, n_even++;
        }
        if (d == 2) {
            tiny_edge(&s, f, x, y, z, c, 2, 2);
        } else if (d == 3) {
            int32_t sx = x[0] + x[1] + x[2], sy = y[0] + y[1] + y[2];
            if (sx % 3 == 0 && sy % 3 == 0) {
                tiny_add(&s, f, sx / 3, sy / 3, z[0] + z[1] + z[2], 3);
            } else {
                for (c = 0; c < 2; c++)
                    if ((x[wm_k1(c)] - x[c]) % 3 == 0 && (y[wm_k1(c)] - y[c]) % 3 == 0) break;
                tiny_edge(&s, f, x, y, z, c, 3, 3);
            }
        } else if (n_even == 3) {
            for (c = 0; c < 3; c++) tiny_edge(&s, f, x, y, z, c, 4, 2);
        } else if ((((x[wm_k1(c)] - x[c]) | (y[wm_k1(c)] - y[c])) & 3) == 0) {
            tiny_edge(&s, f, x, y, z, c, 4, 4);
        } else {
            int b = wm_k1(c), o = wm_k2(c);
            tiny_edge(&s, f, x, y, z, c, 4, 2);
            tiny_add(&s, f, (x[c] + x[b] + 2 * x[o]) / 4, (y[c] + y[b] + 2 * y[o]) / 4, z[c] + z[b] + 2 * z[o], 4);
        }
    }
    WM_PROF_ADD(WM_PC_SAMPLES, s.n);
    for (int32_t i = 0; i < s.n; i++)
        if (s.v[i] > vm) {
            vm = s.v[i];
            bx = s.x[i];
            by = s.y[i];
            if (vm > limit) break;
        }
    if (wx) *wx = bx;
    if (wy) *wy = by;
    return vm;
}

/* scan_tiny of a triangle of D = 2 (some three fifths of its calls on Jacksboro / 4), apart: its one
 * sample besides the corners, the middle of its one edge a -> b whose coordinate differences are both
 * even, V = |z_a + z_b - 2 h| there, Vmax 0 at corner 0 (its limit needs no test: one sample).  Two
 * corners' heights, not three, and no registers to save (on the board scan_tiny's saves and restores
 * of twelve took some 50 cycles a call).  Checked builds compare it with the scan (scan_any). */
WM_NEVER_INLINE static uint64_t scan_two(const wm_field *f, const int32_t x[3], const int32_t y[3], int32_t *wx,
                                         int32_t *wy)
{
    const uint16_t *h = f->samples;
    int32_t W = f->width, a = 0, b = 1, mx, my;
    uint32_t s, dh, v;
    if (((x[1] - x[0]) | (y[1] - y[0])) & 1) {
        a = 1, b = 2;
        if (((x[2] - x[1]) | (y[2] - y[1])) & 1) a = 2, b = 0;
    }
    mx = (x[a] + x[b]) >> 1; /* the sums even, the coordinates not negative */
    my = (y[a] + y[b]) >> 1;
    s = (uint32_t)h[y[a] * W + x[a]] + h[y[b] * W + x[b]];
    dh = 2u * h[my * W + mx];
    v = s > dh ? s - dh : dh - s;
    if (v == 0) mx = x[0], my = y[0];
    if (wx) *wx = mx;
    if (wy) *wy = my;
    return v;
}

#if WM_SCAN_LATTICE
/* The largest D of the triangles scan_lattice takes (the ten pairs of bench/refiner_instructions.py at 8,
 * 12, 16, 20: 0.982, 0.977, 0.975, 0.976 of their instructions with scan32). */
#define WM_LATTICE_D 16

/* E(T)'s scan of a triangle of 4 < d <= WM_LATTICE_D without its rows.  Name the corners o, j, i
 * (counter-clockwise) so that the edge v = p_j - p_o is primitive (coprime coordinates: no sample inside
 * it), with u = p_i - p_o.  A sample p has edge functions e_i, e_j (those vanishing on the edges opposite
 * p_i, p_j) with p = p_o + (e_i u + e_j v) / d, and the (e_i, e_j) of the grid's samples, v being
 * primitive, are those with e_j = c e_i mod d, c = -cross(u, w') mod d for any w' with cross(v, w') = 1
 * (w' = (-v_y, 0) or (0, v_x) for an edge with a coordinate +-1, most; else from Euclid's extended
 * algorithm).  The triangle's samples are those with e_i + e_j <= d: one step for each e_i = 1 .. d - 1,
 * the sample moving by w = (u + c v) / d (an integer vector), less v where e_j wraps past d, and S by the
 * same combination of the corners' heights (the corners, V = 0, left out).  They do not come in row
 * order, but a sample's row order is its offset in the grid: the answer is the largest V at the smallest
 * offset, or, when some V is above the limit, that of the smallest offset among those (the scan stops at
 * the first such sample in row order, with its V); (x[0], y[0]) for Vmax = 0: scan32's Vmax and sample,
 * in its 32-bit arithmetic (d < 2^15 on grids of at most 2^14 a side).  0 (the caller scans) when no edge
 * is primitive: a prime divides every edge's coordinates (d a multiple of its square: 8, 9, 12, 16).
 * Checked builds compare it with the scan (scan_any). */
WM_NEVER_INLINE static int scan_lattice(const wm_field *f, const int32_t x[3], const int32_t y[3], int32_t d,
                                        uint64_t limit, uint64_t *vmax, int32_t *wx, int32_t *wy)
{
    const uint16_t *h = f->samples;
    int32_t W = f->width, o, j, i, vx = 0, vy = 0, ux, uy, cr = 0, c, gx, gy, ej = 0, off, offw, offv;
    int32_t boff = INT32_MAX, ooff = INT32_MAX; /* the largest V's offset, the first above the limit */
    uint32_t zo, si, sj, lim = limit >> 32 ? 0xFFFFFFFFu : (uint32_t)limit, vm = 0, over = 0, S, dSw, dSv;
    for (o = 0; o < 3; o++) { /* cr = cross(u, w') */
        j = wm_k1(o), i = wm_k2(o);
        vx = x[j] - x[o], vy = y[j] - y[o];
        if (vy == 1 || vy == -1) {
            cr = (y[i] - y[o]) * vy;
            break;
        }
        if (vx == 1 || vx == -1) {
            cr = (x[i] - x[o]) * vx;
            break;
        }
    }
    if (o == 3) {
        for (o = 0; o < 3; o++) {
            int32_t a, b, s0 = 1, s1 = 0, t0 = 0, t1 = 1; /* s0 v_x + t0 v_y = a, the gcd up to its sign */
            j = wm_k1(o), i = wm_k2(o);
            vx = a = x[j] - x[o], vy = b = y[j] - y[o];
            if (((a | b) & 1) == 0) continue;
            while (b != 0) {
                int32_t q = a / b, r = a - q * b, ns = s0 - q * s1, nt = t0 - q * t1;
                a = b, b = r, s0 = s1, s1 = ns, t0 = t1, t1 = nt;
            }
            if (a == 1 || a == -1) { /* w' = (-a t0, a s0) */
                cr = (int32_t)((((int64_t)(x[i] - x[o]) * s0 + (int64_t)(y[i] - y[o]) * t0) * a) % d);
                break;
            }
        }
        if (o == 3) return 0;
    }
    ux = x[i] - x[o], uy = y[i] - y[o];
    c = -(cr % d);
    if (c < 0) c += d;
    gx = (ux + c * vx) / d; /* exact */
    gy = (uy + c * vy) / d;
    WM_ASSERT(gx * d == ux + c * vx && gy * d == uy + c * vy);
    off = y[o] * W + x[o], offw = gy * W + gx, offv = vy * W + vx;
    zo = h[off], si = h[y[i] * W + x[i]] - zo, sj = h[y[j] * W + x[j]] - zo;
    S = (uint32_t)d * zo; /* e_o z_o + e_i z_i + e_j z_j modulo 2^32, e_o = d - e_i - e_j */
    dSw = si + (uint32_t)c * sj;
    dSv = (uint32_t)d * sj;
    for (int32_t ei = 1; ei < d; ei++) {
        off += offw;
        S += dSw;
        ej += c;
        if (ej >= d) {
            ej -= d;
            off -= offv;
            S -= dSv;
        }
        if (ei + ej <= d) {
            uint32_t dh = (uint32_t)d * h[off], v = S > dh ? S - dh : dh - S;
            if (v > vm || (v == vm && off < boff)) {
                vm = v;
                boff = off;
            }
            if (v > lim && off < ooff) {
                ooff = off;
                over = v;
            }
        }
    }
    if (ooff != INT32_MAX) vm = over, boff = ooff;
    *vmax = vm;
    if (vm == 0) {
        if (wx) *wx = x[0];
        if (wy) *wy = y[0];
    } else if (wx || wy) {
        int32_t py = boff / W;
        if (wx) *wx = boff - py * W;
        if (wy) *wy = py;
    }
    return 1;
}
#endif

/* The scan that fits the triangle (the same result either way).  The board's refiner (WM_TRI_ENGINE)
 * hands it to the FPGA's triangle error engine, which returns the same Vmax and sample; the holes
 * mask's cover test (holes.c) has run before, on the CPU.  A triangle of D = 1 has no sample but its
 * corners (Vmax 0 at corner 0, answered here without scan_tiny's call: a quarter of the scans on
 * Jacksboro / 4), one of D = 2 takes scan_two, one of D = 3 or 4 scan_tiny, one of D <= WM_LATTICE_D
 * scan_lattice in the native builds (where the hook declines), which inline it in each measure (out of
 * line, its call cost 1.5 % of the refiner's instructions; the board's is as before). */
#if WM_SCAN_LATTICE
WM_ALWAYS_INLINE
#endif
static uint64_t scan_any(const wm_field *f, const int32_t x[3], const int32_t y[3], int64_t D, uint64_t limit,
                         int32_t *wx, int32_t *wy)
{
    WM_PROF_ADD(WM_PC_SCANS, 1);
    if (D <= 4) {
#if WM_CHECK
        int32_t cx, cy, tx, ty;
        uint64_t v = scan(f, x, y, D, limit, &cx, &cy), t = scan_tiny(f, x, y, (int32_t)D, limit, &tx, &ty);
        WM_ASSERT(v == t && cx == tx && cy == ty);
        if (D == 2) {
            t = scan_two(f, x, y, &tx, &ty);
            WM_ASSERT(v == t && cx == tx && cy == ty);
        }
        WM_ASSERT(D != 1 || (v == 0 && cx == x[0] && cy == y[0])); /* the shortcut below */
#endif
        if (D == 1) { /* no sample but the corners (Pick: I = 0, B = 3): scan_tiny's answer without its call */
            if (wx) *wx = x[0];
            if (wy) *wy = y[0];
            return 0;
        }
        if (D == 2) return scan_two(f, x, y, wx, wy);
        return scan_tiny(f, x, y, (int32_t)D, limit, wx, wy);
    }
#ifdef WM_TRI_ENGINE
    uint64_t v;
    if (wm_tri_engine_scan(f, x, y, limit, &v, wx, wy)) return v;
#endif
#if WM_SCAN_LATTICE
    if (D <= WM_LATTICE_D && f->width <= (1 << 14) && f->height <= (1 << 14)) {
        uint64_t lv;
#if WM_CHECK
        int32_t cx, cy, tx, ty;
        uint64_t sv = scan(f, x, y, D, limit, &cx, &cy);
        if (scan_lattice(f, x, y, (int32_t)D, limit, &lv, &tx, &ty)) WM_ASSERT(lv == sv && cx == tx && cy == ty);
#endif
        if (scan_lattice(f, x, y, (int32_t)D, limit, &lv, wx, wy)) return lv;
    }
#endif
    if (f->width <= (1 << 14) && f->height <= (1 << 14) && D < (1 << 15))
        return scan32(f, x, y, (uint32_t)D, limit, wx, wy);
    return scan(f, x, y, D, limit, wx, wy);
}

/* The plane's gradient numerators Na, Nb (the file's head comment) from the corner samples. */
static WM_ALWAYS_INLINE void gradient(const wm_field *f, const int32_t x[3], const int32_t y[3], int64_t *Na,
                                      int64_t *Nb)
{
    int64_t z0 = f->samples[(int64_t)y[0] * f->width + x[0]];
    int64_t dz1 = (int64_t)f->samples[(int64_t)y[1] * f->width + x[1]] - z0;
    int64_t dz2 = (int64_t)f->samples[(int64_t)y[2] * f->width + x[2]] - z0;
    *Na = dz1 * ((int64_t)y[2] - y[0]) - dz2 * ((int64_t)y[1] - y[0]);
    *Nb = ((int64_t)x[1] - x[0]) * dz2 - ((int64_t)x[2] - x[0]) * dz1;
}

/* slope_square with the numerators at hand (have: Na, Nb are the triangle's; else they are worked out). */
static WM_ALWAYS_INLINE uint64_t slope_square_n(const wm_field *f, const wm_params *p, const int32_t x[3],
                                                const int32_t y[3], int64_t D, int have, int64_t Na, int64_t Nb,
                                                int *k, uint32_t *root)
{
    uint64_t ga, gb;
    uint32_t sm;
    int32_t se;
    uint64_t one;
    WM_PROF_ADD(WM_PC_SLOPES, 1);
    *root = 0;
#ifdef WM_SLOPE_ENGINE
    if (wm_tri_engine_slope(f, p, x, y, root, k)) return 0;
#endif
    if (!have) gradient(f, x, y, &Na, &Nb);
    wm_slope_scale(p, 0, &sm, &se);
    ga = wm_frac_mul((uint64_t)(Na < 0 ? -Na : Na), (uint64_t)D, sm, se, 16, GCAP);
    wm_slope_scale(p, 1, &sm, &se);
    gb = wm_frac_mul((uint64_t)(Nb < 0 ? -Nb : Nb), (uint64_t)D, sm, se, 16, GCAP);
    /* steep slopes are shifted right by k first (ga, gb keep >= 30 significant bits), and the root
     * shifted back */
    *k = 0;
    if ((ga | gb) >> 31) /* most slopes are below it: no shift */
        while ((ga >> *k) >= ((uint64_t)1 << 31) || (gb >> *k) >= ((uint64_t)1 << 31)) (*k)++;
    one = 2 * *k >= 33 ? 0 : ((uint64_t)1 << 32) >> (2 * *k);
    ga >>= *k;
    gb >>= *k; /* both below 2^31 now: 32-bit squares (a multiply and a multiply-high each on rv32) */
    return one + (uint64_t)(uint32_t)ga * (uint32_t)ga + (uint64_t)(uint32_t)gb * (uint32_t)gb; /* < 2^64 */
}

/* sqrt(1 + g^2) in Q16.16, rounded down (the file's head comment), for the normal metric, before its
 * root: r = floor(sqrt(X)) << *k for the X returned.  The board's refiner (WM_SLOPE_ENGINE) hands it to
 * the FPGA's slope unit, which returns floor(sqrt(X)) itself: then *root is that (>= 1) and X is not
 * returned (0); else *root is 0. */
static uint64_t slope_square(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                             int64_t D, int *k, uint32_t *root)
{
    return slope_square_n(f, p, x, y, D, 0, 0, 0, k, root);
}

/* The slope factor r of the triangle, from *kept when a measure of the same triangle left it there
 * (non-zero: r >= 2^16), else computed and left there (kept may be NULL). */
static uint64_t slope_factor(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                             int64_t D, uint64_t *kept)
{
    int k;
    uint32_t root;
    uint64_t r;
    if (kept && *kept) return *kept;
    r = slope_square(f, p, x, y, D, &k, &root);
    r = (root ? root : wm_isqrt64(r)) << k;
    if (kept) *kept = r;
    return r;
}

/* ev = ceil(2^16 vmax / D), saturated at 2^32 - 1: E(T) in the vertical metric. */
static uint32_t vertical(uint64_t vmax, int64_t D)
{
    uint64_t ev;
    if (!WM_SPLIT_DIV && vmax == 0) return 0; /* flat (every D = 1): the board skips its divider call */
    ev = wm_ceil_q16_div(vmax, (uint64_t)D); /* vmax < 2^47 */
    return ev > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)ev;
}

/* vertical(vmax, D) for a triangle of D <= 4 (scan_tiny's) without a division: D = 1, 2, 4 a shift, D = 3
 * the quotient by 3 a multiply-high by ceil(2^33 / 3) (exact below 2^32; vmax < 2^16 D here) and
 * ceil(2^16 r / 3) for its remainder r from a table.  Only where the division would not run beside
 * the slope unit (wm_tri_error_over's triangles within zeta: normal_beside's division overlaps the
 * unit's work, which the CPU would wait for instead). */
static WM_ALWAYS_INLINE uint32_t vertical_tiny(uint64_t vmax, int32_t D)
{
    uint32_t v = (uint32_t)vmax, q, r;
    uint64_t ev;
    WM_ASSERT(D >= 1 && D <= 4 && vmax >> 32 == 0);
    if (D == 3) {
        q = (uint32_t)(((uint64_t)v * 0xAAAAAAABu) >> 33);
        r = v - 3u * q;
        ev = ((uint64_t)q << 16) + (r == 0 ? 0u : (r == 1 ? 21846u : 43691u));
    } else {
        ev = (uint64_t)v << (D == 4 ? 14 : (D == 2 ? 15 : 16));
    }
    WM_ASSERT(ev == wm_ceil_q16_div(vmax, (uint64_t)D));
    return ev > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)ev;
}

#ifdef WM_SLOPE_ENGINE
/* The board: E(T) in the normal metric with the slope unit started before ev's division, which runs beside
 * it (the same ev, the same r = root << k as slope_factor's): 1 and E(T) in *e, or 0 when the unit cannot
 * take the field (nothing done). */
static WM_ALWAYS_INLINE int normal_beside(const wm_field *f, const wm_params *p, const int32_t x[3],
                                          const int32_t y[3], int64_t D, uint64_t vmax, uint64_t *kept,
                                          uint32_t *e)
{
    uint32_t ev;
    uint64_t r;
    int k;
    if (!wm_tri_engine_slope_go(f, p, x, y)) return 0;
    ev = vertical(vmax, D);
    /* ev here, before _take's wait: the compiler takes the division's library call for one without side
     * effects and put it after _take's call (the CPU waited for the unit, then divided) */
    __asm__ volatile("" : "+r"(ev) : : "memory");
    r = (uint64_t)wm_tri_engine_slope_take(&k) << k;
    if (kept) *kept = r;
    *e = (uint32_t)wm_ceil_q16_div(ev, r); /* <= ev (r >= 2^16) */
    return 1;
}
#endif

/* E(T) from Vmax (the rounding of the file's head comment): monotone in vmax.  kept: as slope_factor's.
 * This and point_v, the small steps every measure takes, are inlined in each, as one copy was before they
 * were shared (a call and its spills cost the native build some 1 % of the refiner's instructions). */
static WM_ALWAYS_INLINE uint32_t finish(const wm_field *f, const wm_params *p, const int32_t x[3],
                                        const int32_t y[3], int64_t D, uint64_t vmax, uint64_t *kept)
{
    uint32_t ev;
#ifdef WM_SLOPE_ENGINE
    /* a slope factor to find (ev > 0 iff vmax > 0): the slope unit beside ev's division */
    if (p->metric != WM_METRIC_VERTICAL && vmax != 0 && !(kept && *kept) &&
        normal_beside(f, p, x, y, D, vmax, kept, &ev))
        return ev;
#endif
    ev = vertical(vmax, D);
    if (p->metric == WM_METRIC_VERTICAL || ev == 0) return ev;
    return (uint32_t)wm_ceil_q16_div(ev, slope_factor(f, p, x, y, D, kept)); /* <= ev (r >= 2^16) */
}

uint32_t wm_tri_error_kept(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                           int32_t *wx, int32_t *wy, uint64_t *kept)
{
    int64_t D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    uint32_t e;
    WM_ASSERT(D > 0);
    if (D <= 0) return 0xFFFFFFFFu;
    if (f->mask && wm_hole_error(f, x, y, &e, wx, wy)) return e; /* holes.c */
    return finish(f, p, x, y, D, scan_any(f, x, y, D, UINT64_MAX, wx, wy), kept);
}

uint32_t wm_tri_error(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t *wx,
                      int32_t *wy)
{
    return wm_tri_error_kept(f, p, x, y, wx, wy, NULL);
}

uint32_t wm_tri_error_over(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                           int32_t D, int32_t *wx, int32_t *wy, int *exact)
{
    uint64_t vmax;
    uint32_t e, bound = p->zeta;
    WM_ASSERT(D == wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]) && D > 0);
    *exact = 1;
    if (D <= 0) return 0xFFFFFFFFu;
    if (f->mask && wm_hole_error(f, x, y, &e, wx, wy)) return e; /* holes.c */
    vmax = scan_any(f, x, y, D, UINT64_MAX, wx, wy);
    /* ev = ceil(2^16 Vmax / D) <= bound iff 2^16 Vmax <= bound D (vmax < 2^47; D < 2^31, bound D < 2^63),
     * and then E(T) <= ev <= bound in either metric (the normal one's r >= 2^16): ev without the slope
     * factor (in the vertical metric ev is E(T), but not said to be) */
    if ((vmax << 16) <= (uint64_t)bound * (uint64_t)D) {
        *exact = 0;
        return D <= 4 && vmax >> 32 == 0 ? vertical_tiny(vmax, D) : vertical(vmax, D);
    }
    return finish(f, p, x, y, D, vmax, NULL);
}

uint32_t wm_tri_error_within(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                             uint32_t bound, int32_t *wx, int32_t *wy, uint64_t *kept)
{
    int64_t D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    uint64_t r, evm = bound, limit = UINT64_MAX;
    uint32_t e;
    WM_ASSERT(D > 0);
    if (D <= 0) return 0xFFFFFFFFu;
    if (f->mask && wm_hole_error(f, x, y, &e, wx, wy)) return e; /* holes.c */
    /* the largest Vmax whose E(T) is <= bound: E = ceil(2^16 ev / r) <= bound iff
     * ev <= floor(bound r / 2^16), and ev = ceil(2^16 V / D) <= evm iff V <= floor(evm D / 2^16) */
    if (p->metric != WM_METRIC_VERTICAL) {
        r = slope_factor(f, p, x, y, D, kept);
        evm = r < ((uint64_t)1 << 31) ? ((uint64_t)bound * r) >> 16 : 0xFFFFFFFFu;
        kept = &r;
    }
    if (evm < 0xFFFFFFFFu && D < ((int64_t)1 << 31)) limit = (evm * (uint64_t)D) >> 16;
    return finish(f, p, x, y, D, scan_any(f, x, y, D, limit, wx, wy), kept);
}

/* wm_tri_error_upto in the normal metric.  Where the slope factor is not known yet: with
 * T >= sqrt(D^2 + (s_x Na)^2 + (s_y Nb)^2) (wm_hypot_up twice), r <= 2^16 T / D (every rounding of the
 * slope factor is down), so E(T) >= 2^16 Vmax / T, and a sample whose V is above bound T / 2^16 puts
 * E(T) over bound for certain: the scan stops there, at that sample or after the one where the exact
 * limit would stop it (the same answer, above bound).  A scan within it is the whole scan; its ev
 * bounds E(T) from above, and the exact E(T), with the slope factor from the same Na, Nb, is taken
 * only when ev is above least: a scan that refuses, and a triangle that is not its candidate's
 * largest, take no slope factor. */
WM_NEVER_INLINE static uint32_t upto_normal(const wm_field *f, const wm_params *p, const int32_t x[3],
                                            const int32_t y[3], uint32_t bound, uint32_t least, uint64_t *kept)
{
    int64_t D, Na, Nb;
    uint64_t Ga, Gb, T, vmax, X, r;
    uint32_t sx, sy, root;
#ifdef WM_SLOPE_ENGINE
    uint32_t e;
#endif
    int32_t ex, ey;
    int k;
#if WM_NARROW_DIV
    /* wm_slope_scale's with the slope scales set (the usual case) falling through, where its choice was a
     * forward branch taken each call and one back */
    sx = p->slope_x_m, ex = p->slope_x_e, sy = p->slope_y_m, ey = p->slope_y_e;
    if (__builtin_expect(sx == 0, 0)) sx = p->scale_m, ex = p->scale_e;
    if (__builtin_expect(sy == 0, 0)) sy = p->scale_m, ey = p->scale_e;
#if WM_CHECK
    {
        uint32_t m2;
        int32_t e2;
        wm_slope_scale(p, 0, &m2, &e2);
        WM_ASSERT(m2 == sx && e2 == ex);
        wm_slope_scale(p, 1, &m2, &e2);
        WM_ASSERT(m2 == sy && e2 == ey);
    }
#endif
#else
    wm_slope_scale(p, 0, &sx, &ex);
    wm_slope_scale(p, 1, &sy, &ey);
#endif
    D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    if ((kept && *kept) || ex < 0 || ey < 0 || D <= 0 || D >= WM_SLOPE_LATER_D) /* ex, ey: wm_scaled_up's */
        return wm_tri_error_within(f, p, x, y, bound, NULL, NULL, kept);
#if WM_NARROW_DIV
    {
        /* on a 32-bit CPU (and in the checked builds) |Na|, |Nb| in 32-bit products, as first_fit's
         * far_above: differences of 16-bit samples (|dz| <= 65535) times differences of grid coordinates
         * (at most 32766) are below 2^31, and each numerator, the larger product less the smaller, below
         * 2^32 (the 64-bit products were a multiply triple and carries each); only their absolute values
         * are taken below (slope_square_n's too) */
        int32_t z0 = f->samples[y[0] * f->width + x[0]];
        int32_t dz1 = f->samples[y[1] * f->width + x[1]] - z0, dz2 = f->samples[y[2] * f->width + x[2]] - z0;
        int32_t p1 = dz1 * (y[2] - y[0]), p2 = dz2 * (y[1] - y[0]), p3 = (x[1] - x[0]) * dz2,
                p4 = (x[2] - x[0]) * dz1;
        uint32_t da = (uint32_t)p1 - (uint32_t)p2, sa = -(uint32_t)(p1 < p2);
        uint32_t db = (uint32_t)p3 - (uint32_t)p4, sb = -(uint32_t)(p3 < p4);
        Na = (da ^ sa) - sa; /* |p1 - p2| without a branch (taken half the time) */
        Nb = (db ^ sb) - sb;
#if WM_CHECK
        {
            int64_t Na64, Nb64;
            gradient(f, x, y, &Na64, &Nb64);
            WM_ASSERT(Na == (Na64 < 0 ? -Na64 : Na64) && Nb == (Nb64 < 0 ? -Nb64 : Nb64));
        }
#endif
    }
#else
    gradient(f, x, y, &Na, &Nb);
#endif
#if WM_NARROW_DIV
    /* the usual case first, falling through (on the board a forward branch taken costs some 3 cycles,
     * and GCC put both scales' 32-bit path and the 32-bit chords out of line, each taken at every call):
     * within it the inline functions' own tests are known and gone; the same integers either way */
    if (__builtin_expect(ex > 0 && ex < 32 && ey > 0 && ey < 32, 1)) {
        Ga = wm_scaled_up((uint64_t)Na, sx, ex);
        Gb = wm_scaled_up((uint64_t)Nb, sy, ey);
    } else {
        Ga = wm_scaled_up((uint64_t)Na, sx, ex);
        Gb = wm_scaled_up((uint64_t)Nb, sy, ey);
    }
    if (__builtin_expect((Ga | Gb | (uint64_t)D) < ((uint64_t)1 << 31), 1)) T = wm_hypot3_up(Ga, Gb, (uint64_t)D);
    else T = wm_hypot3_up(Ga, Gb, (uint64_t)D);
#else
    Ga = wm_scaled_up((uint64_t)(Na < 0 ? -Na : Na), sx, ex);
    Gb = wm_scaled_up((uint64_t)(Nb < 0 ? -Nb : Nb), sy, ey);
    T = wm_hypot3_up(Ga, Gb, (uint64_t)D);
#endif
    if (T >= ((uint64_t)1 << 31)) return wm_tri_error_within(f, p, x, y, bound, NULL, NULL, kept);
    vmax = scan_any(f, x, y, D, ((uint64_t)bound * T) >> 16, NULL, NULL);
    if ((vmax << 16) > (uint64_t)bound * T) return bound + 1;          /* E(T) > bound */
    if ((vmax << 16) <= (uint64_t)least * (uint64_t)D) return least; /* E(T) <= ev <= least */
#ifdef WM_SLOPE_ENGINE
    if (normal_beside(f, p, x, y, D, vmax, kept, &e)) return e; /* vmax > 0 here */
#endif
    X = slope_square_n(f, p, x, y, D, 1, Na, Nb, &k, &root);
    r = (uint64_t)(root ? root : wm_isqrt64(X)) << k;
    if (kept) *kept = r;
    return (uint32_t)wm_ceil_q16_div(vertical(vmax, D), r);
}

uint32_t wm_tri_error_upto(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                           uint32_t bound, uint32_t least, uint64_t *kept)
{
    int64_t D;
    uint64_t vmax;
    if (f->mask || bound == 0xFFFFFFFFu || least > bound)
        return wm_tri_error_within(f, p, x, y, bound, NULL, NULL, kept);
    if (p->metric != WM_METRIC_VERTICAL) return upto_normal(f, p, x, y, bound, least, kept);
    D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    WM_ASSERT(D > 0);
    if (D <= 0 || D >= ((int64_t)1 << 31)) return wm_tri_error_within(f, p, x, y, bound, NULL, NULL, kept);
    /* the vertical E(T) = ev = ceil(2^16 Vmax / D) <= least iff 2^16 Vmax <= least D: no division then */
    vmax = scan_any(f, x, y, D, ((uint64_t)bound * (uint64_t)D) >> 16, NULL, NULL);
    if ((vmax << 16) <= (uint64_t)least * (uint64_t)D) return least;
    return vertical(vmax, D);
}

/* |V| at sample (px, py) (the file's head comment) for the triangle of D = twice its area. */
static WM_ALWAYS_INLINE uint64_t point_v(const wm_field *f, const int32_t x[3], const int32_t y[3], int64_t D,
                                         int32_t px, int32_t py)
{
    int64_t S = 0, v;
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        S += wm_orient(x[k1], y[k1], x[k2], y[k2], px, py) * (int64_t)f->samples[(int64_t)y[k] * f->width + x[k]];
    }
    v = S - D * (int64_t)f->samples[(int64_t)py * f->width + px];
    return (uint64_t)(v < 0 ? -v : v);
}

uint32_t wm_point_error(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t px,
                        int32_t py, uint64_t *kept)
{
    int64_t D;
#ifdef WM_POINT_ENGINE
    uint32_t e;
    if (wm_tri_engine_point(f, p, x, y, px, py, kept, &e)) return e; /* the board's point-error unit */
#endif
    D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    if (D <= 0) return 0xFFFFFFFFu;
    WM_PROF_ADD(WM_PC_POINTS, 1);
    if (f->mask && wm_hole_at(f, px, py)) return 0; /* never above E(T) (holes.c) */
    return finish(f, p, x, y, D, point_v(f, x, y, D, px, py), kept);
}

int wm_point_above(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t px,
                   int32_t py, uint32_t bound, uint64_t *kept)
{
    int64_t D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    uint64_t av;
    if (D <= 0 || f->mask || bound == 0xFFFFFFFFu) return wm_point_error(f, p, x, y, px, py, kept) > bound;
    WM_PROF_ADD(WM_PC_POINTS, 1);
    av = point_v(f, x, y, D, px, py);
    /* ev = min(ceil(2^16 |V| / D), 2^32 - 1) <= bound iff 2^16 |V| <= bound D (|V| < 2^47, bound D <
     * 2^63), without a division: then E is within in either metric (the normal one's E <= ev, r >= 2^16,
     * with no slope factor needed); else the vertical E is above it */
    if (av * 65536u <= (uint64_t)bound * (uint64_t)D) return 0;
    return wm_point_above_v(f, p, x, y, D, av, bound, kept);
}

/* E(T) > bound for the point error of |V| = av (2^16 av > bound D: its vertical ev is above bound) on the
 * triangle of D = twice its area, with the slope factor r (r < 2^32), without a division: E = ceil(2^16 ev
 * / r) > bound iff 2^16 ev > bound r iff ev > F = floor(bound r / 2^16), and with F < 2^32 - 1 (ev is
 * saturated there) ev = ceil(2^16 av / D) > F iff 2^16 av > F D (F D < 2^63, 2^16 av < 2^63); with F >=
 * 2^32 - 1, ev <= F. */
static WM_ALWAYS_INLINE int above_r(uint64_t av, int64_t D, uint32_t bound, uint64_t r)
{
    uint64_t F = ((uint64_t)bound * r) >> 16;
    int above = F < 0xFFFFFFFFu && (av << 16) > F * (uint64_t)D;
    WM_ASSERT(r >> 32 == 0 && above == (wm_ceil_q16_div(vertical(av, D), r) > bound));
    return above;
}

int wm_point_above_v(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int64_t D,
                     uint64_t av, uint32_t bound, uint64_t *kept)
{
    uint64_t c, X;
    uint32_t ev, root;
    int k;
    if (p->metric == WM_METRIC_VERTICAL) return 1;
    /* On the soft CPU with a slope factor at hand (kept, or on the board the slope unit's root) the test
     * takes no division (above_r); natively, and without one, the divisions below (one instruction each) */
    if (WM_NARROW_DIV && bound != 0) {
        if (kept && *kept) {
            if (*kept >> 32 == 0) return above_r(av, D, bound, *kept);
        }
#ifdef WM_SLOPE_ENGINE
        else if (wm_tri_engine_slope_go(f, p, x, y)) {
            uint64_t r;
            root = wm_tri_engine_slope_take(&k);
            r = (uint64_t)root << k;
            if (r >> 32 ? wm_ceil_q16_div(vertical(av, D), r) > bound : above_r(av, D, bound, r)) return 1;
            if (kept) *kept = r; /* within: the caller measures it */
            return 0;
        }
#endif
    }
    ev = vertical(av, D); /* > bound */
    if (bound == 0) return 1; /* E >= 1: r is finite */
    if (kept && *kept) return wm_ceil_q16_div(ev, *kept) > bound;
    /* The normal metric without the root: E = ceil(2^16 ev / r) > bound iff 2^16 ev > bound r iff
     * r < c = ceil(2^16 ev / bound) (r an integer), and with r = floor(sqrt(X)) 2^k iff
     * floor(sqrt(X)) < c' = ceil(c / 2^k) iff X < c'^2 (X < 2^64 <= c'^2 when c' >= 2^32). */
    c = wm_ceil_q16_div(ev, bound); /* < 2^48 */
    X = slope_square(f, p, x, y, D, &k, &root);
    c = (c + ((uint64_t)1 << k) - 1) >> k;
    if (root ? root >= c : c >> 32 == 0 && X >= c * c) { /* floor(sqrt(X)) >= c' iff X >= c'^2 */
        if (kept) *kept = (uint64_t)(root ? root : wm_isqrt64(X)) << k; /* within: the caller measures it */
        return 0;
    }
    return 1;
}
