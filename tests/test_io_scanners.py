"""Scanner formats: LAS/LAZ, E57 and PCD read with their normals and fields; bad files refused."""

from __future__ import annotations

import numpy as np
import pytest

from houghcad.errors import InputError
from houghcad.io import read_points
from houghcad.io.readers import detect_format

from _scanner_files import e57_bytes, las_bytes, pcd_bytes

N = 400


def _cloud(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points on a sphere of radius 2 about (10, -5, 3) and their unit normals."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(N, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.array([10.0, -5.0, 3.0]) + 2.0 * n, n


def _write_las(path, pts, normals=None, intensity=None):
    path.write_bytes(las_bytes(pts, normals, intensity, compressed=path.suffix == ".laz"))


@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_las_round_trip_with_normals_and_fields(tmp_path, ext):
    pts, nrm = _cloud()
    path = tmp_path / f"scan{ext}"
    _write_las(path, pts, nrm, intensity=np.arange(N, dtype=np.uint16))
    assert detect_format(str(path), path.read_bytes()) == "las"
    cloud = read_points(path)
    np.testing.assert_allclose(cloud.points, pts, atol=1e-6)
    np.testing.assert_allclose(cloud.normals, nrm, atol=1e-6)
    np.testing.assert_array_equal(cloud.fields["intensity"], np.arange(N))
    assert "classification" in cloud.fields and "nx" not in cloud.fields


def _write_pcd(path, columns: dict[str, np.ndarray], encoding: str):
    path.write_bytes(pcd_bytes(columns, encoding))


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_pcd_round_trip_with_normals_and_fields(tmp_path, encoding):
    pts, nrm = _cloud(1)
    cols = {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2], "normal_x": nrm[:, 0], "normal_y": nrm[:, 1],
            "normal_z": nrm[:, 2], "intensity": np.arange(N, dtype=float)}
    path = tmp_path / "cloud.pcd"
    _write_pcd(path, cols, encoding)
    cloud = read_points(path)
    np.testing.assert_allclose(cloud.points, pts, atol=1e-5)
    np.testing.assert_allclose(cloud.normals, nrm, atol=1e-5)
    np.testing.assert_array_equal(cloud.fields["intensity"], np.arange(N))
    # Found by content too, whatever the file is called.
    other = tmp_path / "cloud.dat"
    other.write_bytes(path.read_bytes())
    assert read_points(other).points.shape == (N, 3)


def test_an_ascii_pcd_cut_short_is_called_truncated(tmp_path):
    pts, _ = _cloud(1)
    data = pcd_bytes({"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}, "ascii")
    path = tmp_path / "cut.pcd"
    path.write_bytes(data[: data.rindex(b"\n", 0, len(data) // 2) + 1])  # whole rows, half of them
    with pytest.raises(InputError, match=f"truncated PCD file \\(\\d+ of the {N} points"):
        read_points(path)


def test_nan_rows_are_refused_unless_dropped(tmp_path):
    pts, _ = _cloud(2)
    pts[[5, 17, 99]] = np.nan  # an organised cloud's missing points
    path = tmp_path / "organised.pcd"
    _write_pcd(path, {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2], "intensity": np.arange(N, dtype=float)},
               "binary")
    with pytest.raises(InputError, match="NaN coordinate at point 6 of 400"):
        read_points(path)
    cloud = read_points(path, drop_invalid=True)
    assert cloud.dropped == 3 and len(cloud.points) == N - 3
    assert len(cloud.fields["intensity"]) == N - 3 and 5 not in cloud.fields["intensity"]


def _write_e57(path, scans):
    path.write_bytes(e57_bytes(scans))


def test_e57_merges_every_scan_in_the_common_frame_or_reads_one(tmp_path):
    a, _ = _cloud(3)
    b, _ = _cloud(4)
    path = tmp_path / "site.e57"
    _write_e57(path, [(a, np.zeros(3)), (b, np.array([100.0, 0.0, 0.0]))])
    assert detect_format(str(path), path.read_bytes()) == "e57"
    cloud = read_points(path)
    assert cloud.points.shape == (2 * N, 3)
    np.testing.assert_allclose(cloud.points[:N], a, atol=1e-9)
    np.testing.assert_allclose(cloud.points[N:], b + [100.0, 0.0, 0.0], atol=1e-9)  # each scan's pose applied
    np.testing.assert_array_equal(cloud.fields["scan"], np.repeat([0, 1], N))
    one = read_points(path, scan=1)
    np.testing.assert_allclose(one.points, b + [100.0, 0.0, 0.0], atol=1e-9)
    with pytest.raises(InputError, match="no scan 2 \\(the file holds scans 0 to 1\\)"):
        read_points(path, scan=2)
    xyz = tmp_path / "a.xyz"
    np.savetxt(xyz, a)
    with pytest.raises(InputError, match="a scan can be chosen in E57 files only"):
        read_points(xyz, scan=0)


@pytest.mark.parametrize("name", ["scan.las", "scan.laz", "cloud.pcd", "site.e57"])
def test_bad_scanner_files_give_one_line_errors_and_no_output(tmp_path, capsys, name):
    from houghcad.cli import main

    pts, nrm = _cloud(5)
    path = tmp_path / name
    if name.endswith((".las", ".laz")):
        _write_las(path, pts, nrm)
    elif name.endswith(".pcd"):
        _write_pcd(path, {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}, "binary")
    else:
        _write_e57(path, [(pts, np.zeros(3))])
    good = path.read_bytes()
    # Truncated, and a damaged header (LAS: its header size and offset to the points).
    at = 94 if name.endswith((".las", ".laz")) else 8
    for bad in (good[: len(good) // 3], good[:at] + b"\xff" * 40 + good[at + 40:]):
        path.write_bytes(bad)
        out = tmp_path / "r.json"
        assert main(["segment", str(path), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("houghcad: error: ") and err.count("\n") == 1, err
        assert not out.exists()


def test_cli_drop_invalid_says_how_many(tmp_path, capsys, monkeypatch):
    import sys
    import types

    from houghcad.cli import main
    from houghcad.result import Result

    pts, _ = _cloud(6)
    pts[:4] = np.inf
    path = tmp_path / "organised.pcd"
    _write_pcd(path, {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}, "ascii")
    stub = types.ModuleType("houghcad.pipeline")
    stub.segment = lambda points, normals=None, **kw: Result(len(points), [], np.arange(len(points)))
    monkeypatch.setitem(sys.modules, "houghcad.pipeline", stub)
    assert main(["segment", str(path), "-o", str(tmp_path / "a.json")]) == 2
    assert "infinite coordinate at point 1 of 400" in capsys.readouterr().err
    assert main(["segment", str(path), "-o", str(tmp_path / "b.json"), "--drop-invalid"]) == 0
    assert "left out 4 points with a NaN or infinite coordinate" in capsys.readouterr().err
