// wavemesh simulated board: the Verilator model of soc_top with its UART bridged to TCP.
//
//   wmsim --firmware FILE.hex [--port N] [--fast] [--exit-on-close] [--no-socket]
//         [--max-cycles N] [--trace FILE.fst] [--profile FILE [--pc-trace FILE]] [--progress S] [--quiet]
//
// A host talks to it as to a board: pyserial's serial_for_url("socket://127.0.0.1:N").  Bytes
// from the client are driven onto the UART RX pin bit by bit at the board's current baud divisor,
// and the TX pin is sampled back into bytes for the client (pin-accurate mode).  --fast instead
// feeds bytes straight into the UART's RX FIFO (with back-pressure) and takes them straight from
// its TX FIFO: the same firmware, much shorter runs.
//
// The options, the socket loop and the common lines are sim_main.h's (one main for both simulators).
// --no-socket runs without any socket until the firmware halts (for programs that do not talk).
//
// This board's lines on stdout, beside sim_main.h's:
//   wmsim: stage 0xVALUE cycle N              (every SYS.STAGE write)
//   wmsim: leds 0xVALUE cycle N               (every change of the LED outputs)
//   wmsim: halt 0xCODE cycle N                wmsim: trap cycle N pc 0xPC
//   wmsim: uart divisor 0xN cycle N           (every change of the UART's divisor: a baud switch, the
//                                              switch back; a test's line model reads the board's rate)
//
// --profile FILE writes, at exit, "PC CYCLES" lines (hex, decimal): every cycle is counted against the
// address of the last instruction fetched (the CPU is not pipelined: the cycles an instruction takes,
// its memory accesses included, follow its fetch).  tools/board_profile.py maps them to functions.
// With it, FILE.data gets the data accesses by 64-byte block: "BLOCK WAIT READS WRITES" (the block's
// byte address in hex; the cycles data accesses to it waited beyond the 2 of a block RAM's answer,
// and the reads and writes it took): where the SDRAM's misses and write-through cost go
// (tools/board_profile.py --data maps them to the memory map's areas and the refiner's arrays).
// FILE.ibus gets the cycles instruction fetches waited for memory, by the 32-byte line fetched:
// "LINE CYCLES" (the VexRiscv's instruction cache refills from the firmware RAM's port B; every fetch
// of the PicoRV32, on the memory bus).
// --pc-trace FILE (with --profile) writes the PC of every cycle that starts another instruction than the
// cycle before, as 32-bit little-endian words, and 0xffffffff at every SYS.STAGE write (the firmware
// flushes both caches there): the instruction stream tools/code_layout.py replays through a model of the
// instruction cache to choose the hot code's order (firmware/board/hot_order.txt).
//
// Exit status: 0 halt with code 0; 1 halt with another code; 2 CPU trap; the others sim_main.h's.
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <deque>
#include <memory>
#include <map>
#include <string>
#include <vector>

#include "Vboard_sim.h"
#include "Vboard_sim___024root.h"
#include "sim_main.h"
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
constexpr int RESET_CYCLES = 8;

class Board {
public:
    Board(const SimOptions &o, VerilatedContext *ctx) : opt_(o), top_(new Vboard_sim(ctx)) {
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
        div_ = top_->uart_div;
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
            if (r < 0) sim_log(opt_.quiet, "tx framing error cycle %" PRIu64, cycles_);
        }
        int status = -1;
        if (top_->stage_valid) {
            sim_log(opt_.quiet, "stage 0x%08x cycle %" PRIu64, top_->stage, cycles_);
            ready_ = true;  // the firmware's first marker (app/main.c: STAGE_SERVE, the engine serves)
        }
        if (top_->led != leds_) {
            leds_ = top_->led;
            sim_log(opt_.quiet, "leds 0x%02x cycle %" PRIu64, leds_, cycles_);
        }
        if (top_->uart_div != div_) {
            div_ = top_->uart_div;
            sim_log(opt_.quiet, "uart divisor 0x%x cycle %" PRIu64, static_cast<unsigned>(div_), cycles_);
        }
        if (top_->halt_valid) {
            sim_log(opt_.quiet, "halt 0x%08x cycle %" PRIu64, top_->halt_code, cycles_);
            status = top_->halt_code == 0 ? 0 : 1;
        }
        if (top_->trap) {
            sim_log(opt_.quiet, "trap cycle %" PRIu64 " pc 0x%08x", cycles_,
                    static_cast<unsigned>(top_->prof_fetch_pc));
            status = 2;
        }
        if (profiling_) {
            if (top_->prof_fetch) pc_ = top_->prof_fetch_pc;
            if (pc_trace_ && pc_ != traced_pc_) trace_pc(traced_pc_ = pc_);
            if (pc_trace_ && top_->stage_valid) trace_pc(traced_pc_ = PC_TRACE_FLUSH);
            if (pc_ / 2 < profile_fw_.size())
                ++profile_fw_[pc_ / 2];  // the firmware RAM: an array (a map lookup a cycle halved the rate)
            else
                ++profile_[pc_];
            if (top_->prof_ibus) ++ibus_[top_->prof_ibus_addr >> 5];
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
        if (fclose(f) != 0) return false;
        f = fopen((path + ".ibus").c_str(), "w");
        if (!f) return false;
        for (const auto &kv : ibus_) fprintf(f, "%08x %" PRIu64 "\n", kv.first << 5, kv.second);
        return fclose(f) == 0;
    }

    uint64_t cycles() const { return cycles_; }
    // The boot is over at the firmware's first SYS.STAGE write (sim_main.h runs it without a host).
    bool ready() const { return ready_; }

    // At exit: the --profile files and the PC trace; false when they cannot be written.
    bool finish() {
        bool ok = pc_trace_ok_;
        if (pc_trace_) {
            ok = fwrite(pc_buf_.data(), 4, pc_buf_.size(), pc_trace_) == pc_buf_.size() && pc_trace_ok_;
            ok = fclose(pc_trace_) == 0 && ok;
            pc_trace_ = nullptr;
        }
        if (!ok) fprintf(stderr, "wmsim: error: cannot write the PC trace '%s'\n", opt_.pc_trace.c_str());
        return (opt_.profile.empty() || write_profile(opt_.profile)) && ok;
    }

    const char *mode() const { return opt_.fast ? "fast mode" : "pin mode"; }

    // Verilator sees the firmware as a plusarg (board_sim.v loads it), and any +plusargs given.
    static std::vector<std::string> plusargs(const SimOptions &o, int argc, char **argv) {
        std::vector<std::string> v{argv[0], "+firmware=" + o.firmware};
        for (int i = 1; i < argc; ++i)
            if (argv[i][0] == '+') v.push_back(argv[i]);
        return v;
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

    const SimOptions &opt_;
    std::unique_ptr<Vboard_sim> top_;
#if VM_TRACE
    std::unique_ptr<VerilatedFstC> trace_;
    uint64_t time_ = 0;
#endif
    UartLineDriver line_out_;
    UartLineSampler line_in_;
    uint64_t cycles_ = 0;
    bool ready_ = false;  // a SYS.STAGE write seen
    uint32_t leds_ = 0;
    uint32_t div_ = 0;  // the UART divisor last logged
    bool rx_valid_ = false;
    bool profiling_ = !opt_.profile.empty();
    uint32_t pc_ = 0;
    std::map<uint32_t, uint64_t> profile_;
    std::vector<uint64_t> profile_fw_ = std::vector<uint64_t>(profiling_ ? WM_FW_RAM_ENTRIES * 2 : 0);
    struct DataBlock {
        uint64_t wait = 0, reads = 0, writes = 0;
    };
    uint64_t data_wait_ = 0;  // cycles the current data access has waited
    std::map<uint32_t, uint64_t> ibus_;
    // --pc-trace: the PCs, buffered; 0xffffffff marks a stage write (the caches' flush)
    static constexpr uint32_t PC_TRACE_FLUSH = 0xffffffffu;
    FILE *pc_trace_ = opt_.pc_trace.empty() ? nullptr : fopen(opt_.pc_trace.c_str(), "wb");
    bool pc_trace_ok_ = opt_.pc_trace.empty() || pc_trace_ != nullptr;
    uint32_t traced_pc_ = PC_TRACE_FLUSH;
    std::vector<uint32_t> pc_buf_;
    void trace_pc(uint32_t pc) {
        pc_buf_.push_back(pc);  // little-endian hosts (x86-64, arm64) write the words as the file holds them
        if (pc_buf_.size() == (1u << 16)) {
            pc_trace_ok_ = fwrite(pc_buf_.data(), 4, pc_buf_.size(), pc_trace_) == pc_buf_.size() && pc_trace_ok_;
            pc_buf_.clear();
        }
    }  // by 32-byte line: cycles instruction fetches waited
    std::map<uint32_t, DataBlock> data_;
};

}  // namespace

int main(int argc, char **argv) { return sim_main<Board>(argc, argv, SimBoardInfo{DEFAULT_PORT, true}); }
