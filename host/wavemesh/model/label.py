"""The dominant-coefficient labeller and the variant resolver (3.5.1-3.5.4, 3.6.2).

Blocks.  With S = 2^M, the mesh is cut into blocks of S grid steps: block
column i spans x in [iS, min((i+1)S, W-1)], so there are ceil((W-1)/S) block
columns and the last one may be narrower (likewise rows).  Block (j, i) takes
its label from level M's coefficients at (j, i), the Haar block of samples
[iS, (i+1)S) x [jS, (j+1)S), which is the mesh block less its last row and
column (the paper's "[2^M i, 2^M (i+1))", 3.6.2).

Labels (per block):

1. k* = the k in 1..3 with the largest |d_k|, the lowest k on ties;
2. if |d_k*| > tau (in coefficient units, see :func:`tau_counts`): V for k*=1,
   H for k*=2, D for k*=3; otherwise F;
3. F, V and H become their duals f, v, h when d1 * d2 < 0 (the diagonal then
   follows the level contours the other way, fig. 3.12);
4. a block narrower than 2 grid steps has no room for a vertical edge or a
   centre: V/v/D there become F/f (by the sign rule of 3); a block lower than 2
   steps likewise turns H/h/D into F/f.

Variants (vertex compatibility): a side gets a midpoint when either block
sharing it asks for one (V/v: top and bottom; H/h: left and right; blocks on
the mesh border have no outside neighbour).  The block's split mask then picks
its template from the look-up table (:mod:`wavemesh.model.templates`).  Variants
never add midpoints of their own, so one pass settles every block.
"""

from __future__ import annotations

import numpy as np

from wavemesh.limits import TAU_MAX  # one source: the wire protocol's CONFIG range too, wm_protocol.h
from wavemesh.model.haar import HaarLevel
from wavemesh.model.templates import (
    KIND_DIAGONAL,
    KIND_FLAT,
    KIND_HORIZONTAL,
    KIND_VERTICAL,
    SIDE_BOTTOM,
    SIDE_LEFT,
    SIDE_RIGHT,
    SIDE_TOP,
    template_set,
)
from wavemesh.record import record


def block_edges(n: int, size: int) -> np.ndarray:
    """Grid positions of the block boundaries along an axis of n samples: 0, S, 2S, ..., n-1."""
    if n < 2:
        raise ValueError("an axis needs at least 2 samples")
    nb = -(-(n - 1) // size)
    return np.minimum(np.arange(nb + 1, dtype=np.int64) * size, n - 1)


def tau_counts(tau: float, scale: float) -> int:
    """A threshold in height units as an integer in detail-coefficient units.

    A detail d stands for d / 2 * scale height units, so |d| * scale / 2 > tau
    exactly when |d| > floor(2 * tau / scale) (d is an integer).
    """
    if not np.isfinite(tau) or tau < 0:
        raise ValueError(f"tau must be a finite number >= 0, got {tau}")
    q = 2.0 * tau / scale
    return TAU_MAX if q >= TAU_MAX else int(np.floor(q))


@record(frozen=True)
class Labelling:
    """Per-block results of the template stage, each array (block rows, block columns)."""

    xs: np.ndarray  # block column boundaries (grid x)
    ys: np.ndarray  # block row boundaries (grid y)
    label: np.ndarray  # label codes 0..6 (templates.LABELS)
    mask: np.ndarray  # split masks 0..15
    template: np.ndarray  # template ids


def dominant_labels(level: HaarLevel, tau_q: int, shape: tuple[int, int]) -> np.ndarray:
    """Steps 1-3 above on the first shape[0] x shape[1] blocks of a level."""
    rows, cols = shape
    d1 = level.d1[:rows, :cols]
    d2 = level.d2[:rows, :cols]
    d3 = level.d3[:rows, :cols]
    a1, a2, a3 = np.abs(d1), np.abs(d2), np.abs(d3)
    kind = np.where(
        (a1 >= a2) & (a1 >= a3), KIND_VERTICAL, np.where(a2 >= a3, KIND_HORIZONTAL, KIND_DIAGONAL)
    )
    top = np.maximum(np.maximum(a1, a2), a3)
    kind = np.where(top > tau_q, kind, KIND_FLAT)
    dual = (d1 * d2 < 0) & (kind != KIND_DIAGONAL)
    return (kind << 1 | dual).astype(np.int64)


def label_blocks(level: HaarLevel, tau_q: int, width: int, height: int) -> Labelling:
    """Label, demote, resolve and look up every block of a W x H grid from level M."""
    size = 1 << level.m
    xs, ys = block_edges(width, size), block_edges(height, size)
    rows, cols = len(ys) - 1, len(xs) - 1
    label = dominant_labels(level, tau_q, (rows, cols))
    kind, dual = label >> 1, label & 1

    narrow = (np.diff(xs) < 2)[None, :]
    low = (np.diff(ys) < 2)[:, None]
    demote = (narrow & ((kind == KIND_VERTICAL) | (kind == KIND_DIAGONAL))) | (
        low & ((kind == KIND_HORIZONTAL) | (kind == KIND_DIAGONAL))
    )
    sign_dual = (level.d1[:rows, :cols] * level.d2[:rows, :cols] < 0).astype(np.int64)
    label = np.where(demote, KIND_FLAT << 1 | sign_dual, kind << 1 | dual)
    kind = label >> 1

    vert = kind == KIND_VERTICAL
    horiz = kind == KIND_HORIZONTAL
    # hsplit[j, i]: horizontal boundary j (row j of ys) has a midpoint in block column i
    hsplit = np.zeros((rows + 1, cols), dtype=bool)
    hsplit[:-1] |= vert  # a V block splits its top side ...
    hsplit[1:] |= vert  # ... and its bottom side
    vsplit = np.zeros((rows, cols + 1), dtype=bool)
    vsplit[:, :-1] |= horiz
    vsplit[:, 1:] |= horiz
    mask = (
        hsplit[:-1] * SIDE_TOP
        + vsplit[:, :-1] * SIDE_LEFT
        + vsplit[:, 1:] * SIDE_RIGHT
        + hsplit[1:] * SIDE_BOTTOM
    ).astype(np.int64)

    lut = np.asarray(template_set().lut, dtype=np.int64)
    template = lut[label << 4 | mask]
    if np.any(template == 0xFF):  # cannot happen: V/H always carry their own sides
        raise AssertionError("template look-up hit an invalid entry")
    return Labelling(xs, ys, label, mask, template)
