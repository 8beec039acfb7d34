"""Host side of the board's stand-in exchange: HELLO, LOAD, READ (docs/soc.md has the byte tables).

A thin client in esptool's manner: it opens any pyserial URL (``/dev/ttyUSB1``,
``socket://127.0.0.1:7720`` for the simulated board of ``make sim``, ``rfc2217://``, ``loop://``)
or takes an open port, frames requests, reads whole responses and raises a :class:`BoardError` on a
timeout, a corrupt frame or an error status.  The full protocol of the next issue replaces it.

    with Board("socket://127.0.0.1:7720") as b:
        info = b.sync()                     # HELLO, with retries: the device's capabilities
        result = b.load(heights)            # (H, W) uint16 array -> CRC-32 and cycle counts
        back = b.read(0, heights.size)      # samples from the height memory

``python -m wavemesh.board URL hello | load FILE.npy | read FIRST COUNT`` does the same from a shell.
"""

from __future__ import annotations

import struct
import sys
import time
import zlib
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from wavemesh import memmap
from wavemesh.errors import WavemeshError

# --- link constants (docs/soc.md; firmware/board/app/main.c has the device side) ---------------
MAGIC = b"WM"
CHECK_SEED = 0xEF  # request check byte = CHECK_SEED ^ cmd ^ every argument byte
RESPONSE = 0x80  # response cmd = request cmd | RESPONSE
PROTOCOL_VERSION = 1
BAUD = memmap.UART_BAUD  # the board's rate after reset (a socket ignores it)

# --- timeouts and retries ----------------------------------------------------------------------
# The simulated board runs some ten times slower than a real one, so these are generous.
RESPONSE_TIMEOUT = 10.0  # s: a response must begin within this after its request
PER_BYTE_TIMEOUT = 0.002  # s added per payload byte (about 20 byte times at 115200 baud)
SYNC_RETRIES = 4  # HELLO attempts in sync() before giving up
SYNC_TIMEOUT = 3.0  # s to wait for the answer to one of sync()'s HELLOs
STALE_RESPONSES = 8  # answers to other requests (sent before, or caused by garbage) skipped per command


class Cmd(IntEnum):
    HELLO = 0x01
    LOAD = 0x02
    READ = 0x03


class Status(IntEnum):
    OK = 0
    BAD_CHECK = 1  # the request's check byte was wrong
    BAD_CMD = 2  # unknown command
    BAD_ARG = 3  # an argument out of range (size, range)
    TIMEOUT = 4  # the request or its data stopped arriving


class BoardError(WavemeshError):
    """The board did not answer, answered garbage, or refused a request."""

    def __init__(self, message: str, hint: str | None = None, status: Status | None = None):
        super().__init__(message, hint)
        self.status = status


class BoardTimeout(BoardError):
    """No (complete) response in time."""


@dataclass(frozen=True)
class Hello:
    """The device's capabilities (HELLO payload)."""

    protocol: int
    fw_version: tuple[int, int]
    max_w: int
    max_h: int
    clk_hz: int
    fw_ram_bytes: int
    height_samples: int
    coef_entries: int
    tout_entries: int
    tri_capacity: int
    uart_div: int
    rx_timeout_cycles: int

    FORMAT = "<HBBHHIIIIIIII"


@dataclass(frozen=True)
class LoadResult:
    """LOAD's answer: CRC-32 of the stored samples and what it cost."""

    crc: int
    samples: int
    crc_cycles: int  # cycles the device took to compute the CRC over the height memory (deterministic)
    receive_cycles: int  # cycles from the first sample expected to the last stored (depends on the link)

    FORMAT = "<IIQQ"


def request(cmd: int, arg0: int = 0, arg1: int = 0) -> bytes:
    """A 12-byte request frame."""
    body = struct.pack("<BII", cmd, arg0, arg1)
    check = CHECK_SEED
    for b in body:
        check ^= b
    return MAGIC + body + bytes([check])


def samples_crc(heights: np.ndarray) -> int:
    """The CRC-32 the device reports for these samples (little-endian 16-bit, row-major)."""
    return zlib.crc32(np.ascontiguousarray(heights, dtype="<u2").tobytes())


class Board:
    """A board (or the simulated one) behind a pyserial URL or an open port."""

    def __init__(self, port, timeout: float = RESPONSE_TIMEOUT, trace: bool = False):
        import serial

        if isinstance(port, str):
            try:
                self.port = serial.serial_for_url(port, baudrate=BAUD, timeout=0.05)
            except (serial.SerialException, OSError, ValueError) as e:
                raise BoardError(f"cannot open {port}: {e}",
                                 "for the simulated board run `make sim` first") from e
            self._own = True
        else:
            self.port = port
            self._own = False
        self.timeout = timeout
        self.trace = trace

    def close(self) -> None:
        if self._own:
            self.port.close()

    def __enter__(self) -> Board:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- link ---------------------------------------------------------------------------------
    def _trace(self, tag: str, data: bytes) -> None:
        if self.trace and data:
            sys.stderr.write(f"{tag} {len(data):5d} {data[:64].hex(' ')}{' ...' if len(data) > 64 else ''}\n")

    def write(self, data: bytes) -> None:
        self._trace("TX", data)
        self.port.write(data)
        self.port.flush()

    def _read_exact(self, n: int, deadline: float) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = self.port.read(n - len(buf))
            if chunk:
                buf += chunk
            elif time.monotonic() > deadline:
                self._trace("RX", bytes(buf))
                raise BoardTimeout(f"no response from the board (got {len(buf)} of {n} bytes)",
                                   "is the board (or `make sim`) running and idle?")
        self._trace("RX", bytes(buf))
        return bytes(buf)

    def read_response(self, timeout: float | None = None) -> tuple[int, Status, bytes]:
        """The next whole response frame: (request cmd, status, payload).  Skips bytes before the magic."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        window = b""
        while window != MAGIC:
            window = (window + self._read_exact(1, deadline))[-2:]
        head = self._read_exact(6, deadline)
        cmd, status, length = struct.unpack("<BBI", head)
        if not cmd & RESPONSE or length > 2 * memmap.HEIGHT_SAMPLES:
            raise BoardError(f"corrupt response header {head.hex()}")
        deadline += length * PER_BYTE_TIMEOUT
        payload = self._read_exact(length, deadline)
        (crc,) = struct.unpack("<I", self._read_exact(4, deadline))
        if crc != zlib.crc32(head + payload):
            raise BoardError(f"response CRC mismatch (cmd 0x{cmd:02x}, {length} bytes)")
        try:
            st = Status(status)
        except ValueError:
            raise BoardError(f"unknown status {status} in a response") from None
        return cmd & ~RESPONSE, st, payload

    def command(self, cmd: Cmd, arg0: int = 0, arg1: int = 0, timeout: float | None = None) -> bytes:
        """Send a request and return the payload of its OK response; BoardError otherwise."""
        self.write(request(cmd, arg0, arg1))
        return self._expect(cmd, timeout)

    def _expect(self, cmd: Cmd, timeout: float | None = None) -> bytes:
        for _ in range(STALE_RESPONSES + 1):
            rcmd, status, payload = self.read_response(timeout)
            if rcmd == cmd:
                break
            # an answer to an earlier request (a retried HELLO, garbage on the line): skip it
        else:
            raise BoardError(f"no answer to {cmd.name} among {STALE_RESPONSES + 1} responses")
        if status != Status.OK:
            raise BoardError(f"{cmd.name} refused: {status.name}", status=status)
        return payload

    # --- commands -----------------------------------------------------------------------------
    def hello(self) -> Hello:
        """The device's capabilities."""
        payload = self.command(Cmd.HELLO)
        if len(payload) != struct.calcsize(Hello.FORMAT):
            raise BoardError(f"HELLO payload of {len(payload)} bytes")
        f = struct.unpack(Hello.FORMAT, payload)
        return Hello(f[0], (f[1], f[2]), *f[3:])

    def sync(self, retries: int = SYNC_RETRIES) -> Hello:
        """HELLO until the device answers it (esptool's sync): after garbage on the line the device may
        first answer what the garbage looked like, or take our request for the rest of one; then we
        ask again at once."""
        last: BoardError | None = None
        for _ in range(retries):
            self.port.reset_input_buffer()
            self.write(request(Cmd.HELLO))
            try:
                cmd, status, payload = self.read_response(SYNC_TIMEOUT)
                if cmd == Cmd.HELLO and status == Status.OK:
                    f = struct.unpack(Hello.FORMAT, payload)
                    return Hello(f[0], (f[1], f[2]), *f[3:])
                last = BoardError(f"answer 0x{cmd:02x} {status.name} to HELLO")
            except BoardError as e:
                last = e
        raise BoardTimeout(f"no HELLO answer after {retries} attempts ({last.message if last else ''})",
                           "is the board (or `make sim`) running?")

    def load(self, heights: np.ndarray) -> LoadResult:
        """Store an (H, W) array of 16-bit samples in the height memory."""
        a = np.asarray(heights)
        if a.ndim != 2 or a.size == 0 or a.min() < 0 or a.max() > 0xFFFF:
            raise BoardError("LOAD needs a 2-D array of samples in 0..65535")
        h, w = a.shape
        self.command(Cmd.LOAD, w, h)  # BAD_ARG here when W x H does not fit
        data = np.ascontiguousarray(a, dtype="<u2").tobytes()
        self.write(data)
        payload = self._expect(Cmd.LOAD, self.timeout + len(data) * PER_BYTE_TIMEOUT)
        return LoadResult(*struct.unpack(LoadResult.FORMAT, payload))

    def read(self, first: int, count: int) -> np.ndarray:
        """`count` samples of the height memory from sample `first`."""
        payload = self.command(Cmd.READ, first, count)
        if len(payload) != 2 * count:
            raise BoardError(f"READ returned {len(payload)} bytes for {count} samples")
        return np.frombuffer(payload, dtype="<u2").astype(np.uint16)


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m wavemesh.board", description=__doc__.splitlines()[0])
    ap.add_argument("url", help="pyserial URL, e.g. socket://127.0.0.1:7720 (make sim)")
    ap.add_argument("--trace", action="store_true", help="hex dump of every transfer on stderr")
    sub = ap.add_subparsers(dest="what", required=True)
    sub.add_parser("hello", help="print the device's capabilities")
    p = sub.add_parser("load", help="send a .npy height field (16-bit samples)")
    p.add_argument("file")
    p = sub.add_parser("read", help="print samples of the height memory")
    p.add_argument("first", type=int)
    p.add_argument("count", type=int)
    args = ap.parse_args(argv)
    try:
        with Board(args.url, trace=args.trace) as b:
            info = b.sync()
            if args.what == "hello":
                for k, v in info.__dict__.items():
                    print(f"{k:18s} {v}")
            elif args.what == "load":
                heights = np.load(args.file)
                r = b.load(heights)
                ok = "ok" if r.crc == samples_crc(heights) else "MISMATCH"
                print(f"crc 0x{r.crc:08x} ({ok}) samples {r.samples} crc_cycles {r.crc_cycles} "
                      f"receive_cycles {r.receive_cycles}")
            else:
                print(" ".join(str(int(v)) for v in b.read(args.first, args.count)))
    except (WavemeshError, OSError) as e:
        print(f"error: {getattr(e, 'message', e)}", file=sys.stderr)
        if getattr(e, "hint", None):
            print(f"hint: {e.hint}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
