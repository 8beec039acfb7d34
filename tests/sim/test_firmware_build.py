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
