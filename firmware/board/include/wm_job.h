/*
 * The job both devices run, as one library: the board (firmware/board/app/board_job.c: the FPGA stage
 * labels the blocks) and the native stand-in device (firmware/board/native/native_job.c: the labeller here)
 * differ only in where the details and the template entries come from and where the storage is.
 *
 *   details of level M --wm_job_label--> template entries (TOUT's format)
 *   template entries --wm_job_initial--> initial triangulation (canonical form) in caller storage
 *   initial triangulation --wm_job_refine--> every level's mesh, each sent as it is made
 *
 * The initial triangulation is host/wavemesh/model/initial.py's (tests/firmware/test_job.py compares them):
 * each block's template (the generated wm_templates.h) on the block's grid positions (docs/model.md,
 * "Blocks"), then the canonical form of host/wavemesh/mesh.py (vertices by (y, x), each triangle
 * from its smallest vertex, triangles sorted), the order the refiner's result depends on.
 *
 * No allocation: the caller hands in storage, sized by the *_bound functions.  Every public symbol
 * starts with wm_job_.
 */
#ifndef WM_JOB_H
#define WM_JOB_H

#include <stddef.h>
#include <stdint.h>

#include "proto.h"
#include "wavemesh.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Level M's blocks over a W x H grid: cols x rows blocks of size 2^M (the last ones clipped). */
typedef struct wm_job_blocks {
    int32_t width, height, levels, size, cols, rows;
} wm_job_blocks;

void wm_job_blocks_init(wm_job_blocks *b, int32_t width, int32_t height, int32_t levels);

/*
 * The labeller (3.5.1-3.5.3: dominant detail above tau, dual sign, thin blocks demoted to flat) and the
 * variant resolver (3.5.4: the sides a neighbouring V or H block splits) of host/wavemesh/model/label.py:
 * one template entry per block in raster order, as the FPGA stage writes TOUT ((label <<
 * WM_TOUT_LABEL_SHIFT) | template id).  details_m: level M's details, cells row by row (the
 * layout of wm_details_offset(W, H, M)), (d1, d2, d3) each.  entries: cols * rows words.
 * WM_ERR_MESH when the look-up table has no template for a block (a bug: V and H carry their sides).
 */
int wm_job_label(const wm_job_blocks *b, uint32_t tau, const int32_t *details_m, uint32_t *entries);

/* The triangles the entries' templates make: the initial triangulation's count. */
int32_t wm_job_triangles(const wm_job_blocks *b, const volatile uint32_t *entries);

/* The largest storage wm_job_initial takes for nt triangles (entries of these blocks). */
size_t wm_job_initial_bound(const wm_job_blocks *b, int32_t nt);

/* wm_job_initial's result: arrays inside the caller's storage. */
typedef struct wm_job_initial_mesh {
    int32_t *xy;   /* 2 nv: x, y of each vertex, by (y, x) */
    int32_t *tris; /* 3 nt: counter-clockwise, from the smallest vertex, sorted */
    int32_t nv, nt;
    uint8_t *low; /* the lowest byte of the storage used: [mem, low) is free */
} wm_job_initial_mesh;

/*
 * The initial triangulation of nt triangles (wm_job_triangles) from the blocks' template entries, in
 * canonical form, staged from the END of mem[0..bytes) downwards (the caller keeps the start for the
 * refiner's storage): triangles, the lattice bitmap and its word bases, then the vertices.  Nothing is
 * read before it is written there.  WM_ERR_MEMORY when the staging would reach below mem + keep
 * (wm_job_initial_bound bytes above keep always suffice); WM_ERR_ARG on a template id out of range.
 */
int wm_job_initial(const wm_job_blocks *b, const volatile uint32_t *entries, int32_t nt, void *mem, size_t bytes,
                   size_t keep, wm_job_initial_mesh *out);

/* Storage wm_job_emit_initial takes for the mesh of nv vertices and nt triangles. */
size_t wm_job_mesh_bound(int32_t nv, int32_t nt);

/*
 * The initial triangulation alone, as a level (CONFIG_INITIAL_ONLY): built in mem[0..bytes), which is
 * cleared first, and sent (its counts stated for DONE: wm_proto_initial).  Returns wm_proto_emit_level's
 * code, or WM_PROTO_E_CAPACITY (detail M - 1) when bytes < wm_job_mesh_bound, WM_PROTO_E_JOB (detail: the
 * library's code) when it is not a mesh.
 */
int wm_job_emit_initial(wm_proto *p, const wm_proto_job *j, const wm_job_initial_mesh *init, void *mem,
                        size_t bytes, uint32_t *detail);

/*
 * The refine-and-emit loop: the refiner (firmware/src) from the initial triangulation in mem[0..bytes)
 * (wm_refine_bound(W, H, j->capacity) bytes, not cleared: the refiner writes every entry before it reads
 * it, so what an earlier job left there never reaches this one), each level sent through
 * wm_proto_emit_level as soon as it is made, the refiner's level M-1 first (the initial
 * triangulation's counts stated for DONE: wm_proto_initial).
 * spare[0..spare_bytes) (the initial triangulation's staging, or NULL), free once the refiner has taken
 * the initial mesh, holds the level streams (wm_proto_stream_buffer) until it returns.
 * Returns wm_proto_emit_level's code when it asks to stop, WM_PROTO_E_NONE when every level went out,
 * WM_PROTO_E_CAPACITY (detail: the level) when the storage ran out, WM_PROTO_E_JOB (detail: the
 * library's code) on any other refiner error.
 */
int wm_job_refine(wm_proto *p, const wm_proto_job *j, const wm_field *f, const wm_job_initial_mesh *init,
                  void *mem, size_t bytes, void *spare, size_t spare_bytes, uint32_t *detail);

/* Zero the words of [mem, mem + bytes) (word-aligned). */
void wm_job_clear(void *mem, size_t bytes);

#ifdef __cplusplus
}
#endif

#endif /* WM_JOB_H */
