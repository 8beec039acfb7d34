"""Mesh files: Wavefront OBJ, PLY, binary STL and glTF binary written (:data:`FORMATS`, the one list of
them); OBJ and PLY are read back by :mod:`wavemesh.io.meshread`.

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
    written before any caller comment, so ``read_mesh`` recovers W and H even
    when the mesh does not reach the last row or column.
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wavemesh.errors import InputError
from wavemesh.io.georef import UNITS, grid_ground, sidecar_path, write_sidecar
from wavemesh.mesh import Mesh
from wavemesh.record import record
from wavemesh.refine import native

__all__ = ["FORMATS", "write_obj", "write_ply", "write_mesh", "vertex_normals", "normal_map"]

GRID_TAG = "wavemesh"  # the comment that names the grid: "wavemesh W H"
_CHUNK = 1 << 16  # vertices / faces formatted per write when writing OBJ


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
    """``v x y z`` lines, z as ``repr(float(z))``: for integer x, y in C when the library is there
    (native.obj_vertices: the same text, tests/host/test_host_stages.py; a tenth of repr's time), else by
    one %-format, not line by line.  Float x, y (map coordinates) are written as ``repr`` too."""
    n = len(xy)
    if xy.dtype.kind == "f":
        return ("v %r %r %r\n" * n) % tuple(np.column_stack([xy, z]).ravel().tolist())
    text = native.obj_vertices(xy, z)
    return text if text is not None else _obj_vertex_lines_model(xy, z)


def _obj_vertex_lines_model(xy: np.ndarray, z: np.ndarray) -> str:
    """_obj_vertex_lines' text for integer x, y in Python (its model)."""
    n = len(xy)
    flat: list = [None] * (3 * n)
    flat[0::3] = xy[:, 0].tolist()
    flat[1::3] = xy[:, 1].tolist()
    # repr of an integral double below 1e16 is its integer and ".0" (-0.0 is the exception)
    if np.all((z == np.trunc(z)) & (np.abs(z) < 1e16) & ~((z == 0) & np.signbit(z))):
        flat[2::3] = z.astype(np.int64).tolist()
        return ("v %d %d %d.0\n" * n) % tuple(flat)
    flat[2::3] = z.tolist()
    return ("v %d %d %r\n" * n) % tuple(flat)


def _obj_face_lines(tris: np.ndarray) -> str:
    """``f a b c`` lines of (T, 3) 0-based vertex indices (formatted in C when the library is there: the
    same text, tests/host/test_host_stages.py)."""
    text = native.obj_faces(tris)
    if text is None:
        text = ("f %d %d %d\n" * len(tris)) % tuple((tris + 1).ravel().tolist())
    return text


@record(frozen=True)
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
    head = [f"# {GRID_TAG} {s.width} {s.height}"]
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
                if s.normals is None:
                    f.write(_obj_face_lines(tris[a : a + _CHUNK]))
                    continue
                t = np.repeat(tris[a : a + _CHUNK] + 1, 2, axis=1)
                f.write((face * len(t)) % tuple(t.ravel().tolist()))
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def write_ply(path, mesh: Mesh, heights: np.ndarray, comment: str | None = None,
              xy: np.ndarray | None = None) -> None:
    """Write ``mesh`` as a binary little-endian PLY file with z from ``heights`` (x, y as write_obj)."""
    xy = mesh.xy if xy is None else np.asarray(xy, dtype=np.float64)
    _write_ply(path, _Surface(mesh.width, mesh.height, xy, _vertex_z(mesh, heights), mesh.tris,
                                    None, comment))


def _ply_head(width: int, height: int, comment: str | None, V: int, T: int, normals: bool) -> bytes:
    if V >= 1 << 31:
        raise InputError(f"{V} vertices do not fit the PLY 'int' vertex index")
    head = ["ply", "format binary_little_endian 1.0", f"comment {GRID_TAG} {width} {height}"]
    head += [f"comment {c}" if c else "comment" for c in _comment_lines(comment)]
    head += [f"element vertex {V}", "property double x", "property double y", "property double z"]
    if normals:
        head += ["property float nx", "property float ny", "property float nz"]
    head += [f"element face {T}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(head) + "\n").encode("utf-8")


def _ply_vertices(xy: np.ndarray, z: np.ndarray, normals: np.ndarray | None = None) -> bytes:
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    verts = np.empty(len(xy), dtype=fields)
    verts["x"], verts["y"], verts["z"] = xy[:, 0], xy[:, 1], z
    if normals is not None:
        verts["nx"], verts["ny"], verts["nz"] = normals.T
    return verts.tobytes()


def _ply_faces(tris: np.ndarray) -> bytes:
    faces = np.empty(len(tris), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = tris
    return faces.tobytes()


def _write_ply(path, s: _Surface) -> None:
    head = _ply_head(s.width, s.height, s.comment, len(s.xy), len(s.tris), s.normals is not None)
    with _open_for_writing(path, binary=True) as f:
        try:
            f.write(head)
            f.write(_ply_vertices(s.xy, s.z, s.normals))
            f.write(_ply_faces(s.tris))
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def _stl_head(width: int, height: int, comment: str | None) -> bytes:
    head = f"{GRID_TAG} {width} {height} binary STL; {' '.join(_comment_lines(comment))}".encode()
    return head[:80].ljust(80, b" ")


def _stl_facets(xy: np.ndarray, z: np.ndarray, tris: np.ndarray) -> bytes:
    pos = np.column_stack([xy, z]).astype(np.float64)
    corners = pos[tris]
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1), np.finfo(np.float64).tiny)[:, None]
    rec = np.zeros(len(tris), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = n, corners
    return rec.tobytes()


def _write_stl(path, s: _Surface) -> None:
    """Binary STL: an 80-byte header (not starting with "solid", which would read as ASCII STL), the
    triangle count, and per triangle its unit normal and three corners as float32."""
    with _open_for_writing(path, binary=True) as f:
        try:
            f.write(_stl_head(s.width, s.height, s.comment) + struct.pack("<I", len(s.tris))
                    + _stl_facets(s.xy, s.z, s.tris))
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


@record(frozen=True)
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
    frame = _Frame(mesh.width, mesh.height, fmt.suffix, ground, units, local)
    xy = frame.place(mesh.xy)
    tris = mesh.tris[:, ::-1] if frame.mirror else mesh.tris
    if base is not None:
        xy, z, tris = solid(xy, z, tris, base)
    pos = np.column_stack([xy, z]).astype(np.float64) if normals else None
    surface = _Surface(mesh.width, mesh.height, xy, z, tris,
                       vertex_normals(pos, tris) if normals else None, comment,
                       (frame.ground, xy) if fmt.suffix == ".glb" else ())
    fmt.writer(path, surface)
    frame.sidecar(path)


class _Frame:
    """Where a file of ``suffix`` puts the grid's vertices (write_mesh's options): ``place(xy)`` their x, y
    in it (grid positions as they are without a georeference; east and north in ground units from sample
    (0, 0), as the .glb always is; or the CRS's map coordinates, less sample (0, 0)'s when ``local``),
    ``mirror``: the triangles reversed to stay counter-clockwise seen from above; ``sidecar(path)`` the
    georeference's sidecar beside the file (or an older one removed)."""

    def __init__(self, width: int, height: int, suffix: str, ground, units: str, local: bool):
        self.geo = ground is not None and ground.georeferenced
        self.ground = ground if self.geo else grid_ground(width, height)
        self.suffix, self.units, self.local = suffix, units, local
        if suffix == ".glb" or (self.geo and units == "metres"):
            self.mirror = self.ground.mirrors("metres")
        elif not self.geo:
            self.mirror = False  # (col, row, z): right-handed, the grid's triangles face up
        else:
            self.mirror = self.ground.mirrors("crs")

    def place(self, xy: np.ndarray) -> np.ndarray:
        g = self.ground
        if self.suffix == ".glb" or (self.geo and self.units == "metres"):
            return np.column_stack(g.ground_xy(xy[:, 0], xy[:, 1]))
        if not self.geo:
            return xy
        x, y = g.map_xy(xy[:, 0], xy[:, 1])
        if self.local:
            x0, y0 = g.origin
            x, y = x - x0, y - y0
        return np.column_stack([x, y])

    def sidecar(self, path) -> None:
        if self.geo and self.suffix != ".glb":
            write_sidecar(self.ground, path, self.local, self.units)
        else:  # grid coordinates, or a .glb (which says where it is): an older sidecar would misplace it
            sidecar_path(path).unlink(missing_ok=True)


# ---- A mesh file written piece by piece (a tiled run's tiles as they finish)


class MeshStream:
    """A mesh file of write_mesh's formats and frame written piece by piece: each :meth:`add` appends a
    piece's vertices not written before and its triangles, numbered as the caller says; :meth:`finish`
    completes the file (and its sidecar).  The same file write_mesh writes of the same vertices and
    triangles in the same order, except that OBJ's ``v`` and ``f`` lines come piece by piece (faces name
    only vertices above them, as OBJ asks).  Formats: :data:`STREAMS` (.obj, .ply, .stl); not with
    per-vertex normals or a base (they need every triangle of a vertex, the whole border).  A failure
    leaves the file unfinished: write it where wavemesh.io.outputs stages it."""

    binary = True

    def __init__(self, path, width: int, height: int, comment: str | None = None, *, ground=None,
                 units: str = "metres", local: bool = False):
        geo = ground is not None and ground.georeferenced
        fmt = check_options(path, units=units, local=local, georeferenced=geo)
        if fmt.suffix not in STREAMS:
            raise InputError(f"a {fmt.suffix} file is written whole, not piece by piece")
        self.path, self.width, self.height, self.comment = path, width, height, comment
        self.frame = _Frame(width, height, fmt.suffix, ground, units, local)
        self.vertices = self.triangles = 0
        self.file = _open_for_writing(path, binary=self.binary)
        self._io(self.start)

    def add(self, xy: np.ndarray, z: np.ndarray, tris: np.ndarray, number: np.ndarray, start: int) -> None:
        """A piece: its vertices ``xy`` (grid positions) and heights ``z``, of which those from ``start`` on
        are new (numbered next, in order: ``number[start:]`` is ``vertices, vertices + 1, ...``), the first
        ``start`` written before with the numbers ``number[:start]``; ``tris`` (counter-clockwise) index
        ``xy``."""
        if len(number) - start and number[start] != self.vertices:
            raise ValueError(f"the piece's new vertices start at {number[start]}, not {self.vertices}")
        tris = tris[:, ::-1] if self.frame.mirror else tris
        self._io(self._add, xy, z, tris, number, start)
        self.vertices += len(xy) - start
        self.triangles += len(tris)

    def finish(self) -> None:
        """The file complete (the counts in its header), closed; its sidecar."""
        try:
            self._io(self.end)
        finally:
            self.close()
        self.frame.sidecar(self.path)

    def close(self) -> None:
        self.file.close()

    def _io(self, fn, *args) -> None:
        try:
            fn(*args)
        except OSError as e:
            self.close()
            raise InputError(f"cannot write mesh file {os.fspath(self.path)}: {e.strerror or e}") from None

    def start(self) -> None: ...
    def _add(self, xy, z, tris, number, start) -> None: ...
    def end(self) -> None: ...


class _ObjStream(MeshStream):
    binary = False

    def start(self) -> None:
        head = [f"# {GRID_TAG} {self.width} {self.height}"]
        head += [f"# {c}" if c else "#" for c in _comment_lines(self.comment)]
        self.file.write("\n".join(head) + "\n")

    def _add(self, xy, z, tris, number, start) -> None:
        xy, z = self.frame.place(xy[start:]), z[start:]
        for a in range(0, len(xy), _CHUNK):
            self.file.write(_obj_vertex_lines(xy[a : a + _CHUNK], z[a : a + _CHUNK]))
        for a in range(0, len(tris), _CHUNK):
            self.file.write(_obj_face_lines(number[tris[a : a + _CHUNK]]))


class _PlyStream(MeshStream):
    """The vertices and the faces into two unnamed temporary files beside the output (gone with the
    process whatever happens), then the header with their counts, and both copied after it."""

    def start(self) -> None:
        import tempfile  # only a streamed PLY needs it

        where = os.path.dirname(os.path.abspath(self.path))
        self.parts = [tempfile.TemporaryFile(dir=where), tempfile.TemporaryFile(dir=where)]

    def _add(self, xy, z, tris, number, start) -> None:
        self.parts[0].write(_ply_vertices(self.frame.place(xy[start:]), z[start:]))
        self.parts[1].write(_ply_faces(number[tris]))

    def end(self) -> None:
        import shutil  # imported here: only a streamed .ply copies its parts (kept off start-up)

        self.file.write(_ply_head(self.width, self.height, self.comment, self.vertices, self.triangles,
                                  False))
        for part in self.parts:
            part.seek(0)
            shutil.copyfileobj(part, self.file, 1 << 20)

    def close(self) -> None:
        for part in getattr(self, "parts", ()):
            part.close()
        super().close()


class _StlStream(MeshStream):
    """The header, a triangle count to fill in at the end, the facets as they come."""

    def start(self) -> None:
        self.file.write(_stl_head(self.width, self.height, self.comment) + struct.pack("<I", 0))

    def _add(self, xy, z, tris, number, start) -> None:
        self.file.write(_stl_facets(self.frame.place(xy), z, tris))

    def end(self) -> None:
        if self.triangles >= 1 << 32:
            raise InputError(f"{self.triangles} triangles do not fit binary STL's count")
        self.file.seek(80)
        self.file.write(struct.pack("<I", self.triangles))


STREAMS = {".obj": _ObjStream, ".ply": _PlyStream, ".stl": _StlStream}  # the formats written piece by piece


def mesh_stream(path, width: int, height: int, comment: str | None = None, **frame) -> MeshStream:
    """A MeshStream of the format ``path`` names (STREAMS); ``frame``: ground, units, local (write_mesh's)."""
    return STREAMS.get(_format_of(path).suffix, MeshStream)(path, width, height, comment, **frame)


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
