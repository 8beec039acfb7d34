#!/usr/bin/env python3
"""The hot code's order in the board's firmware RAM, chosen by replaying real jobs through a model of the
instruction cache.

    .venv/bin/python tools/code_layout.py [--seconds S] [--seed N] [--traces DIR] [--write]

The VexRiscv's instruction cache is one way (docs/soc.md, "The caches"): two functions that run in the same
loop and lie a multiple of its size apart take each other's lines, and every refill costs some 9 cycles.
The image's hot code is several times the cache, so where each function lands decides how many cycles the
fetches wait, and any change of code size moves it (docs/soc.md, "Cost model": the fetches' share).

This tool runs bench-soc's tuning jobs (bench/bench_soc.py's CASES less the held-out one) through the
simulated board with `tools/board_profile.py --pc-trace` (every executed PC, and the cache flushes at the
stage writes), replays the traces through a model of the cache (a direct-mapped cache of `icache_kib` of
the SoC's CPU in 32-byte lines: a miss whenever a line's set last held another line or was flushed since),
and searches an order of the hot code's functions (those placed after the cold code: board.ld) that the
model says misses least: a hill climb that moves one function (with its clones, which the linker script's
pattern places together) to another place in the order.  It prints the model's misses and the cycles the
fetches waited (wmsim's profile) per job, the held-out job's apart (never used in the search), and with
--write puts the order into firmware/board/hot_order.txt, which the board's build turns into the hot
code's order (firmware/board/CMakeLists.txt, wm_hot.ld).  Rerun it when the fetch waits of
`tools/board_profile.py` grow after code changes.  --traces DIR keeps the traces (and reuses those there).
"""

from __future__ import annotations

import argparse
import hashlib
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import bench_soc  # noqa: E402  (bench/: the jobs)
import board_profile  # noqa: E402  (tools/: its profile files' reader)

ORDER_FILE = ROOT / "firmware" / "board" / "hot_order.txt"
LINE_BYTES = 32  # the VexRiscv's cache lines (docs/soc.md, "CPU")
FLUSH = 0xFFFFFFFF  # wmsim --pc-trace's mark of a stage write (the firmware flushes the caches there)


def functions(elf: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The ELF's functions in address order: (starts, sizes, names)."""
    out = subprocess.run(["riscv64-unknown-elf-nm", "-S", "-n", str(elf)], check=True, capture_output=True,
                         text=True).stdout
    st, sz, nm = [], [], []
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "tTwW":
            st.append(int(parts[0], 16))
            sz.append(int(parts[1], 16))
            nm.append(parts[3])
    return np.array(st, np.int64), np.array(sz, np.int64), nm


class Trace:
    """One job's PC trace, as runs of PCs within one function's line and one flush epoch: the refs a layout
    maps to lines (a run's first and last PC, whose lines differ when the layout splits it)."""

    def __init__(self, path: Path, starts: np.ndarray):
        t = np.fromfile(path, dtype="<u4").astype(np.int64)
        flush = t == FLUSH
        epoch = np.cumsum(flush)[~flush]
        t = t[~flush]
        f = np.searchsorted(starts, t, side="right") - 1
        key = (f << 40) | ((t // LINE_BYTES) << 8) | (epoch & 0xFF)
        first = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
        self.f = f[first]
        self.epoch = epoch[first]
        self.lo = np.minimum.reduceat(t, first) - starts[self.f]
        self.hi = np.maximum.reduceat(t, first) - starts[self.f]

    def misses(self, starts: np.ndarray, sets: int) -> int:
        """The model's misses with the functions at `starts`."""
        a = (starts[self.f] + self.lo) // LINE_BYTES
        b = (starts[self.f] + self.hi) // LINE_BYTES
        two = b != a
        pos = np.arange(len(a)) + np.concatenate([[0], np.cumsum(two)[:-1]])
        n = len(a) + int(two.sum())
        lines = np.empty(n, np.int64)
        epoch = np.empty(n, np.int64)
        lines[pos], epoch[pos] = a, self.epoch
        lines[pos[two] + 1], epoch[pos[two] + 1] = b[two], self.epoch[two]
        s = (lines % sets).astype(np.int16)
        o = np.argsort(s, kind="stable")  # each set's refs in order (a radix sort)
        lo, eo, so = lines[o], epoch[o], s[o]
        hit = (lo[1:] == lo[:-1]) & (eo[1:] == eo[:-1]) & (so[1:] == so[:-1])
        return n - int(hit.sum())


class Layout:
    """The hot code as units (a function with its clones: `name`, `name.constprop.0`, ...: one pattern of
    wm_hot.ld), placed one after another from the hot code's start, each function at 2 bytes (board.ld's
    sections: rv32imc code)."""

    def __init__(self, starts: np.ndarray, sizes: np.ndarray, names: list[str], hot_start: int, hot_end: int,
                 sections: set[str] | None = None):
        self.starts, self.sizes = starts, sizes
        self.hot_start = hot_start
        self.units: dict[str, list[int]] = {}
        for i, n in enumerate(names):
            if hot_start <= starts[i] < hot_end:
                self.units.setdefault(n.split(".")[0], []).append(i)
        # a function without a section of its own (libgcc's, in .text) stays after the ordered ones
        self.fixed = [u for u in self.units if sections is not None and u not in sections]

    def orderable(self) -> list[str]:
        """The units the order may place, in their present order."""
        return [u for u in self.units if u not in self.fixed]

    def place(self, order: list[str]) -> np.ndarray:
        new = self.starts.copy()
        c = self.hot_start
        for u in order + self.fixed:
            for f in self.units[u]:
                c += c & 1
                new[f] = c
                c += int(self.sizes[f])
        return new


def own_sections(map_file: Path) -> set[str]:
    """The functions with a section of their own (`.text.NAME`, `.text.NAME.constprop.0`, ...) in the
    linker's map: those wm_hot.ld's patterns can place."""
    return {ln.split()[0][len(".text."):].split(".")[0] for ln in map_file.read_text().splitlines()
            if ln.startswith(" .text.")}


def hot_range(elf: Path) -> tuple[int, int]:
    """Where the hot code starts (board.ld's __wm_hot_start, after the cold code) and where .text ends."""
    out = subprocess.run(["riscv64-unknown-elf-nm", str(elf)], check=True, capture_output=True,
                         text=True).stdout
    syms = {p[2]: int(p[0], 16) for p in (ln.split() for ln in out.splitlines()) if len(p) == 3}
    out = subprocess.run(["riscv64-unknown-elf-readelf", "-S", "-W", str(elf)], check=True,
                         capture_output=True, text=True).stdout
    text = next(ln.split() for ln in out.splitlines() if " .text " in ln)
    i = text.index(".text")
    return syms["__wm_hot_start"], int(text[i + 2], 16) + int(text[i + 4], 16)


def run_jobs(folder: Path, cases: list[str], elf: Path) -> None:
    """Each case through tools/board_profile.py --pc-trace, into folder/NAME.pc (kept if there, when they
    are of this image: folder/image.sha256 says which image they are of)."""
    digest = hashlib.sha256(elf.read_bytes()).hexdigest()
    stamp = folder / "image.sha256"
    if stamp.exists() and stamp.read_text().strip() != digest:
        raise SystemExit(f"error: the traces in {folder} are of another firmware image: remove them or give "
                         "another --traces folder")
    stamp.write_text(digest + "\n")
    bench_soc._inputs(folder)
    from wavemesh.harness import jacksboro

    for name in cases:
        out = folder / (_slug(name) + ".pc")
        if out.exists():
            continue
        file, opts = bench_soc.CASES[name]
        src = jacksboro() if file == "JACKSBORO" else str(folder / file)
        print(f"code_layout: tracing {name}", flush=True)
        subprocess.run([sys.executable, str(ROOT / "tools" / "board_profile.py"), src, *opts, "--top", "0",
                        "--firmware", str(elf.with_suffix(".hex")),
                        "--raw", str(folder / (_slug(name) + ".prof")), "--pc-trace", str(out)],
                       check=True, stdout=subprocess.DEVNULL)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name)


def fetch_waits(folder: Path, name: str) -> int:
    """The cycles the job's instruction fetches waited (wmsim's FILE.ibus)."""
    return sum(c for _, c in board_profile._histogram(folder / (_slug(name) + ".prof.ibus")))


def search(layout: Layout, traces: list[Trace], sets: int, order: list[str], seconds: float,
           seed: int) -> tuple[list[str], int]:
    """Hill climb: move one unit (drawn by its share of the traces' runs) to a random place; keep the order
    when the model misses no more."""
    def cost(o: list[str]) -> int:
        new = layout.place(o)
        return sum(t.misses(new, sets) for t in traces)

    runs = np.zeros(len(layout.starts))
    for t in traces:
        np.add.at(runs, t.f, 1)
    weight = {u: float(np.sqrt(sum(runs[f] for f in fs))) for u, fs in layout.units.items()}
    movable = [u for u in order if weight[u] > 0]
    rng = random.Random(seed)
    best = cost(order)
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        u = rng.choices(movable, weights=[weight[m] for m in movable])[0]
        o = [x for x in order if x != u]
        o.insert(rng.randrange(len(o) + 1), u)
        c = cost(o)
        if c <= best:
            best, order = c, o
    return order, best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=600, help="the search's time (default 600)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--traces", help="keep the traces in this folder (and reuse those already there)")
    ap.add_argument("--write", action="store_true",
                    help=f"write the order into {ORDER_FILE.relative_to(ROOT)}")
    args = ap.parse_args(argv)

    from wavemesh.device import soc_cpu
    from wavemesh.harness import simboard

    sets = soc_cpu.selected().icache_kib * 1024 // LINE_BYTES
    if not sets:
        print("error: the SoC's CPU has no instruction cache to lay the code out for (CPU=vexriscv)",
              file=sys.stderr)
        return 2
    tuning = [n for n in bench_soc.CASES if n not in bench_soc.HELD_OUT]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.traces) if args.traces else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        elf = simboard.build.build_firmware().with_suffix(".elf")
        run_jobs(folder, list(bench_soc.CASES), elf)
        starts, sizes, names = functions(elf)
        hot_start, hot_end = hot_range(elf)
        layout = Layout(starts, sizes, names, hot_start, hot_end,
                        own_sections(elf.with_suffix(".map")))
        traces = {n: Trace(folder / (_slug(n) + ".pc"), starts) for n in bench_soc.CASES}
        order, _ = search(layout, [traces[n] for n in tuning], sets, layout.orderable(), args.seconds,
                          args.seed)
        new = layout.place(order)
        print(f"{'job':<28} {'fetch waits':>12} {'model misses':>13} {'in the new order':>17}")
        for n in bench_soc.CASES:
            was, now = traces[n].misses(starts, sets), traces[n].misses(new, sets)
            print(f"{n:<28} {fetch_waits(folder, n):>12,} {was:>13,} {now:>10,} ({now / was:.2f})")
    if args.write:
        old = ORDER_FILE.read_text().splitlines() if ORDER_FILE.exists() else []
        head = [ln for ln in old if ln.startswith("#")]
        ORDER_FILE.write_text("\n".join(head + order) + "\n")
        print(f"wrote {ORDER_FILE.relative_to(ROOT)} ({len(order)} functions)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
