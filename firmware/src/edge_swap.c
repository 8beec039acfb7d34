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
    if (e < 0 || e >= 3 * m->tri_end || m->he[3 * WM_TRI(e)].v < 0) return 0;
    f = m->he[e].o;
    if (f < 0) return 0;
    return wm_quad_convex(m, m->he[e].v, m->he[f].v, m->he[WM_PREV(e)].v, m->he[WM_PREV(f)].v);
}

int wm_edge_swap(wm_mesh *m, int32_t e, int32_t touched[2], int32_t *n_touched)
{
    if (e < 0 || e >= 3 * m->tri_end || m->he[3 * WM_TRI(e)].v < 0) return WM_ERR_ARG;
    if (!wm_edge_swappable(m, e)) return WM_ERR_REFUSED;
    wm_edge_swap_convex(m, e, touched, n_touched);
    return WM_OK;
}

void wm_edge_swap_convex(wm_mesh *m, int32_t e, int32_t touched[2], int32_t *n_touched)
{
    int32_t f;
    WM_ASSERT(wm_edge_swappable(m, e));
    f = m->he[e].o;
    wm_flip(m, e, f, WM_TRI(e), WM_TRI(f), m->he[e].v, m->he[f].v, m->he[WM_PREV(e)].v, m->he[WM_PREV(f)].v);
    if (touched) {
        touched[0] = WM_TRI(e);
        touched[1] = WM_TRI(f);
    }
    if (n_touched) *n_touched = 2;
    WM_CHECK_MESH(m);
}
