"""The link layer (host/wavemesh/device/link.py): SLIP framing, CRC-32, the frame reader, port errors,
--trace.

No device needed: frames go through pyserial's loop:// port or straight through the decoder.
"""

from __future__ import annotations

import io
import random
import socket
import struct
import time
import zlib

import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st
from wavemesh.device import protocol as P
from wavemesh.device.link import (
    FrameError,
    Link,
    LinkError,
    LinkTimeout,
    PortBusy,
    SlipDecoder,
    _open_error,
    encode_frame,
    frame_bytes,
    parse_frame,
    slip_encode,
)

SPECIAL = bytes([P.SLIP_END, P.SLIP_ESC, P.SLIP_ESC_END, P.SLIP_ESC_ESC])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=300) | st.sampled_from([SPECIAL, SPECIAL * 3]), min_size=1, max_size=5))
def test_slip_round_trip_in_any_split(payloads):
    wire = b"".join(slip_encode(p) for p in payloads if p)
    dec = SlipDecoder(limit=10_000)
    out = []
    rng = random.Random(len(wire))
    i = 0
    while i < len(wire):  # fed in random pieces
        n = rng.randint(1, 40)
        out += dec.feed(wire[i:i + n])
        i += n
    assert out == [p for p in payloads if p]


def test_escapes_only_where_needed():
    assert slip_encode(b"\x01\xc0\x02\xdb\x03") == b"\xc0\x01\xdb\xdc\x02\xdb\xdd\x03\xc0"
    assert P.SLIP_END not in slip_encode(bytes(range(256)))[1:-1]


def test_frame_layout_and_crc():
    raw = frame_bytes(P.FrameType.RUN, 0x42, b"\x01\x02\x03\x04")
    assert raw[:4] == bytes([P.FrameType.RUN, 0x42, 4, 0])
    assert struct.unpack("<I", raw[-4:])[0] == zlib.crc32(raw[:-4])
    f = parse_frame(raw)
    assert (f.type, f.seq, f.payload, f.name) == (P.FrameType.RUN, 0x42, b"\x01\x02\x03\x04", "RUN")
    assert f.fields() == {"crc": 0x04030201}


@pytest.mark.parametrize("mutate, why", [
    (lambda r: r[:5], "short"),
    (lambda r: r[:-5] + r[-4:], "length"),
    (lambda r: r[:4] + bytes([r[4] ^ 1]) + r[5:], "CRC"),
    (lambda r: frame_bytes(0x55, 0, b""), "unknown frame type"),
    (lambda r: frame_bytes(P.FrameType.RUN, 0, b"\x01"), "payload of 1 bytes"),
    (lambda r: frame_bytes(P.FrameType.DATA, 0, b"\x01\x02"), "payload of 2 bytes"),
])
def test_damaged_frames_are_refused(mutate, why):
    raw = frame_bytes(P.FrameType.RUN, 1, b"\x00\x00\x00\x00")
    with pytest.raises(FrameError, match=why):
        parse_frame(mutate(raw))


def test_decoder_survives_garbage_and_finds_the_frames_after_it():
    rng = random.Random(5)
    good = encode_frame(P.FrameType.STATUS, 9)
    garbage = bytes(rng.randrange(256) for _ in range(5000)) + b"\xdb\x00" + bytes([P.SLIP_ESC]) * 3
    dec = SlipDecoder()
    items = dec.feed(garbage + good)
    frames = []
    for it in items:
        if isinstance(it, bytes):
            try:
                frames.append(parse_frame(it))
            except FrameError:
                pass
    assert frames[-1].type == P.FrameType.STATUS and frames[-1].seq == 9


def test_decoder_drops_overlong_runs():
    dec = SlipDecoder(limit=16)
    items = dec.feed(b"\xc0" + b"x" * 40 + b"\xc0" + slip_encode(b"ok"))
    assert isinstance(items[0], FrameError) and "longer" in str(items[0])
    assert items[1] == b"ok"


def test_link_over_loop_port_reads_whole_frames_and_counts_damage():
    port = serial.serial_for_url("loop://", timeout=0)
    trace = io.StringIO()
    with Link(port, trace=trace) as link:
        link.write_raw(b"\xc0garbage\xc0")
        link.write_frame(P.FrameType.STATUS, 3)
        data = P.DATA.pack(offset=7, count=1, coding=P.CODING_RAW) + b"\x01\x00"
        link.write_frame(P.FrameType.DATA, 4, data)
        f1 = link.read_frame(1.0)
        f2 = link.read_frame(1.0)
        assert (f1.name, f1.seq, f2.name) == ("STATUS", 3, "DATA")
        assert (f2.fields()["offset"], f2.tail()) == (7, b"\x01\x00")
        assert link.stats.damaged == 1 and link.stats.frames_in == 2 and link.stats.frames_out == 2
        t0 = time.monotonic()
        with pytest.raises(LinkTimeout):
            link.read_frame(0.2)
        assert 0.15 < time.monotonic() - t0 < 1.0
        assert link.poll_frame() is None
    text = trace.getvalue()
    assert "TX STATUS seq 3" in text and "RX DATA seq 4" in text and "damaged frame skipped" in text
    assert "0000  06 03 00 00" in text  # the hex dump of the STATUS frame
    assert port.is_open and port.timeout == 0  # a port object handed in is not closed


def test_connection_refused_is_one_clear_error():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    with pytest.raises(LinkError) as e:
        Link(f"socket://127.0.0.1:{port}")
    assert "no device is listening" in e.value.message and "make sim" in e.value.hint


def test_missing_and_busy_ports_get_hints():
    with pytest.raises(LinkError) as e:
        Link("/dev/ttyUSB_wavemesh_missing")
    assert "no such port" in e.value.message and "list_ports" in e.value.hint
    busy = _open_error("/dev/ttyUSB1", serial.SerialException(
        "[Errno 16] could not open port /dev/ttyUSB1: [Errno 16] Device or resource busy: '/dev/ttyUSB1'"))
    assert isinstance(busy, PortBusy) and "busy" in busy.message and "close" in busy.hint
    locked = _open_error("/dev/ttyUSB1", serial.SerialException("Could not exclusively lock port x"))
    assert isinstance(locked, PortBusy)
    other = _open_error("bogus://x", ValueError("invalid URL, protocol 'bogus' not known"))
    assert "pyserial URL" in other.hint


def test_a_peer_that_goes_away_is_a_link_error():
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    link = Link(f"socket://127.0.0.1:{srv.getsockname()[1]}")
    conn, _ = srv.accept()
    conn.close()
    srv.close()
    with pytest.raises(LinkError) as e:
        link.read_frame(2.0)
    assert "broke" in e.value.message
    link.close()
