"""Tests of houghcad.evaluate: hand-computed measures, readers, and the real Fit4CAD files."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from houghcad.errors import InputError
from houghcad.evaluate import (
    MEASURES,
    classification_measures,
    evaluate_files,
    in_file_rows,
    ground_truth_for,
    mfe_stats,
    read_fit4cad_parameters,
    read_fit4cad_segments,
    read_fit4cad_types,
)
from houghcad.result import Part, Result, Segment


def _fit4cad_dir() -> Path:
    """Folder holding PCn.txt files: $HOUGHCAD_FIT4CAD, else ../shared/fit4cad beside the repo."""
    root = Path(os.environ.get("HOUGHCAD_FIT4CAD") or
                Path(__file__).resolve().parents[1].parent / "shared" / "fit4cad")
    return root / "training_set" if (root / "training_set").is_dir() else root


DATA = _fit4cad_dir()
needs_data = pytest.mark.skipif(
    not (DATA / "PC1_primitives.txt").is_file(),
    reason=f"Fit4CAD training set not found at {DATA} (set HOUGHCAD_FIT4CAD to its folder)",
)


def _arr(*xs: int) -> np.ndarray:
    return np.array(xs, dtype=np.int64)


def _check(got: dict, want: dict) -> None:
    for k, v in want.items():
        assert got[k] == pytest.approx(v), k


# --------------------------------------------------------------------------- hand-computed


def test_perfect_segmentation_scores_one():
    gt = [_arr(0, 1, 2), _arr(3, 4)]
    m = classification_measures([_arr(3, 4), _arr(2, 1, 0)], gt, 6)  # order and point 5 irrelevant
    _check(m, {k: 1.0 for k in MEASURES})


def test_split_ground_truth_segment():
    # G0 = {0,1,2,3} split into P0 = {0,1} and P1 = {2,3}: tie -> first (P0).
    # G0: TP=2 FP=0 FN=2 TN=6-4=2 -> DSC 4/6, PPV 1, TPR 1/2, TNR 1, NPV 1/2, ACC 4/6.
    gt = [_arr(0, 1, 2, 3), _arr(4, 5)]
    pred = [_arr(0, 1), _arr(2, 3), _arr(4, 5)]
    m = classification_measures(pred, gt, 6, per_segment=True)
    _check(m, {"DSC": (2 / 3 + 1) / 2, "PPV": 1.0, "TPR": 0.75, "TNR": 1.0, "NPV": 0.75,
               "ACC": (2 / 3 + 1) / 2})
    ps = m["per_segment"]
    assert ps["match"].tolist() == [0, 2]
    assert ps["TP"].tolist() == [2, 2] and ps["FN"].tolist() == [2, 0] and ps["TN"].tolist() == [2, 4]


def test_merged_prediction_counts_points_outside_u_in_dsc_only():
    # One prediction {0..6} covers both G0={0,1,2}, G1={3,4,5}; point 6 is in no GT segment.
    # G0: TP=3, |P|=7, |P n U|=6 -> FP=3, FN=0, TN=0. DSC=6/(3+7)=0.6 (|P| is the full size),
    # PPV=0.5, TPR=1, TNR=0/3=0, NPV=0/0 -> 1, ACC=3/6.
    gt = [_arr(0, 1, 2), _arr(3, 4, 5)]
    m = classification_measures([np.arange(7)], gt, 7)
    _check(m, {"DSC": 0.6, "PPV": 0.5, "TPR": 1.0, "TNR": 0.0, "NPV": 1.0, "ACC": 0.5})


def test_ground_truth_point_in_two_segments():
    # Point 2 is in G0 and G1. G0 matches P0 exactly (TN = 5-3 = 2). G1 = {2,3,4}: P0 shares 1,
    # P1 = {3,4} shares 2 -> P1: TP=2 FP=0 FN=1 TN=2 -> DSC .8, TPR 2/3, NPV 2/3, ACC .8.
    gt = [_arr(0, 1, 2), _arr(2, 3, 4)]
    pred = [_arr(0, 1, 2), _arr(3, 4)]
    m = classification_measures(pred, gt, 5, per_segment=True)
    assert m["per_segment"]["match"].tolist() == [0, 1]
    _check(m, {"DSC": 0.9, "PPV": 1.0, "TPR": (1 + 2 / 3) / 2, "TNR": 1.0, "NPV": (1 + 2 / 3) / 2,
               "ACC": 0.9})


def test_unmatched_ground_truth_scores_zero():
    # G1 = {2,3} shares no point with any prediction: P = {}, TP=FP=0, FN=2, TN=2.
    gt = [_arr(0, 1), _arr(2, 3)]
    m = classification_measures([_arr(0, 1), _arr(4)], gt, 5, per_segment=True)
    ps = m["per_segment"]
    assert ps["match"].tolist() == [0, -1]
    assert ps["DSC"].tolist() == [1.0, 0.0]
    assert ps["PPV"][1] == 0.0 and ps["TPR"][1] == 0.0
    assert ps["TNR"][1] == 1.0 and ps["NPV"][1] == 0.5 and ps["ACC"][1] == 0.5


def test_no_prediction_and_no_ground_truth():
    m = classification_measures([], [_arr(0, 1)], 3)
    assert m["DSC"] == 0.0 and m["PPV"] == 0.0 and m["TPR"] == 0.0
    m = classification_measures([_arr(0)], [], 3)
    assert all(np.isnan(m[k]) for k in MEASURES)


def test_duplicates_count_once_and_range_is_checked():
    m = classification_measures([_arr(0, 0, 1)], [_arr(0, 1, 1)], 2)
    assert m["DSC"] == 1.0
    with pytest.raises(InputError, match="predicted segment 1: index 5 out of range"):
        classification_measures([_arr(0), _arr(5)], [_arr(0)], 3)
    with pytest.raises(InputError, match="ground-truth segment 0: index -1"):
        classification_measures([_arr(0)], [_arr(-1)], 3)


def _reference(pred: list[np.ndarray], gt: list[np.ndarray]) -> dict[str, float]:
    """Set-based transcription of the README (loops are fine in a test)."""
    u = set().union(*map(set, gt))
    per: dict[str, list[float]] = {k: [] for k in MEASURES}
    for g in map(set, gt):
        overlaps = [len(g & set(p)) for p in pred]
        best = int(np.argmax(overlaps)) if overlaps and max(overlaps) > 0 else None
        p = set(pred[best]) if best is not None else set()
        tp = len(g & p)
        fp = len(p & u) - tp
        fn = len(g) - tp
        tn = len(u) - tp - fp - fn
        per["DSC"].append(2 * tp / (len(g) + len(p)))
        per["PPV"].append(tp / (tp + fp) if tp + fp else 0.0)
        per["TPR"].append(tp / (tp + fn))
        per["TNR"].append(tn / (tn + fp) if tn + fp else 1.0)
        per["NPV"].append(tn / (tn + fn) if tn + fn else 1.0)
        per["ACC"].append((tp + tn) / len(u))
    return {k: float(np.mean(v)) for k, v in per.items()}


def test_matches_set_based_reference_on_random_segmentations():
    rng = np.random.default_rng(0)

    def draw(n: int, k_min: int, k_max: int, frac: int) -> list[np.ndarray]:
        k = int(rng.integers(k_min, k_max))
        return [rng.choice(n, size=int(rng.integers(1, n // frac)), replace=False) for _ in range(k)]

    for _ in range(30):
        n = int(rng.integers(20, 200))
        gt, pred = draw(n, 1, 6, 3), draw(n, 0, 8, 2)
        got = classification_measures(pred, gt, n)
        want = _reference(pred, gt)
        for k in MEASURES:
            assert got[k] == pytest.approx(want[k], abs=1e-12), k


def test_mfe_stats_ignores_non_finite():
    segs = [Segment(i, "plane", _arr(i), {}, v) for i, v in enumerate([0.1, float("nan"), 0.3])]
    r = Result(n_points=3, segments=segs, unsegmented=_arr())
    assert mfe_stats(r) == pytest.approx({"min": 0.1, "mean": 0.2, "max": 0.3})
    assert np.isnan(mfe_stats(Result(3, [], _arr()))["mean"])


# --------------------------------------------------------------------------- readers on small files


def test_read_segments_tolerates_spacing_and_sorts_by_k(tmp_path: Path):
    f = tmp_path / "X_primitives.txt"
    f.write_text("Primitive2 :=[4 5];\n\nPrimitive1:=[3 1 2];\n")
    segs = read_fit4cad_segments(f)
    assert [s.tolist() for s in segs] == [[2, 0, 1], [3, 4]]
    assert all(s.dtype == np.int64 for s in segs)


@pytest.mark.parametrize(
    "text, msg",
    [
        ("nothing here", "no 'PrimitiveK"),
        ("Primitive1:=[1 2 x];", "non-integer entry 'x'"),
        ("Primitive1:=[0 1];", "indices are 1-based"),
        ("Primitive1:=[1];Primitive1:=[2];", "appears twice"),
        ("Primitive1:=[1 2 99999999999999999999999];", "beyond any cloud's size"),
    ],
)
def test_read_segments_rejects_bad_files(tmp_path: Path, text: str, msg: str):
    f = tmp_path / "bad_primitives.txt"
    f.write_text(text)
    with pytest.raises(InputError, match=msg) as info:
        read_fit4cad_segments(f)
    assert str(f) in str(info.value) and "\n" not in str(info.value)


def test_read_segments_missing_file(tmp_path: Path):
    with pytest.raises(InputError, match="file not found"):
        read_fit4cad_segments(tmp_path / "none_primitives.txt")


def test_types_and_parameters_from_small_file(tmp_path: Path):
    f = tmp_path / "X_parametric.txt"
    # Cylinder of radius 2 around the z axis through (1, 2, 0); a torus R=5, r=1 around +z at z=3.
    f.write_text(
        "Primitive1:=[Cylinder, [2 0 0 0 2 0 0 0 1 1 2 0]];\n\n"
        "Primitive2:=[Torus, [Torus, [5 0 0 0 5 0 1 0 0 0 1 0 0 0 1 0 0 3]];\n\n"
        "Primitive3:=[BSpline, []];\n"
    )
    assert read_fit4cad_types(f) == ["cylinder", "torus", "bspline"]
    cyl, tor, bsp = read_fit4cad_parameters(f)
    assert cyl["radius"] == 2.0 and cyl["axis"].tolist() == [0, 0, 1]
    assert cyl["axis_point"].tolist() == [1, 2, 0]
    assert (tor["major_radius"], tor["minor_radius"]) == (5.0, 1.0)
    assert tor["center"].tolist() == [0, 0, 3]
    assert bsp == {"type": "bspline", "values": []}


def test_ground_truth_for_accepts_cloud_prefix_and_gt(tmp_path: Path):
    gt = tmp_path / "PC7_primitives.txt"
    gt.write_text("Primitive1:=[1];")
    for p in ("PC7.txt", "PC7", "PC7_primitives.txt", "PC7_parametric.txt"):
        assert ground_truth_for(tmp_path / p) == gt
    with pytest.raises(InputError, match="PC8_primitives.txt not found"):
        ground_truth_for(tmp_path / "PC8.txt")


@pytest.mark.parametrize("ext", [".ply", ".xyz", ".txt", ".csv", ".pts", ".asc", ".npy", ".obj", ".off",
                                 ".stl", ".PLY"])
def test_ground_truth_for_strips_any_cloud_extension(tmp_path: Path, ext: str):
    # Regression: demo_part.ply used to look for demo_part.ply_primitives.txt.
    gt = tmp_path / "demo_part_primitives.txt"
    gt.write_text("Primitive1:=[1];")
    assert ground_truth_for(tmp_path / f"demo_part{ext}") == gt
    with pytest.raises(InputError, match=r"other_primitives\.txt not found"):
        ground_truth_for(tmp_path / f"other{ext}")


def test_ground_truth_for_bundled_demo_part():
    from importlib.resources import as_file, files

    with as_file(files("houghcad") / "data" / "demo_part.ply") as cloud:
        assert ground_truth_for(cloud) == cloud.with_name("demo_part_primitives.txt")


def _result_json(tmp_path: Path, segments: list[np.ndarray], n: int) -> Path:
    segs = [Segment(i, "plane", np.sort(s), {}, 0.01 * (i + 1)) for i, s in enumerate(segments)]
    p = tmp_path / "result.json"
    rest = np.setdiff1d(np.arange(n), np.concatenate([_arr(), *segments])).astype(np.int64)
    p.write_text(Result(n, segs, rest).to_json())
    return p


def test_evaluate_files_round_trip(tmp_path: Path):
    (tmp_path / "PC7_primitives.txt").write_text("Primitive1:=[1 2 3];\nPrimitive2:=[4 5];\n")
    rj = _result_json(tmp_path, [_arr(0, 1, 2), _arr(3, 4)], 6)
    out = evaluate_files(rj, tmp_path / "PC7.txt")
    assert out["measures"] == {k: 1.0 for k in MEASURES}
    assert out["mfe"] == pytest.approx({"min": 0.01, "mean": 0.015, "max": 0.02})
    assert (out["n_gt"], out["n_pred"]) == (2, 2)


def test_evaluate_files_scores_faces_unless_maximal(tmp_path: Path):
    # Two CAD faces on one cylinder: houghcad reports one maximal primitive with two parts.
    (tmp_path / "PC7_primitives.txt").write_text("Primitive1:=[1 2 3];\nPrimitive2:=[4 5 6];\n")
    seg = Segment(0, "cylinder", _arr(0, 1, 2, 3, 4, 5), {}, 0.01,
                  parts=[Part(_arr(0, 1, 2), {}, 0.01), Part(_arr(3, 4, 5), {}, 0.01)])
    rj = tmp_path / "result.json"
    rj.write_text(Result(6, [seg], _arr()).to_json())
    faces = evaluate_files(rj, tmp_path / "PC7_primitives.txt")
    assert faces["scored"] == "faces" and faces["n_pred"] == 2
    assert faces["measures"]["DSC"] == 1.0
    whole = evaluate_files(rj, tmp_path / "PC7_primitives.txt", maximal=True)
    assert whole["scored"] == "maximal" and whole["n_pred"] == 1
    assert whole["measures"]["DSC"] == pytest.approx(2 * 3 / (3 + 6))  # each face against all six points


def test_evaluate_files_rejects_bad_results(tmp_path: Path):
    gt = tmp_path / "PC7_primitives.txt"
    gt.write_text("Primitive1:=[1 2 3];\n")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="malformed JSON"):
        evaluate_files(bad, gt)
    bad.write_text(json.dumps({"segments": []}))
    with pytest.raises(InputError, match="missing key 'n_points'"):
        evaluate_files(bad, gt)
    bad.write_text(json.dumps({"n_points": 5, "segments": [{"id": 0, "type": "plane"}]}))
    with pytest.raises(InputError, match="lacks key 'indices'"):
        evaluate_files(bad, gt)
    with pytest.raises(InputError, match="index 9 out of range"):
        evaluate_files(_result_json(tmp_path, [_arr(0, 9)], 5), gt)
    with pytest.raises(InputError, match="exceeds the result's n_points 2"):
        evaluate_files(_result_json(tmp_path, [_arr(0)], 2), gt)
    bad.write_text(json.dumps({"n_points": 5, "segments": [{"id": 0, "type": "plane", "indices": [10**30]}]}))
    with pytest.raises(InputError, match="invalid result"):
        evaluate_files(bad, gt)
    bad.write_text(json.dumps({"n_points": 5, "segments": [{"id": 0, "type": "plane", "indices": [0, 1.5]}]}))
    with pytest.raises(InputError, match="whole numbers"):
        evaluate_files(bad, gt)
    bad.write_text(json.dumps({"format": "other-tool", "n_points": 5, "segments": []}))
    with pytest.raises(InputError, match="not a houghcad result"):
        evaluate_files(bad, gt)
    bad.write_text(json.dumps({"format": "houghcad-result", "version": 99, "n_points": 5, "segments": []}))
    with pytest.raises(InputError, match="version 99"):
        evaluate_files(bad, gt)


def test_evaluate_files_refuses_a_result_of_another_cloud(tmp_path: Path):
    # The cloud beside the ground truth has 30 points; a result of 100 points is not of this cloud.
    (tmp_path / "PC7_primitives.txt").write_text("Primitive1:=[1 2 3];\n")
    pts = np.random.default_rng(0).normal(size=(30, 3))
    (tmp_path / "PC7.txt").write_text("Points:=[\n" + "".join(f"[{x}, {y}, {z}],\n" for x, y, z in pts) + "];\n")
    rj = _result_json(tmp_path, [_arr(0, 1, 2)], 100)
    for given in ("PC7_primitives.txt", "PC7.txt"):
        with pytest.raises(InputError, match="has 100 points but the cloud PC7.txt has 30"):
            evaluate_files(rj, tmp_path / given)
    assert evaluate_files(_result_json(tmp_path, [_arr(0, 1, 2)], 30), tmp_path / "PC7.txt")["measures"]["DSC"] == 1.0


# --------------------------------------------------------------------------- real Fit4CAD files


def _cloud(name: str) -> np.ndarray:
    from houghcad.io import read_points

    return read_points(DATA / f"{name}.txt").points


@needs_data
@pytest.mark.parametrize("name", ["PC1", "PC2", "PC3", "PC83", "PC117"])
def test_ground_truth_against_itself_is_perfect(name: str, tmp_path: Path):
    gt = read_fit4cad_segments(DATA / f"{name}_primitives.txt")
    n = len(_cloud(name))
    m = classification_measures(gt, gt, n)
    assert m == {k: 1.0 for k in MEASURES}
    # Same through the file route.
    out = evaluate_files(_result_json(tmp_path, gt, n), DATA / f"{name}.txt")
    assert out["measures"]["DSC"] == 1.0 and out["n_gt"] == len(gt)


@needs_data
def test_parametric_files_align_with_segments_by_position():
    # PC83 numbers its primitives 1-4, 7-23 but its parametric blocks 1-21; PC117 has a B-spline
    # that its implicit file omits.
    for name in ("PC83", "PC117", "PC144"):
        n_seg = len(read_fit4cad_segments(DATA / f"{name}_primitives.txt"))
        assert len(read_fit4cad_types(DATA / f"{name}_parametric.txt")) == n_seg
    assert "bspline" in read_fit4cad_types(DATA / "PC117_parametric.txt")
    assert "bspline" not in read_fit4cad_types(DATA / "PC117_implicit.txt")


def _distance(p: dict, x: np.ndarray) -> np.ndarray:
    """Distance (cloud units) of points x (N, 3) to a decoded surface."""
    t = p["type"]
    if t == "plane":
        return np.abs(x @ p["normal"] - p["offset"])
    if t == "sphere":
        return np.abs(np.linalg.norm(x - p["center"], axis=1) - p["radius"])
    if t in ("cylinder", "torus", "cone"):
        origin = p["axis_point"] if t == "cylinder" else p.get("center", p.get("apex"))
        d = x - origin
        h = d @ p["axis"]
        rho = np.linalg.norm(d - np.outer(h, p["axis"]), axis=1)
        if t == "cylinder":
            return np.abs(rho - p["radius"])
        if t == "torus":
            return np.abs(np.hypot(rho - p["major_radius"], h) - p["minor_radius"])
        a = p["half_angle"]
        assert h.min() > -1e-6 * np.ptp(x)  # points lie on the +axis side of the apex
        return np.abs(rho * np.cos(a) - h * np.sin(a))
    raise AssertionError(t)


@needs_data
@pytest.mark.parametrize("name", ["PC1", "PC3", "PC10", "PC14", "PC92", "PC104", "PC107", "PC124",
                                  "PC131", "PC149", "PC186"])
def test_decoded_parameters_agree_with_points(name: str):
    # These clouds hold every type and every axis orientation seen in the training set.
    x = _cloud(name)
    diag = float(np.linalg.norm(np.ptp(x, axis=0)))
    gt = read_fit4cad_segments(DATA / f"{name}_primitives.txt")
    params = read_fit4cad_parameters(DATA / f"{name}_parametric.txt")
    assert len(params) == len(gt)
    for k, (seg, p) in enumerate(zip(gt, params)):
        if p["type"] == "bspline":
            continue
        d = _distance(p, x[seg])
        assert np.percentile(d, 95) < 1e-4 * diag, (name, k + 1, p["type"])
        if p["type"] == "cylinder":  # the radius itself: median distance to the decoded axis
            dd = x[seg] - p["axis_point"]
            rho = np.linalg.norm(dd - np.outer(dd @ p["axis"], p["axis"]), axis=1)
            assert np.median(rho) == pytest.approx(p["radius"], rel=1e-4), (name, k + 1)


def test_parameter_errors_are_zero_on_the_truth_and_measure_a_tilt():
    from houghcad.evaluate import PARAMETER_TOLERANCES, parameter_errors

    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    truth = {"axis_point": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "radius": 1.0}
    assert all(v == 0 for v in parameter_errors("cylinder", truth, truth, 10.0, pts).values())
    t = np.radians(2.0)
    found = {"axis_point": [0.0, 0.0, 0.0], "axis": [np.sin(t), 0.0, np.cos(t)], "radius": 1.05}
    err = parameter_errors("cylinder", truth, found, 10.0, pts)
    assert err["axis_deg"] == pytest.approx(2.0)
    assert err["radius"] == pytest.approx(0.005)
    assert err["axis_line"] == pytest.approx(2.0 * np.sin(t) / 10.0)  # at the far end of the extent
    assert set(err) <= set(PARAMETER_TOLERANCES)
    with pytest.raises(ValueError):
        parameter_errors("helical_surface", {}, {}, 1.0, pts)


def test_a_result_of_another_cloud_is_scored_with_a_warning(tmp_path: Path):
    """Two clouds of one point count: the result names its cloud, and the scoring says so."""
    import warnings

    from houghcad.errors import InputWarning

    (tmp_path / "PC7_primitives.txt").write_text("Primitive1:=[1 2 3];\n")
    rj = _result_json(tmp_path, [_arr(0, 1, 2)], 3)
    data = json.loads(rj.read_text())
    rj.write_text(json.dumps({**data, "source": "/data/PC9.txt"}))
    with pytest.warns(InputWarning, match="the result is of PC9.txt, the ground truth of PC7"):
        assert evaluate_files(rj, tmp_path / "PC7_primitives.txt")["measures"]["DSC"] == 1.0
    rj.write_text(json.dumps({**data, "source": "/elsewhere/PC7.txt"}))
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        evaluate_files(rj, tmp_path / "PC7_primitives.txt")


def test_a_result_that_left_rows_out_is_scored_in_the_file_rows(tmp_path: Path):
    # File rows 0-29; rows 2 and 5 held NaN and were left out (--drop-invalid): the run's
    # 28 points are the file's other rows, in order. The truth numbers the file's rows.
    P = np.random.default_rng(0).random((30, 3))
    P[[2, 5]] = np.nan
    np.savetxt(tmp_path / "PC7.xyz", P)
    rows = np.setdiff1d(np.arange(30), [2, 5])
    (tmp_path / "PC7_primitives.txt").write_text(
        "".join(f"Primitive{j + 1}:=[{' '.join(str(r + 1) for r in part)}];\n"
                for j, part in enumerate((rows[:14], rows[14:]))))
    segs = [Segment(0, "plane", np.arange(14), {}, 0.01), Segment(1, "plane", np.arange(14, 28), {}, 0.01)]
    options = {"input": {"rows": 30, "drop_invalid": True, "dropped_rows": [[2, 3], [5, 6]]}}
    result = Result(28, segs, _arr(), options=options)
    mapped = in_file_rows(result)
    assert mapped.n_points == 30 and mapped.unsegmented.tolist() == [2, 5]
    assert [s.indices.tolist() for s in mapped.segments] == [rows[:14].tolist(), rows[14:].tolist()]
    (tmp_path / "result.json").write_text(result.to_json())
    out = evaluate_files(tmp_path / "result.json", tmp_path / "PC7_primitives.txt")
    assert out["measures"]["DSC"] == 1.0
    options["input"]["dropped_rows"] = [[2, 3]]  # a record that does not fit the points
    (tmp_path / "result.json").write_text(Result(28, segs, _arr(), options=options).to_json())
    with pytest.raises(InputError, match="not a result of this cloud"):
        evaluate_files(tmp_path / "result.json", tmp_path / "PC7_primitives.txt")
