"""Selective triangulation (--roi, dissertation 5.6; wavemesh.model.roi, firmware/src/roi.c): inside the
region
of interest every sample is within zeta (checked here sample by sample, in exact integers, apart from
the library and from check.py); outside the mesh stays at the initial triangulation's coarseness; the
mesh is proper; an ROI of the whole grid changes nothing."""

import ctypes
from fractions import Fraction

import numpy as np
import pytest
from scipy import ndimage
from wavemesh import api
from wavemesh.check import check_mesh
from wavemesh.harness import run_cli
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import decompose
from wavemesh.model.roi import cell_mask, mask_details, roi_report
from wavemesh.refine import native
from wavemesh.refine.native import RefineParams

M = 4


def terrain(n=96, seed=7):
    """Rough integer heights (lossless: the refiner sees them as they are), 0 .. about 400."""
    rng = np.random.default_rng(seed)
    z = ndimage.gaussian_filter(rng.normal(size=(n, n + 16)), 3) * 900 + rng.normal(size=(n, n + 16)) * 2
    return np.round(z - z.min())


def roi_rect(shape):
    roi = np.zeros(shape, dtype=bool)
    roi[20:52, 30:70] = True
    return roi


def exact_errors_inside(mesh, samples, roi, scale):
    """The largest vertical distance, in height units, from an ROI sample to the plane of any triangle
    that holds it: exact edge functions, exact rational heights (independent of wavemesh's metrics)."""
    worst = Fraction(0)
    for tri in mesh.tris:
        (x0, y0), (x1, y1), (x2, y2) = mesh.xy[tri]
        d = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        assert d > 0
        gy, gx = np.mgrid[min(y0, y1, y2):max(y0, y1, y2) + 1, min(x0, x1, x2):max(x0, x1, x2) + 1]
        e0 = (x2 - x1) * (gy - y1) - (y2 - y1) * (gx - x1)
        e1 = (x0 - x2) * (gy - y2) - (y0 - y2) * (gx - x2)
        e2 = d - e0 - e1
        inside = (e0 >= 0) & (e1 >= 0) & (e2 >= 0) & roi[gy, gx]
        if not inside.any():
            continue
        z = [int(samples[y, x]) for x, y in ((x0, y0), (x1, y1), (x2, y2))]
        v = np.abs(e0 * z[0] + e1 * z[1] + e2 * z[2] - d * samples[gy, gx].astype(np.int64))[inside].max()
        worst = max(worst, Fraction(int(v), int(d)))
    return float(worst * Fraction(scale))


def far_outside(roi, m=M):
    """Samples more than one coarsest block (2^M) from the ROI (chessboard distance)."""
    return ndimage.distance_transform_cdt(~roi, metric="chessboard") > (1 << m)


def vertices_in(mesh, region):
    return int(np.count_nonzero(region[mesh.xy[:, 1], mesh.xy[:, 0]]))


@pytest.mark.parametrize("metric,zeta", [("vertical", 2.0), ("normal", 1.0)])
def test_bound_inside_coarse_outside(metric, zeta):
    hf = from_array(terrain())
    assert hf.lossless
    roi = roi_rect(hf.values.shape)
    p = api.MeshParams(levels=M, refine=RefineParams(zeta=zeta, metric=metric))
    sel = api.mesh(hf, api.MeshParams(levels=M, refine=p.refine, roi=roi))
    whole = api.mesh(hf, p)
    mesh = sel.mesh
    assert check_mesh(mesh).valid and sel.bound_met
    # inside: within zeta at every ROI sample (vertical distance bounds the normal one)
    e_in = exact_errors_inside(mesh, hf.samples, roi, hf.scale)
    assert e_in <= (zeta if metric == "vertical" else 1e9)
    r = sel.report["roi"]
    assert r["e_max_inside"] <= zeta * (1 + 1e-9)
    if metric == "vertical":
        assert abs(r["e_max_inside"] - e_in) <= 1e-9 * zeta  # check.py's measure agrees with the exact one
    # ... and not outside: the whole grid is far off, so the ROI really limited the work
    assert r["e_max_whole"] > 4 * zeta
    # outside: far from the ROI no more vertices than the initial triangulation had there
    far = far_outside(roi)
    initial = sel.level_meshes[0][1]
    assert vertices_in(mesh, far) <= vertices_in(initial, far)
    assert vertices_in(whole.mesh, far) > 5 * vertices_in(initial, far)  # the full run refines there
    # finer inside than outside, and inside about as fine as the full run
    area_in, area_out = roi.sum(), (~roi).sum()
    assert r["triangles_inside"] / area_in > 5 * r["triangles_outside"] / area_out
    full_in = roi_report(whole.mesh, roi, whole.errors, whole.errors, metric)["triangles_inside"]
    assert 0.5 * full_in <= r["triangles_inside"] <= 2 * full_in


def test_roi_of_the_whole_grid_changes_nothing():
    hf = from_array(terrain(64, seed=3))
    p = api.MeshParams(levels=M, refine=RefineParams(zeta=3.0))
    a = api.mesh(hf, p).mesh
    b = api.mesh(hf, api.MeshParams(levels=M, refine=p.refine, roi=np.ones(hf.values.shape, bool))).mesh
    assert a.same_as(b)


def test_mask_details_per_cell():
    rng = np.random.default_rng(1)
    samples = rng.integers(0, 4000, size=(37, 45))
    roi = np.zeros(samples.shape, bool)
    roi[5:9, 30:31] = True
    roi[36, 0] = True
    levels = decompose(samples, 4)
    masked = mask_details(levels, roi)
    for lv, mk in zip(levels, masked, strict=True):
        keep = cell_mask(roi, lv.m)
        for i, j in np.ndindex(keep.shape):
            block = roi[i << lv.m:(i + 1) << lv.m, j << lv.m:(j + 1) << lv.m]
            assert keep[i, j] == block.any()
        for d, dm in ((lv.d1, mk.d1), (lv.d2, mk.d2), (lv.d3, mk.d3)):
            if lv.m == len(levels):  # the initial triangulation's level is kept whole
                np.testing.assert_array_equal(dm, d)
            else:
                np.testing.assert_array_equal(dm, np.where(keep, d, 0))


def test_set_roi_refuses_bad_tables_and_late_calls():
    lib = native.load()
    hf = from_array(terrain(32, seed=2))
    h, w = hf.samples.shape
    job = api.triangulate(hf, 2)
    det = native.details_array(decompose(hf.samples, 2))
    samples = np.ascontiguousarray(hf.samples, dtype=np.uint16)
    fld = native.Field()
    fld.width, fld.height, fld.levels = w, h, 2
    fld.samples = samples.ctypes.data_as(ctypes.POINTER(ctypes.c_uint16))
    fld.details = det.ctypes.data_as(ctypes.POINTER(ctypes.c_int32))
    fp = native.fixed_params(RefineParams(), hf.scale)
    xy = np.ascontiguousarray(job.mesh.xy, dtype=np.int32)
    tris = np.ascontiguousarray(job.mesh.tris, dtype=np.int32)
    cap = lib.wm_tri_cap_max(w, h)
    mem = np.empty(lib.wm_refine_bound(w, h, cap) + 16, np.uint8)
    handle = ctypes.c_void_p()
    base = mem.ctypes.data + (-mem.ctypes.data) % 16
    assert lib.wm_refine_init(ctypes.byref(handle), ctypes.c_void_p(base), len(mem) - 16, ctypes.byref(fld),
                              ctypes.byref(fp), xy.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)), len(xy),
                              tris.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)), len(tris), cap) == 0
    good = native.roi_rows(np.ones((h, w), bool))
    ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_int32))  # noqa: E731
    for bad in (good + 1, np.where(np.arange(w + 1) == 3, 7, good).astype(np.int32)):  # row start, a jump
        assert lib.wm_refine_set_roi(handle, ptr(np.ascontiguousarray(bad, np.int32))) == -1  # WM_ERR_ARG
    assert lib.wm_refine_set_roi(handle, ptr(good)) == 0
    assert lib.wm_refine_step(handle, None) == 0
    assert lib.wm_refine_set_roi(handle, ptr(good)) == -5  # WM_ERR_STATE: refinement under way


def test_cli(tmp_path):
    hf = terrain(64, seed=4)
    np.save(tmp_path / "t.npy", hf)
    mask = np.zeros(hf.shape)
    mask[10:30, 40:60] = 1
    np.save(tmp_path / "mask.npy", mask)
    rc, out, err = run_cli("mesh", str(tmp_path / "t.npy"), "-o", str(tmp_path / "t.obj"), "--levels", "3",
                           "--roi", "0,0,20,20", "--roi", str(tmp_path / "mask.npy"), "--zeta", "2",
                           "--report", str(tmp_path / "t.json"))
    assert rc == 0, err
    assert "ROI: 800 samples" in out
    rc, out, err = run_cli("check", str(tmp_path / "t.obj"), "--against", str(tmp_path / "t.npy"), "--roi",
                           "0,0,20,20", "--roi", str(tmp_path / "mask.npy"))
    assert rc == 0 and "a proper triangulation" in out
    inside = float(out.split("inside the ROI: E_max normal ")[1].split(",")[0])
    whole = float(out.split("  E_max normal ")[1].split(",")[0])
    assert inside <= 2 * (1 + 1e-9) < whole  # within zeta inside the ROI only
    for bad, says in ((["--roi", "0,0,99,10"], "does not fit"), (["--roi", "nothing.png"], "no such file"),
                      (["--roi", "1,2,x,4"], "not four integers"),
                      (["--roi", "0,0,5,5", "--stage", "initial"], "--stage full")):
        rc, out, err = run_cli("mesh", str(tmp_path / "t.npy"), "-o", str(tmp_path / "u.obj"), *bad)
        assert rc != 0 and err.startswith("error: ") and says in err, err
        assert not (tmp_path / "u.obj").exists()
    np.save(tmp_path / "small.npy", mask[:10])
    rc, out, err = run_cli("mesh", str(tmp_path / "t.npy"), "-o", str(tmp_path / "u.obj"), "--roi",
                           str(tmp_path / "small.npy"))
    assert rc == 2 and "80 x 10 but the grid is 80 x 64" in err
    rc, out, err = run_cli("stream", str(tmp_path / "t.npy"), "-o", str(tmp_path / "u.obj"), "--roi",
                           "0,0,5,5", "--port", "socket://127.0.0.1:9")  # refused before any port is opened
    assert rc == 2 and "--roi" in err and "host only" in err


def test_doc_is_current():
    """docs/selective.md (ROI and de-noising) is what tools/make_selective_doc.py writes (`make docs`)."""
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location("doc", root / "tools" / "make_selective_doc.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert (root / "docs" / "selective.md").read_text() == mod.markdown(), "stale: run `make docs`"
    for picture in ("selective-left.png", "selective-right.png", "denoise-noisy.png", "denoise-sure.png"):
        assert (root / "docs" / picture).exists(), "run `make docs`"
