"""Splitting phase: RANSAC fallback determinism, edge settling."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest

import houghcad
from houghcad import synth
from houghcad.pipeline import Segmenter
from houghcad.preprocess import preprocess
from houghcad.boundaries import dissolve_redundant, settle_edges
from houghcad.cgal_random import seed_cgal_random
from houghcad.ransac import ransac_pieces


def _context(points, seed=0):
    seg = Segmenter(seed=seed)
    pre = preprocess(points, seed=seed)
    return seg._context(pre, len(points))


def _cloud():
    # A part with several surfaces, so RANSAC has real choices to make.
    return synth.PARTS["plate_with_holes"](seed=3, n_points=4000, noise=0.002).points


def test_seed_cgal_random_writes_the_generator():
    assert seed_cgal_random(5)


def test_ransac_pieces_are_the_same_on_every_call():
    ctx = _context(_cloud())
    idx = np.arange(len(ctx.pre.points))
    runs = [ransac_pieces(idx, ctx) for _ in range(3)]
    assert len(runs[0]) >= 2
    for other in runs[1:]:
        assert len(other) == len(runs[0])
        for a, b in zip(runs[0], other):
            np.testing.assert_array_equal(a, b)


def test_ransac_pieces_in_another_thread_match():
    ctx = _context(_cloud())
    idx = np.arange(len(ctx.pre.points))
    here = ransac_pieces(idx, ctx)
    there = []
    t = threading.Thread(target=lambda: there.append(ransac_pieces(idx, ctx)))
    t.start()
    t.join()
    assert len(there[0]) == len(here)
    for a, b in zip(here, there[0]):
        np.testing.assert_array_equal(a, b)


def test_settle_edges_gives_shared_boundary_points_to_the_smaller_segment():
    cloud = synth.PARTS["plate_with_holes"](seed=0, n_points=12000, noise=0.0)
    seg = Segmenter(seed=0).fit(cloud.points)
    segments, pre, ctx, *_ = seg._recognised
    delta = max(0.3 * pre.spacing, ctx.tau)
    big = int(np.argmax([len(s.indices) for s in segments]))
    B = segments[big]
    # Rim points of smaller segments that also lie on the biggest one's surface.
    moved = {}
    for j, s in enumerate(segments):
        if j == big:
            continue
        on = s.indices[B.family.distance(B.prim, pre.points[s.indices]) < delta]
        if len(on) and len(s.indices) - len(on) >= ctx.min_points:
            moved[j] = on
    assert moved, "the plate's holes share their rims with the face"
    # Hand them to the big segment, as the first acceptance would.
    for j, on in moved.items():
        segments[j] = replace(segments[j], indices=np.setdiff1d(segments[j].indices, on))
    segments[big] = replace(B, indices=np.union1d(B.indices, np.concatenate(list(moved.values()))))
    settle_edges(segments, ctx, delta, ctx.link)
    for j, on in moved.items():
        assert np.isin(on, segments[j].indices).all()
        assert not np.isin(on, segments[big].indices).any()
    assert min(len(s.indices) for s in segments) >= ctx.min_points


def _carved(family, seed, n_points=3000):
    """A complex surface carved into cylinder slices, as the global round of
    simple families leaves it."""
    from houghcad.families import REGISTRY
    from houghcad.recognize import recognize
    from houghcad.growth import accept

    cloud = synth.single(family, seed=seed, n_points=n_points)
    ctx = _context(cloud.points)
    free = np.ones(len(cloud.points), bool)
    segments = []
    lctx = replace(ctx, local=True)
    for _ in range(4):
        found = recognize(np.flatnonzero(free), [REGISTRY["cylinder"], REGISTRY["plane"]], lctx, free)
        if not found:
            break
        accept(found, free, ctx, segments)
    return cloud, ctx, free, segments


def test_consolidate_lets_a_complex_family_retake_its_carved_surface():
    from houghcad.families import select
    from houghcad.consolidation import consolidate

    cloud, ctx, free, segments = _carved("generalized_cylinder", seed=1)
    assert len(segments) >= 3 and all(s.family.name in ("cylinder", "plane") for s in segments)
    consolidate(select("all"), ctx, free, segments)
    truth = np.flatnonzero(cloud.labels == 0)
    best = max(segments, key=lambda s: len(s.indices))
    assert best.family.name == "generalized_cylinder"
    inter = len(np.intersect1d(best.indices, truth))
    assert 2 * inter / (len(best.indices) + len(truth)) >= 0.8
    assert best.prim.params["n"] == cloud.primitives[0]["params"]["n"]
    # Every point is owned by one segment or free, never both.
    owned = np.concatenate([s.indices for s in segments])
    assert len(owned) == len(np.unique(owned))
    assert not free[owned].any()


def test_consolidate_leaves_simple_faces_alone():
    import houghcad

    # A plate with holes and a boss: planes and cylinders, several of them
    # tangent-continuous, no complex surface. All families give the simple result.
    points = synth.PARTS["plate_with_holes"](seed=2, n_points=4000).points
    simple = houghcad.segment(points, families="simple")
    every = houghcad.segment(points, families="all")
    assert sorted(s.type for s in every.segments) == sorted(s.type for s in simple.segments)
    assert sorted(len(s.indices) for s in every.segments) == sorted(len(s.indices) for s in simple.segments)


@pytest.mark.parametrize("seed", [0, 3, 4])
def test_noisy_cones_come_out_whole(seed):
    import houghcad

    # Two mirrored cones at noise 0.001 (a fifth of the spacing): the whole-cloud
    # round places one cone from all the normals, and the other one's bands go
    # to cylinders, spheres and planes; consolidation votes the cone on them.
    cloud = synth.PARTS["mirrored_cones"](seed=seed, n_points=12000, noise=0.001)
    res = houghcad.segment(cloud.points, seed=0)
    for k, prim in enumerate(cloud.primitives):
        if not prim["name"].startswith("cone"):
            continue
        truth = np.flatnonzero(cloud.labels == k)
        best = max(res.segments, key=lambda s: len(np.intersect1d(s.indices, truth)))
        inter = len(np.intersect1d(best.indices, truth))
        assert best.type == "cone", (prim["name"], [(s.type, len(s.indices)) for s in res.segments])
        assert 2 * inter / (len(best.indices) + len(truth)) >= 0.9, prim["name"]


def test_edge_sliver_is_dissolved_into_the_faces_it_lies_on():
    # Seed 3: rim points of the shaft whose blurred normals kept them out of
    # both faces got a 9-point cylinder of their own, fitted worse than the
    # shaft and the end plane fit them.
    cloud = synth.shaft_with_groove(seed=3, n_points=12000)
    res = houghcad.segment(cloud.points, seed=0, merge=False)
    shaft = next(k for k, p in enumerate(cloud.primitives) if p["name"] == "shaft")
    for s in res.segments:
        ids, counts = np.unique(cloud.labels[s.indices], return_counts=True)
        if ids[np.argmax(counts)] == shaft:
            assert len(s.indices) > 1000, [(x.type, len(x.indices)) for x in res.segments]


def test_dissolve_keeps_true_faces_however_small_the_threshold_calls_them():
    # Every face of the part, the narrow groove walls included, lies off its
    # neighbours' surfaces: even when all count as small, only fragments of a
    # face beside a larger piece of it go, and every face keeps a segment.
    cloud = synth.shaft_with_groove(seed=3, n_points=12000)
    seg = Segmenter(seed=0).fit(cloud.points)
    segments, pre, ctx, *_ = seg._recognised

    def faces():
        return sorted(int(np.bincount(cloud.labels[s.indices][cloud.labels[s.indices] >= 0]).argmax())
                      for s in segments)

    before = faces()
    assert len(set(before)) == len(cloud.primitives)
    dissolve_redundant(segments, replace(ctx, min_points=10 ** 6), max(0.3 * pre.spacing, ctx.tau), ctx.link)
    assert set(faces()) == set(before)
    assert len(segments) >= len(before) - (len(before) - len(set(before)))


def test_small_holes_are_found_about_the_plate_normal():
    # At 1500 points a hole is 35-40 points, two or three rows: no PCA
    # neighbourhood lies on the hole alone, so its normals are blends and the
    # per-cluster vote finds nothing; the plate's normal gives the axis.
    cloud = synth.plate_with_holes(seed=0, n_points=1500, n_holes=4, boss=False)
    res = Segmenter(seed=0).fit(cloud.points).result_
    faces = res.faces()
    types = [s.type for s in res.segments for _ in s.faces()]
    lab = np.full(len(cloud.points), -1)
    for k, f in enumerate(faces):
        lab[f] = k
    for g in cloud.segments()[6:]:  # the holes
        own = lab[g][lab[g] >= 0]
        assert len(own), "hole left unsegmented"
        best = int(np.bincount(own).argmax())
        dsc = 2 * np.sum(lab[g] == best) / (len(g) + len(faces[best]))
        assert types[best] == "cylinder" and dsc > 0.9, (types[best], dsc)


def test_noisy_coverage_is_judged_over_all_the_points_not_the_inliers():
    # On a noisy cloud, a surface half a noise sigma off a face keeps more
    # than 80 % of its points within tau (3 sigma), and their truncated mean
    # is within the old bound of the face's own (12 % above it over all the
    # points): the test over all the points rejects it.
    from houghcad.families import REGISTRY
    from houghcad.state import Candidate
    from houghcad.consolidation import _covered

    cloud = synth.single("plane", 0, n_points=3000, noise=0.01)
    ctx = _context(cloud.points)
    assert ctx.noisy
    fam = REGISTRY["plane"]
    idx = np.arange(len(cloud.points))
    P, N = ctx.pre.points, ctx.pre.normals
    own = fam.fit(_seed_plane(P), P, N)
    piece = Candidate(fam, own, idx, 0.0, {})
    sigma = float(np.std(P @ own.params["normal"] - own.params["offset"]))
    off = replace(own, params={**own.params, "offset": own.params["offset"] + 0.5 * sigma})
    cand = Candidate(fam, off, idx, 0.0, {})
    assert len(_covered(cand, [piece], ctx, strict=False)) == 1  # the truncated test lets it through
    assert _covered(cand, [piece], ctx) == []
    assert len(_covered(piece, [piece], ctx)) == 1  # the face's own primitive still covers it


def _seed_plane(P):
    from houghcad.families.base import Primitive

    c = P.mean(axis=0)
    n = np.linalg.eigh(np.cov((P - c).T))[1][:, 0]
    return Primitive("plane", {"normal": n, "offset": float(n @ c), "point": c})


def _plane_segment(ctx, idx):
    from houghcad.families import REGISTRY
    from houghcad.families.base import Primitive
    from houghcad.state import Candidate, mean_fitting_error

    fam = REGISTRY["plane"]
    P = ctx.pre.points[idx]
    c = P.mean(axis=0)
    nrm = np.linalg.eigh(np.cov(P.T))[1][:, 0]
    prim = fam.fit(Primitive("plane", {"normal": nrm, "offset": float(nrm @ c)}), P, ctx.pre.normals[idx])
    d = fam.distance(prim, P)
    return Candidate(fam, prim, idx, mean_fitting_error(d, P), {"d": d})


def test_noisy_segment_fitted_worse_than_the_noise_goes_to_its_own_surface():
    from houghcad.families import select
    from houghcad.consolidation import revisit_poor_fits

    # A plane across a noisy helical strip (as the whole-cloud round leaves one beside a thread).
    cloud = synth.single("helical_strip", 0, n_points=3000, noise=0.005)
    ctx = _context(cloud.points)
    assert ctx.noisy
    idx = np.flatnonzero(cloud.labels == 0)
    seg = _plane_segment(ctx, idx)
    segments = [seg]
    free = np.ones(len(cloud.points), bool)
    free[idx] = False
    revisit_poor_fits(select("all"), ctx, free, segments)
    assert segments[0].family.name == "helical_strip"
    assert len(segments[0].indices) >= 0.8 * len(idx)
    assert not free[segments[0].indices].any()
    # A plane across a noisy dome and a band of the side face it meets (a
    # quarter of the segment): a curved family takes the dome, and the band
    # is freed for its neighbours.
    from scipy.spatial import cKDTree

    part = synth.PARTS["ellipsoid_part"](seed=2, n_points=6000, noise=0.005)
    ctx = _context(part.points)
    names = [p["name"] for p in part.primitives]
    P = ctx.pre.points
    dome = np.flatnonzero(part.labels == names.index("dome"))
    side = np.flatnonzero(part.labels == names.index("box +y"))
    band = side[np.argsort(cKDTree(P[dome]).query(P[side])[0])[: len(dome) // 3]]
    segments = [_plane_segment(ctx, np.union1d(dome, band))]
    free = np.ones(len(P), bool)
    free[segments[0].indices] = False
    revisit_poor_fits(select("all"), ctx, free, segments)
    got = segments[0]
    assert got.family.name in ("sphere", "torus", "ellipsoid", "surface_of_revolution")
    assert np.isin(dome, got.indices).mean() >= 0.85
    assert np.isin(band, got.indices).mean() <= 0.05
    assert free[np.setdiff1d(band, got.indices)].all() and not free[got.indices].any()
    # A plane fitted to the noise stays as it is.
    cloud = synth.single("plane", 0, n_points=3000, noise=0.005)
    ctx = _context(cloud.points)
    seg = _plane_segment(ctx, np.arange(len(cloud.points)))
    segments = [seg]
    revisit_poor_fits(select("all"), ctx, np.zeros(len(cloud.points), bool), segments)
    assert segments[0] is seg


def test_noisy_edge_band_goes_back_to_the_face_it_lies_nearest():
    # Two noisy faces of a block meeting at an edge; the smaller one has
    # grown a band ε wide into the larger, as acceptance and growth leave it.
    from houghcad.boundaries import settle_noisy_edges

    cloud = synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=12000, noise=0.005)
    ctx = _context(cloud.points)
    assert ctx.noisy
    names = [p["name"] for p in cloud.primitives]
    big = np.flatnonzero(cloud.labels == names.index("box -z"))
    small = np.flatnonzero(cloud.labels == names.index("box -x"))
    S = _plane_segment(ctx, small)
    P = ctx.pre.points
    band = big[S.family.distance(S.prim, P[big]) < ctx.epsilon]
    assert len(band) > 0.05 * len(big)
    segments = [_plane_segment(ctx, np.setdiff1d(big, band)), replace(S, indices=np.union1d(small, band))]
    before = np.isin(band, segments[1].indices).sum()
    settle_noisy_edges(segments, ctx, ctx.link)
    wrong = np.isin(band, segments[1].indices).sum() + np.isin(small, segments[0].indices).sum()
    # What stays wrong is the noise's own ambiguity: points scattered nearer
    # the other face's plane than their own.
    truth = [_plane_segment(ctx, big), _plane_segment(ctx, small)]
    d = [t.family.distance(t.prim, P[np.union1d(band, small)]) for t in truth]
    ambiguous = np.sum(np.where(np.isin(np.union1d(band, small), band), d[1] < d[0], d[0] < d[1]))
    assert wrong <= max(1.5 * ambiguous, 0.05 * before)
    assert not np.intersect1d(segments[0].indices, segments[1].indices).size
    assert sum(len(s.indices) for s in segments) == len(big) + len(small)


def test_noisy_points_beyond_a_convex_edge_stay_with_the_face_that_reaches_there():
    # Two noisy box faces at a convex edge, split where their planes are
    # nearer (the old rule's fixed point). A point scattered beyond the edge,
    # on the far side of one face's plane from the other face, is that other
    # face's: the first does not reach there. Over three seeds the side rule
    # leaves 75 of the nearest rule's 102 wrong points (it moved none before).
    from houghcad.boundaries import settle_noisy_edges

    wrong, wrong_nearest = 0, 0
    for seed in range(3):
        cloud = synth.PARTS["block_with_hole_and_slot"](seed=seed, n_points=12000, noise=0.005)
        ctx = _context(cloud.points)
        names = [p["name"] for p in cloud.primitives]
        big = np.flatnonzero(cloud.labels == names.index("box -z"))
        small = np.flatnonzero(cloud.labels == names.index("box -x"))
        truth = [_plane_segment(ctx, big), _plane_segment(ctx, small)]
        both = np.union1d(big, small)
        d = np.stack([t.family.distance(t.prim, ctx.pre.points[both]) for t in truth])
        near = d.argmin(axis=0)
        segments = [replace(truth[0], indices=both[near == 0]), replace(truth[1], indices=both[near == 1])]
        wrong_nearest += np.isin(big, segments[1].indices).sum() + np.isin(small, segments[0].indices).sum()
        settle_noisy_edges(segments, ctx, ctx.link)
        wrong += np.isin(big, segments[1].indices).sum() + np.isin(small, segments[0].indices).sum()
        assert sum(len(s.indices) for s in segments) == len(both)
    assert wrong <= 0.8 * wrong_nearest


def test_sides_of_two_faces_at_an_edge_and_of_a_plane_and_a_wide_cylinder():
    from houghcad.families import REGISTRY
    from houghcad.families.base import Primitive
    from houghcad.state import Candidate
    from houghcad.boundaries import _sides

    cloud = synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=12000, noise=0.005)
    ctx = _context(cloud.points)
    names = [p["name"] for p in cloud.primitives]
    bottom = _plane_segment(ctx, np.flatnonzero(cloud.labels == names.index("box -z")))
    wall = _plane_segment(ctx, np.flatnonzero(cloud.labels == names.index("box -x")))
    side = _sides([bottom, wall], np.array([[0, 1]]), ctx)
    # Each face lies on the side of the other's plane where its middle is.
    P = ctx.pre.points
    c0, c1 = P[bottom.indices].mean(axis=0), P[wall.indices].mean(axis=0)
    assert side[0, 1] == np.sign(wall.family.signed_distance(wall.prim, c0[None])[0]) != 0
    assert side[1, 0] == np.sign(bottom.family.signed_distance(bottom.prim, c1[None])[0]) != 0
    # A wide cylinder tangent to the bottom face, on part of it: no edge there.
    n = bottom.prim.params["normal"]
    e = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    e /= np.linalg.norm(e)
    R = 50.0 * ctx.pre.diagonal
    cyl = Primitive("cylinder", {"axis_point": c0 + R * n, "axis": e, "radius": R})
    half = bottom.indices[(P[bottom.indices] - c0) @ np.cross(n, e) > 0]
    piece = Candidate(REGISTRY["cylinder"], cyl, half, 0.0)
    rest = replace(bottom, indices=np.setdiff1d(bottom.indices, half))
    assert not _sides([rest, piece], np.array([[0, 1]]), ctx).any()


def _wide_cylinder(ctx, flat):
    """A cylinder of radius 50 diagonals tangent to the plane segment ``flat``
    at its centroid (flat within any noise over the cloud), and the unit
    vector across its axis in the plane."""
    from houghcad.families.base import Primitive

    P = ctx.pre.points
    n = flat.prim.params["normal"]
    e = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    e /= np.linalg.norm(e)
    c0 = P.mean(axis=0)
    R = 50.0 * ctx.pre.diagonal
    foot = c0 - (c0 @ n - flat.prim.params["offset"]) * n
    return Primitive("cylinder", {"axis_point": foot + R * n, "axis": e, "radius": R}), np.cross(n, e)


def test_noisy_plane_takes_back_the_wide_cylinder_on_its_face():
    # Noise lets a cylinder of radius ~50 diagonals take part of a plane face
    # beside the plane's own segment; the plane covers it and takes it back.
    from houghcad.families import REGISTRY
    from houghcad.state import Candidate
    from houghcad.consolidation import merge_complex

    cloud = synth.single("plane", 0, n_points=3000, noise=0.005)
    ctx = _context(cloud.points)
    assert ctx.noisy
    P = ctx.pre.points
    cyl, across = _wide_cylinder(ctx, _plane_segment(ctx, np.arange(len(P))))
    u = (P - P.mean(axis=0)) @ across
    piece = np.flatnonzero(u > np.quantile(u, 0.6))
    d = REGISTRY["cylinder"].distance(cyl, P[piece])
    segments = [_plane_segment(ctx, np.flatnonzero(u <= np.quantile(u, 0.6))),
                Candidate(REGISTRY["cylinder"], cyl, piece, float(d.mean()), {"d": d})]
    free = np.zeros(len(P), bool)
    merge_complex(segments, ctx, free)
    assert len(segments) == 1 and segments[0].family.name == "plane"
    assert len(segments[0].indices) >= 0.97 * len(P)


def test_noisy_dome_read_as_planes_is_voted_whole_again():
    # The whole-cloud round reads this noisy flat dome as planes meeting at
    # creases wider than half the angle tolerance: the tangent-joined groups
    # kept them apart, the complex families never saw the dome whole, and it
    # came out as a sphere and cylinder bands (DSC 0.67).
    part = synth.PARTS["ellipsoid_part"](seed=2, n_points=12000, noise=0.005)
    res = houghcad.segment(part.points, families="all", seed=0)
    names = [p["name"] for p in part.primitives]
    dome = np.flatnonzero(part.labels == names.index("dome"))
    best = max(res.segments, key=lambda s: len(np.intersect1d(s.indices, dome)))
    inter = len(np.intersect1d(best.indices, dome))
    assert best.type == "ellipsoid"
    assert 2 * inter / (len(best.indices) + len(dome)) >= 0.9


def test_noisy_curved_segment_that_a_plane_fits_as_well_becomes_a_plane():
    from houghcad.families import REGISTRY, select
    from houghcad.families.base import Primitive
    from houghcad.state import Candidate
    from houghcad.consolidation import prefer_planes

    # A cylinder of radius 50 diagonals on a noisy plane face: flat within the noise.
    cloud = synth.single("plane", 0, n_points=3000, noise=0.005)
    ctx = _context(cloud.points)
    P = ctx.pre.points
    flat = _plane_segment(ctx, np.arange(len(P)))
    cyl, _ = _wide_cylinder(ctx, flat)
    segments = [Candidate(REGISTRY["cylinder"], cyl, flat.indices, 0.0)]
    assert prefer_planes(segments, select("simple"), ctx) == 1
    assert segments[0].family.name == "plane" and len(segments[0].indices) == len(P)
    # Without the plane family selected, nothing changes.
    segments = [Candidate(REGISTRY["cylinder"], cyl, flat.indices, 0.0)]
    assert prefer_planes(segments, select("cylinder"), ctx) == 0
    # A noisy cylinder (its true primitive, in the standard frame) stays one.
    cloud = synth.single("cylinder", 0, n_points=3000, noise=0.005)
    ctx = _context(cloud.points)
    T = ctx.pre.transform
    g = cloud.primitives[0]["params"]
    prim = Primitive("cylinder", {"axis_point": T.points(np.asarray(g["axis_point"])[None])[0],
                                  "axis": T.dirs(np.asarray(g["axis"])[None])[0], "radius": T.scale * g["radius"]})
    segments = [Candidate(REGISTRY["cylinder"], prim, np.flatnonzero(cloud.labels == 0), 0.0)]
    assert prefer_planes(segments, select("simple"), ctx) == 0
    assert segments[0].family.name == "cylinder"
