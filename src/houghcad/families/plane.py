"""Planes. Standard form z = k (one unknown) once the normal is along z."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..hough import Grid, direction_accumulator, refine_direction
from ..preprocess import rotation_to_z
from .base import Frame, Family, Placement, Primitive, register, unit
from ._sampling import ORIGIN, TAU, Z_AXIS, Array, Sampler


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def sample_plane_patch(
    rng: np.random.Generator, n: int, size: tuple[float, float] = (1.0, 1.0), shape: str = "rect"
) -> tuple[Array, Array]:
    """Uniform points on a patch of the plane z = 0, centred at the origin.

    Parameters
    ----------
    rng : numpy Generator
    n : int
        Number of points.
    size : (w, h)
        Side lengths along x and y (units). For ``shape="disc"`` the patch is the ellipse
        inscribed in that rectangle (a disc of radius w/2 when w = h).
    shape : "rect" or "disc"

    Returns
    -------
    points : (n, 3) float64, normals : (n, 3) float64 (all +z)
    """
    w, h = float(size[0]), float(size[1])
    if shape == "rect":
        xy = (rng.random((n, 2)) - 0.5) * np.array([w, h])
    elif shape == "disc":
        rho = np.sqrt(rng.random(n))
        phi = TAU * rng.random(n)
        xy = np.stack([0.5 * w * rho * np.cos(phi), 0.5 * h * rho * np.sin(phi)], axis=1)
    else:
        raise ValueError(f"unknown plane patch shape {shape!r}")
    pts = np.column_stack([xy, np.zeros(n)])
    nrm = np.zeros((n, 3))
    nrm[:, 2] = 1.0
    return pts, nrm


def _plane_area(size: tuple[float, float] = (1.0, 1.0), shape: str = "rect") -> float:
    return float(size[0] * size[1] * (1.0 if shape == "rect" else np.pi / 4))


def _plane_local(**_: Any) -> dict[str, Any]:
    return {"normal": list(Z_AXIS), "offset": 0.0, "point": list(ORIGIN)}


def _plane_random(rng: np.random.Generator) -> dict[str, Any]:
    size = (float(rng.uniform(0.6, 1.4)), float(rng.uniform(0.6, 1.4)))
    return {"size": size, "shape": "rect" if rng.random() < 0.7 else "disc"}


@register
class Plane(Family):
    name = "plane"
    param_names = ("normal", "offset", "point")
    n_unknowns = 1
    role = "simple"
    precedence = 0
    search = "whole"
    pointwise = True
    order = 10
    color = (228, 26, 28)  # red
    type_code = 1
    sampler = Sampler(sample_plane_patch, _plane_area, _plane_local, _plane_random,
                      {"normal": "direction", "offset": "offset", "point": "point"})

    def placements(self, P, N, ctx):
        # Standard-form estimation: the persistent peaks of the normals' votes
        # on the half-sphere are the planes' normal directions.
        acc = direction_accumulator()
        H = acc.smooth(acc.vote(N))
        dirs, pers = acc.peaks(H, ctx.persistence, max_peaks=ctx.max_directions)
        out = []
        for d in dirs:
            d = refine_direction(d, N, ctx.angle)
            if (np.abs(N @ d) >= ctx.cos_angle).sum() >= ctx.min_points:
                out.append(Placement(rotation_to_z(d), np.zeros(3)))
        return out

    def region(self, Pl, Nl, ctx):
        z = Pl[:, 2]
        lo, hi = z.min() - ctx.tau, z.max() + ctx.tau
        w = max(ctx.cell, 1e-6)
        nb = int(np.clip(np.ceil((hi - lo) / w), 1, 4096))
        return Grid((lo,), (hi,), (nb,))

    def gamma(self, Pl, Nl, grid, ctx):
        ok = np.abs(Nl[:, 2]) >= ctx.cos_angle
        idx = np.flatnonzero(ok)
        return idx, Pl[idx, 2:3]

    def primitive(self, values, placement):
        n = placement.R[2]
        k = float(values[0]) + placement.origin @ n
        return Primitive("plane", {"normal": n.copy(), "offset": k})

    def distance(self, prim, P):
        return np.abs(P @ prim.params["normal"] - prim.params["offset"])

    def surface_normals(self, prim, P):
        return np.broadcast_to(prim.params["normal"], P.shape)

    def fit(self, prim, P, N):
        if len(P) < 3:
            return None
        c = P.mean(axis=0)
        _, _, vt = np.linalg.svd(P - c, full_matrices=False)
        n = vt[2]
        if n @ prim.params["normal"] < 0:
            n = -n
        return Primitive("plane", {"normal": n, "offset": float(n @ c), "point": c})

    def to_world(self, prim, T):
        n = unit(T.inv_dirs(prim.params["normal"]))
        p = prim.params.get("point")
        if p is None:
            p = prim.params["normal"] * prim.params["offset"]
        pw = T.inv_points(p)
        return {"normal": n.tolist(), "offset": float(n @ pw), "point": pw.tolist()}

    def descriptors(self, prim):
        return {}

    def frame(self, prim):
        n = prim.params["normal"]
        return Frame("plane", n * prim.params["offset"], n)
