/* Shape-preserving edge split (dissertation 4.4): gradient-consistent pairing (eq. 4.16) with
 * quasi-valid pairs on the border, the split point (eq. 4.17-4.20) snapped to a grid sample, vertex
 * movement (eq. 4.21) and the ternary subdivision of unpaired triangles.
 *
 *          c                      The gradient g of a triangle is (d1, d2) of its barycentre's
 *         /|\   g1 -->            coefficient (eq. 4.15: d ~ -2^m grad f; the sign does not
 *        / | \                    matter).  T1 and T2 pair across c = b - a when
 *       a  |  b   l1: through         |g_i . c| > delta_p |g_i| |c|,  i = 1, 2        (4.16)
 *        \ | /    T1's barycentre  and a-d-b-c is convex.  Each triangle's line through its
 *         \|/     along g1-perp    barycentre along g-perp (4.19) meets the common edge at t_i
 *          d      meets a-b at t1  (4.20); the split point is at t = (t1 + t2) / 2, snapped. */
#include "wm_internal.h"

/* (d1, d2) of triangle t's barycentre cell at level m, scaled down (toward zero) below 2^12 so
 * that every product below fits in 64 bits; (0, 0) when there is no gradient. */
static void gradient(const wm_refiner *r, const wm_level_cells *lv, int32_t t, int64_t g[2])
{
    int32_t x[3], y[3], bx, by;
    const int32_t *d;
    wm_tri_xy(&r->mesh, t, x, y);
    bx = wm_div3(x[0] + x[1] + x[2]), by = wm_div3(y[0] + y[1] + y[2]);
    d = lv->d + 3 * ((int64_t)(by >> lv->m) * lv->cw + (bx >> lv->m));
    WM_ASSERT(d == wm_detail_at(&r->field, lv->m, bx, by));
    g[0] = d[0];
    g[1] = d[1];
    while (g[0] >= 4096 || g[0] <= -4096 || g[1] >= 4096 || g[1] <= -4096) {
        g[0] /= 2; /* C99: truncation toward zero, the same everywhere */
        g[1] /= 2;
    }
}

/* Criterion (4.16) for one triangle: |g . c| > delta_p |g| |c|, exactly:
 * (g . c)^2 2^32 > delta_p^2 |g|^2 |c|^2 with delta_p in Q0.16.  |g|'s parts are below 2^12 and c's
 * below 2^15, so A = (g . c)^2 < 2^57 and B = |g|^2 |c|^2 < 2^56; with Q = delta_p^2 < 2^32 (delta_p <=
 * 65535), Q B = H 2^32 + L with L < 2^32 and H = Q (B >> 32) + (Q (B mod 2^32) >> 32) < 2^57, so the test
 * is A > H: two 32 x 32-bit products, not two 64 x 64 -> 128-bit ones. */
static int consistent(const wm_refiner *r, const int64_t g[2], int64_t cx, int64_t cy)
{
    int64_t dot = g[0] * cx + g[1] * cy;
    uint64_t gg = (uint64_t)(g[0] * g[0] + g[1] * g[1]), cc = (uint64_t)(cx * cx + cy * cy), a, b, h;
    uint32_t q = r->params.delta_p * r->params.delta_p;
    if (gg == 0 || cc == 0) return 0;
    a = (uint64_t)(dot * dot);
    b = gg * cc;
    h = (uint64_t)q * (uint32_t)(b >> 32) + (((uint64_t)q * (uint32_t)b) >> 32);
    WM_ASSERT((a > h) == (wm_cmp_mul(a, (uint64_t)1 << 32, q, b) > 0));
    return a > h;
}

static void edge_vec(const wm_mesh *me, int32_t e, int64_t *cx, int64_t *cy)
{
    int32_t a = me->he[e].v, b = wm_dest(me, e);
    *cx = (int64_t)me->vxy[b].x - me->vxy[a].x;
    *cy = (int64_t)me->vxy[b].y - me->vxy[a].y;
}

/* Quadrilateral a-d-b-c of the two triangles at e convex (strictly or not, fig. 4.10). */
static int convex(const wm_mesh *me, int32_t e)
{
    int32_t f = me->he[e].o, a = me->he[e].v, b = me->he[f].v, c = me->he[WM_PREV(e)].v, d = me->he[WM_PREV(f)].v;
    int64_t s1 = wm_orient(me->vxy[c].x, me->vxy[c].y, me->vxy[d].x, me->vxy[d].y, me->vxy[a].x, me->vxy[a].y);
    int64_t s2 = wm_orient(me->vxy[c].x, me->vxy[c].y, me->vxy[d].x, me->vxy[d].y, me->vxy[b].x, me->vxy[b].y);
    return !((s1 > 0 && s2 > 0) || (s1 < 0 && s2 < 0));
}

/* The best edge of active triangle t for a pair with a partner having flag `want` (0: the border,
 * a quasi-valid pair with an imaginary triangle of t's gradient): the longest consistent edge,
 * the first slot on ties.  -1 when none.  An edge's tests are pure, so their order does not change the
 * answer: the partner's flags first (a border edge, or an unplanned neighbour with `want`), then the
 * length, and t's gradient only once an edge has come that far (passes 2 and 3 and most triangles of
 * pass 1 have no such edge, and took the gradient and three criteria each). */
static int32_t best_edge(const wm_refiner *r, const wm_level_cells *lv, int32_t t, uint8_t want)
{
    const wm_mesh *me = &r->mesh;
    int64_t g[2], best_len = -1;
    int32_t best = -1, have_g = 0;
    for (int32_t e = 3 * t; e < 3 * t + 3; e++) {
        int32_t o = me->he[e].o, u = 0;
        int64_t cx, cy, len;
        if (want == 0) {
            if (o >= 0) continue;
        } else {
            if (o < 0) continue;
            u = WM_TRI(o);
            if (!(me->tflag[u] & want) || (me->tflag[u] & WM_F_PLAN)) continue;
        }
        edge_vec(me, e, &cx, &cy);
        len = cx * cx + cy * cy;
        if (len <= best_len) continue;
        if (!have_g) {
            gradient(r, lv, t, g);
            have_g = 1;
        }
        if (!consistent(r, g, cx, cy)) continue;
        if (want != 0) {
            int64_t g2[2];
            if (!convex(me, e)) continue;
            gradient(r, lv, u, g2);
            if (!consistent(r, g2, cx, cy)) continue;
        }
        best = e;
        best_len = len;
    }
#if WM_CHECK
    { /* the same edge as every test of every edge in their first order */
        int32_t full = -1;
        int64_t full_len = -1;
        gradient(r, lv, t, g);
        for (int32_t e = 3 * t; e < 3 * t + 3; e++) {
            int32_t o = me->he[e].o;
            int64_t cx, cy, len, g2[2];
            edge_vec(me, e, &cx, &cy);
            len = cx * cx + cy * cy;
            if (len <= full_len || !consistent(r, g, cx, cy)) continue;
            if (want == 0 ? o >= 0
                          : o < 0 || !(me->tflag[WM_TRI(o)] & want) || (me->tflag[WM_TRI(o)] & WM_F_PLAN) ||
                                !convex(me, e))
                continue;
            if (want != 0) {
                gradient(r, lv, WM_TRI(o), g2);
                if (!consistent(r, g2, cx, cy)) continue;
            }
            full = e;
            full_len = len;
        }
        WM_ASSERT(full == best);
    }
#endif
    return best;
}

int32_t wm_plan(wm_refiner *r, int32_t m, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    int32_t n = 0;
    /* Pass 1: active with active; pass 2: leftovers with the dependent region (N1); pass 3:
     * quasi-valid pairs on the border; pass 4: unpaired (ternary subdivision). */
    static const uint8_t partner[3] = {WM_F_ACTIVE, WM_F_DEP, 0};
    wm_level_cells lv = wm_level_cells_of(&r->field, m);
    for (int pass = 0; pass < 3; pass++) {
        for (int32_t t = 0; t < me->tri_end; t++) {
            int32_t e;
            if ((me->tflag[t] & (WM_F_ACTIVE | WM_F_PLAN)) != WM_F_ACTIVE) continue;
            e = best_edge(r, &lv, t, partner[pass]);
            if (e < 0) continue;
            me->tflag[t] |= WM_F_PLAN;
            if (me->he[e].o >= 0) me->tflag[WM_TRI(me->he[e].o)] |= WM_F_PLAN;
            r->list[n++] = e;
            if (st) {
                if (pass < 2) st->pairs++;
                else st->quasi_pairs++;
            }
        }
    }
    for (int32_t t = 0; t < me->tri_end; t++) {
        if ((me->tflag[t] & (WM_F_ACTIVE | WM_F_PLAN)) != WM_F_ACTIVE) continue;
        me->tflag[t] |= WM_F_PLAN | WM_F_UNPAIRED;
        r->list[n++] = -(t + 1);
        if (st) st->unpaired++;
    }
    return n;
}

/* Where triangle t's line through its barycentre along g-perp (4.19) meets the line of edge e
 * (a -> b), as t in [0, 1] along the edge, Q16: t = g . (3 c_t - 3 a) / (3 g . (b - a)), clamped
 * (4.20 solved in the edge's parameter).  One half when g is parallel to the edge. */
static int64_t crossing(const wm_refiner *r, int32_t m, int32_t t, int32_t e)
{
    const wm_mesh *me = &r->mesh;
    int32_t x[3], y[3], a = me->he[e].v;
    int64_t g[2], cx, cy, num, den;
    wm_level_cells lv = wm_level_cells_of(&r->field, m);
    gradient(r, &lv, t, g);
    wm_tri_xy(me, t, x, y);
    edge_vec(me, e, &cx, &cy);
    num = g[0] * ((int64_t)x[0] + x[1] + x[2] - 3 * (int64_t)me->vxy[a].x) +
          g[1] * ((int64_t)y[0] + y[1] + y[2] - 3 * (int64_t)me->vxy[a].y);
    den = 3 * (g[0] * cx + g[1] * cy);
    if (den == 0) return 32768;
    if (den < 0) {
        num = -num;
        den = -den;
    }
    if (num <= 0) return 0;
    if (num >= den) return 65536;
    return (num * 65536) / den;
}

/* 3-D distance of grid points p and q below delta_v (4.21): dx^2 + dy^2 + (s dz)^2 < delta_v^2,
 * in Q32 (height difference s dz rounded down to Q16.16). */
static uint64_t dist2_q32(const wm_refiner *r, int32_t px, int32_t py, int32_t qx, int32_t qy)
{
    const wm_field *f = &r->field;
    int64_t dx = (int64_t)px - qx, dy = (int64_t)py - qy;
    int64_t dz = (int64_t)f->samples[(int64_t)py * f->width + px] - f->samples[(int64_t)qy * f->width + qx];
    uint64_t hz = wm_scale_mul(&r->params, (uint64_t)(dz < 0 ? -dz : dz), 1, 16, 0xFFFFFFFFu);
    uint64_t planar = (uint64_t)(dx * dx + dy * dy) << 32, vert = hz * hz;
    return planar > UINT64_MAX - vert ? UINT64_MAX : planar + vert;
}

static void touch_fan(wm_refiner *r, int32_t v)
{
    wm_mesh *me = &r->mesh;
    int32_t first = wm_fan_first(me, v), e = first;
    do {
        wm_touch(r, WM_TRI(e));
        e = wm_rot_ccw(me, e);
    } while (e >= 0 && e != first);
}

static int split_edge_at(wm_refiner *r, int32_t e, int32_t x, int32_t y, wm_level_stats *st)
{
    int32_t touched[4], nt = 0;
    int room = wm_room(r, r->mesh.he[e].o >= 0 ? 2 : 1), rc;
    if (room != 0) return room < 0 ? room : WM_OK;
    rc = wm_edge_split(&r->mesh, e, x, y, touched, &nt);
    if (rc != WM_OK) return rc == WM_ERR_CAPACITY ? rc : WM_OK;
    for (int32_t i = 0; i < nt; i++) wm_touch(r, touched[i]);
    if (st) st->edge_splits++;
    return WM_OK;
}

int wm_split_unpaired(wm_refiner *r, int32_t t, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    int32_t x[3], y[3], bx = -1, by = -1, ymin, ymax, best_e = -1, A[3], B[3], C[3], sx, sy, px0;
    int64_t best = -1, best_len = -1;
    wm_tri_xy(me, t, x, y);
    sx = x[0] + x[1] + x[2];
    sy = y[0] + y[1] + y[2];
    ymin = ymax = y[0];
    /* In 32 bits (grid sides at most WM_MAX_SIDE: coordinates below 2^15 - 1): |A|, |B| < 2^15, |C| and
     * every row's B py + C = E_k(0, py) = B (py - y_k1) - A x_k1 below 2^31 - 2^17, so the divisions below
     * are 32-bit ones (on the soft CPU the hardware's, where the 64-bit ones were library calls) */
    for (int k = 0; k < 3; k++) {
        int k1 = wm_k1(k), k2 = wm_k2(k);
        A[k] = -(y[k2] - y[k1]);
        B[k] = x[k2] - x[k1];
        C[k] = -(B[k] * y[k1]) - A[k] * x[k1];
        if (y[k] < ymin) ymin = y[k];
        if (y[k] > ymax) ymax = y[k];
    }
    px0 = wm_floor_div32(sx, 3);
    if (sx - 3 * px0 > 1) px0++; /* nearest to sx / 3, the smaller on a tie (never: thirds) */
    /* The interior grid point nearest the barycentre: |3p - (v0 + v1 + v2)|^2 smallest, the first
     * row and then the smaller x on ties.  Per row the interior run is E_k >= 1 for all k.  The rows
     * are taken outward from the barycentre's, each way until the row's own term (3 py - sy)^2 alone
     * exceeds the best so far: no row beyond can do better, so the point is the one a scan of every
     * row finds (a tie goes to the smaller row). */
    for (int dir = 0; dir < 2; dir++) {
        int32_t pc = wm_floor_div32(sy, 3), py = dir == 0 ? pc : pc + 1, step = dir == 0 ? -1 : 1;
        if (py > ymax) py = ymax + (dir == 0 ? 0 : 1);
        if (py < ymin) py = ymin - (dir == 0 ? 1 : 0);
        for (; py >= ymin && py <= ymax; py += step) {
            int32_t lo = INT32_MIN, hi = INT32_MAX, px; /* a triangle has an A_k > 0 and an A_k < 0 */
            int64_t d, ry = 3 * (int64_t)py - sy;
            int empty = 0;
            if (best >= 0 && ry * ry > best) break;
            for (int k = 0; k < 3; k++) {
                int32_t num = B[k] * py + C[k] - 1; /* A x + num >= 0 */
                if (A[k] > 0) {
                    int32_t l = wm_ceil_div32(-num, A[k]);
                    if (l > lo) lo = l;
                } else if (A[k] < 0) {
                    int32_t h = wm_floor_div32(num, -A[k]);
                    if (h < hi) hi = h;
                } else if (num < 0) {
                    empty = 1;
                }
            }
            if (empty || lo > hi) continue;
            px = px0;
            if (px < lo) px = lo;
            if (px > hi) px = hi;
            d = (int64_t)(3 * px - sx) * (3 * px - sx) + ry * ry;
            if (best < 0 || d < best || (d == best && py < by)) {
                best = d;
                bx = px;
                by = py;
            }
        }
    }
    if (best >= 0) {
        int32_t touched[3], nt = 0;
        int room = wm_room(r, 2), rc;
        if (room != 0) return room < 0 ? room : WM_OK;
        rc = wm_tri_split(me, t, bx, by, touched, &nt);
        if (rc == WM_ERR_CAPACITY) return rc;
        if (rc != WM_OK) return WM_OK;
        for (int32_t i = 0; i < nt; i++) wm_touch(r, touched[i]);
        if (st) st->ternary_splits++;
        return WM_OK;
    }
    /* No interior grid point: split the longest edge that has one (by Pick's theorem there is one
     * when twice the area exceeds 1), at the grid point nearest its middle, unless the triangle on
     * the other side belongs to another planned operation. */
    for (int32_t e = 3 * t; e < 3 * t + 3; e++) {
        int32_t o = me->he[e].o;
        int64_t cx, cy, len;
        edge_vec(me, e, &cx, &cy);
        len = cx * cx + cy * cy;
        if (len <= best_len || wm_gcd((int32_t)cx, (int32_t)cy) < 2) continue;
        if (o >= 0 && (me->tflag[WM_TRI(o)] & (WM_F_PLAN | WM_F_UNPAIRED)) == WM_F_PLAN) continue;
        best_e = e;
        best_len = len;
    }
    if (best_e >= 0) {
        int64_t cx, cy;
        int32_t a = me->he[best_e].v, G, k;
        edge_vec(me, best_e, &cx, &cy);
        G = wm_gcd((int32_t)cx, (int32_t)cy);
        k = G / 2;
        return split_edge_at(r, best_e, me->vxy[a].x + (int32_t)(k * (cx / G)),
                             me->vxy[a].y + (int32_t)(k * (cy / G)), st);
    }
    return WM_OK;
}

int wm_execute(wm_refiner *r, int32_t m, int32_t op, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    int32_t e = op, f, a, b, G, k, px, py;
    int64_t cx, cy, tq;
    uint64_t lim, da, db;
    if (op < 0) { /* the slot of an unpaired triangle an earlier one's edge split halved holds a half */
        int32_t t = -op - 1;
        if ((me->tflag[t] & WM_F_NEW) && (r->err[t] <= r->params.zeta || wm_tri_area2(me, t) <= 1)) return WM_OK;
        return wm_split_unpaired(r, t, st);
    }
    f = me->he[e].o;
    a = me->he[e].v;
    b = wm_dest(me, e);
    edge_vec(me, e, &cx, &cy);
    G = wm_gcd((int32_t)cx, (int32_t)cy);
    if (G < 2) {
        /* No grid sample inside the common edge: the pair cannot be split there; each triangle is
         * subdivided as an unpaired one, the partner only when it is not yet within zeta (a dependent
         * partner often is: splitting it adds a vertex the bound never needs). */
        int32_t t2 = f >= 0 ? WM_TRI(f) : -1, rc = wm_split_unpaired(r, WM_TRI(e), st);
        if (rc == WM_OK && t2 >= 0 && r->err[t2] > r->params.zeta) rc = wm_split_unpaired(r, t2, st);
        return rc;
    }
    /* Split point: the mean of the two crossings (one for a quasi-valid pair), snapped to the grid
     * sample of the edge nearest to it, never an end point: k = round(t G) in 1 .. G-1. */
    tq = crossing(r, m, WM_TRI(e), e);
    if (f >= 0) tq = (tq + (65536 - crossing(r, m, WM_TRI(f), f))) / 2; /* f runs b -> a */
    k = (int32_t)((tq * G + 32768) >> 16);
    if (k < 1) k = 1;
    if (k > G - 1) k = G - 1;
    px = me->vxy[a].x + (int32_t)(k * (cx / G));
    py = me->vxy[a].y + (int32_t)(k * (cy / G));
    /* Vertex movement (4.21): when the split point is within delta_v (3-D) of an end of the edge,
     * move that end (the nearer, a on ties) there instead, if the mesh stays proper. */
    lim = (uint64_t)r->params.delta_v * r->params.delta_v;
    da = dist2_q32(r, px, py, me->vxy[a].x, me->vxy[a].y);
    db = dist2_q32(r, px, py, me->vxy[b].x, me->vxy[b].y);
    if (da < lim || db < lim) {
        int32_t v = da <= db ? a : b;
        if (wm_vertex_move(me, v, px, py) == WM_OK) {
            touch_fan(r, v);
            if (st) st->moves++;
            return WM_OK;
        }
    }
    return split_edge_at(r, e, px, py, st);
}
