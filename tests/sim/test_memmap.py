"""The memory map (host/wavemesh/device/memmap.py) is consistent, fits the ECP5, and every consumer agrees.

- regions and registers do not overlap and fit their address windows;
- the default sizes hold what docs/soc.md says they support (1024 x 1024 samples, levels 1..10 of
  details, the blocks of M >= 2), the SDRAM's areas are disjoint and inside it, and the block RAM
  (firmware RAM, the cache, the filter bank) stays well below an LFE5U-85F's;
- the generated C header, compiled with the host's gcc, and the Verilog include, elaborated by
  Verilator, give the same numbers as the Python module;
- docs/soc.md embeds the current generated tables.
"""

from __future__ import annotations

import re
import subprocess
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
    assert total <= memmap.ECP5_85F_EBR // 2  # the heights, details and mesh live in the SDRAM


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
