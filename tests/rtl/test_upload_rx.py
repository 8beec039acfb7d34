"""rtl/upload_rx.v, the upload block (frames checked, DATA's samples decoded into the SDRAM), against the
protocol's Python model under random back-pressure and corrupted frames; the bench is upload_rx_tb.py.

Built with a 64-sample line buffer, so grids of 37 and 50 columns wrap it within two rows and a repeat
from further back needs the reload from the SDRAM."""

import os

import pytest
from wavemesh.harness.rtl_runner import RTL, run

PARAMS = {"LB_DEPTH": 64, "ADDR_BITS": 16, "HEIGHT_BASE": 0x140}


@pytest.mark.parametrize("w,h,seed", [(37, 70, 1), (50, 50, 2)])
def test_upload_rx(w, h, seed):
    run("upload_rx", [RTL / "upload_rx.v"], "upload_rx_tb", parameters=PARAMS,
        extra_env={"WM_UPLOAD_W": str(w), "WM_UPLOAD_H": str(h),
                   "WM_UPLOAD_SEED": os.environ.get("WM_UPLOAD_SEED", str(seed))})
