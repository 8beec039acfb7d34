"""Whole refinements in the checking build (asserts, the invariant check after every operator,
AddressSanitizer, UndefinedBehaviorSanitizer) through the file-driven runner tests/firmware/wm_run.c;
the meshes are identical, slot for slot, to the release library's (-O0 and -O2 agree bit for bit, and
so do 16-bit indices, the checking build's, and 32-bit ones).  And the host library's own AVX2 scans
(firmware/host/host_scan.c) in that build, against the C scan (tests/firmware/wm_scan_check.c)."""

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from wavemesh import api
from wavemesh.check import check_mesh
from wavemesh.harness.fwio import read_output, write_input
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import decompose
from wavemesh.refine import native

CASES = [
    ("ball", lambda rng: synth.ball(48), 3, native.RefineParams(zeta=0.5, iterations=3), None),
    ("box", lambda rng: synth.box(40), 3, native.RefineParams(zeta=0.0, metric="vertical",
                                                              neighbourhood="vertex"), None),
    ("noise", lambda rng: rng.integers(0, 500, size=(23, 37)).astype(float), 2,
     native.RefineParams(zeta=30, alpha=0.2, iterations=2, delta_v=3), None),
    ("budget", lambda rng: rng.integers(0, 500, size=(31, 29)).astype(float), 4,
     native.RefineParams(zeta=1, max_triangles=150, alpha=1.0), None),
    # 1500 triangle slots: 64 of the regularisation's swap records (refine.c, vert_cap / 7), so some
    # swap backs find their record taken by a later swap and test the edge as any (5 % of them here;
    # none in the cases above, whose records are more); the checking build asserts each record's E(T),
    # worst sample and angle, and the mesh must be the library's, whose capacity is the default
    ("swap_records", lambda rng: synth.ball(64), 3,
     native.RefineParams(zeta=0.2, alpha=0.6, iterations=3), 1500),
]


def write_case(make, levels, params, path, cap=None):
    """A case's runner input (tests/firmware/wm_run.c) written to ``path`` with ``cap`` triangle slots
    (None: the grid's full triangulation's): its height field and initial mesh (returned: the height
    field and the initial job)."""
    hf = from_array(make(np.random.default_rng(5)))
    job = api.triangulate(hf, levels)
    fp = native.fixed_params(params, hf.scale)
    det = native.details_array(decompose(hf.samples, levels))
    cap = cap or max(2 * (hf.width - 1) * (hf.height - 1), 8)
    write_input(path, hf.samples, det, levels, job.mesh, fp, cap)
    return hf, job


@pytest.mark.parametrize("name,make,levels,params,cap", CASES, ids=[c[0] for c in CASES])
def test_refine_under_sanitizers(name, make, levels, params, cap, check_build, release_build, tmp_path):
    hf, job = write_case(make, levels, params, tmp_path / "in.bin", cap)
    meshes = []
    for build in (check_build, release_build):
        r = subprocess.run([str(build / "wm_run"), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stdout + r.stderr
        assert "runtime error" not in r.stderr and "Sanitizer" not in r.stderr, r.stderr
        meshes.append(read_output(tmp_path / "out.bin", hf.width, hf.height))
    assert check_mesh(meshes[0]).valid
    via_ctypes = native.refine(hf.samples, decompose(hf.samples, levels), job.mesh, params, scale=hf.scale)
    for m in meshes[1:] + [via_ctypes.final.mesh]:
        np.testing.assert_array_equal(m.xy, meshes[0].xy)
        np.testing.assert_array_equal(m.tris, meshes[0].tris)


def test_host_scans_under_sanitizers(check_build, tmp_path):
    """host_scan.c's AVX2 scans, which only the host's shared library has (the runner above keeps the C
    scan), in the checking build's shared library with ASan and UBSan: tests/firmware/wm_scan_check.c
    compares them with the C scan on random triangles of grids allocated to their last sample (E(T), the
    worst sample, the stop at a bound; the 32-bit lanes, the boxes and the 64-bit blocks)."""
    native.build(check_build, "Debug", ("-DWM_SANITIZE=ON", "-DWM_INDEX_BITS=16"),
                 targets=("wavemesh_shared",))
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "a C compiler builds the check"
    here = Path(__file__).resolve().parent
    firmware = here.parents[1] / "firmware"
    exe = tmp_path / "wm_scan_check"
    subprocess.run([cc, "-g", "-fsanitize=address,undefined", "-fno-sanitize-recover=all",
                    "-DWM_INDEX_BITS=16", "-I", str(firmware / "include"), "-I", str(firmware / "src"),
                    "-I", str(native.GEN),
                    str(here / "wm_scan_check.c"), "-o", str(exe), "-L", str(check_build), "-lwavemesh",
                    f"-Wl,-rpath,{check_build}"], check=True, capture_output=True)
    r = subprocess.run([str(exe), "200000"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "runtime error" not in r.stderr and "Sanitizer" not in r.stderr, r.stderr
    checked, narrow = (int(v) for v in re.fullmatch(r"(\d+) triangles \((\d+) at most 8 samples wide\), 0 "
                                                     r"differences\n", r.stdout).groups())
    assert checked > 50000 and narrow > 20000, r.stdout


@pytest.mark.parametrize("cap,fails_at", [(40, "init"), (120, "level")])
def test_capacity_error_frees_everything(cap, fails_at, check_build, tmp_path):
    """A job that runs out of triangle slots, in the checking build with LeakSanitizer on: refused at
    wm_refine_init (40 slots, fewer than the initial mesh's triangles: no output) or at a level (120: the
    mesh kept is written), the runner reports the capacity error and leaks nothing; and a truncated input
    (exit status 2) leaks nothing either."""
    write_case(lambda rng: synth.ball(48), 3, native.RefineParams(zeta=0.5, iterations=3),
               tmp_path / "in.bin", cap)
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1")
    r = subprocess.run([str(check_build / "wm_run"), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
                       capture_output=True, text=True, timeout=300, env=env)
    assert "Sanitizer" not in r.stderr and "runtime error" not in r.stderr, r.stderr
    assert r.returncode == 1, r.stdout + r.stderr
    assert f"error {native.WM_ERR_CAPACITY} " in r.stdout, r.stdout
    assert (tmp_path / "out.bin").exists() == (fails_at == "level")
    data = (tmp_path / "in.bin").read_bytes()
    (tmp_path / "short.bin").write_bytes(data[:len(data) // 2])
    r = subprocess.run([str(check_build / "wm_run"), str(tmp_path / "short.bin"), str(tmp_path / "o2.bin")],
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 2 and "Sanitizer" not in r.stderr, r.stdout + r.stderr
