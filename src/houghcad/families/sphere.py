"""Spheres. Standard form x² + y² + z² = r² (one unknown) once the centre is
at the origin."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..hough import Grid, normal_line_peaks
from .base import Frame, Family, Placement, Primitive, gauss_newton, lines_intersection, register, unit
from ._sampling import ORIGIN, TAU, Array, Sampler, span


def center_votes(P, N, ctx, max_centers):
    """Centres where many normal lines meet: each point votes along its normal line."""
    lo, hi = P.min(axis=0), P.max(axis=0)
    ext = float((hi - lo).max())
    if ext <= 0:
        return np.zeros((0, 3))
    half = 0.5 * ext * 1.5
    nb = int(np.clip(ext / max(2 * ctx.cell, ctx.spacing), 12, 56))
    return normal_line_peaks(P, N, 0.5 * (lo + hi) - half, 2 * half, nb, half, ctx.persistence, ctx.min_votes,
                             max_centers)


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_sphere(
    rng: np.random.Generator,
    n: int,
    radius: float,
    polar_range: tuple[float, float] = (0.0, np.pi),
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the sphere of ``radius`` centred at the origin.

    ``polar_range`` (rad, within [0, π]) is the range of the angle from +z, ``arc`` the azimuth
    range. Area-correct: z is uniform (Archimedes). Returns points (n, 3), outward normals (n, 3).
    """
    p0, p1 = span(polar_range)
    a0, a1 = span(arc)
    u = np.cos(p1) + (np.cos(p0) - np.cos(p1)) * rng.random(n)  # cos(polar), uniform
    rho = np.sqrt(np.clip(1.0 - u * u, 0.0, None))
    th = a0 + (a1 - a0) * rng.random(n)
    nrm = np.column_stack([rho * np.cos(th), rho * np.sin(th), u])
    return radius * nrm, nrm


def _sphere_area(
    radius: float, polar_range: tuple[float, float] = (0.0, np.pi), arc: tuple[float, float] = (0.0, TAU)
) -> float:
    return float((arc[1] - arc[0]) * radius**2 * (np.cos(polar_range[0]) - np.cos(polar_range[1])))


def _sphere_local(radius: float, **_: Any) -> dict[str, Any]:
    return {"center": list(ORIGIN), "radius": float(radius)}


def _sphere_random(rng: np.random.Generator) -> dict[str, Any]:
    cap = (0.0, np.pi) if rng.random() < 0.5 else (0.0, float(rng.uniform(np.pi / 3, 0.9 * np.pi)))
    return {"radius": float(rng.uniform(0.5, 1.2)), "polar_range": cap}


@register
class Sphere(Family):
    name = "sphere"
    param_names = ("center", "radius")
    n_unknowns = 1
    role = "simple"
    precedence = 2
    search = "whole"
    pointwise = True
    order = 30
    color = (200, 40, 200)  # magenta
    type_code = 4
    sampler = Sampler(sample_sphere, _sphere_area, _sphere_local, _sphere_random,
                      {"center": "point", "radius": "length"})

    def placements(self, P, N, ctx):
        # Globally only the least-squares centre (cheap; right when one sphere
        # dominates); clusters also get the centre votes.
        cents = list(center_votes(P, N, ctx, ctx.max_peaks)) if ctx.local else []
        c, cond = lines_intersection(P, N)
        if cond > 1e-3:
            cents.insert(0, c)
        return [Placement(np.eye(3), np.asarray(c, float)) for c in cents]

    def region(self, Pl, Nl, ctx):
        r = np.linalg.norm(Pl, axis=1)
        hi = min(float(r.max()) + ctx.tau, ctx.max_radius)
        return Grid((0.0,), (hi,), (int(np.clip(np.ceil(hi / max(ctx.cell, 1e-6)), 1, 4096)),))

    def gamma(self, Pl, Nl, grid, ctx):
        r = np.linalg.norm(Pl, axis=1)
        cos = np.abs(np.einsum("ij,ij->i", Pl, Nl)) / np.maximum(r, 1e-12)
        idx = np.flatnonzero(cos >= ctx.cos_angle)
        return idx, r[idx, None]

    def primitive(self, values, placement):
        return Primitive("sphere", {"center": placement.origin.copy(), "radius": float(values[0])})

    def distance(self, prim, P):
        return np.abs(np.linalg.norm(P - prim.params["center"], axis=1) - prim.params["radius"])

    def surface_normals(self, prim, P):
        return unit(P - prim.params["center"])

    def valid(self, prim, ctx):
        return 0 < prim.params["radius"] < ctx.max_radius

    def fit(self, prim, P, N):
        def fun(x):
            v = P - x[:3]
            r = np.linalg.norm(v, axis=1)
            J = np.hstack([-v / np.maximum(r, 1e-15)[:, None], -np.ones((len(P), 1))])
            return r - x[3], J

        x = gauss_newton(fun, np.r_[prim.params["center"], prim.params["radius"]])
        if x is None:
            return None
        return Primitive("sphere", {"center": x[:3], "radius": float(abs(x[3]))})

    def to_world(self, prim, T):
        return {"center": T.inv_points(prim.params["center"]).tolist(),
                "radius": T.inv_length(prim.params["radius"])}

    length_descriptors = ("radius",)

    def descriptors(self, prim):
        return {"radius": float(prim.params["radius"])}

    def frame(self, prim):
        return Frame("point", np.asarray(prim.params["center"], float))
