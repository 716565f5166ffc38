"""Generalised cones over an n-convexity directrix: geometry, sampler, recognition, composite part."""

from __future__ import annotations

import numpy as np
import pytest

import houghcad
from houghcad import synth
from houghcad.families import REGISTRY, Primitive

FAM = "generalized_cone"


def _prim(gt: dict) -> Primitive:
    p = gt["params"]
    return Primitive(gt["type"], {k: (np.asarray(v, float) if isinstance(v, list) else
                                      (int(round(v)) if k == "n" else float(v))) for k, v in p.items()})


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_sampler_lies_on_the_surface_with_its_normals(seed):
    c = synth.single(FAM, seed, n_points=2000)
    fam, prim = REGISTRY[FAM], _prim(c.primitives[0])
    assert fam.distance(prim, c.points).max() < 1e-9 * c.diagonal()
    dots = np.abs(np.einsum("ij,ij->i", fam.surface_normals(prim, c.points), c.normals))
    assert dots.min() > 1 - 1e-9
    h = 1e-3 * c.diagonal()
    assert np.allclose(fam.distance(prim, c.points + h * c.normals), h, rtol=1e-5)
    # Behind the apex the nearest point of the surface is the apex.
    apex, axis = np.asarray(c.primitives[0]["params"]["apex"]), np.asarray(c.primitives[0]["params"]["axis"])
    assert np.isclose(fam.distance(prim, (apex - 0.5 * axis)[None])[0], 0.5)


def test_sampler_area_matches_a_circular_cone():
    """With b → 0 the generalised cone is a circular cone of half-angle atan(slope)."""
    alpha = 0.5
    a = synth.SAMPLERS[FAM].area(slope=np.tan(alpha), b=1e-12, order=3, z_range=(0.5, 1.5))
    assert np.isclose(a, synth.SAMPLERS["cone"].area(half_angle=alpha, z_range=(0.5, 1.5)), rtol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recognised_in_random_poses(seed):
    c = synth.single(FAM, seed, n_points=4000, noise=0.005, missing=0.1)
    r = houghcad.segment(c.points, families="all")
    segs = [s for s in r.segments if s.type == FAM]
    assert segs, [s.type for s in r.segments]
    s = max(segs, key=lambda s: len(s.indices))
    truth, got = set(np.flatnonzero(c.labels == 0)), set(s.indices.tolist())
    assert 2 * len(truth & got) / (len(truth) + len(got)) >= 0.9
    gt = c.primitives[0]["params"]
    assert s.params["n"] == int(round(gt["n"]))
    assert abs(s.params["a"] / gt["a"] - 1) < 0.02
    assert abs(s.params["b"] / gt["b"] - 1) < 0.02
    assert np.linalg.norm(np.subtract(s.params["apex"], gt["apex"])) < 0.02 * c.diagonal()
    assert np.dot(s.params["axis"], gt["axis"]) > np.cos(np.radians(1.0))
    assert (s.params["A"], s.params["B"]) == (1.0, 0.0)
    assert s.mfe <= 0.01


def test_circular_cone_does_not_become_generalised():
    c = synth.single("cone", 0, n_points=2500, noise=0.0)
    r = houghcad.segment(c.points, families="all")
    assert r.segments[0].type == "cone"
    assert not any(s.type.startswith("generalized") for s in r.segments)


def test_composite_part_structure():
    c = synth.PARTS["generalized_cone_part"](seed=1, n_points=6000)
    types = [p["type"] for p in c.primitives]
    assert types == ["generalized_cylinder", "generalized_cone", "generalized_cylinder", "plane", "plane"]
    assert set(np.unique(c.labels)) == set(range(5))
    for k, p in enumerate(c.primitives[:3]):
        fam = REGISTRY[p["type"]]
        assert fam.distance(_prim(p), c.points[c.labels == k]).max() < 1e-6 * c.diagonal()
    n = {p["params"]["n"] for p in c.primitives[:3]}
    assert len(n) == 1


# Seed 2 failed from 2026-11-22 (the cone in pieces, its largest a generalised cylinder) while
# preprocessing voted crease normals on nearly every point of this cloud, which the noise policy
# reads as noisy: since a noisy cloud keeps its PCA normals, it passes.
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_composite_part_recognised(seed):
    c = synth.PARTS["generalized_cone_part"](seed=seed, n_points=5000, noise=0.002)
    r = houghcad.segment(c.points, families="all")
    for k, p in enumerate(c.primitives[:3]):
        truth = np.flatnonzero(c.labels == k)
        best = max(r.segments, key=lambda s: np.intersect1d(s.indices, truth).size)
        inter = np.intersect1d(best.indices, truth).size
        assert best.type == p["type"]
        assert 2 * inter / (len(truth) + len(best.indices)) >= 0.8
        assert best.params["n"] == int(round(p["params"]["n"]))


def _noisy_part_context(seed):
    from dataclasses import replace

    from houghcad.pipeline import Segmenter
    from houghcad.preprocess import preprocess

    c = synth.PARTS["generalized_cone_part"](seed=seed, n_points=12000, noise=0.005)
    pre = preprocess(c.points, None, seed=0)
    return c, pre, replace(Segmenter(families="all")._context(pre, len(c.points)), local=True)


def test_apex_consensus_sets_aside_the_cylinder_on_the_same_directrix():
    """Noisy part, seed 1: half the cone's turn with the band of the second
    generalised cylinder beside it, as a segment cut across their edge holds
    them. The least-squares apex of all tangent planes is pulled off by a tenth
    of the cone's size; the consensus apex takes the cone's points alone and
    places the cone with the right order."""
    from houghcad.families.base import planes_intersection, unit
    from houghcad.families.generalized_cone import cone_directrix_frame, consensus_apexes

    c, pre, ctx = _noisy_part_context(1)
    P, N = pre.points, pre.normals
    g = c.primitives[1]["params"]
    axis, apex = np.asarray(g["axis"]), np.asarray(g["apex"])
    V = c.points - apex
    h = V @ axis
    e1 = unit(np.cross(axis, [0.3, 0.5, 0.8]))
    sector = np.abs(np.arctan2(V @ np.cross(axis, e1), V @ e1)) < 1.8
    cone_h = h[c.labels == 1]
    band = h > h[c.labels == 2].max() - 0.25 * np.ptp(cone_h)
    cone = np.flatnonzero((c.labels == 1) & sector)
    region = np.sort(np.r_[cone, np.flatnonzero((c.labels == 2) & sector & band)])
    whole = c.labels == 1
    apex_true = planes_intersection(P[whole], N[whole])[0]
    size = np.ptp(P[whole], axis=0).max()

    ls = cone_directrix_frame(P[region], N[region])
    assert ls is None or np.linalg.norm(ls[0] - apex_true) > 0.07 * size
    first = consensus_apexes(P[region], N[region], np.random.default_rng(0))[0]
    on_cone = np.isin(region[first], cone)
    assert on_cone.mean() > 0.97 and on_cone.sum() > 0.6 * len(cone)
    placed = REGISTRY[FAM].placements(P[region], N[region], ctx)
    assert any(pl.info["n"] == int(g["n"]) and np.linalg.norm(pl.origin - apex_true) < 0.05 * size for pl in placed)
