"""Fuzzing campaign (issue 13): the libFuzzer harnesses of fuzz/ (refine, proto; clang, ASan + UBSan) and
the atheris harness of the readers, side by side, each for FUZZ_CPU CPU seconds (default 1200: one
CPU-hour in all), at the priority the benchmark was started with (`nice -n 19 make bench-fuzz` on a
shared machine).  Each starts from the corpus in the repository (fuzz/corpus/).  Reports executions,
coverage (libFuzzer's edges and features; atheris traces wavemesh's own Python only) and crashes; a crash's
input is kept in build/fuzz/findings/.
"""

from __future__ import annotations

import importlib.util
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


def run() -> dict:
    cpu = float(os.environ.get("FUZZ_CPU", "1200"))
    fuzz_run.build()
    results = fuzz_run.run(list(fuzz_run.TARGETS), None, cpu, [])
    for r in results:
        r["edges_total"] = _edges_total((ROOT / r["log"]).read_text(errors="replace"))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=ROOT).stdout.strip()
    return {"cpu_per_target": cpu, "commit": commit, "nice": os.nice(0), "targets": results}


def markdown(data: dict) -> str:
    rows = ["| harness | what it checks | CPU s | executions | exec/CPU s | coverage | corpus | crashes |",
            "|---|---|---|---|---|---|---|---|"]
    what = {
        "refine": "refiner on random grids and parameters: proper mesh after every level, E(T) <= zeta",
        "proto": "frame decoder and protocol engine with the native job: the device's frames well formed",
        "readers": "height-field and mesh readers: a valid result or one `error:` line, nothing on stderr",
    }
    total_cpu = total_exec = total_crash = 0
    for r in data["targets"]:
        of = f" of {r['edges_total']}" if r.get("edges_total") else ""
        cov = f"{r['cov']} edges{of}, {r['ft']} features"
        rate = r["execs"] / r["cpu_seconds"] if r["cpu_seconds"] else 0
        rows.append(f"| {r['target']} | {what.get(r['target'], '')} | {r['cpu_seconds']:.0f} | "
                    f"{r['execs']:,} | {rate:,.0f} | {cov} | {r['corpus']} | {r['crashes']} |")
        total_cpu += r["cpu_seconds"]
        total_exec += r["execs"]
        total_crash += r["crashes"]
    found = [f for r in data["targets"] for f in r["findings"]]
    short = [r["target"] for r in data["targets"]
             if r["cpu_seconds"] < 0.98 * data["cpu_per_target"] and not r["crashes"]]  # a crash stops one
    return "\n".join([
        f"On {data['commit']}, at nice {data['nice']}, a budget of {data['cpu_per_target']:.0f} CPU seconds "
        f"per harness (`FUZZ_CPU`)"
        + (f", stopped by hand before it was spent ({', '.join(short)}: at nice 19 the machine's other work "
           f"left them a fraction of a core)"
           if short else "")
        + f": {total_cpu / 3600:.2f} CPU hours in all, {total_exec:,} executions, "
        f"{total_crash} crash{'' if total_crash == 1 else 'es'}"
        + (f" ({', '.join(found)}: a harness stops at its first)" if found else "")
        + ".  Harnesses, corpus, checks and what the findings were: fuzz/README.md.",
        "",
        *rows,
        "",
        "Coverage counts what each harness instruments: for refine and proto the edges of the C code linked "
        "(the refiner, proto.c, the native job), for readers the branches of wavemesh's Python modules the "
        "readers import (atheris); GDAL, numpy and Pillow run untraced.",
    ])
