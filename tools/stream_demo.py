#!/usr/bin/env python3
"""`make demo`'s device half: start a device, stream a real DEM through it, stop it, say what was written.

    python tools/stream_demo.py --device sim|native [--out out] [--mode fast|pin]

Builds what it needs (the simulated board: board firmware and Verilator model, sim/build.py; the
native stand-in device: CMake), starts it on a free port of 127.0.0.1, runs

    wavemesh stream jacksboro_fault_dem.npz --key elevation --decimate N --zeta Z ... --port socket://...

(the Jacksboro fault DEM that ships with matplotlib, 403 x 344 samples of 3 arc-seconds, 74.6 m x
92.5 m, whose ridges the normal metric now sees in ground units.  The simulated board gets it
decimated by 16 to 26 x 22 with zeta 10 m, 817 triangles: some 11 M cycles of the soft CPU (0.28 s
of the board at 39 MHz; the stream's `device:` line gives each stage's time), which the simulator
runs in under a minute (its speed: docs/soc.md, "The simulated board").  The
whole DEM through the simulated board is `make bench-soc-full SOC_FULL=jacksboro`: some 0.65 G cycles,
about 9 to 11 minutes of the simulator's CPU (docs/soc.md, "The simulated board").  The native
stand-in device, given storage for 65536 triangles, gets it decimated by 2 to 202 x 172 with zeta
15 m, 14376 triangles.)  It writes the mesh, every level's mesh, a picture and a report into --out,
checks the mesh, and stops the device.  Exit status: that of `wavemesh stream` (0, or 3 when the
budget stopped it).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

from wavemesh.harness import jacksboro
from wavemesh.harness.devproc import DeviceProcess  # the device-process helper the tests use

ROOT = Path(__file__).resolve().parents[1]

VENV_BIN = Path(sys.executable).parent
# Per device: the input and bound (see the docstring for why)
STREAM_OPTS = {"sim": ["--key", "elevation", "--decimate", "16", "--zeta", "10"],
               "native": ["--key", "elevation", "--decimate", "2", "--zeta", "15"]}
START_TIMEOUT = 20.0  # s for the device to say it is listening
NATIVE_TRIANGLES = 65536  # the native stand-in's storage: Jacksboro / 2 at 15 m ends at 14376 triangles


def device_command(kind: str, mode: str) -> list[str]:
    if kind == "native":
        from wavemesh.harness.nativedev import build_wmdev

        print("demo: building the native stand-in device (firmware/board/native)", flush=True)
        return [str(build_wmdev()), "--port", "0", "--tri-capacity", str(NATIVE_TRIANGLES)]
    from wavemesh.harness.simboard import build  # sim/build.py as a module

    print("demo: building the board firmware and the simulated board (about a minute the first time)",
          flush=True)
    hexfile = build.build_firmware()
    exe = build.build_sim()
    return [str(exe), "--firmware", str(hexfile), "--port", "0", *(["--fast"] if mode == "fast" else [])]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", choices=("sim", "native"), default="sim")
    ap.add_argument("--mode", choices=("fast", "pin"), default="fast",
                    help="simulated board: fast UART mode (default) or pin-accurate at 115200 baud")
    ap.add_argument("--out", default=str(ROOT / "out"))
    ap.add_argument("--timeout", default="1800", help="wavemesh stream --timeout (the simulated CPU is slow)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "jacksboro-board" if args.device == "sim" else "jacksboro-native"

    cmd = device_command(args.device, args.mode)
    try:
        device = DeviceProcess(cmd, start_timeout=START_TIMEOUT)
    except AssertionError as e:
        print(f"demo: {e}", file=sys.stderr)
        return 1
    try:
        url = device.url
        print(f"demo: {device.lines[0]}", flush=True)
        src = jacksboro()
        opts = STREAM_OPTS[args.device]
        print(f"demo: streaming {src} (403 x 344, {' '.join(opts[2:])}) to {url}", flush=True)
        t0 = time.monotonic()
        stream = [str(VENV_BIN / "wavemesh"), "stream", src, *opts, "--port", url, "--timeout",
                  args.timeout, "-o", str(out / f"{name}.obj"), "--lod", str(out / f"{name}-lod"), "--report",
                  str(out / f"{name}.json"), "--render", str(out / f"{name}.png")]
        rc = subprocess.run(stream).returncode
        took = time.monotonic() - t0
        if rc not in (0, 3):
            return rc
        check = [str(VENV_BIN / "wavemesh"), "check", str(out / f"{name}.obj"), "--against", src,
                 *opts[:4]]  # the same input: --key elevation --decimate N
        if subprocess.run(check).returncode != 0:
            return 1
        print(f"demo: {args.device} device done in {took:.1f} s: mesh {out / name}.obj, levels in "
              f"{out / name}-lod/, picture {out / name}.png, report {out / name}.json", flush=True)
        return rc
    finally:
        device.stop()


if __name__ == "__main__":
    sys.exit(main())
