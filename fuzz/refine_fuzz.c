/*
 * fuzz_refine: the refiner (firmware/src) on random grids and parameters, under ASan and UBSan, with
 * the library's own asserts on (WM_CHECK=1: the invariant check after every operator).
 *
 * Each input is a job: W x H (2..40), M, tau, every field of wm_params within the range
 * wm_params_check accepts, a triangle storage (from just enough to never running out) and the
 * heights, drawn from the input's bytes in one of a few shapes (raw noise, ramps, cliffs, a
 * constant, a few spikes on a plane).  The pipeline is the native device's: wm_haar, the template
 * stage in C (firmware/board/native/native_job.c), wm_refine_init, wm_refine_step to the end.
 *
 * Checked independently of the library, after every level (an abort is a finding):
 *   - the mesh is a proper triangulation of the W x H rectangle: every triangle counter-clockwise,
 *     the doubled areas add up to 2 (W-1)(H-1), every edge is shared by two triangles in opposite
 *     directions or lies on the rectangle's border, no two vertices at one sample;
 *   - at the end, when the refiner reports every triangle within zeta (over == 0, the bound on),
 *     every triangle's exact E(T) (vertical or normal, computed here in double from the samples) is
 *     <= zeta; when it does not, the triangle budget or the storage stopped it.
 *
 *   build/fuzz/fuzz_refine CORPUS...        (make fuzz; fuzz/README.md)
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "native_job.h"
#include "wavemesh.h"

#define MAX_SIDE 40

/* The input as a stream of numbers; zeros once it runs out. */
typedef struct {
    const uint8_t *d;
    size_t n, pos;
} src;

static uint32_t take(src *s, int bytes)
{
    uint32_t v = 0;
    for (int i = 0; i < bytes; i++) v = v << 8 | (s->pos < s->n ? s->d[s->pos++] : 0);
    return v;
}

static uint32_t pick(src *s, uint32_t lo, uint32_t hi)
{ /* lo..hi inclusive */
    uint32_t span = hi - lo + 1;
    return lo + (span > 255 ? (span > 65535 ? take(s, 4) : take(s, 2)) : take(s, 1)) % span;
}

/* A 32-bit value over many magnitudes: 4 bytes, then a right shift of 0..31 (read in that order: the
 * input means the same whatever order a compiler evaluates operands in). */
static uint32_t scaled(src *s)
{
    uint32_t v = take(s, 4);
    return v >> pick(s, 0, 31);
}

#define FAIL(...)                                     \
    do {                                              \
        fprintf(stderr, "fuzz_refine: " __VA_ARGS__); \
        fprintf(stderr, "\n");                        \
        abort();                                      \
    } while (0)

static void heights(src *s, uint16_t *h, int32_t w, int32_t ht)
{
    uint32_t shape = pick(s, 0, 5), amp = pick(s, 0, 65535);
    int32_t n = w * ht;
    switch (shape) {
    case 0: /* raw 16-bit noise from the input (repeated when it runs short) */
    case 1: {
        size_t start = s->pos;
        for (int32_t i = 0; i < n; i++) {
            if (s->pos + 2 > s->n) s->pos = start;
            h[i] = (uint16_t)(s->pos + 2 <= s->n ? take(s, 2) : (uint32_t)i * 2654435761u >> 16);
            if (shape == 1) h[i] = (uint16_t)(h[i] % (amp + 1));
        }
        break;
    }
    case 2: { /* a plane with a cliff */
        int32_t gx = (int32_t)pick(s, 0, 2000) - 1000, gy = (int32_t)pick(s, 0, 2000) - 1000;
        int32_t cx = (int32_t)pick(s, 0, (uint32_t)w), jump = (int32_t)pick(s, 0, 65535);
        for (int32_t y = 0; y < ht; y++)
            for (int32_t x = 0; x < w; x++) {
                int64_t v = 32768 + (int64_t)gx * x + (int64_t)gy * y + (x >= cx ? jump - 32768 : 0);
                h[y * w + x] = (uint16_t)(v < 0 ? 0 : v > 65535 ? 65535 : v);
            }
        break;
    }
    case 3: /* a constant */
        for (int32_t i = 0; i < n; i++) h[i] = (uint16_t)amp;
        break;
    case 4: { /* spikes on a plane */
        uint32_t k = pick(s, 1, 8);
        for (int32_t i = 0; i < n; i++) h[i] = (uint16_t)(1000 + (i % w) * 7);
        for (uint32_t j = 0; j < k; j++) h[pick(s, 0, (uint32_t)n - 1)] = (uint16_t)pick(s, 0, 65535);
        break;
    }
    default: /* smooth bumps, the kind of terrain the refiner is made for */
        for (int32_t y = 0; y < ht; y++)
            for (int32_t x = 0; x < w; x++) {
                double v = 30000.0 + (double)amp * 0.4 * sin(0.37 * x + 0.11 * (double)shape) * cos(0.29 * y);
                h[y * w + x] = (uint16_t)(v < 0 ? 0 : v > 65535 ? 65535 : v);
            }
        break;
    }
}

/* Exact E(T) in sample counts (double: the products are exact below 2^53), as docs/refiner.md
 * defines it, by a scan of every sample of the closed triangle written apart from tri_error.c. */
static double exact_error(const uint16_t *h, int32_t w, const int32_t x[3], const int32_t y[3], int normal,
                          double s)
{
    double z[3], D, na, nb, vmax = 0;
    int32_t xmin = x[0], xmax = x[0], ymin = y[0], ymax = y[0];
    for (int k = 0; k < 3; k++) {
        z[k] = h[y[k] * w + x[k]];
        if (x[k] < xmin) xmin = x[k];
        if (x[k] > xmax) xmax = x[k];
        if (y[k] < ymin) ymin = y[k];
        if (y[k] > ymax) ymax = y[k];
    }
    D = (double)(x[1] - x[0]) * (y[2] - y[0]) - (double)(x[2] - x[0]) * (y[1] - y[0]);
    /* plane z = (na x + nb y + c) / D */
    na = (z[1] - z[0]) * (y[2] - y[0]) - (z[2] - z[0]) * (y[1] - y[0]);
    nb = (x[1] - x[0]) * (z[2] - z[0]) - (x[2] - x[0]) * (z[1] - z[0]);
    for (int32_t py = ymin; py <= ymax; py++)
        for (int32_t px = xmin; px <= xmax; px++) {
            double e[3];
            int inside = 1;
            for (int k = 0; k < 3; k++) {
                int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
                e[k] = (double)(x[k2] - x[k1]) * (py - y[k1]) - (double)(y[k2] - y[k1]) * (px - x[k1]);
                if (e[k] < 0) inside = 0;
            }
            if (inside) {
                double v = fabs(e[0] * z[0] + e[1] * z[1] + e[2] * z[2] - D * h[py * w + px]);
                if (v > vmax) vmax = v;
            }
        }
    vmax /= D;
    if (normal) vmax /= sqrt(1.0 + (s * s) * (na * na + nb * nb) / (D * D));
    return vmax;
}

static int64_t edge_key(int32_t a, int32_t b) { return (int64_t)a << 32 | (uint32_t)b; }

static int cmp_i64(const void *a, const void *b)
{
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* A proper triangulation of the W x H rectangle (module comment), from wm_mesh_export's arrays. */
static void check_proper(const wm_mesh *m, const char *when)
{
    int32_t w = m->width, h = m->height, nt;
    int32_t *xy = malloc(sizeof(int32_t) * 2 * (size_t)(m->vert_end + 1));
    int32_t *tris = malloc(sizeof(int32_t) * 3 * (size_t)(m->n_tri + 1));
    uint8_t *at = calloc((size_t)w * h, 1);
    int64_t area = 0;
    if (!xy || !tris || !at) abort();
    nt = wm_mesh_export(m, xy, tris);
    if (nt != m->n_tri) FAIL("%s: export gave %d triangles, the mesh says %d", when, nt, m->n_tri);
    for (int32_t v = 0; v < m->vert_end; v++) {
        int32_t vx = xy[2 * v], vy = xy[2 * v + 1];
        if (vx == -1 && vy == -1) continue;
        if (vx < 0 || vy < 0 || vx >= w || vy >= h)
            FAIL("%s: vertex %d at (%d, %d) off the grid", when, v, vx, vy);
        if (at[vy * w + vx]++) FAIL("%s: two vertices at (%d, %d)", when, vx, vy);
    }
    for (int32_t t = 0; t < nt; t++) {
        const int32_t *v = tris + 3 * t;
        int64_t a;
        for (int k = 0; k < 3; k++)
            if (v[k] < 0 || v[k] >= m->vert_end || xy[2 * v[k]] < 0)
                FAIL("%s: triangle %d uses a free vertex", when, t);
        a = (int64_t)(xy[2 * v[1]] - xy[2 * v[0]]) * (xy[2 * v[2] + 1] - xy[2 * v[0] + 1]) -
            (int64_t)(xy[2 * v[2]] - xy[2 * v[0]]) * (xy[2 * v[1] + 1] - xy[2 * v[0] + 1]);
        if (a <= 0) FAIL("%s: triangle %d is not counter-clockwise (doubled area %lld)", when, t, (long long)a);
        area += a;
    }
    if (area != 2 * (int64_t)(w - 1) * (h - 1))
        FAIL("%s: doubled areas add up to %lld, not %lld", when, (long long)area, 2LL * (w - 1) * (h - 1));
    /* every directed edge once, its reverse present or the edge on the border */
    {
        int64_t *keys = malloc(sizeof(int64_t) * 3 * (size_t)(nt + 1));
        int32_t ne = 0;
        if (!keys) abort();
        for (int32_t t = 0; t < nt; t++)
            for (int k = 0; k < 3; k++) keys[ne++] = edge_key(tris[3 * t + k], tris[3 * t + (k + 1) % 3]);
        qsort(keys, (size_t)ne, sizeof *keys, cmp_i64);
        for (int32_t i = 0; i < ne; i++) {
            int32_t a = (int32_t)(keys[i] >> 32), b = (int32_t)(keys[i] & 0xFFFFFFFF);
            int64_t rev = edge_key(b, a);
            int32_t ax = xy[2 * a], ay = xy[2 * a + 1], bx = xy[2 * b], by = xy[2 * b + 1];
            int border = (ax == bx && (ax == 0 || ax == w - 1)) || (ay == by && (ay == 0 || ay == h - 1));
            if (i > 0 && keys[i - 1] == keys[i]) FAIL("%s: edge %d-%d twice in one direction", when, a, b);
            if (!border && !bsearch(&rev, keys, (size_t)ne, sizeof *keys, cmp_i64))
                FAIL("%s: inner edge (%d,%d)-(%d,%d) has one triangle", when, ax, ay, bx, by);
            if (border && bsearch(&rev, keys, (size_t)ne, sizeof *keys, cmp_i64))
                FAIL("%s: border edge (%d,%d)-(%d,%d) has two triangles", when, ax, ay, bx, by);
        }
        free(keys);
    }
    free(xy);
    free(tris);
    free(at);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    src s = {data, size, 0};
    int32_t w = (int32_t)pick(&s, 2, MAX_SIDE), h = (int32_t)pick(&s, 2, MAX_SIDE);
    int32_t levels = (int32_t)pick(&s, 1, pick(&s, 0, 3) ? 6 : WM_MAX_LEVELS);
    uint32_t tau = pick(&s, 0, 3) ? pick(&s, 0, 2000) : pick(&s, 0, 262143);
    wm_params p;
    uint16_t *hs = malloc(sizeof(uint16_t) * (size_t)w * h);
    int32_t *details = NULL, *xy = NULL, *tris = NULL, nv = 0, nt = 0, cap, cap_max = wm_tri_cap_max(w, h);
    uint16_t *scratch = NULL;
    void *mem = NULL;
    wm_refiner *r = NULL;
    wm_level_stats st;
    wm_field f;
    int rc, steps = 0;
    char when[64];

    memset(&p, 0, sizeof p);
    p.metric = (int32_t)pick(&s, 0, 1);
    p.neighbourhood = (int32_t)pick(&s, 0, 1);
    p.iterations = (int32_t)pick(&s, 0, 3);
    p.zeta = scaled(&s);
    p.scale_m = pick(&s, 0, 65535);
    p.scale_e = (int32_t)(pick(&s, 0, 1) ? pick(&s, 8, 24) : pick(&s, 0, 126));
    p.delta_p = pick(&s, 0, 65535);
    p.alpha = pick(&s, 0, 65536);
    p.delta_v = scaled(&s);
    p.flags = pick(&s, 0, WM_FLAG_ALL);
    p.delta_d = (uint64_t)take(&s, 4) << 32;
    p.delta_d |= take(&s, 4);
    p.delta_d >>= pick(&s, 0, 63);
    p.delta_lambda = scaled(&s);
    p.delta_c = pick(&s, 0, 65536);
    if (wm_params_check(&p) != WM_OK) FAIL("wm_params_check refuses parameters within its documented ranges");
    if (!hs) abort();
    heights(&s, hs, w, h);

    /* the device's pipeline: filter bank, template stage, refiner */
    {
        int64_t nd = wm_details_size(w, h, levels), ns = wm_haar_scratch(w, h);
        details = malloc(sizeof(int32_t) * (size_t)(nd > 0 ? nd : 1));
        scratch = malloc(sizeof(uint16_t) * (size_t)(ns > 0 ? ns : 1));
        if (!details || !scratch) abort();
        rc = wm_haar(hs, w, h, levels, details, scratch);
        if (rc != WM_OK) FAIL("wm_haar %d x %d M=%d: %s", w, h, levels, wm_strerror(rc));
        if (wm_native_initial(w, h, levels, tau, details, &xy, &nv, &tris, &nt) != 0)
            FAIL("the template stage failed on %d x %d M=%d tau=%u", w, h, levels, tau);
    }
    switch (pick(&s, 0, 3)) { /* the storage: plenty, just enough, or maybe too little */
    case 0: cap = (int32_t)pick(&s, 2, (uint32_t)cap_max); break;
    case 1: cap = nt + (int32_t)pick(&s, 0, 64); break;
    default: cap = cap_max; break;
    }
    if (pick(&s, 0, 2) == 0 && cap > 2) p.max_triangles = (int32_t)pick(&s, 2, (uint32_t)cap - 1);
    f.width = w;
    f.height = h;
    f.levels = levels;
    f.samples = hs;
    f.details = details;
    f.mask = NULL; /* no holes */
    {
        size_t bytes = wm_refine_bound(w, h, cap);
        if (bytes == 0) FAIL("wm_refine_bound(%d, %d, %d) overflows", w, h, cap);
        mem = malloc(bytes);
        if (!mem) abort();
        rc = wm_refine_init(&r, mem, bytes, &f, &p, xy, nv, tris, nt, cap);
    }
    if (rc == WM_ERR_CAPACITY && nt > cap) goto out; /* refused, as documented */
    if (rc != WM_OK) FAIL("wm_refine_init on the template stage's mesh: %s", wm_strerror(rc));
    check_proper(wm_refine_mesh(r), "initial mesh");
    memset(&st, 0, sizeof st);
    while (!wm_refine_done(r)) {
        int32_t level = wm_refine_level(r) - 1;
        memset(&st, 0, sizeof st);
        rc = wm_refine_step(r, &st);
        snprintf(when, sizeof when, "level %d", level);
        if (rc != WM_OK && rc != WM_ERR_CAPACITY) FAIL("wm_refine_step at %s: %s", when, wm_strerror(rc));
        check_proper(wm_refine_mesh(r), when);
        if (++steps > WM_MAX_LEVELS + 1) FAIL("the refiner is not done after %d steps", steps);
        if (rc == WM_ERR_CAPACITY) {
            if (!wm_refine_done(r)) FAIL("out of storage but not done");
            goto out;
        }
    }
    /* the bound: every triangle within zeta unless a budget stopped the refiner */
    if (!(p.flags & WM_FLAG_NO_BOUND)) {
        const wm_mesh *m = wm_refine_mesh(r);
        double zeta = p.zeta / 65536.0, sc = (double)p.scale_m / ldexp(1.0, p.scale_e), worst = 0;
        if (st.over != 0 && !st.budget_hit)
            FAIL("%d triangles over zeta at the end, and no budget stopped the refiner", st.over);
        if (st.over == 0) {
            for (int32_t t = 0; t < m->tri_end; t++) {
                int32_t x[3], y[3];
                double e;
                if (m->he[3 * t].v < 0) continue;
                for (int k = 0; k < 3; k++) {
                    x[k] = m->vxy[m->he[3 * t + k].v].x;
                    y[k] = m->vxy[m->he[3 * t + k].v].y;
                }
                e = exact_error(hs, w, x, y, p.metric == WM_METRIC_NORMAL, sc);
                if (e > worst) worst = e;
                if (e > zeta * (1 + 1e-12) + 1e-12)
                    FAIL("E(T) %.9g > zeta %.9g (triangle (%d,%d) (%d,%d) (%d,%d), %s metric), though the "
                         "refiner reports every triangle within zeta",
                         e, zeta, x[0], y[0], x[1], y[1], x[2], y[2],
                         p.metric == WM_METRIC_NORMAL ? "normal" : "vertical");
            }
            if (st.e_max / 65536.0 + 1e-9 < worst)
                FAIL("the refiner's E_max %.9g is below the exact %.9g", st.e_max / 65536.0, worst);
        }
    }
out:
    free(hs);
    free(details);
    free(scratch);
    free(xy);
    free(tris);
    free(mem);
    return 0;
}
