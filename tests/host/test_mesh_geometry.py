"""wavemesh.mesh's exact polygon geometry (ear clipping, the search of triangulations within a test): its
two predicates, the corner-in-closed-triangle test (_holds_corner) and the proper crossing of segments
(_crosses_any), against shapely's (GEOS: exact on small integer points) on random points of a small grid,
where collinear corners and shared ends are common; and ear_clip's and triangulate_within's answers on
random simple polygons checked for what they are: triangulations of the polygon (shapely: the triangles
cover it and overlap nowhere), counter-clockwise, no corner on a triangle's closed region, refused
triangles left out."""

from __future__ import annotations

import itertools
import math
import random

import pytest
from shapely import union_all
from shapely.geometry import LineString, Point, Polygon
from wavemesh import mesh as M
from wavemesh.mesh import orient


def polygon(rng: random.Random) -> list[tuple[int, int]]:
    """A simple counter-clockwise polygon on a small integer grid: star-shaped about its centre (corners
    by angle, random radii), so concave corners, and with collinear corners along a few axis-parallel
    runs (as a tile's sides give)."""
    n = rng.randint(3, 14)
    angles = sorted(rng.uniform(0, 2 * math.pi) for _ in range(n))
    pts = []
    for a in angles:
        r = rng.uniform(2, 12)
        p = (round(20 + r * math.cos(a)), round(20 + r * math.sin(a)))
        if not pts or p != pts[-1]:
            pts.append(p)
    if rng.random() < 0.3:  # a straight side with corners on it
        pts = [(0, 0), (4, 0), (8, 0), (8, 4), (8, 8), (5, 9), (0, 8), (0, 4)][: rng.randint(5, 8)]
    return pts


def _point(rng: random.Random) -> tuple[int, int]:
    return rng.randint(0, 6), rng.randint(0, 6)


def test_corner_test_against_shapely():
    # every point of a 7 x 7 grid against random counter-clockwise triangles (ear_clip and
    # triangulate_within ask only about those): held when on the closed triangle, its sides included
    rng = random.Random(1)
    grid = [(x, y) for x in range(7) for y in range(7)]
    held = on_side = 0
    for _ in range(300):
        a, b, c = _point(rng), _point(rng), _point(rng)
        if orient(a, b, c) <= 0:
            continue
        tri = Polygon([a, b, c])
        for o in grid:
            if o in (a, b, c):
                continue
            want = tri.covers(Point(o))
            held += want
            on_side += tri.exterior.covers(Point(o))
            assert M._holds_corner([a, b, c, o], range(4), 0, 1, 2) == want, (a, b, c, o)
            assert M._holds_corner([o, b, a, c], range(4), 2, 1, 3) == want, (a, b, c, o)  # other slots
    assert held > 400 and on_side > 100  # sides and insides both met


def test_crossing_against_shapely():
    # a proper crossing: one point inside both segments, not a shared end, not collinear (shapely's
    # crosses: interiors meet in a point), on a 7 x 7 grid where the other cases are common
    rng = random.Random(2)
    crossed = 0
    for _ in range(6000):
        p, q = _point(rng), _point(rng)
        edges = [(_point(rng), _point(rng)) for _ in range(rng.randint(1, 3))]
        if p == q or any(r == s for r, s in edges):
            continue
        want = [LineString([p, q]).crosses(LineString([r, s])) for r, s in edges]
        crossed += any(want)
        assert M._crosses_any(p, q, edges) == any(want), (p, q, edges)
        assert M._crosses_any(p, q, edges[:1]) == want[0], (p, q, edges[0])
    assert crossed > 500


def _is_triangulation(pts, tris, ok=None) -> None:
    """Each triangle counter-clockwise, holding no other corner, allowed by ``ok``; on a simple polygon
    (shapely's valid, counter-clockwise), n - 2 of them that cover it and overlap nowhere (on another, no
    more is asked: ear_clip's is only ever one of these; triangulate_within tests every corner)."""
    assert tris is not None
    poly = Polygon(pts)
    shapes = [Polygon([pts[k] for k in t]) for t in tris]
    for t, s in zip(tris, shapes, strict=True):
        assert orient(*(pts[k] for k in t)) > 0, t  # counter-clockwise, not degenerate
        assert not any(s.covers(Point(pts[o])) for o in range(len(pts)) if o not in t), t  # no T-junction
        assert ok is None or ok(t), t
    if poly.is_valid and poly.exterior.is_ccw:
        assert len(tris) == len(pts) - 2
        assert sum(s.area for s in shapes) == poly.area  # no overlap
        assert union_all(shapes).symmetric_difference(poly).area == 0  # the polygon, covered


@pytest.mark.parametrize("seed", range(4))
def test_triangulations_of_random_polygons(seed):
    rng = random.Random(seed)
    found = 0
    for _ in range(200):
        pts = polygon(rng)
        simple = Polygon(pts).is_valid and Polygon(pts).exterior.is_ccw  # (rounding makes a few not)
        # no three corners on a line: an ear is there to clip at every step (the two ears theorem)
        general = simple and all(orient(a, b, c) for a, b, c in itertools.combinations(pts, 3))
        for fattest in (False, True):
            tris = M.ear_clip(pts, fattest)
            assert tris is not None or not general, (pts, fattest)
            if tris is not None and simple:
                _is_triangulation(pts, tris)
                found += 1
        banned = {tuple(sorted(rng.sample(range(len(pts)), 3)))} if len(pts) >= 4 else set()

        def ok(t, banned=banned):
            return tuple(sorted(t)) not in banned

        tris = M.triangulate_within(pts, ok)
        if tris is not None:
            _is_triangulation(pts, tris, ok)
    assert found > 300  # of some 380


def test_fill_hole_tries_in_its_order():
    """fill_hole: the fans first (with_fans), then the ears in the order asked, then the search; what ok
    refuses never in the answer; None when ok refuses every triangulation or the polygon is over limit."""
    hexagon = [(4, 0), (8, 2), (8, 6), (4, 8), (0, 6), (0, 2)]
    every = lambda t: True  # noqa: E731
    assert M.fill_hole(hexagon, every, with_fans=True) == next(M.fans(hexagon)) == [(0, 1, 2), (0, 2, 3),
                                                                                     (0, 3, 4), (0, 4, 5)]
    assert M.fill_hole(hexagon, every) == M.ear_clip(hexagon, fattest=True)
    assert M.fill_hole(hexagon, every, ears=(False,)) == M.ear_clip(hexagon)
    # only the triangulation with the middle triangle (1, 3, 5): no fan, no ear clipping's, the search's
    want = {(1, 2, 3), (3, 4, 5), (5, 0, 1), (1, 3, 5)}
    ok = lambda t: tuple(sorted(t)) in {tuple(sorted(w)) for w in want}  # noqa: E731
    got = M.fill_hole(hexagon, ok, with_fans=True)
    assert got is not None and {tuple(sorted(t)) for t in got} == {tuple(sorted(w)) for w in want}
    assert M.fill_hole(hexagon, ok, with_fans=True, limit=5) is None
    assert M.fill_hole(hexagon, lambda t: False, with_fans=True) is None
