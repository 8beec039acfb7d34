"""A tile's jobs (free, conformed, thinned), a run of them, the stitched mesh (docs/tiles.md, steps 3-7)."""

from __future__ import annotations

import functools
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from wavemesh import api
from wavemesh.check import mesh_errors
from wavemesh.errors import InputError, MeshInvalid
from wavemesh.io.georef import cropped
from wavemesh.io.heightfield import HeightField
from wavemesh.mesh import Mesh
from wavemesh.record import record
from wavemesh.refine import native
from wavemesh.tiles.plan import Tile, TilePlan, plan_tiles, with_error
from wavemesh.tiles.runner import Here, Node, Ref, Runner
from wavemesh.tiles.sides import (
    FACING,
    SIDES,
    Editable,
    _on_sides,
    border_of,
    conform,
    decimate_inner,
    reconcile,
    side_point,
    side_profile,
    thin_side,
    touching,
)
from wavemesh.tiles.source import BLOCK_SAMPLES, Source, file_identity, light_source, strip_error, strip_tasks

# ---------------------------------------------------------------------------------------------------
# One tile's jobs: free (step 3), conformed to its reconciled sides (steps 4 and 5), thinned (step 6)


@record
class FreeTile:
    """A tile's mesh by the full pipeline (tile coordinates), the refiner's last statistics, its sides'
    vertices, and its numbers."""

    index: int
    mesh: Mesh
    over: int  # triangles above zeta (0: the bound met)
    bound_splits: int
    sides: dict  # side -> positions (border_of)
    seconds: float
    extra: dict


@record
class TileResult:
    """A tile's mesh in grid coordinates of the whole input, its vertices' heights, and its numbers."""

    index: int
    name: str
    xy: np.ndarray  # (V, 2) int64, whole-grid positions
    tris: np.ndarray  # (T, 3) int64 into xy
    z: np.ndarray  # (V,) float64 heights (of a float32 tile too)
    report: dict
    device: str | None = None  # the port that made it (stream)
    # E_max (vertical, normal) of its triangles that touch none of its shared sides (_checked): thin_tile
    # keeps those as they are and measures only the others
    inner: tuple[float, float] | None = None


# a process's tiles kept by tile_heightfield (1025^2: 10.5 MiB each, 6.3 with float32 heights; a tile's
# steps wait for the next two rows of tiles: 8192^2 in tiles of 1025, one worker, reads each tile once
# with 320 MiB, 136 reads with 256, 470 without, as float64), none above a sixth of it (4097^2: 168 MiB,
# read again)
TILE_CACHE_BYTES = 320 << 20
_TILE_CACHE: OrderedDict = OrderedDict()  # key -> HeightField, the last used last
_TILE_LOCK = threading.Lock()  # stream's threads read tiles at once


def tile_heightfield(plan: TilePlan, t: Tile, window: np.ndarray | None = None, keep: bool = True
                     ) -> HeightField:
    """The tile as a HeightField: its window of the input with the whole grid's quantisation, its
    place on the ground, and the whole grid's cell size.  A file's tiles are kept by the process that read
    them (the last TILE_CACHE_BYTES of them, read-only): every phase of a tile reads it (free, conformed,
    its sides thinned), and the pool gives a tile's tasks to the worker that read it first (Runner.graph).
    A file replaced under the same name is read anew.  ``keep`` False: a tile this process does not hold
    is read and not kept (a seam's neighbour another worker holds: it would stay here, never forgotten)."""
    key = _cache_key(plan, t, window)
    if key is None:
        return _tile_heightfield(plan, t, window)
    hf = _held(key)
    if hf is not None:
        return hf
    hf = _tile_heightfield(plan, t, None)
    if not keep:
        return hf
    for a in (hf.values, hf.samples):
        a.flags.writeable = False
    with _TILE_LOCK:
        _TILE_CACHE[key] = hf
        while sum(h.values.nbytes + h.samples.nbytes for h in _TILE_CACHE.values()) > TILE_CACHE_BYTES \
                and len(_TILE_CACHE) > 1:
            _TILE_CACHE.popitem(last=False)
    return hf


def _cache_key(plan: TilePlan, t: Tile, window: np.ndarray | None) -> tuple | None:
    src = plan.source
    if window is not None or src.kind == "array" or src.path is None \
            or 10 * t.width * t.height > TILE_CACHE_BYTES // 6:
        return None
    quant = plan.quant  # its q aside: the samples do not depend on it (tile_graph may find it later)
    return (src, quant.scale, quant.offset, quant.exact, plan.spacing, t.x, t.y, t.width, t.height,
            file_identity(src.path))


def _held(key: tuple | None) -> HeightField | None:
    """The tile this process holds under ``key`` (_cache_key; now the last used), or None."""
    if key is None:
        return None
    with _TILE_LOCK:
        hf = _TILE_CACHE.get(key)
        if hf is not None:
            _TILE_CACHE.move_to_end(key)
    return hf


def _finite(plan: TilePlan, t: Tile, v: np.ndarray) -> np.ndarray:
    """``v``, heights of tile ``t``, or InputError when one is NaN or infinite: checked a block of rows at a
    time (source.BLOCK_SAMPLES), each block's flags in the core's own cache and in one buffer, not a whole
    tile's flags in fresh memory (1 MiB at 1025^2: a pool worker's heap grew for it, pages faulted in)."""
    step = max(1, BLOCK_SAMPLES // max(1, v.shape[1]))
    flags = np.empty((min(step, v.shape[0]), v.shape[1]), dtype=bool)
    for b in range(0, v.shape[0], step):
        block = v[b : b + step]
        ok = flags[: len(block)]
        if not np.isfinite(block, out=ok).all():
            raise InputError(f"{plan.source.name}: non-finite samples in {t.name}", hint="use --fill VALUE")
    return v


def forget_tile(plan: TilePlan, index: int) -> None:
    """The tile out of this process's tiles (its last step is done): its memory for the next tiles."""
    key = _cache_key(plan, plan.tiles[index], None)
    if key is not None:
        with _TILE_LOCK:
            _TILE_CACHE.pop(key, None)


def clear_tile_cache() -> None:
    """Forget the tiles tile_heightfield kept in this process."""
    with _TILE_LOCK:
        _TILE_CACHE.clear()


def _tile_heightfield(plan: TilePlan, t: Tile, window: np.ndarray | None) -> HeightField:
    src, quant = plan.source, plan.quant
    v = _finite(plan, t, src.read(t.x, t.y, t.width, t.height) if window is None else window)
    samples, error = quant.quantised(v)
    hf = HeightField(values=v, samples=samples, scale=quant.scale, offset=quant.offset,
                     lossless=quant.lossless, source=f"{src.name} {t.name}",
                     transform=cropped(src.transform, t.x, t.y, 1), crs=src.crs, spacing=plan.spacing)
    if not hf.lossless:  # the tile's own largest error, from the same pass (that cached property's value)
        hf.__dict__["max_quantisation_error"] = error
    return hf


def free_tile(plan: TilePlan, index: int, window: np.ndarray | None = None) -> FreeTile:
    """Step 3 for one tile: the full pipeline of `wavemesh mesh` (with the whole grid's tau and M)."""
    t0 = time.perf_counter()
    hf = tile_heightfield(plan, plan.tiles[index], window)
    p = plan.params.refine
    job = api.triangulate(hf, plan.levels, plan.tau, plan.params.wavelet)
    # the details by the library's filter bank, as api.refine (the templates' own when triangulate made them)
    out = native.refine(hf.samples, job.levels, job.mesh, p, scale=hf.scale, zeta=hf.refiner_zeta(p.zeta),
                        spacing=plan.spacing, wavelet=job.wavelet, details=job.details)
    final = out.final
    return FreeTile(index, final.mesh, final.stats["over"], final.stats["bound_splits"],
                    border_of(final.mesh), time.perf_counter() - t0, {"levels": job.levels})


@record
class _Level:
    """The shape of a refiner level (wavemesh.native's) that api.RefineJob reads."""

    mesh: Mesh
    stats: dict


@record
class _Levels:
    final: _Level


def finish_tile(plan: TilePlan, free: FreeTile, facing: dict, window: np.ndarray | None = None) -> TileResult:
    """Steps 4 and 5 for one tile: each shared side reconciled with the neighbour's vertices on it
    (``facing``: side -> the neighbour's positions), the free mesh conformed to them, the error bound run
    on it, the inner vertices of the triangles the free mesh lacks decimated again (decimate_inner), the
    result checked (proper, the reconciled sides, within zeta) and measured."""
    t0 = time.perf_counter()
    t = plan.tiles[free.index]
    hf = tile_heightfield(plan, t, window)
    p = plan.params.refine
    fp = native.fixed_params(p, hf.scale, plan.zeta_used, plan.spacing)
    sides = {s: reconcile(side_profile(hf.samples, s), free.sides[s], facing[s], fp,
                          0 if s in ("top", "bottom") else 1, p.metric) for s in t.neighbours}
    out = _Levels(_Level(free.mesh, {"over": free.over, "bound_splits": free.bound_splits}))
    if any(sides[s] != free.sides[s] for s in sides):
        bound = replace(p, reduce=False, decimate=False, max_triangles=None, capacity=None)
        conformed, made = conform(free.mesh, sides, made=True)
        out = native.refine(hf.samples, 1, conformed, bound,
                            scale=hf.scale, zeta=plan.zeta_used, spacing=plan.spacing)
        if not out.final.stats["over"]:  # the stars that changed decimated again
            m = out.final.mesh
            ch = _changed(conformed, made, m)
            m, _, _ = decimate_inner(m, native.error_within(hf.samples, fp), _touched(m, ch))
            out = _Levels(_Level(m, out.final.stats))
    if out.final.stats["over"]:
        raise MeshInvalid(f"{t.name}: {out.final.stats['over']} triangles above zeta after the border's "
                          "error bound", hint=api.BUG_HINT)
    report = {"tile": t.name, "row": t.row, "col": t.col, "x": t.x, "y": t.y, "width": t.width,
              "height": t.height, "triangles_before_border": free.mesh.n_triangles,
              "bound_splits": out.final.stats["bound_splits"]} | free.extra
    zeta = plan.zeta_used if sides else hf.refiner_zeta(p.zeta)
    seconds = free.seconds + time.perf_counter() - t0
    return _checked(plan, free.index, hf, out.final.mesh, sides, report, seconds, zeta)


def _measured(mesh: Mesh, hf: HeightField, spacing, which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """E(T) vertical and normal of ``mesh``'s triangles ``which`` (mesh_errors' per-triangle values: each
    triangle's are its own, however many are measured with it)."""
    if not which.any():
        return np.empty(0), np.empty(0)
    tris = np.compress(which, mesh.tris, axis=0)  # mesh.tris[which]'s rows, in a quarter of its time
    e = mesh_errors(Mesh(mesh.width, mesh.height, mesh.xy, tris), hf.values, rms=False, spacing=spacing)
    return e.per_triangle_vertical, e.per_triangle_normal


def _top(*parts) -> float:
    """The largest of the measured values (NaN: not measured) in ``parts``, -inf when there are none."""
    return max((float(np.nanmax(a)) for a in parts if len(a) and not np.isnan(a).all()), default=-np.inf)


def _checked(plan: TilePlan, index: int, hf: HeightField, final: Mesh, sides: dict, report: dict,
             seconds: float, zeta_used: float, inner: tuple | None = None, new: np.ndarray | None = None
             ) -> TileResult:
    """A tile's last mesh checked (proper, exactly the decided ``sides``, within zeta) and measured.
    ``inner``, ``new``: the E_max of the triangles of the mesh before that touch none of the tile's shared
    sides (TileResult.inner) and which triangles are new: those kept as they were are not measured
    again (thin_tile: each removal only replaces triangles at a shared side)."""
    p, t = plan.params.refine, plan.tiles[index]
    api.require_proper(final, f"{t.name}'s mesh")
    got = border_of(final)
    diff = [s for s in SIDES if s in sides and got[s] != tuple(sides[s])]
    if diff:
        raise MeshInvalid(f"{t.name}: the mesh's border is not the decided one ({', '.join(diff)})",
                          hint=api.BUG_HINT)
    on = np.zeros(len(final.xy), dtype=bool)
    for s, m in _on_sides(final.xy, final.width, final.height).items():
        if s in t.neighbours:
            on |= m
    shared = touching(on, final.tris)  # the triangles that touch a shared side
    if inner is None:
        errors = mesh_errors(final, hf.values, rms=False, spacing=plan.spacing)
        per_v, per_n = errors.per_triangle_vertical, errors.per_triangle_normal
        inner = (_top(per_v[~shared]), _top(per_n[~shared]))
    else:  # the triangles touching no shared side that were there before: within inner
        which = shared | new
        per_v, per_n = _measured(final, hf, plan.spacing, which)
        away = ~shared[which]  # the new ones touching no shared side
        e_v, e_n = _top(per_v), _top(per_n)
        errors = SimpleNamespace(e_max_vertical=max(inner[0], e_v), e_max_normal=max(inner[1], e_n))
        if errors.e_max_vertical == -np.inf:
            errors = SimpleNamespace(e_max_vertical=math.nan, e_max_normal=math.nan)
        inner = (max(inner[0], _top(per_v[away])), max(inner[1], _top(per_n[away])))
    rjob = api.RefineJob(None, p, zeta_used, _Levels(_Level(final, {"over": 0})), 0.0)
    excess = api.bound_excess(hf, rjob, errors)
    if excess:
        raise MeshInvalid(f"{t.name}: {excess}", hint=api.BUG_HINT)
    report = report | {"vertices": final.n_vertices, "triangles": final.n_triangles,
                       "border_vertices": {s: len(v) for s, v in sides.items()}, "seconds": seconds,
                       "e_max_normal": errors.e_max_normal, "e_max_vertical": errors.e_max_vertical}
    return TileResult(index, t.name, final.xy + np.array([t.x, t.y], dtype=np.int64),
                      final.tris, final.z(hf.values).astype(np.float64, copy=False), report,
                      report.get("device"), inner)


def _editable(plan: TilePlan, r: TileResult, window: np.ndarray | None, sides: list[str], keep: bool = True
              ) -> tuple[Editable, HeightField]:
    t = plan.tiles[r.index]
    hf = tile_heightfield(plan, t, window, keep)
    fp = native.fixed_params(plan.params.refine, hf.scale, plan.zeta_used, plan.spacing)
    mesh = Mesh(t.width, t.height, r.xy - np.array([t.x, t.y], dtype=np.int64), r.tris)
    return Editable(mesh, native.error_within(hf.samples, fp), sides), hf


def _seam_editable(plan: TilePlan, r: TileResult, window: np.ndarray | None, side: str) -> Editable:
    """Tile ``r`` as thin_seam edits it at its ``side``.  A tile this process does not hold (the other tile
    of a seam between two workers' tiles; a tile too large to keep) is read for it alone, not kept, and only
    its band at the side: the box of the triangles that touch the side.  Every triangle the thinning tests
    lies in it (each is of a side vertex's ring, within its star: within those triangles or the ones made
    from them), and E(T) reads only the samples in its triangle; a triangle outside it is an error."""
    t = plan.tiles[r.index]
    mesh = Mesh(t.width, t.height, r.xy - np.array([t.x, t.y], dtype=np.int64), r.tris)
    fp = native.fixed_params(plan.params.refine, plan.quant.scale, plan.zeta_used, plan.spacing)
    held = _held(_cache_key(plan, t, window))
    if held is not None or window is not None:
        hf = held if held is not None else tile_heightfield(plan, t, window, False)
        return Editable(mesh, native.error_within(hf.samples, fp), [side])
    on = _on_sides(mesh.xy, t.width, t.height)[side]
    # their box (no np.unique: sides.conform)
    at = mesh.xy[np.compress(touching(on, mesh.tris), mesh.tris, axis=0).ravel()]
    (x0, y0), (x1, y1) = at.min(axis=0).tolist(), at.max(axis=0).tolist()
    v = _finite(plan, t, plan.source.read(t.x + x0, t.y + y0, x1 - x0 + 1, y1 - y0 + 1))
    samples = np.zeros((t.height, t.width), dtype=np.uint16)
    samples[y0 : y1 + 1, x0 : x1 + 1] = plan.quant.quantised(v)[0]
    test = native.error_within(samples, fp)

    def within(x, y) -> bool:
        if not (x0 <= min(x) and max(x) <= x1 and y0 <= min(y) and max(y) <= y1):
            raise MeshInvalid(f"{t.name}: a triangle off the band read at its {side} side", hint=api.BUG_HINT)
        return test(x, y)

    return Editable(mesh, within, [side])


def thin_seam(plan: TilePlan, a: TileResult, b: TileResult, side: str, win_a=None, win_b=None) -> tuple:
    """Step 6 for one shared side (``a``'s ``side``, facing ``b``): the positions of the vertices on it
    both tiles can do without (sides.thin_side), found on copies of both meshes.  A tile this process does
    not hold (the other tile of a seam between two workers' tiles) is read for it alone, not kept: only its
    band at the side (_seam_editable)."""
    return thin_side(_seam_editable(plan, a, win_a, side), _seam_editable(plan, b, win_b, FACING[side]), side)


def thin_tile(plan: TilePlan, r: TileResult, removed: dict, window: np.ndarray | None = None) -> TileResult:
    """Step 6 for one tile: the vertices ``removed`` (side -> positions, as thin_seam found them) taken
    out, side by side (the sides' removals touch no common triangle), the result checked again.  A side
    given as thin_seam's Cut is taken out by the removals it found on this same mesh (each vertex's star
    there is its star here: the other sides' removals never touch it); plain positions are worked out
    again.  Then the inner vertices of the triangles the removals made decimated again (_decimated)."""
    if not any(removed.values()):  # nothing to take out: the mesh as it was checked
        return replace(r, report=r.report | {"seam_removed": r.report.get("seam_removed", 0)})
    t0 = time.perf_counter()
    t = plan.tiles[r.index]
    ed, hf = _editable(plan, r, window, [s for s in SIDES if removed.get(s)])
    for side in SIDES:
        cut = removed.get(side, ())
        plans = getattr(cut, "plans", {}).get(side)
        for k, pos in enumerate(cut):
            p = side_point(side, pos, t.width, t.height)
            step = ed.removal(p, side) if plans is None else plans[k]
            if step is not None and ed.at.get(p) != step[0]:
                step = None
            if step is None:
                raise MeshInvalid(f"{t.name}: a seam vertex both tiles could do without could not be removed "
                                  f"({side} {pos})", hint=api.BUG_HINT)
            ed.apply(step)
    final, new = ed.mesh(), ed.new()
    inner = r.inner
    final, new, inner = _decimated(plan, t, hf, final, new, inner, ed.within)
    before = border_of(ed.source)  # r's mesh in tile coordinates, as _editable made it
    gone = {s: set(removed.get(s, ())) for s in t.neighbours}
    sides = {s: tuple(q for q in before[s] if q not in gone[s]) for s in t.neighbours}
    report = r.report | {"seam_removed": r.report.get("seam_removed", 0) + sum(map(len, removed.values()))}
    seconds = r.report["seconds"] + time.perf_counter() - t0
    return _checked(plan, r.index, hf, final, sides, report, seconds, plan.zeta_used, inner, new)


def _touched(mesh: Mesh, which: np.ndarray) -> np.ndarray:
    """The vertices of ``mesh``'s triangles ``which`` (a (T,) bool), sorted (no np.unique: sides.conform)."""
    return np.flatnonzero(np.bincount(np.compress(which, mesh.tris, axis=0).ravel(), minlength=len(mesh.xy)))


def _changed(conformed: Mesh, made: int, final: Mesh) -> np.ndarray:
    """(T,) bool over the error bound's ``final`` mesh: the triangles that the conformed tile's free mesh
    lacks (conform made its last ``made`` triangles).  The refiner keeps a mesh's vertices and triangles
    in their slots (a split triangle's first child in its slot, the others and new vertices after them):
    a triangle in the slot of the same triangle is the free mesh's, every other one is new."""
    n, k = len(conformed.tris), min(len(conformed.tris), len(final.tris))
    if len(final.xy) < len(conformed.xy) or not np.array_equal(final.xy[: len(conformed.xy)], conformed.xy):
        return np.ones(len(final.tris), dtype=bool)  # not kept in their slots: all of them
    out = np.ones(len(final.tris), dtype=bool)
    out[:k] = np.any(final.tris[:k] != conformed.tris[:k], axis=1)
    out[n - made : k] = True
    return out


def _decimated(plan: TilePlan, t: Tile, hf: HeightField, mesh: Mesh, new: np.ndarray, inner: tuple | None,
               within) -> tuple[Mesh, np.ndarray, tuple | None]:
    """thin_tile's mesh decimated again at the vertices of its new triangles (decimate_inner): the mesh,
    its new triangles, and ``inner`` still the E_max of the others that touch no shared side (None: measure
    the whole tile again, when a triangle that went held it)."""
    out, made, went = decimate_inner(mesh, within, _touched(mesh, new))
    if not went.any():
        return mesh, new, inner
    on = np.zeros(len(mesh.xy), dtype=bool)
    for s, m in _on_sides(mesh.xy, mesh.width, mesh.height).items():
        if s in t.neighbours:
            on |= m
    old = went & ~new & ~touching(on, mesh.tris)  # the triangles inner measured that went
    if inner is not None and old.any():
        per_v, per_n = _measured(mesh, hf, plan.spacing, old)
        if _top(per_v) >= inner[0] or _top(per_n) >= inner[1]:
            inner = None
    return out, np.concatenate([np.compress(~went, new), np.ones(int(made.sum()), dtype=bool)]), inner


def _window(plan: TilePlan, index: int) -> np.ndarray | None:
    """A tile's heights when the input is in memory here (a worker cannot read it), else None."""
    if plan.source.kind != "array":
        return None
    t = plan.tiles[index]
    return plan.source.read(t.x, t.y, t.width, t.height)


def _side(side: str, free: FreeTile) -> tuple:
    return free.sides[side]


# a Ref's pick of a free mesh's side (partials of a module-level function: they pickle, for the pool and Dask)
_SIDE_OF = {s: functools.partial(_side, s) for s in SIDES}


def _largest(*errors: float) -> float:
    """The whole grid's largest quantisation error from its strips' (tile_graph's node)."""
    return max(errors)


def _finish_node(plan: TilePlan, free: FreeTile, window, last: bool, sides: tuple, q: float, *facing
                 ) -> TileResult:
    """finish_tile, ``facing`` the neighbours' sides in the order of ``sides`` (Runner.graph's args), ``q``
    the whole grid's largest quantisation error; ``last``: the tile's last step (its heights forgotten
    then)."""
    plan = with_error(plan, q)
    r = finish_tile(plan, free, dict(zip(sides, facing, strict=True)), window)
    if last:
        forget_tile(plan, free.index)
    return r


def _seam_node(plan: TilePlan, q: float, a: TileResult, b: TileResult, side: str, win_a, win_b) -> tuple:
    """thin_seam, ``q`` the whole grid's largest quantisation error."""
    return thin_seam(with_error(plan, q), a, b, side, win_a, win_b)


def _thin_node(plan: TilePlan, r: TileResult, window, last: bool, sides: tuple, q: float, *cuts
               ) -> TileResult:
    """thin_tile with ``removed`` as the seams' cuts in the order of ``sides`` (Runner.graph's args), ``q``
    the whole grid's largest quantisation error."""
    plan = with_error(plan, q)
    out = thin_tile(plan, r, dict(zip(sides, cuts, strict=True)), window)
    if last:
        forget_tile(plan, r.index)
    return out


def tile_graph(plan: TilePlan, frees: list | None = None) -> tuple[list[Node], dict]:
    """Every tile's jobs as Runner.graph nodes: free (unless ``frees`` has them), conformed (once the
    tile's and its neighbours' free meshes are done), each column side thinned (once both tiles are
    conformed), each tile without its column sides' thinned vertices, then the same for the row sides.
    Ranked by the last tile (row by row) their inputs wait for, then the step: a tile goes on through its
    steps while the next tiles are made.  A plan without its largest quantisation error yet (plan_tiles'
    ``defer_error``): the quantisation's strips (strip_error) and their largest ("q") too, ranked after the
    first row of free meshes and before the first conformed tile, which (as every later step) reads it.
    Also {"free": nodes, "finish": nodes, "last": nodes} in tile order, "q" (the node or None) and "homes"
    and "shared" (Runner.graph's: a block of columns of tiles per worker; the plan)."""
    n = len(plan.tiles)
    light = replace(plan, source=light_source(plan.source))
    win = [Here(_window, (plan, i)) if plan.source.kind == "array" else None for i in range(n)]
    nodes: list[Node] = []
    wave: list[int] = []  # each node's rank's first number

    def add(fn, args: tuple, step: int, tiles: tuple, waits: tuple = ()) -> int:
        w = max([*tiles, *waits, *(wave[a.node] for a in args if isinstance(a, Ref))])
        nodes.append(Node(fn, args, (w, step), tiles))
        wave.append(w)
        return len(nodes) - 1

    free_of: list = [add(free_tile, (light, i, win[i]), 0, (i,)) for i in range(n)] if frees is None \
        else [None] * n

    nx = len(plan.xcuts) - 1
    q_node = None
    q: object = plan.quant.q
    if q is None:
        strips = [add(strip_error, (*task, plan.quant), -1, (), (nx,)) for task in strip_tasks(light.source)]
        q_node = add(_largest, tuple(map(Ref, strips)), -1, (), (nx,))
        q = Ref(q_node)

    def free_arg(i: int, pick=None):
        return Ref(free_of[i], pick) if frees is None else (frees[i] if pick is None else pick(frees[i]))

    cur = []
    phases = [s for s in ("right", "bottom") if any(s in t.neighbours for t in plan.tiles)]
    for i, t in enumerate(plan.tiles):
        sides = tuple(t.neighbours)
        facing = [free_arg(k, _SIDE_OF[FACING[s]]) for s, k in t.neighbours.items()]
        cur.append(add(_finish_node, (light, free_arg(i), win[i], not phases, sides, q, *facing), 1, (i,),
                       tuple(t.neighbours.values())))
    finish = list(cur)
    step = 2
    for side in phases:  # the columns' sides, then the rows': two opposite sides at a time
        pairs = [(i, k) for i, t in enumerate(plan.tiles) for s, k in t.neighbours.items() if s == side]
        cut: list[dict] = [{} for _ in range(n)]
        for i, k in pairs:
            c = add(_seam_node, (light, q, Ref(cur[i]), Ref(cur[k]), side, win[i], win[k]), step, (i, k))
            cut[i][side] = cut[k][FACING[side]] = c
        last = side == phases[-1]
        cur = [add(_thin_node, (light, Ref(cur[i]), win[i], last, tuple(cut[i]), q,
                                *map(Ref, cut[i].values())), step + 1, (i,)) for i in range(n)]
        step += 2
    homes = {i: t.col / nx for i, t in enumerate(plan.tiles)}  # columns of tiles, a block per worker
    return nodes, {"free": free_of if frees is None else [], "finish": finish, "last": cur, "q": q_node,
                   "homes": homes, "shared": (light,)}


def run_tiles(plan: TilePlan, *, workers: int | None = None, scheduler=None, runner: Runner | None = None,
              progress: bool = False, log: Callable[[str], None] | None = None,
              frees: list | None = None, sink: Callable[[TileResult], None] | None = None
              ) -> list[TileResult]:
    """Every tile's jobs (tile_graph) on ``runner`` (or a Runner of ``workers`` / ``scheduler`` for this
    call): the free meshes (unless ``frees`` has them, as stream_tiles makes them), each tile conformed to
    its reconciled sides, each shared side thinned (thin_seam), each tile without its sides' thinned
    vertices (thin_tile), each step of a tile as soon as its inputs are done; the results in tile order
    whatever order they finish in.  ``sink``: each tile's result given to it as it finishes (any order;
    files.TiledFiles writes them in tile order), none kept here (the list is empty).  A failed task ends
    the run with its error."""
    if runner is None:
        with Runner(workers, scheduler) as own:
            return run_tiles(plan, runner=own, progress=progress, log=log, frees=frees, sink=sink)
    n = len(plan.tiles)
    nodes, roles = tile_graph(plan, frees)
    counted = set(roles["free"]) | set(roles["finish"])
    last = {k: i for i, k in enumerate(roles["last"])}
    try:
        with api.Progress("tiles", 3 * n, progress) as bar:
            count = [0 if frees is None else n, 0]

            def done(k: int, r) -> None:
                if k in counted:
                    count[0] += 1
                    bar.update(count[0] + count[1])
                if k in last:
                    count[1] += 1
                    note = f"{r.name}: {len(r.tris)} triangles, {r.report['seconds']:.2f} s"
                    bar.update(count[0] + count[1], note)
                    if log:
                        log(f"  {count[1]}/{n} {note}")
                    if sink:
                        sink(r)
                if k == roles["q"]:  # the plan complete (every tile's last step reads q: before them)
                    known = with_error(plan, r)
                    plan.quant, plan.zeta_used = known.quant, known.zeta_used

            keep = () if sink else roles["last"]
            seen = [*roles["last"], *([roles["q"]] if roles["q"] is not None else [])]  # what done reads
            results = runner.graph(nodes, done, roles["homes"], roles["shared"], keep, last=True, seen=seen)
            bar.finish(f"{n} tiles")
    finally:
        clear_tile_cache()  # this process's (run here: one worker); a pool's ends with its workers
    return [] if sink else [results[k] for k in roles["last"]]


# ---------------------------------------------------------------------------------------------------
# Stitching


@record
class TiledResult:
    """The stitched mesh, the vertices' heights, and the run's report."""

    mesh: Mesh
    z: np.ndarray
    tiles: list[TileResult]
    report: dict


ONE_KEY = 1 << 21  # TileOrder sorts the triangles of a tile of fewer vertices by one key, n^3 < 2^63
_TURNS = np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1]])  # a triangle's corners from corner 0, 1 or 2


class TileOrder:
    """The whole mesh's vertex numbers, given tile by tile in tile order (row by row, each row left to
    right: :meth:`number` of every tile in turn), so that a file can be written as the tiles come: a
    tile's vertices on a side it shares with a tile before it (its top side, its left side) keep the
    numbers that tile gave them; its others are numbered next, by (y, x); its triangles are renumbered,
    each started at its smallest number, and sorted.  Only the shared sides' vertices the next tiles need
    are kept (a row of tiles' bottom sides and the current row's right sides).  Checks that every shared
    side has the same vertices in both tiles: with each tile proper (checked in its worker, _checked) and
    the tiles covering the grid (the plan), the whole mesh is then a proper triangulation, no T-junction,
    no crack."""

    def __init__(self, plan: TilePlan):
        self.plan = plan
        self.next = 0  # the tile number() expects
        self.vertices = self.triangles = 0
        self._known: dict[int, int] = {}  # y W + x -> the vertex's number, for the sides the next tiles share
        self._counts: dict[tuple, int] = {}  # (tile, side) -> its vertices on that side (bottom, right)

    def number(self, r: TileResult) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
        """Tile ``r`` (the next in tile order): its vertices (grid positions) and heights, first those an
        earlier tile numbered, then its new ones in their order; its triangles into them; each vertex's
        number; and how many were numbered before (wavemesh.io.meshio.MeshStream.add's piece)."""
        plan, W = self.plan, self.plan.width
        if r.index != self.next:
            raise ValueError(f"tile {r.index} given where tile {self.next} is next")
        t = plan.tiles[r.index]
        x, y = r.xy[:, 0], r.xy[:, 1]
        if t.col == 0:  # a new row of tiles: the sides above its top are read no more
            self._known = {k: v for k, v in self._known.items() if k >= t.y * W}
        old = np.zeros(len(x), dtype=bool)
        for side, on in (("top", y == t.y), ("left", x == t.x)):
            if side in t.neighbours:
                k = t.neighbours[side]
                had = self._counts.pop((k, "bottom" if side == "top" else "right"))
                if int(np.count_nonzero(on)) != had:
                    raise MeshInvalid(f"{t.name} has {np.count_nonzero(on)} vertices on its {side} side, "
                                      f"{plan.tiles[k].name} {had} on the same side", hint=api.BUG_HINT)
                old |= on
        was = np.flatnonzero(old)
        try:
            before = [self._known[k] for k in (y[was] * W + x[was]).tolist()]
        except KeyError as e:
            raise MeshInvalid(f"{t.name}: its vertex ({e.args[0] % W}, {e.args[0] // W}) on a shared side is "
                              "not its neighbour's", hint=api.BUG_HINT) from None
        new = np.flatnonzero(~old)
        new = new[np.argsort(y[new] * W + x[new])]  # by (y, x): one key (no two vertices at one place)
        perm = np.concatenate([was, new])
        number = np.concatenate([np.asarray(before, dtype=np.int64),
                                 np.arange(self.vertices, self.vertices + len(new), dtype=np.int64)])
        where = np.empty(len(perm), dtype=np.int64)
        where[perm] = np.arange(len(perm))
        tris = where[r.tris]
        if len(tris):  # each from its smallest number (orientation kept), sorted by their numbers
            n = len(number)  # their order within the tile: the earlier tiles' numbers (sorted), then the new
            rank = np.empty(n, dtype=np.int64)
            rank[np.argsort(number[: len(was)])] = np.arange(len(was))
            rank[len(was):] = np.arange(len(was), n)
            g = rank[tris]
            at = _TURNS[np.argmin(g, axis=1)] + 3 * np.arange(len(g))[:, None]  # flat, from the smallest
            tris, g = tris.ravel()[at], g.ravel()[at]
            if n < ONE_KEY:  # one key: (g0 n + g1) n + g2 < 2^63
                order = np.argsort((g[:, 0] * n + g[:, 1]) * n + g[:, 2])
            else:
                order = np.lexsort((g[:, 2], g[:, 1], g[:, 0]))
            tris = tris[order]
        xy, z = r.xy[perm], r.z[perm]
        ends = (("bottom", xy[:, 1] == t.y + t.height - 1), ("right", xy[:, 0] == t.x + t.width - 1))
        for side, on in ends:
            if side in t.neighbours:
                self._counts[r.index, side] = int(np.count_nonzero(on))
                keys = (xy[on, 1] * W + xy[on, 0]).tolist()
                self._known.update(zip(keys, number[on].tolist(), strict=True))
        self.next += 1
        self.vertices += len(new)
        self.triangles += len(tris)
        return xy, z, tris, number, len(was)


def tiled_report(plan: TilePlan, reports: list[dict], vertices: int, triangles: int) -> dict:
    """A tiled run's report: the layout, the quantisation, the whole mesh's counts, each tile's report."""
    return {
        "tile": plan.tile, "layout": [len(plan.xcuts) - 1, len(plan.ycuts) - 1],
        "xcuts": plan.xcuts, "ycuts": plan.ycuts, "tau": plan.tau, "zeta_refiner": plan.zeta_used,
        "quantisation": {"scale": plan.quant.scale, "offset": plan.quant.offset,
                         "max_quantisation_error": plan.quant.q},
        "vertices": vertices, "triangles": triangles,
        "e_max_normal": max(r["e_max_normal"] for r in reports),
        "e_max_vertical": max(r["e_max_vertical"] for r in reports), "scan_seconds": plan.scan_seconds,
        "tiles": reports,
    }


def stitch(plan: TilePlan, results: list[TileResult]) -> TiledResult:
    """One mesh of the whole grid from the tiles' (in tile order), numbered as TileOrder numbers them (the
    order `wavemesh mesh --tile` writes them in as the tiles finish), checked: a proper triangulation
    (check_mesh: no T-junctions, no cracks)."""
    order = TileOrder(plan)
    xys, zs, triss = [], [], []
    for r in results:
        xy, z, tris, number, start = order.number(r)
        xys.append(xy[start:])
        zs.append(z[start:])
        triss.append(number[tris])
    mesh = Mesh(plan.width, plan.height, np.concatenate(xys), np.concatenate(triss))
    api.require_proper(mesh, "the stitched mesh")
    report = tiled_report(plan, [r.report for r in results], mesh.n_vertices, mesh.n_triangles)
    return TiledResult(mesh, np.concatenate(zs), results, report)


def mesh_tiled(src: Source, params, tile: int | None = None, *, workers: int | None = None, scheduler=None,
               progress: bool = False, log: Callable[[str], None] | None = None) -> TiledResult:
    """`wavemesh mesh --tile`: plan, run the tiles, stitch (one Runner for every phase)."""
    with Runner(workers, scheduler) as runner:
        plan = plan_tiles(src, params, tile, runner=runner, log=log, defer_error=True)
        return stitch(plan, run_tiles(plan, runner=runner, progress=progress, log=log))
