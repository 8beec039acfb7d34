"""rtl/tri_engine.v, the triangle error engine, against wavemesh.model.tri_scan (bench: tri_engine_tb.py), and
wavemesh.model.tri_scan against the C (firmware/src/tri_error.c through the native library).

The bench runs random triangles of every kind (thin, border, big, one sample wide, flat edges, every
triangle of a 4 x 3 grid) with random heights and limits under random back-pressure on every port, and
the full-rate case; on the SoC's coordinates (11 bits) and on small ones with one-entry FIFOs.
"""

import ctypes
import random

import numpy as np
import pytest
from tri_engine_tb import heights, random_triangles
from wavemesh.harness.rtl_runner import RTL, run
from wavemesh.model.tri_scan import scan
from wavemesh.refine import native

SETS = [
    {"COORD_BITS": 11, "ADDR_BITS": 24},
    {"COORD_BITS": 8, "ADDR_BITS": 18, "CMD_DEPTH": 1, "RES_DEPTH": 1, "SPAN_DEPTH": 1},
]


@pytest.mark.parametrize("params", SETS, ids=["soc", "small"])
def test_tri_engine(params):
    env = {"TRI_ENGINE_SEED": str(params["COORD_BITS"]), "TRI_ENGINE_COORD_BITS": str(params["COORD_BITS"])}
    run("tri_engine", [RTL / "tri_engine.v", RTL / "wm_fifo.v"], "tri_engine_tb", parameters=params,
        extra_env=env)


def _within(lib):
    fn = lib.wm_tri_error_within  # internal (wm_internal.h), exported by the shared library
    pi32 = ctypes.POINTER(ctypes.c_int32)
    fn.restype = ctypes.c_uint32
    fn.argtypes = [ctypes.POINTER(native.Field), ctypes.POINTER(native.Params), pi32, pi32, ctypes.c_uint32,
                   pi32, pi32]
    return fn


@pytest.mark.parametrize("shape", [(37, 23), (300, 7), (3, 200)])
def test_model_matches_c(shape):
    """scan's Vmax and sample against wm_tri_error (vertical metric: E = ceil(2^16 Vmax / D)) and,
    with bounds, wm_tri_error_within's early exit."""
    rng = random.Random(shape[0] * shape[1])
    w, hh = shape
    lib = native.load()
    within = _within(lib)
    fp = native.fixed_params(native.RefineParams(metric="vertical"), 1.0)
    for _ in range(4):
        h = np.ascontiguousarray(heights(rng, w, hh))
        fld = native.Field(w, hh, 1, h.ctypes.data_as(ctypes.POINTER(ctypes.c_uint16)), None, None)
        for tri in random_triangles(rng, w, hh, 120):
            x, y = [p[0] for p in tri], [p[1] for p in tri]
            xs, ys = (ctypes.c_int32 * 3)(*x), (ctypes.c_int32 * 3)(*y)
            wx, wy = ctypes.c_int32(-1), ctypes.c_int32(-1)
            e = lib.wm_tri_error(ctypes.byref(fld), ctypes.byref(fp), xs, ys, ctypes.byref(wx),
                                 ctypes.byref(wy))
            vmax, mx, my = scan(h, x, y)
            d = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0])
            assert (mx, my) == (wx.value, wy.value), f"{tri}: model ({mx}, {my}), C ({wx.value}, {wy.value})"
            assert e == min(-(-(vmax << 16) // d), 0xFFFFFFFF), f"{tri}: model Vmax {vmax}, C E(T) {e}"
            # a bound below E(T): the C stops at the first V above limit = floor(bound D / 2^16)
            bound = rng.randrange(e + 1) if e else 0
            limit = (bound * d) >> 16
            e2 = within(ctypes.byref(fld), ctypes.byref(fp), xs, ys, bound, ctypes.byref(wx),
                        ctypes.byref(wy))
            v2, mx2, my2 = scan(h, x, y, limit)
            assert (mx2, my2) == (wx.value, wy.value), f"{tri} bound {bound}: model ({mx2}, {my2})"
            assert e2 == min(-(-(v2 << 16) // d), 0xFFFFFFFF), f"{tri} bound {bound}: model V {v2}, C {e2}"
