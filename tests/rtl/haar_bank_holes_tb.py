"""cocotb bench of rtl/haar_bank.v with HOLES = 1: a validity mask beside the samples (s_axis_tuser,
1 = invalid) and every record's flag on m_axis_tuser[36].

Every record (value, level, position, per-level raster order, nothing missing or extra) is compared
with wavemesh.model.haar.decompose as in haar_bank_tb, and its flag with wavemesh.model.roi.cell_mask:
1 when any of the 2^m x 2^m samples its coefficient is computed from (the slice clipped at the frame's edge,
which is what the padding repeats) is invalid.  Random sizes, levels and masks (densities 0..1,
blobs), random input idle and output back-pressure, frames back to back.

Parameters come from the environment: HAAR_HOLES_SEED, HAAR_HOLES_FRAMES, HAAR_MAX_LEVELS.
Run through tests/rtl/test_haar_bank_holes.py.
"""

from __future__ import annotations

import os

import cocotb
import numpy as np
from cocotbext.axi import AxiStreamFrame
from haar_bank_tb import TB, expected_records, frame_samples, signed18
from wavemesh.model.roi import cell_mask

SEED = int(os.environ.get("HAAR_HOLES_SEED", "1"))
FRAMES = int(os.environ.get("HAAR_HOLES_FRAMES", "8"))
MAX_LEVELS = int(os.environ.get("HAAR_MAX_LEVELS", "4"))


def random_mask(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    if rng.integers(0, 2):
        return rng.random((height, width)) < rng.choice([0.0, 0.005, 0.05, 0.5, 1.0])
    m = np.zeros((height, width), dtype=bool)
    for _ in range(int(rng.integers(1, 4))):
        y, x = int(rng.integers(0, height)), int(rng.integers(0, width))
        m[y:y + int(rng.integers(1, 4)), x:x + int(rng.integers(1, 4))] = True
    return m


@cocotb.test()
async def random_holes(dut):
    tb = TB(dut)
    tb.set_patterns("random", "random", SEED)
    await tb.reset()
    rng = np.random.default_rng(SEED)
    max_w, max_h = int(dut.MAX_WIDTH.value), int(dut.MAX_HEIGHT.value)
    flagged = unflagged = 0
    for n in range(FRAMES):
        width, height = int(rng.integers(2, max_w + 1)), int(rng.integers(2, max_h + 1))
        levels = int(rng.integers(1, MAX_LEVELS + 1))
        samples = frame_samples(width, height, SEED * 100 + n)
        mask = random_mask(rng, width, height)
        want = expected_records(samples, levels)
        dut.cfg_width.value, dut.cfg_height.value, dut.cfg_levels.value = width, height, levels
        await tb.source.send(AxiStreamFrame(tdata=samples.ravel().tolist(),
                                            tuser=[int(b) for b in mask.ravel()]))
        rx = await tb.sink.recv()
        what = f"{width}x{height}, {levels} levels, frame {n}"
        got: dict[int, list[tuple]] = {}
        flags: dict[int, list[int]] = {}
        for d, u in zip(rx.tdata, rx.tuser, strict=True):
            m = (u >> 32) & 15
            got.setdefault(m, []).append(((u >> 16) & 0xFFFF, u & 0xFFFF, d & 0xFFFF,
                                          signed18((d >> 16) & 0x3FFFF), signed18((d >> 34) & 0x3FFFF),
                                          signed18((d >> 52) & 0x3FFFF)))
            flags.setdefault(m, []).append(u >> 36 & 1)
        assert sorted(got) == sorted(want), f"{what}: levels {sorted(got)}"
        for m in want:
            assert got[m] == want[m], f"{what}: level {m}: records differ from the reference"
            ref = [int(f) for f in cell_mask(mask, m).ravel()]
            bad = [k for k, (a, b) in enumerate(zip(flags[m], ref, strict=True)) if a != b]
            assert not bad, f"{what}: level {m}: flag of record {bad[0]} differs ({len(bad)} flags)"
            flagged += sum(ref)
            unflagged += len(ref) - sum(ref)
        assert tb.sink.empty(), f"{what}: records after the one with tlast"
    assert flagged and unflagged
