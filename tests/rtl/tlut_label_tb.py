"""cocotb bench of rtl/tlut_label.v: one record per cycle, labels against wavemesh.model.label.

Expected labels come from wavemesh.model.label.label_blocks on 2 x 2-block levels of a 4 x 4 grid at
M = 1, whose second block column is 1 grid step wide and second block row 1 step high: the four
blocks cover no demotion, narrow, low and both (docs/model.md "Labeller", step 4).  Without
demotion, label_blocks' label is wavemesh.model.label.dominant_labels'.
"""

from __future__ import annotations

import os

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, RisingEdge
from wavemesh.model.haar import HaarLevel
from wavemesh.model.label import TAU_MAX, dominant_labels, label_blocks

M18 = (1 << 18) - 1
D_MAX = (1 << 17) - 1


def random_details(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) details with many ties (equal magnitudes, opposite signs), zeros and range ends."""
    scale = rng.choice([2, 40, 2000, D_MAX], size=(n, 1))
    d = rng.integers(-scale, scale + 1, size=(n, 3))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        tie = rng.random(n) < 0.25
        d[tie, b] = d[tie, a] * rng.choice([-1, 1], size=tie.sum())
    d[rng.random((n, 3)) < 0.1] = 0
    ends = rng.random((n, 3)) < 0.03
    d[ends] = rng.choice([-(1 << 17), D_MAX], size=ends.sum())
    return d


def expected_labels(d: np.ndarray, tau_q: int) -> np.ndarray:
    """Labels of the records d (n a multiple of 4), record 4k + 2j + i being block (j, i) of level k:
    block column 1 is narrow, block row 1 is low."""
    out = []
    for k in range(0, len(d), 4):
        q = d[k:k + 4].reshape(2, 2, 3)
        lv = HaarLevel(1, np.zeros((2, 2), dtype=np.int64), q[..., 0], q[..., 1], q[..., 2])
        lab = label_blocks(lv, tau_q, 4, 4).label
        assert lab[0, 0] == dominant_labels(lv, tau_q, (1, 1))[0, 0]
        out.extend(lab.ravel().tolist())
    return np.asarray(out)


@cocotb.test()
async def test_labels(dut):
    """Random records at full rate (and with gaps) for several thresholds."""
    cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
    dut.rst.value = 1
    dut.s_valid.value = 0
    await ClockCycles(dut.clk, 2)
    dut.rst.value = 0
    rng = np.random.default_rng(int(os.environ.get("TLUT_SEED", "3")))
    n = 4 * int(os.environ.get("TLUT_LEVELS", "600"))
    for tau_q in (0, 1, 2, 39, 1000, D_MAX - 1, D_MAX, 1 << 17, TAU_MAX, int(rng.integers(0, 1 << 18))):
        d = random_details(rng, n)
        # records whose largest magnitude is tau or tau + 1: the strict comparison
        edge = rng.random(n) < 0.2
        d[edge, int(rng.integers(0, 3))] = np.clip(tau_q + rng.integers(0, 2, size=edge.sum()), 0, D_MAX)
        want = expected_labels(d, tau_q)
        dut.cfg_tau.value = tau_q
        got: dict[int, int] = {}

        async def collect(count, got=got):
            while len(got) < count:
                await RisingEdge(dut.clk)
                if dut.m_valid.value:
                    got[int(dut.m_user.value)] = int(dut.m_label.value)

        task = cocotb.start_soon(collect(n))
        gaps = rng.random(n) < 0.2
        for k in range(n):
            await FallingEdge(dut.clk)
            if gaps[k]:
                dut.s_valid.value = 0
                await FallingEdge(dut.clk)
            dut.s_valid.value = 1
            dut.s_d1.value, dut.s_d2.value, dut.s_d3.value = (int(x) & M18 for x in d[k])
            dut.s_narrow.value = k % 2
            dut.s_low.value = (k >> 1) % 2
            dut.s_user.value = k
        await FallingEdge(dut.clk)
        dut.s_valid.value = 0
        await task
        bad = [k for k in range(n) if got.get(k) != want[k]]
        if bad:
            k = bad[0]
            raise AssertionError(f"tau {tau_q}: {len(bad)} wrong labels, first record {k}: "
                                 f"d = {d[k].tolist()}, narrow {k % 2}, low {(k >> 1) % 2}: "
                                 f"got {got.get(k)}, want {want[k]}")
