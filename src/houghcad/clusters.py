"""Dense connected subsets (paper §5.2): the X_i of a candidate's inliers, and the splitting
phase's clusters.

DBSCAN over the points, written here with numba's union-find, and each point's own link
(:meth:`houghcad.context.Context.link_scales`): a sparsely sampled face links at its own spacing.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .kernels import kernel


def dbscan(P: np.ndarray, eps: float, min_samples: int, scale: np.ndarray | None = None) -> np.ndarray:
    """DBSCAN labels (n,) of P (n, 3), -1 for noise: the same labels as
    ``sklearn.cluster.DBSCAN(eps, min_samples=min_samples).fit_predict(P)``.

    With ``scale`` (n,) (:meth:`Context.link_scales`), points i and j are neighbours within
    ``eps * min(|scale[i]|, |scale[j]|)``: a sparsely sampled face links at its own spacing, and
    where it meets a dense one the dense side's link holds. A negative scale marks a point whose
    neighbourhood no surface explains: two such points link within ``eps`` only, so that points
    scattered in space never chain among themselves, while a sparse face's points beside a crease
    still link to the face. Without it, or with every scale 1, the labels are scikit-learn's.

    Written here because the recognition clusters thousands of small inlier
    sets per cloud, where scikit-learn's per-call validation and neighbour
    lists cost several times the clustering itself. Core points have at least
    ``min_samples`` points within ``eps`` (themselves included); clusters are
    the connected components of the core points, numbered by their lowest
    point index (scikit-learn's discovery order); a border point joins the
    first discovered cluster among its core neighbours'.
    """
    n = len(P)
    if n == 0:
        return np.empty(0, np.int64)
    pairs = _pairs(P, eps, scale)
    deg = np.bincount(pairs.ravel(), minlength=n) + 1
    core = deg >= min_samples
    both = core[pairs[:, 0]] & core[pairs[:, 1]]
    comp = _components(n, pairs[both])
    lab = np.full(n, -1, np.int64)
    if not core.any():
        return lab
    # Number the components of core points by their lowest index.
    first = np.full(comp.max() + 1, n, np.int64)
    ci = np.flatnonzero(core)
    np.minimum.at(first, comp[ci], ci)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    lab[ci] = rank[comp[ci]]
    # Border points: the lowest-numbered cluster among their core neighbours.
    half = pairs[~both]
    a, b = np.r_[half[:, 0], half[:, 1]], np.r_[half[:, 1], half[:, 0]]
    m = ~core[a] & core[b]
    none = np.iinfo(np.int64).max
    cand = np.full(n, none)
    np.minimum.at(cand, a[m], lab[b[m]])
    border = cand < none
    lab[border] = cand[border]
    return lab


def _pairs(P: np.ndarray, eps: float, scale: np.ndarray | None) -> np.ndarray:
    """Index pairs (m, 2) of the points of P (n, 3) within ``eps`` times the smaller of their
    ``|scale|`` (n,), unless both scales are negative, or within ``eps`` when there is no scale
    (see :func:`dbscan`).

    A pair farther than ``eps`` has both scales above 1 in size, so only those points are searched
    farther: on a cloud with a few sparse regions or scattered outliers, one search of all points
    at the largest scale would return the dense faces' pairs many times over."""
    pairs = cKDTree(P).query_pairs(eps, output_type="ndarray")
    size = np.abs(scale) if scale is not None else None
    far = np.flatnonzero(size > 1.0) if size is not None else np.empty(0, np.int64)
    if len(far) < 2:
        return pairs
    sub = cKDTree(P[far]).query_pairs(eps * float(size[far].max()), output_type="ndarray")
    i, j = far[sub[:, 0]], far[sub[:, 1]]
    d = np.linalg.norm(P[i] - P[j], axis=1)
    keep = (d <= eps * np.minimum(size[i], size[j])) & ((scale[i] > 0) | (scale[j] > 0))
    # The union: the pairs within eps are in both searches.
    return np.unique(np.vstack([pairs, np.c_[i[keep], j[keep]]]), axis=0)


# Union-find in numba instead of scipy's connected_components: the recognition clusters thousands
# of small inlier sets per cloud, and building and validating a sparse matrix for each cost more
# than the components themselves. Components are numbered by their lowest point afterwards, so
# the labels are the same whichever way they are found.
@kernel("i8, i8[:, ::1]")
def _components(n: int, pairs: np.ndarray) -> np.ndarray:
    """A component id (its root point, int64 (n,)) per point of the undirected graph on n
    points with the edges ``pairs`` (m, 2)."""
    root = np.arange(n)
    for e in range(pairs.shape[0]):
        a, b = pairs[e, 0], pairs[e, 1]
        while root[a] != a:
            root[a] = root[root[a]]
            a = root[a]
        while root[b] != b:
            root[b] = root[root[b]]
            b = root[b]
        if a != b:
            if a < b:
                root[b] = a
            else:
                root[a] = b
    for i in range(n):
        r = i
        while root[r] != r:
            r = root[r]
        root[i] = r
    return root


def dense_subsets(P: np.ndarray, link: float, min_points: int, min_samples: int,
                  scale: np.ndarray | None = None) -> list[np.ndarray]:
    """Connected dense subsets of P (n, 3): DBSCAN components (core points
    with ``min_samples`` neighbours within ``link``, scaled per point by ``scale`` (n,) as in
    :func:`dbscan`) of at least min_points."""
    if len(P) < min_points:
        return []
    lab = dbscan(P, link, min_samples, scale)
    ok = lab >= 0
    if not ok.any():
        return []
    counts = np.bincount(lab[ok])
    order = np.argsort(lab, kind="stable")
    lab_sorted = lab[order]
    out = []
    for k in np.flatnonzero(counts >= min_points):
        lo, hi = np.searchsorted(lab_sorted, [k, k + 1])
        out.append(np.sort(order[lo:hi]))
    return out
