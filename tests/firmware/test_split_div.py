"""wm_internal.h's division helpers (wm_udiv_small, wm_ceil_q16_div, wm_frac_mul) in each of the builds'
forms against Python's integers: the plain divisions (a native release build), the 32-bit-division paths
(WM_NARROW_DIV, here through the checked build's WM_CHECK=1, as on rv32) and the board's one division
(WM_DIV64_ENGINE: WM_SPLIT_DIV 0, which only the board's image builds otherwise, so no native test ran it).

The header is compiled natively into a program that answers each input line, with the undefined behaviour
sanitizer where the compiler has it.  The inputs: dividends of every bit length, divisors at the paths'
limits (below 2^16, 2^24 and above) and random ones, every slope scale exponent and shift wm_frac_mul takes.
"""

import random
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
CAP = (1 << 63) - 1

MAIN = r"""
#include "wm_internal.h"
#include <inttypes.h>
#include <stdio.h>
int main(void)
{
    uint64_t n, d, fd;
    unsigned m, e, sh;
    while (scanf("%" SCNx64 " %" SCNx64 " %" SCNx64 " %x %x %x", &n, &d, &fd, &m, &e, &sh) == 6) {
        uint32_t rem = 0;
        uint64_t q = wm_udiv_small(n, (uint32_t)d, &rem);
        printf("%" PRIx64 " %" PRIx32 " %" PRIx64 " %" PRIx64 "\n", q, rem, wm_ceil_q16_div(n >> 17, fd),
               wm_frac_mul(n >> 17, fd, m, (int32_t)e, (int)sh, UINT64_MAX >> 1));
    }
    return 0;
}
"""

BUILDS = {"plain (native release)": ["-DWM_CHECK=0"], "32-bit divisions (checked)": ["-DWM_CHECK=1"],
          "the board's (WM_DIV64_ENGINE)": ["-DWM_CHECK=1", "-DWM_DIV64_ENGINE"]}


def _frac_mul(n: int, d: int, m: int, e: int, sh: int) -> int:
    """floor(n m 2^(sh - e) / d) saturated at CAP, as wm_frac_mul rounds it (the quotient, then the
    remainder's bits)."""
    q, r = divmod(n * m, d)
    k = sh - e
    if k <= 0:
        return min(q >> -k, CAP)
    if q > CAP >> k:
        return CAP
    return min((q << k) + ((r << k) // d), CAP)


def _inputs() -> list[tuple[int, int, int, int, int, int]]:
    rng = random.Random(20261129)
    out = []
    for b in range(65):
        for i in range(300):
            n = rng.getrandbits(b) if b else 0
            d = (65535, 1, 256, 65534)[i] if i < 4 else rng.randint(1, 65535)
            bits = rng.randint(1, 40)
            fd = rng.getrandbits(bits) | (1 << (bits - 1))  # below 2^16, 2^24 and above: every path
            out.append((n, d, fd, rng.randint(0, 65535), rng.randint(0, 39), rng.randint(0, 16)))
    return out


def _run_c(source: str, build: str, tmp_path, inputs: list[tuple[int, ...]]) -> list[str]:
    """Compiles `source` (a main over wm_internal.h's helpers) for `build` (with UBSan where the compiler
    has it), feeds it `inputs` a line each in hex, and returns its output lines, one per input."""
    main = tmp_path / "main.c"
    main.write_text(source)
    exe = tmp_path / "main"
    base = [CC, "-O2", "-std=c99", "-Wall", "-Wextra", "-Werror", *BUILDS[build],
            f"-I{ROOT / 'firmware' / 'include'}", f"-I{ROOT / 'firmware' / 'src'}", str(main), "-o", str(exe)]
    ubsan = ["-fsanitize=undefined", "-fno-sanitize-recover=all"]
    if subprocess.run(base + ubsan, capture_output=True).returncode != 0:
        subprocess.run(base, check=True)
    out = subprocess.run([str(exe)], input="".join(" ".join(f"{v:x}" for v in t) + "\n" for t in inputs),
                         capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[-1] == "" and len(out) == len(inputs) + 1
    return out[:-1]


@pytest.mark.skipif(CC is None, reason="no native C compiler")
@pytest.mark.parametrize("build", list(BUILDS))
def test_division_helpers_against_python(build, tmp_path):
    inputs = _inputs()
    for (n, d, fd, m, e, sh), line in zip(inputs, _run_c(MAIN, build, tmp_path, inputs), strict=True):
        q, rem, ceil, frac = (int(v, 16) for v in line.split())
        assert (q, rem) == divmod(n, d), f"wm_udiv_small({n:#x}, {d}): {q:#x} rem {rem}"
        assert ceil == -(-((n >> 17) << 16) // fd), f"wm_ceil_q16_div({n >> 17:#x}, {fd:#x}): {ceil:#x}"
        assert frac == _frac_mul(n >> 17, fd, m, e, sh), f"wm_frac_mul({n >> 17:#x}, {fd:#x}, {m}, {e}, {sh})"


RECIP_MAIN = r"""
#include "wm_internal.h"
#include <inttypes.h>
#include <stdio.h>
int main(void)
{
    unsigned c, l;
    while (scanf("%x %x", &c, &l) == 2)
        printf("%" PRIx32 "\n", wm_q28_div_recip(c, l, (uint32_t)((((uint64_t)1 << 61) - 1) / l)));
    return 0;
}
"""


def _recip_inputs() -> list[tuple[int, int]]:
    """The unit normals' quotients: L at [2^29, 2^31)'s ends and random, C at 0, 1, L - 1, L and random."""
    rng = random.Random(20261130)
    ls = [1 << 29, (1 << 29) + 1, (1 << 30) - 1, 1 << 30, (1 << 31) - 2, (1 << 31) - 1]
    out = []
    for i in range(20000):
        L = ls[i % len(ls)] if i < 600 else rng.randrange(1 << 29, 1 << 31)
        C = (0, L, L - 1, 1)[i % 4] if i < 1200 else rng.randint(0, L)
        out.append((C, L))
    return out


@pytest.mark.skipif(CC is None, reason="no native C compiler")
@pytest.mark.parametrize("build", list(BUILDS))
def test_reciprocal_divisions_against_python(build, tmp_path):
    """wm_q28_div_recip (the unit normals' three quotients by one reciprocal) equals the division, in each
    build."""
    inputs = _recip_inputs()
    for (c, len_), line in zip(inputs, _run_c(RECIP_MAIN, build, tmp_path, inputs), strict=True):
        want = ((c << 28) + (len_ >> 1)) // len_
        assert int(line, 16) == want, f"wm_q28_div_recip({c:#x}, {len_:#x}): {line}"
