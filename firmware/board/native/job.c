/*
 * The native stand-in device's job: what the board's FPGA stage and CPU do, on the host CPU.
 *
 *   heights --wm_haar--> details --labeller, resolver, templates--> initial mesh --refiner--> levels
 *
 * The template stage is host/wavemesh/label.py and initial.py in C (docs/model.md), with the
 * template set and look-up table of the generated wm_templates.h; the refiner is the firmware
 * library (firmware/src), the same code the board runs.  Each level goes out through
 * wm_proto_emit_level as soon as it is made, the initial triangulation first.  This is a hosted
 * program: it may malloc.
 */
#include "job.h"

#include <stdlib.h>
#include <string.h>

#include "wm_templates.h"

enum { KIND_FLAT = 0, KIND_VERTICAL = 1, KIND_HORIZONTAL = 2, KIND_DIAGONAL = 3 };

static int32_t block_edge(int32_t i, int32_t size, int32_t n) {
    int64_t e = (int64_t)i * size;
    return e < n - 1 ? (int32_t)e : n - 1;
}

static int cmp_i32(const void *a, const void *b) {
    int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
    return (x > y) - (x < y);
}

static int cmp_tri(const void *a, const void *b) {
    const int32_t *s = a, *t = b;
    for (int i = 0; i < 3; i++)
        if (s[i] != t[i]) return (s[i] > t[i]) - (s[i] < t[i]);
    return 0;
}

int wm_native_initial(int32_t width, int32_t height, int32_t levels, uint32_t tau, const int32_t *details,
                      int32_t **xy_out, int32_t *nv_out, int32_t **tris_out, int32_t *nt_out) {
    int32_t size = 1 << levels;
    int32_t cols = (width - 1 + size - 1) / size, rows = (height - 1 + size - 1) / size;
    int32_t cw = (width + size - 1) >> levels; /* cells per row of level M */
    const int32_t *d = details + wm_details_offset(width, height, levels);
    uint8_t *label = malloc((size_t)rows * cols);
    int32_t *keys = NULL, *uniq = NULL, *tris = NULL, *xy = NULL;
    int32_t nt = 0, nu = 0;
    int rc = -1;
    if (!label) goto out;

    /* labels (3.5.1-3.5.3): dominant detail, threshold, dual sign, demotion of thin blocks */
    for (int32_t j = 0; j < rows; j++) {
        for (int32_t i = 0; i < cols; i++) {
            const int32_t *c = d + 3 * ((int64_t)j * cw + i);
            int32_t a1 = abs(c[0]), a2 = abs(c[1]), a3 = abs(c[2]);
            int32_t top = a1 > a2 ? a1 : a2;
            int kind, sign_dual = (int64_t)c[0] * c[1] < 0, dual;
            int narrow = block_edge(i + 1, size, width) - block_edge(i, size, width) < 2;
            int low = block_edge(j + 1, size, height) - block_edge(j, size, height) < 2;
            top = top > a3 ? top : a3;
            if (a1 >= a2 && a1 >= a3) kind = KIND_VERTICAL;
            else if (a2 >= a3) kind = KIND_HORIZONTAL;
            else kind = KIND_DIAGONAL;
            if (!((uint32_t)top > tau)) kind = KIND_FLAT;
            dual = sign_dual && kind != KIND_DIAGONAL;
            if ((narrow && (kind == KIND_VERTICAL || kind == KIND_DIAGONAL)) ||
                (low && (kind == KIND_HORIZONTAL || kind == KIND_DIAGONAL)))
                label[(int64_t)j * cols + i] = (uint8_t)(KIND_FLAT << 1 | sign_dual);
            else
                label[(int64_t)j * cols + i] = (uint8_t)(kind << 1 | dual);
        }
    }

    /* variants (3.5.4) and assembly (3.6.2): every block's template on its grid positions */
    tris = malloc(sizeof(int32_t) * 3 * WM_TEMPLATE_MAX_TRIANGLES * (size_t)rows * cols);
    keys = malloc(sizeof(int32_t) * 3 * WM_TEMPLATE_MAX_TRIANGLES * (size_t)rows * cols);
    if (!tris || !keys) goto out;
#define KIND(jj, ii) (label[(int64_t)(jj) * cols + (ii)] >> 1)
    for (int32_t j = 0; j < rows; j++) {
        int32_t y0 = block_edge(j, size, height), y1 = block_edge(j + 1, size, height);
        int32_t ry[3] = {y0, y0 + (y1 - y0) / 2, y1};
        for (int32_t i = 0; i < cols; i++) {
            int32_t x0 = block_edge(i, size, width), x1 = block_edge(i + 1, size, width);
            int32_t rx[3] = {x0, x0 + (x1 - x0) / 2, x1};
            unsigned mask = 0, lab = label[(int64_t)j * cols + i], tid;
            if (KIND(j, i) == KIND_VERTICAL || (j > 0 && KIND(j - 1, i) == KIND_VERTICAL)) mask |= WM_SIDE_TOP;
            if (KIND(j, i) == KIND_VERTICAL || (j + 1 < rows && KIND(j + 1, i) == KIND_VERTICAL))
                mask |= WM_SIDE_BOTTOM;
            if (KIND(j, i) == KIND_HORIZONTAL || (i > 0 && KIND(j, i - 1) == KIND_HORIZONTAL)) mask |= WM_SIDE_LEFT;
            if (KIND(j, i) == KIND_HORIZONTAL || (i + 1 < cols && KIND(j, i + 1) == KIND_HORIZONTAL))
                mask |= WM_SIDE_RIGHT;
            tid = wm_template_lut[lab << 4 | mask];
            if (tid == WM_LUT_INVALID) goto out; /* cannot happen: V and H carry their own sides */
            for (int t = 0; t < wm_template_ntri[tid]; t++) {
                for (int k = 0; k < 3; k++) {
                    int s = wm_template_tri[tid][t][k];
                    keys[3 * nt + k] = ry[s / 3] * width + rx[s % 3];
                }
                nt++;
            }
        }
    }
#undef KIND

    /* canonical form: vertices by (y, x) = by key, triangles from their smallest vertex, sorted */
    uniq = malloc(sizeof(int32_t) * 3 * (size_t)nt);
    if (!uniq) goto out;
    memcpy(uniq, keys, sizeof(int32_t) * 3 * (size_t)nt);
    qsort(uniq, 3 * (size_t)nt, sizeof(int32_t), cmp_i32);
    for (int32_t k = 0; k < 3 * nt; k++)
        if (nu == 0 || uniq[nu - 1] != uniq[k]) uniq[nu++] = uniq[k];
    for (int32_t k = 0; k < 3 * nt; k++) {
        int32_t *hit = bsearch(&keys[k], uniq, (size_t)nu, sizeof(int32_t), cmp_i32);
        tris[k] = (int32_t)(hit - uniq);
    }
    for (int32_t t = 0; t < nt; t++) {
        int32_t *v = tris + 3 * t, a = v[0], b = v[1], c = v[2];
        if (b < a && b < c) {
            v[0] = b, v[1] = c, v[2] = a;
        } else if (c < a && c < b) {
            v[0] = c, v[1] = a, v[2] = b;
        }
    }
    qsort(tris, (size_t)nt, 3 * sizeof(int32_t), cmp_tri);
    xy = malloc(sizeof(int32_t) * 2 * (size_t)nu);
    if (!xy) goto out;
    for (int32_t v = 0; v < nu; v++) {
        xy[2 * v] = uniq[v] % width;
        xy[2 * v + 1] = uniq[v] / width;
    }
    *xy_out = xy;
    *nv_out = nu;
    *tris_out = tris;
    *nt_out = nt;
    xy = tris = NULL;
    rc = 0;
out:
    free(label);
    free(keys);
    free(uniq);
    free(tris);
    free(xy);
    return rc;
}

/* The initial triangulation alone, as a mesh (CONFIG_INITIAL_ONLY). */
static int initial_only(const wm_proto_job *j, wm_proto *p, const int32_t *xy, int32_t nv, const int32_t *tris,
                        int32_t nt, uint32_t *detail) {
    wm_mesh m;
    wm_level_stats st;
    size_t bytes = wm_mesh_bound(nt, nv);
    void *mem = malloc(bytes ? bytes : 1);
    uint32_t *scratch = malloc(sizeof(uint32_t) * 3 * (size_t)nt);
    int rc;
    if (!mem || !scratch) {
        free(mem);
        free(scratch);
        *detail = (uint32_t)WM_ERR_MEMORY;
        return WM_PROTO_E_JOB;
    }
    rc = wm_mesh_init(&m, mem, bytes, j->width, j->height, nt, nv);
    if (rc == WM_OK) rc = wm_mesh_build(&m, xy, nv, tris, nt, scratch);
    if (rc != WM_OK) {
        free(mem);
        free(scratch);
        *detail = (uint32_t)rc;
        return WM_PROTO_E_JOB;
    }
    memset(&st, 0, sizeof st);
    st.level = j->levels - 1;
    st.vertices = m.n_vert;
    st.triangles = m.n_tri;
    rc = wm_proto_emit_level(p, &m, &st, 1);
    free(mem);
    free(scratch);
    return rc;
}

int wm_native_job(void *ctx, const wm_proto_job *j, wm_proto *p, uint32_t *detail) {
    int32_t w = j->width, h = j->height, m = j->levels;
    int64_t nd = wm_details_size(w, h, m), ns = wm_haar_scratch(w, h);
    int32_t *details = malloc(sizeof(int32_t) * (size_t)(nd > 0 ? nd : 1));
    uint16_t *scratch = malloc(sizeof(uint16_t) * (size_t)(ns > 0 ? ns : 1));
    int32_t *xy = NULL, *tris = NULL, nv = 0, nt = 0;
    void *mem = NULL;
    wm_refiner *r = NULL;
    wm_level_stats st;
    int rc = WM_PROTO_E_NONE, lib;
    (void)ctx;
    if (!details || !scratch) {
        *detail = (uint32_t)WM_ERR_MEMORY;
        rc = WM_PROTO_E_JOB;
        goto out;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_FILTER, m);
    lib = wm_haar(j->heights, w, h, m, details, scratch);
    if (lib != WM_OK) {
        *detail = (uint32_t)lib;
        rc = WM_PROTO_E_JOB;
        goto out;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_TEMPLATE, m);
    if (wm_native_initial(w, h, m, j->tau, details, &xy, &nv, &tris, &nt) != 0) {
        *detail = (uint32_t)WM_ERR_MEMORY;
        rc = WM_PROTO_E_JOB;
        goto out;
    }
    if (nt > j->capacity) {
        *detail = (uint32_t)(m - 1);
        rc = WM_PROTO_E_CAPACITY;
        goto out;
    }
    if (j->flags & WM_PROTO_CONFIG_INITIAL_ONLY) {
        rc = initial_only(j, p, xy, nv, tris, nt, detail);
        goto out;
    }

    wm_proto_stage(p, WM_PROTO_STAGE_REFINE, m - 1);
    {
        wm_field f = {w, h, m, j->heights, details};
        size_t bytes = wm_refine_bound(w, h, j->capacity);
        mem = malloc(bytes ? bytes : 1);
        if (!mem || bytes == 0) {
            *detail = (uint32_t)WM_ERR_MEMORY;
            rc = WM_PROTO_E_JOB;
            goto out;
        }
        lib = wm_refine_init(&r, mem, bytes, &f, &j->params, xy, nv, tris, nt, j->capacity);
    }
    if (lib != WM_OK) {
        *detail = lib == WM_ERR_CAPACITY ? (uint32_t)(m - 1) : (uint32_t)lib;
        rc = lib == WM_ERR_CAPACITY ? WM_PROTO_E_CAPACITY : WM_PROTO_E_JOB;
        goto out;
    }
    memset(&st, 0, sizeof st); /* wm_refine_stats fills only the counts it knows (as the host's ctypes) */
    wm_refine_stats(r, &st);
    rc = wm_proto_emit_level(p, wm_refine_mesh(r), &st, wm_refine_done(r));
    while (rc == WM_PROTO_E_NONE && !wm_refine_done(r)) {
        int32_t level = wm_refine_level(r) - 1;
        wm_proto_stage(p, WM_PROTO_STAGE_REFINE, level);
        memset(&st, 0, sizeof st);
        lib = wm_refine_step(r, &st);
        if (lib != WM_OK) {
            *detail = lib == WM_ERR_CAPACITY ? (uint32_t)level : (uint32_t)lib;
            rc = lib == WM_ERR_CAPACITY ? WM_PROTO_E_CAPACITY : WM_PROTO_E_JOB;
            break;
        }
        rc = wm_proto_emit_level(p, wm_refine_mesh(r), &st, wm_refine_done(r));
    }
out:
    free(details);
    free(scratch);
    free(xy);
    free(tris);
    free(mem);
    return rc;
}
