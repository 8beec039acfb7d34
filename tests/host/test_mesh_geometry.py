"""wavemesh.mesh's exact polygon geometry (ear clipping, the search of triangulations within a test) against
its first, plain form (the orient() calls as the definitions read, kept here as the reference): the same
triangles on random simple polygons, collinear corners and refused triangles included."""

from __future__ import annotations

import math
import random
from functools import lru_cache

import pytest
from wavemesh import mesh as M
from wavemesh.mesh import orient


def ear_clip_ref(pts, fattest=False):
    idx = list(range(len(pts)))
    out = []
    while len(idx) > 3:
        n = len(idx)
        best, best_q = None, -1.0
        for k in range(n):
            i, j, m = idx[k - 1], idx[k], idx[(k + 1) % n]
            pi, pj, pm = pts[i], pts[j], pts[m]
            if orient(pi, pj, pm) <= 0:
                continue
            if any(orient(pi, pj, pts[o]) >= 0 and orient(pj, pm, pts[o]) >= 0 and orient(pm, pi, pts[o]) >= 0
                   for o in idx if o not in (i, j, m)):
                continue
            if not fattest:
                best = k
                break
            d2 = orient(pi, pj, pm)
            la, lb, lc = math.dist(pj, pm), math.dist(pi, pm), math.dist(pi, pj)
            q = d2 / max(la * lb, lb * lc, lc * la)
            if q > best_q:
                best, best_q = k, q
        if best is None:
            return None
        out.append((idx[best - 1], idx[best], idx[(best + 1) % n]))
        del idx[best]
    if orient(pts[idx[0]], pts[idx[1]], pts[idx[2]]) <= 0:
        return None
    return out + [tuple(idx)]


def crosses_ref(p, q, r, s):
    d1, d2 = orient(p, q, r), orient(p, q, s)
    d3, d4 = orient(r, s, p), orient(r, s, q)
    return d1 * d2 < 0 and d3 * d4 < 0


def triangulate_within_ref(pts, ok, limit=16):
    n = len(pts)
    if n < 3 or n > limit:
        return None
    edges = [(pts[i - 1], pts[i]) for i in range(n)]

    def fits(i, j, k):
        p, q, r = pts[i], pts[j], pts[k]
        if orient(p, q, r) <= 0:
            return False
        for o in range(n):
            if o not in (i, j, k) and orient(p, q, pts[o]) >= 0 and orient(q, r, pts[o]) >= 0 \
                    and orient(r, p, pts[o]) >= 0:
                return False
        if any(crosses_ref(a, b, c, d) for a, b in ((p, q), (q, r), (r, p)) for c, d in edges):
            return False
        return M._inside(pts, p[0] + q[0] + r[0], p[1] + q[1] + r[1]) and ok((i, j, k))

    @lru_cache(maxsize=None)
    def solve(i, k):
        if k - i < 2:
            return ()
        for j in range(i + 1, k):
            if fits(i, j, k):
                a = solve(i, j)
                b = solve(j, k) if a is not None else None
                if b is not None:
                    return a + b + ((i, j, k),)
        return None

    out = solve(0, n - 1)
    return None if out is None else list(out)


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


@pytest.mark.parametrize("seed", range(4))
def test_the_same_triangles_as_the_plain_form(seed):
    rng = random.Random(seed)
    for _ in range(400):
        pts = polygon(rng)
        for fattest in (False, True):
            assert M.ear_clip(pts, fattest) == ear_clip_ref(pts, fattest), (pts, fattest)
        banned = {tuple(sorted(rng.sample(range(len(pts)), 3)))} if len(pts) >= 4 else set()

        def ok(t, banned=banned):
            return tuple(sorted(t)) not in banned

        assert M.triangulate_within(pts, ok) == triangulate_within_ref(pts, ok), pts
        a, b, c, d = (rng.choice(pts) for _ in range(4))
        assert M._crosses_any(a, b, [(c, d)]) == crosses_ref(a, b, c, d)
