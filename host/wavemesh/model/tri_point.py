"""One sample's error against a triangle's plane, in integers: the model of firmware/src/tri_error.c's
``wm_point_error`` (without a holes mask) and of the point-error unit (rtl/tri_point.v).

For the counter-clockwise triangle (x_k, y_k) with corner heights z_k, the sample p = (px, py) of height
h and the slope factor r (``wavemesh.model.tri_slope``; None: the vertical metric):

    D  = orient(p0, p1, p2),   E_k = orient(p_k+1, p_k+2, p)
    V  = |E_0 z_0 + E_1 z_1 + E_2 z_2 - D h|
    ev = min(ceil(2^16 V / D), 2^32 - 1)                   the vertical error, Q16.16
    e  = ev when r is None or ev = 0, else ceil(2^16 ev / r)

and all ones when D <= 0 (tri_error.c's head comment has the rounding).
"""

from __future__ import annotations

ALL_ONES = 0xFFFFFFFF


def orient(ax: int, ay: int, bx: int, by: int, cx: int, cy: int) -> int:
    """(b - a) x (c - a): twice the signed area of (a, b, c), > 0 counter-clockwise."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def point_v(x, y, z, px: int, py: int, h: int) -> tuple[int, int]:
    """(|V|, D) of the sample (px, py) of height h against the triangle (x, y) with heights z."""
    x, y, z = [int(v) for v in x], [int(v) for v in y], [int(v) for v in z]
    d = orient(x[0], y[0], x[1], y[1], x[2], y[2])
    s = sum(orient(x[(k + 1) % 3], y[(k + 1) % 3], x[(k + 2) % 3], y[(k + 2) % 3], px, py) * z[k]
            for k in range(3))
    return abs(s - d * int(h)), d


def point_error(x, y, z, px: int, py: int, h: int, r: int | None = None) -> int:
    """e of the module docstring: the vertical error (r None) or the normal one with slope factor r."""
    v, d = point_v(x, y, z, px, py, h)
    if d <= 0:
        return ALL_ONES
    ev = min(-(-(v << 16) // d), ALL_ONES)
    if r is None or ev == 0:
        return ev
    return -(-(ev << 16) // r)
