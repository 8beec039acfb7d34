"""cocotb bench of the SoC's FPGA stage (rtl/soc_accel.v) with Python models of its three memories.

The height memory is loaded with the samples; after START and DONE, the coefficient memory must hold
every level's details in the layout of wm_details_offset (level by level from m = 1, row-major,
d1 d2 d3 per cell) as wavemesh.haar.decompose makes them, the template memory one entry per block
{label, template id} as wavemesh.label.label_blocks makes them, the registers the counts, and a
refused configuration must set ERROR and touch nothing.
"""

from __future__ import annotations

import logging

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, RisingEdge
from wavemesh import synth
from wavemesh.haar import decompose
from wavemesh.heightfield import from_array
from wavemesh.label import label_blocks
from wavemesh.memmap import ACCEL, TOUT_LABEL_SHIFT, TOUT_TEMPLATE_MASK

REG = {r.name: r.offset for r in ACCEL.registers}


class TB:
    """Clock, reset, register bus and the three memories (synchronous, one access per cycle)."""

    def __init__(self, dut):
        self.dut = dut
        self.log = logging.getLogger("cocotb.tb")
        self.height = {}
        self.coef = {}
        self.tout = {}
        self.coef_writes = 0
        self.tout_writes = 0
        self.height_reads_idle = 0
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
        cocotb.start_soon(self._memories())

    async def _memories(self):
        dut = self.dut
        while True:
            await FallingEdge(dut.clk)
            rdata = None
            if int(dut.height_en.value):
                if not int(dut.busy.value):
                    self.height_reads_idle += 1
                rdata = self.height.get(int(dut.height_addr.value), 0)
            if int(dut.coef_en.value):
                v = int(dut.coef_wdata.value)
                self.coef[int(dut.coef_addr.value)] = v - (1 << 18) if v >> 17 else v
                self.coef_writes += 1
            if int(dut.tout_en.value):
                self.tout[int(dut.tout_addr.value)] = int(dut.tout_wdata.value)
                self.tout_writes += 1
            await RisingEdge(dut.clk)
            if rdata is not None:
                dut.height_rdata.value = rdata

    async def reset(self):
        dut = self.dut
        dut.rst.value = 1
        dut.bus_valid.value = 0
        dut.bus_addr.value = 0
        dut.bus_wdata.value = 0
        dut.bus_wstrb.value = 0
        dut.height_rdata.value = 0
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
        flat = samples.astype(np.int64).ravel().tolist()
        if len(flat) % 2:
            flat.append(0xBEEF)  # the word's unused high half must not matter
        self.height = {k: flat[2 * k] | flat[2 * k + 1] << 16 for k in range(len(flat) // 2)}

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
        assert total < 2 * w * h + 100, f"{name}: {total} cycles for {w * h} samples"
        tb.log.info("%s: %d coefficients, %d blocks; cycles filter %d template %d total %d",
                    name, len(coef), len(tout), cf, ct, total)
    assert tb.height_reads_idle == 0


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
        assert not tb.coef and not tb.tout
    # and a good run afterwards
    samples = from_array(synth.ball(16)).samples
    tb.load(samples)
    status = await tb.run(16, 16, 2, 5)
    assert status == 2
    assert await tb.read("MAX_LEVELS") == maxl
