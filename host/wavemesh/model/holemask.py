"""The validity mask of ``--nodata hole`` and its wire format (docs/model.md, "Holes").

The mask is True where a sample is invalid (NaN, the reader's no-data value, ``--invalid VALUE``):
:attr:`HeightField.mask <wavemesh.io.heightfield.HeightField.mask>`.  :func:`pack` is its one wire and
memory format: a bit per sample, row-major, least significant bit first, set where the sample is invalid
(wm_field.mask, the MASK frames of docs/protocol.md).  :func:`coverage` and :func:`cover_counts` say which
samples a mesh's triangles cover (exact integer row spans); :func:`stranded` the valid samples no grid
cell's triangle of valid samples has, which the reader meshes as invalid; :func:`block_flags` the
template stage's per-block flag (rtl/tlut_holes.v's reference).
"""

from __future__ import annotations

import numpy as np

from wavemesh.mesh import Mesh
from wavemesh.model.label import block_edges


def pack(mask: np.ndarray) -> bytes:
    """The mask as wm_field.mask: bit i % 8 of byte i // 8 for sample i = y W + x, set when invalid."""
    return np.packbits(np.asarray(mask, dtype=bool).ravel(), bitorder="little").tobytes()


def unpack(data: bytes, width: int, height: int) -> np.ndarray:
    """pack's inverse: the (H, W) bool mask."""
    bits = np.unpackbits(np.frombuffer(data, dtype=np.uint8), bitorder="little", count=width * height)
    return bits.reshape(height, width).astype(bool)


def _spans(mesh: Mesh):
    """Each triangle's closed region row by row: (triangle, row, first, last, count), from the exact
    edge functions (counter-clockwise: E_k >= 0 inside) by integer floor division."""
    xy, t = mesh.xy, mesh.tris
    x, y = xy[t, 0], xy[t, 1]  # (T, 3)
    ymin, ymax = y.min(1), y.max(1)
    rows = ymax - ymin + 1
    tri = np.repeat(np.arange(len(t)), rows)
    py = ymin[tri] + np.arange(int(rows.sum())) - np.repeat(np.cumsum(rows) - rows, rows)
    lo, hi = x.min(1)[tri], x.max(1)[tri]
    empty = np.zeros(len(tri), dtype=bool)
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        a = (y[:, k1] - y[:, k2])[tri]  # E_k = a px + num
        b = (x[:, k2] - x[:, k1])[tri]
        c = (-(x[:, k2] - x[:, k1]) * y[:, k1] - (y[:, k1] - y[:, k2]) * x[:, k1])[tri]
        num = b * py + c
        d = np.where(a == 0, 1, np.abs(a))
        lo = np.where(a > 0, np.maximum(lo, -(num // d)), lo)  # ceil(-num / a)
        hi = np.where(a < 0, np.minimum(hi, num // d), hi)  # floor(num / -a)
        empty |= (a == 0) & (num < 0)
    cnt = np.where(empty, 0, np.maximum(hi - lo + 1, 0))
    return tri, py, lo, hi, cnt


def cover_counts(mesh: Mesh, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each triangle: (samples it covers, invalid samples among them), counted with per-row prefix
    sums of the mask."""
    n = mesh.n_triangles
    tri, py, lo, hi, cnt = _spans(mesh)
    bad = np.asarray(mask, dtype=bool)
    w = bad.shape[1]
    prefix = np.zeros((bad.shape[0], w + 1), dtype=np.int64)
    np.cumsum(bad, axis=1, out=prefix[:, 1:])
    inv = np.where(cnt > 0, prefix[py, np.clip(hi + 1, 0, w)] - prefix[py, np.clip(lo, 0, w)], 0)
    return np.bincount(tri, cnt, n).astype(np.int64), np.bincount(tri, inv, n).astype(np.int64)


def coverage(mesh: Mesh) -> np.ndarray:
    """(H, W) int: how many triangles of ``mesh`` cover each sample (closed triangles)."""
    tri, py, lo, hi, cnt = _spans(mesh)
    keep = cnt > 0
    py, lo, hi = py[keep], lo[keep], hi[keep]
    diff = np.zeros((mesh.height, mesh.width + 1), dtype=np.int64)
    np.add.at(diff, (py, lo), 1)
    np.add.at(diff, (py, hi + 1), -1)
    return np.cumsum(diff, axis=1)[:, :mesh.width]


def block_flags(mask: np.ndarray, levels: int) -> np.ndarray:
    """The per-block validity flag of the template stage's blocks (wavemesh.model.label: block (j, i) spans
    samples [iS, min((i+1)S, W-1)] x [jS, min((j+1)S, H-1)], S = 2^M, closed): True where the block holds
    an invalid sample.  The reference for an RTL flag beside each template; not used by the mesh (the
    templates see the filled heights; only the refiner and the host read the mask)."""
    bad = np.asarray(mask, dtype=bool)
    h, w = bad.shape
    size = 1 << levels
    xs, ys = block_edges(w, size), block_edges(h, size)
    # any invalid sample in a closed box: a 2-D prefix sum
    pre = np.zeros((h + 1, w + 1), dtype=np.int64)
    pre[1:, 1:] = np.cumsum(np.cumsum(bad, axis=0), axis=1)
    x0, x1 = xs[:-1], xs[1:] + 1
    y0, y1 = ys[:-1, None], ys[1:, None] + 1
    return (pre[y1, x1] - pre[y0, x1] - pre[y1, x0] + pre[y0, x0]) > 0


def coverable(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the valid samples that are a corner of a unit right triangle of three valid samples
    (three of the four corners of a grid cell).  No mesh with grid-sample vertices covers the others
    (isolated samples, one-sample-wide lines) without a triangle over an invalid sample, save long thin
    triangles this leaves out."""
    v = ~np.asarray(mask, dtype=bool)
    h, w = v.shape
    cell = v[:-1, :-1].astype(np.int8) + v[1:, :-1] + v[:-1, 1:] + v[1:, 1:] >= 3  # (H-1, W-1)
    out = np.zeros((h, w), dtype=bool)
    for dy in (0, 1):
        for dx in (0, 1):
            out[dy:dy + h - 1, dx:dx + w - 1] |= cell
    return out & v


def stranded(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the valid samples no grid cell's triangle of three valid samples has as a corner
    (``~coverable`` among the valid ones).  ``--nodata hole`` meshes them as invalid (the height field's
    mask takes them in, heightfield.from_array), as range-image meshers do, which triangulate grid cells of
    valid samples: no triangle of cell corners covers them without an invalid sample.  Idempotent: every
    valid sample of a cell with three valid corners stays valid."""
    v = ~np.asarray(mask, dtype=bool)
    return v & ~coverable(mask)


def enclosed_holes(mask: np.ndarray) -> int:
    """The 8-connected groups of invalid samples that do not touch the rectangle's border: each is a hole
    of any mesh that covers every valid sample around it and no invalid one.  A piece of mesh with h holes
    whose rims share no vertex, V_i inner and V_b rim vertices has 2 V_i + V_b + 2h - 2 triangles (Euler),
    and a rim has 3 vertices at least, so such a mesh has at least 5h + 1 triangles (rims that pinch at a
    shared vertex can do with fewer)."""
    from scipy import ndimage  # start-up: scipy only for masks (tests/host/test_mesh_costs.py)

    bad = np.asarray(mask, dtype=bool)
    lab, n = ndimage.label(bad, structure=np.ones((3, 3), dtype=bool))
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    return n - int((border > 0).sum())
