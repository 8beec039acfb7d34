"""`verilator --lint-only -Wall` is clean on every module under rtl/ (waivers only in rtl/lint.vlt)."""

import subprocess
from pathlib import Path

import pytest
from wavemesh.harness.rtl_runner import GEN, RTL

MODULES = sorted(RTL.glob("*.v"))


def cpu_dirs() -> list[str]:
    """-y for the folders of every CPU's Verilog (their pythondata packages; never copied here)."""
    from wavemesh.device import soc_cpu

    return [a for d in soc_cpu.lint_folders() for a in ("-y", str(d))]


def lint(source: Path, verilator, *defines: str):
    from wavemesh.device.gen import write_all

    write_all(GEN)
    exe, env = verilator
    return subprocess.run([exe, "--lint-only", "-Wall", f"-I{GEN}", "-y", str(RTL), *cpu_dirs(),
                           *(f"+define+{d}" for d in defines), str(RTL / "lint.vlt"),
                           str(source), "--top-module", source.stem], capture_output=True, text=True, env=env)


@pytest.mark.parametrize("source", MODULES, ids=[p.stem for p in MODULES])
def test_lint_clean(source: Path, verilator):
    r = lint(source, verilator)
    assert r.returncode == 0, r.stderr


def test_lint_clean_with_the_simulators_stage_gate(verilator):
    """soc_accel as the simulator builds it, its stage clock gated (sim/build.py, STAGE_GATE)."""
    r = lint(RTL / "soc_accel.v", verilator, "WM_SIM_STAGE_GATE")
    assert r.returncode == 0, r.stderr


def test_lint_clean_with_the_simulators_engine_gates(verilator):
    """soc_engine as the simulator builds it, its units' clocks gated (sim/build.py, ENGINE_GATE)."""
    r = lint(RTL / "soc_engine.v", verilator, "WM_SIM_ENGINE_GATE")
    assert r.returncode == 0, r.stderr


def test_lint_clean_every_cpu(verilator):
    """soc_top with each CPU host/wavemesh/device/soc_cpu.py offers (the default one is linted above)."""
    from wavemesh.device import soc_cpu

    for cpu in soc_cpu.CPUS.values():
        if cpu.define:
            r = lint(RTL / "soc_top.v", verilator, cpu.define)
            assert r.returncode == 0, f"{cpu.name}: {r.stderr}"


def test_waivers_have_reasons():
    lines = [ln.strip() for ln in (RTL / "lint.vlt").read_text().splitlines()]
    for i, line in enumerate(lines):
        if line.startswith("lint_off"):
            assert i > 0 and lines[i - 1].startswith("//"), f"waiver without a reason: {line}"
