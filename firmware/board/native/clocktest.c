/*
 * wm_clocktest: the protocol engine's cycle accounting (../src/proto_session.c) against a scripted host on a
 * virtual clock, so that every count has an exact expected value.
 *
 * Nothing advances the clock but the fake job and the transport: the job's stages cost exactly
 * WORK_FILTER, WORK_TEMPLATE, WORK_REFINE1 (level 1) and WORK_REFINE0 (level 0) ticks; writing costs
 * --tx-cost ticks per byte (a UART); the host answers each LEVEL_END --ack-delay ticks later (a slow
 * host; one delay per job, cycled), and with --short-ack it first claims only half of each level, so
 * the engine sends the rest again.  The jobs run one after the other in one session, so the device's
 * frame numbers (and with them CRCs and SLIP escapes) differ from job to job.  So DONE must say
 * filter = WORK_FILTER, template = WORK_TEMPLATE, refine = WORK_REFINE1 + WORK_REFINE0, emit = 0 (the
 * engine's own work takes no virtual time), and link = all the rest of the time from RUN's OK to the
 * last level's ACK; the level headers carry filter + template + WORK_REFINE1, then WORK_REFINE0.
 * Any cycle of link I/O counted in a stage shows up as a difference.
 *
 *   wm_clocktest [--jobs N] [--tx-cost N] [--ack-delay D1,D2,...] [--short-ack]
 *
 * On stdout, the work of the fake job, then one line per job (tests/sim/test_cycle_accounting.py
 * checks them):
 *
 *   work filter WF template WT refine1 WR1 refine0 WR0
 *   job K filter F template T refine R emit E link L span S levels C1,C0 resent B status X
 *
 * with DONE's counters and status, S the host's clock from RUN's OK to the last level's ACK, C1, C0
 * the level headers' cycles and B the level bytes the engine sent again.  Exit status 0, or 1 when the session
 * did not go through (a message on stderr).
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "proto.h"
#include "testhost.h"

enum { WORK_FILTER = 1000, WORK_TEMPLATE = 20000, WORK_REFINE1 = 300000, WORK_REFINE0 = 4000000 };
enum { SIDE = 4, MAX_JOBS = 16, MAX_DELAYS = 16, CLK_HZ = 1000000 };

typedef struct host {
    uint64_t t;                    /* the virtual clock */
    uint64_t tx_cost;              /* ticks per byte the device writes */
    uint64_t delays[MAX_DELAYS];   /* ticks before the host answers a LEVEL_END, per job (cycled) */
    int n_delays, short_ack, jobs, job, failed;
    uint8_t seq;                   /* the host's frame numbers */
    /* bytes to the device, available from ready_at on */
    uint8_t q[4096];
    size_t q_len, q_pos;
    uint64_t ready_at;
    int last_ack_queued;           /* the queue ends with the ACK of the job's last level */
    th_rx rx;                      /* the device's frames */
    /* per job */
    uint64_t t_ok, t_last_ack, level_cycles[2], resent;
    int level_end_seen[2];
} host;

/* A host frame onto the queue (SLIP, CRC-32). */
static void q_frame(host *h, uint8_t type, const uint8_t *payload, uint32_t n)
{
    size_t k;
    if (h->q_pos == h->q_len) h->q_len = h->q_pos = 0;
    k = th_frame(h->q + h->q_len, sizeof h->q - h->q_len, type, h->seq++, payload, n);
    if (k == 0) {
        fprintf(stderr, "wm_clocktest: host queue full\n");
        exit(1);
    }
    h->q_len += k;
}

/* CONFIG (a SIDE x SIDE grid, M = 2, zeros elsewhere), the samples, RUN. */
static void q_job(host *h)
{
    uint8_t cfg[WM_PROTO_CONFIG_BYTES], data[WM_PROTO_DATA_BYTES + 2 * SIDE * SIDE], run[WM_PROTO_RUN_BYTES];
    uint8_t le[2 * SIDE * SIDE];
    memset(cfg, 0, sizeof cfg);
    th_put16(cfg + WM_PROTO_CONFIG_WIDTH, SIDE);
    th_put16(cfg + WM_PROTO_CONFIG_HEIGHT, SIDE);
    cfg[WM_PROTO_CONFIG_LEVELS] = 2;
    th_put32(cfg + WM_PROTO_CONFIG_ZETA, 1u << 16);
    q_frame(h, WM_PROTO_T_CONFIG, cfg, sizeof cfg);
    memset(data, 0, sizeof data);
    for (int i = 0; i < SIDE * SIDE; i++) th_put16(le + 2 * i, (uint32_t)(100 * i));
    th_put16(data + WM_PROTO_DATA_COUNT, SIDE * SIDE); /* CODING_RAW (0): the words as they are */
    memcpy(data + WM_PROTO_DATA_BYTES, le, sizeof le);
    q_frame(h, WM_PROTO_T_DATA, data, sizeof data);
    th_put32(run + WM_PROTO_RUN_CRC, wm_proto_crc32(0, le, sizeof le));
    q_frame(h, WM_PROTO_T_RUN, run, sizeof run);
    h->ready_at = h->t;
    h->last_ack_queued = 0;
    memset(h->level_end_seen, 0, sizeof h->level_end_seen);
    h->resent = 0;
    h->level_cycles[0] = h->level_cycles[1] = 0;
}

static void q_ack(host *h, uint8_t kind, uint8_t index, uint32_t have)
{
    uint8_t b[WM_PROTO_ACK_BYTES];
    memset(b, 0, sizeof b);
    b[WM_PROTO_ACK_KIND] = kind;
    b[WM_PROTO_ACK_INDEX] = index;
    th_put32(b + WM_PROTO_ACK_HAVE, have);
    q_frame(h, WM_PROTO_T_ACK, b, sizeof b);
}

/* A complete frame from the device. */
static void device_frame(host *h)
{
    const uint8_t *pay = h->rx.f + WM_PROTO_HEADER_BYTES;
    const char *problem = th_frame_problem(&h->rx);
    uint32_t n;
    if (problem) {
        fprintf(stderr, "wm_clocktest: the device sent %s\n", problem);
        h->failed = 1;
        return;
    }
    n = th_get16(h->rx.f + 2);
    switch (h->rx.f[0]) {
    case WM_PROTO_T_OK:
        if (pay[WM_PROTO_OK_REQUEST] == WM_PROTO_T_RUN) h->t_ok = h->t; /* the job starts now */
        break;
    case WM_PROTO_T_ERROR:
        fprintf(stderr, "wm_clocktest: ERROR code %u detail %u\n", pay[WM_PROTO_ERROR_CODE],
                (unsigned)th_get32(pay + WM_PROTO_ERROR_DETAIL));
        h->failed = 1;
        break;
    case WM_PROTO_T_MESH: {
        uint32_t off = th_get32(pay + WM_PROTO_MESH_OFFSET), index = pay[WM_PROTO_MESH_INDEX];
        if (index < 2 && off == 0)
            h->level_cycles[index] = th_get64(pay + WM_PROTO_MESH_BYTES + WM_PROTO_LEVEL_HEADER_CYCLES);
        if (index < 2 && h->level_end_seen[index]) h->resent += n - WM_PROTO_MESH_BYTES;
        break;
    }
    case WM_PROTO_T_LEVEL_END: {
        uint32_t index = pay[WM_PROTO_LEVEL_END_INDEX], total = th_get32(pay + WM_PROTO_LEVEL_END_TOTAL);
        int full = !h->short_ack || h->level_end_seen[index & 1];
        h->level_end_seen[index & 1] = 1;
        q_ack(h, WM_PROTO_T_LEVEL_END, (uint8_t)index, full ? total : total / 2);
        h->ready_at = h->t + h->delays[h->job % h->n_delays];
        h->last_ack_queued = full && (pay[WM_PROTO_LEVEL_END_FLAGS] & WM_PROTO_LEVEL_LAST);
        break;
    }
    case WM_PROTO_T_DONE: {
        const uint8_t *d = pay;
        printf("job %d filter %llu template %llu refine %llu emit %llu link %llu span %llu levels %llu,%llu "
               "resent %llu status %u\n",
               h->job, (unsigned long long)th_get64(d + WM_PROTO_DONE_CYCLES_FILTER),
               (unsigned long long)th_get64(d + WM_PROTO_DONE_CYCLES_TEMPLATE),
               (unsigned long long)th_get64(d + WM_PROTO_DONE_CYCLES_REFINE),
               (unsigned long long)th_get64(d + WM_PROTO_DONE_CYCLES_EMIT),
               (unsigned long long)th_get64(d + WM_PROTO_DONE_CYCLES_LINK),
               (unsigned long long)(h->t_last_ack - h->t_ok), (unsigned long long)h->level_cycles[0],
               (unsigned long long)h->level_cycles[1], (unsigned long long)h->resent, d[WM_PROTO_DONE_STATUS]);
        if (d[WM_PROTO_DONE_STATUS] != 0) h->failed = 1;
        q_ack(h, WM_PROTO_T_DONE, 0, 0);
        h->ready_at = h->t;
        if (++h->job < h->jobs) q_job(h);
        break;
    }
    default: break; /* PROGRESS, replies to CONFIG and DATA */
    }
}

/* --- the transport of the engine ---------------------------------------------------------------- */

static void io_write(void *ctx, const uint8_t *data, size_t n)
{
    host *h = ctx;
    h->t += h->tx_cost * n;
    for (size_t i = 0; i < n; i++)
        if (th_rx_byte(&h->rx, data[i])) device_frame(h);
}

static int io_getc(void *ctx, uint32_t timeout_ms)
{
    host *h = ctx;
    uint64_t limit = h->t + (uint64_t)timeout_ms * (CLK_HZ / 1000);
    if (h->failed) return WM_PROTO_RX_CLOSED;
    if (h->q_pos == h->q_len) {
        if (h->job >= h->jobs) return WM_PROTO_RX_CLOSED; /* every job done and acknowledged */
        h->t = limit;                                     /* the host has nothing to say */
        return WM_PROTO_RX_TIMEOUT;
    }
    if (h->ready_at > limit) {
        h->t = limit;
        return WM_PROTO_RX_TIMEOUT;
    }
    if (h->ready_at > h->t) h->t = h->ready_at;
    if (h->q_pos + 1 == h->q_len && h->last_ack_queued) h->t_last_ack = h->t; /* its last byte */
    return h->q[h->q_pos++];
}

static uint64_t io_cycles(void *ctx) { return ((host *)ctx)->t; }

/* --- the fake job: stages of known cost, two levels of a two-triangle mesh ---------------------- */

static int fake_job(void *ctx, const wm_proto_job *j, wm_proto *p, uint32_t *detail)
{
    static const int32_t xy[8] = {0, 0, SIDE - 1, 0, 0, SIDE - 1, SIDE - 1, SIDE - 1};
    static const int32_t tris[6] = {0, 1, 3, 0, 3, 2};
    static uint8_t mem[4096];
    uint32_t scratch[6];
    host *h = ctx;
    wm_mesh m;
    wm_level_stats st;
    int rc;
    (void)detail;
    wm_proto_stage(p, WM_PROTO_STAGE_FILTER, j->levels);
    h->t += WORK_FILTER;
    wm_proto_stage(p, WM_PROTO_STAGE_TEMPLATE, j->levels);
    h->t += WORK_TEMPLATE;
    if (wm_mesh_bound(2, 4) > sizeof mem ||
        wm_mesh_init(&m, mem, sizeof mem, j->width, j->height, 2, 4) != WM_OK ||
        wm_mesh_build(&m, xy, 4, tris, 2, scratch) != WM_OK) {
        fprintf(stderr, "wm_clocktest: cannot build the mesh\n");
        h->failed = 1;
        return WM_PROTO_E_JOB;
    }
    wm_proto_stage(p, WM_PROTO_STAGE_REFINE, 1);
    h->t += WORK_REFINE1;
    memset(&st, 0, sizeof st);
    st.level = 1;
    st.vertices = m.n_vert;
    st.triangles = m.n_tri;
    rc = wm_proto_emit_level(p, &m, &st, 0);
    if (rc) return rc;
    wm_proto_stage(p, WM_PROTO_STAGE_REFINE, 0);
    h->t += WORK_REFINE0;
    st.level = 0;
    return wm_proto_emit_level(p, &m, &st, 1);
}

int main(int argc, char **argv)
{
    static wm_proto eng;
    static host h;
    static uint16_t heights[SIDE * SIDE];
    wm_proto_caps caps;
    wm_proto_io io;
    memset(&h, 0, sizeof h);
    h.jobs = 3;
    h.n_delays = 1;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--short-ack")) {
            h.short_ack = 1;
        } else if (!strcmp(argv[i], "--jobs") && i + 1 < argc) {
            h.jobs = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--tx-cost") && i + 1 < argc) {
            h.tx_cost = strtoull(argv[++i], NULL, 10);
        } else if (!strcmp(argv[i], "--ack-delay") && i + 1 < argc) {
            char *s = argv[++i];
            h.n_delays = 0;
            while (*s && h.n_delays < MAX_DELAYS) {
                h.delays[h.n_delays++] = strtoull(s, &s, 10);
                if (*s == ',') s++;
            }
        } else {
            fprintf(stderr,
                    "usage: wm_clocktest [--jobs N] [--tx-cost N] [--ack-delay D1,D2,...] [--short-ack]\n");
            return 64;
        }
    }
    if (h.jobs < 1 || h.jobs > MAX_JOBS || h.n_delays < 1) return 64;

    memset(&caps, 0, sizeof caps);
    memcpy(caps.name, "wm-clock", 8);
    caps.max_width = caps.max_height = SIDE;
    caps.max_samples = SIDE * SIDE;
    caps.tri_capacity = 16;
    caps.max_levels = 2;
    caps.window = 1;
    caps.max_payload = WM_PROTO_MIN_PAYLOAD; /* several MESH frames per level */
    caps.clk_hz = CLK_HZ;
    io.ctx = &h;
    io.getc = io_getc;
    io.read = NULL;
    io.write = io_write;
    io.write_escaped = NULL;
    io.cycles = io_cycles;
    io.mark = NULL;
    io.frame = NULL; /* the engine deframes the bytes itself */
    io.upload = NULL;
    io.upload_crc = NULL;
    printf("work filter %d template %d refine1 %d refine0 %d\n", WORK_FILTER, WORK_TEMPLATE, WORK_REFINE1,
           WORK_REFINE0);
    wm_proto_init(&eng, &io, &caps, heights, fake_job, &h);
    q_job(&h);
    wm_proto_serve(&eng);
    if (h.failed || h.job != h.jobs) {
        fprintf(stderr, "wm_clocktest: %d of %d jobs done\n", h.job, h.jobs);
        return 1;
    }
    return 0;
}
