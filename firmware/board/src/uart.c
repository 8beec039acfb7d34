/* wavemesh board firmware: UART driver (see board.h). */
#include "board.h"

void board_uart_set_div(uint32_t div) { WM_UART_DIV = div & WM_UART_DIV_MASK; }

uint32_t board_uart_div(void) { return WM_UART_DIV & WM_UART_DIV_MASK; }

void board_uart_putc(uint8_t byte)
{
    while (WM_UART_STATUS & WM_UART_STATUS_TX_FULL) {
        /* the transmitter empties the FIFO at the baud rate */
    }
    WM_UART_DATA = byte;
}

void board_uart_write(const void *data, size_t n)
{
    const uint8_t *p = data, *end = p + n;
    while (p < end) {
        /* an empty FIFO takes WM_UART_TX_DEPTH bytes without a look at the status between them (the
         * line still sends the last byte meanwhile: at 115200 baud a byte time is far longer than the
         * refill) */
        const uint8_t *stop = (size_t)(end - p) > WM_UART_TX_DEPTH ? p + WM_UART_TX_DEPTH : end;
        while (!(WM_UART_STATUS & WM_UART_STATUS_TX_EMPTY)) {
            /* the transmitter empties the FIFO at the baud rate */
        }
        while (p < stop) WM_UART_DATA = *p++;
    }
}

void board_uart_write_escaped(const void *data, size_t n, uint8_t esc, uint8_t a, uint8_t a_sub, uint8_t esc_sub)
{
    const uint8_t *p = data, *end = p + n;
    while (p < end) {
        /* half the FIFO's depth a fill: each byte takes at most two places */
        const uint8_t *stop = (size_t)(end - p) > WM_UART_TX_DEPTH / 2 ? p + WM_UART_TX_DEPTH / 2 : end;
        while (!(WM_UART_STATUS & WM_UART_STATUS_TX_EMPTY)) {
            /* the transmitter empties the FIFO at the baud rate */
        }
        for (; p < stop; p++) {
            uint32_t c = *p;
            if (c == a) {
                WM_UART_DATA = esc;
                c = a_sub;
            } else if (c == esc) {
                WM_UART_DATA = esc;
                c = esc_sub;
            }
            WM_UART_DATA = c;
        }
    }
}

void board_uart_flush(void)
{
    while (!(WM_UART_STATUS & WM_UART_STATUS_TX_IDLE)) {
        /* the last frame is still on the line */
    }
}

int board_uart_getc(void)
{
    uint32_t data = WM_UART_DATA;
    return (data & WM_UART_DATA_EMPTY) ? -1 : (int)(data & WM_UART_DATA_BYTE_MASK);
}

size_t board_uart_read(uint8_t *dst, size_t max, uint8_t stop_a, uint8_t stop_b)
{
    /* as many as the FIFO holds now, four to a step: no EMPTY test per byte */
    uint32_t have = (WM_UART_STATUS & WM_UART_STATUS_RX_COUNT_MASK) >> WM_UART_STATUS_RX_COUNT_SHIFT;
    uint8_t *p = dst, *end = dst + (have < max ? have : max);
    uint32_t c;
#define TAKE(k)                                                              \
    do {                                                                     \
        c = WM_UART_DATA;                                                    \
        p[k] = (uint8_t)c;                                                   \
        if (c == stop_a || c == stop_b) return (size_t)(p - dst) + (k) + 1u; \
    } while (0)
    for (; end - p >= 4; p += 4) {
        TAKE(0);
        TAKE(1);
        TAKE(2);
        TAKE(3);
    }
    for (; p < end; p++) TAKE(0);
#undef TAKE
    return (size_t)(p - dst);
}

int board_uart_getc_timeout(uint32_t cycles)
{
    uint32_t start = board_cycles32();
    for (;;) {
        uint32_t data = WM_UART_DATA;
        if (!(data & WM_UART_DATA_EMPTY)) return (int)(data & WM_UART_DATA_BYTE_MASK);
        if (board_cycles32() - start >= cycles) return -1;
    }
}

uint32_t board_uart_take_errors(void)
{
    const uint32_t sticky = WM_UART_STATUS_RX_OVERRUN | WM_UART_STATUS_RX_FRAME_ERR | WM_UART_STATUS_TX_OVERRUN;
    uint32_t errors = WM_UART_STATUS & sticky;
    WM_UART_STATUS = errors; /* write 1 to clear */
    return errors;
}

/* the upload block: CTRL's ENABLE and ARM as last written (CLEAR, FLUSH and RELEASE are pulses) */
static uint32_t upload_ctrl;
static int upload_held;

void board_upload_enable(uint32_t timeout_cycles)
{
    WM_UPLOAD_TIMEOUT = timeout_cycles;
    upload_ctrl = WM_UPLOAD_CTRL_ENABLE;
    WM_UPLOAD_CTRL = upload_ctrl;
    upload_held = 0;
}

int board_upload_frame(uint32_t cycles)
{
    uint32_t start;
    if (upload_held) {
        WM_UPLOAD_CTRL = upload_ctrl | WM_UPLOAD_CTRL_RELEASE;
        upload_held = 0;
    }
    start = board_cycles32();
    for (;;) {
        if (WM_UPLOAD_STATUS & WM_UPLOAD_STATUS_FRAME) {
            upload_held = 1;
            return 1;
        }
        if (board_cycles32() - start >= cycles) return 0;
    }
}

void board_upload_arm(uint32_t width, uint32_t samples, uint32_t total)
{
    if (samples) {
        WM_UPLOAD_WIDTH = width;
        WM_UPLOAD_SAMPLES = samples;
        WM_UPLOAD_TOTAL = total;
        upload_ctrl = WM_UPLOAD_CTRL_ENABLE | WM_UPLOAD_CTRL_ARM;
        WM_UPLOAD_CTRL = upload_ctrl | WM_UPLOAD_CTRL_CLEAR;
    } else {
        upload_ctrl = WM_UPLOAD_CTRL_ENABLE;
        WM_UPLOAD_CTRL = upload_ctrl;
    }
}

void board_upload_flush(void) { WM_UPLOAD_CTRL = upload_ctrl | WM_UPLOAD_CTRL_FLUSH; }
