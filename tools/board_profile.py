#!/usr/bin/env python3
"""Where the soft CPU spends its cycles: one `wavemesh stream` job through the simulated board, profiled.

    .venv/bin/python tools/board_profile.py INPUT [wavemesh stream options ...] [--top N] [--raw FILE]
        [--data] [--firmware FILE.hex] [--check] [--pc-trace FILE]

Builds the board firmware and the simulator and starts `wmsim --fast --profile` (both through
wavemesh.harness.simboard, as the tests and benchmarks do), streams INPUT with the options given (e.g.
`--decimate 8`), and prints the cycles of the whole run (the wait for
the host included: it shows up in the UART receive loop) by function, from the firmware's ELF symbols
(riscv64-unknown-elf-nm).  Every cycle counts against the last instruction fetched (sim/board_main.cpp,
--profile; with the VexRiscv, WM_CPU=vexriscv, the instruction in its last stage): a function's *self*
cycles, not its callees'.

--data also prints where the data accesses wait (wmsim's FILE.data: the cycles each access waited beyond
a block RAM's answer): by memory-map area (the stack and the rest of the firmware RAM, the SDRAM's
HEIGHT, COEF, TOUT) and, in the heap, by the refiner's arrays (firmware/src refine.c and mesh.c's
layout for the job's grid and the board's storage clamp, app/board_job.c), with the reads and writes of each.
"""

from __future__ import annotations

import argparse
import bisect
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from wavemesh.harness import simboard

VENV_BIN = Path(sys.executable).parent


def _symbols(elf: Path) -> list[tuple[int, str]]:
    out = subprocess.run(["riscv64-unknown-elf-nm", "-n", "-C", str(elf)], check=True, capture_output=True,
                         text=True).stdout
    syms = []
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1].lower() == "t":
            syms.append((int(parts[0], 16), parts[2]))
    return syms


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input")
    ap.add_argument("--top", type=int, default=30, help="functions to list (default 30)")
    ap.add_argument("--raw", help="also keep the raw PC histogram here")
    ap.add_argument("--data", action="store_true", help="also the data accesses' waits by area and array")
    ap.add_argument("--firmware", help="profile this image (FILE.hex, FILE.elf beside it), not a new build")
    ap.add_argument("--pc-trace", help="also write wmsim's trace of executed PCs here (tools/code_layout.py)")
    ap.add_argument("--check", action="store_true",
                    help="also run `wavemesh mesh` with the same options: are the meshes equal?")
    args, stream_opts = ap.parse_known_args(argv)
    sim = simboard.build.build_sim()
    hexfile = Path(args.firmware) if args.firmware else simboard.build.build_firmware()
    with tempfile.TemporaryDirectory() as tmp:
        # a copy of the image: the work tree is shared, and a build during the run would move the symbols
        elf = Path(tmp) / "fw.elf"
        shutil.copyfile(hexfile.with_suffix(".elf"), elf)
        shutil.copyfile(hexfile, elf.with_suffix(".hex"))
        hexfile = elf.with_suffix(".hex")
        prof = Path(args.raw) if args.raw else Path(tmp) / "profile.txt"
        board = simboard.SimBoard(sim, hexfile, "--port", "0", "--fast", "--exit-on-close", "--quiet",
                                  "--profile", str(prof),
                                  *(["--pc-trace", args.pc_trace] if args.pc_trace else []))
        report = Path(tmp) / "report.json"
        cmd = [str(VENV_BIN / "wavemesh"), "stream", args.input, *stream_opts, "--port", board.url, "-o",
               str(Path(tmp) / "out.obj"), "--quiet", "--report", str(report),
               *([] if "--timeout" in stream_opts else ["--timeout", "3600"])]
        try:
            rc = subprocess.run(cmd).returncode
            board.wait(timeout=60)
        finally:
            board.stop()
        if rc != 0:
            print(f"error: wavemesh stream exited {rc}", file=sys.stderr)
            return 2
        same = None
        if args.check:
            soft = Path(tmp) / "soft.obj"
            subprocess.run([str(VENV_BIN / "wavemesh"), "mesh", args.input, *stream_opts, "-o", str(soft),
                            "-q"], check=True)
            same = soft.read_bytes() == (Path(tmp) / "out.obj").read_bytes()
        hist = _histogram(prof)
        rep = json.loads(report.read_text())
        stages = rep["device_cycles"]
        if args.data:
            data = [[int(f, 16) if i == 0 else int(f) for i, f in enumerate(ln.split())]
                    for ln in Path(str(prof) + ".data").read_text().splitlines()]
            areas = _areas(rep, elf)
        ibus_file = Path(str(prof) + ".ibus")
        ibus = _histogram(ibus_file) if ibus_file.exists() else None
        syms = _symbols(elf)
    addrs = [a for a, _ in syms]
    per = _by_function(hist, syms, addrs)
    total = sum(per.values())
    print(f"{total:,} cycles")
    print("stages (DONE's counters): "
          + ", ".join(f"{k} {v:,}" for k, v in stages.items() if isinstance(v, int)))
    print("per unit: " + ", ".join(f"{k} {v:,.1f} per {u}" for k, v, u in _per_unit(rep)))
    if same is not None:
        print("the mesh equals wavemesh mesh's" if same else "THE MESH DIFFERS from wavemesh mesh's")
    _print_top(per, total, args.top)
    if ibus is not None:
        _ibus_report(ibus, syms, addrs, total, args.top)
    if args.data:
        _data_report(data, areas, total)
    return 0


def _histogram(path: Path) -> list[tuple[int, int]]:
    """(address, cycles) from a profile file's "HEXADDR COUNT" lines."""
    return [(int(a, 16), int(c)) for a, c in (ln.split() for ln in path.read_text().splitlines())]


def _by_function(hist: list[tuple[int, int]], syms: list[tuple[int, str]],
                 addrs: list[int]) -> dict[str, int]:
    """The cycles of (address, cycles) pairs summed by the function the address is in ("?": before all)."""
    per: dict[str, int] = {}
    for pc, cyc in hist:
        i = bisect.bisect_right(addrs, pc) - 1
        name = syms[i][1] if i >= 0 else "?"
        per[name] = per.get(name, 0) + cyc
    return per


def _print_top(per: dict[str, int], total: int, top: int) -> None:
    """The ``top`` functions of ``per`` by cycles, each with its share of ``total``."""
    for name, cyc in sorted(per.items(), key=lambda kv: -kv[1])[:top]:
        print(f"{cyc:>14,} {100 * cyc / total:6.2f} %  {name}")


def _per_unit(rep: dict) -> list[tuple[str, float, str]]:
    """Each stage's cycles over what it scales with (docs/soc.md's 1024 x 1024 extrapolation): samples,
    the initial triangulation's triangles (the templates': the report's initial.triangles, DONE's), output
    triangles, level-stream bytes."""
    c = rep["device_cycles"]
    samples = rep["input"]["width"] * rep["input"]["height"]
    stream = rep["transfer"]["mesh_bytes"]
    out = rep["refiner"]["levels"][-1]["triangles"] if "refiner" in rep else rep["initial"]["triangles"]
    return [("receive", c["receive"] / samples, "sample"), ("filter", c["filter"] / samples, "sample"),
            ("template", c["template"] / rep["initial"]["triangles"], "template triangle"),
            ("refine", c["refine"] / out, "output triangle"), ("emit", c["emit"] / stream, "stream byte"),
            ("link", c["link"] / stream, "stream byte")]


def _refiner_struct_bytes() -> int:
    """sizeof(struct wm_refiner) on the board (rv32, 32-bit indices), from the cross compiler."""
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        src, obj = Path(tmp) / "probe.c", Path(tmp) / "probe.o"
        src.write_text('#include "wm_internal.h"\nchar probe[sizeof(struct wm_refiner)];\n')
        subprocess.run(["riscv64-unknown-elf-gcc", "-ffreestanding", "-march=rv32im", "-mabi=ilp32",
                        "-DWM_INDEX_BITS=32", f"-I{root / 'firmware/src'}", f"-I{root / 'firmware/include'}",
                        f"-I{root / 'build/gen'}", "-c", str(src), "-o", str(obj)], check=True)
        out = subprocess.run(["riscv64-unknown-elf-nm", "-S", str(obj)], check=True, capture_output=True,
                             text=True).stdout
    return int(out.split()[1], 16)


def _native(name: str, *args: int) -> int:
    """A layout function of firmware/src/mesh.c (wm_tri_cap_skewed: the board's capacity clamp) from the
    native library, the same source the board's firmware is built from."""
    import ctypes

    from wavemesh.refine import native

    fn = getattr(native.load(), name)
    fn.restype = ctypes.c_int32
    fn.argtypes = [ctypes.c_int32] * len(args)
    return int(fn(*args))


def _ibus_report(ibus: list[tuple[int, int]], syms: list[tuple[int, str]], addrs: list[int], total: int,
                 top: int) -> None:
    """The cycles instruction fetches waited (the VexRiscv's cache refills), by the function fetched."""
    per = _by_function(ibus, syms, addrs)
    n = sum(per.values())
    print(f"\ninstruction fetches: {n:,} cycles waited for memory ({100 * n / total:.2f} % of all), "
          "by the function at the start of the line fetched")
    _print_top(per, total, min(top, 15))


def _areas(rep: dict, elf: Path) -> list[tuple[int, str]]:
    """(start address, name), ascending: the firmware RAM's parts, the SDRAM's areas, the refiner's arrays."""
    from wavemesh.device import memmap as mm

    def a8(n: int) -> int:
        return (n + 7) & ~7

    syms = {}
    for line in subprocess.run(["riscv64-unknown-elf-nm", str(elf)], check=True, capture_output=True,
                               text=True).stdout.splitlines():
        parts = line.split()
        if len(parts) == 3:
            syms[parts[2]] = int(parts[0], 16)
    w, h = rep["input"]["width"], rep["input"]["height"]
    cap = rep["device"]["tri_capacity"]
    grid = 2 * (w - 1) * (h - 1)  # board_job.c's clamp (wm_tri_cap_max), skewed
    if 2 <= grid < cap:
        cap = _native("wm_tri_cap_skewed", w, h, grid, cap)
    vc = cap // 2 + w + h + 2  # wm_vert_cap_for
    items = max(cap, vc)
    out = [(mm.FW_RAM.base, "firmware RAM: code, rodata"), (syms["__data_start"], "firmware RAM: data, bss"),
           (syms["__bss_end"], "firmware RAM: free"), (syms["__stack_bottom"], "firmware RAM: stack"),
           (mm.HEIGHT.base, "SDRAM HEIGHT (samples)"), (mm.COEF.base, "SDRAM COEF (details)"),
           (mm.TOUT.base, "SDRAM TOUT"), (mm.HEAP.base, "heap: struct wm_refiner")]
    q = mm.HEAP.base + a8(_refiner_struct_bytes())
    for name, size in (("he", 24 * cap), ("vh", 4 * vc), ("vxy", 4 * vc),
                       ("tflag", cap), ("err", 4 * cap), ("worst", 4 * cap), ("list", 8 * items),
                       ("pos", 4 * items), ("vkey", 4 * vc), ("vapex", vc)):
        out.append((q, f"heap: {name}"))
        q += a8(size) if name not in ("err", "list") else size
    out.append((q, "heap: above the refiner (staging, hole mask)"))
    return out


def _data_report(data: list[list[int]], areas: list[tuple[int, str]], total: int) -> None:
    starts = [a for a, _ in areas]
    per: dict[str, list[int]] = {}
    for block, wait, reads, writes in data:
        i = bisect.bisect_right(starts, block) - 1
        name = areas[i][1] if i >= 0 else "?"
        acc = per.setdefault(name, [0, 0, 0])
        acc[0] += wait
        acc[1] += reads
        acc[2] += writes
    waited = sum(v[0] for v in per.values())
    share = 100 * waited / total
    print(f"\ndata accesses: {waited:,} cycles waited beyond a block RAM's ({share:.2f} % of all)")
    print(f"{'waited':>14} {'share':>8} {'reads':>14} {'writes':>14}  area")
    for name, (wait, reads, writes) in sorted(per.items(), key=lambda kv: -kv[1][0]):
        print(f"{wait:>14,} {100 * wait / max(waited, 1):6.2f} % {reads:>14,} {writes:>14,}  {name}")


if __name__ == "__main__":
    sys.exit(main())
