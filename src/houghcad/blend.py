"""Rolling-ball fillets between adjacent segments of a noisy cloud.

On a noisy cloud the inlier distance τ is a few σ. A fillet whose sag off its
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
  likelihood-ratio test against the noise) and holds at least
  ``min_points`` points. Its points then form a new segment, which keeps
  the fitted radius and axis (a free refit on a quarter tube a few σ
  across drifts); it replaces the pieces.

One radius is fitted given the two neighbours' surfaces, so at a sharp edge
the best r stays near 0: free votes on the same band find spurious cylinders
there. No library offers fillet detection on point segments; the 2-D
geometry below is a few lines of numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .families import Family
from .families.base import Primitive, radial, unit
from .context import Context
from .state import SegmentRecord, SegmentView, Segmentation
from .tolerances import FilletTolerances

_DEFAULT = FilletTolerances()

#: The likelihood-ratio test (:attr:`FilletTolerances.lr_min`):
#: (SSE(sharp) − SSE(fillet)) / σ² must exceed it. Under an ideal sharp
#: corner the statistic is half χ²(1) and half 0 (r ≥ 0 is a boundary): above
#: 10 with probability 8e-4. The neighbours' fitted lines and the estimated σ
#: widen that: on the sharp edges of the synthetic parts (σ = 0.2 % and 0.5 %
#: of the diagonal) it reached 11 and 16, and 28 where a neighbour's line was
#: tilted by another fillet's flank (before the lines were refitted, trimmed,
#: below); so 25.
LR_MIN = FilletTolerances().lr_min
#: A guard against a zero noise estimate.
_TINY = 1e-12
#: x is a safe helper axis for a basis across n unless n is within 26° of it.
_HELPER_AXIS_COS = 0.9


@dataclass
class Section:
    """A corner's cross-section: 2-D coordinates of 3-D points and two lines.

    ``lines`` (2, 3): rows (nx, ny, c) of the lines n·x = c (unit n), one per segment.
    ``to2d`` maps points (m, 3) to (m, 2). ``kind`` is "edge" (two planes,
    coordinates across their common line) or "axis" (meridian (ρ, h) of a
    common axis).
    """

    kind: str
    lines: np.ndarray
    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray

    def to2d(self, P: np.ndarray) -> np.ndarray:
        if self.kind == "edge":
            d = P - self.origin
            return np.stack([d @ self.e1, d @ self.e2], axis=1)
        h, rho, _ = radial(P, self.origin, self.e2)
        return np.stack([rho, h], axis=1)


def _plane_line(prim: Primitive, q: np.ndarray, a: np.ndarray, t: FilletTolerances) -> np.ndarray | None:
    """A plane perpendicular to the axis (q, a) as the meridian line h = h0."""
    n = unit(prim.params["normal"])
    na = float(n @ a)
    if abs(na) < np.cos(np.radians(t.coaxial_deg)):
        return None
    return np.array([0.0, 1.0, (prim.params["offset"] - n @ q) / na])


def _coaxial(q: np.ndarray, a: np.ndarray, p: np.ndarray, b: np.ndarray, tol: float, t: FilletTolerances) -> bool:
    if abs(float(a @ unit(b))) < np.cos(np.radians(t.coaxial_deg)):
        return False
    d = p - q
    return float(np.linalg.norm(d - (d @ a) * a)) <= tol


def _axis_line(fam: Family, prim: Primitive, q: np.ndarray, a: np.ndarray, tol: float,
               t: FilletTolerances) -> np.ndarray | None:
    """A plane, cylinder or cone as a line of the meridian half-plane of the axis (q, a)."""
    p = prim.params
    if fam.name == "plane":
        return _plane_line(prim, q, a, t)
    if fam.name == "cylinder":
        if not _coaxial(q, a, p["axis_point"], p["axis"], tol, t):
            return None
        return np.array([1.0, 0.0, float(p["radius"])])
    if fam.name == "cone":
        if not _coaxial(q, a, p["apex"], p["axis"], tol, t):
            return None
        s = 1.0 if float(a @ p["axis"]) > 0 else -1.0
        hp = float((p["apex"] - q) @ a)
        al = float(p["half_angle"])
        # rho cos(al) - h' sin(al) = 0 with h' = s (h - hp)
        return np.array([np.cos(al), -s * np.sin(al), -s * np.sin(al) * hp])
    return None


def section(fa: Family, pa: Primitive, fb: Family, pb: Primitive, tol: float,
            t: FilletTolerances = _DEFAULT) -> Section | None:
    """The cross-section of the corner between two primitives, or None when
    their fillet is not a circle swept along a line or about an axis.
    ``tol``: axis lines this close are one (standard units)."""
    if fa.name == "plane" and fb.name == "plane":
        na, nb = unit(pa.params["normal"]), unit(pb.params["normal"])
        d = np.cross(na, nb)
        if np.linalg.norm(d) < np.sin(np.radians(t.parallel_deg)):
            return None
        d = unit(d)
        M = np.stack([na, nb, d])
        origin = np.linalg.solve(M, np.array([pa.params["offset"], pb.params["offset"], 0.0]))
        e1 = na
        e2 = np.cross(d, e1)
        lines = np.array([[1.0, 0.0, 0.0], [nb @ e1, nb @ e2, 0.0]])
        lines[1, :2] /= np.linalg.norm(lines[1, :2])
        return Section("edge", lines, origin, e1, e2)
    axes = []
    for f, p in ((fa, pa), (fb, pb)):
        if f.name == "cylinder":
            axes.append((np.asarray(p.params["axis_point"], float), unit(p.params["axis"])))
        elif f.name == "cone":
            axes.append((np.asarray(p.params["apex"], float), unit(p.params["axis"])))
    if not axes:
        return None
    q, a = axes[0]
    la, lb = _axis_line(fa, pa, q, a, tol, t), _axis_line(fb, pb, q, a, tol, t)
    if la is None or lb is None:
        return None
    if abs(la[0] * lb[1] - la[1] * lb[0]) < np.sin(np.radians(t.parallel_deg)):
        return None  # parallel in the meridian plane: two coaxial cylinders, two parallel planes
    return Section("axis", np.stack([la, lb]), q, np.zeros(3), a)


def profile_distance(X: np.ndarray, C: np.ndarray, t: np.ndarray, n: np.ndarray, r: float) \
        -> tuple[np.ndarray, np.ndarray]:
    """Distance of 2-D points X (m, 2) to a corner rounded with radius r.

    The corner C (2,) joins two rays of unit directions t (2, 2); n (2, 2)
    are the lines' unit normals. r = 0 is the sharp corner. Returns the
    distance (m,) and whether the arc is the nearest piece (m,).
    """
    cos_t = float(np.clip(t[0] @ t[1], -1.0, 1.0))
    half = np.arccos(cos_t) / 2
    s = r / np.tan(half)  # corner to tangent points
    dist = np.full(len(X), np.inf)
    for k in range(2):
        along = (X - C) @ t[k]
        across = np.abs((X - C) @ n[k])
        end = C + s * t[k]
        d = np.where(along >= s, across, np.linalg.norm(X - end, axis=1))
        dist = np.minimum(dist, d)
    on_arc = np.zeros(len(X), bool)
    if r > 0:
        b = unit(t[0] + t[1])
        O = C + (r / np.sin(half)) * b
        v = X - O
        rv = np.linalg.norm(v, axis=1)
        # Within the arc's angular span: between the normals at the tangent points.
        ta, tb = C + s * t[0] - O, C + s * t[1] - O
        cross = lambda u, w: u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]  # noqa: E731
        inside = (np.sign(cross(ta, v)) == np.sign(cross(ta, tb))) & (np.sign(cross(v, tb)) == np.sign(cross(ta, tb)))
        d_arc = np.where(inside, np.abs(rv - r), np.inf)
        on_arc = d_arc < dist
        dist = np.minimum(dist, d_arc)
    return dist, on_arc


@dataclass
class Arc:
    """A fillet's rounded corner, for the boundaries drawn after it is found.

    Its torus or cylinder goes on past the arc, and its two faces' surfaces
    past the tangent points into the corner; near a fillet a few σ across,
    nearest-surface boundaries on those unbounded surfaces hand much of the
    arc to its faces and give it points of theirs. The rounded profile (two
    rays from the tangent points and the arc between them) draws them as the
    fillet was found.
    """

    section: Section
    C: np.ndarray  # (2,) the sharp corner
    t: np.ndarray  # (2, 2) the rays' unit directions
    n: np.ndarray  # (2, 2) the lines' unit normals
    r: float

    def distance(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance of points P (m, 3) to the arc and whether the rounded
        profile puts them on it (m,); off it the distance is inf."""
        d, on = profile_distance(self.section.to2d(P), self.C, self.t, self.n, self.r)
        return np.where(on, d, np.inf), on


def _corner(L: np.ndarray) -> np.ndarray:
    return np.linalg.solve(L[:, :2], L[:, 2])



@dataclass(frozen=True)
class FilletFit:
    """The best fillet of a corner (:func:`fit_fillet`), in the section's 2-D units.

    Attributes
    ----------
    radius : float
    lr : float
        Likelihood ratio against the sharp corner, (SSE(sharp) − SSE(fillet)) / σ².
    corner : ndarray (2,)
        The sharp corner C.
    rays : ndarray (2, 2)
        Unit directions of the two rays from C.
    band : ndarray of bool
        Over the stacked points [XA; XB]: those in the corner's band.
    lines : ndarray (2, 3)
        The two lines refitted beyond the band.
    taken : ndarray of int
        Labels of the other segments judged with the corner.
    """

    radius: float
    lr: float
    corner: np.ndarray
    rays: np.ndarray
    band: np.ndarray
    lines: np.ndarray
    taken: np.ndarray


def fit_fillet(XA: np.ndarray, XB: np.ndarray, L: np.ndarray, sigma: float, r_cap: float,
               XS: np.ndarray | None = None, dS: np.ndarray | None = None, gS: np.ndarray | None = None,
               t: FilletTolerances = _DEFAULT) -> FilletFit | None:
    """Best fillet radius between two 2-D point sets on lines L (2, 3).

    ``XS`` (m, 2), ``dS`` (m,), ``gS`` (m,): points of other segments, their
    distances to their own primitives and their segments' labels. A segment
    with at least ``taken_share`` of its points in the corner's band (a
    piece of the fillet that recognition found with its own, wrong
    primitive) is judged with the corner: its own primitive is part of the
    null model.

    None when the lines do not make a corner both sets leave from. Lengths
    are in the units of the points; ``sigma`` is the noise's standard
    deviation, ``r_cap`` the largest radius tried.
    """
    C = _corner(L)
    n = L[:, :2]
    rays = np.stack([[-n[0, 1], n[0, 0]], [-n[1, 1], n[1, 0]]])
    for k, X in enumerate((XA, XB)):
        if np.median((X - C) @ rays[k]) < 0:
            rays[k] = -rays[k]
    ang = np.degrees(np.arccos(np.clip(rays[0] @ rays[1], -1, 1)))
    if not t.corner_min_deg < ang < t.corner_max_deg:
        return None
    half = np.radians(ang) / 2
    ext = [np.quantile((X - C) @ rays[k], t.extent_quantile) for k, X in enumerate((XA, XB))]
    W = min(min(ext) * t.band_share, r_cap / np.tan(half))  # band along each ray
    L = _refit_lines(XA, XB, L, C, rays, W, sigma, t)
    n = L[:, :2]
    if abs(np.linalg.det(n)) < np.sin(np.radians(t.parallel_deg)):
        return None
    C = _corner(L)
    r_max = W * np.tan(half)
    if r_max <= t.min_radius_sigmas * sigma:
        return None
    X = np.vstack([XA, XB])
    k = np.r_[np.zeros(len(XA), int), np.ones(len(XB), int)]
    along = np.einsum("ij,ij->i", X - C, rays[k])
    band = (along >= -t.band_before_sigmas * sigma) & (along <= W)
    if band.sum() < t.band_min_points:
        return None
    Xb = X[band]
    d0 = profile_distance(Xb, C, rays, n, 0.0)[0]
    taken = np.zeros(0, np.int64)
    null = float(np.sum(d0 ** 2))
    if XS is not None and len(XS):
        al = (XS - C) @ rays.T
        inside = np.all((al >= -t.band_before_sigmas * sigma) & (al <= W + t.band_before_sigmas * sigma), axis=1)
        labels, cnt = np.unique(gS, return_counts=True)
        share = np.array([inside[gS == g].sum() for g in labels]) / cnt
        taken = labels[share >= t.taken_share]
        if len(taken):
            m = np.isin(gS, taken)
            dS0 = np.minimum(dS[m], profile_distance(XS[m], C, rays, n, 0.0)[0])
            Xb = np.vstack([Xb, XS[m]])
            null += float(np.sum(dS0 ** 2))
    r, sse = _best_radius(Xb, C, rays, n, r_max, t)
    lr = (null - sse) / max(sigma, _TINY) ** 2
    return FilletFit(r, lr, C, rays, band, L, taken)


def _refit_lines(XA: np.ndarray, XB: np.ndarray, L: np.ndarray, C: np.ndarray, rays: np.ndarray, W: float,
                 sigma: float, t: FilletTolerances) -> np.ndarray:
    """The lines L (2, 3) refitted on each set's points beyond the band W,
    trimmed to the points within ``trim_sigmas`` σ of the line; ``rays``
    (2, 2) follow them, in place.

    The neighbours' fits hold the fillet's points too, which pull them toward
    it: their offsets again from their flats, beyond the band. Their
    directions too: a segment that also holds a band of a curved neighbour
    (the flank of another fillet) is tilted by it, and a normal a degree off
    leaves a wedge of misfit at the corner that an arc takes up.
    """
    L = L.copy()
    for k, X in enumerate((XA, XB)):
        far = X[(X - C) @ rays[k] > W]
        lk = L[k].copy()
        for _ in range(t.trim_rounds):
            keep = far[np.abs(far @ lk[:2] - lk[2]) <= t.trim_sigmas * sigma]
            if len(keep) < t.trim_min_points:
                break
            c = keep.mean(axis=0)
            _, _, vt = np.linalg.svd(keep - c, full_matrices=False)
            nk = vt[1] if vt[1] @ lk[:2] > 0 else -vt[1]
            lk = np.array([nk[0], nk[1], float(c @ nk)])
        L[k] = lk
        rays[k] = np.sign(rays[k] @ [-lk[1], lk[0]]) * np.array([-lk[1], lk[0]])
    return L


def _best_radius(X: np.ndarray, C: np.ndarray, rays: np.ndarray, n: np.ndarray, r_max: float,
                 t: FilletTolerances) -> tuple[float, float]:
    """The radius in (0, r_max] whose rounded corner fits X (m, 2) best, and
    its sum of squared distances: a grid, then a finer grid about its best."""
    radii = np.linspace(r_max / t.radii, r_max, t.radii)
    sse = np.array([np.sum(profile_distance(X, C, rays, n, r)[0] ** 2) for r in radii])
    j = int(np.argmin(sse))
    lo, hi = radii[max(j - 1, 0)], radii[min(j + 1, t.radii - 1)]
    fine = np.linspace(lo, hi, t.fine_radii)
    sf = np.array([np.sum(profile_distance(X, C, rays, n, r)[0] ** 2) for r in fine])
    return float(fine[int(np.argmin(sf))]), float(sf.min())


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
    P = ctx.pre.points
    trees: dict[int, cKDTree] = {}

    def tree(k: int) -> cKDTree:
        if k not in trees:
            trees[k] = cKDTree(P[seg[k].indices])
        return trees[k]

    found = [p for i, j in pairs if (p := _propose(seg, i, j, nbrs, by_name, tree, ctx)) is not None]
    return _apply(seg, found, ctx)


def _corner_pairs(seg: Segmentation, ctx: Context) -> tuple[list[tuple[int, int]], dict[int, set[int]]]:
    """Pairs (i < j) of segments to test for a fillet, and each segment's neighbours.

    Adjacent segments are those with at least min_points pairs of points
    within the link. Two faces that a piece of their fillet keeps apart (a
    strip along its middle, read as a plane) are a corner too, with that
    piece in it.
    """
    P = ctx.pre.points
    owner = seg.owner()
    seg_pts = np.flatnonzero(owner >= 0)
    close = cKDTree(P[seg_pts]).query_pairs(ctx.link, output_type="ndarray")
    a, b = owner[seg_pts[close[:, 0]]], owner[seg_pts[close[:, 1]]]
    diff = a != b
    if not diff.any():
        return [], {}
    lo, hi = np.minimum(a[diff], b[diff]), np.maximum(a[diff], b[diff])
    adj, cnt = np.unique(np.stack([lo, hi], 1), axis=0, return_counts=True)
    adj = adj[cnt >= ctx.min_points]
    nbrs: dict[int, set[int]] = {}
    for u, v in adj.tolist():
        nbrs.setdefault(u, set()).add(v)
        nbrs.setdefault(v, set()).add(u)
    sizes = seg.sizes()
    bridged = {(u, v) for k, nb in nbrs.items() for u in nb for v in nb
               if u < v and sizes[k] < min(sizes[u], sizes[v]) and v not in nbrs[u]}
    return [tuple(p) for p in adj.tolist()] + sorted(bridged), nbrs


def _propose(seg: Segmentation, i: int, j: int, nbrs: dict[int, set[int]], by_name: dict[str, Family],
             tree, ctx: Context) -> _Proposal | None:
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
    reach = t.reach_diagonals * ctx.pre.diagonal
    near_a = A.indices[np.isfinite(tree(j).query(P[A.indices], distance_upper_bound=reach)[0])]
    near_b = B.indices[np.isfinite(tree(i).query(P[B.indices], distance_upper_bound=reach)[0])]
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
