#!/usr/bin/env python3
"""Run benchmarks and write bench/results/<name>.json and docs/benchmarks.md (`make bench`).

Each benchmark is a module bench/bench_<name>.py with

    TITLE = "..."                   # section heading in docs/benchmarks.md
    def run() -> dict               # measures; returns JSON-able results
    def markdown(results) -> str    # the section body for docs/benchmarks.md

`python bench/run.py [NAME ...]` runs the named ones (default: all but those with ``DEFAULT = False``,
runs of hours such as bench_board1024.py) and rebuilds docs/benchmarks.md from every results file
present, so one benchmark can be re-run without the others.  Benchmarks report; they
never fail on a number (speed targets are read from the document, not asserted).
"""

from __future__ import annotations

import datetime
import importlib
import json
import platform
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RESULTS = BENCH / "results"
DOC = ROOT / "docs" / "benchmarks.md"


def available() -> list[str]:
    return sorted(p.stem.removeprefix("bench_") for p in BENCH.glob("bench_*.py"))


def load(name: str):
    # bench/ is on the path as this script's folder: the benchmarks and their helpers import by name
    return importlib.import_module(f"bench_{name}")


def write_doc() -> None:
    parts = ["# Benchmarks", "", "Written by `make bench` (bench/run.py); raw numbers in bench/results/.", ""]
    for name in available():
        path = RESULTS / f"{name}.json"
        if not path.exists():
            continue
        data = json.loads(path.read_text())
        mod = load(name)
        parts += [f"## {mod.TITLE}", "", f"Run {data['_meta']['date']} on {data['_meta']['machine']}.", "",
                  mod.markdown(data).rstrip(), ""]
    DOC.write_text("\n".join(parts) + "\n")


def main(argv: list[str]) -> int:
    names = argv or [n for n in available() if getattr(load(n), "DEFAULT", True)]
    unknown = [n for n in names if n not in available()]
    if unknown:
        print(f"error: unknown benchmark {', '.join(unknown)}; have: {', '.join(available())}",
              file=sys.stderr)
        return 2
    RESULTS.mkdir(parents=True, exist_ok=True)
    for name in names:
        print(f"bench: {name} ...", flush=True)
        results = load(name).run()
        results["_meta"] = {"date": datetime.date.today().isoformat(),
                            "machine": f"{platform.machine()}, {platform.python_implementation()} "
                                       f"{platform.python_version()}"}
        (RESULTS / f"{name}.json").write_text(json.dumps(results, indent=1) + "\n")
    write_doc()
    print(f"bench: wrote {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
