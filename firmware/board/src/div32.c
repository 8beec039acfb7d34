/* 32-bit division for the board's refiner (rv32): the compiler's __divsi3, __udivsi3, __modsi3 and
 * __umodsi3, linked before libgcc's, each the CPU's own division instruction.
 *
 * GCC 12 for rv32 emits a division instruction for every division, also by a constant: the
 * half-edge's triangle h / 3 and corner h % 3 (wm_internal.h's WM_TRI, the rotations) are one of the
 * CPU's some 33-cycle divisions each, where a multiply-high and two or three more instructions give the
 * same integer.  It keeps those sequences for -mno-div, and makes every other division a call of the
 * routines below: so the refiner (wm_refiner, firmware/board/CMakeLists.txt) is built with -mno-div and
 * this file without it, each routine the division instruction and a return (a call's few cycles more
 * than the instruction inline).  The results are the C operators' (truncated; a zero divisor is the
 * caller's error, as with libgcc's, and gives the instruction's answer). */

int __divsi3(int a, int b);
unsigned __udivsi3(unsigned a, unsigned b);
int __modsi3(int a, int b);
unsigned __umodsi3(unsigned a, unsigned b);

int __divsi3(int a, int b) { return a / b; }
unsigned __udivsi3(unsigned a, unsigned b) { return a / b; }
int __modsi3(int a, int b) { return a % b; }
unsigned __umodsi3(unsigned a, unsigned b) { return a % b; }
