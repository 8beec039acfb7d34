/* host_scan.c's AVX2 scans against tri_error.c's C scan, for the checking build's shared library
 * (AddressSanitizer, UndefinedBehaviorSanitizer; tests/firmware/test_sanitized.py builds and runs it):
 * random triangles on grids allocated to their last sample (a load past it is a report), E(T) and its
 * worst sample by wm_tri_error_within with the scan set to 0 (the C scan), 2 (the blocks) and 3 (the
 * small triangles' lanes and boxes), with and without a bound that stops the scan, and E(T) alone (no
 * worst sample asked for: the lanes and boxes that keep no place).  Grids from 2 x 2 to
 * 70 x 70, a few wider than 2^14 (the 64-bit lanes; the small triangles' scans then decline) and a few
 * 3000 rows tall; heights random, in two values (ties: the first worst sample must be named) or small.
 * Prints the triangles compared and the differences; exits 1 on any difference.
 *
 *     wm_scan_check [TRIANGLES] */
#include "wavemesh.h"
#include "wm_host.h"
#include "wm_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static uint64_t state = 88172645463325252ull;

static uint32_t rnd(void) /* xorshift64 */
{
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return (uint32_t)(state >> 11);
}

static int32_t clamp(int32_t v, int32_t n) { return v < 0 ? 0 : v >= n ? n - 1 : v; }

int main(int argc, char **argv)
{
    const int32_t modes[3] = {0, 2, 3};
    const long grids = 400;
    long triangles = argc > 1 ? atol(argv[1]) : 200000, checked = 0, narrow = 0, diff = 0;
    for (long g = 0; g < grids; g++) {
        int32_t w = 2 + (int32_t)(rnd() % (g % 3 == 0 ? 9 : 70)), h = 2 + (int32_t)(rnd() % (g % 4 == 0 ? 9 : 70));
        int32_t reach = 70;
        uint16_t *s;
        wm_field f;
        wm_params p;
        if (g % 10 == 9) w = 16385 + (int32_t)(rnd() % 3), h = 2 + (int32_t)(rnd() % 4), reach = 3000;
        if (g % 10 == 8) w = 2 + (int32_t)(rnd() % 3), h = 3000 + (int32_t)(rnd() % 100), reach = 3000;
        s = malloc(sizeof(uint16_t) * (size_t)w * (size_t)h);
        if (s == NULL) return 2;
        for (long i = 0; i < (long)w * h; i++)
            s[i] = (uint16_t)(g % 3 == 0 ? rnd() : g % 3 == 1 ? (rnd() & 1) * 1000 : rnd() % 64);
        memset(&f, 0, sizeof f);
        f.width = w, f.height = h, f.levels = 1, f.samples = s;
        memset(&p, 0, sizeof p);
        p.metric = g & 1 ? WM_METRIC_VERTICAL : WM_METRIC_NORMAL;
        p.scale_m = 1 + rnd() % 65535, p.scale_e = (int32_t)(rnd() % 20);
        for (long t = 0; t < triangles / grids; t++) {
            int32_t x[3], y[3], wx[3], wy[3], r = t % 4 == 0 ? reach : t % 4 == 1 ? 4 : 9;
            int32_t cx = (int32_t)(rnd() % (uint32_t)w), cy = (int32_t)(rnd() % (uint32_t)h), lo, hi;
            uint32_t e[3], e0[3], bound = t % 5 == 0 ? 0xFFFFFFFFu : rnd() % (1u << (rnd() % 26));
            for (int k = 0; k < 3; k++) {
                x[k] = clamp(cx + (int32_t)(rnd() % (uint32_t)(2 * r + 1)) - r, w);
                y[k] = clamp(cy + (int32_t)(rnd() % (uint32_t)(2 * r + 1)) - r, h);
            }
            if (((int64_t)x[1] - x[0]) * (y[2] - y[0]) - ((int64_t)x[2] - x[0]) * (y[1] - y[0]) <= 0) continue;
            for (int m = 0; m < 3; m++) {
                wm_host_scan(modes[m]);
                wx[m] = wy[m] = -1;
                e[m] = wm_tri_error_within(&f, &p, x, y, bound, &wx[m], &wy[m], NULL);
                e0[m] = wm_tri_error_within(&f, &p, x, y, bound, NULL, NULL, NULL); /* the scans without place */
            }
            lo = hi = x[0];
            for (int k = 1; k < 3; k++) lo = x[k] < lo ? x[k] : lo, hi = x[k] > hi ? x[k] : hi;
            narrow += hi - lo < 8;
            checked++;
            for (int m = 1; m < 3; m++) /* the worst sample is named only within the bound */
                if (e[m] != e[0] || e0[m] != e[0] || (e[0] <= bound && (wx[m] != wx[0] || wy[m] != wy[0]))) {
                    if (diff++ < 10)
                        printf("scan %d: (%d, %d) (%d, %d) (%d, %d) on %d x %d, bound %u: %u at (%d, %d), the C "
                               "scan %u at (%d, %d); without the place %u, the C scan %u\n",
                               modes[m], x[0], y[0], x[1], y[1], x[2], y[2], w, h, bound, e[m], wx[m], wy[m], e[0],
                               wx[0], wy[0], e0[m], e0[0]);
                }
        }
        free(s);
    }
    wm_host_scan(1);
    printf("%ld triangles (%ld at most 8 samples wide), %ld differences\n", checked, narrow, diff);
    return diff != 0;
}
