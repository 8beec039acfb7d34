/* Region selection for refinement (dissertation 4.3): detail energy (eq. 4.12) of the detail cells a
 * triangle contains (face-based) or of the cells its vertices lie in (vertex-based), the active region
 * (union of N0), the dependent region (union of N1) and the union of N2 (4.9, 4.10).
 *
 *        N2  N1  N2              A triangle is active when its own E(T) exceeds zeta (Table 4.3:
 *          \ | /                 E(T) <= zeta; refining a triangle that already meets it adds
 *        N1- T -N1               nothing), it has a grid sample besides its corners (twice its area
 *          / | \                 > 1) and a detail cell it contains is energetic: 4.2.1, "triangles
 *        N2  N1  N2              that contain wavelet detail coefficients with large magnitude".
 *
 * The cells of level m that T contains are those holding one of T's grid samples (the closed
 * triangle, as E(T) measures it): the barycentre's cell (4.13) first, which decides most triangles,
 * then T rasterised over the 2^m x 2^m cells row by row, each row's span from two divisions, each
 * cell tested once per row of cells; the first energetic cell ends it. */
#include "wm_internal.h"

static WM_ALWAYS_INLINE int energetic_at(const wm_refiner *r, const wm_level_cells *c, int32_t x, int32_t y)
{
    const int32_t *d = c->d + 3 * ((int64_t)(y >> c->m) * c->cw + (x >> c->m));
    uint64_t e = 0;
    WM_ASSERT(d == wm_detail_at(&r->field, c->m, x, y));
    for (int k = 0; k < 3; k++) {
        uint64_t a = (uint64_t)(d[k] < 0 ? -(int64_t)d[k] : d[k]);
        e += a * a;
    }
    return e > r->params.delta_d; /* as wm_energetic's */
}

int wm_energetic(const wm_refiner *r, int32_t m, int32_t x, int32_t y)
{
    const int32_t *d = wm_detail_at(&r->field, m, x, y);
    uint64_t e = 0;
    for (int k = 0; k < 3; k++) {
        uint64_t a = (uint64_t)(d[k] < 0 ? -(int64_t)d[k] : d[k]);
        e += a * a;
    }
    /* delta_d is the detail's energy per sample of its square (Parseval on the orthonormal details of
     * eq. 3.16: sum D^2 / 4 at every level) over zeta^2; the host folds 16 zeta^2 / s^2 into
     * params.delta_d (native.fixed_params; docs/refiner.md, "Region selection"). */
    return e > r->params.delta_d;
}

static int32_t fdiv(int64_t a, int64_t b) /* floor(a / b), b > 0: 32-bit when it fits (the soft CPU) */
{
    if (a > -0x40000000 && a < 0x40000000 && b < 0x40000000) { /* no int32 overflow below */
        int32_t a32 = (int32_t)a, b32 = (int32_t)b;
        return a32 >= 0 ? a32 / b32 : -((-a32 + b32 - 1) / b32);
    }
    return (int32_t)wm_floor_div(a, b);
}

/* 1 when a detail cell of level m holding a grid sample of the closed triangle (x, y) is energetic. */
static int any_cell(const wm_refiner *r, const wm_level_cells *cl, const int32_t x[3], const int32_t y[3])
{
    int64_t A[3], B[3], C[3];
    int32_t box[4], clo = 1, chi = 0, crow = -1, m = cl->m;
    if (energetic_at(r, cl, wm_div3(x[0] + x[1] + x[2]), wm_div3(y[0] + y[1] + y[2]))) return 1;
    wm_tri_edges(x, y, A, B, C, box);
    for (int32_t py = box[2]; py <= box[3]; py++) {
        int32_t lo = box[0], hi = box[1], a, b;
        for (int k = 0; k < 3; k++) {
            int64_t num = B[k] * py + C[k]; /* E_k = A x + num >= 0 */
            if (A[k] > 0) {
                int32_t l = -fdiv(num, A[k]); /* ceil(-num / A) */
                if (l > lo) lo = l;
            } else if (A[k] < 0) {
                int32_t h = fdiv(num, -A[k]);
                if (h < hi) hi = h;
            }
        }
        if (lo > hi) continue; /* (a row with A_k = 0 lies on or inside that edge: py in the box) */
        a = lo >> m;
        b = hi >> m;
        if ((py >> m) != crow) { /* a new row of cells: nothing of it tested yet */
            crow = py >> m;
            clo = 1;
            chi = 0;
        }
        for (int32_t c = a; c <= b; c++) {
            if (c >= clo && c <= chi) continue; /* tested on the row above */
            if (energetic_at(r, cl, c << m, py)) return 1;
        }
        clo = a;
        chi = b;
    }
    return 0;
}

static int candidate(const wm_refiner *r, const wm_level_cells *cl, int32_t t)
{
    const wm_mesh *me = &r->mesh;
    int32_t x[3], y[3];
    if (r->err[t] <= r->params.zeta || wm_tri_area2(me, t) <= 1) return 0;
    wm_tri_xy(me, t, x, y);
    if (r->params.neighbourhood == WM_NEIGHBOURHOOD_VERTEX) {
        /* N0(v) of every vertex v whose nearest coefficient (the cell containing v) is energetic. */
        for (int k = 0; k < 3; k++)
            if (energetic_at(r, cl, x[k], y[k])) return 1;
        return 0;
    }
    return any_cell(r, cl, x, y);
}

/* Whether the N2 walk round corner v of active triangle t (h = 3 t + k, its half-edge from v) was made
 * already: an active triangle of a lower slot across either edge of t at v has v for a corner, and its
 * walk came first.  A walk only marks WM_F_NEAR, read by no walk (they test ACTIVE and DEP, which are
 * set by then), so a second one round the same vertex changes nothing. */
static int walked(const wm_mesh *me, int32_t t, int32_t h)
{
    int32_t o1 = me->he[h].o, o2 = me->he[WM_PREV(h)].o;
    int w = (o1 >= 0 && WM_TRI(o1) < t && (me->tflag[WM_TRI(o1)] & WM_F_ACTIVE)) ||
            (o2 >= 0 && WM_TRI(o2) < t && (me->tflag[WM_TRI(o2)] & WM_F_ACTIVE));
#if WM_CHECK
    if (w) { /* every triangle round v is active, dependent or marked near already */
        int32_t first = wm_fan_first(me, me->he[h].v), e = first;
        do {
            WM_ASSERT(me->tflag[WM_TRI(e)] & (WM_F_ACTIVE | WM_F_DEP | WM_F_NEAR));
            e = wm_rot_ccw(me, e);
        } while (e >= 0 && e != first);
    }
#endif
    return w;
}

int32_t wm_select(wm_refiner *r, int32_t m, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    int32_t active = 0, dep = 0;
    wm_level_cells cl = wm_level_cells_of(&r->field, m);
    for (int32_t t = 0; t < me->tri_end; t++) me->tflag[t] = 0;
    for (int32_t t = 0; t < me->tri_end; t++) {
        if (me->he[3 * t].v < 0 || !candidate(r, &cl, t)) continue;
        me->tflag[t] = WM_F_ACTIVE;
        active++;
    }
    for (int32_t t = 0; t < me->tri_end; t++) {
        if (!(me->tflag[t] & WM_F_ACTIVE)) continue;
        for (int32_t e = 3 * t; e < 3 * t + 3; e++) { /* N1: across an edge */
            int32_t o = me->he[e].o;
            if (o >= 0 && !(me->tflag[WM_TRI(o)] & (WM_F_ACTIVE | WM_F_DEP))) {
                me->tflag[WM_TRI(o)] |= WM_F_DEP;
                dep++;
            }
        }
    }
    for (int32_t t = 0; t < me->tri_end; t++) {
        if (!(me->tflag[t] & WM_F_ACTIVE)) continue;
        for (int32_t k = 0; k < 3; k++) { /* N2: around a corner only */
            int32_t v = me->he[3 * t + k].v, first, e;
            if (walked(me, t, 3 * t + k)) continue;
            first = wm_fan_first(me, v), e = first;
            do {
                uint8_t *fl = &me->tflag[WM_TRI(e)];
                if (!(*fl & (WM_F_ACTIVE | WM_F_DEP))) *fl |= WM_F_NEAR;
                e = wm_rot_ccw(me, e);
            } while (e >= 0 && e != first);
        }
    }
    if (st) {
        st->active += active;
        st->dependent += dep;
    }
    return active;
}
