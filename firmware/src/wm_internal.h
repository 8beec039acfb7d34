/* Internal helpers shared by the firmware sources (not part of the public API). */
#ifndef WM_INTERNAL_H
#define WM_INTERNAL_H

#include "wavemesh.h"
#include "wm_inline.h"

/* Asserts: on with WM_CHECK=1 (debug and sanitizer builds), off otherwise.  A hosted build uses
 * <assert.h>; a freestanding one (the soft CPU) traps. */
#ifndef WM_CHECK
#define WM_CHECK 0
#endif
#if WM_CHECK
#if defined(__STDC_HOSTED__) && __STDC_HOSTED__
#include <assert.h>
#define WM_ASSERT(c) assert(c)
#else
#define WM_ASSERT(c) ((c) ? (void)0 : __builtin_trap())
#endif
/* The full invariant check after every operator. */
#define WM_CHECK_MESH(m) WM_ASSERT(wm_mesh_check(m) == WM_OK)
#else
#define WM_ASSERT(c) ((void)0)
#define WM_CHECK_MESH(m) ((void)0)
#endif

/* 1: take the exact 32-bit-division paths (wm_udiv_small, wm_ceil_q16_div's digits) where a 64-bit
 * division is a library call of some 300 cycles (32-bit CPUs: the soft CPU); on x86-64 one instruction
 * does, and the paths would add instructions.  The checked (debug) builds take them too, so the tests
 * run them natively against the release build's plain divisions. */
#ifndef WM_NARROW_DIV
#define WM_NARROW_DIV (UINTPTR_MAX <= 0xFFFFFFFFu || WM_CHECK)
#endif

/* 0 where one 64-bit division is cheaper than two or three 32-bit ones: the board's refiner
 * (WM_DIV64_ENGINE, firmware/board/CMakeLists.txt), whose 64-bit division is the FPGA divider's (div64.c:
 * one 32-bit division when both fit 32 bits, else the engine's 26 to 34 clocks) and each 32-bit one some
 * 33 cycles and a call: there wm_ceil_q16_div and wm_udiv_small divide once (the same integers; wm_frac_mul
 * keeps its two 32-bit divisions, which measured cheaper than the divider's call).  1 elsewhere:
 * natively the 32-bit divisions are the quicker instructions. */
#ifdef WM_DIV64_ENGINE
#define WM_SPLIT_DIV 0
#else
#define WM_SPLIT_DIV 1
#endif

#define WM_TRI(e) ((e) / 3)

/* Profiling counters (WM_PROFILE=1: the profile build, firmware/CMakeLists.txt's WM_PROFILE option, for
 * bench/refiner_instructions.py --scans; never the library the host loads nor the board's image): what
 * the refiner's E(T) work costs by phase, in units the FPGA's triangle engine would take over (samples
 * visited by scans) and units left to the CPU (scans, slope factors, point errors). */
#ifndef WM_PROFILE
#define WM_PROFILE 0
#endif
enum { WM_PH_LEVELS, WM_PH_REDUCE, WM_PH_BOUND, WM_PH_DECIMATE, WM_PH_COUNT };
enum { WM_PC_SCANS, WM_PC_SAMPLES, WM_PC_ROWS, WM_PC_SLOPES, WM_PC_POINTS, WM_PC_COUNT };
#if WM_PROFILE
extern int wm_prof_phase;                                /* the phase now running (WM_PH_*) */
extern uint64_t wm_prof_count[WM_PH_COUNT][WM_PC_COUNT]; /* per phase: WM_PC_* */
#define WM_PROF_ADD(what, n) (wm_prof_count[wm_prof_phase][what] += (uint64_t)(n))
#define WM_PROF_SET(ph) (wm_prof_phase = (ph)) /* the phases follow each other, none nests */
#else
#define WM_PROF_ADD(what, n) ((void)0)
#define WM_PROF_SET(ph) ((void)0)
#endif

/* (k + 1) % 3 and (k + 2) % 3 for a corner k in 0..2, without a division: GCC keeps % 3 as one on rv32
 * (some 40 cycles on the PicoRV32) even in a loop of three. */
static inline int wm_k1(int k) { return k == 2 ? 0 : k + 1; }
static inline int wm_k2(int k) { return k == 0 ? 2 : k - 1; }

/* wm_mesh_check, returning 0 or the source line of the first failed invariant (for debugging). */
int wm_mesh_check_line(const wm_mesh *m);

/* Twice the signed area of (a, b, c): > 0 counter-clockwise.  Exact in 32-bit arithmetic for grid
 * coordinates (0..WM_MAX_SIDE - 1, WM_MAX_SIDE < 2^15, as every caller's are): each difference is below
 * 2^15 - 1 in magnitude, each product below 2^30 and their difference below 2^31 (on the soft CPU a
 * multiply each, not a multiply pair and a 64-bit subtraction); the result widened for the callers. */
static inline int64_t wm_orient(int32_t ax, int32_t ay, int32_t bx, int32_t by, int32_t cx, int32_t cy)
{
    WM_ASSERT((uint32_t)ax < WM_MAX_SIDE && (uint32_t)ay < WM_MAX_SIDE && (uint32_t)bx < WM_MAX_SIDE &&
              (uint32_t)by < WM_MAX_SIDE && (uint32_t)cx < WM_MAX_SIDE && (uint32_t)cy < WM_MAX_SIDE);
    return (bx - ax) * (cy - ay) - (cx - ax) * (by - ay);
}

static inline int32_t wm_dest(const wm_mesh *m, int32_t e) { return m->he[WM_NEXT(e)].v; }

/* 1 when a and b lie strictly on opposite sides of the line c-d: for the edge a-b between the
 * counter-clockwise (a, b, c) and (b, a, d), whose c and d lie strictly on opposite sides of a-b, the
 * quadrilateral a-d-b-c is strictly convex (wm_edge_swappable; the legalisation's flips). */
static inline int wm_quad_convex(const wm_mesh *m, int32_t a, int32_t b, int32_t c, int32_t d)
{
    int64_t sa = wm_orient(m->vxy[c].x, m->vxy[c].y, m->vxy[d].x, m->vxy[d].y, m->vxy[a].x, m->vxy[a].y);
    int64_t sb = wm_orient(m->vxy[c].x, m->vxy[c].y, m->vxy[d].x, m->vxy[d].y, m->vxy[b].x, m->vxy[b].y);
    return (sa > 0 && sb < 0) || (sa < 0 && sb > 0);
}

static inline int wm_tri_live(const wm_mesh *m, int32_t t)
{
    return t >= 0 && t < m->tri_end && m->he[3 * t].v >= 0;
}

static inline int wm_on_border(const wm_mesh *m, int32_t x, int32_t y)
{
    return x == 0 || y == 0 || x == m->width - 1 || y == m->height - 1;
}

/* Room for an operator that adds `tris` triangles and one vertex (the splits): free triangle slots (the
 * free list's and those past tri_end) and a vertex slot. */
static inline int wm_room_for_split(const wm_mesh *m, int32_t tris)
{
    return m->tri_cap - m->n_tri >= tris && m->n_vert < m->vert_cap;
}

/* Allocation of slots (free list first, then the end); -1 when full. */
int32_t wm_vert_alloc(wm_mesh *m, int32_t x, int32_t y);
/* A triangle slot, inline and without placeholder stores to he[]: its callers (the splits) write
 * every one of them (on the board each a store the write buffer waited on, and the call a split's
 * largest cost after its loads).  -1 when full. */
static inline int32_t wm_tri_take(wm_mesh *m)
{
    int32_t t;
    if (m->tri_free >= 0) {
        t = m->tri_free;
        m->tri_free = m->he[3 * t].o;
    } else {
        if (m->tri_end >= m->tri_cap) return -1;
        t = m->tri_end++;
    }
    m->n_tri++;
    m->tflag[t] = 0;
    return t;
}
/* Writes triangle t's three vertices (its half-edges' origins). */
static inline void wm_tri_set(wm_mesh *m, int32_t t, int32_t a, int32_t b, int32_t c)
{
    m->he[3 * t].v = a;
    m->he[3 * t + 1].v = b;
    m->he[3 * t + 2].v = c;
}
/* Makes e and f opposite (f may be -1: e on the border). */
static inline void wm_link(wm_mesh *m, int32_t e, int32_t f)
{
    m->he[e].o = f;
    if (f >= 0) m->he[f].o = e;
}
/* Points vh of triangle t's vertices at t's half-edges. */
void wm_tri_claim(wm_mesh *m, int32_t t);
/* wm_edge_swap of an edge the caller has found wm_edge_swappable (the mesh unchanged since). */
void wm_edge_swap_convex(wm_mesh *m, int32_t e, int32_t touched[2], int32_t *n_touched);
/* The swap itself, e = a->b in T1 = (a, b, c), f = b->a in T2 = (b, a, d): the triangles (a, d, c) and
 * (d, b, c) in the same slots, their outer edges linked as before, and each corner's half-edge (vh) the
 * one of the new triangles wm_tri_claim of T1 and then T2 leaves it.  Inline in wm_edge_swap_convex and
 * the legalisation (as a call each of the error bound's flips cost the board some 25 cycles more). */
static WM_ALWAYS_INLINE void wm_flip(wm_mesh *m, int32_t e, int32_t f, int32_t t1, int32_t t2, int32_t a,
                                     int32_t b, int32_t c, int32_t d)
{
    int32_t e1 = 3 * t1, e2 = 3 * t2;
    int32_t o_bc = m->he[WM_NEXT(e)].o, o_ca = m->he[WM_PREV(e)].o, o_ad = m->he[WM_NEXT(f)].o,
            o_db = m->he[WM_PREV(f)].o;
    m->he[e1].v = a;
    m->he[e1 + 1].v = d;
    m->he[e1 + 2].v = c;
    m->he[e2].v = d;
    m->he[e2 + 1].v = b;
    m->he[e2 + 2].v = c;
    wm_link(m, e1, o_ad);       /* a->d */
    wm_link(m, e1 + 1, e2 + 2); /* d->c with c->d */
    wm_link(m, e1 + 2, o_ca);   /* c->a */
    wm_link(m, e2, o_db);       /* d->b */
    wm_link(m, e2 + 1, o_bc);   /* b->c */
    m->vh[a] = e1;
    m->vh[d] = e2; /* T2's claim after T1's */
    m->vh[b] = e2 + 1;
    m->vh[c] = e2 + 2;
}
/* The same with its half-edges, triangles and corners known: e = a->b in (a, b, c), slot t1 = WM_TRI(e),
 * f = he[e].o in (b, a, d), slot t2 = WM_TRI(f). */
static WM_ALWAYS_INLINE void wm_edge_flip(wm_mesh *m, int32_t e, int32_t f, int32_t t1, int32_t t2, int32_t a,
                                          int32_t b, int32_t c, int32_t d)
{
    WM_ASSERT(wm_edge_swappable(m, e) && m->he[e].o == f && m->he[e].v == a && m->he[f].v == b &&
              m->he[WM_PREV(e)].v == c && m->he[WM_PREV(f)].v == d && t1 == WM_TRI(e) && t2 == WM_TRI(f));
    wm_flip(m, e, f, t1, t2, a, b, c, d);
    WM_CHECK_MESH(m);
}

/* wm_tri_split of a point (x, y) the caller knows strictly inside live t, and wm_edge_split of one it knows
 * strictly inside edge e (the error bound's worst samples): the same, without the tests of the point
 * (WM_ERR_CAPACITY still). */
int wm_tri_split_inside(wm_mesh *m, int32_t t, int32_t x, int32_t y, int32_t touched[3], int32_t *n_touched);
int wm_edge_split_inside(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t touched[4], int32_t *n_touched);

/* Rotation around a vertex: e is a half-edge leaving v.  Counter-clockwise: the next half-edge
 * leaving v, or -1 at the border.  wm_fan_first: the most clockwise half-edge leaving v (vh[v] for an
 * interior vertex). */
static inline int32_t wm_rot_ccw(const wm_mesh *m, int32_t e) { return m->he[WM_PREV(e)].o; }
static inline int32_t wm_rot_cw(const wm_mesh *m, int32_t e)
{
    int32_t o = m->he[e].o;
    return o < 0 ? -1 : WM_NEXT(o);
}
int32_t wm_fan_first(const wm_mesh *m, int32_t v);

#define WM_CLASS_UNKNOWN (-1) /* r->vapex: no class known for the vertex's current star (reduce.c) */

/* Fixed-point and exact integer helpers (fixed.c). */
/* floor(a / b) for b > 0 in 32 bits (the soft CPU divides 32-bit numbers in hardware, 64-bit ones in a
 * library routine many times slower). */
static inline int32_t wm_floor_div32(int32_t a, int32_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
/* ceil(a / b) for b > 0 in 32 bits (wm_floor_div32's twin). */
static inline int32_t wm_ceil_div32(int32_t a, int32_t b) { return a >= 0 ? (a + b - 1) / b : -((-a) / b); }
/* One end of a 32-bit scan's rows (tri_error.c's scan32, host_scan.c's scan_lanes): floor(u / a) stepped
 * row by row (the remainder r, its step dr), as a pointer into the samples (p, stepped by a row and the
 * quotient's step, st).  Each scan steps it its own way (scan32 with a branch, scan_lanes without). */
struct wm_end32 {
    const uint16_t *p;
    int32_t r, dr, a, st, q, dq;
};
/* The end at a row whose quotient q and remainder r (of its numerator by a) are known; du the numerator's
 * step a row. */
static WM_ALWAYS_INLINE void wm_end_at(struct wm_end32 *e, const uint16_t *row, int32_t width, int32_t q,
                                       int32_t r, int32_t du, int32_t a)
{
    e->q = q;
    e->r = r;
    e->dq = wm_floor_div32(du, a);
    e->dr = du - e->dq * a;
    e->a = a;
    e->p = row + e->q;
    e->st = width + e->dq;
}
/* The end at a row (its first sample row): u and du, the numerator and its step a row. */
static WM_ALWAYS_INLINE void wm_end_start(struct wm_end32 *e, const uint16_t *row, int32_t width, int32_t u,
                                          int32_t du, int32_t a)
{
    int32_t q = wm_floor_div32(u, a);
    wm_end_at(e, row, width, q, u - q * a, du, a);
}
/* A 32-bit scan's worst sample as its grid place, from its address at (NULL while no V beat 0: the first
 * corner), into whichever of wx, wy is not NULL: at the scan's end, once (tri_error.c's scan32, host_scan.c's
 * lanes; a caller asking for neither skips the division). */
static WM_ALWAYS_INLINE void wm_place_at(const wm_field *f, const uint16_t *at, const int32_t x[3],
                                         const int32_t y[3], int32_t *wx, int32_t *wy)
{
    if (at) {
        int32_t i = (int32_t)(at - f->samples), ay = i / f->width;
        if (wx) *wx = i - ay * f->width;
        if (wy) *wy = ay;
    } else {
        if (wx) *wx = x[0];
        if (wy) *wy = y[0];
    }
}
/* The error bound's heap of triangle slots (mesh_state.c), the largest key first: ties go to the lower
 * slot, so the order is total and any heap pops the same sequence.  An entry holds its slot with the
 * slot's key (E(T)), equal to err[] at every step, so a sift compares entries it has loaded, both
 * children in 16 bytes (one cache line when the entries start at 8 mod 16, else at every other node
 * two: docs/refiner.md, "Tried and not kept"), instead of reading the keys' array at every slot it
 * passes (a random line each: on the board, err[] of a large mesh is far beyond the data cache).  Each
 * slot's place is in pos[].
 * The entries live in list[]'s storage (sized for tri_cap of them: refine.c), which the
 * other phases use as wm_index words; WM_MAY_ALIAS tells the compiler so. */
typedef struct WM_MAY_ALIAS wm_hent {
    uint32_t key;
    wm_index t;
} wm_hent;

static WM_ALWAYS_INLINE int wm_heap_before(uint32_t ka, int32_t a, uint32_t kb, int32_t b)
{
    return ka > kb || (ka == kb && a < b);
}

static WM_ALWAYS_INLINE void wm_heap_put(wm_hent *h, wm_index *pos, int32_t i, uint32_t key, int32_t t)
{
    h[i].key = key, h[i].t = (wm_index)t, pos[t] = (wm_index)i;
}

/* Entry (key, t) at i (h[i] itself not read) up past the parents it is before; 1 when it moved. */
static WM_ALWAYS_INLINE int wm_heap_up(wm_hent *h, wm_index *pos, int32_t i, uint32_t key, int32_t t)
{
    int32_t i0 = i;
    while (i > 0) {
        int32_t p = (i - 1) / 2;
        wm_hent u = h[p];
        if (!wm_heap_before(key, t, u.key, u.t)) break;
        wm_heap_put(h, pos, i, u.key, u.t);
        i = p;
    }
    wm_heap_put(h, pos, i, key, t);
    return i != i0;
}

/* Entry (key, t) at i (no parent it is before) down past the children before it. */
static WM_ALWAYS_INLINE void wm_heap_down(wm_hent *h, wm_index *pos, int32_t i, int32_t n, uint32_t key, int32_t t)
{
    for (;;) {
        int32_t c = 2 * i + 1;
        wm_hent u;
        if (c >= n) break;
        u = h[c];
        if (c + 1 < n) {
            wm_hent w = h[c + 1];
            if (wm_heap_before(w.key, w.t, u.key, u.t)) c++, u = w;
        }
        if (!wm_heap_before(u.key, u.t, key, t)) break;
        wm_heap_put(h, pos, i, u.key, u.t);
        i = c;
    }
    wm_heap_put(h, pos, i, key, t);
}

/* The entry at i sifted down when it most likely sinks to the bottom (the heap's last one, moved into
 * the place of one taken out): the hole first goes down the children that come first to a leaf, one
 * comparison a level, then the entry comes up from there past what it is before.  The same places as
 * wm_heap_down's (the children the hole passes are those it moves up, the order total), in about half
 * its comparisons. */
static WM_ALWAYS_INLINE void wm_heap_sink(wm_hent *h, wm_index *pos, int32_t i, int32_t n)
{
    wm_hent x = h[i];
    int32_t j = i, m = (n - 1) / 2; /* j < m: both children in the heap */
    while (j < m) {
        int32_t c = 2 * j + 1;
        wm_hent u = h[c], w = h[c + 1];
        if (wm_heap_before(w.key, w.t, u.key, u.t)) c++, u = w;
        wm_heap_put(h, pos, j, u.key, u.t);
        j = c;
    }
    if (2 * j + 1 < n) { /* an only child */
        wm_hent u = h[2 * j + 1];
        wm_heap_put(h, pos, j, u.key, u.t);
        j = 2 * j + 1;
    }
    while (j > i) {
        int32_t p = (j - 1) / 2;
        wm_hent u = h[p];
        if (!wm_heap_before(x.key, x.t, u.key, u.t)) break;
        wm_heap_put(h, pos, j, u.key, u.t);
        j = p;
    }
    wm_heap_put(h, pos, j, x.key, x.t);
}

/* The entry at i out of a heap of n + 1 entries (n: the count after it): its slot's place -1, the last
 * entry moved into its place, up past the parents it is before, else sunk. */
static WM_ALWAYS_INLINE void wm_heap_remove(wm_hent *h, wm_index *pos, int32_t i, int32_t n)
{
    pos[h[i].t] = -1;
    if (i == n) return;
    h[i] = h[n];
    if (i == 0 || !wm_heap_up(h, pos, i, h[i].key, h[i].t)) wm_heap_sink(h, pos, i, n);
}

uint64_t wm_isqrt64(uint64_t x);                        /* floor(sqrt(x)) */
/* ceil(2^16 n / d) for d > 0, n < 2^48 (the result may exceed 32 bits): in 32-bit divisions when
 * n < 2^32 and d < 2^16, as on the board's grids, by long division: n = q d + rem with rem < d, then
 * the next 16 bits of the quotient in one digit (2^16 rem < 2^32), rounded up when a remainder is left.
 * With WM_NARROW_DIV also for d < 2^24 (the slope factors of all but the steepest planes) in two 8-bit
 * digits (2^8 rem < 2^32).  On the board (WM_SPLIT_DIV 0) the one division. */
static inline uint64_t wm_ceil_q16_div(uint64_t n, uint64_t d)
{
    if (WM_SPLIT_DIV && n < ((uint64_t)1 << 32) && d < ((uint64_t)1 << 16)) {
        uint32_t q = (uint32_t)n / (uint32_t)d, rem = (uint32_t)n - q * (uint32_t)d;
        return ((uint64_t)q << 16) + ((rem << 16) + (uint32_t)d - 1u) / (uint32_t)d;
    }
    if (WM_SPLIT_DIV && WM_NARROW_DIV && n < ((uint64_t)1 << 32) && d < ((uint64_t)1 << 24)) {
        uint32_t d32 = (uint32_t)d, q = (uint32_t)n / d32, rem = (uint32_t)n - q * d32, q1, q0;
        q1 = (rem << 8) / d32;
        rem = (rem << 8) - q1 * d32;
        q0 = (rem << 8) / d32;
        rem = (rem << 8) - q0 * d32;
        return ((uint64_t)q << 16) + (q1 << 8) + q0 + (rem != 0);
    }
    return (n * 65536u + d - 1) / d;
}
/* n / d and its remainder (*rem) for 0 < d < 2^16, by long division in 16-bit digits: each partial
 * dividend, remainder (< d) times 2^16 plus the next digit, is below 2^32, so every step is one 32-bit
 * division (one for n < 2^32, three above) where a 64-bit division is a library call on the soft CPU
 * (some 300 cycles).  On the board (WM_SPLIT_DIV 0) n >= 2^32 takes the one 64-bit division instead,
 * the FPGA divider's.  The same quotient and remainder as n / d, n % d. */
static inline uint64_t wm_udiv_small(uint64_t n, uint32_t d, uint32_t *rem)
{
    uint32_t hi, mid, lo, q2, q1, q0;
    if (n >> 32 == 0) {
        q0 = (uint32_t)n / d;
        *rem = (uint32_t)n - q0 * d;
        return q0;
    }
    if (!WM_SPLIT_DIV) {
        uint64_t q = n / d;
        *rem = (uint32_t)n - (uint32_t)q * d; /* the remainder, below d: modulo 2^32 */
        return q;
    }
    hi = (uint32_t)(n >> 32);
    q2 = hi / d;
    mid = (hi - q2 * d) << 16 | (uint32_t)(n >> 16 & 0xFFFFu);
    q1 = mid / d;
    lo = (mid - q1 * d) << 16 | (uint32_t)(n & 0xFFFFu);
    q0 = lo / d;
    *rem = lo - q0 * d;
    return ((uint64_t)q2 << 32) + ((uint64_t)q1 << 16) + q0;
}
/* round(2^28 C / L) as the unit normals round it, floor((2^28 C + floor(L / 2)) / L), for 2^29 <= L < 2^31
 * and C <= L, with inv = floor((2^61 - 1) / L) (< 2^32): for the soft CPU (WM_NARROW_DIV), where each
 * 64-bit division is a library call (on the board the FPGA divider's, some 80 cycles with its call), the
 * three components' quotients by one reciprocal.  inv >= 2^61 / L - 1, so C inv / 2^33 lies in
 * (2^28 C / L - 1/4, 2^28 C / L], within 3/4 below the dividend over L, and its floor is the quotient or
 * one less; the remainder, below 2 L < 2^32, is taken modulo 2^32.  A multiply-high and a multiply where
 * the division was (tests/firmware/test_split_div.py). */
static inline uint32_t wm_q28_div_recip(uint32_t C, uint32_t L, uint32_t inv)
{
    uint32_t q = (uint32_t)(((uint64_t)C * inv) >> 33);
    if ((C << 28) + (L >> 1) - q * L >= L) q++;
    return q;
}
int wm_bit_length64(uint64_t x);                        /* bits of x: 0 for 0, 64 for 2^63 and above */
int32_t wm_gcd(int32_t a, int32_t b);                   /* gcd(|a|, |b|), gcd(0, 0) = 0 */
int64_t wm_floor_div(int64_t a, int64_t b);             /* floor(a / b), b > 0 */
int64_t wm_ceil_div(int64_t a, int64_t b);              /* ceil(a / b), b > 0 */
int wm_cmp_mul(uint64_t a, uint64_t b, uint64_t c, uint64_t d); /* sign(a b - c d), exact */
int32_t wm_angle_q16(int64_t x, int64_t y);             /* atan2(y, x) for y >= 0, Q16 radians */
/* floor(n * s * 2^sh / d) with the height scale s = scale_m / 2^scale_e, saturated at cap. */
uint64_t wm_scale_mul(const wm_params *p, uint64_t n, uint64_t d, int sh, uint64_t cap);
/* The same with the scale m / 2^e (m < 2^16, e in 0..126).  Inline, as wm_slope_scale: the normal
 * metric's slope factor takes both twice for every E(T) and point error. */
static inline uint64_t wm_frac_mul(uint64_t n, uint64_t d, uint32_t m, int32_t e, int sh, uint64_t cap)
{
    uint64_t prod, q, r, res;
    int k = sh - e;
    WM_ASSERT(d > 0 && n < ((uint64_t)1 << 47) && m < 65536u && sh <= 16);
    prod = n * m; /* < 2^63 */
    if (WM_NARROW_DIV && d < 65536u && n >> 32 == 0 && prod >> 32 != 0) {
        /* n = q1 d + r1 (r1 < d < 2^16), so n m = (q1 m + q2) d + r with r1 m = q2 d + r, r1 m < 2^32:
         * two 32-bit divisions where wm_udiv_small takes three (one when n m < 2^32) */
        uint32_t d32 = (uint32_t)d, q1 = (uint32_t)n / d32, t = ((uint32_t)n - q1 * d32) * m, q2 = t / d32;
        q = (uint64_t)q1 * m + q2;
        r = t - q2 * d32;
    } else if (WM_NARROW_DIV && d < 65536u) { /* 32-bit divisions only (wm_udiv_small) */
        uint32_t r32;
        q = wm_udiv_small(prod, (uint32_t)d, &r32);
        r = r32;
    } else {
        q = prod / d;
        r = prod % d;
    }
    if (k <= 0) {
        res = (-k >= 64) ? 0 : q >> (-k);
    } else {
        if (q > (cap >> k)) return cap;
        /* r < d and k <= 16 (e >= 0): no overflow, and r 2^k < 2^32 when d < 2^16 */
        res =
            (q << k) + (WM_NARROW_DIV && d < 65536u && k <= 16 ? (uint32_t)(r << k) / (uint32_t)d : (r << k) / d);
    }
    return res > cap ? cap : res;
}
/* The normal metric's slope scale s / dx (axis 0) or s / dy (axis 1) as (m, e): the slope_* fields,
 * or the height scale when their m is 0 (a cell of 1). */
static inline void wm_slope_scale(const wm_params *p, int axis, uint32_t *m, int32_t *e)
{
    uint32_t sm = axis ? p->slope_y_m : p->slope_x_m;
    *m = sm ? sm : p->scale_m;
    *e = sm ? (axis ? p->slope_y_e : p->slope_x_e) : p->scale_e;
}
/* ceil(n m / 2^e) for n < 2^33, m < 2^16 and e >= 0: s |N| rounded up, for the scale s = m / 2^e (the
 * normal metric's slope numerators, bounded from above without a division). */
static inline uint64_t wm_scaled_up(uint64_t n, uint32_t m, int32_t e)
{
    uint64_t t = n * m;
    if (WM_NARROW_DIV && n >> 32 == 0 && e > 0 && e < 32) {
        /* t + 2^e - 1 below 2^49, shifted word by word in 32-bit operations (the same integer; on rv32 the
         * 64-bit variable shift's branches otherwise) */
        uint64_t u = (uint64_t)(uint32_t)n * m + ((1u << e) - 1u);
        uint32_t lo = (uint32_t)u, hi = (uint32_t)(u >> 32);
        u = ((uint64_t)(hi >> e) << 32) | (lo >> e) | (hi << (32 - e));
        WM_ASSERT(u == (t + ((uint64_t)1 << e) - 1) >> e);
        return u;
    }
    return e >= 49 ? (t != 0) : (t + ((uint64_t)1 << e) - 1) >> e;
}
/* An upper bound of sqrt(a^2 + b^2) for a, b < 2^56: max + (sqrt 2 - 1) min rounded up (the chord of
 * the convex sqrt(1 + t^2) over [0, 1] lies above it; 107 / 256 > sqrt 2 - 1), at most 8.4 % above it. */
static inline uint64_t wm_hypot_up(uint64_t a, uint64_t b)
{
    uint64_t hi = a > b ? a : b, lo = a > b ? b : a;
    return hi + ((lo * 107 + 255) >> 8);
}
/* wm_hypot_up(wm_hypot_up(a, b), d), an upper bound of sqrt(a^2 + b^2 + d^2) (the normal metric's
 * D sqrt(1 + g^2) from D and the scaled gradient numerators), in 32-bit operands when a, b and d are
 * below 2^31 (the same integer: the first bound is then below 2^32, the second's operands too): on the
 * soft CPU (WM_NARROW_DIV) a multiply pair each where the 64-bit operands took three multiplies and
 * their carries, and comparisons of one word; natively the 64-bit ones (fewer instructions there). */
static inline uint64_t wm_hypot3_up(uint64_t a, uint64_t b, uint64_t d)
{
    if (WM_NARROW_DIV && (a | b | d) < ((uint64_t)1 << 31)) {
        uint32_t hi = (uint32_t)(a > b ? a : b), lo = (uint32_t)(a > b ? b : a), h, d32 = (uint32_t)d;
        uint64_t T;
        h = hi + (uint32_t)(((uint64_t)lo * 107u + 255u) >> 8);
        hi = h > d32 ? h : d32, lo = h > d32 ? d32 : h;
        T = hi + (((uint64_t)lo * 107u + 255u) >> 8);
        WM_ASSERT(T == wm_hypot_up(wm_hypot_up(a, b), d));
        return T;
    }
    return wm_hypot_up(wm_hypot_up(a, b), d);
}
/* The smallest angle of a triangle, Q16 radians. */
int32_t wm_min_angle(const int32_t x[3], const int32_t y[3]);
/* wm_min_angle in two steps: the dot and |cross| products at the corner opposite the shortest side
 * (wm_min_angle is wm_angle_q16 of them), and an upper bound of that angle without the CORDIC (the
 * tangent, with the CORDIC's error added; a counter-clockwise triangle: dot > 0). */
void wm_min_corner(const int32_t x[3], const int32_t y[3], int64_t *dot, int64_t *cross);
/* wm_min_corner inline, for the regularisation's swaps (two a swap examined) */
static inline void wm_min_corner_in(const int32_t x[3], const int32_t y[3], int64_t *dot, int64_t *cross)
{
    /* The smallest angle is the one opposite the shortest side (law of sines), so one atan2 does.
     * Two equally short sides have equal angles opposite them, and those corners have the same dot
     * and cross products (the cross product is twice the area at every corner, the dot product
     * |u||v| cos): the same integers, the same CORDIC result, whichever corner is taken.  With the
     * sides s_k = p_k+2 - p_k+1 (opposite corner k), the corner's vectors are s_k+2 and -s_k+1, and in
     * 32 bits: coordinates below 2^15 (WM_MAX_SIDE), so |s|^2, the dot and the cross product are at
     * most 2 (2^15 - 1)^2 < 2^31. */
    int32_t sx[3], sy[3], len[3], k = 0, c, d;
    for (int i = 0; i < 3; i++) {
        sx[i] = x[wm_k2(i)] - x[wm_k1(i)];
        sy[i] = y[wm_k2(i)] - y[wm_k1(i)];
        len[i] = sx[i] * sx[i] + sy[i] * sy[i];
    }
    if (len[1] < len[k]) k = 1;
    if (len[2] < len[k]) k = 2;
    c = wm_k2(k), d = wm_k1(k); /* u = p_k+1 - p_k = s_k+2, v = p_k+2 - p_k = -s_k+1 */
    *dot = -(int64_t)(sx[c] * sx[d] + sy[c] * sy[d]);
    c = sx[1] * sy[2] - sy[1] * sx[2]; /* at corner 0 (u = s_2, v = -s_1): u x v = s_1 x s_2 */
    *cross = c < 0 ? -(int64_t)c : c;
}
int32_t wm_angle_above(int64_t dot, int64_t cross);
/* In-circle predicate, exact for coordinates in 0..WM_MAX_SIDE-1: > 0 when d lies strictly inside
 * the circle through the counter-clockwise a, b, c; 0 on it; < 0 outside. */
static inline int wm_incircle(int32_t ax, int32_t ay, int32_t bx, int32_t by, int32_t cx, int32_t cy, int32_t dx,
                              int32_t dy)
{
    /* Relative to d every difference is below 2^15 in magnitude, so each squared length is below
     * 2^31, each cross product below 2^31, each term below 2^62, the sum of two below 2^63: the
     * sign of the third sum is a comparison, exact in 64 bits.  The lengths and cross products in 32
     * bits, so each term is one 32 x 32 bit product (on the soft CPU a mul and a mulh, where 64-bit
     * operands took four multiplies and their carries). */
    int32_t adx = ax - dx, ady = ay - dy, bdx = bx - dx, bdy = by - dy, cdx = cx - dx, cdy = cy - dy;
    int64_t t1 = (int64_t)(adx * adx + ady * ady) * (bdx * cdy - cdx * bdy);
    int64_t t2 = (int64_t)(bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy);
    int64_t t3 = (int64_t)(cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady);
    int64_t s;
    WM_ASSERT(adx > -32768 && adx < 32768 && ady > -32768 && ady < 32768 && bdx > -32768 && bdx < 32768 &&
              bdy > -32768 && bdy < 32768 && cdx > -32768 && cdx < 32768 && cdy > -32768 && cdy < 32768);
    s = t1 + t2;
    return s > -t3 ? 1 : (s < -t3 ? -1 : 0);
}

/* wm_incircle(a, b, p, d) > 0 for the edge a-b between the counter-clockwise (a, b, p) and (b, a, d) (the
 * legalisation's test), by the angles at p and d (Lawson's: d lies strictly inside the circle through a,
 * b, p iff they sum to more than pi, as p and d lie on either side of a-b).  With cos and sin of each
 * times its two sides' lengths (dot and cross products, all below 2^31: differences below 2^15), the sum
 * is more than pi iff sin(alpha + beta) < 0: decided by the two dot products alone when they have the
 * same sign (both angles at most pi / 2: not; both above it: inside), else by the sign of
 * sin_p cos_d + cos_p sin_d in 64 bits (each product below 2^62).  Most edges are refused by the dot
 * products: four products, where the determinant takes twelve and three 64-bit ones. */
static inline int wm_flip_circle(int32_t ax, int32_t ay, int32_t bx, int32_t by, int32_t px, int32_t py,
                                 int32_t dx, int32_t dy)
{
    int32_t pax = ax - px, pay = ay - py, pbx = bx - px, pby = by - py;
    int32_t dax = ax - dx, day = ay - dy, dbx = bx - dx, dby = by - dy;
    int32_t cp = pax * pbx + pay * pby, cd = dax * dbx + day * dby, r;
    int64_t sin_sum; /* sin(alpha + beta) times the four sides' lengths */
    WM_ASSERT(pax > -32768 && pax < 32768 && pay > -32768 && pay < 32768 && pbx > -32768 && pbx < 32768 &&
              pby > -32768 && pby < 32768 && dax > -32768 && dax < 32768 && day > -32768 && day < 32768 &&
              dbx > -32768 && dbx < 32768 && dby > -32768 && dby < 32768);
    /* (a, b, p) and (b, a, d) counter-clockwise */
    WM_ASSERT(pax * pby - pay * pbx > 0 && dbx * day - dby * dax > 0);
    if ((cp ^ cd) >= 0) { /* the same sign: both at most pi / 2, or both above it */
        r = cp < 0;
    } else {
        sin_sum = (int64_t)(pax * pby - pay * pbx) * cd + (int64_t)cp * (dbx * day - dby * dax);
        r = sin_sum < 0;
    }
    WM_ASSERT(r == (wm_incircle(ax, ay, bx, by, px, py, dx, dy) > 0));
    return r;
}

/* The normal metric's slope factor r of a triangle (sqrt(1 + g^2) in Q16.16: tri_error.c) is the same
 * for every measure of the triangle.  A caller that measures one triangle more than once (a point test,
 * then its scan) hands each the same kept word, 0 at first: the first measure that needs r leaves it
 * there and the others take it (r >= 2^16, so 0 means unknown).  NULL: not kept. */
/* E(T)'s measure at the one sample (px, py) of the closed triangle, rounded as E(T) is: never more
 * than wm_tri_error of the same triangle, so a value above zeta rules the triangle out cheaply. */
uint32_t wm_point_error(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t px,
                        int32_t py, uint64_t *kept);
/* wm_point_error(...) > bound, without a division in the vertical metric and without the slope factor's
 * root in the normal one (the cheap tests of the decimation and the reduction; r is kept only when the
 * answer is 0, as the caller then measures the triangle). */
int wm_point_above(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t px,
                   int32_t py, uint32_t bound, uint64_t *kept);
/* wm_point_above's answer once 2^16 |V| > bound D is known (D = twice the area > 0, av = |V| at the
 * sample, no mask, bound < 2^32 - 1): 1 in the vertical metric, the slope factor's test in the normal
 * one (for a caller that has V from its own orientations: decimate.c's fans). */
int wm_point_above_v(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int64_t D,
                     uint64_t av, uint32_t bound, uint64_t *kept);
/* wm_tri_error with a kept word. */
uint32_t wm_tri_error_kept(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                           int32_t *wx, int32_t *wy, uint64_t *kept);
/* wm_tri_error_upto, and while E(T) <= bound also the worst sample as wm_tri_error finds it. */
uint32_t wm_tri_error_within(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                             uint32_t bound, int32_t *wx, int32_t *wy, uint64_t *kept);
/* wm_tri_error's scan, and E(T) with its worst sample when E(T) may be above bound = p->zeta; when the
 * scan's Vmax alone shows E(T) <= bound (2^16 Vmax <= bound D), ev = ceil(2^16 Vmax / D) instead, an
 * upper bound of E(T) at most bound without the normal metric's slope factor, with *exact = 0 (the worst
 * sample is still the scan's).  Else *exact = 1 and the value is wm_tri_error's.  D: twice the area
 * (wm_orient of the corners, > 0), which the caller has worked out (the error bound's, for D = 1). */
uint32_t wm_tri_error_over(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                           int32_t D, int32_t *wx, int32_t *wy, int *exact);
/* For a candidate triangulation whose largest E(T) so far is least (<= bound): some value above bound
 * when E(T) is above it, found with the scan stopped early; else E(T) when it is above least, and
 * otherwise some value at most least (E(T) itself or more).  The decimation's tests need no more, and
 * in the normal metric a triangle that stays within least needs no slope factor. */
uint32_t wm_tri_error_upto(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                           uint32_t bound, uint32_t least, uint64_t *kept);

#ifdef WM_TRI_ENGINE
/* The board's triangle error engine (firmware/board/src/tri_engine.c): E(T)'s scan of the counter-
 * clockwise triangle (x, y) in the FPGA, the same Vmax and sample as the C scan (tri_error.c) into
 * *vmax, *wx, *wy (each may be NULL but vmax); 0 when it cannot take the field (the C scan runs). */
int wm_tri_engine_scan(const wm_field *f, const int32_t x[3], const int32_t y[3], uint64_t limit, uint64_t *vmax,
                       int32_t *wx, int32_t *wy);
#endif

#ifdef WM_ANGLE_ENGINE
/* The engine's angle unit (the board's refiner alone, firmware/board/src/tri_engine.c): wm_angle_q16(x, y)
 * of an x and a y >= 0 of 32 bits, the same CORDIC in the FPGA. */
int32_t wm_tri_engine_angle(int32_t x, uint32_t y);
#endif

#ifdef WM_POINT_ENGINE
/* The engine's point-error unit (the board's refiner alone): wm_point_error(f, p, x, y, px, py, kept) into
 * *e, the same integers in the FPGA; 0 when it cannot take the field (the C computes it). */
int wm_tri_engine_point(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t px,
                        int32_t py, uint64_t *kept, uint32_t *e);
#endif

#if defined(WM_SLOPE_ENGINE) || defined(WM_ROOT_ENGINE)
/* The engine's slope unit alone: floor(sqrt(x)), wm_isqrt64's root (firmware/board/src/tri_engine.c); in
 * the host's shared library (WM_ROOT_ENGINE, firmware/CMakeLists.txt) the processor's square root made
 * exact (firmware/host/host_scan.c): the same integers. */
uint32_t wm_tri_engine_root(uint64_t x);
#endif

#ifdef WM_SLOPE_ENGINE
/* (the board's refiner alone: firmware/board/CMakeLists.txt; the host's library takes the scan's hook
 * above, WM_TRI_ENGINE, and the root's, WM_ROOT_ENGINE, but not these) */
/* The engine's slope unit: the normal metric's slope factor of the counter-clockwise triangle (x, y) as
 * tri_error.c's slope_square and wm_isqrt64 compute it, floor(sqrt(X)) into *root and k into *k (the
 * slope factor is *root << *k); 0 when it cannot take the field (the C computes it). */
int wm_tri_engine_slope(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3],
                        uint32_t *root, int *k);
/* The same in two halves, so that the CPU works beside the unit: _go starts it on the triangle (0: it cannot
 * take the field, and nothing started), _take waits for it, returns the root and sets *k; nothing else
 * may use the slope unit between them. */
int wm_tri_engine_slope_go(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3]);
uint32_t wm_tri_engine_slope_take(int *k);
/* Clears what the engine's hooks know the registers hold (the field, the params, the staged triangle):
 * each board job calls it before its refiner's first (app/board_job.c), as HEIGHT's samples are new. */
void wm_tri_engine_forget(void);
#endif

/* The detail cell (d1, d2, d3) of level m containing grid point (x, y) (x, y in 0..W-1, 0..H-1). */
const int32_t *wm_detail_at(const wm_field *f, int32_t m, int32_t x, int32_t y);

/* The details of level m located once, for a pass over many cells (region.c's selection, pairing.c's
 * plan): wm_detail_at works out the level's offset in the details at every call, on the soft CPU a loop of
 * 64-bit products (some 1 % of Ball 256's refine cycles).  Cell (cx, cy) is d + 3 (cy cw + cx). */
typedef struct {
    const int32_t *d;
    int32_t cw, m;
} wm_level_cells;

static inline wm_level_cells wm_level_cells_of(const wm_field *f, int32_t m)
{
    wm_level_cells c;
    c.d = f->details + wm_details_offset(f->width, f->height, m);
    c.cw = (f->width + (1 << m) - 1) >> m;
    c.m = m;
    return c;
}

/* ---------------------------------------------------------------------------------------------- */
/* The refiner's state (refine.c, region.c, pairing.c) */

/* Triangle flags (wm_mesh.tflag), rebuilt at every iteration. */
#define WM_F_ACTIVE 1u /* in the active region, union of N0 (4.3.1) */
#define WM_F_DEP 2u    /* in the dependent region, union of N1 */
#define WM_F_NEAR 4u   /* in the union of N2: only regularised */
#define WM_F_NEW 8u    /* created or changed by this iteration (counts as N0 for the swaps) */
#define WM_F_PLAN 16u  /* belongs to a planned operation of this iteration (the plan, its execution) */
#define WM_F_SWAP (WM_F_ACTIVE | WM_F_DEP | WM_F_NEAR | WM_F_NEW)
#define WM_F_MEASURE 128u /* error bound, decimation: err[] an upper bound of E(T) within zeta (wm_settle) */
#define WM_F_UNPAIRED \
    WM_F_MEASURE /* levels: planned as unpaired (the regularisation after the splits clears it) */
/* regularisation: WM_F_EXAMINE0 << i, edge i of the triangle (half-edge 3 t + i, the other triangle's
 * slot above t's) is to be examined: not yet in this sweep, or a triangle of it changed since.  Set and
 * read by regularise alone, which takes the plan's bit (WM_F_PLAN, read no more after the execution;
 * the next iteration's wm_select clears every flag) and leaves them as they are when it returns. */
#define WM_F_EXAMINE0 WM_F_PLAN
#define WM_F_EXAMINE (WM_F_EXAMINE0 * 7u)

/* The reduction's unit normals by triangle slot (direct-mapped, slot modulo the cache's size), each with
 * its triangle's corners (y W + x, in the slot's order; key[0] = -1: empty): a normal depends on its
 * corners alone, and R(v) takes every triangle of a star, so each triangle's is asked for by each of its
 * corners.  And the middle eigenvectors (e2 of 4.34, Q30) of the latest collapse-class vertices, by
 * vertex slot (direct-mapped likewise; v = -1: empty), reduce.c.  Both caches have
 * wm_cache_slots(vert_cap) entries in the refiner's storage (refine.c): 128 for a small mesh, up to
 * WM_CACHE_SLOTS_MAX for a large one, whose stars' slot numbers lie farther apart. */
#define WM_CACHE_SLOTS_MAX 1024
struct wm_normal_slot {
    int32_t key[3];
    int32_t n[3];
};

struct wm_ecache_slot {
    int32_t v;
    int32_t e2[3];
};

struct wm_refiner {
    wm_mesh mesh;
    wm_field field;
    wm_params params;
    int32_t level;       /* current resolution level */
    int32_t done;        /* 1 after the error bound at level 0 */
    int32_t limit;       /* most triangles allowed: the budget or the capacity */
    int32_t limit_is_budget;
    int32_t budget_hit;  /* set when the budget stopped an operation (this step) */
    int32_t failed;      /* a WM_ERR_* code that ended the refinement, or 0 */
    int32_t flips, removals; /* this step's legalisation flips and vertex removals */
    /* The regularisation's swaps, whose swap back is known (refine.c): while the levels run (swept = 1;
     * pos[] is free then) pos[t] of both triangles a swap made holds its number (swap_stamp counts them;
     * odd: the swap back is refused, even: made, from the swap's record in vkey), until either changes
     * (wm_forget_class sets pos[t] = -1). */
    int32_t swept, swap_stamp;
    uint32_t *err;       /* [tri_cap] E(T), Q16.16 sample counts, always current */
    int32_t *worst;      /* [tri_cap] the sample (y W + x) where E(T) is reached, always current */
    wm_index *list;      /* [tri_cap] the plan of an iteration, the regularisation's
                            smallest angles (refine.c); its storage holds as many wm_hent, the error
                            bound's heap (wm_heap_entries) */
    wm_index *pos;       /* [tri_cap] heap position of each triangle, -1 when not in it */
    uint32_t *vkey;      /* [vert_cap] the levels: the regularisation's records (refine.c) */
    int8_t *vapex;       /* [vert_cap] reduction: the class of the vertex's star (WM_CLASS_UNKNOWN when it
                            changed); decimation: the dirty flags, by place in its order (decimate.c) */
    const int32_t *roi;  /* NULL, or the region of interest's row prefix counts (roi.c) */
    struct wm_normal_slot *normals; /* [cache_mask + 1] reduce.c's unit normals, kept */
    struct wm_ecache_slot *ecache;  /* [cache_mask + 1] reduce.c's middle eigenvectors, kept */
    int32_t cache_mask;             /* wm_cache_slots(vert_cap) - 1 */
    uint32_t swap_recs;             /* the regularisation's records in vkey: their count - 1 (refine.c) */
};

static inline wm_hent *wm_heap_entries(const wm_refiner *r) { return (wm_hent *)(void *)r->list; }

/* A triangle's edge functions E_k(px, py) = A_k px + B_k py + C_k (>= 0 inside) and its bounding box
 * {xmin, xmax, ymin, ymax}, in 64 bits (tri_error.c), for roi.c and holes.c. */
void wm_tri_edges(const int32_t x[3], const int32_t y[3], int64_t A[3], int64_t B[3], int64_t C[3],
                  int32_t box[4]);

/* The span [*lo, *hi] of the closed triangle on row py, narrowed from the caller's bounding box; 0 when
 * the row has none.  E_k(px, py) = A_k px + B_k py + C_k >= 0 inside (tri_error.c): the generic 64-bit
 * form for roi.c and holes.c; the scans keep their own, with 32-bit divisions for the soft CPU. */
int wm_row_span(const int64_t A[3], const int64_t B[3], const int64_t C[3], int32_t py, int64_t *lo, int64_t *hi);

/* E(T) over the samples of the triangle in the region of interest, 0 when it has none (roi.c). */
uint32_t wm_roi_error(const wm_refiner *r, const int32_t x[3], const int32_t y[3], int32_t *wx, int32_t *wy);

/* Holes (holes.c), for f->mask != NULL: 1 when the mask decides E(T) of the triangle (wm_tri_cover: 0
 * for a hole or a thin triangle, 0xFFFFFFFF with the split sample as the worst for one covering both
 * kinds), with the value in *e and the worst sample in (*wx, *wy) when not NULL; 0 when it covers valid
 * samples only and E(T) is measured as without a mask. */
int wm_hole_error(const wm_field *f, const int32_t x[3], const int32_t y[3], uint32_t *e, int32_t *wx,
                  int32_t *wy);

/* 1 when removing vertex v (its ring of n vertices) with the n - 2 or so triangles tris leaves every
 * valid ring vertex that had a triangle of three valid corners with one (f->mask != NULL; holes.c). */
int wm_hole_keeps_cover(const wm_refiner *r, int32_t v, const int32_t *ring, int32_t n, const int32_t *tris,
                        int32_t nt);
/* After the error bound: each valid vertex in no triangle of three valid corners gets a vertex at one
 * more valid corner of a grid cell with three valid corners it is one of (split where that sample
 * lies, legalised).  Returns the vertices added (the caller runs the bound again while > 0), or an
 * error; stops adding at the budget (holes.c). */
int wm_hole_cover(wm_refiner *r);
/* 1 when sample (px, py) is invalid (f->mask != NULL). */
int wm_hole_at(const wm_field *f, int32_t px, int32_t py);

/* Triangle t's corner coordinates. */
static inline void wm_tri_xy(const wm_mesh *m, int32_t t, int32_t x[3], int32_t y[3])
{
    for (int k = 0; k < 3; k++) {
        int32_t v = m->he[3 * t + k].v;
        x[k] = m->vxy[v].x;
        y[k] = m->vxy[v].y;
    }
}

/* The refiner's mesh state under every phase (mesh_state.c): wm_touch, wm_room, wm_legalise and
 * wm_heap_update; the phases call them, they call no phase. */
/* Recomputes E(T) of t (and its worst sample) and marks it new; forgets its corners' classes. */
void wm_touch(wm_refiner *r, int32_t t);
/* After the error bound and the final decimation: E(T) of every triangle flagged WM_F_MEASURE (err[t]
 * then an upper bound of it, not E(T) itself), as far as the level's E_max needs it (mesh_state.c).  It
 * leaves the mesh's E_max and count over zeta in st->e_max and st->over (the job's last step: so
 * wm_refine_step does not read every slot's he[] again for them, wm_refine_stats). */
void wm_settle(wm_refiner *r, wm_level_stats *st);
/* 0 when an operation adding `added` triangles fits; WM_ERR_CAPACITY when the storage is too
 * small; 1 when the budget forbids it (and records that). */
int wm_room(wm_refiner *r, int32_t added);
/* t was made or changed: the stars of its corners changed, and the reduction's class of each, kept in
 * vapex from pass to pass, is forgotten (reduce.c).  Every operator's new triangles come through here. */
static inline void wm_forget_class(wm_refiner *r, int32_t t)
{
    for (int c = 0; c < 3; c++) r->vapex[r->mesh.he[3 * t + c].v] = WM_CLASS_UNKNOWN;
    if (r->swept) r->pos[t] = -1; /* the regularisation's swaps (refine.c) */
}
/* The error bound's legalisation: Lawson flips of the edges opposite vertex p in the triangles
 * touched[0..n) until every such edge is locally Delaunay (hmm's design), then E(T) of touched[] and
 * of every flipped triangle, once each, as wm_touch.  touched[] and n as wm_tri_split or wm_edge_split
 * left them, p the split's vertex.  heap_n: the error bound's heap (updated; touched[0] its top, the
 * others but wm_edge_split's third new slots), or NULL. */
void wm_legalise(wm_refiner *r, int32_t p, const int32_t *touched, int32_t n, int32_t *heap_n);
/* The error bound's heap (mesh_state.c): re-files t after its E(T) changed to e (err[t]); i = pos[t], its
 * place (-1: in no heap). */
void wm_heap_update(wm_refiner *r, int32_t t, uint32_t e, int32_t i, int32_t *n);
/* The final decimation (decimate.c): removes vertices, in passes over the slots, while every new
 * triangle keeps E(T) <= zeta; returns WM_OK (or a removal's error, which cannot happen). */
int wm_decimate(wm_refiner *r, wm_level_stats *st);
/* The reduction of 4.6 steps 2(d) and 3(b) (reduce.c): one pass over the vertices in slot order,
 * vertex removal where both small eigenvalues of R(v) are below delta_lambda (4.32), else edge
 * collapse where 4.33 and 4.34 hold; each only when every new triangle's E(T) is at most
 * max(zeta, the largest E(T) of the triangles it replaces).  Returns the vertices removed. */
int32_t wm_reduce(wm_refiner *r);
/* The region of interest changes every E(T) and the bound: the reduction's refused removals and
 * collapses are tried again (reduce.c). */
void wm_reduce_forget_refusals(wm_refiner *r);
/* wm_edge_collapse_plan in two parts (edge_collapse.c), for a reduction that tries several collapse
 * points of one edge: the ends' stars and the link condition, which do not depend on the point
 * (WM_OK, the star's error or WM_ERR_REFUSED; e a live triangle's half-edge), then the plan at (x, y)
 * from them (wm_edge_collapse_plan's checks of the point and its triangles; the mesh unchanged since). */
struct wm_collapse_stars {
    int32_t v[2], nb[2][WM_MAX_RING], out[2][WM_MAX_RING], k[2], n[2];
};
int wm_collapse_stars(const wm_mesh *m, int32_t e, struct wm_collapse_stars *s);
int wm_collapse_plan_at(const wm_mesh *m, const struct wm_collapse_stars *s, int32_t x, int32_t y,
                        int32_t tris[6 * WM_MAX_RING], int32_t *n_tris);
/* wm_edge_collapse carried out without planning it again: the collapse of e at (x, y) whose plan
 * (wm_edge_collapse_plan, or wm_collapse_stars and wm_collapse_plan_at) was made on this mesh, WM_OK
 * with nt triangles.  As wm_edge_collapse: WM_ERR_CAPACITY (nothing changed) when the split finds no
 * free slot. */
int wm_edge_collapse_planned(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t nt,
                             int32_t touched[6 * WM_MAX_RING], int32_t *n_touched, int32_t *vertex);
/* R(v) (Q30, as wm_vertex_autocorr) without its eigen-decomposition; the triangle count or an error.
 * kept: NULL, or the normals' cache of kept_mask + 1 slots (a power of two). */
int wm_vertex_r(const wm_mesh *m, const wm_field *f, const wm_params *p, int32_t v, int64_t r[6],
                struct wm_normal_slot *kept, int32_t kept_mask);
/* wm_ring_plan with a probe (the decimation's cheap test, vertex_remove.c): the first planned triangle,
 * in plan order, that holds (px, py) in its closed interior goes to above(ctx, x, y, px, py); when that answers
 * 1, or a planned triangle is one of bad's, the plan is refused at once (WM_ERR_REFUSED) without working out
 * the rest.  (px, py) is the vertex whose ring this is (on no ring edge's outer side).  pr may be NULL.  *big
 * (when big is not NULL) gets the index of the plan's largest triangle (the first of them): the plan
 * works out every triangle's area anyway. */
struct wm_plan_probe {
    int32_t px, py;
    int (*above)(void *ctx, const int32_t x[3], const int32_t y[3], int32_t px, int32_t py);
    void *ctx;
    const uint32_t *bad; /* NULL, or triangles that refuse any plan holding them (bit b of bad[a]: ring
                            positions (a, b, b + 1)) */
};
#if WM_MAX_RING > 32 /* bad's ring positions are the bits of a 32-bit word (1u << b, b < WM_MAX_RING) */
#error "wm_plan_probe.bad and first_fit's bad[] need WM_MAX_RING <= 32"
#endif
/* 1 when the triangle of ring positions (i, j, k) (counter-clockwise, n ring vertices) is one of bad's:
 * as (x, y, y + 1) from whichever of its corners sees two consecutive ring vertices. */
static inline int wm_tri_bad(const uint32_t *bad, int32_t n, int32_t i, int32_t j, int32_t k)
{
    return ((j + 1 == n ? 0 : j + 1) == k && (bad[i] >> j & 1)) ||
           ((k + 1 == n ? 0 : k + 1) == i && (bad[j] >> k & 1)) ||
           ((i + 1 == n ? 0 : i + 1) == j && (bad[k] >> i & 1));
}
/* wm_vertex_ring that also keeps the fan's half-edges leaving v (e[], *k of them, counter-clockwise; k = n
 * for an interior vertex, n - 1 on a side), for wm_vertex_remove_fan. */
int32_t wm_vertex_fan(const wm_mesh *m, int32_t v, int32_t e[WM_MAX_RING], int32_t *k, int32_t ring[WM_MAX_RING]);
/* wm_vertex_remove with v's fan (e, k) and ring (n) as wm_vertex_fan gave them on this mesh as it is,
 * without walking the fan again (the decimation's removals: first_fit walked it for its plan).  apex >= 0:
 * the plan is the fan from that ring position (wm_ring_plan's for it), made here from the ring (tris may
 * then be NULL; when given, checked builds assert it is that fan); -1: tris. */
int wm_vertex_remove_fan(wm_mesh *m, int32_t v, const int32_t *e, int32_t k, const int32_t *ring, int32_t n,
                         int32_t apex, const int32_t *tris, int32_t n_tris, int32_t touched[WM_MAX_RING],
                         int32_t *n_touched);
int wm_ring_plan_probe(const wm_mesh *m, const int32_t *ring, int32_t n, int32_t apex,
                       int32_t tris[3 * WM_MAX_RING], int32_t *n_tris, const struct wm_plan_probe *pr,
                       int32_t *big);
/* The hole of a removed vertex triangulated by ear clipping with a heap of ears (O(h log h)): the
 * ring (n vertices, counter-clockwise, as wm_vertex_ring gives it) is star-shaped from (kx, ky),
 * the removed vertex, and an ear (a, b, c) is cut only when it is strictly convex and (kx, ky) is
 * not strictly on b's side of a-c, which makes it lie inside the polygon; the ear with the largest
 * smallest angle first (ties: the lower ring position).  n - 2 triangles into tris[]; WM_OK, or
 * WM_ERR_REFUSED when no such ear is left (the caller falls back to wm_vertex_remove_plan). */
int wm_star_plan(const wm_mesh *m, const int32_t *ring, int32_t n, int32_t kx, int32_t ky,
                 int32_t tris[3 * WM_MAX_RING], int32_t *n_tris);

/* The detail energy test (4.12) for the cell of level m at (x, y). */
int wm_energetic(const wm_refiner *r, int32_t m, int32_t x, int32_t y);
/* Region selection (4.3): sets the flags, returns the number of active triangles. */
int32_t wm_select(wm_refiner *r, int32_t m, wm_level_stats *st);
/* Gradient-consistent pairing (4.4.1): fills r->list, returns the number of operations. */
int32_t wm_plan(wm_refiner *r, int32_t m, wm_level_stats *st);
/* Carries out one planned operation (4.4.2, 4.4.3); WM_OK or WM_ERR_CAPACITY. */
int wm_execute(wm_refiner *r, int32_t m, int32_t op, wm_level_stats *st);
/* Ternary subdivision of t at the interior grid point nearest its barycentre, or the fall-back
 * edge split when t has no interior grid point.  WM_OK (also when nothing could be done). */
int wm_split_unpaired(wm_refiner *r, int32_t t, wm_level_stats *st);

#endif /* WM_INTERNAL_H */
