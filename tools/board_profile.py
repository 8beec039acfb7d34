#!/usr/bin/env python3
"""Where the soft CPU spends its cycles: one `wavemesh stream` job through the simulated board, profiled.

    .venv/bin/python tools/board_profile.py INPUT [wavemesh stream options ...] [--top N] [--raw FILE]

Builds the board firmware and the simulator and starts `wmsim --fast --profile` (both through
wavemesh.harness.simboard, as the tests and benchmarks do), streams INPUT with the options given (e.g.
`--decimate 8`), and prints the cycles of the whole run (the wait for
the host included: it shows up in the UART receive loop) by function, from the firmware's ELF symbols
(riscv64-unknown-elf-nm).  Every cycle counts against the last instruction fetched (sim/board_main.cpp,
--profile): a function's *self* cycles, not its callees'.
"""

from __future__ import annotations

import argparse
import bisect
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
    args, stream_opts = ap.parse_known_args(argv)
    sim, hexfile = simboard.build.build_sim(), simboard.build.build_firmware()
    elf = hexfile.with_suffix(".elf")
    with tempfile.TemporaryDirectory() as tmp:
        prof = Path(args.raw) if args.raw else Path(tmp) / "profile.txt"
        board = simboard.SimBoard(sim, hexfile, "--port", "0", "--fast", "--exit-on-close", "--quiet",
                                  "--profile", str(prof))
        cmd = [str(VENV_BIN / "wavemesh"), "stream", args.input, *stream_opts, "--port", board.url, "-o",
               str(Path(tmp) / "out.obj"), "--quiet",
               *([] if "--timeout" in stream_opts else ["--timeout", "3600"])]
        try:
            rc = subprocess.run(cmd).returncode
            board.wait(timeout=60)
        finally:
            board.stop()
        if rc != 0:
            print(f"error: wavemesh stream exited {rc}", file=sys.stderr)
            return 2
        hist = [(int(a, 16), int(c)) for a, c in (ln.split() for ln in prof.read_text().splitlines())]
    syms = _symbols(elf)
    addrs = [a for a, _ in syms]
    per: dict[str, int] = {}
    for pc, cyc in hist:
        i = bisect.bisect_right(addrs, pc) - 1
        name = syms[i][1] if i >= 0 else "?"
        per[name] = per.get(name, 0) + cyc
    total = sum(per.values())
    print(f"{total:,} cycles")
    for name, cyc in sorted(per.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"{cyc:>14,} {100 * cyc / total:6.2f} %  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
