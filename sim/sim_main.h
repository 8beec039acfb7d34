// wavemesh simulators' one main: wmsim (sim/board_main.cpp, the ULX3S SoC) and wmsim-icebreaker
// (sim/icebreaker_main.cpp, the iCEBreaker's FPGA stage) differ only in their Board class; the
// options, the socket loop and the lines on stdout are these.
//
// The board boots from reset without a host until it is ready to serve (Board::ready: the ULX3S at the
// firmware's first SYS.STAGE write, the iCEBreaker at once), the socket unserved meanwhile (a client's
// connection and first bytes wait in the kernel's queue); from then on the clock stops while no client
// is connected (a board waits for its host; cycle counts do not depend on when the host connects).  One
// client at a time (TcpBridge); when it leaves, the model waits for the next one, or exits with
// --exit-on-close.
//
// Lines on stdout, all starting with "wmsim: " (a board adds its own, Board::cycle):
//   wmsim: listening on 127.0.0.1:PORT (MODE)  wmsim: client connected / client left cycle N
//   wmsim: progress cycle N cpu S.SSS s        (every S seconds of wall time with --progress S)
//   wmsim: summary cycles N wall S.SSS s rate K kHz bytes-in N bytes-out N cpu S.SSS s
// (wall: the seconds spent simulating, not waiting for a client; cpu: the process's CPU time)
//
// Exit status: a board's own (Board::cycle), 0 when the client left with --exit-on-close, 3
// --max-cycles reached, 4 socket error, 64 bad command line, 130 interrupted.
#ifndef WM_SIM_MAIN_H
#define WM_SIM_MAIN_H

#include <chrono>
#include <cinttypes>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "tcp_bridge.h"
#include "verilated.h"

struct SimOptions {
    int port = 0;
    std::string firmware;
    std::string trace;
    std::string profile;
    std::string pc_trace;  // --pc-trace: every executed PC change (with --profile)
    bool fast = false;
    bool exit_on_close = false;
    bool no_socket = false;
    bool quiet = false;
    uint64_t max_cycles = 0;
    double progress = 0;  // seconds between progress lines (0: none)
};

// What a board's simulator is and takes.
struct SimBoardInfo {
    int default_port;
    bool soc;  // the SoC: --firmware (required), --fast, --no-socket, --trace, --profile, --pc-trace, --progress
};

constexpr uint64_t SIM_SOCKET_EVERY = 256;  // cycles between socket services
constexpr int SIM_WAIT_POLL_MS = 200;       // poll interval while waiting for a client
constexpr int SIM_FLUSH_MS = 2000;          // how long output may take to drain at exit

extern volatile std::sig_atomic_t g_sim_stop;

void sim_usage(const char *argv0, const SimBoardInfo &info);
bool sim_parse(int argc, char **argv, const SimBoardInfo &info, SimOptions *o);
void sim_log(bool quiet, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
double sim_cpu_seconds();
void sim_signals();

// Board: Board(const SimOptions &, VerilatedContext *); int cycle(TcpBridge *) (one clock cycle with
// the UART bridged, nullptr: no host; an exit status when the run ends, else -1); uint64_t cycles();
// bool ready() (the boot is over: it serves its UART); bool finish() (at exit: false when its files
// cannot be written); const char *mode() (the listening line's); static std::vector<std::string>
// plusargs(const SimOptions &, int argc, char **argv) (what Verilator's context sees).
template <class Board>
int sim_main(int argc, char **argv, const SimBoardInfo &info) {
    SimOptions opt;
    opt.port = info.default_port;
    if (!sim_parse(argc, argv, info, &opt)) {
        sim_usage(argv[0], info);
        return 64;
    }
    auto ctx = std::make_unique<VerilatedContext>();
    std::vector<std::string> args = Board::plusargs(opt, argc, argv);
    std::vector<const char *> vargs;
    for (const auto &a : args) vargs.push_back(a.c_str());
    ctx->commandArgs(static_cast<int>(vargs.size()), vargs.data());
    sim_signals();

    TcpBridge bridge;
    std::unique_ptr<Board> board(new Board(opt, ctx.get()));
    if (!opt.no_socket) {
        if (!bridge.listen_on(opt.port)) {
            fprintf(stderr, "wmsim: error: %s\n", bridge.error().c_str());
            return 4;
        }
        printf("wmsim: listening on 127.0.0.1:%d (%s)\n", bridge.port(), board->mode());
        fflush(stdout);
    }
    auto t0 = std::chrono::steady_clock::now();
    auto next_progress = t0 + std::chrono::duration<double>(opt.progress);
    double waited = 0;  // seconds spent waiting for a client (not simulating)
    bool was_connected = false;
    bool booted = false;  // (never with --no-socket)
    int status = -1;
    while (status < 0) {
        if (g_sim_stop) {
            sim_log(opt.quiet, "interrupted cycle %" PRIu64, board->cycles());
            status = 130;
            break;
        }
        if (opt.progress > 0 && (board->cycles() % SIM_SOCKET_EVERY) == 0 &&
            std::chrono::steady_clock::now() >= next_progress) {
            // (also with --quiet: asked for)
            printf("wmsim: progress cycle %" PRIu64 " cpu %.3f s\n", board->cycles(), sim_cpu_seconds());
            fflush(stdout);
            next_progress = std::chrono::steady_clock::now() + std::chrono::duration<double>(opt.progress);
        }
        if (!opt.no_socket && !booted) booted = board->ready();  // until then: no host, no socket
        if (booted && (board->cycles() % SIM_SOCKET_EVERY) == 0) {
            if (!bridge.service() && was_connected) {
                was_connected = false;
                sim_log(opt.quiet, "client left cycle %" PRIu64, board->cycles());
                if (opt.exit_on_close) {
                    status = 0;
                    break;
                }
            }
            while (!bridge.connected() && !g_sim_stop) {
                // the board waits for its host: the clock stops
                auto w0 = std::chrono::steady_clock::now();
                bridge.wait_for_client(SIM_WAIT_POLL_MS);
                waited += std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
            }
            if (!was_connected && bridge.connected()) sim_log(opt.quiet, "client connected cycle %" PRIu64, board->cycles());
            was_connected = bridge.connected();
        }
        status = board->cycle(bridge.connected() ? &bridge : nullptr);
        if (status < 0 && opt.max_cycles && board->cycles() >= opt.max_cycles) {
            sim_log(opt.quiet, "max cycles %" PRIu64 " reached", opt.max_cycles);
            status = 3;
        }
    }
    if (!opt.no_socket) {
        bridge.service();
        bridge.flush(SIM_FLUSH_MS);
    }
    uint64_t cycles = board->cycles();
    if (!board->finish()) fprintf(stderr, "wmsim: error: cannot write profile '%s'\n", opt.profile.c_str());
    board.reset();
    double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() - waited;
    double khz = wall > 0 ? cycles / wall / 1000.0 : 0.0;
    printf("wmsim: summary cycles %" PRIu64 " wall %.3f s rate %.0f kHz bytes-in %" PRIu64 " bytes-out %" PRIu64
           " cpu %.3f s\n",
           cycles, wall, khz, bridge.bytes_in, bridge.bytes_out, sim_cpu_seconds());
    fflush(stdout);
    return status;
}

#endif
