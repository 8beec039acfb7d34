"""A fault-injecting TCP proxy between the host and a device (the native stand-in or the simulated board).

    with FaultProxy(("127.0.0.1", device_port), Faults(seed=7, rate=0.002, limit=6)) as proxy:
        run `wavemesh stream ... --port socket://127.0.0.1:{proxy.port}`

One client connection at a time is forwarded to the device; each direction passes through its own
seeded random generator that, byte by byte with probability ``rate``, corrupts a byte (XOR with a
non-zero mask), drops a run of 1..``run`` bytes, duplicates a run of 1..``run`` bytes, or delays
the stream by up to ``max_delay`` seconds; at most ``limit`` faults per direction and connection
(bounded, so a session can always get through in the end).  ``log`` records every fault injected.
Closing the proxy (or the client leaving) closes both sides.
"""

from __future__ import annotations

import random
import select
import socket
import threading
import time
from dataclasses import dataclass

KINDS = ("corrupt", "drop", "duplicate", "delay")


@dataclass
class Faults:
    seed: int = 0
    rate: float = 0.001  # probability per byte of a fault
    limit: int = 8  # faults per direction and connection
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
        self.active = name in faults.directions and faults.rate > 0

    def apply(self, data: bytes) -> tuple[bytes, float]:
        """The bytes to forward and a delay before them."""
        if not self.active or self.count >= self.f.limit:
            self.pos += len(data)
            return data, 0.0
        out = bytearray()
        delay = 0.0
        i = 0
        while i < len(data):
            if self.count < self.f.limit and self.rng.random() < self.f.rate:
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
                delay += d
                self.log.append(Injected(self.name, kind, self.pos + i, int(d * 1000)))
            out.append(data[i])
            i += 1
        self.pos += len(data)
        return bytes(out), delay


class FaultProxy:
    def __init__(self, upstream: tuple[str, int], faults: Faults | None = None):
        self.upstream = upstream
        self.faults = faults or Faults(rate=0)
        self.log: list[Injected] = []
        self.connections = 0
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
                out, delay = pump.apply(data)
                if delay:
                    time.sleep(delay)
                if out:
                    dst.sendall(out)
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


def _close(s: socket.socket) -> None:
    try:
        s.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    try:
        s.close()
    except OSError:
        pass


__all__ = ["FaultProxy", "Faults", "Injected", "KINDS"]
