"""Synthetic clouds of single primitives, and what every synthetic cloud shares:
the :class:`SynthCloud` with its ground truth, the seeded random streams, and the
finishing (pose, noise, outliers, shuffle).

Each family samples itself (:attr:`houghcad.families.Family.sampler`, in its own file);
:data:`SAMPLERS` is the live table of those samplers.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..families import SIMPLE
from ..families._sampling import span
from ._poses import SAMPLERS, apply_transform, random_pose, transform_params

Array = np.ndarray

#: The simple families (plane, cylinder, cone, sphere, torus).
FAMILIES: tuple[str, ...] = SIMPLE


@dataclass
class SynthCloud:
    """A synthetic cloud with its ground truth.

    Attributes
    ----------
    points : ndarray of float64, shape (N, 3)
        Point coordinates (world frame, after pose and noise).
    normals : ndarray of float64, shape (N, 3)
        True unit normals of the noise-free surface at each point (outward for solids);
        zeros for outliers.
    labels : ndarray of int64, shape (N,)
        Index into :attr:`primitives`, -1 for outliers.
    primitives : list of dict
        ``{"type": str, "params": dict, ...}`` in world coordinates (see :mod:`houghcad.synth`).
    name : str
        A short description (family or part name and seed).
    sigma : float
        Standard deviation of the Gaussian noise added per coordinate, in world units
        (``noise × diagonal of the noise-free surface points``); 0 for clean clouds.
    """

    points: Array
    normals: Array
    labels: Array
    primitives: list[dict[str, Any]]
    name: str
    sigma: float = 0.0

    def segments(self) -> list[Array]:
        """Indices (int64, sorted) of the points of each primitive, in primitive order."""
        return [np.flatnonzero(self.labels == k).astype(np.int64) for k in range(len(self.primitives))]

    def diagonal(self) -> float:
        """Diagonal of the axis-aligned bounding box of all points (world units)."""
        if len(self.points) == 0:
            return 0.0
        return float(np.linalg.norm(self.points.max(axis=0) - self.points.min(axis=0)))


def sample_family(name: str, rng: np.random.Generator, n: int, **shape: Any) -> tuple[Array, Array]:
    """Sample ``n`` points of family ``name`` in its local frame: ``SAMPLERS[name](rng, n, **shape)``."""
    try:
        sampler = SAMPLERS[name]
    except KeyError:
        raise ValueError(f"unknown family {name!r}; known: {sorted(SAMPLERS)}") from None
    return sampler(rng, n, **shape)


@dataclass
class _Streams:
    shape: np.random.Generator
    sample: np.random.Generator
    pose: np.random.Generator
    noise: np.random.Generator
    outliers: np.random.Generator
    perm: np.random.Generator

    @classmethod
    def from_seed(cls, seed: int, salt: str) -> "_Streams":
        """Independent child generators of ``seed``; ``salt`` (family or part name) decorrelates
        different generators called with the same seed."""
        kids = np.random.SeedSequence([int(seed), zlib.crc32(salt.encode())]).spawn(6)
        return cls(*[np.random.default_rng(k) for k in kids])


def _bbox_diag(p: Array) -> float:
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) if len(p) else 0.0


def _check_fraction(name: str, x: float, upper: float = 1.0) -> None:
    if not 0.0 <= x < upper:
        raise ValueError(f"{name} must be in [0, {upper}), got {x!r}")


def _finish(
    st: _Streams,
    pts: Array,
    nrm: Array,
    labels: Array,
    prims: list[dict[str, Any]],
    name: str,
    noise: float,
    outliers: float,
    pose: bool,
    scale: float | None,
    extent: float,
) -> SynthCloud:
    """Pose (all of points, normals, params), then noise, then outliers, then shuffle.

    ``extent`` (units) sizes the random translation; it must not depend on ``missing``/``noise``
    so that those options leave the pose unchanged.
    """
    if noise < 0:
        raise ValueError(f"noise must be ≥ 0, got {noise!r}")
    _check_fraction("outliers", outliers)
    if pose or scale is not None:
        R, t, s = random_pose(st.pose, scale, extent=extent)
        if not pose:
            R, t = np.eye(3), np.zeros(3)
        pts, nrm = apply_transform(pts, nrm, R, t, s)
        prims = [{**p, "params": transform_params(p["type"], p["params"], R, t, s)} for p in prims]
    diag = _bbox_diag(pts)
    sigma = float(noise) * diag
    if sigma > 0:
        pts = pts + st.noise.normal(0.0, sigma, pts.shape)
    if outliers > 0:
        n_out = int(round(outliers / (1.0 - outliers) * len(pts)))
        lo, hi = pts.min(axis=0) - 0.1 * diag, pts.max(axis=0) + 0.1 * diag
        out = lo + (hi - lo) * st.outliers.random((n_out, 3))
        pts = np.vstack([pts, out])
        nrm = np.vstack([nrm, np.zeros((n_out, 3))])
        labels = np.concatenate([labels, np.full(n_out, -1, np.int64)])
    perm = st.perm.permutation(len(pts))
    return SynthCloud(
        points=np.ascontiguousarray(pts[perm], dtype=np.float64),
        normals=np.ascontiguousarray(nrm[perm], dtype=np.float64),
        labels=labels[perm].astype(np.int64),
        primitives=prims,
        name=name,
        sigma=sigma,
    )


def single(
    family: str,
    seed: int = 0,
    n_points: int = 4000,
    noise: float = 0.0,
    outliers: float = 0.0,
    missing: float = 0.0,
    pose: bool = True,
    scale: float | None = None,
) -> SynthCloud:
    """One primitive of ``family`` with random shape parameters.

    Parameters
    ----------
    family : one of :data:`SAMPLERS` (``FAMILIES`` and any added later)
    seed : int
    n_points : int
        Surface points sampled before ``missing`` is cut away.
    noise : float
        Gaussian σ per coordinate (isotropic 3-D noise) as a fraction of the bounding-box diagonal
        of the noise-free surface points; the absolute σ is stored in ``SynthCloud.sigma``.
    outliers : float in [0, 1)
        Fraction of the *final* cloud made of uniform random points in the bounding box inflated
        by 10 % of its diagonal on every side (label -1, normal 0).
    missing : float in [0, 1)
        Fraction of the surface cut away as one contiguous region: the points beyond a plane of
        random orientation, placed so that exactly ``round(missing · n_points)`` points go.
    pose : bool
        Random rotation, translation and scale (see :func:`random_pose`); otherwise the local
        standard frame (axis z, centre / apex at the origin).
    scale : float, optional
        Fixed scale factor (applied even when ``pose`` is False).

    Shapes (local frame, before scale): plane rectangle or ellipse with sides 0.6–1.4; cylinder
    radius 0.4–1, height 1–3 × radius, full or partial; cone half-angle 15°–60°, radius 0.6–1.2 at
    the wide end, cut at 10–50 % of the length from the apex; sphere radius 0.5–1.2, full or a
    cap; torus minor/major 0.2–0.5, full or partial in either angle.
    """
    if family not in SAMPLERS:
        raise ValueError(f"unknown family {family!r}; known: {sorted(SAMPLERS)}")
    _check_fraction("missing", missing)
    st = _Streams.from_seed(seed, family)
    spec = SAMPLERS[family]
    shape = spec.random_shape(st.shape)
    pts, nrm = spec.sample(st.sample, int(n_points), **shape)
    extent = _bbox_diag(pts)
    if missing > 0:
        d = st.shape.standard_normal(3)
        d /= np.linalg.norm(d)
        n_keep = len(pts) - int(round(missing * len(pts)))
        keep = np.sort(np.argsort(pts @ d, kind="stable")[:n_keep])
        pts, nrm = pts[keep], nrm[keep]
    prims = [{"type": family, "params": spec.local_params(**shape), "name": family}]
    labels = np.zeros(len(pts), np.int64)
    return _finish(st, pts, nrm, labels, prims, f"{family}-{seed}", noise, outliers, pose, scale, extent)


# --------------------------------------------------------------------------------------------
# User-defined parametric families: area-uniform samples of any x(u, v), y(u, v), z(u, v)
# --------------------------------------------------------------------------------------------


def sample_parametric(
    fx: Callable[[Array, Array], Array],
    fy: Callable[[Array, Array], Array],
    fz: Callable[[Array, Array], Array],
    u_range: tuple[float, float],
    v_range: tuple[float, float],
    n: int,
    rng: np.random.Generator,
    grid: int = 256,
) -> tuple[Array, Array]:
    """Uniform points (by area) on the patch ``(fx, fy, fz)(u, v)``, ``(u, v)`` in the ranges.

    ``fx, fy, fz`` are numpy-vectorised functions of (u, v). A ``grid × grid`` partition of the
    (u, v) rectangle is weighted by the area element ``|X_u × X_v|`` at the cell centres (central
    differences); cells are drawn with that probability and the point is uniform in its cell, so
    the density is uniform up to the area element's variation within one cell.

    Returns points (n, 3) and unit normals (n, 3) (``X_u × X_v``; zero where it vanishes).
    """
    u0, u1 = span(u_range)
    v0, v1 = span(v_range)

    def X(u: Array, v: Array) -> Array:
        return np.stack([np.broadcast_to(np.asarray(f(u, v), float), np.shape(u)) for f in (fx, fy, fz)], axis=-1)

    def cross(u: Array, v: Array) -> Array:
        hu, hv = 1e-6 * max(1.0, abs(u0), abs(u1)), 1e-6 * max(1.0, abs(v0), abs(v1))
        xu = (X(u + hu, v) - X(u - hu, v)) / (2 * hu)
        xv = (X(u, v + hv) - X(u, v - hv)) / (2 * hv)
        return np.cross(xu, xv)

    du, dv = (u1 - u0) / grid, (v1 - v0) / grid
    cu, cv = np.meshgrid(u0 + du * (np.arange(grid) + 0.5), v0 + dv * (np.arange(grid) + 0.5), indexing="ij")
    w = np.linalg.norm(cross(cu.ravel(), cv.ravel()), axis=1)
    w = np.where(np.isfinite(w), w, 0.0)
    if not w.sum() > 0:
        raise ValueError("the parametric patch has zero area")
    cell = rng.choice(w.size, size=int(n), p=w / w.sum())
    u = cu.ravel()[cell] + du * (rng.random(int(n)) - 0.5)
    v = cv.ravel()[cell] + dv * (rng.random(int(n)) - 0.5)
    c = cross(u, v)
    ln = np.linalg.norm(c, axis=1, keepdims=True)
    return X(u, v), np.where(ln > 0, c / np.where(ln > 0, ln, 1.0), 0.0)
