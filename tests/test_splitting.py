"""The splitting phase (paper §5.3): clusters of what recognition leaves, recognised again."""

from __future__ import annotations

import numpy as np
import pytest

import houghcad
from _helpers import context, plane_candidate
from houghcad import synth
from houghcad.families import select
from houghcad.families.base import Primitive
from houghcad.pipeline import Segmenter
from houghcad.families import REGISTRY
from houghcad.splitting import _still_free, cluster_context, clusters, on_one_line, splitting_phase
from houghcad.state import Candidate, Segmentation


def test_splitting_phase_segments_a_free_cloud_on_its_own():
    # Nothing recognised yet: the phase alone finds the block's faces.
    cloud = synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=4000)
    ctx = context(cloud.points)
    seg = Segmentation(len(cloud.points))
    sizes = []
    splitting_phase(seg, select("simple"), ctx, progress=sizes.append)
    seg.check()
    assert len(seg) >= len(cloud.primitives) - 2
    assert (seg.labels >= 0).mean() > 0.9
    assert sum(sizes) >= 0.9 * len(cloud.points)
    assert {s.family.name for s in seg} >= {"plane", "cylinder"}


def test_clusters_are_dense_groups_of_at_least_min_points_largest_first():
    cloud = synth.PARTS["plate_with_holes"](seed=0, n_points=3000)
    ctx = context(cloud.points)
    idx = np.arange(len(cloud.points))
    cl = clusters(idx, ctx)
    assert len(cl) == 1 and len(cl[0]) == len(idx)  # one connected part
    far = np.r_[ctx.pre.points, ctx.pre.points[:40] + 10.0]
    ctx2 = context(far)
    parts = clusters(np.arange(len(far)), ctx2)
    assert [len(c) for c in parts] == sorted((len(c) for c in parts), reverse=True)


@pytest.mark.parametrize("seed", [0, 3, 4])
def test_noisy_cones_come_out_whole(seed):
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


def test_points_on_one_line_are_told_from_a_strip():
    t = np.linspace(0.0, 1.0, 30)[:, None]
    line = np.array([0.3, -0.2, 0.1]) + t * np.array([1.0, 2.0, -0.5])
    assert on_one_line(line)
    assert on_one_line(np.repeat(line[:1], 5, axis=0))
    strip = line + np.array([0.0, 0.0, 1e-4]) * (np.arange(30) % 2)[:, None]
    assert not on_one_line(strip)


def test_a_candidate_left_a_line_of_points_keeps_its_fit():
    # A cone cut to the points of one of its generatrices: every cone through
    # that line fits them exactly, so a refit there would be arbitrary.
    rng = np.random.default_rng(0)
    alpha = 0.3
    h, phi = rng.uniform(0.5, 2.0, 600), rng.uniform(0, 2 * np.pi, 600)
    surface = np.c_[h * np.tan(alpha) * np.cos(phi), h * np.tan(alpha) * np.sin(phi), h]
    line = np.linspace(0.5, 2.0, 40)[:, None] * np.array([np.sin(alpha), 0.0, np.cos(alpha)])
    ctx = context(np.r_[surface, line])
    cone = REGISTRY["cone"]
    T = ctx.pre.transform
    start = cone.fit(Primitive("cone", {"apex": T.points(np.zeros(3)), "axis": T.dirs(np.array([0, 0, 1.0])),
                                        "half_angle": alpha}), ctx.pre.points[:600], ctx.pre.normals[:600])
    idx = np.arange(640)
    c = Candidate(cone, start, idx, 0.0, np.zeros(640))
    avail = np.zeros(640, bool)
    avail[600:] = True
    (kept,) = _still_free([c], avail, ctx)
    assert kept.prim is start
    np.testing.assert_array_equal(kept.indices, np.arange(600, 640))
    avail[:300] = True  # a piece of the surface as well: refitted on it
    (refit,) = _still_free([c], avail, ctx)
    assert refit.prim is not start
    assert abs(refit.prim.params["half_angle"] - alpha) < 1e-6


def test_a_small_holes_crease_normals_are_read_again_from_its_own_points():
    # Holes about 1.3 spacings wide: every wall point is a crease point whose
    # voted normal is often the plate's. From the wall's own points alone PCA
    # reads the wall's orientation.
    cloud = synth.PARTS["bracket"](seed=0, n_points=8000)
    ctx = context(cloud.points)
    truth = ctx.pre.transform.dirs(cloud.normals)
    truth /= np.linalg.norm(truth, axis=1, keepdims=True)
    holes = [np.asarray(g) for g, p in zip(cloud.segments(), cloud.primitives) if p["name"].endswith("hole")]
    before, after = [], []
    for cl in holes:
        own = cluster_context(cl, ctx)
        assert own is not ctx and ctx.pre.normals is not own.pre.normals
        for N, out in ((ctx.pre.normals, before), (own.pre.normals, after)):
            out += np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", N[cl], truth[cl])), 0, 1))).tolist()
        others = np.setdiff1d(np.arange(len(cloud.points)), cl)
        np.testing.assert_array_equal(own.pre.normals[others], ctx.pre.normals[others])
    assert np.median(after) < 0.5 * np.median(before)
    assert np.median(after) < ctx.tol.scale.angle_deg


def test_a_cluster_without_crease_points_keeps_the_context():
    cloud = synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=3000)
    ctx = context(cloud.points)
    flat = np.flatnonzero(~ctx.pre.crease) if ctx.pre.crease is not None else np.arange(len(cloud.points))
    assert cluster_context(flat[:50], ctx) is ctx


def test_a_wall_end_rounded_by_two_fillets_comes_out_as_its_faces():
    # Over-segmentation reduced to a small case: a thick tube's top rounded by two quarter tori
    # with a narrow flat between them. The cluster's normals place one tube between the two
    # fillets, which fits neither: recognition leaves slices of both (12 faces for 6 before
    # the RANSAC fallback was also tried on fragmented clusters; fillets' DSC 0.87 and 0.36).
    from houghcad.evaluate import classification_measures

    cloud = synth.PARTS["rounded_tube"](seed=1, n_points=2500)
    res = houghcad.segment(cloud.points, families="simple", seed=0)
    faces = [np.asarray(f) for s in res.segments for f in s.faces()]
    m = classification_measures(faces, cloud.segments(), len(cloud.points), per_segment=True)
    assert len(faces) == len(cloud.primitives)
    outer, inner = m["per_segment"]["DSC"][4:6]
    assert outer >= 0.85 and inner >= 0.85
    assert m["DSC"] >= 0.9


@pytest.mark.xfail(strict=True, reason="a rim's two fillets shred into slices: the compromise tube between them "
                   "(see the test above) with the tubes' centres at two heights")
def test_a_rim_rounded_on_both_edges_comes_out_as_its_faces():
    # The same over-segmentation on a disc's rim: quarter tori of one radius at its top and
    # bottom edges, a narrow band between. One tube between the fillets fits both within tau
    # (0.4-0.5 tau mean); pieces that fit it locally better shred it, and 5,000 points come
    # out in 37-59 faces for 6. Refitting such a loose torus on each half (its centre plane
    # parts the two tubes) finds both fillets, but on Fit4CAD the exact fillets then also
    # take flat lands two rows wide between tangent tori (two clouds, -0.13 each), which the
    # loose fits left to a plane: open (BENCHMARKS.md, issue 22).
    from houghcad.evaluate import classification_measures

    cloud = synth.filleted_disc(seed=0, n_points=5000)
    res = houghcad.segment(cloud.points, families="simple", seed=0)
    faces = [np.asarray(f) for s in res.segments for f in s.faces()]
    m = classification_measures(faces, cloud.segments(), len(cloud.points), per_segment=True)
    upper, lower = m["per_segment"]["DSC"][4:6]
    assert upper >= 0.7 and lower >= 0.7
    assert len(faces) <= len(cloud.primitives) + 3


def test_where_the_vote_finds_nothing_the_fallback_in_larger_pieces_is_taken(monkeypatch):
    # A cylinder sampled in rows whose rows lie at levels across a neighbour's normal: the
    # aligned features offer planes of a few rows, RANSAC the cylinder through all of them. The
    # fallbacks compete as the RANSAC split competes with fragments: larger pieces win.
    import houghcad.splitting as sp
    from houghcad.state import mean_fitting_error

    cloud = synth.PARTS["plate_with_holes"](seed=0, n_points=3000)
    ctx = context(cloud.points)
    k = [p["name"] for p in cloud.primitives].index("hole 0")
    hole = np.flatnonzero(cloud.labels == k)
    P, T = ctx.pre.points, ctx.pre.transform
    cyl = REGISTRY["cylinder"]
    g = cloud.primitives[k]["params"]  # world units; the context's points are in standard units
    prim = Primitive("cylinder", {"axis_point": T.points(np.asarray(g["axis_point"])[None])[0],
                                  "axis": T.dirs(np.asarray(g["axis"])[None])[0], "radius": g["radius"] * T.scale})
    d = cyl.distance(prim, P[hole])
    whole = Candidate(cyl, prim, hole, mean_fitting_error(d, P[hole]), d)
    rest = np.setdiff1d(np.arange(len(P)), hole)
    seg = Segmentation.of(len(P), [plane_candidate(ctx, rest)])

    monkeypatch.setattr(sp, "recognize", lambda *a, **kw: [])
    monkeypatch.setattr(sp, "aligned_features",
                        lambda cl, *a, **kw: [plane_candidate(ctx, cl[:12]), plane_candidate(ctx, cl[12:19])])
    monkeypatch.setattr(sp, "ransac_recognised", lambda *a, **kw: [whole])
    splitting_phase(seg, select("simple"), ctx)
    seg.check()
    assert len(seg) == 2 and seg[1].family.name == "cylinder"
    assert (seg.labels[hole] == 1).all()


def test_ransac_skips_points_on_one_line():
    # CGAL's Efficient RANSAC wrote through a null pointer on these 51 points of one edge, their
    # normals those of its two faces (a scan rounded to a coarse grid): the process died with
    # SIGSEGV. Points on one line determine no surface.
    from dataclasses import replace

    from houghcad.ransac import ransac_pieces

    ctx = context(synth.block_with_hole_and_slot(seed=3, n_points=4000).points)
    P, N = ctx.pre.points.copy(), ctx.pre.normals.copy()
    P[:51] = np.array([-0.12, 0.35, 0.08]) + np.outer(np.linspace(0, 0.0738, 51), [0.0, 1.0, 0.0])
    N[:51] = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 0, -1.0]])[np.arange(51) % 3]
    edge = replace(ctx, pre=replace(ctx.pre, points=P, normals=N), tau=6.4e-5, link=0.0076)
    assert ransac_pieces(np.arange(51), edge) == []
