"""rtl/sdram_ctrl.v (with sdram_cache.v and wm_fifo.v) against a behavioural SDRAM that checks the
datasheet's timings, and a scoreboard of every datum (bench: sdram_tb.py).

Two builds: the ULX3S SoC's clock (memmap.CLK_HZ) with its CAS latency (most timings are one or two
cycles there) and the default cache (16 lines of 4 words), and 125 MHz with CAS latency 3, where tRCD,
tRP, tRAS, tRC, tRFC, tWR, tRRD and the read-to-write turnaround take several cycles each, with a larger cache
(64 lines of 8 words, lines across two banks); the second also shows that the chip model catches a
controller that is too fast for it.
"""

import pytest
from wavemesh.device import memmap
from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [RTL / "sdram_ctrl.v", RTL / "sdram_cache.v", RTL / "wm_fifo.v"]
# (CLK_HZ, CAS_LATENCY, CACHE_LINES, LINE_WORDS)
CONFIGS = [(memmap.CLK_HZ, memmap.SDRAM_CAS_LATENCY, 16, 4), (125_000_000, 3, 64, 8),
           (memmap.CLK_HZ, memmap.SDRAM_CAS_LATENCY, memmap.SDRAM_CACHE_LINES, memmap.SDRAM_LINE_WORDS)]


@pytest.mark.parametrize("clk_hz,cl,lines,words", CONFIGS,
                         ids=[f"{c // 1_000_000}MHz_CL{cl}_{n}x{w}" for c, cl, n, w in CONFIGS])
def test_sdram(clk_hz, cl, lines, words):
    env = {"SDRAM_CLK_HZ": str(clk_hz), "SDRAM_CL": str(cl), "SDRAM_SEED": str(clk_hz // 1_000_000 + cl),
           "SDRAM_LINE_WORDS": str(words)}
    params = {"CLK_HZ": clk_hz, "CAS_LATENCY": cl, "CACHE_LINES": lines, "LINE_WORDS": words}
    # the timings the SoC builds it with (memmap.SDRAM_TIMING, the table the chip model checks too)
    params |= {k: v for k, v in memmap.SDRAM_TIMING.items() if k not in ("T_AC_NS", "T_OH_NS")}
    run("sdram_ctrl", SOURCES, "sdram_tb", parameters=params, extra_env=env)
