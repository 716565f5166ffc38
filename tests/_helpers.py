"""Helpers shared by the tests of the pipeline modules."""

from __future__ import annotations

import numpy as np

from houghcad.context import Context
from houghcad.families import REGISTRY
from houghcad.families.base import Primitive
from houghcad.pipeline import Segmenter
from houghcad.preprocess import preprocess
from houghcad.state import Candidate, Segmentation, mean_fitting_error


def context(points: np.ndarray, seed: int = 0, **options) -> Context:
    """The run context ``Segmenter(**options)`` derives for ``points`` (n, 3)."""
    pre = preprocess(points, seed=seed)
    return Segmenter(seed=seed, **options)._context(pre, len(points))


def seed_plane(P: np.ndarray) -> Primitive:
    """The PCA plane of points P (n, 3)."""
    c = P.mean(axis=0)
    n = np.linalg.eigh(np.cov((P - c).T))[1][:, 0]
    return Primitive("plane", {"normal": n, "offset": float(n @ c), "point": c})


def plane_candidate(ctx: Context, idx: np.ndarray) -> Candidate:
    """A plane fitted to the points ``idx`` of the context's cloud, as a candidate."""
    fam = REGISTRY["plane"]
    P = ctx.pre.points[idx]
    prim = fam.fit(seed_plane(P), P, ctx.pre.normals[idx])
    d = fam.distance(prim, P)
    return Candidate(fam, prim, idx, mean_fitting_error(d, P), d)


def state_before(points: np.ndarray, pass_name: str, **options) -> tuple[Segmentation | None, Context]:
    """The state just before the pass ``pass_name`` of a run on ``points`` (None
    when the pass did not run; an empty state for the first), and its context."""
    states: dict[str, Segmentation] = {}
    last = [Segmentation(len(points))]

    def trace(step: int, name: str, seg: Segmentation) -> None:
        states.setdefault(name, last[0])
        last[0] = seg.copy()

    fitted = Segmenter(trace=trace, **options).fit(points)
    return states.get(pass_name), fitted.context_


def wide_cylinder(ctx: Context, flat: Candidate) -> tuple[Primitive, np.ndarray]:
    """A cylinder of radius 50 diagonals tangent to the plane segment ``flat``
    at its centroid (flat within any noise over the cloud), and the unit
    vector across its axis in the plane."""
    P = ctx.pre.points
    n = flat.prim.params["normal"]
    e = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    e /= np.linalg.norm(e)
    c0 = P.mean(axis=0)
    R = 50.0 * ctx.pre.diagonal
    foot = c0 - (c0 @ n - flat.prim.params["offset"]) * n
    return Primitive("cylinder", {"axis_point": foot + R * n, "axis": e, "radius": R}), np.cross(n, e)


def rim_rows(flat_land: bool) -> tuple[np.ndarray, list[np.ndarray]]:
    """Exact samples (spacing 0.5) of the row of points at radius 10 around the z axis, and of the
    two discs of faces beside it whose boundary rows run along it. A rim (``flat_land`` False):
    the row at z = 0.5 between the discs z = 0 and z = 1 (radius 10 each: their edge rows are
    the rim's own edge rows). A flat land: the row at z = 0 between the disc z = 0 inside
    (radius 9.5) and the ring z = 0 outside (radii 10.5 to 12). Returns the points and the
    index arrays of the row and of the two neighbours."""
    s = 0.5

    def rings(radii, z):
        return np.concatenate([np.c_[r * np.cos(t), r * np.sin(t), np.full(len(t), z)]
                               for r in radii
                               for t in [np.linspace(0, 2 * np.pi, max(int(2 * np.pi * r / s), 1), endpoint=False)]])

    if flat_land:
        row, a, b = rings([10.0], 0.0), rings(np.arange(0.0, 9.75, s), 0.0), rings(np.arange(10.5, 12.25, s), 0.0)
    else:
        row, a, b = rings([10.0], 0.5), rings(np.arange(0.0, 10.25, s), 0.0), rings(np.arange(0.0, 10.25, s), 1.0)
    pts = np.r_[row, a, b]
    ends = np.cumsum([0, len(row), len(a), len(b)])
    return pts, [np.arange(ends[i], ends[i + 1]) for i in range(3)]
