/* Edge swap (dissertation 2.5.1, fig. 2.7(d); the regularisation of 4.5.1).
 *
 *          c                         c
 *         / \                       /|\
 *        / T1\                     / | \
 *       a --e-> b       ->         a T1|T2 b      T1 = (a, d, c), T2 = (d, b, c)
 *        \ T2/                     \ | /
 *         \ /                       \|/
 *          d                         d
 *
 *   e = a->b in T1 = (a, b, c), f = b->a in T2 = (b, a, d): the diagonal a-b becomes c-d.
 *
 * Only for a strictly convex quadrilateral a-d-b-c (no three corners collinear, 4.5.1): then both
 * new triangles are counter-clockwise, and no vertex or edge outside the quadrilateral changes. */
#include "wm_internal.h"

int wm_edge_swappable(const wm_mesh *m, int32_t e)
{
    int32_t f;
    if (e < 0 || e >= 3 * m->tri_end || m->hv[3 * WM_TRI(e)] < 0) return 0;
    f = m->ho[e];
    if (f < 0) return 0;
    return wm_quad_convex(m, m->hv[e], m->hv[f], m->hv[WM_PREV(e)], m->hv[WM_PREV(f)]);
}

int wm_edge_swap(wm_mesh *m, int32_t e, int32_t touched[2], int32_t *n_touched)
{
    if (e < 0 || e >= 3 * m->tri_end || m->hv[3 * WM_TRI(e)] < 0) return WM_ERR_ARG;
    if (!wm_edge_swappable(m, e)) return WM_ERR_REFUSED;
    wm_edge_swap_convex(m, e, touched, n_touched);
    return WM_OK;
}

/* The swap itself, e = a->b in T1 = (a, b, c), f = b->a in T2 = (b, a, d): the triangles (a, d, c) and
 * (d, b, c) in the same slots, their outer edges linked as before, and each corner's half-edge (vh) the
 * one of the new triangles wm_tri_claim of T1 and then T2 leaves it.  Inlined in both callers. */
static WM_ALWAYS_INLINE void flip(wm_mesh *m, int32_t e, int32_t f, int32_t t1, int32_t t2, int32_t a, int32_t b,
                                  int32_t c, int32_t d)
{
    int32_t e1 = 3 * t1, e2 = 3 * t2;
    int32_t o_bc = m->ho[WM_NEXT(e)], o_ca = m->ho[WM_PREV(e)], o_ad = m->ho[WM_NEXT(f)], o_db = m->ho[WM_PREV(f)];
    m->hv[e1] = a;
    m->hv[e1 + 1] = d;
    m->hv[e1 + 2] = c;
    m->hv[e2] = d;
    m->hv[e2 + 1] = b;
    m->hv[e2 + 2] = c;
    wm_link(m, e1, o_ad);         /* a->d */
    wm_link(m, e1 + 1, e2 + 2);   /* d->c with c->d */
    wm_link(m, e1 + 2, o_ca);     /* c->a */
    wm_link(m, e2, o_db);         /* d->b */
    wm_link(m, e2 + 1, o_bc);     /* b->c */
    m->vh[a] = e1;
    m->vh[d] = e2;      /* T2's claim after T1's */
    m->vh[b] = e2 + 1;
    m->vh[c] = e2 + 2;
}

void wm_edge_flip(wm_mesh *m, int32_t e, int32_t f, int32_t t1, int32_t t2, int32_t a, int32_t b, int32_t c,
                  int32_t d)
{
    WM_ASSERT(wm_edge_swappable(m, e) && m->ho[e] == f && m->hv[e] == a && m->hv[f] == b &&
              m->hv[WM_PREV(e)] == c && m->hv[WM_PREV(f)] == d && t1 == WM_TRI(e) && t2 == WM_TRI(f));
    flip(m, e, f, t1, t2, a, b, c, d);
    WM_CHECK_MESH(m);
}

void wm_edge_swap_convex(wm_mesh *m, int32_t e, int32_t touched[2], int32_t *n_touched)
{
    int32_t f;
    WM_ASSERT(wm_edge_swappable(m, e));
    f = m->ho[e];
    flip(m, e, f, WM_TRI(e), WM_TRI(f), m->hv[e], m->hv[f], m->hv[WM_PREV(e)], m->hv[WM_PREV(f)]);
    if (touched) {
        touched[0] = WM_TRI(e);
        touched[1] = WM_TRI(f);
    }
    if (n_touched) *n_touched = 2;
    WM_CHECK_MESH(m);
}
