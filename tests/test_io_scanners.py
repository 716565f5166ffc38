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
    with pytest.raises(InputError, match="NaN coordinate at point 6 of 400") as e:
        read_points(path)
    # The refusal names the way out, for the CLI's user and read_points's caller alike, on one line.
    assert "--drop-invalid" in str(e.value) and "drop_invalid=True" in str(e.value) and "\n" not in str(e.value)
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


def _stub_pipeline(monkeypatch):
    """``houghcad.pipeline`` replaced by a stub: the first half of the points one plane."""
    import sys
    import types

    from houghcad.result import Result, Segment

    def segment(points, normals=None, **kw):
        half = len(points) // 2
        plane = Segment(0, "plane", np.arange(half), {"normal": [0.0, 0.0, 1.0], "offset": 0.0}, 0.0)
        return Result(len(points), [plane], np.arange(half, len(points)), source=kw.get("source"))

    stub = types.ModuleType("houghcad.pipeline")
    stub.segment = segment
    monkeypatch.setitem(sys.modules, "houghcad.pipeline", stub)


def test_cli_drop_invalid_says_how_many(tmp_path, capsys, monkeypatch):
    from houghcad.cli import main

    pts, _ = _cloud(6)
    pts[:4] = np.inf
    path = tmp_path / "organised.pcd"
    _write_pcd(path, {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}, "ascii")
    _stub_pipeline(monkeypatch)
    assert main(["segment", str(path), "-o", str(tmp_path / "a.json")]) == 2
    err = capsys.readouterr().err
    assert "infinite coordinate at point 1 of 400" in err
    assert "--drop-invalid, or drop_invalid=True in read_points, leaves such rows out" in err
    assert len(err.strip().splitlines()) == 1
    assert main(["segment", str(path), "-o", str(tmp_path / "b.json"), "--drop-invalid"]) == 0
    assert "left out 4 points with a NaN or infinite coordinate" in capsys.readouterr().err


# --------------------------------------------------------------------------- field types


def test_pcd_fields_keep_their_own_types_through_to_the_output_ply(tmp_path, monkeypatch):
    """A packed float rgb stays float32 bit for bit (CloudCompare reads it as colour), a uint32
    label stays uint32: neither goes through float64."""
    from plyfile import PlyData

    from houghcad.cli import main

    pts, nrm = _cloud(7)
    pts += [500000.0, 4000000.0, 100.0]  # georeferenced: x, y, z stored as F 8
    k = np.arange(N)
    # Packed 0xAARRGGBB; an alpha of 255 makes NaN bit patterns (0xFF80.. a signalling one).
    rgb = np.array([0xFF800001, 0x00FF0000, 0xFFFFFFFF, 0x0000FF00], dtype=np.uint32)[k % 4]
    label = (4_000_000_000 - 1000 * k).astype(np.uint32)  # exact only as an integer type
    cols = {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2], "normal_x": nrm[:, 0], "normal_y": nrm[:, 1],
            "normal_z": nrm[:, 2], "intensity": k / 7.0, "rgb": rgb.view(np.float32), "label": label}
    types = {"x": np.float64, "y": np.float64, "z": np.float64, "rgb": np.float32, "label": np.uint32}
    path = tmp_path / "typed.pcd"
    path.write_bytes(pcd_bytes(cols, "binary_compressed", types))
    cloud = read_points(path)
    assert {k: v.dtype for k, v in cloud.fields.items()} == {
        "intensity": np.float32, "rgb": np.float32, "label": np.uint32}
    np.testing.assert_allclose(cloud.points, pts, rtol=0, atol=1e-9)  # F 8 coordinates read as such

    _stub_pipeline(monkeypatch)
    out = tmp_path / "out.ply"
    assert main(["segment", str(path), "-o", str(tmp_path / "r.json"), "--ply", str(out), "-q"]) == 0
    v = PlyData.read(str(out))["vertex"]
    types_out = {p.name: p.val_dtype for p in v.properties}
    assert (types_out["intensity"], types_out["rgb"], types_out["label"]) == ("f4", "f4", "u4")
    np.testing.assert_array_equal(v.data["rgb"].view(np.uint32), rgb)
    np.testing.assert_array_equal(v.data["label"], label)
    np.testing.assert_array_equal(v.data["intensity"], (k / 7.0).astype(np.float32))


def test_las_and_e57_fields_keep_their_own_types(tmp_path):
    pts, nrm = _cloud(8)
    las = tmp_path / "scan.las"
    _write_las(las, pts, nrm, intensity=np.arange(N, dtype=np.uint16))
    fields = read_points(las).fields
    assert fields["intensity"].dtype == np.uint16 and fields["classification"].dtype == np.uint8
    e57 = tmp_path / "site.e57"
    _write_e57(e57, [(pts, np.zeros(3)), (pts, np.ones(3))])
    fields = read_points(e57).fields
    assert fields["intensity"].dtype == np.float32 and fields["scan"].dtype == np.int32


# --------------------------------------------------------------------------- provenance


def test_row_ranges_are_half_open_runs():
    from houghcad.io.readers import row_ranges

    mask = np.zeros(12, dtype=bool)
    mask[[0, 1, 2, 5, 11]] = True
    assert row_ranges(mask).tolist() == [[0, 3], [5, 6], [11, 12]]
    assert row_ranges(np.zeros(4, dtype=bool)).shape == (0, 2)


def test_drop_invalid_records_the_rows_left_out(tmp_path):
    pts, _ = _cloud(9)
    pts[[5, 6, 7, 99]] = np.nan  # a run of missing points, and one alone
    path = tmp_path / "organised.pcd"
    _write_pcd(path, {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}, "binary")
    cloud = read_points(path, drop_invalid=True)
    assert cloud.provenance() == {"rows": N, "scan": None, "drop_invalid": True, "dropped_rows": [[5, 8], [99, 100]],
                                  "dropped": {"flagged_invalid": 0, "non_finite": 4}}
    # Point i is the i-th row outside the ranges.
    rows = np.setdiff1d(np.arange(N), np.r_[5:8, 99])
    np.testing.assert_allclose(cloud.points, pts[rows], atol=1e-5)
    whole, _ = _cloud(9)
    _write_pcd(path, {"x": whole[:, 0], "y": whole[:, 1], "z": whole[:, 2]}, "binary")
    assert read_points(path, drop_invalid=True).provenance() == {
        "rows": N, "scan": None, "drop_invalid": True, "dropped_rows": [],
        "dropped": {"flagged_invalid": 0, "non_finite": 0}}


def test_e57_rows_flagged_invalid_are_left_out_counted_and_recorded(tmp_path):
    a, _ = _cloud(10)
    b, _ = _cloud(11)
    state = np.zeros(N, dtype=np.int8)
    state[[0, 1, 2, 50, N - 1]] = [2, 2, 1, 2, 2]  # no point, no point, direction only ...
    path = tmp_path / "site.e57"
    path.write_bytes(e57_bytes([(a, np.zeros(3)), (b, np.array([100.0, 0.0, 0.0]))], invalid=[None, state]))
    # Left out without --drop-invalid: they hold no coordinates (pye57 returns none for them).
    cloud = read_points(path)
    assert len(cloud) == 2 * N - 5 and cloud.flagged == 5 and cloud.dropped == 0
    assert cloud.provenance() == {"rows": 2 * N, "scan": None, "drop_invalid": False,
                                  "dropped_rows": [[N, N + 3], [N + 50, N + 51], [2 * N - 1, 2 * N]],
                                  "dropped": {"flagged_invalid": 5, "non_finite": 0}, "scan_rows": [N, N]}
    np.testing.assert_allclose(cloud.points[N:], b[state == 0] + [100.0, 0.0, 0.0], atol=1e-9)
    assert len(cloud.fields["intensity"]) == len(cloud) and (cloud.fields["scan"][N:] == 1).all()
    one = read_points(path, scan=1)  # rows numbered in the scan
    assert one.provenance() == {"rows": N, "scan": 1, "drop_invalid": False,
                                "dropped_rows": [[0, 3], [50, 51], [N - 1, N]],
                                "dropped": {"flagged_invalid": 5, "non_finite": 0}}
    assert read_points(path, scan=0).provenance()["dropped_rows"] == []


def test_flagged_and_non_finite_rows_are_recorded_together(tmp_path, monkeypatch):
    """A NaN row among the points of a file that also flags rows: the ranges count file rows."""
    import dataclasses

    from houghcad.io import readers
    from houghcad.io.common import Rows

    pts, _ = _cloud(12)
    flagged = np.zeros(N + 4, dtype=bool)
    flagged[[3, 4, 10, 11]] = True  # rows 3, 4, 10, 11 hold no point: point 8 is row 12
    pts[[8, 9]] = np.nan  # rows 12, 13: [10, 14) is one run

    def fake(data, source, scan=None):
        return pts, None, {"i": np.arange(N, dtype=np.uint16)}, Rows(flagged)

    fmt = readers._BY_NAME["e57"]
    monkeypatch.setitem(readers._BY_NAME, "e57", dataclasses.replace(fmt, read=fake))
    path = tmp_path / "site.e57"
    path.write_bytes(b"ASTM-E57" + bytes(64))  # found as E57 by its signature, read by the fake
    cloud = read_points(path, drop_invalid=True)
    assert cloud.provenance()["dropped_rows"] == [[3, 5], [10, 14]]
    assert (cloud.flagged, cloud.dropped, cloud.rows) == (4, 2, N + 4)
    assert 8 not in cloud.fields["i"] and len(cloud.fields["i"]) == N - 2


def test_cli_records_the_scan_and_the_rows_left_out(tmp_path, capsys, monkeypatch):
    import json

    from houghcad.cli import main

    _stub_pipeline(monkeypatch)
    a, _ = _cloud(13)
    state = np.zeros(N, dtype=np.int8)
    state[::40] = 2
    site = tmp_path / "site.e57"
    site.write_bytes(e57_bytes([(a, np.zeros(3)), (a, np.ones(3))], invalid=[state, None]))
    # Flagged rows: left out and said without --drop-invalid.
    assert main(["segment", str(site), "-o", str(tmp_path / "all.json")]) == 0
    assert "left out 10 points the scanner flagged as invalid" in capsys.readouterr().err
    doc = json.loads((tmp_path / "all.json").read_text())
    assert doc["n_points"] == 2 * N - 10
    assert doc["options"]["input"] == {"rows": 2 * N, "scan": None, "drop_invalid": False,
                                       "dropped_rows": [[r, r + 1] for r in range(0, N, 40)],
                                       "dropped": {"flagged_invalid": 10, "non_finite": 0}, "scan_rows": [N, N]}
    assert main(["segment", str(site), "--scan", "1", "-o", str(tmp_path / "one.json"), "-q"]) == 0
    assert capsys.readouterr().err == ""
    doc = json.loads((tmp_path / "one.json").read_text())
    assert doc["source"] == str(site) and doc["n_points"] == N
    assert doc["options"]["input"] == {"rows": N, "scan": 1, "drop_invalid": False, "dropped_rows": [],
                                       "dropped": {"flagged_invalid": 0, "non_finite": 0}}
    pts, _ = _cloud(14)
    pts[10:20] = np.nan
    pcd = tmp_path / "organised.pcd"
    _write_pcd(pcd, {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}, "binary")
    assert main(["segment", str(pcd), "--drop-invalid", "-o", str(tmp_path / "pcd.json")]) == 0
    assert "left out 10 points with a NaN or infinite coordinate" in capsys.readouterr().err
    doc = json.loads((tmp_path / "pcd.json").read_text())
    assert doc["options"]["input"] == {"rows": N, "scan": None, "drop_invalid": True, "dropped_rows": [[10, 20]],
                                       "dropped": {"flagged_invalid": 0, "non_finite": 10}}
