/* File-driven runner of the refiner, for the sanitizer builds (tests/firmware/test_sanitized.py).
 *
 *   wm_run IN OUT      IN as written by wavemesh.harness.fwio, OUT the final mesh
 *
 * IN (native byte order): "WMR1", int32 W, H, M, nv, nt, tri_cap, sizeof(wm_params); wm_params;
 * uint16 samples[W H]; int64 n; int32 details[n]; int32 xy[2 nv]; int32 tris[3 nt].
 * OUT: int32 vertex slots V, triangles T; int32 xy[2 V]; int32 tris[3 T].
 * Prints one line per level: level vertices triangles e_max over splits swaps; built with WM_PROFILE, then
 * one line per phase: profile PHASE scans samples rows slopes points (wm_internal.h's counters).
 * Exit status 0; 1 when the refiner returned an error (a line "error CODE TEXT": out of capacity at
 * wm_refine_init, no OUT, or at a level, OUT the mesh it kept); 2 for a bad input or a failed write.
 * Every way out frees what it took (the sanitized build's LeakSanitizer checks each, test_sanitized.py). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "wavemesh.h"
#if WM_PROFILE
#include "wm_internal.h"
#endif

static int rd(FILE *f, void *p, size_t n) { return fread(p, 1, n, f) == n; }

int main(int argc, char **argv)
{
    FILE *in = NULL, *out = NULL;
    char magic[4];
    int32_t hdr[7], nv, nt, cap;
    int64_t nd;
    wm_params p;
    wm_field fld;
    uint16_t *samples = NULL;
    int32_t *details = NULL, *xy = NULL, *tris = NULL, *oxy = NULL, *otris = NULL;
    void *mem = NULL;
    size_t bytes;
    wm_refiner *r;
    wm_level_stats st;
    int rc, status = 2; /* every way out goes through done: what was taken is given back */
    if (argc != 3) {
        fprintf(stderr, "usage: wm_run IN OUT\n");
        return 2;
    }
    in = fopen(argv[1], "rb");
    if (!in || !rd(in, magic, 4) || memcmp(magic, "WMR1", 4) != 0 || !rd(in, hdr, sizeof hdr) ||
        hdr[6] != (int32_t)sizeof p || !rd(in, &p, sizeof p)) {
        fprintf(stderr, "wm_run: bad input %s\n", argv[1]);
        goto done;
    }
    fld.width = hdr[0];
    fld.height = hdr[1];
    fld.levels = hdr[2];
    nv = hdr[3];
    nt = hdr[4];
    cap = hdr[5];
    samples = malloc((size_t)fld.width * (size_t)fld.height * 2);
    if (!samples || !rd(in, samples, (size_t)fld.width * (size_t)fld.height * 2) || !rd(in, &nd, 8)) goto done;
    details = malloc((size_t)(nd > 0 ? nd : 1) * 4);
    xy = malloc((size_t)nv * 8);
    tris = malloc((size_t)nt * 12);
    if (!details || !xy || !tris || !rd(in, details, (size_t)nd * 4) || !rd(in, xy, (size_t)nv * 8) ||
        !rd(in, tris, (size_t)nt * 12))
        goto done;
    fclose(in);
    in = NULL;
    fld.samples = samples;
    fld.details = details;
    fld.mask = NULL; /* no holes */
    bytes = wm_refine_bound(fld.width, fld.height, cap);
    mem = malloc(bytes ? bytes : 1);
    if (!mem) goto done;
    rc = wm_refine_init(&r, mem, bytes, &fld, &p, xy, nv, tris, nt, cap);
    if (rc != WM_OK) {
        printf("error %d %s\n", rc, wm_strerror(rc));
        status = 1;
        goto done;
    }
    wm_refine_stats(r, &st);
    printf("level %d %d %d %u %d 0 0\n", st.level, st.vertices, st.triangles, st.e_max, st.over);
    while (!wm_refine_done(r)) {
        rc = wm_refine_step(r, &st);
        printf("level %d %d %d %u %d %d %d\n", st.level, st.vertices, st.triangles, st.e_max, st.over,
               st.edge_splits + st.ternary_splits + st.bound_splits, st.swaps);
        if (rc != WM_OK) {
            printf("error %d %s\n", rc, wm_strerror(rc));
            break;
        }
    }
    {
        const wm_mesh *m = wm_refine_mesh(r);
        int32_t hdr2[2];
        oxy = malloc((size_t)m->vert_end * 8 + 8);
        otris = malloc((size_t)m->n_tri * 12 + 12);
        if (!oxy || !otris) goto done;
        hdr2[0] = m->vert_end;
        hdr2[1] = wm_mesh_export(m, oxy, otris);
        out = fopen(argv[2], "wb");
        if (!out || fwrite(hdr2, 4, 2, out) != 2 || fwrite(oxy, 8, (size_t)hdr2[0], out) != (size_t)hdr2[0] ||
            fwrite(otris, 12, (size_t)hdr2[1], out) != (size_t)hdr2[1])
            goto done;
        if (fclose(out) != 0) {
            out = NULL;
            goto done;
        }
        out = NULL;
    }
#if WM_PROFILE
    for (int ph = 0; ph < WM_PH_COUNT; ph++) {
        static const char *const names[WM_PH_COUNT] = {"levels", "reduction", "bound", "decimation"};
        printf("profile %s", names[ph]);
        for (int c = 0; c < WM_PC_COUNT; c++) printf(" %llu", (unsigned long long)wm_prof_count[ph][c]);
        printf("\n");
    }
#endif
    status = rc == WM_OK ? 0 : 1;
done:
    if (in) fclose(in);
    if (out) fclose(out);
    free(oxy);
    free(otris);
    free(mem);
    free(samples);
    free(details);
    free(xy);
    free(tris);
    return status;
}
