"""`wavemesh mesh` pays only for what is asked (issue 11): the final mesh is always checked (proper, and
within zeta when the refiner says so), every level only with --check-levels, --report or --lod; and the
faster OBJ writer writes the very bytes of the line-by-line one it replaced."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from wavemesh import api, check
from wavemesh.cli import build_parser, main
from wavemesh.io import synth
from wavemesh.io.meshio import write_obj
from wavemesh.io.meshread import read_mesh
from wavemesh.mesh import Mesh
from wavemesh.refine import native


@pytest.fixture
def ball(tmp_path):
    path = tmp_path / "ball.npy"
    np.save(path, np.round(synth.ball(64) * 20))  # integers: lossless, the bound holds on the input
    return path


def count_calls(monkeypatch) -> dict:
    """Count api's calls of check_mesh and mesh_errors (and the meshes they were given)."""
    calls = {"check_mesh": [], "mesh_errors": [], "rms": []}
    for name in ("check_mesh", "mesh_errors"):
        real = getattr(api, name)

        def wrapper(mesh, *a, _real=real, _name=name, **kw):
            calls[_name].append(mesh)
            if _name == "mesh_errors":
                calls["rms"].append(kw.get("rms", True))
            return _real(mesh, *a, **kw)

        monkeypatch.setattr(api, name, wrapper)
    return calls


def run_mesh(path, out, *extra) -> int:
    return main(["mesh", str(path), "-o", str(out), "--levels", "4", "-q", *map(str, extra)])


def test_without_report_only_the_final_mesh_is_measured(tmp_path, ball, monkeypatch):
    calls = count_calls(monkeypatch)
    assert run_mesh(ball, tmp_path / "m.obj") == 0
    final, _ = read_mesh(tmp_path / "m.obj")
    # check_mesh: the initial triangulation (the templates' own check) and the final mesh; mesh_errors:
    # the final mesh once
    assert len(calls["check_mesh"]) == 2 and calls["check_mesh"][1].same_as(final)
    assert len(calls["mesh_errors"]) == 1 and calls["mesh_errors"][0].same_as(final)
    assert calls["rms"] == [False]  # its maxima: the RMS is for the report


@pytest.mark.parametrize("flag", ["--check-levels", "--report", "--lod"])
def test_report_lod_and_check_levels_measure_every_level(tmp_path, ball, monkeypatch, flag):
    calls = count_calls(monkeypatch)
    extra = {"--check-levels": [], "--report": [tmp_path / "r.json"], "--lod": [tmp_path / "lod"]}[flag]
    assert run_mesh(ball, tmp_path / "m.obj", flag, *extra) == 0
    levels = 4  # levels 3..0
    assert len(calls["check_mesh"]) == 1 + levels
    assert len(calls["mesh_errors"]) == levels  # the final level's errors are measured once
    assert calls["rms"] == [flag == "--report"] + [False] * (levels - 1)  # a level's row: its maxima


def broken(mesh: Mesh) -> Mesh:
    return Mesh(mesh.width, mesh.height, mesh.xy, mesh.tris[:-1])  # a hole


def break_level(monkeypatch, which: int) -> None:
    """native.refine, but the level at index ``which`` of its output has lost a triangle."""
    real = native.refine

    def refine(*a, **kw):
        out = real(*a, **kw)
        lv = out.levels[which]
        lv.mesh = broken(lv.mesh)
        return out

    monkeypatch.setattr(native, "refine", refine)


def test_check_levels_finds_a_broken_level(tmp_path, ball, monkeypatch, capsys):
    break_level(monkeypatch, 1)
    out = tmp_path / "m.obj"
    assert run_mesh(ball, out) == 0  # not asked: a coarser level is not looked at
    assert run_mesh(ball, tmp_path / "n.obj", "--check-levels") == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("error: the refiner's mesh at level 2 is not a proper triangulation: ")
    assert err[1].startswith("hint: this is a bug") and len(err) == 2
    assert not (tmp_path / "n.obj").exists()


def test_a_broken_final_mesh_is_always_found(tmp_path, ball, monkeypatch, capsys):
    break_level(monkeypatch, -1)
    assert run_mesh(ball, tmp_path / "m.obj") == 1
    err = capsys.readouterr().err
    assert err.startswith("error: the refiner's mesh at level 0 is not a proper triangulation: ")
    assert "Traceback" not in err and not (tmp_path / "m.obj").exists()


def test_a_broken_initial_triangulation_is_found(tmp_path, ball, monkeypatch, capsys):
    real = api.initial_triangulation
    monkeypatch.setattr(api, "initial_triangulation",
                        lambda *a: replace(r := real(*a), mesh=broken(r.mesh)))
    assert run_mesh(ball, tmp_path / "m.obj", "--stage", "initial") == 1
    err = capsys.readouterr().err
    assert err.startswith("error: the initial triangulation is not a proper triangulation: ")
    assert "Traceback" not in err and not (tmp_path / "m.obj").exists()


def test_a_final_mesh_above_zeta_is_always_found(tmp_path, ball, monkeypatch, capsys):
    """The refiner claims every triangle within zeta, but the host measures more: a clear error."""
    real = native.refine

    def refine(samples, *a, **kw):
        out = real(samples, *a, **kw)
        coarse = out.levels[0]  # the initial triangulation, far above zeta, claimed within it
        out.levels[-1].mesh = coarse.mesh
        return out

    monkeypatch.setattr(native, "refine", refine)
    assert run_mesh(ball, tmp_path / "m.obj", "--zeta", "0.5") == 1
    err = capsys.readouterr().err
    assert err.startswith("error: the refined mesh is not within zeta: E_max normal ")
    assert "> zeta 0.5 on the input" in err and not (tmp_path / "m.obj").exists()


def test_bound_check_on_lossy_input():
    """Lossy quantisation: the normal bound is checked on the 16-bit samples the refiner saw."""
    from wavemesh.io.heightfield import from_array

    hf = from_array(synth.ball(64))
    assert not hf.lossless
    rjob = api.refine(hf, 3, None, native.RefineParams(zeta=0.05))
    assert rjob.bound_met and api.bound_excess(hf, rjob, rjob.errors) is None
    fake = api.RefineJob(rjob.initial, rjob.params, rjob.zeta_used,
                         replace(rjob.output, levels=rjob.output.levels[:1] + [native.Level(
                             rjob.output.final.level, rjob.output.levels[0].mesh, rjob.output.final.stats)]),
                         0.0)
    fake.errors = check.mesh_errors(fake.mesh, hf.values)
    assert "on the 16-bit samples" in api.bound_excess(hf, fake, fake.errors)


def test_the_report_is_the_same_with_or_without_check_levels(tmp_path, ball):
    reports = []
    for k, extra in enumerate([[], ["--check-levels"], ["--lod", tmp_path / "lod"]]):
        rep = tmp_path / f"r{k}.json"
        assert run_mesh(ball, tmp_path / f"m{k}.obj", "--report", rep, *extra) == 0
        r = json.loads(rep.read_text())
        r["refiner"]["seconds"] = 0
        r["output"] = None
        r.pop("lod", None)
        reports.append(r)
    assert reports[0] == reports[1] == reports[2]
    r = reports[0]
    assert list(r) == ["wavemesh", "input", "ground", "parameters", "initial", "errors", "refiner", "output",
                       "mesh_files"]
    rows = r["refiner"]["levels"]
    assert [row["level"] for row in rows] == [3, 2, 1, 0]
    assert list(rows[0]) == ["level", "vertices", "triangles", "e_max", "e_max_normal", "e_max_vertical",
                             "e_max_firmware", "over_zeta", "splits", "swaps", "firmware"]
    final, _ = read_mesh(tmp_path / "m0.obj")
    values = np.load(tmp_path / "ball.npy")
    assert r["errors"] == check.mesh_errors(final, values).to_report()
    assert rows[-1]["e_max_normal"] == r["errors"]["e_max_normal"]


def test_the_level_table_says_where_its_e_max_comes_from(tmp_path, ball, capsys):
    assert main(["mesh", str(ball), "-o", str(tmp_path / "m.obj"), "--levels", "4"]) == 0
    assert "level  vertices  triangles  E_max(ref)  splits  swaps" in capsys.readouterr().out
    assert main(["mesh", str(ball), "-o", str(tmp_path / "m.obj"), "--levels", "4", "--check-levels"]) == 0
    assert "level  vertices  triangles       E_max  splits  swaps" in capsys.readouterr().out


def test_help_documents_check_levels():
    commands = build_parser()._subparsers._group_actions[0].choices
    text = commands["mesh"].format_help()
    assert "--check-levels" in text and "every level" in text
    assert "--check-levels" in commands["stream"].format_help()  # stream takes mesh's options


@pytest.mark.parametrize("tiled, out", [(False, "m.obj"), (True, "m.ply")])
def test_mesh_imports_only_what_it_runs(tmp_path, ball, tiled, out):
    """A plain `wavemesh mesh` imports neither the wire protocol, the device session, pictures nor tiles
    (start-up is most of a short run's time; api.py and cli.py import them where used, for the cost each
    comment states; the model's limits come from wavemesh.limits), nor the optional readers' libraries;
    nor numpy.ma (47M instructions), which a plain np.unique imports on its first call; nor what only
    other commands or options call: the mesh reader (`check`, `render`), the ROI (--roi), the cover of
    holes (--nodata hole), the synthetic sets (`synth`), json (a report, a sidecar, --tiles-dir).  A tiled
    run (its tiles here in this process, as --workers 1 runs them) the same, but the tiles."""
    extra = ", '--tile', '32', '--workers', '1'" if tiled else ""
    code = ("import sys; from wavemesh.cli import main; "
            f"status = main(['mesh', {str(ball)!r}, '-o', {str(tmp_path / out)!r}, '-q'{extra}]); "
            "print(status, *sorted(sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    status, *modules = r.stdout.split()
    assert status == "0" and "wavemesh.refine.native" in modules  # it did run the refiner
    assert ("wavemesh.tiles.jobs" in modules) == tiled
    unused = ("wavemesh.device.protocol", "wavemesh.device.stream", "wavemesh.device.link",
              "wavemesh.device.devices", "wavemesh.check.render", "serial", "matplotlib", "numpy.ma",
              "tqdm", "PIL", "rasterio", "scipy", "trimesh", "secrets", "zipfile", "json",
              "wavemesh.io.meshread", "wavemesh.model.roi", "wavemesh.refine.cover", "wavemesh.io.synth")
    # the pool forks and pipes without multiprocessing (its modules, socket's enums: 41M of the start)
    unused += ("multiprocessing", "socket") + (() if tiled else ("wavemesh.tiles", "zlib"))
    assert [m for m in modules if m.split(".")[0] in unused or m in unused] == []


def test_cli_imports_only_the_mesh_path():
    """`import wavemesh.cli` (every command's start) loads none of what only other commands or options
    call (api.py, cli.py and io/results.py import them where used): a module moved back to the top of
    one of them fails here."""
    code = "import sys, wavemesh.cli; print(*sorted(sys.modules))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    modules = set(r.stdout.split())
    assert "wavemesh.api" in modules and "wavemesh.io.load" in modules  # it did import the command
    unused = {"wavemesh.io.meshread", "wavemesh.model.roi", "wavemesh.refine.cover", "wavemesh.io.synth",
              "wavemesh.tiles", "wavemesh.device.stream", "wavemesh.check.render", "json", "bisect", "zlib"}
    assert sorted(modules & unused) == []


# ---------------------------------------------------------------------------------------------
# The OBJ writer


def obj_line_by_line(mesh: Mesh, z: np.ndarray) -> str:
    """The OBJ body as the writer made it before, one f-string per line."""
    v = "".join(f"v {p[0]} {p[1]} {zz!r}\n" for p, zz in zip(mesh.xy.tolist(), z.tolist(), strict=True))
    return v + "".join(f"f {a} {b} {c}\n" for a, b, c in (mesh.tris + 1).tolist())


@pytest.mark.parametrize("kind", ["integers", "zeros", "floats", "specials", "mixed"])
def test_obj_writer_writes_the_same_bytes(tmp_path, kind, monkeypatch):
    rng = np.random.default_rng(len(kind))
    from test_check import random_cut_mesh

    mesh = random_cut_mesh(rng, 40)
    V = mesh.n_vertices
    z = {
        "integers": np.round(rng.normal(size=V) * 10.0 ** rng.integers(0, 17, V)),
        "zeros": rng.choice([0.0, -0.0, 3.0, -7.0, 9999999999999998.0], V),  # integral, but -0.0
        "floats": rng.normal(size=V) * 10.0 ** rng.integers(-20, 20, V),
        "specials": rng.choice([0.0, -0.0, 1e16, -1e16, 9999999999999998.0, 1e15, np.inf, -np.inf, np.nan,
                                5e-324, 1.5, -2.0], V),
        "mixed": np.where(rng.random(V) < 0.5, np.round(rng.normal(size=V) * 1e3), rng.normal(size=V)),
    }[kind]
    from wavemesh.io import meshio

    for chunk in (meshio._CHUNK, 7):
        monkeypatch.setattr(meshio, "_CHUNK", chunk)
        write_obj(tmp_path / "m.obj", mesh, z, comment="c")
        text = (tmp_path / "m.obj").read_text()
        head = f"# wavemesh {mesh.width} {mesh.height}\n# c\n"
        assert text == head + obj_line_by_line(mesh, z)
