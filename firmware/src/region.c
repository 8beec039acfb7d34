/* Region selection for refinement (dissertation 4.3): detail energy (eq. 4.12) at the coefficient
 * of the triangle's barycentre (face-based, eq. 4.13) or of its vertices (vertex-based), the active
 * region (union of N0), the dependent region (union of N1) and the union of N2 (4.9, 4.10).
 *
 *        N2  N1  N2              A triangle is active when the detail energy of its coefficient
 *          \ | /                 exceeds delta_d, its own E(T) exceeds zeta (refining a triangle
 *        N1- T -N1               that already meets the bound adds nothing: 4.6 step 3 stops
 *          / | \                 "when the user specified error criterion is satisfied") and it
 *        N2  N1  N2              has a grid sample besides its corners (twice its area > 1). */
#include "wm_internal.h"

int wm_energetic(const wm_refiner *r, int32_t m, int32_t x, int32_t y)
{
    const int32_t *d = wm_detail_at(&r->field, m, x, y);
    uint64_t e = 0;
    for (int k = 0; k < 3; k++) {
        uint64_t a = (uint64_t)(d[k] < 0 ? -(int64_t)d[k] : d[k]);
        e += a * a;
    }
    /* delta_d is the detail's energy per sample of the square (Parseval on the orthonormal details
     * of eq. 3.16) over the square of the tolerance zeta 2^(m-1) this level refines toward; the host
     * folds 16 zeta^2 / s^2 into params.delta_d (native.fixed_params), the level's 4^(m-1) is here
     * (docs/refiner.md, "Region selection"). */
    {
        int sh = 2 * (m - 1);
        uint64_t th = r->params.delta_d;
        if (sh > 0) th = th > (UINT64_MAX >> sh) ? UINT64_MAX : th << sh;
        return e > th;
    }
}

/* The tolerance of the resolution level m - 1 the details of level m refine toward: zeta 2^(m-1),
 * so that each level of detail stops where its own, coarser, bound holds. */
uint32_t wm_level_zeta(const wm_refiner *r, int32_t m)
{
    uint64_t z = (uint64_t)r->params.zeta << (m - 1);
    return z > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)z;
}

static int candidate(const wm_refiner *r, int32_t m, int32_t t)
{
    const wm_mesh *me = &r->mesh;
    int32_t x[3], y[3];
    if (r->err[t] <= wm_level_zeta(r, m) || wm_tri_area2(me, t) <= 1) return 0;
    wm_tri_xy(me, t, x, y);
    if (r->params.neighbourhood == WM_NEIGHBOURHOOD_VERTEX) {
        /* N0(v) of every vertex v whose nearest coefficient (the cell containing v) is energetic. */
        for (int k = 0; k < 3; k++)
            if (wm_energetic(r, m, x[k], y[k])) return 1;
        return 0;
    }
    /* (i, j) = floor of the barycentre in cell units (4.13): floor((x0 + x1 + x2) / (3 * 2^m)). */
    return wm_energetic(r, m, wm_div3(x[0] + x[1] + x[2]), wm_div3(y[0] + y[1] + y[2]));
}

int32_t wm_select(wm_refiner *r, int32_t m, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    int32_t active = 0, dep = 0;
    for (int32_t t = 0; t < me->tri_end; t++) me->tflag[t] = 0;
    for (int32_t t = 0; t < me->tri_end; t++) {
        if (me->hv[3 * t] < 0 || !candidate(r, m, t)) continue;
        me->tflag[t] = WM_F_ACTIVE;
        active++;
    }
    for (int32_t t = 0; t < me->tri_end; t++) {
        if (!(me->tflag[t] & WM_F_ACTIVE)) continue;
        for (int32_t e = 3 * t; e < 3 * t + 3; e++) { /* N1: across an edge */
            int32_t o = me->ho[e];
            if (o >= 0 && !(me->tflag[WM_TRI(o)] & (WM_F_ACTIVE | WM_F_DEP))) {
                me->tflag[WM_TRI(o)] |= WM_F_DEP;
                dep++;
            }
        }
    }
    for (int32_t t = 0; t < me->tri_end; t++) {
        if (!(me->tflag[t] & WM_F_ACTIVE)) continue;
        for (int32_t k = 0; k < 3; k++) { /* N2: around a corner only */
            int32_t v = me->hv[3 * t + k], first = wm_fan_first(me, v), e = first;
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
