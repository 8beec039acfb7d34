"""Assembly of the initial triangulation of the whole grid (3.6.2).

Each block's template is expanded on the block's own grid positions: sites in
column 0, 1, 2 sit at x0, x0 + (x1 - x0) // 2, x1, and likewise in y.  Blocks
share their boundary vertices, so the union of the templates is one mesh.
"""

from __future__ import annotations

import functools

import numpy as np

from wavemesh.mesh import Mesh
from wavemesh.model.haar import HaarLevel, decompose
from wavemesh.model.label import Labelling, label_blocks, tau_counts
from wavemesh.model.templates import LABELS, template_set
from wavemesh.record import record


@record(frozen=True)
class InitialResult:
    mesh: Mesh
    labelling: Labelling
    tau_q: int
    levels: int

    def to_report(self) -> dict:
        lab = self.labelling
        counts = {LABELS[c]: int(np.count_nonzero(lab.label == c)) for c in range(len(LABELS))}
        ts = template_set()
        used = np.bincount(lab.template.ravel(), minlength=len(ts.templates))
        return {
            "levels": self.levels,
            "block_size": 1 << self.levels,
            "blocks": [int(lab.label.shape[1]), int(lab.label.shape[0])],
            "tau_counts": self.tau_q,
            "labels": counts,
            "label_table": ["".join(LABELS[c] for c in row) for row in lab.label],
            "templates_used": {ts.templates[i].name: int(n) for i, n in enumerate(used) if n},
            "vertices": self.mesh.n_vertices,
            "triangles": self.mesh.n_triangles,
        }


def assemble(lab: Labelling, width: int, height: int) -> Mesh:
    """The mesh made of every block's template, in canonical form."""
    table, counts = _site_table()
    tmpl = np.asarray(lab.template, dtype=np.int64).ravel()  # blocks row by row, as the mesh lists them
    xs, ys = np.asarray(lab.xs, dtype=np.int64), np.asarray(lab.ys, dtype=np.int64)
    bw = len(xs) - 1
    # each block's sites in column 0, 1, 2 (and row 0, 1, 2): its edges and their midpoint (floored)
    rx = np.stack([xs[:-1], xs[:-1] + (xs[1:] - xs[:-1]) // 2, xs[1:]], axis=1)  # (block columns, 3)
    ry = np.stack([ys[:-1], ys[:-1] + (ys[1:] - ys[:-1]) // 2, ys[1:]], axis=1)  # (block rows, 3)
    n = counts[tmpl]
    block = np.repeat(np.arange(len(tmpl)), n)  # each triangle's block, the blocks' triangles in turn
    k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)  # its place in its template
    sites = table[tmpl[block], k]  # (triangles, 3) sites 0..8 (column s % 3, row s // 3)
    px = rx[(block % bw)[:, None], sites % 3]
    py = ry[(block // bw)[:, None], sites // 3]
    keys = (py * width + px).ravel()
    uniq, inverse = np.unique(keys, return_inverse=True)
    xy = np.stack([uniq % width, uniq // width], axis=1)
    return Mesh(width, height, xy, inverse.reshape(-1, 3)).canonical()


@functools.cache
def _site_table() -> tuple[np.ndarray, np.ndarray]:
    """The templates' triangles as sites, (templates, most triangles, 3) padded with 0, and their counts."""
    ts = template_set().templates
    table = np.zeros((len(ts), max(len(t.triangles) for t in ts), 3), dtype=np.int64)
    for i, t in enumerate(ts):
        table[i, : len(t.triangles)] = t.triangles
    return table, np.array([len(t.triangles) for t in ts], dtype=np.int64)


def last_level(details: np.ndarray, width: int, height: int, levels: int) -> HaarLevel:
    """Level M's details from the C filter bank's layout (native.haar_details: per level, cells row by
    row, (d1, d2, d3)); its approximation is not kept there (``a`` is None: the labeller reads none)."""
    off = sum(3 * (-(-width >> m)) * (-(-height >> m)) for m in range(1, levels))
    cw, ch = -(-width >> levels), -(-height >> levels)
    d = details[off:off + 3 * cw * ch].reshape(ch, cw, 3).astype(np.int64)
    return HaarLevel(levels, None, d[..., 0], d[..., 1], d[..., 2])


def initial_triangulation(samples: np.ndarray, levels: int, tau_q: int,
                          wavelet: str = "haar", details: np.ndarray | None = None) -> InitialResult:
    """Filter bank (``wavelet``: wavemesh.model.haar.WAVELETS), labeller and templates on (H, W) 16-bit
    samples.
    ``details``: the filter bank's details as the C library made them (native.haar_details, equal to
    decompose's: tests/host/test_host_stages.py), else wavemesh.model.haar's model makes them."""
    height, width = samples.shape
    level = (decompose(samples, levels, wavelet)[-1] if details is None
             else last_level(details, width, height, levels))
    lab = label_blocks(level, tau_q, width, height)
    return InitialResult(assemble(lab, width, height), lab, tau_q, levels)


__all__ = ["InitialResult", "assemble", "initial_triangulation", "tau_counts"]
