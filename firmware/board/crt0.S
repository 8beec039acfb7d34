/*
 * wavemesh board firmware: start-up code, at the reset vector (address 0).
 *
 * Sets gp and sp, copies .data from its load image (so a CPU reset without reloading the RAM
 * starts from the initial values), clears .bss, calls main(), and halts with main's return value
 * (SYS.HALT: the simulator exits with it; on a board the CPU spins).
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

4:  call    main

    /* main returned: halt with its return value */
    li      t0, WM_SYS_HALT_ADDR
    sw      a0, 0(t0)
5:  j       5b
