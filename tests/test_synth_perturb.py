"""Tests of houghcad.synth.perturb: each perturbation does what it says to the points and keeps
the ground truth in step, seeded and without touching its input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from houghcad import synth
from houghcad.synth import Perturbation, perturb


@pytest.fixture(scope="module")
def flat():
    """A plane in its standard frame (normal z, at z = 0), 4,000 points."""
    return synth.single("plane", 2, n_points=4000, pose=False)


@pytest.fixture(scope="module")
def part():
    return synth.block_with_hole_and_slot(seed=1, n_points=6000)


def test_same_seed_same_cloud_and_the_input_untouched(part):
    before = part.points.copy(), part.labels.copy()
    p = Perturbation(gaussian=0.003, missing=0.2, outliers=0.1, bumps=0.01, uneven=0.5)
    a, b = perturb(part, p, seed=4), perturb(part, p, seed=4)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.labels, b.labels)
    assert not np.array_equal(a.points, perturb(part, p, seed=5).points)
    np.testing.assert_array_equal(part.points, before[0])
    np.testing.assert_array_equal(part.labels, before[1])


def test_clean_is_the_same_cloud_reordered(part):
    q = perturb(part, Perturbation(), seed=0)
    order_p, order_q = np.lexsort(part.points.T), np.lexsort(q.points.T)
    np.testing.assert_array_equal(part.points[order_p], q.points[order_q])
    np.testing.assert_array_equal(part.labels[order_p], q.labels[order_q])
    assert q.primitives == part.primitives and q.sigma == 0.0


def test_gaussian_and_uniform_noise_have_their_spread(flat):
    diag = flat.diagonal()
    g = perturb(flat, Perturbation(gaussian=0.01), seed=1)
    assert np.std(g.points[:, 2]) == pytest.approx(0.01 * diag, rel=0.05)
    assert g.sigma == pytest.approx(0.01 * diag)
    u = perturb(flat, Perturbation(uniform=0.01), seed=1)
    z = u.points[:, 2]
    assert np.abs(z).max() <= 0.01 * diag
    assert np.std(z) == pytest.approx(0.01 * diag / np.sqrt(3), rel=0.05)


def test_holes_cut_the_fraction_in_that_many_pieces(flat):
    q = perturb(flat, Perturbation(missing=0.3, holes=3), seed=2)
    assert len(q.points) == len(flat.points) - round(0.3 * len(flat.points))
    # The removed points: the clean points with no kept point at the same place.
    d, _ = cKDTree(q.points).query(flat.points)
    gone = flat.points[d > 0]
    assert len(gone) == round(0.3 * len(flat.points))
    spacing = np.median(cKDTree(flat.points).query(flat.points, k=2)[0][:, 1])
    graph = cKDTree(gone).sparse_distance_matrix(cKDTree(gone), 4 * spacing)
    sizes = np.bincount(connected_components(graph, directed=False)[1])
    assert (sizes > 0.02 * len(gone)).sum() <= 3  # (a stray point at a ragged rim aside)


def test_undersampling_and_uneven_density(flat):
    assert len(perturb(flat, Perturbation(n_points=300), seed=0).points) == 300
    q = perturb(flat, Perturbation(uneven=0.9), seed=0)
    # The keep probability falls linearly from 1 to 0.1: 55 % kept on average.
    assert len(q.points) == pytest.approx(0.55 * len(flat.points), rel=0.1)
    # One end of the cloud is several times denser than the other along some direction.
    counts = []
    for d in np.eye(3)[:2]:
        t = q.points @ d
        lo, hi = np.quantile(flat.points @ d, [0.2, 0.8])
        counts.append(max((t < lo).sum(), (t > hi).sum()) / max(min((t < lo).sum(), (t > hi).sum()), 1))
    assert max(counts) > 2


def test_bumps_move_points_along_the_normals(flat):
    diag = flat.diagonal()
    q = perturb(flat, Perturbation(bumps=0.03, n_bumps=2), seed=3)
    z = q.points[:, 2]
    assert 0.9 * 0.03 * diag <= z.max() <= 2 * 0.03 * diag  # two bumps may overlap a little
    assert z.min() >= 0.0
    assert np.mean(z > 0.001 * diag) < 0.6  # local: most of the plane stays flat
    np.testing.assert_allclose(np.sort(q.points[:, 0]), np.sort(flat.points[:, 0]))  # x, y unchanged


def test_outliers_fill_the_grown_box_with_label_minus_one(part):
    q = perturb(part, Perturbation(outliers=0.2), seed=0)
    out = q.labels == -1
    assert out.mean() == pytest.approx(0.2, abs=1e-3)
    assert (np.abs(q.normals[out]).sum(axis=1) == 0).all()
    lo, hi = part.points.min(axis=0), part.points.max(axis=0)
    grow = 0.1 * part.diagonal() + 1e-9
    assert (q.points[out] >= lo - grow).all() and (q.points[out] <= hi + grow).all()
    np.testing.assert_array_equal(np.bincount(q.labels[~out]), np.bincount(part.labels))


@pytest.mark.parametrize("kwargs", [{"gaussian": -0.1}, {"missing": 1.0}, {"outliers": -0.2}, {"uneven": 1.0},
                                    {"n_points": 0}, {"holes": 0}])
def test_bad_perturbations_are_refused(kwargs):
    with pytest.raises(ValueError):
        Perturbation(**kwargs)


def test_describe_names_what_differs():
    assert Perturbation().describe() == "clean"
    assert Perturbation(gaussian=0.005, missing=0.3).describe() == "gaussian=0.005, missing=0.3"


def test_scan_rows_keep_bands_of_a_dense_sample_and_normal_noise_stays_on_the_normal(flat):
    """Rows: the kept points lie in parallel bands a twentieth of their gap wide, a twentieth of
    the points, and along a row closer than the rows are apart. Noise along the normal moves a
    plane's points off it only along z."""
    from houghcad.preprocess import _neighbourhoods, _unit_cube
    from houghcad.scanrows import on_rows

    dense = synth.single("plane", 2, n_points=80000, pose=False)
    q = perturb(dense, Perturbation(rows=10.0, row_band=0.05), seed=3)
    assert 0.035 < len(q.points) / len(dense.points) < 0.065
    assert np.abs(q.points[:, 2]).max() < 1e-12  # a subset of the plane's points, unmoved
    x = _unit_cube(q.points)[2]
    h = _neighbourhoods(x, 16)
    assert on_rows(x, h.nbr, h.normals).mean() > 0.3
    noisy = perturb(flat, Perturbation(normal_noise=0.002), seed=3)
    order_a, order_b = np.lexsort(flat.points[:, :2].T), np.lexsort(noisy.points[:, :2].T)
    np.testing.assert_allclose(noisy.points[order_b, :2], flat.points[order_a, :2])
    assert 0.5 < np.std(noisy.points[:, 2]) / (0.002 * synth.primitives._bbox_diag(flat.points)) < 1.5
    with pytest.raises(ValueError, match="row_band"):
        Perturbation(rows=5.0, row_band=0.0)

