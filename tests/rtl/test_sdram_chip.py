"""The simulated board's SDRAM chip model (sim/sdram_chip.v) accepts a legal command sequence, returns
a read datum in its CAS-latency window only, and reports every kind of violation it checks; the bench
is sdram_chip_tb.py.  Built small (2048 rows x 256 columns) at 125 MHz."""

from wavemesh.harness.rtl_runner import ROOT, run

PARAMS = {"CLK_HZ": 125_000_000, "ROW_BITS": 11, "COL_BITS": 8, "FATAL": 0}


def test_sdram_chip():
    run("sdram_chip", [ROOT / "sim" / "sdram_chip.v"], "sdram_chip_tb", parameters=PARAMS)
