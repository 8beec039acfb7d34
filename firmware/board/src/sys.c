/* wavemesh board firmware: cycle counter, timer, LEDs, halt, the stack's mark, configuration (see board.h). */
#include "board.h"

extern uint32_t __wm_tail_end[], __stack_bottom[], __stack_top[]; /* board.ld */

uint64_t board_cycles(void)
{
    uint32_t lo = WM_SYS_CYCLE_LO; /* latches the high word */
    uint32_t hi = WM_SYS_CYCLE_HI;
    return (uint64_t)hi << 32 | lo;
}

void board_timer_start(uint32_t cycles) { WM_SYS_TIMER = cycles; }

uint32_t board_timer_left(void) { return WM_SYS_TIMER; }

void board_delay_cycles(uint32_t cycles)
{
    uint32_t start = board_cycles32();
    while (board_cycles32() - start < cycles) {
        /* wait */
    }
}

void board_leds_set(uint32_t leds) { WM_SYS_LEDS = leds; }

uint32_t board_leds(void) { return WM_SYS_LEDS; }

void board_halt(uint32_t code)
{
    WM_SYS_HALT = code;
    for (;;) {
        /* a board has nowhere to go */
    }
}

void board_read_config(struct board_config *config)
{
    config->clk_hz = WM_SYS_CLK_HZ;
    config->fw_ram_bytes = WM_SYS_FW_RAM_BYTES;
    config->height_samples = WM_SYS_HEIGHT_SAMPLES;
    config->coef_entries = WM_SYS_COEF_ENTRIES;
    config->tout_entries = WM_SYS_TOUT_ENTRIES;
}

/* In .wm_tail, after .bss (board.ld): what runs between jobs moves no other code or data */
__attribute__((section(".wm_tail"))) uint32_t board_stack_bytes(void)
{
    return (uint32_t)((uintptr_t)__stack_top - (uintptr_t)__stack_bottom);
}

__attribute__((section(".wm_tail"))) uint32_t board_stack_peak(void)
{
    volatile uint32_t *w = __wm_tail_end, *sp;
    __asm__ volatile("mv %0, sp" : "=r"(sp));
    while (w < sp && *w == WM_STACK_PAINT) w++;
    uint32_t peak = (uint32_t)((uintptr_t)__stack_top - (uintptr_t)w);
    for (; w < sp; w++) *w = WM_STACK_PAINT; /* below this frame: the next job's to write */
    return peak;
}
