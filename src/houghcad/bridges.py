"""Pieces of a narrow face apart across gaps in its sampling (part of the association, §5.4).

A random sample of a face narrower than the link distance is a row of points, whose gaps are far
longer than a wide face's: the splitting phase's pieces of it stay apart, and the contact rule
(:meth:`houghcad.associate.Associator._adjacency`) cannot join them. :func:`bridged` tells which
pieces of one surface the gap between them joins into one face.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .families.base import Family, Primitive, unit
from .tolerances import AssociationTolerances

__all__ = ["bridged", "ring_row", "row_axis", "row_direction", "row_shape", "sampling_gaps"]

#: A row's width spans the central 95 % of its points across it: a few edge points a piece took
#: from its neighbour do not widen it.
ROW_PERCENTILES = (2.5, 97.5)
#: Points a row's shape is read on at most (a regular subsample).
ROW_POINTS = 2000
#: Fewest points read as a circle: three fix one, the rest must agree with it.
RING_MIN_POINTS = 6


def row_axis(P: np.ndarray, width: float) -> np.ndarray | None:
    """Main axis (3,) of the points P (n, 3) when they are a straight row narrower than ``width``
    across (their central 95 % in the second principal direction), else None."""
    if len(P) < 3:
        return None
    Q = P - P.mean(axis=0)
    _, _, vt = np.linalg.svd(Q[:: max(1, len(Q) // ROW_POINTS)], full_matrices=False)
    lo, hi = np.percentile(Q @ vt[1], ROW_PERCENTILES)
    return vt[0] if hi - lo <= width else None


def ring_row(P: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Centre (3,) and unit normal (3,) of the circle along which the points P (n, 3) run as a
    row narrower than ``width`` (their central 95 % across it, radially and along the normal),
    else None: an annular land, a band of a cylinder, an arc of either."""
    if len(P) < RING_MIN_POINTS:
        return None
    Q = P[:: max(1, len(P) // ROW_POINTS)]
    c0 = Q.mean(axis=0)
    _, _, vt = np.linalg.svd(Q - c0, full_matrices=False)
    x, y = (Q - c0) @ vt[0], (Q - c0) @ vt[1]
    # Algebraic circle fit: x² + y² = 2 a x + 2 b y + c, linear in (a, b, c).
    (a, b, _), *_ = np.linalg.lstsq(np.column_stack([2 * x, 2 * y, np.ones_like(x)]), x * x + y * y, rcond=None)
    r = np.hypot(x - a, y - b)
    if not np.isfinite(r).all() or np.ptp(np.percentile(r, ROW_PERCENTILES)) > width or \
            np.ptp(np.percentile((Q - c0) @ vt[2], ROW_PERCENTILES)) > width:
        return None
    return c0 + a * vt[0] + b * vt[1], vt[2]


def row_shape(P: np.ndarray, width: float) -> np.ndarray | tuple[np.ndarray, np.ndarray] | None:
    """What row the points P (n, 3) are, narrower than ``width``: the axis (3,) of a straight one
    (:func:`row_axis`), else the centre and normal of a circular one (:func:`ring_row`), else
    None."""
    axis = row_axis(P, width)
    return axis if axis is not None else ring_row(P, width)


def row_direction(shape: np.ndarray | tuple[np.ndarray, np.ndarray], at: np.ndarray) -> np.ndarray:
    """Direction (3,) at the point ``at`` (3,) of a row of :func:`row_shape` ``shape``: a straight
    row's axis, a circular row's tangent there."""
    if isinstance(shape, np.ndarray):
        return shape
    centre, normal = shape
    return unit(np.cross(normal, at - centre))


def bridged(pieces: list[np.ndarray], P: np.ndarray, tree: cKDTree, family: Family, prim: Primitive,
            link: float, tol: AssociationTolerances) -> set[tuple[int, int]]:
    """Pairs (i < j) of ``pieces`` (index arrays into the cloud P (n, 3), whose KD-tree is
    ``tree``) of one surface ``prim`` of ``family``: pieces of a narrow face apart across a gap
    in its sampling.

    Two pieces are one part when each is a row, the gap continues both, and the cloud goes on
    along the gap: every point of the segment joining their nearest points lies within
    ``bridge_links`` × ``link`` of the surface and within ``link`` of some point of the cloud (the
    neighbouring faces' edges run on beside it). A row runs straight or along a circle (a narrow
    annular land, a band of a cylinder, an arc of either): its direction is read where it meets
    the gap, the gap's between the middles of the two rows' ends (their points within
    ``bridge_reach`` links of it). Faces that taper to a point where they meet (pieces of a plane
    between a circle and the square around it) are rows only there, and stay apart. Pieces
    closer than ``link`` are left to the contact rule; pieces of a wide face, or apart across
    empty space, stay apart.
    """
    shapes = {m: row_shape(P[idx], link) for m, idx in enumerate(pieces)}
    rows = [m for m in shapes if shapes[m] is not None]
    trees = {m: cKDTree(P[pieces[m]]) for m in rows}
    reach = tol.bridge_reach * link
    cos_max = np.cos(np.radians(tol.bridge_angle))
    out: set[tuple[int, int]] = set()
    for i, a in enumerate(rows):
        for b in rows[i + 1:]:
            A, B = pieces[a], pieces[b]
            d, j = trees[b].query(P[A])
            k = int(np.argmin(d))
            if d[k] <= link:  # in contact: a line or a corner, as the contact rule says
                continue
            p, q = P[A[k]], P[B[j[k]]]
            ax_a, ax_b = row_direction(shapes[a], p), row_direction(shapes[b], q)
            # From one row end's middle to the other's: the nearest points may sit on
            # opposite sides of a row two spacings wide, as far apart across as along.
            end_a, end_b = P[A[trees[a].query_ball_point(p, reach)]], P[B[trees[b].query_ball_point(q, reach)]]
            u = end_b.mean(axis=0) - end_a.mean(axis=0)
            u /= max(float(np.linalg.norm(u)), np.finfo(float).tiny)
            if min(abs(u @ ax_a), abs(u @ ax_b)) < cos_max:
                continue
            S = p + np.linspace(0.0, 1.0, int(np.ceil(2 * d[k] / link)) + 1)[1:-1, None] * (q - p)
            if np.any(family.distance(prim, S) > tol.bridge_links * link) or \
                    not np.all(np.isfinite(tree.query(S, distance_upper_bound=link)[0])):
                continue
            out.add((a, b))
    return out


def sampling_gaps(members: list[int], pieces: list[np.ndarray], owner: np.ndarray, P: np.ndarray, tree: cKDTree,
                  link: float, tol: AssociationTolerances) -> set[tuple[int, int]]:
    """Pairs (i < j) of ``pieces`` (index arrays into P (n, 3), of the segments ``members`` of
    one surface; ``owner`` (n,) gives every point's segment, -1 free) apart by a gap of the
    sampling: as the contact rule asks within the link (``contact`` × √(points of the smaller)
    on each side, a boundary, not a corner), within ``gap_links`` × ``link``; when they are
    apart by more than the link, along no more than ``gap_front`` × √(points of the smaller)
    (a hole, not a boundary all along); and no point but theirs within half a link of the
    middle of the gap between their nearest points.

    Random samples of a face leave gaps a little wider than the link, which part its pieces
    as DBSCAN does; two faces of one surface are parted by something between them (a slot's
    walls, a rib, points no face explains), or meet at a corner.
    """
    out: set[tuple[int, int]] = set()
    reach = tol.gap_links * link
    trees = [cKDTree(P[idx]) for idx in pieces]
    for i in range(len(pieces)):
        for j in range(i + 1, len(pieces)):
            d, nn = trees[j].query(P[pieces[i]], distance_upper_bound=reach)
            k = int(np.argmin(d))
            if not np.isfinite(d[k]):
                continue
            front = np.array([np.isfinite(d).sum(),
                              np.isfinite(trees[i].query(P[pieces[j]], distance_upper_bound=reach)[0]).sum()])
            root = np.sqrt(min(len(pieces[i]), len(pieces[j])))
            # A corner, not a boundary; or, beyond the link, a boundary all along (a groove
            # too narrow to be sampled), not a hole.
            if front.min() < tol.contact * root or d[k] > link and front.max() > tol.gap_front * root:
                continue
            mid = 0.5 * (P[pieces[i][k]] + P[pieces[j][nn[k]]])
            near = owner[tree.query_ball_point(mid, 0.5 * link)]
            if np.all((near == members[i]) | (near == members[j])):
                out.add((i, j))
    return out
