"""The dissertation's synthetic data sets, rebuilt from their descriptions.

The originals are lost with the figures; each function says what the text
gives and what we chose.  All return (H, W) float64 arrays in their own units.

- f1, f2, f3 (3.6.3): the quadratics -5x^2 - 10y^2 (elliptic), 5x^2 (parabolic),
  5x^2 - 10y^2 (hyperbolic) on 128 x 128 samples.  The domain is not given; we
  sample x and y on [-1, 1] (x along columns, y along rows).  ``extent=np.pi``
  samples [-pi, pi] instead, where Table 3.1's errors are reproduced
  (docs/initial-results.md); the meshes are the same on either.
- f4 (3.6.3): 128 x 128, values 0..110, "smooth changes through the diagonal":
  a tanh ramp across the anti-diagonal, 16 samples wide, rounded to integers.
- f5 (3.6.3): 128 x 128, values 0..110, "discontinuities along the boundary of a
  circle": a disc of radius 40 at 110 on a floor of 0.
- ball (5.2.1): 256 x 256, 0..96, "smooth surface with sharp discontinuities": a
  sphere of radius 80 whose centre stands 16 above the floor, so its top is at
  96 and its rim is a 16-unit cliff.
- box (5.2.1): 256 x 256, 0..250: a box with vertical sides on a floor of 0 whose
  top is a plane rising from 200 to 250 across it.
"""

from __future__ import annotations

import numpy as np


def _xy(n: int, extent: float = 1.0):
    t = np.linspace(-extent, extent, n)
    return np.meshgrid(t, t)  # x varies along columns, y along rows


def f1(n: int = 128, extent: float = 1.0) -> np.ndarray:
    x, y = _xy(n, extent)
    return -5 * x**2 - 10 * y**2


def f2(n: int = 128, extent: float = 1.0) -> np.ndarray:
    x, _ = _xy(n, extent)
    return 5 * x**2 + 0 * _


def f3(n: int = 128, extent: float = 1.0) -> np.ndarray:
    x, y = _xy(n, extent)
    return 5 * x**2 - 10 * y**2


def f4(n: int = 128) -> np.ndarray:
    j, i = np.meshgrid(np.arange(n), np.arange(n))
    return np.round(55.0 * (1.0 + np.tanh((i + j - (n - 1)) / 16.0)))


def f5(n: int = 128) -> np.ndarray:
    j, i = np.meshgrid(np.arange(n), np.arange(n))
    c = (n - 1) / 2
    return np.where((i - c) ** 2 + (j - c) ** 2 <= (40.0 * n / 128) ** 2, 110.0, 0.0)


def ball(n: int = 256) -> np.ndarray:
    j, i = np.meshgrid(np.arange(n), np.arange(n))
    c = (n - 1) / 2
    r2 = (i - c) ** 2 + (j - c) ** 2
    radius = 80.0 * n / 256
    cap = 16.0 + np.sqrt(np.maximum(radius**2 - r2, 0.0)) * (80.0 / radius)
    return np.where(r2 <= radius**2, cap, 0.0)


def box(n: int = 256) -> np.ndarray:
    j, i = np.meshgrid(np.arange(n), np.arange(n))
    lo, hi = int(n * 72 / 256), int(n * 184 / 256)
    inside = (j >= lo) & (j < hi) & (i >= int(n * 56 / 256)) & (i < int(n * 200 / 256))
    top = 200.0 + 50.0 * (j - lo) / max(hi - 1 - lo, 1)
    return np.where(inside, top, 0.0)


DATASETS = {"f1": f1, "f2": f2, "f3": f3, "f4": f4, "f5": f5, "ball": ball, "box": box}
ALIASES = {"elliptic": "f1", "parabolic": "f2", "hyperbolic": "f3"}


def make(name: str, n: int | None = None) -> np.ndarray:
    """A data set by name (f1..f5, elliptic, parabolic, hyperbolic, ball, box), n x n samples."""
    fn = DATASETS[ALIASES.get(name, name)]
    return fn() if n is None else fn(n)
