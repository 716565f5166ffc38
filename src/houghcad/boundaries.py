"""Boundaries between adjacent segments (extensions): edge points settled
between the faces that explain them, and slivers dissolved into their
neighbours."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .context import Context, threads
from .state import Segmentation, surface_distance

#: Median distance of Gaussian-noisy points (σ = 1) to their exact surface: the median of |N(0, 1)|.
HALF_NORMAL_MEDIAN = 0.6745


def _neighbour_owners(owner: np.ndarray, pts: np.ndarray, ctx: Context, reach: float,
                      k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k nearest neighbours (m, k) of the points ``pts`` within ``reach``
    (missing ones as index 0) and their segments in ``owner`` (-1: none)."""
    nb, near = ctx.pre.neighbours_within(k, reach, threads(ctx))
    nb, near = nb[pts], near[pts]
    return nb, np.where(near, owner[nb], -1)


def _reassign(seg: Segmentation, owner: np.ndarray, best: np.ndarray, min_points: int) -> bool:
    """Move, in place, each point from segment ``owner`` to segment ``best``
    (both (n,), -1: none), except that a segment keeps at least min_points of
    its own. Returns whether any point moved."""
    moved = best != owner
    left = np.bincount(owner[(owner >= 0) & ~moved], minlength=len(seg))
    short = moved & (owner >= 0)
    short[short] = left[owner[short]] < min_points
    best = np.where(short, owner, best)
    if not (moved & ~short).any():
        return False
    seg.relabel(best)
    return True


def settle_edges(seg: Segmentation, ctx: Context, delta: float, reach: float) -> None:
    """Give each point to the nearest surface it lies on, and a point that lies on
    several adjacent segments' surfaces to the one with the smallest core.

    CAD samples include the faces' boundary curves, which lie on both faces;
    whoever was accepted first took them. To a narrow face (a fillet, a
    chamfer, a hole) those rows are a large share of its points, to a wide
    one a negligible share. A segment's core is its points that lie on no
    other surface: a narrow face that took the tangent bands of the wide
    ones beside it (a cylinder between two fillets) is large by its points
    and small by its core.

    A point lies on a surface within ``delta`` of it (standard units) and
    within an allowance of the nearest one: ``settle_slack`` τ, or
    ``settle_fits`` times the segment's median distance to its surface in
    excess of the noise's own, since a small face's fit leaves its boundary
    rows that far off it. A
    face that continues another tangentially (a plane beyond a fillet)
    passes within τ of the other's rows beside the tangent line, as the
    square of the distance from it, and a small surface crossing a face at
    a shallow angle within ``delta`` of a wide band of it; those points lie
    exactly on their own face and stay.

    A round settles the points next to a boundary (``neighbours`` of them
    within ``reach``); rounds repeat, at most ``settle_rounds``, while
    points move, since a band a segment took beside its boundary is
    deeper than one ring.
    """
    if len(seg) < 2:
        return
    # The points and the reach stay: one neighbour table serves every round.
    nb, near = ctx.pre.neighbours_within(ctx.tol.boundaries.neighbours, reach, threads(ctx))
    for _ in range(ctx.tol.boundaries.settle_rounds):
        if not _settle_round(seg, ctx, delta, nb, ~near):
            return


def _settle_round(seg: Segmentation, ctx: Context, delta: float, nb: np.ndarray, far: np.ndarray) -> bool:
    """One round of :func:`settle_edges` with every point's neighbours ``nb`` (n, k) within the
    reach (``far``: none there); whether any point moved."""
    P = ctx.pre.points
    owner = seg.owner()
    other = np.where(far, -1, owner[nb])
    mask = (other >= 0) & (other != owner[:, None])
    if not mask.any():
        return False
    # The distinct (segment, point) pairs, ordered by segment then point.
    n = len(P)
    key = np.unique(other[mask].astype(np.int64) * n + np.nonzero(mask)[0])
    pairs = np.stack([key // n, key % n], axis=1)
    own, fit = _owned_distances(seg, P)
    d = np.empty(len(pairs))
    for j in np.unique(pairs[:, 0]):
        at = pairs[:, 0] == j
        s = seg[int(j)]
        d[at] = s.family.distance(s.prim, P[pairs[at, 1]])
    # The nearest surface of each point: its own, or an adjacent one within delta.
    nearest = own.copy()
    ok = d < delta
    np.minimum.at(nearest, pairs[ok, 1], d[ok])
    t = ctx.tol.boundaries
    # A fit is only as sure as its error, which its median distance measures on exact samples;
    # noise adds its own median distance, HALF_NORMAL_MEDIAN σ, which no fit removes. Left in, it
    # makes every point within a few σ of an adjacent surface lie "on" it, and the band beside each
    # edge goes to the narrower face. (On exact samples the noise estimate reads curvature.)
    scatter = 0.0 if ctx.pre.exact else HALF_NORMAL_MEDIAN * ctx.pre.noise
    allow = np.maximum(t.settle_slack * ctx.tau, t.settle_fits * np.maximum(fit - scatter, 0.0))
    on = ok & (d <= nearest[pairs[:, 1]] + allow[pairs[:, 0]])
    if not on.any():
        return False
    # Cores: the points each segment owns that lie on no other surface.
    contested = np.zeros(len(P), dtype=bool)
    contested[pairs[on, 1]] = True
    core = np.bincount(owner[(owner >= 0) & ~contested], minlength=len(seg)).astype(np.int64)
    big = np.iinfo(np.int64).max
    own_ok = (owner >= 0) & (own <= nearest + allow[np.maximum(owner, 0)])
    best = np.where(own_ok, owner, -1)
    best_core = np.where(own_ok, core[np.maximum(owner, 0)], big)
    # Smallest core first; equal cores keep the owner, then the lower index.
    cand = pairs[on]
    order = np.lexsort((cand[:, 0], core[cand[:, 0]]))
    cand = cand[order]
    first = np.unique(cand[:, 1], return_index=True)[1]
    j, p = cand[first, 0], cand[first, 1]
    win = core[j] < best_core[p]
    # An owned point off its own surface by more than the allowance lies on the nearer one, which
    # is a candidate: every point ends with a segment when it had one.
    best[p[win]] = j[win]
    return _reassign(seg, owner, best, ctx.min_points)


def _owned_distances(seg: Segmentation, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (n,) of every point of P (n, 3) to its own segment's surface (inf when
    unsegmented), and each of the m segments' median (m,), robust to the few points of a
    neighbour that a segment may hold (standard units)."""
    dist = np.full(len(P), np.inf)
    median = np.zeros(len(seg))
    for k in range(len(seg)):
        s = seg[k]
        if len(s.indices):
            dist[s.indices] = s.family.distance(s.prim, P[s.indices])
            median[k] = float(np.median(dist[s.indices]))
    return dist, median


def settle_noisy_edges(seg: Segmentation, ctx: Context, reach: float) -> None:
    """Noisy clouds: give each point near a boundary to the adjacent segment
    whose surface is nearest, in place.

    Scattered points near an edge lie within the inlier distance of both
    faces; whoever was accepted or grown first took a band up to ε wide of its
    neighbour's points. The nearest surface (among the point's own segment and
    the segments of its neighbours within ``reach``, with the estimated normal
    within the angle tolerance of that surface's) is the likelier face, except
    where a point lies where only one of two faces meeting at an edge reaches
    (see :func:`_sides`) and near a segment with a ``boundary`` (a fillet's
    rounded corner draws its boundaries, see :func:`houghcad.state.surface_distance`).
    Each round moves the points next to the current boundary, so the boundary
    walks to where the surfaces cross; a segment keeps at least min_points.
    """
    if len(seg) < 2:
        return
    P, N = ctx.pre.points, ctx.pre.normals
    side = None
    for _ in range(ctx.tol.boundaries.noisy_rounds):
        owner = seg.owner()
        pts = np.flatnonzero(owner >= 0)
        _, other = _neighbour_owners(owner, pts, ctx, reach, ctx.tol.boundaries.neighbours)
        mask = (other >= 0) & (other != owner[pts][:, None])
        if not mask.any():
            return
        pairs = np.unique(np.stack([other[mask], np.broadcast_to(pts[:, None], other.shape)[mask]], 1), axis=0)
        if side is None:
            side = _sides(seg, np.unique(np.stack([owner[pairs[:, 1]], pairs[:, 0]], 1), axis=0), ctx)
        edge = np.unique(pairs[:, 1])
        best = owner.copy()
        best_d = np.full(len(P), np.inf)
        own_s = np.zeros(len(P))
        held = np.zeros(len(P), bool)  # claimed by a fillet's arc (see surface_distance)
        for j in np.unique(owner[edge]):
            e = edge[owner[edge] == j]
            own_s[e] = seg[j].family.signed_distance(seg[j].prim, P[e])
            best_d[e], claim = surface_distance(seg[j], P[e], own_s[e])
            if claim is not None:
                held[e[claim & (best_d[e] < ctx.tau)]] = True
        for j in np.unique(pairs[:, 0]):
            cand = pairs[pairs[:, 0] == j, 1]
            s = seg[j]
            sn = s.family.surface_normals(s.prim, P[cand])
            sd = s.family.signed_distance(s.prim, P[cand], sn)
            d, claim = surface_distance(s, P[cand], sd)
            a = owner[cand]
            # Where the point lies against the two faces' sides of each
            # other (see _sides): a point that only j's face could have
            # produced goes to j, one that only its owner's could stays.
            mine = own_s[cand] * side[j, a] >= 0
            theirs = sd * side[a, j] >= 0
            # (The estimated normals blur across an edge: they judge only
            # the points either face could have produced.)
            near = (d < best_d[cand]) & (np.abs(np.einsum("ij,ij->i", sn, N[cand])) >= ctx.cos_angle)
            ok = np.where(mine & ~theirs, d < ctx.tau, np.where(theirs & ~mine, False, near)) & ~held[cand]
            if claim is not None:
                ok |= claim & (d < ctx.tau) & ~held[cand]
                held[cand[ok]] = True
            best[cand[ok]] = j
            best_d[cand[ok]] = d[ok]
        if not _reassign(seg, owner, best, ctx.min_points):
            return


def _sides(seg: Segmentation, pairs: np.ndarray, ctx: Context) -> np.ndarray:
    """side[a, b]: the side of b's surface (+1 along its normals, -1, 0
    unclear) on which a's points lie near their contact, for the segment
    pairs (m, 2); an (n, n) int8 array, 0 elsewhere.

    Two faces meeting at an edge each stop at the other: face a lies on one
    side of b's surface. A noisy point beyond a convex edge, on the far side
    of b from a's face, is a's only if its foot on b would fall outside b's
    face, where b has no points; a nearest-surface rule gives it to b
    whenever b's surface is nearer. The side is read on a's points within
    ``side_links`` links of b's that lie clearly off b's surface (beyond
    tau), by a majority of ``side_majority``; both faces' sides must be clear.
    """
    t = ctx.tol.boundaries
    n = len(seg)
    P = ctx.pre.points
    side = np.zeros((n, n), np.int8)
    # A wrong primitive (a cylinder across a wall and its two corners) fits
    # clearly worse than the part's faces do, and its sides would spread
    # the error: it keeps the nearer-surface rule.
    fit = np.array([s.family.distance(s.prim, P[s.indices]).mean() for s in seg])
    sound = fit <= t.sound_fit * np.median(fit)
    trees: dict[int, cKDTree] = {}
    for a, b in {(int(min(u, v)), int(max(u, v))) for u, v in pairs.tolist() if u != v}:
        if not (sound[a] and sound[b]):
            continue
        for x, y in ((a, b), (b, a)):
            if y not in trees:
                trees[y] = cKDTree(P[seg[y].indices])
            Q = P[seg[x].indices]
            Q = Q[np.isfinite(trees[y].query(Q, distance_upper_bound=t.side_links * ctx.link)[0])]
            if len(Q) < ctx.min_points:
                continue
            # Tangent there (a plane and the wide cylinder beside it on one
            # noisy face): no edge, and the nearer surface decides.
            ny = seg[y].family.surface_normals(seg[y].prim, Q)
            cos = np.abs(np.einsum("ij,ij->i", seg[x].family.surface_normals(seg[x].prim, Q), ny))
            if np.median(cos) >= ctx.cos_angle:
                continue
            sd = seg[y].family.signed_distance(seg[y].prim, Q, ny)
            sd = sd[np.abs(sd) >= ctx.tau]
            if len(sd) >= ctx.min_points:
                f = float(np.mean(sd > 0))
                side[x, y] = 1 if f >= t.side_majority else -1 if 1 - f >= t.side_majority else 0
        # An edge has each face on one side of the other; a face that
        # crosses the other (a T-junction) or straddles it (a wrong
        # primitive cutting through a face) leaves the pair to nearness.
        if side[a, b] == 0 or side[b, a] == 0:
            side[a, b] = side[b, a] = 0
    return side


def dissolve_redundant(seg: Segmentation, ctx: Context, delta: float, reach: float) -> None:
    """Dissolve, in place, the small segments that their neighbours explain better.

    A sliver along an edge (points whose blurred normals kept them out of
    both faces) gets its own primitive in the splitting phase, fitted worse
    than the faces fit the same points. A segment smaller than ``3 *
    min_points`` is dissolved when every point lies within ``delta`` of a
    larger adjacent segment's surface, or one of a segment's size (neighbours
    within ``reach``), and those distances are on average below its own; each
    point goes to the nearest such surface. A narrow true face (a fillet) fits
    its own points at least as well and stays. (A face cut in pieces of a few
    points each gives a sliver across them more points than either piece,
    though it fits them worse than both.)

    On exact samples a larger segment goes too when every point lies on a
    larger neighbour's surface to the rounding of an exact fit
    (``dissolve_exact_taus``) and its own primitive does not fit it as
    closely: a piece of that surface with a wrong primitive. A true face
    fits its own points exactly and is never one.

    In rounds, until none is dissolved: a face that the splitting phase cut
    into a row of pieces touches only the first of them, and reaches the next
    once it holds that one's points.
    """
    while _dissolve_round(seg, ctx, delta, reach):
        pass


def _dissolve_round(seg: Segmentation, ctx: Context, delta: float, reach: float) -> bool:
    """One round of :func:`dissolve_redundant`; whether it dissolved a segment."""
    if len(seg) < 2:
        return False
    P = ctx.pre.points
    sizes = seg.sizes()
    sliver = ctx.tol.boundaries.dissolve_size * ctx.min_points
    # Segments larger than a sliver are considered on exact samples only, and only they read
    # ``exact``: off exact samples it is never read.
    exact = ctx.tol.boundaries.dissolve_exact_taus * ctx.tau if ctx.pre.exact else -1.0
    which = np.flatnonzero(sizes < (np.inf if ctx.pre.exact else sliver))
    if len(which) == 0:
        return False
    owner = seg.owner()
    gone: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for j in which[np.argsort(sizes[which], kind="stable")]:
        s = seg[j]
        idx = s.indices
        own = s.family.distance(s.prim, P[idx])
        large = sizes[j] >= sliver
        if large and own.mean() <= exact:
            continue  # a face its own primitive fits exactly stays whatever its neighbours fit
        _, nb = ctx.pre.tree.query(P[idx], k=min(ctx.tol.boundaries.neighbours, len(P)), distance_upper_bound=reach)
        nb = nb[nb < len(P)]
        adj = np.unique(owner[nb])
        adj = [int(a) for a in adj
               if a >= 0 and a != j and a not in gone
               and (sizes[a] > sizes[j] or (not large and sizes[a] >= ctx.min_points))]
        if not adj:
            continue
        d = np.stack([seg[a].family.distance(seg[a].prim, P[idx]) for a in adj])
        near = d.min(axis=0)
        if not (near < delta).all() or near.mean() >= own.mean() or (large and not (near <= exact).all()):
            continue
        gone[int(j)] = (idx, np.asarray(adj)[d.argmin(axis=0)])
    if not gone:
        return False
    add: dict[int, list[np.ndarray]] = {}
    for idx, to in gone.values():
        for a in np.unique(to):
            add.setdefault(int(a), []).append(idx[to == a])
    for a, parts in add.items():
        seg.assign(np.concatenate(parts), a)
    seg.remove(gone)
    return True


def edge_points(seg: Segmentation, ctx: Context) -> list[list[np.ndarray]]:
    """Each segment's pieces' boundary curves (extension): for segment k and each of its pieces
    (:meth:`Segmentation.pieces`), the points (global indices, sorted) that pieces of
    other segments own and that lie on this piece's boundary curve.

    A CAD sample includes the faces' boundary curves, and a point sampled on one lies on both
    faces (the Fit4CAD ground truth lists it in both), at a crease as where one face continues
    another tangentially. Its owner is one of them (:func:`settle_edges`); here it is also
    reported with the other: it has a neighbour (within the link distance) in the other piece
    and lies within ``boundaries.edge_taus`` τ of both surfaces. Clean clouds only: on noisy ones
    no point lies on a curve to within the noise."""
    pieces = [seg.pieces(k) for k in range(len(seg))]
    out = [[np.zeros(0, dtype=np.int64) for _ in p] for p in pieces]
    if len(seg) < 2 or ctx.policy.nearest_edges:
        return out
    n = seg.n_points
    of_seg = [(k, i) for k, ps in enumerate(pieces) for i in range(len(ps))]  # piece → (segment, its piece)
    piece = np.full(n, -1, dtype=np.int32)  # int32: the (n, k) table of neighbours' pieces below
    for j, (k, i) in enumerate(of_seg):
        piece[pieces[k][i]] = j
    seg_of = np.array([k for k, _ in of_seg], dtype=np.int32)
    nb, near = ctx.pre.neighbours_within(ctx.tol.boundaries.neighbours, ctx.link, threads(ctx))
    other = np.where(near, piece[nb], -1)
    # Pieces of one segment are one surface: each would hold the other's points.
    own_seg = np.where(piece >= 0, seg_of[np.maximum(piece, 0)], -1)
    mask = (other >= 0) & (own_seg[:, None] >= 0) & (seg_of[np.maximum(other, 0)] != own_seg[:, None])
    if not mask.any():
        return out
    key = np.unique(other[mask].astype(np.int64) * n + np.nonzero(mask)[0])
    pairs = np.stack([key // n, key % n], axis=1)  # (piece that may list it, point), by piece then point
    P = ctx.pre.points[pairs[:, 1]]
    on = np.ones(len(pairs), dtype=bool)
    for which in (pairs[:, 0], piece[pairs[:, 1]]):
        segs = seg_of[which]
        for k in np.unique(segs):
            at = np.flatnonzero(segs == k)
            s = seg[int(k)]
            on[at] &= s.family.distance(s.prim, P[at]) <= ctx.tol.boundaries.edge_taus * ctx.tau
    got = pairs[on]
    starts = np.flatnonzero(np.r_[True, got[1:, 0] != got[:-1, 0]]) if len(got) else np.zeros(0, dtype=np.int64)
    for a, b in zip(starts, np.r_[starts[1:], len(got)]):
        k, i = of_seg[int(got[a, 0])]
        out[k][i] = got[a:b, 1]
    return out
