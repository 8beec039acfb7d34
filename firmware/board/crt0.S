/*
 * wavemesh board firmware: start-up code, at the reset vector (address 0).
 *
 * Sets gp and sp, copies .data from its load image (so a CPU reset without reloading the RAM
 * starts from the initial values), clears .bss, paints the free RAM and the stack (board_start, below),
 * calls main(), and halts with main's return value (SYS.HALT: the simulator exits with it; on a board
 * the CPU spins).
 */
#include "wm_memmap.h"

    .section .text.start, "ax"
    .globl _start
_start:
    .option push
    .option norelax
    la      gp, __global_pointer$
    .option pop
    la      sp, __stack_top

    /* copy .data from __data_load */
    la      a0, __data_load
    la      a1, __data_start
    la      a2, __data_end
1:  bgeu    a1, a2, 2f
    lw      t0, 0(a0)
    sw      t0, 0(a1)
    addi    a0, a0, 4
    addi    a1, a1, 4
    j       1b

    /* clear .bss */
2:  la      a1, __bss_start
    la      a2, __bss_end
3:  bgeu    a1, a2, 4f
    sw      zero, 0(a1)
    addi    a1, a1, 4
    j       3b

4:  call    board_start

    /* main returned: halt with its return value */
    li      t0, WM_SYS_HALT_ADDR
    sw      a0, 0(t0)
5:  j       5b

/*
 * board_start: every word from __wm_tail_end to __stack_top (the free RAM below the stack's reserve and
 * the reserve itself; nothing is on the stack yet) set to WM_STACK_PAINT, then main (returning to
 * _start's halt).  The deepest word no longer painted is the stack's high-water mark (src/sys.c,
 * board_stack_peak).  In .wm_tail, after .bss (board.ld): _start's call is as long as a call of main,
 * so the paint moves no other code or data.
 */
    .section .wm_tail, "ax"
    .globl board_start
board_start:
    li      t0, WM_STACK_PAINT
    la      a1, __wm_tail_end
    la      a2, __stack_top
6:  bgeu    a1, a2, 7f
    sw      t0, 0(a1)
    addi    a1, a1, 4
    j       6b
7:  tail    main
