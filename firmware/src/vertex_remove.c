/* Vertex removal (dissertation 4.5.2) and, as a fan from one neighbour, the half-edge collapse
 * (4.5.3 with the collapse point at a grid vertex).
 *
 *        p3-----p2                 p3-----p2
 *        / \   / \                 / \_    \          the fan of v (h triangles, or h - 1 on a
 *       /   \ /   \               /    \_   \         side of the rectangle) becomes n - 2
 *      p4----v-----p1     ->     p4------\_--p1       triangles over the ring p0 .. p(n-1)
 *       \   / \   /               \        \_ /       (here an ear-clipped choice); v and the
 *        \ /   \ /                 \         p0       one or two slots left over are freed
 *        p5-----p0                 p5-------/
 *
 * Why the result is proper: the ring polygon is simple (it is the boundary of v's star), and a set
 * of strictly counter-clockwise triangles whose signed areas add up to the polygon's and that meet
 * edge to edge covers every point of it exactly once (the winding number of a point is the number of
 * triangles holding it).  Ear clipping keeps that by taking only strictly convex ears with no other
 * remaining ring vertex in the closed ear; a fan from p_i by requiring each triangle strictly
 * counter-clockwise, which also rules out a ring vertex on a diagonal.  On a side of the rectangle
 * v lies on the segment p(n-1) -> p0, which becomes a border edge. */
#include "wm_internal.h"

/* The fan of v, counter-clockwise: the half-edges leaving v into e[], their count into *k; the ring
 * vertices p_i = dest(e_i), plus the last triangle's third vertex on a side.  n or an error. */
static int32_t fan(const wm_mesh *m, int32_t v, int32_t e[WM_MAX_RING], int32_t *k, int32_t ring[WM_MAX_RING])
{
    const wm_he *he = m->he; /* held: e[] and ring[] are stored to as the fan goes round */
    int32_t first, h, d, n = 0;
    if (v < 0 || v >= m->vert_end || m->vxy[v].x == WM_FREE) return WM_ERR_ARG;
    {
        int32_t x = m->vxy[v].x, y = m->vxy[v].y;
        if ((x == 0 || x == m->width - 1) && (y == 0 || y == m->height - 1)) return WM_ERR_REFUSED;
        /* wm_fan_first: any half-edge of an interior vertex's full fan */
        first = wm_on_border(m, x, y) ? wm_fan_first(m, v) : m->vh[v];
    }
    /* Each step takes one corner of its triangle, prev(h) (the half-edge into v): its twin is the next
     * half-edge leaving v, and its origin that half-edge's end, the next ring vertex (or, on a side,
     * the last triangle's far corner, which closes the ring).  So a step loads he[].v and he[].o at one
     * index, where dest(h) = he[next(h)].v took a second corner's index; prev(h) by whether h is its
     * triangle's first corner (wm_div3_exact, wavemesh.h) as arithmetic, not branches (h % 3 is as
     * likely one number as another). */
    h = first;
    d = he[WM_NEXT(first)].v; /* wm_dest(first) */
    do {
        int32_t corner0, p;
        if (n >= WM_MAX_RING) return WM_ERR_REFUSED;
        corner0 = wm_div3_exact((uint32_t)h); /* h % 3 == 0 */
        p = h - 1 + 3 * corner0;                           /* prev(h) */
        WM_ASSERT(p == WM_PREV(h) && d == he[WM_NEXT(h)].v);
        e[n] = h;
        ring[n++] = d;
        d = he[p].v;
        h = he[p].o; /* wm_rot_ccw */
    } while (h >= 0 && h != first);
    *k = n;
    if (h < 0) { /* on a side: the last triangle's far corner closes the ring */
        if (n >= WM_MAX_RING) return WM_ERR_REFUSED;
        WM_ASSERT(d == he[WM_PREV(e[n - 1])].v);
        ring[n++] = d;
    }
    return n;
}

int wm_vertex_ring(const wm_mesh *m, int32_t v, int32_t ring[WM_MAX_RING])
{
    int32_t e[WM_MAX_RING], k;
    return (int)fan(m, v, e, &k, ring);
}

int32_t wm_vertex_fan(const wm_mesh *m, int32_t v, int32_t e[WM_MAX_RING], int32_t *k, int32_t ring[WM_MAX_RING])
{
    return fan(m, v, e, k, ring);
}

/* wm_incircle(a, b, c, d) > 0 for one triangle and many d (an ear against the polygon's other
 * vertices): relative to a, with b' = b - a, c' = c - a, d' = d - a, the in-circle determinant is
 *
 *     -(k0 |d'|^2 + k1 d'x + k2 d'y),   k0 = b' x c',  k1 = b'y |c'|^2 - |b'|^2 c'y,  k2 = |b'|^2 c'x - b'x |c'|^2
 *
 * exactly (the same integer with the sign turned), so the three products per point replace the
 * predicate's eleven.  Differences are below 2^15 (WM_MAX_SIDE): |d'|^2 and |k0| < 2^31, |k1|, |k2| <
 * 2^47, each term below 2^62 and the sum of two below 2^63; the third is compared, as wm_incircle does. */
/* The differences, |b'|^2, |c'|^2, |d'|^2 and k0 fit 32 bits: on a 32-bit CPU (and in the checked builds)
 * they are held in 32-bit integers, so that each product is one 32 x 32 bit multiply (on rv32 a mul and
 * a mulh); natively in 64 bits, which the x86-64 code takes without sign extensions.  The same integers. */
#if WM_NARROW_DIV
typedef int32_t circ_int;
#else
typedef int64_t circ_int;
#endif

struct circle {
    int64_t k1, k2;
    circ_int k0, ax, ay;
};

static void circle_of(struct circle *q, int32_t ax, int32_t ay, int32_t bx, int32_t by, int32_t cx, int32_t cy)
{
    circ_int ux = (circ_int)bx - ax, uy = (circ_int)by - ay, vx = (circ_int)cx - ax, vy = (circ_int)cy - ay;
    circ_int u2 = ux * ux + uy * uy, v2 = vx * vx + vy * vy;
    q->k0 = ux * vy - uy * vx;
    q->k1 = (int64_t)uy * v2 - (int64_t)u2 * vy;
    q->k2 = (int64_t)u2 * vx - (int64_t)ux * v2;
    q->ax = ax;
    q->ay = ay;
}

static int in_circle(const struct circle *q, int32_t dx, int32_t dy)
{
    circ_int ex = (circ_int)dx - q->ax, ey = (circ_int)dy - q->ay;
    int64_t s = (int64_t)q->k0 * (ex * ex + ey * ey) + q->k1 * ex;
    return s < -(q->k2 * ey);
}

/* The same test in 32-bit integers for a polygon within a 128 x 128 box (every difference |d| <= 127, the
 * ring of most vertices the decimation plans for): |b'|^2, |c'|^2, |d'|^2 and |k0| <= 2 * 127^2 < 2^15,
 * |k1|, |k2| <= 2 * 127 * 2 * 127^2 < 2^23, so each term is at most 2 * 127^2 * 2 * 127^2 < 2^30 and
 * the sum of two below 2^31: the same integers, one 32-bit multiply each where the 64-bit products on
 * a 32-bit CPU took a multiply pair or three multiplies and their carries.  On the soft CPU (and in the
 * checked builds, which assert the answer equals in_circle's); natively in_circle's 64-bit integers. */
struct circle32 {
    int32_t k0, k1, k2, ax, ay;
};

static void circle_of32(struct circle32 *q, int32_t ax, int32_t ay, int32_t bx, int32_t by, int32_t cx, int32_t cy)
{
    int32_t ux = bx - ax, uy = by - ay, vx = cx - ax, vy = cy - ay, u2 = ux * ux + uy * uy, v2 = vx * vx + vy * vy;
    q->k0 = ux * vy - uy * vx;
    q->k1 = uy * v2 - u2 * vy;
    q->k2 = u2 * vx - ux * v2;
    q->ax = ax;
    q->ay = ay;
}

static int in_circle32(const struct circle32 *q, int32_t dx, int32_t dy)
{
    int32_t ex = dx - q->ax, ey = dy - q->ay;
    return q->k0 * (ex * ex + ey * ey) + q->k1 * ex < -(q->k2 * ey);
}

/* 1 when (px, py) lies in the closed counter-clockwise triangle. */
static WM_ALWAYS_INLINE int holds(int32_t ax, int32_t ay, int32_t bx, int32_t by, int32_t cx, int32_t cy,
                                  int32_t px, int32_t py)
{
    return wm_orient(ax, ay, bx, by, px, py) >= 0 && wm_orient(bx, by, cx, cy, px, py) >= 0 &&
           wm_orient(cx, cy, ax, ay, px, py) >= 0;
}

/* The ear clipping's polygon (wm_ring_plan_probe): its positions' coordinates (px, py), the list (nx,
 * pv), each ear's blocking vertex (blk), twice its area and its state (ok).  On a 32-bit CPU (and in the
 * checked builds) a record of 32 bytes a position, reached through a pointer that GCC is not shown to be
 * the stack's: one shift and one add give an element's fields, where GCC formed each of seven arrays'
 * element from the stack pointer in four instructions (sll, add, add, and the load's offset; the frame
 * is over 1 KB); natively seven arrays, which x86-64 indexes in the load itself. */
#if WM_NARROW_DIV
struct ring_pt {
    int32_t x, y, nx, pv, blk, area, ok, pad;
};
#define PX(i) P[i].x
#define PY(i) P[i].y
#define NX(i) P[i].nx
#define PV(i) P[i].pv
#define BLK(i) P[i].blk
#define AREA(i) P[i].area
#define OK(i) P[i].ok
typedef struct ring_pt *polygon;
#else
struct ring_arrays {
    int32_t x[WM_MAX_RING], y[WM_MAX_RING], nx[WM_MAX_RING], pv[WM_MAX_RING], blk[WM_MAX_RING], area[WM_MAX_RING];
    int8_t ok[WM_MAX_RING];
};
#define PX(i) P->x[i]
#define PY(i) P->y[i]
#define NX(i) P->nx[i]
#define PV(i) P->pv[i]
#define BLK(i) P->blk[i]
#define AREA(i) P->area[i]
#define OK(i) P->ok[i]
typedef struct ring_arrays *polygon;
#endif

/* 1 when no polygon vertex other than the ear's (ia, ib, ic) lies in the closed ear (the ear is strictly
 * counter-clockwise): the ear is valid. */
static int ear_holds_none(const polygon P, int32_t ia, int32_t ib, int32_t ic)
{
    int32_t ax = PX(ia), ay = PY(ia), bx = PX(ib), by = PY(ib), cx = PX(ic), cy = PY(ic), x0, x1, y0, y1, j;
    x0 = ax < bx ? ax : bx;
    if (cx < x0) x0 = cx;
    x1 = ax > bx ? ax : bx;
    if (cx > x1) x1 = cx;
    y0 = ay < by ? ay : by;
    if (cy < y0) y0 = cy;
    y1 = ay > by ? ay : by;
    if (cy > y1) y1 = cy;
    for (j = NX(ic); j != ia; j = NX(j)) {
        if (PX(j) < x0 || PX(j) > x1 || PY(j) < y0 || PY(j) > y1) continue; /* outside */
        if (holds(ax, ay, bx, by, cx, cy, PX(j), PY(j))) return 0;
    }
    return 1;
}

/* The probe's answer for the triangle (a, b, c), the first that holds its point. */
static int ask(const struct wm_plan_probe *pr, int32_t ax, int32_t ay, int32_t bx, int32_t by, int32_t cx,
               int32_t cy)
{
    int32_t x[3], y[3];
    x[0] = ax, x[1] = bx, x[2] = cx, y[0] = ay, y[1] = by, y[2] = cy;
    return pr->above(pr->ctx, x, y, pr->px, pr->py);
}

/* The first of the ear clipping's triangles (in the order they are cut) that holds the probe's point
 * is handed to the probe; an answer of 1 refuses the plan at once (the rest is not worked out). */
static int probed(const struct wm_plan_probe *pr, int *done, int32_t ax, int32_t ay, int32_t bx, int32_t by,
                  int32_t cx, int32_t cy)
{
    if (pr == NULL || *done || !holds(ax, ay, bx, by, cx, cy, pr->px, pr->py)) return 0;
    *done = 1;
    return ask(pr, ax, ay, bx, by, cx, cy);
}

int wm_ring_plan(const wm_mesh *m, const int32_t *ring, int32_t n, int32_t apex, int32_t tris[3 * WM_MAX_RING],
                 int32_t *n_tris)
{
    return wm_ring_plan_probe(m, ring, n, apex, tris, n_tris, NULL, NULL);
}

int wm_ring_plan_probe(const wm_mesh *m, const int32_t *ring, int32_t n, int32_t apex,
                       int32_t tris[3 * WM_MAX_RING], int32_t *n_tris, const struct wm_plan_probe *pr,
                       int32_t *big)
{
    int32_t nt = 0, at = 0;
    /* twice a triangle's area in 32 bits, as wm_orient works it out (below 2^31: coordinates below
     * WM_MAX_SIDE): the largest so far (most), each ear's (area[]) and the probe's side (o) compared and
     * stored as one word on the soft CPU, not a pair */
    int32_t most = -1, d;
    int done = 0;
    if (n < 3 || n > WM_MAX_RING || apex >= n) return WM_ERR_ARG;
    if (apex >= 0) {
        /* the fan (a, p_i, p_i+1) for i = apex + 1 .. apex + n - 2 (mod n), positions wrapped by a
         * compare: the decimation tries every fan of every vertex it looks at */
        int32_t a = ring[apex], ax = m->vxy[a].x, ay = m->vxy[a].y, i = apex + 1 == n ? 0 : apex + 1;
        int32_t b = ring[i], bx = m->vxy[b].x, by = m->vxy[b].y;
        for (int32_t j = 1; j + 1 < n; j++) {
            int32_t c, cx, cy;
            i = i + 1 == n ? 0 : i + 1;
            c = ring[i], cx = m->vxy[c].x, cy = m->vxy[c].y;
            d = (int32_t)wm_orient(ax, ay, bx, by, cx, cy);
            if (d <= 0) return WM_ERR_REFUSED;
            if (d > most) most = d, at = nt;
            tris[3 * nt] = a, tris[3 * nt + 1] = b, tris[3 * nt + 2] = c;
            nt++;
            b = c, bx = cx, by = cy;
        }
        *n_tris = nt;
        if (big) *big = at;
        return WM_OK;
    }
    /* The polygon as a list over the ring positions (nx, pv; cut ones -1 in ok[]), walked in position
     * order, which is polygon order from the lowest position left.  A strictly convex ear with no other
     * polygon vertex strictly inside its circumcircle is valid too (every point of the closed triangle
     * but its corners lies strictly inside that circle), so the in-circle test comes first, and the
     * containment test (ear_holds_none) is taken only in a round that finds no Delaunay ear, for the
     * ears that fail it in polygon order until a valid one (most rounds find one: the Jacksboro job's
     * decimation 0.4 % fewer instructions than taking it during the round).  An ear's status only improves as other vertices go (fewer points to
     * contain or to lie in its circle), so an ear once found valid stays valid and a Delaunay ear stays
     * Delaunay until a neighbour of it is cut: ok[] keeps that (0 unknown, 3 strictly convex, 1 valid,
     * 2 Delaunay, -1 cut) and only unknown ears are tested again; an ear that is not Delaunay keeps the vertex
     * in its circle (blk) and is tested again only when that vertex has been cut (the decimation plans
     * a hole for every vertex it looks at: this was half the cost).  The choice is the same as testing
     * every ear each round: the first Delaunay ear in polygon order, else the first valid one. */
    {
#if WM_NARROW_DIV
        struct ring_pt at_[WM_MAX_RING];
        polygon P = at_; /* a cut position's ok -1: no array of positions alive to set up */
#else
        struct ring_arrays at_;
        polygon P = &at_;
#endif
        int32_t cut[3 * WM_MAX_RING]; /* the cut ears as ring positions (tris[] once the plan is made) */
        int32_t left = n, i0 = 0, i1, i2, ox, oy, small;
        uint32_t far = 0;
        /* bit i: the polygon's edge from position i is the ring's edge i -> i + 1 (no position between
         * them cut), so that a cut ear (a, b, c) is one of bad's (wm_tri_bad: (a, b, b + 1) or (c, a, a +
         * 1); c -> a is no ring edge while a vertex is left between them) from two bits of this word and
         * one of bad[a] and of bad[c], where wm_tri_bad's wrapped positions and compares took some 20
         * instructions (on the board 7 % of the plan's cycles) */
        uint32_t edge = ~0u;
        /* bit i: the probe's point is not on the outer side of the polygon's edge from position i to nx[i],
         * while no cut triangle has held it: so an ear holds it iff the side of its diagonal c-a (one
         * orientation) and its two edges' bits say so, and the cut sets the new edge's bit from that
         * orientation.  All set at first: the point is the vertex whose ring this is (wm_plan_probe). */
        uint32_t side = ~0u;
        /* in_circle32's range (the polygon within a 128 x 128 box): first whether every vertex is
         * within [-63, 64] of p0 in x and in y, as an OR of the offsets p - p0 + 63 (each in [0, 127]
         * then, any other as an unsigned word at least 128: the OR below 128 says all are), and only
         * when not the box's bounds (the same answer: such a polygon is within the box; on the soft
         * CPU four branches a vertex were most of this loop) */
#if WM_NARROW_DIV
        __asm__("" : "+r"(P)); /* P a register, not the stack pointer and an offset (polygon) */
#endif
        ox = m->vxy[ring[0]].x - 63, oy = m->vxy[ring[0]].y - 63;
        for (int32_t i = 0; i < n; i++) {
            PX(i) = m->vxy[ring[i]].x;
            PY(i) = m->vxy[ring[i]].y;
            far |= (uint32_t)(PX(i) - ox) | (uint32_t)(PY(i) - oy);
            NX(i) = i + 1;
            PV(i) = i - 1;
            OK(i) = 0;
        }
        NX(n - 1) = 0, PV(0) = n - 1;
        small = far < 128;
        if (!small || WM_CHECK) {
            int32_t x0 = PX(0), x1 = PX(0), y0 = PY(0), y1 = PY(0);
            for (int32_t i = 1; i < n; i++) {
                x0 = PX(i) < x0 ? PX(i) : x0, x1 = PX(i) > x1 ? PX(i) : x1;
                y0 = PY(i) < y0 ? PY(i) : y0, y1 = PY(i) > y1 ? PY(i) : y1;
            }
            WM_ASSERT(!small || (x1 - x0 < 128 && y1 - y0 < 128));
            small = x1 - x0 < 128 && y1 - y0 < 128;
        }
#if WM_CHECK
        for (int32_t i = 0; pr && i < n; i++)
            WM_ASSERT(wm_orient(PX(i), PY(i), PX(NX(i)), PY(NX(i)), pr->px, pr->py) >= 0);
#endif
        while (left > 3) {
            int32_t best = -1, first = -1; /* first: the round's first strictly convex ear */
            /* the polygon's vertices in position order: from the lowest left (i0), round the list */
            for (int32_t i = i0, c = 0; c < left; i = NX(i), c++) {
                int32_t ia = PV(i), ic = NX(i), j;
                int32_t ax, ay, bx, by, cx, cy;
                WM_ASSERT(OK(i) >= 0 && (c == 0 || i > PV(i)));
                ax = PX(ia), ay = PY(ia), bx = PX(i), by = PY(i), cx = PX(ic), cy = PY(ic);
                if (OK(i) == 0) {
                    AREA(i) = (int32_t)wm_orient(ax, ay, bx, by, cx, cy);
                    if (AREA(i) <= 0) continue;
                    OK(i) = 3;
                    BLK(i) = -1;
                }
                /* the other polygon vertices, after ic up to ia (either test's answer does not depend on
                 * the order) */
                if (OK(i) != 2 && (BLK(i) < 0 || OK(BLK(i)) < 0)) {
                    if (WM_NARROW_DIV && small) {
                        struct circle32 q;
                        circle_of32(&q, ax, ay, bx, by, cx, cy);
                        for (j = NX(ic); j != ia; j = NX(j))
                            if (in_circle32(&q, PX(j), PY(j))) break;
#if WM_CHECK
                        {
                            struct circle q2;
                            int32_t j2;
                            circle_of(&q2, ax, ay, bx, by, cx, cy);
                            for (j2 = NX(ic); j2 != ia; j2 = NX(j2))
                                if (in_circle(&q2, PX(j2), PY(j2))) break;
                            WM_ASSERT(j2 == j);
                        }
#endif
                    } else {
                        struct circle q;
                        circle_of(&q, ax, ay, bx, by, cx, cy);
                        for (j = NX(ic); j != ia; j = NX(j))
                            if (in_circle(&q, PX(j), PY(j))) break;
                    }
                    if (j == ia) OK(i) = 2;
                    else BLK(i) = j;
                }
                if (OK(i) == 2) {
                    WM_ASSERT(ear_holds_none(P, ia, i, ic));
                    best = i;
                    break;
                }
                if (first < 0) first = i;
            }
            /* No Delaunay ear: the first valid one, from the first strictly convex ear on to the round's end
             * (the containment test only here, where it decides: most rounds find a Delaunay ear) */
            for (int32_t i = first; best < 0 && i >= 0; i = NX(i) == i0 ? -1 : NX(i)) {
                if (OK(i) == 3 && ear_holds_none(P, PV(i), i, NX(i))) OK(i) = 1;
                if (OK(i) == 1) best = i;
            }
#if WM_CHECK
            if (best >= 0 && OK(best) != 2) { /* the round's first valid ear in polygon order, as taken before */
                int32_t i = i0, c = 0;
                while (c++ < left && !(OK(i) != 0 && ear_holds_none(P, PV(i), i, NX(i)))) i = NX(i);
                WM_ASSERT(i == best);
            }
#endif
            /* A simple polygon always has an ear (two, in fact). */
            WM_ASSERT(best >= 0);
            if (best < 0) return WM_ERR_REFUSED;
            cut[3 * nt] = PV(best), cut[3 * nt + 1] = best, cut[3 * nt + 2] = NX(best);
            if (AREA(best) > most) most = AREA(best), at = nt;
            nt++;
            if (pr && pr->bad) {
                const uint32_t *bad = pr->bad;
                int32_t ia = PV(best), ic = NX(best);
                uint32_t bd = ((edge & bad[ia]) >> best | (edge & bad[ic]) >> ia) & 1u;
                WM_ASSERT((int)bd == wm_tri_bad(bad, n, ia, best, ic) && (ic + 1 == n ? 0 : ic + 1) != ia);
                if (bd) return WM_ERR_REFUSED;
            }
            if (pr && !done) {
                int32_t ia = PV(best), ic = NX(best);
                int32_t o = (int32_t)wm_orient(PX(ic), PY(ic), PX(ia), PY(ia), pr->px, pr->py);
                int in = (side >> ia & 1) && (side >> best & 1) && o >= 0;
                WM_ASSERT(in == holds(PX(ia), PY(ia), PX(best), PY(best), PX(ic), PY(ic), pr->px, pr->py));
                if (in) {
                    done = 1;
                    if (ask(pr, PX(ia), PY(ia), PX(best), PY(best), PX(ic), PY(ic))) return WM_ERR_REFUSED;
                } else if (o > 0) {
                    side &= ~(1u << ia); /* the new edge a-c has the point on its outer side */
                }
            }
            OK(PV(best)) = OK(NX(best)) = 0; /* its neighbours' ears changed shape */
            edge &= ~(1u << PV(best));
            NX(PV(best)) = NX(best);
            PV(NX(best)) = PV(best);
            OK(best) = -1;
            if (best == i0) i0 = NX(best); /* the next position left, the lowest now */
            left--;
        }
        i1 = NX(i0), i2 = NX(i1);
        WM_ASSERT(OK(i0) >= 0 && i1 > i0 && i2 > i1);
        if (pr && pr->bad && wm_tri_bad(pr->bad, n, i0, i1, i2)) return WM_ERR_REFUSED;
        /* the last triangle, from the polygon's coordinates; then the plan as ring vertices */
        d = (int32_t)wm_orient(PX(i0), PY(i0), PX(i1), PY(i1), PX(i2), PY(i2));
        if (d <= 0) return WM_ERR_REFUSED;
        if (d > most) at = nt;
        if (probed(pr, &done, PX(i0), PY(i0), PX(i1), PY(i1), PX(i2), PY(i2))) return WM_ERR_REFUSED;
        cut[3 * nt] = i0, cut[3 * nt + 1] = i1, cut[3 * nt + 2] = i2;
        for (int32_t k = 0; k < 3 * nt + 3; k++) tris[k] = ring[cut[k]];
    }
    *n_tris = nt + 1;
    if (big) *big = at;
    return WM_OK;
}

#undef PX
#undef PY
#undef NX
#undef PV
#undef BLK
#undef AREA
#undef OK

int wm_vertex_remove_plan(const wm_mesh *m, int32_t v, int32_t apex, int32_t tris[3 * WM_MAX_RING],
                          int32_t *n_tris)
{
    int32_t e[WM_MAX_RING], ring[WM_MAX_RING], k, n;
    n = fan(m, v, e, &k, ring);
    if (n < 0) return (int)n;
    return wm_ring_plan(m, ring, n, apex, tris, n_tris);
}

int wm_vertex_remove(wm_mesh *m, int32_t v, const int32_t *tris, int32_t n_tris, int32_t touched[WM_MAX_RING],
                     int32_t *n_touched)
{
    int32_t e[WM_MAX_RING], ring[WM_MAX_RING], k, n;
    n = fan(m, v, e, &k, ring);
    if (n < 0) return (int)n;
    return wm_vertex_remove_fan(m, v, e, k, ring, n, -1, tris, n_tris, touched, n_touched);
}

int wm_vertex_remove_fan(wm_mesh *m, int32_t v, const int32_t *e, int32_t k, const int32_t *ring, int32_t n,
                         int32_t apex, const int32_t *tris, int32_t n_tris, int32_t touched[WM_MAX_RING],
                         int32_t *n_touched)
{
    int32_t slot[WM_MAX_RING], out[WM_MAX_RING];
#if WM_CHECK
    {
        int32_t e2[WM_MAX_RING], ring2[WM_MAX_RING], k2;
        WM_ASSERT(fan(m, v, e2, &k2, ring2) == n && k2 == k);
        for (int32_t i = 0; i < n; i++) WM_ASSERT(ring2[i] == ring[i] && (i >= k || e2[i] == e[i]));
    }
#endif
    if (n_tris != n - 2) return WM_ERR_ARG;
    /* Remember the outside: out[i] is the half-edge across ring edge p_i -> p_i+1 of fan triangle i. */
    for (int32_t i = 0; i < k; i++) {
        slot[i] = WM_TRI(e[i]);
        out[i] = m->he[WM_NEXT(e[i])].o;
    }
    /* Free what is not reused: fan slots n_tris .. k-1 and v. */
    for (int32_t i = n_tris; i < k; i++) {
        int32_t t = slot[i];
        m->he[3 * t].v = m->he[3 * t + 1].v = m->he[3 * t + 2].v = -1;
        m->he[3 * t].o = m->tri_free;
        m->tri_free = t;
        m->n_tri--;
    }
    m->vxy[v].x = WM_FREE;
    m->vxy[v].y = WM_FREE;
    m->vh[v] = m->vert_free;
    m->vert_free = v;
    m->n_vert--;
    if (apex >= 0) {
        /* The fan from ring position apex (a): triangle j is (p_a, p_b, p_b+1) with b = a + 1 + j, its
         * corners' ring positions known, so no search: its edge a -> b is the ring's edge from a (j = 0)
         * or the twin of the triangle before's edge b -> a, its edge b -> b+1 the ring's edge from b, and
         * its edge b+1 -> a the ring's edge into a for the last (else the next's twin, linked there).  The
         * same triangles in the same slots and the same links as the search below (most removals of the
         * decimation are fans: the search walked a step a corner past the apex, then the pending list). */
        int32_t pa = ring[apex], b = apex + 1 == n ? 0 : apex + 1, prev = -1;
        for (int32_t j = 0; j < n_tris; j++) {
            int32_t c = b + 1 == n ? 0 : b + 1, h = 3 * slot[j];
            WM_ASSERT(tris == NULL ||
                      (tris[3 * j] == pa && tris[3 * j + 1] == ring[b] && tris[3 * j + 2] == ring[c]));
            wm_tri_set(m, slot[j], pa, ring[b], ring[c]);
            wm_link(m, h, j == 0 ? (apex < k ? out[apex] : -1) : prev);
            wm_link(m, h + 1, b < k ? out[b] : -1);
            if (j == n_tris - 1) wm_link(m, h + 2, c < k ? out[c] : -1);
            /* what wm_tri_claim of each triangle in turn leaves in vh[] (the last half-edge claimed
             * from each vertex), from the corners at hand, where the claims loaded the he[] just stored
             * (on the board a store does not allocate: a refill): p_b's is triangle j's (triangle j - 1
             * claimed it before), the apex's and the last corner's the last triangle's (below) */
            m->vh[ring[b]] = h + 1;
            if (touched) touched[j] = slot[j];
            prev = h + 2;
            b = c;
        }
        m->vh[pa] = prev - 2, m->vh[ring[b]] = prev;
#if WM_CHECK
        for (int32_t j = 0; j < n_tris; j++)
            for (int32_t c = 0; c < 3; c++) { /* the claims in turn leave these */
                int32_t u = m->he[3 * slot[j] + c].v, last = -1;
                for (int32_t j2 = 0; j2 < n_tris; j2++)
                    for (int32_t c2 = 0; c2 < 3; c2++)
                        if (m->he[3 * slot[j2] + c2].v == u) last = 3 * slot[j2] + c2;
                WM_ASSERT(m->vh[u] == last);
            }
#endif
        if (n_touched) *n_touched = n_tris;
        WM_CHECK_MESH(m);
        return WM_OK;
    }
    for (int32_t j = 0; j < n_tris; j++) wm_tri_set(m, slot[j], tris[3 * j], tris[3 * j + 1], tris[3 * j + 2]);
    /* Link every new half-edge a -> b by the ring positions of its ends: across ring edge p_i -> p_i+1
     * to the outside, on the new border edge p(n-1) -> p0 (a side of the rectangle) to -1, else to
     * its twin b -> a inside the hole, met before (pending) or later: each diagonal is cut once, so
     * both its directions are among the new triangles. */
    {
        int32_t pend_a[WM_MAX_RING], pend_b[WM_MAX_RING], pend_h[WM_MAX_RING], np = 0, from = 0;
        for (int32_t j = 0; j < n_tris; j++) {
            int32_t at[3]; /* the ring positions of the triangle's corners (he[3 slot + c].v = tris[3 j + c]) */
            /* The corners of a counter-clockwise triangle over the ring polygon come in ring order, so
             * each is looked for from the one before it on, round the ring, the first from the last
             * triangle's first (found at once in a fan's (a, p_i, p_i+1)); the ring's vertices are
             * distinct, so where a search starts does not change what it finds. */
            for (int32_t c = 0, i = from; c < 3; c++) {
                int32_t left = n;
                while (left > 0 && ring[i] != tris[3 * j + c]) {
                    i = i + 1 == n ? 0 : i + 1;
                    left--;
                }
                at[c] = left > 0 ? i : -1;
                i = i + 1 == n ? 0 : i + 1;
            }
            if (at[0] >= 0) from = at[0];
            for (int32_t c = 0; c < 3; c++) {
                int32_t h = 3 * slot[j] + c, pa = at[c], pb = at[wm_k1(c)], f = -1, q;
                WM_ASSERT(pa >= 0 && pb >= 0);
                if (pa < 0 || pb < 0) { /* cannot happen for a plan of this mesh */
                    wm_link(m, h, -1);
                    continue;
                }
                if (pb == (pa + 1 == n ? 0 : pa + 1)) {
                    if (pa < k) f = out[pa]; /* else the new border edge */
                    wm_link(m, h, f);
                    continue;
                }
                for (q = 0; q < np; q++)
                    if (pend_a[q] == pb && pend_b[q] == pa) break;
                if (q < np) { /* its twin came first */
                    wm_link(m, h, pend_h[q]);
                    np--;
                    pend_a[q] = pend_a[np], pend_b[q] = pend_b[np], pend_h[q] = pend_h[np];
                } else if (np < WM_MAX_RING) {
                    pend_a[np] = pa, pend_b[np] = pb, pend_h[np++] = h;
                }
            }
        }
        WM_ASSERT(np == 0);
    }
    for (int32_t j = 0; j < n_tris; j++) {
        wm_tri_claim(m, slot[j]);
        if (touched) touched[j] = slot[j];
    }
    if (n_touched) *n_touched = n_tris;
    WM_CHECK_MESH(m);
    return WM_OK;
}
