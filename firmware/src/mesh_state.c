/* The refiner's mesh state under every phase: what an operator's caller does after changing the mesh.
 * E(T) of a made or changed triangle again (wm_touch), the room an operation needs (wm_room), the
 * error bound's heap (wm_heap_update) and the legalisation after a split (wm_legalise).  The phases
 * (refine.c's level loop and error bound, pairing.c, holes.c, reduce.c, decimate.c) call down into
 * here; nothing here calls a phase. */
#include "wm_internal.h"

void wm_touch(wm_refiner *r, int32_t t)
{
    int32_t x[3], y[3], wx, wy;
    wm_tri_xy(&r->mesh, t, x, y);
    r->err[t] = r->roi ? wm_roi_error(r, x, y, &wx, &wy) : wm_tri_error(&r->field, &r->params, x, y, &wx, &wy);
    r->worst[t] = wy * r->field.width + wx;
    r->mesh.tflag[t] |= WM_F_NEW;
    wm_forget_class(r, t);
}

/* wm_touch in the error bound (its legalisation's slots), without forgetting classes: a triangle that
 * the scan's Vmax alone shows within zeta leaves the heap without its exact E(T) (no slope factor):
 * err[t] = its vertical ev, an upper bound, and WM_F_MEASURE.  Nothing in the bound or the decimation
 * reads the E(T) of a triangle within zeta, and most of them go again in a later split's flips or a
 * removal; wm_settle measures those left at the end as far as E_max needs them.  With a holes mask or a
 * region of interest (masked: the caller's r->roi || r->field.mask), wm_touch. */
static WM_ALWAYS_INLINE uint32_t touch_bound(wm_refiner *r, int32_t t, int masked)
{
    int32_t x[3], y[3], wx, wy, D;
    int exact;
    uint32_t e;
    WM_ASSERT(masked == (r->roi || r->field.mask));
    if (masked) {
        wm_touch(r, t);
        return r->err[t];
    }
    wm_tri_xy(&r->mesh, t, x, y);
    D = (int32_t)wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]);
    if (D == 1) {
        /* twice the area 1 (a third of the error bound's measures on Jacksboro / 4): no sample but the
         * corners, so wm_tri_error_over's answer without its call: ev 0 at corner 0, not exact */
#if WM_CHECK
        int32_t cx, cy, ce;
        WM_ASSERT(wm_tri_error_over(&r->field, &r->params, x, y, 1, &cx, &cy, &ce) == 0 && ce == 0 && cx == x[0] &&
                  cy == y[0]);
#endif
        WM_PROF_ADD(WM_PC_SCANS, 1); /* scan_any's count */
        e = 0, exact = 0, wx = x[0], wy = y[0];
    } else {
        e = wm_tri_error_over(&r->field, &r->params, x, y, D, &wx, &wy, &exact);
    }
    r->err[t] = e;
    r->worst[t] = wy * r->field.width + wx;
    /* The flags written, not read first: after the levels no flag but WM_F_MEASURE is read (wm_settle;
     * the decimation sets it), so the levels' marks go.  Not wm_forget_class: no reduction follows the
     * bound (level 0's comes before it), the decimation writes a vertex's vapex before it reads it, and
     * pos[] is the heap's (swept is 0). */
    r->mesh.tflag[t] = (uint8_t)(WM_F_NEW | (exact ? 0 : WM_F_MEASURE));
    return e;
}

void wm_settle(wm_refiner *r, wm_level_stats *st)
{
    wm_mesh *me = &r->mesh;
    uint32_t known = 0, *err = r->err, zeta = r->params.zeta;
    int32_t over = 0; /* the live slots with err[] over zeta */
    const wm_he *he = me->he;
    uint8_t *tflag = me->tflag;
    /* taken once, not at each slot: a store to tflag[] might have changed them, for all the compiler
     * knew (on the board four loads and two branches a slot) */
    int masked = r->roi || r->field.mask;
    int32_t end = me->tri_end;
    /* E_max is the largest E(T).  In slot order: known, the largest E(T) so far, and each flagged
     * triangle whose upper bound is above it measured only as far as that (wm_tri_error_upto: E(T)
     * when above it, else at most it), one pass.  So err[] holds E(T) or an upper bound at most E_max,
     * their largest is E_max, and the count over zeta is unchanged (every flagged triangle is within
     * zeta).  known ends as the largest err[] of a live slot, E_max, and over counts the live slots over
     * zeta (only unflagged slots or a masked job's can be: a flagged slot's bound is within zeta), what
     * wm_refine_stats would read every slot's he[] again for. */
    for (int32_t t = 0; t < end; t++) {
        int32_t x[3], y[3], wx, wy;
        uint8_t f = tflag[t];
        if (!(f & WM_F_MEASURE)) {
            if (he[3 * t].v >= 0) {
                uint32_t e = err[t];
                if (e > known) known = e;
                over += e > zeta;
            }
            continue;
        }
        f &= (uint8_t)~WM_F_MEASURE;
        /* A flagged slot's err[] was written with its flag (touch_bound, the decimation), live or dead
         * since; one within known keeps its bound without reading he[] (whether it is live: on the board
         * each slot's he[] was a refill of its own, 24 bytes a slot, err[] one for eight slots).  Its
         * WM_F_NEW then also on a dead slot: the flags are scratch (wm_tri_take clears a slot's), and
         * nothing reads them after this, the job's last step. */
        if (!masked && err[t] <= known) {
            WM_ASSERT(err[t] <= zeta);
            tflag[t] = (uint8_t)(f | WM_F_NEW);
#if WM_CHECK
            if (he[3 * t].v >= 0) {
                wm_tri_xy(me, t, x, y);
                WM_ASSERT(wm_tri_error(&r->field, &r->params, x, y, &wx, &wy) <= known);
            }
#endif
            continue;
        }
        if (he[3 * t].v < 0) {
            tflag[t] = f;
            continue;
        }
        tflag[t] = (uint8_t)(f | WM_F_NEW);
        /* the corners read only for a scan: most flagged triangles are within known and keep their bound
         * (on the board each corner's vxy[] is likely an SDRAM refill: random vertices) */
        if (masked) { /* as wm_touch, without forgetting the corners' classes */
            wm_tri_xy(me, t, x, y);
            err[t] =
                r->roi ? wm_roi_error(r, x, y, &wx, &wy) : wm_tri_error(&r->field, &r->params, x, y, &wx, &wy);
            r->worst[t] = wy * r->field.width + wx;
            if (err[t] > known) known = err[t];
            over += err[t] > zeta;
        } else if (err[t] > known) {
            WM_ASSERT(err[t] <= zeta);
            wm_tri_xy(me, t, x, y);
            err[t] = wm_tri_error_upto(&r->field, &r->params, x, y, r->params.zeta, known, NULL);
            if (err[t] > known) known = err[t];
        }
#if WM_CHECK
        if (!masked) {
            wm_tri_xy(me, t, x, y);
            WM_ASSERT(wm_tri_error(&r->field, &r->params, x, y, &wx, &wy) <= known);
        }
#endif
    }
    st->e_max = known;
    st->over = over;
}

int wm_room(wm_refiner *r, int32_t added)
{
    if (r->mesh.n_tri + added <= r->limit) return 0;
    if (r->limit_is_budget) {
        r->budget_hit = 1;
        return 1;
    }
    return WM_ERR_CAPACITY;
}

/* The error bound: a max-heap of the triangles with E(T) > zeta, by E(T) and then by slot (a total
 * order: any heap pops them in the same order).  Each entry holds its slot's key (wm_hent: E(T), equal
 * to err[t] at every step, since every E(T) the error bound measures is filed at once), so a sift reads
 * the entries alone, both children in 16 bytes (wm_internal.h); the item filed comes with its key
 * (just measured: on the board the load of err[] after its store would wait for the SDRAM, the data
 * cache not allocating on a write).  pos[] is exact in the error bound (-1 for every slot out of the
 * heap, error_bound), so pos[t] alone says whether t is in the heap. */

/* The heap's operations (wm_internal.h), the largest key first. */
static int heap_up(wm_refiner *r, int32_t i, int32_t t, uint32_t e)
{
    WM_ASSERT(e == r->err[t]);
    return wm_heap_up(wm_heap_entries(r), r->pos, i, e, t);
}

static void heap_down(wm_refiner *r, int32_t i, int32_t n, int32_t t, uint32_t e)
{
    WM_ASSERT(e == r->err[t]);
    wm_heap_down(wm_heap_entries(r), r->pos, i, n, e, t);
}

#if WM_CHECK
/* The order holds around the entry at i: its parent is before it, it is before its children; the keys
 * are their slots' E(T). */
static int heap_holds_at(const wm_refiner *r, int32_t i, int32_t n)
{
    const wm_hent *h = wm_heap_entries(r);
    int32_t t = h[i].t, p = (i - 1) / 2;
    if (r->pos[t] != i || h[i].key != r->err[t]) return 0;
    if (i > 0 && !wm_heap_before(h[p].key, h[p].t, h[i].key, t)) return 0;
    for (int32_t c = 2 * i + 1; c <= 2 * i + 2 && c < n; c++)
        if (!wm_heap_before(h[i].key, t, h[c].key, h[c].t) || h[c].key != r->err[h[c].t]) return 0;
    return 1;
}
#endif

/* Entry t, at i, out of the heap. */
static void heap_remove(wm_refiner *r, int32_t t, int32_t i, int32_t *n)
{
    wm_hent *h = wm_heap_entries(r);
    int32_t moved = h[--(*n)].t; /* the last entry, moved into i's place */
    WM_ASSERT(h[i].t == t);
    (void)t;
    wm_heap_remove(h, r->pos, i, *n);
    WM_ASSERT(i == *n || heap_holds_at(r, r->pos[moved], *n));
    (void)moved;
}

void wm_heap_update(wm_refiner *r, int32_t t, uint32_t e, int32_t i, int32_t *n)
{
    WM_ASSERT(i == r->pos[t]);
    WM_ASSERT(e == r->err[t] && (i == -1 || (i >= 0 && i < *n && wm_heap_entries(r)[i].t == t)));
    if (e <= r->params.zeta) {
        if (i >= 0) heap_remove(r, t, i, n);
    } else if (i >= 0) {                                      /* in place: (E(T), slot) orders totally */
        /* the entry's own key says which way it moves: a smaller one cannot pass its parent (before the
         * old key, so before the new), a larger one no child (after the old); an equal key stays (the
         * same places as the sifts' both ways, without the parent's or the children's loads) */
        uint32_t old = wm_heap_entries(r)[i].key;
        if (e < old) heap_down(r, i, *n, t, e);
        else if (e > old) heap_up(r, i, t, e);
        WM_ASSERT(heap_holds_at(r, r->pos[t], *n));
    } else {
        heap_up(r, (*n)++, t, e);
        WM_ASSERT(heap_holds_at(r, r->pos[t], *n));
    }
}

/* Legalisation after inserting p (Lawson; hmm's design).  An edge a -> b opposite p, in triangle
 * (a, b, p), is flipped when the far vertex d of the triangle across it lies strictly inside the
 * circle through a, b, p; the two edges that then face p are examined in turn.
 *
 *          p                     p
 *         / \                   /|\
 *        a---b       ->        a | b
 *         \ /                   \|/
 *          d                     d
 *
 * Each flip makes p adjacent to one more vertex, so the loop ends; the stack is bounded and an edge
 * that does not fit is simply left as it is (the mesh stays proper either way). */
#define LEGAL_STACK 64

/* The room of wm_legalise's list of slots to measure: LEGAL_STACK, but 4 in checked builds, so that
 * their runs take the path past it (a split lists 2 to 4 slots, each flip one more), and the tests
 * that compare their meshes with the release library's check that path too: a release run reaches it
 * only after some 60 flips around one vertex, which no test or known job makes. */
#if WM_CHECK
#define LEGAL_SLOTS 4
#else
#define LEGAL_SLOTS LEGAL_STACK
#endif

/* A slot legalisation changed, measured: in the error bound (heap_n) touch_bound and the heap, else
 * wm_touch.  Every such slot takes this one path, so none that touch_bound left flagged is measured
 * exactly with its flag kept (wm_settle would take an E(T) over zeta there for a bound within it).
 * masked: r->roi || r->field.mask, taken once a legalisation (on the board the two loads and the branch
 * on them stalled every slot: a store to err[] or tflag[] might have changed them, for all the compiler
 * knew). */
#define PLACE_UNKNOWN (-2)
static WM_ALWAYS_INLINE void measure_slot(wm_refiner *r, int32_t t, int32_t *heap_n, int masked, int32_t place)
{
    if (heap_n) {
        uint32_t e = touch_bound(r, t, masked);
        /* t's heap place (pos[t]) when the caller does not know it: on the board a load of pos[] is most
         * often a refill, and a split's new slots are in no heap and its first is the top */
        int32_t i = place == PLACE_UNKNOWN ? r->pos[t] : place;
        /* within zeta and in no heap (most new triangles): wm_heap_update would do nothing */
        if (e > r->params.zeta || i >= 0) wm_heap_update(r, t, e, i, heap_n);
    } else {
        wm_touch(r, t);
    }
}

/* A slot legalisation changed: E(T) is measured once, at the end, for the triangle the slot then
 * holds (a split's triangle that a flip replaces at once was scanned for nothing: a third of the error
 * bound's scans).  Past the list's room, at once.  The list is the split's slots (touched[0..n)) and
 * then each flip's second (list[0..*ns)): they hold p's triangles, so while it has room a flip's first
 * slot is in it already (it held p) and its second is not (it did not), and wm_legalise appends that one
 * without a search. */
static void changed(wm_refiner *r, const int32_t *touched, int32_t n, int32_t *list, int32_t *ns, int32_t t,
                    int32_t *heap_n, int masked)
{
    for (int32_t i = 0; i < n; i++)
        if (touched[i] == t) return;
    for (int32_t i = 0; i < *ns; i++)
        if (list[i] == t) return;
    if (n + *ns < LEGAL_SLOTS) {
        list[(*ns)++] = t;
        return;
    }
    measure_slot(r, t, heap_n, masked, PLACE_UNKNOWN);
}

void wm_legalise(wm_refiner *r, int32_t p, const int32_t *touched, int32_t n, int32_t *heap_n)
{
    wm_mesh *me = &r->mesh;
    /* the stack's edges (half-edges opposite p), their triangle divided out only for a flip; slots[] the
     * flips' second slots, after the split's (touched[], distinct, at most 4 = LEGAL_SLOTS at the least)
     * in the list of slots to measure */
    int32_t stack[LEGAL_STACK], top = 0, slots[LEGAL_STACK], ns = 0, early = 0;
    int masked = r->roi || r->field.mask;
    /* the arrays and p's corner in registers: a flip stores through me's arrays, so the compiler (for
     * all it knew, the stores might change them) loaded the four pointers and xy[p].x, xy[p].y again at
     * every edge; a flip changes no vertex and no pointer */
    const wm_he *he = me->he;
    const wm_xy *xy = me->vxy;
    int32_t px = xy[p].x, py = xy[p].y;
    WM_ASSERT(n == 2 || n == 3 || n == 4);
    for (int32_t i = 0; i < n; i++) {
        int32_t t = touched[i];
        /* p's corner in a split's triangles (wm_tri_split: 2 in each; wm_edge_split: 1, 0, 1, 0), and the
         * edge opposite it, 3 t + k from corner k to corner k + 1 (wm_dest), the one after p's corner */
        int32_t k = n == 3 ? 0 : (i & 1 ? 1 : 2);
        WM_ASSERT(me->he[3 * t + (k == 0 ? 2 : k - 1)].v == p && me->he[3 * t + k].v != p &&
                  me->he[3 * t + (k == 2 ? 0 : k + 1)].v != p);
        stack[top++] = 3 * t + k; /* n <= 4 < LEGAL_STACK */
    }
    while (top > 0) {
        int32_t e = stack[--top], o = he[e].o, a, b, d, t1, t2, ko, ax, ay, bx, by, dx, dy;
        int64_t sa, sb;
        /* e's triangle still holds p: a flip changes the popped triangle and the one across its edge, which
         * does not hold p (two triangles of the same three corners cannot both be counter-clockwise), and
         * a stacked triangle holds p, each on the stack once */
        WM_ASSERT(he[WM_PREV(e)].v == p);
        if (o < 0) continue;
        t2 = (int32_t)((uint32_t)o / 3u); /* WM_TRI(o), o >= 0: unsigned */
        ko = o - 3 * t2;
        a = he[e].v;
        b = he[o].v;
        WM_ASSERT(WM_PREV(o) == (ko == 0 ? o + 2 : o - 1));
        d = he[ko == 0 ? o + 2 : o - 1].v;
        ax = xy[a].x, ay = xy[a].y, bx = xy[b].x, by = xy[b].y, dx = xy[d].x, dy = xy[d].y;
        if (!wm_flip_circle(ax, ay, bx, by, px, py, dx, dy)) continue;
        /* wm_quad_convex(me, a, b, p, d) (wm_edge_swappable's test) from the corners at hand */
        sa = wm_orient(px, py, dx, dy, ax, ay);
        sb = wm_orient(px, py, dx, dy, bx, by);
        WM_ASSERT(((sa > 0 && sb < 0) || (sa < 0 && sb > 0)) == wm_quad_convex(me, a, b, p, d));
        if (!((sa > 0 && sb < 0) || (sa < 0 && sb > 0))) continue;
        t1 = (int32_t)((uint32_t)e / 3u);
        wm_edge_flip(me, e, o, t1, t2, a, b, p, d); /* T1 = (a, d, p), T2 = (d, b, p) in the same slots */
        if (n + ns < LEGAL_SLOTS) {
#if WM_CHECK
            int in1 = 0, in2 = 0;
            for (int32_t i = 0; i < n; i++) in1 |= touched[i] == t1, in2 |= touched[i] == t2;
            for (int32_t i = 0; i < ns; i++) in1 |= slots[i] == t1, in2 |= slots[i] == t2;
            WM_ASSERT(in1 && !in2);
#endif
            slots[ns++] = t2;
        } else {
            changed(r, touched, n, slots, &ns, t1, heap_n, masked);
            changed(r, touched, n, slots, &ns, t2, heap_n, masked);
            early = 1;
        }
        r->flips++;
        if (top + 2 <= LEGAL_STACK) { /* edges 3 t1 and 3 t2: a -> d and d -> b, opposite p */
            stack[top++] = 3 * t1;
            stack[top++] = 3 * t2;
        }
    }
    /* The heap orders by (E(T), slot), a total order, so filing the slots now rather than flip by
     * flip pops the same triangles in the same order.  Of the split's slots the first is the error
     * bound's top (place 0), unless a slot past the list's room was filed already (changed), and the
     * others are new (pos[] -1, error_bound) but wm_edge_split's T2 (the third). */
    for (int32_t i = 0; i < n + ns; i++) {
        int32_t place = i >= n || (i == 2 && n == 4) ? PLACE_UNKNOWN : (i > 0 ? -1 : (early ? PLACE_UNKNOWN : 0));
        measure_slot(r, i < n ? touched[i] : slots[i - n], heap_n, masked, place);
    }
}
