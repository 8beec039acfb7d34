/*
 * The protocol engine's session (proto_int.h lists the engine's parts; docs/protocol.md).
 *
 * States (host requests in brackets):
 *
 *   IDLE --[CONFIG ok]--> RECEIVING --[DATA .. last sample]--> READY --[RUN, CRC ok]--> RUNNING
 *     ^                       |  silence > SESSION_TIMEOUT: ERROR TIMEOUT                  |
 *     +-----------------------+------------------- [HELLO], [ABORT] ----------------------+
 *     +------- job done: DONE (repeated until ACK, or the host silent for link_timeout_s) --+
 *
 * Everything a valid frame can get wrong (type, length, state, value) gets an ERROR frame with its
 * code.  During RUNNING the job has the CPU; the engine reads frames only inside wm_proto_emit_level
 * and while it waits for DONE's ACK: ACK, HELLO (ends the job), ABORT (ends the job), STATUS, and
 * duplicates of the RUN request are handled there, anything else gets BAD_STATE.
 */
#include "proto_int.h"

#define CACHED_MAX 16u /* largest reply kept for duplicate requests (OK: 4, ERROR: 8) */
#define SERVE_POLL_MS 100u /* how often the idle loop looks at the session clock */

/* A frame of the device's own (not a reply): the device's sequence number. */
void wm_proto_send_own(wm_proto *p, uint8_t type, const uint8_t *payload, uint32_t n)
{
    wm_proto_send_frame(p, type, p->seq++, payload, n);
}

/* A reply to the frame just received; kept for a duplicate of it when it answers CONFIG/RUN/ABORT. */
void wm_proto_reply(wm_proto *p, uint8_t type, const uint8_t *payload, uint32_t n)
{
    wm_proto_send_frame(p, type, p->f_seq, payload, n);
    if ((p->f_type == WM_PROTO_T_CONFIG || p->f_type == WM_PROTO_T_RUN || p->f_type == WM_PROTO_T_ABORT) &&
        n <= CACHED_MAX) {
        for (uint32_t i = 0; i < n; i++) p->cache[i] = payload[i];
        p->cache_type = type;
        p->cache_len = (uint8_t)n;
        p->cache_req = p->f_type;
        p->cache_seq = p->f_seq;
        p->cache_valid = 1;
    }
}

/* A duplicate of the last CONFIG, RUN or ABORT (the host sent it again: our reply was lost). */
int wm_proto_duplicate(wm_proto *p)
{
    if (!p->cache_valid || p->cache_req != p->f_type || p->cache_seq != p->f_seq) return 0;
    wm_proto_send_frame(p, p->cache_type, p->f_seq, p->cache, p->cache_len);
    return 1;
}

void wm_proto_reply_ok(wm_proto *p)
{
    uint8_t b[WM_PROTO_OK_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_OK_REQUEST] = p->f_type;
    wm_proto_reply(p, WM_PROTO_T_OK, b, sizeof b);
}

static void error_payload(wm_proto *p, uint8_t b[WM_PROTO_ERROR_BYTES], uint8_t code, uint8_t req, uint32_t detail)
{
    zero(b, WM_PROTO_ERROR_BYTES);
    b[WM_PROTO_ERROR_CODE] = code;
    b[WM_PROTO_ERROR_REQUEST] = req;
    b[WM_PROTO_ERROR_STATE] = p->state;
    put32(b + WM_PROTO_ERROR_DETAIL, detail);
    p->last_error = code;
    p->last_detail = detail;
}

/* ERROR in answer to the frame just received. */
void wm_proto_reply_error(wm_proto *p, uint8_t code, uint32_t detail)
{
    uint8_t b[WM_PROTO_ERROR_BYTES];
    error_payload(p, b, code, p->f_type, detail);
    wm_proto_reply(p, WM_PROTO_T_ERROR, b, sizeof b);
}

/* ERROR of the device's own (the session was dropped). */
static void send_error(wm_proto *p, uint8_t code, uint32_t detail)
{
    uint8_t b[WM_PROTO_ERROR_BYTES];
    error_payload(p, b, code, 0, detail);
    wm_proto_send_own(p, WM_PROTO_T_ERROR, b, sizeof b);
}

/* ---------------------------------------------------------------------------------------------- */
/* Cycle accounting and progress
 *
 * One clock runs at a time: the current stage's, or, while link_depth > 0, the link's.  Link I/O is
 * everything whose duration or work depends on something other than the job: every frame the job
 * sends (PROGRESS carries a timestamp, every frame the device's sequence number, the CRC and the
 * SLIP escapes follow from both), every write to the transport (a UART's FIFO may be full), every
 * wait for the host and every resend it asks for.  What is left to the stages (filter, template,
 * refine, and emit: building each level stream once) depends only on the job, so a job gives the same
 * stage counts on every run, over any link, at any host speed. */

/* The cycles since the last charge go to the clock that ran: the link's or the current stage's. */
void wm_proto_charge(wm_proto *p)
{
    uint64_t t = now(p);
    if (p->link_depth) p->link += t - p->t_mark;
    else if (p->stage >= 0 && p->stage < WM_PROTO_STAGE_COUNT) p->cycles[p->stage] += t - p->t_mark;
    p->t_mark = t;
}

void wm_proto_send_progress(wm_proto *p, int stage, int level)
{
    uint8_t b[WM_PROTO_PROGRESS_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_PROGRESS_STAGE] = (uint8_t)stage;
    b[WM_PROTO_PROGRESS_LEVEL] = (uint8_t)level;
    b[WM_PROTO_PROGRESS_LEVELS] = (uint8_t)p->job.levels;
    put64(b + WM_PROTO_PROGRESS_CYCLES, now(p) - p->run_t0);
    wm_proto_send_own(p, WM_PROTO_T_PROGRESS, b, sizeof b);
    out_flush(p);
}

void wm_proto_stage(wm_proto *p, int stage, int level)
{
    if (stage == WM_PROTO_STAGE_REFINE) p->level = (uint8_t)level;
    stage_enter(p, stage);
    link_begin(p);
    wm_proto_send_progress(p, stage, level);
    link_end(p);
}

/* ---------------------------------------------------------------------------------------------- */
/* Requests outside a job */

static void status_reply(wm_proto *p)
{
    uint8_t b[WM_PROTO_STATUS_REPLY_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_STATUS_REPLY_STATE] = p->state;
    b[WM_PROTO_STATUS_REPLY_LAST_ERROR] = p->last_error;
    b[WM_PROTO_STATUS_REPLY_LEVEL] = p->level;
    put32(b + WM_PROTO_STATUS_REPLY_SAMPLES, p->next);
    put32(b + WM_PROTO_STATUS_REPLY_EXPECTED, p->total);
    put32(b + WM_PROTO_STATUS_REPLY_LAST_DETAIL, p->last_detail);
    wm_proto_reply(p, WM_PROTO_T_STATUS_REPLY, b, sizeof b);
}

void wm_proto_session_end(wm_proto *p)
{
    p->state = WM_PROTO_STATE_IDLE;
    p->total = p->next = 0;
}

static void do_hello(wm_proto *p)
{
    uint8_t b[WM_PROTO_HELLO_REPLY_BYTES];
    const wm_proto_caps *c = &p->caps;
    if (p->f_len != WM_PROTO_HELLO_BYTES) { /* not a HELLO: nothing ends */
        wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    wm_proto_session_end(p); /* a HELLO starts afresh, whatever was going on */
    p->cache_valid = 0;
    if ((get16(p->f_pay + WM_PROTO_HELLO_VERSION) >> 8) != WM_PROTO_VERSION_MAJOR) {
        wm_proto_reply_error(p, WM_PROTO_E_VERSION, WM_PROTO_VERSION);
        return;
    }
    zero(b, sizeof b);
    put16(b + WM_PROTO_HELLO_REPLY_VERSION, WM_PROTO_VERSION);
    b[WM_PROTO_HELLO_REPLY_FW_MAJOR] = c->fw_major;
    b[WM_PROTO_HELLO_REPLY_FW_MINOR] = c->fw_minor;
    for (int i = 0; i < 8; i++) b[WM_PROTO_HELLO_REPLY_NAME + i] = (uint8_t)c->name[i];
    put16(b + WM_PROTO_HELLO_REPLY_MAX_WIDTH, c->max_width);
    put16(b + WM_PROTO_HELLO_REPLY_MAX_HEIGHT, c->max_height);
    put32(b + WM_PROTO_HELLO_REPLY_MAX_SAMPLES, c->max_samples);
    put32(b + WM_PROTO_HELLO_REPLY_TRI_CAPACITY, c->tri_capacity);
    b[WM_PROTO_HELLO_REPLY_MAX_LEVELS] = c->max_levels;
    b[WM_PROTO_HELLO_REPLY_WINDOW] = p->div != c->div && c->switched_window ? c->switched_window : c->window;
    put16(b + WM_PROTO_HELLO_REPLY_MAX_PAYLOAD, c->max_payload);
    put32(b + WM_PROTO_HELLO_REPLY_CLK_HZ, c->clk_hz);
    /* the start rate as the transport states it; after a BAUD clk_hz / div rounded (protocol.divisor_baud) */
    put32(b + WM_PROTO_HELLO_REPLY_BAUD,
          p->div && p->div != c->div ? (c->clk_hz + p->div / 2u) / p->div : c->baud);
    put32(b + WM_PROTO_HELLO_REPLY_FEATURES,
          p->div && p->div < c->rice_min_div ? c->features & ~(uint32_t)WM_PROTO_FEATURE_RICE : c->features);
    put16(b + WM_PROTO_HELLO_REPLY_BYTE_TIMEOUT_MS, WM_PROTO_BYTE_TIMEOUT_MS);
    put16(b + WM_PROTO_HELLO_REPLY_ACK_TIMEOUT_MS, WM_PROTO_ACK_TIMEOUT_MS);
    put32(b + WM_PROTO_HELLO_REPLY_SESSION_TIMEOUT_MS, WM_PROTO_SESSION_TIMEOUT_MS);
    put16(b + WM_PROTO_HELLO_REPLY_ACK_RETRIES, WM_PROTO_ACK_RETRIES);
    put16(b + WM_PROTO_HELLO_REPLY_LINK_TIMEOUT_S, c->link_timeout_s);
    put32(b + WM_PROTO_HELLO_REPLY_IDLE_TIMEOUT_MS, c->idle_timeout_ms);
    put32(b + WM_PROTO_HELLO_REPLY_WRITE_TIMEOUT_MS, c->write_timeout_ms);
    put32(b + WM_PROTO_HELLO_REPLY_DIV_MIN, c->div_min);
    put32(b + WM_PROTO_HELLO_REPLY_DIV_MAX, c->div_max);
    wm_proto_reply(p, WM_PROTO_T_HELLO_REPLY, b, sizeof b);
}

/* BAUD, outside a session: OK at the old rate, then the new divisor.  Until a valid frame comes at the
 * new rate (the host's HELLO) the old divisor is kept in probe_div; wm_proto_serve goes back to it after
 * WM_PROTO_BAUD_PROBE_MS without one, so a switch the host cannot follow never strands the device. */
static void do_baud(wm_proto *p)
{
    uint32_t div;
    if (p->f_len != WM_PROTO_BAUD_BYTES) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    if (p->state != WM_PROTO_STATE_IDLE) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return;
    }
    div = get32(p->f_pay + WM_PROTO_BAUD_DIVISOR);
    if (!p->io.set_divisor || p->caps.div_max == 0 || div < p->caps.div_min || div > p->caps.div_max) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_BAUD, div);
        return;
    }
    wm_proto_reply_ok(p);
    out_flush(p);
    if (!p->probing)
        p->probe_div = p->div; /* a second BAUD before the first was proved: back to the first's old */
    p->io.set_divisor(p->io.ctx, div);
    p->div = div;
    p->probing = 1;
    p->probe_t0 = now(p);
    rx_reset(p);
}

/* Word k of what DATA stored (proto_data.c): sample k, or beyond the W H samples the mask's bytes in pairs. */
static uint16_t word_at(const wm_proto *p, uint32_t k)
{
    uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height;
    if (k < wh) return p->heights[k];
    return (uint16_t)(p->mask[2 * (k - wh)] | p->mask[2 * (k - wh) + 1] << 8);
}

static void run_job(wm_proto *p);

static void do_run(wm_proto *p)
{
    uint32_t crc = 0;
    if (wm_proto_duplicate(p)) return;
    if (p->f_len != WM_PROTO_RUN_BYTES) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    if (p->state != WM_PROTO_STATE_READY) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return;
    }
    {
        /* the samples, then the mask's words, each as its two little-endian bytes */
        uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height, c = ~crc;
        if (p->io.frame) {
            c = p->io.upload_crc(p->io.ctx); /* the transport summed the samples as it stored them */
        } else {
#if WM_LITTLE_ENDIAN
            c = wm_proto_crc_run(c, (const uint8_t *)p->heights, 2u * (wh < p->total ? wh : p->total));
#else
            for (uint32_t i = 0; i < wh && i < p->total; i++) c = crc_update16(c, p->heights[i]);
#endif
        }
        for (uint32_t i = wh; i < p->total; i++) c = crc_update16(c, word_at(p, i));
        crc = ~c;
    }
    if (crc != get32(p->f_pay + WM_PROTO_RUN_CRC)) {
        wm_proto_session_end(p);
        wm_proto_reply_error(p, WM_PROTO_E_DATA_CRC, crc);
        return;
    }
    p->run_crc = crc;
    wm_proto_reply_ok(p);
    out_flush(p);
    run_job(p);
}

/* A frame outside a job. */
static void handle(wm_proto *p)
{
    switch (p->f_type) {
    case WM_PROTO_T_HELLO: do_hello(p); break;
    case WM_PROTO_T_STATUS:
        if (p->f_len != 0) wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        else status_reply(p);
        break;
    case WM_PROTO_T_ABORT:
        if (wm_proto_duplicate(p)) break;
        if (p->f_len != 0) {
            wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            break;
        }
        wm_proto_session_end(p);
        wm_proto_reply_ok(p);
        break;
    case WM_PROTO_T_CONFIG: wm_proto_do_config(p); break;
    case WM_PROTO_T_DATA: wm_proto_do_data(p); break;
    case WM_PROTO_T_RUN: do_run(p); break;
    case WM_PROTO_T_BAUD: do_baud(p); break;
    case WM_PROTO_T_ACK: break;       /* a late answer to a job that is over */
    case WM_PROTO_T_KEEPALIVE: break; /* never answered (the session clock restarts, as for every frame) */
    case WM_PROTO_T_RESUME:           /* no job to resume (it ended, or another host's HELLO ended it) */
        if (p->f_len != WM_PROTO_RESUME_BYTES) wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        else wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        break;
    default:
        /* the device's own types (an echo on the line) are ignored; anything else is unknown */
        if (p->f_type < 0x80u) wm_proto_reply_error(p, WM_PROTO_E_BAD_TYPE, p->f_type);
        break;
    }
}

/* ---------------------------------------------------------------------------------------------- */
/* During the job */

/* ACK.chunk or RESUME.chunk: the MESH tail from now on (0: the largest) */
static void set_chunk(wm_proto *p, uint32_t c)
{
    uint32_t most = p->caps.max_payload - WM_PROTO_MESH_BYTES;
    p->chunk = (uint16_t)(c == 0 || c > most ? most : c < WM_PROTO_MIN_CHUNK ? WM_PROTO_MIN_CHUNK : c);
}

/* RESUME while the job waits for (kind, index): 1 when it stands for that ACK (a level from the host's
 * bytes on), 0 otherwise (DONE's wait: DONE again at once; another job, or a level the device does not
 * wait for: ERROR BAD_STATE, the job goes on). */
static int resume(wm_proto *p, uint8_t kind, uint8_t index, uint32_t *have)
{
    const uint8_t *r = p->f_pay;
    if (p->f_len != WM_PROTO_RESUME_BYTES) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return 0;
    }
    if (get32(r + WM_PROTO_RESUME_CRC) != p->run_crc) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return 0;
    }
    set_chunk(p, get16(r + WM_PROTO_RESUME_CHUNK));
    if (kind == WM_PROTO_T_DONE) {
        p->again_now = 1;
        return 0;
    }
    if (r[WM_PROTO_RESUME_INDEX] != index) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->levels_sent);
        return 0;
    }
    *have = get32(r + WM_PROTO_RESUME_HAVE);
    if (*have > p->ltotal) *have = p->ltotal;
    p->lwant = 0;
    p->lresume = 1; /* the host has no LEVEL_END of this level (else it would have acknowledged it) */
    return 1;
}

/* A frame that arrived while the job waits: 1 when it is the ACK of (kind, index), with *have. */
static int job_frame(wm_proto *p, uint8_t kind, uint8_t index, uint32_t *have)
{
    switch (p->f_type) {
    case WM_PROTO_T_KEEPALIVE: return 0;
    case WM_PROTO_T_RESUME: return resume(p, kind, index, have);
    case WM_PROTO_T_ACK:
        if (p->f_len != WM_PROTO_ACK_BYTES) {
            wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return 0;
        }
        if (p->f_pay[WM_PROTO_ACK_KIND] == kind && p->f_pay[WM_PROTO_ACK_INDEX] == index) {
            *have = get32(p->f_pay + WM_PROTO_ACK_HAVE);
            if (kind == WM_PROTO_T_LEVEL_END) {
                /* a host on a lossy line asks for smaller frames (and only the bytes it misses) */
                p->lwant = get32(p->f_pay + WM_PROTO_ACK_WANT);
                set_chunk(p, get16(p->f_pay + WM_PROTO_ACK_CHUNK));
            }
            return 1;
        }
        return 0; /* an ACK of something earlier */
    case WM_PROTO_T_HELLO:
        if (p->f_len == WM_PROTO_HELLO_BYTES) p->abort = ABORT_HOST; /* else BAD_LENGTH, the job goes on */
        do_hello(p);
        return 0;
    case WM_PROTO_T_ABORT:
        if (wm_proto_duplicate(p)) return 0;
        if (p->f_len != 0) {
            wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return 0;
        }
        p->abort = ABORT_HOST;
        wm_proto_session_end(p);
        wm_proto_reply_ok(p);
        return 0;
    case WM_PROTO_T_STATUS:
        if (p->f_len != 0) wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        else status_reply(p);
        return 0;
    case WM_PROTO_T_RUN:
    case WM_PROTO_T_CONFIG:
        if (wm_proto_duplicate(p)) return 0;
        wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return 0;
    case WM_PROTO_T_DATA:
    case WM_PROTO_T_BAUD: wm_proto_reply_error(p, WM_PROTO_E_BAD_STATE, p->state); return 0;
    default:
        if (p->f_type < 0x80u) wm_proto_reply_error(p, WM_PROTO_E_BAD_TYPE, p->f_type);
        return 0;
    }
}

int wm_proto_wait_ack(wm_proto *p, uint8_t kind, uint8_t index, uint32_t *have, void (*again)(wm_proto *))
{
    uint64_t heard = now(p), limit = ms_to_cycles(p, 1000u * p->caps.link_timeout_s);
    for (;;) {
        int r = wm_proto_rx_frame(p, WM_PROTO_ACK_TIMEOUT_MS);
        if (r < 0) {
            p->abort = ABORT_CLOSED;
            return 0;
        }
        if (r == 0) {
            if (now(p) - heard >= limit) { /* the host is gone: not a pause */
                p->abort = ABORT_NO_ACK;
                return 0;
            }
            again(p);
            continue;
        }
        heard = now(p);
        if (job_frame(p, kind, index, have)) return 1;
        if (p->abort) return 0;
        if (p->again_now) {
            p->again_now = 0;
            again(p);
        }
    }
}

void wm_proto_initial(wm_proto *p, int32_t nv, int32_t nt)
{
    p->initial_vertices = (uint32_t)nv;
    p->initial_triangles = (uint32_t)nt;
}

#ifdef WM_PROTO_STACK
/* DONE's stack fields (wm_proto_stack_peak), after the job: no clock runs, the scan is no stage's and not
 * the link's */
WM_PROTO_BETWEEN_JOBS static void done_stack(uint8_t *b)
{
    uint32_t bytes = 0;
    put32(b + WM_PROTO_DONE_STACK_PEAK, wm_proto_stack_peak(&bytes));
    put16(b + WM_PROTO_DONE_STACK_BYTES, bytes);
}
#endif

static void send_done(wm_proto *p)
{
    wm_proto_send_own(p, WM_PROTO_T_DONE, p->done, sizeof p->done);
    out_flush(p);
}

static void run_job(wm_proto *p)
{
    uint32_t detail = 0, have = 0;
    int rc;
    uint8_t *b = p->done;
    p->state = WM_PROTO_STATE_RUNNING;
    p->abort = 0;
    p->again_now = 0;
    p->levels_sent = 0;
    p->chunk = (uint16_t)(p->caps.max_payload - WM_PROTO_MESH_BYTES); /* until the host asks for less */
    p->e_max = p->triangles = p->vertices = 0;
    p->initial_triangles = p->initial_vertices = 0;
    p->level = (uint8_t)(p->job.levels - 1);
    p->run_t0 = now(p);
    p->link = 0;
    p->link_depth = 0;
    p->work_mark = 0;
    stage_enter(p, -1); /* the receive stage ends */

    rc = p->job_fn(p->job_ctx, &p->job, p, &detail);
    stage_enter(p, -1);
    if (p->abort == ABORT_HOST || p->abort == ABORT_CLOSED) {
        wm_proto_session_end(p); /* already answered (HELLO, ABORT), or nobody is listening */
        if (p->abort == ABORT_HOST) p->last_error = WM_PROTO_E_ABORTED;
        return;
    }
    if (p->abort == ABORT_NO_ACK) {
        rc = WM_PROTO_E_NO_ACK;
        detail = p->level;
    }
    zero(b, WM_PROTO_DONE_BYTES);
    b[WM_PROTO_DONE_STATUS] = (uint8_t)rc;
    b[WM_PROTO_DONE_LEVELS] = p->levels_sent;
    put32(b + WM_PROTO_DONE_DETAIL, detail);
    put32(b + WM_PROTO_DONE_E_MAX, p->e_max);
    put32(b + WM_PROTO_DONE_TRIANGLES, p->triangles);
    put32(b + WM_PROTO_DONE_VERTICES, p->vertices);
    put32(b + WM_PROTO_DONE_INITIAL_TRIANGLES, p->initial_triangles);
    put32(b + WM_PROTO_DONE_INITIAL_VERTICES, p->initial_vertices);
    put64(b + WM_PROTO_DONE_CYCLES_RECEIVE, p->cycles[WM_PROTO_STAGE_RECEIVE]);
    put64(b + WM_PROTO_DONE_CYCLES_FILTER, p->cycles[WM_PROTO_STAGE_FILTER]);
    put64(b + WM_PROTO_DONE_CYCLES_TEMPLATE, p->cycles[WM_PROTO_STAGE_TEMPLATE]);
    put64(b + WM_PROTO_DONE_CYCLES_REFINE, p->cycles[WM_PROTO_STAGE_REFINE]);
    put64(b + WM_PROTO_DONE_CYCLES_EMIT, p->cycles[WM_PROTO_STAGE_EMIT]);
    put64(b + WM_PROTO_DONE_CYCLES_LINK, p->link);
#ifdef WM_PROTO_STACK
    done_stack(b);
#endif
    if (rc) {
        p->last_error = (uint8_t)rc;
        p->last_detail = detail;
    }
    wm_proto_send_progress(p, WM_PROTO_STAGE_DONE, 0);
    send_done(p);
    if (p->abort != ABORT_NO_ACK) /* a host that stopped answering gets one DONE, no wait */
        wm_proto_wait_ack(p, WM_PROTO_T_DONE, 0, &have, send_done);
    wm_proto_session_end(p);
}

/* ---------------------------------------------------------------------------------------------- */

void wm_proto_init(wm_proto *p, const wm_proto_io *io, const wm_proto_caps *caps, uint16_t *heights,
                   wm_proto_job_fn job, void *job_ctx)
{
    zero((uint8_t *)p, sizeof *p);
    p->io = *io;
    p->caps = *caps;
    if (p->caps.window < 1) p->caps.window = 1;
    if (p->caps.window > WM_PROTO_MAX_WINDOW) p->caps.window = WM_PROTO_MAX_WINDOW;
    if (p->caps.switched_window > p->caps.window) p->caps.switched_window = p->caps.window;
    if (p->caps.max_payload < WM_PROTO_MIN_PAYLOAD || p->caps.max_payload > WM_PROTO_MAX_PAYLOAD)
        p->caps.max_payload = WM_PROTO_MAX_PAYLOAD;
    if (p->caps.max_levels > WM_PROTO_MAX_LEVELS) p->caps.max_levels = WM_PROTO_MAX_LEVELS;
    if (p->caps.link_timeout_s == 0) p->caps.link_timeout_s = WM_PROTO_LINK_TIMEOUT_S;
    p->heights = heights;
    p->job_fn = job;
    p->job_ctx = job_ctx;
    p->ms_cycles = caps->clk_hz / 1000u ? caps->clk_hz / 1000u : 1u;
    if (!p->io.set_divisor) p->caps.div_max = 0;
    if (p->caps.div_max == 0) p->caps.div_min = 0;
    p->div = p->caps.div_max ? p->caps.div : 0; /* 0: HELLO states caps.baud */
    p->stage = -1;
    p->state = WM_PROTO_STATE_IDLE;
    p->last_valid = now(p); /* the idle clock starts when the connection does */
    p->x8n = 0x80000000u;   /* x^0, for x8n_n = 0 */
    wm_proto_crc_init();
    rx_reset(p);
}

void wm_proto_set_mask(wm_proto *p, uint8_t *mask, uint32_t bytes)
{
    p->mask = mask;
    p->mask_bytes = mask ? bytes : 0;
}

void wm_proto_stream_buffer(wm_proto *p, void *buf, uint32_t bytes)
{
    p->sbuf = buf;
    p->sbuf_cap = buf ? bytes : 0;
}

int wm_proto_serve(wm_proto *p)
{
    for (;;) {
        int r = wm_proto_rx_frame(p, SERVE_POLL_MS);
        if (r < 0) {
            wm_proto_session_end(p);
            out_flush(p);
            return WM_PROTO_SERVE_CLOSED;
        }
        if (r > 0) {
            p->probing = 0; /* a valid frame: the line's rate is proved */
            handle(p);
            p->last_valid = now(p); /* the session clock restarts with every valid frame */
            out_flush(p);
            continue;
        }
        if (p->probing && now(p) - p->probe_t0 >= ms_to_cycles(p, WM_PROTO_BAUD_PROBE_MS)) {
            /* nothing valid at the new rate: back to the old one, where the host will look for us */
            p->probing = 0;
            p->div = p->probe_div;
            p->io.set_divisor(p->io.ctx, p->div);
            rx_reset(p);
        }
        if (p->state == WM_PROTO_STATE_IDLE && !p->probing && p->div != p->caps.div &&
            now(p) - p->last_valid >= ms_to_cycles(p, WM_PROTO_BAUD_IDLE_MS)) {
            /* the host left at a switched rate: the next one starts at the start rate */
            p->div = p->caps.div;
            p->io.set_divisor(p->io.ctx, p->div);
            rx_reset(p);
        }
        if ((p->state == WM_PROTO_STATE_RECEIVING || p->state == WM_PROTO_STATE_READY) &&
            now(p) - p->last_valid >= ms_to_cycles(p, WM_PROTO_SESSION_TIMEOUT_MS)) {
            uint32_t got = p->next;
            wm_proto_session_end(p);
            send_error(p, WM_PROTO_E_TIMEOUT, got);
            out_flush(p);
            p->last_valid = now(p); /* the idle clock counts from the session's end */
        }
        if (p->state == WM_PROTO_STATE_IDLE && p->caps.idle_timeout_ms &&
            now(p) - p->last_valid >= ms_to_cycles(p, p->caps.idle_timeout_ms)) {
            out_flush(p);
            return WM_PROTO_SERVE_IDLE; /* the transport closes the connection: another client may come */
        }
    }
}
