"""The `wavemesh` command end to end, as a user runs it, bad input included."""

import json
import subprocess
import sys

import numpy as np
import pytest
from wavemesh import api
from wavemesh.check import check_mesh
from wavemesh.cli import main
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.io.meshread import read_mesh


def wavemesh(*args, cwd=None):
    """Run the installed command in a subprocess: what a user sees, tracebacks included."""
    return subprocess.run([sys.executable, "-m", "wavemesh", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


@pytest.fixture
def parabolic(tmp_path):
    path = tmp_path / "f2.npy"
    np.save(path, synth.f2())
    return path


def test_mesh_writes_mesh_report_and_picture(tmp_path, parabolic):
    out, rep, png = tmp_path / "m.obj", tmp_path / "r.json", tmp_path / "m.png"
    r = wavemesh("mesh", parabolic, "-o", out, "--levels", "4", "--stage", "initial", "--report", rep,
                 "--render", png)
    assert r.returncode == 0, r.stderr
    assert "153 vertices, 256 triangles" in r.stdout
    mesh, z = read_mesh(out)
    assert (mesh.n_vertices, mesh.n_triangles) == (153, 256)
    job = api.triangulate(from_array(synth.f2()), 4)
    assert mesh.same_as(job.mesh)
    np.testing.assert_array_equal(z, mesh.z(synth.f2()))
    report = json.loads(rep.read_text())
    assert report["initial"]["vertices"] == 153 and report["initial"]["triangles"] == 256
    assert report["input"]["width"] == 128 and report["errors"]["e_max_normal"] >= 0
    assert png.stat().st_size > 1000


def test_mesh_ply_and_check_agree(tmp_path):
    values = synth.ball()
    np.save(tmp_path / "ball.npy", values)
    assert main(["mesh", str(tmp_path / "ball.npy"), "-o", str(tmp_path / "b.ply"), "-q"]) == 0
    mesh, _ = read_mesh(tmp_path / "b.ply")
    assert check_mesh(mesh).valid
    assert main(["check", str(tmp_path / "b.ply"), "--against", str(tmp_path / "ball.npy"),
                 "--report", str(tmp_path / "c.json")]) == 0
    report = json.loads((tmp_path / "c.json").read_text())
    assert report["valid"] and report["triangles"] == mesh.n_triangles


def test_check_rejects_a_broken_mesh(tmp_path, parabolic):
    out = tmp_path / "m.obj"
    assert main(["mesh", str(parabolic), "-o", str(out), "-q"]) == 0
    lines = out.read_text().splitlines()
    last_face = max(i for i, line in enumerate(lines) if line.startswith("f "))
    (tmp_path / "holed.obj").write_text("\n".join(lines[:last_face] + lines[last_face + 1:]) + "\n")
    r = wavemesh("check", tmp_path / "holed.obj", "--against", parabolic)
    assert r.returncode == 1
    assert "NOT a proper triangulation" in r.stdout
    assert r.stderr.startswith("error:") and "Traceback" not in r.stderr


def test_check_rejects_wrong_heights(tmp_path, parabolic):
    out = tmp_path / "m.obj"
    assert main(["mesh", str(parabolic), "-o", str(out), "-q"]) == 0
    text = out.read_text().replace("v 0 0 ", "v 0 0 1", 1)
    (tmp_path / "z.obj").write_text(text)
    assert main(["check", str(tmp_path / "z.obj"), "--against", str(parabolic), "-q"]) == 1


def test_fill_nearest_makes_nan_input_work(tmp_path):
    values = synth.f5()
    values[10:20, 30:40] = np.nan
    np.save(tmp_path / "holes.npy", values)
    r = wavemesh("mesh", tmp_path / "holes.npy", "-o", tmp_path / "m.obj")
    assert r.returncode != 0 and r.stderr.startswith("error:") and "--fill" in r.stderr
    r = wavemesh("mesh", tmp_path / "holes.npy", "-o", tmp_path / "m.obj", "--fill", "nearest")
    assert r.returncode == 0, r.stderr


def test_render_command(tmp_path, parabolic):
    out = tmp_path / "m.obj"
    assert main(["mesh", str(parabolic), "-o", str(out), "-q"]) == 0
    r = wavemesh("render", out, "-o", tmp_path / "top.png", "--view", "top")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "top.png").stat().st_size > 1000


def test_synth_command(tmp_path):
    assert main(["synth", "box", "-o", str(tmp_path / "box.npy"), "--size", "64"]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "box.npy"), synth.box(64))


def bad_inputs(tmp_path):
    np.save(tmp_path / "ok.npy", synth.f2())
    np.save(tmp_path / "line.npy", np.arange(10.0))
    np.save(tmp_path / "empty.npy", np.zeros((0, 5)))
    np.save(tmp_path / "nan.npy", np.full((4, 4), np.nan))
    data = (tmp_path / "ok.npy").read_bytes()
    (tmp_path / "cut.npy").write_bytes(data[: len(data) // 2])
    (tmp_path / "junk.xyz").write_bytes(b"\x00\x01garbage" * 10)
    (tmp_path / "junk.npy").write_bytes(b"garbage")
    (tmp_path / "text.png").write_text("not a png")
    ok = tmp_path / "ok.npy"
    o = str(tmp_path / "o.obj")
    return {
        "missing file": ["mesh", tmp_path / "nope.npy", "-o", o],
        "truncated": ["mesh", tmp_path / "cut.npy", "-o", o],
        "1-D": ["mesh", tmp_path / "line.npy", "-o", o],
        "empty": ["mesh", tmp_path / "empty.npy", "-o", o],
        "all NaN": ["mesh", tmp_path / "nan.npy", "-o", o],
        "unknown format": ["mesh", tmp_path / "junk.xyz", "-o", o],
        "not an npy": ["mesh", tmp_path / "junk.npy", "-o", o],
        "corrupt png": ["mesh", tmp_path / "text.png", "-o", o],
        "bad levels": ["mesh", ok, "-o", o, "--levels", "0"],
        "levels not a number": ["mesh", ok, "-o", o, "--levels", "x"],
        "negative tau": ["mesh", ok, "-o", o, "--tau", "-1"],
        "bad output extension": ["mesh", ok, "-o", tmp_path / "o.stp"],
        "output dir missing": ["mesh", ok, "-o", tmp_path / "no" / "o.obj"],
        "bad fill": ["mesh", ok, "-o", o, "--fill", "sideways"],
        "negative zeta": ["mesh", ok, "-o", o, "--zeta", "-1"],
        "negative max-hole": ["mesh", ok, "-o", o, "--nodata", "hole", "--max-hole", "-3"],
        "bad metric": ["mesh", ok, "-o", o, "--metric", "sideways"],
        "too many iterations": ["mesh", ok, "-o", o, "--iterations", "5"],
        "alpha above 1": ["mesh", ok, "-o", o, "--alpha", "2"],
        "capacity too small": ["mesh", ok, "-o", o, "--zeta", "0", "--capacity", "300"],
        "lod is a file": ["mesh", ok, "-o", o, "--lod", ok],
        "check missing mesh": ["check", tmp_path / "none.obj", "--against", ok],
        "check garbage mesh": ["check", tmp_path / "junk.xyz", "--against", ok],
        "no command": [],
        "unknown command": ["frobnicate"],
    }


def test_bad_input_gives_one_line_and_no_traceback(tmp_path):
    for name, args in bad_inputs(tmp_path).items():
        r = wavemesh(*args)
        assert r.returncode != 0, name
        assert "Traceback" not in r.stderr, (name, r.stderr)
        errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
        assert len(errors) == 1, (name, r.stderr)
        assert not (tmp_path / "o.obj").exists(), name
        if name == "not an npy":  # not numpy's advice to load it as a pickle
            assert "not a .npy file" in errors[0] and "pickle" not in errors[0], errors
        if name == "negative max-hole":  # what is wrong, not what the option does
            assert errors[0] == "error: --max-hole -3 is out of range", errors


def test_module_and_version():
    r = wavemesh("--version")
    assert r.returncode == 0 and r.stdout.startswith("wavemesh ")


def test_mesh_full_pipeline_levels_lod_and_report(tmp_path):
    np.save(tmp_path / "box.npy", synth.box(96))
    out, rep, lod = tmp_path / "m.ply", tmp_path / "r.json", tmp_path / "lod"
    r = wavemesh("mesh", tmp_path / "box.npy", "-o", out, "--levels", "4", "--zeta", "0.5", "--metric",
                 "vertical",
                 "--iterations", "3", "--neighbourhood", "vertex", "--alpha", "0.8", "--delta-d", "1",
                 "--delta-p", "0.8", "--delta-v", "1.5", "--report", rep, "--lod", lod)
    assert r.returncode == 0, r.stderr
    assert "level  vertices  triangles" in r.stdout
    report = json.loads(rep.read_text())
    rows = report["refiner"]["levels"]
    assert [row["level"] for row in rows] == [3, 2, 1, 0]
    assert rows[-1]["e_max_vertical"] <= 0.5 and report["refiner"]["bound_met"]
    assert report["parameters"]["metric"] == "vertical" and report["parameters"]["neighbourhood"] == "vertex"
    assert sorted(p.name for p in lod.iterdir()) == [f"level-{m}.ply" for m in range(4)]
    final, _ = read_mesh(out)
    level0, _ = read_mesh(lod / "level-0.ply")
    assert final.same_as(level0) and check_mesh(final).valid
    assert final.n_triangles == rows[-1]["triangles"]


def test_mesh_is_the_same_byte_for_byte(tmp_path):
    np.save(tmp_path / "ball.npy", synth.ball(128))
    outs = []
    for k in range(2):
        out = tmp_path / f"m{k}.obj"
        assert main(["mesh", str(tmp_path / "ball.npy"), "-o", str(out), "-q", "--levels", "4"]) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


def test_simplify_off_keeps_the_vertices_the_bound_does_not_need(tmp_path):
    """--simplify off skips the final decimation: more triangles, the same bound; both proper."""
    from wavemesh.check import mesh_errors

    np.save(tmp_path / "ball.npy", synth.ball(64))
    counts = {}
    for mode in ("on", "off"):
        out = tmp_path / f"{mode}.obj"
        r = wavemesh("mesh", tmp_path / "ball.npy", "-o", out, "-q", "--metric", "vertical", "--zeta", "0.5",
                     "--simplify", mode)
        assert r.returncode == 0, r.stderr
        mesh, _ = read_mesh(out)
        assert check_mesh(mesh).valid
        assert mesh_errors(mesh, synth.ball(64).astype(float), rms=False).e_max_vertical <= 0.5 + 1e-9
        counts[mode] = mesh.n_triangles
    assert counts["on"] < counts["off"]


def test_budget_exit_status_says_bound_not_met(tmp_path):
    np.save(tmp_path / "box.npy", synth.box(96))
    out = tmp_path / "m.obj"
    r = wavemesh("mesh", tmp_path / "box.npy", "-o", out, "--levels", "3", "--zeta", "0.1",
                 "--max-triangles", "500", "--reduce", "off")
    assert r.returncode == api.BOUND_NOT_MET
    assert "warning: the error bound is not met" in r.stderr and "Traceback" not in r.stderr
    mesh, _ = read_mesh(out)
    assert check_mesh(mesh).valid and 400 < mesh.n_triangles <= 500


def test_tiled_command_leaves_without_the_teardown_its_output_whole(tmp_path):
    """The process's own tiled `mesh` on local workers ends at once (os._exit, no interpreter teardown:
    an atexit handler does not run) once its files are in place, its printed lines flushed into a pipe and
    its mesh the one an in-process call writes; an untiled command ends as usual (the handler runs)."""
    np.save(tmp_path / "h.npy", synth.ball(130).astype(np.float32))
    code = ("import atexit, sys; atexit.register(print, 'teardown'); sys.argv = ['wavemesh', *sys.argv[1:]]; "
            "from wavemesh.cli import main; sys.exit(main())")
    runs = {}
    for name, extra in (("tiled", ["--tile", "65", "--workers", "2"]), ("whole", [])):
        out = tmp_path / f"{name}.obj"
        r = subprocess.run([sys.executable, "-c", code, "mesh", str(tmp_path / "h.npy"), "-o", str(out),
                            "--metric", "vertical", "--zeta", "0.5", *extra], capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, r.stderr
        runs[name] = r.stdout
        assert f"wrote {out}" in r.stdout
    assert "teardown" not in runs["tiled"] and "the tiles' shared sides match" in runs["tiled"]
    assert runs["whole"].rstrip().endswith("teardown")
    assert main(["mesh", str(tmp_path / "h.npy"), "-o", str(tmp_path / "here.obj"), "-q", "--metric",
                 "vertical", "--zeta", "0.5", "--tile", "65", "--workers", "2"]) == 0
    assert (tmp_path / "here.obj").read_bytes() == (tmp_path / "tiled.obj").read_bytes()
