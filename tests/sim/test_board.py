"""The real firmware (firmware/board, cross-compiled) on the simulated board, over the wire protocol.

The protocol engine on the soft CPU (docs/protocol.md) replaces the stand-in exchange these tests
checked before: HELLO states the built sizes and the heap's triangle capacity; CONFIG and the DATA
upload store the samples in the height memory (STATUS counts them); garbage never keeps the board
from answering the next HELLO; one client at a time, a new one after the previous left; the
simulator's cycle log does not depend on the run.  (`wavemesh stream` through the board, the meshes
and the cycles per stage: test_stream_board.py.)
"""

from __future__ import annotations

import random
import socket
import time

import numpy as np
import pytest
from wavemesh.device import memmap
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.device.link import SlipDecoder, encode_frame, parse_frame

pytestmark = pytest.mark.sim

TIMEOUTS = S.Timeouts(sync=2.0, sync_attempts=5, reply=5.0, attempts=3, ack=5.0, job=60.0)
STAGE_SERVE = 0x00010000  # app/main.c: the engine starts serving


@pytest.fixture
def fast_board(start_sim, firmware_hex):
    return start_sim(firmware_hex, "--fast")


def test_hello_reports_capabilities(fast_board):
    with S.Device(fast_board.url, timeouts=TIMEOUTS) as dev:
        info = dev.sync()
    assert info.name == "wm-board"
    assert (info.max_width, info.max_height) == (memmap.GRID_MAX_W, memmap.GRID_MAX_H)
    assert info.max_samples == memmap.HEIGHT_SAMPLES
    assert info.max_levels == memmap.MAX_LEVELS
    assert info.clk_hz == memmap.CLK_HZ
    # the SDRAM's heap holds at least the documented capacity (memmap.TRI_CAPACITY), within 3 %
    assert memmap.TRI_CAPACITY <= info.tri_capacity < memmap.TRI_CAPACITY * 103 // 100
    assert fast_board.events("stage")[0][0] == STAGE_SERVE
    # the board's FPGA stage is built with Haar's filter bank: no FEATURE_SPLINE, and CONFIG_SPLINE refused
    assert not info.features & P.FEATURE_SPLINE
    with S.Device(fast_board.url, timeouts=TIMEOUTS) as dev:
        dev.sync()
        with pytest.raises(S.DeviceError) as e:
            dev.configure(P.CONFIG.pack(
                width=16, height=16, levels=1, metric=0, neighbourhood=0, iterations=2, flags=P.CONFIG_SPLINE,
                tau=10, max_triangles=0, capacity=0, zeta=65536, scale_m=32768, scale_e=15, delta_p=58982,
                alpha=39322, delta_v=131072, delta_lambda=655, delta_c=64225, delta_d=0))
    assert e.value.code == P.ErrorCode.BAD_VALUE


def test_a_fresh_board_answers_the_first_hello(start_sim, firmware_hex):
    """The board boots before its first client (sim/sim_main.h: the clock runs from reset to the firmware's
    first SYS.STAGE write without a host): a fresh board's first HELLO is answered at the first attempt (a
    board that booted only once the client came lost that HELLO to its boot, and the host waited the sync
    timeout before it tried again).  The proof is in simulated cycles, not wall time: the client connected
    after the firmware's serving marker."""
    board = start_sim(firmware_hex, "--fast")
    with S.Device(board.url, timeouts=TIMEOUTS) as dev:
        info = dev.sync(attempts=1, timeout=5.0)
    assert info.name == "wm-board"
    # the boot ran before the client: it connected after the serving marker (at the next socket service)
    serve = board.events("stage")[0]
    assert serve[0] == STAGE_SERVE
    connected = [ln for ln in board.lines if "client connected cycle" in ln]
    assert int(connected[0].split()[-1]) >= serve[1]


def upload(url: str, a: np.ndarray) -> dict:
    with S.Device(url, timeouts=TIMEOUTS) as dev:
        dev.sync()
        h, w = a.shape
        dev.configure(P.CONFIG.pack(
            width=w, height=h, levels=1, metric=0, neighbourhood=0, iterations=2, flags=0, tau=10,
            max_triangles=0, capacity=0, zeta=65536, scale_m=32768, scale_e=15, delta_p=58982,
            alpha=39322, delta_v=131072, delta_lambda=655, delta_c=64225, delta_d=0))
        dev.upload(a)
        return dev.status()


@pytest.mark.parametrize("w,h", [(16, 16), (33, 17), (2, 2), (256, 3)])
def test_upload_fills_the_height_memory(fast_board, w, h):
    a = np.random.default_rng(w * h).integers(0, 65536, size=(h, w), dtype=np.uint16)
    st = upload(fast_board.url, a)
    assert st["samples"] == st["expected"] == w * h


def test_garbage_then_a_valid_request(fast_board):
    rng = random.Random(3)
    with socket.create_connection(("127.0.0.1", fast_board.port), timeout=5) as s:
        s.sendall(bytes(rng.randrange(256) for _ in range(2000)))
        s.sendall(b"\xc0" + bytes(rng.randrange(256) for _ in range(40)) + b"\xc0")
        time.sleep(0.3)
    time.sleep(0.2)
    with S.Device(fast_board.url, timeouts=TIMEOUTS) as dev:
        assert dev.sync().name == "wm-board"


def test_cycle_log_is_deterministic(start_sim, firmware_hex):
    """Two boards, the same session: the same stage markers at the same cycles."""
    logs = []
    for _ in range(2):
        b = start_sim(firmware_hex, "--fast", "--exit-on-close")
        with S.Device(b.url, timeouts=TIMEOUTS) as dev:
            dev.sync()
        assert b.wait() == 0
        logs.append(b.events("stage"))
    assert logs[0] == logs[1] and logs[0]


def busy_answer(port: int, send: bytes) -> list:
    """Connect while another client is served, send `send`: the frames until the board closes.  A
    board that held the connection open (queued it behind the first client) raises the socket's
    timeout instead, a wait no answer needs: the bridge answers at once."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.settimeout(5)
        s.sendall(send)
        dec, frames = SlipDecoder(), []
        while chunk := s.recv(64):
            frames += dec.feed(chunk)
    return [parse_frame(f) for f in frames]


def test_one_client_at_a_time(start_sim, firmware_hex):
    """A second client gets ERROR BUSY and is closed, as from the native device (the bridge sends
    proto_slip.c's frame), without waiting for the first to leave; the first is still served; later
    clients are served in turn.  No wall-clock bound: a loaded machine may take a while to answer, a
    board that queued the second client would not answer before the socket's timeout."""
    board = start_sim(firmware_hex, "--fast")
    with S.Device(board.url, timeouts=TIMEOUTS) as first:
        first.sync()
        hello = encode_frame(P.FrameType.HELLO, 1)
        for send in (hello, b""):  # a host's HELLO; a connection that sends nothing
            frames = busy_answer(board.port, send)
            assert [(f.type, f.fields()["code"]) for f in frames] == [(P.FrameType.ERROR, P.ErrorCode.BUSY)]
            board.wait_for_line("second client refused (busy)")
        with S.Device(board.url, timeouts=TIMEOUTS) as second, pytest.raises(S.DeviceError) as e:
            second.sync()
        assert e.value.code == P.ErrorCode.BUSY
        assert first.sync().name == "wm-board"
    board.wait_for_line("client left")
    for _ in range(2):  # later clients, one after the other
        with S.Device(board.url, timeouts=TIMEOUTS) as dev:
            assert dev.sync().name == "wm-board"
    assert board.proc.poll() is None  # still running: it exits only with --exit-on-close
