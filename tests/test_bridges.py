"""Rows of points of narrow faces and gaps of the sampling (houghcad.bridges); the bridging itself
is tested through the association in test_associate.py (a strip and a ring cut by gaps, faces that
taper to a point)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from houghcad.bridges import ring_row, row_axis, row_direction, row_shape, sampling_gaps
from houghcad.tolerances import AssociationTolerances


def _ring(rng: np.random.Generator, r0: float, width: float, turn: tuple[float, float], n: int) -> np.ndarray:
    r = np.sqrt(rng.uniform(r0 ** 2, (r0 + width) ** 2, n))
    t = rng.uniform(*turn, n)
    return np.column_stack([r * np.cos(t), r * np.sin(t), np.zeros(n)])


def test_a_straight_strip_is_a_row_along_its_length():
    rng = np.random.default_rng(0)
    P = np.column_stack([rng.uniform(0, 10, 400), rng.uniform(0, 0.3, 400), np.zeros(400)])
    axis = row_axis(P, 0.5)
    assert axis is not None and abs(axis[0]) > 0.999
    assert row_axis(P, 0.2) is None  # wider than that


def test_half_a_ring_is_a_row_along_its_circle_only():
    rng = np.random.default_rng(1)
    P = _ring(rng, 5.0, 0.3, (0.0, np.pi), 600)
    assert row_axis(P, 0.5) is None  # no straight row: it turns through half a turn
    centre, normal = ring_row(P, 0.5)
    assert np.allclose(centre, 0.0, atol=0.05) and abs(normal[2]) > 0.999
    d = row_direction(row_shape(P, 0.5), np.array([5.15, 0.0, 0.0]))  # the tangent where the arc starts
    assert abs(d[1]) > 0.999


def test_a_band_of_a_cylinder_is_a_row_along_its_circle():
    rng = np.random.default_rng(2)
    t = rng.uniform(0, 1.5 * np.pi, 500)
    P = np.column_stack([3 * np.cos(t), 3 * np.sin(t), rng.uniform(0, 0.2, 500)])
    centre, normal = ring_row(P, 0.4)
    assert np.allclose(centre[:2], 0.0, atol=0.05) and abs(normal[2]) > 0.999


def test_a_wide_face_and_a_tapering_one_are_no_rows():
    rng = np.random.default_rng(3)
    disc = _ring(rng, 0.0, 5.0, (0.0, 2 * np.pi), 800)
    assert row_axis(disc, 0.5) is None and ring_row(disc, 0.5) is None
    # The piece of a square around a circle of radius 1, in one quadrant: it tapers to the two
    # points where the circle touches the square, and is a row only there.
    Q = rng.uniform(0, 1, (3000, 2))
    Q = Q[np.hypot(Q[:, 0], Q[:, 1]) > 1.0]
    corner = np.column_stack([Q, np.zeros(len(Q))])
    assert row_axis(corner, 0.1) is None and ring_row(corner, 0.1) is None
    assert row_shape(corner, 0.1) is None


def _two_strips(gap: float, rng: np.random.Generator, width: float = 0.05, n: int = 60) \
        -> tuple[np.ndarray, list[np.ndarray]]:
    """Random samples of two strips of the plane z = 0 end to end, [0, 1] × [0, width] and
    [1 + gap, 2 + gap] × [0, width], n points each, and their index arrays."""
    a = np.c_[rng.uniform(0, 1, n), rng.uniform(0, width, n), np.zeros(n)]
    b = np.c_[rng.uniform(1 + gap, 2 + gap, n), rng.uniform(0, width, n), np.zeros(n)]
    return np.r_[a, b], [np.arange(n), np.arange(n, 2 * n)]


def test_pieces_of_a_face_apart_by_a_gap_of_the_sampling_are_one_part():
    tol, link = AssociationTolerances(), 0.2
    rng = np.random.default_rng(0)
    owner = np.r_[np.zeros(60, int), np.ones(60, int)]
    for gap, joined in ((1.0 * link, True), (2.0 * link, False)):
        P, pieces = _two_strips(gap, rng)
        assert (sampling_gaps([0, 1], pieces, owner, P, cKDTree(P), link, tol) == {(0, 1)}) is joined, gap
    # A third face between them (a rib's top, owned by another segment) parts them ...
    P, pieces = _two_strips(1.0 * link, rng)
    rib = np.c_[np.full(5, 1 + 0.5 * link), np.linspace(0, 0.05, 5), np.full(5, 0.05)]
    P = np.r_[P, rib]
    owner3 = np.r_[owner, np.full(5, 2)]
    assert sampling_gaps([0, 1], pieces, owner3, P, cKDTree(P), link, tol) == set()
    # ... and so do points no face explains.
    owner3[120:] = -1
    assert sampling_gaps([0, 1], pieces, owner3, P, cKDTree(P), link, tol) == set()
    # Wide faces facing each other across the gap all along are parted by a boundary (a groove
    # too narrow to be sampled), not by a hole in the sampling.
    P, pieces = _two_strips(1.2 * link, rng, width=1.0, n=400)
    owner = np.r_[np.zeros(400, int), np.ones(400, int)]
    assert sampling_gaps([0, 1], pieces, owner, P, cKDTree(P), link, tol) == set()
    tol = replace(tol, gap_front=10.0)  # the same pieces, were a front that long a hole
    assert sampling_gaps([0, 1], pieces, owner, P, cKDTree(P), link, tol) == {(0, 1)}
