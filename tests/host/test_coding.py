"""The compact coding of DATA's samples (wavemesh.device.coding, docs/protocol.md "Sample coding"): every
frame the
encoder cuts decodes, by the reference decoder, to the samples (smooth, noisy, random, steps, wrap-around);
incompressible samples cost no more than raw words; a real DEM costs under a byte a sample.  The device's
decoder (proto_data.c) is checked end to end by every stream test (RUN's CRC and the meshes)."""

from __future__ import annotations

import numpy as np
import pytest
from wavemesh.device import coding as C
from wavemesh.device import protocol as P
from wavemesh.harness import jacksboro

RNG = np.random.default_rng(20261127)
CASES = {
    "random": RNG.integers(0, 65536, (9, 37)),
    "ramp": np.add.outer(np.arange(23) * 301, np.arange(41) * 7),
    "walk": np.cumsum(RNG.integers(-40, 41, (31, 29)), axis=1) + 30000,
    "steps": np.where(np.add.outer(np.arange(17), np.arange(19)) > 15, 65535, 0),
    "one row": RNG.integers(0, 100, (1, 50)),
    "one column": RNG.integers(0, 100, (50, 1)),
}


def roundtrip(a: np.ndarray, budget: int) -> tuple[np.ndarray, int, int]:
    enc = C.SampleEncoder(a)
    out = np.zeros(a.size, np.uint16)
    start = tail_bytes = 0
    frames = 0
    while start < enc.n:
        n, coding, tail = enc.frame(start, budget)
        assert 1 <= n and len(tail) <= max(budget, 2 * P.RICE_BLOCK)
        if coding == P.CODING_RAW:
            assert len(tail) == 2 * n
            out[start:start + n] = np.frombuffer(tail, "<u2")
        else:
            assert len(tail) < 2 * n
            C.decode(tail, start, n, out, a.shape[1])
        start += n
        tail_bytes += len(tail)
        frames += 1
    return out, tail_bytes, frames


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("budget", [64, 1016])
def test_every_frame_decodes_to_the_samples(name, budget):
    a = (CASES[name] & 0xFFFF).astype(np.uint16)
    out, tail, _ = roundtrip(a, budget)
    assert np.array_equal(out, a.ravel())
    assert tail <= 2 * a.size  # never more than raw words


def test_a_damaged_stream_is_refused():
    a = CASES["walk"].astype(np.uint16)
    n, coding, tail = C.SampleEncoder(a).frame(0, 1016)
    assert coding == P.CODING_RICE
    with pytest.raises(ValueError):
        C.decode(tail[:-3], 0, n, np.zeros(a.size, np.uint16), a.shape[1])
    with pytest.raises(ValueError):
        C.decode(tail + b"\0", 0, n, np.zeros(a.size, np.uint16), a.shape[1])


def test_a_real_dem_costs_under_a_byte_a_sample():
    from wavemesh.io.heightfield import load_heightfield as load

    hf = load(jacksboro(), key="elevation")
    part = hf.samples[:24]  # the reference decoder (a loop over bits) on a strip
    out, _, _ = roundtrip(part, P.MAX_PAYLOAD - P.DATA.size)
    assert np.array_equal(out, part.ravel())
    enc, start, tail = C.SampleEncoder(hf.samples), 0, 0
    while start < enc.n:
        n, _, t = enc.frame(start, P.MAX_PAYLOAD - P.DATA.size)
        start, tail = start + n, tail + len(t)
    assert tail / hf.samples.size < 0.7  # 0.65 (bench/bench_link.py reports the wire bytes)


def test_level_bodies_decode_to_their_numbers():
    """LEVEL_DELTA: the vertex slots (free ones too) and triangles come back as they went, and a damaged
    body is refused (the device's coder, proto_emit.c's code_item, is checked end to end by the stream
    tests)."""
    rng = np.random.default_rng(5)
    xy = rng.integers(0, 1024, (300, 2))
    xy[rng.random(300) < 0.1] = P.FREE_VERTEX
    tris = rng.integers(0, 300, (500, 3))
    body = C.encode_level_body(xy, tris)
    got_xy, got_tris = C.decode_level_body(body, 300, 500)
    assert np.array_equal(got_xy, xy) and np.array_equal(got_tris, tris)
    assert len(body) < 4 * 300 + 3 * 2 * 500  # shorter than raw even for random numbers of this range
    for bad in (body[:-1], body + b"\x00", body[:-2] + b"\xff\xff"):
        with pytest.raises(ValueError):
            C.decode_level_body(bad, 300, 500)
    assert C.decode_level_body(b"", 0, 0)[0].shape == (0, 2)
