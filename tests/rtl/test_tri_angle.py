"""rtl/tri_angle.v, the angle unit, against wavemesh.model.angle (bench: tri_angle_tb.py), and
wavemesh.model.angle against the C (firmware/src/fixed.c's wm_angle_q16 and wm_min_corner through the
native library).

The bench runs (x, y) of every size, the edges of the halvings and the doubling, the axes and the
extremes, and the smallest corners of random triangles, under random back-pressure.
"""

import ctypes
import math
import random

from tri_angle_tb import random_xy
from tri_engine_tb import random_triangles
from wavemesh.harness.rtl_runner import RTL, run
from wavemesh.model.angle import ATAN_Q16, HALF_PI_Q16, angle_q16, min_corner
from wavemesh.refine import native


def test_tri_angle():
    run("tri_angle", [RTL / "tri_angle.v"], "tri_angle_tb", extra_env={"TRI_ANGLE_SEED": "1"})


def test_model_tables_are_rounded_atan():
    """The model's constants from math, not from the C they are checked against: atan(2^-i) and pi / 2
    in Q16, rounded to nearest (fixed.c's error bound assumes it)."""
    assert list(ATAN_Q16) == [round(math.atan(2.0**-i) * 65536) for i in range(17)]
    assert round(math.pi / 2 * 65536) == HALF_PI_Q16


def test_model_matches_c():
    """The model's angle_q16 and min_corner against fixed.c's on random arguments of every size (the
    unit's 32-bit ones and the C's 64-bit ones) and on random triangles' corners."""
    lib = native.load()
    angle = lib.wm_angle_q16  # internal (wm_internal.h), exported by the shared library
    angle.restype = ctypes.c_int32
    angle.argtypes = [ctypes.c_int64, ctypes.c_int64]
    corner = lib.wm_min_corner
    corner.restype = None
    pi32, pi64 = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_int64)
    corner.argtypes = [pi32, pi32, pi64, pi64]
    rng = random.Random(7)
    for _ in range(3000):
        x, y = random_xy(rng)
        assert angle(x, y) == angle_q16(x, y), (x, y)
        b = rng.randrange(1, 64)
        x, y = rng.randrange(-(1 << b), 1 << b), rng.getrandbits(rng.randrange(0, 63))
        assert angle(x, y) == angle_q16(x, y), (x, y)
    for w, h in [(37, 23), (2048, 2048), (32767, 32767)]:
        for tri in random_triangles(rng, w, h, 400):
            xs, ys = [p[0] for p in tri], [p[1] for p in tri]
            dot, cross = ctypes.c_int64(), ctypes.c_int64()
            cx, cy = (ctypes.c_int32 * 3)(*xs), (ctypes.c_int32 * 3)(*ys)
            corner(cx, cy, ctypes.byref(dot), ctypes.byref(cross))
            assert (dot.value, cross.value) == min_corner(xs, ys), tri
