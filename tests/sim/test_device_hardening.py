"""No client can hold a device, and a device that dies mid-job costs the user nothing (issue 13).

The native stand-in device (wmdev) closes a connection that stays idle for the idle timeout it states
in HELLO, and one that takes none of its bytes for the stated write timeout (a client flooding STATUS
without reading); the next client is served.  Frames longer than the stated max_payload, and ABORT,
STATUS or ACK of the wrong length during a job, get BAD_LENGTH without ending anything.  A device
killed in the middle of a job (the native device; the simulated board, marked `sim`) ends `wavemesh
stream` with one clear error at once (the connection breaks), with no output file, and the next run
against a restarted device gives the reference mesh (the board: pin-accurate, at 3 Mbaud).
"""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
from jobs import REFUSED_IN_A_JOB, run_with_payloads  # tests/sim/jobs.py
from wavemesh import cli
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.device.link import Link, LinkError
from wavemesh.harness.faultproxy import FrameTap, stream_once
from wavemesh.harness.nativedev import NativeDevice, build_wmdev
from wavemesh.io.synth import make

FAST = S.Timeouts(sync=0.5, sync_attempts=3, reply=0.5, attempts=3, ack=0.5, job=5.0)
RUN_LIMIT = 150.0


@pytest.fixture(scope="module")
def wmdev_exe():
    return build_wmdev(sanitize=True)  # what a hostile client reaches, under ASan and UBSan


def hello(link: Link) -> dict:
    link.write_frame(P.FrameType.HELLO, 1, P.HELLO.pack(version=P.VERSION))
    while True:
        f = link.read_frame(2.0)
        if f.type == P.FrameType.HELLO_REPLY:
            return f.fields()


def closed_after(sock: socket.socket, limit: float) -> float:
    """Seconds until the peer closed the socket (reading and dropping what comes), at most limit."""
    t0 = time.monotonic()
    sock.settimeout(limit)
    try:
        while sock.recv(65536):
            pass
    except (ConnectionResetError, TimeoutError, socket.timeout):
        pass
    return time.monotonic() - t0


def test_an_idle_client_is_dropped_after_the_stated_timeout(wmdev_exe):
    dev = NativeDevice(wmdev_exe, "--idle-timeout-ms", "1500")
    try:
        with Link(dev.url) as link:
            # from before the HELLO: the device's last frame is no earlier, however late its reply is read
            t0 = time.monotonic()
            info = hello(link)
            assert info["idle_timeout_ms"] == 1500 and info["write_timeout_ms"] == P.WRITE_TIMEOUT_MS
            with pytest.raises(LinkError, match="broke"):
                link.read_frame(10.0)  # nothing comes; then the device closes the connection
            waited = time.monotonic() - t0
        assert waited >= 1.5 - 0.05  # not before the stated timeout (counted from the last frame)
        dev.wait_for_line("client idle, closed")
        with S.Device(dev.url, timeouts=FAST) as host:  # the next client is served
            assert host.sync().idle_timeout_ms == 1500
    finally:
        dev.stop()


def test_a_session_keeps_the_idle_clock_away(wmdev_exe):
    """Inside a session the session timeout (ERROR TIMEOUT) comes first; the idle timeout after it."""
    dev = NativeDevice(wmdev_exe, "--idle-timeout-ms", "1000")
    try:
        with S.Device(dev.url, timeouts=FAST) as host:
            host.sync()
            host.configure(S.config_payload(16, 12, 2, 10, _fixed()))
            f = host.link.read_frame(P.SESSION_TIMEOUT_MS / 1000 + 3)
            assert f.type == P.FrameType.ERROR and f.fields()["code"] == P.ErrorCode.TIMEOUT
            with pytest.raises(LinkError, match="broke"):
                host.link.read_frame(5.0)
        dev.wait_for_line("client idle, closed")
    finally:
        dev.stop()


def test_a_client_that_does_not_read_is_dropped(wmdev_exe):
    """STATUS after STATUS without reading a reply: the device's writes stall, it gives the client up
    after its write timeout and serves the next one."""
    dev = NativeDevice(wmdev_exe, "--write-timeout-ms", "500")
    try:
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        s.connect(("127.0.0.1", dev.port))
        flood = b"".join(_status(i) for i in range(20000))
        s.settimeout(10.0)
        with pytest.raises(OSError):  # the device closes: the flood hits a reset connection
            for _ in range(400):
                s.sendall(flood)
        s.close()
        dev.wait_for_line("client not reading, closed")
        with S.Device(dev.url, timeouts=FAST) as host:
            assert host.sync().write_timeout_ms == 500
    finally:
        dev.stop()


def _status(i: int) -> bytes:
    from wavemesh.device.link import encode_frame

    return encode_frame(P.FrameType.STATUS, i & 0xFF)


def test_lengths_are_checked_against_max_payload_and_during_a_job(wmdev_exe):
    dev = NativeDevice(wmdev_exe, "--max-payload", "256")
    try:
        with S.Device(dev.url, timeouts=FAST) as host:
            assert host.sync().max_payload == 256
            host.link.write_frame(P.FrameType.DATA, 7, bytes(300))  # a valid frame, beyond max_payload
            f = host.link.read_frame(2.0)
            assert (f.type, f.seq) == (P.FrameType.ERROR, 7)
            assert f.fields()["code"] == P.ErrorCode.BAD_LENGTH and f.fields()["detail"] == 300
            # during a job: ABORT, STATUS and ACK with a payload get BAD_LENGTH, the job goes on
            a = np.arange(64 * 64, dtype=np.uint16).reshape(64, 64) * 7
            levels, done, refused = run_with_payloads(host, a, 3, _fixed())
            assert done["status"] == 0 and len(levels) == 3
            assert refused == dict.fromkeys(REFUSED_IN_A_JOB, P.ErrorCode.BAD_LENGTH)
    finally:
        dev.stop()


def _fixed():
    from wavemesh.refine.native import RefineParams, fixed_params

    return fixed_params(RefineParams(), 1.0)


# ---------------------------------------------------------------------------------------------------
# a device killed mid-job


def kill_mid_job(start_device, src, opts, ref, tmp_path):
    """Stream through a FrameTap that kills the device when the first MESH frame comes: one clear
    error, no output; then the same run against a new device gives the reference."""
    dev = start_device()
    killed = []

    def on_frame(direction, f) -> bool:
        if direction == "down" and f.type == P.FrameType.MESH and not killed:
            killed.append(f.fields()["level"])
            dev.proc.kill()
            return False
        return True

    out = tmp_path / "out.obj"
    try:
        with FrameTap(("127.0.0.1", dev.port), on_frame) as tap:
            outcome, seconds, msg = stream_once(["stream", str(src), *opts, "--port", tap.url, "-o", str(out),
                                                 "-q"], out, ref, RUN_LIMIT)
    finally:
        dev.stop()
    assert killed, "the job never sent a level"
    assert outcome == "error" and not out.exists(), msg
    assert "broke" in msg or "stopped answering" in msg, msg
    dev = start_device()
    try:
        argv = ["stream", str(src), *opts, "--port", dev.url, "-o", str(out), "-q"]
        outcome, _, msg = stream_once(argv, out, ref, RUN_LIMIT)
        assert outcome == "identical", msg
    finally:
        dev.stop()


def test_native_device_killed_mid_job(tmp_path):
    exe = build_wmdev()
    src = tmp_path / "ball.npy"
    np.save(src, make("ball", 64))
    opts = ["--levels", "3"]
    assert cli.main(["mesh", str(src), *opts, "-o", str(tmp_path / "ref.obj"), "-q", "--max-triangles",
                     str(_board_budget())]) in (0, 3)
    kill_mid_job(lambda: NativeDevice(exe, "--quiet"), src, opts, tmp_path / "ref.obj", tmp_path)


def _board_budget() -> int:
    """The budget `wavemesh stream` uses on wmdev without --max-triangles: its storage less one."""
    from wavemesh.device.memmap import TRI_CAPACITY

    return TRI_CAPACITY - 1


@pytest.mark.sim
def test_simulated_board_killed_mid_job(start_sim, firmware_hex, tmp_path, monkeypatch):
    """The pin-accurate board (every byte over the UART pins) switched to its rate nearest to 3 Mbaud
    (3 Mbaud), killed when its first MESH frame passes."""
    from wavemesh.harness.simboard import SIM_TIMEOUTS, fastest_rate

    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", SIM_TIMEOUTS)
    src = tmp_path / "tiny.npy"
    np.save(src, make("ball", 16)[3:12, 2:12])  # 10 x 9
    opts = ["--levels", "2", "--reduce", "off", "--simplify", "off"]
    assert cli.main(["mesh", str(src), *opts, "-o", str(tmp_path / "ref.obj"), "-q"]) == 0
    rate = fastest_rate()

    def board():
        return start_sim(firmware_hex, "--quiet")

    kill_mid_job(board, src, [*opts, "--link-baud", str(rate)], tmp_path / "ref.obj", tmp_path)
