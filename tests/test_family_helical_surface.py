"""Helical surfaces (threads): geometry against brute force, sampler, recognition in random poses."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import houghcad
from houghcad import synth
from houghcad.families import REGISTRY
from houghcad.families.helical_surface import from_world

FAM = REGISTRY["helical_surface"]


@pytest.mark.parametrize("seed", [0, 2])
def test_distance_and_normals_on_the_sampled_surface(seed):
    cloud = synth.single("helical_surface", seed, n_points=2000)
    prim = from_world(cloud.primitives[0]["params"])
    assert FAM.distance(prim, cloud.points).max() < 1e-9 * cloud.diagonal()
    sn = FAM.surface_normals(prim, cloud.points)
    assert np.abs(np.einsum("ij,ij->i", sn, cloud.normals)).min() > 1 - 1e-9


def test_distance_matches_brute_force():
    dense = synth.single("helical_surface", 4, n_points=600000, pose=False)
    prim = from_world(dense.primitives[0]["params"])
    z = dense.points[:, 2]
    mid = dense.points[np.abs(z - np.median(z)) < 0.2 * np.ptp(z)][:300]  # away from the patch's ends
    rng = np.random.default_rng(1)
    X = mid + rng.normal(0, 0.02, mid.shape)
    d = FAM.distance(prim, X)
    ref, _ = cKDTree(dense.points).query(X)
    area = synth.SAMPLERS["helical_surface"].area(
        **synth.SAMPLERS["helical_surface"].random_shape(synth._Streams.from_seed(4, "helical_surface").shape))
    spacing = np.sqrt(area / len(dense.points))
    assert np.all(d <= ref + 1e-9)  # the brute-force sample only over-estimates
    assert np.all(ref - d <= 1.5 * spacing)


def test_world_parameters_describe_the_sampled_surface():
    # k2 is the crest's axial offset in the half-plane of ref_direction: moving
    # axis_point along the axis by k2 puts a crest (radius R2) there.
    cloud = synth.single("helical_surface", 5, n_points=500)
    p = cloud.primitives[0]["params"]
    crest = np.asarray(p["axis_point"]) + p["k2"] * np.asarray(p["axis"]) + p["R2"] * np.asarray(p["ref_direction"])
    assert FAM.distance(from_world(p), crest[None])[0] < 1e-9 * cloud.diagonal()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recognised_in_random_pose(seed):
    cloud = synth.single("helical_surface", seed, n_points=4000, noise=0.005, missing=0.1)
    gt = cloud.primitives[0]["params"]
    res = houghcad.segment(cloud.points, families="all", seed=0)
    segs = [s for s in res.segments if s.type == "helical_surface"]
    assert segs, [s.type for s in res.segments]
    s = max(segs, key=lambda s: len(s.indices))
    dsc = 2 * np.sum(cloud.labels[s.indices] == 0) / (len(s.indices) + len(cloud.points))
    assert dsc >= 0.9
    assert s.params["n"] == int(gt["n"])
    for k in ("R1", "R2", "k1"):
        assert abs(s.params[k] - gt[k]) <= 0.02 * gt[k], k
    assert s.mfe <= 0.01
    d = FAM.distance(from_world(s.params), cloud.points)
    assert np.median(d) < 2 * cloud.sigma


@pytest.mark.parametrize("family,seed", [("cylinder", 0), ("sphere", 1)])
def test_simple_singles_stay_simple(family, seed):
    cloud = synth.single(family, seed, n_points=3000, noise=0.005)
    res = houghcad.segment(cloud.points, families="all", seed=0)
    big = max(res.segments, key=lambda s: len(s.indices))
    assert big.type == family


def test_trimmed_complex_sees_the_screw_of_a_noisy_threaded_part():
    # The ends of the threaded sector (two planes, a tenth of the part) keep the
    # whole cloud's complex above the global gate; left out, the rest is one screw.
    from houghcad.families._helix import GLOBAL_COMPLEX_RESIDUAL, NOISY_TRIM, screw_placement
    from houghcad.preprocess import preprocess

    c = synth.PARTS["screw_part"](seed=1, n_points=6000, noise=0.005)
    pre = preprocess(c.points)
    _, _, res = screw_placement(pre.points, pre.normals)
    pl, p, res_t = screw_placement(pre.points, pre.normals, NOISY_TRIM)
    assert res > GLOBAL_COMPLEX_RESIDUAL > 5 * res_t
    gt = pre.transform.R @ np.asarray(c.primitives[0]["params"]["axis"], float)
    # Measured on seeds 0-2: 0.87°, 1.07°, 0.36° with the normals' neighbourhood sized by the
    # noise (0.99°, 0.94°, 0.29° with 64 neighbours).
    assert np.degrees(np.arccos(min(1.0, abs(pl.R[2] @ gt)))) < 1.2
    pitch = c.primitives[0]["params"]["k1"] * c.primitives[0]["params"]["n"] * pre.transform.scale
    assert abs(abs(p) - pitch) < 0.1 * pitch
    # A part of several surfaces of revolution and planes is still no screw.
    e = synth.PARTS["ellipsoid_part"](seed=1, n_points=6000, noise=0.005)
    pre = preprocess(e.points)
    assert screw_placement(pre.points, pre.normals, NOISY_TRIM)[2] > GLOBAL_COMPLEX_RESIDUAL


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_thread_of_a_noisy_screw_part_is_one_helical_surface(seed):
    c = synth.PARTS["screw_part"](seed=seed, n_points=6000, noise=0.005)
    res = houghcad.segment(c.points, families="all", seed=0)
    truth = np.flatnonzero(c.labels == 0)
    best = max(res.segments, key=lambda s: np.intersect1d(s.indices, truth).size)
    assert best.type == "helical_surface"
    assert best.params["n"] == int(c.primitives[0]["params"]["n"])
    assert 2 * np.intersect1d(best.indices, truth).size / (len(truth) + len(best.indices)) >= 0.85
    assert best.mfe <= 0.01


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_fit_does_not_flatten_a_deep_fine_thread_under_noise(seed):
    # Deep threads (root 0.41-0.55 R2) with a period of 0.3-0.5 R2: their root and crest bend
    # within the noise (σ = 1.2 % of R2), where Sampson's first-order distance under-reads the
    # points' distances and the fit came out too shallow (root radius +1.3 to +2.2 %).
    from houghcad.families.helical_surface import sample_helical_surface

    rng = np.random.default_rng(seed)
    R1, k1, n = rng.uniform(0.4, 0.55), rng.uniform(0.25, 0.5) / (2 * np.pi), int(rng.integers(1, 4))
    P, N = sample_helical_surface(rng, 6000, R1, 1.0, k1, n, 4)
    P = P + rng.normal(0, 0.012, P.shape)
    truth = from_world({"axis_point": [0, 0, 0], "axis": [0, 0, 1], "ref_direction": [1, 0, 0], "R1": R1,
                        "R2": 1.0, "n": n, "k1": k1, "k2": 0.0})
    fit = FAM.fit(truth, P[:1500], N[:1500])
    assert abs(fit.params["R1"] / R1 - 1) < 0.012
    assert abs(fit.params["R2"] - 1) < 0.008
    assert abs(fit.params["k1"] / k1 - 1) < 0.01


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_final_fit_reads_the_radii_of_a_deep_fine_thread_that_least_squares_deepens(seed):
    # Root 0.45 R2, period 0.3 R2, σ = 1.6 % of R2 (the complex benchmark's deep threads): the root
    # and crest bend within the noise, and least squares on orthogonal distances moves the crest
    # out and the root in to meet the points scattered past them (root 1.4-2.4 % low, crest
    # 0.9-1.1 % high). The likelihood of the points as the surface blurred by the noise does not.
    from houghcad.families.helical_surface import sample_helical_surface

    rng = np.random.default_rng(seed)
    R1, k1, n = 0.45, 0.3 / (2 * np.pi), 1 + seed
    P, N = sample_helical_surface(rng, 3000, R1, 1.0, k1, n, 4)
    P = P + rng.normal(0, 0.016, P.shape)
    truth = from_world({"axis_point": [0, 0, 0], "axis": [0, 0, 1], "ref_direction": [1, 0, 0], "R1": R1,
                        "R2": 1.0, "n": n, "k1": k1, "k2": 0.0})
    ls, ml = FAM.fit(truth, P, N).params, FAM.final_fit(truth, P, N).params
    assert ls["R1"] / R1 - 1 < -0.012 and ls["R2"] - 1 > 0.007
    assert abs(ml["R1"] / R1 - 1) < 0.006 and abs(ml["R2"] - 1) < 0.003
    assert ml["k1"] == ls["k1"] and ml["k2"] == ls["k2"] and ml["n"] == ls["n"]


def test_final_fit_keeps_least_squares_where_the_segment_is_not_the_thread_it_claims():
    # A one-start thread fitted as a two-start one of another period: the likelihood's σ is half
    # the residuals' RMS, and its radii would move the reported error for no truer shape.
    from houghcad.families.helical_surface import sample_helical_surface

    rng = np.random.default_rng(0)
    k1 = 0.3 / (2 * np.pi)
    P, N = sample_helical_surface(rng, 3000, 0.45, 1.0, k1, 1, 4)
    P = P + rng.normal(0, 0.016, P.shape)
    wrong = from_world({"axis_point": [0, 0, 0], "axis": [0, 0, 1], "ref_direction": [1, 0, 0], "R1": 0.45,
                        "R2": 1.0, "n": 2, "k1": 0.65 * k1, "k2": 0.0})
    ls, final = FAM.fit(wrong, P, N), FAM.final_fit(wrong, P, N)
    assert all(np.array_equal(final.params[k], ls.params[k]) for k in ls.params)


def test_final_fit_is_least_squares_on_exact_samples():
    cloud = synth.single("helical_surface", 1, n_points=2000)
    prim = from_world(cloud.primitives[0]["params"])
    ls, final = FAM.fit(prim, cloud.points, cloud.normals), FAM.final_fit(prim, cloud.points, cloud.normals)
    assert all(np.array_equal(final.params[k], ls.params[k]) for k in ls.params)


def test_a_thread_finer_than_the_inlier_band_is_not_valid():
    from types import SimpleNamespace

    from houghcad.families.helical_surface import RESOLVED_QUARTER_TAUS

    ctx = SimpleNamespace(tau=0.01, max_radius=1.0)

    def thread(period: float):
        return from_world({"axis_point": [0, 0, 0], "axis": [0, 0, 1], "ref_direction": [1, 0, 0], "R1": 0.3,
                           "R2": 0.5, "n": 2, "k1": period / (2 * np.pi), "k2": 0.0})

    # Every point lies within a quarter period of a flank: below the band, any point fits.
    assert not FAM.valid(thread(4 * 0.5 * RESOLVED_QUARTER_TAUS * ctx.tau), ctx)
    assert FAM.valid(thread(4 * 1.5 * RESOLVED_QUARTER_TAUS * ctx.tau), ctx)


@pytest.mark.parametrize("seed", [3, 19])
def test_profile_pitch_recovers_the_pitch_that_blurred_normals_lower(seed):
    # Deep fine threads (period 0.3-0.4 R2) at 0.5 % noise: the widened normals average both flanks
    # towards a cylinder's, and the normal lines' pitch comes out 13 % and 54 % low (seeds 3, 19).
    # Sorted along w = z - p φ, the radii trace one profile only at the true pitch.
    from houghcad.families._helix import NOISY_TRIM, screw_placement
    from houghcad.families.helical_surface import profile_pitch
    from houghcad.preprocess import preprocess

    c = synth.single("helical_surface", seed=seed, n_points=4000, noise=0.005, missing=0.1)
    pre = preprocess(c.points)
    pl, p0, _ = screw_placement(pre.points, pre.normals, NOISY_TRIM)
    true = c.primitives[0]["params"]["k1"] * c.primitives[0]["params"]["n"] * pre.transform.scale
    assert abs(p0 / true - 1) > 0.1
    assert abs(profile_pitch(pl.local(pre.points, pre.normals)[0], p0) / true - 1) < 0.02
