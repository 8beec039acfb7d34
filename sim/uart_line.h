// wavemesh simulated board: the host's end of the UART line, bit by bit (pin-accurate mode).
//
// UartLineDriver turns bytes into 8N1 frames on the board's RX pin; UartLineSampler turns the
// board's TX pin back into bytes.  Both take the bit time in clock cycles from the board's current
// divisor at the start of each frame, as a host set to the same baud rate would.  Call step() once
// per clock cycle.
#pragma once

#include <cstdint>

class UartLineDriver {
public:
    // True while a frame is on the line.
    bool busy() const { return bit_ >= 0; }
    // Start sending a byte (only when !busy()).
    void start(uint8_t byte, uint32_t div);
    // The RX pin level for this cycle; advances one cycle.
    int step();

private:
    uint16_t frame_ = 0;    // start bit, 8 data bits, stop bit; LSB first
    int bit_ = -1;          // bit on the line, -1 when idle
    uint32_t left_ = 0;     // cycles left in this bit
    uint32_t div_ = 1;
};

class UartLineSampler {
public:
    // Feed this cycle's TX pin level; returns 1 with *byte set when a frame completes, -1 on a
    // framing error (stop bit 0), 0 otherwise.
    int step(int txd, uint32_t div, uint8_t *byte);

private:
    int prev_ = 1;
    int bit_ = -1;          // -1 idle, 0 start, 1..8 data, 9 stop
    uint32_t left_ = 0;     // cycles to the next sample point
    uint32_t div_ = 1;
    uint8_t data_ = 0;
};
