"""GDAL rasters read through rasterio: SRTM .hgt, GeoTIFF with no-data, ESRI ASCII, .bil/.flt, .img,
.vrt, and `wavemesh mesh` on them as a user runs it.  Every raster here is written by rasterio."""

import json
import subprocess
import sys

import numpy as np
import pytest
import rasterio
import rasterio.shutil
from rasterio.transform import Affine
from wavemesh.check import check_mesh
from wavemesh.errors import InputError
from wavemesh.io.heightfield import load_heightfield
from wavemesh.io.meshread import read_mesh

SRTM3 = 1201  # samples per side of a 3 arc-second SRTM tile (the smallest size GDAL's SRTMHGT takes)
UTM = {"crs": "EPSG:32617", "transform": Affine(30.0, 0.0, 500000.0, 0.0, -30.0, 4100000.0)}


def wavemesh(*args):
    """The installed command in a subprocess: what a user sees, tracebacks included."""
    return subprocess.run([sys.executable, "-m", "wavemesh", *map(str, args)], capture_output=True,
                          text=True, timeout=300)


def terrain(h, w, dtype=np.int16):
    """Smooth hills in metres."""
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    z = 600 + 250 * np.sin(5 * x + 1) * np.cos(3 * y) + 120 * np.exp(-((x - 0.4) ** 2 + (y - 0.6) ** 2) * 25)
    return np.rint(z).astype(dtype)


def write_raster(path, array, driver, nodata=None, crs=UTM["crs"], transform=UTM["transform"]):
    with rasterio.open(path, "w", driver=driver, width=array.shape[1], height=array.shape[0], count=1,
                       dtype=array.dtype, nodata=nodata, crs=crs, transform=transform) as ds:
        ds.write(array, 1)
    return path


def one_error_line(r, *words):
    """A failed run: exit status 2, `error:` and at most a `hint:` line on stderr, no traceback."""
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.splitlines()
    assert lines and lines[0].startswith("error: ") and len(lines) <= 2, r.stderr
    assert all(line.startswith(("error: ", "hint: ")) for line in lines), r.stderr
    for word in words:
        assert word in r.stderr, (word, r.stderr)


def srtm_tile(tmp_path, name="N36W084.hgt"):
    """A 3 arc-second SRTM tile with voids (-32768), as the USGS ships it: raw big-endian int16."""
    z = terrain(SRTM3, SRTM3)
    voids = np.zeros(z.shape, dtype=bool)
    voids[300:312, 500:540] = True  # a void of 12 x 40 samples
    voids[0, 0] = voids[SRTM3 - 1, 77] = True
    z[voids] = -32768
    corner = Affine(1 / 1200, 0, -84 - 0.5 / 1200, 0, -1 / 1200, 37 + 0.5 / 1200)  # samples on whole degrees
    path = write_raster(tmp_path / name, z, "SRTMHGT", nodata=-32768, crs="EPSG:4326", transform=corner)
    return path, z, voids


# ---------------------------------------------------------------------------
# `wavemesh mesh` on an SRTM tile and on a GeoTIFF with no-data


def test_mesh_reads_srtm_hgt(tmp_path):
    path, z, voids = srtm_tile(tmp_path)
    assert path.stat().st_size == SRTM3 * SRTM3 * 2  # the bare tile, no header
    assert np.array_equal(np.fromfile(path, dtype=">i2").reshape(SRTM3, SRTM3), z)
    out, report = tmp_path / "tile.obj", tmp_path / "tile.json"

    r = wavemesh("mesh", path, "-o", out)
    one_error_line(r, f"{int(voids.sum())} of {SRTM3 * SRTM3} samples", "--fill nearest")
    assert not out.exists()

    r = wavemesh("mesh", path, "-o", out, "--fill", "nearest", "--report", report)
    assert r.returncode == 0, r.stderr
    rep = json.loads(report.read_text())["input"]
    assert (rep["width"], rep["height"], rep["filled"]) == (SRTM3, SRTM3, int(voids.sum()))
    assert rep["min"] == z[~voids].min() and rep["max"] == z[~voids].max() and rep["lossless"]
    mesh, heights = read_mesh(out)
    assert check_mesh(mesh).valid
    hf = load_heightfield(path, fill="nearest")
    assert np.array_equal(hf.values[~voids], z[~voids])
    np.testing.assert_array_equal(heights, mesh.z(hf.values))
    # the tile's place comes from its name: sample (0, 0) is at 37 N, 84 W
    a, b, c, d, e, f = hf.transform
    assert (b, d) == (0.0, 0.0) and a == pytest.approx(1 / 1200) and e == pytest.approx(-1 / 1200)
    assert c + a / 2 == pytest.approx(-84) and f + e / 2 == pytest.approx(37) and hf.crs == "EPSG:4326"


def test_srtm_tile_under_another_name_is_refused(tmp_path):
    path, _, _ = srtm_tile(tmp_path)
    renamed = tmp_path / "dem.hgt"
    renamed.write_bytes(path.read_bytes())
    r = wavemesh("mesh", renamed, "-o", tmp_path / "m.obj", "--fill", "nearest")
    one_error_line(r, "dem.hgt", "N36W084.hgt")


def test_mesh_reads_geotiff_with_nodata(tmp_path):
    z = terrain(97, 130, np.float32) + np.float32(0.25)
    z[40:47, 60:75] = -9999
    z[0, :3] = -9999
    tif = write_raster(tmp_path / "dem.tif", z, "GTiff", nodata=-9999)
    out = tmp_path / "dem.obj"

    r = wavemesh("mesh", tif, "-o", out)
    one_error_line(r, "108 of 12610 samples", "--fill nearest", "--fill VALUE")
    assert not out.exists()

    r = wavemesh("mesh", tif, "-o", out, "--fill", "nearest")
    assert r.returncode == 0, r.stderr
    mesh, heights = read_mesh(out)
    assert check_mesh(mesh).valid
    hf = load_heightfield(tif, fill="nearest")
    good = z != -9999
    assert hf.filled == 108 and np.array_equal(hf.values[good], z[good].astype(np.float64))
    np.testing.assert_array_equal(heights, mesh.z(hf.values))
    assert hf.transform == (30.0, 0.0, 500000.0, 0.0, -30.0, 4100000.0) and hf.crs == "EPSG:32617"

    # the reader changes nothing in the mesh: the same heights from a .npy with the GeoTIFF's 30 m cell
    # give the same mesh (its vertices in grid steps, the GeoTIFF's in UTM metres beside their sidecar)
    np.save(tmp_path / "dem.npy", hf.values)
    r = wavemesh("mesh", tmp_path / "dem.npy", "-o", tmp_path / "npy.ply", "--spacing", "30")
    assert r.returncode == 0, r.stderr
    npy_mesh, npy_heights = read_mesh(tmp_path / "npy.ply")
    assert np.array_equal(npy_mesh.xy, mesh.xy) and np.array_equal(npy_mesh.tris, mesh.tris)
    assert np.array_equal(npy_heights, heights)

    r = wavemesh("mesh", tif, "-o", tmp_path / "zero.obj", "--fill", "0", "--stage", "initial")
    assert r.returncode == 0, r.stderr


# ---------------------------------------------------------------------------
# every GDAL format a DEM user is likely to have, written by rasterio


@pytest.mark.parametrize(
    "name, driver, dtype",
    [
        ("dem.tif", "GTiff", np.float32),
        ("dem.tiff", "GTiff", np.int16),
        ("dem.asc", "AAIGrid", np.float32),
        ("dem.bil", "EHdr", np.int16),
        ("dem.flt", "EHdr", np.float32),
        ("dem.img", "HFA", np.float32),
        ("DEM.IMG", "HFA", np.int16),
    ],
)
def test_gdal_formats_with_nodata(tmp_path, name, driver, dtype):
    z = terrain(23, 31, dtype)
    if np.dtype(dtype).kind == "f":
        z = z + dtype(0.5)
    holes = np.zeros(z.shape, dtype=bool)
    holes[5:8, 10:12] = holes[22, 30] = True
    z[holes] = -9999
    path = write_raster(tmp_path / name, z, driver, nodata=-9999)
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(InputError) as info:
        load_heightfield(path)
    assert "7 of 713 samples" in str(info.value) and "--fill" in str(info.value)
    hf = load_heightfield(path, fill="-1")
    expected = np.where(holes, -1.0, z.astype(np.float64))
    assert np.array_equal(hf.values, expected) and hf.filled == 7
    assert hf.transform == (30.0, 0.0, 500000.0, 0.0, -30.0, 4100000.0) and hf.crs is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # reading leaves nothing beside the file


def test_vrt(tmp_path):
    z = terrain(17, 19)
    z[3, 4] = -32768
    write_raster(tmp_path / "src.tif", z, "GTiff", nodata=-32768)
    rasterio.shutil.copy(tmp_path / "src.tif", tmp_path / "dem.vrt", driver="VRT")
    assert "<VRTDataset" in (tmp_path / "dem.vrt").read_text()
    hf = load_heightfield(tmp_path / "dem.vrt", fill="nearest")
    assert hf.filled == 1 and hf.values[3, 4] in (z[2, 4], z[4, 4], z[3, 3], z[3, 5])
    assert np.array_equal(np.delete(hf.values.ravel(), 3 * 19 + 4), np.delete(z.ravel(), 3 * 19 + 4))
    (tmp_path / "src.tif").unlink()
    with pytest.raises(InputError) as info:
        load_heightfield(tmp_path / "dem.vrt")
    assert "dem.vrt" in str(info.value) and "\n" not in str(info.value)


def test_band_scale_and_offset_applied(tmp_path):
    counts = np.arange(12, dtype=np.int16).reshape(3, 4) * 10
    with rasterio.open(tmp_path / "s.tif", "w", driver="GTiff", width=4, height=3, count=1, dtype="int16",
                       **UTM) as ds:
        ds.write(counts, 1)
        ds.scales, ds.offsets = (0.5,), (-100.0,)
    hf = load_heightfield(tmp_path / "s.tif")
    assert np.array_equal(hf.values, counts * 0.5 - 100)


def test_float_nan_nodata(tmp_path):
    z = terrain(6, 7, np.float32)
    z[2, 3] = np.nan
    path = write_raster(tmp_path / "nan.tif", z, "GTiff", nodata=np.nan)
    with pytest.raises(InputError, match="1 of 42"):
        load_heightfield(path)
    assert load_heightfield(path, fill="nearest").filled == 1


def test_damaged_gdal_files_never_crash(tmp_path):
    """Cut and scribbled-over rasters: a height field or a one-line InputError, nothing else."""
    rng = np.random.default_rng(21)
    z = terrain(9, 11)
    z[4, 5] = -9999
    write_raster(tmp_path / "a.bil", z, "EHdr", nodata=-9999)
    write_raster(tmp_path / "a.img", z, "HFA", nodata=-9999)
    write_raster(tmp_path / "a.tif", z, "GTiff", nodata=-9999)
    rasterio.shutil.copy(tmp_path / "a.tif", tmp_path / "a.vrt", driver="VRT")
    for name in ("a.bil", "a.hdr", "a.img", "a.vrt"):
        data = (tmp_path / name).read_bytes()
        for trial in range(40):
            m = bytearray(data[: rng.integers(0, len(data))] if trial % 2 else data)
            if trial % 2 == 0:
                for i in rng.integers(0, len(m), size=4):
                    m[i] = rng.integers(0, 256)
            (tmp_path / name).write_bytes(bytes(m))
            target = tmp_path / ("a.bil" if name == "a.hdr" else name)
            try:
                hf = load_heightfield(target, fill="nearest")
            except InputError as e:
                assert str(e) and "\n" not in str(e)
            else:
                assert hf.samples.dtype == np.uint16 and hf.values.shape == hf.samples.shape
        (tmp_path / name).write_bytes(data)


def test_truncated_raw_raster_is_an_error(tmp_path):
    write_raster(tmp_path / "a.bil", terrain(40, 50), "EHdr")
    data = (tmp_path / "a.bil").read_bytes()
    (tmp_path / "a.bil").write_bytes(data[: len(data) - 100])
    with pytest.raises(InputError, match="a.bil"):
        load_heightfield(tmp_path / "a.bil")


# ---------------------------------------------------------------------------
# start-up: rasterio and scipy only when a GDAL raster is read or --fill nearest asked


def test_cli_starts_without_rasterio_or_scipy(tmp_path):
    np.save(tmp_path / "a.npy", np.arange(12.0).reshape(3, 4))
    code = (
        "import sys, wavemesh.cli\n"
        "from wavemesh.io.heightfield import load_heightfield\n"
        f"load_heightfield({str(tmp_path / 'a.npy')!r})\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'rasterio', 'scipy', 'tifffile'}))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
