"""Scan rows: a scanner samples along lines (rows) closer than the rows are apart, and a point's
nearest neighbours then lie on its own row. The noise estimate's quadruples
(:func:`houghcad.preprocess._noise_estimate`) assume a point's 3 nearest surround it; on rows
they are built across them."""

from __future__ import annotations

import numpy as np

#: Three neighbours within this angle (degrees) of one line through a point lie on its row
#: (:func:`on_rows`); three random directions do so about 8 % of the time (the Fit4CAD clouds'
#: points at most 13 %, the synthetic parts' 9 %, scans 50-96 %).
ROW_DEG = 30.0
#: Share of points on rows from which the cloud is read as sampled in rows, and each point's
#: quadruple is built across them (:func:`spread_quadruples`); elsewhere a point's 3 nearest
#: surround it, and the quadruples reach no further than they must (built across on every cloud,
#: they span more of a curved face, and an exact sample of a tube read as noisy).
ROWS_SHARE = 0.2
#: The least angle (degrees) between the lines from a point to its quadruple's three neighbours
#: (:func:`spread_quadruples`): no three of the four on one line.
QUADRUPLE_APART_DEG = 40.0


def _directions(x: np.ndarray, points: np.ndarray | slice, nbr: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """Unit directions (m, j, 3) from ``x[points]`` to their neighbours ``nbr`` (m, j), in the
    tangent planes of their normals ``nrm`` (m, 3)."""
    d = (x[nbr] - x[points, None, :]).astype(np.float32)
    d -= np.einsum("ikj,ij->ik", d, nrm)[:, :, None] * nrm[:, None, :]
    d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-30)
    return d


def on_rows(x: np.ndarray, nbr: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """Whether each point's 3 nearest neighbours (of ``nbr`` (n, k), nearest first) lie on one
    line through it, within :data:`ROW_DEG` about its normal ``nrm`` (n, 3), shape (n,): the
    point is on a scan's row, sampled closer along it than the rows are apart."""
    d = _directions(x, slice(None), nbr[:, 1:4], nrm)
    near = np.sin(np.radians(ROW_DEG))
    return np.all([np.linalg.norm(np.cross(d[:, i], d[:, j]), axis=1) <= near
                   for i, j in ((0, 1), (0, 2), (1, 2))], axis=0)


def spread_quadruples(x: np.ndarray, nbr: np.ndarray, nrm: np.ndarray, rows: int = 100_000) \
        -> tuple[np.ndarray, np.ndarray]:
    """Each point of ``x`` (n, 3) with three neighbours (of ``nbr`` (n, k), nearest first) in
    three directions about its normal ``nrm`` (n, 3) at least :data:`QUADRUPLE_APART_DEG` apart
    as lines: its nearest, the nearest off that line, and the nearest off both. Returns the
    quadruples (n, 4) and whether the point has all three (n,).

    Why not its 3 nearest: along a scan line (points closer along their line than the lines are
    apart) they lie on its line, and three points on a line with a fourth anywhere are
    coplanar, or nearly so with noise along one direction (the normal, the scanner's ray),
    whatever the noise. Rows in chunks of ``rows`` (the offsets take k × 12 bytes a point).
    """
    n = len(x)
    quads, spread = np.empty((n, 4), dtype=nbr.dtype), np.ones(n, dtype=bool)
    quads[:, 0] = np.arange(n)
    off = np.sin(np.radians(QUADRUPLE_APART_DEG))
    for lo in range(0, n, rows):
        r = slice(lo, min(lo + rows, n))
        nb, nz = nbr[r, 1:], nrm[r]
        d = _directions(x, r, nb, nz)
        rr = np.arange(len(nb))
        line_a = d[:, 0]  # the nearest neighbour's direction
        apart_a = np.linalg.norm(np.cross(d, line_a[:, None, :]), axis=2) >= off
        b = apart_a.argmax(axis=1)
        apart_b = np.linalg.norm(np.cross(d, d[rr, b][:, None, :]), axis=2) >= off
        c = (apart_a & apart_b).argmax(axis=1)
        spread[r] = apart_a[rr, b] & apart_a[rr, c] & apart_b[rr, c]
        quads[r, 1], quads[r, 2], quads[r, 3] = nb[:, 0], nb[rr, b], nb[rr, c]
    return quads, spread
