/* The host stages of `wavemesh mesh` in C (include/wm_host.h): quantisation and the final check (the
 * proper-mesh check, the error measure), split over threads.  Compiled with -ffp-contract=off: every
 * product and sum rounds on its own, as numpy's do, so the results equal the Python model's bit for bit. */
#define _POSIX_C_SOURCE 200809L
#include "wm_host.h"

#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define SAMPLE_MAX 65535.0
#define RINT_MAGIC 4503599627370496.0 /* 2^52: (c + 2^52) - 2^52 is rint(c) for 0 <= c < 2^52 */
/* The passes over every sample, compiled twice, for AVX2 too (the loader picks the one the processor
 * runs): the same IEEE operations on twice the lanes, so the same results (no contraction into FMAs:
 * -ffp-contract=off).  WM_NO_CLONES: the default alone, as a processor without AVX2 runs it
 * (tests/host/test_host_stages_default.py builds it so and compares). */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_ADDRESS__) && \
    !defined(WM_NO_CLONES)
#define CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CLONES
#endif
#define MAX_THREADS 64
#define TRI_CHUNK 512 /* triangles a thread takes at a time (their sizes vary a lot) */
/* samples a thread takes at least: starting one costs about what a pass over this many does, more on
 * a busy machine */
#define PART_MIN ((int64_t)1 << 18)
#define EXACT ((int64_t)1 << 52) /* E_k below this: E_k(xl) + a_k k exact in doubles (each term < 2^53) */
#define ABS(v) ((v) < 0 ? -(v) : (v))
#define NAN_BITS ((int64_t)0x7FF0000000000000) /* the bits of +inf: a NaN's (sign clear) are above them */

/* A double >= 0 (or a NaN, sign clear) as its bits, which order as the numbers do (a NaN above every
 * number): the maxima of the passes below are integer maxima, which the compiler vectorises (a double's
 * maximum it may not, without -ffast-math). */
static inline int64_t bits_of(double v)
{
    int64_t b;
    memcpy(&b, &v, sizeof b);
    return b;
}

static inline double of_bits(int64_t b)
{
    double v;
    memcpy(&v, &b, sizeof v);
    return v;
}

static int64_t part_min = PART_MIN;

int64_t wm_host_part_min(int64_t n)
{
    int64_t old = part_min;
    if (n > 0) part_min = n;
    return old;
}

typedef void (*part_fn)(void *ctx, int32_t part, int32_t parts);

struct part_job {
    part_fn fn;
    void *ctx;
    int32_t part, parts;
};

static void *part_main(void *arg)
{
    struct part_job *j = arg;
    j->fn(j->ctx, j->part, j->parts);
    return NULL;
}

/* fn(ctx, p, parts) for p in 0..parts-1, part 0 on this thread, and on it too, after part 0, each part
 * whose thread would not start: every part runs, whatever the threads (every caller's parts write
 * disjoint results). */
static void run_parts(part_fn fn, void *ctx, int32_t parts)
{
    pthread_t tid[MAX_THREADS];
    struct part_job jobs[MAX_THREADS];
    int32_t started = 0;
    if (parts > MAX_THREADS) parts = MAX_THREADS;
    if (parts < 1) parts = 1;
    for (int32_t p = 1; p < parts; p++) {
        jobs[p].fn = fn;
        jobs[p].ctx = ctx;
        jobs[p].part = p;
        jobs[p].parts = parts;
        if (pthread_create(&tid[p], NULL, part_main, &jobs[p]) != 0) break;
        started = p;
    }
    fn(ctx, 0, parts);
    for (int32_t p = started + 1; p < parts; p++) fn(ctx, p, parts);
    for (int32_t p = 1; p <= started; p++) pthread_join(tid[p], NULL);
}

/* How many parts n samples are split into: at most `threads`, each of part_min samples or more. */
static int32_t parts_for(int32_t threads, int64_t n)
{
    int32_t parts = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
    if (n / part_min < parts) parts = n / part_min > 1 ? (int32_t)(n / part_min) : 1;
    return parts;
}

static void part_range(int64_t n, int32_t part, int32_t parts, int64_t *lo, int64_t *hi)
{
    *lo = n / parts * part + (part < n % parts ? part : n % parts);
    *hi = *lo + n / parts + (part < n % parts ? 1 : 0);
}

/* ---------------------------------------------------------------------------------------------- */
/* Quantisation */

struct scan {
    const double *v;
    int64_t n;
    double min[MAX_THREADS], max[MAX_THREADS];
    int32_t finite[MAX_THREADS], integer[MAX_THREADS];
};

/* A double's bits as an integer that orders as the doubles do (-0.0 just below +0.0; a NaN's, never
 * used, anywhere), and back. */
static inline int64_t key_of(double v)
{
    int64_t b = bits_of(v);
    return b < 0 ? b ^ INT64_MAX : b;
}

static inline double of_key(int64_t k) { return of_bits(k < 0 ? k ^ INT64_MAX : k); }

#define SCAN_BLOCK 4096 /* samples between the scan's looks at whether one was not finite */

/* The least and largest height, whether all are finite and whether all are whole numbers, in blocks whose
 * loop has no branch (the compiler vectorises it: integer extremes of key_of, see bits_of). */
static CLONES void scan_part(void *ctx, int32_t part, int32_t parts)
{
    struct scan *s = ctx;
    const double *v = s->v;
    int64_t lo, hi, mn = key_of(INFINITY), mx = key_of(-INFINITY);
    int32_t finite = 1, integer = 1;
    part_range(s->n, part, parts, &lo, &hi);
    for (int64_t b = lo; b < hi; b += SCAN_BLOCK) {
        int64_t end = hi - b < SCAN_BLOCK ? hi : b + SCAN_BLOCK, bad = 0, frac = 0;
        for (int64_t i = b; i < end; i++) {
            double x = v[i];
            int64_t k = key_of(x);
            bad |= (bits_of(x) & NAN_BITS) == NAN_BITS; /* inf or NaN: every exponent bit set */
            double ax = fabs(x); /* whole when 2^52 or more, else when (ax + 2^52) - 2^52, rint, is ax */
            frac |= (ax < RINT_MAGIC) & (((ax + RINT_MAGIC) - RINT_MAGIC) != ax);
            mn = k < mn ? k : mn;
            mx = k > mx ? k : mx;
        }
        if (bad) {
            finite = 0;
            break;
        }
        integer &= !frac;
    }
    s->min[part] = of_key(mn);
    s->max[part] = of_key(mx);
    s->finite[part] = finite;
    s->integer[part] = integer;
}

struct apply {
    const double *v;
    const float *v32; /* the heights as float32 instead (wm_host_quantise_with32; v then NULL), */
    int64_t width, pitch; /* rows of width heights, pitch floats apart (samples: rows of width) */
    uint16_t *samples;
    int64_t n;
    double offset, scale;
    int32_t mode; /* 0: v - offset (integers), 1: zeros, 2: rint((v - offset) / scale) clipped */
    double err[MAX_THREADS];
};

/* Each mode a loop of its own, without branches, which the compiler vectorises.  Mode 2's
 * rint((v - offset) / scale) is (c + 2^52) - 2^52 for the quotient c, as rint rounds (half to even in
 * the default mode) for 0 <= c < 2^51.  c is clipped to 0..65535 first (the same samples as rint then
 * clip: the bounds are whole numbers), so a height outside the range the scale was made for (a tile's,
 * wm_host_quantise_with) is clipped as the model clips it; clipped as its bits, an integer (a double's
 * clip the compiler does not vectorise without -ffast-math): a negative number's bits (sign set) are
 * below 0, a positive one's order as the numbers do (bits_of). */
#define SAMPLE_MAX_BITS ((int64_t)0x40EFFFE000000000) /* bits_of(65535.0) */
/* The three modes' loops over heights read as V(i): a double, or a float widened to the same double */
#define APPLY_LOOPS                                                                             \
    if (a->mode == 0) {                                                                         \
        for (int64_t i = i0; i < i1; i++) {                                                     \
            uint16_t s = (uint16_t)(int32_t)(V(i) - offset);                                    \
            int64_t e = bits_of(fabs(V(i) - (offset + scale * (double)s)));                     \
            samples[i] = s;                                                                     \
            err = e > err ? e : err;                                                            \
        }                                                                                       \
    } else if (a->mode == 1) {                                                                  \
        for (int64_t i = i0; i < i1; i++) {                                                     \
            int64_t e = bits_of(fabs(V(i) - (offset + scale * 0.0)));                           \
            samples[i] = 0;                                                                     \
            err = e > err ? e : err;                                                            \
        }                                                                                       \
    } else {                                                                                    \
        for (int64_t i = i0; i < i1; i++) {                                                     \
            int64_t c = bits_of((V(i) - offset) / scale); /* clipped as bits (see clip_bits) */ \
            c = c < 0 ? 0 : c;                                                                  \
            c = c > SAMPLE_MAX_BITS ? SAMPLE_MAX_BITS : c;                                      \
            uint16_t s = (uint16_t)(int32_t)((of_bits(c) + RINT_MAGIC) - RINT_MAGIC);           \
            int64_t e = bits_of(fabs(V(i) - (offset + scale * (double)s)));                     \
            samples[i] = s;                                                                     \
            err = e > err ? e : err;                                                            \
        }                                                                                       \
    }

static CLONES void apply_part(void *ctx, int32_t part, int32_t parts)
{
    struct apply *a = ctx;
    int64_t lo, hi, err = 0; /* the largest error's bits (bits_of) */
    const double offset = a->offset, scale = a->scale;
    uint16_t *samples = a->samples;
    part_range(a->n, part, parts, &lo, &hi);
    if (a->v32 != NULL) {
        int64_t w = a->width, gap = a->pitch - a->width;
        for (int64_t i0 = lo, i1; i0 < hi; i0 = i1) { /* row by row: height i of row r at v32[i + r gap] */
            int64_t r = i0 / w;
            const float *v32 = a->v32 + r * gap;
            i1 = (r + 1) * w < hi ? (r + 1) * w : hi;
#define V(i) ((double)v32[i])
            APPLY_LOOPS
#undef V
        }
    } else {
        const double *v = a->v;
        int64_t i0 = lo, i1 = hi;
#define V(i) (v[i])
        APPLY_LOOPS
#undef V
    }
    a->err[part] = of_bits(err);
}

int wm_host_quantise(const double *v, int64_t n, int32_t threads, uint16_t *samples, double *out,
                     int32_t *lossless)
{
    struct scan *s = malloc(sizeof *s);
    struct apply *a = malloc(sizeof *a);
    int32_t parts = parts_for(threads, n);
    double mn = INFINITY, mx = -INFINITY, err = 0.0;
    int32_t integer = 1, code = WM_HOST_OK;
    if (s == NULL || a == NULL) {
        code = WM_HOST_NOMEM;
        goto done;
    }
    s->v = v;
    s->n = n;
    run_parts(scan_part, s, parts);
    for (int32_t p = 0; p < parts; p++) {
        if (!s->finite[p]) {
            code = WM_HOST_NONFINITE;
            goto done;
        }
        if (s->min[p] < mn) mn = s->min[p];
        if (s->max[p] > mx) mx = s->max[p];
        integer &= s->integer[p];
    }
    out[3] = mn;
    out[4] = mx;
    mn += 0.0; /* a least height of -0.0 is 0.0 (heightfield.quant_rule's offset) */
    double span = mx - mn;
    if (!isfinite(span)) {
        code = WM_HOST_SPAN;
        goto done;
    }
    a->v = v;
    a->v32 = NULL;
    a->width = a->pitch = n;
    a->samples = samples;
    a->n = n;
    if (span <= SAMPLE_MAX && integer) {
        a->offset = (mn >= 0.0 && mx <= SAMPLE_MAX) ? 0.0 : mn;
        a->scale = 1.0;
        a->mode = 0;
    } else if (span / SAMPLE_MAX == 0.0) {
        a->offset = mn;
        a->scale = 1.0;
        a->mode = 1;
    } else {
        a->offset = mn;
        a->scale = span / SAMPLE_MAX;
        a->mode = 2;
    }
    run_parts(apply_part, a, parts);
    for (int32_t p = 0; p < parts; p++)
        if (a->err[p] > err) err = a->err[p];
    out[0] = a->scale;
    out[1] = a->offset;
    out[2] = err;
    *lossless = err == 0.0;
done:
    free(s);
    free(a);
    return code;
}

static double quantise_with(const double *v, const float *v32, int64_t n, int64_t width, int64_t pitch,
                            double offset, double scale, int32_t exact, int32_t threads, uint16_t *samples)
{
    struct apply a;
    int32_t parts = parts_for(threads, n);
    double err = 0.0;
    a.v = v;
    a.v32 = v32;
    a.width = width;
    a.pitch = pitch;
    a.samples = samples;
    a.n = n;
    a.offset = offset;
    a.scale = scale;
    a.mode = exact ? 0 : 2;
    run_parts(apply_part, &a, parts);
    for (int32_t p = 0; p < parts; p++)
        if (a.err[p] > err) err = a.err[p];
    return err;
}

double wm_host_quantise_with(const double *v, int64_t n, double offset, double scale, int32_t exact,
                             int32_t threads, uint16_t *samples)
{
    return quantise_with(v, NULL, n, n, n, offset, scale, exact, threads, samples);
}

double wm_host_quantise_with32(const float *v, int64_t rows, int64_t width, int64_t pitch, double offset,
                               double scale, int32_t exact, int32_t threads, uint16_t *samples)
{
    return quantise_with(NULL, v, rows * width, width, pitch, offset, scale, exact, threads, samples);
}

struct qerr {
    const double *v;
    const uint16_t *s;
    int64_t n;
    double offset, scale;
    double err[MAX_THREADS];
};

static void qerr_part(void *ctx, int32_t part, int32_t parts)
{
    struct qerr *q = ctx;
    int64_t lo, hi;
    double err = 0.0;
    part_range(q->n, part, parts, &lo, &hi);
    for (int64_t i = lo; i < hi; i++) {
        double e = fabs(q->v[i] - (q->offset + q->scale * (double)q->s[i]));
        if (e > err || e != e) err = e; /* NaN stays, as numpy's max keeps it */
        if (err != err) break;
    }
    q->err[part] = err;
}

double wm_host_quant_error(const double *v, const uint16_t *s, int64_t n, double offset, double scale,
                           int32_t threads)
{
    struct qerr q;
    int32_t parts = parts_for(threads, n);
    double err = 0.0;
    q.v = v;
    q.s = s;
    q.n = n;
    q.offset = offset;
    q.scale = scale;
    run_parts(qerr_part, &q, parts);
    for (int32_t p = 0; p < parts; p++)
        if (q.err[p] > err || q.err[p] != q.err[p]) err = q.err[p];
    return err;
}

/* ---------------------------------------------------------------------------------------------- */
/* A numbering for locality: the error measure and the proper-mesh check read three vertices for every
 * triangle and two for every edge, and a refined mesh numbers its vertices and triangles in the
 * refiner's order, so that in it those reads jump over arrays of megabytes (a cache miss nearly every
 * time: 1.26M triangles on 2048^2, 0.3 s of each pass).  Renumbered, the vertices by row then column and
 * the triangles by their first vertex, the same passes read nearby memory (4x faster).  Both answers are
 * per triangle or for the whole mesh, so the numbering changes nothing else. */

struct local {
    int64_t *xy;      /* vertex coordinates in the new numbering, x and y interleaved */
    double *z;        /* the vertices' heights in it (when given) */
    int64_t *tris;    /* the triangles in the new order, with the new vertex numbers */
    int32_t *tri_old; /* a triangle's index as given, by its new position */
};

static void local_free(struct local *l)
{
    free(l->xy);
    free(l->z);
    free(l->tris);
    free(l->tri_old);
}

/* out = the v indices in (NULL: 0 .. v - 1) stably sorted by c[index * stride] clamped into [0, n - 1]: a
 * counting sort, start (n + 1 entries) its scratch. */
static void by_coord(const int64_t *c, int64_t stride, int64_t n, int64_t v, const int32_t *in, int32_t *out,
                     int64_t *start)
{
    for (int64_t i = 0; i <= n; i++) start[i] = 0;
    for (int64_t i = 0; i < v; i++) {
        int64_t k = c[i * stride];
        start[(k < 0 ? 0 : k > n - 1 ? n - 1 : k) + 1]++;
    }
    for (int64_t i = 0; i < n; i++) start[i + 1] += start[i];
    for (int64_t i = 0; i < v; i++) {
        int64_t o = in != NULL ? in[i] : i, k = c[o * stride];
        out[start[k < 0 ? 0 : k > n - 1 ? n - 1 : k]++] = (int32_t)o;
    }
}

/* Vertex i at (x[i * stride], y[i * stride]), height z[i] (z may be NULL); v vertices, or -1: as many as
 * the triangles name.  0 with *l filled; -1 (nothing kept) when an index is out of range, the counts are
 * beyond int32 or memory is short: the caller then works in the numbering given. */
static int local_order(const int64_t *x, const int64_t *y, int64_t stride, const double *z, int64_t v,
                       const int64_t *tris, int64_t t, int64_t width, int64_t height, struct local *l)
{
    int64_t most = -1;
    l->xy = NULL;
    l->z = NULL;
    l->tris = NULL;
    l->tri_old = NULL;
    if (t <= 0 || t > INT32_MAX || width <= 0 || height <= 0) return -1;
    for (int64_t k = 0; k < 3 * t; k++) {
        if (tris[k] < 0 || (v >= 0 && tris[k] >= v)) return -1;
        if (tris[k] > most) most = tris[k];
    }
    if (v < 0) v = most + 1;
    if (v > INT32_MAX) return -1;
    int64_t n = width > height ? width : height;
    n = n > v ? n : v;
    int32_t *tmp = malloc((size_t)v * sizeof *tmp), *order = malloc((size_t)v * sizeof *order);
    int32_t *inv = malloc((size_t)v * sizeof *inv), *key = malloc((size_t)t * sizeof *key);
    int64_t *start = malloc((size_t)(n + 1) * sizeof *start);
    l->xy = malloc((size_t)(2 * v) * sizeof *l->xy);
    l->z = z != NULL ? malloc((size_t)v * sizeof *l->z) : NULL;
    l->tris = malloc((size_t)(3 * t) * sizeof *l->tris);
    l->tri_old = malloc((size_t)t * sizeof *l->tri_old);
    int ok = tmp != NULL && order != NULL && inv != NULL && key != NULL && start != NULL && l->xy != NULL &&
             (z == NULL || l->z != NULL) && l->tris != NULL && l->tri_old != NULL;
    if (ok) {
        /* the vertices by column, then (stable) by row: two counting sorts, coordinates clamped into the
         * grid (a vertex outside it only sorts at its edge) */
        by_coord(x, stride, width, v, NULL, tmp, start);
        by_coord(y, stride, height, v, tmp, order, start);
        for (int64_t i = 0; i < v; i++) {
            int64_t o = order[i];
            inv[o] = (int32_t)i;
            l->xy[2 * i] = x[o * stride];
            l->xy[2 * i + 1] = y[o * stride];
            if (z != NULL) l->z[i] = z[o];
        }
        /* the triangles by their first vertex in the new numbering (a counting sort) */
        for (int64_t i = 0; i <= v; i++) start[i] = 0;
        for (int64_t k = 0; k < t; k++) {
            int32_t a = inv[tris[3 * k]], b = inv[tris[3 * k + 1]], c = inv[tris[3 * k + 2]];
            int32_t lo = a < b ? a : b;
            key[k] = lo < c ? lo : c;
            start[key[k] + 1]++;
        }
        for (int64_t i = 0; i < v; i++) start[i + 1] += start[i];
        for (int64_t k = 0; k < t; k++) {
            int64_t pos = start[key[k]]++;
            l->tri_old[pos] = (int32_t)k;
            for (int c = 0; c < 3; c++) l->tris[3 * pos + c] = inv[tris[3 * k + c]];
        }
    }
    free(tmp);
    free(order);
    free(inv);
    free(key);
    free(start);
    if (!ok) {
        local_free(l);
        l->xy = NULL;
        l->z = NULL;
        l->tris = NULL;
        l->tri_old = NULL;
        return -1;
    }
    return 0;
}

/* ---------------------------------------------------------------------------------------------- */
/* Per-triangle vertical maxima (check.py's mesh_errors) */

struct trimax {
    const double *h;
    const float *h32; /* the heights as float32 instead (wm_host_tri_max32; h then NULL) */
    int64_t width, height, pitch; /* row y's heights from h[y pitch] (pitch: width, but for h32) */
    const int64_t *x, *y, *tris; /* vertex i at (x[i * stride], y[i * stride]) */
    int64_t stride;
    const double *zv;
    int64_t t;
    const int32_t *tri_old; /* the index as given of the triangle at each position (NULL: the same) */
    double *per_v;
    double *nfac, sx, sy; /* the normal factors (NULL: not asked) and the cell size */
    pthread_mutex_t lock;
    int64_t next; /* the next chunk of triangles to take */
};

static int64_t floor_div(int64_t a, int64_t b) /* b > 0 */
{
    int64_t q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

static inline __attribute__((always_inline)) double tri_max(const struct trimax *m, int64_t t, int64_t out)
{
    const int64_t *tri = m->tris + 3 * t, st = m->stride;
    int64_t x0 = m->x[tri[0] * st], y0 = m->y[tri[0] * st], x1 = m->x[tri[1] * st], y1 = m->y[tri[1] * st];
    int64_t x2 = m->x[tri[2] * st], y2 = m->y[tri[2] * st];
    int64_t d = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    double best = -INFINITY;
    if (m->nfac != NULL) { /* check.mesh_errors's numpy expressions, term for term (inf or NaN when d = 0) */
        double z0 = m->zv[tri[0]], dz1 = m->zv[tri[1]] - z0, dz2 = m->zv[tri[2]] - z0, df = (double)d;
        double sa = (dz1 * (double)(y2 - y0) - dz2 * (double)(y1 - y0)) / df / m->sx;
        double sb = ((double)(x1 - x0) * dz2 - (double)(x2 - x0) * dz1) / df / m->sy;
        m->nfac[out] = hypot(1.0, hypot(sa, sb));
    }
    if (d == 0) return best;
    int64_t sg = d > 0 ? 1 : -1;
    int64_t a[3] = {(y1 - y2) * sg, (y2 - y0) * sg, (y0 - y1) * sg};
    int64_t b[3] = {(x2 - x1) * sg, (x0 - x2) * sg, (x1 - x0) * sg};
    int64_t c[3] = {(x1 * y2 - x2 * y1) * sg, (x2 * y0 - x0 * y2) * sg, (x0 * y1 - x1 * y0) * sg};
    int64_t xmin = x0 < x1 ? x0 : x1, xmax = x0 > x1 ? x0 : x1, ymin = y0 < y1 ? y0 : y1, ymax = y0 > y1 ? y0 : y1;
    if (x2 < xmin) xmin = x2;
    if (x2 > xmax) xmax = x2;
    if (y2 < ymin) ymin = y2;
    if (y2 > ymax) ymax = y2;
    if (xmin < 0) xmin = 0;
    if (ymin < 0) ymin = 0;
    if (xmax > m->width - 1) xmax = m->width - 1;
    if (ymax > m->height - 1) ymax = m->height - 1;
    double z0 = m->zv[tri[0]];
    double dz1 = m->zv[tri[1]] - z0, dz2 = m->zv[tri[2]] - z0;
    double absd = (double)(d < 0 ? -d : d);
    for (int64_t yy = ymin; yy <= ymax; yy++) {
        int64_t xl = xmin, xr = xmax, num[3];
        int empty = 0;
        for (int k = 0; k < 3; k++) {
            num[k] = b[k] * yy + c[k]; /* E_k(x, y) = a_k x + num_k >= 0 */
            int64_t q = floor_div(num[k], a[k] < 0 ? -a[k] : a[k] > 0 ? a[k] : 1);
            if (a[k] > 0 && -q > xl) xl = -q;
            if (a[k] < 0 && q < xr) xr = q;
            if (a[k] == 0 && num[k] < 0) empty = 1;
        }
        if (empty || xr < xl) continue;
        int64_t at = yy * m->pitch + xl; /* the row's first sample */
        int64_t e1l = a[1] * xl + num[1], e2l = a[2] * xl + num[2];
        int64_t e1r = a[1] * xr + num[1], e2r = a[2] * xr + num[2];
        if (ABS(e1l) < EXACT && ABS(e2l) < EXACT && ABS(e1r) < EXACT && ABS(e2r) < EXACT) {
            /* every E_k on the row is an integer below 2^52: e_k(xl) + a_k k in doubles is exact, as
             * numpy's conversion of the int64 E_k is; a loop the compiler vectorises */
            double e1 = (double)e1l, e2 = (double)e2l, da1 = (double)a[1], da2 = (double)a[2];
            int32_t n = (int32_t)(xr - xl + 1);
            int64_t rb = 0; /* the row's largest |h - plane| as its bits (bits_of) */
#define ROW_BITS(ROW)                                                                                \
    for (int32_t k = 0; k < n; k++) {                                                                \
        double kd = (double)k;                                                                       \
        double plane = z0 + ((e1 + da1 * kd) * dz1 + (e2 + da2 * kd) * dz2) / absd;                  \
        int64_t v = bits_of(fabs((double)(ROW)[k] - plane)); /* a float widens to the same double */ \
        rb = v > rb ? v : rb;                                                                        \
    }
            if (m->h32 != NULL) {
                ROW_BITS(m->h32 + at)
            } else {
                ROW_BITS(m->h + at)
            }
#undef ROW_BITS
            if (rb > NAN_BITS) return NAN; /* numpy's maximum keeps a NaN */
            best = of_bits(rb) > best ? of_bits(rb) : best;
            continue;
        }
        for (int64_t xx = xl; xx <= xr; xx++) {
            int64_t e1 = a[1] * xx + num[1], e2 = a[2] * xx + num[2];
            double plane = z0 + ((double)e1 * dz1 + (double)e2 * dz2) / absd;
            int64_t i = at + xx - xl;
            double v = fabs((m->h32 != NULL ? (double)m->h32[i] : m->h[i]) - plane);
            if (v > best || v != v) best = v;
            if (best != best) return best;
        }
    }
    return best;
}

static CLONES void trimax_part(void *ctx, int32_t part, int32_t parts)
{
    struct trimax *m = ctx;
    (void)part;
    for (;;) {
        int64_t lo;
        if (parts > 1) pthread_mutex_lock(&m->lock);
        lo = m->next;
        m->next += TRI_CHUNK;
        if (parts > 1) pthread_mutex_unlock(&m->lock);
        if (lo >= m->t) break;
        int64_t hi = lo + TRI_CHUNK < m->t ? lo + TRI_CHUNK : m->t;
        for (int64_t t = lo; t < hi; t++) {
            int64_t out = m->tri_old != NULL ? m->tri_old[t] : t;
            m->per_v[out] = tri_max(m, t, out);
        }
    }
}

static int tri_max_all(const double *h, const float *h32, int32_t width, int32_t height, int64_t pitch,
                       const int64_t *x, const int64_t *y, const double *zv, const int64_t *tris, int64_t t,
                       double *per_v, double *nfac, double sx, double sy, int32_t threads)
{
    struct trimax m;
    int32_t parts = parts_for(threads, (int64_t)width * height); /* the triangles cover the grid once */
    if ((int64_t)parts > (t + TRI_CHUNK - 1) / TRI_CHUNK) parts = (int32_t)((t + TRI_CHUNK - 1) / TRI_CHUNK);
    m.h = h;
    m.h32 = h32;
    m.pitch = pitch;
    m.width = width;
    m.height = height;
    struct local l;
    int local = local_order(x, y, 1, zv, -1, tris, t, width, height, &l) == 0;
    m.x = local ? l.xy : x;
    m.y = local ? l.xy + 1 : y;
    m.stride = local ? 2 : 1;
    m.tris = local ? l.tris : tris;
    m.zv = local ? l.z : zv;
    m.tri_old = local ? l.tri_old : NULL;
    m.t = t;
    m.per_v = per_v;
    m.nfac = nfac;
    m.sx = sx;
    m.sy = sy;
    m.next = 0;
    if (parts > 1 && pthread_mutex_init(&m.lock, NULL) != 0) parts = 1;
    run_parts(trimax_part, &m, parts);
    if (parts > 1) pthread_mutex_destroy(&m.lock);
    if (local) local_free(&l);
    return WM_HOST_OK;
}

int wm_host_tri_max(const double *h, int32_t width, int32_t height, const int64_t *x, const int64_t *y,
                    const double *zv, const int64_t *tris, int64_t t, double *per_v, double *nfac, double sx,
                    double sy, int32_t threads)
{
    return tri_max_all(h, NULL, width, height, width, x, y, zv, tris, t, per_v, nfac, sx, sy, threads);
}

int wm_host_tri_max32(const float *h, int32_t width, int32_t height, int64_t pitch, const int64_t *x,
                      const int64_t *y, const double *zv, const int64_t *tris, int64_t t, double *per_v,
                      double *nfac, double sx, double sy, int32_t threads)
{
    return tri_max_all(NULL, h, width, height, pitch, x, y, zv, tris, t, per_v, nfac, sx, sy, threads);
}

/* ---------------------------------------------------------------------------------------------- */
/* The proper-triangulation check (check.py's check_mesh) for a mesh that passes it */

#define CHECK_CELLS ((int64_t)1 << 30)   /* the occupancy bitmap's largest grid (128 MiB) */
#define LATTICE_PER_ELEMENT 64          /* inner lattice points visited: per vertex and triangle, */
#define LATTICE_FREE ((int64_t)1 << 24) /* and these (~20 ms) besides, at most */
#define LINEAR_DEGREE 16 /* out-neighbours searched one by one up to this many, else sorted */

static int64_t gcd64(int64_t a, int64_t b) /* a, b >= 0; most edges are short: no division for them */
{
    if (a <= 1 || b <= 1) return a == 0 ? b : b == 0 ? a : 1;
    while (b != 0) {
        int64_t r = a % b;
        a = b;
        b = r;
    }
    return a;
}

static int bit_get(const uint8_t *bits, int64_t i) { return (bits[i >> 3] >> (i & 7)) & 1; }

/* The sorted out-neighbours dst[lo..hi) hold want (binary search). */
static int holds(const int32_t *dst, int64_t lo, int64_t end, int32_t want)
{
    int64_t hi = end;
    while (lo < hi) {
        int64_t mid = lo + (hi - lo) / 2;
        if (dst[mid] < want) lo = mid + 1;
        else hi = mid;
    }
    return lo < end && dst[lo] == want;
}

/* dst[lo..hi) holds want (a vertex's few out-neighbours: a linear search). */
static int in_list(const int32_t *dst, int64_t lo, int64_t hi, int32_t want)
{
    for (int64_t i = lo; i < hi; i++)
        if (dst[i] == want) return 1;
    return 0;
}

static int cmp_i32(const void *a, const void *b)
{
    int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
    return (x > y) - (x < y);
}

static void sort_i32(int32_t *a, int64_t n) { qsort(a, (size_t)n, sizeof *a, cmp_i32); }

/* The edges of the vertices of one part (their out-neighbours listed): 4. and 5. of check_mesh. */
struct edges {
    const int64_t *xy, *start;
    const int32_t *dst;
    const uint8_t *grid;
    int64_t W, H, v, budget;
    int32_t code[MAX_THREADS]; /* per part: 1 passed, 0 failed, -1 over its lattice budget */
};

static void edges_part(void *ctx, int32_t part, int32_t parts)
{
    struct edges *e = ctx;
    const int64_t *xy = e->xy, *start = e->start;
    const int32_t *dst = e->dst;
    int64_t W = e->W, H = e->H, lattice = 0, first, last;
    e->code[part] = 0; /* until the part's edges all pass */
    part_range(e->v, part, parts, &first, &last);
    for (int64_t a = first; a < last; a++) {
        int64_t xa = xy[2 * a], ya = xy[2 * a + 1], lo = start[a], hi = start[a + 1];
        for (int64_t j = lo; j < hi; j++) {
            int32_t bb = dst[j];
            if (hi - lo > LINEAR_DEGREE ? (j > lo && dst[j - 1] == bb) : in_list(dst, lo, j, bb))
                return; /* a directed edge twice */
            int64_t xb = xy[2 * (int64_t)bb], yb = xy[2 * (int64_t)bb + 1];
            int back = start[bb + 1] - start[bb] > LINEAR_DEGREE
                           ? holds(dst, start[bb], start[bb + 1], (int32_t)a)
                           : in_list(dst, start[bb], start[bb + 1], (int32_t)a);
            if (!back && !((xa == xb && (xa == 0 || xa == W - 1)) || (ya == yb && (ya == 0 || ya == H - 1))))
                return; /* an edge of one triangle inside the rectangle */
            if (back && a > bb) continue; /* an inner edge: its lattice points once */
            /* 5. no vertex strictly inside an edge: every inner lattice point looked up, within a budget
             * (a mesh of a few long edges over a huge grid is Python's, which tests vertex by vertex) */
            int64_t dx = xb - xa, dy = yb - ya;
            int64_t g = gcd64(dx < 0 ? -dx : dx, dy < 0 ? -dy : dy);
            if (g < 2) continue;
            lattice += g - 1;
            if (lattice > e->budget) {
                e->code[part] = -1;
                return;
            }
            int64_t sx = dx / g, sy = dy / g;
            for (int64_t k = 1; k < g; k++)
                if (bit_get(e->grid, (ya + k * sy) * W + xa + k * sx)) return;
        }
    }
    e->code[part] = 1;
}

int wm_host_check_mesh(int64_t width, int64_t height, const int64_t *xy, int64_t v, const int64_t *tris, int64_t t,
                       int32_t threads, int64_t *border)
{
    int64_t W = width, H = height, b = 0, total = 0;
    uint8_t *grid = NULL, *used = NULL;
    int64_t *start = NULL;
    int32_t *dst = NULL;
    int code = 0;
    *border = 0;
    if (W < 2 || H < 2 || v <= 0 || t <= 0) return 0;
    if (W > CHECK_CELLS || H > CHECK_CELLS || W * H > CHECK_CELLS || v > INT32_MAX || t > INT32_MAX / 3) return -1;
    struct local l;
    int local = local_order(xy, xy + 1, 2, NULL, v, tris, t, W, H, &l) == 0;
    if (local) { /* the same mesh, renumbered: the same verdict, the same border count */
        xy = l.xy;
        tris = l.tris;
    }
    grid = calloc((size_t)((W * H + 7) / 8), 1);
    used = calloc((size_t)v, 1);
    start = calloc((size_t)v + 1, sizeof *start);
    dst = malloc((size_t)(3 * t) * sizeof *dst);
    if (grid == NULL || used == NULL || start == NULL || dst == NULL) {
        code = -1;
        goto done;
    }
    /* 1. vertices: in the rectangle, distinct (the bitmap), on the border counted */
    for (int64_t i = 0; i < v; i++) {
        int64_t x = xy[2 * i], y = xy[2 * i + 1];
        if (x < 0 || x > W - 1 || y < 0 || y > H - 1) goto done;
        int64_t cell = y * W + x;
        if (bit_get(grid, cell)) goto done;
        grid[cell >> 3] |= (uint8_t)(1u << (cell & 7));
        b += x == 0 || y == 0 || x == W - 1 || y == H - 1;
    }
    *border = b;
    /* indices in range, every vertex used; 2. counter-clockwise; 3. the areas' sum; out-degrees */
    for (int64_t k = 0; k < t; k++) {
        const int64_t *tri = tris + 3 * k;
        for (int c = 0; c < 3; c++) {
            if (tri[c] < 0 || tri[c] >= v) goto done;
            used[tri[c]] = 1;
            start[tri[c] + 1]++;
        }
        int64_t x0 = xy[2 * tri[0]], y0 = xy[2 * tri[0] + 1];
        int64_t area2 =
            (xy[2 * tri[1]] - x0) * (xy[2 * tri[2] + 1] - y0) - (xy[2 * tri[2]] - x0) * (xy[2 * tri[1] + 1] - y0);
        if (area2 <= 0) goto done;
        total += area2; /* each below 2 W H <= 2^31, t below 2^31: no overflow */
    }
    for (int64_t i = 0; i < v; i++)
        if (!used[i]) goto done;
    if (total != 2 * (W - 1) * (H - 1)) goto done;
    if (t != 2 * v - b - 2) goto done; /* 6. Euler */
    /* 4. edges, each vertex's out-neighbours listed: no directed edge twice; an edge whose reverse is
     * missing lies on the border (no edge can then have more than two triangles) */
    for (int64_t i = 0; i < v; i++) start[i + 1] += start[i];
    {
        int64_t *fill = malloc((size_t)v * sizeof *fill);
        if (fill == NULL) {
            code = -1;
            goto done;
        }
        for (int64_t i = 0; i < v; i++) fill[i] = start[i];
        for (int64_t k = 0; k < t; k++)
            for (int c = 0; c < 3; c++) dst[fill[tris[3 * k + c]]++] = (int32_t)tris[3 * k + (c + 1) % 3];
        free(fill);
    }
    for (int64_t i = 0; i < v; i++) /* a long list sorted: searched by halves below */
        if (start[i + 1] - start[i] > LINEAR_DEGREE) sort_i32(dst + start[i], start[i + 1] - start[i]);
    {
        struct edges e = {xy, start, dst, grid, W, H, v, (LATTICE_PER_ELEMENT * (v + t) + LATTICE_FREE), {0}};
        int32_t parts = parts_for(threads, 3 * t);
        e.budget /= parts; /* each part's share: a part over it answers -1 (Python decides) */
        run_parts(edges_part, &e, parts);
        code = 1; /* every part passed: proper; any failed: not; else one over its budget: undecided */
        for (int32_t p = 0; p < parts; p++)
            if (e.code[p] == -1) code = -1;
        for (int32_t p = 0; p < parts; p++)
            if (e.code[p] == 0) code = 0;
    }
done:
    free(grid);
    free(used);
    free(start);
    free(dst);
    if (local) local_free(&l);
    return code;
}

/* ---------------------------------------------------------------------------------------------- */
/* The OBJ face lines (meshio.write_obj) */

/* i in decimal at p (the OBJ lines' integers) */
static char *put_int(char *p, int64_t i)
{
    char digits[20];
    int n = 0;
    uint64_t u = (uint64_t)i;
    if (i < 0) {
        *p++ = '-';
        u = 0u - u;
    }
    do {
        digits[n++] = (char)('0' + u % 10u);
        u /= 10u;
    } while (u != 0u);
    while (n > 0) *p++ = digits[--n];
    return p;
}

static char *put_index(char *p, int64_t i)
{
    return put_int(p, (int64_t)((uint64_t)i + 1u)); /* index + 1, wrapping as numpy's int64 addition does */
}

int64_t wm_host_obj_faces(const int64_t *tris, int64_t t, char *out)
{
    char *p = out;
    for (int64_t k = 0; k < 3 * t; k += 3) {
        *p++ = 'f';
        for (int c = 0; c < 3; c++) {
            *p++ = ' ';
            p = put_index(p, tris[k + c]);
        }
        *p++ = '\n';
    }
    return (int64_t)(p - out);
}

/* ---------------------------------------------------------------------------------------------- */
/* The OBJ vertex lines (meshio.write_obj): "v x y z", z as Python's repr(float) writes it, the shortest
 * decimal that reads back to the same double and of those the nearest (a tie to the even last digit).
 * Exact in integers: for 1e-4 <= |z| < 2^53, z = m 2^q, the doubles that read back to z are those within
 * half a step of it (2^(q-1); 2^(q-2) below a power of two; the ends only for an even m, as a reader
 * rounds ties to even), here in units of 2^(q-2): 4m - 2 (4m - 1) .. 4m + 2.  Scaled by 10^g to 17
 * digits (10^16 <= 4m 10^g 2^(q-2) < 10^17), the decimals of 17 - j digits are the multiples of 10^j
 * there; the largest j with one between the ends gives the shortest, the nearest of them the digits
 * (every product below 2^125; a tie between two to the even one, as repr's).  Other heights are left to
 * the caller's repr: see wm_host_obj_vertices. */

#ifdef __SIZEOF_INT128__
__extension__ typedef unsigned __int128 u128; /* GCC's and Clang's on 64-bit hosts */

static const uint64_t POW10[17] = {1u,
                                   10u,
                                   100u,
                                   1000u,
                                   10000u,
                                   100000u,
                                   1000000u,
                                   10000000u,
                                   100000000u,
                                   1000000000u,
                                   10000000000u,
                                   100000000000u,
                                   1000000000000u,
                                   10000000000000u,
                                   100000000000000u,
                                   1000000000000000u,
                                   10000000000000000u};

static u128 pow10_128(int g)
{
    u128 r = 1u;
    while (g-- > 0) r *= 10u;
    return r;
}

/* repr(v) at p; NULL for a height left to the caller. */
static char *put_repr(char *p, double v)
{
    uint64_t b = (uint64_t)bits_of(v), frac = b & ((UINT64_C(1) << 52) - 1u);
    int bexp = (int)((b >> 52) & 0x7FFu), neg = (int)(b >> 63);
    if (bexp == 0 && frac == 0) { /* 0.0, -0.0 */
        if (neg) *p++ = '-';
        memcpy(p, "0.0", 3);
        return p + 3;
    }
    double a = fabs(v);
    if (!(a >= 1e-4 && a < 9007199254740992.0)) return NULL; /* 2^53; a NaN fails too */
    uint64_t m = frac | (UINT64_C(1) << 52);
    int s = 2 - (bexp - 1075); /* units of 2^-s: z is 4m; 2 <= s <= 68 */
    int incl = (m & 1u) == 0u;
    u128 mask = ((u128)1 << s) - 1u;
    uint64_t four = m << 2, low = four - ((frac == 0 && bexp > 1) ? 1u : 2u), high = four + 2u;
    int g = 16 - (int)floor(log10(a));
    u128 vg = (u128)four * pow10_128(g);
    while ((vg >> s) < POW10[16]) vg = (u128)four * pow10_128(++g);
    while ((vg >> s) >= POW10[16] * 10u) vg = (u128)four * pow10_128(--g);
    u128 lg = (u128)low * pow10_128(g), hg = (u128)high * pow10_128(g);
    uint64_t vf = (uint64_t)(vg >> s), lf = (uint64_t)(lg >> s), hf = (uint64_t)(hg >> s);
    u128 vr = vg & mask;
    uint64_t lo = lf + (((lg & mask) != 0u || !incl) ? 1u : 0u);
    uint64_t hi = ((hg & mask) != 0u || incl) ? hf : hf - 1u;
    if (lo > hi) return NULL;
    int j = 16;
    while (j > 0 && hi / POW10[j] * POW10[j] < lo) j--;
    uint64_t pw = POW10[j], d = vf / pw;
    u128 twice = ((u128)(vf % pw) << (s + 1)) + (vr << 1), unit = (u128)pw << s;
    if (twice > unit || (twice == unit && (d & 1u))) d++; /* a tie to the even digit, as repr's */
    if (d * pw < lo || d * pw > hi) return NULL;
    char digits[20];
    int n = 0;
    while (d % 10u == 0u) { /* the trailing zeros: the point's place counts them */
        d /= 10u;
        j++;
    }
    do {
        digits[n++] = (char)('0' + d % 10u);
        d /= 10u;
    } while (d != 0u);
    int point = n + j - g; /* z = 0.d1 d2 ... 10^point */
    if (point <= -4 || point > 16) return NULL;
    if (neg) *p++ = '-';
    if (point <= 0) {
        *p++ = '0';
        *p++ = '.';
        for (int k = 0; k < -point; k++) *p++ = '0';
        while (n > 0) *p++ = digits[--n];
    } else {
        for (int k = 0; k < point; k++) *p++ = k < n ? digits[n - 1 - k] : '0';
        *p++ = '.';
        if (point >= n) *p++ = '0';
        for (int k = point; k < n; k++) *p++ = digits[n - 1 - k];
    }
    return p;
}

#endif

int64_t wm_host_obj_vertices(const int64_t *xy, const double *z, int64_t n, char *out, int64_t *left,
                             int64_t *n_left)
{
    char *p = out;
    *n_left = 0;
#ifndef __SIZEOF_INT128__
    (void)xy;
    (void)z;
    (void)n;
    (void)left;
    return -1; /* the caller writes every line */
#else
    for (int64_t i = 0; i < n; i++) {
        *p++ = 'v';
        *p++ = ' ';
        p = put_int(p, xy[2 * i]);
        *p++ = ' ';
        p = put_int(p, xy[2 * i + 1]);
        *p++ = ' ';
        char *after = put_repr(p, z[i]);
        if (after == NULL) {
            *p++ = '\0';
            left[(*n_left)++] = i;
        } else {
            p = after;
        }
        *p++ = '\n';
    }
    return (int64_t)(p - out);
#endif
}
