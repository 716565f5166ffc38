"""The ellipsoid family (issue 3): geometry, quadric placement, recognition in random poses with
families="all", spheres staying spheres, and the synthetic samplers and part."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from houghcad import segment, synth
from houghcad.families import REGISTRY, Primitive
from houghcad.families.ellipsoid import SPHERE_TOL, ellipsoid_foot, quadric_fit
from houghcad.context import Context


def _largest(result, type_: str):
    segs = [s for s in result.segments if s.type == type_]
    return max(segs, key=lambda s: len(s.indices)) if segs else None


def _dsc(indices: np.ndarray, truth: np.ndarray) -> float:
    inter = np.isin(indices, truth).sum()
    return 2.0 * inter / (len(indices) + len(truth))


def test_foot_matches_a_dense_sample_of_the_surface():
    rng = np.random.default_rng(3)
    e = np.array([0.4, 0.7, 1.1])
    Y = rng.normal(scale=0.8, size=(3000, 3))
    foot, d = ellipsoid_foot(Y, e)
    assert np.allclose(np.sum((foot / e) ** 2, axis=1), 1.0, atol=1e-9)
    S, _ = synth.sample_ellipsoid(np.random.default_rng(0), 150_000, e)
    dd, _ = cKDTree(S).query(Y)
    # The dense sample's spacing (≈ 0.004) bounds the difference from above.
    assert np.all(d <= dd + 1e-12)
    assert np.max(dd - d) < 0.015


def test_quadric_fit_recovers_centre_axes_and_semi_axes():
    rng = np.random.default_rng(5)
    e = np.array([0.5, 0.8, 1.2])
    P, N = synth.sample_ellipsoid(rng, 2000, e, polar_range=(0.0, 0.7 * np.pi))
    R = synth.random_rotation(rng)
    t = rng.uniform(-1, 1, 3)
    P, N = synth.apply_transform(P, N, R, t)
    c, V, semi = quadric_fit(P, N)
    assert np.allclose(c, t, atol=1e-8)
    assert np.allclose(semi, e, rtol=1e-8)
    assert np.allclose(np.abs(np.einsum("ij,ij->i", V, R.T)), 1.0, atol=1e-8)


def test_valid_rejects_near_spheres():
    fam = REGISTRY["ellipsoid"]
    ctx = Context(pre=None, tau=0, epsilon=0, angle=0, link=0, cell=0, min_points=0, max_radius=1.0)

    def prim(e):
        return Primitive("ellipsoid", {"center": np.zeros(3), "axes": np.eye(3), "semi_axes": np.asarray(e, float),
                                       "kind": "triaxial"})

    assert not fam.valid(prim([0.5, 0.5, 0.5 * (1 - 0.5 * SPHERE_TOL)]), ctx)
    assert fam.valid(prim([0.5, 0.5, 0.4]), ctx)
    assert not fam.valid(prim([0.5, 0.5, 3.0]), ctx)


def test_sampler_is_area_uniform_and_matches_the_spheroid_area():
    p, q = 1.0, 0.5
    e_ = np.sqrt(1 - q * q / (p * p))
    oblate = 2 * np.pi * p * p * (1 + (1 - e_ * e_) / e_ * np.arctanh(e_))
    assert synth.SAMPLERS["ellipsoid"].area(semi_axes=(p, p, q)) == pytest.approx(oblate, rel=1e-4)
    # Area-uniform: the share of points above z = 0.25 equals that zone's share of the area.
    P, N = synth.sample_ellipsoid(np.random.default_rng(1), 100_000, (p, p, q))
    zc = 0.25 / q  # cos of the polar angle on the unit sphere
    share = synth.SAMPLERS["ellipsoid"].area((p, p, q), (0.0, np.arccos(zc))) / oblate
    assert np.mean(P[:, 2] > 0.25) == pytest.approx(share, abs=0.006)
    assert np.allclose(np.linalg.norm(N, axis=1), 1.0)


def test_single_ellipsoid_ground_truth_is_consistent():
    for seed in range(4):
        c = synth.single("ellipsoid", seed, n_points=2000, noise=0.0)
        p = c.primitives[0]["params"]
        V, e = np.asarray(p["axes"]), np.asarray(p["semi_axes"])
        assert np.all(np.diff(e) >= 0) and e[0] / e[-1] <= 0.8 + 1e-9
        Y = (c.points - p["center"]) @ V.T
        assert np.allclose(np.sum((Y / e) ** 2, axis=1), 1.0, atol=1e-9)
        assert min(abs(float(np.asarray(p["axis"]) @ v)) for v in V) < 1.0 + 1e-12


def test_ellipsoid_part_has_ground_truth_per_face():
    c = synth.PARTS["ellipsoid_part"](seed=0, n_points=8000)
    types = [p["type"] for p in c.primitives]
    assert types.count("plane") == 7 and types.count("ellipsoid") == 1
    assert "torus" in types and "cylinder" in types
    counts = np.bincount(c.labels, minlength=len(types))
    assert np.all(counts > 0)
    k = types.index("ellipsoid")
    p = c.primitives[k]["params"]
    Y = (c.points[c.labels == k] - p["center"]) @ np.asarray(p["axes"]).T
    assert np.allclose(np.sum((Y / np.asarray(p["semi_axes"])) ** 2, axis=1), 1.0, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1])
def test_ellipsoid_recognised_in_random_pose(seed):
    c = synth.single("ellipsoid", seed, n_points=4000, noise=0.005, missing=0.1)
    r = segment(c.points, families="all", seed=0)
    s = _largest(r, "ellipsoid")
    assert s is not None, [(x.type, len(x.indices)) for x in r.segments]
    assert _dsc(s.indices, np.flatnonzero(c.labels == 0)) >= 0.9
    gt = c.primitives[0]["params"]
    assert np.allclose(np.sort(s.params["semi_axes"]), gt["semi_axes"], rtol=0.02)
    assert np.linalg.norm(np.subtract(s.params["center"], gt["center"])) < 0.02 * max(gt["semi_axes"])
    assert s.mfe <= 0.01


@pytest.mark.parametrize("seed", [0, 1])
def test_spheres_stay_spheres_with_all_families(seed):
    c = synth.single("sphere", seed, n_points=4000, noise=0.005)
    r = segment(c.points, families="all", seed=0)
    assert not [s for s in r.segments if s.type == "ellipsoid"]
    s = _largest(r, "sphere")
    assert s is not None and _dsc(s.indices, np.flatnonzero(c.labels == 0)) >= 0.9


@pytest.mark.parametrize("kind,e", [("triaxial", (0.5, 0.8, 1.2)), ("revolution", (0.9, 0.9, 0.5))])
def test_fit_converges_from_a_perturbed_start(kind, e):
    # Eight evaluations of the analytic Jacobian reach the noise-limited fit.
    rng = np.random.default_rng(11)
    Y, _ = synth.sample_ellipsoid(rng, 2000, e)
    R = synth.random_rotation(rng)
    c = np.array([0.3, -0.2, 0.5])
    P = Y @ R.T + c + rng.normal(0, 0.002, (2000, 3))
    start = Primitive("ellipsoid", {"center": c + 0.03, "axes": R.T.copy(),
                                    "semi_axes": np.array(e) * [1.04, 0.97, 1.03], "kind": kind})
    fit = REGISTRY["ellipsoid"].fit(start, P, None)
    assert np.allclose(np.sort(fit.params["semi_axes"]), np.sort(e), rtol=3e-3)
    assert np.linalg.norm(fit.params["center"] - c) < 3e-3
    assert REGISTRY["ellipsoid"].distance(fit, P).mean() < 1.2 * 0.8 * 0.002
