"""cocotb bench of rtl/upload_rx.v (the upload block) against the Python model of the protocol.

The byte source sends SLIP frames built by wavemesh.device.link (header, payload, CRC) with random gaps; the
DATA frames carry the samples of a height field (and mask words past W H) as wavemesh.device.coding's
SampleEncoder cuts them (Rice-coded or raw, per frame).  Among them: corrupted frames (a byte
changed, a bad escape, a frame cut short, bytes after the CRC, a length above MAX_PAYLOAD, junk
between frames, a silence past the timeout, a flush), resends after them (go-back-N), repeats from
earlier offsets (which the line buffer no longer holds: the reload from the SDRAM), gaps, DATA
frames that fail the header checks, Rice streams one byte short or long (good CRC), other frame
types, DATA frames while disarmed.

The model (`Model`) is the firmware's DATA logic: the header checks in its order, the Rice decoding
of wavemesh.device.coding.decode on the samples stored so far, `next` and the CRC of samples 0 .. next-1.
The CPU side takes every held frame in order and compares its header, its payload (read from the
payload buffer word by word), its code, next and the CRC with the model's, and the count of dropped
frames before it.  The SDRAM is a memory behind the addressed writer, whose beats land a random time
after they are taken (wa_busy meanwhile), and the stream reader, which answers with random gaps; at
the end its samples 0 .. W H - 1 must be the height field's.  Back-pressure everywhere: the byte
source, the writer's ready, the read command's ready, the read data, the CPU's release.

Parameters come from the environment: WM_UPLOAD_SEED, WM_UPLOAD_W, WM_UPLOAD_H.
"""

from __future__ import annotations

import os
import random
import struct
import zlib
from collections import deque

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge
from wavemesh.device import coding
from wavemesh.device import protocol as P
from wavemesh.device.link import encode_frame, frame_bytes, slip_encode

SEED = int(os.environ.get("WM_UPLOAD_SEED", "1"))
W = int(os.environ.get("WM_UPLOAD_W", "37"))
H = int(os.environ.get("WM_UPLOAD_H", "23"))
TIMEOUT = 300
CODE_OK, CODE_LENGTH, CODE_OFFSET, CODE_GAP, CODE_STREAM = range(5)


def field(rng: random.Random, w: int, h: int) -> np.ndarray:
    """Smooth terrain with noise, steps and the 16-bit extremes (escapes, wrap-around residuals)."""
    y, x = np.mgrid[0:h, 0:w]
    z = 30000 + 9000 * np.sin(x / 7.0) * np.cos(y / 5.0) + np.array([[rng.gauss(0, 40) for _ in range(w)]
                                                                     for _ in range(h)])
    z[h // 3:, w // 2:] += 12000  # a step
    z = np.clip(z, 0, 65535).astype(np.uint16)
    for _ in range(6):
        z[rng.randrange(h), rng.randrange(w)] = rng.choice([0, 65535])
    return z


class Model:
    """The firmware's DATA logic (proto.c's do_data) over the samples the device holds."""

    def __init__(self, w: int, samples: np.ndarray, total: int):
        self.w, self.wh, self.total = w, samples.size, total
        self.stored = np.zeros(samples.size, np.uint16)
        self.next = 0     # the block's: samples stored in order, below W H
        self.fw_next = 0  # the firmware's: words stored, the mask's too

    def crc(self) -> int:
        return zlib.crc32(self.stored[:self.next].astype("<u2").tobytes()) ^ 0xFFFFFFFF

    def data(self, payload: bytes) -> int:
        code = self._data(payload)
        if code == CODE_OK:
            off, n = struct.unpack_from("<IH", payload)
            if off <= self.fw_next:
                self.fw_next = max(self.fw_next, off + n)
        return code

    def _data(self, payload: bytes) -> int:
        if len(payload) < P.DATA.size:
            return CODE_LENGTH
        off, n, cod = struct.unpack_from("<IHB", payload)
        tail = payload[P.DATA.size:]
        if (len(payload) < P.DATA.size + 1 or n == 0 or (cod == P.CODING_RAW and len(tail) != 2 * n)
                or cod not in (P.CODING_RAW, P.CODING_RICE)):
            return CODE_LENGTH
        if off > self.total or n > self.total - off or (cod == P.CODING_RICE and off + n > self.wh):
            return CODE_OFFSET
        if off > self.next and off < self.wh:
            return CODE_GAP
        if off >= self.wh:
            return CODE_OK
        end = min(off + n, self.wh)
        if cod == P.CODING_RICE:
            trial = self.stored.copy()
            try:
                coding.decode(tail, off, n, trial, self.w)
            except ValueError:
                return CODE_STREAM
            vals = trial[off:end]
        else:
            vals = np.frombuffer(tail, "<u2")[:end - off]
        # the samples before next are the host's already (the bench's host never changes them)
        assert (self.stored[off:min(end, self.next)] == vals[:max(0, min(end, self.next) - off)]).all()
        self.stored[off:end] = vals
        self.next = max(self.next, end)
        return CODE_OK


class Bench:
    def __init__(self, dut, seed: int):
        self.dut = dut
        self.rng = random.Random(seed)
        self.src: deque = deque()      # bytes, ("pause", cycles), ("flush",), ("arm", ...)
        # held frames, in order: (type, seq, payload, data, code, next, crc, dropped before it)
        self.expect: deque = deque()
        self.bad_sent = 0              # frames sent that must be dropped and counted
        self.mem: dict[int, int] = {}
        self.landing: deque = deque()  # (cycle, addr, data) beats taken, not yet in the memory
        self.reads: deque = deque()    # addresses the stream reader owes
        self.cycle = 0
        self.held = 0
        self.reloads = 0
        self.stalls = 0
        self.base = int(dut.HEIGHT_BASE.value)
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())

    async def start(self):
        d = self.dut
        for s in ("s_axis_tvalid", "s_axis_tdata", "cfg_arm", "cfg_width", "cfg_samples", "cfg_total",
                  "clear", "flush", "frame_release", "buf_addr", "m_wa_tready", "wa_busy", "m_rd_ready",
                  "s_rd_tdata", "s_rd_tvalid"):
            getattr(d, s).value = 0
        d.cfg_timeout.value = TIMEOUT
        d.rst.value = 1
        await ClockCycles(d.clk, 3)
        await FallingEdge(d.clk)
        d.rst.value = 0

    # --- the host's side -----------------------------------------------------------------------
    def frame(self, ftype: int, seq: int, payload: bytes, model: Model | None, armed: bool):
        """A good frame, and what the CPU must find."""
        self.src.extend(encode_frame(ftype, seq, payload))
        data = armed and ftype == P.FrameType.DATA
        code = model.data(payload) if data else 0
        nxt, crc = (model.next, model.crc()) if model else (0, 0xFFFFFFFF)
        self.expect.append((ftype, seq & 0xFF, payload, int(data), code, nxt, crc, self.bad_sent))

    def bad(self, wire: bytes):
        if os.environ.get("WM_UPLOAD_DEBUG"):
            self.dut._log.info(f"bad {self.bad_sent}: {wire.hex()}")
        self.src.extend(wire)
        self.bad_sent += 1

    def corrupt(self, ftype: int, seq: int, payload: bytes) -> bytes:
        raw = bytearray(frame_bytes(ftype, seq, payload))
        kind = self.rng.randrange(6)
        if kind == 0:  # a byte changed (never into a delimiter or an escape)
            i = self.rng.randrange(len(raw))
            raw[i] ^= self.rng.choice([1, 0x10, 0x80, 0x5A])
            if raw[i] in (P.SLIP_END, P.SLIP_ESC):
                raw[i] ^= 0x01
            return slip_encode(bytes(raw))
        if kind == 1:  # cut short
            return slip_encode(bytes(raw[:self.rng.randrange(1, len(raw))]))
        if kind == 2:  # a byte after the CRC
            return slip_encode(bytes(raw) + b"\x00")
        if kind == 3:  # a bad escape
            w = bytearray(slip_encode(bytes(raw)))
            i = self.rng.randrange(1, len(w) - 1)
            return bytes(w[:i]) + bytes([P.SLIP_ESC, 0x00]) + bytes(w[i:])
        if kind == 4:  # a length beyond MAX_PAYLOAD (with a CRC that fits it)
            head = struct.pack("<BBH", ftype, seq & 0xFF, P.MAX_PAYLOAD + 1 + self.rng.randrange(100))
            body = head + payload
            return slip_encode(body + struct.pack("<I", zlib.crc32(body)))
        return bytes([1, 2, 3, P.SLIP_END])  # junk between delimiters: a frame of its own

    # --- the device's side ---------------------------------------------------------------------
    async def drive(self):
        """Every cycle, at the falling edge: each side's beat is decided with the DUT's valid or ready
        of this cycle (registered: stable until the next rising edge, where the beat moves)."""
        d = self.dut
        cur, taken, pause = None, False, 0
        rd_cur, rd_taken = False, False
        while True:
            await FallingEdge(d.clk)
            self.cycle += 1
            d.flush.value = 0
            d.clear.value = 0
            # the byte source (a beat is held until taken)
            if cur is not None and taken:
                cur = None
            if cur is None and pause:
                pause -= 1
            elif cur is None and self.src:
                item = self.src[0]
                if isinstance(item, tuple):
                    self.src.popleft()
                    if item[0] == "pause":
                        pause = item[1]
                    elif item[0] == "flush":
                        d.flush.value = 1
                    elif item[0] == "arm":
                        _, arm, w, wh, total = item
                        d.cfg_arm.value = arm
                        d.cfg_width.value = w
                        d.cfg_samples.value = wh
                        d.cfg_total.value = total
                        d.clear.value = 1
                elif self.rng.random() < 0.75:
                    cur = self.src.popleft()
            d.s_axis_tvalid.value = int(cur is not None)
            d.s_axis_tdata.value = cur if cur is not None else 0
            taken = cur is not None and bool(int(d.s_axis_tready.value))
            # the addressed writer: beats land a random time after they are taken
            wa_ready = self.rng.random() < 0.6
            d.m_wa_tready.value = int(wa_ready)
            if int(d.m_wa_tvalid.value):
                if wa_ready:
                    self.landing.append((self.cycle + self.rng.randrange(7), int(d.m_wa_tuser.value),
                                         int(d.m_wa_tdata.value)))
                else:
                    self.stalls += 1
            while self.landing and self.landing[0][0] <= self.cycle:
                _, a, v = self.landing.popleft()
                self.mem[a] = v
            d.wa_busy.value = int(bool(self.landing))
            # the stream reader: the command, then its halfwords with gaps
            rd_ready = self.rng.random() < 0.5
            d.m_rd_ready.value = int(rd_ready)
            if int(d.m_rd_valid.value) and rd_ready:
                a, n = int(d.m_rd_addr.value), int(d.m_rd_len.value)
                assert not self.landing, "a reload read before the writes landed"
                self.reads.extend(range(a, a + n))
                self.reloads += 1
            if rd_cur and rd_taken:
                self.reads.popleft()
                rd_cur = False
            if not rd_cur and self.reads and self.rng.random() < 0.7:
                rd_cur = True
                d.s_rd_tdata.value = self.mem.get(self.reads[0], 0xDEAD)
            d.s_rd_tvalid.value = int(rd_cur)
            rd_taken = rd_cur and bool(int(d.s_rd_tready.value))

    async def cpu(self):
        d = self.dut
        while True:
            await FallingEdge(d.clk)
            d.frame_release.value = 0
            if not int(d.frame_valid.value):
                continue
            assert self.expect, "a frame held that the model did not expect"
            ftype, seq, payload, data, code, nxt, crc, bad = self.expect.popleft()
            hdr = struct.unpack_from("<IHB", payload) if ftype == P.FrameType.DATA and len(payload) > 7 else 0
            what = f"frame {self.held} (type {ftype}, DATA {hdr})"
            if os.environ.get("WM_UPLOAD_DEBUG"):
                d._log.info(f"{what}: code {code} next {nxt} dropped {bad} reloads {self.reloads}")
            got = (int(d.frame_type.value), int(d.frame_seq.value), int(d.frame_len.value),
                   int(d.bad_frames.value), int(d.frame_data.value))
            assert got == (ftype, seq, len(payload), bad, data), f"{what}: type seq len dropped data {got}"
            got = (int(d.frame_code.value) if data else code, int(d.next_sample.value), int(d.crc.value))
            assert got == (code, nxt, crc), f"{what}: code next crc {got}, model {(code, nxt, crc)}"
            # the payload, a word a cycle
            words = (len(payload) + 3) // 4
            for k in range(words + 1):
                if k < words:
                    d.buf_addr.value = k
                if k:
                    want = int.from_bytes(payload[4 * (k - 1):4 * k].ljust(4, b"\0"), "little")
                    v = int(d.buf_rdata.value)
                    n = min(4, len(payload) - 4 * (k - 1))
                    mask = (1 << (8 * n)) - 1
                    assert v & mask == want & mask, f"frame {self.held}: payload word {k - 1}"
                await FallingEdge(d.clk)
            for _ in range(self.rng.choice([0, 0, 1, 5, 30])):
                await FallingEdge(d.clk)
            d.frame_release.value = 1
            self.held += 1


@cocotb.test()
async def upload_session(dut):
    b = Bench(dut, SEED)
    rng = b.rng
    await b.start()
    cocotb.start_soon(b.drive())
    cocotb.start_soon(b.cpu())
    z = field(rng, W, H)
    mask = np.array([rng.randrange(65536) for _ in range(-(-W * H // 16))], np.uint16)
    words = np.concatenate([z.ravel(), mask])
    total = words.size
    enc = coding.SampleEncoder(z, mask)
    raw_enc = coding.SampleEncoder(z, mask, coded=False)
    seq = 0

    # disarmed: frames are held with their payloads, DATA included, nothing stored
    b.frame(P.FrameType.HELLO, seq, P.HELLO.pack(version=P.VERSION), None, False)
    n, cod, tail = enc.frame(0, 200)
    b.frame(P.FrameType.DATA, seq + 1, P.DATA.pack(offset=0, count=n, coding=cod) + tail, None, False)
    seq += 2
    b.src.append(("arm", 1, W, W * H, total))
    model = Model(W, z, total)

    sent_rice = 0
    while model.fw_next < total:
        start = model.fw_next
        r = rng.random()
        if r < 0.10 and start > 2:
            start = max(0, start - rng.randrange(1, 3 * W))   # a repeat from further back
            if rng.random() < 0.5:
                start -= start % P.RICE_BLOCK                  # where a Rice frame may start
        elif r < 0.10:
            start = min(total - 1, start + rng.randrange(1, 50))  # a gap
        budget = rng.choice([12, 24, 40, 60, 100, 160, 300] + [P.MAX_PAYLOAD - P.DATA.size] * (W * H > 4000))
        n, cod, tail = (raw_enc if rng.random() < 0.15 else enc).frame(start, budget)
        sent_rice += cod == P.CODING_RICE
        payload = P.DATA.pack(offset=start, count=n, coding=cod) + tail
        r = rng.random()
        if r < 0.12:
            b.bad(b.corrupt(P.FrameType.DATA, seq, payload))
        elif r < 0.14:
            # a silence inside a frame: dropped at the timeout, counted
            b.bad(encode_frame(P.FrameType.DATA, seq, payload)[:-3])
            b.src.append(("pause", TIMEOUT + 200))
        elif r < 0.16:
            # the rate changed under a frame: flushed, not counted
            b.src.extend(encode_frame(P.FrameType.DATA, seq, payload)[:-5])
            b.src.append(("pause", 40))
            b.src.append(("flush",))
            b.src.append(("pause", 3))
        elif r < 0.18 and cod == P.CODING_RICE:
            # a Rice stream one byte short or long, with a good CRC
            bad_tail = tail[:-1] if rng.random() < 0.5 else tail + b"\x00"
            pl = P.DATA.pack(offset=start, count=n, coding=cod) + bad_tail
            b.frame(P.FrameType.DATA, seq, pl, model, True)
        elif r < 0.20:
            # header checks: no samples, a wrong length, past the end, an unknown coding
            k = rng.randrange(5)
            pl = [P.DATA.pack(offset=start, count=0, coding=cod) + tail,
                  payload + b"\x00\x00" if cod == P.CODING_RAW else payload[:P.DATA.size],
                  P.DATA.pack(offset=total + 1, count=n, coding=cod) + tail,
                  P.DATA.pack(offset=start, count=n, coding=7) + tail,
                  payload[:rng.randrange(P.DATA.size)]][k]
            b.frame(P.FrameType.DATA, seq, pl, model, True)
        elif r < 0.22:
            b.frame(P.FrameType.STATUS if rng.random() < 0.5 else P.FrameType.CONFIG, seq,
                    bytes(rng.randrange(256) for _ in range(rng.choice([0, 80]))), model, True)
        else:
            b.frame(P.FrameType.DATA, seq, payload, model, True)
        seq += 1
        # the host waits for the device now and then (its window), so the source never runs far ahead
        while len(b.expect) > 3:
            await ClockCycles(dut.clk, 50)

    while b.expect or b.src:
        await ClockCycles(dut.clk, 100)
    await ClockCycles(dut.clk, 50)
    assert int(dut.next_sample.value) == W * H
    assert int(dut.crc.value) == zlib.crc32(z.astype("<u2").tobytes()) ^ 0xFFFFFFFF
    got = np.array([b.mem.get(b.base + i, -1) for i in range(W * H)])
    assert (got == z.ravel().astype(int)).all(), f"SDRAM differs at {np.flatnonzero(got != z.ravel())[:10]}"
    assert int(dut.bad_frames.value) == b.bad_sent
    dut._log.info(f"{b.held} frames held, {b.bad_sent} dropped, {sent_rice} Rice frames, "
                  f"{b.reloads} reloads, {b.stalls} writer stalls, {b.cycle} cycles")
    dut._log.info("done")
    assert b.reloads > 0 and sent_rice > 10 and b.stalls > 0, "the corners were not reached"
