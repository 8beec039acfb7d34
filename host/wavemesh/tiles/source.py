"""The input of a tiled run, read window by window, and its one quantisation (docs/tiles.md, steps 1-2)."""

from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wavemesh import api
from wavemesh.errors import InputError
from wavemesh.io.georef import apply_overrides, cropped
from wavemesh.io.heightfield import parse_fill, quant_rule, to_samples
from wavemesh.io.readers import raster_header, read_raster_window, regular_file
from wavemesh.record import record
from wavemesh.refine import native

if TYPE_CHECKING:
    from wavemesh.tiles.runner import Runner


STRIP_BYTES = 16 << 20  # the quantisation pass reads the input in row strips of about this many float64 bytes
# and takes each strip's numbers this many samples at a time (whole rows, 512 KiB of float64: in a core's own
# cache, where a whole strip's float64 copy and its temporaries went out to memory, which two workers share)
BLOCK_SAMPLES = 1 << 16

# ---------------------------------------------------------------------------------------------------
# The input, read window by window


@record(frozen=True)
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
        """Heights of the w x h window whose top-left sample is (x, y), non-finite ones filled by --fill
        VALUE (left as they are without it): float64, or float32 where a .npy input is float32 and the
        fill (if any) a float32, read-only and in place, the window of the file's memory map, without
        --fill and --decimate (half a float64 copy's memory, or none; its every use widens each to the
        same double: the C quantisation and error measure, check.mesh_errors, TileResult.z)."""
        s = self.step
        fx, fy = self.x0 + s * x, self.y0 + s * y
        cols = slice(fx, fx + s * (w - 1) + 1, s)
        rows = slice(fy, fy + s * (h - 1) + 1, s)
        if self.kind == "array":
            v = np.array(self.array[rows, cols], dtype=np.float64)
        elif self.kind == "npy":
            mm = _npy_map(self.path)
            with np.errstate(invalid="ignore", over="ignore"):
                single = mm.dtype == np.float32 and (self.fill is None
                                                     or float(np.float32(self.fill)) == self.fill)
                if single and s == 1 and self.fill is None:
                    return np.asarray(mm[rows, cols])  # in place (the file's pages this process maps)
                v = np.array(mm[rows, cols], dtype=np.float32 if single else np.float64)
        else:
            v = read_raster_window(self.path, fx, fy, s * (w - 1) + 1, s * (h - 1) + 1)[::s, ::s]
        if self.fill is not None:
            v[~np.isfinite(v)] = self.fill
        return v

    def grid(self) -> _Grid:
        return _Grid(self.width, self.height, self.transform, self.crs, self.spacing, self.name)


@record(frozen=True)
class _Grid:
    """What wavemesh.georef.ground needs of a height field, without its samples."""

    width: int
    height: int
    transform: tuple[float, ...] | None
    crs: str | None
    spacing: tuple[float, float] | None
    source: str


def open_source(path: str, *, key: str | None = None, fill: str | None = None, crop: str | None = None,
                decimate: int | None = None, spacing: str | None = None, origin: str | None = None) -> Source:
    """A height field file as a tiled job reads it: .npy through a memmap and GeoTIFF (any GDAL raster)
    through rasterio windows, without reading the samples; every other format, and --fill nearest (which
    needs the whole grid), is read whole by wavemesh.api.load_input."""
    fill_mode = parse_fill(fill)
    ext = Path(path).suffix.lower()

    def whole() -> Source:
        hf = api.load_input(path, key=key, fill=fill, crop=crop, decimate=decimate, spacing=spacing,
                            origin=origin)
        return Source("array", hf.width, hf.height, array=hf.values, name=hf.source, transform=hf.transform,
                      crs=hf.crs, spacing=hf.spacing)

    if fill_mode == "nearest" or ext not in (".npy", ".tif", ".tiff"):
        return whole()
    transform = crs = None
    regular_file(path)  # not a FIFO, not a device
    if ext == ".npy":
        try:
            mm = np.load(path, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError) as e:
            raise InputError(f"cannot read {path}: not a valid .npy file ({e})") from None
        if mm.ndim != 2 or mm.dtype.kind not in "biuf" or min(mm.shape) < 2:
            return whole()  # the whole-file reader says what is wrong, in its words
        fh, fw = mm.shape
        kind = "npy"
    else:
        fw, fh, transform, crs = raster_header(path)
        kind = "raster"
    x0, y0, w, h, step, what = api.crop_window(crop, decimate, fw, fh)
    name = path + (f" ({', '.join(what)})" if what else "")
    grid = apply_overrides(_Grid(fw, fh, transform, crs, None, path), spacing, origin)
    return Source(kind, w, h, path=path, x0=x0, y0=y0, step=step,
                  fill=None if fill_mode is None else float(fill_mode), name=name,
                  transform=cropped(grid.transform, x0, y0, step), crs=grid.crs, spacing=grid.spacing)


# ---------------------------------------------------------------------------------------------------
# One quantisation for the whole grid: wavemesh.heightfield's rules, its statistics found strip by strip


@record(frozen=True)
class Quant:
    """The whole grid's quantisation (heightfield.quant_rule of its range): samples = the heights less
    offset, over scale (rounded and clipped unless ``exact``); ``q`` the largest quantisation error (None:
    not found yet, scan's ``error=False``)."""

    scale: float
    offset: float
    exact: bool  # integers within SAMPLE_MAX of each other: the lossless case of heightfield.quantise
    q: float | None
    vmin: float
    vmax: float

    @property
    def lossless(self) -> bool:
        return self.exact if self.q is None else self.q == 0

    def samples(self, v: np.ndarray) -> np.ndarray:
        return self.quantised(v)[0]

    def quantised(self, v: np.ndarray) -> tuple[np.ndarray, float | None]:
        """The samples of the finite heights ``v`` (2-D) and, unless exact, their largest quantisation
        error (max |v - (offset + scale samples)|, as HeightField.max_quantisation_error measures it; None
        when exact): in C (wm_host_quantise_with, firmware/host), else by quantised_model, its model (the
        same samples and error, tests/host/test_host_stages.py)."""
        got = native.quantise_with(v, self.scale, self.offset, self.exact)
        if got is None:
            return self.quantised_model(v)
        return got[0], None if self.exact else got[1]

    def quantised_model(self, v: np.ndarray) -> tuple[np.ndarray, float | None]:
        """quantised in numpy, a block of rows at a time (BLOCK_SAMPLES: each block's temporaries stay in
        the core's own cache)."""
        out = np.empty(v.shape, dtype=np.uint16)
        err = None if self.exact else 0.0
        step = max(1, BLOCK_SAMPLES // max(1, v.shape[1]))
        for b in range(0, v.shape[0], step):
            block, s = v[b : b + step].astype(np.float64, copy=False), out[b : b + step]
            s[...] = to_samples(block, self.scale, self.offset, self.exact)
            if err is not None:
                recon = self.offset + self.scale * s.astype(np.float64)
                err = max(err, float(np.max(np.abs(block - recon))))
        return out, err


_NPY_MAP: list = []  # [(path, the file's identity, its memmap)]: the last .npy input this process read


def _npy_map(path) -> np.ndarray:
    """The .npy input's memmap, kept by this process while it reads the same file: every phase of a tiled
    run reads its tiles' windows again, and a new mapping per read faults every page in again (terrain
    8192^2 in tiles of 1025, one worker: 2.2 s of system time and 7.5 s wall with a mapping per read,
    0.6 s and 5.7 s with this one).  One file at a time (a long-lived process, a Dask worker, holds no
    other input's mapping); a file replaced under the same name is mapped anew."""
    key = (str(path), file_identity(path))
    if not _NPY_MAP or _NPY_MAP[0][0] != key:
        _NPY_MAP[:] = [(key, np.load(path, mmap_mode="r", allow_pickle=False))]
    return _NPY_MAP[0][1]


def file_identity(path) -> tuple[int, int, int, int]:
    """The file at ``path`` as the caches of its reads tell it apart (device, inode, size, modification
    time): a file replaced under the same name is another."""
    st = os.stat(path)
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


def light_source(src: Source) -> Source:
    """The source without an in-memory input (each task then carries its own window)."""
    return src if src.kind != "array" else replace(src, array=None)


def _strip_rows(src: Source) -> int:
    return max(1, STRIP_BYTES // (8 * src.width))


def _blocks(src: Source, y: int, rows: int):
    """The heights (float64, filled as Source.read fills them) of rows y .. y + rows - 1, in blocks of whole
    rows of about BLOCK_SAMPLES each: read block by block from a .npy's memmap or an array, a raster's strip
    read at once (one window) and cut."""
    step = max(1, BLOCK_SAMPLES // src.width)
    if src.kind == "raster":
        v = src.read(0, y, src.width, rows)
        for b in range(0, rows, step):
            yield v[b : b + step]
    else:
        for b in range(y, y + rows, step):
            yield src.read(0, b, src.width, min(step, y + rows - b))


def _strip_stats(src: Source, y: int, rows: int) -> tuple[float, float, bool, int]:
    """(least, largest, all integers, non-finite count) of the heights of rows y .. y + rows - 1."""
    least, largest, integers, bad = math.inf, -math.inf, True, 0
    for v in _blocks(src, y, rows):
        ok = np.isfinite(v)
        n_bad = int(v.size - np.count_nonzero(ok))
        if n_bad:
            bad += n_bad
            v = v[ok]
            if not v.size:
                continue
        least, largest = min(least, float(v.min())), max(largest, float(v.max()))
        integers = integers and bool(np.all(v == np.floor(v)))
    return least, largest, integers, bad


def strip_tasks(src: Source) -> list[tuple[Source, int, int]]:
    """The quantisation passes' strips: (the light source, first row, rows) each."""
    rows = _strip_rows(src)
    light = light_source(src)
    return [(light, y, min(rows, src.height - y)) for y in range(0, src.height, rows)]


def strip_error(src: Source, y: int, rows: int, quant: Quant) -> float:
    """The largest quantisation error of rows y .. y + rows - 1."""
    return max(quant.quantised(v)[1] for v in _blocks(src, y, rows))


def scan(src: Source, runner: Runner | None = None, error: bool = True) -> Quant:
    """The quantisation of the whole grid, from the strips' statistics (on ``runner``'s workers: an input
    in memory is scanned here); a second pass for the largest quantisation error unless exact (``error``
    False: q left None, for the tiles' task graph to find, strip_error)."""
    tasks = strip_tasks(src)
    here = runner is None or src.kind == "array"

    def each(fn, extra=()):
        if here:
            return [fn(src, y, r, *extra) for _, y, r in tasks]
        return runner.map(fn, [t + extra for t in tasks])

    stats = each(_strip_stats)
    bad = sum(s[3] for s in stats)
    if bad:
        raise InputError(f"{src.name}: {bad} samples are NaN, infinite or no-data",
                         hint="use --fill VALUE (or --fill nearest, which reads the whole grid), or --nodata "
                              "hole to leave holes (the grid then meshed whole, not in tiles)")
    vmin, vmax = min(s[0] for s in stats), max(s[1] for s in stats)
    scale, offset, exact = quant_rule(vmin, vmax, all(s[2] for s in stats))
    quant = Quant(scale, offset, exact, 0.0, vmin, vmax)
    if exact:
        return quant
    if not error:
        return replace(quant, q=None)
    return replace(quant, q=max(each(strip_error, (quant,))))
