/* Ternary subdivision (dissertation 4.4.3, fig. 4.15) of an unpaired triangle.
 *
 *            c                          c
 *           / \                       / | \
 *          /   \                     / N2|N1\
 *         /  T  \         ->        /  .p.  \        p strictly inside T = (a, b, c)
 *        /       \                 / .  T  . \
 *       a---------b               a-----------b
 *
 * T keeps its slot as (a, b, p); N1 = (b, c, p) and N2 = (c, a, p) are new. */
#include "wm_internal.h"

/* The split of live t at (x, y), strictly inside it, with room for it.  Each corner's half-edge (vh) is the
 * one wm_tri_claim of t, N1 and then N2 would leave it, stored once (no load of he[].v back). */
static WM_ALWAYS_INLINE void split(wm_mesh *m, int32_t t, int32_t x, int32_t y, int32_t touched[3],
                                   int32_t *n_touched)
{
    int32_t a = m->he[3 * t].v, b = m->he[3 * t + 1].v, c = m->he[3 * t + 2].v, p, n1, n2, o_ab, o_bc, o_ca;
    o_ab = m->he[3 * t].o;
    o_bc = m->he[3 * t + 1].o;
    o_ca = m->he[3 * t + 2].o;
    p = wm_vert_alloc(m, x, y);
    n1 = wm_tri_take(m);
    n2 = wm_tri_take(m);
    WM_ASSERT(p >= 0 && n1 >= 0 && n2 >= 0);
    wm_tri_set(m, t, a, b, p);
    wm_tri_set(m, n1, b, c, p);
    wm_tri_set(m, n2, c, a, p);
    wm_link(m, 3 * t + 0, o_ab);
    wm_link(m, 3 * n1 + 0, o_bc);
    wm_link(m, 3 * n2 + 0, o_ca);
    wm_link(m, 3 * t + 1, 3 * n1 + 2);  /* b->p with p->b */
    wm_link(m, 3 * n1 + 1, 3 * n2 + 2); /* c->p with p->c */
    wm_link(m, 3 * n2 + 1, 3 * t + 2);  /* a->p with p->a */
    m->vh[a] = 3 * n2 + 1;              /* the claims of t, N1, N2 in turn */
    m->vh[b] = 3 * n1;
    m->vh[c] = 3 * n2;
    m->vh[p] = 3 * n2 + 2;
    if (touched) {
        touched[0] = t;
        touched[1] = n1;
        touched[2] = n2;
    }
    if (n_touched) *n_touched = 3;
    WM_CHECK_MESH(m);
}

/* (x, y) strictly inside live t (a grid point: wm_orient is exact for grid points only). */
static int strictly_inside(const wm_mesh *m, int32_t t, int32_t x, int32_t y)
{
    int32_t a = m->he[3 * t].v, b = m->he[3 * t + 1].v, c = m->he[3 * t + 2].v;
    return x >= 0 && y >= 0 && x < m->width && y < m->height &&
           wm_orient(m->vxy[a].x, m->vxy[a].y, m->vxy[b].x, m->vxy[b].y, x, y) > 0 &&
           wm_orient(m->vxy[b].x, m->vxy[b].y, m->vxy[c].x, m->vxy[c].y, x, y) > 0 &&
           wm_orient(m->vxy[c].x, m->vxy[c].y, m->vxy[a].x, m->vxy[a].y, x, y) > 0;
}

int wm_tri_split(wm_mesh *m, int32_t t, int32_t x, int32_t y, int32_t touched[3], int32_t *n_touched)
{
    if (!wm_tri_live(m, t)) return WM_ERR_ARG;
    if (!strictly_inside(m, t, x, y)) return WM_ERR_REFUSED;
    if (!wm_room_for_split(m, 2)) return WM_ERR_CAPACITY;
    split(m, t, x, y, touched, n_touched);
    return WM_OK;
}

int wm_tri_split_inside(wm_mesh *m, int32_t t, int32_t x, int32_t y, int32_t touched[3], int32_t *n_touched)
{
    WM_ASSERT(wm_tri_live(m, t) && strictly_inside(m, t, x, y));
    if (!wm_room_for_split(m, 2)) return WM_ERR_CAPACITY;
    split(m, t, x, y, touched, n_touched);
    return WM_OK;
}
