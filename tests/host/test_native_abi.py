"""The ctypes side of the native library (wavemesh.refine.native) against the C header it mirrors, field by
field: the structures' member names, types and order, and the codes and limits the host uses.  The
header (firmware/include/wavemesh.h) is the truth for the library and its limits (wavemesh.limits reads
them from it)."""

from __future__ import annotations

import ctypes
import re

import pytest
from wavemesh.device import protocol as P
from wavemesh.refine import native

HEADER = (native.FIRMWARE / "include" / "wavemesh.h").read_text()


def test_structures_are_read_from_the_header():
    # native.Params and native.Field are made from wavemesh.h (native.c_struct): every member, in order,
    # of the right width; the library's own sizeof agrees (native.load checks wm_abi_size too)
    names = [n for n, _ in native.Params._fields_]
    assert names[:4] == ["metric", "neighbourhood", "iterations", "max_triangles"]
    assert dict(native.Params._fields_)["delta_d"] is ctypes.c_uint64
    assert dict(native.Field._fields_)["mask"] is ctypes.POINTER(ctypes.c_uint8)
    lib = native.load()
    assert lib.wm_abi_size(0) == ctypes.sizeof(native.Params)
    assert lib.wm_abi_size(1) == ctypes.sizeof(native.Field)
    # a member added to the header is a member of the structure
    grown = HEADER.replace("int32_t slope_y_e;", "int32_t slope_y_e;\n    uint32_t new_one; /* new */")
    assert native.c_struct("wm_params", grown)[-1] == ("new_one", ctypes.c_uint32)


def test_level_stats_are_the_headers_member_by_member():
    assert native.LevelStats._fields_ == native.c_struct("wm_level_stats")


def define(name: str) -> int:
    return int(re.search(rf"#define {name} \(?(-?\d+)u?\)?", HEADER).group(1))


def test_codes_flags_and_limits_are_the_headers():
    assert (native.WM_OK, native.WM_ERR_CAPACITY) == (define("WM_OK"), define("WM_ERR_CAPACITY"))
    for flag in ("NO_BOUND", "NO_LEGALISE", "NO_DECIMATE", "NO_REDUCE"):
        assert getattr(native, f"FLAG_{flag}") == define(f"WM_FLAG_{flag}"), flag
    assert native.METRICS == {"normal": define("WM_METRIC_NORMAL"), "vertical": define("WM_METRIC_VERTICAL")}
    assert native.NEIGHBOURHOODS == {"face": define("WM_NEIGHBOURHOOD_FACE"),
                                     "vertex": define("WM_NEIGHBOURHOOD_VERTEX")}
    # the header is the one statement of the limits: wavemesh.limits reads them, protocol.py states them to
    # devices (board/src/wm_job.c checks the generated wm_protocol.h against the header at compile time)
    assert (P.MAX_SIDE, P.MAX_LEVELS) == (define("WM_MAX_SIDE"), define("WM_MAX_LEVELS"))
    assert native.MAX_SIDE == P.MAX_SIDE


def test_error_texts_come_from_the_library():
    assert native.error_text(define("WM_ERR_CAPACITY")) == "capacity exhausted"
    assert native.error_text(define("WM_ERR_ARG")) == "argument out of range"


def test_fixed_params_kept_are_the_same_and_a_copy():
    """fixed_params keeps its answers: each is the one worked out anew (every field, byte for byte), for
    parameters that differ in one field, the scale, zeta or the cell size; the caller gets a copy."""
    from wavemesh.api import RefineParams

    cases = [(RefineParams(), 0.01, None, (1.0, 1.0)),
             (RefineParams(metric="vertical"), 0.01, None, (1.0, 1.0)),
             (RefineParams(delta_d=0.2), 0.01, None, (1.0, 1.0)), (RefineParams(), 0.02, None, (1.0, 1.0)),
             (RefineParams(), 0.01, 3.5, (1.0, 1.0)), (RefineParams(), 0.01, 3.5, (2.0, 0.5)),
             (RefineParams(max_triangles=99, reduce=False), 1.0, 7.0, (30.0, 30.0))]
    for _ in range(2):  # worked out, then kept
        got = [native.fixed_params(*c) for c in cases]
        assert [bytes(g) for g in got] == [bytes(native._fixed_params(*c)) for c in cases]
        assert len({bytes(g) for g in got}) == len(cases)
    got[0].zeta = 12345
    assert native.fixed_params(*cases[0]).zeta != 12345


def test_fixed_params_kept_answer_follows_every_field():
    """A kept answer is never another parameter set's: every field of RefineParams changed alone (all of
    them, so a field fixed_params comes to read is in its cache key or fails here) gives the answer worked
    out anew, with the default's kept; so does one object with its fields assigned one after another."""
    from wavemesh.api import RefineParams

    other = {"zeta": 2.5, "metric": "vertical", "delta_d": 0.3, "delta_p": 0.7, "delta_v": 3.0, "alpha": 0.4,
             "delta_lambda": 0.05, "delta_c": 0.9, "iterations": 2, "neighbourhood": "vertex", "bound": False,
             "legalise": False, "decimate": False, "reduce": False, "max_triangles": 99, "capacity": 500,
             "extra": {"x": 1}}
    assert set(other) == set(RefineParams.__annotations__)
    rest = (0.01, None, (1.0, 1.0))
    native.fixed_params(RefineParams(), *rest)
    for name, value in other.items():
        p = RefineParams(**{name: value})
        assert bytes(native.fixed_params(p, *rest)) == bytes(native._fixed_params(p, *rest)), name
    # one object changed field by field after each answer: its values are read again after an assignment
    q = RefineParams()
    native.fixed_params(q, *rest)
    for name, value in other.items():
        setattr(q, name, value)
        assert bytes(native.fixed_params(q, *rest)) == bytes(native._fixed_params(q, *rest)), name


def _levels(job):
    return [(lv.level, lv.mesh.xy.tobytes(), lv.mesh.tris.tobytes(), lv.stats) for lv in job.output.levels]


def test_levels_do_not_depend_on_the_export_array(monkeypatch):
    """native.refine's levels come from wm_host_refine_levels into one array while it has room; a call that
    runs out leaves its level pending for the next (mode 0, its statistics already written).  With no room
    at all the first call exports nothing and every later one starts from a pending level: the same levels,
    meshes and statistics as with the default room, and the same capacity error."""
    from wavemesh import api
    from wavemesh.errors import WavemeshError
    from wavemesh.io import synth
    from wavemesh.io.heightfield import from_array

    hf = from_array(synth.f2(64))
    params = native.RefineParams(zeta=0.002)
    want = _levels(api.refine(hf, 5, None, params))
    assert len(want) >= 4 and len({len(w[2]) for w in want}) == len(want)
    monkeypatch.setattr(native, "_EXPORT_ROOM", 1)
    monkeypatch.setattr(native, "_EXPORT_AHEAD", 0)
    assert _levels(api.refine(hf, 5, None, params)) == want
    errors = []
    for room in (None, 1):
        if room is None:
            monkeypatch.undo()
        with pytest.raises(WavemeshError) as e:
            api.refine(hf, 5, None, native.RefineParams(zeta=0.002, capacity=len(want[-1][2]) // 12 - 1))
        errors.append(str(e.value))
        monkeypatch.setattr(native, "_EXPORT_ROOM", 1)
        monkeypatch.setattr(native, "_EXPORT_AHEAD", 0)
    assert errors[0] == errors[1]


def test_an_unexpected_code_of_the_levels_call_names_it(monkeypatch):
    """wm_host_refine_levels' code 2 (no room for the statistics: native.refine has room for every level the
    refiner makes, so only a bug gets it) ends in one NativeError that names the function and the code, not
    in wm_strerror's text of 2.  Reached for real: the library called with room for one level's statistics."""
    from wavemesh import api
    from wavemesh.io import synth
    from wavemesh.io.heightfield import from_array

    lib = native.load()
    real = lib.wm_host_refine_levels
    monkeypatch.setattr(lib, "wm_host_refine_levels",
                        lambda r, mode, stats, n, *rest: real(r, mode, stats, min(n, 1), *rest))
    with pytest.raises(native.NativeError) as e:
        api.refine(from_array(synth.f2(64)), 5, None, native.RefineParams())
    assert str(e.value) == ("wm_host_refine_levels returned the unexpected code 2 (levels exported: 1, "
                            "room for statistics: 7)")


def test_params_check_pass_goes_only_with_the_same_fields(monkeypatch):
    """The kept pass of RefineParams.check is no field (not in repr, equality, fields or asdict), and goes
    with an object only where its fields go unchanged: a copy, a deep copy and a pickled copy (a tile
    worker's) of an object that passed pass without the checks, each answers as a new object once a field
    is assigned, and dataclasses.replace makes a new object that is checked (a NaN zeta refused)."""
    import copy
    import dataclasses
    import pickle

    from wavemesh.errors import WavemeshError

    p = native.RefineParams(zeta=2.0)
    p.check()
    assert "_passed" not in repr(p) and "_passed" not in dataclasses.asdict(p)
    assert "_passed" not in {f.name for f in dataclasses.fields(p)} and p == native.RefineParams(zeta=2.0)
    checks = []
    inner = native.RefineParams._check
    monkeypatch.setattr(native.RefineParams, "_check", lambda q: checks.append(1) or inner(q))
    for q in (copy.copy(p), copy.deepcopy(p), pickle.loads(pickle.dumps(p))):
        assert q == p
        q.check()
        assert checks == []
        q.zeta = float("inf")
        with pytest.raises(WavemeshError, match="--zeta inf is out of range"):
            q.check()
        checks.clear()
    with pytest.raises(WavemeshError, match="--zeta nan is out of range"):
        dataclasses.replace(p, zeta=float("nan")).check()
    dataclasses.replace(p, zeta=3.0).check()
    assert len(checks) == 2


def test_params_check_passes_once_until_a_field_is_assigned(monkeypatch):
    """RefineParams.check runs its checks once for an object that passes them and again after any field is
    assigned.  Every field given alone, and in pairs, good, bad, at its bounds and of odd types: asked twice,
    the same answer (passed, or the same error), the second asking of a pass without the checks; and each
    field assigned on an object that passed answers as a new object with that field."""
    import itertools

    import numpy as np
    from wavemesh.errors import WavemeshError

    num = [0, 0.0, 0.5, 1, 1.0, 2, -1, -0.0, 1e-300, 65535, 65535.99, 65536, 1e300, float("inf"),
           float("-inf"), float("nan"), True, False, np.float64(0.5), np.int32(2), np.float32(1.5)]
    whole = [None, 0, 1, 2, 3, 4, -1, 2**31 - 1, 2**31, 2.0, 1.5, True, np.int64(5)]
    values = {name: num for name in ("zeta", "delta_d", "delta_v", "delta_lambda", "delta_c", "delta_p",
                                     "alpha")}
    values |= {"iterations": [v for v in whole if v is not None], "max_triangles": whole, "capacity": whole,
               "metric": ["normal", "vertical", "x", None], "neighbourhood": ["face", "vertex", "", 1]}

    def answer(p):
        try:
            p.check()
        except (WavemeshError, TypeError) as e:
            return type(e).__name__, str(e), e.hint if isinstance(e, WavemeshError) else None
        return "ok"

    cases = [{n: v} for n, vs in values.items() for v in vs]
    cases += [{a: u, b: w} for (a, us), (b, ws) in itertools.combinations(values.items(), 2)
              for u in us[::3] for w in ws[::3]]
    checks = []
    inner = native.RefineParams._check
    monkeypatch.setattr(native.RefineParams, "_check", lambda p: checks.append(1) or inner(p))
    first, again = [], []
    for kw in cases:
        p = native.RefineParams(**kw)
        first.append(answer(p))
        again.append(answer(p))
    assert again == first
    assert first.count("ok") > len(cases) // 10 and first.count("ok") < len(cases)
    assert len(checks) == 2 * len(cases) - first.count("ok")
    for kw, want in zip(cases, first, strict=True):
        if len(kw) == 1:
            p = native.RefineParams()
            assert answer(p) == "ok"
            (name, v), = kw.items()
            setattr(p, name, v)
            assert answer(p) == want, kw
