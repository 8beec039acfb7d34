/* The reduction of 4.6 steps 2(d) and 3(b): vertex removal (4.5.2) and edge collapse (4.5.3) where
 * the autocorrelation matrix R(v) of the normals around a vertex (autocorr.c) says the surface is
 * flat (both small eigenvalues below delta_lambda) or a crease shared by both ends of an edge.
 *
 *   for v in slot order (vertices made on the way are visited when their slot comes):
 *       lambda1 <= lambda2 < delta_lambda (4.32):  remove v, the hole re-triangulated by
 *                                                  wm_star_plan (O(h log h)), if within the bound
 *       lambda1 < delta_lambda < lambda2 (4.33):   for each neighbour w (counter-clockwise) with
 *                                                  4.33 too and |e2(v) . e2(w)| > delta_c (4.34):
 *                                                  collapse v - w at the first collapse point that
 *                                                  is valid and within the bound; stop at the first
 *
 *   the bound: every new triangle's E(T) <= max(zeta, the largest E(T) of the triangles it
 *   replaces), so E_max never grows and no part of the mesh gets worse than it was
 *
 *        p3------p2           p3------p2
 *        / \    / \           / \_     \         removal: the star of v (here flat) becomes the
 *       /   \  /   \         /    \_    \        ring's ear triangulation, h - 2 triangles
 *     p4-----v------p1  ->  p4-------\_--p1
 *       \   /  \   /         \         \_/       collapse: see edge_collapse.c
 *        \ /    \ /           \         /
 *        p5------p0           p5-------p0
 *
 * The collapse point (4.5.3: "a midpoint of the edge"): every vertex is a grid sample, so the
 * midpoint when it is one (both coordinate differences even); otherwise the edge's inner grid
 * samples nearest the midpoint (for G = gcd(|dx|, |dy|) odd, the two at (G -+ 1) / 2 of G, the one
 * nearer v first); then, when the edge has no inner sample (G = 1) or those fail, a half-edge
 * collapse into v's position and then into w's.  The first candidate that gives a proper mesh and
 * keeps the bound is taken.
 *
 * Determinism: slot order, ring order, integer arithmetic: the same mesh on every machine. */
#include "wm_internal.h"

/* ---------------------------------------------------------------------------------------------- */
/* The hole of a removed vertex: ear clipping over a binary heap of ears, O(h log h) */

#ifndef WM_ANGLE_ENGINE
/* The ears' keys, measured lazily: the heap orders by the CORDIC's Q16 angle (wm_angle_q16, ties by
 * position), but most of its comparisons are decided by a cheaper monotone proxy.  With t = cross / dot
 * the tangent of the ear's smallest angle theta (in (0, 60] degrees, dot > 0), the proxy is
 *
 *     K = floor(2^16 t)              for t <= 1
 *     K = 2^17 - floor(2^16 / t)     for t > 1        (one division; K in [0, 2^17], monotone in theta)
 *
 * 2^16 f(theta) less under 1, with f = tan below 45 degrees and 2 - cot above: f' = 1 + tan^2 or
 * 1 + cot^2, within [1, 2].  So K_i - K_j >= KEY_MARGIN (80) gives theta_i - theta_j > 79 / 2^17 rad,
 * 39.5 Q16 units, more than twice the CORDIC's error (within 10 of atan2, fixed.c; 16 taken): the
 * CORDIC's angles are ordered as the proxies, strictly.  Closer proxies take both CORDIC angles (kept
 * once measured): the heap's comparisons, so its order and the plan, are those of the Q16 keys. */
#define KEY_MARGIN 80
#define KEY_UNKNOWN INT32_MAX /* key[i] not measured yet (prox, dot, cross hold the ear) */
#define KEY_OLD WM_MAX_RING   /* the slot of an ear's key before its update */
#endif

#ifndef WM_ANGLE_ENGINE
#define EAR_KEYS (WM_MAX_RING + 1) /* and KEY_OLD */
#else
#define EAR_KEYS WM_MAX_RING
#endif

struct ears {
    int32_t prev[WM_MAX_RING], next[WM_MAX_RING], key[EAR_KEYS], heap[WM_MAX_RING], pos[WM_MAX_RING];
#ifndef WM_ANGLE_ENGINE
    int32_t prox[EAR_KEYS], dot[EAR_KEYS], cross[EAR_KEYS];
#endif
    int32_t n;
};

#ifndef WM_ANGLE_ENGINE
static int32_t key_of(struct ears *s, int32_t i)
{
    if (s->key[i] == KEY_UNKNOWN) s->key[i] = wm_angle_q16(s->dot[i], s->cross[i]);
    return s->key[i];
}

#if WM_CHECK
static int32_t key_measured(const struct ears *s, int32_t i)
{
    return s->key[i] != KEY_UNKNOWN ? s->key[i] : wm_angle_q16(s->dot[i], s->cross[i]);
}
#endif

/* The sign of key[i] - key[j] (KEY_OLD may be either) */
static int key_cmp(struct ears *s, int32_t i, int32_t j)
{
    int32_t a, b;
    if (s->key[i] == KEY_UNKNOWN || s->key[j] == KEY_UNKNOWN) {
        int32_t d = s->prox[i] - s->prox[j];
        /* checked builds: the proxy's order is the CORDIC's */
        WM_ASSERT(d < KEY_MARGIN || key_measured(s, i) > key_measured(s, j));
        WM_ASSERT(d > -KEY_MARGIN || key_measured(s, i) < key_measured(s, j));
        if (d >= KEY_MARGIN) return 1;
        if (d <= -KEY_MARGIN) return -1;
    }
    a = key_of(s, i), b = key_of(s, j);
    return a > b ? 1 : a < b ? -1 : 0;
}

static int better(struct ears *s, int32_t i, int32_t j)
{
    int c = key_cmp(s, i, j);
    return c > 0 || (c == 0 && i < j);
}
#else
static int better(const struct ears *s, int32_t i, int32_t j)
{
    return s->key[i] > s->key[j] || (s->key[i] == s->key[j] && i < j);
}
#endif

static void ear_put(struct ears *s, int32_t at, int32_t i)
{
    s->heap[at] = i;
    s->pos[i] = at;
}

static void ear_up(struct ears *s, int32_t at)
{
    int32_t i = s->heap[at];
    while (at > 0 && better(s, i, s->heap[(at - 1) / 2])) {
        ear_put(s, at, s->heap[(at - 1) / 2]);
        at = (at - 1) / 2;
    }
    ear_put(s, at, i);
}

static void ear_down(struct ears *s, int32_t at)
{
    int32_t i = s->heap[at];
    for (;;) {
        int32_t c = 2 * at + 1;
        if (c >= s->n) break;
        if (c + 1 < s->n && better(s, s->heap[c + 1], s->heap[c])) c++;
        if (!better(s, s->heap[c], i)) break;
        ear_put(s, at, s->heap[c]);
        at = c;
    }
    ear_put(s, at, i);
}

/* The key of the ear at ring position i: its smallest angle (Q16 radians) when it may be cut, else -1;
 * with angle 0, 0 for an ear that may be cut (no angle measured). */
static int32_t ear_key(const wm_mesh *m, const int32_t *ring, const struct ears *s, int32_t i, int32_t kx,
                       int32_t ky, int angle)
{
    int32_t a = ring[s->prev[i]], b = ring[i], c = ring[s->next[i]];
    int32_t x[3] = {m->vxy[a].x, m->vxy[b].x, m->vxy[c].x}, y[3] = {m->vxy[a].y, m->vxy[b].y, m->vxy[c].y};
    if (wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]) <= 0) return -1;
    if (wm_orient(x[0], y[0], x[2], y[2], kx, ky) < 0) return -1; /* k strictly on b's side of a-c */
    return angle ? wm_min_angle(x, y) : 0;
}

#ifndef WM_ANGLE_ENGINE
/* ear_key's key into s (slot i): -1, or KEY_UNKNOWN with the proxy and the corner's products */
static void ear_set(const wm_mesh *m, const int32_t *ring, struct ears *s, int32_t i, int32_t kx, int32_t ky)
{
    int64_t dot, cross;
    int32_t a = ring[s->prev[i]], b = ring[i], c = ring[s->next[i]];
    int32_t x[3] = {m->vxy[a].x, m->vxy[b].x, m->vxy[c].x}, y[3] = {m->vxy[a].y, m->vxy[b].y, m->vxy[c].y};
    if (wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]) <= 0 || wm_orient(x[0], y[0], x[2], y[2], kx, ky) < 0) {
        s->key[i] = -1;
        s->prox[i] = -(1 << 20); /* below every proxy by more than KEY_MARGIN */
        return;
    }
    wm_min_corner(x, y, &dot, &cross); /* 0 < dot, cross < 2^31; the smallest angle is at most 60 degrees */
    WM_ASSERT(dot > 0 && cross > 0);
    s->key[i] = KEY_UNKNOWN;
    s->dot[i] = (int32_t)dot, s->cross[i] = (int32_t)cross;
    s->prox[i] = cross <= dot ? (int32_t)(((uint64_t)cross << 16) / (uint64_t)dot)
                              : (1 << 17) - (int32_t)(((uint64_t)dot << 16) / (uint64_t)cross);
}
#endif

/* The ear the heap would hold first once three ring positions are left (i, next, next of next): the
 * three ears are one triangle, so those that may be cut share one key (its smallest angle: the same
 * integers at any corner, wm_min_corner) and the others have -1; the heap's order (key, then the lower
 * position) then takes the lowest position that may be cut, else the lowest of the three.  Without
 * measuring the angle (two ear_key updates a plan, three a ring of three). */
static int32_t last_ear(const wm_mesh *m, const int32_t *ring, const struct ears *s, int32_t i, int32_t kx,
                        int32_t ky)
{
    int32_t e[3] = {i, s->next[i], s->next[s->next[i]]}, best = -1, low = e[0];
    for (int q = 0; q < 3; q++) {
        if (e[q] < low) low = e[q];
        if ((best < 0 || e[q] < best) && ear_key(m, ring, s, e[q], kx, ky, 0) == 0) best = e[q];
    }
    return best >= 0 ? best : low;
}

int wm_star_plan(const wm_mesh *m, const int32_t *ring, int32_t n, int32_t kx, int32_t ky,
                 int32_t tris[3 * WM_MAX_RING], int32_t *n_tris)
{
    struct ears s_, *s = &s_;
    int32_t left = n, nt = 0, last = 0;
#if WM_NARROW_DIV
    /* s a register, not the stack pointer and an offset: GCC formed each element's address from the stack
     * pointer in four or five instructions (sll, add, add sp, add, the load's offset) */
    __asm__("" : "+r"(s));
#endif
    if (n < 3 || n > WM_MAX_RING) return WM_ERR_ARG;
    /* the list's ends wrapped once, not by a remainder a position (on the board each remainder a call of
     * __modsi3 and the CPU's 33-cycle division) */
    for (int32_t i = 0; i < n; i++) {
        s->prev[i] = i - 1;
        s->next[i] = i + 1;
    }
    s->prev[0] = n - 1, s->next[n - 1] = 0;
    if (n > 3) {
        for (int32_t i = 0; i < n; i++) {
#ifndef WM_ANGLE_ENGINE
            ear_set(m, ring, s, i, kx, ky);
#else
            s->key[i] = ear_key(m, ring, s, i, kx, ky, 1);
#endif
            s->heap[i] = i;
            s->pos[i] = i;
        }
        s->n = n;
        for (int32_t at = n / 2 - 1; at >= 0; at--) ear_down(s, at);
    }
    while (left > 3) {
        int32_t b = s->heap[0], a = s->prev[b], c = s->next[b];
        if (s->key[b] < 0) return WM_ERR_REFUSED; /* no ear may be cut */
        tris[3 * nt] = ring[a], tris[3 * nt + 1] = ring[b], tris[3 * nt + 2] = ring[c];
        nt++;
        /* b leaves the polygon and the heap (the last entry takes its place) */
        s->next[a] = c;
        s->prev[c] = a;
        if (--left == 3) {
            last = a; /* last_ear finds the first of the three without the heap */
            break;
        }
        s->n--;
        ear_put(s, 0, s->heap[s->n]);
        ear_down(s, 0);
        for (int q = 0; q < 2; q++) {
#ifndef WM_ANGLE_ENGINE
            int32_t i = q == 0 ? a : c;
            s->key[KEY_OLD] = s->key[i], s->prox[KEY_OLD] = s->prox[i];
            s->dot[KEY_OLD] = s->dot[i], s->cross[KEY_OLD] = s->cross[i];
            ear_set(m, ring, s, i, kx, ky);
            if (key_cmp(s, i, KEY_OLD) > 0) ear_up(s, s->pos[i]);
            else ear_down(s, s->pos[i]);
#else
            int32_t i = q == 0 ? a : c, old = s->key[i];
            s->key[i] = ear_key(m, ring, s, i, kx, ky, 1);
            if (s->key[i] > old) ear_up(s, s->pos[i]);
            else ear_down(s, s->pos[i]);
#endif
        }
    }
    {
        int32_t b = last_ear(m, ring, s, last, kx, ky), a = s->prev[b], c = s->next[b];
        if (wm_orient(m->vxy[ring[a]].x, m->vxy[ring[a]].y, m->vxy[ring[b]].x, m->vxy[ring[b]].y,
                      m->vxy[ring[c]].x, m->vxy[ring[c]].y) <= 0)
            return WM_ERR_REFUSED;
        tris[3 * nt] = ring[a], tris[3 * nt + 1] = ring[b], tris[3 * nt + 2] = ring[c];
        nt++;
    }
    *n_tris = nt;
    return WM_OK;
}

/* ---------------------------------------------------------------------------------------------- */
/* The pass */

/* A vertex's class, kept in r->vapex from pass to pass: wm_touch forgets it (CLS_UNKNOWN) for the
 * three vertices of every triangle an operator makes or changes, so a class that is still there
 * belongs to the star the vertex has now.  A removal that failed fails again on the same star (its
 * plan and its bound depend on nothing else): CLS_REMOVE_FAILED skips it until the star changes.
 *
 * A collapse of v - u depends on the stars of v and u alone (their classes, e2's test, the candidates
 * and the bound), and is the same from either end: the test |e2(v) . e2(u)| is symmetric, the
 * candidates are the same points (the inner ones nearest the midpoint, then both ends) and a candidate
 * is taken when its plan is valid and every one of its triangles within the bound, whatever their
 * order.  So a 4.33 vertex u whose visit saw every neighbour and had every collapse refused by the
 * stars (not the storage) is CLS_COLLAPSE_FAILED: while it stays so, the pair u - v is refused with
 * the stars u and v have now, and v's visit skips u (no class, test or collapse), unless v's own star
 * may have changed since u's visit:
 *   - v's class forgotten and found again at v's own visit (was CLS_UNKNOWN there): no skips in that
 *     visit, which tries every pair itself;
 *   - v's class found again by a neighbour's visit (the loop below): unfail_ring makes v's
 *     CLS_COLLAPSE_FAILED neighbours CLS_COLLAPSE.
 * A CLS_COLLAPSE_FAILED vertex's own visit is a 4.33 vertex's (its neighbours' stars may have changed;
 * its class is still its star's). */
#define CLS_UNKNOWN WM_CLASS_UNKNOWN
#define CLS_NONE 0
#define CLS_REMOVE 1          /* 4.32 */
#define CLS_COLLAPSE 2        /* 4.33 */
#define CLS_REMOVE_FAILED 3   /* 4.32, and its removal was refused on this star */
#define CLS_COLLAPSE_FAILED 4 /* 4.33, and its visit's collapses were refused (above) */

struct eig {
    int64_t r[6], lambda[3], vec[9];
};

static int64_t shift_round(int64_t a, int sh)
{
    uint64_t u = a < 0 ? (uint64_t)0 - (uint64_t)a : (uint64_t)a;
    u = (u + ((uint64_t)1 << (sh - 1))) >> sh;
    return a < 0 ? -(int64_t)u : (int64_t)u;
}

/* The class of R (4.32, 4.33) from the number of its eigenvalues below, and equal to, t = delta_lambda,
 * without the eigenvalues: R's characteristic polynomial p(x) = x^3 - T x^2 + S x - det R has only real
 * roots (R is symmetric), so by Descartes' rule, exact for such polynomials, the number of roots above
 * t is the number of sign changes in the coefficients of
 *
 *     q(u) = p(t + u) = u^3 + (3t - T) u^2 + (3t^2 - 2Tt + S) u + p(t)
 *
 * (a root at t itself first divided out: p(t) = 0).  In integers on R and t rounded to Q19 (entries
 * and t within [-1, 1]: every term below 2^61), so the class is exact for that matrix: it differs from
 * one made with R's exact eigenvalues only when one of them lies within a few 2^-19 of delta_lambda. */
static int8_t class_of(const int64_t r[6], uint32_t delta_lambda)
{
    /* R's entries in Q19 are within 2^19 + 1 in magnitude: 32-bit integers, so each product of two is
     * one 32 x 32 bit multiply (on the soft CPU a mul and a mulh, not a 64-bit product's four) */
    int32_t a = (int32_t)shift_round(r[0], 11), b = (int32_t)shift_round(r[1], 11); /* Q19 */
    int32_t c = (int32_t)shift_round(r[2], 11), d = (int32_t)shift_round(r[3], 11);
    int32_t e = (int32_t)shift_round(r[4], 11), f = (int32_t)shift_round(r[5], 11);
    int64_t t = (int64_t)delta_lambda << 3; /* Q19 */
    int64_t T = (int64_t)a + d + f;
    int64_t S =
        (int64_t)a * d - (int64_t)b * b + (int64_t)a * f - (int64_t)c * c + (int64_t)d * f - (int64_t)e * e;
    int64_t det = a * ((int64_t)d * f - (int64_t)e * e) - b * ((int64_t)b * f - (int64_t)c * e) +
                  c * ((int64_t)b * e - (int64_t)d * c); /* Q57 */
    int64_t k[4], prev = 1;
    int n = 4, above = 0, at = 0, below;
    if (delta_lambda >= 65536u) return CLS_REMOVE; /* every eigenvalue of R is at most 1 */
    k[0] = 1;
    k[1] = 3 * t - T;
    k[2] = 3 * t * t - 2 * T * t + S;
    k[3] = ((t - T) * t + S) * t - det; /* p(t), Q57: t^3 - T t^2 + S t - det */
    while (n > 1 && k[n - 1] == 0) {
        n--;
        at++;
    }
    for (int i = 1; i < n; i++) {
        if (k[i] == 0) continue;
        if ((k[i] < 0) != (prev < 0)) above++;
        prev = k[i];
    }
    below = 3 - above - at;
    if (below >= 2) return CLS_REMOVE;                /* lambda1 <= lambda2 < delta_lambda */
    if (below == 1 && at == 0) return CLS_COLLAPSE;   /* lambda1 < delta_lambda < lambda2 */
    return CLS_NONE;
}

/* The class of v (4.32, 4.33); for a collapse also the eigen-decomposition (into g), whose middle
 * eigenvector the collapse test compares (4.34). */
static int8_t classify(wm_refiner *r, int32_t v, struct eig *g)
{
    int8_t cls;
    if (wm_vertex_r(&r->mesh, &r->field, &r->params, v, g->r, r->normals, r->cache_mask) < 0) return CLS_NONE;
    cls = class_of(g->r, r->params.delta_lambda);
    if (cls == CLS_COLLAPSE) wm_sym3_eigen(g->r, g->lambda, g->vec);
    return cls;
}

/* The largest E(T) around v, at least zeta; *any gets the OR of those E(T) (0: every one is 0). */
static uint32_t star_bound(const wm_refiner *r, int32_t v, uint32_t b, uint32_t *any)
{
    const wm_mesh *me = &r->mesh;
    int32_t first = wm_fan_first(me, v), h = first;
    uint32_t o = 0;
    if (b < r->params.zeta) b = r->params.zeta;
    do {
        uint32_t e = r->err[WM_TRI(h)];
        o |= e;
        if (e > b) b = e;
        h = wm_rot_ccw(me, h);
    } while (h >= 0 && h != first);
    *any |= o;
    return b;
}

/* A flat region: when every triangle an operation replaces has E(T) = 0 (each sample of it on its
 * plane) and every corner of them lies on one plane P, every sample of the region lies on P, and so
 * does every new triangle (its corners are the region's vertices, or a grid sample of it: the collapse
 * point), which covers part of the region: its E(T) is 0, and its worst sample is the scan's for
 * Vmax = 0, its corner 0 (wm_place_at).  Known without a scan (Box 256's enhancement: most of its
 * reduction's scans).  Not with a holes mask or a region of interest, whose E(T) is over some samples
 * only.  The plane through the corners of triangle t: (x, y, z) lies on it iff
 * D (z - z0) = Na (x - x0) + Nb (y - y0) (|D| < 2^31, |Na|, |Nb| < 2^33: every term below 2^50). */
struct plane {
    int32_t x0, y0, z0;
    int64_t d, na, nb;
};

static void plane_of(const wm_refiner *r, int32_t t, struct plane *pl)
{
    const wm_mesh *me = &r->mesh;
    int32_t x[3], y[3], z[3];
    for (int c = 0; c < 3; c++) {
        int32_t v = me->he[3 * t + c].v;
        x[c] = me->vxy[v].x, y[c] = me->vxy[v].y;
        z[c] = r->field.samples[(int64_t)y[c] * r->field.width + x[c]];
    }
    pl->x0 = x[0], pl->y0 = y[0], pl->z0 = z[0];
    pl->d = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    pl->na = (int64_t)(z[1] - z[0]) * (y[2] - y[0]) - (int64_t)(z[2] - z[0]) * (y[1] - y[0]);
    pl->nb = (int64_t)(x[1] - x[0]) * (z[2] - z[0]) - (int64_t)(x[2] - x[0]) * (z[1] - z[0]);
}

static int on_plane(const wm_refiner *r, const struct plane *pl, const int32_t *vs, int32_t n)
{
    const wm_mesh *me = &r->mesh;
    for (int32_t i = 0; i < n; i++) {
        int32_t x = me->vxy[vs[i]].x, y = me->vxy[vs[i]].y;
        int32_t z = r->field.samples[(int64_t)y * r->field.width + x];
        if (pl->d * (z - pl->z0) != pl->na * (x - pl->x0) + pl->nb * (y - pl->y0)) return 0;
    }
    return 1;
}

/* Whether the vertices vs[0 .. n) and ws[0 .. m) lie on the plane of triangle t (out of line: few
 * operations ask, and inline its terms grew the reduction's code by a kilobyte). */
WM_NEVER_INLINE static int flat_region(const wm_refiner *r, int32_t t, const int32_t *vs, int32_t n,
                                       const int32_t *ws, int32_t m)
{
    struct plane pl;
    plane_of(r, t, &pl);
    return on_plane(r, &pl, vs, n) && on_plane(r, &pl, ws, m);
}

/* within's answer for a flat region: every new triangle E(T) 0, its worst sample its corner 0. */
WM_NEVER_INLINE static void flat_within(const wm_refiner *r, const int32_t *tris, int32_t nt, int32_t px,
                                        int32_t py, uint32_t *e, int32_t *w)
{
    const wm_mesh *me = &r->mesh;
    for (int32_t j = 0; j < nt; j++) {
        int32_t v = tris[3 * j];
#if WM_CHECK
        int32_t x[3], y[3], wx, wy;
        for (int c = 0; c < 3; c++) {
            int32_t u = tris[3 * j + c];
            x[c] = u < 0 ? px : me->vxy[u].x;
            y[c] = u < 0 ? py : me->vxy[u].y;
        }
        WM_ASSERT(wm_tri_error(&r->field, &r->params, x, y, &wx, &wy) == 0 && wx == x[0] && wy == y[0]);
#endif
        e[j] = 0;
        w[j] = (v < 0 ? py : me->vxy[v].y) * r->field.width + (v < 0 ? px : me->vxy[v].x);
    }
}

static int may_be_flat(const wm_refiner *r) { return r->field.mask == NULL && r->roi == NULL; }

/* 1 when every triangle of tris (WM_COLLAPSE_POINT standing for (px, py)) has E(T) <= bound; then, without
 * an ROI (whose E(T) is over its samples only), each one's E(T) and worst sample in e[] and w[] (a scan
 * that never passes its bound is the whole scan, so these are wm_tri_error's values: known[] below). */
static int within(const wm_refiner *r, const int32_t *tris, int32_t nt, int32_t px, int32_t py, uint32_t bound,
                  uint32_t *e, int32_t *w, const int32_t *gone, int ngone, int flat)
{
    const wm_mesh *me = &r->mesh;
    uint64_t kept = 0; /* the slope factor of triangle jk, which the cheap test measured (wm_internal.h) */
    int32_t jk = -1;
    if (flat) { /* a flat region (plane_of above): E(T) 0 at corner 0, without a scan */
        flat_within(r, tris, nt, px, py, e, w);
        return 1;
    }
    /* First the cheap test: the samples of the vertices the operation takes away, against the new
     * triangle holding each (a lower bound of its E(T), rounded as E(T) is): a failed operation
     * mostly stops here, without a scan. */
    for (int g = 0; g < ngone; g++) {
        int32_t gx = me->vxy[gone[g]].x, gy = me->vxy[gone[g]].y;
        for (int32_t j = 0; j < nt; j++) {
            int32_t x[3], y[3];
            for (int c = 0; c < 3; c++) {
                int32_t v = tris[3 * j + c];
                x[c] = v < 0 ? px : me->vxy[v].x;
                y[c] = v < 0 ? py : me->vxy[v].y;
            }
            if (wm_orient(x[0], y[0], x[1], y[1], gx, gy) < 0 || wm_orient(x[1], y[1], x[2], y[2], gx, gy) < 0 ||
                wm_orient(x[2], y[2], x[0], y[0], gx, gy) < 0)
                continue;
            if (wm_point_above(&r->field, &r->params, x, y, gx, gy, bound, &kept)) return 0;
            jk = j;
            break;
        }
    }
    for (int32_t j = 0; j < nt; j++) {
        int32_t x[3], y[3], wx = 0, wy = 0;
        for (int c = 0; c < 3; c++) {
            int32_t v = tris[3 * j + c];
            x[c] = v < 0 ? px : me->vxy[v].x;
            y[c] = v < 0 ? py : me->vxy[v].y;
        }
        e[j] = wm_tri_error_within(&r->field, &r->params, x, y, bound, &wx, &wy, j == jk ? &kept : NULL);
        if (e[j] > bound) return 0;
        w[j] = wy * r->field.width + wx;
    }
    return 1;
}

/* As wm_touch for each of the nt triangles an operation made (touched[]), with the E(T) and worst
 * sample within() measured for the planned triangle of the same corners (a corner order of the plan's
 * is a rotation of the mesh's: both counter-clockwise, and the scan's result does not depend on it). */
static void known(wm_refiner *r, const int32_t *touched, int32_t k, const int32_t *tris, int32_t nt, int32_t px,
                  int32_t py, const uint32_t *e, const int32_t *w)
{
    wm_mesh *me = &r->mesh;
    for (int32_t i = 0; i < k; i++) {
        int32_t t = touched[i], j = nt, x[3], y[3];
        if (r->roi == NULL) {
            /* from plan triangle i on (a removal makes touched[i] of tris' i-th triangle, so the first
             * one tried is mostly it); a triangle's corners are in one plan triangle at most, so the
             * one found is the one a search from 0 finds */
            int32_t s;
            wm_tri_xy(me, t, x, y);
            for (s = 0, j = i < nt ? i : 0; s < nt; s++, j = j + 1 < nt ? j + 1 : 0) {
                int c = 0, hit = 0;
                for (c = 0; c < 3; c++) {
                    int32_t v = tris[3 * j + c];
                    if ((v < 0 ? px : me->vxy[v].x) == x[0] && (v < 0 ? py : me->vxy[v].y) == y[0]) break;
                }
                if (c < 3) {
                    int32_t v1 = tris[3 * j + wm_k1(c)], v2 = tris[3 * j + wm_k2(c)];
                    hit = (v1 < 0 ? px : me->vxy[v1].x) == x[1] && (v1 < 0 ? py : me->vxy[v1].y) == y[1] &&
                          (v2 < 0 ? px : me->vxy[v2].x) == x[2] && (v2 < 0 ? py : me->vxy[v2].y) == y[2];
                }
                if (hit) break;
            }
            if (s == nt) j = nt;
        }
        if (j == nt) {
            wm_touch(r, t);
            continue;
        }
        r->err[t] = e[j];
        r->worst[t] = w[j];
        me->tflag[t] |= WM_F_NEW;
        wm_forget_class(r, t);
    }
}

static int try_remove(wm_refiner *r, int32_t v)
{
    wm_mesh *me = &r->mesh;
    int32_t ring[WM_MAX_RING], tris[3 * WM_MAX_RING], touched[WM_MAX_RING], w[WM_MAX_RING], n, nt, k;
    uint32_t e[WM_MAX_RING];
    n = wm_vertex_ring(me, v, ring);
    if (n < 0) return 0; /* a corner, or too many neighbours */
    if (wm_star_plan(me, ring, n, me->vxy[v].x, me->vxy[v].y, tris, &nt) != WM_OK &&
        wm_vertex_remove_plan(me, v, -1, tris, &nt) != WM_OK)
        return 0;
    {
        uint32_t any = 0, bound = star_bound(r, v, 0, &any);
        int flat = 0;
        if (any == 0 && may_be_flat(r)) flat = flat_region(r, WM_TRI(wm_fan_first(me, v)), ring, n, ring, 0);
        if (!within(r, tris, nt, 0, 0, bound, e, w, &v, 1, flat)) return 0;
    }
    if (wm_vertex_remove(me, v, tris, nt, touched, &k) != WM_OK) return 0;
    known(r, touched, k, tris, nt, 0, 0, e, w);
    return 1;
}

/* Collapses the edge e = v -> w (see the head of this file for the collapse point): 1 when it did, 0
 * when the stars of v and w refused it (their plans or their bound), -1 when the storage did. */
static int try_collapse(wm_refiner *r, int32_t e)
{
    wm_mesh *me = &r->mesh;
    int32_t v = me->he[e].v, w = wm_dest(me, e), tris[6 * WM_MAX_RING], touched[6 * WM_MAX_RING], nt, k;
    int32_t ws[6 * WM_MAX_RING];
    uint32_t es[6 * WM_MAX_RING];
    struct wm_collapse_stars stars;
    int32_t ax = me->vxy[v].x, ay = me->vxy[v].y, bx = me->vxy[w].x, by = me->vxy[w].y;
    int32_t dx = bx - ax, dy = by - ay, g = wm_gcd(dx, dy), cx[4], cy[4], nc = 0;
    uint32_t any = 0, bound = star_bound(r, w, star_bound(r, v, 0, &any), &any);
    int flat = 0;
    if (g >= 2) {
        int32_t k0 = g / 2, k1 = (g + 1) / 2; /* equal for an even g: the midpoint itself */
        cx[nc] = ax + dx / g * k0, cy[nc++] = ay + dy / g * k0;
        if (k1 != k0) cx[nc] = ax + dx / g * k1, cy[nc++] = ay + dy / g * k1;
    }
    cx[nc] = ax, cy[nc++] = ay;
    cx[nc] = bx, cy[nc++] = by;
    /* the stars and the link condition once for every point (a failure there fails every point) */
    if (wm_collapse_stars(me, e, &stars) != WM_OK) return 0;
    if (any == 0 && may_be_flat(r)) /* both stars flat, in one plane */
        flat = flat_region(r, WM_TRI(stars.out[0][0]), stars.nb[0], stars.n[0], stars.nb[1], stars.n[1]);
    for (int32_t i = 0; i < nc; i++) {
        if (wm_collapse_plan_at(me, &stars, cx[i], cy[i], tris, &nt) != WM_OK) continue;
        WM_ASSERT(wm_edge_collapse_plan(me, e, cx[i], cy[i], ws, &k) == WM_OK && k == nt);
        if (!within(r, tris, nt, cx[i], cy[i], bound, es, ws, NULL, 0, flat)) continue;
        if (wm_edge_collapse_planned(me, e, cx[i], cy[i], nt, touched, &k, NULL) != WM_OK)
            return -1; /* capacity */
        known(r, touched, k, tris, nt, cx[i], cy[i], es, ws);
        return 1;
    }
    return 0;
}

/* The middle eigenvectors of the latest collapse-class vertices, by slot (r->ecache, direct-mapped,
 * emptied when the refiner starts): a vertex of class 4.33 is tested once as v and again as a
 * neighbour of each of its collapse-class neighbours, in this pass and the next ones, and its star has
 * not changed in between unless its class was forgotten (wm_forget_class), so while vapex still says
 * 4.33 the vector kept is the one classify would compute again.  Its entries are Q30 within [-1, 1],
 * kept in 32 bits. */
static int8_t classify_cached(wm_refiner *r, int32_t v, struct eig *g)
{
    struct wm_ecache_slot *c = &r->ecache[v & r->cache_mask];
    int8_t cls;
    if ((r->vapex[v] == CLS_COLLAPSE || r->vapex[v] == CLS_COLLAPSE_FAILED) && c->v == v) {
        for (int i = 0; i < 3; i++) g->vec[3 + i] = c->e2[i];
        return CLS_COLLAPSE;
    }
    cls = classify(r, v, g);
    if (cls == CLS_COLLAPSE) {
        c->v = v;
        for (int i = 0; i < 3; i++) {
            WM_ASSERT(g->vec[3 + i] >= -((int64_t)1 << 31) && g->vec[3 + i] < ((int64_t)1 << 31));
            c->e2[i] = (int32_t)g->vec[3 + i];
        }
    }
    return cls;
}

/* v has a class again, found by a neighbour's visit, after its star changed: a neighbour of v whose
 * collapses were refused with v's old star (CLS_COLLAPSE_FAILED) is a plain 4.33 vertex again. */
static void unfail_ring(wm_refiner *r, int32_t v)
{
    const wm_mesh *me = &r->mesh;
    int32_t first = wm_fan_first(me, v), h = first, last = first;
    do {
        int32_t u = wm_dest(me, h);
        if (r->vapex[u] == CLS_COLLAPSE_FAILED) r->vapex[u] = CLS_COLLAPSE;
        last = h;
        h = wm_rot_ccw(me, h);
    } while (h >= 0 && h != first);
    last = me->he[WM_PREV(last)].v; /* on a side: the last neighbour, whose edge arrives at v */
    if (h < 0 && r->vapex[last] == CLS_COLLAPSE_FAILED) r->vapex[last] = CLS_COLLAPSE;
}

#if WM_CHECK
/* Checked builds: the pair v - u (edge e) that v's visit skips is refused again: u is 4.33 and either
 * e2's test or every collapse candidate refuses it (a collapse made here fails the assert). */
static int refused_again(wm_refiner *r, int32_t e, int32_t u, const struct eig *gv, uint64_t dc)
{
    struct eig gw;
    int64_t dot = 0;
    if (classify(r, u, &gw) != CLS_COLLAPSE) return 0;
    for (int c = 0; c < 3; c++) dot += gv->vec[3 + c] * gw.vec[3 + c];
    if ((dot < 0 ? (uint64_t)0 - (uint64_t)dot : (uint64_t)dot) <= dc) return 1;
    return try_collapse(r, e) <= 0;
}
#endif

void wm_reduce_forget_refusals(wm_refiner *r)
{
    for (int32_t v = 0; v < r->mesh.vert_end; v++) {
        if (r->vapex[v] == CLS_COLLAPSE_FAILED) r->vapex[v] = CLS_COLLAPSE;
        if (r->vapex[v] == CLS_REMOVE_FAILED) r->vapex[v] = CLS_REMOVE;
    }
}

int32_t wm_reduce(wm_refiner *r)
{
    wm_mesh *me = &r->mesh;
    int32_t removed = 0;
    uint64_t dc = (uint64_t)r->params.delta_c << 44; /* Q16.16 -> Q60, the scale of e21 . e22 */
    for (int32_t v = 0; v < me->vert_end; v++) {
        struct eig gv, gw;
        int32_t out[WM_MAX_RING + 1], k = 0, first, h, refused = 1, whole;
        int8_t cls, was = r->vapex[v];
        if (me->vxy[v].x == WM_FREE || was == CLS_NONE || was == CLS_REMOVE_FAILED) continue;
        if (was == CLS_COLLAPSE_FAILED) r->vapex[v] = CLS_COLLAPSE;
        /* a 4.32 class still there is its current star's (a neighbour's test below found it; the
         * removal needs no eigenvectors) */
        cls = was == CLS_REMOVE ? CLS_REMOVE : classify_cached(r, v, &gv);
        if (was == CLS_UNKNOWN) r->vapex[v] = cls;
        if (cls == CLS_REMOVE) {
            if (try_remove(r, v)) removed++;
            else r->vapex[v] = CLS_REMOVE_FAILED;
            continue;
        }
        if (cls != CLS_COLLAPSE) continue;
        /* the edges at v, counter-clockwise (on a side, the last one arrives at v) */
        first = wm_fan_first(me, v);
        h = first;
        do {
            out[k++] = h;
            h = wm_rot_ccw(me, h);
        } while (h >= 0 && h != first && k < WM_MAX_RING);
        whole = h < 0 || h == first; /* every neighbour, none left out by WM_MAX_RING */
        if (h < 0) {
            out[k] = WM_PREV(out[k - 1]);
            k++;
        }
        for (int32_t i = 0; i < k; i++) {
            int32_t e = out[i], u = me->he[e].v == v ? wm_dest(me, e) : me->he[e].v;
            int64_t dot = 0;
            uint64_t adot;
            int8_t a = r->vapex[u];
            int done;
            if (a == CLS_NONE || a == CLS_REMOVE || a == CLS_REMOVE_FAILED) continue;
            if (a == CLS_COLLAPSE_FAILED && was != CLS_UNKNOWN) {
                WM_ASSERT(refused_again(r, e, u, &gv, dc)); /* refused from u's end */
                continue;
            }
            cls = classify_cached(r, u, &gw);
            if (a == CLS_UNKNOWN) {
                r->vapex[u] = cls;
                if (cls == CLS_COLLAPSE) unfail_ring(r, u);
            }
            if (cls != CLS_COLLAPSE) continue;
            for (int c = 0; c < 3; c++) dot += gv.vec[3 + c] * gw.vec[3 + c]; /* Q60, below 3 2^60 */
            adot = dot < 0 ? (uint64_t)0 - (uint64_t)dot : (uint64_t)dot;
            if (adot <= dc) continue;
            done = try_collapse(r, e);
            if (done > 0) {
                removed++;
                refused = 0;
                break;
            }
            if (done < 0) refused = 0;
        }
        /* every neighbour seen and every collapse refused by the stars */
        if (r->vapex[v] == CLS_COLLAPSE && refused && whole) {
            r->vapex[v] = CLS_COLLAPSE_FAILED;
        }
    }
    r->removals += removed;
    return removed;
}
