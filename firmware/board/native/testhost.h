/*
 * The host's end of the line for programs that drive the protocol engine (../src/proto_*.c) directly on
 * a virtual clock, with no transport around it: wm_clocktest (clocktest.c, the cycle accounting) and
 * fuzz_proto (fuzz/proto_fuzz.c).  It frames the host's requests and takes the device's bytes apart,
 * written apart from the engine's own framing so that it checks the engine rather than mirror it (only
 * the CRC-32, wm_proto_crc32, is shared).
 */
#ifndef WM_TESTHOST_H
#define WM_TESTHOST_H

#include <stddef.h>
#include <stdint.h>

#include "proto.h"

/* Little-endian fields */
void th_put16(uint8_t *b, uint32_t v);
void th_put32(uint8_t *b, uint32_t v);
uint32_t th_get16(const uint8_t *b);
uint32_t th_get32(const uint8_t *b);
uint64_t th_get64(const uint8_t *b);

/* A frame (type, seq, the payload's n bytes, CRC-32), SLIP-encoded into dst; its length, or 0 when
 * cap is below 2 (8 + n) + 2 (every byte escaped, two ENDs).  n may be any 16-bit length: a test may
 * send more than the device takes. */
size_t th_frame(uint8_t *dst, size_t cap, uint8_t type, uint8_t seq, const uint8_t *payload, uint32_t n);

/* The device's bytes, unescaped into frames */
typedef struct th_rx {
    uint8_t f[WM_PROTO_MAX_FRAME + 64]; /* the frame so far (type, seq, len, payload, CRC) */
    size_t len;
    int esc;  /* the last byte was an escape */
    int bad;  /* a bad escape, or more bytes than f holds: the frame is broken */
    int done; /* f holds a whole frame; the next byte starts another */
} th_rx;

/* One byte from the device (an all-zero th_rx to begin).  Returns 1 when it ends a non-empty run of
 * bytes: the frame is f[0..len) (bad: broken) until the next call. */
int th_rx_byte(th_rx *r, uint8_t c);

/* 1 when bytes of a frame came and its END did not (the device stopped in the middle of a frame) */
int th_rx_pending(const th_rx *r);

/* NULL when f[0..len) is a well-formed frame (whole header, length field matching the bytes, CRC
 * right), else what is wrong. */
const char *th_frame_problem(const th_rx *r);

#endif
