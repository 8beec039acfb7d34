/*
 * The native stand-in device's job (firmware/board/native/): the filter bank, the template stage and
 * the refiner in C on the host CPU, behind the protocol engine's job interface (proto.h).
 */
#ifndef WM_NATIVE_JOB_H
#define WM_NATIVE_JOB_H

#include <stdint.h>

#include "proto.h"

/* The initial triangulation of a W x H field from the details of levels 1..M (the layout of wm_haar):
 * the job library's labeller and assembly (wm_job.h) with malloc'ed storage.  *xy (2 nv int32) and
 * *tris (3 nt int32) are malloc'ed.  Returns 0, or -1 when memory runs out or the look-up table has
 * no template (a bug). */
int wm_native_initial(int32_t width, int32_t height, int32_t levels, uint32_t tau, const int32_t *details,
                      int32_t **xy, int32_t *nv, int32_t **tris, int32_t *nt);

/* The job (wm_proto_job_fn).  ctx is unused. */
int wm_native_job(void *ctx, const wm_proto_job *job, wm_proto *p, uint32_t *detail);

#endif /* WM_NATIVE_JOB_H */
