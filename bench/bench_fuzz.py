"""Fuzzing campaign: the libFuzzer harnesses of fuzz/ (refine, proto; clang, ASan + UBSan) and
the atheris harness of the readers, one after the other (one process at a time: at the priority the
benchmark was started with, `nice -n 19 make bench-fuzz`, it takes only the idle CPU of a shared
machine), each for FUZZ_CPU CPU seconds (default 1200: one CPU-hour in all).  Each starts from the
corpus in the repository (fuzz/corpus/) and from what earlier runs found (build/fuzz/corpus/).
Reports executions, coverage (libFuzzer's edges and features; atheris traces wavemesh's own Python
only) and crashes; a crash's input is kept in build/fuzz/findings/.

A campaign may take several parts: with FUZZ_RESUME=1 the run continues the one in
bench/results/fuzz.json, giving each harness what is left of that campaign's budget, and adds a part
(its commit, its numbers); the totals add the parts up.  A part stopped early (SIGINT to the fuzzer,
which prints its final statistics) keeps what it spent.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TITLE = "Fuzzing (make bench-fuzz)"

_spec = importlib.util.spec_from_file_location("wm_fuzz_run", ROOT / "fuzz" / "run.py")
fuzz_run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz_run)


def _edges_total(log: str) -> int:
    """Instrumented edges of a libFuzzer build ("Loaded 1 modules (N inline 8-bit counters)")."""
    m = re.search(r"\((\d+) inline 8-bit counters\)", log)
    return int(m.group(1)) if m else 0


def _parts(data: dict) -> list[dict]:
    """The campaign's parts (a results file from before parts existed is one part)."""
    if "parts" in data:
        return data["parts"]
    return [{k: data[k] for k in ("commit", "nice", "targets")}]


def spent(data: dict) -> dict[str, float]:
    """CPU seconds each harness has had in the campaign so far."""
    out = {t: 0.0 for t in fuzz_run.TARGETS}
    for part in _parts(data):
        for r in part["targets"]:
            out[r["target"]] = out.get(r["target"], 0.0) + r["cpu_seconds"]
    return out


def part(results: list[dict], commit: str, note: str = "") -> dict:
    for r in results:
        r["edges_total"] = _edges_total((ROOT / r["log"]).read_text(errors="replace"))
    return {"commit": commit, "nice": os.nice(0), "targets": results, **({"note": note} if note else {})}


def run() -> dict:
    cpu = float(os.environ.get("FUZZ_CPU", "1200"))
    old = ROOT / "bench" / "results" / "fuzz.json"
    data = {"cpu_per_target": cpu, "parts": []}
    if os.environ.get("FUZZ_RESUME") == "1" and old.exists():
        prev = json.loads(old.read_text())
        data = {"cpu_per_target": prev["cpu_per_target"], "parts": list(_parts(prev))}
    have = spent(data)
    fuzz_run.build()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=ROOT).stdout.strip()
    results = []
    for t in fuzz_run.TARGETS:  # one at a time
        left = data["cpu_per_target"] - have.get(t, 0.0)
        if left >= 1:
            results += fuzz_run.run([t], None, left, [])
    if results:
        data["parts"].append(part(results, commit))
    return data


def markdown(data: dict) -> str:
    parts = _parts(data)
    rows = ["| harness | what it checks | CPU s | executions | exec/CPU s | coverage (last part) | corpus "
            "| crashes |", "|---|---|---|---|---|---|---|---|"]
    what = {
        "refine": "refiner on random grids and parameters: proper mesh after every level, E(T) <= zeta",
        "proto": "frame decoder and protocol engine with the native job: the device's frames well formed",
        "readers": "height-field and mesh readers: a valid result or one `error:` line, nothing on stderr",
    }
    total_cpu = total_exec = total_crash = 0
    for t in fuzz_run.TARGETS:
        runs = [r for p in parts for r in p["targets"] if r["target"] == t]
        if not runs:
            continue
        cpu = sum(r["cpu_seconds"] for r in runs)
        execs = sum(r["execs"] for r in runs)
        crashes = sum(r["crashes"] for r in runs)
        last = runs[-1]
        of = f" of {last['edges_total']}" if last.get("edges_total") else ""
        rate = execs / cpu if cpu else 0
        rows.append(f"| {t} | {what.get(t, '')} | {cpu:.0f} | {execs:,} | {rate:,.0f} | "
                    f"{last['cov']} edges{of}, {last['ft']} features | {last['corpus']} | {crashes} |")
        total_cpu += cpu
        total_exec += execs
        total_crash += crashes
    found = [f for p in parts for r in p["targets"] for f in r["findings"]]
    lines = []
    for i, p in enumerate(parts, 1):
        bits = ", ".join(f"{r['target']} {r['cpu_seconds']:.0f} CPU s ({r['execs']:,} executions, "
                         f"{r['crashes']} crash{'' if r['crashes'] == 1 else 'es'})" for r in p["targets"])
        note = f"; {p['note']}" if p.get("note") else ""
        lines.append(f"{i}. on {p['commit']} at nice {p['nice']}: {bits}{note}")
    short = [t for t, c in spent(data).items() if c < 0.98 * data["cpu_per_target"]]
    return "\n".join([
        f"A budget of {data['cpu_per_target']:.0f} CPU seconds per harness (`FUZZ_CPU`), in {len(parts)} "
        f"part{'' if len(parts) == 1 else 's'}: {total_cpu / 3600:.2f} CPU hours in all, {total_exec:,} "
        f"executions, {total_crash} crash{'' if total_crash == 1 else 'es'}"
        + (f" ({', '.join(found)}: a harness stops at its first; fuzz/README.md says what each was and "
           f"how it was fixed)" if found else "")
        + (f".  Not spent yet: {', '.join(short)} (stopped by hand: at nice 19 the machine's other work "
           f"left a fraction of a core)" if short else "")
        + ".  Harnesses, corpus and checks: fuzz/README.md.",
        "",
        *rows,
        "",
        "Parts (`FUZZ_RESUME=1 nice -n 19 make bench-fuzz` adds one):",
        "",
        *lines,
        "",
        "Coverage counts what each harness instruments: for refine and proto the edges of the C code linked "
        "(the refiner, the protocol engine, the native job), for readers the branches of wavemesh's Python "
        "modules the readers import (atheris); GDAL, numpy and Pillow run untraced.",
    ])
