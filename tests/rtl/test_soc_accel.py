"""The SoC's FPGA stage (rtl/soc_accel.v: height reader, haar_bank, coefficient writer, tlut_stage,
template-entry writer, registers) against the reference model; the bench is soc_accel_tb.py.

Built small (64 x 64, 5 levels, 32 block columns, small memories) so the refusals are reachable."""


from wavemesh.harness.rtl_runner import RTL, run

PARAMS = {"MAX_WIDTH": 64, "MAX_HEIGHT": 64, "MAX_LEVELS": 5, "MAX_COLS": 24,
          "HEIGHT_SAMPLES": 4000, "COEF_ENTRIES": 8192, "TOUT_ENTRIES": 512}


def test_soc_accel():
    sources = [RTL / "soc_accel.v", *sorted(RTL.glob("haar_*.v")), *sorted(RTL.glob("tlut_*.v")),
               RTL / "wm_fifo.v"]
    run("soc_accel", sources, "soc_accel_tb", parameters=PARAMS)
