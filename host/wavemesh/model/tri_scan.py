"""E(T)'s scan of a triangle's samples, in integers: the model of firmware/src/tri_error.c's scan
(``scan32`` / ``scan``) and of the triangle error engine (rtl/tri_engine.v).

For a counter-clockwise triangle with corners (x_k, y_k), twice its area D > 0, corner heights z_k and
the edge functions E_k(p) = orient(p_k+1, p_k+2, p) = A_k x + B_k y + C_k, the scan visits the samples
of the closed triangle row by row (y ascending; in each row the span lo..hi, x ascending) and returns
the largest

    V(p) = | E_0(p) z_0 + E_1(p) z_1 + E_2(p) z_2 - D h(p) |

with the first sample reaching it (a later one replaces it only when strictly greater; (x_0, y_0)
while no sample beats 0).  With a limit the scan stops at the first sample whose V exceeds it and
returns that V and sample.  E(T) = ceil(2^16 Vmax / D) (vertical metric) and the normal metric's slope
factor stay with the caller (docs/refiner.md).
"""

from __future__ import annotations

import numpy as np


def tri_edges(x, y) -> tuple[list[int], list[int], list[int]]:
    """A_k, B_k, C_k of E_k(px, py) = A_k px + B_k py + C_k (k1 = k + 1, k2 = k + 2 mod 3)."""
    a, b, c = [], [], []
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        ak = int(y[k1]) - int(y[k2])
        bk = int(x[k2]) - int(x[k1])
        a.append(ak)
        b.append(bk)
        c.append(-(bk * int(y[k1])) - ak * int(x[k1]))
    return a, b, c


def row_span(a, b, c, py: int, xmin: int, xmax: int) -> tuple[int, int] | None:
    """The closed triangle's samples of row py: (lo, hi), or None when it has none (tri_error.c)."""
    lo, hi = xmin, xmax
    for k in range(3):
        num = b[k] * py + c[k]  # E_k = A x + num >= 0
        if a[k] > 0:
            lo = max(lo, -(num // a[k]))  # ceil(-num / A)
        elif a[k] < 0:
            hi = min(hi, num // -a[k])  # floor(num / -A)
        elif num < 0:
            return None
    return (lo, hi) if lo <= hi else None


def spans(x, y) -> list[tuple[int, int, int]]:
    """(py, lo, hi) of every row of the closed triangle that has samples, in scan order."""
    a, b, c = tri_edges(x, y)
    xmin, xmax = min(map(int, x)), max(map(int, x))
    out = []
    for py in range(min(map(int, y)), max(map(int, y)) + 1):
        s = row_span(a, b, c, py, xmin, xmax)
        if s is not None:
            out.append((py, s[0], s[1]))
    return out


def twice_area(x, y) -> int:
    """D = orient(p0, p1, p2), positive for a counter-clockwise triangle."""
    x0, y0 = int(x[0]), int(y[0])
    return (int(x[1]) - x0) * (int(y[2]) - y0) - (int(y[1]) - y0) * (int(x[2]) - x0)


def scan(h: np.ndarray, x, y, limit: int | None = None) -> tuple[int, int, int]:
    """(Vmax, wx, wy) of the triangle with corner columns x and rows y over the (H, W) heights h: the
    largest V and its first sample in scan order; with ``limit``, the first V above it and its sample."""
    d = twice_area(x, y)
    if d <= 0:
        raise ValueError(f"the triangle {list(zip(x, y, strict=True))} is not counter-clockwise (2 area {d})")
    a, b, c = tri_edges(x, y)
    z = [int(h[int(y[k]), int(x[k])]) for k in range(3)]
    vmax, wx, wy = 0, int(x[0]), int(y[0])
    for py, lo, hi in spans(x, y):
        row = h[py]
        for px in range(lo, hi + 1):
            s = sum((a[k] * px + b[k] * py + c[k]) * z[k] for k in range(3))
            v = abs(s - d * int(row[px]))
            if v > vmax:
                vmax, wx, wy = v, px, py
                if limit is not None and v > limit:
                    return vmax, wx, wy
    return vmax, wx, wy
