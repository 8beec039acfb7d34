/*
 * wavemesh wire protocol, device side: a transport-agnostic engine (docs/protocol.md).
 *
 * The engine speaks the protocol over two byte callbacks (read one byte with a timeout, write bytes)
 * and a cycle counter; it touches no hardware, allocates nothing and never waits without a timeout.
 * The board program (firmware/board/app/main.c) gives it the UART; the native stand-in device
 * (firmware/board/native/) gives it a TCP socket.  Both hand in a job function that turns the
 * received heights and parameters into meshes, level by level:
 *
 *     static wm_proto eng;                                  (about 3 KiB: buffers inside)
 *     wm_proto_init(&eng, &io, &caps, heights, job, job_ctx);
 *     wm_proto_serve(&eng);                                 (returns only when the link closes)
 *
 *     int job(void *ctx, const wm_proto_job *j, wm_proto *p, uint32_t *detail) {
 *         wm_proto_stage(p, WM_PROTO_STAGE_FILTER, j->levels);   ... filter bank ...
 *         wm_proto_stage(p, WM_PROTO_STAGE_TEMPLATE, j->levels); ... initial triangulation ...
 *         wm_proto_stage(p, WM_PROTO_STAGE_REFINE, m);           ... refiner ...
 *         rc = wm_proto_emit_level(p, mesh, &stats, last);  if (rc) return rc;
 *         ...
 *         return WM_PROTO_E_NONE;        (or WM_PROTO_E_CAPACITY / WM_PROTO_E_JOB with *detail)
 *     }
 *
 * Cycle accounting (DONE): from RUN on, exactly one clock runs at a time: the current stage's
 * (filter, template, refine, emit: work that depends only on the job) or, inside link I/O (every
 * frame the job sends, every wait for the host), the link's.  So a stage's count never holds a
 * cycle that the host's timing, the line's speed or the frames' contents (sequence numbers,
 * timestamps, SLIP escapes) can change.
 *
 * Every public symbol starts with wm_proto_.  Frame types, error codes, limits and field offsets
 * come from the generated wm_protocol.h (host/wavemesh/device/protocol.py is their one source).
 */
#ifndef WM_PROTO_H
#define WM_PROTO_H

#include <stddef.h>
#include <stdint.h>

#include "wavemesh.h"
#include "wm_protocol.h"

#ifdef __cplusplus
extern "C" {
#endif

/* getc results besides a byte 0..255 */
#define WM_PROTO_RX_TIMEOUT (-1) /* no byte within the timeout */
#define WM_PROTO_RX_CLOSED (-2)  /* the link is gone (a socket closed): wm_proto_serve returns */

/* wm_proto_serve's results */
#define WM_PROTO_SERVE_CLOSED 0 /* the link closed */
#define WM_PROTO_SERVE_IDLE 1   /* no valid frame for caps.idle_timeout_ms outside a session: close it */

/* Room for wm_proto_busy_frame's frame: every byte of the header, payload and CRC escaped, two ENDs */
#define WM_PROTO_BUSY_FRAME_MAX (2 * (WM_PROTO_HEADER_BYTES + WM_PROTO_ERROR_BYTES + WM_PROTO_CRC_BYTES) + 2)

/* Which clock runs (wm_proto_io.mark): a stage WM_PROTO_STAGE_*, WM_PROTO_CLOCK_NONE (between jobs,
 * before the job's first stage), or WM_PROTO_CLOCK_LINK | the stage that link I/O interrupted. */
#define WM_PROTO_CLOCK_NONE 0xFFu
#define WM_PROTO_CLOCK_LINK 0x100u

/* The transport.  getc, write and cycles are required; read and mark may be NULL. */
/* A frame a transport received whole (wm_proto_io.frame): deframed and checked, the payload in the
 * transport's memory until the next call. */
typedef struct wm_proto_frame_in {
    uint8_t type, seq;
    uint16_t len;
    const uint8_t *payload;
    /* data: an armed DATA frame whose samples below W H the transport stored itself (wm_proto_io.upload);
     * code: then 0 (stored, or nothing to store), 1 BAD_LENGTH, 2 BAD_OFFSET, 3 a start beyond the
     * samples stored, 4 a CODING_RICE tail that is not one (memmap.py, UPLOAD.STATUS.CODE) */
    uint8_t data, code;
} wm_proto_frame_in;

#define WM_PROTO_UPLOAD_STREAM 4u /* wm_proto_frame_in.code: the Rice stream is not one */

typedef struct wm_proto_io {
    void *ctx;
    /* The next received byte, waiting up to timeout_ms milliseconds (0: do not wait);
     * WM_PROTO_RX_TIMEOUT or WM_PROTO_RX_CLOSED otherwise. */
    int (*getc)(void *ctx, uint32_t timeout_ms);
    /* Optional, for speed (NULL: getc with timeout 0, a byte at a time): the bytes already received,
     * at most max, into dst without waiting, up to and including the first WM_PROTO_SLIP_END or
     * WM_PROTO_SLIP_ESC; their number (0: none waiting) or WM_PROTO_RX_CLOSED. */
    int (*read)(void *ctx, uint8_t *dst, uint32_t max);
    /* Send n bytes (may block while a FIFO drains; must not block forever). */
    void (*write)(void *ctx, const uint8_t *data, size_t n);
    /* Optional, for speed (NULL: the engine escapes into its buffer and calls write): send n bytes
     * SLIP-escaped, WM_PROTO_SLIP_END as WM_PROTO_SLIP_ESC WM_PROTO_SLIP_ESC_END and WM_PROTO_SLIP_ESC
     * as WM_PROTO_SLIP_ESC WM_PROTO_SLIP_ESC_ESC (the engine uses it for long runs: payloads). */
    void (*write_escaped)(void *ctx, const uint8_t *data, size_t n);
    /* A free-running counter at caps.clk_hz (wraps after 2^64). */
    uint64_t (*cycles)(void *ctx);
    /* Optional: called whenever another clock starts to run (WM_PROTO_CLOCK_*), right before the
     * engine reads the counter, so that a trace of the calls shows what each clock counted. */
    void (*mark)(void *ctx, uint32_t clock);
    /* Optional (NULL: the device cannot switch its rate; caps.div_max must then be 0): switch the line
     * to div clock cycles per bit (at caps.clk_hz) once every byte written so far has left the
     * transmitter (BAUD: the OK goes out at the old rate); bytes half received are dropped. */
    void (*set_divisor)(void *ctx, uint32_t div);
    /* Optional (NULL: the engine deframes what getc and read give): a transport that receives frames
     * whole and stores DATA's samples itself (the board's upload block, rtl/upload_rx.v: docs/protocol.md,
     * "The upload in hardware").  frame: the previous frame is done with; wait up to timeout_ms for the
     * next good one: 1 (in *f), WM_PROTO_RX_TIMEOUT, WM_PROTO_RX_CLOSED.  upload: from the next frame on,
     * DATA frames of a session of width W, samples W H and total words are stored (samples > 0: a new
     * session, nothing stored yet) or not (samples 0).  upload_crc: the CRC-32 register (not inverted)
     * of the samples stored in order.  All three or none; a build with WM_PROTO_WHOLE_FRAMES (the board's:
     * firmware/board/CMakeLists.txt) has no byte deframer and its frame buffer, and needs them. */
    int (*frame)(void *ctx, uint32_t timeout_ms, wm_proto_frame_in *f);
    void (*upload)(void *ctx, uint32_t width, uint32_t samples, uint32_t total);
    uint32_t (*upload_crc)(void *ctx);
} wm_proto_io;

#ifdef WM_PROTO_STACK
/* A device that measures its stack (built with WM_PROTO_STACK: the board, firmware/board/CMakeLists.txt)
 * defines this: the stack's high-water mark, bytes from its top to the deepest word written since the
 * previous call (since start-up for the first), the mark reset for the next, and its reserve in
 * *stack_bytes.  The engine calls it after each job, while no clock runs (DONE.stack_peak,
 * DONE.stack_bytes; without WM_PROTO_STACK both are 0). */
uint32_t wm_proto_stack_peak(uint32_t *stack_bytes);
#endif

/* What the device states in HELLO_REPLY (docs/protocol.md, HELLO_REPLY). */
typedef struct wm_proto_caps {
    char name[8];            /* e.g. "wm-board", NUL-padded */
    uint8_t fw_major, fw_minor;
    uint16_t max_width, max_height; /* 2..WM_PROTO_MAX_SIDE */
    uint32_t max_samples;    /* <= the heights array handed to wm_proto_init */
    uint32_t tri_capacity;   /* triangle storage the job can give the refiner */
    uint8_t max_levels;      /* 1..WM_PROTO_MAX_LEVELS */
    uint8_t window;          /* 1..WM_PROTO_MAX_WINDOW */
    uint16_t max_payload;    /* WM_PROTO_MIN_PAYLOAD..WM_PROTO_MAX_PAYLOAD */
    uint32_t clk_hz;         /* >= 1000 */
    uint32_t baud;           /* reported only (0: not a UART) */
    uint32_t features;       /* WM_PROTO_FEATURE_* */
    /* A transport with connections (a socket; 0 on a UART: never): wm_proto_serve returns
     * WM_PROTO_SERVE_IDLE after idle_timeout_ms without a valid frame outside a session and a job;
     * write_timeout_ms is the transport's own (its write gives up on a peer that does not read).
     * Both are stated in HELLO_REPLY. */
    uint32_t idle_timeout_ms, write_timeout_ms;
    /* BAUD (docs/protocol.md, "Changing the rate"): the line runs at clk_hz / div; the host may ask for
     * any divisor div_min..div_max (div_max 0: none, the rate is fixed).  div is the start divisor. */
    uint32_t div, div_min, div_max;
    /* The DATA window HELLO states at a switched rate (0: window): a transport that can take a frame in
     * while it works on the one before at the start rate but not at a faster one states less. */
    uint8_t switched_window;
    /* FEATURE_RICE (in features) is stated only at divisors >= rice_min_div (0: at every rate): a device
     * whose decoding costs more cycles a sample than the line time it saves at fast rates asks for raw
     * samples there (it decodes CODING_RICE frames at every rate). */
    uint32_t rice_min_div;
    /* A job ends with NO_ACK after link_timeout_s seconds without a valid frame from the host (0:
     * WM_PROTO_LINK_TIMEOUT_S); stated in HELLO_REPLY.  Until then the job is kept: the host may come
     * back (RESUME). */
    uint16_t link_timeout_s;
} wm_proto_caps;

/* The job as CONFIG described it, checked; heights holds the W H samples (row-major). */
typedef struct wm_proto_job {
    int32_t width, height;   /* 2..max */
    int32_t levels;          /* M, 1..max_levels */
    uint32_t tau;            /* tau_M in coefficient units, 0..WM_PROTO_TAU_MAX */
    uint32_t flags;          /* WM_PROTO_CONFIG_* */
    int32_t capacity;        /* triangle storage to use: 2..caps.tri_capacity (never 0 here) */
    wm_params params;        /* checked with wm_params_check; max_triangles < capacity or 0 */
    uint32_t delta_lambda;   /* Q16.16, for the reduction operators */
    uint32_t delta_c;        /* Q16.16, 0..65536 */
    const uint16_t *heights;
    const uint8_t *mask;     /* CONFIG_MASK: the validity mask (wm_field.mask's format), else NULL */
} wm_proto_job;

struct wm_proto;

/* The job: run the filter bank, the template stage and the refiner on job->heights, call
 * wm_proto_stage at each stage and wm_proto_emit_level for each level's mesh (the initial
 * triangulation first).  Returns WM_PROTO_E_NONE, the non-zero code wm_proto_emit_level returned
 * (stop at once), or an error code of its own (WM_PROTO_E_CAPACITY, WM_PROTO_E_JOB) with *detail. */
typedef int (*wm_proto_job_fn)(void *ctx, const wm_proto_job *job, struct wm_proto *p, uint32_t *detail);

/* LEVEL_DELTA's coder (proto_emit.c's code_item): where it stands in a level's body. */
typedef struct wm_proto_coder {
    int32_t v, k, slot; /* next vertex slot; next live triangle, the slot to look for it from */
    int32_t px, py, pi; /* the previous live vertex's x, y; the previous triangle's first index */
} wm_proto_coder;

/* The engine's state.  Opaque: use the functions below.  (About 3 KiB: buffers inside.) */
typedef struct wm_proto {
    wm_proto_io io;
    wm_proto_caps caps;
    uint16_t *heights;
    uint8_t *mask;           /* wm_proto_set_mask's storage, or NULL */
    uint32_t mask_bytes;
    wm_proto_job_fn job_fn;
    void *job_ctx;
    uint32_t ms_cycles;      /* cycles per millisecond */

#ifndef WM_PROTO_WHOLE_FRAMES
    /* reception (h, w: DATA's samples read as halfwords or pairs of them) */
    union {
        uint8_t b[WM_PROTO_MAX_FRAME];
        uint16_t h[WM_PROTO_MAX_FRAME / 2];
        uint32_t w[WM_PROTO_MAX_FRAME / 4];
    } rx;
    uint32_t rx_len;
    uint8_t rx_esc, rx_bad;
    uint64_t rx_last;        /* cycles of the last byte of the frame being received */
#endif
    uint8_t f_type, f_seq;   /* the frame just received */
    uint16_t f_len;
    const uint8_t *f_pay;
    uint8_t f_data, f_code;  /* io.frame: the transport stored its samples (wm_proto_frame_in) */
    uint8_t up_armed;        /* io.frame: the transport stores DATA frames of session up_session */
    uint32_t up_session, session_id;
    uint32_t bad_frames;     /* damaged frames dropped (counter, for tests) */

    /* transmission (h: the level stream written as halfwords) */
    union {
        uint8_t b[WM_PROTO_MAX_PAYLOAD];
        uint16_t h[WM_PROTO_MAX_PAYLOAD / 2];
        uint32_t w[WM_PROTO_MAX_PAYLOAD / 4];
    } tx;
    uint8_t out[256];
    uint32_t out_len;
    uint32_t x8n_n, x8n;     /* CRC combination: x^(8 n) modulo the CRC's polynomial for n = x8n_n */
    uint8_t seq;             /* the device's own frames */

    /* reply cache: the answer to the last CONFIG, RUN or ABORT, sent again for a duplicate */
    uint8_t cache[16];
    uint8_t cache_type, cache_len, cache_req, cache_seq, cache_valid;

    /* session */
    uint8_t state;           /* WM_PROTO_STATE_* */
    uint8_t last_error, nak_sent, abort;
    uint8_t again_now;       /* RESUME during DONE's wait: send DONE again at once */
    uint32_t run_crc;        /* RUN's crc: the job a RESUME names */
    uint32_t last_detail;
    uint64_t last_valid;     /* cycles of the last valid frame of the session */
    wm_proto_job job;
    uint32_t total, next;    /* words expected (samples, then the mask's), words stored in order */

    /* job accounting: one clock runs at a time, the current stage's or, inside link I/O, the link's */
    int32_t stage;           /* current stage, -1 none */
    uint32_t link_depth;     /* > 0: inside link I/O (the stage's clock stands still) */
    uint64_t t_mark, run_t0;
    uint64_t cycles[WM_PROTO_STAGE_COUNT];
    uint64_t link;           /* cycles of link I/O during the job */
    uint64_t work_mark;      /* filter + template + refine cycles when the last level was sent */
    uint8_t level, levels_sent;
    uint32_t e_max, triangles, vertices;
    uint32_t initial_triangles, initial_vertices; /* the templates' triangulation (wm_proto_initial) */
    uint8_t done[WM_PROTO_DONE_BYTES]; /* the DONE payload, kept for its repeats */

    /* the line's rate: the divisor now; after a BAUD, until a valid frame proves it, the one to go back to */
    uint32_t div, probe_div;
    uint8_t probing;
    uint64_t probe_t0;

    /* the level being sent */
    const wm_mesh *lm;
    uint8_t lhdr[WM_PROTO_LEVEL_HEADER_BYTES];
    uint8_t lib;             /* index bytes */
    uint8_t llast;           /* no level follows */
    uint32_t ltotal, lcrc;
    uint32_t lwant;          /* the last ACK's want: bytes from have to send again (0: all) */
    uint8_t lresume;         /* the answer is a RESUME: LEVEL_END goes again even when the host has all bytes */
    uint16_t chunk;          /* MESH tail bytes (the host's ACK.chunk; max_payload - 8 at RUN) */
    int32_t cur_k, cur_slot; /* triangle cursor: k-th live triangle is in slot cur_slot */
    /* LEVEL_DELTA: the coder of the stream's body, which gives its bytes in order from cpos on (a resend
     * from before cpos starts it again) */
    uint8_t lcoded;
    uint8_t cb[16], cbn, cbi; /* the current item's bytes, cbi of them given */
    uint32_t cpos;            /* stream position of the next byte */
    wm_proto_coder coder;     /* where the coder stands at cpos */
    /* the level stream coded whole into storage (wm_proto_stream_buffer): one pass of the coder, its
     * length the count, every MESH frame's payload (a resend's too) read from it */
    uint8_t *sbuf;
    uint32_t sbuf_cap;
    uint8_t lbuf;             /* the level being sent is in sbuf[0 .. ltotal) */
    const uint32_t *lpc;      /* in sbuf after it, or NULL: the CRC of each of its first sending's frames' */
    uint32_t lpc_chunk;       /* payloads, lpc_chunk bytes each (the last the rest) */
} wm_proto;

/* Sets up the engine.  heights must hold caps->max_samples samples.  Nothing is sent. */
void wm_proto_init(wm_proto *p, const wm_proto_io *io, const wm_proto_caps *caps, uint16_t *heights,
                   wm_proto_job_fn job, void *job_ctx);

/* Storage for a validity mask (CONFIG_MASK, --nodata hole): bytes >= 2 ceil(max_samples / 16), static on
 * the device.  Call it after wm_proto_init; caps.features should then state WM_PROTO_FEATURE_HOLES.  A
 * CONFIG with CONFIG_MASK is refused (BAD_VALUE, FLAGS) without it or when W H needs more. */
void wm_proto_set_mask(wm_proto *p, uint8_t *mask, uint32_t bytes);

/* Storage for a job's level streams (bytes of it; NULL: none), for wm_proto_emit_level until the next
 * call: a delta-coded level that fits is coded into it once, its length then known without a counting
 * pass of the coder; a level that does not fit goes as without it (the same bytes).  The job sets it
 * (wm_job_refine: the initial mesh's staging, free once the refiner has taken the mesh) and clears it. */
void wm_proto_stream_buffer(wm_proto *p, void *buf, uint32_t bytes);

/* Serves requests until io->getc returns WM_PROTO_RX_CLOSED (WM_PROTO_SERVE_CLOSED) or, with
 * caps.idle_timeout_ms, until the connection was idle that long (WM_PROTO_SERVE_IDLE).  On a UART
 * (getc never closes, no idle timeout) it never returns. */
int wm_proto_serve(wm_proto *p);

/* For a transport with connections: the ERROR BUSY frame (request 0, seq 0) to send to a connection
 * that comes while another is served, before closing it.  Writes at most WM_PROTO_BUSY_FRAME_MAX
 * bytes into dst; returns their number (0 when cap is smaller). */
size_t wm_proto_busy_frame(uint8_t *dst, size_t cap);

/* How a transport refuses such a connection: it waits up to WM_PROTO_BUSY_WAIT_MS for the connection's
 * first bytes (a host empties its input before its HELLO, so a frame sent before would be lost), sends
 * the frame, ends its side and reads until the client closes, at most WM_PROTO_BUSY_WAIT_MS more (so
 * that the close does not reset the connection under the frame).  The native device's accepting thread
 * and the simulated board's TCP bridge (sim/tcp_bridge.cpp) both do this. */
#define WM_PROTO_BUSY_WAIT_MS 500

/* For the job: a stage begins (WM_PROTO_STAGE_FILTER, _TEMPLATE, _REFINE with the level being made).
 * Accounts the cycles since the previous stage to that stage, then sends a PROGRESS frame (link I/O:
 * its cycles count as link cycles, not the stage's). */
void wm_proto_stage(wm_proto *p, int stage, int level);

/* For the job: the initial triangulation (the templates', before the refiner) has nv vertices and nt
 * triangles; DONE states them (initial_vertices, initial_triangles; 0 until the job calls this). */
void wm_proto_initial(wm_proto *p, int32_t nv, int32_t nt);

/* For the job: sends a level's mesh (wm_mesh_export's order: vertex slots, live triangles in slot
 * order) with the refiner's statistics, and waits until the host has all of it.  The mesh must not
 * change until this returns.  last: no level follows.  Returns WM_PROTO_E_NONE, or non-zero when the
 * job must stop (WM_PROTO_E_ABORTED: the host aborted or started again; WM_PROTO_E_NO_ACK: the host
 * stopped answering; the link closed).  Building the level stream (its header, vertex slots,
 * triangles and CRC-32) once counts as the EMIT stage; the PROGRESS frame, the framing, writing,
 * waiting for the ACK and any resending count as link cycles. */
int wm_proto_emit_level(wm_proto *p, const wm_mesh *mesh, const wm_level_stats *st, int last);

/* CRC-32 (zlib's): start with 0, pass the result back in to continue. */
uint32_t wm_proto_crc32(uint32_t crc, const uint8_t *data, size_t n);

#ifdef __cplusplus
}
#endif

#endif /* WM_PROTO_H */
