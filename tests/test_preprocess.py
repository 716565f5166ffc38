"""Tests of houghcad.preprocess: the similarity, standard position, normal estimation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from houghcad import synth
from houghcad.preprocess import Similarity, pca_normals, preprocess, rotation_to_z, voting_normals
import houghcad.preprocess as preprocess_module


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise angles (n,) between unoriented unit directions a, b (n, 3), degrees."""
    c = np.abs(np.einsum("ij,ij->i", a, b))
    return np.degrees(np.arccos(np.clip(c, 0.0, 1.0)))


def _normal_errors(cloud: synth.SynthCloud, pre) -> np.ndarray:
    """Angle (deg) between estimated normals and the true ones, in the standard frame."""
    return _angles_deg(pre.normals, pre.transform.dirs(cloud.normals))


# ---------------------------------------------------------------------------- Similarity


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_similarity_round_trip(seed):
    rng = np.random.default_rng(seed)
    T = Similarity(center=rng.uniform(-5, 5, 3), R=synth.random_rotation(rng), scale=float(rng.uniform(0.1, 10)))
    x = rng.normal(size=(50, 3)) * 3
    v = rng.normal(size=(50, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    np.testing.assert_allclose(T.inv_points(T.points(x)), x, atol=1e-12)
    np.testing.assert_allclose(T.points(T.inv_points(x)), x, atol=1e-10)
    np.testing.assert_allclose(T.inv_dirs(T.dirs(v)), v, atol=1e-12)
    # Directions keep their length, lengths scale by `scale`, the centre goes to the origin.
    np.testing.assert_allclose(np.linalg.norm(T.dirs(v), axis=1), 1.0)
    d_world = np.linalg.norm(x[1:] - x[:-1], axis=1)
    d_std = np.linalg.norm(T.points(x)[1:] - T.points(x)[:-1], axis=1)
    np.testing.assert_allclose(d_std, T.scale * d_world)
    for L in d_world[:5]:
        assert T.inv_length(T.scale * L) == pytest.approx(L)
    np.testing.assert_allclose(T.points(T.center[None]), 0.0, atol=1e-12)
    # A point moved along a direction stays consistent: T(x + t v) = T(x) + t s T.dirs(v).
    np.testing.assert_allclose(T.points(x + 0.7 * v), T.points(x) + 0.7 * T.scale * T.dirs(v), atol=1e-10)


def test_rotation_to_z_is_a_rotation_with_d_as_third_row():
    rng = np.random.default_rng(0)
    for _ in range(20):
        d = rng.normal(size=3)
        R = rotation_to_z(d, x_hint=rng.normal(size=3))
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(R[2], d / np.linalg.norm(d))
    # Along a coordinate axis too (the default x hint is then degenerate or not).
    for d in np.eye(3):
        R = rotation_to_z(d)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(R[2], d)


# ---------------------------------------------------------------------------- standard position


@pytest.mark.parametrize("part,seed,noise", [
    ("block_with_hole_and_slot", 0, 0.0),
    ("block_with_hole_and_slot", 1, 0.002),
    ("filleted_block", 2, 0.0),
    ("plate_with_holes", 0, 0.002),
])
def test_most_voted_normal_direction_goes_to_z(part, seed, noise):
    cloud = synth.PARTS[part](seed=seed, n_points=5000, noise=noise)  # random pose
    pre = preprocess(cloud.points)
    sizes = [len(s) for s in cloud.segments()]
    big = cloud.primitives[int(np.argmax(sizes))]
    assert big["type"] == "plane"
    n_std = pre.transform.dirs(np.asarray(big["params"]["normal"])[None])[0]
    assert np.degrees(np.arccos(min(1.0, abs(n_std[2])))) <= 2.0
    # Before preprocessing the pose is random: the test is not trivially true.
    n_world = np.asarray(big["params"]["normal"])
    assert abs(n_world[2]) < np.cos(np.radians(2.0))


@pytest.mark.parametrize("family,seed", [("cylinder", 0), ("torus", 1), ("plane", 2)])
def test_points_in_unit_cube_centred_at_the_barycentre(family, seed):
    cloud = synth.single(family, seed, n_points=3000, noise=0.002)
    pre = preprocess(cloud.points)
    assert pre.points.shape == cloud.points.shape
    np.testing.assert_allclose(pre.points.mean(axis=0), 0.0, atol=1e-12)
    assert np.ptp(pre.points, axis=0).max() == pytest.approx(1.0)
    assert np.abs(pre.points).max() <= 1.0
    # The kept transform maps the input onto the standard points, and back.
    np.testing.assert_allclose(pre.transform.points(cloud.points), pre.points, atol=1e-12)
    np.testing.assert_allclose(pre.transform.inv_points(pre.points), cloud.points,
                               atol=1e-9 * np.abs(cloud.points).max())
    np.testing.assert_allclose(np.linalg.norm(pre.normals, axis=1), 1.0)
    assert pre.diagonal == pytest.approx(float(np.linalg.norm(np.ptp(pre.points, axis=0))))
    d, _ = pre.tree.query(pre.points[:10])
    np.testing.assert_allclose(d, 0.0)


# ---------------------------------------------------------------------------- normals


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pca_normals_on_a_clean_plane_are_exact(seed):
    cloud = synth.single("plane", seed, n_points=4000)
    pre = preprocess(cloud.points, method="pca")
    assert pre.normals_method == "pca"
    assert _normal_errors(cloud, pre).max() <= 1e-4


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_pca_normals_on_a_clean_cylinder_within_one_degree(seed):
    cloud = synth.single("cylinder", seed, n_points=4000)
    pre = preprocess(cloud.points, method="pca")
    err = _normal_errors(cloud, pre)
    # Random sampling makes k-NN neighbourhoods lopsided, which tilts PCA normals on curved
    # surfaces by a fraction of (neighbourhood radius / radius): typical error < 1°, a tail of 2–3°.
    assert np.median(err) <= 1.0
    assert err.mean() <= 1.0
    assert np.percentile(err, 99) <= 4.0


def test_pca_normals_function_returns_sorted_eigenvalues():
    rng = np.random.default_rng(0)
    P, N = synth.sample_plane_patch(rng, 500, (1.0, 1.0))
    R = synth.random_rotation(rng)
    P, N = synth.apply_transform(P, N, R, np.zeros(3))
    _, nbr = cKDTree(P).query(P, k=12)
    nrm, ev = pca_normals(P, nbr)
    assert np.all(np.diff(ev, axis=1) >= -1e-15)
    assert np.abs(ev[:, 0]).max() < 1e-12  # flat: no spread along the normal
    assert _angles_deg(nrm, N).max() < 1e-4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_voting_normals_on_a_noisy_plane_within_a_few_degrees(seed):
    cloud = synth.single("plane", seed, n_points=4000, noise=0.001)
    pre = preprocess(cloud.points, method="voting")
    assert pre.normals_method == "voting"
    err = _normal_errors(cloud, pre)
    assert np.median(err) <= 4.0
    assert np.percentile(err, 90) <= 8.0


@pytest.mark.xfail(strict=False, reason=(
    "voting normals are worse than PCA on noisy smooth surfaces (so `auto` widens PCA instead); measured "
    "there: plane noise=0.001, seeds 0-2, median/90th-pct error voting 3.4°/7.4°, 3.4°/7.1°, 3.4°/7.3° "
    "vs pca 2.0°/3.8°, 2.1°/4.1°, 2.0°/3.8° (noise=0.002: 8.1°/19.0° vs 3.9°/8.0°)"))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_voting_normals_not_worse_than_pca_on_a_noisy_plane(seed):
    cloud = synth.single("plane", seed, n_points=4000, noise=0.001)
    err_v = _normal_errors(cloud, preprocess(cloud.points, method="voting"))
    err_p = _normal_errors(cloud, preprocess(cloud.points, method="pca"))
    assert np.median(err_v) <= 1.25 * np.median(err_p)


def _roof(seed: int, n: int = 3000, angle_deg: float = 90.0):
    """Two square plane patches (synth samplers) meeting at a sharp edge along the x-axis."""
    rng = np.random.default_rng(seed)
    p1, n1 = synth.sample_plane_patch(rng, n, (1.0, 1.0))
    p2, n2 = synth.sample_plane_patch(rng, n, (1.0, 1.0))
    shift = np.array([0.0, 0.5, 0.0])  # both patches: y in [0, 1], the edge is y = z = 0
    t = np.radians(angle_deg)
    Rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    p1, n1 = synth.apply_transform(p1 + shift, n1, np.eye(3), np.zeros(3))
    p2, n2 = synth.apply_transform(p2 + shift, n2, Rx, np.zeros(3))
    R, tr, s = synth.random_pose(rng)
    P, N = synth.apply_transform(np.vstack([p1, p2]), np.vstack([n1, n2]), R, tr, s)
    edge_dist = np.linalg.norm(np.vstack([p1, p2])[:, 1:], axis=1) * s
    return P, R @ n1[0], R @ n2[0], edge_dist


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_voting_normals_at_a_sharp_edge_pick_one_side(seed):
    P, na, nb, edge_dist = _roof(seed)
    tree = cKDTree(P)
    _, nbr = tree.query(P, k=16)
    spacing = np.median(tree.query(P, k=2)[0][:, 1])
    edge = edge_dist < 2.0 * spacing  # neighbourhoods straddle the edge
    assert edge.sum() > 50

    def side_error(N):  # angle to the closer of the two faces' normals
        c = np.maximum(np.abs(N @ na), np.abs(N @ nb))
        return np.degrees(np.arccos(np.clip(c, 0, 1)))

    vote = side_error(voting_normals(P, nbr, seed=seed))[edge]
    pca = side_error(pca_normals(P, nbr)[0])[edge]
    assert np.median(vote) <= 3.0
    assert (vote <= 5.0).mean() >= 0.7
    # PCA averages the two sides there: the case really discriminates.
    assert np.median(pca) >= 15.0
    assert (pca <= 5.0).mean() <= 0.1


def _chamfer(seed: int, rows: float = 2.5, h: float = 0.01):
    """Two wide faces at a right angle joined by a 45° chamfer ``rows`` spacings
    wide: jittered grids of spacing ``h`` in a random pose. Returns the points,
    the chamfer's mask and its normal (world)."""
    rng = np.random.default_rng(seed)
    w = rows * h
    a = w / np.sqrt(2.0)
    y = np.arange(0.0, 0.6, h)

    def strip(u0, u1, f):  # grid over u (profile) x y, mapped to (x, z) by f
        u = np.arange(u0, u1, h)
        U, Y = np.meshgrid(u, y, indexing="ij")
        U = U + rng.uniform(-0.2, 0.2, U.shape) * h
        x, z = f(U.ravel())
        return np.column_stack([x, Y.ravel() + rng.uniform(-0.2, 0.2, U.size) * h, z])

    top = strip(-0.4, 0.0, lambda u: (u, np.zeros_like(u)))
    cham = strip(h / 2, w, lambda t: (t / np.sqrt(2.0), -t / np.sqrt(2.0)))
    side = strip(h, 0.4, lambda t: (np.full_like(t, a), -a - t))
    P = np.vstack([top, cham, side])
    mask = np.r_[np.zeros(len(top), bool), np.ones(len(cham), bool), np.zeros(len(side), bool)]
    R, t, s = synth.random_pose(rng)
    n = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
    return s * P @ R.T + t, mask, R @ n


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_anchored_voting_keeps_a_narrow_face_own_plane(seed):
    # Two or three rows of chamfer between two wide faces: free triples mostly
    # span a wide face and vote its plane; triples through the point itself
    # agree only on the chamfer's.
    P, cham, n = _chamfer(seed)
    _, nbr = cKDTree(P).query(P, k=16)
    err = {a: _angles_deg(voting_normals(P, nbr[cham], seed=seed, anchored=a), np.broadcast_to(n, (cham.sum(), 3)))
           for a in (True, False)}
    # Two rows: half the points or more get the chamfer's plane exactly (the
    # others, at its edges, a wide face's), free triples a wide face's.
    assert np.median(err[True]) <= 1.0 and (err[True] <= 10.0).mean() >= 0.5
    assert np.median(err[False]) >= 10.0
    # Three rows: nearly all of them.
    P, cham, n = _chamfer(seed, rows=3.5)
    _, nbr = cKDTree(P).query(P, k=16)
    e3 = _angles_deg(voting_normals(P, nbr[cham], seed=seed, anchored=True), np.broadcast_to(n, (cham.sum(), 3)))
    assert (e3 <= 10.0).mean() >= 0.9


@pytest.mark.parametrize("seed", [0, 1])
def test_auto_normals_on_a_clean_groove_wall(seed):
    # The shaft's groove walls are annuli a few spacings wide between two
    # cylinders: PCA averages them with their neighbours, the crease points'
    # voted normals keep them.
    cloud = synth.shaft_with_groove(seed=seed, n_points=12000)
    walls = np.isin(cloud.labels, [k for k, p in enumerate(cloud.primitives) if p["name"].startswith("groove wall")])
    auto, pca = preprocess(cloud.points, seed=0), preprocess(cloud.points, method="pca", seed=0)
    assert auto.normals_method == "pca"
    e_auto, e_pca = _normal_errors(cloud, auto)[walls], _normal_errors(cloud, pca)[walls]
    assert np.percentile(e_auto, 75) <= 6.0
    assert np.median(e_pca) >= 15.0


@pytest.mark.parametrize("family,seed", [("cylinder", 0), ("sphere", 1), ("torus", 2), ("cone", 0)])
def test_auto_normals_are_pca_on_a_clean_smooth_surface(family, seed):
    # A local quadric explains curvature (measured: no point of these faces is
    # taken for a crease, even along the patch's boundary).
    cloud = synth.single(family, seed, n_points=4000)
    auto, pca = preprocess(cloud.points, seed=0), preprocess(cloud.points, method="pca", seed=0)
    assert np.all(auto.normals == pca.normals, axis=1).mean() >= 0.99


@pytest.mark.parametrize("family,seed", [("plane", 0), ("cylinder", 1), ("sphere", 2), ("torus", 0)])
def test_auto_widens_the_neighbourhood_on_a_noisy_cloud(family, seed):
    # On noisy clouds `auto` keeps PCA but with more neighbours: measured better
    # than the voting estimate there (see test_voting_normals_not_worse...). As
    # many as the noise needs: at 0.3 % of the diagonal, fewer than 64.
    cloud = synth.single(family, seed, n_points=4000, noise=0.003)
    pre = preprocess(cloud.points)
    assert pre.normals_method.startswith("pca-k") and 16 < int(pre.normals_method[5:]) < 64
    err = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", pre.transform.inv_dirs(pre.normals), cloud.normals)), 0, 1)))
    assert np.median(err) <= 5.0


@pytest.mark.parametrize("make", [
    pytest.param(lambda: synth.single("plane", 0, n_points=4000), id="plane"),
    pytest.param(lambda: synth.single("cylinder", 1, n_points=4000), id="cylinder"),
    pytest.param(lambda: synth.single("torus", 2, n_points=4000), id="torus"),
    pytest.param(lambda: synth.block_with_hole_and_slot(0, n_points=5000), id="block"),
    pytest.param(lambda: synth.filleted_block(0, n_points=5000), id="filleted_block"),
    pytest.param(lambda: synth.plate_with_holes(0, n_points=5000), id="plate"),
])
def test_auto_chooses_pca_on_a_clean_cloud(make):
    cloud = make()
    assert preprocess(cloud.points).normals_method == "pca"


def test_crease_points_are_the_voted_ones_on_a_clean_part_only():
    cloud = synth.block_with_hole_and_slot(0, n_points=5000)
    auto, pca = preprocess(cloud.points, seed=0), preprocess(cloud.points, method="pca", seed=0)
    assert auto.crease is not None and auto.crease.shape == (5000,)
    dot = np.einsum("ij,ij->i", auto.transform.inv_dirs(auto.normals), pca.transform.inv_dirs(pca.normals))
    voted = np.abs(dot) < 1 - 1e-9
    assert np.array_equal(voted, auto.crease & voted) and voted.sum() >= 0.9 * auto.crease.sum()
    assert 0 < auto.crease.mean() < 0.5
    # Noisy clouds keep PCA normals, given normals are trusted: no crease points.
    noisy = synth.block_with_hole_and_slot(0, n_points=5000, noise=0.003)
    assert preprocess(noisy.points).crease is None
    assert preprocess(cloud.points, cloud.normals).crease is None


def test_a_cloud_read_as_noisy_has_no_crease_points():
    """Between the noise policy's threshold and the one that widens PCA, noise keeps every
    neighbourhood off its local quadric: the crease test would flag nearly every point."""
    from houghcad.noise import NOISY_SPACINGS

    cloud = synth.gear_like(seed=0, n_points=100_000, noise=0.0005)
    pre = preprocess(cloud.points, seed=0)
    assert pre.noise >= NOISY_SPACINGS * pre.spacing and pre.normals_method == "pca"
    assert pre.crease is None
    pca = preprocess(cloud.points, method="pca", seed=0)
    np.testing.assert_array_equal(pre.normals, pca.normals)
    # Read as clean on request, the same cloud votes its crease normals: nearly all of them.
    clean = preprocess(cloud.points, seed=0, noise="clean")
    assert clean.crease is not None and clean.crease.mean() > 0.9


def test_input_normals_are_used_as_given():
    cloud = synth.single("cylinder", 0, n_points=2000, noise=0.003)
    pre = preprocess(cloud.points, cloud.normals)
    assert pre.normals_method == "input"
    assert _normal_errors(cloud, pre).max() < 1e-4  # arccos near 1: ~1e-6° of rounding
    with pytest.raises(ValueError):
        preprocess(cloud.points, method="nonsense")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sparse_clean_plate_is_not_taken_for_noise(seed):
    # At 1500 points the plate is about two spacings thick: every 8- and
    # 16-neighbourhood holds both faces, and the residual-based estimate read
    # about 2 spacings of noise (then the wide-neighbourhood normals blurred
    # the holes away). Most 4-point neighbourhoods stay on one face.
    cloud = synth.plate_with_holes(seed=seed, n_points=1500, noise=0.0)
    pre = preprocess(cloud.points, seed=0)
    assert pre.noise < 0.05 * pre.spacing
    assert pre.normals_method == "pca"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_plate_thinner_than_the_spacing_is_not_taken_for_noise(seed):
    # Two exact faces half a spacing apart interleave: most 4-point neighbourhoods hold both,
    # and every residual-based estimate read 0.4 spacings of noise (the cloud then followed
    # the noisy policy). A tenth of the quadruples still lie on one face, to rounding.
    rng = np.random.default_rng(seed)
    n = 1500
    P = np.column_stack([rng.uniform(0, 1, n), rng.uniform(0, 1, n), np.zeros(n)])
    P[n // 2:, 2] = 0.012  # the spacing is about 0.018
    pre = preprocess(P, seed=0)
    assert pre.noise < 0.01 * pre.spacing
    assert pre.normals_method == "pca"


@pytest.mark.parametrize("name", ["block_with_hole_and_slot", "filleted_block", "bracket"])
def test_exact_samples_are_told_from_noise_of_a_twentieth_of_a_spacing(name):
    # Sampled CAD models lie on their faces to rounding, and their noise estimate reads the
    # curvature and thin features; noise of 0.05-0.07 spacings already lifts the quadruples'
    # residuals off rounding.
    n = 4000 if name == "bracket" else 12000
    assert preprocess(synth.PARTS[name](seed=0, n_points=n, noise=0.0).points).exact
    assert not preprocess(synth.PARTS[name](seed=0, n_points=n, noise=0.0003).points).exact


@pytest.mark.parametrize("rows, incidence", [(2.0, 0.0), (3.0, 0.0), (2.0, 50.0), (1.0, 50.0)])
def test_noise_of_a_scan_sampled_in_rows_is_read(rows: float, incidence: float):
    """A plane scanned in rows ``rows`` times further apart than the points along them, with
    noise along the scanner's ray (``incidence`` degrees from the normal, tilted along the rows):
    a point's 3 nearest neighbours lie on its row, coplanar with it whatever the noise, and the
    cloud read as an exact sample (σ 0, every surface cut into slivers). Its noise is the ray
    noise's normal part."""
    rng = np.random.default_rng(0)
    x, y = np.meshgrid(np.arange(0.0, 1.0, 0.01), np.arange(0.0, 1.0, 0.01 * rows))
    P = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    ray = np.array([np.sin(np.radians(incidence)), 0.0, np.cos(np.radians(incidence))])
    sigma = 0.003
    P = P + rng.normal(0.0, sigma, (len(P), 1)) * ray
    P = P @ synth.random_rotation(rng).T
    pre = preprocess(P)
    assert not pre.exact
    normal_part = sigma * np.cos(np.radians(incidence))
    assert 0.7 < pre.noise / pre.transform.scale / normal_part < 1.3


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_low_noise_on_small_faces_is_read_near_its_value(seed):
    # The bracket's narrow faces put two surfaces in 8 and 16 neighbours: at σ = 0.08 spacings
    # they read 2.2-2.8 σ, past the noisy policy's threshold. The quadruple residuals' low
    # quantile reads 1.3 σ.
    from houghcad.noise import NOISY_SPACINGS

    cloud = synth.bracket(seed=seed, n_points=4000, noise=0.0005)
    pre = preprocess(cloud.points, seed=0)
    sigma = 0.0005 * cloud.diagonal()
    assert 0.7 < pre.noise / pre.transform.scale / sigma < 1.6
    assert pre.noise < NOISY_SPACINGS * pre.spacing


@pytest.mark.parametrize("name, noise", [("bracket", 0.002), ("plate_with_holes", 0.002), ("gear_like", 0.005)])
def test_noise_estimate_of_a_noisy_part_with_small_features(name: str, noise: float):
    # 64 neighbours straddle the thin walls and small features: their residual alone read the
    # bracket's noise as 4 sigma, its faces' rows then fell inside one inlier band.
    from houghcad import synth

    cloud = synth.PARTS[name](seed=0, noise=noise)
    pre = preprocess(cloud.points, noise="noisy")
    sigma = noise * cloud.diagonal()  # world units
    assert 0.7 < pre.noise / pre.transform.scale / sigma < 1.8  # 64 neighbours alone: up to 4.2


@pytest.mark.parametrize("anchored", [False, True])
def test_voting_normals_do_not_depend_on_threads_or_chunks(anchored):
    """The triples are drawn in one stream, in order, and the threads only share the voting:
    the same normals for any number of threads, and for chunks of draws cut anywhere else than
    the stream's (the draws of a chunk are the same)."""
    cloud = synth.block_with_hole_and_slot(seed=1, n_points=5000)
    P = cloud.points
    nbr = cKDTree(P).query(P, k=16)[1]
    one = voting_normals(P, nbr, seed=4, chunk=3000, anchored=anchored)
    np.testing.assert_array_equal(one, voting_normals(P, nbr, seed=4, chunk=3000, anchored=anchored, workers=2))
    np.testing.assert_array_equal(one[:3000], voting_normals(P, nbr[:3000], seed=4, chunk=3000, anchored=anchored))


def test_neighbour_tables_are_the_per_point_queries_and_stay_with_their_points():
    from dataclasses import replace

    pre = preprocess(synth.block_with_hole_and_slot(seed=0, n_points=3000).points)
    r = 2.5 * pre.spacing
    nb, near = pre.neighbours_within(8, r, workers=2)
    assert nb.dtype == np.int32 and nb.shape == near.shape == (3000, 8)
    assert pre.neighbours_within(8, r) is not None and pre.neighbours_within(8, r)[0] is nb  # read once
    for i in (0, 17, 2999):
        d, j = pre.tree.query(pre.points[i], k=8, distance_upper_bound=r)
        np.testing.assert_array_equal(near[i], np.isfinite(d))
        np.testing.assert_array_equal(nb[i][near[i]], j[np.isfinite(d)])
    assert 0 < near.sum() < near.size
    # Another state of the points (dataclasses.replace) reads its own tables.
    moved = replace(pre, points=pre.points * 2)
    assert moved.neighbours_within(8, r)[0] is not nb


def test_noisy_normals_take_as_many_neighbours_as_the_noise_needs(monkeypatch):
    # The shaft's groove walls are a few spacings wide. At σ = 0.2 % of the diagonal the
    # noise needs about 40 neighbours, and 64 reach across the walls into the shaft and the
    # groove's bottom: the walls' normals come out further from the truth (measured median
    # 38° against 46°), while over the whole part 64 average the noise a little better
    # (2.5° against 3.3°).
    cloud = synth.PARTS["shaft_with_groove"](seed=0, noise=0.002)
    names = [p["name"] for p in cloud.primitives]
    walls = np.concatenate([s for s, n in zip(cloud.segments(), names) if "groove wall" in n])

    def errors() -> tuple[str, float, float]:
        pre = preprocess(cloud.points)
        cos = np.abs(np.einsum("ij,ij->i", pre.transform.inv_dirs(pre.normals), cloud.normals))
        err = np.degrees(np.arccos(np.clip(cos, 0, 1)))
        return pre.normals_method, float(np.median(err[walls])), float(np.median(err))

    used, walls_err, all_err = errors()
    monkeypatch.setattr(preprocess_module, "NOISE_NEIGHBOURS_PER_SPACING", 10_000)
    wide, walls_wide, all_wide = errors()
    assert wide == "pca-k64" and used.startswith("pca-k") and int(used[5:]) < 56
    assert walls_err < walls_wide - 5
    assert all_err < 4.0


def test_link_scale_reads_how_much_sparser_the_sampling_is_around_each_point():
    """Half a plane 4 times sparser (spacing twice as wide) than the other: scale about 2 there,
    1 on the dense half, and never below 1."""
    rng = np.random.default_rng(1)
    xy = np.vstack([rng.random((6000, 2)) * [0.5, 1.0], rng.random((1500, 2)) * [0.5, 1.0] + [0.5, 0.0]])
    pre = preprocess(np.c_[xy, np.zeros(len(xy))], sampling_scales=True)
    s = pre.link_scale
    assert s.dtype == np.float32 and s.shape == (len(xy),) and s.min() >= 1.0
    assert np.median(s[:6000][xy[:6000, 0] < 0.4]) == 1.0
    assert 1.7 < np.median(s[6000:][xy[6000:, 0] > 0.6]) < 2.3


def test_an_interrupt_lets_the_running_chunks_finish_and_drops_the_rest():
    # Ctrl-C while threads share the rows: the interrupt goes on only once no thread is left
    # inside a chunk (one still running while the interpreter exits crashed it).
    import _thread
    import time

    from houghcad.normals import ROWS, by_rows

    done = []

    def chunk(rows: slice) -> int:
        if rows.start == 0:
            _thread.interrupt_main()
        time.sleep(0.05)
        done.append(rows.start)
        return rows.start

    with pytest.raises(KeyboardInterrupt):
        by_rows(chunk, 200 * ROWS, workers=2)
    finished = len(done)
    assert 0 < finished < 200  # the running chunks finished, the queued ones were dropped
    time.sleep(0.3)
    assert len(done) == finished  # and nothing ran after the interrupt went on
