"""The refiner reads no entry of its storage before writing it: the board hands it storage an earlier
job used without clearing it (firmware/board/src/wm_job.c, wm_job_refine), so a read of an unwritten
entry would let that job's data reach this one (its cycle counts, at least).  valgrind's memcheck runs
the release runner (tests/firmware/wm_run.c: its storage from malloc, undefined to memcheck) on
test_sanitized.py's refinements, and any use of an undefined value fails the run."""

import shutil
import subprocess

import numpy as np
import pytest
from test_sanitized import CASES
from wavemesh import api
from wavemesh.harness.fwio import write_input
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import decompose
from wavemesh.refine import native

pytestmark = pytest.mark.skipif(shutil.which("valgrind") is None,
                                reason="valgrind is not installed (tools/debian-packages.txt)")


@pytest.mark.parametrize("name,make,levels,params", CASES, ids=[c[0] for c in CASES])
def test_no_storage_read_before_written(name, make, levels, params, release_build, tmp_path):
    hf = from_array(make(np.random.default_rng(5)))
    job = api.triangulate(hf, levels)
    fp = native.fixed_params(params, hf.scale)
    det = native.details_array(decompose(hf.samples, levels))
    cap = max(2 * (hf.width - 1) * (hf.height - 1), 8)
    write_input(tmp_path / "in.bin", hf.samples, det, levels, job.mesh, fp, cap)
    r = subprocess.run(["valgrind", "--tool=memcheck", "--error-exitcode=99", "--track-origins=yes",
                        str(release_build / "wm_run"), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-4000:]
    assert "ERROR SUMMARY: 0 errors" in r.stderr
