"""Readers, validation and atomic writers of :mod:`houghcad.io`."""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from houghcad.errors import InputError, InputWarning
from houghcad.io import (
    PointCloud,
    atomic_write,
    read_points,
    validate_points,
    write_fit4cad_primitives,
    write_json,
    write_points_ply,
)
from houghcad.io.readers import MIN_POINTS, clean_normals

N = 60


# --------------------------------------------------------------------------- fixtures / helpers


@pytest.fixture
def cloud() -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) points spread in 3-D and (N, 3) unit normals, deterministic."""
    rng = np.random.default_rng(1234)
    pts = rng.uniform(-5.0, 5.0, size=(N, 3))
    nrm = rng.normal(size=(N, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pts, nrm


def _ply(path: Path, pts: np.ndarray, nrm: np.ndarray | None, *, text: bool, byte_order: str = "<") -> Path:
    fields = [("x", "f8"), ("y", "f8"), ("z", "f8")]
    if nrm is not None:
        fields += [("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    v = np.empty(len(pts), dtype=fields)
    v["x"], v["y"], v["z"] = pts.T
    if nrm is not None:
        v["nx"], v["ny"], v["nz"] = nrm.T
    PlyData([PlyElement.describe(v, "vertex")], text=text, byte_order=byte_order).write(str(path))
    return path


def _r(v: float) -> str:
    """Shortest round-tripping text of a float."""
    return repr(float(v))


def _table(path: Path, rows: np.ndarray, header: str | None = None, sep: str = " ", first: str | None = None) -> Path:
    lines = [] if first is None else [first]
    if header is not None:
        lines.append(header)
    lines += [sep.join(_r(v) for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _fit4cad(path: Path, pts: np.ndarray) -> Path:
    body = [f"[{x:.12f}, {y:.12f}, {z:.12f}], " for x, y, z in pts[:-1]]
    x, y, z = pts[-1]
    body.append(f"[{x:.12f}, {y:.12f}, {z:.12f}] ")
    path.write_text("Points:=[\n" + "\n".join(body) + "\n ];\n")
    return path


def _triangles(pts: np.ndarray) -> np.ndarray:
    """(T, 3) vertex indices using every point at least once (a fan-like strip)."""
    n = len(pts)
    return np.array([[i, (i + 1) % n, (i + 2) % n] for i in range(n)], dtype=np.int64)


def _assert_error(path_or_none, exc: pytest.ExceptionInfo, *words: str) -> None:
    msg = str(exc.value)
    assert "\n" not in msg
    if path_or_none is not None:
        assert msg.startswith(f"{path_or_none}: "), msg
    for w in words:
        assert w in msg, msg


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("text", [True, False])
@pytest.mark.parametrize("with_normals", [True, False])
def test_ply_round_trip(tmp_path, cloud, text, with_normals):
    pts, nrm = cloud
    path = _ply(tmp_path / "c.ply", pts, nrm if with_normals else None, text=text)
    pc = read_points(path)
    assert isinstance(pc, PointCloud)
    assert pc.source == str(path)
    assert pc.points.dtype == np.float64 and pc.points.shape == (N, 3)
    np.testing.assert_allclose(pc.points, pts, rtol=1e-12, atol=1e-12)
    if with_normals:
        np.testing.assert_allclose(pc.normals, nrm, atol=1e-6)
    else:
        assert pc.normals is None


def test_ply_big_endian(tmp_path, cloud):
    pts, nrm = cloud
    pc = read_points(_ply(tmp_path / "be.ply", pts, nrm, text=False, byte_order=">"))
    np.testing.assert_array_equal(pc.points, pts)
    np.testing.assert_allclose(pc.normals, nrm, atol=1e-6)


def test_binary_ply_is_memory_mapped_with_the_same_result(tmp_path, cloud, monkeypatch):
    from houghcad.io import ply as ply_io

    pts, nrm = cloud
    rng = np.random.default_rng(0)
    vertex = np.zeros(N, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("nx", "f4"), ("ny", "f4"), ("nz", "f4"),
                                ("intensity", "u2")])
    for i, k in enumerate("xyz"):
        vertex[k] = pts[:, i]
        vertex["n" + k] = nrm[:, i]
    vertex["intensity"] = rng.integers(0, 60000, N)
    path = tmp_path / "c.ply"
    PlyData([PlyElement.describe(vertex, "vertex")], text=False).write(str(path))
    before = path.read_bytes()
    read = ply_io.read_ply(before, str(path))  # from the bytes, as ascii files are read
    calls = []
    mapped = ply_io.read_ply_mapped
    monkeypatch.setattr(ply_io, "read_ply_mapped", lambda *a: calls.append(a) or mapped(*a))
    got = read_points(path)
    assert calls
    np.testing.assert_array_equal(got.points, read[0])
    np.testing.assert_array_equal(got.normals, clean_normals(read[1], N))
    np.testing.assert_array_equal(got.fields["intensity"], vertex["intensity"])
    # Plain arrays, not views of the mapped file, which is left as it was.
    assert type(got.points) is np.ndarray and type(got.fields["intensity"]) is np.ndarray
    assert path.read_bytes() == before
    # A body cut short, or a header announcing more rows than the body holds: one-line errors.
    path.write_bytes(before[: len(before) - 5])
    with pytest.raises(InputError, match="PLY"):
        read_points(path)
    head = before[: before.index(b"end_header")].replace(f"element vertex {N}".encode(), b"element vertex 99999999")
    path.write_bytes(head + before[before.index(b"end_header"):])
    with pytest.raises(InputError, match="more than the file"):
        read_points(path)


def test_ply_detected_by_content_whatever_the_extension(tmp_path, cloud):
    pts, _ = cloud
    path = _ply(tmp_path / "c.xyz", pts, None, text=False)
    np.testing.assert_array_equal(read_points(path).points, pts)


def test_csv_with_header_and_normals(tmp_path, cloud):
    pts, nrm = cloud
    path = _table(tmp_path / "c.csv", np.hstack([pts, nrm]), header="X,Y,Z,Nx,Ny,Nz", sep=",")
    pc = read_points(path)
    np.testing.assert_array_equal(pc.points, pts)
    np.testing.assert_allclose(pc.normals, nrm, atol=1e-12)


@pytest.mark.parametrize(
    "header",
    ["x y z nx ny nz", "# x y z nx ny nz", "//X Y Z Nx Ny Nz", "X Y Z normal_x normal_y normal_z"],
)
def test_xyz_header_variants(tmp_path, cloud, header):
    pts, nrm = cloud
    pc = read_points(_table(tmp_path / "c.xyz", np.hstack([pts, nrm]), header=header))
    np.testing.assert_array_equal(pc.points, pts)
    np.testing.assert_allclose(pc.normals, nrm, atol=1e-12)


def test_header_column_order_is_respected(tmp_path, cloud):
    pts, nrm = cloud
    rows = np.hstack([nrm, np.ones((N, 1)), pts])
    pc = read_points(_table(tmp_path / "c.txt", rows, header="nx ny nz intensity x y z"))
    np.testing.assert_array_equal(pc.points, pts)
    np.testing.assert_allclose(pc.normals, nrm, atol=1e-12)


def test_pts_with_count_line_and_extra_columns(tmp_path, cloud):
    pts, _ = cloud
    extra = np.tile([17.0, 200, 100, 50], (N, 1))  # intensity r g b
    path = _table(tmp_path / "c.pts", np.hstack([pts, extra]), first=str(N))
    pc = read_points(path)
    np.testing.assert_array_equal(pc.points, pts)
    assert pc.normals is None


def test_xyz_six_columns_without_header_are_not_normals(tmp_path, cloud):
    pts, nrm = cloud
    pc = read_points(_table(tmp_path / "c.xyz", np.hstack([pts, nrm])))
    np.testing.assert_array_equal(pc.points, pts)
    assert pc.normals is None


def test_xyz_tabs_blank_lines_and_comments(tmp_path, cloud):
    pts, _ = cloud
    lines = ["# scanner export", ""] + ["\t".join(_r(v) for v in r) + "\t9" for r in pts]
    lines.insert(10, "")
    lines.insert(20, "# a comment in the middle")
    path = tmp_path / "c.xyz"
    path.write_text("\n".join(lines) + "\n")
    np.testing.assert_array_equal(read_points(path).points, pts)


def test_csv_comma_and_spaces(tmp_path, cloud):
    pts, _ = cloud
    path = _table(tmp_path / "c.csv", pts, sep=" , ")
    np.testing.assert_array_equal(read_points(path).points, pts)


@pytest.mark.parametrize("width", [3, 6])
def test_npy_round_trip(tmp_path, cloud, width):
    pts, nrm = cloud
    arr = pts if width == 3 else np.hstack([pts, nrm])
    np.save(tmp_path / "c.npy", arr)
    pc = read_points(tmp_path / "c.npy")
    np.testing.assert_array_equal(pc.points, pts)
    if width == 6:
        np.testing.assert_allclose(pc.normals, nrm, atol=1e-12)
    else:
        assert pc.normals is None


def test_npy_structured_and_float32(tmp_path, cloud):
    pts, nrm = cloud
    rec = np.empty(N, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("nx", "f4"), ("ny", "f4"), ("nz", "f4")])
    rec["x"], rec["y"], rec["z"] = pts.T
    rec["nx"], rec["ny"], rec["nz"] = nrm.T
    np.save(tmp_path / "s.npy", rec)
    pc = read_points(tmp_path / "s.npy")
    assert pc.points.dtype == np.float64
    np.testing.assert_allclose(pc.points, pts, rtol=1e-6)
    np.testing.assert_allclose(pc.normals, nrm, atol=1e-6)


def test_npy_detected_by_magic(tmp_path, cloud):
    pts, _ = cloud
    with open(tmp_path / "c.data", "wb") as f:
        np.save(f, pts)
    np.testing.assert_array_equal(read_points(tmp_path / "c.data").points, pts)


@pytest.mark.parametrize("matching_normals", [True, False])
def test_obj_round_trip(tmp_path, cloud, matching_normals):
    pts, nrm = cloud
    n_vn = N if matching_normals else N - 1
    lines = ["# obj", "o part"] + [f"v {_r(x)} {_r(y)} {_r(z)}" for x, y, z in pts]
    lines += [f"vn {_r(x)} {_r(y)} {_r(z)}" for x, y, z in nrm[:n_vn]]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in _triangles(pts)]
    path = tmp_path / "c.obj"
    path.write_text("\n".join(lines) + "\n")
    pc = read_points(path)
    np.testing.assert_array_equal(pc.points, pts)
    if matching_normals:
        np.testing.assert_allclose(pc.normals, nrm, atol=1e-12)
    else:
        assert pc.normals is None


@pytest.mark.parametrize("keyword", ["OFF", "NOFF", "OFF-inline"])
def test_off_round_trip(tmp_path, cloud, keyword):
    pts, nrm = cloud
    tri = _triangles(pts)
    if keyword == "OFF-inline":
        head = [f"OFF {N} {len(tri)} 0"]
        rows = pts
    else:
        head = [keyword, "# a comment", f"{N} {len(tri)} 0"]
        rows = np.hstack([pts, nrm]) if keyword == "NOFF" else pts
    lines = head + [" ".join(_r(v) for v in r) for r in rows]
    lines += [f"3 {a} {b} {c}" for a, b, c in tri]
    path = tmp_path / "c.off"
    path.write_text("\n".join(lines) + "\n")
    pc = read_points(path)
    np.testing.assert_array_equal(pc.points, pts)
    if keyword == "NOFF":
        np.testing.assert_allclose(pc.normals, nrm, atol=1e-12)
    else:
        assert pc.normals is None


def _stl_binary(path: Path, pts: np.ndarray, tri: np.ndarray, header: bytes = b"binary stl") -> None:
    rec = np.zeros(len(tri), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = pts[tri]
    with open(path, "wb") as f:
        f.write(header.ljust(80, b" "))
        f.write(np.uint32(len(tri)).tobytes())
        f.write(rec.tobytes())


def _stl_ascii(path: Path, pts: np.ndarray, tri: np.ndarray) -> None:
    out = ["solid part"]
    for t in tri:
        out.append("  facet normal 0 0 1\n    outer loop")
        out += [f"      vertex {_r(x)} {_r(y)} {_r(z)}" for x, y, z in pts[t]]
        out.append("    endloop\n  endfacet")
    out.append("endsolid part")
    path.write_text("\n".join(out) + "\n")


@pytest.mark.parametrize("kind", ["ascii", "binary", "binary-solid-header"])
def test_stl_unique_vertices(tmp_path, cloud, kind):
    pts = cloud[0].astype(np.float32).astype(np.float64)  # binary STL stores float32
    tri = _triangles(pts)
    path = tmp_path / "c.stl"
    if kind == "ascii":
        _stl_ascii(path, pts, tri)
    else:
        _stl_binary(path, pts, tri, header=b"solid but binary" if kind.endswith("header") else b"bin")
    pc = read_points(path)
    assert pc.points.shape == (N, 3)  # each vertex appears 3 times in the triangles, once in the result
    np.testing.assert_array_equal(pc.points, pts)  # first-appearance order == index order here
    assert pc.normals is None
    # deterministic
    np.testing.assert_array_equal(read_points(path).points, pc.points)


@pytest.mark.parametrize("suffix", [".txt", ".f4c"])
def test_fit4cad_round_trip(tmp_path, cloud, suffix):
    pts, _ = cloud
    path = _fit4cad(tmp_path / f"PC{suffix}", pts)
    pc = read_points(path)
    np.testing.assert_allclose(pc.points, pts, atol=1e-12)
    assert pc.normals is None


def test_explicit_format(tmp_path, cloud):
    pts, _ = cloud
    path = _table(tmp_path / "points.dat", pts, header="x y z")
    np.testing.assert_array_equal(read_points(path, fmt="xyz").points, pts)
    with pytest.raises(InputError) as e:
        read_points(path, fmt="bogus")
    _assert_error(path, e, "unknown format")


def test_unknown_extension_numeric_table_is_read_as_xyz(tmp_path, cloud):
    pts, _ = cloud
    np.testing.assert_array_equal(read_points(_table(tmp_path / "c.dat", pts)).points, pts)


def test_write_points_ply_round_trip(tmp_path, cloud):
    pts, _ = cloud
    labels = np.arange(N) % 4 - 1
    dist = np.linspace(0.0, 1.0, N)
    colors = np.tile([0.0, 0.5, 1.0], (N, 1))
    for binary in (True, False):
        path = tmp_path / f"out_{binary}.ply"
        fields = {"segment": labels, "dist": dist, "near": dist.astype(np.float32), "on": labels >= 0,
                  "big": np.full(N, 2**40)}
        write_points_ply(path, pts, fields=fields, colors=colors, binary=binary)
        ply = PlyData.read(str(path))
        v = ply["vertex"]
        assert [p.name for p in v.properties] == ["x", "y", "z", *fields, "red", "green", "blue"]
        # Each field in its own type where PLY has one; int64 as int32 when it fits, else double.
        types = {name: v.data.dtype[name] for name in ("x", *fields, "red")}
        assert types == {"x": np.float64, "segment": np.int32, "dist": np.float64, "near": np.float32,
                         "on": np.uint8, "big": np.float64, "red": np.uint8}
        np.testing.assert_array_equal(v["segment"], labels)
        np.testing.assert_array_equal(v["dist"], dist)
        assert (v["big"] == 2**40).all()
        np.testing.assert_array_equal(np.column_stack([v["red"], v["green"], v["blue"]])[0], [0, 128, 255])
        np.testing.assert_allclose(read_points(path).points, pts, rtol=1e-12, atol=1e-12)


def test_write_points_ply_rejects_bad_fields(tmp_path, cloud):
    pts, _ = cloud
    with pytest.raises(ValueError):
        write_points_ply(tmp_path / "a.ply", pts, fields={"x": np.zeros(N)})
    with pytest.raises(ValueError):
        write_points_ply(tmp_path / "a.ply", pts, fields={"s": np.zeros(N - 1)})
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------- speed


def test_large_files_parse_fast(tmp_path):
    rng = np.random.default_rng(0)
    pts = rng.uniform(-100, 100, size=(50_000, 3))
    f4c = _fit4cad(tmp_path / "big.txt", pts)
    xyz = _table(tmp_path / "big.xyz", np.hstack([pts, rng.normal(size=(50_000, 3))]), header="x y z nx ny nz")
    for path in (f4c, xyz):
        t0 = time.perf_counter()
        pc = read_points(path)
        assert time.perf_counter() - t0 < 1.0
        assert len(pc) == 50_000


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("name", ["empty.xyz", "empty.ply", "empty.txt", "empty.npy", "empty.stl", "empty.what"])
def test_empty_file(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"")
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "empty")


def test_header_only_has_no_points(tmp_path):
    path = tmp_path / "h.csv"
    path.write_text("x,y,z\n")
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "no numeric point data")


def _replace_line(path, i, text):
    """Replace line i (0-based) of a text file."""
    lines = path.read_text().splitlines()
    lines[i] = text
    path.write_text("\n".join(lines) + "\n")


def test_non_numeric_value_names_file_and_line(tmp_path, cloud):
    pts, _ = cloud
    path = _table(tmp_path / "bad.xyz", pts, header="x y z")
    _replace_line(path, 7, "1.0 abc 3.0")
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "non-numeric", "'abc'", "line 8")


def test_non_numeric_on_first_line(tmp_path, cloud):
    path = _table(tmp_path / "bad.xyz", cloud[0], first="1.0 2.0 oops")
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "non-numeric", "'oops'", "line 1")


def test_too_few_columns(tmp_path, cloud):
    path = _table(tmp_path / "c.xyz", cloud[0])
    _replace_line(path, 4, "1.0 2.0")
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "line 5", "2 columns")


def test_fit4cad_non_numeric_names_line(tmp_path, cloud):
    path = _fit4cad(tmp_path / "PC.txt", cloud[0])
    _replace_line(path, 5, "[1.0, x2, 3.0], ")
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "non-numeric", "'x2'", "line 6")


def test_fit4cad_unclosed(tmp_path, cloud):
    path = _fit4cad(tmp_path / "PC.txt", cloud[0])
    path.write_text(path.read_text().replace("];", ""))
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "not closed")


@pytest.mark.parametrize("bad,word", [(np.nan, "NaN"), (np.inf, "infinite"), (-np.inf, "infinite")])
@pytest.mark.parametrize("fmt", ["xyz", "npy", "ply"])
def test_non_finite(tmp_path, cloud, bad, word, fmt):
    pts = cloud[0].copy()
    pts[12, 1] = bad
    path = tmp_path / f"c.{fmt}"
    if fmt == "xyz":
        _table(path, pts)
    elif fmt == "npy":
        np.save(path, pts)
    else:
        _ply(path, pts, None, text=True)
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, word, "point 13")


def test_too_few_points(tmp_path, cloud):
    path = _table(tmp_path / "ten.xyz", cloud[0][:10])
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "only 10 points", str(MIN_POINTS))


def test_coplanar_is_a_surface(tmp_path):
    """A flat cloud (one planar face) is read; only lines and single points are refused."""
    rng = np.random.default_rng(3)
    uv = rng.uniform(-1, 1, size=(100, 2))
    # a tilted plane, so no coordinate is constant
    pts = np.array([1.0, 0.0, 2.0]) + uv[:, :1] * [0.6, 0.8, 0.0] + uv[:, 1:] * [0.0, 0.0, 1.0] * 3.0
    path = _table(tmp_path / "flat.xyz", pts)
    np.testing.assert_allclose(read_points(path).points, pts)


def test_collinear(tmp_path):
    t = np.linspace(-2.0, 5.0, 50)[:, None]
    pts = np.array([1.0, 2.0, 3.0]) + t * np.array([0.3, -0.2, 0.9])
    path = _table(tmp_path / "line.xyz", pts)
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "all points are collinear")


@pytest.mark.parametrize("point", [[1.0, 2.0, 3.0], [0.1, 0.2, 0.3]])
def test_identical_points(tmp_path, point):
    # 50 copies of (0.1, 0.2, 0.3): their mean's rounding once read as collinear.
    path = _table(tmp_path / "same.xyz", np.tile(point, (50, 1)))
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "all points are identical")


def test_missing_file(tmp_path):
    path = tmp_path / "nope.ply"
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "file not found")


def test_directory(tmp_path):
    with pytest.raises(InputError) as e:
        read_points(tmp_path)
    _assert_error(tmp_path, e, "directory")


@pytest.mark.parametrize("content", [b"hello world\nthis is not a point cloud\n", bytes(range(256)) * 4])
def test_unknown_extension_garbage(tmp_path, content):
    path = tmp_path / "thing.foo"
    path.write_bytes(content)
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e, "unrecognised file format", ".foo")


@pytest.mark.parametrize("name,content", [
    ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n"),
    ("bad.npy", b"\x93NUMPY garbage"),
    ("bad.stl", b"not an stl at all"),
    ("bad.off", b"OFF\nlots of nonsense\n"),
    ("bad.obj", b"v 1 2\n"),
    ("bad.xyz", b"\x00\x01\x02binary"),
])
def test_corrupt_files(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(InputError) as e:
        read_points(path)
    _assert_error(path, e)


def test_duplicate_points_tolerated(tmp_path, cloud):
    pts = np.repeat(cloud[0], 3, axis=0)
    pc = read_points(_table(tmp_path / "dup.xyz", pts))
    assert pc.points.shape == (3 * N, 3)


def test_input_file_unchanged(tmp_path, cloud):
    pts, nrm = cloud
    paths = [
        _ply(tmp_path / "a.ply", pts, nrm, text=False),
        _table(tmp_path / "a.csv", np.hstack([pts, nrm]), header="x,y,z,nx,ny,nz", sep=","),
        _fit4cad(tmp_path / "a.txt", pts),
    ]
    np.save(tmp_path / "a.npy", pts)
    paths.append(tmp_path / "a.npy")
    before = {p: (p.read_bytes(), p.stat().st_mtime_ns, p.stat().st_mode) for p in paths}
    for p in paths:
        read_points(p)
    after = {p: (p.read_bytes(), p.stat().st_mtime_ns, p.stat().st_mode) for p in paths}
    assert before == after
    assert sorted(tmp_path.iterdir()) == sorted(paths)


# --------------------------------------------------------------------------- validate_points / normals


def test_validate_points_messages_without_source():
    with pytest.raises(InputError) as e:
        validate_points(np.zeros((0, 3)), None)
    _assert_error("input", e, "no points")
    with pytest.raises(InputError) as e:
        validate_points(np.zeros((30, 2)), None)
    _assert_error("input", e, "shape")
    with pytest.raises(InputError) as e:
        validate_points(np.array([["a", "b", "c"]] * 30), "mem")
    _assert_error("mem", e, "non-numeric")


def test_non_finite_points_name_the_way_out_only_when_read_from_a_file(tmp_path, cloud):
    # An array handed in has no --drop-invalid to name; a file read by read_points has.
    pts = cloud[0].copy()
    pts[3, 1] = np.nan
    with pytest.raises(InputError, match=r"^mem: NaN coordinate at point 4 of \d+$"):
        validate_points(pts, "mem")
    path = tmp_path / "holes.xyz"
    np.savetxt(path, pts)
    with pytest.raises(InputError, match=r"NaN coordinate at point 4 of \d+ \(.*--drop-invalid.*\)$"):
        read_points(path)
    assert len(read_points(path, drop_invalid=True)) == len(pts) - 1


def test_validate_points_returns_float64(cloud):
    pts = validate_points(cloud[0].astype(np.float32), "x")
    assert pts.dtype == np.float64 and pts.flags.c_contiguous
    pts2, nrm = validate_points(cloud[0], "x", cloud[1], return_normals=True)
    np.testing.assert_array_equal(pts2, cloud[0])
    np.testing.assert_allclose(nrm, cloud[1])


def test_bad_normals_are_dropped(tmp_path, cloud):
    pts, nrm = cloud
    # Each time a warning names the file (or "input") and why the normals are not used.
    with pytest.warns(InputWarning, match=rf"input: the normals given are not used \(shape \({N - 1}, 3\)"):
        assert clean_normals(nrm[:-1], N) is None
    bad = nrm.copy()
    bad[3, 0] = np.nan
    with pytest.warns(InputWarning, match="a NaN or infinite value at row 4"):
        assert clean_normals(bad, N) is None
    bad = nrm.copy()
    bad[5] = 0.0
    with pytest.warns(InputWarning, match="a zero-length normal at row 6"):
        assert clean_normals(bad, N, "part.ply") is None
    np.testing.assert_allclose(np.linalg.norm(clean_normals(nrm * 7.0, N), axis=1), 1.0)
    # through a file: NaN normals do not make the file unreadable
    with pytest.warns(InputWarning, match="n.csv: the normals given are not used"):
        pc = read_points(_table(tmp_path / "n.csv", np.hstack([pts, np.full((N, 3), np.nan)]),
                                header="x,y,z,nx,ny,nz", sep=","))
    assert pc.normals is None
    np.testing.assert_array_equal(pc.points, pts)


# --------------------------------------------------------------------------- writers


def test_atomic_write_success_and_permissions(tmp_path):
    path = tmp_path / "out.txt"
    with atomic_write(path) as f:
        f.write("hello")
        assert not path.exists()  # nothing visible until the block completes
    assert path.read_text() == "hello"
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_write_failure_leaves_nothing(tmp_path):
    path = tmp_path / "out.bin"
    with pytest.raises(RuntimeError):
        with atomic_write(path, "wb") as f:
            f.write(b"partial")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []
    # an existing file survives a failed rewrite untouched
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_write(path, "wb") as f:
            f.write(b"new")
            raise RuntimeError("boom")
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.bin"]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_atomic_write_to_a_pipe_writes_into_it_and_keeps_it(tmp_path):
    # A device or a pipe (/dev/null, a FIFO) is written directly: renaming a
    # temporary file over it replaced /dev/null itself with a regular file.
    import threading

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    with atomic_write(fifo, "wb") as f:
        f.write(b"streamed")
    reader.join(timeout=10)
    assert got == [b"streamed"]
    assert fifo.is_fifo()
    assert [p.name for p in tmp_path.iterdir()] == ["pipe"]


def test_atomic_write_to_dev_full_fails_and_dev_null_stays_a_device():
    if os.path.exists("/dev/full") and os.path.exists("/dev/null"):
        with pytest.raises(OSError):
            with atomic_write("/dev/full") as f:
                f.write("x" * 100_000)
        with atomic_write("/dev/null") as f:
            f.write("discarded")
        assert Path("/dev/null").is_char_device() and Path("/dev/full").is_char_device()


def test_atomic_write_missing_directory(tmp_path):
    with pytest.raises(OSError):
        with atomic_write(tmp_path / "no" / "such" / "dir.json") as f:
            f.write("x")


def test_write_json_compact_and_numpy(tmp_path):
    path = tmp_path / "r.json"
    write_json(path, {"a": np.int64(3), "b": np.arange(3), "c": [np.float32(0.5)], "d": "é"})
    text = path.read_text(encoding="utf-8")
    assert text == '{"a":3,"b":[0,1,2],"c":[0.5],"d":"\\u00e9"}\n'
    assert json.loads(text)["b"] == [0, 1, 2]


def test_write_json_unserialisable_writes_nothing(tmp_path):
    path = tmp_path / "r.json"
    with pytest.raises(TypeError):
        write_json(path, {"x": object()})
    assert list(tmp_path.iterdir()) == []


def test_write_fit4cad_primitives_layout(tmp_path):
    path = tmp_path / "PC_primitives.txt"
    write_fit4cad_primitives(path, [np.array([3, 0, 1, 2]), np.array([10, 4], dtype=np.int32), np.array([], dtype=np.int64)])
    assert path.read_text() == "Primitive1:=[1 2 3 4];\n\nPrimitive2:=[5 11];\n\nPrimitive3:=[];\n\n"
    blocks = re.findall(r"Primitive(\d+):=\[([^\]]*)\];", path.read_text())
    assert [b[0] for b in blocks] == ["1", "2", "3"]
    with pytest.raises(ValueError):
        write_fit4cad_primitives(tmp_path / "bad.txt", [np.array([-1, 2])])
    assert not (tmp_path / "bad.txt").exists()
