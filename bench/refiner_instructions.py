#!/usr/bin/env python3
"""The native refiner's instruction counts on fixed inputs, for cost work on firmware/src.

    .venv/bin/python bench/refiner_instructions.py [--runner BUILD/wm_run] [--base OTHER/wm_run]
    .venv/bin/python bench/refiner_instructions.py --phases [--peer] [--set NAME=VALUE,...]
    .venv/bin/python bench/refiner_instructions.py --job 'INPUT [wavemesh mesh options]' ... [--phases]
                                                   [--routines N] [--scans]

Writes the C runner's inputs (tests/firmware/wm_run.c) for ten pairs of the quality benchmark's tuning
set (bench/bench_quality.py: its grids, its errors, --metric vertical, the defaults; never the held-out
grids), runs each under `valgrind --tool=callgrind` and prints the instructions and the output triangles
per pair and in all.  Instruction counts do not depend on the machine's load, unlike times, so a change
to the refiner can be measured on a shared machine.  With --base, the same for a second runner (e.g. a
build of the commit before) and the ratios.  Needs valgrind.

--phases splits each pair's instructions by phase (callgrind_annotate, inclusive): the reduction (wm_reduce,
steps 2(d) and 3(b)), the error bound (greedy insertion with Lawson flips), the final decimation, and the
rest (set-up and the levels' select, pair, split, swap).  --peer also counts pydelatin's
Triangulator::Run (the same greedy insertion, its whole algorithm; inclusive, in a Python process that
calls Delatin as the quality benchmark does) on the same grid and error, and gives each phase over it:
what the speed target (native refine time at most pydelatin's) asks of each phase, in a unit the machine's
load does not change.  --set changes the job from the defaults, e.g. `--set reduce=off,iterations=0` or
`levels=1`: RefineParams' fields (on/off for the switches) and the job's levels M, to measure what a
phase buys.

--job runs `wavemesh mesh`'s own job instead of the pairs (repeatable; the CLI's option parsing, its
initial triangulation and fixed-point parameters, as bench/bench_soc.py's native column; INPUT may be
JACKSBORO, matplotlib's Jacksboro DEM with `--key elevation`), e.g. `--job 'JACKSBORO --zeta 10'`.
--routines N lists each input's N costliest functions (self and inclusive instructions).  --scans also
runs a profile build of the runner (build/firmware-profile, WM_PROFILE: counters in the E(T) code) and
splits the E(T) work by phase: the scans, the samples they visit (the FPGA triangle engine's work),
the rows, the slope factors and point errors (the CPU's).
"""

from __future__ import annotations

import argparse
import os
import re
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PAIRS = (("jacksboro", "5 m"), ("jacksboro", "10 m"), ("mri", "1%"), ("mri", "5%"), ("f1", "1%"),
         ("f3", "2%"), ("f4", "0.5%"), ("f5", "0.5%"), ("ball", "1%"), ("box", "1%"))


def parse_set(text: str | None) -> dict:
    """--set's NAME=VALUE,... as RefineParams keywords (and "levels"); SystemExit naming a bad one."""
    import dataclasses

    from wavemesh.refine import native

    kinds = {f.name: f.type for f in dataclasses.fields(native.RefineParams)}
    out = {}
    for item in filter(None, (text or "").split(",")):
        name, _, value = item.partition("=")
        kind = "int" if name == "levels" else kinds.get(name)
        if kind is None or not value or (kind == "bool" and value not in ("on", "off")):
            raise SystemExit(f"error: --set {item}: not NAME=VALUE of a RefineParams field (on/off for a "
                             "switch) or levels")
        try:
            out[name] = (value == "on" if kind == "bool" else int(value) if kind in ("int", "int | None")
                         else float(value) if kind == "float" else value)
        except ValueError:
            raise SystemExit(f"error: --set {item}: {value} is not a number") from None
    return out


def write_inputs(folder: Path, changes: dict | None = None) -> list[tuple[str, Path]]:
    import bench_quality as Q
    import datasets as D
    from wavemesh import api
    from wavemesh.harness.fwio import write_input
    from wavemesh.io.heightfield import from_array
    from wavemesh.model.haar import decompose
    from wavemesh.refine import native

    out = []
    for name, want in PAIRS:
        assert name not in Q.HELD_OUT, name
        grid = D.load(name)
        zeta = dict(Q.zetas(grid))[want]
        hf = from_array(grid.values)
        changes = dict(changes or {})
        levels = changes.pop("levels", None)
        params = native.RefineParams(**{"zeta": float(zeta), "metric": "vertical", **changes})
        job = api.triangulate(hf, levels)
        fp = native.fixed_params(params, hf.scale, hf.refiner_zeta(params.zeta))  # as api.refine
        det = native.details_array(decompose(hf.samples, job.levels))
        path = folder / f"{name}-{len(out)}.bin"
        write_input(path, hf.samples, det, job.levels, job.mesh, fp, 2 * (hf.width - 1) * (hf.height - 1))
        out.append((f"{name} {want}", path))
    return out


def cli_input(spec: str, path: Path) -> str:
    """Writes the runner's input for `wavemesh mesh INPUT OPTIONS` (spec, shell words) to path, the job
    exactly as the CLI makes it; returns the spec.  INPUT JACKSBORO: matplotlib's DEM, --key elevation."""
    import shlex

    from wavemesh import api, cli
    from wavemesh.harness import jacksboro
    from wavemesh.harness.fwio import write_input
    from wavemesh.refine import native

    src, *opts = shlex.split(spec)
    if src == "JACKSBORO":
        src, opts = jacksboro(), ["--key", "elevation", *opts]
    args = cli.build_parser("mesh").parse_args(["mesh", src, "-o", str(path.with_suffix(".obj")), *opts])
    mp, hf = cli._mesh_params(args), cli._load(args, src)
    job = api.triangulate(hf, mp.levels, mp.tau, mp.wavelet)
    fp = native.fixed_params(mp.refine, hf.scale, hf.refiner_zeta(mp.refine.zeta), api.ground(hf).spacing)
    det = native.haar_details(hf.samples, job.levels, job.wavelet)
    write_input(path, hf.samples, det, job.levels, job.mesh, fp, 2 * (hf.width - 1) * (hf.height - 1))
    return spec


def measure(runner: Path, inp: Path, out: Path, profile: Path | None = None) -> tuple[int, int]:
    """(instructions, output triangles) of one run; the callgrind profile kept in ``profile`` if given."""
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={profile or '/dev/null'}", str(runner),
           str(inp), str(out)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    refs = int(re.search(r"refs:\s+([\d,]+)", res.stderr).group(1).replace(",", ""))
    last = [ln for ln in res.stdout.splitlines() if ln.startswith("level")][-1].split()
    return refs, int(last[3])


# The refiner's phases by their entry functions (firmware/src): each inclusive of what it calls.
PHASES = (("reduction", "wm_reduce"), ("error bound", "error_bound"), ("decimation", "wm_decimate"))
REFINER = ("wm_refine_init", "wm_refine_step")
PEER = "Triangulator::Run("  # pydelatin's C++ core (its whole algorithm)


def inclusive(profile: Path, incl: bool = True) -> dict[str, int]:
    """Every function's inclusive (incl=False: self) instructions in a callgrind profile, by name (C++
    names demangled)."""
    out = subprocess.run(["callgrind_annotate", f"--inclusive={'yes' if incl else 'no'}", "--threshold=100",
                          str(profile)], capture_output=True, text=True, check=True).stdout
    found = {}
    for line in out.splitlines():
        m = re.match(r"\s*([\d,]+) \([^)]*\)\s+\S*?:(.+?) \[", line)
        if m:
            found.setdefault(m.group(2), int(m.group(1).replace(",", "")))
    return found


def phases(profile: Path) -> dict[str, int]:
    """The refiner's instructions by phase; "rest" is the set-up and the levels' iterations."""
    inc = inclusive(profile)
    total = sum(inc.get(f, 0) for f in REFINER)
    out = {name: inc.get(f, 0) for name, f in PHASES}
    out["rest"] = total - sum(out.values())
    out["refiner"] = total
    return out


PEER_SCRIPT = """
import sys
import bench_quality as Q, datasets as D, peers as P
g = D.load(sys.argv[1])
print("triangles", len(P.delatin_call(g.values, dict(Q.zetas(g))[sys.argv[2]])[1]))
"""


def peer_instructions(name: str, want: str, folder: Path) -> tuple[int, int]:
    """(instructions, triangles) of pydelatin's Triangulator::Run on the pair, inclusive, under callgrind."""
    prof = folder / f"peer-{name}.cg"
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={prof}", sys.executable, "-c", PEER_SCRIPT,
           name, want]
    env = {**os.environ, "PYTHONPATH": str(ROOT / "bench")}  # its peers, as this script has them
    res = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
    tris = int(re.search(r"triangles (\d+)", res.stdout).group(1))
    return next(v for k, v in inclusive(prof).items() if k.startswith(PEER)), tris


def routine_table(label: str, profile: Path, top: int) -> None:
    """The top functions of one run by self instructions, with their inclusive ones and shares of the
    refiner's (wm_refine_init and wm_refine_step, inclusive)."""
    own, inc = inclusive(profile, incl=False), inclusive(profile)
    total = sum(inc.get(f, 0) for f in REFINER)
    print(f"\n{label}: the refiner {total:,} instructions\n")
    print("| routine | self | self share | inclusive | inclusive share |")
    print("|---|---|---|---|---|")
    for name, n in sorted(own.items(), key=lambda kv: -kv[1])[:top]:
        print(f"| {name} | {n:,} | {100 * n / total:.1f} % | {inc.get(name, 0):,} | "
              f"{100 * inc.get(name, 0) / total:.1f} % |")


SCAN_PHASES = ("levels", "reduction", "bound", "decimation")  # wm_run's profile lines (WM_PH_*)
SCAN_COUNTS = ("scans", "samples", "rows", "slopes", "points")


def profile_runner() -> Path:
    """The runner of the profile build (WM_PROFILE: the E(T) counters), built from this tree."""
    from wavemesh.device.gen import write_all

    out = ROOT / "build" / "firmware-profile"
    write_all(ROOT / "build" / "gen")  # fixed.c's wm_angle.h
    subprocess.run(["cmake", "-S", str(ROOT / "firmware"), "-B", str(out), "-DCMAKE_BUILD_TYPE=Release",
                    "-DWM_PROFILE=ON"], check=True, capture_output=True)
    subprocess.run(["cmake", "--build", str(out), "-j2", "--target", "wm_run"], check=True,
                   capture_output=True)
    return out / "wm_run"


def scan_counts(runner: Path, inp: Path, out: Path) -> tuple[dict[str, dict[str, int]], int, int]:
    """({phase: {count: n}}, samples of the grid, output triangles) of one run of the profile runner."""
    res = subprocess.run([str(runner), str(inp), str(out)], capture_output=True, text=True, check=True).stdout
    counts = {}
    for line in res.splitlines():
        if line.startswith("profile "):
            name, *vals = line.split()[1:]
            counts[name] = dict(zip(SCAN_COUNTS, map(int, vals), strict=True))
    w, h = struct.unpack_from("=2i", inp.read_bytes(), 4)
    last = [ln for ln in res.splitlines() if ln.startswith("level")][-1].split()
    return counts, w * h, int(last[3])


def scan_table(inputs, runner: Path, folder: Path) -> None:
    """Per input and phase: scans, samples visited (per grid sample, per scan), rows, slope factors, point
    errors."""
    print("| input | phase | scans | samples visited | per grid sample | per scan | rows | slope factors | "
          "point errors |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, path in inputs:
        counts, n, tris = scan_counts(runner, path, folder / "out.bin")
        tot = {c: sum(counts[p][c] for p in SCAN_PHASES) for c in SCAN_COUNTS}
        head = f"{label} ({n:,} samples, {tris:,} triangles)"
        for ph, c in [*((p, counts[p]) for p in SCAN_PHASES), ("all", tot)]:
            print(f"| {head} | {ph} | {c['scans']:,} | {c['samples']:,} | {c['samples'] / n:.1f} | "
                  f"{c['samples'] / max(c['scans'], 1):.1f} | {c['rows']:,} | {c['slopes']:,} | "
                  f"{c['points']:,} |")
            head = ""


def phase_table(inputs, runner: Path, folder: Path, peer: bool) -> None:
    cols = [name for name, _ in PHASES] + ["rest", "refiner"]
    head = "| pair | triangles | " + " | ".join(cols) + " |" + (" pydelatin Run | " + " | ".join(
        f"{c} / pydelatin" for c in cols) + " | triangles / pydelatin's |" if peer else "")
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    ratios = []
    for i, (label, path) in enumerate(inputs):
        prof = folder / "refiner.cg"
        _, tris = measure(runner, path, folder / "out.bin", prof)
        ph = phases(prof)
        row = [label, str(tris)] + [f"{ph[c]:,}" for c in cols]
        if peer:
            name, want = PAIRS[i]
            pd, pd_tris = peer_instructions(name, want, folder)
            row += [f"{pd:,}"] + [f"{ph[c] / pd:.2f}" for c in cols] + [f"{tris / pd_tris:.3f}"]
            ratios.append((ph["refiner"] / pd, tris / pd_tris))
        print("| " + " | ".join(row) + " |", flush=True)
    if ratios:
        import statistics

        tri = [t for _, t in ratios]
        print(f"\nmedian refiner / pydelatin {statistics.median(r for r, _ in ratios):.2f}, triangles / "
              f"pydelatin's median {statistics.median(tri):.3f}, max {max(tri):.3f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runner", type=Path, default=ROOT / "build" / "firmware-native" / "wm_run")
    ap.add_argument("--base", type=Path, help="a second wm_run to compare with")
    ap.add_argument("--phases", action="store_true", help="instructions by phase (not with --base)")
    ap.add_argument("--peer", action="store_true", help="with --phases: pydelatin's on the same pairs")
    ap.add_argument("--set", help="NAME=VALUE,...: RefineParams fields (on/off) and levels, not the defaults")
    ap.add_argument("--job", action="append", help="'INPUT [wavemesh mesh options]': that job, not the pairs")
    ap.add_argument("--routines", type=int, metavar="N", help="each input's N costliest functions")
    ap.add_argument("--scans", action="store_true",
                    help="E(T)'s scans and samples by phase (a profile build)")
    args = ap.parse_args(argv)
    if args.peer and not args.phases:
        ap.error("--peer goes with --phases")
    if args.job and (args.peer or args.set):
        ap.error("--job runs the CLI's own job: no --peer, no --set (write its options in the job)")
    if args.phases and args.base:
        ap.error("--phases measures one runner: leave out --base")
    if args.runner == ap.get_default("runner"):
        from wavemesh.device.gen import write_all

        write_all(ROOT / "build" / "gen")  # fixed.c's wm_angle.h
        subprocess.run(["cmake", "-S", str(ROOT / "firmware"), "-B", str(args.runner.parent),
                        "-DCMAKE_BUILD_TYPE=Release"], check=True, capture_output=True)
        subprocess.run(["cmake", "--build", str(args.runner.parent), "-j2", "--target", "wm_run"], check=True,
                       capture_output=True)
    runners = [args.runner] + ([args.base] if args.base else [])
    with tempfile.TemporaryDirectory() as tmp:
        if args.job:
            inputs = [(cli_input(spec, Path(tmp) / f"job-{i}.bin"), Path(tmp) / f"job-{i}.bin")
                      for i, spec in enumerate(args.job)]
        else:
            inputs = write_inputs(Path(tmp), parse_set(args.set))
        if args.phases or args.routines or args.scans:
            if args.phases:
                phase_table(inputs, args.runner, Path(tmp), args.peer)
            for label, path in inputs if args.routines else ():
                measure(args.runner, path, Path(tmp) / "out.bin", Path(tmp) / "refiner.cg")
                routine_table(label, Path(tmp) / "refiner.cg", args.routines)
            if args.scans:
                print()
                scan_table(inputs, profile_runner(), Path(tmp))
            return 0
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
