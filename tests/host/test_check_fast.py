"""The sped-up checker and error metrics (wavemesh.check) against the versions they replaced
(check_reference.py, kept verbatim): the same verdicts, the same problem lines and the same error
values, bit for bit, on random valid and broken meshes, and on each fallback path."""

from __future__ import annotations

import math

import check_reference as ref
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_check import cut_mesh, fan_mesh, grid_mesh, random_cut_mesh
from wavemesh import api, check
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.mesh import Mesh


def assert_same_check(mesh: Mesh) -> check.CheckResult:
    new, old = check.check_mesh(mesh), ref.check_mesh(mesh)
    assert (new.valid, new.problems, new.n_vertices, new.n_triangles, new.n_border, new.euler_ok) == (
        old.valid, old.problems, old.n_vertices, old.n_triangles, old.n_border, old.euler_ok)
    return new


def _same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def assert_same_errors(mesh: Mesh, heights: np.ndarray, z=None, **kw) -> check.ErrorReport:
    new, old = check.mesh_errors(mesh, heights, z, **kw), ref.mesh_errors(mesh, heights, z, **kw)
    for name in ("e_max_vertical", "e_max_normal", "rms_vertical", "rms_normal", "e_total_normal",
                 "e_mean_normal"):
        assert _same(getattr(new, name), getattr(old, name)), (name, getattr(new, name), getattr(old, name))
    assert new.n_uncovered == old.n_uncovered
    np.testing.assert_array_equal(new.per_triangle_vertical, old.per_triangle_vertical)
    np.testing.assert_array_equal(new.per_triangle_normal, old.per_triangle_normal)
    assert new.to_report() == old.to_report()
    maxima = check.mesh_errors(mesh, heights, z, rms=False, **kw)  # the maxima alone: the same numbers
    for name in ("e_max_vertical", "e_max_normal", "e_total_normal", "e_mean_normal"):
        assert _same(getattr(maxima, name), getattr(old, name)), name
    np.testing.assert_array_equal(maxima.per_triangle_vertical, old.per_triangle_vertical)
    np.testing.assert_array_equal(maxima.per_triangle_normal, old.per_triangle_normal)
    assert math.isnan(maxima.rms_vertical) and math.isnan(maxima.rms_normal) and maxima.n_uncovered == -1
    return new


# ---------------------------------------------------------------------------------------------
# Meshes: valid ones, and every kind of damage


def valid_meshes(rng: np.random.Generator) -> list[Mesh]:
    w, h = int(rng.integers(2, 30)), int(rng.integers(2, 30))
    meshes = [grid_mesh(w, h, rng), random_cut_mesh(rng, 20)]
    if w > 2 and h > 2:
        meshes.append(fan_mesh(w, h, (int(rng.integers(1, w - 1)), int(rng.integers(1, h - 1)))))
    return meshes


def damaged(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """One random kind of damage (some of them may leave the mesh valid, which is fine)."""
    xy, tris = mesh.xy.copy(), mesh.tris.copy()
    T, V = len(tris), len(xy)
    kind = int(rng.integers(0, 11))
    t = int(rng.integers(0, T))
    if kind == 0:  # a hole
        tris = np.delete(tris, t, axis=0)
    elif kind == 1:  # a clockwise triangle
        tris[t] = tris[t, ::-1]
    elif kind == 2:  # an overlap
        tris = np.vstack([tris, tris[t]])
    elif kind == 3:  # a moved vertex (perhaps outside, perhaps onto another)
        xy[int(rng.integers(0, V))] += rng.integers(-3, 4, 2)
    elif kind == 4:  # an index out of range
        tris[t, int(rng.integers(0, 3))] = V + int(rng.integers(0, 3)) if rng.random() < 0.7 else -1
    elif kind == 5:  # a degenerate triangle
        tris[t, 2] = tris[t, 1]
    elif kind == 6:  # an unused vertex
        xy = np.vstack([xy, rng.integers(0, [mesh.width, mesh.height], size=(1, 2))])
    elif kind == 7:  # a coincident vertex, used instead of its twin
        i = int(tris[t, 0])
        xy = np.vstack([xy, xy[i:i + 1]])
        tris[t, 0] = V
    elif kind == 8:  # random triangles
        tris = rng.integers(0, V, size=(max(1, T // 2), 3))
    elif kind == 9:  # a swapped pair of vertices in two triangles
        u = int(rng.integers(0, T))
        tris[t, 0], tris[u, 1] = tris[u, 1], tris[t, 0]
    else:  # the wrong grid size
        return Mesh(mesh.width + int(rng.integers(-1, 2)), mesh.height + 1, xy, tris)
    return Mesh(mesh.width, mesh.height, xy, tris)


@pytest.mark.parametrize("seed", range(40))
def test_check_equals_reference_on_valid_and_damaged_meshes(seed):
    rng = np.random.default_rng(seed)
    for mesh in valid_meshes(rng):
        assert assert_same_check(mesh).valid
        for _ in range(6):
            assert_same_check(damaged(mesh, rng))


def test_check_equals_reference_on_special_cases():
    t_mesh = Mesh(3, 3, [(0, 0), (1, 0), (2, 0), (0, 2), (1, 2), (2, 2), (1, 1), (2, 1)],
                  [(0, 1, 4), (0, 4, 3), (1, 2, 7), (1, 7, 6), (6, 7, 5), (6, 5, 4)])
    assert not assert_same_check(t_mesh).valid  # T-junctions
    assert not assert_same_check(Mesh(1, 5, np.zeros((0, 2)), np.zeros((0, 3)))).valid
    assert not assert_same_check(Mesh(3, 3, [(0, 0), (2, 0), (2, 2)], np.zeros((0, 3)))).valid
    far = Mesh(3, 3, [(0, 0), (2, 0), (2, 2), (1 << 40, 0)], [(0, 1, 2), (0, 1, 3)])
    assert not assert_same_check(far).valid
    grid = cut_mesh(40, 40, range(40), range(40), None)
    assert not assert_same_check(Mesh(40, 40, grid.xy, grid.tris[:, ::-1])).valid
    rng = np.random.default_rng(3)  # random triangles: more problems than the list keeps
    junk = Mesh(40, 40, grid.xy, rng.integers(0, 1600, size=(500, 3)))
    assert len(assert_same_check(junk).problems) >= 20


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(w=st.integers(2, 12), h=st.integers(2, 12), seed=st.integers(0, 2**32 - 1),
       points=st.lists(st.tuples(st.integers(-2, 13), st.integers(-2, 13)), min_size=0, max_size=30),
       tris=st.lists(st.tuples(st.integers(-1, 40), st.integers(-1, 40), st.integers(-1, 40)),
                     min_size=0, max_size=40))
def test_check_equals_reference_on_arbitrary_meshes(w, h, seed, points, tris):
    rng = np.random.default_rng(seed)
    assert_same_check(Mesh(w, h, np.array(points, dtype=np.int64).reshape(-1, 2),
                           np.array(tris, dtype=np.int64).reshape(-1, 3)))
    assert_same_check(damaged(random_cut_mesh(rng, 12), rng))


@pytest.mark.parametrize("seed", range(25))
def test_errors_equal_reference(seed):
    rng = np.random.default_rng(100 + seed)
    for mesh in valid_meshes(rng):
        heights = rng.normal(size=(mesh.height, mesh.width)) * 10 ** float(rng.integers(-3, 5))
        assert_same_errors(mesh, heights)
        assert_same_errors(mesh, np.round(heights))
        assert_same_errors(mesh, heights, rng.normal(size=mesh.n_vertices))
        for budget in (1, 5, 64):
            assert_same_errors(mesh, heights, point_budget=budget)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(w=st.integers(2, 12), h=st.integers(2, 12), seed=st.integers(0, 2**32 - 1),
       points=st.lists(st.tuples(st.integers(-3, 14), st.integers(-3, 14)), min_size=3, max_size=25),
       tris=st.lists(st.tuples(st.integers(0, 24), st.integers(0, 24), st.integers(0, 24)), min_size=1,
                     max_size=30),
       budget=st.sampled_from([1, 3, 17, 1 << 20]))
def test_errors_equal_reference_on_arbitrary_meshes(w, h, seed, points, tris, budget):
    """Overlaps, holes, clockwise and degenerate triangles, vertices outside the grid (own z)."""
    rng = np.random.default_rng(seed)
    xy = np.array(points, dtype=np.int64)
    t = np.array(tris, dtype=np.int64) % len(xy)
    heights = rng.normal(size=(h, w)) * 100
    assert_same_errors(Mesh(w, h, xy, t), heights, rng.normal(size=len(xy)), point_budget=budget)


def test_errors_equal_reference_on_real_meshes():
    """The initial and refined meshes of the synthetic sets: several chunks of rows and samples."""
    for values in (synth.ball(96), synth.f5()):
        hf = from_array(values)
        job = api.triangulate(hf, 4)
        assert_same_errors(job.mesh, hf.values)
        assert_same_errors(job.mesh, hf.values, point_budget=1000)
        assert_same_check(job.mesh)
        rjob = api.refine(hf, 4, None, None, check_levels=True)
        for lv in rjob.output.levels:
            assert_same_check(lv.mesh)
            assert_same_errors(lv.mesh, hf.values, point_budget=3000)
        assert_same_errors(rjob.mesh, hf.values)


def test_fallback_paths_equal_reference(monkeypatch):
    """Sort keys too wide (many vertices, huge bounding boxes), numerators too large for the float
    floor, T-junctions looked up without the occupancy grid: the slow paths give the same answers."""
    rng = np.random.default_rng(5)
    meshes = [m for _ in range(4) for m in valid_meshes(rng)]
    meshes += [damaged(m, rng) for m in meshes for _ in range(3)]
    monkeypatch.setattr(check, "_KEY_LIMIT", 2)
    monkeypatch.setattr(check, "_GRID_LOOKUP_LIMIT", 0)
    monkeypatch.setattr(check, "_FLOAT_FLOOR_LIMIT", 0)
    monkeypatch.setattr(check, "_SAMPLE_KEY_LIMIT", 0)
    for mesh in meshes:
        assert_same_check(mesh)
        if check.check_mesh(mesh).valid:
            heights = rng.normal(size=(mesh.height, mesh.width))
            assert_same_errors(mesh, heights)
            assert_same_errors(mesh, heights, point_budget=7)



def test_vertex_by_vertex_t_junctions_equal_reference(monkeypatch):
    """Edges checked vertex by vertex (as edges through more lattice points than the mesh has vertices
    are), forced here for every edge: the same results as the reference."""
    rng = np.random.default_rng(7)
    meshes = [m for _ in range(3) for m in valid_meshes(rng)]
    meshes += [damaged(m, rng) for m in meshes for _ in range(4)]
    monkeypatch.setattr(check, "_LATTICE_PER_VERTEX", 0)
    for budget in (check._POINT_BUDGET, 7):
        monkeypatch.setattr(check, "_POINT_BUDGET", budget)
        for mesh in meshes:
            assert_same_check(mesh)
