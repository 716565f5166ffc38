"""Circular cylinders. Standard form x² + y² = r² (one unknown) once the axis
is along z through the origin."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..context import neighbour_table
from ..hough import Grid, direction_accumulator, normal_line_peaks, refine_direction
from ..preprocess import rotation_to_z
from .base import Frame, Family, Placement, Primitive, axial, damped_step, radial, register, tangent_basis, unit
from ._sampling import ORIGIN, TAU, Z_AXIS, Array, Sampler, partial, span
from ..kernels import kernel


def axis_candidates(P, N, ctx, max_dirs):
    """Axis directions: persistent peaks of the votes n_i × n_j of neighbour
    pairs (a cylinder's normals are all orthogonal to its axis)."""
    out = []
    if ctx.local:
        # A cluster's own estimate: the direction least represented among the normals.
        out.append(np.linalg.eigh(N.T @ N)[1][:, 0])
    nb = neighbour_table(ctx)
    if nb is None or len(nb) != len(P) or nb.shape[1] < 4:
        return out
    k = nb.shape[1]
    c = np.cross(N[:, None, :], N[nb[:, [k // 2, k - 1]]]).reshape(-1, 3)
    ln = np.linalg.norm(c, axis=1)
    ok = ln > np.sin(np.radians(1.5))
    if ok.sum() < ctx.min_points:
        return out
    c = c[ok] / ln[ok, None]
    acc = direction_accumulator()
    H = acc.smooth(acc.vote(c))
    dirs, _ = acc.peaks(H, ctx.persistence, max_peaks=max_dirs)
    return out + [refine_direction(d, c, np.radians(6.0)) for d in dirs]


@kernel()
def _normal_equations(P, a0, p0, e1, e2, x):
    """Cost Σ r², JᵀJ (5, 5) and Jᵀr (5,) of the cylinder residuals r = ρ − x[4] at the
    parameters x: the axis unit(a0 + x0 e1 + x1 e2) through p0 + x2 e1 + x3 e2, radius x4."""
    a = a0 + x[0] * e1 + x[1] * e2
    na = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if na > 0:
        a = a / na
    c = p0 + x[2] * e1 + x[3] * e2
    A = np.zeros((5, 5))
    g = np.zeros(5)
    J = np.empty(5)
    cost = 0.0
    for i in range(P.shape[0]):
        v0, v1, v2 = P[i, 0] - c[0], P[i, 1] - c[1], P[i, 2] - c[2]
        h = v0 * a[0] + v1 * a[1] + v2 * a[2]
        w0, w1, w2 = v0 - h * a[0], v1 - h * a[1], v2 - h * a[2]
        rho = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        s = max(rho, 1e-15)
        ue1 = (w0 * e1[0] + w1 * e1[1] + w2 * e1[2]) / s
        ue2 = (w0 * e2[0] + w1 * e2[1] + w2 * e2[2]) / s
        J[0], J[1], J[2], J[3], J[4] = -h * ue1, -h * ue2, -ue1, -ue2, -1.0
        r = rho - x[4]
        cost += r * r
        for j in range(5):
            g[j] += J[j] * r
            for k in range(5):
                A[j, k] += J[j] * J[k]
    return cost, A, g


# The cylinder's refit by hand in numba: it runs on every candidate's inliers, thousands of times
# a cloud, and numpy's per-call overhead on a few hundred points was most of its time. The same
# damped Gauss–Newton as families.base.gauss_newton (8 iterations, the same damping and stops).
@kernel("f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8")
def _gauss_newton_fit(P, a0, p0, e1, e2, r0):
    """The parameters x (5,) of :func:`_normal_equations` that fit the points P (n, 3), from
    (0, 0, 0, 0, r0); None when a step's system is singular or its cost not finite."""
    x = np.array([0.0, 0.0, 0.0, 0.0, r0])
    cost, A, g = _normal_equations(P, a0, p0, e1, e2, x)
    lam = 1e-6
    for _ in range(8):
        step, ok = damped_step(A, g, lam, np.diag(A) + 1e-15)
        if not ok:
            return None
        xn = x + step
        cn, An, gn = _normal_equations(P, a0, p0, e1, e2, xn)
        if not np.isfinite(cn):
            return None
        if cn <= cost:
            x, A, g, cost = xn, An, gn, cn
            lam = max(lam / 10, 1e-12)
            if np.abs(step).max() < 1e-12:
                break
        else:
            lam *= 10
    return x


def circle_centers(Q, M, ctx, max_centers):
    """Circle centres of 2-D points Q (n, 2) with unit normals M (n, 2): each
    point votes along its normal line (the 2-D circle vote)."""
    lo = Q.min(axis=0)
    ext = float((Q.max(axis=0) - lo).max())
    if ext <= 0:
        return np.zeros((0, 2))
    nb = int(np.clip(ext / max(2 * ctx.cell, ctx.spacing), 16, 160))
    return normal_line_peaks(Q, M, lo, ext, nb, 0.5 * ext * 1.05, ctx.persistence, ctx.min_votes, max_centers)


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_cylinder(
    rng: np.random.Generator,
    n: int,
    radius: float,
    height: float,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on x² + y² = radius², -height/2 ≤ z ≤ height/2, azimuth in ``arc`` (rad).

    Returns points (n, 3) and outward unit normals (n, 3).
    """
    a0, a1 = span(arc)
    th = a0 + (a1 - a0) * rng.random(n)
    z = (rng.random(n) - 0.5) * float(height)
    c, s = np.cos(th), np.sin(th)
    pts = np.column_stack([radius * c, radius * s, z])
    nrm = np.column_stack([c, s, np.zeros(n)])
    return pts, nrm


def _cylinder_area(radius: float, height: float, arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float(radius * (arc[1] - arc[0]) * height)


def _cylinder_local(radius: float, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(ORIGIN), "axis": list(Z_AXIS), "radius": float(radius)}


def _cylinder_random(rng: np.random.Generator) -> dict[str, Any]:
    r = float(rng.uniform(0.4, 1.0))
    return {"radius": r, "height": r * float(rng.uniform(1.0, 3.0)), "arc": partial(rng, 0.6, np.pi / 2, 1.6 * np.pi)}


@register
class Cylinder(Family):
    name = "cylinder"
    param_names = ("axis_point", "axis", "radius")
    n_unknowns = 1
    role = "simple"
    precedence = 1
    search = "whole"
    pointwise = True
    order = 20
    color = (30, 160, 45)  # green
    type_code = 2
    sampler = Sampler(sample_cylinder, _cylinder_area, _cylinder_local, _cylinder_random,
                      {"axis_point": "point", "axis": "direction", "radius": "length"})

    def placements(self, P, N, ctx):
        out = []
        for a in axis_candidates(P, N, ctx, ctx.max_directions):
            R = rotation_to_z(a)
            ok = np.abs(N @ a) <= np.sin(ctx.angle)
            if ok.sum() < ctx.min_points:
                continue
            Q = (P[ok] @ R.T)[:, :2]
            M = (N[ok] @ R.T)[:, :2]
            M = M / np.maximum(np.linalg.norm(M, axis=1, keepdims=True), 1e-12)
            cents = circle_centers(Q, M, ctx, ctx.max_peaks)
            if ctx.local and len(Q) >= 3:
                # Algebraic (Kåsa) circle fit as the cluster's own estimate.
                A = np.c_[2 * Q, np.ones(len(Q))]
                sol = np.linalg.lstsq(A, (Q**2).sum(1), rcond=None)[0]
                cents = np.vstack([sol[:2][None], cents])
            for c in cents:
                out.append(Placement(R, R.T @ np.array([c[0], c[1], 0.0])))
        return out

    def region(self, Pl, Nl, ctx):
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        hi = min(float(rho.max()) + ctx.tau, ctx.max_radius)
        w = max(ctx.cell, 1e-6)
        return Grid((0.0,), (hi,), (int(np.clip(np.ceil(hi / w), 1, 4096)),))

    def gamma(self, Pl, Nl, grid, ctx):
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        radial_n = np.abs(Nl[:, 0] * Pl[:, 0] + Nl[:, 1] * Pl[:, 1]) / np.maximum(rho, 1e-12)
        idx = np.flatnonzero((radial_n >= ctx.cos_angle) & (np.abs(Nl[:, 2]) <= np.sin(ctx.angle)))
        return idx, rho[idx, None]

    def primitive(self, values, placement):
        return Primitive("cylinder", {"axis_point": placement.origin.copy(), "axis": placement.R[2].copy(),
                                      "radius": float(values[0])})

    def distance(self, prim, P):
        _, rho = axial(P, prim.params["axis_point"], prim.params["axis"])
        return np.abs(rho - prim.params["radius"])

    def surface_normals(self, prim, P):
        return radial(P, prim.params["axis_point"], prim.params["axis"])[2]

    def valid(self, prim, ctx):
        return 0 < prim.params["radius"] < ctx.max_radius

    def well_determined(self, prim, P, ctx):
        # A short band of a partial cylinder is also a slice of a torus, a
        # cone or a sphere: leave it to the per-cluster rounds.
        h, _, rad = radial(P, prim.params["axis_point"], prim.params["axis"])
        if np.ptp(h) >= 4 * ctx.link:
            return True
        e1, e2 = tangent_basis(prim.params["axis"])
        ang = np.arctan2(rad @ e2, rad @ e1)
        covered = np.unique(np.floor((ang + np.pi) / (2 * np.pi) * 36).astype(int)).size
        return covered >= 27

    def fit(self, prim, P, N):
        a0 = unit(prim.params["axis"])
        p0 = prim.params["axis_point"]
        e1, e2 = tangent_basis(a0)

        P = np.ascontiguousarray(P, dtype=np.float64)
        x = _gauss_newton_fit(P, a0, np.asarray(p0, np.float64), e1, e2, float(prim.params["radius"]))
        if x is None:
            return None
        a = unit(a0 + x[0] * e1 + x[1] * e2)
        p = p0 + x[2] * e1 + x[3] * e2
        # Keep the axis point as the foot of the points' centroid (a stable choice).
        h = (P.mean(axis=0) - p) @ a
        return Primitive("cylinder", {"axis_point": p + h * a, "axis": a, "radius": float(abs(x[4]))})

    def to_world(self, prim, T):
        return {"axis_point": T.inv_points(prim.params["axis_point"]).tolist(),
                "axis": unit(T.inv_dirs(prim.params["axis"])).tolist(),
                "radius": T.inv_length(prim.params["radius"])}

    length_descriptors = ("radius",)

    def descriptors(self, prim):
        return {"radius": float(prim.params["radius"])}

    def frame(self, prim):
        return Frame("line", np.asarray(prim.params["axis_point"], float), unit(prim.params["axis"]))
