"""`wavemesh stream --tile` of an input larger than the device (wavemesh.tiles): tiles one after another on
one native stand-in device, on two at once, and with a device that dies mid-run (its tile retried on the
other, and said so): the same bytes every time, and the same as `wavemesh mesh --tile`."""

from __future__ import annotations

import numpy as np
import pytest
from wavemesh import api, tiles
from wavemesh.device.stream import DEFAULT_TIMEOUTS
from wavemesh.harness import jacksboro, run_cli
from wavemesh.harness.nativedev import NativeDevice, build_wmdev
from wavemesh.refine.native import RefineParams

SMALL = ("--tri-capacity", "60000", "--max-width", "128", "--max-height", "128")


@pytest.fixture(scope="module")
def devices():
    exe = build_wmdev()
    ds = [NativeDevice(exe, *SMALL), NativeDevice(exe, *SMALL)]
    yield ds
    for d in ds:
        d.stop()


@pytest.fixture(scope="module")
def dem(tmp_path_factory):
    hf = api.load_input(jacksboro(), key="elevation", crop="20,10,240,200")
    path = tmp_path_factory.mktemp("tiles") / "j.npy"
    np.save(path, hf.values)
    return path


def test_two_devices_equal_one_and_mesh(devices, dem, tmp_path):
    a, b = (d.url for d in devices)
    common = ("--zeta", "2", "--spacing", "10", "-q")
    rc, _, err = run_cli("stream", str(dem), "--port", a, "-o", str(tmp_path / "one.obj"), *common)
    assert rc == 2 and "holds at most 128 x 128" in err  # without --tile: too large, as before
    rc, _, err = run_cli("stream", str(dem), "--port", a, "--tile", "128", "-o", str(tmp_path / "one.obj"),
                         *common)
    assert rc == 0, err
    # two devices: the tile size from their capacity (128)
    rc, _, err = run_cli("stream", str(dem), "--port", a, "--port", b, "-o", str(tmp_path / "two.obj"),
                         *common)
    assert rc == 0, err
    rc, _, err = run_cli("mesh", str(dem), "--tile", "128", "--workers", "1", "-o",
                         str(tmp_path / "mesh.obj"), *common)
    assert rc == 0, err
    one = (tmp_path / "one.obj").read_bytes()
    assert one == (tmp_path / "two.obj").read_bytes() == (tmp_path / "mesh.obj").read_bytes()
    rc, out, err = run_cli("check", str(tmp_path / "two.obj"), "--against", str(dem), "--spacing", "10")
    assert rc == 0 and "a proper triangulation" in out, out + err


def test_failed_device_tile_retried_on_another(dem, tmp_path):
    """The second device is killed after its first tile: its next tile fails (nothing answers) and is
    made by the first device; the mesh is the same."""
    exe = build_wmdev()
    good, bad = NativeDevice(exe, *SMALL), NativeDevice(exe, *SMALL)
    try:
        src = tiles.open_source(str(dem), spacing="10")
        plan = tiles.plan_tiles(src, api.MeshParams(refine=RefineParams(zeta=2.0)), 128)
        lines = []

        def log(text: str) -> None:
            lines.append(text)
            if f"on {bad.url}:" in text and bad.alive():
                bad.stop()  # after its first tile: the next one finds no device

        timeouts = DEFAULT_TIMEOUTS
        both = tiles.stream_tiles(plan, [good.url, bad.url], baud=115200, timeouts=timeouts, log=log)
        failed = [ln for ln in lines if ln.startswith("warning:")]
        assert len(failed) == 1 and f"failed on {bad.url}" in failed[0] and "retrying it on another device" \
            in failed[0], lines
        assert {r.device for r in both} == {good.url, bad.url}
        here = tiles.run_tiles(plan, workers=1)  # = one device (the other test)
        m1, m2 = tiles.stitch(plan, both).mesh, tiles.stitch(plan, here).mesh
        assert np.array_equal(m1.xy, m2.xy) and np.array_equal(m1.tris, m2.tris)
    finally:
        good.stop()
        bad.stop()
