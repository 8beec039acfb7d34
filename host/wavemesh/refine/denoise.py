"""De-noising before the mesh (dissertation 5.5): SURE soft thresholding of the wavelet details, the
inverse transform, and an optional 5 x 5 median filter.

5.5: "we have applied the de-noising technique for the noisy input data, and instead of using the
original data, the reconstructed data is used for the height value ... We have selected the threshold
values by using Stein's unbiased risk estimate method [Stein 81] and used soft-thresholding for detail
coefficients at each decomposition level", and "we applied a 5 x 5 median filter to remove peak noise".
What the text leaves open, and what we chose:

- The transform: the orthonormal 2-D Haar wavelet in floating point (the project's wavelet, made
  orthonormal so that white noise of deviation sigma stays white with the same sigma in every detail
  band, which SURE assumes), over ``levels(W, H)`` = the mesh's default M levels, the last row and
  column repeated where a size is odd (as the filter bank pads), cropped after the inverse.
- The noise: sigma = median(|d|) / 0.6745 of the finest diagonal band (Donoho and Johnstone's estimate).
- The threshold, per level and per band (d1, d2, d3): t = sigma t*, t* the minimiser of Stein's
  unbiased risk estimate of soft thresholding over [0, sqrt(2 ln n)] (SureShrink's range; the
  minimum is at 0 or at one of the |d| / sigma), n the band's size (:func:`sure_threshold`).
- ``median``: scipy's 5 x 5 median filter (edges: nearest sample), after the wavelet step in
  ``sure+median``.

The result replaces the height field before anything else sees it (``wavemesh.api.load_input``), so
`mesh`, `stream` and `check` all mesh and measure the same de-noised heights: a device gets the
de-noised samples, and its mesh equals `wavemesh mesh --denoise ...`'s.  The error bound holds against
the de-noised heights.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from wavemesh.errors import InputError
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import default_levels

METHODS = ("sure", "median", "sure+median")
MEDIAN_SIZE = 5  # 5.5's 5 x 5 median filter
MAD_TO_SIGMA = 0.6745  # the median of |N(0, 1)|


def levels_for(width: int, height: int) -> int:
    """The transform's depth: the mesh's default M (haar.default_levels), within what the grid allows."""
    return max(1, min(default_levels(width, height), int(math.log2(max(2, min(width, height))))))


def haar_forward(a: np.ndarray, levels: int) -> tuple[np.ndarray, list[tuple[np.ndarray, ...]], list]:
    """Orthonormal 2-D Haar: (approximation, [(d1, d2, d3) per level, finest first], shapes before each
    level's padding)."""
    a = np.asarray(a, dtype=np.float64)
    details, shapes = [], []
    for _ in range(levels):
        shapes.append(a.shape)
        if a.shape[1] % 2:
            a = np.concatenate([a, a[:, -1:]], axis=1)
        if a.shape[0] % 2:
            a = np.concatenate([a, a[-1:, :]], axis=0)
        p00, p01, p10, p11 = a[0::2, 0::2], a[0::2, 1::2], a[1::2, 0::2], a[1::2, 1::2]
        details.append(((p01 + p11 - p00 - p10) / 2, (p10 + p11 - p00 - p01) / 2,
                        (p00 + p11 - p01 - p10) / 2))
        a = (p00 + p01 + p10 + p11) / 2
    return a, details, shapes


def haar_inverse(a: np.ndarray, details: list[tuple[np.ndarray, ...]], shapes: list) -> np.ndarray:
    """The inverse of haar_forward."""
    for (d1, d2, d3), shape in zip(reversed(details), reversed(shapes), strict=True):
        out = np.empty((2 * a.shape[0], 2 * a.shape[1]))
        out[0::2, 0::2] = (a - d1 - d2 + d3) / 2
        out[0::2, 1::2] = (a + d1 - d2 - d3) / 2
        out[1::2, 0::2] = (a - d1 + d2 - d3) / 2
        out[1::2, 1::2] = (a + d1 + d2 + d3) / 2
        a = out[:shape[0], :shape[1]]
    return a


def sure_threshold(x: np.ndarray) -> float:
    """The t in [0, sqrt(2 ln n)] minimising Stein's unbiased estimate of the risk of soft thresholding
    x (unit noise) at t: SURE(t) = n - 2 #{|x_i| <= t} + sum min(|x_i|, t)^2.  Between consecutive
    |x_i| it rises with t, so the minimum is at 0 or at some |x_i| (ties: the smallest t)."""
    a = np.sort(np.abs(np.asarray(x, dtype=np.float64).ravel()))
    n = a.size
    if n == 0:
        return 0.0
    cap = math.sqrt(2 * math.log(max(n, 2)))
    k = np.arange(1, n + 1)
    risk = n - 2 * k + np.cumsum(a * a) + (n - k) * a * a  # at t = a[k-1]
    risk = np.where(a <= cap, risk, np.inf)
    i = int(np.argmin(risk))
    return float(a[i]) if risk[i] < n else 0.0  # SURE(0) = n


def soft(x: np.ndarray, t: float) -> np.ndarray:
    return np.sign(x) * np.maximum(np.abs(x) - t, 0.0)


def sure_denoise(values: np.ndarray, levels: int) -> tuple[np.ndarray, dict]:
    """5.5's wavelet de-noising of a height array: (de-noised array, what was done)."""
    a, details, shapes = haar_forward(values, levels)
    diag = details[0][2]
    sigma = float(np.median(np.abs(diag)) / MAD_TO_SIGMA) if diag.size else 0.0
    thresholds, out = [], []
    for bands in details:
        ts = [sigma * sure_threshold(d / sigma) if sigma > 0 else 0.0 for d in bands]
        thresholds.append(ts)
        out.append(tuple(soft(d, t) for d, t in zip(bands, ts, strict=True)))
    return haar_inverse(a, out, shapes), {"sigma": sigma, "levels": levels, "thresholds": thresholds}


def median5(values: np.ndarray) -> np.ndarray:
    from scipy.ndimage import median_filter  # start-up: scipy only for --denoise median (test_mesh_costs.py)

    return median_filter(np.asarray(values, dtype=np.float64), size=MEDIAN_SIZE, mode="nearest")


def denoise_values(values: np.ndarray, method: str) -> tuple[np.ndarray, dict]:
    """``method`` (METHODS) applied to an (H, W) array: (result, the report's "denoise" entry)."""
    h, w = values.shape
    info: dict = {"method": method}
    out = np.asarray(values, dtype=np.float64)
    if method in ("sure", "sure+median"):
        out, sure = sure_denoise(out, levels_for(w, h))
        info |= sure
    if method in ("median", "sure+median"):
        out = median5(out)
        info["median"] = f"{MEDIAN_SIZE} x {MEDIAN_SIZE}"
    diff = out - values
    info["change_max"] = float(np.abs(diff).max())
    info["change_rms"] = float(np.sqrt(np.mean(diff * diff)))
    return out, info


def denoise_heightfield(hf, method: str):
    """The height field with de-noised heights (re-quantised as a file would be), its georeference
    kept; the source names the method and the noise estimate."""
    if method not in METHODS:
        raise InputError(f"--denoise {method}: not a de-noising method", hint=f"use {', '.join(METHODS)}")
    if getattr(hf, "mask", None) is not None:
        raise InputError("--denoise and --nodata hole do not go together yet (the filters would smear the "
                         "filled-in heights under the holes)",
                         hint="fill the invalid samples, or drop --denoise")
    out, info = denoise_values(hf.values, method)
    sigma = f", sigma {info['sigma']:.4g}" if "sigma" in info else ""
    new = from_array(out, source=f"{hf.source} (de-noised: {method}{sigma})")
    return replace(new, filled=hf.filled, transform=hf.transform, crs=hf.crs, spacing=hf.spacing), info
