/*
 * The board's job (firmware/board/app/board_job.c): the FPGA stage, the initial triangulation from its
 * template entries, and the refiner, behind the protocol engine's job interface (proto.h).
 */
#ifndef WM_BOARD_JOB_H
#define WM_BOARD_JOB_H

#include <stddef.h>
#include <stdint.h>

#include "proto.h"

/* The largest triangle capacity whose refiner storage (wm_refine_bound) and the worst staging of the
 * initial triangulation (wm_job_initial, for any block size) fit heap_bytes for a W x H grid; 0 when
 * not even 2 fit. */
uint32_t board_job_capacity(size_t heap_bytes, int32_t width, int32_t height);

/* The validity mask's storage (CONFIG_MASK, --nodata hole): a bit per sample of the largest grid
 * (WM_GRID_MAX_W x WM_GRID_MAX_H, 2 ceil(W H / 16) bytes: 128 KiB), static at the top of the heap;
 * the job's heap (board_heap_bytes) ends below it. */
uint8_t *board_mask(void);
uint32_t board_mask_bytes(void);
size_t board_heap_bytes(void);

/* The job (wm_proto_job_fn).  ctx is unused.  The heights are in the height memory already (the
 * engine's heights array is WM_HEIGHT_BASE); the heap is the linker's __heap_start .. __heap_end. */
int board_job(void *ctx, const wm_proto_job *job, wm_proto *p, uint32_t *detail);

#endif /* WM_BOARD_JOB_H */
