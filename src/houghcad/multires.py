"""Multi-resolution segmentation (our extension, not in the paper): big clouds are recognised on
an even subsample, then every input point is labelled from its subsample neighbours.

Recognition cost grows with the points, but a surface is pinned down long before a scan's
millions of samples: a voxel subsample of about ``max_points`` points, one per occupied voxel,
keeps every face its share of the surface area. After the pipeline has run on it:

1. each input point looks at its ``neighbours`` nearest subsample points; their segments are its
   candidates;
2. it goes to the candidate whose surface is nearest, if that distance is within the subsample's
   removal distance ε and the point's normal, where it can be trusted, agrees with the surface's;
   otherwise it stays unsegmented. Only points whose neighbours disagree (or are partly free)
   need a normal of their own: the others lie inside one segment, whose subsample points passed
   that test already, and take their nearest subsample point's normal;
3. the output then refits every segment on a bounded random sample of all its points and
   computes its MFE on all of them (:func:`houghcad.output.build_segments`).

All work is in chunks of :data:`CHUNK` points (neighbour tables of ``CHUNK x neighbours`` int32,
never ``n x k``), and the KD-tree queries use both cores; the result does not depend on them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from .context import Context
from .parallel import resolve_jobs
from .preprocess import Preprocessed, pca_normals
from .state import Segmentation, surface_distance
from .tolerances import ResolutionTolerances
from .normals import tree_query

__all__ = ["CHUNK", "Subsample", "voxel_keys", "voxel_subsample", "distinct_points", "FullResolution", "propagate",
           "copy_to_twins"]

#: Points handled at once by the propagation and the normal estimate (bounds the temporary tables).
CHUNK = 1 << 18
#: Voxel-size refinements of the subsample: each moves the occupied-voxel count toward the target.
_VOXEL_STEPS = 6
#: Coarse grid (cells along the diagonal) of the first surface-area estimate.
_COARSE_CELLS = 64


@dataclass(frozen=True)
class Subsample:
    """An even subsample of a cloud.

    Attributes
    ----------
    indices : ndarray of int64, shape (m,)
        Sorted indices of the kept points into the input.
    voxel : float
        Edge of the voxels (input units); one point is kept per occupied voxel. 0 for the
        distinct points of a cloud with exact copies (:func:`distinct_points`).
    twin : ndarray of int64, shape (n,), or None
        With copies: each input point's position in ``indices`` (its first occurrence's).
    """

    indices: np.ndarray
    voxel: float
    twin: np.ndarray | None = None


def voxel_keys(points: np.ndarray, lo: np.ndarray, h: float) -> np.ndarray:
    """Voxel key (n,) int64 of each point for voxels of edge h from corner lo."""
    cells = np.floor((points - lo) / h).astype(np.int64)
    dims = cells.max(axis=0) + 1
    return (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]


def voxel_subsample(points: np.ndarray, max_points: int, seed: int = 0) -> Subsample:
    """At most ``max_points`` points of ``points`` (n, 3), one per voxel, evenly over the surface.

    The voxel edge starts from the surface area read on a coarse grid (a surface of area A
    occupies about A / h² voxels of edge h) and is refined until at most ``max_points`` voxels
    are occupied. The point kept in a voxel is drawn with ``seed``.
    """
    lo = points.min(axis=0)
    diag = float(np.linalg.norm(np.ptp(points, axis=0)))
    h0 = diag / _COARSE_CELLS
    area = len(np.unique(voxel_keys(points, lo, h0))) * h0 * h0
    h = float(np.sqrt(area / max_points))
    for _ in range(_VOXEL_STEPS):
        keys = voxel_keys(points, lo, h)
        count = len(np.unique(keys))
        if count <= max_points:
            break
        h *= float(np.sqrt(count / max_points)) * 1.02  # a surface fills voxels as 1 / h²
    else:
        keys = voxel_keys(points, lo, h)
    order = np.random.default_rng(seed).permutation(len(points))
    _, first = np.unique(keys[order], return_index=True)
    return Subsample(indices=np.sort(order[first]).astype(np.int64), voxel=h)


#: A fixed direction with no rational relation between its coordinates: equal projections on it
#: come from equal points (:func:`distinct_points`).
_HASH_DIRECTION = np.array([1.0, 0.7548776662466927, 0.5698402909980532])


def distinct_points(points: np.ndarray) -> Subsample | None:
    """The distinct points of ``points`` (n, 3), first occurrences in input order, with each
    point's twin; None when no point repeats another exactly (the usual case, read in one sort
    of a projection, about 2 ms for 25,000 points).

    Copies add nothing to a surface but break every k-neighbour estimate: a neighbourhood of
    copies has no extent, so the spacing, the noise and the normals read zero (a cloud stored
    twice segmented nothing). Recognition runs on the distinct points; each copy then takes its
    twin's label, normal and part (:func:`copy_to_twins`).
    """
    h = np.ascontiguousarray(points, dtype=np.float64) @ _HASH_DIRECTION
    h.sort()
    if not (h[1:] == h[:-1]).any():
        return None
    _, first, inverse = np.unique(points, axis=0, return_index=True, return_inverse=True)
    if len(first) == len(points):
        return None
    keep = np.sort(first)
    position = np.empty(len(points), dtype=np.int64)
    position[keep] = np.arange(len(keep))
    return Subsample(indices=keep.astype(np.int64), voxel=0.0, twin=position[first[inverse.ravel()]])


@dataclass
class FullResolution:
    """The subsample's segmentation carried to every input point (standard frame).

    Attributes
    ----------
    seg : Segmentation
        Labels (n,) over the input, the subsample's records, parts and groups.
    pre : Preprocessed
        The input in the subsample's standard frame, with normals (n, 3).
    """

    seg: Segmentation
    pre: Preprocessed


def _pca_rows(x: np.ndarray, rows: np.ndarray, tree: cKDTree, k: int, flat: float,
              workers: int) -> tuple[np.ndarray, np.ndarray]:
    """PCA normals (r, 3) of the points ``x[rows]`` from their k nearest neighbours in ``x``, and
    whether each can be trusted (r,): the neighbourhood is flat (surface variation λ0 / Σλ at most
    ``flat``). Across a crease PCA averages the two faces' normals: such a normal says nothing
    about either face."""
    if len(rows) == 0:
        return np.empty((0, 3)), np.empty(0, dtype=bool)
    _, nb = tree_query(tree, x[rows], workers, k=k)
    nrm, ev = pca_normals(x, nb.astype(np.int32), workers=resolve_jobs(workers))
    return nrm, ev[:, 0] <= flat * ev.sum(axis=1)


def propagate(sub: Segmentation, ctx: Context, picked: np.ndarray, points: np.ndarray,
              normals: np.ndarray | None, tol: ResolutionTolerances, workers: int = -1) -> FullResolution:
    """Label every input point from the segmentation ``sub`` of its subsample.

    A point whose subsample neighbours all belong to one segment lies inside it: only its
    distance to that surface is checked, and its normal is its nearest subsample point's (the
    subsample's normals were checked against that surface already). Where the neighbours
    disagree, or some are free, the point may sit on a crease or on a face the subsample did not
    resolve: its own normal is estimated (PCA of its ``normals_neighbours`` nearest input points,
    unless the file has normals) and must agree with the surface's where it can be trusted.

    Parameters
    ----------
    sub : Segmentation
        The final (associated) segmentation of the subsample.
    ctx : Context
        The subsample run's context: its standard frame, KD-tree, ε and normals.
    picked : ndarray of int64, shape (m,)
        The subsample's indices into the input.
    points : ndarray, shape (n, 3)
        The input (world units).
    normals : ndarray, shape (n, 3), optional
        The input's normals (world), else estimated.
    """
    pre = ctx.pre
    T = pre.transform
    x = T.points(points)
    given = None if normals is None else T.dirs(normals)
    full_tree = None if given is not None else cKDTree(x)
    nrm = np.empty_like(x)
    labels = np.full(len(x), -1, dtype=np.int32)
    part_of = _part_ids(sub)
    parts_full = np.full(len(x), -1, dtype=np.int32)
    reach = tol.inlier_epsilons * ctx.epsilon
    cos_min = float(np.cos(np.radians(tol.angle_deg)))
    k = min(tol.neighbours, len(picked))
    for a in range(0, len(x), CHUNK):
        X = x[a:a + CHUNK]
        _, nb = tree_query(pre.tree, X, workers, k=k)
        nb = nb.reshape(len(X), k).astype(np.int32)
        lab = sub.labels[nb]
        N, sure = _chunk_normals(x, a, lab, pre.normals[nb[:, 0]], given, full_tree, tol, workers)
        nrm[a:a + CHUNK] = N
        rows, segs, near = _candidates(lab, nb)
        best = np.full(len(X), np.inf)
        choice = np.full(len(X), -1, dtype=np.int32)
        # Pairs grouped by segment with one sort, not one scan of every pair per segment.
        by_seg = np.argsort(segs, kind="stable")
        present, starts = np.unique(segs[by_seg], return_index=True)
        for s, sel in zip(present.tolist(), np.split(by_seg, starts[1:])):
            r = rows[sel]
            rec = sub.records[s]
            d, claimed = surface_distance(rec, X[r])
            ok = d <= reach
            check = sure[r]
            if check.any():
                cos = np.abs(np.einsum("ij,ij->i", rec.family.surface_normals(rec.prim, X[r[check]]), N[r[check]]))
                ok[check] &= cos >= cos_min
            if claimed is not None:  # a fillet's arc takes the points it claims outright
                ok |= claimed
            better = ok & (d < best[r])
            best[r[better]] = d[better]
            choice[r[better]] = s
            parts_full[a + r[better]] = part_of[near[sel][better]]
        labels[a:a + CHUNK] = choice
    # The subsample's own points keep the labels and normals the pipeline gave them.
    labels[picked] = sub.labels
    parts_full[picked] = part_of
    if given is None:
        nrm[picked] = pre.normals
    return FullResolution(seg=_carried(sub, labels, parts_full),
                          pre=replace(pre, points=x, normals=nrm, crease=None, link_scale=None, off_surface=None))


def _carried(sub: Segmentation, labels: np.ndarray, part: np.ndarray) -> Segmentation:
    """The segments of ``sub`` (records, groups) over the points ``labels`` (n,) assigns them,
    each split into parts by ``part`` (n,): the index of a point's part within its segment."""
    seg = Segmentation(len(labels))
    seg.records = list(sub.records)
    seg.relabel(labels)
    if sub.parts is not None:
        seg.parts = [_pieces(seg.indices(s), part) for s in range(len(sub))]
    seg.groups = list(sub.groups)
    return seg


def _chunk_normals(x: np.ndarray, a: int, lab: np.ndarray, nearest: np.ndarray, given: np.ndarray | None,
                   tree: cKDTree | None, tol: ResolutionTolerances, workers: int) -> tuple[np.ndarray, np.ndarray]:
    """Normals (c, 3) of the chunk of ``x`` from row ``a`` whose subsample neighbours' labels are
    ``lab`` (c, k), and which of them the propagation checks (c,), see :func:`propagate`.
    ``nearest``: the nearest subsample point's normal of each row; ``given``: the file's normals
    (all rows, standard frame) or None; ``tree``: on ``x`` when they are None."""
    c = len(lab)
    inside = (lab[:, 0] >= 0) & (lab == lab[:, :1]).all(axis=1)
    if given is not None:  # the file's: trusted where they have a length
        length = np.linalg.norm(given[a:a + c], axis=1)
        return given[a:a + c] / np.where(length > 0, length, 1.0)[:, None], (length > 0) & ~inside
    N, sure = nearest.copy(), np.zeros(c, dtype=bool)
    edge = np.flatnonzero(~inside)
    assert tree is not None
    N[edge], sure[edge] = _pca_rows(x, a + edge, tree, tol.normals_neighbours, tol.flat_variation, workers)
    return N, sure


def _candidates(labels: np.ndarray, nb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct segments among each row's neighbours: (row, segment, nearest neighbour of that
    segment in the row), one triple per pair. ``labels`` and ``nb`` are (c, k), nearest first."""
    c, k = labels.shape
    order = np.argsort(labels, axis=1, kind="stable")  # equal labels stay nearest first
    lab = np.take_along_axis(labels, order, axis=1)
    first = np.ones((c, k), dtype=bool)
    first[:, 1:] = lab[:, 1:] != lab[:, :-1]
    keep = first & (lab >= 0)
    rows, cols = np.nonzero(keep)
    return rows, lab[rows, cols], nb[rows, order[rows, cols]]


def _part_ids(sub: Segmentation) -> np.ndarray:
    """Index (m,) of each subsample point's part within its segment (0 when unsplit, -1 free)."""
    out = np.where(sub.labels >= 0, 0, -1).astype(np.int32)
    for pieces in sub.parts or []:
        for j, p in enumerate(pieces):
            out[p] = j
    return out


def _pieces(idx: np.ndarray, part: np.ndarray) -> list[np.ndarray]:
    """A segment's points ``idx`` split by their part ids, in part order (no empty piece)."""
    ids = part[idx]
    return [idx[ids == j] for j in np.unique(ids)]


def copy_to_twins(sub: Segmentation, pre: Preprocessed, twin: np.ndarray) -> FullResolution:
    """The segmentation ``sub`` of a cloud's distinct points (:func:`distinct_points`) carried to
    every input point: a copy has its twin's label, part and normal. ``pre``: the distinct
    points' preprocessing; ``twin`` (n,): each input point's distinct point."""
    seg = _carried(sub, sub.labels[twin], _part_ids(sub)[twin])
    x = pre.points[twin]

    def each(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[twin]

    return FullResolution(seg=seg, pre=replace(pre, points=x, normals=pre.normals[twin], tree=cKDTree(x),
                                               crease=each(pre.crease), link_scale=each(pre.link_scale),
                                               off_surface=each(pre.off_surface)))
