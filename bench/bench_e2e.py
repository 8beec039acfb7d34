"""End to end on the board: seconds from the first byte of the upload to the last level's mesh, at
115200, 921600 and 3,000,000 baud (`python bench/run.py e2e`).

Board seconds = line time + job time.  Line time: the session's bytes both ways (the samples as the host
codes them in DATA frames, every level's stream in MESH frames as the device codes them, the small frames:
HELLO, CONFIG, RUN, ACKs, DONE; counted by the real encoder and framing, bench/bench_link.py's functions,
on a clean line) x 10 bits / the rate the board reaches, clk_hz / round(clk_hz / baud) (at 30, 36 and
39 MHz 3 Mbaud exactly for 3,000,000).  The receive stage runs within it (the upload block checks and stores
the samples as they arrive: about 13 cycles a sample, "The link" below), and so does sending the level
streams.  Job time: the job's own cycles (filter, template, refine and emit: the FPGA stage, the refiner
on the soft CPU, building the level streams) at the board clock, from the cost model of "The whole job on the
simulated board": a cycles per input sample and b cycles per output triangle, fitted by least squares to
the work cycles of the budget's own inputs measured whole (`make bench-soc-full`,
bench/results/soc-full.json: there the cost follows the output triangles more than the samples), times
the job's samples and triangles.  The jobs themselves are not simulated here: the whole inputs took the
simulator up to 40 minutes each.  Inputs: bench/datasets.py's seeded terrain at 256 x 256, 640 x 480 and
1024 x 1024, and a range image, the Motorcycle disparity (741 x 500) cropped to 640 x 480; `wavemesh mesh`'s
default options, every level's mesh down.
"""

from __future__ import annotations

import json
from pathlib import Path

TITLE = "End to end on the board: line time and job time"
BAUDS = (115_200, 921_600, 3_000_000)
BAR_S = 5.0  # the 640 x 480 range image at 3 Mbaud
RESULTS = Path(__file__).resolve().parent / "results"


def inputs() -> dict:
    import datasets

    return {"256x256": ("terrain", lambda: datasets.terrain(256)),
            "640x480": ("terrain", lambda: datasets.terrain(640)[:480, :640]),
            "1024x1024": ("terrain", lambda: datasets.terrain(1024)),
            "640x480 range": ("range image (Motorcycle disparity, cropped)",
                              lambda: datasets.load("motorcycle").values[:480, :640])}


def cost_model() -> dict:
    """Work cycles = a x samples + b x output triangles, least squares over `make bench-soc-full`'s cases;
    each case's model / measured."""
    import numpy as np

    cases = json.loads((RESULTS / "soc-full.json").read_text())["cases"]
    x = np.array([[c["samples"], c["output_triangles"]] for c in cases], dtype=float)
    y = np.array([c["work_cycles"] for c in cases], dtype=float)
    (a, b), *_ = np.linalg.lstsq(x, y, rcond=None)
    fit = {c["name"]: float(m / w) for c, m, w in zip(cases, x @ (a, b), y, strict=True)}
    return {"per_sample": float(a), "per_triangle": float(b), "fit": fit, "clk_hz": cases[0]["clk_hz"],
            "date": max(c["date"] for c in cases)}


def job_cycles(j: dict, model: dict) -> float:
    return model["per_sample"] * j["samples"] + model["per_triangle"] * j["triangles"]


def job(grid) -> dict:
    import bench_link
    from wavemesh import api
    from wavemesh.io.heightfield import from_array

    hf = from_array(grid)
    res = api.mesh(hf, api.MeshParams())
    extra = bench_link.session_bytes(len(res.level_meshes))
    return {"shape": list(hf.samples.shape), "samples": int(hf.samples.size),
            "triangles": int(res.mesh.n_triangles), "levels": len(res.level_meshes),
            "upload": bench_link.upload_bytes(hf.samples), "mesh": bench_link.mesh_bytes(res.level_meshes),
            "session": extra}


def run() -> dict:
    jobs = {name: {"kind": kind, **job(make())} for name, (kind, make) in inputs().items()}
    return {"jobs": jobs, "bauds": list(BAUDS), "model": cost_model()}


def seconds(j: dict, baud: int, model: dict) -> dict:
    from wavemesh.device import protocol as P

    clk = model["clk_hz"]
    rate = clk / P.baud_divisor(clk, baud)
    line = 10 * (j["upload"] + j["mesh"] + j["session"]) / rate
    work = job_cycles(j, model) / clk
    return {"rate": rate, "line": line, "job": work, "total": line + work}


def markdown(r: dict) -> str:
    m = r["model"]
    fit = ", ".join(f"{k} {v:.2f}" for k, v in m["fit"].items())
    out = [__doc__.split("\n\n", 1)[1].strip(), "",
           f"The cost model (bench/results/soc-full.json, {m['date']}, {m['clk_hz'] / 1e6:g} MHz): work "
           f"cycles = {m['per_sample']:,.0f} x samples + {m['per_triangle']:,.0f} x output triangles; the "
           f"model over the measured work: {fit}.", "",
           "| input | kind | triangles | bytes up + down | job cycles (model) | job s | "
           + " | ".join(f"{b:,} baud: line s, total s" for b in r["bauds"]) + " |",
           "|---|---|---:|---:|---:|---:|" + "---:|" * len(r["bauds"])]
    for j in r["jobs"].values():
        h, w = j["shape"]
        s0 = seconds(j, r["bauds"][0], m)
        cells = []
        for b in r["bauds"]:
            s = seconds(j, b, m)
            cells.append(f"{s['line']:.2f}, **{s['total']:.0f}**")
        out.append(f"| {w} x {h} | {j['kind']} | {j['triangles']:,} | {j['upload']:,} + "
                   f"{j['mesh'] + j['session']:,} | {job_cycles(j, m) / 1e9:.2f} G | "
                   f"{s0['job']:.1f} | " + " | ".join(cells) + " |")
    rng = r["jobs"].get("640x480 range")
    if rng:
        s = seconds(rng, 3_000_000, m)
        link_ok, e2e_ok = s["line"] <= BAR_S, s["total"] <= BAR_S
        out += ["", f"**Bar: the 640 x 480 range image end to end in at most {BAR_S:g} s of board time at 3 "
                f"Mbaud: the link alone {'meets' if link_ok else 'misses'} it** ({s['line']:.2f} s "
                f"of line at {s['rate'] / 1e6:.3f} Mbaud); **end to end {'met' if e2e_ok else 'not met'}** "
                f"({s['total']:.0f} s: the job's {s['job']:.0f} s on the soft CPU by the cost model; "
                "the refiner's work against the board-speed budget is in \"The whole job on the simulated "
                "board\")."]
    return "\n".join(out) + "\n"
