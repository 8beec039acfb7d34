"""The firmware refiner, loaded natively through ctypes.

The C library (``firmware/``, built by CMake into ``build/firmware-native``) is the same source that
will run on the soft CPU.  :func:`load` builds it on first use and again whenever a source is newer
than the library (so a fresh clone needs nothing but cmake and a C compiler); ``WAVEMESH_FIRMWARE_LIB``
names a prebuilt library instead.

:func:`refine` takes a height field's 16-bit samples, the filter bank's details (as
:mod:`wavemesh.model.haar` computes them: the hardware will hand over exactly these), the initial
triangulation and the parameters, and returns the mesh of every resolution level with the
library's statistics.  Parameters are converted to the library's fixed-point formats here, each
with the rounding docs/refiner.md states (exactly, through :class:`fractions.Fraction`).
"""

from __future__ import annotations

import ctypes
import os
import re
from dataclasses import field
from fractions import Fraction
from math import floor
from operator import attrgetter
from pathlib import Path

import numpy as np

from wavemesh.errors import WavemeshError
from wavemesh.limits import HEADER_TEXT, MAX_SIDE, STAT_FIELDS  # wavemesh.h's text, WM_MAX_SIDE; the stats
from wavemesh.mesh import Mesh
from wavemesh.model.haar import HaarLevel
from wavemesh.record import record

ROOT = Path(__file__).resolve().parents[3]
FIRMWARE = ROOT / "firmware"
BUILD = ROOT / "build" / "firmware-native"
GEN = ROOT / "build" / "gen"  # the generated headers (wavemesh.device.gen): fixed.c's wm_angle.h
LIB_NAME = "libwavemesh.so"

WM_OK, WM_ERR_CAPACITY = 0, -3  # wavemesh.h's (tests/host/test_native_abi.py); the texts: wm_strerror
METRICS = {"normal": 0, "vertical": 1}
NEIGHBOURHOODS = {"face": 0, "vertex": 1}
U32 = (1 << 32) - 1
U64 = (1 << 64) - 1
_INF = float("inf")


class NativeError(WavemeshError):
    """The library could not be built or loaded, or it returned an error code."""


# HEADER_TEXT (wavemesh.h, read once by wavemesh.limits): the one statement of the structures the library
# takes
_C_TYPES = {"int32_t": ctypes.c_int32, "uint32_t": ctypes.c_uint32, "uint64_t": ctypes.c_uint64,
            "const uint16_t *": ctypes.POINTER(ctypes.c_uint16),
            "const int32_t *": ctypes.POINTER(ctypes.c_int32),
            "const uint8_t *": ctypes.POINTER(ctypes.c_uint8)}


def c_struct(name: str, header: str | None = None) -> list[tuple[str, object]]:
    """The ctypes fields of ``typedef struct NAME { ... } NAME;`` in wavemesh.h: (member, type), in order.
    The structures below are made from the header, so a member added there is one here too (their sizes
    are checked against the library's wm_abi_size when it loads)."""
    text = HEADER_TEXT if header is None else header
    body = re.search(rf"typedef struct {name} \{{(.*?)\}} {name};", text, re.S).group(1)
    body = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    out = []
    for decl in filter(None, (" ".join(d.split()) for d in body.split(";"))):
        m = re.fullmatch(r"((?:const )?u?int(?:8|16|32|64)_t)\s*(\*?)\s*(.*)", decl)
        ctype = _C_TYPES[m.group(1) + (" *" if m.group(2) else "")]
        out += [(n.strip(), ctype) for n in m.group(3).split(",")]
    return out


class Params(ctypes.Structure):
    _fields_ = c_struct("wm_params")  # the refiner's parameters (fixed_params fills them)


class Field(ctypes.Structure):
    _fields_ = c_struct("wm_field")  # samples, details, the validity mask (a bit per sample, set: invalid)


class _FieldAt(ctypes.Structure):
    """wm_field with its pointers as addresses (ints), for refine's Field (Field.from_buffer of it: a third
    of the time of two data_as pointers)."""

    _fields_ = [(n, ctypes.c_void_p if issubclass(t, ctypes._Pointer) else t) for n, t in Field._fields_]


# wm_params.flags (WM_FLAG_* in wavemesh.h); 0 is the default pipeline.
FLAG_NO_BOUND, FLAG_NO_LEGALISE, FLAG_NO_DECIMATE, FLAG_NO_REDUCE = 1, 2, 4, 8


class LevelStats(ctypes.Structure):
    _fields_ = [(name, ctypes.c_int32) for name in STAT_FIELDS] + [
        ("e_max", ctypes.c_uint32),
        ("removals", ctypes.c_int32),
    ]

    def to_dict(self) -> dict:
        return {name: int(getattr(self, name)) for name in STAT_FIELDS} | {"e_max_q16": int(self.e_max),
                                                                          "removals": int(self.removals)}


# ---------------------------------------------------------------------------------------------
# Building and loading


def _stale(lib: Path) -> bool:
    """The library is missing or older than a source of it (every run asks: os.scandir, no sorting)."""
    try:
        built = os.stat(lib).st_mtime
    except OSError:
        return True
    for d in ("src", "include", "host"):
        with os.scandir(FIRMWARE / d) as entries:
            if any(e.name.endswith((".c", ".h")) and e.stat().st_mtime > built for e in entries):
                return True
    try:
        if os.stat(GEN / "wm_angle.h").st_mtime > built:
            return True
    except OSError:
        return True
    return any(os.stat(FIRMWARE / name).st_mtime > built for name in ("CMakeLists.txt", "sources.cmake"))


def build(build_dir: Path = BUILD, build_type: str = "Release", extra: tuple[str, ...] = (),
          targets: tuple[str, ...] = ("wavemesh_shared",)) -> Path:
    """Write fixed.c's generated build/gen/wm_angle.h, configure (once) and build the firmware with CMake
    into build_dir; returns build_dir."""
    import fcntl  # building is rare: a run that only loads the library does not import these
    import shutil  # as fcntl

    from wavemesh.device import cordic  # as fcntl

    cmake = shutil.which("cmake")
    if cmake is None:
        raise NativeError("cannot build the firmware library: cmake is not installed",
                          hint="run `make setup`")
    build_dir.mkdir(parents=True, exist_ok=True)
    with open(build_dir / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # concurrent first uses build once
        try:
            cordic.write(GEN)  # fixed.c's wm_angle.h (rewritten only when its text changes)
            if not (build_dir / "CMakeCache.txt").exists():
                _run([cmake, "-S", str(FIRMWARE), "-B", str(build_dir), f"-DCMAKE_BUILD_TYPE={build_type}",
                      *extra])
            _run([cmake, "--build", str(build_dir), "-j", str(min(4, os.cpu_count() or 1)), "--target",
                  *targets])
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    return build_dir


def _run(cmd: list[str]) -> None:
    import subprocess  # start-up: a build only (subprocess: about 3 ms)

    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        tail = (r.stdout + r.stderr).strip().splitlines()[-15:]
        raise NativeError("building the firmware library failed:\n" + "\n".join(tail),
                          hint="run `make firmware` to see the whole build")


_LIB: ctypes.CDLL | None = None


def load() -> ctypes.CDLL:
    """The firmware library, built first when it is missing or older than its sources."""
    global _LIB
    if _LIB is not None:
        return _LIB
    override = os.environ.get("WAVEMESH_FIRMWARE_LIB")
    if override:
        path = Path(override)
    else:
        path = BUILD / LIB_NAME
        if _stale(path):
            build()
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as e:
        raise NativeError(f"cannot load the firmware library {path}: {e}") from None
    _declare(lib)
    for which, cls in ((0, Params), (1, Field), (2, LevelStats)):
        if lib.wm_abi_size(which) != ctypes.sizeof(cls):
            raise NativeError(f"{path} does not match native.py ({cls.__name__} layout); rebuild it")
    _LIB = lib
    return lib


def _declare(lib: ctypes.CDLL) -> None:
    i32, u32, sz, vp = ctypes.c_int32, ctypes.c_uint32, ctypes.c_size_t, ctypes.c_void_p
    pi32, pi64 = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_int64)
    i64, pf64, pu16 = ctypes.c_int64, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_uint16)
    pf32 = ctypes.POINTER(ctypes.c_float)
    sig = {
        "wm_abi_size": (sz, [ctypes.c_int]),
        "wm_strerror": (ctypes.c_char_p, [ctypes.c_int]),
        "wm_refine_bound": (sz, [i32, i32, i32]),
        "wm_tri_cap_max": (i32, [i32, i32]),
        # the arrays refine passes by address (an int: a.ctypes.data, half data_as's time; a ctypes pointer
        # still converts)
        "wm_refine_init": (ctypes.c_int, [ctypes.POINTER(vp), vp, sz, ctypes.POINTER(Field),
                                          ctypes.POINTER(Params),
                                          vp, i32, vp, i32, i32]),
        "wm_refine_set_roi": (ctypes.c_int, [vp, pi32]),
        "wm_refine_step": (ctypes.c_int, [vp, ctypes.POINTER(LevelStats)]),
        "wm_refine_stats": (None, [vp, ctypes.POINTER(LevelStats)]),
        "wm_refine_done": (ctypes.c_int, [vp]),
        "wm_refine_mesh": (vp, [vp]),
        "wm_mesh_export": (i32, [vp, vp, vp]),
        "wm_tri_error": (u32, [ctypes.POINTER(Field), ctypes.POINTER(Params), pi32, pi32, pi32, pi32]),
        "wm_haar": (ctypes.c_int, [ctypes.POINTER(ctypes.c_uint16), i32, i32, i32, pi32,
                                   ctypes.POINTER(ctypes.c_uint16)]),
        "wm_details_size": (ctypes.c_int64, [i32, i32, i32]),
        "wm_haar_scratch": (ctypes.c_int64, [i32, i32]),
        "wm_spline": (ctypes.c_int, [ctypes.POINTER(ctypes.c_uint16), i32, i32, i32, pi32,
                                     ctypes.POINTER(ctypes.c_uint16)]),
        "wm_spline_scratch": (ctypes.c_int64, [i32, i32]),
        "wm_host_quantise": (ctypes.c_int, [pf64, i64, i32, pu16, pf64, pi32]),
        "wm_host_quant_error": (ctypes.c_double, [pf64, pu16, i64, ctypes.c_double, ctypes.c_double, i32]),
        "wm_host_quantise_with": (ctypes.c_double, [pf64, i64, ctypes.c_double, ctypes.c_double, i32, i32,
                                                    pu16]),
        "wm_host_tri_max": (ctypes.c_int, [pf64, i32, i32, pi64, pi64, pf64, pi64, i64, pf64, pf64,
                                           ctypes.c_double, ctypes.c_double, i32]),
        "wm_host_quantise_with32": (ctypes.c_double, [pf32, i64, i64, i64, ctypes.c_double, ctypes.c_double,
                                                      i32, i32, pu16]),
        "wm_host_tri_max32": (ctypes.c_int, [pf32, i32, i32, i64, pi64, pi64, pf64, pi64, i64, pf64, pf64,
                                             ctypes.c_double, ctypes.c_double, i32]),
        "wm_host_check_mesh": (ctypes.c_int, [i64, i64, pi64, i64, pi64, i64, i32, pi64]),
        "wm_host_part_min": (i64, [i64]),
        "wm_host_scan": (i32, [i32]),
        "wm_host_obj_faces": (i64, [pi64, i64, ctypes.c_char_p]),
        "wm_host_obj_vertices": (i64, [pi64, pf64, i64, ctypes.c_char_p, pi64, pi64]),
        "wm_host_refine_levels": (i32, [vp, i32, vp, i32, vp, i64, pi32, pi32]),
    }
    for name, (res, args) in sig.items():
        fn = getattr(lib, name)
        fn.restype = res
        fn.argtypes = args


def error_text(code: int) -> str:
    """The library's own text for one of its error codes (wm_strerror)."""
    return load().wm_strerror(code).decode("ascii", "replace")


# ---------------------------------------------------------------------------------------------
# Parameters


@record
class RefineParams:
    """Table 4.3's parameters in user units (height units, grid steps), dissertation defaults.

    delta_lambda and delta_c drive the reduction of steps 2(d) and 3(b) (vertex removal 4.32, edge
    collapse 4.33-4.34); ``reduce=False`` turns it off.
    """

    zeta: float = 1.0  # E(T) <= zeta at level 0, height units (5.3: 1 unit synthetic, 2 m terrain)
    metric: str = "normal"  # "normal" (the dissertation's) or "vertical"
    delta_d: float = 0.1  # detail energy threshold: per sample, over zeta squared (4.12)
    delta_p: float = 0.9  # pairing criterion, 0.5 < delta_p < 1
    delta_v: float = 2.0  # vertex movement threshold, 3-D distance (grid steps and height units)
    alpha: float = 0.6  # mesh regularity factor, 0..1 (5.2.3: "most of the later experiments")
    delta_lambda: float = 0.01  # vertex removal criterion, eigenvalues of R(v) (4.32)
    delta_c: float = 0.98  # edge collapsing criterion, |e21 . e22| > delta_c (4.34), 0..1
    iterations: int = 1  # k, 1..3 (0: only the error bound); 1 measured best (docs/refiner.md)
    neighbourhood: str = "face"  # "face" (5.2.2) or "vertex"
    bound: bool = True  # the error bound at level 0 (False: the dissertation's levels alone)
    legalise: bool = True  # Lawson flips after each split of the error bound
    decimate: bool = True  # the final decimation within zeta after the error bound
    reduce: bool = True  # vertex removal and edge collapse at 2(d) and 3(b)
    max_triangles: int | None = None  # triangle budget
    capacity: int | None = None  # triangle storage, as on a device (default: 2 (W-1)(H-1), never short)
    extra: dict = field(default_factory=dict)

    _passed = False  # check passed, and no field was assigned since (__setattr__)
    _fixed_key = None  # the fields fixed_params reads, once per state (None: not made since an assignment)

    def __setattr__(self, name, value):
        object.__setattr__(self, "_passed", False)
        object.__setattr__(self, "_fixed_key", None)
        object.__setattr__(self, name, value)

    def check(self) -> None:
        """WavemeshError (the option, a hint) when a field is out of its range.  The checks run once for an
        object that passes them, and again after any assignment to it (a refine call checks its parameters
        inside its time: 0.05 us, where the checks take 1.5)."""
        if self._passed:
            return
        self._check()
        object.__setattr__(self, "_passed", True)

    def _check(self) -> None:
        def bad(name, value, want):
            raise WavemeshError(f"--{name.replace('_', '-')} {value} is out of range", hint=want)

        for name in ("zeta", "delta_d", "delta_v", "delta_lambda", "delta_c", "delta_p", "alpha"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0 <= v < _INF):  # NaN and infinities too
                bad(name, v, "give a finite number >= 0")
        if not 0 <= self.delta_p < 1:
            bad("delta_p", self.delta_p, "use 0 <= delta_p < 1 (the dissertation: 0.5 < delta_p < 1)")
        if not 0 <= self.alpha <= 1:
            bad("alpha", self.alpha, "use 0 <= alpha <= 1")
        if not 0 <= self.delta_c <= 1:
            bad("delta_c", self.delta_c, "use 0 <= delta_c <= 1")
        if self.delta_lambda >= 65536:
            bad("delta_lambda", self.delta_lambda, "use 0 <= delta_lambda < 65536 (eigenvalues are in 0..1)")
        if self.metric not in METRICS:
            bad("metric", self.metric, "use normal or vertical")
        if self.neighbourhood not in NEIGHBOURHOODS:
            bad("neighbourhood", self.neighbourhood, "use face or vertex")
        if not 0 <= self.iterations <= 3:
            bad("iterations", self.iterations, "use 0..3 (the dissertation: 1..3)")
        if self.max_triangles is not None and not 2 <= self.max_triangles < 2**31:
            bad("max_triangles", self.max_triangles, "use at least 2")
        if self.capacity is not None and not 2 <= self.capacity < 2**31:
            bad("capacity", self.capacity, "use at least 2")

    def to_report(self) -> dict:
        return {k: getattr(self, k) for k in ("zeta", "metric", "delta_d", "delta_p", "delta_v", "alpha",
                                              "delta_lambda", "delta_c", "iterations", "neighbourhood",
                                              "max_triangles", "capacity", "bound", "reduce")}


def scale_fixed(scale: float | Fraction) -> tuple[int, int]:
    """s = m / 2^e, rounded down, m < 2^16 (in 2^15..2^16-1 unless s is out of range), e in 0..126."""
    exact = scale if hasattr(scale, "as_integer_ratio") else Fraction(scale)
    n, d = map(int, exact.as_integer_ratio())  # numpy's are numpy integers
    if n <= 0:
        raise ValueError("the height scale must be positive")
    if n >= 65535 * d:
        return 65535, 0  # smaller than s: conservative (the normal factor is estimated too large)
    # e: the least e >= 0 with s 2^e >= 2^15, at most 126, from the bit lengths (in integers: the refine
    # call runs this three times, and a Fraction loop cost 0.1 ms each)
    t = d << 15
    e = max(0, t.bit_length() - n.bit_length())
    while e > 0 and n << (e - 1) >= t:
        e -= 1
    while n << e < t:
        e += 1
    e = min(e, 126)
    return (n << e) // d, e


_FIXED: dict = {}  # fixed_params' answers by its arguments (a tiled run asks 8 times a tile, the same)
# every field _fixed_params reads: its cache key, made once per state of a RefineParams (_fixed_key)
_fixed_fields = attrgetter("zeta", "metric", "delta_d", "delta_p", "delta_v", "alpha", "delta_lambda",
                           "delta_c", "iterations", "neighbourhood", "bound", "legalise", "decimate",
                           "reduce", "max_triangles")


def fixed_params(p: RefineParams, scale: float, zeta: float | None = None,
                 spacing: tuple[float, float] = (1.0, 1.0)) -> Params:
    """The library's wm_params for p, the height scale and the cell size ``spacing`` = (dx, dy), the
    ground distance between neighbouring samples in height units (docs/refiner.md, "Fixed-point
    formats").  Each answer is kept (by the values of the fields it reads, equal values giving equal
    answers, and the other arguments: about 0.1 ms of Fraction arithmetic each) and a copy of it returned.
    The fields' values are read once per state of p (RefineParams.__setattr__ drops them)."""
    values = p._fixed_key
    if values is None:
        values = _fixed_fields(p)
        object.__setattr__(p, "_fixed_key", values)
    key = (values, scale, zeta, tuple(spacing))
    out = _FIXED.get(key)
    if out is None:
        if len(_FIXED) >= 64:
            _FIXED.clear()
        _FIXED[key] = out = _fixed_params(p, scale, zeta, spacing)
    return Params.from_buffer_copy(out)


def _fixed_params(p: RefineParams, scale: float, zeta: float | None, spacing: tuple[float, float]) -> Params:
    s = Fraction(scale)
    z = Fraction(p.zeta if zeta is None else zeta)
    m, e = scale_fixed(scale)
    out = Params()
    out.metric = METRICS[p.metric]
    out.neighbourhood = NEIGHBOURHOODS[p.neighbourhood]
    out.iterations = p.iterations
    out.max_triangles = p.max_triangles or 0
    # rounded down: conservative; below 0xFFFFFFFF, the E(T) of a triangle over valid and invalid samples
    # (firmware/src/holes.c), which must stay above zeta; no measured E(T) comes near (16-bit samples:
    # E(T) <= 0xFFFF0000), so only a mask sees the difference
    out.zeta = max(0, min(U32 - 1, floor(z / s * 2**16)))
    out.scale_m, out.scale_e = m, e
    out.delta_p = min(65535, round(Fraction(p.delta_p) * 2**16))
    out.alpha = min(65536, round(Fraction(p.alpha) * 2**16))
    out.delta_v = min(U32, round(Fraction(p.delta_v) * 2**16))
    out.flags = ((0 if p.bound else FLAG_NO_BOUND) | (0 if p.legalise else FLAG_NO_LEGALISE)
                 | (0 if p.decimate else FLAG_NO_DECIMATE) | (0 if p.reduce else FLAG_NO_REDUCE))
    # delta_d is the detail's energy per sample over zeta squared (docs/refiner.md, "Region selection"):
    # e = d1^2 + d2^2 + d3^2 in coefficient units, (d / 2) s is a half-block mean difference D, and the
    # orthonormal details' energy per sample of the square is sum D^2 / 4 at every level, so
    # e (s / 2)^2 / 4 > delta_d zeta^2  <=>  e > 16 delta_d zeta^2 / s^2, rounded down (e an integer).
    out.delta_d = min(U64, floor(16 * Fraction(p.delta_d) * z * z / (s * s)))
    out.delta_lambda = min(U32, round(Fraction(p.delta_lambda) * 2**16))  # Q16.16, as CONFIG carries it
    out.delta_c = min(65536, round(Fraction(p.delta_c) * 2**16))
    # The normal metric's slope scales s / dx, s / dy, rounded down as s (a smaller slope: conservative);
    # never 0, which the library reads as a cell of 1.
    (out.slope_x_m, out.slope_x_e), (out.slope_y_m, out.slope_y_e) = (
        _nonzero(scale_fixed(s / Fraction(d))) for d in spacing)
    return out


def _nonzero(me: tuple[int, int]) -> tuple[int, int]:
    # below 2^-126 the slope term is 0 in every Q16.16 product either way
    return me if me[0] else (1, 126)


# ---------------------------------------------------------------------------------------------
# Running


def details_array(levels: list[HaarLevel]) -> np.ndarray:
    """wavemesh.model.haar's levels 1..M as the library's layout: per level, cells row by row, (d1, d2,
    d3)."""
    parts = [np.stack([lv.d1, lv.d2, lv.d3], axis=-1).astype(np.int32).ravel() for lv in levels]
    return np.ascontiguousarray(np.concatenate(parts) if parts else np.zeros(0, np.int32), dtype=np.int32)


def _ptr(a: np.ndarray, ctype):
    return a.ctypes.data_as(ctypes.POINTER(ctype))


def _addr(a: np.ndarray) -> int:
    """The address of a contiguous array's data: through a ctypes view of its buffer (0.4 us where
    a.ctypes.data takes 0.8 to 1.8), or a.ctypes.data for a read-only or empty one."""
    try:
        return ctypes.addressof(ctypes.c_char.from_buffer(a))
    except (TypeError, ValueError):
        return a.ctypes.data


class Level:
    """One resolution level's mesh and the library's statistics for it.  The Mesh is made from the
    exported slot arrays when first read: a refine call exports every level (the library's mesh moves
    on), and most callers read only the final one (0.1 ms a call on a 128 x 128 grid); the statistics
    likewise become a dict when first read (until then a view of the statistics array the library filled)."""

    def __init__(self, level: int, mesh: Mesh | tuple, stats: dict | LevelStats):
        self.level, self._stats, self._mesh = level, stats, mesh

    @property
    def stats(self) -> dict:
        if isinstance(self._stats, LevelStats):
            self._stats = self._stats.to_dict()
        return self._stats

    @stats.setter
    def stats(self, stats: dict) -> None:
        self._stats = stats

    @property
    def mesh(self) -> Mesh:
        if isinstance(self._mesh, tuple):  # (width, height, slots, vertex slots) as refine's export gave them
            width, height, buf, vert_end = self._mesh  # buf: this level's slots, vertices then triangles
            self._mesh = Mesh.from_slots(width, height, buf[: 2 * vert_end], buf[2 * vert_end :])
        return self._mesh

    @mesh.setter
    def mesh(self, mesh: Mesh) -> None:
        self._mesh = mesh


@record
class RefineOutput:
    levels: list[Level]  # from the initial triangulation (level M-1) down to level 0
    capacity: int  # the triangle storage used
    params: Params

    def __init__(self, levels: list[Level], capacity: int, params: Params):  # record's, without its loops
        self.levels, self.capacity, self.params = levels, capacity, params

    @property
    def final(self) -> Level:
        return self.levels[-1]


_EXPORT_ROOM = 1 << 14  # int32s: the least array _run_once's exports start in
_EXPORT_AHEAD = 8  # and at least room for this many exports of the initial mesh's size
_STATS_SIZE = ctypes.sizeof(LevelStats)


def refine(samples: np.ndarray, levels: list[HaarLevel] | int, initial: Mesh, params: RefineParams,
           scale: float = 1.0, zeta: float | None = None,
           spacing: tuple[float, float] = (1.0, 1.0), roi: np.ndarray | None = None,
           mask: np.ndarray | None = None, wavelet: str = "haar", details: np.ndarray | None = None
           ) -> RefineOutput:
    """Run the firmware refiner; returns every level's mesh (initial first) and statistics.

    ``levels``: the details (wavemesh.model.haar.decompose's), or their number M, and then the library's own
    filter bank for ``wavelet`` makes them (haar_details: equal to decompose's, tests/firmware/test_error.py,
    in a tenth of the time).

    ``zeta`` overrides params.zeta (the host tightens it for lossy quantisation); ``spacing`` is the
    cell size (dx, dy) the normal metric measures slopes with (fixed_params).  Without an
    explicit capacity the storage is sized once for the most triangles any triangulation of the grid
    can have, 2 (W-1) (H-1): the refiner never runs out and runs once.  The library touches only the
    slots it uses, so the operating system commits only those pages of the (lazily mapped) buffer.
    ``roi``: an (H, W) bool region of interest E(T) keeps to (wm_refine_set_roi; wavemesh.model.roi).
    """
    params.check()
    lib = load()
    samples = np.ascontiguousarray(samples, dtype=np.uint16)
    height, width = samples.shape
    if width > MAX_SIDE or height > MAX_SIDE:
        raise WavemeshError(f"the grid is {width} x {height}; the refiner takes at most {MAX_SIDE} per side",
                            hint="crop or subsample the height field, or use --stage initial")
    count = isinstance(levels, (int, np.integer))
    if count:  # ``details``: haar_details' already made (the initial triangulation's)
        det = details if details is not None else haar_details(samples, int(levels), wavelet)
    else:
        det = details_array(levels)
    m = int(levels) if count else len(levels)
    fld = Field.from_buffer(_FieldAt(width, height, m, _addr(samples), _addr(det)))
    if mask is not None:  # ``mask``: (H, W) bool, True where invalid (wavemesh.refine.cover; wm_field.mask)
        from wavemesh.model.holemask import pack  # holes are asked for: imported only then

        bits = np.frombuffer(pack(mask), dtype=np.uint8)
        fld.mask = _ptr(bits, ctypes.c_uint8)
    fp = fixed_params(params, scale, zeta, spacing)
    xy = np.ascontiguousarray(initial.xy, dtype=np.int32)
    tris = np.ascontiguousarray(initial.tris, dtype=np.int32)
    cap, nbytes = _sizes(lib, width, height, params.capacity)
    rows = None if roi is None else roi_rows(roi)
    out, code = _run_once(lib, fld, fp, xy, tris, cap, nbytes, width, height, rows)
    if code != WM_OK:
        what = error_text(code)
        if code == WM_ERR_CAPACITY:
            raise WavemeshError(f"refiner: {what} (storage for {cap} triangles)",
                                hint="raise --capacity or set --max-triangles")
        raise WavemeshError(f"refiner: {what}")
    return RefineOutput(out, cap, fp)


_SIZES: dict = {}  # _sizes' answers by its arguments


def _sizes(lib, width: int, height: int, capacity: int | None) -> tuple[int, int]:
    """The triangle capacity (``capacity``, or by default wm_tri_cap_max's) and the refiner's storage in
    bytes for it (wm_refine_bound's), each kept by the library and the arguments (two ctypes calls fewer
    a refine call)."""
    key = (lib, width, height, capacity)
    out = _SIZES.get(key)
    if out is None:
        if len(_SIZES) >= 64:
            _SIZES.clear()
        cap = capacity if capacity is not None else lib.wm_tri_cap_max(width, height)
        _SIZES[key] = out = (cap, lib.wm_refine_bound(width, height, cap))
    return out


def _run_once(lib, fld, fp, xy, tris, cap, nbytes, width, height, rows=None) -> tuple[list[Level], int]:
    if nbytes == 0:
        return [], -1
    # malloc: large blocks are mapped lazily, in transparent huge pages where the system makes them.  The
    # refiner touches the start of each of its tables (sized for the most triangles the grid can have),
    # so a small mesh has the kernel clear 2 MiB pages it hardly uses (26 MiB at 2048^2 for 8k triangles);
    # small pages (madvise MADV_NOHUGEPAGE) saved that but cost a large mesh its TLB reach: 4 % of
    # api.mesh's CPU on Jacksboro mirror-tiled to 2048^2 (1.26M triangles), so huge pages stay.
    mem = np.empty(nbytes + 16, dtype=np.uint8)
    addr = _addr(mem)
    handle = ctypes.c_void_p()
    code = lib.wm_refine_init(ctypes.byref(handle), addr + (-addr) % 16, nbytes, ctypes.byref(fld),
                              ctypes.byref(fp), _addr(xy), len(xy), _addr(tris), len(tris), cap)
    if code == WM_OK and rows is not None:
        code = lib.wm_refine_set_roi(handle, _ptr(rows, ctypes.c_int32))
    if code != WM_OK:
        return [], code
    # The steps and each level's export in C (wm_host_refine_levels: one call, not a step, an export and
    # their Python objects a level), into one array while it has room: every level's statistics (the
    # refiner's levels count down from fld.levels - 1 to 0, two levels for one), and after a call that
    # ran out of room the level it left pending in a larger one.
    hdr = (ctypes.c_int32 * 8).from_address(lib.wm_refine_mesh(handle))  # wm_mesh's head: vert_end, n_tri
    n_stats = fld.levels + 2
    stats = (LevelStats * n_stats)()
    sizes = (ctypes.c_int32 * (2 * n_stats))()
    said = ctypes.c_int32()
    room = max(_EXPORT_ROOM, _EXPORT_AHEAD * (2 * hdr[5] + 3 * hdr[6]))
    levels, first, mode, base = [], 0, 1, ctypes.addressof(stats)
    while True:
        buf = np.empty(room, dtype=np.int32)
        k = lib.wm_host_refine_levels(handle, mode, base + first * _STATS_SIZE, n_stats - first, _addr(buf),
                                      room, sizes, ctypes.byref(said))
        at = 0
        for i in range(k):
            vert_end = sizes[2 * i]
            end = at + 2 * vert_end + 3 * sizes[2 * i + 1]
            st = stats[first + i]
            levels.append(Level(st.level, (width, height, buf[at:end], vert_end), st))
            at = end
        code = said.value
        if code > 1:  # 2: no room in stats, sized for every level the refiner makes (a bug, if ever)
            raise NativeError(f"wm_host_refine_levels returned the unexpected code {code} (levels exported: "
                              f"{first + k}, room for statistics: {n_stats})")
        if code != 1:  # done (0), or a step's error
            break
        first, mode = first + k, 0
        room = max(2 * room, 4 * (2 * hdr[5] + 3 * hdr[6]))
    del mem
    return levels, code


def roi_rows(roi: np.ndarray) -> np.ndarray:
    """wm_refine_set_roi's table for an (H, W) bool ROI: (H, W + 1) int32, each row's count of ROI
    samples left of every column."""
    h, w = roi.shape
    out = np.zeros((h, w + 1), dtype=np.int32)
    np.cumsum(roi, axis=1, out=out[:, 1:])
    return out


def tri_error(samples: np.ndarray, x, y, metric: str = "normal", scale: float = 1.0,
              spacing: tuple[float, float] = (1.0, 1.0)) -> float:
    """The library's E(T) of one triangle, in height units (an upper bound; docs/refiner.md)."""
    lib = load()
    samples = np.ascontiguousarray(samples, dtype=np.uint16)
    height, width = samples.shape
    fld = Field(width, height, 1, _ptr(samples, ctypes.c_uint16), None)
    fp = fixed_params(RefineParams(metric=metric), scale, spacing=spacing)
    xs = (ctypes.c_int32 * 3)(*map(int, x))
    ys = (ctypes.c_int32 * 3)(*map(int, y))
    q = lib.wm_tri_error(ctypes.byref(fld), ctypes.byref(fp), xs, ys, None, None)
    return q / 65536 * scale


def error_within(samples: np.ndarray, fp: Params):
    """A test ``within(x, y)``: the library's E(T) of the triangle (counter-clockwise corner columns x and
    rows y) with the run's fixed-point parameters ``fp`` is at most its zeta (cover.simplify_rims)."""
    lib = load()
    samples = np.ascontiguousarray(samples, dtype=np.uint16)
    height, width = samples.shape
    fld = Field(width, height, 1, _ptr(samples, ctypes.c_uint16), None)

    def within(x, y) -> bool:
        xs = (ctypes.c_int32 * 3)(*x)
        ys = (ctypes.c_int32 * 3)(*y)
        return lib.wm_tri_error(ctypes.byref(fld), ctypes.byref(fp), xs, ys, None, None) <= fp.zeta

    within.samples = samples  # kept alive with the test
    return within


def haar_details(samples: np.ndarray, levels: int, wavelet: str = "haar") -> np.ndarray:
    """The C filter bank's details (the layout of details_array): wm_haar, or wm_spline for the spline
    wavelet (the native device's filter banks); refine's when it is given the number of levels."""
    lib = load()
    spline = wavelet == "spline"
    bank, size = (lib.wm_spline, lib.wm_spline_scratch) if spline else (lib.wm_haar, lib.wm_haar_scratch)
    samples = np.ascontiguousarray(samples, dtype=np.uint16)
    height, width = samples.shape
    out = np.empty(lib.wm_details_size(width, height, levels), dtype=np.int32)
    scratch = np.empty(max(2, size(width, height)), dtype=np.uint32).view(np.uint16)  # 4-byte aligned
    code = bank(_ptr(samples, ctypes.c_uint16), width, height, levels, _ptr(out, ctypes.c_int32),
                _ptr(scratch, ctypes.c_uint16))
    if code != WM_OK:
        raise WavemeshError(f"{'wm_spline' if spline else 'wm_haar'}: {error_text(code)}")
    return out


# ---------------------------------------------------------------------------------------------
# The host stages in C (firmware/host, wm_host.h): quantisation, the final check's error measure.
# Each equals its Python model (heightfield.quantise, check.mesh_errors) bit for bit whatever the thread
# count (tests/host/test_host_stages.py); the callers use them when the library loads, else the model.

_THREADS: int | None = None  # set_threads(); None: every core this process may use
_HOST: ctypes.CDLL | None | bool = None  # host_lib()'s answer, once: the library, or False


def cores() -> int:
    """The processors this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def set_threads(n: int | None) -> None:
    """How many threads the host stages use (``wavemesh mesh --threads N``); None: cores()."""
    global _THREADS
    if n is not None and n < 1:
        raise WavemeshError(f"--threads {n} is out of range", hint="use 1 or more (1: one core)")
    _THREADS = n


def threads() -> int:
    return _THREADS if _THREADS is not None else cores()


def threads_set() -> int | None:
    """The count set_threads() was given (``--threads``), or None when none was."""
    return _THREADS


def host_lib() -> ctypes.CDLL | None:
    """The library for the host stages, or None when it cannot be built or loaded (then the callers run
    the Python model; `wavemesh mesh` needs the library anyway and says so)."""
    global _HOST
    if _HOST is None:
        try:
            _HOST = load()
        except WavemeshError:
            _HOST = False
    return _HOST or None


QUANTISE_ERRORS = {1: "non-finite", 2: "span"}


def quantise(values: np.ndarray) -> tuple[np.ndarray, float, float, bool, float, float, float] | str | None:
    """wm_host_quantise on float64 heights: (samples, scale, offset, lossless, max error, least height,
    largest height), or the kind of problem ("non-finite", "span") for the caller's message, or None
    without the library."""
    lib = host_lib()
    if lib is None:
        return None
    v = np.ascontiguousarray(values, dtype=np.float64)
    samples = np.empty(v.shape, dtype=np.uint16)
    out = np.zeros(5, dtype=np.float64)
    lossless = ctypes.c_int32(0)
    # a part whose thread will not start runs on the calling one (host_stages.c's run_parts); code 3, no
    # memory for the passes' state, returns None below: the caller quantises in numpy
    code = lib.wm_host_quantise(_ptr(v, ctypes.c_double), v.size, threads(), _ptr(samples, ctypes.c_uint16),
                                _ptr(out, ctypes.c_double), ctypes.byref(lossless))
    if code in QUANTISE_ERRORS:
        return QUANTISE_ERRORS[code]
    if code != 0:
        return None
    scale, offset, err, lo, hi = (float(x) for x in out)
    return samples, scale, offset, bool(lossless.value), err, lo, hi


def quantise_with(values: np.ndarray, scale: float, offset: float, exact: bool
                  ) -> tuple[np.ndarray, float] | None:
    """wm_host_quantise_with on finite heights (a tile's window) by a scale and offset found before:
    (samples, their largest quantisation error), or None without the library.  float32 heights (2-D) are
    read as they are, a window of a larger grid in place (wm_host_quantise_with32: the same as of their
    float64 copy), others as float64."""
    lib = host_lib()
    if lib is None:
        return None
    values = np.asarray(values)
    if values.dtype == np.float32 and values.ndim == 2:
        v, pitch = _rows(values)
        samples = np.empty(v.shape, dtype=np.uint16)
        err = lib.wm_host_quantise_with32(_ptr(v, ctypes.c_float), v.shape[0], v.shape[1], pitch,
                                          float(offset), float(scale), int(bool(exact)), threads(),
                                          _ptr(samples, ctypes.c_uint16))
        return samples, float(err)
    v = np.ascontiguousarray(values, dtype=np.float64)
    samples = np.empty(v.shape, dtype=np.uint16)
    err = lib.wm_host_quantise_with(_ptr(v, ctypes.c_double), v.size, float(offset), float(scale),
                                    int(bool(exact)), threads(), _ptr(samples, ctypes.c_uint16))
    return samples, float(err)


def _rows(a: np.ndarray) -> tuple[np.ndarray, int]:
    """A 2-D float32 array whose rows are each contiguous, a whole number of samples apart (a window of the
    input's memory map, tiles.source.Source.read's) as it is, with that pitch; any other a contiguous copy."""
    if a.size and a.strides[1] == 4 and a.strides[0] % 4 == 0 and a.strides[0] >= 4 * a.shape[1]:
        return a, a.strides[0] // 4
    return np.ascontiguousarray(a), a.shape[1]


def quant_error(values: np.ndarray, samples: np.ndarray, offset: float, scale: float) -> float | None:
    """max |values - (offset + scale * samples)| (wm_host_quant_error), or None without the library."""
    lib = host_lib()
    if lib is None or values.shape != samples.shape:
        return None
    v = np.ascontiguousarray(values, dtype=np.float64)
    s = np.ascontiguousarray(samples, dtype=np.uint16)
    return float(lib.wm_host_quant_error(_ptr(v, ctypes.c_double), _ptr(s, ctypes.c_uint16), v.size,
                                         float(offset), float(scale), threads()))


def tri_max(heights: np.ndarray, x: np.ndarray, y: np.ndarray, zv: np.ndarray, tris: np.ndarray,
            spacing: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray | None] | None:
    """Per triangle, the largest |height - plane| over the samples in the closed triangle (-inf: none),
    as check.mesh_errors measures it (wm_host_tri_max), and with ``spacing`` (the cell size) the normal
    factors sqrt(1 + a^2 + b^2) it computes (else None); None without the library.  float32 heights are
    read as they are, a window of a larger grid in place (wm_host_tri_max32: the same maxima as of their
    float64 copy), others as float64."""
    lib = host_lib()
    if lib is None:
        return None
    heights = np.asarray(heights)
    single = heights.dtype == np.float32 and heights.ndim == 2
    h, pitch = _rows(heights) if single else (np.ascontiguousarray(heights, dtype=np.float64), 0)
    x, y = np.ascontiguousarray(x, dtype=np.int64), np.ascontiguousarray(y, dtype=np.int64)
    zv = np.ascontiguousarray(zv, dtype=np.float64)
    tris = np.ascontiguousarray(tris, dtype=np.int64)
    out = np.empty(len(tris), dtype=np.float64)
    nfac = None if spacing is None else np.empty(len(tris), dtype=np.float64)
    sx, sy = (1.0, 1.0) if spacing is None else (float(spacing[0]), float(spacing[1]))
    grid = (_ptr(h, ctypes.c_float), h.shape[1], h.shape[0], pitch) if single else \
        (_ptr(h, ctypes.c_double), h.shape[1], h.shape[0])
    (lib.wm_host_tri_max32 if single else lib.wm_host_tri_max)(
        *grid, _ptr(x, ctypes.c_int64), _ptr(y, ctypes.c_int64), _ptr(zv, ctypes.c_double),
        _ptr(tris, ctypes.c_int64), len(tris), _ptr(out, ctypes.c_double),
        None if nfac is None else _ptr(nfac, ctypes.c_double), sx, sy, threads())
    return out, nfac


OBJ_FACE_MAX = 65  # WM_HOST_OBJ_FACE_MAX: the longest "f a b c" line, three int64 indices


def obj_faces(tris: np.ndarray) -> str | None:
    """The OBJ face lines of (T, 3) vertex indices, "f a b c\\n" with each index plus one, as the text
    ``("f %d %d %d\\n" * T) % tuple((tris + 1).ravel().tolist())`` (wm_host_obj_faces; about a tenth of
    its time); None without the library."""
    lib = host_lib()
    if lib is None:
        return None
    t = np.ascontiguousarray(tris, dtype=np.int64)
    buf = _text_buffer(OBJ_FACE_MAX * len(t))
    n = lib.wm_host_obj_faces(_ptr(t, ctypes.c_int64), len(t), buf.ctypes.data_as(ctypes.c_char_p))
    return buf[:n].tobytes().decode("ascii")


def _text_buffer(n: int) -> np.ndarray:
    """n bytes for the C to write text into, not cleared (a ctypes string buffer is: 83 MB for Jacksboro's
    1.27M triangles at 2048^2, 25 ms); only the pages it writes are touched."""
    return np.empty(n + 1, dtype=np.uint8)


OBJ_VERTEX_MAX = 72  # WM_HOST_OBJ_VERTEX_MAX: the longest "v x y z" line it writes


def obj_vertices(xy: np.ndarray, z: np.ndarray) -> str | None:
    """The OBJ vertex lines of (V, 2) integer positions and (V,) heights, "v x y z\n" with z as
    ``repr(float(z))``, as the text ``("v %d %d %r\n" * V) % ...`` (wm_host_obj_vertices; the heights it
    leaves, not finite, or not zero and below 1e-4 or from 2^53 in size, by repr here); None without the
    library."""
    lib = host_lib()
    if lib is None:
        return None
    xy = np.ascontiguousarray(xy, dtype=np.int64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    buf = _text_buffer(OBJ_VERTEX_MAX * len(z))
    left = np.empty(len(z), dtype=np.int64)
    n_left = ctypes.c_int64(0)
    k = lib.wm_host_obj_vertices(_ptr(xy, ctypes.c_int64), _ptr(z, ctypes.c_double), len(z),
                                 buf.ctypes.data_as(ctypes.c_char_p), _ptr(left, ctypes.c_int64),
                                 ctypes.byref(n_left))
    if k < 0:  # a host without 128-bit integers
        return None
    text = buf[:k].tobytes().decode("ascii")
    if not n_left.value:
        return text
    pieces = text.split("\0")  # the heights left, in order
    out = [pieces[0]]
    for r, piece in zip(map(repr, z[left[: n_left.value]].tolist()), pieces[1:], strict=True):
        out += [r, piece]
    return "".join(out)


def check_proper(mesh: Mesh) -> tuple[bool, int] | None:
    """wm_host_check_mesh: (True, B) when ``mesh`` passes every check of check.check_mesh (B: its vertices
    on the border), (False, 0) when one fails; None when the C check cannot decide cheaply or the
    library is missing (then check_mesh's Python decides, and says what is wrong)."""
    lib = host_lib()
    if lib is None:
        return None
    xy = np.ascontiguousarray(mesh.xy, dtype=np.int64)
    tris = np.ascontiguousarray(mesh.tris, dtype=np.int64)
    border = ctypes.c_int64(0)
    code = lib.wm_host_check_mesh(int(mesh.width), int(mesh.height), _ptr(xy, ctypes.c_int64), len(xy),
                                  _ptr(tris, ctypes.c_int64), len(tris), threads(), ctypes.byref(border))
    return None if code < 0 else (code == 1, int(border.value))
