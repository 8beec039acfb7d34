// wavemesh simulated board: the host's end of the UART line (see uart_line.h).
#include "uart_line.h"

void UartLineDriver::start(uint8_t byte, uint32_t div) {
    frame_ = static_cast<uint16_t>((1u << 9) | (static_cast<uint32_t>(byte) << 1));  // stop, data, start
    div_ = div ? div : 1;
    bit_ = 0;
    left_ = div_;
}

int UartLineDriver::step() {
    if (bit_ < 0) return 1;  // idle line
    int level = (frame_ >> bit_) & 1;
    if (--left_ == 0) {
        // next bit, or the end of the stop bit
        if (++bit_ > 9) {
            bit_ = -1;
        } else {
            left_ = div_;
        }
    }
    return level;
}

int UartLineSampler::step(int txd, uint32_t div, uint8_t *byte) {
    int result = 0;
    if (bit_ < 0) {
        if (prev_ == 1 && txd == 0) {
            // falling edge: sample the start bit in its middle
            div_ = div ? div : 1;
            bit_ = 0;
            left_ = div_ / 2;
        }
    } else if (left_ == 0 || --left_ == 0) {
        if (bit_ == 0) {
            // start bit: a glitch when it is high again
            bit_ = txd == 0 ? 1 : -1;
            data_ = 0;
        } else if (bit_ <= 8) {
            // data bit, LSB first
            data_ = static_cast<uint8_t>(data_ | (txd << (bit_ - 1)));
            ++bit_;
        } else {
            // stop bit
            if (txd == 1) {
                *byte = data_;
                result = 1;
            } else {
                result = -1;
            }
            bit_ = -1;
        }
        left_ = div_;
    }
    prev_ = txd;
    return result;
}
