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
import math
import re
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import field, replace
from typing import TYPE_CHECKING

import numpy as np

from wavemesh import __version__, limits
from wavemesh.check import ErrorReport, HoleCheck, check_holes, check_mesh, mesh_errors
from wavemesh.errors import InputError, MeshInvalid, WavemeshError
from wavemesh.io.georef import (
    ground,
    read_sidecar,
    to_grid,
)
from wavemesh.io.heightfield import HeightField
from wavemesh.io.load import (
    AUTO_TILE,
    AUTO_TILE_SAMPLES,
    MESH_BYTES_PER_SAMPLE,
    READ_BYTES_PER_SAMPLE,
    RESIDENT_BYTES_PER_SAMPLE,
    TILE_BYTES_PER_SAMPLE,
    TILE_CHOICES,
    TileInstead,
    auto_tile,
    available_memory,
    check_hole_options,
    crop_window,
    default_workers,
    load_input,
    memory_available,
    memory_check,
    parse_crop,
    shape_heightfield,
)
from wavemesh.io.results import (
    PICTURE_SUFFIXES,
    MeshFiles,
    check_exaggeration,
    check_outputs,
    check_report,
    render_file,
    render_picture,
    write_json,
    write_result,
    write_synth,
)
from wavemesh.mesh import Mesh
from wavemesh.model.haar import WAVELETS, decompose, default_levels
from wavemesh.model.initial import InitialResult, assemble, initial_triangulation
from wavemesh.model.label import Labelling, tau_counts
from wavemesh.record import record
from wavemesh.refine import native
from wavemesh.refine.native import RefineOutput, RefineParams, fixed_params

__all__ = [  # the public API (io.load's and io.results' functions are offered here too)
    "AUTO_TILE", "AUTO_TILE_SAMPLES", "BOUND_EPS", "BOUND_NOT_MET", "BUG_HINT", "DEFAULT_TAU_FRACTION",
    "LevelMeshes", "MAX_LEVELS", "MESH_BYTES_PER_SAMPLE", "MeshFiles", "MeshJob", "MeshParams", "MeshResult",
    "PICTURE_SUFFIXES", "Progress", "READ_BYTES_PER_SAMPLE", "RESIDENT_BYTES_PER_SAMPLE", "RefineJob",
    "STAGE_NAMES", "StreamResult", "TILE_BYTES_PER_SAMPLE", "TILE_CHOICES", "TileInstead", "UNTILED_ONLY",
    "auto_tile", "available_memory", "bound_excess", "check_exaggeration", "check_file", "check_hole_options",
    "check_outputs", "check_port", "check_report", "crop_window", "default_levels", "default_tau",
    "default_workers", "device_fit_hint", "drop_holes", "level_counts", "level_report", "load_input",
    "memory_available", "memory_check", "mesh", "native_within", "parse_crop", "refine", "render_file",
    "render_picture", "require_proper", "shape_heightfield", "stream", "triangulate", "untiled_error",
    "untiled_options", "write_json",
    "write_result", "write_synth",
]

# Imported where used, for their start-up cost (tests/host/test_mesh_costs.py: `wavemesh mesh` does not
# load them): the device path (wavemesh.device: protocol, link, stream, about 16 ms), tqdm; pictures
# (wavemesh.check.render: matplotlib, about 270 ms) in wavemesh.io.results; and what a plain run does not
# call: the mesh reader (wavemesh.io.meshread: `check`, `render`), the ROI (wavemesh.model.roi: --roi) and
# the cover of holes (wavemesh.refine.cover: --nodata hole), with bisect under it (about 0.8 ms together).
if TYPE_CHECKING:
    from wavemesh.device.link import LinkStats
    from wavemesh.device.stream import Device, DeviceInfo, Timeouts

def _roi():
    """wavemesh.model.roi, imported on the first use (start-up: see the top)."""
    from wavemesh.model import roi  # start-up: only with an ROI (see the top)

    return roi


MAX_LEVELS = limits.MAX_LEVELS  # the model's limit (wavemesh.limits: the refiner's header, the one statement)
DEFAULT_TAU_FRACTION = 0.01  # default tau_M: this fraction of the height range (docs/model.md)
BOUND_NOT_MET = 3  # exit status of `wavemesh mesh` when the triangle budget stopped it above zeta


def default_tau(hf: HeightField) -> float:
    lo, hi = hf.extremes
    return DEFAULT_TAU_FRACTION * (hi - lo)


@record(frozen=True)
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


@record
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
                    else _roi().roi_errors(rjob.mesh, quantised, rjob.roi, spacing=sp), metric)
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
        details = _roi().mask_details(decompose(hf.samples, job.levels, job.wavelet), roi)
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
        rjob.roi_errors = _roi().roi_errors(rjob.mesh, hf.values, roi, rms=rms, spacing=spacing)
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
    from wavemesh.refine import cover  # start-up: only with holes (see the top)

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


@record(frozen=True)
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


# The options a tiled run does not do, and why: the one list.  A tiled run (--tile N, --tiles-dir,
# --scheduler, `stream`'s tiles; tiles.plan_tiles for the parameters it has) refuses each with one error
# line; the default meshes a large grid whole when the job has one (cli; docs/usage.md, "Threads and
# tiles", which points at `wavemesh mesh --help`: --tile's help lists them from here).
UNTILED_ONLY = {
    "--lod": "every level's mesh is one of the whole grid",
    "--check-levels": "each tile's levels are its own",
    "--roi": "it needs the whole grid at once",
    "--nodata hole": "it needs the whole grid at once (so do --max-hole and --min-area, which go with it)",
    "--invalid": "it needs the whole grid at once",
    "--denoise": "it needs the whole grid at once",
    "--normal-map": "it needs the whole grid at once",
    "--stage initial": "the tiles' shared sides are decided by the refiner",
    "--bound off": "the tiles' shared sides are decided within zeta",
    "--max-triangles": "a budget is the job's, not a tile's",
    "--capacity": "the refiner's storage is sized for each tile's grid",
}


def untiled_options(params: MeshParams, *, check_levels: bool | None = None, lod=None, nodata=None,
                    invalid=None, denoise=None, normal_map=None) -> list[str]:
    """The options of UNTILED_ONLY the job has, in its order: from ``params`` (``check_levels``: instead of
    params.check_levels, which --report sets too) and from the other options' values as the command has
    them (None: not given)."""
    p = params.refine
    has = {"--lod": lod, "--check-levels": params.check_levels if check_levels is None else check_levels,
           "--roi": params.roi is not None, "--nodata hole": nodata == "hole",
           "--invalid": invalid is not None, "--denoise": denoise, "--normal-map": normal_map,
           "--stage initial": params.initial_only, "--bound off": not p.bound,
           "--max-triangles": p.max_triangles is not None, "--capacity": p.capacity is not None}
    return [option for option in UNTILED_ONLY if has[option]]


def untiled_error(option: str) -> WavemeshError:
    """The error a tiled run gives for an option of UNTILED_ONLY."""
    return WavemeshError(f"{option} is not done in tiles: {UNTILED_ONLY[option]}",
                         hint=f"leave out {option}, or mesh the grid whole (--tile off)")


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


@record(kw_only=True)
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


@record(kw_only=True)
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
        roi = _roi().parse_roi(params.roi, hf.width, hf.height)
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
        report["roi"] = _roi().roi_report(rjob.mesh, roi, rjob.roi_errors, rjob.errors, p.metric)
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
        if enabled:
            from tqdm import tqdm  # only when a bar or its line is drawn (its import: about 20 ms of CPU)
        else:
            tqdm = None
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
        # the templates' triangulation, as mesh()'s report (DONE states it: the first level sent is the
        # refiner's level M-1, reduced)
        "initial": {"levels": m, "block_size": 1 << m, "tau_counts": tau_q,
                    "vertices": done["initial_vertices"], "triangles": done["initial_triangles"]},
        "errors": errors.to_report(),
        "device": info.to_report(),
        "device_cycles": cycles | {"seconds": {k: v / clk for k, v in cycles.items()}},
        # the stack's reserve and high-water mark after the job (DONE; 0, 0: the device does not measure it)
        "device_stack": {"bytes": done["stack_bytes"], "peak": done["stack_peak"]},
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
    if link_baud == "auto":
        rate = info.auto_rate
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
        roi = _roi().parse_roi(roi, hf.width, hf.height)
    from wavemesh.io.meshread import read_mesh  # start-up: only `check` reads a mesh (see the top)

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
                report["roi_errors"] = _roi().roi_errors(mesh, hf.values, roi, spacing=g.spacing).to_report()
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


