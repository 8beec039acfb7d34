"""The normal metric's slope factor of a triangle, in integers: the model of firmware/src/tri_error.c's
``slope_square`` and ``wm_isqrt64`` (the slope factor r = isqrt(X) << k) and of the slope unit
(rtl/tri_slope.v).

For a triangle with corners (x_k, y_k), twice its area D > 0, corner heights z_k and the slope scales
s_x = m_x / 2^e_x, s_y = m_y / 2^e_y (``wm_slope_scale``: m < 2^16, e in 0..126):

    Na = (z1 - z0)(y2 - y0) - (z2 - z0)(y1 - y0),   Nb = (x1 - x0)(z2 - z0) - (x2 - x0)(z1 - z0)
    ga = min(floor(2^16 |Na| m_x / 2^e_x / D), 2^62)      gb alike with Nb, m_y, e_y
    k  = the smallest k with ga >> k and gb >> k below 2^31
    X  = floor(2^32 / 4^k) (0 when 2 k >= 33) + (ga >> k)^2 + (gb >> k)^2
    r  = floor(sqrt(X)) << k                               sqrt(1 + g^2) in Q16.16, rounded down

(tri_error.c's head comment has the rounding; docs/soc.md, "The slope unit", the hardware.)
"""

from __future__ import annotations

import math

GCAP = 1 << 62


def twice_area(x, y) -> int:
    """D = orient(p0, p1, p2) (> 0: counter-clockwise)."""
    dx1, dy1 = int(x[1]) - int(x[0]), int(y[1]) - int(y[0])
    dx2, dy2 = int(x[2]) - int(x[0]), int(y[2]) - int(y[0])
    return dx1 * dy2 - dx2 * dy1


def frac_mul(n: int, d: int, m: int, e: int, sh: int = 16, cap: int = GCAP) -> int:
    """min(floor(n m 2^sh / 2^e / d), cap): fixed.c's wm_frac_mul."""
    return min((n * m << sh) // (d << e), cap)


def slope_square(x, y, z, sx: tuple[int, int], sy: tuple[int, int]) -> tuple[int, int]:
    """(X, k) of the triangle (corners x, y; heights z; the scales (m, e) along x and y)."""
    d = twice_area(x, y)
    dz1, dz2 = int(z[1]) - int(z[0]), int(z[2]) - int(z[0])
    na = dz1 * (int(y[2]) - int(y[0])) - dz2 * (int(y[1]) - int(y[0]))
    nb = (int(x[1]) - int(x[0])) * dz2 - (int(x[2]) - int(x[0])) * dz1
    ga = frac_mul(abs(na), d, sx[0], sx[1])
    gb = frac_mul(abs(nb), d, sy[0], sy[1])
    k = 0
    while (ga >> k) >= 1 << 31 or (gb >> k) >= 1 << 31:
        k += 1
    one = 0 if 2 * k >= 33 else (1 << 32) >> (2 * k)
    return one + (ga >> k) ** 2 + (gb >> k) ** 2, k


def slope_root(x, y, z, sx: tuple[int, int], sy: tuple[int, int]) -> tuple[int, int]:
    """(floor(sqrt(X)), k): what the slope unit returns; (0, 0) when D <= 0."""
    if twice_area(x, y) <= 0:
        return 0, 0
    big_x, k = slope_square(x, y, z, sx, sy)
    return math.isqrt(big_x), k


def slope_factor(x, y, z, sx: tuple[int, int], sy: tuple[int, int]) -> int:
    """r = floor(sqrt(X)) << k, sqrt(1 + g^2) in Q16.16 (>= 2^16)."""
    root, k = slope_root(x, y, z, sx, sy)
    return root << k
