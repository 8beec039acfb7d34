"""The board's target: a 1024 x 1024 input through the simulated ULX3S, bit for bit `wavemesh mesh`'s mesh.

    make bench-board1024                               the 1024 x 1024 run: hours; not part of `make bench`
    .venv/bin/python bench/bench_board1024.py --side 128   the same job at 128 x 128 (minutes), its results
                                                       to build/bench/ (bench/results/ keeps the 1024 run)

The input is wavemesh.io.synth's Ball at SIDE x SIDE, meshed with `--levels 2 --reduce off --simplify off
-k 0`: the cheapest job with 100k triangles (docs/soc.md, "A 1024 x 1024 job on the simulated board"):
at M = 2 every 4 x 4 block gives at least two triangles, so the template stage alone makes 139,216 of
them at 1024 x 1024, and `-k 0` refines only until the error bound holds (139,950).  It is streamed by
`wavemesh stream` (in this process, with the simulated board's host timeouts made long enough for a
loaded machine) through `wmsim --fast` (sim/: the cycle-accurate Verilator model of the bitstream's
design, the SDRAM chip model included), and the OBJ file it writes is compared byte for byte with
`wavemesh mesh`'s.  The device's cycles per stage come from `--report` (`device_cycles`), the
simulator's cycles, wall and CPU seconds from its summary line.

A run of hours must be watchable and must leave something if it is cut short: every PROGRESS_S
seconds it prints the simulated cycle (wmsim --progress), the stage running (the firmware's stage
markers in wmsim's log), the simulator's CPU seconds and rate, and writes the same to the partial
results file (bench/results/board1024.partial.json for the 1024 run), which ends with the final
results or the error.  The simulator and the firmware image are copies made at the start: the run
outlasts other work in the tree that rebuilds them.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RESULTS = BENCH / "results"

TITLE = "1024 x 1024 through the simulated board"
DEFAULT = False  # hours: bench/run.py runs it only when named (`make bench-board1024`)
SIDE = 1024
OPTIONS = ["--levels", "2", "--reduce", "off", "--simplify", "off", "-k", "0"]
BAR_TRIANGLES = 100_000  # the target: at least 100k triangles
PROGRESS_S = 60.0  # seconds between progress lines and partial results
STAGES = ("receive", "filter", "template", "refine", "emit", "link")  # DONE's counters
WORK = ("filter", "template", "refine", "emit")  # the device's work, apart from the host link
JOB_TIMEOUT = 6 * 3600.0  # s the device may compute without a frame (the refine of one level: an hour here)


def _stage_name(value: int) -> str:
    """A firmware stage marker (docs/soc.md, "The job": 0x00020000 | the engine's clock) as text."""
    from wavemesh.device.protocol import Stage

    if value >> 16 != 2:
        return f"0x{value:08x}"
    clock = value & 0xFFFF
    link = clock & 0x100
    clock &= 0xFF
    name = "none" if clock == 0xFF else Stage(clock).name.lower() if clock < len(Stage) else f"clock {clock}"
    return f"link ({name})" if link else name


class _Monitor(threading.Thread):
    """Prints the run's progress and writes the partial results every PROGRESS_S seconds."""

    def __init__(self, board, partial: Path, head: dict):
        super().__init__(daemon=True)
        self.board, self.partial, self.head = board, partial, head
        self.t0 = time.monotonic()
        self.done = threading.Event()

    def state(self) -> dict:
        cycle, cpu, stage, stage_cycle, stages = 0, None, "", 0, []
        for line in list(self.board.lines):
            m = re.match(r"wmsim: progress cycle (\d+) cpu ([\d.]+) s", line)
            if m:
                cycle, cpu = int(m.group(1)), float(m.group(2))
                continue
            m = re.match(r"wmsim: stage 0x([0-9a-f]+) cycle (\d+)", line)
            if m:
                name, at = _stage_name(int(m.group(1), 16)), int(m.group(2))
                if not name.startswith("link") and name != stage:
                    stages.append({"stage": name, "cycle": at})
                stage, stage_cycle = name, at
        # the cycle and CPU time of wmsim's last progress line (a rate over the same span)
        return {"elapsed_s": round(time.monotonic() - self.t0, 1), "cycle": cycle, "stage": stage,
                "stage_since_cycle": stage_cycle, "stages_started": stages,
                "sim_cpu_s": cpu, "khz_per_cpu_s": round(cycle / cpu / 1e3, 1) if cpu else None}

    def write(self, status: str, **extra) -> None:
        data = {**self.head, "status": status, "progress": self.state(), **extra}
        self.partial.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.partial.with_name(self.partial.name + ".tmp")
        tmp.write_text(json.dumps(data, indent=1) + "\n")
        tmp.replace(self.partial)

    def run(self) -> None:
        while not self.done.wait(PROGRESS_S):
            s = self.state()
            rate = f"{s['khz_per_cpu_s']:,.0f} kHz per CPU s" if s["khz_per_cpu_s"] else "rate ?"
            print(f"board{self.head['side']}: {s['elapsed_s'] / 60:6.1f} min  cycle {s['cycle']:,}  "
                  f"stage {s['stage'] or '-'}  simulator CPU {s['sim_cpu_s'] or 0:,.0f} s  {rate}",
                  flush=True)
            self.write("running")


def run(side: int = SIDE, partial: Path | None = None) -> dict:
    import numpy as np
    from peers import code_state
    from wavemesh import cli
    from wavemesh.harness import run_cli
    from wavemesh.harness.simboard import SimBoard, build, host_timeouts
    from wavemesh.io.synth import ball

    partial = partial or RESULTS / f"board{side}.partial.json"
    from wavemesh.device import soc_cpu

    head = {"side": side, "input": f"wavemesh.io.synth.ball({side})", "options": OPTIONS,
            "code": code_state(), "cpu": soc_cpu.selected().name}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        exe, fw = build.copies(tmp)
        src = tmp / "ball.npy"
        np.save(src, ball(side))

        t0 = time.monotonic()
        rc, _, err = run_cli("mesh", str(src), *OPTIONS, "-o", str(tmp / "soft.obj"), "--report",
                             str(tmp / "soft.json"), "-q")
        mesh_s = time.monotonic() - t0
        if rc != 0:
            return {**head, "error": f"wavemesh mesh failed: {err.strip()[-500:]}"}
        soft = json.loads((tmp / "soft.json").read_text())
        head["mesh_seconds"] = round(mesh_s, 1)
        head["mesh_triangles"] = soft["refiner"]["levels"][-1]["triangles"]
        print(f"board{side}: wavemesh mesh: {head['mesh_triangles']:,} triangles in {mesh_s:.1f} s; "
              f"streaming through the simulated board (progress every {PROGRESS_S:.0f} s)", flush=True)

        # (wmsim's progress lines twice as often as the monitor's: each of these has a recent one)
        board = SimBoard(exe, fw, "--port", "0", "--fast", "--exit-on-close",
                         "--progress", str(PROGRESS_S / 2))
        monitor = _Monitor(board, partial, head)
        monitor.write("running")
        monitor.start()
        # the simulator runs at 1/30 of the board or far less on a loaded machine, and a level of the
        # refiner takes it an hour (no device cycle depends on these waits)
        t0 = time.monotonic()
        try:
            with (host_timeouts(sync=20.0, reply=120.0, ack=120.0, job=JOB_TIMEOUT),
                  open(tmp / "stream.err", "w") as err_file, contextlib.redirect_stderr(err_file)):
                rc = cli.main(["stream", str(src), *OPTIONS, "--port", board.url,
                               "-o", str(tmp / "board.obj"), "--report", str(tmp / "board.json")])
            wall = time.monotonic() - t0
            board.wait(60)
        except BaseException as e:
            monitor.done.set()
            monitor.write("failed", error=repr(e))
            raise
        finally:
            board.stop()
            monitor.done.set()
        err = (tmp / "stream.err").read_text()
        if rc != 0:
            lines = [ln for ln in err.splitlines() if ln.startswith(("error", "hint"))]
            lines = lines or err.splitlines()[-3:]
            result = {**head, "error": " / ".join(lines)[-800:], "progress": monitor.state()}
            monitor.write("failed", error=result["error"])
            return result
        rep = json.loads((tmp / "board.json").read_text())
        same = (tmp / "board.obj").read_bytes() == (tmp / "soft.obj").read_bytes()
        obj_bytes = (tmp / "board.obj").stat().st_size

    summary = board.summary()
    cyc = rep["device_cycles"]
    levels = rep["refiner"]["levels"]
    result = {
        **head, "width": rep["input"]["width"], "height": rep["input"]["height"],
        # the templates' triangulation (DONE's initial_triangles), not the first level the board sent
        "initial_triangles": rep["initial"]["triangles"], "output_triangles": levels[-1]["triangles"],
        "meets_triangles": levels[-1]["triangles"] >= BAR_TRIANGLES, "same_as_mesh": same,
        "obj_bytes": obj_bytes,
        "cycles": {k: cyc[k] for k in STAGES}, "work_cycles": sum(cyc[k] for k in WORK),
        "job_cycles": sum(cyc[k] for k in STAGES), "clk_hz": rep["device"]["clk_hz"],
        "link_bytes": rep["transfer"]["bytes_out"] + rep["transfer"]["bytes_in"],
        "refiner_levels": [{k: lv[k] for k in ("level", "triangles", "splits", "swaps", "device_cycles")}
                           for lv in levels],
        "stream_wall_s": round(wall, 1), "stages_started": monitor.state()["stages_started"],
    }
    if summary:
        cycles, cpu = summary["cycles"], summary["cpu_seconds"]
        result["simulator"] = {"cycles": cycles, "wall_s": summary["wall_seconds"], "cpu_s": cpu,
                               "khz_per_cpu_s": round(cycles / cpu / 1e3, 1)}
    monitor.write("done", result=result)
    return result


def _duration(s: float) -> str:
    return f"{s / 3600:.2f} h" if s >= 3600 else f"{s / 60:.1f} min" if s >= 60 else f"{s:.0f} s"


def markdown(results: dict) -> str:
    from peers import code_line

    r = results
    side = r["side"]
    lines = [
        f"wavemesh.io.synth's Ball at {side} x {side}, `wavemesh stream {' '.join(r['options'])}` through "
        "the simulated ULX3S (`wmsim --fast`: the Verilator model of the bitstream's design, "
        f"{r.get('cpu', 'picorv32')}, FPGA stage, SDRAM controller and the SDRAM chip's cycle model), "
        "compared byte for byte with `wavemesh mesh`'s OBJ file.  " + code_line(r.get("code")),
        "",
    ]
    if "error" in r:
        prog = r.get("progress") or {}
        where = f" (at cycle {prog['cycle']:,}, stage {prog['stage']})" if prog else ""
        return "\n".join(lines + [f"**The run failed**: `{r['error']}`{where}", ""])
    clk = r["clk_hz"]
    bar = "met" if r["meets_triangles"] and r["same_as_mesh"] else "NOT met"
    lines += [
        f"**Bar ({side} x {side}, at least {BAR_TRIANGLES:,} triangles, bit-exact): {bar}.**  "
        f"{r['initial_triangles']:,} triangles in the initial triangulation (the templates') and "
        f"{r['output_triangles']:,} in the output; the board's OBJ "
        f"file ({r['obj_bytes']:,} bytes) {'equals' if r['same_as_mesh'] else 'DIFFERS from'} "
        "`wavemesh mesh`'s "
        f"({r['mesh_triangles']:,} triangles in {r['mesh_seconds']:.1f} s on the host).",
        "",
        "| stage | cycles | on the board at 25 MHz |",
        "|---|---|---|",
    ]
    for k in STAGES:
        lines.append(f"| {k} | {r['cycles'][k]:,} | {r['cycles'][k] / clk:,.1f} s |")
    for name, n in (("work (filter + template + refine + emit)", r["work_cycles"]),
                    ("job (all six)", r["job_cycles"])):
        lines.append(f"| {name} | {n:,} | {n / clk:,.1f} s |")
    lines.append("")
    per = "; ".join(f"{lv['level']}: {lv['triangles']:,} triangles, {lv['splits']} splits, "
                    f"{lv['device_cycles']:,} cycles" for lv in r["refiner_levels"])
    lines += [f"Refiner levels: {per}.  *receive* and *link* are fast-mode figures (the bytes go straight "
              "into and out of the UART's FIFOs); on a board the 115200-baud line paces them "
              f"({r['link_bytes']:,} bytes both ways: {r['link_bytes'] * 10 / 115200:,.0f} s).", ""]
    sim = r.get("simulator")
    if sim:
        lines += [f"Simulator: {sim['cycles']:,} cycles in {_duration(sim['wall_s'])} of wall time and "
                  f"{_duration(sim['cpu_s'])} of CPU time, {sim['khz_per_cpu_s']:,.0f} kHz per CPU second "
                  "(wmsim's summary line; the machine is shared, so wall time is longer); the stream took "
                  f"{_duration(r['stream_wall_s'])}."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=SIDE, help=f"grid side (default {SIDE}: the bar)")
    ap.add_argument("--out", type=Path, default=None,
                    help="results file (default build/bench/boardSIDE.json; bench/results/ has the "
                         "1024 run of make bench-board1024)")
    args = ap.parse_args(argv)
    if not 8 <= args.side <= 1024:
        print(f"error: --side {args.side} is out of range; give 8..1024 (the board's grid)", file=sys.stderr)
        return 2
    out = args.out or ROOT / "build" / "bench" / f"board{args.side}.json"
    results = run(args.side, partial=out.with_name(out.stem + ".partial.json"))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(markdown(results))
    print(f"board{args.side}: results in {out}")
    return 0 if "error" not in results else 1


if __name__ == "__main__":
    sys.exit(main())
