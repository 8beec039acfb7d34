"""cocotb bench of rtl/soc_uart.v (uart_rx, uart_tx, two wm_fifo): the UART at its pins.

cocotbext-uart's UartSource drives the RX pin and its UartSink reads the TX pin; the register bus
(DATA, STATUS, DIV) is driven as the CPU would.  Run by tests/rtl/test_uart_soc.py with small
FIFOs (RX_DEPTH, TX_DEPTH from the environment) so that full FIFOs are quick to reach.  Every
received byte list is compared with what was sent, byte by byte.
"""

from __future__ import annotations

import logging
import os
import random

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, RisingEdge, Timer
from cocotbext.uart import UartSink, UartSource
from wavemesh.device import memmap

CLOCK_NS = 10
RX_DEPTH = int(os.environ.get("UART_RX_DEPTH", "8"))
TX_DEPTH = int(os.environ.get("UART_TX_DEPTH", "8"))
DIV_RESET = int(os.environ.get("UART_DIV_RESET", "16"))

DATA = 0x00
STATUS = 0x04
DIV = 0x08
F = {f.name: f for r in memmap.UART.registers for f in r.fields}
RX_VALID = F["RX_VALID"].mask
RX_FULL = F["RX_FULL"].mask
TX_FULL = F["TX_FULL"].mask
TX_EMPTY = F["TX_EMPTY"].mask
TX_IDLE = F["TX_IDLE"].mask
RX_OVERRUN = F["RX_OVERRUN"].mask
RX_FRAME_ERR = F["RX_FRAME_ERR"].mask
TX_OVERRUN = F["TX_OVERRUN"].mask
EMPTY = F["EMPTY"].mask


class TB:
    """Clock, reset, register bus, and the UART models at the pins."""

    def __init__(self, dut):
        self.dut = dut
        self.log = logging.getLogger("cocotb.tb")
        logging.getLogger(f"cocotb.{dut.rxd._path}").setLevel(logging.WARNING)
        logging.getLogger(f"cocotb.{dut.txd._path}").setLevel(logging.WARNING)
        cocotb.start_soon(Clock(dut.clk, CLOCK_NS, unit="ns").start())
        dut.bus_valid.value = 0
        dut.bus_addr.value = 0
        dut.bus_wdata.value = 0
        dut.bus_wstrb.value = 0
        dut.bypass.value = 0
        dut.rx_redirect.value = 0
        dut.m_axis_rx_tready.value = 0
        dut.s_axis_rx_tdata.value = 0
        dut.s_axis_rx_tvalid.value = 0
        dut.m_axis_tx_tready.value = 0
        self.source = UartSource(dut.rxd, baud=self.baud(DIV_RESET))
        self.sink = UartSink(dut.txd, baud=self.baud(DIV_RESET))

    @staticmethod
    def baud(div: int) -> float:
        return 1e9 / (div * CLOCK_NS)

    def set_line_baud(self, div: int) -> None:
        """Both pin models to `div` clock cycles per bit (the models' baud setter is broken: restart)."""
        for model in (self.source, self.sink):
            model._baud = self.baud(div)
            model._restart()

    async def reset(self):
        self.dut.rst.value = 1
        await ClockCycles(self.dut.clk, 4)
        self.dut.rst.value = 0
        await ClockCycles(self.dut.clk, 4)

    async def access(self, addr: int, wdata: int = 0, wstrb: int = 0) -> int:
        """One bus request (read when wstrb is 0); returns the read data of the next cycle."""
        await FallingEdge(self.dut.clk)
        self.dut.bus_valid.value = 1
        self.dut.bus_addr.value = addr
        self.dut.bus_wdata.value = wdata
        self.dut.bus_wstrb.value = wstrb
        await FallingEdge(self.dut.clk)
        self.dut.bus_valid.value = 0
        self.dut.bus_wstrb.value = 0
        return int(self.dut.bus_rdata.value)

    async def read(self, addr: int) -> int:
        return await self.access(addr)

    async def write(self, addr: int, value: int) -> None:
        await self.access(addr, value, 0xF)

    async def status(self) -> int:
        return await self.read(STATUS)

    async def set_div(self, div: int) -> None:
        await self.write(DIV, div)
        self.set_line_baud(div)

    async def receive_all(self) -> list[int]:
        """Pop the RX FIFO until DATA says EMPTY."""
        out = []
        while True:
            v = await self.read(DATA)
            if v & EMPTY:
                return out
            out.append(v & 0xFF)

    async def wait_rx_idle(self, div: int) -> None:
        await self.source.wait()
        await ClockCycles(self.dut.clk, 3 * div)


@cocotb.test()
async def test_reset_state(dut):
    tb = TB(dut)
    await tb.reset()
    assert await tb.read(DIV) == DIV_RESET
    st = await tb.status()
    assert st == TX_EMPTY | TX_IDLE, hex(st)
    assert await tb.read(DATA) == EMPTY
    assert int(dut.txd.value) == 1
    await tb.write(DIV, 1)
    assert await tb.read(DIV) == memmap.UART_DIV_MIN  # raised to the smallest divisor
    await tb.write(0x40, 0xFFFF)  # unmapped: ignored, reads 0
    assert await tb.read(0x40) == 0


@cocotb.test()
@cocotb.parametrize(div=[16, 50])
async def test_rx_tx(dut, div):
    """Bytes in at the RX pin and out at the TX pin at two baud divisors."""
    tb = TB(dut)
    await tb.reset()
    await tb.set_div(div)
    rng = random.Random(div)
    for _ in range(3):
        sent = [rng.randrange(256) for _ in range(rng.randint(1, RX_DEPTH))]
        await tb.source.write(sent)
        await tb.wait_rx_idle(div)
        st = await tb.status()
        assert st & RX_VALID and st >> 16 == len(sent), hex(st)
        assert await tb.receive_all() == sent
        assert not (await tb.status()) & (RX_OVERRUN | RX_FRAME_ERR)

        out = [rng.randrange(256) for _ in range(rng.randint(1, TX_DEPTH))]
        for b in out:
            await tb.write(DATA, b)
        while not (await tb.status()) & TX_IDLE:
            await ClockCycles(dut.clk, div)
        await Timer(div * CLOCK_NS, "ns")  # the sink reads the stop bit
        got = tb.sink.read_nowait()
        assert list(got) == out
        assert not (await tb.status()) & TX_OVERRUN


@cocotb.test()
async def test_rx_fifo_full(dut):
    """More bytes than the RX FIFO holds: the first RX_DEPTH kept in order, the rest counted as overrun."""
    tb = TB(dut)
    await tb.reset()
    div = DIV_RESET
    sent = list(range(0x30, 0x30 + RX_DEPTH + 3))
    await tb.source.write(sent)
    await tb.wait_rx_idle(div)
    st = await tb.status()
    assert st & RX_FULL and st & RX_OVERRUN and st >> 16 == RX_DEPTH, hex(st)
    assert await tb.receive_all() == sent[:RX_DEPTH]
    st = await tb.status()
    assert st & RX_OVERRUN and not st & RX_FULL  # sticky until cleared
    await tb.write(STATUS, RX_OVERRUN)
    assert not (await tb.status()) & RX_OVERRUN
    # and it works again
    await tb.source.write([0xA5, 0x5A])
    await tb.wait_rx_idle(div)
    assert await tb.receive_all() == [0xA5, 0x5A]


@cocotb.test()
async def test_tx_fifo_full(dut):
    """Writes faster than the line: TX_FULL, writes dropped and counted, the accepted bytes sent in order."""
    tb = TB(dut)
    await tb.reset()
    div = DIV_RESET
    out = list(range(0x40, 0x40 + TX_DEPTH + 4))
    saw_full = False
    for b in out:
        await tb.write(DATA, b)
    st = await tb.status()
    saw_full = bool(st & TX_FULL)
    assert saw_full and st & TX_OVERRUN, hex(st)
    while not (await tb.status()) & TX_IDLE:
        await ClockCycles(dut.clk, div)
    await Timer(div * CLOCK_NS, "ns")
    got = list(tb.sink.read_nowait())
    # one byte went straight to the transmitter, TX_DEPTH waited in the FIFO, the rest were dropped
    assert got == out[:TX_DEPTH + 1]
    await tb.write(STATUS, TX_OVERRUN)
    assert (await tb.status()) & (TX_OVERRUN | TX_EMPTY | TX_IDLE) == TX_EMPTY | TX_IDLE


@cocotb.test()
async def test_frame_error_and_glitch(dut):
    """A stop bit of 0 drops the byte and sets RX_FRAME_ERR; a short low glitch is no start bit."""
    tb = TB(dut)
    await tb.reset()
    div = DIV_RESET
    tb.source._run_cr.kill()  # drive the pin by hand
    bit = div * CLOCK_NS

    async def frame(byte: int, stop: int):
        dut.rxd.value = 0
        await Timer(bit, "ns")
        for k in range(8):
            dut.rxd.value = byte >> k & 1
            await Timer(bit, "ns")
        dut.rxd.value = stop
        await Timer(bit, "ns")

    await frame(0x3C, 0)  # bad stop bit, then the line stays low (a break) for a while
    await Timer(4 * bit, "ns")
    dut.rxd.value = 1
    await Timer(2 * bit, "ns")
    st = await tb.status()
    assert st & RX_FRAME_ERR and not st & RX_VALID, hex(st)
    await tb.write(STATUS, RX_FRAME_ERR)

    dut.rxd.value = 0  # glitch shorter than half a bit
    await Timer(2 * CLOCK_NS, "ns")
    dut.rxd.value = 1
    await Timer(2 * bit, "ns")
    await frame(0xC3, 1)
    await Timer(2 * bit, "ns")
    assert await tb.receive_all() == [0xC3]
    assert not (await tb.status()) & (RX_FRAME_ERR | RX_OVERRUN)


@cocotb.test()
async def test_bypass(dut):
    """Fast mode: bytes enter the RX FIFO from s_axis_rx with back-pressure (none lost) and leave the
    TX FIFO on m_axis_tx; the pins stay idle."""
    tb = TB(dut)
    await tb.reset()
    dut.bypass.value = 1
    sent = list(range(RX_DEPTH + 5))
    got_rx = []

    async def feed():
        for b in sent:
            dut.s_axis_rx_tdata.value = b
            dut.s_axis_rx_tvalid.value = 1
            while True:
                await RisingEdge(dut.clk)
                if int(dut.s_axis_rx_tready.value):
                    break
        dut.s_axis_rx_tvalid.value = 0

    feeder = cocotb.start_soon(feed())
    while len(got_rx) < len(sent):
        got_rx += await tb.receive_all()
    await feeder
    assert got_rx == sent
    assert not (await tb.status()) & RX_OVERRUN

    out = [0x11, 0x22, 0x33]
    for b in out:
        await tb.write(DATA, b)
    got_tx = []
    dut.m_axis_tx_tready.value = 1
    for _ in range(10):
        await RisingEdge(dut.clk)
        if int(dut.m_axis_tx_tvalid.value):
            got_tx.append(int(dut.m_axis_tx_tdata.value))
    dut.m_axis_tx_tready.value = 0
    assert got_tx == out
    assert int(dut.txd.value) == 1
    assert tb.sink.empty()
