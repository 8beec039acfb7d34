"""Selective triangulation (dissertation 5.6): a region of interest (ROI) refined, the rest left coarse.

The dissertation suppresses "all wavelet coefficients corresponding to a region" with a mask, so that
"no refinement takes place in that region" and it "remains in its primitive stage".  Here ``--roi``
names the region to keep (rectangles or a mask image) and the job does three things with it:

- the details of levels 1 .. M-1 are set to 0 in every cell that holds no ROI sample
  (:func:`mask_details`), so the energy test of 4.12 selects nothing outside; level M's are kept,
  so the initial triangulation (the "primitive stage") covers the whole grid as without an ROI;
- the refiner measures E(T) over the ROI samples of a triangle only (firmware/src/roi.c,
  ``wm_refine_set_roi``): a triangle with none is never refined, and the error bound ends with every
  ROI sample within zeta;
- the errors are measured twice: inside the ROI (the bound, :func:`roi_errors`) and over the whole
  grid (what the coarse outside costs), and the triangles counted on each side (:func:`roi_report`).

Coordinates are those of the grid being meshed (after --crop and --decimate): a rectangle
``X,Y,W,H`` is W x H samples from column X, row Y; an image (PNG, PGM, .npy, ...) must have the
grid's size, and its non-zero samples are the ROI.  Several ``--roi`` add up.
"""

from __future__ import annotations

import os

import numpy as np

from wavemesh.check import ErrorReport, mesh_errors
from wavemesh.errors import InputError
from wavemesh.mesh import Mesh
from wavemesh.model.haar import HaarLevel


def parse_roi(specs, width: int, height: int) -> np.ndarray:
    """The (H, W) bool ROI of ``specs``: a bool/0-1 array of the grid's shape, or strings, each a
    rectangle ``X,Y,W,H`` or a mask image's path (non-zero: inside).  InputError for anything else,
    a rectangle off the grid, an image of another size, or an empty ROI."""
    if isinstance(specs, np.ndarray):
        roi = specs.astype(bool)
        if roi.shape != (height, width):
            raise InputError(f"the ROI mask is {roi.shape[1]} x {roi.shape[0]} but the grid is "
                             f"{width} x {height}", hint="give a mask of the grid's size")
        return _non_empty(roi, "the ROI mask")
    roi = np.zeros((height, width), dtype=bool)
    for spec in specs:
        roi |= _one(str(spec), width, height)
    return _non_empty(roi, "--roi " + " --roi ".join(map(str, specs)))


def _non_empty(roi: np.ndarray, what: str) -> np.ndarray:
    if not roi.any():
        raise InputError(f"{what} selects no sample of the grid",
                         hint="give rectangles X,Y,W,H inside the grid, or a mask with non-zero samples")
    return roi


def _one(spec: str, width: int, height: int) -> np.ndarray:
    parts = spec.split(",")
    if len(parts) == 4 and not os.path.exists(spec):
        try:
            x, y, w, h = (int(v) for v in parts)
        except ValueError:
            raise InputError(f"--roi {spec}: not four integers X,Y,W,H nor a mask file",
                             hint="give --roi X,Y,W,H (samples) or --roi MASK.png") from None
        if x < 0 or y < 0 or w < 1 or h < 1 or x + w > width or y + h > height:
            raise InputError(f"--roi {spec} does not fit the {width} x {height} grid",
                             hint="X + W <= width, Y + H <= height, W and H at least 1 (after --crop and "
                                  "--decimate)")
        out = np.zeros((height, width), dtype=bool)
        out[y:y + h, x:x + w] = True
        return out
    from wavemesh.io.heightfield import load_heightfield  # the height field readers read masks too

    if not os.path.exists(spec):
        raise InputError(f"--roi {spec}: no such file, and not a rectangle X,Y,W,H",
                         hint="give --roi X,Y,W,H (samples) or --roi MASK.png")
    img = load_heightfield(spec, fill="0").values
    if img.shape != (height, width):
        raise InputError(f"--roi {spec} is {img.shape[1]} x {img.shape[0]} but the grid is "
                         f"{width} x {height}",
                         hint="the mask must have the size of the grid meshed (after --crop and --decimate)")
    return img != 0


def cell_mask(roi: np.ndarray, m: int) -> np.ndarray:
    """The cells of decomposition level m (ceil(H / 2^m) x ceil(W / 2^m)) that hold an ROI sample: the
    half-open 2^m x 2^m boxes a coefficient is computed from, clipped at the edge.  Given the invalid
    samples, the filter bank's per-coefficient hole flag (rtl/haar_bank.v, HOLES = 1)."""
    s = 1 << m
    h, w = roi.shape
    ch, cw = -(-h // s), -(-w // s)
    pad = np.zeros((ch * s, cw * s), dtype=bool)
    pad[:h, :w] = roi
    return pad.reshape(ch, s, cw, s).any(axis=(1, 3))


def mask_details(levels: list[HaarLevel], roi: np.ndarray) -> list[HaarLevel]:
    """The details of levels 1 .. M-1 set to 0 in the cells without an ROI sample (5.6's mask); level M
    (the initial triangulation's) as it is."""
    out = []
    for lv in levels:
        if lv.m == len(levels):
            out.append(lv)
            continue
        keep = cell_mask(roi, lv.m)
        out.append(HaarLevel(lv.m, lv.a, *(np.where(keep, d, 0) for d in (lv.d1, lv.d2, lv.d3))))
    return out


def surface(mesh: Mesh, heights: np.ndarray) -> np.ndarray:
    """The mesh's piecewise-linear surface at every grid sample, (H, W) float64."""
    import matplotlib.tri as mtri  # start-up: matplotlib (about 150 ms) only for ROI errors

    z = mesh.z(heights).astype(np.float64)
    tri = mtri.Triangulation(mesh.xy[:, 0].astype(np.float64), mesh.xy[:, 1].astype(np.float64), mesh.tris)
    gy, gx = np.mgrid[0:mesh.height, 0:mesh.width]
    s = mtri.LinearTriInterpolator(tri, z)(gx.astype(np.float64), gy.astype(np.float64))
    out = np.ma.filled(s, np.nan)
    if np.isnan(out).any():  # a sample on no triangle: only in an improper mesh
        raise InputError("the mesh does not cover every sample of the grid")
    return out


def roi_errors(mesh: Mesh, heights: np.ndarray, roi: np.ndarray, *, rms: bool = False,
               spacing: tuple[float, float] = (1.0, 1.0)) -> ErrorReport:
    """The errors of check.mesh_errors over the ROI samples alone: the samples outside are put on the
    mesh's own surface (distance 0 to the triangle holding them), the vertices keep their heights."""
    h = np.asarray(heights, dtype=np.float64)
    inside = np.where(roi, h, surface(mesh, h))
    return mesh_errors(mesh, inside, z=mesh.z(h), rms=rms, spacing=spacing)


def roi_report(mesh: Mesh, roi: np.ndarray, inside: ErrorReport, whole: ErrorReport, metric: str) -> dict:
    """The report's "roi" entry: the ROI's size, triangles and vertices on each side (a triangle by the
    sample nearest its barycentre), E_max inside (where the bound holds) and over the whole grid."""
    c = mesh.xy[mesh.tris].mean(axis=1)
    cx = np.clip(np.rint(c[:, 0]).astype(np.int64), 0, mesh.width - 1)
    cy = np.clip(np.rint(c[:, 1]).astype(np.int64), 0, mesh.height - 1)
    t_in = int(np.count_nonzero(roi[cy, cx]))
    v_in = int(np.count_nonzero(roi[mesh.xy[:, 1], mesh.xy[:, 0]]))
    key = "e_max_normal" if metric == "normal" else "e_max_vertical"
    return {
        "samples": int(np.count_nonzero(roi)),
        "fraction": float(np.count_nonzero(roi) / roi.size),
        "triangles_inside": t_in,
        "triangles_outside": mesh.n_triangles - t_in,
        "vertices_inside": v_in,
        "vertices_outside": mesh.n_vertices - v_in,
        "e_max_inside": float(getattr(inside, key)),
        "e_max_inside_vertical": float(inside.e_max_vertical),
        "e_max_whole": float(getattr(whole, key)),
    }
