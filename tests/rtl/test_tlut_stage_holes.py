"""The template stage with holes (rtl/tlut_stage.v, HOLES = 1; issue 20): every output beat's hole flag
(tuser[45]) against wavemesh.holes.block_flags and its template against the reference model, under
random masks, mask gaps, idle records and output back-pressure (bench: tlut_stage_holes_tb.py)."""

import pytest
from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [*sorted(RTL.glob("tlut_*.v")), RTL / "wm_fifo.v"]


@pytest.mark.parametrize("expand,max_cols,flag_depth", [(1, 19, 2), (0, 16, 5)])
def test_tlut_stage_holes(expand, max_cols, flag_depth):
    """With the expander and the smallest flag FIFO (the mask waits for the blocks); without the
    expander (one beat per block, as the SoC's TOUT writer takes it) and a FIFO of 5."""
    run("tlut_stage", SOURCES, "tlut_stage_holes_tb",
        parameters={"MAX_COLS": max_cols, "FIFO_DEPTH": 3, "EXPAND": expand, "HOLES": 1,
                    "HOLES_FIFO_DEPTH": flag_depth},
        extra_env={"TLUT_HOLES_SEED": str(max_cols), "TLUT_HOLES_EXPAND": str(expand)})
