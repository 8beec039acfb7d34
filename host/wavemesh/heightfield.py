"""Reading height fields and quantising them to 16-bit unsigned samples.

A height field is a 2-D grid of heights with H rows and W columns (W, H >= 2).
Row 0 is the first row stored in the file (north for DEMs), column 0 the left
column.  :func:`load_heightfield` reads a file, :func:`from_array` takes an
array; both return a :class:`HeightField` holding the heights (float64) and
their quantised 16-bit samples.

Formats (chosen by the file extension, case-insensitive; when the extension is
not one of these, by the first bytes of the file):

- ``.npy``: a NumPy array (``allow_pickle=False``).
- ``.npz``: a NumPy archive; ``key`` names the array.  Without a key the archive
  must hold exactly one array.
- ``.pgm``: binary (P5, one byte per sample when maxval <= 255, else two bytes
  big-endian) or plain (P2) graymap, ``#`` comments allowed in the header.  The
  sample values are the heights (they are not scaled by maxval).
- ``.png``: one-channel PNG (modes 1, L, I;16, I;16B, I;16L, I, F) read with
  Pillow; 16-bit PNGs keep their full 16-bit values.  Colour, palette or alpha
  images are rejected.
- ``.tif``/``.tiff``: TIFF or GeoTIFF with one band (a 3-D array with a
  singleton band axis is squeezed).  Samples equal to the GDAL_NODATA tag
  (42113) become NaN.
- ``.asc``: ESRI ASCII grid.  Header lines ``key value`` (keys case-insensitive,
  any order): ``ncols`` and ``nrows`` are required; ``xllcorner``/``xllcenter``,
  ``yllcorner``/``yllcenter``, ``cellsize``, ``dx``, ``dy`` are accepted and
  ignored (the georeference plays no part in the mesh); samples equal to
  ``NODATA_value`` become NaN.  Then nrows*ncols numbers, row by row, separated
  by any whitespace.

Accepted data: a 2-D array of bool, integer or float samples, at least 2 x 2.
Non-finite samples (NaN, +-inf, no-data) are an error unless ``fill`` is given:
``fill="nearest"`` replaces each by the value of the nearest finite sample and
a number replaces them by that number (see :func:`fill_nearest`).  Every problem
a user can cause is an :class:`~wavemesh.errors.InputError` with a one-line
message.

Quantisation (the contract the RTL and the firmware rely on; ``quantise``):

- Heights are float64 ``v``; ``min``/``max`` are their extremes (bool becomes 0/1).
- Lossless case: every ``v`` is an integer (also when stored as float) and
  ``max - min <= 65535``.  Then ``scale = 1.0``; ``offset = 0.0`` when
  ``0 <= min`` and ``max <= 65535``, else ``offset = min``; ``samples = v - offset``
  and ``lossless = True``.
- Otherwise: ``offset = min``; ``scale = (max - min) / 65535`` (``scale = 1.0`` when
  ``max == min``); ``samples = clip(rint((v - offset) / scale), 0, 65535)`` where
  ``rint`` rounds half to even; the quantisation error is at most ``scale / 2``.
  ``lossless`` is True only when ``offset + scale * samples == v`` exactly
  (e.g. a constant non-integer field).
- In every case a height is reconstructed as ``offset + scale * sample``.
"""

from __future__ import annotations

import os
import re
import struct
import tokenize
import zipfile
import zlib
from dataclasses import dataclass

import numpy as np

from wavemesh.errors import InputError

SAMPLE_MAX = 65535  # largest 16-bit unsigned sample

SUPPORTED_FORMATS = ".npy, .npz, .pgm (P2/P5), .png, .tif/.tiff (GeoTIFF), .asc (ESRI ASCII grid)"

_EXTENSIONS = {
    ".npy": "npy",
    ".npz": "npz",
    ".pgm": "pgm",
    ".png": "png",
    ".tif": "tiff",
    ".tiff": "tiff",
    ".asc": "asc",
}

_GDAL_NODATA_TAG = 42113

_ASC_KEYS = {
    "ncols",
    "nrows",
    "xllcorner",
    "xllcenter",
    "yllcorner",
    "yllcenter",
    "cellsize",
    "dx",
    "dy",
    "nodata_value",
}

# Exceptions the file readers (numpy, zipfile, zlib, Pillow, tifffile) raise for
# unreadable, truncated or corrupt files.  Only caught around library calls.
_READ_ERRORS: tuple[type[BaseException], ...] = (
    OSError,
    ValueError,
    TypeError,
    EOFError,
    KeyError,
    IndexError,
    SyntaxError,
    ArithmeticError,  # e.g. ZeroDivisionError from a corrupt TIFF tag
    RuntimeError,  # includes NotImplementedError (unsupported zip or TIFF features)
    MemoryError,  # a corrupt header claiming an enormous array
    struct.error,
    zlib.error,
    zipfile.BadZipFile,
    tokenize.TokenError,  # a corrupt .npy header
)


@dataclass(frozen=True)
class HeightField:
    """Heights on a W x H grid together with their quantised 16-bit samples."""

    values: np.ndarray  # (H, W) float64 heights in input units, after fill
    samples: np.ndarray  # (H, W) uint16, values ~= offset + scale * samples
    scale: float  # height units per sample count (quantisation step), > 0
    offset: float  # height of sample 0
    lossless: bool  # offset + scale * samples == values exactly
    source: str  # path or description, for reports
    filled: int = 0  # number of non-finite samples replaced by fill

    @property
    def width(self) -> int:
        return int(self.values.shape[1])

    @property
    def height(self) -> int:
        return int(self.values.shape[0])

    @property
    def max_quantisation_error(self) -> float:
        """Largest ``|values - (offset + scale * samples)|``; 0.0 when lossless."""
        if self.lossless:
            return 0.0
        recon = self.offset + self.scale * self.samples.astype(np.float64)
        return float(np.max(np.abs(self.values - recon)))

    def to_report(self) -> dict:
        """A JSON-able summary for reports."""
        return {
            "source": self.source,
            "width": self.width,
            "height": self.height,
            "scale": float(self.scale),
            "offset": float(self.offset),
            "lossless": bool(self.lossless),
            "quantisation_step": float(self.scale),
            "max_quantisation_error": self.max_quantisation_error,
            "filled": int(self.filled),
            "min": float(np.min(self.values)),
            "max": float(np.max(self.values)),
        }


# ---------------------------------------------------------------------------
# Public entry points


def parse_fill(text: str | float | None) -> None | str | float:
    """Parse a ``--fill`` option: None, ``"nearest"`` or a finite number."""
    if text is None:
        return None
    if isinstance(text, (int, float, np.integer, np.floating)) and not isinstance(text, bool):
        value = float(text)
    else:
        s = str(text).strip()
        if s.lower() == "nearest":
            return "nearest"
        try:
            value = float(s)
        except ValueError:
            raise InputError(
                f"bad --fill {_short(str(text))}: expected 'nearest' or a number (e.g. --fill 0)"
            ) from None
    if not np.isfinite(value):
        raise InputError(f"bad --fill {_short(str(text))}: the fill value must be a finite number")
    return value


def quantise(values: np.ndarray) -> tuple[np.ndarray, float, float, bool]:
    """Quantise finite heights to 16-bit samples: ``(samples, scale, offset, lossless)``.

    The rules are in the module docstring; ``offset + scale * samples``
    reconstructs the heights.
    """
    v = np.asarray(values)
    if v.dtype == np.bool_:
        v = v.astype(np.float64)
    v = v.astype(np.float64, copy=False)
    if v.size == 0:
        raise InputError("cannot quantise an empty height field")
    if not np.all(np.isfinite(v)):
        raise InputError("cannot quantise non-finite heights; use --fill nearest or --fill VALUE")
    vmin = float(np.min(v))
    vmax = float(np.max(v))
    span = vmax - vmin
    if not np.isfinite(span):
        raise InputError(f"height range {vmin:g} .. {vmax:g} is too large to quantise; rescale the heights")
    if span <= SAMPLE_MAX and bool(np.all(v == np.floor(v))):
        offset = 0.0 if (vmin >= 0 and vmax <= SAMPLE_MAX) else vmin
        samples = (v - offset).astype(np.uint16)
        return samples, 1.0, float(offset), True
    offset = vmin
    if span / SAMPLE_MAX == 0:  # constant (or a span so small the step underflows)
        scale = 1.0
        samples = np.zeros(v.shape, dtype=np.uint16)
    else:
        scale = span / SAMPLE_MAX
        counts = np.rint((v - offset) / scale)  # rint: round half to even
        samples = np.clip(counts, 0, SAMPLE_MAX).astype(np.uint16)
    lossless = bool(np.array_equal(offset + scale * samples.astype(np.float64), v))
    return samples, float(scale), float(offset), lossless


def from_array(array, source: str = "<array>", fill: str | float | None = None) -> HeightField:
    """Check an array of heights, fill non-finite samples if asked, quantise it."""
    fill_mode = parse_fill(fill)
    if isinstance(array, np.ma.MaskedArray):
        array = np.ma.filled(array.astype(np.float64), np.nan)
    try:
        arr = np.asarray(array)
    except (ValueError, TypeError) as e:
        raise InputError(f"{source}: not a numeric array ({_one_line(e)})") from None
    kind = arr.dtype.kind
    if kind not in "biuf":
        raise InputError(
            f"{source}: unsupported sample type {arr.dtype}; heights must be bool, integer or float"
        )
    if arr.ndim != 2:
        raise InputError(
            f"{source}: a height field must be a 2-D array, found {arr.ndim}-D shape {tuple(arr.shape)}"
        )
    h, w = arr.shape
    if h < 2 or w < 2:
        raise InputError(
            f"{source}: a height field needs at least 2 x 2 samples, found shape {tuple(arr.shape)} "
            f"({h} rows x {w} columns)"
        )
    values = np.array(arr, dtype=np.float64)  # a fresh copy, never a view of the caller's array
    bad = ~np.isfinite(values)
    n_bad = int(np.count_nonzero(bad))
    filled = 0
    if n_bad:
        if n_bad == values.size:
            raise InputError(
                f"{source}: all {n_bad} samples are NaN, infinite or no-data; nothing to fill from"
            )
        if fill_mode is None:
            raise InputError(
                f"{source}: {n_bad} of {values.size} samples are NaN, infinite or no-data; "
                f"use --fill nearest or --fill VALUE to replace them"
            )
        if fill_mode == "nearest":
            values = fill_nearest(values, bad)
        else:
            values[bad] = float(fill_mode)
        filled = n_bad
    samples, scale, offset, lossless = quantise(values)
    return HeightField(
        values=values,
        samples=samples,
        scale=scale,
        offset=offset,
        lossless=lossless,
        source=source,
        filled=filled,
    )


def load_heightfield(path: str, key: str | None = None, fill: str | float | None = None) -> HeightField:
    """Read a height field file (format by extension, else by content) and quantise it."""
    path = os.fspath(path)
    fill_mode = parse_fill(fill)  # a bad --fill is reported before the file is read
    try:
        with open(path, "rb") as f:
            head = f.read(64)
    except OSError as e:
        raise InputError(f"cannot read {path}: {e.strerror or _one_line(e)}") from None
    ext = os.path.splitext(path)[1].lower()
    fmt = _EXTENSIONS.get(ext) or _sniff(head)
    if fmt is None:
        raise InputError(
            f"cannot read {path}: unknown format (extension {ext or 'none'!r}, content not recognised); "
            f"supported formats: {SUPPORTED_FORMATS}"
        )
    if key is not None and fmt != "npz":
        raise InputError(f"{path}: --key applies only to .npz files, this is a {fmt} file")
    reader = {
        "npy": _read_npy,
        "npz": lambda p: _read_npz(p, key),
        "pgm": _read_pgm,
        "png": _read_png,
        "tiff": _read_tiff,
        "asc": _read_asc,
    }[fmt]
    return from_array(reader(path), source=path, fill=fill_mode)


# ---------------------------------------------------------------------------
# Filling non-finite samples


def fill_nearest(values: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Replace ``values[bad]`` by the value of the nearest sample that is not bad.

    Exact Euclidean nearest (squared distance ``drow**2 + dcol**2``), computed
    with the two-pass separable method of Felzenszwalb and Huttenlocher
    ("Distance transforms of sampled functions", 2012), vectorised over rows
    with NumPy:

    1. for every sample and every column, the nearest good row in that column
       (cumulative max/min of row indices; equally near above and below: above);
    2. for every row containing bad samples, the lower envelope of the parabolas
       ``(x - c)**2 + drow(c)**2`` over the columns ``c`` holding a good sample,
       evaluated at each column ``x`` (exact integer arithmetic).

    Ties are deterministic: among equally near good samples the one with the
    smallest column wins, then the smallest row.

    Small holes are resolved first by a local search: the offsets with
    ``drow**2 + dcol**2 <= 4**2`` are tried in (distance, dcol, drow) order and the
    first good sample found is the nearest (same tie rule).  Only rows holding
    samples farther than that from any good sample go through the two passes,
    whose cost is O(H*W) with one Python-level loop over columns per block of
    rows.  At least one sample must be good.  Returns a new array.
    """
    values = np.ascontiguousarray(values, dtype=np.float64)
    bad = np.asarray(bad, dtype=bool)
    out = values.copy()
    if not bad.any():
        return out
    good = ~bad
    if not good.any():
        raise InputError("all samples are NaN, infinite or no-data; nothing to fill from")
    h, w = values.shape

    # Stage 1: look for a good sample among the offsets with drow**2 + dcol**2 <= _LOCAL_RADIUS**2,
    # in increasing (distance, dcol, drow) order; the first one found is the nearest.  Only
    # samples within _LOCAL_RADIUS rows and columns of a good sample can succeed.
    near = _dilate(good, _LOCAL_RADIUS)
    hr, hc = np.nonzero(bad & near)
    todo = np.ones(len(hr), dtype=bool)
    for dr, dc in _LOCAL_OFFSETS:
        idx = np.nonzero(todo)[0]
        if not idx.size:
            break
        r, c = hr[idx] + dr, hc[idx] + dc
        inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        idx, r, c = idx[inside], r[inside], c[inside]
        hit = good[r, c]
        idx, r, c = idx[hit], r[hit], c[hit]
        out[hr[idx], hc[idx]] = values[r, c]
        todo[idx] = False
    far = bad & ~near
    far[hr[todo], hc[todo]] = True
    if not far.any():
        return out

    # Stage 2: exact two-pass method for the rows still holding unresolved samples.
    # Pass 1 (nearest good row in a column) runs on the columns that can matter only: first
    # those of the unresolved samples, whose own column bounds their distance D, then every
    # column within D of one of them.
    rows_h = np.arange(h)[:, None]
    far_cols = np.nonzero(far.any(axis=0))[0]
    c0, c1 = int(far_cols[0]), int(far_cols[-1])
    if 2 * (c1 - c0 + 1) > w:
        c0, c1 = 0, w - 1  # narrowing would not pay for a second pass
    up, down = _nearest_rows(good[:, c0 : c1 + 1])
    lo, hi = (0, w - 1) if (c0, c1) == (0, w - 1) else _reach(far[:, c0 : c1 + 1], up, down, rows_h, c0, w)
    if (lo, hi) != (c0, c1):
        c0, c1 = lo, hi
        up, down = _nearest_rows(good[:, c0 : c1 + 1])
    all_cols = np.nonzero(good[:, c0 : c1 + 1].any(axis=0))[0].astype(np.int64) + c0
    hole_rows = np.nonzero(far.any(axis=1))[0]
    flat = values.ravel()
    block = max(1, (1 << 22) // max(len(all_cols), 1))  # bound the envelope arrays to ~4M entries each
    for start in range(0, len(hole_rows), block):
        rr = hole_rows[start : start + block]
        ri = rr[:, None].astype(np.int64)
        fb = far[rr]
        xs = np.nonzero(fb.any(axis=0))[0]
        x0, x1 = int(xs[0]), int(xs[-1])
        ub, db = up[rr], down[rr]
        fbs = fb[:, x0 : x1 + 1]
        lo, hi = _reach(fbs, ub[:, x0 - c0 : x1 - c0 + 1], db[:, x0 - c0 : x1 - c0 + 1], ri, x0, w)
        cols = all_cols[(all_cols >= lo) & (all_cols <= hi)]
        uc = ub[:, cols - c0].astype(np.int64)
        dc = db[:, cols - c0].astype(np.int64)
        near_row = np.where(ri - uc <= dc - ri, uc, dc)  # nearest good row per (row, column); ties: above
        dist = np.abs(near_row - ri)
        cost = dist * dist + cols[None, :] ** 2  # f(c) + c**2 of each parabola
        which = _envelope_argmin(cost, cols, x0, x1)  # (len(rr), x1 - x0 + 1) index into cols
        src = flat[np.take_along_axis(near_row, which, axis=1) * w + cols[which]]
        out[rr, x0 : x1 + 1] = np.where(fbs, src, out[rr, x0 : x1 + 1])
    return out


_LOCAL_RADIUS = 4
_LOCAL_OFFSETS = sorted(
    (
        (dr, dc)
        for dr in range(-_LOCAL_RADIUS, _LOCAL_RADIUS + 1)
        for dc in range(-_LOCAL_RADIUS, _LOCAL_RADIUS + 1)
        if 0 < dr * dr + dc * dc <= _LOCAL_RADIUS**2
    ),
    key=lambda o: (o[0] * o[0] + o[1] * o[1], o[1], o[0]),
)


def _nearest_rows(good: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, the nearest good row at or above it and at or below it in its column.

    int32 arrays; a side without a good sample gives -2**30 (above) or 2**30 (below).
    """
    missing = np.int32(1 << 30)
    rows = np.arange(good.shape[0], dtype=np.int32)[:, None]
    up = np.where(good, rows, -missing)
    np.maximum.accumulate(up, axis=0, out=up)
    down = np.where(good, rows, missing)[::-1]
    down = np.ascontiguousarray(np.minimum.accumulate(down, axis=0)[::-1])
    return up, down


def _reach(mask: np.ndarray, up: np.ndarray, down: np.ndarray, rows: np.ndarray, x0: int, w: int):
    """Column range ``(lo, hi)`` holding the nearest good sample of every masked sample.

    A masked sample at (row, x) has a good sample ``D = min(row - up, down - row)`` away in
    its own column, so its nearest lies in columns ``x - D .. x + D``; clipped to 0..w-1.
    """
    reach = np.minimum(rows - up, down - rows)
    x = np.arange(x0, x0 + mask.shape[1])[None, :]
    lo = int(np.min(np.where(mask, x - reach, w)))
    hi = int(np.max(np.where(mask, x + reach, -1)))
    return max(0, lo), min(w - 1, hi)


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Samples within ``radius`` rows and ``radius`` columns of a True sample."""
    out = mask.copy()
    for axis in (0, 1):
        src = out.copy()
        n = src.shape[axis]
        for d in range(1, min(radius, n - 1) + 1):
            if axis == 0:
                out[d:] |= src[:-d]
                out[:-d] |= src[d:]
            else:
                out[:, d:] |= src[:, :-d]
                out[:, :-d] |= src[:, d:]
    return out


def _envelope_argmin(cost: np.ndarray, cols: np.ndarray, x0: int, x1: int) -> np.ndarray:
    """For each row and x in x0..x1, the index p minimising ``cost[:, p] - 2*x*cols[p]``.

    ``cost[:, p] = f(p) + cols[p]**2``, so this minimises ``(x - cols[p])**2 + f(p)``:
    the lower envelope of parabolas, built and queried for all rows at once.
    Breakpoints ``z = num / den`` are exact integer fractions (den > 0); ties go to
    the smaller column.
    """
    n, m = cost.shape
    big = np.int64(1) << 40  # stands for +-infinity in breakpoints
    ar = np.arange(n)
    v = np.zeros((n, m), dtype=np.int64)  # envelope parabolas (index into cols)
    znum = np.zeros((n, m + 1), dtype=np.int64)
    zden = np.ones((n, m + 1), dtype=np.int64)
    k = np.zeros(n, dtype=np.int64)  # index of the last parabola in each envelope
    znum[:, 0] = -big
    znum[:, 1] = big
    for p in range(1, m):
        q = cols[p]
        fq = cost[:, p]
        b = ar
        while b.size:
            kb = k[b]
            vp = v[b, kb]
            num = fq[b] - cost[b, vp]
            den = 2 * (q - cols[vp])
            pop = num * zden[b, kb] <= znum[b, kb] * den  # new breakpoint s <= z[k]
            keep = ~pop
            if keep.any():
                pb = b[keep]
                kk = kb[keep] + 1
                k[pb] = kk
                v[pb, kk] = p
                znum[pb, kk] = num[keep]
                zden[pb, kk] = den[keep]
                znum[pb, kk + 1] = big
                zden[pb, kk + 1] = 1
            b = b[pop]
            k[b] -= 1
    which = np.empty((n, x1 - x0 + 1), dtype=np.int64)
    kq = np.zeros(n, dtype=np.int64)
    for x in range(x0, x1 + 1):
        b = ar
        while b.size:
            nk = kq[b] + 1
            adv = znum[b, nk] < x * zden[b, nk]  # z[k+1] < x: move right
            b = b[adv]
            kq[b] += 1
        which[:, x - x0] = v[ar, kq]
    return which


# ---------------------------------------------------------------------------
# Format readers: each returns an array (validated later by from_array)


def _sniff(head: bytes) -> str | None:
    """Identify a format from the first bytes of a file, or None."""
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if head.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        return "npz"
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "tiff"
    if re.match(rb"P[25]\s", head):
        return "pgm"
    m = re.match(rb"\s*([A-Za-z_]+)\s", head)
    if m and m.group(1).decode("ascii").lower() in _ASC_KEYS:
        return "asc"
    return None


def _read_bytes(path: str) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        raise InputError(f"cannot read {path}: {e.strerror or _one_line(e)}") from None


def _read_npy(path: str) -> np.ndarray:
    try:
        arr = np.load(path, allow_pickle=False)
    except _READ_ERRORS as e:
        raise InputError(f"cannot read {path}: not a valid .npy file ({_one_line(e)})") from None
    if not isinstance(arr, np.ndarray):
        if hasattr(arr, "close"):
            arr.close()
        raise InputError(f"cannot read {path}: not a .npy file (it is a .npz archive); rename it to .npz")
    return arr


def _read_npz(path: str, key: str | None) -> np.ndarray:
    try:
        npz = np.load(path, allow_pickle=False)
    except _READ_ERRORS as e:
        raise InputError(f"cannot read {path}: not a valid .npz file ({_one_line(e)})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise InputError(f"cannot read {path}: not a .npz archive (it is a .npy file); rename it to .npy")
    with npz:
        names = list(npz.files)
        listed = ", ".join(names)
        if not names:
            raise InputError(f"{path}: the .npz archive holds no arrays")
        if key is None:
            if len(names) != 1:
                raise InputError(
                    f"{path}: the .npz archive holds {len(names)} arrays ({listed}); "
                    f"choose one with --key NAME"
                )
            key = names[0]
        elif key not in names:
            raise InputError(f"{path}: no array {key!r} in the .npz archive; its arrays are: {listed}")
        try:
            return np.asarray(npz[key])
        except _READ_ERRORS as e:
            raise InputError(f"cannot read {path}: array {key!r} is corrupt ({_one_line(e)})") from None


def _pgm_header(data: bytes, path: str) -> tuple[bytes, int, int, int, int]:
    """Parse ``magic width height maxval``; return them and the offset after the header."""
    magic = data[:2]
    if magic not in (b"P2", b"P5"):
        kinds = {
            b"P1": "a bitmap (PBM)",
            b"P4": "a bitmap (PBM)",
            b"P3": "a colour PPM",
            b"P6": "a colour PPM",
        }
        kind = kinds.get(magic, "not a PGM file")
        raise InputError(
            f"cannot read {path}: {kind} (magic {_short(magic.decode('latin-1'))}); "
            f"only P2/P5 graymaps are supported, convert it to 16-bit grayscale"
        )
    pos = 2
    fields = []
    n = len(data)
    while len(fields) < 3:
        # skip whitespace and comments
        while pos < n:
            c = data[pos : pos + 1]
            if c in b" \t\r\n\v\f":
                pos += 1
            elif c == b"#":
                while pos < n and data[pos : pos + 1] not in b"\r\n":
                    pos += 1
            else:
                break
        start = pos
        while pos < n and data[pos : pos + 1].isdigit():
            pos += 1
        if start == pos:
            names = ("width", "height", "maxval")
            missing = names[len(fields)]
            raise InputError(f"cannot read {path}: PGM header is truncated or corrupt (no {missing})")
        fields.append(int(data[start:pos]))
    width, height, maxval = fields
    if not 1 <= maxval <= 65535:
        raise InputError(f"cannot read {path}: PGM maxval {maxval} is outside 1..65535")
    if pos < n and data[pos : pos + 1] in b" \t\r\n\v\f":
        pos += 1  # the single whitespace character ending the header
    elif magic == b"P5":
        raise InputError(f"cannot read {path}: PGM header is truncated or corrupt (no data after maxval)")
    return magic, width, height, maxval, pos


def _read_pgm(path: str) -> np.ndarray:
    data = _read_bytes(path)
    magic, width, height, maxval, pos = _pgm_header(data, path)
    count = width * height
    if magic == b"P5":
        dtype = np.dtype(np.uint8) if maxval <= 255 else np.dtype(">u2")
        need = count * dtype.itemsize
        raster = data[pos : pos + need]
        found = len(raster) // dtype.itemsize
        if found < count:
            raise InputError(
                f"cannot read {path}: PGM data is truncated: expected {width} x {height} = {count} samples, "
                f"found {found}"
            )
        arr = np.frombuffer(raster, dtype=dtype).astype(np.int64)
    else:
        body = re.sub(rb"#[^\r\n]*", b" ", data[pos:])
        tokens = body.split()
        if len(tokens) != count:
            what = "truncated" if len(tokens) < count else "too long"
            raise InputError(
                f"cannot read {path}: PGM data is {what}: expected {width} x {height} = {count} samples, "
                f"found {len(tokens)}"
            )
        try:
            arr = np.array(tokens).astype(np.int64) if tokens else np.zeros(0, dtype=np.int64)
        except (ValueError, OverflowError):
            raise InputError(f"cannot read {path}: PGM data holds a value that is not an integer") from None
    if arr.size and (arr.min() < 0 or arr.max() > maxval):
        bad = int(arr.max()) if arr.max() > maxval else int(arr.min())
        raise InputError(
            f"cannot read {path}: PGM sample {bad} is outside 0..maxval ({maxval}); fix the header's maxval"
        )
    return arr.reshape(height, width)


def _read_png(path: str) -> np.ndarray:
    from PIL import Image  # imported here: only PNG needs Pillow

    try:
        with Image.open(path, formats=["PNG"]) as img:
            img.load()
            mode = img.mode
            bands = len(img.getbands())
            if bands != 1 or mode in ("P", "PA"):
                kind = f"{bands} channels" if mode != "P" else "a colour palette"
                raise InputError(
                    f"{path}: PNG has {kind} (mode {mode}); a height field needs one channel, "
                    f"convert it to 16-bit grayscale"
                )
            arr = np.asarray(img)
    except (*_READ_ERRORS, Image.DecompressionBombError) as e:
        raise InputError(f"cannot read {path}: not a valid PNG file ({_one_line(e)})") from None
    if arr.dtype.byteorder == ">":
        arr = arr.astype(arr.dtype.newbyteorder("="))
    return arr


def _read_tiff(path: str) -> np.ndarray:
    import tifffile  # imported here: only TIFF needs tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            if not tif.series or not tif.pages:
                raise InputError(f"cannot read {path}: the TIFF file holds no image")
            arr = tif.series[0].asarray()
            tag = tif.pages[0].tags.get(_GDAL_NODATA_TAG)
            nodata_text = tag.value if tag is not None else None
    except _READ_ERRORS as e:
        raise InputError(f"cannot read {path}: not a valid TIFF file ({_one_line(e)})") from None
    arr = np.asarray(arr)
    if arr.ndim == 3 and arr.shape[0] == 1:
        arr = arr[0]
    elif arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    elif arr.ndim == 3:
        raise InputError(
            f"{path}: TIFF has shape {tuple(arr.shape)} (several bands or pages); "
            f"a height field needs a single band, extract one (e.g. gdal_translate -b 1)"
        )
    if nodata_text is not None and arr.dtype.kind in "biuf":
        if isinstance(nodata_text, bytes):
            nodata_text = nodata_text.decode("latin-1")
        text = str(nodata_text).strip().strip("\x00").strip()
        try:
            nodata = float(text)
        except ValueError:
            raise InputError(f"{path}: GDAL_NODATA tag {_short(text)} is not a number") from None
        if not np.isnan(nodata):
            arr = _mark_nodata(arr, nodata)
    return arr


def _read_asc(path: str) -> np.ndarray:
    text = _read_bytes(path).decode("latin-1")
    where = f"cannot read {path}: ESRI ASCII grid"
    tokens = text.split()
    header: dict[str, str] = {}
    i = 0
    while i < len(tokens) and not _is_number(tokens[i]):
        name = tokens[i].lower()
        if name not in _ASC_KEYS:
            raise InputError(
                f"{where}: unknown header key {_short(tokens[i])} "
                f"(expected ncols, nrows, xllcorner, yllcorner, cellsize, NODATA_value)"
            )
        if name in header:
            raise InputError(f"{where}: header repeats {tokens[i]}")
        if i + 1 >= len(tokens) or not _is_number(tokens[i + 1]):
            raise InputError(f"{where}: header key {tokens[i]} has no numeric value")
        header[name] = tokens[i + 1]
        i += 2
    dims = []
    for name in ("ncols", "nrows"):
        if name not in header:
            raise InputError(f"{where}: header has no {name}")
        try:
            dims.append(int(header[name]))
        except ValueError:
            raise InputError(f"{where}: {name} {header[name]!r} is not an integer") from None
    ncols, nrows = dims
    if ncols < 1 or nrows < 1:
        raise InputError(f"{where}: the grid is {nrows} rows x {ncols} columns; both must be >= 1")
    count = ncols * nrows
    data = tokens[i:]
    if len(data) != count:
        what = "truncated" if len(data) < count else "too long"
        raise InputError(
            f"{where}: data is {what}: expected {nrows} x {ncols} = {count} values, found {len(data)}"
        )
    try:
        arr = np.array(data, dtype=np.float64)
    except ValueError:
        raise InputError(f"{where}: data holds a value that is not a number") from None
    arr = arr.reshape(nrows, ncols)
    if "nodata_value" in header:
        nodata = float(header["nodata_value"])
        if not np.isnan(nodata):
            arr = _mark_nodata(arr, nodata)
    return arr


# ---------------------------------------------------------------------------
# Helpers


def _mark_nodata(arr: np.ndarray, nodata: float) -> np.ndarray:
    """A float64 copy of ``arr`` with samples equal to ``nodata`` set to NaN.

    For float arrays a sample also matches when it equals ``nodata`` converted
    to the array's type (GDAL casts the no-data value to the band type).
    """
    values = arr.astype(np.float64)
    mask = values == nodata
    if arr.dtype.kind == "f":
        with np.errstate(over="ignore", invalid="ignore"):
            mask |= arr == arr.dtype.type(nodata)
    if mask.any():
        values[mask] = np.nan
    return values


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _one_line(e: BaseException | str) -> str:
    text = " ".join(str(e).split())
    return text or type(e).__name__


def _short(text: str, limit: int = 40) -> str:
    text = _one_line(text)
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return repr(text)
