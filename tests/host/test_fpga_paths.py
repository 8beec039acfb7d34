"""host/wavemesh/harness/fpga.py and tools/boards.py run the YoWASP tools, whose sandbox mounts a private
/tmp over the
host's: a design under /tmp (pytest's tmp_path is there) must still synthesise, place and route
(host/wavemesh/harness/fpga.py, "Paths")."""

from __future__ import annotations

from pathlib import Path

from wavemesh.harness import fpga


def test_design_under_tmp_synthesises_and_routes(tmp_path: Path, monkeypatch):
    assert str(tmp_path).startswith("/tmp/"), "the point of the test is a folder under /tmp"
    src = tmp_path / "src" / "count4.v"
    src.parent.mkdir()
    src.write_text("module count4 (input wire clk, input wire en, output reg [3:0] q = 4'd0);\n"
                   "always @(posedge clk) if (en) q <= q + 4'd1;\nendmodule\n")
    monkeypatch.setattr(fpga, "BUILD", tmp_path / "fpga")
    r = fpga.synth_pnr("count4", [src], {}, "up5k", io="pins")
    assert r["fits"], r.get("error")
    assert r["fmax_mhz"] > 50 and r["ffs"] == 4 and r["lcs"] >= 4
    assert (tmp_path / "fpga" / "count4_up5k_default" / "netlist.json").exists()


def test_rel_is_relative_to_the_work_folder(tmp_path: Path):
    assert fpga.rel(tmp_path / "a" / "b.v", tmp_path / "c") == "../a/b.v"
