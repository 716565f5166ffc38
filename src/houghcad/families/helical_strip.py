"""Helical strips: the convex combination of two helices of equal pitch,
x = R(u) cos v, y = R(u) sin v, z = c v, R(u) = a u + (1 − u) b, u ∈ [0, 1]:
a strip of the helicoid z = c φ between the radii b (inner) and a (outer).

Standard form: the helix axis along z through the origin (from the linear
line complex of the normal lines, whose pitch is c). Voted: c and the phase
θ0 of the helicoid z = c (φ + θ0) (the frame's free rotation about z); the
radial extent [b, a] is estimated from the inliers (the strip is a bounded
piece of the helicoid, its ends are not a surface equation a point can vote
for).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..hough import Grid
from .base import Frame, Family, Primitive, axis_from_normal_lines, register, tangent_basis, unit
from . import _lm
from ._sampling import ORIGIN, Z_AXIS, Array, Sampler, inverse_cdf, span
from ._helix import band_edges, cylindrical, frame_axes, gated_screw_placement

TAU = 2.0 * np.pi


def helicoid_distance(rho: np.ndarray, phi: np.ndarray, z: np.ndarray, c: float, r_inner: float = 0.0,
                      r_outer: float = np.inf, iters: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance of points in cylindrical coordinates (n,) to the helicoid strip
    z = c φ (mod 2π c), r_inner ≤ ρ ≤ r_outer.

    The screw-invariant coordinate w = z − c φ, wrapped to the nearest turn,
    gives the axial gap to the sheet; times ρ/√(c² + ρ²) (the normal's axial
    component) it is the distance to first order. A few vectorised Newton
    steps on the foot's angular offset δ, with the foot's radius
    r = clip(ρ cos δ, r_inner, r_outer), make it exact, the strip's edges
    included.

    Returns the distance (n,), the foot's angular offset δ (n,) and radius (n,).
    """
    w = z - c * phi
    period = TAU * abs(c)
    w = w - period * np.round(w / period)
    d = c * w / (c * c + rho * rho)  # first-order foot: δ with ρ² δ + c (c δ − w) = 0
    for _ in range(iters):
        r = np.clip(rho * np.cos(d), r_inner, r_outer)
        g = r * rho * np.sin(d) + c * (c * d - w)
        h = r * rho * np.cos(d) + c * c
        d = d - g / np.where(h > 1e-12, h, 1e-12)
    r = np.clip(rho * np.cos(d), r_inner, r_outer)
    f = r * r - 2 * r * rho * np.cos(d) + rho * rho + (c * d - w) ** 2
    return np.sqrt(np.maximum(f, 0.0)), d, r


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_helical_strip(
    rng: np.random.Generator,
    n: int,
    r_inner: float,
    r_outer: float,
    c: float,
    v_range: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the helicoid strip x = ρ cos v, y = ρ sin v, z = c v, r_inner ≤ ρ ≤ r_outer.

    The area element √(c² + ρ²) dρ dv: v uniform, ρ by inverse CDF. Returns points (n, 3) and unit
    normals (n, 3) ∝ (c sin v, −c cos v, ρ).
    """
    if not (r_outer > r_inner >= 0 and c != 0):
        raise ValueError("helical strip needs r_outer > r_inner ≥ 0 and c ≠ 0")
    v0, v1 = span(v_range)
    v = v0 + (v1 - v0) * rng.random(n)
    g = np.linspace(r_inner, r_outer, 2049)
    rho = inverse_cdf(rng, n, g, np.sqrt(c * c + g * g))
    cv, sv = np.cos(v), np.sin(v)
    pts = np.column_stack([rho * cv, rho * sv, c * v])
    nrm = np.column_stack([c * sv, -c * cv, rho])
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _helical_strip_area(r_inner: float, r_outer: float, c: float, v_range: tuple[float, float] = (0.0, TAU)) -> float:
    def F(r: float) -> float:  # ∫ √(c² + r²) dr
        return 0.5 * (r * np.hypot(c, r) + c * c * np.arcsinh(r / abs(c)))

    return float((v_range[1] - v_range[0]) * (F(r_outer) - F(r_inner)))


def _helical_strip_local(r_inner: float, r_outer: float, c: float, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(ORIGIN), "axis": list(Z_AXIS), "ref_direction": [1.0, 0.0, 0.0],
            "r_inner": float(r_inner), "r_outer": float(r_outer), "pitch": float(abs(c) * TAU),
            "handedness": float(np.sign(c))}


def _helical_strip_random(rng: np.random.Generator) -> dict[str, Any]:
    a = float(rng.uniform(0.7, 1.0))
    c = a * float(rng.uniform(0.5, 1.0)) / TAU * (1 if rng.random() < 0.7 else -1)
    return {"r_inner": a * float(rng.uniform(0.3, 0.6)), "r_outer": a, "c": c,
            "v_range": (0.0, TAU * float(rng.uniform(1.0, 3.0)))}


@register
class HelicalStrip(Family):
    name = "helical_strip"
    param_names = ("axis_point", "axis", "ref_direction", "r_inner", "r_outer", "pitch", "handedness")
    n_unknowns = 2
    role = "complex"
    precedence = 8
    #: Sought in the global round too, when the whole cloud's normal lines form
    #: one linear complex: otherwise planes and cylinders take the strip's bands
    #: there (5 noisy single instances: 0/5 recognised, 5/5 with it).
    search = "whole"
    pointwise = True
    order = 90
    color = (110, 60, 200)  # violet
    type_code = 11
    sampler = Sampler(sample_helical_strip, _helical_strip_area, _helical_strip_local, _helical_strip_random,
                      {"axis_point": "point", "axis": "direction", "ref_direction": "direction",
                       "r_inner": "length", "r_outer": "length", "pitch": "length",
                       "handedness": "invariant"})

    # --- standard form and voting -------------------------------------------
    def placements(self, P, N, ctx):
        placed = gated_screw_placement(P, N, ctx)
        if placed is None:
            return []  # the whole cloud is not screw-invariant: leave it to the per-cluster rounds
        pl, p = placed
        rho = np.hypot(*pl.local(P, N)[0][:, :2].T)
        if abs(p) < 0.01 * max(float(np.median(rho)), 1e-9):
            return []  # no screw motion: a plane or a surface of revolution
        pl.info.update(p=p, rho=rho)
        return [pl]

    @staticmethod
    def _pitch(Pl, Nl) -> float:
        # The complex's pitch is invariant under rigid motions: recomputed in the local frame.
        return axis_from_normal_lines(Pl, Nl)[2]

    def region(self, Pl, Nl, ctx):
        p = self._pitch(Pl, Nl)
        lo, hi = sorted((0.75 * p, 1.25 * p))
        nb = int(np.clip((hi - lo) / max(0.01 * abs(p), 1e-9), 8, 64))
        return Grid((lo, 0.0), (hi, TAU), (nb, 72), (False, True))

    def gamma(self, Pl, Nl, grid, ctx):
        c = grid.centers(0)
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        phi = np.arctan2(Pl[:, 1], Pl[:, 0])
        # Normal of the helicoid z = c(φ + θ0) at a point: (0, −c, ρ)/√(c² + ρ²) in (e_ρ, e_φ, e_z).
        n_phi = (-Nl[:, 0] * np.sin(phi) + Nl[:, 1] * np.cos(phi))
        cos_n = np.abs(-n_phi[:, None] * c[None, :] + Nl[:, 2, None] * rho[:, None]) / np.hypot(c[None, :], rho[:, None])
        ok = cos_n >= ctx.cos_angle
        vi, ci = np.nonzero(ok)
        th = np.mod(Pl[vi, 2] / c[ci] - phi[vi], TAU)
        return vi, np.stack([c[ci], th], axis=1)

    def primitive(self, values, placement):
        c, th = float(values[0]), float(values[1])
        R = placement.R
        # z = c(φ + θ0) passes z = 0 at φ = −θ0: the reference ruling.
        ref = np.cos(th) * R[0] - np.sin(th) * R[1]
        b, a = band_edges(placement.info.get("rho", np.array([0.0, 1.0])), 0.0)
        return Primitive(self.name, {"axis_point": placement.origin.copy(), "axis": R[2].copy(), "ref_direction": ref,
                                     "c": c, "r_inner": float(b), "r_outer": float(a)})

    # --- geometry -----------------------------------------------------------
    def _coords(self, prim, P):
        p = prim.params
        return cylindrical(P, p["axis_point"], p["axis"], p["ref_direction"])

    def distance(self, prim, P):
        rho, phi, z, _ = self._coords(prim, P)
        p = prim.params
        return helicoid_distance(rho, phi, z, p["c"], p["r_inner"], p["r_outer"])[0]

    def surface_normals(self, prim, P):
        rho, phi, z, (e1, e2, a) = self._coords(prim, P)
        p = prim.params
        _, d, r = helicoid_distance(rho, phi, z, p["c"], p["r_inner"], p["r_outer"])
        v = phi + d
        c = p["c"]
        n = (c * np.sin(v))[:, None] * e1 - (c * np.cos(v))[:, None] * e2 + r[:, None] * a
        return unit(n)

    def valid(self, prim, ctx):
        p = prim.params
        c, b, a = abs(p["c"]), p["r_inner"], p["r_outer"]
        # Below 2 % of the radius the strip is an annulus (a plane explains it); far above
        # ten radii per radian it is a half-plane through the axis.
        return (0 <= b < a < ctx.max_radius and 0.02 * a <= c <= 10 * a and np.isfinite(c))

    def fit(self, prim, P, N):
        if len(P) < 12:
            return None
        p0 = prim.params
        a0 = unit(p0["axis"])
        e1, e2 = tangent_basis(a0)

        def unpack(x):
            a = unit(a0 + x[0] * e1 + x[1] * e2)
            q = p0["axis_point"] + x[2] * e1 + x[3] * e2 + x[4] * a0
            return a, q, x[5]

        def res(x):
            a, q, c = unpack(x)
            rho, phi, z, _ = cylindrical(P, q, a, p0["ref_direction"])
            w = z - c * phi
            w = w - TAU * abs(c) * np.round(w / (TAU * abs(c)))
            return w * rho / np.hypot(c, rho)

        x0 = np.array([0, 0, 0, 0, 0, p0["c"]], float)
        try:
            sol = _lm.solve(_lm.forward_difference_rows(res), x0, max_nfev=60)
        except Exception:
            return None
        a, q, c = unpack(sol.x)
        if not np.isfinite(sol.x).all() or abs(c) < 1e-9:
            return None
        # Axis point at the foot of the centroid; the reference ruling turned to keep the sheet.
        e1n, e2n, _ = frame_axes(a, p0["ref_direction"])
        s = (P.mean(axis=0) - q) @ a
        ref = np.cos(s / c) * e1n + np.sin(s / c) * e2n
        q = q + s * a
        rho = cylindrical(P, q, a, ref)[0]
        sigma = float(np.sqrt(np.mean(sol.fun ** 2)))
        b, a_out = band_edges(rho, sigma)
        return Primitive(self.name, {"axis_point": q, "axis": a, "ref_direction": ref, "c": float(c),
                                     "r_inner": float(max(b, 0.0)), "r_outer": float(a_out)})

    # --- output -------------------------------------------------------------
    def to_world(self, prim, T):
        p = prim.params
        return {"axis_point": T.inv_points(p["axis_point"]).tolist(),
                "axis": unit(T.inv_dirs(p["axis"])).tolist(),
                "ref_direction": unit(T.inv_dirs(p["ref_direction"])).tolist(),
                "r_inner": T.inv_length(p["r_inner"]), "r_outer": T.inv_length(p["r_outer"]),
                "pitch": T.inv_length(TAU * abs(p["c"])), "handedness": float(np.sign(p["c"]))}

    length_descriptors = ("r_inner", "r_outer", "pitch")
    integer_descriptors = ("handedness",)

    def descriptors(self, prim):
        p = prim.params
        return {"r_inner": float(p["r_inner"]), "r_outer": float(p["r_outer"]),
                "pitch": float(TAU * abs(p["c"])), "handedness": int(np.sign(p["c"]))}

    def frame(self, prim):
        return Frame("line", np.asarray(prim.params["axis_point"], float), unit(prim.params["axis"]))


def from_world(params: dict) -> Primitive:
    """A Primitive from world-style parameters (synth's ground truth), same frame."""
    return Primitive("helical_strip", {
        "axis_point": np.asarray(params["axis_point"], float), "axis": unit(np.asarray(params["axis"], float)),
        "ref_direction": unit(np.asarray(params["ref_direction"], float)),
        "c": float(params["handedness"]) * float(params["pitch"]) / TAU,
        "r_inner": float(params["r_inner"]), "r_outer": float(params["r_outer"])})
