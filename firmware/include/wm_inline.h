/* Inlining (GCC, Clang; other compilers choose for themselves), the three kinds the firmware's sources ask
 * for: the refiner's (src/, through wm_internal.h) and the board's (board/src: div64.c, proto_emit.c).
 * WM_ALWAYS_INLINE: inlined wherever it is called, also where the compiler would not choose to.
 * WM_NEVER_INLINE: never inlined, on every CPU (a path few calls take, whose registers and saves would
 *   cost its caller's common path).
 * WM_NOINLINE_32: never inlined on a 32-bit CPU, the compiler's choice on a 64-bit one: a small hot
 *   function whose loop gets the registers out of its caller there (the soft CPU); a 64-bit host has
 *   registers enough and saves the call.
 * WM_MAY_ALIAS: a type whose objects share their bytes with another type's (the error bound's heap entries
 *   in the storage of list[], which other phases use as wm_index words: wm_internal.h, wm_hent).
 * WM_ENGINE_FALLBACK: the C path that one of the board's FPGA units replaces (with WM_TRI_ENGINE: the C
 *   E(T) scans, for fields the engine does not read), so cold there: GCC compiles it for size into
 *   .text.unlikely, which the board's linker script keeps out of the hot code (firmware/board/board.ld). */
#ifndef WM_INLINE_H
#define WM_INLINE_H

#include <stdint.h>

#if defined(__GNUC__)
#define WM_ALWAYS_INLINE inline __attribute__((always_inline))
#define WM_NEVER_INLINE __attribute__((noinline))
#define WM_MAY_ALIAS __attribute__((may_alias))
#else
#define WM_ALWAYS_INLINE inline
#define WM_NEVER_INLINE
#define WM_MAY_ALIAS
#endif
#if UINTPTR_MAX == 0xFFFFFFFFu
#define WM_NOINLINE_32 WM_NEVER_INLINE
#else
#define WM_NOINLINE_32
#endif
#if defined(__GNUC__) && defined(WM_TRI_ENGINE)
#define WM_ENGINE_FALLBACK __attribute__((cold))
#else
#define WM_ENGINE_FALLBACK
#endif

#endif /* WM_INLINE_H */
