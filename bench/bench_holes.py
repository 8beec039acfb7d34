"""Holes against filling (issue 20): `--nodata hole` and `--fill nearest` at the same zeta, on a disparity
map with real dropouts (Middlebury's Motorcycle, scikit-image's copy: 27,226 unknown pixels) and on the
synthetic sets with a synthesised scanner shadow.  Triangles, vertices, E_max, and the hole mesh's check
(wavemesh.holes.check: nothing over an invalid sample, coverage of the valid ones)."""

from __future__ import annotations

import time

import numpy as np

TITLE = "Holes against filling (`make bench-holes`)"
SYNTHETIC = ("f1", "f2", "f3", "f4", "f5", "ball", "box")
ZETA_FRACTION = 0.005  # zeta = this fraction of the height range (the synthetic sets)
SHADOW_DROP = 3.0  # the scanner's ray falls by this many height ranges across the grid


def shadow(z: np.ndarray, drop: float = SHADOW_DROP) -> np.ndarray:
    """z with NaN where a scanner left of the grid, its ray falling by ``drop`` height ranges across the
    grid, does not see the surface (the samples below the ray through a higher sample on their left)."""
    w = z.shape[1]
    fall = drop * float(z.max() - z.min()) / w * np.arange(w)[None, :]
    ray = np.maximum.accumulate(z + fall, axis=1)
    out = z.astype(np.float64).copy()
    out[z + fall < ray - 1e-9 * max(1.0, float(np.abs(z).max()))] = np.nan
    return out


def motorcycle_raw() -> np.ndarray:
    from datasets import package_file

    path = package_file("scikit-image", "skimage/data/motorcycle_disp.npz")
    return np.load(path)["arr_0"].astype(np.float64)


def one(name: str, z: np.ndarray, zeta: float) -> dict:
    from wavemesh import api, holes
    from wavemesh.heightfield import from_array
    from wavemesh.native import RefineParams

    params = api.MeshParams(refine=RefineParams(zeta=zeta))
    row = {"name": name, "width": z.shape[1], "height": z.shape[0], "zeta": zeta,
           "invalid": int((~np.isfinite(z)).sum())}
    for mode, hf in (("hole", from_array(z, holes=True)), ("fill", from_array(z, fill="nearest"))):
        t0 = time.process_time()
        r = api.mesh(hf, params)
        row[mode] = {"triangles": r.mesh.n_triangles, "vertices": r.mesh.n_vertices, "e_max": r.e_max,
                     "cpu_s": round(time.process_time() - t0, 3)}
        if mode == "hole":
            row[mode]["check"] = r.report.get("holes")  # None: the shadow left every sample valid
            row["stranded"] = hf.stranded
            row["enclosed_holes"] = holes.enclosed_holes(hf.mask) if hf.mask is not None else 0
    row["ratio"] = row["hole"]["triangles"] / row["fill"]["triangles"]
    return row


def run() -> dict:
    from wavemesh.synth import make

    rows = []
    d = motorcycle_raw()
    for zeta in (0.5, 1.0, 2.0):
        rows.append(one("motorcycle (real dropouts)", d, zeta))
    for name in SYNTHETIC:
        z = make(name).astype(np.float64)
        rows.append(one(f"{name} + shadow", shadow(z), ZETA_FRACTION * float(z.max() - z.min())))
    return {"rows": rows, "zeta_fraction": ZETA_FRACTION, "shadow_drop": SHADOW_DROP}


def markdown(results: dict) -> str:
    lines = [
        "`wavemesh mesh --nodata hole` against `--fill nearest` at the same zeta (normal metric, defaults "
        "otherwise; bench/bench_holes.py).  Motorcycle: Middlebury 2014's ground-truth disparity in "
        "scikit-image (741 x 500, px), its unknown pixels as they come.  Synthetic sets (wavemesh synth, "
        f"zeta {results['zeta_fraction']:g} of the height range) with a scanner's shadow: NaN where a ray "
        f"from the left, falling {results['shadow_drop']:g} height ranges across the grid, does not reach.  "
        "`stranded`: valid samples no grid cell with three valid corners has as a corner (isolated samples, "
        "one-sample-wide lines: no triangle of grid samples covers them without an invalid one), meshed as "
        "invalid (holes.stranded); `covered`: the other valid samples in a triangle, of all of them; "
        "`over`: triangles over an invalid sample.  `bound`: 5h + 1, "
        "h the groups of invalid samples the valid ones enclose (holes.enclosed_holes): fewer triangles "
        "than this no mesh has that leaves every such group a hole with a rim of its own (Euler, 3 "
        "vertices a rim); `hole / fill`: the triangle ratio.",
        "",
        "| grid | size | invalid | stranded | zeta | fill: triangles | hole: triangles | hole / fill | "
        "bound | hole E_max | covered | over |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results["rows"]:
        n = r["width"] * r["height"]
        c = r["hole"]["check"] or {"covered_valid": n, "valid_samples": n, "triangles_over_invalid": 0,
                                   "uncovered_coverable": 0}
        bound = 5 * r["enclosed_holes"] + 1 if r["invalid"] else "-"
        lines.append(f"| {r['name']} | {r['width']} x {r['height']} | {r['invalid']} | {r['stranded']} | "
                     f"{r['zeta']:.4g} | {r['fill']['triangles']} | {r['hole']['triangles']} | "
                     f"{r['ratio']:.2f} | {bound} | "
                     f"{r['hole']['e_max']:.4g} | {c['covered_valid']} / {c['valid_samples']} | "
                     f"{c['triangles_over_invalid']} |")
    ratios = [r["ratio"] for r in results["rows"] if r["invalid"]]
    real = [r["ratio"] for r in results["rows"] if "real" in r["name"]]
    moto = [r for r in results["rows"] if "real" in r["name"]]
    need = 5 * moto[0]["enclosed_holes"] + 1
    under = [r for r in moto if r["fill"]["triangles"] < need]
    lines += ["", f"Median hole / fill over the rows with invalid samples {float(np.median(ratios)):.2f} "
              "(the shadow leaves f1, f3 and f4 whole); on the real dropouts "
              f"{min(real):.2f} .. {max(real):.2f}: outlining every speckle of a real scan costs triangles "
              "that bridging it with invented surface does not; a shadow behind a depth jump saves them.  "
              f"Motorcycle's {moto[0]['enclosed_holes']} enclosed groups of dropouts need {need} triangles "
              "at least" + (", more than `--fill nearest` uses at "
                            + ", ".join(f"zeta {r['zeta']:g} ({r['fill']['triangles']})" for r in under)
                            + ": there no mesh that keeps every dropout a hole (rims sharing no vertex) has "
                            "fewer triangles than the filled one." if under else ".")]
    return "\n".join(lines) + "\n"
