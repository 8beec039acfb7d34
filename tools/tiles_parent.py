#!/usr/bin/env python3
"""The parent's side of a tiled run: its own peak memory, its CPU, and its tail.

    .venv/bin/python tools/tiles_parent.py INPUT -o OUT --tile N [wavemesh mesh options ...]
    .venv/bin/python tools/tiles_parent.py --stitched INPUT -o OUT --tile N [...]

Runs `wavemesh mesh INPUT ...` (as given: `--tile 1025 --workers 2 --metric vertical --zeta 0.1 -q`) in
this process and prints one line of JSON: the parent's peak RSS (getrusage's ru_maxrss of this process:
the pool's workers apart, every one forked: runner.THREADS = 0), its CPU (user + system) over the run,
and the tail: its CPU and wall time from the moment the last task's result arrives (before the parent
handles it) to the end of the run (writing what was left, the files moved into place, the workers
ended).  ``--stitched``: the tiles as the
API's tiles.stitch takes them, every tile's last result kept until the last one, stitched into one mesh
(checked whole), then written (docs/tiles.md, "Memory": against the mesh file written as the tiles
finish).  CPU seconds and ru_maxrss hold on a loaded machine where wall times do not.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time

from wavemesh import cli, tiles
from wavemesh.tiles import runner

MARK: dict = {}
_graph = runner.Runner.graph


def _marked_graph(self, nodes, done=None, *args, **kw):
    """Runner.graph, the time noted when the last node's result arrives (before the parent handles it)."""
    seen = [0]

    def counted(i, r):
        seen[0] += 1
        if seen[0] == len(nodes):
            t = os.times()
            MARK["cpu"], MARK["wall"] = t.user + t.system, time.perf_counter()
        if done:
            done(i, r)

    return _graph(self, nodes, counted, *args, **kw)


_run_tiles = tiles.run_tiles


def _stitched_run(plan, *, sink=None, **kw):
    """run_tiles with every tile's result kept, the whole mesh stitched (and checked), then given to
    ``sink`` in tile order."""
    results = _run_tiles(plan, **kw)
    tiles.stitch(plan, results)
    for r in results:
        sink(r)
    return results


def main(argv: list[str]) -> int:
    runner.Runner.graph = _marked_graph
    runner.THREADS = 0  # every worker forked: the parent's own memory, not a thread worker's tiles
    if argv and argv[0] == "--stitched":
        argv = argv[1:]
        tiles.run_tiles = _stitched_run
    t0 = os.times()
    rc = cli.main(["mesh", *argv])
    t1, w1 = os.times(), time.perf_counter()
    if "cpu" not in MARK:
        print("tiles_parent: no tiled run (give --tile N)", file=sys.stderr)
        return 2
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"status": rc, "peak_rss_mib": round(peak, 1),
                      "cpu_s": round(t1.user + t1.system - t0.user - t0.system, 2),
                      "tail_cpu_s": round(t1.user + t1.system - MARK["cpu"], 2),
                      "tail_wall_s": round(w1 - MARK["wall"], 2), "load": round(os.getloadavg()[0], 1)}))
    return rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
