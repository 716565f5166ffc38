"""The surface_of_revolution family (issue 3): profile dictionary, meridian distance, recognition
in random poses with families="all", simple surfaces of revolution staying simple, and a
user-supplied profile."""

from __future__ import annotations

import numpy as np
import pytest

from houghcad import segment, synth
from houghcad.families import REGISTRY, Primitive
from houghcad.families import revolution as rev


def _largest(result, type_: str):
    segs = [s for s in result.segments if s.type == type_]
    return max(segs, key=lambda s: len(s.indices)) if segs else None


def _dsc(indices: np.ndarray, truth: np.ndarray) -> float:
    inter = np.isin(indices, truth).sum()
    return 2.0 * inter / (len(indices) + len(truth))


@pytest.fixture
def restore_profiles():
    """Leave the profile dictionary and the active list as they were."""
    saved, active = dict(rev.PROFILES), list(rev.ACTIVE)
    yield
    rev.PROFILES.clear()
    rev.PROFILES.update(saved)
    rev.ACTIVE[:] = active


def test_builtin_profiles_and_their_linear_parameters():
    assert {"paper", "ellipse", "line", "circle"} <= set(rev.PROFILES)
    assert rev.PROFILES["paper"].linear == (True,)
    assert rev.PROFILES["ellipse"].linear == (True, True, True)
    # Degenerate profiles (simpler families cover them) are not voted by default.
    assert "line" not in rev.ACTIVE and "circle" not in rev.ACTIVE
    assert {"paper", "ellipse"} <= set(rev.ACTIVE)


def test_nonlinear_parameters_are_detected(restore_profiles):
    p = rev.register_profile("catenary", lambda u, a: a * np.cosh(u / a), lambda u, a: u, ("a",), [(0.1, 1.0)],
                             u_range=(-1.0, 1.0), active=False)
    assert p.linear == (False,)
    with pytest.raises(ValueError):
        rev.register_profile("too_many", lambda u, a, b, c: a + b * u, lambda u, a, b, c: c * u,
                             ("a", "b", "c"), [(0, 1)] * 3)


@pytest.mark.parametrize("profile,params,u_range", [("paper", (0.8,), (0.95, 1.45)),
                                                    ("ellipse", (1.0, 0.4, 0.6), (0.0, 2 * np.pi))])
def test_meridian_distance_is_euclidean(profile, params, u_range):
    rng = np.random.default_rng(0)
    fam = REGISTRY["surface_of_revolution"]
    prim = Primitive(fam.name, {"axis_point": np.zeros(3), "axis": np.array([0.0, 0.0, 1.0]), "profile": profile,
                                "theta": np.asarray(params, float)})
    P, N = synth.sample_revolution(rng, 500, profile, params, u_range)
    assert np.max(fam.distance(prim, P)) < 1e-6
    assert np.min(np.abs(np.einsum("ij,ij->i", fam.surface_normals(prim, P), N))) > 1 - 1e-6
    off = rng.uniform(-0.05, 0.05, len(P))
    assert np.allclose(fam.distance(prim, P + off[:, None] * N), np.abs(off), atol=1e-6)


def test_area_of_the_circle_profile_is_the_torus_area():
    R, r = 1.0, 0.3
    a = synth.SAMPLERS["surface_of_revolution"].area(profile="circle", params=(R, r), u_range=(0.0, 2 * np.pi))
    assert a == pytest.approx(4 * np.pi ** 2 * R * r, rel=1e-5)


@pytest.mark.parametrize("seed", [0, 1])
def test_surface_of_revolution_recognised_in_random_pose(seed):
    c = synth.single("surface_of_revolution", seed, n_points=4000, noise=0.005, missing=0.1)
    gt = c.primitives[0]["params"]
    r = segment(c.points, families="all", seed=0)
    s = _largest(r, "surface_of_revolution")
    assert s is not None, [(x.type, len(x.indices)) for x in r.segments]
    assert _dsc(s.indices, np.flatnonzero(c.labels == 0)) >= 0.9
    assert s.params["profile"] == gt["profile"]
    for k in rev.PROFILES[gt["profile"]].params:
        assert s.params[k] == pytest.approx(gt[k], rel=0.02), k
    assert abs(float(np.dot(s.params["axis"], gt["axis"]))) > np.cos(np.radians(2.0))
    assert s.mfe <= 0.01


@pytest.mark.parametrize("family,seed", [("cylinder", 0), ("cone", 0), ("torus", 3)])
def test_simple_surfaces_of_revolution_stay_simple(family, seed):
    # At noise 0.005 the simple pipeline itself carves some cones and tori into
    # sphere/cylinder patches; the complex families must change nothing there.
    c = synth.single(family, seed, n_points=4000, noise=0.005)
    r = segment(c.points, families="all", seed=0)
    cplx = [s for s in r.segments if s.type in ("surface_of_revolution", "ellipsoid")]
    assert sum(len(s.indices) for s in cplx) < 0.1 * len(c.points), [(x.type, len(x.indices)) for x in r.segments]
    ref = segment(c.points, families="simple", seed=0)
    s, s_ref = _largest(r, family), _largest(ref, family)
    n, n_ref = (len(x.indices) if x is not None else 0 for x in (s, s_ref))
    assert n >= n_ref - 0.05 * len(c.points)


def test_user_profile_from_sympy_is_recognised(restore_profiles):
    # A bellows: radius a (1.2 + 0.3 cos 2πu) along z = a u, affine in a.
    rev.register_profile("bellows", "a*(1.2 + 0.3*cos(2*pi*u))", "a*u", ["a"], [(0.05, 1.5)], u_range=(-0.5, 2.0))
    assert rev.PROFILES["bellows"].linear == (True,)
    rng = np.random.default_rng(7)
    a = 0.8
    P, _ = synth.sample_revolution(rng, 3000, "bellows", (a,), (0.0, 1.5))
    R, t, s = synth.random_pose(rng)
    P, _ = synth.apply_transform(P, None, R, t, s)
    P = P + rng.normal(scale=0.003 * np.linalg.norm(np.ptp(P, axis=0)), size=P.shape)
    r = segment(P, families="all", seed=0)
    seg = _largest(r, "surface_of_revolution")
    assert seg is not None and seg.params["profile"] == "bellows"
    assert len(seg.indices) >= 0.9 * len(P)
    assert seg.params["a"] == pytest.approx(a * s, rel=0.02)


def test_batched_three_by_three_solve_matches_the_pseudo_inverse():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(40, 30, 3, 3))
    b = rng.normal(size=(40, 30, 3))
    A[0, 0, 2] = A[0, 0, 1]  # singular: flagged, not solved
    x, ok = rev.solve_batched(A, b)
    x_ref = np.einsum("...cr,...r->...c", np.linalg.pinv(A), b)
    assert not ok[0, 0]
    assert ok.mean() > 0.99
    np.testing.assert_allclose(x[ok], x_ref[ok], atol=1e-6 * np.abs(x_ref[ok]).max())
    # Other shapes take the pseudo-inverse path.
    x2, ok2 = rev.solve_batched(A[..., :2, :], b[..., :2])
    assert x2.shape == (40, 30, 3) and ok2.shape == (40, 30)


def test_closed_surfaces_thinner_than_the_inlier_band_are_not_surfaces():
    # A noisy disc's points, above and below it, lie on a flat ring of ellipse profile
    # whose two sheets are within tau of each other (it fitted them to 0.4 σ, half the
    # noise): an envelope of the layer, rejected; so are a torus and an ellipsoid as thin.
    from types import SimpleNamespace

    ctx = SimpleNamespace(tau=0.024, max_radius=1.0)
    sor = REGISTRY["surface_of_revolution"]

    def ring(q):
        return Primitive("surface_of_revolution", {"axis_point": np.zeros(3), "axis": np.array([0.0, 0, 1]),
                                                   "profile": "ellipse", "theta": np.array([0.04, 0.034, q])})

    assert not sor.valid(ring(0.0075), ctx)
    assert sor.valid(ring(0.02), ctx)
    torus = REGISTRY["torus"]
    assert not torus.valid(Primitive("torus", {"center": np.zeros(3), "axis": np.array([0.0, 0, 1]),
                                               "major_radius": 0.3, "minor_radius": 0.01}), ctx)
    assert torus.valid(Primitive("torus", {"center": np.zeros(3), "axis": np.array([0.0, 0, 1]),
                                           "major_radius": 0.3, "minor_radius": 0.05}), ctx)
    ell = REGISTRY["ellipsoid"]

    def ellipsoid(c):
        return Primitive("ellipsoid", {"center": np.zeros(3), "axes": np.eye(3), "semi_axes": np.array([0.3, 0.2, c]),
                                       "axis": np.array([0.0, 0, 1])})

    assert not ell.valid(ellipsoid(0.01), ctx)
    assert ell.valid(ellipsoid(0.1), ctx)
