"""Features aligned with their neighbours (extension of the splitting phase): circles and levels
across a neighbour's axis or normal, found from the points alone."""

from __future__ import annotations

import numpy as np

import houghcad
from _helpers import context
from houghcad import synth
from houghcad.aligned import _best_circle, _best_level, _circumcircles
from houghcad.evaluate import classification_measures


def _ring(n: int, r: float, z: float, rng: np.random.Generator, centre=(0.0, 0.0)) -> np.ndarray:
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[centre[0] + r * np.cos(t), centre[1] + r * np.sin(t), np.full(n, z)]


def test_circumcircles_of_three_points_and_of_three_on_a_line():
    A = np.array([[1.0, 0.0], [0.0, 0.0]])
    B = np.array([[0.0, 1.0], [1.0, 0.0]])
    C = np.array([[-1.0, 0.0], [2.0, 0.0]])
    c, r = _circumcircles(A, B, C)
    assert np.allclose(c[0], [0.0, 0.0]) and np.isclose(r[0], 1.0)
    assert np.isinf(r[1])


def test_a_ring_and_a_level_are_found_among_a_counterbores_points():
    # A counterbore across z, exact: hole ring r = 1 below, bore ring r = 2.3 above, and the
    # flat step between them at z = 0. Its normals would be blends; the points alone place it.
    ctx = context(synth.plate_with_holes(seed=0, n_points=3000).points)
    rng = np.random.default_rng(0)
    s = 4 * ctx.spacing
    hole = np.concatenate([_ring(15, s, -z, rng) for z in (0.5 * s, 1.0 * s)])
    bore = np.concatenate([_ring(20, 2.3 * s, z, rng) for z in (0.5 * s, 1.0 * s)])
    rho = rng.uniform(1.1 * s, 2.2 * s, 25)
    t = rng.uniform(0, 2 * np.pi, 25)
    step = np.c_[rho * np.cos(t), rho * np.sin(t), np.zeros(25)]
    X = np.concatenate([hole, bore, step])
    level, on = _best_level(X[:, 2], ctx.tau)
    assert abs(level) < ctx.tau and on.sum() == len(step)
    c, r, on = _best_circle(X[:, :2], rng, ctx)
    assert np.isclose(r, 2.3 * s, rtol=1e-6) and np.allclose(c, 0.0, atol=1e-6 * s)
    assert on.sum() == len(bore)


def test_the_brackets_counterbores_come_out_as_hole_bore_and_step():
    # At 8,000 points a counterbore is about 20 hole points, 40 bore points and 25 step
    # points; before this extension every hole, and some whole counterbores, stayed
    # unsegmented (the bracket's mean DSC was 0.80).
    cloud = synth.bracket(seed=0, n_points=8000)
    res = houghcad.segment(cloud.points, families="simple", seed=0)
    faces = [np.asarray(f) for f in res.faces()]
    types = [s.type for s in res.segments for _ in s.faces()]
    per = classification_measures(faces, cloud.segments(), len(cloud.points), per_segment=True)
    lab = np.full(len(cloud.points), -1)
    for k, f in enumerate(faces):
        lab[f] = k
    names = [p["name"] for p in cloud.primitives]
    bores = [k for k, n in enumerate(names) if n.startswith("counterbore")]
    assert len(bores) == 12
    for k in bores:
        g = cloud.segments()[k]
        best = int(np.bincount(lab[g][lab[g] >= 0]).argmax())
        assert types[best] == cloud.primitives[k]["type"], names[k]
        assert per["per_segment"]["DSC"][k] >= 0.6, (names[k], per["per_segment"]["DSC"][k])
    assert per["DSC"] >= 0.9
