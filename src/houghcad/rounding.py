"""Coordinates rounded coarsely against the point spacing: detected, and warned about.

A scan's coordinates pass through a file format before they reach us: float32 far from the
origin keeps too few digits, a LAS file stores integers times its scale, a text export its
decimals. Rounded to a step near the point spacing, the points snap to rows that no fit undoes.
"""

from __future__ import annotations

import warnings

import numpy as np

from .errors import InputWarning

__all__ = ["COARSE_FLOAT32_SPACINGS", "float32_resolution", "grid_step", "warn_coarse_coordinates"]

#: Float32 rounding of the coordinates, in point spacings, from which a run warns: measured on
#: a synthetic block offset to georeferenced coordinates, DSC 0.974 exact, 0.964 at 0.56
#: spacings (the noise estimate reads the scatter), 0.69 at 1 spacing, 0.14 at 2.
COARSE_FLOAT32_SPACINGS = 0.5


#: Rows of a cloud the checks read at most, evenly spread: a rounding holds on every row.
READ_ROWS = 100_000


def _read_rows(P: np.ndarray) -> np.ndarray:
    """At most :data:`READ_ROWS` rows of ``P`` (n, 3), evenly spread."""
    return P[::max(1, len(P) // READ_ROWS)]


def float32_resolution(points: np.ndarray) -> float:
    """The rounding step (units) of coordinates that went through float32, as a float32 PLY or
    PCD of a scan stores them: the float32 spacing at the largest magnitude of the coarsest axis
    when every coordinate of ``points`` (n, 3) is a float32 value, else 0 (float64 data)."""
    P = np.asarray(points, dtype=np.float64)
    rows = _read_rows(P)  # float64 data fails at once, a scan's rows all pass
    if not len(P) or not np.array_equal(rows.astype(np.float32).astype(np.float64), rows):
        return 0.0
    return float(np.spacing(np.abs(P).max(axis=0).astype(np.float32)).max())


def grid_step(points: np.ndarray, at_least: float = 0.0) -> float:
    """The step (units) of a grid that every coordinate of ``points`` (n, 3) lies on, on every axis
    that varies, when it is at least ``at_least``; else 0. A LAS file stores integers times its
    scale (often 1 mm), a text export its decimals: a grid near the point spacing snaps the surfaces
    into rows that no fit undoes (on a gear at 1 mm against 0.55 mm spacing: 421 segments for 16
    faces, 60 times the time). An axis's step is its smallest gap between distinct values, and it
    counts when 99 % of the values are whole multiples of it away from the smallest.

    Rounding by storage hits every axis, while regular sampling along one axis (scan lines, a
    profiler's stage steps, slices) puts that axis alone on a grid and blurs nothing: so each axis
    that varies must lie on a grid, and the step is the finest of theirs, the grid they all share
    (a sampling axis's steps are whole multiples of the storage's). An axis with a single value (a
    flat part lying in z = const) lies on any grid, so it neither shows nor rules out a rounding
    and the other axes decide."""
    P = np.asarray(points, dtype=np.float64)
    rows = _read_rows(P)  # a grid holds on any rows; random values fail at once
    steps = []
    for v in rows.T:
        u = np.unique(v)
        gaps = np.diff(u)
        gaps = gaps[gaps > 1e-12 * max(float(np.abs(u).max()), 1e-300)]  # float64's own rounding
        if not len(gaps):
            continue  # a constant axis
        q = float(gaps.min())
        if q < at_least:
            return 0.0  # this axis is finer than asked for, so the grid they share is too
        k = (u - u[0]) / q
        if np.mean(np.abs(k - np.round(k)) < 1e-3) < 0.99:
            return 0.0  # an axis off any grid: what grids the others have is sampling, not rounding
        steps.append(q)
    # One varying axis alone is a line along it (refused as collinear): no rounding to tell.
    return min(steps) if len(steps) >= 2 else 0.0


def warn_coarse_coordinates(points: np.ndarray, spacing: float, source: str | None) -> None:
    """Warn when the coordinates are rounded coarsely against the point ``spacing`` (units):
    float32 far from the origin (georeferenced scans) keeps too few digits, and a LAS scale or a
    text export's decimals put them on a grid; either way the points snap to rows that no fit
    can undo."""
    if not spacing > 0:
        return
    where, least = source or "input", COARSE_FLOAT32_SPACINGS * spacing
    step = float32_resolution(points)
    if step >= least:
        warnings.warn(f"{where}: the coordinates are float32 values rounded to {step:.3g} units, "
                      f"{step / spacing:.2g} point spacings, so the surfaces blur; store them as float64 or "
                      "subtract an offset (e.g. the cloud's centre) before saving", InputWarning, stacklevel=3)
        return
    step = grid_step(points, least)
    if step:
        warnings.warn(f"{where}: the coordinates lie on a grid {step:.3g} units apart, {step / spacing:.2g} "
                      "point spacings, so the surfaces blur (and the run is slow); store them with more digits "
                      "(a finer LAS scale, more decimals)", InputWarning, stacklevel=3)
