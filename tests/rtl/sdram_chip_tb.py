"""cocotb bench of the simulated board's SDRAM chip model (sim/sdram_chip.v) on its own.

The model must take a legal command sequence without a word (and return each read datum in its CAS
latency window only) and must report each violation at the command that makes it: the bench drives
the pins as the controller does (at clk's rising edge; the model samples at the falling edge) at
125 MHz, where every datasheet timing of memmap.SDRAM_TIMING spans more than one cycle, and the
model is built with FATAL = 0 so it counts violations (violations_reg, last_what_reg) instead of
stopping.
"""

from __future__ import annotations

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge
from wavemesh.device import memmap

T_NS = 8  # 125 MHz
CL = memmap.SDRAM_CAS_LATENCY
NOP, ACT, READ, WRITE, PRE, REF, MRS = "nop", "act", "read", "write", "pre", "ref", "mrs"
CODES = {NOP: 0b111, ACT: 0b011, READ: 0b101, WRITE: 0b100, PRE: 0b010, REF: 0b001, MRS: 0b000}


def cycles(ns: float) -> int:
    return -(-int(ns) // T_NS)


class TB:
    def __init__(self, dut):
        self.dut = dut
        cocotb.start_soon(Clock(dut.clk, T_NS, unit="ns").start())
        dut.cke.value = 1
        dut.cs_n.value = 0
        dut.dqm.value = 0
        dut.dq_o.value = 0
        dut.dq_oe.value = 0
        dut.ba.value = 0
        dut.a.value = 0
        self.cmd(NOP)

    def cmd(self, kind: str, ba: int = 0, a: int = 0, dq: int | None = None):
        dut = self.dut
        code = CODES[kind]
        dut.ras_n.value, dut.cas_n.value, dut.we_n.value = code >> 2 & 1, code >> 1 & 1, code & 1
        dut.ba.value = ba
        dut.a.value = a
        dut.dq_oe.value = int(dq is not None)
        dut.dq_o.value = dq or 0

    async def issue(self, kind: str, ba: int = 0, a: int = 0, dq: int | None = None, then: int = 0):
        """One command in the next cycle, then `then` cycles of NOP."""
        await RisingEdge(self.dut.clk)
        self.cmd(kind, ba, a, dq)
        await RisingEdge(self.dut.clk)
        self.cmd(NOP)
        if then:
            await ClockCycles(self.dut.clk, then)

    async def pair(self, first: tuple, second: tuple, then: int = 0):
        """Two commands in consecutive cycles (kind, bank, address each), then `then` cycles of NOP."""
        await RisingEdge(self.dut.clk)
        self.cmd(*first)
        await RisingEdge(self.dut.clk)
        self.cmd(*second)
        await RisingEdge(self.dut.clk)
        self.cmd(NOP)
        if then:
            await ClockCycles(self.dut.clk, then)

    @property
    def violations(self) -> int:
        return int(self.dut.violations_reg.value)

    @property
    def last(self) -> str:
        return self.dut.last_what_reg.value.to_bytes(byteorder="big").decode(errors="replace").strip("\x00 ")

    async def expect(self, what: str, coro):
        """Run `coro`; exactly one new violation, named `what`."""
        before = self.violations
        await coro
        await ClockCycles(self.dut.clk, 2)
        assert self.violations == before + 1 and self.last.startswith(what), (what, self.violations - before,
                                                                              self.last)

    async def legal(self, coro):
        before = self.violations
        await coro
        await ClockCycles(self.dut.clk, 2)
        assert self.violations == before, self.last


def mode_word(cl: int) -> int:
    return cl << 4  # burst length 1, sequential, CL, standard operation


@cocotb.test()
async def test_legal_sequence_and_violations(dut):
    tb = TB(dut)
    t = memmap.SDRAM_TIMING
    rcd, rp, ras, rfc = (cycles(t[k]) for k in ("T_RCD_NS", "T_RP_NS", "T_RAS_NS", "T_RFC_NS"))
    rc = cycles(t["T_RC_NS"])
    # a command before the power-up wait (and before the initialisation)
    await tb.expect("power-up wait", tb.issue(PRE, a=1 << 10, then=rp))
    await ClockCycles(dut.clk, cycles(t["T_INIT_NS"]))
    # the initialisation: PRECHARGE ALL, two REFRESH, LOAD MODE
    await tb.legal(tb.issue(PRE, a=1 << 10, then=rp))
    await tb.legal(tb.issue(REF))
    await tb.expect("tRFC", tb.issue(REF, then=rfc))  # 4 cycles after the last
    await tb.expect("mode register", tb.issue(MRS, a=mode_word(CL + 1), then=2))
    await tb.legal(tb.issue(MRS, a=mode_word(CL), then=2))
    # a row: ACTIVATE, WRITE after tRCD, READ it back in its CAS latency window
    await tb.legal(tb.issue(ACT, ba=1, a=0x155, then=rcd))
    await tb.legal(tb.issue(WRITE, ba=1, a=7, dq=0xBEEF))
    await RisingEdge(dut.clk)
    tb.cmd(READ, ba=1, a=7)
    seen = []
    for _ in range(CL + 2):
        await RisingEdge(dut.clk)
        tb.cmd(NOP)
        seen.append(int(dut.dq_i.value))
    assert seen[CL - 1] == 0xBEEF and seen.count(0xBEEF) == 1, [hex(v) for v in seen]
    # READ too soon after ACTIVATE
    await tb.expect("tRCD", tb.pair((ACT, 2, 3), (READ, 2, 0), then=ras))
    # PRECHARGE too soon after ACTIVATE
    await tb.expect("tRAS", tb.pair((ACT, 3, 3), (PRE, 3, 0), then=rp))
    # ACTIVATE of an open bank; READ of a closed one
    await tb.expect("ACTIVATE of an open bank", tb.issue(ACT, ba=1, a=1, then=rc))
    await tb.expect("READ/WRITE of a closed bank", tb.issue(READ, ba=3, a=0, then=2))
    # WRITE without its datum, and the controller driving DQ into a read datum
    await tb.expect("WRITE without its datum", tb.issue(WRITE, ba=1, a=2, then=2))
    await RisingEdge(dut.clk)
    tb.cmd(READ, ba=1, a=7)
    await RisingEdge(dut.clk)
    tb.cmd(NOP, dq=0x1234)  # DQ driven for one cycle, into the chip's datum

    async def release():
        await RisingEdge(dut.clk)
        tb.cmd(NOP)
        await ClockCycles(dut.clk, CL + 2)

    await tb.expect("DQ contention", release())
    # REFRESH with a bank open
    await tb.expect("REFRESH with a bank open", tb.issue(REF, then=rfc))
    # close every bank; two ACTIVATEs too close together
    await tb.legal(tb.issue(PRE, a=1 << 10, then=rp))
    await tb.expect("tRRD", tb.pair((ACT, 0, 9), (ACT, 2, 9), then=ras))
    await tb.legal(tb.issue(PRE, a=1 << 10, then=rp))
    # a refresh in time, then one too late
    await tb.legal(tb.issue(REF, then=rfc))
    await tb.expect("tREFI", ClockCycles(dut.clk, cycles(t["T_REFI_NS"]) + 2))
    await tb.legal(tb.issue(REF, then=rfc))
