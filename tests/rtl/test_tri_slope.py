"""rtl/tri_slope.v, the slope unit, against wavemesh.model.tri_slope (bench: tri_slope_tb.py), and
wavemesh.model.tri_slope against the C (firmware/src/tri_error.c's slope factor through the native
library's wm_point_error in the normal metric).

The bench runs random triangles of every kind (thin, border, big, one sample wide, flat, the steepest
cliffs, collinear and clockwise ones) with random heights and slope scales under random back-pressure;
on the SoC's coordinates (11 bits), on small ones with one quotient and root bit a clock, and on the
widest (15 bits: the slopes' cap).
"""

import ctypes
import random

import numpy as np
import pytest
from tri_engine_tb import random_triangles
from wavemesh.harness.rtl_runner import RTL, run
from wavemesh.model.tri_slope import slope_factor, twice_area
from wavemesh.refine import native

SETS = [
    {"COORD_BITS": 11},
    {"COORD_BITS": 6, "DIV_STEPS": 1, "SQRT_STEPS": 1},
    {"COORD_BITS": 15, "DIV_STEPS": 2, "SQRT_STEPS": 1},
]


@pytest.mark.parametrize("params", SETS, ids=["soc", "small", "wide"])
def test_tri_slope(params):
    env = {"TRI_SLOPE_SEED": str(params["COORD_BITS"]), "TRI_SLOPE_COORD_BITS": str(params["COORD_BITS"]),
           "TRI_SLOPE_DIV_STEPS": str(params.get("DIV_STEPS", 2)),
           "TRI_SLOPE_SQRT_STEPS": str(params.get("SQRT_STEPS", 2))}
    run("tri_slope", [RTL / "tri_slope.v", RTL / "udiv_step.v"], "tri_slope_tb", parameters=params,
        extra_env=env)


def _point_error(lib):
    fn = lib.wm_point_error  # internal (wm_internal.h), exported by the shared library
    pi32 = ctypes.POINTER(ctypes.c_int32)
    fn.restype = ctypes.c_uint32
    fn.argtypes = [ctypes.POINTER(native.Field), ctypes.POINTER(native.Params), pi32, pi32, ctypes.c_int32,
                   ctypes.c_int32, ctypes.POINTER(ctypes.c_uint64)]
    return fn


@pytest.mark.parametrize("shape", [(37, 23), (300, 7), (3, 200)])
def test_model_matches_c(shape):
    """The model's slope factor r in the C's normal-metric point error E = ceil(2^16 ev / r) (ev the
    vertical one) at a sample inside each triangle, its height far from the plane so that E tells r
    apart from its neighbours, on random scales and cell sizes."""
    rng = random.Random(shape[0] * shape[1] + 5)
    w, hh = shape
    lib = native.load()
    point_error = _point_error(lib)
    checked = 0
    for scale, spacing in [(1.0, (1.0, 1.0)), (0.37, (2.5, 0.75)), (13.0, (1.0, 1.0)), (0.001, (3.0, 3.0))]:
        fp = native.fixed_params(native.RefineParams(metric="normal"), scale, spacing=spacing)
        sx, sy = (fp.slope_x_m, fp.slope_x_e), (fp.slope_y_m, fp.slope_y_e)
        h = np.array([[rng.randrange(65536) for _ in range(w)] for _ in range(hh)], dtype=np.uint16)
        fld = native.Field(w, hh, 1, h.ctypes.data_as(ctypes.POINTER(ctypes.c_uint16)), None, None)
        for tri in random_triangles(rng, w, hh, 150):
            x, y = [p[0] for p in tri], [p[1] for p in tri]
            d = twice_area(x, y)
            px, py = x[0], y[0]  # a sample of the closed triangle other than a corner when there is one
            for cx in range(min(x), max(x) + 1):
                for cy in range(min(y), max(y) + 1):
                    e = [(x[(k + 2) % 3] - x[(k + 1) % 3]) * (cy - y[(k + 1) % 3])
                         - (y[(k + 2) % 3] - y[(k + 1) % 3]) * (cx - x[(k + 1) % 3]) for k in range(3)]
                    if min(e) >= 0 and (cx, cy) not in tri:
                        px, py = cx, cy
            z = [int(h[y[k], x[k]]) for k in range(3)]
            xs, ys = (ctypes.c_int32 * 3)(*x), (ctypes.c_int32 * 3)(*y)
            e_c = point_error(ctypes.byref(fld), ctypes.byref(fp), xs, ys, px, py, None)
            edges = [(x[(k + 2) % 3] - x[(k + 1) % 3]) * (py - y[(k + 1) % 3])
                     - (y[(k + 2) % 3] - y[(k + 1) % 3]) * (px - x[(k + 1) % 3]) for k in range(3)]
            v = abs(sum(edges[k] * z[k] for k in range(3)) - d * int(h[py, px]))
            ev = min(-(-(v << 16) // d), 0xFFFFFFFF)
            r = slope_factor(x, y, z, sx, sy)
            want = 0 if ev == 0 else -(-(ev << 16) // r)
            assert e_c == want, f"{tri} at ({px}, {py}) scales {sx} {sy}: C {e_c}, model r {r} gives {want}"
            checked += 1
    assert checked >= 400
