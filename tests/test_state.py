"""The segmentation state: labels are the one truth of ownership; invariants hold."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from houghcad.associate import RawGroup
from houghcad.families import REGISTRY
from houghcad.families.base import Primitive
from houghcad.state import SegmentRecord, Segmentation, surface_distance

PLANE = SegmentRecord(REGISTRY["plane"], Primitive("plane", {"normal": np.array([0, 0, 1.0]), "offset": 0.0}))
CYL = SegmentRecord(REGISTRY["cylinder"], Primitive("cylinder", {"axis_point": np.zeros(3),
                                                                 "axis": np.array([0, 0, 1.0]), "radius": 1.0}))


def _state() -> Segmentation:
    seg = Segmentation(10)
    seg.add(PLANE, np.array([0, 1, 2, 3]))
    seg.add(CYL, np.array([5, 6]))
    return seg


def test_new_state_is_all_free():
    seg = Segmentation(5)
    assert seg.labels.dtype == np.int32 and (seg.labels == -1).all() and seg.free.all()
    assert len(seg) == 0
    seg.check()


def test_indices_are_read_from_the_labels():
    seg = _state()
    np.testing.assert_array_equal(seg.indices(0), [0, 1, 2, 3])
    np.testing.assert_array_equal(seg[1].indices, [5, 6])
    assert seg[1].family.name == "cylinder"
    np.testing.assert_array_equal(seg.sizes(), [4, 2])
    np.testing.assert_array_equal(np.flatnonzero(seg.free), [4, 7, 8, 9])
    seg.check()


def test_adding_a_segment_takes_its_points_from_their_holder():
    seg = _state()
    seg.add(CYL, np.array([3, 4, 5]))
    np.testing.assert_array_equal(seg.indices(0), [0, 1, 2])
    np.testing.assert_array_equal(seg.indices(1), [6])
    np.testing.assert_array_equal(seg.indices(2), [3, 4, 5])
    seg.check()


def test_set_points_frees_what_the_segment_no_longer_holds():
    seg = _state()
    seg.set_points(0, np.array([1, 2, 8]))
    np.testing.assert_array_equal(seg.indices(0), [1, 2, 8])
    assert seg.free[[0, 3]].all()
    seg.check()


def test_remove_frees_points_and_moves_later_ids_down():
    seg = _state()
    seg.add(PLANE, np.array([9]))
    seg.remove([1])
    assert len(seg) == 2 and seg.records[1] is PLANE
    np.testing.assert_array_equal(seg.indices(1), [9])
    assert seg.free[[5, 6]].all()
    seg.check()


def test_every_write_moves_the_version():
    seg = _state()
    v = seg.version
    seg.release(np.array([0]))
    seg.set_record(0, replace(PLANE, fixed=True))
    seg.relabel(seg.labels)
    assert seg.version == v + 3
    v = seg.version
    seg.assign(np.array([], dtype=np.int64), 0)  # nothing written
    seg.remove([])
    assert seg.version == v


def test_copy_is_independent():
    seg = _state()
    other = seg.copy()
    other.assign(np.array([9]), 0)
    assert seg.labels[9] == -1 and other.labels[9] == 0
    other.check()
    seg.check()


def test_of_builds_a_state_from_pieces():
    class Piece:
        family, prim = PLANE.family, PLANE.prim

        def __init__(self, idx):
            self.indices = np.asarray(idx)

    seg = Segmentation.of(6, [Piece([0, 1]), Piece([1, 2, 3])])
    np.testing.assert_array_equal(seg.labels, [0, 1, 1, 1, -1, -1])


def test_check_catches_an_empty_segment_a_bad_label_and_a_stale_cache():
    seg = _state()
    seg.release(seg.indices(1))
    with pytest.raises(AssertionError, match="empty"):
        seg.check()
    seg.remove_empty()
    seg.check()
    seg.labels[7] = 5  # written behind the methods' back
    with pytest.raises(AssertionError, match="out of range"):
        seg.check()
    seg = _state()
    seg.indices(0)
    seg.labels[0] = 1  # written behind the methods' back: the cached indices are stale
    with pytest.raises(AssertionError, match="stale"):
        seg.check()


def test_check_catches_untyped_records_and_parts_that_do_not_partition():
    seg = _state()
    seg.records[0] = ("plane", None)
    with pytest.raises(AssertionError, match="record 0"):
        seg.check()
    seg = _state()
    seg.parts = [[np.array([0, 1]), np.array([2, 3])], [np.array([5])]]
    with pytest.raises(AssertionError, match="partition"):
        seg.check()
    seg.parts = [[np.array([0, 1]), np.array([2, 3])], [np.array([5, 6])]]
    seg.groups = [RawGroup("parallel", [0, 4])]
    with pytest.raises(AssertionError, match="missing segment"):
        seg.check()


def test_writes_clear_the_association():
    seg = _state()
    seg.parts = [[seg.indices(0)], [seg.indices(1)]]
    seg.groups = [RawGroup("parallel", [0, 1])]
    seg.check()
    seg.assign(np.array([9]), 1)
    assert seg.parts is None and seg.groups == []


def test_a_boundary_bounds_the_surface_distance():
    class Half:
        """Claims the points with x > 0 at their |z|; the others are off it."""

        def distance(self, P):
            on = P[:, 0] > 0
            return np.where(on, np.abs(P[:, 2]), np.inf), on

    P = np.array([[1.0, 0, 0.5], [-1.0, 0, 0.5]])
    d, claim = surface_distance(PLANE, P)
    np.testing.assert_allclose(d, [0.5, 0.5]) and claim is None
    d, claim = surface_distance(replace(PLANE, boundary=Half()), P)
    assert d[0] == 0.5 and np.isinf(d[1]) and claim.tolist() == [True, False]
