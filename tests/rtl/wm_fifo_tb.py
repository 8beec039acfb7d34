"""cocotb bench of rtl/wm_fifo.v against a cycle-exact Python model.

Each cycle the bench drives s_valid, s_data and m_ready after the falling edge and, with the inputs
settled, compares s_ready, m_valid, m_data and count with the model: a deque of the entries held,
s_ready = not full, m_valid = not empty, m_data = the oldest entry, count = how many; a beat moves
where valid and ready are both high.  So the model also pins the latency (a beat written in cycle t
is readable in t + 1, a full FIFO refuses a write in the cycle it is read, an empty one passes
nothing through in the cycle a beat arrives).  Apart from the model, the beats read must be the
beats written, once each and in order (no loss, no duplication).  Every test asserts that it hit
the corners it is about.

Parameters come from the environment: WM_FIFO_DEPTH, WM_FIFO_WIDTH, WM_FIFO_SEED.
"""

from __future__ import annotations

import os
import random
from collections import Counter, deque

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, ReadOnly

DEPTH = int(os.environ.get("WM_FIFO_DEPTH", "4"))
WIDTH = int(os.environ.get("WM_FIFO_WIDTH", "8"))
SEED = int(os.environ.get("WM_FIFO_SEED", "1"))
MASK = (1 << WIDTH) - 1


class Bench:
    def __init__(self, dut, seed: int):
        self.dut = dut
        self.rng = random.Random(seed)
        self.model: deque[int] = deque()
        self.sent: list[int] = []   # beats the FIFO took, in order (seen at its write port)
        self.got: list[int] = []    # beats it handed out, in order (seen at its read port)
        self.corners: Counter[str] = Counter()
        self.beat = None            # the writer's pending beat (held until taken unless it gives up)
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())

    async def start(self):
        dut = self.dut
        dut.rst.value = 1
        dut.s_valid.value = 0
        dut.s_data.value = 0
        dut.m_ready.value = 0
        await ClockCycles(dut.clk, 2)
        await FallingEdge(dut.clk)
        dut.rst.value = 0
        self.model.clear()

    def check(self):
        dut, q = self.dut, self.model
        state = (f"model holds {len(q)} of {DEPTH}: s_ready {dut.s_ready.value}, "
                 f"m_valid {dut.m_valid.value}, count {dut.count.value}")
        assert int(dut.s_ready.value) == (len(q) < DEPTH), state
        assert int(dut.m_valid.value) == (len(q) > 0), state
        assert int(dut.count.value) == len(q), state
        if q:
            got = int(dut.m_data.value)
            assert got == q[0], f"m_data {got:#x}, want {q[0]:#x}; {state}"

    async def cycle(self, s_valid: bool, m_ready: bool, data: int | None = None, rst: bool = False):
        """One clock: inputs after the falling edge, outputs checked, the rising edge modelled.
        Returns (written, read)."""
        dut, q = self.dut, self.model
        await FallingEdge(dut.clk)
        if data is None:
            data = self.rng.getrandbits(WIDTH)
        dut.s_valid.value = int(s_valid)
        dut.s_data.value = data
        dut.m_ready.value = int(m_ready)
        dut.rst.value = int(rst)
        await ReadOnly()
        self.check()
        written = s_valid and bool(dut.s_ready.value)
        read = m_ready and bool(dut.m_valid.value)
        full, empty = len(q) == DEPTH, not q
        self.corners["full"] += full
        self.corners["empty"] += empty
        self.corners["write refused while read"] += full and s_valid and m_ready
        self.corners["read of empty"] += empty and m_ready
        self.corners["write into empty while ready"] += empty and s_valid and m_ready
        self.corners["write and read"] += written and read
        if read:
            self.got.append(int(dut.m_data.value))
            q.popleft()
        if written:
            self.sent.append(data)
            q.append(data)
        if rst:
            # the reset empties the FIFO: what it held is gone, what comes later starts afresh
            self.check_order()
            q.clear()
            self.sent.clear()
            self.got.clear()
        return written, read

    async def stream(self, cycles: int, p_write: float, p_read: float, hold: bool = True):
        """Random valid and ready; with hold the writer keeps its beat (and s_valid) until it is taken,
        as AXI-stream requires, otherwise it may withdraw or change it."""
        for _ in range(cycles):
            if self.beat is None and self.rng.random() < p_write:
                self.beat = self.rng.getrandbits(WIDTH)
            valid = self.beat is not None
            written, _ = await self.cycle(valid, self.rng.random() < p_read, self.beat)
            if written or (not hold and self.rng.random() < 0.5):
                self.beat = None

    async def drain(self):
        for _ in range(DEPTH + 2):
            await self.cycle(False, True)
        assert not self.model

    def check_order(self):
        assert self.got == self.sent[:len(self.got)], \
            "the beats read differ from the beats written (lost, repeated or reordered)"

    def finish(self, *corners: str):
        self.check_order()
        assert self.got == self.sent, f"{len(self.sent) - len(self.got)} beats never came out"
        missing = [c for c in corners if not self.corners[c]]
        assert not missing, f"corners not reached: {missing} ({dict(self.corners)})"
        self.dut._log.info("%d beats through a %d x %d FIFO; corners %s", len(self.got), DEPTH, WIDTH,
                           dict(self.corners))


@cocotb.test()
async def test_random_backpressure(dut):
    """Random valid and ready on both sides at several rates, in runs and bursts, full and empty."""
    tb = Bench(dut, SEED)
    await tb.start()
    for _ in range(3):
        await tb.stream(DEPTH + 3, 1.0, 0.0)      # fill up; the writer waits at the full FIFO
        await tb.stream(DEPTH + 3, 1.0, 1.0)      # read while full: writes refused, then one per cycle
        await tb.stream(DEPTH + 3, 0.0, 1.0)      # drain; the reader waits at the empty FIFO
    for p_write, p_read, hold in ((0.5, 0.5, True), (0.9, 0.3, True), (0.3, 0.9, True), (0.7, 0.7, False),
                                  (1.0, 0.5, True), (0.5, 1.0, False)):
        await tb.stream(1500, p_write, p_read, hold)
    for _ in range(60):
        # bursts: long runs of one rate, then another
        await tb.stream(tb.rng.randint(1, 3 * DEPTH + 4), tb.rng.choice((0.0, 0.2, 0.9, 1.0)),
                        tb.rng.choice((0.0, 0.2, 0.9, 1.0)))
    await tb.drain()
    both = ("write and read",) if DEPTH >= 2 else ()   # a one-entry FIFO is never neither full nor empty
    tb.finish("full", "empty", "write refused while read", "read of empty", "write into empty while ready",
              *both)


@cocotb.test()
async def test_full_rate(dut):
    """Writer always valid, reader always ready: one beat per cycle from an empty FIFO when DEPTH >= 2
    (the first comes out one cycle after it went in), one every other cycle when DEPTH = 1."""
    tb = Bench(dut, SEED + 1)
    await tb.start()
    n = 200
    writes = reads = 0
    for k in range(n):
        written, read = await tb.cycle(True, True)
        writes += written
        reads += read
        if k == 0:
            assert written and not read
    if DEPTH >= 2:
        assert (writes, reads) == (n, n - 1)
    else:
        assert (writes, reads) == ((n + 1) // 2, n // 2)
    await tb.drain()
    tb.finish("write into empty while ready")


@cocotb.test()
async def test_corners(dut):
    """Exactly DEPTH entries fit; a full FIFO read and written in one cycle takes only the read; an
    empty FIFO read yields nothing; the count follows every step."""
    tb = Bench(dut, SEED + 2)
    await tb.start()
    for k in range(DEPTH + 3):
        written, _ = await tb.cycle(True, False, data=k & MASK)
        assert written == (k < DEPTH)
    written, read = await tb.cycle(True, True, data=MASK)
    assert read and not written
    written, read = await tb.cycle(True, False, data=MASK)   # the freed place, one cycle later
    assert written and not read
    for _ in range(DEPTH):
        await tb.cycle(False, True)
    for _ in range(3):
        written, read = await tb.cycle(False, True)
        assert not written and not read
    # one entry in and out, at every fill level from 0 to DEPTH - 1: the pointers wrap everywhere
    for level in range(DEPTH):
        for _ in range(level):
            await tb.cycle(True, False)
        for _ in range(DEPTH + 1):
            await tb.cycle(True, False)
            await tb.cycle(False, True)
        await tb.drain()
    tb.finish("full", "empty", "write refused while read", "read of empty")


@cocotb.test()
async def test_reset(dut):
    """A reset empties the FIFO whatever it holds (also with a write and a read in that cycle); beats
    written afterwards come out alone and in order."""
    tb = Bench(dut, SEED + 3)
    await tb.start()
    for fill in (1, DEPTH, max(1, DEPTH - 1)):
        for _ in range(fill):
            await tb.cycle(True, False)
        assert len(tb.model) == fill
        await tb.cycle(True, True, rst=True)
        await tb.cycle(False, False)    # the outputs right after the reset (checked by the model: empty)
        assert not tb.model
        await tb.stream(4 * DEPTH + 20, 0.6, 0.6)
        await tb.drain()
        tb.beat = None
    tb.finish("empty")
