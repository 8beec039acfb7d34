"""The template stage (rtl/tlut_stage.v and its tlut_* parts) against the reference model.

The cocotb bench is tlut_stage_tb.py; its golden-model helpers are checked here first without a
simulator, so a failure in the simulation is the RTL's, not the bench's.
"""

import numpy as np
import pytest
from tlut_stage_tb import (
    TS,
    assemble_beats,
    bank_records,
    coefficient_frame,
    decode_beat,
    lut_coverage_level,
    random_level,
    samples_frame,
)
from wavemesh.check import check_mesh
from wavemesh.harness.rtl_runner import RTL, run
from wavemesh.io import synth
from wavemesh.model.haar import decompose

SOURCES = [*sorted(RTL.glob("tlut_*.v")), RTL / "wm_fifo.v"]
# cocotb test names; test_sizes is crossed with idle input cycles and output back-pressure
TESTS = ["test_synthetic_sets", "test_random_stress", "test_lut_coverage", "test_throughput",
         "test_dropped_records_never_stall", "test_bad_configuration"] + [
    f"test_sizes/idle={idle}/backpressure={bp}" for idle in (False, True) for bp in (False, True)]


@pytest.mark.parametrize("name,size,levels", [("f1", 128, 4), ("ball", 64, 3), ("rand", 37, 2)])
def test_bench_model_reproduces_the_reference(name, size, levels):
    """The beats the bench expects assemble into the reference initial triangulation."""
    values = (np.random.default_rng(0).integers(0, 999, size=(size, size + 5)) if name == "rand"
              else synth.make(name, size))
    frame = samples_frame(name, values, levels)
    mesh = assemble_beats([d for d, _, _ in frame.beats], frame.width, frame.height)
    assert mesh.same_as(frame.reference)
    assert check_mesh(mesh).valid
    assert sum(t for _, _, t in frame.beats) == 1 and frame.beats[-1][2] == 1
    ends = [decode_beat(d, u)["end"] for d, u, _ in frame.beats]
    assert sum(ends) == frame.blocks


def test_bank_order_keeps_each_level_in_raster_order():
    values = np.arange(35 * 22).reshape(22, 35) % 65536
    recs = bank_records(decompose(values, 3), 35, 22)
    for m in (1, 2, 3):
        pos = [(u >> 16 & 0xFFFF, u & 0xFFFF) for _, u in recs if u >> 32 == m]
        assert pos == sorted(pos) and len(pos) == len(set(pos))


def test_lut_coverage_frame_covers_the_table():
    lv, width, height, tau_q = lut_coverage_level()
    frame = coefficient_frame("lut", lv, width, height, tau_q)
    assert set(frame.lab.template.ravel().tolist()) == set(range(len(TS.templates)))


def test_random_level_has_ties():
    lv = random_level(np.random.default_rng(1), 2, 40, 40, 5)
    assert np.any(np.abs(lv.d1) == np.abs(lv.d2)) and np.any(np.abs(lv.d2) == np.abs(lv.d3))


@pytest.mark.parametrize("testcase", TESTS, ids=[t.replace("/", "-") for t in TESTS])
def test_tlut_stage(testcase):
    run("tlut_stage", SOURCES, "tlut_stage_tb", parameters={"MAX_COLS": 64, "FIFO_DEPTH": 4},
        testcase=testcase)


@pytest.mark.parametrize("fifo_depth", [2, 3])
def test_tlut_stage_small_buffers(fifo_depth):
    """The smallest block FIFO and one whose depth is not a power of two, with a row buffer whose
    depth is not one either, on random frames."""
    run("tlut_stage", SOURCES, "tlut_stage_tb", parameters={"MAX_COLS": 59, "FIFO_DEPTH": fifo_depth},
        testcase="test_random_stress", extra_env={"TLUT_SEED": "9", "TLUT_STRESS": "12"})
