"""Planes. Standard form z = k (one unknown) once the normal is along z."""

from __future__ import annotations

import numpy as np

from ..hough import Grid, direction_accumulator, refine_direction
from ..preprocess import rotation_to_z
from .base import Frame, Family, Placement, Primitive, register, unit


@register
class Plane(Family):
    name = "plane"
    param_names = ("normal", "offset", "point")
    n_unknowns = 1
    complexity = 0

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
