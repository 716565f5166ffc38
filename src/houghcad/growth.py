"""Growth of accepted segments: the paper's removal of the points within ε of
a recognised primitive (:func:`grow`), and the absorption of leftover points
by the segment of their nearest assigned neighbour (extension)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .context import Context, threads
from .state import Candidate, Segmentation, surface_distance


def grow(seg: Segmentation, k: int, ctx: Context) -> None:
    """Give segment k the free points within ε of its primitive that touch it
    (paper: points closer than ε to a recognised primitive are removed)."""
    cand = np.flatnonzero(seg.free)
    if len(cand) == 0:
        return
    c = seg[k]
    P = ctx.pre.points
    d = c.family.distance(c.prim, P[cand])
    cand = cand[d < ctx.epsilon]
    if len(cand) == 0:
        return
    sn = c.family.surface_normals(c.prim, P[cand])
    cand = cand[np.abs(np.einsum("ij,ij->i", sn, ctx.pre.normals[cand])) >= ctx.cos_angle]
    if len(cand) == 0:
        return
    dist, _ = cKDTree(P[c.indices]).query(P[cand], distance_upper_bound=ctx.link)
    seg.assign(cand[np.isfinite(dist)], k)


def accept(found: list[Candidate], seg: Segmentation, ctx: Context) -> None:
    """Add the accepted candidates as segments, then grow each in turn."""
    ks = [seg.add(c.record, c.indices) for c in found]
    for k in ks:
        grow(seg, k, ctx)


def absorb(seg: Segmentation, ctx: Context) -> None:
    """Give each leftover point to the segment of its nearest assigned
    neighbour when it lies within ε (noisy clouds: τ) of that segment's primitive."""
    rest = np.flatnonzero(seg.free)
    if len(rest) == 0 or not len(seg):
        return
    owner = seg.labels
    assigned = np.flatnonzero(owner >= 0)
    P = ctx.pre.points
    dist, j = cKDTree(P[assigned]).query(P[rest], distance_upper_bound=2 * ctx.link, workers=threads(ctx))
    ok = np.isfinite(dist)
    rest, near = rest[ok], owner[assigned[j[ok]]]
    for k in np.unique(near).tolist():
        pts = rest[near == k]
        # On a noisy cloud ε is 6 σ: a band that wide beyond a surface is
        # another surface's (its own points lie within τ = 3 σ).
        pts = pts[surface_distance(seg.records[k], P[pts])[0] < (ctx.tau if ctx.policy.absorb_within_tau
                                                                  else ctx.epsilon)]
        seg.assign(pts, k)
