"""`wavemesh stream --nodata hole` (issue 20): the validity mask goes over the wire after the samples
(CONFIG_MASK, protocol.job_words) and the device's refiner measures E(T) against it, so the mesh it
streams is `wavemesh mesh --nodata hole`'s, byte for byte: through the native stand-in device and
through the simulated board (the FPGA stage in RTL, the refiner on the soft CPU)."""

from __future__ import annotations

import filecmp

import numpy as np
import pytest
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.harness import run_cli
from wavemesh.harness.nativedev import NativeDevice, build_wmdev
from wavemesh.io.synth import make


def shadowed(name: str, n: int, crop) -> np.ndarray:
    """A synthetic set with a scanner's shadow (NaN where a ray from the left, falling 3 height ranges
    across the grid, does not reach), cropped; and a 0 sentinel for --invalid 0."""
    z = make(name, n).astype(np.float64)
    fall = 3.0 * float(z.max() - z.min()) / n * np.arange(n)[None, :]
    z[z + fall < np.maximum.accumulate(z + fall, axis=1) - 1e-9] = np.nan
    return z[crop]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("holes_inputs")
    np.save(d / "ball.npy", shadowed("ball", 64, np.s_[8:48, 10:60]))  # 50 x 40
    np.save(d / "tiny.npy", shadowed("box", 32, np.s_[4:20, 8:30]))  # 22 x 16
    speckled = shadowed("ball", 64, np.s_[8:48, 10:60])
    rng = np.random.default_rng(5)
    speckled[rng.integers(2, 38, 40), rng.integers(2, 48, 40)] = np.nan  # dropouts of a sample or a few
    np.save(d / "speckled.npy", speckled)
    return d


def same_files(tmp_path, src, port: str, opts: list[str], read: tuple[str, ...] = ()) -> None:
    """``read``: the input options `check` needs too."""
    a, b = tmp_path / "mesh.obj", tmp_path / "stream.obj"
    rc, _, err = run_cli("mesh", str(src), "--nodata", "hole", *read, *opts, "-o", str(a), "-q")
    assert rc == 0, err
    rc, _, err = run_cli("stream", str(src), "--nodata", "hole", *read, *opts, "--port", port, "-o", str(b),
                         "-q")
    assert rc == 0, err
    assert filecmp.cmp(a, b, shallow=False)
    rc, out, err = run_cli("check", str(b), "--against", str(src), "--nodata", "hole", *read)
    assert rc == 0 and "of the valid samples" in out, out + err


def test_mask_words_are_the_packed_mask():
    rng = np.random.default_rng(7)
    s = rng.integers(0, 65536, (5, 7), dtype=np.uint16)
    m = rng.random((5, 7)) < 0.4
    w = P.job_words(s, m)
    assert len(w) == 35 + P.mask_words(7, 5) and np.array_equal(w[:35], s.ravel())
    bits = np.unpackbits(w[35:].astype("<u2").view(np.uint8), bitorder="little")[:35]
    assert np.array_equal(bits.astype(bool), m.ravel())


@pytest.fixture(scope="module")
def device():
    d = NativeDevice(build_wmdev(), "--tri-capacity", "20000")
    yield d
    d.stop()


def test_native_device_streams_the_hole_mesh(device, inputs, tmp_path):
    same_files(tmp_path, inputs / "ball.npy", device.url, [])


def test_native_device_invalid_sentinel_and_min_area(device, inputs, tmp_path):
    z = np.load(inputs / "ball.npy")
    z[~np.isfinite(z)] = 0.0
    np.save(tmp_path / "zero.npy", z)
    same_files(tmp_path, tmp_path / "zero.npy", device.url, ["--min-area", "20"], ("--invalid", "0"))


def test_native_device_max_hole(device, inputs, tmp_path):
    # --max-hole bridges the small dropouts before the job: the device gets the bridged mask
    same_files(tmp_path, inputs / "speckled.npy", device.url, [], ("--max-hole", "2"))
    rc, out, _ = run_cli("check", str(tmp_path / "stream.obj"), "--against", str(inputs / "speckled.npy"),
                         "--nodata", "hole", "--max-hole", "2")
    assert rc == 0 and "filled: " in out and "filled: 0 " not in out


def test_a_device_without_holes_refuses(inputs, tmp_path, monkeypatch):
    # a HELLO_REPLY without FEATURE_HOLES: one error line, before CONFIG
    real = S.Device.sync

    def sync(self):
        info = real(self)
        object.__setattr__(info, "features", info.features & ~P.FEATURE_HOLES)
        return info

    monkeypatch.setattr(S.Device, "sync", sync)
    d = NativeDevice(build_wmdev())
    try:
        rc, _, err = run_cli("stream", str(inputs / "tiny.npy"), "--nodata", "hole", "--port", d.url,
                             "-o", str(tmp_path / "x.obj"), "-q")
    finally:
        d.stop()
    assert rc != 0 and err.startswith("error: --nodata hole") and not (tmp_path / "x.obj").exists()


@pytest.mark.sim
def test_board_streams_the_hole_mesh(sim_exe, firmware_hex, inputs, tmp_path, monkeypatch):
    from wavemesh.harness.simboard import SIM_TIMEOUTS, SimBoard

    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", SIM_TIMEOUTS)
    b = SimBoard(sim_exe, firmware_hex, "--port", "0", "--fast", "--quiet")
    try:
        same_files(tmp_path, inputs / "tiny.npy", b.url, ["--reduce", "off", "--simplify", "off"])
    finally:
        b.stop()
