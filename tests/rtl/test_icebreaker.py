"""The iCEBreaker's board top (rtl/boards/icebreaker_top.v: the FPGA stage behind the UART) through its
pins, against the reference model; the bench is icebreaker_tb.py.

Built as the bitstream is (the same top and stage parameters) but with a UART of 8 clocks per bit (BAUD
1.5 M at the 12 MHz clock) and a short power-on reset, so whole jobs take seconds in simulation."""

from wavemesh.harness.rtl_runner import ICEBREAKER_BENCH_PARAMETERS as BENCH_PARAMETERS
from wavemesh.harness.rtl_runner import RTL, run


def test_icebreaker_top():
    boards = RTL / "boards"
    sources = [boards / "icebreaker_top.v", boards / "stage_uart.v", boards / "wm_por.v",
               *sorted(RTL.glob("haar_*.v")), *sorted(RTL.glob("tlut_*.v")), RTL / "wm_fifo.v",
               RTL / "uart_rx.v", RTL / "uart_tx.v"]
    run("icebreaker_top", sources, "icebreaker_tb", parameters=BENCH_PARAMETERS)
