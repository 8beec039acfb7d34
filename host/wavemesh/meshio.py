"""Mesh files: Wavefront OBJ and PLY, written and read.

Writing
    :func:`write_obj` writes ``v x y z`` lines (x, y as integers, z as
    ``repr(float(z))``, the shortest text that reads back to the same double)
    and ``f i j k`` lines (1-based).  :func:`write_ply` writes
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

import os
import re
import struct
import warnings
from pathlib import Path

import numpy as np

from .errors import InputError
from .mesh import Mesh

__all__ = ["write_obj", "write_ply", "write_mesh", "read_mesh"]

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


def write_obj(path, mesh: Mesh, heights: np.ndarray, comment: str | None = None,
              xy: np.ndarray | None = None) -> None:
    """Write ``mesh`` as a Wavefront OBJ file with z from ``heights`` ((H, W), or (V,) per vertex); x and y
    are the grid positions, or ``xy`` ((V, 2) floats: map coordinates) when given."""
    z = _vertex_z(mesh, heights)
    head = [f"# {_TAG} {mesh.width} {mesh.height}"]
    head += [f"# {c}" if c else "#" for c in _comment_lines(comment)]
    xy, tris = (mesh.xy if xy is None else np.asarray(xy, dtype=np.float64)), mesh.tris
    with _open_for_writing(path, binary=False) as f:
        try:
            f.write("\n".join(head) + "\n")
            for s in range(0, len(xy), _CHUNK):
                f.write(_obj_vertex_lines(xy[s : s + _CHUNK], z[s : s + _CHUNK]))
            for s in range(0, len(tris), _CHUNK):
                t = tris[s : s + _CHUNK] + 1
                f.write(("f %d %d %d\n" * len(t)) % tuple(t.ravel().tolist()))
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def write_ply(path, mesh: Mesh, heights: np.ndarray, comment: str | None = None,
              xy: np.ndarray | None = None) -> None:
    """Write ``mesh`` as a binary little-endian PLY file with z from ``heights`` (x, y as write_obj)."""
    z = _vertex_z(mesh, heights)
    V, T = mesh.n_vertices, mesh.n_triangles
    if V >= 1 << 31:
        raise InputError(f"{V} vertices do not fit the PLY 'int' vertex index")
    head = ["ply", "format binary_little_endian 1.0", f"comment {_TAG} {mesh.width} {mesh.height}"]
    head += [f"comment {c}" if c else "comment" for c in _comment_lines(comment)]
    head += [
        f"element vertex {V}",
        "property double x",
        "property double y",
        "property double z",
        f"element face {T}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    verts = np.empty(V, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    verts["x"] = mesh.xy[:, 0] if xy is None else xy[:, 0]
    verts["y"] = mesh.xy[:, 1] if xy is None else xy[:, 1]
    verts["z"] = z
    faces = np.empty(T, dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = mesh.tris
    with _open_for_writing(path, binary=True) as f:
        try:
            f.write(("\n".join(head) + "\n").encode("utf-8"))
            f.write(verts.tobytes())
            f.write(faces.tobytes())
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


def write_mesh(path, mesh: Mesh, heights: np.ndarray, comment: str | None = None, *,
               ground=None, local: bool = False) -> None:
    """Write ``mesh`` as OBJ, PLY or glTF binary, chosen by the extension of ``path`` (``.obj`` / ``.ply`` /
    ``.glb``).  ``ground`` (a wavemesh.georef.Ground) with a georeference puts an OBJ's or PLY's
    vertices at their map coordinates (less the origin, sample (0, 0)'s, when ``local``) and writes the
    sidecar ``PATH.georef.json`` naming the CRS and the origin; without one x and y are grid positions."""
    ext = Path(os.fspath(path)).suffix.lower()
    xy = None
    if ground is not None and ground.georeferenced and ext in (".obj", ".ply"):
        from .georef import write_sidecar

        x, y = ground.map_xy(mesh.xy[:, 0], mesh.xy[:, 1])
        if local:
            x0, y0 = ground.origin
            x, y = x - x0, y - y0
        xy = np.column_stack([x, y])
    if ext == ".obj":
        write_obj(path, mesh, heights, comment, xy)
    elif ext == ".ply":
        write_ply(path, mesh, heights, comment, xy)
    elif ext == ".glb":
        write_glb(path, mesh, heights, ground, comment)
        return
    else:
        raise InputError(
            f"cannot tell the mesh format of {os.fspath(path)}: the name must end in .obj, .ply or .glb",
        )
    if xy is not None:
        write_sidecar(ground, path, local)
    else:  # grid coordinates: a sidecar left by an earlier run would misplace them
        from .georef import sidecar_path

        sidecar_path(path).unlink(missing_ok=True)


def write_glb(path, mesh: Mesh, heights: np.ndarray, ground=None, comment: str | None = None) -> None:
    """Write ``mesh`` as a glTF 2.0 binary (.glb) through trimesh: glTF's frame (metres, +Y up, +Z toward
    the viewer: east, up, south) relative to sample (0, 0), positions as float32.  ``ground`` (a
    wavemesh.georef.Ground; None: the grid in grid steps) gives (east, north); the scene's ``extras``
    (trimesh writes a scene's metadata there) name the CRS, the origin and the grid, as the sidecar does."""
    import trimesh  # imported here: only .glb needs it

    from .georef import grid_ground

    z = _vertex_z(mesh, heights)
    g = ground or grid_ground(mesh.width, mesh.height)
    east, north = g.ground_xy(mesh.xy[:, 0], mesh.xy[:, 1])
    # glTF triangles are counter-clockwise seen from their front (above, in (east, north)): the grid's are
    # counter-clockwise in (col, row), whose row 0 (east, north) always puts north: a mirror, so reversed.
    tris = mesh.tris[:, ::-1]
    verts = np.column_stack([east, z, -north])
    tm = trimesh.Trimesh(vertices=verts, faces=tris, process=False, validate=False)
    x0, y0 = g.origin
    extras = {"wavemesh": {"grid": [mesh.width, mesh.height], "crs": g.crs, "map_unit": g.map_unit,
                           "origin_map": [x0, y0], "transform": list(g.transform),
                           "frame": "x east, y up, z south, in ground units from sample (0, 0)",
                           "comment": comment or ""}}
    try:
        data = trimesh.exchange.gltf.export_glb(trimesh.Scene(tm, metadata=extras), include_normals=False)
    except (ValueError, TypeError) as e:
        raise InputError(f"cannot write {os.fspath(path)}: {e}") from None
    with _open_for_writing(path, binary=True) as f:
        try:
            f.write(data)
        except OSError as e:
            raise InputError(f"cannot write mesh file {os.fspath(path)}: {e.strerror or e}") from None


# --------------------------------------------------------------------------------------------
# Reading


def read_mesh(path, width: int | None = None, height: int | None = None,
              to_grid=None) -> tuple[Mesh, np.ndarray]:
    """Read an OBJ or PLY mesh file; return the mesh and the z of each vertex (float64).

    The grid size is taken from the ``wavemesh W H`` comment when the file has one
    (``width``/``height``, when given, must then agree), else from ``width`` and
    ``height``, else from the largest vertex coordinates (max x + 1, max y + 1).
    ``to_grid(x, y) -> (col, row)`` maps vertex coordinates in map units to grid positions
    (wavemesh.georef.to_grid); by default the sidecar ``PATH.georef.json``, when there is one, does.
    """
    if to_grid is None:
        from .georef import read_sidecar
        from .georef import to_grid as placing

        placed = read_sidecar(path)
        to_grid = placing(*placed) if placed else None
    name = os.fspath(path)
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
