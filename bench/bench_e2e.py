"""End to end on the board: seconds from the first byte of the upload to the last level's mesh, at
115200, 921600 and 3,000,000 baud (`python bench/run.py e2e`).

Board seconds = line time + job time.  Line time: the bytes the host and the board actually sent in the
session (`wavemesh stream --report`: transfer.bytes_out + bytes_in, SLIP framing, CRCs, ACKs and all)
x 10 bits / the rate the board reaches (clk_hz / round(clk_hz / baud): at 25 MHz 3.125 Mbaud for
3,000,000).  Job time: the job's own cycles (DONE's filter, template, refine and emit: the FPGA stage,
the refiner, building the level streams) at the board clock.  The receive stage (the upload block
checks and stores the samples as they arrive) and the link's cycles (sending the level streams) run
within the line time; one frame's turnaround per DATA window and level is left out (a USB bridge adds
about a millisecond each).  The simulated board runs the jobs in fast mode (its firmware,
its RTL: the cycles the FPGA would take), every mesh byte for byte `wavemesh mesh`'s, with the default
options: bench/datasets.py's seeded terrain at 256 x 256, and a range image, the Motorcycle disparity
(741 x 500) cropped to 640 x 480.  The terrain at 640 x 480 and 1024 x 1024 would take the simulator
here an hour and more (10^8 to 10^9 cycles on two shared cores): those rows are modelled, their bytes
from the real encoder and framing (bench/bench_link.py's counts: on the simulated runs they agree with
the session's bytes within the small frames), their cycles from the 256 x 256 run's per unit: filter
per sample, template per initial triangle, refine per output triangle, emit per level-stream byte.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np

TITLE = "End to end on the board: line time and job time"
DEFAULT = False  # tens of minutes of simulation: `make bench-e2e`, not in `make bench`
BAUDS = (115_200, 921_600, 3_000_000)
STAGES = ("filter", "template", "refine", "emit")  # the job's own cycles
BAR_S = 5.0  # the 640 x 480 range image at 3 Mbaud


def inputs() -> dict[str, tuple[str, np.ndarray]]:
    import datasets

    return {"256x256": ("terrain", datasets.terrain(256)),
            "640x480 range": ("range image (Motorcycle disparity, cropped)",
                              datasets.load("motorcycle").values[:480, :640])}


def board_job(grid: np.ndarray, board_url: str, tmp: Path) -> dict:
    """One job through `wavemesh stream` on the board at board_url, and `wavemesh mesh` beside it."""
    from wavemesh.harness import run_cli

    src = tmp / "in.npy"
    np.save(src, grid)
    t0 = time.perf_counter()
    # the simulator runs some 10^5 to 10^6 cycles a second: a level may take an hour of it
    rc, _, err = run_cli("stream", str(src), "--port", board_url, "--timeout", "36000", "--deadline", "72000",
                         "-o", str(tmp / "board.obj"), "--report", str(tmp / "board.json"), "-q")
    if rc != 0:
        raise RuntimeError(f"wavemesh stream failed: {err}")
    wall = time.perf_counter() - t0
    rc, _, err = run_cli("mesh", str(src), "-o", str(tmp / "mesh.obj"), "--report", str(tmp / "mesh.json"),
                         "-q")
    if rc != 0:
        raise RuntimeError(f"wavemesh mesh failed: {err}")
    r = json.loads((tmp / "board.json").read_text())
    m = json.loads((tmp / "mesh.json").read_text())
    cyc = {k: v for k, v in r["device_cycles"].items() if k != "seconds"}
    return {"shape": list(grid.shape), "cycles": cyc, "clk_hz": r["device"]["clk_hz"],
            "bytes_out": r["transfer"]["bytes_out"], "bytes_in": r["transfer"]["bytes_in"],
            "initial_triangles": _initial(r), "triangles": _triangles(m),
            "same_as_mesh": (tmp / "board.obj").read_bytes() == (tmp / "mesh.obj").read_bytes(),
            "sim_wall_s": round(wall, 1)}


def _initial(report: dict) -> int:
    return int(report["initial"]["triangles"])


def _triangles(report: dict) -> int:
    return int(report["errors"]["n_triangles"])


def run_jobs(names=None) -> dict:
    from wavemesh.device import stream as S
    from wavemesh.harness.simboard import SIM_TIMEOUTS, SimBoard, build

    jobs = {}
    saved = S.DEFAULT_TIMEOUTS
    S.DEFAULT_TIMEOUTS = SIM_TIMEOUTS
    board = SimBoard(build.build_sim(), build.build_firmware(), "--port", "0", "--fast", "--quiet")
    try:
        for name, (kind, grid) in inputs().items():
            if names and name not in names:
                continue
            with tempfile.TemporaryDirectory() as tmp:
                jobs[name] = {"kind": kind, **board_job(grid, board.url, Path(tmp))}
    finally:
        S.DEFAULT_TIMEOUTS = saved
        board.stop()
    return jobs


def modelled(w: int, h: int, base: dict) -> dict:
    """The seeded terrain at w x h: its bytes from the encoder and framing, its cycles per unit of the
    simulated run `base` (filter per sample, template per initial triangle, refine per output triangle,
    emit per level-stream byte)."""
    import bench_link
    import datasets
    from wavemesh import api
    from wavemesh.io.heightfield import from_array

    hf = from_array(datasets.terrain(max(w, h))[:h, :w])
    res = api.mesh(hf, api.MeshParams())
    up = bench_link.upload_bytes(hf.samples)
    down = bench_link.mesh_bytes(res.level_meshes)
    extra = bench_link.session_bytes(len(res.level_meshes))
    n0 = base["shape"][0] * base["shape"][1]
    init, tris = int(res.report["initial"]["triangles"]), int(res.mesh.n_triangles)
    cyc = {"filter": base["cycles"]["filter"] * w * h / n0,
           "template": base["cycles"]["template"] * init / base["initial_triangles"],
           "refine": base["cycles"]["refine"] * tris / base["triangles"],
           "emit": base["cycles"]["emit"] * down / base["bytes_in"]}
    return {"kind": "terrain (modelled)", "shape": [h, w], "cycles": {k: int(v) for k, v in cyc.items()},
            "clk_hz": base["clk_hz"], "bytes_out": up + extra // 2, "bytes_in": down + extra // 2,
            "initial_triangles": init, "triangles": tris, "modelled": True}


def seconds(job: dict, baud: int) -> dict:
    from wavemesh.device import protocol as P

    clk = job["clk_hz"]
    rate = clk / P.baud_divisor(clk, baud)
    line = 10 * (job["bytes_out"] + job["bytes_in"]) / rate
    work = sum(job["cycles"][s] for s in STAGES) / clk
    return {"rate": rate, "line": line, "job": work, "total": line + work}


def run() -> dict:
    jobs = run_jobs()
    base = jobs["256x256"]
    jobs = {"256x256": base, "640x480": modelled(640, 480, base), "1024x1024": modelled(1024, 1024, base),
            "640x480 range": jobs["640x480 range"]}
    check = {k: v for k, v in modelled(256, 256, base).items() if k.startswith("bytes")}
    return {"jobs": jobs, "bauds": list(BAUDS), "check_256": check}


def markdown(r: dict) -> str:
    out = [__doc__.split("\n\n", 1)[1].strip(), "",
           "| input | kind | job cycles (filter + template + refine + emit) | receive cycles / sample | "
           "bytes up + down | = `mesh` | "
           + " | ".join(f"{b:,} baud: line + job = s" for b in r["bauds"]) + " |",
           "|---|---|---:|---:|---:|---|" + "---:|" * len(r["bauds"])]
    for j in r["jobs"].values():
        n = j["shape"][0] * j["shape"][1]
        cyc = sum(j["cycles"][s] for s in STAGES)
        rx = "" if j.get("modelled") else f"{j['cycles']['receive'] / n:.1f}"
        same = "modelled" if j.get("modelled") else ("yes" if j["same_as_mesh"] else "**no**")
        cells = []
        for b in r["bauds"]:
            s = seconds(j, b)
            cells.append(f"{s['line']:.2f} + {s['job']:.2f} = **{s['total']:.2f}**")
        h, w = j["shape"]
        out.append(f"| {w} x {h} | {j['kind']} | {cyc:,} | {rx} | {j['bytes_out']:,} + {j['bytes_in']:,} | "
                   f"{same} | " + " | ".join(cells) + " |")
    c, b = r.get("check_256"), r["jobs"]["256x256"]
    if c:
        out += ["", f"The model's bytes against a session's: at 256 x 256 the encoder and framing count "
                f"{c['bytes_out']:,} + {c['bytes_in']:,}, the simulated session sent {b['bytes_out']:,} + "
                f"{b['bytes_in']:,}."]
    rng = r["jobs"].get("640x480 range")
    if rng:
        s = seconds(rng, 3_000_000)
        verdict = "met" if s["total"] <= BAR_S else "not met"
        out += ["", f"**Bar: the 640 x 480 range image end to end in at most {BAR_S:g} s of board time at "
                f"3 Mbaud: {verdict}** ({s['total']:.2f} s: {s['line']:.2f} s of line at "
                f"{s['rate'] / 1e6:.3f} Mbaud, {s['job']:.2f} s of job at {rng['clk_hz'] / 1e6:g} MHz)."]
    return "\n".join(out) + "\n"
