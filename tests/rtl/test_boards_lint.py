"""`verilator --lint-only -Wall` is clean on every board top and module of rtl/boards/ (waivers only in
rtl/lint.vlt), as tests/rtl/test_lint.py checks rtl/."""

import subprocess
from pathlib import Path

import pytest
from wavemesh.harness.rtl_runner import GEN, RTL

BOARDS = RTL / "boards"
MODULES = sorted(BOARDS.glob("*.v"))


@pytest.mark.parametrize("source", MODULES, ids=[p.stem for p in MODULES])
def test_board_module_lint_clean(source: Path, verilator):
    from wavemesh.device import soc_cpu
    from wavemesh.device.gen import write_all

    write_all(GEN)
    exe, env = verilator
    r = subprocess.run([exe, "--lint-only", "-Wall", f"-I{GEN}", "-y", str(RTL), "-y", str(BOARDS),
                        *(a for d in soc_cpu.lint_folders() for a in ("-y", str(d))), str(RTL / "lint.vlt"),
                        str(source), "--top-module", source.stem], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
