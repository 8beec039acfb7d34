"""The host stages in C (firmware/host, native.quantise / quant_error / tri_max / obj_faces, the C filter
bank for the labeller) against their Python models (heightfield.quantise, check.mesh_errors,
haar.decompose, the OBJ writer's face format), bit for bit, on random and real grids, at several thread
counts; and `wavemesh mesh` writes the same mesh whatever --threads says."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
from wavemesh import api
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.cli import main
from wavemesh.errors import InputError
from wavemesh.io.heightfield import from_array, quantise
from wavemesh.mesh import Mesh
from wavemesh.model.initial import initial_triangulation
from wavemesh.refine import native

THREADS = (1, 2, 3, 7)


@pytest.fixture(autouse=True)
def _threads():
    lib = native.host_lib()
    assert lib is not None  # the library builds here: the fast paths are what is tested
    old = lib.wm_host_part_min(1)  # small grids split over the threads too (else they run on one)
    yield
    lib.wm_host_part_min(old)
    native.set_threads(None)


def real_grids() -> dict[str, np.ndarray]:
    import datasets  # bench/ (pytest.ini's pythonpath)

    return {name: datasets.load(name).values for name in ("jacksboro", "topobathy", "mri")}


def random_grids() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(31)
    return {
        "floats": rng.normal(100.0, 30.0, (37, 53)),
        "integers": rng.integers(0, 65536, (41, 29)).astype(np.float64),  # lossless, offset 0
        "negative integers": rng.integers(-70000, -10000, (23, 31)).astype(np.float64) // 2,  # lossless
        "wide integers": rng.integers(-10**9, 10**9, (19, 17)).astype(np.float64),  # lossy
        "constant": np.full((5, 7), 2.5),
        "tiny span": np.array([[0.0, 5e-324], [5e-324, 0.0]]),  # the step underflows
        "halves": np.round(rng.uniform(0, 10, (33, 33)) * 2) / 2,
        "float32": rng.uniform(-1, 1, (16, 64)).astype(np.float32).astype(np.float64),
        "big": rng.normal(0.0, 1e6, (300, 301)),
        # a zero extreme keeps the sign of the grid's first zero (offset = the least height, -0.0 or 0.0)
        "zeros, +0 first": _zeros(rng, 1.0, (0.0, -0.0)),
        "zeros, -0 first": _zeros(rng, 1.0, (-0.0, 0.0)),
        "zeros at the top": _zeros(rng, -1.0, (-0.0, 0.0)),
        "zeros, wide": _zeros(rng, 1e6, (-0.0, 0.0)),
    }


def _zeros(rng, sign: float, first: tuple[float, float]) -> np.ndarray:
    """Heights of one sign, with zeros of both signs far apart (first[0] before first[1])."""
    v = sign * rng.uniform(1.0, 9.5, (90, 101))
    v[40, 7], v[80, 99] = first
    return v


ALL = {**random_grids(), **real_grids()}


@pytest.mark.parametrize("name", list(ALL))
def test_quantise_equals_the_model(name):
    v = ALL[name]
    ref = quantise(v, native=False)
    want_err = float(np.max(np.abs(v - (ref[2] + ref[1] * ref[0].astype(np.float64)))))
    for n in THREADS:
        native.set_threads(n)
        fast = native.quantise(v)
        assert np.array_equal(fast[0], ref[0]) and fast[0].dtype == np.uint16
        assert fast[1:4] == ref[1:4]
        assert np.array(fast[1:3]).view(np.int64).tolist() == np.array(ref[1:3]).view(np.int64).tolist()
        assert fast[5:7] == (float(np.min(v)), float(np.max(v)))  # found by the same pass
        assert fast[4] == (0.0 if ref[3] else want_err)
        assert native.quant_error(v, ref[0], ref[2], ref[1]) == want_err
        hf = from_array(v)  # the fast path, and the property's cached value
        assert np.array_equal(hf.samples, ref[0])
        assert hf.max_quantisation_error == (0.0 if ref[3] else want_err)
        assert hf.extremes == fast[5:7] and api.default_tau(hf) == 0.01 * float(np.max(v) - np.min(v))


@pytest.mark.parametrize("name", list(ALL))
def test_quantise_with_a_given_scale_equals_the_model(name):
    """A tile's window by the whole grid's scale and offset (wm_host_quantise_with, tiles.source.Quant's
    quantised): its Python model's samples and largest error bit for bit; heights outside the range the
    scale was made for (a window of a grid whose range is another's) clipped as the model clips them."""
    from wavemesh.io.heightfield import quant_rule
    from wavemesh.tiles.source import Quant

    v = ALL[name]
    lo, hi = float(np.min(v)), float(np.max(v))
    whole = quant_rule(lo, hi, bool(np.all(v == np.floor(v))))
    mid = (lo + hi) / 2
    rules = [whole, quant_rule(mid, hi, False), quant_rule(lo, mid, False)]  # the last two clip some
    for scale, offset, exact in rules:
        for window in (v, v[1:-1, 2:-1], v[:, ::2]):  # a window's rows are not contiguous in the grid
            quant = Quant(scale, offset, exact, None, lo, hi)
            want = quant.quantised_model(window)
            for n in THREADS:
                native.set_threads(n)
                got = quant.quantised(window)
                assert got[0].dtype == np.uint16 and np.array_equal(got[0], want[0])
                assert got[1] == want[1] and (got[1] is None) == exact
                if not exact:
                    assert np.float64(got[1]).view(np.int64) == np.float64(want[1]).view(np.int64)


@pytest.mark.parametrize("name", ["floats", "halves", "big", "wide integers", "jacksboro", "topobathy"])
def test_float32_heights_read_as_their_float64_copy(name):
    """A tiled job's float32 input is read in place (tiles.source.Source.read): the quantisation by a
    given scale (wm_host_quantise_with32) and the error measure (wm_host_tri_max32) on float32 heights, a
    grid or a window of a wider one, are those of their float64 copy, bit for bit, whatever the threads."""
    from wavemesh.io.heightfield import quant_rule
    from wavemesh.tiles.source import Quant

    v32 = ALL[name].astype(np.float32)
    v = v32.astype(np.float64)
    # the grid as a window of a wider one, read in place (rows a pitch apart, as a memory map's window)
    inside = np.pad(v32, ((2, 3), (5, 7)), constant_values=np.nan)[2:-3, 5:-7]
    assert not inside.flags.c_contiguous and native._rows(inside)[0] is inside
    lo, hi = float(np.min(v)), float(np.max(v))
    for scale, offset, exact in (quant_rule(lo, hi, bool(np.all(v == np.floor(v)))),
                                 quant_rule((lo + hi) / 2, hi, False)):
        quant = Quant(scale, offset, exact, None, lo, hi)
        for window in (np.s_[:, :], np.s_[1:-1, 2:-1], np.s_[:, ::2], np.s_[3:, 1:], np.s_[:1, :]):
            want = quant.quantised(v[window])
            assert quant.quantised_model(v32[window])[1] == want[1]
            for n in THREADS:
                native.set_threads(n)
                for h in (v32[window], inside[window]):
                    got = quant.quantised(h)
                    assert np.array_equal(got[0], want[0]) and got[1] == want[1]
    for mesh in meshes(name, v):
        for spacing in ((1.0, 1.0), (30.0, 20.0)):
            ref = mesh_errors(mesh, v, rms=False, spacing=spacing)
            for n in THREADS:
                native.set_threads(n)
                for h in (v32, inside):
                    got = mesh_errors(mesh, h, rms=False, spacing=spacing)
                    assert np.array_equal(got.per_triangle_vertical, ref.per_triangle_vertical, True)
                    assert np.array_equal(got.per_triangle_normal, ref.per_triangle_normal, True)
            slow = mesh_errors(mesh, v32, rms=False, spacing=spacing, native=False)  # numpy on the copy
            assert np.array_equal(slow.per_triangle_vertical, ref.per_triangle_vertical, equal_nan=True)


def test_quantise_refuses_what_the_model_refuses():
    for bad in (np.array([[1.0, np.nan], [0.0, 2.0]]), np.array([[1.0, np.inf], [0.0, 2.0]])):
        assert native.quantise(bad) == "non-finite"
        with pytest.raises(InputError, match="non-finite"):
            quantise(bad)
    for at in (0, 4095, 4096, 9999):  # the C pass looks at whether all were finite block by block
        for value in (np.nan, -np.inf):
            v = np.arange(10000.0).reshape(100, 100)
            v.flat[at] = value
            for n in THREADS:
                native.set_threads(n)
                assert native.quantise(v) == "non-finite"
    huge = np.array([[-1.7e308, 1.7e308], [0.0, 0.0]])
    assert native.quantise(huge) == "span"
    with pytest.raises(InputError, match="too large"):
        quantise(huge)


def meshes(name: str, v: np.ndarray) -> list[Mesh]:
    hf = from_array(v)
    job = api.triangulate(hf)
    out = [job.mesh]
    if min(v.shape) >= 8:
        out.append(api.mesh(hf, api.MeshParams(refine=native.RefineParams(zeta=hf.scale * 500))).mesh)
    return out


@pytest.mark.parametrize("name", ["floats", "halves", "big", "jacksboro", "topobathy", "mri"])
def test_error_measure_equals_the_model(name):
    v = ALL[name]
    for mesh in meshes(name, v):
        for spacing in ((1.0, 1.0), (30.0, 20.0)):
            ref = mesh_errors(mesh, v, rms=False, spacing=spacing, native=False)
            for n in THREADS:
                native.set_threads(n)
                fast = mesh_errors(mesh, v, rms=False, spacing=spacing)
                assert np.array_equal(fast.per_triangle_vertical, ref.per_triangle_vertical, equal_nan=True)
                assert np.array_equal(fast.per_triangle_normal, ref.per_triangle_normal, equal_nan=True)
                assert (fast.e_max_vertical, fast.e_max_normal) == (ref.e_max_vertical, ref.e_max_normal)


def test_error_measure_of_odd_meshes():
    """Degenerate and thin triangles, vertices off the grid (given heights), a NaN height: as the model."""
    rng = np.random.default_rng(5)
    h = rng.normal(0, 10, (12, 15))
    xy = np.array([[0, 0], [14, 0], [14, 11], [0, 11], [7, 0], [7, 11], [3, 5], [20, 5]])
    tris = np.array([[0, 1, 2], [0, 2, 3], [0, 4, 1], [4, 5, 0], [6, 6, 1], [1, 7, 2], [0, 1, 7]])
    mesh = Mesh(15, 12, xy, tris)
    z = rng.normal(0, 10, len(xy))
    for heights in (h, np.where(np.arange(h.size).reshape(h.shape) == 40, np.nan, h)):
        ref = mesh_errors(mesh, heights, z, rms=False, native=False)
        for n in THREADS:
            native.set_threads(n)
            fast = mesh_errors(mesh, heights, z, rms=False)
            assert np.array_equal(fast.per_triangle_vertical, ref.per_triangle_vertical, equal_nan=True)
            assert np.array_equal(fast.per_triangle_normal, ref.per_triangle_normal, equal_nan=True)
            assert np.isnan(fast.e_max_vertical) == np.isnan(ref.e_max_vertical)
    # the normal factors (the slopes' terms, hypot) of degenerate and sloped triangles, spacings included
    for spacing in ((1.0, 1.0), (0.3, 7.0)):
        got = native.tri_max(h, xy[:, 0], xy[:, 1], z, tris, spacing)[1]
        x, y = xy[:, 0][tris], xy[:, 1][tris]
        d = ((x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])) * 1.0
        dz1, dz2 = z[tris[:, 1]] - z[tris[:, 0]], z[tris[:, 2]] - z[tris[:, 0]]
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (dz1 * (y[:, 2] - y[:, 0]) - dz2 * (y[:, 1] - y[:, 0])) / d / spacing[0]
            b = ((x[:, 1] - x[:, 0]) * dz2 - (x[:, 2] - x[:, 0]) * dz1) / d / spacing[1]
            assert np.array_equal(got, np.hypot(1.0, np.hypot(a, b)), equal_nan=True)


@pytest.mark.parametrize("wavelet", ["haar", "spline"])
@pytest.mark.parametrize("shape", [(17, 33), (64, 64), (65, 40), (3, 130)])
def test_initial_triangulation_from_the_c_filter_bank(wavelet, shape):
    rng = np.random.default_rng(shape[0] * shape[1])
    samples = rng.integers(0, 65536, shape).astype(np.uint16)
    samples = np.cumsum(np.cumsum(samples % 64, axis=0), axis=1).astype(np.uint16)  # smooth-ish
    for m in range(1, api.default_levels(shape[1], shape[0]) + 2):
        for tau_q in (0, 40, 4000):
            ref = initial_triangulation(samples, m, tau_q, wavelet)
            det = native.haar_details(samples, m, wavelet)
            fast = initial_triangulation(samples, m, tau_q, wavelet, det)
            for k in ("label", "mask", "template"):
                assert np.array_equal(getattr(fast.labelling, k), getattr(ref.labelling, k))
            assert fast.mesh.same_as(ref.mesh)


def test_mesh_is_the_same_whatever_the_thread_count(tmp_path):
    v = ALL["big"]
    np.save(tmp_path / "in.npy", v)
    outs = []
    for n in ("1", "2", "5", None):
        out = tmp_path / f"m{n}.obj"
        assert main(["mesh", str(tmp_path / "in.npy"), "-o", str(out), "--zeta", "20000", "-q",
                     *(["--threads", n] if n else [])]) == 0
        outs.append(out.read_bytes())
    assert all(o == outs[0] for o in outs[1:])


def test_threads_out_of_range(tmp_path, capsys):
    np.save(tmp_path / "in.npy", ALL["floats"])
    assert main(["mesh", str(tmp_path / "in.npy"), "-o", str(tmp_path / "m.obj"), "--threads", "0"]) != 0
    assert "--threads 0" in capsys.readouterr().err
    assert not (tmp_path / "m.obj").exists()


def _mutations(mesh: Mesh, rng: np.random.Generator) -> list[Mesh]:
    """Broken variants of a proper mesh: each check of check_mesh has one that fails it."""
    w, h, xy, tris = mesh.width, mesh.height, mesh.xy.copy(), mesh.tris.copy()
    t = int(rng.integers(len(tris)))
    out = [Mesh(w, h, xy, np.delete(tris, t, axis=0)),  # a hole (and an unused vertex, maybe)
           Mesh(w, h, xy, np.vstack([tris, tris[t:t + 1]])),  # an overlap: a directed edge twice
           Mesh(w, h, xy, np.vstack([tris[:t], tris[t, ::-1][None], tris[t + 1:]])),  # clockwise
           Mesh(w + 1, h, xy, tris), Mesh(w, h + 1, xy, tris),  # not the rectangle's area
           Mesh(w, h, np.vstack([xy, [[w - 1, h - 1]]]), tris),  # a coincident, unused vertex
           Mesh(w, h, xy, np.where(tris == tris[t, 0], len(xy), tris))]  # an index out of range
    moved = xy.copy()
    moved[int(rng.integers(len(xy)))] += (int(rng.integers(-1, 2)), int(rng.integers(-1, 2)))
    out.append(Mesh(w, h, moved, tris))  # a vertex moved: outside, coincident, folded or still proper
    return out


def test_proper_mesh_check_in_c_agrees_with_the_model():
    """native.check_proper's verdict is check_mesh's (fast=False) on proper meshes (grids, fans, cut
    meshes, the refiner's) and on broken variants of each, at every thread count; check_mesh's own answer
    is the same either way."""
    import test_check as tc  # tests/host (pytest.ini's pythonpath): the checker's own mesh builders

    rng = np.random.default_rng(31)
    proper = [tc.SQUARE, tc.fan_mesh(9, 7, (4, 3)), tc.fan_mesh(40, 3, (17, 1)), tc.grid_mesh(6, 5, rng)]
    proper += [tc.random_cut_mesh(rng) for _ in range(40)]
    proper += [m for name in ("floats", "big", "mri") for m in meshes(name, ALL[name])]
    # a T-junction: a square cut into a triangle and a quad split at its edge's midpoint
    tj = Mesh(3, 3, [(0, 0), (2, 0), (2, 2), (0, 2), (1, 1), (2, 1)], [(0, 1, 4), (1, 5, 4), (5, 2, 4),
                                                                      (0, 4, 3), (4, 2, 3)])
    cases = [(m, True) for m in proper] + [(tj, None)]
    cases += [(b, None) for m in proper for b in _mutations(m, rng)]
    seen = set()
    for mesh, want in cases:
        ref = check_mesh(mesh, fast=False)
        if want is not None:
            assert ref.valid
        for n in THREADS:
            native.set_threads(n)
            c = native.check_proper(mesh)
            assert c is not None, (mesh, ref.problems)
            assert c[0] == ref.valid
            if c[0]:
                assert c[1] == ref.n_border
            assert check_mesh(mesh) == ref
        seen.add(ref.valid)
    assert seen == {True, False}


def test_obj_face_lines_in_c_equal_the_format(tmp_path, monkeypatch):
    rng = np.random.default_rng(5)
    cases = [np.zeros((0, 3), np.int64), rng.integers(0, 10**6, (5000, 3)),
             np.array([[0, 9, 99], [2**62, -5, -1], [2**63 - 1, -2**63, 7]], np.int64)]  # signs, wrap-around
    for t in cases:
        with np.errstate(over="ignore"):
            want = ("f %d %d %d\n" * len(t)) % tuple((t + 1).ravel().tolist())
        assert native.obj_faces(t) == want
    # a whole file: the same bytes with the library and without it (the Python format)
    from wavemesh.io.meshio import write_obj

    hf = from_array(real_grids()["topobathy"])
    mesh = api.mesh(hf, api.MeshParams()).mesh
    write_obj(tmp_path / "c.obj", mesh, hf.values)
    monkeypatch.setattr(native, "host_lib", lambda: None)
    write_obj(tmp_path / "py.obj", mesh, hf.values)
    assert (tmp_path / "c.obj").read_bytes() == (tmp_path / "py.obj").read_bytes()


def _vertex_heights() -> dict[str, np.ndarray]:
    """Heights of every kind a grid has, and the edges of what the C writes itself (1e-4 .. 2^53)."""
    rng = np.random.default_rng(11)
    n = 100_000
    near = [np.nextafter(x, d) for x in [2.0**k for k in range(-16, 55)] + [10.0**k for k in range(-6, 18)]
            for d in (-np.inf, np.inf)]
    return {
        "uniform": rng.uniform(-1000.0, 5000.0, n),
        "float32": rng.uniform(-500.0, 9000.0, n).astype(np.float32).astype(np.float64),
        "small float32": rng.uniform(-1.0, 1.0, n).astype(np.float32).astype(np.float64),
        "decimals": np.round(rng.uniform(-1e6, 1e6, n)) / 10.0 ** rng.integers(0, 5, n),
        "integers": rng.integers(-10**6, 10**6, n).astype(np.float64),
        "any size": rng.uniform(0.0, 1.0, n) * 10.0 ** rng.integers(-6, 18, n),
        "any bits": rng.integers(0, 2**64, n, dtype=np.uint64).view(np.float64),  # NaNs, huge, tiny
        "powers and their neighbours": np.array([2.0**k for k in range(-16, 55)] + near),
        "edges": np.array([0.0, -0.0, 1e-4, -1e-4, 2.0**53, 2.0**53 - 1, np.inf, -np.inf, np.nan, 5e-324,
                           0.1, 0.3, 1 / 3, 1234567890123456.5, 4503599627370496.5, 9.999999999999999e15]),
    }


@pytest.mark.parametrize("name", list(_vertex_heights()))
def test_obj_vertex_lines_in_c_equal_the_format(name, tmp_path, monkeypatch):
    """native.obj_vertices: "v x y z" with z as repr writes it (the shortest decimal that reads back, the
    nearest of them), the text of the Python format, on every kind of height (those the C leaves to repr
    too); and a whole file the same bytes with the library and without it."""
    from wavemesh.io import meshio

    z = _vertex_heights()[name]
    xy = np.random.default_rng(3).integers(-9, 10**5, (len(z), 2))
    with np.errstate(invalid="ignore"):
        assert native.obj_vertices(xy, z) == meshio._obj_vertex_lines_model(xy, z)
    # the C writes the heights in its range itself: repr gets only its ties (none of these)
    lib, ptr = native.host_lib(), native._ptr
    left, n_left = np.empty(len(z), dtype=np.int64), ctypes.c_int64(0)
    lib.wm_host_obj_vertices(ptr(np.ascontiguousarray(xy), ctypes.c_int64), ptr(z, ctypes.c_double), len(z),
                             ctypes.create_string_buffer(native.OBJ_VERTEX_MAX * len(z)),
                             ptr(left, ctypes.c_int64), ctypes.byref(n_left))
    mine = (z == 0) | ((np.abs(z) >= 1e-4) & (np.abs(z) < 2.0**53))
    assert sorted(left[: n_left.value]) == np.flatnonzero(~mine).tolist()
    if name == "uniform":
        assert native.obj_vertices(xy[:0], z[:0]) == ""
        hf = from_array(real_grids()["topobathy"])
        mesh = api.mesh(hf, api.MeshParams()).mesh
        meshio.write_obj(tmp_path / "c.obj", mesh, hf.values)
        monkeypatch.setattr(native, "host_lib", lambda: None)
        meshio.write_obj(tmp_path / "py.obj", mesh, hf.values)
        assert (tmp_path / "c.obj").read_bytes() == (tmp_path / "py.obj").read_bytes()


@pytest.mark.parametrize("name", sorted(ALL))
def test_quantisation_error_kept_from_the_quantising_pass(name):
    """from_array keeps wm_host_quantise's own error measure as max_quantisation_error: the model's value."""
    hf = from_array(ALL[name])
    recon = hf.offset + hf.scale * hf.samples.astype(np.float64)
    assert "max_quantisation_error" in hf.__dict__  # set by the pass, not measured again
    assert hf.max_quantisation_error == float(np.max(np.abs(hf.values - recon)))


@pytest.fixture
def c_scan():
    """The library, its scan setting put back after the test (wm_host_scan: 0 the C scan, 2 host_scan.c's
    blocks on every grid, as the test grids are smaller than their default's 2^20 samples, 3 its small
    triangles' lanes on every grid)."""
    lib = native.load()
    old = lib.wm_host_scan(-1)
    yield lib
    lib.wm_host_scan(old)


@pytest.mark.parametrize("mode", [2, 3])
@pytest.mark.parametrize("name", ["floats", "halves", "big", "jacksboro", "topobathy", "mri"])
def test_refiner_scan_in_avx2_equals_the_c_scan(name, mode, c_scan):
    """The host library's E(T) scans (host_scan.c, AVX2: its blocks, mode 2, and its small triangles'
    lanes, mode 3) against tri_error.c's: the same meshes and statistics at every level, bound met or
    stopped by a budget, in both metrics (every scan's Vmax, first worst sample and early stop at a limit
    shape them)."""
    v = ALL[name]
    hf = from_array(v)
    span = float(v.max() - v.min())
    for metric in ("vertical", "normal"):
        for zeta, budget in ((0.002 * span, None), (0.02 * span, None), (0.002 * span, 60)):
            params = api.MeshParams(refine=native.RefineParams(zeta=zeta, metric=metric,
                                                               max_triangles=budget))
            got = []
            for on in (0, mode):
                c_scan.wm_host_scan(on)
                r = api.mesh(hf, params)
                got.append((r.mesh.xy.tolist(), r.mesh.tris.tolist(), r.rows))
            assert got[0] == got[1], (metric, zeta, budget)


def test_refiner_default_scan_on_a_large_grid_equals_the_c_scan(c_scan):
    """The default (wm_host_scan(1)) on a grid of 2^20 samples or more, where host_scan.c takes every
    triangle: the small ones in its lanes, the others in its blocks (Jacksboro mirrored to 1024 x 1024):
    the same meshes and statistics at every level as the C scan's, in both metrics."""
    v = ALL["jacksboro"]
    v = np.pad(v, ((0, 1024 - v.shape[0]), (0, 1024 - v.shape[1])), mode="symmetric")
    assert v.size >= 1 << 20  # host_scan.c's SCAN_MIN_SAMPLES: the blocks' grids
    hf = from_array(v)
    span = float(v.max() - v.min())
    for metric in ("vertical", "normal"):
        params = api.MeshParams(refine=native.RefineParams(zeta=0.01 * span, metric=metric))
        got = []
        for on in (0, 1):
            c_scan.wm_host_scan(on)
            r = api.mesh(hf, params)
            got.append((r.mesh.xy.tolist(), r.mesh.tris.tolist(), r.rows))
        assert got[0] == got[1], metric


def test_triangle_scan_in_avx2_equals_the_c_scan(c_scan):
    """E(T) of random triangles, small (the 32-bit lanes) and large or on a grid wider than 2^14 (the
    64-bit lanes), by both scans: the same value, bit for bit."""
    rng = np.random.default_rng(5)
    for shape in ((300, 301), (3, 17000)):
        samples = rng.integers(0, 65536, shape).astype(np.uint16)
        samples[:, : shape[1] // 2] //= 64  # smooth half: maxima reached late and often
        h, w = shape
        for _ in range(300):
            x = rng.integers(0, w, 3)
            y = rng.integers(0, h, 3)
            if (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]) <= 0:
                continue
            for metric in ("vertical", "normal"):
                e = []
                for on in (0, 1):
                    c_scan.wm_host_scan(2 * on)
                    e.append(native.tri_error(samples, x, y, metric))
                assert e[0] == e[1], (x, y, metric)


def test_small_triangle_lanes_equal_the_c_scan(c_scan):
    """E(T) and its worst sample of random small triangles (D < 2^15: scan32's, which host_scan.c takes in
    lanes), by the C scan and the lanes, bit for bit, and E(T) alone (the lanes that keep no place); on
    small grids many touch the last samples, which the lanes read without loading past them."""
    rng = np.random.default_rng(7)
    lib = native.load()
    for shape, ties in (((300, 301), False), ((37, 40), False), ((9, 8), False), ((60, 50), True)):
        samples = rng.integers(0, 65536, shape).astype(np.uint16)
        samples[:, : shape[1] // 2] //= 64  # smooth half: maxima reached late and often
        if ties:  # two heights: many samples share the largest V, the first must be named
            samples = (rng.integers(0, 2, shape) * 1000).astype(np.uint16)
        h, w = shape
        fld = native.Field(w, h, 1, native._ptr(samples, ctypes.c_uint16), None)
        taken = 0
        for _ in range(1500):
            x0, y0 = rng.integers(0, w), rng.integers(0, h)
            r = int(rng.choice([3, 8, 20, 60]))
            x = np.clip(x0 + rng.integers(-r, r + 1, 3), 0, w - 1)
            y = np.clip(y0 + rng.integers(-r, r + 1, 3), 0, h - 1)
            d = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
            if d <= 0 or d >= 1 << 15:
                continue
            taken += 1
            xs, ys = (ctypes.c_int32 * 3)(*map(int, x)), (ctypes.c_int32 * 3)(*map(int, y))
            for metric in ("vertical", "normal"):
                fp = native.fixed_params(native.RefineParams(metric=metric), 1.0)
                got = []
                for on in (0, 3):
                    c_scan.wm_host_scan(on)
                    wx, wy = ctypes.c_int32(-1), ctypes.c_int32(-1)
                    e = lib.wm_tri_error(ctypes.byref(fld), ctypes.byref(fp), xs, ys, ctypes.byref(wx),
                                         ctypes.byref(wy))
                    # and without the worst sample asked for (the lanes that keep no place)
                    e0 = lib.wm_tri_error(ctypes.byref(fld), ctypes.byref(fp), xs, ys, None, None)
                    got.append((e, wx.value, wy.value, e0))
                assert got[0] == got[1], (x, y, metric)
        assert taken > 300


def test_square_root_hook_equals_isqrt():
    """The shared library's wm_isqrt64 (fixed.c), whose roots from 256 on come from host_scan.c's hook
    (WM_ROOT_ENGINE: the processor's square root made exact), is floor(sqrt(x)): against math.isqrt at
    every x below 4096, around every square of a power of two and its neighbours (where a double's
    rounding lands on the wrong side), up to 2^64 - 1, and at random values of every bit length."""
    lib = native.load()
    root = lib.wm_isqrt64
    root.restype, root.argtypes = ctypes.c_uint64, [ctypes.c_uint64]
    values = list(range(4096)) + [2**64 - 1, 2**64 - 2, 2**63, 2**63 - 1]
    for k in range(1, 33):
        for r in (2**k - 1, 2**k, 2**k + 1, 3 * 2 ** (k - 1), 2**k - 3):
            values += [v for v in (r * r - 2, r * r - 1, r * r, r * r + 1, r * r + 2 * r, r * r + 2 * r + 1)
                       if 0 <= v < 2**64]
    rng = np.random.default_rng(11)
    values += [int(v) >> s for s in range(64) for v in rng.integers(0, 2**63, 200, dtype=np.uint64) * 2 + 1]
    bad = [v for v in values if root(v) != math.isqrt(v)]
    assert not bad, bad[:5]
