"""rtl/tri_point.v, the point-error unit, against wavemesh.model.tri_point (bench: tri_point_tb.py), and
wavemesh.model.tri_point against the C (firmware/src/tri_error.c's wm_point_error through the native
library, in both metrics).

The bench runs random triangles of every kind (thin, border, big, one sample wide, clockwise ones), samples
at their corners, inside them and anywhere on the grid, heights on, near and far from the plane, slope
factors of random scales and of every size, in the three modes, under random back-pressure and delays of
the slope unit's r; on the SoC's coordinates (11 bits) and on the widest (14 bits) with one quotient bit a
clock.
"""

import ctypes
import random

import numpy as np
import pytest
from test_tri_slope import _point_error
from tri_engine_tb import random_triangles
from wavemesh.harness.rtl_runner import RTL, run
from wavemesh.model.tri_point import point_error
from wavemesh.refine import native

SETS = [{"COORD_BITS": 11}, {"COORD_BITS": 14, "DIV_STEPS": 1}]


@pytest.mark.parametrize("params", SETS, ids=["soc", "wide"])
def test_tri_point(params):
    env = {"TRI_POINT_SEED": str(params["COORD_BITS"]), "TRI_POINT_COORD_BITS": str(params["COORD_BITS"]),
           "TRI_POINT_DIV_STEPS": str(params.get("DIV_STEPS", 2))}
    run("tri_point", [RTL / "tri_point.v", RTL / "udiv_step.v"], "tri_point_tb", parameters=params,
        extra_env=env)


@pytest.mark.parametrize("shape", [(37, 23), (2048, 5), (5, 16384)])
def test_model_matches_c(shape):
    """The model's e against the C's wm_point_error: the vertical metric, and the normal one with a kept
    slope factor r (the C then divides by it, as the unit's modes 1 and 2), at samples inside each
    triangle and anywhere on the grid (saturated ev among them), heights at random."""
    rng = random.Random(shape[0] + 3 * shape[1])
    w, hh = shape
    lib = native.load()
    point_error_c = _point_error(lib)
    h = np.array(rng.choices(range(65536), k=w * hh), dtype=np.uint16).reshape(hh, w)
    fld = native.Field(w, hh, 1, h.ctypes.data_as(ctypes.POINTER(ctypes.c_uint16)), None, None)
    vertical = native.fixed_params(native.RefineParams(metric="vertical"), 1.0)
    normal = native.fixed_params(native.RefineParams(metric="normal"), 1.0)
    saturated = 0
    for tri in random_triangles(rng, w, hh, 300):
        x, y = [p[0] for p in tri], [p[1] for p in tri]
        if rng.random() < 0.05:
            x, y = [x[0], x[2], x[1]], [y[0], y[2], y[1]]
        z = [int(h[y[k], x[k]]) for k in range(3)]
        k = rng.randrange(3)
        for px, py in [(x[k], y[k]), (rng.randrange(min(x), max(x) + 1), rng.randrange(min(y), max(y) + 1)),
                       (rng.randrange(w), rng.randrange(hh))]:
            xs, ys = (ctypes.c_int32 * 3)(*x), (ctypes.c_int32 * 3)(*y)
            e_c = point_error_c(ctypes.byref(fld), ctypes.byref(vertical), xs, ys, px, py, None)
            assert e_c == point_error(x, y, z, px, py, int(h[py, px])), (tri, px, py)
            saturated += e_c == 0xFFFFFFFF
            r = rng.randrange(1 << 16, 1 << rng.randrange(17, 65))
            kept = ctypes.c_uint64(r)
            e_c = point_error_c(ctypes.byref(fld), ctypes.byref(normal), xs, ys, px, py, ctypes.byref(kept))
            assert e_c == point_error(x, y, z, px, py, int(h[py, px]), r), (tri, px, py, r)
    assert saturated > 0
