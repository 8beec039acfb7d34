// wavemesh simulated iCEBreaker: the Verilator model of rtl/boards/icebreaker_top.v (the FPGA stage
// alone behind its UART) with the UART bridged to TCP, as wmsim bridges the simulated ULX3S.
//
//   wmsim-icebreaker [--port N] [--exit-on-close] [--max-cycles N] [--quiet]
//
// A host talks to it as to the board: pyserial's serial_for_url("socket://127.0.0.1:N") (wavemesh
// stream, wavemesh devices).  Bytes from the client are driven onto the RX pin bit by bit at the
// stage's divisor and the TX pin is sampled back into bytes (there is no fast mode: the stage has no
// FIFO port to bypass to, and it is small enough to simulate at a few MHz).  The clock stops while no
// client is connected; one client at a time (TcpBridge).
//
// Lines on stdout, all starting with "wmsim: ":
//   wmsim: listening on 127.0.0.1:PORT        wmsim: client connected / client left
//   wmsim: leds 0xVALUE cycle N               (bit 0 the red LED, a job runs; bit 1 the green, an
//                                              RX overrun; 1 = lit)
//   wmsim: summary cycles N wall S.SSS s rate K kHz bytes-in N bytes-out N
//
// Exit status: 0 the client left with --exit-on-close; 3 --max-cycles reached; 4 socket error;
// 64 bad command line; 130 interrupted.
#include <chrono>
#include <cinttypes>
#include <csignal>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "Vicebreaker_sim.h"
#include "tcp_bridge.h"
#include "uart_line.h"
#include "verilated.h"

namespace {

constexpr int DEFAULT_PORT = 7722;
constexpr uint64_t SOCKET_EVERY = 256;  // cycles between socket services
constexpr int WAIT_POLL_MS = 200;
constexpr int FLUSH_MS = 2000;

volatile std::sig_atomic_t g_stop = 0;
bool g_quiet = false;

void on_signal(int) { g_stop = 1; }

void say(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void say(const char *fmt, ...) {
    if (g_quiet) return;
    va_list ap;
    va_start(ap, fmt);
    fputs("wmsim: ", stdout);
    vfprintf(stdout, fmt, ap);
    fputc('\n', stdout);
    fflush(stdout);
    va_end(ap);
}

struct Options {
    int port = DEFAULT_PORT;
    bool exit_on_close = false;
    bool quiet = false;
    uint64_t max_cycles = 0;
};

bool parse(int argc, char **argv, Options *o) {
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if ((a == "--port" || a == "--max-cycles") && i + 1 < argc) {
            char *end = nullptr;
            unsigned long long v = strtoull(argv[++i], &end, 10);
            if (*end || (a == "--port" && v > 65535)) {
                fprintf(stderr, "wmsim: error: bad %s '%s'\n", a.c_str(), argv[i]);
                return false;
            }
            if (a == "--port") o->port = static_cast<int>(v);
            else o->max_cycles = v;
        } else if (a == "--exit-on-close") {
            o->exit_on_close = true;
        } else if (a == "--quiet") {
            o->quiet = true;
        } else {
            fprintf(stderr, "wmsim: error: unknown option '%s'\n", a.c_str());
            return false;
        }
    }
    return true;
}

}  // namespace

int main(int argc, char **argv) {
    Options opt;
    if (!parse(argc, argv, &opt)) {
        fprintf(stderr, "usage: %s [--port N (default %d, 0 = any)] [--exit-on-close] [--max-cycles N] "
                        "[--quiet]\n", argv[0], DEFAULT_PORT);
        return 64;
    }
    auto ctx = std::make_unique<VerilatedContext>();
    ctx->commandArgs(argc, argv);
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);

    TcpBridge bridge;
    if (!bridge.listen_on(opt.port)) {
        fprintf(stderr, "wmsim: error: %s\n", bridge.error().c_str());
        return 4;
    }
    printf("wmsim: listening on 127.0.0.1:%d (iCEBreaker, pin mode)\n", bridge.port());
    fflush(stdout);

    g_quiet = opt.quiet;

    std::unique_ptr<Vicebreaker_sim> top(new Vicebreaker_sim(ctx.get()));
    top->clk = 0;
    top->btn_n = 1;  // the power-on reset does the rest
    top->rxd = 1;
    top->eval();
    UartLineDriver line_out;
    UartLineSampler line_in;
    uint64_t cycles = 0;
    unsigned leds = 0;
    int status = -1;
    bool was_connected = false;
    auto t0 = std::chrono::steady_clock::now();
    double waited = 0;
    while (status < 0) {
        if (g_stop) {
            status = 130;
            break;
        }
        if ((cycles % SOCKET_EVERY) == 0) {
            if (!bridge.service() && was_connected) {
                was_connected = false;
                say("client left cycle %" PRIu64, cycles);
                if (opt.exit_on_close) {
                    status = 0;
                    break;
                }
            }
            while (!bridge.connected() && !g_stop) {
                auto w0 = std::chrono::steady_clock::now();
                bridge.wait_for_client(WAIT_POLL_MS);
                waited += std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
            }
            if (!was_connected && bridge.connected()) say("client connected cycle %" PRIu64, cycles);
            was_connected = bridge.connected();
        }
        if (!line_out.busy() && !bridge.rx.empty()) {
            line_out.start(bridge.rx.front(), top->uart_div);
            bridge.rx.pop_front();
        }
        top->rxd = line_out.step();
        top->clk = 0;
        top->eval();
        uint8_t byte;
        int r = line_in.step(top->txd, top->uart_div, &byte);
        if (r > 0) bridge.tx.push_back(static_cast<char>(byte));
        if (r < 0) say("tx framing error cycle %" PRIu64, cycles);
        unsigned now = (top->ledr_n ? 0u : 1u) | (top->ledg_n ? 0u : 2u);
        if (now != leds) {
            leds = now;
            say("leds 0x%02x cycle %" PRIu64, leds, cycles);
        }
        top->clk = 1;
        top->eval();
        ++cycles;
        if (opt.max_cycles && cycles >= opt.max_cycles) {
            say("max cycles %" PRIu64 " reached", opt.max_cycles);
            status = 3;
        }
    }
    bridge.service();
    bridge.flush(FLUSH_MS);
    top->final();
    double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() - waited;
    printf("wmsim: summary cycles %" PRIu64 " wall %.3f s rate %.0f kHz bytes-in %" PRIu64 " bytes-out %" PRIu64 "\n",
           cycles, wall, wall > 0 ? cycles / wall / 1000.0 : 0.0, bridge.bytes_in, bridge.bytes_out);
    fflush(stdout);
    return status;
}
