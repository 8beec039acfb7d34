"""Fault campaign: `wavemesh stream` of a big job through a proxy that corrupts, drops, duplicates and
delays bytes both ways, with the host's default timeouts, against the native stand-in device.

The job: a 200 x 200 crop of the Jacksboro DEM at full resolution, zeta 4 m: 25,001 triangles in the
final level, some 260 KB of level streams down and 28 KB up (samples, ACKs).  The device (wmdev) runs
paced like the board's UART at 115200 baud, so that a run's fault-free time is a line's and not a
socket's: an injected delay holds the line for up to 0.3 s whatever its rate, and on a socket the
delays alone (some 20 s a run at 0.2 %) are twenty times the fault-free second.  A smaller set on the
unpaced socket shows that floor.  Each run (wavemesh.harness.faultproxy.campaign) ends identical (the
very file `wavemesh mesh` writes), with a clear error (exit 2, one `error:` line and a hint, no
output), silently different, unclear (anything else) or hung (past the set's run limit).

The sets run at once, dealt to processes that each have a device of their own (`make bench-faults`; the short
seeded version is tests/sim/test_stream_faults.py).  Bars: at 0.2 % both ways (delays among the faults)
at least 95 % identical, 0 different, 0 hangs, the slowest run at most 5 x the fault-free time; at 1 %
with --deadline, no run past the deadline and every failure one clear line.
"""

from __future__ import annotations

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
DEADLINE = 300  # s: --deadline of the 1 % set
GRACE = 5.0  # s past the deadline that still counts as "at the deadline" (the process's own ending)
# (name, device baud (0: socket speed), fault rate per byte and direction, runs, first seed, extra options,
# shards: processes the runs are dealt to, each with a device of its own)
SETS = [
    ("fault-free, 115200 baud", UART, 0.0, 3, 0, [], 1),
    ("0.2 %, 115200 baud", UART, 0.002, 20, 2000, [], 3),
    (f"1 %, 115200 baud, --deadline {DEADLINE}", UART, 0.01, 6, 4000, ["--deadline", str(DEADLINE)], 3),
    ("fault-free, socket", 0, 0.0, 3, 0, [], 1),
    ("0.2 %, socket", 0, 0.002, 5, 6000, [], 1),
]
RUN_LIMIT = 900.0  # s: longer counts as a hang


def _one_set(index: int, shard: int, out: Path) -> None:
    """Runs shard `shard` of SETS[index] (every shards-th run) against a device of its own; its runs as
    JSON into out."""
    from wavemesh import cli
    from wavemesh.harness import jacksboro
    from wavemesh.harness.faultproxy import Faults, campaign
    from wavemesh.harness.nativedev import NativeDevice, build_wmdev

    name, baud, rate, runs, seed, extra, shards = SETS[index]
    dev = NativeDevice(build_wmdev(), *DEVICE, *(["--baud", str(baud)] if baud else []))
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            src = Path(jacksboro())
            ref = work / "ref.obj"
            if cli.main(["mesh", str(src), *OPTS, "-o", str(ref), "-q"]) != 0:
                raise RuntimeError("wavemesh mesh failed")
            faults = [Faults(seed=seed + s, rate=rate, limit=None) for s in range(shard, runs, shards)]
            done = campaign(("127.0.0.1", dev.port), src, [*OPTS, *extra], ref, faults, work, RUN_LIMIT,
                            on_run=lambda r: print(f"bench faults: {name}: {r.outcome} {r.seconds:.1f} s "
                                                   f"{r.message}", flush=True))
    finally:
        dev.stop()
    out.write_text(json.dumps([{"seed": r.faults.seed, "outcome": r.outcome, "seconds": round(r.seconds, 3),
                                "faults": r.injected, "frames": r.frames, "delay_s": round(r.delay_s, 3),
                                "message": r.message} for r in done]))


def run() -> dict:
    import numpy as np
    from wavemesh.harness import jacksboro
    from wavemesh.harness.faultproxy import OUTCOMES

    with tempfile.TemporaryDirectory() as tmp:
        procs = []
        for i, s in enumerate(SETS):
            for k in range(s[-1]):
                out = Path(tmp) / f"set{i}-{k}.json"
                procs.append((i, out, subprocess.Popen([sys.executable, __file__, "--set", str(i), str(k),
                                                        str(out)])))
        for i, _, proc in procs:
            if proc.wait() != 0:
                raise RuntimeError(f"set {SETS[i][0]!r} failed ({proc.returncode})")
        sets = []
        for i, s in enumerate(SETS):
            runs = sorted((r for j, out, _ in procs if j == i for r in json.loads(out.read_text())),
                          key=lambda r: r["seed"])
            name, baud, rate, _, _, extra, _ = s
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
    h, w = np.load(jacksboro())["elevation"][:200, :200].shape
    return {"commit": _commit(), "input": f"Jacksboro DEM, {w} x {h} crop, zeta 4 m",
            "options": OPTS, "deadline": DEADLINE, "sets": sets}


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
    base = {s["baud"]: s["median_s"] for s in sets if s["rate"] == 0}
    lines = [
        f"Code measured: {results.get('commit', 'not recorded')}.",
        "",
        f"`wavemesh stream` of the {results['input']} (`{' '.join(results['options'])}`; 25,001 triangles) "
        "through wavemesh.harness.faultproxy to the native stand-in device, with the host's default "
        "timeouts.  Faults per byte and direction, no bound (as on a real lossy line), a quarter each "
        "corrupted bytes, dropped runs of 1-64 bytes, duplicated runs and delays of up to 0.3 s that hold "
        "the line at the byte they strike.  *x fault-free*: the slowest run over the median fault-free run "
        "of the same device; *delays*: the most that the injected delays held the line in one run.",
        "",
        "| set | runs | frames | faults | identical | clear error | different | unclear | hang | median "
        "| slowest | x fault-free | delays |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in sets:
        o = s["outcomes"]
        ratio = s["slowest_s"] / base[s["baud"]] if base.get(s["baud"]) else 0.0
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
              f"{lossy['slowest_s'] / base[lossy['baud']]:.1f} x the fault-free time (the bar: at most "
              "5 x).  "
              f"At 1 % with --deadline {results['deadline']}: {len(late)} runs past the deadline, "
              f"{unclear} runs that ended otherwise than identical or with one clear error line.  On the "
              "socket the delays alone hold the line for many times the fault-free second, so its ratio "
              "measures them, not the protocol."]
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
