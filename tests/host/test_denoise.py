"""De-noising (--denoise, dissertation 5.5; wavemesh.refine.denoise): the SURE threshold is the minimiser of
Stein's risk estimate (against a brute-force scan), the transform inverts exactly, and on noisy synthetic
sets the heights and the mesh come closer to the clean surface with fewer triangles, the mesh proper and
within zeta of the de-noised heights."""

import numpy as np
import pytest
from wavemesh import api
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.harness import run_cli
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.refine.denoise import denoise_values, haar_forward, haar_inverse, sure_threshold
from wavemesh.refine.native import RefineParams

SIGMA = 2.0


def sure(x, t):
    """Stein's unbiased risk estimate of soft thresholding at t, unit noise, written out."""
    a = np.abs(x)
    return x.size - 2 * np.count_nonzero(a <= t) + np.sum(np.minimum(a, t) ** 2)


@pytest.mark.parametrize("seed", range(6))
def test_sure_threshold_minimises_the_risk(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 400))
    x = rng.normal(size=n) + np.where(rng.random(n) < rng.random(), rng.normal(scale=6, size=n), 0)
    t = sure_threshold(x)
    cap = np.sqrt(2 * np.log(n))
    assert 0 <= t <= cap
    grid = np.concatenate([np.linspace(0, cap, 2001), np.abs(x)[np.abs(x) <= cap]])
    assert sure(x, t) <= min(sure(x, s) for s in grid) + 1e-9


@pytest.mark.parametrize("shape,levels", [((37, 53), 4), ((64, 64), 5), ((5, 2), 1)])
def test_haar_inverts_and_keeps_energy(shape, levels):
    a = np.random.default_rng(1).normal(size=shape) * 100
    approx, details, shapes = haar_forward(a, levels)
    np.testing.assert_allclose(haar_inverse(approx, details, shapes), a, atol=1e-9)
    if shape == (64, 64):  # no padding: orthonormal
        energy = np.sum(approx**2) + sum(np.sum(d**2) for ds in details for d in ds)
        assert energy == pytest.approx(np.sum(a**2), rel=1e-12)


def test_noise_estimate():
    rng = np.random.default_rng(5)
    _, info = denoise_values(np.full((128, 96), 50.0) + rng.normal(scale=3.0, size=(128, 96)), "sure")
    assert info["sigma"] == pytest.approx(3.0, rel=0.1)


@pytest.mark.parametrize("name", ["box", "f1"])
def test_closer_to_the_clean_surface_with_fewer_triangles(name):
    clean = synth.box(128) if name == "box" else synth.f1(128, extent=np.pi)
    noisy = clean + np.random.default_rng(11).normal(scale=SIGMA, size=clean.shape)
    den, info = denoise_values(noisy, "sure")
    rms = lambda v: float(np.sqrt(np.mean((v - clean) ** 2)))  # noqa: E731
    assert rms(den) < 0.65 * rms(noisy)
    meshes = {}
    for tag, v in (("noisy", noisy), ("denoised", den)):
        hf = from_array(v)
        r = api.mesh(hf, api.MeshParams(refine=RefineParams(zeta=2 * SIGMA, metric="vertical")))
        assert check_mesh(r.mesh).valid and r.bound_met  # api.mesh also checked zeta against v
        e = mesh_errors(r.mesh, clean, z=r.mesh.z(v))
        meshes[tag] = (r.mesh.n_triangles, e.rms_vertical)
    assert meshes["denoised"][0] < meshes["noisy"][0] / 3
    assert meshes["denoised"][1] < 0.8 * meshes["noisy"][1]


def test_cli_mesh_and_check(tmp_path):
    clean = synth.ball(64)
    src = str(tmp_path / "n.npy")
    np.save(src, clean + np.random.default_rng(2).normal(scale=SIGMA, size=clean.shape))
    rc, out, err = run_cli("mesh", src, "-o", str(tmp_path / "n.obj"), "--denoise", "sure", "--zeta", "4",
                           "--report", str(tmp_path / "n.json"))
    assert rc == 0, err
    assert "de-noised: sure, sigma" in (tmp_path / "n.json").read_text()
    rc, out, err = run_cli("check", str(tmp_path / "n.obj"), "--against", src, "--denoise", "sure")
    assert rc == 0 and "a proper triangulation" in out, err
    # against the noisy heights the vertices are not the input's: check says so
    rc, out, err = run_cli("check", str(tmp_path / "n.obj"), "--against", src)
    assert rc == 1 and "do not carry the input height" in out
    rc, out, err = run_cli("mesh", src, "-o", str(tmp_path / "m.obj"), "--denoise", "wiener")
    assert rc == 2 and err.startswith("error: ") and not (tmp_path / "m.obj").exists()
