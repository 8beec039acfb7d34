"""Holes: meshes of height fields with invalid samples (range scans, disparity and depth images).

``--nodata hole`` (docs/model.md, "Holes") keeps a validity mask beside the heights
(:attr:`HeightField.mask <wavemesh.io.heightfield.HeightField.mask>`, True where a sample is invalid: NaN,
the reader's no-data value, ``--invalid VALUE``).  The heights under the mask are a nearest valid
sample's, for the filter bank and the templates alone.  The refiner measures E(T) against the mask
(firmware/src/holes.c): a triangle that covers both valid and invalid samples is refined until each
triangle covers one kind, or only its three corners; the mesh stays a proper triangulation of the
rectangle.  :func:`drop` then keeps the triangles that cover valid samples only: holes bounded by mesh
edges, every kept triangle within zeta over its samples, and nothing over an invalid one.  The same
function filters the native run's meshes and the ones a device streams (the device runs the same C).

:func:`pack` is the mask's one wire and memory format: a bit per sample, row-major, least significant
bit first, set where the sample is invalid (wm_field.mask, the MASK frames of docs/protocol.md).
:func:`check` is what ``wavemesh check`` adds for a mesh with holes.  :func:`bridge` is ``--max-hole N``:
the enclosed dropouts of at most N samples filled as ``--fill nearest`` fills them before the run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wavemesh.mesh import Mesh, ear_clip, orient


def pack(mask: np.ndarray) -> bytes:
    """The mask as wm_field.mask: bit i % 8 of byte i // 8 for sample i = y W + x, set when invalid."""
    return np.packbits(np.asarray(mask, dtype=bool).ravel(), bitorder="little").tobytes()


def unpack(data: bytes, width: int, height: int) -> np.ndarray:
    """pack's inverse: the (H, W) bool mask."""
    bits = np.unpackbits(np.frombuffer(data, dtype=np.uint8), bitorder="little", count=width * height)
    return bits.reshape(height, width).astype(bool)


def _spans(mesh: Mesh):
    """Each triangle's closed region row by row: (triangle, row, first, last, count), from the exact
    edge functions (counter-clockwise: E_k >= 0 inside) by integer floor division."""
    xy, t = mesh.xy, mesh.tris
    x, y = xy[t, 0], xy[t, 1]  # (T, 3)
    ymin, ymax = y.min(1), y.max(1)
    rows = ymax - ymin + 1
    tri = np.repeat(np.arange(len(t)), rows)
    py = ymin[tri] + np.arange(int(rows.sum())) - np.repeat(np.cumsum(rows) - rows, rows)
    lo, hi = x.min(1)[tri], x.max(1)[tri]
    empty = np.zeros(len(tri), dtype=bool)
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        a = (y[:, k1] - y[:, k2])[tri]  # E_k = a px + num
        b = (x[:, k2] - x[:, k1])[tri]
        c = (-(x[:, k2] - x[:, k1]) * y[:, k1] - (y[:, k1] - y[:, k2]) * x[:, k1])[tri]
        num = b * py + c
        d = np.where(a == 0, 1, np.abs(a))
        lo = np.where(a > 0, np.maximum(lo, -(num // d)), lo)  # ceil(-num / a)
        hi = np.where(a < 0, np.minimum(hi, num // d), hi)  # floor(num / -a)
        empty |= (a == 0) & (num < 0)
    cnt = np.where(empty, 0, np.maximum(hi - lo + 1, 0))
    return tri, py, lo, hi, cnt


def cover_counts(mesh: Mesh, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each triangle: (samples it covers, invalid samples among them), counted with per-row prefix
    sums of the mask."""
    n = mesh.n_triangles
    tri, py, lo, hi, cnt = _spans(mesh)
    bad = np.asarray(mask, dtype=bool)
    w = bad.shape[1]
    prefix = np.zeros((bad.shape[0], w + 1), dtype=np.int64)
    np.cumsum(bad, axis=1, out=prefix[:, 1:])
    inv = np.where(cnt > 0, prefix[py, np.clip(hi + 1, 0, w)] - prefix[py, np.clip(lo, 0, w)], 0)
    return np.bincount(tri, cnt, n).astype(np.int64), np.bincount(tri, inv, n).astype(np.int64)


def coverage(mesh: Mesh) -> np.ndarray:
    """(H, W) int: how many triangles of ``mesh`` cover each sample (closed triangles)."""
    tri, py, lo, hi, cnt = _spans(mesh)
    keep = cnt > 0
    py, lo, hi = py[keep], lo[keep], hi[keep]
    diff = np.zeros((mesh.height, mesh.width + 1), dtype=np.int64)
    np.add.at(diff, (py, lo), 1)
    np.add.at(diff, (py, hi + 1), -1)
    return np.cumsum(diff, axis=1)[:, :mesh.width]


def compact(width: int, height: int, xy: np.ndarray, tris: np.ndarray) -> Mesh:
    """A mesh of the given triangles and only the vertices they use (in their order)."""
    used = np.zeros(len(xy), dtype=bool)
    used[tris.ravel()] = True
    remap = np.cumsum(used) - 1
    return Mesh(width, height, xy[used], remap[tris] if len(tris) else tris)


def block_flags(mask: np.ndarray, levels: int) -> np.ndarray:
    """The per-block validity flag of the template stage's blocks (wavemesh.model.label: block (j, i) spans
    samples [iS, min((i+1)S, W-1)] x [jS, min((j+1)S, H-1)], S = 2^M, closed): True where the block holds
    an invalid sample.  The reference for an RTL flag beside each template; not used by the mesh (the
    templates see the filled heights; only the refiner and the host read the mask)."""
    from wavemesh.model.label import block_edges

    bad = np.asarray(mask, dtype=bool)
    h, w = bad.shape
    size = 1 << levels
    xs, ys = block_edges(w, size), block_edges(h, size)
    # any invalid sample in a closed box: a 2-D prefix sum
    pre = np.zeros((h + 1, w + 1), dtype=np.int64)
    pre[1:, 1:] = np.cumsum(np.cumsum(bad, axis=0), axis=1)
    x0, x1 = xs[:-1], xs[1:] + 1
    y0, y1 = ys[:-1, None], ys[1:, None] + 1
    return (pre[y1, x1] - pre[y0, x1] - pre[y1, x0] + pre[y0, x0]) > 0


def flip_thin(mesh: Mesh, mask: np.ndarray) -> Mesh:
    """The refiner's full triangulation with its thin triangles over both kinds of samples (doubled area
    1: no sample but their corners, E(T) 0; wm_tri_cover's THIN) flipped in pairs where that makes a
    triangle of three valid corners with a corner in no such triangle yet: two such triangles sharing an
    edge form a strictly convex quadrilateral of four samples whose other diagonal may give one, which
    the mesh then keeps (a valid sample at a hole's rim covered that the first diagonal left out).  Each
    flip keeps the triangulation proper and makes one more triangle kept, so the work ends; triangles
    from the lowest slot, a stack of the ones a flip changed (deterministic)."""
    X = mesh.xy[:, 0].tolist()
    Y = mesh.xy[:, 1].tolist()
    bad = np.asarray(mask, dtype=bool)[mesh.xy[:, 1], mesh.xy[:, 0]].tolist()  # per vertex
    t = mesh.tris.tolist()

    def orient(a, b, c) -> int:
        return (X[b] - X[a]) * (Y[c] - Y[a]) - (X[c] - X[a]) * (Y[b] - Y[a])

    def thin_mixed(tri) -> bool:
        k = bad[tri[0]] + bad[tri[1]] + bad[tri[2]]
        return 0 < k < 3 and orient(*tri) == 1

    kept = [0] * len(X)  # triangles of three valid corners at each vertex (the refiner done: kept ones)
    for a, b, c in t:
        if not (bad[a] or bad[b] or bad[c]):
            kept[a] += 1
            kept[b] += 1
            kept[c] += 1
    edge = {}  # directed edge -> its thin mixed triangle
    for i in range(len(t)):
        if thin_mixed(t[i]):
            for k in range(3):
                edge[t[i][k], t[i][(k + 1) % 3]] = i
    todo = sorted(set(edge.values()), reverse=True)  # a stack: the lowest slot first
    while todo:
        i = todo.pop()
        if not thin_mixed(t[i]):
            continue
        for k in range(3):
            u, v, w = t[i][k], t[i][(k + 1) % 3], t[i][(k + 2) % 3]
            j = edge.get((v, u))
            if j is None or j == i or not thin_mixed(t[j]):
                continue
            z = next(c for c in t[j] if c != u and c != v)
            if orient(w, u, z) <= 0 or orient(w, z, v) <= 0:
                continue  # not strictly convex
            keep = [w, u, z] if not (bad[w] or bad[u] or bad[z]) else [w, z, v]
            if bad[keep[0]] or bad[keep[1]] or bad[keep[2]] or all(kept[c] for c in keep):
                continue  # the other diagonal keeps nothing, or nothing not kept already
            for c in keep:
                kept[c] += 1
            for tri in (t[i], t[j]):
                for m in range(3):
                    edge.pop((tri[m], tri[(m + 1) % 3]), None)
            t[i], t[j] = [w, u, z], [w, z, v]
            for n in (i, j):
                if thin_mixed(t[n]):
                    for m in range(3):
                        edge[t[n][m], t[n][(m + 1) % 3]] = n
                    todo.append(n)
                    # its thin neighbours may flip now too
                    todo.extend(edge[b, a] for m in range(3)
                                for a, b in [(t[n][m], t[n][(m + 1) % 3])] if (b, a) in edge)
            break
    return Mesh(mesh.width, mesh.height, mesh.xy, np.array(t, dtype=np.int64).reshape(-1, 3))


def drop(mesh: Mesh, mask: np.ndarray | None) -> Mesh:
    """The triangles of ``mesh`` that cover no invalid sample (all of them when ``mask`` is None)."""
    if mask is None:
        return mesh
    _, inv = cover_counts(mesh, mask)
    return compact(mesh.width, mesh.height, mesh.xy, mesh.tris[inv == 0])


def drop_islands(mesh: Mesh, min_area: float) -> Mesh:
    """--min-area A: without the pieces (triangles joined through shared edges) smaller than A square
    grid steps: the islands and slivers a few samples big that dropouts leave."""
    if min_area <= 0 or mesh.n_triangles == 0:
        return mesh
    t = mesh.tris
    n = len(t)
    parent = np.arange(n)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    owner = np.tile(np.arange(n), 3)
    key = np.minimum(e[:, 0], e[:, 1]) * (len(mesh.xy) + 1) + np.maximum(e[:, 0], e[:, 1])
    order = np.argsort(key, kind="stable")
    ks, os_ = key[order], owner[order]
    for i in np.flatnonzero(ks[1:] == ks[:-1]):
        a, b = find(os_[i]), find(os_[i + 1])
        if a != b:
            parent[a] = b
    roots = np.array([find(i) for i in range(n)])
    xy = mesh.xy
    p0, p1, p2 = xy[t[:, 0]], xy[t[:, 1]], xy[t[:, 2]]
    area = ((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p2[:, 0] - p0[:, 0]) * (p1[:, 1] - p0[:, 1])) / 2
    total = np.bincount(roots, area, n)
    keep = total[roots] >= min_area
    return compact(mesh.width, mesh.height, xy, t[keep])


def _crosses(p, q, r, s) -> bool:
    """Segments p-q and r-s cross at a point inside both (not at a shared end, not collinear)."""
    d1, d2 = orient(p, q, r), orient(p, q, s)
    d3, d4 = orient(r, s, p), orient(r, s, q)
    return d1 * d2 < 0 and d3 * d4 < 0


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


def _dp_triangulate(pts: list, ok, limit: int = 16) -> list | None:
    """A triangulation (index triples into ``pts``) of the simple counter-clockwise polygon ``pts`` whose
    every triangle ``ok`` accepts, if one exists: all triangulations searched by the polygon's intervals
    (the first middle corner that works, in order: deterministic); None when none exists or the polygon
    has more than ``limit`` corners.  The fallback when ear clipping's one triangulation is not within
    zeta."""
    from functools import lru_cache

    n = len(pts)
    if n < 3 or n > limit:
        return None
    edges = [(pts[i - 1], pts[i]) for i in range(n)]

    def fits(i, j, k) -> bool:
        p, q, r = pts[i], pts[j], pts[k]
        if orient(p, q, r) <= 0:
            return False
        for o in range(n):
            if o not in (i, j, k) and orient(p, q, pts[o]) >= 0 and orient(q, r, pts[o]) >= 0 \
                    and orient(r, p, pts[o]) >= 0:
                return False  # a corner in the closed triangle
        if any(_crosses(a, b, c, d) for a, b in ((p, q), (q, r), (r, p)) for c, d in edges):
            return False
        return _inside(pts, p[0] + q[0] + r[0], p[1] + q[1] + r[1]) and ok((i, j, k))

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


def _rows(p, q, r):
    """The closed counter-clockwise triangle (p, q, r) row by row: (row, first, last) of its samples, from
    the exact edge functions (as _spans, for one triangle)."""
    x, y = (p[0], q[0], r[0]), (p[1], q[1], r[1])
    for py in range(min(y), max(y) + 1):
        lo, hi = min(x), max(x)
        for k in range(3):
            k1, k2 = (k + 1) % 3, (k + 2) % 3
            a, b = y[k1] - y[k2], x[k2] - x[k1]
            num = b * py - b * y[k1] - a * x[k1]
            if a > 0:
                lo = max(lo, -(num // a))
            elif a < 0:
                hi = min(hi, num // -a)
            elif num < 0:
                hi = lo - 1
        if lo <= hi:
            yield py, lo, hi


def _free(p, q, r, prefix, rows_x) -> bool:
    """The closed triangle (p, q, r) holds no invalid sample (``prefix``: the mask's per-row prefix sums)
    and no vertex but its corners (``rows_x``: the vertices' columns by row, sorted)."""
    import bisect

    corners = {p, q, r}
    for py, lo, hi in _rows(p, q, r):
        if prefix[py][hi + 1] - prefix[py][lo]:
            return False
        xs = rows_x.get(py, ())
        i = bisect.bisect_left(xs, lo)
        while i < len(xs) and xs[i] <= hi:
            if (xs[i], py) not in corners:
                return False
            i += 1
    return True


def simplify_rims(mesh: Mesh, within, mask: np.ndarray | None = None) -> Mesh:
    """The mesh less every vertex that lies on the straight border between its two border neighbours
    (a hole's rim, or the rectangle's side), or inside the mesh, and whose triangles re-triangulate (ear
    clipping, else the first of all triangulations: _dp_triangulate) into triangles ``within(x, y)``
    accepts: the covered region stays the same, so every new triangle covers only valid samples.  The
    refiner cannot remove these vertices itself: on its full triangulation the triangle across the rim
    would cover valid and invalid samples, and its decimation tries one triangulation of a ring.
    Vertices in slot order, passes until nothing changes (deterministic: the native and the device path
    give the same mesh).  Motorcycle at zeta 1: 13,723 -> 13,528 triangles with the fallback and the
    inner vertices, f2's shadow 44 -> 32 (bench/bench_holes.py)."""
    xy = [tuple(map(int, p)) for p in mesh.xy]
    tris = {k: tuple(map(int, t)) for k, t in enumerate(mesh.tris)}
    prefix = rows_x = None
    if mask is not None:  # a reflex rim vertex may go too when the triangle it leaves is free
        bad = np.asarray(mask, dtype=bool)
        prefix = np.zeros((bad.shape[0], bad.shape[1] + 1), dtype=np.int64)
        np.cumsum(bad, axis=1, out=prefix[:, 1:])
        prefix = prefix.tolist()
        rows_x = {}
        for px, py in xy:
            rows_x.setdefault(py, []).append(px)
        for r in rows_x.values():
            r.sort()
    around: dict[int, set] = {}
    for k, t in tris.items():
        for v in t:
            around.setdefault(v, set()).add(k)
    nxt = len(tris)
    changed = True
    while changed:
        changed = False
        for v in sorted(around):
            fan = around.get(v)
            if not fan:
                continue
            step = {}  # p -> q for each triangle (v, p, q), counter-clockwise around v
            for k in fan:
                t = tris[k]
                r = t.index(v)
                step[t[(r + 1) % 3]] = t[(r + 2) % 3]
            starts = set(step) - set(step.values())
            if len(starts) > 1:
                continue  # where two pieces touch
            inner = not starts  # v inside the mesh: its ring is closed
            ring = [starts.pop() if starts else min(step)]
            while ring[-1] in step and len(ring) <= len(fan):
                ring.append(step[ring[-1]])
            if inner:
                if ring[-1] != ring[0] or len(ring) != len(fan) + 1:
                    continue
                ring.pop()
            else:
                if len(ring) != len(fan) + 1:
                    continue
                a, b = xy[ring[0]], xy[ring[-1]]
                grow = orient(xy[v], b, a)  # > 0: the ring's polygon is the star and the triangle (v, b, a)
                if grow < 0 or (grow > 0 and (mask is None or not _free(xy[v], b, a, prefix, rows_x))):
                    continue
            pts = [xy[u] for u in ring]

            def ok(c, pts=pts):
                return within([pts[i][0] for i in c], [pts[i][1] for i in c])

            cut = ear_clip(pts)
            if cut is None or not all(map(ok, cut)):
                cut = _dp_triangulate(pts, ok)  # every triangulation, when ear clipping's one is not within
                if cut is None:
                    continue
            for k in fan:
                for u in tris.pop(k):
                    if u != v:
                        around[u].discard(k)
            del around[v]
            if rows_x is not None:
                rows_x[xy[v][1]].remove(xy[v][0])
            for c in cut:
                t = tuple(ring[i] for i in c)
                tris[nxt] = t
                for u in t:
                    around[u].add(nxt)
                nxt += 1
            changed = True
    kept = np.array([tris[k] for k in sorted(tris)], dtype=np.int64)
    return compact(mesh.width, mesh.height, mesh.xy, kept)


# ---------------------------------------------------------------------------------------------------
# The check of a mesh with holes


@dataclass
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


def coverable(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the valid samples that are a corner of a unit right triangle of three valid samples
    (three of the four corners of a grid cell).  No mesh with grid-sample vertices covers the others
    (isolated samples, one-sample-wide lines) without a triangle over an invalid sample, save long thin
    triangles this leaves out."""
    v = ~np.asarray(mask, dtype=bool)
    h, w = v.shape
    cell = v[:-1, :-1].astype(np.int8) + v[1:, :-1] + v[:-1, 1:] + v[1:, 1:] >= 3  # (H-1, W-1)
    out = np.zeros((h, w), dtype=bool)
    for dy in (0, 1):
        for dx in (0, 1):
            out[dy:dy + h - 1, dx:dx + w - 1] |= cell
    return out & v


def stranded(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the valid samples no grid cell's triangle of three valid samples has as a corner
    (``~coverable`` among the valid ones).  ``--nodata hole`` meshes them as invalid (the height field's
    mask takes them in, heightfield.from_array), as range-image meshers do, which triangulate grid cells of
    valid samples: no triangle of cell corners covers them without an invalid sample.  Idempotent: every
    valid sample of a cell with three valid corners stays valid."""
    v = ~np.asarray(mask, dtype=bool)
    return v & ~coverable(mask)


def enclosed_holes(mask: np.ndarray) -> int:
    """The 8-connected groups of invalid samples that do not touch the rectangle's border: each is a hole
    of any mesh that covers every valid sample around it and no invalid one.  A piece of mesh with h holes
    whose rims share no vertex, V_i inner and V_b rim vertices has 2 V_i + V_b + 2h - 2 triangles (Euler),
    and a rim has 3 vertices at least, so such a mesh has at least 5h + 1 triangles (rims that pinch at a
    shared vertex can do with fewer)."""
    from scipy import ndimage

    bad = np.asarray(mask, dtype=bool)
    lab, n = ndimage.label(bad, structure=np.ones((3, 3), dtype=bool))
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    return n - int((border > 0).sum())


def small_holes(mask: np.ndarray, max_hole: int) -> np.ndarray:
    """(H, W) bool: the samples of the 8-connected groups of ``mask`` that hold at most ``max_hole``
    samples and do not touch the rectangle's border (the enclosed dropouts --max-hole bridges)."""
    from scipy import ndimage

    bad = np.asarray(mask, dtype=bool)
    lab, n = ndimage.label(bad, structure=np.ones((3, 3), dtype=bool))
    size = np.bincount(lab.ravel(), minlength=n + 1)
    keep = size <= max_hole
    keep[0] = False
    keep[np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]])] = False
    return keep[lab]


def bridge(hf, max_hole: int):
    """--max-hole N: the height field with its enclosed groups of at most N invalid samples (small_holes)
    made valid, at the heights --fill nearest gives them (the mask's heights are a nearest valid sample's
    already: heightfield.from_array), the others left holes; the stranded samples found afresh (a bridged
    dropout may give them a cell of valid samples).  ``filled`` counts the bridged samples."""
    from dataclasses import replace

    if max_hole <= 0 or hf.mask is None:
        return hf
    raw = hf.mask if hf.lone is None else hf.mask & ~hf.lone
    small = small_holes(raw, max_hole)
    if not small.any():
        return hf
    bad = raw & ~small
    lone = stranded(bad)
    mask = bad | lone
    return replace(hf, mask=np.ascontiguousarray(mask) if mask.any() else None,
                   lone=lone if lone.any() else None, filled=hf.filled + int(np.count_nonzero(small)))


def check(mesh: Mesh, mask: np.ndarray, min_area: float = 0.0) -> HoleCheck:
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
        from scipy import ndimage

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
    from scipy import ndimage

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
