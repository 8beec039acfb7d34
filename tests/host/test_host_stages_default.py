"""firmware/host/host_stages.c's passes as a processor without AVX2 runs them: the library's passes are
compiled twice (target_clones "avx2" and "default") and the loader picks the AVX2 one wherever the
processor has it, so the other is never run by the rest of the tests here.  This file builds
host_stages.c alone with WM_NO_CLONES (the default's code only), puts it in place of the library's host
stages (native.host_lib) and compares: the quantisation, its error, and whole meshes with their checks
and error measures, bit for bit."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import types
from pathlib import Path

import numpy as np
import pytest
from test_host_stages import ALL
from wavemesh import api
from wavemesh.check import mesh_errors
from wavemesh.io.heightfield import from_array
from wavemesh.refine import native

FIRMWARE = Path(__file__).resolve().parents[2] / "firmware"


@pytest.fixture(scope="module")
def default_lib(tmp_path_factory):
    """host_stages.c without the AVX2 clone (the flags of CMakeLists.txt's wm_host, Release)."""
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "a C compiler builds the library"
    out = tmp_path_factory.mktemp("default") / "libhost_default.so"
    subprocess.run([cc, "-O3", "-DNDEBUG", "-shared", "-fPIC", "-ffp-contract=off", "-DWM_NO_CLONES",
                    "-I", str(FIRMWARE / "include"), str(FIRMWARE / "host" / "host_stages.c"), "-o", str(out),
                    "-pthread", "-lm"], check=True, capture_output=True)
    lib = ctypes.CDLL(str(out))

    class Present:  # native's declarations of the functions this library has
        def __getattr__(self, name):
            return getattr(lib, name) if hasattr(lib, name) else types.SimpleNamespace()

    native._declare(Present())
    return lib


def _bits(a) -> list[int]:
    return np.asarray(a, dtype=np.float64).view(np.int64).tolist()


def _run(v: np.ndarray) -> tuple:
    q = native.quantise(v)
    hf = from_array(v)
    span = float(v.max() - v.min())
    r = api.mesh(hf, api.MeshParams(refine=native.RefineParams(zeta=0.01 * span or 1.0)))
    e = mesh_errors(r.mesh, hf.values, rms=True, spacing=(1.0, 2.0))
    return (q if isinstance(q, str) else (q[0].tobytes(), _bits(q[1:])),
            native.quant_error(v, hf.samples, hf.offset, hf.scale), r.mesh.xy.tolist(),
            r.mesh.tris.tolist(), r.rows, _bits(e.per_triangle_vertical), _bits(e.per_triangle_normal),
            e.rms_vertical, e.rms_normal)


@pytest.mark.parametrize("name", sorted(ALL))
def test_default_clone_equals_the_library(name, default_lib, monkeypatch):
    v = ALL[name]
    got = []
    for lib in (native.host_lib(), default_lib):
        monkeypatch.setattr(native, "_HOST", lib)
        for n in (1, 3):
            native.set_threads(n)
            got.append(_run(v))
    native.set_threads(None)
    assert got[0] == got[1] == got[2] == got[3]
