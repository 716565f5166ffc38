"""Splitting phase (paper §5.3).

What the recognition step leaves is clustered with DBSCAN; every cluster is
put in each family's standard form and recognised again. A cluster where
nothing is recognised is over-segmented with CGAL's Efficient RANSAC
(:mod:`houghcad.ransac`), and each RANSAC piece goes through the Hough
recognition: RANSAC only proposes regions, the vote decides type and
parameters. A cluster recognised only in fragments (no piece a
``fragment_share`` of it) is split by RANSAC too, and the split in larger
pieces wins (our extension).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from .aligned import aligned_features
from .context import Context
from .families import Family
from .families.base import on_one_line
from .growth import absorb, accept
from .normals import pca_normals
from .ransac import ransac_pieces
from .clusters import dbscan
from .recognize import recognize
from .state import Candidate, Segmentation


def clusters(idx: np.ndarray, ctx: Context) -> list[np.ndarray]:
    """DBSCAN clusters (global indices) of the points ``idx``, largest first."""
    if len(idx) < ctx.min_points:
        return []
    lab = dbscan(ctx.pre.points[idx], ctx.link, ctx.tol.splitting.cluster_min_samples, ctx.link_scales(idx))
    out = [idx[lab == k] for k in range(lab.max() + 1)]
    out = [c for c in out if len(c) >= ctx.min_points]
    return sorted(out, key=lambda c: (-len(c), int(c[0])))


#: Clusters go to the workers one per task unless the largest holds more than this share of
#: their points (then its own families and peaks are spread instead).
CLUSTER_SHARE = 0.5


def splitting_phase(seg: Segmentation, families: list[Family], ctx: Context,
                    progress: Callable[[int], None] | None = None) -> None:
    """Iterate DBSCAN clustering + recognition on what is left, in place.
    ``progress(n)`` is called after each cluster of n points.

    Within a round every cluster is recognised on its points at the start of
    the round (on the run's workers when there are some: the clusters are then
    independent); the segments found are taken in order of cluster size, each
    keeping the points that the segments taken before it and their growth left
    free, refitted on them. The next round reclusters what remains. (Our
    change to the paper's loop, which recognises each cluster after the
    previous one's segments have grown: same DSC on the Fit4CAD folds, and it
    lets the clusters run on both cores.)"""
    lctx = replace(ctx, local=True)
    t = ctx.tol.splitting
    for _ in range(t.max_rounds):
        free0 = seg.free
        found_any = False
        cls = clusters(np.flatnonzero(free0), ctx)
        seen = [cl[free0[cl]] for cl in cls]
        ahead = _recognised_ahead(seen, families, lctx, free0)
        for k, cl in enumerate(cls):
            avail = seg.free
            cl = cl[avail[cl]]
            if len(cl) < ctx.min_points:
                continue
            # Without workers each cluster is recognised when its turn comes
            # (one swallowed by the segments before it costs nothing), on its
            # points at the round's start all the same.
            got, pieces = ahead(k) or (recognize(seen[k], families, lctx, free0), None)
            found = _still_free(got, avail, ctx)
            # Extension: a cluster recognised only in fragments goes to the RANSAC fallback as
            # well. The placements come from the cluster's normals, and where several surfaces
            # share them (a wall end rounded by two fillets with a narrow flat between: their
            # normal lines meet between the fillets' centres) they fit none: each candidate then
            # keeps a slice. RANSAC's regions grow from minimal samples of one surface. The
            # features aligned with the neighbours compete in the same way (a small torus through
            # a countersink and its hole would hide the cone and cylinder about the hole's axis);
            # where the vote found nothing, so do the cluster's own crease normals and RANSAC (the
            # rows of a cylinder sampled in rows lie at levels across its neighbour's normal, a
            # few points each: the cylinder through them all explains more). Of all, the split
            # that explains the cluster in larger pieces is taken.
            fragmented = bool(got) and _wants_ransac(got, seen[k], ctx)
            if fragmented:
                found = _larger(found, _still_free(_ransac_pieces(pieces, seen[k], families, lctx, free0), avail, ctx))
            if not found or fragmented:
                found = _larger(found, aligned_features(cl, families, seg, lctx))
            if not got:
                found = _larger(found, _still_free(own_normals_recognised(seen[k], families, lctx, free0), avail, ctx))
                if _wants_ransac(got, seen[k], ctx):
                    found = _larger(found, _still_free(_ransac_pieces(pieces, seen[k], families, lctx, free0),
                                                       avail, ctx))
            accept(found, seg, ctx)
            found_any |= bool(found)
            if found:
                absorb(seg, ctx)
            if progress is not None:
                progress(len(cl))
        if not found_any:
            break


def _still_free(found: list[Candidate], avail: np.ndarray, ctx: Context) -> list[Candidate]:
    """The candidates cut to their points ``avail`` (bool (n,)) leaves, those
    still of a segment's size."""
    out = []
    for c in found:
        keep = avail[c.indices]
        if keep.all():
            out.append(c)
        elif keep.sum() >= ctx.min_points:
            # Refitted on what is left, as recognising the cluster now would.
            idx = c.indices[keep]
            P = ctx.pre.points[idx]
            # Points on one line determine no surface: every primitive of a
            # family through that line fits them exactly, and the refit would
            # stop wherever rounding sends it along that family (different
            # answers from bit-identical inputs). The candidate keeps its fit.
            prim = None if on_one_line(P) else c.family.fit(c.prim, P, ctx.pre.normals[idx])
            ok = prim is not None and c.family.valid(prim, ctx)
            out.append(replace(c, prim=prim if ok else c.prim, indices=idx))
    return out


def ransac_recognised(cl: np.ndarray, families: list[Family], ctx: Context,
                      avail: np.ndarray) -> list[Candidate]:
    """What the Hough recognition finds in each region CGAL's RANSAC proposes on
    the cluster ``cl``, in order. The regions are disjoint and a region's
    candidates hold its points only, so each region is recognised on its own
    (on the run's workers when there are some)."""
    pieces = [p[avail[p]] for p in ransac_pieces(cl, ctx)]
    got = ctx.workers.run("recognize", [(p, families, None) for p in pieces], ctx) if ctx.workers else None
    if got is None:
        got = [recognize(p, families, ctx, avail) for p in pieces]
    return [c for found in got for c in found]


def recognise_cluster(cl: np.ndarray, families: list[Family], ctx: Context,
                      avail: np.ndarray) -> tuple[list[Candidate], list[Candidate] | None]:
    """A cluster's recognition, and, when :func:`_wants_ransac` sends the
    cluster to the fallback, its RANSAC regions' (None otherwise): what the
    splitting loop needs of a cluster that depends on its points alone."""
    found = recognize(cl, families, ctx, avail)
    return found, (ransac_recognised(cl, families, ctx, avail) if _wants_ransac(found, cl, ctx) else None)


def _wants_ransac(found: list[Candidate], cl: np.ndarray, ctx: Context) -> bool:
    """Whether the cluster ``cl``, whose recognition gave ``found``, goes to the RANSAC fallback:
    it is large enough, and recognition found nothing or only pieces each a small share of it
    (the one rule of the splitting loop and of :func:`recognise_cluster` on the workers)."""
    t = ctx.tol.splitting
    fragmented = not found or max(len(c.indices) for c in found) < t.fragment_share * len(cl)
    return fragmented and len(cl) >= t.ransac_min_size * ctx.min_points


def _ransac_pieces(pieces: list[Candidate] | None, cl: np.ndarray, families: list[Family], ctx: Context,
                   avail: np.ndarray) -> list[Candidate]:
    """RANSAC's regions of the cluster ``cl`` as recognised: ``pieces`` when the workers computed
    them ahead (under :func:`_wants_ransac`, as here), else computed now."""
    return pieces if pieces is not None else ransac_recognised(cl, families, ctx, avail)


def _piece_score(found: list[Candidate]) -> float:
    """How well candidates explain their points in few pieces: the sum of their squared sizes
    (the same points in larger pieces score more)."""
    return float(sum(len(c.indices) ** 2 for c in found))


def _larger(found: list[Candidate], alt: list[Candidate]) -> list[Candidate]:
    """Whichever of two explanations of a cluster is in larger pieces (``found`` on a tie)."""
    return alt if _piece_score(alt) > _piece_score(found) else found


def own_normals_recognised(cl: np.ndarray, families: list[Family], ctx: Context,
                           avail: np.ndarray) -> list[Candidate]:
    """The cluster's recognition with its crease points' normals read from the cluster's own
    points (:func:`cluster_context`); nothing when none of them changes."""
    own = cluster_context(cl, ctx)
    return recognize(cl, families, own, avail) if own is not ctx else []


def cluster_context(cl: np.ndarray, ctx: Context) -> Context:
    """``ctx`` with the normals of the cluster's crease points (global indices ``cl``) estimated
    again from the cluster's own points (extension).

    A crease point's normal was voted among neighbours on both faces of its crease, and on a
    small face (a hole a few spacings wide, a counterbore's step) it is often the large
    neighbour's. Once the large faces hold their points, the cluster's points near a crease
    point are the small face's own: PCA on the few nearest of them reads its orientation.
    Neighbourhoods on one row of points (no plane through them) keep the voted normal."""
    crease = ctx.pre.crease
    if crease is None or len(cl) < ctx.tol.splitting.crease_neighbours:
        return ctx
    rows = np.flatnonzero(crease[cl])
    if len(rows) == 0:
        return ctx
    k = ctx.tol.splitting.crease_neighbours
    P = ctx.pre.points[cl]
    _, nb = cKDTree(P).query(P[rows], k=k)
    nrm, ev = pca_normals(P, nb.astype(np.int32))
    flat = ev[:, 1] >= ctx.tol.splitting.crease_row_ratio * ev[:, 2]
    N = ctx.pre.normals.copy()
    N[cl[rows[flat]]] = nrm[flat]
    return replace(ctx, pre=replace(ctx.pre, normals=N))


def _recognised_ahead(seen: list[np.ndarray], families: list[Family], ctx: Context, free: np.ndarray) \
        -> Callable[[int], tuple[list[Candidate], list[Candidate] | None] | None]:
    """What :func:`recognise_cluster` gives on cluster k's points ``seen[k]`` (free in ``free``,
    bool (n,)), computed on the run's workers, as a function of k that waits for it; None for
    the clusters left to the caller (all of them when there are no workers)."""
    todo = [k for k, s in enumerate(seen) if len(s) >= ctx.min_points]
    if not ctx.workers or not todo:
        return lambda k: None
    # Clusters come largest first: the costliest are handed out first. When
    # one cluster holds most of the points, it would keep one worker busy
    # while the others idle: it is left to the caller, who recognises it with
    # its families and peaks spread over the workers, and the workers take the
    # other clusters between those tasks.
    if len(seen[todo[0]]) > CLUSTER_SHARE * sum(len(seen[k]) for k in todo):
        todo = todo[1:]
    wait = ctx.workers.submit("cluster", [(seen[k], families, None) for k in todo], ctx)
    if wait is None:
        return lambda k: None
    waited: list[dict[int, tuple]] = []
    handed = set(todo)

    def result(k: int) -> tuple[list[Candidate], list[Candidate] | None] | None:
        if k not in handed:  # the caller's own: it works on it while the workers take the rest
            return None
        if not waited:
            done = wait()
            waited.append(dict(zip(todo, done)) if done is not None else {})
        return waited[0].get(k)

    return result
