"""Splitting phase (paper §5.3) and the growth of accepted segments.

What the recognition step leaves is clustered with DBSCAN; every cluster is
put in each family's standard form and recognised again. A cluster where
nothing is recognised is over-segmented with CGAL's Efficient RANSAC, and each
RANSAC piece goes through the Hough recognition: RANSAC only proposes regions,
the vote decides type and parameters.
"""

from __future__ import annotations

import ctypes
import functools
import warnings
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree
from sklearn.cluster import DBSCAN

from .families import Family
from .families.base import Primitive
from .preprocess import rotation_to_z
from .recognize import Candidate, Context, candidates, dense_subsets, inliers, mean_fitting_error, recognize, select


def owners(segments: list[Candidate], n: int) -> np.ndarray:
    """Index (n,) of the segment that holds each of n points, -1 for none."""
    owner = np.full(n, -1, dtype=np.int64)
    for j, s in enumerate(segments):
        owner[s.indices] = j
    return owner


def clusters(idx: np.ndarray, ctx: Context, min_samples: int = 4) -> list[np.ndarray]:
    """DBSCAN clusters (global indices) of the points ``idx``, largest first."""
    if len(idx) < ctx.min_points:
        return []
    lab = DBSCAN(eps=ctx.link, min_samples=min_samples).fit_predict(ctx.pre.points[idx])
    out = [idx[lab == k] for k in range(lab.max() + 1)]
    out = [c for c in out if len(c) >= ctx.min_points]
    return sorted(out, key=lambda c: (-len(c), int(c[0])))


# CGAL's Random (6.x, Random_numbers/include/CGAL/Random.h): unsigned
# random_value, val, seed, then a boost::rand48 whose 48-bit state sits in a
# uint64 at offset 16; 24 bytes in all.
_CGAL_RANDOM = "_ZZN4CGAL18get_default_randomEvE14default_random"
_CGAL_RANDOM_GUARD = "_ZGVZN4CGAL18get_default_randomEvE14default_random"
_cgal_warned = False


@functools.lru_cache(maxsize=1)
def _cgal_shape_detection() -> ctypes.CDLL:
    """The bindings' Shape_detection module as a C library (loaded once)."""
    from CGAL import _CGAL_Shape_detection

    return ctypes.CDLL(_CGAL_Shape_detection.__file__)


def seed_cgal_random(seed: int) -> bool:
    """Put CGAL's default random generator, in the calling thread, in a state
    given by ``seed``, as ``CGAL::Random(seed)`` would.

    Efficient RANSAC draws from ``CGAL::get_default_random()``, which CGAL
    seeds with ``time()`` and the Python bindings expose no way to seed: two
    runs a second apart gave different pieces. The generator is a
    thread-local object of the bindings' module, found with ``dlsym``, and
    written here. Returns False (after one warning) where that fails, for
    example with a CGAL whose ``Random`` has another layout.
    """
    global _cgal_warned
    try:
        lib = _cgal_shape_detection()
        addr = ctypes.addressof(ctypes.c_char.in_dll(lib, _CGAL_RANDOM))
        guard = ctypes.c_char.in_dll(lib, _CGAL_RANDOM_GUARD)
    except (ImportError, OSError, ValueError, AttributeError):
        if not _cgal_warned:
            _cgal_warned = True
            warnings.warn("cannot seed CGAL's random generator: the RANSAC fallback of the splitting "
                          "phase may differ between runs", RuntimeWarning, stacklevel=2)
        return False
    s = int(seed) & 0xFFFFFFFF
    head = (ctypes.c_uint32 * 3).from_address(addr)
    head[0], head[1], head[2] = s % 32749, 0, s
    ctypes.c_uint64.from_address(addr + 16).value = (s << 16) | 0x330E
    # A thread-local static is constructed on first use unless its guard is
    # set; Random has a trivial destructor, so setting it is all there is.
    guard.value = b"\x01"
    return True


def ransac_pieces(idx: np.ndarray, ctx: Context) -> list[np.ndarray]:
    """Over-segment a cluster with CGAL's Efficient RANSAC (Schnabel et al. 2007).

    Returns the pieces (global indices) RANSAC assigns to a shape. The
    bindings have no vectorised normal setter, hence the per-point loop at the
    boundary; clusters are small.
    """
    try:
        from CGAL.CGAL_Kernel import Vector_3
        from CGAL.CGAL_Point_set_3 import Point_set_3
        from CGAL.CGAL_Shape_detection import efficient_RANSAC
    except ImportError:  # pragma: no cover - cgal is a declared dependency
        return []
    P, N = ctx.pre.points[idx], ctx.pre.normals[idx]
    ps = Point_set_3()
    ps.add_normal_map()
    ps.insert_range(np.ascontiguousarray(P, dtype=np.float64).ravel())
    nm = ps.normal_map()
    for i, n in enumerate(N.tolist()):
        nm.set(i, Vector_3(*n))
    sm = ps.add_int_map("shape_index")
    seed_cgal_random(ctx.seed)
    efficient_RANSAC(ps, sm, min_points=max(ctx.min_points, 10), epsilon=max(ctx.tau, 1e-6),
                     cluster_epsilon=ctx.link, normal_threshold=float(np.cos(ctx.angle)), probability=0.01,
                     planes=True, cylinders=True, cones=True, spheres=True, tori=True)
    lab = np.fromiter((sm.get(i) for i in range(len(idx))), dtype=np.int64, count=len(idx))
    return [idx[lab == k] for k in range(lab.max() + 1) if (lab == k).sum() >= ctx.min_points]


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


def splitting_phase(families: list[Family], ctx: Context, free: np.ndarray, segments: list[Candidate],
                    max_rounds: int = 6, progress=None) -> None:
    """Iterate DBSCAN clustering + recognition on what is left, in place."""
    lctx = replace(ctx, local=True)
    for _ in range(max_rounds):
        rest = np.flatnonzero(free)
        found_any = False
        for cl in clusters(rest, ctx):
            cl = cl[free[cl]]
            if len(cl) < ctx.min_points:
                continue
            found = recognize(cl, families, lctx, free)
            if not found:
                found = coaxial_bands(cl, families, segments, free, lctx)
            if not found and len(cl) >= 3 * ctx.min_points:
                for piece in ransac_pieces(cl, ctx):
                    got = recognize(piece, families, lctx, free)
                    for c in got:  # hide from the next pieces; accept() below takes them
                        free[c.indices] = False
                    found += got
                for c in found:
                    free[c.indices] = True
            accept(found, free, ctx, segments)
            found_any |= bool(found)
            if found:
                absorb(segments, free, ctx)
            if progress is not None:
                progress(len(cl))
        if not found_any:
            break


def coaxial_bands(cl: np.ndarray, families: list[Family], segments: list[Candidate], free: np.ndarray,
                  ctx: Context) -> list[Candidate]:
    """Cylinders about the axes of the adjacent segments, for a cluster the
    normals could not place.

    A small hole or a band a few rows high between two faces has no point
    whose neighbourhood lies on it alone: its PCA normals are blends and
    neither the axis estimate nor the vote finds it, while its boundary rows,
    which lie on it too, went to the faces around it. On CAD parts such a
    feature is mostly coaxial with, or perpendicular to, a neighbour: take
    those directions as axes, the circle through the cluster's projection as
    the placement, and refit on the cluster and the adjacent boundary points
    that lie on the cylinder (one free row alone does not fix a tilt).
    """
    cyl = next((f for f in families if f.name == "cylinder"), None)
    if cyl is None or not segments or len(cl) < ctx.min_points:
        return []
    P = ctx.pre.points
    owner = owners(segments, len(P))
    k = min(12, len(P))
    dist, nb = ctx.pre.tree.query(P[cl], k=k, distance_upper_bound=ctx.link)
    nb = nb[np.isfinite(dist)]
    adj = np.unique(owner[nb])
    adj = adj[adj >= 0]
    border = np.unique(nb[owner[nb] >= 0])
    axes: list[np.ndarray] = []
    for j in adj:
        fr = segments[j].family.frame(segments[j].prim)
        if fr is None or fr.direction is None:
            continue
        a = np.asarray(fr.direction, float)
        if all(abs(a @ b) < np.cos(np.radians(2.0)) for b in axes):
            axes.append(a)
    out = []
    ext = np.concatenate([cl, border])
    for a in axes:
        R = rotation_to_z(a)
        Q = (P[cl] @ R.T)[:, :2]
        A = np.c_[2 * Q, np.ones(len(Q))]
        sol = np.linalg.lstsq(A, (Q**2).sum(1), rcond=None)[0]
        r2 = sol[2] + sol[:2] @ sol[:2]
        if not 0 < r2 < ctx.max_radius**2:
            continue
        prim = Primitive("cylinder", {"axis_point": R.T @ np.array([sol[0], sol[1], 0.0]), "axis": a,
                                      "radius": float(np.sqrt(r2))})
        for _ in range(2):
            on = ext[cyl.distance(prim, P[ext]) < 2 * ctx.tau]
            if np.isin(cl, on).mean() < 0.8:
                break
            new = cyl.fit(prim, P[on], ctx.pre.normals[on])
            if new is None or not cyl.valid(new, ctx):
                break
            prim = new
        else:
            d = cyl.distance(prim, P[cl])
            ok = d < ctx.tau
            if ok.mean() < 0.8:
                continue
            sel = cl[ok]
            for comp in dense_subsets(P[sel], ctx.link, ctx.min_points):
                out.append(Candidate(cyl, prim, sel[comp], mean_fitting_error(d[ok][comp], P[sel[comp]]),
                                     {"d": d[ok][comp]}))
    return select(out, free, ctx)


def surface_distance(s: Candidate, P: np.ndarray, signed: np.ndarray | None = None) \
        -> tuple[np.ndarray, np.ndarray | None]:
    """Distance (m,) of points P (m, 3) to segment s's surface, and which of
    them s claims outright (bool (m,)) or None. ``signed``: the points'
    signed distances to s's primitive when the caller has them already.

    A fillet found by :mod:`houghcad.blend` (``extra["arc"]``) is bounded to
    its arc: the points its rounded corner puts on its faces are at infinity
    from it, and those it puts on the arc are its own, whatever the faces'
    unbounded surfaces say there.
    """
    arc = s.extra.get("arc")
    if arc is not None:
        return arc.distance(P)
    return (s.family.distance(s.prim, P) if signed is None else np.abs(signed)), None


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


def _neighbour_owners(owner: np.ndarray, pts: np.ndarray, ctx: Context, reach: float,
                      k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k nearest neighbours (m, k) of the points ``pts`` within ``reach``
    (missing ones as index 0) and their segments in ``owner`` (-1: none)."""
    P = ctx.pre.points
    dist, nb = ctx.pre.tree.query(P[pts], k=min(k, len(P)), distance_upper_bound=reach)
    ok = np.isfinite(dist)
    nb = np.where(ok, nb, 0)
    return nb, np.where(ok, owner[nb], -1)


def _reassign(segments: list[Candidate], owner: np.ndarray, best: np.ndarray, min_points: int) -> bool:
    """Move, in place, each point from segment ``owner`` to segment ``best``
    (both (n,), -1: none), except that a segment keeps at least min_points of
    its own. Returns whether any point moved."""
    moved = best != owner
    left = np.bincount(owner[(owner >= 0) & ~moved], minlength=len(segments))
    short = moved & (owner >= 0)
    short[short] = left[owner[short]] < min_points
    best = np.where(short, owner, best)
    moved &= ~short
    if not moved.any():
        return False
    for j, s in enumerate(segments):
        keep = s.indices[best[s.indices] == j]
        add = np.flatnonzero(moved & (best == j))
        if len(add) or len(keep) < len(s.indices):
            segments[j] = replace(s, indices=np.union1d(keep, add))
    return True


def settle_edges(segments: list[Candidate], ctx: Context, delta: float, reach: float, k: int = 12) -> None:
    """Give the points that lie on two adjacent segments' surfaces to the smaller one,
    and unsegmented points that lie on an adjacent segment's surface to it.

    CAD samples include the faces' boundary curves, which lie on both faces;
    whoever was accepted first took them. To a narrow face (a fillet, a
    chamfer, a hole) those rows are a large share of its points, to a wide
    one a negligible share. ``delta``: distance to a surface that counts as
    on it (standard units).
    """
    if len(segments) < 2:
        return
    P = ctx.pre.points
    owner = owners(segments, len(P))
    sizes = np.array([len(s.indices) for s in segments])
    best = owner.copy()
    best_size = np.where(owner >= 0, sizes[np.maximum(owner, 0)], np.iinfo(np.int64).max)
    pts = np.arange(len(P))
    _, other = _neighbour_owners(owner, pts, ctx, reach, k)
    # Pairs (point, adjacent smaller segment), each once; unsegmented points
    # count as owned by an infinitely large segment.
    mask = (other >= 0) & (other != owner[pts][:, None])
    mask &= sizes[np.maximum(other, 0)] < best_size[pts][:, None]
    if not mask.any():
        return
    pi = np.broadcast_to(pts[:, None], other.shape)[mask]
    sj = other[mask]
    pairs = np.unique(np.stack([sj, pi], axis=1), axis=0)
    for j in np.unique(pairs[:, 0]):
        cand = pairs[pairs[:, 0] == j, 1]
        s = segments[j]
        cand = cand[s.family.distance(s.prim, P[cand]) < delta]
        cand = cand[sizes[j] < best_size[cand]]
        best[cand] = j
        best_size[cand] = sizes[j]
    _reassign(segments, owner, best, ctx.min_points)


def settle_noisy_edges(segments: list[Candidate], ctx: Context, reach: float, k: int = 12,
                       rounds: int = 8) -> None:
    """Noisy clouds: give each point near a boundary to the adjacent segment
    whose surface is nearest, in place.

    Scattered points near an edge lie within the inlier distance of both
    faces; whoever was accepted or grown first took a band up to ε wide of its
    neighbour's points. The nearest surface (among the point's own segment and
    the segments of its neighbours within ``reach``, with the estimated normal
    within the angle tolerance of that surface's) is the likelier face, except
    where a point lies where only one of two faces meeting at an edge reaches
    (see :func:`_sides`) and near a fillet found by :mod:`houghcad.blend`,
    whose rounded corner draws its boundaries (see :func:`surface_distance`).
    Each round moves the points next to the current boundary, so the boundary
    walks to where the surfaces cross; a segment keeps at least min_points.
    """
    if len(segments) < 2:
        return
    P, N = ctx.pre.points, ctx.pre.normals
    side = None
    for _ in range(rounds):
        owner = owners(segments, len(P))
        pts = np.flatnonzero(owner >= 0)
        _, other = _neighbour_owners(owner, pts, ctx, reach, k)
        mask = (other >= 0) & (other != owner[pts][:, None])
        if not mask.any():
            return
        pairs = np.unique(np.stack([other[mask], np.broadcast_to(pts[:, None], other.shape)[mask]], 1), axis=0)
        if side is None:
            side = _sides(segments, np.unique(np.stack([owner[pairs[:, 1]], pairs[:, 0]], 1), axis=0), ctx)
        edge = np.unique(pairs[:, 1])
        best = owner.copy()
        best_d = np.full(len(P), np.inf)
        own_s = np.zeros(len(P))
        held = np.zeros(len(P), bool)  # claimed by a fillet's arc (see surface_distance)
        for j in np.unique(owner[edge]):
            e = edge[owner[edge] == j]
            own_s[e] = segments[j].family.signed_distance(segments[j].prim, P[e])
            best_d[e], claim = surface_distance(segments[j], P[e], own_s[e])
            if claim is not None:
                held[e[claim & (best_d[e] < ctx.tau)]] = True
        for j in np.unique(pairs[:, 0]):
            cand = pairs[pairs[:, 0] == j, 1]
            s = segments[j]
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
        if not _reassign(segments, owner, best, ctx.min_points):
            return


def prefer_planes(segments: list[Candidate], families: list[Family], ctx: Context) -> int:
    """On a noisy cloud, give a plane to each curved segment that a plane
    fits as well, in place; returns how many.

    A cylinder or sphere of radius many times a face's width sags off it by
    less than the noise: on a noisy plane face it fits as well as the plane
    and may win the face by size (radii of 66 and 250 diagonals after the
    final refit, on two box faces). A cylinder, sphere or torus is compared
    with the plane by MSAC cost over all the segment's points; the plane
    takes the segment unless it is worse by more than two standard errors
    (so does a short arc of a small hole that the noise leaves flat). A
    fillet found by :mod:`houghcad.blend` keeps its primitive.
    """
    plane = next((f for f in families if f.name == "plane"), None)
    if plane is None or not ctx.noisy:
        return 0
    P, N = ctx.pre.points, ctx.pre.normals
    changed = 0
    for k, s in enumerate(segments):
        if s.family.name not in ("cylinder", "sphere", "torus") or s.extra.get("constrained") or len(s.indices) < 10:
            continue
        Q = P[s.indices]
        c = Q.mean(axis=0)
        n0 = np.linalg.eigh(np.cov(Q.T))[1][:, 0]
        prim = plane.fit(Primitive("plane", {"normal": n0, "offset": float(n0 @ c)}), Q, N[s.indices])
        if prim is None:
            continue
        d_own = np.minimum(s.family.distance(s.prim, Q), ctx.tau)
        d_pl = np.minimum(plane.distance(prim, Q), ctx.tau)
        if d_pl.mean() > d_own.mean() + 2.0 * d_own.std() / np.sqrt(len(Q)):
            continue
        d = plane.distance(prim, Q)
        segments[k] = Candidate(plane, prim, s.indices, mean_fitting_error(d, Q), {"d": d})
        changed += 1
    return changed


def _sides(segments: list[Candidate], pairs: np.ndarray, ctx: Context) -> np.ndarray:
    """side[a, b]: the side of b's surface (+1 along its normals, -1, 0
    unclear) on which a's points lie near their contact, for the segment
    pairs (m, 2); an (n, n) int8 array, 0 elsewhere.

    Two faces meeting at an edge each stop at the other: face a lies on one
    side of b's surface. A noisy point beyond a convex edge, on the far side
    of b from a's face, is a's only if its foot on b would fall outside b's
    face, where b has no points; a nearest-surface rule gives it to b
    whenever b's surface is nearer. The side is read on a's points within
    3 links of b's that lie clearly off b's surface (beyond tau), by a
    majority of 80 %; both faces' sides must be clear.
    """
    n = len(segments)
    P = ctx.pre.points
    side = np.zeros((n, n), np.int8)
    # A wrong primitive (a cylinder across a wall and its two corners) fits
    # clearly worse than the part's faces do, and its sides would spread
    # the error: it keeps the nearer-surface rule.
    fit = np.array([s.family.distance(s.prim, P[s.indices]).mean() for s in segments])
    sound = fit <= 1.5 * np.median(fit)
    trees: dict[int, cKDTree] = {}
    for a, b in {(int(min(u, v)), int(max(u, v))) for u, v in pairs.tolist() if u != v}:
        if not (sound[a] and sound[b]):
            continue
        for x, y in ((a, b), (b, a)):
            if y not in trees:
                trees[y] = cKDTree(P[segments[y].indices])
            Q = P[segments[x].indices]
            Q = Q[np.isfinite(trees[y].query(Q, distance_upper_bound=3 * ctx.link)[0])]
            if len(Q) < ctx.min_points:
                continue
            # Tangent there (a plane and the wide cylinder beside it on one
            # noisy face): no edge, and the nearer surface decides.
            ny = segments[y].family.surface_normals(segments[y].prim, Q)
            cos = np.abs(np.einsum("ij,ij->i", segments[x].family.surface_normals(segments[x].prim, Q), ny))
            if np.median(cos) >= ctx.cos_angle:
                continue
            sd = segments[y].family.signed_distance(segments[y].prim, Q, ny)
            sd = sd[np.abs(sd) >= ctx.tau]
            if len(sd) >= ctx.min_points:
                f = float(np.mean(sd > 0))
                side[x, y] = 1 if f >= 0.8 else -1 if f <= 0.2 else 0
        # An edge has each face on one side of the other; a face that
        # crosses the other (a T-junction) or straddles it (a wrong
        # primitive cutting through a face) leaves the pair to nearness.
        if side[a, b] == 0 or side[b, a] == 0:
            side[a, b] = side[b, a] = 0
    return side


def dissolve_redundant(segments: list[Candidate], ctx: Context, delta: float, reach: float,
                       k: int = 12) -> None:
    """Dissolve, in place, the small segments that their neighbours explain better.

    A sliver along an edge (points whose blurred normals kept them out of
    both faces) gets its own primitive in the splitting phase, fitted worse
    than the faces fit the same points. A segment smaller than ``3 *
    min_points`` is dissolved when every point lies within ``delta`` of a
    larger adjacent segment's surface (neighbours within ``reach``) and those
    distances are on average below its own; each point goes to the nearest
    such surface. A narrow true face (a fillet) fits its own points at least
    as well and stays.
    """
    if len(segments) < 2:
        return
    P = ctx.pre.points
    sizes = np.array([len(s.indices) for s in segments])
    small = np.flatnonzero(sizes < 3 * ctx.min_points)
    if len(small) == 0:
        return
    owner = owners(segments, len(P))
    gone: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for j in small[np.argsort(sizes[small], kind="stable")]:
        s = segments[j]
        idx = s.indices
        _, nb = ctx.pre.tree.query(P[idx], k=min(k, len(P)), distance_upper_bound=reach)
        nb = nb[nb < len(P)]
        adj = np.unique(owner[nb])
        adj = [int(a) for a in adj if a >= 0 and a != j and a not in gone and sizes[a] > sizes[j]]
        if not adj:
            continue
        d = np.stack([segments[a].family.distance(segments[a].prim, P[idx]) for a in adj])
        near = d.min(axis=0)
        own = s.family.distance(s.prim, P[idx])
        if not (near < delta).all() or near.mean() >= own.mean():
            continue
        gone[int(j)] = (idx, np.asarray(adj)[d.argmin(axis=0)])
    if not gone:
        return
    add: dict[int, list[np.ndarray]] = {}
    for idx, to in gone.values():
        for a in np.unique(to):
            add.setdefault(int(a), []).append(idx[to == a])
    for a, parts in add.items():
        s = segments[a]
        segments[a] = replace(s, indices=np.union1d(s.indices, np.concatenate(parts)))
    for j in sorted(gone, reverse=True):
        del segments[j]


def smooth_adjacency(segments: list[Candidate], ctx: Context, k: int = 8, smooth: bool = True,
                     crease: float | None = None) -> np.ndarray:
    """Pairs (m, 2) of segments that meet along a tangent-continuous boundary.

    Two segments touch where a point of one has a neighbour (within ``link``)
    in the other; the contact is smooth where the two primitives' normals at
    those points agree within the angle tolerance (the fitted surfaces', not
    the estimated normals, which blur across a crease) for most contacts.
    A pair needs at least √(points of the smaller) / 3 contact points, and 3:
    a boundary, not a corner. ``smooth=False``: any such contact. ``crease``
    (radians): the angle within which normals agree (default: half the
    angle tolerance).
    """
    if len(segments) < 2:
        return np.zeros((0, 2), np.int64)
    P = ctx.pre.points
    owner = owners(segments, len(P))
    sn = np.zeros_like(P)
    for s in segments:
        sn[s.indices] = s.family.surface_normals(s.prim, P[s.indices])
    pts = np.flatnonzero(owner >= 0)
    nb, other = _neighbour_owners(owner, pts, ctx, ctx.link, k)
    mine = owner[pts][:, None]
    cos = np.abs(np.einsum("ij,ikj->ik", sn[pts], sn[nb]))
    mask = (other >= 0) & (other != mine)
    if not mask.any():
        return np.zeros((0, 2), np.int64)
    n = len(segments)
    a, b = np.broadcast_to(mine, other.shape)[mask], other[mask]
    pi = np.broadcast_to(pts[:, None], other.shape)[mask]
    pair = np.minimum(a, b) * n + np.maximum(a, b)
    # Per pair: contact points (each once) and the share of contacts whose
    # normals agree within half the tolerance (a crease of a few degrees
    # between two faces is still a crease).
    key = np.unique(pair * len(P) + pi)
    pair_u, count = np.unique(key // len(P), return_counts=True)
    agree = cos[mask] >= np.cos(0.5 * ctx.angle if crease is None else crease)
    share = np.bincount(np.searchsorted(pair_u, pair), weights=agree, minlength=len(pair_u)) / \
        np.bincount(np.searchsorted(pair_u, pair), minlength=len(pair_u))
    sizes = np.array([len(s.indices) for s in segments])
    u, v = pair_u // n, pair_u % n
    keep = ((share >= 0.5) | (not smooth)) & (count >= np.maximum(3, np.sqrt(np.minimum(sizes[u], sizes[v])) / 3))
    return np.stack([u[keep], v[keep]], axis=1)


def consolidate(families: list[Family], ctx: Context, free: np.ndarray, segments: list[Candidate]) -> None:
    """Let complex families retake surfaces that simpler ones carved into pieces, in place.

    The global round votes only the simple families on the whole cloud; on a
    complex surface they find tangent slices (cylinders along the lobes of a
    generalised cylinder, spheres and planes on a helical surface), each
    within the inlier distance, before the per-cluster rounds can see the
    whole surface. Each group of segments joined by tangent-continuous
    boundaries is voted again by the complex families; a complex candidate
    replaces the segments it explains when it covers at least two of them
    (80 % of each one's points) and fits them no worse than they fit
    themselves. Complex segments, and those of the families voted per
    cluster, then take the adjacent pieces of their surface
    (:func:`merge_complex`). On noisy clouds every family first votes again
    on each segment fitted clearly worse than the noise
    (:func:`revisit_poor_fits`).
    """
    if len(segments) < 2:
        return
    cplx = [f for f in families if not f.simple]
    # Only noise lets simpler families slice a cone or torus in the
    # whole-cloud round (on clean samples evaluate()'s gate rejects slices).
    per_cluster = [f for f in families if f.simple and not f.global_search] if ctx.noisy else []
    if ctx.noisy:
        revisit_poor_fits(families, ctx, free, segments)
    _revote_groups(cplx, per_cluster, ctx, free, segments)
    merge_complex(segments, ctx, free)


#: Share of a poorly fitted segment that a candidate must explain to replace it.
DOMINANT = 0.6


def revisit_poor_fits(families: list[Family], ctx: Context, free: np.ndarray, segments: list[Candidate],
                      excess: float = 1.3) -> bool:
    """On a noisy cloud, vote every family again on each segment whose
    primitive fits it clearly worse than the noise, in place.

    Such a segment was mostly taken in a round that saw other surfaces too: a
    plane across a helical strip, a sphere across a generalised cylinder whose
    own candidate there also held points of its neighbours. Alone, its
    surface's family fits it to the noise.

    Fits are compared by their cost over all the segment's points, each
    distance capped at tau (MSAC: a stray point of a neighbouring face costs
    every candidate the same), less the noise's own mean distance (0.8 σ).
    Segments within ``excess`` times the noise's cost are left alone. Among
    the candidates that explain most of the segment (a share of at least
    ``DOMINANT`` of its points, 80 % of that share within tau, see
    :func:`_covered`), a more complex family displaces a simpler one only by
    halving that excess, as in selection; the choice replaces the segment
    when, on its share, it halves the excess of the segment's own primitive
    (its own family refitted, or a simpler one, need only lower it). The
    rest of the segment, often a band of a neighbouring face that no one
    primitive explains with it, is freed for its neighbours (:func:`absorb`).
    Returns whether a segment was replaced.
    """
    P = ctx.pre.points
    ref = 0.8 * ctx.pre.noise
    least = 0.05 * ref  # excesses below this are the noise's own
    lctx = replace(ctx, local=True)

    def cost(c: Candidate, idx: np.ndarray) -> float:
        return float(np.minimum(c.family.distance(c.prim, P[idx]), ctx.tau).mean()) - ref

    replaced = False

    for k in sorted(range(len(segments)), key=lambda i: -len(segments[i].indices)):
        s = segments[k]
        if len(s.indices) < 3 * ctx.min_points:
            continue
        own = cost(s, s.indices)
        if own <= (excess - 1.0) * ref:
            continue
        avail = np.zeros(len(P), bool)
        avail[s.indices] = True
        cover = []
        for c in candidates(s.indices, families, lctx, avail):
            if len(c.indices) < DOMINANT * len(s.indices):
                continue
            # The candidate's share of the segment, compared there.
            sub = replace(s, indices=c.indices)
            got = _covered(c, [sub], ctx)
            if got:
                cover.append((max(cost(c, s.indices), least), c, got[0][1]))
        best = None
        for e, c, q in sorted(cover, key=lambda t: (t[1].family.complexity, t[0])):
            if best is None or (e < 0.5 * best[0] if c.family.complexity > best[1].family.complexity else e < best[0]):
                best = (e, c, q)
        if best is None:
            continue
        e, c, q = best
        # Against the segment's own primitive on the candidate's share only:
        # the rest may be another surface, which no one primitive explains.
        mine, theirs = max(cost(c, c.indices), least), max(cost(s, c.indices), least)
        if mine >= (0.5 if c.family.complexity > s.family.complexity else 1.0) * theirs:
            continue
        free[s.indices] = True
        new = _union(c, [q], P)
        free[new.indices] = False
        segments[k] = new
        replaced = True
    return replaced


def _revote_groups(cplx: list[Family], per_cluster: list[Family], ctx: Context, free: np.ndarray,
                   segments: list[Candidate]) -> None:
    """The complex families' and the per-cluster simple families' vote on
    each group of tangent-joined segments (see :func:`consolidate`).

    A cone or torus is placed from all the normals of the whole cloud, which
    suits one of them at most: a second cone of a part comes out in cylinder,
    sphere and plane bands. Those families are voted on the group as on a
    cluster (their placements from its normals).
    """
    if not cplx and not per_cluster:
        return
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(segments)
    P = ctx.pre.points
    removed = np.zeros(n, bool)
    added: list[Candidate] = []
    joined = smooth_adjacency(segments, ctx)
    votes = []
    if cplx:
        # Voted as a whole cloud (ctx.local False): the families' gates skip a
        # group that is not one complex surface, which most groups of simple
        # faces are not (a plane, a fillet and a plane).
        votes.append((joined, cplx, ctx, False))
        if ctx.noisy:
            # Planes and spheres that slice a noisy curved surface meet at
            # creases wider than a face's own normals wander: joined up to
            # the normals' tolerance, they make the group again.
            votes.append((smooth_adjacency(segments, ctx, crease=ctx.angle), cplx, ctx, False))
    if per_cluster:
        # The bands of a noisy cone fit to the noise each, and their fitted
        # normals often disagree at their contacts: after the tangent-joined
        # groups, any contact joins them, and so the faces of a whole part;
        # the faces that dominate what remains are set aside in turn.
        lctx = replace(ctx, local=True)
        votes.append((joined, per_cluster, lctx, True))
        votes.append((smooth_adjacency(segments, ctx, smooth=False), per_cluster, lctx, True))
    # A wider grouping repeats most groups: each (families, members) is voted
    # once (a vote that took nothing would take nothing again).
    voted: set[tuple[int, ...]] = set()
    for edges, fams, vctx, peel in votes:
        g = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
        ncomp, lab = connected_components(g, directed=False)
        for comp in range(ncomp):
            members = np.flatnonzero((lab == comp) & ~removed)
            key = (id(fams), peel, *members.tolist())
            if key in voted:
                continue
            voted.add(key)
            if peel:
                # Segments of these families are whole surfaces already.
                members = np.array([m for m in members if segments[m].family not in fams], dtype=np.int64)
            sizes = np.array([len(segments[m].indices) for m in members])
            # A carved surface is cut into comparable pieces; a face that
            # dominates its group (the plane a torus meets) is not one of them.
            # Where the vote takes nothing, the largest face is set aside too
            # (twice at most): the placement from the group's normals suits
            # one surface of it, which need not be the carved one.
            retries = 2
            while True:
                while peel and len(members) >= 2 and sizes.max() > 2 / 3 * sizes.sum():
                    keep = np.arange(len(members)) != np.argmax(sizes)
                    members, sizes = members[keep], sizes[keep]
                if len(members) < 2 or sizes.max() > 2 / 3 * sizes.sum():
                    break
                region = np.concatenate([segments[m].indices for m in members])
                avail = np.zeros(len(P), bool)
                avail[region] = True
                took = False
                for c in recognize(np.sort(region), fams, vctx, avail):
                    got = _covered(c, [segments[m] for m in members], ctx)
                    got = [(members[j], q, d) for j, q, d in got if not removed[members[j]]]
                    if peel:
                        # A carved surface is contiguous: the pieces must touch one
                        # another, not only the peeled faces (two opposite holes of
                        # a thin plate lie on one torus through both).
                        got = _touching(got, edges)
                    if len(got) < 2 or _simple_suffices([segments[m] for m, _, _ in got], ctx):
                        continue
                    removed[[m for m, _, _ in got]] = True
                    added.append(_union(c, [q for _, q, _ in got], P))
                    took = True
                if took or not peel or retries == 0:
                    break
                retries -= 1
                keep = np.arange(len(members)) != np.argmax(sizes)
                members, sizes = members[keep], sizes[keep]
    if added:
        for m in np.flatnonzero(removed):
            free[segments[m].indices] = True
        for c in added:
            free[c.indices] = False
        segments[:] = [s for m, s in enumerate(segments) if not removed[m]]
        segments.extend(grow(c, free, ctx) for c in added)


def _touching(got: list, edges: np.ndarray) -> list:
    """The largest set of ``got``'s pieces (position first) connected by ``edges`` (k, 2)."""
    if len(got) < 2:
        return got
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    pos = {m: i for i, (m, _, _) in enumerate(got)}
    e = [(pos[a], pos[b]) for a, b in edges.tolist() if a in pos and b in pos]
    if not e:
        return []
    r, c = np.array(e).T
    k, lab = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(len(got),) * 2), directed=False)
    big = np.bincount(lab).argmax()
    return [g for g, l in zip(got, lab) if l == big]


def merge_complex(segments: list[Candidate], ctx: Context, free: np.ndarray, rounds: int = 10) -> None:
    """Each complex segment, or on a noisy cloud any segment, takes the
    adjacent segments that lie on its surface (a complex one only smaller
    ones), in place.

    On a noisy cloud the whole-cloud round places a cone or torus from all
    the normals, which fits one of them at most: the others' slices go to
    simpler families (two cylinder bands of a cone) before a cluster round
    finds the rest. Noise also lets a wide cylinder take part of a plane
    face beside the plane's own segment: the plane takes it back.

    Pieces of one complex surface found apart (by different clusters, or
    after a seam cut a group) each fit their own small patch; association
    merges only equal parameters, and the small patches' parameters are
    loose, so the family is voted again on the segment and those neighbours.
    A slice of another family joins when the segment fits it about as well
    as its own points.
    """
    P = ctx.pre.points
    tried: set[tuple[int, ...]] = set()  # re-votes done: each configuration once
    for _ in range(rounds):
        grown = False
        edges = smooth_adjacency(segments, ctx, smooth=False)
        order = sorted(range(len(segments)), key=lambda i: -len(segments[i].indices))
        segs: list[Candidate | None] = list(segments)
        for i in order:
            c = segs[i]
            if c is None or (c.family.simple and not ctx.noisy):
                continue
            nbrs = np.unique(np.r_[edges[edges[:, 0] == i, 1], edges[edges[:, 1] == i, 0]])
            # A cone or torus piece may be the smallest of its surface's pieces
            # (the slices came first); a complex segment takes only smaller ones.
            bound = np.inf if c.family.simple else len(c.indices)
            nbrs = [j for j in nbrs.tolist() if segs[j] is not None and len(segs[j].indices) <= bound]
            if not nbrs:
                continue
            got = _covered(c, [segs[j] for j in nbrs], ctx, own_fit=True)
            take = [(nbrs[k], q) for k, q, _ in got]
            rest = sorted(set(nbrs) - {j for j, _ in take})
            key = (len(c.indices), int(c.indices[0]), *(int(segs[j].indices[0]) for j in rest))
            # (A segment of a whole-cloud family, found on a whole face, has
            # firm parameters: it only takes what it covers.)
            if rest and key not in tried and not (c.family.simple and c.family.global_search):
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
                        free[c.indices] = True
                        c = _union(new, [mine[0][1]], P)
                        free[c.indices] = False
                        take += [(rest[k], q) for k, q, _ in more]
                    break
            for j, q in take:
                free[segs[j].indices] = True
                segs[j] = None
            if take:
                c = _union(c, [c.indices] + [q for _, q in take], P)
                free[c.indices] = False
                grown = True
            segs[i] = c
        segments[:] = [s for s in segs if s is not None]
        if not grown:
            break


def _simple_suffices(pieces: list[Candidate], ctx: Context) -> bool:
    """Whether one primitive of the pieces' own (simple) families, refitted on
    all of them, explains every piece: then they are pieces of one simple
    face (a hole split in two), for association to merge."""
    idx = np.concatenate([s.indices for s in pieces])
    sel = idx[np.sort(np.random.default_rng(ctx.seed).choice(len(idx), min(len(idx), 600), replace=False))]
    for s in sorted(pieces, key=lambda s: -len(s.indices)):
        if not s.family.simple:
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
    P, N = ctx.pre.points, ctx.pre.normals
    own = c.family.distance(c.prim, P[c.indices]).mean() if own_fit else 0.0
    out = []
    for j, s in enumerate(pieces):
        Q = s.indices
        ok, d = inliers(c.family, c.prim, P[Q], N[Q], ctx.tau, ctx.cos_angle)
        if ok.mean() < 0.8:
            continue
        mine = s.family.distance(s.prim, P[Q]).mean()
        bound = max(1.1 * mine + 0.02 * ctx.tau, 1.5 * own)
        if d[ok].mean() > bound:
            continue
        if strict and ctx.noisy and not own_fit:
            # The mean over the inliers within tau (3 σ) is truncated: a
            # surface a noise σ off the piece still passes the test above.
            # Over all the piece's points, c must fit as well as the piece's
            # own primitive, or the noise where that fits below it (a slice
            # chosen for being close), within two standard errors.
            ref = max(mine, 0.8 * ctx.pre.noise)
            if d.mean() > ref * (1.0 + 1.5 / np.sqrt(len(Q))):
                continue
        out.append((j, Q[ok], d[ok]))
    return out


def _union(c: Candidate, parts: list[np.ndarray], P: np.ndarray) -> Candidate:
    """Candidate ``c``'s primitive over the union of the index arrays ``parts``."""
    idx = np.unique(np.concatenate(parts))
    d = c.family.distance(c.prim, P[idx])
    return Candidate(c.family, c.prim, idx, mean_fitting_error(d, P[idx]), {"d": d})
