"""Per-point normal estimators on k-neighbourhoods (used by :mod:`houghcad.preprocess`).

- :func:`pca_normals`: the covariance's smallest eigenvector, the default;
- :func:`quadric_residuals`: how far a neighbourhood is from any smooth surface (creases);
- :func:`voting_normals`: normals voted by triples of neighbours (on creases, and ``method="voting"``).
"""

from __future__ import annotations

import threading
from concurrent.futures import CancelledError, ThreadPoolExecutor
from typing import TYPE_CHECKING, Any, Callable, TypeVar

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from .kernels import kernel

T = TypeVar("T")
#: Rows per chunk of the per-point fits: fixed, so that the result does not depend on how
#: many threads share the chunks. Small enough that a cloud of a few thousand points still
#: makes a chunk for each core, and that a chunk's (rows, k, 6) arrays stay in the cache
#: (1024 against 8192: the fits of Fit4CAD's clouds 1.3x faster on one thread, 1.4x on two).
ROWS = 1024
#: Rows per chunk of a threaded KD-tree query (:func:`tree_query`): a query's own set-up costs more
#: than a fit's, and its rows need no cache.
QUERY_ROWS = 8192


def pca_normals(points: np.ndarray, neighbors: np.ndarray, workers: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Unoriented normals by PCA of each point's neighbourhood.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    neighbors : ndarray of int, shape (n, k)
        Indices of the k nearest neighbours (the point itself included).
    workers : int
        Threads sharing the chunks of rows (numpy releases the GIL in them).

    Returns
    -------
    normals : ndarray, shape (n, 3), unit
    eigvals : ndarray, shape (n, 3)
        Covariance eigenvalues, ascending (squared length units).
    """
    P = np.ascontiguousarray(points, dtype=np.float64)

    def fit(rows: slice) -> tuple[np.ndarray, np.ndarray]:
        w, v = np.linalg.eigh(_scatter(P, neighbors[rows]) / neighbors.shape[1])
        return v[:, :, 0], w

    parts = by_rows(fit, len(neighbors), workers)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


# By hand in numba: numpy's einsum for the (rows, 3, 3) scatter matrices took most of the
# per-point fits' time. The sums run in numpy's order (the mean over the neighbours, then each
# entry over them in turn), so the matrices are numpy's to the bit. No GIL: threads share rows.
@kernel("f8[:, ::1], i8[:, ::1]", "f8[:, ::1], i8[:, :]", "f8[:, ::1], i4[:, ::1]", nogil=True)
def _scatter(points: np.ndarray, neighbors: np.ndarray) -> np.ndarray:
    """Σ (p − mean)(p − mean)ᵀ over each row's neighbours: (m, 3, 3), from points (n, 3) and
    neighbour indices (m, k)."""
    m, k = neighbors.shape
    out = np.empty((m, 3, 3))
    for r in range(m):
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        for t in range(k):
            p = neighbors[r, t]
            c0 += points[p, 0]
            c1 += points[p, 1]
            c2 += points[p, 2]
        c0 /= k
        c1 /= k
        c2 /= k
        s00 = s01 = s02 = s11 = s12 = s22 = 0.0
        for t in range(k):
            p = neighbors[r, t]
            a0 = points[p, 0] - c0
            a1 = points[p, 1] - c1
            a2 = points[p, 2] - c2
            s00 += a0 * a0
            s01 += a0 * a1
            s02 += a0 * a2
            s11 += a1 * a1
            s12 += a1 * a2
            s22 += a2 * a2
        out[r, 0, 0] = s00
        out[r, 0, 1] = out[r, 1, 0] = s01
        out[r, 0, 2] = out[r, 2, 0] = s02
        out[r, 1, 1] = s11
        out[r, 1, 2] = out[r, 2, 1] = s12
        out[r, 2, 2] = s22
    return out


@kernel("f8[:, ::1], i8[:, ::1], f8[:, :, ::1]", nogil=True)
def _quadric_system(points: np.ndarray, neighbors: np.ndarray, frames: np.ndarray) \
        -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each row's height-field quadric fit in its PCA frame ``frames`` (m, 3, 3), columns the
    axes, the normal first: heights h (m, k), design A (m, k, 6) of the terms x², xy, y², x, y,
    1, normal matrix AᵀA with a 1e-9 trace ridge (m, 6, 6) and Aᵀh (m, 6). Summed in numpy's
    order (see :func:`_scatter`)."""
    m, k = neighbors.shape
    h = np.empty((m, k))
    A = np.empty((m, k, 6))
    M = np.empty((m, 6, 6))
    rhs = np.empty((m, 6))
    u = np.empty(3)
    for r in range(m):
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        for t in range(k):
            p = neighbors[r, t]
            c0 += points[p, 0]
            c1 += points[p, 1]
            c2 += points[p, 2]
        c0 /= k
        c1 /= k
        c2 /= k
        for t in range(k):
            p = neighbors[r, t]
            a0 = points[p, 0] - c0
            a1 = points[p, 1] - c1
            a2 = points[p, 2] - c2
            for j in range(3):
                acc = 0.0
                acc += a0 * frames[r, 0, j]
                acc += a1 * frames[r, 1, j]
                acc += a2 * frames[r, 2, j]
                u[j] = acc
            x, y = u[2], u[1]
            h[r, t] = u[0]
            A[r, t, 0] = x * x
            A[r, t, 1] = x * y
            A[r, t, 2] = y * y
            A[r, t, 3] = x
            A[r, t, 4] = y
            A[r, t, 5] = 1.0
        for i in range(6):
            for j in range(6):
                acc = 0.0
                for t in range(k):
                    acc += A[r, t, i] * A[r, t, j]
                M[r, i, j] = acc
            acc = 0.0
            for t in range(k):
                acc += A[r, t, i] * h[r, t]
            rhs[r, i] = acc
        tr = 0.0
        for i in range(6):
            tr += M[r, i, i]
        ridge = 1e-9 * tr
        for i in range(6):
            M[r, i, i] += ridge
    return h, A, M, rhs


def by_rows(fn: Callable[[slice], T], n: int, workers: int = 1, rows: int = ROWS) -> list[T]:
    """``fn`` over the chunks of ``rows`` consecutive rows of ``n``, on ``workers`` threads, in
    order. The chunks do not depend on ``workers``: neither does the result."""
    chunks = [slice(s, min(s + rows, n)) for s in range(0, n, rows)] or [slice(0, 0)]
    if workers <= 1 or len(chunks) < 2:
        return [fn(c) for c in chunks]
    gate = _Gate()
    ex = ThreadPoolExecutor(min(workers, len(chunks)))
    try:
        futures = [ex.submit(gate.run, fn, c) for c in chunks]
        return [f.result() for f in futures]
    finally:
        ex.shutdown(wait=False, cancel_futures=True)
        gate.close()  # no chunk runs past this
        ex.shutdown(wait=True)  # nor any idle thread: the run forks its workers, which must not copy one


def tree_query(tree: "cKDTree", X: np.ndarray, workers: int = 1, **kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """``tree.query(X, **kwargs)`` on ``workers`` threads of :func:`by_rows`, rows in chunks.

    Why not scipy's own ``workers``: its threads outlive a Ctrl-C that cuts its join short, and
    the interpreter then exits under them (a segmentation fault); the query releases the GIL, so
    ours run as fast, and a query's rows do not depend on each other: the result is the same.
    """
    if workers <= 1 or len(X) <= QUERY_ROWS:
        return tree.query(X, **kwargs)
    parts = by_rows(lambda rows: tree.query(X[rows], **kwargs), len(X), workers, QUERY_ROWS)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


class _Gate:
    """Lets chunks run until closed; closing waits until none is running, even under Ctrl-C,
    which goes on afterwards. Why not the executor's own join: a Ctrl-C can cut it short, and an
    interrupted ``Thread.join`` marks a thread still inside a kernel as stopped (CPython 3.11);
    the interpreter then exits under that thread (a segmentation fault)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._running = 0
        self._closed = False

    def run(self, fn: Callable[[slice], T], rows: slice) -> T:
        with self._cond:
            if self._closed:
                raise CancelledError
            self._running += 1
        try:
            return fn(rows)
        finally:
            with self._cond:
                self._running -= 1
                self._cond.notify_all()

    def close(self) -> None:
        interrupted = False
        with self._cond:
            self._closed = True
            while self._running:
                try:
                    self._cond.wait()
                except KeyboardInterrupt:
                    interrupted = True
        if interrupted:
            raise KeyboardInterrupt


def quadric_residuals(points: np.ndarray, neighbors: np.ndarray, workers: int = 1) -> np.ndarray:
    """RMS residual of a local quadric height-field fit, per point.

    Each neighbourhood is put in its PCA frame and fitted with
    h = a x² + b xy + c y² + d x + e y + f: curvature no longer counts as
    residual, noise still does.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    neighbors : ndarray of int, shape (n, k), k >= 7
    workers : int
        Threads sharing the chunks of rows.

    Returns
    -------
    ndarray, shape (n,)
    """
    P = np.ascontiguousarray(points, dtype=np.float64)

    def fit(rows: slice) -> np.ndarray:
        nbr = neighbors[rows]
        _, v = np.linalg.eigh(_scatter(P, nbr))
        h, A, M, rhs = _quadric_system(P, nbr, v)
        c = np.linalg.solve(M, rhs[..., None])[..., 0]
        r = h - np.einsum("nki,ni->nk", A, c)  # numpy's: its sum over the six terms is vectorised
        return np.sqrt((r**2).mean(axis=1))

    return np.concatenate(by_rows(fit, len(neighbors), workers))


def voting_normals(points: np.ndarray, neighbors: np.ndarray, n_triples: int = 24, angle: float = 10.0,
                   seed: int = 0, chunk: int = 8192, anchored: bool = False, workers: int = 1) -> np.ndarray:
    """Robust unoriented normals by voting (after Raffo et al. 2022).

    Every point draws ``n_triples`` random triples of its neighbours; each
    triple's plane normal is a vote, and the normal is the mean of the votes
    that agree (within ``angle`` degrees) with the most supported one. Near
    sharp edges this picks one side's plane instead of averaging both.

    ``anchored``: every triple is the point itself and two of its
    neighbours. The most supported side is then a plane through the point:
    on a face two or three spacings wide between two wide ones, the point's
    own face, where free triples pick the wide neighbour's plane.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    neighbors : ndarray of int, shape (m, k)
        Neighbours of the m points to estimate; with ``anchored``, column 0
        is the point itself (as a KD-tree query of the points returns it).
    workers : int
        Threads sharing each chunk's votes (the draws stay in one stream, in order: the result
        does not depend on them).

    Returns
    -------
    normals : ndarray, shape (m, 3), unit
    """
    rng = np.random.default_rng(seed)
    n, k = neighbors.shape
    out = np.empty((n, 3))
    cosa = np.cos(np.radians(angle))
    for s in range(0, n, chunk):
        nbr = neighbors[s:s + chunk]
        m = len(nbr)
        # Anchored triples overwrite this draw; it stays so that the random
        # stream, and every clean cloud's crease normals, keep their values.
        pick = rng.integers(0, k, size=(m, n_triples, 3))
        if anchored:
            pick[:, :, 0] = 0
            pick[:, :, 1:] = rng.integers(1, k, size=(m, n_triples, 2))

        def vote(rows: slice, s: int = s, nbr: np.ndarray = nbr, pick: np.ndarray = pick) -> None:
            out[s + rows.start:s + rows.stop] = _voted(points, nbr[rows], pick[rows], cosa)

        by_rows(vote, m, workers)
    return out


def _voted(points: np.ndarray, nbr: np.ndarray, pick: np.ndarray, cosa: float) -> np.ndarray:
    """The voted unit normals (m, 3) of the rows ``nbr`` (m, k) from their triples ``pick``
    (m, t, 3) of neighbour positions; votes agree within the angle of cosine ``cosa``."""
    m, n_triples = pick.shape[:2]
    tri = points[np.take_along_axis(nbr[:, None, :], pick.reshape(m, -1)[:, None, :], axis=2)[:, 0]]
    tri = tri.reshape(m, n_triples, 3, 3)
    nrm = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
    ln = np.linalg.norm(nrm, axis=2)
    ok = ln > 1e-12 * (1 + ln.max(axis=1, keepdims=True))
    nrm = nrm / np.where(ln > 0, ln, 1)[..., None]
    agree = (np.abs(np.einsum("mti,msi->mts", nrm, nrm)) >= cosa) & ok[:, None, :] & ok[:, :, None]
    best = np.argmax(agree.sum(axis=2), axis=1)
    bvec = nrm[np.arange(m), best]
    sgn = np.sign(np.einsum("mti,mi->mt", nrm, bvec))
    sel = agree[np.arange(m), best] * sgn
    v = np.einsum("mt,mti->mi", sel, nrm)
    lv = np.linalg.norm(v, axis=1)
    return v / np.where(lv > 0, lv, 1)[:, None]
