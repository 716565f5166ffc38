"""Generalised cones over an n-convexity directrix (paper Table 2(b)).

The paper's x = a v cos u / (1 + b cos nu), y = a v sin u / (1 + b cos nu),
z = A v + B has a scale redundancy (a, v, A); it is fixed here by A = 1 and
B = 0 with z measured from the apex along the axis, so that a is the
dimensionless ``slope``: the cross-section at height z is the directrix
ρ(θ) = slope · z / (1 + b cos n(θ − φ)).

Standard form: apex at the origin (least-squares point of the tangent planes,
which all pass through it), axis z. The central projection (x/z, y/z) of the
points is the directrix of size ``slope``; its centre there is the axis'
offset (iterated), the linear polar fit of :mod:`.generalized_cylinder` gives
the order n (swept 2 … 12) and the phase φ, and (b, slope) are voted.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..preprocess import rotation_to_z
from .base import Frame, Family, Primitive, frame_turn_rows, planes_intersection, register, unit
from ._sampling import ORIGIN, TAU, Z_AXIS, Array, Sampler, directrix_random, directrix_speed, draw_by_weight, span
from .generalized_cylinder import (B_MAX, B_MIN, N_VALUES, DirectrixPlacement, active_order, best_order, debias_b,
                                   normalise_shape, phase_frame, polar_fit, polar_local,
                                   polar_rows, ref_basis, vote_grid)
from . import _lm


def projected(Pl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central projection (x/z, y/z) (m, 2) of the local points with z > 0, and their mask (n,)."""
    z = Pl[:, 2]
    ok = z > 1e-9 * (np.abs(Pl).max() + 1e-12)
    return Pl[ok, :2] / z[ok, None], ok


def typical_height(Pl: np.ndarray) -> float:
    """Median height above the apex (standard units) of the local points in
    front of it (1 when there are none)."""
    ok = projected(Pl)[1]
    return float(np.median(Pl[ok, 2])) if ok.any() else 1.0


#: Angle (degrees) within which a point's tangent plane passes through an apex (consensus).
APEX_ANGLE = 5.0


def apex_support(x: np.ndarray, P: np.ndarray, N: np.ndarray) -> np.ndarray:
    """Mask (n,) of the points (P, N (n, 3)) whose tangent planes pass through
    the apex x (3,), within ``APEX_ANGLE`` of the ray to it; for apexes x
    (t, 3), one row per apex (t, n)."""
    U = unit(np.asarray(x, float)[..., None, :] - P)
    return np.abs(np.einsum("...ij,ij->...i", U, N)) < np.sin(np.radians(APEX_ANGLE))


def consensus_apexes(P: np.ndarray, N: np.ndarray, rng: np.random.Generator, count: int = 2, trials: int = 300,
                     max_points: int = 1000, min_points: int = 10) -> list[np.ndarray]:
    """Point sets (masks (n,)) whose tangent planes pass through one apex,
    the best supported first, at most ``count``.

    The least-squares point of all tangent planes is pulled off by every
    other surface in the set (a generalised cylinder on the same directrix
    beside the cone). The apex of three tangent planes that the most others
    pass through (:func:`apex_support`) is not: RANSAC over angles, not
    distances, since a normal's error moves its plane in proportion to the
    distance from the apex. Each further apex is sought among the points the
    previous ones left.
    """
    left = np.ones(len(P), bool)
    out = []
    for _ in range(count):
        idx = np.flatnonzero(left)
        if len(idx) < max(min_points, 10):
            break
        sub = idx[np.sort(rng.choice(len(idx), min(len(idx), max_points), replace=False))]
        Ps, Ns = P[sub], N[sub]
        t = rng.integers(0, len(sub), size=(trials, 3))
        A = Ns[t]
        good = np.abs(np.linalg.det(A)) > 0.05
        if not good.any():
            break
        A, t = A[good], t[good]
        X = np.linalg.solve(A, np.einsum("tij,tij->ti", A, Ps[t])[..., None])[..., 0]
        # (trials, points) at once: 300 x 1000 rays.
        score = apex_support(X, Ps, Ns).sum(axis=1)
        ok = left & apex_support(X[int(np.argmax(score))], P, N)
        if ok.sum() < max(min_points, 10):
            break
        out.append(ok)
        left &= ~ok
    return out


def cone_directrix_frame(P: np.ndarray, N: np.ndarray, iters: int = 4):
    """Apex (3,), frame R (3, 3) (rows: ref_dir, ·, axis) and order n of a generalised cone, or None."""
    apex, cond = planes_intersection(P, N)
    if cond < 1e-6:
        return None
    u = unit(P - apex)
    axis = np.linalg.eigh(np.cov(u.T))[1][:, 0]
    if axis @ u.mean(axis=0) < 0:
        axis = -axis
    n = None
    for _ in range(iters):
        R = rotation_to_z(axis)
        W, _ = projected((P - apex) @ R.T)
        fit = best_order(W, np.zeros(2))
        if fit is None:
            return None
        n, c = fit[0], fit[1]
        axis = unit(R.T @ np.array([c[0], c[1], 1.0]))
        if np.linalg.norm(c) < 1e-6:
            break
    R = rotation_to_z(axis)
    W, _ = projected((P - apex) @ R.T)
    if len(W) < 10:
        return None
    th, rho = np.arctan2(W[:, 1], W[:, 0]), np.hypot(W[:, 0], W[:, 1])
    p, _ = polar_fit(th, rho, n)
    if abs(p[0]) < 1e-12 or np.hypot(p[1], p[2]) / abs(p[0]) < 0.5 * B_MIN:
        # A circular cone (or no directrix): valid() would reject every peak.
        return None
    phi = float(np.arctan2(p[2], p[1]) / n)
    return apex, phase_frame(R, phi), int(n)


def _same_frame(fr, pl: DirectrixPlacement, tol: float = 1e-3) -> bool:
    return (fr[2] == pl.info["n"] and np.linalg.norm(fr[0] - pl.origin) < tol
            and fr[1][2] @ pl.R[2] > np.cos(np.radians(1.0)))


def _rulings(u: np.ndarray, s: float, b: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Ruling directions D(u) = (ρ_s cos u, ρ_s sin u, 1) and D'(u), each (m, 3) (local frame)."""
    c, si = np.cos(u), np.sin(u)
    g = 1.0 + b * np.cos(n * u)
    r = s / g
    r1 = s * b * n * np.sin(n * u) / g**2
    D = np.stack([r * c, r * si, np.ones_like(u)], axis=1)
    D1 = np.stack([r1 * c - r * si, r1 * si + r * c, np.zeros_like(u)], axis=1)
    return D, D1


def ruling_foot(q: np.ndarray, s: float, b: float, n: int, iters: int = 5) -> np.ndarray:
    """Parameter u (m,) of the ruling closest in angle to local points q (m, 3).

    The distance to a half-line through the apex is |q| sin(angle), so the
    nearest ruling is the one of smallest angle: nearest of a dense sample of
    unit ruling directions (cKDTree), then vectorised Newton steps on
    q̂·D̂(u) (second derivative by central differences of the first).
    """
    m = int(max(720, 96 * n))
    us = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    D, _ = _rulings(us, s, b, n)
    qh = unit(q)
    u = us[cKDTree(unit(D)).query(qh)[1]]
    h = 2 * np.pi / m

    def slope1(v):
        D, D1 = _rulings(v, s, b, n)
        nd = np.linalg.norm(D, axis=1)
        qd = np.einsum("ij,ij->i", qh, D)
        return np.einsum("ij,ij->i", qh, D1) / nd - qd * np.einsum("ij,ij->i", D, D1) / nd**3

    for _ in range(iters):
        f1 = slope1(u)
        f2 = (slope1(u + 1e-5) - slope1(u - 1e-5)) / 2e-5
        step = np.where(f2 < -1e-12, -f1 / np.where(f2 < -1e-12, f2, -1.0), np.sign(f1) * h)
        u = u + np.clip(step, -h, h)
    return u


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_generalized_cone(
    rng: np.random.Generator, n: int, slope: float, b: float, order: int, z_range: tuple[float, float],
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the generalised cone z (ρ_s(u) cos u, ρ_s(u) sin u, 1), ρ_s = slope / (1 + b cos(order·u)):
    apex at the origin, opening towards +z, z in ``z_range`` (0 ≤ z0 < z1), u in ``arc``.

    This is the paper's x = a v cos u / (1 + b cos nu), y = a v sin u / (1 + b cos nu), z = A v + B
    with A = 1, B = 0 (v = z, a = ``slope``). With D(u) = (ρ_s e(u), 1) the area element is
    z |D(u) × D'(u)| du dz: separable, z drawn with density ∝ z, u with density ∝ |D × D'|.
    Returns points (n, 3) and outward unit normals (n, 3) (∝ D' × D).
    """
    z0, z1 = span(z_range)
    if z0 < 0:
        raise ValueError("generalised cone z_range must be on the opening side of the apex (z ≥ 0)")
    a0, a1 = span(arc)
    u = draw_by_weight(rng, n, lambda t: np.linalg.norm(_gcone_cross(t, slope, b, order), axis=1), a0, a1)
    z = np.sqrt(z0 * z0 + rng.random(n) * (z1 * z1 - z0 * z0))
    r = directrix_speed(u, slope, b, order)[0]
    pts = np.column_stack([z * r * np.cos(u), z * r * np.sin(u), z])
    nrm = _gcone_cross(u, slope, b, order)
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _gcone_cross(u: Array, slope: float, b: float, order: int) -> Array:
    """D'(u) × D(u), (m, 3): an outward normal of the generalised cone along the ruling D(u)."""
    r, r1, _ = directrix_speed(u, slope, b, order)
    c, s = np.cos(u), np.sin(u)
    D = np.column_stack([r * c, r * s, np.ones_like(u)])
    D1 = np.column_stack([r1 * c - r * s, r1 * s + r * c, np.zeros_like(u)])
    return np.cross(D1, D)


def _gcone_area(slope: float, b: float, order: int, z_range: tuple[float, float],
                arc: tuple[float, float] = (0.0, TAU), m: int = 8192) -> float:
    u = np.linspace(arc[0], arc[1], m + 1)
    w = np.linalg.norm(_gcone_cross(u, slope, b, order), axis=1)
    return float(np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(u)) * (z_range[1] ** 2 - z_range[0] ** 2) / 2)


def _gcone_local(slope: float, b: float, order: int, **_: Any) -> dict[str, Any]:
    return {"apex": list(ORIGIN), "axis": list(Z_AXIS), "ref_direction": [1.0, 0.0, 0.0], "a": float(slope),
            "b": float(b), "n": int(order), "A": 1.0, "B": 0.0}


def _gcone_random(rng: np.random.Generator) -> dict[str, Any]:
    order, b = directrix_random(rng)
    slope = float(np.tan(np.deg2rad(rng.uniform(20.0, 45.0))))
    z1 = float(rng.uniform(0.6, 1.2)) / slope  # mean radius 0.6-1.2 at the wide end
    return {"slope": slope, "b": b, "order": order, "z_range": (z1 * float(rng.uniform(0.2, 0.5)), z1)}


@register
class GeneralizedCone(Family):
    name = "generalized_cone"
    param_names = ("apex", "axis", "ref_direction", "a", "b", "n", "A", "B")
    n_unknowns = 2
    role = "complex"
    precedence = 7
    search = "whole"
    order = 70
    color = (128, 128, 0)  # olive
    type_code = 8
    sampler = Sampler(sample_generalized_cone, _gcone_area, _gcone_local, _gcone_random,
                      {"apex": "point", "axis": "direction", "ref_direction": "direction",
                       # the paper's a with A = 1: ρ/z, no unit
                       "a": "invariant", "b": "invariant", "n": "invariant",
                       "A": "invariant", "B": "length"})

    # --- standard form -------------------------------------------------------------------
    def placements(self, P, N, ctx):
        out = []
        fr = cone_directrix_frame(P, N)
        if fr is not None:
            out.append(DirectrixPlacement(fr[1], fr[0], {"n": fr[2]}))
        if not ctx.local:
            # On a whole part the best supported apex is often a far one of
            # a cylinder-like surface, and its candidates span several faces.
            return out
        ls = 0 if fr is None else int(apex_support(fr[0], P, N).sum())
        for ok in consensus_apexes(P, N, np.random.default_rng(ctx.seed), min_points=ctx.min_points):
            # The least-squares apex stands when nearly as well supported.
            if ok.all() or ok.sum() <= 1.1 * ls:
                continue
            fr = cone_directrix_frame(P[ok], N[ok])
            if fr is not None and not any(_same_frame(fr, o) for o in out):
                out.append(DirectrixPlacement(fr[1], fr[0], {"n": fr[2]}))
        return out

    def _order(self, Pl):
        n = active_order()
        if n is None:  # called outside propose(): analyse the points themselves
            W, _ = projected(Pl)
            fit = best_order(W, np.zeros(2), trim=False)
            n = 2 if fit is None else fit[0]
        return n

    def region(self, Pl, Nl, ctx):
        W, _ = projected(Pl)
        s = np.hypot(W[:, 0], W[:, 1]) if len(W) else np.ones(1)
        zt = typical_height(Pl)
        hi = float(min(s.max() * (1 + B_MAX), np.tan(np.radians(85.0))))
        return vote_grid(self._order(Pl), hi, ctx.cell / max(zt, 1e-6), float(np.median(s)))

    def coarse_tolerance(self, grid, Pl, ctx):
        # The grid is (n, b, slope): a slope cell moves the surface by its
        # width times the height of the points above the apex.
        return max(2.0 * ctx.cell, 1.5 * float(grid.width[2]) * abs(typical_height(Pl)))

    def gamma(self, Pl, Nl, grid, ctx):
        # Sweep b over its bins and solve slope = (ρ/z)(1 + b cos nθ) (phase 0 in this frame).
        n = self._order(Pl)
        W, ok = projected(Pl)
        idx = np.flatnonzero(ok)
        th, s = polar_local(W)
        b = grid.centers(1)
        S = s[:, None] * (1.0 + b[None, :] * np.cos(n * th)[:, None])
        voter = np.repeat(idx, len(b))
        vals = np.stack([np.full(S.size, float(n)), np.broadcast_to(b, S.shape).ravel(), S.ravel()], axis=1)
        return voter, vals

    def primitive(self, values, placement):
        return Primitive(self.name, {"apex": placement.origin.copy(), "axis": placement.R[2].copy(),
                                     "ref_direction": placement.R[0].copy(), "a": float(values[2]),
                                     "b": float(values[1]), "n": int(round(values[0]))})

    # --- geometry ------------------------------------------------------------------------
    def _local(self, prim, P):
        e1, e2, ax = ref_basis(prim.params["axis"], prim.params["ref_direction"])
        v = P - prim.params["apex"]
        return np.stack([v @ e1, v @ e2, v @ ax], axis=1), (e1, e2, ax)

    def distance(self, prim, P):
        p = prim.params
        q, _ = self._local(prim, P)
        u = ruling_foot(q, p["a"], p["b"], p["n"])
        D, _ = _rulings(u, p["a"], p["b"], p["n"])
        Dh = unit(D)
        along = np.einsum("ij,ij->i", q, Dh)
        return np.where(along > 0, np.linalg.norm(np.cross(q, Dh), axis=1), np.linalg.norm(q, axis=1))

    def surface_normals(self, prim, P):
        p = prim.params
        q, (e1, e2, ax) = self._local(prim, P)
        u = ruling_foot(q, p["a"], p["b"], p["n"])
        D, D1 = _rulings(u, p["a"], p["b"], p["n"])
        m = unit(np.cross(D1, D))
        return unit(m[:, :1] * e1 + m[:, 1:2] * e2 + m[:, 2:] * ax)

    def valid(self, prim, ctx):
        p = prim.params
        return (np.tan(np.radians(2.0)) < p["a"] < np.tan(np.radians(85.0)) and B_MIN <= p["b"] <= B_MAX
                and p["n"] in N_VALUES)

    def fit(self, prim, P, N):
        p0 = prim.params
        n = int(p0["n"])
        e1, e2, a0 = ref_basis(p0["axis"], p0["ref_direction"])

        def unpack(x):
            return p0["apex"] + x[:3], unit(a0 + x[3] * e1 + x[4] * e2), x[5], x[6], x[7]

        def frame(x):
            return ref_basis(a0 + x[3] * e1 + x[4] * e2, e1)

        state: dict = {}

        def res(x):
            apex = p0["apex"] + x[:3]
            s, b, phi = x[5], x[6], x[7]
            f1, f2, ax = frame(x)
            v = P - apex
            X, Y, Z = v @ f1, v @ f2, v @ ax
            rho = np.maximum(np.hypot(X, Y), 1e-12)
            th = np.arctan2(Y, X) - phi
            cn, sn = np.cos(n * th), np.sin(n * th)
            g = 1.0 + b * cn
            t = b * n * sn
            G = np.sqrt(np.maximum(g**2 + t**2 + s * s, 1e-24))
            r = (rho * g - s * Z) / G  # Sampson distance F / |∇F| of F = ρ g(θ) − s z
            state.update(x=x.copy(), v=v, X=X, Y=Y, Z=Z, rho=rho, cn=cn, sn=sn, g=g, t=t, G=G, r=r,
                         f=(f1, f2, ax))
            return r

        def jac(x):
            # Analytic but for the frame's turn with the axis: a numerical
            # Jacobian costs 9 residuals.
            if "x" not in state or not np.array_equal(state["x"], x):
                res(x)
            st = state
            f1, f2, ax = st["f"]
            X, Y, Z, rho, cn, sn, g, t, G, r = (st[k] for k in ("X", "Y", "Z", "rho", "cn", "sn", "g", "t", "G", "r"))
            dX, dY, dZ = frame_turn_rows(frame, x, st["v"], (3, 4))
            for j in range(3):
                dX[j], dY[j], dZ[j] = -f1[j], -f2[j], -ax[j]
            s = x[5]
            drho, dg, dt = polar_rows(X, Y, rho, cn, sn, x[6], n, dX, dY, b_col=6, phi_col=7)
            ds = np.zeros((len(x), 1))
            ds[5] = 1.0
            dF = drho * g + rho * dg - ds * Z - s * dZ
            dG = (g * dg + t * dt + s * ds) / G
            J = ((dF - r * dG) / G).T
            return np.where(np.isfinite(J), J, 0.0)

        x0 = np.array([0, 0, 0, 0, 0, p0["a"], p0["b"], 0.0])
        try:
            sol = _lm.solve(_lm.rows_of(res, jac), x0, max_nfev=80)
        except Exception:
            return None
        apex, ax, s, b, phi = unpack(sol.x)
        if not (np.isfinite(sol.x).all() and s > 0):
            return None
        if np.mean((P - apex) @ ax) < 0:
            return None
        f1, f2, _ = ref_basis(ax, e1)
        b, phi = normalise_shape(b, phi, n)
        v = P - apex
        b = debias_b(b, n, sol.fun, np.hypot(v @ f1, v @ f2))
        ref = np.cos(phi) * f1 + np.sin(phi) * f2
        return Primitive(self.name, {"apex": apex, "axis": ax, "ref_direction": ref, "a": float(s), "b": float(b),
                                     "n": n})

    # --- output --------------------------------------------------------------------------
    def to_world(self, prim, T):
        p = prim.params
        e1, _, ax = ref_basis(p["axis"], p["ref_direction"])
        return {"apex": T.inv_points(p["apex"]).tolist(), "axis": unit(T.inv_dirs(ax)).tolist(),
                "ref_direction": unit(T.inv_dirs(e1)).tolist(), "a": float(p["a"]), "b": float(p["b"]),
                "n": int(p["n"]), "A": 1.0, "B": 0.0}

    integer_descriptors = ("n",)

    def descriptors(self, prim):
        p = prim.params
        return {"a": float(p["a"]), "b": float(p["b"]), "n": int(p["n"])}

    def frame(self, prim):
        return Frame("point", np.asarray(prim.params["apex"], float), unit(prim.params["axis"]), oriented=True)
