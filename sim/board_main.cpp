// wavemesh simulated board: the Verilator model of soc_top with its UART bridged to TCP.
//
//   wmsim --firmware FILE.hex [--port N] [--fast] [--exit-on-close] [--no-socket]
//         [--max-cycles N] [--trace FILE.fst] [--profile FILE] [--progress S] [--quiet]
//
// A host talks to it as to a board: pyserial's serial_for_url("socket://127.0.0.1:N").  Bytes
// from the client are driven onto the UART RX pin bit by bit at the board's current baud divisor,
// and the TX pin is sampled back into bytes for the client (pin-accurate mode).  --fast instead
// feeds bytes straight into the UART's RX FIFO (with back-pressure) and takes them straight from
// its TX FIFO: the same firmware, much shorter runs.
//
// The clock stops while no client is connected (the board waits for its host; cycle counts do not
// depend on when the host connects).  One client at a time; when it leaves, the model waits for
// the next one, or exits with --exit-on-close.  --no-socket runs without any socket until the
// firmware halts (for programs that do not talk).
//
// Lines on stdout, all starting with "wmsim: ", for people and tests:
//   wmsim: listening on 127.0.0.1:PORT        wmsim: client connected / client left
//   wmsim: stage 0xVALUE cycle N              (every SYS.STAGE write)
//   wmsim: leds 0xVALUE cycle N               (every change of the LED outputs)
//   wmsim: halt 0xCODE cycle N                wmsim: trap cycle N
//   wmsim: progress cycle N cpu S.SSS s       (every S seconds of wall time with --progress S)
//   wmsim: summary cycles N wall S.SSS s rate K kHz bytes-in N bytes-out N cpu S.SSS s
// (wall: the seconds spent simulating, not waiting for a client; cpu: the process's CPU time)
//
// --profile FILE writes, at exit, "PC CYCLES" lines (hex, decimal): every cycle is counted against the
// address of the last instruction fetched (the CPU is not pipelined: the cycles an instruction takes,
// its memory accesses included, follow its fetch).  tools/board_profile.py maps them to functions.
// With it, FILE.data gets the data accesses by 64-byte block: "BLOCK WAIT READS WRITES" (the block's
// byte address in hex; the cycles data accesses to it waited beyond the 2 of a block RAM's answer,
// and the reads and writes it took): where the SDRAM's misses and write-through cost go
// (tools/board_profile.py --data maps them to the memory map's areas and the refiner's arrays).
//
// Exit status: 0 halt with code 0 (or the client left with --exit-on-close); 1 halt with another
// code; 2 CPU trap; 3 --max-cycles reached; 4 socket error; 64 bad command line; 130 interrupted.
#include <chrono>
#include <cinttypes>
#include <cstdarg>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <deque>
#include <memory>
#include <map>
#include <string>
#include <vector>

#include "Vboard_sim.h"
#include "Vboard_sim___024root.h"
#include "tcp_bridge.h"
#include "uart_line.h"
#include "wm_memmap.h"
#include "verilated.h"
#if VM_TRACE
#include "verilated_fst_c.h"
#endif

// the generated model's evaluation (Vboard_sim___024root__*.cpp; no header of Verilator's declares it)
void Vboard_sim___024root___eval(Vboard_sim___024root *vlSelf);

namespace {

constexpr int DEFAULT_PORT = 7720;
constexpr uint64_t SOCKET_EVERY = 256;   // cycles between socket services
constexpr int RESET_CYCLES = 8;
constexpr int WAIT_POLL_MS = 200;       // poll interval while waiting for a client
constexpr int FLUSH_MS = 2000;          // how long output may take to drain at exit

struct Options {
    int port = DEFAULT_PORT;
    std::string firmware;
    std::string trace;
    std::string profile;
    bool fast = false;
    bool exit_on_close = false;
    bool no_socket = false;
    bool quiet = false;
    uint64_t max_cycles = 0;
    double progress = 0;  // seconds between progress lines (0: none)
};

volatile std::sig_atomic_t g_stop = 0;

void on_signal(int) { g_stop = 1; }

double cpu_seconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }  // the process's CPU time

void usage(const char *argv0) {
    fprintf(stderr,
            "usage: %s --firmware FILE.hex [--port N (default %d, 0 = any)] [--fast] [--exit-on-close]\n"
            "          [--no-socket] [--max-cycles N] [--trace FILE.fst] [--profile FILE] [--progress S]\n"
            "          [--quiet]\n",
            argv0, DEFAULT_PORT);
}

bool parse(int argc, char **argv, Options *o) {
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto value = [&](const char *name) -> const char * {
            if (i + 1 >= argc) {
                fprintf(stderr, "wmsim: error: %s needs a value\n", name);
                return nullptr;
            }
            return argv[++i];
        };
        if (a == "--firmware") {
            const char *v = value("--firmware");
            if (!v) return false;
            o->firmware = v;
        } else if (a == "--port") {
            const char *v = value("--port");
            if (!v) return false;
            char *end = nullptr;
            long p = strtol(v, &end, 10);
            if (*end || p < 0 || p > 65535) {
                fprintf(stderr, "wmsim: error: bad port '%s'\n", v);
                return false;
            }
            o->port = static_cast<int>(p);
        } else if (a == "--max-cycles") {
            const char *v = value("--max-cycles");
            if (!v) return false;
            o->max_cycles = strtoull(v, nullptr, 10);
        } else if (a == "--trace") {
            const char *v = value("--trace");
            if (!v) return false;
            o->trace = v;
        } else if (a == "--profile") {
            const char *v = value("--profile");
            if (!v) return false;
            o->profile = v;
        } else if (a == "--progress") {
            const char *v = value("--progress");
            if (!v) return false;
            char *end = nullptr;
            o->progress = strtod(v, &end);
            if (*end || !(o->progress > 0)) {
                fprintf(stderr, "wmsim: error: bad --progress '%s' (seconds > 0)\n", v);
                return false;
            }
        } else if (a == "--fast") {
            o->fast = true;
        } else if (a == "--exit-on-close") {
            o->exit_on_close = true;
        } else if (a == "--no-socket") {
            o->no_socket = true;
        } else if (a == "--quiet") {
            o->quiet = true;
        } else if (a == "-h" || a == "--help") {
            usage(argv[0]);
            exit(0);
        } else if (a.rfind("+", 0) == 0) {
            // a Verilator plusarg: passed through
        } else {
            fprintf(stderr, "wmsim: error: unknown option '%s'\n", a.c_str());
            return false;
        }
    }
    if (o->firmware.empty()) {
        fprintf(stderr, "wmsim: error: --firmware FILE.hex is required\n");
        return false;
    }
    if (FILE *f = fopen(o->firmware.c_str(), "r")) {
        fclose(f);
    } else {
        fprintf(stderr, "wmsim: error: cannot read firmware '%s'\n", o->firmware.c_str());
        return false;
    }
#if !VM_TRACE
    if (!o->trace.empty()) {
        fprintf(stderr, "wmsim: error: this simulator was built without tracing: make sim TRACE=1\n");
        return false;
    }
#endif
    return true;
}

class Board {
public:
    Board(const Options &o, VerilatedContext *ctx) : opt_(o), top_(new Vboard_sim(ctx)) {
#if VM_TRACE
        if (!o.trace.empty()) {
            ctx->traceEverOn(true);
            trace_.reset(new VerilatedFstC);
            top_->trace(trace_.get(), 99);
            trace_->open(o.trace.c_str());
        }
#endif
        top_->clk = 0;
        top_->rst = 1;
        top_->uart_rxd = 1;
        top_->eval();  // the model's initialisation, no clock edge (it clears the force controls below)
        // soc_top's fast-mode ports, forced over ulx3s_top's tie-offs (board_sim.vlt); in pin mode
        // forced to the tie-offs' values
        Vboard_sim___024root &r = *top_->rootp;
        r.board_sim__DOT__top_inst__DOT__soc_inst__DOT__uart_bypass__VforceEn = 1;
        r.board_sim__DOT__top_inst__DOT__soc_inst__DOT__uart_bypass__VforceVal = o.fast ? 1 : 0;
        r.board_sim__DOT__top_inst__DOT__soc_inst__DOT__m_axis_uart_tx_tready__VforceEn = 1;
        r.board_sim__DOT__top_inst__DOT__soc_inst__DOT__m_axis_uart_tx_tready__VforceVal = o.fast ? 1 : 0;
        r.board_sim__DOT__top_inst__DOT__soc_inst__DOT__s_axis_uart_rx_tvalid__VforceEn = 1;
        r.board_sim__DOT__top_inst__DOT__soc_inst__DOT__s_axis_uart_rx_tdata__VforceEn = 0xff;
        offer_rx(false, 0);
        for (int i = 0; i < RESET_CYCLES; ++i) tick_raw();
        top_->rst = 0;
        leds_ = top_->led;
    }

    ~Board() {
#if VM_TRACE
        if (trace_) trace_->close();
#endif
        top_->final();
    }

    // One clock cycle with the UART bridged to `bridge` (nullptr: no host).  Returns an exit status
    // when the run ends, -1 otherwise.
    int cycle(TcpBridge *bridge) {
        std::deque<uint8_t> *rx = bridge ? &bridge->rx : nullptr;
        // inputs for this cycle
        if (opt_.fast) {
            offer_rx(rx && !rx->empty(), rx && !rx->empty() ? rx->front() : 0);
        } else {
            if (!line_out_.busy() && rx && !rx->empty()) {
                line_out_.start(rx->front(), top_->uart_div);
                rx->pop_front();
            }
            top_->uart_rxd = line_out_.step();
        }
        top_->clk = 0;
        eval();
        dump();
        // what happens at this rising edge
        if (opt_.fast) {
            if (rx_valid_ && top_->s_axis_uart_rx_tready) rx->pop_front();
            if (top_->m_axis_uart_tx_tvalid && bridge) bridge->tx.push_back(static_cast<char>(top_->m_axis_uart_tx_tdata));
        } else {
            uint8_t byte;
            int r = line_in_.step(top_->uart_txd, top_->uart_div, &byte);
            if (r > 0 && bridge) bridge->tx.push_back(static_cast<char>(byte));
            if (r < 0) log("tx framing error cycle %" PRIu64, cycles_);
        }
        int status = -1;
        if (top_->stage_valid) log("stage 0x%08x cycle %" PRIu64, top_->stage, cycles_);
        if (top_->led != leds_) {
            leds_ = top_->led;
            log("leds 0x%02x cycle %" PRIu64, leds_, cycles_);
        }
        if (top_->halt_valid) {
            log("halt 0x%08x cycle %" PRIu64, top_->halt_code, cycles_);
            status = top_->halt_code == 0 ? 0 : 1;
        }
        if (top_->trap) {
            log("trap cycle %" PRIu64, cycles_);
            status = 2;
        }
        if (profiling_) {
            if (top_->prof_fetch) pc_ = top_->prof_fetch_pc;
            if (pc_ / 2 < profile_fw_.size())
                ++profile_fw_[pc_ / 2];  // the firmware RAM: an array (a map lookup a cycle halved the rate)
            else
                ++profile_[pc_];
            if (top_->prof_data_wait) {
                ++data_wait_;
            } else if (top_->prof_data_done) {
                DataBlock &b = data_[top_->prof_pc >> 6];
                b.wait += data_wait_ > 1 ? data_wait_ - 1 : 0;  // a block RAM waits 1 cycle
                ++(top_->prof_data_write ? b.writes : b.reads);
                data_wait_ = 0;
            }
        }
        top_->clk = 1;
        eval();
        dump();
        ++cycles_;
        return status;
    }

    // The --profile histogram, "PC CYCLES" per line in address order; false when it cannot be written.
    bool write_profile(const std::string &path) {
        FILE *f = fopen(path.c_str(), "w");
        if (!f) return false;
        for (size_t i = 0; i < profile_fw_.size(); ++i)
            if (profile_fw_[i]) profile_[static_cast<uint32_t>(2 * i)] += profile_fw_[i];
        profile_fw_.clear();
        for (const auto &kv : profile_) fprintf(f, "%08x %" PRIu64 "\n", kv.first, kv.second);
        if (fclose(f) != 0) return false;
        f = fopen((path + ".data").c_str(), "w");
        if (!f) return false;
        for (const auto &kv : data_)
            fprintf(f, "%08x %" PRIu64 " %" PRIu64 " %" PRIu64 "\n", kv.first << 6, kv.second.wait, kv.second.reads,
                    kv.second.writes);
        return fclose(f) == 0;
    }

    uint64_t cycles() const { return cycles_; }

    void log(const char *fmt, ...) __attribute__((format(printf, 2, 3))) {
        if (opt_.quiet) return;
        va_list ap;
        va_start(ap, fmt);
        fputs("wmsim: ", stdout);
        vfprintf(stdout, fmt, ap);
        fputc('\n', stdout);
        fflush(stdout);
        va_end(ap);
    }

private:
    // One evaluation of the model: Vboard_sim::eval() without the housekeeping it does for Verilator's
    // multi-threaded runtime (a deleter and a message queue, each behind a mutex: 3 % of a run), which
    // this single-threaded model without dynamic objects never needs ($display and $fatal print at
    // once).  The first evaluation, which initialises the model, is top_->eval() in the constructor.
    void eval() { Vboard_sim___024root___eval(top_->rootp); }

    // fast mode: the byte offered to the UART's RX FIFO this cycle (soc_top's s_axis_uart_rx_*)
    void offer_rx(bool valid, uint8_t byte) {
        rx_valid_ = valid;
        top_->rootp->board_sim__DOT__top_inst__DOT__soc_inst__DOT__s_axis_uart_rx_tvalid__VforceVal = valid;
        top_->rootp->board_sim__DOT__top_inst__DOT__soc_inst__DOT__s_axis_uart_rx_tdata__VforceVal = byte;
    }

    void tick_raw() {
        top_->clk = 0;
        top_->eval();
        top_->clk = 1;
        top_->eval();
    }

    void dump() {
#if VM_TRACE
        if (trace_) trace_->dump(time_);
        ++time_;
#endif
    }

    const Options &opt_;
    std::unique_ptr<Vboard_sim> top_;
#if VM_TRACE
    std::unique_ptr<VerilatedFstC> trace_;
    uint64_t time_ = 0;
#endif
    UartLineDriver line_out_;
    UartLineSampler line_in_;
    uint64_t cycles_ = 0;
    uint32_t leds_ = 0;
    bool rx_valid_ = false;
    bool profiling_ = !opt_.profile.empty();
    uint32_t pc_ = 0;
    std::map<uint32_t, uint64_t> profile_;
    std::vector<uint64_t> profile_fw_ = std::vector<uint64_t>(profiling_ ? WM_FW_RAM_ENTRIES * 2 : 0);
    struct DataBlock {
        uint64_t wait = 0, reads = 0, writes = 0;
    };
    uint64_t data_wait_ = 0;  // cycles the current data access has waited
    std::map<uint32_t, DataBlock> data_;
};

}  // namespace

int main(int argc, char **argv) {
    Options opt;
    if (!parse(argc, argv, &opt)) {
        usage(argv[0]);
        return 64;
    }
    auto ctx = std::make_unique<VerilatedContext>();
    // Verilator sees the firmware as a plusarg (board_sim.v loads it), and any +plusargs given
    std::string plusarg = "+firmware=" + opt.firmware;
    std::vector<const char *> vargs{argv[0], plusarg.c_str()};
    for (int i = 1; i < argc; ++i)
        if (argv[i][0] == '+') vargs.push_back(argv[i]);
    ctx->commandArgs(static_cast<int>(vargs.size()), vargs.data());
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);

    TcpBridge bridge;
    if (!opt.no_socket) {
        if (!bridge.listen_on(opt.port)) {
            fprintf(stderr, "wmsim: error: %s\n", bridge.error().c_str());
            return 4;
        }
        printf("wmsim: listening on 127.0.0.1:%d (%s mode)\n", bridge.port(), opt.fast ? "fast" : "pin");
        fflush(stdout);
    }

    Board board(opt, ctx.get());
    auto t0 = std::chrono::steady_clock::now();
    auto next_progress = t0 + std::chrono::duration<double>(opt.progress);
    double waited = 0;  // seconds spent waiting for a client (not simulating)
    int status = -1;
    while (status < 0) {
        if (g_stop) {
            board.log("interrupted cycle %" PRIu64, board.cycles());
            status = 130;
            break;
        }
        if (opt.progress > 0 && (board.cycles() % SOCKET_EVERY) == 0 &&
            std::chrono::steady_clock::now() >= next_progress) {
            // (also with --quiet: asked for)
            printf("wmsim: progress cycle %" PRIu64 " cpu %.3f s\n", board.cycles(), cpu_seconds());
            fflush(stdout);
            next_progress = std::chrono::steady_clock::now() + std::chrono::duration<double>(opt.progress);
        }
        if (!opt.no_socket && (board.cycles() % SOCKET_EVERY) == 0) {
            if (!bridge.service()) {
                board.log("client left cycle %" PRIu64, board.cycles());
                if (opt.exit_on_close) {
                    status = 0;
                    break;
                }
            }
            while (!bridge.connected() && !g_stop) {
                // the board waits for its host: the clock stops
                auto w0 = std::chrono::steady_clock::now();
                bridge.wait_for_client(WAIT_POLL_MS);
                waited += std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
            }
        }
        status = board.cycle(opt.no_socket ? nullptr : &bridge);
        if (status < 0 && opt.max_cycles && board.cycles() >= opt.max_cycles) {
            board.log("max cycles %" PRIu64 " reached", opt.max_cycles);
            status = 3;
        }
    }
    if (!opt.no_socket) {
        bridge.service();
        bridge.flush(FLUSH_MS);
    }
    if (!opt.profile.empty() && !board.write_profile(opt.profile))
        fprintf(stderr, "wmsim: error: cannot write profile '%s'\n", opt.profile.c_str());
    double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() - waited;
    double khz = wall > 0 ? board.cycles() / wall / 1000.0 : 0.0;
    double cpu = cpu_seconds();
    printf("wmsim: summary cycles %" PRIu64 " wall %.3f s rate %.0f kHz bytes-in %" PRIu64 " bytes-out %" PRIu64
           " cpu %.3f s\n",
           board.cycles(), wall, khz, bridge.bytes_in, bridge.bytes_out, cpu);
    fflush(stdout);
    return status;
}
