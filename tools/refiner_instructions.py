#!/usr/bin/env python3
"""The native refiner's instruction counts on fixed inputs, for cost work on firmware/src.

    .venv/bin/python tools/refiner_instructions.py [--runner BUILD/wm_run] [--base OTHER/wm_run]

Writes the C runner's inputs (firmware/tests/wm_run.c) for ten pairs of the quality benchmark's tuning
set (bench/bench_quality.py: its grids, its errors, --metric vertical, the defaults; never the held-out
grids), runs each under `valgrind --tool=callgrind` and prints the instructions and the output triangles
per pair and in all.  Instruction counts do not depend on the machine's load, unlike times, so a change
to the refiner can be measured on a shared machine.  With --base, the same for a second runner (e.g. a
build of the commit before) and the ratios.  Needs valgrind.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "host"), str(ROOT / "bench"), str(ROOT / "tests" / "firmware")]

PAIRS = (("jacksboro", "5 m"), ("jacksboro", "10 m"), ("mri", "1%"), ("mri", "5%"), ("f1", "1%"),
         ("f3", "2%"), ("f4", "0.5%"), ("f5", "0.5%"), ("ball", "1%"), ("box", "1%"))


def write_inputs(folder: Path) -> list[tuple[str, Path]]:
    import bench_quality as Q
    import datasets as D
    from fwio import write_input
    from wavemesh import api, native
    from wavemesh.haar import decompose
    from wavemesh.heightfield import from_array

    out = []
    for name, want in PAIRS:
        assert name not in Q.HELD_OUT, name
        grid = D.load(name)
        zeta = dict(Q.zetas(grid))[want]
        hf = from_array(grid.values)
        params = native.RefineParams(zeta=float(zeta), metric="vertical")
        job = api.triangulate(hf, None)
        fp = native.fixed_params(params, hf.scale)
        det = native.details_array(decompose(hf.samples, job.levels))
        path = folder / f"{name}-{len(out)}.bin"
        write_input(path, hf.samples, det, job.levels, job.mesh, fp, 2 * (hf.width - 1) * (hf.height - 1))
        out.append((f"{name} {want}", path))
    return out


def measure(runner: Path, inp: Path, out: Path) -> tuple[int, int]:
    """(instructions, output triangles) of one run."""
    cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", str(runner), str(inp), str(out)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    refs = int(re.search(r"refs:\s+([\d,]+)", res.stderr).group(1).replace(",", ""))
    last = [ln for ln in res.stdout.splitlines() if ln.startswith("level")][-1].split()
    return refs, int(last[3])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runner", type=Path, default=ROOT / "build" / "firmware-native" / "wm_run")
    ap.add_argument("--base", type=Path, help="a second wm_run to compare with")
    args = ap.parse_args(argv)
    if args.runner == ap.get_default("runner"):
        subprocess.run(["cmake", "-S", str(ROOT / "firmware"), "-B", str(args.runner.parent),
                        "-DCMAKE_BUILD_TYPE=Release"], check=True, capture_output=True)
        subprocess.run(["cmake", "--build", str(args.runner.parent), "-j2", "--target", "wm_run"], check=True,
                       capture_output=True)
    runners = [args.runner] + ([args.base] if args.base else [])
    with tempfile.TemporaryDirectory() as tmp:
        inputs = write_inputs(Path(tmp))
        head = "| pair | instructions | triangles |" + (" base instructions | base triangles | ratio |"
                                                         if args.base else "")
        print(head)
        print("|" + "---|" * (head.count("|") - 1))
        tot = [0, 0]
        for label, path in inputs:
            row = []
            for i, runner in enumerate(runners):
                ir, tris = measure(runner, path, Path(tmp) / f"out{i}.bin")
                tot[i] += ir
                row += [f"{ir:,}", str(tris)]
            if args.base:
                row.append(f"{int(row[0].replace(',', '')) / int(row[2].replace(',', '')):.3f}")
            print(f"| {label} | " + " | ".join(row) + " |")
        print(f"| all | {tot[0]:,} | |" + (f" {tot[1]:,} | | {tot[0] / tot[1]:.3f} |" if args.base else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
