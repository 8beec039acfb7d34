"""Reading height fields and quantising them to 16-bit unsigned samples.

A height field is a 2-D grid of heights with H rows and W columns (W, H >= 2).
Row 0 is the first row stored in the file (north for DEMs), column 0 the left
column.  :func:`load_heightfield` reads a file, :func:`from_array` takes an
array; both return a :class:`HeightField` holding the heights (float64) and
their quantised 16-bit samples.

Formats.  NumPy files, PGM and PNG have thin readers (wavemesh.io.readers: numpy, Pillow); every
other raster is read by rasterio, that is by GDAL.  The extension chooses a thin
reader (case-insensitive); a file with another extension whose first bytes are
those of a NumPy file, a PGM or a PNG goes to that reader, and anything else to
GDAL.

- ``.npy``: a NumPy array (``allow_pickle=False``).
- ``.npz``: a NumPy archive; ``key`` names the array.  Without a key the archive
  must hold exactly one array.
- ``.pgm``: binary (P5, one byte per sample when maxval <= 255, else two bytes
  big-endian) or plain (P2) graymap, ``#`` comments allowed in the header.  The
  sample values are the heights (they are not scaled by maxval).
- ``.png``: one-channel PNG (modes 1, L, I;16, I;16B, I;16L, I, F) read with
  Pillow; 16-bit PNGs keep their full 16-bit values.  Colour, palette or alpha
  images are rejected.
- GDAL rasters (:func:`_read_raster`): GeoTIFF and plain TIFF (``.tif``,
  ``.tiff``), ESRI ASCII grids (``.asc``, GDAL's AAIGrid: a header with ``ncols``,
  ``nrows``, ``xllcorner``/``xllcenter``, ``yllcorner``/``yllcenter``, ``cellsize``
  or ``dx``/``dy``, optionally ``NODATA_value``; read as float64), SRTM tiles
  (``.hgt`` under the tile's own name, e.g. ``N36W084.hgt``: GDAL knows the
  tile's place and size from it), Erdas Imagine (``.img``), ESRI ``.bil``/``.flt``
  with their ``.hdr``, GDAL virtual rasters (``.vrt``) and GDAL's other raster
  formats.  The raster must hold one band and one image.  Samples GDAL masks
  (equal to the band's no-data value, or masked by the file's mask band) become
  NaN; a band scale and offset are applied.  The georeference is kept in
  ``HeightField.transform`` and ``HeightField.crs`` (an .npz's ``dx``, ``dy``, ``xmin``, ``ymin``
  too, :func:`_npz_transform`); :mod:`wavemesh.io.georef` derives the cell size and the coordinates.
  An ESRI ASCII grid's data must be exactly ``nrows * ncols`` numbers, and its header's
  values numbers (GDAL itself would read missing samples or text as 0 without a word:
  ``NODATA_value abc`` would mask every 0).  A no-data value must be a number the band's
  samples can hold (:func:`check_nodata`: a GeoTIFF's GDAL_NODATA tag ``xyzzy``, NaN on
  int16 or -9999 on uint16 are refused; GDAL would read 0, or drop the value).

Every reader reads a regular file only (:func:`wavemesh.io.readers.regular_file`: a FIFO would block, a
device such as /dev/zero never ends) and no more than its header says: a P5 PGM's
W x H samples, an .npy's shape (checked against the file's size before numpy sets the
array aside).  ``load_heightfield(..., size_check=f)`` calls ``f(W, H, itemsize)`` once the
header has told the size, before the samples are read (the untiled run's memory estimate).

Accepted data: a 2-D array of bool, integer or float samples, at least 2 x 2; a
constant field too (two triangles).  Heights become float64: 64-bit integers
must fit one exactly (at most 53 significant bits, e.g. any |v| <= 2^53, or
+-2^62), else they are refused rather than changed.
Non-finite samples (NaN, +-inf, no-data) are an error unless ``fill`` is given:
``fill="nearest"`` replaces each by the value of a nearest finite sample
(exact Euclidean distance, :func:`fill_nearest`) and a number replaces them by
that number.  Every problem a user can cause is an
:class:`~wavemesh.errors.InputError` with a one-line message.

Quantisation (the contract the RTL and the firmware rely on; ``quantise``):

- Heights are float64 ``v``; ``min``/``max`` are their extremes (bool becomes 0/1).
- Lossless case: every ``v`` is an integer (also when stored as float) and
  ``max - min <= 65535``.  Then ``scale = 1.0``; ``offset = 0.0`` when
  ``0 <= min`` and ``max <= 65535``, else ``offset = min``; ``samples = v - offset``
  and ``lossless = True``.
- Otherwise: ``offset = min`` (0.0 for a least height of -0.0); ``scale = (max - min) / 65535``
  (``scale = 1.0`` when ``max == min``); ``samples = clip(rint((v - offset) / scale), 0, 65535)`` where
  ``rint`` rounds half to even; the quantisation error is at most ``scale / 2``.
  ``lossless`` is True only when ``offset + scale * samples == v`` exactly
  (e.g. a constant non-integer field).
- In every case a height is reconstructed as ``offset + scale * sample``.
"""

from __future__ import annotations

import os
import sys
from dataclasses import replace
from functools import cached_property

import numpy as np

from wavemesh.errors import InputError
from wavemesh.io.readers import (
    _EXTENSIONS,
    _library_warnings_quiet,
    _one_line,
    _read_head,
    _read_npy,
    _read_npz,
    _read_pgm,
    _read_png,
    _read_raster,
    _short,
    _sniff,
)
from wavemesh.model.holemask import stranded
from wavemesh.record import record

SAMPLE_MAX = 65535  # largest 16-bit unsigned sample
# A raster's header can claim any size (300 bytes of TIFF saying 6 x 16777221 samples took GDAL and the
# fill 3.7 GB and minutes): a side longer than the refiner's (MAX_SIDE) is refused before GDAL reads it.


@record(frozen=True)
class HeightField:
    """Heights on a W x H grid together with their quantised 16-bit samples."""

    values: np.ndarray  # (H, W) float64 heights in input units, after fill
    samples: np.ndarray  # (H, W) uint16, values ~= offset + scale * samples
    scale: float  # height units per sample count (quantisation step), > 0
    offset: float  # height of sample 0
    lossless: bool  # offset + scale * samples == values exactly
    source: str  # path or description, for reports
    filled: int = 0  # number of non-finite samples replaced by fill
    # The georeference of a GDAL raster or an .npz with dx, dy, xmin, ymin (None otherwise): the affine
    # (a, b, c, d, e, f) with x = a*col + b*row + c, y = d*col + e*row + f, (0, 0) the outer corner of
    # sample (0, 0)'s cell (samples sit at cell centres); and the CRS ("EPSG:4326" or WKT).
    transform: tuple[float, ...] | None = None
    crs: str | None = None
    # The cell size (dx, dy) in ground units when --spacing gave it (None: from the transform, or 1 without
    # one); wavemesh.io.georef.ground tells the cell size and the coordinates of every height field.
    spacing: tuple[float, float] | None = None
    # --nodata hole: (H, W) bool, True where the sample is invalid (NaN, no-data, --invalid VALUE); values
    # and samples hold a nearest valid height there, for the filter bank only
    # (wavemesh.model.holemask).  None: none.
    mask: np.ndarray | None = None
    # --nodata hole: (H, W) bool, True at the valid samples the mask takes in because no grid cell's
    # triangle of three valid samples has them as a corner (isolated samples, one-sample-wide lines:
    # wavemesh.model.holemask.stranded).  None: none.
    lone: np.ndarray | None = None

    @property
    def stranded(self) -> int:
        """How many valid samples --nodata hole meshes as invalid (``lone``)."""
        return 0 if self.lone is None else int(np.count_nonzero(self.lone))

    @property
    def width(self) -> int:
        return int(self.values.shape[1])

    @property
    def height(self) -> int:
        return int(self.values.shape[0])

    @cached_property  # once per height field (a pass over the grid; mesh asks three times)
    def max_quantisation_error(self) -> float:
        """Largest ``|values - (offset + scale * samples)|``; 0.0 when lossless."""
        if self.lossless:
            return 0.0
        from wavemesh.refine import native  # the host stages in C (equal to the lines below, tested)

        fast = native.quant_error(self.values, self.samples, self.offset, self.scale)
        if fast is not None:
            return fast
        recon = self.offset + self.scale * self.samples.astype(np.float64)
        return float(np.max(np.abs(self.values - recon)))

    @cached_property  # once per height field (from_array's quantising pass finds them: no pass of its own)
    def extremes(self) -> tuple[float, float]:
        """The least and the largest height (default_tau's range, the report's)."""
        return float(np.min(self.values)), float(np.max(self.values))

    def refiner_zeta(self, zeta: float) -> float:
        """The zeta the refiner is given on the 16-bit samples (`mesh`, `stream`, every tile): for lossy
        quantisation a sample is off its input value by at most q, and so is a plane through three samples,
        so zeta - 2q on the samples keeps the vertical bound on the input values (docs/refiner.md,
        "Quantised input"); never below 0."""
        return refiner_zeta(zeta, self.max_quantisation_error)

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
            "min": self.extremes[0],
            "max": self.extremes[1],
        } | ({"invalid": int(np.count_nonzero(self.mask)) - self.stranded, "stranded": self.stranded}
             if self.mask is not None else {})


# ---------------------------------------------------------------------------
# Public entry points


def refiner_zeta(zeta: float, q: float) -> float:
    """zeta on the 16-bit samples for a quantisation whose largest error is q (HeightField.refiner_zeta,
    a tiled run's whole grid): zeta - 2q, never below 0; zeta itself when lossless."""
    return max(0.0, zeta - 2 * q) if q > 0 else zeta


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


def quantise(values: np.ndarray, native: bool = True) -> tuple[np.ndarray, float, float, bool]:
    """Quantise finite heights to 16-bit samples: ``(samples, scale, offset, lossless)``.

    The rules are in the module docstring; ``offset + scale * samples``
    reconstructs the heights.  ``native``: by the C library's wm_host_quantise when it loads (one pass,
    on every core: the same result); False: by the numpy lines here alone, the model it is tested against.
    """
    v = np.asarray(values)
    if v.dtype == np.bool_:
        v = v.astype(np.float64)
    v = v.astype(np.float64, copy=False)
    if v.size == 0:
        raise InputError("cannot quantise an empty height field")
    if native:
        from wavemesh.refine import (
            native as lib,  # the same rules in C, one pass (tested equal to the lines below)
        )

        fast = lib.quantise(v)
        if isinstance(fast, tuple):
            return fast[:4]
    if not np.all(np.isfinite(v)):
        raise InputError("cannot quantise non-finite heights; use --fill nearest or --fill VALUE")
    vmin = float(np.min(v))
    vmax = float(np.max(v))
    scale, offset, exact = quant_rule(vmin, vmax, bool(np.all(v == np.floor(v))))
    samples = to_samples(v, scale, offset, exact)
    lossless = exact or bool(np.array_equal(offset + scale * samples.astype(np.float64), v))
    return samples, scale, offset, lossless


def quant_rule(vmin: float, vmax: float, integers: bool) -> tuple[float, float, bool]:
    """quantise's scale and offset for finite heights in vmin..vmax (``integers``: all of them whole
    numbers): ``(scale, offset, exact)``, exact for integers within SAMPLE_MAX of each other (scale 1).
    wavemesh.tiles finds vmin, vmax and ``integers`` strip by strip and quantises every tile by them."""
    vmin += 0.0  # a least height of -0.0 is 0.0: a zero offset is +0.0 (whichever zero np.min returns)
    span = vmax - vmin
    if not np.isfinite(span):
        raise InputError(f"height range {vmin:g} .. {vmax:g} is too large to quantise; rescale the heights")
    if span <= SAMPLE_MAX and integers:
        return 1.0, 0.0 if (vmin >= 0 and vmax <= SAMPLE_MAX) else float(vmin), True
    if span / SAMPLE_MAX == 0:  # constant (or a span so small the step underflows)
        return 1.0, float(vmin), False
    return float(span / SAMPLE_MAX), float(vmin), False


def to_samples(v: np.ndarray, scale: float, offset: float, exact: bool) -> np.ndarray:
    """Heights to 16-bit samples by quant_rule's scale and offset: rint (half to even), clipped (a constant
    grid, scale 1: all 0)."""
    if exact:
        return (v - offset).astype(np.uint16)
    return np.clip(np.rint((v - offset) / scale), 0, SAMPLE_MAX).astype(np.uint16)


def from_array(array, source: str = "<array>", fill: str | float | None = None, *,
               invalid: float | None = None, holes: bool = False, owned: bool = False) -> HeightField:
    """Check an array of heights, fill non-finite samples if asked, quantise it.  ``invalid``: samples
    equal to it are no-data too; ``holes`` (--nodata hole): no-data samples become the mask.  ``owned``:
    the array is the caller's to give away (a reader's fresh one): a writeable C-ordered float64 array is
    then kept as the values, not copied (a 4096^2 grid: 128 MiB and ~0.1 s less)."""
    fill_mode = parse_fill(fill)
    ma = sys.modules.get("numpy.ma")  # a masked array means numpy.ma is loaded; np.ma would load it (~15 ms)
    if ma is not None and isinstance(array, ma.MaskedArray):
        with np.errstate(invalid="ignore"):  # a signalling NaN is cast quietly: a NaN like any other
            array = ma.filled(array.astype(np.float64), np.nan)
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
    with np.errstate(invalid="ignore"):  # a signalling NaN (float32 input) raises no warning: reported below
        keep = (owned and type(arr) is np.ndarray and arr.dtype == np.float64 and arr.flags.c_contiguous
                and arr.flags.writeable and not isinstance(arr.base, np.memmap))
        values = arr if keep else np.array(arr, dtype=np.float64)  # a fresh copy, never a caller's view
    if kind in "iu" and arr.dtype.itemsize == 8:
        _check_exact_integers(arr, values, source)
    if invalid is None and not holes:
        from wavemesh.refine import (
            native,  # every height finite: quantised in one pass, no mask made (tested equal)
        )

        fast = native.quantise(values)
        if isinstance(fast, tuple):
            samples, scale, offset, lossless = fast[:4]
            hf = HeightField(values=values, samples=samples, scale=scale, offset=offset, lossless=lossless,
                             source=source)
            # the same passes measured max_quantisation_error (wm_host_quantise: quant_error's terms, tested
            # equal) and found the extremes: kept as those cached properties' values, not measured again
            # (a pass over the grid each)
            hf.__dict__["max_quantisation_error"] = 0.0 if lossless else fast[4]
            hf.__dict__["extremes"] = fast[5:7]
            return hf
    bad = ~np.isfinite(values)
    if invalid is not None:
        bad |= values == invalid
    n_bad = int(np.count_nonzero(bad))
    filled = 0
    if n_bad and holes:
        if n_bad == values.size:
            raise InputError(f"{source}: all {n_bad} samples are invalid; there is nothing to mesh")

        lone = stranded(bad)  # meshed as invalid, as range-image meshers do: no triangle could cover them
        if n_bad + int(lone.sum()) == values.size:
            raise InputError(f"{source}: no three valid samples form a triangle of a grid cell; there is "
                             "nothing to mesh")
        hidden = fill_nearest(values, bad)  # heights under the holes, for the filter bank alone
        samples, scale, offset, lossless = quantise(hidden)
        return HeightField(values=hidden, samples=samples, scale=scale, offset=offset, lossless=lossless,
                           source=source, mask=bad | lone, lone=lone if lone.any() else None)
    if n_bad:
        if n_bad == values.size:
            raise InputError(
                f"{source}: all {n_bad} samples are NaN, infinite or no-data; nothing to fill from"
            )
        if fill_mode is None:
            raise InputError(
                f"{source}: {n_bad} of {values.size} samples are NaN, infinite or no-data; "
                f"use --fill nearest or --fill VALUE to replace them, or --nodata hole to leave holes"
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


def _check_exact_integers(arr: np.ndarray, values: np.ndarray, source: str) -> None:
    """64-bit integer heights must convert to float64 exactly (every integer up to 2^53 does, larger ones
    only some, e.g. +-2^62): the heights written into the mesh are the float64 ones, and an input
    silently changed by up to 2^10 per sample would not be the input."""
    if arr.size == 0 or (int(arr.min()) >= -(1 << 53) and int(arr.max()) <= 1 << 53):
        return
    limit = float(1 << 63) if arr.dtype.kind == "i" else float(1 << 64)
    outside = (values >= limit) | (values < -limit)  # rounded up to 2^63 (2^64): not the integer given
    back = np.where(outside, 0, values).astype(arr.dtype)
    inexact = outside | (back != arr)
    if inexact.any():
        row, col = (int(i) for i in np.argwhere(inexact)[0])
        raise InputError(
            f"{source}: {int(np.count_nonzero(inexact))} integer heights have more than 53 significant bits, "
            f"which a float64 cannot hold (e.g. {int(arr[row, col])} at row {row}, column {col})",
            hint="divide the heights down, or give them as float64",
        )


def load_heightfield(path: str, key: str | None = None, fill: str | float | None = None, *,
                     invalid: float | None = None, holes: bool = False, size_check=None) -> HeightField:
    """Read a height field file (a thin reader by extension or first bytes, else GDAL) and quantise it;
    ``invalid`` and ``holes`` as from_array's.  ``size_check(width, height, itemsize)``, when given, is
    called once the file's header has told its size, before its samples are read (wavemesh.api's memory
    estimate)."""
    path = os.fspath(path)
    fill_mode = parse_fill(fill)  # a bad --fill is reported before the file is read
    marks = {"invalid": invalid, "holes": holes}
    size_check = size_check or (lambda w, h, itemsize: None)
    head = _read_head(path, 64)
    ext = os.path.splitext(path)[1].lower()
    fmt = _EXTENSIONS.get(ext) or _sniff(head) or "raster"
    if key is not None and fmt != "npz":
        what = "GDAL raster" if fmt == "raster" else fmt
        raise InputError(f"{path}: --key applies only to .npz files, this is a {what} file")
    if fmt == "raster":
        array, transform, crs = _read_raster(path, ext, size_check)
        hf = from_array(array, source=path, fill=fill_mode, owned=True, **marks)
        return _measured(hf, replace(hf, transform=transform, crs=crs))
    if fmt == "npz":
        with _library_warnings_quiet():
            array, transform = _read_npz(path, key, size_check)
        hf = from_array(array, source=path, fill=fill_mode, owned=True, **marks)
        return _measured(hf, replace(hf, transform=transform))
    reader = {
        "npy": _read_npy,
        "pgm": _read_pgm,
        "png": _read_png,
    }[fmt]
    with _library_warnings_quiet():
        array = reader(path, size_check)
    return from_array(array, source=path, fill=fill_mode, owned=True, **marks)


def _measured(hf: HeightField, new: HeightField) -> HeightField:
    """``new``, a copy of ``hf`` with other georeference, with what was measured of hf's heights (the
    cached properties: the same heights, no pass over them again)."""
    for name in ("max_quantisation_error", "extremes"):
        if name in hf.__dict__:
            new.__dict__[name] = hf.__dict__[name]
    return new


# ---------------------------------------------------------------------------
# Filling non-finite samples


def fill_nearest(values: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Replace ``values[bad]`` by the value of a nearest sample that is not bad.

    Nearest by exact Euclidean distance on the grid (``drow**2 + dcol**2``):
    ``scipy.ndimage.distance_transform_edt`` with ``return_indices=True`` gives,
    for every bad sample, the row and column of a nearest good one.

    Ties (several good samples equally near): the choice is scipy's.  Its
    algorithm is a fixed computation on the mask alone, so the choice depends on
    which samples are bad, never on the heights, and is the same on every run;
    scipy documents no rule, and wavemesh promises none beyond "a nearest good
    sample".  (Measured on scipy 1.17: the smallest column, then the smallest
    row, which is also what the hand-written fill it replaced did.)

    At least one sample must be good.  Returns a new float64 array; costs
    O(H*W) time and two int32 index arrays of H*W.
    """
    values = np.asarray(values, dtype=np.float64)
    bad = np.asarray(bad, dtype=bool)
    out = values.copy()
    if not bad.any():
        return out
    if bad.all():
        raise InputError("all samples are NaN, infinite or no-data; nothing to fill from")
    from scipy import ndimage  # imported here: only --fill nearest needs scipy

    rows, cols = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
    out[bad] = values[rows[bad], cols[bad]]
    return out
