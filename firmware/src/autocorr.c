/* The reduction criteria (dissertation 4.5.2, 4.5.3): unit normals, the autocorrelation matrix
 *
 *     R(v) = (1/k) sum_{i=1..k} n_i n_i^T                                          (4.31)
 *
 * over the k triangles around v, and its eigen-decomposition.  Both small eigenvalues below
 * delta_lambda (4.32) select v for removal; lambda1 < delta_lambda < lambda2 at both ends of an edge
 * with |e21 . e22| > delta_c (4.33, 4.34) selects the edge for a collapse (reduce.c).
 *
 *        n_i  (Gauss map: the normals of N0(v) as points on the unit sphere)
 *         \  |  /
 *          \ | /            lambda3 ~ 1: the mean direction; lambda1, lambda2: the spread across it
 *      ---- (v) ----        (a flat star: 0, 0, 1; a crease: 0, > 0, < 1, e2 across the crease)
 *
 * Fixed point, identical on every machine:
 *   normal   (s A, s B, D) exact in integers (A, B < 2^32, D < 2^31, s = scale_m / 2^scale_e), the
 *            three brought to one binary scale below 2^31 by right shifts of their magnitudes, the
 *            length by an exact integer square root, each component rounded to Q28 (error a few 2^-28)
 *   R(v)     sums of Q56 products (k <= 32: below 2^61), rounded to Q30
 *   eigen    cyclic Jacobi rotations (t = sgn(theta) / (|theta| + sqrt(theta^2 + 1)),
 *            theta = (a_qq - a_pp) / (2 a_pq), all in Q30 with products rounded half away from
 *            zero), at most JACOBI_SWEEPS sweeps of the three pairs (an off-diagonal entry of at most
 *            SETTLED 2^-30 is not rotated): the off-diagonal falls quadratically,
 *            so the eigenvalues are within a few 2^-30 of R's (tests: against numpy's eigvalsh)
 * No product leaves 64 bits: every matrix entry is within [-1, 1] (Frobenius norm <= 1 for
 * R(v), whose eigenvalues are >= 0 and add up to 1), t, c, s within [-1, 1]. */
#include "wm_internal.h"

#define JACOBI_SWEEPS 8
#define ONE30 ((int64_t)1 << 30)
#define SETTLED \
    4u /* an off-diagonal entry this small (4 2^-30) is left alone: it moves an eigenvalue by
                      less than 2^-28 */

static uint64_t mag(int64_t a) { return a < 0 ? (uint64_t)0 - (uint64_t)a : (uint64_t)a; }

/* x y for x, y < 2^32 (always here: the entries, t, c and s are within [-1, 1] in Q30) as one 32 x 32
 * bit product (on rv32 a mul and a mulhu instead of a 64 x 64 bit one's four multiplies), else in 64
 * bits: the same integer. */
static uint64_t umul(uint64_t x, uint64_t y)
{
    if ((x | y) >> 32) return x * y;
    return (uint64_t)(uint32_t)x * (uint32_t)y;
}

#if WM_CHECK
/* round(a b / 2^30), half away from zero (the checked builds' reference for mulq32, below), for |a|, |b| < 2^31 (every matrix entry, t, c and s is
 * within [-1, 1] in Q30, above, but for a few units of rounding): p = a b + 2^29 - [a b < 0], below
 * 2^62 + 2^29 in magnitude, and floor(p / 2^30) by an unsigned shift of p + 2^63 (no shift of a
 * negative number, which C99 leaves to the implementation).  The same integer as rounding the
 * magnitudes' product; on rv32 one 32 x 32 bit product (mul, mulh) and some ten more instructions, no
 * branch, where the 64-bit magnitudes' product took four multiplies and the signs' branches. */
static int64_t mulq(int64_t a, int64_t b)
{
    int64_t ab = (int64_t)(int32_t)a * (int32_t)b;
    uint64_t p = (uint64_t)ab + ((uint64_t)1 << 29) - (uint64_t)(ab < 0);
    return (int64_t)((p ^ ((uint64_t)1 << 63)) >> 30) - ((int64_t)1 << 33);
}
#endif

/* mulq when the result fits 32 bits (every matrix entry, t, c and s below; the checked builds test it):
 * its low 32 bits are bits 30 .. 61 of p, whatever p's sign, so the 64-bit floor (mulq's shift of
 * p + 2^63 and the subtraction of 2^33) is not needed.  With WM_NARROW_DIV (32-bit CPUs, and the
 * checked builds) p = a b + k with k = 2^29 - [a b < 0] is one 64-bit addition of a 32-bit number in
 * 32-bit words (the low word's carry into the high one): on rv32 ten instructions where mulq took
 * sixteen.  Natively the 64-bit sum, fewer instructions there. */
static WM_ALWAYS_INLINE int32_t mulq32(int32_t a, int32_t b)
{
    uint64_t ab = (uint64_t)((int64_t)a * b);
    uint32_t q;
    if (WM_NARROW_DIV) {
        uint32_t lo = (uint32_t)ab, hi = (uint32_t)(ab >> 32), k = ((uint32_t)1 << 29) - (hi >> 31);
        lo += k;
        hi += lo < k;
        q = lo >> 30 | hi << 2;
    } else {
        q = (uint32_t)((ab + ((uint64_t)1 << 29) - (ab >> 63)) >> 30);
    }
    WM_ASSERT((int32_t)q == mulq(a, b));
    return (int32_t)q;
}

/* The difference and the sum of two mulq32, which also fit 32 bits (the entries of the rotated
 * matrices): taken modulo 2^32, the same integers. */
static WM_ALWAYS_INLINE int32_t sub32(int32_t x, int32_t y) { return (int32_t)((uint32_t)x - (uint32_t)y); }
static WM_ALWAYS_INLINE int32_t add32(int32_t x, int32_t y) { return (int32_t)((uint32_t)x + (uint32_t)y); }

/* The rotations' matrices are kept in 32 bits: every entry is within [-1, 1] in Q30 but for a few units
 * of rounding (above), so the same integers as in 64 bits, where on rv32 each load, store, add and
 * product of one took two or more instructions (the rotations were most of the reduction's
 * eigen-decompositions on the board).  *ident: whether v is still the identity (cleared by the first rotation
 * made). */
static void rotate(int32_t a[3][3], int32_t v[3][3], int p, int q, int *ident)
{
    int32_t apq = a[p][q], t, c, s;
    int64_t num = (int64_t)a[q][q] - a[p][p];
    uint64_t den = 2 * mag(apq), sq, tt;
    int neg;
    if (mag(apq) <= SETTLED) return;
    /* t = sgn(theta) |2 a_pq| / (|a_qq - a_pp| + sqrt((a_qq - a_pp)^2 + (2 a_pq)^2)), |t| <= 1 */
    sq = wm_isqrt64(umul(mag(num), mag(num)) + umul(den, den));
    tt = (den << 30) / (mag(num) + sq);
    neg = (num < 0) != (apq < 0);
    WM_ASSERT(tt <= (uint64_t)ONE30);
    t = neg ? -(int32_t)tt : (int32_t)tt;
    /* c = 1 / sqrt(1 + t^2), s = t c */
    sq = wm_isqrt64(((uint64_t)1 << 60) + umul(tt, tt));
    c = (int32_t)((((uint64_t)1 << 60) + sq / 2) / sq);
    s = mulq32(t, c);
    {
        int32_t tq = mulq32(t, apq);
        WM_ASSERT(a[p][p] - (int64_t)tq == (int64_t)sub32(a[p][p], tq) &&
                  a[q][q] + (int64_t)tq == (int64_t)add32(a[q][q], tq));
        a[p][p] = sub32(a[p][p], tq);
        a[q][q] = add32(a[q][q], tq);
        a[p][q] = a[q][p] = 0;
    }
    {
        int r = 3 - p - q; /* the third row and column */
        int32_t g = a[r][p], h = a[r][q];
        WM_ASSERT(mulq(c, g) - mulq(s, h) == (int64_t)sub32(mulq32(c, g), mulq32(s, h)) &&
                  mulq(s, g) + mulq(c, h) == (int64_t)add32(mulq32(s, g), mulq32(c, h)));
        a[r][p] = a[p][r] = sub32(mulq32(c, g), mulq32(s, h));
        a[r][q] = a[q][r] = add32(mulq32(s, g), mulq32(c, h));
    }
    if (*ident) {
        /* v is the identity (no rotation made yet): its columns p and q become (c, -s) and (s, c) in rows
         * p and q, the rest 0, exactly as the products below give them (mulq32(x, 2^30) = x, mulq32(x,
         * 0) = 0), without their twelve products */
        WM_ASSERT(mulq(c, ONE30) == c && mulq(s, ONE30) == s);
        v[p][p] = c, v[p][q] = s;
        v[q][p] = -s, v[q][q] = c;
        *ident = 0;
        return;
    }
    for (int r = 0; r < 3; r++) {
        int32_t g = v[r][p], h = v[r][q];
        WM_ASSERT(mulq(c, g) - mulq(s, h) == (int64_t)sub32(mulq32(c, g), mulq32(s, h)) &&
                  mulq(s, g) + mulq(c, h) == (int64_t)add32(mulq32(s, g), mulq32(c, h)));
        v[r][p] = sub32(mulq32(c, g), mulq32(s, h));
        v[r][q] = add32(mulq32(s, g), mulq32(c, h));
    }
}

void wm_sym3_eigen(const int64_t in[6], int64_t lambda[3], int64_t vec[9])
{
    int32_t a[3][3], v[3][3];
    int order[3] = {0, 1, 2}, ident = 1;
    for (int i = 0; i < 6; i++) WM_ASSERT(in[i] >= -ONE30 - 64 && in[i] <= ONE30 + 64); /* R's: within [-1, 1] */
    a[0][0] = (int32_t)in[0], a[0][1] = a[1][0] = (int32_t)in[1], a[0][2] = a[2][0] = (int32_t)in[2];
    a[1][1] = (int32_t)in[3], a[1][2] = a[2][1] = (int32_t)in[4], a[2][2] = (int32_t)in[5];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) v[i][j] = i == j ? ONE30 : 0;
    for (int sweep = 0; sweep < JACOBI_SWEEPS; sweep++) {
        if (mag(a[0][1]) <= SETTLED && mag(a[0][2]) <= SETTLED && mag(a[1][2]) <= SETTLED) break;
        rotate(a, v, 0, 1, &ident);
        rotate(a, v, 0, 2, &ident);
        rotate(a, v, 1, 2, &ident);
    }
    /* ascending, ties in column order (a stable insertion sort) */
    for (int i = 1; i < 3; i++)
        for (int j = i; j > 0 && a[order[j]][order[j]] < a[order[j - 1]][order[j - 1]]; j--) {
            int o = order[j];
            order[j] = order[j - 1];
            order[j - 1] = o;
        }
    for (int i = 0; i < 3; i++) {
        lambda[i] = a[order[i]][order[i]];
        for (int r = 0; r < 3; r++) vec[3 * i + r] = v[r][order[i]];
    }
}

void wm_unit_normal(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t n[3])
{
    /* The sample numbers, coordinate and height differences in 32 bits (below 2^30, 2^15 and 2^16 in
     * magnitude), so each product below is one 32 x 32 bit multiply: the same integers. */
    const uint16_t *h = f->samples;
    int32_t z0 = h[y[0] * f->width + x[0]], z1 = h[y[1] * f->width + x[1]], z2 = h[y[2] * f->width + x[2]];
    int32_t dx1 = x[1] - x[0], dy1 = y[1] - y[0], dz1 = z1 - z0;
    int32_t dx2 = x[2] - x[0], dy2 = y[2] - y[0], dz2 = z2 - z0;
    int64_t A = (int64_t)dy1 * dz2 - (int64_t)dz1 * dy2, B = (int64_t)dz1 * dx2 - (int64_t)dx1 * dz2;
    int64_t D = (int64_t)dx1 * dy2 - (int64_t)dx2 * dy1;
    uint64_t c[3], m, len;
    uint32_t mx, my;
    int32_t ex, ey;
    int e, sh = 0;
    /* A level triangle (its corners at one height: Box's and Ball's ground, Box's top): (0, 0, D), whose
     * unit normal below is (0, 0, 2^28) exactly (c[0] = c[1] = 0, len = c[2], each quotient exact), here
     * without the scaling, the root and the division (checked builds take the path below and compare) */
    if (!WM_CHECK && (A | B) == 0 && D > 0) {
        n[0] = n[1] = 0;
        n[2] = 1 << 28;
        return;
    }
    /* In ground units (cells dx x dy) the normal is (s A / dx, s B / dy, D): the slope scales of the
     * normal metric (wm_slope_scale; with a cell of 1 both are s, and nothing changes).  Brought to the
     * smaller exponent e: (sx A, sy B, D) 2^e = (mx A 2^(e - ex), my B 2^(e - ey), D 2^e), magnitudes
     * below 2^48, 2^48, 2^63 (the right shift of the finer scale truncates toward zero, the same bits
     * everywhere). */
    wm_slope_scale(p, 0, &mx, &ex);
    wm_slope_scale(p, 1, &my, &ey);
    e = ex < ey ? ex : ey;
    if (ex == ey && e < 32) {
        /* One scale (a square cell, or a cell of 1: Ball's, Box's, the DEMs'): no finer scale to shift
         * down, and D's shift below 32; |A|, |B| < 2^32 and |D| < 2^31 (above), so 32 x 32 bit products
         * and a shift of a 32-bit word, the same integers as below (on the soft CPU without three 64-bit
         * shifts by a variable, each a branch and some seven instructions). */
        c[0] = (uint64_t)(uint32_t)mag(A) * mx;
        c[1] = (uint64_t)(uint32_t)mag(B) * my;
        c[2] = (uint64_t)(uint32_t)mag(D) << e;
    } else {
        c[0] = ex - e >= 64 ? 0 : (mag(A) * mx) >> (ex - e);
        c[1] = ey - e >= 64 ? 0 : (mag(B) * my) >> (ey - e);
        c[2] = mag(D);
        if (e <= 32) {
            c[2] <<= e;
        } else {
            c[0] = e - 32 >= 64 ? 0 : c[0] >> (e - 32);
            c[1] = e - 32 >= 64 ? 0 : c[1] >> (e - 32);
            c[2] <<= 32;
        }
    }
    m = c[0] > c[1] ? c[0] : c[1];
    if (c[2] > m) m = c[2];
    sh = wm_bit_length64(m) - 31; /* the least shift that brings m below 2^31 */
    if (sh > 0)
        for (int k = 0; k < 3; k++) c[k] >>= sh;
    len = wm_isqrt64((uint64_t)(uint32_t)c[0] * (uint32_t)c[0] + (uint64_t)(uint32_t)c[1] * (uint32_t)c[1] +
                     (uint64_t)(uint32_t)c[2] * (uint32_t)c[2]); /* each below 2^31: < 3 2^62 */
    if (len == 0) { /* a degenerate triangle (not in a valid mesh) */
        n[0] = n[1] = 0;
        n[2] = 1 << 28;
        return;
    }
    if (WM_NARROW_DIV && len >> 31 == 0) {
        /* The three quotients by one reciprocal (wm_q28_div_recip: one division where three were, on the
         * soft CPU each a library call or the FPGA divider's), with len and the c[k] brought up by 2^t to L
         * in [2^29, 2^31): for sh < 0, m 2^t is in [2^29, 2^30) for t = -sh - 1, and m <= len < 2 m; else m
         * is in [2^30, 2^31) and t = 0 (len >= 2^31, rare, divides).  The same quotients: for t >= 1,
         * (2^28 c 2^t + floor(L / 2)) / L is (2^28 c + len / 2) / len exactly, which for an odd len is
         * a half more than the integer a = 2^28 c + floor(len / 2) over len: no multiple of len lies in
         * (a, a + 1/2], so the floors agree. */
        int t = sh < 0 ? -sh - 1 : 0;
        uint32_t L = (uint32_t)len << t, inv = (uint32_t)((((uint64_t)1 << 61) - 1) / L);
        for (int k = 0; k < 3; k++) {
            uint32_t q = wm_q28_div_recip((uint32_t)c[k] << t, L, inv);
            int neg = k == 0 ? A < 0 : k == 1 ? B < 0 : D < 0;
            WM_ASSERT(L >> 29 == 1 || L >> 29 == 2 || L >> 29 == 3);
            WM_ASSERT(q == ((c[k] << 28) + len / 2) / len);
            n[k] = (int32_t)(neg ? -(int32_t)q : (int32_t)q);
        }
        WM_ASSERT((A | B) != 0 || D <= 0 || (n[0] == 0 && n[1] == 0 && n[2] == 1 << 28));
        return;
    }
    for (int k = 0; k < 3; k++) {
        int64_t q = (int64_t)(((c[k] << 28) + len / 2) / len);
        int neg = k == 0 ? A < 0 : k == 1 ? B < 0 : D < 0;
        n[k] = (int32_t)(neg ? -q : q);
    }
    WM_ASSERT((A | B) != 0 || D <= 0 || (n[0] == 0 && n[1] == 0 && n[2] == 1 << 28));
}

/* floor(n / k) for 1 <= k <= WM_MAX_RING and n < 2^36, by multiplication: with M = ceil(2^32 / k)
 * (recip[k], k >= 2), floor(a M / 2^32) = floor(a / k) for every a < 2^27 (the error a (M k - 2^32) /
 * (k 2^32) is below 2^27 k / (k 2^32) < 1 / k), so n in two 16-bit steps: floor(n / 2^16) < 2^20, then
 * the remainder (below k <= 32) times 2^16 plus n's low 16 bits, below 2^21.  With WM_NARROW_DIV (the
 * soft CPU) four multiplies where the division by k took one to three calls of its 33-cycle division;
 * natively the division, one instruction. */
#define RECIP(k) (uint32_t)((0xFFFFFFFFu / (k)) + 1u)
#define RECIP8(k) \
    RECIP(k), RECIP(k + 1), RECIP(k + 2), RECIP(k + 3), RECIP(k + 4), RECIP(k + 5), RECIP(k + 6), RECIP(k + 7)
static const uint32_t recip[WM_MAX_RING + 1] = {0,        0,        RECIP(2),  RECIP(3),   RECIP(4),   RECIP(5),
                                                RECIP(6), RECIP(7), RECIP8(8), RECIP8(16), RECIP8(24), RECIP(32)};
typedef char recip_covers_the_ring[WM_MAX_RING == 32 ? 1 : -1]; /* recip[] has every k */

static uint64_t div_k(uint64_t n, int32_t k)
{
    uint32_t m = recip[k], hi, q1, lo, q0;
    if (k == 1) return n;
    hi = (uint32_t)(n >> 16);
    q1 = (uint32_t)(((uint64_t)hi * m) >> 32);
    lo = (hi - q1 * (uint32_t)k) << 16 | (uint32_t)(n & 0xFFFFu);
    q0 = (uint32_t)(((uint64_t)lo * m) >> 32);
    WM_ASSERT(n < ((uint64_t)1 << 36) && ((uint64_t)q1 << 16) + q0 == n / (uint32_t)k);
    return ((uint64_t)q1 << 16) + q0;
}

/* floor(x / (k 2^26)) for 1 <= k <= WM_MAX_RING and |x| < 2^62, as floor(floor(x / 2^26) / k) (and ceil
 * likewise for x < 0): the same integer as wm_floor_div(x, k << 26). */
static int64_t floor_div_k26(int64_t x, int32_t k)
{
    uint64_t m = x < 0 ? (uint64_t)0 - (uint64_t)x : (uint64_t)x;
    if (x >= 0) {
        m >>= 26;
        return (int64_t)(WM_NARROW_DIV ? div_k(m, k) : m / (uint32_t)k);
    }
    m = ((m + ((uint64_t)1 << 26) - 1) >> 26) + (uint32_t)k - 1; /* ceil(|x| / 2^26), then ceil(. / k) */
    return -(int64_t)(WM_NARROW_DIV ? div_k(m, k) : m / (uint32_t)k);
}

int wm_vertex_r(const wm_mesh *m, const wm_field *f, const wm_params *p, int32_t v, int64_t r[6],
                struct wm_normal_slot *kept, int32_t kept_mask)
{
    int64_t sum[6] = {0, 0, 0, 0, 0, 0};
    int32_t first, h, k = 0;
    if (v < 0 || v >= m->vert_end || m->vxy[v].x == WM_FREE) return WM_ERR_ARG;
    first = wm_fan_first(m, v);
    h = first;
    do {
        int32_t x[3], y[3], n[3];
        if (k >= WM_MAX_RING) return WM_ERR_REFUSED; /* keeps the sums below 2^61 */
        wm_tri_xy(m, WM_TRI(h), x, y);
        if (kept) { /* the slot's normal when its corners are the ones it was computed for */
            struct wm_normal_slot *s = &kept[WM_TRI(h) & kept_mask];
            int32_t key[3];
            for (int c = 0; c < 3; c++) key[c] = y[c] * m->width + x[c];
            if (s->key[0] != key[0] || s->key[1] != key[1] || s->key[2] != key[2]) {
                wm_unit_normal(f, p, x, y, s->n);
                for (int c = 0; c < 3; c++) s->key[c] = key[c];
            }
            for (int c = 0; c < 3; c++) n[c] = s->n[c];
        } else {
            wm_unit_normal(f, p, x, y, n);
        }
        sum[0] += (int64_t)n[0] * n[0];
        sum[1] += (int64_t)n[0] * n[1];
        sum[2] += (int64_t)n[0] * n[2];
        sum[3] += (int64_t)n[1] * n[1];
        sum[4] += (int64_t)n[1] * n[2];
        sum[5] += (int64_t)n[2] * n[2];
        k++;
        h = wm_rot_ccw(m, h);
    } while (h >= 0 && h != first);
    /* Q56 sums / k -> Q30, rounded (half up) */
    for (int i = 0; i < 6; i++) r[i] = floor_div_k26(sum[i] + ((int64_t)k << 25), k);
    return (int)k;
}

int wm_vertex_autocorr(const wm_mesh *m, const wm_field *f, const wm_params *p, int32_t v, int64_t r[6],
                       int64_t lambda[3], int64_t vec[9])
{
    int k = wm_vertex_r(m, f, p, v, r, NULL, 0);
    if (k < 0) return k;
    wm_sym3_eigen(r, lambda, vec);
    return k;
}
