"""Planes for curved segments (extension): a plane takes a curved segment it
fits as well, and planes that fit a loosely fitted curved surface exactly take
it in strips (a chamfered edge)."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .adjacency import SegmentGraph, border_points, row_support
from .context import Context
from .families import Family
from .families.base import Primitive
from .state import SegmentRecord, Segmentation, SegmentView

#: Families whose segments a plane, or planes, may take.
CURVED = ("cylinder", "cone", "sphere", "torus")


def prefer_planes(seg: Segmentation, families: list[Family], ctx: Context) -> int:
    """Give planes to the curved segments that planes fit as well, in place;
    returns how many segments changed.

    A cylinder or sphere of radius many times a face's width sags off it by
    less than the noise: on a noisy plane face it fits as well as the plane
    and may win the face by size (radii of 66 and 250 diagonals after the
    final refit, on two box faces). A cylinder, cone, sphere or torus is
    compared with the plane by MSAC cost over all the segment's points; the
    plane takes the segment unless it is worse by more than two standard
    errors (so does a short arc of a small hole that the noise leaves flat),
    or by the rounding of exact fits (``cover_taus``), which decides on exact
    samples: a strip one or two rows wide (a chamfer, a land) lies on a plane
    and on every cylinder through its rows, and the blended normals there
    often vote the cylinder alone. The boundary rows of the faces beside the
    strip decide between the two: a curve that fits exactly and holds more of
    them than the plane stays (:func:`_rows_curve`: the middle row of a band
    whose edge rows went to its neighbours). Curved segments that fit their points
    loosely may then go to several planes (:func:`split_into_facets`). A
    ``fixed`` primitive (a fillet found by :mod:`houghcad.blend`) stays.
    """
    plane = next((f for f in families if f.name == "plane"), None)
    if plane is None:
        return 0
    P, N = ctx.pre.points, ctx.pre.normals
    t = ctx.tol.consolidation
    exact = t.cover_taus * ctx.tau
    changed = 0
    loose: dict[int, np.ndarray] = {}
    for k, s in enumerate(seg):
        if s.family.name not in CURVED or s.fixed:
            continue
        Q = P[s.indices]
        d_own = np.minimum(s.family.distance(s.prim, Q), ctx.tau)
        if len(Q) >= t.plane_min_points:
            n0, c = _pca_plane(Q)
            prim = plane.fit(Primitive("plane", {"normal": n0, "offset": float(n0 @ c)}), Q, N[s.indices])
            if prim is not None:
                d_pl = np.minimum(plane.distance(prim, Q), ctx.tau)
                if d_pl.mean() <= d_own.mean() + max(t.plane_se * d_own.std() / np.sqrt(len(Q)), exact) \
                        and not _rows_curve(s, prim, d_own, plane, seg, ctx):
                    seg.set_record(k, SegmentRecord(plane, prim))
                    changed += 1
                    continue
        if d_own.mean() > t.facet_exact_ratio * exact:
            loose[k] = d_own
    return changed + split_into_facets(seg, loose, plane, ctx)


def _rows_curve(s: SegmentView, prim: Primitive, d_own: np.ndarray, plane: Family, seg: Segmentation,
                ctx: Context) -> bool:
    """Whether the curved segment ``s`` of ``seg`` (its points at distances ``d_own`` from its
    surface), which the plane ``prim`` fits as well, keeps its curve: it fits its points to the
    rounding of an exact fit, and the neighbouring faces' boundary rows beside it lie on the curve
    more than on the plane (a band whose edge rows went to its neighbours: its middle row lies on
    its own plane too, :func:`houghcad.adjacency.row_support`)."""
    if d_own.mean() > ctx.tol.consolidation.cover_taus * ctx.tau:
        return False
    border = border_points(s.indices, seg.labels, ctx, ctx.tol.splitting.aligned_neighbours)
    return row_support(s.family, s.prim, border, ctx) > row_support(plane, prim, border, ctx)


def split_into_facets(seg: Segmentation, loose: dict[int, np.ndarray], plane: Family, ctx: Context) -> int:
    """Give the loosely fitted curved segments ``loose`` (id: distances (m,) of
    its points to its primitive, capped at τ) to planes that fit them exactly,
    in place; returns how many segments went.

    On exact samples a chamfered edge (plane strips one or two rows wide at
    obtuse angles) is as near a cylinder as a polygon is to its circle:
    within the inlier distance, so a curve takes the strips together, often
    in several short pieces along the edge, while each strip lies on its
    plane to the rounding of exact fits and the curve sags off them. Planes
    are found over each group of adjacent loose segments
    (:func:`exact_planes`); a segment goes to them when they hold
    ``facet_cover`` of its points within that rounding and fit it better than
    its curve by the rounding. A true curved face in the group (a hole's wall
    touching a chamfer) stays: its curve fits it, and no plane holds more
    than two of its rows.
    """
    if not loose:
        return 0
    P = ctx.pre.points
    t = ctx.tol.consolidation
    exact = t.cover_taus * ctx.tau
    ids = np.array(sorted(loose))
    pos = np.full(len(seg), -1)
    pos[ids] = np.arange(len(ids))
    # Any contact groups them: each segment's own points decide whether it goes.
    pairs = SegmentGraph.of(seg, ctx, ctx.tol.adjacency.neighbours).edges if len(ids) > 1 else \
        np.zeros((0, 2), np.int64)
    pairs = pos[pairs[(pos[pairs] >= 0).all(axis=1)]] if len(pairs) else pairs
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(ids),) * 2)
    _, comp = connected_components(g, directed=False)
    rng = np.random.default_rng(ctx.seed)
    gone = 0
    for c in range(comp.max() + 1):
        group = ids[comp == c].tolist()
        idx = np.concatenate([seg.indices(k) for k in group])
        planes = exact_planes(P[idx], exact, ctx.min_points, ctx, rng)
        if not planes:
            continue
        dist = np.stack([plane.distance(p, P[idx]) for p in planes])
        near = dist.min(axis=0)
        member = np.repeat(np.arange(len(group)), [len(loose[k]) for k in group])
        on = np.bincount(member, weights=near <= exact, minlength=len(group))
        fit = np.bincount(member, weights=np.minimum(near, ctx.tau), minlength=len(group))
        sizes = np.bincount(member, minlength=len(group))
        own = np.array([loose[k].mean() for k in group])
        goes = (on >= t.facet_cover * sizes) & (fit / sizes + exact <= own)
        if goes.any():
            gone += _give(seg, [k for k, go in zip(group, goes) if go], idx[goes[member]], planes,
                          dist[:, goes[member]], plane, ctx)
    seg.remove_empty()
    return gone


def _give(seg: Segmentation, members: list[int], idx: np.ndarray, planes: list[Primitive], dist: np.ndarray,
          plane: Family, ctx: Context) -> int:
    """The segments ``members`` (their points ``idx``, at distances ``dist``
    (planes, m) from the ``planes``) become the planes that hold at least
    ``min_points`` of them; each point goes to its nearest plane within τ, or
    is freed (a row of a neighbour the curve held). Members beyond the planes
    are left empty."""
    for _ in range(len(planes)):
        counts = np.bincount(dist.argmin(axis=0), minlength=len(planes))
        if counts.min() >= ctx.min_points:
            break
        keep = counts > counts.min()
        if not keep.any():
            return 0
        planes, dist = [p for p, k in zip(planes, keep) if k], dist[keep]
    near = dist.argmin(axis=0)
    near[dist.min(axis=0) > ctx.tau] = -1
    seg.release(idx[near < 0])
    for j, p in enumerate(planes):
        if j < len(members):
            seg.set_record(members[j], SegmentRecord(plane, p))
            seg.set_points(members[j], idx[near == j])
        else:
            seg.add(SegmentRecord(plane, p), idx[near == j])
    return len(members)


def exact_planes(Q: np.ndarray, exact: float, min_points: int, ctx: Context, rng: np.random.Generator) \
        -> list[Primitive]:
    """Up to ``facet_max_planes`` planes, largest first, each holding at least
    ``min_points`` of the points Q (m, 3) within ``exact`` (world units)
    that no earlier plane holds.

    Sequential RANSAC: planes through three points drawn among those left,
    scored on a bounded sample of them, the best refitted by least squares.
    Written here because scikit-learn's RANSACRegressor fits a graph
    z = f(x, y), not planes of every orientation, one after another.
    """
    t = ctx.tol.consolidation
    left = np.arange(len(Q))
    out: list[Primitive] = []
    while len(out) < t.facet_max_planes and len(left) >= max(3, min_points):
        score = left if len(left) <= t.facet_score_points else \
            np.sort(rng.choice(left, t.facet_score_points, replace=False))
        tri = Q[left[rng.integers(0, len(left), size=(t.facet_samples, 3))]]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        ln = np.linalg.norm(nrm, axis=1)
        ok = ln > 0
        if not ok.any():
            break
        nrm, off = nrm[ok] / ln[ok, None], np.einsum("ij,ij->i", nrm[ok], tri[ok, 0]) / ln[ok]
        b = int(np.argmax((np.abs(Q[score] @ nrm.T - off) <= exact).sum(axis=0)))
        on = left[np.abs(Q[left] @ nrm[b] - off[b]) <= exact]
        if len(on) < max(3, min_points):
            break
        n, c = _pca_plane(Q[on])
        on = left[np.abs((Q[left] - c) @ n) <= exact]
        if len(on) < min_points:
            break
        out.append(Primitive("plane", {"normal": n, "offset": float(n @ c)}))
        left = np.setdiff1d(left, on)
    return out


def _pca_plane(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares plane of the points Q (m, 3): its unit normal (3,), their least
    principal direction, and their centroid (3,), which it passes through."""
    return np.linalg.eigh(np.cov(Q.T))[1][:, 0], Q.mean(axis=0)
