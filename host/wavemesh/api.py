"""What the ``wavemesh`` commands do, as typed functions scripts can call: :func:`mesh` and
:func:`stream` run a job (in process, or on a device over the wire protocol) and return a
:class:`MeshResult`; :func:`write_result` writes its files.  The CLI (wavemesh.cli) is argument
parsing and printing over them.

    hf = load_input("dem.tif", fill="nearest")
    result = mesh(hf, MeshParams(refine=RefineParams(zeta=2.0)))
    write_result(result, "dem.obj", report="dem.json")
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import resource
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wavemesh import __version__, limits
from wavemesh.check import ErrorReport, HoleCheck, check_holes, check_mesh, mesh_errors
from wavemesh.errors import InputError, MeshInvalid, WavemeshError
from wavemesh.io.bridge import bridge
from wavemesh.io.georef import SIDECAR_SUFFIX as SIDECAR
from wavemesh.io.georef import (
    apply_overrides,
    cropped,
    grid_ground,
    ground,
    parse_pair,
    read_sidecar,
    sidecar_path,
    to_grid,
)
from wavemesh.io.heightfield import HeightField, from_array, load_heightfield, parse_fill
from wavemesh.io.meshio import MESH_SUFFIXES, check_options, write_mesh, write_normal_map
from wavemesh.io.meshread import read_mesh
from wavemesh.io.outputs import Inputs, Outputs, as_inputs, check_path, distinct
from wavemesh.io.synth import make
from wavemesh.mesh import Mesh
from wavemesh.model.haar import WAVELETS, decompose, default_levels
from wavemesh.model.holemask import stranded
from wavemesh.model.initial import InitialResult, assemble, initial_triangulation
from wavemesh.model.label import Labelling, tau_counts
from wavemesh.model.roi import mask_details, parse_roi, roi_errors, roi_report
from wavemesh.refine import cover, native
from wavemesh.refine.denoise import denoise_heightfield
from wavemesh.refine.native import RefineOutput, RefineParams, fixed_params

# Imported where used, for their start-up cost (tests/host/test_mesh_costs.py: `wavemesh mesh` does not
# load them): the device path (wavemesh.device: protocol, link, stream, about 16 ms), pictures
# (wavemesh.check.render: matplotlib, about 270 ms), tiles (about 16 ms), tqdm.
if TYPE_CHECKING:
    from wavemesh.device.link import LinkStats
    from wavemesh.device.stream import Device, DeviceInfo, Timeouts

MAX_LEVELS = limits.MAX_LEVELS  # the model's limit (wavemesh.limits, the one source)
DEFAULT_TAU_FRACTION = 0.01  # default tau_M: this fraction of the height range (docs/model.md)
BOUND_NOT_MET = 3  # exit status of `wavemesh mesh` when the triangle budget stopped it above zeta


def default_tau(hf: HeightField) -> float:
    return DEFAULT_TAU_FRACTION * float(np.max(hf.values) - np.min(hf.values))


@dataclass(frozen=True)
class MeshJob:
    heightfield: HeightField
    levels: int
    tau: float
    result: InitialResult
    wavelet: str = "haar"  # the filter bank's (wavemesh.model.haar.WAVELETS)
    details: np.ndarray | None = None  # the C filter bank's details (native.haar_details), None: not made

    @property
    def mesh(self) -> Mesh:
        return self.result.mesh


def triangulate(hf: HeightField, levels: int | None = None, tau: float | None = None,
                wavelet: str = "haar", labelling: Labelling | None = None) -> MeshJob:
    """The initial triangulation of a height field (filter bank, labeller, templates); with ``labelling``
    (the blocks' labels and templates as a device's template stage made them, wavemesh.device.stage) the
    templates of that labelling instead of the host's."""
    m, t = _levels_and_tau(hf, levels, tau)
    if wavelet not in WAVELETS:
        raise WavemeshError(f"--wavelet {wavelet} is not a wavelet here", hint=f"use {' or '.join(WAVELETS)}")
    details = None  # with a device's labelling the refiner's details are made later (native.refine)
    if labelling is not None:
        mesh = assemble(labelling, hf.width, hf.height)
        result = InitialResult(mesh, labelling, tau_counts(t, hf.scale), m)
    else:
        # the C filter bank once, for the labeller and the refiner (tested equal)
        details = native.haar_details(hf.samples, m, wavelet) if native.host_lib() is not None else None
        result = initial_triangulation(hf.samples, m, tau_counts(t, hf.scale), wavelet, details)
    require_proper(result.mesh, "the initial triangulation")  # the templates guarantee it: else a bug
    return MeshJob(hf, m, t, result, wavelet, details)


def _levels_and_tau(hf: HeightField, levels: int | None, tau: float | None) -> tuple[int, float]:
    """M and tau_M as given, or their defaults; WavemeshError when out of range."""
    m = default_levels(hf.width, hf.height) if levels is None else levels
    if not 1 <= m <= MAX_LEVELS:
        raise WavemeshError(f"--levels {m} is out of range", hint=f"use 1..{MAX_LEVELS}")
    t = default_tau(hf) if tau is None else tau
    if not math.isfinite(t) or t < 0:
        raise WavemeshError(f"--tau {t} is not a finite number >= 0", hint="give tau in height units")
    return m, t


def _check_output(path: str, suffixes: tuple[str, ...], what: str, inputs=None) -> Path:
    return check_path(path, suffixes, what, inputs)  # extension, directory, writable, not an input (outputs)


def _write_json(path: str, data: dict, inputs=None) -> None:
    p = _check_output(path, (".json",), "report", inputs)
    with Outputs(inputs) as staged:  # whole or not at all
        staged.path(p, what="report").write_text(json.dumps(data, indent=2) + "\n")


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


def load_input(path: str, *, key: str | None = None, fill: str | None = None, crop: str | None = None,
               decimate: int | None = None, spacing: str | None = None,
               origin: str | None = None, nodata: str | None = None, invalid: float | None = None,
               denoise: str | None = None, max_hole: int = 0, check_memory: bool = False) -> HeightField:
    """A height field file as the commands read it: --key, --fill (or --nodata hole, --invalid), --spacing
    and --origin (of the file's grid), then --crop and --decimate, then --max-hole (bridge.bridge), then
    --denoise (wavemesh.refine.denoise: what every command meshes and measures).  ``check_memory``: before the
    samples are read, the memory an untiled run of the grid takes is estimated (memory_check)."""
    if max_hole and (nodata != "hole" or max_hole < 0):
        raise InputError(f"--max-hole {max_hole}: fills the enclosed dropouts of at most that many samples "
                         "and keeps the others holes", hint="use it with --nodata hole, N >= 0")
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
        memory_check(path, width, height, itemsize, w, h)

    hf = shape_heightfield(apply_overrides(_load(path, key, fill, nodata, invalid,
                                                 size_check if check_memory else None), spacing, origin),
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


@dataclass
class RefineJob:
    """The full pipeline: the initial triangulation, then the firmware refiner (docs/refiner.md)."""

    initial: MeshJob
    params: RefineParams
    zeta_used: float  # zeta given to the refiner (less 2 x the quantisation error for lossy input)
    output: RefineOutput
    seconds: float  # time spent in the refiner
    errors: ErrorReport | None = None  # the final mesh's errors against the input (check.mesh_errors)
    roi: np.ndarray | None = None  # the region of interest (wavemesh.model.roi), or None: the whole grid
    roi_errors: ErrorReport | None = None  # the final mesh's errors over the ROI samples (roi.roi_errors)
    holes: HoleCheck | None = None  # with holes (--nodata hole): the final mesh's check (drop_holes)

    @property
    def mesh(self) -> Mesh:
        return self.output.final.mesh

    @property
    def bound_met(self) -> bool:
        return self.output.final.stats["over"] == 0


BUG_HINT = "this is a bug in wavemesh: please report it with the input and the options"
BOUND_EPS = 1e-9  # the float metric's own rounding, relative (docs/refiner.md)


def require_proper(mesh: Mesh, what: str) -> None:
    """MeshInvalid (one line, exit status 1) unless ``mesh`` is a proper triangulation (check_mesh)."""
    verdict = check_mesh(mesh)
    if not verdict.valid:
        raise MeshInvalid(f"{what} is not a proper triangulation: " + "; ".join(verdict.problems[:3]),
                          hint=BUG_HINT)


def bound_excess(hf: HeightField, rjob: RefineJob, errors: ErrorReport) -> str | None:
    """None when the final mesh is within zeta where the bound applies, else what is wrong.

    The bound applies when the refiner reports every triangle within zeta (not when the triangle budget
    stopped it).  Lossless input: E_max by the chosen metric <= zeta on the input.  Lossy quantisation
    (docs/refiner.md): vertically on the input when zeta >= 2q, else E_max <= the zeta the refiner was
    given on the 16-bit samples it saw.  The float metric's own rounding is allowed (1e-9 relative).
    With an ROI the bound and ``errors`` are over the ROI samples (wavemesh.model.roi)."""
    if not rjob.bound_met:
        return None
    p = rjob.params
    eps = BOUND_EPS * max(1.0, p.zeta)
    metric = "e_max_normal" if p.metric == "normal" else "e_max_vertical"
    if hf.lossless or (p.metric == "vertical" and p.zeta >= 2 * hf.max_quantisation_error):
        e, zeta, on = getattr(errors, metric), p.zeta, "the input"
    else:
        quantised = hf.offset + hf.scale * hf.samples.astype(np.float64)
        sp = ground(hf).spacing
        e = getattr(mesh_errors(rjob.mesh, quantised, spacing=sp) if rjob.roi is None
                    else roi_errors(rjob.mesh, quantised, rjob.roi, spacing=sp), metric)
        zeta, on = rjob.zeta_used, "the 16-bit samples"
    if e <= zeta + eps:
        return None
    return (f"the refined mesh is not within zeta: E_max {p.metric} {e:.9g} > zeta {zeta:g} on {on}, though "
            f"the refiner reported every triangle within it")


def refine(hf: HeightField, levels: int | None = None, tau: float | None = None,
           params: RefineParams | None = None, *, check_levels: bool = False, rms: bool = False,
           wavelet: str = "haar", roi: np.ndarray | None = None, min_area: float = 0.0,
           labelling: Labelling | None = None) -> RefineJob:
    """Filter bank, templates, then the native refiner down to level 0 with E(T) <= zeta.

    The final mesh is always checked: a proper triangulation (check_mesh) and, when the refiner reports
    the bound met, within zeta (mesh_errors, kept in ``errors``: its maxima, and its RMS when ``rms``);
    otherwise MeshInvalid.  ``check_levels`` also checks every coarser level's mesh.  ``roi``: an (H, W)
    bool region of interest, the only place refined and bounded (selective triangulation,
    wavemesh.model.roi)."""
    params = params or RefineParams()
    params.check()
    native.load()  # builds the C library if it is missing or stale: not part of the refiner's time
    job = triangulate(hf, levels, tau, wavelet, labelling)
    zeta = hf.refiner_zeta(params.zeta)  # the refiner sees the 16-bit samples
    start = time.perf_counter()
    spacing = ground(hf).spacing  # the normal metric's cell size in height units (wavemesh.io.georef)
    details = job.levels  # the library's filter bank makes them (native.refine)
    if roi is not None:
        # 5.6: no detail energy outside the ROI
        details = mask_details(decompose(hf.samples, job.levels, job.wavelet), roi)
    out = native.refine(hf.samples, details, job.mesh, params, scale=hf.scale, zeta=zeta, spacing=spacing,
                        roi=roi, mask=hf.mask, wavelet=job.wavelet,
                        details=job.details if roi is None else None)
    seconds = time.perf_counter() - start
    # The operators keep the mesh proper and within zeta: a failure here is a bug.
    for lv in out.levels if check_levels else out.levels[-1:]:
        require_proper(lv.mesh, f"the refiner's mesh at level {lv.level}")
    hole_check = drop_holes(out.levels, hf, min_area,
                            native.error_within(hf.samples, out.params) if hf.mask is not None else None)
    rjob = RefineJob(job, params, zeta, out, seconds, roi=roi, holes=hole_check)
    rjob.errors = mesh_errors(rjob.mesh, hf.values, rms=rms, spacing=spacing)
    if roi is not None:
        rjob.roi_errors = roi_errors(rjob.mesh, hf.values, roi, rms=rms, spacing=spacing)
    excess = bound_excess(hf, rjob, rjob.errors if roi is None else rjob.roi_errors)
    if excess:
        raise MeshInvalid(excess, hint=BUG_HINT)
    return rjob


def native_within(samples, fp):
    """native.error_within (the library loads, and builds if needed, when holes need it)."""
    return native.error_within(samples, fp)


def drop_holes(levels: list, hf: HeightField, min_area: float = 0.0, within=None) -> HoleCheck | None:
    """With holes (hf.mask): every level's mesh less the triangles over invalid samples, the final one
    also less the rim vertices that ``within`` (native.error_within) lets go
    (cover.simplify_rims) and the pieces under ``min_area``, and checked (wavemesh.refine.cover: the refiner's
    full meshes were proper triangulations of the rectangle); MeshInvalid when it is not a mesh of the
    valid samples."""
    if hf.mask is None:
        if min_area > 0:
            raise InputError("--min-area drops pieces of a mesh with holes", hint="use it with --nodata hole")
        return None
    final = levels[-1]
    for lv in levels:  # the final mesh's thin rim triangles flipped where a valid one comes of it
        lv.mesh = cover.drop(cover.flip_thin(lv.mesh, hf.mask) if lv is final else lv.mesh, hf.mask)
    if within is not None:
        final.mesh = cover.simplify_rims(final.mesh, within, hf.mask)
    final.mesh = cover.drop_islands(final.mesh, min_area)
    verdict = check_holes(final.mesh, hf.mask, min_area)
    # (with --min-area, pieces dropped next to each other can leave a larger uncovered group than
    # check_holes's bound: the report says so, and the run goes on)
    if final.stats["over"] == 0 and min_area <= 0 and not verdict.valid_mesh:
        raise MeshInvalid("the mesh with holes is not a proper mesh of the valid samples: "
                          + "; ".join(verdict.problems[:3]), hint=BUG_HINT)
    return verdict


def level_report(lv, hf: HeightField, metric: str, errors: ErrorReport | None = None) -> dict:
    """One level's row: counts, the firmware's E_max and the independent float E_max (``errors``: the
    level's mesh_errors when already measured)."""
    errors = errors if errors is not None else mesh_errors(lv.mesh, hf.values, rms=False,  # maxima
                                                           spacing=ground(hf).spacing)
    st = lv.stats
    return {
        "level": lv.level,
        "vertices": lv.mesh.n_vertices,
        "triangles": lv.mesh.n_triangles,
        "e_max": errors.e_max_normal if metric == "normal" else errors.e_max_vertical,
        "e_max_normal": errors.e_max_normal,
        "e_max_vertical": errors.e_max_vertical,
        "e_max_firmware": st["e_max_q16"] / 65536 * hf.scale,
        "over_zeta": st["over"],
        "splits": st["edge_splits"] + st["ternary_splits"] + st["bound_splits"],
        "swaps": st["swaps"],
        "firmware": st,
    }


def level_counts(lv, hf: HeightField) -> dict:
    """A level's row without measuring it: counts and the refiner's own E_max (never below the exact)."""
    st = lv.stats
    return {
        "level": lv.level,
        "vertices": lv.mesh.n_vertices,
        "triangles": lv.mesh.n_triangles,
        "e_max_firmware": st["e_max_q16"] / 65536 * hf.scale,
        "over_zeta": st["over"],
        "splits": st["edge_splits"] + st["ternary_splits"] + st["bound_splits"],
        "swaps": st["swaps"],
    }


# ---------------------------------------------------------------------------------------------------
# The typed API: `wavemesh mesh` and `wavemesh stream` as functions (the CLI is argument parsing over
# them, wavemesh.cli).


@dataclass(frozen=True)
class MeshParams:
    """The job of `wavemesh mesh` and `wavemesh stream`: every option that is not a file."""

    levels: int | None = None  # M, 1..MAX_LEVELS; None: default_levels
    tau: float | None = None  # tau_M in height units; None: default_tau
    wavelet: str = "haar"  # the filter bank (--wavelet): wavemesh.model.haar.WAVELETS
    initial_only: bool = False  # stop after the template stage (--stage initial)
    refine: RefineParams = field(default_factory=RefineParams)  # the refiner's (ignored when initial_only)
    check_levels: bool = False  # also check and measure every coarser level (stream always does)
    rms: bool = False  # RMS errors too (the report's), not only the maxima
    roi: tuple | np.ndarray | None = None  # --roi: rectangles "X,Y,W,H" / mask files, or a bool array
    min_area: float = 0.0  # --min-area: with holes, drop pieces of the mesh smaller (square grid steps)


class LevelMeshes(Sequence):
    """(level, mesh) of each of the refiner's levels, the coarsest first, each Mesh made when first read
    (native.Level): a run without --lod, --report or --check-levels reads the final one alone (at 4096^2
    the finer levels' int64 copies are hundreds of MiB)."""

    def __init__(self, levels: list) -> None:
        self._levels = levels

    def __len__(self) -> int:
        return len(self._levels)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [(lv.level, lv.mesh) for lv in self._levels[i]]
        lv = self._levels[i]
        return lv.level, lv.mesh


@dataclass(kw_only=True)
class MeshResult:
    """What a job made: the final mesh, every level's, their errors, and the JSON report's content."""

    heightfield: HeightField
    params: MeshParams
    refine_params: RefineParams | None  # as run (stream: the device's budget filled in); None: initial only
    levels: int  # M as used
    tau: float  # tau_M as used
    mesh: Mesh  # the final mesh
    errors: ErrorReport  # the final mesh's against the input
    level_meshes: Sequence[tuple[int, Mesh]]  # (level, mesh), the coarsest first; the last is ``mesh``
    rows: list[dict]  # the level table (level_report or level_counts rows); empty for initial only
    bound_met: bool  # the refiner reports every triangle within zeta (True for initial only)
    comment: str  # the mesh files' comment line
    report: dict  # the JSON report, less its file names (write_result adds them)
    refined: RefineJob | None = None  # mesh(): the refiner's job

    @property
    def e_max(self) -> float:
        """The final mesh's E_max by the run's metric, where the bound applies (with an ROI: inside it)."""
        metric = self.refine_params.metric if self.refine_params else "normal"
        e = self.refined.roi_errors if self.refined is not None and self.refined.roi_errors else self.errors
        return e.e_max_normal if metric == "normal" else e.e_max_vertical

    @property
    def exit_status(self) -> int:
        """0, or BOUND_NOT_MET when the triangle budget stopped the run above zeta."""
        p = self.refine_params
        return BOUND_NOT_MET if p is not None and p.bound and not self.bound_met else 0

    def bound_warning(self) -> str | None:
        """The warning when the triangle budget stopped the run above zeta, else None."""
        if not self.exit_status:
            return None
        p = self.refine_params
        return (f"the error bound is not met: E_max {self.e_max:.6g} > zeta {p.zeta:g} "
                f"({self.rows[-1]['over_zeta']} triangles over) at the triangle budget (--max-triangles "
                f"{p.max_triangles})")


@dataclass(kw_only=True)
class StreamResult(MeshResult):
    """A job done on a device: MeshResult, and what the device and the link reported."""

    device: DeviceInfo
    cycles: dict  # the device's cycles per stage (DONE's cycles_* fields, the prefix dropped)
    link: LinkStats
    upload_seconds: float
    job_seconds: float


def _comment(m: int, tau: float, p: RefineParams | None) -> str:
    if p is None:
        return f"wavemesh {__version__} initial triangulation, M={m} tau={tau:g}"
    return f"wavemesh {__version__} refined mesh, M={m} tau={tau:g} zeta={p.zeta:g} metric={p.metric}"


def mesh(hf: HeightField, params: MeshParams | None = None, labelling: Labelling | None = None) -> MeshResult:
    """`wavemesh mesh` without the files: the filter bank and the templates, then (unless
    ``initial_only``) the native refiner.  The final mesh is always checked (a proper triangulation,
    within zeta when the refiner reports the bound met; else MeshInvalid); the coarser levels are
    checked and measured only with ``check_levels``.  ``labelling``: see :func:`triangulate`."""
    params = params or MeshParams()
    m, t = _levels_and_tau(hf, params.levels, params.tau)
    roi = None
    if params.roi is not None:
        roi = parse_roi(params.roi, hf.width, hf.height)
    if roi is not None and (params.initial_only or not params.refine.bound):
        raise InputError("--roi selects where the refiner works and bounds the error",
                         hint="use it with --stage full and --bound on")
    if roi is not None and hf.mask is not None:
        raise InputError("--roi and --nodata hole do not go together yet (the ROI's error measure does not "
                         "know holes)", hint="fill the invalid samples (--fill nearest), or drop --roi")
    if params.initial_only:
        job = triangulate(hf, m, t, params.wavelet, labelling)  # checks the mesh
        errors = mesh_errors(job.mesh, hf.values, rms=params.rms, spacing=ground(hf).spacing)
        report = {"wavemesh": __version__, "input": hf.to_report(), "ground": ground(hf).to_report(),
                  "parameters": {"levels": m, "tau": t, "wavelet": params.wavelet, "stage": "initial"},
                  "initial": job.result.to_report(), "errors": errors.to_report()}
        return MeshResult(heightfield=hf, params=params, refine_params=None, levels=m, tau=t, mesh=job.mesh,
                          errors=errors, level_meshes=[(m - 1, job.mesh)], rows=[], bound_met=True,
                          comment=_comment(m, t, None), report=report)
    p = params.refine
    rjob = refine(hf, m, t, p, check_levels=params.check_levels, rms=params.rms, wavelet=params.wavelet,
                  roi=roi, min_area=params.min_area, labelling=labelling)
    final = rjob.output.final
    if params.check_levels:
        rows = [level_report(lv, hf, p.metric, rjob.errors if lv is final else None)
                for lv in rjob.output.levels]
    else:
        rows = [level_counts(lv, hf) for lv in rjob.output.levels]
    parameters = ({"levels": m, "tau": t, "wavelet": params.wavelet, "stage": "full"} | p.to_report()
                  | {"zeta_refiner": rjob.zeta_used})
    report = {
        "wavemesh": __version__,
        "input": hf.to_report(),
        "ground": ground(hf).to_report(),
        "parameters": parameters,
        "initial": rjob.initial.result.to_report(),
        "errors": rjob.errors.to_report(),
        "refiner": {
            "levels": rows,
            "bound_met": rjob.bound_met,
            "seconds": rjob.seconds,
            "capacity": rjob.output.capacity,
            "fixed_point": {name: int(getattr(rjob.output.params, name))
                            for name, _ in rjob.output.params._fields_},
        },
    }
    if rjob.holes is not None:
        parameters["min_area"] = params.min_area
        report["holes"] = rjob.holes.to_report()
    if roi is not None:
        parameters["roi"] = [str(s) for s in params.roi] if isinstance(params.roi, (tuple, list)) else "array"
        report["roi"] = roi_report(rjob.mesh, roi, rjob.roi_errors, rjob.errors, p.metric)
    return MeshResult(heightfield=hf, params=params, refine_params=p, levels=m, tau=t, mesh=rjob.mesh,
                      errors=rjob.errors, level_meshes=LevelMeshes(rjob.output.levels),
                      rows=rows, bound_met=rjob.bound_met, comment=_comment(m, t, p), report=report,
                      refined=rjob)


class Progress:
    """A progress bar on stderr (tqdm) fed absolute counts with a note, as Device.upload feeds it: redrawn
    in place on a terminal; elsewhere (logs, tests) only its last line, when it finishes.  A context
    manager: leaving it early (an error) ends a terminal's bar with a newline, so the error line starts
    a line of its own."""

    FORMAT = "{desc:<9} [{bar:28}] {percentage:5.1f}%{postfix}"

    def __init__(self, label: str, total: int, enabled: bool):
        from tqdm import tqdm  # only when a bar is drawn

        self.tqdm, self.label, self.total, self.enabled = tqdm, label, total, enabled
        self.done, self.note, self.t0 = 0, "", time.monotonic()
        self.bar = None
        if enabled and sys.stderr.isatty():
            self.bar = tqdm(total=total, desc=label, file=sys.stderr, ascii=".#", bar_format=self.FORMAT,
                            mininterval=0.1, dynamic_ncols=True)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        self.enabled = False

    def update(self, done: int, note: str | None = None) -> None:
        self.done = done
        if note is not None:
            self.note = note
        if self.bar is not None:
            self.bar.set_postfix_str(self.note, refresh=False)
            self.bar.update(done - self.bar.n)

    def finish(self, note: str | None = None) -> None:
        if note is not None:
            self.update(self.done, note)
        if self.bar is None and self.enabled:  # not a terminal: the last line alone
            print(self.tqdm.format_meter(self.done, self.total, time.monotonic() - self.t0, prefix=self.label,
                                         ascii=".#", bar_format=self.FORMAT, postfix=self.note),
                  file=sys.stderr, flush=True)
        self.__exit__()


def device_fit_hint(hf: HeightField, info: DeviceInfo) -> str | None:
    """None when the device holds the height field, else a hint: the --decimate that makes it fit."""
    w, h = hf.width, hf.height
    if w <= info.max_width and h <= info.max_height and w * h <= info.max_samples:
        return None
    for n in range(2, 1 + max(w, h)):
        dw, dh = -(-w // n), -(-h // n)
        if dw <= info.max_width and dh <= info.max_height and dw * dh <= info.max_samples:
            return (f"--decimate {n} makes it {dw} x {dh}; or --crop X,Y,W,H with W <= {info.max_width}, "
                    f"H <= {info.max_height}; or --tile {min(info.max_width, info.max_height)}: the whole "
                    f"input in tiles (docs/tiles.md)")
    return "crop it with --crop X,Y,W,H, or mesh it in tiles with --tile N (docs/tiles.md)"


STAGE_NAMES = {0: "receiving", 1: "filter bank", 2: "templates", 3: "refining", 4: "sending", 5: "done"}


def stream(hf: HeightField, port, params: MeshParams | None = None, *, baud: int | None = None,
           link_baud: int | str | None = None, timeouts: Timeouts | None = None, trace=None,
           progress: bool = False, log: Callable[[str], None] | None = None,
           warn: Callable[[str], None] | None = None) -> StreamResult:
    """`wavemesh stream` without the files: the job of :func:`mesh` on a device behind ``port`` (a
    pyserial URL or an open port object) over the wire protocol (wavemesh.device.stream.Device).

    The device's capacity bounds the job: an input larger than it holds, more levels than it makes, a
    --capacity or --max-triangles beyond its storage are DeviceErrors with a hint; without
    ``max_triangles`` the budget is its storage less one.  Every level is checked (a proper
    triangulation, else ProtocolError) and measured.  ``trace``: a text stream for the frames' hex
    dump; ``progress``: bars on stderr; ``log``: called with each line worth telling a user; ``baud`` and
    ``timeouts``: by default wavemesh.device.link.DEFAULT_BAUD and wavemesh.device.stream.DEFAULT_TIMEOUTS.
    ``link_baud``: after HELLO move the line to this rate (``"auto"``: the fastest of
    protocol.COMMON_BAUDS the device reaches; wavemesh.device.stream.Device.change_baud); a switch that does
    not
    happen or fails is one line to ``warn`` and the job runs at ``baud``."""
    from wavemesh.device import protocol as P  # start-up: the device path only for `stream` (see the top)
    from wavemesh.device.link import DEFAULT_BAUD  # the same
    from wavemesh.device.stream import (  # the same
        DEFAULT_TIMEOUTS,
        Device,
        DeviceError,
        ProtocolError,
        config_payload,
        samples_crc,
    )

    baud = DEFAULT_BAUD if baud is None else baud
    timeouts = DEFAULT_TIMEOUTS if timeouts is None else timeouts
    params = params or MeshParams()
    p = params.refine
    p.check()
    if params.roi is not None:  # no device takes an ROI (model.roi): refused before the port is opened
        raise InputError("--roi: selective triangulation runs on the host only; no device takes a region of "
                         "interest", hint="use `wavemesh mesh --roi ...`, or stream without --roi")
    m, tau = _levels_and_tau(hf, params.levels, params.tau)
    full = not params.initial_only
    tau_q = tau_counts(tau, hf.scale)
    zeta = hf.refiner_zeta(p.zeta)  # as refine()
    say = log or (lambda text: None)

    with Device(port, baud, trace=trace, timeouts=timeouts) as dev:
        info = dev.sync()
        say(f"device: {info.summary()}")
        if link_baud is not None:
            info = _switch_baud(dev, info, link_baud, say, warn or say)
        hint = device_fit_hint(hf, info)
        if hint:
            raise DeviceError(f"{hf.source} is {hf.width} x {hf.height} samples; the device holds at most "
                              f"{info.max_width} x {info.max_height} ({info.max_samples} samples)", hint)
        if m > info.max_levels:
            raise DeviceError(f"--levels {m}: the device makes at most {info.max_levels}",
                              hint=f"use --levels {info.max_levels} or fewer")
        if not full and not info.features & (P.FEATURE_INITIAL_ONLY | P.FEATURE_STAGE):
            raise DeviceError("the device cannot stop after the template stage", hint="use --stage full")
        if hf.mask is not None and not info.features & P.FEATURE_HOLES:
            raise DeviceError("--nodata hole: the device takes no validity mask (no FEATURE_HOLES)",
                              hint="use `wavemesh mesh --nodata hole`, or stream with --fill nearest")
        if params.wavelet != "haar" and not info.features & P.FEATURE_SPLINE:
            raise DeviceError(f"--wavelet {params.wavelet}: the device's filter bank makes Haar's only",
                              hint="use --wavelet haar, or `wavemesh mesh` on the host")
        if info.features & P.FEATURE_STAGE:
            return _stream_on_stage(hf, dev, info, replace(params, levels=m, tau=tau), port, baud, timeouts,
                                    progress)
        storage = p.capacity or info.tri_capacity
        if storage > info.tri_capacity:
            raise DeviceError(f"--capacity {storage}: the device has storage for {info.tri_capacity} "
                              "triangles",
                              hint=f"use --capacity {info.tri_capacity} or less")
        budget_note = ""
        if p.max_triangles is None:
            p = replace(p, max_triangles=storage - 1)
            budget_note = " (the device's capacity less one)"
        elif p.max_triangles >= storage:
            raise DeviceError(f"--max-triangles {p.max_triangles}: the device honours a budget of "
                              f"at most {storage - 1} (storage for {storage} triangles)",
                              hint=f"use --max-triangles {storage - 1} or less")
        fp = fixed_params(p, hf.scale, zeta, ground(hf).spacing)
        dev.configure(config_payload(hf.width, hf.height, m, tau_q, fp, capacity=p.capacity or 0,
                                     initial_only=not full, spline=params.wavelet == "spline",
                                     mask=hf.mask is not None))
        if full:
            say(f"job: {hf.width} x {hf.height}, M={m}, tau={tau:g}, zeta {p.zeta:g} ({p.metric}), "
                f"budget {p.max_triangles} triangles{budget_note}")
        words = P.job_words(hf.samples, hf.mask)  # the samples, then a mask's bits (CONFIG_MASK)
        kib = 2 * len(words) / 1024
        with Progress("heights", len(words), progress) as bar:
            t0 = time.monotonic()
            sent = dev.upload(hf.samples, bar, None if hf.mask is None else words[hf.samples.size:],
                              coded=bool(info.features & P.FEATURE_RICE))
            upload_s = time.monotonic() - t0
            bar.finish(f"{kib:.1f} KiB in {upload_s:.2f} s ({kib / max(upload_s, 1e-9):.1f} KiB/s)")
        got: list = []
        with Progress("device", m if full else 1, progress) as work:

            def on_progress(x: dict) -> None:
                name = STAGE_NAMES.get(x["stage"], "?")
                lvl = f" level {x['level']}" if x["stage"] in (P.Stage.REFINE, P.Stage.EMIT) else ""
                work.update(len(got), f"{name}{lvl}")

            def on_level(lv) -> None:
                got.append(lv)
                work.update(len(got), f"level {lv.level}: {lv.mesh.n_triangles} triangles")

            t1 = time.monotonic()
            levels, done = dev.run(samples_crc(words), hf.width, hf.height, on_level, on_progress)
            job_s = time.monotonic() - t1
            work.finish(f"{len(levels)} level{'s' if len(levels) != 1 else ''} in {job_s:.2f} s")
        link = dev.link.stats

    for lv in levels:
        verdict = check_mesh(lv.mesh)
        if not verdict.valid:
            raise ProtocolError(f"the device's level {lv.level} is not a proper triangulation: "
                                + "; ".join(verdict.problems[:3]))
    hole_check = drop_holes(levels, hf, params.min_area,  # as mesh() does: the same meshes
                            native_within(hf.samples, fp) if hf.mask is not None and full else None)
    final = levels[-1]
    rows = [level_report(lv, hf, p.metric) | {"device_cycles": lv.cycles, "stream_bytes": lv.nbytes,
                                              "arrived_s": lv.seconds} for lv in levels] if full else []
    errors = mesh_errors(final.mesh, hf.values, rms=params.rms, spacing=ground(hf).spacing)
    clk = info.clk_hz
    cycles = {f.name[len("cycles_"):]: done[f.name] for f in P.DONE.fields if f.name.startswith("cycles_")}
    parameters = {"levels": m, "tau": tau, "wavelet": params.wavelet, "stage": "full" if full else "initial"}
    report = {
        "wavemesh": __version__,
        "input": hf.to_report(),
        "ground": ground(hf).to_report(),
        "parameters": parameters,
        "initial": {"levels": m, "block_size": 1 << m, "tau_counts": tau_q,
                    "vertices": levels[0].mesh.n_vertices, "triangles": levels[0].mesh.n_triangles},
        "errors": errors.to_report(),
        "device": info.to_report(),
        "device_cycles": cycles | {"seconds": {k: v / clk for k, v in cycles.items()}},
        "transfer": {"port": port if isinstance(port, str) else repr(port), "baud": baud,
                     "line_baud": info.baud, "height_bytes": 2 * hf.width * hf.height, "bytes_sent": sent,
                     "upload_seconds": upload_s,
                     "mesh_bytes": sum(lv.nbytes for lv in levels), "job_seconds": job_s,
                     "frames_out": link.frames_out, "frames_in": link.frames_in, "bytes_out": link.bytes_out,
                     "bytes_in": link.bytes_in, "damaged_frames": link.damaged},
    }
    bound_met = final.stats["over"] == 0
    if hole_check is not None:
        parameters["min_area"] = params.min_area
        report["holes"] = hole_check.to_report()
    if full:
        parameters.update(p.to_report())
        parameters["zeta_refiner"] = zeta
        report["refiner"] = {
            "levels": rows,
            "bound_met": bound_met,
            "seconds": cycles["refine"] / clk,
            "capacity": storage,
            "fixed_point": {name: int(getattr(fp, name)) for name, _ in fp._fields_},
        }
    run = p if full else None
    return StreamResult(heightfield=hf, params=params, refine_params=run, levels=m, tau=tau,
                        mesh=final.mesh, errors=errors, level_meshes=LevelMeshes(levels),
                        rows=rows, bound_met=bound_met or not full, comment=_comment(m, tau, run),
                        report=report, device=info, cycles=cycles, link=link, upload_seconds=upload_s,
                        job_seconds=job_s)


def _switch_baud(dev, info, link_baud, say, warn):
    """--link-baud: the device's HELLO at the rate the line runs at from now on (the start rate after a
    switch that did not happen or failed: one line to ``warn`` says so)."""
    from wavemesh.device import protocol as P  # start-up: the device path only for `stream` (see the top)

    if link_baud == "auto":
        rate = next((b for b in P.COMMON_BAUDS if info.reachable(b)), None)
        if rate is None:
            if info.div_max:
                warn(f"--link-baud auto: the device reaches none of the common rates; staying at "
                     f"{dev.link.baud} baud")
            return info
    else:
        rate = int(link_baud)
    if rate == dev.link.baud:
        return info
    new, problem = dev.change_baud(rate)
    if problem:
        warn(problem)
    else:
        say(f"link: {rate} baud (the device at {new.baud})")
    return new


def _stream_on_stage(hf: HeightField, dev: Device, info: DeviceInfo, params: MeshParams, port, baud: int,
                     timeouts: Timeouts, progress: bool) -> StreamResult:
    """stream() on a device that states FEATURE_STAGE (the iCEBreaker's FPGA stage alone): its filter bank
    and template stage label the blocks (wavemesh.device.stage), and the host does the rest as mesh() does,
    from
    that labelling: the same mesh as `wavemesh mesh` when the device's labels are the model's."""
    from wavemesh.device import stage  # start-up: the device path only for `stream` (see the top)

    silence = timeouts.reply * timeouts.attempts
    with Progress("heights", hf.width * hf.height, progress) as bar:
        t0 = time.monotonic()
        tau_q = tau_counts(params.tau, hf.scale)
        lab = stage.labelling(dev.link, hf.samples, params.levels, tau_q, silence, bar)
        upload_s = time.monotonic() - t0
        bar.finish(f"{2 * hf.width * hf.height / 1024:.1f} KiB in {upload_s:.2f} s, the blocks' templates "
                   "back")
    t1 = time.monotonic()
    result = mesh(hf, params, labelling=lab)
    link = dev.link.stats
    report = result.report | {
        "device": info.to_report(),
        "transfer": {"port": port if isinstance(port, str) else repr(port), "baud": baud,
                     "height_bytes": 2 * hf.width * hf.height, "entry_bytes": 2 * lab.label.size,
                     "upload_seconds": upload_s, "bytes_out": link.bytes_out, "bytes_in": link.bytes_in}}
    base = {f.name: getattr(result, f.name) for f in dataclasses.fields(MeshResult)}
    return StreamResult(**(base | {"report": report}), device=info, cycles={}, link=link,
                        upload_seconds=upload_s, job_seconds=time.monotonic() - t1)


# ---------------------------------------------------------------------------------------------------
# Files


@dataclass(frozen=True)
class MeshFiles:
    """How the mesh files are written (wavemesh.io.meshio.write_mesh): ``units`` "metres" or "crs" for a
    georeferenced grid, ``local`` (with "crs"), per-vertex ``normals``, a solid ``base`` (thickness below
    the lowest height), and ``normal_map``, a PNG of the heights' normals to write beside them."""

    units: str = "metres"
    local: bool = False
    normals: bool = False
    base: float | None = None
    normal_map: str | None = None

    def to_report(self) -> dict:
        return {"units": self.units, "local": self.local, "normals": self.normals, "base": self.base}


PICTURE_SUFFIXES = (".png", ".svg", ".pdf")


def check_outputs(output: str, *, lod: str | None = None, report: str | None = None,
                  render: str | None = None, files: MeshFiles | None = None,
                  inputs: Inputs | list | None = None,
                  exaggeration: float | None = None) -> tuple[Path, Path | None]:
    """The output paths of `mesh` and `stream`, and the options of their mesh files, checked before any
    work: (mesh file, --lod folder).  None of them (nor the mesh's sidecar) may be one of ``inputs``
    (wavemesh.io.outputs.Inputs)."""
    inputs = as_inputs(inputs)
    out = _check_output(output, MESH_SUFFIXES, "mesh", inputs)
    inputs.refuse(sidecar_path(out), "the mesh's sidecar")
    distinct({"-o": output, "--report": report, "--render": render,
              "--normal-map": files.normal_map if files is not None else None})
    if files is not None:
        check_options(out, units=files.units, local=files.local, normals=files.normals, base=files.base)
        if files.normal_map:
            _check_output(files.normal_map, (".png",), "normal map", inputs)
    if render:
        _check_output(render, PICTURE_SUFFIXES, "picture", inputs)
        check_exaggeration(exaggeration)
    if report:
        _check_output(report, (".json",), "report", inputs)
    folder = check_path(lod, None, "--lod", inputs) if lod else None
    if folder is not None and folder.resolve() in {Path(p).resolve() for p in (output, report, render) if p}:
        raise InputError(f"--lod {lod} names a file the run also writes", hint="give --lod its own folder")
    return out, folder


def write_result(result: MeshResult, output: str, *, lod: str | None = None, report: str | None = None,
                 render: str | None = None, title: str | None = None, local: bool = False,
                 exaggeration: float | None = None, files: MeshFiles | None = None,
                 inputs: Inputs | list | None = None) -> list[str]:
    """Write a result's files: the mesh (a format of wavemesh.io.meshio.FORMATS, in the frame ``files``
    chooses, with its sidecar), each level's into ``lod``, the normal map, the JSON report and a
    picture (true aspect, heights times ``exaggeration``: by default 1 in ground units, automatic in
    grid steps).  ``local``: MeshFiles(units="crs", local=True), as before ``files``.  None of them may
    be one of ``inputs`` (the input file: wavemesh.io.outputs).  Returns the level files written."""
    if files is None:
        files = MeshFiles(units="crs", local=True) if local else MeshFiles()
    inputs = as_inputs(inputs)
    out, folder = check_outputs(output, lod=lod, report=report, render=render, files=files, inputs=inputs,
                                exaggeration=exaggeration)
    hf = result.heightfield
    if files.base is not None and hf.mask is not None:
        raise InputError("--base closes a mesh of the whole grid rectangle into a solid; this one has holes",
                         hint="leave out --base, or fill the invalid samples (--fill nearest)")
    g = ground(hf)
    opts = {"ground": g, "local": files.local, "units": files.units, "normals": files.normals,
            "base": files.base}
    written = []
    with Outputs(inputs) as staged:  # every file whole, or none of them (wavemesh.io.outputs)
        write_mesh(str(staged.path(out, (SIDECAR,), "mesh")), result.mesh, hf.values, comment=result.comment,
                   **opts)
        if folder is not None:
            # M = 1: the initial triangulation and the refined mesh are both level 0; the refined one is kept
            for level, m in dict(result.level_meshes).items():
                path = folder / f"level-{level}{out.suffix.lower()}"
                write_mesh(str(staged.path(path, (SIDECAR,), "--lod")), m, hf.values,
                           comment=f"{result.comment} level={level}", **opts)
                written.append(str(path))
        if files.normal_map:
            write_normal_map(staged.path(files.normal_map, what="normal map"), hf.values, g.spacing)
        if report:
            frame = ("grid positions (no georeference)" if not g.georeferenced
                     else "x, y the CRS's map coordinates" + (" less sample (0, 0)'s" if files.local else "")
                     if files.units == "crs" and out.suffix.lower() != ".glb"
                     else f"x east, y north, z up in {g.ground_unit}s from sample (0, 0)")
            data = result.report | {"output": str(out), "mesh_files": files.to_report() | {"frame": frame}}
            if written:
                data["lod"] = written
            staged.path(report, what="report").write_text(json.dumps(data, indent=2) + "\n")
        if render:
            render_picture(result.mesh, result.mesh.z(hf.values), str(staged.path(render, what="picture")), g,
                    exaggeration, title=title)
    if not g.georeferenced:  # grid coordinates: a sidecar an earlier run left would misplace them
        for path in (out, *written):
            sidecar_path(path).unlink(missing_ok=True)
    return written


def render_picture(mesh: Mesh, z, output: str, g, exaggeration: float | None, **kw) -> None:
    """A picture in true aspect: (east, north) in ground units; the exaggeration stated in it."""
    from wavemesh.check.render import render_mesh  # matplotlib is slow to import; only when asked

    check_exaggeration(exaggeration)
    if exaggeration is None and g.georeferenced:
        exaggeration = 1.0  # ground units: true aspect
    east, north = g.ground_xy(mesh.xy[:, 0], mesh.xy[:, 1])
    render_mesh(mesh, z, output, zscale=exaggeration, en=np.column_stack([east, north]), label=True, **kw)


def check_exaggeration(exaggeration: float | None, name: str = "--exaggeration") -> None:
    """A picture's vertical exaggeration: None (automatic) or a finite number > 0; checked before any
    work."""
    if exaggeration is not None and not (math.isfinite(exaggeration) and exaggeration > 0):
        raise InputError(f"{name} {exaggeration} is out of range", hint="give a number > 0")


def check_file(path: str, hf: HeightField, roi=None, min_area: float = 0.0) -> dict:
    """`wavemesh check`: whether the mesh file ``path`` is a proper triangulation of ``hf``'s grid whose
    vertices carry its heights, and its errors; the report's content (``valid``, ``problems``, ...).
    A mesh in map units is placed on the grid by its sidecar (PATH.georef.json), whose cell size the
    normal metric then uses; else by the height field's georeference.  ``roi`` (--roi's specs, or a bool
    array): also the errors over the region of interest alone (``roi_errors``; wavemesh.model.roi).
    ``min_area`` (with holes): the mesh was made with --min-area, whose dropped pieces may leave valid
    samples uncovered."""
    if roi is not None and hf.mask is not None:
        raise InputError("--roi and --nodata hole do not go together yet", hint="drop one of them")
    if min_area > 0 and hf.mask is None:
        raise InputError("--min-area checks a mesh with holes", hint="use it with --nodata hole")
    if roi is not None:
        roi = parse_roi(roi, hf.width, hf.height)
    placed = read_sidecar(path)
    g = placed[0] if placed else ground(hf)
    mesh, z = read_mesh(path, hf.width, hf.height, to_grid=to_grid(*placed) if placed else None)
    if (mesh.width, mesh.height) != (hf.width, hf.height):
        raise InputError(f"{path} is for a {mesh.width} x {mesh.height} grid but the height field "
                         f"is {hf.width} x {hf.height}")
    if hf.mask is not None:  # --nodata hole: a proper mesh of the valid samples (wavemesh.refine.cover)
        hc = check_holes(mesh, hf.mask, min_area)
        report = {"mesh": path, "valid": hc.valid_mesh, "problems": hc.problems, "vertices": mesh.n_vertices,
                  "triangles": mesh.n_triangles, "border_vertices": mesh.border_count(),
                  "holes": hc.to_report(), "ground": g.to_report()}
    else:
        verdict = check_mesh(mesh)
        report = {
            "mesh": path,
            "valid": verdict.valid,
            "problems": verdict.problems,
            "vertices": verdict.n_vertices,
            "triangles": verdict.n_triangles,
            "border_vertices": verdict.n_border,
            "euler_ok": verdict.euler_ok,
            "ground": g.to_report(),
        }
    if report["valid"]:
        want = mesh.z(hf.values)
        off = np.abs(z - want) > 1e-9 * np.maximum(1.0, np.abs(want))
        if np.any(off):
            i = int(np.argmax(off))
            report["valid"] = False
            report["problems"].append(f"{int(np.count_nonzero(off))} vertices do not carry the input height, "
                                      f"first at ({mesh.xy[i, 0]}, {mesh.xy[i, 1]}): {z[i]!r} != {want[i]!r}")
        else:
            report["errors"] = mesh_errors(mesh, hf.values, spacing=g.spacing).to_report()
            if roi is not None:
                report["roi_errors"] = roi_errors(mesh, hf.values, roi, spacing=g.spacing).to_report()
    return report


def check_port(url: str) -> None:
    """A port URL's TCP port, checked before any work: pyserial's own message for a bad one misleads
    (``socket://127.0.0.1:99999`` gives "'debug|info|warning|error'")."""
    m = re.match(r"(socket|rfc2217)://(\[[^]]*\]|[^:/?]*)(?::([^/?]*))?", url)
    if m is None:
        return
    port = m.group(3) or ""
    if not (port.isdigit() and 0 < int(port) < 65536):
        what = f"port {port!r} is not a TCP port number" if port else "no TCP port given"
        raise InputError(f"--port {url}: {what}",
                         hint=f"use {m.group(1)}://HOST:PORT, PORT in 1..65535 (e.g. {m.group(1)}://127.0.0.1:7721)")


def check_report(path: str, inputs: Inputs | list | None = None) -> Path:
    """A JSON report's path, checked before any work (not one of ``inputs``)."""
    return _check_output(path, (".json",), "report", inputs)


def write_json(path: str, data: dict, inputs: Inputs | list | None = None) -> None:
    """A JSON file (.json), not one of ``inputs``, or InputError."""
    _write_json(path, data, inputs)


def write_synth(name: str, output: str, size: int | None = None) -> Path:
    """`wavemesh synth`: one of the dissertation's synthetic sets into an .npy file."""
    out = _check_output(output, (".npy",), "height field")
    if size is not None and not 2 <= size <= 16384:
        raise WavemeshError(f"--size {size} is out of range", hint="use 2..16384")
    with Outputs() as staged:
        np.save(staged.path(out), make(name, size))
    return out


def render_file(mesh_path: str, output: str, *, view: str = "3d", wireframe: bool = True,
                zscale: float | None = None, title: str | None = None) -> None:
    """`wavemesh render`: a picture of a mesh file, in true aspect when its sidecar places it
    (``zscale``: the vertical exaggeration, stated in the picture)."""
    inputs = Inputs([mesh_path, sidecar_path(mesh_path)])
    _check_output(output, PICTURE_SUFFIXES, "picture", inputs)
    check_exaggeration(zscale, "vertical exaggeration")
    placed = read_sidecar(mesh_path)
    m, z = read_mesh(mesh_path, to_grid=to_grid(*placed) if placed else None)
    g = placed[0] if placed else grid_ground(m.width, m.height)
    with Outputs(inputs) as staged:
        render_picture(m, z, str(staged.path(output, what="picture")), g, zscale, view=view,
                       wireframe=wireframe, title=title)
