"""The job library both devices run (firmware/board/include/wm_job.h, src/wm_job.c) against the reference
model: its labels and template entries against wavemesh.model.label, its initial triangulation against
wavemesh.model.initial, element for element, and its staging inside the caller's storage."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wavemesh.device import memmap
from wavemesh.harness.nativedev import build_wmdev
from wavemesh.io import synth
from wavemesh.model.haar import HaarLevel, decompose
from wavemesh.model.initial import assemble, initial_triangulation
from wavemesh.model.label import TAU_MAX, label_blocks

WM_OK, WM_ERR_MEMORY = 0, -2


class Blocks(ctypes.Structure):
    _fields_ = [(n, ctypes.c_int32) for n in ("width", "height", "levels", "size", "cols", "rows")]


class Initial(ctypes.Structure):
    _fields_ = [("xy", ctypes.POINTER(ctypes.c_int32)), ("tris", ctypes.POINTER(ctypes.c_int32)),
                ("nv", ctypes.c_int32), ("nt", ctypes.c_int32), ("low", ctypes.c_void_p)]


@pytest.fixture(scope="module")
def job() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(build_wmdev(target="wm_job_shared").with_name("libwmjob.so")))
    pb, pi, pu = ctypes.POINTER(Blocks), ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_uint32)
    lib.wm_job_blocks_init.argtypes = [pb, ctypes.c_int32, ctypes.c_int32, ctypes.c_int32]
    lib.wm_job_label.argtypes = [pb, ctypes.c_uint32, pi, pu]
    lib.wm_job_triangles.argtypes = [pb, pu]
    lib.wm_job_triangles.restype = ctypes.c_int32
    lib.wm_job_initial_bound.argtypes = [pb, ctypes.c_int32]
    lib.wm_job_initial_bound.restype = ctypes.c_size_t
    lib.wm_job_initial.argtypes = [pb, pu, ctypes.c_int32, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t,
                                   ctypes.POINTER(Initial)]
    return lib


def blocks(lib, width: int, height: int, levels: int) -> Blocks:
    b = Blocks()
    lib.wm_job_blocks_init(ctypes.byref(b), width, height, levels)
    return b


def label(lib, b: Blocks, tau: int, level: HaarLevel) -> np.ndarray:
    """wm_job_label on level M's details: the template entries, (rows, cols)."""
    det = np.ascontiguousarray(np.stack([level.d1, level.d2, level.d3], axis=-1), dtype=np.int32)
    entries = np.zeros(b.rows * b.cols, dtype=np.uint32)
    rc = lib.wm_job_label(ctypes.byref(b), tau, det.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)),
                          entries.ctypes.data_as(ctypes.POINTER(ctypes.c_uint32)))
    assert rc == WM_OK
    return entries.reshape(b.rows, b.cols)


def initial(lib, b: Blocks, entries: np.ndarray, keep: int = 0, extra: int = 0):
    """wm_job_initial in storage of its bound (+ keep at the start, + extra): (rc, xy, tris, storage)."""
    e = np.ascontiguousarray(entries.ravel(), dtype=np.uint32)
    pu = e.ctypes.data_as(ctypes.POINTER(ctypes.c_uint32))
    nt = lib.wm_job_triangles(ctypes.byref(b), pu)
    size = keep + lib.wm_job_initial_bound(ctypes.byref(b), nt) + extra
    mem = np.full(size + 8, 0xA5, dtype=np.uint8)  # garbage: nothing may be read before it is written
    base = mem.ctypes.data + (-mem.ctypes.data) % 8
    out = Initial()
    rc = lib.wm_job_initial(ctypes.byref(b), pu, nt, base, size, keep, ctypes.byref(out))
    if rc != WM_OK:
        return rc, None, None, (base, size)
    assert base + keep <= out.low <= base + size
    xy = np.ctypeslib.as_array(out.xy, (out.nv, 2)).copy()
    tris = np.ctypeslib.as_array(out.tris, (out.nt, 3)).copy()
    return rc, xy, tris, (base, size)


def random_level(rng, width: int, height: int, levels: int) -> HaarLevel:
    """Level M's details, 18-bit signed as the filter bank makes them, many ties and small values."""
    shape = (-(-height // (1 << levels)), -(-width // (1 << levels)))
    scale = rng.choice([3, 40, 1 << 17])
    d = [rng.integers(-scale, scale + 1, shape) for _ in range(3)]
    return HaarLevel(levels, np.zeros(shape, np.int64), *d)


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 70), st.integers(2, 70), st.integers(1, 5), st.integers(0, 2**32 - 1))
def test_labels_templates_and_initial_equal_the_model(job, width, height, levels, seed):
    rng = np.random.default_rng(seed)
    level = random_level(rng, width, height, levels)
    tau = int(rng.choice([0, 1, 20, rng.integers(0, 1 << 17), TAU_MAX]))
    b = blocks(job, width, height, levels)
    lab = label_blocks(level, tau, width, height)
    entries = label(job, b, tau, level)
    np.testing.assert_array_equal(entries >> memmap.TOUT_LABEL_SHIFT & memmap.TOUT_LABEL_MASK, lab.label)
    np.testing.assert_array_equal(entries >> memmap.TOUT_TEMPLATE_SHIFT & memmap.TOUT_TEMPLATE_MASK,
                                  lab.template)
    rc, xy, tris, _ = initial(job, b, entries)
    assert rc == WM_OK
    want = assemble(lab, width, height)  # canonical form
    np.testing.assert_array_equal(xy, want.xy)
    np.testing.assert_array_equal(tris, want.tris)


@pytest.mark.parametrize("name,levels", [("ball", 4), ("box", 5), ("f2", 3)])
def test_the_whole_template_stage_on_real_fields(job, name, levels):
    values = synth.make(name, 96)[:90, :77]
    samples = np.round((values - values.min()) / np.ptp(values) * 65535).astype(np.uint16)
    tau = 300
    b = blocks(job, 77, 90, levels)
    want = initial_triangulation(samples, levels, tau).mesh
    rc, xy, tris, _ = initial(job, b, label(job, b, tau, decompose(samples, levels)[-1]))
    assert rc == WM_OK
    np.testing.assert_array_equal(xy, want.xy)
    np.testing.assert_array_equal(tris, want.tris)


def test_staging_stays_above_what_the_caller_keeps(job):
    rng = np.random.default_rng(7)
    level = random_level(rng, 61, 45, 2)
    b = blocks(job, 61, 45, 2)
    entries = label(job, b, 10, level)
    rc, xy, tris, _ = initial(job, b, entries, keep=4096)
    assert rc == WM_OK  # the bound above keep suffices
    rc0, xy0, tris0, _ = initial(job, b, entries)
    np.testing.assert_array_equal(xy, xy0)
    np.testing.assert_array_equal(tris, tris0)
    # one word short of the staging: refused, never written below keep
    e = np.ascontiguousarray(entries.ravel(), dtype=np.uint32)
    pu = e.ctypes.data_as(ctypes.POINTER(ctypes.c_uint32))
    nt = job.wm_job_triangles(ctypes.byref(b), pu)
    need = 8 * len(xy) + 12 * nt  # at least the vertices and the triangles
    mem = np.zeros(need + 4096, dtype=np.uint64)
    out = Initial()
    keep = 8 * len(mem) - need + 8
    rc = job.wm_job_initial(ctypes.byref(b), pu, nt, mem.ctypes.data, 8 * len(mem), keep, ctypes.byref(out))
    assert rc == WM_ERR_MEMORY
    assert not mem.view(np.uint8)[:keep].any()  # nothing written into what the caller keeps
