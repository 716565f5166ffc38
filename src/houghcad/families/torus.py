"""Tori. Standard form (√(x²+y²) − R)² + z² = r²: two unknowns (R, r) once
the axis is along z and the centre at the origin."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..hough import Grid, persistent_peaks, smooth
from ..preprocess import rotation_to_z
from .base import (Frame, Family, Placement, Primitive, axis_from_normal_lines, axial, radial, register, swept_votes,
                   axial_row, tangent_basis, turned_axis, unit)
from . import _lm
from ._sampling import ORIGIN, TAU, Z_AXIS, Array, Sampler, partial, span
from ..kernels import kernel


def torus_frame(P, N):
    """Axis from the normal lines (they all meet it); centre along the axis
    where, in the meridian plane, the normal lines meet at (R, h0)."""
    q, a, _, _ = axis_from_normal_lines(P, N)
    h, rho, rad = radial(P, q, a)
    centre = meridian_centre(rho, h, np.einsum("ij,ij->i", N, rad), N @ a)
    if centre is None:
        return q, a, 0.0
    return q + centre[1] * a, a, centre[0]


def meridian_centre(rho: np.ndarray, h: np.ndarray, n_rho: np.ndarray, n_h: np.ndarray,
                    spread: float = 0.0) -> tuple[float, float] | None:
    """Where the normal lines (rho, h) + t (n_rho, n_h) of the meridian plane meet (all (n,)),
    least squares: the tube's centre (R, h0), or None when their directions spread less than
    ``spread`` (the smallest eigenvalue of the lines' projector sum against the largest;
    parallel lines meet nowhere)."""
    D = np.stack([n_rho, n_h], axis=1)
    D = D / np.maximum(np.linalg.norm(D, axis=1, keepdims=True), 1e-12)
    A = np.eye(2)[None] - D[:, :, None] * D[:, None, :]
    M = A.sum(axis=0)
    b = np.einsum("nij,nj->i", A, np.stack([rho, h], axis=1))
    ev = np.linalg.eigvalsh(M)
    if np.linalg.cond(M) > 1e8 or ev[0] < spread * ev[1]:
        return None
    R0, h0 = np.linalg.solve(M, b)
    return float(R0), float(h0)


#: Spread of the normals' directions in the meridian plane (eigenvalue ratio, about the
#: squared standard deviation of their angles in radians) from which their meeting point is
#: trusted to place the tube's centre: a band 10 degrees wide around the tube.
MERIDIAN_SPREAD = 0.01
#: Most bins per axis of the torus accumulator.
MAX_BINS = 200


def tube_heights(P: np.ndarray, N: np.ndarray, q: np.ndarray, a: np.ndarray, ctx) -> list[float]:
    """Heights along the axis (point q, direction a (3,)) of the tube centres a torus is sought
    about, for the points P and normals N (n, 3).

    The normal lines of a torus meet its axis and, in the meridian plane, its tube's centre: the
    least-squares meeting point comes first, as the paper finds it, and is the only one in a
    cluster's round (one connected region: extra tubes there let slices of its faces compete, and
    cost Fit4CAD 0.7 thousandths). On the whole cloud (a noisy part, where the torus joins the
    first round) of a part turned about the axis, when fewer than ``tube_centre_share`` of the
    lines pass near that point, it is no meeting point but the average of several (a bead, a
    groove, the cylinder's and the planes' lines); each line then votes for the meridian cells
    it crosses, and the persistent peaks, where many lines meet, add their heights.
    """
    h, rho, rad = radial(P, q, a)
    n_rho, n_h = np.einsum("ij,ij->i", N, rad), N @ a
    centre = meridian_centre(rho, h, n_rho, n_h)
    heights = [0.0 if centre is None else centre[1]]
    if ctx.local:
        return heights
    t = ctx.tol.recognition
    lo = np.array([0.0, h.min() - ctx.tau])
    ext = np.array([rho.max() + ctx.tau, h.max() + ctx.tau]) - lo
    cell = max(float(ext.max()) / t.meridian_bins, ctx.tau)
    D = np.stack([n_rho, n_h], axis=1)
    D /= np.maximum(np.linalg.norm(D, axis=1, keepdims=True), 1e-12)
    reach = t.meet_cells * cell
    if centre is not None:
        off = np.abs(D[:, 0] * (centre[1] - h) - D[:, 1] * (centre[0] - rho))  # each line's distance to it
        if np.mean(off <= reach) >= t.tube_centre_share:
            return heights
    # Other centres are sought on a turned part only, where most of the normal lines that are
    # not parallel to the axis (a disc's are) meet it; elsewhere the axis, and any meeting
    # point on it, is an average of unrelated surfaces, and lines too noisy to meet their axis
    # meet each other at random.
    cross = np.cross(N, a)
    sin = np.linalg.norm(cross, axis=1)
    slanted = sin >= np.sin(np.radians(t.parallel_deg))
    miss = np.abs(np.einsum("ij,ij->i", P[slanted] - q, cross[slanted])) / sin[slanted]
    if not slanted.any() or np.mean(miss <= reach) < t.turned_share:
        return heights
    bins = np.maximum(np.ceil(ext / cell).astype(np.int64), 1)
    H = smooth(_line_votes(rho, h, D[:, 0], D[:, 1], lo[0], lo[1], cell, int(bins[0]), int(bins[1])))
    pk, _ = persistent_peaks(H, ctx.persistence, max_peaks=t.tube_centres)
    for k in pk[H.ravel()[pk] >= ctx.min_votes]:
        # Lines meeting on or beside the axis meet at a sphere's centre or near a cone's apex,
        # which those families vote on their own; a torus there is a sphere with a spindle.
        if k // bins[1] < t.axis_cells:
            continue
        z = lo[1] + (k % bins[1] + 0.5) * cell
        if all(abs(z - y) > cell for y in heights):
            heights.append(float(z))
    return heights


# By hand in numba: rasterising lines into an accumulator, one vote per cell a line crosses.
@kernel("f8[::1], f8[::1], f8[:], f8[:], f8, f8, f8, i8, i8")
def _line_votes(rho, h, d_rho, d_h, lo_rho, lo_h, cell, n_rho, n_h):
    """Votes (n_rho, n_h) of the lines (rho, h) + t (d_rho, d_h) (all (n,), directions unit) over
    the meridian cells ``cell`` wide from (lo_rho, lo_h): each line once per cell it crosses."""
    H = np.zeros((n_rho, n_h))
    step = 0.5 * cell
    m = int(np.ceil(np.hypot(n_rho, n_h) * cell / step))
    for i in range(rho.size):
        last = -1
        for k in range(-m, m + 1):
            x = int(np.floor((rho[i] + k * step * d_rho[i] - lo_rho) / cell))
            y = int(np.floor((h[i] + k * step * d_h[i] - lo_h) / cell))
            if 0 <= x < n_rho and 0 <= y < n_h:
                c = x * n_h + y
                if c != last:
                    H[x, y] += 1.0
                    last = c
    return H


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_torus(
    rng: np.random.Generator,
    n: int,
    major: float,
    minor: float,
    u_range: tuple[float, float] = (0.0, TAU),
    v_range: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on a ring torus around z, centred at the origin (major > minor > 0).

    Point ``((R + r cos v) cos u, (R + r cos v) sin u, r sin v)``: u (rad) goes around the axis,
    v (rad) around the tube (v = 0 outermost, v = π/2 top). The area element
    ``r (R + r cos v) du dv`` is honoured by drawing v by inverse CDF (interpolated start,
    then Newton steps on the closed-form CDF). Returns points (n, 3), outward normals (n, 3).
    """
    if not major > minor > 0:
        raise ValueError("torus needs major > minor > 0")
    u0, u1 = span(u_range)
    v0, v1 = span(v_range)
    u = u0 + (u1 - u0) * rng.random(n)

    def cdf(v: Array) -> Array:
        return major * (v - v0) + minor * (np.sin(v) - np.sin(v0))

    target = rng.random(n) * cdf(np.array(v1))
    grid = np.linspace(v0, v1, 1025)
    v = np.interp(target, cdf(grid), grid)
    for _ in range(4):
        v = np.clip(v - (cdf(v) - target) / (major + minor * np.cos(v)), v0, v1)
    cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
    nrm = np.column_stack([cv * cu, cv * su, sv])
    pts = np.column_stack([(major + minor * cv) * cu, (major + minor * cv) * su, minor * sv])
    return pts, nrm


def _torus_area(
    major: float, minor: float, u_range: tuple[float, float] = (0.0, TAU), v_range: tuple[float, float] = (0.0, TAU)
) -> float:
    dv = v_range[1] - v_range[0]
    return float(minor * (u_range[1] - u_range[0]) * (major * dv + minor * (np.sin(v_range[1]) - np.sin(v_range[0]))))


def _torus_local(major: float, minor: float, **_: Any) -> dict[str, Any]:
    return {"center": list(ORIGIN), "axis": list(Z_AXIS), "major_radius": float(major), "minor_radius": float(minor)}


def _torus_random(rng: np.random.Generator) -> dict[str, Any]:
    major = float(rng.uniform(0.8, 1.2))
    return {
        "major": major,
        "minor": major * float(rng.uniform(0.2, 0.5)),
        "u_range": partial(rng, 0.5, np.pi / 2, 1.7 * np.pi),
        "v_range": partial(rng, 0.6, np.pi, 1.8 * np.pi),
    }


@register
class Torus(Family):
    name = "torus"
    param_names = ("center", "axis", "major_radius", "minor_radius")
    n_unknowns = 2
    role = "simple"
    precedence = 4
    search = "cluster"
    pointwise = True
    order = 50
    color = (0, 0, 0)  # black
    type_code = 5
    sampler = Sampler(sample_torus, _torus_area, _torus_local, _torus_random,
                      {"center": "point", "axis": "direction", "major_radius": "length", "minor_radius": "length"})

    def placements(self, P, N, ctx):
        q, a, _, _ = axis_from_normal_lines(P, N)
        R = rotation_to_z(a)
        return [Placement(R, q + z * a) for z in tube_heights(P, N, q, a, ctx)]

    def region(self, Pl, Nl, ctx):
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        hi = min(float(rho.max()) + ctx.tau, ctx.max_radius)
        nb = int(np.clip(hi / max(ctx.cell, 1e-6), 16, MAX_BINS))
        # Points on the inside of the tube lie nearer the axis than its centre circle: where
        # their normal lines meet past them, the major radius reaches there, in bins as wide
        # (exact samples: noisy normals meet at random, see houghcad.noise).
        if ctx.policy.torus_grid_from_points:
            return Grid((0.0, 0.0), (hi, hi), (nb, nb))
        rad = Pl[:, :2] / np.maximum(rho, 1e-12)[:, None]
        centre = meridian_centre(rho, Pl[:, 2], np.einsum("ij,ij->i", Nl[:, :2], rad), Nl[:, 2], MERIDIAN_SPREAD)
        if centre is not None and centre[0] + ctx.tau > hi:
            w = hi / nb
            hi = min(centre[0] + float(np.ptp(rho)) + ctx.tau, ctx.max_radius)
            nb = int(np.clip(np.ceil(hi / w), 16, 2 * MAX_BINS))
        return Grid((0.0, 0.0), (hi, hi), (nb, nb))

    def gamma(self, Pl, Nl, grid, ctx):
        # Sweep the major radius over its bins and solve for the minor one.
        R = grid.centers(0)
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        r = np.hypot(rho[:, None] - R[None, :], Pl[:, 2, None])
        voter = np.repeat(np.arange(len(Pl)), len(R))
        return voter, np.stack([np.broadcast_to(R, r.shape).ravel(), r.ravel()], axis=1)

    def votes(self, Pl, Nl, grid, ctx):
        return swept_votes(_sweep_votes, Pl, grid)  # the sweep of gamma, voted as it goes

    def primitive(self, values, placement):
        return Primitive("torus", {"center": placement.origin.copy(), "axis": placement.R[2].copy(),
                                   "major_radius": float(values[0]), "minor_radius": float(values[1])})

    def distance(self, prim, P):
        h, rho = axial(P, prim.params["center"], prim.params["axis"])
        return np.abs(np.hypot(rho - prim.params["major_radius"], h) - prim.params["minor_radius"])

    def surface_normals(self, prim, P):
        h, rho, rad = radial(P, prim.params["center"], prim.params["axis"])
        return unit(rad * (rho - prim.params["major_radius"])[:, None] + h[:, None] * prim.params["axis"][None, :])

    def valid(self, prim, ctx):
        p = prim.params
        # A tube thinner than the inlier band envelops a noisy curve's points.
        return 0.5 * ctx.tau <= p["minor_radius"] < ctx.max_radius and 0 <= p["major_radius"] < ctx.max_radius

    def fit(self, prim, P, N):
        c0, a0 = np.asarray(prim.params["center"], np.float64), unit(prim.params["axis"])
        e1, e2 = tangent_basis(a0)
        P = np.ascontiguousarray(P, dtype=np.float64)

        def unpack(x):
            return c0 + x[:3], unit(a0 + x[3] * e1 + x[4] * e2), x[5], x[6]

        x0 = np.r_[0, 0, 0, 0, 0, prim.params["major_radius"], prim.params["minor_radius"]]
        try:
            x = _lm.solve(_refit_rows, x0, (P, c0, a0, e1, e2), max_nfev=50).x
        except ValueError:  # fewer points than parameters, or not finite
            return None
        c, a, R, r = unpack(x)
        return Primitive("torus", {"center": c, "axis": a, "major_radius": float(abs(R)),
                                   "minor_radius": float(abs(r))})

    def to_world(self, prim, T):
        return {"center": T.inv_points(prim.params["center"]).tolist(),
                "axis": unit(T.inv_dirs(prim.params["axis"])).tolist(),
                "major_radius": T.inv_length(prim.params["major_radius"]),
                "minor_radius": T.inv_length(prim.params["minor_radius"])}

    length_descriptors = ("major_radius", "minor_radius")

    def descriptors(self, prim):
        return {"major_radius": float(prim.params["major_radius"]),
                "minor_radius": float(prim.params["minor_radius"])}

    def frame(self, prim):
        return Frame("point", np.asarray(prim.params["center"], float), unit(prim.params["axis"]))


# The refit's residuals and analytic Jacobian in numba, as the cone's (cone._refit_rows): the
# Levenberg–Marquardt (:mod:`._lm`) asks for them up to 50 times a refit, and numpy's per-call
# overhead on a few hundred points was most of the refit's time.
@kernel("f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], b1")
def _refit_rows(P, c0, a0, e1, e2, x, jacobian):
    """Residuals r = D − x6 (n,) of the points P (n, 3) about the torus with centre c0 + x[:3],
    axis unit(a0 + x3 e1 + x4 e2), major radius x5 and minor radius x6, where D = hypot(ρ − R, h)
    is the distance to the tube's centre circle; and, when ``jacobian``, their derivatives J (n, 7)
    (else an empty (0, 7)), with dD/dρ = (ρ − R) / D and dD/dh = h / D."""
    a, U = turned_axis(a0, e1, e2, x[3], x[4])
    c = c0 + x[:3]
    R, rr = x[5], x[6]
    n = P.shape[0]
    r = np.empty(n)
    J = np.empty((n if jacobian else 0, 7))
    for i in range(n):
        v0, v1, v2, h, w0, w1, w2, rho = axial_row(P, i, c, a)
        D0 = np.hypot(rho - R, h)
        r[i] = D0 - rr
        if jacobian:
            s = rho if rho > 1e-15 else 1.0
            D = max(D0, 1e-15)
            dr, dh = (rho - R) / D, h / D
            # d/d centre: dh = −a, dρ = −e (e the radial unit vector)
            J[i, 0] = -dr * w0 / s - dh * a[0]
            J[i, 1] = -dr * w1 / s - dh * a[1]
            J[i, 2] = -dr * w2 / s - dh * a[2]
            # d/d axis: dh/da = v, dρ/da = −h v / ρ, so dD/da = v (h / D) R / ρ
            f = dh * R / max(rho, 1e-15)
            J[i, 3] = f * (v0 * U[0, 0] + v1 * U[1, 0] + v2 * U[2, 0])
            J[i, 4] = f * (v0 * U[0, 1] + v1 * U[1, 1] + v2 * U[2, 1])
            J[i, 5] = -dr
            J[i, 6] = -1.0
    return r, J


# By hand in numba: gamma's (n, bins) samples are held whole and then voted.
@kernel("f8[::1], f8[::1], f8[::1], f8, f8, f8[:, ::1]")
def _sweep_votes(z: np.ndarray, rho: np.ndarray, R: np.ndarray, lo: float, w: float, H: np.ndarray) -> None:
    """Add to H (len(R), k) a vote per point (z, rho (n,)) and major radius R[j], in the minor
    radius bin of hypot(rho − R[j], z) (bins from ``lo``, ``w`` wide)."""
    k = H.shape[1]
    for i in range(z.size):
        for j in range(R.size):
            x = np.floor((np.hypot(rho[i] - R[j], z[i]) - lo) / w)
            if 0 <= x < k:
                H[j, int(x)] += 1.0
