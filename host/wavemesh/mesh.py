"""The mesh type shared by every stage: grid vertices and counter-clockwise triangles.

Conventions (docs/model.md, "Mesh conventions"):

- A mesh triangulates the grid rectangle ``[0, W-1] x [0, H-1]`` of a height
  field with W columns and H rows.  Every vertex is a grid sample: ``xy[i] =
  (x, y)`` with ``x`` the column and ``y`` the row, 0-based integers.
- Triangles index ``xy`` and are counter-clockwise in the (x, y) plane:
  ``(x1-x0)*(y2-y0) - (x2-x0)*(y1-y0) > 0``.  With z up in a right-handed
  frame their normals point to +z.
- Heights are not part of the mesh: z of a vertex is the height field's value
  at that sample, looked up when a file is written or an error is measured.
- The canonical form (:meth:`Mesh.canonical`) orders vertices by (y, x), starts
  each triangle at its smallest vertex index (keeping its orientation) and sorts
  the triangles.  Two implementations agree "bit for bit" when their canonical
  forms are equal.
"""

from __future__ import annotations

import math

import numpy as np

from wavemesh.record import record


@record(frozen=True)
class Mesh:
    """A triangulation of the W x H grid rectangle with grid-sample vertices."""

    width: int  # W: number of grid columns (x runs 0..W-1)
    height: int  # H: number of grid rows (y runs 0..H-1)
    xy: np.ndarray  # (V, 2) int64, columns (x, y)
    tris: np.ndarray  # (T, 3) int64, counter-clockwise vertex indices

    def __post_init__(self):
        object.__setattr__(self, "xy", np.asarray(self.xy, dtype=np.int64).reshape(-1, 2))
        object.__setattr__(self, "tris", np.asarray(self.tris, dtype=np.int64).reshape(-1, 3))

    @property
    def n_vertices(self) -> int:
        return int(self.xy.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.tris.shape[0])

    @classmethod
    def from_slots(cls, width: int, height: int, xy: np.ndarray, tris: np.ndarray) -> Mesh:
        """A mesh from the refiner's slot arrays (wm_mesh_export): vertex slots whose x is negative
        are free (vertex removal leaves them) and are dropped, the triangles renumbered."""
        xy = np.asarray(xy, dtype=np.int64).reshape(-1, 2)
        tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
        live = xy[:, 0] >= 0
        if not live.all():
            remap = np.cumsum(live) - 1
            xy, tris = xy[live], remap[tris]
        return cls(width, height, xy, tris)

    def canonical(self) -> Mesh:
        """The same mesh with vertices sorted by (y, x) and triangles in a fixed order."""
        order = np.lexsort((self.xy[:, 0], self.xy[:, 1]))
        remap = np.empty(len(order), dtype=np.int64)
        remap[order] = np.arange(len(order))
        xy = self.xy[order]
        t = remap[self.tris] if self.n_triangles else self.tris.copy()
        if len(t):
            # Rotate each triangle so its smallest index comes first (orientation kept).
            k = np.argmin(t, axis=1)
            rows = np.arange(len(t))[:, None]
            t = t[rows, (k[:, None] + np.arange(3)[None, :]) % 3]
            t = t[np.lexsort((t[:, 2], t[:, 1], t[:, 0]))]
        return Mesh(self.width, self.height, xy, t)

    def same_as(self, other: Mesh) -> bool:
        """True when both meshes are the same triangulation (canonical forms equal)."""
        if (self.width, self.height) != (other.width, other.height):
            return False
        a, b = self.canonical(), other.canonical()
        return np.array_equal(a.xy, b.xy) and np.array_equal(a.tris, b.tris)

    def z(self, heights: np.ndarray) -> np.ndarray:
        """Heights of the vertices, looked up in a (H, W) array."""
        return np.asarray(heights)[self.xy[:, 1], self.xy[:, 0]]

    def border_count(self) -> int:
        """Number of vertices on the border of the grid rectangle."""
        x, y = self.xy[:, 0], self.xy[:, 1]
        on = (x == 0) | (y == 0) | (x == self.width - 1) | (y == self.height - 1)
        return int(np.count_nonzero(on))


def orient(a, b, c) -> int:
    """Twice the signed area of the triangle a, b, c (integer points): > 0 counter-clockwise, 0 collinear."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])


def ear_clip(pts: list, fattest: bool = False) -> list[tuple[int, int, int]] | None:
    """Triangles (index triples into ``pts``) of the simple counter-clockwise polygon ``pts`` by ear
    clipping in exact integers: an ear is a strictly convex corner whose closed triangle holds no other
    corner, not even on its sides (that would be a T-junction).  The first ear, or with ``fattest`` the
    one with the largest smallest angle (its sine, in floats; ties: the first); None when none is left
    (wavemesh.refine.cover re-triangulates a rim, wavemesh.tiles a tile's border)."""
    idx = list(range(len(pts)))
    out = []
    while len(idx) > 3:
        n = len(idx)
        best, best_q = None, -1.0
        for k in range(n):
            i, j, m = idx[k - 1], idx[k], idx[(k + 1) % n]
            pi, pj, pm = pts[i], pts[j], pts[m]
            d2 = orient(pi, pj, pm)
            if d2 <= 0:
                continue
            if _holds_corner(pts, idx, i, j, m):
                continue
            if not fattest:
                best = k
                break
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


def _holds_corner(pts: list, idx, i: int, j: int, m: int) -> bool:
    """Whether the closed triangle pts[i], pts[j], pts[m] holds a corner pts[o] (o in ``idx``, not i, j, m):
    orient(pi, pj, o) >= 0 and orient(pj, pm, o) >= 0 and orient(pm, pi, o) >= 0, written out (the
    seams' hottest loop: a tiled run's tiles clip thousands of small polygons)."""
    (ax, ay), (bx, by), (cx, cy) = pts[i], pts[j], pts[m]
    abx, aby, bcx, bcy, cax, cay = bx - ax, by - ay, cx - bx, cy - by, ax - cx, ay - cy
    for o in idx:
        if o == i or o == j or o == m:
            continue
        px, py = pts[o]
        if abx * (py - ay) - (px - ax) * aby >= 0 and bcx * (py - by) - (px - bx) * bcy >= 0 \
                and cax * (py - cy) - (px - cx) * cay >= 0:
            return True
    return False


def _crosses_any(p, q, edges: list) -> bool:
    """Whether segment p-q and one of the segments r-s of ``edges`` cross at a point inside both (not at a
    shared end, not collinear): orient(p, q, r) orient(p, q, s) < 0 and orient(r, s, p) orient(r, s, q) < 0,
    written out."""
    (px, py), (qx, qy) = p, q
    dx, dy = qx - px, qy - py
    for (rx, ry), (sx, sy) in edges:
        d1 = dx * (ry - py) - (rx - px) * dy  # orient(p, q, r)
        d2 = dx * (sy - py) - (sx - px) * dy  # orient(p, q, s)
        if d1 * d2 < 0:
            ex, ey = sx - rx, sy - ry
            if (ex * (py - ry) - (px - rx) * ey) * (ex * (qy - ry) - (qx - rx) * ey) < 0:  # orient(r, s, p/q)
                return True
    return False


def _inside(pts: list, x3: int, y3: int) -> bool:
    """The point (x3 / 3, y3 / 3) strictly inside the simple polygon ``pts`` (even-odd rule, exact)."""
    n, odd = len(pts), False
    for i in range(n):
        (ax, ay), (bx, by) = pts[i - 1], pts[i]
        ax, ay, bx, by = 3 * ax, 3 * ay, 3 * bx, 3 * by
        if (ay > y3) != (by > y3) and (x3 - ax) * (by - ay) * (1 if by > ay else -1) < (
                (bx - ax) * (y3 - ay) * (1 if by > ay else -1)):
            odd = not odd
    return odd


def triangulate_within(pts: list, ok, limit: int = 16) -> list | None:
    """A triangulation (index triples into ``pts``) of the simple counter-clockwise polygon ``pts`` whose
    every triangle ``ok`` accepts, if one exists: all triangulations searched by the polygon's intervals
    (the first middle corner that works, in order: deterministic); None when none exists or the polygon
    has more than ``limit`` corners.  The fallback when ear clipping's one triangulation is not within
    zeta (wavemesh.holes' rims, wavemesh.tiles' seams)."""
    n = len(pts)
    if n < 3 or n > limit:
        return None
    edges = [(pts[i - 1], pts[i]) for i in range(n)]

    everyone = range(n)

    def fits(i, j, k) -> bool:
        p, q, r = pts[i], pts[j], pts[k]
        if orient(p, q, r) <= 0:
            return False
        if _holds_corner(pts, everyone, i, j, k):
            return False  # a corner in the closed triangle
        for a, b in ((p, q), (q, r), (r, p)):
            if _crosses_any(a, b, edges):
                return False
        return _inside(pts, p[0] + q[0] + r[0], p[1] + q[1] + r[1]) and ok((i, j, k))

    memo: dict = {}  # (i, k) -> solve's answer (a plain dict: functools.lru_cache's wrapper, made at each
    # call, was a tenth of a tiled run's seam removals)

    def solve(i, k):
        if k - i < 2:
            return ()
        if (i, k) in memo:
            return memo[i, k]
        out = None
        for j in range(i + 1, k):
            if fits(i, j, k):
                a = solve(i, j)
                b = solve(j, k) if a is not None else None
                if b is not None:
                    out = a + b + ((i, j, k),)
                    break
        memo[i, k] = out
        return out

    out = solve(0, n - 1)
    return None if out is None else list(out)


def fans(pts: list):
    """The fans of the simple counter-clockwise polygon ``pts`` from each of its corners in turn (the
    refiner's first tries, decimate.c), those whose every triangle turns counter-clockwise (then they tile
    the polygon)."""
    n = len(pts)
    for a in range(n):
        fan = [(a, (a + k) % n, (a + k + 1) % n) for k in range(1, n - 1)]
        if all(orient(pts[i], pts[j], pts[m]) > 0 for i, j, m in fan):
            yield fan


def fill_hole(pts: list, ok, ears=(True, False), with_fans: bool = False, limit: int = 16) -> list | None:
    """A triangulation (index triples into ``pts``) of the simple counter-clockwise polygon ``pts`` (a
    removed vertex's hole) whose every triangle ``ok`` accepts, the first of: with ``with_fans`` the fans
    (:func:`fans`); ear clipping, for each of ``ears`` its fattest or first ears (:func:`ear_clip`); every
    triangulation of a polygon of at most ``limit`` corners (:func:`triangulate_within`).  None when none
    is accepted.  The one order of tries of wavemesh.refine.cover's rims and wavemesh.tiles' seams."""
    if with_fans:
        cut = next((f for f in fans(pts) if all(map(ok, f))), None)
        if cut is not None:
            return cut
    for fattest in ears:
        cut = ear_clip(pts, fattest=fattest)
        if cut is not None and all(map(ok, cut)):
            return cut
    return triangulate_within(pts, ok, limit)
