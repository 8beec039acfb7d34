"""The link layer of the wire protocol: SLIP framing, CRC-32, a reader that yields whole frames.

docs/protocol.md has the byte tables; :mod:`wavemesh.device.protocol` the constants.  A frame on the wire::

    0xC0 | type | seq | len u16 | payload[len] | crc u32 | 0xC0

(SLIP-escaped between the delimiters; crc = zlib.crc32 of type .. payload, little-endian.)

:class:`Link` opens any pyserial URL (``/dev/ttyUSB1``, ``socket://127.0.0.1:7720`` for the simulated
board or the native stand-in device, ``rfc2217://``, ``loop://``) or takes an open port object,
writes frames, and reads whole, checked frames: :meth:`Link.read_frame` returns the next frame whose
CRC and length are right and counts (and with ``trace`` dumps) the damaged ones it skips; it raises
:class:`LinkTimeout` when none came in time.  Retries live one level up (:mod:`wavemesh.device.stream`),
where it is known what to send again.
"""

from __future__ import annotations

import select
import struct
import sys
import time
import zlib
from dataclasses import dataclass, field

import serial

from wavemesh.device import protocol as P
from wavemesh.device.memmap import UART_BAUD
from wavemesh.errors import WavemeshError

# --- link constants -----------------------------------------------------------------------------------
DEFAULT_BAUD = UART_BAUD  # the board's UART after reset (memmap's, the one source; a socket ignores it)
POLL_INTERVAL = 0.001  # s between polls of a port that had nothing to read (first poll)
POLL_MAX = 0.005  # s: the longest pause between polls (latency added to a frame at most)
READ_CHUNK = 65536  # bytes asked of the port per read
TRACE_BYTES = 128  # bytes of a frame shown by --trace (the rest is summarised)
_HEAD = struct.Struct("<BBH")


class LinkError(WavemeshError):
    """The port cannot be opened or used, or the peer went away."""


class LinkTimeout(LinkError):
    """No (valid) frame arrived in time."""


class PortBusy(LinkError):
    """Another program holds the port."""


# ---------------------------------------------------------------------------------------------------
# Framing


def slip_encode(raw: bytes) -> bytes:
    """A frame's bytes between two END delimiters, with END and ESC escaped."""
    body = raw.replace(bytes([P.SLIP_ESC]), bytes([P.SLIP_ESC, P.SLIP_ESC_ESC])).replace(
        bytes([P.SLIP_END]), bytes([P.SLIP_ESC, P.SLIP_ESC_END]))
    return bytes([P.SLIP_END]) + body + bytes([P.SLIP_END])


def frame_bytes(ftype: int, seq: int, payload: bytes = b"") -> bytes:
    """The unescaped frame: header, payload, CRC."""
    if len(payload) > P.MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes > {P.MAX_PAYLOAD}")
    head = _HEAD.pack(ftype, seq & 0xFF, len(payload)) + payload
    return head + struct.pack("<I", zlib.crc32(head))


def encode_frame(ftype: int, seq: int, payload: bytes = b"") -> bytes:
    """The frame as it goes on the wire."""
    return slip_encode(frame_bytes(ftype, seq, payload))


@dataclass(frozen=True)
class Frame:
    type: int
    seq: int
    payload: bytes

    @property
    def name(self) -> str:
        try:
            return P.FrameType(self.type).name
        except ValueError:
            return f"0x{self.type:02x}"

    def fields(self) -> dict:
        """The payload's fixed fields (the payload's length was checked on reception)."""
        return P.PAYLOAD[P.FrameType(self.type)].unpack(self.payload)

    def tail(self) -> bytes:
        return self.payload[P.PAYLOAD[P.FrameType(self.type)].size:]


class FrameError(ValueError):
    """A delimited run of bytes that is not a valid frame (its reason in the message)."""


def parse_frame(raw: bytes) -> Frame:
    """Check one unescaped frame (length, CRC, known type, payload size) and split it."""
    if len(raw) < P.HEADER_BYTES + P.CRC_BYTES:
        raise FrameError(f"short frame ({len(raw)} bytes)")
    ftype, seq, n = _HEAD.unpack_from(raw)
    if len(raw) != P.HEADER_BYTES + n + P.CRC_BYTES:
        raise FrameError(f"length field {n} but {len(raw) - P.HEADER_BYTES - P.CRC_BYTES} payload bytes")
    (crc,) = struct.unpack_from("<I", raw, len(raw) - P.CRC_BYTES)
    if crc != zlib.crc32(raw[:-P.CRC_BYTES]):
        raise FrameError("CRC mismatch")
    payload = raw[P.HEADER_BYTES:-P.CRC_BYTES]
    try:
        t = P.FrameType(ftype)
    except ValueError:
        raise FrameError(f"unknown frame type 0x{ftype:02x}") from None
    m = P.PAYLOAD[t]
    if len(payload) < m.size or (t not in P.VARIABLE and len(payload) != m.size):
        raise FrameError(f"{t.name} payload of {len(payload)} bytes")
    return Frame(ftype, seq, payload)


class SlipDecoder:
    """Splits a byte stream into unescaped frames.  feed() returns what completed: bytes for a frame,
    a FrameError for a run that was not one (bad escape, too long)."""

    def __init__(self, limit: int = P.MAX_FRAME):
        self.limit = limit
        self.buf = bytearray()
        self.esc = False
        self.bad: str | None = None  # why the current run is discarded

    def feed(self, data: bytes) -> list[bytes | FrameError]:
        out: list[bytes | FrameError] = []
        for b in data:
            if b == P.SLIP_END:
                if self.bad is not None:
                    out.append(FrameError(self.bad))
                elif self.esc:
                    out.append(FrameError("frame ends in an escape"))
                elif self.buf:
                    out.append(bytes(self.buf))
                self.buf.clear()
                self.esc, self.bad = False, None
                continue
            if self.bad is not None:
                continue
            if self.esc:
                self.esc = False
                if b == P.SLIP_ESC_END:
                    b = P.SLIP_END
                elif b == P.SLIP_ESC_ESC:
                    b = P.SLIP_ESC
                else:
                    self.bad = f"bad escape 0x{b:02x}"
                    continue
            elif b == P.SLIP_ESC:
                self.esc = True
                continue
            if len(self.buf) >= self.limit:
                self.bad = f"frame longer than {self.limit} bytes"
                continue
            self.buf.append(b)
        return out

    def reset(self) -> None:
        self.buf.clear()
        self.esc, self.bad = False, None


# ---------------------------------------------------------------------------------------------------
# The port


def open_port(port, baud: int = DEFAULT_BAUD):
    """A pyserial port from a URL (opened here) or an open port object (used as it is)."""
    if not isinstance(port, str):
        return port
    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=0, write_timeout=None)
    except (serial.SerialException, OSError, ValueError) as e:
        raise _open_error(port, e) from None


def _open_error(url: str, e: Exception) -> LinkError:
    text = str(e)
    low = text.lower()
    if "busy" in low or "errno 16" in low or "exclusively lock" in low or "resource temporarily" in low:
        return PortBusy(f"cannot open {url}: the port is busy",
                        "another program (a terminal, another wavemesh) holds it: close that first")
    if url.startswith("socket://") and ("refused" in low or "errno 111" in low):
        return LinkError(f"cannot connect to {url}: no device is listening there",
                         "start the simulated board (`make sim`) or the native stand-in "
                         "(`make native-device`), or check the port number")
    if "no such file" in low or "errno 2" in low or "could not open port" in low and "errno 2" in low:
        return LinkError(f"cannot open {url}: no such port",
                         "is the board plugged in? `python -m serial.tools.list_ports` lists the ports")
    if "permission" in low or "errno 13" in low:
        return LinkError(f"cannot open {url}: permission denied",
                         "add yourself to the group that owns the port (dialout on Debian) and log in again")
    return LinkError(f"cannot open {url}: {text}", "give a pyserial URL: /dev/ttyUSB1, socket://HOST:PORT, "
                                                   "rfc2217://HOST:PORT, loop://")


@dataclass
class LinkStats:
    frames_out: int = 0
    frames_in: int = 0
    bytes_out: int = 0
    bytes_in: int = 0
    damaged: int = 0  # delimited runs that were not valid frames
    reasons: dict = field(default_factory=dict)


class Link:
    """Frames over a pyserial port.

    ``trace`` (a file, e.g. sys.stderr, or True for stderr) dumps every frame sent and received and
    every damaged one skipped.
    """

    def __init__(self, port, baud: int = DEFAULT_BAUD, trace=None):
        self.url = port if isinstance(port, str) else getattr(port, "name", None) or repr(port)
        self.port = open_port(port, baud)
        self._own = isinstance(port, str)
        self._saved_timeout = None if self._own else self.port.timeout
        if not self._own:
            self.port.timeout = 0  # reads return what is there; read_frame does the waiting
        self.trace = sys.stderr if trace is True else (trace or None)
        self.decoder = SlipDecoder()
        self.pending: list[bytes | FrameError] = []
        self.stats = LinkStats()
        self.t0 = time.monotonic()
        self._fd = _waitable(self.port)

    # --- lifetime --------------------------------------------------------------------------------------
    @property
    def reopenable(self) -> bool:
        """A port this link opened from a URL (it can open it again after the connection broke)."""
        return self._own

    def reopen(self) -> None:
        """Close the port and open the URL again (a socket's new connection; the same baud), with an
        empty receive side.  LinkError when it cannot be opened now."""
        baud = self.baud
        self.close()
        self.port = open_port(self.url, baud)
        self.decoder = SlipDecoder()
        self.pending = []
        self._fd = _waitable(self.port)

    def close(self) -> None:
        if self._own:
            try:
                self.port.close()
            except Exception:  # noqa: BLE001 - closing a broken port must not hide the real error
                pass
        else:
            self.port.timeout = self._saved_timeout  # the caller's port as it was, still open

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- trace -----------------------------------------------------------------------------------------
    def _dump(self, tag: str, what: str, raw: bytes) -> None:
        if not self.trace:
            return
        t = time.monotonic() - self.t0
        self.trace.write(f"{t:9.3f} {tag} {what} ({len(raw)} bytes)\n")
        show = raw[:TRACE_BYTES]
        for i in range(0, len(show), 16):
            self.trace.write(f"          {i:04x}  {show[i:i + 16].hex(' ')}\n")
        if len(raw) > TRACE_BYTES:
            self.trace.write(f"          ... {len(raw) - TRACE_BYTES} more bytes\n")

    # --- writing ---------------------------------------------------------------------------------------
    def write_frame(self, ftype: int, seq: int, payload: bytes = b"") -> None:
        raw = frame_bytes(ftype, seq, payload)
        wire = slip_encode(raw)
        if self.trace:
            self._dump("TX", f"{_name(ftype)} seq {seq & 0xFF}", raw)
        try:
            self.port.write(wire)
        except Exception as e:  # serial.SerialException, OSError: the peer went away
            raise LinkError(f"cannot write to {self.url}: {e}",
                            "the device closed the connection (or was unplugged)") from None
        self.stats.frames_out += 1
        self.stats.bytes_out += len(wire)

    def write_raw(self, data: bytes) -> None:
        """Bytes as they are (wavemesh.device.stage's byte stream; tests: garbage on the line)."""
        if self.trace:
            self._dump("TX", "raw", data)
        try:
            self.port.write(data)
        except Exception as e:  # serial.SerialException, OSError: the peer went away
            raise LinkError(f"cannot write to {self.url}: {e}",
                            "the device closed the connection (or was unplugged)") from None
        self.stats.bytes_out += len(data)

    # --- reading ---------------------------------------------------------------------------------------
    def _read_some(self, deadline: float) -> bool:
        """Wait until some bytes came (True) or the deadline passed (False)."""
        data = self._wait_bytes(deadline, READ_CHUNK)
        if data:
            self.pending.extend(self.decoder.feed(data))
        return bool(data)

    def read_raw(self, timeout: float, limit: int = READ_CHUNK) -> bytes:
        """Unframed bytes, at most ``limit``: what came within ``timeout`` s (b"" if nothing), for a device
        that speaks a plain byte stream (wavemesh.device.stage: the FPGA stage's job)."""
        data = self._wait_bytes(time.monotonic() + timeout, limit)
        if data and self.trace:
            self._dump("RX", "raw", data)
        return data

    def _wait_bytes(self, deadline: float, limit: int) -> bytes:
        """The bytes that came first (b"" when none did by the deadline), counted."""
        pause = POLL_INTERVAL
        while True:
            try:
                data = self.port.read(limit)
            except Exception as e:  # serial.SerialException: socket disconnected, device unplugged
                hint = "the device went away (a simulated board serves one client at a time)"
                raise LinkError(f"the connection to {self.url} broke: {e}", hint) from None
            if data:
                self.stats.bytes_in += len(data)
                return data
            now = time.monotonic()
            if now >= deadline:
                return b""
            if self._fd is not None:  # a socket or a tty: sleep until something arrives
                try:
                    select.select([self._fd], [], [], min(deadline - now, 0.5))
                    continue
                except (OSError, ValueError):
                    self._fd = None
            time.sleep(min(pause, deadline - now))
            pause = min(POLL_MAX, pause * 2)

    def read_frame(self, timeout: float) -> Frame:
        """The next valid frame; damaged ones are counted and skipped.  LinkTimeout after `timeout` s."""
        deadline = time.monotonic() + timeout
        while True:
            while self.pending:
                item = self.pending.pop(0)
                if isinstance(item, FrameError):
                    self._damaged(str(item), b"")
                    continue
                try:
                    f = parse_frame(item)
                except FrameError as e:
                    self._damaged(str(e), item)
                    continue
                self.stats.frames_in += 1
                if self.trace:
                    self._dump("RX", f"{f.name} seq {f.seq}", item)
                return f
            if not self._read_some(deadline):
                raise LinkTimeout(f"no frame from the device within {timeout:g} s")

    def poll_frame(self) -> Frame | None:
        """A frame that has already arrived, or None (never waits)."""
        try:
            return self.read_frame(0)
        except LinkTimeout:
            return None

    def _damaged(self, why: str, raw: bytes) -> None:
        self.stats.damaged += 1
        key = why.split(" (")[0].split(" 0x")[0]
        self.stats.reasons[key] = self.stats.reasons.get(key, 0) + 1
        if self.trace:
            self._dump("RX", f"damaged frame skipped: {why}", raw)

    @property
    def baud(self) -> int:
        return int(getattr(self.port, "baudrate", 0) or 0)

    def set_baud(self, baud: int) -> None:
        """Set the port's rate (a socket takes any and ignores it); LinkError when the port refuses it.
        What was received before is dropped (it came at the old rate)."""
        try:
            self.port.baudrate = baud
        except Exception as e:  # ValueError, serial.SerialException: the driver does not take the rate
            raise LinkError(f"{self.url} does not take {baud} baud: {e}",
                            "give a rate the USB-serial bridge supports, or leave --link-baud out") from None
        self.discard_input()

    def discard_input(self) -> None:
        """Drop everything received so far (esptool's flush before a sync)."""
        try:
            self.port.reset_input_buffer()
        except Exception:  # noqa: BLE001 - not every port object has it
            pass
        self.pending.clear()
        self.decoder.reset()


def _waitable(port):
    """Something select() can wait on for this port (socket:// and POSIX serial ports), or None."""
    sock = getattr(port, "_socket", None)
    if sock is not None:
        return sock
    try:
        fd = port.fileno()
        return fd if isinstance(fd, int) and fd >= 0 else None
    except Exception:  # noqa: BLE001 - loop://, test doubles: poll instead
        return None


def _name(ftype: int) -> str:
    try:
        return P.FrameType(ftype).name
    except ValueError:
        return f"0x{ftype:02x}"
