"""Tests for wavemesh.check: the validity checker and the error metrics."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.errors import InputError
from wavemesh.mesh import Mesh

# ---------------------------------------------------------------------------------------------
# Mesh builders (independent of the code under test)


def cut_mesh(w: int, h: int, xs, ys, rng: np.random.Generator | None) -> Mesh:
    """Vertices at the crossings of columns ``xs`` and rows ``ys``; each cell split by a random
    diagonal (always the one from its lower-left corner when ``rng`` is None)."""
    xs, ys = list(xs), list(ys)
    nx = len(xs)
    xy = [(x, y) for y in ys for x in xs]
    tris = []
    for j in range(len(ys) - 1):
        for i in range(nx - 1):
            a, b, c, d = j * nx + i, j * nx + i + 1, (j + 1) * nx + i, (j + 1) * nx + i + 1
            tris += [(a, b, d), (a, d, c)] if rng is None or rng.random() < 0.5 else [(a, b, c), (b, d, c)]
    return Mesh(w, h, np.array(xy), np.array(tris))


def grid_mesh(w: int, h: int, rng: np.random.Generator) -> Mesh:
    return cut_mesh(w, h, range(w), range(h), rng)


def random_cut_mesh(rng: np.random.Generator, max_size: int = 14) -> Mesh:
    w, h = int(rng.integers(2, max_size)), int(rng.integers(2, max_size))
    xs = sorted({0, w - 1, *rng.integers(0, w, int(rng.integers(0, w))).tolist()})
    ys = sorted({0, h - 1, *rng.integers(0, h, int(rng.integers(0, h))).tolist()})
    return cut_mesh(w, h, xs, ys, rng)


def fan_mesh(w: int, h: int, centre: tuple[int, int]) -> Mesh:
    """Every border sample joined to one inner vertex: long thin triangles whose edges pass
    through many lattice points that are not vertices."""
    ring = [(x, 0) for x in range(w - 1)] + [(w - 1, y) for y in range(h - 1)]
    ring += [(x, h - 1) for x in range(w - 1, 0, -1)] + [(0, y) for y in range(h - 1, 0, -1)]
    xy = ring + [centre]
    c = len(ring)
    tris = [(i, (i + 1) % c, c) for i in range(c)]
    return Mesh(w, h, np.array(xy), np.array(tris))


SQUARE = Mesh(2, 2, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 1, 2), (0, 2, 3)])


def problems_with(result, word: str) -> list[str]:
    return [p for p in result.problems if word in p]


# ---------------------------------------------------------------------------------------------
# Valid meshes


def test_two_triangle_square_is_valid():
    r = check_mesh(SQUARE)
    assert r.valid and r.problems == []
    assert (r.n_vertices, r.n_triangles, r.n_border, r.euler_ok) == (4, 2, 4, True)


@pytest.mark.parametrize("seed", range(12))
def test_random_grids_are_valid(seed):
    rng = np.random.default_rng(seed)
    w, h = int(rng.integers(2, 40)), int(rng.integers(2, 40))
    r = check_mesh(grid_mesh(w, h, rng))
    assert r.valid, r.problems
    assert r.n_border == 2 * (w + h) - 4 and r.n_triangles == 2 * (w - 1) * (h - 1) and r.euler_ok


@pytest.mark.parametrize("seed", range(12))
def test_random_cut_meshes_are_valid(seed):
    rng = np.random.default_rng(100 + seed)
    mesh = random_cut_mesh(rng, 30)
    # Shuffle both orders: validity does not depend on them.
    perm = rng.permutation(mesh.n_vertices)
    mesh = Mesh(mesh.width, mesh.height, mesh.xy[perm], np.argsort(perm)[mesh.tris][::-1])
    assert check_mesh(mesh).valid


@pytest.mark.parametrize("w, h, centre", [(9, 7, (4, 3)), (13, 5, (1, 1)), (6, 6, (3, 2)), (32, 21, (17, 4))])
def test_fan_meshes_are_valid(w, h, centre):
    r = check_mesh(fan_mesh(w, h, centre))
    assert r.valid, r.problems


# ---------------------------------------------------------------------------------------------
# Defects, each with its own hand-built mesh


def test_hole():
    rng = np.random.default_rng(1)
    full = grid_mesh(4, 3, rng)
    mesh = Mesh(4, 3, full.xy, np.delete(full.tris, 5, axis=0))
    r = check_mesh(mesh)
    assert not r.valid and not r.euler_ok
    assert problems_with(r, "holes")  # total area too small
    assert len(problems_with(r, "not on the border")) == 3  # the hole's three edges are unmatched


def test_overlapping_extra_triangle():
    rng = np.random.default_rng(2)
    full = grid_mesh(3, 3, rng)
    mesh = Mesh(3, 3, full.xy, np.vstack([full.tris, full.tris[3:4]]))
    r = check_mesh(mesh)
    assert not r.valid
    assert problems_with(r, "overlaps")
    assert len(problems_with(r, "directed edge")) >= 1


def test_overlap_with_correct_total_area():
    # Two triangles over the same square, stacked on the lower-left half: area adds up.
    mesh = Mesh(2, 2, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 1, 2), (0, 1, 3)])
    r = check_mesh(mesh)
    assert not r.valid
    assert not problems_with(r, "add up")
    assert problems_with(r, "directed edge 0->1")


def test_clockwise_triangle():
    rng = np.random.default_rng(3)
    full = grid_mesh(3, 3, rng)
    tris = full.tris.copy()
    tris[3] = tris[3][::-1]
    r = check_mesh(Mesh(3, 3, full.xy, tris))
    assert not r.valid
    cw = problems_with(r, "clockwise")
    assert len(cw) == 1 and cw[0].startswith("triangle 3 ") and "doubled area -1" in cw[0]


def test_degenerate_triangle():
    # A 3 x 2 rectangle triangulated with (0,0) (1,0) (2,0) (2,1) (0,1), plus a flat triangle on the
    # bottom edge: it has zero area, so the total area is still right.
    xy = [(0, 0), (1, 0), (2, 0), (2, 1), (0, 1)]
    good = [(0, 1, 4), (1, 3, 4), (1, 2, 3)]
    assert check_mesh(Mesh(3, 2, xy, good)).valid
    r = check_mesh(Mesh(3, 2, xy, good + [(0, 1, 2)]))
    assert not r.valid
    assert len(problems_with(r, "degenerate")) == 1 and problems_with(r, "triangle 3 ")
    assert not problems_with(r, "add up")


def test_t_junction():
    # Left column: one 1 x 2 rectangle in two triangles.  Right column: two 1 x 1 squares, so (1, 1)
    # is a vertex on the right only and lies inside the left column's edge (1, 0)-(1, 2).
    xy = [(0, 0), (1, 0), (2, 0), (0, 2), (1, 2), (2, 2), (1, 1), (2, 1)]
    tris = [(0, 1, 4), (0, 4, 3), (1, 2, 7), (1, 7, 6), (6, 7, 5), (6, 5, 4)]
    r = check_mesh(Mesh(3, 3, xy, tris))
    assert not r.valid
    tj = problems_with(r, "lies inside edge")
    assert tj == ["vertex 6 at (1, 1) lies inside edge 1-4 (1, 0)-(1, 2) (T-junction)"]
    assert not problems_with(r, "add up")  # the area is right


def test_t_junctions_on_edges_longer_than_the_mesh(monkeypatch):
    """An edge through more lattice points than the mesh has vertices is tested vertex by vertex: the
    same verdicts and lines as the lattice-point search (forced here for every edge)."""
    from wavemesh import check

    xy = [(0, 0), (1, 0), (2, 0), (0, 2), (1, 2), (2, 2), (1, 1), (2, 1), (1, 1)]  # 8: a second (1, 1)
    tris = [(0, 1, 4), (0, 4, 3), (1, 2, 7), (1, 7, 6), (6, 7, 5), (6, 5, 4), (8, 7, 6)]
    meshes = [Mesh(3, 3, xy[:8], tris[:6]), Mesh(3, 3, xy, tris), fan_mesh(31, 17, (12, 5)),
              fan_mesh(9, 40, (3, 30))]
    expected = [check_mesh(m).problems for m in meshes]
    monkeypatch.setattr(check, "_LATTICE_PER_VERTEX", 0)
    for budget in (check._POINT_BUDGET, 5, 1):
        monkeypatch.setattr(check, "_POINT_BUDGET", budget)
        assert [check_mesh(m).problems for m in meshes] == expected


def test_a_grid_of_any_size_is_checked_in_little_memory():
    """Coordinates may state any grid (a mesh file's do): 123 bytes of OBJ stating 55555551 x 3 once
    took check_mesh past 2.5 GB (the readers fuzzer's finding).  Checked here under a 1.5 GiB address
    space limit (numpy's own needs are far below), on the 2^30-wide grid the arithmetic allows."""
    import subprocess
    import sys

    code = """if 1:
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))
        from wavemesh.check import check_mesh
        from wavemesh.mesh import Mesh
        W = (1 << 30) + 1
        corners = [(0, 0), (W - 1, 0), (W - 1, 2), (0, 2)]
        print(check_mesh(Mesh(W, 3, corners, [(0, 1, 2), (0, 2, 3)])).problems)
        # a vertex inside the long bottom edge, and a triangle on it: a T-junction
        print(check_mesh(Mesh(W, 3, corners + [(7, 0)], [(0, 1, 2), (0, 2, 3), (0, 4, 2)])).problems)
        # the fuzzer's input: a degenerate triangle along a 55555551-wide, 1-high grid
        print(check_mesh(Mesh(55555551, 1, [(0, 0), (2, 0), (55555550, 0)], [(0, 1, 2)])).problems)
    """
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    valid, junction, fuzz = r.stdout.splitlines()
    assert valid == "[]"
    assert "vertex 4 at (7, 0) lies inside edge 0-1 (0, 0)-(1073741824, 0) (T-junction)" in junction
    assert "vertex 1 at (2, 0) lies inside edge 0-2 (0, 0)-(55555550, 0) (T-junction)" in fuzz
    assert "the grid is 55555551 x 1; a mesh needs at least 2 x 2 samples" in fuzz


def test_duplicate_vertex():
    # Vertex 4 is a second copy of (1, 1).
    mesh = Mesh(2, 2, [(0, 0), (1, 0), (1, 1), (0, 1), (1, 1)], [(0, 1, 2), (0, 4, 3)])
    r = check_mesh(mesh)
    assert not r.valid
    assert problems_with(r, "coincide") == ["vertices 2 and 4 coincide at (1, 1)"]


def test_vertex_outside():
    rng = np.random.default_rng(4)
    full = grid_mesh(4, 3, rng)
    r = check_mesh(Mesh(3, 3, full.xy, full.tris))  # the mesh of a 4 x 3 grid, claimed to be 3 x 3
    assert not r.valid
    out = problems_with(r, "outside")
    assert out[0] == "vertex 3 at (3, 0) is outside the grid rectangle [0, 2] x [0, 2]"
    assert len(out) == 3


def test_unused_vertex():
    mesh = Mesh(4, 3, [(0, 0), (3, 0), (3, 2), (0, 2), (1, 1)], [(0, 1, 2), (0, 2, 3)])
    r = check_mesh(mesh)
    assert not r.valid and not r.euler_ok
    assert r.problems[0] == "vertex 4 at (1, 1) is not used by any triangle"
    assert len(r.problems) == 2 and "Euler" in r.problems[1]


def test_index_out_of_range():
    mesh = Mesh(2, 2, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 1, 2), (0, 2, 7)])
    r = check_mesh(mesh)
    assert not r.valid
    assert problems_with(r, "triangle 1 refers to vertex 7, which does not exist")


def test_flipped_fold_with_correct_area():
    # A coarse 4 x 4 vertex grid with spacing 3; the inner vertex (3, 3) moved to (7, 5), across
    # the edge of its star.  The edges still match in opposite directions and the signed areas
    # still add up to the rectangle's, yet the mesh folds over itself.
    sp = 3
    coords = [0, sp, 2 * sp, 3 * sp]
    mesh = cut_mesh(10, 10, coords, coords, None)
    xy = mesh.xy.copy()
    k = int(np.flatnonzero((xy[:, 0] == sp) & (xy[:, 1] == sp))[0])
    xy[k] = (7, 5)
    folded = Mesh(10, 10, xy, mesh.tris)
    p = xy[folded.tris]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    signed = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
    assert signed.sum() == 2 * 9 * 9 and (signed < 0).any()  # the premise of the test
    r = check_mesh(folded)
    assert not r.valid
    assert r.problems and all("clockwise" in q for q in r.problems)


def test_grid_too_small_and_empty():
    assert not check_mesh(Mesh(1, 5, [(0, 0)], np.zeros((0, 3)))).valid
    r = check_mesh(Mesh(3, 3, np.zeros((0, 2)), np.zeros((0, 3))))
    assert not r.valid and "no vertices" in r.problems[0]


def test_problem_list_is_short():
    rng = np.random.default_rng(5)
    full = grid_mesh(30, 30, rng)
    r = check_mesh(Mesh(30, 30, full.xy, full.tris[:, ::-1]))  # every triangle clockwise
    assert not r.valid
    assert len(r.problems) <= 21 and all("\n" not in q for q in r.problems)
    assert any("1682 in total" in q for q in r.problems)


# ---------------------------------------------------------------------------------------------
# Error metrics


def test_planar_heights_give_zero_error():
    rng = np.random.default_rng(6)
    for _ in range(5):
        mesh = random_cut_mesh(rng)
        yy, xx = np.mgrid[0 : mesh.height, 0 : mesh.width]
        heights = 0.5 * xx - 2.25 * yy + 3.0
        e = mesh_errors(mesh, heights)
        assert e.e_max_vertical < 1e-12 and e.e_max_normal < 1e-12
        assert e.rms_vertical < 1e-12 and e.e_total_normal < 1e-10 and e.n_uncovered == 0


def test_hand_computed_example():
    # 3 x 3 grid, triangles A = (0,0) (2,0) (2,2) and B = (0,0) (2,2) (0,2).
    # Corner heights 0, 2, 4, 0: plane of A is z = x + y, plane of B is z = 2x.
    heights = np.array(
        [
            [0.0, 1.0, 2.0],  # (1,0) on A: 1 - 1 = 0
            [0.0, 5.0, 3.0],  # (1,1) on the diagonal: A 5 - 2 = 3, B 5 - 2 = 3; (2,1) on A: 0; (0,1) on B: 0
            [0.0, 3.0, 4.0],  # (1,2) on B: 3 - 2 = 1
        ]
    )
    mesh = Mesh(3, 3, [(0, 0), (2, 0), (2, 2), (0, 2)], [(0, 1, 2), (0, 2, 3)])
    e = mesh_errors(mesh, heights)
    assert e.per_triangle_vertical.tolist() == pytest.approx([3.0, 3.0], abs=1e-15)
    assert e.per_triangle_normal.tolist() == pytest.approx([3 / math.sqrt(3), 3 / math.sqrt(5)], rel=1e-15)
    assert e.e_max_vertical == pytest.approx(3.0, abs=1e-15)
    assert e.e_max_normal == pytest.approx(math.sqrt(3), rel=1e-15)
    assert e.e_total_normal == pytest.approx(math.sqrt(3) + 3 / math.sqrt(5), rel=1e-15)
    assert e.e_mean_normal == pytest.approx((math.sqrt(3) + 3 / math.sqrt(5)) / 2, rel=1e-15)
    # RMS: 9 samples, each once; (1,1) is counted with A (the lower index): normal 3/sqrt(3).
    assert e.rms_vertical == pytest.approx(math.sqrt((9 + 1) / 9), rel=1e-15)
    assert e.rms_normal == pytest.approx(math.sqrt((3 + 1 / 5) / 9), rel=1e-15)
    rep = e.to_report()
    json.dumps(rep, allow_nan=False)
    assert rep["e_max_vertical"] == pytest.approx(3.0) and rep["n_uncovered"] == 0


def reference_errors(mesh: Mesh, heights: np.ndarray, z: np.ndarray):
    """Slow pure-Python E(T) and RMS: plane by a 3x3 solve, inside test by cross products."""
    xy = mesh.xy.tolist()
    T = mesh.n_triangles
    ev, en = [0.0] * T, [0.0] * T
    owner = {}
    for t, (i, j, k) in enumerate(mesh.tris.tolist()):
        pts = [xy[i], xy[j], xy[k]]
        a, b, c = np.linalg.solve(np.array([[p[0], p[1], 1.0] for p in pts]), np.array([z[i], z[j], z[k]]))
        nf = math.sqrt(1 + a * a + b * b)
        xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        for y in range(min(ys), max(ys) + 1):
            for x in range(min(xs), max(xs) + 1):
                if all(
                    (q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]) >= 0
                    for p, q in zip(pts, pts[1:] + pts[:1], strict=True)
                ):
                    d = abs(heights[y, x] - (a * x + b * y + c))
                    ev[t] = max(ev[t], d)
                    en[t] = max(en[t], d / nf)
                    owner.setdefault((x, y), (d, d / nf))
    sv = sum(v * v for v, _ in owner.values())
    sn = sum(n * n for _, n in owner.values())
    return np.array(ev), np.array(en), math.sqrt(sv / len(owner)), math.sqrt(sn / len(owner)), len(owner)


@pytest.mark.parametrize("seed", range(10))
def test_against_slow_reference(seed):
    rng = np.random.default_rng(1000 + seed)
    if seed % 3 == 2:
        w, h = int(rng.integers(3, 15)), int(rng.integers(3, 15))
        mesh = fan_mesh(w, h, (int(rng.integers(1, w - 1)), int(rng.integers(1, h - 1))))
    else:
        mesh = random_cut_mesh(rng)
    heights = rng.normal(size=(mesh.height, mesh.width)) * 10
    custom_z = seed % 2 == 1
    z = rng.normal(size=mesh.n_vertices) * 10 if custom_z else mesh.z(heights)
    e = mesh_errors(mesh, heights, z if custom_z else None)
    ev, en, rv, rn, n = reference_errors(mesh, heights, z)
    assert n == mesh.width * mesh.height and e.n_uncovered == 0
    np.testing.assert_allclose(e.per_triangle_vertical, ev, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(e.per_triangle_normal, en, rtol=1e-9, atol=1e-9)
    assert e.e_max_vertical == pytest.approx(ev.max(), rel=1e-9)
    assert e.e_max_normal == pytest.approx(en.max(), rel=1e-9)
    assert e.e_total_normal == pytest.approx(en.sum(), rel=1e-9)
    assert e.e_mean_normal == pytest.approx(en.mean(), rel=1e-9)
    assert e.rms_vertical == pytest.approx(rv, rel=1e-9)
    assert e.rms_normal == pytest.approx(rn, rel=1e-9)


@pytest.mark.parametrize("budget", [1, 5, 37])
def test_chunking_does_not_change_results(budget):
    rng = np.random.default_rng(77)
    mesh = fan_mesh(23, 17, (9, 6))
    heights = rng.random((17, 23))
    a = mesh_errors(mesh, heights)
    b = mesh_errors(mesh, heights, point_budget=budget)
    np.testing.assert_allclose(b.per_triangle_vertical, a.per_triangle_vertical, rtol=1e-15)
    np.testing.assert_allclose(b.per_triangle_normal, a.per_triangle_normal, rtol=1e-15)
    assert b.rms_normal == pytest.approx(a.rms_normal, rel=1e-12)


def test_uncovered_samples_and_degenerate_triangles():
    # Only the lower-right half of a 3 x 3 grid, plus a flat triangle: 3 samples uncovered.
    mesh = Mesh(3, 3, [(0, 0), (2, 0), (2, 2), (1, 0)], [(0, 1, 2), (0, 3, 1)])
    e = mesh_errors(mesh, np.zeros((3, 3)))
    assert e.n_uncovered == 3
    assert e.per_triangle_vertical[0] == 0 and math.isnan(e.per_triangle_vertical[1])
    assert e.e_max_vertical == 0 and e.to_report()["n_uncovered"] == 3


def test_height_field_shape_must_match():
    with pytest.raises(InputError):
        mesh_errors(SQUARE, np.zeros((3, 2)))


def test_lookup_and_chunking_variants(monkeypatch):
    """The T-junction search gives the same answers with the sorted-key lookup (large grids) and
    with tiny chunks as with the occupancy grid in one chunk."""
    from wavemesh import check

    xy = [(0, 0), (1, 0), (2, 0), (0, 2), (1, 2), (2, 2), (1, 1), (2, 1)]
    tris = [(0, 1, 4), (0, 4, 3), (1, 2, 7), (1, 7, 6), (6, 7, 5), (6, 5, 4)]
    t_mesh = Mesh(3, 3, xy, tris)
    expected = check_mesh(t_mesh).problems
    fans = [fan_mesh(31, 17, (12, 5)), fan_mesh(9, 40, (3, 30))]
    for limit, budget in [(0, check._POINT_BUDGET), (1 << 26, 3), (0, 1)]:
        monkeypatch.setattr(check, "_GRID_LOOKUP_LIMIT", limit)
        monkeypatch.setattr(check, "_POINT_BUDGET", budget)
        assert check_mesh(t_mesh).problems == expected
        assert all(check_mesh(f).valid for f in fans)
