"""rtl/haar_bank.v against the reference model (wavemesh.model.haar), under Verilator through cocotb.

The cocotb side is haar_bank_tb.py: it sends frames of random samples (uniform, extremes 0/65535,
noisy ramps), compares every record with wavemesh.model.haar.decompose (value, level, block position,
per-level raster order, nothing missing or extra, tlast on the last one only) and scrambles the
configuration inputs while a frame runs (they are sampled at its start).  Here each test builds one
parameter set (once: rtl_runner keeps a build directory per set) and runs a list of frames under one
input-idle and one output back-pressure pattern; with neither, the bank must also take one sample per
clock throughout every frame.
"""

import json
import random

import pytest
from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [RTL / f"{m}.v" for m in ("haar_raster", "wm_linebuf", "haar_level", "wm_fifo", "haar_bank")]

# (idle, back-pressure) patterns of haar_bank_tb.pattern
PATTERNS = [("none", "none"), ("none", "random"), ("random", "none"), ("random", "random"),
            ("bursty", "bursty")]
TWO_PATTERNS = [("none", "none"), ("random", "random")]


def bank(frames, max_width, max_height, max_levels, idle="none", bp="none", testcase="run_frames", **extra):
    """Build haar_bank with these parameters and run `testcase` of haar_bank_tb on `frames`."""
    params = {"MAX_WIDTH": max_width, "MAX_HEIGHT": max_height, "MAX_LEVELS": max_levels, **extra}
    env = {"HAAR_FRAMES": json.dumps(frames), "HAAR_IDLE": idle, "HAAR_BP": bp,
           "HAAR_MAX_LEVELS": str(max_levels),
           "HAAR_NO_STALL": "1" if (idle, bp) == ("none", "none") else "0"}
    run("haar_bank", SOURCES, "haar_bank_tb", parameters=params, extra_env=env, testcase=testcase)


def frames_for(max_width, max_height, max_levels, count, seed):
    """Edge sizes (2 x 2, odd, one block wide or high, the maximum) and `count` random frames.

    A frame is [width, height, cfg_levels, seed]; cfg_levels 0 and 15 are out of range on purpose
    (the bank saturates them to 1 and MAX_LEVELS).
    """
    w, h, m = max_width, max_height, max_levels
    edges = [[2, 2, m, 1], [3, 2, 1, 2], [2, 3, m, 3], [3, 3, m, 4], [w, h, m, 5], [w - 1, h - 1, m, 6],
             [3, h, m, 7], [w, 3, m, 8], [2, h, m, 9], [w, 2, 1, 10], [5, 7, 0, 11], [7, 5, 15, 12]]
    rng = random.Random(seed)
    rand = [[rng.randint(2, w), rng.randint(2, h), rng.randint(1, m), 100 + k] for k in range(count)]
    return edges + rand


@pytest.mark.parametrize("idle,bp", PATTERNS, ids=[f"{i}-{b}" for i, b in PATTERNS])
def test_small(idle, bp):
    """A 32 x 32, 4-level bank: edge and random sizes under every idle/back-pressure pattern."""
    bank(frames_for(32, 32, 4, 14, seed=len(idle) * 7 + len(bp)), 32, 32, 4, idle, bp)


@pytest.mark.parametrize("idle,bp", TWO_PATTERNS, ids=["none-none", "random-random"])
def test_odd_maximum(idle, bp):
    """Maxima that are not powers of two, deep levels one block wide, deeper FIFOs than the default
    whose depths are not powers of two either."""
    frames = frames_for(45, 19, 6, 12, seed=3) + [[45, 19, 6, 40], [1 + 2 ** 4, 19, 6, 41]]
    bank(frames, 45, 19, 6, idle, bp, FIFO_DEPTH=3, APPROX_FIFO_DEPTH=5)


def test_one_level():
    """MAX_LEVELS = 1: the bank is a single level."""
    bank(frames_for(24, 24, 1, 6, seed=5), 24, 24, 1, "random", "random")


@pytest.mark.parametrize("idle,bp", TWO_PATTERNS, ids=["none-none", "random-random"])
def test_512(idle, bp):
    """The default 512 x 512, 7-level bank: long thin frames, odd sizes, and the full width at full speed
    over two level-7 block rows and an odd last row (512 x 257: every line buffer full; a 512 x 512 frame
    only repeats those rows, at 20 s of make test)."""
    frames = [[3, 512, 7, 1], [512, 3, 7, 2], [511, 37, 7, 3], [2, 2, 7, 4], [321, 65, 7, 5]]
    if (idle, bp) == ("none", "none"):
        frames += [[512, 257, 7, 6]]
    bank(frames, 512, 512, 7, idle, bp)


def test_reset_mid_frame():
    """A reset in the middle of a frame leaves the bank idle; the next frame is exact."""
    bank([[9, 7, 3, 1], [16, 16, 4, 2]], 32, 32, 4, testcase="reset_mid_frame")
