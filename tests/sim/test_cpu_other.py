"""The SoC with its other CPUs (host/wavemesh/device/soc_cpu.py: the VexRiscv, the default, and the
PicoRV32): the board jobs of each CPU other than the default, which the other board tests run.

Each CPU's simulator and firmware (its -march, its build folders) are built beside the default ones.
Two small jobs and the first again on one board: every mesh byte for byte `wavemesh mesh`'s, and the
repeated job with exactly the same cycles in every stage and every level (docs/soc.md, "Cycle
accounting").
"""

from __future__ import annotations

import numpy as np
import pytest
from test_stream_board import LEAN, assert_same_work, job_cycles, stream_and_mesh
from wavemesh.device import soc_cpu
from wavemesh.device import stream as S
from wavemesh.harness.simboard import SIM_TIMEOUTS, SimBoard, build
from wavemesh.io.synth import make

pytestmark = pytest.mark.sim

OTHERS = [name for name in soc_cpu.CPUS if name != soc_cpu.CPU]


@pytest.fixture(params=OTHERS)
def other_board(request, verilator, tmp_path_factory):
    try:
        exe, image = build.copies(tmp_path_factory.mktemp(request.param), request.param)
    except RuntimeError as e:
        pytest.fail(str(e))
    b = SimBoard(exe, image, "--port", "0", "--fast", "--quiet")
    yield b
    b.stop()


def test_other_cpu_board_jobs_equal_mesh(other_board, tmp_path, monkeypatch):
    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", SIM_TIMEOUTS)
    np.save(tmp_path / "tiny.npy", make("ball", 16)[3:12, 2:12])  # 10 x 9
    np.save(tmp_path / "box.npy", make("box", 32)[:24, 4:32])  # 28 x 24
    jobs = [("tiny.npy", []), ("box.npy", ["--metric", "vertical", "--zeta", "2", *LEAN]), ("tiny.npy", [])]
    cycles = []
    for i, (name, opts) in enumerate(jobs):
        d = tmp_path / f"job{i}"
        d.mkdir()
        report = stream_and_mesh(str(tmp_path / name), opts, other_board.url, d)
        cycles.append(job_cycles(report))
    assert_same_work(cycles[0], cycles[2])


def test_the_choice_is_checked(monkeypatch):
    """An unknown WM_CPU is one clear error naming the CPUs, not a build of something else."""
    monkeypatch.setenv("WM_CPU", "z80")
    with pytest.raises(soc_cpu.UnknownCpu, match="picorv32, vexriscv"):
        build.build_sim()


def _module(text: str, name: str) -> str:
    start = text.index(f"module {name} (")
    return text[start:text.index("endmodule", start)]


@pytest.mark.parametrize("kib", [8, 16, 32])
def test_caches_resized(kib, verilator, tmp_path):
    """The VexRiscv with larger caches (soc_cpu.icache_resized, dcache_resized): only the cache modules
    change, their memories as deep as the size asks, their flushes sweeping every line, and Verilator
    finds no width or other warning in the result that the package's own file does not have (the whole
    firmware running on the default CPU's caches is tests/sim/test_stream_board.py's)."""
    import re
    import subprocess

    cpu = soc_cpu.CPUS["vexriscv"]
    shipped = (cpu.folder() / cpu.verilog).read_text()
    lines, words = kib * 32, kib * 256
    lb, top = lines.bit_length() - 1, 12 + (kib // 4).bit_length() - 1
    icache = soc_cpu.icache_resized(shipped, kib)
    text = soc_cpu.dcache_resized(icache, kib)
    old_i, new_i = _module(shipped, "InstructionCache"), _module(text, "InstructionCache")
    old_d, new_d = _module(shipped, "DataCache"), _module(text, "DataCache")
    assert text.replace(new_i, old_i).replace(new_d, old_d) == shipped  # nothing outside the two modules
    assert _module(icache, "DataCache") == old_d  # each function its own cache
    assert f"reg [31:0] banks_0 [0:{words - 1}];" in new_i and f"ways_0_tags [0:{lines - 1}];" in new_i
    assert f"io_cpu_prefetch_pc[{top - 1} : 2]" in new_i and f"io_cpu_prefetch_pc[{top - 1} : 5]" in new_i
    assert f"reg        [{lb}:0]    lineLoader_flushCounter;" in new_i  # line index bits and a done bit
    assert f"ways_0_data_symbol3 [0:{words - 1}];" in new_d and f"ways_0_tags [0:{lines - 1}];" in new_d
    assert f"io_cpu_execute_address[{top - 1} : 2]" in new_d
    assert f"io_cpu_memory_address[{top - 1} : 2]" in new_d
    assert f"reg        [{lb}:0]    stageB_flusher_counter;" in new_d
    for body in (new_i, new_d):
        assert "[11 : 5]" not in body and "[11 : 2]" not in body

    exe, env = verilator

    def warnings(src: str, name: str) -> set[str]:
        f = tmp_path / name / "VexRiscv.v"
        f.parent.mkdir()
        f.write_text(src)
        r = subprocess.run([exe, "--lint-only", "-Wall", "-Wno-fatal", "--top-module", "VexRiscv", str(f)],
                           capture_output=True, text=True, env=env)
        assert "%Error" not in r.stderr, r.stderr[-3000:]
        # (which bits of an address go unused moves with the cache's size)
        return {re.sub(r"\S*\.v:\d+:\d+:|\[[0-9:,]+\]$", "", ln) for ln in r.stderr.splitlines()
                if ln.startswith("%Warning")}

    assert warnings(text, "resized") <= warnings(shipped, "shipped")


def test_caches_resized_refuse():
    """Another size, or a core whose caches are not the ones expected (the Lite's: a 2 KiB instruction
    cache, no data cache), is an error."""
    cpu = soc_cpu.CPUS["vexriscv"]
    shipped = (cpu.folder() / cpu.verilog).read_text()
    lite = (cpu.folder() / "VexRiscv_Lite.v").read_text()
    for resize in (soc_cpu.icache_resized, soc_cpu.dcache_resized):
        with pytest.raises(ValueError, match="8, 16 or 32"):
            resize(shipped, 64)
        with pytest.raises(ValueError, match="not the .*Cache expected"):
            resize(lite, 16)
