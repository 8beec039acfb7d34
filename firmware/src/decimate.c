/* The final decimation, after the error bound (beyond the dissertation: docs/refiner.md).
 *
 *   a vertex can go when its hole has a triangulation that keeps every E(T) <= zeta (the first one
 *   found, trying the fan from each ring vertex, the half-edge collapses of v, then ear clipping)
 *   a pass: each dirty vertex in the grid's row order (by y, a row's vertices by slot) is evaluated
 *           (its flag cleared) and, when it can go, removed at once with that triangulation, its ring
 *           vertices marked dirty (their stars changed); every vertex is dirty at first, and the passes
 *           end when one leaves none dirty
 *
 * The dirty flag (r->vapex, a byte a place in the pass order) is what keeps the passes cheap: a vertex
 * that cannot go is tried again only after a removal in its ring, the only thing that changes its hole.
 * The pass order is fixed once, by a counting sort of the vertices by row (each pass from the least place
 * marked behind the one before; it reads the flags in that order, and a place's vertex only when it is
 * marked), and no cost is measured: a candidate's triangles are scanned only as far as
 * zeta (a bound at most zeta, which the removal leaves in err[] for wm_settle).  The rows sweep the
 * removals across the grid: fewer triangles than the slots' order (the error bound's insertion order)
 * on nearly every job (docs/refiner.md, "The final decimation").  Removing the least-cost vertex first
 * (a heap) took 46 % more of the decimation's instructions for as many triangles.  Every new
 * triangle has E(T) <= zeta, so the bound that held still holds, and each removal takes one or two
 * triangles away; all arithmetic is integer, the order of work fixed: the same mesh on every machine. */
#include "wm_internal.h"

#define NONE 0xFFFFFFFFu

/* The triangle a cheap test measured and its slope factor (kept as wm_internal.h says), for the scan
 * of the same triangle that follows when the test passes. */
struct tested {
    const wm_refiner *r;
    int32_t x[3], y[3];
    uint64_t kept;
};

static int test_point(struct tested *t, const int32_t x[3], const int32_t y[3], int32_t px, int32_t py)
{
    int above;
    t->kept = 0;
    above = wm_point_above(&t->r->field, &t->r->params, x, y, px, py, t->r->params.zeta, &t->kept);
    if (t->kept) /* the normal metric, and the test passed */
        for (int c = 0; c < 3; c++) t->x[c] = x[c], t->y[c] = y[c];
    return above;
}

/* The kept word for the triangle (x, y) when it is the tested one (its corners in any rotation), else NULL. */
static uint64_t *kept_for(struct tested *t, const int32_t x[3], const int32_t y[3])
{
    if (t->kept == 0) return NULL;
    for (int c = 0; c < 3; c++)
        if (x[c] == t->x[0] && y[c] == t->y[0]) {
            int c1 = wm_k1(c), c2 = wm_k2(c);
            return x[c1] == t->x[1] && y[c1] == t->y[1] && x[c2] == t->x[2] && y[c2] == t->y[2] ? &t->kept : NULL;
        }
    return NULL;
}

/* The first triangulation of v's hole that keeps every E(T) <= zeta, in the order the fans from ring
 * vertex 0, 1, ..., then ear clipping (Delaunay ears first): a bound at most zeta of its E(T) (each
 * triangle scanned only as far as zeta) and its kind (apex, as wm_vertex_remove_plan takes it), its
 * ring and triangles in vs; NONE when there is none.  Taking the first rather than the cheapest of them
 * measured as good (Jacksboro, Ball: 1-2 % fewer triangles) at 9 % fewer instructions. */
/* first_fit's cheap test for the fans, before a fan is built.  With d_i = p_i - v (v's star: the d_i
 * counter-clockwise, each step below a half turn, a side's two ends a half turn apart), v lies in the
 * fan triangle (p_a, p_k-1, p_k) where f(k) = orient(p_a, p_k, v) = d_a x d_k first falls to <= 0
 * going round from p_a+2 (the test on the built fan takes the same triangle); that k never moves back
 * as a goes round (the half-plane of d_a turns with it), so one pointer serves every fan of v: two or
 * three orientations a fan instead of one a ring step.  The edge functions of v in that triangle are
 * d_k-1 x d_k, d_k x d_a = -f(k) and d_a x d_k-1 = f(k - 1), so v's own error against it (a lower
 * bound of its E(T), rounded the same way) needs no more orientations: 2^16 |V| <= zeta D says it is
 * within zeta in either metric (as wm_point_above); above it, the vertical metric refuses the fan at
 * once and the normal one takes the slope factor's test (wm_point_above_v).  0 when v's error is above
 * zeta: that fan cannot go, valid or not; else 1 (also when no triangle holds v, which only an invalid
 * fan allows: wm_ring_plan then refuses it).  D < 2^31 (the grid's sides are below 2^15): its
 * products are 32 by 32 bits. */
/* A ring vertex p_i as v sees it: d_i and its sample less v's, side by side (one base address for all
 * three: on the soft CPU, with three arrays, each load of a z_i worked out its place on the stack
 * again, five instructions; pad: a power of two apart). */
struct ringd {
    int32_t x, y; /* d_i */
    int32_t z;    /* the sample of p_i less v's (16-bit samples) */
    int32_t pad;
};

struct fans {
    int32_t n, k;               /* ring size; the pointer, unwrapped */
    struct ringd d[WM_MAX_RING]; /* d_i, z_i */
    int32_t vx, vy;                           /* v */
    int32_t quick;                            /* 1: no holes mask and a bound (zeta): the test applies */
    uint32_t zeta;
    uint32_t zh, zl;                          /* zeta's high and low 16 bits (the 32-bit V's test) */
    uint32_t sx, sy;                          /* the normal metric's slope scales (wm_slope_scale) */
    int32_t ex, ey;
    int32_t words;                            /* 1: 0 < ex, ey < 32 (far_above's 32-bit path) */
    int32_t same;                             /* 1: words and ex = ey (far_above's one sum) */
    uint32_t mx, my;                          /* then 2^ex - 1, 2^ey - 1 (wm_scaled_up's rounding terms) */
    int32_t vertical;                         /* 1: the vertical metric */
    int32_t j;                                /* the fan triangle v lies in: (p_a, p_j, p_j+1) */
};

/* fan_may_fit's fan triangle (p_a, p_j, p_k) as v's differences d_a, d_j, d_k, loaded once for its
 * orientations and handed on to far_above (on the soft CPU far_above's own loads of them from q were
 * 6 % of first_fit's cycles on Jacksboro / 16). */
struct corners {
    int32_t ax, ay, jx, jy, kx, ky;
    int32_t az, jz, kz; /* and their z_i */
};

/* ceil(107 lo / 256), wm_hypot_up's term, for lo < 2^32: on a 32-bit CPU (and in the checked builds) in
 * 32-bit operations, lo = 256 h + l giving 107 h + ceil(107 l / 256) (the same integer: 256 * 107 h is a
 * multiple of 256), where the 64-bit product was a multiply pair and a carry; natively the product. */
static WM_ALWAYS_INLINE uint32_t chord(uint32_t lo)
{
#if WM_NARROW_DIV
    uint32_t c = (lo >> 8) * 107u + (((lo & 255u) * 107u + 255u) >> 8);
    WM_ASSERT((uint64_t)c == (((uint64_t)lo * 107u + 255u) >> 8));
    return c;
#else
    return (uint32_t)(((uint64_t)lo * 107u + 255u) >> 8);
#endif
}

/* 1 when v's normal distance to the fan triangle (p_a, p_j, p_k) is above zeta for certain, from its
 * |V| (av, above zeta D / 2^16: the vertical test failed) and the plane's gradient numerators Na, Nb
 * (wm_tri_error.c's slope factor), without the slope factor's divisions and root: with T >= sqrt(D^2 +
 * (s_x Na)^2 + (s_y Nb)^2) = D sqrt(1 + g^2) (wm_hypot_up twice), the rounded-down r <= 2^16 T / D,
 * and c = ceil(2^16 ev / zeta) >= 2^32 av / (D zeta) (ev >= 2^16 av / D, never saturated: v lies in the
 * closed triangle, so av <= (2^16 - 1) D), so zeta T < 2^16 av gives r < c, E > zeta
 * (wm_point_above_v's test).  0 says nothing: the exact test decides.  Most fans refused by v's point
 * are refused far above zeta, and this spares them the slope factor (the Jacksboro job: three in four). */
static int far_above(const struct fans *q, const struct corners *co, int64_t D, uint64_t av)
{
    int32_t z1 = co->jz - co->az, z2 = co->kz - co->az;
    int32_t jx = co->jx - co->ax, kx = co->kx - co->ax, jy = co->jy - co->ay, ky = co->ky - co->ay;
    uint64_t A, B, T;
#if WM_NARROW_DIV
    {
        /* differences of 16-bit samples times differences of grid coordinates (at most 32766): |z| <= 65535,
         * so each product is below 2^31, and |Na| = |z1 ky - z2 jy|, |Nb| = |jx z2 - kx z1| below 2^32: one
         * 32-bit multiply each and the difference taken the larger less the smaller (on a 32-bit CPU
         * the 64-bit products, differences and absolute values were carries and branches) */
        int32_t p1 = z1 * ky, p2 = z2 * jy, p3 = jx * z2, p4 = kx * z1;
        uint32_t na = p1 >= p2 ? (uint32_t)p1 - (uint32_t)p2 : (uint32_t)p2 - (uint32_t)p1;
        uint32_t nb = p3 >= p4 ? (uint32_t)p3 - (uint32_t)p4 : (uint32_t)p4 - (uint32_t)p3;
        int have = 0; /* A, B taken by the word shifts */
#if WM_CHECK
        {
            int64_t Na = (int64_t)z1 * ky - (int64_t)z2 * jy, Nb = (int64_t)jx * z2 - (int64_t)kx * z1;
            WM_ASSERT(na == (uint64_t)(Na < 0 ? -Na : Na) && nb == (uint64_t)(Nb < 0 ? -Nb : Nb));
        }
#endif
        if (q->same) {
            /* ex = ey = e (both cells' sides alike, the usual case): s = ceil((sx |Na| + sy |Nb|) / 2^e) bounds
             * the reals sx |Na| / 2^e + sy |Nb| / 2^e from above, so T <= D + s as with A + B below, and s <=
             * A + B (two roundings up against one): one sum shifted where the bound below takes each
             * product's words shifted and a sum of the two (each product below 2^48, their sum with 2^e - 1
             * below 2^49); when it does not answer, neither does A + B's, and the bounds below decide */
            uint64_t u = (uint64_t)na * q->sx + (uint64_t)nb * q->sy + q->mx;
            uint32_t lo = (uint32_t)u, hi = (uint32_t)(u >> 32);
            uint32_t s = (lo >> q->ex) | (hi << (32 - q->ex)), S = s + (uint32_t)D;
            WM_ASSERT(q->ex == q->ey && q->ex > 0 && q->ex < 32);
            if ((hi >> q->ex) == 0 && s < (1u << 31) && S < (1u << 31)) {
                uint64_t p = (uint64_t)q->zeta * S;
                uint32_t hx = (uint32_t)(p >> 32), lx = (uint32_t)p;
                uint32_t hy = (uint32_t)(av >> 16), ly = (uint32_t)av << 16;
                WM_ASSERT(((uint64_t)s << q->ex) >= (uint64_t)na * q->sx + (uint64_t)nb * q->sy);
                WM_ASSERT(s <= wm_scaled_up(na, q->sx, q->ex) + wm_scaled_up(nb, q->sy, q->ey));
                WM_ASSERT(av >> 46 == 0 && (hx < hy + (lx < ly)) == (p < (av << 16)));
                if (hx < hy + (lx < ly)) return 1;
            }
        }
        if (q->words) {
            /* wm_scaled_up's word-by-word shifts with 0 < e < 32 known (first_fit), when A and B are below
             * 2^31 (their high words 0, the low ones below 2^31) */
            uint64_t u = (uint64_t)na * q->sx + q->mx, w = (uint64_t)nb * q->sy + q->my;
            uint32_t ulo = (uint32_t)u, uhi = (uint32_t)(u >> 32), wlo = (uint32_t)w, whi = (uint32_t)(w >> 32);
            uint32_t a32 = (ulo >> q->ex) | (uhi << (32 - q->ex)), b32 = (wlo >> q->ey) | (whi << (32 - q->ey));
            WM_ASSERT(q->ex > 0 && q->ex < 32 && q->ey > 0 && q->ey < 32);
            WM_ASSERT(q->mx == (1u << q->ex) - 1u && q->my == (1u << q->ey) - 1u);
            if (((uhi >> q->ex) | (whi >> q->ey)) == 0 && (a32 | b32) < (1u << 31)) {
                /* the bound A + B + D >= T below, here at once (most calls end in it): s = A + B below
                 * 2^32, and zeta S < 2^16 av for S = s + D < 2^31 by words, with av < 2^46 (v in the
                 * closed triangle: av <= (2^16 - 1) D, D < 2^30), so its high word
                 * av >> 16 < 2^30: X < Y for X = 2^32 hx + lx, Y = 2^32 hy + ly is hx < hy + (lx < ly) */
                uint32_t s = a32 + b32, S = s + (uint32_t)D;
                WM_ASSERT(a32 == wm_scaled_up(na, q->sx, q->ex) && b32 == wm_scaled_up(nb, q->sy, q->ey));
                if (s < (1u << 31) && S < (1u << 31)) {
                    uint64_t p = (uint64_t)q->zeta * S;
                    uint32_t hx = (uint32_t)(p >> 32), lx = (uint32_t)p;
                    uint32_t hy = (uint32_t)(av >> 16), ly = (uint32_t)av << 16;
                    WM_ASSERT(av >> 46 == 0);
                    WM_ASSERT((hx < hy + (lx < ly)) == (p < (av << 16)));
                    if (hx < hy + (lx < ly)) {
                        WM_ASSERT(wm_hypot_up(wm_hypot_up(a32, b32), (uint64_t)D) <= S);
                        return 1;
                    }
                }
                A = a32, B = b32; /* the 32-bit bound below */
                have = 1;
            }
        }
        if (!have) {
            if (q->ex < 0 || q->ey < 0) return 0; /* not in wm_frac_mul's range */
            A = wm_scaled_up(na, q->sx, q->ex);
            B = wm_scaled_up(nb, q->sy, q->ey);
        }
    }
#else
    if (q->ex < 0 || q->ey < 0) return 0; /* not in wm_frac_mul's range */
    {
        int64_t Na = (int64_t)z1 * ky - (int64_t)z2 * jy, Nb = (int64_t)jx * z2 - (int64_t)kx * z1;
        A = wm_scaled_up((uint64_t)(Na < 0 ? -Na : Na), q->sx, q->ex);
        B = wm_scaled_up((uint64_t)(Nb < 0 ? -Nb : Nb), q->sy, q->ey);
    }
#endif
    if ((A | B) < ((uint64_t)1 << 31)) {
        /* wm_hypot_up twice in 32-bit operands (the same integers): A, B and D below 2^31, so the first
         * is below 2^32, and T is at least the larger operand of the second */
        uint32_t hi = (uint32_t)(A > B ? A : B), lo = (uint32_t)(A > B ? B : A), h, d = (uint32_t)D, s = hi + lo;
        /* first the bound A + B + D >= T (wm_hypot_up(x, y) = max + ceil(107 min / 256) <= x + y): when
         * it is below 2^31 and zeta times it below 2^16 av, so is T, and the answer is 1 without the
         * roots' chords (most calls: v is far above) */
        if (s < (1u << 31) && s + d < (1u << 31) && (uint64_t)q->zeta * (s + d) < (av << 16)) {
            WM_ASSERT(wm_hypot_up(wm_hypot_up(A, B), (uint64_t)D) <= (uint64_t)s + d);
            return 1;
        }
        h = hi + chord(lo);
        hi = h > d ? h : d, lo = h > d ? d : h;
        if (hi >= (1u << 31)) return 0;
        T = (uint64_t)hi + chord(lo);
        WM_ASSERT(T == wm_hypot_up(wm_hypot_up(A, B), (uint64_t)D));
    } else {
        T = wm_hypot_up(wm_hypot_up(A, B), (uint64_t)D);
    }
    return T < ((uint64_t)1 << 31) && (uint64_t)q->zeta * T < (av << 16);
}

#if WM_CHECK
/* d_i x d_j: |d| < 2^15, so it fits 32 bits (the products in 64): the checked builds' reference for
 * fan_may_fit's 32-bit orientations. */
static int32_t cross(const struct fans *q, int32_t i, int32_t j)
{
    return (int32_t)((int64_t)q->d[i].x * q->d[j].y - (int64_t)q->d[j].x * q->d[i].y);
}
#endif

/* fan_may_fit's test of v against the fan triangle (p_a, p_j, p_k) in the normal metric, its |V| (av)
 * above zeta D / 2^16: far_above, else wm_point_above_v (which keeps the slope factor when v is within). */
/* The fan triangle (p_a, p_j, p_k)'s corners. */
static void fan_corners(const struct fans *q, int32_t a, int32_t j, int32_t k, int32_t x[3], int32_t y[3])
{
    x[0] = q->vx + q->d[a].x, x[1] = q->vx + q->d[j].x, x[2] = q->vx + q->d[k].x;
    y[0] = q->vy + q->d[a].y, y[1] = q->vy + q->d[j].y, y[2] = q->vy + q->d[k].y;
}

static int normal_above(const struct fans *q, struct tested *t, int32_t a, int32_t j, int32_t k,
                        const struct corners *co, int64_t D, uint64_t av)
{
    const wm_refiner *r = t->r;
    int32_t x[3], y[3];
    int above;
    if (far_above(q, co, D, av)) return 1;
    fan_corners(q, a, j, k, x, y);
    above = wm_point_above_v(&r->field, &r->params, x, y, D, av, r->params.zeta, &t->kept);
    if (t->kept) /* as test_point */
        for (int c = 0; c < 3; c++) t->x[c] = x[c], t->y[c] = y[c];
    return above;
}

/* fan_may_fit's test where its own does not apply (no triangle, a holes mask, no bound): test_point's. */
WM_NOINLINE_32 static int other_above(const struct fans *q, struct tested *t, int32_t a, int32_t j, int32_t k)
{
    int32_t x[3], y[3];
    fan_corners(q, a, j, k, x, y);
    return test_point(t, x, y, q->vx, q->vy);
}

static int fan_may_fit(struct fans *q, struct tested *t, int32_t a)
{
    int32_t n = q->n, k, j, fk, fj, e0, D;
    int64_t V;
    uint64_t av = 0;
    struct corners c;
    {
        /* the pointer u unwrapped and k its ring position stepped together, d_a held, the orientations
         * in 32-bit products (|d| < 2^15: each below 2^30) (the soft CPU's job Jacksboro / 16: first_fit
         * 4 % fewer cycles; natively, with d_i in three arrays, 0.4 % more instructions than a loop of
         * cross's by index, which with one array of struct ringd took the more) */
        const struct ringd *d = q->d, *pa = d + a, *pj, *pk, *end = d + n;
        int32_t ax = pa->x, ay = pa->y, u = q->k < a + 2 ? a + 2 : q->k;
        /* d_k through a pointer stepped with u, wrapped at the ring's end (on the soft CPU each
         * array's place was worked out again every step), p_j's beside it, and the z_i from the same
         * three places */
        k = u < n ? u : u - n;
        pk = d + k;
        for (;;) {
            if (u > a + n - 1) {
                q->k = u;
                return 1;
            }
            fk = ax * pk->y - pk->x * ay;
            WM_ASSERT(fk == cross(q, a, (int32_t)(pk - d)));
            if (fk <= 0) break;
            u++;
            if (++pk == end) pk = d;
        }
        q->k = u;
        k = (int32_t)(pk - d);
        j = k == 0 ? n - 1 : k - 1;
        pj = pk == d ? end - 1 : pk - 1;
        c.ax = ax, c.ay = ay, c.jx = pj->x, c.jy = pj->y, c.kx = pk->x, c.ky = pk->y;
        c.az = pa->z, c.jz = pj->z, c.kz = pk->z;
        fj = ax * c.jy - c.jx * ay;
        e0 = c.jx * c.ky - c.kx * c.jy;
        WM_ASSERT(fj == cross(q, a, j) && e0 == cross(q, j, k));
    }
    q->j = j;
    /* D = (p_j - p_a) x (p_k - p_a), twice the signed area of a triangle of grid points: |D| <= (W - 1)(H - 1)
     * < 2^30, so the sum is taken modulo 2^32 (on rv32 no carries, one branch for D > 0) */
    D = (int32_t)((uint32_t)e0 - (uint32_t)fk + (uint32_t)fj);
    WM_ASSERT((int64_t)D == (int64_t)e0 - fk + fj);
    if (D > 0 && q->quick) {
        /* e0 z_a - fk z_j + fj z_k - D z_v with the z_i taken less z_v (q->d, c): one product fewer */
#if WM_NARROW_DIV
        if (D < (1 << 15) && (e0 | fj) >= 0 && fk <= 0) {
            /* on a 32-bit CPU (and in the checked builds): e0, -fk and fj are v's edge functions, each
             * at least 0 and their sum D, and |z_i| <= 65535 (16-bit samples), so every partial sum
             * is at most D 65535 < 2^31 in magnitude: 32-bit products and sums, where the 64-bit ones
             * were a multiply pair and carries each (v in the closed fan triangle, the usual case) */
            int32_t v32 = e0 * c.az - fk * c.jz + fj * c.kz;
            uint32_t a32 = v32 < 0 ? 0u - (uint32_t)v32 : (uint32_t)v32;
            WM_ASSERT((int64_t)v32 == (int64_t)e0 * c.az - (int64_t)fk * c.jz + (int64_t)fj * c.kz);
            av = a32;
            WM_PROF_ADD(WM_PC_POINTS, 1);
            t->kept = 0;
            /* 2^16 av <= zeta D with zeta = 2^16 zh + zl: av <= zh D + floor(zl D / 2^16) (av and zh D
             * integers), each product below 2^31 (zh, zl < 2^16, D < 2^15) and their sum below 2^32 */
            if (a32 <= q->zh * (uint32_t)D + ((q->zl * (uint32_t)D) >> 16)) {
                WM_ASSERT(av * 65536u <= (uint64_t)q->zeta * (uint32_t)D);
                return 1;
            }
            WM_ASSERT(av * 65536u > (uint64_t)q->zeta * (uint32_t)D);
            goto above;
        }
#endif
        V = (int64_t)e0 * c.az - (int64_t)fk * c.jz + (int64_t)fj * c.kz;
        av = (uint64_t)(V < 0 ? -V : V);
        WM_PROF_ADD(WM_PC_POINTS, 1);
        t->kept = 0;
        if (av * 65536u <= (uint64_t)q->zeta * (uint32_t)D) return 1;
#if WM_NARROW_DIV
    above:
#endif
        if (q->vertical) return 0;
        return !normal_above(q, t, a, j, k, &c, D, av);
    }
    return !other_above(q, t, a, j, k);
}

/* The fan from ring position a (wm_ring_plan_probe's, the same triangles in the same order) as ring
 * positions into tp, from v's d_i at hand: each orientation (p_b - p_a) x (p_c - p_a), differences of
 * grid coordinates below 2^15 - 1 as wm_orient's, exact in 32 bits; 0 when a triangle is not
 * counter-clockwise; *big the first of the largest. */
static int fan_plan(const struct fans *q, int32_t a, int32_t *tp, int32_t *nt, int32_t *big)
{
    int32_t n = q->n, b = a + 1 == n ? 0 : a + 1, k = 0, at = 0, most = -1;
    for (int32_t j = 1; j + 1 < n; j++) {
        int32_t c = b + 1 == n ? 0 : b + 1;
        int32_t d =
            (q->d[b].x - q->d[a].x) * (q->d[c].y - q->d[a].y) - (q->d[b].y - q->d[a].y) * (q->d[c].x - q->d[a].x);
        if (d <= 0) {
            *big = b; /* the triangle (a, b, c) */
            return 0;
        }
        if (d > most) most = d, at = k;
        tp[3 * k] = a, tp[3 * k + 1] = b, tp[3 * k + 2] = c;
        k++;
        b = c;
    }
    *nt = k;
    *big = at;
    return 1;
}

#if WM_CHECK
/* The checking build: fan_plan's answer and plan are wm_ring_plan_probe's from the mesh's arrays, the plan
 * the removal makes (wm_decimate's wm_ring_plan), triangle for triangle. */
static void check_fan_plan(const struct fans *q, const wm_mesh *me, const int32_t *ring, int32_t a)
{
    int32_t tp[3 * WM_MAX_RING], tris[3 * WM_MAX_RING], nt = 0, big = 0, n2 = 0, big2 = 0;
    int ok = fan_plan(q, a, tp, &nt, &big);
    WM_ASSERT(ok == (wm_ring_plan_probe(me, ring, q->n, a, tris, &n2, NULL, &big2) == WM_OK));
    if (!ok) return;
    WM_ASSERT(n2 == nt && big2 == big);
    for (int32_t k = 0; k < 3 * nt; k++) WM_ASSERT(tris[k] == ring[tp[k]]);
}
#endif

/* The probe of the ear clipping's plan (wm_ring_plan_probe): v's sample above zeta. */
static int v_above(void *ctx, const int32_t x[3], const int32_t y[3], int32_t px, int32_t py)
{
    return test_point((struct tested *)ctx, x, y, px, py);
}

/* 1 when every triangle of the plan has one corner in common (the plan is the fan from it). */
static int is_fan(const int32_t *tris, int32_t nt)
{
    for (int c = 0; c < 3; c++) {
        int32_t q = tris[c], j = 1;
        while (j < nt && (tris[3 * j] == q || tris[3 * j + 1] == q || tris[3 * j + 2] == q)) j++;
        if (j == nt) return 1;
    }
    return 0;
}

/* first_fit's record of the triangles that refused a candidate of this evaluation, as ring positions:
 * bit y of bad[x] is the fan triangle (p_x, p_y, p_y+1).  Whether a triangle refuses a candidate that
 * holds it is a property of its three corners alone (an E(T) over zeta, which v's own sample above it
 * shows, or not counter-clockwise), so every later candidate that holds one is refused for certain. */
/* And on a 32-bit CPU (and in the checked builds), as it marks one, the later fan that holds it (bit a
 * of *skip: the fan from p_a is refused for certain; fan_refused below says why no other does):
 * (p_x, p_x+1, p_x+2), the fan from p_x+2's last, when x + 2 < n; (p_x, p_x-2, p_x-1) with x - 2
 * wrapped round, the fan from p_x-2's first, when x < 2 (the fans are tried from p_0 on, so the others'
 * turn is past).  There first_fit asks one bit before each fan where fan_refused's two tests of bad[]
 * took some 15 instructions, most of them loads of its spilled terms (on the board's Jacksboro / 4
 * first_fit 23.70 M -> 23.29 M cycles); natively fan_refused (the skip word cost the ten pairs 0.5 %
 * more instructions, the compiler's code round it). */
static WM_ALWAYS_INLINE void mark_bad(uint32_t *bad, uint32_t *skip, int32_t n, int32_t x, int32_t y)
{
    bad[x] |= 1u << y;
    if (!WM_NARROW_DIV) return;
    if (y == x + 1 && x + 2 < n) *skip |= 1u << (x + 2);
    else if (x < 2 && y == x - 2 + n) *skip |= 1u << (x - 2 + n);
}

/* 1 when the fan from p_a holds a triangle in bad[] (n ring vertices), asked before that fan is tried:
 * the fan triangle (p_a-2, p_a-1, p_a) of the fan from p_a-2 (this fan's last) or (p_a+2, p_a, p_a+1) of
 * that from p_a+2 (this fan's first; evaluated before it only when a + 2 wraps round): no other triangle
 * of a fan has two consecutive ring vertices as it is seen from another corner, and bad[a], the fan's
 * own, is still empty (only the fan from p_a marks it, when refused).  On a 32-bit CPU skip's bit a
 * (mark_bad; the checked builds assert they agree). */
static WM_ALWAYS_INLINE int fan_refused(const uint32_t *bad, uint32_t skip, int32_t n, int32_t a)
{
#if WM_NARROW_DIV && !WM_CHECK
    (void)bad, (void)n;
    return (int)(skip >> a & 1);
#else
    int refused = (a >= 2 && (bad[a - 2] >> (a - 1) & 1)) || (a >= n - 2 && (bad[a + 2 - n] >> a & 1));
    WM_ASSERT(!WM_NARROW_DIV || (int)(skip >> a & 1) == refused);
    (void)skip;
    return refused;
#endif
}

#if WM_CHECK
/* The fan from ring position a's triangles as ring vertices (n - 2 of them), as fan_plan and
 * wm_ring_plan make them: (p_a, p_a+k, p_a+k+1) for k = 1 .. n - 2 (first_fit's scans take the fan's
 * corners from v's differences; the removal makes them from the ring and its apex, and the checked
 * builds assert they are these). */
static void fan_tris(const int32_t *ring, int32_t n, int32_t a, int32_t *tris)
{
    int32_t b = a + 1 == n ? 0 : a + 1;
    for (int32_t k = 0; k < n - 2; k++) {
        int32_t c = b + 1 == n ? 0 : b + 1;
        tris[3 * k] = ring[a], tris[3 * k + 1] = ring[b], tris[3 * k + 2] = ring[c];
        b = c;
    }
}
#endif

/* One evaluation of a vertex v (first_fit) and the removal that follows it (remove_planned), kept by
 * wm_decimate for the whole decimation: v's fan and ring (wm_vertex_fan) and, after a call that found a
 * plan, its triangles as wm_ring_plan gives them for its apex (a fan's are left to its removal:
 * wm_vertex_remove_fan makes them from the ring and the apex), which the removal, at once, takes instead of working them out again; and the fans' terms
 * (the job's set once, v's each call). */
struct evaluation {
    int32_t nr, nt, k;
    int32_t ring[WM_MAX_RING], tris[3 * WM_MAX_RING];
    int32_t e[WM_MAX_RING]; /* and v's fan (wm_vertex_fan), k half-edges, for wm_vertex_remove_fan */
    struct fans q;          /* first_fit's fans: the job's terms set once (fans_setup), v's per call */
};

/* The terms of fan_may_fit and far_above that are the job's, not a vertex's (the metric, zeta, the slope
 * scales and their rounding terms): set once for the decimation, where each evaluation worked them out
 * again (on the soft CPU a dozen loads through the refiner's pointer a call, most of them the SDRAM's). */
static void fans_setup(const wm_refiner *r, struct fans *q)
{
    q->quick = r->field.mask == NULL && r->params.zeta != 0xFFFFFFFFu;
    q->zeta = r->params.zeta;
    q->zh = q->zeta >> 16, q->zl = q->zeta & 0xFFFFu;
    wm_slope_scale(&r->params, 0, &q->sx, &q->ex);
    wm_slope_scale(&r->params, 1, &q->sy, &q->ey);
    q->words = WM_NARROW_DIV && q->ex > 0 && q->ex < 32 && q->ey > 0 && q->ey < 32;
    q->same = q->words && q->ex == q->ey;
    q->mx = q->words ? (1u << q->ex) - 1u : 0, q->my = q->words ? (1u << q->ey) - 1u : 0;
    q->vertical = r->params.metric == WM_METRIC_VERTICAL;
}

static uint32_t first_fit(const wm_refiner *r, int32_t v, int32_t *apex, struct evaluation *vs)
{
    const wm_mesh *me = &r->mesh;
    int32_t *ring = vs->ring, *tris = vs->tris, rx[WM_MAX_RING], ry[WM_MAX_RING], tp[3 * WM_MAX_RING], n, nt, big;
    uint32_t best = NONE, bad[WM_MAX_RING], skip = 0;
    int32_t vx = me->vxy[v].x, vy = me->vxy[v].y, zv;
    struct wm_plan_probe probe;
    struct tested tested;
    struct fans *q = &vs->q;
    tested.r = r;
    probe.px = vx, probe.py = vy, probe.above = v_above, probe.ctx = &tested, probe.bad = WM_CHECK ? NULL : bad;
    n = wm_vertex_fan(me, v, vs->e, &vs->k, ring);
    if (n < 0) return NONE;
    q->n = n;
    q->k = 0;
    zv = r->field.samples[(int64_t)vy * r->field.width + vx];
    q->vx = vx, q->vy = vy;
    for (int32_t i = 0; i < n; i++) {
        rx[i] = me->vxy[ring[i]].x;
        ry[i] = me->vxy[ring[i]].y;
        q->d[i].x = rx[i] - vx;
        q->d[i].y = ry[i] - vy;
        q->d[i].z = r->field.samples[(int64_t)ry[i] * r->field.width + rx[i]] - zv;
        bad[i] = 0;
    }
    /* Three ring vertices have one triangulation, four have two (the fans from 0 and 2 are the same,
     * and those from 1 and 3): the duplicates are not tried again.  The fans first, then the ear
     * clipping: a fan is refused from one orientation a step, the ear clipping only after part of its
     * plan (Jacksboro at 5 m: 4 % fewer instructions; triangles over the quality benchmark's 52 pairs
     * +0.4 %).  Every triangulation of four or five ring vertices is a fan (two diagonals of a pentagon
     * that do not cross share a corner), so there the ear clipping, whose plan is one of the fans
     * already refused, is not tried (ears); with more, a plan that is a fan is not measured again. */
    for (int32_t i = 0, fans = n == 3 ? 0 : n == 4 ? 2 : n, ears = n == 3 || n > 5; i < fans + ears; i++) {
        int32_t a = i < fans ? i : -1, j;
        uint32_t worst = 0;
        tested.kept = 0;
        /* First the cheap test: v's own sample against the new triangle that holds it (a lower bound
         * of that triangle's E(T), rounded the same way); most candidates stop here.  A fan's before
         * it is built (fan_may_fit), the ear clipping's as soon as that triangle is cut (the probe). */
        if (a >= 0) {
#if WM_CHECK
            check_fan_plan(q, me, ring, a);
#endif
            if (!WM_CHECK && fan_refused(bad, skip, n, a)) continue; /* the checking build tries it and asserts */
            if (!fan_may_fit(q, &tested, a)) {
                mark_bad(bad, &skip, n, a, q->j);
                continue;
            }
            if (!fan_plan(q, a, tp, &nt, &big)) {
                mark_bad(bad, &skip, n, a, big);
                continue;
            }
        } else {
            if (wm_ring_plan_probe(me, ring, n, a, tris, &nt, &probe, &big) != WM_OK) continue;
            if (n > 3 && is_fan(tris, nt)) continue; /* a fan refused above, the same triangles */
        }
        /* Then the scans, the plan's largest triangle first (the plan found it: big): a candidate is
         * refused by any triangle over zeta and otherwise goes, so their order changes no result, and
         * the triangle that refuses a candidate is most often its largest (it holds the most samples):
         * scanned first, it saves the scans of the others.  Each only as far as zeta: the passes need
         * no cost, and in the normal metric a triangle within zeta needs no slope factor. */
        for (j = 0; j < nt; j++) {
            int32_t x[3], y[3], t = j == 0 ? big : j == big ? 0 : j;
            uint32_t e;
            for (int c = 0; c < 3; c++) {
                x[c] = a >= 0 ? vx + q->d[tp[3 * t + c]].x : me->vxy[tris[3 * t + c]].x;
                y[c] = a >= 0 ? vy + q->d[tp[3 * t + c]].y : me->vxy[tris[3 * t + c]].y;
            }
            e = wm_tri_error_upto(&r->field, &r->params, x, y, r->params.zeta, r->params.zeta,
                                  kept_for(&tested, x, y));
            if (e > worst) worst = e;
            if (worst > r->params.zeta) break;
        }
        if (j < nt) {
            if (a >= 0) mark_bad(bad, &skip, n, a, tp[3 * (j == 0 ? big : j == big ? 0 : j) + 1]);
            continue;
        }
        if (r->field.mask) { /* holes.c */
            for (int32_t k = 0; a >= 0 && k < 3 * nt; k++) tris[k] = ring[tp[k]];
            if (!wm_hole_keeps_cover(r, v, ring, n, tris, nt)) continue;
        }
#if WM_CHECK
        if (a >= 0) /* a candidate holding a triangle that refused another is refused */
            WM_ASSERT(!fan_refused(bad, skip, n, a));
        else
            for (int32_t k = 0; k < nt; k++) {
                int32_t at[3];
                for (int c = 0; c < 3; c++)
                    for (at[c] = 0; ring[at[c]] != tris[3 * k + c]; at[c]++) {}
                WM_ASSERT(!wm_tri_bad(bad, n, at[0], at[1], at[2]));
            }
#endif
        best = worst;
        *apex = a;
        vs->nr = n, vs->nt = nt; /* a fan's triangles: its removal's, from the apex */
        break;
    }
    return best;
}

/* v's removal with the plan first_fit just made on its star (vs: its ring, triangles and fan; apex its
 * kind), which nothing has changed since; bound, first_fit's, is at least the E(T) of every new triangle
 * (measured at the end: wm_settle).  Its ring size, or wm_vertex_remove_fan's error (it refuses only a
 * plan that is not of this mesh, which cannot happen: the checked builds assert it, and wm_decimate
 * stops the job with the error). */
static int32_t remove_planned(wm_refiner *r, int32_t v, int32_t apex, uint32_t bound, struct evaluation *vs)
{
    wm_mesh *me = &r->mesh;
    int32_t touched[WM_MAX_RING], k, nr = vs->nr, nt = vs->nt, *ring = vs->ring, *tris = vs->tris;
    int rc;
#if WM_CHECK
    {
        if (apex >= 0) fan_tris(ring, nr, apex, tris); /* what wm_vertex_remove_fan makes of a fan, asserted */
        int32_t ring2[WM_MAX_RING], tris2[3 * WM_MAX_RING], nt2 = 0;
        WM_ASSERT(wm_vertex_ring(me, v, ring2) == nr);
        WM_ASSERT(wm_ring_plan(me, ring2, nr, apex, tris2, &nt2) == WM_OK && nt2 == nt);
        for (int32_t i = 0; i < nr; i++) WM_ASSERT(ring2[i] == ring[i]);
        for (int32_t i = 0; i < 3 * nt; i++) WM_ASSERT(tris2[i] == tris[i]);
    }
#endif
    rc = wm_vertex_remove_fan(me, v, vs->e, vs->k, ring, nr, apex, WM_CHECK || apex < 0 ? tris : NULL, nt, touched,
                              &k);
    WM_ASSERT(rc == WM_OK);
    if (rc != WM_OK) return rc;
    for (int32_t i = 0; i < k; i++) {
        me->tflag[touched[i]] |= WM_F_MEASURE;
        r->err[touched[i]] = bound;
    }
    r->removals++;
    return nr;
}

int wm_decimate(wm_refiner *r, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    int8_t *dirty = r->vapex; /* by place in order[] (the reduction's classes are not read after the levels) */
    /* the vertices in the grid's rows, each row's in slot order (a counting sort by y): order[] in the
     * error bound's heap storage (list[]: 2 tri_cap words at least, and vert_end <= tri_cap + 2, a mesh
     * of V vertices having at least V - 2 triangles), place[] in vkey (first the rows' starts, H + 1 <=
     * vert_cap words, then each vertex's place in order[]) */
    int32_t *order = (int32_t *)(void *)r->list, end = me->vert_end, height = me->height, m = 0, from = 0;
    uint32_t *place = r->vkey;
    struct evaluation vs;
    WM_ASSERT((uint64_t)end <= 2 * (uint64_t)me->tri_cap && height + 1 <= me->vert_cap);
    fans_setup(r, &vs.q);
    for (int32_t y = 0; y <= height; y++) place[y] = 0;
    for (int32_t v = 0; v < end; v++)
        if (me->vxy[v].x != WM_FREE) place[me->vxy[v].y + 1]++;
    for (int32_t y = 1; y <= height; y++) place[y] += place[y - 1];
    for (int32_t v = 0; v < end; v++)
        if (me->vxy[v].x != WM_FREE) order[place[me->vxy[v].y]++] = v;
    m = (int32_t)place[height - 1];
    for (int32_t i = 0; i < m; i++) place[order[i]] = (uint32_t)i, dirty[i] = 1; /* every vertex dirty at first */
    /* the passes over order[]: each from the least place marked dirty behind the one before (places below
     * it are clean), until a pass marks none behind its cursor (every place marked ahead of it it has seen) */
    while (from < m) {
        int32_t i = from;
        from = m;
        for (; i < m; i++) {
            int32_t apex = -1, nr, v;
            uint32_t bound;
            if (!dirty[i]) continue;
            dirty[i] = 0;
            v = order[i];
            WM_ASSERT(me->vxy[v].x != WM_FREE);
            bound = first_fit(r, v, &apex, &vs);
            if (bound == NONE) continue; /* tried again only when its ring changes */
            nr = remove_planned(r, v, apex, bound, &vs);
            if (nr < 0) return nr; /* cannot happen (remove_planned) */
            for (int32_t h = 0; h < nr; h++) { /* their stars changed */
                int32_t at = (int32_t)place[vs.ring[h]];
                dirty[at] = 1;
                if (at < i && at < from) from = at;
            }
        }
    }
    /* The triangles the removals made (and those the error bound left unmeasured) are measured once, at
     * the end, for those still there and as far as E_max needs them (wm_settle): nothing above reads
     * them (first_fit measures its candidates itself), and most of them go again in a later removal. */
    wm_settle(r, st);
    return WM_OK;
}
