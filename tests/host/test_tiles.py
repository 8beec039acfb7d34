"""Seamless tiles (wavemesh.tiles): the stitched mesh of a multi-tile input is proper and within zeta in
both metrics, `wavemesh check` says so; the decided borders hold every side's samples within zeta; the
conforming of a tile's border keeps a proper mesh; a single tile is `wavemesh mesh`'s mesh; the Dask path
(a LocalCluster of 2 worker processes) writes the same bytes as the local paths; inputs are read window
by window; bad options end in one error line."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from wavemesh import api, tiles
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.errors import InputError, MeshInvalid
from wavemesh.harness import jacksboro, run_cli
from wavemesh.io.synth import make
from wavemesh.refine.native import RefineParams, fixed_params


def terrain(w: int, h: int, seed: int = 7) -> np.ndarray:
    """A rough seeded surface (integer heights 0..~2000): sums of random waves and a little noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    z = np.zeros((h, w))
    for _ in range(24):
        f = rng.uniform(0.005, 0.12)
        th = rng.uniform(0, 2 * np.pi)
        phase = f * (x * np.cos(th) + y * np.sin(th)) + rng.uniform(0, 6)
        z += rng.uniform(20, 200) / (1 + 20 * f) * np.sin(phase)
    return np.rint(z - z.min() + rng.normal(0, 1.5, z.shape).clip(-4, 4) + 10)


@pytest.fixture(scope="module")
def dem(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiles")
    path = d / "t.npy"
    np.save(path, terrain(203, 170))
    return path


@pytest.mark.parametrize("metric,extra", [("vertical", ()), ("normal", ("--spacing", "4"))])
def test_stitched_mesh_is_proper_and_within_zeta(dem, tmp_path, metric, extra):
    out = tmp_path / "m.obj"
    rc, stdout, err = run_cli("mesh", str(dem), "-o", str(out), "--tile", "64", "--zeta", "3", "--metric",
                              metric, "--workers", "1", "--tiles-dir", str(tmp_path / "td"), *extra)
    assert rc == 0, err
    assert "4 x 3 tiles" in stdout
    rc, stdout, err = run_cli("check", str(out), "--against", str(dem), *extra)
    assert rc == 0 and "a proper triangulation" in stdout, stdout + err
    hf = api.load_input(str(dem), spacing=extra[1] if extra else None)
    report = api.check_file(str(out), hf)
    assert report["valid"] and report["errors"][f"e_max_{metric}"] <= 3 * (1 + 1e-9)
    # each tile's file fits the whole grid as it is; the index names them
    import json

    index = json.loads((tmp_path / "td" / "index.json").read_text())
    assert len(index["tiles"]) == 12 and sum(t["triangles"] for t in index["tiles"]) == report["triangles"]


@pytest.mark.parametrize("metric", ["vertical", "normal"])
def test_jacksboro_tiles(tmp_path, metric):
    """A real DEM in ground units (about 10 m cells), 4 x 3 tiles: proper, within zeta, tiles' shared
    border vertices merged (fewer vertices than the tiles' sum)."""
    src = tiles.open_source(jacksboro(), key="elevation")
    params = api.MeshParams(refine=RefineParams(zeta=2.0, metric=metric))
    plan = tiles.plan_tiles(src, params, 128)
    results = tiles.run_tiles(plan, workers=1)
    tiled = tiles.stitch(plan, results)
    hf = api.load_input(jacksboro(), key="elevation")
    assert check_mesh(tiled.mesh).valid
    e = mesh_errors(tiled.mesh, hf.values, rms=False, spacing=api.ground(hf).spacing)
    assert getattr(e, f"e_max_{metric}") <= 2.0 * (1 + 1e-9)
    assert np.array_equal(tiled.z, tiled.mesh.z(hf.values))
    assert tiled.mesh.n_vertices < sum(len(r.xy) for r in results)
    # the seams thinned: vertices both neighbours could do without left the shared sides
    assert sum(r.report["seam_removed"] for r in results) > 0


@pytest.mark.parametrize("metric", ["vertical", "normal"])
def test_decided_border_within_zeta(metric):
    """Every sample of a side lies within zeta of the segment between its kept neighbours, measured
    independently in floats (the vertical distance; the distance to the 3-D segment)."""
    rng = np.random.default_rng(3)
    z = np.cumsum(rng.integers(-6, 7, 700)) + 30000
    scale, spacing, zeta = 0.25, (3.0, 3.0), 2.0
    fp = fixed_params(RefineParams(zeta=zeta, metric=metric), scale, None, spacing)
    kept = tiles.simplify_profile(z, fp, 0, metric)
    assert kept[0] == 0 and kept[-1] == len(z) - 1 and list(kept) == sorted(set(kept))
    worst = 0.0
    for a, b in zip(kept, kept[1:], strict=False):
        for i in range(a + 1, b):
            dz = scale * (z[i] - (z[a] * (b - i) + z[b] * (i - a)) / (b - a))
            if metric == "normal":
                slope = scale * (z[b] - z[a]) / ((b - a) * spacing[0])
                dz /= math.sqrt(1 + slope * slope)
            worst = max(worst, abs(dz))
    assert worst <= zeta
    assert len(kept) < len(z) / 3  # and it simplifies
    # one sample off by more than zeta is kept
    flat = np.zeros(50, dtype=np.int64)
    flat[20] = 100
    assert 20 in tiles.simplify_profile(flat, fp, 0, metric)


def test_reconcile_keeps_both_sides_vertices_within_zeta():
    """A shared side from two neighbours' vertices: the same list whichever side asks, every vertex of both
    kept (conforming then only inserts), every sample within zeta of its segment (the 1-D test, and an
    independent float check of the vertical distance)."""
    rng = np.random.default_rng(11)
    z = np.cumsum(rng.integers(-9, 10, 400)) + 20000
    fp = fixed_params(RefineParams(zeta=3.0, metric="vertical"), 1.0, None, (1.0, 1.0))
    for _ in range(10):
        mine, theirs = ({0, 399, *rng.choice(np.arange(1, 399), size=int(rng.integers(0, 30))).tolist()}
                        for _ in range(2))
        kept = tiles.reconcile(z, mine, theirs, fp, 0, "vertical")
        assert kept == tiles.reconcile(z, theirs, mine, fp, 0, "vertical")
        assert set(kept) >= mine | theirs and list(kept) == sorted(set(kept))
        for a, b in zip(kept, kept[1:], strict=False):
            i = np.arange(a, b + 1)
            assert np.all(np.abs(z[a:b + 1] - (z[a] + (z[b] - z[a]) * (i - a) / (b - a))) <= 3.0 + 1e-9)


def test_conform_keeps_a_proper_mesh():
    """Random decided borders forced on a real tile's mesh: always proper, with exactly those on the sides."""
    hf = api.load_input(jacksboro(), key="elevation", crop="0,0,97,81")
    mesh = api.refine(hf, params=RefineParams(zeta=1.0)).mesh
    rng = np.random.default_rng(5)
    for _ in range(20):
        sides = {}
        for side, n in (("top", 97), ("bottom", 97), ("left", 81), ("right", 81)):
            if rng.random() < 0.7:
                inner = rng.choice(np.arange(1, n - 1), size=int(rng.integers(0, 12)), replace=False)
                sides[side] = tuple(sorted({0, n - 1, *inner.tolist()}))
        out = tiles.conform(mesh, sides)
        assert check_mesh(out).valid
        got = tiles.border_of(out)
        for side, want in sides.items():
            assert got[side] == want
        for side in set(tiles.SIDES) - set(sides):  # an undecided side keeps its vertices
            assert set(got[side]) >= set(tiles.border_of(mesh)[side]) - {0}


def test_decimate_inner_keeps_the_sides_and_zeta():
    """decimate_inner on a real tile's mesh from every inner vertex: proper, every side vertex kept, every
    new triangle within zeta by the refiner's E(T), the masks exactly the new triangles and those that
    went, the mesh smaller; from no vertex the mesh as it was; from a few only vertices of their rings'
    cascade go (never one of a triangle no removal touched)."""
    from wavemesh.mesh import Mesh
    from wavemesh.refine import native

    hf = api.load_input(jacksboro(), key="elevation", crop="0,0,97,81")
    p = RefineParams(zeta=1.0)
    mesh = api.refine(hf, params=p).mesh
    fp = fixed_params(p, hf.scale, hf.refiner_zeta(p.zeta))
    within = native.error_within(hf.samples, fp)
    out, new, went = tiles.decimate_inner(mesh, within, range(len(mesh.xy)))
    assert check_mesh(out).valid and tiles.border_of(out) == tiles.border_of(mesh)
    assert len(new) == out.n_triangles and len(went) == mesh.n_triangles
    assert out.n_triangles == mesh.n_triangles - int(went.sum()) + int(new.sum()) < mesh.n_triangles
    key = {tuple(sorted(map(tuple, mesh.xy[t].tolist()))) for t in mesh.tris}
    for t, made in zip(out.tris, new, strict=True):
        assert (tuple(sorted(map(tuple, out.xy[t].tolist()))) not in key) == made
        if made:
            assert within(out.xy[t, 0].tolist(), out.xy[t, 1].tolist())
    same, new, went = tiles.decimate_inner(mesh, within, [])
    assert same is mesh and not new.any() and not went.any()
    out, new, went = tiles.decimate_inner(mesh, within, [int(np.flatnonzero(
        (mesh.xy[:, 0] > 0) & (mesh.xy[:, 1] > 0) & (mesh.xy[:, 0] < 96) & (mesh.xy[:, 1] < 80))[0])])
    kept = {tuple(q) for q in out.xy.tolist()}
    lost = [v for v, q in enumerate(mesh.xy.tolist()) if tuple(q) not in kept]
    assert lost and np.isin(lost, mesh.tris[went]).all()
    assert isinstance(out, Mesh)


def test_finish_decimates_the_changed_stars(dem, monkeypatch):
    """finish_tile's pass after the error bound: it starts from the triangles the free mesh lacks (by their
    slots: the same as by their corners), and takes triangles back on this input (fewer than without it,
    every tile proper and within zeta: finish_tile checks it)."""
    from wavemesh.tiles import jobs
    from wavemesh.tiles.sides import FACING

    plan = tiles.plan_tiles(tiles.open_source(str(dem)), api.MeshParams(refine=RefineParams(zeta=2.0)), 64)
    frees = [tiles.free_tile(plan, i) for i in range(len(plan.tiles))]
    facing = [{s: frees[k].sides[FACING[s]] for s, k in t.neighbours.items()} for t in plan.tiles]
    seen = []
    real = jobs._changed

    def spy(conformed, made, final):
        got = real(conformed, made, final)
        seen.append((conformed, made, final, got))
        return got

    monkeypatch.setattr(jobs, "_changed", spy)
    done = [tiles.finish_tile(plan, frees[i], facing[i]) for i in range(len(plan.tiles))]
    assert len(seen) > 1
    for conformed, made, final, got in seen:
        kept = conformed.tris[: len(conformed.tris) - made]  # the free mesh's (conform made the others)
        old = {tuple(sorted(map(tuple, conformed.xy[t].tolist()))) for t in kept}
        want = [tuple(sorted(map(tuple, final.xy[t].tolist()))) not in old for t in final.tris]
        assert got.tolist() == want
    monkeypatch.setattr(jobs, "decimate_inner", lambda m, within, dirty: (m, None, None))
    plain = [tiles.finish_tile(plan, frees[i], facing[i]) for i in range(len(plan.tiles))]
    fewer = [len(a.tris) - len(b.tris) for a, b in zip(plain, done, strict=True)]
    assert min(fewer) >= 0 and sum(fewer) > 0


def test_one_tile_is_the_untiled_mesh(tmp_path):
    hf = api.load_input(jacksboro(), key="elevation", crop="100,80,200,150")
    untiled = api.mesh(hf, api.MeshParams(refine=RefineParams(zeta=2.0)))
    src = tiles.open_source(jacksboro(), key="elevation", crop="100,80,200,150")
    tiled = tiles.mesh_tiled(src, api.MeshParams(refine=RefineParams(zeta=2.0)), 1024, workers=1)
    assert tiled.mesh.same_as(untiled.mesh)


def test_dask_equals_local(dem, tmp_path, monkeypatch):
    """The same tiles on a Dask LocalCluster of 2 worker processes (chains of nodes, as the pool gives them
    out; DASK_CHAIN 16 and 1), on the local pool of 2 workers and in this process:
    the same files, byte for byte; a lossy quantisation's largest error found before the tiles
    (plan_tiles) or in their task graph beside the free meshes (defer_error): the same plan after."""
    distributed = pytest.importorskip("distributed")
    path = tmp_path / "f.npy"
    np.save(path, np.load(dem) + 0.25)  # not integers: a lossy quantisation, q > 0
    src = tiles.open_source(str(path))
    params = api.MeshParams(refine=RefineParams(zeta=3.0, metric="vertical"))

    def files(name, defer, **kw):
        out = tmp_path / name
        out.mkdir()
        with tiles.Runner(**kw) as runner:
            plan = tiles.plan_tiles(src, params, 64, runner=runner, defer_error=defer)
            assert (plan.quant.q is None) == defer and (plan.zeta_used is None) == defer
            if name == "here":  # every tile first, stitched, then written
                tiled = tiles.stitch(plan, tiles.run_tiles(plan, runner=runner))
                tiles.write_tiled(tiled, plan, str(out / "m.obj"), tiles_dir=str(out / "t"))
                report = tiled.report
            else:  # as `wavemesh mesh --tile`: written as the tiles finish
                with tiles.TiledFiles(str(out / "m.obj"), tiles_dir=str(out / "t")) as written:
                    tiles.run_tiles(plan, runner=runner, sink=written.start(plan))
                    report = written.finish()
        return {p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*.obj"))}, \
            (plan.quant, plan.zeta_used, report["quantisation"])

    here = files("here", False, workers=1)
    one = files("one", True, workers=1)
    pool = files("pool", True, workers=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as c, distributed.Client(c) as client:
        dask = files("dask", True, scheduler=client)
        monkeypatch.setattr(tiles.runner, "DASK_CHAIN", 1)
        nodes = files("nodes", True, scheduler=client)
        assert len(client.scheduler_info()["workers"]) == 2
    assert len(here[0]) == 13 and here[1][0].q > 0 and here[1][1] < 3.0
    assert here == one == pool == dask == nodes


def foreign_error(err: str, who: str) -> bool:
    """One error line naming the cluster and the problem, and the hint: the same wavemesh everywhere."""
    lines = err.splitlines()
    return (len(lines) == 2 and lines[0].startswith(f"error: the Dask {who} at tcp://")
            and "cannot load this wavemesh's tasks" in lines[0]
            and lines[1].startswith("hint: run the same wavemesh as here") and "Traceback" not in err)


@pytest.mark.parametrize("other, says", [
    ("del r._dask_start, r._dask_chain", "Can't get attribute '_dask_start'"),
    ("r._TREE[:] = ['0' * 16]", "another wavemesh there"),  # its files another's (its tasks' functions
    # other, or missing: its process would end at its first task, and the run wait for ever)
])
def test_dask_workers_of_another_wavemesh(dem, tmp_path, other, says):
    """Dask workers whose wavemesh is not this one (the runner's functions missing there, or its files
    another's): one error line naming the workers before any task, not Dask's traceback nor a run that
    waits for ever for a worker that died loading a task; no output written."""
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "m.obj"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as c, distributed.Client(c) as client:
        client.run(exec, f"import wavemesh.tiles.runner as r; {other}")
        rc, _, err = run_cli("mesh", str(dem), "-o", str(out), "--tile", "64",
                             "--scheduler", c.scheduler_address)
    assert rc == 2 and foreign_error(err, "workers"), err
    assert says in err and not out.exists()


def test_dask_workers_that_cannot_read_the_input(dem, tmp_path):
    """A Dask worker that cannot read the input (its path not on a file system it shares with this
    machine: here its reads made to fail) stops the run with one error line naming the cluster and what
    failed, and the fix, not Dask's traceback of the worker's OSError; no output written."""
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "m.obj"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as c, distributed.Client(c) as client:
        client.run(exec, "import wavemesh.tiles.source as s\n"
                         "def gone(path): raise FileNotFoundError(2, 'No such file', str(path))\n"
                         "s.file_identity = gone")
        rc, _, err = run_cli("mesh", str(dem), "-o", str(out), "--tile", "64",
                             "--scheduler", c.scheduler_address)
    lines = err.splitlines()
    assert rc == 2 and len(lines) == 2 and "Traceback" not in err, err
    assert lines[0].startswith("error: the Dask run at tcp://") and "FileNotFoundError" in lines[0], err
    assert lines[1].startswith("hint: ") and "shared file system" in lines[1] and not out.exists()


def test_dask_scheduler_of_another_wavemesh(dem, tmp_path):
    """A Dask scheduler whose Python has another wavemesh (a package tree without the runner's functions),
    which cannot read the task graph: one error line naming the scheduler, not Dask's RuntimeError."""
    import json
    import os
    import subprocess
    import sys
    import time

    distributed = pytest.importorskip("distributed")
    other = tmp_path / "other" / "host" / "wavemesh"
    (other / "tiles").mkdir(parents=True)
    (other / "__init__.py").write_text('__version__ = "0.0.0"\n')
    (other / "tiles" / "__init__.py").write_text("")
    (other / "tiles" / "runner.py").write_text("")
    info = tmp_path / "scheduler.json"
    env = dict(os.environ, PYTHONPATH=str(other.parent))  # the venv's .pth then leaves sys.path alone
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(info)],
                              env=env, stderr=subprocess.DEVNULL)]
    out = tmp_path / "m.obj"
    try:
        end, address = time.monotonic() + 60, None
        while address is None and time.monotonic() < end:
            try:  # the file is there and written whole (not only created)
                address = json.loads(info.read_text())["address"]
            except (OSError, ValueError, KeyError):
                time.sleep(0.05)
        assert address, "the scheduler wrote no scheduler file within 60 s"
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                       "--nthreads", "1", "--no-nanny", "--no-dashboard"],
                                      stderr=subprocess.DEVNULL))
        with distributed.Client(address) as client:
            client.wait_for_workers(1, timeout=60)
        rc, _, err = run_cli("mesh", str(dem), "-o", str(out), "--tile", "64", "--scheduler", address)
    finally:
        for p in procs:
            p.terminate()
            p.wait(timeout=30)
    assert rc == 2 and foreign_error(err, "scheduler"), err
    assert "deserialization of the task graph" in err and not out.exists()


@pytest.fixture(scope="module")
def tiled_dem(dem):
    """The dem's 4 x 3 tiles of 64 (every tile's result, the plan) and their stitched mesh."""
    src = tiles.open_source(str(dem))
    plan = tiles.plan_tiles(src, api.MeshParams(refine=RefineParams(zeta=3.0, metric="vertical")), 64)
    results = tiles.run_tiles(plan, workers=1)
    return plan, results, tiles.stitch(plan, results)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_written_as_tiles_finish(tiled_dem, tmp_path, suffix):
    """The mesh file written tile by tile, the tiles given in any order (reversed: each waits for those
    before it), is the stitched mesh: read back (OBJ: its v and f lines tile by tile), or byte for byte what
    write_mesh writes of it whole (PLY, STL); the run's counts are the mesh's."""
    from wavemesh.io.meshio import write_mesh
    from wavemesh.io.meshread import read_mesh

    plan, results, tiled = tiled_dem
    out = tmp_path / f"m{suffix}"
    with tiles.TiledFiles(str(out)) as files:
        add = files.start(plan, "c")
        for r in reversed(results):
            assert not out.exists()
            add(r)
        report = files.finish()
    assert (report["vertices"], report["triangles"]) == (tiled.mesh.n_vertices, tiled.mesh.n_triangles)
    assert not list(tmp_path.glob(".wavemesh-*"))  # the staging folder gone, nothing else left
    if suffix == ".obj":
        mesh, z = read_mesh(str(out))
        assert np.array_equal(mesh.xy, tiled.mesh.xy) and np.array_equal(mesh.tris, tiled.mesh.tris)
        assert np.array_equal(z, tiled.z) and check_mesh(mesh).valid
        lines = out.read_text().splitlines()
        first_f = next(i for i, ln in enumerate(lines) if ln.startswith("f "))
        assert any(ln.startswith("v ") for ln in lines[first_f:])  # the second tile's vertices after faces
    whole = tmp_path / f"whole{suffix}"
    write_mesh(str(whole), tiled.mesh, tiled.z, comment="c")
    if suffix != ".obj":
        assert out.read_bytes() == whole.read_bytes()


def test_tile_order_one_key_or_three(tiled_dem, monkeypatch):
    """TileOrder's triangles sorted by one key of their ranks (tiles of fewer than 2^21 vertices) or by
    their three numbers (larger tiles): the same order."""
    from wavemesh.tiles import jobs

    plan, results, tiled = tiled_dem
    monkeypatch.setattr(jobs, "ONE_KEY", 0)
    three = tiles.stitch(plan, results)
    assert np.array_equal(three.mesh.tris, tiled.mesh.tris) and np.array_equal(three.mesh.xy, tiled.mesh.xy)
    t = three.mesh.tris
    assert np.all(t[:, 0] < t[:, 1:].min(axis=1)) and len(t) > 1000


def test_written_as_tiles_finish_georeferenced(dem, tmp_path):
    """A georeferenced grid (a GeoTIFF whose rows run south): the streamed PLY in the CRS's units and STL
    in metres (their triangles reversed to face up) are write_mesh's files of the stitched mesh, and so
    are their sidecars."""
    import rasterio
    from rasterio.transform import from_origin
    from wavemesh.io.georef import ground
    from wavemesh.io.meshio import write_mesh

    tif = tmp_path / "g.tif"
    a = np.load(dem)
    with rasterio.open(tif, "w", driver="GTiff", width=a.shape[1], height=a.shape[0], count=1,
                       dtype="float64", crs="EPSG:32614", transform=from_origin(500000, 4000000, 5, 5)) as ds:
        ds.write(a, 1)
    src = tiles.open_source(str(tif))
    plan = tiles.plan_tiles(src, api.MeshParams(refine=RefineParams(zeta=3.0, metric="vertical")), 64)
    tiled = tiles.stitch(plan, tiles.run_tiles(plan, workers=1))
    g = ground(src.grid())
    for name, units in (("c.ply", "crs"), ("m.stl", "metres")):
        tiles.write_tiled(tiled, plan, str(tmp_path / name), files=api.MeshFiles(units=units), comment="c")
        write_mesh(str(tmp_path / f"whole-{name}"), tiled.mesh, tiled.z, comment="c", ground=g, units=units)
        for suffix in ("", ".georef.json"):
            a, b = tmp_path / f"{name}{suffix}", tmp_path / f"whole-{name}{suffix}"
            assert a.exists() and b.exists(), name
            assert a.read_bytes() == b.read_bytes().replace(b"whole-", b""), name  # a sidecar names its mesh


def test_written_whole_where_a_format_needs_it(tiled_dem, tmp_path):
    """--normals, --base and .glb: the mesh gathered tile by tile and written whole, as write_mesh writes
    the stitched mesh; --render draws it beside a streamed file."""
    from wavemesh.io.meshio import write_mesh

    plan, results, tiled = tiled_dem
    for name, files, kw in (("n.obj", api.MeshFiles(normals=True), {"normals": True}),
                            ("b.ply", api.MeshFiles(base=5.0), {"base": 5.0}), ("g.glb", None, {})):
        out = tmp_path / name
        tiles.write_tiled(tiled, plan, str(out), files=files, comment="c")
        write_mesh(str(tmp_path / f"whole-{name}"), tiled.mesh, tiled.z, comment="c", **kw)
        assert out.read_bytes() == (tmp_path / f"whole-{name}").read_bytes(), name
    tiles.write_tiled(tiled, plan, str(tmp_path / "r.obj"), render=str(tmp_path / "r.png"), comment="c")
    assert (tmp_path / "r.png").stat().st_size > 0


def test_written_as_tiles_finish_leaves_nothing_on_failure(tiled_dem, tmp_path):
    """A run that fails after some tiles were written (a shared side that does not match: a tile's vertex
    its neighbour lacks) leaves no file, no staging folder, and the old output as it was."""
    plan, results, _ = tiled_dem
    out = tmp_path / "m.ply"
    out.write_bytes(b"old")
    t = plan.tiles[1]
    r = results[1]
    left = np.flatnonzero((r.xy[:, 0] == t.x) & (r.xy[:, 1] > t.y) & (r.xy[:, 1] < t.y + t.height - 2))
    have = set(map(tuple, r.xy.tolist()))
    k = next(i for i in left if (t.x, int(r.xy[i, 1]) + 1) not in have)
    xy = r.xy.copy()
    xy[k, 1] += 1  # moved along the side: not the left neighbour's vertex
    bad = [results[0], replace(r, xy=xy), *results[2:]]
    with pytest.raises(MeshInvalid, match="tile-000-001: its vertex .* on a shared side is not its neighbo"):
        with tiles.TiledFiles(str(out)) as files:
            add = files.start(plan)
            for x in bad:
                add(x)
    assert out.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["m.ply"]


def test_lazy_sources_read_the_same(dem, tmp_path):
    """.npy through a memmap, a GeoTIFF through rasterio windows, --crop and --decimate: the windows are the
    whole-file reader's samples; a float input is quantised as the whole grid is."""
    import rasterio
    from rasterio.transform import from_origin

    a = np.load(dem)
    tif = tmp_path / "t.tif"
    with rasterio.open(tif, "w", driver="GTiff", width=a.shape[1], height=a.shape[0], count=1,
                       dtype="float64", crs="EPSG:32614", transform=from_origin(500000, 4000000, 5, 5),
                       tiled=True, blockxsize=64, blockysize=64) as ds:
        ds.write(a + 0.25, 1)
    for path, kw in ((str(dem), {}), (str(tif), {}), (str(dem), {"crop": "5,7,150,120", "decimate": 2})):
        src = tiles.open_source(path, **kw)
        assert src.kind in ("npy", "raster")
        hf = api.load_input(path, **kw)
        assert (src.width, src.height) == (hf.width, hf.height)
        assert np.array_equal(src.read(3, 4, 40, 30), hf.values[4:34, 3:43])
        quant = tiles.scan(src)
        assert (quant.scale, quant.offset) == (hf.scale, hf.offset)
        assert np.array_equal(quant.samples(hf.values), hf.samples)
    src = tiles.open_source(str(tif))
    assert api.ground(src.grid()).spacing == (5.0, 5.0)


@pytest.mark.parametrize("block", [1, 300, 1 << 16])
def test_strips_in_blocks(tmp_path, monkeypatch, block):
    """The quantisation's strips taken block by block (a row, a few rows, the whole strip; strips of 7
    rows): the whole grid's range, integers, non-finite count and largest quantisation error, as numpy
    finds them on the whole grid at once."""
    from wavemesh.io.heightfield import quant_rule

    monkeypatch.setattr(tiles.source, "BLOCK_SAMPLES", block)
    monkeypatch.setattr(tiles.source, "STRIP_BYTES", 7 * 8 * 61)
    rng = np.random.default_rng(3)
    v = rng.normal(0, 300, (45, 61)) + 0.5
    path = tmp_path / "f.npy"
    np.save(path, v.astype(np.float32))
    w = np.load(path).astype(np.float64)
    src = tiles.open_source(str(path))
    assert len(tiles.source.strip_tasks(src)) == 7
    quant = tiles.scan(src)
    scale, offset, exact = quant_rule(w.min(), w.max(), False)
    recon = offset + scale * np.clip(np.rint((w - offset) / scale), 0, 65535)
    assert (quant.vmin, quant.vmax, quant.scale, quant.offset, quant.exact) == (w.min(), w.max(), scale,
                                                                                 offset, exact)
    assert quant.q == np.max(np.abs(w - recon)) > 0
    np.save(path, np.rint(v))  # integers
    assert tiles.scan(tiles.open_source(str(path))).exact
    v[[3, 20, 44], [60, 0, 7]] = (np.nan, np.inf, -np.inf)
    np.save(path, v)
    with pytest.raises(InputError, match="3 samples are NaN"):
        tiles.scan(tiles.open_source(str(path)))
    filled = tiles.scan(tiles.open_source(str(path), fill="-5000"))
    assert (filled.vmin, filled.vmax) == (-5000, np.nanmax(np.where(np.isfinite(v), v, np.nan)))


@pytest.mark.parametrize("block", [1, 300, 1 << 16])
def test_tile_quantised_in_blocks(tmp_path, monkeypatch, block):
    """A tile's samples and its own largest quantisation error taken block by block (Quant's model of
    its C pass, quantised_model): heightfield's to_samples and HeightField.max_quantisation_error (the C
    pass) on the whole tile at once."""
    from wavemesh.io.heightfield import HeightField, to_samples

    monkeypatch.setattr(tiles.source, "BLOCK_SAMPLES", block)
    v = np.random.default_rng(5).normal(0, 300, (45, 61))
    for quant in (tiles.source.Quant(np.ptp(v) / 65535, v.min(), False, None, v.min(), v.max()),
                  tiles.source.Quant(1.0, -2000.0, True, None, v.min(), v.max())):
        samples, error = quant.quantised_model(v if not quant.exact else np.rint(v))
        assert np.array_equal(samples, to_samples(v if not quant.exact else np.rint(v), quant.scale,
                                                  quant.offset, quant.exact))
        if quant.exact:
            assert error is None
        else:
            hf = HeightField(values=v, samples=samples, scale=quant.scale, offset=quant.offset,
                             lossless=False, source="t")
            assert error == hf.max_quantisation_error > 0


@pytest.mark.parametrize("block", [1, 300, 1 << 16])
def test_tile_checked_finite_in_blocks(monkeypatch, block):
    """A tile's heights checked finite a block of rows at a time (jobs._finite): an InputError naming the
    tile exactly when np.isfinite finds a NaN or an infinity anywhere in it (first row, a middle one, the
    last), the heights themselves returned otherwise."""
    monkeypatch.setattr(tiles.jobs, "BLOCK_SAMPLES", block)
    plan = tiles.plan_tiles(tiles.Source("array", 61, 45, array=np.zeros((45, 61))), api.MeshParams(), 33)
    t = plan.tiles[0]
    v = np.random.default_rng(6).normal(0, 300, (45, 61))
    assert tiles.jobs._finite(plan, t, v) is v
    for (r, c), bad in zip([(0, 0), (22, 30), (44, 60), (7, 59)], [np.nan, np.inf, -np.inf, np.nan],
                           strict=True):
        w = v.copy()
        w[r, c] = bad
        assert not np.isfinite(w).all()
        with pytest.raises(InputError, match=f"non-finite samples in {t.name}"):
            tiles.jobs._finite(plan, t, w)
        with pytest.raises(InputError, match="non-finite"):
            tiles.jobs._finite(plan, t, w[r : r + 1])  # one row: a band at a seam


def test_float_input_within_zeta_on_the_input(tmp_path):
    """Lossy quantisation (float heights over a range wider than 16 bits): one zeta on the samples for every
    tile, the vertical bound on the input heights."""
    v = make("f3", 150) * 1000.0 + 0.123
    path = tmp_path / "f.npy"
    np.save(path, v)
    src = tiles.open_source(str(path))
    tiled = tiles.mesh_tiled(src, api.MeshParams(refine=RefineParams(zeta=0.5, metric="vertical")), 64,
                             workers=1)
    assert check_mesh(tiled.mesh).valid
    assert mesh_errors(tiled.mesh, v, rms=False).e_max_vertical <= 0.5 * (1 + 1e-9)


@pytest.mark.parametrize("workers", [1, 2])
def test_float32_input_held_as_float32(tmp_path, workers):
    """A float32 .npy's tiles are held as float32, without --fill in place (the file's memory map, no copy),
    and mesh exactly as its float64 copy: the same vertices, heights (float64) and triangles, lossy and
    lossless, with a --fill a float32 holds (a copy); a fill it does not hold reads the tile as float64."""
    v = (make("f3", 150) * 1000.0 + 0.123).astype(np.float32)
    v[7, 9] = np.nan
    params = api.MeshParams(refine=RefineParams(zeta=20.0, metric="vertical"))
    for heights, fill in ((v, "-0.5"), (np.rint(v), "3"), (v, "0.1"), (np.nan_to_num(v), None)):
        got = []
        for dtype in (np.float32, np.float64):
            path = tmp_path / f"{np.dtype(dtype).name}.npy"
            np.save(path, heights.astype(dtype))
            src = tiles.open_source(str(path), fill=fill)
            window = src.read(3, 2, 20, 10)
            assert window.dtype == (np.float32 if dtype == np.float32 and fill != "0.1" else np.float64)
            assert window.flags.owndata == (dtype == np.float64 or fill is not None)
            assert np.array_equal(window, heights.astype(dtype)[2:12, 3:23], equal_nan=True) or fill
            got.append(tiles.mesh_tiled(src, params, 64, workers=workers))
        (a, b) = got
        assert a.z.dtype == b.z.dtype == np.float64
        assert np.array_equal(a.mesh.xy, b.mesh.xy) and np.array_equal(a.mesh.tris, b.mesh.tris)
        assert np.array_equal(a.z, b.z)
        assert [(t.report["e_max_vertical"], t.report["triangles"]) for t in a.tiles] == \
            [(t.report["e_max_vertical"], t.report["triangles"]) for t in b.tiles]


@pytest.mark.parametrize("args,expect", [
    (("--tile", "4"), "--tile 4 is too small"),
    (("--tile", "64", "--max-triangles", "100"), "--max-triangles is not done in tiles"),
    (("--tile", "64", "--bound", "off"), "--bound off is not done in tiles"),
    (("--tile", "64", "--scheduler", "tcp://127.0.0.1:9"), "no Dask scheduler answers"),
    (("--tile", "64", "--workers", "0"), "--workers 0 is out of range"),
])
def test_bad_options(dem, tmp_path, monkeypatch, args, expect):
    monkeypatch.setattr(tiles.runner, "DASK_CONNECT_S", 1)
    out = tmp_path / "m.obj"
    rc, _, err = run_cli("mesh", str(dem), "-o", str(out), *args)
    assert rc != 0 and expect in err and err.startswith("error:"), err
    assert not out.exists()


def test_default_tile_from_memory():
    per = tiles.TILE_BYTES_PER_SAMPLE
    assert tiles.default_tile(2, 2 * per * 4097**2) == 4097
    assert tiles.default_tile(2, 2 * per * 4097**2 - 1) == 2049
    assert tiles.default_tile(4, 4 * per * 1025**2) == 1025
    assert tiles.default_tile(64, 1) == 513
    assert tiles.cuts(8192, 4097) == [0, 4096, 8191] and tiles.cuts(4097, 4097) == [0, 4096]


def test_quiet_tiled_run_imports_no_progress_bar(dem, tmp_path):
    """--quiet: no bar and no line are drawn, and tqdm is not imported for them (a serial 20 ms between the
    quantisation's strips and the tiles with a pool)."""
    import subprocess
    import sys

    code = ("import sys; from wavemesh import cli; rc = cli.main(['mesh', sys.argv[1], '-o', sys.argv[2], "
            "'--tile', '64', '--workers', '2', '--quiet']); print(rc, 'tqdm' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, str(dem), str(tmp_path / "m.obj")], capture_output=True,
                         text=True, check=True)
    assert out.stdout.split() == ["0", "False"], out.stdout + out.stderr


def test_seam_reads_only_the_band_of_a_tile_it_does_not_hold(dem, monkeypatch):
    """A seam's tile this process does not hold (another worker's) is read only in its band at the side,
    the box of the triangles that touch it: the same cuts as with every tile held; a triangle off the band
    is refused, not measured on samples that were not read."""
    from wavemesh.tiles import jobs
    from wavemesh.tiles.sides import FACING
    from wavemesh.tiles.source import Source

    plan = tiles.plan_tiles(tiles.open_source(str(dem)), api.MeshParams(refine=RefineParams(zeta=2.0)), 64)
    frees = [tiles.free_tile(plan, i) for i in range(len(plan.tiles))]
    done = [tiles.finish_tile(plan, frees[i], {s: frees[k].sides[FACING[s]] for s, k in t.neighbours.items()})
            for i, t in enumerate(plan.tiles)]
    seams = [(i, k, s) for i, t in enumerate(plan.tiles) for s, k in t.neighbours.items()
             if s in ("right", "bottom")]
    held = [tiles.thin_seam(plan, done[i], done[k], s) for i, k, s in seams]  # every tile held (finish_tile)
    assert sum(map(len, held)) > 0
    jobs.clear_tile_cache()
    reads, read = [], Source.read
    monkeypatch.setattr(Source, "read", lambda src, x, y, w, h: reads.append(w * h) or read(src, x, y, w, h))
    for (i, k, s), cut in zip(seams, held, strict=True):
        band = tiles.thin_seam(plan, done[i], done[k], s)
        assert band == cut and band.plans == cut.plans
    area = [plan.tiles[i].width * plan.tiles[i].height for i, _, _ in seams]
    assert len(reads) == 2 * len(seams) and sum(reads) < sum(area)  # two bands a seam, less than a tile each
    assert not jobs._TILE_CACHE  # nothing kept
    # tile 0's bottom band (rows 36 to 56 of 57: its right one is the whole tile, a triangle at the right
    # side reaching the top left corner)
    ed = jobs._seam_editable(plan, done[0], None, "bottom")
    t = plan.tiles[0]
    with pytest.raises(MeshInvalid, match="off the band"):
        ed.within([0, 1, 0], [0, 0, 1])  # the tile's top left corner: far from its bottom side
    assert ed.within([0, 1, 1], [t.height - 2, t.height - 2, t.height - 1])


def test_seam_cut_carries_the_removals(dem, monkeypatch):
    """thin_seam works each removal out once (Editable.removal keeps an answer until the vertex's star
    changes) and hands the removals to thin_tile in its Cut: the same cut as every removal worked out
    anew each time; every tile thinned by them equals the tile thinned by its removals worked out again
    from the positions alone; a Cut pickles (pool, Dask); a removal from another mesh is refused."""
    import pickle

    from wavemesh.mesh import Mesh
    from wavemesh.tiles.sides import FACING, Cut

    plan = tiles.plan_tiles(tiles.open_source(str(dem)), api.MeshParams(refine=RefineParams(zeta=2.0)), 64)
    frees = [tiles.free_tile(plan, i) for i in range(len(plan.tiles))]
    done = [tiles.finish_tile(plan, frees[i], {s: frees[k].sides[FACING[s]] for s, k in t.neighbours.items()})
            for i, t in enumerate(plan.tiles)]
    cuts: list[dict] = [{} for _ in plan.tiles]
    for i, t in enumerate(plan.tiles):
        if "right" in t.neighbours:
            k = t.neighbours["right"]
            cut = tiles.thin_seam(plan, done[i], done[k], "right")
            again = pickle.loads(pickle.dumps(cut))
            assert again == cut and again.plans == cut.plans and set(cut.plans) == {"right", "left"}
            assert all(len(p) == len(cut) for p in cut.plans.values())
            cuts[i]["right"] = cuts[k]["left"] = cut
    with monkeypatch.context() as m:  # no answer kept: each removal worked out anew
        m.setattr(tiles.Editable, "removal", tiles.Editable._removal)
        for i, t in enumerate(plan.tiles):
            if "right" in t.neighbours:
                fresh = tiles.thin_seam(plan, done[i], done[t.neighbours["right"]], "right")
                assert fresh == cuts[i]["right"] and fresh.plans == cuts[i]["right"].plans
    removed, z = 0, np.load(dem)
    for i, r in enumerate(done):
        a = tiles.thin_tile(plan, r, cuts[i])
        b = tiles.thin_tile(plan, r, {s: tuple(c) for s, c in cuts[i].items()})
        assert np.array_equal(a.xy, b.xy) and np.array_equal(a.tris, b.tris)
        removed += a.report["seam_removed"]
        # only the triangles at the shared sides measured again: the whole tile's E_max all the same
        t = plan.tiles[i]
        e = mesh_errors(Mesh(t.width, t.height, a.xy - [t.x, t.y], a.tris),
                        z[t.y:t.y + t.height, t.x:t.x + t.width], rms=False)
        assert (a.report["e_max_vertical"], a.report["e_max_normal"]) == (e.e_max_vertical, e.e_max_normal)
    assert removed > 0
    i, cut = next((i, c["right"]) for i, c in enumerate(cuts) if c.get("right"))
    wrong = Cut(cut, {"right": [(cut.plans["right"][0][0] + 1, cut.plans["right"][0][1])]
                                  + cut.plans["right"][1:]})
    with pytest.raises(MeshInvalid):
        tiles.thin_tile(plan, done[i], {"right": wrong})
