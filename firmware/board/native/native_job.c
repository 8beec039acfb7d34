/*
 * The native stand-in device's job: what the board's FPGA stage and CPU do, on the host CPU.
 *
 *   heights --wm_haar (or wm_spline)--> details --wm_job_label--> template entries
 *           --wm_job_initial--> initial mesh --wm_job_refine--> levels
 *
 * The filter bank is the firmware library's (firmware/src), the labeller, the assembly and the
 * refine-and-emit loop the job library's (wm_job.h), the same code the board runs after its FPGA
 * stage.  This is a hosted program: the storage the library takes comes from malloc.
 */
#include "native_job.h"

#include <stdlib.h>
#include <string.h>

#include "wm_job.h"

/* Level M's details and the template entries of its blocks: malloc'ed *entries (cols * rows). */
static int label(const wm_job_blocks *b, uint32_t tau, const int32_t *details, uint32_t **entries)
{
    *entries = malloc(sizeof(uint32_t) * ((size_t)b->cols * b->rows + 1));
    if (!*entries) return WM_ERR_MEMORY;
    return wm_job_label(b, tau, details + wm_details_offset(b->width, b->height, b->levels), *entries);
}

int wm_native_initial(int32_t width, int32_t height, int32_t levels, uint32_t tau, const int32_t *details,
                      int32_t **xy_out, int32_t *nv_out, int32_t **tris_out, int32_t *nt_out)
{
    wm_job_blocks b;
    wm_job_initial_mesh init;
    uint32_t *entries = NULL;
    void *mem = NULL;
    int32_t *xy = NULL, *tris = NULL;
    size_t bytes;
    int rc = -1;
    wm_job_blocks_init(&b, width, height, levels);
    if (label(&b, tau, details, &entries) != WM_OK) goto out;
    init.nt = wm_job_triangles(&b, entries);
    bytes = wm_job_initial_bound(&b, init.nt);
    mem = malloc(bytes ? bytes : 1);
    if (!mem || wm_job_initial(&b, entries, init.nt, mem, bytes, 0, &init) != WM_OK) goto out;
    xy = malloc(sizeof(int32_t) * 2 * ((size_t)init.nv + 1));
    tris = malloc(sizeof(int32_t) * 3 * ((size_t)init.nt + 1));
    if (!xy || !tris) goto out;
    memcpy(xy, init.xy, sizeof(int32_t) * 2 * (size_t)init.nv);
    memcpy(tris, init.tris, sizeof(int32_t) * 3 * (size_t)init.nt);
    *xy_out = xy, *nv_out = init.nv, *tris_out = tris, *nt_out = init.nt;
    xy = tris = NULL;
    rc = 0;
out:
    free(entries);
    free(mem);
    free(xy);
    free(tris);
    return rc;
}

int wm_native_job(void *ctx, const wm_proto_job *j, wm_proto *p, uint32_t *detail)
{
    int32_t w = j->width, h = j->height, m = j->levels;
    int spline = (j->flags & WM_PROTO_CONFIG_SPLINE) != 0; /* the filter bank CONFIG chose */
    int64_t nd = wm_details_size(w, h, m), ns = spline ? wm_spline_scratch(w, h) : wm_haar_scratch(w, h);
    int32_t *details = malloc(sizeof(int32_t) * (size_t)(nd > 0 ? nd : 1));
    uint16_t *scratch = malloc(sizeof(uint16_t) * (size_t)(ns > 0 ? ns : 1));
    uint32_t *entries = NULL;
    void *staging = NULL, *mem = NULL;
    wm_job_blocks b;
    wm_job_initial_mesh init;
    int rc = WM_PROTO_E_JOB, lib;
    size_t bytes, staging_bytes;
    (void)ctx;
    *detail = (uint32_t)WM_ERR_MEMORY;
    if (!details || !scratch) goto out;

    wm_proto_stage(p, WM_PROTO_STAGE_FILTER, m);
    lib =
        spline ? wm_spline(j->heights, w, h, m, details, scratch) : wm_haar(j->heights, w, h, m, details, scratch);
    if (lib != WM_OK) {
        *detail = (uint32_t)lib;
        goto out;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_TEMPLATE, m);
    wm_job_blocks_init(&b, w, h, m);
    lib = label(&b, j->tau, details, &entries);
    if (lib != WM_OK) {
        *detail = (uint32_t)lib;
        goto out;
    }
    init.nt = wm_job_triangles(&b, entries);
    if (init.nt > j->capacity) {
        *detail = (uint32_t)(m - 1);
        rc = WM_PROTO_E_CAPACITY;
        goto out;
    }
    bytes = wm_job_initial_bound(&b, init.nt);
    staging = malloc(bytes ? bytes : 1);
    if (!staging || wm_job_initial(&b, entries, init.nt, staging, bytes, 0, &init) != WM_OK) goto out;

    staging_bytes = bytes;
    if (j->flags & WM_PROTO_CONFIG_INITIAL_ONLY) {
        bytes = wm_job_mesh_bound(init.nv, init.nt);
    } else {
        bytes = wm_refine_bound(w, h, j->capacity);
    }
    mem = bytes ? malloc(bytes) : NULL;
    if (!mem) goto out;
    if (j->flags & WM_PROTO_CONFIG_INITIAL_ONLY) {
        rc = wm_job_emit_initial(p, j, &init, mem, bytes, detail);
    } else {
        wm_field f = {w, h, m, j->heights, details, j->mask};
        rc = wm_job_refine(p, j, &f, &init, mem, bytes, staging, staging_bytes, detail);
    }
out:
    free(details);
    free(scratch);
    free(entries);
    free(staging);
    free(mem);
    return rc;
}
