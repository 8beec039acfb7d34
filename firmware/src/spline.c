/* The integer 2-D spline-wavelet filter bank of host/wavemesh/model/spline.py (docs/model.md, "The spline
 * wavelet"), for a device without the FPGA stage (the native stand-in device) and for tests: the
 * same detail layout as wm_haar (wm_details_offset), so the refiner takes either.  Per level, with
 * every index clamped into the previous approximation a (h x w):
 *
 *     L[c] = a[2i-1,c] + 3 a[2i,c] + 3 a[2i+1,c] + a[2i+2,c]        D[c] = a[2i+1,c] - a[2i,c]
 *     a'   = (L[2j-1] + 3 L[2j] + 3 L[2j+1] + L[2j+2] + 32) >> 6
 *     d1   = floor((L[2j+1] - L[2j] + 2) / 4)    d2 = floor((D[2j-1] + 3 D[2j] + 3 D[2j+1] + D[2j+2] + 2) / 4)
 *     d3   = D[2j+1] - D[2j]
 *
 * One record row at a time: the vertical sums of its 4 input rows into two int32 rows of scratch,
 * then the horizontal filter over them. */
#include "wm_internal.h"

static int64_t cells(int32_t width, int32_t height, int32_t m)
{
    int64_t cw = ((int64_t)width + (1 << m) - 1) >> m, ch = ((int64_t)height + (1 << m) - 1) >> m;
    return cw * ch;
}

static int32_t clampi(int32_t v, int32_t hi) { return v < 0 ? 0 : v > hi ? hi : v; }

/* floor(x / 4) without relying on >> of a negative number (implementation-defined in C99) */
static int32_t floor4(int32_t x) { return x >= 0 ? x / 4 : -((-x + 3) / 4); }

int64_t wm_spline_scratch(int32_t width, int32_t height)
{
    /* the two approximation buffers of wm_haar_scratch, rounded up to an int32 boundary, and the
     * L and D rows (width int32s each) */
    return ((2 * cells(width, height, 1) + 1) & ~(int64_t)1) + 4 * (int64_t)width;
}

int wm_spline(const uint16_t *samples, int32_t width, int32_t height, int32_t levels, int32_t *details,
              uint16_t *scratch)
{
    const uint16_t *src = samples;
    uint16_t *bufs[2];
    int32_t *lrow, *drow;
    int32_t w = width, h = height;
    if (width < 1 || height < 1 || width > WM_MAX_SIDE || height > WM_MAX_SIDE || levels < 1 ||
        levels > WM_MAX_LEVELS)
        return WM_ERR_ARG;
    bufs[0] = scratch;
    bufs[1] = scratch + cells(width, height, 1);
    lrow = (int32_t *)(void *)(scratch + ((2 * cells(width, height, 1) + 1) & ~(int64_t)1));
    drow = lrow + width;
    for (int32_t m = 1; m <= levels; m++) {
        int32_t w2 = (w + 1) / 2, h2 = (h + 1) / 2;
        uint16_t *dst = bufs[(m - 1) & 1];
        int32_t *d = details + wm_details_offset(width, height, m);
        for (int32_t i = 0; i < h2; i++) {
            const uint16_t *r0 = src + (int64_t)clampi(2 * i - 1, h - 1) * w;
            const uint16_t *r1 = src + (int64_t)clampi(2 * i, h - 1) * w;
            const uint16_t *r2 = src + (int64_t)clampi(2 * i + 1, h - 1) * w;
            const uint16_t *r3 = src + (int64_t)clampi(2 * i + 2, h - 1) * w;
            for (int32_t c = 0; c < w; c++) {
                lrow[c] = r0[c] + 3 * (r1[c] + r2[c]) + r3[c];
                drow[c] = (int32_t)r2[c] - r1[c];
            }
            for (int32_t j = 0; j < w2; j++) {
                int32_t c0 = clampi(2 * j - 1, w - 1), c1 = clampi(2 * j, w - 1);
                int32_t c2 = clampi(2 * j + 1, w - 1), c3 = clampi(2 * j + 2, w - 1);
                int32_t sl = lrow[c0] + 3 * (lrow[c1] + lrow[c2]) + lrow[c3];
                int32_t sd = drow[c0] + 3 * (drow[c1] + drow[c2]) + drow[c3];
                int64_t k = 3 * ((int64_t)i * w2 + j);
                dst[(int64_t)i * w2 + j] = (uint16_t)((sl + 32) >> 6);
                d[k] = floor4(lrow[c2] - lrow[c1] + 2);
                d[k + 1] = floor4(sd + 2);
                d[k + 2] = drow[c2] - drow[c1];
            }
        }
        src = dst;
        w = w2;
        h = h2;
    }
    return WM_OK;
}
