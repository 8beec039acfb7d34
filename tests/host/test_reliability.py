"""Issue 13: outputs written whole or not at all, paths checked before any work, the messages that misled,
and the inputs once rejected at once (constant, bool, float16, 64-bit integers) decided one by one."""

import io
import json
import os
import resource
import subprocess
import sys

import numpy as np
import pytest
import tifffile
from wavemesh.check import check_mesh
from wavemesh.errors import InputError
from wavemesh.harness import run_cli
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array, load_heightfield
from wavemesh.io.meshread import read_mesh
from wavemesh.io.outputs import Outputs


def wavemesh(*args, fsize=None, memory=None, cwd=None):
    """The command in a subprocess (what a user sees on stderr, GDAL's and numpy's lines included),
    with a file size limit (ulimit -f, bytes) and an address space limit (ulimit -v, bytes) when given."""
    def limit():
        for what, value in ((resource.RLIMIT_FSIZE, fsize), (resource.RLIMIT_AS, memory)):
            if value is not None:
                resource.setrlimit(what, (value, value))

    return subprocess.run([sys.executable, "-m", "wavemesh", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=300, preexec_fn=limit)


def one_error(stderr: str) -> str:
    """The error line of a failed run whose stderr holds nothing but ``error:`` and ``hint:`` lines."""
    lines = stderr.splitlines()
    assert lines and lines[0].startswith("error: "), stderr
    assert all(line.startswith("hint: ") for line in lines[1:]), stderr
    return lines[0]


def entries(folder) -> list[str]:
    return sorted(os.listdir(folder))


@pytest.fixture(scope="module")
def terrain(tmp_path_factory):
    """A 129 x 129 height field whose outputs run to some hundred KiB.  The native library is built
    here if it has to be (not inside a run under a file size limit)."""
    from wavemesh.refine import native

    native.load()
    path = tmp_path_factory.mktemp("in") / "t.npy"
    np.save(path, synth.make("ball", 129) + synth.make("f2", 129))
    return path


# --- atomic outputs ------------------------------------------------------------------------------


def test_all_outputs_or_none_under_a_file_size_limit(tmp_path, terrain):
    """ulimit -f smaller than the mesh: one error line, and nothing at all in the output folder."""
    out = tmp_path / "out"
    out.mkdir()
    args = ("mesh", terrain, "-o", out / "m.obj", "--lod", out / "lod", "--report", out / "m.json",
            "--render", out / "m.png", "--zeta", "0.05")
    r = wavemesh(*args, fsize=20_000)
    assert r.returncode == 2
    assert "File too large" in one_error(r.stderr) and "m.obj" in r.stderr
    assert entries(out) == []
    # the same run without the limit writes every file and nothing else
    r = wavemesh(*args)
    assert r.returncode == 0, r.stderr
    assert entries(out) == ["lod", "m.json", "m.obj", "m.png"]
    assert os.path.getsize(out / "m.obj") > 20_000
    assert json.loads((out / "m.json").read_text())["lod"]


def test_a_failed_run_keeps_the_files_it_would_have_replaced(tmp_path, terrain):
    old = tmp_path / "m.obj"
    old.write_text("# the user's own file\n")
    r = wavemesh("mesh", terrain, "-o", old, "--zeta", "0.05", fsize=20_000)
    assert r.returncode == 2
    assert old.read_text() == "# the user's own file\n"
    assert entries(tmp_path) == ["m.obj"]


def test_output_paths_checked_before_any_work(tmp_path, terrain):
    # a report that cannot be written: refused before the mesh is made, no mesh left behind
    for report, why in ((tmp_path / "no" / "r.json", "does not exist"), ("/proc/r.json", "not writable")):
        rc, _, err = run_cli("mesh", str(terrain), "-o", str(tmp_path / "m.obj"), "--report", str(report))
        assert rc == 2 and why in one_error(err)
        assert entries(tmp_path) == []
    (tmp_path / "d.obj").mkdir()
    rc, _, err = run_cli("mesh", str(terrain), "-o", str(tmp_path / "d.obj"))
    assert rc == 2 and "is a directory" in one_error(err)
    m = str(tmp_path / "m.obj")
    rc, _, err = run_cli("mesh", str(terrain), "-o", m, "--lod", m)
    assert rc == 2 and "--lod" in one_error(err)
    rc, _, err = run_cli("check", str(tmp_path / "absent.obj"), "--against", str(terrain), "--report",
                         "/proc/c.json")
    assert rc == 2 and "c.json" in one_error(err)  # the report's path, not the missing mesh
    assert entries(tmp_path) == ["d.obj"]


def test_a_failure_late_in_the_run_leaves_nothing(tmp_path, terrain, monkeypatch):
    """The picture fails after the mesh, the levels and the report were written: none of them stays."""
    from wavemesh.check import render

    def broken(*a, **k):
        raise InputError("cannot draw")

    monkeypatch.setattr(render, "render_mesh", broken)
    rc, _, err = run_cli("mesh", str(terrain), "-o", str(tmp_path / "m.obj"), "--lod", str(tmp_path / "lod"),
                         "--report", str(tmp_path / "m.json"), "--render", str(tmp_path / "m.png"))
    assert rc == 2 and one_error(err) == "error: cannot draw"
    assert entries(tmp_path) == []


def test_synth_and_render_write_whole_files(tmp_path):
    r = wavemesh("synth", "ball", "-o", tmp_path / "b.npy", "--size", "257", fsize=4096)
    assert r.returncode == 2 and "b.npy" in one_error(r.stderr)
    assert entries(tmp_path) == []
    assert run_cli("synth", "ball", "-o", str(tmp_path / "b.npy"), "--size", "33")[0] == 0
    assert run_cli("mesh", str(tmp_path / "b.npy"), "-o", str(tmp_path / "b.obj"), "-q")[0] == 0
    assert run_cli("render", str(tmp_path / "b.obj"), "-o", str(tmp_path / "b.png"))[0] == 0
    assert entries(tmp_path) == ["b.npy", "b.obj", "b.png"]


def test_outputs_move_companions_and_clear_stale_ones(tmp_path):
    (tmp_path / "m.obj.side").write_text("stale")
    (tmp_path / "n.obj.side").write_text("stale")
    with Outputs() as out:
        m = out.path(tmp_path / "m.obj", (".side",))
        m.write_text("mesh m")
        m.with_name(m.name + ".side").write_text("fresh")
        out.path(tmp_path / "n.obj", (".side",)).write_text("mesh n")  # wrote no companion
        out.path(tmp_path / "new" / "sub" / "l.obj").write_text("level")
        assert entries(tmp_path) == [e for e in entries(tmp_path) if e.startswith(".wavemesh-partial-")] + [
            "m.obj.side", "n.obj.side"]
    assert (tmp_path / "m.obj.side").read_text() == "fresh"
    assert not (tmp_path / "n.obj.side").exists()
    assert (tmp_path / "new" / "sub" / "l.obj").read_text() == "level"
    assert entries(tmp_path) == ["m.obj", "m.obj.side", "n.obj", "new"]


# --- messages ----------------------------------------------------------------------------------------


def test_garbage_tiff_gives_one_error_line(tmp_path):
    """A float32 TIFF with a signalling NaN once printed numpy's cast warning before the error line."""
    a = np.ones((5, 6), np.float32)
    a.view(np.uint32)[2, 3] = 0x7F800001  # a signalling NaN
    tifffile.imwrite(tmp_path / "g.tif", a)
    r = wavemesh("mesh", tmp_path / "g.tif", "-o", tmp_path / "g.obj")
    assert r.returncode == 2 and "NaN" in one_error(r.stderr)
    np.save(tmp_path / "s.npy", a)
    r = wavemesh("mesh", tmp_path / "s.npy", "-o", tmp_path / "s.obj")
    assert r.returncode == 2 and "NaN" in one_error(r.stderr)
    # and random garbage named .tif
    (tmp_path / "r.tif").write_bytes(b"II*\x00" + bytes(range(256)) * 4)
    r = wavemesh("mesh", tmp_path / "r.tif", "-o", tmp_path / "r.obj")
    assert r.returncode == 2 and "r.tif" in one_error(r.stderr)


@pytest.mark.parametrize("rows", [1_660_944_389, 16_777_221])
def test_a_raster_claiming_billions_of_samples_is_refused_before_reading(tmp_path, rows):
    """300 bytes of TIFF saying 6 x 1.6e9 samples once took GDAL 11 GB and minutes, 6 x 16777221 took
    3.7 GB with --fill nearest (found by the fuzzer)."""
    tifffile.imwrite(tmp_path / "h.tif", np.zeros((8, 6), np.uint8))
    data = bytearray((tmp_path / "h.tif").read_bytes())
    ifd = int.from_bytes(data[4:8], "little")
    for k in range(int.from_bytes(data[ifd:ifd + 2], "little")):
        entry = ifd + 2 + 12 * k
        if int.from_bytes(data[entry:entry + 2], "little") == 257:  # ImageLength, a LONG in place
            data[entry + 2:entry + 4] = (4).to_bytes(2, "little")
            data[entry + 8:entry + 12] = rows.to_bytes(4, "little")
    (tmp_path / "h.tif").write_bytes(bytes(data))
    r = wavemesh("mesh", tmp_path / "h.tif", "-o", tmp_path / "h.obj", "--fill", "nearest", memory=3 << 30)
    assert r.returncode == 2 and f"6 x {rows} samples; wavemesh meshes at most 32767" in one_error(r.stderr)
    # in tiles (as `wavemesh mesh` meshes a grid this large by default): read window by window, the first
    # window's read fails: one error line, not rasterio's traceback
    r = wavemesh("mesh", tmp_path / "h.tif", "-o", tmp_path / "h.obj", "--tile", "513", memory=3 << 30)
    assert r.returncode == 2 and "h.tif: TIFF data is corrupt" in one_error(r.stderr)


def test_a_pgm_header_beyond_any_grid_is_refused(tmp_path):
    """The readers fuzzer's P2 header "0 2222...225 8" (a height of 126 digits, no samples) ended in
    numpy's ValueError, not an error line."""
    (tmp_path / "h.pgm").write_bytes(b"P2\n0 " + b"2" * 125 + b"5 8\n")
    r = wavemesh("mesh", tmp_path / "h.pgm", "-o", tmp_path / "h.obj")
    assert r.returncode == 2 and "says 0 x 2222" in one_error(r.stderr)
    assert "wavemesh meshes at most 32767 per side" in r.stderr


def test_library_warnings_stay_off_stderr(tmp_path):
    header = "{'descr': '<i2', 'fortran_order': False, 'shape': (3L, 4L), }"  # as Python 2 wrote it
    header = header.ljust(117) + "\n"
    magic = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little")
    (tmp_path / "py2.npy").write_bytes(magic + header.encode() + np.arange(12, dtype="<i2").tobytes())
    r = wavemesh("mesh", tmp_path / "py2.npy", "-o", tmp_path / "p.obj", "-q")
    assert r.returncode == 0 and r.stderr == ""


def test_npz_array_names_stay_on_one_line(tmp_path):
    buf = io.BytesIO()
    np.savez(buf, **{"a\nb": np.zeros((3, 3)), "c": np.ones((3, 3))})
    (tmp_path / "n.npz").write_bytes(buf.getvalue())
    rc, _, err = run_cli("mesh", str(tmp_path / "n.npz"), "-o", str(tmp_path / "n.obj"))
    assert rc == 2 and "('a b', c)" in one_error(err)  # shown on one line, quoted


def test_negative_crop_is_judged_not_misparsed(tmp_path, terrain):
    rc, _, err = run_cli("mesh", str(terrain), "-o", str(tmp_path / "m.obj"), "--crop", "-5,0,10,10")
    line = one_error(err)
    assert rc == 2 and "--crop -5,0,10,10 does not fit" in line and "usage" not in err
    rc, _, err = run_cli("mesh", str(terrain), "-o", str(tmp_path / "m.obj"), "--crop")
    assert rc == 2 and "expected one argument" in one_error(err)  # a missing value is still that


@pytest.mark.parametrize("url, what", [("socket://127.0.0.1:99999", "port '99999' is not a TCP port number"),
                                       ("socket://127.0.0.1", "no TCP port given"),
                                       ("rfc2217://localhost:x", "port 'x' is not a TCP port number")])
def test_bad_port_number(tmp_path, terrain, url, what):
    rc, _, err = run_cli("stream", str(terrain), "-o", str(tmp_path / "m.obj"), "--port", url)
    assert rc == 2 and one_error(err) == f"error: --port {url}: {what}"


@pytest.mark.parametrize("z", ["nan", "inf", "0", "-2"])
def test_render_refuses_a_bad_exaggeration(tmp_path, z):
    np.save(tmp_path / "b.npy", synth.make("ball", 17))
    assert run_cli("mesh", str(tmp_path / "b.npy"), "-o", str(tmp_path / "b.obj"), "-q")[0] == 0
    rc, _, err = run_cli("render", str(tmp_path / "b.obj"), "-o", str(tmp_path / "b.png"), "--zscale", z)
    line = one_error(err)
    assert rc == 2 and ("out of range" in line if z in ("0", "-2") else "not a finite number" in line), line
    assert not (tmp_path / "b.png").exists()


# --- inputs once rejected at once ------------------------------------------------------------------


def _mesh_of(tmp_path, array, *opts):
    np.save(tmp_path / "in.npy", array)
    rc, _, err = run_cli("mesh", str(tmp_path / "in.npy"), "-o", str(tmp_path / "m.obj"), "-q", *opts)
    assert rc == 0, err
    mesh, z = read_mesh(tmp_path / "m.obj")
    assert check_mesh(mesh).valid
    return mesh, z


def test_a_constant_field_is_two_triangles(tmp_path):
    mesh, z = _mesh_of(tmp_path, np.full((20, 30), 7.25), "--zeta", "0")
    assert mesh.n_triangles == 2 and np.all(z == 7.25)


def test_bool_heights_are_zero_and_one(tmp_path):
    a = (np.indices((17, 19)).sum(axis=0) % 5 == 0)
    mesh, z = _mesh_of(tmp_path, a, "--zeta", "0", "--metric", "vertical")
    np.testing.assert_array_equal(z, mesh.z(a.astype(np.float64)))
    assert set(np.unique(z)) <= {0.0, 1.0}
    hf = from_array(a)
    assert hf.lossless and hf.scale == 1.0


def test_float16_heights_are_kept_exactly(tmp_path):
    a = (np.random.default_rng(7).random((18, 21)) * 500 - 250).astype(np.float16)
    mesh, z = _mesh_of(tmp_path, a)
    np.testing.assert_array_equal(z, mesh.z(a.astype(np.float64)))


def test_64_bit_integers_exact_or_refused(tmp_path):
    ok = np.full((12, 12), 1 << 62, np.int64)
    ok[3, 4] = -(1 << 62)
    ok[5, 5] = (1 << 53) + 2  # 53 significant bits
    mesh, z = _mesh_of(tmp_path, ok)
    assert [int(v) for v in z] == [int(ok[y, x]) for x, y in mesh.xy]
    bad = ok.copy()
    bad[7, 2] = (1 << 62) + 1
    np.save(tmp_path / "bad.npy", bad)
    with pytest.raises(InputError, match=r"1 integer heights have more than 53 significant bits.*row 7, col"):
        load_heightfield(str(tmp_path / "bad.npy"))
    for extreme, dtype in (((1 << 63) - 1, np.int64), ((1 << 64) - 1, np.uint64)):
        with pytest.raises(InputError, match="53 significant bits"):
            from_array(np.full((3, 3), extreme, dtype))
    assert from_array(np.array([[-(1 << 63), 0], [0, 0]], np.int64)).values[0, 0] == -(2.0 ** 63)


def test_a_corrupt_raster_is_one_error_whole_or_by_windows(tmp_path):
    """A GeoTIFF whose header reads but whose strips do not: the whole read (an untiled run) and the
    window read (a tiled one, wavemesh.tiles) give the same error line."""
    import rasterio
    from wavemesh.io import readers

    path = tmp_path / "c.tif"
    with rasterio.open(path, "w", driver="GTiff", width=64, height=64, count=1, dtype="float32",
                       compress="deflate", transform=rasterio.Affine(1, 0, 0, 0, -1, 64)) as ds:
        ds.write(np.random.default_rng(1).random((1, 64, 64)).astype(np.float32))
    data = bytearray(path.read_bytes())
    for i in range(200, len(data) - 400):  # the compressed strips, not the header or its tags
        data[i] ^= 0x5A
    path.write_bytes(bytes(data))
    said = []
    for read in (lambda: load_heightfield(str(path)),
                 lambda: readers.read_raster_window(str(path), 0, 0, 64, 64)):
        with pytest.raises(InputError) as e:
            read()
        said.append(str(e.value))
    assert said[0] == said[1] and said[0].startswith(f"cannot read {path}: TIFF data is corrupt ("), said
