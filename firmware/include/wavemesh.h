/*
 * wavemesh firmware: the refiner of Lee's "Wavelet-Based Multiresolution Surface Approximation from
 * Height Fields" (chapter 4), in C99 with integer arithmetic only.
 *
 * One public header.  Conventions (firmware/README.md, docs/refiner.md):
 *
 * - Every public symbol starts with wm_ (types wm_*, macros WM_*), snake_case.
 * - No malloc: the caller hands in storage sized by the *_bound() functions.  Running out of room is
 *   the return code WM_ERR_CAPACITY, never a crash; the mesh stays valid.
 * - No floating point anywhere: parameters arrive as fixed-point integers (formats below), so the
 *   same sources give the same mesh, bit for bit, on x86-64 and on an rv32 soft CPU without FPU.
 * - Freestanding: the core uses only <stdint.h> and <stddef.h> (no stdio, no libc calls).
 * - Functions return WM_OK (0) or a negative WM_ERR_* code for anything data can cause; programmer
 *   errors and invariants are asserts (compiled in with WM_CHECK=1, which also runs the full mesh
 *   invariant check after every operator).
 *
 * Geometry: a height field has W columns and H rows (2 <= W, H <= WM_MAX_SIDE); sample (x, y) is
 * column x, row y.  A mesh triangulates the rectangle [0, W-1] x [0, H-1], every vertex is a grid
 * sample, triangles are counter-clockwise: (x1-x0)(y2-y0) - (x2-x0)(y1-y0) > 0.
 *
 * Half-edge mesh (hmm style): triangle t owns half-edges 3t, 3t+1, 3t+2; half-edge e starts at vertex
 * he[e].v and ends at he[next(e)].v, next(e) = e - e%3 + (e+1)%3; he[e].o is the opposite half-edge or
 * -1 on the border of the rectangle.  A half-edge's origin and opposite lie side by side (wm_he), as do
 * a vertex's x and y (wm_xy, vxy[]): the routines that read one nearly always read the other, and on the
 * board each separate array was a cache line of its own to refill (docs/soc.md, "What the SDRAM costs
 * the job").  Free triangle slots have he[3t].v = -1 and are chained through he[3t].o; free vertex slots
 * have vxy[].x = WM_FREE and are chained through vh (vertex removal frees both).
 */
#ifndef WAVEMESH_H
#define WAVEMESH_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------------------------------------- */
/* Return codes */

#define WM_OK 0
#define WM_ERR_ARG (-1)      /* an argument is out of range (size, count, index, parameter) */
#define WM_ERR_MEMORY (-2)   /* the storage handed in is smaller than the *_bound() asks for */
#define WM_ERR_CAPACITY (-3) /* the mesh needs more triangles or vertices than the storage holds */
#define WM_ERR_MESH (-4)     /* the input is not a proper triangulation of the grid rectangle */
#define WM_ERR_STATE (-5)    /* the refiner has finished (or was never initialised) */
#define WM_ERR_REFUSED (-6)  /* an operator's precondition fails (it would not give a proper mesh) */

#define WM_MAX_SIDE 32767  /* largest W or H: keeps every exact product within 64 bits */
#define WM_MAX_LEVELS 12   /* largest M, as the reference model */
#define WM_FREE 0xFFFFu    /* vxy[].x of a free vertex slot */

/* Index storage: vertex and half-edge numbers in the mesh and the refiner's lists are wm_index.
 * 32-bit by default; a device with little memory builds with -DWM_INDEX_BITS=16 (the board does), which
 * halves them and limits a mesh to WM_INDEX_MAX / 3 triangles and WM_INDEX_MAX vertices
 * (wm_mesh_bound says 0 beyond).  Arithmetic stays 32-bit: the same mesh either way. */
#ifndef WM_INDEX_BITS
#define WM_INDEX_BITS 32
#endif
#if WM_INDEX_BITS == 16
typedef int16_t wm_index;
#define WM_INDEX_MAX 32767
#elif WM_INDEX_BITS == 32
typedef int32_t wm_index;
#define WM_INDEX_MAX 0x7FFFFFFF
#else
#error "WM_INDEX_BITS is 16 or 32"
#endif

/* A short text for a return code ("ok", "capacity exhausted", ...); never NULL. */
const char *wm_strerror(int code);

/* ---------------------------------------------------------------------------------------------- */
/* The half-edge mesh */

typedef struct wm_xy {
    uint16_t x, y;
} wm_xy;

typedef struct wm_he {
    wm_index v, o;
} wm_he;

typedef struct wm_mesh {
    int32_t width, height;     /* W, H of the grid */
    int32_t tri_cap, vert_cap; /* slots in the arrays */
    int32_t tri_end, vert_end; /* slots in use (live or free) are 0 .. end-1 */
    int32_t n_tri, n_vert;     /* live triangles and vertices */
    int32_t tri_free, vert_free; /* heads of the free lists, -1 when empty */
    wm_he *he;      /* [3 tri_cap] each half-edge's origin vertex v (he[3t].v = -1: free slot) and its opposite
                     * half-edge o (-1 on the border), side by side */
    uint8_t *tflag; /* [tri_cap] scratch flags for the algorithms (region, pairing) */
    wm_xy *vxy;     /* [vert_cap] column x (WM_FREE: free slot) and row y of each vertex, side by side */
    wm_index *vh;   /* [vert_cap] one half-edge leaving the vertex */
} wm_mesh;

/* Half-edge e's successor and predecessor in its triangle (e >= 0), without a division: e / 3 is a
 * multiply-high by ceil(2^33 / 3) (exact for every 0 <= e < 2^32).  -Os compiles `% 3` to the division
 * instruction, some 40 cycles on the soft CPU, and every mesh walk takes these.  Which corner e is needs
 * less: 3 divides u (0 <= u < 2^32) iff u times 3's inverse modulo 2^32 (0xAAAAAAAB) is at most
 * (2^32 - 1) / 3 (wm_div3_exact: one multiply and a comparison, where e - 3 (e / 3) took a multiply-high,
 * shifts and a subtraction): e is a triangle's last corner iff 3 divides e + 1, its first iff 3 divides e. */
static inline int32_t wm_div3(int32_t e) { return (int32_t)(((uint64_t)(uint32_t)e * 0xAAAAAAABu) >> 33); }
static inline int wm_div3_exact(uint32_t u) { return u * 0xAAAAAAABu <= 0x55555555u; }
static inline int32_t wm_next_he(int32_t e) { return wm_div3_exact((uint32_t)e + 1u) ? e - 2 : e + 1; }
static inline int32_t wm_prev_he(int32_t e) { return wm_div3_exact((uint32_t)e) ? e + 2 : e - 1; }
#define WM_NEXT(e) wm_next_he(e)
#define WM_PREV(e) wm_prev_he(e)

/* Bytes of storage wm_mesh_init needs for tri_cap triangles and vert_cap vertices (0 if too big). */
size_t wm_mesh_bound(int32_t tri_cap, int32_t vert_cap);

/* Vertex slots enough for any triangulation of the W x H rectangle with tri_cap triangles
 * (Euler: V = (T + B + 2) / 2 with B <= 2(W + H) - 4 border vertices). */
int32_t wm_vert_cap_for(int32_t width, int32_t height, int32_t tri_cap);

/* A triangle capacity for a W x H grid's storage, from cap (the grid's own, wm_tri_cap_max) up to limit:
 * the smallest for which 2 vert_cap rounded up to 8 bytes lies 1 to 7 KiB past a multiple of 8 KiB; cap
 * when none within 8192 more.  The board's clamp (app/board_job.c): with a power-of-two grid's own
 * capacity the vertex arrays vh and vxy (4 bytes a vertex each with 32-bit indices, read together by the
 * fan walks) lie a multiple of 8 KiB plus 16 bytes apart, and a vertex's two fall on the same or the
 * next line index of the board's direct-mapped caches; for the grids it moves, about 2 KiB apart (mesh.c).  The refiner
 * cannot reach it, so the mesh is the same. */
int32_t wm_tri_cap_skewed(int32_t width, int32_t height, int32_t cap, int32_t limit);

/* Lays out an empty mesh of a W x H grid in mem (bytes >= wm_mesh_bound).
 * WM_ERR_ARG: W or H outside 2..WM_MAX_SIDE or a capacity < 1; WM_ERR_MEMORY: bytes too small. */
int wm_mesh_init(wm_mesh *m, void *mem, size_t bytes, int32_t width, int32_t height, int32_t tri_cap,
                 int32_t vert_cap);

/* Fills an empty mesh from triangle arrays as wavemesh.model.initial makes them: xy[2 nv] (x, y pairs),
 * tris[3 nt] counter-clockwise vertex indices.  scratch: 3 nt words, clobbered.
 * WM_ERR_CAPACITY: nt > tri_cap or nv > vert_cap; WM_ERR_ARG: an index or coordinate out of range;
 * WM_ERR_MESH: not a proper triangulation (orientation, edges, border, area, unused vertex). */
int wm_mesh_build(wm_mesh *m, const int32_t *xy, int32_t nv, const int32_t *tris, int32_t nt, uint32_t *scratch);

/* Writes the mesh out: xy[2 vert_end] per vertex slot (free slots get -1, -1) and tris[3 n_tri],
 * the live triangles in slot order as vertex slot numbers.  Returns n_tri. */
int32_t wm_mesh_export(const wm_mesh *m, int32_t *xy, int32_t *tris);

/* The full invariant check, O(n): live indices, counter-clockwise triangles, opposite half-edges
 * that match (same edge, reversed), border half-edges on the rectangle's border, vh consistent,
 * free lists sound, doubled areas adding up to 2 (W-1)(H-1), Euler's T = 2V - B - 2.
 * WM_OK or WM_ERR_MESH.  Together these imply a proper triangulation (host/wavemesh/check/__init__.py gives
 * the proof), except for two vertices at one position, which no operator can create. */
int wm_mesh_check(const wm_mesh *m);

/* Twice the signed area of triangle t (> 0 in a valid mesh). */
int64_t wm_tri_area2(const wm_mesh *m, int32_t t);

/* ---------------------------------------------------------------------------------------------- */
/* Local operators (one .c each).  Each returns WM_OK, WM_ERR_CAPACITY (nothing changed),
 * WM_ERR_REFUSED (precondition fails, nothing changed) or WM_ERR_ARG.  touched[] receives the
 * triangles that changed or were created (up to 4) and the function returns their count through
 * *n_touched when it is not NULL. */

/* Splits edge e at grid point (x, y), which must lie strictly inside the edge (4.4, fig. 2.7(c)):
 * the two triangles at the edge become four (two on the border); the new vertex is corner 1 of
 * touched[0]. */
int wm_edge_split(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t touched[4], int32_t *n_touched);

/* Ternary subdivision (fig. 4.15): triangle t becomes three around the grid point (x, y), which must
 * lie strictly inside t; the new vertex is corner 2 of each, touched[0] = t. */
int wm_tri_split(wm_mesh *m, int32_t t, int32_t x, int32_t y, int32_t touched[3], int32_t *n_touched);

/* 1 when the quadrilateral of the two triangles at e is strictly convex (no three corners collinear),
 * the condition for an edge swap (4.5.1); 0 otherwise and on the border. */
int wm_edge_swappable(const wm_mesh *m, int32_t e);

/* Edge swap (4.5.1, fig. 2.7(d)): replaces the diagonal e of a strictly convex quadrilateral by the
 * other one. */
int wm_edge_swap(wm_mesh *m, int32_t e, int32_t touched[2], int32_t *n_touched);

/* Vertex movement (4.4.3): moves vertex v to grid point (x, y) when every triangle around v stays
 * counter-clockwise; a border vertex may only slide along its side, a corner never moves. */
int wm_vertex_move(wm_mesh *m, int32_t v, int32_t x, int32_t y);

/* Vertex removal (4.5.2), in two steps so that the caller can judge the new triangles before
 * anything changes.  The ring of v is the polygon of its neighbours in counter-clockwise order,
 * WM_MAX_RING of them at most; for a vertex on a side of the rectangle it starts and ends with its
 * two neighbours on that side.  Corners are never removed. */
#define WM_MAX_RING 32

/* The ring of v into ring[] (vertex numbers); returns its size n (>= 3), or WM_ERR_REFUSED (a corner,
 * or more than WM_MAX_RING neighbours), WM_ERR_ARG (not a live vertex). */
int wm_vertex_ring(const wm_mesh *m, int32_t v, int32_t ring[WM_MAX_RING]);

/* A triangulation of the hole v leaves: n - 2 triangles into tris[] (counter-clockwise vertex
 * numbers), covering the ring polygon exactly.  apex = -1: ear clipping that takes the first ear
 * whose circumcircle holds no other ring vertex (else the first ear); apex = i (0 <= i < n): the fan from ring
 * vertex i, which is the half-edge collapse of v into that neighbour (4.5.3 with the collapse
 * point at a grid vertex).  WM_ERR_REFUSED when that triangulation does not exist (a fan whose
 * triangles are not all strictly counter-clockwise); WM_OK otherwise. */
int wm_vertex_remove_plan(const wm_mesh *m, int32_t v, int32_t apex, int32_t tris[3 * WM_MAX_RING],
                          int32_t *n_tris);

/* The same from a ring as wm_vertex_ring returns it (n vertices), without walking the fan again. */
int wm_ring_plan(const wm_mesh *m, const int32_t *ring, int32_t n, int32_t apex, int32_t tris[3 * WM_MAX_RING],
                 int32_t *n_tris);

/* Removes v and fills its hole with the planned triangles (made by wm_vertex_remove_plan on this
 * mesh as it is).  The triangles reuse v's fan's slots; the one or two slots left over and v's slot
 * go to the free lists.  touched[] receives the new triangles' slots (n_tris of them). */
int wm_vertex_remove(wm_mesh *m, int32_t v, const int32_t *tris, int32_t n_tris, int32_t touched[WM_MAX_RING],
                     int32_t *n_touched);

/* Edge collapse (4.5.3): the edge e = v1 -> v2 becomes one vertex at grid point (x, y), which is
 * v1's position, v2's position (a half-edge collapse) or a grid point strictly inside the edge (the
 * dissertation's midpoint, snapped).  Every triangle around v1 or v2 but the one or two on the edge
 * keeps its other corners and takes (x, y) for v1 or v2.  Refused (nothing changes) when a new
 * triangle is not strictly counter-clockwise, when v1 and v2 have a common neighbour that is not a
 * corner of a triangle on the edge (the link condition), when a border vertex would leave its side
 * of the rectangle (a corner never moves), or when a ring has more than WM_MAX_RING vertices.
 *
 * The plan, without changing anything: the new triangles into tris[] (counter-clockwise), with
 * WM_COLLAPSE_POINT standing for the vertex at (x, y); their count into *n_tris (for a half-edge
 * collapse only the removed end's triangles: the kept end's do not change). */
#define WM_COLLAPSE_POINT (-2)
int wm_edge_collapse_plan(const wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t tris[6 * WM_MAX_RING],
                          int32_t *n_tris);

/* Carries the collapse out (an edge split at (x, y) when it is inside the edge, then the half-edge
 * collapses of v1 and v2 into it).  touched[] receives the new triangles' slots; *vertex (may be NULL)
 * the vertex at (x, y).  WM_ERR_CAPACITY (nothing changed) when the split finds no free slot. */
int wm_edge_collapse(wm_mesh *m, int32_t e, int32_t x, int32_t y, int32_t touched[6 * WM_MAX_RING],
                     int32_t *n_touched, int32_t *vertex);

/* ---------------------------------------------------------------------------------------------- */
/* The height field, its wavelet details, the parameters */

/* Detail coefficients as wavemesh.model.haar computes them (docs/model.md, "Filter bank"): for each level
 * m = 1..M, ceil(H / 2^m) rows of ceil(W / 2^m) cells, each cell three int32 (d1, d2, d3), levels
 * one after the other from m = 1.  d is twice the difference of half-block means in sample counts. */
int64_t wm_details_offset(int32_t width, int32_t height, int32_t m); /* int32 index of level m */
int64_t wm_details_size(int32_t width, int32_t height, int32_t levels); /* int32s for levels 1..M */

/* The same filter bank in C (for tests and for a device without the FPGA stage).  details receives
 * wm_details_size() int32s; scratch holds wm_haar_scratch() uint16s.  WM_ERR_ARG on bad sizes. */
int64_t wm_haar_scratch(int32_t width, int32_t height);
int wm_haar(const uint16_t *samples, int32_t width, int32_t height, int32_t levels, int32_t *details,
            uint16_t *scratch);
/* The spline wavelet's filter bank (host/wavemesh/model/spline.py), the same detail layout as wm_haar;
 * scratch holds wm_spline_scratch() uint16s and must be 4-byte aligned. */
int64_t wm_spline_scratch(int32_t width, int32_t height);
int wm_spline(const uint16_t *samples, int32_t width, int32_t height, int32_t levels, int32_t *details,
              uint16_t *scratch);

typedef struct wm_field {
    int32_t width, height;    /* W, H */
    int32_t levels;           /* M >= 1: the initial triangulation used level M */
    const uint16_t *samples;  /* [H W] row-major 16-bit samples */
    const int32_t *details;   /* levels 1..M as above (level M is not used by the refiner) */
    const uint8_t *mask;      /* NULL, or a bit per sample, set where the sample is invalid (a hole):
                                 sample (x, y) is bit i % 8 of byte i / 8, i = y W + x (WM_MASK_BYTES);
                                 see wm_tri_cover for what E(T) then measures */
} wm_field;

/* Bytes of a validity mask for W x H samples. */
#define WM_MASK_BYTES(w, h) (((int64_t)(w) * (int64_t)(h) + 7) / 8)

/* What the closed triangle covers of a field with a mask (holes.c):
 * WM_COVER_VALID   only valid samples: E(T) measures them as without a mask;
 * WM_COVER_HOLE    only invalid samples: E(T) = 0 (a hole: the host drops it, wavemesh/refine/cover.py);
 * WM_COVER_THIN    both, but no sample besides its corners (twice its area is 1): it cannot be split,
 *                  E(T) = 0 and it is dropped with the holes;
 * WM_COVER_MIXED   both, and a sample besides its corners: E(T) = 0xFFFFFFFF, so every stage refines it,
 *                  and its worst sample (*sx, *sy) is a non-corner sample to split at: the valid sample
 *                  next to an invalid one (else any) nearest the barycentre.
 * The refiner therefore splits every triangle that covers both until it covers one kind (or is thin);
 * the error bound then holds over the valid samples of the triangles kept. */
#define WM_COVER_VALID 0
#define WM_COVER_HOLE 1
#define WM_COVER_THIN 2
#define WM_COVER_MIXED 3
int wm_tri_cover(const wm_field *f, const int32_t x[3], const int32_t y[3], int32_t *sx, int32_t *sy);

#define WM_METRIC_NORMAL 0   /* distance along the triangle's normal (the dissertation's) */
#define WM_METRIC_VERTICAL 1 /* vertical distance */
#define WM_NEIGHBOURHOOD_FACE 0   /* face-based neighbourhood (4.10), the coefficients the triangle holds */
#define WM_NEIGHBOURHOOD_VERTEX 1 /* vertex-based neighbourhood (4.9), coefficient at the vertex */

/* Parameters (Table 4.3) as fixed-point numbers.  The host converts them (host/wavemesh/refine/native.py)
 * with the rounding stated for each, and wm_params_check rejects values out of range. */
typedef struct wm_params {
    int32_t metric;         /* WM_METRIC_* */
    int32_t neighbourhood;  /* WM_NEIGHBOURHOOD_* */
    int32_t iterations;     /* k: refinement iterations per level, 0..3 (0: only the error bound; none at
                               level 0 when the error bound and the final decimation follow) */
    int32_t max_triangles;  /* triangle budget, 0 = none (the storage is the only limit) */
    uint32_t zeta;          /* zeta in sample counts, Q16.16, rounded down (conservative) */
    uint32_t scale_m;       /* height scale s (height units per sample count) = scale_m / 2^scale_e, */
    int32_t scale_e;        /*   scale_m < 2^16, scale_e in 0..126, rounded down (conservative) */
    uint32_t delta_p;       /* pairing threshold delta_p (4.16), Q0.16, 0..65535 */
    uint32_t alpha;         /* mesh regularity factor alpha (4.22), Q0.16, 0..65536 */
    uint32_t delta_v;       /* vertex movement threshold delta_v (4.21), 3-D distance, Q16.16 */
    uint32_t flags;         /* WM_FLAG_*: 0 is the default pipeline */
    uint64_t delta_d;       /* detail energy threshold: e = d1^2 + d2^2 + d3^2 > delta_d at every level
                               (4.12), in coefficient units: floor(16 delta_d zeta^2 / s^2) (delta_d: energy
                               per sample over zeta squared, docs/refiner.md) */
    uint32_t delta_lambda;  /* vertex removal criterion delta_lambda (4.32, 4.33): eigenvalues of R(v)
                               (unit normals, so in 0..1), Q16.16, rounded */
    uint32_t delta_c;       /* edge collapse criterion delta_c (4.34), |e21 . e22| > delta_c, Q16.16,
                               0..65536, rounded */
    uint32_t slope_x_m;     /* the normal metric's slope scales s / dx and s / dy (dx, dy: the ground */
    int32_t slope_x_e;      /*   distance between neighbouring samples along a row and along a column, */
    uint32_t slope_y_m;     /*   in height units) = m / 2^e in scale_m's format, rounded down */
    int32_t slope_y_e;      /*   (conservative); m = 0: a cell of 1 (s / dx = s), as a zeroed struct */
} wm_params;

/* wm_params.flags.  The default (0) runs the levels, the error bound with Delaunay legalisation and
 * the final decimation. */
#define WM_FLAG_NO_BOUND 1u    /* the dissertation's stopping rule: the levels alone, no error bound */
#define WM_FLAG_NO_LEGALISE 2u /* the error bound splits without Lawson flips */
#define WM_FLAG_NO_DECIMATE 4u /* no final decimation */
#define WM_FLAG_NO_REDUCE 8u   /* no reduction at 2(d) and 3(b) (vertex removal, edge collapse) */
#define WM_FLAG_ALL 15u

/* WM_OK, or WM_ERR_ARG when a parameter is out of its range. */
int wm_params_check(const wm_params *p);

/* sizeof of the structures a foreign-function interface fills in (host/wavemesh/refine/native.py checks
 * its own layout against these): WM_ABI_PARAMS, WM_ABI_FIELD, WM_ABI_STATS; 0 for anything else. */
#define WM_ABI_PARAMS 0
#define WM_ABI_FIELD 1
#define WM_ABI_STATS 2
size_t wm_abi_size(int which);

/* ---------------------------------------------------------------------------------------------- */
/* E(T): the largest distance from the samples in the closed triangle to its plane */

/* E(T) of the triangle (x0,y0), (x1,y1), (x2,y2) (counter-clockwise, inside the grid) in sample
 * counts, Q16.16, an upper bound of the exact value that exceeds it by at most about 2^-15
 * relative + 2^-16 (docs/refiner.md, "E(T) in integers").  E(T) <= zeta exactly when the result is
 * <= p->zeta (vertical metric), and never <= zeta when the exact value is > zeta (normal).
 * (*wx, *wy) receive the first sample (row by row) with the largest distance, when not NULL. */
uint32_t wm_tri_error(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t *wx,
                      int32_t *wy);

/* ---------------------------------------------------------------------------------------------- */
/* The reduction criteria (4.31-4.34): the autocorrelation matrix R(v) of the unit normals around a
 * vertex and its eigen-decomposition, in fixed point (firmware/src/autocorr.c) */

/* Eigenvalues and eigenvectors of the symmetric 3 x 3 matrix a (a00, a01, a02, a11, a12, a22, Q30) by
 * cyclic Jacobi rotations, a fixed number of sweeps: lambda[0] <= lambda[1] <= lambda[2] (Q30) and
 * vec[3 i .. 3 i + 2] the unit eigenvector of lambda[i] (Q30).  For a matrix of Frobenius norm at most 1,
 * as R(v) (autocorr.c: every product then within 64 bits); larger ones are out of its range (all entries
 * 1.9: eigenvalues -0.64, 0, 6.34, not 0, 0, 5.7; 2, -2, 2 in turn: a division by zero). */
void wm_sym3_eigen(const int64_t a[6], int64_t lambda[3], int64_t vec[9]);

/* The unit normal (Q28) of the triangle (x, y, z = samples there) with the height scale of p:
 * the cross product (s A, s B, D) of its edges in grid steps and height units, normalised. */
void wm_unit_normal(const wm_field *f, const wm_params *p, const int32_t x[3], const int32_t y[3], int32_t n[3]);

/* R(v) = (1/k) sum n_i n_i^T over the k triangles around vertex v (4.31), as wm_sym3_eigen takes it
 * (Q30), then its eigen-decomposition.  Returns k, or WM_ERR_ARG for a free vertex. */
int wm_vertex_autocorr(const wm_mesh *m, const wm_field *f, const wm_params *p, int32_t v, int64_t r[6],
                       int64_t lambda[3], int64_t vec[9]);

/* ---------------------------------------------------------------------------------------------- */
/* The refiner (4.6, step 3, and the error bound) */

typedef struct wm_level_stats {
    int32_t level;            /* resolution level m of this mesh (M-1 initial ... 0) */
    int32_t vertices, triangles;
    int32_t iterations;       /* iterations run (stops early when nothing is active) */
    int32_t active;           /* active triangles, summed over iterations */
    int32_t dependent;        /* dependent-region triangles, summed */
    int32_t pairs;            /* valid pairs split (or resolved by a vertex movement) */
    int32_t quasi_pairs;      /* quasi-valid pairs on the border */
    int32_t unpaired;         /* unpaired triangles (ternary subdivision) */
    int32_t edge_splits;      /* edge splits done (pairs, quasi-valid pairs, fall-backs) */
    int32_t ternary_splits;   /* ternary subdivisions done */
    int32_t moves;            /* vertex movements done instead of a split */
    int32_t swaps;            /* edge swaps (regularisation) */
    int32_t bound_splits;     /* splits of the error-bound loop (level 0 only) */
    int32_t flips;            /* Lawson flips of the error bound's legalisation */
    int32_t budget_hit;       /* 1: the triangle budget stopped a split */
    int32_t over;             /* triangles with E(T) > zeta */
    uint32_t e_max;           /* max E(T), Q16.16 sample counts, chosen metric (upper bound) */
    int32_t removals;         /* vertices removed (decimation, reduction) */
} wm_level_stats;

typedef struct wm_refiner wm_refiner;

/* Bytes the refiner needs for a W x H field and a mesh of up to tri_cap triangles (0: overflow). */
size_t wm_refine_bound(int32_t width, int32_t height, int32_t tri_cap);

/* The most triangles any triangulation of the W x H grid with grid-sample vertices can have,
 * 2 (W-1) (H-1): a tri_cap that never runs out. */
int32_t wm_tri_cap_max(int32_t width, int32_t height);

/* Sets up a refiner in mem (bytes >= wm_refine_bound) from the initial triangulation (xy, tris as
 * wm_mesh_build) and computes E(T) of every triangle.  *out points into mem.  The field and its
 * arrays must stay alive and unchanged while the refiner is used.  Errors: WM_ERR_ARG (sizes,
 * parameters), WM_ERR_MEMORY, WM_ERR_CAPACITY (nt > tri_cap), WM_ERR_MESH. */
int wm_refine_init(wm_refiner **out, void *mem, size_t bytes, const wm_field *f, const wm_params *p,
                   const int32_t *xy, int32_t nv, const int32_t *tris, int32_t nt, int32_t tri_cap);

/* Selective triangulation (dissertation 5.6): restricts E(T), everywhere the refiner uses it, to the
 * samples in a region of interest (firmware/src/roi.c), so that only triangles holding ROI samples are
 * refined and the error bound ends with every ROI sample within zeta.  rows[(W + 1) y + x] is the
 * number of ROI samples in row y left of column x ((W + 1) H int32s, each row starting at 0 and rising
 * by 0 or 1 per column); it must stay alive and unchanged while the refiner is used.  The details the
 * refiner was given should be zero outside the ROI (the dissertation's mask; the host does that).
 * Call it after wm_refine_init and before the first wm_refine_step: WM_ERR_STATE otherwise;
 * WM_ERR_ARG when rows is NULL or not such a table.  The statistics' e_max and over then count ROI
 * samples only. */
int wm_refine_set_roi(wm_refiner *r, const int32_t *rows);

/* Runs the next resolution level: level m = current - 1 with k iterations of region selection,
 * pairing, shape-preserving split and regularisation on the details of decomposition level m + 1;
 * at level 0 it then refines every triangle with E(T) > zeta until none is left (or the budget
 * stops it).  Level 0 takes no iterations when the error bound and the final decimation follow
 * (neither WM_FLAG_NO_BOUND nor WM_FLAG_NO_DECIMATE).  With M = 1 the only step is the error bound
 * at level 0.  Fills *st (may be NULL).
 * Returns WM_OK, WM_ERR_STATE when already done, WM_ERR_CAPACITY when the storage ran out (the mesh
 * is valid and can be exported; the refiner is then done). */
int wm_refine_step(wm_refiner *r, wm_level_stats *st);

/* Statistics of the current mesh (level, counts, E_max, over) without running anything. */
void wm_refine_stats(const wm_refiner *r, wm_level_stats *st);

int32_t wm_refine_level(const wm_refiner *r); /* current resolution level */
int wm_refine_done(const wm_refiner *r);      /* 1 after level 0 and the error bound */
const wm_mesh *wm_refine_mesh(const wm_refiner *r);

#ifdef __cplusplus
}
#endif

#endif /* WAVEMESH_H */
