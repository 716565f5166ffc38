"""houghcad.result: a result read back from JSON is checked for consistency."""

from __future__ import annotations

import json

import numpy as np
import pytest

from houghcad.result import Group, Part, Result, Segment


def _result() -> Result:
    a, b = np.arange(0, 4), np.arange(4, 8)
    seg = Segment(0, "plane", np.concatenate([a, b]), {}, 0.01,
                  parts=[Part(a, {}, 0.01), Part(b, {}, 0.01)])
    return Result(10, [seg], np.array([8, 9]))


def _grouped() -> Result:
    """Three segments (the first in two parts) and two groups, as the pipeline writes them."""
    r = _result()
    r.segments += [Segment(1, "cylinder", np.array([8, 9]), {"radius": 1.0}, 0.02),
                   Segment(2, "cylinder", np.array([10, 11]), {"radius": 1.0}, 0.02)]
    r.n_points, r.unsegmented = 13, np.array([12])
    r.groups = [Group("same_primitive", [0], {"parts": 2}), Group("translation", [1, 2], {"radius": 1.0})]
    return r


def test_round_trip():
    r = _result()
    assert Result.from_dict(r.to_dict()) == r


def test_unsegmented_left_out_is_the_points_no_segment_holds():
    d = _result().to_dict()
    del d["unsegmented"]
    assert Result.from_dict(d).unsegmented.tolist() == [8, 9]


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["segments"][0]["indices"].append(-1), "-1 out of range"),  # labels() took the last point
    (lambda d: d["unsegmented"].append(13), "13 out of range"),
    (lambda d: d["segments"][0].update(edge_indices=[13]), "13 out of range"),
    (lambda d: d.update(n_points="10"), "whole number"),
    (lambda d: d.update(n_points=True), "whole number"),
    (lambda d: d.update(segments={}), "must be a list"),
    (lambda d: d["segments"][0]["parts"].pop(), "parts do not hold its points"),
    # A segment deleted by hand: labels() gave ids past the list, groups named other segments.
    (lambda d: d["segments"].pop(0), "position 0 has id 1"),
    (lambda d: d["segments"].reverse(), "position 0 has id 2"),
    (lambda d: d["segments"][0].update(id=0.0), "segment id must be a whole number"),
    (lambda d: d["groups"][0].update(members=[0, 99]), "group 0: member 99 is not a segment id"),
    (lambda d: d["groups"][0].update(members=[-1]), "group 0: member -1 is not a segment id"),
    (lambda d: d["groups"][1].update(members=[1.5]), "group 1: member must be a whole number"),
    (lambda d: d["groups"][1].update(kind="symmetry"), "group 1: unknown kind 'symmetry'"),
    (lambda d: d["segments"][1].pop("params"), "segment 1: missing 'params'"),
    (lambda d: d["segments"][1].update(params=[1, 2]), "segment 1: 'params' must be an object"),
    (lambda d: d["segments"][0]["parts"][1].pop("params"), "segment 0, part 1: missing 'params'"),
    (lambda d: d["segments"][1].update(n_points=4), "segment 1: n_points 4 but 2 indices"),
    (lambda d: d["segments"][1].update(n_points="2"), "segment 1: n_points must be a whole number"),
    (lambda d: d["segments"][0]["parts"][0].update(n_points=3), "segment 0, part 0: n_points 3 but 4"),
])
def test_inconsistent_results_are_refused(edit, message):
    d = _grouped().to_dict()
    edit(d)
    with pytest.raises(ValueError, match=message):
        Result.from_dict(d)


def test_a_point_may_be_in_two_segments():
    # A ground truth's faces share their boundary points; scored against itself it reads 1.
    d = _result().to_dict()
    d["segments"].append({"id": 1, "type": "plane", "indices": [7, 8, 9], "params": {}})
    d["unsegmented"] = []
    assert len(Result.from_dict(d).segments) == 2


def test_grouped_round_trip():
    r = _grouped()
    assert Result.from_dict(json.loads(r.to_json())) == r


def test_a_renumbered_result_is_read():
    # The hand edit done right: segment 0 deleted, the others and the groups' members renumbered.
    d = _grouped().to_dict()
    gone = d["segments"].pop(0)
    d["unsegmented"] = sorted(d["unsegmented"] + gone["indices"])
    for s in d["segments"]:
        s["id"] -= 1
    d["groups"] = [{**g, "members": [m - 1 for m in g["members"]]} for g in d["groups"] if 0 not in g["members"]]
    r = Result.from_dict(d)
    assert r.labels().max() == len(r.segments) - 1 and r.groups[0].members == [0, 1]


def test_unsorted_indices_and_members_are_sorted():
    # Documented ascending; a hand-edited list is read sorted (nothing pairs them by position).
    d = _grouped().to_dict()
    seg = d["segments"][0]
    seg["indices"].reverse()
    seg["edge_indices"] = [12, 9]
    seg["parts"][1]["indices"].reverse()
    d["unsegmented"] = [12]
    d["groups"][1]["members"] = [2, 1]
    r = Result.from_dict(d)
    assert r.segments[0].indices.tolist() == list(range(8))
    assert r.segments[0].parts[1].indices.tolist() == [4, 5, 6, 7]
    assert r.segments[0].edges.tolist() == [9, 12]
    assert r.groups[1].members == [1, 2]


def test_unknown_segment_type_and_absent_n_points_are_read():
    # A user-defined family's result is read in a process where the family is not registered;
    # another writer may leave n_points out (it is the length of indices).
    d = _grouped().to_dict()
    d["segments"][1]["type"] = "my_paraboloid"
    del d["segments"][1]["n_points"]
    r = Result.from_dict(d)
    assert r.segments[1].type == "my_paraboloid" and len(r.segments[1].indices) == 2
