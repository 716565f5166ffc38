"""Rolling-ball fillets between adjacent segments.

On exact samples at a low density, a fillet a few spacings wide is a strip
one or two points across: too narrow for any vote, its points go partly to
its two faces and stay partly free. On a noisy cloud the inlier distance τ is
a few σ. A fillet whose sag off its
two neighbours (the largest distance between the fillet and the sharp corner
they would make) is below τ sits inside both neighbours' inlier bands: the
recognition rounds give its points to them, and no vote on what is left can
see it. Here every pair of adjacent segments whose surfaces meet at a corner
with a circular fillet of one free radius (two planes: a cylinder; a plane,
cylinder or cone and a coaxial one: a torus) is tested for that fillet:

- the corner's cross-section is two lines in a plane (the plane across the
  edge, or the meridian half-plane of the common axis);
- the fillet is the circle of radius r tangent to both; r is fitted to the
  points of both segments near the corner by least squares, r = 0 being
  the sharp corner;
- a segment that touches both and lies in the corner (a piece of the
  fillet that recognition read with a primitive of its own, a cylinder
  too small or a plane along its middle) is judged with the corner: its
  points join the fit, its own primitive joins the null model;
- the fillet is kept when it explains those points better than the sharp
  corner (and the pieces' own primitives) by far more than chance (a
  likelihood-ratio test against the noise; on exact samples the noise
  estimate is about 0, and any radius that fits better is kept) and holds at least
  ``min_points`` points. Its points then form a new segment, which keeps
  the fitted radius and axis (a free refit on a quarter tube a few σ
  across drifts); it replaces the pieces.

One radius is fitted given the two neighbours' surfaces, so at a sharp edge
the best r stays near 0: free votes on the same band find spurious cylinders
there. The corner's 2-D geometry and the fit are in :mod:`houghcad.corners`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .families import Family
from .families.base import Primitive, unit
from .adjacency import SegmentGraph
from .context import Context, threads
from .multires import voxel_keys
from .state import SegmentRecord, SegmentView, Segmentation
from .corners import Arc, FilletFit, Section, fit_fillet, profile_distance, section
from .tolerances import FilletTolerances
from .normals import tree_query


#: x is a safe helper axis for a basis across n unless n is within 26° of it.
_HELPER_AXIS_COS = 0.9


def _aligned(S: SegmentView, other: SegmentView, P: np.ndarray, sigma: float, t: FilletTolerances) -> Primitive:
    """S's primitive; a cylinder beside a plane it nearly stands on gets the
    plane's normal as its axis (a boss on a face), its circle refitted.

    A short cylinder's axis is the least certain of its parameters: a few
    degrees off, the corner it makes with the plane is no longer a circle
    swept about one axis."""
    if S.family.name != "cylinder" or other.family.name != "plane":
        return S.prim
    a, n = unit(S.prim.params["axis"]), unit(other.prim.params["normal"])
    c = abs(float(a @ n))
    if c >= np.cos(np.radians(t.aligned_min_deg)) or c < np.cos(np.radians(t.aligned_max_deg)):
        return S.prim
    n = n if a @ n > 0 else -n
    e1, e2 = _across(n)
    Q = P[S.indices]
    u, v = Q @ e1, Q @ e2
    keep = np.ones(len(u), bool)
    for _ in range(t.aligned_rounds):  # trimmed: the segment may hold a band of its neighbours
        # Kasa circle fit in the plane across n (algebraic least squares).
        M = np.stack([u[keep], v[keep], np.ones(keep.sum())], axis=1)
        sol, *_ = np.linalg.lstsq(M, u[keep] ** 2 + v[keep] ** 2, rcond=None)
        cu, cv = sol[0] / 2, sol[1] / 2
        r2 = sol[2] + cu * cu + cv * cv
        if not r2 > 0:
            return S.prim
        res = np.abs(np.hypot(u - cu, v - cv) - np.sqrt(r2))
        keep = res <= max(t.trim_sigmas * sigma, np.median(res))
    return Primitive("cylinder", {"axis_point": cu * e1 + cv * e2, "axis": n, "radius": float(np.sqrt(r2))})


def _across(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across the unit normal n: from the x axis unless n is
    near it (then from y)."""
    near_x = abs(n[0]) >= _HELPER_AXIS_COS
    e1 = unit(np.cross(n, [0, 1.0, 0] if near_x else [1.0, 0, 0]))
    return e1, np.cross(n, e1)


def find_fillets(seg: Segmentation, families: list[Family], ctx: Context) -> int:
    """Add the fillets hidden between adjacent segments, in place; returns how many.

    See the module docstring. Needs the cylinder family (fillets between two
    planes) or the torus family (about an axis) among ``families``. A
    segment gives points to one fillet per pass.
    """
    total = 0
    for _ in range(ctx.tol.fillets.passes):
        added = _fillet_pass(seg, families, ctx)
        total += added
        if not added:
            break
    return total


@dataclass(frozen=True)
class _Proposal:
    """A fillet found between segments i and j, before it is applied."""

    lr: float
    i: int
    j: int
    taken: list[int]  # segments in the corner, replaced by the fillet
    family: Family
    prim: Primitive
    idx: np.ndarray  # the fillet's points
    rest: np.ndarray  # the taken segments' points off the arc
    to_a: np.ndarray  # bool (len(rest),): nearer i's line than j's
    close: np.ndarray  # bool (len(rest),): within τ of that line
    arc: Arc


def _fillet_pass(seg: Segmentation, families: list[Family], ctx: Context) -> int:
    by_name = {f.name: f for f in families}
    if len(seg) < 2 or not ({"cylinder", "torus"} & set(by_name)):
        return 0
    pairs, nbrs = _corner_pairs(seg, ctx)
    # Each pair's proposal reads the state only: the pairs go to the run's workers when it has some.
    got = ctx.workers.map_segments(_proposals, seg, pairs, ctx, families, nbrs) if ctx.workers else None
    if got is None:
        got = _proposals(seg, pairs, ctx, families, nbrs)
    return _apply(seg, [p for p in got if p is not None], ctx)


def _proposals(seg: Segmentation, pairs: list[tuple[int, int]], ctx: Context, families: list[Family],
               nbrs: dict[int, set[int]]) -> list[_Proposal | None]:
    """:func:`_propose` of each pair (i, j) of segments, in order."""
    by_name = {f.name: f for f in families}
    near = _Near(seg, ctx.pre.points, ctx.tol.fillets.reach_diagonals * ctx.pre.diagonal, threads(ctx))
    return [_propose(seg, i, j, nbrs, by_name, near, ctx) for i, j in pairs]


def _corner_pairs(seg: Segmentation, ctx: Context) -> tuple[list[tuple[int, int]], dict[int, set[int]]]:
    """Pairs (i < j) of segments to test for a fillet, and each segment's neighbours.

    Adjacent segments are those with at least min_points pairs of points
    within the link. Two faces that a piece of their fillet keeps apart (a
    strip along its middle, read as a plane) are a corner too, with that
    piece in it.
    """
    g = SegmentGraph.of(seg, ctx)
    near = g.close_pairs >= ctx.min_points
    nbrs = g.neighbours(near)
    sizes = seg.sizes()
    bridged = {(u, v) for k, nb in nbrs.items() for u in nb for v in nb
               if u < v and sizes[k] < min(sizes[u], sizes[v]) and v not in nbrs[u]}
    return [tuple(p) for p in g.edges[near].tolist()] + sorted(bridged), nbrs


def _propose(seg: Segmentation, i: int, j: int, nbrs: dict[int, set[int]], by_name: dict[str, Family],
             near: "_Near", ctx: Context) -> _Proposal | None:
    """The fillet between segments i and j, or None (see the module docstring)."""
    t = ctx.tol.fillets
    P = ctx.pre.points
    sigma = float(ctx.pre.noise)
    A, B = seg[i], seg[j]
    pa, pb = _aligned(A, B, P, sigma, t), _aligned(B, A, P, sigma, t)
    sec = section(A.family, pa, B.family, pb, max(t.coaxial_taus * ctx.tau, t.coaxial_diagonals * ctx.pre.diagonal), t)
    if sec is None:
        return None
    fam = by_name.get("cylinder" if sec.kind == "edge" else "torus")
    if fam is None:
        return None
    # Only the points of each segment near the other: the corner may run
    # along part of a long edge only.
    near_a, near_b = near.within(i, j), near.within(j, i)
    if len(near_a) < ctx.min_points or len(near_b) < ctx.min_points:
        return None
    # Segments touching both may be pieces of the fillet itself.
    third = sorted((nbrs.get(i, set()) & nbrs.get(j, set())) - {i, j})
    XS = dS = gS = None
    if third:
        iS = np.concatenate([seg[k].indices for k in third])
        gS = np.concatenate([np.full(len(seg[k].indices), k) for k in third])
        dS = np.concatenate([seg[k].family.distance(seg[k].prim, P[seg[k].indices]) for k in third])
        XS = sec.to2d(P[iS])
    XA, XB = sec.to2d(P[near_a]), sec.to2d(P[near_b])
    fit = fit_fillet(XA, XB, sec.lines, sigma, r_cap=t.max_radius_diagonals * ctx.pre.diagonal,
                     XS=XS, dS=dS, gS=gS, t=t)
    if fit is None or fit.lr < t.lr_min or fit.radius < t.min_radius_sigmas * sigma:
        return None
    # The band's points, then the taken pieces' (in XS, they are in label order too).
    pool = np.concatenate([np.r_[near_a, near_b][fit.band], *(seg[k].indices for k in fit.taken.tolist())])
    X2 = np.vstack([np.vstack([XA, XB])[fit.band], *([XS[np.isin(gS, fit.taken)]] if len(fit.taken) else [])])
    lines = fit.lines
    _, on_arc = profile_distance(X2, fit.corner, fit.rays, lines[:, :2], fit.radius)
    idx = pool[on_arc]
    if len(idx) < ctx.min_points:
        return None
    prim = _fillet_primitive(sec, fit)
    if not fam.valid(prim, ctx):
        return None
    # What the taken segments held off the arc goes to the nearer neighbour.
    off = ~on_arc & np.isin(seg.labels[pool], fit.taken)
    dA, dB = np.abs(X2[off] @ lines[:, :2].T - lines[:, 2]).T
    arc = Arc(sec, fit.corner, fit.rays, lines[:, :2].copy(), float(fit.radius))
    return _Proposal(fit.lr, i, j, fit.taken.tolist(), fam, prim, idx, pool[off], dA <= dB,
                     np.minimum(dA, dB) <= ctx.tau, arc)


class _Near:
    """Which points of a segment lie within ``reach`` of another segment's points, exactly, for the
    segments of one fillet pass (``reach`` is a quarter of the diagonal: most of a big face is that
    near its neighbours, and a nearest-neighbour search per point costs more than the fillet fits).

    A segment is also kept as one point per voxel of edge ``h = reach / COARSE``, within ``h√3`` of
    each of its points. A point within ``reach`` of that sample is within reach of the segment, one
    farther than ``reach + h√3`` from it is not; only those in between search all its points. The
    asking segment's points are first taken a voxel at a time: every point of a voxel lies within
    ``RHO`` voxel edges of its centre, so a voxel whose centre decides for all of them is settled
    without a search per point, and the answer is the per-point one.
    """

    COARSE = 8
    #: Voxel edges from a voxel's centre to its farthest point (√3 / 2, rounded up).
    RHO = 0.87
    #: A voxel's centre, in voxel edges from its lower corner along each axis.
    CENTRE = 0.5

    def __init__(self, seg: Segmentation, P: np.ndarray, reach: float, workers: int = 1):
        self.seg, self.P, self.reach, self.workers = seg, P, reach, workers
        self.h = reach / self.COARSE
        self._trees: dict[int, tuple[cKDTree, cKDTree]] = {}
        self._cells: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def _of(self, k: int) -> tuple[cKDTree, cKDTree]:
        """KD-trees of segment ``k``'s points and of its sample, one point per voxel."""
        if k not in self._trees:
            Q = self.P[self.seg[k].indices]
            self._trees[k] = (cKDTree(Q), cKDTree(Q[self._voxels(k)[0]]))
        return self._trees[k]

    def _voxels(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Segment ``k``'s occupied voxels: the first of its points (m,) in each, their centres
        (m, 3), and each point's voxel (n_k,)."""
        if k not in self._cells:
            Q = self.P[self.seg[k].indices]
            lo = Q.min(axis=0)
            _, first, inv = np.unique(voxel_keys(Q, lo, self.h), return_index=True, return_inverse=True)
            centres = lo + (np.floor((Q[first] - lo) / self.h) + self.CENTRE) * self.h
            self._cells[k] = (first, centres, inv.ravel())
        return self._cells[k]

    def within(self, i: int, k: int) -> np.ndarray:
        """The points of segment ``i`` (global indices) within ``reach`` of segment ``k``'s points."""
        idx = self.seg[i].indices
        full, coarse = self._of(k)
        _, centres, inv = self._voxels(i)
        r, slack, rho = self.reach, np.sqrt(3) * self.h, self.RHO * self.h
        D = tree_query(coarse, centres, self.workers, distance_upper_bound=2 * r)[0]
        # Per voxel: all its points near the sample (1), all beyond the exact search (0), or mixed.
        state = np.where(D + rho <= r, 1, np.where(D - rho > r + slack, 0, -1))[inv]
        ok = state == 1
        mixed = np.flatnonzero(state < 0)
        if len(mixed):
            X = self.P[idx[mixed]]
            d = tree_query(coarse, X, self.workers, distance_upper_bound=2 * r)[0]
            ok[mixed] = d <= r
            unsure = mixed[(d > r) & (d <= r + slack)]
            if len(unsure):
                ok[unsure] = np.isfinite(tree_query(full, self.P[idx[unsure]], self.workers,
                                                    distance_upper_bound=r)[0])
        return idx[ok]


def _fillet_primitive(sec: Section, fit: FilletFit) -> Primitive:
    """The fillet's cylinder (two planes) or torus (about an axis) in 3-D."""
    rays, r = fit.rays, fit.radius
    half = np.arccos(np.clip(rays[0] @ rays[1], -1, 1)) / 2
    O = fit.corner + (r / np.sin(half)) * unit(rays[0] + rays[1])
    if sec.kind == "edge":
        return Primitive("cylinder", {"axis_point": sec.origin + O[0] * sec.e1 + O[1] * sec.e2,
                                      "axis": unit(np.cross(sec.e1, sec.e2)), "radius": float(r)})
    return Primitive("torus", {"center": sec.origin + O[1] * sec.e2, "axis": sec.e2.copy(),
                               "major_radius": float(O[0]), "minor_radius": float(r)})


def _apply(seg: Segmentation, found: list[_Proposal], ctx: Context) -> int:
    """Add the proposed fillets, strongest first, in place; returns how many.
    A segment gives points to one fillet per pass."""
    used: set[int] = set()
    drop: set[int] = set()
    added = 0
    for f in sorted(found, key=lambda f: -f.lr):
        if used & {f.i, f.j, *f.taken}:
            continue
        keep = [np.setdiff1d(seg[k].indices, f.idx) for k in (f.i, f.j)]
        if min(len(x) for x in keep) < ctx.min_points:
            continue
        keep[0] = np.union1d(keep[0], f.rest[f.to_a & f.close])
        keep[1] = np.union1d(keep[1], f.rest[~f.to_a & f.close])
        for k, x in zip((f.i, f.j), keep):
            seg.set_points(k, x)
        seg.release(f.rest[~f.close])
        # Not refitted freely, here or later: on a quarter tube a few σ
        # across, a free torus or cylinder trades its radius for its axis
        # and drifts (minor radius 0.49 for a true 0.28); the tangency to
        # both neighbours pins it.
        seg.add(SegmentRecord(f.family, f.prim, boundary=f.arc, fixed=True), np.sort(f.idx))
        used |= {f.i, f.j, *f.taken}
        drop |= set(f.taken)
        added += 1
    seg.remove(drop)
    return added
