"""Consolidation: complex families retake carved surfaces, pieces are voted again,
poor fits are revisited."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

import houghcad
from _helpers import context, plane_candidate, seed_plane, wide_cylinder
from houghcad import synth
from houghcad.consolidation import _covered, consolidate, merge_complex, revisit_poor_fits
from houghcad.evaluate import classification_measures
from houghcad.families import REGISTRY, select
from houghcad.growth import accept
from houghcad.recognize import recognize
from houghcad.state import Candidate, Segmentation


def _carved(family, seed, n_points=3000):
    """A complex surface carved into cylinder slices, as the global round of
    simple families leaves it."""
    cloud = synth.single(family, seed=seed, n_points=n_points)
    ctx = context(cloud.points)
    seg = Segmentation(len(cloud.points))
    lctx = replace(ctx, local=True)
    for _ in range(4):
        found = recognize(np.flatnonzero(seg.free), [REGISTRY["cylinder"], REGISTRY["plane"]], lctx, seg.free)
        if not found:
            break
        accept(found, seg, ctx)
    return cloud, ctx, seg


def test_consolidate_lets_a_complex_family_retake_its_carved_surface():
    cloud, ctx, seg = _carved("generalized_cylinder", seed=1)
    assert len(seg) >= 3 and all(s.family.name in ("cylinder", "plane") for s in seg)
    consolidate(seg, select("all"), ctx)
    seg.check()
    truth = np.flatnonzero(cloud.labels == 0)
    best = max(seg, key=lambda s: len(s.indices))
    assert best.family.name == "generalized_cylinder"
    inter = len(np.intersect1d(best.indices, truth))
    assert 2 * inter / (len(best.indices) + len(truth)) >= 0.8
    assert best.prim.params["n"] == cloud.primitives[0]["params"]["n"]


def test_consolidate_leaves_simple_faces_alone():
    # A plate with holes and a boss: planes and cylinders, several of them
    # tangent-continuous, no complex surface. All families give the simple result.
    points = synth.PARTS["plate_with_holes"](seed=2, n_points=4000).points
    simple = houghcad.segment(points, families="simple")
    every = houghcad.segment(points, families="all")
    assert sorted(s.type for s in every.segments) == sorted(s.type for s in simple.segments)
    assert sorted(len(s.indices) for s in every.segments) == sorted(len(s.indices) for s in simple.segments)


def test_noisy_coverage_is_judged_over_all_the_points_not_the_inliers():
    # On a noisy cloud, a surface half a noise sigma off a face keeps more
    # than 80 % of its points within tau (3 sigma), and their truncated mean
    # is within the old bound of the face's own (12 % above it over all the
    # points): the test over all the points rejects it.
    cloud = synth.single("plane", 0, n_points=3000, noise=0.01)
    ctx = context(cloud.points)
    assert ctx.noisy
    fam = REGISTRY["plane"]
    idx = np.arange(len(cloud.points))
    P, N = ctx.pre.points, ctx.pre.normals
    own = fam.fit(seed_plane(P), P, N)
    piece = Candidate(fam, own, idx, 0.0, np.zeros(len(idx)))
    sigma = float(np.std(P @ own.params["normal"] - own.params["offset"]))
    off = replace(own, params={**own.params, "offset": own.params["offset"] + 0.5 * sigma})
    cand = Candidate(fam, off, idx, 0.0, np.zeros(len(idx)))
    assert len(_covered(cand, [piece], ctx, strict=False)) == 1  # the truncated test lets it through
    assert _covered(cand, [piece], ctx) == []
    assert len(_covered(piece, [piece], ctx)) == 1  # the face's own primitive still covers it


def test_noisy_segment_fitted_worse_than_the_noise_goes_to_its_own_surface():
    # A plane across a noisy helical strip (as the whole-cloud round leaves one beside a thread).
    cloud = synth.single("helical_strip", 0, n_points=3000, noise=0.005)
    ctx = context(cloud.points)
    assert ctx.noisy
    idx = np.flatnonzero(cloud.labels == 0)
    seg = Segmentation.of(len(cloud.points), [plane_candidate(ctx, idx)])
    assert revisit_poor_fits(seg, select("all"), ctx)
    seg.check()
    assert seg[0].family.name == "helical_strip"
    assert len(seg.indices(0)) >= 0.8 * len(idx)
    # A plane across a noisy dome and a band of the side face it meets (a
    # quarter of the segment): a curved family takes the dome, and the band
    # is freed for its neighbours.
    from scipy.spatial import cKDTree

    part = synth.PARTS["ellipsoid_part"](seed=2, n_points=6000, noise=0.005)
    ctx = context(part.points)
    names = [p["name"] for p in part.primitives]
    P = ctx.pre.points
    dome = np.flatnonzero(part.labels == names.index("dome"))
    side = np.flatnonzero(part.labels == names.index("box +y"))
    band = side[np.argsort(cKDTree(P[dome]).query(P[side])[0])[: len(dome) // 3]]
    seg = Segmentation.of(len(P), [plane_candidate(ctx, np.union1d(dome, band))])
    revisit_poor_fits(seg, select("all"), ctx)
    got = seg[0]
    assert got.family.name in ("sphere", "torus", "ellipsoid", "surface_of_revolution")
    assert np.isin(dome, got.indices).mean() >= 0.85
    assert np.isin(band, got.indices).mean() <= 0.05
    assert (seg.labels[np.setdiff1d(band, got.indices)] < 0).all()
    # A plane fitted to the noise stays as it is.
    cloud = synth.single("plane", 0, n_points=3000, noise=0.005)
    ctx = context(cloud.points)
    flat = plane_candidate(ctx, np.arange(len(cloud.points)))
    seg = Segmentation.of(len(cloud.points), [flat])
    version = seg.version
    assert not revisit_poor_fits(seg, select("all"), ctx)
    assert seg.version == version and seg[0].prim is flat.prim


def test_noisy_plane_takes_back_the_wide_cylinder_on_its_face():
    # Noise lets a cylinder of radius ~50 diagonals take part of a plane face
    # beside the plane's own segment; the plane covers it and takes it back.
    cloud = synth.single("plane", 0, n_points=3000, noise=0.005)
    ctx = context(cloud.points)
    assert ctx.noisy
    P = ctx.pre.points
    cyl, across = wide_cylinder(ctx, plane_candidate(ctx, np.arange(len(P))))
    u = (P - P.mean(axis=0)) @ across
    piece = np.flatnonzero(u > np.quantile(u, 0.6))
    d = REGISTRY["cylinder"].distance(cyl, P[piece])
    seg = Segmentation.of(len(P), [plane_candidate(ctx, np.flatnonzero(u <= np.quantile(u, 0.6))),
                                   Candidate(REGISTRY["cylinder"], cyl, piece, float(d.mean()), d)])
    merge_complex(seg, ctx)
    seg.check()
    assert len(seg) == 1 and seg[0].family.name == "plane"
    assert len(seg.indices(0)) >= 0.97 * len(P)


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


def test_a_torus_cut_into_bands_is_joined_again():
    """Over-segmentation reduced: a torus carved into cylinder and plane bands (over a hundred of
    them), as rounds of the simpler families leave it, is one torus again after the per-cluster
    families' votes on groups of segments and the merging of pieces."""
    cloud, ctx, seg = _carved("torus", seed=0)
    assert len(seg) > 20 and {s.family.name for s in seg} <= {"cylinder", "plane"}
    consolidate(seg, select("simple"), ctx)
    assert [s.family.name for s in seg] == ["torus"]
    assert len(seg[0].indices) >= 0.9 * len(cloud.points)


def test_clean_tori_of_the_noise_experiment_part_come_out_whole():
    """The paper's noise-experiment part, exact sample: the five primitives, the cylinder in its
    two faces. (Before the candidates were connected through crease points, the splitting phase
    cut both tori into 55 bands here, which consolidation joined again.)"""
    cloud = synth.table5_block(n_points=8000)
    res = houghcad.segment(cloud.points, seed=0)
    assert sorted(s.type for s in res.segments) == ["cylinder", "plane", "plane", "torus", "torus"]
    assert len(res.faces()) == 6
    m = classification_measures([np.asarray(f) for f in res.faces()], cloud.segments(), len(cloud.points))
    assert m["DSC"] > 0.9
    tori = sorted((s.params["major_radius"], s.params["minor_radius"]) for s in res.segments if s.type == "torus")
    assert np.allclose(tori, [(1.05, 0.79), (1.49, 0.72)], atol=0.01)
