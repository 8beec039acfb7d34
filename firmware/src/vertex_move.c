/* Vertex movement (dissertation 4.4.3, fig. 4.14): instead of splitting next to a vertex, move it.
 *
 *        \   |   /                 \   |   /
 *         \  |  /                   \  |  /
 *       ---- v ----     ->        ----  \ /
 *         /  |  \                   /   v' (the split point)
 *
 * Valid exactly when every triangle around v is still counter-clockwise with v at (x, y): (x, y)
 * is then inside the kernel of v's star, so the star is still triangulated once.  A vertex on the
 * border may only slide along its own side (the rectangle stays covered); a corner never moves. */
#include "wm_internal.h"

int wm_vertex_move(wm_mesh *m, int32_t v, int32_t x, int32_t y)
{
    int32_t ox, oy, first, e;
    if (v < 0 || v >= m->vert_end || m->vxy[v].x == WM_FREE) return WM_ERR_ARG;
    if (x < 0 || y < 0 || x >= m->width || y >= m->height) return WM_ERR_REFUSED;
    ox = m->vxy[v].x;
    oy = m->vxy[v].y;
    if (x == ox && y == oy) return WM_OK;
    if (wm_on_border(m, ox, oy)) {
        int vert_side = ox == 0 || ox == m->width - 1, horz_side = oy == 0 || oy == m->height - 1;
        if (vert_side && horz_side) return WM_ERR_REFUSED; /* corner */
        if (vert_side && x != ox) return WM_ERR_REFUSED;
        if (horz_side && y != oy) return WM_ERR_REFUSED;
    }
    first = wm_fan_first(m, v);
    e = first;
    do {
        int32_t b = wm_dest(m, e), c = m->he[WM_PREV(e)].v;
        if (wm_orient(x, y, m->vxy[b].x, m->vxy[b].y, m->vxy[c].x, m->vxy[c].y) <= 0) return WM_ERR_REFUSED;
        e = wm_rot_ccw(m, e);
    } while (e >= 0 && e != first);
    m->vxy[v].x = (uint16_t)x;
    m->vxy[v].y = (uint16_t)y;
    WM_CHECK_MESH(m);
    return WM_OK;
}
