"""Fixtures of the simulated-board tests: the simulator, the firmware, a running board.

The simulator (sim/build.py, Verilator) and the firmware (firmware/board, riscv64-unknown-elf-gcc)
are built once per session and copied for it: another session in the same tree may rebuild them
while this one runs, and the boards of one session, whose cycle counts the tests compare, must run
the same simulator and the same image.  A missing cross compiler fails the tests that need it with
the hint to run `make setup` (which installs it), never skips them.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from wavemesh.harness.simboard import SimBoard, build


def pytest_configure(config):
    config.addinivalue_line("markers", "sim: needs the simulated board (Verilator model of the SoC)")


@pytest.fixture(scope="session")
def sim_exe(verilator, tmp_path_factory) -> Path:
    try:
        exe = build.build_sim()
    except RuntimeError as e:
        pytest.fail(str(e))
    # (build.py renames a new simulator over the old one: a copy is one or the other, never half of one)
    return Path(shutil.copy2(exe, tmp_path_factory.mktemp("sim") / exe.name))


@pytest.fixture(scope="session")
def firmware_hex(tmp_path_factory) -> Path:
    try:
        image = build.build_firmware()
    except RuntimeError as e:  # MissingToolchain too: its message says to run `make setup`
        pytest.fail(str(e))
    with build.locked(image.parent):  # (the firmware build writes the image in place, under this lock)
        return Path(shutil.copy2(image, tmp_path_factory.mktemp("firmware") / image.name))


@pytest.fixture
def start_sim(sim_exe):
    """start_sim(firmware, *options) -> SimBoard on a free port (or --no-socket); stopped afterwards."""
    boards = []

    def start(firmware: Path, *args: str) -> SimBoard:
        extra = () if "--no-socket" in args else ("--port", "0")
        b = SimBoard(sim_exe, firmware, *extra, *args)
        boards.append(b)
        return b

    yield start
    for b in boards:
        b.stop()
