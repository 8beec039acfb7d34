"""Tests for wavemesh.io.meshio: OBJ and PLY mesh files, written and read."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from wavemesh.errors import InputError
from wavemesh.io.meshio import write_mesh, write_obj, write_ply
from wavemesh.io.meshread import read_mesh
from wavemesh.mesh import Mesh


def grid_mesh(w: int, h: int, rng: np.random.Generator) -> Mesh:
    """A w x h grid, each cell split by a random diagonal into two counter-clockwise triangles."""
    xy = [(x, y) for y in range(h) for x in range(w)]
    tris = []
    for y in range(h - 1):
        for x in range(w - 1):
            a, b, c, d = y * w + x, y * w + x + 1, (y + 1) * w + x, (y + 1) * w + x + 1
            tris += [(a, b, d), (a, d, c)] if rng.random() < 0.5 else [(a, b, c), (b, d, c)]
    return Mesh(w, h, np.array(xy), np.array(tris))


def awkward_heights(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    """Heights whose exact round trip needs all 17 digits, plus a few special values."""
    z = rng.normal(size=(h, w)) * 10.0 ** rng.integers(-300, 300, size=(h, w))
    special = [0.1, 1 / 3, -0.0, 5e-324, 1.7976931348623157e308, 2.0**-1074 * 3, 123456789.123456789]
    z.flat[: len(special)] = special[: z.size]
    return z


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def one_line_input_error(path, **kw) -> str:
    with pytest.raises(InputError) as info:
        read_mesh(path, **kw)
    msg = str(info.value)
    assert msg and "\n" not in msg
    return msg


# ---------------------------------------------------------------------------------------------
# Round trips


@pytest.mark.parametrize("ext", [".obj", ".ply"])
@pytest.mark.parametrize("seed", range(4))
def test_round_trip(tmp_path, ext, seed):
    rng = np.random.default_rng(seed)
    w, h = int(rng.integers(2, 12)), int(rng.integers(2, 12))
    mesh = grid_mesh(w, h, rng)
    # Shuffle vertices and triangles so the file order is not the canonical one.
    perm = rng.permutation(mesh.n_vertices)
    inv = np.argsort(perm)
    mesh = Mesh(w, h, mesh.xy[perm], inv[mesh.tris][rng.permutation(mesh.n_triangles)])
    heights = awkward_heights(h, w, rng)
    path = tmp_path / f"m{ext}"
    write_mesh(path, mesh, heights, comment="made by a test\nsecond line")
    back, z = read_mesh(path)
    assert (back.width, back.height) == (w, h)
    assert back.same_as(mesh)
    assert np.array_equal(back.xy, mesh.xy) and np.array_equal(back.tris, mesh.tris)  # order kept too
    assert z.dtype == np.float64
    assert same_bits(z, heights[mesh.xy[:, 1], mesh.xy[:, 0]])


@pytest.mark.parametrize("ext,kind", [(".stl", "binary STL"), (".glb", "glTF binary")])
def test_formats_not_read_back_say_which_are(tmp_path, ext, kind):
    # STL and glTF are written, not read back: one line that names the format and the ones that are read,
    # whatever the file is called; other binary data stays "not a mesh file"
    mesh = Mesh(9, 7, [(0, 0), (3, 0), (3, 2), (0, 2)], [(0, 1, 2), (0, 2, 3)])
    write_mesh(tmp_path / f"m{ext}", mesh, np.zeros((7, 9)))
    (tmp_path / "renamed.obj").write_bytes((tmp_path / f"m{ext}").read_bytes())
    for path in (tmp_path / f"m{ext}", tmp_path / "renamed.obj"):
        with pytest.raises(InputError, match=f"a {kind} file: meshes are read back from OBJ and PLY only"):
            read_mesh(path)
    (tmp_path / "noise.stl").write_bytes(bytes(range(256)) * 3)
    with pytest.raises(InputError, match="not a mesh file"):
        read_mesh(tmp_path / "noise.stl")


@pytest.mark.parametrize("ext", [".obj", ".ply"])
def test_grid_size_comes_from_the_comment(tmp_path, ext):
    # A mesh that does not reach the last row and column: W, H must come from the file's comment.
    mesh = Mesh(9, 7, [(0, 0), (3, 0), (3, 2), (0, 2)], [(0, 1, 2), (0, 2, 3)])
    path = tmp_path / f"m{ext}"
    write_mesh(path, mesh, np.zeros((7, 9)))
    back, _ = read_mesh(path)
    assert (back.width, back.height) == (9, 7)
    back, _ = read_mesh(path, width=9, height=7)
    assert (back.width, back.height) == (9, 7)
    msg = one_line_input_error(path, width=10)
    assert "9 x 7" in msg


def test_grid_size_without_comment(tmp_path):
    p = tmp_path / "plain.obj"
    p.write_text("v 0 0 1\nv 4 0 2\nv 4 3 3\nf 1 2 3\n")
    assert (read_mesh(p)[0].width, read_mesh(p)[0].height) == (5, 4)
    m, _ = read_mesh(p, width=8, height=6)
    assert (m.width, m.height) == (8, 6)
    m, _ = read_mesh(p, height=6)
    assert (m.width, m.height) == (5, 6)


def test_obj_text_format(tmp_path):
    mesh = Mesh(2, 2, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 1, 2), (0, 2, 3)])
    heights = np.array([[0.1, 2.0], [1 / 3, -1e-300]])
    p = tmp_path / "m.obj"
    write_obj(p, mesh, heights, comment="hello")
    lines = p.read_text().splitlines()
    assert "# wavemesh 2 2" in lines and "# hello" in lines
    v = [line for line in lines if line.startswith("v ")]
    assert v == ["v 0 0 0.1", "v 1 0 2.0", "v 1 1 -1e-300", f"v 0 1 {1 / 3!r}"]
    assert [line for line in lines if line.startswith("f ")] == ["f 1 2 3", "f 1 3 4"]


def test_ply_header_and_body(tmp_path):
    mesh = Mesh(3, 2, [(0, 0), (2, 0), (2, 1), (0, 1)], [(0, 1, 2), (0, 2, 3)])
    heights = np.arange(6, dtype=float).reshape(2, 3) / 7
    p = tmp_path / "m.ply"
    write_ply(p, mesh, heights, comment="hi")
    data = p.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    assert header[:2] == ["ply", "format binary_little_endian 1.0"]
    assert "comment wavemesh 3 2" in header and "comment hi" in header
    assert header[-7:] == [
        "element vertex 4", "property double x", "property double y", "property double z",
        "element face 2", "property list uchar int vertex_indices", "end_header",
    ]  # fmt: skip
    body = data[end:]
    assert len(body) == 4 * 24 + 2 * 13
    verts = struct.unpack("<12d", body[:96])
    assert verts[:3] == (0.0, 0.0, heights[0, 0]) and verts[6:9] == (2.0, 1.0, heights[1, 2])
    assert struct.unpack("<B3i", body[96:109]) == (3, 0, 1, 2)
    assert struct.unpack("<B3i", body[109:122]) == (3, 0, 2, 3)


def test_write_per_vertex_z(tmp_path):
    mesh = Mesh(2, 2, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 1, 2), (0, 2, 3)])
    z = np.array([1.5, -2.0, 0.25, 7.0])
    for ext in (".obj", ".ply"):
        write_mesh(tmp_path / f"z{ext}", mesh, z)
        assert same_bits(read_mesh(tmp_path / f"z{ext}")[1], z)


def test_write_errors(tmp_path):
    mesh = Mesh(2, 2, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 1, 2), (0, 2, 3)])
    with pytest.raises(InputError, match=r"\.obj, \.ply, \.stl or \.glb"):
        write_mesh(tmp_path / "m.stp", mesh, np.zeros((2, 2)))
    with pytest.raises(InputError):
        write_mesh(tmp_path / "m.obj", mesh, np.zeros((3, 2)))
    with pytest.raises(InputError, match="cannot write"):
        write_mesh(tmp_path / "no" / "such" / "dir.ply", mesh, np.zeros((2, 2)))


# ---------------------------------------------------------------------------------------------
# OBJ reading


SQUARE_XY = np.array([(0, 0), (1, 0), (1, 1), (0, 1)])
SQUARE = Mesh(2, 2, SQUARE_XY, [(0, 1, 2), (0, 2, 3)])


def test_obj_reference_forms(tmp_path):
    p = tmp_path / "forms.obj"
    p.write_text(
        "# exported by something\n"
        "mtllib x.mtl\no square\n"
        "v 0 0 1.0\nv 1.0 0.0 2\n"
        "vt 0 0\nvn 0 0 1\n"
        "f 1/1 2/1/1 -1//1\n"  # -1: the last vertex read so far (the 2nd)
        "\n"
        "v 1 1 3 1.0\n"  # a 4th coordinate (w) is ignored
        "v  0\t1   4   \n"
        "g part\ns off\nusemtl m\n"
        "f -4 -2 -1\n"
    )
    mesh, z = read_mesh(p)
    # face 1: 1, 2, -1 -> the last vertex read so far, vertex 2 (degenerate, but that is check's business)
    assert mesh.tris.tolist() == [[0, 1, 1], [0, 2, 3]]
    assert mesh.xy.tolist() == SQUARE_XY.tolist()
    assert z.tolist() == [1.0, 2.0, 3.0, 4.0]
    assert (mesh.width, mesh.height) == (2, 2)


def test_obj_non_utf8_comment(tmp_path):
    p = tmp_path / "latin.obj"
    p.write_bytes("# caf\xe9\ng gr\xfcn\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("latin-1"))
    assert read_mesh(p)[0].tris.tolist() == [[0, 1, 2]]


def test_obj_line_continuation(tmp_path):
    p = tmp_path / "cont.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 \\\n 2 3\n")
    assert read_mesh(p)[0].tris.tolist() == [[0, 1, 2]]


# ---------------------------------------------------------------------------------------------
# PLY reading, files made by hand


def test_ply_ascii_by_hand(tmp_path):
    p = tmp_path / "ascii.ply"
    p.write_text(
        "ply\n"
        "format ascii 1.0\n"
        "comment made by hand\n"
        "obj_info nothing\n"
        "element vertex 4\n"
        "property float nx\n"
        "property float x\n"
        "property float y\n"
        "property list uchar int junk\n"
        "property float z\n"
        "property uchar red\n"
        "element face 2\n"
        "property int flags\n"
        "property list uchar uint vertex_index\n"
        "property list uchar float texcoord\n"
        "element edge 1\n"
        "property int vertex1\n"
        "property int vertex2\n"
        "end_header\n"
        "9 0 0 0 0.5 255\n"
        "9 1 0 2 7 7 -1.25 0\n"
        "9 1 1 1 3 2.5e2 12\n"
        "9 0 1 3 1 2 3 1e-3 0\n"
        "7 3 0 1 2 6 0 0 1 0 1 1\n"
        "7 3 0 2 3 0\n"
        "0 1\n"
    )
    mesh, z = read_mesh(p)
    assert mesh.same_as(SQUARE)
    assert mesh.tris.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert z.tolist() == [0.5, -1.25, 250.0, 1e-3]


def _be_ply(faces: list[list[int]], n_vertices: int = 4) -> bytes:
    header = (
        "ply\r\n"  # CRLF header lines are tolerated
        "format binary_big_endian 1.0\n"
        "comment wavemesh 2 2\n"
        f"element vertex {n_vertices}\n"
        "property short x\n"
        "property uint16 y\n"
        "property double z\n"
        "property uchar alpha\n"
        f"element face {len(faces)}\n"
        "property list ushort int vertex_indices\n"
        "property int8 tag\n"
        "element extra 2\n"
        "property list uchar short stuff\n"
        "end_header\n"
    ).encode()
    body = b""
    for i, (x, y) in enumerate(SQUARE_XY.tolist() * (n_vertices // 4)):
        body += struct.pack(">hHdB", x, y, 0.1 * i, 9)
    for f in faces:
        body += struct.pack(f">H{len(f)}ib", len(f), *f, -3)
    body += struct.pack(">B2h", 2, 5, 6) + struct.pack(">Bh", 1, 7)
    return header + body


def test_ply_big_endian_by_hand(tmp_path):
    p = tmp_path / "be.ply"
    p.write_bytes(_be_ply([[0, 1, 2], [0, 2, 3]]))
    mesh, z = read_mesh(p)
    assert mesh.tris.tolist() == [[0, 1, 2], [0, 2, 3]] and mesh.same_as(SQUARE)
    assert same_bits(z, [0.0, 0.1, 0.2, 0.1 * 3])


def test_ply_little_endian_other_types(tmp_path):
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        "element vertex 4\nproperty int32 x\nproperty uchar y\nproperty float z\n"
        "element face 2\nproperty list int uint8 vertex_indices\nend_header\n"
    ).encode()
    body = b"".join(struct.pack("<iBf", x, y, 0.5 * x) for x, y in SQUARE_XY.tolist())
    body += struct.pack("<i3B", 3, 0, 1, 2) + struct.pack("<i3B", 3, 0, 2, 3)
    p = tmp_path / "le.ply"
    p.write_bytes(header + body)
    mesh, z = read_mesh(p)
    assert mesh.same_as(SQUARE) and z.tolist() == [0.0, 0.5, 0.5, 0.0]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_an_element_without_properties_reads_at_once(tmp_path, fmt):
    """Its records take no bytes however many the header states: 10^20 of them once kept the reader
    counting them one by one (the readers fuzzer's hang)."""
    header = (
        f"ply\nformat {fmt} 1.0\nelement x 99999999999999999999\n"
        "element vertex 4\nproperty int32 x\nproperty int32 y\nproperty int32 z\n"
        "element face 2\nproperty list uchar int32 vertex_indices\nend_header\n"
    ).encode()
    tris = [[0, 1, 2], [0, 2, 3]]
    if fmt == "ascii":
        rows = [f"{x} {y} 0" for x, y in SQUARE_XY.tolist()] + [f"3 {a} {b} {c}" for a, b, c in tris]
        body = "".join(r + "\n" for r in rows).encode()
    else:
        body = b"".join(struct.pack("<3i", x, y, 0) for x, y in SQUARE_XY.tolist())
        body += b"".join(struct.pack("<B3i", 3, *t) for t in tris)
    (tmp_path / "m.ply").write_bytes(header + body)
    mesh, _ = read_mesh(tmp_path / "m.ply")
    assert mesh.same_as(SQUARE)


# ---------------------------------------------------------------------------------------------
# Bad files


def test_truncated_ply(tmp_path):
    rng = np.random.default_rng(3)
    mesh = grid_mesh(4, 3, rng)
    good = tmp_path / "good.ply"
    write_ply(good, mesh, np.zeros((3, 4)))
    data = good.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    for cut in (10, end - 3, end, end + 5, end + 12 * 24, len(data) - 13, len(data) - 1):
        p = tmp_path / f"cut{cut}.ply"
        p.write_bytes(data[:cut])
        msg = one_line_input_error(p)
        assert "truncated" in msg or "end_header" in msg


def test_truncated_ascii_ply(tmp_path):
    p = tmp_path / "t.ply"
    p.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty int x\nproperty int y\nproperty int z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1\n"
    )
    assert "truncated" in one_line_input_error(p)


def test_quad_faces(tmp_path):
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 2 3 4\n")
    assert "face 2 has 4 vertices; only triangles are supported" in one_line_input_error(obj)
    ply = tmp_path / "quad.ply"
    ply.write_bytes(_be_ply([[0, 1, 2], [0, 1, 2, 3], [0, 2, 3]]))
    assert "face 1 has 4 vertices; only triangles are supported" in one_line_input_error(ply)
    ply.write_bytes(_be_ply([[0, 1, 2, 3]]))
    assert "face 0 has 4 vertices" in one_line_input_error(ply)
    two = tmp_path / "two.obj"
    two.write_text("v 0 0 0\nv 1 0 0\nf 1 2\n")
    assert "face 1 has 2 vertices" in one_line_input_error(two)


def test_non_integer_vertex(tmp_path):
    obj = tmp_path / "frac.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0.5 1 0\nf 1 2 3\n")
    assert "vertex 3 at (0.5, 1.0) is not a grid sample" in one_line_input_error(obj)
    obj.write_text("v 0 0 0\nv 1.0000000001 0 0\nv 0 1 0\nf 1 2 3\n")  # within 1e-9: a sample
    assert read_mesh(obj)[0].xy.tolist() == [[0, 0], [1, 0], [0, 1]]
    obj.write_text("v 0 nan 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert "vertex 1 at (0.0, nan) is not a grid sample" in one_line_input_error(obj)
    ply = tmp_path / "frac.ply"
    ply.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0.25 0\n0 1 0\n3 0 1 2\n"
    )
    assert "vertex 1 at (1.0, 0.25) is not a grid sample" in one_line_input_error(ply)


def test_index_out_of_range(tmp_path):
    obj = tmp_path / "range.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")
    assert "face 1 refers to vertex 4" in one_line_input_error(obj)
    obj.write_text("v 0 0 0\nv 1 0 0\nf 1 2 -3\nv 0 1 0\n")  # relative reference before the vertex exists
    assert "face 1 refers to vertex -3" in one_line_input_error(obj)
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
    assert "0" in one_line_input_error(obj)
    ply = tmp_path / "range.ply"
    ply.write_bytes(_be_ply([[0, 1, 2], [0, 2, 4]]))
    assert "face 1 refers to vertex 4" in one_line_input_error(ply)
    ply.write_bytes(_be_ply([[0, -1, 2]]))
    assert "face 0 refers to vertex -1" in one_line_input_error(ply)


@pytest.mark.parametrize(
    "name, data",
    [
        ("empty.obj", b""),
        ("hello.obj", b"hello world\n"),
        ("random.obj", bytes(np.random.default_rng(1).integers(0, 256, 4000, dtype=np.uint8))),
        ("badnum.obj", b"v 0 0 zero\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        ("badref.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n"),
        ("short.obj", b"v 0 0\n"),
        ("novert.obj", b"f 1 2 3\n"),
        ("noface.obj", b"v 0 0 0\n"),
        ("notply.ply", b"v 0 0 0\n"),
        ("magic.ply", b"ply\n"),
        ("noformat.ply", b"ply\nelement vertex 0\nend_header\n"),
        ("badformat.ply", b"ply\nformat binary_middle_endian 1.0\nend_header\n"),
        ("badtype.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n"),
        ("badline.ply", b"ply\nformat ascii 1.0\nwhat is this\nend_header\n"),
        ("noz.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty int x\nproperty int y\n"
         b"element face 0\nproperty list uchar int vertex_indices\nend_header\n0 0\n"),
        ("noface.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty int x\nproperty int y\n"
         b"property int z\nend_header\n0 0 0\n"),
        ("garbage.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty int x\nproperty int y\n"
         b"property int z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
         b"0 0 0 1 0 0 0 1 zz 3 0 1 2\n"),
        ("count.ply", b"ply\nformat ascii 1.0\nelement vertex -3\nend_header\n"),
    ],
)  # fmt: skip
def test_garbage(tmp_path, name, data):
    p = tmp_path / name
    p.write_bytes(data)
    msg = one_line_input_error(p)
    assert name in msg


def test_missing_file(tmp_path):
    assert "cannot read" in one_line_input_error(tmp_path / "nope.obj")
    assert "cannot read" in one_line_input_error(tmp_path)  # a directory


def test_random_corruption_never_tracebacks(tmp_path):
    """Flip, cut and splice bytes of good files: the result is a mesh or an InputError."""
    rng = np.random.default_rng(7)
    mesh = grid_mesh(4, 4, rng)
    for ext in (".ply", ".obj"):
        good = tmp_path / f"good{ext}"
        write_mesh(good, mesh, rng.random((4, 4)))
        data = bytearray(good.read_bytes())
        for trial in range(150):
            bad = bytearray(data)
            for _ in range(int(rng.integers(1, 4))):
                i = int(rng.integers(0, len(bad)))
                bad[i] = int(rng.integers(0, 256))
            if trial % 3 == 0:
                bad = bad[: int(rng.integers(0, len(bad)))]
            p = tmp_path / f"bad{trial}{ext}"
            p.write_bytes(bytes(bad))
            try:
                m, z = read_mesh(p)
            except InputError as e:
                assert "\n" not in str(e)
            else:
                assert m.xy.dtype == np.int64 and len(z) == m.n_vertices
