/*
 * The protocol engine's shared declarations (private to firmware/board/src/proto_*.c; the API is
 * include/proto.h).  The engine is split by job:
 *
 *   proto_crc.c      CRC-32: the table, the bulk CRC (slicing by four), CRC combination
 *   proto_slip.c     SLIP framing: a frame out (escaped, through a buffer), frames in (checked), the
 *                    BUSY frame for connections the engine does not serve
 *   proto_session.c  the session: HELLO, STATUS, BAUD, ABORT, RUN, the state machine, the cycle
 *                    accounting, the job's waits for the host, DONE, wm_proto_init and wm_proto_serve
 *   proto_config.c   CONFIG: its fields checked against the protocol's ranges and the device's caps
 *   proto_data.c     the upload: DATA (raw and Rice-coded samples, the mask's words)
 *   proto_emit.c     mesh emission: the level stream (raw or delta-coded), its MESH frames, LEVEL_END
 *
 * Helpers every part uses are static inline here; a function one part calls in another is declared
 * here with the prefix wm_proto_ (every symbol of the engine starts with it).
 */
#ifndef WM_PROTO_INT_H
#define WM_PROTO_INT_H

#include "proto.h"

/* Both devices (rv32, x86-64) are little-endian, the wire's order: words and halfwords go straight
 * between it and memory.  Elsewhere byte by byte. */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#define WM_LITTLE_ENDIAN 1
#else
#define WM_LITTLE_ENDIAN 0
#endif

/* DATA's samples start at a word, MESH's stream bytes at an even offset (read and written as pairs of
 * halfwords and as halfwords) */
typedef char proto_halfword_payloads[(WM_PROTO_HEADER_BYTES + WM_PROTO_DATA_BYTES) % 4 == 0 &&
                                             WM_PROTO_MESH_BYTES % 2 == 0 &&
                                             WM_PROTO_LEVEL_HEADER_BYTES % 2 == 0 &&
                                             WM_PROTO_FREE_VERTEX == WM_FREE
                                         ? 1
                                         : -1];

/* Code that runs between jobs, on the board after the image's code and data (board.ld's .wm_tail), so
 * that what it takes moves nothing else; the board is the engine's one rv32 build */
#ifdef __riscv
#define WM_PROTO_BETWEEN_JOBS __attribute__((section(".wm_tail"), noinline))
#else
#define WM_PROTO_BETWEEN_JOBS
#endif

/* Why a job stops (wm_proto.abort) */
#define ABORT_HOST 1u   /* ABORT or HELLO: already answered, no DONE */
#define ABORT_NO_ACK 2u /* the host stopped answering */
#define ABORT_CLOSED 3u /* the link closed */

/* ---------------------------------------------------------------------------------------------- */
/* Little-endian fields */

static inline uint16_t get16(const uint8_t *b) { return (uint16_t)(b[0] | (uint16_t)b[1] << 8); }

static inline uint32_t get32(const uint8_t *b)
{
    return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}

static inline uint64_t get64(const uint8_t *b) { return (uint64_t)get32(b) | (uint64_t)get32(b + 4) << 32; }

static inline void put16(uint8_t *b, uint32_t v)
{
    b[0] = (uint8_t)v;
    b[1] = (uint8_t)(v >> 8);
}

static inline void put32(uint8_t *b, uint32_t v)
{
    put16(b, v);
    put16(b + 2, v >> 16);
}

static inline void put64(uint8_t *b, uint64_t v)
{
    put32(b, (uint32_t)v);
    put32(b + 4, (uint32_t)(v >> 32));
}

static inline void zero(uint8_t *b, size_t n)
{
    for (size_t i = 0; i < n; i++) b[i] = 0;
}

/* ---------------------------------------------------------------------------------------------- */
/* Time */

static inline uint64_t now(const wm_proto *p) { return p->io.cycles(p->io.ctx); }

static inline uint64_t ms_to_cycles(const wm_proto *p, uint32_t ms) { return (uint64_t)ms * p->ms_cycles; }

/* ---------------------------------------------------------------------------------------------- */
/* CRC-32 (proto_crc.c) */

extern const uint32_t wm_proto_crc_table[256];

static inline uint32_t crc_update(uint32_t c, uint8_t byte)
{
    return wm_proto_crc_table[(c ^ byte) & 0xFFu] ^ (c >> 8);
}

/* Two bytes, a 16-bit word's little-endian bytes (the wire order of samples and mask words). */
static inline uint32_t crc_update16(uint32_t c, uint32_t v)
{
    c ^= v & 0xFFFFu;
    c = wm_proto_crc_table[c & 0xFFu] ^ (c >> 8);
    return wm_proto_crc_table[c & 0xFFu] ^ (c >> 8);
}

/* The slicing tables (wm_proto_init calls it). */
void wm_proto_crc_init(void);
/* The bulk CRC over n bytes at s; c is the register (the inverted CRC). */
uint32_t wm_proto_crc_run(uint32_t c, const uint8_t *s, size_t n);
/* The CRC-32 of A B from crc_a = crc(A), crc_b = crc(B) and nb = |B|. */
uint32_t wm_proto_crc_combine(wm_proto *p, uint32_t crc_a, uint32_t crc_b, uint32_t nb);

/* ---------------------------------------------------------------------------------------------- */
/* SLIP framing (proto_slip.c) */

static inline void out_flush(wm_proto *p)
{
    if (p->out_len) {
        p->io.write(p->io.ctx, p->out, p->out_len);
        p->out_len = 0;
    }
}

static inline void frame_head(uint8_t head[WM_PROTO_HEADER_BYTES], uint8_t type, uint8_t seq, uint32_t n)
{
    head[0] = type;
    head[1] = seq;
    put16(head + 2, n);
}

static inline void rx_reset(wm_proto *p)
{
#ifdef WM_PROTO_WHOLE_FRAMES
    (void)p; /* the transport deframes */
#else
    p->rx_len = 0;
    p->rx_esc = 0;
    p->rx_bad = 0;
#endif
}

/* One frame: header, payload (two pieces, either may be empty), CRC (of the header and payload). */
void wm_proto_send_encoded(wm_proto *p, const uint8_t head[WM_PROTO_HEADER_BYTES], const uint8_t *a, uint32_t na,
                           const uint8_t *b, uint32_t nb, uint32_t crc);
/* One frame of a payload in one piece. */
void wm_proto_send_frame(wm_proto *p, uint8_t type, uint8_t seq, const uint8_t *payload, uint32_t n);
/* Waits up to wait_ms for a valid frame: 1 (in f_type, f_seq, f_len, f_pay until the next call),
 * 0 when the time is up, -1 when the link closed.  Damaged frames are dropped and counted. */
int wm_proto_rx_frame(wm_proto *p, uint32_t wait_ms);

/* ---------------------------------------------------------------------------------------------- */
/* The session (proto_session.c) */

/* A frame of the device's own (not a reply): the device's sequence number. */
void wm_proto_send_own(wm_proto *p, uint8_t type, const uint8_t *payload, uint32_t n);
/* A reply to the frame just received; kept for a duplicate of it when it answers CONFIG/RUN/ABORT. */
void wm_proto_reply(wm_proto *p, uint8_t type, const uint8_t *payload, uint32_t n);
/* A duplicate of the last CONFIG, RUN or ABORT (the host sent it again: our reply was lost): 1, and
 * the cached reply sent again. */
int wm_proto_duplicate(wm_proto *p);
void wm_proto_reply_ok(wm_proto *p);
/* ERROR in answer to the frame just received. */
void wm_proto_reply_error(wm_proto *p, uint8_t code, uint32_t detail);
/* Back to IDLE: no samples held. */
void wm_proto_session_end(wm_proto *p);
/* PROGRESS of (stage, level). */
void wm_proto_send_progress(wm_proto *p, int stage, int level);
/* Waits for the ACK (or RESUME) of (kind, index), sending `again` each time ACK_TIMEOUT_MS passes
 * without a valid frame.  Returns 1 with *have, or 0 when the job must stop (p->abort says why: the
 * host ended it, the link closed, or no valid frame came for caps.link_timeout_s: a pause of the line
 * or of the host, however often, is not an error). */
int wm_proto_wait_ack(wm_proto *p, uint8_t kind, uint8_t index, uint32_t *have, void (*again)(wm_proto *));

/* Cycle accounting (proto_session.c says how the clocks run): the cycles since the last charge go to
 * the clock that ran, the link's or the current stage's. */
void wm_proto_charge(wm_proto *p);

/* Tells the transport which clock runs from now on: `stage`'s, or the link's while link_depth > 0
 * (io.mark: on the board the stage marker, its sync and, where a stage's clock starts, the CPU's cache
 * flush).  Every switch marks first and then reads the cycle counter (wm_proto_charge): the clock that
 * ends pays the mark, and the stage that starts starts from the state the mark leaves (the SDRAM
 * synced, the caches empty) whatever the one before left behind; the other order left the few
 * instructions between the counter read and the flush to hit or miss a cache as the clock before had
 * left it (docs/soc.md, "Cycle accounting"). */
static inline void mark(const wm_proto *p, int stage, int link_depth)
{
    if (p->io.mark) {
        uint32_t c = stage >= 0 && stage < WM_PROTO_STAGE_COUNT ? (uint32_t)stage : WM_PROTO_CLOCK_NONE;
        p->io.mark(p->io.ctx, link_depth ? c | WM_PROTO_CLOCK_LINK : c);
    }
}

/* Another stage begins (not inside link I/O); -1: no stage. */
static inline void stage_enter(wm_proto *p, int stage)
{
    mark(p, stage, p->link_depth);
    wm_proto_charge(p);
    p->stage = stage;
}

/* Link I/O begins: the stage's clock stops, the link's runs (nested calls count once). */
static inline void link_begin(wm_proto *p)
{
    if (p->link_depth == 0) {
        mark(p, p->stage, 1);
        wm_proto_charge(p); /* to the stage */
    }
    p->link_depth++;
}

/* Link I/O ends: the stage's clock runs again. */
static inline void link_end(wm_proto *p)
{
    if (p->link_depth == 1) {
        mark(p, p->stage, 0);
        wm_proto_charge(p); /* to the link */
    }
    p->link_depth--;
}

/* ---------------------------------------------------------------------------------------------- */
/* CONFIG (proto_config.c), the upload (proto_data.c) */

/* CONFIG: a new session when its fields are good, ERROR otherwise. */
void wm_proto_do_config(wm_proto *p);
/* DATA: samples (or the mask's words) stored, DATA_ACK. */
void wm_proto_do_data(wm_proto *p);

#endif /* WM_PROTO_INT_H */
