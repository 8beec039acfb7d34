"""Mesh writers: wavemesh's own OBJ and PLY writers (wavemesh.io.meshio) against meshio's and
trimesh's on a mesh of 1M triangles.

The target: OBJ/PLY through meshio or trimesh unless wavemesh's writer is at least 3x faster on
1M triangles.  The mesh: every sample of a 709 x 709 grid of bench/datasets.py's synthetic terrain (heights
0..1000 with full double precision, the hard case for text), split into 1,002,528 triangles.  Each writer
writes it to a temporary file, 3 times; the time is the least CPU time of the process (time.process_time:
what the writer costs, not what the other jobs on the machine cost).  Every file is read back with
wavemesh.io.meshread.read_mesh: *exact* means the same triangles and the same doubles as the heights
(the OBJ text of a lossy writer reads back rounded); *same bytes* that the 3 writes gave the same file
(`wavemesh stream` and `wavemesh mesh` must write the same file byte for byte); *grid* that the file
names the grid size (`# wavemesh W H`, `comment wavemesh W H`: read_mesh needs it when a mesh does not
reach the last row or column).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import time
from pathlib import Path

import numpy as np

TITLE = "Mesh writers: wavemesh.io.meshio against meshio and trimesh (1M triangles)"
N = 709  # samples per side: 2 x 708^2 = 1,002,528 triangles
REPEATS = 3
TARGET = 3.0  # the target: wavemesh's writer at least this much faster, else a kept library writes


def grid_mesh(n: int):
    """Every sample of an n x n grid, each cell split along the same diagonal (counter-clockwise)."""
    from wavemesh.mesh import Mesh

    y, x = np.mgrid[0:n, 0:n]
    xy = np.stack([x.ravel(), y.ravel()], axis=1)
    i = (np.arange(n - 1)[None, :] + n * np.arange(n - 1)[:, None]).ravel()
    tris = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    return Mesh(n, n, xy, tris)


def writers() -> dict:
    """name -> (format, write(path, mesh, heights))."""
    import meshio as mio
    import trimesh
    from wavemesh.io import meshio as wm

    def points(mesh, heights):
        return np.column_stack([mesh.xy.astype(np.float64), mesh.z(heights)])

    def with_meshio(path, mesh, heights):
        mio.write_points_cells(path, points(mesh, heights), [("triangle", mesh.tris.astype(np.int32))])

    def with_trimesh(path, mesh, heights):
        trimesh.Trimesh(points(mesh, heights), mesh.tris, process=False).export(path)

    return {
        "wavemesh OBJ": (".obj", wm.write_obj),
        "meshio OBJ": (".obj", with_meshio),
        "trimesh OBJ": (".obj", with_trimesh),
        "wavemesh PLY": (".ply", wm.write_ply),
        "meshio PLY": (".ply", with_meshio),
        "trimesh PLY": (".ply", with_trimesh),
    }


def run() -> dict:
    import importlib.metadata as md

    from datasets import terrain
    from peers import code_state
    from wavemesh.io.meshread import read_mesh

    heights = terrain(N)
    mesh = grid_mesh(N)
    z = mesh.z(heights)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (ext, write) in writers().items():
            path = Path(tmp) / f"m{ext}"
            times, digests = [], set()
            for _ in range(REPEATS):
                t0 = time.process_time()
                write(str(path), mesh, heights)
                times.append(time.process_time() - t0)
                digests.add(hashlib.sha256(path.read_bytes()).hexdigest())
                time.sleep(0.01)  # a writer that stamps the time writes different bytes
            back, zb = read_mesh(path, N, N)
            rows[name] = {"seconds": min(times), "bytes": os.path.getsize(path),
                          "same_triangles": bool(back.same_as(mesh)),
                          "exact": bool(back.same_as(mesh) and np.array_equal(np.sort(zb), np.sort(z))),
                          "max_height_error": float(np.max(np.abs(np.sort(zb) - np.sort(z)))),
                          "reproducible": len(digests) == 1,
                          "grid_comment": f"wavemesh {N} {N}".encode() in path.read_bytes()[:4096]}
    return {"n": N, "triangles": mesh.n_triangles, "vertices": mesh.n_vertices, "rows": rows,
            "versions": {p: md.version(p) for p in ("meshio", "trimesh", "numpy")}, "code": code_state()}


def _yes(b: bool) -> str:
    return "yes" if b else "no"


def markdown(results: dict) -> str:
    from peers import code_line

    rows = results["rows"]
    lines = [
        f"Every sample of a {results['n']} x {results['n']} grid of bench/datasets.py's synthetic terrain "
        f"({results['vertices']:,} vertices, {results['triangles']:,} triangles), written by each writer: "
        "the least CPU time (time.process_time) of 3 writes of the whole file, its size, and whether "
        "wavemesh.io.meshread.read_mesh reads back the same triangles and the same doubles (*exact*).  "
        + ", ".join(f"{k} {v}" for k, v in results["versions"].items()) + ".  `make bench-writers`.",
        "",
        code_line(results.get("code")),
        "",
        "| writer | s | MB | exact | largest height error | same bytes | grid | wavemesh's speed-up |",
        "|---|---|---|---|---|---|---|---|",
    ]
    verdicts = []
    for fmt in ("OBJ", "PLY"):
        ours = rows[f"wavemesh {fmt}"]["seconds"]
        best = None
        for lib in ("wavemesh", "meshio", "trimesh"):
            r = rows[f"{lib} {fmt}"]
            up = "" if lib == "wavemesh" else f"{r['seconds'] / ours:.2f}x"
            lines.append(f"| {lib} {fmt} | {r['seconds']:.2f} | {r['bytes'] / 1e6:.1f} | "
                         f"{_yes(r['exact'])} | {r['max_height_error']:.3g} | {_yes(r['reproducible'])} | "
                         f"{_yes(r['grid_comment'])} | {up} |")
            if lib != "wavemesh" and r["exact"] and (best is None or r["seconds"] < best[1]):
                best = (lib, r["seconds"], r["reproducible"] and r["grid_comment"])
        if best is None:
            verdicts.append(f"{fmt}: no library writes it exactly; wavemesh's writer stays")
        else:
            ratio = best[1] / ours
            if ratio >= TARGET:
                verdict = "at least 3x, so it stays"
            elif best[2]:
                verdict = f"under {TARGET:g}x, so {best[0]} writes"
            else:
                verdict = (f"under {TARGET:g}x, but {best[0]}'s file differs from write to write or does not "
                           "name the grid, so wavemesh's writer stays")
            verdicts.append(f"{fmt}: wavemesh's writer is {ratio:.2f}x as fast as the fastest exact library "
                            f"({best[0]}): {verdict}")
    lines += ["", "The target (at least 3x faster than a kept library, or the library writes): "
              + "; ".join(verdicts) + "."]
    return "\n".join(lines)


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
