"""A few RV32I instructions as 32-bit words, for test programs that need no cross compiler.

Like picorv32's test_ez, whose program is hex words in the test bench: here the words come from
these encoders so each line of a program reads as assembly.  Registers are numbers (x0..x31);
branch and jump offsets are in bytes relative to the instruction.
"""

from __future__ import annotations


def _i(imm: int, rs1: int, f3: int, rd: int, op: int) -> int:
    assert -2048 <= imm < 2048
    return (imm & 0xFFF) << 20 | rs1 << 15 | f3 << 12 | rd << 7 | op


def lui(rd: int, imm20: int) -> int:
    return (imm20 & 0xFFFFF) << 12 | rd << 7 | 0x37


def addi(rd: int, rs1: int, imm: int) -> int:
    return _i(imm, rs1, 0, rd, 0x13)


def lw(rd: int, rs1: int, imm: int) -> int:
    return _i(imm, rs1, 2, rd, 0x03)


def lh(rd: int, rs1: int, imm: int) -> int:
    return _i(imm, rs1, 1, rd, 0x03)


def lhu(rd: int, rs1: int, imm: int) -> int:
    return _i(imm, rs1, 5, rd, 0x03)


def _s(imm: int, rs2: int, rs1: int, f3: int) -> int:
    assert -2048 <= imm < 2048
    return (imm >> 5 & 0x7F) << 25 | rs2 << 20 | rs1 << 15 | f3 << 12 | (imm & 0x1F) << 7 | 0x23


def sw(rs2: int, rs1: int, imm: int) -> int:
    return _s(imm, rs2, rs1, 2)


def sh(rs2: int, rs1: int, imm: int) -> int:
    return _s(imm, rs2, rs1, 1)


def _b(off: int, rs2: int, rs1: int, f3: int) -> int:
    assert off % 2 == 0 and -4096 <= off < 4096
    return ((off >> 12 & 1) << 31 | (off >> 5 & 0x3F) << 25 | rs2 << 20 | rs1 << 15 | f3 << 12
            | (off >> 1 & 0xF) << 8 | (off >> 11 & 1) << 7 | 0x63)


def beq(rs1: int, rs2: int, off: int) -> int:
    return _b(off, rs2, rs1, 0)


def bne(rs1: int, rs2: int, off: int) -> int:
    return _b(off, rs2, rs1, 1)


def jal(rd: int, off: int) -> int:
    assert off % 2 == 0
    return ((off >> 20 & 1) << 31 | (off >> 1 & 0x3FF) << 21 | (off >> 11 & 1) << 20
            | (off >> 12 & 0xFF) << 12 | rd << 7 | 0x6F)


def hex_words(words: list[int]) -> str:
    """$readmemh text: one 32-bit word per line."""
    return "".join(f"{w & 0xFFFFFFFF:08x}\n" for w in words)


def li(rd: int, value: int) -> list[int]:
    """Load a 32-bit constant: lui + addi (the addi's sign folded into the lui)."""
    value &= 0xFFFFFFFF
    lo = value & 0xFFF
    if lo >= 0x800:
        lo -= 0x1000
    hi = ((value - lo) >> 12) & 0xFFFFF
    return [lui(rd, hi), addi(rd, rd, lo)] if hi else [addi(rd, 0, lo)]


class Program:
    """Words with forward branches to labels: emit(), branch(kind, rs1, rs2, label), label(), words()."""

    def __init__(self):
        self._items: list = []
        self._labels: dict[str, int] = {}

    def emit(self, *words) -> None:
        for w in words:
            if isinstance(w, list):
                self._items.extend(w)
            else:
                self._items.append(w)

    def branch(self, kind, rs1: int, rs2: int, label: str) -> None:
        self._items.append((kind, rs1, rs2, label))

    def label(self, name: str) -> None:
        self._labels[name] = len(self._items)

    def words(self) -> list[int]:
        out = []
        for i, it in enumerate(self._items):
            if isinstance(it, tuple):
                kind, rs1, rs2, label = it
                out.append(kind(rs1, rs2, 4 * (self._labels[label] - i)))
            else:
                out.append(it)
        return out
