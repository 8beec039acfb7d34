"""What the ``wavemesh`` commands do, as functions scripts can call."""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wavemesh import __version__
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.errors import InputError, MeshInvalid, WavemeshError
from wavemesh.haar import decompose
from wavemesh.heightfield import HeightField, load_heightfield, parse_fill
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
    verdict = check_mesh(result.mesh)
    if not verdict.valid:  # the templates guarantee validity: this is a bug, not a user error
        raise AssertionError("initial triangulation is not proper: " + "; ".join(verdict.problems[:3]))
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


@dataclass
class RefineJob:
    """The full pipeline: the initial triangulation, then the firmware refiner (docs/refiner.md)."""

    initial: MeshJob
    params: RefineParams
    zeta_used: float  # zeta given to the refiner (less 2 x the quantisation error for lossy input)
    output: RefineOutput
    seconds: float  # time spent in the refiner

    @property
    def mesh(self) -> Mesh:
        return self.output.final.mesh

    @property
    def bound_met(self) -> bool:
        return self.output.final.stats["over"] == 0


def refine(hf: HeightField, levels: int | None = None, tau: float | None = None,
           params: RefineParams | None = None) -> RefineJob:
    """Filter bank, templates, then the native refiner down to level 0 with E(T) <= zeta."""
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
    for lv in out.levels:
        verdict = check_mesh(lv.mesh)
        if not verdict.valid:  # the operators keep the mesh proper: a failure here is a bug
            raise AssertionError(f"refined mesh at level {lv.level} is not proper: "
                                 + "; ".join(verdict.problems[:3]))
    return RefineJob(job, params, zeta, out, seconds)


def level_report(lv, hf: HeightField, metric: str) -> dict:
    """One level's row: counts, the firmware's E_max and the independent float E_max."""
    errors = mesh_errors(lv.mesh, hf.values)
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


def _params_from_args(args) -> RefineParams:
    return RefineParams(zeta=args.zeta, metric=args.metric, delta_d=args.delta_d, delta_p=args.delta_p,
                        delta_v=args.delta_v, alpha=args.alpha, delta_lambda=args.delta_lambda,
                        delta_c=args.delta_c, iterations=args.iterations, neighbourhood=args.neighbourhood,
                        max_triangles=args.max_triangles, capacity=args.capacity)


def mesh_command(args) -> int:
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
    stage = getattr(args, "stage", "initial")
    params = _params_from_args(args) if stage == "full" else None
    if params is not None:
        params.check()
    hf = _load(args.input, args.key, args.fill)
    if stage == "full":
        rjob = refine(hf, args.levels, args.tau, params)
        job, mesh = rjob.initial, rjob.mesh
        comment = (f"wavemesh {__version__} refined mesh, M={job.levels} tau={job.tau:g} "
                   f"zeta={params.zeta:g} "
                   f"metric={params.metric}")
        levels = [level_report(lv, hf, params.metric) for lv in rjob.output.levels]
    else:
        rjob, job = None, triangulate(hf, args.levels, args.tau)
        mesh = job.mesh
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
    errors = mesh_errors(mesh, hf.values)
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
    if written:
        report["lod"] = written
    if args.report:
        _write_json(args.report, report)
    if args.render:
        from wavemesh.render import render_mesh  # matplotlib is slow to import; only when asked

        render_mesh(mesh, mesh.z(hf.values), args.render, title=Path(args.input).name)
    if not args.quiet:
        print(f"{args.input}: {hf.width} x {hf.height}, M={job.levels}, tau={job.tau:g}: "
              f"{mesh.n_vertices} vertices, {mesh.n_triangles} triangles, "
              f"E_max normal {errors.e_max_normal:.6g}, vertical {errors.e_max_vertical:.6g}")
        if rjob is not None:
            print(f"  refiner: zeta {params.zeta:g} ({params.metric}), k={params.iterations}, "
                  f"{params.neighbourhood}-based, {rjob.seconds:.3f} s")
            print("  level  vertices  triangles       E_max  splits  swaps")
            for row in levels:
                print(f"  {row['level']:>5}  {row['vertices']:>8}  {row['triangles']:>9}  "
                      f"{row['e_max']:>10.4g}  "
                      f"{row['splits']:>6}  {row['swaps']:>5}")
        print(f"wrote {out}" + "".join(f", {p}" for p in (args.report, args.render) if p)
              + (f", {len(written)} levels in {args.lod}" if written else ""))
    if rjob is not None and not rjob.bound_met:
        final = levels[-1]
        print(f"warning: the error bound is not met: E_max {final['e_max']:.6g} > zeta {params.zeta:g} "
              f"({final['over_zeta']} triangles over) at the triangle budget (--max-triangles "
              f"{params.max_triangles})", file=sys.stderr)
        return BOUND_NOT_MET
    return 0


def check_command(args) -> int:
    hf = _load(args.against, args.key, args.fill)
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


COMMANDS = {"mesh": mesh_command, "check": check_command, "render": render_command, "synth": synth_command}


def run(args) -> int:
    return COMMANDS[args.command](args)
