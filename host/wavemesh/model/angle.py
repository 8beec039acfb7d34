"""A triangle's smallest angle in integers: the model of firmware/src/fixed.c's ``wm_angle_q16`` (atan2 by
CORDIC in Q16 radians) and ``wm_min_corner`` (the dot and cross products at the corner of the smallest
angle), and of the angle unit (rtl/tri_angle.v).

``angle_q16(x, y)`` for y >= 0:

    1. while |x| > 2^28 or y > 2^28: x, y = x / 2, y / 2 (both toward zero)
    2. x < 0: (x, y) = (y, -x), z = pi/2 in Q16 (102,944); else z = 0
    3. x, y >= 0 both below 2^27 and not both 0: both doubled until the larger reaches 2^27
       (shifted left by 28 minus the bit length of x | y)
    4. 17 rotations i = 0..16, while y != 0: y > 0: x += y >> i, y -= x >> i, z += atan(2^-i);
       y < 0: x -= y >> i, y += x >> i, z -= atan(2^-i) (y >> i toward zero; x the value before the
       step in both updates)
    5. the result max(z, 0)

(docs/soc.md, "The angle unit", the hardware.)
"""

from __future__ import annotations

import math

# The one source of the CORDIC's constants: the firmware's (wm_angle.h) and the angle unit's (wm_angle.vh)
# are generated from these (wavemesh.device.gen).  atan(2^-i) in Q16 radians, i = 0..16, and pi / 2, each
# rounded to nearest (fixed.c's error bound assumes it): 51472, 30386, ..., 2, 1 and 102,944.
ATAN_Q16 = tuple(round(math.atan(2.0**-i) * 65536) for i in range(17))
HALF_PI_Q16 = round(math.pi / 2 * 65536)


def _shr0(v: int, s: int) -> int:
    """v / 2^s toward zero."""
    return v >> s if v >= 0 else -((-v) >> s)


def angle_q16(x: int, y: int) -> int:
    """atan2(y, x) in Q16 radians for y >= 0 (0 .. pi): wm_angle_q16."""
    if y < 0:
        raise ValueError("angle_q16: y < 0")
    z = 0
    lim = 1 << 28
    while x > lim or x < -lim or y > lim:
        x, y = _shr0(x, 1), _shr0(y, 1)
    if x < 0:
        x, y, z = y, -x, HALF_PI_Q16
    if (x | y) != 0 and x < (1 << 27) and y < (1 << 27):
        s = 28 - (x | y).bit_length()
        x <<= s
        y <<= s
    for i, a in enumerate(ATAN_Q16):
        xs, ys = x >> i, _shr0(y, i)
        if y > 0:
            x, y, z = x + ys, y - xs, z + a
        elif y < 0:
            x, y, z = x - ys, y + xs, z - a
        else:
            break
    return max(z, 0)


def min_corner(x, y) -> tuple[int, int]:
    """(dot, |cross|) at the corner opposite the shortest side (the first of equal ones):
    wm_min_corner."""
    sx = [int(x[(i + 2) % 3]) - int(x[(i + 1) % 3]) for i in range(3)]
    sy = [int(y[(i + 2) % 3]) - int(y[(i + 1) % 3]) for i in range(3)]
    length = [sx[i] * sx[i] + sy[i] * sy[i] for i in range(3)]
    k = 0
    if length[1] < length[k]:
        k = 1
    if length[2] < length[k]:
        k = 2
    c, d = (k + 2) % 3, (k + 1) % 3
    dot = -(sx[c] * sx[d] + sy[c] * sy[d])
    cross = sx[1] * sy[2] - sy[1] * sx[2]
    return dot, abs(cross)

