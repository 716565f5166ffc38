"""houghcad.result: a result read back from JSON is checked for consistency."""

from __future__ import annotations

import numpy as np
import pytest

from houghcad.result import Part, Result, Segment


def _result() -> Result:
    a, b = np.arange(0, 4), np.arange(4, 8)
    seg = Segment(0, "plane", np.concatenate([a, b]), {}, 0.01,
                  parts=[Part(a, {}, 0.01), Part(b, {}, 0.01)])
    return Result(10, [seg], np.array([8, 9]))


def test_round_trip():
    r = _result()
    assert Result.from_dict(r.to_dict()) == r


def test_unsegmented_left_out_is_the_points_no_segment_holds():
    d = _result().to_dict()
    del d["unsegmented"]
    assert Result.from_dict(d).unsegmented.tolist() == [8, 9]


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["segments"][0]["indices"].append(-1), "-1 out of range"),  # labels() took the last point
    (lambda d: d["unsegmented"].append(10), "10 out of range"),
    (lambda d: d["segments"][0].update(edge_indices=[12]), "12 out of range"),
    (lambda d: d.update(n_points="10"), "whole number"),
    (lambda d: d.update(n_points=True), "whole number"),
    (lambda d: d.update(segments={}), "must be a list"),
    (lambda d: d["segments"][0]["parts"].pop(), "parts do not hold its points"),
])
def test_inconsistent_results_are_refused(edit, message):
    d = _result().to_dict()
    edit(d)
    with pytest.raises(ValueError, match=message):
        Result.from_dict(d)


def test_a_point_may_be_in_two_segments():
    # A ground truth's faces share their boundary points; scored against itself it reads 1.
    d = _result().to_dict()
    d["segments"].append({"id": 1, "type": "plane", "indices": [7, 8, 9]})
    d["unsegmented"] = []
    assert len(Result.from_dict(d).segments) == 2
