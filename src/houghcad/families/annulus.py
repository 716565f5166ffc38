"""Planar annuli: the convex combination of two concentric circles,
x = R(u) cos v, y = R(u) sin v, z = 0, R(u) = a u + (1 − u) b, u ∈ [0, 1]:
the region of a plane between the radii b (inner) and a (outer).

Standard form: the normal along z (the dominant normal direction), the
centre at the origin (the circle vote of the boundary points, refined by a
robust fit of two concentric circles). Voted: the offset z = k, as for a
plane; the radii bound the region (they are not a surface equation a point
could vote for). The fit is a maximum-likelihood fit of the centre and radii
to the points' radial distribution (:func:`ring_fit`).

An annulus explains a planar region exactly as well as its plane does, so
it refines the plane (``refines = "plane"``): when the plane is selected
too (``families="all"``), the annulus is not voted; after recognition every
plane segment is offered to :meth:`Annulus.refine`, which takes it when the
points fill a ring (shape test: :func:`_fills_ring`). Selected without the
plane (``families="annulus"``), the annulus is voted. See
docs/family-annulus.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import ndtr
from scipy.spatial import cKDTree

from ..hough import Grid
from ..preprocess import rotation_to_z
from .base import REGISTRY, Frame, Family, Placement, Primitive, register, regular_indices, tangent_basis, unit
from ._sampling import ORIGIN, TAU, Z_AXIS, Array, Sampler, partial, span
from .cylinder import circle_centers
from ._helix import band_edges

# scipy.optimize is imported in the functions that call it: its import is 66 ms of every run's
# start, and only this family (with the thread's final fit) uses it.


def boundary_directions(Q: np.ndarray, k: int = 20, ratio: float = 0.45) -> tuple[np.ndarray, np.ndarray, float]:
    """Boundary points of a 2-D point set Q (n, 2) and their inward directions.

    A point is on the boundary when the centroid of its k nearest neighbours
    is offset by more than ``ratio`` times their mean distance; the offset
    points into the region, along the boundary's normal.

    Returns the boundary mask (n,), unit directions (n, 2) and the median
    nearest-neighbour distance.
    """
    k = min(k, len(Q))
    if k < 4:
        return np.zeros(len(Q), bool), np.zeros((len(Q), 2)), 0.0
    dist, nb = cKDTree(Q).query(Q, k=k)
    off = Q[nb[:, 1:]].mean(axis=1) - Q
    ln = np.linalg.norm(off, axis=1)
    mask = ln > ratio * np.maximum(dist[:, 1:].mean(axis=1), 1e-15)
    return mask, off / np.maximum(ln, 1e-15)[:, None], float(np.median(dist[:, 1]))


def concentric_circles(Q: np.ndarray, c0: np.ndarray, scale: float, radii=None):
    """Centre (2,) and radii (r_in, r_out) of two concentric circles through the
    2-D boundary points Q (m, 2): robust least squares (soft-L1 loss of
    ``scale``) of each point's distance to the nearer circle, so that straight
    cuts of a partial annulus count as outliers. Starts from the centre c0
    and ``radii`` (default: the 5 % and 95 % quantiles of the radii). Returns
    None when it fails."""
    c0 = np.asarray(c0, float)
    rho = np.linalg.norm(Q - c0, axis=1)
    r0 = np.quantile(rho, [0.05, 0.95]) if radii is None else np.asarray(radii, float)

    def res(x):
        r = np.linalg.norm(Q - x[:2], axis=1)
        return np.minimum(np.abs(r - x[2]), np.abs(r - x[3]))

    from scipy.optimize import least_squares

    try:
        sol = least_squares(res, np.r_[c0, r0], loss="soft_l1", f_scale=max(scale, 1e-9), max_nfev=100)
    except Exception:
        return None
    c, (r1, r2) = sol.x[:2], sorted(np.abs(sol.x[2:]))
    return (c, (float(r1), float(r2))) if np.isfinite(sol.x).all() else None


_SQ2PI = float(np.sqrt(2 * np.pi))


def _ring_nll(x: np.ndarray, Q: np.ndarray, bg: float, eps: float = 0.01):
    """Negative log-likelihood of the radii ρ of 2-D points Q (n, 2) given their
    azimuths, and its gradient; x = (cx, cy, b, w, s) with a = b + w.

    Model: ρ uniform in area on [b, a] (density 2ρ / (a² − b²)), blurred by
    Gaussian noise s, mixed with ``eps`` of a uniform background ``bg`` (per
    unit of ρ). Conditioning on the azimuth makes the likelihood indifferent to
    how much of the circle the points cover: a partial ring is fitted without
    the bias a full-circle 2-D model has (its centre drifts into the arc).
    """
    cx, cy, b, w, s = x
    a = b + w
    d = Q - (cx, cy)
    rho = np.maximum(np.sqrt((d**2).sum(1)), 1e-12)
    u1, u2 = (rho - b) / s, (rho - a) / s
    # Φ(u1) − Φ(u2), from the side that does not cancel beyond a.
    t = np.where(u2 > 0, -1.0, 1.0)
    g = t * (ndtr(t * u1) - ndtr(t * u2))
    p1, p2 = np.exp(-0.5 * u1**2) / _SQ2PI, np.exp(-0.5 * u2**2) / _SQ2PI
    A = w * (a + b) / 2
    k = (1 - eps) / A
    L = k * rho * g + eps * bg
    wl = k / L
    gc = ((wl * (g + rho * (p1 - p2) / s)) / rho)[:, None] * d
    gb = -(wl * rho * ((p2 - p1) / s - g * w / A)).sum()
    gw = -(wl * rho * (p2 / s - g * (b + w) / A)).sum()
    gs = (wl * rho * (u1 * p1 - u2 * p2) / s).sum()
    return -np.log(L).sum(), np.r_[gc.sum(0), gb, gw, gs]


def _complete_sectors(Q: np.ndarray, c, b: float, a: float, s: float, k: int = 24) -> np.ndarray:
    """Mask of the points in azimuth sectors (k of them about c) whose radii
    reach both edges: their 10 % and 90 % quantiles match those of a full band.
    A straight cut of the ring truncates its sectors; they would bias the radii."""
    d = Q - c
    sec = np.minimum(((np.arctan2(d[:, 1], d[:, 0]) + np.pi) * (k / (2 * np.pi))).astype(np.int64), k - 1)
    rho = np.linalg.norm(d, axis=1)
    srt = rho[np.lexsort((rho, sec))]
    cnt = np.bincount(sec, minlength=k)
    first = np.cumsum(cnt) - cnt
    at = lambda f: srt[np.minimum(first + (f * np.maximum(cnt - 1, 0)).astype(np.int64), len(Q) - 1)]  # noqa: E731
    lo, hi = at(0.1), at(0.9)
    lo_e, hi_e = np.sqrt(b * b + np.array([0.1, 0.9]) * (a * a - b * b))
    tol = 0.08 * (a - b) + 2 * s
    good = (cnt >= 8) & (lo <= lo_e + tol) & (hi >= hi_e - tol)
    return good[sec]


def ring_fit(Q: np.ndarray, c0, b0: float, a0: float, s0: float, smin: float, trims: int = 2):
    """Centre (2,), radii b < a and edge blur s of the ring of 2-D points Q (n, 2):
    maximum likelihood (:func:`_ring_nll`) from (c0, b0, a0, s0), refitted
    ``trims`` times on the sectors that reach both edges. Returns
    (c, b, a, s, kept mask) or None."""
    ext = float(np.ptp(Q, axis=0).max()) if len(Q) else 0.0
    if len(Q) < 20 or ext <= 0:
        return None
    bg = 1.0 / ext
    w0 = max(a0 - b0, 10 * smin)
    x = np.array([c0[0], c0[1], max(b0, 0.0), w0, min(max(s0, smin), 0.25 * w0)], float)
    # A blur comparable to the band's width is no ring, and there the
    # normalisation (a² − b²)/2 fails: the likelihood grows without bound as
    # the band shrinks under a wide blur.
    bounds = [(None, None), (None, None), (0.0, None), (0.25 * w0, 4 * w0), (smin, max(0.25 * w0, smin))]
    keep = np.ones(len(Q), bool)
    from scipy.optimize import minimize

    for it in range(trims + 1):
        if it:
            k = _complete_sectors(Q, x[:2], x[2], x[2] + x[3], x[4])
            if k.sum() < max(20, 0.3 * len(Q)) or k.all() or (k == keep).all():
                break
            keep = k
        try:
            sol = minimize(_ring_nll, x, args=(Q[keep], bg), jac=True, method="L-BFGS-B", bounds=bounds,
                           options={"maxiter": 100})
        except (ValueError, FloatingPointError):
            return None
        if not np.isfinite(sol.x).all():
            return None
        x = sol.x
    # On exact samples the blur sits at its floor and the edges at about two
    # floors beyond the extreme radii; the band never extends past the points.
    rho = np.linalg.norm(Q - x[:2], axis=1)
    b, a = max(float(x[2]), float(rho.min())), min(float(x[2] + x[3]), float(rho.max()))
    if not b < a:
        return None
    return x[:2], b, a, float(x[4]), keep


def circle_centre(Q: np.ndarray) -> np.ndarray:
    """Centre of the circle best fitting all 2-D points Q (n, 2) (algebraic fit,
    then geometric): for a ring with radial ends, the ring's centre, since the
    radii do not depend on the azimuth."""
    A = np.c_[2 * Q, np.ones(len(Q))]
    c0 = np.linalg.lstsq(A, (Q**2).sum(1), rcond=None)[0][:2]
    r0 = float(np.linalg.norm(Q - c0, axis=1).mean())
    from scipy.optimize import least_squares

    try:
        sol = least_squares(lambda x: np.linalg.norm(Q - x[:2], axis=1) - x[2], np.r_[c0, r0], max_nfev=50)
    except Exception:
        return c0
    return sol.x[:2] if np.isfinite(sol.x).all() else c0


def ring_coverage(Q: np.ndarray, c, b: float, a: float) -> tuple[float, float, float, int]:
    """How the 2-D points Q (n, 2) fill the band b ≤ ρ ≤ a about c, on a grid
    of azimuth bins × four shells of equal width. Returns the fractions of the
    circle filled in the inner and in the outer shell, the fraction of cells
    filled in the bins where both of these are (below 1: holes in the band),
    and the number of separate empty stretches of the middle shells (one for
    a partial or cut ring; a ring interrupted by ribs or slots has several).

    A cell is filled when it holds at least 0.3 of the count the band's
    density predicts; the density is the 75th percentile over non-empty
    cells, so missing parts do not lower it."""
    d = Q - c
    rho = np.linalg.norm(d, axis=1)
    w = 0.25 * (a - b)
    # Noise spreads the edge shells' points a little beyond the band.
    shell = np.clip(np.floor((rho - b) / w), 0, 3).astype(np.int64)
    ok = (rho > b - w) & (rho < a + w)
    # About 8 points per inner cell when the inner shell is full.
    k = int(np.clip(np.count_nonzero(ok & (shell == 0)) // 8, 8, 36))
    sec = np.minimum(((np.arctan2(d[:, 1], d[:, 0]) + np.pi) * (k / (2 * np.pi))).astype(np.int64), k - 1)
    cnt = np.bincount(shell[ok] * k + sec[ok], minlength=4 * k).reshape(4, k).astype(float)
    if not (cnt > 0).any():
        return 0.0, 0.0, 0.0, k
    r = b + w * np.arange(5)
    area = ((r[1:] ** 2 - r[:-1] ** 2) * (np.pi / k))[:, None]
    dens = np.quantile((cnt / area)[cnt > 0], 0.75)
    filled = cnt >= np.maximum(0.3 * dens * area, 1.0)
    both = filled[0] & filled[3]
    fill = float(filled[:, both].mean()) if both.any() else 0.0
    mid = filled[1:3]
    # Empty stretches: filled → empty steps around the circle (a fully empty shell counts one).
    gaps = int(max(np.count_nonzero(m & ~np.roll(m, -1)) if m.any() else 1 for m in mid))
    return float(filled[0].mean()), float(filled[3].mean()), fill, gaps


def _fills_ring(Q, c, b, a, cover=0.4, out_in=0.6, in_out=0.85, fill=0.9) -> bool:
    """Shape test of :meth:`Annulus.refine` on :func:`ring_coverage`: the
    points fill at least ``cover`` of the circle near an edge (a half ring
    passes); a straight cut takes more of the outer circle than of the inner
    one, down to ``out_in`` of it for a quarter of the ring (a square plate
    with a hole fills it only at its corners); the converse, below ``in_out``,
    means the hole is not round (a slot); the band has no holes (``fill``) and
    at most two separate empty stretches (ribs, radial slots make more)."""
    cov_in, cov_out, filled, gaps = ring_coverage(Q, c, b, a)
    return bool(max(cov_in, cov_out) >= cover and cov_out >= out_in * cov_in and cov_in >= in_out * cov_out
                and filled >= fill and gaps <= 2)


def _plane_coords(P: np.ndarray, ref_normal):
    """Least-squares plane of P (n, 3): centroid m, unit normal n (on the side
    of ``ref_normal``), in-plane basis e1, e2, in-plane coordinates Q (n, 2)
    and the RMS distance to the plane."""
    m = P.mean(axis=0)
    n = np.linalg.svd(P - m, full_matrices=False)[2][2]
    if n @ ref_normal < 0:
        n = -n
    e1, e2 = tangent_basis(n)
    D = P - m
    return m, n, e1, e2, np.stack([D @ e1, D @ e2], axis=1), float(np.sqrt(np.mean((D @ n) ** 2)))


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_annulus(
    rng: np.random.Generator,
    n: int,
    r_inner: float,
    r_outer: float,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the planar annulus r_inner ≤ ρ ≤ r_outer of z = 0 (azimuth in ``arc``).

    ρ² is uniform. Returns points (n, 3) and normals (n, 3) (all +z).
    """
    if not r_outer > r_inner >= 0:
        raise ValueError("annulus needs r_outer > r_inner ≥ 0")
    a0, a1 = span(arc)
    rho = np.sqrt(r_inner**2 + rng.random(n) * (r_outer**2 - r_inner**2))
    th = a0 + (a1 - a0) * rng.random(n)
    pts = np.column_stack([rho * np.cos(th), rho * np.sin(th), np.zeros(n)])
    nrm = np.zeros((n, 3))
    nrm[:, 2] = 1.0
    return pts, nrm


def _annulus_area(r_inner: float, r_outer: float, arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float(0.5 * (arc[1] - arc[0]) * (r_outer**2 - r_inner**2))


def _annulus_local(r_inner: float, r_outer: float, **_: Any) -> dict[str, Any]:
    return {"center": list(ORIGIN), "normal": list(Z_AXIS), "r_inner": float(r_inner), "r_outer": float(r_outer)}


def _annulus_random(rng: np.random.Generator) -> dict[str, Any]:
    a = float(rng.uniform(0.6, 1.2))
    return {"r_inner": a * float(rng.uniform(0.3, 0.7)), "r_outer": a, "arc": partial(rng, 0.7, np.pi, 1.7 * np.pi)}


@register
class Annulus(Family):
    name = "annulus"
    param_names = ("center", "normal", "r_inner", "r_outer")
    n_unknowns = 1
    role = "complex"
    precedence = 7
    search = "cluster"
    pointwise = True
    order = 100
    color = (128, 128, 128)  # grey
    type_code = 12
    sampler = Sampler(sample_annulus, _annulus_area, _annulus_local, _annulus_random,
                      {"center": "point", "normal": "direction", "r_inner": "length", "r_outer": "length"})
    refines = "plane"

    # --- standard form and voting -------------------------------------------
    def placements(self, P, N, ctx):
        a = np.linalg.eigh(N.T @ N)[1][:, -1]
        if (np.abs(N @ a) >= ctx.cos_angle).sum() < ctx.min_points:
            return []
        R = rotation_to_z(a)
        Q = (P @ R.T)[:, :2]
        mask, M, _ = boundary_directions(Q)
        if mask.sum() < 10:
            return []
        out = []
        for c in circle_centers(Q[mask], M[mask], ctx, 2):
            fitc = concentric_circles(Q[mask], c, max(ctx.pre.noise, ctx.spacing))
            cc = fitc[0] if fitc is not None else c
            rho = np.linalg.norm(Q - cc, axis=1)
            out.append(Placement(R, R.T @ np.array([cc[0], cc[1], 0.0]), {"rho": rho}))
        return out

    def region(self, Pl, Nl, ctx):
        z = Pl[:, 2]
        lo, hi = z.min() - ctx.tau, z.max() + ctx.tau
        nb = int(np.clip(np.ceil((hi - lo) / max(ctx.cell, 1e-6)), 1, 4096))
        return Grid((lo,), (hi,), (nb,))

    def gamma(self, Pl, Nl, grid, ctx):
        idx = np.flatnonzero(np.abs(Nl[:, 2]) >= ctx.cos_angle)
        return idx, Pl[idx, 2:3]

    def primitive(self, values, placement):
        a = placement.R[2]
        b, r = band_edges(placement.info.get("rho", np.array([0.0, 1.0])), 0.0)
        return Primitive(self.name, {"center": placement.origin + float(values[0]) * a, "normal": a.copy(),
                                     "r_inner": float(b), "r_outer": float(r)})

    # --- geometry -----------------------------------------------------------
    def _local(self, prim, P):
        p = prim.params
        d = P - p["center"]
        h = d @ p["normal"]
        rho = np.linalg.norm(d - h[:, None] * p["normal"], axis=1)
        return h, rho

    def distance(self, prim, P):
        h, rho = self._local(prim, P)
        out = rho - np.clip(rho, prim.params["r_inner"], prim.params["r_outer"])
        return np.hypot(h, out)

    def surface_normals(self, prim, P):
        return np.broadcast_to(prim.params["normal"], P.shape)

    def valid(self, prim, ctx):
        p = prim.params
        # An inner radius below 5 % of the outer one is a disc: a plane.
        return 0.05 * p["r_outer"] <= p["r_inner"] < p["r_outer"] < ctx.max_radius

    def fit(self, prim, P, N):
        if len(P) < 20:
            return None
        m, n, e1, e2, Q, sigma = _plane_coords(P, prim.params["normal"])
        c0 = prim.params["center"] - m
        c0 = np.array([c0 @ e1, c0 @ e2])
        b0, a0 = prim.params["r_inner"], prim.params["r_outer"]
        if not 0 <= b0 < a0:
            b0, a0 = band_edges(np.linalg.norm(Q - c0, axis=1), sigma)
        # The spacing floors the edges' blur: on exact samples it would go to 0.
        sp = float(np.median(cKDTree(Q).query(Q, k=2)[0][:, 1]))
        got = ring_fit(Q, c0, b0, a0, max(sigma, 0.5 * sp), 0.05 * max(sp, 1e-9), trims=1)
        if got is None:
            return None
        c, b, a, _, _ = got
        return Primitive(self.name, {"center": m + c[0] * e1 + c[1] * e2, "normal": n,
                                     "r_inner": b, "r_outer": a})

    def refine(self, base, P, N, ctx):
        """The annulus for a plane segment whose points fill a ring
        (:func:`_fills_ring`) and leave no more points beyond tau than the
        plane does (the hole and the outside are empty)."""
        if len(P) < max(ctx.min_points, 50):
            return None
        sub = regular_indices(len(P), 2000)
        m, n, e1, e2, Q, sigma = _plane_coords(P[sub], base.params["normal"])
        c0 = circle_centre(Q)
        b0, a0 = band_edges(np.linalg.norm(Q - c0, axis=1), sigma)
        # Cheap exits for most faces, before the likelihood fit: no hole about
        # the best circle's centre (plates, discs), or clearly no ring about it
        # (strips, U-shaped faces), with the shape test's bounds loosened
        # since that centre is rough.
        if not (b0 >= 0.1 * a0 and a0 - b0 >= 4 * max(sigma, ctx.spacing)
                and _fills_ring(Q, c0, b0, a0, 0.4, 0.45, 0.5, 0.0)):
            return None
        got = ring_fit(Q, c0, b0, a0, max(sigma, 0.5 * ctx.spacing), 0.05 * ctx.spacing)
        if got is None:
            return None
        c, b, a, s, _ = got
        # A clear hole, and a band wide enough for the coverage grid's shells.
        if not (b >= 0.1 * a and a - b >= 4 * max(s, ctx.spacing) and _fills_ring(Q, c, b, a)):
            return None
        prim = Primitive(self.name, {"center": m + c[0] * e1 + c[1] * e2, "normal": n,
                                     "r_inner": b, "r_outer": a})
        if not self.valid(prim, ctx):
            return None
        # All of the segment, not the subsample: points in the hole or beyond
        # the outer circle (a square's corners) are what the plane has more of.
        d_a = self.distance(prim, P)
        d_p = REGISTRY[self.refines].distance(base, P)
        if (np.mean(d_a < ctx.tau) < np.mean(d_p < ctx.tau) - 0.01
                or d_a.mean() > d_p.mean() + 0.1 * ctx.tau):
            return None
        return prim

    # --- output -------------------------------------------------------------
    def to_world(self, prim, T):
        p = prim.params
        return {"center": T.inv_points(p["center"]).tolist(), "normal": unit(T.inv_dirs(p["normal"])).tolist(),
                "r_inner": T.inv_length(p["r_inner"]), "r_outer": T.inv_length(p["r_outer"])}

    length_descriptors = ("r_inner", "r_outer")

    def descriptors(self, prim):
        return {"r_inner": float(prim.params["r_inner"]), "r_outer": float(prim.params["r_outer"])}

    def frame(self, prim):
        return Frame("point", np.asarray(prim.params["center"], float), unit(prim.params["normal"]))
