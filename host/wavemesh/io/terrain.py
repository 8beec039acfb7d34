"""Web terrain tiles: a quantized-mesh-1.0 tile pyramid with ``layer.json``, as CesiumJS reads it.

    wavemesh tiles dem.tif -o terrain/ [--max-zoom N] [--zeta Z]

The tiling is CesiumJS's geographic scheme (``GeographicTilingScheme``, EPSG:4326): level 0 is two tiles,
the western and the eastern hemisphere, each level halves the tiles' sides, tile (x, y) of level L spans
longitude -180 + x d .. -180 + (x + 1) d and latitude -90 + y d .. -90 + (y + 1) d with d = 180 / 2^L
(TMS: y counts from the south).  Files ``DIR/L/x/y.terrain`` (uncompressed: a static server may gzip
them) and ``DIR/layer.json``, whose ``available`` lists, per level, the rectangles of tiles written.

Each tile is a mesh of the existing pipeline (``wavemesh mesh``'s filter bank, templates and refiner,
:func:`wavemesh.api.mesh`) on the DEM resampled to the tile: a 65 x 65 grid (the sample count of
Cesium's own height-map tiles) of longitude/latitude points from the tile's west to east edge and
north to south, each the bilinear interpolation of the DEM's four nearest samples (its CRS reprojected
by rasterio when it is not geographic); points outside the DEM get height 0 (the ellipsoid, as
cesium-terrain-builder's no-data).  The refiner bounds every triangle's vertical error by the level's
tolerance, ``min(E0 / 2^L, zeta 2^(Lmax - L))``: E0 = 77067 m is the geometric error Cesium assumes for
a level-0 height-map tile of 65 samples (a 2 pi / 4 / (65 2)), so no tile is coarser than Cesium's own
would be, and the finest level is within ``--zeta`` of the resampled DEM.

Encoding: quantized-mesh-encoder's (PyPI) header, vertex, index and edge writers, fed u, v and h
rounded here (the grid positions scaled to 0..32767, the heights from the tile's minimum to maximum in
32767 steps: half a unit of error); its one-call ``encode()`` truncates them (up to a whole unit of u
and a whole step of h on Jacksboro's pyramid) and its ``oct_encode`` wraps a normal's component of 1 to
-1 (an east-pointing normal decodes as west: 179.8 degrees off, where CesiumJS's own encoding,
:func:`oct_encode`, is at most 0.94 off); both measured by ``tools/terrain_encoder.py``.  Triangles
are counter-clockwise seen from above, indices in first-use order (the high-water-mark coding needs it).
Skirts: CesiumJS builds them from the edge lists (west, south, east, north); they hide the cracks
between tiles of different levels.  Extension: octvertexnormals, the area-weighted vertex normals of the
mesh (:func:`normals_ecef`).
"""

from __future__ import annotations

import io
import json
import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wavemesh import api
from wavemesh.errors import InputError
from wavemesh.io.georef import ground, metres_per_degree
from wavemesh.io.heightfield import from_array
from wavemesh.io.meshio import vertex_normals
from wavemesh.io.outputs import Outputs, check_path
from wavemesh.refine.native import RefineParams

SAMPLES = 65  # a tile's grid: 65 x 65, as Cesium's height-map tiles
QMAX = 32767  # quantized-mesh's u, v, h range
WGS84_A = 6378137.0
E0 = WGS84_A * 2 * math.pi * 0.25 / (SAMPLES * 2)  # Cesium's level-0 geometric error for such tiles, m
MAX_ZOOM = 18


def tile_bounds(level: int, x: int, y: int) -> tuple[float, float, float, float]:
    """(west, south, east, north) in degrees of tile (x, y) of ``level`` (TMS y, from the south)."""
    d = 180.0 / (1 << level)
    return -180.0 + x * d, -90.0 + y * d, -180.0 + (x + 1) * d, -90.0 + (y + 1) * d


def tolerance(level: int, max_zoom: int, zeta: float) -> float:
    """The vertical error bound of a level's tiles (module docstring)."""
    return min(E0 / (1 << level), zeta * 2.0 ** (max_zoom - level))


@dataclass(frozen=True)
class Sampler:
    """The DEM as a function of longitude and latitude (bilinear; 0 outside), and its extent."""

    hf: object  # the HeightField
    bounds: tuple[float, float, float, float]  # west, south, east, north (degrees)
    cell_degrees: float  # the DEM's cell, in degrees of latitude
    crs: str | None  # the DEM's CRS when it must be reprojected to, None when geographic

    def __call__(self, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        lon, lat = np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)
        if self.crs is not None:
            from rasterio.warp import transform  # start-up: rasterio only for georeferenced DEMs

            xs, ys = transform("EPSG:4326", self.crs, lon.ravel(), lat.ravel())
            x, y = np.reshape(xs, lon.shape), np.reshape(ys, lat.shape)
        else:
            x, y = lon, lat
        g = ground(self.hf)
        col, row = g.grid_xy(x, y)
        z = self.hf.values
        h, w = z.shape
        inside = (col >= -0.5) & (col <= w - 0.5) & (row >= -0.5) & (row <= h - 0.5)
        c = np.clip(col, 0, w - 1)
        r = np.clip(row, 0, h - 1)
        c0 = np.minimum(np.floor(c).astype(np.int64), w - 2)
        r0 = np.minimum(np.floor(r).astype(np.int64), h - 2)
        fc, fr = c - c0, r - r0
        v = ((1 - fr) * ((1 - fc) * z[r0, c0] + fc * z[r0, c0 + 1])
             + fr * ((1 - fc) * z[r0 + 1, c0] + fc * z[r0 + 1, c0 + 1]))
        return np.where(inside, v, 0.0)


def sampler(hf) -> Sampler:
    """The DEM placed on the globe by its georeference; InputError without one."""
    g = ground(hf)
    if hf.transform is None or not g.georeferenced:
        raise InputError(f"{hf.source}: terrain tiles need a georeference (where on the Earth the grid "
                         "lies), and this input has none",
                         hint="use a georeferenced raster (GeoTIFF, .asc, .hgt; an .npz as matplotlib's)")
    w, h = hf.width, hf.height
    a, b, c, d, e, f = g.transform
    corners_x = [c + a * u + b * v for u in (0, w) for v in (0, h)]
    corners_y = [f + d * u + e * v for u in (0, w) for v in (0, h)]
    if g.geographic:
        bounds = (min(corners_x), min(corners_y), max(corners_x), max(corners_y))
        return Sampler(hf, bounds, abs(e), None)
    if not g.crs:
        raise InputError(f"{hf.source}: the grid's map coordinates name no CRS, so its place on the Earth "
                         "is unknown", hint="use a raster whose georeference names its CRS (a GeoTIFF)")
    from rasterio.warp import transform_bounds  # start-up: rasterio only for georeferenced DEMs

    west, south, east, north = transform_bounds(g.crs, "EPSG:4326", min(corners_x), min(corners_y),
                                                max(corners_x), max(corners_y), densify_pts=21)
    metres = min(g.spacing)
    return Sampler(hf, (west, south, east, north), metres / 111320.0, g.crs)


def default_max_zoom(s: Sampler) -> int:
    """The first level whose tiles' samples are as close as the DEM's (no finer: that would only
    interpolate)."""
    level = math.ceil(math.log2(180.0 / ((SAMPLES - 1) * s.cell_degrees)))
    return max(0, min(MAX_ZOOM, level))


def tiles_at(level: int, bounds: tuple[float, float, float, float]) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1), inclusive: the tiles of ``level`` the extent touches (level 0: both)."""
    if level == 0:
        return 0, 0, 1, 0
    d = 180.0 / (1 << level)
    west, south, east, north = bounds
    nx, ny = 2 << level, 1 << level
    x0 = min(nx - 1, max(0, int(math.floor((west + 180.0) / d))))
    x1 = min(nx - 1, max(0, int(math.ceil((east + 180.0) / d)) - 1))
    y0 = min(ny - 1, max(0, int(math.floor((south + 90.0) / d))))
    y1 = min(ny - 1, max(0, int(math.ceil((north + 90.0) / d)) - 1))
    return x0, y0, max(x0, x1), max(y0, y1)


def tile_grid(s: Sampler, level: int, x: int, y: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tile's resampled grid: (heights (65, 65), lon (65,), lat (65,)); row 0 the north edge."""
    west, south, east, north = tile_bounds(level, x, y)
    t = np.arange(SAMPLES) / (SAMPLES - 1)
    lon = west + t * (east - west)
    lat = north - t * (north - south)
    lon[-1], lat[-1] = east, south
    return s(lon[None, :] + 0 * lat[:, None], lat[:, None] + 0 * lon[None, :]), lon, lat


def normals_ecef(lon, lat, z, tris) -> np.ndarray:
    """Unit vertex normals in Earth-centred coordinates: the mesh's area-weighted normals in a local
    (east, north, up) frame in metres (degrees scaled at the tile's middle latitude), each turned to
    the Earth-centred frame at its vertex.  Flat ground is then exactly the ellipsoid's up, also on a
    level-0 tile, whose chord triangles would tilt it by tens of degrees."""
    kx, ky = metres_per_degree(float(np.clip((lat.min() + lat.max()) / 2, -89.9, 89.9)))
    n = vertex_normals(np.column_stack([(lon - lon.min()) * kx, (lat - lat.min()) * ky, z]), tris)
    lo, la = np.radians(lon), np.radians(lat)
    east = np.column_stack([-np.sin(lo), np.cos(lo), np.zeros_like(lo)])
    north = np.column_stack([-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)])
    up = np.column_stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
    out = n[:, :1] * east + n[:, 1:2] * north + n[:, 2:] * up
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def oct_encode(n: np.ndarray) -> np.ndarray:
    """Unit vectors as two bytes each, CesiumJS's oct encoding (AttributeCompression.octEncode: the
    octahedron folded onto the square, each coordinate round((c + 1) / 2 * 255)).  quantized-mesh-
    encoder's oct_encode takes floor((c + 1) / 2 * 256) into a byte, so c = 1 wraps to 0: an east-pointing
    normal decodes as west (measured on a level-0 tile, tests/host/test_terrain.py)."""
    p = n[:, :2] / np.abs(n).sum(axis=1, keepdims=True)
    sx, sy = np.where(p[:, 0] < 0, -1.0, 1.0), np.where(p[:, 1] < 0, -1.0, 1.0)
    below = n[:, 2] < 0
    folded = np.column_stack([(1 - np.abs(p[:, 1])) * sx, (1 - np.abs(p[:, 0])) * sy])
    p = np.where(below[:, None], folded, p)
    return np.rint((np.clip(p, -1, 1) * 0.5 + 0.5) * 255).astype(np.uint8)


def encode_tile(mesh, z: np.ndarray, level: int, x: int, y: int) -> bytes:
    """A quantized-mesh-1.0 tile with the octvertexnormals extension from a mesh of the tile's 65 x 65 grid
    (``z`` per vertex), through quantized-mesh-encoder's writers (module docstring)."""
    from quantized_mesh_encoder.constants import EXTENSION_HEADER  # start-up: only when a tile is written
    from quantized_mesh_encoder.encode import (  # start-up: only when a tile is written
        compute_header,
        encode_header,
        write_edge_indices,
        write_indices,
        write_vertices,
    )

    tris = np.asarray(mesh.tris)[:, ::-1]  # (u, v) = (col, -row) mirrors the grid: counter-clockwise again
    order = np.unique(tris.ravel(), return_index=True)
    first = np.full(mesh.n_vertices, np.iinfo(np.int64).max)
    first[order[0]] = order[1]
    perm = np.argsort(first, kind="stable")  # vertices in the order the triangles first use them
    new = np.empty_like(perm)
    new[perm] = np.arange(len(perm))
    tris = new[tris]
    col, row, z = mesh.xy[perm, 0], mesh.xy[perm, 1], np.asarray(z, dtype=np.float64)[perm]
    west, south, east, north = tile_bounds(level, x, y)
    lon = west + col / (SAMPLES - 1) * (east - west)
    lat = north - row / (SAMPLES - 1) * (north - south)
    zlo, zhi = float(np.float32(z.min())), float(np.float32(z.max()))  # as the header stores them
    u = np.rint(col * QMAX / (SAMPLES - 1)).astype(np.int16)
    v = np.rint((SAMPLES - 1 - row) * QMAX / (SAMPLES - 1)).astype(np.int16)
    hq = np.rint((z - zlo) / (zhi - zlo) * QMAX) if zhi > zlo else np.zeros_like(z)
    uvh = np.column_stack([u, v, np.clip(hq, 0, QMAX).astype(np.int16)])
    f = io.BytesIO()
    header = compute_header(np.column_stack([lon, lat, z]).astype(np.float32), None)
    header["minimumHeight"], header["maximumHeight"] = zlo, zhi
    encode_header(f, header)
    write_vertices(f, uvh, len(uvh))
    write_indices(f, tris.astype(np.uint32), len(uvh))
    write_edge_indices(f, uvh, len(uvh))
    normals = oct_encode(normals_ecef(lon, lat, z, tris)).tobytes("C")
    f.write(struct.pack(EXTENSION_HEADER["extensionId"], 1))
    f.write(struct.pack(EXTENSION_HEADER["extensionLength"], len(normals)))
    f.write(normals)
    return f.getvalue()


def layer_json(name: str, max_zoom: int, available: list[list[dict]], bounds) -> dict:
    return {"tilejson": "2.1.0", "name": name, "description": "wavemesh terrain tiles", "version": "1.0.0",
            "format": "quantized-mesh-1.0", "attribution": "", "scheme": "tms",
            "tiles": ["{z}/{x}/{y}.terrain?v={version}"], "projection": "EPSG:4326",
            "bounds": [-180.0, -90.0, 180.0, 90.0], "data_bounds": list(bounds), "minzoom": 0,
            "maxzoom": max_zoom, "extensions": ["octvertexnormals"], "available": available}


@dataclass
class TileSet:
    """What :func:`make_tiles` made: per tile (level, x, y) its bytes and numbers."""

    files: dict  # (level, x, y) -> bytes
    rows: list  # per tile: level, x, y, vertices, triangles, tolerance, e_max (vertical, on its grid)
    layer: dict  # layer.json


def make_tiles(hf, *, max_zoom: int | None = None, zeta: float = 1.0, log=None) -> TileSet:
    """Every tile of levels 0..max_zoom over the DEM (module docstring)."""
    if not (math.isfinite(zeta) and zeta > 0):
        raise InputError(f"--zeta {zeta} is out of range",
                         hint="give the finest level's bound in metres, > 0")
    s = sampler(hf)
    if max_zoom is None:
        max_zoom = default_max_zoom(s)
    if not 0 <= max_zoom <= MAX_ZOOM:
        raise InputError(f"--max-zoom {max_zoom} is out of range", hint=f"use 0..{MAX_ZOOM}")
    files, rows, available = {}, [], []
    for level in range(max_zoom + 1):
        x0, y0, x1, y1 = tiles_at(level, s.bounds)
        available.append([{"startX": x0, "startY": y0, "endX": x1, "endY": y1}])
        tol = tolerance(level, max_zoom, zeta)
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                z, _, _ = tile_grid(s, level, x, y)
                tile_hf = from_array(z, f"tile {level}/{x}/{y}")
                params = api.MeshParams(refine=RefineParams(zeta=tol, metric="vertical"))
                result = api.mesh(tile_hf, params)
                zv = result.mesh.z(z)
                files[(level, x, y)] = encode_tile(result.mesh, zv, level, x, y)
                rows.append({"level": level, "x": x, "y": y, "vertices": result.mesh.n_vertices,
                             "triangles": result.mesh.n_triangles, "tolerance": tol,
                             "e_max_vertical": result.errors.e_max_vertical})
        if log:
            mine = [r for r in rows if r["level"] == level]
            size = sum(len(files[(level, r["x"], r["y"])]) for r in mine)
            tris = sum(r["triangles"] for r in mine)
            log(f"  level {level:>2}: {len(mine):>3} tiles, {tris:>6} triangles, "
                f"{size / 1024:>6.0f} KiB, tolerance {tol:>7.4g} m, E_max "
                f"{max(r['e_max_vertical'] for r in mine):.4g} m")
    return TileSet(files, rows, layer_json(getattr(hf, "source", "wavemesh"), max_zoom, available, s.bounds))


def write_tiles(ts: TileSet, folder: str, inputs=None) -> Path:
    """The pyramid into ``folder`` (created; its existing files kept unless replaced), whole or not at all,
    none of its files one of ``inputs`` (wavemesh.io.outputs)."""
    out = check_path(folder, None, "terrain tiles", inputs)
    with Outputs(inputs) as staged:
        for (level, x, y), data in ts.files.items():
            staged.path(out / str(level) / str(x) / f"{y}.terrain", what="terrain tile").write_bytes(data)
        staged.path(out / "layer.json", what="terrain tiles").write_text(
            json.dumps(ts.layer, indent=1) + "\n")
    return out
