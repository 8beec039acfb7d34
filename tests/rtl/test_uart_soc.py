"""rtl/soc_uart.v (uart_rx, uart_tx, two wm_fifo) at its pins with cocotbext-uart, under Verilator.

The cocotb side is uart_soc_tb.py: reset state, bytes both ways at two baud divisors, RX and TX
FIFOs full, a framing error and a glitch, the simulator's FIFO bypass.  Small FIFOs make the full
cases quick.
"""

from wavemesh.harness.rtl_runner import RTL, run

SOURCES = [RTL / f"{m}.v" for m in ("uart_rx", "uart_tx", "wm_fifo", "soc_uart")]


def test_uart_at_the_pins():
    params = {"RX_DEPTH": 8, "TX_DEPTH": 8, "DIV_RESET": 16}
    env = {"UART_RX_DEPTH": "8", "UART_TX_DEPTH": "8", "UART_DIV_RESET": "16"}
    run("soc_uart", SOURCES, "uart_soc_tb", parameters=params, extra_env=env)
