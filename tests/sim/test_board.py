"""The real firmware (firmware/board, cross-compiled) on the simulated board, through pyserial socket://.

HELLO, LOAD (CRC-32 of what was stored, cycle counts) and READ for a few sizes in the fast mode and
once pin-accurate; cycle counts are deterministic (exact equality between runs and between modes);
bad requests, garbage and stalled transfers get their error answers and never hang the device; one
client at a time, a new one after the previous left.
"""

from __future__ import annotations

import random
import socket
import struct
import time

import numpy as np
import pytest
from wavemesh import memmap
from wavemesh.board import MAGIC, Board, BoardError, Cmd, Status, request, samples_crc

pytestmark = pytest.mark.sim

SIZES = [(16, 16), (33, 17), (2, 2), (256, 3), (5, 64)]
STAGE_CRC, STAGE_DONE = 0x00020002, 0x00020003


def heights(w: int, h: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 65536, size=(h, w), dtype=np.uint16)


def crc_stage_cycles(board) -> list[int]:
    """Cycles between the CRC stage markers of every LOAD, from the simulator's log."""
    st = board.events("stage")
    pairs = zip(st, st[1:], strict=False)
    return [c2 - c1 for (v1, c1), (v2, c2) in pairs if (v1, v2) == (STAGE_CRC, STAGE_DONE)]


@pytest.fixture
def fast_board(start_sim, firmware_hex):
    return start_sim(firmware_hex, "--fast")


def test_hello_reports_capabilities(fast_board):
    with Board(fast_board.url) as b:
        info = b.sync()
    assert info.protocol == 1 and info.fw_version == (0, 1)
    assert (info.max_w, info.max_h) == (memmap.GRID_MAX_W, memmap.GRID_MAX_H)
    assert info.clk_hz == memmap.CLK_HZ
    assert info.fw_ram_bytes == memmap.FW_RAM.bytes
    assert info.height_samples == memmap.HEIGHT.entries
    assert info.coef_entries == memmap.COEF.entries
    assert info.tout_entries == memmap.TOUT.entries
    assert info.tri_capacity == memmap.TRI_CAPACITY
    assert info.uart_div == memmap.UART_DIV_RESET
    assert info.rx_timeout_cycles == memmap.CLK_HZ // 10


def test_load_crc_and_read_back(fast_board):
    with Board(fast_board.url) as b:
        b.sync()
        for i, (w, h) in enumerate(SIZES):
            a = heights(w, h, i)
            r = b.load(a)
            assert r.samples == w * h
            assert r.crc == samples_crc(a), (w, h)
            assert np.array_equal(b.read(0, w * h), a.ravel()), (w, h)
            # a range inside, and single samples at both ends
            first, count = (w * h) // 3, max(1, (w * h) // 2)
            assert np.array_equal(b.read(first, count), a.ravel()[first:first + count])
            assert b.read(w * h - 1, 1)[0] == a.ravel()[-1]
        b.read(memmap.HEIGHT_SAMPLES - 1, 1)  # the last sample of the memory is readable
    assert len(fast_board.events("stage")) == 3 * len(SIZES)


def test_cycle_counts_are_deterministic(start_sim, firmware_hex):
    """Same samples -> same CRC cycle count: twice in one run, in a second run, and pin-accurate."""
    a = heights(16, 16, 7)
    results, stage_cycles = [], []
    for mode in ("--fast", "--fast", None):
        board = start_sim(firmware_hex, *([mode] if mode else []))
        with Board(board.url) as b:
            b.sync()
            results += [b.load(a), b.load(a)]
            assert np.array_equal(b.read(0, a.size), a.ravel())
        stage_cycles += crc_stage_cycles(board)
    crc_cycles = {r.crc_cycles for r in results}
    assert len(crc_cycles) == 1, [r.crc_cycles for r in results]
    assert len(set(stage_cycles)) == 1, stage_cycles
    assert {r.crc for r in results} == {samples_crc(a)}
    # the CRC-32 of 512 bytes, 4 bits per table look-up: tens of cycles per byte on the PicoRV32
    (cycles,) = crc_cycles
    assert 20 * a.nbytes < cycles < 200 * a.nbytes
    assert cycles <= stage_cycles[0]


def test_pin_accurate_transfer(start_sim, firmware_hex):
    """The UART at its pins, bit by bit at the board's divisor, both ways."""
    board = start_sim(firmware_hex)
    assert "(pin mode)" in board.lines[0]
    a = heights(9, 7, 3)
    with Board(board.url) as b:
        info = b.sync()
        assert info.uart_div == memmap.UART_DIV_RESET
        r = b.load(a)
        assert r.crc == samples_crc(a)
        assert np.array_equal(b.read(0, a.size), a.ravel())
        # receiving took at least 10 bits per byte at the divisor
        assert r.receive_cycles >= a.nbytes * 10 * memmap.UART_DIV_RESET * 0.99


def raw_response(b: Board):
    cmd, status, payload = b.read_response()
    return Cmd(cmd) if cmd in Cmd._value2member_map_ else cmd, status, payload


def test_bad_requests_get_error_answers(fast_board):
    with Board(fast_board.url) as b:
        b.sync()
        # a wrong check byte
        bad = bytearray(request(Cmd.HELLO))
        bad[-1] ^= 0x55
        b.write(bytes(bad))
        assert raw_response(b) == (Cmd.HELLO, Status.BAD_CHECK, b"")
        # an unknown command
        b.write(request(0x7E))
        assert raw_response(b) == (0x7E, Status.BAD_CMD, b"")
        # arguments out of range: no data is expected afterwards
        for cmd, a0, a1 in ((Cmd.HELLO, 1, 0), (Cmd.LOAD, 1, 16), (Cmd.LOAD, 16, 1),
                            (Cmd.LOAD, memmap.GRID_MAX_W + 1, 2), (Cmd.LOAD, 2, memmap.GRID_MAX_H + 1),
                            (Cmd.LOAD, 0xFFFFFFFF, 0xFFFFFFFF), (Cmd.READ, 0, 0),
                            (Cmd.READ, memmap.HEIGHT_SAMPLES, 1), (Cmd.READ, 1, memmap.HEIGHT_SAMPLES),
                            (Cmd.READ, 0xFFFFFFFF, 2)):
            b.write(request(cmd, a0, a1))
            assert raw_response(b) == (cmd, Status.BAD_ARG, b""), (cmd, a0, a1)
        with pytest.raises(BoardError) as e:
            b.load(np.zeros((1, 300), dtype=np.uint16))
        assert e.value.status == Status.BAD_ARG
        assert b.hello().protocol == 1


def test_stalled_request_and_data_time_out(fast_board):
    with Board(fast_board.url) as b:
        b.sync()
        # a request that stops after its command byte
        b.write(MAGIC + bytes([Cmd.READ, 0, 0]))
        assert raw_response(b) == (Cmd.READ, Status.TIMEOUT, b"")
        # a LOAD whose samples stop half-way (5 samples and one byte of the sixth)
        b.write(request(Cmd.LOAD, 4, 4))
        assert raw_response(b) == (Cmd.LOAD, Status.OK, b"")
        b.write(bytes(11))
        cmd, status, payload = raw_response(b)
        assert (cmd, status, struct.unpack("<I", payload)[0]) == (Cmd.LOAD, Status.TIMEOUT, 5)
        a = heights(4, 4, 1)
        assert b.load(a).crc == samples_crc(a)


def test_garbage_then_valid_requests(fast_board):
    rng = random.Random(6)
    a = heights(16, 16, 11)
    with Board(fast_board.url) as b:
        b.sync()
        for tail in (b"", b"W", b"WM", b"WM\x02\x10"):
            garbage = bytes(rng.randrange(256) for _ in range(200)) + b"WWMW" + tail
            b.write(garbage)
            info = b.sync()  # skips the answers the garbage caused, retries if needed
            assert info.protocol == 1
            assert b.load(a).crc == samples_crc(a)


def test_one_client_at_a_time(start_sim, firmware_hex):
    board = start_sim(firmware_hex, "--fast")
    with Board(board.url) as first:
        first.sync()
        with socket.create_connection(("127.0.0.1", board.port), timeout=5) as second:
            second.settimeout(10)
            assert second.recv(16) == b""  # closed by the board at once
        board.wait_for_line("refused a second client")
        assert first.hello().protocol == 1
    board.wait_for_line("client left")
    for _ in range(2):  # later clients, one after the other
        with Board(board.url) as b:
            assert b.sync().protocol == 1
    assert board.proc.poll() is None  # still running: it exits only with --exit-on-close


def test_exit_on_close(start_sim, firmware_hex):
    board = start_sim(firmware_hex, "--fast", "--exit-on-close")
    with Board(board.url) as b:
        b.sync()
    assert board.wait() == 0
    assert any(ln.startswith("wmsim: summary cycles") for ln in board.lines)


def test_board_client_errors_are_one_line(tmp_path):
    """No board behind the URL: a BoardError with a hint, not a traceback."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    with pytest.raises(BoardError) as e:
        Board(f"socket://127.0.0.1:{port}")
    assert "make sim" in e.value.hint
    assert time.monotonic() - t0 < 5
