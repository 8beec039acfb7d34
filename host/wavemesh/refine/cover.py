"""The refiner-side cover of a mesh with holes (docs/model.md, "Holes").

The refiner measures E(T) against the validity mask (firmware/src/holes.c): a triangle that covers both
valid and invalid samples is refined until each triangle covers one kind, or only its three corners; the
mesh stays a proper triangulation of the rectangle.  :func:`drop` then keeps the triangles that cover
valid samples only: holes bounded by mesh edges, every kept triangle within zeta over its samples, and
nothing over an invalid one.  The same functions filter the native run's meshes and the ones a device
streams (the device runs the same C): :func:`flip_thin` before, :func:`simplify_rims` and
:func:`drop_islands` (``--min-area``) after.
"""

from __future__ import annotations

import bisect

import numpy as np

from wavemesh.mesh import Mesh, fill_hole, orient
from wavemesh.model.holemask import cover_counts


def compact(width: int, height: int, xy: np.ndarray, tris: np.ndarray) -> Mesh:
    """A mesh of the given triangles and only the vertices they use (in their order)."""
    used = np.zeros(len(xy), dtype=bool)
    used[tris.ravel()] = True
    remap = np.cumsum(used) - 1
    return Mesh(width, height, xy[used], remap[tris] if len(tris) else tris)


def flip_thin(mesh: Mesh, mask: np.ndarray) -> Mesh:
    """The refiner's full triangulation with its thin triangles over both kinds of samples (doubled area
    1: no sample but their corners, E(T) 0; wm_tri_cover's THIN) flipped in pairs where that makes a
    triangle of three valid corners with a corner in no such triangle yet, or where one of the pair is
    long (a corner two samples or more from each of its invalid corners: it may cross grid cells of four
    valid corners, and dropped, leave a crack there, an edge of one triangle away from every invalid
    sample; Motorcycle's disparity at --decimate 2, zeta 1): two such triangles sharing an edge form a
    strictly convex quadrilateral of four samples whose other diagonal may give one, which the mesh then
    keeps (a valid sample at a hole's rim covered that the first diagonal left out, or the crack
    closed).  Each flip keeps the triangulation proper and makes one more triangle kept, so the work
    ends; triangles from the lowest slot, a stack of the ones a flip changed (deterministic)."""
    X = mesh.xy[:, 0].tolist()
    Y = mesh.xy[:, 1].tolist()
    bad = np.asarray(mask, dtype=bool)[mesh.xy[:, 1], mesh.xy[:, 0]].tolist()  # per vertex
    t = mesh.tris.tolist()

    def orient(a, b, c) -> int:
        return (X[b] - X[a]) * (Y[c] - Y[a]) - (X[c] - X[a]) * (Y[b] - Y[a])

    def thin_mixed(tri) -> bool:
        k = bad[tri[0]] + bad[tri[1]] + bad[tri[2]]
        return 0 < k < 3 and orient(*tri) == 1

    def long(tri) -> bool:
        """A corner two samples or more from each invalid corner (Chebyshev): the triangle may then cross
        grid cells of four valid corners, a crack in the valid region when it is dropped."""
        bads = [c for c in tri if bad[c]]
        return any(all(max(abs(X[c] - X[b]), abs(Y[c] - Y[b])) > 1 for b in bads) for c in tri)

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
            if bad[keep[0]] or bad[keep[1]] or bad[keep[2]]:
                continue  # the other diagonal keeps nothing
            if all(kept[c] for c in keep) and not (long(t[i]) or long(t[j])):
                continue  # nothing not kept already, and no crack closed
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
    clipping, else the first of all triangulations: mesh.triangulate_within) into triangles ``within(x, y)``
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

            cut = fill_hole(pts, ok, ears=(False,))  # the first ears, then every triangulation
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
