"""Fillets hidden between adjacent segments of noisy clouds (``houghcad.blend``)."""

from __future__ import annotations

import numpy as np
import pytest

import houghcad
from houghcad import pipeline, synth
from houghcad.corners import LR_MIN, _profile_sse, fit_fillet, profile_distance, section
from houghcad.evaluate import classification_measures
from houghcad.families import REGISTRY, Primitive

# A right-angled corner at the origin, rays along +x and +y.
C0 = np.zeros(2)
T0 = np.array([[1.0, 0.0], [0.0, 1.0]])
N0 = np.array([[0.0, 1.0], [1.0, 0.0]])
L0 = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # y = 0 (ray along x), x = 0 (ray along y)


def test_profile_distance_of_a_rounded_right_angle():
    r = 1.0
    phi = np.radians([0.0, 30.0, 45.0, 90.0])
    on = np.stack([1 - r * np.sin(phi), 1 - r * np.cos(phi)], axis=1)  # arc about (1, 1)
    d, arc = profile_distance(on, C0, T0, N0, r)
    assert np.allclose(d, 0, atol=1e-12)
    assert arc[1] and arc[2]
    # The sharp corner is √2 − 1 off the arc; far along a ray only the line counts.
    d, arc = profile_distance(np.array([[0.0, 0.0], [5.0, 0.1], [-0.2, 3.0]]), C0, T0, N0, r)
    assert d == pytest.approx([np.sqrt(2) - 1, 0.1, 0.2])
    assert arc.tolist() == [True, False, False]
    # r = 0: the sharp corner itself.
    d, arc = profile_distance(np.array([[0.3, 0.4], [-1.0, -1.0]]), C0, T0, N0, 0.0)
    assert d == pytest.approx([0.3, np.sqrt(2)]) and not arc.any()


def _corner_points(r: float, sigma: float, seed: int, n_side: int = 1500, length: float = 40.0):
    """Noisy 2-D samples of the right-angled corner rounded with radius r (r = 0: sharp)."""
    rng = np.random.default_rng(seed)
    s = rng.uniform(r, length, n_side)
    A = np.stack([s, np.zeros(n_side)], 1)
    B = np.stack([np.zeros(n_side), s], 1)
    if r > 0:
        m = int(n_side * (np.pi / 2 * r) / (length - r))
        phi = rng.uniform(0, np.pi / 2, m)
        arc = np.stack([r - r * np.sin(phi), r - r * np.cos(phi)], 1)
        h = arc[:, 0] >= arc[:, 1]  # each half of the arc went to the nearer segment
        A, B = np.vstack([A, arc[h]]), np.vstack([B, arc[~h]])
    # Noise along the surface normal, which is what a scanner's noise amounts to at these scales.
    A[:, 1] += rng.normal(0, sigma, len(A)) * (A[:, 0] >= r)
    B[:, 0] += rng.normal(0, sigma, len(B)) * (B[:, 1] >= r)
    for X in (A, B):
        on_arc = (X[:, 0] < r) & (X[:, 1] < r)
        if on_arc.any():
            v = X[on_arc] - r
            X[on_arc] += v / np.linalg.norm(v, axis=1, keepdims=True) * rng.normal(0, sigma, (on_arc.sum(), 1))
    return A, B


def test_profile_sums_of_squares_are_the_profile_distances():
    # The radius grid's numba sums against the distances they stand for, at corners of
    # 30-160 degrees with points on every side of them.
    rng = np.random.default_rng(3)
    for deg in (30, 75, 90, 120, 160):
        a = np.radians(deg)
        t = np.array([[1.0, 0.0], [np.cos(a), np.sin(a)]])
        n = np.array([[0.0, 1.0], [np.sin(a), -np.cos(a)]])
        C = rng.normal(size=2)
        X = C + rng.normal(scale=2.0, size=(400, 2))
        radii = np.array([0.05, 0.4, 1.0, 2.5])
        want = [np.sum(profile_distance(X, C, t, n, r)[0] ** 2) for r in radii]
        assert _profile_sse(X, C, t, n, radii) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_fillet_finds_a_fillet_of_six_sigma(seed):
    A, B = _corner_points(6.0, 1.0, seed)
    fit = fit_fillet(A, B, L0, 1.0, r_cap=30.0)
    assert fit.radius == pytest.approx(6.0, rel=0.15)
    assert fit.lr > LR_MIN
    assert np.allclose(fit.corner, 0, atol=0.3)
    assert len(fit.taken) == 0 and fit.band.shape == (len(A) + len(B),)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_fillet_reaches_a_fillet_wider_than_half_its_narrow_face(seed):
    # A rim rounded on both edges: the flat between the fillets (0.6 r here) is narrower than
    # either fillet, so half the rim's extent stops short of the tangent point at r. The
    # radius found at the band's end sends the fit to the rim's far end.
    A, B = _corner_points(6.0, 0.2, seed)
    B = B[B[:, 1] <= 6.0 + 3.6]
    fit = fit_fillet(A, B, L0, 0.2, r_cap=30.0)
    assert fit.radius == pytest.approx(6.0, rel=0.05)
    assert fit.r_max > 6.0 and fit.lr > LR_MIN
    # A sharp corner beside the same narrow face stays sharp, whichever band is tried.
    A, B = _corner_points(0.0, 0.2, seed)
    fit = fit_fillet(A, B[B[:, 1] <= 3.6], L0, 0.2, r_cap=30.0)
    assert fit.lr < LR_MIN


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_fillet_leaves_a_sharp_corner_sharp(seed):
    A, B = _corner_points(0.0, 1.0, seed)
    fit = fit_fillet(A, B, L0, 1.0, r_cap=30.0)
    assert fit.lr < LR_MIN and fit.radius < 1.5


def test_section_of_two_planes_and_of_a_plane_with_a_coaxial_cylinder():
    plane, cyl = REGISTRY["plane"], REGISTRY["cylinder"]
    top = Primitive("plane", {"normal": np.array([0.0, 0, 1]), "offset": 1.0})
    side = Primitive("plane", {"normal": np.array([0.0, 1, 0]), "offset": 2.0})
    sec = section(plane, top, plane, side, tol=0.01)
    assert sec.kind == "edge"
    # The edge (y = 2, z = 1) is the corner of the two lines.
    edge = sec.to2d(np.array([[5.0, 2.0, 1.0], [-3.0, 2.0, 1.0]]))
    corner = np.linalg.solve(sec.lines[:, :2], sec.lines[:, 2])
    assert np.allclose(edge, corner, atol=1e-12)
    boss = Primitive("cylinder", {"axis_point": np.array([1.0, 1, 0]), "axis": np.array([0.0, 0, 1]), "radius": 0.5})
    sec = section(plane, top, cyl, boss, tol=0.01)
    assert sec.kind == "axis"
    rim = sec.to2d(np.array([[1.5, 1.0, 1.0], [1.0, 0.5, 1.0]]))
    assert np.allclose(rim, np.linalg.solve(sec.lines[:, :2], sec.lines[:, 2]), atol=1e-12)
    # Parallel planes, or an axis off the plane's normal, make no such corner.
    assert section(plane, top, plane, Primitive("plane", {"normal": np.array([0.0, 0, 1]), "offset": 3.0}), 0.01) is None
    tilted = Primitive("cylinder", {"axis_point": np.array([1.0, 1, 0]), "axis": np.array([0.0, 0.2, 1]) / np.hypot(0.2, 1),
                                    "radius": 0.5})
    assert section(plane, top, cyl, tilted, tol=0.01) is None


def _face_dsc(cloud, res, name):
    k = next(i for i, p in enumerate(cloud.primitives) if p["name"] == name)
    m = classification_measures([np.asarray(f) for f in res.faces()], cloud.segments(), len(cloud.points),
                                per_segment=True)
    return float(m["per_segment"]["DSC"][k])


@pytest.fixture(scope="module")
def noisy_blocks():
    """The filleted block at σ = 0.5 % of the diagonal, seeds 0-2, segmented."""
    out = []
    for seed in range(3):
        cloud = synth.PARTS["filleted_block"](seed=seed, n_points=12000, noise=0.005)
        out.append((cloud, houghcad.segment(cloud.points, seed=0)))
    return out


def test_noisy_boss_fillet_is_recognised(noisy_blocks):
    # The boss's concave torus fillet (minor radius 5-6 σ) sags at most 1.5-1.8 σ off the
    # top face and the boss: inside both inlier bands, it used to go to them (DSC 0.11-0.15).
    # Its boundaries are drawn by the rounded corner (boundaries.surface_distance): nearest
    # unbounded surfaces handed a third of it back to its faces (DSC 0.60-0.64, edge
    # fillet 0.63-0.70; now 0.88-0.92 and 0.93-0.94).
    for cloud, res in noisy_blocks:
        assert _face_dsc(cloud, res, "boss fillet") >= 0.8
        assert _face_dsc(cloud, res, "edge fillet") >= 0.8
        tori = [s for s in res.segments if s.type == "torus"]
        assert len(tori) == 1
        true = next(p for p in cloud.primitives if p["name"] == "boss fillet")["params"]
        assert tori[0].params["minor_radius"] == pytest.approx(true["minor_radius"], rel=0.3)


def test_clean_sparse_boss_fillet_is_recognised(monkeypatch):
    # Exact samples, 2,500 points: the boss's torus fillet is two or three spacings wide,
    # too narrow for any vote; its points went partly to the top face and the boss and
    # stayed partly free (DSC 0.23-0.95, two seeds of four below 0.8). Tested against the
    # sharp corner between its two faces, it is found on every seed (0.91-0.96).
    clouds = [synth.PARTS["filleted_block"](seed=seed, n_points=2500) for seed in range(4)]
    found = [_face_dsc(c, houghcad.segment(c.points, seed=0), "boss fillet") for c in clouds]
    monkeypatch.setattr(pipeline, "find_fillets", lambda *a, **k: 0)
    hidden = [_face_dsc(c, houghcad.segment(c.points, seed=0), "boss fillet") for c in clouds]
    assert min(found) >= 0.9
    assert min(hidden) < 0.5


def test_sharp_edges_get_no_fillet(monkeypatch):
    # Box, hole and slot, every edge sharp (plane-plane and plane-hole corners):
    # the output is the same with and without the fillet test.
    runs = []
    for seed in range(2):
        cloud = synth.PARTS["block_with_hole_and_slot"](seed=seed, n_points=12000, noise=0.005)
        runs.append((cloud, houghcad.segment(cloud.points, seed=0)))
    monkeypatch.setattr(pipeline, "find_fillets", lambda *a, **k: 0)
    for cloud, res in runs:
        off = houghcad.segment(cloud.points, seed=0)
        assert [(s.type, s.indices.tolist()) for s in res.segments] == [(s.type, s.indices.tolist()) for s in off.segments]


@pytest.mark.parametrize("seed", range(6))
def test_points_within_reach_of_a_segment_are_the_brute_force_ones(seed):
    """The voxel shortcut of the fillet pass's reach test gives each point's exact answer."""
    from types import SimpleNamespace

    from houghcad.blend import _Near

    rng = np.random.default_rng(seed)
    P = np.vstack([rng.normal(size=(1500, 3)) * rng.uniform(0.1, 0.5, 3), rng.random((500, 3)) * 2 - 1])
    segs = [SimpleNamespace(indices=np.sort(rng.choice(len(P), 700, replace=False))) for _ in range(2)]
    reach = float(rng.uniform(0.2, 0.8))
    near = _Near(segs, P, reach)
    for i, k in ((0, 1), (1, 0)):
        d = np.linalg.norm(P[segs[i].indices][:, None] - P[segs[k].indices][None], axis=2).min(axis=1)
        assert np.array_equal(near.within(i, k), segs[i].indices[d <= reach])
