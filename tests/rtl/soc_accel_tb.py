"""cocotb bench of the SoC's FPGA stage (rtl/soc_accel.v) with Python models of its three memories.

The memories sit behind streams as in the SoC (the SDRAM's stream reader and writers): the height
stream starts on height_start with the count asked for, and every stream stalls at random (the
height data gaps, the coefficient and template entries' back-pressure), and mem_idle stays low for a
while after the last entry, so DONE must wait for it.  After START and DONE, the coefficient memory must hold
every level's details in the layout of wm_details_offset (level by level from m = 1, row-major,
d1 d2 d3 per cell) as wavemesh.model.haar.decompose makes them, the template memory one entry per block
{label, template id} as wavemesh.model.label.label_blocks makes them, the registers the counts, and a
refused configuration must set ERROR and touch nothing.
"""

from __future__ import annotations

import logging
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, RisingEdge
from wavemesh.device.memmap import ACCEL, TOUT_LABEL_SHIFT, TOUT_TEMPLATE_MASK
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import decompose
from wavemesh.model.label import label_blocks

REG = {r.name: r.offset for r in ACCEL.registers}


class TB:
    """Clock, reset, register bus and the three memories (synchronous, one access per cycle)."""

    def __init__(self, dut, seed: int = 1):
        self.dut = dut
        self.log = logging.getLogger("cocotb.tb")
        self.rng = random.Random(seed)
        self.height = []
        self.coef = {}
        self.tout = {}
        self.coef_writes = 0
        self.tout_writes = 0
        self.height_starts_idle = 0
        self.stream = []      # samples still to hand out
        self.pending = 0      # cycles mem_idle stays low after an entry
        self.early_done = 0   # DONE rose while mem_idle was low
        self.done = 0
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
        cocotb.start_soon(self._memories())

    async def _memories(self):
        dut = self.dut
        while True:
            await FallingEdge(dut.clk)
            done = int(dut.done_reg.value)
            if done and not self.done and self.pending:
                self.early_done += 1
            self.done = done
            # what the DUT does at the coming rising edge, with this cycle's valid/ready
            if int(dut.s_axis_height_tvalid.value) and int(dut.s_axis_height_tready.value):
                self.stream.pop(0)
            if int(dut.m_axis_coef_tvalid.value) and int(dut.m_axis_coef_tready.value):
                v = int(dut.m_axis_coef_tdata.value)
                self.coef[int(dut.m_axis_coef_tuser.value)] = v - (1 << 18) if v >> 17 else v
                self.coef_writes += 1
                self.pending = self.rng.randrange(12)
            if int(dut.m_axis_tout_tvalid.value) and int(dut.m_axis_tout_tready.value):
                self.tout[int(dut.m_axis_tout_tuser.value)] = int(dut.m_axis_tout_tdata.value)
                self.tout_writes += 1
                self.pending = self.rng.randrange(12)
            if int(dut.height_start.value):
                if self.stream:
                    self.height_starts_idle += 1  # a new stream while the last one runs
                self.stream = list(self.height[:int(dut.height_count.value)])
            await RisingEdge(dut.clk)
            # the next cycle's stream state: random gaps and back-pressure
            self.pending = max(0, self.pending - 1)
            dut.mem_idle.value = int(self.pending == 0)
            ok = bool(self.stream) and self.rng.random() < 0.7
            dut.s_axis_height_tvalid.value = int(ok)
            dut.s_axis_height_tdata.value = self.stream[0] if ok else 0xDEAD
            dut.m_axis_coef_tready.value = int(self.rng.random() < 0.6)
            dut.m_axis_tout_tready.value = int(self.rng.random() < 0.5)

    async def reset(self):
        dut = self.dut
        dut.rst.value = 1
        dut.bus_valid.value = 0
        dut.bus_addr.value = 0
        dut.bus_wdata.value = 0
        dut.bus_wstrb.value = 0
        dut.s_axis_height_tvalid.value = 0
        dut.s_axis_height_tdata.value = 0
        dut.m_axis_coef_tready.value = 0
        dut.m_axis_tout_tready.value = 0
        dut.mem_idle.value = 1
        await ClockCycles(dut.clk, 3)
        dut.rst.value = 0
        await ClockCycles(dut.clk, 2)

    async def write(self, name: str, value: int):
        dut = self.dut
        await RisingEdge(dut.clk)
        dut.bus_valid.value = 1
        dut.bus_addr.value = REG[name]
        dut.bus_wdata.value = value
        dut.bus_wstrb.value = 0xF
        await RisingEdge(dut.clk)
        dut.bus_valid.value = 0
        dut.bus_wstrb.value = 0

    async def read(self, name: str) -> int:
        dut = self.dut
        await RisingEdge(dut.clk)
        dut.bus_valid.value = 1
        dut.bus_addr.value = REG[name]
        dut.bus_wstrb.value = 0
        await RisingEdge(dut.clk)
        dut.bus_valid.value = 0
        await FallingEdge(dut.clk)
        return int(dut.bus_rdata.value)

    def load(self, samples: np.ndarray):
        # the height memory's samples, and more behind them that the stream must not reach
        self.height = samples.astype(np.int64).ravel().tolist() + [0xBEEF] * 7

    async def run(self, w: int, h: int, m: int, tau: int, timeout: int = 200000) -> int:
        for name, v in (("WIDTH", w), ("HEIGHT", h), ("LEVELS", m), ("TAU", tau)):
            await self.write(name, v)
        await self.write("CTRL", 1)
        for _ in range(timeout // 64):
            status = await self.read("STATUS")
            if status & 2:
                return status
            await ClockCycles(self.dut.clk, 60)
        raise AssertionError("the stage never finished")


def expected(samples: np.ndarray, m: int, tau: int):
    """COEF entries (wm_details layout) and TOUT entries of the reference model."""
    h, w = samples.shape
    coef = []
    levels = decompose(samples, m)
    for lv in levels:
        cells = np.stack([lv.d1, lv.d2, lv.d3], axis=-1)
        coef += cells.ravel().tolist()
    lab = label_blocks(levels[-1], tau, w, h)
    tout = (lab.label.astype(np.int64) << TOUT_LABEL_SHIFT | lab.template).ravel().tolist()
    return coef, tout


CASES = [
    ("ball 32x32 M=3", lambda: synth.ball(32), 3, 40),
    ("random 37x23 M=3 tau=0", lambda: np.random.default_rng(3).integers(0, 65536, (23, 37)), 3, 0),
    ("f1 64x48 M=4", lambda: synth.f1(64)[:48], 4, 200),
    ("box 2x2 M=1", lambda: np.array([[0, 9], [65535, 3]]), 1, 1),
    ("odd 33x17 M=5 (M above the blocks)",
     lambda: np.random.default_rng(5).integers(0, 4000, (17, 33)), 5, 100),
    ("f3 45x19 M=2", lambda: synth.f3(45)[:19], 2, 10),
]


@cocotb.test()
async def test_coefficients_and_templates(dut):
    """Every case: COEF and TOUT equal the reference entry for entry, nothing else is written."""
    tb = TB(dut)
    await tb.reset()
    for name, make, m, tau in CASES:
        samples = from_array(np.asarray(make())).samples
        h, w = samples.shape
        tb.load(samples)
        tb.coef, tb.tout = {}, {}
        tb.coef_writes = tb.tout_writes = 0
        status = await tb.run(w, h, m, tau)
        assert status == 2, f"{name}: STATUS {status:#x}"
        coef, tout = expected(samples, m, tau)
        assert tb.coef_writes == len(coef), name
        assert [tb.coef.get(i) for i in range(len(coef))] == coef, name
        assert tb.tout_writes == len(tout), name
        got = [tb.tout.get(i) for i in range(len(tout))]
        assert got == tout, f"{name}: template entries differ"
        assert all(v >> 9 == 0 and (v & TOUT_TEMPLATE_MASK) < 64 for v in got)
        assert await tb.read("COEFS") == len(coef)
        assert await tb.read("BLOCKS") == len(tout)
        cf, ct, total = (await tb.read("CYC_FILTER"), await tb.read("CYC_TEMPLATE"),
                         await tb.read("CYC_TOTAL"))
        assert 0 < cf <= total and 0 < ct <= total
        assert total < 8 * w * h + 200, f"{name}: {total} cycles for {w * h} samples"
        assert not tb.stream, f"{name}: {len(tb.stream)} samples not taken"
        tb.log.info("%s: %d coefficients, %d blocks; cycles filter %d template %d total %d",
                    name, len(coef), len(tout), cf, ct, total)
    assert tb.height_starts_idle == 0 and tb.early_done == 0


@cocotb.test()
async def test_refused_configurations(dut):
    """W, H, M out of range, W H above the height memory, too many blocks: ERROR, nothing written."""
    tb = TB(dut)
    await tb.reset()
    maxw = int(dut.MAX_WIDTH.value)
    maxl = int(dut.MAX_LEVELS.value)
    # (the bench's build: 64 x 64, 4000 samples, 24 block columns, 512 template entries)
    bad = [(1, 8, 1), (8, 1, 1), (8, 8, 0), (8, 8, maxl + 1), (maxw + 1, 4, 2), (8, maxw + 1, 2),
           (64, 63, 2),  # W H above the height memory
           (64, 8, 1),   # 32 block columns above MAX_COLS
           (48, 48, 1)]  # 24 x 24 blocks above TOUT
    for w, h, m in bad:
        tb.coef, tb.tout = {}, {}
        status = await tb.run(w, h, m, 0)
        assert status == 6, f"{w}x{h} M={m}: STATUS {status:#x}"
        assert not tb.coef and not tb.tout and not tb.stream
    # and a good run afterwards
    samples = from_array(synth.ball(16)).samples
    tb.load(samples)
    status = await tb.run(16, 16, 2, 5)
    assert status == 2
    assert await tb.read("MAX_LEVELS") == maxl
