"""Accumulators, voting and persistent peaks (paper §5.2).

An accumulator ``H`` is a regular grid over a box ``T`` of the parameter space.
Every point votes for the cells its sampled Hough transform Γ_P crosses; a
point votes at most once per cell. Peaks are the local maxima of ``H`` whose
0-dimensional topological persistence (superlevel-set filtration) exceeds a
fraction of ``max H``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kernels import kernel
from .normals import tree_query


@dataclass(frozen=True)
class Grid:
    """A discretised box ``T`` of a parameter space.

    Attributes
    ----------
    lower, upper : tuple of float, length d
        Bounds of the box (cell edges), in the units of each parameter.
    bins : tuple of int, length d
        Number of cells per dimension.
    wrap : tuple of bool, length d
        Whether a dimension is periodic (angles).
    """

    lower: tuple[float, ...]
    upper: tuple[float, ...]
    bins: tuple[int, ...]
    wrap: tuple[bool, ...] | None = None

    @property
    def ndim(self) -> int:
        return len(self.bins)

    @property
    def width(self) -> np.ndarray:
        """Cell width per dimension, shape (d,)."""
        return (np.asarray(self.upper) - np.asarray(self.lower)) / np.asarray(self.bins)

    def centers(self, dim: int) -> np.ndarray:
        """Cell centres along one dimension, shape (bins[dim],)."""
        w = (self.upper[dim] - self.lower[dim]) / self.bins[dim]
        return self.lower[dim] + w * (np.arange(self.bins[dim]) + 0.5)

    def cell_center(self, flat: np.ndarray) -> np.ndarray:
        """Parameter values of flat cell indices, shape (k, d)."""
        idx = np.stack(np.unravel_index(np.asarray(flat), self.bins), axis=-1)
        return np.asarray(self.lower) + (idx + 0.5) * self.width

    def cell_index(self, values: np.ndarray) -> np.ndarray:
        """Flat cell index of parameter vectors ``values`` (k, d); -1 outside T."""
        values = np.atleast_2d(values)
        with np.errstate(invalid="ignore"):
            x = np.floor((values - np.asarray(self.lower)) / self.width)
        # NaN, inf and values beyond int64 fall outside, as in accumulate.
        finite = np.all(np.abs(x) < 2.0 ** 62, axis=1)
        idx = np.where(finite[:, None], x, -1.0).astype(np.int64)
        bins = np.asarray(self.bins)
        wrap = np.asarray(self.wrap if self.wrap is not None else (False,) * self.ndim)
        idx = np.where(wrap, np.mod(idx, bins), idx)
        ok = finite & np.all((idx >= 0) & (idx < bins), axis=1)
        flat = np.full(len(values), -1, dtype=np.int64)
        if ok.any():
            flat[ok] = np.ravel_multi_index(tuple(idx[ok].T), self.bins)
        return flat


def accumulate(grid: Grid, voter: np.ndarray, values: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Fill an accumulator from samples of the Hough transforms Γ_P.

    Parameters
    ----------
    grid : Grid
    voter : ndarray of int, shape (k,)
        Index of the point that produced each sample.
    values : ndarray, shape (k, d)
        Parameter vectors sampled on Γ_P.
    weights : ndarray, shape (k,), optional
        Vote weight of each sample (default 1).

    Returns
    -------
    H : ndarray of float64, shape ``grid.bins``
        Each point adds its weight at most once to each cell it crosses.
    """
    values = np.ascontiguousarray(np.atleast_2d(values), dtype=np.float64)
    voter = np.ascontiguousarray(voter, dtype=np.int64)
    wrap = grid.wrap if grid.wrap is not None else (False,) * grid.ndim
    w = np.ones(0) if weights is None else np.ascontiguousarray(weights, dtype=np.float64)
    H = np.zeros(int(np.prod(grid.bins)), np.float64)
    if len(voter):
        args = (voter, values, np.asarray(grid.lower, np.float64), grid.width.astype(np.float64),
                np.asarray(grid.bins, np.int64), np.asarray(wrap, np.bool_), w)
        # Samples come grouped by point from every Γ_P sampler; otherwise order them by point,
        # stably (the first sample of a point in a cell carries its weight).
        if not _vote(*args, np.zeros(0, np.int64), H):
            H[:] = 0.0
            _vote(*args, np.argsort(voter, kind="stable"), H)
    return H.reshape(grid.bins)


@kernel(inline="always")
def _bin(v, lower, width, bins, wrap):
    """The bin of value ``v`` along one axis of a grid (from ``lower``, ``width`` wide, ``bins``
    of them, cyclic when ``wrap``), or -1 when it falls outside (NaN and inf included): the
    one binning rule of :func:`_vote` and :func:`_line_vote`. A grid too narrow to differ from its
    lower corner in float64 (a cluster a rounding step wide, far from the origin) has cells of
    width 0: nothing falls in them."""
    if not width > 0.0:
        return np.int64(-1)
    x = np.floor((v - lower) / width)
    if not (abs(x) < 2.0 ** 62):  # NaN, inf, or far outside
        return np.int64(-1)
    c = np.int64(x)
    if wrap:
        return c % bins
    return c if 0 <= c < bins else np.int64(-1)


# Voting by hand in numba rather than numpy's unique on (point, cell) keys: that sorted every
# sample and held several (k, d) index arrays, the bulk of a round's time and memory on big clouds.
@kernel("i8[::1], f8[:, ::1], f8[::1], f8[::1], i8[::1], b1[::1], f8[::1], i8[::1], f8[::1]")
def _vote(voter, values, lower, width, bins, wrap, weights, order, H):
    """Add each sample's weight (1 when ``weights`` is empty) to its cell of the flat
    accumulator H, once per (point, cell): samples are taken in ``order`` (when given, else as
    they come), and a cell remembers the last point that voted in it. Returns False, leaving H
    partly filled, when the points' indices decrease along that order."""
    ncell = H.size
    stamp = np.full(ncell, -1, np.int64)
    d = values.shape[1]
    last = -1
    for t in range(voter.size):
        i = order[t] if order.size else t
        if voter[i] < last:
            return False
        last = voter[i]
        flat = 0
        for j in range(d):
            c = _bin(values[i, j], lower[j], width[j], bins[j], wrap[j])
            if c < 0:
                break
            flat = flat * bins[j] + c
        if c < 0:
            continue
        # Voters are non-negative point indices, so the stamp's -1 is never a voter; a point's
        # samples are consecutive, so an older stamp means this point has not voted here.
        if stamp[flat] != voter[i]:
            stamp[flat] = voter[i]
            H[flat] += weights[i] if weights.size else 1.0
    return True


@kernel()
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@kernel()
def _merge(parent, values, c, nb, v, peaks, pers, npk):
    """Union of the components of cells c and nb at level v: the younger
    (lower peak) dies, its persistence recorded. Returns the peak count."""
    r1 = _find(parent, c)
    r2 = _find(parent, nb)
    if r1 == r2:
        return npk
    if values[r1] > values[r2] or (values[r1] == values[r2] and r1 < r2):
        hi, lo = r1, r2
    else:
        hi, lo = r2, r1
    if lo != c:
        peaks[npk] = lo
        pers[npk] = values[lo] - v
        npk += 1
    parent[lo] = hi
    return npk


@kernel()
def _survivors(values, order, parent, peaks, pers, npk):
    """Components alive at the lowest level: persistence = their peak value. ``order`` holds the
    cells above zero, highest first."""
    for t in range(order.size):
        c = order[t]
        if parent[c] == c:
            peaks[npk] = c
            pers[npk] = values[c]
            npk += 1
    return peaks[:npk], pers[:npk]


@kernel(inline="always")
def _sweep_order(values):
    """The cells (flat indices) above zero, highest first, ties by cell index. Only those enter
    a sweep: most of a 3-D accumulator is empty, and sorting every cell was most of its time."""
    pos = np.nonzero(values > 0)[0]
    return pos[np.argsort(-values[pos], kind="mergesort")]


@kernel("f8[::1], i8[::1], b1[::1], i8[:, ::1]")
def _persistence_grid(values: np.ndarray, shape: np.ndarray, wrap: np.ndarray, offsets: np.ndarray):
    """0-dimensional persistence of the superlevel sets of a grid function.

    Hand-written because no library offers union-find persistence on an
    n-D grid with periodic dimensions; numba because it is a sequential sweep.
    Returns (peak flat index, persistence) for every local maximum.
    """
    n = values.size
    ndim = shape.size
    order = _sweep_order(values)
    parent = np.full(n, -1, dtype=np.int64)
    peaks = np.empty(n, dtype=np.int64)
    pers = np.empty(n, dtype=np.float64)
    npk = 0
    coord = np.empty(ndim, dtype=np.int64)
    strides = np.ones(ndim, dtype=np.int64)
    for d in range(ndim - 2, -1, -1):
        strides[d] = strides[d + 1] * shape[d + 1]
    for t in range(order.size):
        c = order[t]
        v = values[c]
        parent[c] = c
        rem = c
        for d in range(ndim):
            coord[d] = rem // strides[d]
            rem = rem % strides[d]
        for o in range(offsets.shape[0]):
            nb = 0
            ok = True
            for d in range(ndim):
                x = coord[d] + offsets[o, d]
                if x < 0 or x >= shape[d]:
                    if wrap[d]:
                        x = x % shape[d]
                    else:
                        ok = False
                        break
                nb += x * strides[d]
            if not ok or parent[nb] < 0:
                continue
            npk = _merge(parent, values, c, nb, v, peaks, pers, npk)
    return _survivors(values, order, parent, peaks, pers, npk)


def _offsets(ndim: int) -> np.ndarray:
    g = np.stack(np.meshgrid(*([np.array([-1, 0, 1])] * ndim), indexing="ij"), -1).reshape(-1, ndim)
    return g[np.any(g != 0, axis=1)].astype(np.int64)


def persistent_peaks(H: np.ndarray, min_persistence: float = 0.1, wrap=None, max_peaks: int | None = None):
    """Local maxima of ``H`` with persistence above ``min_persistence * max(H)``.

    Parameters
    ----------
    H : ndarray, any shape
        Accumulator.
    min_persistence : float
        Threshold as a fraction of ``H.max()`` (the paper uses 0.1).
    wrap : sequence of bool, optional
        Periodic dimensions.
    max_peaks : int, optional
        Keep at most this many, most persistent first.

    Returns
    -------
    flat : ndarray of int64, shape (k,)
        Flat indices of the peak cells, most persistent first.
    persistence : ndarray of float64, shape (k,)
    """
    H = np.asarray(H, dtype=np.float64)
    top = H.max() if H.size else 0.0
    if top <= 0:
        return np.zeros(0, np.int64), np.zeros(0)
    wrap_arr = np.zeros(H.ndim, dtype=np.bool_) if wrap is None else np.asarray(wrap, dtype=np.bool_)
    peaks, pers = _persistence_grid(H.ravel(), np.asarray(H.shape, np.int64), wrap_arr, _offsets(H.ndim))
    keep = pers > min_persistence * top
    peaks, pers = peaks[keep], pers[keep]
    order = np.lexsort((peaks, -pers))
    peaks, pers = peaks[order], pers[order]
    if max_peaks is not None:
        peaks, pers = peaks[:max_peaks], pers[:max_peaks]
    return peaks, pers


def smooth(H: np.ndarray, wrap=None) -> np.ndarray:
    """Light [1 2 1] smoothing per dimension, so that votes split across cell
    borders still form one peak."""
    out = np.asarray(H, dtype=np.float64)
    for d in range(out.ndim):
        w = bool(wrap[d]) if wrap is not None else False
        if out.shape[d] < 3:
            continue
        a = np.roll(out, 1, axis=d)
        b = np.roll(out, -1, axis=d)
        if not w:
            idx0 = [slice(None)] * out.ndim
            idx0[d] = 0
            a[tuple(idx0)] = 0
            idx1 = [slice(None)] * out.ndim
            idx1[d] = -1
            b[tuple(idx1)] = 0
        out = 0.5 * out + 0.25 * (a + b)
    return out


@kernel("f8[::1], i8[::1], i8[::1]")
def _persistence_graph(values: np.ndarray, indptr: np.ndarray, indices: np.ndarray):
    """Same sweep as :func:`_persistence_grid`, on a cell graph (CSR adjacency)."""
    n = values.size
    order = _sweep_order(values)
    parent = np.full(n, -1, dtype=np.int64)
    peaks = np.empty(n, dtype=np.int64)
    pers = np.empty(n, dtype=np.float64)
    npk = 0
    for t in range(order.size):
        c = order[t]
        v = values[c]
        parent[c] = c
        for j in range(indptr[c], indptr[c + 1]):
            nb = indices[j]
            if parent[nb] < 0:
                continue
            npk = _merge(parent, values, c, nb, v, peaks, pers, npk)
    return _survivors(values, order, parent, peaks, pers, npk)


class DirectionAccumulator:
    """Accumulator over unoriented directions (the half-sphere).

    Cells are the points of a Fibonacci lattice on the whole sphere, so that
    cells have near-equal area and no pole or seam; a direction votes for the
    cell nearest to it and to its antipode, and peaks are read on the z ≥ 0
    half. Neighbourhoods for the persistence come from a KD-tree.

    Parameters
    ----------
    n_cells : int
        Number of cells on the whole sphere (4000 → about 3.2° apart).
    """

    def __init__(self, n_cells: int = 4000):
        from scipy.sparse import csr_matrix
        from scipy.spatial import cKDTree

        i = np.arange(n_cells) + 0.5
        z = 1.0 - 2.0 * i / n_cells
        phi = np.pi * (1.0 + 5**0.5) * i
        r = np.sqrt(1.0 - z * z)
        self.cells = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
        self.tree = cKDTree(self.cells)
        _, nb = self.tree.query(self.cells, k=9)
        rows = np.repeat(np.arange(n_cells), 8)
        adj = csr_matrix((np.ones(rows.size), (rows, nb[:, 1:].ravel())), shape=(n_cells, n_cells))
        adj = ((adj + adj.T) > 0).tocsr()
        self.indptr = adj.indptr.astype(np.int64)
        self.indices = adj.indices.astype(np.int64)
        self.n_cells = n_cells

    def vote(self, dirs: np.ndarray, weights: np.ndarray | None = None, workers: int = 1) -> np.ndarray:
        """Accumulator values, shape (n_cells,), from unit directions (k, 3); ``workers``: the
        nearest-cell queries' threads (the result does not depend on them)."""
        _, a = tree_query(self.tree, dirs, workers)
        _, b = tree_query(self.tree, -dirs, workers)
        w = None if weights is None else np.concatenate([weights, weights])
        return np.bincount(np.concatenate([a, b]), weights=w, minlength=self.n_cells).astype(np.float64)

    def smooth(self, H: np.ndarray) -> np.ndarray:
        """Average each cell with its neighbours (votes split between cells)."""
        deg = np.diff(self.indptr)
        s = np.add.reduceat(H[self.indices], self.indptr[:-1]) * (deg > 0)
        return 0.5 * H + 0.5 * s / np.maximum(deg, 1)

    def peaks(self, H: np.ndarray, min_persistence: float = 0.1, max_peaks: int | None = None):
        """Persistent peak directions on the z ≥ 0 half.

        Returns
        -------
        dirs : ndarray, shape (k, 3)
            Unit directions of the peak cells, most persistent first.
        persistence : ndarray, shape (k,)
        """
        top = H.max() if H.size else 0.0
        if top <= 0:
            return np.zeros((0, 3)), np.zeros(0)
        pk, pers = _persistence_graph(H.astype(np.float64), self.indptr, self.indices)
        keep = pers > min_persistence * top
        pk, pers = pk[keep], pers[keep]
        order = np.lexsort((pk, -pers))
        pk, pers = pk[order], pers[order]
        # Every direction votes twice (n and -n): keep one peak per antipodal pair.
        kept: list[int] = []
        for j, c in enumerate(pk):
            d = self.cells[c]
            if all(abs(d @ self.cells[pk[m]]) < np.cos(np.radians(8.0)) for m in kept):
                kept.append(j)
            if max_peaks is not None and len(kept) >= max_peaks:
                break
        dirs = self.cells[pk[kept]]
        dirs = dirs * np.where(dirs[:, 2:3] < 0, -1.0, 1.0)
        return dirs, pers[kept]


_DIRACC: dict[int, DirectionAccumulator] = {}


def direction_accumulator(n_cells: int = 4000) -> DirectionAccumulator:
    """Shared, lazily built :class:`DirectionAccumulator`."""
    if n_cells not in _DIRACC:
        _DIRACC[n_cells] = DirectionAccumulator(n_cells)
    return _DIRACC[n_cells]


def refine_direction(d: np.ndarray, dirs: np.ndarray, max_angle: float, weights: np.ndarray | None = None) -> np.ndarray:
    """Mean of the unoriented ``dirs`` (k, 3) within ``max_angle`` (rad) of ``d``
    (principal eigenvector of their scatter), a refined unit direction."""
    c = np.abs(dirs @ d)
    sel = c >= np.cos(max_angle)
    if sel.sum() < 3:
        return d / np.linalg.norm(d)
    v = dirs[sel]
    w = np.ones(len(v)) if weights is None else weights[sel]
    S = (v * w[:, None]).T @ v
    _, vec = np.linalg.eigh(S)
    out = vec[:, -1]
    return out if out @ d >= 0 else -out


# The samples of each normal line are walked in numba, not materialised: as (n, s, d) arrays
# fed to accumulate they cost 4x the time (a whole-cloud cylinder vote holds 10^7 samples).
@kernel("f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], i8[::1], f8[::1]")
def _line_vote(Q, M, s, lower, width, bins, H):
    """Add 1 to each cell of the flat accumulator H (grid ``lower``, cell ``width``, ``bins``)
    that the samples ``Q[i] + s[k] M[i]`` of point i's normal line fall in, once per (point,
    cell): :func:`accumulate` on those samples, without holding them."""
    n, d = Q.shape
    stamp = np.full(H.size, -1, np.int64)
    for i in range(n):
        for k in range(s.size):
            flat = 0
            for j in range(d):
                c = _bin(Q[i, j] + s[k] * M[i, j], lower[j], width[j], bins[j], False)
                if c < 0:
                    break
                flat = flat * bins[j] + c
            if c >= 0 and stamp[flat] != i:
                stamp[flat] = i
                H[flat] += 1.0


def normal_line_peaks(Q: np.ndarray, M: np.ndarray, lower: np.ndarray, width: float, bins: int, smax: float,
                      persistence: float, min_votes: float, max_peaks: int) -> np.ndarray:
    """Points where many normal lines meet (circle or sphere centres).

    Parameters
    ----------
    Q, M : ndarray, shape (n, d)
        Points and their unit normals (d = 2 or 3).
    lower : ndarray, shape (d,)
        Lower corner of the cubic box voted over; ``width`` its side.
    bins : int
        Cells per side.
    smax : float
        Each point votes at distances up to ``smax`` along its normal line,
        both ways, one sample per cell width.

    Returns
    -------
    ndarray, shape (k, d)
        Persistent peak cell centres with at least ``min_votes`` votes.
    """
    d = Q.shape[1]
    cw = width / bins
    s = np.arange(cw, smax, cw)
    s = np.concatenate([-s, s])
    g = Grid(tuple(lower), tuple(np.asarray(lower) + width), (bins,) * d)
    H = np.zeros(int(np.prod(g.bins)))
    _line_vote(np.ascontiguousarray(Q, np.float64), np.ascontiguousarray(M, np.float64), s,
               np.asarray(g.lower, np.float64), g.width.astype(np.float64), np.asarray(g.bins, np.int64), H)
    H = smooth(H.reshape(g.bins))
    pk, _ = persistent_peaks(H, persistence, max_peaks=max_peaks)
    pk = pk[H.ravel()[pk] >= min_votes]
    return g.cell_center(pk)
