"""SDRAM controller (rtl/sdram_ctrl.v): cycles in simulation, resources and fmax on the ECP5-85F.

Cycles: the cocotb bench tests/rtl/sdram_tb.py (test_bench_cycles) at 25 MHz (the ULX3S's oscillator) with CAS
latency 2, against its behavioural chip (every timing checked): a 16384-halfword stream write and
read with the data always valid / ready, addressed writes of three interleaved sequences (as the
filter bank's levels) each in a linear area (they meet in the banks as they advance) or each kept in
a bank of its own, and CPU accesses through the cache (sequential words, hits, row misses, posted
writes).  Resources and fmax: host/wavemesh/harness/fpga.py's synth_pnr on the ECP5-85F, the
controller (with its cache and FIFOs) inside harness/fpga.py's pin harness, with the default 256-byte cache
and a 4 KB one.
"""

from __future__ import annotations

import json
import statistics
import tempfile
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RTL = ROOT / "rtl"

TITLE = "SDRAM controller (sdram_ctrl)"
CLK_HZ, CL = 25_000_000, 2  # the bench's fixed clock, for comparable figures (the SoC: memmap.CLK_HZ)
PARAMS = {"CLK_HZ": CLK_HZ, "CAS_LATENCY": CL}
SOURCES = [RTL / "sdram_ctrl.v", RTL / "sdram_cache.v", RTL / "wm_fifo.v"]
TARGET = "ecp5-85k"


def cycles() -> dict:
    from wavemesh.harness.rtl_runner import run as run_rtl

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cycles.json"
        run_rtl("sdram_ctrl", SOURCES, "sdram_tb", parameters=PARAMS, testcase="test_bench_cycles",
                extra_env={"SDRAM_BENCH_OUT": str(out), "SDRAM_CLK_HZ": str(CLK_HZ), "SDRAM_CL": str(CL),
                           "SDRAM_SEED": "1"})
        return json.loads(out.read_text())


# FPGA builds: the default cache (16 lines of 4 words, LUT RAM) and a 4 KB one (256 x 4, block RAM)
CACHES = {"256 B": {}, "4 KB": {"CACHE_LINES": 256, "LINE_WORDS": 4}}


def fpga(cache: dict) -> dict:
    from wavemesh.harness import fpga as fp

    r = fp.synth_pnr("sdram_ctrl", SOURCES, {**PARAMS, **cache}, TARGET)
    r.pop("yosys_cells", None)
    return r


def run() -> dict:
    return {"params": PARAMS, "cycles": cycles(), "fpga": {name: fpga(c) for name, c in CACHES.items()}}


def markdown(results: dict) -> str:
    c, r = results["cycles"], results["fpga"]
    mhz = c["clk_hz"] / 1e6
    cpu = c["cpu"]
    seq = cpu["sequential_read"]
    lines = [
        f"The controller at the ULX3S's {mhz:g} MHz board clock, CAS latency {c['cas_latency']} "
        "(rtl/README.md, \"SDRAM controller\"), against the bench's behavioural chip with every timing "
        "checked (tests/rtl/sdram_tb.py).",
        "",
        "**Streams** (data always valid / ready; cycles from the command to the last halfword handed "
        "out, or to the writer's last WRITE; refreshes and row changes included; the interleaved "
        "sequences advance at random, one twice as often as the next, as a filter bank's levels):",
        "",
        "| stream | halfwords | cycles | cycles / halfword | MB/s | refreshes |",
        "|---|---|---|---|---|---|",
    ]
    for name in ("stream_write", "stream_read"):
        s = c[name]
        per = s["cycles"] / s["halfwords"]
        lines.append(f"| {name.replace('_', ' ')} | {s['halfwords']} | {s['cycles']} | {per:.3f} "
                     f"| {2 * mhz / per:.1f} | {s['refreshes']} |")
    labels = {"scatter_linear": "addressed writes: 3 interleaved sequences, each in a linear area",
              "scatter_own_banks": "addressed writes: 3 interleaved sequences, each in a bank of its own"}
    for name, label in labels.items():
        s = c[name]
        per = s["cycles"] / s["halfwords"]
        lines.append(f"| {label} | {s['halfwords']} | {s['cycles']} | {per:.3f} | {2 * mhz / per:.1f} | |")
    lines += [
        "",
        "**CPU port** (cycles per access from the request's first cycle to the one with `cpu_ready`, "
        "both counted, as the SoC's block RAMs take 2):",
        "",
        "| access | cycles |",
        "|---|---|",
        f"| read hit | {statistics.median(cpu['hit']):g} |",
        f"| read miss, row open (the line's first word) | {statistics.median(seq[4::4]):g} |",
        f"| read miss, row closed (another row of the bank) | {statistics.median(cpu['row_miss']):g} |",
        f"| sequential reads, mean over {len(seq)} words (a miss per 4-word line) "
        f"| {sum(seq) / len(seq):.2f} |",
        "| write (posted; back to back, each waits for the one before) "
        f"| {statistics.median(cpu['write']):g} |",
        "",
    ]
    builds = r
    lines += [
        "**FPGA** (Yosys + nextpnr from the pinned .venv, host/wavemesh/harness/fpga.py's harness, whose "
        "flip-flops "
        "and LUTs are in the totals and listed apart; *controller* = total less harness), "
        f"{next(iter(builds.values()))['device']}:",
        "",
        "| CPU cache | LUTs (controller) | FFs (controller) | LUT RAM slices | BRAM | DSP | fmax MHz "
        f"| margin over {mhz:g} MHz |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, b in builds.items():
        if not b.get("fits"):
            lines.append(f"| {name} | did not fit: {b.get('error')} | | | | | | |")
            continue
        own_luts = b["luts"] - b.get("harness_luts", 0)
        own_ffs = b["ffs"] - b.get("harness_ffs", 0)
        lines.append(
            f"| {name} | {b['luts']} ({own_luts}, {100 * own_luts / b['luts_available']:.1f}% of "
            f"{b['luts_available']}) | {b['ffs']} ({own_ffs}) | {b.get('lutram_slices', 0)} | {b['bram']} "
            f"| {b['dsp']} | {b['fmax_mhz']} | {100 * (b['fmax_mhz'] / mhz - 1):.0f}% |")
    return "\n".join(lines) + "\n"
