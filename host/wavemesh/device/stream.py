"""A session with a wavemesh device over the wire protocol (docs/protocol.md): the host's side.

:class:`Device` is to the protocol what esptool's loader is to the ROM's: it syncs (HELLO with
retries), sends requests and waits for their answers with bounded retries, streams the samples under
a window of DATA frames with go-back-N retransmission, and collects the levels the device sends,
asking again for whatever arrived damaged.  Every wait has a timeout and every retry loop a bound,
so a session ends with the meshes or with one :class:`~wavemesh.errors.WavemeshError` in bounded
time, never with a hang or a silently different mesh (every frame and every level carries a CRC-32).

    with Device("socket://127.0.0.1:7721") as dev:
        info = dev.sync()
        dev.configure(config_payload(...))
        dev.upload(samples)
        levels, done = dev.run(samples_crc(samples), on_level=show)

:func:`wavemesh.api.stream` (``wavemesh stream``) drives it.
"""

from __future__ import annotations

import random
import time
import zlib
from dataclasses import dataclass, field, replace
from fractions import Fraction

import numpy as np

from wavemesh.device import protocol as P
from wavemesh.device.coding import SampleEncoder, decode_level_body
from wavemesh.device.link import DEFAULT_BAUD, Frame, Link, LinkError, LinkTimeout
from wavemesh.errors import WavemeshError
from wavemesh.mesh import Mesh

# --- timeouts and retries (host side; seconds of wall time) -------------------------------------------
# Inside a session the device drops everything after its stated session timeout without a valid frame,
# so the host never stays silent that long: it writes again (a repeated request, or during the upload
# a STATUS probe) after protocol.host_resend_s(...) of the device's HELLO, the one rule both sides
# follow.  The rest bounds how long the host waits for a device that does not answer at all.


@dataclass(frozen=True)
class Timeouts:
    sync: float = 1.0  # s to wait for the answer to one HELLO
    sync_attempts: int = 5  # HELLOs before "no device answers"
    reply: float = 2.0  # s to wait for the answer to a request (CONFIG, RUN, STATUS, ABORT) ...
    attempts: int = 5  # ... this many times over (repeated every resend interval) before giving up
    ack: float | None = None  # s: the resend interval; None: protocol.host_resend_s of the device's HELLO
    data_retries: int = 8  # upload: rewinds (a NAK, a probe finding a loss) without progress, then give up
    level_retries: int = 40  # requests for the rest of one level without progress before giving up
    job: float = 120.0  # s the device may stay silent while it computes
    deadline: float | None = None  # s for the whole session (sync to DONE); None: each wait bounded alone
    reconnects: int = 8  # a connection lost during the job: reopened and the job resumed this many times
    keepalive: float | None = None  # s the host stays silent in a job at most; None: KEEPALIVE_S (a device
    # slower than real time, the simulated board, needs more: see harness.simboard.SIM_TIMEOUTS)


DEFAULT_TIMEOUTS = Timeouts()

# --- frame sizes on a lossy line ----------------------------------------------------------------------
# A frame is lost when any of its bytes is, so on a line that loses a byte in every few hundred most
# 1 KiB frames never get through.  Like XMODEM-1K falling back to 128-byte blocks, the host halves its
# DATA frames after every go-back and asks the device (ACK.chunk) for half-size MESH frames after every
# level pass with a hole, down to SMALLEST_TAIL bytes, and doubles them again after clean stretches.
# Near 64 bytes the framing (some 20 bytes a frame) and the losses (0.2 % a byte: 15 % of the frames)
# cost about the same.
SMALLEST_TAIL = 64  # bytes of samples or level stream in one frame, at the least
GROW_AFTER = 2  # windows (DATA) or levels (MESH) without a loss before frames double again
PROBE_RTTS = 3  # upload: a STATUS probe after this many smoothed round trips without progress ...
PROBE_MIN_S = 0.05  # ... but not sooner than this
WANT_SPAN = 8  # holes of a level within this many frames of the first are asked for in one ACK
# The device has written a level long before its bytes arrive when the line buffers (a socket, a USB
# bridge) and stalls; it repeats LEVEL_END after ACK_TIMEOUT_MS without a frame, and ends the job with
# NO_ACK only after its link timeout (HELLO_REPLY.link_timeout_s) without one.  So while a job runs the
# host writes KEEPALIVE (never answered) whenever it wrote nothing for KEEPALIVE_S, and every
# FLOW_KEEPALIVE_S while MESH frames still come (the device, reading again, hears it and does not
# repeat LEVEL_END for nothing): a pause of the line or of the host, however long its parts add up to,
# never ends the job; only a silence longer than the link timeout does.  Since every frame postpones the
# device's repeat, a silence while the host waits for the rest of a level (or for DONE) gets RESUME
# instead of KEEPALIVE: the device sends what is missing at once (Device.run).
KEEPALIVE_S = P.KEEPALIVE_MS / 1000
FLOW_KEEPALIVE_S = P.ACK_TIMEOUT_MS / 2000
RECONNECT_PAUSE_S = 0.2  # between attempts to open a connection that was lost during the job


class DeviceError(WavemeshError):
    """The device refused a request or its job failed: an ERROR frame or a DONE with an error code."""

    def __init__(self, message: str, hint: str | None = None, code: int = 0, detail: int = 0):
        super().__init__(message, hint)
        self.code = code
        self.detail = detail


class ProtocolError(WavemeshError):
    """The device sent something the protocol does not allow (a firmware bug, or another protocol)."""


class DeadlineError(LinkTimeout):
    """The session ran past the deadline the user set (Timeouts.deadline, ``--deadline``)."""


def reachable(clk_hz: int, div_min: int, div_max: int, baud: int) -> tuple[int, int] | None:
    """(divisor, the device's rate) nearest to baud for a device whose HELLO_REPLY states clk_hz and the
    divisors div_min..div_max, or None when it cannot switch (div_max 0) or lands farther than
    protocol.BAUD_TOLERANCE from baud."""
    if not div_max or baud <= 0:
        return None
    div = min(max(P.baud_divisor(clk_hz, baud), div_min), div_max)
    rate = P.divisor_baud(clk_hz, div)
    return (div, rate) if abs(rate - baud) <= P.BAUD_TOLERANCE * baud else None


def auto_rate(clk_hz: int, div_min: int, div_max: int) -> int | None:
    """The rate `--link-baud auto` asks of a device whose HELLO_REPLY states clk_hz and the divisors
    div_min..div_max: the first of protocol.COMMON_BAUDS it reaches (reachable), or None."""
    return next((b for b in P.COMMON_BAUDS if reachable(clk_hz, div_min, div_max, b)), None)


@dataclass(frozen=True)
class DeviceInfo:
    """HELLO_REPLY: what the device is and can do."""

    version: int
    fw_version: tuple[int, int]
    name: str
    max_width: int
    max_height: int
    max_samples: int
    tri_capacity: int
    max_levels: int
    window: int
    max_payload: int
    clk_hz: int
    baud: int
    features: int
    byte_timeout_ms: int
    ack_timeout_ms: int
    session_timeout_ms: int
    ack_retries: int
    idle_timeout_ms: int  # 0: the device never closes an idle connection (a UART)
    write_timeout_ms: int  # 0: the device never gives up on a peer that does not read (a UART)
    div_min: int = 0  # BAUD: the rates clk_hz / d for d in div_min..div_max
    div_max: int = 0  # 0: the device cannot switch its rate
    link_timeout_s: int = 0  # a job ends with NO_ACK after this silence of the host (0: not stated)

    @classmethod
    def from_fields(cls, f: dict) -> DeviceInfo:
        name = f["name"].rstrip(b"\0").decode("ascii", "replace")
        return cls(f["version"], (f["fw_major"], f["fw_minor"]), name,
                   f["max_width"], f["max_height"], f["max_samples"], f["tri_capacity"], f["max_levels"],
                   f["window"], f["max_payload"], f["clk_hz"], f["baud"], f["features"], f["byte_timeout_ms"],
                   f["ack_timeout_ms"], f["session_timeout_ms"], f["ack_retries"], f["idle_timeout_ms"],
                   f["write_timeout_ms"], f["div_min"], f["div_max"], f["link_timeout_s"])

    def reachable(self, baud: int) -> tuple[int, int] | None:
        """(divisor, the device's rate) nearest to baud, or None when the device cannot switch or lands
        farther than protocol.BAUD_TOLERANCE from it."""
        return reachable(self.clk_hz, self.div_min, self.div_max, baud)

    @property
    def auto_rate(self) -> int | None:
        """The rate `--link-baud auto` asks of the device (auto_rate), or None."""
        return auto_rate(self.clk_hz, self.div_min, self.div_max)

    @property
    def resend_s(self) -> float:
        """The longest the host may stay silent inside a session with this device (protocol.py)."""
        return P.host_resend_s(self.session_timeout_ms, self.baud, self.max_payload)

    @property
    def max_budget(self) -> int:
        """The largest triangle budget the device honours (a budget equal to the storage is none)."""
        return self.tri_capacity - 1

    def summary(self) -> str:
        clock = f"{self.clk_hz / 1e6:g} MHz" if self.clk_hz != 10**9 else "ns clock"
        what = ("the FPGA stage alone (the host refines)" if self.features & P.FEATURE_STAGE
                else f"{self.tri_capacity} triangles")
        return (f"{self.name} firmware {self.fw_version[0]}.{self.fw_version[1]}, protocol "
                f"{self.version >> 8}.{self.version & 0xFF}: up to {self.max_width} x {self.max_height} "
                f"({self.max_samples} samples), {what}, M <= {self.max_levels}, {clock}")

    def to_report(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass
class LevelResult:
    """One level as the device sent it."""

    level: int
    index: int  # order of arrival, 0 first
    mesh: Mesh
    stats: dict  # wm_level_stats (STAT_FIELDS) and e_max_q16, as wavemesh.refine.native.Level.stats
    cycles: int  # device cycles spent making it
    nbytes: int  # size of its level stream
    seconds: float  # host time when it arrived, from RUN


@dataclass
class JobResult:
    info: DeviceInfo
    levels: list[LevelResult]
    done: dict  # DONE's fields
    upload_seconds: float = 0.0
    job_seconds: float = 0.0
    upload_bytes: int = 0
    link: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------------
# Payloads


def samples_crc(samples: np.ndarray) -> int:
    """CRC-32 of the samples as they go on the wire (little-endian u16, row-major): RUN's field."""
    return zlib.crc32(np.ascontiguousarray(samples, dtype="<u2").tobytes())


def q16(x: float) -> int:
    return round(Fraction(x) * 2**16)


def config_payload(width: int, height: int, levels: int, tau_q: int, fixed, *, capacity: int = 0,
                   initial_only: bool = False, spline: bool = False, mask: bool = False) -> bytes:
    """CONFIG from the refiner's fixed-point parameters (wavemesh.refine.native.fixed_params: the same
    conversion `wavemesh mesh` uses, so both paths give the library the same numbers): every member of
    wm_params that CONFIG carries, by name, and the WM_FLAG_* bits; ``spline``: the spline wavelet's
    filter bank (CONFIG_SPLINE, for a device with FEATURE_SPLINE); ``mask``: a validity mask follows the
    samples (CONFIG_MASK, protocol.job_words; FEATURE_HOLES).  Every field is checked against the range
    the device checks (protocol.CONFIG) before it is sent."""
    carried = {f.name for f in P.CONFIG.fields} - {"flags"}
    values = {name: getattr(fixed, name) for name, _ in fixed._fields_ if name in carried}
    values.update(
        width=width, height=height, levels=levels, tau=tau_q, capacity=capacity,
        flags=((P.CONFIG_INITIAL_ONLY if initial_only else 0) | (P.CONFIG_SPLINE if spline else 0)
               | (P.CONFIG_MASK if mask else 0)
               | fixed.flags << P.CONFIG_REFINER_SHIFT))
    values = {k: int(v) for k, v in values.items()}
    problem = P.config_problem(values)
    if problem:
        raise WavemeshError(f"the job cannot be sent: {problem}",
                            "a parameter is beyond what the protocol carries; see `wavemesh stream --help`")
    return P.CONFIG.pack(**values)


def parse_level(buf: bytes, width: int, height: int) -> tuple[dict, Mesh, dict, int]:
    """A level stream -> (header fields, mesh, stats, cycles).  ProtocolError when inconsistent."""
    if len(buf) < P.LEVEL_HEADER.size:
        raise ProtocolError(f"level stream of {len(buf)} bytes")
    h = P.LEVEL_HEADER.unpack(buf)
    nv, nt, ib = h["vertex_slots"], h["triangles"], h["index_bytes"]
    off = P.LEVEL_HEADER.size
    if h["coding"] == P.LEVEL_DELTA:
        try:
            xy, tris = decode_level_body(buf[off:], nv, nt)
        except ValueError as e:
            raise ProtocolError(f"level {h['level']}: {e}") from None
    elif h["coding"] != P.LEVEL_RAW:
        raise ProtocolError(f"level {h['level']}: unknown coding {h['coding']}")
    elif ib not in (2, 4) or len(buf) != P.level_stream_size(nv, nt, ib):
        raise ProtocolError(f"level {h['level']}: {nv} vertex slots, {nt} triangles, {ib}-byte indices "
                            f"do not make {len(buf)} bytes")
    else:
        xy = np.frombuffer(buf, "<u2", count=2 * nv, offset=off).reshape(nv, 2).astype(np.int64)
        tris = np.frombuffer(buf, "<u2" if ib == 2 else "<u4", count=3 * nt,
                             offset=off + 4 * nv).reshape(nt, 3).astype(np.int64)
    free = xy[:, 0] == P.FREE_VERTEX
    live = ~free
    if np.any(xy[live] < 0) or np.any(xy[live, 0] >= width) or np.any(xy[live, 1] >= height):
        raise ProtocolError(f"level {h['level']}: a vertex outside the {width} x {height} grid")
    if nt and (tris.min() < 0 or tris.max() >= nv or np.any(free[tris])):
        raise ProtocolError(f"level {h['level']}: a triangle refers to a missing vertex")
    if not live.all():  # free vertex slots: dropped, as wavemesh.refine.native does
        remap = np.cumsum(live) - 1
        xy, tris = xy[live], remap[tris]
    stats = {name: h[f"st_{name}"] for name in P.STAT_FIELDS} | {"e_max_q16": h["st_e_max"],
                                                                 "removals": h["st_removals"]}
    return h, Mesh(width, height, xy, tris), stats, h["cycles"]


# ---------------------------------------------------------------------------------------------------
# The device


ERROR_HINTS = {
    P.ErrorCode.VERSION: "update the device's firmware (or the host tool): both must speak protocol "
                         f"{P.VERSION_MAJOR}.x",
    P.ErrorCode.TOO_LARGE: "crop or decimate the input (--crop, --decimate) to what the device holds",
    P.ErrorCode.BAD_VALUE: "see `wavemesh stream --help` for the ranges",
    P.ErrorCode.TIMEOUT: "the link stalled for seconds; try again (a lower --baud on a serial line)",
    P.ErrorCode.CAPACITY: "set a smaller --max-triangles, raise --zeta, or use more --levels",
    P.ErrorCode.DATA_CRC: "the link corrupts data that the frame checks did not catch; try again",
    P.ErrorCode.NO_ACK: "the device heard nothing from the host for its link timeout; check the link, "
                        "then try again",
    P.ErrorCode.BUSY: "another program (another wavemesh) is using the device: wait until it is done, "
                      "then try again",
}


def device_error(code: int, detail: int, request: int = 0) -> DeviceError:
    try:
        c = P.ErrorCode(code)
        text = P.ERROR_TEXT.get(c, c.name)
    except ValueError:
        c, text = None, f"unknown error code {code}"
    if c == P.ErrorCode.BAD_VALUE:
        text += f" ({P.config_field_at(detail)})"
    elif c == P.ErrorCode.TOO_LARGE:
        text += f" ({detail >> 16} x {detail & 0xFFFF})"
    elif c == P.ErrorCode.CAPACITY:
        text += f" at level {detail}"
    elif c == P.ErrorCode.JOB:
        text += f" (refiner code {detail - 2**32 if detail >= 2**31 else detail})"
    elif c == P.ErrorCode.BAD_STATE:
        try:
            text += f" (state {P.State(detail).name})"
        except ValueError:
            pass
    if request:
        try:
            text += f" in answer to {P.FrameType(request).name}"
        except ValueError:
            pass
    return DeviceError(f"device error {code} {c.name if c else ''}: {text}".replace("  ", " "),
                       ERROR_HINTS.get(c), code, detail)


class Device:
    """A wavemesh device behind a pyserial URL or an open port object."""

    def __init__(self, port, baud: int = DEFAULT_BAUD, trace=None, timeouts: Timeouts | None = None):
        """``timeouts``: DEFAULT_TIMEOUTS as it is when the device opens (None), else these."""
        self.link = Link(port, baud, trace)
        timeouts = DEFAULT_TIMEOUTS if timeouts is None else timeouts
        self.t = timeouts
        self.seq = random.randrange(256)  # a fresh session never looks like a repeat of the last one
        self.info: DeviceInfo | None = None
        self.t0 = time.monotonic()
        self.deadline = None if timeouts.deadline is None else self.t0 + timeouts.deadline
        self.where = "before the device answered"  # for the deadline's message
        self.resumes = 0  # connections reopened and the job resumed

    def close(self) -> None:
        self.link.close()

    def __enter__(self) -> Device:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _read(self, timeout: float) -> Frame:
        """The next valid frame within ``timeout`` s (LinkTimeout), and never past the deadline
        (DeadlineError)."""
        if self.deadline is not None:
            left = self.deadline - time.monotonic()
            if left <= 0:
                raise self._late()
            if timeout >= left:
                try:
                    return self.link.read_frame(left)
                except LinkTimeout:
                    raise self._late() from None
        return self.link.read_frame(timeout)

    def _late(self) -> DeadlineError:
        return DeadlineError(f"the device did not finish within the deadline of {self.t.deadline:g} s "
                             f"({self.where})",
                             "the link loses or stalls too much for that deadline: raise --deadline, or "
                             "check the cable and --baud")

    def _next_seq(self) -> int:
        self.seq = (self.seq + 1) & 0xFF
        return self.seq

    def _raise_if_error(self, f: Frame, request: int) -> None:
        if f.type == P.FrameType.ERROR:
            e = f.fields()
            if e["request"] in (request, 0):
                raise device_error(e["code"], e["detail"], e["request"])

    @property
    def resend_s(self) -> float:
        """The host's longest silence inside a session: from the device's HELLO (protocol.host_resend_s),
        or Timeouts.ack when that is shorter; before HELLO, the reply timeout."""
        if self.info is None:
            return self.t.reply if self.t.ack is None else min(self.t.ack, self.t.reply)
        return self.info.resend_s if self.t.ack is None else min(self.t.ack, self.info.resend_s)

    # --- requests ---------------------------------------------------------------------------------------
    def request(self, ftype: int, payload: bytes, expect: int, timeout: float | None = None,
                attempts: int | None = None) -> Frame:
        """Send a request until its answer comes, again after every resend interval (the same seq: the
        device answers a repeat from its cache without doing it twice), for timeout x attempts seconds
        in all; ERROR answers (and the device's own, request 0: the session is gone) raise DeviceError."""
        seq = self._next_seq()
        timeout = self.t.reply if timeout is None else timeout
        attempts = self.t.attempts if attempts is None else attempts
        every = min(timeout, self.resend_s)
        give_up = time.monotonic() + timeout * attempts
        sends = 0
        while True:
            now = time.monotonic()
            if now >= give_up - 1e-3 and sends:
                break
            self.link.write_frame(ftype, seq, payload)
            sends += 1
            deadline = min(now + every, give_up)
            while True:
                try:
                    f = self._read(max(0.0, deadline - time.monotonic()))
                except DeadlineError:
                    raise
                except LinkTimeout:
                    break
                if f.type == P.FrameType.ERROR and f.fields()["request"] == 0:
                    self._raise_if_error(f, ftype)  # unasked: the device dropped the session, or is busy
                if f.seq != seq:
                    continue  # an answer to something earlier
                self._raise_if_error(f, ftype)
                if f.type == expect:
                    return f
        raise LinkTimeout(f"no answer to {P.FrameType(ftype).name} from {self.link.url} after {sends} "
                          f"attempts in {timeout * attempts:g} s",
                          "the device stopped answering: is it still running?")

    def sync(self, attempts: int | None = None, timeout: float | None = None) -> DeviceInfo:
        """HELLO until the device answers (esptool's sync): its capabilities."""
        self.link.discard_input()
        payload = P.HELLO.pack(version=P.VERSION)
        attempts = self.t.sync_attempts if attempts is None else attempts
        timeout = self.t.sync if timeout is None else timeout
        for _ in range(attempts):
            try:
                f = self.request(P.FrameType.HELLO, payload, P.FrameType.HELLO_REPLY, timeout, 1)
            except DeadlineError:
                raise
            except LinkTimeout:
                continue
            info = DeviceInfo.from_fields(f.fields())
            if info.version >> 8 != P.VERSION_MAJOR:
                raise DeviceError(f"the device speaks protocol {info.version >> 8}.{info.version & 0xFF}, "
                                  f"this host {P.VERSION_MAJOR}.{P.VERSION_MINOR}",
                                  ERROR_HINTS[P.ErrorCode.VERSION], P.ErrorCode.VERSION)
            if not (2 <= info.max_width <= P.MAX_SIDE and 2 <= info.max_height <= P.MAX_SIDE
                    and 1 <= info.window <= P.MAX_WINDOW
                    and P.MIN_PAYLOAD <= info.max_payload <= P.MAX_PAYLOAD
                    and 1 <= info.max_levels <= P.MAX_LEVELS and info.clk_hz >= 1000
                    and info.session_timeout_ms >= 100
                    and (info.div_max == 0 or 1 <= info.div_min <= info.div_max)):
                raise ProtocolError(f"the device states impossible capabilities: {info}")
            self.info = info
            return info
        raise LinkTimeout(f"no device answers on {self.link.url} ({attempts} HELLOs, "
                          f"{timeout:g} s each)",
                          f"is the device running wavemesh firmware with protocol {P.VERSION_MAJOR} "
                          "(`make sim`, `make native-device`), at this --baud, and not serving another "
                          "client?")

    def change_baud(self, baud: int) -> tuple[DeviceInfo, str | None]:
        """Move the line from the start rate to ``baud`` after sync(), esptool's change_baud with a proof:
        BAUD(divisor) at the start rate, OK, both switch, a HELLO at the new rate proves it.  Returns the
        device's HELLO (at the rate the line has now) and None, or, when the switch did not happen or did
        not work, the HELLO at the start rate and one line saying why: the device went back by itself
        (BAUD_PROBE_MS without a valid frame) and the job runs at the start rate."""
        info = self.info
        start = self.link.baud
        if not info.div_max:
            return info, f"the device cannot change its rate: staying at {start} baud"
        got = info.reachable(baud)
        if got is None:
            div = min(max(P.baud_divisor(info.clk_hz, baud), info.div_min), info.div_max)
            near = P.divisor_baud(info.clk_hz, div)
            return info, (f"the device cannot run at {baud} baud (its nearest rate {near} is "
                          f"{100 * abs(near - baud) / baud:.1f} % off): staying at {start} baud")
        div, rate = got
        self.link.set_baud(baud)  # the port takes the rate? (LinkError if not, before the device switches)
        self.link.set_baud(start)
        try:
            self.request(P.FrameType.BAUD, P.BAUD.pack(divisor=div, baud=baud), P.FrameType.OK)
        except DeviceError as e:
            return info, f"the device refused {baud} baud ({e}): staying at {start} baud"
        switched = time.monotonic()
        self.link.set_baud(baud)
        probe = P.BAUD_PROBE_MS / 1000
        try:  # HELLOs at the new rate, well inside the device's probe window
            new = self.sync(attempts=3, timeout=min(self.t.sync, probe / 4))
            if new.baud and abs(new.baud - rate) > 1:
                raise ProtocolError(f"the device says {new.baud} baud after switching to {rate}")
            return new, None
        except LinkTimeout:
            pass
        # the device goes back to the start rate once its probe window has passed without a valid frame
        self.link.set_baud(start)
        time.sleep(max(0.0, switched + probe - time.monotonic()))
        return self.sync(), (f"the switch to {baud} baud failed (no answer at the new rate): back at "
                             f"{start} baud")

    def status(self) -> dict:
        return self.request(P.FrameType.STATUS, b"", P.FrameType.STATUS_REPLY).fields()

    def abort(self) -> None:
        self.request(P.FrameType.ABORT, b"", P.FrameType.OK)

    def configure(self, payload: bytes) -> None:
        self.request(P.FrameType.CONFIG, payload, P.FrameType.OK)

    # --- samples ------------------------------------------------------------------------------------------
    def upload(self, samples: np.ndarray, bar=None, extra: np.ndarray | None = None,
               coded: bool = True) -> int:
        """Send the (H, W) samples (then ``extra`` words raw: a validity mask) in DATA frames, a window at
        a time, compactly coded (wavemesh.device.coding; ``coded`` False: raw words); returns the bytes sent
        (frames repeated after a loss included).

        The device answers every DATA frame with DATA_ACK(next) and flags a gap (NAK): the host goes
        back to `next` (go-back-N).  A loss that leaves no later frame to show it (the window's last
        frame, or the DATA_ACKs after it) is found by a STATUS probe: when the device has been silent
        for the resend interval the host asks how many samples it stored.  The line keeps its order,
        so the answer comes after every frame sent before the probe was taken in: fewer samples than
        were sent before it means a loss, and the host goes back to them.  A slow device (a simulated
        board) only answers later; nothing is sent twice because of it."""
        info = self.info
        enc = SampleEncoder(samples, extra, coded)
        total = enc.total
        largest = min(info.max_payload, P.MAX_PAYLOAD) - P.DATA.size  # tail bytes of a frame
        smallest = min(largest, SMALLEST_TAIL)
        budget = largest  # halved after a go-back, doubled after clean windows
        in_flight: list[int] = []  # the end (sample) of every frame sent and not yet acknowledged
        clean = 0  # frames acknowledged since the last go-back (or the last growth)
        every = self.resend_s
        acked = sent = 0
        rewinds = 0  # go-backs since the last progress
        epoch = 0  # go-backs so far: a probe taken before the last one says nothing new
        probes: dict[int, tuple[int, int]] = {}  # seq -> (epoch, samples sent) when it was sent
        bytes_out0 = self.link.stats.bytes_out
        heard = time.monotonic()  # the last frame from the device
        write_by = heard + every  # the host writes again by then
        silence = self.t.reply * self.t.attempts
        # the probe's timer: a loss that no later frame shows is found after a few round trips (the time
        # from a DATA frame to its DATA_ACK, smoothed as TCP's), not after the resend interval: a probe
        # taken early only costs a STATUS (the line keeps its order, so its answer never shows a loss
        # that is not one); it backs off, doubling, up to the resend interval while none helps
        sent_at: dict[int, float] = {}  # end (sample) of a frame sent once -> when
        srtt: float | None = None
        backoff = 1

        def wait_s() -> float:
            return every if srtt is None else min(every, max(PROBE_MIN_S, PROBE_RTTS * srtt) * backoff)

        def go_back(to: int) -> None:
            nonlocal sent, epoch, rewinds, budget, clean, in_flight
            sent, epoch = to, epoch + 1
            in_flight = []
            sent_at.clear()  # a frame sent twice times nothing (Karn)
            rewinds += 1
            budget, clean = max(smallest, budget // 2), 0
            if rewinds > self.t.data_retries:
                raise LinkTimeout(f"the samples do not get through: stored {acked} of {total} after "
                                  f"{rewinds - 1} resends",
                                  "the link loses too much; check the cable and --baud")

        while acked < total:
            while sent < total and len(in_flight) < info.window:
                n, coding, tail = enc.frame(sent, budget)
                self.link.write_frame(P.FrameType.DATA, self._next_seq(),
                                      P.DATA.pack(offset=sent, count=n, coding=coding) + tail)
                sent += n
                in_flight.append(sent)
                sent_at[sent] = time.monotonic()
                write_by = time.monotonic() + wait_s()
            try:
                f = self._read(max(0.0, write_by - time.monotonic()))
            except DeadlineError:
                raise
            except LinkTimeout:
                if time.monotonic() - heard >= silence:
                    raise LinkTimeout(f"the device stopped answering during the upload ({acked} of {total} "
                                      f"samples stored, nothing heard for {silence:g} s)",
                                      "is it still running? check the cable and --baud") from None
                seq = self._next_seq()
                self.link.write_frame(P.FrameType.STATUS, seq)
                probes[seq] = (epoch, sent)
                backoff = min(2 * backoff, 64)
                write_by = time.monotonic() + wait_s()
                continue
            heard = time.monotonic()
            if f.type == P.FrameType.ERROR:
                e = f.fields()
                if e["request"] in (P.FrameType.DATA, P.FrameType.STATUS, 0):
                    raise device_error(e["code"], e["detail"], e["request"])
                continue
            if f.type == P.FrameType.STATUS_REPLY and f.seq in probes:
                taken, before = probes.pop(f.seq)
                st = f.fields()
                if st["state"] not in (P.State.RECEIVING, P.State.READY) or st["expected"] != total:
                    code = st["last_error"] or P.ErrorCode.TIMEOUT
                    raise device_error(code, st["last_detail"])  # the session is gone
                got = st["samples"]
            elif f.type == P.FrameType.DATA_ACK:
                ack = f.fields()
                got, taken, before = ack["next"], None, None
                if got in sent_at:
                    rtt = heard - sent_at.pop(got)
                    srtt = rtt if srtt is None else 0.875 * srtt + 0.125 * rtt
                if ack["flags"] & P.ACK_NAK and sent > got:
                    taken, before = epoch, sent  # the device saw a gap: go back at once
            else:
                continue  # a late answer to something earlier
            if got > total:
                raise ProtocolError(f"the device says it stored {got} of {total} samples")
            if got > acked:
                acked = got
                rewinds, backoff = 0, 1
                done = sum(1 for e in in_flight if e <= acked)
                in_flight = [e for e in in_flight if e > acked]
                clean += done
                if clean >= GROW_AFTER * info.window and budget < largest:
                    budget, clean = min(largest, 2 * budget), 0
                self.where = f"during the upload: {acked} of {total} samples stored"
                if bar:
                    bar.update(acked, f"{2 * acked // 1024} of {2 * total // 1024} KiB")
            if taken == epoch and got < before and sent > got:
                go_back(max(got, acked))
        return self.link.stats.bytes_out - bytes_out0

    # --- the job -------------------------------------------------------------------------------------------
    def _ack(self, kind: int, index: int, have: int, chunk: int = 0, want: int = 0) -> None:
        payload = P.ACK.pack(kind=kind, index=index, have=have, chunk=chunk, want=want)
        now = time.monotonic()
        if payload == self._last_ack[0] and now - self._last_ack[1] < FLOW_KEEPALIVE_S:
            return  # a LEVEL_END repeated while the first was on its way: this answer is on its way too
        self._last_ack = (payload, now)
        self._wrote = now
        self.link.write_frame(P.FrameType.ACK, self._next_seq(), payload)

    def _keepalive(self) -> None:
        self._wrote = time.monotonic()
        self.link.write_frame(P.FrameType.KEEPALIVE, self._next_seq())

    def _reconnect(self, crc: int, index: int, have: int, chunk: int, error: LinkError) -> None:
        """The connection broke during the job: open it again (the device keeps the job for its link
        timeout) and RESUME from the bytes the host has.  Raises ``error`` when that cannot be."""
        if not self.link.reopenable or self.resumes >= self.t.reconnects:
            raise error
        window = min(self.info.link_timeout_s or P.LINK_TIMEOUT_S, self.t.reply * self.t.attempts)
        give_up = time.monotonic() + window
        if self.deadline is not None:
            give_up = min(give_up, self.deadline)
        while True:
            time.sleep(RECONNECT_PAUSE_S)
            try:
                self.link.reopen()
                break
            except LinkError:
                if time.monotonic() >= give_up:
                    raise error from None
        self.resumes += 1
        self._resume = (P.RESUME.pack(crc=crc, index=index, chunk=chunk, have=have), time.monotonic(), error)
        self._send_resume()

    def _send_resume(self) -> None:
        self._wrote = time.monotonic()
        self.link.write_frame(P.FrameType.RESUME, self._next_seq(), self._resume[0])

    def run(self, crc: int, width: int, height: int, on_level=None, on_progress=None) -> tuple[list, dict]:
        """RUN, then the levels as they come (on_level(LevelResult) for each) until DONE.
        Returns (levels, DONE's fields); DeviceError when the job failed.

        While the job runs the host writes KEEPALIVE whenever it wrote nothing for KEEPALIVE_S (so the
        device tells a pause from a host that is gone), and a connection lost on the way is opened again
        and the job resumed where the host's bytes end (RESUME)."""
        seq = self._next_seq()
        payload = P.RUN.pack(crc=crc)
        self.link.write_frame(P.FrameType.RUN, seq, payload)
        t0 = last = self._wrote = time.monotonic()
        self._last_ack = (b"", 0.0)
        started, runs = False, 1
        levels: list[LevelResult] = []
        # the current level's bytes as they came, and a 1 for every byte that came: pieces after a lost
        # MESH frame are kept, and the ACK asks for the holes only
        buf, got = bytearray(), bytearray()
        largest = self.info.max_payload - P.MESH.size
        chunk = largest  # MESH tail bytes asked for (ACK.chunk): halved after a pass with a hole
        lossless = 0  # levels in a row that came whole in their first pass
        first_pass = True
        cap = self.info.tri_capacity  # a level of this device is at most this long (MESH beyond: ignored)
        limit = P.level_stream_size(self.info.max_samples + cap + 3, cap, 4)
        stale_asks = 0  # ACKs asking for more of the current level without getting any
        last_have = -1
        every = min(self.t.reply, self.resend_s)  # RUN again (the device waits for it in a session)
        give_up = t0 + self.t.reply * self.t.attempts
        link_s = self.info.link_timeout_s or P.LINK_TIMEOUT_S
        quiet_s = self.t.keepalive or min(KEEPALIVE_S, link_s / 4)  # the longest the host stays silent
        self.where = "before the first level"
        self._resume = None  # (RESUME's payload, when the connection was opened again, why) until an answer
        done_next = False  # the last level (LEVEL_LAST) arrived whole: DONE comes next

        def nudge() -> bytes | None:
            """RESUME's payload when the device must be waiting for the host's answer to a frame that did
            not come (a LEVEL_END of the level whose bytes came, the DONE after the last level), else None
            (the device may be computing: a RESUME would make it send a level twice)."""
            if got:
                have = got.find(0)
                have = len(got) if have < 0 else have
                return P.RESUME.pack(crc=crc, index=len(levels), chunk=chunk, have=have)
            if done_next:  # it waits for DONE's ACK, or for this level's (ours was lost): either comes again
                return P.RESUME.pack(crc=crc, index=len(levels) - 1, chunk=chunk, have=levels[-1].nbytes)
            return None

        def resume_after(error: LinkError) -> float:
            """Reopen and RESUME from the current level's first missing byte; returns when."""
            have = got.find(0)
            self._reconnect(crc, len(levels), len(got) if have < 0 else have, chunk, error)
            return time.monotonic()

        while True:
            try:
                now = time.monotonic()
                if self._resume and now - self._resume[1] >= self.t.reply * self.t.attempts:
                    raise LinkTimeout(f"{self._resume[2]}; the device did not answer after it was opened "
                                      "again", "the device stopped (or another program holds it): run the "
                                      "job again") from None
                if self._resume and now - self._wrote >= every:
                    self._send_resume()
                elif started and now - self._wrote >= quiet_s:
                    # the device repeats LEVEL_END and DONE only after ACK_TIMEOUT_MS without any frame, so
                    # a KEEPALIVE more often than that (a device slower than real time: the simulated board)
                    # would keep it from ever repeating one that was lost: after a silence the host asks
                    again = nudge() if now - last >= quiet_s else None
                    if again:
                        self._wrote = now
                        self.link.write_frame(P.FrameType.RESUME, self._next_seq(), again)
                    else:
                        self._keepalive()
                wait = (min(every, give_up - last) if not started else self.t.job) - (now - last)
                if started:
                    wait = min(wait, self._wrote + (every if self._resume else quiet_s) - now)
                try:
                    f = self._read(max(0.0, wait))
                except DeadlineError:
                    raise
                except LinkTimeout:
                    now = time.monotonic()
                    if started and now - last < self.t.job:
                        continue  # time to write a KEEPALIVE
                    if not started and now < give_up - 1e-3:
                        runs += 1
                        self.link.write_frame(P.FrameType.RUN, seq, payload)  # same seq: not run twice
                        last = time.monotonic()
                        continue
                    if not started:
                        raise LinkTimeout(f"no answer to RUN from {self.link.url} after {runs} attempts",
                                          "the device stopped answering") from None
                    where = f"after level {levels[-1].level}" if levels else "before the first level"
                    raise LinkTimeout(f"the device sent nothing for {self.t.job:g} s {where}",
                                      "a slow device (a simulated board) may need a longer --timeout"
                                      ) from None
            except LinkTimeout:
                raise
            except LinkError as e:
                if not started:
                    raise
                last = resume_after(e)
                continue
            last = time.monotonic()
            self._resume = None
            t = f.type
            if t == P.FrameType.OK and f.seq == seq:
                started = True
                continue
            if t == P.FrameType.ERROR:
                e = f.fields()
                if e["request"] == P.FrameType.RESUME:
                    raise DeviceError("the device no longer has the job (it ended, or another host started "
                                      "one, while the connection was lost)", "run the job again",
                                      e["code"], e["detail"])
                if e["code"] == P.ErrorCode.BUSY and self.resumes:  # the device has not let the old one go
                    last = resume_after(device_error(e["code"], e["detail"], e["request"]))
                    continue
                if (e["request"] == P.FrameType.RUN and f.seq == seq) or e["request"] == 0:
                    raise device_error(e["code"], e["detail"], e["request"])
                continue
            if t not in (P.FrameType.PROGRESS, P.FrameType.MESH, P.FrameType.LEVEL_END, P.FrameType.DONE):
                continue
            started = True
            x = f.fields()
            try:
                if t == P.FrameType.PROGRESS:
                    if on_progress:
                        on_progress(x)
                elif t == P.FrameType.MESH:
                    if last - self._wrote >= FLOW_KEEPALIVE_S:
                        self._keepalive()
                    if x["index"] == len(levels):
                        off, data = x["offset"], f.tail()
                        end = off + len(data)
                        if end <= limit:  # else not a level of this device: never asked for, ignored
                            if end > len(buf):
                                buf += bytes(end - len(buf))
                                got += bytes(end - len(got))
                            buf[off:end] = data
                            got[off:end] = b"\1" * len(data)
                elif t == P.FrameType.LEVEL_END:
                    idx = x["index"]
                    if idx < len(levels):  # our ACK was lost: again
                        self._ack(P.FrameType.LEVEL_END, idx, x["total"], chunk)
                        continue
                    if idx > len(levels):
                        raise ProtocolError(f"level index {idx} after {len(levels)} levels")
                    total = x["total"]
                    if total > limit:
                        raise ProtocolError(f"level {x['level']}: a stream of {total} bytes from a device of "
                                            f"{self.info.tri_capacity} triangles")
                    if len(buf) < total:
                        buf += bytes(total - len(buf))
                        got += bytes(total - len(got))
                    have = got.find(0, 0, total)
                    if have < 0 and zlib.crc32(buf[:total]) == x["crc"]:
                        hdr, mesh, stats, cycles = parse_level(bytes(buf[:total]), width, height)
                        lv = LevelResult(hdr["level"], idx, mesh, stats, cycles, total, time.monotonic() - t0)
                        levels.append(lv)
                        done_next = bool(x["flags"] & P.LEVEL_LAST)
                        self.where = f"{len(levels)} levels arrived, the last level {lv.level}"
                        lossless = lossless + 1 if first_pass else 0
                        if lossless >= GROW_AFTER and chunk < largest:
                            chunk, lossless = min(largest, 2 * chunk), 0
                        self._ack(P.FrameType.LEVEL_END, idx, total, chunk)
                        buf, got = bytearray(), bytearray()
                        stale_asks, last_have, first_pass = 0, -1, True
                        if on_level:
                            on_level(lv)
                        continue
                    if have < 0:  # all there but not right: everything again
                        got[:] = bytes(len(got))
                        have = 0
                    first_pass, lossless = False, 0
                    chunk = max(min(SMALLEST_TAIL, largest), chunk // 2)
                    if have > last_have:
                        last_have, stale_asks = have, 0
                    else:
                        stale_asks += 1
                        if stale_asks > self.t.level_retries:
                            raise LinkTimeout(f"level {x['level']} does not get through: {have} of {total} "
                                              f"bytes after {stale_asks} requests",
                                              "the link loses too much; check the cable and --baud")
                    # the holes that start within WANT_SPAN frames of the first, in one request
                    end, start = have, have
                    while 0 <= start < min(total, have + WANT_SPAN * chunk):
                        end = got.find(1, start, total)
                        end = total if end < 0 else end
                        start = got.find(0, end, total)
                    self._ack(P.FrameType.LEVEL_END, idx, have, chunk, end - have)
                else:  # DONE
                    self._ack(P.FrameType.DONE, 0, 0)
                    if x["status"] != 0:
                        raise device_error(x["status"], x["detail"])
                    if x["levels"] != len(levels):
                        raise ProtocolError(f"DONE says {x['levels']} levels, {len(levels)} arrived")
                    check_done(x, levels)
                    check_stack(x)
                    return levels, x
            except LinkTimeout:
                raise
            except LinkError as e:  # writing an ACK or a KEEPALIVE found the connection gone
                last = resume_after(e)


def check_done(done: dict, levels: list[LevelResult]) -> None:
    """DONE states the last level's triangles, vertices and E_max: they must be those of the last level
    that arrived (each level stream is checked frame by frame; this checks the job's end as a whole)."""
    if not levels:
        return
    last = levels[-1]
    said = (done["triangles"], done["vertices"], done["e_max"])
    got = (last.mesh.n_triangles, last.mesh.n_vertices, last.stats["e_max_q16"])
    if said != got:
        raise ProtocolError(f"DONE says the last level has {said[0]} triangles, {said[1]} vertices and E_max "
                            f"{said[2]} (Q16.16), but level {last.level} arrived with {got[0]}, {got[1]} "
                            f"and {got[2]}")


def check_stack(done: dict) -> None:
    """DONE's stack_peak, the device's stack's high-water mark, against its stack_bytes: a job whose stack
    came within protocol.STACK_GUARD_BYTES of the reserve, or went past it into the RAM below, is an
    error, whatever it sent (a device that states stack_bytes 0 does not measure its stack)."""
    size, peak = done["stack_bytes"], done["stack_peak"]
    if size and peak > size - P.STACK_GUARD_BYTES:
        what = (f"overflowed its {size}-byte reserve by {peak - size} bytes" if peak > size else
                f"came within {size - peak} bytes of its {size}-byte reserve (the guard: "
                f"{P.STACK_GUARD_BYTES})")
        raise DeviceError(f"the device's stack reached {peak} bytes: it {what}; the job's results are not "
                          "trusted", "the firmware's stack is too small for this job (memmap.STACK_BYTES, "
                          "docs/soc.md \"The stack's high-water mark\"); reset the device before the next "
                          "job")


def with_timeouts(t: Timeouts, **kw) -> Timeouts:
    return replace(t, **kw)
