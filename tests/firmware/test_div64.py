"""The board's 64-bit divisions (firmware/board/src/div64.c: the __udivdi3, __divdi3 and __umoddi3 the rv32
build links before libgcc's) against Python's integers.

The file is compiled natively under other names (WM_DIV64_UDIV / WM_DIV64_SDIV / WM_DIV64_UMOD), with
the undefined behaviour sanitizer where the compiler has it, into a program that divides the pairs it
reads; each quotient and the remainder are checked against Python's (truncated towards zero for the
signed one).  The pairs: every path of the routine (operands below 2^32, a 32-bit divisor with
quotients of 32 and 64 bits, divisors of 2^32 and more with every normalisation shift), the
corrections' edges (divisors and dividends next to powers of two, all-ones halves) and random
operands of every pair of bit lengths.
"""

import random
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DIV64 = ROOT / "firmware" / "board" / "src" / "div64.c"
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
M64 = (1 << 64) - 1

MAIN = r"""
#include <inttypes.h>
#include <stdio.h>
uint64_t wm_udiv64(uint64_t n, uint64_t d);
int64_t wm_sdiv64(int64_t n, int64_t d);
uint64_t wm_umod64(uint64_t n, uint64_t d);
int main(void)
{
    uint64_t n, d;
    while (scanf("%" SCNx64 " %" SCNx64, &n, &d) == 2) {
        printf("%" PRIx64 " %" PRIx64 " %" PRIx64 "\n", wm_udiv64(n, d),
               (uint64_t)wm_sdiv64((int64_t)n, (int64_t)d), wm_umod64(n, d));
    }
    return 0;
}
"""


def _signed(v: int) -> int:
    return v - (1 << 64) if v >> 63 else v


def _sdiv(n: int, d: int) -> int:
    n, d = _signed(n), _signed(d)
    q = abs(n) // abs(d)
    return (-q if (n < 0) != (d < 0) else q) & M64


def _pairs() -> list[tuple[int, int]]:
    rng = random.Random(20261128)
    edges = set()
    for b in range(65):
        for delta in (-1, 0, 1):
            v = (1 << b) + delta
            if 0 <= v <= M64:
                edges.add(v)
    edges |= {
        0xFFFFFFFF,
        0xFFFFFFFF00000000,
        M64,
        0x8000000000000000,
        0x7FFFFFFFFFFFFFFF,
        0xFFFF,
        0x10000,
        0xFFFF0000,
        0x80000000FFFFFFFF,
    }
    edges = sorted(edges)
    pairs = [(n, d) for n in edges for d in edges if d]
    for _ in range(60_000):
        bn, bd = rng.randint(0, 64), rng.randint(1, 64)
        n = rng.getrandbits(bn) if bn else 0
        d = rng.getrandbits(bd) | (1 << (bd - 1))
        pairs.append((n, d))
        # a multiple of d, and one less: the estimate's correction at its edge
        q = rng.getrandbits(rng.randint(1, 64))
        if q * d <= M64:
            pairs.append((q * d, d))
            if q * d:
                pairs.append((q * d - 1, d))
    return pairs


@pytest.mark.skipif(CC is None, reason="no native C compiler")
def test_div64_against_python(tmp_path):
    main = tmp_path / "main.c"
    main.write_text(MAIN)
    exe = tmp_path / "div64"
    base = [
        CC,
        "-O2",
        "-std=c99",
        "-Wall",
        "-Wextra",
        "-Werror",
        "-DWM_DIV64_UDIV=wm_udiv64",
        "-DWM_DIV64_SDIV=wm_sdiv64",
        "-DWM_DIV64_UMOD=wm_umod64",
        f"-I{ROOT / 'firmware' / 'include'}",
        str(DIV64),
        str(main),
        "-o",
        str(exe),
    ]
    ubsan = ["-fsanitize=undefined", "-fno-sanitize-recover=all"]
    if subprocess.run(base + ubsan, capture_output=True).returncode != 0:
        subprocess.run(base, check=True)
    pairs = _pairs()
    out = subprocess.run(
        [str(exe)],
        input="".join(f"{n:x} {d:x}\n" for n, d in pairs),
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split("\n")
    assert out[-1] == ""
    for (n, d), line in zip(pairs, out[:-1], strict=True):
        uq, sq, ur = (int(v, 16) for v in line.split())
        assert uq == n // d, f"{n:#x} / {d:#x}: {uq:#x}, not {n // d:#x}"
        assert ur == n % d, f"{n:#x} % {d:#x}: {ur:#x}, not {n % d:#x}"
        if _signed(d) != -1 or n != 1 << 63:  # INT64_MIN / -1 overflows in C
            assert sq == _sdiv(n, d), f"{_signed(n)} / {_signed(d)} (signed): {_signed(sq)}"
