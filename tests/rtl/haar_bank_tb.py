"""cocotb bench of rtl/haar_bank.v: every record against the reference model wavemesh.model.haar.

Run by tests/rtl/test_haar_bank.py (and bench/bench_rtl.py) through rtl_runner.run; the environment
says what to do:

    HAAR_FRAMES   JSON list of [width, height, cfg_levels, seed] frames, sent one after the other
    HAAR_MAX_LEVELS  the bank's MAX_LEVELS (cfg_levels saturates to 1 .. MAX_LEVELS)
    HAAR_IDLE     input pattern: "none" (valid every cycle), "random", "bursty"
    HAAR_BP       output pattern: "none" (always ready), "random", "bursty"
    HAAR_NO_STALL "1": also require that the input never waits inside a frame and that a frame takes
                  W * H + 3 M + 3 clocks from its start to its last record (needs HAAR_BP=none)
    HAAR_RESULTS  file to write per-frame cycle counts to (JSON), for the benchmark
    HAAR_WAVELET  the bank's filters, as wavemesh.model.haar.WAVELETS names them (default "haar"); the
                  spline bank's frames take longer (its flush), so HAAR_NO_STALL checks only the input
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.simtime import get_sim_time
from cocotb.triggers import ClockCycles, RisingEdge
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSink, AxiStreamSource
from wavemesh.model.haar import decompose

CLOCK_NS = 10
STATE_RUN = 2  # haar_bank's state_reg while it takes samples


def pattern(name: str, seed: int):
    """Pause generator for cocotbext-axi: True pauses the bus for a cycle."""
    rng = random.Random(seed)
    if name == "none":
        return None
    if name == "random":  # about 30% of the cycles paused, independently
        return (rng.random() < 0.3 for _ in itertools.count())
    if name == "bursty":  # runs of up to 40 cycles on, up to 12 off
        def gen():
            while True:
                yield from [False] * rng.randint(1, 40)
                yield from [True] * rng.randint(1, 12)
        return gen()
    raise ValueError(f"unknown pattern {name!r}")


def frame_samples(width: int, height: int, seed: int) -> np.ndarray:
    """(height, width) 16-bit samples of one of three kinds, chosen by the seed."""
    rng = np.random.default_rng(seed)
    kind = seed % 3
    if kind == 0:  # uniform: every value
        return rng.integers(0, 65536, size=(height, width))
    if kind == 1:  # extremes: the largest details, both signs (18-bit sign extension)
        return rng.choice(np.array([0, 65535]), size=(height, width))
    y, x = np.mgrid[0:height, 0:width]  # smooth ramp with noise: small details, carries in a
    return np.clip(x * 97 + y * 211 + rng.integers(-3, 4, size=(height, width)), 0, 65535)


def expected_records(samples: np.ndarray, levels: int, wavelet: str = "haar") -> dict[int, list[tuple]]:
    """Level -> records (by, bx, a, d1, d2, d3) in raster order, from the reference model."""
    out = {}
    for lv in decompose(samples, levels, wavelet):
        rows, cols = lv.a.shape
        by, bx = np.mgrid[0:rows, 0:cols]
        out[lv.m] = list(zip(by.ravel().tolist(), bx.ravel().tolist(), lv.a.ravel().tolist(),
                             lv.d1.ravel().tolist(), lv.d2.ravel().tolist(), lv.d3.ravel().tolist(),
                             strict=True))
    return out


def signed18(v: int) -> int:
    return v - (1 << 18) if v & (1 << 17) else v


def received_records(frame: AxiStreamFrame) -> dict[int, list[tuple]]:
    """Level -> records (by, bx, a, d1, d2, d3) in the order the bank emitted them."""
    tdata = frame.tdata
    tuser = frame.tuser if isinstance(frame.tuser, list) else [frame.tuser] * len(tdata)
    out: dict[int, list[tuple]] = {}
    for d, u in zip(tdata, tuser, strict=True):
        rec = ((u >> 16) & 0xFFFF, u & 0xFFFF, d & 0xFFFF, signed18((d >> 16) & 0x3FFFF),
               signed18((d >> 34) & 0x3FFFF), signed18((d >> 52) & 0x3FFFF))
        out.setdefault(u >> 32, []).append(rec)
    return out


def compare(got: dict[int, list[tuple]], want: dict[int, list[tuple]], what: str) -> None:
    assert sorted(got) == sorted(want), f"{what}: levels {sorted(got)}, expected {sorted(want)}"
    for m in want:
        g, w = got[m], want[m]
        for k, (a, b) in enumerate(zip(g, w, strict=False)):
            assert a == b, (f"{what}: level {m} record {k}: got (by, bx, a, d1, d2, d3) = {a}, "
                            f"expected {b}")
        assert len(g) == len(w), f"{what}: level {m}: {len(g)} records, expected {len(w)}"


class TB:
    def __init__(self, dut):
        self.dut = dut
        self.log = logging.getLogger("cocotb.tb")
        self.log.setLevel(logging.INFO)
        Clock(dut.clk, CLOCK_NS, unit="ns").start()
        # one "byte" per beat: a 16-bit sample in, a 70-bit record out
        self.source = AxiStreamSource(AxiStreamBus.from_prefix(dut, "s_axis"), dut.clk, dut.rst, byte_lanes=1)
        self.sink = AxiStreamSink(AxiStreamBus.from_prefix(dut, "m_axis"), dut.clk, dut.rst, byte_lanes=1)
        for bus in (self.source, self.sink):
            bus.log.setLevel(logging.WARNING)  # they would print every frame
        self.stalls = 0
        dut.cfg_width.value = 2
        dut.cfg_height.value = 2
        dut.cfg_levels.value = 1

    def set_patterns(self, idle: str, bp: str, seed: int) -> None:
        self.source.set_pause_generator(pattern(idle, seed))
        self.sink.set_pause_generator(pattern(bp, seed + 1))

    async def reset(self) -> None:
        self.dut.rst.value = 1
        await ClockCycles(self.dut.clk, 3)
        self.dut.rst.value = 0
        await ClockCycles(self.dut.clk, 2)

    async def count_stalls(self) -> None:
        """Count cycles in which a sample waits although the bank is taking samples."""
        dut = self.dut
        while True:
            await RisingEdge(dut.clk)
            waiting = dut.s_axis_tvalid.value and not dut.s_axis_tready.value
            if waiting and int(dut.state_reg.value) == STATE_RUN:
                self.stalls += 1

    async def run_frame(self, width: int, height: int, cfg_levels: int, seed: int, max_levels: int) -> dict:
        """Send one frame, check every record against the model; return cycle counts."""
        dut = self.dut
        samples = frame_samples(width, height, seed)
        levels = min(max(cfg_levels, 1), max_levels)
        want = expected_records(samples, levels, os.environ.get("HAAR_WAVELET", "haar"))
        dut.cfg_width.value = width
        dut.cfg_height.value = height
        dut.cfg_levels.value = cfg_levels
        stalls0 = self.stalls
        await self.source.send(AxiStreamFrame(samples.ravel().tolist()))
        await RisingEdge(dut.busy)
        # the configuration was sampled when the frame started: scramble it
        rng = random.Random(seed)
        dut.cfg_width.value = rng.randrange(65536)
        dut.cfg_height.value = rng.randrange(65536)
        dut.cfg_levels.value = rng.randrange(16)
        start = get_sim_time("ns")
        rx = await self.sink.recv()
        what = f"{width}x{height}, {levels} levels, seed {seed}"
        compare(received_records(rx), want, what)
        assert self.sink.empty(), f"{what}: records after the one with tlast"
        await RisingEdge(dut.clk)
        assert not dut.busy.value, f"{what}: still busy after the last record"
        end = get_sim_time("ns")
        return {"width": width, "height": height, "levels": levels,
                "records": sum(len(v) for v in want.values()),
                "cycles": round((end - start) / CLOCK_NS), "stalls": self.stalls - stalls0}


@cocotb.test()
async def run_frames(dut):
    """The frames of HAAR_FRAMES with the idle and back-pressure patterns of the environment."""
    frames = json.loads(os.environ.get("HAAR_FRAMES", "[[4, 4, 1, 0]]"))
    idle = os.environ.get("HAAR_IDLE", "none")
    bp = os.environ.get("HAAR_BP", "none")
    no_stall = os.environ.get("HAAR_NO_STALL") == "1"
    max_levels = int(os.environ.get("HAAR_MAX_LEVELS", "7"))
    tb = TB(dut)
    tb.set_patterns(idle, bp, seed=len(frames))
    await tb.reset()
    cocotb.start_soon(tb.count_stalls())
    results = []
    for width, height, levels, seed in frames:
        r = await tb.run_frame(width, height, levels, seed, max_levels)
        tb.log.info("frame %dx%d L%d: %d records, %d cycles, %d input stalls", width, height, levels,
                    r["records"], r["cycles"], r["stalls"])
        if no_stall:
            assert r["stalls"] == 0, f"{width}x{height}: the input waited {r['stalls']} cycles"
        if no_stall and os.environ.get("HAAR_WAVELET", "haar") == "haar":
            # rtl/README.md: W * H + 3 M + 3 clocks from the frame's start to its last record
            expect = width * height + 3 * min(max(levels, 1), max_levels) + 3
            assert r["cycles"] == expect, f"{width}x{height}: {r['cycles']} cycles, expected {expect}"
        results.append(r)
    await ClockCycles(dut.clk, 10)
    assert not dut.m_axis_tvalid.value, "a record after the last frame"
    if os.environ.get("HAAR_RESULTS"):
        with open(os.environ["HAAR_RESULTS"], "w") as f:
            json.dump(results, f)


@cocotb.test()
async def reset_mid_frame(dut):
    """Reset in the middle of the first frame of HAAR_FRAMES; then the other frames must be exact."""
    frames = json.loads(os.environ["HAAR_FRAMES"])
    max_levels = int(os.environ.get("HAAR_MAX_LEVELS", "7"))
    tb = TB(dut)
    await tb.reset()
    width, height, levels, seed = frames[0]
    dut.cfg_width.value = width
    dut.cfg_height.value = height
    dut.cfg_levels.value = levels
    await tb.source.send(AxiStreamFrame(frame_samples(width, height, seed).ravel().tolist()))
    await ClockCycles(dut.clk, width * height // 2)
    assert dut.busy.value, "the frame did not start"
    # cocotbext-axi drops its queues on its own reset: source and sink start clean with the bank
    await tb.reset()
    assert not dut.busy.value and not dut.m_axis_tvalid.value, "not idle after reset"
    tb.sink.clear()
    for width, height, levels, seed in frames[1:]:
        await tb.run_frame(width, height, levels, seed, max_levels)
