/*
 * wavemesh board firmware: drivers for the SoC's peripherals (UART, cycle counter, timer, LEDs,
 * stage markers, halt) and a CRC-32.
 *
 * Every public symbol starts with board_.  Registers and sizes come from the generated
 * wm_memmap.h (host/wavemesh/device/memmap.py); docs/soc.md has the register tables.  Nothing here
 * allocates memory or uses interrupts; every wait that depends on the outside world has a timeout.
 */
#ifndef BOARD_H
#define BOARD_H

#include <stddef.h>
#include <stdint.h>

#include "wm_memmap.h"

/* ---- UART ------------------------------------------------------------------------------------ */

/*
 * Set the baud divisor (clock cycles per bit; the hardware raises values below WM_UART_DIV_MIN).
 * Applies from the next bit, on both directions: wait for board_uart_flush() first.
 */
void board_uart_set_div(uint32_t div);

/* The current baud divisor. */
uint32_t board_uart_div(void);

/* Queue one byte; waits while the TX FIFO is full (it always drains: no timeout needed). */
void board_uart_putc(uint8_t byte);

/* Queue n bytes: waits until the TX FIFO is empty, then fills it (no status read per byte). */
void board_uart_write(const void *data, size_t n);

/*
 * Queue n bytes escaped: a byte equal to a is sent as esc then a_sub, one equal to esc as
 * esc then esc_sub (SLIP's escaping, RFC 1055); an empty TX FIFO takes half its depth of input at once.
 */
void board_uart_write_escaped(const void *data, size_t n, uint8_t esc, uint8_t a, uint8_t a_sub, uint8_t esc_sub);

/* Wait until the TX FIFO is empty and the last stop bit has been sent. */
void board_uart_flush(void);

/* The oldest received byte, or -1 when none is waiting.  Never waits. */
int board_uart_getc(void);

/*
 * The received bytes already waiting, at most max, into dst, up to and including the first that is
 * stop_a or stop_b (a delimiter the caller handles itself); their number.  Never waits.
 */
size_t board_uart_read(uint8_t *dst, size_t max, uint8_t stop_a, uint8_t stop_b);

/*
 * The oldest received byte, waiting up to `cycles` clock cycles (< 2^31) for one; -1 on timeout.
 */
int board_uart_getc_timeout(uint32_t cycles);

/* Read and clear the sticky error bits (WM_UART_STATUS_RX_OVERRUN, _RX_FRAME_ERR, _TX_OVERRUN). */
uint32_t board_uart_take_errors(void);

/* ---- the upload block (UPLOAD registers, rtl/upload_rx.v) ------------------------------------- */

/*
 * Hand the UART's received bytes to the upload block: it deframes and checks every frame itself and
 * drops a frame with no byte for timeout_cycles.  UART DATA reads then read EMPTY.
 */
void board_upload_enable(uint32_t timeout_cycles);

/*
 * Release the frame held (if any), then wait up to `cycles` for the next good one: 1 when one is
 * held (UPLOAD.STATUS, HEADER and the payload at WM_UPLOAD_BUF_BASE describe it), 0 when none came.
 */
int board_upload_frame(uint32_t cycles);

/*
 * From the next frame on, store the samples of DATA frames of a session of width W, W H samples and
 * total words (a new session: nothing stored), or, with samples 0, store none.
 */
void board_upload_arm(uint32_t width, uint32_t samples, uint32_t total);

/* Drop a frame half received (the line's rate changed); uncounted. */
void board_upload_flush(void);

/* ---- the CPU's caches ------------------------------------------------------------------------- */

/*
 * Make the CPU's next loads read the memory: the VexRiscv's data cache (write through) does not see
 * what the FPGA stage writes into the SDRAM, so the job flushes it after the stage (its custom
 * instruction 0x500F: every line invalid).  The PicoRV32 has no caches: nothing to do.
 */
static inline void board_dcache_flush(void)
{
#ifdef WM_CPU_VEXRISCV
    __asm__ volatile(".word 0x500F" ::: "memory");
#endif
}

/*
 * Empty the CPU's instruction and data caches (the VexRiscv's: fence.i, as its configuration reports
 * it, and 0x500F), so that the cycles of what follows do not depend on what ran before (board_stage).
 */
static inline void board_caches_flush(void)
{
#ifdef WM_CPU_VEXRISCV
    __asm__ volatile(".word 0x500F\n\t.word 0x100F\n\tnop\n\tnop\n\tnop" ::: "memory");
#endif
}

/* ---- cycles and timer ------------------------------------------------------------------------ */

/* Clock cycles since reset (64-bit counter read consistently: CYCLE_LO latches CYCLE_HI). */
uint64_t board_cycles(void);

/* The low 32 bits of the cycle counter (one load; for intervals below 2^31 cycles). */
static inline uint32_t board_cycles32(void) { return WM_SYS_CYCLE_LO; }

/* Load the down-counter with `cycles`; board_timer_left() reaches 0 that many cycles later. */
void board_timer_start(uint32_t cycles);

/* Cycles left on the down-counter (0: expired). */
uint32_t board_timer_left(void);

/* Busy-wait `cycles` clock cycles (uses the cycle counter, not the timer). */
void board_delay_cycles(uint32_t cycles);

/* ---- LEDs, stage markers, halt ---------------------------------------------------------------- */

/* Set the LED outputs (bit i = LED i, 1 = on). */
void board_leds_set(uint32_t leds);

/* The LED outputs as last set. */
uint32_t board_leds(void);

/*
 * A stage marker that leaves the caches as they are: the simulator's log and the stage sync as
 * board_stage's, without the flush, for a stretch whose cycles no check compares between runs (the
 * link I/O's, app/main.c's io_mark: the stage's stretch after it starts with board_stage's flush).
 */
static inline void board_stage_sync(uint32_t marker) { WM_SYS_STAGE = marker; }

/*
 * Mark the start or end of a stage: the simulator logs `stage 0xMARKER cycle N`; on a board it
 * costs one store (the stage sync: docs/soc.md, "Cycle accounting"), and with the VexRiscv the
 * flush of its caches, so that the next stretch starts from the same state whatever ran before.
 */
static inline void board_stage(uint32_t marker)
{
    board_stage_sync(marker);
    board_caches_flush();
}

/* Halt with an exit code: the simulator exits (status 0 for code 0); on a board the CPU spins. */
void board_halt(uint32_t code) __attribute__((noreturn));

/* ---- the stack ------------------------------------------------------------------------------- */

/* The stack's reserve in bytes (board.ld: memmap.STACK_BYTES, or a test build's WM_STACK_BYTES). */
uint32_t board_stack_bytes(void);

/*
 * The stack's high-water mark: bytes from its top (__stack_top) to the deepest word that is no longer
 * crt0's paint (WM_STACK_PAINT), searched from the end of the image (board.ld's __wm_tail_end) up, since
 * start-up or the previous call; then every word below the caller's frame painted again, so the next call
 * measures from here.  Above board_stack_bytes(): the stack overflowed its reserve into the free RAM (or
 * further: from the image's end on, the mark is at least the reserve and the free RAM).  A word written with the paint's value, or
 * a frame's bytes never written, look unused: the mark is the deepest word written.  A loop of a load
 * and a compare a word over the painted RAM (up to 25 KB: some 60 k cycles), run between jobs.
 */
uint32_t board_stack_peak(void);

/* ---- configuration ---------------------------------------------------------------------------- */

/* The sizes the hardware was built with (SYS block read-only registers). */
struct board_config {
    uint32_t clk_hz;          /* system clock */
    uint32_t fw_ram_bytes;    /* firmware RAM */
    uint32_t height_samples;  /* height memory, 16-bit samples */
    uint32_t coef_entries;    /* coefficient memory, 18-bit entries */
    uint32_t tout_entries;    /* template output memory, 16-bit entries */
};

/* Read the configuration registers into *config. */
void board_read_config(struct board_config *config);

/* The height memory as an array of samples (row-major, W per row). */
#define BOARD_HEIGHTS ((volatile uint16_t *)WM_HEIGHT_BASE)

#endif /* BOARD_H */
