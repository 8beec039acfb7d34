"""Cost growth: time and triangles at 256^2, 512^2, 1024^2 and 2048^2 samples, with the
log-log slope of time against samples.

The height field is a seeded synthetic terrain (bench/datasets.py terrain(): one continuous surface, a
sum of random plane waves with a fractal-like spectrum, 0..1000 "m"), in two series:

- *resolution*: the same unit square sampled finer ("resampled"): the surface is the same,
  so the triangles needed for E level off and the cost is what more samples add;
- *extent*: the same sample spacing over a larger area ((n - 1) / 255 units across): more of the same
  terrain, triangles growing with the samples, so the cost per triangle shows.

At every size: wavemesh in process (api.refine with --metric vertical --zeta E: the native refine time,
RefineJob.seconds, and the whole call) and pydelatin's call (Delatin(...), .vertices, .triangles), both
meshes checked by wavemesh.check (proper, within E).  The slope is the least-squares fit of
log(time) on log(samples) over the four sizes.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import datasets as D  # bench/ is on the path: the folder of bench/run.py and of this script
import peers as P

BENCH = Path(__file__).resolve().parent

TITLE = "Cost growth: 256^2 to 2048^2"
SIZES = (256, 512, 1024, 2048)
ZETA = 10.0  # "m": 1% of the terrain's 0..1000 on the unit square
SERIES = {"resolution": lambda n: 1.0, "extent": lambda n: (n - 1) / 255}
TARGET_SLOPE = 1.15


def slope(xs, ys) -> float | None:
    """Least-squares slope of log(y) on log(x)."""
    pts = [(math.log(x), math.log(y)) for x, y in zip(xs, ys, strict=True) if x and y and y > 0]
    if len(pts) < 2:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx


def measure(n: int, extent: float, zeta: float = ZETA, budget: float = 3.0) -> dict:
    from bench_quality import wavemesh_mesh

    z = D.terrain(n, extent)
    natives = []

    def wm():
        job = wavemesh_mesh(z, zeta)
        natives.append(job.seconds)
        return job

    job, call, runs = P.timed(wm, budget=budget)
    wm_v = P.verdict(job.mesh, z, zeta)
    P.delatin_call(z, zeta)  # untimed first call
    (v, t), pd_call, pd_runs = P.timed(lambda: P.delatin_call(z, zeta), budget=budget)
    mesh, vz, problems = P.from_delatin(v, t, n, n)
    pd_v = P.verdict(mesh, z, zeta, vz, problems)
    return {
        "n": n, "samples": n * n, "extent": extent, "zeta": zeta,
        "height_range": float(z.max() - z.min()),
        "wavemesh": {**wm_v.to_json(), "native_s": P.median(natives), "call_s": call, "runs": runs},
        "pydelatin": {**pd_v.to_json(), "call_s": pd_call, "runs": pd_runs},
    }


def run() -> dict:
    out = {"code": P.code_state(), "sizes": list(SIZES), "zeta": ZETA, "series": {}}
    for name, ext in SERIES.items():
        rows = []
        for n in SIZES:
            t0 = time.perf_counter()
            r = measure(n, ext(n))
            rows.append(r)
            print(f"  {name} {n}^2: wavemesh {r['wavemesh']['triangles']} triangles, native "
                  f"{r['wavemesh']['native_s']:.2f} s; pydelatin {r['pydelatin']['triangles']}, "
                  f"{r['pydelatin']['call_s']:.2f} s ({time.perf_counter() - t0:.0f} s)", flush=True)
        xs = [r["samples"] for r in rows]
        out["series"][name] = {
            "rows": rows,
            "slopes": {
                "wavemesh_native": slope(xs, [r["wavemesh"]["native_s"] for r in rows]),
                "wavemesh_call": slope(xs, [r["wavemesh"]["call_s"] for r in rows]),
                "pydelatin_call": slope(xs, [r["pydelatin"]["call_s"] for r in rows]),
                "wavemesh_triangles": slope(xs, [r["wavemesh"]["triangles"] for r in rows]),
                "pydelatin_triangles": slope(xs, [r["pydelatin"]["triangles"] for r in rows]),
            },
        }
    return out


def _f(v, nd=2) -> str:
    return "-" if v is None else f"{v:.{nd}f}"


def _ok(m: dict) -> str:
    if not m["proper"]:
        return "NOT PROPER"
    return "ok" if m["within"] else f"E_max {m['e_max_vertical']:.4g} > E"


def markdown(results: dict) -> str:
    lines = [
        "A seeded synthetic terrain (bench/datasets.py `terrain`: one continuous surface, random plane "
        f"waves with a fractal-like spectrum, 0..1000 \"m\" on the unit square) at E = {results['zeta']:g} "
        "(vertical), in two series: *resolution* samples the same unit square finer (the surface is the "
        "same, so the triangles level off), *extent* keeps the sample spacing and grows the area (more of "
        "the same terrain: triangles grow with the samples).  wavemesh: api.refine in process, *native* = "
        "RefineJob.seconds (the C refiner and its ctypes calls), *call* = the whole api.refine (filter bank, "
        "templates, refiner, its checks); pydelatin: Delatin(...) with .vertices and .triangles.  Times "
        "are medians of up to 3 runs (slow calls run once) on a shared 2-core machine; every mesh checked "
        "by wavemesh.check (*checks*: wavemesh / pydelatin).  Slope: least-squares fit of log(time) on "
        "log(samples) over the four sizes.",
        "",
        P.code_line(results.get("code")),
        "",
        "| series | grid | wavemesh triangles | pydelatin triangles | ratio | wavemesh native s "
        "| wavemesh call s | pydelatin s | native / pydelatin | checks |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, s in results["series"].items():
        for r in s["rows"]:
            wm, pd = r["wavemesh"], r["pydelatin"]
            lines.append(
                f"| {name} | {r['n']}^2 | {wm['triangles']} | {pd['triangles']} "
                f"| {wm['triangles'] / pd['triangles']:.3f} | {wm['native_s']:.3f} | {wm['call_s']:.3f} "
                f"| {pd['call_s']:.3f} | {wm['native_s'] / pd['call_s']:.2f} | {_ok(wm)} / {_ok(pd)} |")
    lines += [
        "",
        "| series | slope: wavemesh native | wavemesh call | pydelatin | triangles: wavemesh | pydelatin "
        f"| target: native slope <= {TARGET_SLOPE} |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, s in results["series"].items():
        sl = s["slopes"]
        met = sl["wavemesh_native"] is not None and sl["wavemesh_native"] <= TARGET_SLOPE
        lines.append(
            f"| {name} | **{_f(sl['wavemesh_native'])}** | {_f(sl['wavemesh_call'])} "
            f"| {_f(sl['pydelatin_call'])} | {_f(sl['wavemesh_triangles'])} "
            f"| {_f(sl['pydelatin_triangles'])} "
            f"| {'met' if met else '**not met**'} |")
    return "\n".join(lines)


if __name__ == "__main__":
    import json

    res = run()
    print(json.dumps({k: v["slopes"] for k, v in res["series"].items()}, indent=1))
    print(markdown(res))
