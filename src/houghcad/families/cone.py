"""Circular cones. Standard form x² + y² = a (z − b)² with a = tan² α: two
unknowns (b, α) once the axis is along z."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..hough import Grid
from ..preprocess import rotation_to_z
from .base import (Frame, Family, Placement, Primitive, axis_from_normal_lines, planes_intersection, axial, radial,
                   axial_row, register, swept_votes, tangent_basis, turned_axis, unit)
from . import _lm
from ._sampling import ORIGIN, TAU, Z_AXIS, Array, Sampler, span
from ..kernels import kernel


def cone_frame(P, N):
    """Apex (least-squares point of the tangent planes) and axis (the rays from
    the apex make a constant angle with it)."""
    apex, cond = planes_intersection(P, N)
    if cond < 1e-6:
        return None
    u = unit(P - apex)
    m = u.mean(axis=0)
    w, v = np.linalg.eigh(np.cov(u.T))
    a = v[:, 0]
    if a @ m < 0:
        a = -a
    return apex, a


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_cone(
    rng: np.random.Generator,
    n: int,
    half_angle: float,
    z_range: tuple[float, float],
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the cone x² + y² = (z tan α)², apex at the origin, opening towards +z.

    ``z_range = (z0, z1)`` (0 ≤ z0 < z1, units) bounds the patch along the axis, measured from
    the apex. The area element is proportional to z, so z is drawn by inverse CDF
    (z² uniform). Returns points (n, 3) and outward unit normals (n, 3)
    ``(cos α cos θ, cos α sin θ, −sin α)``.
    """
    z0, z1 = span(z_range)
    if z0 < 0:
        raise ValueError("cone z_range must be on the opening side of the apex (z ≥ 0)")
    a0, a1 = span(arc)
    z = np.sqrt(z0 * z0 + rng.random(n) * (z1 * z1 - z0 * z0))
    th = a0 + (a1 - a0) * rng.random(n)
    c, s = np.cos(th), np.sin(th)
    r = z * np.tan(half_angle)
    pts = np.column_stack([r * c, r * s, z])
    ca, sa = np.cos(half_angle), np.sin(half_angle)
    nrm = np.column_stack([ca * c, ca * s, np.full(n, -sa)])
    return pts, nrm


def _cone_area(half_angle: float, z_range: tuple[float, float], arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float((arc[1] - arc[0]) * np.tan(half_angle) / np.cos(half_angle) * (z_range[1] ** 2 - z_range[0] ** 2) / 2)


def _cone_local(half_angle: float, **_: Any) -> dict[str, Any]:
    return {"apex": list(ORIGIN), "axis": list(Z_AXIS), "half_angle": float(half_angle)}


def _cone_random(rng: np.random.Generator) -> dict[str, Any]:
    alpha = float(np.deg2rad(rng.uniform(15.0, 60.0)))
    z1 = float(rng.uniform(0.6, 1.2)) / np.tan(alpha)  # radius 0.6-1.2 at the wide end
    return {"half_angle": alpha, "z_range": (z1 * float(rng.uniform(0.1, 0.5)), z1)}


@register
class Cone(Family):
    name = "cone"
    param_names = ("apex", "axis", "half_angle")
    n_unknowns = 2
    role = "simple"
    precedence = 3
    search = "cluster"
    pointwise = True
    order = 40
    color = (35, 70, 230)  # blue
    type_code = 3
    sampler = Sampler(sample_cone, _cone_area, _cone_local, _cone_random,
                      {"apex": "point", "axis": "direction", "half_angle": "invariant"})

    def placements(self, P, N, ctx):
        out = []
        fr = cone_frame(P, N)
        if fr is not None:
            out.append(Placement(rotation_to_z(fr[1]), fr[0]))
        q, a, _, _ = axis_from_normal_lines(P, N)
        h = (P - q) @ a
        if np.mean(h) < 0:
            a = -a
        out.append(Placement(rotation_to_z(a), q + a * ((P - q) @ a).min()))
        return out

    def region(self, Pl, Nl, ctx):
        z = Pl[:, 2]
        ext = float(np.ptp(Pl, axis=0).max())
        lo, hi = min(z.min(), 0.0) - ext, max(z.min(), 0.0) + 0.25 * ext
        nb = int(np.clip((hi - lo) / max(ctx.cell, 1e-6), 16, 256))
        return Grid((lo, np.radians(1.0)), (hi, np.radians(89.0)), (nb, 176))

    def gamma(self, Pl, Nl, grid, ctx):
        # Sweep the apex height b over its bins and solve for the half-angle.
        b = grid.centers(0)
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        dz = Pl[:, 2, None] - b[None, :]
        alpha = np.arctan2(rho[:, None], dz)
        ok = dz > 0
        voter = np.broadcast_to(np.arange(len(Pl))[:, None], dz.shape)[ok]
        vals = np.stack([np.broadcast_to(b, dz.shape)[ok], alpha[ok]], axis=1)
        return voter, vals

    def votes(self, Pl, Nl, grid, ctx):
        return swept_votes(_sweep_votes, Pl, grid)  # the sweep of gamma, voted as it goes

    def primitive(self, values, placement):
        b, alpha = float(values[0]), float(values[1])
        a = placement.R[2]
        return Primitive("cone", {"apex": placement.origin + b * a, "axis": a.copy(), "half_angle": alpha})

    def _meridian(self, prim, P):
        h, rho, rad = radial(P, prim.params["apex"], prim.params["axis"])
        return h, rho, rad

    def distance(self, prim, P):
        al = prim.params["half_angle"]
        h, rho, _ = self._meridian(prim, P)
        t = rho * np.sin(al) + h * np.cos(al)
        d = np.abs(rho * np.cos(al) - h * np.sin(al))
        return np.where(t >= 0, d, np.hypot(rho, h))

    def surface_normals(self, prim, P):
        al = prim.params["half_angle"]
        _, _, rad = self._meridian(prim, P)
        return unit(rad * np.cos(al) - np.sin(al) * prim.params["axis"][None, :])

    def valid(self, prim, ctx):
        return np.radians(2.0) < prim.params["half_angle"] < np.radians(88.0)

    def fit(self, prim, P, N):
        p0, a0, al0 = prim.params["apex"], unit(prim.params["axis"]), prim.params["half_angle"]
        e1, e2 = tangent_basis(a0)
        P = np.ascontiguousarray(P, dtype=np.float64)
        p0 = np.asarray(p0, np.float64)

        def unpack(x):
            return p0 + x[:3], unit(a0 + x[3] * e1 + x[4] * e2), x[5]

        try:
            x = _lm.solve(_refit_rows, np.r_[0, 0, 0, 0, 0, al0], (P, p0, a0, e1, e2), max_nfev=40).x
        except ValueError:  # fewer points than parameters, or not finite
            return None
        p, a, al = unpack(x)
        if not (0 < al < np.pi / 2):
            return None
        if axial(P, p, a)[0].mean() < 0:
            a = -a
        return Primitive("cone", {"apex": p, "axis": a, "half_angle": float(al)})

    def to_world(self, prim, T):
        return {"apex": T.inv_points(prim.params["apex"]).tolist(),
                "axis": unit(T.inv_dirs(prim.params["axis"])).tolist(),
                "half_angle": float(prim.params["half_angle"])}

    def descriptors(self, prim):
        return {"half_angle": float(prim.params["half_angle"])}

    def frame(self, prim):
        return Frame("point", np.asarray(prim.params["apex"], float), unit(prim.params["axis"]), oriented=True)


# The refit's residuals and analytic Jacobian in numba: the Levenberg–Marquardt (:mod:`._lm`)
# asks for them 10–40 times a refit, in every cluster's vote, and numpy's per-call overhead on a
# few hundred points was most of the refit's time. Finite differences would cost six residuals more a step.
@kernel("f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], b1")
def _refit_rows(P, p0, a0, e1, e2, x, jacobian):
    """Residuals r = ρ cos α − h sin α (n,) of the points P (n, 3) about the cone with apex
    p0 + x[:3], axis unit(a0 + x3 e1 + x4 e2) and half-angle x5, and, when ``jacobian``, their
    derivatives J (n, 6) (else an empty (0, 6)): d/d apex = −cos α e + sin α a (dh = −a,
    dρ = −e, e the radial unit vector); d/d axis through dh/da = v, dρ/da = −h v / ρ."""
    a, U = turned_axis(a0, e1, e2, x[3], x[4])
    p = p0 + x[:3]
    ca, sa = np.cos(x[5]), np.sin(x[5])
    n = P.shape[0]
    r = np.empty(n)
    J = np.empty((n if jacobian else 0, 6))
    for i in range(n):
        v0, v1, v2, h, w0, w1, w2, rho = axial_row(P, i, p, a)
        r[i] = rho * ca - h * sa
        if jacobian:
            s = rho if rho > 1e-15 else 1.0
            J[i, 0] = -ca * w0 / s + sa * a[0]
            J[i, 1] = -ca * w1 / s + sa * a[1]
            J[i, 2] = -ca * w2 / s + sa * a[2]
            f = -(h * ca / max(rho, 1e-15) + sa)
            J[i, 3] = f * (v0 * U[0, 0] + v1 * U[1, 0] + v2 * U[2, 0])
            J[i, 4] = f * (v0 * U[0, 1] + v1 * U[1, 1] + v2 * U[2, 1])
            J[i, 5] = -rho * sa - h * ca
    return r, J


# By hand in numba: gamma's (n, bins) samples are 200 MB per 100k points, and voting them
# afterwards reads them again.
@kernel("f8[::1], f8[::1], f8[::1], f8, f8, f8[:, ::1]")
def _sweep_votes(z: np.ndarray, rho: np.ndarray, b: np.ndarray, lo: float, w: float, H: np.ndarray) -> None:
    """Add to H (len(b), k) a vote per point (z, rho (n,)) and apex height b[j] below it, in the
    half-angle bin of atan2(rho, z − b[j]) (bins from ``lo``, ``w`` wide; ``b`` ascending).

    No arctangent per sample: the angle is in bin x or above when rho ≥ (z − b) tan(lo + x w),
    and it grows as the apex rises towards the point, so each point walks the bin edges once."""
    k = H.shape[1]
    T = np.empty(k + 1)
    for x in range(k + 1):
        t = lo + x * w
        T[x] = -np.inf if t <= -np.pi / 2 else (np.inf if t >= np.pi / 2 else np.tan(t))
    for i in range(z.size):
        x = -1  # the bin of the angle: -1 below lo, k at or above the last edge
        r = rho[i]
        for j in range(b.size):
            dz = z[i] - b[j]
            if dz <= 0:
                break
            while x < k and r >= dz * T[x + 1]:
                x += 1
            if 0 <= x < k:
                H[j, x] += 1.0
