"""Mesh files: Wavefront OBJ, PLY, binary STL and glTF binary written (:data:`FORMATS`, the one list of
them), OBJ and PLY read.

Writing
    :func:`write_mesh` writes the format its file name ends in, in the frame the options choose: grid
    positions without a georeference; with one, east, north and up in ground units from sample (0, 0)
    (``units="metres"``, as the .glb always is) or the CRS's own map coordinates (``units="crs"``),
    beside a sidecar naming the frame (wavemesh.io.georef), the triangles then counter-clockwise seen from
    above.  ``normals`` adds per-vertex unit normals (:func:`vertex_normals`), ``base`` closes the
    surface into a watertight solid (:func:`solid`).  :func:`write_obj` writes ``v x y z`` lines (x, y as
    integers, z as ``repr(float(z))``, the shortest text that reads back to the same double) and
    ``f i j k`` lines (1-based; ``f i//i j//j k//k`` with ``vn`` normals).  :func:`write_ply` writes
    ``binary_little_endian 1.0`` with ``double`` x, y, z per vertex and a
    ``list uchar int vertex_indices`` per face.  Both files carry the grid size
    as a comment, ``# wavemesh W H`` (OBJ) or ``comment wavemesh W H`` (PLY),
    written before any caller comment, so :func:`read_mesh` recovers W and H even
    when the mesh does not reach the last row or column.

Reading
    :func:`read_mesh` takes OBJ (``v``/``f`` statements; ``i``, ``i/j``,
    ``i/j/k``, ``i//k`` references; negative references relative to the
    vertices read so far; other OBJ statements ignored) and PLY (``ascii``,
    ``binary_little_endian``, ``binary_big_endian``; any scalar types; extra
    elements and properties ignored; the face list named ``vertex_indices`` or
    ``vertex_index``).  The format is recognised by the ``ply`` magic line, not
    the file name.  Only triangles are accepted, and every vertex must be a
    grid sample (integral x and y).  Every problem with a file is an
    :class:`InputError` with a one-line message naming the file; vertices and
    faces are numbered as the format numbers them (1-based in OBJ, 0-based in
    PLY).  Whether the triangles form a proper triangulation is not checked
    here (that is :func:`wavemesh.check.check_mesh`).
"""

from __future__ import annotations

import math
import os
import re
import struct
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wavemesh.errors import InputError
from wavemesh.io.georef import UNITS, grid_ground, read_sidecar, sidecar_path, write_sidecar
from wavemesh.io.georef import to_grid as placing
from wavemesh.io.heightfield import regular_file
from wavemesh.mesh import Mesh

__all__ = ["FORMATS", "write_obj", "write_ply", "write_mesh", "read_mesh", "vertex_normals", "normal_map"]

_TAG = "wavemesh"
_TAG_RE = re.compile(r"^wavemesh\s+(-?\d+)\s+(-?\d+)\s*$")
_CHUNK = 1 << 16  # vertices / faces formatted per write when writing OBJ

# Integral coordinates: |x - round(x)| below this counts as a grid sample.
_INTEGRAL_TOL = 1e-9
_COORD_LIMIT = float(1 << 40)  # larger coordinates are certainly not samples of a real grid


class _Bad(Exception):
    """A parse failure inside this module; read_mesh turns it into an InputError."""


# --------------------------------------------------------------------------------------------
# Writing


def _vertex_z(mesh: Mesh, heights: np.ndarray) -> np.ndarray:
    """z per vertex: ``heights`` is the (H, W) height field, or already a (V,) array of z."""
    h = np.asarray(heights, dtype=np.float64)
    if h.ndim == 1:
        if h.shape[0] != mesh.n_vertices:
            raise InputError(f"{h.shape[0]} vertex heights given for a mesh with {mesh.n_vertices} vertices")
        return h
    if h.shape != (mesh.height, mesh.width):
        raise InputError(
            f"the height field has {h.shape[-1] if h.ndim else 0} x {h.shape[0] if h.ndim else 0} samples "
            f"but the mesh is for a {mesh.width} x {mesh.height} grid"
        )
    x, y = mesh.xy[:, 0], mesh.xy[:, 1]
    out = (x < 0) | (x >= mesh.width) | (y < 0) | (y >= mesh.height)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise InputError(f"vertex {i} at ({x[i]}, {y[i]}) lies outside the {mesh.width} x {mesh.height} grid")
    return h[y, x]


def _comment_lines(comment: str | None) -> list[str]:
    if comment is None:
        return []
    return [line.rstrip("\r") for line in str(comment).splitlines()] or [""]


def _open_for_writing(path, binary: bool):
    try:
        if binary:
            return open(path, "wb")
        return open(path, "w", encoding="utf-8", newline="\n")
    except OSError as e:
        raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def _obj_vertex_lines(xy: np.ndarray, z: np.ndarray) -> str:
    """``v x y z`` lines, z as ``repr(float(z))``; formatted by one %-format in C, not line by line.
    Float x, y (map coordinates) are written as ``repr`` too."""
    n = len(xy)
    if xy.dtype.kind == "f":
        return ("v %r %r %r\n" * n) % tuple(np.column_stack([xy, z]).ravel().tolist())
    flat: list = [None] * (3 * n)
    flat[0::3] = xy[:, 0].tolist()
    flat[1::3] = xy[:, 1].tolist()
    # repr of an integral double below 1e16 is its integer and ".0" (-0.0 is the exception)
    if np.all((z == np.trunc(z)) & (np.abs(z) < 1e16) & ~((z == 0) & np.signbit(z))):
        flat[2::3] = z.astype(np.int64).tolist()
        return ("v %d %d %d.0\n" * n) % tuple(flat)
    flat[2::3] = z.tolist()
    return ("v %d %d %r\n" * n) % tuple(flat)


@dataclass(frozen=True)
class _Surface:
    """What a writer writes: vertices (x, y as grid positions (ints) or in the output frame (floats); z),
    triangles, per-vertex unit normals or None, the grid size and the comment."""

    width: int
    height: int
    xy: np.ndarray  # (V, 2)
    z: np.ndarray  # (V,)
    tris: np.ndarray  # (T, 3)
    normals: np.ndarray | None = None  # (V, 3)
    comment: str | None = None
    glb: tuple = ()  # write_glb's frame: (Ground, its east/north of the vertices (V, 2))


def write_obj(path, mesh: Mesh, heights: np.ndarray, comment: str | None = None,
              xy: np.ndarray | None = None) -> None:
    """Write ``mesh`` as a Wavefront OBJ file with z from ``heights`` ((H, W), or (V,) per vertex); x and y
    are the grid positions, or ``xy`` ((V, 2) floats: map coordinates) when given."""
    xy = mesh.xy if xy is None else np.asarray(xy, dtype=np.float64)
    _write_obj(path, _Surface(mesh.width, mesh.height, xy, _vertex_z(mesh, heights), mesh.tris,
                                    None, comment))


def _write_obj(path, s: _Surface) -> None:
    head = [f"# {_TAG} {s.width} {s.height}"]
    head += [f"# {c}" if c else "#" for c in _comment_lines(s.comment)]
    xy, z, tris = s.xy, s.z, s.tris
    face = "f %d %d %d\n" if s.normals is None else "f %d//%d %d//%d %d//%d\n"
    with _open_for_writing(path, binary=False) as f:
        try:
            f.write("\n".join(head) + "\n")
            for a in range(0, len(xy), _CHUNK):
                f.write(_obj_vertex_lines(xy[a : a + _CHUNK], z[a : a + _CHUNK]))
            if s.normals is not None:
                for a in range(0, len(xy), _CHUNK):
                    n = s.normals[a : a + _CHUNK]
                    f.write(("vn %.7g %.7g %.7g\n" * len(n)) % tuple(n.ravel().tolist()))
            for a in range(0, len(tris), _CHUNK):
                t = tris[a : a + _CHUNK] + 1
                if s.normals is not None:
                    t = np.repeat(t, 2, axis=1)
                f.write((face * len(t)) % tuple(t.ravel().tolist()))
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def write_ply(path, mesh: Mesh, heights: np.ndarray, comment: str | None = None,
              xy: np.ndarray | None = None) -> None:
    """Write ``mesh`` as a binary little-endian PLY file with z from ``heights`` (x, y as write_obj)."""
    xy = mesh.xy if xy is None else np.asarray(xy, dtype=np.float64)
    _write_ply(path, _Surface(mesh.width, mesh.height, xy, _vertex_z(mesh, heights), mesh.tris,
                                    None, comment))


def _write_ply(path, s: _Surface) -> None:
    V, T = len(s.xy), len(s.tris)
    if V >= 1 << 31:
        raise InputError(f"{V} vertices do not fit the PLY 'int' vertex index")
    head = ["ply", "format binary_little_endian 1.0", f"comment {_TAG} {s.width} {s.height}"]
    head += [f"comment {c}" if c else "comment" for c in _comment_lines(s.comment)]
    head += [f"element vertex {V}", "property double x", "property double y", "property double z"]
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if s.normals is not None:
        head += ["property float nx", "property float ny", "property float nz"]
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    head += [f"element face {T}", "property list uchar int vertex_indices", "end_header"]
    verts = np.empty(V, dtype=fields)
    verts["x"], verts["y"], verts["z"] = s.xy[:, 0], s.xy[:, 1], s.z
    if s.normals is not None:
        verts["nx"], verts["ny"], verts["nz"] = s.normals.T
    faces = np.empty(T, dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = s.tris
    with _open_for_writing(path, binary=True) as f:
        try:
            f.write(("\n".join(head) + "\n").encode("utf-8"))
            f.write(verts.tobytes())
            f.write(faces.tobytes())
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def _write_stl(path, s: _Surface) -> None:
    """Binary STL: an 80-byte header (not starting with "solid", which would read as ASCII STL), the
    triangle count, and per triangle its unit normal and three corners as float32."""
    pos = np.column_stack([s.xy, s.z]).astype(np.float64)
    corners = pos[s.tris]
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1), np.finfo(np.float64).tiny)[:, None]
    rec = np.zeros(len(s.tris), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = n, corners
    head = f"{_TAG} {s.width} {s.height} binary STL; {' '.join(_comment_lines(s.comment))}".encode()
    with _open_for_writing(path, binary=True) as f:
        try:
            f.write(head[:80].ljust(80, b" ") + struct.pack("<I", len(s.tris)) + rec.tobytes())
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def _write_glb(path, s: _Surface) -> None:
    """glTF binary through trimesh (module write_glb)."""
    import trimesh  # imported here: only .glb needs it

    g, en = s.glb
    # glTF's frame: x east, y up, z toward the viewer (south); a rotation of (east, north, up)
    verts = np.column_stack([en[:, 0], s.z, -en[:, 1]])
    tm = trimesh.Trimesh(vertices=verts, faces=s.tris, process=False, validate=False)
    if s.normals is not None:
        tm.vertex_normals = np.column_stack([s.normals[:, 0], s.normals[:, 2], -s.normals[:, 1]])
    x0, y0 = g.origin
    extras = {"wavemesh": {"grid": [s.width, s.height], "crs": g.crs, "map_unit": g.map_unit,
                           "origin_map": [x0, y0], "transform": list(g.transform),
                           "frame": "x east, y up, z south, in ground units from sample (0, 0)",
                           "comment": s.comment or ""}}
    try:
        data = trimesh.exchange.gltf.export_glb(trimesh.Scene(tm, metadata=extras),
                                                include_normals=s.normals is not None)
    except (ValueError, TypeError) as e:
        raise InputError(f"cannot write {os.fspath(path)}: {e}") from None
    with _open_for_writing(path, binary=True) as f:
        try:
            f.write(data)
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


# ---- The output formats: one registry (the CLI's help, the checks of -o, the docs table read it)


@dataclass(frozen=True)
class Format:
    """An output mesh format: its writer and what it can hold."""

    suffix: str
    name: str
    writer: Callable[..., None]
    normals: bool  # holds per-vertex normals (--normals)
    crs_units: bool  # can be written in the CRS's own units (--units crs)
    about: str  # one sentence for the docs table


FORMATS: dict[str, Format] = {f.suffix: f for f in (
    Format(".obj", "Wavefront OBJ", _write_obj, True, True,
           "text; `vn` normals; `wavemesh check` and `render` read it back"),
    Format(".ply", "PLY", _write_ply, True, True,
           "binary little-endian, double x y z, float nx ny nz; `check` and `render` read it back"),
    Format(".stl", "binary STL", _write_stl, False, True,
           "float32 triangles with their facet normals, for 3-D printing (`--base H`: a closed solid)"),
    Format(".glb", "glTF binary", _write_glb, True, False,
           "glTF 2.0 (metres, +Y up, from sample (0, 0); through trimesh) for three.js, Cesium, Blender"),
)}
MESH_SUFFIXES = tuple(FORMATS)


def formats_help() -> str:
    """The formats for `-o`'s help."""
    return ", ".join(f"{f.suffix} ({f.name})" for f in FORMATS.values())


def suffixes(holds: str) -> str:
    """The suffixes of the formats that hold ``holds`` (a Format flag: "normals", "crs_units"), as words:
    ".obj, .ply or .glb"."""
    *most, last = [f.suffix for f in FORMATS.values() if getattr(f, holds)]
    return f"{', '.join(most)} or {last}" if most else last


def formats_table() -> str:
    """The docs' table of output formats (README.md holds it; tests/host/test_outputs.py compares)."""
    rows = ["| `-o` | format | `--normals` | `--base H` | `--units crs` | |",
            "| --- | --- | --- | --- | --- | --- |"]
    for f in FORMATS.values():
        rows.append(f"| `{f.suffix}` | {f.name} | {'yes' if f.normals else 'facet normals'} | yes | "
                    f"{'yes' if f.crs_units else 'no (metres)'} | {f.about} |")
    return "\n".join(rows) + "\n"


def _format_of(path) -> Format:
    ext = Path(os.fspath(path)).suffix.lower()
    fmt = FORMATS.get(ext)
    if fmt is None:
        *most, last = FORMATS
        raise InputError(f"cannot tell the mesh format of {os.fspath(path)}: the name must end in "
                         f"{', '.join(most)} or {last}")
    return fmt


def check_options(path, *, units: str = "metres", local: bool = False, normals: bool = False,
                  base: float | None = None, georeferenced: bool = True) -> Format:
    """The mesh options against the format of ``path``, before any work: InputError naming the problem."""
    fmt = _format_of(path)
    if units not in UNITS:
        raise InputError(f"--units {units}: not a unit of the outputs", hint=f"use {' or '.join(UNITS)}")
    if local and units != "crs":
        raise InputError("--local subtracts sample (0, 0)'s map position from the CRS's coordinates",
                         hint="use it with --units crs (--units metres is already from sample (0, 0))")
    if units == "crs" and not fmt.crs_units and georeferenced:
        raise InputError(f"--units crs: a {fmt.suffix} file ({fmt.name}) is always in metres",
                         hint=f"leave out --units, or write {suffixes('crs_units')}")
    if normals and not fmt.normals:
        raise InputError(f"--normals: a {fmt.suffix} file holds one normal per triangle (always written), "
                         "not vertex normals", hint=f"leave out --normals, or write {suffixes('normals')}")
    if base is not None and not (math.isfinite(base) and base > 0):
        raise InputError(f"--base {base}: the thickness below the lowest height must be a number > 0",
                         hint="give the base's thickness in height units, e.g. --base 10")
    return fmt


def vertex_normals(pos: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Unit normals per vertex, each the area-weighted mean of its triangles' normals (the sum of their
    cross products); triangles counter-clockwise seen from their front."""
    c = pos[tris]
    face = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])  # length: twice the area
    idx = tris.ravel()
    acc = np.column_stack([np.bincount(idx, np.repeat(face[:, k], 3), minlength=len(pos)) for k in range(3)])
    length = np.linalg.norm(acc, axis=1)
    out = np.zeros_like(acc)
    out[:, 2] = 1.0  # a vertex of no triangle (none in a proper mesh): up
    ok = length > 0
    out[ok] = acc[ok] / length[ok, None]
    return out


def solid(xy: np.ndarray, z: np.ndarray, tris: np.ndarray, base: float):
    """The surface closed into a solid: a wall down from every border edge to a flat bottom ``base``
    below the lowest height, and the bottom, a fan from the border's centre.  ``tris`` counter-clockwise
    seen from above; every edge of the result is in exactly two triangles, used once each way (watertight,
    consistently oriented, outward).  Returns (xy, z, tris) with the new vertices after the old ones."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    n = max(int(tris.max()) + 1, len(xy))
    key = e[:, 0].astype(np.int64) * n + e[:, 1]
    rev = e[:, 1].astype(np.int64) * n + e[:, 0]
    border = e[~np.isin(key, rev)]  # directed edges with no twin: the border, interior on their left
    rim = np.unique(border)
    low = {int(v): len(xy) + i for i, v in enumerate(rim)}  # each border vertex's copy on the bottom
    centre = len(xy) + len(rim)
    a, b = border[:, 0], border[:, 1]
    la, lb = np.array([low[int(v)] for v in a]), np.array([low[int(v)] for v in b])
    c = np.full(len(a), centre)
    walls = np.concatenate([np.column_stack([b, a, la]), np.column_stack([b, la, lb])])
    bottom = np.column_stack([c, lb, la])
    bxy = xy[rim].astype(np.float64)
    mid = (bxy.min(axis=0) + bxy.max(axis=0)) / 2
    floor = float(np.min(z)) - base
    xy2 = np.concatenate([xy.astype(np.float64), bxy, mid[None, :]])
    z2 = np.concatenate([z, np.full(len(rim) + 1, floor)])
    return xy2, z2, np.concatenate([tris, walls, bottom]).astype(np.int64)


def write_mesh(path, mesh: Mesh, heights: np.ndarray, comment: str | None = None, *,
               ground=None, local: bool = False, units: str = "metres", normals: bool = False,
               base: float | None = None) -> None:
    """Write ``mesh`` in the format of the extension of ``path`` (FORMATS: ``.obj`` / ``.ply`` / ``.stl``
    / ``.glb``).  ``ground`` (a wavemesh.io.georef.Ground) with a georeference places the vertices:
    ``units`` "metres" (default) east, north and up in ground units from sample (0, 0), as the .glb;
    "crs" the map coordinates (less sample (0, 0)'s when ``local``); either way with the sidecar
    ``PATH.georef.json`` naming the frame, the CRS and the origin, and the triangles counter-clockwise
    seen from above.  Without one x and y are grid positions.  ``normals``: per-vertex normals (area-
    weighted, unit length); ``base``: a closed solid, the bottom ``base`` below the lowest height."""
    geo = ground is not None and ground.georeferenced
    fmt = check_options(path, units=units, local=local, normals=normals, base=base, georeferenced=geo)
    z = _vertex_z(mesh, heights)
    g = ground if geo else grid_ground(mesh.width, mesh.height)
    en = None
    if fmt.suffix == ".glb" or geo:
        east, north = g.ground_xy(mesh.xy[:, 0], mesh.xy[:, 1])
        en = np.column_stack([east, north])
    if fmt.suffix == ".glb":
        xy, mirror = en, g.mirrors("metres")
    elif not geo:
        xy, mirror = mesh.xy, False  # (col, row, z): right-handed, the grid's triangles face up
    elif units == "metres":
        xy, mirror = en, g.mirrors("metres")
    else:
        x, y = g.map_xy(mesh.xy[:, 0], mesh.xy[:, 1])
        if local:
            x0, y0 = g.origin
            x, y = x - x0, y - y0
        xy, mirror = np.column_stack([x, y]), g.mirrors("crs")
    tris = mesh.tris[:, ::-1] if mirror else mesh.tris
    if base is not None:
        xy, z, tris = solid(xy, z, tris, base)
        if fmt.suffix == ".glb":
            en = xy
    pos = np.column_stack([xy, z]).astype(np.float64) if normals else None
    surface = _Surface(mesh.width, mesh.height, xy, z, tris,
                       vertex_normals(pos, tris) if normals else None, comment,
                       (g, en) if fmt.suffix == ".glb" else ())
    fmt.writer(path, surface)
    if geo and fmt.suffix != ".glb":
        write_sidecar(g, path, local, units)
    else:  # grid coordinates, or a .glb (which says where it is): an older sidecar would misplace it
        sidecar_path(path).unlink(missing_ok=True)


def normal_map(values: np.ndarray, spacing: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """A tangent-space normal map of a height field, (H, W, 3) uint8: the surface normal at each sample
    from the heights' central differences (one-sided at the edges) over the ground spacing (dx, dy), in
    the picture's frame (x right along a row, y up the picture: row 0 at the top, z out of it), each
    component c written as round((c + 1) / 2 * 255): flat ground is (128, 128, 255)."""
    h = np.asarray(values, dtype=np.float64)
    dx, dy = spacing
    if h.shape[0] > 1:
        dz_down = np.gradient(h, axis=0) / dy
    else:
        dz_down = np.zeros_like(h)
    dz_right = np.gradient(h, axis=1) / dx if h.shape[1] > 1 else np.zeros_like(h)
    n = np.stack([-dz_right, dz_down, np.ones_like(h)], axis=-1)  # up the picture is minus a row
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.rint((n + 1.0) / 2.0 * 255.0).astype(np.uint8)


def write_normal_map(path, values: np.ndarray, spacing: tuple[float, float] = (1.0, 1.0)) -> None:
    """:func:`normal_map` as an RGB PNG of the grid's size (one pixel a sample)."""
    from PIL import Image  # only --normal-map needs it

    try:
        Image.fromarray(normal_map(values, spacing), "RGB").save(path, format="PNG")
    except OSError as e:
        raise InputError(f"cannot write normal map {os.fspath(path)}: {e.strerror or e}") from None


# --------------------------------------------------------------------------------------------
# Reading


def read_mesh(path, width: int | None = None, height: int | None = None,
              to_grid=None) -> tuple[Mesh, np.ndarray]:
    """Read an OBJ or PLY mesh file; return the mesh and the z of each vertex (float64).

    The grid size is taken from the ``wavemesh W H`` comment when the file has one
    (``width``/``height``, when given, must then agree), else from ``width`` and
    ``height``, else from the largest vertex coordinates (max x + 1, max y + 1).
    ``to_grid(x, y) -> (col, row)`` maps vertex coordinates in map units to grid positions
    (wavemesh.io.georef.to_grid); by default the sidecar ``PATH.georef.json``, when there is one, does.
    """
    if to_grid is None:
        placed = read_sidecar(path)
        to_grid = placing(*placed) if placed else None
    name = os.fspath(path)
    regular_file(name, "mesh file")  # not a FIFO (the read would wait for a writer), not a device
    try:
        data = Path(name).read_bytes()
    except OSError as e:
        raise InputError(f"cannot read mesh file {name}: {e.strerror or e}") from None
    try:
        if _is_ply(data):
            x, y, z, tris, comments, base = _parse_ply(data)
        elif Path(name).suffix.lower() == ".ply":
            raise _Bad("not a PLY file (it does not start with a 'ply' line)")
        else:
            x, y, z, tris, comments, base = _parse_obj(data)
        if to_grid is not None:
            x, y = to_grid(x, y)
            if getattr(to_grid, "mirror", False):  # written facing up in a frame that mirrors the grid
                tris = np.asarray(tris)[:, ::-1]
        return _finish(x, y, z, tris, comments, base, width, height)
    except _Bad as e:
        raise InputError(f"{name}: {e}") from None
    except (ValueError, IndexError, KeyError, OverflowError, TypeError, struct.error, MemoryError) as e:
        # A safety net: any other failure to make sense of the bytes is still a bad file.
        msg = " ".join(str(e).split()) or type(e).__name__
        raise InputError(f"{name}: cannot parse mesh file ({msg})") from None


def _finish(x, y, z, tris, comments, base, width, height) -> tuple[Mesh, np.ndarray]:
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    V = len(x)
    if V == 0:
        raise _Bad("the file has no vertices")
    if len(tris) == 0:
        raise _Bad("the file has no triangles")
    with np.errstate(invalid="ignore"):
        rx, ry = np.round(x), np.round(y)
        good = (np.abs(x - rx) < _INTEGRAL_TOL) & (np.abs(y - ry) < _INTEGRAL_TOL)
        good &= (np.abs(rx) < _COORD_LIMIT) & (np.abs(ry) < _COORD_LIMIT)
    if not good.all():
        i = int(np.flatnonzero(~good)[0])
        raise _Bad(f"vertex {i + base} at ({float(x[i])!r}, {float(y[i])!r}) is not a grid sample")
    xy = np.stack([rx, ry], axis=1).astype(np.int64)
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    bad = (tris < 0) | (tris >= V)
    if bad.any():
        f, k = (int(v) for v in np.argwhere(bad)[0])
        raise _Bad(
            f"face {f + base} refers to vertex {int(tris[f, k]) + base}, which does not exist "
            f"(the file has {V} vertices)"
        )
    tagged = None
    for c in comments:
        m = _TAG_RE.match(c.strip())
        if m:
            tagged = int(m.group(1)), int(m.group(2))
            break
    if tagged is not None:
        W, H = tagged
        if W < 1 or H < 1:
            raise _Bad(f"bad grid size {W} x {H} in the '{_TAG} W H' comment")
        if (width is not None and width != W) or (height is not None and height != H):
            raise _Bad(
                f"the file is a mesh of a {W} x {H} grid, not of the "
                f"{width if width is not None else W} x {height if height is not None else H} grid asked for"
            )
    else:
        W = int(width) if width is not None else int(xy[:, 0].max()) + 1
        H = int(height) if height is not None else int(xy[:, 1].max()) + 1
    return Mesh(W, H, xy, tris), z


# ---- OBJ

# Every statement of the OBJ specification other than v and f: accepted and ignored.
_OBJ_IGNORED = frozenset(
    "vt vn vp cstype deg bmat step p l curv curv2 surf parm trim hole scrv sp end con g s mg o "
    "bevel c_interp d_interp lod usemtl mtllib shadow_obj trace_obj ctech stech".split()
)


_OBJ_FACE_TEXT = re.compile(r"[0-9 ]*")


def _numbers(text: str, dtype) -> np.ndarray | None:
    """All whitespace-separated numbers of ``text``, or None when one does not parse."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        try:
            return np.fromstring(text, sep=" ", dtype=dtype)
        except (ValueError, DeprecationWarning):
            return None


def _parse_obj_fast(lines: list[str]):
    """The common case in bulk: only ``v x y z``, ``f i j k`` (plain numbers), comments and
    empty lines, single spaces.  Returns None for anything else; the line-by-line parser
    then reads the file (and finds the errors, with line numbers)."""
    vl = [line for line in lines if line[:2] == "v "]
    fl = [line for line in lines if line[:2] == "f "]
    cl = [line for line in lines if line[:1] == "#"]
    if len(vl) + len(fl) + len(cl) + lines.count("") != len(lines):
        return None
    vtext = " ".join(line[2:] for line in vl)
    ftext = " ".join(line[2:] for line in fl)
    for block, text in ((vl, vtext), (fl, ftext)):
        if "  " in text or text[:1] == " " or text[-1:] == " ":
            return None
        if not all(line.count(" ") == 3 for line in block):
            return None
    if not _OBJ_FACE_TEXT.fullmatch(ftext):
        return None
    xyz = _numbers(vtext, np.float64)
    idx = _numbers(ftext, np.int64)
    if xyz is None or idx is None or len(xyz) != 3 * len(vl) or len(idx) != 3 * len(fl):
        return None
    if (idx <= 0).any():
        return None
    xyz = xyz.reshape(-1, 3)
    comments = [line[1:].strip() for line in cl]
    return xyz[:, 0], xyz[:, 1], xyz[:, 2], idx.reshape(-1, 3) - 1, comments, 1


def _parse_obj(data: bytes):
    if b"\0" in data:
        raise _Bad("not a mesh file (binary data, and not PLY)")
    text = data.decode("utf-8", errors="replace")  # only comments and names may be non-ASCII
    text = text.replace("\\\r\n", " ").replace("\\\n", " ")  # OBJ line continuations
    lines = text.splitlines()
    fast = _parse_obj_fast(lines)
    if fast is not None:
        return fast
    verts: list[list[str]] = []
    vline: list[int] = []
    faces: list[list[str]] = []
    fline: list[int] = []
    fnv: list[int] = []  # vertices read before each face (for negative references)
    comments: list[str] = []
    for lineno, line in enumerate(lines, 1):
        parts = line.split()
        if not parts:
            continue
        kw = parts[0]
        if kw == "v":
            if len(parts) < 4:
                raise _Bad(f"line {lineno}: vertex {len(verts) + 1} needs x, y and z")
            verts.append(parts[1:4])
            vline.append(lineno)
        elif kw == "f":
            if len(parts) != 4:
                raise _Bad(
                    f"face {len(faces) + 1} has {len(parts) - 1} vertices; only triangles are supported "
                    f"(line {lineno})"
                )
            faces.append(parts[1:])
            fline.append(lineno)
            fnv.append(len(verts))
        elif kw[0] == "#":
            comments.append(line.strip()[1:].strip())
        elif kw not in _OBJ_IGNORED:
            shown = kw if len(kw) <= 20 else kw[:20] + "..."
            raise _Bad(f"line {lineno}: {shown!r} is not an OBJ statement")
    if verts:
        try:
            xyz = np.array(verts).astype(np.float64)
        except ValueError:
            for i, row in enumerate(verts):
                try:
                    [float(v) for v in row]
                except ValueError:
                    raise _Bad(f"line {vline[i]}: vertex {i + 1} has a bad coordinate") from None
            raise
    else:
        xyz = np.zeros((0, 3))
    if faces:
        refs = np.array(faces)
        try:
            idx = refs.astype(np.int64)  # the common case: plain vertex numbers
        except (ValueError, OverflowError):
            idx = np.zeros(refs.shape, dtype=np.int64)
            for f, row in enumerate(faces):
                for k, tok in enumerate(row):
                    try:
                        idx[f, k] = int(tok.split("/", 1)[0])
                    except (ValueError, OverflowError):
                        raise _Bad(f"line {fline[f]}: bad vertex reference {tok!r} in face {f + 1}") from None
        zero = np.argwhere(idx == 0)
        if len(zero):
            f = int(zero[0][0])
            raise _Bad(f"line {fline[f]}: vertex number 0 in face {f + 1} (OBJ counts from 1)")
        nv = np.array(fnv, dtype=np.int64)[:, None]
        back = (idx < 0) & (-idx > nv)
        if back.any():
            f, k = (int(v) for v in np.argwhere(back)[0])
            raise _Bad(
                f"face {f + 1} refers to vertex {int(idx[f, k])} but only {int(nv[f, 0])} vertices "
                f"precede it (line {fline[f]})"
            )
        tris = np.where(idx > 0, idx - 1, nv + idx)
    else:
        tris = np.zeros((0, 3), dtype=np.int64)
    return xyz[:, 0], xyz[:, 1], xyz[:, 2], tris, comments, 1


# ---- PLY

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_FACE_LISTS = ("vertex_indices", "vertex_index")


def _is_ply(data: bytes) -> bool:
    return data[:3] == b"ply" and data[3:4] in (b"\n", b"\r")


class _Prop:
    __slots__ = ("name", "type", "count_type")

    def __init__(self, name: str, type_: str, count_type: str | None):
        self.name, self.type, self.count_type = name, type_, count_type

    @property
    def is_list(self) -> bool:
        return self.count_type is not None


class _Element:
    __slots__ = ("name", "count", "props")

    def __init__(self, name: str, count: int):
        self.name, self.count, self.props = name, count, []


def _ply_type(word: str, line: str) -> str:
    t = _PLY_TYPES.get(word)
    if t is None:
        raise _Bad(f"unknown PLY type {word!r} in header line {line!r}")
    return t


def _parse_header(data: bytes):
    """Header lines up to ``end_header``: (format, elements, comments, offset of the body)."""
    pos = 0
    fmt = None
    elements: list[_Element] = []
    comments: list[str] = []
    first = True
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            raise _Bad("truncated PLY header (no end_header line)")
        line = data[pos:nl].decode("latin-1").rstrip("\r")
        pos = nl + 1
        if first:
            first = False
            continue  # the "ply" magic
        words = line.split()
        if not words:
            continue
        kw = words[0]
        shown = line if len(line) <= 60 else line[:60] + "..."
        if kw == "end_header":
            break
        if kw == "comment":
            comments.append(line.strip()[len("comment") :].strip())
        elif kw == "obj_info":
            continue
        elif kw == "format":
            if len(words) < 2 or words[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise _Bad(f"unknown PLY format line {shown!r}")
            fmt = words[1]
        elif kw == "element":
            if len(words) != 3:
                raise _Bad(f"bad PLY element line {shown!r}")
            try:
                count = int(words[2])
            except ValueError:
                raise _Bad(f"bad PLY element count in {shown!r}") from None
            if count < 0:
                raise _Bad(f"negative PLY element count in {shown!r}")
            elements.append(_Element(words[1], count))
        elif kw == "property":
            if not elements:
                raise _Bad(f"PLY property before any element: {shown!r}")
            if len(words) == 5 and words[1] == "list":
                prop = _Prop(words[4], _ply_type(words[3], shown), _ply_type(words[2], shown))
                if prop.count_type[0] == "f":
                    raise _Bad(f"PLY list count must have an integer type: {shown!r}")
            elif len(words) == 3 and words[1] != "list":
                prop = _Prop(words[2], _ply_type(words[1], shown), None)
            else:
                raise _Bad(f"bad PLY property line {shown!r}")
            elements[-1].props.append(prop)
        else:
            raise _Bad(f"bad PLY header line {shown!r}")
    if fmt is None:
        raise _Bad("PLY header has no format line")
    return fmt, elements, comments, pos


def _required(el: _Element) -> dict[str, int]:
    """List properties whose length is fixed (3 for the face list)."""
    if el.name == "face":
        return {p.name: 3 for p in el.props if p.is_list and p.name in _FACE_LISTS}
    return {}


def _too_long(el: _Element, r: int, prop: _Prop, c: int) -> _Bad:
    if el.name == "face" and prop.name in _FACE_LISTS:
        return _Bad(f"face {r} has {c} vertices; only triangles are supported")
    return _Bad(f"{el.name} {r}: bad length {c} of list property {prop.name!r}")


def _read_binary_element(buf: bytes, pos: int, el: _Element, e: str):
    """Read the records of one element; return ({property: [chunk arrays]}, offset after them).

    Records are read in runs that share the list lengths of their first record
    (for the face list: all 3), each run with one ``np.frombuffer``.
    """
    fixed = _required(el)
    out: dict[str, list[np.ndarray]] = {p.name: [] for p in el.props}
    r = 0
    n_buf = len(buf)
    while r < el.count:
        fields, counts, p = [], [], pos
        for j, prop in enumerate(el.props):
            if prop.is_list:
                size = np.dtype(prop.count_type).itemsize
                if p + size > n_buf:
                    raise _Bad(f"truncated PLY file (in {el.name} {r} of {el.count})")
                c = int(np.frombuffer(buf, dtype=e + prop.count_type, count=1, offset=p)[0])
                if c < 0 or (prop.name in fixed and c != fixed[prop.name]):
                    raise _too_long(el, r, prop, c)
                fields.append((f"n{j}", e + prop.count_type))
                fields.append((f"v{j}", e + prop.type, (c,)))
                counts.append((j, c))
                p += size + c * np.dtype(prop.type).itemsize
            else:
                fields.append((f"v{j}", e + prop.type))
                p += np.dtype(prop.type).itemsize
        dt = np.dtype(fields)
        rec = dt.itemsize
        if rec == 0:  # an element without properties: its records take no bytes, however many it states
            break
        n_fit = min(el.count - r, (n_buf - pos) // rec)
        if n_fit <= 0:
            raise _Bad(f"truncated PLY file (in {el.name} {r} of {el.count})")
        arr = np.frombuffer(buf, dtype=dt, count=n_fit, offset=pos)
        m = n_fit
        for j, c in counts:
            diff = np.flatnonzero(arr[f"n{j}"] != c)
            if len(diff):
                m = min(m, int(diff[0]))
        for j, prop in enumerate(el.props):
            out[prop.name].append(arr[f"v{j}"][:m])
        pos += m * rec
        r += m
    return out, pos


def _read_ascii_element(vals: np.ndarray, pos: int, el: _Element):
    """The ASCII twin of :func:`_read_binary_element` over the body's numbers."""
    fixed = _required(el)
    out: dict[str, list[np.ndarray]] = {p.name: [] for p in el.props}
    r = 0
    n_vals = len(vals)
    while r < el.count:
        cols, counts, p = [], [], pos
        for j, prop in enumerate(el.props):
            if prop.is_list:
                if p >= n_vals:
                    raise _Bad(f"truncated PLY file (in {el.name} {r} of {el.count})")
                cv = vals[p]
                if not (cv >= 0 and cv == np.floor(cv) and cv < 1 << 31):
                    raise _Bad(f"{el.name} {r}: bad list length {cv!r} for {prop.name!r}")
                c = int(cv)
                if prop.name in fixed and c != fixed[prop.name]:
                    raise _too_long(el, r, prop, c)
                cols.append((j, p - pos, c))
                counts.append((p - pos, c))
                p += 1 + c
            else:
                cols.append((j, p - pos, None))
                p += 1
        w = p - pos
        if w == 0:  # an element without properties: its records take no numbers, however many it states
            break
        n_fit = min(el.count - r, (n_vals - pos) // w)
        if n_fit <= 0:
            raise _Bad(f"truncated PLY file (in {el.name} {r} of {el.count})")
        arr = vals[pos : pos + n_fit * w].reshape(n_fit, w)
        m = n_fit
        for off, c in counts:
            diff = np.flatnonzero(arr[:, off] != c)
            if len(diff):
                m = min(m, int(diff[0]))
        for j, off, c in cols:
            prop = el.props[j]
            if c is None:
                out[prop.name].append(arr[:m, off])
            else:
                out[prop.name].append(arr[:m, off + 1 : off + 1 + c])
        pos += m * w
        r += m
    return out, pos


def _parse_ply(data: bytes):
    fmt, elements, comments, body_at = _parse_header(data)
    seen = set()
    for el in elements:
        if el.name in seen:
            raise _Bad(f"PLY element {el.name!r} appears twice")
        seen.add(el.name)
    by_name = {el.name: el for el in elements}
    vel, fel = by_name.get("vertex"), by_name.get("face")
    if vel is None:
        raise _Bad("PLY file has no vertex element")
    if fel is None:
        raise _Bad("PLY file has no face element")
    vprops = {p.name: p for p in vel.props}
    for c in "xyz":
        if c not in vprops:
            raise _Bad(f"PLY vertex element has no {c!r} property")
        if vprops[c].is_list:
            raise _Bad(f"PLY vertex property {c!r} is a list")
    flist = next((p for p in fel.props if p.name in _FACE_LISTS), None)
    if flist is None or not flist.is_list:
        raise _Bad("PLY face element has no 'vertex_indices' list")

    got: dict[str, dict[str, list[np.ndarray]]] = {}
    if fmt == "ascii":
        try:
            vals = np.array(data[body_at:].split()).astype(np.float64)
        except ValueError:
            raise _Bad("PLY ascii body has a token that is not a number") from None
        pos = 0
        for el in elements:
            got[el.name], pos = _read_ascii_element(vals, pos, el)
    else:
        e = "<" if fmt == "binary_little_endian" else ">"
        buf = memoryview(data)[body_at:]
        pos = 0
        for el in elements:
            got[el.name], pos = _read_binary_element(buf, pos, el, e)

    def cat(chunks, shape):
        return np.concatenate(chunks) if chunks else np.zeros(shape)

    x = cat(got["vertex"]["x"], (0,)).astype(np.float64)
    y = cat(got["vertex"]["y"], (0,)).astype(np.float64)
    z = cat(got["vertex"]["z"], (0,)).astype(np.float64)
    idx = cat(got["face"][flist.name], (0, 3))
    if idx.dtype.kind == "f":
        bad = idx != np.floor(idx)
        if bad.any():
            f = int(np.argwhere(bad)[0][0])
            raise _Bad(f"face {f} has a vertex index that is not an integer")
        idx = np.clip(idx, -1, float(1 << 62))  # anything out of range stays out of range
    tris = idx.astype(np.int64).reshape(-1, 3)
    return x, y, z, tris, comments, 0
