"""`wavemesh mesh`'s default on a large grid (api.auto_tile, docs/usage.md "Threads and tiles"): over the
threshold it is `--tile AUTO_TILE`'s mesh, byte for byte, on one worker and on two; under it, and with
`--tile off` or an option tiles do not do, the untiled mesh; bad --tile values end in one error line.

The product's threshold (4M samples) would make these tests slow: they lower api.AUTO_TILE_SAMPLES and
api.AUTO_TILE (io.load's, which auto_tile reads) on a 203 x 170 grid; the last test pins the product's."""

from __future__ import annotations

import numpy as np
import pytest
from test_tiles import terrain
from wavemesh import api
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.harness import run_cli
from wavemesh.io import load
from wavemesh.io.meshread import read_mesh


@pytest.fixture(scope="module")
def dem(tmp_path_factory):
    path = tmp_path_factory.mktemp("auto") / "t.npy"
    np.save(path, terrain(203, 170))
    return path


def mesh(dem, out, *args) -> tuple[bytes, str]:
    rc, stdout, err = run_cli("mesh", str(dem), "-o", str(out), "--zeta", "3", *args)
    assert rc == 0, err
    return out.read_bytes(), stdout


@pytest.fixture
def small(monkeypatch):
    """The default's threshold lowered under the test grid (203 x 170 = 34510 samples), tiles of 64."""
    monkeypatch.setattr(load, "AUTO_TILE_SAMPLES", 30000)
    monkeypatch.setattr(load, "AUTO_TILE", 64)


def test_over_the_threshold_the_default_is_tiled(dem, tmp_path, small):
    tiled, said = mesh(dem, tmp_path / "t.obj", "--tile", "64", "--workers", "1")
    one, said1 = mesh(dem, tmp_path / "w1.obj", "--workers", "1")
    two, _ = mesh(dem, tmp_path / "w2.obj", "--workers", "2", "--metric", "normal")  # normal: the default
    assert one == tiled and "4 x 3 tiles of at most 64" in said1
    assert "tiles of at most 64 (the default for a grid this large; --tile off meshes it whole)" in said1
    assert "the default" not in said  # --tile 64: the user's choice
    assert two == tiled
    untiled, _ = mesh(dem, tmp_path / "u.obj", "--tile", "off")
    assert untiled != tiled and b"tiled mesh" not in untiled and b"tiled mesh, tile=64" in tiled


def test_under_the_threshold_the_default_is_untiled(dem, tmp_path, monkeypatch):
    monkeypatch.setattr(load, "AUTO_TILE_SAMPLES", 203 * 170 + 1)
    monkeypatch.setattr(load, "AUTO_TILE", 64)
    default, said = mesh(dem, tmp_path / "d.obj", "--workers", "2")
    off, _ = mesh(dem, tmp_path / "off.obj", "--tile", "off")
    hf = api.load_input(str(dem))
    assert default == off and "refiner:" in said and "tiles of at most" not in said
    # not silently ignored; why: the grid under the default's threshold (as the test lowered it), or
    # the option that keeps it whole (--tile N would refuse it: not "--tile N tiles it")
    assert "meshed whole by one process: --workers 2 spreads tiles (the default meshes a 203 x 170 grid " \
           "whole; --tile N tiles it)" in said
    assert "--workers 2 spreads tiles (--lod is not done in tiles)" in mesh(
        dem, tmp_path / "lod.obj", "--workers", "2", "--lod", str(tmp_path / "lod"))[1]
    assert "--workers 3 spreads tiles (--tile off)" in mesh(dem, tmp_path / "o3.obj", "--tile", "off",
                                                            "--workers", "3")[1]
    assert "spreads tiles" not in mesh(dem, tmp_path / "w1.obj", "--workers", "1")[1]
    assert "meshed whole" not in mesh(dem, tmp_path / "c.obj", "--check-levels")[1]  # under: nothing to say
    assert api.mesh(hf, api.MeshParams(refine=api.RefineParams(zeta=3.0))).mesh.n_triangles \
        == default.count(b"\nf ")


@pytest.mark.parametrize("option,name", [(("--check-levels",), "--check-levels"),
                                         (("--roi", "10,10,100,80"), "--roi"),
                                         (("--bound", "off"), "--bound off"),
                                         (("--stage", "initial"), "--stage initial"),
                                         (("--nodata", "hole"), "--nodata hole")])
def test_options_tiles_do_not_do_stay_untiled(dem, tmp_path, small, option, name):
    default, said = mesh(dem, tmp_path / "d.obj", *option)
    off, said_off = mesh(dem, tmp_path / "off.obj", "--tile", "off", *option)
    assert default == off and "tiles of at most" not in said
    # the run says why it is whole, which the user who asked for it (--tile off) need not be told
    assert f"meshed whole: {name} is not done in tiles (without it this grid goes in tiles of 64" in said
    assert "meshed whole" not in said_off


@pytest.mark.parametrize("args,expect", [
    (("--tile", "x"), "argument --tile: 'x' is not a tile side"),
    (("--tile", "1.5"), "argument --tile: '1.5' is not a tile side"),
    (("--tile", "8"), "--tile 8 is too small"),
    (("--tile", "off", "--tiles-dir", "d"), "--tile off meshes the grid whole: --tiles-dir needs tiles"),
    (("--tile", "off", "--scheduler", "tcp://127.0.0.1:9"), "--scheduler needs tiles"),
    (("--workers", "0"), "--workers 0 is out of range"),
    (("--tile", "64", "--check-levels"), "--check-levels is not done in tiles"),  # was ignored
])
def test_bad_tile_values(dem, tmp_path, small, args, expect):
    out = tmp_path / "m.obj"
    rc, _, err = run_cli("mesh", str(dem), "-o", str(out), *args)
    assert rc == 2 and err.startswith("error: ") and expect in err.splitlines()[0], err
    assert len(err.splitlines()) <= 2 and not out.exists()


# an example of each option of api.UNTILED_ONLY, the one list of what tiles do not do
UNTILED_EXAMPLES = {
    "--lod": ("--lod", "lod"), "--check-levels": ("--check-levels",), "--roi": ("--roi", "10,10,100,80"),
    "--nodata hole": ("--nodata", "hole"), "--invalid": ("--invalid", "-9999"),
    "--denoise": ("--denoise", "median"), "--normal-map": ("--normal-map", "n.png"),
    "--stage initial": ("--stage", "initial"), "--bound off": ("--bound", "off"),
    "--max-triangles": ("--max-triangles", "100000"), "--capacity": ("--capacity", "100000"),
}


def test_every_option_tiles_do_not_do_is_refused_with_tiles(dem, tmp_path, small):
    """Each option of the one list: one error line naming it and why with --tile N (nothing written), the
    --tile help names it, and the default meshes the grid whole (one of them run: test above)."""
    assert set(UNTILED_EXAMPLES) == set(api.UNTILED_ONLY)
    from wavemesh import cli

    sub = cli.build_parser("mesh")._subparsers._group_actions[0].choices["mesh"]
    assert ", ".join(api.UNTILED_ONLY) in next(a.help for a in sub._actions if a.dest == "tile")
    for option, args in UNTILED_EXAMPLES.items():
        out = tmp_path / "m.obj"
        rc, _, err = run_cli("mesh", str(dem), "-o", str(out), "--tile", "64", *args)
        line = f"error: {option} is not done in tiles: {api.UNTILED_ONLY[option]}"
        assert rc == 2 and err.splitlines()[0] == line, (option, err)
        assert not out.exists()
    default = api.MeshParams()
    assert api.untiled_options(default) == []
    assert api.untiled_options(api.MeshParams(roi=((10, 10, 5, 5),), initial_only=True),
                               lod="d") == ["--lod", "--roi", "--stage initial"]


def test_stream_tile_off_is_one_device(dem, tmp_path):
    rc, _, err = run_cli("stream", str(dem), "-o", str(tmp_path / "m.obj"), "--tile", "off",
                         "--port", "loop://", "--port", "loop://")
    assert rc == 2 and err.startswith("error: --tile off meshes the grid whole on one device"), err


def test_the_product_default():
    """The measured default (docs/usage.md): grids of 2048^2 samples and more, in tiles of 513; the
    decision reads the grid's size alone."""
    assert (api.AUTO_TILE, api.AUTO_TILE_SAMPLES) == (513, 2048 * 2048)
    assert api.auto_tile(2048, 2048) == 513 and api.auto_tile(4096, 4096) == 513
    assert api.auto_tile(2048, 2047) is None and api.auto_tile(1025, 8192) == 513
    assert api.auto_tile(8192, 512) == 513
    # a side the refiner cannot take whole (over MAX_SIDE, 32767): in tiles, however few its samples
    assert api.auto_tile(32768, 2) == 513 and api.auto_tile(3, 40000) == 513
    assert api.auto_tile(32767, 2) is None


def test_a_side_over_the_refiners_goes_in_tiles(tmp_path):
    """32768 x 3 samples: refused whole, from the header (one error line; the filter bank said only
    "argument out of range"), meshed in tiles by default."""
    path = tmp_path / "long.npy"
    np.save(path, np.sin(np.arange(3 * 32768) / 500.0).reshape(3, 32768) * 50)
    rc, _, err = run_cli("mesh", str(path), "-o", str(tmp_path / "off.obj"), "--tile", "off")
    assert rc == 2 and "the 32768 x 3 grid has a side over 32767 samples" in err.splitlines()[0], err
    mesh(path, tmp_path / "m.obj", "-q")
    got, _ = read_mesh(tmp_path / "m.obj")
    assert (got.width, got.height) == (32768, 3) and check_mesh(got).valid  # the whole rectangle
    e = mesh_errors(got, np.load(path).astype(np.float64), rms=False)
    assert e.e_max_normal <= 3 * (1 + 1e-9)  # --zeta 3, the default metric


def test_a_raster_wider_than_the_refiner_goes_in_tiles(tmp_path):
    """A GeoTIFF more than MAX_SIDE wide (which the refiner cannot take whole) and large enough for the
    default: in tiles (TileInstead from its header), not refused; whole (--tile off) it is refused."""
    import rasterio
    from wavemesh.errors import InputError
    from wavemesh.limits import MAX_SIDE

    path = tmp_path / "wide.tif"
    w, h = MAX_SIDE + 1, -(-api.AUTO_TILE_SAMPLES // (MAX_SIDE + 1))
    with rasterio.open(path, "w", driver="GTiff", width=w, height=h, count=1, dtype="uint8",
                       compress="deflate", tiled=True, transform=rasterio.Affine(1, 0, 0, 0, -1, h)) as ds:
        ds.write(np.zeros((1, h, w), dtype=np.uint8))
    with pytest.raises(api.TileInstead) as got:
        api.load_input(str(path), check_memory=True, tile_from=api.auto_tile)
    assert (got.value.tile, got.value.width, got.value.height) == (api.AUTO_TILE, w, h)
    with pytest.raises(InputError, match=f"grid has a side over {MAX_SIDE} samples"):
        api.load_input(str(path), check_memory=True)


def test_the_default_tiles_before_the_memory_estimate(tmp_path, monkeypatch):
    """docs/tiles.md "Memory": a grid too large to mesh whole is refused with --tile off only; by default
    (over the threshold) it goes in tiles, decided from the header before the untiled run's estimate."""
    from wavemesh.errors import InputError

    path = tmp_path / "z.npy"
    np.lib.format.open_memmap(path, mode="w+", dtype=np.float32, shape=(2048, 2048)).flush()
    monkeypatch.setattr(load, "memory_available", lambda: [(1 << 20, "a test's 1 MiB", "resident")])
    with pytest.raises(InputError, match="untiled needs at least"):
        api.load_input(str(path), check_memory=True)
    with pytest.raises(api.TileInstead):
        api.load_input(str(path), check_memory=True, tile_from=api.auto_tile)


@pytest.mark.parametrize("args,expect", [
    (("--max-hole", "3", "--tile", "64"), "error: --max-hole 3: fills the enclosed dropouts"),
    (("--min-area", "5"), "error: --min-area drops pieces of a mesh with holes"),
    (("--min-area", "5", "--tile", "64"), "error: --min-area drops pieces of a mesh with holes"),
])
def test_hole_options_without_nodata_hole_are_refused_tiled_too(dem, tmp_path, small, args, expect):
    """--max-hole and --min-area only act with --nodata hole: an untiled run refused them without it, a
    tiled one (the default over the threshold) took them and did nothing."""
    out = tmp_path / "m.obj"
    rc, _, err = run_cli("mesh", str(dem), "-o", str(out), *args)
    assert rc == 2 and err.startswith(expect) and "hint: use it with --nodata hole" in err, err
    assert not out.exists()


def test_no_data_refused_in_tiles_and_the_hint_works(dem, tmp_path, small):
    """A large grid with no-data samples, tiled by default: one error line whose hint names --nodata hole,
    and that run (untiled, holes) then succeeds without any --tile."""
    v = np.load(dem)
    v[50, 60] = np.nan
    path = tmp_path / "nan.npy"
    np.save(path, v)
    rc, _, err = run_cli("mesh", str(path), "-o", str(tmp_path / "m.obj"))
    assert rc == 2 and "1 samples are NaN" in err.splitlines()[0], err
    assert "--nodata hole to leave holes (the grid then meshed whole, not in tiles)" in err
    _, said = mesh(path, tmp_path / "h.obj", "--nodata", "hole")
    assert "meshed whole: --nodata hole is not done in tiles" in said
