"""The recognition step (paper §5.2).

For each family: standard-form placements, accumulator over the region T,
votes of the sampled Γ_P, persistent peaks, then candidate evaluation
(inliers within a threshold with compatible normals, least-squares
refinement, dense connected subsets X_i, mean fitting error) and selection
(where candidates compete for the same points, the lowest MFE wins, ties to
the simpler family).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .clusters import dense_subsets
from .context import Context
from .families import Family, Primitive
from .hough import Grid, accumulate, persistent_peaks, smooth
from .state import Candidate, SegmentRecord, Segmentation, mean_fitting_error
from .tolerances import RecognitionTolerances


def inliers(fam: Family, prim: Primitive, P: np.ndarray, N: np.ndarray, tau: float, cos_angle: float):
    """Boolean mask of the points within ``tau`` with a compatible normal, and the distances."""
    d = fam.distance(prim, P)
    near = d < tau
    ok = near.copy()
    if near.any():
        sn = fam.surface_normals(prim, P[near])
        ok[near] = np.abs(np.einsum("ij,ij->i", sn, N[near])) >= cos_angle
    return ok, d


def _subsample(n: int, m: int, rng: np.random.Generator) -> np.ndarray:
    return np.arange(n) if n <= m else np.sort(rng.choice(n, m, replace=False))


def evaluate(fam: Family, prim: Primitive, idx: np.ndarray, ctx: Context, coarse: float) -> list[Candidate]:
    """Candidate evaluation on the point set ``idx`` (global indices).

    Inliers within ``coarse`` → least-squares refit → inliers within tau →
    dense subsets of the inliers and the crease points within tau → one
    Candidate per subset (its inliers) with its MFE.
    """
    P, N = ctx.pre.points[idx], ctx.pre.normals[idx]
    rng = np.random.default_rng(ctx.seed)
    t = ctx.tol.recognition
    # Coarse (cell size) → intermediate → tau: each refit sees cleaner inliers.
    for tol in (coarse, max(ctx.tau, min(coarse, t.coarse_taus * ctx.tau))):
        ok, d = inliers(fam, prim, P, N, tol, ctx.cos_angle)
        if ok.sum() < ctx.min_points:
            return []
        sel = np.flatnonzero(ok)
        sel = sel[_subsample(len(sel), t.refit_points, rng)]
        new = fam.fit(prim, P[sel], N[sel])
        if new is None or not fam.valid(new, ctx):
            return []
        prim = new
    prim, ok, d = _trimmed_refits(fam, prim, P, N, ctx, rng)
    # Connected also through crease points on the surface, kept by the normal test: on a face
    # two or three spacings wide (a chamfer, a land) most points are on a crease, where the
    # normal may be a neighbouring face's, and dropping them cuts the face into pieces. Other
    # points with a wrong normal belong to a surface that crosses this one: no bridge.
    bridge = ok if ctx.pre.crease is None else ok | ctx.pre.crease[idx]
    near = np.flatnonzero(bridge & (d < ctx.tau))
    out = []
    scale = ctx.link_scales(idx[near])
    for comp in dense_subsets(P[near], ctx.link, ctx.min_points, t.dense_min_samples, scale):
        loc = near[comp]
        loc = loc[ok[loc]]
        if len(loc) < ctx.min_points:
            continue
        X = P[loc]
        if not _patch(X, ctx):
            continue
        if not ctx.local and not fam.well_determined(prim, X, ctx):
            continue
        # On the whole cloud, a candidate whose inliers fit only to a fraction
        # of tau, not to the noise, is a tangent slice of a surface that
        # another family or the per-cluster rounds explain exactly.
        if not ctx.local and d[loc].mean() > max(t.slice_sigmas * ctx.pre.noise, t.slice_taus * ctx.tau):
            continue
        out.append(Candidate(fam, prim, idx[loc], mean_fitting_error(d[loc], X), d[loc]))
    return out


def _trimmed_refits(fam: Family, prim: Primitive, P: np.ndarray, N: np.ndarray, ctx: Context,
                    rng: np.random.Generator) -> tuple[Primitive, np.ndarray, np.ndarray]:
    """Refits on the inliers a face's own points dominate; the primitive, its
    inlier mask (m,) and distances (m,) over P (m, 3).

    Clean samples lie exactly on their face, and a neighbour's tangent band
    among the inliers pulls the least squares off it: refit on the closer
    half until the inliers fit to a small fraction of tau, or to the noise
    (past it, trimming fits the noise, not the face). Noise scatters a face's
    points symmetrically about it, 95 % of them within 2 σ, while a
    neighbouring face's points within tau (3 σ) sit further out on one side:
    refit on the inliers within 2 σ, which trims both sides of the face alike.
    """
    t = ctx.tol.recognition
    noisy = ctx.policy.trim_to_noise
    ok, d = inliers(fam, prim, P, N, ctx.tau, ctx.cos_angle)
    for _ in range(t.noisy_trim_rounds if noisy else t.clean_trim_rounds):
        sel = np.flatnonzero(ok)
        if noisy:
            sel = sel[d[sel] <= t.trim_sigmas * ctx.pre.noise]
            if len(sel) < t.trim_min_points * ctx.min_points:
                break
        else:
            if len(sel) < t.trim_min_points * ctx.min_points or \
                    d[sel].mean() <= max(t.trim_stop_taus * ctx.tau, ctx.pre.noise):
                break
            sel = sel[d[sel] <= np.median(d[sel])]
        sel = sel[_subsample(len(sel), t.refit_points, rng)]
        new = fam.fit(prim, P[sel], N[sel])
        if new is None or not fam.valid(new, ctx):
            break
        prim = new
        ok, d = inliers(fam, prim, P, N, ctx.tau, ctx.cos_angle)
    return prim, ok, d


def _patch(X: np.ndarray, ctx: Context) -> bool:
    """Whether the dense subset X (m, 3) is a surface patch, not a one-row strip: every surface
    through a row of points fits it, so a strip says nothing of its family."""
    width = ctx.tol.recognition.strip_width_spacings * ctx.pre.spacing
    ev = np.linalg.eigvalsh(np.cov(X.T))
    return bool(np.sqrt(max(ev[1], 0)) >= width)


def propose(fam: Family, idx: np.ndarray, ctx: Context) -> list[tuple[Primitive, float]]:
    """Peaks of the family's accumulators on the point set ``idx``: coarse
    primitives with the tolerance their cell size allows."""
    P, N = ctx.pre.points[idx], ctx.pre.normals[idx]
    out = []
    for pl in fam.placements(P, N, ctx):
        Pl, Nl = pl.local(P, N)
        grid = fam.region(Pl, Nl, ctx)
        if fam.pointwise:
            voter = vals = None
            H = block_votes(fam, Pl, Nl, grid, ctx)
            if not H.any():
                continue
        else:
            voter, vals = fam.gamma(Pl, Nl, grid, ctx)
            if len(voter) == 0:
                continue
            H = accumulate(grid, voter, vals)
        H = smooth(H, grid.wrap)
        # A complex family's candidate costs tens of milliseconds of nonlinear
        # fits; its surface is one of the most persistent peaks.
        cap = ctx.max_peaks if fam.role == "simple" else min(ctx.max_peaks, ctx.tol.recognition.complex_max_peaks)
        pk, _ = persistent_peaks(H, ctx.persistence, grid.wrap, max_peaks=cap)
        pk = pk[H.ravel()[pk] >= ctx.min_votes]
        if fam.stacked and not ctx.local and len(pk) and voter is not None:
            # A surface that shares its placement with a larger one (two
            # generalised cylinders on one directrix and axis) votes a lower
            # peak, and the cones or bands between them fill the valley: its
            # persistence falls under the threshold relative to the top. Its
            # own votes, without the top's points, confirm it.
            more = _beside_top(fam, pl, grid, H, pk, P, Pl, voter, vals, ctx)
            pk = np.concatenate([pk, more[:ctx.tol.recognition.beside_top_peaks]])
        for v in grid.cell_center(pk):
            prim = fam.primitive(v, pl)
            if prim is not None and fam.valid(prim, ctx):
                out.append((prim, fam.coarse_tolerance(grid, Pl, ctx)))
    return out


#: Points per block when a pointwise family votes: bounds the Γ_P samples (and their cell
#: indices) held at once; the accumulator is the same for any block size.
VOTE_BLOCK = 8192


def block_votes(fam: Family, Pl: np.ndarray, Nl: np.ndarray, grid: Grid, ctx: Context) -> np.ndarray:
    """The accumulator (``grid.bins``) of a pointwise family's votes (``Family.pointwise``) from
    the points Pl (m, 3) with normals Nl (m, 3), taken over blocks of VOTE_BLOCK points. Unit
    votes sum exactly, so it equals one accumulation over all the points. A family that votes
    directly (:meth:`Family.votes`) does so instead."""
    direct = fam.votes(Pl, Nl, grid, ctx)
    if direct is not None:
        return direct
    H = np.zeros(grid.bins)
    for start in range(0, len(Pl), VOTE_BLOCK):
        stop = start + VOTE_BLOCK
        voter, vals = fam.gamma(Pl[start:stop], Nl[start:stop], grid, ctx)
        if len(voter):
            H += accumulate(grid, voter, vals)
    return H


def _beside_top(fam: Family, pl, grid, H: np.ndarray, pk: np.ndarray, P: np.ndarray, Pl: np.ndarray,
                voter: np.ndarray, vals: np.ndarray, ctx: Context) -> np.ndarray:
    """Flat indices (k,) of the local maxima of the accumulator ``H`` whose
    persistence misses the threshold by at most half, and that stay peaks
    above the threshold (against H's top) when the points (P (n, 3), Pl the
    same in the placement's frame) within the coarse tolerance of the top
    peak's surface withdraw their votes (``voter`` (m,), ``vals`` (m, d)).
    ``pk``: the peaks kept already, the top one first."""
    none = np.zeros(0, np.int64)
    top = float(H.max())
    near, _ = persistent_peaks(H, ctx.tol.recognition.beside_top_persistence * ctx.persistence, grid.wrap)
    near = near[~np.isin(near, pk)]
    if not len(near):
        return none
    prim = fam.primitive(grid.cell_center(pk[:1])[0], pl)
    if prim is None or not fam.valid(prim, ctx):
        return none
    off = fam.distance(prim, P) > fam.coarse_tolerance(grid, Pl, ctx)
    if off.sum() < ctx.min_points:
        return none
    keep = off[voter]
    H2 = smooth(accumulate(grid, voter[keep], vals[keep]), grid.wrap)
    if H2.max() < ctx.persistence * top:
        return none
    again, _ = persistent_peaks(H2, ctx.persistence * top / H2.max(), grid.wrap)
    return again[np.isin(again, near) & (H2.ravel()[again] >= ctx.min_votes)]


def compete(cands: list[Candidate], ctx: Context) -> list[Candidate]:
    """Point-wise competition: a point stays with a candidate only if no other
    candidate explains it clearly better (by more than a quarter of tau).
    Candidates are then cut again into dense subsets."""
    if len(cands) < 2:
        return cands
    pts = np.concatenate([c.indices for c in cands])
    d = np.concatenate([c.distances for c in cands])
    dmin = np.full(len(ctx.pre.points), np.inf)
    np.minimum.at(dmin, pts, d)
    # On a noisy cloud some candidate among dozens passes through almost any
    # point: a margin under the noise would shred the true surface.
    t = ctx.tol.recognition
    margin = t.compete_taus * ctx.tau
    if ctx.policy.compete_above_noise:
        margin = max(margin, t.compete_sigmas * ctx.pre.noise)
    keep = d <= dmin[pts] + margin
    out = []
    start = 0
    for c in cands:
        k = keep[start:start + len(c.indices)]
        start += len(c.indices)
        if k.all():
            out.append(c)
            continue
        idx, dd = c.indices[k], c.distances[k]
        for comp in dense_subsets(ctx.pre.points[idx], ctx.link, ctx.min_points,
                                  ctx.tol.recognition.dense_min_samples, ctx.link_scales(idx)):
            out.append(Candidate(c.family, c.prim, idx[comp],
                                 mean_fitting_error(dd[comp], ctx.pre.points[idx[comp]]), dd[comp]))
    return out


def select(cands: list[Candidate], avail: np.ndarray, ctx: Context) -> list[Candidate]:
    """Greedy choice among competing candidates for the points ``avail`` (bool (n,)) leaves.

    After the point-wise competition, largest first; a candidate competes with
    the others that share more than 1 − ``keep_share`` of the smaller one's
    points (taking either would leave the other too few to be accepted), and
    among them the lowest MFE wins (a more complex family must beat a simpler
    one clearly). A candidate the accepted ones have left too few free points
    to be accepted is out of the running.
    """
    cands = compete(cands, ctx)
    keep_share = ctx.tol.recognition.keep_share
    settle_share = ctx.tol.recognition.settle_share
    free = avail.copy()
    judged = _noise_floored(cands, ctx)
    order = sorted(range(len(cands)), key=lambda i: (-len(cands[i].indices), cands[i].mfe))
    done = np.zeros(len(cands), bool)
    sets = [c.indices for c in cands]
    accepted = []
    need = np.array([max(ctx.min_points, keep_share * len(s)) for s in sets])

    def acceptable() -> np.ndarray:
        # A candidate whose points the accepted ones hold can no longer be
        # accepted: it must not win a group and settle the others with it (a
        # band straddling two noisy surfaces, mostly taken, would take a plane
        # down with it). Whether each still can changes only when one is accepted.
        return np.array([free[s].sum() for s in sets]) >= need

    can = acceptable()
    for i in order:
        if done[i] or not can[i]:
            continue
        group = [i]
        for j in order:
            if j == i or done[j] or not can[j]:
                continue
            inter = np.intersect1d(sets[i], sets[j], assume_unique=True).size
            # Whichever is taken, the other must keep keep_share of its points
            # to be accepted: a candidate competes with every one that could
            # displace it.
            if inter > (1.0 - keep_share) * min(len(sets[i]), len(sets[j])):
                group.append(j)
        best = group[0]
        for j in group[1:]:
            if _better(judged[j], judged[best], ctx.tol.recognition, ctx.policy.complex_dominates):
                best = j
        # Only the candidates that mostly overlap the winner are settled; a
        # larger one that merely contains it stays in the running.
        for j in group:
            inter = np.intersect1d(sets[best], sets[j], assume_unique=True).size
            if j == best or inter > settle_share * min(len(sets[best]), len(sets[j])):
                done[j] = True
        c = cands[best]
        left = c.indices[free[c.indices]]
        c = replace(c, indices=left)
        free[left] = False
        accepted.append(c)
        can = acceptable()
    return accepted


def _noise_floored(cands: list[Candidate], ctx: Context) -> list[Candidate]:
    """The candidates as selection compares them: on a noisy cloud, by their
    mean distance in excess of the noise's own.

    No surface fits noisy points better than the noise; only a subset chosen
    for being close to it does (a sphere cut from a wide cone fits its band to
    0.6 σ), while the true surface fits the whole to 0.8 σ (the mean of
    |N(0, σ²)|) and a wrong one to more. Near the noise level the ratio of
    two raw errors says nothing; the excess does. The noise's own error is
    0.8 × the estimated σ, or the best fit among the candidates about as
    large as the largest where that is lower (curvature inflates the
    estimate on threads; a subset cannot be that large).
    """
    if not ctx.policy.floor_selection or not cands:
        return cands
    t = ctx.tol.recognition
    md = np.array([float(c.distances.mean()) if len(c.distances) else 0.0 for c in cands])
    size = np.array([len(c.indices) for c in cands])
    big = (size >= t.noise_floor_size * size.max()) & (md > 0)
    floor = min(t.noise_mean_sigmas * ctx.pre.noise, float(md[big].min()) if big.any() else np.inf)
    out = []
    for c, m, n in zip(cands, md, size):
        if c.mfe <= 0 or m <= 0:
            out.append(c)
            continue
        # An excess below two standard errors of the mean |d| (0.755 m /
        # sqrt(n) for Gaussian noise) is the floor itself.
        least = floor * min(t.noise_floor_least, t.noise_floor_se / np.sqrt(max(n, 1)))
        out.append(replace(c, mfe=c.mfe * max(m - floor, least) / m))
    return out


def _better(a: Candidate, b: Candidate, t: RecognitionTolerances, dominates: bool = False) -> bool:
    """Whether candidate a should replace b for the same points; with ``dominates``, a more
    complex candidate explaining more points at a lower error also wins
    (:attr:`houghcad.noise.NoisePolicy.complex_dominates`)."""
    ca, cb = a.family.precedence, b.family.precedence
    if ca == cb and not (a.family.role == b.family.role == "simple"):
        # Two complex candidates (several profiles, placements): a small piece
        # fitted marginally better must not replace one explaining far more.
        def covers(x: Candidate, y: Candidate) -> bool:
            return len(x.indices) >= t.covers_size * len(y.indices) and x.mfe <= t.covers_mfe * y.mfe
        if covers(a, b) or covers(b, a):
            return covers(a, b)
    if ca == cb:
        return (a.mfe, -len(a.indices)) < (b.mfe, -len(b.indices))
    simple, cplx = (a, b) if ca < cb else (b, a)
    if dominates and len(cplx.indices) > len(simple.indices) and cplx.mfe < simple.mfe \
            and _clearly_closer(cplx, simple, t.dominance_se):
        return a is cplx
    # The more complex family wins with a clearly lower error, or when it
    # explains many more points about as well.
    cplx_wins = (cplx.mfe < t.complex_wins_mfe * simple.mfe and simple.mfe - cplx.mfe > t.complex_wins_abs) or (
        len(cplx.indices) >= t.covers_size * len(simple.indices) and cplx.mfe <= t.covers_mfe * simple.mfe)
    return (a is cplx) == cplx_wins


def _clearly_closer(a: Candidate, b: Candidate, z: float) -> bool:
    """Whether a's points lie nearer its surface than b's do to b's by more than ``z`` standard
    errors of the difference of the two mean distances. A family that nests another (a cone
    about a cylinder's points) always fits a little closer, by its extra freedom alone."""
    da, db = a.distances, b.distances
    return float(db.mean() - da.mean()) > z * float(np.sqrt(da.var() / len(da) + db.var() / len(db)))


def recognize(idx: np.ndarray, families: list[Family], ctx: Context, avail: np.ndarray) -> list[Candidate]:
    """One recognition step on the points of ``idx`` (global indices) that
    ``avail`` (bool (n,)) leaves: the selected candidates, disjoint (the
    caller takes their points)."""
    return select(candidates(idx, families, ctx, avail), avail, ctx)


def candidates(idx: np.ndarray, families: list[Family], ctx: Context, avail: np.ndarray) -> list[Candidate]:
    """Every family's evaluated candidates on the points of ``idx`` (global
    indices) that ``avail`` (bool (n,)) leaves, before selection."""
    idx = idx[avail[idx]]
    if len(idx) < ctx.min_points:
        return []
    # Families voted per cluster join the whole-cloud round on noisy clouds:
    # there a slice of a cone or torus by a simpler family fits within the
    # noise, the tangent-slice gate of evaluate() cannot reject it, and only
    # the whole surface's candidate can beat it.
    fams = [f for f in families
            if ctx.local or f.search == "whole" or (ctx.policy.cluster_families_first and f.role == "simple")]
    got = ctx.workers.candidates(idx, fams, ctx) if ctx.workers else None
    if got is not None:
        return got
    ctx = voting_context(idx, ctx)
    return [c for f in fams for prim, coarse in propose(f, idx, ctx) for c in evaluate(f, prim, idx, ctx, coarse)]


def voting_context(idx: np.ndarray, ctx: Context) -> Context:
    """``ctx`` for a vote on the points ``idx`` (global indices): the axis votes read their
    neighbour table among themselves (:func:`houghcad.context.neighbour_table`, built when first
    read)."""
    return replace(ctx, voting=idx)


def refine(seg: Segmentation, families: list[Family], ctx: Context) -> None:
    """Offer every segment to the selected families that refine its family
    (:attr:`Family.refines`), in place: the first that accepts takes the
    segment, points unchanged. Selection cannot make that choice, since both
    families explain the points equally well and ties go to the simpler one."""
    by_base: dict[str, list[Family]] = {}
    for f in families:
        if f.refines is not None:
            by_base.setdefault(f.refines, []).append(f)
    if not by_base:
        return
    for k, c in enumerate(seg):
        for f in by_base.get(c.family.name, ()):
            P = ctx.pre.points[c.indices]
            prim = f.refine(c.prim, P, ctx.pre.normals[c.indices], ctx)
            if prim is not None and f.valid(prim, ctx):
                seg.set_record(k, SegmentRecord(f, prim))
                break
