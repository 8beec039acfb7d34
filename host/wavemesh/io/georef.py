"""Where the samples lie on the ground: the georeference of a height field, its cell size in ground
units, and the coordinates the outputs are written in.

A height field's georeference is the affine ``transform`` (a, b, c, d, e, f) of GDAL: the map position
of grid position (col, row) is ``x = a col + b row + c``, ``y = d col + e row + f``, (0, 0) the outer
corner of sample (0, 0)'s cell, so sample (col, row) sits at (col + 0.5, row + 0.5); and the CRS
(``HeightField.transform``, ``HeightField.crs``; :mod:`wavemesh.io.heightfield` reads them).  Without a
georeference the map is the grid itself: sample (col, row) at x = col, y = row (:data:`GRID`).

The cell size (:attr:`Ground.spacing`, dx along a row, dy along a column) is the ground distance
between neighbouring samples, in the unit the heights are taken to be in: the normal metric measures
slopes with it (docs/refiner.md, "Ground units").  It is

- the lengths of the transform's column and row vectors (map units: the CRS's linear unit, or the
  file's own unit when it names no CRS), for a projected grid;
- for a geographic grid (a geographic CRS, or no CRS and a transform whose whole extent fits
  longitude -180..180 and latitude -90..90 with cells of at most 0.1: taken as degrees, and said so),
  the degrees converted to metres at the latitude of the grid's centre on the WGS 84 ellipsoid:
  ``pi / 180 * N cos(lat)`` metres per degree of longitude and ``pi / 180 * M`` per degree of
  latitude, with N = a / sqrt(1 - e^2 sin^2 lat) and M = a (1 - e^2) / (1 - e^2 sin^2 lat)^1.5
  (other ellipsoids differ by less than 1e-4); the scale of a degree of longitude changes with
  the latitude, so a grid taller than a few degrees is reported as distorted;
- ``--spacing DX[,DY]`` when given; else 1 (a grid step) without a georeference, as before.

The map units (or metres) are taken to be the heights' unit: a DEM in feet on a metre grid needs
``--spacing`` in feet.  A sheared transform (column and row vectors not perpendicular) and a rotated
geographic one are refused: reproject them first (gdalwarp).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from wavemesh.errors import InputError
from wavemesh.io.readers import regular_file
from wavemesh.record import record

GRID = (1.0, 0.0, -0.5, 0.0, 1.0, -0.5)  # no georeference: sample (col, row) at (col, row)
WGS84_A = 6378137.0  # semi-major axis, metres
WGS84_E2 = 0.00669437999014  # first eccentricity squared (1 / f = 298.257223563)
DEGREE_CELL_MAX = 0.1  # a grid without a CRS is taken as degrees only with cells at most this large
DISTORTION_NOTE = 0.01  # a degree of longitude changing by more than this fraction over the grid is noted
SIDECAR_SUFFIX = ".georef.json"  # mesh.obj -> mesh.obj.georef.json
# The frames of a georeferenced mesh file's x and y (--units): "metres", east and north in ground units
# from sample (0, 0) (metres for a geographic or metric CRS), as the .glb; "crs", the CRS's own map
# coordinates (less sample (0, 0)'s with --local).  Heights are z in both.
UNITS = ("metres", "crs")


def metres_per_degree(lat: float) -> tuple[float, float]:
    """(longitude, latitude): metres per degree at latitude ``lat`` on the WGS 84 ellipsoid."""
    phi = math.radians(lat)
    w = 1.0 - WGS84_E2 * math.sin(phi) ** 2
    n = WGS84_A / math.sqrt(w)
    m = WGS84_A * (1.0 - WGS84_E2) / w**1.5
    return math.pi / 180.0 * n * math.cos(phi), math.pi / 180.0 * m


@record(frozen=True)
class Ground:
    """A grid's place on the ground: its map coordinates and its cell size in ground units."""

    width: int
    height: int
    transform: tuple[float, ...]  # GDAL's affine (above); GRID without a georeference
    crs: str | None  # "EPSG:4326", WKT, or None
    map_unit: str  # the unit of x and y: "grid step", "degree", the CRS's ("metre"), "map unit"
    spacing: tuple[float, float]  # (dx, dy): ground distance between neighbouring samples
    ground_unit: str  # the unit of spacing (and, by assumption, of the heights)
    how: str  # where the spacing comes from, one sentence
    geographic: bool = False
    metres_per_unit: tuple[float, float] = (1.0, 1.0)  # ground units per map unit in x and y

    @property
    def georeferenced(self) -> bool:
        return self.transform != GRID or self.map_unit != "grid step"

    def map_xy(self, cols, rows) -> tuple[np.ndarray, np.ndarray]:
        """Map coordinates of samples (col, row) (cell centres)."""
        a, b, c, d, e, f = self.transform
        u = np.asarray(cols, dtype=np.float64) + 0.5
        v = np.asarray(rows, dtype=np.float64) + 0.5
        return a * u + b * v + c, d * u + e * v + f

    @property
    def origin(self) -> tuple[float, float]:
        """The map position of sample (0, 0), what ``--local`` subtracts."""
        x, y = self.map_xy(0, 0)
        return float(x), float(y)

    def grid_xy(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Grid positions (col, row) of map positions: the inverse of map_xy."""
        a, b, c, d, e, f = self.transform
        det = a * e - b * d
        dx = np.asarray(x, dtype=np.float64) - c
        dy = np.asarray(y, dtype=np.float64) - f
        return (e * dx - b * dy) / det - 0.5, (a * dy - d * dx) / det - 0.5

    def ground_xy(self, cols, rows) -> tuple[np.ndarray, np.ndarray]:
        """(east, north) in ground units from sample (0, 0): the frame of the pictures and the .glb.
        A transform whose y grows down the rows (a * e - b * d > 0, as the grid itself without a
        georeference) is an image: row 0 is its north edge."""
        a, b, _, d, e, _ = self.transform
        x, y = self.map_xy(cols, rows)
        x0, y0 = self.origin
        kx, ky = self.metres_per_unit
        if a * e - b * d > 0:
            ky = -ky
        return (x - x0) * kx, (y - y0) * ky

    def from_ground(self, east, north) -> tuple[np.ndarray, np.ndarray]:
        """Grid positions (col, row) of (east, north) from sample (0, 0): the inverse of ground_xy."""
        a, b, _, d, e, _ = self.transform
        x0, y0 = self.origin
        kx, ky = self.metres_per_unit
        if a * e - b * d > 0:
            ky = -ky
        return self.grid_xy(x0 + np.asarray(east, dtype=np.float64) / kx,
                            y0 + np.asarray(north, dtype=np.float64) / ky)

    def mirrors(self, units: str) -> bool:
        """Whether (col, row) -> the output frame's (x, y) reverses orientation (``units`` "metres": east,
        north; "crs": map x, y): a counter-clockwise grid triangle is then clockwise seen from above."""
        f = self.ground_xy if units == UNITS[0] else self.map_xy
        (x0, y0), (x1, y1), (x2, y2) = (f(c, r) for c, r in ((0, 0), (1, 0), (0, 1)))
        return float((x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)) < 0

    def to_report(self) -> dict:
        return {"crs": self.crs, "transform": list(self.transform), "map_unit": self.map_unit,
                "spacing": list(self.spacing), "ground_unit": self.ground_unit, "spacing_from": self.how}

    def summary(self) -> str:
        dx, dy = self.spacing
        return f"cell {dx:.6g} x {dy:.6g} {self.ground_unit}: {self.how}"


_GRID_GROUNDS: dict = {}  # grid_ground's answers by size: a Ground is frozen (one made: 2 us a refine call)


def grid_ground(width: int, height: int) -> Ground:
    """The Ground of a grid without a georeference: grid steps."""
    g = _GRID_GROUNDS.get((width, height))
    if g is None:
        if len(_GRID_GROUNDS) >= 64:
            _GRID_GROUNDS.clear()
        g = _GRID_GROUNDS[(width, height)] = Ground(width, height, GRID, None, "grid step", (1.0, 1.0),
                                                    "grid step", "no georeference: 1 grid step")
    return g


def parse_pair(text: str, what: str, *, positive: bool, one_ok: bool) -> tuple[float, float]:
    """``A,B`` (or ``A`` for both when one_ok) as two finite floats."""
    parts = str(text).replace(" ", "").split(",")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) == 1 and one_ok:
        vals = vals * 2
    ok = len(vals) == 2 and all(math.isfinite(v) and (v > 0 or not positive) for v in vals)
    if not ok:
        form = f"{what} DX[,DY] with DX, DY > 0" if positive else f"{what} X,Y"
        raise InputError(f"bad {what} {text}: expected {'positive numbers' if positive else 'two numbers'}",
                         hint=f"give {form}")
    return vals[0], vals[1]


def _crs_info(crs: str | None):
    """(geographic, unit name) of a CRS string; (None, None) without one."""
    if crs is None:
        return None, None
    from rasterio.crs import CRS  # only georeferenced rasters carry a CRS, and they came through rasterio

    try:
        c = CRS.from_user_input(crs)
    except Exception as e:  # noqa: BLE001 - rasterio raises CRSError and others for a CRS it cannot parse
        raise InputError(f"cannot interpret the CRS {crs[:60]!r}: {e}",
                         hint="give the cell size with --spacing DX[,DY]") from None
    if c.is_geographic:
        return True, "degree"
    unit = c.linear_units or "map unit"
    return False, "map unit" if unit in ("unknown", "") else unit


def _looks_geographic(t: tuple[float, ...], width: int, height: int) -> bool:
    """No CRS: a transform whose whole extent fits longitude/latitude, with cells of at most 0.1."""
    a, b, c, d, e, f = t
    xs = [a * u + b * v + c for u in (0, width) for v in (0, height)]
    ys = [d * u + e * v + f for u in (0, width) for v in (0, height)]
    cell = max(math.hypot(a, d), math.hypot(b, e))
    return (b == 0 and d == 0 and cell <= DEGREE_CELL_MAX and all(-180 <= x <= 180 for x in xs)
            and all(-90 <= y <= 90 for y in ys))


def ground(hf) -> Ground:
    """The Ground of a HeightField: its transform, CRS and ``spacing`` override (module docstring)."""
    w, h = hf.width, hf.height
    t = tuple(float(v) for v in hf.transform) if hf.transform is not None else None
    override = getattr(hf, "spacing", None)
    if t is None:
        if override is None:
            return grid_ground(w, h)
        dx, dy = float(override[0]), float(override[1])
        return Ground(w, h, (dx, 0.0, -dx / 2, 0.0, dy, -dy / 2), None, "map unit", (dx, dy), "map unit",
                      "--spacing", False)
    a, b, c, d, e, f = t
    col, row = math.hypot(a, d), math.hypot(b, e)
    if not (all(math.isfinite(v) for v in t) and col > 0 and row > 0 and a * e - b * d != 0):
        raise InputError(f"{hf.source}: the georeference {t} is degenerate",
                         hint="fix the file's geotransform, or give --spacing DX[,DY]")
    if abs(a * b + d * e) > 1e-9 * col * row:
        raise InputError(f"{hf.source}: the grid is sheared (its columns and rows are not perpendicular)",
                         hint="reproject it (e.g. gdalwarp -t_srs ...), or give --spacing DX[,DY]")
    geographic, unit = _crs_info(hf.crs)
    guessed = False
    if geographic is None:  # no CRS: guessed from the extent, unless the user gave the cell size
        geographic = override is None and _looks_geographic(t, w, h)
        unit, guessed = ("degree", True) if geographic else ("map unit", False)
    if not geographic:
        sp = override or (col, row)
        how = "--spacing" if override else f"the georeference ({unit}s; the heights taken in {unit}s too)"
        return Ground(w, h, t, hf.crs, unit, (float(sp[0]), float(sp[1])), unit, how, False)
    if b != 0 or d != 0:
        raise InputError(f"{hf.source}: a rotated geographic grid is not supported",
                         hint="reproject it to a projected CRS (gdalwarp -t_srs EPSG:...), or give --spacing")
    lats = [f, f + e * h]
    if not all(-90 <= v <= 90 for v in lats) or not all(-360 <= v <= 360 for v in (c, c + a * w)):
        raise InputError(f"{hf.source}: the geographic grid reaches latitude {max(lats, key=abs):g}, "
                         f"outside -90..90", hint="fix the file's georeference, or give --spacing DX[,DY]")
    lat_c = f + e * h / 2
    kx, ky = metres_per_degree(lat_c)
    near_pole = max(abs(v) for v in lats)
    k_edge = metres_per_degree(min(near_pole, 89.999))[0]
    how = (f"degrees at latitude {lat_c:.4f} (WGS 84: 1 degree = {kx:.1f} m east, {ky:.1f} m north)"
           + ("; no CRS, taken as longitude/latitude from its extent" if guessed else ""))
    if 1 - k_edge / kx > DISTORTION_NOTE:
        how += (f"; a degree of longitude shrinks by {100 * (1 - k_edge / kx):.1f}% towards the grid's "
                f"edge: reproject for a uniform cell")
    sp = override or (abs(a) * kx, abs(e) * ky)
    if override:
        how = "--spacing (the grid's coordinates stay degrees)"
    crs = hf.crs or ("EPSG:4326" if guessed else None)
    return Ground(w, h, t, crs, "degree", (float(sp[0]), float(sp[1])), "metre", how, True,
                  (sp[0] / abs(a), sp[1] / abs(e)))


def apply_overrides(hf, spacing: str | None = None, origin: str | None = None):
    """The HeightField with ``--spacing DX[,DY]`` and ``--origin X,Y`` (the map position of sample
    (0, 0)) applied.  On a grid in map units --spacing sets the transform's cell (its directions kept);
    on a geographic grid it sets only the cell size the metric uses, the coordinates stay degrees."""
    if spacing is None and origin is None:
        return hf
    t = tuple(hf.transform) if hf.transform is not None else None
    if spacing is not None:
        dx, dy = parse_pair(spacing, "--spacing", positive=True, one_ok=True)
        geographic = t is not None and ground(hf).geographic
        hf = replace(hf, spacing=(dx, dy), crs=hf.crs or ("EPSG:4326" if geographic else None))
        if t is None:
            t = (dx, 0.0, -dx / 2, 0.0, dy, -dy / 2)
        elif not geographic:
            a, b, c, d, e, f = t
            x0, y0 = ground(hf).origin
            ka, kb = dx / math.hypot(a, d), dy / math.hypot(b, e)
            a, d, b, e = a * ka, d * ka, b * kb, e * kb
            t = (a, b, x0 - 0.5 * a - 0.5 * b, d, e, y0 - 0.5 * d - 0.5 * e)
    if origin is not None:
        x, y = parse_pair(origin, "--origin", positive=False, one_ok=False)
        a, b, c, d, e, f = t if t is not None else GRID
        t = (a, b, x - 0.5 * a - 0.5 * b, d, e, y - 0.5 * d - 0.5 * e)
    hf = replace(hf, transform=t)
    ground(hf)  # the errors of a bad georeference now, not at the first use
    return hf


def cropped(transform: tuple[float, ...] | None, x: int, y: int, step: int) -> tuple[float, ...] | None:
    """The transform of the grid whose sample (i, j) is sample (x + step i, y + step j) of the old one."""
    if transform is None:
        return None
    a, b, c, d, e, f = transform
    cx = a * (x + 0.5) + b * (y + 0.5) + c  # the old map position of the new sample (0, 0)
    cy = d * (x + 0.5) + e * (y + 0.5) + f
    a, b, d, e = a * step, b * step, d * step, e * step
    return (a, b, cx - 0.5 * a - 0.5 * b, d, e, cy - 0.5 * d - 0.5 * e)


# ---------------------------------------------------------------------------------------------------
# The sidecar of a mesh in map units


def sidecar_path(mesh_path) -> Path:
    p = Path(mesh_path)
    return p.with_name(p.name + SIDECAR_SUFFIX)


def sidecar(g: Ground, mesh_path, local: bool, units: str = "crs") -> dict:
    """The sidecar's content: ``units`` (UNITS) and ``local`` name the frame of the mesh's x and y."""
    metres = units == UNITS[0]
    x0, y0 = g.origin if local or metres else (0.0, 0.0)
    vertices = "ground" if metres else "local" if local else "map"
    return {
        "wavemesh_georef": 1,
        "mesh": Path(mesh_path).name,
        "crs": g.crs,
        "map_unit": g.map_unit,
        "grid": {"width": g.width, "height": g.height},
        "transform": list(g.transform),
        "transform_doc": "GDAL geotransform as (a, b, c, d, e, f): x = a col + b row + c, "
                         "y = d col + e row + f; sample (col, row) at (col + 0.5, row + 0.5)",
        "units": units,
        "vertices": vertices,
        "vertices_doc": {"ground": f"x east, y north, z up in {g.ground_unit}s from sample (0, 0) "
                                   "(at the map position origin)",
                         "map": "x, y the map coordinates of the CRS, z the height",
                         "local": "x, y the map coordinates less origin, z the height"}[vertices],
        "faces": "counter-clockwise seen from above (+z)",
        "origin": [x0, y0],
        "origin_doc": "the map position of sample (0, 0)" if metres else
                      "subtracted from every vertex's x and y (--local: the map position of sample (0, 0))",
        "spacing": list(g.spacing),
        "ground_unit": g.ground_unit,
        "spacing_from": g.how,
        "geographic": g.geographic,
        "metres_per_unit": list(g.metres_per_unit),
    }


def write_sidecar(g: Ground, mesh_path, local: bool, units: str = "crs") -> Path:
    import json  # start-up: json (5M instructions) only where a report or a sidecar is written or read

    p = sidecar_path(mesh_path)
    try:
        p.write_text(json.dumps(sidecar(g, mesh_path, local, units), indent=2) + "\n")
    except OSError as e:
        raise InputError(f"cannot write {p}: {e.strerror or e}") from None
    return p


def read_sidecar(mesh_path) -> tuple[Ground, tuple[float, float], str, bool] | None:
    """(the Ground, the origin subtracted from the vertices, the units (UNITS), whether the faces were
    written counter-clockwise seen from above) from the sidecar beside a mesh; None when there is none
    (:func:`to_grid` takes the rest of the tuple)."""
    p = sidecar_path(mesh_path)
    if not p.exists():
        return None

    import json  # start-up: json (5M instructions) only where a report or a sidecar is written or read

    regular_file(str(p), "sidecar")
    try:
        s = json.loads(p.read_text())
        t = tuple(float(v) for v in s["transform"])
        g = Ground(int(s["grid"]["width"]), int(s["grid"]["height"]), t, s.get("crs"), str(s["map_unit"]),
                   (float(s["spacing"][0]), float(s["spacing"][1])), str(s["ground_unit"]),
                   str(s.get("spacing_from", p.name)), bool(s.get("geographic", False)),
                   tuple(float(v) for v in s.get("metres_per_unit", (1.0, 1.0))))
        origin = (float(s["origin"][0]), float(s["origin"][1]))
        units = str(s.get("units", "crs"))
        up = "faces" in s  # files before --units kept the grid's winding
        if units not in UNITS:
            raise ValueError(f"unknown units {units!r}")
    except (OSError, ValueError, KeyError, TypeError, IndexError) as e:
        raise InputError(f"cannot read the mesh's sidecar {p}: {e}",
                         hint=f"delete it if {Path(mesh_path).name} is in grid coordinates") from None
    if len(t) != 6 or len(g.transform) != 6 or t[0] * t[4] - t[1] * t[3] == 0:
        raise InputError(f"{p}: the transform is not an invertible affine")
    return g, (0.0, 0.0) if units == UNITS[0] else origin, units, up


def to_grid(g: Ground, origin: tuple[float, float], units: str = "crs", up: bool = False):
    """A function mapping vertex coordinates in a sidecar's frame to grid positions (col, row), the
    near-integral ones snapped (map coordinates carry a rounding error of a few ulps).  Its attribute
    ``mirror`` says whether the file's triangles must be reversed to be counter-clockwise on the grid
    (``up``: they were written counter-clockwise seen from above, in a frame that mirrors the grid)."""

    def conv(x, y):
        if units == UNITS[0]:
            col, row = g.from_ground(x, y)
        else:
            col, row = g.grid_xy(np.asarray(x, dtype=np.float64) + origin[0],
                                 np.asarray(y, dtype=np.float64) + origin[1])
        for v in (col, row):
            r = np.round(v)
            near = np.abs(v - r) < 1e-6
            v[near] = r[near]
        return col, row

    conv.mirror = up and g.mirrors(units)
    return conv
