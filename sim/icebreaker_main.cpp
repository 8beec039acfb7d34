// wavemesh simulated iCEBreaker: the Verilator model of rtl/boards/icebreaker_top.v (the FPGA stage
// alone behind its UART) with the UART bridged to TCP, as wmsim bridges the simulated ULX3S.
//
//   wmsim-icebreaker [--port N] [--exit-on-close] [--max-cycles N] [--quiet]
//
// A host talks to it as to the board: pyserial's serial_for_url("socket://127.0.0.1:N") (wavemesh
// stream, wavemesh devices).  Bytes from the client are driven onto the RX pin bit by bit at the
// stage's divisor and the TX pin is sampled back into bytes (there is no fast mode: the stage has no
// FIFO port to bypass to, and it is small enough to simulate at a few MHz).  The options, the socket
// loop and the common lines are sim_main.h's (one main for both simulators).
//
// This board's lines on stdout, beside sim_main.h's:
//   wmsim: leds 0xVALUE cycle N               (bit 0 the red LED, a job runs; bit 1 the green, an
//                                              RX overrun; 1 = lit)
#include <cinttypes>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "Vicebreaker_sim.h"
#include "sim_main.h"
#include "uart_line.h"
#include "verilated.h"

namespace {

constexpr int DEFAULT_PORT = 7722;

class Board {
public:
    Board(const SimOptions &o, VerilatedContext *ctx) : opt_(o), top_(new Vicebreaker_sim(ctx)) {
        top_->clk = 0;
        top_->btn_n = 1;  // the power-on reset does the rest
        top_->rxd = 1;
        top_->eval();
    }

    ~Board() { top_->final(); }

    int cycle(TcpBridge *bridge) {
        if (bridge && !line_out_.busy() && !bridge->rx.empty()) {
            line_out_.start(bridge->rx.front(), top_->uart_div);
            bridge->rx.pop_front();
        }
        top_->rxd = line_out_.step();
        top_->clk = 0;
        top_->eval();
        uint8_t byte;
        int r = line_in_.step(top_->txd, top_->uart_div, &byte);
        if (r > 0 && bridge) bridge->tx.push_back(static_cast<char>(byte));
        if (r < 0) sim_log(opt_.quiet, "tx framing error cycle %" PRIu64, cycles_);
        unsigned now = (top_->ledr_n ? 0u : 1u) | (top_->ledg_n ? 0u : 2u);
        if (now != leds_) {
            leds_ = now;
            sim_log(opt_.quiet, "leds 0x%02x cycle %" PRIu64, leds_, cycles_);
        }
        top_->clk = 1;
        top_->eval();
        ++cycles_;
        return -1;
    }

    uint64_t cycles() const { return cycles_; }
    bool ready() const { return true; }  // no firmware: it waits for its host from cycle 0
    bool finish() { return true; }
    const char *mode() const { return "iCEBreaker, pin mode"; }
    static std::vector<std::string> plusargs(const SimOptions &, int argc, char **argv) {
        return std::vector<std::string>(argv, argv + argc);
    }

private:
    const SimOptions &opt_;
    std::unique_ptr<Vicebreaker_sim> top_;
    UartLineDriver line_out_;
    UartLineSampler line_in_;
    uint64_t cycles_ = 0;
    unsigned leds_ = 0;
};

}  // namespace

int main(int argc, char **argv) { return sim_main<Board>(argc, argv, SimBoardInfo{DEFAULT_PORT, false}); }
