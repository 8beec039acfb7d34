/*
 * wmdev: the native stand-in device.  The board's protocol engine (firmware/board/src/proto_*.c) and
 * the refiner library (firmware/src) on the host CPU, serving the wire protocol on a TCP socket of
 * 127.0.0.1, so `wavemesh stream INPUT --port socket://127.0.0.1:PORT` talks to it as to a board.
 * A fast device for protocol and fault-injection tests; the simulated board (sim/) is the exact one.
 *
 *   wmdev [--port N] [--max-width N] [--max-height N] [--max-samples N] [--tri-capacity N]
 *         [--max-levels N] [--window N] [--max-payload N] [--baud N] [--idle-timeout-ms N]
 *         [--write-timeout-ms N] [--link-timeout S] [--no-baud-switch] [--exit-on-close] [--quiet]
 *
 * Defaults are the board's sizes (wm_memmap.h: WM_GRID_MAX_W x WM_GRID_MAX_H, WM_TRI_CAPACITY
 * triangles) and 8 levels.  --port 0 picks a free port.  --baud N paces both directions at N baud
 * (8N1: ten bit times per byte), as a UART would; 0 (the default) runs at socket speed.  A paced device
 * takes BAUD (the host's --link-baud) for any rate from 1000 to 10 M baud (divisors in nanoseconds a
 * bit); --no-baud-switch states none (div_max 0), as a board with a fixed rate.
 *
 * One client at a time, and no client can hold the device: a connection that sends no valid frame
 * for --idle-timeout-ms outside a session and a job (default WM_PROTO_IDLE_TIMEOUT_MS), or that
 * takes none of the device's bytes for --write-timeout-ms (default WM_PROTO_WRITE_TIMEOUT_MS), is
 * closed; HELLO states both.  A connection that comes while another is served gets ERROR BUSY (after
 * its first bytes, or when it sends none within WM_PROTO_BUSY_WAIT_MS) and is closed: a thread
 * accepts every connection, so this happens within a second even while a job computes.
 *
 * A job outlives its connection: when the client leaves during a job, the next connection continues it
 * (the host that lost its line comes back with RESUME; a HELLO ends the job as ever).  The job ends with
 * NO_ACK when no valid frame came for --link-timeout seconds (default WM_PROTO_LINK_TIMEOUT_S; HELLO
 * states it), connection or not.
 *
 * Output lines on stdout: "wmdev: listening on 127.0.0.1:PORT", "wmdev: client connected",
 * "wmdev: second client refused (busy)", "wmdev: client idle, closed", "wmdev: client not reading,
 * closed", "wmdev: client left during the job", "wmdev: client came back",
 * "wmdev: client left bytes-in N bytes-out N bad-frames N".
 * Exit status: 0 after --exit-on-close, 4 socket error, 64 bad command line.
 */
#define _POSIX_C_SOURCE 200809L
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "native_job.h"
#include "proto.h"
#include "wm_memmap.h"

#define FW_MAJOR 0
#define FW_MINOR 2
#define DEFAULT_LEVELS 8 /* the board's coefficient memory holds levels 1..8 */
#define DEFAULT_WINDOW 4

typedef struct conn {
    int lfd, cfd, closed, quiet, stalled;
    uint32_t write_timeout_ms;
    uint8_t in[4096];
    size_t in_len, in_pos;
    uint8_t out[8192];
    size_t out_len;
    uint64_t byte_ns;          /* --baud: nanoseconds per byte, 0 unpaced */
    uint64_t rx_clock, tx_clock;
    uint64_t bytes_in, bytes_out;
    const wm_proto *eng;       /* its state says whether a job runs (a connection lost then is waited for) */
} conn;

static uint64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static void sleep_until(uint64_t t)
{
    uint64_t n = mono_ns();
    if (t > n) {
        struct timespec ts = {(time_t)((t - n) / 1000000000u), (long)((t - n) % 1000000000u)};
        nanosleep(&ts, NULL);
    }
}

/* A UART of the given rate: a byte may not go out (come in) before the line has carried the ones
 * before it.  Sleeping only when 2 ms ahead keeps the number of system calls down. */
static void pace(uint64_t *clock, uint64_t byte_ns, size_t n)
{
    uint64_t t = mono_ns();
    if (*clock < t) *clock = t;
    *clock += byte_ns * n;
    if (*clock > t + 2000000u) sleep_until(*clock);
}

/* Sends the buffered bytes.  A client that takes none of them for write_timeout_ms (it does not
 * read: its socket buffers are full) is given up: the connection counts as closed. */
static void conn_flush(conn *c)
{
    size_t done = 0;
    uint64_t deadline = mono_ns() + (uint64_t)c->write_timeout_ms * 1000000u;
    if (c->closed) {
        c->out_len = 0;
        return;
    }
    while (done < c->out_len) {
        size_t n = c->out_len - done;
        ssize_t k;
        if (c->byte_ns && n > 64) n = 64;
        k = send(c->cfd, c->out + done, n, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (k < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
            struct pollfd pf = {c->cfd, POLLOUT, 0};
            uint64_t t = mono_ns();
            if (c->write_timeout_ms && t >= deadline) {
                c->closed = c->stalled = 1;
                break;
            }
            poll(&pf, 1, c->write_timeout_ms ? (int)((deadline - t + 999999u) / 1000000u) : -1);
            continue;
        }
        if (k < 0) {
            if (errno == EINTR) continue;
            c->closed = 1;
            break;
        }
        deadline = mono_ns() + (uint64_t)c->write_timeout_ms * 1000000u; /* progress: the clock restarts */
        if (c->byte_ns) pace(&c->tx_clock, c->byte_ns, (size_t)k);
        done += (size_t)k;
    }
    c->bytes_out += done;
    c->out_len = 0;
}

static void io_write(void *ctx, const uint8_t *data, size_t n)
{
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

/* --- the doorman: a thread that accepts every connection ------------------------------------------
 * It hands a connection to the main thread when none is served, and refuses it with ERROR BUSY
 * otherwise, as proto.h's WM_PROTO_BUSY_WAIT_MS says: after the client's first bytes (or the wait),
 * the frame, then reading until the client closes, so that the close does not reset the connection
 * under the frame. */

static pthread_mutex_t door_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t door_cond = PTHREAD_COND_INITIALIZER;
static int door_fd = -1; /* a connection handed over, not yet taken */
static int door_busy;    /* a connection is handed over or being served */
#define DOOR_GRACE_MS 200u /* a connection that comes while another is served waits this long for the door */

/* ms milliseconds from now, on door_cond's clock (pthread_cond_timedwait's absolute time) */
static struct timespec door_deadline(uint32_t ms)
{
    struct timespec t;
    clock_gettime(CLOCK_REALTIME, &t);
    t.tv_sec += (time_t)(ms / 1000u);
    t.tv_nsec += (long)(ms % 1000u) * 1000000L;
    if (t.tv_nsec >= 1000000000L) t.tv_sec++, t.tv_nsec -= 1000000000L;
    return t;
}

static void drain(int fd, int ms)
{
    uint8_t junk[256];
    uint64_t deadline = mono_ns() + (uint64_t)ms * 1000000u;
    for (;;) {
        struct pollfd pf = {fd, POLLIN, 0};
        uint64_t t = mono_ns();
        if (t >= deadline || poll(&pf, 1, (int)((deadline - t) / 1000000u) + 1) <= 0) return;
        if (recv(fd, junk, sizeof junk, 0) <= 0) return;
    }
}

static void refuse(int fd, int quiet)
{
    uint8_t frame[WM_PROTO_BUSY_FRAME_MAX];
    size_t n = wm_proto_busy_frame(frame, sizeof frame);
    struct pollfd pf = {fd, POLLIN, 0};
    poll(&pf, 1, WM_PROTO_BUSY_WAIT_MS); /* its first bytes, or the wait ends */
    if (send(fd, frame, n, MSG_NOSIGNAL | MSG_DONTWAIT) < 0) { /* nothing more to do for it */
    }
    shutdown(fd, SHUT_WR);
    drain(fd, WM_PROTO_BUSY_WAIT_MS);
    close(fd);
    if (!quiet) printf("wmdev: second client refused (busy)\n"), fflush(stdout);
}

static void *doorman(void *arg)
{
    conn *c = arg;
    for (;;) {
        int fd = accept(c->lfd, NULL, NULL), take;
        if (fd < 0) {
            if (errno == EINTR || errno == ECONNABORTED) continue;
            fprintf(stderr, "wmdev: accept: %s\n", strerror(errno));
            exit(4);
        }
        pthread_mutex_lock(&door_lock);
        if (door_busy) { /* the client served may just have left during a job: give it a moment */
            struct timespec until = door_deadline(DOOR_GRACE_MS);
            while (door_busy)
                if (pthread_cond_timedwait(&door_cond, &door_lock, &until) != 0) break;
        }
        take = !door_busy;
        if (take) {
            door_busy = 1;
            door_fd = fd;
            pthread_cond_broadcast(&door_cond);
        }
        pthread_mutex_unlock(&door_lock);
        if (!take) refuse(fd, c->quiet);
    }
    return NULL;
}

/* The next client (the main thread waits here); door_done() when it left. */
static int door_next(void)
{
    int fd;
    pthread_mutex_lock(&door_lock);
    while (door_fd < 0) pthread_cond_wait(&door_cond, &door_lock);
    fd = door_fd;
    door_fd = -1;
    pthread_mutex_unlock(&door_lock);
    return fd;
}

static void door_done(void)
{
    pthread_mutex_lock(&door_lock);
    door_busy = 0;
    pthread_cond_broadcast(&door_cond);
    pthread_mutex_unlock(&door_lock);
}

/* The next client within ms milliseconds (-1: none came). */
static int door_wait(uint32_t ms)
{
    int fd;
    struct timespec until = door_deadline(ms);
    pthread_mutex_lock(&door_lock);
    while (door_fd < 0)
        if (pthread_cond_timedwait(&door_cond, &door_lock, &until) != 0) break;
    fd = door_fd;
    door_fd = -1;
    pthread_mutex_unlock(&door_lock);
    return fd;
}

/* The connection closed while a job runs: the door opens for the next client, who continues the job (a
 * host coming back with RESUME).  1 when one came within ms milliseconds. */
static int reconnect(conn *c, uint32_t ms)
{
    static const int one = 1;
    int fd;
    if (c->cfd >= 0) {
        close(c->cfd);
        c->cfd = -1;
        door_done();
        if (!c->quiet) printf("wmdev: client left during the job\n"), fflush(stdout);
    }
    fd = door_wait(ms);
    if (fd < 0) return 0;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    c->cfd = fd;
    c->closed = c->stalled = 0;
    c->in_len = c->in_pos = c->out_len = 0;
    if (!c->quiet) printf("wmdev: client came back\n"), fflush(stdout);
    return 1;
}

static int io_getc(void *ctx, uint32_t timeout_ms)
{
    conn *c = ctx;
    uint64_t deadline = mono_ns() + (uint64_t)timeout_ms * 1000000u;
    conn_flush(c);
    while (c->in_pos == c->in_len) {
        struct pollfd fds[1] = {{c->cfd, POLLIN, 0}};
        uint64_t t = mono_ns();
        int left = t >= deadline ? 0 : (int)((deadline - t + 999999u) / 1000000u), r;
        ssize_t k;
        if (c->closed && c->eng && c->eng->state == WM_PROTO_STATE_RUNNING) {
            if (!reconnect(c, (uint32_t)left)) return WM_PROTO_RX_TIMEOUT; /* the job's clock decides */
            continue;
        }
        if (c->closed) return WM_PROTO_RX_CLOSED;
        r = poll(fds, 1, left);
        if (r < 0) {
            if (errno == EINTR) continue;
            c->closed = 1;
            continue;
        }
        if (fds[0].revents & (POLLIN | POLLHUP | POLLERR)) {
            k = recv(c->cfd, c->in, sizeof c->in, 0);
            if (k < 0 && errno == EINTR) continue;
            if (k <= 0) {
                c->closed = 1; /* (a job waits for the client to come back: above) */
                continue;
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

/* BAUD (with --baud only: an unpaced socket has no rate to switch): the bytes written so far leave at
 * the old rate, then both directions are paced at div nanoseconds a bit */
static void io_set_divisor(void *ctx, uint32_t div)
{
    conn *c = ctx;
    conn_flush(c);
    sleep_until(c->tx_clock);
    c->byte_ns = 10u * (uint64_t)div;
}

static uint64_t io_cycles(void *ctx)
{
    (void)ctx;
    return mono_ns();
}

static int usage(const char *why)
{
    fprintf(stderr,
            "wmdev: %s\nusage: wmdev [--port N] [--max-width N] [--max-height N] [--max-samples N] "
            "[--tri-capacity N] [--max-levels N] [--window N] [--max-payload N] [--baud N] "
            "[--idle-timeout-ms N] [--write-timeout-ms N] [--link-timeout S] [--no-baud-switch] [--exit-on-close] "
            "[--quiet]\n",
            why);
    return 64;
}

static int number(const char *s, long lo, long hi, long *out)
{
    char *end;
    long v;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || *end || end == s || v < lo || v > hi) return 0;
    *out = v;
    return 1;
}

int main(int argc, char **argv)
{
    static wm_proto eng;
    wm_proto_caps caps;
    wm_proto_io io;
    conn c;
    long port = 7721, max_w = WM_GRID_MAX_W, max_h = WM_GRID_MAX_H, max_samples = -1, tri_cap = WM_TRI_CAPACITY;
    long levels = DEFAULT_LEVELS, window = DEFAULT_WINDOW, payload = WM_PROTO_MAX_PAYLOAD, baud = 0;
    long idle_ms = WM_PROTO_IDLE_TIMEOUT_MS, write_ms = WM_PROTO_WRITE_TIMEOUT_MS,
         link_s = WM_PROTO_LINK_TIMEOUT_S;
    pthread_t door;
    int exit_on_close = 0, quiet = 0, no_switch = 0;
    uint16_t *heights;
    uint8_t *mask;
    uint32_t mask_bytes;
    struct sockaddr_in addr;
    socklen_t len = sizeof addr;
    int one = 1;

    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        long *dst = NULL, lo = 0, hi = 0;
        if (!strcmp(a, "--exit-on-close")) {
            exit_on_close = 1;
            continue;
        }
        if (!strcmp(a, "--quiet")) {
            quiet = 1;
            continue;
        }
        if (!strcmp(a, "--no-baud-switch")) {
            no_switch = 1;
            continue;
        }
        if (!strcmp(a, "--port")) dst = &port, lo = 0, hi = 65535;
        else if (!strcmp(a, "--max-width")) dst = &max_w, lo = 2, hi = WM_PROTO_MAX_SIDE;
        else if (!strcmp(a, "--max-height")) dst = &max_h, lo = 2, hi = WM_PROTO_MAX_SIDE;
        else if (!strcmp(a, "--max-samples")) dst = &max_samples, lo = 4, hi = 1L << 28;
        else if (!strcmp(a, "--tri-capacity")) dst = &tri_cap, lo = 2, hi = 1L << 30;
        else if (!strcmp(a, "--max-levels")) dst = &levels, lo = 1, hi = WM_PROTO_MAX_LEVELS;
        else if (!strcmp(a, "--window")) dst = &window, lo = 1, hi = WM_PROTO_MAX_WINDOW;
        else if (!strcmp(a, "--max-payload")) dst = &payload, lo = WM_PROTO_MIN_PAYLOAD, hi = WM_PROTO_MAX_PAYLOAD;
        else if (!strcmp(a, "--baud")) dst = &baud, lo = 0, hi = 100000000;
        else if (!strcmp(a, "--idle-timeout-ms")) dst = &idle_ms, lo = 1, hi = 86400000;
        else if (!strcmp(a, "--write-timeout-ms")) dst = &write_ms, lo = 1, hi = 86400000;
        else if (!strcmp(a, "--link-timeout")) dst = &link_s, lo = 1, hi = 65535;
        else return usage("unknown option");
        if (i + 1 >= argc || !number(argv[++i], lo, hi, dst)) return usage("bad or missing number");
    }
    if (max_samples < 0) max_samples = max_w * max_h;
    mask_bytes = 2 * (uint32_t)((max_samples + 15) / 16);

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
    caps.features = WM_PROTO_FEATURE_INITIAL_ONLY | WM_PROTO_FEATURE_SPLINE | /* wm_spline, as the host's model */
                    WM_PROTO_FEATURE_HOLES | WM_PROTO_FEATURE_RICE; /* decoding costs it nothing that counts */
    caps.idle_timeout_ms = (uint32_t)idle_ms;
    if (baud && !no_switch) { /* a divisor is nanoseconds a bit (clk_hz 1e9) */
        caps.div = (uint32_t)((2000000000ull + (uint64_t)baud) / (2ull * (uint64_t)baud));
        caps.div_min = 100u; /* 10 Mbaud */
        caps.div_max = 1000000u; /* 1000 baud */
    }
    caps.write_timeout_ms = (uint32_t)write_ms;
    caps.link_timeout_s = (uint16_t)link_s;
    heights = calloc((size_t)max_samples, sizeof *heights);
    mask = calloc((size_t)mask_bytes, 1); /* --nodata hole: a bit per sample */
    if (!heights || !mask) return usage("cannot allocate the height memory");

    signal(SIGPIPE, SIG_IGN);
    memset(&c, 0, sizeof c);
    c.quiet = quiet;
    c.write_timeout_ms = (uint32_t)write_ms;
    c.byte_ns = baud ? 10000000000ull / (uint64_t)baud : 0;
    c.eng = &eng;
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
    printf("wmdev: listening on 127.0.0.1:%d (%ld x %ld, %ld triangles, %ld levels, %s)\n", ntohs(addr.sin_port),
           max_w, max_h, tri_cap, levels, baud ? "paced" : "unpaced");
    fflush(stdout);

    io.ctx = &c;
    io.getc = io_getc;
    io.read = NULL; /* getc(0) a byte at a time: a socket's reads are cheap */
    io.write = io_write;
    io.write_escaped = NULL;
    io.cycles = io_cycles;
    io.mark = NULL;
    io.frame = NULL; /* the engine deframes the bytes itself */
    io.upload = NULL;
    io.upload_crc = NULL;
    io.set_divisor = caps.div_max ? io_set_divisor : NULL;
    if (pthread_create(&door, NULL, doorman, &c) != 0) {
        fprintf(stderr, "wmdev: cannot start the accepting thread\n");
        return 4;
    }
    for (;;) {
        int how;
        c.cfd = door_next();
        setsockopt(c.cfd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        c.closed = c.stalled = 0;
        c.in_len = c.in_pos = c.out_len = 0;
        c.bytes_in = c.bytes_out = 0;
        c.rx_clock = c.tx_clock = 0;
        c.byte_ns = baud ? 10000000000ull / (uint64_t)baud : 0; /* every client starts at --baud */
        if (!quiet) printf("wmdev: client connected\n"), fflush(stdout);
        wm_proto_init(&eng, &io, &caps, heights, wm_native_job, NULL);
        wm_proto_set_mask(&eng, mask, mask_bytes);
        how = wm_proto_serve(&eng);
        if (c.cfd >= 0) close(c.cfd);
        door_done(); /* before the lines below: whoever reads them may connect at once */
        if (!quiet && how == WM_PROTO_SERVE_IDLE) printf("wmdev: client idle, closed\n"), fflush(stdout);
        if (!quiet && c.stalled) printf("wmdev: client not reading, closed\n"), fflush(stdout);
        if (!quiet)
            printf("wmdev: client left bytes-in %llu bytes-out %llu bad-frames %lu\n",
                   (unsigned long long)c.bytes_in, (unsigned long long)c.bytes_out, (unsigned long)eng.bad_frames),
                fflush(stdout);
        if (exit_on_close) return 0;
    }
}
