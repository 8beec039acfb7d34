"""Fault campaign: `wavemesh stream` of a big job through a proxy that corrupts, drops, duplicates and
delays bytes both ways, with the host's default timeouts, against the native stand-in device, and of a
small job against the pin-accurate simulated board switched to 3 Mbaud.

The job: a 200 x 200 crop of the Jacksboro DEM at full resolution, zeta 4 m: 24,751 triangles in the
final level, some 260 KB of level streams down and 28 KB up (samples, ACKs).  The device (wmdev) runs
paced like the board's UART at 115200 baud, so that a run's fault-free time is a line's and not a
socket's: an injected delay holds the line for up to 0.3 s whatever its rate, and on a socket the delays
alone (some 20 s a run at 0.2 %) are twenty times the fault-free second.  A smaller set on the unpaced
socket shows that floor.  The 3 Mbaud sets: wmdev paced at 115200 baud and switched by the host
(`--link-baud 3000000`), and the simulated board (wmsim without --fast: every byte bit by bit over the
UART pins, the upload block in the path) switched to the rate `--link-baud auto` takes on it, 3 Mbaud
(divisor 13 at 39 MHz), with a job it finishes in seconds of simulation (BOARD_OPTS: a 64 x 64 crop, the
template stage alone; the simulator runs about a hundredth of the board's speed on a loaded machine) and
the host's timeouts for the simulator (harness.simboard.SIM_TIMEOUTS).  A fault that hits the switch
leaves the job at the start rate with one warning line (the run still counts by its mesh).  Each run
(wavemesh.harness.faultproxy.campaign) ends identical (the very file `wavemesh mesh` writes), with a
clear error (exit 2, one `error:` line and a hint, no output), silently different, unclear (anything
else) or hung (past the set's run limit).  On the board one more run, not faulted at random: the switch
fails (a line model passes frames only while the board runs at the host's start rate, and the host's port
never leaves it), the board goes back by itself after its probe window, the host says so in one warning
line and the job runs at 115200 baud.

The sets run at once, dealt to processes that each have a device of their own (`make bench-faults`;
`python bench/bench_faults.py --board` runs the simulated board's sets and its failed switch alone and
puts them into bench/results/faults.json beside the other sets' results, with the commit each part
measured; the short seeded version is tests/sim/test_stream_faults.py, and
tests/sim/test_stream_board_3mbaud.py on the board).  Bars: at 0.2 % both ways (delays among the faults)
at least 95 % identical, 0 different, 0 hangs, the slowest run at most 5 x the fault-free time; at 1 %
with --deadline, no run past the deadline and every failure one clear line.
"""

from __future__ import annotations

import contextlib
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

TITLE = "Fault campaign (wavemesh stream through a fault-injecting proxy)"
OPTS = ["--key", "elevation", "--crop", "0,0,200,200", "--zeta", "4"]
DEVICE = ["--tri-capacity", "200000", "--quiet"]
UART = 115200
LINK_3M = ["--link-baud", "3000000"]
# the board: the rate `--link-baud auto` takes on it (3,000,000 exactly at 39 MHz: _board_rate)
BOARD_OPTS = ["--key", "elevation", "--crop", "0,0,64,64", "--zeta", "4", "--stage", "initial"]
DEADLINE = 300  # s: --deadline of the 1 % set
GRACE = 5.0  # s past the deadline that still counts as "at the deadline" (the process's own ending)
# (name, device baud (0: socket speed; "board": the pin-accurate simulated board), fault rate per byte
# and direction, runs, first seed, extra options, shards: processes the runs are dealt to, each with a
# device of its own)
SETS = [
    ("fault-free, 115200 baud", UART, 0.0, 3, 0, [], 1),
    ("0.2 %, 115200 baud", UART, 0.002, 20, 2000, [], 3),
    (f"1 %, 115200 baud, --deadline {DEADLINE}", UART, 0.01, 6, 4000, ["--deadline", str(DEADLINE)], 3),
    ("fault-free, socket", 0, 0.0, 3, 0, [], 1),
    ("0.2 %, socket", 0, 0.002, 5, 6000, [], 1),
    ("fault-free, 3 Mbaud", UART, 0.0, 3, 0, LINK_3M, 1),
    ("0.2 %, 3 Mbaud", UART, 0.002, 20, 3000, LINK_3M, 2),
    ("fault-free, board at 3 Mbaud", "board", 0.0, 2, 0, [], 1),
    ("0.2 %, board at 3 Mbaud", "board", 0.002, 20, 5000, [], 3),
]
RUN_LIMIT = 900.0  # s: longer counts as a hang


def _one_set(index: int, shard: int, out: Path) -> None:
    """Runs shard `shard` of SETS[index] (every shards-th run) against a device of its own; its runs as
    JSON into out."""
    from wavemesh import cli
    from wavemesh.harness import jacksboro
    from wavemesh.harness.faultproxy import Faults, campaign

    name, baud, rate, runs, seed, extra, shards = SETS[index]
    board = baud == "board"
    dev = _board() if board else _native(baud)
    opts = BOARD_OPTS if board else OPTS
    try:
        with tempfile.TemporaryDirectory() as tmp, _timeouts(board):
            work = Path(tmp)
            src = Path(jacksboro())
            ref = work / "ref.obj"
            if cli.main(["mesh", str(src), *opts, "-o", str(ref), "-q"]) != 0:
                raise RuntimeError("wavemesh mesh failed")
            if board:
                extra = ["--link-baud", str(_board_rate())]
            faults = [Faults(seed=seed + s, rate=rate, limit=None) for s in range(shard, runs, shards)]
            done = campaign(("127.0.0.1", dev.port), src, [*opts, *extra], ref, faults, work, RUN_LIMIT,
                            on_run=lambda r: print(f"bench faults: {name}: {r.outcome} {r.seconds:.1f} s "
                                                   f"{r.message}", flush=True, file=sys.__stdout__))
            # (sys.__stdout__: a hung run's thread keeps sys.stdout redirected, faultproxy.stream_once)
            rows = [{"seed": r.faults.seed, "outcome": r.outcome, "seconds": round(r.seconds, 3),
                     "faults": r.injected, "frames": r.frames, "delay_s": round(r.delay_s, 3),
                     "message": r.message} for r in done]
            if board and rate == 0 and shard == 0:
                # on a board that never switched: the one above keeps 3 Mbaud for BAUD_IDLE_MS after
                # each run (117 million cycles at 39 MHz, minutes of simulation), which a line at 115200
                # would not pass
                dev.stop()
                dev = _board()
                try:
                    rows.append(_failed_switch(dev, src, ref, work))
                except Exception as e:  # noqa: BLE001 - reported as the run's outcome, the sets go on
                    rows.append({"seed": -1, "outcome": "unclear", "seconds": 0.0, "faults": 0, "frames": 0,
                                 "delay_s": 0.0, "switch": True, "message": repr(e)[-300:]})
    finally:
        dev.stop()
    out.write_text(json.dumps(rows))


def _native(baud: int):
    from wavemesh.harness.nativedev import NativeDevice, build_wmdev

    return NativeDevice(build_wmdev(), *DEVICE, *(["--baud", str(baud)] if baud else []))


def _board():
    """The pin-accurate simulated board."""
    from wavemesh.harness.simboard import SimBoard, build

    return SimBoard(build.build_sim(), build.build_firmware(), "--port", "0")


def _timeouts(board: bool):
    """The host's timeouts for a set's runs: the simulated board's (harness.simboard.host_timeouts), else
    the defaults."""
    if not board:
        return contextlib.nullcontext()
    from wavemesh.harness.simboard import host_timeouts

    return host_timeouts()


def _board_rate() -> int:
    """The board's rate after the switch: what `--link-baud auto` takes on it, from the clock and the
    divisors its HELLO_REPLY states (memmap.py, protocol.COMMON_BAUDS; harness.simboard.fastest_rate)."""
    from wavemesh.harness.simboard import fastest_rate

    return fastest_rate()


def _failed_switch(board, src: Path, ref: Path, work: Path) -> dict:
    """`--link-baud` to the board's 3 Mbaud through a line that stays at the start rate: the host's
    port takes the new rate but the line never follows it, so nothing passes while the board runs at
    another rate (the OK to BAUD, sent at the old rate, excepted).  The host's proof fails, the board goes
    back after its probe window (BAUD_PROBE_MS of its clock, minutes of simulation: the host's HELLOs
    at the start rate are given that many tries), the host says so in one warning line, and the job runs
    at the start rate: the reference mesh, the report's line_baud the start rate."""
    import time

    from wavemesh.device import memmap
    from wavemesh.device import protocol as P
    from wavemesh.harness import run_cli
    from wavemesh.harness.faultproxy import FrameTap
    from wavemesh.harness.simboard import host_timeouts

    start = P.baud_divisor(memmap.CLK_HZ, UART)

    def on_frame(direction, f) -> bool:
        div = (board.events("uart divisor") or [(start, 0)])[-1][0]
        return div == start or (f.type == P.FrameType.OK and f.fields()["request"] == P.FrameType.BAUD)

    # the probe window is BAUD_PROBE_MS of the board's clock (39 million cycles at 39 MHz): minutes of
    # simulation alone, 10 or more beside the campaign's boards (40 kHz each on a loaded machine: 60 HELLOs
    # of 8 s were not enough); the run ends when it answers
    out = work / "switch.obj"
    with host_timeouts(sync_attempts=250), FrameTap(("127.0.0.1", board.port), on_frame) as tap:
        t0 = time.monotonic()
        rc, _, err = run_cli("stream", str(src), *BOARD_OPTS, "--link-baud", str(_board_rate()), "--port",
                             tap.url, "-o", str(out), "--report", str(work / "switch.json"), "-q")
        seconds = time.monotonic() - t0
    warnings = [ln for ln in err.splitlines() if ln.startswith("warning:")]
    back = [d for d, _ in board.events("uart divisor")]
    ok = (rc == 0 and out.exists() and out.read_bytes() == ref.read_bytes() and len(warnings) == 1
          and json.loads((work / "switch.json").read_text())["transfer"]["line_baud"]
          == P.divisor_baud(memmap.CLK_HZ, start)  # (115,385 at 39 MHz: the rate its divisor gives)
          and back[-2:] == [P.baud_divisor(memmap.CLK_HZ, _board_rate()), start])
    return {"seed": -1, "outcome": "identical" if ok else "different", "seconds": round(seconds, 3),
            "faults": 0, "frames": 0, "delay_s": 0.0, "switch": True,
            "message": warnings[0] if len(warnings) == 1 else err.strip()[-300:]}


def run(board_only: bool = False) -> dict:
    """Every set (`make bench-faults`), or with board_only the simulated board's sets and its failed
    switch alone (board()): the board's part of the results."""
    import numpy as np
    from wavemesh.harness import jacksboro

    chosen = [i for i, s in enumerate(SETS) if not board_only or s[1] == "board"]
    with tempfile.TemporaryDirectory() as tmp:
        procs = []
        for i in chosen:
            for k in range(SETS[i][-1]):
                out = Path(tmp) / f"set{i}-{k}.json"
                procs.append((i, out, subprocess.Popen([sys.executable, __file__, "--set", str(i), str(k),
                                                        str(out)])))
        for i, _, proc in procs:
            if proc.wait() != 0:
                raise RuntimeError(f"set {SETS[i][0]!r} failed ({proc.returncode})")
        sets, switch = summarise({i: [json.loads(out.read_text()) for j, out, _ in procs if j == i]
                                  for i in chosen})
    if board_only:
        return board_part(sets, switch, _commit())
    h, w = np.load(jacksboro())["elevation"][:200, :200].shape
    return {"commit": _commit(), "input": f"Jacksboro DEM, {w} x {h} crop, zeta 4 m",
            "options": OPTS, "board_options": BOARD_OPTS, "board_baud": _board_rate(),
            "board_clk_hz": _board_clk(), "deadline": DEADLINE, "sets": sets, "failed_switch": switch}


def summarise(shards: dict) -> tuple[list, dict | None]:
    """The sets' rows from their shards' runs ({index in SETS: [runs of each shard]}), and the failed
    switch's run (None when no shard ran it)."""
    from wavemesh.harness.faultproxy import OUTCOMES

    sets, switch = [], None
    for i, parts in sorted(shards.items()):
        runs = sorted((r for part in parts for r in part), key=lambda r: r["seed"])
        switch = next((r for r in runs if r.get("switch")), switch)
        runs = [r for r in runs if not r.get("switch")]
        name, baud, rate, _, _, extra, _ = SETS[i]
        outcomes = {k: sum(r["outcome"] == k for r in runs) for k in OUTCOMES}
        errors: dict = {}
        for r in runs:
            if r["outcome"] == "error":
                key = r["message"].split(":")[1].strip() if ":" in r["message"] else r["message"]
                errors[key] = errors.get(key, 0) + 1
        sets.append({"name": name, "baud": baud, "rate": rate, "options": extra, "runs": runs,
                     "outcomes": outcomes, "errors": errors,
                     "frames": sum(r["frames"] for r in runs), "faults": sum(r["faults"] for r in runs),
                     "median_s": statistics.median(r["seconds"] for r in runs),
                     "slowest_s": max(r["seconds"] for r in runs),
                     "delay_max_s": max(r["delay_s"] for r in runs)})
    return sets, switch


def board_part(sets: list, switch: dict | None, commit: str) -> dict:
    """The results' keys that the board's sets give (board()), with the commit and the day they ran."""
    import datetime

    return {"board_sets": sets, "failed_switch": switch, "board_commit": commit,
            "board_date": datetime.date.today().isoformat(), "board_options": BOARD_OPTS,
            "board_baud": _board_rate(), "board_clk_hz": _board_clk()}


def merge_board(results: dict, part: dict) -> dict:
    """results (a whole run's) with the board's sets and failed switch replaced by part's."""
    sets = [s for s in results["sets"] if s["baud"] != "board"] + part["board_sets"]
    order = {s[0]: i for i, s in enumerate(SETS)}
    sets.sort(key=lambda s: order.get(s["name"], len(SETS)))
    return {**results, **{k: v for k, v in part.items() if k != "board_sets"}, "sets": sets}


def board(path: Path) -> None:
    """Runs the board's sets and failed switch alone (the other sets need no simulator and keep their
    results) into the results file at path, and rebuilds docs/benchmarks.md (bench/run.py)."""
    import run as bench_run  # bench/run.py: this script's folder is on the path

    results = merge_board(json.loads(path.read_text()), run(board_only=True))
    path.write_text(json.dumps(results, indent=1) + "\n")
    bench_run.write_doc()


def _board_clk() -> int:
    from wavemesh.device import memmap

    return memmap.CLK_HZ


def _commit() -> str:
    """The commit measured, and whether the host or the device code differed from it."""
    root = Path(__file__).resolve().parents[1]
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                          text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "host/wavemesh", "firmware/board"],
                           cwd=root, capture_output=True, text=True).stdout.strip()
    return head + (" with uncommitted changes in host/wavemesh or firmware/board" if dirty else "")


def markdown(results: dict) -> str:
    sets = results["sets"]
    def line(s) -> tuple:  # a device and its rate: the fault-free runs the others are compared with
        return s["baud"], "--link-baud" in s["options"]

    from wavemesh.device import protocol as P

    base = {line(s): s["median_s"] for s in sets if s["rate"] == 0}
    # the board's clock when its sets ran (25 MHz before it was recorded)
    ack_cycles = P.ACK_TIMEOUT_MS * results.get("board_clk_hz", 25_000_000) // 1000
    measured = f"Code measured: {results.get('commit', 'not recorded')}"
    if "board_commit" in results:
        measured += (f"; the simulated board's sets and its failed switch again on {results['board_commit']} "
                     f"({results['board_date']}, `python bench/bench_faults.py --board`)")
    lines = [
        measured + ".",
        "",
        f"`wavemesh stream` of the {results['input']} (`{' '.join(results['options'])}`; 24,751 triangles) "
        "through wavemesh.harness.faultproxy to the native stand-in device, with the host's default "
        "timeouts.  Faults per byte and direction, no bound (as on a real lossy line), a quarter each "
        "corrupted bytes, dropped runs of 1-64 bytes, duplicated runs and delays of up to 0.3 s that hold "
        "the line at the byte they strike.  *x fault-free*: the slowest run over the median fault-free run "
        "of the same device at the same rate; *delays*: the most that the injected delays held the line in "
        "one run.  *3 Mbaud*: wmdev paced at 115200 baud and switched by the host (`--link-baud 3000000`); "
        "*board at 3 Mbaud*: the pin-accurate simulated board (every byte bit by bit over the UART pins, "
        "through the upload block) switched to the rate `--link-baud auto` takes on it (`--link-baud "
        f"{results.get('board_baud', 3000000)}`), with "
        f"`{' '.join(results.get('board_options', BOARD_OPTS))}` "
        "(what the simulator, at about a hundredth of the board's speed, runs in seconds) and the host's "
        "timeouts for the simulator (harness.simboard.SIM_TIMEOUTS; its seconds are the simulator's, "
        "not the board's).  A fault that hits the switch leaves a run at 115200 baud with one warning.",
        "",
        "| set | runs | frames | faults | identical | clear error | different | unclear | hang | median "
        "| slowest | x fault-free | delays |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in sets:
        o = s["outcomes"]
        ratio = s["slowest_s"] / base[line(s)] if base.get(line(s)) else 0.0
        lines.append(f"| {s['name']} | {len(s['runs'])} | {s['frames']} | {s['faults']} | {o['identical']} "
                     f"| {o['error']} | {o['different']} | {o['unclear']} | {o['hang']} "
                     f"| {s['median_s']:.1f} s | {s['slowest_s']:.1f} s | {ratio:.1f} "
                     f"| {s['delay_max_s']:.1f} s |")
    lossy = next(s for s in sets if s["rate"] == 0.002 and s["baud"])
    heavy = next(s for s in sets if s["rate"] == 0.01)
    share = lossy["outcomes"]["identical"] / len(lossy["runs"])
    late = [r for r in heavy["runs"] if r["seconds"] > results["deadline"] + GRACE]
    unclear = sum(heavy["outcomes"][k] for k in ("different", "unclear", "hang"))
    lo = lossy["outcomes"]
    lines += ["", f"At 0.2 % on the line at 115200 baud: {100 * share:.0f} % of the runs identical (the bar: "
              f"at least 95 %), {lo['different']} different, {lo['hang']} hung, the slowest "
              f"{lossy['slowest_s'] / base[line(lossy)]:.1f} x the fault-free time (the bar: at most "
              "5 x).  "
              f"At 1 % with --deadline {results['deadline']}: {len(late)} runs past the deadline, "
              f"{unclear} runs that ended otherwise than identical or with one clear error line.  On the "
              "socket the delays alone hold the line for many times the fault-free second, so its ratio "
              "measures them, not the protocol; so at 3 Mbaud (a fault-free run of a few seconds, some 40 s "
              "of delays in a run at 0.2 %).  On the simulated board a lost LEVEL_END, DONE or ACK waits out "
              f"the board's ACK_TIMEOUT_MS, {ack_cycles / 1e6:g} million cycles of its clock, a minute or "
              "more of simulation, or the host's keepalive interval for the simulator (SIM_TIMEOUTS."
              "keepalive, after which it asks with RESUME), whichever ends first: its ratio measures the "
              "simulator's speed."]
    for s in sets:
        if s["rate"] == 0.002 and s["name"] != lossy["name"] and s["baud"]:
            o = s["outcomes"]
            lines += ["", f"At {s['name']}: {100 * o['identical'] / len(s['runs']):.0f} % of the runs "
                      f"identical, {o['different']} different, {o['hang']} hung."]
    sw = results.get("failed_switch")
    if sw:
        lines += ["", "A failed switch on the board (the line stays at 115200 baud, the host's port "
                  "believes it switched; bench_faults._failed_switch): "
                  + ("the board went back by itself, the host said so in one line "
                     f"(`{sw['message']}`) and the job ran at 115200 baud, the reference mesh"
                     if sw["outcome"] == "identical" else f"NOT as it should: {sw['message']}")
                  + f", {sw['seconds']:.0f} s of simulation."]
    kinds: dict = {}
    for s in sets:
        for k, v in s["errors"].items():
            kinds[k] = kinds.get(k, 0) + v
    if kinds:
        lines += ["", "The clear errors, by message:", ""]
        lines += [f"- {v} x `{k}`" for k, v in sorted(kinds.items(), key=lambda kv: -kv[1])]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--set":
        _one_set(int(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[4]))
    elif sys.argv[1:] == ["--board"]:
        board(Path(__file__).resolve().parent / "results" / "faults.json")
    else:
        sys.exit("usage: bench_faults.py --board (the simulated board's sets alone; the whole bench: "
                 "make bench-faults)")
