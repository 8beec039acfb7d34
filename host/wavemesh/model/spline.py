"""The integer 2D spline-wavelet filter bank (dissertation 3.3.4, fig. 3.5(b) and 3.7).

The spline wavelet of Mallat and Zhong: the scaling function is the cubic B-spline, the wavelet the
quadratic spline that is its (discrete) derivative, one vanishing moment.  Its two-scale filters are

    h = [1, 3, 3, 1] / 8    at taps 2i-1, 2i, 2i+1, 2i+2      (cubic spline, low pass)
    g = [-1, 1]             at taps 2i, 2i+1                  (quadratic spline, high pass)

both centred on 2i + 1/2, the centre of the Haar pair (2i, 2i+1): coefficient (i, j) of every level
describes the same square of samples as the Haar coefficient (i, j), which is what the labeller and
the refiner's cell look-up assume (docs/model.md, "Blocks").  The 2D bank is the tensor product of
eq. 3.19 (fig. 3.7: scaling function h x h, wavelets g x h, h x g, g x g).  In integers, on the
previous level's approximation ``a`` (h x w), with the vertical sums of each column c

    L[c] = a[2i-1, c] + 3 a[2i, c] + 3 a[2i+1, c] + a[2i+2, c]      (sum of weights 8)
    D[c] = a[2i+1, c] - a[2i, c]

one record per (i, j):

    a'  = (L[2j-1] + 3 L[2j] + 3 L[2j+1] + L[2j+2] + 32) >> 6      16 bits unsigned
    d1  = (L[2j+1] - L[2j] + 2) >> 2                                right minus left     18 bits signed
    d2  = (D[2j-1] + 3 D[2j] + 3 D[2j+1] + D[2j+2] + 2) >> 2        bottom minus top     18 bits signed
    d3  = D[2j+1] - D[2j]                                           diagonal minus anti  18 bits signed

Scaling: the same as the Haar bank's (``wavemesh.model.haar``), so every threshold (tau, delta_d) means the
same with either wavelet: the high-pass filter is applied to the smoothed (weights 8) neighbours and the
result divided by 4, so a plane of slope g per sample gives d1 = 2g at level 1 exactly as Haar does,
and d3 is Haar's d3 itself (p00 + p11 - p01 - p10).  d1 and d2 round half up (``+ 2 >> 2``, an
arithmetic shift: floor); the approximation rounds half up like Haar's.

Borders: every index is clamped into the level (a[-1] = a[0], a[h] = a[h+1] = a[h-1]), so an odd
last row or column pairs with itself exactly as Haar pads it, and the filters see a constant
extension beyond the edge (no false edge).  Level m has ceil(H / 2^m) x ceil(W / 2^m) entries.
"""

from __future__ import annotations

import numpy as np

H_TAPS = (1, 3, 3, 1)  # cubic B-spline at offsets -1, 0, 1, 2 from 2i


def _taps(n: int) -> list[np.ndarray]:
    """The clamped input indices of offsets -1, 0, 1, 2 for every output position 0..ceil(n/2)-1."""
    base = 2 * np.arange(-(-n // 2))
    return [np.clip(base + k, 0, n - 1) for k in (-1, 0, 1, 2)]


def spline_step(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One level of the spline filter bank on an (h, w) integer array; returns (a', d1, d2, d3)."""
    a = np.asarray(a, dtype=np.int64)
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"spline_step needs a non-empty 2-D array, got shape {a.shape}")
    r = _taps(a.shape[0])
    c = _taps(a.shape[1])
    low = sum(w * a[idx, :] for w, idx in zip(H_TAPS, r, strict=True))  # L, (h2, w)
    high = a[r[2], :] - a[r[1], :]  # D, (h2, w)
    approx = (sum(w * low[:, idx] for w, idx in zip(H_TAPS, c, strict=True)) + 32) >> 6
    d1 = (low[:, c[2]] - low[:, c[1]] + 2) >> 2
    d2 = (sum(w * high[:, idx] for w, idx in zip(H_TAPS, c, strict=True)) + 2) >> 2
    d3 = high[:, c[2]] - high[:, c[1]]
    return approx, d1, d2, d3
