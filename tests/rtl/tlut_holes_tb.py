"""cocotb bench of rtl/tlut_holes.v, the template stage's per-block validity flag, against the reference
model wavemesh.model.holemask.block_flags.

Each frame: a random W x H (2..37 a side, within MAX_COLS block columns), levels and mask density; the
mask goes in raster order with random gaps in s_valid, the flags come out with random m_ready, and
they must be block_flags(mask, levels) row by row, once each.  Frames follow each other without a reset
(the module starts the next frame at sample (0, 0) after a frame's last flag), after one reset.

Parameters come from the environment: WM_HOLES_SEED, WM_HOLES_MAX_COLS.
"""

from __future__ import annotations

import os
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, ReadOnly, RisingEdge
from wavemesh.model.holemask import block_flags

SEED = int(os.environ.get("WM_HOLES_SEED", "1"))
MAX_COLS = int(os.environ.get("WM_HOLES_MAX_COLS", "16"))


def frame(rng: random.Random) -> tuple[np.ndarray, int]:
    while True:
        levels = rng.randint(1, 3)
        w, h = rng.randint(2, 37), rng.randint(2, 37)
        if -(-(w - 1) // (1 << levels)) <= MAX_COLS:
            break
    density = rng.choice((0.0, 0.02, 0.1, 0.5, 1.0))
    m = np.array([[rng.random() < density for _ in range(w)] for _ in range(h)], dtype=bool)
    return m, levels


async def run_frame(dut, rng: random.Random, m: np.ndarray, levels: int) -> list[int]:
    h, w = m.shape
    want = block_flags(m, levels)
    n_flags = want.size
    bits = [int(b) for b in m.ravel()]
    got: list[int] = []
    i = 0
    cycles = 0
    while len(got) < n_flags:
        cycles += 1
        assert cycles < 10 * (len(bits) + n_flags) + 100, (
            f"{w} x {h}, levels {levels}: stuck after {i} of {len(bits)} mask bits, "
            f"{len(got)} of {n_flags} flags")
        await FallingEdge(dut.clk)
        offer = i < len(bits) and rng.random() < 0.8
        dut.s_valid.value = int(offer)
        dut.s_data.value = bits[i] if i < len(bits) else 0
        take = rng.random() < 0.7
        dut.m_ready.value = int(take)
        await ReadOnly()
        if offer and int(dut.s_ready.value):
            i += 1
        if take and int(dut.m_valid.value):
            got.append(int(dut.m_data.value))
        await RisingEdge(dut.clk)
    await FallingEdge(dut.clk)
    dut.s_valid.value = 0
    dut.m_ready.value = 0
    assert i == len(bits), f"{w} x {h}, levels {levels}: {i} of {len(bits)} mask bits taken"
    assert got == [int(b) for b in want.ravel()], f"{w} x {h}, levels {levels}: flags differ"
    return got


@cocotb.test()
async def random_frames(dut):
    rng = random.Random(SEED)
    cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
    m, levels = frame(rng)
    dut.cfg_width.value = m.shape[1]
    dut.cfg_height.value = m.shape[0]
    dut.cfg_levels.value = levels
    dut.s_valid.value = 0
    dut.m_ready.value = 0
    dut.rst.value = 1
    await ClockCycles(dut.clk, 2)
    await FallingEdge(dut.clk)
    dut.rst.value = 0
    seen = set()
    for k in range(20):
        if k:
            m, levels = frame(rng)
            await FallingEdge(dut.clk)
            dut.cfg_width.value = m.shape[1]
            dut.cfg_height.value = m.shape[0]
            dut.cfg_levels.value = levels
            if int(dut.m_valid.value):
                raise AssertionError("a flag is offered between frames")
        await run_frame(dut, rng, m, levels)
        seen.add((m.shape[1] % (1 << levels) == 1, m.shape[0] % (1 << levels) == 1))
    # frames whose last block column and row are whole, and ones where they are narrower
    assert len(seen) >= 3, seen
