"""rtl/tlut_holes.v, the template stage's per-block validity flag (issue 20), against
wavemesh.model.holemask.block_flags (bench: tlut_holes_tb.py): random frames, sizes, levels and mask
densities,
random stalls on both streams, frames back to back."""

import pytest
from wavemesh.harness.rtl_runner import RTL, run


# MAX_COLS 19 (not a power of two) runs inside the stage too (test_tlut_stage_holes.py): one build here
@pytest.mark.parametrize("max_cols", [16])
def test_tlut_holes(max_cols):
    run("tlut_holes", [RTL / "tlut_holes.v"], "tlut_holes_tb", parameters={"MAX_COLS": max_cols},
        extra_env={"WM_HOLES_SEED": str(max_cols), "WM_HOLES_MAX_COLS": str(max_cols)})
