/* Edge collapse (dissertation 4.5.3, fig. 4.18): the edge v1 - v2 becomes one vertex p.
 *
 *        a-------b-------c                a-------b-------c
 *       / \     / \     / \              / \      |      / \
 *      /   \   /   \   /   \            /   \_    |    _/   \       the one or two triangles on
 *     f----v1 ------- v2----d    ->    f------ ---p--- ------d      the edge vanish; every other
 *      \   /   \   /   \   /            \    _/   |   \_    /       triangle around v1 or v2 takes
 *       \ /     \ /     \ /              \  /     |     \  /        p for v1 or v2
 *        g-------h-------i                g-------h-------i
 *
 * p is the dissertation's midpoint snapped to a grid sample of the edge (every vertex is a grid
 * sample), or one of the ends (a half-edge collapse); reduce.c chooses it.  The result is a proper
 * triangulation when (1) every new triangle is strictly counter-clockwise, (2) the common neighbours
 * of v1 and v2 are exactly the far corners of the triangles on the edge (the link condition: no edge
 * or triangle appears twice), and (3) the border stays the rectangle's (a corner never moves, a
 * vertex on a side moves only along that side).  Then the new triangles cover the union of the two
 * stars exactly: their signed areas add up to its area (a fan from p over its closed boundary), and
 * a set of strictly counter-clockwise triangles meeting edge to edge with that area covers every
 * point once (the argument of vertex_remove.c).
 *
 * Carried out with the existing operators, so every step is a valid mesh: an edge split at p when p
 * is inside the edge, then the fans of v1 and of v2 from p (wm_vertex_remove with the apex at p,
 * the half-edge collapses), whose triangles are exactly the planned ones. */
#include "wm_internal.h"

static int same_side(const wm_mesh *m, int32_t v, int32_t x, int32_t y)
{
    int32_t vx = m->vxy[v].x, vy = m->vxy[v].y;
    return (vx == 0 && x == 0) || (vx == m->width - 1 && x == m->width - 1) || (vy == 0 && y == 0) ||
           (vy == m->height - 1 && y == m->height - 1);
}

static int corner(const wm_mesh *m, int32_t v)
{
    int32_t vx = m->vxy[v].x, vy = m->vxy[v].y;
    return (vx == 0 || vx == m->width - 1) && (vy == 0 || vy == m->height - 1);
}

/* v's neighbours (the ring, with both side neighbours for a border vertex) and the half-edges
 * leaving v; the neighbour count, or WM_ERR_REFUSED beyond WM_MAX_RING. */
static int32_t star(const wm_mesh *m, int32_t v, int32_t nb[WM_MAX_RING], int32_t out[WM_MAX_RING], int32_t *k)
{
    int32_t first = wm_fan_first(m, v), h = first, n = 0;
    do {
        if (n >= WM_MAX_RING) return WM_ERR_REFUSED;
        out[n] = h;
        nb[n++] = wm_dest(m, h);
        h = wm_rot_ccw(m, h);
    } while (h >= 0 && h != first);
    *k = n;
    if (h < 0) {
        if (n >= WM_MAX_RING) return WM_ERR_REFUSED;
        nb[n] = m->he[WM_PREV(out[n - 1])].v;
        n++;
    }
    return n;
}

/* (x, y) for the edge v1 -> v2: WM_ERR_ARG unless an end or strictly inside the edge, WM_ERR_REFUSED
 * when the border would not stay; else WM_OK. */
static int point_check(const wm_mesh *m, const int32_t v[2], int32_t x, int32_t y)
{
    int64_t dx = (int64_t)m->vxy[v[1]].x - m->vxy[v[0]].x, dy = (int64_t)m->vxy[v[1]].y - m->vxy[v[0]].y;
    int64_t px = (int64_t)x - m->vxy[v[0]].x, py = (int64_t)y - m->vxy[v[0]].y;
    if (px * dy - py * dx != 0 || px * dx + py * dy < 0 || px * dx + py * dy > dx * dx + dy * dy)
        return WM_ERR_ARG;
    /* the border stays */
    for (int i = 0; i < 2; i++) {
        if (m->vxy[v[i]].x == x && m->vxy[v[i]].y == y) continue;
        if (wm_on_border(m, m->vxy[v[i]].x, m->vxy[v[i]].y) && (corner(m, v[i]) || !same_side(m, v[i], x, y)))
            return WM_ERR_REFUSED;
    }
    return WM_OK;
}

int wm_collapse_stars(const wm_mesh *m, int32_t e, struct wm_collapse_stars *s)
{
    int32_t common = 0;
    s->v[0] = m->he[e].v;
    s->v[1] = wm_dest(m, e);
    for (int i = 0; i < 2; i++) {
        s->n[i] = star(m, s->v[i], s->nb[i], s->out[i], &s->k[i]);
        if (s->n[i] < 0) return (int)s->n[i];
    }
    /* the link condition */
    for (int32_t i = 0; i < s->n[0]; i++)
        for (int32_t j = 0; j < s->n[1]; j++)
            if (s->nb[0][i] == s->nb[1][j]) common++;
    return common != (m->he[e].o >= 0 ? 2 : 1) ? WM_ERR_REFUSED : WM_OK;
}

int wm_collapse_plan_at(const wm_mesh *m, const struct wm_collapse_stars *s, int32_t x, int32_t y,
                        int32_t tris[6 * WM_MAX_RING], int32_t *n_tris)
{
    const int32_t *v = s->v;
    int32_t nt = 0;
    int rc = point_check(m, v, x, y);
    if (rc != WM_OK) return rc;
    /* the triangles around v1, then v2, that do not hold the edge, with p for v1 or v2 (those around
     * an end that stays where it is do not change: a half-edge collapse plans only the other end's) */
    for (int i = 0; i < 2; i++) {
        if (m->vxy[v[i]].x == x && m->vxy[v[i]].y == y) continue;
        for (int32_t j = 0; j < s->k[i]; j++) {
            int32_t t = WM_TRI(s->out[i][j]), c[3], cx[3], cy[3], other = 0;
            for (int q = 0; q < 3; q++) {
                int32_t w = m->he[3 * t + q].v;
                if (w == v[1 - i]) other = 1;
                c[q] = (w == v[0] || w == v[1]) ? WM_COLLAPSE_POINT : w;
                cx[q] = c[q] < 0 ? x : m->vxy[w].x;
                cy[q] = c[q] < 0 ? y : m->vxy[w].y;
            }
            if (other) continue;
            if (wm_orient(cx[0], cy[0], cx[1], cy[1], cx[2], cy[2]) <= 0) return WM_ERR_REFUSED;
            tris[3 * nt] = c[0], tris[3 * nt + 1] = c[1], tris[3 * nt + 2] = c[2];
            nt++;
        }
    }
    *n_tris = nt;
    return WM_OK;
}

int wm_edge_collapse_plan(const wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t tris[6 * WM_MAX_RING],
                          int32_t *n_tris)
{
    struct wm_collapse_stars s;
    int32_t v[2];
    int rc;
    if (e < 0 || e >= 3 * m->tri_end || m->he[3 * WM_TRI(e)].v < 0) return WM_ERR_ARG;
    v[0] = m->he[e].v;
    v[1] = wm_dest(m, e);
    rc = point_check(m, v, x, y);
    if (rc == WM_OK) rc = wm_collapse_stars(m, e, &s);
    return rc == WM_OK ? wm_collapse_plan_at(m, &s, x, y, tris, n_tris) : rc;
}

/* Removes v by the fan from its neighbour p (a half-edge collapse of v into p), after the collapse's
 * plan, whose triangles are this fan's (so strictly counter-clockwise): v's fan walked once, for its
 * ring and the removal with the fan from p's ring position (wm_vertex_remove_fan with its apex), where
 * wm_vertex_remove_plan and wm_vertex_remove walked it again each and planned the fan (checked builds
 * plan it and compare). */
static int fan_into(wm_mesh *m, int32_t v, int32_t p, int32_t *touched, int32_t *n_touched)
{
    int32_t e[WM_MAX_RING], ring[WM_MAX_RING], n, i, k;
    const int32_t *plan = NULL;
#if WM_CHECK
    int32_t tris[3 * WM_MAX_RING], nt;
#endif
    n = wm_vertex_fan(m, v, e, &k, ring);
    if (n < 0) return (int)n;
    for (i = 0; i < n && ring[i] != p; i++) {}
    if (i == n) return WM_ERR_REFUSED;
#if WM_CHECK
    WM_ASSERT(wm_ring_plan(m, ring, n, i, tris, &nt) == WM_OK && nt == n - 2);
    plan = tris;
#endif
    return wm_vertex_remove_fan(m, v, e, k, ring, n, i, plan, n - 2, touched, n_touched);
}

int wm_edge_collapse_planned(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t nt,
                             int32_t touched[6 * WM_MAX_RING], int32_t *n_touched, int32_t *vertex)
{
    int32_t v1 = m->he[e].v, v2 = wm_dest(m, e), p = -1, na = 0, nb = 0, rc;
    if (m->vxy[v1].x == x && m->vxy[v1].y == y) {
        p = v1;
        rc = fan_into(m, v2, v1, touched, &na);
    } else if (m->vxy[v2].x == x && m->vxy[v2].y == y) {
        p = v2;
        rc = fan_into(m, v1, v2, touched, &na);
    } else {
        int32_t split[4], ns;
        rc = wm_edge_split(m, e, x, y, split, &ns);
        if (rc != WM_OK) return rc; /* nothing changed (capacity) */
        for (int q = 0; q < 3; q++) {
            int32_t w = m->he[3 * split[0] + q].v;
            if (m->vxy[w].x == x && m->vxy[w].y == y) p = w;
        }
        rc = fan_into(m, v1, p, touched, &na);
        if (rc == WM_OK) rc = fan_into(m, v2, p, touched + na, &nb);
    }
    /* Cannot fail after the plan: the fans are the planned triangles. */
    WM_ASSERT(rc == WM_OK && na + nb == nt);
    (void)nt;
    if (n_touched) *n_touched = na + nb;
    if (vertex) *vertex = p;
    WM_CHECK_MESH(m);
    return rc == WM_OK ? WM_OK : WM_ERR_REFUSED;
}

int wm_edge_collapse(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t touched[6 * WM_MAX_RING],
                     int32_t *n_touched, int32_t *vertex)
{
    int32_t tris[6 * WM_MAX_RING], nt;
    int rc = wm_edge_collapse_plan(m, e, x, y, tris, &nt);
    return rc == WM_OK ? wm_edge_collapse_planned(m, e, x, y, nt, touched, n_touched, vertex) : rc;
}
