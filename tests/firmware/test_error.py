"""E(T) in integers (firmware/src/tri_error.c) against the float metric of wavemesh.check.mesh_errors.

The rule (docs/refiner.md): the firmware's E(T) is an upper bound of the exact value, never below the
float metric by more than the float's own rounding, and above it by at most about 2^-15 relative plus
2^-16 sample counts."""

import numpy as np
import pytest
from wavemesh import api
from wavemesh.check import mesh_errors
from wavemesh.io.heightfield import from_array
from wavemesh.mesh import Mesh
from wavemesh.refine import native


def check_triangles(hf, mesh, metric):
    heights = hf.offset + hf.scale * hf.samples.astype(np.float64)  # what the firmware sees
    rep = mesh_errors(mesh, heights)
    want = rep.per_triangle_normal if metric == "normal" else rep.per_triangle_vertical
    for t, tri in enumerate(mesh.tris):
        x, y = mesh.xy[tri, 0], mesh.xy[tri, 1]
        got = native.tri_error(hf.samples, x, y, metric, hf.scale)
        assert got >= want[t] - 1e-9 * max(1.0, want[t]), (t, got, want[t])
        assert got <= want[t] * (1 + 2**-14) + 2**-15 * hf.scale, (t, got, want[t])


@pytest.mark.parametrize("metric", ["normal", "vertical"])
@pytest.mark.parametrize("seed", range(4))
def test_error_of_initial_triangles(metric, seed):
    rng = np.random.default_rng(seed)
    w, h = rng.integers(3, 60, size=2)
    kind = seed % 2
    if kind == 0:  # integer heights, lossless
        values = rng.integers(0, 3000, size=(h, w)).astype(np.float64)
    else:  # float heights: lossy 16-bit quantisation, scale far from 1
        values = rng.normal(0, 0.01, size=(h, w)).cumsum(axis=1)
    hf = from_array(values)
    job = api.triangulate(hf, int(rng.integers(1, 4)))
    check_triangles(hf, job.mesh, metric)


@pytest.mark.parametrize("metric", ["normal", "vertical"])
def test_error_of_thin_and_steep_triangles(metric):
    """Random lattice triangles, slivers included, on a field with cliffs of 65535."""
    rng = np.random.default_rng(7)
    w, h = 97, 61
    values = rng.integers(0, 65536, size=(h, w)).astype(np.float64)
    values[:, :3] = 0
    values[:, -3:] = 65535
    hf = from_array(values)
    tris, xy = [], []
    while len(tris) < 120:
        p = np.stack([rng.integers(0, w, 3), rng.integers(0, h, 3)], axis=1)
        a2 = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1])
        if a2 == 0:
            continue
        if a2 < 0:
            p = p[[0, 2, 1]]
        tris.append([len(xy), len(xy) + 1, len(xy) + 2])
        xy.extend(p.tolist())
    mesh = Mesh(w, h, np.array(xy), np.array(tris))  # not a triangulation: only its triangles count
    check_triangles(hf, mesh, metric)


@pytest.mark.parametrize("wavelet", ["haar", "spline"])
def test_c_filter_bank_matches_the_model(wavelet):
    from wavemesh.model.haar import decompose

    rng = np.random.default_rng(3)
    for w, h, m in ((1, 1, 1), (2, 3, 2), (17, 9, 4), (64, 33, 6), (5, 130, 3), (3, 2, 2)):
        samples = rng.integers(0, 65536, size=(h, w)).astype(np.uint16)
        np.testing.assert_array_equal(native.haar_details(samples, m, wavelet),
                                      native.details_array(decompose(samples, m, wavelet)))
