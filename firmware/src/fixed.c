/* Exact integer and fixed-point helpers.  Everything here gives the same bits on any C99 target
 * with 32- or 64-bit registers: no floating point, no signed right shifts, no division of negative
 * numbers except through wm_floor_div / wm_ceil_div. */
#include "wm_angle.h" /* generated (make gen): the CORDIC's constants */
#include "wm_internal.h"

/* Square roots by Newton steps from below, each exact: with a = floor(sqrt(x >> 2s)) where x >> 2s lies
 * in [4^(n-1), 4^n) (so a in [2^(n-1), 2^n)) and 1 <= s <= n <= 16, r0 = a 2^s <= sqrt(x) < r0 + 2^s, and
 * c = r0 + floor(e / (2 r0)) with e = x - r0^2 >= 0 is >= floor(sqrt(x)) (a Newton step lands on or
 * above the root) and overshoots sqrt(x) by (sqrt(x) - r0)^2 / (2 r0) < 2^2s / 2^(n + s) <= 1: c is the
 * root or one above it, and one square decides.  floor(e / (2 a 2^s)) = floor(floor(e / 2^(s+1)) / a),
 * and e < (2a + 1) 2^2s makes e >> (s + 1) < 2^(2n) <= 2^32: one 32-bit division a step.  From the
 * table's 4-bit root of the top 8 bits, steps with s = 4, 8, 16 give the 8-, 16- and 32-bit roots of a
 * number normalised to the top of 32 or 64 bits; floor(sqrt(4^k y)) >> k = floor(sqrt(y)) undoes the
 * normalisation.  Three hardware divisions for a 64-bit root on the soft CPU, where Newton's iteration
 * from a power of two took four or five 32-bit ones and two or three library calls for the 64-bit part;
 * exact (wm_unit.c checks against the bit-by-bit root; checked at every x below 2^32 once). */

/* floor(sqrt(i)), i < 256. */
static const uint8_t sqrt8[256] = {
    0,  1,  1,  1,  2,  2,  2,  2,  2,  3,  3,  3,  3,  3,  3,  3,  4,  4,  4,  4,  4,  4,  4,  4,  4,  5,
    5,  5,  5,  5,  5,  5,  5,  5,  5,  5,  6,  6,  6,  6,  6,  6,  6,  6,  6,  6,  6,  6,  6,  7,  7,  7,
    7,  7,  7,  7,  7,  7,  7,  7,  7,  7,  7,  7,  8,  8,  8,  8,  8,  8,  8,  8,  8,  8,  8,  8,  8,  8,
    8,  8,  8,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  9,  10, 10, 10, 10,
    10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 11, 11, 11, 11, 11, 11, 11, 11, 11,
    11, 11, 11, 11, 11, 11, 11, 11, 11, 11, 11, 11, 11, 11, 12, 12, 12, 12, 12, 12, 12, 12, 12, 12, 12, 12,
    12, 12, 12, 12, 12, 12, 12, 12, 12, 12, 12, 12, 12, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13,
    13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 13, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14,
    14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 15, 15, 15, 15, 15, 15, 15, 15, 15,
    15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15,
};

/* The leading zeros of x != 0.  On the soft CPU (WM_NARROW_DIV) by a binary search in registers:
 * __builtin_clz and __builtin_clzll are library calls there (a table load and a call each, 1.4 % of a
 * board job's cycles); one instruction elsewhere. */
static inline int clz32(uint32_t x)
{
    int n = 0;
    if (!WM_NARROW_DIV) return __builtin_clz(x);
    if (x >> 16 == 0) {
        n += 16;
        x <<= 16;
    }
    if (x >> 24 == 0) {
        n += 8;
        x <<= 8;
    }
    if (x >> 28 == 0) {
        n += 4;
        x <<= 4;
    }
    if (x >> 30 == 0) {
        n += 2;
        x <<= 2;
    }
    return n + (int)(x >> 31 == 0);
}

/* One step for x < 2^32 in 32-bit arithmetic: r0^2 <= x; the root is below 2^16, so c <= 2^16, and c
 * clamped below 2^16 squares below 2^32. */
static uint32_t root_step32(uint32_t x, int s, uint32_t a)
{
    uint32_t r0 = a << s, c = r0 + ((x - r0 * r0) >> (s + 1)) / a;
    if (c > 0xFFFFu) c = 0xFFFFu;
    return c * c > x ? c - 1 : c;
}

/* floor(sqrt(x)) for x in [2^30, 2^32): the 4-bit root of the top 8 bits, then steps to 8 and 16 bits. */
static uint32_t root_top32(uint32_t x) { return root_step32(x, 8, root_step32(x >> 16, 4, sqrt8[x >> 24])); }

static uint32_t isqrt32(uint32_t x)
{
    int t;
    if (x < 256) return sqrt8[x];
    t = clz32(x) & ~1; /* an even shift that brings x to [2^30, 2^32) */
    return root_top32(x << t) >> (t / 2);
}

int wm_bit_length64(uint64_t x)
{
    if (!WM_NARROW_DIV) return x ? 64 - __builtin_clzll(x) : 0; /* GCC and Clang, on every target */
    return x >> 32 ? 64 - clz32((uint32_t)(x >> 32)) : x ? 32 - clz32((uint32_t)x) : 0;
}

/* floor(sqrt(x)): below 2^32 isqrt32; above, x normalised to [2^62, 2^64) and one step with s = 16 from
 * the 16-bit root of the top 32 bits (the root is below 2^32, so c <= 2^32: clamped, the square fits). */
uint64_t wm_isqrt64(uint64_t x)
{
    int t;
    uint32_t a, r0, c;
    uint64_t hi, c64;
#if defined(WM_SLOPE_ENGINE) || defined(WM_ROOT_ENGINE)
    if (x >= 256) return wm_tri_engine_root(x); /* the board's FPGA slope unit, the host's hardware root */
#endif
    if (x < ((uint64_t)1 << 32)) return isqrt32((uint32_t)x);
    t = (WM_NARROW_DIV ? clz32((uint32_t)(x >> 32)) : __builtin_clzll(x)) & ~1; /* x >= 2^32: the high word's */
    hi = x << t;
    a = root_top32((uint32_t)(hi >> 32));
    r0 = a << 16; /* 32-bit operands, 64-bit products: a multiply and a multiply-high each on rv32 */
    c64 = (uint64_t)r0 + (uint32_t)((hi - (uint64_t)r0 * r0) >> 17) / a;
    c = c64 > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)c64;
    return ((uint64_t)c * c > hi ? c - 1 : c) >> (t / 2);
}

int32_t wm_gcd(int32_t a, int32_t b)
{
    uint32_t x = (uint32_t)(a < 0 ? -(int64_t)a : a), y = (uint32_t)(b < 0 ? -(int64_t)b : b);
    while (y) {
        uint32_t t = x % y;
        x = y;
        y = t;
    }
    return (int32_t)x;
}

int64_t wm_floor_div(int64_t a, int64_t b)
{
    WM_ASSERT(b > 0);
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}

int64_t wm_ceil_div(int64_t a, int64_t b)
{
    WM_ASSERT(b > 0);
    return a >= 0 ? (a + b - 1) / b : -((-a) / b);
}

/* The 128-bit product a b as (hi, lo), from 32-bit halves. */
static void mul128(uint64_t a, uint64_t b, uint64_t *hi, uint64_t *lo)
{
    uint64_t a0 = a & 0xFFFFFFFFu, a1 = a >> 32, b0 = b & 0xFFFFFFFFu, b1 = b >> 32;
    uint64_t p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    uint64_t mid = (p00 >> 32) + (p01 & 0xFFFFFFFFu) + (p10 & 0xFFFFFFFFu);
    *lo = (mid << 32) | (p00 & 0xFFFFFFFFu);
    *hi = p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
}

int wm_cmp_mul(uint64_t a, uint64_t b, uint64_t c, uint64_t d)
{
    uint64_t h1, l1, h2, l2;
    mul128(a, b, &h1, &l1);
    mul128(c, d, &h2, &l2);
    if (h1 != h2) return h1 < h2 ? -1 : 1;
    if (l1 != l2) return l1 < l2 ? -1 : 1;
    return 0;
}

/* Shift toward zero, the same on every target (no implementation-defined signed shift). */
static int64_t shr0(int64_t v, int s)
{
    return v >= 0 ? (int64_t)((uint64_t)v >> s) : -(int64_t)((uint64_t)(-v) >> s);
}

/* The CORDIC's wm_atan_q16[i] = atan(2^-i) in Q16 radians, i = 0..16 (WM_ANGLE_STEPS), and WM_HALF_PI_Q16
 * come from the generated wm_angle.h (host/wavemesh/model/angle.py, their one source, and the angle unit's). */

int32_t wm_angle_q16(int64_t x, int64_t y)
{
    int32_t z = 0;
    WM_ASSERT(y >= 0);
#ifdef WM_ANGLE_ENGINE
    if (x >= INT32_MIN && x <= INT32_MAX && y <= INT32_MAX) /* the board's refiner: the FPGA's angle unit */
        return wm_tri_engine_angle((int32_t)x, (uint32_t)y);
#endif
    /* Scale both down (toward zero, exactly the same everywhere) below 2^28: CORDIC grows them by
     * 1.65 and adds shifted copies, all inside int64. */
    while (x > ((int64_t)1 << 28) || x < -((int64_t)1 << 28) || y > ((int64_t)1 << 28)) {
        x = shr0(x, 1);
        y = shr0(y, 1);
    }
    if (x < 0) { /* rotate by -90 degrees: (x, y) -> (y, -x), angle - 90 */
        int64_t t = x;
        x = y;
        y = -t;
        z = WM_HALF_PI_Q16;
    }
    /* Scale small vectors up (exactly) for precision: CORDIC's shifts then keep 27 bits.  Both are
     * >= 0 and <= 2^28 here, so doubling until one reaches 2^27 is one shift by 28 minus the bit length
     * of x | y (the larger's length): a third of the function's instructions as a loop (the doubling
     * ran ten to twenty times for a triangle's few-hundred-sample sides). */
    if ((x | y) != 0 && x < ((int64_t)1 << 27) && y < ((int64_t)1 << 27)) {
        int s = 28 - wm_bit_length64((uint64_t)(x | y));
        x *= (int64_t)1 << s;
        y *= (int64_t)1 << s;
    }
    /* The rotations in 32 bits (the soft CPU's word): x and y start in [0, 2^28], the length grows by
     * at most 1.65 and is at most 2^28.5 to begin with, so |x|, |y| < 2^30 throughout; x never falls
     * (each step adds |y| 2^-i), so it stays >= 0 and shifts as unsigned. */
    {
        uint32_t ux = (uint32_t)x;
        int32_t iy = (int32_t)y;
        /* each step turns toward y = 0, by the sign of y: as a mask m (all ones for y < 0), not a branch
         * (which went either way about as often) */
        for (int i = 0; i < WM_ANGLE_STEPS && iy != 0; i++) {
            uint32_t m = 0u - ((uint32_t)iy >> 31), ay = ((uint32_t)iy ^ m) - m, xs = ux >> i; /* ay = |y| */
            ux += ay >> i;                                      /* x grows by |y| 2^-i */
            iy -= (int32_t)((xs ^ m) - m);                      /* y moves toward 0 by x 2^-i */
            z += (int32_t)(((uint32_t)wm_atan_q16[i] ^ m) - m); /* by the step's angle, signed as y */
        }
    }
    return z < 0 ? 0 : z;
}

void wm_min_corner(const int32_t x[3], const int32_t y[3], int64_t *dot, int64_t *cross)
{
    wm_min_corner_in(x, y, dot, cross);
}

int32_t wm_min_angle(const int32_t x[3], const int32_t y[3])
{
    int64_t dot, cross;
    wm_min_corner(x, y, &dot, &cross);
    return wm_angle_q16(dot, cross);
}

/* wm_angle_q16 is within 10 of atan2 in Q16 (its 17 table entries rounded to nearest, 1/2 each; the
 * angle left after the 17th rotation below atan 2^-16 < 1; the shifts' truncations of vectors of at
 * least 2^27 far below 1), and the smallest angle theta is at most pi/3 (68,629.06 in Q16), so
 * theta <= tan theta = |cross| / dot bounds it (tight for the small angles that decide swaps). */
#define ANGLE_SLACK 16

int32_t wm_angle_above(int64_t dot, int64_t cross)
{
    const int32_t cap = 68630 + ANGLE_SLACK;
    uint64_t n, q;
    if (dot <= 0) return cap; /* not a triangle of a proper mesh: its smallest angle is below 90 degrees */
    n = (uint64_t)cross << 16; /* < 2^47: cross < 2^31 (sides below 2^15) */
    q = n >> 32 == 0 && (uint64_t)dot >> 32 == 0 ? (uint32_t)n / (uint32_t)dot : n / (uint64_t)dot;
    return q + 1 + ANGLE_SLACK >= (uint64_t)cap ? cap : (int32_t)q + 1 + ANGLE_SLACK;
}

uint64_t wm_scale_mul(const wm_params *p, uint64_t n, uint64_t d, int sh, uint64_t cap)
{
    uint64_t q;
    int k = sh - p->scale_e;
    if (d != 1) return wm_frac_mul(n, d, p->scale_m, p->scale_e, sh, cap);
    /* wm_frac_mul's result for d = 1 (every caller: the regularisation's E in height units, the pairing's
     * height steps), without its divisions by 1 (two or three 32-bit ones on the soft CPU): q = n m, no
     * remainder */
    WM_ASSERT(n < ((uint64_t)1 << 47) && p->scale_m < 65536u && sh <= 16);
    q = n * p->scale_m;
    if (k <= 0) q = -k >= 64 ? 0 : q >> -k;
    else if (q > (cap >> k)) return cap;
    else q <<= k;
    return q > cap ? cap : q;
}
