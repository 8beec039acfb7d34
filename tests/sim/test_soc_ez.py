"""The SoC with no cross compiler (picorv32's test_ez): a hand-assembled program on the board model.

The program (rv32.py encodings, loaded as hex words) writes the LEDs and stage markers, checks every
region of the memory map from the CPU (byte lanes; the SDRAM's areas through the cache: a hit, lines
that evict each other, the SDRAM's last word; the regions' ends, unmapped addresses), the SYS
configuration registers, the cycle counter and the timer, and halts with 0, or with the number of
the first failed check.  The SDRAM is the simulated board's chip model (sim/sdram_chip.v), which
stops the run at any timing violation.  Every stage marker is a stage sync: the CPU waits a fixed
number of cycles once the SDRAM is initialised, until then for the initialisation.
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from rv32 import Program, addi, beq, bne, hex_words, jal, lhu, li, lw, sh, sw
from wavemesh.device import memmap
from wavemesh.device.memmap import COEF, FW_RAM, HEIGHT, SDRAM, SYS, TOUT, UART, reg_addr
from wavemesh.harness.simboard import SimBoard, build

pytestmark = pytest.mark.sim

IO = 1  # x1 holds the I/O base
CHK = 31  # x31 holds the number of the running check (the halt code when it fails)


def sys_off(name: str) -> int:
    return reg_addr(SYS, name) - (memmap.IO_CODE << memmap.REGION_SHIFT)


def program() -> list[int]:
    p = Program()
    check = 0

    def expect(reg: int, value: int):
        """Fail (halt with the check's number) unless x`reg` == value."""
        nonlocal check
        check += 1
        p.emit(addi(CHK, 0, check), li(30, value))
        p.branch(bne, reg, 30, "fail")

    p.emit(li(IO, memmap.IO_CODE << memmap.REGION_SHIFT))
    # an SDRAM read first: it waits for the chip's initialisation (some 5000 cycles after reset), which
    # a stage marker (a stage sync: rtl/README.md, "Stage sync") would otherwise wait for
    p.emit(li(5, HEIGHT.base), lw(4, 5, 0))
    # LEDs and the first stage marker
    p.emit(addi(2, 0, 0xA5), sw(2, IO, sys_off("LEDS")), addi(3, 0, 1), sw(3, IO, sys_off("STAGE")))
    p.emit(lw(4, IO, sys_off("LEDS")))
    expect(4, 0xA5)
    # a loop of 100 iterations between stage markers 1 and 2
    p.emit(addi(4, 0, 100), addi(4, 4, -1))
    p.emit(bne(4, 0, -4))
    p.emit(addi(3, 0, 2), sw(3, IO, sys_off("STAGE")))
    # SDRAM, height area: two samples in one word (halfword lanes), the last sample
    p.emit(li(5, HEIGHT.base), li(6, 0x1234), sh(6, 5, 0), li(6, 0xBEEF), sh(6, 5, 2), lw(7, 5, 0))
    expect(7, 0xBEEF1234)
    p.emit(li(5, HEIGHT.base + 2 * HEIGHT.entries - 2), li(6, 0xCAFE), sh(6, 5, 0), lhu(7, 5, 0))
    expect(7, 0xCAFE)
    # coefficient area: whole words; a halfword store changes its lanes only
    p.emit(li(5, COEF.base + 4 * (COEF.entries - 1)), li(6, -3), sw(6, 5, 0), lw(7, 5, 0))
    expect(7, 0xFFFFFFFD)
    p.emit(li(6, 0x1234), sh(6, 5, 0), lw(7, 5, 0))
    expect(7, 0xFFFF1234)
    # template area, and a word 1 MB further on (the same cache line index: they evict each other)
    p.emit(li(5, TOUT.base), li(6, 0x5555ABCD), sw(6, 5, 0), li(8, TOUT.base + (1 << 20)), li(6, 0x77),
           sw(6, 8, 0), lw(7, 5, 0))
    expect(7, 0x5555ABCD)
    p.emit(lw(7, 8, 0))
    expect(7, 0x77)
    p.emit(lw(7, 5, 0))
    expect(7, 0x5555ABCD)
    # the SDRAM's last word, and the first address past it
    p.emit(li(5, SDRAM.base + SDRAM.bytes - 4), li(6, 0x0F1E2D3C), sw(6, 5, 0), lw(7, 5, 0))
    expect(7, 0x0F1E2D3C)
    p.emit(li(5, SDRAM.base + SDRAM.bytes), sw(6, 5, 0), lw(7, 5, 0))
    expect(7, 0)
    # firmware RAM: its last word, and the first address past it
    p.emit(li(5, FW_RAM.base + FW_RAM.bytes - 4), li(6, 0x5A5AA5A5), sw(6, 5, 0), lw(7, 5, 0))
    expect(7, 0x5A5AA5A5)
    p.emit(lw(7, 5, 4))
    expect(7, 0)
    # unmapped: another region, another I/O block
    p.emit(li(5, 0x6000_0000), sw(6, 5, 0), lw(7, 5, 0))
    expect(7, 0)
    p.emit(lw(7, IO, 0x200))
    expect(7, 0)
    # configuration registers
    for name, value in (("CLK_HZ", memmap.CLK_HZ), ("FW_RAM_BYTES", FW_RAM.bytes),
                        ("HEIGHT_SAMPLES", HEIGHT.entries), ("COEF_ENTRIES", COEF.entries),
                        ("TOUT_ENTRIES", TOUT.entries)):
        p.emit(lw(7, IO, sys_off(name)))
        expect(7, value)
    p.emit(lw(7, IO, reg_addr(UART, "DIV") & 0xFFF))
    expect(7, memmap.UART_DIV_RESET)
    # cycle counter: counts up, high word 0
    p.emit(lw(8, IO, sys_off("CYCLE_LO")), lw(9, IO, sys_off("CYCLE_LO")), lw(10, IO, sys_off("CYCLE_HI")))
    expect(10, 0)
    check += 1
    p.emit(addi(CHK, 0, check))
    p.branch(beq, 8, 9, "fail")
    # timer: loads, runs down to 0
    p.emit(addi(6, 0, 40), sw(6, IO, sys_off("TIMER")), lw(7, IO, sys_off("TIMER")))
    check += 1
    p.emit(addi(CHK, 0, check))
    p.branch(beq, 7, 0, "fail")
    p.emit(addi(4, 0, 20), addi(4, 4, -1))
    p.emit(bne(4, 0, -4))
    p.emit(lw(7, IO, sys_off("TIMER")))
    expect(7, 0)
    # done: halt 0
    p.emit(addi(3, 0, 3), sw(3, IO, sys_off("STAGE")), sw(0, IO, sys_off("HALT")), jal(0, 0))
    p.label("fail")
    p.emit(sw(CHK, IO, sys_off("HALT")), jal(0, 0))
    return p.words()


MAX_CYCLES = "200000"


def run(start_sim, hexfile, words=None):
    hexfile.write_text(hex_words(program() if words is None else words))
    board = start_sim(hexfile, "--no-socket", "--max-cycles", MAX_CYCLES)
    return board.wait(), board


def test_program_passes_every_check(tmp_path, start_sim):
    rc, board = run(start_sim, tmp_path / "ez.hex")
    halts = board.events("halt")
    failed = halts[-1][0] if halts else "?"
    assert halts and halts[-1][0] == 0, f"check {failed} failed:\n" + "\n".join(board.lines)
    assert rc == 0
    assert [v for v, _ in board.events("leds")] == [0xA5]
    stages = board.events("stage")
    assert [v for v, _ in stages] == [1, 2, 3]
    assert stages[0][1] < stages[1][1] < stages[2][1] < halts[0][1]


def test_cycle_counts_are_deterministic(tmp_path, start_sim):
    runs = [run(start_sim, tmp_path / f"ez{i}.hex") for i in range(2)]
    logs = [[ln for ln in b.lines if not ln.startswith("wmsim: summary")] for _, b in runs]
    assert logs[0] == logs[1]
    stages = runs[0][1].events("stage")
    # 100 iterations of addi + bne between markers 1 and 2
    assert 100 * 2 <= stages[1][1] - stages[0][1] <= 100 * 20


def test_failed_check_halts_with_its_number(tmp_path, start_sim):
    words = program()
    # break the LED check: the first `sw x2, LEDS(x1)` stores x0 instead
    store = sw(2, IO, sys_off("LEDS"))
    words[words.index(store)] = sw(0, IO, sys_off("LEDS"))
    rc, board = run(start_sim, tmp_path / "bad.hex", words)
    assert rc == 1
    assert board.events("halt")[-1][0] == 1


def test_fst_trace(tmp_path, verilator):
    """The tracing build (make sim TRACE=1) writes an FST file and behaves like the default one."""
    exe = build.build_sim(trace=True)
    hexfile = tmp_path / "ez.hex"
    hexfile.write_text(hex_words(program()))
    fst = tmp_path / "ez.fst"
    board = SimBoard(exe, hexfile, "--no-socket", "--max-cycles", MAX_CYCLES, "--trace", str(fst))
    assert board.wait() == 0
    data = fst.read_bytes()
    assert len(data) > 1000 and data[0] == 0  # an FST header block first
    plain = SimBoard(build.build_sim(), hexfile, "--no-socket", "--max-cycles", MAX_CYCLES)
    assert plain.wait() == 0
    def log(b):
        return [ln for ln in b.lines if "summary" not in ln]

    assert log(board) == log(plain)


def test_profile_and_pc_trace(tmp_path, start_sim):
    """--profile counts every cycle against a PC and --pc-trace lists the PCs as they run (with a mark at
    every stage write): the same PCs, the loop's 100 turns, and the run's log as without them."""
    words = program()
    hexfile = tmp_path / "ez.hex"
    hexfile.write_text(hex_words(words))
    prof, trace = tmp_path / "ez.prof", tmp_path / "ez.pc"
    board = start_sim(hexfile, "--no-socket", "--max-cycles", MAX_CYCLES, "--profile", str(prof),
                      "--pc-trace", str(trace))
    assert board.wait() == 0
    plain = start_sim(hexfile, "--no-socket", "--max-cycles", MAX_CYCLES)
    assert plain.wait() == 0
    def log(b):
        return [ln for ln in b.lines if "summary" not in ln]

    assert log(board) == log(plain)
    pcs = np.fromfile(trace, dtype="<u4")
    flush = pcs == 0xFFFFFFFF
    assert flush.sum() == len(board.events("stage")) == 3
    hist = {int(a, 16): int(c) for a, c in (ln.split() for ln in prof.read_text().splitlines())}
    assert set(pcs[~flush].tolist()) == {a for a, c in hist.items() if c}
    assert all(a < 4 * len(words) for a in hist)
    loop = 4 * words.index(addi(4, 4, -1))  # the first loop: 100 turns between stage writes 1 and 2
    assert (pcs == loop).sum() == 100
    first, second = np.flatnonzero(flush)[:2]
    assert (pcs[first:second] == loop).sum() == 100


def test_pc_trace_needs_profile(tmp_path, sim_exe):
    hexfile = tmp_path / "ez.hex"
    hexfile.write_text(hex_words(program()))
    r = subprocess.run([str(sim_exe), "--firmware", str(hexfile), "--no-socket", "--pc-trace",
                        str(tmp_path / "t.pc")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 64
    assert "--pc-trace needs --profile" in r.stderr


def test_trap_and_cycle_limit_end_the_run(tmp_path, start_sim):
    """An illegal instruction traps the CPU (exit 2); a program that never halts meets --max-cycles
    (exit 3).  The illegal word is all ones (major opcode 0x7F: no RV32 instruction); the all-zero word,
    illegal for the PicoRV32, ran on the VexRiscv until --max-cycles."""
    rc, board = run(start_sim, tmp_path / "trap.hex", [0xFFFFFFFF])
    assert rc == 2 and any(ln.startswith("wmsim: trap cycle") for ln in board.lines)
    hexfile = tmp_path / "spin.hex"
    hexfile.write_text(hex_words([jal(0, 0)]))
    board = start_sim(hexfile, "--no-socket", "--max-cycles", "5000")
    assert board.wait() == 3
    assert "wmsim: max cycles 5000 reached" in board.lines
