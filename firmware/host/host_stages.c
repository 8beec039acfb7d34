/* The host stages of `wavemesh mesh` in C (include/wm_host.h): quantisation and the final check's
 * error measure, split over threads.  Compiled with -ffp-contract=off: every product and sum rounds
 * on its own, as numpy's do, so the results equal the Python model's bit for bit. */
#define _POSIX_C_SOURCE 200809L
#include "wm_host.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>

#define SAMPLE_MAX 65535.0
#define MAX_THREADS 64
#define TRI_CHUNK 512
#define EXACT ((int64_t)1 << 52) /* E_k below this: E_k(xl) + a_k k exact in doubles (each term < 2^53) */
#define ABS(v) ((v) < 0 ? -(v) : (v)) /* triangles a thread takes at a time (their sizes vary a lot) */

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

/* fn(ctx, p, parts) for p in 0..parts-1, part 0 on this thread; WM_HOST_NOMEM when a thread could
 * not be started (the parts that ran are not undone: every caller's parts write disjoint results, and
 * the caller then runs again on one thread). */
static int run_parts(part_fn fn, void *ctx, int32_t parts)
{
    pthread_t tid[MAX_THREADS];
    struct part_job jobs[MAX_THREADS];
    int32_t started = 0, ok = 1;
    if (parts > MAX_THREADS) parts = MAX_THREADS;
    if (parts <= 1) {
        fn(ctx, 0, 1);
        return WM_HOST_OK;
    }
    for (int32_t p = 1; p < parts; p++) {
        jobs[p].fn = fn;
        jobs[p].ctx = ctx;
        jobs[p].part = p;
        jobs[p].parts = parts;
        if (pthread_create(&tid[p], NULL, part_main, &jobs[p]) != 0) {
            ok = 0;
            break;
        }
        started = p;
    }
    if (ok) fn(ctx, 0, parts);
    for (int32_t p = 1; p <= started; p++) pthread_join(tid[p], NULL);
    return ok ? WM_HOST_OK : WM_HOST_NOMEM;
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

static void scan_part(void *ctx, int32_t part, int32_t parts)
{
    struct scan *s = ctx;
    int64_t lo, hi;
    double mn = INFINITY, mx = -INFINITY;
    int32_t finite = 1, integer = 1;
    part_range(s->n, part, parts, &lo, &hi);
    for (int64_t i = lo; i < hi; i++) {
        double x = s->v[i];
        if (!isfinite(x)) {
            finite = 0;
            break;
        }
        if (x < mn) mn = x;
        if (x > mx) mx = x;
        if (integer && floor(x) != x) integer = 0;
    }
    s->min[part] = mn;
    s->max[part] = mx;
    s->finite[part] = finite;
    s->integer[part] = integer;
}

struct apply {
    const double *v;
    uint16_t *samples;
    int64_t n;
    double offset, scale;
    int32_t mode; /* 0: v - offset (integers), 1: zeros, 2: rint((v - offset) / scale) clipped */
    double err[MAX_THREADS];
};

static void apply_part(void *ctx, int32_t part, int32_t parts)
{
    struct apply *a = ctx;
    int64_t lo, hi;
    double err = 0.0;
    part_range(a->n, part, parts, &lo, &hi);
    for (int64_t i = lo; i < hi; i++) {
        double x = a->v[i], c;
        uint16_t s;
        if (a->mode == 0) {
            s = (uint16_t)(x - a->offset);
        } else if (a->mode == 1) {
            s = 0;
        } else {
            c = rint((x - a->offset) / a->scale);
            s = (uint16_t)(c < 0.0 ? 0.0 : c > SAMPLE_MAX ? SAMPLE_MAX : c);
        }
        a->samples[i] = s;
        double r = a->offset + a->scale * (double)s;
        double e = fabs(x - r);
        if (e > err) err = e;
    }
    a->err[part] = err;
}

int wm_host_quantise(const double *v, int64_t n, int32_t threads, uint16_t *samples, double *out,
                     int32_t *lossless)
{
    struct scan *s = malloc(sizeof *s);
    struct apply *a = malloc(sizeof *a);
    int32_t parts = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
    double mn = INFINITY, mx = -INFINITY, err = 0.0;
    int32_t integer = 1, code = WM_HOST_OK;
    if (s == NULL || a == NULL) {
        code = WM_HOST_NOMEM;
        goto done;
    }
    if ((int64_t)parts > n) parts = n > 0 ? (int32_t)n : 1;
    s->v = v;
    s->n = n;
    if ((code = run_parts(scan_part, s, parts)) != WM_HOST_OK) goto done;
    for (int32_t p = 0; p < parts; p++) {
        if (!s->finite[p]) {
            code = WM_HOST_NONFINITE;
            goto done;
        }
        if (s->min[p] < mn) mn = s->min[p];
        if (s->max[p] > mx) mx = s->max[p];
        integer &= s->integer[p];
    }
    double span = mx - mn;
    if (!isfinite(span)) {
        code = WM_HOST_SPAN;
        goto done;
    }
    a->v = v;
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
    if ((code = run_parts(apply_part, a, parts)) != WM_HOST_OK) goto done;
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
    int32_t parts = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
    double err = 0.0;
    if ((int64_t)parts > n) parts = n > 0 ? (int32_t)n : 1;
    q.v = v;
    q.s = s;
    q.n = n;
    q.offset = offset;
    q.scale = scale;
    if (run_parts(qerr_part, &q, parts) != WM_HOST_OK) {
        parts = 1;
        qerr_part(&q, 0, 1);
    }
    for (int32_t p = 0; p < parts; p++)
        if (q.err[p] > err || q.err[p] != q.err[p]) err = q.err[p];
    return err;
}

/* ---------------------------------------------------------------------------------------------- */
/* Per-triangle vertical maxima (check.py's mesh_errors) */

struct trimax {
    const double *h;
    int64_t width, height;
    const int64_t *x, *y, *tris;
    const double *zv;
    int64_t t;
    double *per_v;
    pthread_mutex_t lock;
    int64_t next; /* the next chunk of triangles to take */
};

static int64_t floor_div(int64_t a, int64_t b) /* b > 0 */
{
    int64_t q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

static double tri_max(const struct trimax *m, int64_t t)
{
    const int64_t *tri = m->tris + 3 * t;
    int64_t x0 = m->x[tri[0]], y0 = m->y[tri[0]], x1 = m->x[tri[1]], y1 = m->y[tri[1]];
    int64_t x2 = m->x[tri[2]], y2 = m->y[tri[2]];
    int64_t d = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    double best = -INFINITY;
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
        const double *row = m->h + yy * m->width + xl;
        int64_t e1l = a[1] * xl + num[1], e2l = a[2] * xl + num[2];
        int64_t e1r = a[1] * xr + num[1], e2r = a[2] * xr + num[2];
        if (ABS(e1l) < EXACT && ABS(e2l) < EXACT && ABS(e1r) < EXACT && ABS(e2r) < EXACT) {
            /* every E_k on the row is an integer below 2^52: e_k(xl) + a_k k in doubles is exact, as
             * numpy's conversion of the int64 E_k is; a loop the compiler vectorises */
            double e1 = (double)e1l, e2 = (double)e2l, da1 = (double)a[1], da2 = (double)a[2], rb = best;
            int32_t n = (int32_t)(xr - xl + 1), nan = 0;
            for (int32_t k = 0; k < n; k++) {
                double kd = (double)k;
                double plane = z0 + ((e1 + da1 * kd) * dz1 + (e2 + da2 * kd) * dz2) / absd;
                double v = fabs(row[k] - plane);
                rb = v > rb ? v : rb;
                nan |= v != v;
            }
            if (nan) return NAN; /* numpy's maximum keeps a NaN */
            best = rb;
            continue;
        }
        for (int64_t xx = xl; xx <= xr; xx++) {
            int64_t e1 = a[1] * xx + num[1], e2 = a[2] * xx + num[2];
            double plane = z0 + ((double)e1 * dz1 + (double)e2 * dz2) / absd;
            double v = fabs(row[xx - xl] - plane);
            if (v > best || v != v) best = v;
            if (best != best) return best;
        }
    }
    return best;
}

static void trimax_part(void *ctx, int32_t part, int32_t parts)
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
        for (int64_t t = lo; t < hi; t++) m->per_v[t] = tri_max(m, t);
    }
}

int wm_host_tri_max(const double *h, int32_t width, int32_t height, const int64_t *x, const int64_t *y,
                    const double *zv, const int64_t *tris, int64_t t, double *per_v, int32_t threads)
{
    struct trimax m;
    int32_t parts = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
    if ((int64_t)parts > (t + TRI_CHUNK - 1) / TRI_CHUNK) parts = (int32_t)((t + TRI_CHUNK - 1) / TRI_CHUNK);
    m.h = h;
    m.width = width;
    m.height = height;
    m.x = x;
    m.y = y;
    m.tris = tris;
    m.zv = zv;
    m.t = t;
    m.per_v = per_v;
    m.next = 0;
    if (parts > 1 && pthread_mutex_init(&m.lock, NULL) != 0) parts = 1;
    if (run_parts(trimax_part, &m, parts) != WM_HOST_OK) trimax_part(&m, 0, 1); /* the chunks left */
    if (parts > 1) pthread_mutex_destroy(&m.lock);
    return WM_HOST_OK;
}
