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
    # the VexRiscv's instruction cache made this size (icache_resized; docs/soc.md, "The CPU"); 0: as shipped
    icache_kib: int = 0
    dcache_kib: int = 0  # ... and its data cache (dcache_resized)

    def folder(self) -> Path:
        try:
            module = importlib.import_module(self.package)
        except ImportError:
            pkg = self.package.replace("_", "-")
            raise MissingCpu(f"{pkg} is not installed (the {self.name}'s Verilog): run `make setup` "
                             "(requirements.txt pins it)") from None
        return Path(module.data_location)

    def verilog_file(self) -> Path:
        """The CPU's Verilog: the package's file, or for a resized cache the file derived from it in
        build/gen/cpu/ (written when missing or different; never committed, like the rest of build/)."""
        shipped = self.folder() / self.verilog
        if not self.icache_kib and not self.dcache_kib:
            return shipped
        text, name = shipped.read_text(), shipped.stem
        if self.icache_kib:
            text, name = icache_resized(text, self.icache_kib), f"{name}_ic{self.icache_kib}k"
        if self.dcache_kib:
            text, name = dcache_resized(text, self.dcache_kib), f"{name}_dc{self.dcache_kib}k"
        out = GEN_CPU / f"{name}.v"
        if not out.exists() or out.read_text() != text:
            out.parent.mkdir(parents=True, exist_ok=True)
            tmp = out.with_suffix(f".{os.getpid()}.tmp")  # pytest sessions may share the tree
            tmp.write_text(text)
            tmp.replace(out)
        return out

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
            "VexRiscv IMAC (RV32IMAC): 5 stages, 32 KiB instruction and data caches (the package's 4 KiB "
            "ones made larger: icache_resized, dcache_resized), one-cycle multiplier, 33-cycle divider, "
            "compressed instructions; rtl/soc_cpu_vexriscv.v puts its Wishbone buses on the native bus",
            icache_kib=32, dcache_kib=32),
    )
}
CPU = "vexriscv"

# where a CPU's derived Verilog is written (Cpu.verilog_file)
GEN_CPU = Path(__file__).resolve().parents[3] / "build" / "gen" / "cpu"


# the package's caches: 4 KiB of 32-byte lines, 128 lines (7 index bits) of 8 words (10 word index bits)
_LINE_BITS, _WORD_BITS = 7, 10

Edit = tuple[str, str, int]  # (old, new, count): _resize replaces exactly count occurrences of old


def _sizes(kib: int) -> tuple[int, int, int]:
    """(the first address bit above a cache of `kib` KiB, its line index bits, its word index bits)."""
    if kib not in (8, 16, 32):
        raise ValueError(f"a cache of {kib} KiB: 8, 16 or 32")
    lb = (kib * 32).bit_length() - 1  # 32-byte lines
    return lb + 5, lb, lb + 3


def _resize(text: str, module: str, edits: list[Edit]) -> str:
    """`text` with `module`'s body edited: each (old, new, count) replaces exactly count occurrences."""
    start = text.find(f"module {module} (")
    if start < 0:
        raise ValueError(f"not the {module} expected: the core has no such module")
    end = text.index("endmodule", start)
    body = text[start:end]
    for old, new, count in edits:
        if body.count(old) != count:
            raise ValueError(f"not the {module} expected: {old!r} {body.count(old)} times, not {count}")
        body = body.replace(old, new)
    return text[:start] + body + text[end:]


def _widened(kind: str, bits: int, new_bits: int, *names: str) -> list[Edit]:
    """The declarations ``kind [bits-1:0] name;`` of `names` (in the core's columns) made new_bits wide."""
    return [(f"{kind:<11}[{bits - 1}:0]    {n};", f"{kind:<11}[{new_bits - 1}:0]    {n};", 1) for n in names]


def _deepened(memory: str, bits: int, new_bits: int) -> Edit:
    """The memory declared ``memory [0:2**bits-1];`` made 2**new_bits deep."""
    return f"{memory} [0:{2**bits - 1}];", f"{memory} [0:{2**new_bits - 1}];", 1


def _flush_sweep(counter: str, lb: int, sep: str, reads: int, resets: int) -> list[Edit]:
    """A cache's flush sweep over lb line index bits: its `counter` (a line index and a done bit above it)
    declared, its done bit read `reads` times, its line index (sliced ``[6{sep}:{sep}0]``), its increment
    and its `resets` resets, all lb + 1 bits wide."""
    return [
        *_widened("reg", _LINE_BITS + 1, lb + 1, counter),
        (f"{counter}[{_LINE_BITS}]", f"{counter}[{lb}]", reads),
        (f"{counter}[{_LINE_BITS - 1}{sep}:{sep}0]", f"{counter}[{lb - 1}{sep}:{sep}0]", 1),
        (f"{counter} + 8'h01", f"{counter} + {lb + 1}'h001", 1),
        (f"{counter} <= 8'h0;", f"{counter} <= {lb + 1}'h000;", resets),
    ]


def icache_resized(text: str, kib: int) -> str:
    """The VexRiscv Verilog `text` (a GenCoreDefault core with the package's one-way 4 KiB instruction
    cache of 32-byte lines) with that cache made `kib` KiB (8, 16 or 32): the same module, its data
    memory and tag memory deeper, their indices wider, the flush sweep over every line.  The tags keep
    the address bits 31..12, the bits above 4 KiB being then both index and tag (equal by construction),
    so the hit test is unchanged.  Raises ValueError when the text is not the cache this expects."""
    top, lb, wb = _sizes(kib)
    return _resize(text, "InstructionCache", [
        *_flush_sweep("lineLoader_flushCounter", lb, " ", reads=5, resets=1),
        *_widened("wire", _LINE_BITS, lb, "lineLoader_write_tag_0_payload_address"),
        *_widened("wire", _WORD_BITS, wb, "lineLoader_write_data_0_payload_address",
                  "_zz_fetchStage_read_banksValue_0_dataMem"),
        *_widened("wire", _LINE_BITS, lb, "_zz_fetchStage_read_waysValues_0_tag_valid"),
        _deepened("reg [31:0] banks_0", _WORD_BITS, wb),
        _deepened("reg [21:0] ways_0_tags", _LINE_BITS, lb),
        ("lineLoader_address[11 : 5]", f"lineLoader_address[{top - 1} : 5]", 2),
        ("io_cpu_prefetch_pc[11 : 2]", f"io_cpu_prefetch_pc[{top - 1} : 2]", 1),
        ("io_cpu_prefetch_pc[11 : 5]", f"io_cpu_prefetch_pc[{top - 1} : 5]", 1),
    ])


def dcache_resized(text: str, kib: int) -> str:
    """`text` with the VexRiscv's one-way 4 KiB data cache made `kib` KiB, as icache_resized does the
    instruction cache: its tag and data memories deeper, their indices (and the write-collision
    compares) wider, the flush sweep over every line, the tags still the address bits 31..12."""
    top, lb, wb = _sizes(kib)
    return _resize(text, "DataCache", [
        *_widened("reg", _LINE_BITS, lb, "tagsReadCmd_payload", "tagsWriteCmd_payload_address",
                  "tagsWriteLastCmd_payload_address"),
        *_widened("reg", _WORD_BITS, wb, "dataReadCmd_payload", "dataWriteCmd_payload_address"),
        *_widened("wire", _WORD_BITS, wb, "_zz_stage0_dataColisions", "_zz__zz_stageA_dataColisions"),
        *(_deepened(f"reg [7:0] ways_0_data_symbol{k}", _WORD_BITS, wb) for k in range(4)),
        _deepened("reg [21:0] ways_0_tags", _LINE_BITS, lb),
        *_flush_sweep("stageB_flusher_counter", lb, "", reads=2, resets=2),
        # (the 10-bit ones before the 7-bit ones: a 32 KiB cache has 10-bit line numbers)
        ("10'bxxxxxxxxxx", f"{wb}'b" + "x" * wb, 2),
        ("7'bxxxxxxx", f"{lb}'b" + "x" * lb, 2),
        ("[11 : 2]", f"[{top - 1} : 2]", 4),
        ("[11 : 5]", f"[{top - 1} : 5]", 3),
    ])


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
