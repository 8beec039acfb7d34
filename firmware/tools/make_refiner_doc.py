#!/usr/bin/env python3
"""Write docs/refiner.md: the refiner's decisions and its results beside the dissertation's Table 5.6.

    .venv/bin/python firmware/tools/make_refiner_doc.py          # rewrite docs/refiner.md
    .venv/bin/python firmware/tools/make_refiner_doc.py --check  # exit 1 when the doc is stale

Every number in the results is measured here (run times too; the check ignores those).
tests/firmware/test_doc.py runs the check.
"""

# ruff: noqa: E501  (tables and prose lines)
from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "refiner.md"

from wavemesh import api, native, synth  # noqa: E402
from wavemesh.check import mesh_errors  # noqa: E402
from wavemesh.heightfield import from_array  # noqa: E402

# Table 5.6 of the dissertation: |Gamma_m| and E_max (normal distance) per level m, M = 5.
PAPER_5_6 = {
    "Ball": [(4, 156, 9.31), (3, 498, 9.04), (2, 700, 7.72), (1, 766, 1.32), (0, 782, 0.98)],
    "Box": [(4, 164, 152.61), (3, 254, 150.00), (2, 310, 81.74), (1, 322, 21.49), (0, 360, 1.00)],
    "Hawaii": [(4, 292, 23.82), (3, 1409, 32.84), (2, 2021, 16.76), (1, 2173, 16.76), (0, 2239, 2.00)],
    "CraterLake": [(4, 266, 156.56), (3, 2122, 18.17), (2, 3428, 7.00), (1, 3689, 3.20), (0, 3758, 2.00)],
}


def jacksboro() -> np.ndarray:
    import matplotlib.cbook as cbook

    with np.load(cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False)) as z:
        return z["elevation"]


# name, values, paper column to compare with, parameters as in 5.3 (M = 5; synthetic zeta 1 and
# k = 2, terrain zeta 2 m and k = 3; delta_d 0.1, delta_p 0.9, delta_v 2; alpha 0.8 for Ball, 0.6 else)
RUNS = [
    ("Ball", synth.ball, "Ball", dict(zeta=1.0, iterations=2, alpha=0.8)),
    ("Box", synth.box, "Box", dict(zeta=1.0, iterations=2, alpha=0.6)),
    ("Jacksboro", jacksboro, "CraterLake", dict(zeta=2.0, iterations=3, alpha=0.6)),
]
VERTICAL_ZETA = {"Ball": 1.0, "Box": 1.0, "Jacksboro": 10.0}


def run(values, metric: str, **kw):
    hf = from_array(values() if callable(values) else values)
    params = native.RefineParams(metric=metric, delta_d=0.1, delta_p=0.9, delta_v=2.0, **kw)
    rjob = api.refine(hf, 5, None, params)
    seconds = rjob.seconds  # the library's calls (all levels, exports), not the Python checks
    rows = []
    for lv in rjob.output.levels:
        e = mesh_errors(lv.mesh, hf.values)
        st = lv.stats
        rows.append((lv.level, lv.mesh.n_vertices, lv.mesh.n_triangles, e.e_max_normal, e.e_max_vertical,
                     st["edge_splits"] + st["ternary_splits"] + st["bound_splits"], st["moves"], st["swaps"]))
    return hf, rjob, rows, seconds


def results() -> str:
    out = []
    lib = native.load()
    per_tri = (lib.wm_refine_bound(256, 256, 200000) - lib.wm_refine_bound(256, 256, 100000)) / 100000
    out += ["## Results", "",
            "Measured by `firmware/tools/make_refiner_doc.py` (M = 5, delta_d = 0.1, delta_p = 0.9, delta_v = 2,",
            "face-based neighbourhoods; Ball: zeta = 1, k = 2, alpha = 0.8; Box: zeta = 1, k = 2, alpha = 0.6;",
            "Jacksboro: zeta = 2 m, k = 3, alpha = 0.6, as 5.3 sets them for the synthetic and terrain sets).",
            "Jacksboro (the DEM matplotlib ships, 403 x 344, metres) stands in for Hawaii and CraterLake, which",
            "cannot be downloaded here; its column is set beside CraterLake's.  E_max is measured independently",
            "by `wavemesh.check.mesh_errors` in floating point against the input heights; the mesh of level m",
            "is the refiner's output after level m (no reduction yet, see \"Not yet\").", ""]
    timing = []
    for metric in ("normal", "vertical"):
        out += [f"### {metric.capitalize()} distance" + (" (the dissertation's metric)" if metric == "normal" else ""),
                ""]
        head = "| m |"
        sep = "|---|"
        cols = []
        for name, values, paper, kw in RUNS:
            kw = dict(kw)
            if metric == "vertical":
                kw["zeta"] = VERTICAL_ZETA[name]
            hf, rjob, rows, seconds = run(values, metric, **kw)
            cols.append((name, paper, kw["zeta"], rows))
            timing.append((name, metric, hf, rows[-1][2], seconds))
            head += f" {name} T | E_max |"
            sep += "---:|---:|"
            if metric == "normal":
                head += f" paper {paper} T | E_max |"
                sep += "---:|---:|"
        out += [head, sep]
        for i in range(5):
            m = 4 - i
            line = f"| {m} |"
            for _name, paper, _zeta, rows in cols:
                r = rows[i]
                e = r[3] if metric == "normal" else r[4]
                line += f" {r[2]} | {e:.3f} |"
                if metric == "normal":
                    p = PAPER_5_6[paper][i]
                    line += f" {p[1]} | {p[2]:.2f} |"
            out.append(line)
        out += ["", "zeta: " + ", ".join(f"{n} {z:g}" for n, _, z,
                                         _ in cols) + ".  Splits, vertex movements and "
                "swaps per level:", ""]
        out += ["| data | level | vertices | triangles | splits | moves | swaps | E_max normal | E_max vertical |",
                "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for name, _, _, rows in cols:
            for r in rows:
                out.append(f"| {name} | {r[0]} | {r[1]} | {r[2]} | {r[5]} | {r[6]} | {r[7]} | {r[3]:.3f} | {r[4]:.3f} |")
        out.append("")
    # the error bound alone (k = 0): what the wavelet-driven levels add or save
    out += ["### The error bound alone", "",
            "The same runs with `--iterations 0`: only the greedy loop of the error bound (worst triangle first,",
            "split at its worst sample), for comparison with the wavelet-driven levels:", "",
            "| data | metric | zeta | triangles, k = 0 | triangles, full |", "|---|---|---:|---:|---:|"]
    for name, values, _, kw in RUNS:
        for metric in ("normal", "vertical"):
            kw2 = dict(kw, iterations=0)
            if metric == "vertical":
                kw2["zeta"] = VERTICAL_ZETA[name]
            _, rjob, rows, _ = run(values, metric, **kw2)
            full = next(t for t in timing if t[0] == name and t[1] == metric)
            out.append(f"| {name} | {metric} | {kw2['zeta']:g} | {rows[-1][2]} | {full[3]} |")
    out += ["", "### Run time and memory", "",
            "Native build (`-O2`, x86-64, one core), the whole refinement in the library (all levels, the error",
            "bound and the export of every level; not the Python checks), one run:", "",
            "| data | metric | grid | triangles | run time |", "|---|---|---|---:|---:|"]
    for name, metric, hf, tris, seconds in timing:
        out.append(f"| {name} | {metric} | {hf.width} x {hf.height} | {tris} | {seconds:.3f} s |")
    out += ["",
            f"Storage per triangle slot: **{per_tri:.0f} bytes** (`wm_refine_bound`), against the dissertation's",
            "183 bytes (Table 5.3); see \"Memory\" above for the breakdown.", ""]
    return "\n".join(out)


DECISIONS = open(Path(__file__).with_name("refiner_decisions.md")).read()


def document() -> str:
    return DECISIONS.rstrip() + "\n\n" + results()


def normalise(text: str) -> str:
    return re.sub(r"\d+\.\d+ s \|", "X s |", text)


def main(argv: list[str]) -> int:
    text = document()
    if "--check" in argv:
        if not DOC.exists() or normalise(DOC.read_text()) != normalise(text):
            print("docs/refiner.md is stale: run .venv/bin/python firmware/tools/make_refiner_doc.py")
            return 1
        return 0
    DOC.write_text(text)
    print(f"wrote {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
