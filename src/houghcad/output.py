"""From the final segmentation (standard frame) to a :class:`~houghcad.result.Result`
in the input's coordinates: each segment and part refitted on its own
points, mapped to world units, with its mean fitting error (eq. (1))."""

from __future__ import annotations

from typing import Any

import numpy as np

from .associate import RawGroup, extent
from .context import Context
from .families import Family
from .families.base import Primitive
from .preprocess import Preprocessed, Similarity
from .result import GROUP_KINDS, Group, Part, Segment
from .state import Segmentation, mean_fitting_error

#: Points per final refit: beyond this the parameters no longer move.
#: Final refits may reach any radius below this (standard units).
_ANY_RADIUS = 1e9
MAX_REFIT_POINTS = 4000


def build_segments(seg: Segmentation, groups: list[RawGroup], pre: Preprocessed, points: np.ndarray,
                   seed: int, distances: np.ndarray | None = None,
                   edges: list[list[np.ndarray]] | None = None) -> tuple[list[Segment], list[Group]]:
    """The output segments (largest first) and groups, world coordinates.

    ``seg`` holds the associated segments with their parts
    (:attr:`Segmentation.parts`); ``points`` (n, 3) are the input's.
    ``distances`` (n,), when given, receives each segmented point's distance
    to its segment's fitted surface (world units). ``edges[k][i]``, when given, are the points on
    the boundary curves of segment k's i-th piece (:func:`houghcad.boundaries.edge_points`).
    """
    T = pre.transform
    order = sorted(range(len(seg)), key=lambda k: (-len(seg.indices(k)), int(seg.indices(k)[0])))
    new_id = {k: i for i, k in enumerate(order)}
    check = Context(pre=pre, tau=0, epsilon=0, angle=0, link=0, cell=0, min_points=0, max_radius=_ANY_RADIUS)
    rng = np.random.default_rng(seed)

    def fitted(fam: Family, prim0: Primitive, idx: np.ndarray, fixed: bool = False,
               record: bool = False) -> tuple[dict, float]:
        P, N = pre.points[idx], pre.normals[idx]
        sel = np.arange(len(P)) if len(P) <= MAX_REFIT_POINTS else \
            np.sort(rng.choice(len(P), MAX_REFIT_POINTS, replace=False))
        prim = None if fixed else fam.final_fit(prim0, P[sel], N[sel])
        if prim is None or not fam.valid(prim, check):
            prim = prim0
        d = fam.distance(prim, P) / T.scale
        if record and distances is not None:
            distances[idx] = d
        return plain(fam.to_world(prim, T)), mean_fitting_error(d, points[idx])

    out: list[Segment] = []
    for k in order:
        r, idx = seg.records[k], seg.indices(k)
        params, mfe = fitted(r.family, r.prim, idx, r.fixed, record=True)
        parts = []
        pieces = seg.pieces(k)
        rims = edges[k] if edges is not None else [np.zeros(0, dtype=np.int64)] * len(pieces)
        if len(pieces) > 1:
            for i in sorted(range(len(pieces)), key=lambda i: (-len(pieces[i]), int(pieces[i][0]))):
                pp, pm = fitted(r.family, r.prim, pieces[i])
                parts.append(Part(indices=pieces[i].astype(np.int64), params=pp, mfe=pm,
                                  edges=rims[i].astype(np.int64)))
        desc = world_descriptors(r.family, r.family.descriptors(r.prim), T)
        frame = r.family.frame(r.prim)
        axis = T.inv_dirs(frame.direction) if frame is not None and frame.direction is not None else None
        desc["extent"] = extent(points[idx], axis).tolist()
        rim = np.unique(np.concatenate(rims)).astype(np.int64) if len(rims) else np.zeros(0, dtype=np.int64)
        out.append(Segment(id=len(out), type=r.family.name, indices=idx.astype(np.int64),
                           params=params, mfe=mfe, parts=parts, descriptors=desc, edges=rim))
    out_groups = []
    for g in groups:
        fam = seg.records[g.members[0]].family
        out_groups.append(Group(kind=g.kind, members=sorted(new_id[m] for m in g.members),
                                descriptors=world_descriptors(fam, g.descriptors, T)))
    out_groups.sort(key=lambda g: (GROUP_KINDS.index(g.kind), g.members))
    return out, out_groups


def world_descriptors(fam: Family, d: dict[str, Any], T: Similarity) -> dict[str, Any]:
    """Descriptors from the standard frame to world units and axes."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if k in fam.length_descriptors or k == "extent":
            out[k] = (np.asarray(v, float) / T.scale).tolist() if np.ndim(v) else T.inv_length(v)
        elif k in ("axis", "normal", "mirror_normal"):
            out[k] = T.inv_dirs(np.asarray(v, float)).tolist()
        elif k in ("axis_point", "mirror_point"):
            out[k] = T.inv_points(np.asarray(v, float)).tolist()
        else:
            out[k] = v
    return plain(out)


def plain(x: Any) -> Any:
    """``x`` with numpy scalars and arrays, at any depth, as Python numbers and lists:
    results hold plain values, whatever a family's ``to_world`` returns."""
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x
