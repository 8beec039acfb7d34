/* wavemesh host stages: the parts of `wavemesh mesh` around the refiner that run on the host only
 * (quantisation of float heights, the final check: proper mesh, error measure), in hosted C with doubles and
 * threads.  Not part of the refiner's freestanding core (src/) and never built for the board.
 *
 * Each function equals its Python reference model bit for bit (host/wavemesh/io/heightfield.py's
 * quantise, check.py's mesh_errors), whatever the thread count: the threads split the work into
 * independent parts (samples, triangles) and combine them by min / max, which do not depend on the
 * order (tests/host/test_host_stages.py).  threads <= 1 runs on the calling thread, as does a grid of fewer
 * samples than wm_host_part_min's. */
#ifndef WM_HOST_H
#define WM_HOST_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define WM_HOST_OK 0
#define WM_HOST_NONFINITE 1 /* a height is NaN or infinite */
#define WM_HOST_SPAN 2      /* max - min overflows a double */
#define WM_HOST_NOMEM 3     /* no memory for a pass's state (a thread that will not start is not an error) */

/* Each thread takes at least this many samples (default 2^18: a smaller grid runs on the calling
 * thread alone); n > 0 sets it (the tests: 1, to split small grids too).  Returns the value before. */
int64_t wm_host_part_min(int64_t n);

/* Whether the refiner's E(T) scans run in host_scan.c's AVX2 scans where the processor has AVX2 (1, the
 * default: its lanes for the small triangles on every grid, its blocks for the others on grids of 2^20
 * samples or more; 2: the blocks for every triangle; 3: the lanes for the small triangles, the C scan
 * for the others) or in tri_error.c's C scan (0): the same results (tests/host/test_host_stages.py).
 * on: 0 to 3 sets it, -1 only asks; returns what it was. */
int32_t wm_host_scan(int32_t on);

/* quantise(): n finite heights v to 16-bit samples.  out[0] = scale, out[1] = offset, out[2] = the
 * largest |v - (offset + scale * sample)|, out[3] and out[4] the least and the largest height (of zeros,
 * -0.0 is the lesser); *lossless = 1 when out[2] is 0 (every height reconstructed).
 * The rules are heightfield.py's: integers within 65535 of each other are kept exactly (offset 0
 * when they lie in 0..65535, else their minimum); otherwise offset = min, scale = (max - min) / 65535,
 * sample = rint((v - offset) / scale) clipped to 0..65535 (scale 1, samples 0 for a constant). */
int wm_host_quantise(const double *v, int64_t n, int32_t threads, uint16_t *samples, double *out,
                     int32_t *lossless);

/* quantise()'s samples of n finite heights v by a scale and offset found before (a tile's window by the
 * whole grid's, wavemesh.tiles.source.Quant): v - offset when exact (integers within 0..65535 of
 * offset), else rint((v - offset) / scale) clipped to 0..65535.  Returns the largest
 * |v - (offset + scale * sample)| (0 for none). */
double wm_host_quantise_with(const double *v, int64_t n, double offset, double scale, int32_t exact,
                             int32_t threads, uint16_t *samples);
/* The same of float32 heights (each widened to its double: the same samples and error as of v cast
 * to float64), rows x width of them, row r's from v[r pitch] (a window of the input's memory map: a
 * tiled job's float32 input read in place, wavemesh.tiles.source.Source.read); samples rows x width. */
double wm_host_quantise_with32(const float *v, int64_t rows, int64_t width, int64_t pitch, double offset,
                               double scale, int32_t exact, int32_t threads, uint16_t *samples);

/* The largest |v - (offset + scale * s)| over n heights and their samples (0 for none). */
double wm_host_quant_error(const double *v, const uint16_t *s, int64_t n, double offset, double scale,
                           int32_t threads);

/* mesh_errors()'s per-triangle vertical maxima: for each of the t triangles (vertex indices tris[3 i..],
 * vertex columns x, rows y, heights zv) the largest |h - plane| over the samples of the W x H height
 * field h in the closed triangle, the plane z0 + (E1 dz1 + E2 dz2) / |D| evaluated with the exact
 * integer edge functions; -inf for a degenerate triangle or one with no sample in the grid.  With nfac
 * (else NULL) also each triangle's normal factor sqrt(1 + a^2 + b^2) as mesh_errors writes it, the slopes
 * a, b per ground unit (cell size sx, sy), in the same operations (inf or NaN for a degenerate one).
 * Coordinates must be below 2^30 in size (the caller checks). */
int wm_host_tri_max(const double *h, int32_t width, int32_t height, const int64_t *x, const int64_t *y,
                    const double *zv, const int64_t *tris, int64_t t, double *per_v, double *nfac, double sx,
                    double sy, int32_t threads);
/* The same on a float32 height field h (each sample widened to its double: the same maxima as of h cast
 * to float64), row y's samples from h[y pitch] (pitch >= width: a window of a larger grid). */
int wm_host_tri_max32(const float *h, int32_t width, int32_t height, int64_t pitch, const int64_t *x,
                      const int64_t *y, const double *zv, const int64_t *tris, int64_t t, double *per_v,
                      double *nfac, double sx, double sy, int32_t threads);

/* check.py's check_mesh when the mesh is proper: 1 when every one of its checks passes (vertices in the
 * W x H rectangle, distinct and used; indices in range; every triangle counter-clockwise; the doubled
 * areas add up to 2 (W-1) (H-1); no directed edge twice, an edge of one triangle only on the border;
 * no vertex inside an edge; T = 2V - B - 2), *border = B; 0 when one fails (the caller's Python check
 * then says which); -1 when it cannot decide cheaply (W x H over 2^30, a vertex index beyond int32,
 * more lattice points inside edges than its budget, no memory): the caller checks in Python.  The
 * edges are split over `threads` (the verdict is the same whatever the count). */
int wm_host_check_mesh(int64_t width, int64_t height, const int64_t *xy, int64_t v, const int64_t *tris, int64_t t,
                       int32_t threads, int64_t *border);

/* The OBJ writer's face lines (meshio.write_obj): for each of the t triangles "f a b c\n" with its three
 * vertex indices plus one in decimal, as Python's "%d" writes them, into out (at least
 * WM_HOST_OBJ_FACE_MAX bytes a triangle); returns the bytes written. */
#define WM_HOST_OBJ_FACE_MAX 65
int64_t wm_host_obj_faces(const int64_t *tris, int64_t t, char *out);

/* The OBJ writer's vertex lines: for each of the n vertices "v x y z\n" with the integers x, y
 * (xy[2 i], xy[2 i + 1]) as Python's "%d" and z[i] as its repr(float) write them, into out (at least
 * WM_HOST_OBJ_VERTEX_MAX bytes a vertex).  A z it leaves to the caller's repr (not finite, or not zero
 * and below 1e-4 or from 2^53 in size) is written as one NUL byte and its vertex added to left (n entries
 * at most), *n_left of them.  Returns the bytes written (-1: none, on a host without 128-bit integers,
 * where the caller writes them all). */
#define WM_HOST_OBJ_VERTEX_MAX 72
int64_t wm_host_obj_vertices(const int64_t *xy, const double *z, int64_t n, char *out, int64_t *left,
                             int64_t *n_left);

/* native.refine's loop in one call: the refiner's mesh (wavemesh.h's wm_mesh_export) as it is and after
 * each wm_refine_step, until wm_refine_done.  The levels exported are counted from 0: level k's
 * statistics in stats[k], its export in buf after the levels before it (vertex slots then triangles, 2
 * vert_end + 3 n_tri int32s), sizes[2 k] its vert_end and sizes[2 k + 1] its triangles.  mode 1: the
 * first call (stats[0] from wm_refine_stats); 0: the mesh as it is is not exported yet, its statistics
 * in stats[0]; 2: a step first.  Returns the levels exported, *code WM_OK when the refiner is done, a
 * step's error (that level not exported), 1 when buf (cap int32s) has no room for the next level (call
 * again with mode 0, stats[returned] moved to stats[0]) or 2 when stats (max_levels) has none (mode 2). */
struct wm_refiner;
struct wm_level_stats;
int32_t wm_host_refine_levels(struct wm_refiner *r, int32_t mode, struct wm_level_stats *stats, int32_t max_levels,
                              int32_t *buf, int64_t cap, int32_t *sizes, int32_t *code);

#ifdef __cplusplus
}
#endif

#endif
