"""firmware/board builds with its CMake toolchain file, reports its size, and refuses to overflow the RAM.

Needs riscv64-unknown-elf-gcc (`make setup` installs it): its absence fails these tests with that
hint, it never skips them.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from wavemesh.device import gen, memmap

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "firmware" / "board"


def cmake_build(tmp_path: Path, gendir: Path) -> subprocess.CompletedProcess:
    if shutil.which("riscv64-unknown-elf-gcc") is None:
        pytest.fail("riscv64-unknown-elf-gcc not found: run `make setup` (it installs the Debian packages "
                    "gcc-riscv64-unknown-elf and picolibc-riscv64-unknown-elf)")
    out = tmp_path / "build"
    toolchain = SRC / "riscv32-toolchain.cmake"
    cfg = subprocess.run(["cmake", "-S", str(SRC), "-B", str(out), f"-DCMAKE_TOOLCHAIN_FILE={toolchain}",
                          f"-DWM_GEN_DIR={gendir}"], capture_output=True, text=True)
    assert cfg.returncode == 0, cfg.stdout + cfg.stderr
    return subprocess.run(["cmake", "--build", str(out), "-j2"], capture_output=True, text=True)


def test_build_reports_size_and_writes_the_image(tmp_path):
    gendir = tmp_path / "gen"
    gen.write_all(gendir)
    r = cmake_build(tmp_path, gendir)
    assert r.returncode == 0, r.stdout + r.stderr
    line = next(ln for ln in r.stdout.splitlines() if "firmware size:" in ln)
    assert f"of {memmap.FW_RAM_BYTES} bytes of firmware RAM" in line
    assert f"+ stack {memmap.STACK_BYTES} =" in line and line.endswith(" free")
    out = tmp_path / "build"
    binary = (out / "wavemesh_board.bin").read_bytes()
    words = (out / "wavemesh_board.hex").read_text().split()
    assert len(words) == -(-len(binary) // 4)
    assert all(len(w) == 8 for w in words)
    assert int(words[0], 16) == int.from_bytes(binary[:4], "little")  # crt0 at the reset vector
    assert len(binary) + memmap.STACK_BYTES < memmap.FW_RAM_BYTES


def test_build_fails_when_the_firmware_does_not_fit(tmp_path):
    gendir = tmp_path / "gen"
    gen.write_all(gendir)
    ld = gendir / "wm_memmap.ld"
    tiny = memmap.STACK_BYTES + 256  # no room for the code next to the stack
    ld.write_text(ld.read_text().replace(f"LENGTH = {memmap.FW_RAM_BYTES}", f"LENGTH = {tiny}"))
    r = cmake_build(tmp_path, gendir)
    assert r.returncode != 0
    # the linker's count names the bytes (board.ld's .stack reserve): not a bare assertion
    assert "region `FW_RAM' overflowed by" in r.stdout + r.stderr


def test_every_section_but_data_loads_where_it_runs(tmp_path):
    """board.ld: $readmemh loads the image at address 0, so every loaded section but .data (crt0 copies
    it from its load image) must load where it runs, however large .data is.  A tiny program with 12
    bytes of .data, linked by board.ld; .wm_tail (the start-up paint, after .bss) once inherited .data's
    load offset and was loaded 12 bytes before where it runs."""
    if shutil.which("riscv64-unknown-elf-gcc") is None:
        pytest.fail("riscv64-unknown-elf-gcc not found: run `make setup`")
    gendir = tmp_path / "gen"
    gen.write_all(gendir)
    for name in ("wm_cold.ld", "wm_hot.ld"):  # CMake writes the cold objects' list, the hot order; none here
        (tmp_path / name).write_text("")
    src = tmp_path / "tiny.S"
    src.write_text(".section .text.start, \"ax\"\n.globl _start\n_start: j _start\n"
                   ".section .data\n.word 1, 2, 3\n"
                   ".section .wm_tail, \"ax\"\n.globl board_start\nboard_start: ret\n")
    elf = tmp_path / "tiny.elf"
    r = subprocess.run(["riscv64-unknown-elf-gcc", "-march=rv32imc", "-mabi=ilp32", "-nostdlib",
                        "-nostartfiles", "-T", str(SRC / "board.ld"), f"-L{gendir}", f"-L{tmp_path}",
                        str(src), "-o", str(elf)], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    dump = subprocess.run(["riscv64-unknown-elf-objdump", "-h", str(elf)], capture_output=True, text=True,
                          check=True).stdout.splitlines()
    sections = {}
    for head, flags in zip(dump, dump[1:], strict=False):
        f = head.split()
        if len(f) == 7 and f[0].isdigit():  # Idx Name Size VMA LMA File-off Algn, then its flags
            sections[f[1]] = (int(f[2], 16), int(f[3], 16), int(f[4], 16), "LOAD" in flags)
    assert sections[".data"][0] == 12 and sections[".data"][1] == sections[".data"][2] + 12
    assert sections[".wm_tail"][3]
    moved = {n: s for n, s in sections.items() if s[3] and n != ".data" and s[1] != s[2]}
    assert not moved, f"loaded elsewhere than they run (size, VMA, LMA): {moved}"


def test_hot_code_follows_hot_order(tmp_path):
    """hot_order.txt's functions (each with its clones) start the hot code, in its order, and each is in
    the image: a name the code lost means the order is stale (rerun tools/code_layout.py --write)."""
    from wavemesh.harness.simboard import build

    image = build.build_firmware()
    with build.locked(image.parent):
        elf = Path(shutil.copy2(image.with_suffix(".elf"), tmp_path / "fw.elf"))
    names = [ln.strip() for ln in (SRC / "hot_order.txt").read_text().splitlines()
             if ln.strip() and not ln.startswith("#")]
    assert len(names) == len(set(names))
    out = subprocess.run(["riscv64-unknown-elf-nm", "-n", str(elf)], capture_output=True, text=True,
                         check=True).stdout
    first: dict[str, int] = {}
    hot_start = None
    for line in out.splitlines():
        addr, kind, name = line.split()
        if name == "__wm_hot_start":
            hot_start = int(addr, 16)
        elif kind in "tTwW":
            first.setdefault(name.split(".")[0], int(addr, 16))
    missing = [n for n in names if n not in first]
    assert not missing, f"hot_order.txt names functions the image lacks: {missing}"
    if names:
        addrs = [first[n] for n in names]
        assert addrs[0] == hot_start
        assert addrs == sorted(addrs)
