"""Changing the line's rate after HELLO (BAUD, `wavemesh stream --link-baud`), against the native stand-in
device paced like a UART (--baud): the switch happens and the job's mesh is `wavemesh mesh`'s; a device
that cannot switch, a rate it cannot reach and a switch whose proof fails (the fault proxy drops every
frame after the device's OK, as a host at a rate the device does not run at would hear nothing) each
end in one warning line and the job at the start rate, the same mesh; the device goes back to its start
rate by itself; BAUD outside the idle state, of the wrong length or with a divisor outside the stated
range gets its error code."""

from __future__ import annotations

import time
from collections import namedtuple
from pathlib import Path

import numpy as np
import pytest
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.harness import run_cli
from wavemesh.harness.faultproxy import FrameTap
from wavemesh.harness.nativedev import NativeDevice, build_wmdev
from wavemesh.io.synth import make

pytestmark = pytest.mark.sim

Result = namedtuple("Result", "code out err")
FAST = S.Timeouts(sync=0.5, sync_attempts=5, reply=0.5, attempts=3, ack=0.5, job=10.0)


@pytest.fixture(scope="module")
def wmdev_exe() -> Path:
    return build_wmdev()


@pytest.fixture(scope="module")
def paced(wmdev_exe):
    d = NativeDevice(wmdev_exe, "--baud", "115200", "--quiet")
    yield d
    d.stop()


@pytest.fixture(scope="module")
def ref(tmp_path_factory):
    d = tmp_path_factory.mktemp("baud")
    np.save(d / "ball.npy", make("ball", 32)[:24, :30])
    code, _, err = run_cli("mesh", str(d / "ball.npy"), "-o", str(d / "ref.obj"), "-q")
    assert code == 0, err
    return d


def stream(src: Path, url: str, out: Path, *opts: str):
    return Result(*run_cli("stream", str(src / "ball.npy"), "-o", str(out), "--port", url, "--report",
                           str(out.with_suffix(".json")), *opts))


def report(out: Path) -> dict:
    import json

    return json.loads(out.with_suffix(".json").read_text())


def test_the_switch_happens_and_the_mesh_is_the_same(paced, ref, tmp_path):
    out = tmp_path / "s.obj"
    r = stream(ref, paced.url, out, "--link-baud", "921600")
    assert r.code == 0, r.err
    assert "warning" not in r.err
    assert "link: 921600 baud" in r.out
    assert out.read_bytes() == (ref / "ref.obj").read_bytes()
    t = report(out)["transfer"]
    assert t["baud"] == 115200 and abs(t["line_baud"] - 921600) <= P.BAUD_TOLERANCE * 921600
    assert t["bytes_sent"] < t["height_bytes"]  # the device states FEATURE_RICE: coded samples
    # auto: the fastest common rate the device reaches (wmdev: every one of them)
    r = stream(ref, paced.url, out, "--link-baud", "auto")
    assert r.code == 0, r.err
    assert abs(report(out)["transfer"]["line_baud"] - P.COMMON_BAUDS[0]) <= 0.01 * P.COMMON_BAUDS[0]
    # the next client starts at the start rate again
    with S.Device(paced.url, timeouts=FAST) as dev:
        assert dev.sync().baud == 115200


@pytest.mark.parametrize("how", ["fixed rate", "unreachable rate"])
def test_no_switch_is_one_warning_and_the_job_runs(wmdev_exe, ref, tmp_path, how):
    dev = NativeDevice(wmdev_exe, "--baud", "115200", "--quiet", *(["--no-baud-switch"] if how == "fixed rate"
                                                                  else []))
    try:
        out = tmp_path / "s.obj"
        rate = "921600" if how == "fixed rate" else "20000000"  # beyond wmdev's 10 Mbaud
        r = stream(ref, dev.url, out, "--link-baud", rate)
        assert r.code == 0, r.err
        warnings = [ln for ln in r.err.splitlines() if ln.startswith("warning:")]
        assert len(warnings) == 1 and "staying at 115200 baud" in warnings[0], r.err
        assert out.read_bytes() == (ref / "ref.obj").read_bytes()
        assert report(out)["transfer"]["line_baud"] == 115200
    finally:
        dev.stop()


def test_a_failed_switch_falls_back_to_the_start_rate(paced, ref, tmp_path, monkeypatch):
    """After the device's OK to BAUD nothing gets through for longer than the device's probe window (a
    line at two different rates): the host's proof fails, the device goes back by itself, the host syncs
    at the start rate, says so in one line, and the job runs there."""
    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", FAST)
    cut = {"until": 0.0}

    def on_frame(direction, f):
        if time.monotonic() < cut["until"]:
            return False
        if direction == "down" and f.type == P.FrameType.OK and f.fields()["request"] == P.FrameType.BAUD:
            cut["until"] = time.monotonic() + 1.3 * P.BAUD_PROBE_MS / 1000
        return True

    with FrameTap(("127.0.0.1", paced.port), on_frame) as tap:
        out = tmp_path / "s.obj"
        r = stream(ref, tap.url, out, "--link-baud", "921600")
    assert r.code == 0, r.err
    warnings = [ln for ln in r.err.splitlines() if ln.startswith("warning:")]
    assert len(warnings) == 1 and "failed" in warnings[0] and "115200" in warnings[0], r.err
    assert cut["until"] > 0  # the switch was asked for and answered
    assert out.read_bytes() == (ref / "ref.obj").read_bytes()
    assert report(out)["transfer"]["line_baud"] == 115200


def test_the_device_goes_back_to_the_start_rate_when_the_host_leaves(paced):
    """After a switch, BAUD_IDLE_MS without a valid frame outside a session: the start rate again (a
    board keeps its divisor across hosts; the next host starts at the start rate)."""
    with S.Device(paced.url, timeouts=FAST) as dev:
        dev.sync()
        new, problem = dev.change_baud(921600)
        assert problem is None and abs(new.baud - 921600) < 0.01 * 921600
        assert abs(dev.sync().baud - 921600) < 0.01 * 921600  # proved: it stays
        time.sleep(P.BAUD_IDLE_MS / 1000 + 0.3)
        assert dev.sync().baud == 115200


def test_baud_gets_its_error_codes(paced):
    with S.Device(paced.url, timeouts=FAST) as dev:
        info = dev.sync()
        assert info.div_min == 100 and info.div_max == 1_000_000

        def ask(payload: bytes) -> dict:
            seq = dev._next_seq()
            dev.link.write_frame(P.FrameType.BAUD, seq, payload)
            while True:
                f = dev.link.read_frame(2.0)
                if f.seq == seq and f.type in (P.FrameType.ERROR, P.FrameType.OK):
                    return {"type": f.type} | (f.fields() if f.type == P.FrameType.ERROR else {})

        e = ask(P.BAUD.pack(divisor=info.div_max + 1, baud=999))
        assert e["code"] == P.ErrorCode.BAD_BAUD and e["detail"] == info.div_max + 1
        e = ask(P.BAUD.pack(divisor=info.div_min - 1, baud=10**7))
        assert e["code"] == P.ErrorCode.BAD_BAUD
        e = ask(b"\0" * 3)
        assert e["code"] == P.ErrorCode.BAD_LENGTH
        dev.configure(P.CONFIG.pack(**{f.name: 0 for f in P.CONFIG.fields}
                                    | dict(width=4, height=4, levels=1, zeta=65536, scale_m=1)))
        e = ask(P.BAUD.pack(divisor=1000, baud=10**6))
        assert e["code"] == P.ErrorCode.BAD_STATE and e["state"] == P.State.RECEIVING
        # nothing switched: the device still answers at the start rate
        assert dev.sync().baud == 115200
