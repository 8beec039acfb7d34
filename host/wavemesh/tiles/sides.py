"""A tiled run's shared sides: the 1-D test, the two neighbours' vertices reconciled, a tile's mesh conformed
to them (docs/tiles.md, steps 4-5)."""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Iterable
from itertools import chain, compress

import numpy as np

from wavemesh import api
from wavemesh.errors import MeshInvalid
from wavemesh.mesh import Mesh, ear_clip, fill_hole

# The normal metric's 1-D border test keeps this margin below the refiner's zeta (relative, and in sample
# counts), more than the refiner's E(T) rounding (at most about 2^-15 relative + 2^-16, docs/refiner.md).
NORMAL_MARGIN_REL = 2.0 ** -12
NORMAL_MARGIN_ABS = 2.0 ** -12

SIDES = ("top", "right", "bottom", "left")
FACING = {"top": "bottom", "bottom": "top", "left": "right", "right": "left"}


# ---------------------------------------------------------------------------------------------------
# A shared side: the 1-D test, and the two neighbours' vertices reconciled


def _segment_ok(z: np.ndarray, a: int, b: int, fp, axis: int, metric: str) -> bool:
    """Every sample strictly between a and b within the refiner's zeta of the segment (a, z[a])-(b, z[b])."""
    if b - a < 2:
        return True
    i = np.arange(a + 1, b, dtype=np.int64)
    za, zb, L = int(z[a]), int(z[b]), b - a
    num = np.abs(z[a + 1:b].astype(np.int64) * L - (za * (b - i) + zb * (i - a)))  # |dz| L, exact
    if metric == "vertical":  # the refiner's vertical E(T) is exact: |dz| <= zeta (Q16.16 counts)
        return bool(np.all(num * 65536 <= int(fp.zeta) * L))
    m, e = (fp.slope_x_m, fp.slope_x_e) if axis == 0 else (fp.slope_y_m, fp.slope_y_e)
    slope = (m / 2.0 ** e) * (zb - za) / L  # the segment's slope with the refiner's rounded-down scale
    limit = (fp.zeta / 65536) * (1 - NORMAL_MARGIN_REL) - NORMAL_MARGIN_ABS
    return bool(np.all(num / L / math.sqrt(1 + slope * slope) <= limit))


def simplify_profile(z: np.ndarray, fp, axis: int, metric: str) -> tuple[int, ...]:
    """The kept positions of a side's profile z (16-bit samples, its two ends kept): from each kept
    position the farthest next one a galloping search finds whose segment holds every sample between
    within zeta (_segment_ok)."""
    z = np.asarray(z, dtype=np.int64)
    n = len(z)
    kept, a = [0], 0
    while a < n - 1:
        good, step, bad = a + 1, 2, None
        while True:
            b = min(a + step, n - 1)
            if not _segment_ok(z, a, b, fp, axis, metric):
                bad = b
                break
            good = b
            if b == n - 1:
                break
            step *= 2
        while bad is not None and bad - good > 1:
            mid = (good + bad) // 2
            if _segment_ok(z, a, mid, fp, axis, metric):
                good = mid
            else:
                bad = mid
        kept.append(good)
        a = good
    return tuple(kept)


def reconcile(z: np.ndarray, mine, theirs, fp, axis: int, metric: str) -> tuple[int, ...]:
    """A shared side's vertices from both neighbours' free meshes (their positions along it): the union,
    each segment of it that does not hold its samples within zeta (_segment_ok) simplified on its own
    (simplify_profile).  Symmetric in ``mine`` and ``theirs``; every vertex either mesh has is kept, so
    conforming a mesh to it only inserts."""
    z = np.asarray(z, dtype=np.int64)
    kept = [0]
    for c in sorted(set(mine) | set(theirs) | {len(z) - 1})[1:]:
        a = kept[-1]
        if not _segment_ok(z, a, c, fp, axis, metric):
            kept += [a + k for k in simplify_profile(z[a:c + 1], fp, axis, metric)[1:-1]]
        kept.append(c)
    return tuple(kept)


def side_profile(samples: np.ndarray, side: str) -> np.ndarray:
    """A tile's samples along one side (top and bottom left to right, left and right top to bottom)."""
    return {"top": samples[0], "bottom": samples[-1], "left": samples[:, 0], "right": samples[:, -1]}[side]


# ---------------------------------------------------------------------------------------------------
# A tile's mesh conformed to its decided border


def _side_of(x: int, y: int, w: int, h: int) -> list[tuple[str, int]]:
    return [(s, p) for s, p, on in (("top", x, y == 0), ("bottom", x, y == h - 1), ("left", y, x == 0),
                                    ("right", y, x == w - 1)) if on]


def _line(side: str, w: int, h: int) -> tuple[int, int]:
    """(k, c): a point p of the w x h rectangle is on ``side`` when p[k] == c (_side_of's test)."""
    return {"top": (1, 0), "bottom": (1, h - 1), "left": (0, 0), "right": (0, w - 1)}[side]


def _on_sides(xy: np.ndarray, w: int, h: int) -> dict[str, np.ndarray]:
    """side -> (V,) bool: the vertices ``xy`` on that side of the w x h rectangle."""
    return {s: xy[:, k] == c for s in ("top", "right", "bottom", "left") for k, c in (_line(s, w, h),)}


def touching(on: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(T,) bool: the triangles ``tris`` with a corner ``on`` (a (V,) bool) -- one gather per corner column
    (``on[tris].any(axis=1)``, the same answer, is a numpy reduce along a short axis: about 9 times the
    time on a tile's 80,000 triangles)."""
    return on[tris[:, 0]] | on[tris[:, 1]] | on[tris[:, 2]]


def side_point(side: str, pos: int, w: int, h: int) -> tuple[int, int]:
    return {"top": (pos, 0), "bottom": (pos, h - 1), "left": (0, pos), "right": (w - 1, pos)}[side]


def _ring(v: int, fan: Iterable[tuple[int, int, int]]) -> list[int]:
    """The link of v's star (its triangles ``fan``, counter-clockwise): edge (v -> n1) in a triangle (v, n1,
    n2) continues from n2.  A border vertex's is open, walked from the side neighbour no triangle ends at;
    an inner vertex's closed, walked once round from its least vertex."""
    nxt = {}
    for t in fan:
        k = t.index(v)
        nxt[t[(k + 1) % 3]] = t[(k + 2) % 3]
    ends = set(nxt.values())
    start = next((n for n in nxt if n not in ends), None)
    if start is None:  # closed
        ring = [min(nxt)]
        while len(ring) < len(nxt):
            ring.append(nxt[ring[-1]])
        return ring
    ring = [start]
    while ring[-1] in nxt:
        ring.append(nxt[ring[-1]])
    return ring


def _within_kept(within, tested: dict, pts: list):
    """``within`` (the refiner's E(T) <= zeta) as a test of index triples into ``pts``, each answer kept in
    ``tested`` by the triangle's corners (in that order) for every ring that meets the triangle again."""

    def ok(t) -> bool:
        key = (pts[t[0]], pts[t[1]], pts[t[2]])
        good = tested.get(key)
        if good is None:
            a, b, c = key
            tested[key] = good = within([a[0], b[0], c[0]], [a[1], b[1], c[1]])
        return good

    return ok


def conform(mesh: Mesh, sides: dict, made: bool = False) -> Mesh | tuple[Mesh, int]:
    """``mesh`` (a proper triangulation of its grid rectangle) with exactly the decided border vertices:
    each missing one inserted by splitting the triangle on its border edge, each other border vertex
    (corners stay) removed and its hole, a simple polygon, re-triangulated by ear clipping (the fattest
    ear first).  The result is proper (the refiner's wm_mesh_build checks it again); its error is the
    next step's business.  Only the triangles at the border are held as Python objects.  With ``made``,
    also how many triangles it made: the result's last ones (its others are ``mesh``'s, in order)."""
    w, h = mesh.width, mesh.height
    n_v, n_t = len(mesh.xy), len(mesh.tris)
    bset = np.logical_or.reduce(list(_on_sides(mesh.xy, w, h).values()))
    near = np.flatnonzero(touching(bset, mesh.tris))
    tris = {k: tuple(t) for k, t in zip(near.tolist(), mesh.tris[near].tolist(), strict=True)}
    # the vertices of those, sorted (np.unique's answer; its plain call imports numpy.ma, 47M instructions
    # in each worker)
    used = np.flatnonzero(np.bincount(mesh.tris[near].ravel(), minlength=n_v))
    xy = {v: tuple(q) for v, q in zip(used.tolist(), mesh.xy[used].tolist(), strict=True)}
    alive = np.ones(n_t, dtype=bool)
    added: list[int] = []
    dead: set[int] = set()
    freed: list[int] = []
    inc: dict[int, set[int]] = {v: set() for v in np.flatnonzero(bset).tolist()}
    for k, t in tris.items():
        for v in t:
            if v in inc:
                inc[v].add(k)

    def add(tri) -> None:
        k = n_t + len(added)
        tris[k] = tri
        added.append(k)
        for v in tri:
            if v in inc:
                inc[v].add(k)

    def kill(t) -> None:
        if t < n_t:
            alive[t] = False
        else:
            dead.add(t)
        for v in tris[t]:
            if v in inc:
                inc[v].discard(t)

    want = {side_point(s, pos, w, h) for s, ps in sides.items() for pos in ps}
    # each side's vertices by their place along it, sorted (a new vertex's neighbours there by bisection,
    # not a pass over every border vertex for each: 0.69 of Jacksboro 2048^2's 6.96 s on one worker)
    lines: dict[str, tuple[list[int], list[int]]] = {}  # side -> (places, vertices)
    for place, u, s in sorted((pos, v, s) for v in inc for s, pos in _side_of(*xy[v], w, h)):
        line = lines.setdefault(s, ([], []))
        line[0].append(place)
        line[1].append(u)
    # 1. insert the decided vertices the mesh lacks: split the triangle whose border edge holds each
    for p in sorted(want - set(xy.values())):
        side, pos = _side_of(p[0], p[1], w, h)[0]
        ps, vs = lines[side]
        i = bisect_left(ps, pos)  # the side's vertices before and after pos (never at it: it lacks p)
        a, b = vs[i - 1], vs[i]
        t = next(t for t in inc[a] & inc[b])
        ta = tris[t]
        k = ta.index(a)
        if ta[(k + 1) % 3] != b:  # the triangle holds the edge as b -> a
            a, b = b, a
            k = ta.index(a)
        c = ta[(k + 2) % 3]
        v = n_v + len(xy) - len(used)  # the next new vertex
        xy[v] = p
        inc[v] = set()
        ps.insert(i, pos)
        vs.insert(i, v)
        kill(t)
        add((a, v, c))
        add((v, b, c))
    # 2. remove the border vertices that were not decided (never a corner)
    corners = {(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)}
    for v in sorted(inc, key=lambda v: (xy[v][1], xy[v][0])):
        if xy[v] in want or xy[v] in corners or not any(s in sides for s, _ in _side_of(*xy[v], w, h)):
            continue
        fan = list(inc[v])
        ring = _ring(v, (tris[t] for t in fan))
        cut = ear_clip([xy[r] for r in ring], fattest=True)
        if cut is None:
            raise MeshInvalid("a tile's border could not be re-triangulated (no ear)", hint=api.BUG_HINT)
        for t in fan:
            kill(t)
        for tri in cut:
            add(tuple(ring[k] for k in tri))
        del inc[v]
        freed.append(v)
    n_new = len(xy) - len(used)
    every = np.concatenate([mesh.xy, np.array([xy[v] for v in range(n_v, n_v + n_new)],
                                              dtype=np.int64).reshape(-1, 2)])
    keep = np.ones(len(every), dtype=bool)
    keep[freed] = False
    remap = np.cumsum(keep) - 1
    more = np.array([tris[k] for k in added if k not in dead], dtype=np.int64).reshape(-1, 3)
    out = Mesh(w, h, every[keep], remap[np.concatenate([np.compress(alive, mesh.tris, axis=0), more])])
    return (out, len(more)) if made else out


def border_of(mesh: Mesh) -> dict:
    """A mesh's vertices on each side of its rectangle, as positions along the side (sorted)."""
    on = _on_sides(mesh.xy, mesh.width, mesh.height)
    return {s: tuple(sorted(mesh.xy[on[s], 0 if s in ("top", "bottom") else 1].tolist()))
            for s in ("top", "bottom", "left", "right")}


# ---------------------------------------------------------------------------------------------------
# The seams thinned: shared side vertices both neighbours can do without


class Editable:
    """A tile's mesh (tile coordinates) whose vertices on ``sides`` go one at a time: a side vertex's star
    replaced by a triangulation of its ring whose every triangle ``within`` (the refiner's E(T) <= zeta)
    accepts.  Only the triangles at those sides are held as Python objects; the rest stay as they are."""

    def __init__(self, mesh: Mesh, within, sides: Iterable[str]):
        self.w, self.h, self.within, self.source = mesh.width, mesh.height, within, mesh
        on = np.zeros(len(mesh.xy), dtype=bool)
        for side in sides:
            k, at = _line(side, self.w, self.h)
            on |= mesh.xy[:, k] == at
        self.near = touching(on, mesh.tris)  # the mesh's others (the rest) taken only by mesh() and new()
        self.tris = list(map(tuple, np.compress(self.near, mesh.tris, axis=0).tolist()))
        self.alive = [True] * len(self.tris)
        self.made = len(self.tris)  # the triangles from here on are the removals'
        self.inc: dict[int, set[int]] = {}
        for k, t in enumerate(self.tris):
            for v in t:
                self.inc.setdefault(v, set()).add(k)
        vs = list(self.inc)
        self.xy = dict(zip(vs, map(tuple, mesh.xy[vs].tolist()), strict=True))
        self.at = {p: v for v, p in self.xy.items()}
        self.gone: list[int] = []
        self._found: dict = {}  # position -> removal()'s answer, until the vertex's star changes (apply)
        self._tested: dict = {}  # a triangle's corners (in that order) -> within's answer

    def removal(self, p: tuple[int, int], side: str):
        """(vertex, new triangles) that remove the vertex at ``p`` on ``side``, or None: a corner, a vertex
        whose ring reaches the opposite side of the tile (off its corners: the two sides' removals then
        never touch the same triangles, whatever their order), or no triangulation of its hole within zeta
        (ear clipping, the fattest ear first, then the first ear, then every triangulation of a small
        ring: wavemesh.holes' search).  Each answer is worked out once and kept until :meth:`apply` changes
        the vertex's star (it depends on nothing else)."""
        if p in self._found:
            return self._found[p]
        self._found[p] = found = self._removal(p, side)
        return found

    def _removal(self, p: tuple[int, int], side: str):
        w, h = self.w, self.h
        v = self.at.get(p)
        if v is None or v not in self.inc or len(_side_of(*p, w, h)) > 1:
            return None
        ring = _ring(v, (self.tris[k] for k in self.inc[v]))
        pts = [self.xy[r] for r in ring]
        k, at = _line(FACING[side], w, h)  # a ring vertex on the facing side, off its corners
        if any(q[k] == at and len(_side_of(*q, w, h)) == 1 for q in pts):
            return None
        cut = fill_hole(pts, _within_kept(self.within, self._tested, pts))
        if cut is not None:
            return v, [tuple(ring[k] for k in t) for t in cut]
        return None

    def apply(self, plan) -> None:
        """Vertex v's star replaced by the triangles ``new`` of its ring (``plan``: a removal() of this
        mesh, or of another Editable of the same mesh whose changes never touched v's star)."""
        v, new = plan
        if v not in self.inc:
            raise MeshInvalid(f"vertex {v} is not on this mesh's edited sides", hint=api.BUG_HINT)
        for k in list(self.inc[v]):
            self.alive[k] = False
            for u in self.tris[k]:
                self.inc[u].discard(k)
                self._found.pop(self.xy[u], None)  # its star changes (v and its ring)
        for t in new:
            self.tris.append(t)
            self.alive.append(True)
            for u in t:
                self.inc[u].add(len(self.tris) - 1)
        del self.inc[v]
        self.gone.append(v)

    def new(self) -> np.ndarray:
        """(T,) bool over :meth:`mesh`'s triangles: those the removals made (the others are the mesh's
        own, as they were)."""
        made = [k >= self.made for k, ok in enumerate(self.alive) if ok]
        rest = len(self.near) - int(np.count_nonzero(self.near))
        return np.concatenate([np.zeros(rest, dtype=bool), np.array(made, dtype=bool)])

    def mesh(self) -> Mesh:
        keep = np.ones(len(self.source.xy), dtype=bool)
        keep[self.gone] = False
        remap = np.cumsum(keep) - 1
        made = np.fromiter(chain.from_iterable(compress(self.tris, self.alive)), dtype=np.int64)
        # np.compress: a (N, 3) array's rows by a mask in a quarter of the time of tris[mask]
        tris = np.concatenate([np.compress(~self.near, self.source.tris, axis=0), made.reshape(-1, 3)])
        return Mesh(self.w, self.h, np.compress(keep, self.source.xy, axis=0), remap.take(tris))


class Cut(tuple):
    """thin_side's answer: the positions along the side of the vertices removed, in order (a tuple), and
    ``plans``: side -> the removals (vertex, new triangles) that took them out of the tile whose side that
    is (the two tiles' meshes as thin_side was given them), so that each tile applies them as found
    (jobs.thin_tile) instead of working every removal out again."""

    plans: dict

    def __new__(cls, positions, plans: dict):
        cut = super().__new__(cls, positions)
        cut.plans = plans
        return cut

    def __reduce__(self):
        return (Cut, (tuple(self), self.plans))


def thin_side(a: Editable, b: Editable, side: str) -> Cut:
    """The vertices of ``a``'s shared ``side`` (facing ``b``'s FACING side) that both can do without,
    removed from both in order along the side: their positions along it, with each tile's removals (Cut).
    Round after round until none goes; a vertex's removal is worked out again only once its star changed
    (Editable.removal)."""
    other = FACING[side]
    along = 1 if side in ("left", "right") else 0
    k, at = _line(side, a.w, a.h)
    line = sorted((p for p in a.at if p[k] == at), key=lambda p: p[along])
    removed, done, plans_a, plans_b = [], set(), [], []
    while True:
        more = False
        for p in line:
            pos = p[along]
            if pos in done:
                continue
            ra = a.removal(p, side)
            rb = ra and b.removal(side_point(other, pos, b.w, b.h), other)
            if ra and rb:
                a.apply(ra)
                b.apply(rb)
                plans_a.append(ra)
                plans_b.append(rb)
                removed.append(pos)
                done.add(pos)
                more = True
        if not more:
            return Cut(removed, {side: plans_a, other: plans_b})


# ---------------------------------------------------------------------------------------------------
# The band at the seams decimated again: the inner vertices whose stars the seams' steps changed


# decimate_inner searches every triangulation of a ring of at most this many vertices (when no fan and no
# ear clipping is within zeta): make bench-tiles' 8,192^2 terrain in tiles of 1,025 with 0 / 8 / 16 here,
# 8,610 / 8,584 / 8,580 triangles; the pass on the Jacksboro tiles of 1,025 32 / 53 / 66 ms a tile (timed
# at load 6 to 8)
INNER_SEARCH = 8


def decimate_inner(mesh: Mesh, within, dirty: Iterable[int]) -> tuple[Mesh, np.ndarray, np.ndarray]:
    """``mesh`` less the inner vertices (off the rectangle's sides: every side vertex stays) that can go:
    the refiner's final decimation (decimate.c) again, from the vertices ``dirty`` only.  Pass after pass,
    each dirty inner vertex in row order (by y, then x) whose ring has a triangulation every triangle of
    which ``within`` accepts (the fans from each ring vertex, the refiner's first tries; the fattest ears,
    the first ears, then every triangulation of a ring of at most INNER_SEARCH vertices:
    mesh.fill_hole) is removed with it, and its ring's inner vertices are dirty again.  Also
    (T',) bool: the result's triangles that are new, and (T,) bool: ``mesh``'s triangles that went.  Only
    the stars visited are held as Python objects, loaded a pass at a time (one gather over the mesh's
    triangles a pass)."""
    w, h = mesh.width, mesh.height
    base = mesh.tris
    n_t, n_v = len(base), len(mesh.xy)
    xs, ys = mesh.xy[:, 0], mesh.xy[:, 1]
    is_inner = (xs > 0) & (xs < w - 1) & (ys > 0) & (ys < h - 1)
    tris: dict[int, tuple] = {}  # the triangles loaded (and the new ones, numbered from n_t)
    inc: dict[int, set[int]] = {}  # vertex -> its loaded triangles (its whole star once it is in ``full``)
    full = np.zeros(n_v, dtype=bool)
    loaded = np.zeros(n_t, dtype=bool)
    went = np.zeros(n_t, dtype=bool)
    xy: dict[int, tuple[int, int]] = {}
    made: list[int] = []
    gone: list[int] = []
    todo = {v for v in dirty if is_inner[v]}
    tested: dict = {}  # a triangle's corners -> within's answer (_within_kept)
    while todo:
        need = np.zeros(n_v, dtype=bool)
        need[[v for v in todo if not full[v]]] = True
        take = np.flatnonzero(touching(need, base) & ~loaded)  # the stars not yet loaded
        loaded[take] = True
        full |= need
        for k, t in zip(take.tolist(), base[take].tolist(), strict=True):
            tris[k] = t = tuple(t)
            for u in t:
                inc.setdefault(u, set()).add(k)
        fresh = [u for u in inc if u not in xy]
        xy.update(zip(fresh, map(tuple, mesh.xy[fresh].tolist()), strict=True))
        for v in sorted(todo, key=lambda v: (xy[v][1], xy[v][0])):
            todo.discard(v)
            fan = inc[v]
            ring = _ring(v, (tris[k] for k in fan))
            pts = [xy[u] for u in ring]
            cut = fill_hole(pts, _within_kept(within, tested, pts), with_fans=True, limit=INNER_SEARCH)
            if cut is None:
                continue
            for k in list(fan):
                for u in tris.pop(k):
                    inc[u].discard(k)
                if k < n_t:
                    went[k] = True
            for c in cut:
                k = n_t + len(made)
                tris[k] = t = tuple(ring[i] for i in c)
                made.append(k)
                for u in t:
                    inc[u].add(k)
            del inc[v]
            gone.append(v)
            todo.update(u for u in ring if is_inner[u])
    if not gone:
        return mesh, np.zeros(n_t, dtype=bool), went
    new = np.array([tris[k] for k in made if k in tris], dtype=np.int64).reshape(-1, 3)
    keep = np.ones(n_v, dtype=bool)
    keep[gone] = False
    remap = np.cumsum(keep) - 1
    out = remap[np.concatenate([np.compress(~went, base, axis=0), new])]
    mask = np.zeros(len(out), dtype=bool)
    mask[len(out) - len(new):] = True
    return Mesh(w, h, np.compress(keep, mesh.xy, axis=0), out), mask, went
