"""Helical strips: geometry against brute force, sampler, recognition in random poses."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import houghcad
from houghcad import synth
from houghcad.families import REGISTRY
from houghcad.families.helical_strip import from_world, helicoid_distance

FAM = REGISTRY["helical_strip"]


def test_helicoid_distance_matches_brute_force():
    rng = np.random.default_rng(0)
    c, b, a = 0.15, 0.3, 1.0
    X = rng.uniform(-1.2, 1.2, (300, 3)) * [1, 1, 0.5]
    rho, phi = np.hypot(X[:, 0], X[:, 1]), np.arctan2(X[:, 1], X[:, 0])
    d = helicoid_distance(rho, phi, X[:, 2], c, b, a)[0]
    r, v = np.meshgrid(np.linspace(b, a, 400), np.linspace(-4 * np.pi, 4 * np.pi, 6000))
    S = np.stack([r * np.cos(v), r * np.sin(v), c * v], -1).reshape(-1, 3)
    ref = cKDTree(S).query(X)[0]
    # The brute-force sample is 2e-3 apart along the radius and 4e-3 x r around.
    assert np.abs(d - ref).max() < 2e-3


@pytest.mark.parametrize("seed", [0, 1])
def test_distance_and_normals_on_the_sampled_surface(seed):
    cloud = synth.single("helical_strip", seed, n_points=2000)
    prim = from_world(cloud.primitives[0]["params"])
    assert FAM.distance(prim, cloud.points).max() < 1e-9 * cloud.diagonal()
    sn = FAM.surface_normals(prim, cloud.points)
    assert np.abs(np.einsum("ij,ij->i", sn, cloud.normals)).min() > 1 - 1e-9


def test_sampler_is_area_uniform():
    rng = np.random.default_rng(3)
    shape = {"r_inner": 0.3, "r_outer": 1.0, "c": 0.12, "v_range": (0.0, 4 * np.pi)}
    P, _ = synth.sample_helical_strip(rng, 200000, **shape)
    strip = synth.SAMPLERS["helical_strip"]
    rho = np.hypot(P[:, 0], P[:, 1])
    # Fraction below the mid radius vs the area ratio.
    half = strip.area(0.3, 0.65, 0.12, (0.0, 4 * np.pi)) / strip.area(**shape)
    assert abs(np.mean(rho < 0.65) - half) < 0.005


# Seed 2 failed (DSC 0.86) until consolidation: the global round hands 1700 of the strip's 3584 points
# to locally fitting planes and cylinders, which the strip now takes back.
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recognised_in_random_pose(seed):
    cloud = synth.single("helical_strip", seed, n_points=4000, noise=0.005, missing=0.1)
    gt = cloud.primitives[0]["params"]
    res = houghcad.segment(cloud.points, families="all", seed=0)
    segs = [s for s in res.segments if s.type == "helical_strip"]
    assert segs, [s.type for s in res.segments]
    s = max(segs, key=lambda s: len(s.indices))
    dsc = 2 * np.sum(cloud.labels[s.indices] == 0) / (len(s.indices) + len(cloud.points))
    assert dsc >= 0.9
    for k in ("r_inner", "r_outer", "pitch"):
        assert abs(s.params[k] - gt[k]) <= 0.02 * gt[k], k
    assert s.params["handedness"] == gt["handedness"]
    axis = np.asarray(s.params["axis"])
    assert abs(axis @ np.asarray(gt["axis"])) > np.cos(np.radians(1.0))
    assert s.mfe <= 0.01
    # The reported surface is the true one: ground-truth points lie on it.
    d = FAM.distance(from_world(s.params), cloud.points)
    assert np.median(d) < 2 * cloud.sigma


@pytest.mark.parametrize("family,seed", [("plane", 0), ("cylinder", 1)])
def test_simple_singles_stay_simple(family, seed):
    cloud = synth.single(family, seed, n_points=3000, noise=0.005)
    res = houghcad.segment(cloud.points, families="all", seed=0)
    big = max(res.segments, key=lambda s: len(s.indices))
    assert big.type == family
    assert len(big.indices) >= 0.9 * len(cloud.points)
