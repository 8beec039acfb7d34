/* 64-bit division for the board (rv32): the compiler's __udivdi3 and __divdi3, linked before libgcc's.
 *
 * The refiner divides 64-bit integers (E(T)'s rounding, the slope factor's scales, the unit normals,
 * the Jacobi rotations: firmware/src); on rv32 each is a call.  libgcc's routine works in 16-bit
 * digits with a division *and* a remainder instruction per digit, and the CPU's divider takes some 33
 * cycles for either: four of them for a 64-bit dividend over a 32-bit divisor, eight when the quotient
 * has more than 32 bits, even for operands that fit in 32 bits.  Here each remainder is a multiply and
 * a subtraction (one cycle), and the common sizes take the short ways:
 *
 * - dividend and divisor below 2^32: one 32-bit division;
 * - divisor below 2^32: one division for the quotient's high word when it has one, then the 64 / 32
 *   step (Hacker's Delight, divlu: two 16-bit digits, two divisions);
 * - divisor of 2^32 or more (the quotient fits in 32 bits): the divisor's top 32 bits normalised, one
 *   64 / 32 step and at most one correction (Hacker's Delight, divlu64).
 *
 * The results are the C operators' (truncated quotients; a zero divisor is the caller's error, as
 * with libgcc's): tests/firmware/test_div64.py checks them natively against Python's integers, and
 * the board meshes against the native build's.  WM_DIV64_UDIV / WM_DIV64_SDIV rename the two for
 * that test (a native build calls no such helpers); WM_DIV64_UMOD, __umoddi3, the remainder, likewise.
 *
 * The board's program (WM_DIV64_ENGINE, firmware/board/CMakeLists.txt) hands every division that needs
 * more than one 32-bit division to the FPGA's 64-bit divider (rtl/udiv64.v behind the ENGINE registers:
 * four register writes, 16 to 64 steps two a clock, the quotient's two words), and keeps the 32 / 32
 * division and the n < d answer here. */
#include <stdint.h>

#include "wm_inline.h"
#ifdef WM_DIV64_ENGINE
#include "wm_memmap.h"
#endif

#ifndef WM_DIV64_UDIV
#define WM_DIV64_UDIV __udivdi3
#define WM_DIV64_SDIV __divdi3
#define WM_DIV64_UMOD __umoddi3
#endif

uint64_t WM_DIV64_UDIV(uint64_t n, uint64_t d);
int64_t WM_DIV64_SDIV(int64_t n, int64_t d);
uint64_t WM_DIV64_UMOD(uint64_t n, uint64_t d);

/* The leading zeros of v != 0, without branches (rv32imc has no clz; libgcc's __clzsi2 is a call and a
 * table lookup). */
static WM_ALWAYS_INLINE int clz32(uint32_t v)
{
    int n, s;
    s = (v < 0x10000u) << 4;
    v <<= s;
    n = s;
    s = (v < 0x1000000u) << 3;
    v <<= s;
    n += s;
    s = (v < 0x10000000u) << 2;
    v <<= s;
    n += s;
    s = (v < 0x40000000u) << 1;
    v <<= s;
    n += s;
    return n + (v < 0x80000000u);
}

/* The value of q, hidden from the optimiser: x - (x / y) * y stays a multiply and a subtraction (the
 * compiler would make it a remainder instruction, another 33 cycles of the divider). */
static WM_ALWAYS_INLINE uint32_t opaque(uint32_t q)
{
    __asm__("" : "+r"(q));
    return q;
}

/* One 16-bit digit of the quotient (divlu's step): (un * 2^16 + next) / (vn1 * 2^16 + vn0), the divisor
 * normalised and the quotient below 2^16, estimated from vn1 and corrected at most twice. */
static WM_ALWAYS_INLINE uint32_t digit(uint32_t un, uint32_t next, uint32_t vn1, uint32_t vn0)
{
    const uint32_t b = 0x10000u;
    uint32_t q = opaque(un / vn1), rhat = un - q * vn1;
    while (q >= b || q * vn0 > b * rhat + next) {
        q--;
        rhat += vn1;
        if (rhat >= b) break;
    }
    return q;
}

/* (u1 * 2^32 + u0) / v for u1 < v (so the quotient fits in 32 bits). */
static WM_ALWAYS_INLINE uint32_t div_64_32(uint32_t u1, uint32_t u0, uint32_t v)
{
    const uint32_t b = 0x10000u;
    uint32_t vn1, vn0, un32, un10, un1, un0, un21, q1, q0;
    int s = clz32(v); /* v > u1 >= 0 */
    v <<= s;
    vn1 = v >> 16;
    vn0 = v & 0xFFFFu;
    un32 = s ? u1 << s | u0 >> (32 - s) : u1;
    un10 = u0 << s;
    un1 = un10 >> 16;
    un0 = un10 & 0xFFFFu;
    q1 = digit(un32, un1, vn1, vn0);
    un21 = un32 * b + un1 - q1 * v;
    q0 = digit(un21, un0, vn1, vn0);
    return q1 * b + q0;
}

uint64_t WM_DIV64_UDIV(uint64_t n, uint64_t d)
{
    uint32_t nh = (uint32_t)(n >> 32), nl = (uint32_t)n, dh = (uint32_t)(d >> 32), dl = (uint32_t)d;
    uint32_t qh, q;
    int s;
#ifdef WM_DIV64_ENGINE
    if (nh == 0 && dh == 0) return nl / dl;
    if (nh < dh) return 0; /* n < d */
    WM_ENGINE_DIV_N_LO = nl;
    WM_ENGINE_DIV_N_HI = nh;
    WM_ENGINE_DIV_D_LO = dl;
    WM_ENGINE_DIV_D_HI = dh; /* starts it */
    while (!(WM_ENGINE_DIV_STATUS & WM_ENGINE_DIV_STATUS_DONE)) {
        /* the divider's steps */
    }
    qh = WM_ENGINE_DIV_Q_HI;
    return (uint64_t)qh << 32 | WM_ENGINE_DIV_Q_LO;
#endif
    if (dh == 0) {
        if (nh == 0) return nl / dl;
        if (nh < dl) return div_64_32(nh, nl, dl);
        qh = opaque(nh / dl);
        return (uint64_t)qh << 32 | div_64_32(nh - qh * dl, nl, dl);
    }
    if (nh < dh) return 0; /* n < d */
    /* d >= 2^32: the top 32 bits of d normalised divide n / 2 (below 2^63, so its high word is below
     * them); the estimate is the quotient or one more, made at most it by the decrement */
    s = clz32(dh);
    q = div_64_32(nh >> 1, nh << 31 | nl >> 1, s ? dh << s | dl >> (32 - s) : dh) >> (31 - s);
    if (q) q--;
    if (n - (uint64_t)q * d >= d) q++;
    return q;
}

int64_t WM_DIV64_SDIV(int64_t n, int64_t d)
{
    uint64_t q = WM_DIV64_UDIV(n < 0 ? -(uint64_t)n : (uint64_t)n, d < 0 ? -(uint64_t)d : (uint64_t)d);
    return (int64_t)((n < 0) != (d < 0) ? -q : q);
}

/* The remainder from the quotient (a multiply and a subtraction): the refiner's few 64-bit remainders
 * (fixed.c's wm_scale_mul, the C slope factor's) would otherwise link libgcc's __umoddi3 and its
 * __clz_tab, 1.2 KB of firmware RAM for code no board job runs often. */
uint64_t WM_DIV64_UMOD(uint64_t n, uint64_t d) { return n - WM_DIV64_UDIV(n, d) * d; }
