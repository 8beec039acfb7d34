"""The ctypes side of the native library (wavemesh.refine.native) against the C header it mirrors, field by
field: the structures' member names, types and order, and the codes and limits the host uses.  The
header (firmware/include/wavemesh.h) is the truth for the library; protocol.py for the limits."""

from __future__ import annotations

import ctypes
import re
from pathlib import Path

import pytest
from wavemesh.device import protocol as P
from wavemesh.refine import native

HEADER = (Path(__file__).resolve().parents[2] / "firmware" / "include" / "wavemesh.h").read_text()
C_TYPES = {"int32_t": ctypes.c_int32, "uint32_t": ctypes.c_uint32, "uint64_t": ctypes.c_uint64,
           "const uint16_t *": ctypes.POINTER(ctypes.c_uint16),  # POINTER caches: one class per target
           "const int32_t *": ctypes.POINTER(ctypes.c_int32),
           "const uint8_t *": ctypes.POINTER(ctypes.c_uint8)}


def c_struct(name: str) -> list[tuple[str, object]]:
    """(member, ctypes type) of `typedef struct NAME { ... } NAME;`, in order, comments dropped."""
    body = re.search(rf"typedef struct {name} \{{(.*?)\}} {name};", HEADER, re.S).group(1)
    body = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    out = []
    for decl in body.split(";"):
        decl = " ".join(decl.split())
        if not decl:
            continue
        m = re.match(r"((?:const )?u?int(?:8|16|32|64)_t)\s*(\*?)\s*(.*)", decl)
        ctype = C_TYPES[m.group(1) + (" *" if m.group(2) else "")]
        out += [(n.strip(), ctype) for n in m.group(3).split(",")]
    return out


@pytest.mark.parametrize("cls,name", [(native.Params, "wm_params"), (native.Field, "wm_field"),
                                      (native.LevelStats, "wm_level_stats")])
def test_ctypes_structures_are_the_headers_member_by_member(cls, name):
    want = c_struct(name)
    assert [n for n, _ in cls._fields_] == [n for n, _ in want]
    for (member, ctype), (_, want_type) in zip(cls._fields_, want, strict=True):
        assert ctype is want_type, member


def define(name: str) -> int:
    return int(re.search(rf"#define {name} \(?(-?\d+)u?\)?", HEADER).group(1))


def test_codes_flags_and_limits_are_the_headers():
    assert (native.WM_OK, native.WM_ERR_CAPACITY) == (define("WM_OK"), define("WM_ERR_CAPACITY"))
    for flag in ("NO_BOUND", "NO_LEGALISE", "NO_DECIMATE", "NO_REDUCE"):
        assert getattr(native, f"FLAG_{flag}") == define(f"WM_FLAG_{flag}"), flag
    assert native.METRICS == {"normal": define("WM_METRIC_NORMAL"), "vertical": define("WM_METRIC_VERTICAL")}
    assert native.NEIGHBOURHOODS == {"face": define("WM_NEIGHBOURHOOD_FACE"),
                                     "vertex": define("WM_NEIGHBOURHOOD_VERTEX")}
    # protocol.py is the one source of the limits; the header states them too (board/src/wm_job.c checks that
    # at compile time, and this for the host)
    assert (P.MAX_SIDE, P.MAX_LEVELS) == (define("WM_MAX_SIDE"), define("WM_MAX_LEVELS"))
    assert native.MAX_SIDE == P.MAX_SIDE


def test_error_texts_come_from_the_library():
    assert native.error_text(define("WM_ERR_CAPACITY")) == "capacity exhausted"
    assert native.error_text(define("WM_ERR_ARG")) == "argument out of range"
