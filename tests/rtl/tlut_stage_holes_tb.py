"""cocotb bench of rtl/tlut_stage.v with HOLES = 1: the template stage with a validity mask beside its
records, every output beat carrying its block's hole flag on tuser[45].

The records and the expected beats are tlut_stage_tb's (the reference model: wavemesh.model.label,
wavemesh.model.templates, wavemesh.model.initial), so the templates must be exactly those of the stage without
holes; the flag of every beat must be wavemesh.model.holemask.block_flags of the frame's mask at the beat's
block.  The mask goes in on its own stream (s_mask_*) with random gaps, the records with random idle
cycles, the output under random back-pressure; frames follow each other without a reset.

Parameters come from the environment: TLUT_HOLES_SEED, TLUT_HOLES_FRAMES, TLUT_HOLES_EXPAND (the
stage's EXPAND: 0 gives one beat per block).  Run through tests/rtl/test_tlut_stage_holes.py.
"""

from __future__ import annotations

import os
import random

import cocotb
import numpy as np
from cocotb.triggers import ClockCycles, FallingEdge, ReadOnly, RisingEdge, with_timeout
from tlut_stage_tb import (
    TB,
    Frame,
    check_frame,
    coefficient_frame,
    random_level,
    random_pattern,
    samples_frame,
)
from wavemesh.model.holemask import block_flags

SEED = int(os.environ.get("TLUT_HOLES_SEED", "1"))
FRAMES = int(os.environ.get("TLUT_HOLES_FRAMES", "6"))
EXPAND = int(os.environ.get("TLUT_HOLES_EXPAND", "1"))
HOLE_BIT = 45


def random_mask(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    """Invalid samples at a random density, sometimes in blobs (a few rectangles) instead."""
    kind = rng.integers(0, 3)
    if kind == 0:
        return rng.random((height, width)) < rng.choice([0.0, 0.01, 0.05, 0.3, 1.0])
    m = np.zeros((height, width), dtype=bool)
    for _ in range(int(rng.integers(1, 4))):
        y, x = int(rng.integers(0, height)), int(rng.integers(0, width))
        m[y:y + int(rng.integers(1, 6)), x:x + int(rng.integers(1, 6))] = True
    return m


def expected(frame: Frame, mask: np.ndarray) -> list[tuple[int, int, int]]:
    """The beats of the stage without holes (EXPAND's format), each with its block's flag on bit 45."""
    flags = block_flags(mask, frame.levels)
    out = []
    for data, user, last in frame.beats:
        if not EXPAND:
            if not user >> 44 & 1:
                continue
            data, user = 0, user & (1 << 44 | 0xE00 | 0x1F8)  # block_end, label, template id only
        out.append((data, user, last))
    # the flags in block order: every block's beats are consecutive, its last one has block_end
    rows, cols = frame.lab.label.shape
    flat = [bool(f) for f in flags.ravel()]
    assert flags.shape == (rows, cols)
    k = 0
    res = []
    for data, user, last in out:
        res.append((data, user | int(flat[k]) << HOLE_BIT, last))
        if user >> 44 & 1:
            k += 1
    assert k == rows * cols
    return res


class HolesTB(TB):
    def __init__(self, dut, rng: random.Random):
        super().__init__(dut)
        self.rng = rng
        dut.s_mask_tvalid.value = 0
        dut.s_mask_tdata.value = 0
        # coverage: cycles where a triangle waited for its flag, and where the flag FIFO was full
        self.waited_for_flag = 0
        self.flags_full = 0
        cocotb.start_soon(self._coverage())

    async def _coverage(self):
        holes = self.dut.g_holes
        while True:
            await RisingEdge(self.dut.clk)
            if self.dut.st_tvalid.value and not holes.flag_valid.value:
                self.waited_for_flag += 1
            if holes.hole_valid.value and not holes.hole_ready.value:
                self.flags_full += 1

    async def send_mask(self, mask: np.ndarray, p_gap: float):
        """One frame's mask bits, raster order, with random gaps (valid held until taken)."""
        dut = self.dut
        for bit in mask.ravel().tolist():
            while self.rng.random() < p_gap:
                await FallingEdge(dut.clk)
            await FallingEdge(dut.clk)
            dut.s_mask_tdata.value = int(bit)
            dut.s_mask_tvalid.value = 1
            while True:
                await ReadOnly()
                if dut.s_mask_tready.value:
                    break
                await RisingEdge(dut.clk)
            await RisingEdge(dut.clk)
            await FallingEdge(dut.clk)
            dut.s_mask_tvalid.value = 0

    async def run_holes(self, frames: list[tuple[Frame, np.ndarray]], p_gap: float):
        f0 = frames[0][0]
        self.configure(f0)
        await ClockCycles(self.dut.clk, 5)
        assert not self.dut.status_cfg_error.value
        masks = cocotb.start_soon(self._masks([m for _, m in frames], p_gap))
        for f, _ in frames:
            await self.send(f)
        for f, m in frames:
            want = expected(f, m)
            limit = 100 * (len(f.records) + len(want) + m.size) + 10000
            rx = await with_timeout(self.sink.recv(compact=False), limit * 10, "ns")
            got = list(zip(rx.tdata, rx.tuser, [0] * (len(rx.tdata) - 1) + [1], strict=True))
            for n, (g, w) in enumerate(zip(got, want, strict=False)):
                assert g == w, (f"{f.name}: beat {n}: got user {g[1]:012x} data {g[0]:x}, "
                                f"want user {w[1]:012x} data {w[0]:x}")
            assert len(got) == len(want), f"{f.name}: {len(got)} beats, want {len(want)}"
            if EXPAND:  # the templates as the stage without holes gives them: the reference mesh
                check_frame(f, [(d, u & ((1 << HOLE_BIT) - 1), t) for d, u, t in got])
        await with_timeout(masks, 100, "us")
        await with_timeout(self.source.wait(), 10, "us")

    async def _masks(self, masks: list[np.ndarray], p_gap: float):
        for m in masks:
            await self.send_mask(m, p_gap)


@cocotb.test()
async def test_random_holes(dut):
    """Random sizes, levels and coefficients, random masks (densities 0..1 and blobs), random mask
    gaps, idle records and output back-pressure; two frames back to back per configuration."""
    rng = np.random.default_rng(SEED)
    tb = HolesTB(dut, random.Random(SEED))
    await tb.reset()
    max_cols = int(dut.MAX_COLS.value)
    flagged = 0
    for n in range(FRAMES):
        while True:
            m = int(rng.integers(1, 4))
            s = 1 << m
            width, height = int(rng.integers(2, 8 * s)), int(rng.integers(2, 8 * s))
            if -(-(width - 1) // s) <= max_cols:
                break
        tau_q = int(rng.choice([0, 2, 30]))
        frames = []
        for k in range(2):
            if n == 0 and k == 0:  # real heights through the reference filter bank, every level
                values = rng.integers(0, 4000, size=(height, width)).cumsum(axis=1) % 65536
                f = samples_frame(f"heights {width}x{height} M={m}", values, m, all_levels=True)
            else:
                lv = random_level(rng, m, width, height, 40)
                f = coefficient_frame(f"random {n}.{k} {width}x{height} M={m}", lv, width, height,
                                      frames[0][0].tau_q if k else tau_q)
            mask = random_mask(rng, width, height)
            flagged += int(block_flags(mask, m).sum())
            frames.append((f, mask))
        # records and output now slow (the flags run ahead: their FIFO fills), now fast (the
        # triangles wait for their flags)
        idle, bp = float(rng.choice([0.0, 0.3, 0.9])), float(rng.choice([0.2, 0.7]))
        tb.set_idle(lambda idle=idle, n=n: random_pattern(SEED + 2 * n, idle))
        tb.set_backpressure(lambda bp=bp, n=n: random_pattern(SEED + 2 * n + 1, bp))
        tb.log.info("%s: %d blocks", frames[0][0].name, frames[0][0].blocks)
        await tb.run_holes(frames, p_gap=float(rng.choice([0.0, 0.3, 0.8])))
    assert flagged > 0
    tb.log.info("cycles a triangle waited for its flag: %d, the flag FIFO full: %d",
                tb.waited_for_flag, tb.flags_full)
    assert tb.waited_for_flag > 0 and tb.flags_full > 0
