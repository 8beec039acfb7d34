"""Quality and speed against pydelatin and pymartini at the same max vertical error.

Grids (bench/datasets.py, sources and licences in bench/README.md): real height fields that ship inside
packages installed here (terrain DEMs, a stereo disparity map, intensity images) and the dissertation's
synthetic sets, each whole.  Errors: fractions of each grid's height range, fine to coarse
(FRACTIONS); on Jacksboro 5 m and 10 m take the place of the two finest.

Per grid/error pair:

- wavemesh in process: api.refine (defaults of `wavemesh mesh`, --metric vertical, --zeta E): its mesh,
  the native refine time (RefineJob.seconds: native.refine, the C refiner and its ctypes calls; the filter
  bank's details come with the initial triangulation, before it) and the whole call
  (filter bank, templates, refiner, the API's own checks);
- pydelatin in process: Delatin(z, width, height, max_error=E) then .vertices and .triangles, timed;
  its output mapped with y_grid = (H - 1) - y (bench/peers.py);
- pymartini in process: Martini(2^k + 1) on the grid padded by edge replication, create_tile, get_mesh;
- whole processes, run alternately: `wavemesh mesh IN.npy -o x.obj --metric vertical --zeta E` against
  a `python -c` that loads the same .npy, runs pydelatin and writes the same kind of OBJ;
- every mesh (also the OBJ files both processes wrote) checked with wavemesh.check: a proper
  triangulation of the grid rectangle with grid-sample vertices, and E_max vertical and normal measured
  with wavemesh's own metrics.  A mesh that is not proper or exceeds E is flagged in the table.

Times are medians of several runs (a call slower than a few seconds runs once); the machine is shared,
so the ratios (measured back to back) are the figures to read.  HELD_OUT names the grids kept aside:
they are reported in their own table and medians and are not for tuning.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import datasets as D  # bench/ is on the path: the folder of bench/run.py and of this script
import numpy as np
import peers as P

BENCH = Path(__file__).resolve().parent

TITLE = "Quality: triangles and time against pydelatin and pymartini"
FRACTIONS = (0.005, 0.01, 0.02, 0.05)  # of each grid's height range, fine to coarse
ABSOLUTE = {"jacksboro": {0.005: 5.0, 0.01: 10.0}}  # metres, in place of these fractions
# A third of the grids, kept aside: not used for tuning, reported on their own.  Chosen among the grids
# this benchmark brought in (the project's docs and tests had never used them; Jacksboro and the
# synthetic sets had), one per kind and a second terrain, before any result was seen.
HELD_OUT = ("topobathy", "lidar_dem", "motorcycle", "moon")
GRIDS = tuple(D.SETS)
TARGET_MEDIAN, TARGET_MAX = 1.0, 1.3  # the targets: triangles vs pydelatin
TARGET_NATIVE, TARGET_PROCESS = 1.5, 1.0  # the targets: native refine vs pydelatin call, process vs process
WM_BUDGET = 3.0  # seconds of repeats for one wavemesh timing (a slower call runs once)
PEER_BUDGET = 2.0


def zetas(grid: D.Grid) -> list[tuple[str, float]]:
    """(label, E) for a grid, fine to coarse."""
    out = []
    for f in FRACTIONS:
        absolute = ABSOLUTE.get(grid.name, {}).get(f)
        if absolute is not None:
            out.append((f"{absolute:g} {grid.units}", absolute))
        else:
            out.append((f"{100 * f:g}%", f * grid.height_range))
    return out


def _ratio(a, b):
    return None if a is None or b is None or b == 0 else a / b


def wavemesh_mesh(z: np.ndarray, zeta: float, **params):
    """The benchmark's wavemesh job; ``params``: RefineParams fields other than the defaults (triangles())."""
    from wavemesh import api
    from wavemesh.io.heightfield import from_array
    from wavemesh.refine.native import RefineParams

    return api.refine(from_array(z), params=RefineParams(zeta=float(zeta), metric="vertical", **params))


def triangles(params: dict, results: Path = Path(__file__).parent / "results" / "quality.json") -> dict:
    """Triangles over pydelatin's on every pair, the wavemesh job run with ``params`` (RefineParams fields)
    and pydelatin's counts taken from the stored run: the cheap way to compare refiner settings (no
    timings).  Medians of the tuning and the held-out pairs, and the pairs not proper or over zeta."""
    stored = json.loads(results.read_text())
    peer = {(p["grid"], p["label"]): p["pydelatin"]["triangles"] for p in stored["pairs"]}
    ratios: dict[bool, list[float]] = {False: [], True: []}
    bad = []
    for name in GRIDS:
        grid = D.load(name)
        for label, zeta in zetas(grid):
            v = P.verdict(wavemesh_mesh(grid.values, zeta, **params).mesh, grid.values, zeta)
            ratios[name in HELD_OUT].append(v.triangles / peer[(name, label)])
            if not (v.proper and v.within):
                bad.append(f"{name} {label}")
    return {"params": params, "tuning": float(np.median(ratios[False])),
            "held_out": float(np.median(ratios[True])), "bad": bad}


def _run_processes(npy: Path, zeta: float, tmp: Path, runs: int = 3, budget: float = 6.0) -> dict:
    """`wavemesh mesh` and the pydelatin script (bench/peers.py) as whole processes, in turns (wavemesh,
    pydelatin, wavemesh, ...): rounds of both until each ran `runs` times or, after the first round, some
    `budget` seconds are spent.  Each one's median wall seconds and CPU seconds (_children_cpu), and the
    OBJ files they wrote.  A process that fails ends the rounds: `error` names it, and no times are given
    (a failed run's time is not the job's)."""
    objs = {"wavemesh": tmp / "wavemesh.obj", "pydelatin": tmp / "pydelatin.obj"}
    cmds = {"wavemesh": P.wavemesh_argv(str(npy), zeta, str(objs["wavemesh"])),
            "pydelatin": P.peer_argv(str(npy), zeta, str(objs["pydelatin"]))}
    wall: dict[str, list[float]] = {who: [] for who in cmds}
    cpu: dict[str, list[float]] = {who: [] for who in cmds}
    error, rounds, start = None, 0, time.perf_counter()
    while error is None and rounds < runs and (rounds == 0 or time.perf_counter() - start < budget):
        for who, cmd in cmds.items():
            t0, c0 = time.perf_counter(), _children_cpu()
            r = subprocess.run(cmd, capture_output=True, text=True)
            if r.returncode != 0:
                error = f"{who} exit {r.returncode}: {r.stderr.strip()[-300:]}"
                break
            wall[who].append(time.perf_counter() - t0)
            cpu[who].append(_children_cpu() - c0)
        rounds += 1

    def median(times: list[float]) -> float | None:
        return None if error else P.median(times)

    return {"wavemesh_s": median(wall["wavemesh"]), "pydelatin_s": median(wall["pydelatin"]),
            "wavemesh_cpu_s": median(cpu["wavemesh"]), "pydelatin_cpu_s": median(cpu["pydelatin"]),
            "runs": 0 if error else rounds, "error": error,
            "wavemesh_obj": objs["wavemesh"], "pydelatin_obj": objs["pydelatin"]}


def _children_cpu() -> float:
    """User + system seconds of this process's reaped children (a process run is one child: its own CPU
    time, which other work on a shared machine changes less than its wall time)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _check_obj(path: Path, heights: np.ndarray, zeta: float) -> dict:
    from wavemesh.io.meshread import read_mesh

    h, w = heights.shape
    try:
        mesh, z = read_mesh(str(path), w, h)
    except Exception as e:  # noqa: BLE001 - a file the peer wrote badly is a finding, not a crash
        return {"triangles": None, "proper": False, "within": False, "problems": [str(e)[:200]]}
    v = P.verdict(mesh, heights, zeta, z)
    return {"triangles": v.triangles, "proper": v.proper and v.heights_ok,
            "within": v.within and v.heights_ok, "problems": v.problems}


def run_pair(grid: D.Grid, label: str, zeta: float, npy: Path | None = None, *,
             wm_budget: float = WM_BUDGET, peer_budget: float = PEER_BUDGET) -> dict:
    """Every measurement of one grid/error pair; whole processes too when npy (the grid saved) is given."""
    z = grid.values
    h, w = z.shape
    # wavemesh in process (RefineJob.seconds is the native part of each call)
    natives = []

    def wm():
        job = wavemesh_mesh(z, zeta)
        natives.append(job.seconds)
        return job

    try:
        job, wm_call, wm_runs = P.timed(wm, budget=wm_budget)
    except Exception as e:  # noqa: BLE001 - a refiner failure is a finding of the benchmark: flagged
        wm_v = P.Verdict(None, None, False, False, None, None, False, [f"{type(e).__name__}: {e}"[:300]])
        wavemesh = {**wm_v.to_json(), "native_s": None, "call_s": None, "runs": 0, "bound_met": False,
                    "error": wm_v.problems[0]}
    else:
        wm_v = P.verdict(job.mesh, z, zeta)
        wavemesh = {**wm_v.to_json(), "native_s": P.median(natives), "call_s": wm_call, "runs": wm_runs,
                    "bound_met": bool(job.bound_met)}
    # pydelatin in process (one untimed call first: its first call in a process pays for page faults)
    P.delatin_call(z, zeta)
    (verts, tris), pd_call, pd_runs = P.timed(lambda: P.delatin_call(z, zeta), budget=peer_budget)
    mesh, vz, problems = P.from_delatin(verts, tris, w, h)
    pydelatin = {**P.verdict(mesh, z, zeta, vz, problems).to_json(), "call_s": pd_call, "runs": pd_runs}
    # pymartini on the padded grid
    size = P.martini_size(w, h)
    zp = P.pad_edge(z, size)
    (mv, mt), pm_call, pm_runs = P.timed(lambda: P.martini_call(zp, zeta), budget=peer_budget)
    pymartini = {**P.verdict(P.from_martini(mv, mt, size), zp, zeta).to_json(), "call_s": pm_call,
                 "runs": pm_runs, "grid": size}
    pair = {"grid": grid.name, "kind": grid.kind, "held_out": grid.name in HELD_OUT, "width": w, "height": h,
            "height_range": grid.height_range, "units": grid.units, "label": label, "zeta": zeta,
            "wavemesh": wavemesh, "pydelatin": pydelatin, "pymartini": pymartini}
    ratios = {"triangles": _ratio(wm_v.triangles, pydelatin["triangles"]),
              "native_time": _ratio(wavemesh["native_s"], pd_call),
              "call_time": _ratio(wm_call, pd_call),
              "martini_triangles": _ratio(wm_v.triangles, pymartini["triangles"])}
    if npy is not None:
        with tempfile.TemporaryDirectory(dir=npy.parent) as t:
            proc = _run_processes(npy, zeta, Path(t))
            proc["wavemesh_file"] = _check_obj(proc.pop("wavemesh_obj"), z, zeta)
            proc["pydelatin_file"] = _check_obj(proc.pop("pydelatin_obj"), z, zeta)
        pair["process"] = proc
        ratios["process_time"] = _ratio(proc["wavemesh_s"], proc["pydelatin_s"])
        ratios["process_cpu"] = _ratio(proc["wavemesh_cpu_s"], proc["pydelatin_cpu_s"])
    pair["ratios"] = ratios
    return pair


def summarise(pairs: list[dict]) -> dict:
    def col(key):
        return [p["ratios"].get(key) for p in pairs if p["ratios"].get(key) is not None]

    tri = col("triangles")
    return {
        "pairs": len(pairs),
        "grids": len({p["grid"] for p in pairs}),
        "median_triangles": P.median(tri),
        "max_triangles": max(tri) if tri else None,
        "over_max": sum(1 for r in tri if r > TARGET_MAX),
        "median_native_time": P.median(col("native_time")),
        "median_call_time": P.median(col("call_time")),
        "median_process_time": P.median(col("process_time")),
        "median_process_cpu": P.median(col("process_cpu")),
        "median_martini_triangles": P.median(col("martini_triangles")),
        "wavemesh_all_ok": all(p["wavemesh"]["within"] for p in pairs),
        "wavemesh_failed": sum(1 for p in pairs if p["wavemesh"].get("error")),
        "pydelatin_flagged": sum(1 for p in pairs if not p["pydelatin"]["within"]),
        "pymartini_flagged": sum(1 for p in pairs if not p["pymartini"]["within"]),
    }


def run(names: tuple[str, ...] = GRIDS) -> dict:
    pairs = []
    P.compile_wavemesh()  # the processes timed run from byte code, as pydelatin's do
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            grid = D.load(name)
            npy = Path(tmp) / f"{name}.npy"
            np.save(npy, grid.values)
            for label, zeta in zetas(grid):
                t0 = time.perf_counter()
                pair = run_pair(grid, label, zeta, npy)
                pairs.append(pair)
                r = pair["ratios"]
                print(f"  {name} {label}: triangles x{_f(r['triangles'], 3)}, "
                      f"native time x{_f(r['native_time'])}, process x{_f(r.get('process_time'))}; "
                      f"{_flags(pair)} ({time.perf_counter() - t0:.1f} s)", flush=True)
    return assemble(pairs, names)


def assemble(pairs: list[dict], names) -> dict:
    """The results file: versions, the split, the grids' sources, every pair, the medians per set."""
    from importlib.metadata import version

    sets = {"tuning": [p for p in pairs if not p["held_out"]],
            "held_out": [p for p in pairs if p["held_out"]], "all": pairs}
    return {
        "code": P.code_state(),
        "versions": {k: version(k) for k in ("pydelatin", "pymartini", "numpy")},
        "fractions": list(FRACTIONS), "held_out": list(HELD_OUT),
        "grids": {n: {"kind": D.SETS[n][0], "source": D.SETS[n][1], "units": D.SETS[n][2]}
                  if n in D.SETS else {"kind": "test", "source": "-", "units": "-"} for n in names},
        "pairs": pairs,
        "summary": {k: summarise(v) for k, v in sets.items() if v},
    }


# --------------------------------------------------------------------------------------------
# The document section


def _f(v, nd=2) -> str:
    return "-" if v is None or v != v else f"{v:.{nd}f}"


def _flags(p: dict) -> str:
    out = []
    for who, short in (("wavemesh", "wm"), ("pydelatin", "pd"), ("pymartini", "pm")):
        m = p[who]
        if m.get("error"):
            out.append(f"{short}: FAILED ({m['error'][:80]})")
        elif not m["proper"]:
            out.append(f"{short}: NOT PROPER")
        elif not m.get("heights_ok", True):
            out.append(f"{short}: wrong heights")
        elif not m["within"]:
            ev, en = m["e_max_vertical"], m["e_max_normal"]
            worst = max(ev, en)
            out.append(f"{short}: E_max {worst / p['zeta']:.3f} zeta")
    proc = p.get("process") or {}
    for who, short in (("wavemesh_file", "wm file"), ("pydelatin_file", "pd file")):
        f = proc.get(who)
        if f is not None and not f["within"]:
            out.append(f"{short}: {'not proper' if not f['proper'] else 'over zeta'}")
    if proc.get("error"):
        out.append("process failed")
    return "; ".join(out) or "ok"


def _pair_table(pairs: list[dict], s: dict) -> list[str]:
    lines = [
        "| grid | W x H | E | wavemesh triangles | pydelatin | **ratio** | pymartini (grid) | ratio | "
        "native refine / pydelatin call | `mesh` process / peer process | CPU | checks |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in pairs:
        r, wm, pd, pm = p["ratios"], p["wavemesh"], p["pydelatin"], p["pymartini"]
        lines.append(
            f"| {p['grid']} | {p['width']} x {p['height']} | {p['label']} ({p['zeta']:.4g}) "
            f"| {wm['triangles'] if wm['triangles'] is not None else '-'} | {pd['triangles']} "
            f"| **{_f(r['triangles'], 3)}** "
            f"| {pm['triangles']} ({pm['grid']}) "
            f"| {_f(r['martini_triangles'], 3)} | {_f(r['native_time'])} | {_f(r.get('process_time'))} "
            f"| {_f(r.get('process_cpu'))} | {_flags(p)} |")
    lines.append(
        f"| **median** ({s['pairs']} pairs) | | | | | **{_f(s['median_triangles'], 3)}** | | "
        f"{_f(s['median_martini_triangles'], 3)} | {_f(s['median_native_time'])} | "
        f"{_f(s['median_process_time'])} | {_f(s.get('median_process_cpu'))} | |")
    return lines


def _meets(ok: bool) -> str:
    return "met" if ok else "**not met**"


def markdown(results: dict) -> str:
    v = results["versions"]
    S = results["summary"]
    fr = ", ".join(f"{100 * f:g}%" for f in results["fractions"])
    lines = [
        f"wavemesh (`--metric vertical --zeta E`, other options at their defaults) against pydelatin "
        f"{v['pydelatin']} and pymartini {v['pymartini']} at the same max vertical error E, on "
        f"{S['all']['grids']} whole grids (bench/datasets.py; sources and licences in bench/README.md) at "
        f"E = {fr} of each grid's height range (Jacksboro: 5 m and 10 m for the two finest).  Every mesh is "
        "checked by wavemesh's own checker (proper triangulation of the grid rectangle, grid-sample vertices "
        "with the grid's heights) and its E_max vertical and normal measured by wavemesh.check.mesh_errors; "
        "*checks* says `ok` or names "
        "the mesh that is not proper or exceeds E (wm = wavemesh, pd = pydelatin, pm = pymartini; *file*: "
        "the OBJ a whole process wrote).  pydelatin's y is flipped (y_grid = (H - 1) - y).  pymartini meshes "
        "the grid padded by edge replication to 2^k + 1 square (the *grid* column); its triangles in the "
        "padding count.",
        "",
        P.code_line(results.get("code")),
        "",
        "*ratio* = wavemesh triangles / peer triangles (below 1: wavemesh is smaller).  *native refine / "
        "pydelatin call*: RefineJob.seconds (the C refiner and its ctypes calls) over Delatin(...) with "
        ".vertices and .triangles, in one process; *`mesh` process / peer process*: `wavemesh mesh IN.npy "
        "-o x.obj --metric vertical --zeta E` over a `python -c` that loads the same .npy, runs pydelatin "
        "and writes an OBJ, run alternately (wall seconds; *CPU*: the same for each process's user + "
        "system seconds, which a busy machine changes less).  Times are medians of up to 3 runs (a call "
        "slower than a few seconds runs once) on a 2-core machine shared with other work: read the ratios, "
        "not the seconds (in bench/results/quality.json).",
        "",
        "**Summary** (the targets: median triangle ratio at most 1.0, no pair above 1.3, the held-out set "
        f"included; median native refine / pydelatin call at most {TARGET_NATIVE}, median process / process "
        f"at most {TARGET_PROCESS}):",
        "",
        "| set | grids | pairs | median triangle ratio | max | pairs > 1.3 | median native / call | "
        "median process / process | CPU | median ratio vs pymartini | wavemesh meshes all proper and "
        "within E | pydelatin / pymartini meshes flagged |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    names = {"tuning": "tuning set", "held_out": "**held-out set**", "all": "all pairs"}
    for key in ("tuning", "held_out", "all"):
        s = S.get(key)
        if s is None:
            continue
        lines.append(
            f"| {names[key]} | {s['grids']} | {s['pairs']} | {_f(s['median_triangles'], 3)} "
            f"| {_f(s['max_triangles'], 3)} | {s['over_max']} | {_f(s['median_native_time'])} "
            f"| {_f(s['median_process_time'])} | {_f(s.get('median_process_cpu'))} "
            f"| {_f(s['median_martini_triangles'], 3)} "
            f"| {'yes' if s['wavemesh_all_ok'] else '**no**'}"
            f"{f' ({n} failed)' if (n := s.get('wavemesh_failed')) else ''} "
            f"| {s['pydelatin_flagged']} / {s['pymartini_flagged']} |")
    calls = "; ".join(f"{names[k].strip('*')} {_f(S[k]['median_call_time'])}" for k in names if k in S)
    lines += ["", "The whole wavemesh call (from_array and api.refine: quantisation, filter bank, templates, "
              f"refiner, its checks) over pydelatin's call, median: {calls}."]
    a = S["all"]
    held = S.get("held_out", a)
    tri_ok = (a["median_triangles"] <= TARGET_MEDIAN and held["median_triangles"] <= TARGET_MEDIAN
              and a["over_max"] == 0)
    lines += [
        "",
        f"Targets on this run: triangles (median <= {TARGET_MEDIAN}, none > {TARGET_MAX}, held-out "
        f"included): {_meets(tri_ok)}; every wavemesh mesh proper and within E in both metrics: "
        f"{_meets(a['wavemesh_all_ok'])}; native refine <= {TARGET_NATIVE} x pydelatin's call (median): "
        f"{_meets(a['median_native_time'] <= TARGET_NATIVE)}; `wavemesh mesh` process <= {TARGET_PROCESS} x "
        f"pydelatin's (median): {_meets(a['median_process_time'] <= TARGET_PROCESS)}.",
    ]
    if "tuning" in S:
        lines += [
            "",
            f"**Tuning set** ({', '.join(g for g in results['grids'] if g not in results['held_out'])}):",
            "",
            *_pair_table([p for p in results["pairs"] if not p["held_out"]], S["tuning"]),
        ]
    if "held_out" in S:
        lines += [
            "",
            f"**Held-out set** ({', '.join(results['held_out'])}; never used for tuning):",
            "",
            *_pair_table([p for p in results["pairs"] if p["held_out"]], S["held_out"]),
        ]
    lines += ["", "Grids:", ""]
    for n, g in results["grids"].items():
        p = next(p for p in results["pairs"] if p["grid"] == n)
        lines.append(f"- {n} ({g['kind']}, {p['width']} x {p['height']}, range {p['height_range']:.4g} "
                     f"{g['units']}): {g['source']}" + (" (held out)" if n in results["held_out"] else ""))
    return "\n".join(lines)


if __name__ == "__main__":
    # a quick look at some grids: python bench/bench_quality.py f1 ball
    # triangles over pydelatin's with other refiner settings: python bench/bench_quality.py --set iterations=0
    if sys.argv[1:2] == ["--set"] and len(sys.argv) == 3:
        params = {k: int(v) for k, v in (item.split("=") for item in sys.argv[2].split(","))}
        print(json.dumps(triangles(params), indent=1))
        sys.exit(0)
    res = run(tuple(sys.argv[1:]) or GRIDS)
    print(json.dumps(res["summary"], indent=1))
    print(markdown(res))
