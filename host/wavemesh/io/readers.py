"""The height field files' readers: .npy/.npz, PGM, PNG, and GeoTIFF/TIFF, ESRI ASCII, SRTM .hgt, .img, .bil,
.vrt and GDAL's other single-band rasters through rasterio; each returns the raw array (and the
raster's georeference); :func:`wavemesh.io.heightfield.load_heightfield` picks the reader and makes the
:class:`~wavemesh.io.heightfield.HeightField`.  Every reader reads a regular file only
(:func:`regular_file`) and turns a library's error into one InputError line naming the file.
"""

from __future__ import annotations

import contextlib
import os
import re
import stat
import struct
import sys
import warnings

import numpy as np

from wavemesh.errors import InputError
from wavemesh.limits import MAX_SIDE

SUPPORTED_FORMATS = (
    ".npy, .npz, .pgm (P2/P5), .png, and through GDAL: .tif/.tiff (GeoTIFF), .asc (ESRI ASCII grid), "
    ".hgt (SRTM), .img (Erdas Imagine), .bil/.flt (ESRI), .vrt and GDAL's other rasters"
)

# The thin readers, by extension; every other file goes to GDAL (after a look at its first bytes).
_EXTENSIONS = {
    ".npy": "npy",
    ".npz": "npz",
    ".pgm": "pgm",
    ".png": "png",
}

# What GDAL files are called in messages, by extension.
_RASTER_KINDS = {
    ".tif": "TIFF",
    ".tiff": "TIFF",
    ".asc": "ESRI ASCII grid",
    ".hgt": "SRTM .hgt",
    ".img": "Erdas Imagine .img",
    ".bil": "ESRI .bil",
    ".flt": "ESRI .flt",
    ".vrt": "GDAL VRT",
}


def _read_errors() -> tuple[type[BaseException], ...]:
    """Exceptions the thin readers (numpy, zipfile, zlib, Pillow) and rasterio raise for unreadable,
    truncated or corrupt files.  Only caught around library calls; a function, so that reading an .npy
    does not import zipfile (an except clause evaluates it only when an exception comes)."""
    import tokenize  # start-up: only when an error comes (see above)
    import zipfile  # start-up: only when an error comes (zipfile: about 3 ms)
    import zlib  # start-up: only when an error comes (an extension module: about 0.3 ms)

    return (
        OSError,  # includes rasterio's RasterioIOError
        ValueError,
        TypeError,
        EOFError,
        KeyError,
        IndexError,
        SyntaxError,
        ArithmeticError,
        RuntimeError,  # includes NotImplementedError (unsupported zip features)
        MemoryError,  # a corrupt header claiming an enormous array
        struct.error,
        zlib.error,
        zipfile.BadZipFile,
        tokenize.TokenError,  # a corrupt .npy header
    )


def _sniff(head: bytes) -> str | None:
    """A thin reader's format from the first bytes of a file, or None (then GDAL tries)."""
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if head.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        return "npz"
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if re.match(rb"P[25]\s", head):
        return "pgm"
    return None


_NOT_REGULAR = {stat.S_IFIFO: "a FIFO (named pipe)", stat.S_IFCHR: "a character device",
                stat.S_IFBLK: "a block device", stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a directory"}


def regular_file(path: str, what: str = "") -> int:
    """The size of the regular file ``path`` (after its symbolic links); InputError for anything else:
    a FIFO would block the read until a writer came, a device (/dev/zero) never ends.  Opened without
    blocking, then its kind is looked at."""
    name = f"{what} {path}" if what else path
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise InputError(f"cannot read {name}: {e.strerror or _one_line(e)}") from None
    try:
        st = os.fstat(fd)
    finally:
        os.close(fd)
    if not stat.S_ISREG(st.st_mode):
        kind = _NOT_REGULAR.get(stat.S_IFMT(st.st_mode), "not a regular file")
        raise InputError(f"cannot read {name}: it is {kind}, not a regular file",
                         hint="give a file (copy the data into one first)")
    return st.st_size


def _read_head(path: str, n: int) -> bytes:
    """The first ``n`` bytes of a regular file (regular_file)."""
    regular_file(path)
    try:
        with open(path, "rb") as f:
            return f.read(n)
    except OSError as e:
        raise InputError(f"cannot read {path}: {e.strerror or _one_line(e)}") from None


def _read_bytes(path: str, limit: int | None = None, offset: int = 0) -> bytes:
    """A regular file's bytes (at most ``limit`` from ``offset``)."""
    regular_file(path)
    try:
        with open(path, "rb") as f:
            f.seek(offset)
            return f.read() if limit is None else f.read(limit)
    except OSError as e:
        raise InputError(f"cannot read {path}: {e.strerror or _one_line(e)}") from None


def npy_layout(path: str, f) -> tuple[tuple[int, ...], np.dtype, int] | None:
    """An .npy stream's (shape, dtype, data offset) from its header (numpy.lib.format), None when it
    is not one numpy reads that way (numpy's own reader then says what is wrong)."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(f)
        if version == (1, 0):
            shape, _, dtype = fmt.read_array_header_1_0(f)
        elif version in ((2, 0), (3, 0)):
            shape, _, dtype = fmt.read_array_header_2_0(f)
        else:
            return None
        return tuple(int(n) for n in shape), np.dtype(dtype), f.tell()
    except _read_errors():
        return None


def _check_npy_size(path: str, size_check) -> None:
    """An .npy file's header against the file: numpy's magic first (or a .npz archive's), the samples it
    claims must be in the file (numpy would set aside the claimed size first) and, to the caller, fit in
    memory (``size_check``)."""
    size = regular_file(path)
    try:
        with open(path, "rb") as f:
            magic = f.read(6)
            f.seek(0)
            layout = npy_layout(path, f)
    except OSError as e:
        raise InputError(f"cannot read {path}: {e.strerror or _one_line(e)}") from None
    if _sniff(magic) not in ("npy", "npz"):  # (a .npz archive: said below)
        # else numpy tries it as a pickle and says to allow pickles
        raise InputError(f"cannot read {path}: not a .npy file (it does not begin with numpy's \\x93NUMPY)")
    if layout is None or layout[1].hasobject:
        return
    shape, dtype, offset = layout
    need = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if size - offset < need:
        raise InputError(f"cannot read {path}: .npy data is truncated: the header says {dtype} samples of "
                         f"shape {shape}, {need} bytes, the file holds {max(0, size - offset)}")
    if len(shape) == 2:
        size_check(shape[1], shape[0], dtype.itemsize)


def _read_npy(path: str, size_check=lambda w, h, itemsize: None) -> np.ndarray:
    _check_npy_size(path, size_check)
    try:
        arr = np.load(path, allow_pickle=False)
    except _read_errors() as e:
        raise InputError(f"cannot read {path}: not a valid .npy file ({_one_line(e)})") from None
    if not isinstance(arr, np.ndarray):
        if hasattr(arr, "close"):
            arr.close()
        raise InputError(f"cannot read {path}: not a .npy file (it is a .npz archive); rename it to .npz")
    return arr


def _read_npz(path: str, key: str | None, size_check=lambda w, h, itemsize: None
              ) -> tuple[np.ndarray, tuple[float, ...] | None]:
    regular_file(path)
    try:
        npz = np.load(path, allow_pickle=False)
    except _read_errors() as e:
        raise InputError(f"cannot read {path}: not a valid .npz file ({_one_line(e)})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise InputError(f"cannot read {path}: not a .npz archive (it is a .npy file); rename it to .npy")
    with npz:
        names = list(npz.files)
        # a name from the file is shown as is only when printable (else as a short repr: one line)
        listed = ", ".join(n if n.isprintable() and len(n) <= 40 else _short(n) for n in names[:20])
        listed += f" and {len(names) - 20} more" if len(names) > 20 else ""
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
            _check_npz_member(path, npz, key, size_check)
            array = np.asarray(npz[key])
            return array, _npz_transform(path, npz, array.shape)
        except _read_errors() as e:
            raise InputError(f"cannot read {path}: array {key!r} is corrupt ({_one_line(e)})") from None


def _check_npz_member(path: str, npz, key: str, size_check) -> None:
    """An .npz member's header against the member's size in the archive (as _check_npy_size)."""
    try:
        info = npz.zip.getinfo(key if key in npz.zip.namelist() else key + ".npy")
        with npz.zip.open(info) as f:
            layout = npy_layout(path, f)
    except _read_errors():
        return
    if layout is None or layout[1].hasobject:
        return
    shape, dtype, offset = layout
    need = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if info.file_size - offset < need:
        raise InputError(f"cannot read {path}: array {key!r} is truncated: its header says {dtype} samples "
                         f"of shape {shape}, {need} bytes, the archive holds "
                         f"{max(0, info.file_size - offset)}")
    if len(shape) == 2:
        size_check(shape[1], shape[0], dtype.itemsize)


def _npz_transform(path: str, npz, shape: tuple[int, ...]) -> tuple[float, ...] | None:
    """The georeference of an .npz as matplotlib's sample DEMs give it: scalars dx, dy (the cell) and xmin,
    ymin, optionally xmax, ymax.  With xmax (ymax) the columns (rows) run from xmin to xmax (ymin to ymax),
    the extent being the cells' outer edges (|xmax - xmin| = W dx) or their centres ((W - 1) dx); without,
    xmin is the west edge and ymin the south edge of a grid whose row 0 is north.  None without dx, dy,
    xmin and ymin."""
    names = ("dx", "dy", "xmin", "ymin")
    if len(shape) != 2 or not all(n in npz.files for n in names):
        return None
    g = {}
    for n in (*names, "xmax", "ymax"):
        if n in npz.files:
            v = np.asarray(npz[n])
            if v.shape != () or v.dtype.kind not in "iuf" or not np.isfinite(v):
                raise InputError(f"{path}: the georeference {n!r} is not a finite number",
                                 hint="fix the archive, or give --spacing DX[,DY] and --origin X,Y")
            g[n] = float(v)
    if g["dx"] <= 0 or g["dy"] <= 0:
        raise InputError(f"{path}: the cell size dx {g['dx']:g}, dy {g['dy']:g} is not positive")
    h, w = shape

    def axis(lo: float, hi: float | None, cell: float, n: int, default_sign: int,
             name: str) -> tuple[float, float]:
        """(step, position of the outer edge of sample 0) along one axis."""
        if hi is None:
            return default_sign * cell, lo if default_sign > 0 else lo + n * cell
        span, sign = abs(hi - lo), (1.0 if hi >= lo else -1.0)
        for count, shift in ((n, 0.0), (n - 1, 0.5)):  # cell edges, or sample centres
            if abs(span - count * cell) <= 1e-6 * max(span, cell):
                return sign * cell, lo - sign * shift * cell
        raise InputError(f"{path}: {name}min .. {name}max spans {span:g}, which is neither {n} nor {n - 1} "
                         f"cells of d{name} {cell:g}", hint="fix the archive, or give --spacing and --origin")

    a, c = axis(g["xmin"], g.get("xmax"), g["dx"], w, 1, "x")
    e, f = axis(g["ymin"], g.get("ymax"), g["dy"], h, -1, "y")
    return (a, 0.0, c, 0.0, e, f)


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
    if max(width, height) > MAX_SIDE:  # the fuzzer's 0 x 10^123 header: numpy's ValueError on reshape
        raise InputError(
            f"cannot read {path}: the PGM header says {width} x {height} samples; wavemesh meshes at most "
            f"{MAX_SIDE} per side"
        )
    if pos < n and data[pos : pos + 1] in b" \t\r\n\v\f":
        pos += 1  # the single whitespace character ending the header
    elif magic == b"P5":
        raise InputError(f"cannot read {path}: PGM header is truncated or corrupt (no data after maxval)")
    return magic, width, height, maxval, pos


PGM_HEADER_MAX = 1 << 16  # bytes a PGM header (comments included) may take


def _read_pgm(path: str, size_check=lambda w, h, itemsize: None) -> np.ndarray:
    """A PGM's samples, reading no more of the file than its header's W x H samples take (P5; a longer
    file's rest is not read), or the regular file as it is (P2)."""
    size = regular_file(path)
    head = _read_bytes(path, PGM_HEADER_MAX)
    magic, width, height, maxval, pos = _pgm_header(head, path)
    if pos >= len(head) and size > len(head):
        raise InputError(f"cannot read {path}: PGM header is longer than {PGM_HEADER_MAX} bytes")
    count = width * height
    if magic == b"P5":
        dtype = np.dtype(np.uint8) if maxval <= 255 else np.dtype(">u2")
        need = count * dtype.itemsize
        found = max(0, min(size - pos, need)) // dtype.itemsize
        if found >= count:
            size_check(width, height, dtype.itemsize)
        raster = _read_bytes(path, need, pos) if found >= count else b""
        if found < count:
            raise InputError(
                f"cannot read {path}: PGM data is truncated: expected {width} x {height} = {count} samples, "
                f"found {found}"
            )
        arr = np.frombuffer(raster, dtype=dtype).astype(np.int64)
    else:
        if size - pos >= 2 * count - 1:  # else too short for the samples: said below
            size_check(width, height, 8)
        body = re.sub(rb"#[^\r\n]*", b" ", _read_bytes(path, None, pos))
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


def _read_png(path: str, size_check=lambda w, h, itemsize: None) -> np.ndarray:
    from PIL import Image  # imported here: only PNG needs Pillow

    regular_file(path)
    try:
        with Image.open(path, formats=["PNG"]) as img:
            size_check(*img.size, 4)
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
    except (*_read_errors(), Image.DecompressionBombError) as e:
        raise InputError(f"cannot read {path}: not a valid PNG file ({_one_line(e)})") from None
    if arr.dtype.byteorder == ">":
        arr = arr.astype(arr.dtype.newbyteorder("="))
    return arr


def _read_raster(path: str, ext: str, size_check=lambda w, h, itemsize: None
                 ) -> tuple[np.ma.MaskedArray, tuple[float, ...] | None, str | None]:
    """Read band 1 of a raster GDAL can open: ``(masked heights, transform, crs)``.

    The mask is GDAL's (no-data value, mask band); the band's scale and offset
    are applied.  ``transform`` is the affine ``(a, b, c, d, e, f)`` mapping a
    (column, row) position to ``x = a*col + b*row + c``, ``y = d*col + e*row + f``,
    with (0, 0) the outer corner of the first sample's cell, so sample (col, row)
    sits at (col + 0.5, row + 0.5); None when the file has no georeference, and
    ``crs`` then also None.
    """
    import rasterio  # imported here: only GDAL rasters need rasterio (and its start-up cost)
    from rasterio.errors import NotGeoreferencedWarning  # as rasterio's

    _quiet_rasterio_logs()
    regular_file(path)
    kind = _RASTER_KINDS.get(ext)
    errors = _raster_errors()
    try:
        # AAIGRID_DATATYPE: ESRI ASCII grids as float64, not float32 (their text holds any precision)
        env = rasterio.Env(AAIGRID_DATATYPE="Float64")
        with env, warnings.catch_warnings(), _undecodable_gdal_messages():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            try:
                ds = rasterio.open(path)
            except errors as e:
                if kind is None:
                    raise InputError(
                        f"cannot read {path}: unknown format (extension {ext or 'none'!r}, content not "
                        f"recognised); supported formats: {SUPPORTED_FORMATS}"
                    ) from None
                hint = " (an SRTM tile keeps its own name, e.g. N36W084.hgt)" if ext == ".hgt" else ""
                raise InputError(
                    f"cannot read {path}: not a valid {kind} file{hint} (GDAL: {_gdal_message(e, path)})"
                ) from None
            with ds:
                what = f"{path}: {ds.driver} raster"
                if len(ds.subdatasets) > 1 or (ds.count == 0 and ds.subdatasets):
                    raise InputError(
                        f"{what} holds {len(ds.subdatasets)} images; a height field needs one, "
                        f"extract it (e.g. gdal_translate {ds.subdatasets[0]} one.tif)"
                    )
                if ds.count != 1:
                    raise InputError(
                        f"{what} has {ds.count} bands ({ds.height} x {ds.width}); a height field needs "
                        f"a single band, extract one (e.g. gdal_translate -b 1)"
                    )
                if ds.driver == "AAIGrid":
                    _check_ascii_grid(path, ds.height, ds.width)
                if ds.driver in _RAW_DRIVERS:
                    _check_raw_size(path, ds)
                check_nodata(path, ds)
                # first: a grid `wavemesh mesh` tiles by default goes in tiles, whatever its width
                size_check(ds.width, ds.height, np.dtype(ds.dtypes[0]).itemsize)
                if max(ds.width, ds.height) > MAX_SIDE:
                    raise InputError(
                        f"{what} is {ds.width} x {ds.height} samples; wavemesh meshes at most {MAX_SIDE} per "
                        f"side (--crop and --decimate apply after reading)",
                        hint="cut a window or shrink it first (gdal_translate -srcwin or -outsize)",
                    )
                array = ds.read(1, masked=True)
                scale, offset = ds.scales[0], ds.offsets[0]
                georeferenced = ds.crs is not None or not ds.transform.is_identity
                transform = tuple(float(t) for t in ds.transform[:6]) if georeferenced else None
                crs = ds.crs.to_string() if ds.crs is not None else None
    except errors as e:
        raise _corrupt_raster(path, e) from None
    if (scale, offset) != (1.0, 0.0):
        array = array.astype(np.float64) * scale + offset
    return array, transform, crs


def _raster_errors() -> tuple[type[BaseException], ...]:
    """What rasterio and the thin readers raise for a raster they cannot read (_read_errors)."""
    from rasterio._err import CPLE_BaseError  # as rasterio's
    from rasterio.errors import RasterioError  # imported here: only GDAL rasters need rasterio

    return (RasterioError, CPLE_BaseError, *_read_errors())


def _corrupt_raster(path: str, e: BaseException) -> InputError:
    """The error of a raster whose samples cannot be read, whole (_read_raster) or by windows (a tiled
    run: read_raster_window): the same line."""
    kind = _RASTER_KINDS.get(os.path.splitext(path)[1].lower()) or "raster"
    return InputError(f"cannot read {path}: {kind} data is corrupt ({_gdal_message(e, path)})")


def _open_raster(path: str):
    """rasterio's dataset of a GDAL raster, quiet about a plain TIFF's missing georeference."""
    import rasterio  # imported here: only GDAL rasters need rasterio (and its start-up cost)
    from rasterio.errors import NotGeoreferencedWarning  # as rasterio's

    _quiet_rasterio_logs()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        return rasterio.open(path)


def raster_header(path: str) -> tuple[int, int, tuple[float, ...] | None, str | None]:
    """A GDAL raster's ``(width, height, transform, crs)`` without its samples, after _read_raster's
    checks of one band and its no-data value (wavemesh.tiles reads it window by window:
    read_raster_window)."""
    from rasterio.errors import RasterioError  # as rasterio's (_open_raster)

    try:
        with _open_raster(path) as ds:
            if ds.count != 1:
                raise InputError(f"{path} has {ds.count} bands; a height field needs one",
                                 hint="extract one (e.g. gdal_translate -b 1)")
            check_nodata(path, ds)
            georeferenced = ds.crs is not None or not ds.transform.is_identity
            return (ds.width, ds.height, tuple(float(t) for t in ds.transform[:6]) if georeferenced else None,
                    ds.crs.to_string() if ds.crs is not None else None)
    except RasterioError as e:
        raise InputError(f"cannot read {path}: {e}") from None


def read_raster_window(path: str, x: int, y: int, w: int, h: int) -> np.ndarray:
    """The w x h window at (x, y) of band 1 of a GDAL raster as float64: masked samples NaN, the band's
    scale and offset applied (as _read_raster reads the whole raster)."""
    from rasterio.windows import Window  # imported here: only GDAL rasters need rasterio (_open_raster)

    try:
        with _open_raster(path) as ds:
            a = ds.read(1, window=Window(x, y, w, h), masked=True)
            scale, offset = ds.scales[0], ds.offsets[0]
    except _raster_errors() as e:
        raise _corrupt_raster(path, e) from None
    v = np.ma.filled(a.astype(np.float64), np.nan)
    return v * scale + offset if (scale, offset) != (1.0, 0.0) else v


def _check_ascii_grid(path: str, nrows: int, ncols: int) -> None:
    """An ESRI ASCII grid's data: exactly nrows * ncols numbers after the header.

    GDAL's AAIGrid driver reads a short last row's missing samples and
    non-numeric text as 0 and ignores surplus values.
    """
    text = _read_bytes(path)
    header = _ASC_HEADER.match(text)
    data = text[header.end() if header else 0 :].split()
    where = f"cannot read {path}: ESRI ASCII grid"
    for line in text[: header.end() if header else 0].splitlines():
        words = line.split()
        if len(words) != 2:
            continue
        key, value = words[0].decode("latin-1"), words[1].decode("latin-1")
        kind = _ASC_KEYS.get(key.lower())
        try:
            number = int(value) if kind is int else float(value) if kind is float else None
        except ValueError:
            number = None
        if kind is not None and number is None:  # GDAL would read it as 0 (a no-data 0, a cell of 0)
            want = "an integer" if kind is int else "a number"
            raise InputError(f"{where}: header {key} {_short(value)} is not {want}",
                             hint=f"fix the header line '{key} ...'")
    count = nrows * ncols
    if len(data) != count:
        what = "truncated" if len(data) < count else "too long"
        raise InputError(
            f"{where}: data is {what}: expected {nrows} x {ncols} = {count} values, found {len(data)}"
        )
    try:
        np.array(data, dtype=np.float64)
    except ValueError:
        raise InputError(f"{where}: data holds a value that is not a number") from None


def check_nodata(path: str, ds) -> None:
    """A raster's no-data value, strictly: a GeoTIFF's GDAL_NODATA tag must be a number (GDAL reads
    "xyzzy" as 0, and would mask every 0), and the value must be one the band's samples can hold (NaN on
    int16, -9999 on uint16 or 1.5 on int16 mask nothing: the file means something it does not say)."""
    value = ds.nodata
    text = _tiff_nodata_text(path) if ds.driver == "GTiff" else None  # GDAL drops what it cannot use
    if text is not None:
        try:
            value = float(text)
        except ValueError:
            raise InputError(f"cannot read {path}: its no-data value {_short(text)} (the GDAL_NODATA tag) is "
                             "not a number",
                             hint="set it right (gdal_edit.py -a_nodata VALUE, or -unsetnodata)") from None
    if value is None:
        return
    dtype = np.dtype(ds.dtypes[0])
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        if not (np.isfinite(value) and value == np.floor(value) and info.min <= value <= info.max):
            raise InputError(f"cannot read {path}: its no-data value {value:g} cannot occur in {dtype} "
                             f"samples ({info.min}..{info.max}), so it would mark none",
                             hint="set the value the file uses for missing samples "
                                  "(gdal_edit.py -a_nodata VALUE, or -unsetnodata)")


def _tiff_nodata_text(path: str) -> str | None:
    """The GDAL_NODATA tag (42113, ASCII) of a TIFF's first image as written, or None (no tag, not a
    TIFF that can be read here: GDAL's value then stands)."""
    try:
        with open(path, "rb") as f:
            head = f.read(16)
            order = {b"II": "<", b"MM": ">"}.get(head[:2])
            if order is None:
                return None
            magic = struct.unpack(order + "H", head[2:4])[0]
            if magic == 42:
                ifd, count_f, entry_f, small = struct.unpack(order + "I", head[4:8])[0], "H", "HHII", 4
            elif magic == 43:
                ifd, count_f, entry_f, small = struct.unpack(order + "Q", head[8:16])[0], "Q", "HHQQ", 8
            else:
                return None
            f.seek(ifd)
            raw = f.read(struct.calcsize(order + count_f))
            (n,) = struct.unpack(order + count_f, raw)
            size = struct.calcsize(order + entry_f)
            entries = f.read(min(n, 4096) * size)
            for i in range(len(entries) // size):
                tag, typ, count, value = struct.unpack(order + entry_f, entries[i * size:(i + 1) * size])
                if tag != 42113 or typ != 2:
                    continue
                if count <= small:
                    data = entries[i * size + size - small:i * size + size][:count]
                else:
                    f.seek(value)
                    data = f.read(min(count, 1024))
                return data.split(b"\0")[0].decode("latin-1").strip()
    except (OSError, struct.error, OverflowError, ValueError):
        return None
    return None


# GDAL's drivers of raw sample files, which read the missing end of a short file as 0 without a word.
_RAW_DRIVERS = frozenset({"EHdr", "ENVI", "BT"})


def _check_raw_size(path: str, ds) -> None:
    """A raw file holding one band of H x W samples: at least H*W samples' bytes, whatever the layout
    (header, row padding) its header describes."""
    bits = ds.tags(1, ns="IMAGE_STRUCTURE").get("NBITS")
    if bits is not None and bits.isdigit() and int(bits) < 8:
        return  # packed samples: the bound does not apply
    need = ds.height * ds.width * np.dtype(ds.dtypes[0]).itemsize
    size = os.path.getsize(path)
    if size < need:
        raise InputError(
            f"cannot read {path}: {ds.driver} data is truncated: {ds.height} x {ds.width} {ds.dtypes[0]} "
            f"samples need at least {need} bytes, the file has {size}"
        )


# The header keys of an ESRI ASCII grid whose values must be numbers (GDAL reads any text there as 0).
_ASC_KEYS = {"ncols": int, "nrows": int, "xllcorner": float, "yllcorner": float, "xllcenter": float,
             "yllcenter": float, "cellsize": float, "dx": float, "dy": float, "nodata_value": float}


# The header of an ESRI ASCII grid: lines ``key value`` whose key starts with a letter.
_ASC_HEADER = re.compile(rb"(?:\s*[A-Za-z_]\w*[ \t]+\S+)*")


def _gdal_message(e: BaseException, path: str) -> str:
    """The one line that says what GDAL found wrong (rasterio chains it as the cause)."""
    cause = e.__cause__ if e.__cause__ is not None and "previous exception" in str(e) else e
    text = _one_line(cause).rstrip(".")
    for name in (f"'{path}' ", f"{path}: ", f"{path}, "):
        text = text.replace(name, "")
    return text


@contextlib.contextmanager
def _library_warnings_quiet():
    """numpy and Pillow warn on stderr about files they still read (a .npy header written by Python 2, a
    large PNG): a stray line before wavemesh's own output.  A file is read, or refused with one error."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


@contextlib.contextmanager
def _undecodable_gdal_messages():
    """rasterio hands GDAL's messages to logging as UTF-8; a damaged file can put other bytes in them,
    and the UnicodeDecodeError would end as a traceback on stderr ("Exception ignored in
    rasterio._env.log_error").  The message is lost either way; the error it reports is raised."""
    previous = sys.unraisablehook

    def hook(unraisable):
        undecodable = isinstance(unraisable.exc_value, UnicodeDecodeError)
        if not (undecodable and "rasterio" in repr(unraisable.object)):
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous


def _quiet_rasterio_logs() -> None:
    """GDAL's warnings reach Python's logging through rasterio; without a handler of the
    application's, they would be printed on stderr by logging's last resort."""
    import logging  # imported here: rasterio imports it anyway, the rest of wavemesh does not

    logger = logging.getLogger("rasterio")
    if not any(isinstance(h, logging.NullHandler) for h in logger.handlers):
        logger.addHandler(logging.NullHandler())


def _one_line(e: BaseException | str) -> str:
    text = " ".join(str(e).split())
    return text or type(e).__name__


def _short(text: str, limit: int = 40) -> str:
    text = _one_line(text)
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return repr(text)
