"""Big grids: `wavemesh mesh` against pydelatin as whole processes at 2048^2 and 4096^2 samples, time
(wall and CPU) and peak memory of each process beside the triangles (`make bench-big`; minutes, so not
part of `make bench`).

Grids, each made n x n (bench/datasets.py):

- *terrain*: the seeded synthetic terrain sampled n x n over the unit square (datasets.terrain);
- real height fields mirror-tiled to n x n (the grid, then its mirror image, and so on across and down:
  every sample a real one, no seam steps): the Jacksboro DEM (terrain), and held out (never tuned on,
  reported apart) the LiDAR DEM and the Motorcycle disparity map (a range image).

At E = FRACTION of each grid's height range (vertical), for each grid: the grid saved as .npy, then run
in turn (A B C A B C ...) RUNS times each:

- A: `wavemesh mesh IN.npy -o x.obj --metric vertical --zeta E` (its defaults: a grid of 2048^2 samples
  and more in tiles over every core, docs/usage.md "Threads and tiles");
- B: the peer process of bench/peers.py: load the same .npy, run pydelatin, write an OBJ;
- C: A with `--workers 1 --threads 1` (one core: the tiles in this process, the host stages on one
  thread; the refiner runs on one anyway), once.

Each process's CPU time (user + sys) and peak memory (ru_maxrss) come from the operating system
(os.wait4, in a small launcher: see LAUNCH; a tiled run's pool workers counted, those still exiting
when the command returns too).  Both OBJ files are read back and checked by wavemesh.check
(proper, grid-sample vertices carrying the grid's heights, E_max vertical within E); A's and C's files
must be byte for byte equal.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import datasets as D  # bench/ is on the path: the folder of bench/run.py and of this script
import numpy as np
import peers as P

TITLE = "Big grids: whole processes at 2048^2 and 4096^2 against pydelatin (time, memory, triangles)"
DEFAULT = False  # minutes of runs: `make bench-big`
SIZES = (2048, 4096)
FRACTION = 0.01  # E: of each grid's height range
RUNS = 3
HELD_OUT = ("lidar_dem", "motorcycle")
GRIDS = ("terrain", "jacksboro", "lidar_dem", "motorcycle")
TARGET_TIME, TARGET_TRIANGLES = 1.0, 0.6  # process / process on every grid; triangles / pydelatin's


def mirror_tile(z: np.ndarray, n: int) -> np.ndarray:
    """z repeated as z, its mirror image, z, ... across and down, cut to n x n."""
    h, w = z.shape
    reps = (-(-n // h), -(-n // w))
    rows = np.concatenate([z if i % 2 == 0 else z[::-1] for i in range(reps[0])], axis=0)
    full = np.concatenate([rows if j % 2 == 0 else rows[:, ::-1] for j in range(reps[1])], axis=1)
    return np.ascontiguousarray(full[:n, :n])


def make_grid(name: str, n: int) -> tuple[np.ndarray, str]:
    """(heights, how they were made)."""
    if name == "terrain":
        return D.terrain(n), "datasets.terrain(n): the seeded terrain over the unit square"
    g = D.load(name)
    return mirror_tile(g.values, n), f"{name} ({g.shape[1]} x {g.shape[0]}, {g.kind}) mirror-tiled"


def zeta_of(z: np.ndarray) -> float:
    """E: FRACTION of the grid's height range."""
    return FRACTION * float(z.max() - z.min())


# A small launcher between this process and the measured one: a child's ru_maxrss starts from its
# parent's resident size when it is forked (Linux keeps the high-water mark across exec), and this
# process holds the grids; the launcher (a bare interpreter, ~10 MiB) forks, execs, reaps with os.wait4 and
# prints the measured process's figures.  It is the reaper of the process's descendants too (Linux:
# PR_SET_CHILD_SUBREAPER): a tiled run's pool workers still exiting when the command returns (it does not
# wait for them) come to it, and their CPU and peak memory are the command's, as its own waited-for
# children's are; the wall time is the command's, to its return.
LAUNCH = """\
import ctypes, json, os, sys, time
if sys.platform.startswith("linux"):
    ctypes.CDLL(None).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
t0 = time.perf_counter()
pid = os.fork()
if pid == 0:
    fd = os.open(os.devnull, os.O_WRONLY)
    os.dup2(fd, 1)
    os.execv(sys.argv[1], sys.argv[1:])
_, status, ru = os.wait4(pid, 0)
wall, cpu, peak = time.perf_counter() - t0, ru.ru_utime + ru.ru_stime, ru.ru_maxrss
while True:
    try:
        _, _, r = os.wait4(-1, 0)
    except ChildProcessError:
        break
    cpu, peak = cpu + r.ru_utime + r.ru_stime, max(peak, r.ru_maxrss)
print(json.dumps({"wall_s": wall, "cpu_s": cpu, "peak_mib": peak / 1024,
                  "rc": os.waitstatus_to_exitcode(status)}))
"""


def run_process(cmd: list[str], cwd: Path | None = None, env: dict | None = None) -> dict:
    """One whole process (in ``cwd``, with ``env``): wall seconds, CPU seconds (user + sys) and peak memory
    (MiB) by os.wait4, its descendants' CPU and peak included (LAUNCH)."""
    r = subprocess.run([sys.executable, "-c", LAUNCH, *cmd], capture_output=True, text=True, cwd=cwd, env=env)
    out = json.loads(r.stdout.strip().splitlines()[-1])
    out["error"] = r.stderr.strip()[-300:] if out["rc"] else None
    return out


def check_obj(path: Path, heights: np.ndarray, zeta: float) -> dict:
    from wavemesh.io.meshread import read_mesh

    h, w = heights.shape
    try:
        mesh, z = read_mesh(str(path), w, h)
    except Exception as e:  # noqa: BLE001 - a file written badly is a finding, not a crash
        return {"triangles": None, "proper": False, "within": False, "problems": [str(e)[:200]]}
    v = P.verdict(mesh, heights, zeta, z, rms=False)
    return {"triangles": v.triangles, "proper": v.proper and v.heights_ok,
            "within": v.within and v.heights_ok, "e_max_vertical": v.e_max_vertical, "problems": v.problems}


def _summary(runs: list[dict]) -> dict:
    return {"wall_s": P.median(r["wall_s"] for r in runs), "cpu_s": P.median(r["cpu_s"] for r in runs),
            "peak_mib": max(r["peak_mib"] for r in runs), "runs": len(runs),
            "error": next((r["error"] for r in runs if r["rc"]), None)}


def run_grid(name: str, n: int, tmp: Path, runs: int = RUNS) -> dict:
    z, made = make_grid(name, n)
    zeta = zeta_of(z)
    npy = tmp / f"{name}-{n}.npy"
    np.save(npy, z)
    outs = {k: tmp / f"{k}.obj" for k in ("wavemesh", "pydelatin", "threads1")}
    cmds = {"wavemesh": P.wavemesh_argv(str(npy), zeta, str(outs["wavemesh"])),
            "pydelatin": P.peer_argv(str(npy), zeta, str(outs["pydelatin"])),
            "threads1": P.wavemesh_argv(str(npy), zeta, str(outs["threads1"]))
            + ["--workers", "1", "--threads", "1"]}
    got = {k: [] for k in cmds}
    for i in range(runs):
        for k, cmd in cmds.items():
            if k != "threads1" or i == 0:  # one core: once, for its time and its mesh
                got[k].append(run_process(cmd))
    res = {k: _summary(v) for k, v in got.items()}
    res["wavemesh"]["file"] = check_obj(outs["wavemesh"], z, zeta)
    res["pydelatin"]["file"] = check_obj(outs["pydelatin"], z, zeta)
    same = outs["wavemesh"].exists() and outs["wavemesh"].read_bytes() == outs["threads1"].read_bytes()
    wm, pd = res["wavemesh"], res["pydelatin"]

    def ratio(a, b):
        return None if a is None or not b else a / b

    npy.unlink()
    return {"grid": name, "n": n, "made": made, "held_out": name in HELD_OUT, "zeta": zeta,
            "height_range": float(z.max() - z.min()), **res, "same_mesh_one_thread": same,
            "ratios": {"wall": ratio(wm["wall_s"], pd["wall_s"]), "cpu": ratio(wm["cpu_s"], pd["cpu_s"]),
                       "peak": ratio(wm["peak_mib"], pd["peak_mib"]),
                       "triangles": ratio(wm["file"]["triangles"], pd["file"]["triangles"]),
                       "one_thread_wall": ratio(res["threads1"]["wall_s"], pd["wall_s"])}}


def run(sizes=SIZES, grids=GRIDS, runs: int = RUNS, partial: Path | None = None) -> dict:
    """Every grid at every size; ``partial``: a JSON file of the rows so far, rewritten after each."""
    import json

    P.compile_wavemesh()
    rows, load = [], os.getloadavg()
    with tempfile.TemporaryDirectory() as t:
        for n in sizes:
            for name in grids:
                t0 = time.perf_counter()
                r = run_grid(name, n, Path(t), runs)
                rows.append(r)
                if partial is not None:
                    partial.write_text(json.dumps(rows, indent=1) + "\n")
                q = r["ratios"]
                print(f"  {name} {n}^2: wall x{_f(q['wall'])}, cpu x{_f(q['cpu'])}, peak x{_f(q['peak'])}, "
                      f"triangles x{_f(q['triangles'], 3)} ({time.perf_counter() - t0:.0f} s)", flush=True)
    return {"code": P.code_state(), "fraction": FRACTION, "runs": runs, "cores": os.cpu_count(),
            "load_before": load, "load_after": os.getloadavg(), "rows": rows}


def _f(v, nd=2) -> str:
    return "-" if v is None or v != v else f"{v:.{nd}f}"


def _ok(r: dict) -> str:
    f = r["file"]
    return "ok" if f["within"] else ("not proper" if not f["proper"] else "over E")


def markdown(results: dict) -> str:
    rows = results["rows"]
    lines = [
        "`wavemesh mesh IN.npy -o x.obj --metric vertical --zeta E` (every core; and one core, `--workers 1 "
        "--threads 1`) against "
        "a process that loads the same .npy, runs pydelatin and writes an OBJ (bench/peers.py), at E = "
        f"{100 * results['fraction']:g}% of each grid's height range, run in turn {results['runs']} times "
        "each (one core once); medians of wall and CPU (user + sys) seconds, the largest peak memory "
        "(ru_maxrss), from "
        "os.wait4.  Grids n x n: the seeded terrain, and real height fields mirror-tiled to n x n "
        "(bench/bench_big.py).  Both OBJ files checked by wavemesh.check (*checks*: wavemesh / pydelatin); "
        "*same*: the one-core mesh is byte for byte the default's.  "
        f"Machine: {results['cores']} cores, shared (load average {results['load_before'][0]:.1f} at the "
        f"start, {results.get('load_after', results['load_before'])[0]:.1f} at the end): the ratios (runs "
        "interleaved) are the figures to read.",
        "",
        P.code_line(results.get("code")),
        "",
        "| grid | n | E | triangles wm / pd | **wall wm / pd** | cpu wm / pd | peak MiB wm / pd | wall s wm, "
        "one core, pd | cpu s wm, pd | checks | same |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for held in (False, True):
        part = [r for r in rows if r["held_out"] == held]
        if held and part:
            lines.append("| **held out** | | | | | | | | | | |")
        for r in part:
            wm, pd, t1, q = r["wavemesh"], r["pydelatin"], r["threads1"], r["ratios"]
            lines.append(
                f"| {r['grid']} | {r['n']} | {r['zeta']:.4g} | {wm['file']['triangles']} / "
                f"{pd['file']['triangles']} = {_f(q['triangles'], 3)} | **{_f(q['wall'])}** | {_f(q['cpu'])} "
                f"| {wm['peak_mib']:.0f} / {pd['peak_mib']:.0f} = {_f(q['peak'])} "
                f"| {wm['wall_s']:.2f}, {t1['wall_s']:.2f}, {pd['wall_s']:.2f} | {wm['cpu_s']:.2f}, "
                f"{pd['cpu_s']:.2f} | {_ok(wm)} / {_ok(pd)} "
                f"| {'yes' if r['same_mesh_one_thread'] else '**no**'} |")
    walls = [r["ratios"]["wall"] for r in rows]
    tris = [r["ratios"]["triangles"] for r in rows]
    big = [r["ratios"]["peak"] for r in rows if r["n"] == max(x["n"] for x in rows)]
    lines += [
        "",
        f"Targets on this run: `wavemesh mesh` process at most {TARGET_TIME:g}x pydelatin's on every grid "
        f"(wall): {'met' if walls and max(w or 9 for w in walls) <= TARGET_TIME else '**not met**'} "
        f"(largest {_f(max((w for w in walls if w), default=None))}, median {_f(P.median(walls))}); "
        f"triangles at most {TARGET_TRIANGLES:g}x (median): "
        f"{'met' if P.median(tris) <= TARGET_TRIANGLES else '**not met**'} ({_f(P.median(tris), 3)}); peak "
        f"memory at most pydelatin's on the largest grids: "
        f"{'met' if big and max(big) <= 1.0 else '**not met**'} "
        f"(largest ratio {_f(max(big, default=None))}).",
        "",
        "Grids: " + "; ".join(sorted({f"{r['grid']}: {r['made']}" for r in rows})) + ".",
    ]
    return "\n".join(lines)


# `wavemesh mesh`'s default tile (api.AUTO_TILE) and threshold (api.AUTO_TILE_SAMPLES), measured: the grid
# whole (--tile off), in tiles of each side on 2 workers and of 513 and 1025 on 1, against the peer process;
# CPU seconds (user + sys of the process and its workers: what a loaded machine does not change as it does
# wall) and triangles / the untiled mesh's.  Tuning grids only (terrain, jacksboro); held out: see run().
TILE_CONFIGS = {"whole": ["--tile", "off"], **{f"{t} x2": ["--tile", str(t), "--workers", "2"]
                                               for t in (513, 1025, 2049)},
                **{f"{t} x1": ["--tile", str(t), "--workers", "1"] for t in (513, 1025)}}


def tile_sizes(n: int, grids=("terrain", "jacksboro"), runs: int = 2) -> str:
    """`python bench/bench_big.py tiles N [GRID ...]`: the markdown table docs/usage.md's "Threads and
    tiles" quotes (CPU s, median of ``runs`` in turn; triangles / the whole grid's)."""
    P.compile_wavemesh()
    lines = [f"n = {n}: CPU s (triangles / whole's); load average {os.getloadavg()[0]:.1f} at the start",
             "", "| grid | " + " | ".join([*TILE_CONFIGS, "pydelatin"]) + " |",
             "|---" * (len(TILE_CONFIGS) + 2) + "|"]
    with tempfile.TemporaryDirectory() as t:
        for name in grids:
            z, _ = make_grid(name, n)
            zeta = zeta_of(z)
            npy = Path(t) / f"{name}.npy"
            np.save(npy, z)
            del z
            cpu, tris = {}, {}
            for i in range(runs):
                for k, extra in [*TILE_CONFIGS.items(), ("pydelatin", None)]:
                    out = Path(t) / f"{k.replace(' ', '')}.obj"
                    cmd = (P.peer_argv(str(npy), zeta, str(out)) if extra is None
                           else P.wavemesh_argv(str(npy), zeta, str(out)) + extra)
                    r = run_process(cmd)
                    cpu.setdefault(k, []).append(r["cpu_s"] if not r["rc"] else float("nan"))
                    if i == 0:
                        with open(out, "rb") as f:
                            tris[k] = sum(1 for line in f if line.startswith(b"f "))
            cells = [f"{P.median(cpu[k]):.2f}" + ("" if k in ("whole", "pydelatin") else
                                                  f" ({tris[k] / tris['whole']:.4f})")
                     for k in [*TILE_CONFIGS, "pydelatin"]]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
            print(lines[-1], flush=True)
    lines.append(f"(load average {os.getloadavg()[0]:.1f} at the end)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """bench/bench_big.py [N] [GRID ...]: a quick look; ... tiles N [GRID ...] [--runs R]: tile sizes."""
    ap = argparse.ArgumentParser(prog="bench/bench_big.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("what", nargs="*", metavar="[tiles] [N] [GRID ...]",
                    help=f"'tiles N' compares tile sizes at N^2; N alone: that size only (default {SIZES}); "
                         f"grids: {', '.join(GRIDS)} (default all)")
    ap.add_argument("--runs", type=int, default=None, help="runs of each (default: tiles 2, else %d)" % RUNS)
    a = ap.parse_args(argv)
    args = list(a.what)
    tiles = bool(args) and args[0] == "tiles"
    if tiles:
        args.pop(0)
        if not args or not args[0].isdigit():
            ap.error("tiles needs the side N, e.g. 'tiles 2048'")
    size = int(args.pop(0)) if args and args[0].isdigit() else None
    unknown = [g for g in args if g != "terrain" and g not in D.SETS]
    if unknown:
        ap.error(f"unknown grid {unknown[0]!r}: one of {', '.join(GRIDS)} (bench/datasets.py names more)")
    if a.runs is not None and a.runs < 1:
        ap.error("--runs must be at least 1")
    if tiles:
        print(tile_sizes(size, tuple(args) or ("terrain", "jacksboro"), a.runs or 2))
        return
    res = run((size,) if size else SIZES, tuple(args) or GRIDS, a.runs or RUNS)
    print(json.dumps([r["ratios"] for r in res["rows"]], indent=1))
    print(markdown(res))


if __name__ == "__main__":
    main()
