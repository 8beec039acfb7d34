"""rtl/udiv64.v, the 64-bit divider behind the board's __udivdi3 (ENGINE.DIV_*), against Python's integers
(bench: udiv64_tb.py): random divisions of every size (64 / 64, 64 / 32, 32 / 32, quotients of 0, 1 and
64 bits, exact multiples and one off, the extremes) under random back-pressure, at two quotient bits a
clock (the SoC's) and one.  The board firmware's division against the same integers: tests/firmware/
test_div64.py; the board's meshes against the native build's: tests/sim/test_stream_board.py.
"""

import pytest
from wavemesh.harness.rtl_runner import RTL, run


@pytest.mark.parametrize("steps", [2, 1])
def test_udiv64(steps):
    env = {"UDIV64_SEED": str(steps), "UDIV64_STEPS": str(steps)}
    run("udiv64", [RTL / "udiv64.v", RTL / "udiv_step.v"], "udiv64_tb", parameters={"STEPS": steps},
        extra_env=env)
