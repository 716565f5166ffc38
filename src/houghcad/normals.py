"""Per-point normal estimators on k-neighbourhoods (used by :mod:`houghcad.preprocess`).

- :func:`pca_normals`: the covariance's smallest eigenvector, the default;
- :func:`quadric_residuals`: how far a neighbourhood is from any smooth surface (creases);
- :func:`voting_normals`: normals voted by triples of neighbours (on creases, and ``method="voting"``).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable, TypeVar

import numpy as np

T = TypeVar("T")
#: Rows per chunk of the per-point fits: fixed, so that the result does not depend on how
#: many threads share the chunks (and a chunk's (rows, k, 3) arrays stay a few MB).
ROWS = 8192


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
    def fit(rows: slice) -> tuple[np.ndarray, np.ndarray]:
        nb = points[neighbors[rows]]
        nb = nb - nb.mean(axis=1, keepdims=True)
        w, v = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb) / neighbors.shape[1])
        return v[:, :, 0], w

    parts = by_rows(fit, len(neighbors), workers)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def by_rows(fn: Callable[[slice], T], n: int, workers: int = 1, rows: int = ROWS) -> list[T]:
    """``fn`` over the chunks of ``rows`` consecutive rows of ``n``, on ``workers`` threads, in
    order. The chunks do not depend on ``workers``: neither does the result."""
    chunks = [slice(s, min(s + rows, n)) for s in range(0, n, rows)] or [slice(0, 0)]
    if workers <= 1 or len(chunks) < 2:
        return [fn(c) for c in chunks]
    with ThreadPoolExecutor(min(workers, len(chunks))) as ex:
        return list(ex.map(fn, chunks))


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
    def fit(rows: slice) -> np.ndarray:
        nb = points[neighbors[rows]]
        nb = nb - nb.mean(axis=1, keepdims=True)
        _, v = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
        u = np.einsum("nki,nij->nkj", nb, v)
        h, a, b = u[..., 0], u[..., 2], u[..., 1]
        A = np.stack([a * a, a * b, b * b, a, b, np.ones_like(a)], axis=2)
        M = np.einsum("nki,nkj->nij", A, A)
        ridge = 1e-9 * np.einsum("nii->n", M)[:, None, None] * np.eye(6)
        c = np.linalg.solve(M + ridge, np.einsum("nki,nk->ni", A, h)[..., None])[..., 0]
        r = h - np.einsum("nki,ni->nk", A, c)
        return np.sqrt((r**2).mean(axis=1))

    return np.concatenate(by_rows(fit, len(neighbors), workers))


def voting_normals(points: np.ndarray, neighbors: np.ndarray, n_triples: int = 24, angle: float = 10.0,
                   seed: int = 0, chunk: int = 8192, anchored: bool = False) -> np.ndarray:
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
        out[s:s + m] = v / np.where(lv > 0, lv, 1)[:, None]
    return out
