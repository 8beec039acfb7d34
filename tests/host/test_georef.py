"""Ground units (issue 19): the georeference read from the input, the normal metric on the true cell
size, the outputs in map units (OBJ, PLY, the sidecar, .glb), `wavemesh check` and the pictures."""

import json
import math
import struct

import numpy as np
import pytest
import rasterio
from rasterio.transform import Affine
from wavemesh import api, cli
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.errors import InputError
from wavemesh.io import georef
from wavemesh.io.heightfield import from_array, load_heightfield
from wavemesh.io.meshread import read_mesh
from wavemesh.refine import native

# Non-square UTM cells (20 m east, 30 m north), sample (0, 0)'s cell corner at (500000, 4100000)
GEO = Affine(20.0, 0.0, 500000.0, 0.0, -30.0, 4100000.0)


def hills(h, w):
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    z = 600 + 250 * np.sin(5 * x + 1) * np.cos(3 * y) + 120 * np.exp(-((x - 0.4) ** 2 + (y - 0.6) ** 2) * 25)
    return np.rint(z).astype(np.int16)


def geotiff(path, z, crs="EPSG:32617", transform=GEO):
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype=z.dtype,
                       crs=crs, transform=transform) as ds:
        ds.write(z, 1)
    return path


def obj_vertices(path) -> np.ndarray:
    """The raw ``v x y z`` numbers of an OBJ file, read here (not by wavemesh)."""
    return np.array([[float(t) for t in line.split()[1:4]] for line in open(path) if line.startswith("v ")])


def run(*args) -> int:
    return cli.main([str(a) for a in args])


def test_every_obj_vertex_sits_at_its_samples_geotransform(tmp_path):
    z = hills(45, 61)
    tif = geotiff(tmp_path / "dem.tif", z)
    out = tmp_path / "dem.obj"
    assert run("mesh", tif, "-o", out, "--zeta", "2", "--units", "crs", "-q") == 0
    raw = obj_vertices(out)
    # Which sample each vertex is: the heights are those of the samples, so match them independently of
    # the sidecar: col, row from the known geotransform, then the height must be that sample's.
    col = (raw[:, 0] - 500000.0) / 20.0 - 0.5
    row = (4100000.0 - raw[:, 1]) / 30.0 - 0.5
    assert np.allclose(col, np.round(col), atol=1e-9) and np.allclose(row, np.round(row), atol=1e-9)
    col, row = np.round(col).astype(int), np.round(row).astype(int)
    assert np.array_equal(raw[:, 2], z[row, col].astype(float))
    # exactly the geotransform's numbers: x = c + a (col + 0.5), y = f + e (row + 0.5)
    assert np.array_equal(raw[:, 0], 500000.0 + 20.0 * (col + 0.5))
    assert np.array_equal(raw[:, 1], 4100000.0 - 30.0 * (row + 0.5))
    side = json.loads((tmp_path / "dem.obj.georef.json").read_text())
    assert side["crs"] == "EPSG:32617" and side["origin"] == [0.0, 0.0] and side["vertices"] == "map"
    assert side["transform"] == [20.0, 0.0, 500000.0, 0.0, -30.0, 4100000.0]
    assert side["spacing"] == [20.0, 30.0]
    # wavemesh reads it back through the sidecar, and check measures it
    mesh, heights = read_mesh(out)
    assert check_mesh(mesh).valid and np.array_equal(mesh.xy, np.column_stack([col, row]))
    assert run("check", out, "--against", tif, "-q") == 0

    # --local: the same less sample (0, 0)'s position, named in the sidecar; PLY alike
    ply = tmp_path / "local.ply"
    assert run("mesh", tif, "-o", ply, "--zeta", "2", "--local", "-q") == 0
    side = json.loads((tmp_path / "local.ply.georef.json").read_text())
    assert side["vertices"] == "local" and side["origin"] == [500010.0, 4099985.0]
    m2, h2 = read_mesh(ply)
    assert np.array_equal(m2.xy, mesh.xy) and np.array_equal(h2, heights)
    assert run("check", ply, "--against", tif, "-q") == 0


def test_crop_and_decimate_keep_the_georeference(tmp_path):
    z = hills(45, 61)
    tif = geotiff(tmp_path / "dem.tif", z)
    out = tmp_path / "part.obj"
    assert run("mesh", tif, "-o", out, "--crop", "3,4,40,30", "--decimate", "2", "--units", "crs", "-q") == 0
    raw = obj_vertices(out)
    col = np.round((raw[:, 0] - 500000.0) / 20.0 - 0.5).astype(int)
    row = np.round((4100000.0 - raw[:, 1]) / 30.0 - 0.5).astype(int)
    assert np.all((col - 3) % 2 == 0) and np.all((row - 4) % 2 == 0)  # samples of the decimated crop
    assert np.array_equal(raw[:, 2], z[row, col].astype(float))
    hf = api.load_input(str(tif), crop="3,4,40,30", decimate=2)
    assert georef.ground(hf).spacing == (40.0, 60.0)
    assert run("check", out, "--against", tif, "--crop", "3,4,40,30", "--decimate", "2", "-q") == 0


def test_plain_input_stays_in_grid_steps(tmp_path):
    np.save(tmp_path / "h.npy", hills(20, 30))
    out = tmp_path / "h.obj"
    assert run("mesh", tmp_path / "h.npy", "-o", out, "-q") == 0
    raw = obj_vertices(out)
    assert np.array_equal(raw[:, :2], np.round(raw[:, :2])) and not (tmp_path / "h.obj.georef.json").exists()
    g = georef.ground(load_heightfield(tmp_path / "h.npy"))
    assert not g.georeferenced and g.spacing == (1.0, 1.0)
    # a sidecar left by a georeferenced run goes when the file is rewritten in grid steps
    assert run("mesh", tmp_path / "h.npy", "-o", out, "--spacing", "30", "-q") == 0
    assert (tmp_path / "h.obj.georef.json").exists()
    assert run("mesh", tmp_path / "h.npy", "-o", out, "-q") == 0
    assert not (tmp_path / "h.obj.georef.json").exists()
    assert run("check", out, "--against", tmp_path / "h.npy") == 0


def test_one_level_with_lod(tmp_path):
    """M = 1 (a small grid, as `make demo`'s board run): the initial and the refined mesh are both level 0;
    --lod writes the refined one once (staging it twice made the outputs' commit fail)."""
    np.save(tmp_path / "h.npy", hills(12, 10))
    assert run("mesh", tmp_path / "h.npy", "-o", tmp_path / "h.obj", "--lod", tmp_path / "lod", "-q") == 0
    assert sorted(p.name for p in (tmp_path / "lod").iterdir()) == ["level-0.obj"]
    (lod, _), (final, _) = read_mesh(tmp_path / "lod" / "level-0.obj"), read_mesh(tmp_path / "h.obj")
    assert np.array_equal(lod.xy, final.xy) and np.array_equal(lod.tris, final.tris)


def test_npz_georeference_as_matplotlib_gives_it(tmp_path):
    """Jacksboro's convention: xmin..xmax and ymin..ymax are the cells' outer edges, row 0 at ymin."""
    z = hills(30, 40)
    d = 1 / 1200
    np.savez(tmp_path / "dem.npz", elevation=z, dx=d, dy=d, xmin=-84.5, xmax=-84.5 + 40 * d, ymin=36.7,
             ymax=36.7 - 30 * d)
    hf = load_heightfield(tmp_path / "dem.npz", key="elevation")
    assert hf.transform == (d, 0.0, -84.5, 0.0, -d, 36.7)
    g = georef.ground(hf)
    kx, ky = georef.metres_per_degree(36.7 - 15 * d)
    assert g.geographic and g.crs == "EPSG:4326" and g.spacing == pytest.approx((d * kx, d * ky), rel=1e-12)
    # an x extent of sample centres is fine, a y extent of 120 cells for 30 rows is not
    np.savez(tmp_path / "c.npz", elevation=z, dx=d, dy=d, xmin=-84.5, xmax=-84.5 + 39 * d, ymin=36.7,
             ymax=36.8)
    with pytest.raises(InputError, match="neither 30 nor 29 cells"):
        load_heightfield(tmp_path / "c.npz", key="elevation")
    # no xmax/ymax at all: xmin the west, ymin the south edge
    np.savez(tmp_path / "s.npz", elevation=z, dx=d, dy=d, xmin=-84.5, ymin=36.7)
    t = load_heightfield(tmp_path / "s.npz", key="elevation").transform
    assert t == pytest.approx((d, 0.0, -84.5, 0.0, -d, 36.7 + 30 * d))


def test_metres_per_degree_on_wgs84():
    # the series for WGS 84 (NGA): 111412.84 cos(lat) - 93.5 cos(3 lat) + 0.118 cos(5 lat) m per degree of
    # longitude, 111132.92 - 559.82 cos(2 lat) + 1.175 cos(4 lat) - 0.0023 cos(6 lat) of latitude, good to
    # about a millionth
    for lat in (0, 36.6, 60, 85):
        r = math.radians(lat)
        lon = 111412.84 * math.cos(r) - 93.5 * math.cos(3 * r) + 0.118 * math.cos(5 * r)
        lat_m = 111132.92 - 559.82 * math.cos(2 * r) + 1.175 * math.cos(4 * r) - 0.0023 * math.cos(6 * r)
        assert georef.metres_per_degree(lat) == pytest.approx((lon, lat_m), rel=1e-6)


def test_overrides_and_refusals(tmp_path, capsys):
    z = hills(20, 24)
    hf = from_array(z)
    g = georef.ground(georef.apply_overrides(hf, "2.5,0.5", "100,200"))
    assert g.spacing == (2.5, 0.5) and g.origin == (100.0, 200.0)
    assert g.map_xy(4, 2) == (110.0, 201.0)  # the grid's directions: x along columns, y down the rows
    degrees = Affine(1 / 1200, 0, 10.0, 0, -1 / 1200, 50.0)
    tif = geotiff(tmp_path / "g.tif", z, crs="EPSG:4326", transform=degrees)
    geo = load_heightfield(tif)
    g = georef.ground(georef.apply_overrides(geo, "30"))
    assert g.spacing == (30.0, 30.0) and g.map_unit == "degree"  # the coordinates stay degrees
    sheared = geotiff(tmp_path / "s.tif", z, transform=Affine(20.0, 5.0, 0.0, 0.0, -30.0, 0.0))
    assert run("mesh", sheared, "-o", tmp_path / "s.obj") != 0
    assert "sheared" in capsys.readouterr().err
    assert run("mesh", tif, "-o", tmp_path / "b.obj", "--spacing", "0,3") != 0
    assert "--spacing" in capsys.readouterr().err


def test_normal_metric_measures_slopes_per_ground_unit():
    """The refiner's E(T) with the cell size: an upper bound within 2^-15 relative of the float value,
    and a whole run within zeta by mesh_errors on the same cell (api.refine checks it too)."""
    rng = np.random.default_rng(5)
    z = rng.integers(0, 400, size=(9, 9)).astype(np.uint16)
    x, y = [0, 8, 2], [0, 3, 8]
    for spacing in ((1.0, 1.0), (3.0, 0.25), (75.0, 92.5)):
        e = native.tri_error(z, x, y, "normal", 1.0, spacing)
        mesh = api.Mesh(9, 9, np.column_stack([x, y]), [[0, 1, 2]])
        want = mesh_errors(mesh, z.astype(float), spacing=spacing).e_max_normal
        assert want <= e <= want * (1 + 2**-15) + 2**-16, spacing
    hf = georef.apply_overrides(from_array(hills(40, 50)), "30,45")
    rjob = api.refine(hf, 3, None, native.RefineParams(zeta=2.0))
    flat = api.refine(from_array(hills(40, 50)), 3, None, native.RefineParams(zeta=2.0))
    assert rjob.bound_met and mesh_errors(rjob.mesh, hf.values, spacing=(30, 45)).e_max_normal <= 2.0
    assert rjob.mesh.n_triangles > flat.mesh.n_triangles  # slopes are no longer 30-45 times steeper


def test_jacksboro_defaults_are_within_a_small_multiple_of_zeta():
    import matplotlib.cbook as cbook

    path = cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False)
    hf = api.load_input(str(path), key="elevation")
    g = georef.ground(hf)
    assert g.geographic and g.spacing == pytest.approx((74.57, 92.47), abs=0.01)
    result = api.mesh(hf)
    assert result.bound_met and result.errors.e_max_normal <= 1.0
    assert result.errors.e_max_vertical <= 1.5  # was 144 m with a cell of 1 (issue 19)


def test_glb_loads_in_trimesh_and_validates(tmp_path):
    import trimesh

    z = hills(30, 40)
    tif = geotiff(tmp_path / "dem.tif", z)
    out = tmp_path / "dem.glb"
    assert run("mesh", tif, "-o", out, "--zeta", "2", "-q") == 0
    hf = load_heightfield(tif)
    result = api.mesh(hf, api.MeshParams(refine=native.RefineParams(zeta=2.0)))
    mesh = result.mesh
    scene = trimesh.load(out)
    (tm,) = scene.geometry.values()
    east = 20.0 * mesh.xy[:, 0]
    north = -30.0 * mesh.xy[:, 1]
    want = np.column_stack([east, z[mesh.xy[:, 1], mesh.xy[:, 0]], -north]).astype(np.float32)
    assert np.array_equal(np.asarray(tm.vertices, dtype=np.float32), want)
    assert len(tm.faces) == mesh.n_triangles
    # front faces up (+Y): glTF's counter-clockwise winding seen from above
    v = np.asarray(tm.vertices)[np.asarray(tm.faces)]
    assert np.all(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])[:, 1] > 0)
    assert scene.metadata["wavemesh"]["crs"] == "EPSG:32617"
    validate_glb(out.read_bytes())


def validate_glb(data: bytes) -> None:
    """The rules of the glTF 2.0 specification a .glb must keep (container, chunks, accessors), checked
    here without trimesh."""
    magic, version, length = struct.unpack_from("<4sII", data)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    jlen, jtype = struct.unpack_from("<I4s", data, 12)
    assert jtype == b"JSON" and jlen % 4 == 0
    doc = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack_from("<I4s", data, 20 + jlen)
    assert btype == b"BIN\0" and blen % 4 == 0 and 28 + jlen + blen == len(data)
    binary = data[28 + jlen:]
    assert doc["asset"]["version"] == "2.0"
    assert doc["buffers"][0]["byteLength"] <= blen
    sizes = {5126: ("f", 4), 5125: ("I", 4), 5123: ("H", 2), 5121: ("B", 1)}
    comps = {"SCALAR": 1, "VEC3": 3}
    arrays = []
    for acc in doc["accessors"]:
        view = doc["bufferViews"][acc["bufferView"]]
        code, size = sizes[acc["componentType"]]
        n = acc["count"] * comps[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        assert start % size == 0 and start + n * size <= view.get("byteOffset", 0) + view["byteLength"]
        assert view.get("byteOffset", 0) + view["byteLength"] <= doc["buffers"][0]["byteLength"]
        a = np.frombuffer(binary, dtype="<" + code, count=n, offset=start).reshape(acc["count"], -1)
        assert np.all(np.isfinite(a))
        if "min" in acc:
            assert np.array_equal(a.min(axis=0), np.array(acc["min"], dtype=a.dtype))
            assert np.array_equal(a.max(axis=0), np.array(acc["max"], dtype=a.dtype))
        arrays.append(a)
    (prim,) = doc["meshes"][0]["primitives"]
    assert prim.get("mode", 4) == 4  # triangles
    pos = doc["accessors"][prim["attributes"]["POSITION"]]
    assert pos["type"] == "VEC3" and pos["componentType"] == 5126 and "min" in pos and "max" in pos
    idx = arrays[prim["indices"]]
    assert idx.size % 3 == 0 and idx.max() < pos["count"]


def test_render_states_the_exaggeration(tmp_path):
    z = hills(30, 40)
    tif = geotiff(tmp_path / "dem.tif", z)
    pictures = []
    for extra in ([], ["--exaggeration", "3"]):
        png = tmp_path / f"r{len(extra)}.png"
        assert run("mesh", tif, "-o", tmp_path / "m.obj", "--render", png, "-q", *extra) == 0
        pictures.append(png.read_bytes())
    assert pictures[0] != pictures[1]
    # `wavemesh render` places the mesh by its sidecar: the same true-aspect picture as `mesh --render`
    assert run("render", tmp_path / "m.obj", "-o", tmp_path / "again.png", "--title", "dem.tif") == 0
    assert (tmp_path / "again.png").read_bytes() == pictures[0]
    assert run("render", tmp_path / "m.obj", "-o", tmp_path / "bad.png", "--exaggeration", "-1") != 0
