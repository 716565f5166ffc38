"""The RANSAC fallback of the splitting phase: CGAL's Efficient RANSAC proposes
regions of a cluster that the Hough recognition could not place; the vote
then decides type and parameters of each region."""

from __future__ import annotations

import numpy as np

from .cgal_random import seed_cgal_random
from .context import Context
from .families.base import on_one_line

#: RANSAC's distance must be positive (standard units).
_TINY = 1e-6


def ransac_pieces(idx: np.ndarray, ctx: Context) -> list[np.ndarray]:
    """Over-segment a cluster with CGAL's Efficient RANSAC (Schnabel et al. 2007).

    Returns the pieces (global indices) RANSAC assigns to a shape. The
    bindings have no vectorised normal setter, hence the per-point loop at the
    boundary; clusters are small.
    """
    try:
        from CGAL.CGAL_Kernel import Vector_3
        from CGAL.CGAL_Point_set_3 import Point_set_3
        from CGAL.CGAL_Shape_detection import efficient_RANSAC
    except ImportError:  # pragma: no cover - cgal is a declared dependency
        return []
    P, N = ctx.pre.points[idx], ctx.pre.normals[idx]
    if on_one_line(P):  # no surface to find, and CGAL's octree writes through a null pointer on it
        return []
    ps = Point_set_3()
    ps.add_normal_map()
    ps.insert_range(np.ascontiguousarray(P, dtype=np.float64).ravel())
    nm = ps.normal_map()
    for i, n in enumerate(N.tolist()):
        nm.set(i, Vector_3(*n))
    sm = ps.add_int_map("shape_index")
    seed_cgal_random(ctx.seed)
    t = ctx.tol.splitting
    efficient_RANSAC(ps, sm, min_points=max(ctx.min_points, t.ransac_min_points), epsilon=max(ctx.tau, _TINY),
                     cluster_epsilon=ctx.link, normal_threshold=float(np.cos(ctx.angle)),
                     probability=t.ransac_probability, planes=True, cylinders=True, cones=True, spheres=True, tori=True)
    lab = np.fromiter((sm.get(i) for i in range(len(idx))), dtype=np.int64, count=len(idx))
    return [idx[lab == k] for k in range(lab.max() + 1) if (lab == k).sum() >= ctx.min_points]
