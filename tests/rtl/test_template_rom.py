"""The generated template ROM include and C header hold the reference model's template set.

Both are compiled and executed (Verilator, gcc) and every word they produce is
compared with wavemesh.model.templates; a failure here means a consumer would see
other data than the model.
"""

import json
import subprocess

from wavemesh.device import gen
from wavemesh.model.templates import LUT_INVALID, LUT_SIZE, MAX_TRIANGLES, template_set

TS = template_set()

TB = """`default_nettype none
module tb;
`include "wm_templates.vh"
integer i;
initial begin
    for (i = 0; i < 64; i = i + 1) $display("rom %0d %025h", i, wm_template_rom(i[5:0]));
    for (i = 0; i < 128; i = i + 1) $display("lut %0d %0d", i, wm_template_lut(i[6:0]));
    $display("count %0d %0d %0d %0d", WM_TEMPLATE_COUNT, WM_TEMPLATE_MAX_TRIANGLES, WM_TPL_WORD_BITS,
             WM_LUT_INVALID);
    $finish;
end
endmodule
"""

C_MAIN = """#include <stdio.h>
#include "wm_templates.h"
int main(void) {
    for (int t = 0; t < WM_TEMPLATE_COUNT; t++) {
        printf("tpl %d %d", t, wm_template_ntri[t]);
        for (int k = 0; k < WM_TEMPLATE_MAX_TRIANGLES; k++)
            printf(" %d %d %d", wm_template_tri[t][k][0], wm_template_tri[t][k][1], wm_template_tri[t][k][2]);
        printf("\\n");
    }
    for (int i = 0; i < WM_LUT_SIZE; i++) printf("lut %d %d\\n", i, wm_template_lut[i]);
    printf("label %d %d %d\\n", WM_LABEL_D, WM_LABEL_DUAL_V, WM_SIDE_BOTTOM);
    return 0;
}
"""


def expected_word(t):
    return gen.rom_word(t.triangles)


def test_verilog_rom_matches_model(tmp_path, verilator):
    exe, env = verilator
    gen.write_all(tmp_path)
    (tmp_path / "tb.v").write_text(TB)
    subprocess.run([exe, "--binary", "-Wall", "-Wno-UNUSEDSIGNAL", "-I" + str(tmp_path), "--Mdir",
                    str(tmp_path / "obj"), "-o", "tb", str(tmp_path / "tb.v")],
                   check=True, env=env, capture_output=True, text=True)
    out = subprocess.run([str(tmp_path / "obj" / "tb")], check=True, capture_output=True, text=True).stdout
    rom, lut = {}, {}
    for line in out.splitlines():
        f = line.split()
        if f[0] == "rom":
            rom[int(f[1])] = int(f[2], 16)
        elif f[0] == "lut":
            lut[int(f[1])] = int(f[2])
        elif f[0] == "count":
            assert [int(x) for x in f[1:]] == [len(TS.templates), MAX_TRIANGLES, 4 + 12 * MAX_TRIANGLES, 0xFF]
    for t in TS.templates:
        assert rom[t.id] == expected_word(t), t.name
        word = rom[t.id]
        ntri = word >> (12 * MAX_TRIANGLES)
        tris = [((word >> 12 * k) & 15, (word >> 12 * k + 4) & 15, (word >> 12 * k + 8) & 15)
                for k in range(ntri)]
        assert tuple(tris) == t.triangles
    for i in range(len(TS.templates), 64):
        assert rom[i] == 0
    assert [lut[i] for i in range(LUT_SIZE)] == list(TS.lut)


def test_c_header_matches_model(tmp_path):
    gen.write_all(tmp_path)
    (tmp_path / "main.c").write_text(C_MAIN)
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I" + str(tmp_path),
                    str(tmp_path / "main.c"), "-o", str(tmp_path / "main")], check=True)
    out = subprocess.run([str(tmp_path / "main")], check=True, capture_output=True, text=True).stdout
    lines = out.splitlines()
    for t, line in zip(TS.templates, lines, strict=False):
        f = [int(x) for x in line.split()[1:]]
        assert f[0] == t.id and f[1] == len(t.triangles)
        tris = [tuple(f[2 + 3 * k:5 + 3 * k]) for k in range(MAX_TRIANGLES)]
        assert tuple(tris[:len(t.triangles)]) == t.triangles
        assert all(x == (0, 0, 0) for x in tris[len(t.triangles):])
    luts = [int(line.split()[2]) for line in lines if line.startswith("lut")]
    assert luts == list(TS.lut)
    assert lines[-1] == "label 6 3 8"


def test_json_matches_model(tmp_path):
    gen.write_all(tmp_path)
    data = json.loads((tmp_path / "templates.json").read_text())
    got = [tuple(map(tuple, t["triangles"])) for t in data["templates"]]
    assert got == [t.triangles for t in TS.templates]
    assert data["lut"] == list(TS.lut)
    assert sum(x != LUT_INVALID for x in data["lut"]) == 16 * 2 + 4 * 4 + 16  # F f, V v H h, D


def test_generation_is_stable(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    gen.write_all(a)
    gen.write_all(b)
    for name in ("wm_templates.h", "wm_templates.vh", "templates.json"):
        assert (a / name).read_text() == (b / name).read_text()
