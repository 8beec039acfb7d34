"""The link's fault and hardening tests on the pin-accurate simulated board at its fastest rate.

One board (wmsim without --fast: every byte goes bit by bit over the UART pins at the board's current
divisor, through the upload block, rtl/upload_rx.v) is switched by `--link-baud` (or
Device.change_baud) to its nearest rate to 3 Mbaud: divisor 13 at 39 MHz, 3 Mbaud exactly.  At that rate:

- seeded corruption, loss, duplication and delays both ways (wavemesh.harness.faultproxy): the
  reference mesh or one clear error line, the board serving a clean request afterwards;
- the last DATA frame, or its DATA_ACK, lost (nothing after it shows the loss; the upload block holds
  the samples, the host's STATUS probe finds what is missing): the reference mesh;
- a frame longer than the stated max_payload (longer than MAX_FRAME: dropped unanswered), and ABORT,
  STATUS or ACK with a payload during a job (BAD_LENGTH): nothing ended.

The job is a 64 x 64 crop of the Jacksboro DEM, the template stage alone (the link is under test: 8 KB
of samples, 2.7 KB Rice-coded in four DATA frames, and some 1.4 KB of level stream back; the job is
about a million cycles of the board, seconds of simulation).
The killed board is in test_device_hardening.py, the bigger campaign in `make bench-faults` (its
simulated-board sets), the failed switch on this board, whose probe window is 25 million cycles of
simulation, in that bench too (tests/sim/test_stream_baud.py has it on the native stand-in device).
"""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from jobs import REFUSED_IN_A_JOB, run_with_payloads  # tests/sim/jobs.py
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.device.link import _HEAD, slip_encode
from wavemesh.harness import jacksboro, run_cli
from wavemesh.harness.faultproxy import FaultProxy, Faults, FrameTap, stream_once
from wavemesh.harness.simboard import SIM_TIMEOUTS, SimBoard, fastest_rate

pytestmark = pytest.mark.sim

RATE = fastest_rate()  # what --link-baud auto takes on the board: 3,000,000 at 39 MHz
OPTS = ["--key", "elevation", "--crop", "0,0,64,64", "--zeta", "4", "--stage", "initial"]
LINK = ["--link-baud", str(RATE)]
RUN_LIMIT = 600.0  # s: a run that takes longer counts as a hang


@pytest.fixture(scope="module")
def board(sim_exe, firmware_hex):
    b = SimBoard(sim_exe, firmware_hex, "--port", "0", "--quiet")
    yield b
    b.stop()


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    d = tmp_path_factory.mktemp("board3m")
    rc, _, err = run_cli("mesh", jacksboro(), *OPTS, "-o", str(d / "ref.obj"), "-q")
    assert rc == 0, err
    return Path(jacksboro()), d / "ref.obj"


@pytest.fixture(autouse=True)
def sim_timeouts(monkeypatch):
    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", SIM_TIMEOUTS)


def clean_run(board, job, tmp: Path) -> dict:
    """A job without faults at RATE: the reference mesh; the report."""
    src, ref = job
    out = tmp / "clean.obj"
    rc, _, err = run_cli("stream", str(src), *OPTS, *LINK, "--port", board.url, "-o", str(out), "--report",
                         str(tmp / "clean.json"), "-q")
    assert rc == 0, err
    assert out.read_bytes() == ref.read_bytes()
    report = json.loads((tmp / "clean.json").read_text())
    assert report["transfer"]["line_baud"] == RATE
    return report


# One seed with at most 3 faults a direction (a lost LEVEL_END or ACK costs the board's ACK_TIMEOUT_MS,
# 12.5 million cycles, a minute of simulation on a loaded machine); seed 2's fall on the HELLO_REPLY at
# the start rate, on three DATA frames at RATE (two dropped runs and a duplicated one: the upload
# block's checks and the host's go-back) and the level stream.  make bench-faults runs 20 seeds at 0.2 %
# without a bound.
@pytest.mark.parametrize("seed", [2])
def test_faults_at_3_mbaud(seed, board, job, tmp_path):
    """Seeded corruption, loss and duplication both ways, after the switch too: the reference mesh, or
    one clear error line; the board then serves a clean request at RATE."""
    src, ref = job
    out = tmp_path / "out.obj"
    faults = Faults(seed=seed, rate=0.004, limit=3, run=48, max_delay=0.2)
    with FaultProxy(("127.0.0.1", board.port), faults) as proxy:
        outcome, _, msg = stream_once(["stream", str(src), *OPTS, *LINK, "--port", proxy.url, "-o", str(out),
                                       "-q"], out, ref, RUN_LIMIT)
    assert sum(proxy.summary().values()) > 0  # the seed's faults fell inside the session
    assert outcome in ("identical", "error"), msg
    clean_run(board, job, tmp_path)


@pytest.mark.parametrize("lost", ["DATA", "DATA_ACK"])
def test_a_lost_last_upload_frame_at_3_mbaud(lost, board, job, tmp_path):
    """The last DATA frame (the upload block never sees it) or its DATA_ACK (the block stored it) is lost
    after the switch: the host's STATUS probe finds out and the job ends with the reference mesh."""
    src, ref = job
    total = 64 * 64
    dropped: list = []
    switched = []

    def on_frame(direction, f) -> bool:
        if direction == "down" and f.type == P.FrameType.OK and f.fields()["request"] == P.FrameType.BAUD:
            switched.append(True)
        if dropped or f.name != lost:
            return True
        fields = f.fields()
        last = (fields["offset"] + fields["count"] == total if lost == "DATA" else fields["next"] == total)
        if last:
            dropped.append(f.name)
            return False
        return True

    out = tmp_path / "out.obj"
    with FrameTap(("127.0.0.1", board.port), on_frame) as tap:
        outcome, _, msg = stream_once(["stream", str(src), *OPTS, *LINK, "--port", tap.url, "-o", str(out),
                                       "-q"], out, ref, RUN_LIMIT)
    assert switched and dropped == [lost]
    assert outcome == "identical", msg


def test_lengths_are_checked_at_3_mbaud(board):
    """After the switch: a frame longer than the stated max_payload (the board states protocol.MAX_PAYLOAD,
    so it is longer than MAX_FRAME: docs/protocol.md, dropped without an answer) costs nothing, the next
    request is answered; during a job ABORT, STATUS and ACK with a payload get BAD_LENGTH and the job
    goes on."""
    from wavemesh.refine.native import RefineParams, fixed_params

    with S.Device(board.url, timeouts=SIM_TIMEOUTS) as host:
        host.sync()
        info, problem = host.change_baud(RATE)
        assert problem is None and info.baud == RATE and info.max_payload == P.MAX_PAYLOAD
        for t in (P.FrameType.DATA, P.FrameType.STATUS):
            head = _HEAD.pack(t, 7, P.MAX_PAYLOAD + 1) + bytes(P.MAX_PAYLOAD + 1)
            host.link.write_raw(slip_encode(head + struct.pack("<I", zlib.crc32(head))))
        host.link.write_frame(P.FrameType.STATUS, 8)
        f = host.link.read_frame(SIM_TIMEOUTS.reply)
        assert (f.type, f.seq) == (P.FrameType.STATUS_REPLY, 8)
        a = (np.arange(12 * 10, dtype=np.uint16).reshape(10, 12) * 37) % 4001
        fixed = fixed_params(RefineParams(reduce=False, decimate=False), 1.0)
        levels, done, refused = run_with_payloads(host, a, 2, fixed)
        assert done["status"] == 0 and len(levels) == 2
        assert refused == dict.fromkeys(REFUSED_IN_A_JOB, P.ErrorCode.BAD_LENGTH)
