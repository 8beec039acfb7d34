/* native.refine's loop over the refiner's levels in one call (include/wm_host.h's wm_host_refine_levels):
 * each level's wm_refine_step, statistics and wm_mesh_export, for the host's library only (the board's
 * host and the C runner make the same calls one by one).  Apart from host_stages.c, which is built and
 * tested on its own without the refiner (tests/host/test_host_stages_default.py). */
#include "wavemesh.h"
#include "wm_host.h"

#include <stdint.h>

int32_t wm_host_refine_levels(wm_refiner *r, int32_t mode, wm_level_stats *stats, int32_t max_levels, int32_t *buf,
                              int64_t cap, int32_t *sizes, int32_t *code)
{
    const wm_mesh *m = wm_refine_mesh(r);
    int64_t at = 0;
    int32_t k = 0;
    if (mode == 1) wm_refine_stats(r, &stats[0]);
    for (;;) {
        int64_t need;
        if (mode == 2) {
            int rc;
            if (k == max_levels) {
                *code = 2; /* again with room for the statistics, mode 2 */
                return k;
            }
            rc = wm_refine_step(r, &stats[k]);
            if (rc != WM_OK) {
                *code = rc;
                return k;
            }
        }
        mode = 2;
        need = 2 * (int64_t)m->vert_end + 3 * (int64_t)m->n_tri;
        if (at + need > cap) {
            *code = 1; /* again with room for this level, mode 0, its statistics (stats[k]) at stats[0] */
            return k;
        }
        sizes[2 * k] = m->vert_end;
        sizes[2 * k + 1] = wm_mesh_export(m, buf + at, buf + at + 2 * (int64_t)m->vert_end);
        at += need;
        k++;
        if (wm_refine_done(r)) {
            *code = WM_OK;
            return k;
        }
    }
}
