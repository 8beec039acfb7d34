"""rtl/sdram_ctrl.v (with sdram_cache.v and wm_fifo.v) against a behavioural SDRAM that checks the
datasheet's timings, and a scoreboard of every datum (bench: sdram_tb.py).

Two builds: the ULX3S's 25 MHz board clock with CAS latency 2 (most timings are one cycle there),
and 125 MHz with CAS latency 3, where tRCD, tRP, tRAS, tRC, tRFC, tWR, tRRD and the read-to-write
turnaround take several cycles each; the second also shows that the chip model catches a controller
that is too fast for it.
"""

import pytest
from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [RTL / "sdram_ctrl.v", RTL / "sdram_cache.v", RTL / "wm_fifo.v"]
CONFIGS = [(25_000_000, 2), (125_000_000, 3)]


@pytest.mark.parametrize("clk_hz,cl", CONFIGS, ids=[f"{c // 1_000_000}MHz_CL{cl}" for c, cl in CONFIGS])
def test_sdram(clk_hz, cl):
    env = {"SDRAM_CLK_HZ": str(clk_hz), "SDRAM_CL": str(cl), "SDRAM_SEED": str(clk_hz // 1_000_000 + cl)}
    run("sdram_ctrl", SOURCES, "sdram_tb", parameters={"CLK_HZ": clk_hz, "CAS_LATENCY": cl}, extra_env=env)
