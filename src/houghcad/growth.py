"""Growth of accepted segments: the paper's removal of the points within ε of
a recognised primitive (:func:`grow`), and the absorption of leftover points
by the segment of their nearest assigned neighbour (extension)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from .boundaries import surface_distance
from .context import Context
from .state import Candidate, owners


def grow(c: Candidate, free: np.ndarray, ctx: Context) -> Candidate:
    """Add the free points within ε of the primitive that touch the segment
    (paper: points closer than ε to a recognised primitive are removed)."""
    cand = np.flatnonzero(free)
    if len(cand) == 0:
        return c
    P = ctx.pre.points
    d = c.family.distance(c.prim, P[cand])
    cand = cand[d < ctx.epsilon]
    if len(cand) == 0:
        return c
    sn = c.family.surface_normals(c.prim, P[cand])
    cand = cand[np.abs(np.einsum("ij,ij->i", sn, ctx.pre.normals[cand])) >= ctx.cos_angle]
    if len(cand) == 0:
        return c
    dist, _ = cKDTree(P[c.indices]).query(P[cand], distance_upper_bound=ctx.link)
    add = cand[np.isfinite(dist)]
    if len(add) == 0:
        return c
    free[add] = False
    return replace(c, indices=np.union1d(c.indices, add))

def accept(found: list[Candidate], free: np.ndarray, ctx: Context, segments: list[Candidate]) -> None:
    """Remove the points of accepted candidates from ``free``, then grow them."""
    for c in found:
        free[c.indices] = False
    for c in found:
        segments.append(grow(c, free, ctx))

def absorb(segments: list[Candidate], free: np.ndarray, ctx: Context) -> None:
    """Give each leftover point to the segment of its nearest assigned
    neighbour when it lies within ε (noisy clouds: τ) of that segment's primitive."""
    rest = np.flatnonzero(free)
    if len(rest) == 0 or not segments:
        return
    owner = owners(segments, len(free))
    assigned = np.flatnonzero(owner >= 0)
    P = ctx.pre.points
    dist, j = cKDTree(P[assigned]).query(P[rest], distance_upper_bound=2 * ctx.link)
    ok = np.isfinite(dist)
    rest, seg = rest[ok], owner[assigned[j[ok]]]
    for k in np.unique(seg):
        pts = rest[seg == k]
        s = segments[k]
        # On a noisy cloud ε is 6 σ: a band that wide beyond a surface is
        # another surface's (its own points lie within τ = 3 σ).
        pts = pts[surface_distance(s, P[pts])[0] < (ctx.tau if ctx.noisy else ctx.epsilon)]
        if len(pts):
            free[pts] = False
            segments[k] = replace(s, indices=np.union1d(s.indices, pts))
