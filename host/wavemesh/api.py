"""What the ``wavemesh`` commands do, as functions scripts can call."""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from wavemesh import __version__
from wavemesh.check import ErrorReport, check_mesh, mesh_errors
from wavemesh.errors import InputError, MeshInvalid, WavemeshError
from wavemesh.haar import decompose
from wavemesh.heightfield import HeightField, from_array, load_heightfield, parse_fill
from wavemesh.initial import InitialResult, initial_triangulation
from wavemesh.label import tau_counts
from wavemesh.mesh import Mesh
from wavemesh.meshio import read_mesh, write_mesh
from wavemesh.native import RefineOutput, RefineParams

MAX_LEVELS = 12  # the model's limit (16-bit approximations, 18-bit details at every level)
DEFAULT_TAU_FRACTION = 0.01  # default tau_M: this fraction of the height range (docs/model.md)
MESH_SUFFIXES = (".obj", ".ply")
BOUND_NOT_MET = 3  # exit status of `wavemesh mesh` when the triangle budget stopped it above zeta


def default_levels(width: int, height: int) -> int:
    """log2(max(W, H)) - 3 within 1..8: about 8 blocks across, as the paper's 128/M=4, 256/M=5, 512/M=6."""
    return min(8, max(1, int(math.floor(math.log2(max(width, height)))) - 3))


def default_tau(hf: HeightField) -> float:
    return DEFAULT_TAU_FRACTION * float(np.max(hf.values) - np.min(hf.values))


@dataclass(frozen=True)
class MeshJob:
    heightfield: HeightField
    levels: int
    tau: float
    result: InitialResult

    @property
    def mesh(self) -> Mesh:
        return self.result.mesh


def triangulate(hf: HeightField, levels: int | None = None, tau: float | None = None) -> MeshJob:
    """The initial triangulation of a height field (filter bank, labeller, templates)."""
    m = default_levels(hf.width, hf.height) if levels is None else levels
    if not 1 <= m <= MAX_LEVELS:
        raise WavemeshError(f"--levels {m} is out of range", hint=f"use 1..{MAX_LEVELS}")
    t = default_tau(hf) if tau is None else tau
    if not math.isfinite(t) or t < 0:
        raise WavemeshError(f"--tau {t} is not a finite number >= 0", hint="give tau in height units")
    result = initial_triangulation(hf.samples, m, tau_counts(t, hf.scale))
    require_proper(result.mesh, "the initial triangulation")  # the templates guarantee it: else a bug
    return MeshJob(hf, m, t, result)


def _check_output(path: str, suffixes: tuple[str, ...], what: str) -> Path:
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise InputError(f"cannot write {what} {path}: unknown extension '{p.suffix}'",
                         hint="use " + " or ".join(suffixes))
    if not p.parent.exists():
        raise InputError(f"cannot write {path}: directory {p.parent} does not exist")
    return p


def _write_json(path: str, data: dict) -> None:
    p = _check_output(path, (".json",), "report")
    try:
        p.write_text(json.dumps(data, indent=2) + "\n")
    except OSError as e:
        raise InputError(f"cannot write {path}: {e.strerror}") from e


def _load(path: str, key: str | None, fill: str | None) -> HeightField:
    return load_heightfield(path, key=key, fill=parse_fill(fill) if fill is not None else None)


def parse_crop(text: str) -> tuple[int, int, int, int]:
    """--crop X,Y,W,H: the top-left sample (column, row) and the size in samples."""
    try:
        x, y, w, h = (int(v) for v in text.replace(":", ",").split(","))
    except ValueError:
        raise InputError(f"--crop {text}: not four integers",
                         hint="give --crop X,Y,W,H, e.g. 0,0,256,256") from None
    return x, y, w, h


def shape_heightfield(hf: HeightField, crop: str | None = None, decimate: int | None = None) -> HeightField:
    """The part of a height field --crop and --decimate select, quantised afresh (as if it were the file)."""
    if crop is None and decimate in (None, 1):
        return hf
    v, what = hf.values, []
    if crop is not None:
        x, y, w, h = parse_crop(crop)
        if x < 0 or y < 0 or w < 2 or h < 2 or x + w > hf.width or y + h > hf.height:
            raise InputError(f"--crop {crop} does not fit the {hf.width} x {hf.height} input",
                             hint="X + W <= width, Y + H <= height, W and H at least 2")
        v = v[y:y + h, x:x + w]
        what.append(f"crop {x},{y},{w},{h}")
    if decimate is not None:
        if decimate < 1:
            raise InputError(f"--decimate {decimate} is out of range", hint="use 1 or more")
        v = v[::decimate, ::decimate]
        if min(v.shape) < 2:
            raise InputError(f"--decimate {decimate} leaves {v.shape[1]} x {v.shape[0]} samples",
                             hint="a height field needs at least 2 x 2")
        what.append(f"decimate {decimate}")
    out = from_array(np.ascontiguousarray(v), source=f"{hf.source} ({', '.join(what)})")
    return replace(out, filled=hf.filled)


def _load_input(args) -> HeightField:
    hf = _load(args.input, args.key, args.fill)
    return shape_heightfield(hf, getattr(args, "crop", None), getattr(args, "decimate", None))


@dataclass
class RefineJob:
    """The full pipeline: the initial triangulation, then the firmware refiner (docs/refiner.md)."""

    initial: MeshJob
    params: RefineParams
    zeta_used: float  # zeta given to the refiner (less 2 x the quantisation error for lossy input)
    output: RefineOutput
    seconds: float  # time spent in the refiner
    errors: ErrorReport | None = None  # the final mesh's errors against the input (check.mesh_errors)

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
    given on the 16-bit samples it saw.  The float metric's own rounding is allowed (1e-9 relative)."""
    if not rjob.bound_met:
        return None
    p = rjob.params
    eps = BOUND_EPS * max(1.0, p.zeta)
    metric = "e_max_normal" if p.metric == "normal" else "e_max_vertical"
    if hf.lossless or (p.metric == "vertical" and p.zeta >= 2 * hf.max_quantisation_error):
        e, zeta, on = getattr(errors, metric), p.zeta, "the input"
    else:
        quantised = hf.offset + hf.scale * hf.samples.astype(np.float64)
        e, zeta, on = getattr(mesh_errors(rjob.mesh, quantised), metric), rjob.zeta_used, "the 16-bit samples"
    if e <= zeta + eps:
        return None
    return (f"the refined mesh is not within zeta: E_max {p.metric} {e:.9g} > zeta {zeta:g} on {on}, though "
            f"the refiner reported every triangle within it")


def refine(hf: HeightField, levels: int | None = None, tau: float | None = None,
           params: RefineParams | None = None, *, check_levels: bool = False, rms: bool = False) -> RefineJob:
    """Filter bank, templates, then the native refiner down to level 0 with E(T) <= zeta.

    The final mesh is always checked: a proper triangulation (check_mesh) and, when the refiner reports
    the bound met, within zeta (mesh_errors, kept in ``errors``: its maxima, and its RMS when ``rms``);
    otherwise MeshInvalid.  ``check_levels`` also checks every coarser level's mesh."""
    from wavemesh import native  # loads (and if needed builds) the C library

    params = params or RefineParams()
    params.check()
    job = triangulate(hf, levels, tau)
    # The refiner sees the 16-bit samples.  For lossy quantisation a sample is off the input by at
    # most q, a plane through three samples by at most q too: zeta - 2q on the samples keeps the
    # vertical bound on the input values (docs/refiner.md, "Quantised input").
    q = hf.max_quantisation_error
    zeta = max(0.0, params.zeta - 2 * q) if q > 0 else params.zeta
    start = time.perf_counter()
    out = native.refine(hf.samples, decompose(hf.samples, job.levels), job.mesh, params, scale=hf.scale,
                        zeta=zeta)
    seconds = time.perf_counter() - start
    # The operators keep the mesh proper and within zeta: a failure here is a bug.
    for lv in out.levels if check_levels else out.levels[-1:]:
        require_proper(lv.mesh, f"the refiner's mesh at level {lv.level}")
    rjob = RefineJob(job, params, zeta, out, seconds)
    rjob.errors = mesh_errors(rjob.mesh, hf.values, rms=rms)
    excess = bound_excess(hf, rjob, rjob.errors)
    if excess:
        raise MeshInvalid(excess, hint=BUG_HINT)
    return rjob


def level_report(lv, hf: HeightField, metric: str, errors: ErrorReport | None = None) -> dict:
    """One level's row: counts, the firmware's E_max and the independent float E_max (``errors``: the
    level's mesh_errors when already measured)."""
    errors = errors if errors is not None else mesh_errors(lv.mesh, hf.values, rms=False)  # maxima
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


def _params_from_args(args) -> RefineParams:
    return RefineParams(zeta=args.zeta, metric=args.metric, delta_d=args.delta_d, delta_p=args.delta_p,
                        delta_v=args.delta_v, alpha=args.alpha, delta_lambda=args.delta_lambda,
                        delta_c=args.delta_c, iterations=args.iterations, neighbourhood=args.neighbourhood,
                        max_triangles=args.max_triangles, capacity=args.capacity,
                        bound=getattr(args, "bound", "on") == "on",
                        reduce=getattr(args, "reduce", "on") == "on",
                        decimate=getattr(args, "simplify", "on") == "on")


def _check_mesh_outputs(args) -> tuple[Path, Path | None]:
    """The output paths of `mesh` and `stream`, checked before any work: (mesh file, --lod folder)."""
    out = _check_output(args.output, MESH_SUFFIXES, "mesh")
    if args.render:
        _check_output(args.render, (".png", ".svg", ".pdf"), "picture")
    if args.report:
        _check_output(args.report, (".json",), "report")
    lod = None
    if getattr(args, "lod", None):
        lod = Path(args.lod)
        if lod.exists() and not lod.is_dir():
            raise InputError(f"--lod {args.lod} is not a directory")
        if not lod.parent.exists():
            raise InputError(f"cannot write --lod {args.lod}: directory {lod.parent} does not exist")
    return out, lod



def _write_outputs(args, hf: HeightField, mesh: Mesh, report: dict | None, written) -> None:
    """The report and the picture of `mesh` and `stream` (the meshes are written by the caller)."""
    if args.report:
        if written:
            report["lod"] = written
        _write_json(args.report, report)
    if args.render:
        from wavemesh.render import render_mesh  # matplotlib is slow to import; only when asked

        render_mesh(mesh, mesh.z(hf.values), args.render, title=Path(args.input).name)


def _print_summary(args, hf: HeightField, mesh: Mesh, levels: int, tau: float, errors) -> None:
    print(f"{args.input}: {hf.width} x {hf.height}, M={levels}, tau={tau:g}: "
          f"{mesh.n_vertices} vertices, {mesh.n_triangles} triangles, "
          f"E_max normal {errors.e_max_normal:.6g}, vertical {errors.e_max_vertical:.6g}")

def measures_levels(args) -> bool:
    """Whether `mesh` checks and measures every level: only when asked, by --report, --lod or
    --check-levels (the final mesh is always checked and measured)."""
    return bool(args.report or getattr(args, "lod", None) or getattr(args, "check_levels", False))


def mesh_command(args) -> int:
    out, lod = _check_mesh_outputs(args)
    stage = getattr(args, "stage", "initial")
    params = _params_from_args(args) if stage == "full" else None
    if params is not None:
        params.check()
    hf = _load_input(args)
    measure = measures_levels(args)
    if stage == "full":
        rjob = refine(hf, args.levels, args.tau, params, check_levels=measure, rms=bool(args.report))
        job, mesh, errors = rjob.initial, rjob.mesh, rjob.errors
        comment = (f"wavemesh {__version__} refined mesh, M={job.levels} tau={job.tau:g} "
                   f"zeta={params.zeta:g} "
                   f"metric={params.metric}")
        final = rjob.output.final
        if measure:
            levels = [level_report(lv, hf, params.metric, errors if lv is final else None)
                      for lv in rjob.output.levels]
        else:
            levels = [level_counts(lv, hf) for lv in rjob.output.levels]
    else:
        rjob, job = None, triangulate(hf, args.levels, args.tau)  # triangulate checks the mesh
        mesh = job.mesh
        errors = mesh_errors(mesh, hf.values, rms=bool(args.report))  # the RMS only for the report
        comment = f"wavemesh {__version__} initial triangulation, M={job.levels} tau={job.tau:g}"
        levels = []
    write_mesh(str(out), mesh, hf.values, comment=comment)
    written = []
    if lod is not None:
        lod.mkdir(exist_ok=True)
        meshes = [(lv.level, lv.mesh) for lv in rjob.output.levels] if rjob else [(job.levels - 1, job.mesh)]
        for level, m in meshes:
            path = lod / f"level-{level}{out.suffix.lower()}"
            write_mesh(str(path), m, hf.values, comment=f"{comment} level={level}")
            written.append(str(path))
    report = None
    if args.report:
        parameters = {"levels": job.levels, "tau": job.tau, "stage": stage}
        report = {
            "wavemesh": __version__,
            "input": hf.to_report(),
            "parameters": parameters,
            "initial": job.result.to_report(),
            "errors": errors.to_report(),
            "output": str(out),
        }
        if rjob is not None:
            parameters.update(rjob.params.to_report())
            parameters["zeta_refiner"] = rjob.zeta_used
            report["refiner"] = {
                "levels": levels,
                "bound_met": rjob.bound_met,
                "seconds": rjob.seconds,
                "capacity": rjob.output.capacity,
                "fixed_point": {name: int(getattr(rjob.output.params, name)) for name,
                                _ in rjob.output.params._fields_},
            }
    _write_outputs(args, hf, mesh, report, written)
    e_final = None
    if rjob is not None:
        e_final = errors.e_max_normal if params.metric == "normal" else errors.e_max_vertical
    if not args.quiet:
        _print_summary(args, hf, mesh, job.levels, job.tau, errors)
        if rjob is not None:
            print(f"  refiner: zeta {params.zeta:g} ({params.metric}), k={params.iterations}, "
                  f"{params.neighbourhood}-based, {rjob.seconds:.3f} s")
            # Unmeasured levels show the refiner's own E_max (never below the exact value).
            print(f"  level  vertices  triangles  {'E_max' if measure else 'E_max(ref)':>10}  splits  swaps")
            for row in levels:
                print(f"  {row['level']:>5}  {row['vertices']:>8}  {row['triangles']:>9}  "
                      f"{row['e_max'] if measure else row['e_max_firmware']:>10.4g}  "
                      f"{row['splits']:>6}  {row['swaps']:>5}")
        print(f"wrote {out}" + "".join(f", {p}" for p in (args.report, args.render) if p)
              + (f", {len(written)} levels in {args.lod}" if written else ""))
    if rjob is not None and params.bound and not rjob.bound_met:
        print(f"warning: the error bound is not met: E_max {e_final:.6g} > zeta {params.zeta:g} "
              f"({levels[-1]['over_zeta']} triangles over) at the triangle budget (--max-triangles "
              f"{params.max_triangles})", file=sys.stderr)
        return BOUND_NOT_MET
    return 0


def check_command(args) -> int:
    hf = shape_heightfield(_load(args.against, args.key, args.fill), getattr(args, "crop", None),
                           getattr(args, "decimate", None))
    mesh, z = read_mesh(args.mesh, hf.width, hf.height)
    if (mesh.width, mesh.height) != (hf.width, hf.height):
        raise InputError(f"{args.mesh} is for a {mesh.width} x {mesh.height} grid but {args.against} "
                         f"is {hf.width} x {hf.height}")
    verdict = check_mesh(mesh)
    report = {
        "mesh": args.mesh,
        "against": args.against,
        "valid": verdict.valid,
        "problems": verdict.problems,
        "vertices": verdict.n_vertices,
        "triangles": verdict.n_triangles,
        "border_vertices": verdict.n_border,
        "euler_ok": verdict.euler_ok,
    }
    if verdict.valid:
        want = mesh.z(hf.values)
        off = np.abs(z - want) > 1e-9 * np.maximum(1.0, np.abs(want))
        if np.any(off):
            i = int(np.argmax(off))
            report["valid"] = False
            report["problems"].append(f"{int(np.count_nonzero(off))} vertices do not carry the input height, "
                                      f"first at ({mesh.xy[i, 0]}, {mesh.xy[i, 1]}): {z[i]!r} != {want[i]!r}")
        else:
            report["errors"] = mesh_errors(mesh, hf.values).to_report()
    if args.report:
        _write_json(args.report, report)
    if not args.quiet:
        state = "a proper triangulation" if report["valid"] else "NOT a proper triangulation"
        print(f"{args.mesh}: {mesh.n_vertices} vertices, {mesh.n_triangles} triangles, "
              f"{hf.width} x {hf.height} grid: {state}")
        for problem in report["problems"][:20]:
            print(f"  {problem}")
        if "errors" in report:
            e = report["errors"]
            print(f"  E_max normal {e['e_max_normal']:.6g}, vertical {e['e_max_vertical']:.6g}; "
                  f"RMS normal {e['rms_normal']:.6g}, vertical {e['rms_vertical']:.6g}")
    if not report["valid"]:
        raise MeshInvalid(f"{args.mesh} is not a proper triangulation of the {hf.width} x {hf.height} grid"
                          + (f": {report['problems'][0]}" if report["problems"] else ""))
    return 0


def render_command(args) -> int:
    _check_output(args.output, (".png", ".svg", ".pdf"), "picture")
    mesh, z = read_mesh(args.mesh)
    from wavemesh.render import render_mesh

    render_mesh(mesh, z, args.output, view=args.view, wireframe=not args.no_wireframe,
                zscale=args.zscale, title=args.title)
    print(f"wrote {args.output}")
    return 0


def synth_command(args) -> int:
    from wavemesh.synth import make

    out = _check_output(args.output, (".npy",), "height field")
    if args.size is not None and not 2 <= args.size <= 16384:
        raise WavemeshError(f"--size {args.size} is out of range", hint="use 2..16384")
    np.save(out, make(args.name, args.size))
    print(f"wrote {out}")
    return 0


def _fits(hf: HeightField, info) -> str | None:
    """None when the device holds the height field, else a hint: the --decimate that makes it fit."""
    w, h = hf.width, hf.height
    if w <= info.max_width and h <= info.max_height and w * h <= info.max_samples:
        return None
    for n in range(2, 1 + max(w, h)):
        dw, dh = -(-w // n), -(-h // n)
        if dw <= info.max_width and dh <= info.max_height and dw * dh <= info.max_samples:
            return (f"--decimate {n} makes it {dw} x {dh}; or --crop X,Y,W,H with W <= {info.max_width}, "
                    f"H <= {info.max_height}")
    return "crop it with --crop X,Y,W,H"


STAGE_NAMES = {0: "receiving", 1: "filter bank", 2: "templates", 3: "refining", 4: "sending", 5: "done"}


def stream_command(args) -> int:
    """`wavemesh stream`: the job on a device over the wire protocol; the outputs of `wavemesh mesh`."""
    from wavemesh import protocol as P
    from wavemesh import stream as S
    from wavemesh.native import fixed_params

    out, lod = _check_mesh_outputs(args)
    full = args.stage == "full"
    params = _params_from_args(args)
    params.check()
    if not 0 <= params.delta_c <= 1:
        raise WavemeshError(f"--delta-c {params.delta_c} is out of range", hint="use 0 <= delta_c <= 1")
    if args.timeout is not None and not args.timeout > 0:
        raise WavemeshError(f"--timeout {args.timeout} is out of range", hint="give seconds > 0")
    hf = _load_input(args)
    m = default_levels(hf.width, hf.height) if args.levels is None else args.levels
    if not 1 <= m <= MAX_LEVELS:
        raise WavemeshError(f"--levels {m} is out of range", hint=f"use 1..{MAX_LEVELS}")
    tau = default_tau(hf) if args.tau is None else args.tau
    if not math.isfinite(tau) or tau < 0:
        raise WavemeshError(f"--tau {tau} is not a finite number >= 0", hint="give tau in height units")
    tau_q = tau_counts(tau, hf.scale)
    q = hf.max_quantisation_error  # as refine(): zeta - 2q on the samples for lossy quantisation
    zeta = max(0.0, params.zeta - 2 * q) if q > 0 else params.zeta
    timeouts = S.DEFAULT_TIMEOUTS if args.timeout is None else replace(S.DEFAULT_TIMEOUTS, job=args.timeout)

    def say(text: str) -> None:
        if not args.quiet:
            print(text, flush=True)

    with S.Device(args.port, args.baud, trace=sys.stderr if args.trace else None, timeouts=timeouts) as dev:
        info = dev.sync()
        say(f"device: {info.summary()}")
        hint = _fits(hf, info)
        if hint:
            raise S.DeviceError(f"{args.input} is {hf.width} x {hf.height} samples; the device holds at most "
                                f"{info.max_width} x {info.max_height} ({info.max_samples} samples)", hint)
        if m > info.max_levels:
            raise S.DeviceError(f"--levels {m}: the device makes at most {info.max_levels}",
                                hint=f"use --levels {info.max_levels} or fewer")
        if not full and not info.features & P.FEATURE_INITIAL_ONLY:
            raise S.DeviceError("the device cannot stop after the template stage", hint="use --stage full")
        storage = params.capacity or info.tri_capacity
        if storage > info.tri_capacity:
            raise S.DeviceError(f"--capacity {storage}: the device has storage for {info.tri_capacity} "
                                "triangles",
                                hint=f"use --capacity {info.tri_capacity} or less")
        budget_note = ""
        if params.max_triangles is None:
            params = replace(params, max_triangles=storage - 1)
            budget_note = " (the device's capacity less one)"
        elif params.max_triangles >= storage:
            raise S.DeviceError(f"--max-triangles {params.max_triangles}: the device honours a budget of "
                                f"at most {storage - 1} (storage for {storage} triangles)",
                                hint=f"use --max-triangles {storage - 1} or less")
        fp = fixed_params(params, hf.scale, zeta)
        dev.configure(S.config_payload(hf.width, hf.height, m, tau_q, fp, capacity=params.capacity or 0,
                                       initial_only=not full, delta_lambda=params.delta_lambda,
                                       delta_c=params.delta_c))
        if full:
            say(f"job: {hf.width} x {hf.height}, M={m}, tau={tau:g}, zeta {params.zeta:g} ({params.metric}), "
                f"budget {params.max_triangles} triangles{budget_note}")
        kib = 2 * hf.width * hf.height / 1024
        bar = S.Bar("heights", hf.width * hf.height, enabled=not args.quiet)
        t0 = time.monotonic()
        sent = dev.upload(hf.samples, bar)
        upload_s = time.monotonic() - t0
        bar.finish(f"{kib:.1f} KiB in {upload_s:.2f} s ({kib / max(upload_s, 1e-9):.1f} KiB/s)")
        work = S.Bar("device", m if full else 1, enabled=not args.quiet)
        got: list = []

        def on_progress(x: dict) -> None:
            name = STAGE_NAMES.get(x["stage"], "?")
            lvl = f" level {x['level']}" if x["stage"] in (P.Stage.REFINE, P.Stage.EMIT) else ""
            work.update(len(got), f"{name}{lvl}")

        def on_level(lv) -> None:
            got.append(lv)
            work.update(len(got), f"level {lv.level}: {lv.mesh.n_triangles} triangles")

        t1 = time.monotonic()
        levels, done = dev.run(S.samples_crc(hf.samples), hf.width, hf.height, on_level, on_progress)
        job_s = time.monotonic() - t1
        work.finish(f"{len(levels)} level{'s' if len(levels) != 1 else ''} in {job_s:.2f} s")
        link = dev.link.stats

    for lv in levels:
        verdict = check_mesh(lv.mesh)
        if not verdict.valid:
            raise S.ProtocolError(f"the device's level {lv.level} is not a proper triangulation: "
                                  + "; ".join(verdict.problems[:3]))
    final = levels[-1]
    mesh = final.mesh
    if full:
        comment = (f"wavemesh {__version__} refined mesh, M={m} tau={tau:g} zeta={params.zeta:g} "
                   f"metric={params.metric}")
        rows = [level_report(lv, hf, params.metric) | {"device_cycles": lv.cycles, "stream_bytes": lv.nbytes,
                                                        "arrived_s": lv.seconds} for lv in levels]
    else:
        comment = f"wavemesh {__version__} initial triangulation, M={m} tau={tau:g}"
        rows = []
    write_mesh(str(out), mesh, hf.values, comment=comment)
    written = []
    if lod is not None:
        lod.mkdir(exist_ok=True)
        for lv in levels:
            path = lod / f"level-{lv.level}{out.suffix.lower()}"
            write_mesh(str(path), lv.mesh, hf.values, comment=f"{comment} level={lv.level}")
            written.append(str(path))
    errors = mesh_errors(mesh, hf.values)
    clk = info.clk_hz
    cycles = {f.name[len("cycles_"):]: done[f.name] for f in P.DONE.fields if f.name.startswith("cycles_")}
    mesh_bytes = sum(lv.nbytes for lv in levels)
    parameters = {"levels": m, "tau": tau, "stage": args.stage}
    report = {
        "wavemesh": __version__,
        "input": hf.to_report(),
        "parameters": parameters,
        "initial": {"levels": m, "block_size": 1 << m, "tau_counts": tau_q,
                    "vertices": levels[0].mesh.n_vertices, "triangles": levels[0].mesh.n_triangles},
        "errors": errors.to_report(),
        "output": str(out),
        "device": info.to_report(),
        "device_cycles": cycles | {"seconds": {k: v / clk for k, v in cycles.items()}},
        "transfer": {"port": args.port, "baud": args.baud, "height_bytes": 2 * hf.width * hf.height,
                     "bytes_sent": sent, "upload_seconds": upload_s, "mesh_bytes": mesh_bytes,
                     "job_seconds": job_s, "frames_out": link.frames_out, "frames_in": link.frames_in,
                     "bytes_out": link.bytes_out, "bytes_in": link.bytes_in, "damaged_frames": link.damaged},
    }
    if full:
        parameters.update(params.to_report())
        parameters["zeta_refiner"] = zeta
        report["refiner"] = {
            "levels": rows,
            "bound_met": final.stats["over"] == 0,
            "seconds": cycles["refine"] / clk,
            "capacity": storage,
            "fixed_point": {name: int(getattr(fp, name)) for name, _ in fp._fields_},
        }
    _write_outputs(args, hf, mesh, report, written)
    if not args.quiet:
        _print_summary(args, hf, mesh, m, tau, errors)
        if full:
            print("  level  vertices  triangles       E_max  splits  swaps   device ms")
            for row in rows:
                print(f"  {row['level']:>5}  {row['vertices']:>8}  {row['triangles']:>9}  "
                      f"{row['e_max']:>10.4g}  {row['splits']:>6}  {row['swaps']:>5}  "
                      f"{1000 * row['device_cycles'] / clk:>10.2f}")
        print("  device: " + ", ".join(f"{k} {1000 * v / clk:.2f} ms" for k, v in cycles.items())
              + f"; link: {link.frames_out} frames out, {link.frames_in} in, {link.damaged} damaged")
        print(f"wrote {out}" + "".join(f", {p}" for p in (args.report, args.render) if p)
              + (f", {len(written)} levels in {args.lod}" if written else ""))
    if full and params.bound and final.stats["over"] != 0:
        print(f"warning: the error bound is not met: E_max {rows[-1]['e_max']:.6g} > zeta {params.zeta:g} "
              f"({final.stats['over']} triangles over) at the triangle budget (--max-triangles "
              f"{params.max_triangles})", file=sys.stderr)
        return BOUND_NOT_MET
    return 0


COMMANDS = {"mesh": mesh_command, "stream": stream_command, "check": check_command, "render": render_command,
            "synth": synth_command}


def run(args) -> int:
    return COMMANDS[args.command](args)
