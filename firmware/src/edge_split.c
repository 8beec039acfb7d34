/* Edge split (dissertation 2.5.1, fig. 2.7(c); used by the shape-preserving split of 4.4).
 *
 *          c                        c
 *         / \                     / | \
 *        / T1\                   /T1|T3\
 *       a --e-> b       ->      a --p-- b        e = a->b in T1 = (a, b, c),
 *        \ T2/                   \T4|T2/         f = b->a in T2 = (b, a, d)
 *         \ /                     \ | /
 *          d                        d
 *
 * p is a grid point strictly inside the edge, so the four triangles are counter-clockwise and no
 * other vertex can sit there (it would be a T-junction of the valid mesh).  On the border (no T2)
 * T1 becomes T1 and T3.  T1 and T2 keep their slots; T3 and T4 are new. */
#include "wm_internal.h"

/* The split of e at (x, y), strictly inside the edge, with room for it (f = he[e].o).  Each corner's
 * half-edge (vh) is the one wm_tri_claim of T2, T4, T1 and then T3 would leave it, stored once (no load
 * of he[].v back). */
static WM_ALWAYS_INLINE void split(wm_mesh *m, int32_t e, int32_t f, int32_t x, int32_t y, int32_t touched[4],
                                   int32_t *n_touched)
{
    int32_t t1 = WM_TRI(e), t2, t3, t4 = -1, a = m->he[e].v, b = wm_dest(m, e), c = m->he[WM_PREV(e)].v, d = -1, p;
    int32_t o_bc = m->he[WM_NEXT(e)].o, o_ca = m->he[WM_PREV(e)].o, o_ad = -1, o_db = -1;
    if (f >= 0) {
        d = m->he[WM_PREV(f)].v;
        o_ad = m->he[WM_NEXT(f)].o;
        o_db = m->he[WM_PREV(f)].o;
    }
    p = wm_vert_alloc(m, x, y);
    t3 = wm_tri_take(m);
    WM_ASSERT(p >= 0 && t3 >= 0);
    /* T1 = (a, p, c), T3 = (p, b, c) */
    wm_tri_set(m, t1, a, p, c);
    wm_tri_set(m, t3, p, b, c);
    wm_link(m, 3 * t1 + 1, 3 * t3 + 2); /* p->c with c->p */
    wm_link(m, 3 * t1 + 2, o_ca);       /* c->a */
    wm_link(m, 3 * t3 + 1, o_bc);       /* b->c */
    if (f >= 0) {
        t2 = WM_TRI(f);
        t4 = wm_tri_take(m);
        WM_ASSERT(t4 >= 0);
        /* T2 = (b, p, d), T4 = (p, a, d) */
        wm_tri_set(m, t2, b, p, d);
        wm_tri_set(m, t4, p, a, d);
        wm_link(m, 3 * t2 + 0, 3 * t3 + 0); /* b->p with p->b */
        wm_link(m, 3 * t2 + 1, 3 * t4 + 2); /* p->d with d->p */
        wm_link(m, 3 * t2 + 2, o_db);       /* d->b */
        wm_link(m, 3 * t4 + 0, 3 * t1 + 0); /* p->a with a->p */
        wm_link(m, 3 * t4 + 1, o_ad);       /* a->d */
        m->vh[d] = 3 * t4 + 2;
    } else {
        t2 = -1;
        wm_link(m, 3 * t1 + 0, -1);
        wm_link(m, 3 * t3 + 0, -1);
    }
    m->vh[a] = 3 * t1;
    m->vh[p] = 3 * t3;
    m->vh[b] = 3 * t3 + 1;
    m->vh[c] = 3 * t3 + 2;
    if (touched) {
        touched[0] = t1;
        touched[1] = t3;
        if (f >= 0) {
            touched[2] = t2;
            touched[3] = t4;
        }
    }
    if (n_touched) *n_touched = f >= 0 ? 4 : 2;
    WM_CHECK_MESH(m);
}

/* (x, y) strictly between e's ends a and b on the segment. */
static int strictly_inside(const wm_mesh *m, int32_t e, int32_t x, int32_t y)
{
    int32_t a = m->he[e].v, b = wm_dest(m, e);
    int64_t ax = m->vxy[a].x, ay = m->vxy[a].y, dx = m->vxy[b].x - ax, dy = m->vxy[b].y - ay, px = x - ax,
            py = y - ay;
    return px * dy - py * dx == 0 && px * dx + py * dy > 0 && px * dx + py * dy < dx * dx + dy * dy;
}

int wm_edge_split(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t touched[4], int32_t *n_touched)
{
    int32_t f;
    if (e < 0 || e >= 3 * m->tri_end || m->he[3 * WM_TRI(e)].v < 0) return WM_ERR_ARG;
    if (!strictly_inside(m, e, x, y)) return WM_ERR_REFUSED;
    f = m->he[e].o;
    if (!wm_room_for_split(m, f >= 0 ? 2 : 1)) return WM_ERR_CAPACITY;
    split(m, e, f, x, y, touched, n_touched);
    return WM_OK;
}

int wm_edge_split_inside(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t touched[4], int32_t *n_touched)
{
    int32_t f = m->he[e].o;
    WM_ASSERT(e >= 0 && e < 3 * m->tri_end && m->he[3 * WM_TRI(e)].v >= 0 && strictly_inside(m, e, x, y));
    if (!wm_room_for_split(m, f >= 0 ? 2 : 1)) return WM_ERR_CAPACITY;
    split(m, e, f, x, y, touched, n_touched);
    return WM_OK;
}
