"""cocotb bench: the iCEBreaker board top (rtl/boards/icebreaker_top.v: stage_uart behind the UART pins).

The bench is the host's end of the serial line, bit by bit on the RX and TX pins at the top's rate: it
sends a job's header and samples as UART frames and reads the bytes the board sends back, and every
block's entry must be the reference model's TOUT entry (wavemesh.model.label, as tests/rtl/soc_accel_tb.py
computes them).  Jobs run back to back on one reset, with a refused header between them; garbage
(stray bytes, a wire-protocol frame other than HELLO) before a header is skipped, and a header or job
the host abandons is dropped after the silence timeout, the next job unharmed.  HELLO is answered with
a HELLO_REPLY frame (the host's own parser checks its CRC, and its fields must be the stage's
parameters), also when its seq and CRC need SLIP escapes.
"""

from __future__ import annotations

import json
import os
import struct

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, RisingEdge
from soc_accel_tb import expected
from wavemesh.device import protocol as P
from wavemesh.device.link import SlipDecoder, encode_frame, parse_frame
from wavemesh.device.stream import DeviceInfo
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array

# the top's parameters for this bench: wavemesh.harness.rtl_runner.ICEBREAKER_BENCH_PARAMETERS


def param(dut, path: str) -> int:
    """A parameter of the design, e.g. "stage_inst.MAX_WIDTH"; from WM_TB_PARAMS (JSON) when it is set
    (the synthesised netlist has no parameters: tools/postsynth.py)."""
    if "WM_TB_PARAMS" in os.environ:
        return int(json.loads(os.environ["WM_TB_PARAMS"])[path])
    obj = dut
    for part in path.split("."):
        obj = getattr(obj, part)
    return int(obj.value)


class Line:
    """The host's end of the UART: frames onto RX, frames from TX (8N1, CLK_HZ / BAUD clocks per bit)."""

    def __init__(self, dut):
        self.dut = dut
        clk_hz, baud = param(dut, "CLK_HZ"), param(dut, "BAUD")
        self.div = (clk_hz + baud // 2) // baud
        self.received: list[int] = []
        dut.RX.value = 1
        cocotb.start_soon(self._receive())

    async def send(self, data: bytes) -> None:
        for byte in data:
            bits = [0] + [(byte >> k) & 1 for k in range(8)] + [1]
            for b in bits:
                self.dut.RX.value = b
                await ClockCycles(self.dut.CLK, self.div)

    async def _receive(self) -> None:
        while True:
            await FallingEdge(self.dut.TX)
            await ClockCycles(self.dut.CLK, self.div // 2)
            assert int(self.dut.TX.value) == 0, "a glitch on TX, not a start bit"
            byte = 0
            for k in range(8):
                await ClockCycles(self.dut.CLK, self.div)
                byte |= int(self.dut.TX.value) << k
            await ClockCycles(self.dut.CLK, self.div)
            assert int(self.dut.TX.value) == 1, "stop bit"
            self.received.append(byte)

    async def read(self, n: int, timeout_bytes: int = 64) -> bytes:
        """The next n bytes from the board (fails when they do not come within a generous time)."""
        limit = (n + timeout_bytes) * 12 * self.div
        for _ in range(limit):
            if len(self.received) >= n:
                break
            await RisingEdge(self.dut.CLK)
        assert len(self.received) >= n, f"expected {n} bytes, got {len(self.received)}"
        out, self.received = bytes(self.received[:n]), self.received[n:]
        return out


    async def read_frame(self, limit: int = 160):
        """The next SLIP frame from the board, checked and split by the host's link code."""
        decoder = SlipDecoder()
        for _ in range(limit):
            got = decoder.feed(await self.read(1))
            if got:
                assert isinstance(got[0], bytes), got[0]
                return parse_frame(got[0])
        raise AssertionError(f"no frame within {limit} bytes")


def header(w: int, h: int, m: int, tau: int) -> bytes:
    return b"WM" + struct.pack("<HHB", w, h, m) + tau.to_bytes(3, "little")


CASES = [
    ("ball 32x32 M=3", lambda: synth.ball(32), 3, 40),
    ("random 37x23 M=2 tau=0", lambda: np.random.default_rng(3).integers(0, 65536, (23, 37)), 2, 0),
    ("box 2x2 M=1", lambda: np.array([[0, 9], [65535, 3]]), 1, 1),
    ("f3 45x19 M=1", lambda: synth.f3(45)[:19], 1, 10),
    ("f1 40x40 M=3, tau above 18 bits", lambda: synth.f1(40), 3, 1 << 20),
]


@cocotb.test()
async def test_jobs_over_the_uart(dut):
    """Each job: "OK", then the reference TOUT entries in raster order; bad headers get "E" + reason."""
    cocotb.start_soon(Clock(dut.CLK, 10, unit="ns").start())
    dut.BTN_N.value = 1
    line = Line(dut)
    await ClockCycles(dut.CLK, 40)  # the power-on reset
    assert int(dut.LEDR_N.value) == 1, "busy right after reset"

    # (none holds "WM" outside a frame: that starts a header; a DATA frame with a header inside is skipped)
    data = encode_frame(P.FrameType.DATA, 0x57, bytes(4) + header(8, 8, 1, 0))
    garbage = [b"\x00\xc0\xc0A", b"W", b"WW\x00M", data, b"\xc0WX"]
    for k, (name, make, m, tau) in enumerate(CASES):
        samples = from_array(np.asarray(make())).samples
        h, w = samples.shape
        await line.send(garbage[k % len(garbage)] + header(w, h, m, tau))
        assert await line.read(2) == b"OK", name
        await line.send(samples.astype("<u2").tobytes())
        _, tout = expected(samples, m, min(tau, (1 << 18) - 1))
        got = await line.read(2 * len(tout))
        assert list(struct.unpack(f"<{len(tout)}H", got)) == tout, f"{name}: template entries differ"
        await ClockCycles(dut.CLK, 4)
        assert int(dut.LEDR_N.value) == 1, f"{name}: still busy after the last entry"
        assert int(dut.LEDG_N.value) == 1, f"{name}: RX overrun"

        # a refused header between jobs: the board answers and waits for the next header
        max_w, max_m = param(dut, "stage_inst.MAX_WIDTH"), param(dut, "stage_inst.MAX_LEVELS")
        bad = [header(1, 5, 1, 0), header(max_w + 1, 5, 1, 0), header(8, 8, 0, 0), header(8, 8, max_m + 1, 0)]
        reasons = [b"EW", b"EW", b"EM", b"EM"]
        await line.send(bad[k % len(bad)])
        assert await line.read(2) == reasons[k % len(bad)], f"after {name}"
    assert not line.received, "bytes nobody asked for"


@cocotb.test()
async def test_abandoned_header_and_job_are_dropped(dut):
    """A header cut short, and a job whose samples stop, are dropped after the silence timeout (the
    stage reset); the next job gives the reference entries."""
    cocotb.start_soon(Clock(dut.CLK, 10, unit="ns").start())
    dut.BTN_N.value = 1
    line = Line(dut)
    await ClockCycles(dut.CLK, 40)
    silence = 1 << param(dut, "stage_inst.TIMEOUT_BITS")
    samples = from_array(synth.ball(24)).samples
    _, tout = expected(samples, 2, 30)
    good = header(24, 24, 2, 30)

    await line.send(good[:6])  # a header cut short
    await ClockCycles(dut.CLK, silence + 100)
    await line.send(good)
    assert await line.read(2) == b"OK"
    await line.send(samples.astype("<u2").tobytes()[:301])  # a job cut short (an odd byte count)
    await ClockCycles(dut.CLK, silence + 100)
    assert int(dut.LEDR_N.value) == 1, "still busy after the timeout"
    line.received.clear()  # entries of the dropped job's first rows

    await line.send(good)
    assert await line.read(2) == b"OK"
    await line.send(samples.astype("<u2").tobytes())
    got = await line.read(2 * len(tout))
    assert list(struct.unpack(f"<{len(tout)}H", got)) == tout


@cocotb.test()
async def test_hello(dut):
    """HELLO (seq 7, and seq 0xC0 that goes escaped) is answered with a HELLO_REPLY of the same seq that
    states the stage's parameters; a job after it is exact."""
    cocotb.start_soon(Clock(dut.CLK, 10, unit="ns").start())
    dut.BTN_N.value = 1
    line = Line(dut)
    await ClockCycles(dut.CLK, 40)
    for seq in (7, 0xC0, 0xDB):
        await line.send(encode_frame(P.FrameType.HELLO, seq, P.HELLO.pack(version=P.VERSION)))
        f = await line.read_frame()
        assert (f.type, f.seq) == (P.FrameType.HELLO_REPLY, seq)
        info = DeviceInfo.from_fields(f.fields())
        assert f.payload[P.HELLO_REPLY.size - 10:P.HELLO_REPLY.size - 8] == bytes(2), "reserved"
    clk_hz = param(dut, "CLK_HZ")
    silence_ms = (1 << param(dut, "stage_inst.TIMEOUT_BITS")) * 1000 // clk_hz
    assert info == DeviceInfo(
        version=P.VERSION, fw_version=(1, 0), name="wm-stage", max_width=param(dut, "stage_inst.MAX_WIDTH"),
        max_height=param(dut, "stage_inst.MAX_HEIGHT"),
        max_samples=param(dut, "stage_inst.MAX_WIDTH") * param(dut, "stage_inst.MAX_HEIGHT"), tri_capacity=0,
        max_levels=param(dut, "stage_inst.MAX_LEVELS"), window=1, max_payload=P.MIN_PAYLOAD, clk_hz=clk_hz,
        baud=param(dut, "BAUD"), features=P.FEATURE_STAGE, byte_timeout_ms=silence_ms, ack_timeout_ms=0,
        session_timeout_ms=silence_ms, ack_retries=0, idle_timeout_ms=0, write_timeout_ms=0)

    # a HELLO, at once a header: the header's "OK" follows the whole reply
    samples = from_array(synth.ball(12)).samples
    _, tout = expected(samples, 2, 30)
    hello = encode_frame(P.FrameType.HELLO, 1, P.HELLO.pack(version=P.VERSION))
    await line.send(hello + header(12, 12, 2, 30))
    f = await line.read_frame()
    assert (f.type, f.seq) == (P.FrameType.HELLO_REPLY, 1)
    assert await line.read(2) == b"OK"
    await line.send(samples.astype("<u2").tobytes())
    got = await line.read(2 * len(tout))
    assert list(struct.unpack(f"<{len(tout)}H", got)) == tout
    await ClockCycles(dut.CLK, 20 * line.div)
    assert not line.received, "bytes nobody asked for"
