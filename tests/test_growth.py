"""Growth of accepted segments and absorption of leftover points."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from _helpers import context, plane_candidate
from houghcad import synth
from houghcad.growth import absorb
from houghcad.state import Segmentation


def _face_with_a_freed_band(noise: float):
    """The block's bottom face, noisy, held by its plane but for a band across its middle
    8 links wide, as a refit on a noisy cloud releases one; and the band's points."""
    cloud = synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=12000, noise=noise)
    ctx = context(cloud.points)
    face = np.flatnonzero(cloud.labels == [p["name"] for p in cloud.primitives].index("box -z"))
    P = ctx.pre.points
    plane = plane_candidate(ctx, face)
    u = np.cross(plane.prim.params["normal"], [1.0, 0.0, 0.0])
    s = (P[face] - P[face].mean(axis=0)) @ (u / np.linalg.norm(u))
    band = face[np.abs(s) < 4 * ctx.link]
    seg = Segmentation.of(len(P), [replace(plane, indices=np.setdiff1d(face, band))])
    return seg, ctx, band


def test_on_a_noisy_cloud_a_freed_band_is_absorbed_from_its_rim_inwards():
    seg, ctx, band = _face_with_a_freed_band(noise=0.003)
    assert ctx.policy.absorb_inwards
    absorb(seg, ctx)
    seg.check()
    assert (seg.labels[band] == 0).mean() > 0.97


def test_without_rounds_only_the_bands_rim_is_absorbed():
    seg, ctx, band = _face_with_a_freed_band(noise=0.003)
    one = replace(ctx, policy=replace(ctx.policy, absorb_inwards=False))
    absorb(seg, one)
    took = (seg.labels[band] == 0).mean()
    assert 0.2 < took < 0.8
