"""The SoC with its other CPUs (host/wavemesh/device/soc_cpu.py: the VexRiscv, the default, and the
PicoRV32): the board jobs of each CPU other than the default, which the other board tests run.

Each CPU's simulator and firmware (its -march, its build folders) are built beside the default ones.
Two small jobs and the first again on one board: every mesh byte for byte `wavemesh mesh`'s, and the
repeated job with exactly the same cycles in every stage and every level (docs/soc.md, "Cycle
accounting").
"""

from __future__ import annotations

import shutil
from pathlib import Path

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
        exe = build.build_sim(cpu_name=request.param)
        image = build.build_firmware(cpu_name=request.param)
    except RuntimeError as e:
        pytest.fail(str(e))
    d = tmp_path_factory.mktemp(request.param)
    exe = Path(shutil.copy2(exe, d / exe.name))
    with build.locked(image.parent):
        image = Path(shutil.copy2(image, d / image.name))
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
