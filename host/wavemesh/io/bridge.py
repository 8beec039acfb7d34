"""``--max-hole N``: the enclosed dropouts of at most N samples bridged at input, filled as ``--fill
nearest`` fills them, before the run (docs/model.md, "Holes")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wavemesh.model.holemask import stranded


def small_holes(mask: np.ndarray, max_hole: int) -> np.ndarray:
    """(H, W) bool: the samples of the 8-connected groups of ``mask`` that hold at most ``max_hole``
    samples and do not touch the rectangle's border (the enclosed dropouts --max-hole bridges)."""
    from scipy import ndimage  # start-up: scipy only for masks (tests/host/test_mesh_costs.py)

    bad = np.asarray(mask, dtype=bool)
    lab, n = ndimage.label(bad, structure=np.ones((3, 3), dtype=bool))
    size = np.bincount(lab.ravel(), minlength=n + 1)
    keep = size <= max_hole
    keep[0] = False
    keep[np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]])] = False
    return keep[lab]


def bridge(hf, max_hole: int):
    """--max-hole N: the height field with its enclosed groups of at most N invalid samples (small_holes)
    made valid, at the heights --fill nearest gives them (the mask's heights are a nearest valid sample's
    already: heightfield.from_array), the others left holes; the stranded samples found afresh (a bridged
    dropout may give them a cell of valid samples).  ``filled`` counts the bridged samples."""
    if max_hole <= 0 or hf.mask is None:
        return hf
    raw = hf.mask if hf.lone is None else hf.mask & ~hf.lone
    small = small_holes(raw, max_hole)
    if not small.any():
        return hf
    bad = raw & ~small
    lone = stranded(bad)
    mask = bad | lone
    return replace(hf, mask=np.ascontiguousarray(mask) if mask.any() else None,
                   lone=lone if lone.any() else None, filled=hf.filled + int(np.count_nonzero(small)))
