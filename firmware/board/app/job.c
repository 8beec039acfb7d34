/*
 * The board's job: the FPGA stage on the height memory, then the refiner on the soft CPU.
 *
 *   HEIGHT --soc_accel--> COEF (details of levels 1..M), TOUT (label, template id per block)
 *          --expand templates, canonical form--> initial mesh --wm_refine--> levels --engine--> host
 *
 * The coefficient memory holds the details in the layout of wm_details_offset (sign-extended 32-bit
 * words), so the refiner reads it directly as its details array, and the height memory is its
 * samples array.  The initial triangulation is host/wavemesh/initial.py's assemble(): each block's
 * template (the generated wm_templates.h) on the block's grid positions (docs/model.md, "Blocks"),
 * then the canonical form of host/wavemesh/mesh.py (vertices by (y, x), each triangle from its
 * smallest vertex, triangles sorted), the order the refiner's result depends on.
 *
 * Without malloc: the heap (the linker's __heap_start .. __heap_end) holds the refiner's storage
 * from its start and the staging of the initial triangulation from its end:
 *
 *   heap start  refiner storage: wm_refine_bound(W, H, capacity)
 *               (free)
 *               xy[2 nv], the lattice bitmap and its row bases
 *   heap end    tris[3 nt] (the packed sort keys share its upper two thirds)
 *
 * Nothing an earlier job left behind reaches a stage (its cycle counts depend only on this job): the
 * staging is written before it is read (the bitmap cleared, the row bases, xy, the keys and the
 * triangles filled in full), COEF, TOUT and HEIGHT are read only where this job's FPGA stage and
 * upload wrote them, and the storage handed to the refiner (or to the mesh of an initial-only job) is
 * cleared first: the refiner may read entries it has not written (a heap position it then checks),
 * and what such a read finds must not be the last job's data.
 *
 * Vertices sit on the block lattice: lattice column 2i is block column i's left edge, 2i + 1 its
 * middle (when the block is at least 2 wide; a 1-wide last block has no middle of its own); rows
 * likewise.  Positions grow with the lattice index, so numbering the occupied lattice points row by
 * row gives the canonical vertex order without sorting.
 */
#include "job.h"

#include <string.h>

#include "board.h"
#include "wm_memmap.h"
#include "wm_templates.h"

extern uint8_t __heap_start[], __heap_end[];

#define ALIGN8(n) (((n) + 7u) & ~(size_t)7u)
#define TAU_MAX ((1u << 18) - 1u) /* ACCEL.TAU is 18 bits; above 2^17 every block is flat anyway */

static int32_t block_edge(int32_t i, int32_t size, int32_t n) {
    int32_t e = i * size;
    return e < n - 1 ? e : n - 1;
}

/* The lattice of one axis: n samples, blocks of size, count blocks. */
typedef struct axis {
    int32_t n, size, count;
} axis;

/* Lattice index of site s (0, 1, 2) of block b. */
static int32_t lattice(const axis *a, int32_t b, int s) {
    if (s == 0) return 2 * b;
    if (s == 2) return 2 * b + 2;
    return block_edge(b + 1, a->size, a->n) - block_edge(b, a->size, a->n) >= 2 ? 2 * b + 1 : 2 * b;
}

/* Grid position of lattice index u. */
static int32_t position(const axis *a, int32_t u) {
    int32_t b = u >> 1, x0 = block_edge(b, a->size, a->n);
    if (!(u & 1)) return x0;
    return x0 + (block_edge(b + 1, a->size, a->n) - x0) / 2;
}

uint32_t board_job_capacity(size_t heap_bytes, int32_t width, int32_t height) {
    /* the worst staging of a job of cap triangles: lattice of at most cap / 2 blocks on the grid */
    uint32_t lo = 1, hi = 1u << 20;
    while (lo < hi) {
        uint32_t c = (lo + hi + 1) / 2;
        int32_t nv = wm_vert_cap_for(width, height, (int32_t)c);
        size_t need = wm_refine_bound(width, height, (int32_t)c);
        int32_t side = width > height ? width : height;
        /* lattice: at most 2 (cap/2) + 2 (cols + rows) + 1 points, rows of at most 2 side + 1 */
        size_t lat = ALIGN8(((size_t)c + 4u * (size_t)side + 1u) / 8u + 4u * (2u * (size_t)side + 1u)) +
                     ALIGN8(4u * (2u * (size_t)side + 1u));
        need = need ? ALIGN8(need) + ALIGN8(12u * (size_t)c + 4u) + ALIGN8(8u * (size_t)nv) + lat : 0;
        if (need && need <= heap_bytes) lo = c;
        else hi = c - 1;
    }
    return lo < 2 ? 0 : lo;
}

/* Zero the words of [mem, mem + bytes) (word-aligned), eight stores per turn. */
static void clear_storage(void *mem, size_t bytes) {
    volatile uint32_t *w = mem, *end = w + bytes / 4u;
    while (end - w >= 8) {
        w[0] = 0, w[1] = 0, w[2] = 0, w[3] = 0, w[4] = 0, w[5] = 0, w[6] = 0, w[7] = 0;
        w += 8;
    }
    while (w < end) *w++ = 0;
}

/* In-place heap sort of packed triangle keys. */
static void sift(uint64_t *k, int32_t root, int32_t n) {
    for (;;) {
        int32_t c = 2 * root + 1;
        uint64_t t;
        if (c >= n) return;
        if (c + 1 < n && k[c + 1] > k[c]) c++;
        if (k[root] >= k[c]) return;
        t = k[root], k[root] = k[c], k[c] = t;
        root = c;
    }
}

static void sort_keys(uint64_t *k, int32_t n) {
    for (int32_t i = n / 2 - 1; i >= 0; i--) sift(k, i, n);
    for (int32_t end = n - 1; end > 0; end--) {
        uint64_t t = k[0];
        k[0] = k[end], k[end] = t;
        sift(k, 0, end);
    }
}

/* Run the FPGA stage; 0 or -1 when it refused the configuration. */
static int run_stage(const wm_proto_job *j) {
    WM_ACCEL_WIDTH = (uint32_t)j->width;
    WM_ACCEL_HEIGHT = (uint32_t)j->height;
    WM_ACCEL_LEVELS = (uint32_t)j->levels;
    WM_ACCEL_TAU = j->tau > TAU_MAX ? TAU_MAX : j->tau;
    WM_ACCEL_CTRL = WM_ACCEL_CTRL_START;
    while (!(WM_ACCEL_STATUS & WM_ACCEL_STATUS_DONE)) {
        /* the stage owns HEIGHT, COEF and TOUT until DONE */
    }
    return WM_ACCEL_STATUS & WM_ACCEL_STATUS_ERROR ? -1 : 0;
}

#define TOUT ((volatile const uint32_t *)WM_TOUT_BASE)

int board_job(void *ctx, const wm_proto_job *j, wm_proto *p, uint32_t *detail) {
    int32_t w = j->width, h = j->height, m = j->levels, size = 1 << j->levels;
    axis ax = {w, size, (w - 1 + size - 1) >> m}, ay = {h, size, (h - 1 + size - 1) >> m};
    int32_t cols = ax.count, rows = ay.count, ncx = 2 * cols + 1, ncy = 2 * rows + 1;
    int32_t wpr = (ncx + 31) / 32, nt = 0, nv = 0, lib;
    int initial_only = (j->flags & WM_PROTO_CONFIG_INITIAL_ONLY) != 0;
    uint8_t *heap = __heap_start, *top = __heap_end;
    size_t main_bytes;
    uint32_t *bits, *rowbase;
    int32_t *xy, *tris;
    uint64_t *keys;
    wm_level_stats st;
    wm_refiner *r = NULL;
    int rc;
    (void)ctx;

    /* every block has at least two triangles: a grid with more blocks cannot fit (as the native
     * device, which finds out after assembling them) */
    if ((int64_t)cols * rows > WM_TOUT_ENTRIES || 2 * (int64_t)cols * rows > j->capacity) {
        *detail = (uint32_t)(m - 1);
        return WM_PROTO_E_CAPACITY;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_FILTER, m);
    if (run_stage(j) != 0) {
        *detail = (uint32_t)WM_ERR_ARG;
        return WM_PROTO_E_JOB;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_TEMPLATE, m);
    for (int32_t b = 0; b < cols * rows; b++) nt += wm_template_ntri[TOUT[b] & WM_TOUT_TEMPLATE_MASK];
    if (nt > j->capacity) {
        *detail = (uint32_t)(m - 1);
        return WM_PROTO_E_CAPACITY;
    }

    /* staging from the heap's end: tris (keys inside), then the bitmap and its row bases */
    tris = (int32_t *)(void *)(top - ALIGN8(12u * (size_t)nt + 4u));
    keys = (uint64_t *)(void *)((uint8_t *)tris + 4u * (size_t)(nt + (nt & 1)));
    bits = (uint32_t *)(void *)((uint8_t *)tris - ALIGN8(4u * (size_t)wpr * (size_t)ncy));
    rowbase = (uint32_t *)(void *)((uint8_t *)bits - ALIGN8(4u * (size_t)ncy));
    main_bytes = initial_only ? 0 : wm_refine_bound(w, h, j->capacity);
    if ((uint8_t *)rowbase < heap + ALIGN8(main_bytes)) {
        *detail = (uint32_t)(m - 1);
        return WM_PROTO_E_CAPACITY;
    }
    memset(bits, 0, 4u * (size_t)wpr * (size_t)ncy);

    /* the occupied lattice points, then their numbers (row by row: the canonical order) */
    for (int32_t jb = 0; jb < rows; jb++) {
        for (int32_t ib = 0; ib < cols; ib++) {
            unsigned tid = TOUT[jb * cols + ib] & WM_TOUT_TEMPLATE_MASK;
            for (int t = 0; t < wm_template_ntri[tid]; t++) {
                for (int k = 0; k < 3; k++) {
                    int s = wm_template_tri[tid][t][k];
                    int32_t u = lattice(&ax, ib, s % 3), v = lattice(&ay, jb, s / 3);
                    bits[v * wpr + (u >> 5)] |= 1u << (u & 31);
                }
            }
        }
    }
    for (int32_t v = 0; v < ncy; v++) {
        rowbase[v] = (uint32_t)nv;
        for (int32_t q = 0; q < wpr; q++) nv += __builtin_popcount(bits[v * wpr + q]);
    }
    xy = (int32_t *)(void *)((uint8_t *)rowbase - ALIGN8(8u * (size_t)nv));
    if ((uint8_t *)xy < heap + ALIGN8(main_bytes)) {
        *detail = (uint32_t)(m - 1);
        return WM_PROTO_E_CAPACITY;
    }
    {
        int32_t n = 0;
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
    }

    /* the triangles: vertex numbers, from the smallest (orientation kept), as packed keys */
    {
        int32_t n = 0;
        for (int32_t jb = 0; jb < rows; jb++) {
            for (int32_t ib = 0; ib < cols; ib++) {
                unsigned tid = TOUT[jb * cols + ib] & WM_TOUT_TEMPLATE_MASK;
                for (int t = 0; t < wm_template_ntri[tid]; t++) {
                    uint32_t id[3], a, b, c;
                    for (int k = 0; k < 3; k++) {
                        int s = wm_template_tri[tid][t][k];
                        int32_t u = lattice(&ax, ib, s % 3), v = lattice(&ay, jb, s / 3);
                        const uint32_t *row = bits + v * wpr;
                        uint32_t below = rowbase[v];
                        for (int32_t q = 0; q < (u >> 5); q++) below += (uint32_t)__builtin_popcount(row[q]);
                        below += (uint32_t)__builtin_popcount(row[u >> 5] & ((1u << (u & 31)) - 1u));
                        id[k] = below;
                    }
                    a = id[0], b = id[1], c = id[2];
                    if (b < a && b < c) a = id[1], b = id[2], c = id[0];
                    else if (c < a && c < b) a = id[2], b = id[0], c = id[1];
                    keys[n++] = (uint64_t)a << 32 | (uint64_t)b << 16 | c;
                }
            }
        }
        sort_keys(keys, nt);
        for (int32_t t = 0; t < nt; t++) {
            uint64_t key = keys[t]; /* read before tris[3t..] may overwrite it */
            tris[3 * t] = (int32_t)(key >> 32);
            tris[3 * t + 1] = (int32_t)(key >> 16 & 0xFFFFu);
            tris[3 * t + 2] = (int32_t)(key & 0xFFFFu);
        }
    }

    if (initial_only) {
        /* the initial triangulation alone, as a mesh: storage and build scratch from the heap */
        wm_mesh mesh;
        size_t mb = wm_mesh_bound(nt, nv);
        uint32_t *scratch = (uint32_t *)(void *)(heap + ALIGN8(mb));
        if (mb == 0 || (uint8_t *)(scratch + 3 * nt) > (uint8_t *)xy) {
            *detail = (uint32_t)(m - 1);
            return WM_PROTO_E_CAPACITY;
        }
        clear_storage(heap, (size_t)((uint8_t *)(scratch + 3 * nt) - heap));
        rc = wm_mesh_init(&mesh, heap, mb, w, h, nt, nv);
        if (rc == WM_OK) rc = wm_mesh_build(&mesh, xy, nv, tris, nt, scratch);
        if (rc != WM_OK) {
            *detail = (uint32_t)rc;
            return WM_PROTO_E_JOB;
        }
        memset(&st, 0, sizeof st);
        st.level = m - 1;
        st.vertices = mesh.n_vert;
        st.triangles = mesh.n_tri;
        return wm_proto_emit_level(p, &mesh, &st, 1);
    }

    wm_proto_stage(p, WM_PROTO_STAGE_REFINE, m - 1);
    clear_storage(heap, ALIGN8(main_bytes)); /* (below the staging: checked above) */
    {
        wm_field f = {w, h, m, (const uint16_t *)WM_HEIGHT_BASE, (const int32_t *)WM_COEF_BASE};
        lib = wm_refine_init(&r, heap, main_bytes, &f, &j->params, xy, nv, tris, nt, j->capacity);
    }
    if (lib != WM_OK) {
        *detail = lib == WM_ERR_CAPACITY ? (uint32_t)(m - 1) : (uint32_t)lib;
        return lib == WM_ERR_CAPACITY ? WM_PROTO_E_CAPACITY : WM_PROTO_E_JOB;
    }
    memset(&st, 0, sizeof st);
    wm_refine_stats(r, &st);
    rc = wm_proto_emit_level(p, wm_refine_mesh(r), &st, wm_refine_done(r));
    while (rc == WM_PROTO_E_NONE && !wm_refine_done(r)) {
        int32_t level = wm_refine_level(r) - 1;
        wm_proto_stage(p, WM_PROTO_STAGE_REFINE, level);
        memset(&st, 0, sizeof st);
        lib = wm_refine_step(r, &st);
        if (lib != WM_OK) {
            *detail = lib == WM_ERR_CAPACITY ? (uint32_t)level : (uint32_t)lib;
            return lib == WM_ERR_CAPACITY ? WM_PROTO_E_CAPACITY : WM_PROTO_E_JOB;
        }
        rc = wm_proto_emit_level(p, wm_refine_mesh(r), &st, wm_refine_done(r));
    }
    return rc;
}
