"""Filter bank (rtl/haar_bank.v): clocks per sample in simulation, resources and fmax on the FPGAs.

Cycles: the cocotb bench tests/rtl/haar_bank_tb.py (run_frames, every record checked against the
reference model) runs 256 x 256 and 512 x 512 frames of random samples through the default bank
(MAX 512 x 512, 7 levels) under Verilator, input always valid and output always ready, then a
256 x 256 frame with random back-pressure (30% of the cycles not ready) for information.  A frame's
clocks run from its start (the first sample offered while idle) to the hand-out of its last record,
set-up and pipeline drain included.

Resources and fmax: host/wavemesh/harness/fpga.py's synth_pnr on the ECP5-85F and the UP5K, the bank inside
fpga.py's pin harness (its flip-flops and LUTs are listed apart).  The UP5K is also tried with fewer
levels, to show what fits it.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RTL = ROOT / "rtl"

TITLE = "Filter bank (haar_bank)"
PARAMS = {"MAX_WIDTH": 512, "MAX_HEIGHT": 512, "MAX_LEVELS": 7}  # the defaults
SOURCES = [RTL / f"{m}.v" for m in ("haar_raster", "wm_linebuf", "haar_level", "wm_fifo", "haar_bank")]
# (target, parameters): the defaults on both, and a smaller bank on the UP5K (6 levels do not fit
# either, and nextpnr takes minutes to find that out)
SYNTH = [("ecp5-85k", PARAMS), ("up5k", PARAMS), ("up5k", {**PARAMS, "MAX_LEVELS": 5})]


def simulate(frames: list[list[int]], idle: str, bp: str) -> list[dict]:
    """Per-frame cycle counts from haar_bank_tb.run_frames (which also checks every record)."""
    from wavemesh.harness.rtl_runner import run as run_rtl

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cycles.json"
        env = {"HAAR_FRAMES": json.dumps(frames), "HAAR_IDLE": idle, "HAAR_BP": bp,
               "HAAR_MAX_LEVELS": str(PARAMS["MAX_LEVELS"]), "HAAR_RESULTS": str(out)}
        run_rtl("haar_bank", SOURCES, "haar_bank_tb", parameters=PARAMS, testcase="run_frames", extra_env=env)
        rows = json.loads(out.read_text())
    for r in rows:
        samples = r["width"] * r["height"]
        r.update(idle=idle, backpressure=bp, cycles_per_sample=round(r["cycles"] / samples, 5))
    return rows


def run() -> dict:
    from wavemesh.harness import fpga as fp

    cycles = simulate([[256, 256, 7, 0], [512, 512, 7, 1]], "none", "none")
    cycles += simulate([[256, 256, 7, 2]], "none", "random")
    synth = []
    for target, params in SYNTH:
        r = fp.synth_pnr("haar_bank", SOURCES, params, target)
        r.pop("yosys_cells", None)
        synth.append(r)
    return {"params": PARAMS, "cycles": cycles, "fpga": synth}


def markdown(results: dict) -> str:
    p = results["params"]
    lines = [
        "Height samples in, one record per 2 x 2 block and level out (rtl/README.md, \"Filter bank\"); "
        f"MAX_WIDTH={p['MAX_WIDTH']}, MAX_HEIGHT={p['MAX_HEIGHT']}, MAX_LEVELS={p['MAX_LEVELS']}, "
        "random 16-bit samples, every record checked against the reference model.",
        "",
        "| frame | levels | input | output | records | clocks | clocks per sample |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results["cycles"]:
        out = "always ready" if r["backpressure"] == "none" else f"{r['backpressure']} back-pressure"
        inp = "always valid" if r["idle"] == "none" else f"{r['idle']} idle"
        lines.append(f"| {r['width']} x {r['height']} | {r['levels']} | {inp} | {out} | {r['records']} "
                     f"| {r['cycles']} | {r['cycles_per_sample']:.4f} |")
    lines += [
        "",
        "Clocks from the frame's start to its last record, set-up and pipeline drain included; the "
        "random back-pressure holds the output 30% of the cycles.",
        "",
        "Yosys + nextpnr (host/wavemesh/harness/fpga.py), the bank inside a pin harness whose own "
        "flip-flops and LUTs "
        "are in the totals and listed apart (*bank* = total less harness).  ECP5 LUTs are TRELLIS_COMB "
        "cells (LUT4s, carry halves and LUT RAM); on the UP5K, LCs are logic cells (a LUT4 and a "
        "flip-flop each) and LUTs/FFs come from Yosys.",
        "",
        "| target | levels | LUTs (bank) | LCs | FFs (bank) | BRAM | DSP | fmax MHz |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results["fpga"]:
        levels = r["params"].get("MAX_LEVELS", p["MAX_LEVELS"])
        luts, ffs = r["luts"], r["ffs"]
        bank_luts, bank_ffs = luts - r.get("harness_luts", 0), ffs - r.get("harness_ffs", 0)
        if r["fits"]:
            avail = r.get("luts_available") if r["target"] == "ecp5-85k" else None
            share = f", {100 * bank_luts / avail:.1f}% of {avail}" if avail else ""
            lcs = f"{r['lcs']} of {r['lcs_available']}" if "lcs" in r else "-"
            lines.append(f"| {r['device']} | {levels} | {luts} ({bank_luts}{share}) | {lcs} "
                         f"| {ffs} ({bank_ffs}) | {r['bram']} | {r['dsp']} | {r['fmax_mhz']} |")
        else:
            lines.append(f"| {r['device']} | {levels} | {luts} ({bank_luts}) | does not fit "
                         f"| {ffs} ({bank_ffs}) | {r['bram']} | {r['dsp']} | - |")
    misfits = [r for r in results["fpga"] if not r["fits"]]
    for r in misfits:
        lines += ["", f"{r['device']}, {r['params'].get('MAX_LEVELS')} levels: nextpnr says `{r['error']}` "
                      "(counts from Yosys)."]
    return "\n".join(lines) + "\n"
