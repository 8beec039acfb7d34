#!/usr/bin/env python3
"""Whole processes in instructions: `wavemesh mesh` against the quality benchmark's peer process.

    .venv/bin/python bench/process_instructions.py [GRID:LABEL ...]   (GRID:2048^2: bench_big.py's grid)

For pairs of the quality benchmark (bench/bench_quality.py's grids and errors; default: four of the
tuning set and three held out, reported apart), the grid saved as .npy, then each process run once under
`valgrind --tool=callgrind`: `wavemesh mesh IN.npy -o x.obj --metric vertical --zeta E --workers 1` and
the peer process (bench/peers.py: load the .npy, run pydelatin, write an OBJ), as `make bench-quality`
times them (`--workers 1`: a tiled grid's tiles in the one process, every instruction of the job
counted).  Instructions (every thread's) do not depend on the machine's load, unlike the benchmark's
wall times, so the process/process ratio can be read on a shared machine.  Then where the processes'
start-up goes: `import numpy` (both), wavemesh's own imports (`wavemesh.cli` over numpy) and pydelatin's
(over numpy).  Needs valgrind.
"""

from __future__ import annotations

import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import bench_quality as Q  # bench/ is on the path: this script's folder
import datasets as D
import numpy as np
import peers as P

PAIRS = ("f1:1%", "ball:1%", "mri:1%", "jacksboro:10 m", "topobathy:1%", "lidar_dem:1%", "motorcycle:1%")


def instructions(argv: list[str]) -> int:
    """The instructions callgrind counts for the process argv (every thread)."""
    r = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", *argv],
                       capture_output=True, text=True)
    m = re.search(r"Collected : (\d+)", r.stderr)
    if r.returncode != 0 or m is None:
        raise SystemExit(f"error: callgrind failed on {' '.join(argv[:3])} ...: {r.stderr.strip()[-300:]}")
    return int(m.group(1))


def pair(spec: str, tmp: Path) -> dict:
    name, _, label = spec.partition(":")
    if label.endswith("^2") and label[:-2].isdigit():  # NAME:2048^2: bench_big.py's grid and error
        import bench_big as B

        values, _ = B.make_grid(name, int(label[:-2]))
        zeta, held = B.zeta_of(values), name in B.HELD_OUT
    else:
        grid = D.load(name)
        zeta = dict(Q.zetas(grid)).get(label)
        if zeta is None:
            have = ", ".join(dict(Q.zetas(grid)))
            raise SystemExit(f"error: {spec}: no such error for {name}; have {have}")
        values, held = grid.values, name in Q.HELD_OUT
    npy = tmp / f"{name}.npy"
    np.save(npy, values)
    # --workers 1: a grid of 2048^2 samples and more is tiled by default; its tiles then run in this one
    # process (the same mesh): callgrind counts every instruction of the job (a forked worker's own count
    # would start from the parent's at the fork)
    wm = instructions(P.wavemesh_argv(str(npy), zeta, str(tmp / "wm.obj")) + ["--workers", "1"])
    pd = instructions(P.peer_argv(str(npy), zeta, str(tmp / "pd.obj")))
    return {"pair": f"{name} {label}", "held_out": held, "wavemesh": wm, "pydelatin": pd}


def main(argv: list[str]) -> int:
    P.compile_wavemesh()  # the processes run from byte code, as pydelatin's do
    py = sys.executable
    with tempfile.TemporaryDirectory() as t:
        rows = [pair(spec, Path(t)) for spec in (argv or PAIRS)]
    print("| pair | wavemesh mesh | peer process | ratio |\n|---|---|---|---|")
    for held in (False, True):
        part = [r for r in rows if r["held_out"] == held]
        if held and part:
            print("| **held out** | | | |")
        for r in part:
            print(f"| {r['pair']} | {r['wavemesh'] / 1e6:.0f}M | {r['pydelatin'] / 1e6:.0f}M | "
                  f"{r['wavemesh'] / r['pydelatin']:.3f} |")
        if part:
            med = statistics.median(r["wavemesh"] / r["pydelatin"] for r in part)
            print(f"| median ({'held out' if held else 'tuning'}) | | | {med:.3f} |")
    base = instructions([py, "-c", "import numpy"])
    wm = instructions([py, "-c", "import numpy; import wavemesh.cli"]) - base
    pd = instructions([py, "-c", "import numpy; import pydelatin"]) - base
    print(f"\nstart-up: `import numpy` {base / 1e6:.0f}M (both processes, the interpreter's start included); "
          f"over it wavemesh's imports {wm / 1e6:.0f}M, pydelatin's {pd / 1e6:.0f}M")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
