/* Holes: what a triangle covers of a field with a validity mask (wavemesh.h, wm_tri_cover).
 *
 * Range scans, disparity maps and depth images have invalid samples (shadows, dropouts).  The host
 * hands the refiner a bit per sample (wm_field.mask) and heights filled in under the holes (so the
 * filter bank and the templates see a smooth surface); E(T) (tri_error.c) asks wm_tri_cover first:
 *
 *     only valid samples      ->  E(T) as without a mask
 *     only invalid samples    ->  0            (a hole: dropped by the host at the end)
 *     both, thin (D = 1)      ->  0            (no sample to split at: dropped too)
 *     both, a non-corner one  ->  0xFFFFFFFF   (every stage refines it; split at the sample chosen here)
 *
 *       o---o---x---x          o valid, x invalid: the triangle covering both is split at a valid
 *       | \ |   .   |          sample next to an invalid one (the rim), nearest its barycentre, until
 *       o---o---x---x          each triangle covers one kind, or only its three corners
 *
 * The refiner's operators are unchanged: the mesh stays a proper triangulation of the rectangle, and
 * the error bound, the reduction and the decimation never accept a triangle that covers both kinds
 * and can still be split.  The scan reads one bit per covered sample (the rim test four more).
 *
 * A thin triangle over both kinds covers no valid sample but its corners, so E(T) = 0 lets the final
 * decimation and the splits make them freely; the host drops them, and a valid corner with no other
 * triangle of three valid corners would be left in no triangle.  Two steps keep every valid sample that
 * a grid cell's triangle of three valid samples has as a corner covered (the host meshes the others as
 * invalid: wavemesh.model.holemask.stranded):
 *   wm_hole_cover, after the error bound: a valid vertex in no such triangle gets a vertex at another
 *       valid corner of such a cell, or the cell's diagonal swapped, or the thin triangles across the
 *       cell swapped away; the bound runs again;
 *   wm_hole_keeps_cover, in the final decimation: a removal may not take the last such triangle from a
 *       valid vertex (asked of each candidate within zeta when a vertex is evaluated; the removal follows
 *       at once, with the candidate that passed, so nothing changes the answer in between).
 * Motorcycle at zeta 1 (bench/bench_holes.py, measured when the decimation removed the least-cost
 * vertex first and asked the rule again as a vertex went): such samples in no kept triangle 533 -> 113
 * (the decimation's rule) -> 20 (the cover step) -> 0 (the rule asked again), triangles 13,634 -> 14,280. */
#include "wm_internal.h"

static int invalid_at(const wm_field *f, int32_t px, int32_t py)
{
    int64_t i = (int64_t)py * f->width + px;
    return (f->mask[i >> 3] >> (i & 7)) & 1;
}

int wm_hole_at(const wm_field *f, int32_t px, int32_t py) { return invalid_at(f, px, py); }

/* A valid sample with an invalid 4-neighbour. */
static int on_rim(const wm_field *f, int32_t px, int32_t py)
{
    return (px > 0 && invalid_at(f, px - 1, py)) || (px + 1 < f->width && invalid_at(f, px + 1, py)) ||
           (py > 0 && invalid_at(f, px, py - 1)) || (py + 1 < f->height && invalid_at(f, px, py + 1));
}

int wm_tri_cover(const wm_field *f, const int32_t x[3], const int32_t y[3], int32_t *sx, int32_t *sy)
{
    int64_t A[3], B[3], C[3], D = wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    int32_t ymin = y[0], ymax = y[0], xmin = x[0], xmax = x[0];
    int32_t bx = x[0] + x[1] + x[2], by = y[0] + y[1] + y[2]; /* 3 x the barycentre */
    int n_valid = 0, n_invalid = 0, best_rim = -1;
    uint64_t best_d = 0;
    int32_t cx = -1, cy = -1;
    int32_t box[4];
    wm_tri_edges(x, y, A, B, C, box);
    xmin = box[0], xmax = box[1], ymin = box[2], ymax = box[3];
    for (int32_t py = ymin; py <= ymax; py++) {
        int64_t lo = xmin, hi = xmax;
        if (!wm_row_span(A, B, C, py, &lo, &hi)) continue;
        for (int32_t px = (int32_t)lo; px <= (int32_t)hi; px++) {
            int bad = invalid_at(f, px, py), corner = 0, rim;
            uint64_t d;
            if (bad) n_invalid++;
            else n_valid++;
            if (D == 1) continue; /* thin: no candidate to split at */
            for (int k = 0; k < 3; k++) corner |= px == x[k] && py == y[k];
            if (corner) continue;
            rim = !bad && on_rim(f, px, py);
            d = (uint64_t)((int64_t)(3 * px - bx) * (3 * px - bx)) +
                (uint64_t)((int64_t)(3 * py - by) * (3 * py - by));
            if (rim > best_rim || (rim == best_rim && d < best_d)) {
                best_rim = rim;
                best_d = d;
                cx = px;
                cy = py;
            }
        }
    }
    if (n_invalid == 0) return WM_COVER_VALID;
    if (n_valid == 0) return WM_COVER_HOLE;
    if (best_rim < 0) return WM_COVER_THIN;
    if (sx) *sx = cx;
    if (sy) *sy = cy;
    return WM_COVER_MIXED;
}

int wm_hole_error(const wm_field *f, const int32_t x[3], const int32_t y[3], uint32_t *e, int32_t *wx, int32_t *wy)
{
    int32_t sx = x[0], sy = y[0];
    int c = wm_tri_cover(f, x, y, &sx, &sy);
    if (c == WM_COVER_VALID) return 0;
    *e = c == WM_COVER_MIXED ? 0xFFFFFFFFu : 0u;
    if (wx) *wx = sx;
    if (wy) *wy = sy;
    return 1;
}

/* Triangles around vertex c with three valid corners: bit 0, one with corner v; bit 1, one without.
 * At the decimation every E(T) <= zeta, so no triangle covers both kinds and can be split: three valid
 * corners mean a triangle the host keeps. */
static int kept_at(const wm_mesh *me, const wm_field *f, int32_t c, int32_t v)
{
    int32_t first = wm_fan_first(me, c), e = first, out = 0;
    do {
        const wm_he *t = me->he + 3 * WM_TRI(e);
        if (!invalid_at(f, me->vxy[t[0].v].x, me->vxy[t[0].v].y) &&
            !invalid_at(f, me->vxy[t[1].v].x, me->vxy[t[1].v].y) &&
            !invalid_at(f, me->vxy[t[2].v].x, me->vxy[t[2].v].y))
            out |= (t[0].v == v || t[1].v == v || t[2].v == v) ? 1 : 2;
        e = wm_rot_ccw(me, e);
    } while (e >= 0 && e != first);
    return out;
}

int wm_hole_keeps_cover(const wm_refiner *r, int32_t v, const int32_t *ring, int32_t n, const int32_t *tris,
                        int32_t nt)
{
    const wm_mesh *me = &r->mesh;
    const wm_field *f = &r->field;
    for (int32_t i = 0; i < n; i++) {
        int32_t c = ring[i], j;
        /* a valid ring vertex whose kept triangles all go with v must get one of the new ones */
        if (invalid_at(f, me->vxy[c].x, me->vxy[c].y) || kept_at(me, f, c, v) != 1) continue;
        for (j = 0; j < nt; j++) {
            const int32_t *t = tris + 3 * j;
            if ((t[0] == c || t[1] == c || t[2] == c) && !invalid_at(f, me->vxy[t[0]].x, me->vxy[t[0]].y) &&
                !invalid_at(f, me->vxy[t[1]].x, me->vxy[t[1]].y) &&
                !invalid_at(f, me->vxy[t[2]].x, me->vxy[t[2]].y))
                break;
        }
        if (j == nt) return 0;
    }
    return 1;
}

/* The triangle that holds sample (ax, ay), a grid neighbour of vertex s (no sample strictly between
 * them), found by walking along the segment from s; *on: the half-edge that holds it, or -1 inside.
 * -1 when the walk does not end (it cannot in a proper mesh: a safeguard). */
static int32_t locate(const wm_mesh *me, int32_t s, int32_t ax, int32_t ay, int32_t *on)
{
    int32_t sx = me->vxy[s].x, sy = me->vxy[s].y, first = wm_fan_first(me, s), e = first, t = -1, in = -1;
    do { /* the triangle of s's fan whose corner at s holds the direction to a */
        int32_t p = me->he[WM_NEXT(e)].v, q = me->he[WM_PREV(e)].v;
        if (wm_orient(sx, sy, me->vxy[p].x, me->vxy[p].y, ax, ay) >= 0 &&
            wm_orient(me->vxy[q].x, me->vxy[q].y, sx, sy, ax, ay) >= 0) {
            t = WM_TRI(e);
            break;
        }
        e = wm_rot_ccw(me, e);
    } while (e >= 0 && e != first);
    for (int32_t step = 0; t >= 0 && step < 4096; step++) {
        int32_t out = -1, outside = 0, k;
        *on = -1;
        for (k = 0; k < 3; k++) {
            int32_t h = 3 * t + k, u = me->he[h].v, v = me->he[WM_NEXT(h)].v;
            int64_t o = wm_orient(me->vxy[u].x, me->vxy[u].y, me->vxy[v].x, me->vxy[v].y, ax, ay);
            if (o == 0) *on = h;
            outside |= o < 0;
            if (o < 0 && h != in) {
                /* leave through the edge the segment s-a crosses: its ends on both sides of the line */
                int64_t ou = wm_orient(sx, sy, ax, ay, me->vxy[u].x, me->vxy[u].y);
                int64_t ov = wm_orient(sx, sy, ax, ay, me->vxy[v].x, me->vxy[v].y);
                if ((ou <= 0 && ov >= 0) || (ou >= 0 && ov <= 0)) out = h;
            }
        }
        if (out < 0) return outside ? -1 : t; /* a in t (on edge *on, or a corner: two edges hold it) */
        in = me->he[out].o;
        if (in < 0) return -1;
        t = WM_TRI(in);
    }
    return -1;
}

/* The vertex at grid sample (ax, ay), a grid neighbour of vertex s, or -1 when no vertex is there. */
static int32_t vertex_at(const wm_mesh *me, int32_t s, int32_t ax, int32_t ay)
{
    int32_t on, t = locate(me, s, ax, ay, &on);
    for (int32_t j = 0; t >= 0 && j < 3; j++)
        if (me->vxy[me->he[3 * t + j].v].x == ax && me->vxy[me->he[3 * t + j].v].y == ay)
            return me->he[3 * t + j].v;
    return -1;
}

/* Grid cell (cx, cy) with one invalid corner c, all four corners vertices and split by the diagonal
 * from c: swapped, so that the cell's triangle of three valid corners is in the mesh (both triangles
 * cover their corners alone: E(T) = 0).  1 when swapped. */
static int swap_cell(wm_refiner *r, int32_t s, int32_t cx, int32_t cy)
{
    wm_mesh *me = &r->mesh;
    int32_t bad = -1, c, first, e, touched[2], n;
    for (int32_t k = 0; k < 4; k++)
        if (invalid_at(&r->field, cx + (k & 1), cy + (k >> 1))) bad = k;
    c = vertex_at(me, s, cx + (bad & 1), cy + (bad >> 1));
    if (c < 0) return 0;
    first = wm_fan_first(me, c);
    e = first;
    do { /* the half-edge from c to the opposite corner, with the cell's two other corners beside it */
        int32_t o = me->he[WM_NEXT(e)].v, f = me->he[e].o;
        if (me->vxy[o].x == cx + 1 - (bad & 1) && me->vxy[o].y == cy + 1 - (bad >> 1) && f >= 0) {
            int32_t p = me->he[WM_PREV(e)].v, q = me->he[WM_PREV(f)].v;
            if (me->vxy[p].x < cx || me->vxy[p].x > cx + 1 || me->vxy[p].y < cy || me->vxy[p].y > cy + 1 ||
                me->vxy[q].x < cx || me->vxy[q].x > cx + 1 || me->vxy[q].y < cy || me->vxy[q].y > cy + 1 ||
                wm_edge_swap(me, e, touched, &n) != WM_OK)
                return 0;
            for (int32_t i = 0; i < n; i++) wm_touch(r, touched[i]);
            return 1;
        }
        e = wm_rot_ccw(me, e);
    } while (e >= 0 && e != first);
    return 0;
}

static int mixed_thin(const wm_mesh *me, const wm_field *f, int32_t t)
{
    const wm_he *c = me->he + 3 * t;
    int32_t x[3], y[3];
    wm_tri_xy(me, t, x, y);
    return wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]) == 1 &&
           (invalid_at(f, me->vxy[c[0].v].x, me->vxy[c[0].v].y) ||
            invalid_at(f, me->vxy[c[1].v].x, me->vxy[c[1].v].y) ||
            invalid_at(f, me->vxy[c[2].v].x, me->vxy[c[2].v].y));
}

/* The edge from vertex u to vertex w (a grid neighbour) made by swapping the edges that cross it, while
 * each swap is of two thin triangles over both kinds (doubled area 1 each: the two new ones cover their
 * corners alone, E(T) = 0, and no triangle of three valid corners goes).  The swaps made. */
static int recover_edge(wm_refiner *r, int32_t u, int32_t w)
{
    wm_mesh *me = &r->mesh;
    int32_t ux = me->vxy[u].x, uy = me->vxy[u].y, wx = me->vxy[w].x, wy = me->vxy[w].y, swaps = 0;
    for (int32_t step = 0; step < 8; step++) {
        int32_t first = wm_fan_first(me, u), e = first, h = -1, touched[2], n;
        do {
            int32_t p = me->he[WM_NEXT(e)].v, q = me->he[WM_PREV(e)].v;
            if (p == w || q == w) return swaps;
            if (wm_orient(ux, uy, me->vxy[p].x, me->vxy[p].y, wx, wy) > 0 &&
                wm_orient(me->vxy[q].x, me->vxy[q].y, ux, uy, wx, wy) > 0)
                h = WM_NEXT(e); /* the edge p-q opposite u crosses u-w */
            e = wm_rot_ccw(me, e);
        } while (e >= 0 && e != first);
        if (h < 0 || me->he[h].o < 0 || !mixed_thin(me, &r->field, WM_TRI(h)) ||
            !mixed_thin(me, &r->field, WM_TRI(me->he[h].o)) || wm_edge_swap(me, h, touched, &n) != WM_OK)
            return swaps;
        for (int32_t i = 0; i < n; i++) wm_touch(r, touched[i]);
        swaps++;
    }
    return swaps;
}

int wm_hole_cover(wm_refiner *r)
{
    wm_mesh *me = &r->mesh;
    const wm_field *f = &r->field;
    int32_t added = 0, end = me->vert_end;
    for (int32_t s = 0; s < end; s++) {
        int32_t x = me->vxy[s].x, y = me->vxy[s].y, done = 0;
        if (x == WM_FREE || invalid_at(f, x, y) || kept_at(me, f, s, -1)) continue;
        /* the grid cells with corner s and three valid corners (s among them): their valid corners */
        for (int32_t c = 0; c < 4 && !done; c++) {
            int32_t cx = x - 1 + (c & 1), cy = y - 1 + (c >> 1), n = 0;
            if (cx < 0 || cy < 0 || cx + 1 >= f->width || cy + 1 >= f->height) continue;
            for (int32_t k = 0; k < 4; k++) n += !invalid_at(f, cx + (k & 1), cy + (k >> 1));
            if (n < 3) continue;
            for (int32_t k = 0; k < 4 && !done; k++) {
                int32_t ax = cx + (k & 1), ay = cy + (k >> 1), on, t, touched[4], nt = 0, p = -1, rc;
                if ((ax == x && ay == y) || invalid_at(f, ax, ay)) continue;
                t = locate(me, s, ax, ay, &on);
                if (t < 0) continue;
                for (int32_t j = 0; j < 3; j++)
                    if (me->vxy[me->he[3 * t + j].v].x == ax && me->vxy[me->he[3 * t + j].v].y == ay) p = j;
                if (p >= 0) continue; /* a vertex already */
                rc = wm_room(r, 2);
                if (rc != 0) return rc < 0 ? rc : added; /* the budget: as the bound stops */
                rc = on < 0 ? wm_tri_split(me, t, ax, ay, touched, &nt)
                            : wm_edge_split(me, on, ax, ay, touched, &nt);
                if (rc != WM_OK) return rc == WM_ERR_CAPACITY ? rc : WM_ERR_MESH;
                int legal = !(r->params.flags & WM_FLAG_NO_LEGALISE);
                if (!legal) /* wm_legalise measures touched[] itself, after its flips */
                    for (int32_t i = 0; i < nt; i++) wm_touch(r, touched[i]);
                for (int32_t j = 0; j < 3; j++)
                    if (me->vxy[me->he[3 * touched[0] + j].v].x == ax &&
                        me->vxy[me->he[3 * touched[0] + j].v].y == ay)
                        p = me->he[3 * touched[0] + j].v;
                if (legal) wm_legalise(r, p, touched, nt, NULL);
                added++;
                done = 1;
            }
        }
        /* every such corner a vertex already: a cell with the wrong diagonal */
        for (int32_t c = 0; c < 4 && !done; c++) {
            int32_t cx = x - 1 + (c & 1), cy = y - 1 + (c >> 1), n = 0;
            if (cx < 0 || cy < 0 || cx + 1 >= f->width || cy + 1 >= f->height) continue;
            for (int32_t k = 0; k < 4; k++) n += !invalid_at(f, cx + (k & 1), cy + (k >> 1));
            if (n == 3 && swap_cell(r, s, cx, cy)) added++, done = 1;
        }
        /* or thin triangles across the cell: the edges from s to its valid cell corners swapped in */
        for (int32_t c = 0; c < 4 && !done; c++) {
            int32_t cx = x - 1 + (c & 1), cy = y - 1 + (c >> 1), n = 0;
            if (cx < 0 || cy < 0 || cx + 1 >= f->width || cy + 1 >= f->height) continue;
            for (int32_t k = 0; k < 4; k++) n += !invalid_at(f, cx + (k & 1), cy + (k >> 1));
            for (int32_t k = 0; k < 4 && n >= 3; k++) {
                int32_t ax = cx + (k & 1), ay = cy + (k >> 1), a;
                if ((ax == x && ay == y) || invalid_at(f, ax, ay) || (a = vertex_at(me, s, ax, ay)) < 0) continue;
                /* counted only when s is covered then: no kept triangle goes, so passes end */
                if (recover_edge(r, s, a) && kept_at(me, f, s, -1)) added++, done = 1;
            }
        }
    }
    return added;
}
