"""The whole job on the simulated board: work cycles against the budget, per stage, per sample and triangle.

`wavemesh stream` through the simulated board (sim/, the cycle-accurate Verilator model of soc_top:
the soft CPU of host/wavemesh/device/soc_cpu.py with the real firmware and the FPGA stage) in fast
UART mode, on three inputs that fit the board's grid and triangle capacity: Ball and Box
(wavemesh.io.synth, 256 x 256 decimated by 8) and a real DEM (matplotlib's Jacksboro fault DEM
decimated by 16, the options of
tests/sim/test_stream_board.py); and a held-out one never used while cutting cycles,
reported apart (bench/datasets.py's lidar DEM decimated by 8).  The device's cycles per stage come
from `--report` (`device_cycles`: receive, filter bank, templates, refiner, emit, and the link I/O of
the job apart; docs/protocol.md, "Cycle accounting").  The budget: the work cycles (filter,
template, refine and emit; receive and link excluded) at most 200 x input samples + 3,000 x output
triangles; reported per case with the cycles per input sample and per output triangle.  The
simulator and the firmware are built and started with wavemesh.harness.simboard and driven as
tests/sim/test_stream_board.py does (its host timeouts for the simulated board and its in-process CLI
runner).  Each mesh is also compared with `wavemesh mesh` (reported, not asserted).

Beside the board's cycles: the same refiner job (the same initial mesh, details and fixed-point
parameters, built from the same options as `wavemesh mesh` builds them) run natively by the C runner
tests/firmware/wm_run.c under callgrind, its x86-64 instructions per output triangle (when valgrind is
there): how much of the cost is the algorithm's work rather than the soft CPU's.  And the upload's
floor: the receive stage alone per output triangle, in fast mode and at the board's baud rate.

The budget's own inputs, whole (FULL: Ball and Box at 256 x 256, the whole Jacksboro DEM at zeta 10 m,
held out the lidar DEM and the Motorcycle range image), take long simulations (docs/benchmarks.md gives
each case's), so `make bench-soc` does not run them:

    make bench-soc-full [SOC_FULL='ball jacksboro']       all of them, or the named ones
    .venv/bin/python bench/bench_soc.py --full [NAME ...]  the same

streams each the same way (a fresh simulator per case, progress every minute on stderr), merges each
finished case into bench/results/soc-full.json at once (two such runs may share the file) and rewrites
docs/benchmarks.md, whose section of this benchmark shows them beside the decimated cases.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent

TITLE = "The whole job on the simulated board (SoC, fast mode)"
PER_SAMPLE, PER_TRIANGLE = 200, 3_000  # the budget: work cycles <= 200 x samples + 3,000 x output triangles
STAGES = ("receive", "filter", "template", "refine", "emit", "link")  # DONE's counters
WORK = ("filter", "template", "refine", "emit")  # the device's work: cycles that depend only on the job
BAUD = 115200  # the board's UART: 10 bits per byte on the wire

# name -> (input, options of `wavemesh stream` and `wavemesh mesh`); "JACKSBORO" is matplotlib's DEM
CASES = {
    "Ball 256 / 8": ("ball.npy", ["--decimate", "8"]),
    "Box 256 / 8": ("box.npy", ["--decimate", "8"]),
    "Jacksboro / 16": ("JACKSBORO", ["--key", "elevation", "--decimate", "16", "--zeta", "15"]),
    # held out: never looked at while cutting cycles (bench/datasets.py's held-out lidar DEM, as .npy: grid
    # steps, no georeference); reported apart, not one of the three timed inputs
    "lidar_dem / 8 (held out)": ("lidar.npy", ["--decimate", "8"]),
}
HELD_OUT_MARK = " (held out)"  # the end of a held-out case's name: the one place that says it is one
HELD_OUT = tuple(n for n in CASES if n.endswith(HELD_OUT_MARK))


def _inputs(folder: Path) -> None:
    import numpy as np
    from wavemesh.io.synth import ball, box

    np.save(folder / "ball.npy", ball(256))
    np.save(folder / "box.npy", box(256))
    import datasets

    np.save(folder / "lidar.npy", datasets.load("lidar_dem").values)


def _case(board, name: str, tmp: Path, spec: tuple[str, list[str]] | None = None) -> dict:
    import json

    from wavemesh.harness import jacksboro, run_cli

    file, opts = spec or CASES[name]
    src = jacksboro() if file == "JACKSBORO" else str(tmp / file)
    d = tmp / name.replace(" ", "_").replace("/", "")
    d.mkdir()
    t0 = time.monotonic()
    rc, _, err = run_cli("stream", src, *opts, "--port", board.url, "-o", str(d / "board.obj"),
                         "--report", str(d / "board.json"), "--quiet")
    wall = time.monotonic() - t0
    if rc != 0:
        return {"name": name, "options": opts, "error": err.strip()[-500:]}
    rep = json.loads((d / "board.json").read_text())
    rc, _, err = run_cli("mesh", src, *opts, "-o", str(d / "soft.obj"), "-q")
    same = rc == 0 and (d / "board.obj").read_bytes() == (d / "soft.obj").read_bytes()
    cyc = rep["device_cycles"]
    levels = rep["refiner"]["levels"]
    out_tris = levels[-1]["triangles"]
    total = sum(cyc[k] for k in STAGES)
    work = sum(cyc[k] for k in WORK)
    samples = rep["input"]["width"] * rep["input"]["height"]
    budget = PER_SAMPLE * samples + PER_TRIANGLE * out_tris
    return {
        "name": name, "options": opts, "width": rep["input"]["width"], "height": rep["input"]["height"],
        "levels": rep["parameters"]["levels"], "zeta": rep["parameters"]["zeta"],
        # the templates' triangulation (DONE's initial_triangles), not the first level the board sent
        "samples": samples, "initial_triangles": rep["initial"]["triangles"], "output_triangles": out_tris,
        "cycles": {k: cyc[k] for k in STAGES}, "total_cycles": total, "work_cycles": work,
        "budget_cycles": budget, "work_vs_budget": work / budget,
        "work_cycles_per_sample": work / samples, "work_cycles_per_triangle": work / out_tris,
        "cycles_per_triangle": total / out_tris,
        "refine_cycles_per_triangle": cyc["refine"] / out_tris,
        "board_seconds": total / rep["device"]["clk_hz"], "clk_hz": rep["device"]["clk_hz"],
        "refiner_levels": [{k: lv[k] for k in ("level", "triangles", "splits", "swaps", "device_cycles")}
                           for lv in levels],
        "link_bytes": rep["transfer"]["bytes_out"] + rep["transfer"]["bytes_in"],
        "upload_bytes": rep["transfer"]["bytes_out"],
        "same_as_mesh": same, "wall_seconds": round(wall, 1),
    }


def _native_instructions(name: str, tmp: Path) -> tuple[int, int] | None:
    """(x86-64 instructions, output triangles) of the case's refiner job natively (wm_run under
    callgrind: wm_refine_init and wm_refine_step, inclusive), or None without valgrind.  The job is
    made as `wavemesh mesh` makes it: the CLI's own option parsing, api's initial triangulation,
    native's fixed-point parameters (HeightField.refiner_zeta for quantised input)."""
    import shlex
    import shutil

    if shutil.which("valgrind") is None:
        return None
    import refiner_instructions as RI  # its callgrind runs and the CLI's job (cli_input)
    from wavemesh.refine import native

    file, opts = CASES[name]
    inp = tmp / "native.bin"
    RI.cli_input(shlex.join([file if file == "JACKSBORO" else str(tmp / file), *opts]), inp)
    runner = native.build(targets=("wm_run",)) / "wm_run"  # the release build the host's library is in
    profile = tmp / "native.cg"
    _, tris = RI.measure(runner, inp, tmp / "native.out", profile)
    return RI.phases(profile)["refiner"], tris  # the refiner's own, not the runner's start and file I/O


def run() -> dict:
    from peers import code_state
    from wavemesh.harness.simboard import SimBoard, build, host_timeouts

    code = code_state()  # the work tree is shared: what the firmware was built from
    exe, fw = build.build_sim(), build.build_firmware()
    board = SimBoard(exe, fw, "--port", "0", "--fast", "--quiet")
    try:
        # longer waits than the tests' (a benchmark runs at nice 19 beside other work, where the simulator
        # may get a tenth of a core): no device cycle depends on them
        with host_timeouts(sync=20.0, reply=60.0, ack=30.0, job=3600.0), tempfile.TemporaryDirectory() as tmp:
            _inputs(Path(tmp))
            cases = [_case(board, name, Path(tmp)) for name in CASES]
            for c in cases:
                if "error" not in c:
                    ins, tris = _native_instructions(c["name"], Path(tmp)) or (None, None)
                    # the same job, natively: its mesh must have the board's triangle count
                    c["native_instructions"] = ins if tris == c["output_triangles"] else None
                    c["native_triangles"] = tris
    finally:
        board.stop()
    sim = board.summary()
    from wavemesh.device import soc_cpu

    return {"budget": {"per_sample": PER_SAMPLE, "per_output_triangle": PER_TRIANGLE}, "cases": cases,
            "simulator": sim, "code": code, "cpu": soc_cpu.selected().name}


# The budget's own inputs, run for real (`make bench-soc-full`, `bench_soc.py --full [NAME ...]`): each at
# least 5,000 samples and whole, `wavemesh stream`'s defaults but Jacksboro's key and zeta (the issue's demo
# job, 10 m).  Long simulations, so not part of `make bench-soc`; every finished
# case is merged into FULL_RESULTS at once (a run cut short keeps what it measured), and the section of
# docs/benchmarks.md is rewritten from it.  name -> (input, options of `wavemesh stream` and `wavemesh mesh`)
FULL = {
    "Ball 256 x 256": ("ball.npy", []),
    "Box 256 x 256": ("box.npy", []),
    "Jacksboro, whole": ("JACKSBORO", ["--key", "elevation", "--zeta", "10"]),
    # held out: never looked at while cutting cycles (bench/datasets.py's held-out DEM and range image)
    "lidar_dem, whole (held out)": ("lidar.npy", []),
    "motorcycle, whole (held out)": ("motorcycle.npy", []),
}
FULL_HELD_OUT = tuple(n for n in FULL if n.endswith(HELD_OUT_MARK))
FULL_RESULTS = BENCH / "results" / "soc-full.json"
FULL_JOB_TIMEOUT = 6 * 3600.0  # s the device may compute without a frame (a level of a whole DEM: minutes)
PROGRESS_S = 60.0  # seconds between progress lines of a full case


def _measured_commit() -> str | None:
    """The last commit that changed what a board job runs (host/, firmware/, rtl/, sim/): unlike HEAD it
    stays the same when a branch that only changes benchmarks is rebased."""
    import subprocess

    r = subprocess.run(["git", "log", "-1", "--format=%h", "--", "host", "firmware", "rtl", "sim"], cwd=ROOT,
                       capture_output=True, text=True)
    return r.stdout.strip() or None if r.returncode == 0 else None


def _merge(path: Path, case: dict, lock_path: Path = ROOT / "build" / "soc-full.lock") -> dict:
    """Puts one finished case into the full results file (under a lock, in build/ which is not committed:
    two runs may share the file); the cases in FULL's order."""
    import fcntl
    import json

    path.parent.mkdir(parents=True, exist_ok=True)
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        data = json.loads(path.read_text()) if path.exists() else {}
        data["budget"] = {"per_sample": PER_SAMPLE, "per_output_triangle": PER_TRIANGLE}
        cases = {c["name"]: c for c in data.get("cases", [])}
        cases[case["name"]] = case
        order = list(FULL)
        data["cases"] = sorted(cases.values(), key=lambda c: order.index(c["name"]) if c["name"] in order
                               else len(order))
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(data, indent=1) + "\n")
        tmp.replace(path)
    return data


def run_full(names: list[str], results: Path = FULL_RESULTS) -> int:
    """Streams the named FULL cases through the simulated board one after another (a fresh simulator
    each, so its summary line is the case's), prints progress every PROGRESS_S seconds and merges each
    finished case into `results`.  The simulator and the firmware image are copies made at the start:
    the run outlasts other work in the tree that rebuilds them.  Returns the number of failed cases."""
    import datetime
    import platform
    import sys
    import threading

    import numpy as np
    from peers import code_state
    from wavemesh.device import soc_cpu
    from wavemesh.harness.simboard import SimBoard, build, host_timeouts

    code = {**code_state(), "measured": _measured_commit()}
    failed = 0
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        exe, fw = build.copies(tmp)
        files = {FULL[n][0] for n in names}
        import datasets
        from wavemesh.io.synth import ball, box

        for file, make in (("ball.npy", lambda: ball(256)), ("box.npy", lambda: box(256)),
                           ("lidar.npy", lambda: datasets.load("lidar_dem").values),
                           ("motorcycle.npy", lambda: datasets.load("motorcycle").values)):
            if file in files:
                np.save(tmp / file, make())
        # long waits for a loaded machine (no device cycle depends on them)
        with host_timeouts(sync=20.0, reply=120.0, ack=120.0, job=FULL_JOB_TIMEOUT):
            for name in names:
                board = SimBoard(exe, fw, "--port", "0", "--fast", "--quiet", "--progress", str(PROGRESS_S))
                done = threading.Event()
                t0 = time.monotonic()

                def watch(board=board, done=done, name=name, t0=t0) -> None:
                    while not done.wait(PROGRESS_S):
                        last = [ln for ln in list(board.lines) if ln.startswith("wmsim: progress")]
                        # (sys.__stderr__: the in-process CLI runner captures sys.stdout and sys.stderr)
                        print(f"soc-full: {name}: {(time.monotonic() - t0) / 60:5.1f} min  "
                              f"{last[-1][7:] if last else '-'}", file=sys.__stderr__, flush=True)

                threading.Thread(target=watch, daemon=True).start()
                try:
                    c = _case(board, name, tmp, FULL[name])
                finally:
                    done.set()
                    board.stop()
                c.update(held_out=name in FULL_HELD_OUT, simulator=board.summary(), code=code,
                         cpu=soc_cpu.selected().name, date=datetime.date.today().isoformat(),
                         machine=f"{platform.machine()}, {platform.node()}")
                _merge(results, c)
                if results == FULL_RESULTS:
                    _write_doc()
                failed += "error" in c
                print(f"soc-full: {name}: " + (f"FAILED: {c['error']}" if "error" in c else
                      f"work {c['work_cycles']:,} / budget {c['budget_cycles']:,} = "
                      f"{c['work_vs_budget']:.2f} x, "
                      f"{c['output_triangles']:,} triangles, = mesh: {c['same_as_mesh']}, "
                      f"stream {c['wall_seconds'] / 60:.1f} min"), flush=True)
    return failed


def _table(cases: list[dict], per_sample: int, per_tri: int) -> list[str]:
    lines = [
        "| input | grid | samples | M | triangles (templates -> output) | receive | filter | template "
        "| refine | emit | link | work | budget | work / budget | work per sample | work per output triangle "
        "| board s | = `mesh` |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in cases:
        cy = c["cycles"]
        n, tris = c["width"] * c["height"], c["output_triangles"]
        budget = per_sample * n + per_tri * tris
        lines.append(
            f"| {c['name']} | {c['width']} x {c['height']} | {n:,} | {c['levels']} "
            f"| {c['initial_triangles']} -> {tris} "
            + "".join(f"| {cy[k]:,} " for k in STAGES)
            + f"| {c['work_cycles']:,} | {budget:,} | {c['work_cycles'] / budget:.2f} x "
            f"| {c['work_cycles'] / n:,.0f} | {c['work_cycles'] / tris:,.0f} | {c['board_seconds']:.2f} "
            f"| {'yes' if c['same_as_mesh'] else 'NO'} |")
    return lines


def markdown(results: dict) -> str:
    from peers import code_line

    per_sample = results["budget"]["per_sample"]
    per_tri = results["budget"]["per_output_triangle"]
    cases = [c for c in results["cases"] if "error" not in c]
    tuned = [c for c in cases if c["name"] not in HELD_OUT]
    held = [c for c in cases if c["name"] in HELD_OUT]
    clk = cases[0]["clk_hz"] if cases else 25_000_000
    lines = [
        "`wavemesh stream` through the simulated board (Verilator model of soc_top: "
        f"{results.get('cpu', 'picorv32')} + firmware + FPGA stage with the triangle error engine, "
        "docs/soc.md) in fast UART mode; device cycles per stage from `--report` (`device_cycles`).  "
        "Inputs: wavemesh.io.synth's Ball and Box at 256 x 256 with `--decimate 8`, matplotlib's Jacksboro "
        "DEM "
        "(`--key elevation --decimate 16 --zeta 15`, metres); held out (never used while cutting cycles) "
        "and reported apart, the lidar DEM of bench/datasets.py (400 x 400, as .npy: grid steps) with "
        "`--decimate 8`; other options "
        "`wavemesh stream`'s defaults.  " + code_line(results.get("code")),
        "",
        f"**Budget: work cycles <= {per_sample} x input samples + {per_tri:,} x output triangles**, where "
        "*work* is the whole job's filter, template, refine and emit stages (receive and link excluded); "
        "*work / budget* at most 1.00 x meets it.  The simulated clock is the board's, "
        f"{clk / 1e6:g} MHz: 1,000,000 cycles = {1e6 / clk * 1e3:g} ms on a board.",
        "",
        *_table(tuned, per_sample, per_tri),
        "",
    ]
    if held:
        lines += ["Held out:", "", *_table(held, per_sample, per_tri), ""]
    for c in results["cases"]:
        if "error" in c:
            lines += [f"{c['name']}: the run failed: `{(c['error'] or '?').splitlines()[-1]}`", ""]
    lines += [
        "*filter* is the FPGA stage (about 1.4 cycles per sample, its registers and the wait for it); "
        "*template* counts the triangles from the stage's output and builds the initial triangulation on "
        f"the CPU; *refine* is the refiner on the {results.get('cpu', 'picorv32')} "
        "(`make bench-soc CPU=...`, docs/soc.md, \"The CPU\"; its storage cleared, set up, level by level; "
        "its triangle scans on the engine); *emit* builds each level stream once (header, vertices, "
        "triangles, CRC-32).  These four, *work*, count no link I/O and depend only on the job: a second "
        "run, the pin-accurate UART mode or a loaded host give the same numbers (docs/soc.md, \"Cycle "
        "accounting\"; tests/sim/test_stream_board.py compares with `==`).  *link* is the job's link "
        "I/O (PROGRESS frames, framing and writing the level streams, waiting for ACKs) and *receive* the "
        "upload: fast-mode figures here (bytes go straight into and out of the UART FIFOs), which "
        f"depend on the host; on a board the {BAUD} baud line ({10 * round(clk / BAUD):,} cycles per byte) "
        "sets their pace.  "
        "*board s* = all six stages / clock.  *triangles*: the initial triangulation's, the templates' "
        "(`initial.triangles` of `--report`, as `wavemesh mesh`'s: DONE states it), then the output mesh's.  "
        "*= `mesh`*: the board's mesh file equals `wavemesh mesh`'s "
        "byte for byte.  The counts are those of this firmware image: moving code (any change to the "
        "firmware) can shift them by about 1 % (docs/soc.md, \"Cycle accounting\").",
        "",
    ]
    lines += full_markdown(_load_full())
    lines += [
        "**The upload and the algorithm's share, per output triangle** (the decimated cases): *receive* "
        f"alone, in fast mode and on a board at {BAUD} baud (the upload's bytes x 10 bits at the board's "
        "clock); and the refiner's job natively (*native*: x86-64 instructions of the same job in "
        "tests/firmware/wm_run.c under callgrind, the C scan there), which says how much of the cost is the "
        "algorithm's work whatever the CPU, and the soft CPU's refine cycles per native instruction.",
        "",
        "| input | output triangles | receive per triangle (fast) | upload per triangle at "
        f"{BAUD} baud | native instructions per triangle | refine cycles per native instruction |",
        "|---|---|---|---|---|---|",
    ]
    for c in cases:
        n = c["output_triangles"]
        up = c.get("upload_bytes")
        on_board = f"{up * 10 / BAUD * clk / n:,.0f}" if up else "-"
        ins = c.get("native_instructions")
        other = c.get("native_triangles")
        native = (f"{ins / n:,.0f} | {c['cycles']['refine'] / ins:.1f}" if ins else
                  f"not the same job ({other} triangles) | -" if other else "- | -")
        lines.append(f"| {c['name']} | {n} | {c['cycles']['receive'] / n:,.0f} | {on_board} | {native} |")
    lines += [
        "",
        "Refiner cycles per level (level: output triangles, splits, swaps, cycles):",
        "",
    ]
    for c in cases:
        per = "; ".join(f"{lv['level']}: {lv['triangles']}, {lv['splits']}, {lv['swaps']}, "
                        f"{lv['device_cycles']:,}" for lv in c["refiner_levels"])
        link = c["link_bytes"] * 10 / BAUD
        lines.append(f"- {c['name']}: {per}.  Link: {c['link_bytes']} bytes both ways, "
                     f"{link:.2f} s at {BAUD} baud.")
    sim = results.get("simulator") or {}
    if sim:
        lines += ["", f"Simulator: {sim['cycles']:,} cycles in {sim['wall_seconds']:.0f} s of wall time "
                      f"({sim['rate_khz']:,} kHz, about 1/{clk / 1e3 / sim['rate_khz']:.0f} of the board)."]
    return "\n".join(lines) + "\n"


def _load_full(path: Path = FULL_RESULTS) -> dict | None:
    import json

    return json.loads(path.read_text()) if path.exists() else None


def _write_doc() -> None:
    """docs/benchmarks.md again from every results file (bench/run.py's), this section with the full cases."""
    import importlib

    importlib.import_module("run").write_doc()


def _full_table(cases: list[dict]) -> list[str]:
    lines = [
        "| input | grid | samples | options | triangles (templates -> output) | filter | template | refine "
        "| emit | work | budget | work / budget | work per sample | work per output triangle | board s "
        "| simulation | = `mesh` |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in cases:
        cy = c["cycles"]
        sim = c.get("simulator") or {}
        simt = f"{sim['wall_seconds'] / 60:.1f} min ({sim['rate_khz']:,} kHz)" if sim else "-"
        opts = f"`{' '.join(c['options'])}`" if c["options"] else "defaults"
        lines.append(
            f"| {c['name']} | {c['width']} x {c['height']} | {c['samples']:,} | {opts} "
            f"| {c['initial_triangles']:,} -> {c['output_triangles']:,} "
            + "".join(f"| {cy[k] / 1e6:,.1f} M " for k in WORK)
            + f"| {c['work_cycles'] / 1e6:,.1f} M | {c['budget_cycles'] / 1e6:,.1f} M "
            f"| {c['work_vs_budget']:.2f} x "
            f"| {c['work_cycles_per_sample']:,.0f} | {c['work_cycles_per_triangle']:,.0f} "
            f"| {c['board_seconds']:.1f} | {simt} | {'yes' if c['same_as_mesh'] else 'NO'} |")
    return lines


def full_markdown(data: dict | None) -> list[str]:
    """The budget's own inputs (`make bench-soc-full`'s results) as lines of docs/benchmarks.md."""
    lines = [
        "**The budget's own inputs** (`make bench-soc-full`: `bench/bench_soc.py --full [NAME ...]`, results "
        "in bench/results/soc-full.json; minutes to an hour of simulation each, not part of "
        "`make bench-soc`): each at least 5,000 samples and whole, streamed and compared as above with "
        "`wavemesh stream`'s defaults (the normal metric, zeta 1 height unit, M = log2(max(W, H)) - 3), "
        "but the whole Jacksboro DEM with `--key elevation --zeta 10` (metres; the issue's demo job); held "
        "out and reported apart, bench/datasets.py's lidar DEM (400 x 400) and Motorcycle range image "
        "(Middlebury's ground-truth disparity, unknown pixels filled with the nearest known one, 741 x 500), "
        "both as .npy (grid steps).  Cycles in millions; *simulation*: the simulator's own wall time for "
        "the case, beside other work on a shared machine.",
        "",
    ]
    cases = [c for c in (data or {}).get("cases", []) if "error" not in c]
    run = {c["name"] for c in (data or {}).get("cases", [])}
    if cases:
        codes = sorted({(c.get("code") or {}).get("measured") or "?" for c in cases})
        dates = sorted({c.get("date", "?") for c in cases})
        lines[-2] += (f"  Run {', '.join(dates)}; code measured: commit{'s' * (len(codes) > 1)} "
                      f"{', '.join(codes)} (the last change to host/, firmware/, rtl/ or sim/), "
                      f"{cases[0].get('cpu', '?')}.")
        tuned = [c for c in cases if not c.get("held_out")]
        held = [c for c in cases if c.get("held_out")]
        if tuned:
            lines += [*_full_table(tuned), ""]
        if held:
            lines += ["Held out:", "", *_full_table(held), ""]
    for c in (data or {}).get("cases", []):
        if "error" in c:
            lines += [f"{c['name']}: the run failed: `{(c['error'] or '?').splitlines()[-1]}`", ""]
    missing = [n for n in FULL if n not in run]
    if missing:
        lines += ["Not run yet: " + "; ".join(missing) + ".", ""]
    return lines


def full_case(arg: str) -> str | None:
    """The FULL case named by `arg`: its name or the name's first word, in any case (ball, jacksboro)."""
    for name in FULL:
        if arg.lower() in (name.lower(), name.split()[0].rstrip(",").lower()):
            return name
    return None


def main(argv: list[str] | None = None) -> int:
    import argparse
    import sys

    ap = argparse.ArgumentParser(description="The whole job on the simulated board; --full: the budget's "
                                 "own inputs (make bench-soc-full).  Without --full: run `make bench-soc`.")
    ap.add_argument("--full", nargs="*", metavar="NAME",
                    help=f"run these cases of FULL (default all: {'; '.join(FULL)}; a name or its first "
                         "word: ball, jacksboro), merge each into bench/results/soc-full.json and rewrite "
                         "docs/benchmarks.md")
    ap.add_argument("--out", type=Path, default=None, metavar="FILE",
                    help="merge into FILE instead (docs/benchmarks.md then left alone): a trial run")
    args = ap.parse_args(argv)
    if args.full is None:
        ap.error("give --full [NAME ...] (the decimated cases: make bench-soc)")
    names, unknown = [], []
    for arg in args.full or list(FULL):
        name = full_case(arg)
        (names if name else unknown).append(name or arg)
    if unknown:
        ap.error(f"unknown case {', '.join(unknown)}; have: {'; '.join(FULL)}")
    out = args.out.resolve() if args.out else FULL_RESULTS
    failed = run_full(names, out)
    print(f"soc-full: {len(names) - failed} of {len(names)} cases done; results in {out}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    import sys

    sys.path.insert(0, str(BENCH))
    sys.exit(main())
