"""kesbrdf.io.ply: binary PLY in Mitsuba's layout, round trip and errors."""

import numpy as np
import pytest

from kesbrdf.io.ply import read_ply, vertex_normals, write_ply
from kesbrdf.errors import FormatError


def test_round_trip_is_exact(tmp_path, rng):
    p = rng.normal(size=(50, 3)).astype(np.float32)
    f = rng.integers(0, 50, size=(40, 3)).astype(np.int32)
    n = vertex_normals(p, f)
    uv = rng.uniform(0, 2, size=(50, 2)).astype(np.float32)
    path = write_ply(tmp_path / "m.ply", p, f, n, uv, comment="test")
    m = read_ply(path)
    # float32 written and read back bit for bit: no tolerance
    np.testing.assert_array_equal(m.vertices, p)
    np.testing.assert_array_equal(m.faces, f)
    np.testing.assert_array_equal(m.normals, n)
    np.testing.assert_array_equal(m.uv, uv)


def test_header_is_mitsuba_layout(tmp_path):
    path = write_ply(tmp_path / "t.ply", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]],
                     [[0, 0, 1]] * 3, [[0, 0], [1, 0], [0, 1]])
    header = path.read_bytes().split(b"end_header\n")[0].decode().splitlines()
    assert header[1] == "format binary_little_endian 1.0"
    props = [l.split()[-1] for l in header if l.startswith("property float")]
    assert props == ["x", "y", "z", "nx", "ny", "nz", "u", "v"]
    assert "property list uchar int vertex_indices" in header
    # 3 vertices * 8 floats + 1 face * (1 + 3*4) bytes after the header
    assert len(path.read_bytes().split(b"end_header\n")[1]) == 3 * 8 * 4 + 13


def test_optional_attributes_absent(tmp_path):
    m = read_ply(write_ply(tmp_path / "p.ply", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]))
    assert m.normals is None and m.uv is None


def test_vertex_normals_unit_and_oriented():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    n = vertex_normals(p, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(n, [[0, 0, 1]] * 4)


def test_bad_inputs_raise(tmp_path):
    with pytest.raises(FormatError, match="face indices"):
        write_ply(tmp_path / "x.ply", [[0, 0, 0]], [[0, 1, 2]])
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat ascii 1.0\nend_header\n")
    with pytest.raises(FormatError, match="binary_little_endian"):
        read_ply(bad)
    trunc = tmp_path / "trunc.ply"
    data = write_ply(tmp_path / "ok.ply", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]).read_bytes()
    trunc.write_bytes(data[:-5])
    with pytest.raises(FormatError, match="truncated"):
        read_ply(trunc)
    assert not list(tmp_path.glob("*.part"))  # atomic writes leave no temporaries


def test_vertex_normals_fallback_is_the_given_up_axis():
    # vertex 3 is in no face: it takes the fallback (z-up cloth by default, y-up for render scenes)
    p = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]]
    assert vertex_normals(p, [[0, 1, 2]])[3].tolist() == [0.0, 0.0, 1.0]
    assert vertex_normals(p, [[0, 1, 2]], fallback=(0, 1, 0))[3].tolist() == [0.0, 1.0, 0.0]
