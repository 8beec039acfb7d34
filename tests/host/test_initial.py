"""Labeller and initial triangulation: the paper's numbers, hand-built cases, random fields."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wavemesh.check import check_mesh
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import HaarLevel
from wavemesh.model.initial import initial_triangulation
from wavemesh.model.label import block_edges, dominant_labels, tau_counts
from wavemesh.model.templates import LABELS


def run(values, levels, tau=None):
    hf = from_array(values)
    if tau is None:
        tau = 0.01 * float(values.max() - values.min())
    return initial_triangulation(hf.samples, levels, tau_counts(tau, hf.scale))


def test_table_3_1_parabolic_exact():
    r = run(synth.f2(), 4)
    assert (r.mesh.n_vertices, r.mesh.n_triangles) == (153, 256)
    assert set("".join(r.to_report()["label_table"])) == {"V"}


def test_table_3_1_elliptic_matches_the_paper():
    r = run(synth.f1(), 4)
    assert (r.mesh.n_vertices, r.mesh.n_triangles) == (159, 276)


@pytest.mark.parametrize("name", ["f1", "f2", "f3", "f4", "f5", "ball", "box"])
def test_synthetic_sets_give_proper_meshes(name):
    v = synth.make(name)
    r = run(v, 4 if v.shape[0] == 128 else 5)
    res = check_mesh(r.mesh)
    assert res.valid and res.euler_ok, res.problems


def level_of(d1, d2, d3, m=1):
    d1, d2, d3 = (np.asarray(x, dtype=np.int64) for x in (d1, d2, d3))
    return HaarLevel(m, np.zeros_like(d1), d1, d2, d3)


def test_dominant_labels_rules():
    # columns: V, v (d1*d2 < 0), H, h, D, F (below tau), f (below tau, sign), tie d1 == d2 -> V
    d1 = [[9, 9, 2, -2, 1, 1, -1, 5]]
    d2 = [[1, -1, 9, 9, 1, 1, 1, 5]]
    d3 = [[0, 0, 0, 0, 9, 0, 0, 5]]
    got = dominant_labels(level_of(d1, d2, d3), 3, (1, 8))
    assert "".join(LABELS[c] for c in got[0]) == "VvHhDFfV"
    # threshold is strict: |d| == tau is not dominant
    assert LABELS[dominant_labels(level_of([[3]], [[0]], [[0]]), 3, (1, 1))[0, 0]] == "F"


def test_tau_counts():
    assert tau_counts(1.0, 1.0) == 2  # |d| > 2 counts means the half means differ by more than 1
    assert tau_counts(0.75, 0.5) == 3
    assert tau_counts(0.0, 0.25) == 0
    assert tau_counts(1e30, 1e-6) == (1 << 18) - 1
    with pytest.raises(ValueError):
        tau_counts(-1.0, 1.0)


def test_block_edges():
    assert block_edges(128, 16).tolist() == [0, 16, 32, 48, 64, 80, 96, 112, 127]
    assert block_edges(129, 16).tolist() == [0, 16, 32, 48, 64, 80, 96, 112, 128]
    assert block_edges(2, 16).tolist() == [0, 1]
    assert block_edges(18, 16).tolist() == [0, 16, 17]


def test_narrow_blocks_are_demoted():
    # W = 18 with S = 16: the last block column is 1 step wide; a V there would need a midpoint.
    values = np.zeros((33, 18))
    values[:, 17] = 1000.0  # a cliff inside the narrow column
    values[:, 9:] += 500.0
    r = run(values, 4, tau=1.0)
    labels = r.labelling.label
    assert LABELS[labels[0, 0]] in "Vv"
    assert all(LABELS[c] in "Ff" for c in labels[:, 1])
    assert check_mesh(r.mesh).valid


def test_variants_resolve_neighbours():
    # A vertical cliff in block (0,0) and a horizontal one in block (0,1): pi_v beside pi_h.
    values = np.zeros((33, 33))
    values[:16, 8:16] = 100.0
    values[8:16, 16:32] = 100.0
    r = run(values, 4, tau=1.0)
    lab = r.labelling
    assert "".join(LABELS[c] for c in lab.label[0]) in ("VH", "Vh", "vH", "vh")
    assert lab.mask[0, 0] & 4 and lab.mask[0, 1] & 2  # shared side split on both sides
    assert lab.mask[1, 0] & 1 and lab.mask[1, 1] == 0  # the block under the V gets its top split
    assert check_mesh(r.mesh).valid


fields = st.sampled_from(["noise", "steps", "smooth", "flat", "cliffs"])


def make_field(kind, h, w, rng):
    j, i = np.meshgrid(np.arange(w), np.arange(h))
    if kind == "noise":
        return rng.normal(size=(h, w)) * rng.uniform(0.1, 1000)
    if kind == "steps":
        return np.round(rng.uniform(0, 50, size=(h, w)) / 10) * 10
    if kind == "smooth":
        return np.sin(j / rng.uniform(2, 40)) * np.cos(i / rng.uniform(2, 40)) * 100
    if kind == "flat":
        return np.full((h, w), 7.0)
    return ((j * rng.uniform(-1, 1) + i * rng.uniform(-1, 1)) > 0) * 100.0 + rng.integers(0, 3, (h, w))


@settings(max_examples=150, deadline=None)
@given(h=st.integers(2, 90), w=st.integers(2, 90), levels=st.integers(1, 8), kind=fields,
       tau=st.sampled_from([None, 0.0, 1e-3, 5.0, 1e9]), seed=st.integers(0, 2**31))
def test_random_fields_give_proper_meshes(h, w, levels, kind, tau, seed):
    values = make_field(kind, h, w, np.random.default_rng(seed))
    r = run(values, levels, tau)
    res = check_mesh(r.mesh)
    assert res.valid and res.euler_ok, res.problems
    xy = r.mesh.xy
    corners = {(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)}
    assert corners <= set(map(tuple, xy.tolist()))


@pytest.mark.parametrize("shape", [(2, 2), (3, 1000), (1000, 3), (2, 3), (97, 101), (257, 129), (511, 2)])
@pytest.mark.parametrize("levels", [1, 3, 7])
def test_awkward_sizes(shape, levels):
    rng = np.random.default_rng(sum(shape) + levels)
    values = rng.integers(0, 5000, size=shape).astype(float)
    r = run(values, levels, tau=0.0)
    assert check_mesh(r.mesh).valid


def test_deterministic():
    v = synth.ball()
    a, b = run(v, 5), run(v.copy(), 5)
    assert np.array_equal(a.mesh.xy, b.mesh.xy) and np.array_equal(a.mesh.tris, b.mesh.tris)


def _assemble_block_by_block(lab, width, height):
    """The assembly written out block by block, site by site (the model of initial.assemble's arrays)."""
    from wavemesh.mesh import Mesh
    from wavemesh.model.templates import template_set

    ts, tris_xy = template_set(), []
    for j in range(lab.label.shape[0]):
        y0, y1 = int(lab.ys[j]), int(lab.ys[j + 1])
        ry = (y0, y0 + (y1 - y0) // 2, y1)
        for i in range(lab.label.shape[1]):
            x0, x1 = int(lab.xs[i]), int(lab.xs[i + 1])
            rx = (x0, x0 + (x1 - x0) // 2, x1)
            for tri in ts.templates[lab.template[j, i]].triangles:
                tris_xy.append([(rx[s % 3], ry[s // 3]) for s in tri])
    pts = np.asarray(tris_xy, dtype=np.int64).reshape(-1, 2)
    uniq, inverse = np.unique(pts[:, 1] * width + pts[:, 0], return_inverse=True)
    xy = np.stack([uniq % width, uniq // width], axis=1)
    return Mesh(width, height, xy, inverse.reshape(-1, 3)).canonical()


@pytest.mark.parametrize("shape", [(128, 128), (91, 120), (33, 200), (7, 9)])
def test_assembly_equals_the_block_by_block_model(shape):
    rng = np.random.default_rng(shape[0])
    v = np.cumsum(np.cumsum(rng.normal(0, 1, shape), 0), 1)
    for levels in (1, 2, 3, 4):
        r = run(v, levels)
        ref = _assemble_block_by_block(r.labelling, shape[1], shape[0])
        assert np.array_equal(r.mesh.xy, ref.xy) and np.array_equal(r.mesh.tris, ref.tris)
