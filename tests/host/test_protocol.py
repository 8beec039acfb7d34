"""The protocol's single source (host/wavemesh/device/protocol.py): formats, the generated C header, the docs.

The C header is compiled and its every constant and offset compared with the module; docs/protocol.md's
byte tables must be the generated ones; the refiner's statistics and parameters keep the layout the
library has.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from wavemesh.device import gen
from wavemesh.device import protocol as P
from wavemesh.device.stream import DeviceInfo, config_payload, parse_level, samples_crc
from wavemesh.refine import native

ROOT = Path(__file__).resolve().parents[2]


def header_defines() -> dict[str, str]:
    return dict(re.findall(r"^#define (\w+) (\S+)", P.c_header(), re.M))


def test_header_constants_match_the_module():
    d = header_defines()
    assert int(d["WM_PROTO_VERSION"].rstrip("u"), 16) == P.VERSION
    assert int(d["WM_PROTO_MAX_PAYLOAD"]) == P.MAX_PAYLOAD
    for t in P.FrameType:
        assert int(d[f"WM_PROTO_T_{t.name}"].rstrip("u"), 16) == t.value
    for e in P.ErrorCode:
        assert int(d[f"WM_PROTO_E_{e.name}"]) == e.value
    for s in P.Stage:
        assert int(d[f"WM_PROTO_STAGE_{s.name}"]) == s.value
    for m in P.MESSAGES:
        assert int(d[f"WM_PROTO_{m.name}_BYTES"]) == m.size
        for name, off in m.offsets().items():
            assert int(d[f"WM_PROTO_{m.name}_{name.upper()}"]) == off


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_header_compiles_and_agrees_with_struct(tmp_path):
    """Compile the header and print a few offsets from C: the same numbers as struct gives."""
    (tmp_path / "wm_protocol.h").write_text(P.c_header())
    fields = [("CONFIG", "DELTA_D"), ("DONE", "CYCLES_EMIT"), ("HELLO_REPLY", "SESSION_TIMEOUT_MS"),
              ("LEVEL_HEADER", "ST_E_MAX")]
    src = "#include <stdio.h>\n#include \"wm_protocol.h\"\nint main(void){\n" + "".join(
        f'printf("%d\\n", WM_PROTO_{m}_{f});\n' for m, f in fields) + "return 0;}\n"
    (tmp_path / "t.c").write_text(src)
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Werror", "-o", str(tmp_path / "t"), str(tmp_path / "t.c")],
                   check=True, cwd=tmp_path)
    out = subprocess.run([str(tmp_path / "t")], capture_output=True, text=True, check=True).stdout.split()
    msgs = {m.name: m for m in P.MESSAGES}
    assert [int(v) for v in out] == [msgs[m].offsets()[f.lower()] for m, f in fields]


def test_gen_writes_the_protocol_header(tmp_path):
    written = {p.name for p in gen.write_all(tmp_path)}
    assert "wm_protocol.h" in written
    assert (tmp_path / "wm_protocol.h").read_text() == P.c_header()


def test_docs_tables_are_current():
    assert P.doc_is_current(ROOT / "docs" / "protocol.md"), \
        "run `python -m wavemesh.device.protocol --update docs/protocol.md`"


def test_every_frame_type_has_a_payload_and_fits():
    assert set(P.PAYLOAD) == set(P.FrameType)
    for m in P.MESSAGES:
        assert m.size <= P.MAX_PAYLOAD
    assert all(t < 0x80 for t in (P.FrameType.HELLO, P.FrameType.CONFIG, P.FrameType.DATA, P.FrameType.RUN,
                                  P.FrameType.ACK, P.FrameType.STATUS, P.FrameType.ABORT))
    assert all(t >= 0x80 for t in P.FrameType if t.name in {"OK", "HELLO_REPLY", "DATA_ACK", "STATUS_REPLY",
                                                            "PROGRESS", "MESH", "LEVEL_END", "DONE", "ERROR"})


def test_pack_unpack_round_trip_and_checks():
    b = P.DONE.pack(status=0, levels=5, detail=0, e_max=123, triangles=7, vertices=6, initial_triangles=9,
                    initial_vertices=8, cycles_receive=1, cycles_filter=2, cycles_template=3, cycles_refine=4,
                    cycles_emit=2**40)
    f = P.DONE.unpack(b)
    assert f["cycles_emit"] == 2**40 and f["levels"] == 5 and f["stack_bytes"] == f["stack_peak"] == 0
    assert f["initial_triangles"] == 9 and f["initial_vertices"] == 8
    with pytest.raises(TypeError):
        P.DONE.pack(status=0)  # missing fields
    with pytest.raises(TypeError):
        P.OK.pack(request=1, nonsense=2)


def test_stats_layout_is_the_librarys():
    # The C header is the truth for the library: wm_level_stats' fields, in order, from its text.
    header = (Path(__file__).resolve().parents[2] / "firmware" / "include" / "wavemesh.h").read_text()
    body = re.search(r"typedef struct wm_level_stats \{(.*?)\} wm_level_stats;", header, re.S).group(1)
    c_fields = re.findall(r"^\s*u?int32_t\s+([^;]+);", body, re.M)
    c_names = [n.strip() for decl in c_fields for n in decl.split(",")]
    assert c_names == list(P.STAT_FIELDS) + ["e_max", "removals"]
    stats = [f.name for f in P.LEVEL_HEADER.fields if f.name.startswith("st_")]
    assert stats == [f"st_{n}" for n in c_names]
    assert [n for n, _ in native.LevelStats._fields_] == c_names


def test_config_carries_the_refiners_fixed_point_parameters():
    p = native.RefineParams(zeta=2.5, metric="vertical", delta_d=0.3, delta_p=0.75, delta_v=1.5, alpha=0.25,
                            iterations=3, neighbourhood="vertex", max_triangles=999)
    fp = native.fixed_params(p, 0.5)
    c = P.CONFIG.unpack(config_payload(100, 50, 4, 77, fp, capacity=1000, initial_only=True))
    assert (c["width"], c["height"], c["levels"], c["tau"], c["capacity"]) == (100, 50, 4, 77, 1000)
    assert c["flags"] == P.CONFIG_INITIAL_ONLY
    for name, _ in native.Params._fields_:
        if name not in ("reserved", "flags"):  # CONFIG.flags: CONFIG_* bits, wm_params.flags shifted by one
            assert c[name] == getattr(fp, name), name
    assert c["delta_lambda"] == round(0.01 * 65536) and c["delta_c"] == round(0.98 * 65536)


def test_config_field_names_for_bad_value_details():
    off = P.CONFIG.offsets()
    assert P.config_field_at(off["alpha"]) == "alpha"
    assert P.config_field_at(999) == "byte 999"


def test_level_stream_parsing_rejects_inconsistent_streams():
    import struct

    hdr = dict(level=0, index_bytes=2, vertex_slots=3, triangles=1, cycles=5,
               **{f"st_{n}": 0 for n in P.STAT_FIELDS}, st_e_max=0, st_removals=0)
    body = struct.pack("<6H", 0, 0, 1, 0, 0, 1) + struct.pack("<3H", 0, 1, 2)
    h, mesh, stats, cycles = parse_level(P.LEVEL_HEADER.pack(**hdr) + body, 2, 2)
    assert mesh.n_triangles == 1 and mesh.n_vertices == 3 and cycles == 5 and stats["e_max_q16"] == 0
    from wavemesh.device.stream import ProtocolError

    with pytest.raises(ProtocolError):  # one byte short
        parse_level(P.LEVEL_HEADER.pack(**hdr) + body[:-1], 2, 2)
    with pytest.raises(ProtocolError):  # a vertex outside the grid
        parse_level(P.LEVEL_HEADER.pack(**hdr) + struct.pack("<6H", 0, 0, 5, 0, 0, 1) + body[12:], 2, 2)
    with pytest.raises(ProtocolError):  # a triangle refers to vertex 3 of 3
        parse_level(P.LEVEL_HEADER.pack(**hdr) + body[:12] + struct.pack("<3H", 0, 1, 3), 2, 2)
    # a free vertex slot is dropped and the indices renumbered, as wavemesh.refine.native does
    hdr4 = dict(hdr, vertex_slots=4)
    body4 = struct.pack("<8H", 0, 0, 0xFFFF, 0xFFFF, 1, 0, 0, 1) + struct.pack("<3H", 0, 2, 3)
    _, mesh, _, _ = parse_level(P.LEVEL_HEADER.pack(**hdr4) + body4, 2, 2)
    assert mesh.xy.tolist() == [[0, 0], [1, 0], [0, 1]] and mesh.tris.tolist() == [[0, 1, 2]]
    # LEVEL_DELTA: the same level delta-coded gives the same mesh; damaged, a ProtocolError
    from wavemesh.device.coding import encode_level_body

    delta = encode_level_body([(0, 0), (0xFFFF, 0xFFFF), (1, 0), (0, 1)], [(0, 2, 3)])
    hdr_d = dict(hdr4, coding=P.LEVEL_DELTA)
    _, mesh_d, _, _ = parse_level(P.LEVEL_HEADER.pack(**hdr_d) + delta, 2, 2)
    assert mesh_d.xy.tolist() == mesh.xy.tolist() and mesh_d.tris.tolist() == mesh.tris.tolist()
    for bad in (delta[:-1], delta + b"\x00", encode_level_body([(0, 0), (0xFFFF, 0xFFFF), (1, 0), (0, 2)],
                                                                 [(0, 2, 3)])):
        with pytest.raises(ProtocolError):  # short, a number over, a vertex outside the grid
            parse_level(P.LEVEL_HEADER.pack(**hdr_d) + bad, 2, 2)
    with pytest.raises(ProtocolError):  # an unknown coding
        parse_level(P.LEVEL_HEADER.pack(**dict(hdr4, coding=7)) + body4, 2, 2)


def test_hello_reply_parses_into_device_info():
    b = P.HELLO_REPLY.pack(version=P.VERSION, fw_major=1, fw_minor=2, name=b"wm-board", max_width=256,
                           max_height=256, max_samples=65536, tri_capacity=1492, max_levels=8, window=4,
                           max_payload=1024, clk_hz=25_000_000, baud=115200, features=0, byte_timeout_ms=100,
                           ack_timeout_ms=500, session_timeout_ms=5000)
    info = DeviceInfo.from_fields(P.HELLO_REPLY.unpack(b))
    assert info.name == "wm-board" and info.max_budget == 1491 and "25 MHz" in info.summary()


def test_samples_crc_is_zlib_of_little_endian_samples():
    import zlib

    import numpy as np

    a = np.arange(12, dtype=np.uint16).reshape(3, 4) * 4099
    assert samples_crc(a) == zlib.crc32(a.astype("<u2").tobytes())


def _prose() -> str:
    """docs/protocol.md without its generated tables (between the markers)."""
    text = (ROOT / "docs" / "protocol.md").read_text()
    return text[:text.index(P.MD_BEGIN)] + text[text.index(P.MD_END):]


def test_docs_prose_states_the_module_constants():
    """The written text of docs/protocol.md quotes constants as `NAME` (value) or value (`NAME`): each
    such value must be the module's (the generated tables hold the rest)."""
    prose = _prose()
    quoted = [(n, v) for n, v in re.findall(r"`([A-Z][A-Z0-9_]+)` \((\d+)\)", prose)]
    quoted += [(n, v) for v, n in re.findall(r"(\d+) \(`([A-Z][A-Z0-9_]+)`\)", prose)]
    quoted = [(n, int(v)) for n, v in quoted if isinstance(getattr(P, n, None), int)]
    assert len(quoted) >= 5, quoted  # the pattern still finds them
    assert [(n, v) for n, v in quoted if getattr(P, n) != v] == []
    tol = re.search(r"`BAUD_TOLERANCE` \(([\d.]+) %", prose)
    assert tol and float(tol.group(1)) / 100 == P.BAUD_TOLERANCE
    bauds = re.search(r"`COMMON_BAUDS` \(([^:)]+)", prose).group(1)
    as_int = [int(float(b[:-1]) * 1e6) if b.endswith("M") else int(b) for b in bauds.split(", ")]
    assert tuple(as_int) == P.COMMON_BAUDS


def test_docs_timeouts_table_states_the_defaults():
    """The table of the host's timeouts (stream.Timeouts) gives each field's default."""
    from dataclasses import fields

    from wavemesh.device.stream import Timeouts

    table = re.search(r"^\| name \| default \| meaning \|\n((?:\|.*\n)+)", _prose(), re.M).group(1)
    rows = dict(re.findall(r"^\| `(\w+)` \| ([^|]+) \|", table, re.M))
    defaults = {f.name: f.default for f in fields(Timeouts)}
    assert set(rows) == set(defaults)
    stated = {k: None if v.strip() == "None" else float(v) for k, v in rows.items()}
    assert {k: (stated[k], v) for k, v in defaults.items() if stated[k] != v} == {}


def test_done_must_state_the_last_level_that_arrived():
    """Device.run's last check (stream.check_done): DONE's triangles, vertices and E_max against the
    last level that arrived; any one of them off is a ProtocolError naming both, none arrived: nothing
    to check."""
    from wavemesh.device.stream import LevelResult, ProtocolError, check_done
    from wavemesh.mesh import Mesh

    mesh = Mesh(3, 2, [(0, 0), (2, 0), (2, 1), (0, 1)], [(0, 1, 2), (0, 2, 3)])
    last = LevelResult(level=0, index=1, mesh=mesh, stats={"e_max_q16": 70000}, cycles=0, nbytes=0, seconds=0)
    done = {"triangles": 2, "vertices": 4, "e_max": 70000}
    check_done(done, [last])
    check_done(done | {"triangles": 9}, [])
    for field, wrong in (("triangles", 3), ("vertices", 5), ("e_max", 69999)):
        with pytest.raises(ProtocolError, match=r"DONE says the last level has .* level 0 arrived with 2, 4 "
                                                r"and 70000"):
            check_done(done | {field: wrong}, [last])


def test_a_stack_at_its_guard_is_an_error():
    """DONE's stack mark (tests/sim/test_stack.py: on the board): within STACK_GUARD_BYTES of the reserve,
    or past it, the host refuses the job and names the stack; a device that does not measure it states 0."""
    from wavemesh.device import memmap
    from wavemesh.device.stream import DeviceError, check_stack

    assert memmap.STACK_BYTES < 1 << 16  # DONE.stack_bytes is a u16
    size = 12288
    check_stack({"stack_bytes": 0, "stack_peak": 0})
    check_stack({"stack_bytes": size, "stack_peak": size - P.STACK_GUARD_BYTES})
    g = P.STACK_GUARD_BYTES
    near = f"stack reached {size - g + 4} bytes: it came within {g - 4} bytes"
    with pytest.raises(DeviceError, match=near):
        check_stack({"stack_bytes": size, "stack_peak": size - P.STACK_GUARD_BYTES + 4})
    with pytest.raises(DeviceError, match=f"overflowed its {size}-byte reserve by 8 bytes"):
        check_stack({"stack_bytes": size, "stack_peak": size + 8})
