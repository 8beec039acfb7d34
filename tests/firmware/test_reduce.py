"""The reduction of 4.6 steps 2(d) and 3(b) (firmware/src/autocorr.c, edge_collapse.c, reduce.c):
R(v)'s fixed-point eigen-decomposition against numpy, unit normals against numpy, whole refinements
with the reduction checked independently (check_mesh, mesh_errors), the options on the wire and on
the command line."""

import ctypes
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from wavemesh import api
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.device import protocol as P
from wavemesh.device.stream import config_payload
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.refine import native

ROOT = Path(__file__).resolve().parents[2]

Q30 = 1 << 30
EIG_TOL = 2.0**-22  # Jacobi in Q30: a few dozen roundings of 2^-31 each


def _lib():
    lib = native.load()
    lib.wm_sym3_eigen.restype = None
    lib.wm_sym3_eigen.argtypes = [ctypes.POINTER(ctypes.c_int64)] * 3
    lib.wm_unit_normal.restype = None
    lib.wm_unit_normal.argtypes = [ctypes.POINTER(native.Field), ctypes.POINTER(native.Params),
                                   ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_int32),
                                   ctypes.POINTER(ctypes.c_int32)]
    return lib


def _eigen(lib, r: np.ndarray):
    a = (ctypes.c_int64 * 6)(*(int(round(r[i, j] * Q30)) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2),
                                                                      (2, 2))))
    lam, vec = (ctypes.c_int64 * 3)(), (ctypes.c_int64 * 9)()
    lib.wm_sym3_eigen(a, lam, vec)
    return np.array(lam[:]) / Q30, np.array(vec[:]).reshape(3, 3) / Q30


def _random_normals(rng, k: int, spread: float) -> np.ndarray:
    axis = rng.normal(size=3)
    n = axis / np.linalg.norm(axis) + spread * rng.normal(size=(k, 3))
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.mark.parametrize("spread", [0.0, 0.01, 0.1, 0.5, 3.0])
def test_eigenvalues_of_r_match_numpy(spread):
    lib = _lib()
    rng = np.random.default_rng(int(spread * 1000) + 7)
    for _ in range(200):
        n = _random_normals(rng, int(rng.integers(1, 33)), spread)
        r = n.T @ n / len(n)  # R(v) of eq. 4.31
        lam, vec = _eigen(lib, r)
        assert np.all(np.diff(lam) >= 0)
        assert np.allclose(lam, np.linalg.eigvalsh(r), atol=EIG_TOL, rtol=0), (lam, np.linalg.eigvalsh(r))
        for i in range(3):  # unit eigenvectors: R v = lambda v
            v = vec[i]
            assert abs(np.linalg.norm(v) - 1) < 2.0**-20
            assert np.linalg.norm(r @ v - lam[i] * v) < 2.0**-18


def test_unit_normals_match_numpy():
    lib = _lib()
    rng = np.random.default_rng(3)
    z = rng.integers(0, 65536, size=(40, 50)).astype(np.uint16)
    for scale in (1.0, 0.001, 37.5, 2.0**-40):
        fld = native.Field(50, 40, 1, native._ptr(z, ctypes.c_uint16), None)
        fp = native.fixed_params(native.RefineParams(), scale)
        s = fp.scale_m / 2.0**fp.scale_e
        for _ in range(300):
            x = rng.integers(0, 50, size=3)
            y = rng.integers(0, 40, size=3)
            if (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]) <= 0:
                continue
            n = (ctypes.c_int32 * 3)()
            lib.wm_unit_normal(ctypes.byref(fld), ctypes.byref(fp), (ctypes.c_int32 * 3)(*map(int, x)),
                               (ctypes.c_int32 * 3)(*map(int, y)), n)
            p = np.stack([x, y, s * z[y, x].astype(float)], axis=1)
            want = np.cross(p[1] - p[0], p[2] - p[0])
            want /= np.linalg.norm(want)
            assert np.allclose(np.array(n[:]) / 2.0**28, want, atol=2.0**-25, rtol=0), (n[:], want)


CASES = [
    ("ball", lambda: synth.ball(96), 4, dict(zeta=0.5, alpha=0.8)),
    ("box", lambda: synth.box(80), 4, dict(zeta=1.0, metric="vertical", delta_lambda=0.05)),
    ("noise", lambda: np.random.default_rng(9).integers(0, 300, size=(45, 61)).astype(float), 3,
     dict(zeta=20.0, iterations=2, delta_lambda=0.2, delta_c=0.5)),
]


@pytest.mark.parametrize("name,make,levels,kw", CASES, ids=[c[0] for c in CASES])
def test_reduction_keeps_every_level_proper_and_the_bound(name, make, levels, kw):
    hf = from_array(make())
    on = api.refine(hf, levels, None, native.RefineParams(**kw), check_levels=True)  # every level proper
    off = api.refine(hf, levels, None, native.RefineParams(reduce=False, **kw))
    assert on.bound_met and mesh_errors(on.mesh, hf.values, rms=False).to_report() == on.errors.to_report()
    metric = "e_max_normal" if kw.get("metric", "normal") == "normal" else "e_max_vertical"
    assert getattr(on.errors, metric) <= kw["zeta"] + 1e-9
    removals = [lv.stats["removals"] for lv in on.output.levels]
    assert sum(removals[:-1]) > 0  # 2(d) and 3(b) removed something before the final decimation
    assert on.output.levels[0].mesh.n_triangles < off.output.levels[0].mesh.n_triangles  # 2(d)
    # the firmware's E_max is an upper bound of the exact one at every level, on the heights it refines (the
    # 16-bit samples: for lossy input the input values differ from them by up to q, docs/refiner.md)
    seen = hf.samples.astype(np.float64) * hf.scale + hf.offset
    for lv in on.output.levels:
        e = mesh_errors(lv.mesh, seen)
        assert getattr(e, metric) <= lv.stats["e_max_q16"] / 65536 * hf.scale + 1e-6


def test_reduction_never_raises_e_max_of_the_initial_mesh():
    """2(d) only: each removal keeps its new triangles within the largest E(T) it replaces."""
    hf = from_array(synth.ball(128))
    for kw in (dict(), dict(delta_lambda=0.5, delta_c=0.1)):
        on = api.refine(hf, 4, None, native.RefineParams(bound=False, iterations=0, **kw))
        off = api.refine(hf, 4, None, native.RefineParams(bound=False, iterations=0, reduce=False, **kw))
        assert check_mesh(on.output.levels[0].mesh).valid
        e_on = mesh_errors(on.output.levels[0].mesh, hf.values).e_max_normal
        e_off = mesh_errors(off.output.levels[0].mesh, hf.values).e_max_normal
        assert e_on <= e_off + 1e-6


def test_config_carries_the_reduction_and_the_flags():
    p = native.RefineParams(delta_lambda=0.005, delta_c=0.9, bound=False, reduce=False, decimate=False)
    fp = native.fixed_params(p, 1.0)
    assert (fp.delta_lambda, fp.delta_c) == (round(0.005 * 65536), round(0.9 * 65536))
    assert fp.flags == native.FLAG_NO_BOUND | native.FLAG_NO_REDUCE | native.FLAG_NO_DECIMATE
    c = P.CONFIG.unpack(config_payload(10, 10, 2, 5, fp))
    assert c["flags"] == P.CONFIG_NO_BOUND | P.CONFIG_NO_REDUCE | P.CONFIG_NO_DECIMATE
    assert c["flags"] >> P.CONFIG_REFINER_SHIFT == fp.flags
    assert (c["delta_lambda"], c["delta_c"]) == (fp.delta_lambda, fp.delta_c)
    c = P.CONFIG.unpack(config_payload(10, 10, 2, 5, native.fixed_params(native.RefineParams(), 1.0),
                                       initial_only=True))
    assert c["flags"] == P.CONFIG_INITIAL_ONLY


def test_bound_off_on_the_command_line(tmp_path):
    np.save(tmp_path / "ball.npy", synth.ball(128))
    out, rep = tmp_path / "b.obj", tmp_path / "b.json"
    r = subprocess.run([sys.executable, "-m", "wavemesh", "mesh", str(tmp_path / "ball.npy"), "-o", str(out),
                        "--levels", "4", "--zeta", "0.2", "--bound", "off", "--report", str(rep)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    report = json.loads(rep.read_text())
    assert report["parameters"]["bound"] is False and report["parameters"]["reduce"] is True
    assert report["refiner"]["levels"][-1]["over_zeta"] > 0  # the levels alone do not reach 0.2
    assert report["errors"]["e_max_normal"] > 0.2
    r = subprocess.run([sys.executable, "-m", "wavemesh", "mesh", str(tmp_path / "ball.npy"), "-o", str(out),
                        "--bound", "maybe"], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "error:" in r.stderr


def _table_5_7_runs(name: str, wavelet: str) -> list[tuple[int, float]]:
    """Table 5.7's runs as docs/refiner.md makes them (firmware/tools/make_refiner_doc.py: the data, its
    parameters, Jacksboro's tolerance at the paper's operating point and why): (triangles, E_max normal)."""
    if name == "Jacksboro":
        pytest.importorskip("matplotlib.cbook")
    sys.path.insert(0, str(ROOT / "firmware" / "tools"))
    try:
        import make_refiner_doc as doc
    finally:
        sys.path.remove(str(ROOT / "firmware" / "tools"))
    make, kw = doc.TABLE_5_7_RUNS[name]
    hf = from_array(make())
    out = []
    for d, *_ in doc.PAPER_5_7:
        params = native.RefineParams(delta_d=d, bound=False, **kw)
        mesh = api.refine(hf, 5, None, params, wavelet=wavelet).mesh
        out.append((mesh.n_triangles, mesh_errors(mesh, hf.values).e_max_normal))
    return out


# Table 5.7's trend with the levels alone: as delta_d runs over 0.1 .. 10 fewer cells are energetic, so the
# levels stop short of zeta by more (the paper's E_max 2 -> 30.5 at zeta 2), with fewer triangles.  delta_d is
# the detail's energy per sample over zeta^2 (region.c, native.fixed_params).  The triangle counts fall far
# less than the paper's 3.5x: every level refines a triangle over zeta where a cell is energetic, and
# Jacksboro's coarse details are energetic at every delta_d of the range (docs/refiner.md, Table 5.7).
@pytest.mark.parametrize("name,wavelet", [("Ball", "haar"), ("Ball", "spline"),
                                          ("Jacksboro", "haar"), ("Jacksboro", "spline")])
def test_table_5_7_error_grows_with_delta_d(name, wavelet):
    runs = _table_5_7_runs(name, wavelet)
    counts, errors = [r[0] for r in runs], [r[1] for r in runs]
    zeta = 1.0 if name == "Ball" else 4.0
    assert errors[0] <= zeta + 1e-9, errors
    assert np.all(np.diff(errors) >= -1e-9), errors
    assert errors[-1] > 2 * zeta, errors
    assert counts[-1] < counts[0], counts


def test_delta_d_is_relative_to_the_tolerance():
    """delta_d's threshold is 16 delta_d zeta^2 / s^2 rounded down, at every level (region.c): heights and
    zeta in another unit give the same threshold in sample counts."""
    p = native.RefineParams(delta_d=0.5, zeta=2.0)
    assert native.fixed_params(p, 0.25).delta_d == 16 * 0.5 * 4 * 16
    q = native.RefineParams(delta_d=0.5, zeta=2000.0)
    assert native.fixed_params(q, 250.0).delta_d == native.fixed_params(p, 0.25).delta_d
    assert native.fixed_params(p, 0.25, zeta=4.0).delta_d == 4 * native.fixed_params(p, 0.25).delta_d
    assert native.fixed_params(native.RefineParams(delta_d=0.1, zeta=1.0), 3.0).delta_d == 0  # floor(1.6 / 9)
    assert native.fixed_params(native.RefineParams(delta_d=1e30, zeta=1e9), 1e-9).delta_d == 2**64 - 1
