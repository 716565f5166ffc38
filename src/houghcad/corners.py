"""A corner between two faces and the rolling-ball fillet that rounds it, in 2-D.

Two primitives whose fillet is a circle swept along a line (two planes) or
about an axis (a plane, cylinder or cone and a coaxial one) meet at a corner
whose cross-section is two lines in a plane (:func:`section`). The fillet is
the circle of radius r tangent to both lines; :func:`fit_fillet` fits r to the
points of both faces near the corner by least squares (r = 0 being the sharp
corner) and tests it against the sharp corner. No library offers this; the
geometry is a few lines of numpy. :mod:`houghcad.blend` applies it to the
segments of a cloud.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .families import Family
from .families.base import Primitive, radial, unit
from .tolerances import FilletTolerances
from .kernels import kernel

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
    X, C, t, n = (np.ascontiguousarray(a, dtype=np.float64) for a in (X, C, t, n))
    return _profile_rows(X, C, t, n, float(r))


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
    r_max : float
        The largest radius tried: what the corner's band holds.
    """

    radius: float
    lr: float
    corner: np.ndarray
    rays: np.ndarray
    band: np.ndarray
    lines: np.ndarray
    taken: np.ndarray
    r_max: float


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
    ext = min(np.quantile((X - C) @ rays[k], t.extent_quantile) for k, X in enumerate((XA, XB)))
    cap = r_cap / np.tan(half)  # the band that holds a fillet of radius r_cap
    W = min(ext * t.band_share, cap)  # band along each ray
    far = min(ext, cap)  # the widest band: to the shorter face's far end
    L = _refit_lines(XA, XB, L, C, rays, W, sigma, t)
    fit = _fit_in_band(XA, XB, L, rays, half, W, sigma, XS, dS, gS, t)
    # Extension: the radii tried end where the band does. A best radius at that end (or a band
    # holding too few of the faces' points) is bounded by the band, not by the points: a rim
    # rounded on both edges, its flat narrower than its fillets, leaves less than half its extent
    # to either fillet. The band then reaches the narrower face's far end (its line stays as
    # refitted beyond the first band: few points lie beyond the second), and the better fit of
    # the two is kept.
    bounded = fit is None or fit.radius >= fit.r_max * (1 - 1 / t.radii)
    if bounded and W < far:
        wide = _fit_in_band(XA, XB, L, rays, half, far, sigma, XS, dS, gS, t)
        if wide is not None and (fit is None or wide.lr > fit.lr):
            fit = wide
    return fit


def _fit_in_band(XA: np.ndarray, XB: np.ndarray, L: np.ndarray, rays: np.ndarray, half: float, W: float,
                 sigma: float, XS: np.ndarray | None, dS: np.ndarray | None, gS: np.ndarray | None,
                 t: FilletTolerances) -> FilletFit | None:
    """:func:`fit_fillet` on the lines L (2, 3) with ``rays`` (2, 2) along them, within the band of
    width ``W`` along each ray from their corner (``half``: half the corner's angle, radians)."""
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
    return FilletFit(r, lr, C, rays, band, L, taken, r_max)


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
    X, C, rays, n = (np.ascontiguousarray(a, dtype=np.float64) for a in (X, C, rays, n))
    radii = np.linspace(r_max / t.radii, r_max, t.radii)
    sse = _profile_sse(X, C, rays, n, radii)
    j = int(np.argmin(sse))
    lo, hi = radii[max(j - 1, 0)], radii[min(j + 1, t.radii - 1)]
    fine = np.linspace(lo, hi, t.fine_radii)
    sf = _profile_sse(X, C, rays, n, fine)
    return float(fine[int(np.argmin(sf))]), float(sf.min())


@kernel(nogil=True)
def _sign(x: float) -> int:
    return (x > 0) - (x < 0)


# Scalar loops in numba: the radius grids ask for a profile's sum of squares some
# sixty times a corner, and numpy's temporaries per call were most of a corner's cost.
@kernel(nogil=True, inline="always", error_model="numpy")
def _profile_geometry(C, t, r):
    """The rounded corner of radius r: the corner-to-tangent-point length s, the arc's centre
    (ox, oy), the centre-to-tangent-point vectors ta, tb and the sign of their cross product."""
    cos_t = min(max(t[0, 0] * t[1, 0] + t[0, 1] * t[1, 1], -1.0), 1.0)
    half = np.arccos(cos_t) / 2
    bx, by = t[0, 0] + t[1, 0], t[0, 1] + t[1, 1]
    bn = np.sqrt(bx * bx + by * by)
    if bn > 0:
        bx, by = bx / bn, by / bn
    s = r / np.tan(half)
    h = r / np.sin(half)
    ox, oy = C[0] + h * bx, C[1] + h * by
    tax, tay = C[0] + s * t[0, 0] - ox, C[1] + s * t[0, 1] - oy
    tbx, tby = C[0] + s * t[1, 0] - ox, C[1] + s * t[1, 1] - oy
    return s, ox, oy, tax, tay, tbx, tby, _sign(tax * tby - tay * tbx)


@kernel(nogil=True, inline="always", error_model="numpy")
def _profile_point(X, i, C, t, n, r, geo):
    """Point i of X: its distance to the rounded corner (``geo`` from :func:`_profile_geometry`)
    and whether the arc is its nearest piece."""
    s, ox, oy, tax, tay, tbx, tby, sg = geo
    px, py = X[i, 0] - C[0], X[i, 1] - C[1]
    dist = np.inf
    for k in range(2):
        if px * t[k, 0] + py * t[k, 1] >= s:
            d = abs(px * n[k, 0] + py * n[k, 1])
        else:
            ex, ey = px - s * t[k, 0], py - s * t[k, 1]
            d = np.sqrt(ex * ex + ey * ey)
        dist = min(dist, d)
    if r > 0:
        # Within the arc's angular span: between the normals at the tangent points.
        vx, vy = X[i, 0] - ox, X[i, 1] - oy
        if _sign(tax * vy - tay * vx) == sg and _sign(vx * tby - vy * tbx) == sg:
            d_arc = abs(np.sqrt(vx * vx + vy * vy) - r)
            if d_arc < dist:
                return d_arc, True
    return dist, False


@kernel("f8[:, ::1], f8[::1], f8[:, ::1], f8[:, ::1], f8", nogil=True, error_model="numpy")
def _profile_rows(X, C, t, n, r):
    """:func:`profile_distance` in numba: distances (m,) and on-arc flags (m,)."""
    geo = _profile_geometry(C, t, r)
    dist = np.empty(X.shape[0])
    on_arc = np.zeros(X.shape[0], np.bool_)
    for i in range(X.shape[0]):
        dist[i], on_arc[i] = _profile_point(X, i, C, t, n, r, geo)
    return dist, on_arc


@kernel("f8[:, ::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[::1]", nogil=True, error_model="numpy")
def _profile_sse(X: np.ndarray, C: np.ndarray, t: np.ndarray, n: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Sum over X (m, 2) of the squared :func:`profile_distance` for each radius
    in ``radii`` (k,); returns (k,)."""
    out = np.empty(len(radii))
    for j in range(len(radii)):
        r = radii[j]
        geo = _profile_geometry(C, t, r)
        acc = 0.0
        for i in range(X.shape[0]):
            d = _profile_point(X, i, C, t, n, r, geo)[0]
            acc += d * d
        out[j] = acc
    return out
