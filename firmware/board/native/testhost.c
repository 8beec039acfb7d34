/* The host's end of the line for the engine's test programs (testhost.h). */
#include "testhost.h"

void th_put16(uint8_t *b, uint32_t v)
{
    b[0] = (uint8_t)v;
    b[1] = (uint8_t)(v >> 8);
}

void th_put32(uint8_t *b, uint32_t v)
{
    th_put16(b, v);
    th_put16(b + 2, v >> 16);
}

uint32_t th_get16(const uint8_t *b) { return (uint32_t)b[0] | (uint32_t)b[1] << 8; }

uint32_t th_get32(const uint8_t *b) { return th_get16(b) | th_get16(b + 2) << 16; }

uint64_t th_get64(const uint8_t *b) { return (uint64_t)th_get32(b) | (uint64_t)th_get32(b + 4) << 32; }

static size_t put_escaped(uint8_t *dst, size_t len, uint8_t c)
{
    if (c == WM_PROTO_SLIP_END || c == WM_PROTO_SLIP_ESC) {
        dst[len++] = WM_PROTO_SLIP_ESC;
        dst[len++] = c == WM_PROTO_SLIP_END ? WM_PROTO_SLIP_ESC_END : WM_PROTO_SLIP_ESC_ESC;
    } else {
        dst[len++] = c;
    }
    return len;
}

size_t th_frame(uint8_t *dst, size_t cap, uint8_t type, uint8_t seq, const uint8_t *payload, uint32_t n)
{
    uint8_t head[WM_PROTO_HEADER_BYTES], tail[WM_PROTO_CRC_BYTES];
    size_t len = 0;
    uint32_t i;
    if (n > 0xFFFFu || cap < 2 * (WM_PROTO_HEADER_BYTES + (size_t)n + WM_PROTO_CRC_BYTES) + 2) return 0;
    head[0] = type;
    head[1] = seq;
    th_put16(head + 2, n);
    th_put32(tail, wm_proto_crc32(wm_proto_crc32(0, head, sizeof head), payload, n));
    dst[len++] = WM_PROTO_SLIP_END;
    for (i = 0; i < sizeof head; i++) len = put_escaped(dst, len, head[i]);
    for (i = 0; i < n; i++) len = put_escaped(dst, len, payload[i]);
    for (i = 0; i < sizeof tail; i++) len = put_escaped(dst, len, tail[i]);
    dst[len++] = WM_PROTO_SLIP_END;
    return len;
}

int th_rx_byte(th_rx *r, uint8_t c)
{
    if (r->done) {
        r->len = 0;
        r->esc = r->bad = r->done = 0;
    }
    if (c == WM_PROTO_SLIP_END) {
        r->bad |= r->esc; /* an escape must be followed by ESC_END or ESC_ESC */
        r->done = r->len || r->bad;
        return r->done;
    }
    if (r->esc) {
        r->esc = 0;
        if (c == WM_PROTO_SLIP_ESC_END) c = WM_PROTO_SLIP_END;
        else if (c == WM_PROTO_SLIP_ESC_ESC) c = WM_PROTO_SLIP_ESC;
        else r->bad = 1;
    } else if (c == WM_PROTO_SLIP_ESC) {
        r->esc = 1;
        return 0;
    }
    if (r->len < sizeof r->f) r->f[r->len++] = c;
    else r->bad = 1;
    return 0;
}

int th_rx_pending(const th_rx *r) { return !r->done && (r->len || r->esc || r->bad); }

const char *th_frame_problem(const th_rx *r)
{
    if (r->bad) return "a bad SLIP escape, or a frame too long";
    if (r->len < WM_PROTO_HEADER_BYTES + WM_PROTO_CRC_BYTES) return "a frame shorter than header and CRC";
    if (r->len != WM_PROTO_HEADER_BYTES + th_get16(r->f + 2) + WM_PROTO_CRC_BYTES)
        return "a length field that does not match the frame";
    if (wm_proto_crc32(0, r->f, r->len - WM_PROTO_CRC_BYTES) != th_get32(r->f + r->len - WM_PROTO_CRC_BYTES))
        return "a wrong CRC";
    return 0;
}
