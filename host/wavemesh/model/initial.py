"""Assembly of the initial triangulation of the whole grid (3.6.2).

Each block's template is expanded on the block's own grid positions: sites in
column 0, 1, 2 sit at x0, x0 + (x1 - x0) // 2, x1, and likewise in y.  Blocks
share their boundary vertices, so the union of the templates is one mesh.
"""

from __future__ import annotations

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
    ts = template_set()
    tris_xy = []
    for j in range(lab.label.shape[0]):
        y0, y1 = int(lab.ys[j]), int(lab.ys[j + 1])
        ry = (y0, y0 + (y1 - y0) // 2, y1)
        for i in range(lab.label.shape[1]):
            x0, x1 = int(lab.xs[i]), int(lab.xs[i + 1])
            rx = (x0, x0 + (x1 - x0) // 2, x1)
            for tri in ts.templates[lab.template[j, i]].triangles:
                tris_xy.append([(rx[s % 3], ry[s // 3]) for s in tri])
    pts = np.asarray(tris_xy, dtype=np.int64).reshape(-1, 2)
    keys = pts[:, 1] * width + pts[:, 0]
    uniq, inverse = np.unique(keys, return_inverse=True)
    xy = np.stack([uniq % width, uniq // width], axis=1)
    return Mesh(width, height, xy, inverse.reshape(-1, 3)).canonical()


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
