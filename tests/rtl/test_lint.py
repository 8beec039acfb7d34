"""`verilator --lint-only -Wall` is clean on every module under rtl/ (waivers only in rtl/lint.vlt)."""

import subprocess
from pathlib import Path

import pytest
from wavemesh.harness.rtl_runner import GEN, RTL

MODULES = sorted(RTL.glob("*.v"))


def picorv32_dir() -> str:
    """The PicoRV32 of the pythondata-cpu-picorv32 package (soc_top instantiates it; never copied here)."""
    import pythondata_cpu_picorv32

    return pythondata_cpu_picorv32.data_location


@pytest.mark.parametrize("source", MODULES, ids=[p.stem for p in MODULES])
def test_lint_clean(source: Path, verilator):
    from wavemesh.gen import write_all

    write_all(GEN)
    exe, env = verilator
    r = subprocess.run([exe, "--lint-only", "-Wall", f"-I{GEN}", "-y", str(RTL), "-y", picorv32_dir(),
                        str(RTL / "lint.vlt"),
                        str(source), "--top-module", source.stem], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr


def test_waivers_have_reasons():
    lines = [ln.strip() for ln in (RTL / "lint.vlt").read_text().splitlines()]
    for i, line in enumerate(lines):
        if line.startswith("lint_off"):
            assert i > 0 and lines[i - 1].startswith("//"), f"waiver without a reason: {line}"
