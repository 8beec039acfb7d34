/*
 * The board's job: the FPGA stage on the height memory, then the job library (wm_job.h) on the soft
 * CPU.
 *
 *   HEIGHT --soc_accel--> COEF (details of levels 1..M), TOUT (label, template id per block)
 *          --wm_job_initial--> initial mesh --wm_job_refine--> levels --engine--> host
 *
 * The coefficient memory holds the details in the layout of wm_details_offset (sign-extended 32-bit
 * words), so the refiner reads it directly as its details array, the height memory is its samples
 * array, and TOUT's entries are the template entries wm_job_initial takes.
 *
 * Without malloc: the heap (the linker's __heap_start .. __heap_end) holds the refiner's storage
 * from its start (wm_refine_bound(W, H, capacity)) and the staging of the initial triangulation from
 * its end (wm_job_initial).
 *
 * Nothing an earlier job left behind reaches a stage (its cycle counts depend only on this job): the
 * staging is written before it is read, COEF, TOUT and HEIGHT are read only where this job's FPGA
 * stage and upload wrote them, the refiner writes every entry of its storage before it reads it (so
 * that storage is not cleared: valgrind's memcheck on the native runner, tests/firmware), and the
 * storage of an initial-only job's mesh is cleared first (wm_job_emit_initial).
 */
#include "board_job.h"

#include "board.h"
#include "wm_job.h"
#include "wm_memmap.h"

void wm_tri_engine_forget(void); /* src/tri_engine.c (the refiner's library) */

extern uint8_t __heap_start[], __heap_end[];

#define ALIGN8(n) (((n) + 7u) & ~(size_t)7u)

#define MASK_BYTES (2u * ((WM_GRID_MAX_W * WM_GRID_MAX_H + 15u) / 16u))

size_t board_heap_bytes(void) { return (size_t)(__heap_end - __heap_start) - MASK_BYTES; }
uint8_t *board_mask(void) { return __heap_start + board_heap_bytes(); }
uint32_t board_mask_bytes(void) { return MASK_BYTES; }

uint32_t board_job_capacity(size_t heap_bytes, int32_t width, int32_t height)
{
    /* the worst staging of a job of cap triangles: lattice of at most cap / 2 blocks on the grid */
    uint32_t lo = 1, hi = 1u << 20;
    while (lo < hi) {
        uint32_t c = (lo + hi + 1) / 2;
        int32_t nv = wm_vert_cap_for(width, height, (int32_t)c);
        size_t need = wm_refine_bound(width, height, (int32_t)c);
        int32_t side = width > height ? width : height;
        /* lattice: at most 2 (cap/2) + 2 (cols + rows) + 1 points, rows of at most 2 side + 1; the
         * bitmap and its word bases (as many words) */
        size_t lat = 2 * ALIGN8(((size_t)c + 4u * (size_t)side + 1u) / 8u + 4u * (2u * (size_t)side + 1u));
        need = need ? ALIGN8(need) + ALIGN8(12u * (size_t)c + 4u) + ALIGN8(8u * (size_t)nv) + lat : 0;
        if (need && need <= heap_bytes) lo = c;
        else hi = c - 1;
    }
    return lo < 2 ? 0 : lo;
}

/* Run the FPGA stage; 0 or -1 when it refused the configuration. */
static int run_stage(const wm_proto_job *j)
{
    WM_ACCEL_WIDTH = (uint32_t)j->width;
    WM_ACCEL_HEIGHT = (uint32_t)j->height;
    WM_ACCEL_LEVELS = (uint32_t)j->levels;
    WM_ACCEL_TAU = j->tau; /* <= WM_PROTO_TAU_MAX, the register's 18 bits: the engine checked CONFIG */
    WM_ACCEL_CTRL = WM_ACCEL_CTRL_START;
    while (!(WM_ACCEL_STATUS & WM_ACCEL_STATUS_DONE)) {
        /* the stage owns HEIGHT, COEF and TOUT until DONE */
    }
    board_dcache_flush(); /* the CPU reads COEF and TOUT next: what the stage wrote, not old lines */
    return WM_ACCEL_STATUS & WM_ACCEL_STATUS_ERROR ? -1 : 0;
}

#define TOUT ((volatile const uint32_t *)WM_TOUT_BASE)

int board_job(void *ctx, const wm_proto_job *job, wm_proto *p, uint32_t *detail)
{
    /* The refiner's storage holds no more triangles than a triangulation of all the grid's samples
     * (wm_tri_cap_max): with the SDRAM's heap the device's capacity is some 400k triangles, and a
     * small job's storage is laid out for the grid's instead, a few hundred more by wm_tri_cap_skewed
     * (the vertex arrays vh and vxy off a multiple of the caches' size apart; the staging of the initial
     * mesh above it starts lower).  The refiner cannot reach either limit, so the mesh is the same. */
    wm_proto_job jc = *job;
    const wm_proto_job *j = &jc;
    int32_t m = j->levels, nt;
    int initial_only = (j->flags & WM_PROTO_CONFIG_INITIAL_ONLY) != 0;
    uint8_t *heap = __heap_start;
    size_t heap_bytes = board_heap_bytes(); /* the mask's storage above it */
    size_t main_bytes;
    int32_t grid_cap = wm_tri_cap_max(j->width, j->height);
    if (grid_cap >= 2 && grid_cap < jc.capacity)
        jc.capacity = wm_tri_cap_skewed(j->width, j->height, grid_cap, jc.capacity);
    main_bytes = initial_only ? 0 : wm_refine_bound(j->width, j->height, j->capacity);
    wm_job_blocks b;
    wm_job_initial_mesh init;
    (void)ctx;

    /* every block has at least two triangles: a grid with more blocks cannot fit (as the native
     * device, which finds out after labelling them) */
    wm_job_blocks_init(&b, j->width, j->height, m);
    if ((int64_t)b.cols * b.rows > WM_TOUT_ENTRIES || 2 * (int64_t)b.cols * b.rows > j->capacity) {
        *detail = (uint32_t)(m - 1);
        return WM_PROTO_E_CAPACITY;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_FILTER, m);
    if (run_stage(j) != 0) {
        *detail = (uint32_t)WM_ERR_ARG;
        return WM_PROTO_E_JOB;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_TEMPLATE, m);
    nt = wm_job_triangles(&b, TOUT);
    if (nt > j->capacity || wm_job_initial(&b, TOUT, nt, heap, heap_bytes, ALIGN8(main_bytes), &init) != WM_OK) {
        *detail = (uint32_t)(m - 1);
        return WM_PROTO_E_CAPACITY;
    }
    if (initial_only) return wm_job_emit_initial(p, j, &init, heap, (size_t)(init.low - heap), detail);
    {
        wm_field f = {j->width, j->height, m, (const uint16_t *)WM_HEIGHT_BASE, (const int32_t *)WM_COEF_BASE,
                      j->mask};
        wm_tri_engine_forget(); /* the engine's registers hold the last job's triangle: HEIGHT is new */
        return wm_job_refine(p, j, &f, &init, heap, main_bytes, heap + ALIGN8(main_bytes),
                             heap_bytes - ALIGN8(main_bytes), detail);
    }
}
