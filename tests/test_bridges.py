"""Rows of points of narrow faces (houghcad.bridges); the bridging itself is tested through the
association in test_associate.py (a strip and a ring cut by gaps, faces that taper to a point)."""

from __future__ import annotations

import numpy as np

from houghcad.bridges import ring_row, row_axis, row_direction, row_shape


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
