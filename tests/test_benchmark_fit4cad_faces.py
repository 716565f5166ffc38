"""Tests of benchmarks/fit4cad_faces.py: each cause of a lost face on hand-made index sets, the
summary's losses adding up to 1 − mean DSC, and one real cloud written whole."""

from __future__ import annotations

import csv
import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from houghcad import synth

_REPO = Path(__file__).resolve().parents[1]
if str(_REPO / "benchmarks") not in sys.path:
    sys.path.insert(0, str(_REPO / "benchmarks"))
faces_bench = importlib.import_module("fit4cad_faces")


def _a(*x: int) -> np.ndarray:
    return np.asarray(x, dtype=np.int64)


def _cause(k: int, gt: list, gt_types: list, faces: list, face_types: list, n: int = 40,
           min_points: int = 3) -> str:
    from houghcad.evaluate import classification_measures

    match = int(classification_measures(faces, gt, n, per_segment=True)["per_segment"]["match"][k])
    return faces_bench.cause(k, gt, gt_types, faces, face_types, match, n, min_points)


def test_each_cause() -> None:
    big, small = _a(*range(0, 20)), _a(*range(20, 26))
    # Its points all on the curve it shares with the big face.
    assert _cause(1, [_a(*range(0, 24)), _a(20, 21, 22, 23)], ["plane", "cylinder"],
                  [_a(*range(0, 25))], ["plane"]) == "boundary only"
    assert _cause(1, [big, _a(20, 21)], ["plane", "plane"], [big], ["plane"]) == "below the smallest segment"
    assert _cause(1, [big, small], ["plane", "cone"], [big], ["plane"]) == "unsegmented"
    assert _cause(1, [big, small], ["plane", "cone"], [big, _a(20, 21), _a(22, 23), _a(24, 25)],
                  ["plane", "plane", "cylinder", "plane"]) == "cut into pieces"
    # A coplanar patch inside one plane, and a strip a cylinder took.
    assert _cause(1, [big, small], ["plane", "plane"], [_a(*range(0, 26))], ["plane"]) == \
        "joined with a face of its type"
    assert _cause(1, [big, small], ["cylinder", "plane"], [_a(*range(0, 26))], ["cylinder"]) == "taken by another face"
    assert _cause(1, [big, small], ["plane", "cone"], [big, small], ["plane", "cylinder"]) == "wrong type"
    # Without the types, nothing is said of them.
    assert _cause(1, [big, small], ["unknown"] * 2, [big, small], ["plane", "cylinder"]) == "other"


def test_summary_adds_up() -> None:
    rows = [dict(cloud="PC1", fold=1, dsc=1.0, loss=0.0, cause=""),
            dict(cloud="PC1", fold=1, dsc=0.2, loss=0.4, cause="wrong type"),
            dict(cloud="PC2", fold=2, dsc=0.7, loss=0.3, cause="")]
    lines = faces_bench.summary(rows, n_clouds=2)
    assert "| all | 3 | 0.3500 | 0.4000 / 0.3000 |" in lines
    assert "| DSC < 0.5 | 1 | 0.2000 | 0.4000 / 0.0000 |" in lines
    assert "| wrong type | 1 | 1 | 0.2000 | 0.4000 / 0.0000 |" in lines


def test_one_cloud_end_to_end(tmp_path: Path) -> None:
    """A synthetic part written as a Fit4CAD cloud: every face gets a row, the CSV is whole, and the
    losses give back the benchmark's DSC."""
    cloud = synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=3000)
    np.savetxt(tmp_path / "PC7.txt", cloud.points, fmt="%.9f")
    synth.write_fit4cad_segments(cloud, tmp_path / "PC7_primitives.txt")
    out = tmp_path / "faces.csv"
    assert faces_bench.main([str(tmp_path), "--jobs", "1", "--out", str(out), "--no-write"]) == 0
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == len(cloud.segments())
    assert {r["fold"] for r in rows} == {"2"}
    mean = 1 - sum(float(r["loss"]) for r in rows)
    assert mean == pytest.approx(np.mean([float(r["dsc"]) for r in rows]))
    assert mean > 0.8
    assert not list(tmp_path.glob("*.tmp"))


def test_bad_arguments(tmp_path: Path) -> None:
    assert faces_bench.main([str(tmp_path / "missing")]) == 2
    assert faces_bench.main([str(tmp_path)]) == 2  # no clouds
    assert faces_bench.main([str(tmp_path), "--fraction", "0"]) == 2
