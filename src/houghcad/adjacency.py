"""Adjacency between segments: one graph, with contact counts, for every pass that asks.

Two segments touch where a point of one lies within the link distance of a
point of the other. :class:`SegmentGraph` records, for every pair of segments
in contact, the pairs of points across their boundary, how many of each
side's points touch the other, and which cross pairs those are. The passes
read it with their own rule:

- consolidation: a tangent-continuous boundary (:func:`smooth_adjacency`);
- fillets: a corner, by the number of close pairs (:mod:`houghcad.blend`);
- association: a line contact on both sides, not a point (:mod:`houghcad.associate`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from .context import Context, threads
from .state import Segmentation
from .normals import tree_query

if TYPE_CHECKING:
    from .families import Family
    from .families.base import Primitive


@dataclass(frozen=True)
class SegmentGraph:
    """Segments in contact, with their contact counts.

    Attributes
    ----------
    n_segments : int
    edges : ndarray (k, 2) of int64
        Pairs (u < v) of segments with at least one close pair of points.
    close_pairs : ndarray (k,)
        Pairs of points across each edge, closer than the link.
    contact : ndarray (k, 2)
        Distinct points of u touching v, and of v touching u.
    cross : ndarray (m, 2) of int64
        The close point pairs (global indices), u's point first.
    edge_of : ndarray (m,)
        The edge (row of ``edges``) of each cross pair.
    """

    n_segments: int
    edges: np.ndarray
    close_pairs: np.ndarray
    contact: np.ndarray
    cross: np.ndarray
    edge_of: np.ndarray

    @classmethod
    def build(cls, labels: np.ndarray, P: np.ndarray, link: float, k: int | None = None,
              tree: cKDTree | None = None, workers: int = 1,
              table: tuple[np.ndarray, np.ndarray] | None = None,
              pairs: np.ndarray | None = None) -> "SegmentGraph":
        """The graph of the segments ``labels`` (n,) (-1: free) over points P (n, 3).

        With ``k`` the contacts are each segmented point's k nearest points
        of the cloud within ``link`` (``tree``: a KD-tree on all of P), read
        from the querying point: ``close_pairs`` counts these directed pairs,
        ``contact`` the distinct querying points on each side, and ``cross``
        holds (querying point, neighbour). Without it every pair of segmented
        points closer than ``link`` counts once. ``workers``: the query's
        threads (the result does not depend on them). ``table``: every point's k
        nearest within ``link`` as :meth:`~houghcad.preprocess.Preprocessed.neighbours_within`
        gives them, read instead of querying ``tree``. ``pairs``: without ``k``, every pair of
        points closer than ``link`` as :meth:`~houghcad.preprocess.Preprocessed.pairs_within`
        gives them, read instead of querying a tree of the segmented points (the same pairs, in
        another order: ``cross`` comes in that order, every count is the same).
        """
        labels = np.asarray(labels, dtype=np.int64)
        m = max(int(labels.max(initial=-1)) + 1, 1)
        owned = np.flatnonzero(labels >= 0)
        if k is None and pairs is not None:
            both = (labels[pairs[:, 0]] >= 0) & (labels[pairs[:, 1]] >= 0)
            a, b = pairs[both, 0].astype(np.int64), pairs[both, 1].astype(np.int64)
        elif k is None:
            close = cKDTree(P[owned]).query_pairs(link, output_type="ndarray") if len(owned) > 1 else \
                np.zeros((0, 2), np.int64)
            a, b = owned[close[:, 0]], owned[close[:, 1]]
        else:
            if table is not None:
                nb, ok = table[0][owned], table[1][owned]
            else:
                tree = cKDTree(P) if tree is None else tree
                dist, nb = tree_query(tree, P[owned], workers, k=min(k, len(P)), distance_upper_bound=link)
                ok = np.isfinite(dist)
            a = np.broadcast_to(owned[:, None], nb.shape)[ok]
            b = nb[ok].astype(np.int64)
        la, lb = labels[a], labels[b]
        diff = (lb >= 0) & (la != lb)
        a, b, la, lb = a[diff], b[diff], la[diff], lb[diff]
        if k is None:  # u's point first
            swap = la > lb
            a, b, la, lb = np.where(swap, b, a), np.where(swap, a, b), np.minimum(la, lb), np.maximum(la, lb)
        u, v = np.minimum(la, lb), np.maximum(la, lb)
        keys, edge_of, close_pairs = np.unique(u * m + v, return_inverse=True, return_counts=True)
        edge_of = edge_of.ravel().astype(np.int64)
        edges = np.stack([keys // m, keys % m], axis=1)
        contact = np.zeros((len(keys), 2), np.int64)
        n = max(len(P), 1)
        if k is None:
            sides = ((a, np.ones(len(a), bool)), (b, np.ones(len(b), bool)))
        else:  # the querying point, on whichever side it lies
            sides = ((a, la == u), (a, la == v))
        for side, (pts, on) in enumerate(sides):
            distinct = np.unique(edge_of[on] * n + pts[on])
            contact[:, side] = np.bincount(distinct // n, minlength=len(keys))
        return cls(m, edges, close_pairs, contact, np.stack([a, b], axis=1), edge_of)

    @classmethod
    def of(cls, seg: Segmentation, ctx: Context, k: int | None = None) -> "SegmentGraph":
        """The graph of a segmentation state, at the run's link distance (see :meth:`build`)."""
        table = None if k is None else ctx.pre.neighbours_within(k, ctx.link, threads(ctx))
        pairs = ctx.pre.pairs_within(ctx.link) if k is None else None
        return cls.build(seg.labels, ctx.pre.points, ctx.link, k, ctx.pre.tree, threads(ctx), table, pairs)

    def neighbours(self, keep: np.ndarray | None = None) -> dict[int, set[int]]:
        """Each segment's neighbours over the edges ``keep`` (bool (k,); default all)."""
        out: dict[int, set[int]] = {}
        sel = self.edges if keep is None else self.edges[keep]
        for u, v in sel.tolist():
            out.setdefault(u, set()).add(v)
            out.setdefault(v, set()).add(u)
        return out

    def agreement(self, normals: np.ndarray, cos_min: float) -> np.ndarray:
        """Share (k,) of each edge's cross pairs whose surface normals
        ``normals`` (n, 3) agree within the angle of cosine ``cos_min``."""
        cos = np.abs(np.einsum("ij,ij->i", normals[self.cross[:, 0]], normals[self.cross[:, 1]]))
        agree = np.bincount(self.edge_of, weights=cos >= cos_min, minlength=len(self.edges))
        return agree / np.maximum(self.close_pairs, 1)


def smooth_adjacency(seg: Segmentation, ctx: Context, smooth: bool = True,
                     crease: float | None = None, graph: SegmentGraph | None = None) -> np.ndarray:
    """Pairs (m, 2) of segments that meet along a tangent-continuous boundary.

    Contacts are each point's ``neighbours`` nearest points within the link.
    The contact is smooth where the two primitives' normals at the close
    pairs agree within half the angle tolerance (``crease_angles``; the fitted
    surfaces', not the estimated normals, which blur across a crease) for most
    of them (``smooth_share``). A pair needs √(points of the smaller) /
    ``contact_divisor`` contact points on its two sides together, and
    ``contact_min``: a boundary, not a corner. ``smooth=False``: any such
    contact. ``crease`` (radians): the angle within which normals agree.
    """
    t = ctx.tol.adjacency
    if len(seg) < 2:
        return np.zeros((0, 2), np.int64)
    g = SegmentGraph.of(seg, ctx, t.neighbours) if graph is None else graph
    if not len(g.edges):
        return np.zeros((0, 2), np.int64)
    sizes = seg.sizes()
    u, v = g.edges[:, 0], g.edges[:, 1]
    least = np.maximum(t.contact_min, np.sqrt(np.minimum(sizes[u], sizes[v])) / t.contact_divisor)
    keep = g.contact.sum(axis=1) >= least
    if smooth:
        P = ctx.pre.points
        sn = np.zeros_like(P)
        for s in seg:
            sn[s.indices] = s.family.surface_normals(s.prim, P[s.indices])
        angle = t.crease_angles * ctx.angle if crease is None else crease
        keep &= g.agreement(sn, float(np.cos(angle))) >= t.smooth_share
    return g.edges[keep]


def border_points(idx: np.ndarray, labels: np.ndarray, ctx: Context, k: int) -> np.ndarray:
    """Points (global indices, sorted) that segments other than the points ``idx``' own hold among
    each point's ``k`` nearest within the link: the boundary rows of the neighbouring faces.
    ``labels`` (n,): each point's segment, -1 free."""
    P = ctx.pre.points
    if not len(idx):
        return np.zeros(0, np.int64)
    dist, nb = ctx.pre.tree.query(P[idx], k=min(k, len(P)), distance_upper_bound=ctx.link)
    nb = np.unique(nb[np.isfinite(dist)])
    own = np.unique(labels[idx])
    return nb[(labels[nb] >= 0) & ~np.isin(labels[nb], own)]


def row_support(family: Family, prim: Primitive, border: np.ndarray, ctx: Context) -> int:
    """How many of the boundary points ``border`` (global indices) lie within τ of ``prim``.

    A face one or two rows wide lies on every surface through its rows (a circle on its plane, on
    a cylinder, a cone, a sphere through it), so its own points cannot choose among them. The
    neighbouring faces' boundary rows on either side lie on the face as well, as its boundary
    curves: the surface that holds them is the face's."""
    if not len(border):
        return 0
    return int((family.distance(prim, ctx.pre.points[border]) <= ctx.tau).sum())
