"""Holes against filling: `--nodata hole` and `--fill nearest` at the same zeta, on a disparity
map with real dropouts (Middlebury's Motorcycle, scikit-image's copy: 27,226 unknown pixels) and on the
synthetic sets with a synthesised scanner shadow.  Triangles, vertices, E_max, and the hole mesh's check
(wavemesh.check.check_holes: nothing over an invalid sample, coverage of the valid ones)."""

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


MAX_HOLES = (4, 16, 64)  # --max-hole N columns: enclosed dropouts of at most N samples bridged


def structure(mesh) -> dict:
    """Where a hole mesh's triangles go: T = 2 V_i + B + 2 H - 2 P (Euler on each edge-connected piece,
    its pinch vertices split), V_i inner vertices, B edges of one triangle (rims and the rectangle's
    sides), H hole rims (boundary cycles that wind clockwise), P pieces; ``pinch``: vertices where rims
    meet (two or more boundary passages); ``pinholes``: rims whose hole holds one sample alone (an
    invalid one: the mesh covers every valid sample), by their number of edges (3 is the least: a
    lattice triangle with one inner sample)."""
    from collections import Counter

    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    t = mesh.tris.tolist()
    third = {(a[k], a[(k + 1) % 3]): a[(k + 2) % 3] for a in t for k in range(3)}
    owner_of = {(a[k], a[(k + 1) % 3]): i for i, a in enumerate(t) for k in range(3)}
    bnd = [e for e in third if e[::-1] not in third]
    bset = set(bnd)
    passes = Counter(a for a, _ in bnd)
    owner, rows, cols = {}, [], []
    for i, a in enumerate(t):
        for k in range(3):
            key = frozenset((a[k], a[(k + 1) % 3]))
            if key in owner:
                rows.append(i)
                cols.append(owner[key])
            owner[key] = i
    n = len(t)
    pieces, label = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)),
                                         directed=False)
    main = int(np.argmax(np.bincount(label)))
    seen, rims, on_rims, on_main, pinholes = set(), 0, 0, 0, Counter()
    x, y = mesh.xy[:, 0].astype(np.int64), mesh.xy[:, 1].astype(np.int64)
    for e in bnd:  # boundary cycles, each followed through its own piece's fan
        if e in seen:
            continue
        area, corners, piece = 0, [], label[owner_of[e]]
        while e not in seen:
            seen.add(e)
            a, b = e
            area += int(x[a] * y[b] - x[b] * y[a])
            corners.append(a)
            c = third[e]
            while (b, c) not in bset:
                c = third[(c, b)]
            e = (b, c)
        length = len(corners)
        rims += area < 0
        on_rims += length if area < 0 else 0
        on_main += length if area > 0 and piece == main else 0
        if area < 0:  # Pick: 2 I = 2 A - (lattice points on the rim) + 2; every inner sample is invalid
            ring = mesh.xy[corners].astype(np.int64)
            d = np.abs(np.roll(ring, -1, axis=0) - ring)
            if -area - int(np.gcd(d[:, 0], d[:, 1]).sum()) + 2 == 2:
                pinholes[length] += 1
    return {"inner": len(mesh.xy) - len(passes), "boundary_edges": len(bnd), "rims": rims,
            "pieces": int(pieces), "pinch": sum(m > 1 for m in passes.values()),
            "edges_on_rims": on_rims, "edges_around_main": on_main,
            "edges_around_others": len(bnd) - on_rims - on_main,
            "pinholes": {str(k): v for k, v in sorted(pinholes.items())}}


def motorcycle_matched(max_d: int = 64, win: int = 9) -> np.ndarray:
    """A disparity map as a stereo block matcher gives it, with its invalid pixels: scikit-image's
    Motorcycle pair (grey), sum of absolute differences over win x win windows, the best of disparities
    0 .. max_d - 1 for the left and the right image, a parabola through the costs for sub-pixel
    disparities; NaN where the two disagree by more than a pixel (occlusions, mismatches), at the search
    range's ends, and where the window leaves the right image.  Held out: measured, never tuned on."""
    from datasets import package_file
    from PIL import Image
    from scipy import ndimage

    left, right = (np.asarray(Image.open(package_file("scikit-image", f"skimage/data/motorcycle_{s}.png"))
                              .convert("L"), dtype=np.float32) for s in ("left", "right"))
    h, w = left.shape

    def costs(a, b, sign):
        out = np.empty((max_d, h, w), np.float32)
        for d in range(max_d):
            diff = np.full((h, w), 255.0, np.float32)
            if sign > 0:  # a's column x against b's x - d
                diff[:, d:] = np.abs(a[:, d:] - b[:, :w - d])
            else:  # a's column x against b's x + d
                diff[:, :w - d] = np.abs(a[:, :w - d] - b[:, d:])
            out[d] = ndimage.uniform_filter(diff, win)
        return out

    cl = costs(left, right, 1)
    dl = cl.argmin(0)
    dr = costs(right, left, -1).argmin(0)
    x = np.arange(w)[None, :]
    back = np.take_along_axis(dr, np.clip(x - dl, 0, w - 1), 1)
    ok = (np.abs(dl - back) <= 1) & (x - dl >= 0) & (dl > 0) & (dl < max_d - 1)
    d0 = np.clip(dl, 1, max_d - 2)
    c0, c1, c2 = (np.take_along_axis(cl, (d0 + k)[None], 0)[0].astype(np.float64) for k in (-1, 0, 1))
    den = c0 - 2 * c1 + c2
    out = d0 + np.where(den > 0, 0.5 * (c0 - c2) / np.where(den > 0, den, 1.0), 0.0)
    out[~ok] = np.nan
    return out


def one(name: str, z: np.ndarray, zeta: float) -> dict:
    from wavemesh import api
    from wavemesh.io import bridge
    from wavemesh.io.heightfield import from_array
    from wavemesh.model import holemask
    from wavemesh.refine.native import RefineParams

    params = api.MeshParams(refine=RefineParams(zeta=zeta))
    row = {"name": name, "width": z.shape[1], "height": z.shape[0], "zeta": zeta,
           "invalid": int((~np.isfinite(z)).sum())}
    hole = from_array(z, holes=True)
    modes = [("hole", hole), ("fill", from_array(z, fill="nearest"))]
    modes += [(f"hole{n}", bridge.bridge(hole, n)) for n in MAX_HOLES if hole.mask is not None]
    for mode, hf in modes:
        t0 = time.process_time()
        r = api.mesh(hf, params)
        row[mode] = {"triangles": r.mesh.n_triangles, "vertices": r.mesh.n_vertices, "e_max": r.e_max,
                     "cpu_s": round(time.process_time() - t0, 3), "filled": hf.filled,
                     "check": r.report.get("holes")}  # None: every sample valid
        if mode == "hole":
            row["stranded"] = hf.stranded
            row["enclosed_holes"] = holemask.enclosed_holes(hf.mask) if hf.mask is not None else 0
            if hf.mask is not None:
                row["structure"] = structure(r.mesh)
    row["ratio"] = row["hole"]["triangles"] / row["fill"]["triangles"]
    return row


def run() -> dict:
    from wavemesh.io.synth import make

    rows = []
    d = motorcycle_raw()
    for zeta in (0.5, 1.0, 2.0):
        rows.append(one("motorcycle (real dropouts)", d, zeta))
    rows.append(one("motorcycle, block-matched (held out)", motorcycle_matched(), 1.0))
    for name in SYNTHETIC:
        z = make(name).astype(np.float64)
        rows.append(one(f"{name} + shadow", shadow(z), ZETA_FRACTION * float(z.max() - z.min())))
    return {"rows": rows, "zeta_fraction": ZETA_FRACTION, "shadow_drop": SHADOW_DROP,
            "max_holes": list(MAX_HOLES)}


def markdown(results: dict) -> str:
    caps = results.get("max_holes", [])
    lines = [
        "`wavemesh mesh --nodata hole` against `--fill nearest` at the same zeta (normal metric, defaults "
        "otherwise; bench/bench_holes.py).  Motorcycle: Middlebury 2014's ground-truth disparity in "
        "scikit-image (741 x 500, px), its unknown pixels as they come.  Synthetic sets (wavemesh synth, "
        f"zeta {results['zeta_fraction']:g} of the height range) with a scanner's shadow: NaN where a ray "
        f"from the left, falling {results['shadow_drop']:g} height ranges across the grid, does not reach.  "
        "Block-matched: the disparity of scikit-image's Motorcycle stereo pair as a simple block matcher "
        "gives it (bench_holes.motorcycle_matched: 9 x 9 sums of absolute differences, a left-right check; "
        "NaN where it fails): no package here ships a second range or depth image with invalid pixels; held "
        "out (measured, never tuned on).  "
        "`stranded`: valid samples no grid cell with three valid corners has as a corner (isolated samples, "
        "one-sample-wide lines: no triangle of grid samples covers them without an invalid one), meshed as "
        "invalid (holemask.stranded); `covered`: the other valid samples in a triangle, of all of them; "
        "`over`: triangles over an invalid sample.  "
        + ("`--max-hole N`: the hole mesh with the enclosed dropouts of at most N samples filled as "
           "--fill nearest fills them (bridge.bridge; triangles, and the samples filled), the others holes, "
           "every other valid sample covered and nothing over an invalid one (else the cell says NOT "
           "exact).  " if caps else "")
        + "`hole / fill`: the triangle ratio.  `5h + 1`: h the groups of invalid samples the valid ones "
        "enclose (holemask.enclosed_holes); a mesh of one piece whose hole rims share no vertex has at least "
        "this many triangles (Euler, 3 vertices a rim).  It is not a lower bound on every exact mesh: rims "
        "can share vertices (two holes pinched at a vertex need two triangles fewer than two apart) and the "
        "valid samples can fall into pieces, "
        "as the measured meshes do (the second table); no bound for every exact mesh is computed here.",
        "",
        "| grid | size | invalid | stranded | zeta | fill: triangles | hole: triangles | hole / fill | "
        + "".join(f"--max-hole {n}: triangles (filled) | / fill | " for n in caps)
        + "5h + 1 | hole E_max | covered | over |",
        "|---|---|---|---|---|---|---|---|" + "---|---|" * len(caps) + "---|---|---|---|",
    ]
    for r in results["rows"]:
        n = r["width"] * r["height"]
        c = r["hole"]["check"] or {"covered_valid": n, "valid_samples": n, "triangles_over_invalid": 0,
                                   "uncovered_coverable": 0}
        bound = 5 * r["enclosed_holes"] + 1 if r["invalid"] else "-"
        capped = ""
        for k in caps:
            m = r.get(f"hole{k}")
            if m is None:
                capped += "- | - | "
                continue
            exact = m["check"] is None or (m["check"]["triangles_over_invalid"] == 0
                                           and m["check"]["uncovered_coverable"] == 0)
            capped += (f"{m['triangles']} ({m['filled']}){'' if exact else ' NOT exact'} | "
                       f"{m['triangles'] / r['fill']['triangles']:.2f} | ")
        lines.append(f"| {r['name']} | {r['width']} x {r['height']} | {r['invalid']} | {r['stranded']} | "
                     f"{r['zeta']:.4g} | {r['fill']['triangles']} | {r['hole']['triangles']} | "
                     f"{r['ratio']:.2f} | {capped}{bound} | "
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
              f"Motorcycle's {moto[0]['enclosed_holes']} enclosed groups of dropouts would need {need} "
              "triangles in one piece with rims of their own"
              + (", more than `--fill nearest` uses at "
                 + ", ".join(f"zeta {r['zeta']:g} ({r['fill']['triangles']})"
                             for r in under) if under else "") + "."]
    for r in results["rows"]:
        if "held out" in r["name"]:
            lines[-1] += (f"  The block-matched disparity (held out): hole / fill {r['ratio']:.2f} at zeta "
                          f"{r['zeta']:g}: its dropouts sit at depth jumps (occlusions, mismatches), where "
                          "filling invents steps that cost triangles.")
    rows = [r for r in results["rows"] if "structure" in r]
    if rows:
        lines += ["", "Where the hole meshes' triangles go (holes with rims sharing vertices): T = 2 V_i + B "
                  "+ 2 H - 2 P (Euler on each edge-connected piece, its pinch vertices split): V_i inner "
                  "vertices, B edges of one triangle (hole rims and the rectangle's sides), H hole rims, "
                  "P pieces; `pinch`: vertices where rims meet.  B is most of T: the meshes are nearly all "
                  "rim, and a rim edge has a triangle of its own.  B's edges lie on hole rims (clockwise "
                  "cycles), around the largest piece (its outer border: the rectangle and the dropouts "
                  "that reach it) or around the other pieces (islands of valid samples among dropouts).", "",
                  "| grid | zeta | hole: triangles | V_i | B | B: on hole rims / around the largest piece / "
                  "around the other pieces | H | P | pinch vertices | one-sample holes: rim 3 / 4 / more | "
                  "5h + 1 |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            st = r["structure"]
            split = (f"{st['edges_on_rims']} / {st['edges_around_main']} / {st['edges_around_others']}"
                     if "edges_on_rims" in st else "-")
            ph = st.get("pinholes")
            pin = "-" if ph is None else (f"{ph.get('3', 0)} / {ph.get('4', 0)} / "
                                          f"{sum(v for k, v in ph.items() if int(k) > 4)}")
            lines.append(f"| {r['name']} | {r['zeta']:.4g} | {r['hole']['triangles']} | {st['inner']} | "
                         f"{st['boundary_edges']} | {split} | {st['rims']} | {st['pieces']} | "
                         f"{st['pinch']} | {pin} | {5 * r['enclosed_holes'] + 1} |")
    return "\n".join(lines) + "\n"
