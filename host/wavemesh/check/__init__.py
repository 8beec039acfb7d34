"""Mesh validity and approximation errors.

:func:`check_mesh` decides, in exact integer arithmetic, whether a :class:`Mesh`
is a proper triangulation of its grid rectangle ``R = [0, W-1] x [0, H-1]``.
It checks

1. every vertex lies in ``R``; no two vertices coincide; every vertex is used by
   a triangle; every triangle index is in range;
2. every triangle has a positive doubled signed area (counter-clockwise, not
   degenerate);
3. the doubled signed areas add up to ``2 (W-1) (H-1)``, twice the area of ``R``;
4. each directed edge occurs at most once; an undirected edge used by one
   triangle lies on the border of ``R``; every other undirected edge is used by
   exactly two triangles, in opposite directions;
5. no vertex lies in the relative interior of an edge (no T-junction);
6. Euler's relation for a triangulated disc, ``T = 2V - B - 2`` (B = vertices on
   the border of ``R``).

Why 1-5 mean "covers R exactly once, without overlaps".  For a point p of the
interior of R that is on no edge, let d(p) be the number of triangles
containing p.  A counter-clockwise triangle lies to the left of each of its
directed edges, so when a path crosses an edge e (away from vertices and from
points where two non-collinear edges cross: finitely many points, which a path
can avoid), only the triangles having e as an edge change whether they contain
the point, each changing d by one: +1 for a triangle entered, -1 for one left.
By 4 an inner edge has exactly two triangles with opposite directions, hence
(both counter-clockwise, by 2) one on each side: d gains one and loses one.
Collinear edges lying on top of each other are crossed together, but each is
balanced by itself.  The unmatched edges lie on the border of R, which a path
through the interior never meets.  So d is unchanged across every edge, and
since the interior of R minus finitely many points is connected, d is a
constant c there (up to the null set of the edges).  All vertices are in R
(1) and R is convex, so no triangle reaches outside R; with every area
positive (2) the sum of the triangle areas is the integral of d over R, i.e.
c * area(R), and by 3 that sum is area(R), so c = 1: almost every point of R
is covered exactly once: full coverage and no overlap.  The triangles then
form an edge-to-edge (conforming) triangulation: their interiors are
disjoint, so two triangles meet only along their boundaries, and a shared
piece of boundary that is not a whole common edge would put a vertex inside
the other triangle's edge, which 5 rules out.  Matching edges by vertex index
is matching them by position because 1 forbids two indices for one position.
(5 in fact follows from the rest, since a used vertex inside an edge shared by
two triangles would make one of them overlap a triangle at that vertex;
checking it directly gives a precise message.)  Euler's relation (6) then
holds automatically; it is kept as a cheap independent cross-check.

How the checks are computed: over all vertices, triangles and edges at once, in
int64 with no overflow (coordinates beyond 2^30 stop the check after 1).
Repeated positions and edges are found by sorting exact integer keys: a vertex's
position in its bounding box; a directed edge src->dst as ``(lo V + hi) 2 +
[src > dst]`` (lo, hi the smaller and larger index), so equal neighbours are
repeated directed edges and runs of one ``lo V + hi`` are the uses of one
undirected edge.  A check that fails then finds its example lines the way the
first version did (stable sorts), so the lines are the same; that version is
kept in tests/host/check_reference.py and the tests require equal results.

:func:`mesh_errors` measures how well the piecewise-planar surface of a mesh
approximates the height field at every grid sample.
"""

from __future__ import annotations

import math
from dataclasses import field

import numpy as np

from wavemesh.errors import InputError, MeshInvalid
from wavemesh.mesh import Mesh
from wavemesh.model.holemask import cover_counts, coverable, coverage
from wavemesh.record import record

__all__ = ["CheckResult", "check_mesh", "ErrorReport", "mesh_errors", "HoleCheck", "check_holes"]

_MAX_PROBLEMS = 20  # problem lines kept in a CheckResult
_EXAMPLES = 3  # examples shown per kind of problem before a summary line
_COORD_LIMIT = 1 << 30  # beyond this, cross products could overflow int64
_POINT_BUDGET = 1 << 20  # lattice points / samples handled per vectorised chunk
_GRID_LOOKUP_LIMIT = 1 << 26  # use a boolean occupancy grid up to this many cells
_LATTICE_PER_VERTEX = 1  # edges through more inner lattice points than this per vertex: test the vertices
_KEY_LIMIT = 1 << 30  # up to this many vertices (or grid steps a side) a sort key fits int64 with room
_FLOAT_FLOOR_LIMIT = 1 << 53  # integers below this are exact doubles: their quotient floors exactly
_SAMPLE_KEY_LIMIT = 1 << 63  # (sample index, occurrence) packed in one int64 key below this


@record
class CheckResult:
    """The verdict of :func:`check_mesh`."""

    valid: bool
    problems: list[str]  # human readable, one line each, at most ~20
    n_vertices: int
    n_triangles: int
    n_border: int  # vertices on the border of the grid rectangle
    euler_ok: bool  # T == 2V - B - 2


class _Problems:
    def __init__(self, limit: int = _MAX_PROBLEMS):
        self.lines: list[str] = []
        self.limit = limit
        self.dropped = 0

    def add(self, msg: str) -> None:
        if len(self.lines) < self.limit:
            self.lines.append(msg)
        else:
            self.dropped += 1

    def group(self, n: int, examples, what: str) -> None:
        """Report ``n`` problems of one kind: a few examples, then a count of the rest."""
        if n <= 0:
            return
        shown = 0
        for msg in examples:
            if shown >= _EXAMPLES:
                break
            self.add(msg)
            shown += 1
        if n > shown:
            self.add(f"... and {n - shown} more {what} ({n} in total)")

    def result(self) -> list[str]:
        if self.dropped:
            return self.lines + [f"... and {self.dropped} more problems"]
        return list(self.lines)

    def __bool__(self) -> bool:
        return bool(self.lines)


def _pt(xy: np.ndarray, i) -> str:
    return f"({int(xy[i, 0])}, {int(xy[i, 1])})"


def check_mesh(mesh: Mesh, fast: bool = True) -> CheckResult:
    """Check that ``mesh`` is a proper triangulation of its W x H grid rectangle (see module doc).

    Each check first counts its failures with sorts of exact integer keys; only a check that fails
    goes on to find the examples for its problem lines (with stable sorts, so the examples are the
    same ones whatever the sorting algorithm).  ``fast``: the C check (native.check_proper, one pass
    over the vertices and triangles, ~20x quicker) first; a mesh it passes is proper, any other is
    checked here as well, for the lines that say what is wrong (tests/host/test_host_stages.py: the
    same verdict as this code's on proper and broken meshes)."""
    W, H = int(mesh.width), int(mesh.height)
    if fast and mesh.n_vertices and mesh.n_triangles:
        from wavemesh.refine import native  # the C library loads at the first check, not on import

        verdict = native.check_proper(mesh)
        if verdict is not None and verdict[0]:
            return CheckResult(True, [], mesh.n_vertices, mesh.n_triangles, verdict[1], True)
    xy, tris = mesh.xy, mesh.tris
    V, T = mesh.n_vertices, mesh.n_triangles
    B = mesh.border_count()
    euler_ok = T == 2 * V - B - 2
    probs = _Problems()

    def done() -> CheckResult:
        if not euler_ok:
            probs.add(
                f"Euler's relation fails: {T} triangles, but 2V - B - 2 = 2*{V} - {B} - 2 = {2 * V - B - 2}"
            )
        lines = probs.result()
        return CheckResult(not lines, lines, V, T, B, euler_ok)

    if W < 2 or H < 2:
        probs.add(f"the grid is {W} x {H}; a mesh needs at least 2 x 2 samples")
    if V == 0:
        probs.add("the mesh has no vertices")
    if T == 0:
        probs.add("the mesh has no triangles")
    if V == 0 or T == 0:
        return done()
    x, y = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])

    # 1. vertices: inside, distinct, used; indices in range.
    outside = np.flatnonzero((x < 0) | (x > W - 1) | (y < 0) | (y > H - 1))
    probs.group(
        len(outside),
        (
            f"vertex {i} at {_pt(xy, i)} is outside the grid rectangle [0, {W - 1}] x [0, {H - 1}]"
            for i in outside
        ),
        "vertices outside the grid rectangle",
    )
    _coincident(probs, xy, x, y)
    if int(tris.min()) < 0 or int(tris.max()) >= V:
        bad_idx = (tris < 0) | (tris >= V)
        bad_rows = np.flatnonzero(bad_idx.any(axis=1))
        probs.group(
            len(bad_rows),
            (
                f"triangle {t} refers to vertex {int(tris[t][bad_idx[t]][0])}, which does not exist "
                f"({V} vertices)"
                for t in bad_rows
            ),
            "triangles with vertex indices out of range",
        )
        ok_tris = tris[~bad_idx.any(axis=1)]
    else:
        bad_rows, ok_tris = (), tris
    used = np.zeros(V, dtype=bool)
    used[ok_tris.ravel()] = True
    if not used.all():
        unused = np.flatnonzero(~used)
        probs.group(
            len(unused),
            (f"vertex {i} at {_pt(xy, i)} is not used by any triangle" for i in unused),
            "unused vertices",
        )
    if len(bad_rows):
        return done()  # the geometry of triangles with missing vertices is meaningless
    if np.abs(xy).max() > _COORD_LIMIT:
        return done()  # coordinates this far outside could overflow the exact arithmetic

    # 2. orientation, 3. total area.
    i0, i1, i2 = tris[:, 0], tris[:, 1], tris[:, 2]
    x0, y0 = x[i0], y[i0]
    area2 = (x[i1] - x0) * (y[i2] - y0) - (x[i2] - x0) * (y[i1] - y0)

    def tri_str(t) -> str:
        a, b, c = (int(v) for v in tris[t])
        return f"triangle {t} (vertices {a}, {b}, {c} at {_pt(xy, a)}, {_pt(xy, b)}, {_pt(xy, c)})"

    amin, amax = int(area2.min()), int(area2.max())
    if amin <= 0:
        cw = np.flatnonzero(area2 < 0)
        probs.group(
            len(cw),
            (f"{tri_str(t)} is clockwise (doubled area {int(area2[t])})" for t in cw),
            "clockwise triangles",
        )
        flat = np.flatnonzero(area2 == 0)
        probs.group(len(flat), (f"{tri_str(t)} is degenerate (zero area)" for t in flat),
                    "degenerate triangles")
    if T * (max(amax, -amin) + 1) < 1 << 62:
        total = int(area2.sum())
    else:  # an int64 sum could overflow
        total = int(area2.sum(dtype=object))
    want = 2 * (W - 1) * (H - 1)
    if total != want:
        what = "holes" if total < want else "overlaps"
        probs.add(
            f"the doubled signed areas of the triangles add up to {total}, but the rectangle's is "
            f"2*({W}-1)*({H}-1) = {want} ({what})"
        )

    # 4. edges.  Every directed edge src->dst as one key, (undirected key lo*V+hi, direction): sorted,
    # equal neighbours are repeated directed edges and runs of one undirected key are its uses.
    src = tris.ravel()
    dst = np.stack((i1, i2, i0), axis=1).ravel()
    lo, hi = np.minimum(src, dst), np.maximum(src, dst)
    ukey = lo * V + hi
    if V < _KEY_LIMIT:
        sk = np.sort(ukey * 2 + (src > dst))
        n_dup = int(np.count_nonzero(sk[1:] == sk[:-1]))
        uk = sk >> 1
    else:  # the doubled key could overflow: sort the undirected keys and the directed ones apart
        n_dup = -1
        uk = np.sort(ukey)
    etri = None
    if n_dup:
        etri = np.repeat(np.arange(T, dtype=np.int64), 3)
        dkey = src * V + dst
        dorder = np.argsort(dkey, kind="stable")
        dk = dkey[dorder]
        dup = np.flatnonzero(dk[1:] == dk[:-1])
        probs.group(
            len(dup),
            (
                f"directed edge {src[dorder[k]]}->{dst[dorder[k]]} "
                f"{_pt(xy, src[dorder[k]])}->{_pt(xy, dst[dorder[k]])} is used by triangles "
                f"{etri[dorder[k]]} and {etri[dorder[k + 1]]} (overlap or inconsistent orientation)"
                for k in dup
            ),
            "repeated directed edges",
        )
    starts = np.flatnonzero(np.r_[True, uk[1:] != uk[:-1]])
    counts = np.diff(np.r_[starts, len(uk)])
    ue = uk[starts]  # each undirected edge once, in key order
    elo = ue // V
    ehi = ue - elo * V
    xl, yl, xh, yh = x[elo], y[elo], x[ehi], y[ehi]
    on_border = ((xl == xh) & ((xl == 0) | (xl == W - 1))) | ((yl == yh) & ((yl == 0) | (yl == H - 1)))
    lonely = np.flatnonzero((counts == 1) & ~on_border)
    if len(lonely):
        if etri is None:
            etri = np.repeat(np.arange(T, dtype=np.int64), 3)
        first = np.argsort(ukey, kind="stable")[starts]  # the first use of each undirected edge
        probs.group(
            len(lonely),
            (
                f"edge {elo[k]}-{ehi[k]} {_pt(xy, elo[k])}-{_pt(xy, ehi[k])} is used only by triangle "
                f"{etri[first[k]]} but is not on the border (hole, crack or T-junction)"
                for k in lonely
            ),
            "unmatched inner edges",
        )
    crowded = np.flatnonzero(counts > 2)
    probs.group(
        len(crowded),
        (
            f"edge {elo[k]}-{ehi[k]} {_pt(xy, elo[k])}-{_pt(xy, ehi[k])} is used by {counts[k]} triangles "
            f"(overlap)"
            for k in crowded
        ),
        "edges used by more than two triangles",
    )

    # 5. T-junctions: lattice points strictly inside edges that are vertices.
    _t_junctions(probs, x, y, elo, ehi)

    return done()


def _coincident(probs: _Problems, xy: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    """Vertices at the same position: counted with a sort of position keys, shown in (y, x) order."""
    x0, y0 = int(x.min()), int(y.min())
    bw, bh = int(x.max()) - x0 + 1, int(y.max()) - y0 + 1
    if bw * bh < _KEY_LIMIT**2:
        key = np.sort((y - y0) * bw + (x - x0))
        if not (key[1:] == key[:-1]).any():
            return
    order = np.lexsort((x, y))
    sx, sy = x[order], y[order]
    same = np.flatnonzero((sx[1:] == sx[:-1]) & (sy[1:] == sy[:-1]))
    probs.group(
        len(same),
        (f"vertices {order[k]} and {order[k + 1]} coincide at {_pt(xy, order[k])}" for k in same),
        "coincident vertex pairs",
    )


def _t_junctions(probs: _Problems, x: np.ndarray, y: np.ndarray, elo: np.ndarray, ehi: np.ndarray) -> None:
    """Vertices strictly inside edges.  An edge through fewer inner lattice points than the mesh has
    vertices is checked point by point (each looked up among the vertices); a longer one, vertex by
    vertex (collinear and strictly between its ends).  So the work per edge is at most
    min(lattice points, V), never W or H: a mesh whose coordinates state a grid of 55555551 x 3 (one
    edge through 55 million lattice points) is as quick as any, and every chunk holds at most
    _POINT_BUDGET points or (edge, vertex) pairs.  Examples: the first hits in edge order, then along
    the edge, whichever way they were found."""
    dx, dy = x[ehi] - x[elo], y[ehi] - y[elo]
    adx, ady = np.abs(dx), np.abs(dy)
    long = np.flatnonzero((adx > 1) | (ady > 1))  # the others have gcd(|dx|, |dy|) <= 1
    g_long = np.gcd(adx[long], ady[long])
    sel = long[g_long > 1]  # edges through inner lattice points (gcd - 1 of them), in edge order
    if len(sel) == 0:
        return
    g = np.zeros(len(dx), dtype=np.int64)
    g[long] = g_long
    # Positions as keys over the vertices' bounding box.
    x0, y0 = int(x.min()), int(y.min())
    bw = int(x.max()) - x0 + 1
    bh = int(y.max()) - y0 + 1
    vkey = (y - y0) * bw + (x - x0)
    korder = np.argsort(vkey, kind="stable")
    skey = vkey[korder]
    inner = g[sel] - 1
    by_vertex = inner > _LATTICE_PER_VERTEX * len(x)
    n_hits = 0
    found: list[tuple[int, int, int]] = []  # (position in sel, steps from the edge's first end, vertex)

    def keep(pos: np.ndarray, steps: np.ndarray, verts: np.ndarray) -> None:
        nonlocal found
        order = np.lexsort((steps, pos))[:_EXAMPLES]
        found = sorted(found + [(int(pos[i]), int(steps[i]), int(verts[i])) for i in order])[:_EXAMPLES]

    # Short edges: their inner lattice points, looked up among the vertices.
    lat = np.flatnonzero(~by_vertex)
    if len(lat):
        grid = None
        if bw * bh <= _GRID_LOOKUP_LIMIT:
            grid = np.zeros(bw * bh, dtype=bool)
            grid[vkey] = True
        cum = np.cumsum(inner[lat])
        s = 0
        while s < len(lat):
            base = cum[s - 1] if s else 0
            e = max(int(np.searchsorted(cum, base + _POINT_BUDGET, side="right")), s + 1)
            pos = lat[s:e]
            edges = sel[pos]
            n = inner[pos]
            rep = np.repeat(np.arange(len(edges)), n)
            k = np.arange(1, int(n.sum()) + 1) - np.repeat(np.cumsum(n) - n, n)
            ge = g[edges]  # per edge: the first point and the step between lattice points
            px = x[elo[edges]][rep] + k * (dx[edges] // ge)[rep]
            py = y[elo[edges]][rep] + k * (dy[edges] // ge)[rep]
            key = (py - y0) * bw + (px - x0)
            if grid is not None:
                hit = grid[key]
            else:
                at = np.minimum(np.searchsorted(skey, key), len(skey) - 1)
                hit = skey[at] == key
            if hit.any():
                n_hits += int(hit.sum())
                first = np.flatnonzero(hit)[:_EXAMPLES]  # already in (edge, step) order
                keep(pos[rep[first]], k[first], korder[np.searchsorted(skey, key[first])])
            s = e

    # Long edges: every vertex, the first of each position (as the lookup above finds), against them.
    far = np.flatnonzero(by_vertex)
    if len(far):
        vs = korder[np.r_[True, skey[1:] != skey[:-1]]]
        vx, vy = x[vs], y[vs]
        per = max(1, _POINT_BUDGET // len(vs))  # edges per chunk
        vchunk = min(len(vs), _POINT_BUDGET)  # vertices per chunk
        for a in range(0, len(far), per):
            pos = far[a:a + per]
            edges = sel[pos]
            lx, ly, hx, hy = x[elo[edges]], y[elo[edges]], x[ehi[edges]], y[ehi[edges]]
            ex, ey = dx[edges][:, None], dy[edges][:, None]
            for b in range(0, len(vs), vchunk):
                ox = vx[None, b:b + vchunk] - lx[:, None]  # from the edge's first end; products < 2^62
                oy = vy[None, b:b + vchunk] - ly[:, None]
                hit = ((ex * oy == ey * ox)
                       & (np.minimum(lx, hx)[:, None] <= vx[None, b:b + vchunk])
                       & (vx[None, b:b + vchunk] <= np.maximum(lx, hx)[:, None])
                       & (np.minimum(ly, hy)[:, None] <= vy[None, b:b + vchunk])
                       & (vy[None, b:b + vchunk] <= np.maximum(ly, hy)[:, None])
                       & ((ox != 0) | (oy != 0)) & ((ox != ex) | (oy != ey)))
                if hit.any():
                    n_hits += int(np.count_nonzero(hit))
                    ei, vi = np.nonzero(hit)
                    keep(pos[ei], np.maximum(np.abs(ox[ei, vi]), np.abs(oy[ei, vi])), vs[b + vi])

    if not n_hits:
        return

    def _pt(i) -> str:
        return f"({int(x[i])}, {int(y[i])})"

    probs.group(
        n_hits,
        (
            f"vertex {v} at {_pt(v)} lies inside edge {elo[k]}-{ehi[k]} {_pt(elo[k])}-{_pt(ehi[k])} "
            "(T-junction)"
            for v, k in ((v, sel[p]) for p, _, v in found)
        ),
        "T-junctions",
    )


# --------------------------------------------------------------------------------------------
# Error metrics


@record
class ErrorReport:
    """How far the mesh surface is from the height field (x, y in grid steps, z in height units)."""

    e_max_vertical: float  # max over samples of |h - plane|
    e_max_normal: float  # max over samples of the distance to the plane, along its normal
    rms_vertical: float  # over all grid samples, each counted once
    rms_normal: float
    e_total_normal: float  # sum over triangles of E(T) (normal), dissertation eq. 3.34
    e_mean_normal: float  # mean over triangles of E(T) (normal)
    per_triangle_vertical: np.ndarray  # (T,) E(T): max over the samples in the closed triangle
    per_triangle_normal: np.ndarray  # (T,)
    n_uncovered: int = 0  # grid samples in no triangle (0 for a valid mesh); left out of the RMS
    # mesh_errors(..., rms=False) measures the maxima only: then rms_* are NaN and n_uncovered is -1

    def to_report(self) -> dict:
        """The scalar measures as a JSON-able dict (NaN becomes None)."""

        def f(v) -> float | None:
            v = float(v)
            return v if math.isfinite(v) else None

        return {
            "e_max_vertical": f(self.e_max_vertical),
            "e_max_normal": f(self.e_max_normal),
            "rms_vertical": f(self.rms_vertical),
            "rms_normal": f(self.rms_normal),
            "e_total_normal": f(self.e_total_normal),
            "e_mean_normal": f(self.e_mean_normal),
            "n_triangles": int(len(self.per_triangle_vertical)),
            "n_uncovered": int(self.n_uncovered),
        }


def mesh_errors(
    mesh: Mesh, heights: np.ndarray, z: np.ndarray | None = None, *, point_budget: int = _POINT_BUDGET,
    rms: bool = True, spacing: tuple[float, float] = (1.0, 1.0), native: bool = True,
) -> ErrorReport:
    """Vertical and normal distances between the height field and the mesh's triangle planes.

    ``heights`` is the (H, W) height field; ``z`` the vertex heights (default:
    the height field at the vertex samples).  Each triangle's plane passes
    through its three vertices (x, y in grid steps, z in height units):
    ``z = a x + b y + c``; it is evaluated at a sample s as
    ``z0 + (E1(s) (z1 - z0) + E2(s) (z2 - z0)) / D`` with the exact integer
    edge functions E1, E2 (barycentric weights times D) and the doubled area D,
    and ``a``, ``b`` (for the normal factor ``sqrt(1 + a^2 + b^2)``) come from
    Cramer's rule with D as the denominator, divided by the cell size ``spacing``
    = (dx, dy) in height units (the slope per ground unit; 1: per grid step).
    E(T) is the largest distance over
    the samples in the closed triangle (a sample on a shared edge counts for
    every triangle containing it).  For the RMS each sample counts once, with
    the lowest-numbered triangle that contains it; samples in no triangle (only
    in an invalid mesh) are counted in ``n_uncovered`` and left out.
    Degenerate triangles get E(T) = NaN.  Samples are enumerated as exact runs
    per triangle row (so a long thin triangle costs its samples, not its
    bounding box), in chunks of about ``point_budget`` samples, which bounds
    the memory used.  ``rms=False`` skips the RMS and the count of uncovered
    samples (about a quarter of the work): the maxima alone, measured by the C library's
    wm_host_tri_max when it loads (on every core; equal bit for bit) unless ``native`` is False.
    """
    W, H = int(mesh.width), int(mesh.height)
    h = np.asarray(heights)
    # float32 heights (a tiled job's float32 input, held as it is) as they are for the C maxima, which widen
    # each to its double; every other measure here on float64
    fast_h = h if h.dtype == np.float32 and not rms and native else None
    h = h if fast_h is not None else h.astype(np.float64, copy=False)
    if h.shape != (H, W):
        raise InputError(
            f"the height field has shape {h.shape} but the mesh is for a {W} x {H} grid (shape ({H}, {W}))"
        )
    xy, tris = mesh.xy, mesh.tris
    V, T = mesh.n_vertices, mesh.n_triangles
    if T == 0:
        raise MeshInvalid("the mesh has no triangles")
    if ((tris < 0) | (tris >= V)).any():
        raise MeshInvalid("the mesh has triangle vertex indices out of range")
    X, Y = xy[:, 0], xy[:, 1]
    if np.abs(xy).max() > _COORD_LIMIT:
        raise MeshInvalid("the mesh has vertices far outside the grid")
    if z is None:
        if ((X < 0) | (X >= W) | (Y < 0) | (Y >= H)).any():
            raise MeshInvalid("the mesh has vertices outside the grid, so they have no height")
        zv = h[Y, X].astype(np.float64, copy=False)
    else:
        zv = np.asarray(z, dtype=np.float64).reshape(-1)
        if len(zv) != V:
            raise InputError(f"{len(zv)} vertex heights given for a mesh with {V} vertices")

    per_v = None
    t_s = 0  # the first triangle the loop below measures
    if not rms and native:
        from wavemesh.refine import native as lib  # the loop below in C, on every core (tested equal)

        # the maxima and the normal factors below, in one pass over the triangles in C (on 1.26M triangles
        # the arrays below alone took 0.2 s)
        fast = lib.tri_max(h, X, Y, zv, tris, spacing)
        if fast is not None:
            (per_v, nfac), t_s = fast, T
        elif fast_h is not None:
            h = h.astype(np.float64)
    if per_v is None:
        i0, i1, i2 = tris[:, 0], tris[:, 1], tris[:, 2]
        x0, y0, x1, y1, x2, y2 = X[i0], Y[i0], X[i1], Y[i1], X[i2], Y[i2]
        D = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        sgn = np.sign(D)
        z0 = zv[i0]
        dz1, dz2 = zv[i1] - z0, zv[i2] - z0
        Df = D.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (dz1 * (y2 - y0) - dz2 * (y1 - y0)) / Df / spacing[0]
            b = ((x1 - x0) * dz2 - (x2 - x0) * dz1) / Df / spacing[1]
            nfac = np.hypot(1.0, np.hypot(a, b))  # sqrt(1 + a^2 + b^2)
        per_v = np.full(T, -np.inf)
    live = None  # the C maxima: -inf where no sample (a degenerate triangle, none in the grid)
    if t_s < T:  # the samples in Python: the scanlines' terms
        # Scanlines: for each triangle and each row of its bounding box (clipped to the grid), the
        # exact run of samples in the closed triangle, from the edge functions by floor division.
        xmin = np.maximum(np.minimum(np.minimum(x0, x1), x2), 0)
        xmax = np.minimum(np.maximum(np.maximum(x0, x1), x2), W - 1)
        ymin = np.maximum(np.minimum(np.minimum(y0, y1), y2), 0)
        ymax = np.minimum(np.maximum(np.maximum(y0, y1), y2), H - 1)
        live = (D != 0) & (xmax >= xmin) & (ymax >= ymin)
        # Edge functions E_k(s) = A_k x + B_k y + C_k, E_k = D * (barycentric weight of vertex k),
        # multiplied by sign(D) so that "inside the closed triangle" is "all three >= 0".
        A0, A1, A2 = (y1 - y2) * sgn, (y2 - y0) * sgn, (y0 - y1) * sgn
        B0, B1, B2 = (x2 - x1) * sgn, (x0 - x2) * sgn, (x1 - x0) * sgn
        C0, C1, C2 = (x1 * y2 - x2 * y1) * sgn, (x2 * y0 - x0 * y2) * sgn, (x0 * y1 - x1 * y0) * sgn
        absD = np.abs(D).astype(np.float64)

        nrows = np.where(live, ymax - ymin + 1, 0)
        rcum = np.cumsum(nrows)
        edges = ((A0, B0, C0), (A1, B1, C1), (A2, B2, C2))
        hflat = h.ravel()
        row_budget = max(point_budget // 4, 1)
        # A numerator B_k y + C_k is at most 4 c^2 in size (c: the largest coordinate or side); below 2^53
        # the float quotient of two exact integers floors to the exact floor (its rounding error is below
        # 1/|A_k|, the least distance from a non-integral quotient to an integer).
        c_max = max(W, H, int(np.abs(xy).max()))
        float_floor = 4 * c_max * c_max < _FLOAT_FLOOR_LIMIT
    covered = np.zeros(W * H if rms else 0, dtype=bool)
    n_cov = 0
    sum_v2 = 0.0
    sum_n2 = 0.0
    while t_s < T:
        # Triangles [t_s, t_e) with at most ~point_budget / 4 rows between them.
        base = int(rcum[t_s - 1]) if t_s else 0
        t_e = min(max(int(np.searchsorted(rcum, base + row_budget, side="right")), t_s + 1), T)
        nr = nrows[t_s:t_e]
        R = int(nr.sum())
        if R == 0:
            t_s = t_e
            continue
        rt = np.repeat(np.arange(t_s, t_e, dtype=np.int64), nr)
        ry = ymin[rt] + np.arange(R, dtype=np.int64) - np.repeat(np.cumsum(nr) - nr, nr)
        xl, xr = xmin[rt], xmax[rt]
        empty = np.zeros(R, dtype=bool)
        row_terms = []  # B_k y + C_k per row: E_k(x, y) = A_k x + row term
        for Ak, Bk, Ck in edges:
            ak = Ak[rt]
            num = Bk[rt] * ry + Ck[rt]  # E_k(x, y) = ak x + num >= 0
            d = np.maximum(np.abs(ak), 1)
            q = np.floor(num / d).astype(np.int64) if float_floor else num // d  # floor(num / |ak|)
            xl = np.where(ak > 0, np.maximum(xl, -q), xl)  # x >= ceil(-num / ak) = -q
            xr = np.where(ak < 0, np.minimum(xr, q), xr)  # x <= floor(num / -ak) = q
            empty |= (ak == 0) & (num < 0)
            row_terms.append(num)
        cnt = np.where(empty, 0, np.maximum(xr - xl + 1, 0))
        del empty, q, d, ak
        ccum = np.cumsum(cnt)
        r_s = 0
        while r_s < R:
            # Rows [r_s, r_e) with at most ~point_budget samples between them.
            cbase = int(ccum[r_s - 1]) if r_s else 0
            r_e = min(max(int(np.searchsorted(ccum, cbase + point_budget, side="right")), r_s + 1), R)
            c = cnt[r_s:r_e]
            N = int(c.sum())
            if N:
                rows = slice(r_s, r_e)
                rep = np.repeat(np.arange(r_e - r_s, dtype=np.int64), c)
                px = np.arange(N, dtype=np.int64) + (xl[rows] - (np.cumsum(c) - c))[rep]
                t = rt[rows][rep]
                E1 = A1[t] * px + row_terms[1][rows][rep]
                E2 = A2[t] * px + row_terms[2][rows][rep]
                plane = z0[t] + (E1 * dz1[t] + E2 * dz2[t]) / absD[t]
                del E1, E2
                gi = (ry[rows] * W)[rep] + px
                del px, rep
                vert = np.abs(hflat[gi] - plane)
                del plane
                # t is non-decreasing: per-triangle maxima by segments.  The normal distances are
                # vert / nfac, and a division by a positive number keeps the order, so their maxima
                # are the vertical maxima / nfac (bit for bit), taken at the end.
                seg = np.flatnonzero(np.r_[True, t[1:] != t[:-1]])
                ts = t[seg]
                per_v[ts] = np.maximum(per_v[ts], np.maximum.reduceat(vert, seg))
                # Each sample once, with the lowest-numbered triangle containing it (the first of
                # its occurrences here), in sample order.
                new = np.flatnonzero(~covered[gi]) if rms else ()
                if len(new):
                    shift = max(N - 1, 1).bit_length()  # occurrences numbered below 2^shift
                    if (W * H) << shift < _SAMPLE_KEY_LIMIT:
                        key = np.sort((gi[new] << shift) | new)
                        kg = key >> shift
                        firsts = np.r_[True, kg[1:] != kg[:-1]]
                        u, pick = kg[firsts], key[firsts] & ((1 << shift) - 1)
                    else:  # the key would overflow
                        u, firsts = np.unique(gi[new], return_index=True)
                        pick = new[firsts]
                    covered[u] = True
                    n_cov += len(u)
                    vp = vert[pick]
                    npk = vp / nfac[t[pick]]
                    sum_v2 += float(np.dot(vp, vp))
                    sum_n2 += float(np.dot(npk, npk))
            r_s = r_e
        t_s = t_e

    measured = ~np.isneginf(per_v)  # every live triangle has its vertices as samples
    if live is not None:
        measured &= live
    per_v[~measured] = np.nan
    per_n = np.full_like(per_v, np.nan)
    per_n[measured] = per_v[measured] / nfac[measured]  # a dead triangle's factor may be 0 (no warning)
    mv, mn = per_v[measured], per_n[measured]
    e_max_v = float(mv.max()) if len(mv) else math.nan
    e_max_n = float(mn.max()) if len(mn) else math.nan
    return ErrorReport(
        e_max_vertical=e_max_v,
        e_max_normal=e_max_n,
        rms_vertical=math.sqrt(sum_v2 / n_cov) if n_cov and rms else math.nan,
        rms_normal=math.sqrt(sum_n2 / n_cov) if n_cov and rms else math.nan,
        e_total_normal=float(mn.sum()),
        e_mean_normal=float(mn.mean()) if len(mn) else math.nan,
        per_triangle_vertical=per_v,
        per_triangle_normal=per_n,
        n_uncovered=W * H - n_cov if rms else -1,
    )


# ---------------------------------------------------------------------------------------------------
# The check of a mesh with holes (--nodata hole)


@record
class HoleCheck:
    """What check() found: the problems (empty: the mesh passes) and the counts behind them."""

    problems: list[str] = field(default_factory=list)
    invalid: int = 0  # invalid samples in the grid
    valid: int = 0  # valid samples
    covered_valid: int = 0  # valid samples in some triangle
    over_invalid: int = 0  # triangles covering an invalid sample
    uncovered_inland: int = 0  # valid samples in no triangle, no invalid sample among their 8 neighbours
    coverable: int = 0  # valid samples a unit right triangle of valid samples has as a corner (coverable())
    uncovered_coverable: int = 0  # of those, the ones in no triangle
    hole_edges: int = 0  # edges of one triangle, off the rectangle's border
    stray_edges: int = 0  # of those, the ones with no invalid sample within their length + 2 of the middle

    @property
    def valid_mesh(self) -> bool:
        return not self.problems

    def to_report(self) -> dict:
        return {"invalid_samples": self.invalid, "valid_samples": self.valid,
                "covered_valid": self.covered_valid, "uncovered_valid": self.valid - self.covered_valid,
                "uncovered_inland": self.uncovered_inland, "coverable": self.coverable,
                "uncovered_coverable": self.uncovered_coverable,
                "triangles_over_invalid": self.over_invalid, "hole_edges": self.hole_edges,
                "stray_hole_edges": self.stray_edges}


def check_holes(mesh: Mesh, mask: np.ndarray, min_area: float = 0.0) -> HoleCheck:
    """Whether ``mesh`` is a proper triangulation of the valid region of a grid whose invalid samples are
    ``mask``: the triangles (counter-clockwise, positive areas, vertices at distinct grid samples, every
    directed edge once, every edge in at most two triangles) do not overlap (no vertex in another
    triangle, and no triangle with an edge of one triangle overlaps a triangle near it, by separating
    axes, exact in integers: an overlap has such an edge on its border); no triangle covers an invalid
    sample; every valid sample is covered except next to an invalid one; every edge of one triangle
    lies on the rectangle's border or next to invalid samples.  ``min_area`` (--min-area A): valid samples
    away from the holes may also be uncovered in 8-connected groups of at most 2A + 2 samples, the most a
    piece of area under A holds (Pick: I + B/2 - 1 = A with I >= 0 gives I + B <= 2A + 2).  ``mask`` is the
    height field's (stranded samples included: heightfield.from_array)."""
    out = HoleCheck()
    p = out.problems
    bad = np.asarray(mask, dtype=bool)
    H, W = bad.shape
    out.invalid = int(bad.sum())
    out.valid = bad.size - out.invalid
    if (mesh.width, mesh.height) != (W, H):
        p.append(f"the mesh is for a {mesh.width} x {mesh.height} grid, the mask {W} x {H}")
        return out
    xy, t = mesh.xy, mesh.tris
    if len(t) == 0:
        p.append("the mesh has no triangles")
        return out
    if ((t < 0) | (t >= len(xy))).any():
        p.append("triangle vertex indices out of range")
        return out
    x, y = xy[:, 0], xy[:, 1]
    if ((x < 0) | (y < 0) | (x >= W) | (y >= H)).any():
        p.append("vertices outside the grid")
        return out
    if len(np.unique(y * W + x)) != len(xy):
        p.append("two vertices at one sample")
    used = np.zeros(len(xy), dtype=bool)
    used[t.ravel()] = True
    if not used.all():
        p.append(f"{int((~used).sum())} vertices in no triangle")
    tx, ty = x[t], y[t]
    area2 = (tx[:, 1] - tx[:, 0]) * (ty[:, 2] - ty[:, 0]) - (tx[:, 2] - tx[:, 0]) * (ty[:, 1] - ty[:, 0])
    if (area2 <= 0).any():
        p.append(f"{int((area2 <= 0).sum())} triangles are not counter-clockwise (or have no area)")
        return out
    src = t.ravel()
    dst = t[:, [1, 2, 0]].ravel()
    n = len(xy)
    directed = src * n + dst
    if len(np.unique(directed)) != len(directed):
        p.append("a directed edge is in two triangles (overlapping or flipped triangles)")
    und = np.minimum(src, dst) * n + np.maximum(src, dst)
    key, uses = np.unique(und, return_counts=True)
    if (uses > 2).any():
        p.append(f"{int((uses > 2).sum())} edges are in more than two triangles")
    # a vertex in a triangle it is not a corner of: a T-junction or an overlap
    cov = coverage(mesh)
    incident = np.bincount(src, minlength=n)
    extra = cov[y, x] - incident
    if (extra != 0).any():
        i = int(np.flatnonzero(extra)[0])
        p.append(f"{int((extra != 0).sum())} vertices lie in triangles they are not a corner of, first "
                 f"({x[i]}, {y[i]})")
    # one-triangle edges: on the border, or around a hole
    single = np.isin(und, key[uses == 1])
    on_border = ((x[src] == x[dst]) & ((x[src] == 0) | (x[src] == W - 1))) | (
        (y[src] == y[dst]) & ((y[src] == 0) | (y[src] == H - 1)))
    hole = single & ~on_border
    out.hole_edges = int(hole.sum())
    if out.invalid and out.hole_edges:
        from scipy import ndimage  # start-up: scipy only for masks (tests/host/test_mesh_costs.py)

        dist = ndimage.distance_transform_edt(~bad)  # to the nearest invalid sample
        mx, my = (x[src] + x[dst]) / 2, (y[src] + y[dst]) / 2
        length = np.hypot(x[src] - x[dst], y[src] - y[dst])
        near = dist[np.rint(my).astype(int), np.rint(mx).astype(int)] <= length + 2
        out.stray_edges = int((hole & ~near).sum())
    else:
        out.stray_edges = out.hole_edges
    if out.stray_edges:
        p.append(f"{out.stray_edges} edges of one triangle are neither on the rectangle's border nor next to "
                 f"an invalid sample (a hole in the mesh where the input has none)")
    _overlaps(mesh, np.unique(np.flatnonzero(single) // 3), p)
    # no triangle over an invalid sample; every valid sample covered but next to invalid ones
    _, inv = cover_counts(mesh, bad)
    out.over_invalid = int((inv > 0).sum())
    if out.over_invalid:
        i = int(np.flatnonzero(inv)[0])
        p.append(f"{out.over_invalid} triangles cover invalid samples, first "
                 f"{[tuple(map(int, xy[v])) for v in t[i]]}")
    covered = cov > 0
    out.covered_valid = int((covered & ~bad).sum())
    from scipy import ndimage  # start-up: scipy only for masks (tests/host/test_mesh_costs.py)

    rim = ndimage.binary_dilation(bad, structure=np.ones((3, 3), dtype=bool))
    inland = ~covered & ~rim
    if min_area > 0 and inland.any():  # the pieces --min-area dropped
        groups, n = ndimage.label(~covered & ~bad, structure=np.ones((3, 3), dtype=bool))
        size = np.bincount(groups.ravel(), minlength=n + 1)
        inland &= size[groups] > 2 * min_area + 2
    out.uncovered_inland = int(inland.sum())
    can = coverable(bad)
    out.coverable = int(can.sum())
    out.uncovered_coverable = int((can & ~covered).sum())
    if out.uncovered_inland:
        yy, xx = np.argwhere(inland)[0]
        p.append(f"{out.uncovered_inland} valid samples away from any invalid one are in no triangle, first "
                 f"({xx}, {yy})")
    return out


def _overlaps(mesh: Mesh, cand: np.ndarray, p: list[str], chunk: int = 1 << 20) -> None:
    """Separating axes between each triangle of ``cand`` (those with an edge of one triangle) and every
    triangle whose bounding box meets its own; exact in integers.  Two triangles' interiors are
    disjoint when an edge line of one has the other's three corners on its outer closed side.  The pairs
    come from a sweep over the boxes' left ends (each pair once: the later left end within the earlier
    box), ``chunk`` pairs a numpy pass."""
    xy, t = mesh.xy, mesh.tris
    X, Y = xy[t, 0], xy[t, 1]  # (T, 3)
    x0, x1, y0, y1 = X.min(1), X.max(1), Y.min(1), Y.max(1)
    want = np.zeros(len(t), dtype=bool)
    want[cand] = True
    order = np.argsort(x0, kind="stable")
    n = np.searchsorted(x0[order], x1[order], side="right") - np.arange(len(t)) - 1  # pairs per position
    ends = np.cumsum(n)
    total = int(ends[-1]) if len(ends) else 0
    for start in range(0, total, chunk):
        k = np.arange(start, min(start + chunk, total))
        i = np.searchsorted(ends, k, side="right")  # the earlier box's position in the order
        a, b = order[i], order[i + 1 + k - (ends[i] - n[i])]
        keep = (want[a] | want[b]) & (y0[b] <= y1[a]) & (y1[b] >= y0[a])
        a, b = a[keep], b[keep]
        sep = np.zeros(len(a), dtype=bool)
        for one, two in ((a, b), (b, a)):
            for e in range(3):
                e1 = (e + 1) % 3
                ex, ey = X[one, e1] - X[one, e], Y[one, e1] - Y[one, e]
                side = (ex[:, None] * (Y[two] - Y[one, e][:, None])
                        - ey[:, None] * (X[two] - X[one, e][:, None]))
                sep |= (side <= 0).all(axis=1)
        if not sep.all():
            q = int(np.flatnonzero(~sep)[0])
            p.append(f"triangles {[tuple(map(int, xy[v])) for v in t[a[q]]]} and "
                     f"{[tuple(map(int, xy[v])) for v in t[b[q]]]} overlap")
            return
