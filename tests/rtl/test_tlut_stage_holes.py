"""The template stage with holes (rtl/tlut_stage.v, HOLES = 1; issue 20): every output beat's hole flag
(tuser[45]) against wavemesh.model.holemask.block_flags and its template against the reference model, under
random masks, mask gaps, idle records and output back-pressure (bench: tlut_stage_holes_tb.py)."""

from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [*sorted(RTL.glob("tlut_*.v")), RTL / "wm_fifo.v"]


def test_tlut_stage_holes():
    """With the expander (several beats per block, the flag taken with the block_end beat) and the
    smallest flag FIFO (2: the mask waits for the blocks).  The bench also runs EXPAND = 0
    (TLUT_HOLES_EXPAND=0, one beat per block); it passed with MAX_COLS 16 and a FIFO of 5, and is
    left out of make test for its build's time."""
    run("tlut_stage", SOURCES, "tlut_stage_holes_tb",
        parameters={"MAX_COLS": 19, "FIFO_DEPTH": 3, "EXPAND": 1, "HOLES": 1, "HOLES_FIFO_DEPTH": 2},
        extra_env={"TLUT_HOLES_SEED": "19", "TLUT_HOLES_EXPAND": "1"})
