"""The filter bank with holes (rtl/haar_bank.v, HOLES = 1; issue 20): every record against
wavemesh.model.haar.decompose and its flag (m_axis_tuser[36]) against the OR of the mask over the
coefficient's samples, under random masks, idle input and output back-pressure (bench:
haar_bank_holes_tb.py)."""

from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [RTL / f"{m}.v" for m in ("haar_raster", "wm_linebuf", "haar_level", "wm_fifo", "haar_bank")]


def test_haar_bank_holes():
    """45 x 19 x 4 (maxima that are not powers of two; odd widths and heights self-pair)."""
    run("haar_bank", SOURCES, "haar_bank_holes_tb",
        parameters={"MAX_WIDTH": 45, "MAX_HEIGHT": 19, "MAX_LEVELS": 4, "HOLES": 1},
        extra_env={"HAAR_HOLES_SEED": "3", "HAAR_MAX_LEVELS": "4"})
