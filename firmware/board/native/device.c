/*
 * wmdev: the native stand-in device.  The board's protocol engine (firmware/board/src/proto.c) and
 * the refiner library (firmware/src) on the host CPU, serving the wire protocol on a TCP socket of
 * 127.0.0.1, so `wavemesh stream INPUT --port socket://127.0.0.1:PORT` talks to it as to a board.
 * A fast device for protocol and fault-injection tests; the simulated board (sim/) is the exact one.
 *
 *   wmdev [--port N] [--max-width N] [--max-height N] [--max-samples N] [--tri-capacity N]
 *         [--max-levels N] [--window N] [--max-payload N] [--baud N] [--exit-on-close] [--quiet]
 *
 * Defaults are the board's (wm_memmap.h): 256 x 256, 1492 triangles, 8 levels.  --port 0 picks a
 * free port.  --baud N paces both directions at N baud (8N1: ten bit times per byte), as a UART
 * would; 0 (the default) runs at socket speed.  One client at a time: a second one is accepted and
 * closed at once (as the simulated board does); the next may connect when the previous left.
 *
 * Output lines on stdout: "wmdev: listening on 127.0.0.1:PORT", "wmdev: client connected",
 * "wmdev: client left bytes-in N bytes-out N bad-frames N".
 * Exit status: 0 after --exit-on-close, 4 socket error, 64 bad command line.
 */
#define _POSIX_C_SOURCE 200809L
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "job.h"
#include "proto.h"
#include "wm_memmap.h"

#define FW_MAJOR 0
#define FW_MINOR 2
#define DEFAULT_LEVELS 8 /* the board's coefficient memory holds levels 1..8 */
#define DEFAULT_WINDOW 4

typedef struct conn {
    int lfd, cfd, closed, quiet;
    uint8_t in[4096];
    size_t in_len, in_pos;
    uint8_t out[8192];
    size_t out_len;
    uint64_t byte_ns;          /* --baud: nanoseconds per byte, 0 unpaced */
    uint64_t rx_clock, tx_clock;
    uint64_t bytes_in, bytes_out;
} conn;

static uint64_t mono_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static void sleep_until(uint64_t t) {
    uint64_t n = mono_ns();
    if (t > n) {
        struct timespec ts = {(time_t)((t - n) / 1000000000u), (long)((t - n) % 1000000000u)};
        nanosleep(&ts, NULL);
    }
}

/* A UART of the given rate: a byte may not go out (come in) before the line has carried the ones
 * before it.  Sleeping only when 2 ms ahead keeps the number of system calls down. */
static void pace(uint64_t *clock, uint64_t byte_ns, size_t n) {
    uint64_t t = mono_ns();
    if (*clock < t) *clock = t;
    *clock += byte_ns * n;
    if (*clock > t + 2000000u) sleep_until(*clock);
}

static void conn_flush(conn *c) {
    size_t done = 0;
    if (c->closed) {
        c->out_len = 0;
        return;
    }
    while (done < c->out_len) {
        size_t n = c->out_len - done;
        ssize_t k;
        if (c->byte_ns && n > 64) n = 64;
        k = send(c->cfd, c->out + done, n, MSG_NOSIGNAL);
        if (k < 0) {
            if (errno == EINTR) continue;
            c->closed = 1;
            break;
        }
        if (c->byte_ns) pace(&c->tx_clock, c->byte_ns, (size_t)k);
        done += (size_t)k;
    }
    c->bytes_out += done;
    c->out_len = 0;
}

static void io_write(void *ctx, const uint8_t *data, size_t n) {
    conn *c = ctx;
    while (n) {
        size_t k = sizeof c->out - c->out_len < n ? sizeof c->out - c->out_len : n;
        memcpy(c->out + c->out_len, data, k);
        c->out_len += k;
        data += k;
        n -= k;
        if (c->out_len == sizeof c->out) conn_flush(c);
    }
}

/* A second client while one is served: accept it and close it at once. */
static void refuse_extra(conn *c) {
    int fd = accept(c->lfd, NULL, NULL);
    if (fd >= 0) {
        close(fd);
        if (!c->quiet) printf("wmdev: second client refused\n"), fflush(stdout);
    }
}

static int io_getc(void *ctx, uint32_t timeout_ms) {
    conn *c = ctx;
    uint64_t deadline = mono_ns() + (uint64_t)timeout_ms * 1000000u;
    conn_flush(c);
    while (c->in_pos == c->in_len) {
        struct pollfd fds[2] = {{c->cfd, POLLIN, 0}, {c->lfd, POLLIN, 0}};
        uint64_t t = mono_ns();
        int left = t >= deadline ? 0 : (int)((deadline - t + 999999u) / 1000000u), r;
        ssize_t k;
        if (c->closed) return WM_PROTO_RX_CLOSED;
        r = poll(fds, 2, left);
        if (r < 0) {
            if (errno == EINTR) continue;
            return WM_PROTO_RX_CLOSED;
        }
        if (fds[1].revents & POLLIN) refuse_extra(c);
        if (fds[0].revents & (POLLIN | POLLHUP | POLLERR)) {
            k = recv(c->cfd, c->in, sizeof c->in, 0);
            if (k < 0 && errno == EINTR) continue;
            if (k <= 0) {
                c->closed = 1;
                return WM_PROTO_RX_CLOSED;
            }
            c->in_len = (size_t)k;
            c->in_pos = 0;
            c->bytes_in += (uint64_t)k;
            break;
        }
        if (r == 0 || mono_ns() >= deadline) return WM_PROTO_RX_TIMEOUT;
    }
    if (c->byte_ns) pace(&c->rx_clock, c->byte_ns, 1);
    return c->in[c->in_pos++];
}

static uint64_t io_cycles(void *ctx) {
    (void)ctx;
    return mono_ns();
}

static int usage(const char *why) {
    fprintf(stderr, "wmdev: %s\nusage: wmdev [--port N] [--max-width N] [--max-height N] [--max-samples N] "
                    "[--tri-capacity N] [--max-levels N] [--window N] [--max-payload N] [--baud N] "
                    "[--exit-on-close] [--quiet]\n", why);
    return 64;
}

static int number(const char *s, long lo, long hi, long *out) {
    char *end;
    long v;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || *end || end == s || v < lo || v > hi) return 0;
    *out = v;
    return 1;
}

int main(int argc, char **argv) {
    static wm_proto eng;
    wm_proto_caps caps;
    wm_proto_io io;
    conn c;
    long port = 7721, max_w = WM_GRID_MAX_W, max_h = WM_GRID_MAX_H, max_samples = -1, tri_cap = WM_TRI_CAPACITY;
    long levels = DEFAULT_LEVELS, window = DEFAULT_WINDOW, payload = WM_PROTO_MAX_PAYLOAD, baud = 0;
    int exit_on_close = 0, quiet = 0;
    uint16_t *heights;
    struct sockaddr_in addr;
    socklen_t len = sizeof addr;
    int one = 1;

    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        long *dst = NULL, lo = 0, hi = 0;
        if (!strcmp(a, "--exit-on-close")) { exit_on_close = 1; continue; }
        if (!strcmp(a, "--quiet")) { quiet = 1; continue; }
        if (!strcmp(a, "--port")) dst = &port, lo = 0, hi = 65535;
        else if (!strcmp(a, "--max-width")) dst = &max_w, lo = 2, hi = WM_PROTO_MAX_SIDE;
        else if (!strcmp(a, "--max-height")) dst = &max_h, lo = 2, hi = WM_PROTO_MAX_SIDE;
        else if (!strcmp(a, "--max-samples")) dst = &max_samples, lo = 4, hi = 1L << 28;
        else if (!strcmp(a, "--tri-capacity")) dst = &tri_cap, lo = 2, hi = 1L << 30;
        else if (!strcmp(a, "--max-levels")) dst = &levels, lo = 1, hi = WM_PROTO_MAX_LEVELS;
        else if (!strcmp(a, "--window")) dst = &window, lo = 1, hi = WM_PROTO_MAX_WINDOW;
        else if (!strcmp(a, "--max-payload")) dst = &payload, lo = 64, hi = WM_PROTO_MAX_PAYLOAD;
        else if (!strcmp(a, "--baud")) dst = &baud, lo = 0, hi = 100000000;
        else return usage("unknown option");
        if (i + 1 >= argc || !number(argv[++i], lo, hi, dst)) return usage("bad or missing number");
    }
    if (max_samples < 0) max_samples = max_w * max_h;

    memset(&caps, 0, sizeof caps);
    memcpy(caps.name, "wm-nativ", 8);
    caps.fw_major = FW_MAJOR;
    caps.fw_minor = FW_MINOR;
    caps.max_width = (uint16_t)max_w;
    caps.max_height = (uint16_t)max_h;
    caps.max_samples = (uint32_t)max_samples;
    caps.tri_capacity = (uint32_t)tri_cap;
    caps.max_levels = (uint8_t)levels;
    caps.window = (uint8_t)window;
    caps.max_payload = (uint16_t)payload;
    caps.clk_hz = 1000000000u; /* cycle counters count nanoseconds */
    caps.baud = (uint32_t)baud;
    caps.features = WM_PROTO_FEATURE_INITIAL_ONLY;
    heights = calloc((size_t)max_samples, sizeof *heights);
    if (!heights) return usage("cannot allocate the height memory");

    signal(SIGPIPE, SIG_IGN);
    memset(&c, 0, sizeof c);
    c.quiet = quiet;
    c.byte_ns = baud ? 10000000000ull / (uint64_t)baud : 0;
    c.lfd = socket(AF_INET, SOCK_STREAM, 0);
    memset(&addr, 0, sizeof addr);
    addr.sin_family = AF_INET;
    addr.sin_port = htons((uint16_t)port);
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    setsockopt(c.lfd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (c.lfd < 0 || bind(c.lfd, (struct sockaddr *)&addr, sizeof addr) < 0 || listen(c.lfd, 4) < 0 ||
        getsockname(c.lfd, (struct sockaddr *)&addr, &len) < 0) {
        fprintf(stderr, "wmdev: cannot listen on 127.0.0.1:%ld: %s\n", port, strerror(errno));
        return 4;
    }
    printf("wmdev: listening on 127.0.0.1:%d (%ld x %ld, %ld triangles, %ld levels, %s)\n",
           ntohs(addr.sin_port), max_w, max_h, tri_cap, levels, baud ? "paced" : "unpaced");
    fflush(stdout);

    io.ctx = &c;
    io.getc = io_getc;
    io.write = io_write;
    io.cycles = io_cycles;
    io.mark = NULL;
    for (;;) {
        c.cfd = accept(c.lfd, NULL, NULL);
        if (c.cfd < 0) {
            if (errno == EINTR) continue;
            fprintf(stderr, "wmdev: accept: %s\n", strerror(errno));
            return 4;
        }
        setsockopt(c.cfd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        c.closed = 0;
        c.in_len = c.in_pos = c.out_len = 0;
        c.bytes_in = c.bytes_out = 0;
        c.rx_clock = c.tx_clock = 0;
        if (!quiet) printf("wmdev: client connected\n"), fflush(stdout);
        wm_proto_init(&eng, &io, &caps, heights, wm_native_job, NULL);
        wm_proto_serve(&eng);
        close(c.cfd);
        if (!quiet)
            printf("wmdev: client left bytes-in %llu bytes-out %llu bad-frames %lu\n",
                   (unsigned long long)c.bytes_in, (unsigned long long)c.bytes_out, (unsigned long)eng.bad_frames),
                fflush(stdout);
        if (exit_on_close) return 0;
    }
}
