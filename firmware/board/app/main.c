/*
 * wavemesh board firmware: the minimal device program (the stand-in exchange of docs/soc.md).
 *
 * HELLO returns the device's capabilities; LOAD stores W x H 16-bit samples in the height memory
 * and answers with their CRC-32 and the cycles spent; READ returns a range of the height memory.
 * Frames (byte tables in docs/soc.md, host side in host/wavemesh/board.py):
 *
 *   request   'W' 'M' cmd arg0[4] arg1[4] check          check = 0xEF ^ cmd ^ arg bytes
 *   response  'W' 'M' cmd|0x80 status len[4] payload[len] crc[4]
 *                                                      crc = CRC-32 of cmd|0x80 .. payload
 *
 * Nothing the host sends can hang the device: after the 'W' 'M' of a request every byte must
 * arrive within RX_TIMEOUT (a tenth of a second), otherwise the device answers TIMEOUT and goes
 * back to looking for 'W' 'M'; a bad check byte, an unknown command or an argument out of range
 * gets an error answer at once, before any data is expected.
 */
#include "board.h"

#define LINK_MAGIC0 0x57u /* 'W' */
#define LINK_MAGIC1 0x4Du /* 'M' */
#define LINK_CHECK_SEED 0xEFu
#define LINK_RESPONSE 0x80u
#define LINK_HEADER_REST 10u /* request bytes after the magic */
#define PROTOCOL_VERSION 1u

enum link_cmd { CMD_HELLO = 0x01, CMD_LOAD = 0x02, CMD_READ = 0x03 };
enum link_status { ST_OK = 0, ST_BAD_CHECK = 1, ST_BAD_CMD = 2, ST_BAD_ARG = 3, ST_TIMEOUT = 4 };

/* Stage markers (SYS.STAGE): command << 16 | step. */
#define STAGE_LOAD_RECEIVE 0x00020001u /* first sample expected */
#define STAGE_LOAD_CRC 0x00020002u     /* all samples stored, CRC starts */
#define STAGE_LOAD_DONE 0x00020003u    /* CRC done */

/* LEDs: 0 alive, 1 toggles per request, 2 the last request failed. */
#define LED_ALIVE 1u
#define LED_ACTIVITY 2u
#define LED_ERROR 4u

#define HELLO_BYTES 40u
#define LOAD_RESULT_BYTES 24u

static struct board_config config;
static uint32_t rx_timeout; /* cycles one byte of a request may take */

static void put_le16(uint8_t *p, uint32_t v) {
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static void put_le32(uint8_t *p, uint32_t v) {
    put_le16(p, v);
    put_le16(p + 2, v >> 16);
}

static void put_le64(uint8_t *p, uint64_t v) {
    put_le32(p, (uint32_t)v);
    put_le32(p + 4, (uint32_t)(v >> 32));
}

static uint32_t get_le32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* Response: magic, then cmd|0x80, status, length; returns the CRC so far. */
static uint32_t respond_begin(uint8_t cmd, uint8_t status, uint32_t len) {
    uint8_t head[8] = {LINK_MAGIC0, LINK_MAGIC1, (uint8_t)(cmd | LINK_RESPONSE), status};
    put_le32(head + 4, len);
    board_uart_write(head, sizeof head);
    return board_crc32(0, head + 2, sizeof head - 2);
}

static uint32_t respond_data(uint32_t crc, const void *data, uint32_t n) {
    board_uart_write(data, n);
    return board_crc32(crc, data, n);
}

static void respond_end(uint32_t crc) {
    uint8_t tail[4];
    put_le32(tail, crc);
    board_uart_write(tail, sizeof tail);
}

static void respond(uint8_t cmd, uint8_t status, const void *payload, uint32_t len) {
    uint32_t crc = respond_begin(cmd, status, len);
    if (len) crc = respond_data(crc, payload, len);
    respond_end(crc);
    board_leds_set((board_leds() ^ LED_ACTIVITY) & ~LED_ERROR);
    if (status != ST_OK) board_leds_set(board_leds() | LED_ERROR);
}

static void do_hello(uint32_t arg0, uint32_t arg1) {
    if (arg0 != 0 || arg1 != 0) {
        respond(CMD_HELLO, ST_BAD_ARG, 0, 0);
        return;
    }
    uint8_t p[HELLO_BYTES];
    put_le16(p + 0, PROTOCOL_VERSION);
    p[2] = WM_FW_VERSION_MAJOR;
    p[3] = WM_FW_VERSION_MINOR;
    put_le16(p + 4, WM_GRID_MAX_W);
    put_le16(p + 6, WM_GRID_MAX_H);
    put_le32(p + 8, config.clk_hz);
    put_le32(p + 12, config.fw_ram_bytes);
    put_le32(p + 16, config.height_samples);
    put_le32(p + 20, config.coef_entries);
    put_le32(p + 24, config.tout_entries);
    put_le32(p + 28, WM_TRI_CAPACITY);
    put_le32(p + 32, board_uart_div());
    put_le32(p + 36, rx_timeout);
    respond(CMD_HELLO, ST_OK, p, sizeof p);
}

static void do_load(uint32_t w, uint32_t h) {
    if (w < 2 || w > WM_GRID_MAX_W || h < 2 || h > WM_GRID_MAX_H || w * h > config.height_samples) {
        respond(CMD_LOAD, ST_BAD_ARG, 0, 0);
        return;
    }
    uint32_t n = w * h;
    respond(CMD_LOAD, ST_OK, 0, 0); /* ready: send the samples */

    board_stage(STAGE_LOAD_RECEIVE);
    uint64_t t0 = board_cycles();
    volatile uint16_t *heights = BOARD_HEIGHTS;
    for (uint32_t i = 0; i < n; i++) {
        int lo = board_uart_getc_timeout(rx_timeout);
        int hi = lo < 0 ? -1 : board_uart_getc_timeout(rx_timeout);
        if (hi < 0) {
            /* the host stopped sending: say how many samples arrived */
            uint8_t p[4];
            put_le32(p, i);
            respond(CMD_LOAD, ST_TIMEOUT, p, sizeof p);
            return;
        }
        heights[i] = (uint16_t)((uint32_t)lo | (uint32_t)hi << 8);
    }
    uint64_t receive_cycles = board_cycles() - t0;

    /* what was stored, read back from the height memory (little-endian samples) */
    board_stage(STAGE_LOAD_CRC);
    uint64_t t1 = board_cycles();
    uint32_t crc = board_crc32(0, (const void *)(uintptr_t)WM_HEIGHT_BASE, 2 * n);
    uint64_t crc_cycles = board_cycles() - t1;
    board_stage(STAGE_LOAD_DONE);

    uint8_t p[LOAD_RESULT_BYTES];
    put_le32(p + 0, crc);
    put_le32(p + 4, n);
    put_le64(p + 8, crc_cycles);
    put_le64(p + 16, receive_cycles);
    respond(CMD_LOAD, ST_OK, p, sizeof p);
}

static void do_read(uint32_t first, uint32_t count) {
    if (count < 1 || count > config.height_samples || first > config.height_samples - count) {
        respond(CMD_READ, ST_BAD_ARG, 0, 0);
        return;
    }
    uint32_t crc = respond_begin(CMD_READ, ST_OK, 2 * count);
    crc = respond_data(crc, (const void *)(uintptr_t)(WM_HEIGHT_BASE + 2 * first), 2 * count);
    respond_end(crc);
    board_leds_set((board_leds() ^ LED_ACTIVITY) & ~LED_ERROR);
}

/* Read the rest of a request after its magic; false (and a TIMEOUT answer) if it stops. */
static int read_request(uint8_t req[LINK_HEADER_REST]) {
    for (uint32_t i = 0; i < LINK_HEADER_REST; i++) {
        int c = board_uart_getc_timeout(rx_timeout);
        if (c < 0) {
            respond(i ? req[0] : 0, ST_TIMEOUT, 0, 0);
            return 0;
        }
        req[i] = (uint8_t)c;
    }
    return 1;
}

int main(void) {
    board_read_config(&config);
    rx_timeout = config.clk_hz / 10;
    board_leds_set(LED_ALIVE);

    for (;;) {
        /* idle: look for the magic */
        int c = board_uart_getc();
        if (c != (int)LINK_MAGIC0) continue;
        do {
            c = board_uart_getc_timeout(rx_timeout);
        } while (c == (int)LINK_MAGIC0);
        if (c != (int)LINK_MAGIC1) continue; /* not a request (or a lone 'W'): keep looking */

        uint8_t req[LINK_HEADER_REST];
        if (!read_request(req)) continue;
        uint8_t check = LINK_CHECK_SEED;
        for (uint32_t i = 0; i < LINK_HEADER_REST - 1; i++) check ^= req[i];
        uint8_t cmd = req[0];
        if (check != req[LINK_HEADER_REST - 1]) {
            respond(cmd, ST_BAD_CHECK, 0, 0);
            continue;
        }
        uint32_t arg0 = get_le32(req + 1);
        uint32_t arg1 = get_le32(req + 5);
        switch (cmd) {
        case CMD_HELLO:
            do_hello(arg0, arg1);
            break;
        case CMD_LOAD:
            do_load(arg0, arg1);
            break;
        case CMD_READ:
            do_read(arg0, arg1);
            break;
        default:
            respond(cmd, ST_BAD_CMD, 0, 0);
            break;
        }
    }
}
