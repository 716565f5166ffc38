"""Adjacency between segments: which segments touch, and how."""

from __future__ import annotations

import numpy as np

from .boundaries import _neighbour_owners
from .context import Context
from .state import Segmentation


def smooth_adjacency(seg: Segmentation, ctx: Context, smooth: bool = True,
                     crease: float | None = None) -> np.ndarray:
    """Pairs (m, 2) of segments that meet along a tangent-continuous boundary.

    Two segments touch where a point of one has a neighbour (within ``link``)
    in the other; the contact is smooth where the two primitives' normals at
    those points agree within the angle tolerance (the fitted surfaces', not
    the estimated normals, which blur across a crease) for most contacts.
    A pair needs √(points of the smaller) / ``contact_divisor`` contact points, and ``contact_min``:
    a boundary, not a corner. ``smooth=False``: any such contact. ``crease``
    (radians): the angle within which normals agree (default: half the
    angle tolerance, ``crease_angles``).
    """
    t = ctx.tol.adjacency
    if len(seg) < 2:
        return np.zeros((0, 2), np.int64)
    P = ctx.pre.points
    owner = seg.owner()
    sn = np.zeros_like(P)
    for s in seg:
        sn[s.indices] = s.family.surface_normals(s.prim, P[s.indices])
    pts = np.flatnonzero(owner >= 0)
    nb, other = _neighbour_owners(owner, pts, ctx, ctx.link, t.neighbours)
    mine = owner[pts][:, None]
    cos = np.abs(np.einsum("ij,ikj->ik", sn[pts], sn[nb]))
    mask = (other >= 0) & (other != mine)
    if not mask.any():
        return np.zeros((0, 2), np.int64)
    n = len(seg)
    a, b = np.broadcast_to(mine, other.shape)[mask], other[mask]
    pi = np.broadcast_to(pts[:, None], other.shape)[mask]
    pair = np.minimum(a, b) * n + np.maximum(a, b)
    # Per pair: contact points (each once) and the share of contacts whose
    # normals agree within half the tolerance (a crease of a few degrees
    # between two faces is still a crease).
    key = np.unique(pair * len(P) + pi)
    pair_u, count = np.unique(key // len(P), return_counts=True)
    agree = cos[mask] >= np.cos(t.crease_angles * ctx.angle if crease is None else crease)
    share = np.bincount(np.searchsorted(pair_u, pair), weights=agree, minlength=len(pair_u)) / \
        np.bincount(np.searchsorted(pair_u, pair), minlength=len(pair_u))
    sizes = seg.sizes()
    u, v = pair_u // n, pair_u % n
    least = np.maximum(t.contact_min, np.sqrt(np.minimum(sizes[u], sizes[v])) / t.contact_divisor)
    keep = ((share >= t.smooth_share) | (not smooth)) & (count >= least)
    return np.stack([u[keep], v[keep]], axis=1)
