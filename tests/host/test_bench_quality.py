"""The quality benchmark's harness (bench/bench_quality.py, bench/peers.py, bench/bench_cost.py) on one
tiny grid, so that it cannot rot: the peers' output mapped onto wavemesh's conventions and judged by
wavemesh's checker, one whole pair (in process and as whole processes), the table written from it."""

from __future__ import annotations

from pathlib import Path

import bench_cost as C  # bench/ is on pytest's path (pytest.ini)
import bench_quality as Q
import datasets as D
import numpy as np
import peers as P
import pytest
from wavemesh.mesh import Mesh

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tiny() -> D.Grid:
    """Rough and not square (37 x 23), so a lost flip or a transposition shows."""
    z = D.terrain(40, 0.6)[:23, :37].copy()
    return D.Grid("tiny", "synthetic", "bench/datasets.py terrain", "m", z)


def test_delatin_y_flip_gives_a_proper_mesh_within_zeta(tiny):
    z = tiny.values
    h, w = z.shape
    zeta = 0.02 * tiny.height_range
    verts, tris = P.delatin_call(z, zeta)
    mesh, vz, problems = P.from_delatin(verts, tris, w, h)
    v = P.verdict(mesh, z, zeta, vz, problems)
    assert v.proper and v.heights_ok, v.problems
    assert v.within and v.e_max_vertical <= zeta * (1 + P.ZETA_SLACK)
    assert v.triangles == len(tris) > 2
    # The same output without the flip: pydelatin's own heights no longer sit on their samples, and
    # the checker must say so (this is what the mapping is for).
    raw = Mesh(w, h, np.asarray(verts)[:, :2].astype(np.int64), np.asarray(tris, dtype=np.int64))
    bad = P.verdict(raw, z, zeta, vz)
    assert not (bad.heights_ok and bad.within)
    # ... and without turning the triangles round it is not a proper triangulation (clockwise)
    turned = Mesh(w, h, mesh.xy, mesh.tris[:, ::-1])
    assert not P.verdict(turned, z, zeta).proper


def test_martini_padding_and_mapping(tiny):
    assert [P.martini_size(*s) for s in ((129, 129), (128, 128), (130, 10), (37, 23), (2, 2))] == \
        [129, 129, 257, 65, 3]
    z = tiny.values
    size = P.martini_size(*z.shape[::-1])
    zp = P.pad_edge(z, size)
    assert zp.shape == (size, size)
    assert np.array_equal(zp[: z.shape[0], : z.shape[1]], z)
    assert np.array_equal(zp[-1, : z.shape[1]], z[-1]) and np.array_equal(zp[: z.shape[0], -1], z[:, -1])
    zeta = 0.02 * tiny.height_range
    v, t = P.martini_call(zp, zeta)
    ver = P.verdict(P.from_martini(v, t, size), zp, zeta)
    assert ver.proper, ver.problems
    assert ver.e_max_vertical is not None


def test_one_pair_end_to_end(tiny, tmp_path):
    npy = tmp_path / "tiny.npy"
    np.save(npy, tiny.values)
    zeta = 0.02 * tiny.height_range
    pair = Q.run_pair(tiny, "2%", zeta, npy, wm_budget=0.5, peer_budget=0.2)
    assert pair["wavemesh"]["proper"] and pair["wavemesh"]["within"], pair["wavemesh"]["problems"]
    assert pair["pydelatin"]["proper"] and pair["pydelatin"]["within"], pair["pydelatin"]["problems"]
    assert pair["pymartini"]["proper"]
    proc = pair["process"]
    assert proc["error"] is None, proc["error"]
    # the OBJ files both whole processes wrote, read back and checked: the same meshes as in process
    assert proc["wavemesh_file"]["within"] and proc["pydelatin_file"]["within"]
    assert proc["wavemesh_file"]["triangles"] == pair["wavemesh"]["triangles"]
    assert proc["pydelatin_file"]["triangles"] == pair["pydelatin"]["triangles"]
    r = pair["ratios"]
    assert r["triangles"] == pair["wavemesh"]["triangles"] / pair["pydelatin"]["triangles"]
    assert all(r[k] > 0 for k in ("native_time", "call_time", "process_time", "process_cpu",
                                  "martini_triangles"))
    results = Q.assemble([pair], ["tiny"])
    assert results["summary"]["all"]["pairs"] == 1 and "held_out" not in results["summary"]
    text = Q.markdown(results)
    assert "| tiny | 37 x 23 | 2%" in text and "**median** (1 pairs)" in text


def test_failed_process_is_reported_not_timed(tmp_path):
    """A whole process that fails (here: an input that is not there) ends the runs: the error names it and
    no time stands for it, so no ratio is made of a failed run."""
    proc = Q._run_processes(tmp_path / "missing.npy", 1.0, tmp_path)
    assert proc["error"].startswith("wavemesh exit ") and "missing.npy" in proc["error"], proc["error"]
    assert proc["runs"] == 0
    assert all(proc[k] is None for k in ("wavemesh_s", "pydelatin_s", "wavemesh_cpu_s", "pydelatin_cpu_s"))


def test_split_and_errors():
    assert set(Q.HELD_OUT) <= set(Q.GRIDS)
    assert abs(len(Q.HELD_OUT) - len(Q.GRIDS) / 3) < 1  # a third of the grids, not of the pairs
    jb = D.Grid("jacksboro", "terrain", "-", "m", np.array([[236.0, 1076.0], [500.0, 600.0]]))
    assert Q.zetas(jb) == [("5 m", 5.0), ("10 m", 10.0), ("2%", 0.02 * 840), ("5%", 0.05 * 840)]


def test_cost_slope():
    n = [256**2, 512**2, 1024**2, 2048**2]
    assert C.slope(n, [x**1.2 for x in n]) == pytest.approx(1.2)
    assert C.slope(n, [3 * x for x in n]) == pytest.approx(1.0)


def test_bench_big_harness(tmp_path):
    """bench_big on a small grid, one run of each process: the figures come back, both files checked, the
    one-thread mesh the default's, the table written; mirror tiling keeps every sample a real one."""
    import bench_big as B

    z = np.arange(12.0).reshape(3, 4)
    t = B.mirror_tile(z, 8)
    assert t.shape == (8, 8) and np.array_equal(t[:3, :4], z) and np.array_equal(t[3:6, :4], z[::-1])
    assert np.array_equal(t[:3, 4:8], z[:, ::-1])
    r = B.run_grid("terrain", 48, tmp_path, runs=1)
    for who in ("wavemesh", "pydelatin", "threads1"):
        assert r[who]["error"] is None and r[who]["cpu_s"] > 0 and r[who]["peak_mib"] > 5
    assert r["wavemesh"]["file"]["within"] and r["pydelatin"]["file"]["within"]
    assert r["same_mesh_one_thread"] and 0 < r["ratios"]["triangles"] < 2
    text = B.markdown({"code": None, "fraction": B.FRACTION, "runs": 1, "cores": 2, "load_before": (1.0,),
                       "rows": [r]})
    assert "| terrain | 48 |" in text


def test_bench_big_tile_sizes():
    """bench_big's table of tile sides (docs/usage.md quotes it) on a grid smaller than every tile: each
    tiled run is one tile, the whole grid's mesh (triangles 1.0000 of the whole's), every figure there."""
    import bench_big as B

    text = B.tile_sizes(48, ("terrain",), runs=1)
    cells = next(line for line in text.splitlines() if line.startswith("| terrain |")).split("|")[2:-1]
    assert len(cells) == len(B.TILE_CONFIGS) + 1 and all(float(c.split()[0]) > 0 for c in cells)
    assert all(c.strip().endswith("(1.0000)") for c in cells[1:-1]), cells
