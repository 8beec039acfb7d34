"""Template stage (rtl/tlut_stage.v): cycles per block in simulation, resources and fmax on the FPGAs.

Cycles: the cocotb bench tests/rtl/tlut_stage_tb.py (test_bench_cycles) runs the dissertation's
synthetic sets through the stage under Verilator with the output always ready and one record per
cycle: once with level M's records only, once with every level's records in filter-bank order (the
stage drops the others).  Resources and fmax: host/wavemesh/harness/fpga.py's synth_pnr on the ECP5-85F and
the
UP5K, with the stage inside harness/fpga.py's pin harness (its flip-flops and LUTs are listed apart).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RTL = ROOT / "rtl"

TITLE = "Template stage (tlut_stage)"
PARAMS = {"MAX_COLS": 1024, "FIFO_DEPTH": 4}  # the defaults: up to 1024 block columns
TARGETS = ("ecp5-85k", "up5k")
SOURCES = [*sorted(RTL.glob("tlut_*.v")), RTL / "wm_fifo.v"]


def cycles() -> list[dict]:
    from wavemesh.harness.rtl_runner import run as run_rtl

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cycles.json"
        run_rtl("tlut_stage", SOURCES, "tlut_stage_tb", parameters=PARAMS,
                testcase="test_bench_cycles", extra_env={"TLUT_BENCH_OUT": str(out)})
        return json.loads(out.read_text())


def fpga(target: str) -> dict:
    from wavemesh.device.gen import write_all
    from wavemesh.harness import fpga as fp

    # synth_pnr reads the sources with no include path; Yosys also looks in its working directory,
    # so the generated wm_templates.vh is written there (generated, as `make gen` does, not copied)
    write_all(fp.BUILD / f"tlut_stage_{target}_{fp._tag(PARAMS)}")
    r = fp.synth_pnr("tlut_stage", SOURCES, PARAMS, target)
    r.pop("yosys_cells", None)
    return r


def run() -> dict:
    return {"params": PARAMS, "cycles": cycles(), "fpga": {t: fpga(t) for t in TARGETS}}


def markdown(results: dict) -> str:
    own = [r for r in results["cycles"] if not r["all_levels"]]
    per_block = sum(r["output_span"] for r in own) / sum(r["blocks"] for r in own)  # the sets' mean
    lines = [
        "Level M's coefficient records in, triangles out (rtl/README.md, \"Template stage\"); parameters "
        + ", ".join(f"{k}={v}" for k, v in results["params"].items()) + ".",
        "",
        "**Cycles** (Verilator; output always ready, one record offered per cycle).  A block takes as many "
        "cycles as its template has triangles, with no gap between blocks: cycles per block = triangles "
        "per block once the first block row is in.  *first* is the cycles from the record that completes "
        "block (0, 0) to its first triangle, *drain* from the frame's last block record to the last "
        "triangle (the last block row, flushed).  With every level's records the input stream sets the "
        "pace (the stage drops the other levels at one record per cycle).",
        "",
        "| set | size | M | records in | blocks | triangles | cycles | cycles/block | output cycles/block "
        "| first | drain |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results["cycles"]:
        which = "all levels" if r["all_levels"] else "level M"
        lines.append(
            f"| {r['name']} ({which}) | {r['size'][1]}x{r['size'][0]} | {r['levels']} | {r['records']} "
            f"| {r['blocks']} | {r['triangles']} | {r['cycles']} | {r['cycles'] / r['blocks']:.2f} "
            f"| {r['output_span'] / r['blocks']:.2f} | {r['first_latency']} | {r['drain']} |")
    lines += [
        "",
        "**FPGA** (Yosys + nextpnr from the pinned .venv; the stage inside host/wavemesh/harness/fpga.py's "
        "harness, whose "
        "own flip-flops and LUTs are in the totals and listed apart; *stage* = total less harness).",
        "",
        f"| target | LUTs (stage) | FFs (stage) | BRAM | fmax MHz "
        f"| Mblocks/s at fmax ({per_block:.2f} cycles/block) |",
        "|---|---|---|---|---|---|",
    ]
    for target, r in results["fpga"].items():
        if not r.get("fits"):
            lines.append(f"| {r['device']} | {r.get('luts')} | {r.get('ffs')} | {r.get('bram')} | "
                         f"did not fit: {r.get('error')} | |")
            continue
        luts = r.get("luts") if target == "ecp5-85k" else r.get("lcs")
        unit = "LUT4" if target == "ecp5-85k" else "LC"
        stage_luts = luts - r.get("harness_luts", 0)
        stage_ffs = r["ffs"] - r.get("harness_ffs", 0)
        avail = r.get("luts_available") or r.get("lcs_available")
        rate = r["fmax_mhz"] / per_block
        share = f"{100 * stage_luts / avail:.1f}% of {avail}"
        lines.append(f"| {r['device']} | {luts} {unit} ({stage_luts}, {share}) "
                     f"| {r['ffs']} ({stage_ffs}) | {r['bram']} | {r['fmax_mhz']} | {rate:.1f} |")
    lines += [
        "",
        "BRAM: the row buffer (1024 x 4 bits) and the triangle ROM (512 x 12 bits): one DP16KD each on the "
        "ECP5, one and two SB_RAM40_4K on the UP5K.",
    ]
    return "\n".join(lines) + "\n"
