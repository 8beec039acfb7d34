"""The memory of an untiled `wavemesh mesh` against the grid's size: the source of the untiled run's
estimate (wavemesh.api.MESH_BYTES_PER_SAMPLE, docs/tiles.md "Memory").

Each run is a fresh process meshing a float32 .npy of N x N samples (flat: zeros; terrain: synth's ball +
f2; noise: normal, sigma 100) and reporting at its end VmPeak (the peak address space, what ulimit -v
bounds) and VmHWM (the peak resident memory); the slope between consecutive sizes is the bytes a sample.

    .venv/bin/python tools/mesh_memory.py --kinds flat,terrain,noise --sizes 1025,2049,4097
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

RUN = ("import sys; from wavemesh.cli import main; main(sys.argv[1:]); "
       "s = dict(line.split(':', 1) for line in open('/proc/self/status')); "
       "print(int(s['VmPeak'].split()[0]) * 1024, int(s['VmHWM'].split()[0]) * 1024)")


def heights(kind: str, n: int) -> np.ndarray:
    from wavemesh.io import synth

    if kind == "flat":
        return np.zeros((n, n), np.float32)
    if kind == "terrain":
        return (synth.make("ball", n) + synth.make("f2", n)).astype(np.float32)
    if kind == "noise":
        return np.random.default_rng(1).normal(0, 100, (n, n)).astype(np.float32)
    raise SystemExit(f"unknown kind {kind}: flat, terrain or noise")


def peaks(path: Path, extra: list[str]) -> tuple[int, int]:
    # --tile off: untiled at every size (from 2048^2 samples on `wavemesh mesh` tiles by default)
    r = subprocess.run([sys.executable, "-c", RUN, "mesh", str(path), "-o", str(path.with_suffix(".obj")),
                        "-q", "--tile", "off", *extra], capture_output=True, text=True, check=True)
    peak, hwm = map(int, r.stdout.split()[-2:])
    return peak, hwm


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kinds", default="flat,terrain,noise")
    ap.add_argument("--sizes", default="513,1025,2049")
    ap.add_argument("--zeta", default=None, help="wavemesh mesh --zeta (default: its own)")
    args = ap.parse_args()
    extra = ["--zeta", args.zeta] if args.zeta else []
    print(f"{'kind':8} {'N':>6} {'VmPeak MB':>10} {'VmHWM MB':>9} {'peak B/sample':>14} {'HWM B/sample':>13}")
    with tempfile.TemporaryDirectory() as d:
        for kind in args.kinds.split(","):
            last = None
            for n in map(int, args.sizes.split(",")):
                path = Path(d) / f"{kind}-{n}.npy"
                np.save(path, heights(kind, n))
                peak, hwm = peaks(path, extra)
                slope = ("", "") if last is None else tuple(
                    f"{(a - b) / (n * n - last[0] ** 2):.1f}" for a, b in ((peak, last[1]), (hwm, last[2])))
                print(f"{kind:8} {n:>6} {peak / 1e6:>10.1f} {hwm / 1e6:>9.1f} {slope[0]:>14} {slope[1]:>13}",
                      flush=True)
                last = (n, peak, hwm)


if __name__ == "__main__":
    main()
