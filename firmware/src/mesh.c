/* The index-based half-edge mesh: layout, building from triangle arrays, export, invariant check,
 * slot allocation with free lists (room for the reduction operators of a later issue). */
#include "wm_internal.h"

const char *wm_strerror(int code)
{
    switch (code) {
    case WM_OK: return "ok";
    case WM_ERR_ARG: return "argument out of range";
    case WM_ERR_MEMORY: return "storage smaller than the bound";
    case WM_ERR_CAPACITY: return "capacity exhausted";
    case WM_ERR_MESH: return "not a proper triangulation of the grid rectangle";
    case WM_ERR_STATE: return "refiner finished or not initialised";
    case WM_ERR_REFUSED: return "operator precondition fails";
    default: return "unknown error";
    }
}

#define ALIGN8(n) (((n) + 7u) & ~(uint64_t)7u)

static uint64_t mesh_bytes(int32_t tri_cap, int32_t vert_cap)
{
    uint64_t t = (uint64_t)tri_cap, v = (uint64_t)vert_cap, w = sizeof(wm_index);
    return ALIGN8(6 * w * t) + ALIGN8(w * v) + ALIGN8(sizeof(wm_xy) * v) + ALIGN8(t);
}

size_t wm_mesh_bound(int32_t tri_cap, int32_t vert_cap)
{
    uint64_t b;
    if (tri_cap < 1 || vert_cap < 3 || tri_cap > 0x15555554 || vert_cap > 0x3FFFFFFF) return 0;
#if WM_INDEX_BITS == 16
    if (tri_cap > WM_INDEX_MAX / 3 || vert_cap > WM_INDEX_MAX) return 0; /* half-edge and vertex numbers */
#endif
    b = mesh_bytes(tri_cap, vert_cap);
    if (b > (uint64_t)(size_t)-1) return 0;
    return (size_t)b;
}

int32_t wm_vert_cap_for(int32_t width, int32_t height, int32_t tri_cap)
{
    int64_t v = (int64_t)tri_cap / 2 + (int64_t)width + (int64_t)height + 2;
    return v > 0x3FFFFFFF ? 0x3FFFFFFF : (int32_t)v;
}

/* The test is the distance the vertex x and y arrays had (2 bytes a vertex each) before a vertex's x and y
 * lay side by side (vxy), kept as measured: it still moves vh and vxy, twice that distance apart, off a
 * multiple of 8 KiB for the grids it moves (the board's Ball 128 x 128 without it: refine +0.8 % cycles,
 * wm_fan_first's cycles +59 %). */
int32_t wm_tri_cap_skewed(int32_t width, int32_t height, int32_t cap, int32_t limit)
{
    for (int32_t c = cap; c <= limit && c - cap <= 8192; c += 2) {
        uint64_t r = ALIGN8(2 * (uint64_t)wm_vert_cap_for(width, height, c)) % 8192u;
        if (r >= 1024u && r <= 8192u - 1024u) return c;
    }
    return cap;
}

int wm_mesh_init(wm_mesh *m, void *mem, size_t bytes, int32_t width, int32_t height, int32_t tri_cap,
                 int32_t vert_cap)
{
    uint8_t *p = (uint8_t *)mem;
    size_t need;
    if (width < 2 || height < 2 || width > WM_MAX_SIDE || height > WM_MAX_SIDE) return WM_ERR_ARG;
    need = wm_mesh_bound(tri_cap, vert_cap);
    if (need == 0) return WM_ERR_ARG;
    if (mem == NULL || bytes < need) return WM_ERR_MEMORY;
    m->width = width;
    m->height = height;
    m->tri_cap = tri_cap;
    m->vert_cap = vert_cap;
    m->tri_end = m->vert_end = m->n_tri = m->n_vert = 0;
    m->tri_free = m->vert_free = -1;
    m->he = (wm_he *)(void *)p;
    p += ALIGN8(6 * sizeof(wm_index) * (uint64_t)tri_cap);
    m->vh = (wm_index *)(void *)p;
    p += ALIGN8(sizeof(wm_index) * (uint64_t)vert_cap);
    m->vxy = (wm_xy *)(void *)p;
    p += ALIGN8(sizeof(wm_xy) * (uint64_t)vert_cap);
    m->tflag = p;
    return WM_OK;
}

int32_t wm_vert_alloc(wm_mesh *m, int32_t x, int32_t y)
{
    int32_t v;
    if (m->vert_free >= 0) {
        v = m->vert_free;
        m->vert_free = m->vh[v];
    } else {
        if (m->vert_end >= m->vert_cap) return -1;
        v = m->vert_end++;
    }
    m->n_vert++;
    m->vxy[v].x = (uint16_t)x;
    m->vxy[v].y = (uint16_t)y;
    m->vh[v] = -1;
    return v;
}

void wm_tri_claim(wm_mesh *m, int32_t t)
{
    for (int32_t e = 3 * t; e < 3 * t + 3; e++) m->vh[m->he[e].v] = e;
}

int32_t wm_fan_first(const wm_mesh *m, int32_t v)
{
    int32_t start = m->vh[v], e = start;
    if (!wm_on_border(m, m->vxy[v].x, m->vxy[v].y)) return start; /* a full fan: any half-edge is first */
    for (;;) {
        int32_t c = wm_rot_cw(m, e);
        if (c < 0) return e;
        if (c == start) return start;
        e = c;
    }
}

int64_t wm_tri_area2(const wm_mesh *m, int32_t t)
{
    int32_t a = m->he[3 * t].v, b = m->he[3 * t + 1].v, c = m->he[3 * t + 2].v;
    return wm_orient(m->vxy[a].x, m->vxy[a].y, m->vxy[b].x, m->vxy[b].y, m->vxy[c].x, m->vxy[c].y);
}

int wm_mesh_build(wm_mesh *m, const int32_t *xy, int32_t nv, const int32_t *tris, int32_t nt, uint32_t *scratch)
{
    const uint32_t nil = 0xFFFFFFFFu;
    if (m->tri_end != 0 || m->vert_end != 0) return WM_ERR_ARG;
    if (nv < 3 || nt < 1 || xy == NULL || tris == NULL || scratch == NULL) return WM_ERR_ARG;
    if (nt > m->tri_cap || nv > m->vert_cap) return WM_ERR_CAPACITY;
    for (int32_t v = 0; v < nv; v++) {
        int32_t x = xy[2 * v], y = xy[2 * v + 1];
        if (x < 0 || y < 0 || x >= m->width || y >= m->height) return WM_ERR_ARG;
        m->vxy[v].x = (uint16_t)x;
        m->vxy[v].y = (uint16_t)y;
        m->vh[v] = -1;
    }
    /* The half-edges, and buckets of them by origin vertex: heads in vh, links in scratch.  Filled from
     * the last half-edge down, so a head ends as its vertex's lowest half-edge (vh's meaning).  A link
     * names half-edge f by its successor's number, next(f) << 2 | f % 3 (3 nt < 2^30), and is stored
     * at scratch[next(f')] for the f' it follows: the walk below reads f's destination he[next(f)].v and
     * the link after it at one index, without a division.  A head is f itself (vh may be 16-bit). */
    for (int32_t t = nt - 1; t >= 0; t--) {
        for (int32_t k = 2; k >= 0; k--) {
            int32_t e = 3 * t + k, a = tris[e], h;
            if (a < 0 || a >= nv) return WM_ERR_ARG;
            m->he[e].v = a;
            m->he[e].o = -1;
            h = m->vh[a];
            if (h < 0) {
                scratch[k == 2 ? e - 2 : e + 1] = nil;
            } else {
                int32_t r = h - 3 * wm_div3(h);
                scratch[k == 2 ? e - 2 : e + 1] = (uint32_t)(r == 2 ? h - 2 : h + 1) << 2 | (uint32_t)r;
            }
            m->vh[a] = e;
        }
    }
    for (int32_t t = 0; t < nt; t++) m->tflag[t] = 0;
    m->vert_end = m->n_vert = nv;
    m->tri_end = m->n_tri = nt;
    for (int32_t v = 0; v < nv; v++)
        if (m->vh[v] < 0) return WM_ERR_MESH; /* unused vertex */
    /* Each edge once, from the half-edge a -> b with a < b: its opposite is the one half-edge b -> a in
     * b's bucket, and both are linked.  A repeated b -> a is found twice here, a repeated a -> b takes
     * an opposite already taken: either is not a triangulation. */
    for (int32_t e = 0; e < 3 * nt; e += 3) {
        for (int32_t k = 0; k < 3; k++) {
            int32_t a = m->he[e + k].v, b = m->he[k == 2 ? e : e + k + 1].v, found = -1, h = m->vh[b], r;
            uint32_t f;
            if (a > b) continue;
            r = h - 3 * wm_div3(h);
            for (f = (uint32_t)(r == 2 ? h - 2 : h + 1) << 2 | (uint32_t)r; f != nil; f = scratch[f >> 2]) {
                if (m->he[f >> 2].v != a) continue;
                if (found >= 0) return WM_ERR_MESH; /* edge used by more than two triangles */
                found = (f & 3u) == 2 ? (int32_t)(f >> 2) + 2 : (int32_t)(f >> 2) - 1;
            }
            m->he[e + k].o = found;
            if (found >= 0) {
                if (m->he[found].o >= 0) return WM_ERR_MESH; /* a repeated half-edge a -> b */
                m->he[found].o = e + k;
            }
        }
    }
    return wm_mesh_check(m);
}

int32_t wm_mesh_export(const wm_mesh *m, int32_t *xy, int32_t *tris)
{
    int32_t n = 0;
    for (int32_t v = 0; v < m->vert_end; v++) {
        int free_slot = m->vxy[v].x == WM_FREE;
        xy[2 * v] = free_slot ? -1 : m->vxy[v].x;
        xy[2 * v + 1] = free_slot ? -1 : m->vxy[v].y;
    }
    for (int32_t t = 0; t < m->tri_end; t++) {
        if (m->he[3 * t].v < 0) continue;
        tris[3 * n] = m->he[3 * t].v;
        tris[3 * n + 1] = m->he[3 * t + 1].v;
        tris[3 * n + 2] = m->he[3 * t + 2].v;
        n++;
    }
    return n;
}

int wm_mesh_check_line(const wm_mesh *m)
{
    int64_t area = 0;
    int32_t live_t = 0, live_v = 0, border_v = 0, nfree = 0;
    if (m->tri_end < 0 || m->tri_end > m->tri_cap || m->vert_end < 0 || m->vert_end > m->vert_cap) return __LINE__;
    /* Free lists: every entry a free slot, no cycle longer than the slots. */
    for (int32_t t = m->tri_free; t >= 0; t = m->he[3 * t].o) {
        if (t >= m->tri_end || m->he[3 * t].v >= 0 || ++nfree > m->tri_end) return __LINE__;
    }
    nfree = 0;
    for (int32_t v = m->vert_free; v >= 0; v = m->vh[v]) {
        if (v >= m->vert_end || m->vxy[v].x != WM_FREE || ++nfree > m->vert_end) return __LINE__;
    }
    for (int32_t v = 0; v < m->vert_end; v++) {
        int32_t e = m->vh[v];
        if (m->vxy[v].x == WM_FREE) continue;
        live_v++;
        if (m->vxy[v].x >= m->width || m->vxy[v].y >= m->height) return __LINE__;
        if (e < 0 || e >= 3 * m->tri_end || m->he[3 * wm_div3(e)].v < 0 || m->he[e].v != v) return __LINE__;
        if (wm_on_border(m, m->vxy[v].x, m->vxy[v].y)) border_v++;
    }
    for (int32_t t = 0; t < m->tri_end; t++) {
        int64_t a2;
        if (m->he[3 * t].v < 0) continue;
        live_t++;
        for (int32_t e = 3 * t; e < 3 * t + 3; e++) {
            int32_t a = m->he[e].v, b, o = m->he[e].o;
            if (a < 0 || a >= m->vert_end || m->vxy[a].x == WM_FREE) return __LINE__;
            b = m->he[e == 3 * t + 2 ? 3 * t : e + 1].v;
            if (b < 0 || b >= m->vert_end || m->vxy[b].x == WM_FREE) return __LINE__;
            if (o >= 0) {
                int32_t to = wm_div3(o); /* o's triangle, and o's destination from it: one multiply */
                if (o >= 3 * m->tri_end || m->he[3 * to].v < 0 || to == t) return __LINE__;
                if (m->he[o].o != e || m->he[o].v != b || m->he[o == 3 * to + 2 ? 3 * to : o + 1].v != a)
                    return __LINE__;
            } else {
                int32_t ax = m->vxy[a].x, ay = m->vxy[a].y, bx = m->vxy[b].x, by = m->vxy[b].y;
                int on = (ax == bx && (ax == 0 || ax == m->width - 1)) ||
                         (ay == by && (ay == 0 || ay == m->height - 1));
                if (!on) return __LINE__;
            }
        }
        a2 = wm_tri_area2(m, t);
        if (a2 <= 0) return __LINE__;
        area += a2;
    }
    if (live_t != m->n_tri || live_v != m->n_vert) return __LINE__;
    if (area != 2 * (int64_t)(m->width - 1) * (int64_t)(m->height - 1)) return __LINE__;
    if (live_t != 2 * live_v - border_v - 2) return __LINE__;
    return 0;
}

int wm_mesh_check(const wm_mesh *m) { return wm_mesh_check_line(m) == 0 ? WM_OK : WM_ERR_MESH; }
