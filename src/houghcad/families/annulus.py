"""Planar annuli: the convex combination of two concentric circles,
x = R(u) cos v, y = R(u) sin v, z = 0, R(u) = a u + (1 − u) b, u ∈ [0, 1]:
the region of a plane between the radii b (inner) and a (outer).

Standard form: the normal along z (the dominant normal direction), the
centre at the origin (the circle vote of the boundary points, refined by an
algebraic fit of two concentric circles). Voted: the offset z = k, as for a
plane; the radii are the ends of the inliers' radial range (the annulus is a
bounded piece of its plane: its edges are not a surface equation a point
could vote for).

An annulus explains a planar region exactly as well as its plane does, so
under ``families="all"`` the plane (complexity 0, found in the global round)
keeps such regions; the annulus is reported when it is selected without the
plane (e.g. ``families="annulus"`` or ``"annulus,cylinder"``). See
docs/family-annulus.md.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from ..hough import Grid
from ..preprocess import rotation_to_z
from .base import Frame, Family, Placement, Primitive, register, tangent_basis, unit
from .cylinder import circle_centers
from ._helix import band_edges


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

    try:
        sol = least_squares(res, np.r_[c0, r0], loss="soft_l1", f_scale=max(scale, 1e-9), max_nfev=100)
    except Exception:
        return None
    c, (r1, r2) = sol.x[:2], sorted(np.abs(sol.x[2:]))
    return (c, (float(r1), float(r2))) if np.isfinite(sol.x).all() else None


@register
class Annulus(Family):
    name = "annulus"
    param_names = ("center", "normal", "r_inner", "r_outer")
    n_unknowns = 1
    complexity = 7
    simple = False
    global_search = False

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
        m = P.mean(axis=0)
        n = np.linalg.svd(P - m, full_matrices=False)[2][2]
        if n @ prim.params["normal"] < 0:
            n = -n
        e1, e2 = tangent_basis(n)
        Q = np.stack([(P - m) @ e1, (P - m) @ e2], axis=1)
        c0 = prim.params["center"] - m
        c0 = np.array([c0 @ e1, c0 @ e2])
        mask, _, sp = boundary_directions(Q)
        h = (P - m) @ n
        sigma = float(np.sqrt(np.mean(h**2)))
        got = (concentric_circles(Q[mask], c0, max(sigma, sp), (prim.params["r_inner"], prim.params["r_outer"]))
               if mask.sum() >= 10 else None)
        c = got[0] if got is not None else c0
        b, a = band_edges(np.linalg.norm(Q - c, axis=1), sigma)
        return Primitive(self.name, {"center": m + c[0] * e1 + c[1] * e2, "normal": n,
                                     "r_inner": float(max(b, 0.0)), "r_outer": float(a)})

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
