"""Growth of accepted segments: the paper's removal of the points within ε of
a recognised primitive (:func:`grow`), and the absorption of leftover points
by the segment of their nearest assigned neighbour (extension)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .context import Context, threads
from .state import Candidate, Segmentation, surface_distance
from .normals import tree_query


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
    neighbour when it lies within ε (noisy clouds: τ) of that segment's primitive.

    On noisy clouds (extension, ``policy.absorb_inwards``) the point goes to the
    segment, among those of its ``absorb_neighbours`` nearest assigned points, whose
    surface is nearest within τ, and rounds repeat from the points just given: a
    refit there releases whole bands of a face's scatter, whose inner points have no
    assigned neighbour and whose rim's nearest one may lie across the edge.
    """
    P = ctx.pre.points
    t = ctx.tol.boundaries
    # On a noisy cloud ε is 6 σ: a band that wide beyond a surface is
    # another surface's (its own points lie within τ = 3 σ).
    band = ctx.tau if ctx.policy.absorb_within_tau else ctx.epsilon
    inwards = ctx.policy.absorb_inwards
    for _ in range(t.absorb_rounds if inwards else 1):
        rest = np.flatnonzero(seg.free)
        if len(rest) == 0 or not len(seg):
            return
        assigned = np.flatnonzero(seg.labels >= 0)
        k = min(t.absorb_neighbours if inwards else 1, len(assigned))
        dist, j = tree_query(cKDTree(P[assigned]), P[rest], threads(ctx), k=k, distance_upper_bound=2 * ctx.link)
        dist, j = dist.reshape(len(rest), k), j.reshape(len(rest), k)  # k = 1 gives flat arrays
        ok = np.isfinite(dist)
        pairs = np.unique(np.c_[np.nonzero(ok)[0], seg.labels[assigned[j[ok]]]], axis=0)
        to = _nearest_surface(seg, P[rest], pairs, band)
        if not (to >= 0).any():
            return
        for s in np.unique(to[to >= 0]).tolist():
            seg.assign(rest[to == s], s)


def _nearest_surface(seg: Segmentation, X: np.ndarray, pairs: np.ndarray, band: float) -> np.ndarray:
    """For points X (m, 3) and candidate (point row, segment) ``pairs`` (p, 2): each point's
    segment whose surface is nearest within ``band`` (m,), -1 for none."""
    best = np.full(len(X), np.inf)
    to = np.full(len(X), -1)
    # Pairs grouped by segment with one sort, not one scan of every pair per segment (as
    # houghcad.multires.propagate does).
    by_seg = np.argsort(pairs[:, 1], kind="stable")
    present, starts = np.unique(pairs[by_seg, 1], return_index=True)
    for s, sel in zip(present.tolist(), np.split(by_seg, starts[1:])):
        r = pairs[sel, 0]
        d = surface_distance(seg.records[s], X[r])[0]
        take = (d < band) & (d < best[r])
        best[r[take]] = d[take]
        to[r[take]] = s
    return to
