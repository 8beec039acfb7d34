"""Fault injection: `wavemesh stream` through a proxy that corrupts, drops, duplicates and delays bytes.

Between the host and the native stand-in device sits wavemesh.harness.faultproxy (seeded, bounded),
and the host runs with its DEFAULT timeouts: the ones a user gets, derived from the session timeout
the device states in HELLO (protocol.host_resend_s).  Every run must end, within a bounded time,
either with the very mesh `wavemesh mesh` writes (byte for byte) or with one clear `error:` line and
a hint: never a hang, never a traceback, never a different mesh; and faults must really have been
injected.  A lost last DATA frame and a lost last DATA_ACK (which no later frame reveals) must be
recovered, not end in the device's session timeout.  This is the short, seeded version of `make
bench-faults` (bench/bench_faults.py, 10,000+ frames).  Afterwards the device still serves a clean
request.
"""

from __future__ import annotations

import filecmp

import numpy as np
import pytest
from wavemesh import cli
from wavemesh import protocol as P
from wavemesh import stream as S
from wavemesh.harness.faultproxy import Faults, FrameTap, Tally, campaign, stream_once
from wavemesh.harness.nativedev import NativeDevice, build_wmdev
from wavemesh.synth import make

RUN_LIMIT = 150.0  # s: a run that takes longer counts as a hang (the host's longest wait is 120 s)
OPTS = ["--levels", "3", "--max-triangles", "19999"]
# Short host timeouts for the heavy-fault runs, whose errors take the longest: what they test is
# that the retry loops give up, which they do at any timeouts.
FAST = S.Timeouts(sync=0.5, sync_attempts=3, reply=0.5, attempts=3, ack=0.5, job=5.0)


@pytest.fixture(scope="module")
def device():
    d = NativeDevice(build_wmdev(), "--tri-capacity", "20000", "--quiet")
    yield d
    d.stop()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    d = tmp_path_factory.mktemp("faults")
    src = d / "ball48.npy"
    np.save(src, make("ball", 48))
    rc = cli.main(["mesh", str(src), *OPTS, "-o", str(d / "ref.obj"), "-q"])
    assert rc == 0
    return src, d / "ref.obj"


def run_campaign(device, reference, tmp_path, faults: list[Faults]) -> Tally:
    src, ref = reference
    runs = campaign(("127.0.0.1", device.port), src, OPTS, ref, faults, tmp_path, RUN_LIMIT)
    tally = Tally.of(runs)
    print("\n" + tally.line())
    bad = [(r.faults.seed, r.outcome, r.message) for r in runs if r.outcome not in ("identical", "error")]
    assert not bad, bad  # no different mesh, no unclear ending, no hang
    assert all(r.injected > 0 for r in runs), "a run without faults tests nothing"
    return tally


def test_default_timeouts_recover_at_two_per_mille(device, reference, tmp_path):
    """The campaign of issue 13 in small: 0.2 % faults per byte (at most 8 per direction), default
    timeouts; retransmission gets through (it does not just give up)."""
    tally = run_campaign(device, reference, tmp_path, [Faults(seed=s, rate=0.002, limit=8) for s in range(8)])
    assert tally.injected >= 8 * 8
    assert tally.outcomes["identical"] >= 7


@pytest.mark.parametrize("direction", ["up", "down"])
def test_faults_one_way(direction, device, reference, tmp_path):
    faults = [Faults(seed=100 + s, rate=0.01, limit=12, run=64, directions=(direction,)) for s in range(3)]
    tally = run_campaign(device, reference, tmp_path, faults)
    assert tally.outcomes["identical"] >= 2


def test_heavy_faults_end_in_clear_errors(device, reference, tmp_path, monkeypatch):
    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", FAST)
    faults = [Faults(seed=200 + s, rate=0.05, limit=60, run=64, max_delay=0.3) for s in range(6)]
    tally = run_campaign(device, reference, tmp_path, faults)
    assert tally.outcomes["error"] >= 1


def last_data(total: int):
    def pick(direction, f):
        if direction == "up" and f.type == P.FrameType.DATA:
            return f.fields()["offset"] + len(f.tail()) // 2 == total
        return direction == "down" and f.type == P.FrameType.DATA_ACK and f.fields()["next"] == total
    return pick


@pytest.mark.parametrize("lost", ["DATA", "DATA_ACK"])
def test_a_lost_last_frame_of_the_upload_is_resent_in_time(lost, device, reference, tmp_path):
    """The failure of issue 13: nothing after the last DATA frame (or its DATA_ACK) shows the loss;
    the host must find it (a STATUS probe) before the device's session timeout, with the defaults."""
    src, ref = reference
    total = int(np.load(src).size)
    pick, dropped = last_data(total), []

    def on_frame(direction, f) -> bool:
        if not dropped and pick(direction, f) and f.name == lost:
            dropped.append(f.name)
            return False
        return True

    out = tmp_path / "out.obj"
    with FrameTap(("127.0.0.1", device.port), on_frame) as proxy:
        outcome, _, msg = stream_once(["stream", str(src), *OPTS, "--port", proxy.url, "-o", str(out), "-q"],
                                      out, ref, RUN_LIMIT)
    assert dropped == [lost]
    assert outcome == "identical", msg


def test_the_host_resends_well_within_the_session_timeout():
    """One source: the host's resend interval follows from what the device states, with room for
    SESSION_RESENDS - 1 losses in a row and the line time of a lost frame and its successor."""
    for baud in (0, 115200, 9600):
        r = P.host_resend_s(P.SESSION_TIMEOUT_MS, baud)
        frame = 2 * (P.HEADER_BYTES + P.MAX_PAYLOAD + P.CRC_BYTES) + 2
        assert P.SESSION_RESENDS * r + P.line_seconds(2 * frame, baud) <= P.SESSION_TIMEOUT_MS / 1000 + 1e-9


def test_the_device_serves_cleanly_afterwards(device, reference, tmp_path):
    src, ref = reference
    out = tmp_path / "clean.obj"
    outcome, _, msg = stream_once(["stream", str(src), *OPTS, "--port", device.url, "-o", str(out), "-q"],
                                  out, ref, RUN_LIMIT)
    assert outcome == "identical", msg
    assert filecmp.cmp(out, ref, shallow=False)
    assert device.alive()
