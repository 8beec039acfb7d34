"""`wavemesh stream` and the wire protocol against the native stand-in device (firmware/board/native).

The device is the board's protocol engine (firmware/board/src/proto_*.c) and the refiner library on the
host CPU, serving TCP on 127.0.0.1: fast, so these tests exercise the protocol itself.  `wavemesh
stream` must write exactly what `wavemesh mesh` writes; every kind of bad frame gets its error code;
garbage never crashes the device (the garbage tests run an AddressSanitizer/UBSan build) and never
keeps it from serving the next request; duplicates, aborts and departures mid-job leave it idle.
"""

from __future__ import annotations

import filecmp
import json
import random
import socket
import time
from pathlib import Path

import numpy as np
import pytest
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.device.coding import decode_level_body, encode_level_body, varints
from wavemesh.device.link import Link, SlipDecoder, encode_frame, parse_frame
from wavemesh.harness import jacksboro, run_cli
from wavemesh.harness.nativedev import NativeDevice, build_wmdev
from wavemesh.io.synth import make

FAST = S.Timeouts(sync=0.5, sync_attempts=3, reply=0.5, attempts=3, ack=0.5, job=5.0)

@pytest.fixture(scope="module")
def wmdev_exe() -> Path:
    return build_wmdev()


@pytest.fixture(scope="module")
def device(wmdev_exe):
    """A device with room for big meshes (the tests compare with `wavemesh mesh`, which grows its storage)."""
    d = NativeDevice(wmdev_exe, "--tri-capacity", "200000", "--max-width", "512", "--max-height", "512")
    yield d
    d.stop()


LINK_S = 3  # the ASan device's link timeout (wmdev --link-timeout): its NO_ACK tests take seconds


@pytest.fixture(scope="module")
def asan_device():
    """The same device built with AddressSanitizer and UBSan: garbage must not make it touch bad memory."""
    d = NativeDevice(build_wmdev(sanitize=True), "--tri-capacity", "20000", "--link-timeout", str(LINK_S))
    yield d
    d.stop()
    assert d.proc.returncode in (0, -15), "\n".join(d.lines)  # terminated, not aborted by a sanitizer
    assert not any("Sanitizer" in ln or "runtime error" in ln for ln in d.lines), "\n".join(d.lines)


@pytest.fixture
def fast_timeouts(monkeypatch):
    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", FAST)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    np.save(d / "ball64.npy", make("ball", 64))
    np.save(d / "box64.npy", make("box", 64))
    y, x = np.mgrid[0:33, 0:40]
    np.save(d / "lossy.npy", 100.3 * np.sin(x / 7.0) * np.cos(y / 5.0) + 0.01 * x * y)  # floats: lossy
    return d


# ---------------------------------------------------------------------------------------------------
# stream == mesh

CASES = {
    "ball-levels-lod": ("ball64.npy", ["--levels", "3"], ".obj"),
    "ball-levels-alone": ("ball64.npy", ["--levels", "4", "--bound", "off", "-k", "3"], ".obj"),
    "ball-no-simplify": ("ball64.npy", ["--simplify", "off", "--reduce", "off"], ".obj"),
    "box-initial": ("box64.npy", ["--stage", "initial"], ".obj"),
    "ball-denoise": ("ball64.npy", ["--denoise", "sure+median", "--zeta", "2"], ".obj"),  # the host de-noises
    "lossy-odd-ply": ("lossy.npy", ["--zeta", "0.5", "--levels", "2"], ".ply"),
    "vertical-vertex-k3": ("ball64.npy", ["--metric", "vertical", "--neighbourhood", "vertex", "-k", "3",
                                          "--alpha", "0.8", "--zeta", "2"], ".obj"),
    "jacksboro-decimated": ("JACKSBORO", ["--key", "elevation", "--decimate", "4", "--zeta", "2"], ".obj"),
    "jacksboro-crop": ("JACKSBORO", ["--key", "elevation", "--crop", "100,80,70,50", "--zeta", "3",
                                     "--levels", "2"], ".obj"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_stream_equals_mesh(case, device, inputs, tmp_path):
    name, opts, ext = CASES[case]
    src = jacksboro() if name == "JACKSBORO" else str(inputs / name)
    outs = {}
    for cmd in ("mesh", "stream"):
        d = tmp_path / cmd
        d.mkdir()
        extra = ["--port", device.url] if cmd == "stream" else []
        rc, out, err = run_cli(cmd, src, *opts, *extra, "-o", str(d / f"m{ext}"), "--lod", str(d / "lod"),
                               "--report", str(d / "r.json"))
        assert rc == 0, err
        outs[cmd] = d
    m, s = outs["mesh"], outs["stream"]
    assert filecmp.cmp(m / f"m{ext}", s / f"m{ext}", shallow=False), "the meshes differ"
    lods = sorted(p.name for p in (m / "lod").iterdir())
    assert lods == sorted(p.name for p in (s / "lod").iterdir()) and lods
    for n in lods:
        assert filecmp.cmp(m / "lod" / n, s / "lod" / n, shallow=False), n
    rm, rs = json.loads((m / "r.json").read_text()), json.loads((s / "r.json").read_text())
    assert rm["errors"] == rs["errors"] and rm["input"] == rs["input"]
    # the initial triangulation is the templates' (DONE's initial_*), not the first level the device sent
    assert rs["initial"] == {k: rm["initial"][k] for k in rs["initial"]}
    if "refiner" in rm:
        for a, b in zip(rm["refiner"]["levels"], rs["refiner"]["levels"], strict=True):
            assert {k: a[k] for k in a} == {k: b[k] for k in a}  # the device's report adds fields
        assert rm["refiner"]["fixed_point"] | {"max_triangles": 0} == rs["refiner"]["fixed_point"] | {
            "max_triangles": 0}
    assert rs["device"]["name"] == "wm-nativ" and rs["transfer"]["damaged_frames"] == 0
    assert set(rs["device_cycles"]) >= {"receive", "filter", "template", "refine", "emit", "link"}


def test_budget_stops_both_the_same_way(device, inputs, tmp_path):
    src = str(inputs / "ball64.npy")
    rc1, _, err1 = run_cli("mesh", src, "--max-triangles", "150", "-o", str(tmp_path / "m.obj"), "-q")
    rc2, _, err2 = run_cli("stream", src, "--max-triangles", "150", "--port", device.url, "-o",
                           str(tmp_path / "s.obj"), "-q")
    assert rc1 == rc2 == 3
    assert "error bound is not met" in err1 and "error bound is not met" in err2
    assert filecmp.cmp(tmp_path / "m.obj", tmp_path / "s.obj", shallow=False)


def test_delta_coding_of_big_numbers_in_small_frames(wmdev_exe, tmp_path, monkeypatch):
    """LEVEL_DELTA's coder (proto_emit.c's code_item) against the host's (wavemesh.device.coding): a
    random 128 x 128 field meshed at zeta 1 has some 10,000 vertex slots, so index deltas need 3-byte
    numbers, and the smallest MESH frames (72 bytes of stream) cut items, 3-byte numbers among them.
    Each level's body is what encode_level_body writes for its numbers, the length the device counted
    (LEVEL_END's total) is the body's, and the meshes equal `wavemesh mesh`'s."""
    z = np.random.default_rng(7).integers(0, 1000, (128, 128)).astype(np.uint16)
    np.save(tmp_path / "noise.npy", z)
    levels = []
    parse = S.parse_level
    monkeypatch.setattr(S, "parse_level", lambda buf, w, h: levels.append(buf) or parse(buf, w, h))
    dev = NativeDevice(wmdev_exe, "--max-payload", str(P.MIN_PAYLOAD))
    try:
        opts = [str(tmp_path / "noise.npy"), "--zeta", "1", "--levels", "2", "-q"]
        rc, _, err = run_cli("stream", *opts, "--port", dev.url, "-o", str(tmp_path / "s.obj"))
        assert rc == 0, err
    finally:
        dev.stop()
    rc, _, err = run_cli("mesh", *opts, "-o", str(tmp_path / "m.obj"))
    assert rc == 0, err
    assert filecmp.cmp(tmp_path / "m.obj", tmp_path / "s.obj", shallow=False)
    assert len(levels) == 2
    widths, free = [], 0
    for buf in levels:
        h = P.LEVEL_HEADER.unpack(buf)
        raw = P.level_stream_size(h["vertex_slots"], h["triangles"], h["index_bytes"])
        assert h["coding"] == P.LEVEL_DELTA and len(buf) < raw
        body = buf[P.LEVEL_HEADER.size:]
        xy, tris = decode_level_body(body, h["vertex_slots"], h["triangles"])
        assert encode_level_body(xy, tris) == body
        widths += [1 + (v >= 0x80) + (v >= 0x4000) + (v >= 0x200000) for v in varints(body).tolist()]
        free += int(np.count_nonzero(xy[:, 0] == P.FREE_VERTEX))
    assert max(widths) == 3 and widths.count(3) > 100  # 652
    # every kind of item the coder counts and writes: free vertex slots (one byte), live ones, triangles
    assert free > 0 and all(P.LEVEL_HEADER.unpack(b)["triangles"] > 0 for b in levels), free


# ---------------------------------------------------------------------------------------------------
# progress, --quiet, --trace


def test_progress_bars_quiet_and_trace(device, inputs, tmp_path):
    src = str(inputs / "ball64.npy")
    rc, out, err = run_cli("stream", src, "--port", device.url, "-o", str(tmp_path / "a.obj"), "-q")
    assert rc == 0 and out == "" and err == ""
    rc, out, err = run_cli("stream", src, "--port", device.url, "-o", str(tmp_path / "b.obj"))
    assert rc == 0
    assert "device: wm-nativ" in out and "wrote" in out and "level" in out
    assert "heights   [" in err and "100.0%" in err and "device    [" in err
    rc, out, err = run_cli("stream", src, "--port", device.url, "-o", str(tmp_path / "c.obj"), "-q",
                           "--trace")
    assert rc == 0
    for what in ("TX HELLO seq", "RX HELLO_REPLY seq", "TX CONFIG", "TX DATA", "RX DATA_ACK", "RX MESH",
                 "RX LEVEL_END", "TX ACK", "RX DONE", "0000  "):
        assert what in err, what


# ---------------------------------------------------------------------------------------------------
# errors a user meets: one line, a hint, bounded time


def one_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "hint:" in err, err
    return lines[0]


def test_no_device_listening(inputs, tmp_path, fast_timeouts):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    t0 = time.monotonic()
    rc, _, err = run_cli("stream", str(inputs / "ball64.npy"), "--port", f"socket://127.0.0.1:{port}", "-o",
                         str(tmp_path / "x.obj"))
    assert rc == 2 and "no device is listening" in one_error(err) and time.monotonic() - t0 < 2


def test_silent_device(inputs, tmp_path, fast_timeouts):
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    t0 = time.monotonic()
    rc, _, err = run_cli("stream", str(inputs / "ball64.npy"), "--port",
                         f"socket://127.0.0.1:{srv.getsockname()[1]}", "-o", str(tmp_path / "x.obj"))
    srv.close()
    assert rc == 2 and "no device answers" in one_error(err)
    assert time.monotonic() - t0 < FAST.sync * FAST.sync_attempts + 2


def test_device_busy_with_another_client(device, inputs, tmp_path, fast_timeouts):
    with Link(device.url) as other:  # holds the device
        other.write_frame(P.FrameType.STATUS, 1)
        other.read_frame(2.0)
        t0 = time.monotonic()
        rc, _, err = run_cli("stream", str(inputs / "ball64.npy"), "--port", device.url, "-o",
                             str(tmp_path / "x.obj"))
        took = time.monotonic() - t0
        # the first client is still served
        other.write_frame(P.FrameType.STATUS, 2)
        assert other.read_frame(2.0).type == P.FrameType.STATUS_REPLY
    assert rc == 2 and not (tmp_path / "x.obj").exists()
    assert "device error 14 BUSY: the device is serving another client" in one_error(err)
    assert "wait until it is done" in err
    assert took < 1.0  # refused at once (the device answers the connection's first frame)


def test_a_silent_second_connection_gets_busy_too(wmdev_exe):
    """A connection that sends nothing while another is served gets ERROR BUSY within a second too."""
    dev = NativeDevice(wmdev_exe, "--quiet")
    try:
        with S.Device(dev.url, timeouts=FAST) as first:
            first.sync()
            with socket.create_connection(("127.0.0.1", dev.port)) as s:
                s.settimeout(2.0)
                t0 = time.monotonic()
                dec, frames = SlipDecoder(), []
                while not frames:
                    chunk = s.recv(64)
                    assert chunk, "closed without ERROR BUSY"
                    frames = dec.feed(chunk)
                took = time.monotonic() - t0
                assert s.recv(64) == b""  # then closed
            f = parse_frame(frames[0])
            assert f.type == P.FrameType.ERROR and f.fields()["code"] == P.ErrorCode.BUSY and took < 1.0
            assert first.status()["state"] == P.State.IDLE  # the first client is still served
    finally:
        dev.stop()


def test_input_larger_than_the_device(device, tmp_path, fast_timeouts):
    np.save(tmp_path / "big.npy", make("ball", 600))
    rc, _, err = run_cli("stream", str(tmp_path / "big.npy"), "--port", device.url, "-o",
                         str(tmp_path / "x.obj"))
    assert rc == 2 and "the device holds at most 512 x 512" in one_error(err)
    assert "--decimate 2 makes it 300 x 300" in err


def test_options_beyond_the_device(device, inputs, tmp_path, fast_timeouts):
    src = str(inputs / "ball64.npy")
    rc, _, err = run_cli("stream", src, "--levels", "9", "--port", device.url, "-o", str(tmp_path / "x.obj"))
    assert rc == 2 and "at most 8" in one_error(err)
    rc, _, err = run_cli("stream", src, "--max-triangles", "200000", "--port", device.url, "-o",
                         str(tmp_path / "x.obj"))
    assert rc == 2 and "199999" in one_error(err)
    rc, _, err = run_cli("stream", src, "--crop", "0,0,100,10", "--port", device.url, "-o",
                         str(tmp_path / "x.obj"))
    assert rc == 2 and "does not fit" in one_error(err)


def test_spline_wavelet_equals_mesh(device, inputs, tmp_path):
    """The native device runs the spline filter bank (wm_spline) when CONFIG asks for it: the same mesh
    as `wavemesh mesh --wavelet spline`, byte for byte (and not Haar's)."""
    src = str(inputs / "ball64.npy")
    out = {}
    for kind, extra in (("stream", ["--port", device.url]), ("mesh", [])):
        rc, _, err = run_cli(kind, src, "--wavelet", "spline", *extra, "-o", str(tmp_path / f"{kind}.obj"),
                             "-q")
        assert rc == 0, err
        out[kind] = (tmp_path / f"{kind}.obj").read_bytes()
    rc, _, err = run_cli("mesh", src, "-o", str(tmp_path / "haar.obj"), "-q")
    assert rc == 0, err
    assert out["stream"] == out["mesh"] and out["mesh"] != (tmp_path / "haar.obj").read_bytes()


def test_device_error_code_capacity(wmdev_exe, inputs, tmp_path, fast_timeouts):
    small = NativeDevice(wmdev_exe, "--tri-capacity", "100")
    try:
        rc, _, err = run_cli("stream", str(inputs / "ball64.npy"), "--levels", "1", "--port", small.url, "-o",
                             str(tmp_path / "x.obj"))
        assert rc == 2
        assert "device error 10 CAPACITY" in one_error(err) and "--max-triangles" in err
        # the device is idle again and serves the next request
        rc, _, err = run_cli("stream", str(inputs / "ball64.npy"), "--levels", "4", "--zeta", "30",
                             "--port", small.url, "-o", str(tmp_path / "y.obj"), "-q")
        assert rc in (0, 3), err
    finally:
        small.stop()


# ---------------------------------------------------------------------------------------------------
# the protocol, frame by frame


class Raw:
    """A bare link to the device for hand-made frames."""

    def __init__(self, url: str):
        self.link = Link(url)
        self.seq = 0

    def send(self, ftype: int, payload: bytes = b"", seq: int | None = None) -> int:
        if seq is None:
            self.seq = (self.seq + 1) & 0xFF
            seq = self.seq
        self.link.write_frame(ftype, seq, payload)
        return seq

    def expect(self, ftype: int, timeout: float = 2.0):
        while True:
            f = self.link.read_frame(timeout)
            if f.type == ftype:
                return f

    def error(self, timeout: float = 2.0) -> dict:
        return self.expect(P.FrameType.ERROR, timeout).fields()

    def hello(self) -> dict:
        self.send(P.FrameType.HELLO, P.HELLO.pack(version=P.VERSION))
        return self.expect(P.FrameType.HELLO_REPLY).fields()

    @staticmethod
    def config(**over) -> bytes:
        c = dict(width=16, height=12, levels=2, metric=0, neighbourhood=0, iterations=2, flags=0, tau=10,
                 max_triangles=0, capacity=0, zeta=65536, scale_m=32768, scale_e=15, delta_p=58982,
                 alpha=39322, delta_v=131072, delta_lambda=655, delta_c=64225, delta_d=0, slope_x_m=0,
                 slope_x_e=0, slope_y_m=0, slope_y_e=0)
        c.update(over)
        return P.CONFIG.pack(**c)

    def close(self):
        self.link.close()


def data(offset: int, words: bytes) -> bytes:
    """A DATA payload of raw words (an odd number of bytes: the count of the whole words)."""
    return P.DATA.pack(offset=offset, count=len(words) // 2, coding=P.CODING_RAW) + words


def full_job_works(url: str) -> None:
    """A complete small job: HELLO, CONFIG, DATA, RUN, every level, DONE."""
    rng = np.random.default_rng(3)
    a = rng.integers(0, 3000, size=(12, 16)).astype(np.uint16)
    with S.Device(url, timeouts=FAST) as dev:
        dev.sync()
        dev.configure(Raw.config())
        dev.upload(a)
        levels, done = dev.run(S.samples_crc(a), 16, 12)
    assert done["status"] == 0 and len(levels) == 2 and levels[-1].level == 0


# Beyond this device's capabilities (wmdev's defaults, max_levels 8), within the protocol's ranges
BAD_FOR_THE_DEVICE = [("levels", 9), ("capacity", 1), ("capacity", 10**9), ("max_triangles", 1),
                      ("max_triangles", 20000)]  # (CONFIG_SPLINE is not here: wmdev states FEATURE_SPLINE)


def out_of_range() -> list[tuple[str, int]]:
    """Just outside every CONFIG field's range, both ends where the field's type can say it
    (protocol.CONFIG's limits: the host's table, the one the device compiles in)."""
    out = []
    for f in P.CONFIG.fields:
        lo, hi = f.limits
        top = (1 << (8 * f.size)) - 1
        out += [(f.name, lo - 1)] if lo > 0 else []
        out += [(f.name, hi + 1), (f.name, top)] if hi < top else []
    return out


def test_every_config_field_is_checked(asan_device):
    cases = out_of_range()
    every_value = ("zeta", "delta_v", "delta_lambda", "delta_d")  # the refiner takes any value of these
    assert {n for n, _ in cases} == {f.name for f in P.CONFIG.fields} - set(every_value)
    raw = Raw(asan_device.url)
    try:
        caps = raw.hello()
        off = P.CONFIG.offsets()
        for name, value in cases + BAD_FOR_THE_DEVICE:
            raw.send(P.FrameType.CONFIG, raw.config(**{name: value}))
            e = raw.error()
            want = (P.ErrorCode.BAD_VALUE, off[name], P.FrameType.CONFIG)
            assert (e["code"], e["detail"], e["request"]) == want, (name, value)
            # the host checks the same ranges before it sends (config_payload)
            problem = P.config_problem(P.CONFIG.unpack(raw.config(**{name: value})))
            assert (problem is not None and f"CONFIG.{name} =" in problem) == ((name, value) in cases)
        for name in every_value:
            top = (1 << (8 * P.CONFIG.fields[list(off).index(name)].size)) - 1
            raw.send(P.FrameType.CONFIG, raw.config(**{name: top}))
            assert raw.expect(P.FrameType.OK).fields()["request"] == P.FrameType.CONFIG, name
        # one column more than the device states it holds (its HELLO), within the protocol's range
        w, h = caps["max_width"] + 1, 12
        raw.send(P.FrameType.CONFIG, raw.config(width=w, height=h))
        e = raw.error()
        assert e["code"] == P.ErrorCode.TOO_LARGE and e["detail"] == w << 16 | h
        raw.send(P.FrameType.CONFIG, raw.config()[:-1])
        assert raw.error()["code"] == P.ErrorCode.BAD_LENGTH
    finally:
        raw.close()
    full_job_works(asan_device.url)


def test_frames_out_of_place_get_their_codes(asan_device):
    raw = Raw(asan_device.url)
    try:
        assert raw.hello()["version"] == P.VERSION
        raw.send(P.FrameType.HELLO, P.HELLO.pack(version=0x0100))
        assert raw.error() | {"reserved": 0} == {"code": P.ErrorCode.VERSION, "request": P.FrameType.HELLO,
                                                 "state": P.State.IDLE, "reserved": 0, "detail": P.VERSION}
        raw.send(0x3F)
        assert raw.error()["code"] == P.ErrorCode.BAD_TYPE
        raw.send(P.FrameType.STATUS, b"\x00")
        assert raw.error()["code"] == P.ErrorCode.BAD_LENGTH
        raw.send(P.FrameType.DATA, data(0, b"\x00\x00"))
        e = raw.error()
        assert e["code"] == P.ErrorCode.BAD_STATE and e["detail"] == P.State.IDLE
        raw.send(P.FrameType.RUN, P.RUN.pack(crc=0))
        assert raw.error()["code"] == P.ErrorCode.BAD_STATE
        raw.send(P.FrameType.ACK, P.ACK.pack(kind=P.FrameType.LEVEL_END, index=0, have=0))  # stale: ignored
        raw.send(P.FrameType.CONFIG, raw.config())
        raw.expect(P.FrameType.OK)
        raw.send(P.FrameType.DATA, data(190, b"\x00\x00" * 3))  # beyond 16 x 12
        assert raw.error()["code"] == P.ErrorCode.BAD_OFFSET
        raw.send(P.FrameType.DATA, data(0, b"\x00\x00\x00"))  # odd sample bytes
        assert raw.error()["code"] == P.ErrorCode.BAD_LENGTH
        raw.send(P.FrameType.DATA, data(4, b"\x01\x00"))  # a gap: NAK, once
        ack = raw.expect(P.FrameType.DATA_ACK).fields()
        assert ack["next"] == 0 and ack["flags"] == P.ACK_NAK
        raw.send(P.FrameType.DATA, data(8, b"\x01\x00"))
        assert raw.expect(P.FrameType.DATA_ACK).fields()["flags"] == 0
        raw.send(P.FrameType.RUN, P.RUN.pack(crc=0))  # not every sample yet
        assert raw.error()["code"] == P.ErrorCode.BAD_STATE
        raw.send(P.FrameType.DATA, data(0, b"\x07\x00" * 192))
        assert raw.expect(P.FrameType.DATA_ACK).fields()["next"] == 192
        raw.send(P.FrameType.RUN, P.RUN.pack(crc=12345))  # not the samples' CRC
        e = raw.error()
        assert e["code"] == P.ErrorCode.DATA_CRC and e["detail"] == S.samples_crc(np.full(192, 7, np.uint16))
        raw.send(P.FrameType.STATUS)
        st = raw.expect(P.FrameType.STATUS_REPLY).fields()
        assert st["state"] == P.State.IDLE and st["last_error"] == P.ErrorCode.DATA_CRC
    finally:
        raw.close()
    full_job_works(asan_device.url)


def test_a_repeated_request_is_answered_not_redone(asan_device):
    raw = Raw(asan_device.url)
    try:
        raw.hello()
        seq = raw.send(P.FrameType.CONFIG, raw.config())
        assert raw.expect(P.FrameType.OK).seq == seq
        raw.send(P.FrameType.DATA, data(0, b"\x01\x00" * 10))
        raw.expect(P.FrameType.DATA_ACK)
        raw.send(P.FrameType.CONFIG, raw.config(), seq=seq)  # our OK was "lost": the same request again
        assert raw.expect(P.FrameType.OK).seq == seq
        raw.send(P.FrameType.STATUS)
        st = raw.expect(P.FrameType.STATUS_REPLY).fields()
        assert (st["state"], st["samples"], st["expected"]) == (P.State.RECEIVING, 10, 192)
    finally:
        raw.close()


GARBAGE = {
    "random": lambda r: bytes(r.randrange(256) for _ in range(20000)),
    "delimiters": lambda r: bytes(r.choice([0xC0, 0xDB, 0xDC, 0xDD, 0x00]) for _ in range(5000)),
    "no-delimiter": lambda r: bytes(r.choice(range(0xC0)) for _ in range(6000)),  # longer than any frame
    "bad-crc-frames": lambda r: b"".join(
        b"\xc0" + bytes([t, 1, 4, 0, 1, 2, 3, 4]) + bytes(4) + b"\xc0" for t in range(256)),
    "valid-but-wrong": lambda r: b"".join(
        encode_frame(t, r.randrange(256), bytes(r.randrange(256) for _ in range(r.randrange(0, 80))))
        for t in range(256) if t != P.FrameType.HELLO),
    "truncated": lambda r: encode_frame(P.FrameType.CONFIG, 1, bytes(64))[:40],
}


@pytest.mark.parametrize("kind", sorted(GARBAGE))
def test_garbage_leaves_the_device_able_to_serve(kind, asan_device):
    raw = Raw(asan_device.url)
    try:
        raw.link.write_raw(GARBAGE[kind](random.Random(kind)))
        time.sleep(0.2)
    finally:
        raw.close()
    full_job_works(asan_device.url)
    assert asan_device.alive()


def test_garbage_in_mid_session_then_the_same_connection_recovers(asan_device):
    raw = Raw(asan_device.url)
    try:
        raw.hello()
        raw.send(P.FrameType.CONFIG, raw.config())
        raw.expect(P.FrameType.OK)
        raw.link.write_raw(bytes(random.Random(1).randrange(256) for _ in range(3000)))
        info = raw.hello()  # a HELLO starts afresh whatever came before
        assert info["name"].startswith(b"wm-nativ")
        raw.send(P.FrameType.STATUS)
        assert raw.expect(P.FrameType.STATUS_REPLY).fields()["state"] == P.State.IDLE
    finally:
        raw.close()


def start_job(raw: Raw, w: int = 64, h: int = 64) -> int:
    raw.hello()
    raw.send(P.FrameType.CONFIG, raw.config(width=w, height=h, levels=3))
    raw.expect(P.FrameType.OK)
    a = make("ball", 64)[:h, :w].astype("<u2")
    words = a.tobytes()
    for off in range(0, w * h, 256):
        raw.send(P.FrameType.DATA, data(off, words[2 * off:2 * off + 512]))
        raw.expect(P.FrameType.DATA_ACK)
    raw.send(P.FrameType.RUN, P.RUN.pack(crc=S.samples_crc(a)))
    return S.samples_crc(a)


@pytest.mark.parametrize("how", ["abort", "hello", "leave"])
def test_ending_a_job_midway(how, asan_device):
    raw = Raw(asan_device.url)
    try:
        start_job(raw)
        end = raw.expect(P.FrameType.LEVEL_END).fields()  # the first level is out; the device waits for us
        assert end["index"] == 0 and end["level"] == 2
        if how == "abort":
            raw.send(P.FrameType.ABORT)
            raw.expect(P.FrameType.OK)
        elif how == "hello":
            raw.hello()
        if how != "leave":
            raw.send(P.FrameType.STATUS)
            st = raw.expect(P.FrameType.STATUS_REPLY).fields()
            assert st["state"] == P.State.IDLE and st["last_error"] == P.ErrorCode.ABORTED
    finally:
        raw.close()
    full_job_works(asan_device.url)


def test_a_host_that_stops_acknowledging(asan_device):
    """LEVEL_END comes again every ACK_TIMEOUT_MS while the host is silent; after the device's link
    timeout (HELLO states it) without a frame, DONE with NO_ACK, then idle."""
    raw = Raw(asan_device.url)
    try:
        assert raw.hello()["link_timeout_s"] == LINK_S
        start_job(raw)
        ends, t0 = 0, time.monotonic()
        while True:
            f = raw.link.read_frame(3.0)
            if f.type == P.FrameType.LEVEL_END:
                ends += 1
            if f.type == P.FrameType.DONE:
                done = f.fields()
                break
        took = time.monotonic() - t0
        assert ends >= LINK_S * 1000 // P.ACK_TIMEOUT_MS - 1
        assert done["status"] == P.ErrorCode.NO_ACK and done["levels"] == 0
        assert LINK_S * 0.9 < took < LINK_S + 3
        raw.send(P.FrameType.STATUS)
        assert raw.expect(P.FrameType.STATUS_REPLY).fields()["state"] == P.State.IDLE
    finally:
        raw.close()


def test_a_host_that_pauses_but_keeps_alive_keeps_its_job(asan_device):
    """A pause of twice the link timeout with a KEEPALIVE every second (the host at work, or a line
    whose other direction stalls): the device repeats LEVEL_END but keeps the job, and the level is
    acknowledged afterwards as if nothing happened.  (Protocol 7 counted every ACK_TIMEOUT_MS without
    progress, and ended the job with NO_ACK after ten of them: five seconds of pauses.)"""
    raw = Raw(asan_device.url)
    try:
        start_job(raw)
        end = raw.expect(P.FrameType.LEVEL_END).fields()
        t0 = time.monotonic()
        while time.monotonic() - t0 < 2 * LINK_S:
            raw.send(P.FrameType.KEEPALIVE)
            time.sleep(1.0)
        raw.send(P.FrameType.STATUS)
        assert raw.expect(P.FrameType.STATUS_REPLY).fields()["state"] == P.State.RUNNING
        raw.send(P.FrameType.ACK, P.ACK.pack(kind=P.FrameType.LEVEL_END, index=0, have=end["total"]))
        nxt = raw.expect(P.FrameType.LEVEL_END, 5.0).fields()
        assert nxt["index"] == 1
    finally:
        raw.close()


def test_a_job_outlives_its_connection_and_resumes(asan_device):
    """The connection breaks after the first level went out: a new connection's RESUME (RUN's crc, the
    level, the bytes the host has) gets the level from there, and the job goes on; a RESUME that names
    another job gets BAD_STATE and the job goes on too."""
    raw = Raw(asan_device.url)
    crc = start_job(raw)
    end = raw.expect(P.FrameType.LEVEL_END).fields()
    raw.close()
    raw = Raw(asan_device.url)
    try:
        raw.send(P.FrameType.RESUME, P.RESUME.pack(crc=crc ^ 1, index=0, have=0))
        e = raw.error()
        assert e["code"] == P.ErrorCode.BAD_STATE and e["request"] == P.FrameType.RESUME
        raw.send(P.FrameType.RESUME, P.RESUME.pack(crc=crc, index=0, chunk=100, have=40))
        pieces = []
        while True:
            f = raw.link.read_frame(3.0)
            if f.type == P.FrameType.MESH:
                pieces.append((f.fields()["offset"], len(f.tail())))
            if f.type == P.FrameType.LEVEL_END:
                again = f.fields()
                break
        assert again == end
        assert pieces[0] == (40, 100) and sum(n for _, n in pieces) == end["total"] - 40
        raw.send(P.FrameType.ACK, P.ACK.pack(kind=P.FrameType.LEVEL_END, index=0, have=end["total"]))
        assert raw.expect(P.FrameType.LEVEL_END, 5.0).fields()["index"] == 1
    finally:
        raw.close()
    raw = Raw(asan_device.url)  # the job ended with NO_ACK meanwhile, or this HELLO ends it
    try:
        raw.hello()
        raw.send(P.FrameType.RESUME, P.RESUME.pack(crc=crc, index=1, have=0))
        assert raw.error()["code"] == P.ErrorCode.BAD_STATE  # no job to resume
    finally:
        raw.close()


def test_a_session_that_goes_silent_is_dropped(asan_device):
    raw = Raw(asan_device.url)
    try:
        raw.hello()
        raw.send(P.FrameType.CONFIG, raw.config())
        raw.expect(P.FrameType.OK)
        raw.send(P.FrameType.DATA, data(0, b"\x01\x00" * 5))
        raw.expect(P.FrameType.DATA_ACK)
        t0 = time.monotonic()
        e = raw.error(timeout=P.SESSION_TIMEOUT_MS / 1000 + 3)
        assert e["code"] == P.ErrorCode.TIMEOUT and e["detail"] == 5 and e["request"] == 0
        assert time.monotonic() - t0 > P.SESSION_TIMEOUT_MS / 1000 * 0.9
    finally:
        raw.close()


def test_the_device_leaves_a_client_midway_through_the_upload(asan_device):
    raw = Raw(asan_device.url)
    raw.hello()
    raw.send(P.FrameType.CONFIG, raw.config())
    raw.expect(P.FrameType.OK)
    raw.link.write_raw(b"\xc0\x03\x09")  # half a DATA frame, then the host goes away
    raw.close()
    full_job_works(asan_device.url)


# ---------------------------------------------------------------------------------------------------
# throughput


def test_throughput_at_115200_baud(wmdev_exe, tmp_path):
    """Paced like a 115200-baud UART (11520 bytes/s each way): the upload never goes faster than the line,
    and framing costs under 5 %.  How much of the line it uses is printed, not asserted: a wall-clock
    figure depends on the machine's load (speed targets live in `make bench`)."""
    paced = NativeDevice(wmdev_exe, "--baud", "115200")
    try:
        a = np.random.default_rng(0).integers(0, 65536, size=(64, 64)).astype(np.uint16)  # SLIP's worst
        with S.Device(paced.url) as dev:
            dev.sync()
            dev.configure(Raw.config(width=64, height=64, levels=3))
            t0 = time.monotonic()
            sent = dev.upload(a)
            took = time.monotonic() - t0
        line = 115200 / 10
        efficiency = a.nbytes / took / line
        print(f"\n115200 baud: {a.nbytes} bytes of samples ({sent} on the wire) in {took:.3f} s: "
              f"{a.nbytes / took:.0f} B/s, {100 * efficiency:.1f} % of the line")
        assert sent < a.nbytes * 1.05  # framing and escapes: under 5 %
        assert efficiency < 1.02  # a loaded machine is slower, never faster than the paced line
    finally:
        paced.stop()


def test_crop_and_decimate_select_the_samples(inputs, tmp_path):
    """--crop X,Y,W,H then --decimate N: the same as slicing the array (mesh, stream and check share them)."""
    from wavemesh.api import shape_heightfield
    from wavemesh.errors import InputError
    from wavemesh.io.heightfield import from_array

    a = np.arange(20 * 30, dtype=np.float64).reshape(20, 30)
    hf = shape_heightfield(from_array(a), "3,2,20,15", 2)
    assert np.array_equal(hf.values, a[2:17, 3:23][::2, ::2]) and "crop 3,2,20,15, decimate 2" in hf.source
    for crop, dec in (("3,2,40,15", None), ("a,b", None), (None, 0), (None, 20)):
        with pytest.raises(InputError):
            shape_heightfield(from_array(a), crop, dec)
    src = str(inputs / "ball64.npy")
    rc, _, err = run_cli("mesh", src, "--decimate", "2", "--crop", "0,0,60,50", "-o", str(tmp_path / "d.obj"),
                         "-q")
    assert rc == 0, err
    rc, out, err = run_cli("check", str(tmp_path / "d.obj"), "--against", src, "--crop", "0,0,60,50",
                           "--decimate", "2")
    assert rc == 0 and "30 x 25 grid: a proper triangulation" in out, out + err


def test_the_engine_builds_freestanding_for_the_board(tmp_path):
    """proto_*.c for rv32imc as the board builds it: -Werror, no libc beyond memcpy, no 64-bit division."""
    import re
    import shutil
    import subprocess

    from wavemesh.device.gen import write_all

    gcc = shutil.which("riscv64-unknown-elf-gcc")
    if gcc is None:
        pytest.fail("riscv64-unknown-elf-gcc not found: run `make setup`")
    root = Path(__file__).resolve().parents[2]
    write_all(tmp_path)
    names = re.search(r"set\(WM_PROTO_SOURCE_NAMES([^)]*)\)",
                      (root / "firmware/board/proto_sources.cmake").read_text()).group(1).split()
    assert len(names) >= 5, names
    defined, undefined = set(), set()
    for name in names:
        obj = tmp_path / (name + ".o")
        subprocess.run([gcc, "-march=rv32imc", "-mabi=ilp32", "-ffreestanding", "-Os", "-std=c99", "-Wall",
                        "-Wextra", "-Werror", "-Wshadow", "-Wstrict-prototypes", "-Wmissing-prototypes",
                        f"-I{root / 'firmware/board/include'}", f"-I{root / 'firmware/include'}",
                        f"-I{tmp_path}", "-c", str(root / "firmware/board/src" / name), "-o", str(obj)],
                       check=True)
        nm = subprocess.run([gcc.replace("gcc", "nm"), str(obj)], capture_output=True, text=True, check=True)
        for ln in nm.stdout.splitlines():
            parts = ln.split()
            if parts and parts[-2:-1] == ["U"]:
                undefined.add(parts[-1])
            elif len(parts) == 3 and parts[1] in "TDRB":
                defined.add(parts[2])
    assert all(s.startswith("wm_proto_") for s in defined), defined
    assert undefined - defined <= {"memcpy", "wm_params_check"}, undefined - defined
