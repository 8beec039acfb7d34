"""--nodata hole (issue 20): meshes of range data with invalid samples.

Every mesh is checked twice: by wavemesh's own check (wavemesh.check.check_holes, also `wavemesh check
--nodata hole`) and by the independent brute-force check below (lattice points per triangle by their
bounding boxes, overlaps by separating axes over every pair, distances in floats), written apart from
holes.py."""

from __future__ import annotations

import numpy as np
import pytest
from wavemesh import api, check
from wavemesh.cli import main
from wavemesh.errors import InputError
from wavemesh.io.heightfield import from_array
from wavemesh.mesh import Mesh, orient, triangulate_within
from wavemesh.model import holemask
from wavemesh.refine.native import RefineParams

ZETA = 1.0


def motorcycle_crop() -> np.ndarray:
    """A 96 x 72 piece of Middlebury's Motorcycle disparity (scikit-image's copy) with its real dropouts
    (inf: occluded or unmatched pixels)."""
    import importlib.metadata

    try:
        f = next(f for f in importlib.metadata.files("scikit-image") or () if f.name == "motorcycle_disp.npz")
    except (importlib.metadata.PackageNotFoundError, StopIteration):
        pytest.skip("scikit-image's motorcycle_disp.npz is not installed")
    d = np.load(f.locate())["arr_0"].astype(np.float64)
    return d[180:252, 300:396].copy()


def shadowed_ball(n: int = 48) -> np.ndarray:
    """The ball of the synthetic sets with a scanner's shadow: the samples a ray from the left at a low
    angle does not reach behind the ball are NaN."""
    from wavemesh.io.synth import make

    z = make("ball", n).astype(np.float64)
    seen = np.maximum.accumulate(z + 0.6 * np.arange(n)[None, :], axis=1)  # the ray, falling 0.6 a step
    shadow = z + 0.6 * np.arange(n)[None, :] < seen - 1e-9
    z[shadow] = np.nan
    return z


# ---------------------------------------------------------------------------------------------------
# The independent check


def lattice_points(p) -> np.ndarray:
    """The grid points of the closed counter-clockwise triangle p (3 x 2), from its bounding box."""
    (x0, y0), (x1, y1), (x2, y2) = p
    X, Y = np.meshgrid(np.arange(min(x0, x1, x2), max(x0, x1, x2) + 1),
                       np.arange(min(y0, y1, y2), max(y0, y1, y2) + 1))
    ins = np.ones(X.shape, dtype=bool)
    for (ax, ay), (bx, by) in (((x0, y0), (x1, y1)), ((x1, y1), (x2, y2)), ((x2, y2), (x0, y0))):
        ins &= (bx - ax) * (Y - ay) - (by - ay) * (X - ax) >= 0
    return np.column_stack([X[ins], Y[ins]])


def overlapping_pairs(mesh: Mesh) -> int:
    """Pairs of triangles whose interiors meet: no edge of either has the other on its outer side."""
    P = mesh.xy[mesh.tris]  # (T, 3, 2)
    T = len(P)
    a, b = np.triu_indices(T, 1)
    sep = np.zeros(len(a), dtype=bool)
    for one, two in ((a, b), (b, a)):
        for k in range(3):
            s, e = P[one, k], P[one, (k + 1) % 3]
            side = ((e[:, 0] - s[:, 0])[:, None] * (P[two, :, 1] - s[:, 1][:, None])
                    - (e[:, 1] - s[:, 1])[:, None] * (P[two, :, 0] - s[:, 0][:, None]))
            sep |= (side <= 0).all(axis=1)
    return int((~sep).sum())


def lone_samples(invalid: np.ndarray) -> np.ndarray:
    """Valid samples that are a corner of no grid cell with three or four valid corners (no triangle of
    cell corners covers them without an invalid sample): --nodata hole meshes them as invalid."""
    H, W = invalid.shape
    lone = ~invalid.copy()
    for y in range(H - 1):
        for x in range(W - 1):
            cell = [(x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)]
            if sum(not invalid[b, a] for a, b in cell) >= 3:
                for a, b in cell:
                    lone[b, a] = False
    return lone


def independent_check(mesh: Mesh, invalid: np.ndarray, heights: np.ndarray, zeta: float) -> dict:
    lone = lone_samples(invalid)
    invalid = invalid | lone
    H, W = invalid.shape
    covered = np.zeros((H, W), dtype=int)
    worst = 0.0
    for tri in mesh.tris:
        p = mesh.xy[tri]
        d = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1])
        assert d > 0, "a triangle is not counter-clockwise"
        pts = lattice_points(p)
        assert not invalid[pts[:, 1], pts[:, 0]].any(), f"triangle {p.tolist()} covers an invalid sample"
        covered[pts[:, 1], pts[:, 0]] += 1
        z = heights[p[:, 1], p[:, 0]]
        # the plane z = a x + b y + c through the corners; the normal distance of every covered sample
        A = np.column_stack([p, np.ones(3)])
        a, b, c = np.linalg.solve(A, z)
        plane = a * pts[:, 0] + b * pts[:, 1] + c
        dist = np.abs(heights[pts[:, 1], pts[:, 0]] - plane) / np.sqrt(1 + a * a + b * b)
        worst = max(worst, float(dist.max()))
    assert worst <= zeta * (1 + 1e-9), f"E_max {worst} over the valid samples > zeta {zeta}"
    assert overlapping_pairs(mesh) == 0, "triangles overlap"
    valid = ~invalid
    uncovered = valid & (covered == 0)
    near = np.zeros_like(invalid)  # 8-neighbours of invalid samples
    pad = np.pad(invalid, 1)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            near |= pad[dy:dy + H, dx:dx + W]
    assert not (uncovered & ~near).any(), "a valid sample away from the holes is not covered"
    return {"uncovered_valid": int(uncovered.sum()), "valid": int(valid.sum()), "e_max": worst,
            "lone": int(lone.sum())}


def run(z: np.ndarray, **kw) -> api.MeshResult:
    hf = from_array(z, holes=True, **kw)
    return api.mesh(hf, api.MeshParams(refine=RefineParams(zeta=ZETA)))


# ---------------------------------------------------------------------------------------------------


def test_pack_is_the_refiners_bit_order():
    rng = np.random.default_rng(1)
    m = rng.random((7, 13)) < 0.3
    data = holemask.pack(m)
    assert len(data) == (7 * 13 + 7) // 8
    i = 7 * 13 - 1  # sample (12, 6): bit i % 8 of byte i // 8
    assert bool(data[i // 8] >> (i % 8) & 1) == m[6, 12]
    assert np.array_equal(holemask.unpack(data, 13, 7), m)


def test_real_dropouts_are_holes():
    z = motorcycle_crop()
    invalid = ~np.isfinite(z)
    assert 50 < invalid.sum() < z.size // 2  # the crop has real dropouts
    r = run(z)
    assert r.bound_met
    assert r.report["holes"]["triangles_over_invalid"] == 0
    got = independent_check(r.mesh, invalid, r.heightfield.values, ZETA)
    assert got["lone"] == r.report["input"]["stranded"] > 0
    assert got["uncovered_valid"] == r.report["holes"]["uncovered_valid"]
    assert got["uncovered_valid"] == 0  # every valid sample a cell triangle can cover is covered
    assert got["e_max"] <= ZETA


def test_scanner_shadow_is_a_hole():
    # (how many triangles holes save against --fill nearest is measured in make bench-holes)
    z = shadowed_ball()
    r = run(z)
    assert independent_check(r.mesh, ~np.isfinite(z), r.heightfield.values, ZETA)["uncovered_valid"] == 0


def test_a_zeta_above_every_error_still_splits_mixed_triangles():
    # zeta saturates the refiner's Q16.16 (0xFFFFFFFF); the E(T) of a triangle over both kinds must stay
    # above it (native.fixed_params), or such triangles stay and the host drops valid samples with them
    z = shadowed_ball()
    hf = from_array(z, holes=True)
    r = api.mesh(hf, api.MeshParams(refine=RefineParams(zeta=1e9)))
    assert independent_check(r.mesh, ~np.isfinite(z), r.heightfield.values, 1e9)["uncovered_valid"] == 0


@pytest.mark.parametrize("seed", range(6))
def test_random_dropouts_cover_every_coverable_sample(seed):
    # speckle and blobs of dropouts on a rough surface: the refiner's cover steps (holes.c) against the
    # independent check, at a tight and a loose zeta
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    h, w = rng.integers(12, 40, 2)
    z = np.cumsum(np.cumsum(rng.normal(size=(h, w)), 0), 1)
    bad = rng.random((h, w)) < 0.3 if seed % 2 else ndimage.binary_dilation(rng.random((h, w)) < 0.04)
    z[bad] = np.nan
    zeta = (0.2 if seed < 3 else 3.0) * float(np.nanstd(z))
    r = api.mesh(from_array(z, holes=True), api.MeshParams(refine=RefineParams(zeta=zeta)))
    assert independent_check(r.mesh, bad, r.heightfield.values, zeta)["uncovered_valid"] == 0


def test_invalid_value_marks_a_sentinel():
    z = shadowed_ball()
    z[~np.isfinite(z)] = 0.0  # a scanner's "no return"
    z[0, 0] = 0.0
    r = run(z, invalid=0.0)
    assert independent_check(r.mesh, z == 0.0, r.heightfield.values, ZETA)["uncovered_valid"] == 0


def test_check_finds_what_is_wrong():
    z = shadowed_ball()
    invalid = ~np.isfinite(z)
    good = run(z).mesh
    assert check.check_holes(good, invalid).valid_mesh
    # the filled mesh covers invalid samples
    filled = api.mesh(from_array(z, fill="nearest"), api.MeshParams(refine=RefineParams(zeta=ZETA))).mesh
    c = check.check_holes(filled, invalid)
    assert c.over_invalid > 0 and not c.valid_mesh
    # a hole where the input has none: drop the triangle farthest from every invalid sample
    from scipy import ndimage

    dist = ndimage.distance_transform_edt(~invalid)
    centre = good.xy[good.tris].mean(axis=1)
    far = int(np.argmax(dist[centre[:, 1].astype(int), centre[:, 0].astype(int)]))
    gap = Mesh(good.width, good.height, good.xy, np.delete(good.tris, far, axis=0))
    assert any("invalid sample" in p or "no triangle" in p for p in check.check_holes(gap, invalid).problems)
    # an overlap: a triangle twice, shifted by one column
    t = good.tris[far]
    xy = np.vstack([good.xy, good.xy[t] + [1, 0]])
    n = len(good.xy)
    over = Mesh(good.width, good.height, xy, np.vstack([good.tris, [[n, n + 1, n + 2]]]))
    if (xy[n:, 0] < good.width).all():
        assert not check.check_holes(over, invalid).valid_mesh


def test_long_thin_triangles_leave_no_crack():
    # The refiner's full mesh of a 5 x 4 grid with one invalid sample P = (3, 2): five thin triangles
    # around P (doubled area 1, E(T) 0), the rest valid.  Dropping the thin ones leaves a crack: the thin
    # triangle (P, (0, 1), (1, 1)) reaches from P into the valid region, so edge (0, 1)-(1, 1) has one
    # triangle though every cell it borders has four valid corners (Motorcycle's disparity, --decimate 2
    # --zeta 1, failed so).  cover.flip_thin swaps it with a thin neighbour: the other diagonal gives a
    # triangle of three valid corners on that edge, which closes the crack.
    from types import SimpleNamespace

    from wavemesh.mesh import ear_clip

    P = (3, 2)
    star = [(4, 2), (3, 3), (2, 2), (0, 1), (1, 1)]
    tris = [(P, star[i], star[(i + 1) % 5]) for i in range(5)] + [((4, 2), (4, 3), (3, 3))]
    for poly in ([(0, 0), (4, 0), (4, 2), (1, 1), (0, 1)], [(0, 1), (2, 2), (3, 3), (0, 3)]):
        tris += [tuple(poly[i] for i in c) for c in ear_clip(poly)]
    pts = sorted({p for t in tris for p in t})
    ix = {p: i for i, p in enumerate(pts)}
    full = Mesh(5, 4, np.array(pts, dtype=np.int64), np.array([[ix[p] for p in t] for t in tris]))
    assert check.check_mesh(full).valid  # a proper triangulation of the rectangle
    invalid = np.zeros((4, 5), dtype=bool)
    invalid[P[1], P[0]] = True
    level = SimpleNamespace(mesh=full, stats={"over": 0})
    verdict = api.drop_holes([level], SimpleNamespace(mask=invalid))  # MeshInvalid before the flip
    assert verdict.valid_mesh and verdict.hole_edges == 4  # the hole: a quadrilateral around P
    # the crack's edge is in two kept triangles, the one it had and a flipped one, of three valid corners
    xy = [tuple(p) for p in level.mesh.xy.tolist()]
    at = [t for t in level.mesh.tris.tolist() if {(0, 1), (1, 1)} <= {xy[v] for v in t}]
    assert len(at) == 2
    independent_check(level.mesh, invalid, np.zeros((4, 5)), ZETA)


def test_overlap_sweep_agrees_with_every_pair():
    # check.check_holes's overlap test (a sweep of bounding boxes, chunked) against the brute force over every
    # pair, on a hole mesh with vertices moved at random (some moves make overlaps, some do not)
    good = run(shadowed_ball()).mesh
    rng = np.random.default_rng(7)
    found = 0
    for _ in range(24):
        xy = good.xy.copy()
        for v in rng.integers(len(xy), size=2):
            xy[v] = np.clip(xy[v] + rng.integers(-3, 4, 2), 0, [good.width - 1, good.height - 1])
        P = xy[good.tris] - xy[good.tris][:, :1]
        d = P[:, 1, 0] * P[:, 2, 1] - P[:, 2, 0] * P[:, 1, 1]
        m = Mesh(good.width, good.height, xy, good.tris[d > 0])
        for chunk in (7, 1 << 20):
            p = []
            check._overlaps(m, np.arange(m.n_triangles), p, chunk=chunk)
            assert bool(p) == (overlapping_pairs(m) > 0)
        found += bool(p)
    assert 0 < found < 24


def test_rim_triangulation_search():
    # simplify_rims' fallback: every triangulation of the ring searched when ear clipping's one is refused
    square = [(0, 0), (2, 0), (2, 2), (0, 2)]
    cut = triangulate_within(square, lambda c: not {0, 2} <= set(c))  # the diagonal 0-2 refused
    assert sorted(map(sorted, cut)) == [[0, 1, 3], [1, 2, 3]]
    assert triangulate_within(square, lambda c: False) is None
    # a C-shaped ring: the triangles lie inside it and fill it (doubled areas add up)
    c = [(0, 0), (4, 0), (4, 1), (1, 1), (1, 3), (4, 3), (4, 4), (0, 4)]
    cut = triangulate_within(c, lambda t: True)
    area2 = sum(orient(c[i], c[j], c[k]) for i, j, k in cut)
    assert len(cut) == len(c) - 2 and area2 == 2 * (16 - 6)


def test_cli_mesh_check_min_area(tmp_path, capsys):
    z = motorcycle_crop()
    src = tmp_path / "disp.npy"
    np.save(src, z)
    out = tmp_path / "m.obj"
    assert main(["mesh", str(src), "-o", str(out), "--nodata", "hole", "-q"]) == 0
    assert main(["check", str(out), "--against", str(src), "--nodata", "hole"]) == 0
    assert "of the valid samples" in capsys.readouterr().out
    # the same file against the filled input is no triangulation of the rectangle
    assert main(["check", str(out), "--against", str(src), "--fill", "nearest", "-q"]) == 1
    small = tmp_path / "s.obj"
    assert main(["mesh", str(src), "-o", str(small), "--nodata", "hole", "--min-area", "40", "-q"]) == 0
    from wavemesh.io.meshread import read_mesh

    big, _ = read_mesh(str(out), 96, 72)
    kept, _ = read_mesh(str(small), 96, 72)
    assert kept.n_triangles < big.n_triangles
    # the check knows what --min-area drops: uncovered groups of at most 2A + 2 valid samples
    mask = from_array(z, holes=True).mask
    assert check.check_holes(kept, mask, min_area=40).valid_mesh
    assert main(["check", str(small), "--against", str(src), "--nodata", "hole", "--min-area", "40"]) == 0


def enclosed_groups(invalid: np.ndarray) -> list[list[tuple[int, int]]]:
    """The 8-connected groups of invalid samples that touch no side of the grid, by a breadth-first walk."""
    H, W = invalid.shape
    seen = np.zeros_like(invalid)
    out = []
    for y0, x0 in np.argwhere(invalid):
        if seen[y0, x0]:
            continue
        group, todo, seen[y0, x0] = [], [(y0, x0)], True
        while todo:
            y, x = todo.pop()
            group.append((y, x))
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    b, a = y + dy, x + dx
                    if 0 <= b < H and 0 <= a < W and invalid[b, a] and not seen[b, a]:
                        seen[b, a] = True
                        todo.append((b, a))
        if all(0 < y < H - 1 and 0 < x < W - 1 for y, x in group):
            out.append(group)
    return out


def test_max_hole_bridges_small_dropouts(tmp_path, capsys):
    # --max-hole N: the enclosed dropouts of at most N samples are filled as --fill nearest fills them, the
    # others stay holes; the mesh covers the bridged samples and no other invalid one
    z = motorcycle_crop()
    src = tmp_path / "disp.npy"
    np.save(src, z)
    invalid = ~np.isfinite(z)
    small = [g for g in enclosed_groups(invalid) if len(g) <= 4]
    bridged = invalid.copy()
    for g in small:
        for y, x in g:
            bridged[y, x] = False
    n = sum(map(len, small))
    assert 0 < n < invalid.sum()
    hf = api.load_input(str(src), nodata="hole", max_hole=4)
    assert hf.filled == n
    filled = from_array(z, fill="nearest").values
    assert np.array_equal(hf.values[~bridged], filled[~bridged])  # the bridged heights as --fill nearest's
    r = api.mesh(hf, api.MeshParams(refine=RefineParams(zeta=ZETA)))
    got = independent_check(r.mesh, bridged, r.heightfield.values, ZETA)
    assert got["uncovered_valid"] == 0  # the bridged samples covered too (the bench counts triangles)
    out = tmp_path / "m.obj"
    assert main(["mesh", str(src), "-o", str(out), "--nodata", "hole", "--max-hole", "4"]) == 0
    assert f"filled: {n} invalid samples" in capsys.readouterr().out
    assert main(["check", str(out), "--against", str(src), "--nodata", "hole", "--max-hole", "4"]) == 0
    assert f"filled: {n} invalid samples" in capsys.readouterr().out
    assert main(["check", str(out), "--against", str(src), "--nodata", "hole", "-q"]) == 1  # over dropouts


@pytest.mark.parametrize("argv, what", [
    (["--fill", "nearest", "--nodata", "hole"], "both say"),
    (["--min-area", "5", "--fill", "nearest"], "--min-area"),
    (["--nodata", "hole", "--invalid", "nan"], "--invalid"),
    (["--fill", "nearest", "--max-hole", "4"], "--max-hole"),
    (["--nodata", "hole", "--max-hole", "-1"], "--max-hole"),
])
def test_bad_options(tmp_path, capsys, argv, what):
    z = shadowed_ball(16)
    src = tmp_path / "z.npy"
    np.save(src, z)
    assert main(["mesh", str(src), "-o", str(tmp_path / "x.obj"), *argv]) != 0
    err = capsys.readouterr().err
    assert err.startswith("error:") and what in err
    assert not (tmp_path / "x.obj").exists()


def test_all_invalid_and_crop():
    with pytest.raises(InputError, match="invalid"):
        from_array(np.full((4, 4), np.nan), holes=True)
    z = shadowed_ball()
    hf = api.load_input  # crop keeps the mask of the samples it takes
    full = from_array(z, holes=True)
    part = api.shape_heightfield(full, crop="10,5,30,30")
    assert np.array_equal(part.mask, full.mask[5:35, 10:40])
    # and takes in the samples stranded at its edges (real dropouts)
    full = from_array(motorcycle_crop(), holes=True)
    part = api.shape_heightfield(full, crop="10,5,40,30")
    cut = full.mask[5:35, 10:50]
    lone = full.lone[5:35, 10:50] | lone_samples(cut)
    assert np.array_equal(part.mask, cut | lone) and part.stranded == np.count_nonzero(lone) > 0
    assert hf is not None



def test_block_flags_against_a_loop():
    from wavemesh.model.label import block_edges

    rng = np.random.default_rng(3)
    m = rng.random((37, 29)) < 0.01
    for levels in (1, 2, 3):
        got = holemask.block_flags(m, levels)
        xs, ys = block_edges(29, 1 << levels), block_edges(37, 1 << levels)
        want = [[m[ys[j]:ys[j + 1] + 1, xs[i]:xs[i + 1] + 1].any() for i in range(len(xs) - 1)]
                for j in range(len(ys) - 1)]
        assert np.array_equal(got, np.array(want))
