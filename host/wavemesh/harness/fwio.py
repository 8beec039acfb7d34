"""Input files of the C runner tests/firmware/wm_run.c, and its output."""

from __future__ import annotations

import ctypes
import struct
from pathlib import Path

import numpy as np

from wavemesh.mesh import Mesh
from wavemesh.refine import native


def write_input(path: Path, samples: np.ndarray, details: np.ndarray, levels: int, mesh: Mesh,
                params: native.Params, tri_cap: int) -> None:
    h, w = samples.shape
    with open(path, "wb") as f:
        f.write(b"WMR1")
        f.write(struct.pack("=7i", w, h, levels, mesh.n_vertices, mesh.n_triangles, tri_cap,
                            ctypes.sizeof(native.Params)))
        f.write(bytes(params))
        f.write(np.ascontiguousarray(samples, dtype=np.uint16).tobytes())
        f.write(struct.pack("=q", len(details)))
        f.write(np.ascontiguousarray(details, dtype=np.int32).tobytes())
        f.write(np.ascontiguousarray(mesh.xy, dtype=np.int32).tobytes())
        f.write(np.ascontiguousarray(mesh.tris, dtype=np.int32).tobytes())


def read_output(path: Path, width: int, height: int) -> Mesh:
    data = Path(path).read_bytes()
    nv, nt = struct.unpack_from("=2i", data)
    xy = np.frombuffer(data, dtype=np.int32, count=2 * nv, offset=8).reshape(-1, 2)
    tris = np.frombuffer(data, dtype=np.int32, count=3 * nt, offset=8 + 8 * nv).reshape(-1, 3)
    return Mesh.from_slots(width, height, xy, tris)
