"""Seamless tiles: a height field of any size meshed tile by tile, in parallel, into one proper mesh.

    plan = plan_tiles(source, MeshParams(...), tile=1024)     # the layout, the quantisation, the borders
    results = run_tiles(plan, workers=2)                      # or scheduler="tcp://host:8786" (Dask)
    tiled = stitch(plan, results)                             # one mesh, checked

The steps (docs/tiles.md says why each is so):

1. **Layout.**  The W x H grid is cut into tiles of at most ``tile`` x ``tile`` samples; neighbouring
   tiles share their border row or column, so every tile is an ordinary height field and the tiles
   together cover the grid rectangle exactly.  The cuts are spread evenly (no thin last tile).
2. **One quantisation.**  A first pass over the input, window by window, finds the height range; every
   tile's 16-bit samples are then those of the whole grid (the same scale and offset), so a sample has
   one value whichever tile reads it, and the error bound (zeta less twice the quantisation error for
   lossy input) is one number for all tiles.
3. **Borders decided once.**  Every side of every tile, between two tile corners, is simplified in 1-D
   by the parent before any tile runs: the fewest vertices a greedy walk finds such that every sample
   of the side lies within zeta of the segment between its two neighbouring vertices, measured as the
   refiner measures (exact integers for the vertical metric; for the normal metric the distance to the
   3-D segment, with the refiner's own rounded slope scale and a margin for its rounding).  A plane
   through a segment is never farther from a point than the segment's line is, so any triangle on that
   side is within zeta at the side's samples in both metrics.  Both neighbours get the same list.
4. **Each tile**, in a worker (a local process, or a Dask worker that reads its window itself): the
   full pipeline of ``wavemesh mesh`` on the tile, then its border is conformed to the decided one on
   the host (the missing vertices inserted by splitting the border triangle, the others removed with
   their hole re-triangulated by ear clipping), and the refiner's error bound runs once more on that
   mesh (levels 1, no reduction, no decimation): it splits only the triangles now above zeta, and never
   a border edge, since no border sample can be the worst of a triangle above zeta (step 3).  The tile's
   border is then checked to be exactly the decided one, the tile proper and within zeta.
5. **Stitch.**  The tiles' vertices are merged by grid position (the shared borders are identical), the
   triangles renumbered, and the whole mesh checked (check_mesh: proper, no T-junctions, no cracks).

The same tile jobs run on devices (``wavemesh stream --tile``, :func:`stream_tiles`): the device does
step 4's pipeline, the host conforms and bounds the result as above, so the mesh equals ``wavemesh mesh
--tile``'s byte for byte.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from wavemesh.errors import InputError, MeshInvalid, WavemeshError
from wavemesh.mesh import Mesh

# The tile side without --tile N, from memory (default_tile): the largest of these (2^k + 1, so that a grid
# of 2^j or 2^j + 1 samples a side splits evenly; tiles share a border row) whose tiles in flight, at
# TILE_BYTES_PER_SAMPLE each, fit in half the memory available.  Larger tiles cost fewer triangles at the
# seams, smaller ones less memory and more parallel work (make bench-tiles, docs/tiles.md).
TILE_CHOICES = (4097, 2049, 1025, 513)
TILE_BYTES_PER_SAMPLE = 48  # a worker's peak per sample of its tile (make bench-tiles measured about 40)
MIN_TILE = 16  # smaller tiles are all border
DASK_CONNECT_S = 10  # how long --scheduler ADDRESS may take to answer
STRIP_BYTES = 64 << 20  # the first pass reads the input in row strips of about this many float64 bytes
# The normal metric's 1-D border test keeps this margin below the refiner's zeta (relative, and in sample
# counts), more than the refiner's E(T) rounding (at most about 2^-15 relative + 2^-16, docs/refiner.md).
NORMAL_MARGIN_REL = 2.0 ** -12
NORMAL_MARGIN_ABS = 2.0 ** -12

SIDES = ("top", "right", "bottom", "left")
_BUG = "this is a bug in wavemesh: please report it with the input and the options"


# ---------------------------------------------------------------------------------------------------
# The input, read window by window


@dataclass(frozen=True)
class Source:
    """Where a tiled job's heights come from, picklable: a worker opens it and reads its own window.

    ``kind``: "npy" (a .npy file, read through a memmap), "raster" (a GDAL raster, read by rasterio
    window by window) or "array" (heights in memory, for every other format and for --fill nearest).
    (x0, y0, step): the grid is the file's samples (x0 + step i, y0 + step j) (--crop, --decimate)."""

    kind: str
    width: int
    height: int
    path: str | None = None
    array: np.ndarray | None = None
    x0: int = 0
    y0: int = 0
    step: int = 1
    fill: float | None = None  # --fill VALUE for the lazy kinds
    name: str = "<array>"
    transform: tuple[float, ...] | None = None  # of the tiled grid (after crop and decimate)
    crs: str | None = None
    spacing: tuple[float, float] | None = None  # --spacing, when given

    def read(self, x: int, y: int, w: int, h: int) -> np.ndarray:
        """Heights (float64) of the w x h window whose top-left sample is (x, y), non-finite ones filled
        by --fill VALUE (left as they are without it)."""
        s = self.step
        fx, fy = self.x0 + s * x, self.y0 + s * y
        cols = slice(fx, fx + s * (w - 1) + 1, s)
        rows = slice(fy, fy + s * (h - 1) + 1, s)
        if self.kind == "array":
            v = np.array(self.array[rows, cols], dtype=np.float64)
        elif self.kind == "npy":
            mm = np.load(self.path, mmap_mode="r", allow_pickle=False)
            with np.errstate(invalid="ignore"):
                v = np.array(mm[rows, cols], dtype=np.float64)
            del mm
        else:
            v = _read_raster_window(self.path, fx, fy, s * (w - 1) + 1, s * (h - 1) + 1)[::s, ::s]
        if self.fill is not None:
            v[~np.isfinite(v)] = self.fill
        return v

    def grid(self) -> _Grid:
        return _Grid(self.width, self.height, self.transform, self.crs, self.spacing, self.name)


@dataclass(frozen=True)
class _Grid:
    """What wavemesh.io.georef.ground needs of a height field, without its samples."""

    width: int
    height: int
    transform: tuple[float, ...] | None
    crs: str | None
    spacing: tuple[float, float] | None
    source: str


def _read_raster_window(path: str, x: int, y: int, w: int, h: int) -> np.ndarray:
    """A window of band 1 of a GDAL raster as float64: masked samples NaN, the band's scale and offset
    applied (as wavemesh.io.heightfield reads the whole raster)."""
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning
    from rasterio.windows import Window

    with warnings.catch_warnings():  # a plain TIFF: no stray warning line
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        ds = rasterio.open(path)
    with ds:
        a = ds.read(1, window=Window(x, y, w, h), masked=True)
        scale, offset = ds.scales[0], ds.offsets[0]
    v = np.ma.filled(a.astype(np.float64), np.nan)
    if (scale, offset) != (1.0, 0.0):
        v = v * scale + offset
    return v


def open_source(path: str, *, key: str | None = None, fill: str | None = None, crop: str | None = None,
                decimate: int | None = None, spacing: str | None = None, origin: str | None = None) -> Source:
    """A height field file as a tiled job reads it: .npy through a memmap and GeoTIFF (any GDAL raster)
    through rasterio windows, without reading the samples; every other format, and --fill nearest (which
    needs the whole grid), is read whole by wavemesh.api.load_input."""
    from wavemesh import api
    from wavemesh.io.georef import apply_overrides, cropped
    from wavemesh.io.heightfield import check_nodata, parse_fill, regular_file

    fill_mode = parse_fill(fill)
    ext = Path(path).suffix.lower()
    lazy = fill_mode != "nearest" and ext in (".npy", ".tif", ".tiff")
    if not lazy:
        hf = api.load_input(path, key=key, fill=fill, crop=crop, decimate=decimate, spacing=spacing,
                            origin=origin)
        return Source("array", hf.width, hf.height, array=hf.values, name=hf.source, transform=hf.transform,
                      crs=hf.crs, spacing=hf.spacing)
    transform = crs = None
    regular_file(path)  # not a FIFO, not a device
    if ext == ".npy":
        try:
            mm = np.load(path, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError) as e:
            raise InputError(f"cannot read {path}: not a valid .npy file ({e})") from None
        if mm.ndim != 2 or mm.dtype.kind not in "biuf" or min(mm.shape) < 2:
            # the whole-file reader says what is wrong, in its words
            hf = api.load_input(path, fill=fill, crop=crop, decimate=decimate, spacing=spacing, origin=origin)
            return Source("array", hf.width, hf.height, array=hf.values, name=hf.source)
        fh, fw = mm.shape
        kind = "npy"
    else:
        import warnings

        import rasterio
        from rasterio.errors import NotGeoreferencedWarning

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotGeoreferencedWarning)
                ds = rasterio.open(path)
            with ds:
                if ds.count != 1:
                    raise InputError(f"{path} has {ds.count} bands; a height field needs one",
                                     hint="extract one (e.g. gdal_translate -b 1)")
                check_nodata(path, ds)
                fh, fw = ds.height, ds.width
                if ds.crs is not None or not ds.transform.is_identity:
                    transform = tuple(float(t) for t in ds.transform[:6])
                    crs = ds.crs.to_string() if ds.crs is not None else None
        except rasterio.errors.RasterioError as e:
            raise InputError(f"cannot read {path}: {e}") from None
        kind = "raster"
    x0, y0, w, h, step = 0, 0, fw, fh, 1
    what = []
    if crop is not None:
        x0, y0, w, h = api.parse_crop(crop)
        if x0 < 0 or y0 < 0 or w < 2 or h < 2 or x0 + w > fw or y0 + h > fh:
            raise InputError(f"--crop {crop} does not fit the {fw} x {fh} input",
                             hint="X + W <= width, Y + H <= height, W and H at least 2")
        what.append(f"crop {x0},{y0},{w},{h}")
    if decimate is not None:
        if decimate < 1:
            raise InputError(f"--decimate {decimate} is out of range", hint="use 1 or more")
        step = decimate
        w, h = -(-w // step), -(-h // step)
        if min(w, h) < 2:
            raise InputError(f"--decimate {decimate} leaves {w} x {h} samples",
                             hint="a height field needs at least 2 x 2")
        what.append(f"decimate {decimate}")
    name = path + (f" ({', '.join(what)})" if what else "")
    grid = apply_overrides(_Grid(fw, fh, transform, crs, None, path), spacing, origin)
    return Source(kind, w, h, path=path, x0=x0, y0=y0, step=step,
                  fill=None if fill_mode is None else float(fill_mode), name=name,
                  transform=cropped(grid.transform, x0, y0, step), crs=grid.crs, spacing=grid.spacing)


# ---------------------------------------------------------------------------------------------------
# One quantisation for the whole grid (wavemesh.io.heightfield.quantise's rules, found window by window)


@dataclass(frozen=True)
class Quant:
    """The whole grid's quantisation: samples = the heights less offset, over scale (rounded and clipped
    when not ``integer``); ``q`` the largest quantisation error (0 when lossless)."""

    scale: float
    offset: float
    integer: bool  # the lossless case of quantise(): integers within 65535 of each other
    q: float
    vmin: float
    vmax: float
    filled: int

    @property
    def lossless(self) -> bool:
        return self.q == 0

    def samples(self, v: np.ndarray) -> np.ndarray:
        if self.integer:
            return (v - self.offset).astype(np.uint16)
        if self.scale == 1.0 and self.vmax == self.vmin:
            return np.zeros(v.shape, dtype=np.uint16)
        return np.clip(np.rint((v - self.offset) / self.scale), 0, 65535).astype(np.uint16)


def _strips(src: Source) -> Iterable[tuple[int, np.ndarray]]:
    rows = max(1, STRIP_BYTES // (8 * src.width))
    for y in range(0, src.height, rows):
        yield y, src.read(0, y, src.width, min(rows, src.height - y))


def scan(src: Source) -> Quant:
    """The quantisation of the whole grid, in strips of rows: wavemesh.io.heightfield.quantise's scale and
    offset; a second pass for the largest quantisation error when the heights are not integers."""
    vmin, vmax, integer, bad = math.inf, -math.inf, True, 0
    for _, v in _strips(src):
        ok = np.isfinite(v)
        n_bad = int(v.size - np.count_nonzero(ok))
        if n_bad:
            bad += n_bad
            v = v[ok]
        if v.size:
            vmin, vmax = min(vmin, float(v.min())), max(vmax, float(v.max()))
            integer = integer and bool(np.all(v == np.floor(v)))
    if bad:
        raise InputError(f"{src.name}: {bad} samples are NaN, infinite or no-data",
                         hint="use --fill VALUE (or --fill nearest, which reads the whole grid)")
    span = vmax - vmin
    if not math.isfinite(span):
        raise InputError(f"height range {vmin:g} .. {vmax:g} is too large to quantise; rescale the heights")
    if span <= 65535 and integer:
        offset = 0.0 if (vmin >= 0 and vmax <= 65535) else vmin
        return Quant(1.0, offset, True, 0.0, vmin, vmax, 0)
    scale = span / 65535 if span / 65535 != 0 else 1.0
    quant = Quant(scale, vmin, False, 0.0, vmin, vmax, 0)
    q = 0.0
    for _, v in _strips(src):
        back = quant.offset + quant.scale * quant.samples(v).astype(np.float64)
        q = max(q, float(np.max(np.abs(v - back))))
    return replace(quant, q=q)


# ---------------------------------------------------------------------------------------------------
# The layout


def cuts(n: int, tile: int) -> list[int]:
    """Positions 0 = c0 < c1 < ... < ck = n - 1 with every c(i+1) - c(i) + 1 <= tile, evenly spread."""
    k = max(1, -(-(n - 1) // (tile - 1)))
    return [round(i * (n - 1) / k) for i in range(k + 1)]


@dataclass(frozen=True)
class Tile:
    """One tile: its place in the layout and on the grid, and its four sides' decided vertices (positions
    along the side from the tile's corner: top and bottom left to right, left and right top to bottom)."""

    row: int
    col: int
    x: int
    y: int
    width: int
    height: int
    sides: dict  # side name -> tuple of positions (0 and the side's length - 1 included)

    @property
    def name(self) -> str:
        return f"tile-{self.row:03d}-{self.col:03d}"


@dataclass
class TilePlan:
    """A tiled job before any tile runs: the input, the parameters, the quantisation, the tiles."""

    source: Source
    params: object  # wavemesh.api.MeshParams
    tile: int
    quant: Quant
    levels: int | None  # M per tile (None: each tile's default)
    tau: float  # tau_M in height units, one for every tile (default: 1% of the whole grid's range)
    zeta_used: float  # the refiner's zeta on the samples (zeta - 2q for lossy quantisation)
    spacing: tuple[float, float]  # the whole grid's cell size (the normal metric's)
    xcuts: list[int]
    ycuts: list[int]
    tiles: list[Tile] = field(default_factory=list)
    border_seconds: float = 0.0

    @property
    def width(self) -> int:
        return self.source.width

    @property
    def height(self) -> int:
        return self.source.height


def check_tiling(params) -> None:
    """WavemeshError unless the job can be tiled: the error bound on, no triangle budget or storage."""
    p = params.refine
    if params.initial_only:
        raise WavemeshError("--tile needs the refiner: --stage initial is not tiled", hint="use --stage full")
    if not p.bound:
        raise WavemeshError("--tile needs the error bound: the tiles' borders are decided within zeta",
                            hint="use --bound on")
    if p.max_triangles is not None or p.capacity is not None:
        raise WavemeshError("--max-triangles and --capacity are per job, not per tile: not with --tile",
                            hint="leave them out (each tile's storage is sized for its grid)")


def plan_tiles(src: Source, params, tile: int | None = None, *,
               log: Callable[[str], None] | None = None) -> TilePlan:
    """The layout, the whole grid's quantisation and every border's vertices, decided once."""
    from wavemesh import api
    from wavemesh.io.georef import ground
    from wavemesh.refine.native import fixed_params

    check_tiling(params)
    params.refine.check()
    tile = default_tile(default_workers()) if tile is None else tile
    if tile < MIN_TILE:
        raise InputError(f"--tile {tile} is too small", hint=f"use at least {MIN_TILE} samples a side")
    if params.levels is not None and not 1 <= params.levels <= api.MAX_LEVELS:
        raise WavemeshError(f"--levels {params.levels} is out of range", hint=f"use 1..{api.MAX_LEVELS}")
    quant = scan(src)
    tau = params.tau if params.tau is not None else api.DEFAULT_TAU_FRACTION * (quant.vmax - quant.vmin)
    if not math.isfinite(tau) or tau < 0:
        raise WavemeshError(f"--tau {tau} is not a finite number >= 0", hint="give tau in height units")
    p = params.refine
    zeta = max(0.0, p.zeta - 2 * quant.q) if quant.q > 0 else p.zeta
    spacing = ground(src.grid()).spacing
    plan = TilePlan(src, params, tile, quant, params.levels, tau, zeta, spacing,
                    cuts(src.width, tile), cuts(src.height, tile))
    t0 = time.perf_counter()
    fp = fixed_params(p, quant.scale, zeta, spacing)
    # every tile side between two tile corners, simplified once: rows (horizontal) and columns (vertical)
    horiz, vert = {}, {}
    for j, y in enumerate(plan.ycuts[1:-1], 1):
        row = quant.samples(src.read(0, y, src.width, 1))[0]
        for i in range(len(plan.xcuts) - 1):
            a, b = plan.xcuts[i], plan.xcuts[i + 1]
            horiz[j, i] = simplify_profile(row[a:b + 1], fp, axis=0, metric=p.metric)
    for i, x in enumerate(plan.xcuts[1:-1], 1):
        col = quant.samples(src.read(x, 0, 1, src.height))[:, 0]
        for j in range(len(plan.ycuts) - 1):
            a, b = plan.ycuts[j], plan.ycuts[j + 1]
            vert[i, j] = simplify_profile(col[a:b + 1], fp, axis=1, metric=p.metric)
    for j in range(len(plan.ycuts) - 1):
        for i in range(len(plan.xcuts) - 1):
            x, y = plan.xcuts[i], plan.ycuts[j]
            # only the shared sides are decided: the grid's own border stays the refiner's to choose
            sides = {name: seg for name, seg, shared in (
                ("top", horiz.get((j, i)), j > 0), ("bottom", horiz.get((j + 1, i)), j + 2 < len(plan.ycuts)),
                ("left", vert.get((i, j)), i > 0), ("right", vert.get((i + 1, j)), i + 2 < len(plan.xcuts)))
                if shared}
            plan.tiles.append(Tile(j, i, x, y, plan.xcuts[i + 1] - x + 1, plan.ycuts[j + 1] - y + 1, sides))
    plan.border_seconds = time.perf_counter() - t0
    if log:
        n_b = sum(len(v) for v in horiz.values()) + sum(len(v) for v in vert.values())
        log(f"tiles: {len(plan.xcuts) - 1} x {len(plan.ycuts) - 1} of at most {tile} x {tile} samples; "
            f"{len(horiz) + len(vert)} borders decided ({n_b} vertices) in {plan.border_seconds:.2f} s")
    return plan


# ---------------------------------------------------------------------------------------------------
# A border decided once: a 1-D simplification of its profile within zeta


def _segment_ok(z: np.ndarray, a: int, b: int, fp, axis: int, metric: str) -> bool:
    """Every sample strictly between a and b within the refiner's zeta of the segment (a, z[a])-(b, z[b])."""
    if b - a < 2:
        return True
    i = np.arange(a + 1, b, dtype=np.int64)
    za, zb, L = int(z[a]), int(z[b]), b - a
    num = np.abs(z[a + 1:b].astype(np.int64) * L - (za * (b - i) + zb * (i - a)))  # |dz| L, exact
    if metric == "vertical":  # the refiner's vertical E(T) is exact: |dz| <= zeta (Q16.16 counts)
        return bool(np.all(num * 65536 <= int(fp.zeta) * L))
    from wavemesh.refine.native import Params  # noqa: F401  (fp is one)

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
        good, step = a + 1, 2
        bad = None
        while True:
            b = min(a + step, n - 1)
            if _segment_ok(z, a, b, fp, axis, metric):
                good = b
                if b == n - 1:
                    break
                step *= 2
            else:
                bad = b
                break
        if bad is not None:
            while bad - good > 1:
                mid = (good + bad) // 2
                if _segment_ok(z, a, mid, fp, axis, metric):
                    good = mid
                else:
                    bad = mid
        kept.append(good)
        a = good
    return tuple(kept)


# ---------------------------------------------------------------------------------------------------
# A tile's mesh conformed to its decided border


def _side_of(x: int, y: int, w: int, h: int) -> list[tuple[str, int]]:
    out = []
    if y == 0:
        out.append(("top", x))
    if y == h - 1:
        out.append(("bottom", x))
    if x == 0:
        out.append(("left", y))
    if x == w - 1:
        out.append(("right", y))
    return out


def _side_point(side: str, pos: int, w: int, h: int) -> tuple[int, int]:
    return {"top": (pos, 0), "bottom": (pos, h - 1), "left": (0, pos), "right": (w - 1, pos)}[side]


def _orient(a, b, c) -> int:
    return (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])


def _in_closed_tri(p, a, b, c) -> bool:
    return _orient(a, b, p) >= 0 and _orient(b, c, p) >= 0 and _orient(c, a, p) >= 0


def _ear_clip(poly: list[int], xy: list) -> list[tuple[int, int, int]]:
    """A triangulation of the simple counter-clockwise polygon ``poly`` (vertex numbers into xy) by ear
    clipping in exact integers: an ear is strictly convex and holds no other polygon vertex, not even on
    its sides (that would be a T-junction).  Among the ears, the one with the largest smallest angle
    (sine of it, compared in floats, ties by position) keeps the triangles fat."""
    poly = list(poly)
    out = []
    while len(poly) > 3:
        n = len(poly)
        best, best_q = None, -1.0
        for k in range(n):
            a, b, c = poly[k - 1], poly[k], poly[(k + 1) % n]
            pa, pb, pc = xy[a], xy[b], xy[c]
            if _orient(pa, pb, pc) <= 0:
                continue
            if any(_in_closed_tri(xy[v], pa, pb, pc) for v in poly if v not in (a, b, c)):
                continue
            q = _quality(pa, pb, pc)
            if q > best_q:
                best, best_q = k, q
        if best is None:
            raise MeshInvalid("a tile's border could not be re-triangulated (no ear)", hint=_BUG)
        a, b, c = poly[best - 1], poly[best], poly[(best + 1) % n]
        out.append((a, b, c))
        del poly[best]
    a, b, c = poly
    if _orient(xy[a], xy[b], xy[c]) <= 0:
        raise MeshInvalid("a tile's border could not be re-triangulated (a flat last triangle)", hint=_BUG)
    out.append((a, b, c))
    return out


def _quality(a, b, c) -> float:
    """The smallest of the triangle's sin(angle) (twice the area over the two sides' lengths)."""
    d2 = abs(_orient(a, b, c))
    la = math.dist(b, c)
    lb = math.dist(a, c)
    lc = math.dist(a, b)
    return d2 / max(la * lb, lb * lc, lc * la)


def conform(mesh: Mesh, sides: dict) -> Mesh:
    """``mesh`` (a proper triangulation of its grid rectangle) with exactly the decided border vertices:
    each missing one inserted by splitting the triangle on its border edge, each other border vertex
    (corners stay) removed and its hole, a simple polygon, re-triangulated by ear clipping.  The result
    is proper (the refiner's wm_mesh_build checks it again); its error is the next step's business."""
    w, h = mesh.width, mesh.height
    xy = [tuple(p) for p in mesh.xy.tolist()]
    tris = [tuple(t) for t in mesh.tris.tolist()]
    alive = [True] * len(tris)
    at = {p: i for i, p in enumerate(xy)}
    border = [i for i, (x, y) in enumerate(xy) if x in (0, w - 1) or y in (0, h - 1)]
    inc: dict[int, set[int]] = {v: set() for v in border}
    bset = np.zeros(len(xy), dtype=bool)
    bset[border] = True
    for t in np.flatnonzero(bset[mesh.tris].any(axis=1)).tolist():
        for v in tris[t]:
            if v in inc:
                inc[v].add(t)

    def add(tri) -> None:
        tris.append(tri)
        alive.append(True)
        for v in tri:
            if v in inc:
                inc[v].add(len(tris) - 1)

    def kill(t) -> None:
        alive[t] = False
        for v in tris[t]:
            if v in inc:
                inc[v].discard(t)

    want = {_side_point(s, pos, w, h) for s, ps in sides.items() for pos in ps}
    # 1. insert the decided vertices the mesh lacks: split the triangle whose border edge holds each
    for p in sorted(want - set(xy)):
        side, pos = _side_of(p[0], p[1], w, h)[0]
        line = [v for v in inc if any(s == side for s, _ in _side_of(*xy[v], w, h))]
        coord = (lambda v: xy[v][0]) if side in ("top", "bottom") else (lambda v: xy[v][1])
        a = max((v for v in line if coord(v) < pos), key=coord)
        b = min((v for v in line if coord(v) > pos), key=coord)
        t = next(t for t in inc[a] & inc[b])
        ta = tris[t]
        k = ta.index(a)
        if ta[(k + 1) % 3] != b:  # the triangle holds the edge as b -> a
            a, b = b, a
            k = ta.index(a)
        c = ta[(k + 2) % 3]
        v = len(xy)
        xy.append(p)
        at[p] = v
        inc[v] = set()
        kill(t)
        add((a, v, c))
        add((v, b, c))
    # 2. remove the border vertices that were not decided (never a corner)
    corners = {(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)}
    for v in sorted(inc, key=lambda v: (xy[v][1], xy[v][0])):
        if xy[v] in want or xy[v] in corners or not any(s in sides for s, _ in _side_of(*xy[v], w, h)):
            continue
        fan = list(inc[v])
        # the star's link, walked from the side neighbour with v's fan counter-clockwise: edge (v -> n1)
        # in a triangle (v, n1, n2) continues from n2; the start is the neighbour no triangle ends at
        nxt = {}
        for t in fan:
            tv = tris[t]
            k = tv.index(v)
            nxt[tv[(k + 1) % 3]] = tv[(k + 2) % 3]
        start = next(n for n in nxt if n not in nxt.values())
        ring = [start]
        while ring[-1] in nxt:
            ring.append(nxt[ring[-1]])
        for t in fan:
            kill(t)
        for tri in _ear_clip(ring, xy):
            add(tri)
        del inc[v]
        xy[v] = None  # freed
    live_v = [i for i, p in enumerate(xy) if p is not None]
    remap = np.full(len(xy), -1, dtype=np.int64)
    remap[live_v] = np.arange(len(live_v))
    t_out = np.array([t for t, ok in zip(tris, alive, strict=True) if ok], dtype=np.int64).reshape(-1, 3)
    return Mesh(w, h, np.array([xy[i] for i in live_v], dtype=np.int64).reshape(-1, 2), remap[t_out])


def border_of(mesh: Mesh) -> dict:
    """A mesh's vertices on each side of its rectangle, as positions along the side (sorted)."""
    x, y = mesh.xy[:, 0], mesh.xy[:, 1]
    w, h = mesh.width, mesh.height
    return {"top": tuple(sorted(x[y == 0].tolist())), "bottom": tuple(sorted(x[y == h - 1].tolist())),
            "left": tuple(sorted(y[x == 0].tolist())), "right": tuple(sorted(y[x == w - 1].tolist()))}


# ---------------------------------------------------------------------------------------------------
# One tile's job


@dataclass
class TileResult:
    """A tile's mesh in grid coordinates of the whole input, its vertices' heights, and its numbers."""

    index: int
    name: str
    xy: np.ndarray  # (V, 2) int64, whole-grid positions
    tris: np.ndarray  # (T, 3) int64 into xy
    z: np.ndarray  # (V,) float64 heights
    report: dict
    device: str | None = None  # the port that made it (stream)


def tile_heightfield(plan: TilePlan, t: Tile, window: np.ndarray | None = None):
    """The tile as a HeightField: its window of the input with the whole grid's quantisation, its
    place on the ground, and the whole grid's cell size."""
    from wavemesh.io.georef import cropped
    from wavemesh.io.heightfield import HeightField

    src, quant = plan.source, plan.quant
    v = src.read(t.x, t.y, t.width, t.height) if window is None else window
    if not np.all(np.isfinite(v)):
        raise InputError(f"{src.name}: non-finite samples in {t.name}", hint="use --fill VALUE")
    return HeightField(values=v, samples=quant.samples(v), scale=quant.scale, offset=quant.offset,
                       lossless=quant.lossless, source=f"{src.name} {t.name}",
                       transform=cropped(src.transform, t.x, t.y, 1), crs=src.crs, spacing=plan.spacing)


def _finish_tile(plan: TilePlan, t: Tile, index: int, hf, first_out, seconds: float,
                 extra: dict | None = None) -> TileResult:
    """Steps 4's second half: conform ``first_out``'s mesh (the refiner's output for the tile by the full
    pipeline) to the decided border, run the error bound on it, check it, and measure it."""
    from wavemesh.api import BUG_HINT, RefineJob, bound_excess, require_proper
    from wavemesh.check import mesh_errors
    from wavemesh.model.haar import decompose
    from wavemesh.refine import native

    p = plan.params.refine
    t0 = time.perf_counter()
    first = first_out.final.mesh
    if not t.sides:  # a single tile: nothing shared, the mesh of `wavemesh mesh` as it is
        conformed = None
    else:
        conformed = conform(first, t.sides)
    bound = replace(p, reduce=False, decimate=False, max_triangles=None, capacity=None)
    out = first_out if conformed is None else native.refine(
        hf.samples, decompose(hf.samples, 1), conformed, bound, scale=hf.scale, zeta=plan.zeta_used,
        spacing=plan.spacing)
    final = out.final.mesh
    require_proper(final, f"{t.name}'s mesh")
    got = border_of(final)
    diff = [s for s in SIDES if s in t.sides and got[s] != tuple(t.sides[s])]
    if diff:
        raise MeshInvalid(f"{t.name}: the error bound changed the decided border ({', '.join(diff)})",
                          hint=_BUG)
    rjob = RefineJob(None, p, plan.zeta_used if t.sides else hf.refiner_zeta(p.zeta), out, 0.0)
    errors = mesh_errors(final, hf.values, rms=False, spacing=plan.spacing)
    if not rjob.bound_met:
        raise MeshInvalid(f"{t.name}: {out.final.stats['over']} triangles above zeta after the border's "
                          "error bound", hint=BUG_HINT)
    excess = bound_excess(hf, rjob, errors)
    if excess:
        raise MeshInvalid(f"{t.name}: {excess}", hint=BUG_HINT)
    seconds += time.perf_counter() - t0
    xy = final.xy + np.array([t.x, t.y], dtype=np.int64)
    report = {"tile": t.name, "row": t.row, "col": t.col, "x": t.x, "y": t.y, "width": t.width,
              "height": t.height, "triangles_before_border": first.n_triangles,
              "vertices": final.n_vertices, "triangles": final.n_triangles,
              "border_vertices": {s: len(v) for s, v in t.sides.items()},
              "bound_splits": out.final.stats["bound_splits"], "seconds": seconds,
              "e_max_normal": errors.e_max_normal, "e_max_vertical": errors.e_max_vertical} | (extra or {})
    return TileResult(index, t.name, xy, final.tris, final.z(hf.values), report)


def mesh_tile(plan: TilePlan, index: int, window: np.ndarray | None = None) -> TileResult:
    """Step 4 for one tile in this process: the full pipeline of `wavemesh mesh` (with the whole grid's
    zeta on the samples), then the border.  ``window``: the tile's heights when the caller read them."""
    from wavemesh import api
    from wavemesh.model.haar import decompose
    from wavemesh.refine import native

    t = plan.tiles[index]
    t0 = time.perf_counter()
    hf = tile_heightfield(plan, t, window)
    params = plan.params
    job = api.triangulate(hf, plan.levels, plan.tau, params.wavelet)
    out = native.refine(hf.samples, decompose(hf.samples, job.levels, job.wavelet), job.mesh, params.refine,
                        scale=hf.scale, zeta=hf.refiner_zeta(params.refine.zeta), spacing=plan.spacing)
    return _finish_tile(plan, t, index, hf, out, time.perf_counter() - t0, {"levels": job.levels})


def _light(plan: TilePlan) -> TilePlan:
    """The plan without an in-memory input (each task then carries its own window)."""
    if plan.source.kind != "array":
        return plan
    return replace(plan, source=replace(plan.source, array=None))


def _tasks(plan: TilePlan) -> Iterable[tuple[TilePlan, int, np.ndarray | None]]:
    """(plan, index, window) per tile: a lazily read input is read by the worker, one in memory here."""
    light = _light(plan)
    for i, t in enumerate(plan.tiles):
        window = plan.source.read(t.x, t.y, t.width, t.height) if plan.source.kind == "array" else None
        yield light, i, window


def _mesh_tile_task(plan: TilePlan, index: int, window: np.ndarray | None) -> TileResult:
    return mesh_tile(plan, index, window)


# ---------------------------------------------------------------------------------------------------
# Running the tiles: in this process, on a local process pool, or on a Dask cluster


def available_memory() -> int:
    """Bytes this process may still take now (the least of wavemesh.api.memory_available: MemAvailable,
    ulimit -v, the cgroup's limit)."""
    from wavemesh.api import memory_available

    return min(have for have, _, _ in memory_available())


def default_tile(workers: int, budget: int | None = None) -> int:
    """The tile side from memory: the largest of TILE_CHOICES whose ``workers`` tiles in flight fit in
    ``budget`` bytes (default: half the memory available now)."""
    budget = available_memory() // 2 if budget is None else budget
    for t in TILE_CHOICES:
        if workers * TILE_BYTES_PER_SAMPLE * t * t <= budget:
            return t
    return TILE_CHOICES[-1]


def dask_tile(client) -> int:
    """The tile side from the Dask workers' memory limits: one tile in flight per worker thread."""
    workers = client.scheduler_info().get("workers", {}).values()
    per = [w.get("memory_limit") or 0 for w in workers]
    threads = max([w.get("nthreads") or 1 for w in workers] or [1])
    return default_tile(threads, min(per) // 2) if per and min(per) > 0 else default_tile(threads)


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def run_tiles(plan: TilePlan, *, workers: int | None = None, scheduler=None, progress: bool = False,
              log: Callable[[str], None] | None = None) -> list[TileResult]:
    """Every tile's job (mesh_tile), in tile order whatever order they finish in.

    ``scheduler``: a Dask scheduler's address ("tcp://host:8786") or a distributed.Client; the workers
    read their windows themselves (a shared file system, or an input in memory sent with the plan).
    Else a local process pool of ``workers`` processes (default: the CPUs this process may use; 1: in
    this process).  A tile that fails ends the run with its error."""
    from wavemesh.api import _Progress

    n = len(plan.tiles)
    results: list[TileResult | None] = [None] * n
    with _Progress("tiles", n, progress) as bar:
        done = 0

        def finished(r: TileResult) -> None:
            nonlocal done
            results[r.index] = r
            done += 1
            note = f"{r.name}: {len(r.tris)} triangles, {r.report['seconds']:.2f} s"
            bar.update(done, note)
            if log:
                log(f"  {done}/{n} {note}")

        if scheduler is not None:
            _run_dask(plan, scheduler, finished)
        else:
            workers = default_workers() if workers is None else workers
            if workers < 1:
                raise WavemeshError(f"--workers {workers} is out of range", hint="use 1 or more")
            if workers == 1 or n == 1:
                for task in _tasks(plan):
                    finished(_mesh_tile_task(*task))
            else:
                _run_pool(plan, min(workers, n), finished)
        bar.finish(f"{n} tiles")
    return results  # type: ignore[return-value]


def _run_pool(plan: TilePlan, workers: int, finished) -> None:
    """The tiles on ``workers`` forked processes, one tile each at a time, each result through the
    worker's own pipe.  The parent has no threads of its own for them: a run that ends early (a failed
    tile, Ctrl-C, SIGTERM) kills its workers and returns at once (concurrent.futures' pool could wait
    forever at exit for a result a killed worker had half sent)."""
    import multiprocessing
    from multiprocessing.connection import wait

    from wavemesh.refine import native

    native.load()  # built once here, not by every worker at once
    # fork: the workers start from this process as it is (the library loaded; a script that calls this
    # needs no `if __name__ == "__main__"` guard, which spawn and forkserver would ask of it)
    ctx = multiprocessing.get_context("fork")
    pool: list[tuple] = []  # (process, pipe)
    ok = False
    try:
        for _ in range(workers):
            here, there = ctx.Pipe()
            proc = ctx.Process(target=_worker_loop, args=(there, os.getpid()), daemon=True)
            proc.start()
            there.close()
            pool.append((proc, here))
        todo = iter(_tasks(plan))
        busy: dict = {}  # pipe -> process, of the workers at a tile
        for proc, pipe in pool:
            task = next(todo, None)
            if task is None:
                break
            pipe.send(task)
            busy[pipe] = proc
        while busy:
            ready = wait([*busy, *(p.sentinel for p in busy.values())])
            for pipe in [c for c in busy if c in ready]:
                try:
                    kind, value, hint = pipe.recv()
                except (EOFError, OSError):
                    proc = busy[pipe]
                    proc.join(1.0)
                    raise WavemeshError(f"a tile worker ended without its tile (exit status {proc.exitcode})",
                                        hint="out of memory? try a smaller --tile or fewer --workers") \
                        from None
                if kind == "error":
                    if isinstance(value, WavemeshError) and hint is not None:
                        value.hint = hint
                    raise value
                finished(value)
                task = next(todo, None)
                if task is None:
                    del busy[pipe]
                else:
                    pipe.send(task)
            for pipe, proc in list(busy.items()):
                if proc.sentinel in ready and pipe not in ready and not pipe.poll():
                    proc.join(1.0)
                    raise WavemeshError(f"a tile worker ended without its tile (exit status {proc.exitcode})",
                                        hint="out of memory? try a smaller --tile or fewer --workers")
        ok = True
    finally:
        _end_workers(pool, gently=ok)


def _worker_loop(pipe, parent: int) -> None:
    """A pool worker: tiles from its pipe until it closes; each result, or the error, back through it."""
    _worker_start(parent)
    while True:
        try:
            task = pipe.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        try:
            reply = ("ok", _mesh_tile_task(*task), None)
        except Exception as e:  # the parent raises it (WavemeshError with its hint)
            reply = ("error", e, getattr(e, "hint", None))
        try:
            pipe.send(reply)
        except Exception as e:  # an error that does not pickle: its text
            pipe.send(("error", RuntimeError(f"{type(e).__name__}: {e}"), None))


def _worker_start(parent: int) -> None:
    """A pool worker's start: Ctrl-C is the parent's to handle (it ends the workers, _end_workers), SIGTERM
    ends the worker at once, and the worker ends when its parent does, even one killed outright (Linux's
    PR_SET_PDEATHSIG)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent ended before the line above
        os._exit(1)


def _end_workers(pool: list, gently: bool) -> None:
    """End the workers: ``gently`` (the run is done) by closing their pipes; else at once (SIGTERM, then
    SIGKILL after a second).  Reaped either way."""
    for proc, pipe in pool:
        if gently:
            try:
                pipe.send(None)
            except OSError:
                pass
        elif proc.is_alive():
            proc.terminate()
    deadline = time.monotonic() + (10.0 if gently else 1.0)
    for proc, pipe in pool:
        proc.join(max(0.0, deadline - time.monotonic()))
        if proc.is_alive():
            proc.kill()
            proc.join(1.0)
        pipe.close()


def connect(address: str):
    """A distributed.Client of the Dask scheduler at ``address``, or WavemeshError."""
    try:
        from distributed import Client
    except ImportError:
        raise WavemeshError("--scheduler needs Dask's distributed package",
                            hint="pip install 'wavemesh[dask]' (or: pip install dask distributed)") from None
    try:
        return Client(address, timeout=f"{DASK_CONNECT_S}s")
    except (OSError, TimeoutError, ValueError) as e:
        raise WavemeshError(f"--scheduler {address}: no Dask scheduler answers ({e})",
                            hint="start one (dask scheduler; dask worker ADDRESS), or check the address") \
            from None


def _run_dask(plan: TilePlan, scheduler, finished) -> None:
    from distributed import as_completed

    own = not hasattr(scheduler, "submit")
    client = connect(scheduler) if own else scheduler
    try:
        run = f"{time.time_ns()}-{os.getpid()}"  # task keys of this run alone
        futures = [client.submit(_mesh_tile_task, *task, pure=False, key=f"wavemesh-{run}-{task[1]}")
                   for task in _tasks(plan)]
        for fut in as_completed(futures):
            finished(fut.result())
    finally:
        if own:
            client.close()


# ---------------------------------------------------------------------------------------------------
# Tiles on devices: `wavemesh stream --tile`, one device or several at once


@dataclass
class _Levels:
    """A device's levels as _finish_tile takes the refiner's output (final: the last level)."""

    final: object


def device_tile(infos: list) -> int:
    """The largest tile side every device holds (its width, height and sample count)."""
    return min(min(i.max_width, i.max_height, math.isqrt(i.max_samples)) for i in infos)


def hello(ports: list[str], baud: int, timeouts) -> list:
    """Each device's DeviceInfo (HELLO), in the order of ``ports``."""
    from wavemesh.device.stream import Device

    infos = []
    for port in ports:
        with Device(port, baud, timeouts=timeouts) as dev:
            infos.append(dev.sync())
    return infos


def stream_tile(plan: TilePlan, index: int, port, *, baud: int, timeouts) -> TileResult:
    """One tile's full pipeline on the device behind ``port`` (wavemesh.api.stream), then its border on
    the host, as mesh_tile does it: the same mesh, when the device's budget did not stop it."""
    from wavemesh import api

    t = plan.tiles[index]
    t0 = time.perf_counter()
    hf = tile_heightfield(plan, t)
    params = replace(plan.params, levels=plan.levels, tau=plan.tau, check_levels=False, rms=False)
    res = api.stream(hf, port, params, baud=baud, timeouts=timeouts)
    final = res.report["refiner"]["levels"][-1] if res.rows else None
    stats = {"over": 0 if res.bound_met else 1, "bound_splits": final["splits"] if final else 0}
    lv = _LevelShim(res.mesh, stats)
    r = _finish_tile(plan, t, index, hf, _Levels(lv), time.perf_counter() - t0,
                     {"levels": res.levels, "device": str(port), "device_cycles": res.cycles})
    r.device = str(port)
    return r


@dataclass
class _LevelShim:
    mesh: Mesh
    stats: dict


def stream_tiles(plan: TilePlan, ports: list[str], *, baud: int, timeouts, progress: bool = False,
                 log: Callable[[str], None] | None = None) -> list[TileResult]:
    """Every tile on the devices behind ``ports``, one tile per device at a time, each device taking the
    next tile when it is done.  A tile whose device fails (no answer, a broken link, an error) is put
    back and done by another device, and the run says so; the failed device takes no more tiles.  When
    no device is left, DeviceError names each failure."""
    import threading
    from collections import deque

    from wavemesh.api import _Progress
    from wavemesh.device.stream import DeviceError

    n = len(plan.tiles)
    results: list[TileResult | None] = [None] * n
    todo = deque(range(n))
    cond = threading.Condition()
    state = {"busy": 0, "done": 0, "alive": len(ports)}
    failures: list[str] = []
    say = log or (lambda text: None)

    with _Progress("tiles", n, progress) as bar:

        def serve(port: str) -> None:
            while True:
                with cond:
                    while not todo and state["busy"] and state["done"] < n:
                        cond.wait()
                    if not todo:
                        state["alive"] -= 1
                        cond.notify_all()
                        return
                    i = todo.popleft()
                    state["busy"] += 1
                try:
                    r = stream_tile(plan, i, port, baud=baud, timeouts=timeouts)
                except (WavemeshError, OSError) as e:
                    msg = getattr(e, "message", str(e))
                    with cond:
                        todo.appendleft(i)
                        state["busy"] -= 1
                        state["alive"] -= 1
                        failures.append(f"{plan.tiles[i].name} on {port}: {msg}")
                        left = state["alive"]
                        cond.notify_all()
                    say(f"warning: {plan.tiles[i].name} failed on {port} ({msg}); "
                        + (f"retrying it on another device ({left} left); {port} takes no more tiles"
                           if left else "no device left"))
                    return
                with cond:
                    results[i] = r
                    state["busy"] -= 1
                    state["done"] += 1
                    done = state["done"]
                    cond.notify_all()
                note = f"{r.name} on {port}: {len(r.tris)} triangles, {r.report['seconds']:.2f} s"
                bar.update(done, note)
                say(f"  {done}/{n} {note}")

        threads = [threading.Thread(target=serve, args=(port,), daemon=True) for port in ports]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        if any(r is None for r in results):
            raise DeviceError(f"{sum(r is None for r in results)} of {n} tiles were not made: every device "
                              f"failed: " + "; ".join(failures),
                              hint="check the devices (wavemesh devices) and run again")
        bar.finish(f"{n} tiles on {len(ports)} device{'s' if len(ports) != 1 else ''}")
    return results  # type: ignore[return-value]


# ---------------------------------------------------------------------------------------------------
# Stitching


@dataclass
class TiledResult:
    """The stitched mesh, the vertices' heights, and the run's report."""

    mesh: Mesh
    z: np.ndarray
    tiles: list[TileResult]
    report: dict


def stitch(plan: TilePlan, results: list[TileResult]) -> TiledResult:
    """One mesh of the whole grid from the tiles' (their shared border vertices merged by position),
    checked: a proper triangulation (check_mesh: no T-junctions, no cracks)."""
    from wavemesh.api import require_proper

    W = plan.width
    keys = np.concatenate([r.xy[:, 1] * W + r.xy[:, 0] for r in results])
    z_all = np.concatenate([r.z for r in results])
    uniq, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    offsets = np.cumsum([0] + [len(r.xy) for r in results])
    tris = np.concatenate([inverse[r.tris + offsets[k]] for k, r in enumerate(results)])
    xy = np.column_stack([uniq % W, uniq // W]).astype(np.int64)
    mesh = Mesh(W, plan.height, xy, tris).canonical()  # vertices already in (y, x) order: same z order
    z = z_all[first]
    require_proper(mesh, "the stitched mesh")
    e_n = max(r.report["e_max_normal"] for r in results)
    e_v = max(r.report["e_max_vertical"] for r in results)
    report = {
        "tile": plan.tile, "layout": [len(plan.xcuts) - 1, len(plan.ycuts) - 1],
        "xcuts": plan.xcuts, "ycuts": plan.ycuts, "tau": plan.tau, "zeta_refiner": plan.zeta_used,
        "quantisation": {"scale": plan.quant.scale, "offset": plan.quant.offset,
                         "max_quantisation_error": plan.quant.q},
        "vertices": mesh.n_vertices, "triangles": mesh.n_triangles,
        "e_max_normal": e_n, "e_max_vertical": e_v, "border_seconds": plan.border_seconds,
        "tiles": [r.report for r in results],
    }
    return TiledResult(mesh, z, results, report)


def mesh_tiled(src: Source, params, tile: int | None = None, *, workers: int | None = None, scheduler=None,
               progress: bool = False, log: Callable[[str], None] | None = None) -> TiledResult:
    """`wavemesh mesh --tile`: plan, run the tiles, stitch."""
    plan = plan_tiles(src, params, tile, log=log)
    return stitch(plan, run_tiles(plan, workers=workers, scheduler=scheduler, progress=progress, log=log))


# ---------------------------------------------------------------------------------------------------
# Files: the stitched mesh, and each tile's with an index


def check_tiled_outputs(output: str, *, tiles_dir: str | None = None, report: str | None = None,
                        render: str | None = None, exaggeration: float | None = None, inputs=None,
                        files=None):
    """A tiled run's output paths, checked before any work (wavemesh.api.check_outputs, and --tiles-dir):
    (mesh file, --tiles-dir folder)."""
    from wavemesh.api import check_outputs
    from wavemesh.io.outputs import as_inputs, check_path

    inputs = as_inputs(inputs)
    out, _ = check_outputs(output, report=report, render=render, inputs=inputs, exaggeration=exaggeration,
                           files=files)
    folder = check_path(tiles_dir, None, "--tiles-dir", inputs) if tiles_dir else None
    if folder is not None and folder.resolve() in {Path(p).resolve() for p in (output, report, render) if p}:
        raise InputError(f"--tiles-dir {tiles_dir} names a file the run also writes",
                         hint="give --tiles-dir its own folder")
    return out, folder


def write_tiled(tiled: TiledResult, plan: TilePlan, output: str, *, tiles_dir: str | None = None,
                report: str | None = None, comment: str = "", files=None, render: str | None = None,
                exaggeration: float | None = None, title: str | None = None, inputs=None) -> list[str]:
    """The stitched mesh (a format of wavemesh.io.meshio.FORMATS, written as ``files``, an api.MeshFiles,
    says), each tile's mesh into ``tiles_dir`` (tile-RRR-CCC.EXT in the whole grid's frame, so that they
    fit together as they are; no --base) with ``index.json`` naming each tile's file, place and numbers,
    the JSON report and the picture (``render``); whole or not at all, as one set, none of them one of
    ``inputs`` (wavemesh.io.outputs)."""
    import json

    from wavemesh.api import MeshFiles, _render
    from wavemesh.io.georef import SIDECAR_SUFFIX as SIDECAR
    from wavemesh.io.georef import ground
    from wavemesh.io.meshio import write_mesh
    from wavemesh.io.outputs import Outputs, as_inputs

    files = files or MeshFiles()
    inputs = as_inputs(inputs)
    out, folder = check_tiled_outputs(output, tiles_dir=tiles_dir, report=report, render=render,
                                      exaggeration=exaggeration, inputs=inputs, files=files)
    g = ground(plan.source.grid())
    opts = {"ground": g, "units": files.units, "local": files.local, "normals": files.normals}
    written = []
    with Outputs(inputs) as staged:
        write_mesh(str(staged.path(out, (SIDECAR,), "mesh")), tiled.mesh, tiled.z, comment=comment,
                   base=files.base, **opts)
        if folder is not None:
            index = {"grid": [plan.width, plan.height], "tile": plan.tile,
                     "layout": [len(plan.xcuts) - 1, len(plan.ycuts) - 1], "mesh": str(out), "tiles": []}
            for r in tiled.tiles:
                m = Mesh(plan.width, plan.height, r.xy, r.tris)
                path = folder / f"{r.name}{out.suffix.lower()}"
                write_mesh(str(staged.path(path, (SIDECAR,), "--tiles-dir")), m, r.z,
                           comment=f"{comment} {r.name}", **opts)
                index["tiles"].append({"file": path.name} | r.report)
                written.append(str(path))
            staged.path(folder / "index.json", what="--tiles-dir").write_text(
                json.dumps(index, indent=1) + "\n")
        if report:
            staged.path(report, what="report").write_text(
                json.dumps(tiled.report | {"output": str(out)}, indent=2) + "\n")
        if render:
            _render(tiled.mesh, tiled.z, str(staged.path(render, what="picture")), g, exaggeration,
                    title=title)
    return written


def progress_enabled() -> bool:
    return sys.stderr.isatty()


# ---------------------------------------------------------------------------------------------------
# The commands' tiled path (wavemesh.cli hands `mesh --tile` and `stream --tile` or several --port here)


def command(args, params, ports: list[str] | None = None, inputs=None) -> int:
    """`wavemesh mesh --tile N` (``ports`` None) or `wavemesh stream` of tiles on ``ports``: read the input
    lazily, plan, run the tiles, stitch, write; print a summary unless --quiet."""
    from dataclasses import replace as _replace

    from wavemesh import api

    if getattr(args, "lod", None):
        raise WavemeshError("--lod is not written for a tiled run", hint="leave out --lod, or --tile")
    for name in ("roi", "nodata", "invalid", "denoise"):  # they need the whole grid at once
        if getattr(args, name, None) not in (None, "error"):
            raise WavemeshError(f"--{name} is not tiled yet", hint="leave out --tile")
    if getattr(args, "tile", None) is not None and args.tile < MIN_TILE:
        raise InputError(f"--tile {args.tile} is too small", hint=f"use at least {MIN_TILE} samples a side")
    files = api.MeshFiles(units=args.units or ("crs" if args.local else "metres"), local=args.local,
                          normals=args.normals, base=args.base, normal_map=args.normal_map)
    if files.normal_map:
        raise WavemeshError("--normal-map is not tiled yet (it needs the whole grid at once)",
                            hint="leave out --tile, or --normal-map")
    if getattr(args, "workers", None) is not None and args.workers < 1:
        raise WavemeshError(f"--workers {args.workers} is out of range", hint="use 1 or more")
    if getattr(args, "timeout", None) is not None and not args.timeout > 0:
        raise WavemeshError(f"--timeout {args.timeout} is out of range", hint="give seconds > 0")
    check_tiled_outputs(args.output, tiles_dir=args.tiles_dir, report=args.report, render=args.render,
                        exaggeration=args.exaggeration, inputs=inputs, files=files)
    quiet = args.quiet
    say = None if quiet else (lambda text: print(text, flush=True))
    progress = not quiet
    src = open_source(args.input, key=args.key, fill=args.fill, crop=args.crop, decimate=args.decimate,
                      spacing=args.spacing, origin=args.origin)
    params = _replace(params, check_levels=False, rms=False)
    if ports is None:
        client = connect(args.scheduler) if args.scheduler else None
        try:
            tile = args.tile
            if tile is None:  # from memory: the Dask workers' limits, or this machine's
                tile = dask_tile(client) if client else default_tile(args.workers or default_workers())
            plan = plan_tiles(src, params, tile, log=say)
            results = run_tiles(plan, workers=args.workers, scheduler=client, progress=progress,
                                log=say if not progress or not sys.stderr.isatty() else None)
        finally:
            if client is not None:
                client.close()
    else:
        from wavemesh.device.stream import DEFAULT_TIMEOUTS

        for port in ports:
            api.check_port(port)
        timeouts = DEFAULT_TIMEOUTS if args.timeout is None else _replace(DEFAULT_TIMEOUTS, job=args.timeout)
        infos = hello(ports, args.baud, timeouts)
        if say:
            for port, info in zip(ports, infos, strict=True):
                say(f"device {port}: {info.summary()}")
        tile = args.tile if args.tile is not None else device_tile(infos)
        plan = plan_tiles(src, params, tile, log=say)
        results = stream_tiles(plan, ports, baud=args.baud, timeouts=timeouts, progress=progress, log=say)
    tiled = stitch(plan, results)
    p = params.refine
    comment = (f"wavemesh tiled mesh, tile={plan.tile} tau={plan.tau:g} zeta={p.zeta:g} metric={p.metric}")
    written = write_tiled(tiled, plan, args.output, tiles_dir=args.tiles_dir, report=args.report,
                          comment=comment, files=files, render=args.render, exaggeration=args.exaggeration,
                          title=Path(args.input).name, inputs=inputs)
    if not quiet:
        r = tiled.report
        print(f"{args.input}: {plan.width} x {plan.height} in {r['layout'][0]} x {r['layout'][1]} tiles of "
              f"at most {plan.tile}: {tiled.mesh.n_vertices} vertices, {tiled.mesh.n_triangles} triangles, "
              f"E_max normal {r['e_max_normal']:.6g}, vertical {r['e_max_vertical']:.6g} (zeta {p.zeta:g}, "
              f"{p.metric}); the stitched mesh is proper")
        print(f"wrote {args.output}" + "".join(f", {q}" for q in (args.report, args.render) if q)
              + (f", {len(written)} tiles and index.json in {args.tiles_dir}" if written else ""))
    return 0
