#!/usr/bin/env python3
"""fuzz_readers: the height-field and mesh readers (host/wavemesh/io/heightfield.py, meshio.py) under
atheris, coverage-guided over wavemesh's own Python code (GDAL, numpy and Pillow are run, not traced).

An input is ``kind, options, file bytes``: ``kind`` picks the file name the bytes are written under
(READERS: .npy, .npz, .pgm, .png, .tif, .asc, a file without extension; .obj, .ply), ``options`` the
reader's --key and --fill.  Every input must end in one of two ways (anything else is a finding):

- a result that keeps the contract: a height field of at least 2 x 2 finite float64 values whose
  16-bit samples reconstruct them within half a quantisation step (exactly when lossless); a mesh whose
  vertices are integral and whose triangles index them, which the checker (check_mesh) then judges
  without failing (whether it is a proper triangulation is the checker's to say, not the reader's);
- an InputError with a one-line, non-empty message.

And nothing may be written to stderr meanwhile (a stray line before wavemesh's ``error:`` line is
what the user would see): the process's file descriptor 2 is caught around each call.

    .venv/bin/python fuzz/readers_fuzz.py CORPUS... [libFuzzer options]     (fuzz/run.py runs it)
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import atheris

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "host"))

with atheris.instrument_imports(include=["wavemesh"]):
    from wavemesh.check import check_mesh
    from wavemesh.errors import InputError
    from wavemesh.io.heightfield import HeightField, load_heightfield
    from wavemesh.io.meshread import read_mesh

import numpy as np  # noqa: E402  (after the instrumented imports, not traced itself)

READERS = (".npy", ".npz", ".pgm", ".png", ".tif", ".asc", "", ".obj", ".ply")
MESHES = (".obj", ".ply")
FILLS = (None, "nearest", "0", "-12.5", "nan", "1e400")

_DIR = tempfile.mkdtemp(prefix="wm-fuzz-", dir="/dev/shm" if os.path.isdir("/dev/shm") else None)


class Finding(Exception):
    """A broken contract (libFuzzer reports the uncaught exception and keeps the input)."""


def _check_heightfield(hf: HeightField) -> None:
    v, s = hf.values, hf.samples
    if v.ndim != 2 or v.shape[0] < 2 or v.shape[1] < 2 or v.dtype != np.float64:
        raise Finding(f"values {v.dtype} {v.shape}")
    if s.shape != v.shape or s.dtype != np.uint16:
        raise Finding(f"samples {s.dtype} {s.shape} for values {v.shape}")
    if not np.all(np.isfinite(v)):
        raise Finding("non-finite heights accepted")
    if not (np.isfinite(hf.scale) and hf.scale > 0 and np.isfinite(hf.offset)):
        raise Finding(f"scale {hf.scale!r}, offset {hf.offset!r}")
    recon = hf.offset + hf.scale * s.astype(np.float64)
    err = float(np.max(np.abs(recon - v)))
    if hf.lossless and err != 0:
        raise Finding(f"lossless, yet a sample is off by {err!r}")
    span = float(np.max(v) - np.min(v))
    if err > hf.scale / 2 + 1e-9 * max(1.0, span, abs(hf.offset)):
        raise Finding(f"quantisation error {err!r} > half the step {hf.scale!r}")


def _check_mesh(mesh, z) -> None:
    xy, tris = mesh.xy, mesh.tris
    if len(z) != len(xy):
        raise Finding(f"{len(z)} heights for {len(xy)} vertices")
    if xy.dtype.kind not in "iu":
        raise Finding(f"vertex positions of type {xy.dtype}, not grid samples")
    if len(tris) and (tris.min() < 0 or tris.max() >= len(xy)):
        raise Finding("a triangle indexes no vertex")
    # Whether it is a proper triangulation is the checker's to say (read_mesh leaves it open): it must
    # say so, whatever the file held, and whatever grid its coordinates state (123 bytes stating
    # 55555551 x 3 once took check_mesh past 2.5 GB: corpus/readers/regress-obj-wide-grid).
    check_mesh(mesh)


def _call(fn):
    """fn() with file descriptor 2 caught: (result or the InputError, what was written to stderr)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(dir=_DIR) as cap:
        os.dup2(cap.fileno(), 2)
        try:
            try:
                out = fn()
            except InputError as e:
                out = e
            finally:
                sys.stderr.flush()
                os.dup2(saved, 2)
                os.close(saved)
        finally:
            cap.seek(0)
            text = cap.read().decode("utf-8", "replace")
    return out, text


def TestOneInput(data: bytes) -> None:
    if len(data) < 2:
        return
    ext = READERS[data[0] % len(READERS)]
    key = "elevation" if data[1] & 1 else None
    fill = FILLS[(data[1] >> 1) % len(FILLS)]
    path = os.path.join(_DIR, f"input{ext}")
    with open(path, "wb") as f:
        f.write(data[2:])
    if ext in MESHES:
        out, err = _call(lambda: read_mesh(path))
    else:
        out, err = _call(lambda: load_heightfield(path, key=key if ext == ".npz" else None, fill=fill))
    if err:
        raise Finding(f"stderr: {err[:300]!r}")
    if isinstance(out, InputError):
        if not out.message or "\n" in out.message or (out.hint and "\n" in out.hint):
            raise Finding(f"not a one-line message: {out.message!r} / {out.hint!r}")
    elif ext in MESHES:
        _check_mesh(*out)
    else:
        _check_heightfield(out)


def main() -> None:
    # libFuzzer runs argv[0] again for -merge and -fork: the wrapper fuzz/run.py writes, not this script
    argv = [os.environ.get("WM_FUZZ_SELF", sys.argv[0]), *sys.argv[1:]]
    atheris.Setup(argv, TestOneInput)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
