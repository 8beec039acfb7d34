"""An input as a run takes it: the file read (wavemesh.io.heightfield), --spacing and --origin, --crop and
--decimate, --max-hole and --denoise, and the memory an untiled run of it needs (memory_check, with the
--tile N to use instead).  ``wavemesh.api`` offers :func:`load_input` too.
"""

from __future__ import annotations

import math
import os
import resource
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from wavemesh.errors import InputError
from wavemesh.io.bridge import bridge
from wavemesh.io.georef import (
    apply_overrides,
    cropped,
    parse_pair,
)
from wavemesh.io.heightfield import HeightField, from_array, load_heightfield, parse_fill
from wavemesh.limits import MAX_SIDE
from wavemesh.model.holemask import stranded
from wavemesh.refine.denoise import denoise_heightfield


def _load(path: str, key: str | None, fill: str | None, nodata: str | None = None,
          invalid: float | None = None, size_check=None) -> HeightField:
    if nodata not in (None, "error", "hole"):
        raise InputError(f"--nodata {nodata}: not a way to treat invalid samples", hint="use hole or error")
    if nodata == "hole" and fill is not None:
        raise InputError("--fill and --nodata hole both say what to do with invalid samples",
                         hint="give one of them")
    if invalid is not None and not math.isfinite(invalid):
        raise InputError(f"--invalid {invalid}: NaN and infinities are invalid anyway", hint="give a number")
    return load_heightfield(path, key=key, fill=parse_fill(fill) if fill is not None else None,
                            invalid=invalid, holes=nodata == "hole", size_check=size_check)


def parse_crop(text: str) -> tuple[int, int, int, int]:
    """--crop X,Y,W,H: the top-left sample (column, row) and the size in samples."""
    try:
        x, y, w, h = (int(v) for v in text.replace(":", ",").split(","))
    except ValueError:
        raise InputError(f"--crop {text}: not four integers",
                         hint="give --crop X,Y,W,H, e.g. 0,0,256,256") from None
    return x, y, w, h


def crop_window(crop: str | None, decimate: int | None, width: int, height: int
                ) -> tuple[int, int, int, int, int, list[str]]:
    """--crop and --decimate on a ``width`` x ``height`` grid: (x0, y0, w, h, step, what), the samples
    (x0 + step i, y0 + step j) of a w x h grid; InputError when they do not fit.  ``what`` names them for
    the source's name.  The one place these rules live (shape_heightfield, wavemesh.tiles' windows)."""
    x0, y0, w, h, step, what = 0, 0, width, height, 1, []
    if crop is not None:
        x0, y0, w, h = parse_crop(crop)
        if x0 < 0 or y0 < 0 or w < 2 or h < 2 or x0 + w > width or y0 + h > height:
            raise InputError(f"--crop {crop} does not fit the {width} x {height} input",
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
    return x0, y0, w, h, step, what


def shape_heightfield(hf: HeightField, crop: str | None = None, decimate: int | None = None) -> HeightField:
    """The part of a height field --crop and --decimate select, quantised afresh (as if it were the file)."""
    if crop is None and decimate in (None, 1):
        return hf
    x0, y0, w, h, step, what = crop_window(crop, decimate, hf.width, hf.height)
    v = hf.values[y0:y0 + step * (h - 1) + 1:step, x0:x0 + step * (w - 1) + 1:step]
    out = from_array(np.ascontiguousarray(v), source=f"{hf.source} ({', '.join(what)})")
    spacing = hf.spacing and (hf.spacing[0] * step, hf.spacing[1] * step)
    mask = lone = None
    if hf.mask is not None:  # the part of the mask the samples came from
        part = (slice(y0, y0 + v.shape[0] * step, step), slice(x0, x0 + v.shape[1] * step, step))
        mask = hf.mask[part]
        if hf.lone is not None:
            lone = hf.lone[part]
        if mask.any():  # samples whose cells of valid samples lay outside the part are stranded now
            new = stranded(mask)
            lone = new if lone is None else lone | new
            mask = mask | new
        if mask.all():
            raise InputError(f"{out.source}: every sample is invalid; there is nothing to mesh")
        mask = np.ascontiguousarray(mask) if mask.any() else None
        lone = lone if mask is not None and lone is not None and lone.any() else None
    return replace(out, filled=hf.filled, transform=cropped(hf.transform, x0, y0, step), crs=hf.crs,
                   spacing=spacing, mask=mask, lone=lone)


def check_hole_options(nodata: str | None, max_hole: int = 0, min_area: float = 0.0) -> None:
    """--max-hole and --min-area: only with --nodata hole (load_input's check; `mesh` and `stream` make it
    before any work, for a tiled run too, which reads neither)."""
    if max_hole < 0:
        raise InputError(f"--max-hole {max_hole} is out of range",
                         hint="use 0 or more: the enclosed dropouts of at most that many samples are filled")
    if max_hole and nodata != "hole":
        raise InputError(f"--max-hole {max_hole}: fills the enclosed dropouts of at most that many samples "
                         "and keeps the others holes", hint="use it with --nodata hole")
    if min_area > 0 and nodata != "hole":
        raise InputError("--min-area drops pieces of a mesh with holes", hint="use it with --nodata hole")


def load_input(path: str, *, key: str | None = None, fill: str | None = None, crop: str | None = None,
               decimate: int | None = None, spacing: str | None = None,
               origin: str | None = None, nodata: str | None = None, invalid: float | None = None,
               denoise: str | None = None, max_hole: int = 0, check_memory: bool = False,
               tile_from: Callable[[int, int], int | None] | None = None) -> HeightField:
    """A height field file as the commands read it: --key, --fill (or --nodata hole, --invalid), --spacing
    and --origin (of the file's grid), then --crop and --decimate, then --max-hole (bridge.bridge), then
    --denoise (wavemesh.refine.denoise: what every command meshes and measures).  ``check_memory``: before the
    samples are read, the memory an untiled run of the grid takes is estimated (memory_check).
    ``tile_from(w, h)`` (`wavemesh mesh`'s default, auto_tile): asked first, once the header has told the
    W x H grid to mesh; a tile side from it raises TileInstead before any sample is read."""
    check_hole_options(nodata, max_hole)
    # the options that apply after the read, checked before it
    if crop is not None:
        parse_crop(crop)
    if decimate is not None and decimate < 1:
        raise InputError(f"--decimate {decimate} is out of range", hint="use 1 or more")
    if spacing is not None:
        parse_pair(spacing, "--spacing", positive=True, one_ok=True)
    if origin is not None:
        parse_pair(origin, "--origin", positive=False, one_ok=False)

    def size_check(width: int, height: int, itemsize: int) -> None:
        w, h = width, height
        if crop is not None:
            x, y, w, h = parse_crop(crop)
            w, h = max(0, min(w, width - x)), max(0, min(h, height - y))
        if decimate is not None and decimate >= 1:
            w, h = -(-w // decimate), -(-h // decimate)
        tile = tile_from(w, h) if tile_from is not None else None
        if tile is not None:
            raise TileInstead(tile, w, h)
        if check_memory and max(w, h) > MAX_SIDE:  # else the filter bank's "argument out of range"
            raise InputError(f"{path}: the {w} x {h} grid has a side over {MAX_SIDE} samples, more than an "
                             "untiled run takes", hint="mesh it in tiles (--tile N), or --crop or --decimate "
                                                       "it")
        if check_memory:
            memory_check(path, width, height, itemsize, w, h)

    check = size_check if check_memory or tile_from else None
    hf = shape_heightfield(apply_overrides(_load(path, key, fill, nodata, invalid, check), spacing, origin),
                           crop, decimate)
    if max_hole:
        hf = bridge(hf, max_hole)
    if denoise is None:
        return hf
    return denoise_heightfield(hf, denoise)[0]


# Memory of an untiled run (`wavemesh mesh`, `stream`), the least it takes whatever the mesh: the file's
# samples as read (their own size, plus READ_BYTES_PER_SAMPLE: float64 heights and the no-data mask) and
# MESH_BYTES_PER_SAMPLE a sample of the grid it meshes (the 16-bit samples, the filter bank, the refiner's
# grids, the error check), in address space (what ulimit -v bounds); RESIDENT_BYTES_PER_SAMPLE of resident
# memory a sample besides the file's samples (what MemAvailable and a cgroup bound).  The source:
# tools/mesh_memory.py (VmPeak and VmHWM of `wavemesh mesh` on float32 N x N, the slope between N = 1025,
# 2049, 4097; docs/tiles.md "Memory"): address space 107-111 bytes a sample for a flat field and the
# two-ball terrain, 231-246 for noise, 830 when the mesh keeps nearly every sample (noise, --zeta 0.001);
# resident 14.2-15.9 (flat), 25-42 (terrain), 231-246 (noise).  The estimates stay below those floors
# (4 + 9 + 88 = 101 and 4 + 8 = 12 bytes for float32): a run they refuse would not have fitted.
MESH_BYTES_PER_SAMPLE = 88


READ_BYTES_PER_SAMPLE = 9


RESIDENT_BYTES_PER_SAMPLE = 8


# The tile side without --tile N, from memory (wavemesh.tiles.default_tile, and the hint of memory_check
# below): the largest of these (2^k + 1, so that a grid of 2^j or 2^j + 1 samples a side splits evenly;
# tiles share a border row) whose tiles in flight, at TILE_BYTES_PER_SAMPLE each, fit in half the memory
# available.  Larger tiles cost fewer triangles at the seams, smaller ones less memory and more parallel
# work (make bench-tiles, docs/tiles.md).
TILE_CHOICES = (4097, 2049, 1025, 513)


TILE_BYTES_PER_SAMPLE = 48  # a worker's peak per sample of its tile (make bench-tiles measured about 40)


# `wavemesh mesh` without --tile (docs/usage.md, "Threads and tiles"): a grid of at least AUTO_TILE_SAMPLES
# samples, more than AUTO_TILE on a side, is meshed in tiles of AUTO_TILE (its tiles spread over the
# cores, --workers); a smaller one whole.  The grid's W x H alone decides, never the machine (its cores,
# its memory), so the mesh is the same wherever it runs and whatever --workers.  The numbers: measured on
# the tuning grids of bench/bench_big.py (docs/usage.md says which).
AUTO_TILE = 513
AUTO_TILE_SAMPLES = 2048 * 2048


def auto_tile(width: int, height: int) -> int | None:
    """The tile side `wavemesh mesh` meshes a ``width`` x ``height`` grid in without --tile: AUTO_TILE when
    the grid has at least AUTO_TILE_SAMPLES samples and AUTO_TILE cuts it (a side longer than AUTO_TILE),
    or a side is longer than MAX_SIDE (the refiner cannot take it whole), else None (untiled)."""
    if max(width, height) > MAX_SIDE:
        return AUTO_TILE
    if width * height < AUTO_TILE_SAMPLES or max(width, height) <= AUTO_TILE:
        return None
    return AUTO_TILE


class TileInstead(Exception):  # noqa: N818 - not an error: load_input's answer that the grid goes in tiles
    """load_input's ``tile_from`` chose tiles of ``tile`` for the ``width`` x ``height`` grid: the caller
    meshes it tiled (the samples were not read)."""

    def __init__(self, tile: int, width: int, height: int) -> None:
        super().__init__(f"{width} x {height}: tiles of {tile}")
        self.tile, self.width, self.height = tile, width, height


def default_workers() -> int:
    """The tile workers without --workers N: the CPUs this process may use."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def available_memory() -> int:
    """Bytes of memory available now (/proc/meminfo's MemAvailable; else the physical memory)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def memory_available() -> list[tuple[int, str, str]]:
    """What this process may still take: (bytes, what says so, "address" or "resident"): /proc/meminfo's
    MemAvailable and the cgroup's memory.max less its memory.current (resident memory), the address space
    limit (RLIMIT_AS, ulimit -v) less what the process maps now."""
    found = [(available_memory(), "memory available", "resident")]
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        used = 0
        try:
            with open("/proc/self/status") as f:
                for line in f:
                    if line.startswith("VmSize:"):
                        used = int(line.split()[1]) * 1024
        except OSError:
            pass
        found.append((max(0, soft - used), f"the address space limit, ulimit -v {soft // 1024}", "address"))
    try:
        with open("/sys/fs/cgroup/memory.max") as f:
            top = f.read().strip()
        if top.isdigit():
            with open("/sys/fs/cgroup/memory.current") as f:
                left = max(0, int(top) - int(f.read().strip()))
            found.append((left, "the cgroup's memory.max", "resident"))
    except (OSError, ValueError):
        pass
    return found


def _size(n: float) -> str:
    return f"{n / 2 ** 30:.1f} GiB" if n >= 2 ** 30 else f"{n / 2 ** 20:.0f} MiB"


def memory_check(source: str, width: int, height: int, itemsize: int, w: int | None = None,
                 h: int | None = None) -> None:
    """InputError, with the --tile N to use, when an untiled run of the ``w`` x ``h`` grid (default the
    file's ``width`` x ``height``, of ``itemsize``-byte samples) needs more memory than this process may
    take (memory_available; the estimates above)."""
    w, h = (width, height) if w is None else (w, h)
    need = {"address": width * height * (itemsize + READ_BYTES_PER_SAMPLE) + w * h * MESH_BYTES_PER_SAMPLE,
            "resident": width * height * itemsize + w * h * RESIDENT_BYTES_PER_SAMPLE}
    for have, what, kind in memory_available():
        if need[kind] <= have:
            continue
        if kind == "address":  # per process: each worker has its own address space (the tile's float64 too)
            fits = [t for t in TILE_CHOICES if (MESH_BYTES_PER_SAMPLE + READ_BYTES_PER_SAMPLE + 8) * t * t
                    <= have // 2]
        else:  # shared: every worker's tile in flight (tiles.default_tile's rule)
            fits = [t for t in TILE_CHOICES if default_workers() * TILE_BYTES_PER_SAMPLE * t * t <= have // 2]
        tile = fits[0] if fits else TILE_CHOICES[-1]
        raise InputError(f"{source}: meshing the {w} x {h} grid untiled needs at least "
                         f"{_size(need[kind])} of memory; {_size(have)} is left ({what})",
                         hint=f"mesh it in tiles: --tile {tile}" + ("" if fits else " --workers 1")
                         + " (docs/tiles.md)")
