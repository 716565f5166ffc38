"""Dense connected subsets: DBSCAN against scikit-learn, and each point's own link."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import houghcad
from houghcad import synth
from houghcad.pipeline import Segmenter
from houghcad.preprocess import preprocess

@pytest.mark.parametrize("seed", range(40))
def test_dbscan_matches_scikit_learn(seed: int):
    from sklearn.cluster import DBSCAN

    from houghcad.clusters import dbscan

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    # Clumps and scatter, so that core, border and noise points all occur.
    P = np.vstack([rng.normal(size=(n, 3)) * 0.05 + rng.random(3), rng.random((n // 2, 3))])
    eps, ms = float(rng.uniform(0.02, 0.3)), int(rng.integers(1, 8))
    assert np.array_equal(dbscan(P, eps, ms), DBSCAN(eps=eps, min_samples=ms).fit_predict(P))


def test_dbscan_empty_and_single():
    from houghcad.clusters import dbscan

    assert dbscan(np.empty((0, 3)), 0.1, 3).shape == (0,)
    assert dbscan(np.zeros((1, 3)), 0.1, 1).tolist() == [0]
    assert dbscan(np.zeros((1, 3)), 0.1, 2).tolist() == [-1]


@pytest.mark.parametrize("seed", range(20))
def test_dbscan_with_scales_links_within_the_smaller_scale(seed: int):
    """Points i, j are neighbours within eps * min(scale_i, scale_j) (eps when both scales are
    negative): the same labels as scikit-learn on distances divided by that smaller scale."""
    from sklearn.cluster import DBSCAN

    from houghcad.clusters import dbscan

    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 250))
    P = np.vstack([rng.normal(size=(n, 3)) * 0.05 + rng.random(3), rng.random((n // 2, 3))])
    scale = rng.uniform(1.0, 3.0, len(P)).astype(np.float32)
    scale[rng.random(len(P)) < 0.4] = 1.0  # points of the evenly sampled rest
    eps, ms = float(rng.uniform(0.02, 0.2)), int(rng.integers(1, 6))
    D = np.linalg.norm(P[:, None] - P[None], axis=2) / np.minimum(scale[:, None], scale[None]).astype(np.float64)
    want = DBSCAN(eps=eps, min_samples=ms, metric="precomputed").fit_predict(D)
    assert np.array_equal(dbscan(P, eps, ms, scale), want)
    # Points off every surface (negative scales) link farther only to points on one.
    off = rng.random(len(P)) < 0.3
    both = off[:, None] & off[None]
    D_off = np.where(both, D * np.minimum(scale[:, None], scale[None]), D)
    want = DBSCAN(eps=eps, min_samples=ms, metric="precomputed").fit_predict(D_off)
    assert np.array_equal(dbscan(P, eps, ms, np.where(off, -scale, scale)), want)
    # Unit scales are no scales.
    assert np.array_equal(dbscan(P, eps, ms, np.ones(len(P), np.float32)), dbscan(P, eps, ms))


def test_a_face_sampled_four_times_sparser_on_one_side_is_one_dense_subset():
    """Half a plane 4 times sparser than the other half: at the cloud's link the sparse half falls
    apart into fragments, at each point's own scale it is one dense subset with the dense half."""
    from houghcad.clusters import dense_subsets

    rng = np.random.default_rng(0)
    xy = np.vstack([rng.random((4000, 2)) * [0.5, 1.0], rng.random((1000, 2)) * [0.5, 1.0] + [0.5, 0.0]])
    pre = preprocess(np.c_[xy, np.zeros(len(xy))], sampling_scales=True)
    t = houghcad.Tolerances().scale
    link = max(t.link_spacings * pre.spacing, t.link_reach * pre.reach)
    assert len(dense_subsets(pre.points, link, 6, 3)) > 5
    whole = dense_subsets(pre.points, link, 6, 3, pre.link_scale)
    assert [len(c) for c in whole] == [5000]


#: Each point's own link, up to 4 times the cloud's (the 10:1 thinning reads up to about 3).
OWN_LINK = {"scale.link_scale_max": 4.0}
#: One link for the whole cloud.
ONE_LINK = {"scale.link_scale_max": 1.0}


@pytest.mark.parametrize("make,seed", [("gear_like", 0), ("plate_with_holes", 1), ("filleted_block", 2)])
def test_a_part_scanned_from_one_side_keeps_one_segment_per_face(make: str, seed: int):
    """Sampled ten times more sparsely at one end than the other (as a scan sees a part from one
    side), every face is one segment with each point's own link (``link_scale_max`` above 1, the
    default). At the cloud's one link the sparse end's faces came out in 1-5 extra pieces here."""
    from houghcad.evaluate import classification_measures
    from houghcad.synth.perturb import Perturbation, perturb

    cloud = perturb(getattr(synth, make)(n_points=6000, seed=seed), Perturbation(uneven=0.9), seed=seed)
    res = Segmenter(n_jobs=1).fit(cloud.points).result_
    faces = [np.asarray(f) for f in res.faces()]
    assert len(faces) == len(cloud.segments())
    assert classification_measures(faces, cloud.segments(), len(cloud.points))["DSC"] > 0.97


def test_only_clearly_sparser_sampling_lengthens_the_link():
    """Scales under ``link_scale_from`` (random sampling's own variation) link at the cloud's
    link; at or above it, at the point's scale, up to ``link_scale_max``."""
    from houghcad.context import derive_context
    from houghcad.noise import CLEAN, NOISY
    from houghcad.tolerances import Tolerances

    cloud = synth.single("plane", n_points=500, seed=0)
    pre = preprocess(cloud.points)
    pre = replace(pre, link_scale=np.array([1.0, 1.2, 1.25, 1.35, 3.0], np.float32).repeat(100))
    idx = np.arange(0, 500, 100)
    ctx = derive_context(pre, 500, Tolerances.from_dict(OWN_LINK), CLEAN)
    assert np.allclose(ctx.link_scales(idx), [1.0, 1.0, 1.0, 1.35, 3.0])
    capped = derive_context(pre, 500, Tolerances.from_dict({"scale.link_scale_max": 2.0}), CLEAN)
    assert np.allclose(capped.link_scales(idx), [1.0, 1.0, 1.0, 1.35, 2.0])
    assert ctx.link_scales(idx[:3]) is None
    # Under noise the neighbour distances read the noise's spread, not the sampling.
    assert derive_context(pre, 500, Tolerances.from_dict(OWN_LINK), NOISY).link_scales(idx) is None
    # The own link by default; one link for the cloud at link_scale_max = 1.
    assert np.allclose(derive_context(pre, 500, Tolerances(), CLEAN).link_scales(idx), [1.0, 1.0, 1.0, 1.35, 3.0])
    assert derive_context(pre, 500, Tolerances.from_dict(ONE_LINK), CLEAN).link_scales(idx) is None
    # A point whose neighbourhood no surface explains (a scattered outlier) is marked negative.
    off = np.zeros(500, np.float32)
    off[400:] = 0.2
    assert np.allclose(replace(ctx, pre=replace(pre, off_surface=off)).link_scales(idx), [1.0, 1.0, 1.0, 1.35, -3.0])


def test_scattered_outliers_keep_the_clouds_link():
    """Uniform outliers in the bounding box are sampled sparsely too, and would link as a sparse
    face does: they read as off every surface, and link among themselves at the cloud's link
    (linked farther, they formed clusters the splitting phase searched at length). The part's
    sparse faces keep their scales."""
    from houghcad.context import derive_context
    from houghcad.noise import CLEAN
    from houghcad.synth.perturb import Perturbation, perturb

    cloud = perturb(synth.plate_with_holes(n_points=12000, seed=0), Perturbation(outliers=0.3), seed=0)
    pre = preprocess(cloud.points, sampling_scales=True)
    ctx = derive_context(pre, len(cloud.points), houghcad.Tolerances(), CLEAN)
    out = np.flatnonzero(cloud.labels < 0)
    assert np.mean(pre.link_scale[out] >= ctx.tol.scale.link_scale_from) > 0.5  # sparse, as read
    scales = ctx.link_scales(out)
    assert np.mean(scales > 1.0) < 0.01
    # Among themselves they link almost as at the cloud's link: a few small clusters, where their
    # scales alone would chain most of them into one (about 4,400 of 5,100 here).
    from houghcad.clusters import dbscan
    P = pre.points[out]
    lab = dbscan(P, ctx.link, 3, scales)
    assert np.sum(lab >= 0) < 1.2 * np.sum(dbscan(P, ctx.link, 3) >= 0)
    assert np.bincount(lab[lab >= 0]).max() < 50
    assert np.sum(dbscan(P, ctx.link, 3, np.abs(scales)) >= 0) > 0.5 * len(out)
    uneven = perturb(synth.plate_with_holes(n_points=6000, seed=0), Perturbation(uneven=0.9), seed=0)
    pre = preprocess(uneven.points, sampling_scales=True)
    ctx = derive_context(pre, len(uneven.points), houghcad.Tolerances(), CLEAN)
    far = pre.link_scale >= ctx.tol.scale.link_scale_from
    assert np.mean(ctx.link_scales(np.flatnonzero(far)) > 1.0) > 0.6


def test_one_link_for_the_whole_cloud_at_link_scale_max_one(monkeypatch):
    """At ``link_scale_max = 1`` every point links at the cloud's link, as in a cloud without
    scales: the sparse end of the part scanned from one side comes out in extra pieces."""
    import houghcad.preprocess as preprocess_module
    from houghcad.synth.perturb import Perturbation, perturb

    cloud = perturb(synth.gear_like(n_points=6000, seed=0), Perturbation(uneven=0.9), seed=0)
    capped = Segmenter(n_jobs=1, tolerances=ONE_LINK).fit(cloud.points).result_.faces()
    monkeypatch.setattr(preprocess_module, "link_scale", lambda dist, nbr: None)
    none = Segmenter(n_jobs=1).fit(cloud.points).result_.faces()
    assert [list(f) for f in capped] == [list(f) for f in none]
    assert len(capped) > len(cloud.segments())
