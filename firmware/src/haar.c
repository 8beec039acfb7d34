/* The integer 2-D Haar filter bank of host/wavemesh/model/haar.py (docs/model.md, "Filter bank"), for
 * tests and for a device without the FPGA stage.  Per level, on 2 x 2 blocks of the previous
 * approximation (odd sizes repeat their last column / row):
 *
 *     a'  = (p00 + p01 + p10 + p11 + 2) >> 2
 *     d1  = (p01 + p11) - (p00 + p10)     d2 = (p10 + p11) - (p00 + p01)     d3 = (p00 + p11) - (p01 + p10)
 */
#include "wm_internal.h"

static int64_t cells(int32_t width, int32_t height, int32_t m)
{
    int64_t cw = ((int64_t)width + (1 << m) - 1) >> m, ch = ((int64_t)height + (1 << m) - 1) >> m;
    return cw * ch;
}

int64_t wm_details_offset(int32_t width, int32_t height, int32_t m)
{
    int64_t off = 0;
    for (int32_t k = 1; k < m; k++) off += 3 * cells(width, height, k);
    return off;
}

int64_t wm_details_size(int32_t width, int32_t height, int32_t levels)
{
    return wm_details_offset(width, height, levels + 1);
}

int64_t wm_haar_scratch(int32_t width, int32_t height) { return 2 * cells(width, height, 1); }

int wm_haar(const uint16_t *samples, int32_t width, int32_t height, int32_t levels, int32_t *details,
            uint16_t *scratch)
{
    const uint16_t *src = samples;
    uint16_t *bufs[2];
    int32_t w = width, h = height;
    if (width < 1 || height < 1 || width > WM_MAX_SIDE || height > WM_MAX_SIDE || levels < 1 ||
        levels > WM_MAX_LEVELS)
        return WM_ERR_ARG;
    bufs[0] = scratch;
    bufs[1] = scratch + cells(width, height, 1);
    for (int32_t m = 1; m <= levels; m++) {
        int32_t w2 = (w + 1) / 2, h2 = (h + 1) / 2;
        uint16_t *dst = bufs[(m - 1) & 1];
        int32_t *d = details + wm_details_offset(width, height, m);
        for (int32_t i = 0; i < h2; i++) {
            int32_t r0 = 2 * i, r1 = 2 * i + 1 < h ? 2 * i + 1 : 2 * i;
            for (int32_t j = 0; j < w2; j++) {
                int32_t c0 = 2 * j, c1 = 2 * j + 1 < w ? 2 * j + 1 : 2 * j;
                int32_t p00 = src[(int64_t)r0 * w + c0], p01 = src[(int64_t)r0 * w + c1];
                int32_t p10 = src[(int64_t)r1 * w + c0], p11 = src[(int64_t)r1 * w + c1];
                int64_t k = 3 * ((int64_t)i * w2 + j);
                dst[(int64_t)i * w2 + j] = (uint16_t)((p00 + p01 + p10 + p11 + 2) >> 2);
                d[k] = (p01 + p11) - (p00 + p10);
                d[k + 1] = (p10 + p11) - (p00 + p01);
                d[k + 2] = (p00 + p11) - (p01 + p10);
            }
        }
        src = dst;
        w = w2;
        h = h2;
    }
    return WM_OK;
}
