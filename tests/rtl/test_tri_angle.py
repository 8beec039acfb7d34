"""rtl/tri_angle.v, the angle unit, against wavemesh.model.angle (bench: tri_angle_tb.py), and
wavemesh.model.angle against the C (firmware/src/fixed.c's wm_angle_q16 and wm_min_corner through the
native library).

The bench runs (x, y) of every size, the edges of the halvings and the doubling, the axes and the
extremes, and the smallest corners of random triangles, under random back-pressure.
"""

import ctypes
import math
import random
import re
import subprocess

from tri_angle_tb import random_xy
from tri_engine_tb import random_triangles
from wavemesh.device import gen
from wavemesh.harness.rtl_runner import RTL, run
from wavemesh.model.angle import ATAN_Q16, HALF_PI_Q16, angle_q16, min_corner
from wavemesh.refine import native


def test_tri_angle():
    run("tri_angle", [RTL / "tri_angle.v"], "tri_angle_tb", extra_env={"TRI_ANGLE_SEED": "1"})


def test_model_tables_are_rounded_atan():
    """The one source of the CORDIC's constants (the model's, computed from math.atan; fixed.c's and the
    unit's generated from them) holds the values the firmware and the unit were written and checked with:
    atan(2^-i) and pi / 2 in Q16, each rounded to nearest (fixed.c's error bound assumes it), and none
    within 0.01 of a rounding tie, so no libm's last bit of atan can move one."""
    assert ATAN_Q16 == (51472, 30386, 16055, 8150, 4091, 2047, 1024, 512, 256, 128, 64, 32, 16, 8, 4, 2, 1)
    assert HALF_PI_Q16 == 102944
    exact = [math.atan(2.0**-i) * 65536 for i in range(17)] + [math.pi * 32768]
    for a, x in zip([*ATAN_Q16, HALF_PI_Q16], exact, strict=True):
        assert abs(a - x) <= 0.5 - 0.01, (a, x)


def test_generated_tables(tmp_path):
    """wm_angle.h and wm_angle.vh carry the model's constants: the C header compiled and printed, the
    Verilog include's case arms read back."""
    gen.write_all(tmp_path)
    (tmp_path / "t.c").write_text('#include <stdio.h>\n#include "wm_angle.h"\nint main(void) {\n'
                                  '    printf("%d %d", WM_ANGLE_STEPS, WM_HALF_PI_Q16);\n'
                                  '    for (int i = 0; i < WM_ANGLE_STEPS; i++)\n'
                                  '        printf(" %d", (int)wm_atan_q16[i]);\n'
                                  '    return 0;\n}\n')
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", f"-I{tmp_path}",
                    str(tmp_path / "t.c"), "-o", str(tmp_path / "t")], check=True)
    out = [int(v) for v in subprocess.run([str(tmp_path / "t")], capture_output=True, text=True,
                                          check=True).stdout.split()]
    assert out == [len(ATAN_Q16), HALF_PI_Q16, *ATAN_Q16]
    vh = (tmp_path / "wm_angle.vh").read_text()
    arms = re.findall(r"5'd(\d+): wm_atan_q16 = 19'sd(\d+);", vh)
    assert [(int(i), int(a)) for i, a in arms] == list(enumerate(ATAN_Q16))
    assert f"WM_HALF_PI_Q16 = 19'sd{HALF_PI_Q16};" in vh
    assert f"WM_ANGLE_LAST = 5'd{len(ATAN_Q16) - 1};" in vh


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
