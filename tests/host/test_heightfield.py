"""Height field reading (every format), validation, --fill and 16-bit quantisation.

The GDAL formats beyond TIFF and ESRI ASCII (SRTM .hgt, .img, .bil, .vrt) and `wavemesh mesh` on
them are in test_heightfield_gdal.py.
"""

import json
import os

import numpy as np
import pytest
import rasterio
import tifffile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image
from rasterio.transform import Affine
from wavemesh.errors import InputError
from wavemesh.io.heightfield import (
    HeightField,
    fill_nearest,
    from_array,
    load_heightfield,
    parse_fill,
    quantise,
)

# ---------------------------------------------------------------------------
# helpers


def write_pgm_p5(path, arr, maxval=None, comment=True):
    arr = np.asarray(arr)
    h, w = arr.shape
    maxval = int(arr.max()) if maxval is None else maxval
    header = b"P5\n" + (b"# written by a test\n" if comment else b"") + f"{w} {h}\n{maxval}\n".encode()
    data = arr.astype(">u2" if maxval > 255 else np.uint8).tobytes()
    path.write_bytes(header + data)
    return path


def write_pgm_p2(path, arr, maxval=None):
    arr = np.asarray(arr)
    h, w = arr.shape
    maxval = int(arr.max()) if maxval is None else maxval
    lines = ["P2", "# a comment", f"{w}  # width", f"{h}", f"{maxval}"]
    lines += [" ".join(str(int(v)) for v in row) for row in arr]
    path.write_text("\n".join(lines) + "\n")
    return path


def one_line_error(func, *args, match=None, **kw):
    """Call func, expect an InputError with a non-empty one-line message; return the message."""
    with pytest.raises(InputError) as info:
        func(*args, **kw)
    msg = str(info.value)
    assert msg and "\n" not in msg and "\r" not in msg, repr(msg)
    assert msg == info.value.message
    if match is not None:
        for word in [match] if isinstance(match, str) else match:
            assert word.lower() in msg.lower(), (word, msg)
    return msg


def brute_nearest_sets(bad):
    """Reference, by brute force: for every bad sample, the set of good samples nearest to it
    (exact squared Euclidean distance in integers), as {(row, col): {(row, col), ...}}."""
    gr, gc = np.nonzero(~bad)
    nearest = {}
    for r, c in zip(*np.nonzero(bad), strict=True):
        d2 = (gr - r) ** 2 + (gc - c) ** 2
        k = np.nonzero(d2 == d2.min())[0]
        nearest[(int(r), int(c))] = set(zip(gr[k].tolist(), gc[k].tolist(), strict=True))
    return nearest


def assert_nearest_fill(values, bad, filled):
    """Every good sample kept; every bad one holds the value of one of its nearest good samples.

    ``values`` must be distinct, so a filled value names the sample it was taken from; that sample
    is returned per bad sample, {(row, col): (row, col)}."""
    assert len(np.unique(values)) == values.size
    assert np.array_equal(filled[~bad], values[~bad])
    where = {float(v): (int(r), int(c)) for (r, c), v in np.ndenumerate(values)}
    taken = {}
    for (r, c), nearest in brute_nearest_sets(bad).items():
        src = where[float(filled[r, c])]
        assert src in nearest, ((r, c), src, nearest)
        taken[(r, c)] = src
    return taken


# ---------------------------------------------------------------------------
# round trips, one per format


def test_npy_round_trip_int(tmp_path):
    a = np.arange(37 * 53, dtype=np.int32).reshape(37, 53)
    np.save(tmp_path / "a.npy", a)
    hf = load_heightfield(str(tmp_path / "a.npy"))
    assert isinstance(hf, HeightField)
    assert (hf.width, hf.height) == (53, 37)
    assert hf.values.dtype == np.float64 and hf.samples.dtype == np.uint16
    assert np.array_equal(hf.values, a) and np.array_equal(hf.samples, a)
    assert hf.lossless and hf.scale == 1.0 and hf.offset == 0.0 and hf.filled == 0
    assert hf.source == str(tmp_path / "a.npy")


def test_npy_accepts_pathlike_and_float(tmp_path):
    a = np.linspace(-3.5, 7.25, 12).reshape(3, 4)
    np.save(tmp_path / "f.npy", a)
    hf = load_heightfield(tmp_path / "f.npy")
    assert np.array_equal(hf.values, a)
    assert not hf.lossless and hf.offset == -3.5


def test_npz_with_and_without_key(tmp_path):
    a = np.arange(6).reshape(2, 3)
    b = np.arange(12).reshape(3, 4) * 2
    np.savez(tmp_path / "one.npz", dem=a)
    hf = load_heightfield(str(tmp_path / "one.npz"))
    assert np.array_equal(hf.values, a)
    np.savez(tmp_path / "two.npz", a=a, b=b)
    hf = load_heightfield(str(tmp_path / "two.npz"), key="b")
    assert np.array_equal(hf.values, b) and (hf.width, hf.height) == (4, 3)
    msg = one_line_error(load_heightfield, str(tmp_path / "two.npz"), match=["--key", "a, b"])
    assert "2 arrays" in msg
    one_line_error(load_heightfield, str(tmp_path / "two.npz"), key="c", match=["'c'", "a, b"])


def test_npz_compressed(tmp_path):
    a = np.arange(100).reshape(10, 10)
    np.savez_compressed(tmp_path / "c.npz", x=a)
    assert np.array_equal(load_heightfield(str(tmp_path / "c.npz"), key="x").samples, a)


def test_pgm_p5_8bit(tmp_path):
    a = np.arange(20, dtype=np.uint8).reshape(4, 5) * 12
    hf = load_heightfield(str(write_pgm_p5(tmp_path / "a.pgm", a, maxval=255)))
    assert np.array_equal(hf.samples, a) and hf.lossless


def test_pgm_p5_16bit_big_endian(tmp_path):
    a = np.array([[0, 1, 256, 65535], [258, 4660, 513, 40000], [7, 8, 9, 10]], dtype=np.uint16)
    path = write_pgm_p5(tmp_path / "a16.PGM", a, maxval=65535)
    hf = load_heightfield(str(path))
    assert np.array_equal(hf.samples, a)
    assert np.array_equal(hf.values, a.astype(float))
    assert hf.lossless and hf.offset == 0.0 and hf.scale == 1.0


def test_pgm_p2_with_comments(tmp_path):
    a = np.array([[1, 2, 3], [400, 500, 600]])
    hf = load_heightfield(str(write_pgm_p2(tmp_path / "a.pgm", a, maxval=1000)))
    assert np.array_equal(hf.values, a)


def test_pgm_p2_numbers_span_lines(tmp_path):
    (tmp_path / "s.pgm").write_text("P2 3 2 9\n1 2\n3 4 5 # comment in data\n6\n")
    assert np.array_equal(load_heightfield(str(tmp_path / "s.pgm")).values, [[1, 2, 3], [4, 5, 6]])


def test_png_8bit(tmp_path):
    a = (np.arange(35).reshape(5, 7) * 7).astype(np.uint8)
    Image.fromarray(a).save(tmp_path / "a.png")
    hf = load_heightfield(str(tmp_path / "a.png"))
    assert np.array_equal(hf.samples, a) and hf.lossless


def test_png_16bit_keeps_full_values(tmp_path):
    rng = np.random.default_rng(3)
    a = rng.integers(0, 65536, size=(31, 17)).astype(np.uint16)
    a[0, 0], a[0, 1] = 0, 65535
    img = Image.fromarray(a)
    img.save(tmp_path / "a16.png")
    with Image.open(tmp_path / "a16.png") as check:
        assert check.mode.startswith("I")  # written as 16-bit grayscale, not 8-bit
    hf = load_heightfield(str(tmp_path / "a16.png"))
    assert np.array_equal(hf.samples, a)
    assert np.array_equal(hf.values, a.astype(float))
    assert hf.lossless and hf.offset == 0.0


def test_png_colour_and_alpha_rejected(tmp_path):
    Image.fromarray(np.zeros((4, 4, 3), dtype=np.uint8)).save(tmp_path / "rgb.png")
    one_line_error(load_heightfield, str(tmp_path / "rgb.png"), match=["3 channels", "mode RGB", "grayscale"])
    Image.fromarray(np.zeros((4, 4, 2), dtype=np.uint8), mode="LA").save(tmp_path / "la.png")
    one_line_error(load_heightfield, str(tmp_path / "la.png"), match=["2 channels", "LA"])


def test_tiff_float32(tmp_path):
    # a plain TIFF (no georeference), written by tifffile: read through GDAL all the same
    rng = np.random.default_rng(4)
    a = (rng.random((13, 29)) * 1000 - 200).astype(np.float32)
    tifffile.imwrite(tmp_path / "f.tif", a)
    hf = load_heightfield(str(tmp_path / "f.tif"))
    assert np.array_equal(hf.values, a.astype(np.float64))
    assert not hf.lossless
    assert hf.max_quantisation_error <= hf.scale / 2 * (1 + 1e-9)
    assert hf.transform is None and hf.crs is None


def test_tiff_int16_gdal_nodata(tmp_path):
    a = np.array([[10, -9999, 30], [-5, 50, 60], [70, 80, -9999]], dtype=np.int16)
    path = tmp_path / "dem.TIFF"
    tifffile.imwrite(path, a, extratags=[(42113, "s", 0, "-9999", True)])
    msg = one_line_error(load_heightfield, str(path), match=["2 of 9", "--fill nearest", "--fill VALUE"])
    assert str(path) in msg
    hf = load_heightfield(str(path), fill="0")
    assert hf.filled == 2
    expected = a.astype(float)
    expected[a == -9999] = 0
    assert np.array_equal(hf.values, expected)
    hf = load_heightfield(str(path), fill="nearest")
    # equally near neighbours: any of them ((0, 0), (1, 1) or (0, 2); (2, 1) or (1, 2))
    assert hf.values[0, 1] in (10, 50, 30) and hf.values[2, 2] in (80, 60)
    assert hf.filled == 2 and np.array_equal(hf.values[a != -9999], a[a != -9999])


def test_tiff_one_band_read_several_bands_or_images_rejected(tmp_path):
    a = np.arange(12, dtype=np.uint16).reshape(3, 4)
    utm = {"crs": "EPSG:32617", "transform": Affine(30, 0, 500000, 0, -30, 4100000)}
    with rasterio.open(tmp_path / "one.tif", "w", driver="GTiff", width=4, height=3, count=1,
                       dtype="uint16", **utm) as ds:
        ds.write(a, 1)
    hf = load_heightfield(str(tmp_path / "one.tif"))
    assert np.array_equal(hf.values, a)
    assert hf.transform == (30.0, 0.0, 500000.0, 0.0, -30.0, 4100000.0) and hf.crs == "EPSG:32617"
    tifffile.imwrite(tmp_path / "rgb.tif", np.zeros((5, 6, 3), dtype=np.uint8), photometric="rgb")
    one_line_error(load_heightfield, str(tmp_path / "rgb.tif"), match=["single band", "3 bands", "5 x 6"])
    tifffile.imwrite(tmp_path / "pages.tif", np.zeros((5, 6), dtype=np.uint16))
    tifffile.imwrite(tmp_path / "pages.tif", np.ones((5, 6), dtype=np.uint16), append=True)
    one_line_error(load_heightfield, str(tmp_path / "pages.tif"), match=["2 images", "needs one"])


def test_asc_with_nodata(tmp_path):
    text = (
        "NCOLS 4\nnrows 3\nxllcenter 100.0\nYLLCORNER 200\ncellsize 30\nNODATA_value -9999\n"
        "1 2 3\n4 5.5 -9999 7 8\n9 10\n11 12\n"
    )
    (tmp_path / "g.asc").write_text(text)
    one_line_error(load_heightfield, str(tmp_path / "g.asc"), match=["1 of 12", "--fill"])
    hf = load_heightfield(str(tmp_path / "g.asc"), fill="-1.5")
    expected = np.array([[1, 2, 3, 4], [5.5, -1.5, 7, 8], [9, 10, 11, 12]])
    assert np.array_equal(hf.values, expected) and hf.filled == 1


def test_asc_any_header_order_dx_dy(tmp_path):
    (tmp_path / "g.ASC").write_text("dx 1\nnrows 2\nyllcorner 0\nxllcorner 0\ndy 1\nncols 2\n-1 2\n3 4\n")
    hf = load_heightfield(str(tmp_path / "g.ASC"))
    assert np.array_equal(hf.values, [[-1, 2], [3, 4]])
    assert hf.lossless and hf.offset == -1.0 and np.array_equal(hf.samples, [[0, 3], [4, 5]])


def test_asc_wrong_count(tmp_path):
    # GDAL alone would read the short grid's missing sample and the text as 0 and ignore the surplus
    header = "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n"
    (tmp_path / "g.asc").write_text(header + "1 2 3 4 5\n")
    one_line_error(load_heightfield, str(tmp_path / "g.asc"), match=["expected 2 x 3 = 6", "found 5"])
    (tmp_path / "h.asc").write_text(header + "1 2 3 4 5 6 7\n")
    words = ["too long", "expected 2 x 3 = 6", "found 7"]
    one_line_error(load_heightfield, str(tmp_path / "h.asc"), match=words)
    (tmp_path / "i.asc").write_text(header + "1 2 3\n4 x 6\n")
    one_line_error(load_heightfield, str(tmp_path / "i.asc"), match=["not a number"])
    (tmp_path / "j.asc").write_text(header + "1 2 3\n4 5 6\n")
    assert load_heightfield(str(tmp_path / "j.asc")).values.tolist() == [[1, 2, 3], [4, 5, 6]]


def test_asc_keeps_float64_precision(tmp_path):
    values = np.array([[1234.5678901, -0.1], [3.25, 1e-7]])
    rows = "\n".join(" ".join(repr(float(v)) for v in row) for row in values)
    (tmp_path / "p.asc").write_text(f"ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 10\n{rows}\n")
    hf = load_heightfield(str(tmp_path / "p.asc"))
    assert np.array_equal(hf.values, values)  # float32 would not hold these
    assert hf.transform == (10.0, 0.0, 0.0, 0.0, -10.0, 20.0)


def test_unknown_extension_sniffed_by_content(tmp_path):
    a = np.arange(6).reshape(2, 3)
    np.save(tmp_path / "x.npy", a)
    os.rename(tmp_path / "x.npy", tmp_path / "x.dat")
    assert np.array_equal(load_heightfield(str(tmp_path / "x.dat")).values, a)
    write_pgm_p5(tmp_path / "p.raw", a + 1, maxval=255)
    assert np.array_equal(load_heightfield(str(tmp_path / "p.raw")).values, a + 1)
    Image.fromarray(a.astype(np.uint16)).save(tmp_path / "i.png")
    os.rename(tmp_path / "i.png", tmp_path / "i.bin")
    assert np.array_equal(load_heightfield(str(tmp_path / "i.bin")).values, a)
    # anything else goes to GDAL, which recognises an ESRI ASCII grid by its content
    (tmp_path / "g.txt").write_text("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 4\n")
    assert np.array_equal(load_heightfield(str(tmp_path / "g.txt")).values, [[1, 2], [3, 4]])


@pytest.mark.parametrize("shape", [(2, 2), (3, 1000), (1000, 3), (37, 53), (2, 65)])
def test_sizes(tmp_path, shape):
    a = (np.arange(np.prod(shape)).reshape(shape) % 997).astype(np.uint16)
    write_pgm_p5(tmp_path / "s.pgm", a, maxval=65535)
    np.save(tmp_path / "s.npy", a)
    Image.fromarray(a).save(tmp_path / "s.png")
    tifffile.imwrite(tmp_path / "s.tif", a)
    for name in ("s.pgm", "s.npy", "s.png", "s.tif"):
        hf = load_heightfield(str(tmp_path / name))
        assert (hf.height, hf.width) == shape, name
        assert np.array_equal(hf.samples, a), name


# ---------------------------------------------------------------------------
# quantisation


def test_quantise_uint16_lossless():
    a = np.array([[0, 65535], [1, 2]], dtype=np.uint16)
    samples, scale, offset, lossless = quantise(a)
    assert lossless and scale == 1.0 and offset == 0.0 and samples.dtype == np.uint16
    assert np.array_equal(samples, a)


def test_quantise_int16_negative_uses_offset():
    a = np.array([[-32768, 0], [100, 32767]], dtype=np.int16)
    samples, scale, offset, lossless = quantise(a)
    assert lossless and scale == 1.0 and offset == -32768.0
    assert np.array_equal(samples, a.astype(np.int64) + 32768)
    hf = from_array(a)
    assert hf.max_quantisation_error == 0.0
    assert np.array_equal(hf.offset + hf.scale * hf.samples, a)


def test_quantise_large_integers_in_range_use_offset():
    a = np.array([[100000, 100001], [165535, 120000]])
    samples, scale, offset, lossless = quantise(a)
    assert lossless and offset == 100000.0 and scale == 1.0
    assert samples.max() == 65535


def test_quantise_integer_floats_lossless():
    a = np.array([[3.0, 7.0], [1000.0, -2.0]])
    samples, scale, offset, lossless = quantise(a)
    assert lossless and scale == 1.0 and offset == -2.0
    assert np.array_equal(offset + scale * samples, a)


def test_quantise_lossy_float_error_bound():
    rng = np.random.default_rng(5)
    a = rng.normal(size=(40, 61)) * 123.4 + 17
    hf = from_array(a)
    assert not hf.lossless
    assert hf.offset == a.min()
    assert hf.scale == pytest.approx((a.max() - a.min()) / 65535, rel=0, abs=0)
    assert hf.samples.min() == 0 and hf.samples.max() == 65535
    err = np.abs(a - (hf.offset + hf.scale * hf.samples.astype(float)))
    assert 0 < hf.max_quantisation_error == err.max()
    assert hf.max_quantisation_error <= hf.scale / 2 * (1 + 1e-9)


def test_quantise_wide_integer_range_is_lossy_and_rounds_half_to_even():
    # range 131070 > 65535: scale 2, so odd values land exactly half way between samples
    a = np.array([[0, 1, 3, 5], [7, 131070, 2, 4]])
    samples, scale, offset, lossless = quantise(a)
    assert scale == 2.0 and offset == 0.0 and not lossless
    assert samples.tolist() == [[0, 0, 2, 2], [4, 65535, 1, 2]]


def test_quantise_constant_fields():
    samples, scale, offset, lossless = quantise(np.full((3, 3), 7))
    assert lossless and scale == 1.0 and offset == 0.0 and np.all(samples == 7)
    samples, scale, offset, lossless = quantise(np.full((3, 3), 2.5))
    assert lossless and scale == 1.0 and offset == 2.5 and np.all(samples == 0)
    samples, scale, offset, lossless = quantise(np.full((2, 2), -4))
    assert lossless and offset == -4.0 and np.all(samples == 0)


def test_bool_becomes_0_1():
    hf = from_array(np.array([[True, False], [False, True]]))
    assert hf.lossless and np.array_equal(hf.samples, [[1, 0], [0, 1]]) and hf.offset == 0.0


def test_report_is_json():
    hf = from_array(np.array([[0.0, 0.5], [1.0, 2.0]]), source="demo")
    rep = json.loads(json.dumps(hf.to_report()))
    assert rep["source"] == "demo" and rep["width"] == 2 and rep["height"] == 2
    assert rep["min"] == 0.0 and rep["max"] == 2.0 and rep["filled"] == 0
    assert rep["quantisation_step"] == rep["scale"] == hf.scale
    assert rep["lossless"] is hf.lossless
    assert rep["max_quantisation_error"] == hf.max_quantisation_error
    assert set(rep) == {
        "source", "width", "height", "scale", "offset", "lossless", "quantisation_step",
        "max_quantisation_error", "filled", "min", "max",
    }


def test_from_array_copies_input():
    a = np.zeros((3, 3))
    hf = from_array(a)
    a[0, 0] = 99
    assert hf.values[0, 0] == 0


# ---------------------------------------------------------------------------
# --fill


def test_parse_fill():
    assert parse_fill(None) is None
    assert parse_fill("nearest") == "nearest"
    assert parse_fill(" Nearest ") == "nearest"
    assert parse_fill("-12.5") == -12.5
    assert parse_fill("0") == 0.0
    assert parse_fill(3) == 3.0
    for bad in ("sideways", "", "nan", "inf", "1,5"):
        one_line_error(parse_fill, bad, match="--fill")


def test_fill_nearest_hand_checked():
    n = np.nan
    a = np.array([[1, n, n, 4], [n, n, n, n], [9, n, n, 12]])
    hf = from_array(a, fill="nearest")
    v = hf.values
    # one nearest good sample each: (0,1)->(0,0), (0,2)->(0,3), (1,0)->(0,0) or (2,0), ...
    assert v[0].tolist() == [1, 1, 4, 4] and v[2].tolist() == [9, 9, 12, 12]
    # (1,0) and (1,1) are equally near (0,0) and (2,0); (1,2) and (1,3) equally near (0,3) and (2,3)
    assert v[1, 0] in (1, 9) and v[1, 1] in (1, 9) and v[1, 2] in (4, 12) and v[1, 3] in (4, 12)
    assert hf.filled == 8


def test_fill_nearest_far_from_good_samples():
    # Two good samples in opposite corners of an 11 x 11 field: every sample takes the nearer one,
    # a tie (the anti-diagonal) either.
    a = np.full((11, 11), np.nan)
    a[0, 0], a[10, 10] = 5.0, 7.0
    hf = from_array(a, fill="nearest")
    r, c = np.mgrid[0:11, 0:11]
    d_first, d_last = r**2 + c**2, (10 - r) ** 2 + (10 - c) ** 2
    assert np.array_equal(hf.values[d_first < d_last], np.full(np.count_nonzero(d_first < d_last), 5.0))
    assert np.array_equal(hf.values[d_first > d_last], np.full(np.count_nonzero(d_first > d_last), 7.0))
    assert set(hf.values[d_first == d_last].tolist()) <= {5.0, 7.0}
    assert hf.filled == 119


def test_fill_nearest_is_a_nearest_sample_random_masks():
    rng = np.random.default_rng(11)
    for _ in range(150):
        h, w = (int(x) for x in rng.integers(2, 30, size=2))
        values = rng.permutation(h * w).reshape(h, w).astype(float)
        bad = rng.random((h, w)) < rng.choice([0.2, 0.7, 0.97])
        bad[rng.integers(h), rng.integers(w)] = False
        assert_nearest_fill(values, bad, fill_nearest(values, bad))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bad=arrays(bool, st.tuples(st.integers(1, 14), st.integers(1, 14))), seed=st.integers(0, 2**32 - 1))
def test_fill_nearest_property(bad, seed):
    """Any mask: each filled sample takes the value of a nearest valid sample (exact Euclidean
    distance, found by brute force), valid samples are kept, and the choice among equally near
    ones depends on the mask alone (the same for other heights, and on every run)."""
    if bad.all():
        with pytest.raises(InputError):
            fill_nearest(np.zeros(bad.shape), bad)
        return
    rng = np.random.default_rng(seed)
    values = rng.permutation(bad.size).reshape(bad.shape).astype(float) - bad.size / 2
    taken = assert_nearest_fill(values, bad, fill_nearest(values, bad))
    other = rng.permutation(bad.size).reshape(bad.shape).astype(float) * 0.5 + 1000
    assert assert_nearest_fill(other, bad, fill_nearest(other, bad)) == taken
    assert np.array_equal(fill_nearest(values, bad), fill_nearest(values, bad))


def test_fill_nearest_symmetric_ties_deterministic():
    # A lattice of valid samples: most holes are equally near 2 or 4 of them.  Whatever scipy picks,
    # it is a nearest sample and the same every time.
    bad = np.ones((40, 40), dtype=bool)
    bad[::6, ::6] = False
    values = np.arange(bad.size, dtype=float).reshape(bad.shape)
    first = fill_nearest(values, bad)
    assert_nearest_fill(values, bad, first)
    for _ in range(3):
        assert np.array_equal(fill_nearest(values, bad), first)


def test_fill_value_and_inf():
    a = np.array([[1.0, np.inf], [-np.inf, 4.0]])
    one_line_error(from_array, a, match=["2 of 4", "--fill"])
    hf = from_array(a, fill="2")
    assert hf.values.tolist() == [[1, 2], [2, 4]] and hf.filled == 2 and hf.lossless


def test_fill_nearest_large_with_small_holes():
    rng = np.random.default_rng(2)
    a = rng.random((1024, 1024))
    a[rng.random(a.shape) < 0.02] = np.nan
    a[500:520, 300:330] = np.nan
    hf = from_array(a, fill="nearest")
    assert np.isfinite(hf.values).all()
    assert hf.values[510, 301] == a[510, 299]  # the only sample at distance 2


# ---------------------------------------------------------------------------
# bad input: every one an InputError with a one-line message


def test_missing_file(tmp_path):
    one_line_error(load_heightfield, str(tmp_path / "nope.npy"), match=["cannot read", "nope.npy"])


def test_directory(tmp_path):
    one_line_error(load_heightfield, str(tmp_path), match="cannot read")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root can read anything")
def test_unreadable_file(tmp_path):
    p = tmp_path / "secret.npy"
    np.save(p, np.zeros((2, 2)))
    p.chmod(0)
    try:
        one_line_error(load_heightfield, str(p), match=["cannot read", "permission"])
    finally:
        p.chmod(0o600)


def test_truncated_npy(tmp_path):
    np.save(tmp_path / "a.npy", np.arange(400.0).reshape(20, 20))
    data = (tmp_path / "a.npy").read_bytes()
    (tmp_path / "a.npy").write_bytes(data[: len(data) // 2])
    one_line_error(load_heightfield, str(tmp_path / "a.npy"), match=["cannot read", "a.npy"])
    (tmp_path / "a.npy").write_bytes(data[:30])
    one_line_error(load_heightfield, str(tmp_path / "a.npy"), match="cannot read")


def test_object_npy_rejected(tmp_path):
    np.save(tmp_path / "o.npy", np.array([[1, "a"], [None, 2]], dtype=object), allow_pickle=True)
    one_line_error(load_heightfield, str(tmp_path / "o.npy"), match="cannot read")


def test_corrupt_npz(tmp_path):
    np.savez_compressed(tmp_path / "a.npz", x=np.arange(10000.0).reshape(100, 100))
    data = (tmp_path / "a.npz").read_bytes()
    (tmp_path / "a.npz").write_bytes(data[: len(data) // 2])
    one_line_error(load_heightfield, str(tmp_path / "a.npz"), match="cannot read")
    (tmp_path / "b.npz").write_bytes(b"not a zip archive at all")
    one_line_error(load_heightfield, str(tmp_path / "b.npz"), match="cannot read")


def test_truncated_pgm(tmp_path):
    a = np.arange(30, dtype=np.uint16).reshape(5, 6) * 1000
    data = write_pgm_p5(tmp_path / "a.pgm", a, maxval=65535).read_bytes()
    (tmp_path / "a.pgm").write_bytes(data[:-11])
    words = ["expected 6 x 5 = 30 samples", "found 24"]
    one_line_error(load_heightfield, str(tmp_path / "a.pgm"), match=words)
    (tmp_path / "b.pgm").write_text("P2\n3 3\n255\n1 2 3 4\n")
    one_line_error(load_heightfield, str(tmp_path / "b.pgm"), match=["expected 3 x 3 = 9", "found 4"])
    (tmp_path / "c.pgm").write_bytes(b"P5\n3 ")
    one_line_error(load_heightfield, str(tmp_path / "c.pgm"), match="header")


def test_bad_pgm(tmp_path):
    (tmp_path / "a.pgm").write_bytes(b"P6\n2 2\n255\n" + bytes(12))
    one_line_error(load_heightfield, str(tmp_path / "a.pgm"), match=["colour", "P2/P5"])
    (tmp_path / "b.pgm").write_text("P2\n2 2\n10\n1 2 3 11\n")
    one_line_error(load_heightfield, str(tmp_path / "b.pgm"), match=["11", "maxval"])
    (tmp_path / "c.pgm").write_text("P2\n2 2\n10\n1 2 x 1\n")
    one_line_error(load_heightfield, str(tmp_path / "c.pgm"), match="not an integer")


def test_truncated_png(tmp_path):
    rng = np.random.default_rng(6)
    Image.fromarray(rng.integers(0, 65536, size=(64, 64)).astype(np.uint16)).save(tmp_path / "a.png")
    data = (tmp_path / "a.png").read_bytes()
    (tmp_path / "a.png").write_bytes(data[: len(data) // 2])
    one_line_error(load_heightfield, str(tmp_path / "a.png"), match=["cannot read", "a.png"])
    (tmp_path / "b.png").write_bytes(data[:20])
    one_line_error(load_heightfield, str(tmp_path / "b.png"), match="cannot read")


def test_garbage_tif(tmp_path):
    rng = np.random.default_rng(8)
    (tmp_path / "g.tif").write_bytes(rng.integers(0, 256, 1000).astype(np.uint8).tobytes())
    one_line_error(load_heightfield, str(tmp_path / "g.tif"), match=["cannot read", "g.tif"])
    tifffile.imwrite(tmp_path / "t.tif", np.zeros((64, 64), dtype=np.float32))
    data = (tmp_path / "t.tif").read_bytes()
    (tmp_path / "t.tif").write_bytes(data[: len(data) // 2])
    one_line_error(load_heightfield, str(tmp_path / "t.tif"), match="cannot read")


def test_unknown_extension_random_bytes(tmp_path):
    rng = np.random.default_rng(9)
    (tmp_path / "x.xyz").write_bytes(b"\x01\x02" + rng.integers(0, 256, 500).astype(np.uint8).tobytes())
    formats = [".npy", ".npz", ".pgm", ".png", ".tif", ".asc", ".hgt", ".img", ".bil", ".vrt"]
    one_line_error(load_heightfield, str(tmp_path / "x.xyz"), match=["unknown format", *formats])


def test_key_on_non_npz(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros((2, 2)))
    one_line_error(load_heightfield, str(tmp_path / "a.npy"), key="x", match="--key")


@pytest.mark.parametrize(
    "array, words",
    [
        (np.arange(5.0), ["2-D", "(5,)"]),
        (np.zeros((2, 3, 4)), ["2-D", "(2, 3, 4)"]),
        (np.zeros(0), ["2-D", "(0,)"]),
        (np.zeros((0, 0)), ["2 x 2", "(0, 0)"]),
        (np.zeros((1, 1000)), ["2 x 2", "(1, 1000)"]),
        (np.zeros((1000, 1)), ["2 x 2", "(1000, 1)"]),
        (np.zeros((3, 3), dtype=complex), ["complex", "bool, integer or float"]),
        (np.array([["a", "b"], ["c", "d"]]), ["bool, integer or float"]),
        (np.array([[1, None], [2, 3]], dtype=object), ["object"]),
        (np.array([[1.0, np.nan], [2.0, 3.0]]), ["1 of 4", "--fill nearest", "--fill VALUE"]),
    ],
)
def test_bad_arrays(array, words):
    one_line_error(from_array, array, match=words)


def test_bad_arrays_from_files(tmp_path):
    np.save(tmp_path / "v.npy", np.arange(10))
    one_line_error(load_heightfield, str(tmp_path / "v.npy"), match=["v.npy", "(10,)"])
    np.save(tmp_path / "c.npy", np.zeros((4, 4), dtype=np.complex64))
    one_line_error(load_heightfield, str(tmp_path / "c.npy"), match="complex")
    np.save(tmp_path / "n.npy", np.array([[1.0, np.nan], [3.0, 4.0]]))
    one_line_error(load_heightfield, str(tmp_path / "n.npy"), match=["n.npy", "--fill"])


@pytest.mark.parametrize("fill", ["nearest", "0", 3.5])
def test_all_nan_with_fill(fill):
    one_line_error(from_array, np.full((3, 4), np.nan), fill=fill, match=["all 12", "nothing to fill"])


def test_bad_fill_text_reported(tmp_path):
    one_line_error(from_array, np.zeros((2, 2)), fill="sideways", match=["'sideways'", "nearest"])
    np.save(tmp_path / "a.npy", np.zeros((2, 2)))
    one_line_error(load_heightfield, str(tmp_path / "a.npy"), fill="1e", match="--fill")


def test_npy_npz_mixed_up(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros((2, 2)))
    os.rename(tmp_path / "a.npy", tmp_path / "a.npz")
    one_line_error(load_heightfield, str(tmp_path / "a.npz"), match="rename it to .npy")
    np.savez(tmp_path / "b.npz", x=np.zeros((2, 2)))
    os.rename(tmp_path / "b.npz", tmp_path / "b.npy")
    one_line_error(load_heightfield, str(tmp_path / "b.npy"), match="rename it to .npz")


def test_palette_png_rejected(tmp_path):
    Image.fromarray(np.zeros((4, 4), dtype=np.uint8)).convert("P").save(tmp_path / "p.png")
    one_line_error(load_heightfield, str(tmp_path / "p.png"), match=["palette", "16-bit grayscale"])


def test_damaged_files_never_crash(tmp_path):
    """Cut and scribbled-over files of every format: a height field or an InputError, nothing else."""
    rng = np.random.default_rng(12)
    a = (rng.random((9, 11)) * 60000).astype(np.uint16)
    np.save(tmp_path / "a.npy", a)
    np.savez_compressed(tmp_path / "a.npz", x=a)
    Image.fromarray(a).save(tmp_path / "a.png")
    tifffile.imwrite(tmp_path / "a.tif", a, compression="zlib")
    write_pgm_p5(tmp_path / "a.pgm", a, maxval=65535)
    grid = "ncols 11\nnrows 9\ncellsize 1\nNODATA_value 7\n" + " ".join(map(str, a.ravel()))
    (tmp_path / "a.asc").write_text(grid)
    for name in ("a.npy", "a.npz", "a.png", "a.tif", "a.pgm", "a.asc"):
        data = (tmp_path / name).read_bytes()
        damaged = tmp_path / ("damaged" + name[1:])
        for trial in range(60):
            m = bytearray(data[: rng.integers(0, len(data))] if trial % 2 else data)
            if trial % 2 == 0:
                for i in rng.integers(0, min(len(m), 300), size=4):
                    m[i] = rng.integers(0, 256)
            damaged.write_bytes(bytes(m))
            try:
                hf = load_heightfield(str(damaged), fill="nearest")
            except InputError as e:
                assert "\n" not in str(e)
            else:
                assert hf.samples.dtype == np.uint16 and hf.values.shape == hf.samples.shape
