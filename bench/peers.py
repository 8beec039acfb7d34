"""The peer meshers of the quality benchmark, their output mapped onto wavemesh's mesh conventions, and
every mesh measured by wavemesh's own checker (never by a library's own error figure).

- pydelatin (Delatin, greedy Delaunay insertion; exact version in requirements.txt): vertices come
  back as (x, y, z) floats with y flipped, y_grid = (H - 1) - y, so the mirrored triangles are
  clockwise in wavemesh's (column, row) frame and are turned round.  Nothing is fixed up beyond that
  fixed mapping: a peer mesh that is not a proper triangulation, or whose vertices are not grid
  samples carrying the grid's heights, is reported as such.
- pymartini (Martini RTIN): needs a square 2^k + 1 grid, so the height field is padded right and down
  by edge replication to the smallest such size; the mesh is a triangulation of the padded grid and is
  checked and measured against the padded heights (its triangles in the padding count).
"""

from __future__ import annotations

import statistics
import sys
import time
from dataclasses import dataclass

import numpy as np
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.mesh import Mesh

# Relative slack when comparing a measured E_max with zeta: float32 peers (pymartini) and float64
# rounding in the metric must not be flagged for 1e-7 of zeta.
ZETA_SLACK = 1e-6


def median(values) -> float:
    vals = [v for v in values if v is not None]
    return float(statistics.median(vals)) if vals else float("nan")


def timed(fn, min_runs: int = 3, budget: float = 3.0, max_runs: int = 15, min_time: float = 0.2):
    """Run fn() at least once and then until it ran min_runs times and min_time seconds, or max_runs
    times, or the budget (s) is spent; return (last result, median seconds, runs).  A call slower than
    the budget runs once: its spread is small beside it."""
    times, out, start = [], None, time.perf_counter()
    while True:
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
        spent = time.perf_counter() - start
        if len(times) >= max_runs or spent >= budget or (len(times) >= min_runs and spent >= min_time):
            break
    return out, median(times), len(times)


# --------------------------------------------------------------------------------------------
# pydelatin


def delatin_call(z: np.ndarray, zeta: float):
    """The timed call: Delatin on the grid, then its vertices and triangles."""
    from pydelatin import Delatin

    h, w = z.shape
    d = Delatin(z.ravel(), width=w, height=h, max_error=float(zeta))
    return d.vertices, d.triangles


def from_delatin(vertices: np.ndarray, triangles: np.ndarray, width: int, height: int):
    """pydelatin's output as a wavemesh Mesh: y_grid = (H - 1) - y, triangles turned round (the flip
    mirrors them).  Returns (mesh, vertex z, problems): problems lists vertices that are not grid
    samples (they are rounded to the nearest sample for the checker, which then judges the mesh)."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    x, yd, z = v[:, 0], v[:, 1], v[:, 2]
    problems = []
    off = (x != np.round(x)) | (yd != np.round(yd))
    if off.any():
        problems.append(f"{int(off.sum())} vertices are not grid samples")
    xy = np.stack([np.round(x), (height - 1) - np.round(yd)], axis=1).astype(np.int64)
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)[:, ::-1]
    return Mesh(width, height, xy, tris), z, problems


# --------------------------------------------------------------------------------------------
# pymartini


def martini_size(width: int, height: int) -> int:
    n = max(width, height) - 1
    k = max(1, (n - 1).bit_length()) if n > 1 else 1
    return (1 << k) + 1


def pad_edge(z: np.ndarray, size: int) -> np.ndarray:
    h, w = z.shape
    return np.pad(z, ((0, size - h), (0, size - w)), mode="edge")


def martini_call(zp: np.ndarray, zeta: float):
    """The timed call: Martini for the padded grid's size, the tile, the mesh."""
    from pymartini import Martini

    tile = Martini(zp.shape[0]).create_tile(np.ascontiguousarray(zp, dtype=np.float32))
    return tile.get_mesh(float(zeta))


def from_martini(vertices: np.ndarray, triangles: np.ndarray, size: int) -> Mesh:
    """pymartini's output as a Mesh of the padded size x size grid: vertex (x, y) is terrain[y, x];
    its triangles are clockwise in the (column, row) frame and are turned round."""
    xy = np.asarray(vertices, dtype=np.int64).reshape(-1, 2)
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)[:, ::-1]
    return Mesh(size, size, xy, tris)


# --------------------------------------------------------------------------------------------
# Measuring a mesh with wavemesh's checker and metrics


@dataclass
class Verdict:
    triangles: int
    vertices: int
    proper: bool  # a proper triangulation of the grid rectangle, every vertex a grid sample
    heights_ok: bool  # the vertex heights the mesher gave are the grid's (None: it gives none)
    e_max_vertical: float | None
    e_max_normal: float | None
    within: bool  # proper and E_max vertical <= zeta (then normal too: it is never larger)
    problems: list[str]

    def to_json(self) -> dict:
        return dict(self.__dict__)


def verdict(mesh: Mesh, heights: np.ndarray, zeta: float, z: np.ndarray | None = None,
            problems: list[str] | None = None, rms: bool = True) -> Verdict:
    """Proper, heights, E_max; ``rms=False``: mesh_errors' maxima alone (the C measure, on every core)."""
    problems = list(problems or [])
    ck = check_mesh(mesh)
    problems += ck.problems[:5]
    heights_ok = True
    if z is not None and ck.valid:
        want = mesh.z(heights)
        bad = np.abs(np.asarray(z, dtype=np.float64) - want) > 1e-6 * np.maximum(1.0, np.abs(want))
        if bad.any():
            heights_ok = False
            problems.append(f"{int(bad.sum())} vertex heights differ from the grid's")
    ev = en = None
    if ck.valid:
        err = mesh_errors(mesh, heights, rms=rms)
        ev, en = float(err.e_max_vertical), float(err.e_max_normal)
    proper = ck.valid and not any("grid sample" in p for p in problems)
    within = proper and ev is not None and ev <= zeta * (1 + ZETA_SLACK) and en <= zeta * (1 + ZETA_SLACK)
    return Verdict(mesh.n_triangles, mesh.n_vertices, proper, heights_ok, ev, en, within, problems[:6])


# --------------------------------------------------------------------------------------------
# Whole processes

# The peer's whole process: load the same .npy, run pydelatin, write an OBJ in wavemesh's format (the
# `wavemesh W H` comment, grid vertices, counter-clockwise faces), as `wavemesh mesh -o x.obj` does.
PEER_SCRIPT = """\
import sys
import numpy as np
from pydelatin import Delatin
z = np.load(sys.argv[1])
h, w = z.shape
d = Delatin(z.ravel(), width=w, height=h, max_error=float(sys.argv[2]))
v, t = d.vertices, d.triangles
x = v[:, 0].astype(np.int64).tolist()
y = ((h - 1) - v[:, 1].astype(np.int64)).tolist()
zs = z[y, x].tolist()
with open(sys.argv[3], "w") as f:
    f.write(f"# wavemesh {w} {h}\\n# pydelatin\\n")
    f.write("".join(f"v {a} {b} {c!r}\\n" for a, b, c in zip(x, y, zs)))
    f.write("".join(f"f {a} {b} {c}\\n" for c, b, a in (t.astype(np.int64) + 1).tolist()))
"""


def compile_wavemesh() -> None:
    """Byte-compile the wavemesh package in place (its __pycache__, ignored by git) before `wavemesh mesh`
    processes are timed.  pip byte-compiles an installed package, pydelatin's and numpy's too; an
    editable install is compiled by its first run, unless PYTHONDONTWRITEBYTECODE is set (as on this
    project's agent machines): then every timed process would first compile the ~10k lines of the
    package (measured: process / process median 1.73 without, 1.35 with, CPU time, 10 small pairs)."""
    import compileall
    from pathlib import Path

    import wavemesh

    compileall.compile_dir(Path(wavemesh.__file__).parent, quiet=1)


def wavemesh_argv(npy: str, zeta: float, out: str) -> list[str]:
    from pathlib import Path

    exe = Path(sys.executable).with_name("wavemesh")
    return [str(exe), "mesh", npy, "-o", out, "--metric", "vertical", "--zeta", repr(float(zeta)), "-q"]


def peer_argv(npy: str, zeta: float, out: str) -> list[str]:
    return [sys.executable, "-c", PEER_SCRIPT, npy, repr(float(zeta)), out]


def code_state() -> dict:
    """The commit the measured code is at, and the files of host/ and firmware/ that differ from it (the
    work tree is shared while the refiner is being worked on: the results say what they measured)."""
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent

    def git(*args) -> str:
        r = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)
        return r.stdout if r.returncode == 0 else ""

    dirty = [line[3:] for line in git("status", "--porcelain", "--", "host", "firmware").splitlines() if line]
    return {"commit": git("rev-parse", "--short", "HEAD").strip() or None, "uncommitted": dirty}


def code_line(state: dict | None) -> str:
    if not state or not state.get("commit"):
        return ""
    n = len(state.get("uncommitted") or [])
    return (f"Code measured: commit {state['commit']}"
            + (f" with uncommitted changes in {n} files of host/ and firmware/ (listed in the results file)."
               if n else " (host/ and firmware/ as committed)."))
