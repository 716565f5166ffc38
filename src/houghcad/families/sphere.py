"""Spheres. Standard form x² + y² + z² = r² (one unknown) once the centre is
at the origin."""

from __future__ import annotations

import numpy as np

from ..hough import Grid, normal_line_peaks
from .base import Frame, Family, Placement, Primitive, gauss_newton, lines_intersection, register, unit


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


@register
class Sphere(Family):
    name = "sphere"
    param_names = ("center", "radius")
    n_unknowns = 1
    complexity = 2

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
