"""Pictures of meshes and height fields, in the style of the 2003 dissertation's figures.

Flat-shaded triangles: each triangle gets one colour, from its mean height on
matplotlib's ``cool`` colormap (cyan = low, magenta = high), darkened by a
Lambertian term ``ambient + (1 - ambient) * max(0, n . l)`` with ``n`` the
triangle's normal in ``(x, y, z * zscale)`` space and ``l`` a fixed light from
the north-west (the upper left of a top view) and above.  Optional thin black
wireframe edges, white background, no axes.

Two views:

- ``"top"``: orthographic from above, x to the right, row 0 at the top (like
  an image), equal aspect.
- ``"3d"``: an oblique orthographic view computed here (rotate by azim/elev,
  project, sort triangles back to front: painter's algorithm) and drawn as one
  2-D :class:`~matplotlib.collections.PolyCollection`.  The viewer's horizontal
  direction in grid coordinates ``(x, row)`` is ``(-cos azim, -sin azim)``;
  the default ``azim=-60`` looks at the map from the south-south-west (row 0 at
  the back, x growing to the right).  Triangles facing away from the viewer are
  culled when ``elev > 0`` (they can never be seen on a height field).

Figures are built with :class:`matplotlib.figure.Figure` and the Agg canvas, never
pyplot, so rendering works headless and from threads and does not touch the
global backend.
"""

from __future__ import annotations

import math
import os

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from wavemesh.errors import InputError
from wavemesh.mesh import Mesh

__all__ = ["render_mesh", "render_heightfield", "render_grid", "grid_mesh"]

AMBIENT = 0.35
# Light from the north-west and above, in the right-handed frame (east=x, north=-row, up=z).
_LIGHT = np.array([-1.0, 1.0, 2.5])
_LIGHT = _LIGHT / np.linalg.norm(_LIGHT)
_DPI = 100.0
_VIEWS = ("3d", "top")
_MAX_HEIGHTFIELD_CELLS = 200  # per side, for render_heightfield
_PAD = 0.03  # fraction of the drawing's extent left free around it


# ----------------------------------------------------------------------------- helpers


def _check_path(path) -> str:
    """The path as a string; InputError when its directory is missing or its type unknown."""
    p = os.fspath(path)
    if not isinstance(p, str):
        p = os.fsdecode(p)
    d = os.path.dirname(os.path.abspath(p))
    if not os.path.isdir(d):
        raise InputError(f"cannot write picture {p}: directory {d} does not exist")
    if os.path.isdir(p):
        raise InputError(f"cannot write picture {p}: it is a directory")
    ext = os.path.splitext(p)[1].lower().lstrip(".")
    supported = FigureCanvasAgg.get_supported_filetypes()
    if ext not in supported:
        raise InputError(
            f"cannot write picture {p}: unknown picture type '.{ext}'",
            hint="use .png, .svg or .pdf",
        )
    return p


def _save(fig: Figure, path: str) -> None:
    try:
        fig.savefig(path, dpi=_DPI, facecolor="white")
    except OSError as e:
        raise InputError(f"cannot write picture {path}: {e.strerror or e}") from None


def _new_figure(w_px: int, h_px: int) -> Figure:
    if w_px < 1 or h_px < 1:
        raise InputError(f"picture size must be positive, got {w_px}x{h_px}")
    # The tiny excess keeps int(figsize * dpi) from truncating to one pixel less.
    fig = Figure(figsize=((w_px + 1e-3) / _DPI, (h_px + 1e-3) / _DPI), dpi=_DPI, facecolor="white")
    FigureCanvasAgg(fig)
    return fig


def _check_view(view: str) -> None:
    if view not in _VIEWS:
        raise InputError(f"unknown view '{view}' (choose from {', '.join(_VIEWS)})")


def _default_zscale(extent: float, zrange: float) -> float:
    """Vertical scale that makes the z extent 0.25 * the larger horizontal extent (1 for flat data)."""
    if not (zrange > 0) or not math.isfinite(zrange):
        return 1.0
    return 0.25 * max(extent, 1.0) / zrange


def _edge_width(n_tris: int, base: float = 0.5) -> float:
    """Wireframe line width in points: ``base`` for small meshes, thinner for large ones."""
    if n_tris <= 2000:
        return base
    return max(0.06, base * math.sqrt(2000.0 / n_tris))


def _fit_limits(ax, x0, x1, y0, y1, box_w: float, box_h: float) -> None:
    """Set equal-aspect limits showing [x0, x1] x [y0, y1] (plus padding) in a box_w x box_h box."""
    if not (math.isfinite(x0) and math.isfinite(x1) and math.isfinite(y0) and math.isfinite(y1)):
        x0, x1, y0, y1 = 0.0, 1.0, 0.0, 1.0
    dx, dy = max(x1 - x0, 1e-9), max(y1 - y0, 1e-9)
    pad = _PAD * max(dx, dy)
    dx, dy = dx + 2 * pad, dy + 2 * pad
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    aspect = box_w / max(box_h, 1e-9)  # data units per pixel must match in x and y
    if dx / dy < aspect:
        dx = dy * aspect
    else:
        dy = dx / aspect
    ax.set_xlim(cx - dx / 2, cx + dx / 2)
    ax.set_ylim(cy - dy / 2, cy + dy / 2)


def _draw(ax, box_w: float, box_h: float, mesh: Mesh, z, *, view: str, wireframe: bool,
          zscale: float | None, elev: float, azim: float, edge_base: float = 0.5, en=None) -> float:
    """Draw the shaded mesh into ``ax`` (axes box of box_w x box_h pixels); returns the zscale used.
    ``en``: per-vertex (east, north) in the heights' unit (true aspect); default (col, -row)."""
    ax.set_axis_off()
    z = np.asarray(z, dtype=np.float64).reshape(-1)
    if z.shape[0] != mesh.n_vertices:
        raise ValueError(f"z has {z.shape[0]} values, the mesh has {mesh.n_vertices} vertices")
    xy = mesh.xy.astype(np.float64)
    tris = mesh.tris
    finite = np.isfinite(z)
    if len(tris):
        tris = tris[finite[tris].all(axis=1)]
    zf = z[finite]
    zmin = float(zf.min()) if zf.size else 0.0
    zmax = float(zf.max()) if zf.size else 0.0
    zrange = zmax - zmin
    if en is None:
        en = np.column_stack([xy[:, 0], -xy[:, 1]])
    en = np.asarray(en, dtype=np.float64)
    if zscale is None:
        zscale = _default_zscale(float(np.ptp(en, axis=0).max()) if len(en) else 0.0, zrange)
    zz = np.where(finite, z - zmin, 0.0) * float(zscale)

    # Physical right-handed frame: east, north, up = z * zscale.
    P = np.column_stack([en[:, 0], en[:, 1], zz])

    if view == "top":
        sx, sy = P[:, 0], P[:, 1]
        depth = None
    else:
        # Viewer direction (-cos azim, -sin azim) in (x, row) is (-cos azim, sin azim) in (east, north).
        a = math.radians(180.0 - azim)
        e = math.radians(elev)
        d = np.array([math.cos(a), math.sin(a)])  # horizontal direction towards the viewer
        r = np.array([-math.sin(a), math.cos(a)])  # screen right
        dh = P[:, :2] @ d
        sx = P[:, :2] @ r
        sy = -math.sin(e) * dh + math.cos(e) * P[:, 2]
        depth = math.cos(e) * dh + math.sin(e) * P[:, 2]  # larger = nearer the viewer

    if len(tris):
        sx_t, sy_t = sx[tris], sy[tris]
        if depth is not None and elev > 0:
            # Front faces keep on screen the turn they have seen from above in (east, north) (the grid's
            # CCW in (x, row) is clockwise there when north = -row, as without a georeference).
            area = ((sx_t[:, 1] - sx_t[:, 0]) * (sy_t[:, 2] - sy_t[:, 0])
                    - (sx_t[:, 2] - sx_t[:, 0]) * (sy_t[:, 1] - sy_t[:, 0]))
            e0, e1, e2 = P[tris[:, 0], :2], P[tris[:, 1], :2], P[tris[:, 2], :2]
            turn = ((e1[:, 0] - e0[:, 0]) * (e2[:, 1] - e0[:, 1])
                    - (e2[:, 0] - e0[:, 0]) * (e1[:, 1] - e0[:, 1]))
            keep = area * turn > 0
            tris, sx_t, sy_t = tris[keep], sx_t[keep], sy_t[keep]
        if depth is not None:
            order = np.argsort(depth[tris].mean(axis=1), kind="stable")  # far first
            tris, sx_t, sy_t = tris[order], sx_t[order], sy_t[order]

    n = len(tris)
    if n:
        p0, p1, p2 = P[tris[:, 0]], P[tris[:, 1]], P[tris[:, 2]]
        nrm = np.cross(p1 - p0, p2 - p0)
        nrm[nrm[:, 2] < 0] *= -1.0  # orientation-independent: normals point up
        length = np.linalg.norm(nrm, axis=1)
        flat = ~(length > 0)
        nrm[flat] = (0.0, 0.0, 1.0)
        length[flat] = 1.0
        nrm /= length[:, None]
        intensity = AMBIENT + (1.0 - AMBIENT) * np.clip(nrm @ _LIGHT, 0.0, None)
        zmean = z[tris].mean(axis=1)
        t = (zmean - zmin) / zrange if zrange > 0 else np.full(n, 0.5)
        rgb = matplotlib.colormaps["cool"](np.clip(t, 0.0, 1.0))[:, :3] * intensity[:, None]
        fc = np.column_stack([rgb, np.ones(n)])
        verts = np.stack([sx_t, sy_t], axis=2)  # (n, 3, 2)
        if wireframe:
            ec, lw = "black", _edge_width(n, edge_base)
        else:
            ec, lw = fc, 0.25  # edges in the face colour hide antialiasing seams
        ax.add_collection(PolyCollection(verts, facecolors=fc, edgecolors=ec, linewidths=lw,
                                         antialiaseds=True, closed=True))
        _fit_limits(ax, float(sx_t.min()), float(sx_t.max()), float(sy_t.min()), float(sy_t.max()),
                    box_w, box_h)
    else:
        _fit_limits(ax, 0.0, float(max(mesh.width - 1, 1)), -float(max(mesh.height - 1, 1)), 0.0,
                    box_w, box_h)
    return float(zscale)


# ----------------------------------------------------------------------------- public API


def grid_mesh(xs: np.ndarray, ys: np.ndarray, width: int, height: int) -> Mesh:
    """Regular mesh on columns ``xs`` x rows ``ys`` (sorted grid coordinates), two CCW triangles per cell."""
    xs = np.asarray(xs, dtype=np.int64)
    ys = np.asarray(ys, dtype=np.int64)
    nx, ny = len(xs), len(ys)
    gx, gy = np.meshgrid(xs, ys)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    if nx < 2 or ny < 2:
        return Mesh(width, height, xy, np.zeros((0, 3), dtype=np.int64))
    idx = np.arange(nx * ny).reshape(ny, nx)
    a = idx[:-1, :-1].ravel()  # (x, y)
    b = idx[:-1, 1:].ravel()  # (x+1, y)
    c = idx[1:, :-1].ravel()  # (x, y+1)
    d = idx[1:, 1:].ravel()  # (x+1, y+1)
    tris = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return Mesh(width, height, xy, tris)


def render_mesh(mesh: Mesh, z: np.ndarray, path, *, view: str = "3d", wireframe: bool = True,
                zscale: float | None = None, size: tuple[int, int] = (800, 600), title: str | None = None,
                elev: float = 35.0, azim: float = -60.0, en=None, label: bool = False) -> None:
    """Render ``mesh`` with per-vertex heights ``z`` to a picture file (.png, .svg, .pdf, ...).

    ``en`` is each vertex's (east, north) in the heights' unit (wavemesh.io.georef.Ground.ground_xy: true
    aspect); by default (col, -row), one grid step a height unit.  ``zscale`` (the vertical
    exaggeration) multiplies heights for the 3d view and the shading; by default the z extent becomes
    a quarter of the larger horizontal extent (1 when all heights are equal).  ``label`` writes the
    exaggeration used into the picture's lower left corner.
    """
    _check_view(view)
    p = _check_path(path)
    w_px, h_px = int(size[0]), int(size[1])
    fig = _new_figure(w_px, h_px)
    title_px = 0
    if title:
        title_px = min(28, h_px // 4)
        fig.text(0.5, 1.0 - 4.0 / h_px, title, ha="center", va="top", fontsize=11)
    ax_h = max(h_px - title_px, 1)
    ax = fig.add_axes((0.0, 0.0, 1.0, ax_h / h_px))
    used = _draw(ax, w_px, ax_h, mesh, z, view=view, wireframe=wireframe, zscale=zscale, elev=elev, azim=azim,
                 en=en)
    if label and view == "3d":
        how = "true aspect" if used == 1 else ("automatic" if zscale is None else "--exaggeration")
        fig.text(4.0 / w_px, 4.0 / h_px, f"vertical exaggeration {used:.3g}x ({how})", ha="left", va="bottom",
                 fontsize=9, color="0.25")
    _save(fig, p)


def render_heightfield(heights: np.ndarray, path, **kw) -> None:
    """Render a (H, W) height field as a regular grid mesh (subsampled to at most ~200 x 200 cells).

    Keyword arguments are those of :func:`render_mesh`.
    """
    h = np.asarray(heights, dtype=np.float64)
    if h.ndim != 2 or h.shape[0] < 1 or h.shape[1] < 1:
        raise InputError(f"a height field must be a 2-D array, got shape {h.shape}")
    H, W = h.shape
    step = max(1, math.ceil(max(H - 1, W - 1) / _MAX_HEIGHTFIELD_CELLS))
    xs = np.unique(np.append(np.arange(0, W, step), W - 1))
    ys = np.unique(np.append(np.arange(0, H, step), H - 1))
    mesh = grid_mesh(xs, ys, W, H)
    render_mesh(mesh, mesh.z(h), path, **kw)


def render_grid(items: list[tuple[Mesh, np.ndarray, str]], path, *, cols: int = 8, view: str = "top",
                wireframe: bool = True, cell_px: int = 160) -> None:
    """A sheet of small renders, ``cols`` per row, each ``cell_px`` square with its caption on top.

    The picture is ``min(cols, len(items)) * cell_px`` wide and ``ceil(len(items) / cols) * cell_px`` high.
    """
    _check_view(view)
    p = _check_path(path)
    items = list(items)
    if not items:
        raise InputError("nothing to render: the list of meshes is empty")
    if cols < 1 or cell_px < 8:
        raise InputError(f"render_grid needs cols >= 1 and cell_px >= 8, got {cols} and {cell_px}")
    ncols = min(cols, len(items))
    nrows = math.ceil(len(items) / cols)
    W, H = ncols * cell_px, nrows * cell_px
    fig = _new_figure(W, H)
    cap_px = max(10, round(cell_px * 0.12))
    fontsize = max(5.0, min(9.0, cell_px / 20.0))
    margin = max(2, cell_px // 40)
    for k, (mesh, z, caption) in enumerate(items):
        r, c = divmod(k, cols)
        x0 = c * cell_px
        top = H - r * cell_px  # pixel y of the cell's top edge (origin bottom-left)
        fig.text((x0 + cell_px / 2) / W, (top - 2) / H, str(caption), ha="center", va="top",
                 fontsize=fontsize, clip_on=True)
        bw = cell_px - 2 * margin
        bh = max(cell_px - cap_px - 2 * margin, 1)
        ax = fig.add_axes(((x0 + margin) / W, (top - cap_px - margin - bh) / H, bw / W, bh / H))
        _draw(ax, bw, bh, mesh, z, view=view, wireframe=wireframe, zscale=None, elev=35.0, azim=-60.0,
              edge_base=0.4)
    _save(fig, p)
