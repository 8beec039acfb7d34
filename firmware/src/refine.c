/* The refinement loop (dissertation 4.6, step 3) and the error bound.
 *
 *   level M-1: the initial triangulation (templates)
 *   for m = M-2 .. 0, on the details of decomposition level m + 1 (table 4.2):
 *       k times: select (4.3) -> pair (4.4.1) -> split / move / ternary (4.4.2, 4.4.3)
 *                -> regularise by edge swaps (4.5.1)
 *       then reduce (3(b), reduce.c; at level 0 only when no final decimation follows)
 *   at level 0: while some E(T) > zeta: split the worst triangle at its worst sample
 *
 * Determinism: triangles are visited in slot order, the plan of an iteration is fixed before it is
 * carried out, the heap breaks ties by slot, and all arithmetic is integer. */
#include "wm_internal.h"

#define SWAP_PASSES 3 /* regularisation sweeps per iteration (a swap can undo another: bounded) */

#define ALIGN8(n) (((n) + 7u) & ~(uint64_t)7u)

int32_t wm_tri_cap_max(int32_t width, int32_t height)
{
    int64_t t = 2 * (int64_t)(width - 1) * (int64_t)(height - 1);
    if (width < 2 || height < 2) return 0;
    return t > 0x15555554 ? 0x15555554 : (int32_t)t;
}

/* The reduction's caches' slots (wm_internal.h): 128, doubled while below a sixteenth of the vertex slots,
 * up to WM_CACHE_SLOTS_MAX (Jacksboro at 10 m: 128 -> 1024 slots, 997.4 M -> 985.9 M instructions). */
static int32_t cache_slots(int32_t vert_cap)
{
    int32_t s = 128;
    while (s < WM_CACHE_SLOTS_MAX && 16 * (int64_t)s < vert_cap) s *= 2;
    return s;
}

/* Storage after the mesh: err and worst, list and pos (per triangle slot; list's room holds as many
 * error bound heap entries, wm_hent), vkey and vapex (per vertex slot), the reduction's caches. */
static uint64_t list_bytes(uint64_t items) { return ALIGN8(sizeof(wm_hent) * items); }

static uint64_t state_bytes(int32_t tri_cap, int32_t vert_cap)
{
    uint64_t items = (uint64_t)tri_cap;
    return ALIGN8(8 * (uint64_t)tri_cap) + list_bytes(items) + ALIGN8(sizeof(wm_index) * items) +
           ALIGN8(5 * (uint64_t)vert_cap) +
           (uint64_t)cache_slots(vert_cap) * (sizeof(struct wm_normal_slot) + sizeof(struct wm_ecache_slot));
}

static uint64_t refine_bytes(int32_t width, int32_t height, int32_t tri_cap)
{
    int32_t vc = wm_vert_cap_for(width, height, tri_cap);
    size_t mb = wm_mesh_bound(tri_cap, vc);
    if (mb == 0) return 0;
    return ALIGN8(sizeof(struct wm_refiner)) + ALIGN8((uint64_t)mb) + state_bytes(tri_cap, vc);
}

size_t wm_refine_bound(int32_t width, int32_t height, int32_t tri_cap)
{
    uint64_t b;
    if (width < 2 || height < 2 || width > WM_MAX_SIDE || height > WM_MAX_SIDE || tri_cap < 1) return 0;
    b = refine_bytes(width, height, tri_cap);
    if (b == 0 || b > (uint64_t)(size_t)-1) return 0;
    return (size_t)b;
}

int wm_params_check(const wm_params *p)
{
    if (p->metric != WM_METRIC_NORMAL && p->metric != WM_METRIC_VERTICAL) return WM_ERR_ARG;
    if (p->neighbourhood != WM_NEIGHBOURHOOD_FACE && p->neighbourhood != WM_NEIGHBOURHOOD_VERTEX)
        return WM_ERR_ARG;
    if (p->iterations < 0 || p->iterations > 3 || p->max_triangles < 0) return WM_ERR_ARG;
    if (p->scale_m > 65535u || p->scale_e < 0 || p->scale_e > 126) return WM_ERR_ARG;
    if (p->delta_p > 65535u || p->alpha > 65536u || (p->flags & ~WM_FLAG_ALL) != 0) return WM_ERR_ARG;
    if (p->delta_c > 65536u) return WM_ERR_ARG;
    if (p->slope_x_m > 65535u || p->slope_y_m > 65535u || p->slope_x_e < 0 || p->slope_x_e > 126 ||
        p->slope_y_e < 0 || p->slope_y_e > 126)
        return WM_ERR_ARG;
    return WM_OK;
}

size_t wm_abi_size(int which)
{
    switch (which) {
    case WM_ABI_PARAMS: return sizeof(wm_params);
    case WM_ABI_FIELD: return sizeof(wm_field);
    case WM_ABI_STATS: return sizeof(wm_level_stats);
    default: return 0;
    }
}

static void regularise(wm_refiner *r, wm_level_stats *st, uint32_t alpha);

/* 4.6 step 2(d): the initial mesh enhanced with the local operators of 2.5.1 (Table 3.2: fewer triangles
 * and lower errors): edge swaps that lower the error (eq. 4.22 with alpha = 0: R_E > 1) over the whole
 * mesh, the reduction (its removals are level M-1's), then the same swaps over what the reduction made
 * (2.5.1: the swap "minimize[s] the error produced by previously applied operators"). */
static void enhance(wm_refiner *r)
{
    wm_mesh *me = &r->mesh;
    for (int32_t t = 0; t < me->tri_end; t++) me->tflag[t] = WM_F_NEW;
    regularise(r, NULL, 0);
    for (int32_t t = 0; t < me->tri_end; t++) me->tflag[t] = 0;
    WM_PROF_SET(WM_PH_REDUCE);
    wm_reduce(r);
    WM_PROF_SET(WM_PH_LEVELS);
    regularise(r, NULL, 0);
    for (int32_t t = 0; t < me->tri_end; t++) me->tflag[t] = 0;
}

int wm_refine_init(wm_refiner **out, void *mem, size_t bytes, const wm_field *f, const wm_params *p,
                   const int32_t *xy, int32_t nv, const int32_t *tris, int32_t nt, int32_t tri_cap)
{
    wm_refiner *r;
    uint8_t *q = (uint8_t *)mem;
    size_t need, mb;
    int32_t vc;
    int rc;
    if (out == NULL || f == NULL || p == NULL || f->samples == NULL) return WM_ERR_ARG;
    *out = NULL;
    if (f->levels < 1 || f->levels > WM_MAX_LEVELS || (f->levels > 1 && f->details == NULL)) return WM_ERR_ARG;
    if (wm_params_check(p) != WM_OK) return WM_ERR_ARG;
    need = wm_refine_bound(f->width, f->height, tri_cap);
    if (need == 0) return WM_ERR_ARG;
    if (mem == NULL || bytes < need) return WM_ERR_MEMORY;
    if (nt > tri_cap) return WM_ERR_CAPACITY;
    r = (wm_refiner *)mem;
    q += ALIGN8(sizeof(struct wm_refiner));
    vc = wm_vert_cap_for(f->width, f->height, tri_cap);
    mb = wm_mesh_bound(tri_cap, vc);
    rc = wm_mesh_init(&r->mesh, q, mb, f->width, f->height, tri_cap, vc);
    if (rc != WM_OK) return rc;
    q += ALIGN8((uint64_t)mb);
    {
        uint64_t items = (uint64_t)tri_cap;
        r->err = (uint32_t *)(void *)q;
        r->worst = (int32_t *)(void *)(q + 4 * (uint64_t)tri_cap);
        q += ALIGN8(8 * (uint64_t)tri_cap);
        r->list = (wm_index *)(void *)q;
        q += list_bytes(items);
        r->pos = (wm_index *)(void *)q;
        q += ALIGN8(sizeof(wm_index) * items);
        r->vkey = (uint32_t *)(void *)q;
        r->vapex = (int8_t *)(void *)(q + 4 * (uint64_t)vc);
        q += ALIGN8(5 * (uint64_t)vc);
        r->cache_mask = cache_slots(vc) - 1;
        r->normals = (struct wm_normal_slot *)(void *)q;
        r->ecache =
            (struct wm_ecache_slot *)(void *)(q + sizeof(struct wm_normal_slot) * (uint64_t)(r->cache_mask + 1));
    }
    r->field = *f;
    r->params = *p;
    r->level = f->levels - 1;
    r->done = 0;
    r->failed = 0;
    r->budget_hit = 0;
    r->flips = r->removals = 0;
    r->roi = NULL; /* wm_refine_set_roi (roi.c) */
    for (int32_t i = 0; i <= r->cache_mask; i++) {
        r->normals[i].key[0] = -1;
        r->ecache[i].v = -1;
    }
    r->limit = tri_cap;
    r->limit_is_budget = 0;
    if (p->max_triangles > 0 && p->max_triangles < tri_cap) {
        r->limit = p->max_triangles;
        r->limit_is_budget = 1;
    }
    /* err and worst, then list and pos: at least 3 tri_cap words in one run (8 + 2 x 2 bytes per
     * slot with 16-bit indices), the build's scratch. */
    r->swept = 0;
    rc = wm_mesh_build(&r->mesh, xy, nv, tris, nt, (uint32_t *)r->err);
    if (rc != WM_OK) return rc;
    for (int32_t t = 0; t < r->mesh.tri_end; t++) {
        wm_touch(r, t);
        r->mesh.tflag[t] = 0;
        r->pos[t] = -1;
    }
    r->swept = 1; /* until the error bound, which takes pos[] for its heap */
    r->swap_stamp = 0;
    if (!(p->flags & WM_FLAG_NO_REDUCE)) enhance(r);
    *out = r;
    return WM_OK;
}

/* ---------------------------------------------------------------------------------------------- */
/* Regularisation (4.5.1): swap the diagonal of a strictly convex quadrilateral in the region when
 *     xi = alpha R_A + (1 - alpha) R_E > 1,
 *     R_A = min angle(new) / min angle(old),  R_E = (E(T_i) + E(T_j) + 1) / (E(t_i) + E(t_j) + 1)
 * with angles in Q16 radians (integer CORDIC), E in height units Q16.16, ratios Q16.16. */

static uint32_t ratio_q16(uint64_t num, uint64_t den)
{
    uint64_t q;
    uint32_t rem;
    if (den == 0) return num ? 0xFFFFFFFFu : 65536u;
    q = WM_NARROW_DIV && den < 65536u ? wm_udiv_small(num << 16, (uint32_t)den, &rem) : (num << 16) / den;
    return q > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)q;
}

/* The largest den > 0 with xi = alpha R_A + (1 - alpha) R_E > 1 for alpha < 2^16, R_A = ra and R_E =
 * ratio_q16(num, den) (num below 2^42), as the swap rounds it: 0 when there is none,
 * UINT64_MAX when every den has it.  xi > 1 iff alpha ra + (2^16 - alpha) re >= 65537 2^16 iff
 * re >= R = ceil((65537 2^16 - alpha ra) / (2^16 - alpha)), and re = min(floor(2^16 num / den),
 * 2^32 - 1) >= R (R < 2^32) iff 2^16 num >= R den; at alpha = 0, R = 65537.  So a swap's test is a
 * comparison of den with this, and bounds each new E(T) before it is scanned (try_swap).  R into *rq
 * (0 when every den, UINT64_MAX when none), and without need only R (0 returned): den_of takes the
 * rest when it is needed, den_over a test against it. */
/* floor(2^16 num / R) for 0 < R < 2^32: den_max's last step, its divisor R (den_max's *rq). */
static WM_ALWAYS_INLINE uint64_t den_from(uint64_t num, uint64_t R)
{
    uint32_t rem;
    return WM_NARROW_DIV && R < 65536u ? wm_udiv_small(num << 16, (uint32_t)R, &rem) : (num << 16) / R;
}

/* floor(n / (2^16 - alpha)) for alpha < 2^16, am = alpha_recip(alpha) (den_max's R): on the soft CPU a
 * multiply-high by am = floor((2^32 - 1) / a), a = 2^16 - alpha, and one correction (2^32 / a - am <= 1, so
 * n am / 2^32 > n / a - 1 for n < 2^32: the quotient or one less), where the division took some 40 cycles
 * (regularise takes am once a sweep); natively the division. */
static uint32_t alpha_recip(uint32_t alpha) { return alpha < 65536u ? 0xFFFFFFFFu / (65536u - alpha) : 0; }

static WM_ALWAYS_INLINE uint32_t div_by_a(uint32_t n, uint32_t alpha, uint32_t am)
{
    uint32_t a = 65536u - alpha, q;
    if (!WM_NARROW_DIV) return n / a;
    q = (uint32_t)(((uint64_t)n * am) >> 32);
    if (n - q * a >= a) q++;
    WM_ASSERT(q == n / a);
    return q;
}

static WM_ALWAYS_INLINE uint64_t den_max(uint32_t alpha, uint32_t am, uint32_t ra, uint64_t num, int need,
                                         uint64_t *rq)
{
    int64_t t;
    uint64_t R;
    WM_ASSERT(alpha < 65536u);
    t = ((int64_t)65537 << 16) - (int64_t)alpha * ra;
    if (t <= 0) {
        *rq = 0;
        return UINT64_MAX;
    }
    R = (uint64_t)t + (65535u - alpha);
    /* 32 bits unless ra < 2 or alpha = 0 (step 2(d)'s swaps, whose R is t / 2^16 = 65537: on the soft CPU a
     * shift, where the 64-bit division was a library call every try) */
    R = R >> 32 ? (WM_NARROW_DIV && alpha == 0 ? R >> 16 : R / (65536u - alpha))
                : div_by_a((uint32_t)R, alpha, am);
    if (R > 0xFFFFFFFFu) {
        *rq = UINT64_MAX;
        return 0;
    }
    *rq = R;
    if (!need) return 0;
    return den_from(num, R);
}

/* den_max from its R (den_max's *rq). */
static uint64_t den_of(uint64_t rq, uint64_t num)
{
    if (rq == 0) return UINT64_MAX;
    if (rq == UINT64_MAX) return 0;
    return den_from(num, rq);
}

/* x > den_of(rq, num) without its division, for the soft CPU (WM_NARROW_DIV), where that division is a
 * library call (some 80 cycles): x > floor(2^16 num / R) iff x R > 2^16 num (integers), the product below
 * 2^64 when x < 2^32 (R < 2^32, 2^16 num < 2^58; a larger x divides). */
static inline int den_over(uint64_t rq, uint64_t num, uint64_t x)
{
    int over;
    if (rq == 0) return 0; /* den_max = UINT64_MAX */
    if (rq == UINT64_MAX) return x > 0;
    over = x >> 32 ? x > den_of(rq, num) : x * rq > (num << 16);
    WM_ASSERT(over == (x > den_of(rq, num)));
    return over;
}

/* x > dmax, dmax = den_max(alpha, ra, num, !WM_NARROW_DIV, &rq): with WM_NARROW_DIV by den_over. */
static WM_ALWAYS_INLINE int over_dmax(uint64_t rq, uint64_t num, uint64_t dmax, uint64_t x)
{
    return WM_NARROW_DIV ? den_over(rq, num, x) : x > dmax;
}

/* x > den_max(alpha, ra, num), for the tests whose den_max is not needed as a bound (try_swap's exact R_A
 * after the scans, its swap back's): with WM_NARROW_DIV by den_over, natively by the division (one
 * instruction: den_over's products and branches took more). */
static WM_ALWAYS_INLINE int over_den_max(uint32_t alpha, uint32_t am, uint32_t ra, uint64_t num, uint64_t x)
{
    uint64_t rq, d = den_max(alpha, am, ra, num, !WM_NARROW_DIV, &rq);
    return over_dmax(rq, num, d, x);
}

/* 65536 > den_max(alpha, ra, num), without its divisions: den_max is 0 (R_A alone refuses, or R > 2^32 -
 * 1), else floor(2^16 num / R) with R = ceil(t / a), a = 2^16 - alpha, t = 65537 2^16 - alpha ra > 0,
 * which is below 2^16 iff num < R; and R > m iff t > m a for an integer m, so the answer is
 * t > min(num, 2^32 - 1) a (below 2^48 2^16).  The test of most swaps R_A's bound refuses (try_swap). */
static int den_below_one(uint32_t alpha, uint32_t ra, uint64_t num)
{
    int64_t t;
    if (alpha == 65536u) return ra <= 65536u;
    t = ((int64_t)65537 << 16) - (int64_t)alpha * ra;
    if (t <= 0) return 0;
    return (uint64_t)t > (num < 0xFFFFFFFFu ? num : 0xFFFFFFFFu) * (65536u - alpha);
}

/* wm_scale_mul(p, e, 1, 0, 2^40) (the swaps' E(T) in height units) inline: floor(e m / 2^s) (m =
 * scale_m < 2^16), at most 2^40; the same integer without the call and its general case's branches
 * (on the soft CPU a multiply pair and a shift). */
static inline uint64_t in_height(const wm_params *p, uint32_t e)
{
    uint64_t q = (uint64_t)e * p->scale_m, cap = (uint64_t)1 << 40;
    int s = p->scale_e;
    if (WM_NARROW_DIV && s >= 8 && s < 32) {
        /* e m < 2^48 shifted word by word (below 2^40: no cap), where rv32's 64-bit shift branches */
        uint32_t lo = (uint32_t)q, hi = (uint32_t)(q >> 32);
        q = ((uint64_t)(hi >> s) << 32) | (lo >> s | hi << (32 - s));
    } else {
        q = s >= 64 ? 0 : q >> s;
        q = q > cap ? cap : q;
    }
    WM_ASSERT(q == wm_scale_mul(p, e, 1, 0, cap));
    return q;
}

/* The largest E with wm_scale_mul(p, E, 1, 0, cap) <= X (cap = 2^40), saturated at 2^32 - 1: that
 * product is min(cap, floor(E m / 2^e)) (m = scale_m < 2^16), and floor(E m / 2^e) <= X iff
 * E m <= (X + 1) 2^e - 1; every E below 2^32 has it when (X + 1) 2^e >= 2^48. */
static uint32_t scale_inv(const wm_params *p, uint64_t X)
{
    uint64_t q;
    uint32_t rem;
    int e = p->scale_e;
    if (X >= ((uint64_t)1 << 40) || p->scale_m == 0 || e >= 48 || X + 1 >= ((uint64_t)1 << (48 - e)))
        return 0xFFFFFFFFu;
    q = WM_NARROW_DIV ? wm_udiv_small(((X + 1) << e) - 1, p->scale_m, &rem) : (((X + 1) << e) - 1) / p->scale_m;
    return q > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)q;
}

/* The bound of a swap whose old triangles have E(T) e1 and e2 (try_swap): the mesh's E_max when the
 * sweep began, with the levels alone max(zeta, e1, e2). */
static uint32_t swap_bound(const wm_refiner *r, uint32_t emax, uint32_t e1, uint32_t e2)
{
    uint32_t b = r->params.zeta;
    if (!(r->params.flags & WM_FLAG_NO_BOUND)) return emax;
    if (e1 > b) b = e1;
    if (e2 > b) b = e2;
    return b;
}

/* A sample's row s / W (and column s - row W) without a division: every sample number s = y W + x is
 * below 2^30 (W, H <= WM_MAX_SIDE), so with 2^l >= W and m = ceil(2^(30 + l) / W) (below 2^31 + 2),
 * floor(s m / 2^(30 + l)) = floor(s / W) exactly (the error s (m W - 2^(30 + l)) / (W 2^(30 + l)) is
 * below 2^-l <= 1 / W).  With WM_NARROW_DIV (the soft CPU) a multiply pair and a shift, where s / W and
 * s % W were two calls of its 33-cycle division (the swaps' point tests and the error bound take a
 * triangle's worst sample apart); natively the division. */
struct sample_div {
    uint32_t m;
    int sh;
};

static struct sample_div sample_div_of(int32_t w)
{
    struct sample_div d;
    int l = 0;
    while (((int32_t)1 << l) < w) l++;
    d.sh = 30 + l;
    d.m = (uint32_t)((((uint64_t)1 << d.sh) + (uint32_t)w - 1u) / (uint32_t)w);
    return d;
}

static inline int32_t sample_row(struct sample_div d, int32_t s, int32_t w)
{
    return WM_NARROW_DIV ? (int32_t)(((uint64_t)(uint32_t)s * d.m) >> d.sh) : s / w;
}

#if WM_CHECK
/* (px, py) in the closed counter-clockwise triangle (the checking build's test of try_swap's sides). */
static int in_tri(const int32_t x[3], const int32_t y[3], int32_t px, int32_t py)
{
    return wm_orient(x[0], y[0], x[1], y[1], px, py) >= 0 && wm_orient(x[1], y[1], x[2], y[2], px, py) >= 0 &&
           wm_orient(x[2], y[2], x[0], y[0], px, py) >= 0;
}
#endif

/* The smallest angle of triangle slot t, kept in r->list[t] for one regularisation (the iteration's
 * plan is done by then; emptied when it begins): nothing but its own swaps changes a triangle while it
 * runs, and each swap sets its two.  Stored as angle - 2^15, which fits a wm_index of 16 bits for
 * angles 0 .. 2^16 - 2 (a smallest angle is below pi/3, 68,630 in Q16: the few above are computed
 * each time); ANGLE_UNKNOWN (angle 2^16 - 1) is none kept. */
#define ANGLE_UNKNOWN ((wm_index)32767)

static wm_index angle_code(int32_t angle)
{
    return angle >= 0 && angle < 65535 ? (wm_index)(angle - 32768) : ANGLE_UNKNOWN;
}

static void set_angle(wm_refiner *r, int32_t t, int32_t angle) { r->list[t] = angle_code(angle); }

/* Triangle t's smallest angle, kept for the sweep; (x, y) its corners counter-clockwise from any one
 * (a rotation of wm_tri_xy's: the same integers in wm_min_corner, so the same angle as wm_min_angle). */
static int32_t slot_angle(wm_refiner *r, int32_t t, const int32_t x[3], const int32_t y[3])
{
    int64_t dot, cross;
    int32_t a;
    if (r->list[t] != ANGLE_UNKNOWN) return (int32_t)r->list[t] + 32768;
    wm_min_corner_in(x, y, &dot, &cross);
    a = wm_angle_q16(dot, cross);
#if WM_CHECK
    {
        int32_t tx[3], ty[3];
        wm_tri_xy(&r->mesh, t, tx, ty);
        WM_ASSERT(a == wm_min_angle(tx, ty));
    }
#endif
    set_angle(r, t, a);
    return a;
}

/* A swap whose swap back would be made keeps what the swap back needs in a record: the two triangles it
 * replaced (their E(T), worst samples and kept angles), so that the swap back, when its two triangles
 * are still the swap's, is made without a test (try_swap's answer is known: yes) and without a scan:
 * its triangles are the replaced ones.  The records lie in vkey, REC_WORDS words each, a power of two
 * of them, the one of swap number s at (s / 2) mod their count; a record taken by a later swap is not
 * found (its tag is that swap's number) and the swap back is then tested as any edge is.  Such a swap's
 * number is even, a swap whose swap back is refused has an odd one (pos[] of both triangles).  Words: the tag s, the vertex c of the replaced
 * triangle (a, b, c), then of (a, b, c) and (b, a, d): E(T), E(T), worst, worst, both kept angles. */
#define REC_WORDS 7

/* The records' count - 1 (wm_refiner.swap_recs), for vert_cap vertex slots: 0 when there are none, and so
 * with a region of interest or holes, whose E(T) of a flat triangle places no worst sample as the
 * scan's (swap_back). */
static uint32_t rec_mask(int32_t vert_cap, int special)
{
    uint32_t n = (uint32_t)vert_cap / REC_WORDS, m = 1;
    if (n < 2 || special) return 0;
    while (2 * m <= n) m *= 2;
    return m - 1;
}

/* The next swap number of the parity given (1: its swap back is refused; 0: made, with a record), or -1
 * when they ran out (then none: the swap's edge is tested again as any). */
static int32_t next_stamp(wm_refiner *r, int32_t odd)
{
    int32_t s = r->swap_stamp + 1;
    if ((s & 1) != odd) s++;
    if (!r->swept || s > WM_INDEX_MAX - 1) return -1;
    r->swap_stamp = s;
    return s;
}

/* The swap of e's quadrilateral made: the new triangles t1 = (a, d, c), t2 = (d, b, c) get their E(T)
 * e1, e2, worst samples w1, w2 and kept angles k1, k2 (list[] entries); back: whether the swap back
 * would be made (then a record of the replaced triangles, read before the swap). */
static void make_swap(wm_refiner *r, int32_t e, uint32_t alpha, uint32_t e1, uint32_t e2, int32_t w1, int32_t w2,
                      wm_index k1, wm_index k2, int back)
{
    wm_mesh *me = &r->mesh;
    int32_t t1 = WM_TRI(e), t2 = WM_TRI(me->he[e].o), c = me->he[WM_PREV(e)].v, s;
    uint32_t rec[REC_WORDS] = {0,
                               (uint32_t)c,
                               r->err[t1],
                               r->err[t2],
                               (uint32_t)r->worst[t1],
                               (uint32_t)r->worst[t2],
                               (uint32_t)(uint16_t)r->list[t1] | (uint32_t)(uint16_t)r->list[t2] << 16};
    wm_edge_swap_convex(me, e, NULL, NULL); /* swappable: tested by the caller */
    /* wm_edge_swap keeps the slots: t1 = (a, d, c), t2 = (d, b, c). */
    r->list[t1] = k1;
    r->list[t2] = k2;
    if (alpha < 65536u) {
        r->err[t1] = e1;
        r->err[t2] = e2;
        r->worst[t1] = w1;
        r->worst[t2] = w2;
        me->tflag[t1] |= WM_F_NEW;
        me->tflag[t2] |= WM_F_NEW;
        wm_forget_class(r, t1);
        wm_forget_class(r, t2);
    } else {
        wm_touch(r, t1);
        wm_touch(r, t2);
    }
    s = next_stamp(r, !back);
    if (s < 0) return;
    r->pos[t1] = r->pos[t2] = (wm_index)s;
    if (back && r->swap_recs) {
        uint32_t *q = r->vkey + REC_WORDS * (((uint32_t)s >> 1) & r->swap_recs);
        rec[0] = (uint32_t)s;
        for (int i = 0; i < REC_WORDS; i++) q[i] = rec[i];
    }
}

/* A kept angle's list[] entry (-32768 .. 32767) from its record's 16 bits. */
static wm_index rec_angle(uint32_t w) { return (wm_index)((int32_t)((w & 0xFFFFu) ^ 0x8000u) - 32768); }

/* The swap back of the swap numbered s (even) across e, whose triangles are still the swap's: made from
 * its record, 1; 0 when the record was taken by a later swap (the caller tests the edge). */
static int swap_back(wm_refiner *r, int32_t e, uint32_t alpha, int32_t s)
{
    wm_mesh *me = &r->mesh;
    const uint32_t *q = r->vkey + REC_WORDS * (((uint32_t)s >> 1) & r->swap_recs);
    int32_t tt[2] = {WM_TRI(e), WM_TRI(me->he[e].o)};
    int j;
    if (r->swap_recs == 0 || q[0] != (uint32_t)s) return 0;
    /* the swap back's t1 = (a', d', c') holds a' = he[e].v, which is the record's c or d */
    j = (uint32_t)me->he[e].v != q[1];
    make_swap(r, e, alpha, q[2 + j], q[3 - j], (int32_t)q[4 + j], (int32_t)q[5 - j], rec_angle(q[6] >> 16 * j),
              rec_angle(q[6] >> 16 * (1 - j)), 1);
    /* a flat triangle's (E(T) = 0) worst sample is the scan's first corner (wm_place_at): the slot's */
    for (int k = 0; k < 2 && alpha < 65536u; k++) {
        int32_t t = tt[k], v = me->he[3 * t].v;
        if (r->err[t] == 0) r->worst[t] = me->vxy[v].y * r->field.width + me->vxy[v].x;
    }
#if WM_CHECK
    for (int k = 0; k < 2 && alpha < 65536u; k++) { /* what try_swap would have measured */
        int32_t t = tt[k], x[3], y[3], wx, wy;
        uint32_t ev;
        wm_tri_xy(me, t, x, y);
        ev = wm_tri_error(&r->field, &r->params, x, y, &wx, &wy);
        WM_ASSERT(r->err[t] == ev && r->worst[t] == wy * r->field.width + wx);
        WM_ASSERT(r->list[t] == ANGLE_UNKNOWN || (int32_t)r->list[t] + 32768 == wm_min_angle(x, y));
        (void)ev;
    }
#endif
    return 1;
}

/* try_swap's R_A exact (for its dmax): the new triangles' smallest angles (the CORDIC, into *an1 and *an2)
 * over the old pair's, ang_old.  Natively it is taken after the scans (ANGLES_LATE), whose bounds then come
 * from R_A's bound from above (dmax grows with R_A; a scan that stays within its bound is the whole
 * scan, so the answer is the same), and the smaller new triangle is scanned first: the two CORDICs of a
 * swap a scan refuses are saved, and a refusing scan is most often the shorter.  On the board the angle
 * unit (WM_ANGLE_ENGINE) and the scan engine make both cost more cycles than they save: the angles
 * before the scans, (a, d, c) first. */
#ifdef WM_ANGLE_ENGINE
#define ANGLES_LATE 0
#else
#define ANGLES_LATE 1
#endif

static inline uint32_t exact_ra(int64_t dot1, int64_t cross1, int64_t dot2, int64_t cross2, int32_t ang_old,
                                int32_t *an1, int32_t *an2)
{
    int32_t a = *an1 = wm_angle_q16(dot1, cross1), a2 = *an2 = wm_angle_q16(dot2, cross2);
    return ratio_q16((uint64_t)(a2 < a ? a2 : a), (uint64_t)ang_old);
}

/* try_swap's measure of a new triangle (x, y) within its limit: the bound bnd, or, with dmax, den over dmax
 * given the other triangle's part of it (below: its lower bound, or its measure); 0 when E(T) is over the
 * limit (the swap is refused; the scan stopped there), else 1 with E(T) in *e. */
static WM_ALWAYS_INLINE int scan_new(wm_refiner *r, const int32_t x[3], const int32_t y[3], uint64_t dmax,
                                     uint32_t bnd, uint64_t below, uint32_t *e, int32_t *wx, int32_t *wy,
                                     uint64_t *kept)
{
    uint32_t lim = dmax == UINT64_MAX ? bnd : scale_inv(&r->params, dmax - 65536u - below);
    if (lim > bnd) lim = bnd;
    *e = r->roi ? wm_roi_error(r, x, y, wx, wy)
                : wm_tri_error_within(&r->field, &r->params, x, y, lim, wx, wy, kept);
    return *e <= lim;
}

/* min(wm_angle_above(dot1, cross1), wm_angle_above(dot2, cross2)) (try_swap's bound of R_A).  On the soft
 * CPU with one division, where each took one: the bound is min(cap, floor(2^16 cross / dot) + slack),
 * which grows with cross / dot (dot > 0), so the smaller quotient's is the smaller bound, and
 * cross1 / dot1 <= cross2 / dot2 iff cross1 dot2 <= cross2 dot1 (each below 2^31: 32 x 32 bit products). */
static WM_ALWAYS_INLINE int32_t angle_above_min(int64_t dot1, int64_t cross1, int64_t dot2, int64_t cross2)
{
    int32_t a1, a2;
    if (WM_NARROW_DIV && dot1 > 0 && dot2 > 0) {
        int first = (uint64_t)(uint32_t)cross1 * (uint32_t)dot2 <= (uint64_t)(uint32_t)cross2 * (uint32_t)dot1;
        a1 = first ? wm_angle_above(dot1, cross1) : wm_angle_above(dot2, cross2);
        WM_ASSERT(dot1 < ((int64_t)1 << 31) && dot2 < ((int64_t)1 << 31) && cross1 >= 0 &&
                  cross1 < ((int64_t)1 << 31) && cross2 >= 0 && cross2 < ((int64_t)1 << 31));
        WM_ASSERT(a1 == (wm_angle_above(dot1, cross1) < wm_angle_above(dot2, cross2)
                             ? wm_angle_above(dot1, cross1)
                             : wm_angle_above(dot2, cross2)));
        return a1;
    }
    a1 = wm_angle_above(dot1, cross1);
    a2 = wm_angle_above(dot2, cross2);
    return a2 < a1 ? a2 : a1;
}

#if WM_CHECK
static int check_dry; /* try_swap answers without making the swap (swap_made) */
#endif

static int try_swap(wm_refiner *r, int32_t e, uint32_t alpha, uint32_t am, uint32_t emax, struct sample_div wd)
{
    wm_mesh *me = &r->mesh;
    int32_t f = me->he[e].o, t1 = WM_TRI(e), t2 = WM_TRI(f);
    int32_t a = me->he[e].v, b = me->he[f].v, c = me->he[WM_PREV(e)].v, d = me->he[WM_PREV(f)].v;
    int32_t qx[3], qy[3], n1x[3], n1y[3];
    int32_t ang_old = 0, ang_new, a1, an1 = -1, an2 = -1;
    int64_t dot1 = 0, cross1 = 0, dot2 = 0, cross2 = 0; /* the new triangles' smallest angles (fixed.c) */
    uint32_t e1 = 0, e2 = 0, ra, bnd, oe1, oe2;
    const uint64_t one = 65536u;
    uint64_t o1 = 0, o2 = 0, sn = 0; /* old and new E(T) in height units (alpha < 1) */
    int back = 1;                    /* whether the swap back would be made */
    int first;                       /* the new triangle scanned first: 0 (a, d, c), 1 (d, b, c) */
    int32_t w1x = 0, w1y = 0, w2x = 0, w2y = 0;
    uint64_t r1 = 0, r2 = 0;             /* the new triangles' slope factors, kept (wm_internal.h) */
    /* new triangles (a, d, c) and (d, b, c) */
    n1x[0] = me->vxy[a].x, n1y[0] = me->vxy[a].y, n1x[1] = me->vxy[d].x, n1y[1] = me->vxy[d].y;
    n1x[2] = me->vxy[c].x, n1y[2] = me->vxy[c].y;
    qx[0] = me->vxy[d].x, qy[0] = me->vxy[d].y, qx[1] = me->vxy[b].x, qy[1] = me->vxy[b].y;
    qx[2] = me->vxy[c].x, qy[2] = me->vxy[c].y;
    { /* wm_edge_swappable(me, e) from the corners at hand (regularise's e is a live triangle's, with one
       * across): a and b strictly on opposite sides of the line c-d */
        int64_t s1 = wm_orient(n1x[2], n1y[2], qx[0], qy[0], n1x[0], n1y[0]);
        int64_t s2 = wm_orient(n1x[2], n1y[2], qx[0], qy[0], qx[1], qy[1]);
        WM_ASSERT(((s1 > 0 && s2 < 0) || (s1 < 0 && s2 > 0)) == wm_edge_swappable(me, e));
        if (!((s1 > 0 && s2 < 0) || (s1 < 0 && s2 > 0))) return 0;
        first = ANGLES_LATE && s2 < -s1; /* twice the new triangles' areas: -s1 (a, d, c), s2 (d, b, c) */
    }
    /* read once the quad is convex: a third of the edges end above, and err[t2] (a neighbour's slot) is
     * an SDRAM refill on the board */
    oe1 = r->err[t1], oe2 = r->err[t2];
    ra = 0; /* alpha = 0 (step 2(d)'s swaps): xi = R_E, no angle needed */
    if (alpha > 0) {
        /* the old triangles (a, b, c) and (b, a, d) from the corners at hand */
        int32_t ox[3] = {n1x[0], qx[1], n1x[2]}, oy[3] = {n1y[0], qy[1], n1y[2]};
        ang_old = slot_angle(r, t1, ox, oy);
        ox[0] = qx[1], oy[0] = qy[1], ox[1] = n1x[0], oy[1] = n1y[0], ox[2] = qx[0], oy[2] = qy[0];
        a1 = slot_angle(r, t2, ox, oy);
        if (a1 < ang_old) ang_old = a1;
        wm_min_corner_in(n1x, n1y, &dot1, &cross1);
        wm_min_corner_in(qx, qy, &dot2, &cross2);
        if (alpha < 65536u) { /* first a bound of R_A from above: the new angles below */
            ang_new = angle_above_min(dot1, cross1, dot2, cross2);
        } else {
            ang_new = an1 = wm_angle_q16(dot1, cross1);
            a1 = an2 = wm_angle_q16(dot2, cross2);
            if (a1 < ang_new) ang_new = a1;
        }
        ra = ratio_q16((uint64_t)ang_new, (uint64_t)ang_old);
    }
    /* The swap's bound: no new triangle over the mesh's E_max when the sweep began, so a swap never
     * makes E_max grow and each level's mesh stays a level of detail (unbounded, eq. 4.22 trades error
     * for angles: Box at k = 2 went from E_max 3.5 at level 2 to 200 at level 1); with the levels alone,
     * max(zeta, the pair's E(T)), the reduction's bound (docs/refiner.md). */
    bnd = swap_bound(r, emax, oe1, oe2);
    if (alpha < 65536u) {
        uint64_t dmax, rq, s1, s2;
        o1 = in_height(&r->params, oe1);
        o2 = in_height(&r->params, oe2);
        uint32_t lb1 = 0, lb2 = 0;
        /* xi > 1 iff den <= dmax (den_max), and den >= one: R_A alone may refuse the swap.  Then the
         * old triangles' worst samples, measured against the new triangle(s) holding them: they bound
         * the new E(T) from below (rounded as E(T) is), so den from below, without a scan; each
         * point error is tested as it comes.  dmax grows with R_A, so these first take R_A's bound
         * from above (wm_min_angle_above, no CORDIC): a swap they refuse with it is refused with R_A
         * itself (most swaps end here); then the new angles, and the same tests on their R_A. */
        if (den_below_one(alpha, ra, o1 + o2 + one)) return 0; /* one > dmax */
        /* with WM_NARROW_DIV dmax = den_of(rq, o1 + o2 + one) is taken when the scans need it (den_over) */
        dmax = den_max(alpha, am, ra, o1 + o2 + one, !WM_NARROW_DIV, &rq);
        WM_ASSERT(one <= den_of(rq, o1 + o2 + one));
        s1 = s2 = 0;
        for (int k = 0, s0 = -1; k < 2; k++) { /* the worse old triangle's sample first */
            int32_t s = r->worst[(k ^ (oe2 > oe1)) ? t2 : t1], sy, sx;
            if (s == s0) break; /* both old triangles' (on a-b): the same point errors again, no new bound */
            s0 = s;
            sy = sample_row(wd, s, r->field.width), sx = s - sy * r->field.width;
            /* the sample lies in the old triangle (its scan's), so in the strictly convex quad (a, d, b, c)
             * (a and b on either side of c-d, c and d of a-b): in (a, d, c) iff on its side of d-c, in
             * (d, b, c) iff on the other's (both on the diagonal) */
            int64_t side = wm_orient(n1x[1], n1y[1], n1x[2], n1y[2], sx, sy);
            WM_ASSERT(in_tri(n1x, n1y, sx, sy) == (side >= 0) && in_tri(qx, qy, sx, sy) == (side <= 0));
            WM_ASSERT(sy == s / r->field.width && sx == s % r->field.width);
            if (side >= 0) {
                uint32_t v = wm_point_error(&r->field, &r->params, n1x, n1y, sx, sy, &r1);
                if (v > lb1) {
                    lb1 = v;
                    s1 = in_height(&r->params, lb1);
                    if (over_dmax(rq, o1 + o2 + one, dmax, s1 + s2 + one)) return 0;
                }
            }
            if (side <= 0) {
                uint32_t v = wm_point_error(&r->field, &r->params, qx, qy, sx, sy, &r2);
                if (v > lb2) {
                    lb2 = v;
                    s2 = in_height(&r->params, lb2);
                    if (over_dmax(rq, o1 + o2 + one, dmax, s1 + s2 + one)) return 0;
                }
            }
        }
        if (alpha > 0 && !ANGLES_LATE) {
            dmax = den_max(alpha, am, exact_ra(dot1, cross1, dot2, cross2, ang_old, &an1, &an2), o1 + o2 + one,
                           !WM_NARROW_DIV, &rq);
            if (over_dmax(rq, o1 + o2 + one, dmax, s1 + s2 + one)) return 0; /* one > dmax with it */
            if (WM_NARROW_DIV) dmax = den_of(rq, o1 + o2 + one);
        } else if (WM_NARROW_DIV) {
            dmax = den_of(rq, o1 + o2 + one);
        }
        /* Then the scans, the smaller new triangle's first (a swap that one of them refuses is most
         * often refused for fewer samples), each stopping as soon as its E(T) is too large for the swap
         * (the bound, or den over dmax with the other triangle's lower bound, then its measure): the E(T)
         * and worst sample of a scan that stays within are the whole scan's, so the order changes no
         * answer. */
        {
            const int32_t *tx[2] = {n1x, qx}, *ty[2] = {n1y, qy};
            int32_t *twx[2] = {&w1x, &w2x}, *twy[2] = {&w1y, &w2y};
            uint64_t *tk[2] = {&r1, &r2};
            uint32_t et[2];
            int p = first, q = !first;
            if (!scan_new(r, tx[p], ty[p], dmax, bnd, first ? s1 : s2, &et[p], twx[p], twy[p], tk[p])) return 0;
            sn = in_height(&r->params, et[p]);
            if (!scan_new(r, tx[q], ty[q], dmax, bnd, sn, &et[q], twx[q], twy[q], tk[q])) return 0;
            sn += in_height(&r->params, et[q]);
            e1 = et[0], e2 = et[1];
        }
        if (alpha > 0 && ANGLES_LATE) {
            if (over_den_max(alpha, am, exact_ra(dot1, cross1, dot2, cross2, ang_old, &an1, &an2), o1 + o2 + one,
                             sn + one))
                return 0;
        }
        WM_ASSERT(sn + one <= dmax);
    } else {
        if (ra <= 65536u) return 0; /* xi = R_A */
        e1 = r->roi ? wm_roi_error(r, n1x, n1y, &w1x, &w1y)
                    : wm_tri_error_within(&r->field, &r->params, n1x, n1y, bnd, &w1x, &w1y, NULL);
        if (e1 > bnd) return 0;
        e2 = r->roi ? wm_roi_error(r, qx, qy, &w2x, &w2y)
                    : wm_tri_error_within(&r->field, &r->params, qx, qy, bnd, &w2x, &w2y, NULL);
        if (e2 > bnd) return 0;
    }
    /* The swap back (the next pass examines the new diagonal): its new triangles are the old ones,
     * whose E(T) and angles are known, so its answer is known now, exactly as try_swap would find it
     * (a smaller angle or E(T) for a rotation of the same corners is the same number). */
    {
        uint32_t bb = swap_bound(r, emax, e1, e2), rb = 0;
        if (oe1 > bb || oe2 > bb) back = 0;
        else {
            if (alpha > 0) rb = ratio_q16((uint64_t)ang_old, (uint64_t)(an1 < an2 ? an1 : an2));
            back = alpha == 65536u ? rb > 65536u : !over_den_max(alpha, am, rb, sn + one, o1 + o2 + one);
        }
    }
#if WM_CHECK
    if (check_dry) return 1;
#endif
    make_swap(r, e, alpha, e1, e2, w1y * r->field.width + w1x, w2y * r->field.width + w2x, angle_code(an1),
              angle_code(an2), back);
    return 1;
}

#if WM_CHECK
/* Whether try_swap would make the swap of e, without making it (the checking build's test of an edge
 * regularise passes over). */
static int swap_made(wm_refiner *r, int32_t e, uint32_t alpha, uint32_t am, uint32_t emax, struct sample_div wd)
{
    int made;
    check_dry = 1;
    made = try_swap(r, e, alpha, am, emax, wd);
    check_dry = 0;
    return made;
}
#endif

/* After a swap of t's: every edge of t (one of the swap's two triangles) to be examined, its mark on the
 * edge's lower triangle, if that one is swept at all (WM_F_SWAP; t is). */
static WM_ALWAYS_INLINE void mark_edges(wm_mesh *me, int32_t t)
{
    for (int32_t i = 0; i < 3; i++) {
        int32_t h = 3 * t + i, o = me->he[h].o, x;
        if (o < 0) continue;
        if (h < o) {
            me->tflag[t] |= (uint8_t)(WM_F_EXAMINE0 << i);
            continue;
        }
        x = (int32_t)((uint32_t)o / 3u);
        if (me->tflag[x] & WM_F_SWAP) me->tflag[x] |= (uint8_t)(WM_F_EXAMINE0 << (o - 3 * x));
    }
}

/* try_swap's answer depends on the two triangles alone (corners, E(T)), so an edge whose triangles did
 * not change since it was last examined is passed over: it would give the same "no".  Each edge has a
 * mark on its lower triangle (WM_F_EXAMINE): set on every edge of the sweep at its start, taken when the
 * edge is examined, set again on each edge of a swap's two triangles.  The same edges are examined in the
 * same order as with a triangle's mark for "swapped in this pass or the one before", but none again whose
 * triangles all changed before its examination in the pass before. */
static void regularise(wm_refiner *r, wm_level_stats *st, uint32_t alpha)
{
    wm_mesh *me = &r->mesh;
    uint32_t emax = 0; /* the mesh's E_max: the bound of every swap (try_swap) */
    int32_t first; /* this sweep's first swap number */
    struct sample_div wd = sample_div_of(r->field.width);
    const int32_t swept = r->swept;
    const uint32_t am = alpha_recip(alpha); /* den_max's divisor's reciprocal */
    for (int32_t t = 0; t < me->tri_end; t++) { /* and the iteration's WM_F_UNPAIRED marks cleared */
        uint8_t f = (uint8_t)(me->tflag[t] & ~(WM_F_EXAMINE | WM_F_UNPAIRED));
        r->list[t] = ANGLE_UNKNOWN;
        if (me->he[3 * t].v >= 0) {
            if (r->err[t] > emax) emax = r->err[t];
            if (f & WM_F_SWAP) f |= WM_F_EXAMINE;
        }
        me->tflag[t] = f;
    }
    if (r->swap_stamp > WM_INDEX_MAX / 2) { /* stamps of earlier sweeps are never trusted: start again */
        for (int32_t t = 0; t < me->tri_end; t++) r->pos[t] = -1;
        r->swap_stamp = 0;
    }
    first = r->swap_stamp + 1;
    r->swap_recs = rec_mask(me->vert_cap, r->roi != NULL || r->field.mask != NULL);
    for (int pass = 0; pass < SWAP_PASSES; pass++) {
        int32_t swaps = 0;
        for (int32_t t = 0; t < me->tri_end; t++) {
            uint8_t ft = me->tflag[t]; /* its edges to be examined: taken */
            if (!(ft & WM_F_EXAMINE)) continue;
            me->tflag[t] = (uint8_t)(ft & ~WM_F_EXAMINE);
            for (int32_t i = 0; i < 3; i++) {
                int32_t e = 3 * t + i, o = me->he[e].o, u;
                /* o < 3 t: on the border (o < 0) or across to a triangle below t, whose mark it is;
                 * else o >= 0 and its triangle an unsigned division */
                if (o < 3 * t) continue;
                u = (int32_t)((uint32_t)o / 3u);
                if (!(me->tflag[u] & WM_F_SWAP)) continue;
                if (!(ft & (WM_F_EXAMINE0 << i))) {
                    WM_ASSERT(!swap_made(r, e, alpha, am, emax, wd)); /* refused as it stands */
                    continue;
                }
                /* A swap back: t and u both still the swap's (its number in pos[], while the levels run),
                 * t its lower slot (the turn's), so the edge is t's edge 1 (make_swap's d->c): the one
                 * edge the two share, and pos[] is read for it alone. */
                WM_ASSERT(i == 1 || !swept || r->pos[t] < first || r->pos[t] != r->pos[u]);
                if (i == 1 && swept) {
                    int32_t pt = r->pos[t];
                    if (pt >= first && pt == r->pos[u]) {
                        if (pt & 1) continue; /* refused */
                        if (swap_back(r, e, alpha, pt)) goto made;
                    }
                }
                if (!try_swap(r, e, alpha, am, emax, wd)) continue;
            made:
                /* t's edges after i are examined now, those up to it (new ones) in the next pass */
                mark_edges(me, t);
                mark_edges(me, u);
                ft = me->tflag[t];
                me->tflag[t] = (uint8_t)(ft & ~((WM_F_EXAMINE0 << (i + 1)) & WM_F_EXAMINE));
                swaps++;
            }
        }
        if (st) st->swaps += swaps;
        if (swaps == 0) break; /* every mark taken (the last pass's swaps leave some, read by no one) */
    }
}

/* ---------------------------------------------------------------------------------------------- */
/* The error bound: the worst triangle first (the heap of mesh_state.c) until every E(T) <= zeta. */

static int error_bound(wm_refiner *r, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    int32_t n = 0;
    int legal = !(r->params.flags & WM_FLAG_NO_LEGALISE);
    struct sample_div wd = sample_div_of(r->field.width);
    /* Only the slots in use; a slot a split adds beyond them gets pos[] = -1 when it is made, so no
     * entry is read before it is written (the board does not clear the storage, wm_job_refine). */
    for (int32_t t = 0; t < me->tri_end; t++) r->pos[t] = -1;
    for (int32_t t = 0; t < me->tri_end; t++)
        if (me->he[3 * t].v >= 0 && r->err[t] > r->params.zeta)
            wm_heap_update(r, t, r->err[t], -1, &n); /* pos[t] */
    while (n > 0) {
        int32_t t = wm_heap_entries(r)[0].t, x[3], y[3], wx, wy, touched[4], nt = 0, k, on = -1, rc, room, p, te;
        int64_t E[3];
        wm_tri_xy(me, t, x, y);
        wy = sample_row(wd, r->worst[t], r->field.width);
        wx = r->worst[t] - wy * r->field.width;
        WM_ASSERT(wy == r->worst[t] / r->field.width && wx == r->worst[t] % r->field.width);
        /* Which edge holds the worst sample (E_k = 0: the edge from corner k+1 to k+2)?  Never a
         * corner: the distance is 0 there and E(T) > zeta >= 0. */
        for (k = 0; k < 3; k++) {
            int k1 = wm_k1(k), k2 = wm_k2(k);
            E[k] = wm_orient(x[k1], y[k1], x[k2], y[k2], wx, wy);
            if (E[k] == 0) on = 3 * t + k1;
        }
        room = wm_room(r, on < 0 ? 2 : (me->he[on].o >= 0 ? 2 : 1));
        if (room < 0) return room;
        if (room > 0) break; /* the budget: stop with E_max > zeta */
        te = me->tri_end;
        /* the worst sample strictly inside t (every E[k] > 0) or strictly inside edge on (a grid point of
         * the closed triangle, no corner) */
        rc = on < 0 ? wm_tri_split_inside(me, t, wx, wy, touched, &nt)
                    : wm_edge_split_inside(me, on, wx, wy, touched, &nt);
        if (rc != WM_OK) return rc == WM_ERR_CAPACITY ? rc : WM_ERR_MESH; /* cannot happen */
        while (te < me->tri_end) r->pos[te++] = -1; /* slots new to the mesh: in no heap */
        if (!legal)
            for (int32_t i = 0; i < nt; i++) {
                wm_touch(r, touched[i]);
                wm_heap_update(r, touched[i], r->err[touched[i]], r->pos[touched[i]], &n);
            }
        /* the new vertex: corner 2 of touched[0] after a triangle's split, corner 1 after an edge's */
        p = me->he[3 * touched[0] + (on < 0 ? 2 : 1)].v;
        WM_ASSERT(me->vxy[p].x == wx && me->vxy[p].y == wy);
        if (legal) wm_legalise(r, p, touched, nt, &n); /* and measures touched[] and what it flips */
        if (st) st->bound_splits++;
    }
    return WM_OK;
}

/* ---------------------------------------------------------------------------------------------- */

/* wm_refine_stats but E_max and the count over zeta */
static void stats_counts(const wm_refiner *r, wm_level_stats *st)
{
    st->level = r->level;
    st->vertices = r->mesh.n_vert;
    st->triangles = r->mesh.n_tri;
    st->budget_hit = r->budget_hit;
    st->flips = r->flips;
    st->removals = r->removals;
}

void wm_refine_stats(const wm_refiner *r, wm_level_stats *st)
{
    const wm_mesh *me = &r->mesh;
    uint32_t emax = 0;
    int32_t over = 0;
    for (int32_t t = 0; t < me->tri_end; t++) {
        if (me->he[3 * t].v < 0) continue;
        if (r->err[t] > emax) emax = r->err[t];
        if (r->err[t] > r->params.zeta) over++;
    }
    st->e_max = emax;
    st->over = over;
    stats_counts(r, st);
}

static void clear_stats(wm_level_stats *st)
{
    st->level = st->vertices = st->triangles = st->iterations = st->active = st->dependent = 0;
    st->pairs = st->quasi_pairs = st->unpaired = st->edge_splits = st->ternary_splits = 0;
    st->moves = st->swaps = st->bound_splits = st->budget_hit = st->over = st->removals = st->flips = 0;
    st->e_max = 0;
}

static int iterate(wm_refiner *r, int32_t m, wm_level_stats *st)
{
    int32_t nops;
    if (wm_select(r, m, st) == 0) return 1; /* nothing active: the level is done */
    st->iterations++;
    nops = wm_plan(r, m, st);
    for (int32_t i = 0; i < nops; i++) {
        int rc = wm_execute(r, m, r->list[i], st);
        if (rc != WM_OK) return rc;
    }
    regularise(r, st, r->params.alpha); /* which clears the plan's WM_F_UNPAIRED */
    return 0;
}

/* 1 when level 0 ends in the error bound and then the final decimation.  A triangle budget does not
 * count: a device always sets one (its storage), and the same job must give the same mesh on it and
 * on the host; a budget that stops the bound then leaves level 0 unreduced as well as undecimated. */
static int decimates(const wm_refiner *r) { return !(r->params.flags & (WM_FLAG_NO_BOUND | WM_FLAG_NO_DECIMATE)); }

int wm_refine_step(wm_refiner *r, wm_level_stats *st)
{
    wm_level_stats local;
    int rc = WM_OK, settled = 0;
    if (st == NULL) st = &local;
    clear_stats(st);
    if (r == NULL || r->done) return WM_ERR_STATE;
    r->budget_hit = 0;
    r->flips = r->removals = 0;
    if (r->level > 0) {
        int32_t m;
        r->level--;
        m = r->level + 1; /* decomposition level of the details (table 4.2) */
        /* Level 0 takes no iterations when the error bound and the final decimation follow: they place
         * its final vertices whatever the finest details' splits did, and it is the run's largest mesh
         * (docs/refiner.md, "The loop": 11 % of the instructions on ten pairs, the same triangles). */
        int32_t k = r->level == 0 && decimates(r) ? 0 : r->params.iterations;
        for (int32_t it = 0; it < k; it++) {
            int done;
            done = iterate(r, m, st);
            if (done < 0) {
                rc = done;
                break;
            }
            if (done) break;
        }
        /* 4.6 step 3(b): remove redundant vertices (reduce.c).  Not at level 0 when the error bound and
         * the final decimation follow: the decimation removes within zeta what can go, so level 0's pass
         * only cost time (Jacksboro at 5 m: 13 % of the instructions; triangles over the quality
         * benchmark's 52 pairs +0.01 %, docs/refiner.md). */
        if (rc == WM_OK && !(r->params.flags & WM_FLAG_NO_REDUCE) && !(r->level == 0 && decimates(r))) {
            WM_PROF_SET(WM_PH_REDUCE);
            wm_reduce(r);
            WM_PROF_SET(WM_PH_LEVELS);
        }
    }
    if (rc == WM_OK && r->level == 0) {
        r->swept = 0; /* pos[] is the heaps' from here on */
        if (!(r->params.flags & WM_FLAG_NO_BOUND)) {
            WM_PROF_SET(WM_PH_BOUND);
            rc = error_bound(r, st);
            while (rc == WM_OK && r->field.mask && !r->budget_hit && (rc = wm_hole_cover(r)) > 0)
                rc = error_bound(r, st); /* holes.c: a grid neighbour for valid vertices in no kept triangle */
            /* A budget that stopped the bound keeps its triangles: removing vertices would leave
             * fewer than asked for, at the same E_max. */
            WM_PROF_SET(WM_PH_DECIMATE);
            if (rc == WM_OK && !r->budget_hit && !(r->params.flags & WM_FLAG_NO_DECIMATE)) rc = wm_decimate(r, st);
            else wm_settle(r, st); /* the E(T) the bound left unmeasured (wm_decimate settles its own and those) */
            settled = 1; /* st->e_max and st->over: the job's last step, wm_settle's */
            WM_PROF_SET(WM_PH_LEVELS);
        }
        r->done = 1;
    }
    if (rc != WM_OK) {
        r->done = 1;
        r->failed = rc;
    }
    if (settled) {
#if WM_CHECK
        wm_level_stats all;
        wm_refine_stats(r, &all);
        WM_ASSERT(all.e_max == st->e_max && all.over == st->over);
#endif
        stats_counts(r, st);
    } else {
        wm_refine_stats(r, st);
    }
    return rc;
}

int32_t wm_refine_level(const wm_refiner *r) { return r->level; }
int wm_refine_done(const wm_refiner *r) { return r->done; }
const wm_mesh *wm_refine_mesh(const wm_refiner *r) { return &r->mesh; }
