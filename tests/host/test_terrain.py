"""`wavemesh tiles`: a quantized-mesh-1.0 pyramid of Jacksboro, decoded by quantized-mesh-tile (an
independent reader), each tile's mesh compared with the DEM interpolated here (scipy), layer.json with
the files written, and a grid without a georeference refused."""

import json
import math

import matplotlib.cbook
import matplotlib.tri
import numpy as np
import pytest
from quantized_mesh_tile.terrain import TerrainTile
from scipy.interpolate import RegularGridInterpolator
from wavemesh import cli

JACKSBORO = matplotlib.cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False)
MAX_ZOOM, ZETA = 10, 2.0
E0 = 6378137.0 * 2 * math.pi * 0.25 / 130  # Cesium's level-0 geometric error of a 65-sample tile


def run(*args) -> int:
    return cli.main([str(a) for a in args])


def dem():
    """Jacksboro as a function of (lon, lat): bilinear between the sample centres (the .npz's xmin and
    ymin are the outer edges of sample (0, 0)'s cell, row 0 the north: its ymin is the larger), 0 outside
    the cells."""
    d = np.load(JACKSBORO)
    z = d["elevation"].astype(float)
    h, w = z.shape
    step = 1 / 1200
    north = float(d["ymin"])
    assert north > d["ymax"] and north - h * step == pytest.approx(d["ymax"])
    lon = d["xmin"] + (np.arange(w) + 0.5) * step
    lat = north - (np.arange(h) + 0.5) * step
    f = RegularGridInterpolator((lat[::-1], lon), z[::-1], bounds_error=False, fill_value=None)

    def at(x, y):
        inside = ((x >= d["xmin"]) & (x <= d["xmin"] + w * step)
                  & (y <= north) & (y >= north - h * step))
        xc, yc = np.clip(x, lon[0], lon[-1]), np.clip(y, lat[-1], lat[0])
        return np.where(inside, f(np.column_stack([yc.ravel(), xc.ravel()])).reshape(np.shape(x)), 0.0)

    return at


@pytest.fixture(scope="module")
def pyramid(tmp_path_factory):
    out = tmp_path_factory.mktemp("terrain") / "tiles"
    assert run("tiles", JACKSBORO, "--key", "elevation", "-o", out, "--max-zoom", MAX_ZOOM, "--zeta", ZETA,
               "-q") == 0
    return out


def test_layer_json_lists_every_tile(pyramid):
    layer = json.loads((pyramid / "layer.json").read_text())
    assert layer["format"] == "quantized-mesh-1.0" and layer["projection"] == "EPSG:4326"
    assert layer["scheme"] == "tms" and "octvertexnormals" in layer["extensions"]
    assert layer["minzoom"] == 0 and layer["maxzoom"] == MAX_ZOOM and len(layer["available"]) == MAX_ZOOM + 1
    listed = {(z, x, y) for z, rects in enumerate(layer["available"]) for r in rects
              for x in range(r["startX"], r["endX"] + 1) for y in range(r["startY"], r["endY"] + 1)}
    written = {(int(p.parts[-3]), int(p.parts[-2]), int(p.stem)) for p in pyramid.rglob("*.terrain")}
    assert listed == written
    assert {(0, 0, 0), (0, 1, 0)} <= written  # both root tiles of the geographic scheme
    # Jacksboro (-84.41..-84.08, 36.45..36.73) at level 10: tiles of 180/1024 degrees, TMS y from the south
    d = 180 / 1024
    for z, x, y in written:
        if z == MAX_ZOOM:
            west, south = -180 + x * d, -90 + y * d
            assert west < -84.08 and west + d > -84.41 and south < 36.74 and south + d > 36.44


def test_every_tile_decodes_within_its_level_tolerance(pyramid):
    at = dem()
    tiles = sorted(pyramid.rglob("*.terrain"))
    assert len(tiles) > 20
    for path in tiles:
        level, x, y = int(path.parts[-3]), int(path.parts[-2]), int(path.stem)
        d = 180 / 2 ** level
        west, south = -180 + x * d, -90 + y * d
        t = TerrainTile(west=west, south=south, east=west + d, north=south + d)
        t.fromFile(str(path), hasLighting=True)
        u, v = np.array(t.u, float), np.array(t.v, float)
        lon, lat, h = np.array(t.getVerticesCoordinates()).T
        tri = np.array(t.indices).reshape(-1, 3)
        n = len(u)
        step = (t.header["maximumHeight"] - t.header["minimumHeight"]) / 32767
        tol = min(E0 / 2 ** level, ZETA * 2 ** (MAX_ZOOM - level))
        # every vertex a sample of the tile's 65 x 65 grid, its height the DEM's there (to the quantisation)
        col, row = u * 64 / 32767, v * 64 / 32767
        assert np.abs(col - np.rint(col)).max() < 0.01 and np.abs(row - np.rint(row)).max() < 0.01
        gx = west + np.rint(col) / 64 * d
        gy = south + np.rint(row) / 64 * d
        assert np.abs(h - at(gx, gy)).max() <= step / 2 + 1e-3, path
        # the mesh against the DEM at every sample of the tile's grid: within the level's tolerance
        g = np.linspace(0, 1, 65)
        px, py = np.meshgrid(west + g * d, south + g * d)
        surface = matplotlib.tri.LinearTriInterpolator(
            matplotlib.tri.Triangulation(np.rint(col), np.rint(row), tri), h)(*np.meshgrid(g * 64, g * 64))
        assert not np.ma.is_masked(surface) or not surface.mask.any(), "the tile does not cover its square"
        assert np.abs(np.asarray(surface) - at(px, py)).max() <= tol + step + 1e-3, (path, tol)
        # counter-clockwise seen from above, in (u, v)
        c = np.column_stack([u, v])[tri]
        e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
        assert (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0).all()
        # the edge lists Cesium hangs the skirts on: exactly the vertices on each edge, corners included
        for lst, on in ((t.westI, u == 0), (t.eastI, u == 32767), (t.southI, v == 0), (t.northI, v == 32767)):
            assert sorted(lst) == list(np.flatnonzero(on)) and len(lst) >= 2
        # oct-encoded normals, one a vertex, pointing away from the Earth's centre
        normals = np.array(t.vLight, float)
        assert normals.shape == (n, 3)
        assert np.abs(np.linalg.norm(normals, axis=1) - 1).max() < 0.02
        lo, la = np.radians(lon), np.radians(lat)
        up = np.column_stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
        assert (np.sum(normals * up, axis=1) > 0).all()  # (the cliff at the DEM's edge is steep)
        if level == 0:  # flat: the ellipsoid's up, also where a component is 1 (east at longitude 0)
            assert (np.sum(normals * up, axis=1) > 0.99).all()


def test_tiles_without_a_georeference_one_error(tmp_path, capsys):
    np.save(tmp_path / "h.npy", np.random.default_rng(1).random((40, 50)))
    out = tmp_path / "t"
    assert run("tiles", tmp_path / "h.npy", "-o", out) != 0
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("error: ") and "georeference" in err[0]
    assert len([e for e in err if e.startswith("error:")]) == 1
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["h.npy"]
