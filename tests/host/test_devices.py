"""`wavemesh devices`: the ports pyserial lists, and which of them answers HELLO with what.

A stand-in device on 127.0.0.1 answers HELLO with a HELLO_REPLY packed from protocol.py (the one source
of its layout), so the capabilities the command prints are checked field by field against what was
sent; a silent listener, a closed port and a port list without any device are the other cases.
"""

from __future__ import annotations

import json
import socket
import threading

import pytest
from wavemesh.cli import main
from wavemesh.device import protocol as P
from wavemesh.device.devices import PortReport, scan
from wavemesh.device.link import SlipDecoder, encode_frame, parse_frame

CAPS = dict(version=P.VERSION, fw_major=1, fw_minor=7, name=b"wm-test", max_width=300, max_height=200,
            max_samples=40000, tri_capacity=1234, max_levels=6, window=4, max_payload=1024, clk_hz=25_000_000,
            baud=115200, features=0, byte_timeout_ms=100, ack_timeout_ms=500, session_timeout_ms=5000,
            ack_retries=8, link_timeout_s=30, idle_timeout_ms=0, write_timeout_ms=0)


class Listener:
    """A TCP listener on 127.0.0.1 that answers every HELLO (or, silent, reads and says nothing)."""

    def __init__(self, answer: bool):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(4)
        self.sock.settimeout(0.1)
        self.url = f"socket://127.0.0.1:{self.sock.getsockname()[1]}"
        self.answer = answer
        self.hellos = 0
        self.closed = False
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while not self.closed:
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            self._connection(conn)

    def _connection(self, conn) -> None:
        conn.settimeout(0.1)
        dec = SlipDecoder()
        with conn:
            while not self.closed:
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not data:
                    return
                for raw in dec.feed(data):
                    if isinstance(raw, Exception):
                        continue
                    f = parse_frame(raw)
                    if f.type == P.FrameType.HELLO:
                        self.hellos += 1
                        if self.answer:
                            reply = P.HELLO_REPLY.pack(**CAPS)
                            conn.sendall(encode_frame(P.FrameType.HELLO_REPLY, f.seq, reply))

    def close(self) -> None:
        self.closed = True
        self.thread.join(5)
        self.sock.close()


@pytest.fixture
def no_ports(monkeypatch):
    """A machine without serial ports (the tests must not probe the real ones)."""
    import serial.tools.list_ports as lp

    monkeypatch.setattr(lp, "comports", lambda: [])


def test_device_answering_hello_is_listed_with_its_capabilities(no_ports):
    dev = Listener(answer=True)
    try:
        [r] = scan([dev.url])
    finally:
        dev.close()
    assert r.answered and dev.hellos >= 1
    for k, v in CAPS.items():
        if k in r.info:
            assert r.info[k] == (v.rstrip(b"\0").decode() if isinstance(v, bytes) else v), k
    assert r.info["fw_version"] == [1, 7]
    assert "wm-test firmware 1.7" in r.line() and "up to 300 x 200" in r.line()


def test_silent_and_closed_ports_are_named_not_fatal(no_ports):
    silent = Listener(answer=False)
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    url_closed = f"socket://127.0.0.1:{closed.getsockname()[1]}"
    closed.close()
    try:
        a, b = scan([silent.url, url_closed])
    finally:
        silent.close()
    assert not a.answered and a.problem == "no HELLO answer" and silent.hellos >= 1
    assert not b.answered and "no device is listening" in b.problem


def test_pyserial_ports_listed_and_no_probe_sends_nothing(monkeypatch, capsys):
    import serial.tools.list_ports as lp
    from serial.tools.list_ports_common import ListPortInfo

    dev = Listener(answer=True)
    port = ListPortInfo(dev.url, skip_link_detection=True)
    port.description = "FT231X USB UART"
    monkeypatch.setattr(lp, "comports", lambda: [port])
    try:
        assert main(["devices", "--no-probe", "--json"]) == 0
        listed = json.loads(capsys.readouterr().out)
        assert [r["url"] for r in listed] == [dev.url] and listed[0]["description"] == "FT231X USB UART"
        assert dev.hellos == 0
        assert main(["devices"]) == 0
        out = capsys.readouterr().out
    finally:
        dev.close()
    assert out.startswith(f"{dev.url}  (FT231X USB UART): wavemesh device: wm-test")


def test_no_ports_at_all(no_ports, capsys):
    assert main(["devices"]) == 0
    assert "no serial ports" in capsys.readouterr().out
    assert PortReport("x").line() == "x: not probed"
