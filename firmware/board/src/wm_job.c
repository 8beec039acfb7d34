/*
 * The job both devices run (wm_job.h): labels and templates, the initial triangulation in caller
 * storage, the refine-and-emit loop.  Freestanding: no allocation, no stdio.
 *
 * The initial triangulation without sorting its vertices: they sit on the block lattice, where
 * lattice column 2i is block column i's left edge and 2i + 1 its middle (when the block is at least
 * 2 wide; a 1-wide last block has no middle of its own), rows likewise.  Positions grow with the
 * lattice index, so numbering the occupied lattice points row by row (a bitmap, its popcounts per
 * row) gives the canonical vertex order.  The triangles are then sorted in place a block row at a
 * time: a triangle's smallest vertex number lies on its block row's top lattice row or the one below
 * (it spans two lattice rows at least), so the block rows are already in order, and within a row the
 * triangles of each of those two lattice rows are nearly in order already (wm_job_initial).
 *
 * Staging, from the end of the caller's storage downwards:
 *
 *   mem + keep   (the caller's: the refiner's storage)
 *                (free)
 *   low          xy[2 nv]
 *                word bases of the bitmap [ncy rows of wpr words]: the points before each word
 *                the lattice bitmap [ncy rows of wpr words]
 *   mem + bytes  tris[3 nt]
 */
#include "wm_job.h"

#include <string.h>

#include "wm_memmap.h"
#include "wm_templates.h"

#define ALIGN8(n) (((size_t)(n) + 7u) & ~(size_t)7u)

/* The limits' one statement is the refiner's (wavemesh.h); host/wavemesh/limits.py reads it there and
 * protocol.py states it in the generated wm_protocol.h: checked here at compile time on both devices, so
 * that a stale generated header is caught (C99: an array of negative size). */
typedef char
    wm_job_limits_agree[WM_PROTO_MAX_SIDE == WM_MAX_SIDE && WM_PROTO_MAX_LEVELS == WM_MAX_LEVELS ? 1 : -1];

enum { KIND_FLAT = 0, KIND_VERTICAL = 1, KIND_HORIZONTAL = 2, KIND_DIAGONAL = 3 };

static int32_t block_edge(int32_t i, int32_t size, int32_t n)
{
    int64_t e = (int64_t)i * size;
    return e < n - 1 ? (int32_t)e : n - 1;
}

void wm_job_blocks_init(wm_job_blocks *b, int32_t width, int32_t height, int32_t levels)
{
    b->width = width, b->height = height, b->levels = levels, b->size = (int32_t)1 << levels;
    b->cols = (width - 1 + b->size - 1) >> levels;
    b->rows = (height - 1 + b->size - 1) >> levels;
}

/* ---- labels and templates (host/wavemesh/model/label.py) ------------------------------------------- */

int wm_job_label(const wm_job_blocks *b, uint32_t tau, const int32_t *details_m, uint32_t *entries)
{
    int32_t cols = b->cols, rows = b->rows, size = b->size;
    int32_t cw = (b->width + size - 1) >> b->levels; /* cells per row of level M */

    /* labels (3.5.1-3.5.3): dominant detail, threshold, dual sign, demotion of thin blocks */
    for (int32_t j = 0; j < rows; j++) {
        int low = block_edge(j + 1, size, b->height) - block_edge(j, size, b->height) < 2;
        for (int32_t i = 0; i < cols; i++) {
            const int32_t *c = details_m + 3 * ((int64_t)j * cw + i);
            int32_t a1 = c[0] < 0 ? -c[0] : c[0], a2 = c[1] < 0 ? -c[1] : c[1], a3 = c[2] < 0 ? -c[2] : c[2];
            int32_t top = a1 > a2 ? a1 : a2;
            int kind, sign_dual = (int64_t)c[0] * c[1] < 0, dual;
            int narrow = block_edge(i + 1, size, b->width) - block_edge(i, size, b->width) < 2;
            uint32_t label;
            top = top > a3 ? top : a3;
            if (a1 >= a2 && a1 >= a3) kind = KIND_VERTICAL;
            else if (a2 >= a3) kind = KIND_HORIZONTAL;
            else kind = KIND_DIAGONAL;
            if (!((uint32_t)top > tau)) kind = KIND_FLAT;
            dual = sign_dual && kind != KIND_DIAGONAL;
            if ((narrow && (kind == KIND_VERTICAL || kind == KIND_DIAGONAL)) ||
                (low && (kind == KIND_HORIZONTAL || kind == KIND_DIAGONAL)))
                label = (uint32_t)(KIND_FLAT << 1 | sign_dual);
            else label = (uint32_t)(kind << 1 | dual);
            entries[(int64_t)j * cols + i] = label << WM_TOUT_LABEL_SHIFT;
        }
    }

    /* variants (3.5.4): a V block splits its top and bottom sides and its neighbours' facing ones,
     * an H block its left and right sides likewise */
#define KIND(jj, ii) ((entries[(int64_t)(jj) * cols + (ii)] >> WM_TOUT_LABEL_SHIFT & WM_TOUT_LABEL_MASK) >> 1)
    for (int32_t j = 0; j < rows; j++) {
        for (int32_t i = 0; i < cols; i++) {
            uint32_t mask = 0, lab = entries[(int64_t)j * cols + i] >> WM_TOUT_LABEL_SHIFT & WM_TOUT_LABEL_MASK;
            unsigned tid;
            if (KIND(j, i) == KIND_VERTICAL || (j > 0 && KIND(j - 1, i) == KIND_VERTICAL)) mask |= WM_SIDE_TOP;
            if (KIND(j, i) == KIND_VERTICAL || (j + 1 < rows && KIND(j + 1, i) == KIND_VERTICAL))
                mask |= WM_SIDE_BOTTOM;
            if (KIND(j, i) == KIND_HORIZONTAL || (i > 0 && KIND(j, i - 1) == KIND_HORIZONTAL))
                mask |= WM_SIDE_LEFT;
            if (KIND(j, i) == KIND_HORIZONTAL || (i + 1 < cols && KIND(j, i + 1) == KIND_HORIZONTAL))
                mask |= WM_SIDE_RIGHT;
            tid = wm_template_lut[lab << 4 | mask];
            if (tid == WM_LUT_INVALID) return WM_ERR_MESH;
            entries[(int64_t)j * cols + i] |= (uint32_t)tid << WM_TOUT_TEMPLATE_SHIFT;
        }
    }
#undef KIND
    return WM_OK;
}

static unsigned template_of(const volatile uint32_t *entries, int32_t k)
{
    return entries[k] >> WM_TOUT_TEMPLATE_SHIFT & WM_TOUT_TEMPLATE_MASK;
}

int32_t wm_job_triangles(const wm_job_blocks *b, const volatile uint32_t *entries)
{
    int32_t nt = 0;
    for (int32_t k = 0; k < b->cols * b->rows; k++) {
        unsigned tid = template_of(entries, k);
        nt += tid < WM_TEMPLATE_COUNT ? wm_template_ntri[tid] : 0;
    }
    return nt;
}

/* ---- the initial triangulation (host/wavemesh/model/initial.py) -------------------------------------- */

/* The lattice of one axis: n samples in blocks of size. */
typedef struct axis {
    int32_t n, size;
} axis;

/* Lattice index of site s (0, 1, 2) of block i. */
static int32_t lattice(const axis *a, int32_t i, int s)
{
    if (s == 0) return 2 * i;
    if (s == 2) return 2 * i + 2;
    return block_edge(i + 1, a->size, a->n) - block_edge(i, a->size, a->n) >= 2 ? 2 * i + 1 : 2 * i;
}

/* Grid position of lattice index u. */
static int32_t position(const axis *a, int32_t u)
{
    int32_t i = u >> 1, x0 = block_edge(i, a->size, a->n);
    if (!(u & 1)) return x0;
    return x0 + (block_edge(i + 1, a->size, a->n) - x0) / 2;
}

static int32_t popcount(uint32_t w)
{
    w = w - (w >> 1 & 0x55555555u);
    w = (w & 0x33333333u) + (w >> 2 & 0x33333333u);
    return (int32_t)(((w + (w >> 4)) & 0x0F0F0F0Fu) * 0x01010101u >> 24);
}

/* Triangles as index triples, compared in order: the canonical order of mesh.py. */
static int tri_less(const int32_t *s, const int32_t *t)
{
    if (s[0] != t[0]) return s[0] < t[0];
    if (s[1] != t[1]) return s[1] < t[1];
    return s[2] < t[2];
}

/* Insertion sort of n triangles: a run in which each triangle lies at most a few blocks' triangles
 * from its place costs that many moves per triangle (no scratch, any input still sorted). */
static void sort_tris(int32_t *tris, int32_t n)
{
    for (int32_t i = 1; i < n; i++) {
        int32_t t[3] = {tris[3 * i], tris[3 * i + 1], tris[3 * i + 2]}, j = i;
        for (; j > 0 && tri_less(t, tris + 3 * (j - 1)); j--) {
            tris[3 * j] = tris[3 * j - 3];
            tris[3 * j + 1] = tris[3 * j - 2];
            tris[3 * j + 2] = tris[3 * j - 1];
        }
        tris[3 * j] = t[0], tris[3 * j + 1] = t[1], tris[3 * j + 2] = t[2];
    }
}

/* Template site s (0..8) is lattice column s % 3 and row s / 3 of its block (tables: the soft CPU's
 * division takes some 40 cycles, and GCC keeps it for constant divisors on rv32) */
static const uint8_t site_col[9] = {0, 1, 2, 0, 1, 2, 0, 1, 2}, site_row[9] = {0, 0, 0, 1, 1, 1, 2, 2, 2};

size_t wm_job_initial_bound(const wm_job_blocks *b, int32_t nt)
{
    size_t ncx = 2 * (size_t)b->cols + 1, ncy = 2 * (size_t)b->rows + 1, wpr = (ncx + 31) / 32;
    size_t nv = ncx * ncy < 3 * (size_t)nt ? ncx * ncy : 3 * (size_t)nt;
    return ALIGN8(12u * (size_t)nt) + 2 * ALIGN8(4u * wpr * ncy) + ALIGN8(8u * nv);
}

int wm_job_initial(const wm_job_blocks *b, const volatile uint32_t *entries, int32_t nt, void *mem, size_t bytes,
                   size_t keep, wm_job_initial_mesh *out)
{
    axis ax = {b->width, b->size}, ay = {b->height, b->size};
    int32_t cols = b->cols, rows = b->rows, ncx = 2 * cols + 1, ncy = 2 * rows + 1, wpr = (ncx + 31) / 32;
    uint8_t *base = mem, *floor = base + keep, *top = base + bytes;
    size_t tri_bytes = ALIGN8(12u * (size_t)nt), bit_bytes = ALIGN8(4u * (size_t)wpr * (size_t)ncy);
    int32_t *tris, *xy, nv = 0, n = 0;
    uint32_t *bits, *wbase;
    uint8_t used[WM_TEMPLATE_COUNT][10]; /* the sites a template uses: their count, then each */

    if (keep > bytes || bytes - keep < tri_bytes + 2 * bit_bytes) return WM_ERR_MEMORY;
    tris = (int32_t *)(void *)(top - tri_bytes);
    bits = (uint32_t *)(void *)((uint8_t *)tris - bit_bytes);
    wbase = (uint32_t *)(void *)((uint8_t *)bits - bit_bytes);
    memset(bits, 0, 4u * (size_t)wpr * (size_t)ncy);

    /* the sites each template uses */
    for (int t = 0; t < WM_TEMPLATE_COUNT; t++) {
        uint32_t mask = 0;
        for (int i = 0; i < wm_template_ntri[t]; i++)
            for (int k = 0; k < 3; k++) mask |= 1u << wm_template_tri[t][i][k];
        used[t][0] = 0;
        for (uint8_t st = 0; st < 9; st++)
            if (mask >> st & 1u) used[t][1 + used[t][0]++] = st;
    }

    /* the occupied lattice points, then their numbers (row by row: the canonical order) */
    for (int32_t jb = 0; jb < rows; jb++) {
        int32_t v[3] = {2 * jb, lattice(&ay, jb, 1), 2 * jb + 2};
        for (int32_t ib = 0; ib < cols; ib++) {
            unsigned tid = template_of(entries, jb * cols + ib);
            int32_t u[3] = {2 * ib, lattice(&ax, ib, 1), 2 * ib + 2};
            if (tid >= WM_TEMPLATE_COUNT) return WM_ERR_ARG;
            for (int i = 1; i <= used[tid][0]; i++) {
                int st = used[tid][i];
                int32_t uu = u[site_col[st]];
                bits[v[site_row[st]] * wpr + (uu >> 5)] |= 1u << (uu & 31);
            }
        }
    }
    for (int32_t w = 0; w < ncy * wpr; w++) {
        wbase[w] = (uint32_t)nv;
        nv += popcount(bits[w]);
    }
    if ((size_t)((uint8_t *)wbase - floor) < ALIGN8(8u * (size_t)nv) || (uint8_t *)wbase < floor)
        return WM_ERR_MEMORY;
    xy = (int32_t *)(void *)((uint8_t *)wbase - ALIGN8(8u * (size_t)nv));
    for (int32_t v = 0; v < ncy; v++) {
        int32_t y = position(&ay, v);
        for (int32_t u = 0; u < ncx; u++) {
            if (bits[v * wpr + (u >> 5)] >> (u & 31) & 1u) {
                xy[2 * n] = position(&ax, u);
                xy[2 * n + 1] = y;
                n++;
            }
        }
    }

    /* the triangles: vertex numbers, from the smallest (orientation kept), sorted a block row at a
     * time.  A triangle's smallest vertex lies on the row's top lattice row or the one below; those of
     * the top row fill the block row's part of tris from its front, the others from its back (then
     * turned round), each block left to right.  Within each half a triangle is at most a block's
     * triangles from its place (a block's sites span lattice columns 2 ib .. 2 ib + 2), so an insertion
     * sort finishes each in a few moves per triangle. */
    n = 0;
    for (int32_t jb = 0; jb < rows; jb++) {
        int32_t v[3] = {2 * jb, lattice(&ay, jb, 1), 2 * jb + 2}, row_nt = 0, lo, hi, mid_first;
        for (int32_t ib = 0; ib < cols; ib++) row_nt += wm_template_ntri[template_of(entries, jb * cols + ib)];
        if (row_nt > nt - n) return WM_ERR_ARG; /* nt is not these entries' count */
        lo = n, hi = n + row_nt;
        mid_first = (int32_t)wbase[(2 * jb + 1) * wpr]; /* the first number below the top lattice row */
        for (int32_t ib = 0; ib < cols; ib++) {
            unsigned tid = template_of(entries, jb * cols + ib);
            int32_t u[3] = {2 * ib, lattice(&ax, ib, 1), 2 * ib + 2}, site[9];
            for (int i = 1; i <= used[tid][0]; i++) {
                int st = used[tid][i];
                int32_t uu = u[site_col[st]], w = v[site_row[st]] * wpr + (uu >> 5);
                site[st] = (int32_t)wbase[w] + popcount(bits[w] & ((1u << (uu & 31)) - 1u));
            }
            for (int t = 0; t < wm_template_ntri[tid]; t++) {
                const uint8_t *ts = wm_template_tri[tid][t];
                int32_t i0 = site[ts[0]], i1 = site[ts[1]], i2 = site[ts[2]], *tri;
                if (i1 < i0 && i1 < i2) {
                    int32_t x = i0;
                    i0 = i1, i1 = i2, i2 = x;
                } else if (i2 < i0 && i2 < i1) {
                    int32_t x = i2;
                    i2 = i1, i1 = i0, i0 = x;
                }
                tri = i0 < mid_first ? tris + 3 * lo++ : tris + 3 * --hi;
                tri[0] = i0, tri[1] = i1, tri[2] = i2;
            }
        }
        for (int32_t i = hi, j = n + row_nt - 1; i < j; i++, j--) { /* the back half, turned round */
            int32_t *s = tris + 3 * i, *t = tris + 3 * j;
            for (int k = 0; k < 3; k++) {
                int32_t x = s[k];
                s[k] = t[k], t[k] = x;
            }
        }
        sort_tris(tris + 3 * n, lo - n);
        sort_tris(tris + 3 * hi, n + row_nt - hi);
        n += row_nt;
    }
    if (n != nt) return WM_ERR_ARG; /* nt is not these entries' count */

    out->xy = xy, out->tris = tris, out->nv = nv, out->nt = nt, out->low = (uint8_t *)xy;
    return WM_OK;
}

/* ---- the levels --------------------------------------------------------------------------------- */

void wm_job_clear(void *mem, size_t bytes)
{
    /* volatile: the stores stay stores (the board counts this job's cycles, not a libc memset's) */
    volatile uint32_t *w = mem, *end = w + bytes / 4u;
    while (end - w >= 8) {
        w[0] = 0, w[1] = 0, w[2] = 0, w[3] = 0, w[4] = 0, w[5] = 0, w[6] = 0, w[7] = 0;
        w += 8;
    }
    while (w < end) *w++ = 0;
}

size_t wm_job_mesh_bound(int32_t nv, int32_t nt)
{
    size_t mb = wm_mesh_bound(nt, nv);
    return mb == 0 ? 0 : ALIGN8(mb) + ALIGN8(12u * (size_t)nt);
}

int wm_job_emit_initial(wm_proto *p, const wm_proto_job *j, const wm_job_initial_mesh *init, void *mem,
                        size_t bytes, uint32_t *detail)
{
    wm_mesh mesh;
    wm_level_stats st;
    size_t need = wm_job_mesh_bound(init->nv, init->nt);
    int rc;
    wm_proto_initial(p, init->nv, init->nt);
    if (need == 0 || need > bytes) {
        *detail = (uint32_t)(j->levels - 1);
        return WM_PROTO_E_CAPACITY;
    }
    wm_job_clear(mem, need);
    rc = wm_mesh_init(&mesh, mem, wm_mesh_bound(init->nt, init->nv), j->width, j->height, init->nt, init->nv);
    if (rc == WM_OK)
        rc = wm_mesh_build(&mesh, init->xy, init->nv, init->tris, init->nt,
                           (uint32_t *)(void *)((uint8_t *)mem + ALIGN8(wm_mesh_bound(init->nt, init->nv))));
    if (rc != WM_OK) {
        *detail = (uint32_t)rc;
        return WM_PROTO_E_JOB;
    }
    memset(&st, 0, sizeof st);
    st.level = j->levels - 1;
    st.vertices = mesh.n_vert;
    st.triangles = mesh.n_tri;
    return wm_proto_emit_level(p, &mesh, &st, 1);
}

/* A refiner error as the protocol's code and detail. */
static int refiner_error(int lib, int32_t level, uint32_t *detail)
{
    *detail = lib == WM_ERR_CAPACITY ? (uint32_t)level : (uint32_t)lib;
    return lib == WM_ERR_CAPACITY ? WM_PROTO_E_CAPACITY : WM_PROTO_E_JOB;
}

static int refine_levels(wm_proto *p, const wm_proto_job *j, const wm_field *f, const wm_job_initial_mesh *init,
                         void *mem, size_t bytes, void *spare, uint32_t spare_bytes, uint32_t *detail)
{
    wm_refiner *r = NULL;
    wm_level_stats st;
    int rc, lib;
    wm_proto_initial(p, init->nv, init->nt);
    wm_proto_stage(p, WM_PROTO_STAGE_REFINE, j->levels - 1);
    lib = wm_refine_init(&r, mem, bytes, f, &j->params, init->xy, init->nv, init->tris, init->nt, j->capacity);
    if (lib != WM_OK) return refiner_error(lib, j->levels - 1, detail);
    /* the initial mesh is the refiner's now: its staging holds the level streams */
    wm_proto_stream_buffer(p, spare, spare_bytes);
    memset(&st, 0, sizeof st); /* wm_refine_stats fills only the counts it knows (as the host's ctypes) */
    wm_refine_stats(r, &st);
    rc = wm_proto_emit_level(p, wm_refine_mesh(r), &st, wm_refine_done(r));
    while (rc == WM_PROTO_E_NONE && !wm_refine_done(r)) {
        int32_t level = wm_refine_level(r) - 1;
        wm_proto_stage(p, WM_PROTO_STAGE_REFINE, level);
        memset(&st, 0, sizeof st);
        lib = wm_refine_step(r, &st);
        if (lib != WM_OK) return refiner_error(lib, level, detail);
        rc = wm_proto_emit_level(p, wm_refine_mesh(r), &st, wm_refine_done(r));
    }
    return rc;
}

int wm_job_refine(wm_proto *p, const wm_proto_job *j, const wm_field *f, const wm_job_initial_mesh *init,
                  void *mem, size_t bytes, void *spare, size_t spare_bytes, uint32_t *detail)
{
    int rc = refine_levels(p, j, f, init, mem, bytes, spare,
                           spare_bytes < 0xFFFFFFF0u ? (uint32_t)spare_bytes : 0xFFFFFFF0u, detail);
    wm_proto_stream_buffer(p, NULL, 0); /* the storage is the caller's again */
    return rc;
}
