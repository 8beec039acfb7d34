/*
 * The protocol engine's upload (proto_int.h lists the engine's parts; docs/protocol.md, DATA): the
 * samples after CONFIG, raw or Rice-coded, then the validity mask's words (CONFIG_MASK), in order;
 * a gap (a lost frame) is answered with one NAK from the first word missing.
 */
#include "proto_int.h"

/* Word k of what DATA carries: sample k, or beyond the W H samples the mask's bytes in pairs. */
static void put_word(wm_proto *p, uint32_t k, uint16_t v)
{
    uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height;
    if (k < wh) {
        p->heights[k] = v;
    } else {
        p->mask[2 * (k - wh)] = (uint8_t)v;
        p->mask[2 * (k - wh) + 1] = (uint8_t)(v >> 8);
    }
}

/* CODING_RICE (docs/protocol.md, "Sample coding"; host/wavemesh/device/coding.py encodes): n samples from off,
 * each a prediction from the samples stored before it (the block's predictor: MED or the plane) plus a
 * zig-zag residual, Rice-coded in blocks of WM_PROTO_RICE_BLOCK with a k each, bits most significant
 * first.  0, or -1 when the len bytes at s are not such a stream (too short, or a byte or more left
 * over). */
static int rice_decode(wm_proto *p, uint32_t off, uint32_t n, const uint8_t *s, uint32_t len)
{
    /* The bits left-aligned in acc (the next one is bit 31), nb of them valid; refilled a byte at a time
     * to at least 25 while bytes are left.  The left and above-left samples are carried in registers
     * (the height memory is the SDRAM): one load a sample, the one above. */
    const uint8_t *e = s + len;
    uint16_t *h = p->heights;
    uint32_t w = (uint32_t)p->job.width, x = off % w, i = off, end = off + n;
    uint32_t acc = 0, nb = 0, left = 0, ul = 0;
#define REFILL()                             \
    while (nb <= 24 && s < e) {              \
        acc |= (uint32_t)*s++ << (24u - nb); \
        nb += 8u;                            \
    }
    if (x) {
        left = h[i - 1];
        if (i > w) ul = h[i - w - 1];
    }
    while (i < end) {
        uint32_t pick, k, m = end - i < WM_PROTO_RICE_BLOCK ? end - i : WM_PROTO_RICE_BLOCK;
        REFILL();
        if (nb < WM_PROTO_RICE_PRED_BITS + WM_PROTO_RICE_K_BITS) return -1;
        pick = acc >> (32u - WM_PROTO_RICE_PRED_BITS);
        k = (acc << WM_PROTO_RICE_PRED_BITS) >> (32u - WM_PROTO_RICE_K_BITS);
        acc <<= WM_PROTO_RICE_PRED_BITS + WM_PROTO_RICE_K_BITS;
        nb -= WM_PROTO_RICE_PRED_BITS + WM_PROTO_RICE_K_BITS;
        for (; m; m--, i++) {
            uint32_t q = 0, z, pred;
            REFILL();
            while (q < WM_PROTO_RICE_ESCAPE && nb && (acc & 0x80000000u)) { /* the quotient's ones */
                acc <<= 1;
                nb--;
                q++;
            }
            if (q == WM_PROTO_RICE_ESCAPE) {
                REFILL();
                if (nb < 16u) return -1;
                z = acc >> 16;
                acc <<= 16;
                nb -= 16u;
            } else {
                if (nb == 0) return -1; /* no room for the quotient's zero */
                acc <<= 1;
                nb--;
                REFILL();
                if (nb < k) return -1;
                z = k ? (q << k) | (acc >> (32u - k)) : q;
                acc = k ? acc << k : acc;
                nb -= k;
            }
            if (i < w) {
                pred = x ? left : 0u;
            } else {
                uint32_t b = h[i - w];
                if (x == 0) {
                    pred = b;
                } else {
                    uint32_t hi = left > b ? left : b, lo = left > b ? b : left;
                    pred = pick == WM_PROTO_RICE_PRED_PLANE || (ul < hi && ul > lo) ? left + b - ul
                           : ul >= hi                                               ? lo
                                                                                    : hi;
                }
                ul = b;
            }
            left = (uint16_t)(pred + ((z >> 1) ^ (0u - (z & 1u))));
            h[i] = (uint16_t)left;
            if (++x == w) x = 0;
        }
    }
#undef REFILL
    return s == e && nb < 8u ? 0 : -1;
}

void wm_proto_do_data(wm_proto *p)
{
    uint8_t b[WM_PROTO_DATA_ACK_BYTES];
    uint32_t off, n, i, coding, tail;
    const uint8_t *s;
    if (p->state != WM_PROTO_STATE_RECEIVING && p->state != WM_PROTO_STATE_READY) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return;
    }
    off = get32(p->f_pay + WM_PROTO_DATA_OFFSET);
    n = get16(p->f_pay + WM_PROTO_DATA_COUNT);
    coding = p->f_pay[WM_PROTO_DATA_CODING];
    tail = (uint32_t)p->f_len - WM_PROTO_DATA_BYTES;
    if (p->f_len < WM_PROTO_DATA_BYTES + 1 || n == 0 || (coding == WM_PROTO_CODING_RAW && tail != 2 * n) ||
        (coding != WM_PROTO_CODING_RAW && coding != WM_PROTO_CODING_RICE)) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    if (off > p->total || n > p->total - off ||
        (coding == WM_PROTO_CODING_RICE && off + n > (uint32_t)p->job.width * (uint32_t)p->job.height)) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_OFFSET, off);
        return;
    }
    zero(b, sizeof b);
    if (off <= p->next && p->f_data) {
        /* the transport stored the samples below W H and checked the Rice stream (the same checks as
         * above, in the same order: its code is 0 here, or 4); the mask's words are ours */
        uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height;
        if (p->f_code == WM_PROTO_UPLOAD_STREAM) {
            wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return;
        }
        s = p->f_pay + WM_PROTO_DATA_BYTES;
        for (i = off < wh ? wh - off : 0; i < n; i++) put_word(p, off + i, get16(s + 2 * i));
        if (off + n > p->next) {
            p->next = off + n;
            p->nak_sent = 0;
        }
    } else if (off <= p->next && coding == WM_PROTO_CODING_RICE) {
        /* every sample before off is stored: the predictions are the host's */
        if (rice_decode(p, off, n, p->f_pay + WM_PROTO_DATA_BYTES, tail)) {
            wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return;
        }
        if (off + n > p->next) {
            p->next = off + n;
            p->nak_sent = 0;
        }
    } else if (off <= p->next) {
        /* in order, or a repeat that may reach beyond what is stored */
        s = p->f_pay + WM_PROTO_DATA_BYTES;
#if WM_LITTLE_ENDIAN && !defined(WM_PROTO_WHOLE_FRAMES)
        if (off + n <= (uint32_t)p->job.width * (uint32_t)p->job.height) {
            /* samples only, straight (the wire's byte order is the CPU's): two a step when the
             * destination is word-aligned (the source is: an even offset in a word-aligned buffer) */
            const uint16_t *h = p->rx.h + (WM_PROTO_HEADER_BYTES + WM_PROTO_DATA_BYTES) / 2;
            uint16_t *d = p->heights + off;
            i = 0;
            if (!((uintptr_t)d & 3u))
                for (; i + 2 <= n; i += 2)
                    __builtin_memcpy(__builtin_assume_aligned(d + i, 4), __builtin_assume_aligned(h + i, 4), 4);
            for (; i < n; i++) d[i] = h[i];
        } else
#endif
        {
            for (i = 0; i < n; i++) put_word(p, off + i, get16(s + 2 * i));
        }
        if (off + n > p->next) {
            p->next = off + n;
            p->nak_sent = 0;
        }
    } else if (!p->nak_sent) {
        /* a gap: a frame before this one was lost; ask once per gap for everything from next */
        p->nak_sent = 1;
        b[WM_PROTO_DATA_ACK_FLAGS] = WM_PROTO_ACK_NAK;
    }
    if (p->next == p->total) p->state = WM_PROTO_STATE_READY;
    put32(b + WM_PROTO_DATA_ACK_NEXT, p->next);
    wm_proto_reply(p, WM_PROTO_T_DATA_ACK, b, sizeof b);
}
