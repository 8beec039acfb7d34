"""The SoC's CPU: the one place that chooses it.

``CPU`` names the soft CPU of the ULX3S SoC (rtl/soc_top.v) by default; ``WM_CPU=<name>`` in the
environment (``make ... CPU=<name>``) chooses another for one build.  Everything that depends on the
choice reads it here:

- the simulated board (sim/build.py) and the bitstream (tools/boards.py): the CPU's Verilog, from its
  pythondata package (never copied into the repository), and the `` `define`` soc_top selects it by
- the board firmware (sim/build.py's build_firmware, firmware/board's toolchain file): ``-march`` and
  the ``WM_CPU_<NAME>`` macro (the VexRiscv's data cache flush after the FPGA stage, wm_sys.h)
- the lint (tests/rtl/test_lint.py, ``make lint``): the folders of every CPU's Verilog

docs/soc.md, "The CPU", compares the CPUs on the same jobs.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Cpu:
    name: str  # WM_CPU value; the build folders of a CPU other than the default carry it
    package: str  # the pythondata package with its Verilog
    verilog: str  # the file in the package's data_location
    module: str  # the CPU's module in that file (the VexRiscv variants of the package all name it VexRiscv)
    define: str  # the Verilog macro that makes soc_top instantiate it ("" for the PicoRV32)
    march: str  # the firmware's -march
    doc: str

    def folder(self) -> Path:
        try:
            module = importlib.import_module(self.package)
        except ImportError:
            pkg = self.package.replace("_", "-")
            raise MissingCpu(f"{pkg} is not installed (the {self.name}'s Verilog): run `make setup` "
                             "(requirements.txt pins it)") from None
        return Path(module.data_location)

    def verilog_file(self) -> Path:
        return self.folder() / self.verilog

    @property
    def c_macro(self) -> str:
        return "WM_CPU_" + self.name.upper()


CPUS = {
    c.name: c
    for c in (
        Cpu("picorv32", "pythondata_cpu_picorv32", "picorv32.v", "picorv32", "", "rv32imc",
            "PicoRV32 (RV32IMC): no caches, fast multiplier, divider; soc_top's native memory bus"),
        Cpu("vexriscv", "pythondata_cpu_vexriscv", "VexRiscv_IMAC.v", "VexRiscv", "WM_CPU_VEXRISCV",
            "rv32imc",
            "VexRiscv IMAC (RV32IMAC): 5 stages, 4 KiB instruction and data caches, one-cycle multiplier, "
            "33-cycle divider, compressed instructions; rtl/soc_cpu_vexriscv.v puts its Wishbone buses on "
            "the native bus"),
    )
}
CPU = "vexriscv"


class UnknownCpu(ValueError):
    pass


class MissingCpu(RuntimeError):
    """A CPU's pythondata package is not installed."""


def selected(name: str | None = None) -> Cpu:
    """The CPU `name`, else $WM_CPU, else the default ``CPU``."""
    name = name or os.environ.get("WM_CPU") or CPU
    if name not in CPUS:
        raise UnknownCpu(f"WM_CPU={name} is not a CPU of the SoC: use one of {', '.join(CPUS)}")
    return CPUS[name]


def suffix(cpu: Cpu) -> str:
    """The build folders' suffix: "" for the default CPU, else "-NAME"."""
    return "" if cpu.name == CPU else f"-{cpu.name}"


def lint_folders() -> list[Path]:
    """The folders of every CPU's Verilog (for `verilator -y`)."""
    return [c.folder() for c in CPUS.values()]
