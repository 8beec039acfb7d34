/*
 * The protocol engine's framing (proto_int.h lists the engine's parts).  A frame, both ways, SLIP-
 * delimited (0xC0 and 0xDB inside escaped as 0xDB 0xDC and 0xDB 0xDD):
 *
 *   byte  0      type   WM_PROTO_T_*
 *   byte  1      seq    the host's request number; replies carry it back
 *   bytes 2..3   len    payload bytes, 0..WM_PROTO_MAX_PAYLOAD
 *   bytes 4..    payload
 *   last 4       CRC-32 (zlib's) of bytes 0 .. 3+len
 *
 * A run of bytes between two 0xC0 that is not such a frame (short, long, bad escape, wrong length
 * field, wrong CRC) is dropped without an answer; so is a frame whose next byte does not come within
 * WM_PROTO_BYTE_TIMEOUT_MS.  The host finds out by its own timeout and sends again.  A whole frame
 * longer than the device's max_payload gets ERROR BAD_LENGTH.
 */
#include "proto_int.h"

#define RX_BURST 256u

/* ---------------------------------------------------------------------------------------------- */
/* Sending: SLIP-encode into a buffer, written out when it may not hold the next piece and before every
 * read */

static void out_raw(wm_proto *p, uint8_t b)
{
    if (p->out_len == sizeof p->out) out_flush(p);
    p->out[p->out_len++] = b;
}

/* n bytes SLIP-escaped (each takes at most two); a long run straight through the transport's
 * write_escaped when it has one (no copy through the buffer) */
static void out_slip(wm_proto *p, const uint8_t *s, uint32_t n)
{
    if (p->io.write_escaped && n >= 64) {
        out_flush(p);
        p->io.write_escaped(p->io.ctx, s, n);
        return;
    }
    while (n) {
        uint32_t k;
        uint8_t *d;
        const uint8_t *e;
        if (sizeof p->out - p->out_len < 64) out_flush(p);
        k = (uint32_t)(sizeof p->out - p->out_len) / 2;
        if (k > n) k = n;
        n -= k;
        d = p->out + p->out_len;
        for (e = s + k; s < e; s++) {
            uint8_t b = *s;
            if (b == WM_PROTO_SLIP_END) {
                *d++ = WM_PROTO_SLIP_ESC;
                *d++ = WM_PROTO_SLIP_ESC_END;
            } else if (b == WM_PROTO_SLIP_ESC) {
                *d++ = WM_PROTO_SLIP_ESC;
                *d++ = WM_PROTO_SLIP_ESC_ESC;
            } else {
                *d++ = b;
            }
        }
        p->out_len = (uint32_t)(d - p->out);
    }
}

void wm_proto_send_encoded(wm_proto *p, const uint8_t head[WM_PROTO_HEADER_BYTES], const uint8_t *a, uint32_t na,
                           const uint8_t *b, uint32_t nb, uint32_t crc)
{
    uint8_t tail[WM_PROTO_CRC_BYTES];
    put32(tail, crc);
    out_raw(p, WM_PROTO_SLIP_END);
    out_slip(p, head, WM_PROTO_HEADER_BYTES);
    out_slip(p, a, na);
    out_slip(p, b, nb);
    out_slip(p, tail, sizeof tail);
    out_raw(p, WM_PROTO_SLIP_END);
}

static void send_frame2(wm_proto *p, uint8_t type, uint8_t seq, const uint8_t *a, uint32_t na, const uint8_t *b,
                        uint32_t nb)
{
    uint8_t head[WM_PROTO_HEADER_BYTES];
    frame_head(head, type, seq, na + nb);
    wm_proto_send_encoded(
        p, head, a, na, b, nb,
        ~wm_proto_crc_run(wm_proto_crc_run(wm_proto_crc_run(~0u, head, sizeof head), a, na), b, nb));
}

void wm_proto_send_frame(wm_proto *p, uint8_t type, uint8_t seq, const uint8_t *payload, uint32_t n)
{
    send_frame2(p, type, seq, payload, n, 0, 0);
}

/* ---------------------------------------------------------------------------------------------- */
/* Receiving */

#ifndef WM_PROTO_WHOLE_FRAMES
/* The bytes between two delimiters: a frame with the right length field and CRC?  (The CRC in one
 * go at the end: on a UART, the RX FIFO's 64 bytes are some 140 k cycles at 115200 baud, a 1 KB frame's
 * CRC some 30 k.) */
static int rx_check(wm_proto *p)
{
    uint32_t n, body = p->rx_len - WM_PROTO_CRC_BYTES;
    if (p->rx_len < WM_PROTO_HEADER_BYTES + WM_PROTO_CRC_BYTES) return 0;
    n = get16(p->rx.b + 2);
    if (p->rx_len != WM_PROTO_HEADER_BYTES + n + WM_PROTO_CRC_BYTES) return 0;
    if (~wm_proto_crc_run(~0u, p->rx.b, body) != get32(p->rx.b + body)) return 0;
    p->f_type = p->rx.b[0];
    p->f_seq = p->rx.b[1];
    p->f_len = (uint16_t)n;
    p->f_pay = p->rx.b + WM_PROTO_HEADER_BYTES;
    return 1;
}

/* One received byte: 1 when it completes a valid frame (in f_type, f_seq, f_len, f_pay). */
static int rx_byte(wm_proto *p, int c)
{
    if (c == WM_PROTO_SLIP_END) {
        /* the end of a frame (or a delimiter before one) */
        int ok = !p->rx_bad && !p->rx_esc && p->rx_len && rx_check(p);
        if (!ok && (p->rx_len || p->rx_bad || p->rx_esc)) p->bad_frames++;
        rx_reset(p);
        if (ok && p->f_len > p->caps.max_payload) {
            /* a whole frame, but longer than this device said it takes (HELLO's max_payload) */
            wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return 0;
        }
        return ok;
    }
    if (p->rx_bad) return 0; /* discarding until the next delimiter */
    if (p->rx_esc) {
        p->rx_esc = 0;
        if (c == WM_PROTO_SLIP_ESC_END) {
            c = WM_PROTO_SLIP_END;
        } else if (c == WM_PROTO_SLIP_ESC_ESC) {
            c = WM_PROTO_SLIP_ESC;
        } else {
            p->rx_bad = 1; /* an escape of nothing */
            return 0;
        }
    } else if (c == WM_PROTO_SLIP_ESC) {
        p->rx_esc = 1;
        return 0;
    }
    if (p->rx_len >= sizeof p->rx.b) {
        p->rx_bad = 1; /* longer than any frame */
        return 0;
    }
    p->rx.b[p->rx_len++] = (uint8_t)c;
    return 0;
}

/* Bytes already received, at most max, into dst, up to and including the first delimiter or escape
 * (wm_proto_io.read's contract): their number, or WM_PROTO_RX_CLOSED. */
static int rx_take(wm_proto *p, uint8_t *dst, uint32_t max)
{
    uint32_t n = 0;
    if (p->io.read) return p->io.read(p->io.ctx, dst, max);
    while (n < max) {
        int c = p->io.getc(p->io.ctx, 0);
        if (c < 0) return c == WM_PROTO_RX_CLOSED && n == 0 ? WM_PROTO_RX_CLOSED : (int)n;
        dst[n++] = (uint8_t)c;
        if (c == WM_PROTO_SLIP_END || c == WM_PROTO_SLIP_ESC) break;
    }
    return (int)n;
}

/* After the byte c: the bytes already waiting, at most RX_BURST, each in its place in the frame buffer
 * (all but the last of a read are plain bytes: they stay where they landed; the last goes through
 * rx_byte).  1 when a frame is complete, -1 when the link closed, 0 when no byte waits (or the burst's
 * bound is reached: it keeps a flood without delimiters from holding off the caller's timeouts). */
static int rx_burst(wm_proto *p, int c)
{
    uint32_t k = 1;
    if (rx_byte(p, c)) return 1;
    while (k < RX_BURST) {
        uint32_t room = (uint32_t)sizeof p->rx.b - p->rx_len;
        int n;
        if (p->rx_esc || p->rx_bad || room == 0) { /* a byte to translate, or to drop */
            c = p->io.getc(p->io.ctx, 0);
            if (c < 0) return c == WM_PROTO_RX_CLOSED ? -1 : 0;
            k++;
            if (rx_byte(p, c)) return 1;
            continue;
        }
        if (room > RX_BURST - k) room = RX_BURST - k;
        n = rx_take(p, p->rx.b + p->rx_len, room);
        if (n <= 0) return n == WM_PROTO_RX_CLOSED ? -1 : 0;
        k += (uint32_t)n;
        p->rx_len += (uint32_t)n - 1u;
        if (rx_byte(p, p->rx.b[p->rx_len])) return 1;
    }
    return 0;
}

#endif

/* A transport that receives frames whole (io.frame): it stores DATA's samples while a session receives,
 * for the session's CONFIG (told before the next frame comes in, so every DATA frame of the session is
 * stored and none outside it). */
static int rx_frame_whole(wm_proto *p, uint32_t wait_ms)
{
    wm_proto_frame_in f;
    int r, want = p->state == WM_PROTO_STATE_RECEIVING || p->state == WM_PROTO_STATE_READY;
    if (want != p->up_armed || (want && p->up_session != p->session_id)) {
        uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height;
        p->io.upload(p->io.ctx, want ? (uint32_t)p->job.width : 0u, want ? wh : 0u, want ? p->total : 0u);
        p->up_armed = (uint8_t)want;
        p->up_session = p->session_id;
    }
    for (;;) {
        out_flush(p);
        r = p->io.frame(p->io.ctx, wait_ms, &f);
        if (r == WM_PROTO_RX_CLOSED) return -1;
        if (r != 1) return 0;
        p->f_type = f.type;
        p->f_seq = f.seq;
        p->f_len = f.len;
        p->f_pay = f.payload;
        p->f_data = f.data;
        p->f_code = f.code;
        if (p->f_len <= p->caps.max_payload) return 1;
        /* a whole frame, but longer than this device said it takes (HELLO's max_payload) */
        wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
    }
}

int wm_proto_rx_frame(wm_proto *p, uint32_t wait_ms)
{
#ifdef WM_PROTO_WHOLE_FRAMES
    return rx_frame_whole(p, wait_ms);
#else
    uint64_t t0, limit, bt;
    if (p->io.frame) return rx_frame_whole(p, wait_ms);
    t0 = now(p);
    limit = ms_to_cycles(p, wait_ms);
    bt = ms_to_cycles(p, WM_PROTO_BYTE_TIMEOUT_MS);
    for (;;) {
        uint64_t t = now(p), spent = t - t0;
        int in_frame = p->rx_len || p->rx_esc || p->rx_bad;
        uint32_t to;
        int c;
        if (in_frame && t - p->rx_last >= bt) { /* the rest of this frame is not coming */
            p->bad_frames++;
            rx_reset(p);
            in_frame = 0;
        }
        if (spent >= limit) return 0;
        /* milliseconds left, rounded up (a 32-bit division where it fits: no libgcc call per byte) */
        to = limit - spent > 0xFFFFFFFFu ? wait_ms : (uint32_t)(limit - spent) / p->ms_cycles + 1u;
        if (in_frame && to > WM_PROTO_BYTE_TIMEOUT_MS) to = WM_PROTO_BYTE_TIMEOUT_MS;
        out_flush(p);
        c = p->io.getc(p->io.ctx, to);
        if (c == WM_PROTO_RX_CLOSED) return -1;
        if (c < 0) continue;
        /* a burst of what is already waiting, without the timeouts' bookkeeping (the clock reads and
         * the division above cost some 400 cycles a byte on the soft CPU) */
        c = rx_burst(p, c);
        p->rx_last = now(p);
        if (c != 0) return c;
    }
#endif
}

/* A frame with at most WM_PROTO_ERROR_BYTES of payload, SLIP-encoded into dst (for a connection the
 * engine does not serve); its length, 0 when cap is too small. */
static size_t encode_small(uint8_t *dst, size_t cap, uint8_t type, uint8_t seq, const uint8_t *payload, uint32_t n)
{
    uint8_t raw[WM_PROTO_HEADER_BYTES + WM_PROTO_ERROR_BYTES + WM_PROTO_CRC_BYTES];
    size_t len = 0, k;
    if (n > WM_PROTO_ERROR_BYTES || cap < WM_PROTO_BUSY_FRAME_MAX) return 0;
    raw[0] = type;
    raw[1] = seq;
    put16(raw + 2, n);
    for (k = 0; k < n; k++) raw[WM_PROTO_HEADER_BYTES + k] = payload[k];
    put32(raw + WM_PROTO_HEADER_BYTES + n, wm_proto_crc32(0, raw, WM_PROTO_HEADER_BYTES + n));
    dst[len++] = WM_PROTO_SLIP_END;
    for (k = 0; k < WM_PROTO_HEADER_BYTES + n + WM_PROTO_CRC_BYTES; k++) {
        if (raw[k] == WM_PROTO_SLIP_END || raw[k] == WM_PROTO_SLIP_ESC) {
            dst[len++] = WM_PROTO_SLIP_ESC;
            dst[len++] = raw[k] == WM_PROTO_SLIP_END ? WM_PROTO_SLIP_ESC_END : WM_PROTO_SLIP_ESC_ESC;
        } else {
            dst[len++] = raw[k];
        }
    }
    dst[len++] = WM_PROTO_SLIP_END;
    return len;
}

size_t wm_proto_busy_frame(uint8_t *dst, size_t cap)
{
    uint8_t b[WM_PROTO_ERROR_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_ERROR_CODE] = WM_PROTO_E_BUSY;
    b[WM_PROTO_ERROR_STATE] = WM_PROTO_STATE_IDLE; /* nothing starts on this connection */
    return encode_small(dst, cap, WM_PROTO_T_ERROR, 0, b, sizeof b);
}
