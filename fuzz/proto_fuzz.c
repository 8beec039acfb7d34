/*
 * fuzz_proto: the device's frame decoder and protocol engine (firmware/board/src/proto_*.c) with the
 * native device's job (firmware/board/native/native_job.c: filter bank, template stage, refiner), under ASan
 * and UBSan, on a virtual clock.
 *
 * The input is a script for a host: a run of operations, each a byte and its arguments.
 *
 *   raw bytes        any bytes on the line (broken frames, stray delimiters, bad escapes, noise)
 *   silence          the host says nothing for the whole wait the engine asked for, or part of it
 *   a frame          HELLO, CONFIG, DATA, RUN, ACK, STATUS, ABORT or an unknown type, with a valid
 *                    CRC; its fields drawn from the input, mostly within range so that sessions get
 *                    far (CONFIG of a small job, DATA at the offset the device last acknowledged,
 *                    RUN with the CRC of the heights sent, ACK of the level the device last ended);
 *                    sometimes with a wrong length, sometimes with one byte damaged on the line
 *
 * The device's capabilities (sizes, window, max_payload, features: the reduction, initial-only, the
 * spline filter bank, holes with mask storage, so CONFIG_SPLINE and CONFIG_MASK jobs run the native
 * job's spline bank and the refiner's hole handling) come from the first bytes.  When the script
 * ends the link closes, and wm_proto_serve must return.  Every frame the device sends is checked:
 * SLIP well formed, length field and CRC right, a device type, payload at most its stated
 * max_payload (an abort is a finding).  Each getc without a byte in hand consumes input, so every
 * input ends.  The transport's optional fast paths (read, write_escaped: the board's) are given or
 * left NULL (the native device's) by the input's length, so both ways through the engine are fuzzed.
 *
 *   build/fuzz/fuzz_proto CORPUS...        (make fuzz; fuzz/README.md)
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "native_job.h"
#include "proto.h"
#include "testhost.h"

#define MAX_SIDE 24
#define CLK_HZ 1000000u
#define MIN_PAYLOAD (WM_PROTO_CONFIG_BYTES > 64 ? WM_PROTO_CONFIG_BYTES : 64)
#define BYTE_CYCLES 10u /* 10 us per byte on the line (about 1 Mbaud) */
#define MASK_WORDS(n) (((n) + 15u) / 16u) /* CONFIG_MASK: the mask's DATA words after n samples */

#define FAIL(...)                                    \
    do {                                             \
        fprintf(stderr, "fuzz_proto: " __VA_ARGS__); \
        fprintf(stderr, "\n");                       \
        abort();                                     \
    } while (0)

typedef struct host {
    const uint8_t *d;
    size_t n, pos;
    uint64_t t;                          /* the virtual clock, CLK_HZ */
    uint8_t q[2 * WM_PROTO_MAX_FRAME + 64]; /* bytes on their way to the device */
    size_t q_len, q_pos;
    uint8_t seq;
    wm_proto_caps caps;
    th_rx rx; /* the device's frames, decoded as they are written */
    /* what the host learnt from them */
    uint32_t data_next;                  /* DATA_ACK's next */
    uint8_t le_index;                    /* the last LEVEL_END's index and total */
    uint32_t le_total;
    /* the job the host last configured, and the heights it sent */
    uint32_t total;
    uint16_t mirror[MAX_SIDE * MAX_SIDE + MASK_WORDS(MAX_SIDE * MAX_SIDE)];
} host;

static int more(const host *h) { return h->pos < h->n; }

static uint32_t take(host *h, int bytes)
{
    uint32_t v = 0;
    for (int i = 0; i < bytes; i++) v = v << 8 | (h->pos < h->n ? h->d[h->pos++] : 0);
    return v;
}

static uint32_t pick(host *h, uint32_t lo, uint32_t hi)
{
    uint32_t span = hi - lo + 1;
    if (span == 0) return take(h, 4);
    return lo + (span > 255 ? (span > 65535 ? take(h, 4) : take(h, 2)) : take(h, 1)) % span;
}

/* A 32-bit value over many magnitudes: 4 bytes, then a right shift of 0..31 (read in that order). */
static uint32_t scaled(host *h)
{
    uint32_t v = take(h, 4);
    return v >> pick(h, 0, 31);
}

static void q_raw(host *h, uint8_t b)
{
    if (h->q_len < sizeof h->q) h->q[h->q_len++] = b;
}

/* A frame with a valid CRC, SLIP-encoded onto the queue; damage: one byte of it changed on the line. */
static void q_frame(host *h, uint8_t type, const uint8_t *pay, uint32_t n, int damage)
{
    size_t start = h->q_len, k = th_frame(h->q + start, sizeof h->q - start, type, h->seq++, pay, n);
    h->q_len += k;
    if (damage && k) h->q[start + pick(h, 0, (uint32_t)(k - 1))] ^= (uint8_t)pick(h, 1, 255);
}

/* One operation of the script onto the queue (module comment). */
static void next_op(host *h)
{
    uint8_t pay[WM_PROTO_MAX_PAYLOAD + 16];
    uint32_t op = take(h, 1), n = 0, i;
    uint8_t type;
    int damage = (op & 0xE0u) == 0xE0u, odd_length = (op & 0xE0u) == 0xC0u;
    memset(pay, 0, sizeof pay);
    switch (op % 10) {
    case 0: /* raw bytes */
        n = pick(h, 1, 48);
        for (i = 0; i < n && more(h); i++) q_raw(h, (uint8_t)take(h, 1));
        return;
    case 1:
        type = WM_PROTO_T_HELLO;
        n = WM_PROTO_HELLO_BYTES;
        th_put16(pay + WM_PROTO_HELLO_VERSION, pick(h, 0, 7) ? WM_PROTO_VERSION : take(h, 2));
        break;
    case 2: { /* CONFIG of a small job, a field now and then out of range */
        uint32_t w = pick(h, 2, MAX_SIDE), ht = pick(h, 2, MAX_SIDE), wild = pick(h, 0, 15), flags;
        type = WM_PROTO_T_CONFIG;
        n = WM_PROTO_CONFIG_BYTES;
        th_put16(pay + WM_PROTO_CONFIG_WIDTH, wild == 1 ? take(h, 2) : w);
        th_put16(pay + WM_PROTO_CONFIG_HEIGHT, wild == 2 ? take(h, 2) : ht);
        pay[WM_PROTO_CONFIG_LEVELS] = (uint8_t)(wild == 3 ? take(h, 1) : pick(h, 1, 5));
        pay[WM_PROTO_CONFIG_METRIC] = (uint8_t)(wild == 4 ? take(h, 1) : pick(h, 0, 1));
        pay[WM_PROTO_CONFIG_NEIGHBOURHOOD] = (uint8_t)(wild == 5 ? take(h, 1) : pick(h, 0, 1));
        pay[WM_PROTO_CONFIG_ITERATIONS] = (uint8_t)(wild == 6 ? take(h, 1) : pick(h, 0, 3));
        flags = wild == 7 ? take(h, 4) : pick(h, 0, WM_PROTO_CONFIG_KNOWN_FLAGS);
        th_put32(pay + WM_PROTO_CONFIG_FLAGS, flags);
        th_put32(pay + WM_PROTO_CONFIG_TAU, wild == 8 ? take(h, 4) : pick(h, 0, 3000));
        th_put32(pay + WM_PROTO_CONFIG_MAX_TRIANGLES, wild == 9       ? take(h, 4)
                                                      : pick(h, 0, 3) ? 0
                                                                      : pick(h, 2, 600));
        th_put32(pay + WM_PROTO_CONFIG_CAPACITY, wild == 10 ? take(h, 4) : pick(h, 0, 3) ? 0 : pick(h, 2, 1200));
        th_put32(pay + WM_PROTO_CONFIG_ZETA, scaled(h));
        th_put32(pay + WM_PROTO_CONFIG_SCALE_M, wild == 11 ? take(h, 4) : pick(h, 0, 65535));
        th_put32(pay + WM_PROTO_CONFIG_SCALE_E, wild == 12 ? take(h, 4) : pick(h, 0, 40));
        th_put32(pay + WM_PROTO_CONFIG_DELTA_P, wild == 13 ? take(h, 4) : pick(h, 0, 65535));
        th_put32(pay + WM_PROTO_CONFIG_ALPHA, wild == 14 ? take(h, 4) : pick(h, 0, 65536));
        th_put32(pay + WM_PROTO_CONFIG_DELTA_V, scaled(h));
        th_put32(pay + WM_PROTO_CONFIG_DELTA_LAMBDA, scaled(h));
        th_put32(pay + WM_PROTO_CONFIG_DELTA_C, wild == 15 ? take(h, 4) : pick(h, 0, 65536));
        th_put32(pay + WM_PROTO_CONFIG_DELTA_D, scaled(h));
        /* fields after DELTA_D (the generated header may add some) stay 0: their defaults */
        h->total = w * ht + (flags & WM_PROTO_CONFIG_MASK ? MASK_WORDS(w * ht) : 0); /* samples, mask */
        h->data_next = 0;
        break;
    }
    case 3: { /* DATA: at the device's next offset (or anywhere), heights in one of three shapes */
        uint32_t limit = (h->caps.max_payload - WM_PROTO_DATA_BYTES) / 2, off, shape = pick(h, 0, 2);
        uint32_t base = take(h, 2), step = take(h, 1);
        type = WM_PROTO_T_DATA;
        off = pick(h, 0, 7) ? h->data_next : pick(h, 0, h->total + 4);
        n = pick(h, 1, pick(h, 0, 15) ? limit : (WM_PROTO_MAX_PAYLOAD - WM_PROTO_DATA_BYTES) / 2 + 2);
        th_put32(pay + WM_PROTO_DATA_OFFSET, off);
        for (i = 0; i < n; i++) {
            uint16_t v = (uint16_t)(shape == 0 ? base : shape == 1 ? base + step * (off + i) : take(h, 2));
            th_put16(pay + WM_PROTO_DATA_BYTES + 2 * i, v);
            if (off + i < sizeof h->mirror / sizeof h->mirror[0]) h->mirror[off + i] = v;
        }
        n = WM_PROTO_DATA_BYTES + 2 * n;
        break;
    }
    case 4: { /* RUN with the CRC of what the host sent (or not) */
        uint32_t crc = 0;
        type = WM_PROTO_T_RUN;
        n = WM_PROTO_RUN_BYTES;
        for (i = 0; i < h->total && i < sizeof h->mirror / sizeof h->mirror[0]; i++) {
            uint8_t le[2];
            th_put16(le, h->mirror[i]);
            crc = wm_proto_crc32(crc, le, 2);
        }
        th_put32(pay + WM_PROTO_RUN_CRC, pick(h, 0, 7) ? crc : take(h, 4));
        break;
    }
    case 5:
    case 6: { /* ACK of the last LEVEL_END (all of it, or part), or of DONE, or of something else */
        uint32_t which = pick(h, 0, 7);
        type = WM_PROTO_T_ACK;
        n = WM_PROTO_ACK_BYTES;
        pay[WM_PROTO_ACK_KIND] = which < 5   ? WM_PROTO_T_LEVEL_END
                                 : which < 7 ? WM_PROTO_T_DONE
                                             : (uint8_t)take(h, 1);
        pay[WM_PROTO_ACK_INDEX] = which < 5 ? h->le_index : which < 7 ? 0 : (uint8_t)take(h, 1);
        th_put32(pay + WM_PROTO_ACK_HAVE, which < 3 || which > 4 ? h->le_total : pick(h, 0, h->le_total + 8));
        break;
    }
    case 8: type = WM_PROTO_T_ABORT; break;
    default: /* 7 (9, silence, is h_getc's) */ type = WM_PROTO_T_STATUS; break;
    }
    if (odd_length) { /* a length the type does not have */
        n = pick(h, 0, 16);
        for (i = 0; i < n; i++) pay[i] = (uint8_t)take(h, 1);
    }
    if ((op & 0xE0u) == 0xA0u && pick(h, 0, 3) == 0) type = (uint8_t)take(h, 1); /* any type at all */
    q_frame(h, type, pay, n, damage);
}

static int h_getc(void *ctx, uint32_t timeout_ms)
{
    host *h = ctx;
    while (h->q_pos == h->q_len) {
        size_t before = h->pos;
        h->q_pos = h->q_len = 0;
        if (!more(h)) return WM_PROTO_RX_CLOSED;
        if (h->d[h->pos] % 10 == 9) { /* silence */
            h->pos++;
            h->t += (uint64_t)(pick(h, 0, 3) ? timeout_ms : pick(h, 0, timeout_ms)) * (CLK_HZ / 1000u) + 1u;
            return WM_PROTO_RX_TIMEOUT;
        }
        next_op(h);
        if (h->pos == before) h->pos++; /* never stand still */
    }
    h->t += BYTE_CYCLES;
    return h->q[h->q_pos++];
}

static int is_device_type(uint8_t t)
{
    return t == WM_PROTO_T_OK || t == WM_PROTO_T_HELLO_REPLY || t == WM_PROTO_T_DATA_ACK ||
           t == WM_PROTO_T_STATUS_REPLY || t == WM_PROTO_T_PROGRESS || t == WM_PROTO_T_MESH ||
           t == WM_PROTO_T_LEVEL_END || t == WM_PROTO_T_DONE || t == WM_PROTO_T_ERROR;
}

/* A whole frame from the device: well formed, or a finding. */
static void device_frame(host *h)
{
    const uint8_t *f = h->rx.f;
    const char *problem = th_frame_problem(&h->rx);
    uint32_t n;
    if (problem) FAIL("the device sent %s (%zu bytes)", problem, h->rx.len);
    n = th_get16(f + 2);
    if (!is_device_type(f[0])) FAIL("the device sent frame type 0x%02x", f[0]);
    if (n > h->caps.max_payload)
        FAIL("the device sent %u payload bytes, above its max_payload %u", n, h->caps.max_payload);
    if (f[0] == WM_PROTO_T_DATA_ACK && n >= WM_PROTO_DATA_ACK_BYTES) h->data_next = th_get32(f + 4);
    if (f[0] == WM_PROTO_T_LEVEL_END && n >= WM_PROTO_LEVEL_END_BYTES) {
        h->le_index = f[4 + WM_PROTO_LEVEL_END_INDEX];
        h->le_total = th_get32(f + 4 + WM_PROTO_LEVEL_END_TOTAL);
    }
}

static void h_write(void *ctx, const uint8_t *data, size_t n)
{
    host *h = ctx;
    for (size_t i = 0; i < n; i++) {
        h->t += BYTE_CYCLES;
        if (th_rx_byte(&h->rx, data[i])) device_frame(h);
    }
}

/* The transport's optional fast paths, as the board's app/main.c has them: the bytes already in hand
 * (none: 0, and the engine falls back to getc, which draws the next operation), up to and including
 * the first delimiter or escape; and SLIP escaping done by the transport. */
static int h_read(void *ctx, uint8_t *dst, uint32_t max)
{
    host *h = ctx;
    uint32_t k = 0;
    while (k < max && h->q_pos < h->q_len) {
        uint8_t b = h->q[h->q_pos++];
        h->t += BYTE_CYCLES;
        dst[k++] = b;
        if (b == WM_PROTO_SLIP_END || b == WM_PROTO_SLIP_ESC) break;
    }
    return (int)k;
}

static void h_write_escaped(void *ctx, const uint8_t *data, size_t n)
{
    static const uint8_t esc_end[2] = {WM_PROTO_SLIP_ESC, WM_PROTO_SLIP_ESC_END};
    static const uint8_t esc_esc[2] = {WM_PROTO_SLIP_ESC, WM_PROTO_SLIP_ESC_ESC};
    for (size_t i = 0; i < n; i++) {
        if (data[i] == WM_PROTO_SLIP_END) h_write(ctx, esc_end, 2);
        else if (data[i] == WM_PROTO_SLIP_ESC) h_write(ctx, esc_esc, 2);
        else h_write(ctx, data + i, 1);
    }
}

static uint64_t h_cycles(void *ctx) { return ((host *)ctx)->t; }

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static host h;
    static wm_proto eng;
    static uint16_t heights[MAX_SIDE * MAX_SIDE];
    static uint8_t mask[2 * MASK_WORDS(MAX_SIDE * MAX_SIDE)];
    wm_proto_io io = {0};
    uint32_t w, ht;
    memset(&h, 0, sizeof h);
    h.d = data;
    h.n = size;
    w = pick(&h, 2, MAX_SIDE);
    ht = pick(&h, 2, MAX_SIDE);
    memcpy(h.caps.name, "wm-fuzz", 8);
    h.caps.fw_major = 1;
    h.caps.max_width = (uint16_t)w;
    h.caps.max_height = (uint16_t)ht;
    h.caps.max_samples = pick(&h, 4, w * ht);
    h.caps.tri_capacity = pick(&h, 2, 2 * (MAX_SIDE - 1) * (MAX_SIDE - 1));
    h.caps.max_levels = (uint8_t)pick(&h, 1, WM_PROTO_MAX_LEVELS);
    h.caps.window = (uint8_t)pick(&h, 1, WM_PROTO_MAX_WINDOW);
    /* at least CONFIG's length: a device that states less could never be configured */
    h.caps.max_payload = (uint16_t)pick(&h, MIN_PAYLOAD, WM_PROTO_MAX_PAYLOAD);
    h.caps.clk_hz = CLK_HZ;
    h.caps.features = pick(&h, 0, 15); /* reduction, initial-only, the spline bank, holes (a mask) */
    io.ctx = &h;
    io.getc = h_getc;
    io.write = h_write;
    io.cycles = h_cycles;
    io.mark = NULL;
    /* The optional paths (the board's) or the fallbacks (the native device's), chosen by the input's
     * length and not by its bytes, so that the corpus keeps its meaning. */
    io.read = (size & 1u) ? h_read : NULL;
    io.write_escaped = (size & 2u) ? h_write_escaped : NULL;
    wm_proto_init(&eng, &io, &h.caps, heights, wm_native_job, NULL);
    if (h.caps.features & WM_PROTO_FEATURE_HOLES) wm_proto_set_mask(&eng, mask, sizeof mask);
    if (wm_proto_serve(&eng) != 0) FAIL("wm_proto_serve returned non-zero");
    if (th_rx_pending(&h.rx)) FAIL("the device left a frame unfinished");
    return 0;
}
