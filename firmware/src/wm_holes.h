/* The refiner's hooks for holes (holes.c): E(T) of a field with a validity mask.  Internal. */
#ifndef WM_HOLES_H
#define WM_HOLES_H

#include "wavemesh.h"

/* For f->mask != NULL: 1 when the mask decides E(T) of the triangle (wm_tri_cover: 0 for a hole or a
 * thin triangle, 0xFFFFFFFF with the split sample as the worst for one covering both kinds), with
 * the value in *e and the worst sample in (*wx, *wy) when not NULL; 0 when it covers valid samples
 * only and E(T) is measured as without a mask. */
int wm_hole_error(const wm_field *f, const int32_t x[3], const int32_t y[3], uint32_t *e, int32_t *wx,
                  int32_t *wy);

/* 1 when sample (px, py) is invalid (f->mask != NULL). */
int wm_hole_at(const wm_field *f, int32_t px, int32_t py);

#endif /* WM_HOLES_H */
