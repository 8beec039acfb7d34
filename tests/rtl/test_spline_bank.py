"""rtl/haar_bank.v built with WAVELET = 1 (rtl/spline_level.v) against the reference model
(wavemesh.model.spline), under Verilator through cocotb.

The bench is haar_bank_tb.py with HAAR_WAVELET=spline: every record against
wavemesh.model.haar.decompose(..., "spline") (value, level, block position, per-level raster order, nothing
missing or extra, tlast on the last one only), on edge sizes (one and two columns or rows at the deep
levels, odd sizes, whose last record row and column the spline level completes after its input) and
random ones, under input idles and output back-pressure; with neither, the input must never wait
inside a frame (one sample per clock).  One small build keeps it about a minute; bench/bench_rtl.py
runs the default 512 x 512 bank.
"""

import json

import pytest
from test_haar_bank import TWO_PATTERNS, frames_for
from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [RTL / f"{m}.v" for m in ("haar_raster", "wm_linebuf", "haar_level", "spline_level", "wm_fifo",
                                     "haar_bank")]


def bank(frames, max_width, max_height, max_levels, idle="none", bp="none", testcase="run_frames",
         wavelet="spline", **extra):
    """Build haar_bank with WAVELET = 1 and these parameters; run `testcase` of haar_bank_tb on `frames`
    against the model's `wavelet`."""
    params = {"MAX_WIDTH": max_width, "MAX_HEIGHT": max_height, "MAX_LEVELS": max_levels, "WAVELET": 1,
              **extra}
    env = {"HAAR_FRAMES": json.dumps(frames), "HAAR_IDLE": idle, "HAAR_BP": bp, "HAAR_WAVELET": wavelet,
           "HAAR_MAX_LEVELS": str(max_levels),
           "HAAR_NO_STALL": "1" if (idle, bp) == ("none", "none") else "0"}
    run("haar_bank", SOURCES, "haar_bank_tb", parameters=params, extra_env=env, testcase=testcase)


# One build (rtl_runner keeps it): maxima that are not powers of two, deep levels one column or row
# wide, FIFO depths that are not powers of two either; the haar_bank tests cover the rest of the bank.
MAX = dict(max_width=45, max_height=19, max_levels=6, FIFO_DEPTH=3, APPROX_FIFO_DEPTH=5)


@pytest.mark.parametrize("idle,bp", TWO_PATTERNS, ids=["none-none", "random-random"])
def test_frames(idle, bp):
    """Edge sizes (2 x 2, odd, one block wide or high, the maxima) and random ones, bit for bit."""
    frames = frames_for(45, 19, 6, 10, seed=3) + [[1 + 2 ** 4, 19, 6, 41], [44, 18, 6, 42]]
    bank(frames, idle=idle, bp=bp, **MAX)


def test_reset_mid_frame():
    bank([[9, 7, 3, 1], [16, 16, 4, 2]], testcase="reset_mid_frame", **MAX)


def test_is_not_haar():
    """The same bench against Haar's model fails: the records compared are the spline's."""
    with pytest.raises((AssertionError, SystemExit)):  # cocotb's runner exits, or rtl_runner asserts
        bank([[16, 16, 3, 2]], wavelet="haar", **MAX)
