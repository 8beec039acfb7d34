"""The refiner reads no entry of its storage before writing it: the board hands it storage an earlier
job used without clearing it (firmware/board/src/wm_job.c, wm_job_refine), so a read of an unwritten
entry would let that job's data reach this one (its cycle counts, at least).  valgrind's memcheck runs
the release runner (tests/firmware/wm_run.c: its storage from malloc, undefined to memcheck) on
test_sanitized.py's refinements, and any use of an undefined value fails the run."""

import shutil
import subprocess

import pytest
from test_sanitized import CASES, write_case

pytestmark = pytest.mark.skipif(shutil.which("valgrind") is None,
                                reason="valgrind is not installed (tools/debian-packages.txt)")


@pytest.mark.parametrize("name,make,levels,params,cap", CASES, ids=[c[0] for c in CASES])
def test_no_storage_read_before_written(name, make, levels, params, cap, release_build, tmp_path):
    write_case(make, levels, params, tmp_path / "in.bin", cap)
    r = subprocess.run(["valgrind", "--tool=memcheck", "--error-exitcode=99", "--track-origins=yes",
                        str(release_build / "wm_run"), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-4000:]
    assert "ERROR SUMMARY: 0 errors" in r.stderr
