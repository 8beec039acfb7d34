"""rtl/wm_fifo.v, the FIFO of every stream in rtl/, against a cycle-exact model (bench: wm_fifo_tb.py).

Random valid/ready on both sides (AXI-style writers that hold their beat and writers that withdraw
it), full and empty corners, one beat per cycle, the count every cycle, a reset at any fill level;
on depths of 1, a power of two (2, 64) and not (3, 5), and widths from 1 to the filter bank's 70 bits.
"""

import pytest
from wavemesh.harness.rtl_runner import RTL, run

# (DEPTH, DATA_WIDTH): the filter bank's default record FIFO (2 x 70), the UART's (64 x 8), the
# smallest, and depths that are not powers of two
SETS = [(1, 1), (2, 70), (3, 17), (5, 8), (64, 8)]


@pytest.mark.parametrize("depth,width", SETS, ids=[f"{d}x{w}" for d, w in SETS])
def test_wm_fifo(depth, width):
    env = {"WM_FIFO_DEPTH": str(depth), "WM_FIFO_WIDTH": str(width), "WM_FIFO_SEED": str(7 * depth + width)}
    run("wm_fifo", [RTL / "wm_fifo.v"], "wm_fifo_tb", parameters={"DEPTH": depth, "DATA_WIDTH": width},
        extra_env=env)
