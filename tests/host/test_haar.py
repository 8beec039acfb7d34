"""The integer Haar filter bank against a slow element-by-element model of the same spec."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wavemesh.model.haar import decompose, haar_step, level_shape


def slow_step(a):
    """docs/model.md, "Filter bank", written out one block at a time with explicit padding."""
    h, w = len(a), len(a[0])

    def at(r, c):  # the last row/column repeats when the size is odd
        return int(a[min(r, h - 1)][min(c, w - 1)])

    rows, cols = (h + 1) // 2, (w + 1) // 2
    out = [[[0] * cols for _ in range(rows)] for _ in range(4)]
    for i in range(rows):
        for j in range(cols):
            p00, p01 = at(2 * i, 2 * j), at(2 * i, 2 * j + 1)
            p10, p11 = at(2 * i + 1, 2 * j), at(2 * i + 1, 2 * j + 1)
            out[0][i][j] = (p00 + p01 + p10 + p11 + 2) // 4
            out[1][i][j] = p01 + p11 - p00 - p10
            out[2][i][j] = p10 + p11 - p00 - p01
            out[3][i][j] = p00 + p11 - p01 - p10
    return [np.array(x, dtype=np.int64) for x in out]


@settings(max_examples=60, deadline=None)
@given(h=st.integers(1, 40), w=st.integers(1, 40), seed=st.integers(0, 2**32 - 1))
def test_step_matches_slow_model(h, w, seed):
    a = np.random.default_rng(seed).integers(0, 65536, size=(h, w))
    for got, want in zip(haar_step(a), slow_step(a.tolist()), strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("shape", [(2, 2), (3, 1000), (1000, 3), (37, 53), (128, 128), (129, 255)])
def test_levels_chain_and_shapes(shape):
    rng = np.random.default_rng(1)
    s = rng.integers(0, 65536, size=shape)
    levels = decompose(s, 5)
    a = s
    for lv in levels:
        assert lv.a.shape == level_shape(*shape, lv.m)
        for got, want in zip((lv.a, lv.d1, lv.d2, lv.d3), slow_step(a.tolist()), strict=True):
            np.testing.assert_array_equal(got, want)
        a = lv.a


def test_extremes_fit_the_stated_widths():
    # Alternating 0 / 65535 patterns reach the largest details: |d| <= 2 * 65535 (18 bits signed).
    s = np.zeros((64, 64), dtype=np.int64)
    s[:, 1::2] = 65535
    lv = decompose(s, 6)
    assert lv[0].d1.max() == 2 * 65535 and lv[0].d1.min() == 2 * 65535
    full = np.full((33, 17), 65535)
    for level in decompose(full, 6):
        assert level.a.max() == 65535 and level.a.min() == 65535
        assert not level.d1.any() and not level.d2.any() and not level.d3.any()


def test_scaling_is_the_same_at_every_level():
    # A step of 10 counts between the left and right half of every block gives d1 = 2 * 10 at each level.
    for m in range(1, 7):
        size = 1 << m
        s = np.zeros((size, size * 3), dtype=np.int64)
        for b in range(3):
            s[:, b * size + size // 2:(b + 1) * size] = 10
        d1 = decompose(s, m)[-1].d1
        assert np.all(d1 == 20), (m, d1)


def test_signs_follow_the_gradient():
    j, i = np.meshgrid(np.arange(16), np.arange(16))
    lv = decompose(100 + 3 * j, 2)[-1]  # rises to the right
    assert np.all(lv.d1 > 0) and not lv.d2.any()
    lv = decompose(100 + 3 * i, 2)[-1]  # rises downwards (row index)
    assert np.all(lv.d2 > 0) and not lv.d1.any()
    lv = decompose(100 * ((i % 4 < 2) == (j % 4 < 2)), 2)[-1]  # checkerboard of 2 x 2 cells
    assert np.all(lv.d3 > 0) and not lv.d1.any() and not lv.d2.any()


def test_padding_repeats_the_last_sample():
    s = np.array([[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    a, d1, d2, d3 = haar_step(s)
    # bottom-right block is the single sample 9 repeated four times
    assert a[1, 1] == 9 and d1[1, 1] == 0 and d2[1, 1] == 0 and d3[1, 1] == 0
    # right column block [3, 6] repeated: no x variation, y variation 2 * (6 - 3)
    assert d1[0, 1] == 0 and d2[0, 1] == 6


@pytest.mark.parametrize("bad", [np.zeros((0, 4)), np.zeros(5), np.full((2, 2), 70000)])
def test_rejects_bad_arrays(bad):
    with pytest.raises(ValueError):
        decompose(bad, 1)
