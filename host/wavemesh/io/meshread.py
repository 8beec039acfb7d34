"""Mesh files read back: OBJ and PLY (what wavemesh writes, and other programs' files within reason), with
the grid a mesh lies on (the ``# wavemesh W H`` comment, or the sidecar's placing) and its heights.

The writers and the format registry are :mod:`wavemesh.io.meshio`'s.

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

from wavemesh.errors import InputError
from wavemesh.io.georef import read_sidecar
from wavemesh.io.georef import to_grid as placing
from wavemesh.io.meshio import GRID_TAG
from wavemesh.io.readers import regular_file
from wavemesh.mesh import Mesh

_TAG_RE = re.compile(r"^wavemesh\s+(-?\d+)\s+(-?\d+)\s*$")


# Integral coordinates: |x - round(x)| below this counts as a grid sample.
_INTEGRAL_TOL = 1e-9


_COORD_LIMIT = float(1 << 40)  # larger coordinates are certainly not samples of a real grid


class _Bad(Exception):
    """A parse failure inside this module; read_mesh turns it into an InputError."""


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
            raise _Bad(f"bad grid size {W} x {H} in the '{GRID_TAG} W H' comment")
        if (width is not None and width != W) or (height is not None and height != H):
            raise _Bad(
                f"the file is a mesh of a {W} x {H} grid, not of the "
                f"{width if width is not None else W} x {height if height is not None else H} grid asked for"
            )
    else:
        W = int(width) if width is not None else int(xy[:, 0].max()) + 1
        H = int(height) if height is not None else int(xy[:, 1].max()) + 1
    return Mesh(W, H, xy, tris), z


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


def _written_kind(data: bytes) -> str | None:
    """"glTF binary" or "binary STL" when ``data`` is one (glTF's magic; STL's 80-byte header and triangle
    count that give the file's length), else None."""
    if data[:4] == b"glTF":
        return "glTF binary"
    if len(data) >= 84 and 84 + 50 * struct.unpack_from("<I", data, 80)[0] == len(data):
        return "binary STL"
    return None


def _parse_obj(data: bytes):
    if b"\0" in data:
        kind = _written_kind(data)
        if kind:  # a format wavemesh writes but does not read back: say which can be
            raise _Bad(f"a {kind} file: meshes are read back from OBJ and PLY only (mesh again with "
                       f"-o NAME.obj or NAME.ply to check or render it)")
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
