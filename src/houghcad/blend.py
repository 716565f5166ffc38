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

#: Likelihood-ratio threshold: (SSE(sharp) − SSE(fillet)) / σ² must exceed it.
#: Under an ideal sharp corner the statistic is half χ²(1) and half 0 (r ≥ 0
#: is a boundary): above 10 with probability 8e-4. The neighbours' fitted
#: lines and the estimated σ widen that: on the sharp edges of the synthetic
#: parts (σ = 0.2 % and 0.5 % of the diagonal) it reached 11 and 16, and 28
#: where a neighbour's line was tilted by another fillet's flank (before the
#: lines were refitted, trimmed, below); so 25.
LR_MIN = 25.0
#: Radii tried per pair (uniform in (0, r_max]), before a local refinement.
N_RADII = 48


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


def _plane_line(prim: Primitive, q: np.ndarray, a: np.ndarray) -> np.ndarray | None:
    """A plane perpendicular to the axis (q, a) as the meridian line h = h0."""
    n = unit(prim.params["normal"])
    na = float(n @ a)
    if abs(na) < np.cos(np.radians(2.0)):
        return None
    return np.array([0.0, 1.0, (prim.params["offset"] - n @ q) / na])


def _coaxial(q: np.ndarray, a: np.ndarray, p: np.ndarray, b: np.ndarray, tol: float) -> bool:
    if abs(float(a @ unit(b))) < np.cos(np.radians(2.0)):
        return False
    d = p - q
    return float(np.linalg.norm(d - (d @ a) * a)) <= tol


def _axis_line(fam: Family, prim: Primitive, q: np.ndarray, a: np.ndarray, tol: float) -> np.ndarray | None:
    """A plane, cylinder or cone as a line of the meridian half-plane of the axis (q, a)."""
    p = prim.params
    if fam.name == "plane":
        return _plane_line(prim, q, a)
    if fam.name == "cylinder":
        if not _coaxial(q, a, p["axis_point"], p["axis"], tol):
            return None
        return np.array([1.0, 0.0, float(p["radius"])])
    if fam.name == "cone":
        if not _coaxial(q, a, p["apex"], p["axis"], tol):
            return None
        s = 1.0 if float(a @ p["axis"]) > 0 else -1.0
        hp = float((p["apex"] - q) @ a)
        al = float(p["half_angle"])
        # rho cos(al) - h' sin(al) = 0 with h' = s (h - hp)
        return np.array([np.cos(al), -s * np.sin(al), -s * np.sin(al) * hp])
    return None


def section(fa: Family, pa: Primitive, fb: Family, pb: Primitive, tol: float) -> Section | None:
    """The cross-section of the corner between two primitives, or None when
    their fillet is not a circle swept along a line or about an axis."""
    if fa.name == "plane" and fb.name == "plane":
        na, nb = unit(pa.params["normal"]), unit(pb.params["normal"])
        d = np.cross(na, nb)
        if np.linalg.norm(d) < np.sin(np.radians(15.0)):
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
    la, lb = _axis_line(fa, pa, q, a, tol), _axis_line(fb, pb, q, a, tol)
    if la is None or lb is None:
        return None
    if abs(la[0] * lb[1] - la[1] * lb[0]) < np.sin(np.radians(15.0)):
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
    half = 0.5 * np.arccos(cos_t)
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


def fit_fillet(XA: np.ndarray, XB: np.ndarray, L: np.ndarray, sigma: float, r_cap: float,
               XS: np.ndarray | None = None, dS: np.ndarray | None = None, gS: np.ndarray | None = None) \
        -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Best fillet radius between two 2-D point sets on lines L (2, 3).

    ``XS`` (m, 2), ``dS`` (m,), ``gS`` (m,): points of other segments, their
    distances to their own primitives and their segments' labels. A segment
    with at least 80 % of its points in the corner's band (a piece of the
    fillet that recognition found with its own, wrong primitive) is judged
    with the corner: its own primitive is part of the null model.

    Returns (r, likelihood ratio, corner C, ray directions t (2, 2), band mask
    over the stacked points [XA; XB], the lines refitted on the points
    beyond the band, labels of the segments taken in), or None when the
    lines do not make a corner both sets leave from. Lengths are in the
    units of the points; ``sigma`` is the noise's standard deviation.
    """
    C = _corner(L)
    n = L[:, :2]
    t = np.stack([[-n[0, 1], n[0, 0]], [-n[1, 1], n[1, 0]]])
    for k, X in enumerate((XA, XB)):
        if np.median((X - C) @ t[k]) < 0:
            t[k] = -t[k]
    ang = np.degrees(np.arccos(np.clip(t[0] @ t[1], -1, 1)))
    if not 25.0 < ang < 155.0:
        return None
    half = np.radians(ang) / 2
    ext = [np.quantile((X - C) @ t[k], 0.9) for k, X in enumerate((XA, XB))]
    W = min(min(ext) * 0.5, r_cap / np.tan(half))  # band along each ray
    # The neighbours' fits hold the fillet's points too, which pull them
    # toward it: their offsets again from their flats, beyond the band.
    # Their directions too, trimmed to the points within 2.5 σ of the line:
    # a segment that also holds a band of a curved neighbour (the flank of
    # another fillet) is tilted by it, and a normal a degree off leaves a
    # wedge of misfit at the corner that an arc takes up.
    L = L.copy()
    for k, X in enumerate((XA, XB)):
        far = X[(X - C) @ t[k] > W]
        lk = L[k].copy()
        for _ in range(3):
            keep = far[np.abs(far @ lk[:2] - lk[2]) <= 2.5 * sigma]
            if len(keep) < 20:
                break
            c = keep.mean(axis=0)
            _, _, vt = np.linalg.svd(keep - c, full_matrices=False)
            nk = vt[1] if vt[1] @ lk[:2] > 0 else -vt[1]
            lk = np.array([nk[0], nk[1], float(c @ nk)])
        L[k] = lk
        t[k] = np.sign(t[k] @ [-lk[1], lk[0]]) * np.array([-lk[1], lk[0]])
    n = L[:, :2]
    if abs(np.linalg.det(n)) < np.sin(np.radians(15.0)):
        return None
    C = _corner(L)
    r_max = W * np.tan(half)
    if r_max <= 2 * sigma:
        return None
    X = np.vstack([XA, XB])
    k = np.r_[np.zeros(len(XA), int), np.ones(len(XB), int)]
    along = np.einsum("ij,ij->i", X - C, t[k])
    band = (along >= -3 * sigma) & (along <= W)
    if band.sum() < 10:
        return None
    Xb = X[band]
    d0 = profile_distance(Xb, C, t, n, 0.0)[0]
    taken = np.zeros(0, np.int64)
    null = float(np.sum(d0 ** 2))
    if XS is not None and len(XS):
        al = (XS - C) @ t.T
        inside = np.all((al >= -3 * sigma) & (al <= W + 3 * sigma), axis=1)
        labels, cnt = np.unique(gS, return_counts=True)
        share = np.array([inside[gS == g].sum() for g in labels]) / cnt
        taken = labels[share >= 0.8]
        if len(taken):
            m = np.isin(gS, taken)
            dS0 = np.minimum(dS[m], profile_distance(XS[m], C, t, n, 0.0)[0])
            Xb = np.vstack([Xb, XS[m]])
            null += float(np.sum(dS0 ** 2))
    radii = np.linspace(r_max / N_RADII, r_max, N_RADII)
    sse = np.array([np.sum(profile_distance(Xb, C, t, n, r)[0] ** 2) for r in radii])
    j = int(np.argmin(sse))
    lo, hi = radii[max(j - 1, 0)], radii[min(j + 1, N_RADII - 1)]
    fine = np.linspace(lo, hi, 9)
    sf = np.array([np.sum(profile_distance(Xb, C, t, n, r)[0] ** 2) for r in fine])
    r = float(fine[int(np.argmin(sf))])
    lr = (null - float(sf.min())) / max(sigma, 1e-12) ** 2
    return r, lr, C, t, band, L, taken


def _aligned(S: SegmentView, other: SegmentView, P: np.ndarray, sigma: float, max_angle: float = 6.0) -> Primitive:
    """S's primitive; a cylinder beside a plane it nearly stands on gets the
    plane's normal as its axis (a boss on a face), its circle refitted.

    A short cylinder's axis is the least certain of its parameters: a few
    degrees off, the corner it makes with the plane is no longer a circle
    swept about one axis."""
    if S.family.name != "cylinder" or other.family.name != "plane":
        return S.prim
    a, n = unit(S.prim.params["axis"]), unit(other.prim.params["normal"])
    c = abs(float(a @ n))
    if c >= np.cos(np.radians(0.5)) or c < np.cos(np.radians(max_angle)):
        return S.prim
    n = n if a @ n > 0 else -n
    # Kasa circle fit in the plane across n (algebraic least squares).
    e1 = unit(np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0]))
    e2 = np.cross(n, e1)
    Q = P[S.indices]
    u, v = Q @ e1, Q @ e2
    keep = np.ones(len(u), bool)
    for _ in range(3):  # trimmed: the segment may hold a band of its neighbours
        M = np.stack([u[keep], v[keep], np.ones(keep.sum())], axis=1)
        sol, *_ = np.linalg.lstsq(M, u[keep] ** 2 + v[keep] ** 2, rcond=None)
        cu, cv = sol[0] / 2, sol[1] / 2
        r2 = sol[2] + cu * cu + cv * cv
        if not r2 > 0:
            return S.prim
        res = np.abs(np.hypot(u - cu, v - cv) - np.sqrt(r2))
        keep = res <= max(2.5 * sigma, np.quantile(res, 0.5))
    return Primitive("cylinder", {"axis_point": cu * e1 + cv * e2, "axis": n, "radius": float(np.sqrt(r2))})


def find_fillets(seg: Segmentation, families: list[Family], ctx: Context, passes: int = 3) -> int:
    """Add the fillets hidden between adjacent segments, in place; returns how many.

    See the module docstring. Needs the cylinder family (fillets between two
    planes) or the torus family (about an axis) among ``families``. A
    segment gives points to one fillet per pass.
    """
    total = 0
    for _ in range(passes):
        added = _fillet_pass(seg, families, ctx)
        total += added
        if not added:
            break
    return total


def _fillet_pass(seg: Segmentation, families: list[Family], ctx: Context) -> int:
    by_name = {f.name: f for f in families}
    if len(seg) < 2 or not ({"cylinder", "torus"} & set(by_name)):
        return 0
    P = ctx.pre.points
    sigma = float(ctx.pre.noise)
    owner = seg.owner()
    seg_pts = np.flatnonzero(owner >= 0)
    pairs = cKDTree(P[seg_pts]).query_pairs(ctx.link, output_type="ndarray")
    a, b = owner[seg_pts[pairs[:, 0]]], owner[seg_pts[pairs[:, 1]]]
    diff = a != b
    if not diff.any():
        return 0
    lo, hi = np.minimum(a[diff], b[diff]), np.maximum(a[diff], b[diff])
    adj, cnt = np.unique(np.stack([lo, hi], 1), axis=0, return_counts=True)
    adj = adj[cnt >= ctx.min_points]
    nbrs: dict[int, set[int]] = {}
    for u, v in adj.tolist():
        nbrs.setdefault(u, set()).add(v)
        nbrs.setdefault(v, set()).add(u)
    # Two faces that a piece of their fillet keeps apart (a strip along its
    # middle, read as a plane) are a corner too, with that piece in it.
    sizes = seg.sizes()
    bridged = {(u, v) for k, nb in nbrs.items() for u in nb for v in nb
               if u < v and sizes[k] < min(sizes[u], sizes[v]) and v not in nbrs[u]}
    tol = max(2 * ctx.tau, 0.01 * ctx.pre.diagonal)
    trees: dict[int, cKDTree] = {}

    def tree(k: int) -> cKDTree:
        if k not in trees:
            trees[k] = cKDTree(P[seg[k].indices])
        return trees[k]

    found = []
    for i, j in adj.tolist() + sorted(bridged):
        A, B = seg[i], seg[j]
        pa, pb = _aligned(A, B, P, sigma), _aligned(B, A, P, sigma)
        sec = section(A.family, pa, B.family, pb, tol)
        if sec is None:
            continue
        fam = by_name.get("cylinder" if sec.kind == "edge" else "torus")
        if fam is None:
            continue
        # Only the points of each segment near the other: the corner may run
        # along part of a long edge only.
        reach = 0.25 * ctx.pre.diagonal
        near_a = A.indices[np.isfinite(tree(j).query(P[A.indices], distance_upper_bound=reach)[0])]
        near_b = B.indices[np.isfinite(tree(i).query(P[B.indices], distance_upper_bound=reach)[0])]
        if len(near_a) < ctx.min_points or len(near_b) < ctx.min_points:
            continue
        # Segments touching both may be pieces of the fillet itself.
        third = sorted((nbrs.get(i, set()) & nbrs.get(j, set())) - {i, j})
        XS = dS = gS = None
        if third:
            iS = np.concatenate([seg[k].indices for k in third])
            gS = np.concatenate([np.full(len(seg[k].indices), k) for k in third])
            dS = np.concatenate([seg[k].family.distance(seg[k].prim, P[seg[k].indices]) for k in third])
            XS = sec.to2d(P[iS])
        XA, XB = sec.to2d(P[near_a]), sec.to2d(P[near_b])
        got = fit_fillet(XA, XB, sec.lines, sigma, r_cap=0.2 * ctx.pre.diagonal, XS=XS, dS=dS, gS=gS)
        if got is None:
            continue
        r, lr, C, t, band, lines, taken = got
        if lr < LR_MIN or r < 2 * sigma:
            continue
        # The band's points, then the taken pieces' (in XS, they are in label order too).
        pool = np.concatenate([np.r_[near_a, near_b][band], *(seg[k].indices for k in taken.tolist())])
        X2 = np.vstack([np.vstack([XA, XB])[band], *([XS[np.isin(gS, taken)]] if len(taken) else [])])
        _, on_arc = profile_distance(X2, C, t, lines[:, :2], r)
        idx = pool[on_arc]
        if len(idx) < ctx.min_points:
            continue
        half = 0.5 * np.arccos(np.clip(t[0] @ t[1], -1, 1))
        O = C + (r / np.sin(half)) * unit(t[0] + t[1])
        if sec.kind == "edge":
            prim = Primitive("cylinder", {"axis_point": sec.origin + O[0] * sec.e1 + O[1] * sec.e2,
                                          "axis": unit(np.cross(sec.e1, sec.e2)), "radius": float(r)})
        else:
            prim = Primitive("torus", {"center": sec.origin + O[1] * sec.e2, "axis": sec.e2.copy(),
                                       "major_radius": float(O[0]), "minor_radius": float(r)})
        if not fam.valid(prim, ctx):
            continue
        # What the taken segments held off the arc goes to the nearer neighbour.
        off = ~on_arc & np.isin(owner[pool], taken)
        rest = pool[off]
        dA, dB = np.abs(X2[off] @ lines[:, :2].T - lines[:, 2]).T
        found.append((lr, i, j, taken.tolist(), fam, prim, idx, rest, dA <= dB, np.minimum(dA, dB) <= ctx.tau,
                      (sec, C, t, lines, r)))
    # Strongest first; a segment gives points to one fillet per pass.
    used: set[int] = set()
    drop: set[int] = set()
    added = 0
    for lr, i, j, taken, fam, prim, idx, rest, to_a, close, (sec, C, t, lines, r) in sorted(found, key=lambda f: -f[0]):
        if used & {i, j, *taken}:
            continue
        keep = [np.setdiff1d(seg[k].indices, idx) for k in (i, j)]
        if min(len(x) for x in keep) < ctx.min_points:
            continue
        keep[0] = np.union1d(keep[0], rest[to_a & close])
        keep[1] = np.union1d(keep[1], rest[~to_a & close])
        for k, x in zip((i, j), keep):
            seg.set_points(k, x)
        seg.release(rest[~close])
        # Not refitted freely, here or later: on a quarter tube a few σ
        # across, a free torus or cylinder trades its radius for its axis
        # and drifts (minor radius 0.49 for a true 0.28); the tangency to
        # both neighbours pins it.
        arc = Arc(sec, C, t, lines[:, :2].copy(), float(r))
        seg.add(SegmentRecord(fam, prim, boundary=arc, fixed=True), np.sort(idx))
        used |= {i, j, *taken}
        drop |= set(taken)
        added += 1
    seg.remove(drop)
    return added
