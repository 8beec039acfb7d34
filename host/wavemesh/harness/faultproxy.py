"""A fault-injecting TCP proxy between the host and a device (the native stand-in or the simulated
board), and a campaign of `wavemesh stream` runs through it (tests/sim/test_stream_faults.py,
bench/bench_faults.py).

    with FaultProxy(("127.0.0.1", device_port), Faults(seed=7, rate=0.002, limit=6)) as proxy:
        run `wavemesh stream ... --port socket://127.0.0.1:{proxy.port}`

One client connection at a time is forwarded to the device; each direction passes through its own
seeded random generator that, byte by byte with probability ``rate``, corrupts a byte (XOR with a
non-zero mask), drops a run of 1..``run`` bytes, duplicates a run of 1..``run`` bytes, or holds the
stream back at that byte for up to ``max_delay`` seconds; at most ``limit`` faults per direction and
connection (``limit=None``: no bound, as on a real lossy line).  ``log`` records every fault injected,
``frames`` counts the frames that came to the proxy (SLIP delimiters / 2, before any fault) and
``bytes`` their bytes: ``rate * bytes`` is the number of faults to expect with no ``limit``.
Closing the proxy (or the client leaving) closes both sides.

:func:`campaign` runs `wavemesh stream` (in this process, on a thread, with the host's default
timeouts unless told otherwise) once per :class:`Faults` and classifies every run: ``identical``
(exit 0 and the reference mesh byte for byte), ``error`` (exit 2, one ``error:`` line and a hint, no
traceback, no output file), ``different`` (a mesh that is not the reference: the one outcome a
checksummed protocol must never give), ``unclear`` (any other ending: a traceback, several error
lines, a file left behind) and ``hang`` (still running after ``run_limit`` seconds).
"""

from __future__ import annotations

import contextlib
import filecmp
import io
import random
import select
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from wavemesh import cli
from wavemesh.device.link import FrameError, SlipDecoder, parse_frame, slip_encode

KINDS = ("corrupt", "drop", "duplicate", "delay")


@dataclass
class Faults:
    seed: int = 0
    rate: float = 0.001  # probability per byte of a fault
    limit: int | None = 8  # faults per direction and connection (None: no bound)
    run: int = 64  # longest run of bytes dropped or duplicated
    max_delay: float = 0.3  # s, longest delay
    kinds: tuple[str, ...] = KINDS
    directions: tuple[str, ...] = ("up", "down")  # up: host to device; down: device to host


@dataclass
class Injected:
    direction: str
    kind: str
    at: int  # byte position in that direction's stream
    size: int


class _Pump:
    """One direction: applies the faults to the bytes it forwards."""

    def __init__(self, name: str, faults: Faults, rng: random.Random, log: list):
        self.name, self.f, self.rng, self.log = name, faults, rng, log
        self.pos = 0
        self.count = 0
        self.ends = 0  # SLIP delimiters that came (two per frame)
        self.active = name in faults.directions and faults.rate > 0

    def _may(self) -> bool:
        return self.f.limit is None or self.count < self.f.limit

    def apply(self, data: bytes) -> list[tuple[bytes, float]]:
        """The bytes to forward, in pieces each followed by a delay: a delay holds the stream back at
        the byte where it struck (the bytes before it go on at once), as a line that stalls would."""
        self.ends += data.count(0xC0)
        if not self.active or not self._may():
            self.pos += len(data)
            return [(data, 0.0)]
        pieces = []
        out = bytearray()
        i = 0
        while i < len(data):
            if self._may() and self.rng.random() < self.f.rate:
                kind = self.rng.choice(self.f.kinds)
                self.count += 1
                if kind == "corrupt":
                    out.append(data[i] ^ self.rng.randrange(1, 256))
                    self.log.append(Injected(self.name, kind, self.pos + i, 1))
                    i += 1
                    continue
                if kind == "drop":
                    n = self.rng.randrange(1, self.f.run + 1)
                    self.log.append(Injected(self.name, kind, self.pos + i, min(n, len(data) - i)))
                    i += n
                    continue
                if kind == "duplicate":
                    n = self.rng.randrange(1, self.f.run + 1)
                    piece = data[i:i + n]
                    out += piece + piece
                    self.log.append(Injected(self.name, kind, self.pos + i, len(piece)))
                    i += len(piece)
                    continue
                d = self.rng.uniform(0.0, self.f.max_delay)
                pieces.append((bytes(out), d))
                out = bytearray()
                self.log.append(Injected(self.name, kind, self.pos + i, int(d * 1000)))
            out.append(data[i])
            i += 1
        self.pos += len(data)
        return [*pieces, (bytes(out), 0.0)]


class FaultProxy:
    def __init__(self, upstream: tuple[str, int], faults: Faults | None = None):
        self.upstream = upstream
        self.faults = faults or Faults(rate=0)
        self.log: list[Injected] = []
        self.connections = 0
        self.pumps: list[_Pump] = []
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind(("127.0.0.1", 0))
        self.listener.listen(4)
        self.port = self.listener.getsockname()[1]
        self._stop = threading.Event()
        self._socks: list[socket.socket] = []
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    def _serve(self) -> None:
        while not self._stop.is_set():
            r, _, _ = select.select([self.listener], [], [], 0.05)
            if not r:
                continue
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            try:
                dev = socket.create_connection(self.upstream, timeout=5)
            except OSError:
                client.close()
                continue
            for s in (client, dev):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._socks += [client, dev]
            seed = self.faults.seed * 1000 + self.connections
            self.connections += 1
            up = _Pump("up", self.faults, random.Random(seed * 2), self.log)
            down = _Pump("down", self.faults, random.Random(seed * 2 + 1), self.log)
            self.pumps += [up, down]
            done = threading.Event()
            threads = [threading.Thread(target=self._pump, args=(client, dev, up, done), daemon=True),
                       threading.Thread(target=self._pump, args=(dev, client, down, done), daemon=True)]
            for t in threads:
                t.start()
            done.wait()  # one connection at a time: the next client waits in the backlog
            for s in (client, dev):
                _close(s)
            for t in threads:
                t.join(2)

    def _pump(self, src: socket.socket, dst: socket.socket, pump: _Pump, done: threading.Event) -> None:
        try:
            while not self._stop.is_set() and not done.is_set():
                r, _, _ = select.select([src], [], [], 0.05)
                if not r:
                    continue
                data = src.recv(65536)
                if not data:
                    break
                for out, delay in pump.apply(data):
                    if out:
                        dst.sendall(out)
                    if delay:
                        time.sleep(delay)
        except OSError:
            pass
        finally:
            done.set()

    def close(self) -> None:
        self._stop.set()
        _close(self.listener)
        for s in self._socks:
            _close(s)
        self._thread.join(2)

    def __enter__(self) -> FaultProxy:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def summary(self) -> dict:
        out = {k: 0 for k in KINDS}
        for f in self.log:
            out[f.kind] += 1
        return out

    @property
    def frames(self) -> int:
        """Frames that came to the proxy, both ways (before the faults)."""
        return sum(p.ends for p in self.pumps) // 2

    @property
    def bytes(self) -> int:
        """Bytes that came to the proxy, both ways (before the faults)."""
        return sum(p.pos for p in self.pumps)


class FrameTap:
    """A proxy that forwards whole frames, each after ``on_frame(direction, frame)`` (direction "up":
    host to device, "down"; a wavemesh.device.link.Frame) said True: a scripted fault (drop one chosen
    frame, or hold the line: the callback sleeps) or a trigger (stop the device when the first MESH
    frame passes).  ``CUT`` instead: the connection breaks there (both sides closed; the next client
    connection is forwarded anew).  Bytes that are not a valid frame are dropped.  ``connections``
    counts the client connections forwarded."""

    CUT = "cut"

    def __init__(self, upstream: tuple[str, int], on_frame):
        self.upstream, self.on_frame = upstream, on_frame
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.connections = 0
        self._socks: list[socket.socket] = []
        threading.Thread(target=self._serve, daemon=True).start()

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    def _serve(self) -> None:
        while True:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            try:
                dev = socket.create_connection(self.upstream, timeout=5)
            except OSError:  # the device is gone: this client hears it at once
                _close(client)
                continue
            dev.settimeout(None)
            self.connections += 1
            self._socks += [client, dev]
            for a, b, name in ((client, dev, "up"), (dev, client, "down")):
                threading.Thread(target=self._pump, args=(a, b, name), daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket, name: str) -> None:
        dec = SlipDecoder()
        try:
            while data := src.recv(65536):
                for raw in dec.feed(data):
                    if isinstance(raw, FrameError):
                        continue
                    try:
                        f = parse_frame(raw)
                    except FrameError:
                        continue
                    verdict = self.on_frame(name, f)
                    if verdict == self.CUT:
                        return
                    if verdict:
                        dst.sendall(slip_encode(raw))
        except OSError:
            pass
        finally:
            for s in (src, dst):
                _close(s)

    def close(self) -> None:
        _close(self.listener)
        for s in self._socks:
            _close(s)

    def __enter__(self) -> FrameTap:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ---------------------------------------------------------------------------------------------------
# A campaign of `wavemesh stream` runs

OUTCOMES = ("identical", "error", "different", "unclear", "hang")


@dataclass
class Run:
    faults: Faults
    outcome: str  # one of OUTCOMES
    seconds: float
    injected: int  # faults injected, both ways
    frames: int  # frames through the proxy, both ways
    message: str = ""  # the error line, or what was wrong
    delay_s: float = 0.0  # seconds the injected delays held the line, both ways added
    bytes: int = 0  # bytes through the proxy, both ways (before the faults)


def stream_once(argv: list[str], out: Path, ref: Path, run_limit: float) -> tuple[str, float, str]:
    """`wavemesh ARGV` (a stream command writing `out`) on a thread: (outcome, seconds, message)."""
    result: dict = {}

    def work():
        err = io.StringIO()
        t0 = time.monotonic()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                result["rc"] = cli.main(argv)
        except BaseException as e:  # noqa: BLE001 - a traceback is an outcome (unclear), not a crash here
            result["exc"] = repr(e)
        result["err"] = err.getvalue()
        result["t"] = time.monotonic() - t0

    t0 = time.monotonic()
    th = threading.Thread(target=work, daemon=True)
    th.start()
    th.join(run_limit)
    if th.is_alive():
        return "hang", time.monotonic() - t0, f"still running after {run_limit:g} s"
    t, err = result["t"], result["err"]
    if "exc" in result:
        return "unclear", t, f"raised {result['exc']}"
    rc = result["rc"]
    if rc in (0, 3) and out.exists():  # 3: the triangle budget stopped the run (as it did the reference)
        if filecmp.cmp(out, ref, shallow=False):
            return "identical", t, ""
        return "different", t, f"exit {rc} with a mesh that is not the reference"
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    if rc == 2 and len(lines) == 1 and "hint:" in err and "Traceback" not in err and not out.exists():
        return "error", t, lines[0]
    return "unclear", t, f"exit {rc}: {err.strip()[-300:]}"


def campaign(upstream: tuple[str, int], src: Path, opts: list[str], ref: Path, faults: list[Faults],
             workdir: Path, run_limit: float = 150.0, on_run=None) -> list[Run]:
    """`wavemesh stream SRC OPTS` through a FaultProxy in front of `upstream`, once per Faults."""
    runs = []
    for i, f in enumerate(faults):
        out = workdir / f"run{i}{ref.suffix}"
        if out.exists():
            out.unlink()
        with FaultProxy(upstream, f) as proxy:
            argv = ["stream", str(src), *opts, "--port", proxy.url, "-o", str(out), "-q"]
            outcome, t, msg = stream_once(argv, out, ref, run_limit)
            delay = sum(i.size for i in proxy.log if i.kind == "delay") / 1000
            run = Run(f, outcome, t, len(proxy.log), proxy.frames, msg, delay, proxy.bytes)
        runs.append(run)
        if on_run:
            on_run(run)
    return runs


@dataclass
class Tally:
    runs: int = 0
    outcomes: dict = field(default_factory=lambda: {k: 0 for k in OUTCOMES})
    injected: int = 0
    frames: int = 0
    bytes: int = 0
    faulted_runs: int = 0  # runs with at least one fault injected
    slowest: float = 0.0
    slowest_error: float = 0.0
    errors: dict = field(default_factory=dict)  # error line -> count

    @classmethod
    def of(cls, runs: list[Run]) -> Tally:
        t = cls()
        for r in runs:
            t.runs += 1
            t.outcomes[r.outcome] += 1
            t.injected += r.injected
            t.frames += r.frames
            t.bytes += r.bytes
            t.faulted_runs += r.injected > 0
            t.slowest = max(t.slowest, r.seconds)
            if r.outcome == "error":
                t.slowest_error = max(t.slowest_error, r.seconds)
                key = r.message.split(":")[1].strip() if ":" in r.message else r.message
                t.errors[key] = t.errors.get(key, 0) + 1
        return t

    def line(self) -> str:
        return (f"{self.runs} runs, {self.frames} frames ({self.bytes} bytes), {self.injected} faults in "
                f"{self.faulted_runs} runs: " + ", ".join(f"{v} {k}" for k, v in self.outcomes.items())
                + f"; slowest run {self.slowest:.1f} s, slowest error {self.slowest_error:.1f} s")


def _close(s: socket.socket) -> None:
    try:
        s.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    try:
        s.close()
    except OSError:
        pass


__all__ = ["FaultProxy", "Faults", "FrameTap", "Injected", "KINDS", "OUTCOMES", "Run", "Tally", "campaign",
           "stream_once"]
