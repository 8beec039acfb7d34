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
    size_t n = 0;
    while (n < max) {
        uint32_t data = WM_UART_DATA; /* the byte zero-extended, or EMPTY alone */
        if (data & WM_UART_DATA_EMPTY) break;
        dst[n++] = (uint8_t)data;
        if (data == stop_a || data == stop_b) break;
    }
    return n;
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
