"""The mesh files terrain users expect: a georeferenced grid in metres (or the CRS's units), binary STL,
a watertight solid (--base), per-vertex normals, a normal map; one registry of the formats.  Each result
is checked by an independent reader (trimesh, PIL, raw parsing here) or an independent computation."""

import json
import math
import struct
from pathlib import Path

import matplotlib.cbook
import numpy as np
import pytest
import trimesh
from PIL import Image
from wavemesh import cli
from wavemesh.io import meshio

ROOT = Path(__file__).resolve().parents[2]
JACKSBORO = matplotlib.cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False)


def run(*args) -> int:
    return cli.main([str(a) for a in args])


def obj_lines(path, kw: str) -> np.ndarray:
    """The numbers of every ``kw`` line of an OBJ file, read here (not by wavemesh)."""
    lines = [line for line in open(path) if line.startswith(kw + " ")]
    return np.array([[float(t) for t in line.split()[1:4]] for line in lines])


def obj_faces(path) -> np.ndarray:
    return np.array([[int(t.split("/")[0]) - 1 for t in line.split()[1:4]]
                     for line in open(path) if line.startswith("f ")])


@pytest.fixture(scope="module")
def jacksboro(tmp_path_factory):
    """Jacksboro meshed once in metres (every second sample, zeta 5: fast) with normals; and its grid."""
    d = tmp_path_factory.mktemp("jacksboro")
    out = d / "j.obj"
    assert run("mesh", JACKSBORO, "--key", "elevation", "--decimate", "2", "--zeta", "5", "-o", out,
               "--normals", "--report", d / "j.json", "-q") == 0
    return d, out, np.load(JACKSBORO)["elevation"][::2, ::2]


def test_jacksboro_obj_in_metres(jacksboro):
    d, out, z = jacksboro
    v = obj_lines(out, "v")
    span = np.ptp(v, axis=0)
    # 0.335 x 0.2867 degrees at latitude 36.6: independently, a sphere of the mean Earth radius
    # (6371 km) gives 111.2 km a degree north and cos(36.6) of it east; the ellipsoid differs by < 1 %
    deg = math.pi / 180 * 6371000.0
    lat = 36.59
    assert span[0] == pytest.approx(400 * (1 / 1200) * deg * math.cos(math.radians(lat)), rel=0.01)
    assert span[1] == pytest.approx(342 * (1 / 1200) * deg, rel=0.01)
    assert 29000 < span[0] < 31000 and 31000 < span[1] < 33000  # about 30 km by 32 km
    # x east from sample (0, 0) (the north-west corner), y north: all of y <= 0; z the DEM's metres
    assert v[:, 0].min() == 0.0 and v[:, 1].max() == 0.0
    assert set(np.unique(v[:, 2])) <= set(np.unique(z.astype(float)))
    assert v[:, 2].min() == z.min() and v[:, 2].max() == z.max()
    side = json.loads(out.with_name("j.obj.georef.json").read_text())
    assert side["units"] == "metres" and side["vertices"] == "ground"
    report = json.loads((d / "j.json").read_text())
    assert report["mesh_files"]["units"] == "metres" and report["mesh_files"]["normals"] is True
    assert report["mesh_files"]["frame"] == "x east, y north, z up in metres from sample (0, 0)"
    # the faces are counter-clockwise seen from above: every triangle's normal points up
    f = obj_faces(out)
    c = v[f]
    assert (np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])[:, 2] > 0).all()
    # `wavemesh check` places it back on the grid by the sidecar
    assert run("check", out, "--against", JACKSBORO, "--key", "elevation", "--decimate", "2", "-q") == 0


def test_jacksboro_in_crs_units(tmp_path):
    out = tmp_path / "d.ply"
    assert run("mesh", JACKSBORO, "--key", "elevation", "--decimate", "4", "--zeta", "10", "-o", out,
               "--units", "crs", "-q") == 0
    m = trimesh.load(out, process=False)
    lon, lat = np.ptp(m.vertices[:, 0]), np.ptp(m.vertices[:, 1])
    assert lon == pytest.approx(400 / 1200, rel=1e-9) and lat == pytest.approx(340 / 1200, rel=1e-9)
    assert m.vertices[:, 0].min() == pytest.approx(-84.41333333, abs=1e-6)
    assert json.loads((tmp_path / "d.ply.georef.json").read_text())["units"] == "crs"
    assert run("check", out, "--against", JACKSBORO, "--key", "elevation", "--decimate", "4", "-q") == 0


def test_normals_present_and_unit(jacksboro):
    d, out, _ = jacksboro
    v, n = obj_lines(out, "v"), obj_lines(out, "vn")
    assert len(n) == len(v)
    assert np.abs(np.linalg.norm(n, axis=1) - 1).max() < 1e-6
    assert (n[:, 2] > 0).all()  # terrain: every normal has an upward part
    # each face refers to its vertex's own normal (f i//i)
    assert all(a.split("//")[0] == a.split("//")[1] for line in open(out) if line.startswith("f ")
               for a in line.split()[1:])


def plane(tmp_path, w=33, h=21, a=0.5, b=-0.25):
    z = a * np.arange(w)[None, :] + b * np.arange(h)[:, None] + 10.0
    np.save(tmp_path / "plane.npy", z)
    return tmp_path / "plane.npy", z


def test_normals_of_a_plane_in_every_format(tmp_path):
    """On a plane z = 0.5 col - 0.25 row (grid steps, no georeference: x = col, y = row) every vertex
    normal is the plane's, (-0.5, 0.25, 1) normalised, whatever the triangles' sizes."""
    src, _ = plane(tmp_path)
    want = np.array([-0.5, 0.25, 1.0]) / math.sqrt(1.3125)
    for ext in (".obj", ".ply", ".glb"):
        out = tmp_path / f"p{ext}"
        assert run("mesh", src, "-o", out, "--normals", "--stage", "initial", "-q") == 0
        if ext == ".obj":
            n = obj_lines(out, "vn")
        elif ext == ".ply":
            data = out.read_bytes()
            head, body = data.split(b"end_header\n", 1)
            assert b"property float nx" in head
            nv = int(head.split(b"element vertex ")[1].split(b"\n")[0])
            rec = np.frombuffer(body[: nv * 36], dtype=[("p", "<f8", 3), ("n", "<f4", 3)])
            n = rec["n"].astype(float)
        else:  # glTF's NORMAL attribute, in its frame (x east, y up, z south; here x = col, z = row)
            scene = trimesh.load(out, process=False)
            gm = next(iter(scene.geometry.values()))
            raw = out.read_bytes()
            doc = json.loads(raw[20: 20 + struct.unpack("<I", raw[12:16])[0]])
            assert "NORMAL" in doc["meshes"][0]["primitives"][0]["attributes"]
            g = np.asarray(gm.vertex_normals)
            n = np.column_stack([g[:, 0], -g[:, 2], g[:, 1]])  # back to (east, north, up); north = -row
            n[:, 1] = -n[:, 1]  # (col, row, up)
        assert np.allclose(n, want, atol=1e-6), ext


def test_stl_reads_back_and_base_is_watertight(tmp_path):
    out, solid = tmp_path / "j.stl", tmp_path / "solid.stl"
    args = ("--key", "elevation", "--decimate", "4", "--zeta", "10", "-q")
    assert run("mesh", JACKSBORO, "-o", out, *args) == 0
    assert run("mesh", JACKSBORO, "-o", tmp_path / "j.obj", *args) == 0
    surface = trimesh.load(out)
    v, f = obj_lines(tmp_path / "j.obj", "v"), obj_faces(tmp_path / "j.obj")
    assert len(surface.faces) == len(f)
    assert np.allclose(surface.bounds, [v.min(axis=0), v.max(axis=0)], atol=0.01)
    assert not surface.is_watertight  # a surface has a border
    assert run("mesh", JACKSBORO, "-o", solid, "--base", "50", *args) == 0
    s = trimesh.load(solid)
    assert s.is_watertight and s.is_winding_consistent and s.volume > 0  # outward normals: positive volume
    assert s.bounds[0][2] == pytest.approx(v[:, 2].min() - 50)
    # the volume: above the bottom, the surface's (its triangles' prisms down to the bottom)
    c = v[f]
    area = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])[:, 2] / 2
    floor = v[:, 2].min() - 50
    assert s.volume == pytest.approx(float(np.sum(area * (c[:, :, 2].mean(axis=1) - floor))), rel=1e-5)


def test_base_in_obj_every_edge_twice(tmp_path):
    """Counted here, in the OBJ file's own indices: every edge of the solid is in exactly two triangles,
    once each way (a closed, consistently oriented surface)."""
    src, _ = plane(tmp_path)
    out = tmp_path / "s.obj"
    assert run("mesh", src, "-o", out, "--base", "3", "--normals", "-q") == 0
    f = obj_faces(out)
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    keys, counts = np.unique(directed, axis=0, return_counts=True)
    assert (counts == 1).all()
    assert len(np.unique(np.sort(directed, axis=1), axis=0)) * 2 == len(directed)
    m = trimesh.load(tmp_path / "s.obj", process=True)
    assert m.is_watertight and m.volume > 0


def test_normal_map(tmp_path):
    src, z = plane(tmp_path)
    out = tmp_path / "n.png"
    assert run("mesh", src, "-o", tmp_path / "p.obj", "--normal-map", out, "-q") == 0
    img = Image.open(out)
    assert img.mode == "RGB" and img.size == (33, 21)
    # z = 0.5 x - 0.25 row; up the picture is minus a row: the slope up the picture is +0.25
    n = np.array([-0.5, -0.25, 1.0]) / math.sqrt(1.3125)
    assert (np.asarray(img) == np.rint((n + 1) / 2 * 255)).all()
    # Jacksboro: the grid's size; slopes over the ground spacing (metres, here from a sphere of radius
    # 6371 km: the ellipsoid's differ by < 1 %), not over grid steps
    out = tmp_path / "j.png"
    assert run("mesh", JACKSBORO, "--key", "elevation", "--decimate", "4", "--zeta", "20", "-o",
               tmp_path / "j.obj", "--normal-map", out, "-q") == 0
    img = np.asarray(Image.open(out)).astype(int)
    assert img.shape == (86, 101, 3)
    z = np.load(JACKSBORO)["elevation"][::4, ::4].astype(float)
    deg = math.pi / 180 * 6371000.0 * 4 / 1200
    dx, dy = deg * math.cos(math.radians(36.59)), deg
    for r, c in ((40, 50), (10, 90), (70, 5)):
        n = np.array([-(z[r, c + 1] - z[r, c - 1]) / (2 * dx), (z[r + 1, c] - z[r - 1, c]) / (2 * dy), 1.0])
        n /= np.linalg.norm(n)
        assert np.abs(img[r, c] - (n + 1) / 2 * 255).max() <= 1.5, (r, c)


@pytest.mark.parametrize("opts, says", [
    (("--base", "-1"), "--base -1.0"),
    (("--base", "nan"), "--base: nan is not a finite number"),
    (("--base", "0"), "--base 0.0"),
    (("--units", "feet"), "--units: invalid choice"),
    (("--normals", "-o", "x.stl"), "--normals: a .stl file"),
    (("--units", "crs", "-o", "x.glb"), "--units crs: a .glb"),
    (("--local", "--units", "metres"), "--local"),
    (("--normal-map", "n.jpg"), "unknown extension '.jpg'"),
])
def test_bad_options_one_error_nothing_written(tmp_path, capsys, opts, says):
    src, _ = plane(tmp_path)
    before = sorted(tmp_path.iterdir())
    code = run("mesh", src, "-o", tmp_path / "m.obj", *[tmp_path / o if o.startswith(("x.", "n.")) else o
                                                        for o in opts])
    err = capsys.readouterr().err.splitlines()
    assert code != 0 and err[0].startswith("error: ") and says in err[0], err
    assert len([line for line in err if line.startswith("error:")]) == 1
    assert sorted(tmp_path.iterdir()) == before


def test_base_refused_with_holes(tmp_path, capsys):
    z = np.full((20, 20), 5.0)
    z[5:9, 5:9] = np.nan
    np.save(tmp_path / "h.npy", z)
    assert run("mesh", tmp_path / "h.npy", "-o", tmp_path / "h.stl", "--nodata", "hole", "--base", "1") != 0
    assert "--base" in capsys.readouterr().err and not (tmp_path / "h.stl").exists()


def test_one_registry_of_formats(capsys):
    """The formats live in meshio.FORMATS: `-o`'s help and README's table are made from it."""
    assert meshio.MESH_SUFFIXES == (".obj", ".ply", ".stl", ".glb")
    with pytest.raises(SystemExit):
        cli.main(["mesh", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert " ".join(meshio.formats_help().split()) in text
    readme = (ROOT / "README.md").read_text()
    assert meshio.formats_table() in readme, "README's format table is stale: paste meshio.formats_table()"
