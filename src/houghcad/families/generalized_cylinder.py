"""Generalised cylinders over an n-convexity directrix (paper Table 2(a)).

Standard form (axis z through the directrix's centre, local x along the
reference direction): x = a cos u / (1 + b cos nu), y = a sin u / (1 + b cos nu),
z = v. In polar coordinates of the cross-section ρ(θ) = a / (1 + b cos n(θ − φ)),
so 1/ρ = (1 + b cos n(θ − φ)) / a is linear in (1/a, b/a cos nφ, b/a sin nφ):
for every n of the sweep a linear least-squares fit gives the directrix's phase
φ and the residual that picks n; the frame is then turned by φ and (b, a) are
voted (two unknowns). The integer n (2 … 12) reaches ``region``/``gamma``
through the placement (see :class:`DirectrixPlacement`).
"""

from __future__ import annotations

from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..hough import Grid
from ..preprocess import rotation_to_z
from .base import (Frame, Family, Placement, Primitive, frame_turn_rows, register, regular_indices,
                   tangent_basis, unit)
from ._sampling import (ORIGIN, TAU, Z_AXIS, Array, Sampler, directrix_length, directrix_random, directrix_speed,
                        draw_by_weight, span)
from .cylinder import axis_candidates
from . import _lm

#: Orders of the directrix that are swept.
N_VALUES = tuple(range(2, 13))
#: Below this |b| the surface is a circular cylinder (or cone): left to the simple family.
B_MIN = 0.03
_MAX_ORDER_POINTS = 800
#: Largest b voted or accepted (b → 1 makes ρ unbounded).
B_MAX = 0.6

# The protocol's region()/gamma() do not receive the placement; the order n
# and phase chosen by placements() reach them through the placement's local().
_ACTIVE: ContextVar["DirectrixPlacement | None"] = ContextVar("houghcad_directrix_placement", default=None)


@dataclass
class DirectrixPlacement(Placement):
    """A placement that carries the directrix order ``info["n"]`` to region/gamma."""

    def local(self, P, N):
        _ACTIVE.set(self)
        return super().local(P, N)


def active_order() -> int | None:
    """Order n of the placement whose local frame was computed last (None if unknown)."""
    pl = _ACTIVE.get()
    return None if pl is None else int(pl.info.get("n", 0)) or None


# --- the directrix ρ(θ) = a / (1 + b cos nθ) -----------------------------------------------

def directrix(u: np.ndarray, a: float, b: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points C(u), first and second derivatives, each (m, 2), of the directrix (phase 0)."""
    c, s = np.cos(u), np.sin(u)
    g = 1.0 + b * np.cos(n * u)
    g1 = -b * n * np.sin(n * u)
    g2 = -b * n * n * np.cos(n * u)
    r = a / g
    r1 = -a * g1 / g**2
    r2 = -a * g2 / g**2 + 2.0 * a * g1**2 / g**3
    e = np.stack([c, s], axis=1)
    ep = np.stack([-s, c], axis=1)
    C = r[:, None] * e
    C1 = r1[:, None] * e + r[:, None] * ep
    C2 = (r2 - r)[:, None] * e + 2.0 * r1[:, None] * ep
    return C, C1, C2


def directrix_foot(q: np.ndarray, a: float, b: float, n: int, iters: int = 5) -> np.ndarray:
    """Curve parameter u (m,) of the nearest directrix point to 2-D points q (m, 2).

    Nearest of a dense sample (cKDTree), then vectorised Newton steps on
    |C(u) − q|², each clipped to the sample spacing (hand-written: scipy has no
    vectorised scalar minimiser).
    """
    m = int(max(720, 96 * n))
    us = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    C, _, _ = directrix(us, a, b, n)
    u = us[cKDTree(C).query(q)[1]]
    h = 2 * np.pi / m
    for _ in range(iters):
        Cu, C1, C2 = directrix(u, a, b, n)
        d = Cu - q
        f1 = np.einsum("ij,ij->i", C1, d)
        f2 = np.einsum("ij,ij->i", C2, d) + np.einsum("ij,ij->i", C1, C1)
        step = np.where(f2 > 1e-12, -f1 / np.where(f2 > 1e-12, f2, 1.0), -np.sign(f1) * h)
        u = u + np.clip(step, -h, h)
    return u


def polar_fit(theta: np.ndarray, rho: np.ndarray, n: int, centre_terms: bool = False) -> tuple[np.ndarray, float]:
    """Least squares of 1/ρ = p0 + p1 cos nθ + p2 sin nθ (+ q1 cos θ + q2 sin θ).

    Rows are weighted by ρ² so that residuals are radial distances (units of ρ).
    Returns the coefficients and the RMS radial residual.
    """
    cols = [np.ones_like(theta), np.cos(n * theta), np.sin(n * theta)]
    if centre_terms:
        cols += [np.cos(theta), np.sin(theta)]
    A = np.stack(cols, axis=1) * (rho**2)[:, None]
    y = rho
    p, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = float(np.sqrt(np.mean((A @ p - y) ** 2)))
    return p, res


def shape_from_coeffs(p: np.ndarray, n: int) -> tuple[float, float, float]:
    """(a, b, φ) from the linear coefficients (p0, p1, p2); b ≥ 0."""
    p0 = p[0] if abs(p[0]) > 1e-12 else 1e-12
    return float(1.0 / p0), float(np.hypot(p[1], p[2]) / abs(p0)), float(np.arctan2(p[2], p[1]) / n)


def directrix_centre(Q: np.ndarray, n: int, c0: np.ndarray, iters: int = 12) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre of an n-convexity directrix through 2-D points Q (m, 2), from c0.

    An offset δ of the centre adds (δ·e(θ))/ρ² to 1/ρ: the cos θ, sin θ terms
    of the fit give δ ≈ (q1, q2) / p0². Returns (centre, coefficients, residual)
    of the final fit without centre terms.
    """
    c = np.asarray(c0, float).copy()
    scale = float(np.ptp(Q, axis=0).max()) + 1e-12
    for _ in range(iters):
        d = Q - c
        th, rho = np.arctan2(d[:, 1], d[:, 0]), np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
        p, _ = polar_fit(th, rho, n, centre_terms=True)
        if abs(p[0]) < 1e-12:
            break
        delta = p[3:5] / p[0] ** 2
        step = np.linalg.norm(delta)
        if step > 0.25 * scale:  # runaway: keep the last centre
            break
        c = c - delta
        if step < 1e-7 * scale:
            break
    d = Q - c
    th, rho = np.arctan2(d[:, 1], d[:, 0]), np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
    p, res = polar_fit(th, rho, n)
    return c, p, res


def best_order(Q: np.ndarray, c0: np.ndarray, trim: bool = True):
    """Sweep n over :data:`N_VALUES`: centre and linear fit per n, lowest residual wins.

    With ``trim``, points farther than 3 median residuals from the winner's
    directrix are dropped and the sweep repeated (clusters holding a neighbour's
    points). Returns (n, centre (2,), a, b, φ, residual) or None.
    """
    if len(Q) < 10:
        return None
    # 11 orders x 12 centre iterations: a regular subsample fixes the shape as well.
    Q = Q[regular_indices(len(Q), _MAX_ORDER_POINTS)]
    best = None
    for n in N_VALUES:
        c, p, res = directrix_centre(Q, n, c0)
        if p[0] <= 0 or not np.isfinite(res):
            continue
        if best is None or res < best[-1]:
            best = (n, c, *shape_from_coeffs(p, n), res)
    if best is None:
        return None
    if trim:
        n, c, a, b, phi, _ = best
        d = Q - c
        th, rho = np.arctan2(d[:, 1], d[:, 0]), np.hypot(d[:, 0], d[:, 1])
        r = np.abs(rho - a / (1 + b * np.cos(n * (th - phi))))
        keep = r <= 3.0 * np.median(r) + 1e-12
        if 10 <= keep.sum() < len(Q):
            return best_order(Q[keep], c, trim=False) or best
    return best


def rulings_angle(ctx) -> float:
    """Largest angle (radians) between a normal and the plane across the
    axis for a point to count as on the generalised cylinder.

    The normals' tolerance widens with noise (up to 45°); a cone beside the
    cylinder on the same axis (half-angle often 30–40°) would then place and
    vote as cross-sections of every size. A noisy normal's own error stays
    well under 25°.
    """
    return min(ctx.angle, np.radians(25.0))


def polar_local(Pl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polar angle and radius (n,) of local points about the z-axis."""
    return np.arctan2(Pl[:, 1], Pl[:, 0]), np.hypot(Pl[:, 0], Pl[:, 1])


def phase_frame(R: np.ndarray, phi: float) -> np.ndarray:
    """Rotation R turned about its z-axis by φ (local x to the directrix's phase)."""
    e1 = np.cos(phi) * R[0] + np.sin(phi) * R[1]
    return np.stack([e1, np.cross(R[2], e1), R[2]])


def debias_b(b: float, n: int, residuals: np.ndarray, rho: np.ndarray) -> float:
    """b corrected for the curvature bias of a least-squares fit to noisy points.

    Noise σ moves a fitted curve by about σ²κ/2 away from its centres of
    curvature: the lobes (κ ≈ (1 + b(n² − 1))/ρ) outwards, the valleys inwards,
    which inflates b by a factor 1 + (n² − 1) σ² / (2ρ²) (measured on 6 clouds
    at 0.5 % noise: 1.0–1.4 times this). σ² is the mean squared residual;
    ``rho`` (m,) the points' distances from the axis.
    """
    s2 = float(np.mean(residuals**2))
    return float(b / (1.0 + 0.5 * (n * n - 1) * s2 * float(np.mean(1.0 / np.maximum(rho, 1e-12) ** 2))))


def normalise_shape(b: float, phi: float, n: int) -> tuple[float, float]:
    """b ≥ 0 (a negative b is the same curve turned by π/n)."""
    if b < 0:
        b, phi = -b, phi + np.pi / n
    return float(b), float(np.mod(phi, 2 * np.pi / n))


def ref_basis(axis: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal (e1 along ref ⊥ axis, e2 = axis × e1, axis)."""
    a = unit(axis)
    e1 = ref - (ref @ a) * a
    if np.linalg.norm(e1) < 1e-9:
        e1 = tangent_basis(a)[0]
    e1 = unit(e1)
    return e1, np.cross(a, e1), a


def polar_rows(X: np.ndarray, Y: np.ndarray, rho: np.ndarray, cn: np.ndarray, sn: np.ndarray, b: float,
               n: int, dX: np.ndarray, dY: np.ndarray, b_col: int, phi_col: int):
    """Rows (k, m) of dρ, dg and dt for g = 1 + b cos nθ, t = b n sin nθ, with
    θ = atan2(Y, X) − φ, from the rows dX, dY (k, m) of the section
    coordinates; b and φ are the parameters in columns ``b_col``, ``phi_col``.
    Shared by the generalised cylinder's and cone's Sampson Jacobians."""
    dth = (X * dY - Y * dX) / (rho * rho)
    dth[phi_col] -= 1.0
    drho = (X * dX + Y * dY) / rho
    db = np.zeros((len(dX), 1))
    db[b_col] = 1.0
    dg = cn * db - b * n * sn * dth
    dt = n * sn * db + b * n * n * cn * dth
    return drho, dg, dt


def vote_grid(n: int, rho_hi: float, cell: float, rho_typ: float) -> Grid:
    """Grid over (n, b, a): n a single bin (it comes from the placement), b in
    [0, B_MAX] at a step that moves a by about a cell, a in [0, rho_hi]."""
    w = max(cell, 1e-6)
    nb = int(np.clip(B_MAX * max(rho_typ, w) / w, 16, 96))
    na = int(np.clip(np.ceil(rho_hi / w), 16, 400))
    return Grid((n - 0.5, 0.0, 0.0), (n + 0.5, B_MAX, rho_hi), (1, nb, na))


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_generalized_cylinder(
    rng: np.random.Generator, n: int, a: float, b: float, order: int, height: float,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the generalised cylinder over ρ(u) = a / (1 + b cos(order·u)),
    -height/2 ≤ z ≤ height/2, u in ``arc`` (rad).

    Area element |C'(u)| du dz: u is drawn with density ∝ the directrix's speed, z uniformly.
    Returns points (n, 3) and outward unit normals (n, 3) (the directrix is star-shaped, traversed
    counter-clockwise, so the outward normal is C' turned by -90°).
    """
    a0, a1 = span(arc)
    u = draw_by_weight(rng, n, lambda t: directrix_speed(t, a, b, order)[2], a0, a1)
    z = (rng.random(n) - 0.5) * float(height)
    r, r1, sp = directrix_speed(u, a, b, order)
    c, s = np.cos(u), np.sin(u)
    t = np.column_stack([r1 * c - r * s, r1 * s + r * c]) / sp[:, None]  # unit tangent C'/|C'|
    pts = np.column_stack([r * c, r * s, z])
    nrm = np.column_stack([t[:, 1], -t[:, 0], np.zeros(n)])
    return pts, nrm


def _gcyl_area(a: float, b: float, order: int, height: float, arc: tuple[float, float] = (0.0, TAU)) -> float:
    return directrix_length(a, b, order, arc) * float(height)


def _gcyl_local(a: float, b: float, order: int, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(ORIGIN), "axis": list(Z_AXIS), "ref_direction": [1.0, 0.0, 0.0], "a": float(a),
            "b": float(b), "n": int(order)}


def _gcyl_random(rng: np.random.Generator) -> dict[str, Any]:
    order, b = directrix_random(rng)
    a = float(rng.uniform(0.4, 1.0))
    return {"a": a, "b": b, "order": order, "height": a * float(rng.uniform(1.0, 3.0))}


@register
class GeneralizedCylinder(Family):
    name = "generalized_cylinder"
    param_names = ("axis_point", "axis", "ref_direction", "a", "b", "n")
    n_unknowns = 2
    role = "complex"
    precedence = 6
    search = "whole"
    order = 60
    color = (0, 170, 170)  # teal
    type_code = 7
    sampler = Sampler(sample_generalized_cylinder, _gcyl_area, _gcyl_local, _gcyl_random,
                      {"axis_point": "point", "axis": "direction", "ref_direction": "direction",
                       "a": "length", "b": "invariant", "n": "invariant"})
    stacked = True

    # --- standard form -------------------------------------------------------------------
    def placements(self, P, N, ctx):
        out = []
        dirs = axis_candidates(P, N, ctx, 2)
        if not ctx.local:
            dirs = [np.linalg.eigh(N.T @ N)[1][:, 0]] + dirs
        for k, ax in enumerate(dirs[:3]):
            if any(abs(ax @ o.R[2]) > np.cos(np.radians(3.0)) for o in out):
                continue
            R = rotation_to_z(ax)
            ok = np.abs(N @ ax) <= np.sin(rulings_angle(ctx))
            if ok.sum() < max(ctx.min_points, 10):
                continue
            Q = (P[ok] @ R.T)[:, :2]
            # Algebraic (Kåsa) circle fit as the start of the centre.
            A = np.c_[2 * Q, np.ones(len(Q))]
            c0 = np.linalg.lstsq(A, (Q**2).sum(1), rcond=None)[0][:2]
            fit = best_order(Q, c0)
            if fit is None:
                continue
            n, c, a, b, phi, _ = fit
            if b < 0.5 * B_MIN:
                # A circle (a cylinder) or no directrix at all: valid() would
                # reject every peak, so skip the vote.
                continue
            Rp = phase_frame(R, phi)
            out.append(DirectrixPlacement(Rp, R.T @ np.array([c[0], c[1], 0.0]), {"n": int(n), "a": a, "b": b}))
        return out

    def _order(self, Pl):
        n = active_order()
        if n is None:  # called outside propose(): analyse the points themselves
            fit = best_order(Pl[:, :2], np.zeros(2), trim=False)
            n = 2 if fit is None else fit[0]
        return n

    def region(self, Pl, Nl, ctx):
        _, rho = polar_local(Pl)
        hi = min(float(rho.max()) * (1 + B_MAX) + ctx.tau, ctx.max_radius)
        return vote_grid(self._order(Pl), hi, ctx.cell, float(np.median(rho)))

    def coarse_tolerance(self, grid, Pl, ctx):
        # The grid is (n, b, a): a, the size, is the length axis.
        return max(2.0 * ctx.cell, 1.5 * float(grid.width[2]))

    def gamma(self, Pl, Nl, grid, ctx):
        # Sweep b over its bins and solve a = ρ (1 + b cos nθ) (phase 0 in this frame).
        n = self._order(Pl)
        th, rho = polar_local(Pl)
        idx = np.flatnonzero(np.abs(Nl[:, 2]) <= np.sin(rulings_angle(ctx)))
        b = grid.centers(1)
        A = rho[idx, None] * (1.0 + b[None, :] * np.cos(n * th[idx])[:, None])
        voter = np.repeat(idx, len(b))
        vals = np.stack([np.full(A.size, float(n)), np.broadcast_to(b, A.shape).ravel(), A.ravel()], axis=1)
        return voter, vals

    def primitive(self, values, placement):
        n = int(round(values[0]))
        return Primitive(self.name, {"axis_point": placement.origin.copy(), "axis": placement.R[2].copy(),
                                     "ref_direction": placement.R[0].copy(), "a": float(values[2]),
                                     "b": float(values[1]), "n": n})

    # --- geometry ------------------------------------------------------------------------
    def _section(self, prim, P):
        """2-D coordinates (m, 2) in the cross-section frame, and that frame."""
        e1, e2, ax = ref_basis(prim.params["axis"], prim.params["ref_direction"])
        v = P - prim.params["axis_point"]
        return np.stack([v @ e1, v @ e2], axis=1), (e1, e2, ax)

    def distance(self, prim, P):
        p = prim.params
        q, _ = self._section(prim, P)
        u = directrix_foot(q, p["a"], p["b"], p["n"])
        C, _, _ = directrix(u, p["a"], p["b"], p["n"])
        return np.linalg.norm(C - q, axis=1)

    def surface_normals(self, prim, P):
        p = prim.params
        q, (e1, e2, _) = self._section(prim, P)
        u = directrix_foot(q, p["a"], p["b"], p["n"])
        _, C1, _ = directrix(u, p["a"], p["b"], p["n"])
        m = np.stack([C1[:, 1], -C1[:, 0]], axis=1)
        return unit(m[:, :1] * e1 + m[:, 1:] * e2)

    def valid(self, prim, ctx):
        p = prim.params
        return (0 < p["a"] < ctx.max_radius and B_MIN <= p["b"] <= B_MAX and p["n"] in N_VALUES)

    def fit(self, prim, P, N):
        p0 = prim.params
        n = int(p0["n"])
        e1, e2, a0 = ref_basis(p0["axis"], p0["ref_direction"])
        c0 = p0["axis_point"]

        def unpack(x):
            ax = unit(a0 + x[0] * e1 + x[1] * e2)
            return ax, c0 + x[2] * e1 + x[3] * e2, x[4], x[5], x[6]

        def frame(x):
            return ref_basis(a0 + x[0] * e1 + x[1] * e2, e1)

        state: dict = {}

        def res(x):
            c = c0 + x[2] * e1 + x[3] * e2
            a, b, phi = x[4], x[5], x[6]
            f1, f2, _ = frame(x)
            v = P - c
            X, Y = v @ f1, v @ f2
            rho = np.maximum(np.hypot(X, Y), 1e-12)
            th = np.arctan2(Y, X) - phi
            cn, sn = np.cos(n * th), np.sin(n * th)
            g = 1.0 + b * cn
            s = b * n * sn
            G = np.sqrt(np.maximum(g**2 + s**2, 1e-24))
            r = (rho * g - a) / G  # Sampson distance F / |∇F| of F = ρ g(θ) − a
            state.update(x=x.copy(), v=v, X=X, Y=Y, rho=rho, cn=cn, sn=sn, g=g, s=s, G=G, r=r, f=(f1, f2))
            return r

        def jac(x):
            # Analytic but for the frame's turn with the axis: a numerical
            # Jacobian costs 8 residuals.
            if "x" not in state or not np.array_equal(state["x"], x):
                res(x)
            t = state
            f1, f2 = t["f"]
            X, Y, rho, cn, sn, g, s, G, r = (t[k] for k in ("X", "Y", "rho", "cn", "sn", "g", "s", "G", "r"))
            dX, dY, _ = frame_turn_rows(frame, x, t["v"], (0, 1))
            for j, e in ((2, e1), (3, e2)):
                dX[j], dY[j] = -(e @ f1), -(e @ f2)
            drho, dg, ds = polar_rows(X, Y, rho, cn, sn, x[5], n, dX, dY, b_col=5, phi_col=6)
            dF = drho * g + rho * dg
            dF[4] -= 1.0
            dG = (g * dg + s * ds) / G
            J = ((dF - r * dG) / G).T
            return np.where(np.isfinite(J), J, 0.0)

        x0 = np.array([0, 0, 0, 0, p0["a"], p0["b"], 0.0])
        try:
            sol = _lm.solve(_lm.rows_of(res, jac), x0, max_nfev=30)
        except Exception:
            return None
        # On its surface the fit settles in a few evaluations; one that runs
        # to the limit is on another surface.
        if sol.status == 0:
            return None
        ax, c, a, b, phi = unpack(sol.x)
        if not (np.isfinite(sol.x).all() and a > 0):
            return None
        f1, f2, _ = ref_basis(ax, e1)
        b, phi = normalise_shape(b, phi, n)
        v = P - c
        b = debias_b(b, n, sol.fun, np.hypot(v @ f1, v @ f2))
        ref = np.cos(phi) * f1 + np.sin(phi) * f2
        h = (P.mean(axis=0) - c) @ ax
        return Primitive(self.name, {"axis_point": c + h * ax, "axis": ax, "ref_direction": ref, "a": float(a),
                                     "b": float(b), "n": n})

    # --- output --------------------------------------------------------------------------
    def to_world(self, prim, T):
        p = prim.params
        e1, _, ax = ref_basis(p["axis"], p["ref_direction"])
        return {"axis_point": T.inv_points(p["axis_point"]).tolist(), "axis": unit(T.inv_dirs(ax)).tolist(),
                "ref_direction": unit(T.inv_dirs(e1)).tolist(), "a": T.inv_length(p["a"]), "b": float(p["b"]),
                "n": int(p["n"])}

    length_descriptors = ("a",)
    integer_descriptors = ("n",)

    def descriptors(self, prim):
        p = prim.params
        return {"a": float(p["a"]), "b": float(p["b"]), "n": int(p["n"])}

    def frame(self, prim):
        return Frame("line", np.asarray(prim.params["axis_point"], float), unit(prim.params["axis"]))
