#!/usr/bin/env python3
"""The native refine call's time against pydelatin's, two builds or settings of the library in one process.

    .venv/bin/python bench/refine_time.py [--a SPEC] [--b SPEC] [--set tuning|held_out|all] [--reps N]
                                          [GRID:LABEL ...]

bench/bench_quality.py's "native refine / pydelatin call" (RefineJob.seconds of its wavemesh job, over
Delatin's call with .vertices and .triangles) for A and B, measured in turn, A B pydelatin A B pydelatin
..., in one process: a machine shared with other work slows the three alike, so the ratios hold where
the seconds do not.  SPEC is a path to a libwavemesh.so (copied, then loaded beside the tree's), or
`scan=K`: the tree's library with wm_host_scan(K) (firmware/include/wm_host.h: 0 the C scan, 1 the
default).  Prints each pair's medians, A / pydelatin, B / pydelatin and B / A (the median of the pairwise
ratios), the medians over the pairs, the meshes' equality (every level, A against B) and the load.
The pairs: bench_quality's tuning set by default (GRID:LABEL names others, e.g. `mri:1%`); held_out only
to report, never to tune on.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/: datasets, peers, bench_quality

import bench_quality as Q  # noqa: E402
import datasets as D  # noqa: E402
import numpy as np  # noqa: E402
import peers as P  # noqa: E402


def library(spec: str, folder: Path):
    """(library, scan setting or None) for a SPEC."""
    from wavemesh.refine import native

    if spec.startswith("scan="):
        return native.load(), int(spec[5:])
    path = folder / f"lib{len(list(folder.iterdir()))}.so"  # a copy: its own handle beside the tree's
    shutil.copy(spec, path)
    lib = ctypes.CDLL(str(path))
    native._declare(lib)
    return lib, None


def use(which) -> None:
    from wavemesh.refine import native

    native._LIB = which[0]
    if which[1] is not None:
        which[0].wm_host_scan(which[1])


def pairs(chosen: list[str], which: str) -> list[tuple[str, str]]:
    if chosen:
        return [tuple(c.split(":", 1)) for c in chosen]
    out = []
    for name in Q.GRIDS:
        held = name in Q.HELD_OUT
        if which == "all" or held == (which == "held_out"):
            out += [(name, label) for label, _ in Q.zetas(D.load(name))]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--a", default="scan=0", help="SPEC of A (default scan=0, the C scan)")
    ap.add_argument("--b", default="scan=1", help="SPEC of B (default scan=1, the library's default)")
    ap.add_argument("--set", default="tuning", choices=("tuning", "held_out", "all"))
    ap.add_argument("--reps", type=int, default=9, help="rounds per pair (a third on pairs over 0.05 s)")
    ap.add_argument("pairs", nargs="*", help="GRID:LABEL, e.g. mri:1%% (default: the set's pairs)")
    args = ap.parse_args()
    from wavemesh.refine import native

    native.load()
    folder = Path(tempfile.mkdtemp(prefix="refine_time."))
    try:
        A, B = library(args.a, folder), library(args.b, folder)
        print(f"A {args.a}, B {args.b}; load {os.getloadavg()[0]:.2f}")
        print("| pair | A ms | B ms | pydelatin ms | A / pd | B / pd | B / A | same |")
        print("|---|---|---|---|---|---|---|---|")
        ra, rb, rab = [], [], []
        for name, label in pairs(args.pairs, args.set):
            grid = D.load(name)
            zeta = dict(Q.zetas(grid))[label]
            z = grid.values
            meshes = []
            for which in (A, B):  # once untimed each: the same meshes at every level?
                use(which)
                meshes.append(Q.wavemesh_mesh(z, zeta).output.levels)
            same = len(meshes[0]) == len(meshes[1]) and all(
                np.array_equal(a.mesh.xy, b.mesh.xy) and np.array_equal(a.mesh.tris, b.mesh.tris)
                for a, b in zip(*meshes, strict=True))
            P.delatin_call(z, zeta)
            ta, tb, tp = [], [], []
            reps = args.reps
            for i in range(reps):
                for which, times in ((A, ta), (B, tb)):
                    use(which)
                    times.append(Q.wavemesh_mesh(z, zeta).seconds)
                t0 = time.perf_counter()
                P.delatin_call(z, zeta)
                tp.append(time.perf_counter() - t0)
                if i == 0 and ta[0] > 0.05:
                    reps = max(3, args.reps // 3)
            a, b, p = (float(np.median(t)) for t in (ta, tb, tp))
            pab = float(np.median(np.array(tb) / np.array(ta)))
            ra.append(a / p)
            rb.append(b / p)
            rab.append(pab)
            print(f"| {name} {label} | {1e3 * a:.3f} | {1e3 * b:.3f} | {1e3 * p:.3f} | {a / p:.2f} "
                  f"| {b / p:.2f} | {pab:.3f} | {'yes' if same else '**no**'} |", flush=True)
        print(f"| **median** ({len(ra)} pairs) | | | | {np.median(ra):.2f} | {np.median(rb):.2f} "
              f"| {np.median(rab):.3f} | |")
        print(f"load {os.getloadavg()[0]:.2f}")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
