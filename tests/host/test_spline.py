"""The integer spline-wavelet filter bank against a slow element-by-element model of the same spec,
and the properties that let it stand in for Haar (same shapes, widths and scale)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import WAVELETS, decompose, haar_step, level_shape
from wavemesh.model.initial import initial_triangulation
from wavemesh.model.spline import spline_step

H = (1, 3, 3, 1)


def slow_step(a):
    """wavemesh.model.spline's formulas written out one coefficient at a time, 2-D weights h x h etc."""
    h, w = len(a), len(a[0])

    def at(r, c):  # every index clamped into the array
        return int(a[min(max(r, 0), h - 1)][min(max(c, 0), w - 1)])

    rows, cols = (h + 1) // 2, (w + 1) // 2
    out = [[[0] * cols for _ in range(rows)] for _ in range(4)]
    for i in range(rows):
        for j in range(cols):
            s = sum(H[u] * H[v] * at(2 * i + u - 1, 2 * j + v - 1) for u in range(4) for v in range(4))
            g1 = sum(H[u] * (at(2 * i + u - 1, 2 * j + 1) - at(2 * i + u - 1, 2 * j)) for u in range(4))
            g2 = sum(H[v] * (at(2 * i + 1, 2 * j + v - 1) - at(2 * i, 2 * j + v - 1)) for v in range(4))
            out[0][i][j] = (s + 32) // 64
            out[1][i][j] = (g1 + 2) // 4
            out[2][i][j] = (g2 + 2) // 4
            p00, p01 = at(2 * i, 2 * j), at(2 * i, 2 * j + 1)
            p10, p11 = at(2 * i + 1, 2 * j), at(2 * i + 1, 2 * j + 1)
            out[3][i][j] = p00 + p11 - p01 - p10
    return [np.array(x, dtype=np.int64) for x in out]


@settings(max_examples=60, deadline=None)
@given(h=st.integers(1, 30), w=st.integers(1, 30), seed=st.integers(0, 2**32 - 1))
def test_step_matches_slow_model(h, w, seed):
    a = np.random.default_rng(seed).integers(0, 65536, size=(h, w))
    for got, want in zip(spline_step(a), slow_step(a.tolist()), strict=True):
        np.testing.assert_array_equal(got, want)


def test_widths_at_the_extremes():
    """The approximation stays 16-bit unsigned and the details 18-bit signed on the worst inputs."""
    rng = np.random.default_rng(3)
    cases = [np.full((9, 9), 65535), np.zeros((9, 9), np.int64),
             65535 * (np.indices((16, 16)).sum(axis=0) % 2),  # checkerboard
             65535 * (np.arange(16)[None, :] % 4 >= 2) * np.ones((16, 1), np.int64),  # stripes
             rng.integers(0, 2, size=(33, 31)) * 65535]
    for a in cases:
        for m, lv in enumerate(decompose(a, 3, "spline"), start=1):
            assert 0 <= lv.a.min() and lv.a.max() <= 65535, m
            for d in (lv.d1, lv.d2, lv.d3):
                assert -(1 << 17) <= d.min() and d.max() < (1 << 17), m


@pytest.mark.parametrize("shape", [(2, 2), (3, 100), (100, 3), (37, 53), (129, 255)])
def test_shapes_are_haars(shape):
    s = np.random.default_rng(1).integers(0, 65536, size=shape)
    for lv in decompose(s, 4, "spline"):
        assert lv.a.shape == lv.d1.shape == lv.d3.shape == level_shape(*shape, lv.m)


def test_planes_give_haars_details():
    """The scale is Haar's: on a plane both banks give the same slopes (d1 = 2 gx, d2 = 2 gy at level 1,
    doubling per level) and d3 = 0, away from the clamped border; a constant gives no detail at all."""
    i, j = np.indices((64, 64))
    plane = 1000 + 3 * j + 5 * i
    for m, (hs, sp) in enumerate(zip(decompose(plane, 3), decompose(plane, 3, "spline"), strict=True), 1):
        inner = (slice(1, -2), slice(1, -2))  # the clamped border sees a kink
        for k in ("d1", "d2", "d3"):
            np.testing.assert_array_equal(getattr(sp, k)[inner], getattr(hs, k)[inner], err_msg=f"{k} m={m}")
        assert sp.d1[inner].min() == 3 * 2**m and sp.d2[inner].max() == 5 * 2**m
    for lv in decompose(np.full((20, 30), 777), 3, "spline"):
        assert not lv.d1.any() and not lv.d2.any() and not lv.d3.any() and (lv.a == 777).all()


def test_spline_spreads_an_impulse():
    """A single raised sample (fig. 3.6(a)): Haar answers only in the block holding it, the spline's
    d1 and d2 in the neighbouring block along the smoothing filter too (the wider support the
    dissertation calls noise spreading, 3.6.3)."""
    imp = np.zeros((16, 16), np.int64)
    imp[9, 9] = 800
    _, *hd = haar_step(imp)
    assert [np.count_nonzero(d) for d in hd] == [1, 1, 1]
    _, d1, d2, d3 = spline_step(imp)
    assert np.count_nonzero(d1) == 2 and (d1[4, 4], d1[5, 4]) == (600, 200)  # row 9: 2i+1, 2i-1
    assert np.count_nonzero(d2) == 2 and (d2[4, 4], d2[4, 5]) == (600, 200)
    assert np.count_nonzero(d3) == 1 and d3[4, 4] == 800


def test_initial_triangulation_with_either_wavelet():
    assert set(WAVELETS) == {"haar", "spline"}
    hf = from_array(synth.ball())
    for name in WAVELETS:
        res = initial_triangulation(hf.samples, 4, 655, name)
        assert res.mesh.n_triangles > 2
    with pytest.raises(ValueError, match="wavelet"):
        decompose(hf.samples, 2, "daubechies")


def test_mesh_with_the_spline_wavelet(tmp_path):
    """`wavemesh mesh --wavelet spline`: a proper mesh within zeta, the wavelet in the report; the
    spline details reach the refiner (its levels differ from Haar's)."""
    import json
    import subprocess
    import sys

    from wavemesh import api
    from wavemesh.refine.native import RefineParams

    hf = from_array(synth.ball(64))
    runs = {w: api.mesh(hf, api.MeshParams(levels=3, wavelet=w, refine=RefineParams(zeta=0.5)))
            for w in WAVELETS}
    for r in runs.values():
        assert r.bound_met and r.errors.e_max_normal <= 0.5 + 1e-9
    assert runs["spline"].report["parameters"]["wavelet"] == "spline"
    assert [m.n_triangles for _, m in runs["haar"].level_meshes] != [m.n_triangles for _, m in
                                                                     runs["spline"].level_meshes]
    np.save(tmp_path / "b.npy", synth.ball(64))
    r = subprocess.run([sys.executable, "-m", "wavemesh", "mesh", str(tmp_path / "b.npy"), "-o",
                        str(tmp_path / "b.obj"), "--wavelet", "spline", "--report", str(tmp_path / "b.json")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "b.json").read_text())["parameters"]["wavelet"] == "spline"
    r = subprocess.run([sys.executable, "-m", "wavemesh", "mesh", str(tmp_path / "b.npy"), "-o",
                        str(tmp_path / "c.obj"), "--wavelet", "daubechies"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode != 0 and "error:" in r.stderr and not (tmp_path / "c.obj").exists()


def test_config_carries_the_wavelet():
    """CONFIG_SPLINE is a known flag, set only for the spline wavelet."""
    from wavemesh.device import protocol as P
    from wavemesh.device.stream import config_payload
    from wavemesh.refine.native import RefineParams, fixed_params

    fp = fixed_params(RefineParams(), 1.0)
    assert P.CONFIG_SPLINE & P.CONFIG_KNOWN_FLAGS
    for spline in (False, True):
        flags = P.CONFIG.unpack(config_payload(64, 64, 3, 10, fp, spline=spline))["flags"]
        assert bool(flags & P.CONFIG_SPLINE) == spline
