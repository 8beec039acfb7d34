"""A job with frames that must be refused while it runs, shared by the native stand-in's and the board's
hardening tests (tests/sim/test_device_hardening.py, tests/sim/test_stream_board_3mbaud.py)."""

from __future__ import annotations

from wavemesh.device import protocol as P
from wavemesh.device import stream as S

REFUSED_IN_A_JOB = (P.FrameType.ABORT, P.FrameType.STATUS, P.FrameType.ACK)  # with a payload: BAD_LENGTH


def run_with_payloads(host: S.Device, a, levels: int, fixed) -> tuple[list, dict, dict]:
    """Configure, upload and run the job of the samples `a` (levels M) on `host`; when the first level
    arrives, send ABORT, STATUS and ACK each with a one-byte payload (sequence 200 + type).  Returns the
    levels, DONE's fields and {frame type: the ERROR code each got}."""
    h, w = a.shape
    host.configure(S.config_payload(w, h, levels, 10, fixed))
    host.upload(a)
    got, seen = [], []
    read = host.link.read_frame

    def read_and_keep(timeout):
        f = read(timeout)
        seen.append(f)
        return f

    host.link.read_frame = read_and_keep

    def on_level(lv):
        if not got:
            for t in REFUSED_IN_A_JOB:
                host.link.write_frame(t, 200 + t, b"\x01")
        got.append(lv)

    out, done = host.run(S.samples_crc(a), w, h, on_level=on_level)
    refused = {f.seq - 200: f.fields()["code"] for f in seen if f.type == P.FrameType.ERROR}
    return out, done, refused
