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
 * decimation make them freely; the host drops them, and a valid corner with no other triangle of three
 * valid corners would be left in no triangle.  wm_hole_keeps_cover is the decimation's one extra
 * rule: a removal may not take the last such triangle from a valid vertex (Motorcycle at zeta 1:
 * valid samples a grid cell's triangle could cover but no kept triangle does, 533 -> 113, for 5 % more
 * triangles; bench/bench_holes.py). */
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
        const wm_index *t = me->hv + 3 * WM_TRI(e);
        if (!invalid_at(f, me->vx[t[0]], me->vy[t[0]]) && !invalid_at(f, me->vx[t[1]], me->vy[t[1]]) &&
            !invalid_at(f, me->vx[t[2]], me->vy[t[2]]))
            out |= (t[0] == v || t[1] == v || t[2] == v) ? 1 : 2;
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
        if (invalid_at(f, me->vx[c], me->vy[c]) || kept_at(me, f, c, v) != 1) continue;
        for (j = 0; j < nt; j++) {
            const int32_t *t = tris + 3 * j;
            if ((t[0] == c || t[1] == c || t[2] == c) && !invalid_at(f, me->vx[t[0]], me->vy[t[0]]) &&
                !invalid_at(f, me->vx[t[1]], me->vy[t[1]]) && !invalid_at(f, me->vx[t[2]], me->vy[t[2]]))
                break;
        }
        if (j == nt) return 0;
    }
    return 1;
}
