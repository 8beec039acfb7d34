"""Tests for wavemesh.check.render: pictures of meshes (checked through their pixels with Pillow)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from PIL import Image
from wavemesh.check import render
from wavemesh.check.render import render_grid, render_heightfield, render_mesh
from wavemesh.errors import InputError
from wavemesh.mesh import Mesh


def grid(w: int, h: int) -> Mesh:
    """A regular w x h grid mesh, two counter-clockwise triangles per cell (built independently)."""
    xy = [(x, y) for y in range(h) for x in range(w)]
    tris = []
    for y in range(h - 1):
        for x in range(w - 1):
            a, b, c, d = y * w + x, y * w + x + 1, (y + 1) * w + x, (y + 1) * w + x + 1
            tris += [(a, b, d), (a, d, c)]
    return Mesh(w, h, np.array(xy), np.array(tris))


def ccw(mesh: Mesh) -> np.ndarray:
    p = mesh.xy[mesh.tris]
    return (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (
        p[:, 1, 1] - p[:, 0, 1]
    )


def load(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def cyanish(a: np.ndarray) -> np.ndarray:
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return (r < 90) & (g > 140) & (b > 140)


def magentaish(a: np.ndarray) -> np.ndarray:
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return (g < 90) & (r > 140) & (b > 140)


def dark(a: np.ndarray) -> np.ndarray:
    return a.max(axis=-1) < 60


def n_colours(a: np.ndarray) -> int:
    return len(np.unique(a.reshape(-1, 3), axis=0))


def test_helper_grid_is_ccw():
    assert (ccw(grid(5, 4)) > 0).all()
    assert (ccw(render.grid_mesh(np.arange(0, 9, 2), np.array([0, 3, 5]), 9, 6)) > 0).all()


@pytest.mark.parametrize("view", ["3d", "top"])
def test_png_size_and_not_blank(tmp_path, view):
    m = grid(9, 7)
    z = m.xy[:, 0] * 2.0 + m.xy[:, 1]
    out = tmp_path / f"m_{view}.png"
    render_mesh(m, z, str(out), view=view, size=(320, 240))
    img = Image.open(out)
    assert img.size == (320, 240)
    a = load(out)
    assert n_colours(a) > 10
    assert (a == 255).all(axis=-1).mean() > 0.05  # white background around the drawing
    assert (a != 255).any(axis=-1).mean() > 0.2  # the mesh covers a good part of the picture


@pytest.mark.parametrize("size", [(801, 333), (161, 97)])
def test_odd_sizes_exact(tmp_path, size):
    m = grid(4, 4)
    out = tmp_path / "odd.png"
    render_mesh(m, m.xy[:, 0].astype(float), out, size=size, title="odd")
    assert Image.open(out).size == size


@pytest.mark.parametrize("view", ["3d", "top"])
def test_low_cyan_high_magenta(tmp_path, view):
    m = grid(12, 12)
    z = (m.xy[:, 0] + m.xy[:, 1]).astype(float) * 5.0
    out = tmp_path / "ramp.png"
    render_mesh(m, z, out, view=view, wireframe=False, size=(400, 300))
    a = load(out)
    assert cyanish(a).sum() > 100
    assert magentaish(a).sum() > 100


def test_wireframe_dark_pixels(tmp_path):
    m = grid(10, 10)
    z = np.sin(m.xy[:, 0] / 2.0) * 3.0 + m.xy[:, 1] * 0.5
    on, off = tmp_path / "on.png", tmp_path / "off.png"
    for view in ("3d", "top"):
        render_mesh(m, z, on, view=view, wireframe=True, size=(400, 300))
        render_mesh(m, z, off, view=view, wireframe=False, size=(400, 300))
        d_on, d_off = dark(load(on)).sum(), dark(load(off)).sum()
        assert d_on > 300, (view, d_on)
        assert d_off * 20 <= d_on, (view, d_on, d_off)


def test_top_view_left_low_right_high(tmp_path):
    m = grid(16, 10)
    z = np.where(m.xy[:, 0] >= 8, 100.0, 0.0)
    out = tmp_path / "halves.png"
    render_mesh(m, z, out, view="top", wireframe=True, size=(400, 300))
    a = load(out)
    left, right = a[:, :200], a[:, 200:]
    assert cyanish(left).sum() > 5 * max(1, magentaish(left).sum())
    assert magentaish(right).sum() > 5 * max(1, cyanish(right).sum())


def test_top_view_row0_at_top(tmp_path):
    m = grid(10, 16)
    z = np.where(m.xy[:, 1] < 8, 100.0, 0.0)  # high rows 0..7
    out = tmp_path / "rows.png"
    render_mesh(m, z, out, view="top", size=(300, 400))
    a = load(out)
    ym = np.nonzero(magentaish(a))[0].mean()
    yc = np.nonzero(cyanish(a))[0].mean()
    assert ym < yc


def test_3d_view_orientation(tmp_path):
    # Row 0 is at the back (higher up in the picture), x grows to the right.
    m = grid(12, 12)
    out = tmp_path / "o.png"
    render_mesh(m, np.where(m.xy[:, 1] < 6, 10.0, 0.0), out, wireframe=False, size=(400, 300))
    a = load(out)
    assert np.nonzero(magentaish(a))[0].mean() < np.nonzero(cyanish(a))[0].mean()
    render_mesh(m, np.where(m.xy[:, 0] >= 6, 10.0, 0.0), out, wireframe=False, size=(400, 300))
    a = load(out)
    assert np.nonzero(magentaish(a))[1].mean() > np.nonzero(cyanish(a))[1].mean()


def test_3d_painter_front_peak_hides_back(tmp_path):
    # A tall wall along the front rows must hide the (magenta-free) back of the grid behind it:
    # rendering the wall after or before the rest must not matter (triangle order is irrelevant).
    m = grid(12, 12)
    z = np.where(m.xy[:, 1] >= 9, 50.0, 0.0)
    m_rev = Mesh(m.width, m.height, m.xy, m.tris[::-1])
    a1, a2 = tmp_path / "a1.png", tmp_path / "a2.png"
    render_mesh(m, z, a1, wireframe=False, size=(300, 200))
    render_mesh(m_rev, z, a2, wireframe=False, size=(300, 200))
    assert np.abs(load(a1) - load(a2)).max() <= 2


def test_lambert_light_from_north_west(tmp_path):
    # A symmetric valley along x: the east-facing slope (left) is darker than the west-facing one (right).
    m = grid(21, 11)
    z = np.abs(m.xy[:, 0] - 10).astype(float)
    out = tmp_path / "valley.png"
    render_mesh(m, z, out, view="top", wireframe=False, size=(420, 220))
    a = load(out)
    mesh_px = (a != 255).any(axis=-1)
    brightness = a.sum(axis=-1)
    cols = np.arange(a.shape[1])
    xs = cols[mesh_px.any(axis=0)]
    mid = (xs.min() + xs.max()) // 2
    left = brightness[:, :mid][mesh_px[:, :mid]].mean()
    right = brightness[:, mid:][mesh_px[:, mid:]].mean()
    assert right > left + 20


@pytest.mark.parametrize("view", ["3d", "top"])
def test_flat_mesh(tmp_path, view):
    m = grid(6, 5)
    out = tmp_path / "flat.png"
    render_mesh(m, np.full(m.n_vertices, 7.0), out, view=view, size=(200, 150))
    a = load(out)
    assert a.shape == (150, 200, 3)
    assert (a != 255).any(axis=-1).sum() > 1000


def test_zscale_changes_3d_picture(tmp_path):
    m = grid(8, 8)
    z = np.sin(m.xy[:, 0].astype(float))
    p1, p2 = tmp_path / "z1.png", tmp_path / "z2.png"
    render_mesh(m, z, p1, zscale=0.1, size=(200, 150))
    render_mesh(m, z, p2, zscale=3.0, size=(200, 150))
    assert not np.array_equal(load(p1), load(p2))


def test_svg_and_pdf(tmp_path):
    m = grid(4, 4)
    z = m.xy[:, 0].astype(float)
    render_mesh(m, z, tmp_path / "m.svg")
    render_mesh(m, z, tmp_path / "m.pdf", view="top")
    assert (tmp_path / "m.svg").read_text().lstrip().startswith("<?xml")
    assert (tmp_path / "m.pdf").read_bytes().startswith(b"%PDF")


def test_bad_directory(tmp_path):
    m = grid(3, 3)
    with pytest.raises(InputError) as e:
        render_mesh(m, np.zeros(9), str(tmp_path / "missing" / "x.png"))
    assert "\n" not in str(e.value) and "missing" in str(e.value)
    with pytest.raises(InputError):
        render_heightfield(np.zeros((4, 4)), tmp_path / "missing" / "x.png")
    with pytest.raises(InputError):
        render_grid([(m, np.zeros(9), "a")], tmp_path / "missing" / "x.png")


def test_bad_extension_and_view(tmp_path):
    m = grid(3, 3)
    with pytest.raises(InputError):
        render_mesh(m, np.zeros(9), tmp_path / "x.notapicture")
    with pytest.raises(InputError):
        render_mesh(m, np.zeros(9), tmp_path / "x.png", view="side")


def test_z_length_mismatch(tmp_path):
    with pytest.raises(ValueError):
        render_mesh(grid(3, 3), np.zeros(8), tmp_path / "x.png")


def test_render_grid_size(tmp_path):
    rng = np.random.default_rng(0)
    items = []
    for k in range(11):
        m = grid(3 + k % 3, 4)
        items.append((m, rng.normal(size=m.n_vertices), f"t{k}"))
    out = tmp_path / "sheet.png"
    render_grid(items, out, cols=4, cell_px=100)
    assert Image.open(out).size == (4 * 100, 3 * 100)
    a = load(out)
    # every cell, including the last (11th), has something drawn in it; the 12th cell is empty
    for k in range(12):
        r, c = divmod(k, 4)
        cell = a[r * 100 + 15:(r + 1) * 100, c * 100:(c + 1) * 100]
        drawn = (cell != 255).any(axis=-1).sum()
        assert (drawn > 500) == (k < 11), (k, drawn)

    out2 = tmp_path / "sheet2.png"
    render_grid(items[:3], out2, view="3d", wireframe=False, cell_px=80)  # fewer items than cols
    assert Image.open(out2).size == (3 * 80, 80)


def test_render_grid_empty(tmp_path):
    with pytest.raises(InputError):
        render_grid([], tmp_path / "x.png")


def test_render_heightfield_subsamples(tmp_path, monkeypatch):
    yy, xx = np.mgrid[0:601, 0:450]
    hf = np.sin(xx / 40.0) + yy / 300.0
    seen = {}
    real = render.render_mesh

    def spy(mesh, z, path, **kw):
        seen["mesh"], seen["z"], seen["kw"] = mesh, z, kw
        real(mesh, z, path, **kw)

    monkeypatch.setattr(render, "render_mesh", spy)
    out = tmp_path / "hf.png"
    render_heightfield(hf, out, view="top", wireframe=False, size=(300, 400))
    mesh = seen["mesh"]
    assert (mesh.width, mesh.height) == (450, 601)
    assert mesh.n_triangles <= 2 * 205 * 205
    assert mesh.xy[:, 0].max() == 449 and mesh.xy[:, 1].max() == 600  # borders kept
    assert (ccw(mesh) > 0).all()
    np.testing.assert_array_equal(seen["z"], hf[mesh.xy[:, 1], mesh.xy[:, 0]])
    assert seen["kw"]["view"] == "top"
    assert Image.open(out).size == (300, 400)


def test_render_heightfield_small(tmp_path):
    out = tmp_path / "small.png"
    render_heightfield(np.arange(20.0).reshape(4, 5), out, size=(200, 100))
    a = load(out)
    assert a.shape == (100, 200, 3) and n_colours(a) > 5


def test_threads(tmp_path):
    m = grid(8, 8)
    z = m.xy[:, 0] * 1.0
    errors = []

    def work(i):
        try:
            render_mesh(m, z, tmp_path / f"t{i}.png", view="3d" if i % 2 else "top", size=(160, 120))
        except Exception as e:  # noqa: BLE001
            errors.append(e)

    ts = [threading.Thread(target=work, args=(i,)) for i in range(6)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert not errors
    ref = load(tmp_path / "t0.png")
    for i in (2, 4):
        assert np.array_equal(load(tmp_path / f"t{i}.png"), ref)


def test_100k_triangles_fast(tmp_path):
    w, h = 225, 225  # 2 * 224 * 224 = 100352 triangles
    m = render.grid_mesh(np.arange(w), np.arange(h), w, h)
    assert m.n_triangles >= 100_000
    z = np.sin(m.xy[:, 0] / 9.0) * np.cos(m.xy[:, 1] / 13.0)
    t0 = time.perf_counter()
    render_mesh(m, z, tmp_path / "big.png", view="3d", wireframe=True)
    elapsed = time.perf_counter() - t0
    assert elapsed < 15.0, elapsed
