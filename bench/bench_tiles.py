"""Tiles: `wavemesh mesh --tile` of inputs up to 8192 x 8192 in bounded memory.

The height field is the seeded synthetic terrain of bench/datasets.py (terrain(): a fractal-like sum of
plane waves, 0..1000 "m" on the unit square), sampled n x n over the same unit square (the "resolution"
series of bench_cost: the same surface ever finer), written strip by strip into a float32 .npy that the
run reads through a memmap, never whole.  Every run is `wavemesh.tiles` (plan_tiles, run_tiles on the
local pool, stitch: the stitched mesh checked proper) with --metric vertical --zeta 10 (1 % of the
height range), in a process of its own; its peak RSS is that process tree's resident memory (itself and
its pool workers, summed) sampled every 50 ms by psutil, the most it reached.

- *growth*: 1024^2 .. 8192^2 at the default tile size for 2 workers (tiles.default_tile: from the memory
  available; 4097 on a machine with 2 x 4097^2 x 48 bytes to spare), 2 workers;
- *tile size*: 8192^2 at tiles of 1025, 2049 and 4097, 2 workers;
- *workers*: 8192^2 at tiles of 1025 (64 of them) with 1, 2, 4, ... workers up to the CPUs this process may
  use (TILES_WORKERS_MAX, or `python bench/bench_tiles.py --workers-max N` on a bigger machine): the
  speed-up t1 / tw, the parallel efficiency t1 / (w tw), and the parent's own CPU time (os.times of the
  run's process, its workers apart) against t1: the serial part that bounds the speed-up; with
  TILES_SCHEDULER (`--scheduler local` for a Dask LocalCluster of w single-threaded worker processes, or a
  scheduler's address) the same series through Dask;
- *overhead*: the tiled mesh's triangles against one untiled run (wavemesh.api.mesh, in a process of
  its own: its peak RSS is the whole grid's) at every size, at the default tile size and at smaller ones,
  and on the benchmark DEMs of bench_quality (the real ones; each smaller than the default tile, where
  tiling is one tile, the untiled mesh itself, so smaller tiles are shown too).

Wall times on a shared 2-core machine are noisy; CPU seconds are given beside them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parent
TITLE = "Tiles: any size in bounded memory"
ZETA = 10.0
SIZES = (1024, 2048, 4096, 8192)
TILE_SIZES = (1025, 2049, 4097)
TILE_N = 8192
WORKERS_TILE = 1025
STRIP = 256
DEMS = ("jacksboro", "topobathy", "lidar_dem", "motorcycle")
DEM_TILES = (257, 129)
RSS_BAR = 2 << 30
REAL, REAL_N, REAL_TILES, REAL_ZETA = "jacksboro", 8192, (1025, 4097), 0.01  # zeta: of the height range
WORK = Path(os.environ.get("WAVEMESH_BENCH_TMP", "/tmp")) / "wavemesh-bench-tiles"


def terrain_file(n: int, grid: str = "terrain") -> Path:
    """The n x n terrain as a float32 .npy, written strip by strip (once); another ``grid``: that real DEM
    of bench/datasets.py mirror-tiled to n x n (bench_big.mirror_tile: every sample a real one)."""
    import datasets as D

    WORK.mkdir(parents=True, exist_ok=True)
    path = WORK / f"{grid}-{n}.npy"
    if not path.exists() and grid != "terrain":
        from bench_big import mirror_tile

        tmp = path.with_suffix(".part.npy")
        np.save(tmp, mirror_tile(D.load(grid).values, n).astype(np.float32))
        tmp.rename(path)
    if not path.exists():
        tmp = path.with_suffix(".part.npy")
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float32, shape=(n, n))
        for r in range(0, n, STRIP):
            out[r : r + STRIP] = D.terrain(n, rows=slice(r, min(n, r + STRIP)))
        out.flush()
        del out
        tmp.rename(path)
    return path


def one(
    n: int, tile: int, workers: int, untiled: bool = False, scheduler: str = "", grid: str = "terrain"
) -> dict:
    """One run in this process (the child): the tiled mesh (on a Runner of ``workers`` local workers, or
    through Dask: ``scheduler`` "local" for a LocalCluster of ``workers`` processes, or an address), or the
    untiled one.  The parent's own CPU time (os.times: this process, its forked workers and its worker
    threads apart, Runner.threads_cpu; with a LocalCluster, its scheduler's too); on Dask the workers' CPU
    apart (each one's os.times before and after: idle workers' counted too) and in cpu_seconds.
    WAVEMESH_BENCH_RUNNER ("NAME=VALUE,..."): tiles.runner's settings for the run (THREADS=0, ...)."""
    from wavemesh import api, tiles
    from wavemesh.refine.native import RefineParams

    path = str(terrain_file(n, grid))
    zeta = ZETA if grid == "terrain" else REAL_ZETA * float(np.ptp(np.load(path, mmap_mode="r")))
    params = api.MeshParams(refine=RefineParams(zeta=zeta, metric="vertical"))
    from wavemesh.tiles import runner as pool

    for kv in filter(None, os.environ.get("WAVEMESH_BENCH_RUNNER", "").split(",")):  # as LAUNCHER's
        k, v = kv.split("=")
        setattr(pool, k, type(getattr(pool, k))(int(v)))
    cluster = client = None
    via = scheduler
    if scheduler:
        from distributed import Client, LocalCluster

        if scheduler == "local":
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            )
        client = Client(cluster or scheduler)
        scheduler = client
    dask0 = _dask_cpu(client)
    t0, c0 = time.perf_counter(), os.times()
    if untiled:
        r = api.mesh(api.load_input(path), params)
        out = {"triangles": r.mesh.n_triangles, "e_max": r.errors.e_max_vertical}
    else:
        with tiles.Runner(workers, scheduler or None) as runner:
            plan = tiles.plan_tiles(tiles.open_source(path), params, tile, runner=runner)
            tiled = tiles.stitch(plan, tiles.run_tiles(plan, runner=runner))
        out = {
            "triangles": tiled.mesh.n_triangles,
            "e_max": tiled.report["e_max_vertical"],
            "tiles": len(plan.tiles),
            "scan_seconds": plan.scan_seconds,
        }
    seconds = time.perf_counter() - t0
    dask_cpu = _dask_cpu(client) - dask0
    for proc in pool._EXITING:  # the workers still exiting (not waited for by the run): their CPU counted
        proc.join()
    c1 = os.times()
    if client is not None:
        client.close()
    if cluster is not None:
        cluster.close()
    here = c1.user + c1.system - c0.user - c0.system
    parent = here - (runner.threads_cpu if not untiled else 0.0)
    return out | {
        "seconds": seconds,
        "parent_cpu_seconds": parent,
        "cpu_seconds": here + c1.children_user + c1.children_system - c0.children_user - c0.children_system
        + dask_cpu,
        "dask_workers_cpu_seconds": dask_cpu,
        "scheduler": via and ("dask" if cluster is not None else "dask " + via),
    }


def _dask_cpu(client) -> float:
    """The Dask workers' CPU seconds so far (their processes' os.times, summed; 0 without a client)."""
    if client is None:
        return 0.0
    return sum(client.run(lambda: (lambda t: t.user + t.system)(os.times())).values())


def run_child(
    n: int, tile: int, workers: int, untiled: bool = False, scheduler: str = "", grid: str = "terrain"
) -> dict:
    """one() in a process of its own, its tree's peak RSS sampled meanwhile."""
    import psutil

    cmd = [
        sys.executable,
        str(Path(__file__)),
        "one",
        str(n),
        str(tile),
        str(workers),
        "1" if untiled else "0",
        scheduler,
        grid,
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, cwd=BENCH)
    peak = 0
    stop = threading.Event()

    def sample() -> None:
        nonlocal peak
        p = psutil.Process(proc.pid)
        while not stop.is_set():
            try:
                total = p.memory_info().rss + sum(c.memory_info().rss for c in p.children(recursive=True))
            except psutil.Error:
                total = 0
            peak = max(peak, total)
            stop.wait(0.05)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    out, _ = proc.communicate()
    stop.set()
    th.join()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode})")
    r = json.loads(out.strip().splitlines()[-1])
    r |= {
        "n": n,
        "tile": tile,
        "workers": workers,
        "untiled": untiled,
        "peak_rss": peak,
        "via": scheduler,
        "grid": grid,
    }
    print(
        f"  {n}^2 {'untiled' if untiled else f'tile {tile} x{workers}'}: {r['triangles']} triangles, "
        f"{r['seconds']:.1f} s ({r['cpu_seconds']:.1f} CPU s), peak RSS {peak / 2**20:.0f} MiB",
        flush=True,
    )
    return r


def dem_overhead() -> list[dict]:
    """The benchmark DEMs: triangles tiled (default tile and smaller ones) against untiled, in process."""
    import datasets as D
    from wavemesh import api, tiles
    from wavemesh.io.heightfield import from_array
    from wavemesh.refine.native import RefineParams

    rows = []
    for name in DEMS:
        g = D.load(name)
        hf = from_array(g.values, source=name)
        zeta = 0.005 * g.height_range
        params = api.MeshParams(refine=RefineParams(zeta=zeta, metric="vertical"))
        base = api.mesh(hf, params).mesh.n_triangles
        src = tiles.Source("array", hf.width, hf.height, array=hf.values, name=name)
        row = {"name": name, "size": [hf.width, hf.height], "zeta": zeta, "untiled": base, "tiled": {}}
        for tile in (tiles.default_tile(2), *DEM_TILES):
            t = tiles.mesh_tiled(src, params, tile, workers=1)
            row["tiled"][str(tile)] = {"tiles": len(t.tiles), "triangles": t.mesh.n_triangles}
        rows.append(row)
        print(
            f"  {name} {hf.width} x {hf.height}: untiled {base}, "
            + ", ".join(f"tile {k}: {v['triangles']} ({v['tiles']} tiles)" for k, v in row["tiled"].items()),
            flush=True,
        )
    return rows


def freeze_library() -> str:
    """HEAD's package and refiner, exported (git archive) and built aside for every run of this benchmark
    (PYTHONPATH, WAVEMESH_FIRMWARE_LIB): one commit for all of them, whatever the tree holds or does
    meanwhile.  Returns the commit."""
    import shutil

    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=BENCH, check=True
    ).stdout.strip()
    src = WORK / "src"
    shutil.rmtree(src, ignore_errors=True)
    src.mkdir(parents=True)
    archive = subprocess.run(
        ["git", "archive", commit, "host", "firmware", "tests/firmware"],
        capture_output=True,
        cwd=BENCH.parent,
        check=True,
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    # the generated headers the firmware includes (fixed.c's wm_angle.h), by HEAD's own generator
    subprocess.run([sys.executable, "-m", "wavemesh.device.gen", str(src / "build" / "gen")], check=True,
                   capture_output=True, env={**os.environ, "PYTHONPATH": str(src / "host")})
    build = src / "build" / "firmware-native"
    subprocess.run(
        ["cmake", "-S", str(src / "firmware"), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release"],
        check=True,
        capture_output=True,
    )
    subprocess.run(
        ["cmake", "--build", str(build), "-j2", "--target", "wavemesh_shared"],
        check=True,
        capture_output=True,
    )
    os.environ["WAVEMESH_FIRMWARE_LIB"] = str(build / "libwavemesh.so")
    os.environ["PYTHONPATH"] = str(src / "host")
    return commit


def workers_series() -> list[int]:
    """1, 2, 4, ... up to TILES_WORKERS_MAX (default: the CPUs this process may use), that one included."""
    from wavemesh import tiles

    top = int(os.environ.get("TILES_WORKERS_MAX") or tiles.default_workers())
    series = [1 << k for k in range(top.bit_length()) if 1 << k <= top]
    return series + ([top] if series[-1] != top else [])


def run() -> dict:
    from wavemesh import tiles

    schedulers = [os.environ["TILES_SCHEDULER"]] if os.environ.get("TILES_SCHEDULER") else []

    commit = freeze_library()

    d = tiles.default_tile(2)
    sizes = [int(s) for s in os.environ.get("TILES_SIZES", " ".join(map(str, SIZES))).split()]
    out: dict = {
        "zeta": ZETA,
        "default_tile": d,
        "available_gib": tiles.available_memory() / 2**30,
        "commit": commit,
        "growth": [],
        "tile_size": [],
        "workers": [],
        "untiled": [],
    }
    for n in sizes:
        terrain_file(n)
    for n in sizes:
        out["growth"].append(run_child(n, d, 2))
    if TILE_N in sizes:
        for tile in TILE_SIZES:
            if tile != d:
                out["tile_size"].append(run_child(TILE_N, tile, 2))
        out["workers"] = [
            run_child(TILE_N, WORKERS_TILE, w, scheduler=via)
            for via in ("", *schedulers)
            for w in workers_series()
        ]
    for n in sizes:  # one untiled run beside each (its memory too: the whole grid at once)
        out["untiled"].append(run_child(n, d, 1, untiled=True))
        if n in (1024, 2048):
            for tile in (513, 257):
                out["tile_size"].append(run_child(n, tile, 2))
    out["real"] = [run_child(REAL_N, t, 2, untiled=t == 0, grid=REAL) for t in (0, *REAL_TILES)]
    out["dems"] = json.loads(_child(["dems"]).strip().splitlines()[-1])  # with the frozen package too
    return out


def _mib(b: float) -> str:
    return f"{b / 2**20:,.0f}"


def _row(*cells) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def markdown(r: dict) -> str:
    import math

    d = r["default_tile"]
    by = {(x["n"], x["tile"], x["workers"]): x for x in r["growth"] + r["tile_size"]}
    lines = [
        f"`make bench-tiles` (bench/bench_tiles.py): `wavemesh mesh --tile` on the seeded synthetic "
        f"terrain (bench/datasets.py `terrain`, the unit square sampled n x n, a float32 .npy read through "
        f"a memmap), --metric vertical --zeta {r['zeta']:g}; every run a process of its own, the peak RSS "
        f"of its process tree (pool workers included) sampled every 50 ms.  Default tile: {d} "
        f"(tiles.default_tile for 2 workers, "
        f"{r.get('available_gib', 0):.0f} GiB available at the run); every run with the package and "
        f"refiner of {r.get('commit', '?')} (exported and built aside).",
        "",
        "**Growth** (default tile, 2 workers):",
        "",
        "| n^2 | tiles | triangles | E_max | wall s | CPU s | peak RSS MiB | <= 2 GiB |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for x in r["growth"]:
        lines.append(
            _row(
                f"{x['n']}^2",
                x["tiles"],
                f"{x['triangles']:,}",
                f"{x['e_max']:.3f}",
                f"{x['seconds']:.1f}",
                f"{x['cpu_seconds']:.1f}",
                _mib(x["peak_rss"]),
                "yes" if x["peak_rss"] <= RSS_BAR else "NO",
            )
        )
    g = r["growth"]
    if len(g) >= 2:
        ratio, samples = g[-1]["seconds"] / g[0]["seconds"], (g[-1]["n"] / g[0]["n"]) ** 2
        lines += [
            "",
            f"Cost growth {g[0]['n']}^2 -> {g[-1]['n']}^2: wall time ~ samples^"
            f"{math.log(ratio) / math.log(samples):.2f} ({ratio:.1f}x the time for {samples:.0f}x the "
            f"samples); CPU {g[-1]['cpu_seconds'] / g[0]['cpu_seconds']:.1f}x.",
        ]
    rows = sorted(
        (x for x in r["tile_size"] + [by.get((TILE_N, d, 2))] if x), key=lambda x: (x["n"], x["tile"])
    )
    if rows:
        lines += [
            "",
            "**Tile size** (2 workers):",
            "",
            "| n^2 | tile | tiles | triangles | wall s | CPU s | peak RSS MiB |",
            "|---|---|---|---|---|---|---|",
        ]
        for x in rows:
            lines.append(
                _row(
                    f"{x['n']}^2",
                    x["tile"],
                    x["tiles"],
                    f"{x['triangles']:,}",
                    f"{x['seconds']:.1f}",
                    f"{x['cpu_seconds']:.1f}",
                    _mib(x["peak_rss"]),
                )
            )
    for via in dict.fromkeys(x.get("via", "") for x in r["workers"]):
        series = [x for x in r["workers"] if x.get("via", "") == via]
        t1 = next((x for x in series if x["workers"] == 1), None)
        if not t1:
            continue
        lines += [
            "",
            f"**Workers** ({TILE_N}^2, tile {WORKERS_TILE}, {'Dask ' + via if via else 'the local pool'}): "
            "the speed-up t1 / tw, the parallel efficiency t1 / (w tw), and the parent's own CPU time (its "
            "workers apart) against t1, the serial part that bounds the speed-up (at most t1 / parent).  "
            "One worker runs in the run's own process (its parent time is all the work).  One run each: wall "
            "times on a machine shared with other jobs are noisy, CPU seconds beside them; the 2-core bar's "
            "measure is `bench_tiles.py pair` (whole processes in turn, medians: docs/tiles.md).",
            "",
            "| workers | wall s | speed-up | efficiency | CPU s | parent CPU s | parent / t1 | peak MiB |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for x in series:
            lines.append(
                _row(
                    x["workers"],
                    f"{x['seconds']:.1f}",
                    f"{t1['seconds'] / x['seconds']:.2f}x",
                    f"{t1['seconds'] / (x['workers'] * x['seconds']):.2f}",
                    f"{x['cpu_seconds']:.1f}",
                    f"{x.get('parent_cpu_seconds', 0):.2f}",
                    f"{100 * x.get('parent_cpu_seconds', 0) / t1['seconds']:.1f} %",
                    _mib(x["peak_rss"]),
                )
            )
    if r["untiled"]:
        lines += [
            "",
            "**Overhead against one untiled run** (triangles), terrain; the untiled run's wall time and "
            "peak RSS (the whole grid at once) beside it:",
            "",
            "| n^2 | untiled | untiled wall s | untiled peak RSS MiB | tile | tiles | tiled | overhead |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for u in r["untiled"]:
            for x in sorted(
                (x for x in r["growth"] + r["tile_size"] if x["n"] == u["n"]), key=lambda x: -x["tile"]
            ):
                lines.append(
                    _row(
                        f"{u['n']}^2",
                        f"{u['triangles']:,}",
                        f"{u['seconds']:.1f}",
                        _mib(u["peak_rss"]),
                        x["tile"],
                        x["tiles"],
                        f"{x['triangles']:,}",
                        f"{100 * (x['triangles'] / u['triangles'] - 1):+.1f} %",
                    )
                )
    real = r.get("real") or []
    base = next((x for x in real if x["untiled"]), None)
    if base:
        lines += [
            "",
            f"**Seams on a real DEM**: {REAL} mirror-tiled to {REAL_N}^2 (bench_big.mirror_tile), --metric "
            f"vertical, zeta {100 * REAL_ZETA:g} % of its height range; triangles against one untiled run "
            f"({base['triangles']:,}, {base['seconds']:.1f} s):",
            "",
            "| tile | tiles | triangles | overhead | wall s (2 workers) | E_max |",
            "|---|---|---|---|---|---|",
        ]
        for x in real:
            if not x["untiled"]:
                lines.append(
                    _row(
                        x["tile"],
                        x["tiles"],
                        f"{x['triangles']:,}",
                        f"{100 * (x['triangles'] / base['triangles'] - 1):+.1f} %",
                        f"{x['seconds']:.1f}",
                        f"{x['e_max']:.3f}",
                    )
                )
    if r.get("dems"):
        tiles_ = list(r["dems"][0]["tiled"])
        lines += [
            "",
            "Benchmark DEMs (bench_quality's real ones; --metric vertical, zeta 0.5 % of the height range):",
            "",
            _row("DEM", "size", "untiled", *(f"tile {t}" for t in tiles_)),
            "|---|---|---|" + "---|" * len(tiles_),
        ]
        for x in r["dems"]:
            cells = [
                f"{v['triangles']:,} ({100 * (v['triangles'] / x['untiled'] - 1):+.1f} %, {v['tiles']} tiles)"
                for v in x["tiled"].values()
            ]
            lines.append(_row(x["name"], f"{x['size'][0]} x {x['size'][1]}", f"{x['untiled']:,}", *cells))
    return "\n".join(lines) + "\n"


# `wavemesh` as its console script runs it (the package sees the command: wavemesh/__init__.py), with the
# tiles.runner settings of WAVEMESH_BENCH_RUNNER ("NAME=VALUE,...") set first: pair's --against runs
LAUNCHER = """\
import os, sys
from wavemesh.tiles import runner
for kv in filter(None, os.environ.get("WAVEMESH_BENCH_RUNNER", "").split(",")):
    k, v = kv.split("=")
    setattr(runner, k, type(getattr(runner, k))(int(v)))
from wavemesh.cli import main
sys.exit(main())
"""


def pair(n: int = TILE_N, tile: int = WORKERS_TILE, workers: int = 2, runs: int = 5,
         against: str | None = None) -> dict:
    """`wavemesh mesh` of the n^2 terrain in tiles of ``tile`` with 1 worker and with ``workers``, whole
    processes in turn (1, w, 1, w, ...; one of each first, not counted): each run's wall and CPU seconds
    (its process tree), the medians, t1 / tw of the medians and the median of the pairs' ratios, and
    whether both wrote the same bytes.  ``against`` ("NAME=VALUE,...", tiles.runner's settings, e.g.
    "AHEAD=0,PIN=0"): ``workers`` workers with those settings in place of 1 worker (both through
    a launcher that the package takes for the command, as the console script), the ratio theirs / ours.
    A run's wall time ends with its process (the pool's workers may still be exiting then: the bench waits
    for them before the next run and counts their CPU).  The runs import compiled modules, as an installed
    package does: compiled by the first two runs (not counted) into a cache of their own
    (PYTHONPYCACHEPREFIX under the bench's folder, PYTHONDONTWRITEBYTECODE dropped; with it set and no
    cache, every run compiled the package's modules again at its start)."""
    import statistics

    from bench_big import run_process  # bench/ is on the path (as mirror_tile's import)

    path = terrain_file(n)
    root = BENCH.parent
    out = WORK / "pair"
    out.mkdir(parents=True, exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(WORK / "pycache")

    launcher = WORK / "launch" / "wavemesh"
    if against is not None:
        launcher.parent.mkdir(parents=True, exist_ok=True)
        launcher.write_text(LAUNCHER)

    def run1(w: int) -> tuple[float, float]:
        other = against is not None and w == 1  # the settings' run in 1's place
        cmd = [
            sys.executable,
            *((str(launcher),) if against is not None else ("-m", "wavemesh.cli")),
            "mesh",
            str(path),
            "-o",
            str(out / f"w{w}.obj"),
            "--tile",
            str(tile),
            "--metric",
            "vertical",
            "--zeta",
            str(ZETA),
            "--workers",
            str(workers if other else w),
            "--quiet",
        ]
        # its wall time to its return; its CPU with its workers' that were still exiting (reaped before the
        # next run starts)
        r = run_process(cmd, cwd=root, env=env | {"WAVEMESH_BENCH_RUNNER": against if other else ""})
        if r["rc"]:
            raise RuntimeError(f"{' '.join(cmd)}: exit status {r['rc']}: {r['error']}")
        return r["wall_s"], r["cpu_s"]

    run1(1), run1(workers)
    got: dict = {1: [], workers: []}
    for _ in range(runs):
        for w in (1, workers):
            got[w].append(run1(w))
            name = f"x{workers} {against}" if against is not None and w == 1 else f"x{w}"
            print(
                f"  {n}^2 tile {tile} {name}: {got[w][-1][0]:.2f} s wall, {got[w][-1][1]:.2f} s CPU",
                flush=True,
            )
    med = {
        w: (statistics.median(x[0] for x in v), statistics.median(x[1] for x in v)) for w, v in got.items()
    }
    ratio = statistics.median(a[0] / b[0] for a, b in zip(got[1], got[workers], strict=True))
    same = (out / "w1.obj").read_bytes() == (out / f"w{workers}.obj").read_bytes()
    first = f"{workers} workers with {against}" if against is not None else "1 worker"
    print(
        f"{n}^2 tile {tile}: {first} {med[1][0]:.2f} s ({med[1][1]:.2f} CPU s), {workers} workers "
        f"{med[workers][0]:.2f} s ({med[workers][1]:.2f} CPU s): {med[1][0] / med[workers][0]:.2f}x "
        f"(pairs' median {ratio:.2f}x); the same bytes: {'yes' if same else 'NO'}"
    )
    return {"median": med, "pairs": ratio, "same": same}


def _child(args: list[str]) -> str:
    return subprocess.run(
        [sys.executable, str(Path(__file__)), *args], capture_output=True, text=True, cwd=BENCH, check=True
    ).stdout


if __name__ == "__main__":
    if sys.argv[1:2] == ["dems"]:
        print(json.dumps(dem_overhead()))
    elif sys.argv[1:2] == ["one"]:
        n, tile, workers, untiled = (int(a) for a in sys.argv[2:6])
        print(json.dumps(one(n, tile, workers, bool(untiled), *sys.argv[6:8])))
    elif sys.argv[1:2] == ["pair"]:  # 1 worker against w, whole `wavemesh mesh` processes in turn
        import argparse

        ap = argparse.ArgumentParser(prog="bench_tiles.py pair", description=pair.__doc__)
        ap.add_argument("--n", type=int, default=TILE_N)
        ap.add_argument("--tile", type=int, default=WORKERS_TILE)
        ap.add_argument("--workers", type=int, default=2)
        ap.add_argument("--runs", type=int, default=5)
        ap.add_argument("--against", metavar="NAME=VALUE,...",
                        help="in place of 1 worker: --workers with these tiles.runner settings (AHEAD=0,...)")
        a = ap.parse_args(sys.argv[2:])
        sys.exit(0 if pair(a.n, a.tile, a.workers, a.runs, a.against)["same"] else 1)
    else:  # make bench-tiles on a bigger machine: --workers-max N [--scheduler S]
        import argparse

        import run as bench_run

        ap = argparse.ArgumentParser(description="make bench-tiles with other workers (bench/run.py tiles)")
        ap.add_argument("--workers-max", type=int, help="the workers series' top (default: the CPUs)")
        ap.add_argument("--scheduler", help="also through Dask: 'local' (a LocalCluster) or ADDRESS")
        a = ap.parse_args()
        os.environ.update(
            {
                k: str(v)
                for k, v in (("TILES_WORKERS_MAX", a.workers_max), ("TILES_SCHEDULER", a.scheduler))
                if v
            }
        )
        sys.exit(bench_run.main(["tiles"]))
