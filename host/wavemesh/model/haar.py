"""The integer multi-level 2D Haar filter bank (dissertation 3.3.3, eq. 3.16 and 3.19).

This is the specification the RTL filter bank (``rtl/haar_*``) must match bit for
bit, so every operation is stated in integers (docs/model.md, "Filter bank").

One level takes an approximation ``a`` of h x w samples (level 0: the 16-bit
height samples) and makes four arrays of ceil(h/2) x ceil(w/2), one entry per
2 x 2 block of ``a``::

        col 2j   col 2j+1
      +--------+--------+
      |  p00   |  p01   |   row 2i
      +--------+--------+
      |  p10   |  p11   |   row 2i+1
      +--------+--------+

    a'  = (p00 + p01 + p10 + p11 + 2) >> 2        mean, rounded half up   (16 bits unsigned)
    d1  = (p01 + p11) - (p00 + p10)               right minus left        (18 bits signed)
    d2  = (p10 + p11) - (p00 + p01)               bottom minus top        (18 bits signed)
    d3  = (p00 + p11) - (p01 + p10)               diagonal minus anti     (18 bits signed)

Scaling: a detail is twice the difference of the two half-block means, in
sample counts, whatever the level: d / 2 * scale is that difference in height
units, so a step of height h across a block gives |d| = 2h/scale at every level
and thresholds like delta_d mean the same at every level.  (The orthonormal
Haar coefficients of eq. 3.16 are these values times 2^(m-1); we drop that
factor on purpose.)  d1 ~ df/dx and d2 ~ df/dy as eq. 3.24 reads them.

Padding: when h or w is odd, the last row or column of ``a`` is repeated once
to make it even (p01 = p00 at the right edge, p10 = p00 at the bottom), at every
level.  Level m therefore has ceil(H / 2^m) x ceil(W / 2^m) entries and a padded
block shows no variation across the padding.  A streaming implementation only
has to pair the odd last sample of a row (or the last row) with itself.
"""

from __future__ import annotations

import math

import numpy as np

from wavemesh.limits import MAX_LEVELS  # one source: the model's and the protocol's limits, wm_protocol.h
from wavemesh.model.spline import spline_step
from wavemesh.record import record

DETAIL_BITS = 18  # signed width of d1, d2, d3 (|d| <= 2 * 65535)
APPROX_BITS = 16  # unsigned width of a


@record(frozen=True)
class HaarLevel:
    """Coefficients of one level m: arrays of ceil(H/2^m) x ceil(W/2^m)."""

    m: int
    a: np.ndarray  # int64, 0..65535
    d1: np.ndarray  # int64, right minus left
    d2: np.ndarray  # int64, bottom minus top
    d3: np.ndarray  # int64, diagonal minus anti-diagonal


def haar_step(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One level of the filter bank on an (h, w) integer array; returns (a', d1, d2, d3)."""
    a = np.asarray(a, dtype=np.int64)
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"haar_step needs a non-empty 2-D array, got shape {a.shape}")
    if a.shape[1] % 2:
        a = np.concatenate([a, a[:, -1:]], axis=1)
    if a.shape[0] % 2:
        a = np.concatenate([a, a[-1:, :]], axis=0)
    p00, p01 = a[0::2, 0::2], a[0::2, 1::2]
    p10, p11 = a[1::2, 0::2], a[1::2, 1::2]
    approx = (p00 + p01 + p10 + p11 + 2) >> 2
    d1 = (p01 + p11) - (p00 + p10)
    d2 = (p10 + p11) - (p00 + p01)
    d3 = (p00 + p11) - (p01 + p10)
    return approx, d1, d2, d3


def decompose(samples: np.ndarray, levels: int, wavelet: str = "haar") -> list[HaarLevel]:
    """Levels 1..M of the filter bank on (H, W) 16-bit samples; element m-1 is level m.

    ``wavelet`` picks the filters (WAVELETS): "haar" (this module) or "spline" (wavemesh.model.spline, the
    dissertation's spline wavelet); both give records of the same shapes, widths and scale."""
    samples = np.asarray(samples)
    if samples.ndim != 2 or min(samples.shape) < 1:
        raise ValueError(f"decompose needs a non-empty 2-D array, got shape {samples.shape}")
    if not 1 <= levels <= MAX_LEVELS:
        raise ValueError(f"levels must be 1..{MAX_LEVELS}, got {levels}")
    if samples.min() < 0 or samples.max() > 0xFFFF:
        raise ValueError("samples must be 16-bit unsigned")
    if wavelet not in WAVELETS:
        raise ValueError(f"wavelet must be one of {', '.join(WAVELETS)}, got {wavelet!r}")
    step = WAVELETS[wavelet]
    out = []
    a = samples.astype(np.int64)
    for m in range(1, levels + 1):
        a, d1, d2, d3 = step(a)
        out.append(HaarLevel(m, a, d1, d2, d3))
    return out


WAVELETS = {"haar": haar_step, "spline": spline_step}  # --wavelet: name -> one level's step


def default_levels(width: int, height: int) -> int:
    """The default M, log2(max(W, H)) - 3 within 1..8: about 8 blocks across, as the paper's 128/M=4,
    256/M=5, 512/M=6."""
    return min(8, max(1, int(math.floor(math.log2(max(width, height)))) - 3))


def level_shape(height: int, width: int, m: int) -> tuple[int, int]:
    """Shape (rows, cols) of level m's arrays for an H x W input."""
    s = 1 << m
    return (-(-height // s), -(-width // s))
