"""The RANSAC fallback: CGAL's Efficient RANSAC, seeded, gives the same pieces every time."""

from __future__ import annotations

import threading

import numpy as np

from _helpers import context
from houghcad import synth
from houghcad.ransac import ransac_pieces


def _cloud():
    # A part with several surfaces, so RANSAC has real choices to make.
    return synth.PARTS["plate_with_holes"](seed=3, n_points=4000, noise=0.002).points


def test_ransac_pieces_are_the_same_on_every_call():
    ctx = context(_cloud())
    idx = np.arange(len(ctx.pre.points))
    runs = [ransac_pieces(idx, ctx) for _ in range(3)]
    assert len(runs[0]) >= 2
    for other in runs[1:]:
        assert len(other) == len(runs[0])
        for a, b in zip(runs[0], other):
            np.testing.assert_array_equal(a, b)


def test_ransac_pieces_in_another_thread_match():
    ctx = context(_cloud())
    idx = np.arange(len(ctx.pre.points))
    here = ransac_pieces(idx, ctx)
    there = []
    t = threading.Thread(target=lambda: there.append(ransac_pieces(idx, ctx)))
    t.start()
    t.join()
    assert len(there[0]) == len(here)
    for a, b in zip(here, there[0]):
        np.testing.assert_array_equal(a, b)
