/*
 * wavemesh board firmware: the device program.  The protocol engine (src/proto_*.c, docs/protocol.md)
 * on the UART, with the board's job (app/board_job.c: the FPGA stage, then the refiner) behind it.
 *
 * The engine receives whole frames from the upload block (rtl/upload_rx.v: board_upload_frame, waiting
 * in chunks of at most a second, the cycle counter's 32-bit intervals): the block takes the UART's
 * bytes, checks every frame and writes DATA's samples into the height memory (WM_HEIGHT_BASE), where
 * the FPGA stage and the refiner read them, and sums their CRC for RUN; the engine reads the frame's
 * header and payload from the block and answers.  It writes with board_uart_write (payloads with
 * board_uart_write_escaped) and times itself with board_cycles.  HELLO states the built sizes (SYS and
 * ACCEL registers), the triangle capacity the heap holds (app/board_job.c, board_job_capacity: the
 * refiner's storage and the staging of the initial triangulation for the largest grid), the name
 * "wm-board" and the UART's divisor range (BAUD switches the line: io_set_divisor).
 *
 * Stage markers (SYS.STAGE, logged by the simulator): 0x00010000 the engine starts serving;
 * 0x00020000 | clock whenever another of the engine's cycle clocks starts to run (proto.h,
 * WM_PROTO_CLOCK_*: the stage 0..4, 0xFF none, 0x100 | stage inside link I/O), so the simulator's log
 * shows what each clock counted.  LEDs: 0 alive.
 */
#include <string.h>

#include "board.h"
#include "board_job.h"
#include "proto.h"
#include "wm_memmap.h"

#ifndef WM_FW_VERSION_MAJOR
#define WM_FW_VERSION_MAJOR 0
#endif
#ifndef WM_FW_VERSION_MINOR
#define WM_FW_VERSION_MINOR 0
#endif

#define STAGE_SERVE 0x00010000u
#define STAGE_CLOCK 0x00020000u
#define LED_ALIVE 1u
#define WINDOW 4u            /* DATA frames in flight (the upload block takes them at line speed) */
#define GETC_CHUNK_MS 1000u  /* longest single wait: 39 M cycles at 39 MHz, far below 2^31 */

extern uint8_t __heap_start[], __heap_end[];

static uint32_t ms_cycles;

static int io_getc(void *ctx, uint32_t timeout_ms)
{
    (void)ctx;
    if (timeout_ms == 0) { /* a byte already waiting (the engine's bursts): no cycle counter reads */
        int c = board_uart_getc();
        return c >= 0 ? c : WM_PROTO_RX_TIMEOUT;
    }
    for (;;) {
        uint32_t ms = timeout_ms > GETC_CHUNK_MS ? GETC_CHUNK_MS : timeout_ms;
        int c = board_uart_getc_timeout(ms * ms_cycles);
        if (c >= 0) return c;
        if (timeout_ms <= ms) return WM_PROTO_RX_TIMEOUT;
        timeout_ms -= ms;
    }
}

static int io_read(void *ctx, uint8_t *dst, uint32_t max)
{
    (void)ctx;
    return (int)board_uart_read(dst, max, WM_PROTO_SLIP_END, WM_PROTO_SLIP_ESC);
}

static void io_write(void *ctx, const uint8_t *data, size_t n)
{
    (void)ctx;
    board_uart_write(data, n);
}

static void io_write_escaped(void *ctx, const uint8_t *data, size_t n)
{
    (void)ctx;
    board_uart_write_escaped(data, n, WM_PROTO_SLIP_ESC, WM_PROTO_SLIP_END, WM_PROTO_SLIP_ESC_END,
                             WM_PROTO_SLIP_ESC_ESC);
}

/* BAUD: the OK has left the FIFO and the shift register, then the new divisor (from the next bit on) */
static void io_set_divisor(void *ctx, uint32_t div)
{
    (void)ctx;
    board_uart_flush();
    board_uart_set_div(div);
    board_upload_flush();
}

/* Frames whole from the upload block (rtl/upload_rx.v): the engine handles headers and replies, the
 * block the bytes, their CRC and DATA's samples (into the height memory) */
static int io_frame(void *ctx, uint32_t timeout_ms, wm_proto_frame_in *f)
{
    uint32_t status, header;
    (void)ctx;
    for (;;) {
        uint32_t ms = timeout_ms > GETC_CHUNK_MS ? GETC_CHUNK_MS : timeout_ms;
        if (board_upload_frame(ms * ms_cycles)) break;
        if (timeout_ms <= ms) return WM_PROTO_RX_TIMEOUT;
        timeout_ms -= ms;
    }
    status = WM_UPLOAD_STATUS;
    header = WM_UPLOAD_HEADER;
    f->type = (uint8_t)(header >> WM_UPLOAD_HEADER_TYPE_SHIFT);
    f->seq = (uint8_t)(header >> WM_UPLOAD_HEADER_SEQ_SHIFT);
    f->len = (uint16_t)(header >> WM_UPLOAD_HEADER_LEN_SHIFT);
    f->payload = (const uint8_t *)WM_UPLOAD_BUF_BASE;
    f->data = (status & WM_UPLOAD_STATUS_DATA) != 0;
    f->code = (uint8_t)((status & WM_UPLOAD_STATUS_CODE_MASK) >> WM_UPLOAD_STATUS_CODE_SHIFT);
    return 1;
}

static void io_upload(void *ctx, uint32_t width, uint32_t samples, uint32_t total)
{
    (void)ctx;
    board_upload_arm(width, samples, total);
}

static uint32_t io_upload_crc(void *ctx)
{
    (void)ctx;
    return WM_UPLOAD_CRC;
}

static uint64_t io_cycles(void *ctx)
{
    (void)ctx;
    return board_cycles();
}

/* DONE.stack_peak and stack_bytes (include/proto.h, WM_PROTO_STACK; between jobs: board.ld's .wm_tail) */
__attribute__((section(".wm_tail"))) uint32_t wm_proto_stack_peak(uint32_t *stack_bytes)
{
    *stack_bytes = board_stack_bytes();
    return board_stack_peak();
}

/* Another clock starts: its marker (the stage sync) always, the caches' flush only where a stage's or
 * no clock starts.  The link's clock (WM_PROTO_CLOCK_LINK) counts what the host's timing and the frame
 * numbers move anyway, and no check compares it between runs; the stage's stretch after it starts with
 * the flush again (docs/soc.md, "Cycle accounting").  Each frame the emit stage sends switches to the
 * link and back: one flush a frame, not two. */
static void io_mark(void *ctx, uint32_t clock)
{
    (void)ctx;
    if (clock & WM_PROTO_CLOCK_LINK) board_stage_sync(STAGE_CLOCK | clock);
    else board_stage(STAGE_CLOCK | clock);
}

int main(void)
{
    static wm_proto eng;
    struct board_config config;
    wm_proto_caps caps;
    wm_proto_io io;
    uint32_t max_w, max_h;

    board_leds_set(LED_ALIVE);
    board_read_config(&config);
    ms_cycles = config.clk_hz / 1000u;
    max_w = WM_ACCEL_MAX_WIDTH < WM_GRID_MAX_W ? WM_ACCEL_MAX_WIDTH : WM_GRID_MAX_W;
    max_h = WM_ACCEL_MAX_HEIGHT < WM_GRID_MAX_H ? WM_ACCEL_MAX_HEIGHT : WM_GRID_MAX_H;

    memset(&caps, 0, sizeof caps);
    memcpy(caps.name, "wm-board", 8);
    caps.fw_major = WM_FW_VERSION_MAJOR;
    caps.fw_minor = WM_FW_VERSION_MINOR;
    caps.max_width = (uint16_t)max_w;
    caps.max_height = (uint16_t)max_h;
    caps.max_samples = config.height_samples;
    caps.tri_capacity = board_job_capacity(board_heap_bytes(), (int32_t)max_w, (int32_t)max_h);
    caps.max_levels =
        (uint8_t)(WM_ACCEL_MAX_LEVELS < WM_PROTO_MAX_LEVELS ? WM_ACCEL_MAX_LEVELS : WM_PROTO_MAX_LEVELS);
    caps.window = WINDOW;
    caps.max_payload = WM_PROTO_MAX_PAYLOAD;
    caps.clk_hz = config.clk_hz;
    /* the rate the divisor gives, rounded to a whole baud as after a switch (protocol.divisor_baud) */
    caps.baud = (config.clk_hz + board_uart_div() / 2u) / board_uart_div();
    caps.features = WM_PROTO_FEATURE_INITIAL_ONLY | WM_PROTO_FEATURE_HOLES | WM_PROTO_FEATURE_RICE;
    caps.div = board_uart_div(); /* BAUD: any divisor the UART takes (memmap.py, UART.DIV) */
    caps.div_min = WM_UART_DIV_MIN;
    caps.div_max = WM_UART_DIV_MASK;
    /* the upload block takes the bytes at line speed but for the frame the engine is answering (some 2 k
     * cycles for a DATA frame): the RX FIFO's 64 bytes (8.3 k cycles at 3 Mbaud, 39 MHz) absorb the
     * next frame's meanwhile, so frames may come back to back at every rate */
    caps.switched_window = WINDOW;
    /* the upload block decodes CODING_RICE samples as fast as it stores raw ones: coded at every rate */
    caps.rice_min_div = 0;

    io.ctx = NULL;
    io.getc = io_getc;
    io.read = io_read;
    io.write = io_write;
    io.write_escaped = io_write_escaped;
    io.cycles = io_cycles;
    io.mark = io_mark;
    io.set_divisor = io_set_divisor;
    io.frame = io_frame;
    io.upload = io_upload;
    io.upload_crc = io_upload_crc;
    board_upload_enable(WM_PROTO_BYTE_TIMEOUT_MS * ms_cycles);

    board_stage(STAGE_SERVE);
    for (;;) {
        wm_proto_init(&eng, &io, &caps, (uint16_t *)WM_HEIGHT_BASE, board_job, NULL);
        wm_proto_set_mask(&eng, board_mask(), board_mask_bytes());
        wm_proto_serve(&eng);
    }
}
