"""Tests of houghcad.hough: grids, voting, persistent peaks, the direction accumulator."""

from __future__ import annotations

import numpy as np
import pytest

from houghcad import synth
from houghcad.hough import (DirectionAccumulator, Grid, _line_vote, accumulate, normal_line_peaks, persistent_peaks,
                            refine_direction)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two unoriented directions, degrees."""
    c = abs(float(a @ b)) / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(min(c, 1.0))))


# ---------------------------------------------------------------------------- Grid


def test_grid_round_trip_flat_index_to_centre_and_back():
    g = Grid((-1.0, 0.0, 2.0), (1.0, 3.0, 2.5), (7, 5, 3))
    flat = np.arange(int(np.prod(g.bins)))
    centres = g.cell_center(flat)
    assert centres.shape == (flat.size, 3)
    np.testing.assert_array_equal(g.cell_index(centres), flat)
    np.testing.assert_allclose(g.width, [2 / 7, 3 / 5, 0.5 / 3])
    np.testing.assert_allclose(g.centers(1), [0.3, 0.9, 1.5, 2.1, 2.7])


def test_grid_values_land_in_the_cell_that_contains_them():
    g = Grid((0.0, -2.0), (1.0, 2.0), (10, 8))
    rng = np.random.default_rng(0)
    v = rng.uniform([0, -2], [1, 2], size=(500, 2))
    back = g.cell_center(g.cell_index(v))
    assert np.all(np.abs(back - v) <= 0.5 * g.width + 1e-12)


def test_grid_outside_is_minus_one_unless_wrapped():
    g = Grid((0.0, 0.0), (1.0, 2 * np.pi), (4, 8))
    out = np.array([[-0.1, 1.0], [1.1, 1.0], [0.5, 7.0]])
    np.testing.assert_array_equal(g.cell_index(out), [-1, -1, -1])
    gw = Grid((0.0, 0.0), (1.0, 2 * np.pi), (4, 8), wrap=(False, True))
    idx = gw.cell_index(np.array([[0.5, 2 * np.pi + 0.1], [0.5, -0.1], [1.1, 1.0]]))
    # 2π + 0.1 wraps to the first angular cell, -0.1 to the last; the unwrapped dim still clips.
    np.testing.assert_array_equal(idx, [2 * 8 + 0, 2 * 8 + 7, -1])


# ---------------------------------------------------------------------------- accumulate


def test_accumulate_counts_one_vote_per_point_per_cell():
    g = Grid((0.0,), (4.0,), (4,))
    # Point 0 crosses cell 0 three times and cell 1 once; point 1 crosses cell 0 twice;
    # point 2 only votes outside T.
    voter = np.array([0, 0, 0, 0, 1, 1, 2])
    vals = np.array([[0.1], [0.5], [0.9], [1.5], [0.2], [0.3], [9.0]])
    H = accumulate(g, voter, vals)
    np.testing.assert_array_equal(H, [2, 1, 0, 0])
    assert H.shape == g.bins and H.dtype == np.float64


def test_accumulate_weights_count_once_per_point_and_cell():
    g = Grid((0.0, 0.0), (2.0, 2.0), (2, 2))
    voter = np.array([0, 0, 1, 1])
    vals = np.array([[0.5, 0.5], [0.6, 0.4], [0.5, 0.5], [1.5, 1.5]])
    w = np.array([2.0, 2.0, 0.5, 0.5])
    H = accumulate(g, voter, vals, w)
    np.testing.assert_allclose(H, [[2.5, 0.0], [0.0, 0.5]])


def _reference_votes(g: Grid, voter: np.ndarray, vals: np.ndarray, w: np.ndarray) -> np.ndarray:
    """One vote per (point, cell), the point's first sample in the cell carrying the weight:
    the definition, in plain Python."""
    H = np.zeros(int(np.prod(g.bins)))
    seen: set[tuple[int, int]] = set()
    for i in np.argsort(voter, kind="stable"):
        c = int(g.cell_index(vals[i:i + 1])[0])
        if c >= 0 and (int(voter[i]), c) not in seen:
            seen.add((int(voter[i]), c))
            H[c] += w[i]
    return H.reshape(g.bins)


def test_accumulate_interleaved_voters_and_wrapped_angles_match_the_definition():
    rng = np.random.default_rng(3)
    g = Grid((0.0, 0.0), (1.0, 2 * np.pi), (5, 8), wrap=(False, True))
    voter = rng.integers(0, 30, 2000)  # samples of one point are not consecutive
    vals = np.column_stack([rng.uniform(-0.2, 1.2, 2000), rng.uniform(-7.0, 14.0, 2000)])
    vals[::97] = np.nan  # a sampler's undefined sample votes nowhere
    w = rng.random(2000)
    np.testing.assert_array_equal(accumulate(g, voter, vals, w), _reference_votes(g, voter, vals, w))
    np.testing.assert_array_equal(accumulate(g, voter, vals), _reference_votes(g, voter, vals, np.ones(2000)))


def test_accumulate_with_no_sample_inside_is_zero():
    g = Grid((0.0,), (1.0,), (5,))
    H = accumulate(g, np.array([0, 1]), np.array([[2.0], [-1.0]]))
    np.testing.assert_array_equal(H, np.zeros(5))


# ---------------------------------------------------------------------------- persistent peaks


def _bump(shape, centre, height, width):
    grids = np.meshgrid(*[np.arange(n, dtype=float) for n in shape], indexing="ij")
    r2 = sum((x - c) ** 2 for x, c in zip(grids, centre))
    return height * np.exp(-0.5 * r2 / width**2)


@pytest.mark.parametrize("shape,c1,c2", [
    ((60,), (15,), (42,)),
    ((30, 40), (8, 10), (22, 30)),
    ((16, 18, 20), (4, 5, 5), (11, 12, 14)),
])
def test_two_bumps_give_two_peaks_with_their_persistence(shape, c1, c2):
    H = _bump(shape, c1, 10.0, 2.5) + _bump(shape, c2, 6.0, 2.5)
    flat, pers = persistent_peaks(H, 0.1)
    assert len(flat) == 2
    cells = [tuple(int(i) for i in np.unravel_index(f, shape)) for f in flat]
    assert cells == [c1, c2]  # most persistent first
    # The highest peak lives down to 0; the lower one dies at the highest saddle joining them,
    # which on a grid with diagonal neighbours is the max over paths of the path's minimum.
    assert pers[0] == pytest.approx(H[c1])
    saddle = _highest_saddle(H, c1, c2)
    assert pers[1] == pytest.approx(H[c2] - saddle)


def _highest_saddle(H, a, b):
    """Level at which a and b join in the superlevel filtration (brute force, bisection on levels)."""
    from scipy import ndimage

    levels = np.sort(np.unique(H))[::-1]
    struct = np.ones((3,) * H.ndim, bool)
    lo, hi = 0, len(levels) - 1
    while lo < hi:  # smallest index (highest level) at which a and b are connected
        mid = (lo + hi) // 2
        lab, _ = ndimage.label(H >= levels[mid], structure=struct)
        if lab[a] and lab[a] == lab[b]:
            hi = mid
        else:
            lo = mid + 1
    return levels[lo]


@pytest.mark.parametrize("shape", [(80,), (40, 40), (16, 16, 16)])
def test_noise_below_ten_percent_is_suppressed(shape):
    rng = np.random.default_rng(1)
    centre = tuple(n // 2 for n in shape)
    H = _bump(shape, centre, 100.0, 3.0) + rng.uniform(0.0, 8.0, size=shape)
    # The noise makes many local maxima, none persisting more than 8% of max H.
    flat, pers = persistent_peaks(H, 0.1)
    assert len(flat) == 1
    assert np.unravel_index(flat[0], shape) == np.unravel_index(np.argmax(H), shape)
    # With a lower threshold the noisy maxima show up: the 10% rule is what removes them.
    assert len(persistent_peaks(H, 0.001)[0]) > 3


def test_max_peaks_keeps_the_most_persistent():
    H = _bump((90,), (10,), 10.0, 2.0) + _bump((90,), (45,), 8.0, 2.0) + _bump((90,), (80,), 9.0, 2.0)
    flat, pers = persistent_peaks(H, 0.1, max_peaks=2)
    np.testing.assert_array_equal(flat, [10, 80])
    assert pers[0] >= pers[1]


def test_empty_or_zero_accumulator_has_no_peak():
    flat, pers = persistent_peaks(np.zeros((5, 5)))
    assert flat.size == 0 and pers.size == 0


def test_wrap_joins_a_peak_across_the_seam_1d():
    n = 36
    x = np.arange(n, dtype=float)
    # One bump centred on the seam (between the last and the first cell).
    d = np.minimum(np.abs(x - (n - 0.5)), np.abs(x + 0.5))
    H = 10.0 * np.exp(-0.5 * (d / 2.0) ** 2) + _bump((n,), (18,), 6.0, 2.0)
    flat_open, _ = persistent_peaks(H, 0.1)
    flat_wrap, pers_wrap = persistent_peaks(H, 0.1, wrap=[True])
    # Unwrapped, the two halves of the seam bump are two separate peaks.
    assert set(flat_open.tolist()) == {0, n - 1, 18}
    # Wrapped, they are one peak, plus the bump in the middle.
    assert len(flat_wrap) == 2
    assert flat_wrap[0] in (0, n - 1) and flat_wrap[1] == 18


def test_wrap_joins_peaks_across_the_seam_2d_only_in_the_wrapped_dimension():
    shape = (20, 24)
    ii, jj = np.meshgrid(np.arange(20.0), np.arange(24.0), indexing="ij")
    dj = np.minimum(np.abs(jj - 23.5), np.abs(jj + 0.5))  # periodic distance to the seam of dim 1
    H = 10.0 * np.exp(-0.5 * (((ii - 10) / 2.0) ** 2 + (dj / 2.0) ** 2))
    assert len(persistent_peaks(H, 0.1)[0]) == 2
    flat, _ = persistent_peaks(H, 0.1, wrap=[False, True])
    assert len(flat) == 1
    i, j = np.unravel_index(flat[0], shape)
    assert i == 10 and j in (0, 23)


# ---------------------------------------------------------------------------- directions


def _normals_of_planes(dirs, n_each, noise_deg, rng):
    """Noisy, randomly signed unit normals of planes with normals ``dirs``."""
    out = []
    for d in dirs:
        v = np.asarray(d, float) + np.radians(noise_deg) * rng.standard_normal((n_each, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        out.append(v * rng.choice([-1.0, 1.0], size=(n_each, 1)))
    return np.vstack(out)


def _match_directions(found, truth, tol_deg):
    """Each true direction has a found one within tol_deg, and no two found ones are the same."""
    assert len(found) == len(truth)
    for t in truth:
        errs = [_angle_deg(f, np.asarray(t, float)) for f in found]
        assert min(errs) <= tol_deg, (t, errs)


@pytest.fixture(scope="module")
def acc():
    return DirectionAccumulator(4000)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_direction_accumulator_finds_three_plane_normals_in_random_pose(acc, seed):
    rng = np.random.default_rng(seed)
    R = synth.random_rotation(rng)
    truth = R.T  # rows: three orthogonal directions in a random pose
    N = np.vstack([_normals_of_planes(truth[k:k + 1], n, 1.0, rng) for k, n in enumerate([900, 600, 400])])
    H = acc.smooth(acc.vote(N))
    dirs, pers = acc.peaks(H, 0.1)
    _match_directions(dirs, truth, 4.0)  # cells are about 3.2° apart
    refined = [refine_direction(d, N, np.radians(6.0)) for d in dirs]
    _match_directions(refined, truth, 0.5)
    assert np.all(dirs[:, 2] >= 0)
    assert np.all(np.diff(pers) <= 0)


@pytest.mark.parametrize("azimuth", [0.0, 17.0, 45.0, 90.0, 133.0])
def test_direction_accumulator_keeps_equatorial_peaks(acc, azimuth):
    """Regression: n and -n of an equatorial direction both lie on the equator; one peak per
    antipodal pair must survive (an earlier version lost such peaks)."""
    rng = np.random.default_rng(int(azimuth))
    a = np.radians(azimuth)
    truth = np.array([[np.cos(a), np.sin(a), 0.0],
                      [-np.sin(a), np.cos(a), 0.0],
                      [0.0, 0.0, 1.0]])
    N = _normals_of_planes(truth, 500, 1.0, rng)
    H = acc.smooth(acc.vote(N))
    dirs, _ = acc.peaks(H, 0.1)
    _match_directions(dirs, truth, 4.0)


def test_direction_accumulator_three_directions_all_on_the_equator(acc):
    rng = np.random.default_rng(5)
    truth = [[np.cos(t), np.sin(t), 0.0] for t in np.radians([10.0, 70.0, 130.0])]
    N = _normals_of_planes(truth, 400, 1.0, rng)
    dirs, _ = acc.peaks(acc.smooth(acc.vote(N)), 0.1)
    _match_directions(dirs, truth, 4.0)


@pytest.mark.parametrize("d", [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, -0.8, 0.0], [0.3, 0.4, 0.866]])
def test_direction_accumulator_one_peak_per_antipodal_pair(acc, d):
    rng = np.random.default_rng(3)
    d = np.asarray(d) / np.linalg.norm(d)
    N = _normals_of_planes([d], 1000, 1.5, rng)  # half the votes point to -d
    H = acc.vote(N)
    assert H.sum() == pytest.approx(2 * len(N))  # every direction votes for itself and its antipode
    dirs, pers = acc.peaks(acc.smooth(H), 0.1)
    assert len(dirs) == 1
    assert _angle_deg(dirs[0], d) <= 4.0
    assert dirs[0][2] >= 0


def test_direction_accumulator_max_peaks(acc):
    rng = np.random.default_rng(4)
    truth = synth.random_rotation(rng)
    N = np.vstack([_normals_of_planes(truth[:1], 1200, 1.0, rng), _normals_of_planes(truth[1:2], 600, 1.0, rng),
                   _normals_of_planes(truth[2:], 300, 1.0, rng)])
    dirs, _ = acc.peaks(acc.smooth(acc.vote(N)), 0.1, max_peaks=2)
    assert len(dirs) == 2
    _match_directions(dirs, truth[:2], 4.0)


@pytest.mark.parametrize("d", [2, 3])
def test_normal_line_votes_are_accumulate_on_the_lines_samples(d):
    # The walk along each normal line gives exactly what accumulating its
    # samples does, once per (point, cell), including samples off the grid.
    rng = np.random.default_rng(d)
    Q = rng.normal(size=(300, d))
    M = rng.normal(size=(300, d))
    M /= np.linalg.norm(M, axis=1, keepdims=True)
    lo, ext, bins = Q.min(axis=0), float(np.ptp(Q, axis=0).max()), 23
    g = Grid(tuple(lo), tuple(lo + ext), (bins,) * d)
    s = np.arange(ext / bins, 0.7 * ext, ext / bins)
    s = np.r_[-s, s]
    samples = (Q[:, None, :] + s[None, :, None] * M[:, None, :]).reshape(-1, d)
    want = accumulate(g, np.repeat(np.arange(len(Q)), len(s)), samples).ravel()
    H = np.zeros(want.size)
    _line_vote(Q, M, s, np.asarray(g.lower, float), g.width.astype(float), np.asarray(g.bins, np.int64), H)
    np.testing.assert_array_equal(H, want)


def test_normal_lines_of_a_circle_meet_at_its_centre():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    M = np.c_[np.cos(t), np.sin(t)]
    Q = np.array([0.3, -0.2]) + 0.5 * M
    lo = Q.min(axis=0)
    ext = float(np.ptp(Q, axis=0).max())
    (c,) = normal_line_peaks(Q, M, lo, ext, 40, 0.6 * ext, 0.1, 10.0, 5)
    assert np.linalg.norm(c - [0.3, -0.2]) <= ext / 40


def test_a_grid_narrower_than_rounding_bins_nothing():
    # A cluster a rounding step wide far from the origin (a scan rounded to float32): the grid's
    # upper corner rounds onto its lower one, its cells have width 0, and the vote divided by
    # zero (ZeroDivisionError from the kernel, a traceback for the user).
    Q = np.full((20, 2), 1e6) + np.linspace(0, 1e-11, 20)[:, None]
    M = np.tile([1.0, 0.0], (20, 1))
    assert normal_line_peaks(Q, M, Q.min(axis=0), 1e-11, 16, 1e-11, 0.1, 1, 4).shape == (0, 2)
