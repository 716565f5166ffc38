"""Consolidation (extension): complex families retake surfaces that simpler
ones carved into pieces, pieces of one surface are voted again together, and
on noisy clouds poorly fitted segments are voted again alone."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .adjacency import smooth_adjacency
from .context import Context
from .families import Family
from .families.base import regular_indices
from .growth import accept
from .recognize import candidates, inliers, recognize
from .state import Candidate, SegmentView, Segmentation, mean_fitting_error


def consolidate(seg: Segmentation, families: list[Family], ctx: Context) -> None:
    """Let complex families retake surfaces that simpler ones carved into pieces, in place.

    The global round votes only the simple families on the whole cloud; on a
    complex surface they find tangent slices (cylinders along the lobes of a
    generalised cylinder, spheres and planes on a helical surface), each
    within the inlier distance, before the per-cluster rounds can see the
    whole surface. Each group of segments joined by tangent-continuous
    boundaries is voted again by the complex families; a complex candidate
    replaces the segments it explains when it covers at least two of them
    (80 % of each one's points) and fits them no worse than they fit
    themselves. The families voted per cluster (cone, torus) are voted the
    same way on groups of segments: the splitting phase's fallback and the
    simpler families cut a cone or torus into cylinder, sphere and plane
    bands, each within the inlier distance. Every segment then takes the
    adjacent pieces of its surface (:func:`merge_complex`). Before all this,
    every family votes again on each segment fitted clearly worse than the
    noise (:func:`revisit_poor_fits`).

    Ablation on the Fit4CAD training folds: the per-cluster votes on groups,
    the revisits and merging simple segments, all once run on noisy clouds
    only, raise every fold's mean DSC on the clean clouds too (BENCHMARKS.md).
    """
    if len(seg) < 2:
        return
    cplx = [f for f in families if f.role == "complex"]
    per_cluster = [f for f in families if f.role == "simple" and f.search == "cluster"]
    revisit_poor_fits(seg, families, ctx)
    _revote_groups(seg, cplx, per_cluster, ctx)
    merge_complex(seg, ctx)


def revisit_poor_fits(seg: Segmentation, families: list[Family], ctx: Context) -> bool:
    """Vote every family again on each segment whose primitive fits it
    clearly worse than the noise, in place.

    Such a segment was mostly taken in a round that saw other surfaces too: a
    plane across a helical strip, a sphere across a generalised cylinder whose
    own candidate there also held points of its neighbours. Alone, its
    surface's family fits it to the noise.

    Fits are compared by their cost over all the segment's points, each
    distance capped at tau (MSAC: a stray point of a neighbouring face costs
    every candidate the same), less the noise's own mean distance (0.8 σ).
    Segments within ``excess`` times the noise's cost are left alone. Among
    the candidates that explain most of the segment (a share of at least
    ``dominant`` of its points, 80 % of that share within tau, see
    :func:`_covered`), a more complex family displaces a simpler one only by
    halving that excess, as in selection; the choice replaces the segment
    when, on its share, it halves the excess of the segment's own primitive
    (its own family refitted, or a simpler one, need only lower it). The
    rest of the segment, often a band of a neighbouring face that no one
    primitive explains with it, is freed for its neighbours (:func:`absorb`).
    Returns whether a segment was replaced.
    """
    t = ctx.tol.consolidation
    P = ctx.pre.points
    ref = ctx.tol.recognition.noise_mean_sigmas * ctx.pre.noise
    least = t.least_excess * ref  # excesses below this are the noise's own
    lctx = replace(ctx, local=True)

    def cost(c: Candidate, idx: np.ndarray) -> float:
        return float(np.minimum(c.family.distance(c.prim, P[idx]), ctx.tau).mean()) - ref

    # A replacement changes only its own segment's points: every poor
    # segment's vote is known before the first is replaced (on the run's
    # workers, side by side, when there are some).
    todo = [k for k in sorted(range(len(seg)), key=lambda i: -len(seg.indices(i))) if _poor(seg[k], ref, ctx)]
    voted = ctx.workers.run("candidates", [(seg.indices(k), families, None) for k in todo], lctx) \
        if ctx.workers else None
    replaced = False
    for n, k in enumerate(todo):
        s = seg[k]
        if voted is not None:
            found = voted[n]
        else:
            avail = np.zeros(len(P), bool)
            avail[s.indices] = True
            found = candidates(s.indices, families, lctx, avail)
        cover = []
        for c in found:
            if len(c.indices) < t.dominant * len(s.indices):
                continue
            # The candidate's share of the segment, compared there.
            sub = replace(s, indices=c.indices)
            got = _covered(c, [sub], ctx)
            if got:
                cover.append((max(cost(c, s.indices), least), c, got[0][1]))
        best = None
        for e, c, q in sorted(cover, key=lambda x: (x[1].family.precedence, x[0])):
            if best is None or (e < t.complex_halving * best[0] if c.family.precedence > best[1].family.precedence
                                else e < best[0]):
                best = (e, c, q)
        if best is None:
            continue
        e, c, q = best
        # Against the segment's own primitive on the candidate's share only:
        # the rest may be another surface, which no one primitive explains.
        mine, theirs = max(cost(c, c.indices), least), max(cost(s, c.indices), least)
        if mine >= (t.complex_halving if c.family.precedence > s.family.precedence else 1.0) * theirs:
            continue
        new = _union(c, [q], P)
        seg.set_points(k, new.indices)
        seg.set_record(k, new.record)
        replaced = True
    return replaced


def _poor(s: SegmentView, ref: float, ctx: Context) -> bool:
    """Whether :func:`revisit_poor_fits` votes again on segment ``s``: large enough, its cost
    above ``excess`` times the noise's own ``ref``, and not exact on most of its points."""
    t = ctx.tol.consolidation
    if len(s.indices) < t.revisit_min_size * ctx.min_points:
        return False
    d = s.family.distance(s.prim, ctx.pre.points[s.indices])
    if float(np.minimum(d, ctx.tau).mean()) - ref <= (t.excess - 1.0) * ref:  # its cost
        return False
    # Most of the segment on its primitive exactly: the excess is rows of
    # its neighbours, not a wrong surface.
    return bool(np.median(d) > t.exact_taus * ctx.tau)


@dataclass(frozen=True)
class _Vote:
    """One grouping of the segments and the families voted on its groups."""

    edges: np.ndarray  # (k, 2) segment pairs joined
    families: list[Family]
    ctx: Context
    peel: bool  # set aside the faces that dominate a group (see _vote_group)


def _revote_groups(seg: Segmentation, cplx: list[Family], per_cluster: list[Family], ctx: Context) -> None:
    """The complex families' and the per-cluster simple families' vote on
    each group of tangent-joined segments (see :func:`consolidate`).

    A cone or torus is placed from all the normals of the whole cloud, which
    suits one of them at most: a second cone of a part comes out in cylinder,
    sphere and plane bands. Those families are voted on the group as on a
    cluster (their placements from its normals).
    """
    if not cplx and not per_cluster:
        return
    n = len(seg)
    removed = np.zeros(n, bool)
    added: list[Candidate] = []
    # A wider grouping repeats most groups: each (families, members) is voted
    # once (a vote that took nothing would take nothing again).
    voted: set[tuple[int, ...]] = set()
    for vote in _groupings(seg, cplx, per_cluster, ctx):
        g = coo_matrix((np.ones(len(vote.edges)), (vote.edges[:, 0], vote.edges[:, 1])), shape=(n, n))
        ncomp, lab = connected_components(g, directed=False)
        groups = []
        for comp in range(ncomp):
            members = np.flatnonzero((lab == comp) & ~removed)
            key = (id(vote.families), vote.peel, *members.tolist())
            if key in voted:
                continue
            voted.add(key)
            if vote.peel:
                # Segments of these families are whole surfaces already.
                members = np.array([m for m in members if seg[m].family not in vote.families], dtype=np.int64)
            groups.append(members)
        # The groups are disjoint and a group's vote marks its own members
        # only: their first votes are known before the first is taken (on the
        # run's workers, side by side, when there are some).
        placed = [_region(seg, m, np.array([len(seg[k].indices) for k in m]), vote) for m in groups]
        for group, first in zip(placed, _first_votes(placed, vote)):
            added += _vote_group(seg, group, vote, removed, ctx, first)
    if added:
        seg.remove(np.flatnonzero(removed))
        accept(added, seg, ctx)


def _groupings(seg: Segmentation, cplx: list[Family], per_cluster: list[Family], ctx: Context) -> list[_Vote]:
    """The groupings voted, in order (see :func:`_revote_groups`)."""
    joined = smooth_adjacency(seg, ctx)
    votes = []
    if cplx:
        # Voted as a whole cloud (ctx.local False): the families' gates skip a
        # group that is not one complex surface, which most groups of simple
        # faces are not (a plane, a fillet and a plane).
        votes.append(_Vote(joined, cplx, ctx, False))
        if ctx.policy.revote_creases:
            # Planes and spheres that slice a noisy curved surface meet at
            # creases wider than a face's own normals wander: joined up to
            # the normals' tolerance, they make the group again.
            votes.append(_Vote(smooth_adjacency(seg, ctx, crease=ctx.angle), cplx, ctx, False))
    if per_cluster:
        # The bands of a noisy cone fit to the noise each, and their fitted
        # normals often disagree at their contacts: after the tangent-joined
        # groups, any contact joins them, and so the faces of a whole part;
        # the faces that dominate what remains are set aside in turn.
        lctx = replace(ctx, local=True)
        anyc = smooth_adjacency(seg, ctx, smooth=False)
        if not ctx.policy.group_planes:
            curved = np.array([r.family.name != "plane" for r in seg.records], dtype=bool)
            joined, anyc = _between(curved, joined), _between(curved, anyc)
        votes.append(_Vote(joined, per_cluster, lctx, True))
        votes.append(_Vote(anyc, per_cluster, lctx, True))
    return votes


def _between(keep: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The pairs (k, 2) of ``edges`` whose two segments are both in ``keep`` (bool, one per segment)."""
    return edges[keep[edges[:, 0]] & keep[edges[:, 1]]] if len(edges) else edges


def _vote_group(seg: Segmentation, group: _Group, vote: _Vote, removed: np.ndarray, ctx: Context,
                first: list[Candidate] | None = None) -> list[Candidate]:
    """The candidates that replace two or more of a group's members (segment
    ids); their ids are marked in ``removed`` (bool (m,)). ``first``: the
    group's region's recognition when already known (:func:`_first_votes`).

    A carved surface is cut into comparable pieces; a face that dominates its
    group (the plane a torus meets) is not one of them. Where the vote takes
    nothing, the largest face is set aside too (``peel_retries`` at most):
    the placement from the group's normals suits one surface of it, which
    need not be the carved one.
    """
    t = ctx.tol.consolidation
    P = ctx.pre.points
    added: list[Candidate] = []
    retries = t.peel_retries
    while group.region is not None:
        members = group.members
        if first is None:
            avail = np.zeros(len(P), bool)
            avail[group.region] = True
            first = recognize(group.region, vote.families, vote.ctx, avail)
        took = False
        for c in first:
            got = _covered(c, [seg[m] for m in members], ctx)
            got = [(members[j], q, d) for j, q, d in got if not removed[members[j]]]
            if vote.peel:
                # A carved surface is contiguous: the pieces must touch one
                # another, not only the peeled faces (two opposite holes of
                # a thin plate lie on one torus through both).
                got = _touching(got, vote.edges)
            if len(got) < 2 or _simple_suffices([seg[m] for m, _, _ in got], ctx):
                continue
            removed[[m for m, _, _ in got]] = True
            added.append(_union(c, [q for _, q, _ in got], P))
            took = True
        if took or not vote.peel or retries == 0:
            break
        retries -= 1
        keep = np.arange(len(members)) != np.argmax(group.sizes)
        group, first = _region(seg, members[keep], group.sizes[keep], vote), None
    return added


@dataclass(frozen=True)
class _Group:
    """A group :func:`_vote_group` votes on, its dominant faces set aside (:func:`_region`)."""

    members: np.ndarray  # segment ids (m,)
    sizes: np.ndarray  # their point counts (m,)
    region: np.ndarray | None  # their points (sorted global indices); None: too few left, or one dominates


def _region(seg: Segmentation, members: np.ndarray, sizes: np.ndarray, vote: _Vote) -> _Group:
    """The group of ``members`` (ids) of ``sizes`` points that :func:`_vote_group` votes on, after
    the dominant faces are set aside."""
    share = vote.ctx.tol.consolidation.peel_share
    while vote.peel and len(members) >= 2 and sizes.max() > share * sizes.sum():
        keep = np.arange(len(members)) != np.argmax(sizes)
        members, sizes = members[keep], sizes[keep]
    if len(members) < 2 or sizes.max() > share * sizes.sum():
        return _Group(members, sizes, None)
    return _Group(members, sizes, np.sort(np.concatenate([seg[m].indices for m in members])))


def _first_votes(groups: list[_Group], vote: _Vote) -> list[list[Candidate] | None]:
    """The first recognition of each group's region by :func:`_vote_group`, computed on the run's
    workers; None for those left to it (all of them without workers)."""
    out: list[list[Candidate] | None] = [None] * len(groups)
    regions = [g.region for g in groups]
    todo = [i for i, r in enumerate(regions) if r is not None]
    workers = vote.ctx.workers
    got = workers.run("recognize", [(regions[i], vote.families, None) for i in todo], vote.ctx) if workers else None
    for i, found in zip(todo, got or []):
        out[i] = found
    return out


def _touching(got: list, edges: np.ndarray) -> list:
    """The largest set of ``got``'s pieces (position first) connected by ``edges`` (k, 2)."""
    if len(got) < 2:
        return got
    pos = {m: i for i, (m, _, _) in enumerate(got)}
    e = [(pos[a], pos[b]) for a, b in edges.tolist() if a in pos and b in pos]
    if not e:
        return []
    r, c = np.array(e).T
    k, lab = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(len(got),) * 2), directed=False)
    big = np.bincount(lab).argmax()
    return [g for g, l in zip(got, lab) if l == big]


def merge_complex(seg: Segmentation, ctx: Context) -> None:
    """Each segment takes the adjacent segments that lie on its surface (a
    complex one only smaller ones), in place.

    The splitting phase finds a face in several pieces where its clusters
    did (a face cut by the RANSAC fallback's regions, or by the rows its
    neighbours took); on a noisy cloud the whole-cloud round also places a
    cone or torus from all the normals, which fits one of them at most, and
    the others' slices go to simpler families (two cylinder bands of a
    cone) before a cluster round finds the rest. Noise also lets a wide
    cylinder take part of a plane face beside the plane's own segment: the
    plane takes it back.

    Pieces of one complex surface found apart (by different clusters, or
    after a seam cut a group) each fit their own small patch; association
    merges only equal parameters, and the small patches' parameters are
    loose, so the family is voted again on the segment and those neighbours.
    A slice of another family joins when the segment fits it about as well
    as its own points.
    """
    P = ctx.pre.points
    tried: set[tuple[int, ...]] = set()  # re-votes done: each configuration once
    for _ in range(ctx.tol.consolidation.merge_rounds):
        grown = False
        edges = smooth_adjacency(seg, ctx, smooth=False)
        order = sorted(range(len(seg)), key=lambda i: -len(seg.indices(i)))
        # Worked on as a list within the round (the ids stay put), written back after.
        segs: list[SegmentView | Candidate | None] = list(seg)
        for i in order:
            c = segs[i]
            if c is None:
                continue
            nbrs = np.unique(np.r_[edges[edges[:, 0] == i, 1], edges[edges[:, 1] == i, 0]])
            # A cone or torus piece may be the smallest of its surface's pieces
            # (the slices came first); a complex segment takes only smaller ones.
            bound = np.inf if c.family.role == "simple" else len(c.indices)
            nbrs = [j for j in nbrs.tolist() if segs[j] is not None and len(segs[j].indices) <= bound]
            if not nbrs:
                continue
            got = _covered(c, [segs[j] for j in nbrs], ctx, own_fit=True)
            if c.family.role != "simple" and len(got) < len(nbrs):
                tight = _tightened(c, ctx)
                more = _covered(tight, [segs[j] for j in nbrs], ctx, own_fit=True)
                if len(more) > len(got):
                    c, got = tight, more
            take = [(nbrs[k], q) for k, q, _ in got]
            rest = sorted(set(nbrs) - {j for j, _ in take})
            key = (len(c.indices), int(c.indices[0]), *(int(segs[j].indices[0]) for j in rest))
            # (A segment of a whole-cloud family, found on a whole face, has
            # firm parameters: it only takes what it covers.)
            if rest and key not in tried and not (c.family.role == "simple" and c.family.search == "whole"):
                tried.add(key)
                # Pieces fitted apart on small patches have loose parameters:
                # vote the family again on them and the segment.
                region = np.unique(np.concatenate([c.indices] + [segs[j].indices for j in rest]))
                avail = np.zeros(len(P), bool)
                avail[region] = True
                for new in recognize(region, [c.family], ctx, avail):
                    mine = _covered(new, [c], ctx)
                    if not mine:
                        continue
                    more = _covered(new, [segs[j] for j in rest], ctx)
                    if more:
                        c = _union(new, [mine[0][1]], P)
                        take += [(rest[k], q) for k, q, _ in more]
                    break
            for j, q in take:
                segs[j] = None
            if take:
                c = _union(c, [c.indices] + [q for _, q in take], P)
                grown = True
            segs[i] = c
        kept = [s for s in segs if s is not None]
        seg.rebuild([s.record for s in kept], [s.indices for s in kept])
        if not grown:
            break


def _simple_suffices(pieces: list[Candidate], ctx: Context) -> bool:
    """Whether one primitive of the pieces' own (simple) families, refitted on
    all of them, explains every piece: then they are pieces of one simple
    face (a hole split in two), for association to merge."""
    idx = np.concatenate([s.indices for s in pieces])
    m = min(len(idx), ctx.tol.consolidation.suffices_points)
    sel = idx[np.sort(np.random.default_rng(ctx.seed).choice(len(idx), m, replace=False))]
    for s in sorted(pieces, key=lambda s: -len(s.indices)):
        if s.family.role != "simple":
            continue
        prim = s.family.fit(s.prim, ctx.pre.points[sel], ctx.pre.normals[sel])
        if prim is None or not s.family.valid(prim, ctx):
            continue
        if len(_covered(replace(s, prim=prim), pieces, ctx, strict=False)) == len(pieces):
            return True
    return False


def _covered(c: Candidate, pieces: list[Candidate], ctx: Context, own_fit: bool = False, strict: bool = True) \
        -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The pieces that candidate ``c`` explains: (position, points within tau
    with compatible normals, their distances) for each piece that has 80 % of
    its points so and that ``c`` fits no worse than its own primitive does or,
    with ``own_fit``, no worse than half again ``c``'s fit to its own points.
    ``strict`` (noisy clouds): also over all the piece's points (see below)."""
    t = ctx.tol.consolidation
    P, N = ctx.pre.points, ctx.pre.normals
    own = c.family.distance(c.prim, P[c.indices]).mean() if own_fit else 0.0
    out = []
    for j, s in enumerate(pieces):
        Q = s.indices
        ok, d = inliers(c.family, c.prim, P[Q], N[Q], ctx.tau, ctx.cos_angle)
        if ok.mean() < t.cover_share:
            continue
        mine = s.family.distance(s.prim, P[Q]).mean()
        bound = max(t.cover_ratio * mine + t.cover_taus * ctx.tau, t.own_fit_ratio * own)
        if d[ok].mean() > bound:
            continue
        if strict and ctx.policy.strict_cover and not own_fit:
            # The mean over the inliers within tau (3 σ) is truncated: a
            # surface a noise σ off the piece still passes the test above.
            # Over all the piece's points, c must fit as well as the piece's
            # own primitive, or the noise where that fits below it (a slice
            # chosen for being close), within two standard errors.
            ref = max(mine, ctx.tol.recognition.noise_mean_sigmas * ctx.pre.noise)
            if d.mean() > ref * (1.0 + t.strict_se / np.sqrt(len(Q))):
                continue
        out.append((j, Q[ok], d[ok]))
    return out


def _tightened(c: Candidate | SegmentView, ctx: Context) -> Candidate:
    """Complex segment ``c`` refitted by least squares on its own points.

    Recognition stops refining an iterative fit once it lies within a fraction of τ of its
    points (the trimmed refits' stop), so an exact sample's complex segment can still miss its
    own surface by some 0.05 τ; the slices of that surface beyond its points then lie several
    times further from it than from their own simpler primitives, and the cover test leaves
    them. Refitted to the rounding, the segment covers them again."""
    P, N = ctx.pre.points, ctx.pre.normals
    sel = c.indices[regular_indices(len(c.indices), ctx.tol.recognition.refit_points)]
    prim = c.family.fit(c.prim, P[sel], N[sel])
    if prim is None or not c.family.valid(prim, ctx):
        return _union(c, [c.indices], P)
    return _union(replace(c, prim=prim), [c.indices], P)


def _union(c: Candidate, parts: list[np.ndarray], P: np.ndarray) -> Candidate:
    """Candidate ``c``'s primitive over the union of the index arrays ``parts``."""
    idx = np.unique(np.concatenate(parts))
    d = c.family.distance(c.prim, P[idx])
    return Candidate(c.family, c.prim, idx, mean_fitting_error(d, P[idx]), d)
