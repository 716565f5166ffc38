"""Synthetic point clouds with exact ground truth: single primitives and mechanical parts.

This is the one generator behind the tests, the benchmarks and the examples.

Conventions
-----------
Every primitive is described as ``{"type": str, "params": dict}`` (plus a human-readable
``"name"`` for the faces of composite parts) in world coordinates, with the parameter names of
:mod:`houghcad.result` (vectors are lists of 3 floats, angles in radians, lengths in the cloud's
units):

- plane: ``normal`` (unit, outward for parts), ``offset`` (``normal · x = offset``), ``point``
  (the centre of the sampled patch)
- cylinder: ``axis_point`` (centre of the sampled patch on the axis), ``axis`` (unit), ``radius``
- cone: ``apex``, ``axis`` (unit, from the apex into the opening), ``half_angle``
- sphere: ``center``, ``radius``
- torus: ``center``, ``axis`` (unit), ``major_radius``, ``minor_radius``

Surface samplers work in the primitive's *local standard frame*: axis = z, centre / apex at the
origin; they return points and unit normals with a uniform area density (area-correct sampling,
no rejection of points). Composite parts are assembled without a mesh library: every face is
sampled in its own frame as a generous, untrimmed patch of its primitive, placed in the part's
frame, and kept only where it really bounds the part's solid (a vectorised inside test evaluated
just in front of and just behind the surface). That trimming also orients the normals outwards.
All faces use the same density, so the part's density is uniform, and points of one primitive get
one label even when the trimming splits the surface into several pieces.

Randomness: every function takes a seed (or a :class:`numpy.random.Generator`) and never touches
global state; the same seed gives identical arrays. Each stage (shape, surface sampling, pose,
noise, outliers, shuffling) draws from its own child stream, so, for instance, the same seed with
and without noise gives the same underlying surface points.
"""

from __future__ import annotations

import os
import tempfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = [
    "FAMILIES",
    "PARAM_KINDS",
    "PARTS",
    "SAMPLERS",
    "Sampler",
    "SynthCloud",
    "apply_transform",
    "block_with_hole_and_slot",
    "filleted_block",
    "gear_like",
    "mirrored_cones",
    "plate_with_holes",
    "random_pose",
    "random_rotation",
    "sample_cone",
    "sample_cylinder",
    "sample_family",
    "sample_plane_patch",
    "sample_sphere",
    "sample_torus",
    "shaft_with_groove",
    "single",
    "transform_params",
    "write_demo",
    "write_fit4cad_segments",
]

TAU = 2.0 * np.pi
FAMILIES: tuple[str, ...] = ("plane", "cylinder", "cone", "sphere", "torus")

Array = np.ndarray


# --------------------------------------------------------------------------------------------
# The cloud
# --------------------------------------------------------------------------------------------


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
        ``{"type": str, "params": dict, ...}`` in world coordinates (see module docstring).
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


# --------------------------------------------------------------------------------------------
# Surface samplers (local standard frame, uniform area density)
# --------------------------------------------------------------------------------------------


def _span(r: tuple[float, float]) -> tuple[float, float]:
    lo, hi = float(r[0]), float(r[1])
    if not hi > lo:
        raise ValueError(f"empty range {r!r}")
    return lo, hi


def sample_plane_patch(
    rng: np.random.Generator, n: int, size: tuple[float, float] = (1.0, 1.0), shape: str = "rect"
) -> tuple[Array, Array]:
    """Uniform points on a patch of the plane z = 0, centred at the origin.

    Parameters
    ----------
    rng : numpy Generator
    n : int
        Number of points.
    size : (w, h)
        Side lengths along x and y (units). For ``shape="disc"`` the patch is the ellipse
        inscribed in that rectangle (a disc of radius w/2 when w = h).
    shape : "rect" or "disc"

    Returns
    -------
    points : (n, 3) float64, normals : (n, 3) float64 (all +z)
    """
    w, h = float(size[0]), float(size[1])
    if shape == "rect":
        xy = (rng.random((n, 2)) - 0.5) * np.array([w, h])
    elif shape == "disc":
        rho = np.sqrt(rng.random(n))
        phi = TAU * rng.random(n)
        xy = np.stack([0.5 * w * rho * np.cos(phi), 0.5 * h * rho * np.sin(phi)], axis=1)
    else:
        raise ValueError(f"unknown plane patch shape {shape!r}")
    pts = np.column_stack([xy, np.zeros(n)])
    nrm = np.zeros((n, 3))
    nrm[:, 2] = 1.0
    return pts, nrm


def sample_cylinder(
    rng: np.random.Generator,
    n: int,
    radius: float,
    height: float,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on x² + y² = radius², -height/2 ≤ z ≤ height/2, azimuth in ``arc`` (rad).

    Returns points (n, 3) and outward unit normals (n, 3).
    """
    a0, a1 = _span(arc)
    th = a0 + (a1 - a0) * rng.random(n)
    z = (rng.random(n) - 0.5) * float(height)
    c, s = np.cos(th), np.sin(th)
    pts = np.column_stack([radius * c, radius * s, z])
    nrm = np.column_stack([c, s, np.zeros(n)])
    return pts, nrm


def sample_cone(
    rng: np.random.Generator,
    n: int,
    half_angle: float,
    z_range: tuple[float, float],
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the cone x² + y² = (z tan α)², apex at the origin, opening towards +z.

    ``z_range = (z0, z1)`` (0 ≤ z0 < z1, units) bounds the patch along the axis, measured from
    the apex. The area element is proportional to z, so z is drawn by inverse CDF
    (z² uniform). Returns points (n, 3) and outward unit normals (n, 3)
    ``(cos α cos θ, cos α sin θ, −sin α)``.
    """
    z0, z1 = _span(z_range)
    if z0 < 0:
        raise ValueError("cone z_range must be on the opening side of the apex (z ≥ 0)")
    a0, a1 = _span(arc)
    z = np.sqrt(z0 * z0 + rng.random(n) * (z1 * z1 - z0 * z0))
    th = a0 + (a1 - a0) * rng.random(n)
    c, s = np.cos(th), np.sin(th)
    r = z * np.tan(half_angle)
    pts = np.column_stack([r * c, r * s, z])
    ca, sa = np.cos(half_angle), np.sin(half_angle)
    nrm = np.column_stack([ca * c, ca * s, np.full(n, -sa)])
    return pts, nrm


def sample_sphere(
    rng: np.random.Generator,
    n: int,
    radius: float,
    polar_range: tuple[float, float] = (0.0, np.pi),
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the sphere of ``radius`` centred at the origin.

    ``polar_range`` (rad, within [0, π]) is the range of the angle from +z, ``arc`` the azimuth
    range. Area-correct: z is uniform (Archimedes). Returns points (n, 3), outward normals (n, 3).
    """
    p0, p1 = _span(polar_range)
    a0, a1 = _span(arc)
    u = np.cos(p1) + (np.cos(p0) - np.cos(p1)) * rng.random(n)  # cos(polar), uniform
    rho = np.sqrt(np.clip(1.0 - u * u, 0.0, None))
    th = a0 + (a1 - a0) * rng.random(n)
    nrm = np.column_stack([rho * np.cos(th), rho * np.sin(th), u])
    return radius * nrm, nrm


def sample_torus(
    rng: np.random.Generator,
    n: int,
    major: float,
    minor: float,
    u_range: tuple[float, float] = (0.0, TAU),
    v_range: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on a ring torus around z, centred at the origin (major > minor > 0).

    Point ``((R + r cos v) cos u, (R + r cos v) sin u, r sin v)``: u (rad) goes around the axis,
    v (rad) around the tube (v = 0 outermost, v = π/2 top). The area element
    ``r (R + r cos v) du dv`` is honoured by drawing v by inverse CDF (interpolated start,
    then Newton steps on the closed-form CDF). Returns points (n, 3), outward normals (n, 3).
    """
    if not major > minor > 0:
        raise ValueError("torus needs major > minor > 0")
    u0, u1 = _span(u_range)
    v0, v1 = _span(v_range)
    u = u0 + (u1 - u0) * rng.random(n)

    def cdf(v: Array) -> Array:
        return major * (v - v0) + minor * (np.sin(v) - np.sin(v0))

    target = rng.random(n) * cdf(np.array(v1))
    grid = np.linspace(v0, v1, 1025)
    v = np.interp(target, cdf(grid), grid)
    for _ in range(4):
        v = np.clip(v - (cdf(v) - target) / (major + minor * np.cos(v)), v0, v1)
    cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
    nrm = np.column_stack([cv * cu, cv * su, sv])
    pts = np.column_stack([(major + minor * cv) * cu, (major + minor * cv) * su, minor * sv])
    return pts, nrm


# Areas of the untrimmed patches (units²), with the samplers' keyword arguments.


def _plane_area(size: tuple[float, float] = (1.0, 1.0), shape: str = "rect") -> float:
    return float(size[0] * size[1] * (1.0 if shape == "rect" else np.pi / 4))


def _cylinder_area(radius: float, height: float, arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float(radius * (arc[1] - arc[0]) * height)


def _cone_area(half_angle: float, z_range: tuple[float, float], arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float((arc[1] - arc[0]) * np.tan(half_angle) / np.cos(half_angle) * (z_range[1] ** 2 - z_range[0] ** 2) / 2)


def _sphere_area(
    radius: float, polar_range: tuple[float, float] = (0.0, np.pi), arc: tuple[float, float] = (0.0, TAU)
) -> float:
    return float((arc[1] - arc[0]) * radius**2 * (np.cos(polar_range[0]) - np.cos(polar_range[1])))


def _torus_area(
    major: float, minor: float, u_range: tuple[float, float] = (0.0, TAU), v_range: tuple[float, float] = (0.0, TAU)
) -> float:
    dv = v_range[1] - v_range[0]
    return float(minor * (u_range[1] - u_range[0]) * (major * dv + minor * (np.sin(v_range[1]) - np.sin(v_range[0]))))


# Parameters of the sampled primitive in its local frame (world conventions, before any pose).

_O, _Z = [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]


def _plane_local(**_: Any) -> dict[str, Any]:
    return {"normal": list(_Z), "offset": 0.0, "point": list(_O)}


def _cylinder_local(radius: float, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(_O), "axis": list(_Z), "radius": float(radius)}


def _cone_local(half_angle: float, **_: Any) -> dict[str, Any]:
    return {"apex": list(_O), "axis": list(_Z), "half_angle": float(half_angle)}


def _sphere_local(radius: float, **_: Any) -> dict[str, Any]:
    return {"center": list(_O), "radius": float(radius)}


def _torus_local(major: float, minor: float, **_: Any) -> dict[str, Any]:
    return {"center": list(_O), "axis": list(_Z), "major_radius": float(major), "minor_radius": float(minor)}


# Random but sensible shapes for `single` (local frame, sizes of order 1).


def _partial(rng: np.random.Generator, p_full: float, min_span: float, max_span: float) -> tuple[float, float]:
    """A full turn with probability ``p_full``, otherwise a random sub-range (rad)."""
    if rng.random() < p_full:
        return (0.0, TAU)
    a0 = float(rng.uniform(0.0, TAU))
    return (a0, a0 + float(rng.uniform(min_span, max_span)))


def _plane_random(rng: np.random.Generator) -> dict[str, Any]:
    size = (float(rng.uniform(0.6, 1.4)), float(rng.uniform(0.6, 1.4)))
    return {"size": size, "shape": "rect" if rng.random() < 0.7 else "disc"}


def _cylinder_random(rng: np.random.Generator) -> dict[str, Any]:
    r = float(rng.uniform(0.4, 1.0))
    return {"radius": r, "height": r * float(rng.uniform(1.0, 3.0)), "arc": _partial(rng, 0.6, np.pi / 2, 1.6 * np.pi)}


def _cone_random(rng: np.random.Generator) -> dict[str, Any]:
    alpha = float(np.deg2rad(rng.uniform(15.0, 60.0)))
    z1 = float(rng.uniform(0.6, 1.2)) / np.tan(alpha)  # radius 0.6-1.2 at the wide end
    return {"half_angle": alpha, "z_range": (z1 * float(rng.uniform(0.1, 0.5)), z1)}


def _sphere_random(rng: np.random.Generator) -> dict[str, Any]:
    cap = (0.0, np.pi) if rng.random() < 0.5 else (0.0, float(rng.uniform(np.pi / 3, 0.9 * np.pi)))
    return {"radius": float(rng.uniform(0.5, 1.2)), "polar_range": cap}


def _torus_random(rng: np.random.Generator) -> dict[str, Any]:
    major = float(rng.uniform(0.8, 1.2))
    return {
        "major": major,
        "minor": major * float(rng.uniform(0.2, 0.5)),
        "u_range": _partial(rng, 0.5, np.pi / 2, 1.7 * np.pi),
        "v_range": _partial(rng, 0.6, np.pi, 1.8 * np.pi),
    }


@dataclass(frozen=True)
class Sampler:
    """Everything the generator needs to know about one family.

    Attributes
    ----------
    sample : callable ``(rng, n, **shape) -> (points (n,3), normals (n,3))``
        Uniform sampler in the local standard frame.
    area : callable ``(**shape) -> float``
        Area of the sampled (untrimmed) patch, units².
    local_params : callable ``(**shape) -> dict``
        The primitive's parameters in the local frame (world naming conventions).
    random_shape : callable ``(rng) -> dict``
        Random but sensible ``shape`` keyword arguments, sizes of order 1 (used by :func:`single`).
    """

    sample: Callable[..., tuple[Array, Array]]
    area: Callable[..., float]
    local_params: Callable[..., dict[str, Any]]
    random_shape: Callable[[np.random.Generator], dict[str, Any]]

    def __call__(self, rng: np.random.Generator, n: int, **shape: Any) -> tuple[Array, Array]:
        return self.sample(rng, n, **shape)


#: Family name → :class:`Sampler`. A new family plugs in by adding one entry here (and, if its
#: parameters have new names, one line per name in :data:`PARAM_KINDS`).
SAMPLERS: dict[str, Sampler] = {
    "plane": Sampler(sample_plane_patch, _plane_area, _plane_local, _plane_random),
    "cylinder": Sampler(sample_cylinder, _cylinder_area, _cylinder_local, _cylinder_random),
    "cone": Sampler(sample_cone, _cone_area, _cone_local, _cone_random),
    "sphere": Sampler(sample_sphere, _sphere_area, _sphere_local, _sphere_random),
    "torus": Sampler(sample_torus, _torus_area, _torus_local, _torus_random),
}


def sample_family(name: str, rng: np.random.Generator, n: int, **shape: Any) -> tuple[Array, Array]:
    """Sample ``n`` points of family ``name`` in its local frame: ``SAMPLERS[name](rng, n, **shape)``."""
    try:
        sampler = SAMPLERS[name]
    except KeyError:
        raise ValueError(f"unknown family {name!r}; known: {sorted(SAMPLERS)}") from None
    return sampler(rng, n, **shape)


# --------------------------------------------------------------------------------------------
# Poses
# --------------------------------------------------------------------------------------------

#: How each parameter name transforms under x → s R x + t. A ``"family.name"`` key overrides
#: ``"name"`` for that family (the same letter can be a length in one family, a ratio in another).
PARAM_KINDS: dict[str, str] = {
    "point": "point",
    "axis_point": "point",
    "apex": "point",
    "center": "point",
    "normal": "direction",
    "axis": "direction",
    "radius": "length",
    "major_radius": "length",
    "minor_radius": "length",
    "half_angle": "invariant",
    "offset": "offset",  # normal · x = offset; needs the family's "normal"
}


def random_rotation(rng: np.random.Generator) -> Array:
    """Uniformly distributed rotation matrix, shape (3, 3), det +1 (from a random unit quaternion)."""
    q = rng.standard_normal(4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_pose(rng: np.random.Generator, scale: float | None = None, extent: float = 1.0) -> tuple[Array, Array, float]:
    """A random similarity ``x → s R x + t``.

    R is uniform on SO(3); s is log-uniform in [0.25, 4] unless ``scale`` is given; each component
    of t is uniform in [-2, 2] · s · ``extent`` (``extent``: size of the object, units).
    Returns ``(R (3,3), t (3,), s)``. The same draws are consumed whether or not ``scale`` is given.
    """
    R = random_rotation(rng)
    s_rand = float(np.exp(rng.uniform(np.log(0.25), np.log(4.0))))
    s = s_rand if scale is None else float(scale)
    t = rng.uniform(-2.0, 2.0, 3) * s * extent
    return R, t, s


def apply_transform(points: Array, normals: Array | None, R: Array, t: Array, s: float = 1.0) -> tuple[Array, Array | None]:
    """Apply ``x → s R x + t`` to points (N, 3) and ``n → R n`` to normals (N, 3) (or None)."""
    p = s * (np.asarray(points, float) @ np.asarray(R).T) + np.asarray(t, float)
    n = None if normals is None else np.asarray(normals, float) @ np.asarray(R).T
    return p, n


def transform_params(type: str, params: dict[str, Any], R: Array, t: Array, s: float = 1.0) -> dict[str, Any]:
    """Parameters of a primitive after ``x → s R x + t`` (R rotation (3,3), t (3,), s > 0).

    Points map like x, directions by R, lengths scale by s, angles stay; a plane's ``offset``
    becomes ``s · offset + normal' · t``. ``type`` is the family name (for error messages; the
    rules come from :data:`PARAM_KINDS`). Vectors come back as lists of floats.
    """
    R = np.asarray(R, float)
    t = np.asarray(t, float)
    out: dict[str, Any] = {}
    for key, val in params.items():
        kind = PARAM_KINDS.get(f"{type}.{key}", PARAM_KINDS.get(key))
        if kind == "point":
            out[key] = (s * (R @ np.asarray(val, float)) + t).tolist()
        elif kind == "direction":
            out[key] = (R @ np.asarray(val, float)).tolist()
        elif kind == "length":
            out[key] = float(s * val)
        elif kind == "invariant":
            out[key] = float(val)
        elif kind == "lengths":  # a list of lengths (semi-axes)
            out[key] = [float(s * x) for x in val]
        elif kind == "directions":  # rows of unit vectors (an ellipsoid's axes)
            out[key] = (np.asarray(val, float) @ R.T).tolist()
        elif kind == "label":  # a name (a profile)
            out[key] = val
        elif kind == "offset":
            if "normal" not in params:
                raise ValueError(f"{type}: 'offset' without 'normal'")
            n_new = R @ np.asarray(params["normal"], float)
            out[key] = float(s * val + n_new @ t)
        else:
            raise ValueError(f"{type}: don't know how parameter {key!r} transforms (add it to PARAM_KINDS)")
    return out


# --------------------------------------------------------------------------------------------
# Shared finishing: pose, noise, outliers, shuffle
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Single primitives
# --------------------------------------------------------------------------------------------


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
# Composite parts: faces sampled in their own frames, trimmed against the part's solid
# --------------------------------------------------------------------------------------------


@dataclass
class _Face:
    """One face: an untrimmed patch of a primitive placed by ``x → R x + t`` (local → part)."""

    name: str
    family: str
    shape: dict[str, Any]
    R: Array = field(default_factory=lambda: np.eye(3))
    t: Array = field(default_factory=lambda: np.zeros(3))


def _frame(z: Any, x: Any = None) -> Array:
    """Rotation (3, 3) whose columns are the local x, y = z × x, z axes expressed in the part frame."""
    z = np.asarray(z, float)
    z = z / np.linalg.norm(z)
    if x is None:
        x = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.asarray(x, float)
    x = x - (x @ z) * z
    x = x / np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _box_faces(lo: Any, hi: Any) -> list[_Face]:
    """The six rectangles of the box [lo, hi], outward normals, order -x, +x, -y, +y, -z, +z."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    mid, ext = (lo + hi) / 2, hi - lo
    faces = []
    for k, axis in enumerate("xyz"):
        for sign, side in ((-1.0, "-"), (1.0, "+")):
            e = np.eye(3)
            c = mid.copy()
            c[k] = lo[k] if sign < 0 else hi[k]
            R = _frame(sign * e[k], e[(k + 1) % 3])
            size = (float(ext[(k + 1) % 3]), float(ext[(k + 2) % 3]))
            faces.append(_Face(f"box {side}{axis}", "plane", {"size": size}, R, c))
    return faces


def _cyl_face(name: str, center: Any, radius: float, height: float, axis: Any = (0, 0, 1)) -> _Face:
    """Cylinder patch of ``height`` centred at ``center`` (units) along ``axis``."""
    return _Face(name, "cylinder", {"radius": float(radius), "height": float(height)}, _frame(axis), np.asarray(center, float))


def _disc_face(name: str, center: Any, radius: float, normal: Any = (0, 0, 1)) -> _Face:
    d = 2.0 * float(radius)
    return _Face(name, "plane", {"size": (d, d), "shape": "disc"}, _frame(normal), np.asarray(center, float))


def _radial(p: Array, cx: float = 0.0, cy: float = 0.0) -> Array:
    """Distance (N,) of points (N, 3) from the vertical line through (cx, cy)."""
    return np.hypot(p[:, 0] - cx, p[:, 1] - cy)


def _in_box(p: Array, lo: Any, hi: Any) -> Array:
    return np.all((p > np.asarray(lo)) & (p < np.asarray(hi)), axis=1)


def _sample_faces(
    rng: np.random.Generator, faces: list[_Face], solid: Callable[[Array], Array], density: float, eps: float
) -> tuple[Array, Array, Array]:
    """Sample every face at ``density`` (points / units²), keep the points on the solid's boundary."""
    P, N, L = [], [], []
    for k, f in enumerate(faces):  # loop over faces, never over points
        spec = SAMPLERS[f.family]
        n = int(np.ceil(density * spec.area(**f.shape)))
        p, nr = spec.sample(rng, n, **f.shape)
        p, nr = apply_transform(p, nr, f.R, f.t)
        behind, front = solid(p - eps * nr), solid(p + eps * nr)
        keep = behind != front  # material on exactly one side: a real piece of the boundary
        nr = np.where(front[:, None], -nr, nr)  # orient outwards (away from the material)
        P.append(p[keep])
        N.append(nr[keep])
        L.append(np.full(int(keep.sum()), k, np.int64))
    return np.vstack(P), np.vstack(N), np.concatenate(L)


def _part(
    st: _Streams,
    name: str,
    faces: list[_Face],
    solid: Callable[[Array], Array],
    n_points: int,
    noise: float,
    outliers: float,
    pose: bool,
    scale: float | None,
) -> SynthCloud:
    """Assemble a part: uniform density over the trimmed faces, exactly ``n_points`` surface points."""
    areas = [SAMPLERS[f.family].area(**f.shape) for f in faces]
    size = max(1.0, max(float(np.linalg.norm(f.t)) + np.sqrt(a) for f, a in zip(faces, areas)))
    eps = 1e-7 * size  # offset of the inside tests, far below any feature size
    density = n_points / sum(areas)
    for _ in range(20):
        pts, nrm, lab = _sample_faces(st.sample, faces, solid, density, eps)
        if len(pts) >= n_points:
            break
        density *= 1.1 * n_points / max(len(pts), 1)
    else:  # pragma: no cover - would need a degenerate part
        raise RuntimeError(f"{name}: could not reach {n_points} points")
    keep = np.sort(st.sample.choice(len(pts), n_points, replace=False))  # uniform thinning
    pts, nrm, lab = pts[keep], nrm[keep], lab[keep]
    prims = []
    for f in faces:
        params = transform_params(f.family, SAMPLERS[f.family].local_params(**f.shape), f.R, f.t)
        prims.append({"type": f.family, "params": params, "name": f.name})
    return _finish(st, pts, nrm, lab, prims, name, noise, outliers, pose, scale, _bbox_diag(pts))


def block_with_hole_and_slot(
    seed: int = 0,
    n_points: int = 20000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Block with a vertical through-hole crossed by a horizontal rectangular tunnel (the "slot").

    Part frame: block [-Lx/2, Lx/2] × [-Ly/2, Ly/2] × [0, H]. The tunnel runs along y through
    the whole block at mid height and is wider than the hole, so the hole's wall comes in two
    pieces (above and below the tunnel) that share one label; the tunnel's floor and ceiling have
    a hole where the cylinder crosses them, the ±y faces have the tunnel's opening.

    Primitives (11): 0–5 box planes (-x, +x, -y, +y, -z, +z), 6 hole cylinder (2 components),
    7 tunnel floor, 8 tunnel ceiling, 9 and 10 tunnel side walls (planes; normals point into the
    tunnel, i.e. out of the material). See :func:`single` for ``noise``, ``outliers``, ``pose``
    and ``scale``.
    """
    st = _Streams.from_seed(seed, "block_with_hole_and_slot")
    g = st.shape
    Lx, Ly, H = g.uniform(3.0, 4.0), g.uniform(2.0, 2.8), g.uniform(1.6, 2.2)
    r = g.uniform(0.3, 0.45)
    wt = 2 * r + g.uniform(0.3, 0.6)  # tunnel width (x)
    tx = g.uniform(-Lx / 2 + wt / 2 + 0.4, Lx / 2 - wt / 2 - 0.4)
    hx = tx + g.uniform(-1, 1) * (wt / 2 - r - 0.1)
    hy = g.uniform(-Ly / 2 + r + 0.35, Ly / 2 - r - 0.35)
    tz0 = H * g.uniform(0.3, 0.4)
    tz1 = tz0 + H * g.uniform(0.2, 0.3)
    lo, hi = np.array([-Lx / 2, -Ly / 2, 0.0]), np.array([Lx / 2, Ly / 2, H])
    tlo, thi = np.array([tx - wt / 2, -Ly, tz0]), np.array([tx + wt / 2, Ly, tz1])

    def solid(p: Array) -> Array:
        return _in_box(p, lo, hi) & ~(_radial(p, hx, hy) < r) & ~_in_box(p, tlo, thi)

    ex, ey = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    tsize_fc = (wt, Ly)  # floor / ceiling: x × y
    tsize_w = (Ly, tz1 - tz0)  # side walls: y × z
    faces = _box_faces(lo, hi) + [
        _cyl_face("hole", (hx, hy, H / 2), r, H),
        _Face("tunnel floor", "plane", {"size": tsize_fc}, _frame((0, 0, 1), ex), np.array([tx, 0, tz0])),
        _Face("tunnel ceiling", "plane", {"size": tsize_fc}, _frame((0, 0, -1), ex), np.array([tx, 0, tz1])),
        _Face("tunnel wall -x", "plane", {"size": tsize_w}, _frame((1, 0, 0), ey), np.array([tx - wt / 2, 0, (tz0 + tz1) / 2])),
        _Face("tunnel wall +x", "plane", {"size": tsize_w}, _frame((-1, 0, 0), ey), np.array([tx + wt / 2, 0, (tz0 + tz1) / 2])),
    ]
    return _part(st, f"block_with_hole_and_slot-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


def plate_with_holes(
    seed: int = 0,
    n_points: int = 20000,
    n_holes: int = 6,
    pattern: str = "circle",
    boss: bool = True,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Rectangular plate with ``n_holes`` equal through-holes and an optional cylindrical boss.

    ``pattern="circle"``: hole centres equally spaced on a circle around the plate centre, boss in
    the middle. ``pattern="grid"``: a near-square grid (``ceil(sqrt(n))`` columns, rows filled in
    order); the boss goes to the plate centre, the middle of a grid cell or beside the grid,
    wherever it clears the holes. The boss radius differs from the hole radius by ≥ 40 %.
    Part frame: plate [x0, x1] × [y0, y1] × [0, T], boss on top.

    Primitives: 0–5 plate planes (-x, +x, -y, +y, -z, +z), then one cylinder per hole, then (if
    ``boss``) the boss side cylinder and the boss top plane: 6 + n_holes (+ 2). Every label is
    one connected piece.
    """
    if pattern not in ("circle", "grid"):
        raise ValueError(f"pattern must be 'circle' or 'grid', got {pattern!r}")
    if n_holes < 1:
        raise ValueError("n_holes must be ≥ 1")
    st = _Streams.from_seed(seed, "plate_with_holes")
    g = st.shape
    rh = g.uniform(0.15, 0.25)
    T = rh * g.uniform(1.5, 2.5)
    k = np.arange(n_holes)
    if pattern == "circle":
        gap = rh * g.uniform(1.5, 2.5)
        Rc = 4 * rh if n_holes == 1 else max(4 * rh, (2 * rh + gap) / (2 * np.sin(np.pi / n_holes)))
        phi = TAU * k / n_holes + g.uniform(0, TAU)
        holes = np.column_stack([Rc * np.cos(phi), Rc * np.sin(phi)])
        cand = np.zeros((1, 2))
    else:
        cols = int(np.ceil(np.sqrt(n_holes)))
        rows = int(np.ceil(n_holes / cols))
        d = rh * g.uniform(5.0, 6.0)
        holes = np.column_stack([(k % cols - (cols - 1) / 2) * d, (k // cols - (rows - 1) / 2) * d])
        cx = (np.arange(cols - 1) - (cols - 2) / 2) * d
        cy = (np.arange(rows - 1) - (rows - 2) / 2) * d
        cells = np.array([(x, y) for y in cy for x in cx]).reshape(-1, 2)
        cells = cells[np.argsort(np.hypot(cells[:, 0], cells[:, 1]), kind="stable")]
        cand = np.vstack([np.zeros((1, 2)), cells, [[0.0, holes[:, 1].max() + d]]])
    clear = np.min(np.hypot(*(cand[:, None, :] - holes[None, :, :]).transpose(2, 0, 1)), axis=1) - rh
    ok = np.flatnonzero(clear >= 2.4 * rh)
    ib = int(ok[0]) if len(ok) else int(np.argmax(clear))
    bxy, rb = cand[ib], float(min(0.6 * clear[ib], 2.5 * rh))
    hb = T * g.uniform(1.0, 2.0)
    margin = rh * g.uniform(2.0, 3.0)
    feats = np.vstack([holes - rh, holes + rh] + ([bxy - rb, bxy + rb] if boss else []))
    lo2, hi2 = feats.min(axis=0) - margin, feats.max(axis=0) + margin
    lo, hi = np.array([lo2[0], lo2[1], 0.0]), np.array([hi2[0], hi2[1], T])

    def solid(p: Array) -> Array:
        dh = np.hypot(p[:, None, 0] - holes[None, :, 0], p[:, None, 1] - holes[None, :, 1])  # (N, n_holes)
        plate = _in_box(p, lo, hi) & ~np.any(dh < rh, axis=1)
        if not boss:
            return plate
        return plate | ((_radial(p, *bxy) < rb) & (p[:, 2] > 0) & (p[:, 2] < T + hb))

    faces = _box_faces(lo, hi) + [_cyl_face(f"hole {i}", (x, y, T / 2), rh, T) for i, (x, y) in enumerate(holes)]
    if boss:
        faces += [_cyl_face("boss wall", (bxy[0], bxy[1], T + hb / 2), rb, hb), _disc_face("boss top", (bxy[0], bxy[1], T + hb), rb)]
    return _part(st, f"plate_with_holes-{pattern}-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


def shaft_with_groove(
    seed: int = 0,
    n_points: int = 20000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Cylindrical shaft (axis z, 0 ≤ z ≤ L) with a rectangular groove g0 < z < g1.

    Primitives (6): 0 shaft cylinder (2 components: either side of the groove), 1 end plane z=0,
    2 end plane z=L, 3 groove bottom cylinder, 4 groove wall z=g0, 5 groove wall z=g1 (annular
    planes, normals facing into the groove).
    """
    st = _Streams.from_seed(seed, "shaft_with_groove")
    g = st.shape
    R, L = g.uniform(0.4, 0.6), g.uniform(3.0, 5.0)
    w = g.uniform(0.3, 0.6)
    g0 = L * g.uniform(0.35, 0.65) - w / 2
    g1 = g0 + w
    Rg = R * g.uniform(0.6, 0.8)

    def solid(p: Array) -> Array:
        rho, z = _radial(p), p[:, 2]
        return (z > 0) & (z < L) & (rho < R) & ~((z > g0) & (z < g1) & (rho > Rg))

    faces = [
        _cyl_face("shaft", (0, 0, L / 2), R, L),
        _disc_face("end z=0", (0, 0, 0), R, (0, 0, -1)),
        _disc_face("end z=L", (0, 0, L), R, (0, 0, 1)),
        _cyl_face("groove bottom", (0, 0, (g0 + g1) / 2), Rg, w),
        _disc_face("groove wall low", (0, 0, g0), R, (0, 0, 1)),
        _disc_face("groove wall high", (0, 0, g1), R, (0, 0, -1)),
    ]
    return _part(st, f"shaft_with_groove-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


def mirrored_cones(
    seed: int = 0,
    n_points: int = 20000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Double-tapered part, symmetric about z = 0: cylinder in the middle, a cone at each end.

    Cylinder radius R for |z| ≤ h/2, cones (half-angle 20°–40°) narrowing to radius r_end at
    |z| = ze, end discs there. Each cone's apex lies beyond its end disc and its axis points back
    towards the middle (into the opening).

    Primitives (5): 0 cylinder, 1 cone +z, 2 cone -z, 3 end plane +z, 4 end plane -z.
    """
    st = _Streams.from_seed(seed, "mirrored_cones")
    g = st.shape
    R = g.uniform(0.8, 1.2)
    h = R * g.uniform(1.0, 2.0)
    alpha = np.deg2rad(g.uniform(20.0, 40.0))
    r_end = R * g.uniform(0.3, 0.6)
    ta = np.tan(alpha)
    za = h / 2 + R / ta  # apex height
    ze = za - r_end / ta  # end discs
    zr = (r_end / ta, R / ta)  # cone patch, distances from the apex

    def solid(p: Array) -> Array:
        az = np.abs(p[:, 2])
        return (az < ze) & (_radial(p) < np.minimum(R, (za - az) * ta))

    faces = [
        _cyl_face("cylinder", (0, 0, 0), R, h),
        _Face("cone +z", "cone", {"half_angle": float(alpha), "z_range": zr}, _frame((0, 0, -1)), np.array([0, 0, za])),
        _Face("cone -z", "cone", {"half_angle": float(alpha), "z_range": zr}, _frame((0, 0, 1)), np.array([0, 0, -za])),
        _disc_face("end +z", (0, 0, ze), r_end, (0, 0, 1)),
        _disc_face("end -z", (0, 0, -ze), r_end, (0, 0, -1)),
    ]
    return _part(st, f"mirrored_cones-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


def gear_like(
    seed: int = 0,
    n_points: int = 20000,
    n_holes: int = 12,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Disc (axis z, 0 ≤ z ≤ T) with a central bore and ``n_holes`` equal holes on a circle.

    Primitives (4 + n_holes): 0 top plane, 1 bottom plane, 2 outer cylinder, 3 bore cylinder,
    4… hole cylinders. Every label is one connected piece.
    """
    if n_holes < 1:
        raise ValueError("n_holes must be ≥ 1")
    st = _Streams.from_seed(seed, "gear_like")
    g = st.shape
    Ro = g.uniform(1.8, 2.2)
    T = g.uniform(0.3, 0.5)
    rb = Ro * g.uniform(0.2, 0.3)
    Rc = Ro * g.uniform(0.6, 0.65)
    pitch = 2 * Rc * np.sin(np.pi / n_holes) if n_holes > 1 else np.inf
    rh = min(pitch * g.uniform(0.25, 0.35), 0.4 * (Rc - rb), 0.4 * (Ro - Rc))
    phi = TAU * np.arange(n_holes) / n_holes + g.uniform(0, TAU)
    holes = np.column_stack([Rc * np.cos(phi), Rc * np.sin(phi)])

    def solid(p: Array) -> Array:
        rho, z = _radial(p), p[:, 2]
        dh = np.hypot(p[:, None, 0] - holes[None, :, 0], p[:, None, 1] - holes[None, :, 1])
        return (z > 0) & (z < T) & (rho < Ro) & (rho > rb) & ~np.any(dh < rh, axis=1)

    faces = [
        _disc_face("top", (0, 0, T), Ro, (0, 0, 1)),
        _disc_face("bottom", (0, 0, 0), Ro, (0, 0, -1)),
        _cyl_face("outer", (0, 0, T / 2), Ro, T),
        _cyl_face("bore", (0, 0, T / 2), rb, T),
    ] + [_cyl_face(f"hole {i}", (x, y, T / 2), rh, T) for i, (x, y) in enumerate(holes)]
    return _part(st, f"gear_like-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


def filleted_block(
    seed: int = 0,
    n_points: int = 20000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Block with a rounded edge, a spherical dimple and a boss with a toroidal base fillet.

    Part frame: block [-Lx/2, Lx/2] × [-Ly/2, Ly/2] × [0, H]. The edge between the top and the
    +y face is rounded by a quarter cylinder (axis along x). On the top face: a spherical dimple
    (cap of a sphere whose centre lies above the top) and a cylindrical boss whose foot is blended
    into the top face by a concave torus fillet (the inner-lower quarter of the tube).

    Primitives (11): 0–5 box planes (-x, +x, -y, +y, -z, +z), 6 edge fillet cylinder, 7 dimple
    sphere, 8 boss cylinder, 9 boss top plane, 10 fillet torus. Every label is one connected piece.
    """
    st = _Streams.from_seed(seed, "filleted_block")
    g = st.shape
    Lx, Ly, H = g.uniform(4.0, 5.0), g.uniform(3.0, 3.5), g.uniform(1.0, 1.5)
    rf = g.uniform(0.3, 0.5)  # edge fillet radius
    rb, rt = g.uniform(0.4, 0.6), g.uniform(0.15, 0.25)  # boss radius, torus fillet radius
    hb = g.uniform(0.5, 0.8)
    bx, by = -Lx / 4, -rf / 2
    a = g.uniform(0.5, 0.7)  # dimple rim radius
    depth = a * g.uniform(0.3, 0.6)
    Rs = (a * a + depth * depth) / (2 * depth)
    sc = np.array([Lx / 4, -rf / 2, H + Rs - depth])  # sphere centre
    lo, hi = np.array([-Lx / 2, -Ly / 2, 0.0]), np.array([Lx / 2, Ly / 2, H])
    fy, fz = Ly / 2 - rf, H - rf  # fillet axis (along x)

    def solid(p: Array) -> Array:
        y, z = p[:, 1], p[:, 2]
        edge_cut = (y > fy) & (z > fz) & (np.hypot(y - fy, z - fz) > rf)
        rho = _radial(p, bx, by)
        boss = (rho < rb) & (z > 0) & (z < H + hb)
        blend = (rho >= rb) & (rho < rb + rt) & (z >= H) & (z < H + rt) & (np.hypot(rho - rb - rt, z - H - rt) > rt)
        dimple = np.sum((p - sc) ** 2, axis=1) < Rs * Rs
        return ((_in_box(p, lo, hi) & ~edge_cut) | boss | blend) & ~dimple

    theta0 = float(np.arccos(-(Rs - depth) / Rs))  # polar angle of the dimple rim
    faces = _box_faces(lo, hi) + [
        _Face("edge fillet", "cylinder", {"radius": float(rf), "height": float(Lx), "arc": (0.0, np.pi / 2)},
              _frame((1, 0, 0), (0, 1, 0)), np.array([0.0, fy, fz])),
        _Face("dimple", "sphere", {"radius": float(Rs), "polar_range": (theta0, np.pi)}, np.eye(3), sc),
        _cyl_face("boss wall", (bx, by, H + hb / 2), rb, hb),
        _disc_face("boss top", (bx, by, H + hb), rb),
        _Face("boss fillet", "torus", {"major": float(rb + rt), "minor": float(rt), "v_range": (np.pi, 1.5 * np.pi)},
              np.eye(3), np.array([bx, by, H + rt])),
    ]
    return _part(st, f"filleted_block-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


#: Part name → generator function (each takes ``seed=`` and returns a :class:`SynthCloud`).
PARTS: dict[str, Callable[..., SynthCloud]] = {
    "block_with_hole_and_slot": block_with_hole_and_slot,
    "plate_with_holes": plate_with_holes,
    "shaft_with_groove": shaft_with_groove,
    "mirrored_cones": mirrored_cones,
    "gear_like": gear_like,
    "filleted_block": filleted_block,
}


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def _atomic_write(path: Path, write: Callable[[Any], None], mode: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode) as fh:
            write(fh)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_fit4cad_segments(cloud: SynthCloud, path: str | os.PathLike[str]) -> None:
    """Write the ground-truth segments in the Fit4CAD format (atomic).

    One block per primitive, ``PrimitiveK:=[i j k ...];`` with 1-based point indices, blocks
    separated by a blank line. Outliers belong to no block.
    """
    text = "".join(
        f"Primitive{k + 1}:=[{' '.join(str(int(i) + 1) for i in idx)}];\n\n" for k, idx in enumerate(cloud.segments())
    )
    _atomic_write(Path(path), lambda fh: fh.write(text), "w")


def write_demo(path: str | os.PathLike[str] | None = None) -> SynthCloud:
    """Generate the bundled demo cloud and write it.

    The cloud is ``block_with_hole_and_slot(seed=7, n_points=12000, noise=0.001)`` (posed). It is
    written to ``path`` (default ``houghcad/data/demo_part.ply``) as binary little-endian PLY with
    float32 x, y, z only, and its ground-truth segments to ``<stem>_primitives.txt`` next to it
    (Fit4CAD format). Both writes are atomic. Returns the cloud.
    """
    from plyfile import PlyData, PlyElement

    ply_path = Path(path) if path is not None else Path(__file__).parent / "data" / "demo_part.ply"
    cloud = block_with_hole_and_slot(seed=7, n_points=12000, noise=0.001)
    vert = np.empty(len(cloud.points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    for j, c in enumerate("xyz"):
        vert[c] = cloud.points[:, j]
    ply = PlyData([PlyElement.describe(vert, "vertex")], text=False, byte_order="<")
    _atomic_write(ply_path, ply.write, "wb")
    write_fit4cad_segments(cloud, ply_path.with_name(ply_path.stem + "_primitives.txt"))
    return cloud


if __name__ == "__main__":  # python -m houghcad.synth regenerates the bundled demo
    write_demo()


# --------------------------------------------------------------------------------------------
# Generalised cylinders and cones over an n-convexity directrix (issue 3)
# --------------------------------------------------------------------------------------------
#
# Directrix (local frame, phase 0): ρ(u) = a / (1 + b cos(order·u)), the point ρ(u)(cos u, sin u).
# The reference direction ``ref_direction`` is local x (u = 0, a point of smallest radius a / (1 + b)).
# Shape keyword ``order`` is the paper's n (the samplers' second argument is the point count).


def _directrix_speed(u: Array, a: float, b: float, order: int) -> tuple[Array, Array, Array]:
    """Radius ρ(u), its derivative ρ'(u) and the speed |C'(u)| = sqrt(ρ² + ρ'²), each (m,)."""
    g = 1.0 + b * np.cos(order * u)
    r = a / g
    r1 = a * b * order * np.sin(order * u) / g**2
    return r, r1, np.hypot(r, r1)


def _draw_by_weight(rng: np.random.Generator, n: int, w_fun: Callable[[Array], Array], lo: float, hi: float,
                    m: int = 8192) -> Array:
    """``n`` draws of u in [lo, hi] with density ∝ w_fun(u) > 0 (inverse CDF on a fine grid, linear
    interpolation: the density error is O(1/m²))."""
    grid = np.linspace(lo, hi, m + 1)
    w = w_fun(grid)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(grid))])
    return np.interp(rng.random(n) * cdf[-1], cdf, grid)


def _directrix_length(a: float, b: float, order: int, arc: tuple[float, float] = (0.0, TAU), m: int = 8192) -> float:
    u = np.linspace(arc[0], arc[1], m + 1)
    s = _directrix_speed(u, a, b, order)[2]
    return float(np.sum(0.5 * (s[1:] + s[:-1]) * np.diff(u)))


def sample_generalized_cylinder(
    rng: np.random.Generator, n: int, a: float, b: float, order: int, height: float,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the generalised cylinder over ρ(u) = a / (1 + b cos(order·u)),
    -height/2 ≤ z ≤ height/2, u in ``arc`` (rad).

    Area element |C'(u)| du dz: u is drawn with density ∝ the directrix's speed, z uniformly.
    Returns points (n, 3) and outward unit normals (n, 3) (the directrix is star-shaped, traversed
    counter-clockwise, so the outward normal is C' turned by -90°).
    """
    a0, a1 = _span(arc)
    u = _draw_by_weight(rng, n, lambda t: _directrix_speed(t, a, b, order)[2], a0, a1)
    z = (rng.random(n) - 0.5) * float(height)
    r, r1, sp = _directrix_speed(u, a, b, order)
    c, s = np.cos(u), np.sin(u)
    t = np.column_stack([r1 * c - r * s, r1 * s + r * c]) / sp[:, None]  # unit tangent C'/|C'|
    pts = np.column_stack([r * c, r * s, z])
    nrm = np.column_stack([t[:, 1], -t[:, 0], np.zeros(n)])
    return pts, nrm


def sample_generalized_cone(
    rng: np.random.Generator, n: int, slope: float, b: float, order: int, z_range: tuple[float, float],
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the generalised cone z (ρ_s(u) cos u, ρ_s(u) sin u, 1), ρ_s = slope / (1 + b cos(order·u)):
    apex at the origin, opening towards +z, z in ``z_range`` (0 ≤ z0 < z1), u in ``arc``.

    This is the paper's x = a v cos u / (1 + b cos nu), y = a v sin u / (1 + b cos nu), z = A v + B
    with A = 1, B = 0 (v = z, a = ``slope``). With D(u) = (ρ_s e(u), 1) the area element is
    z |D(u) × D'(u)| du dz: separable, z drawn with density ∝ z, u with density ∝ |D × D'|.
    Returns points (n, 3) and outward unit normals (n, 3) (∝ D' × D).
    """
    z0, z1 = _span(z_range)
    if z0 < 0:
        raise ValueError("generalised cone z_range must be on the opening side of the apex (z ≥ 0)")
    a0, a1 = _span(arc)
    u = _draw_by_weight(rng, n, lambda t: np.linalg.norm(_gcone_cross(t, slope, b, order), axis=1), a0, a1)
    z = np.sqrt(z0 * z0 + rng.random(n) * (z1 * z1 - z0 * z0))
    r = _directrix_speed(u, slope, b, order)[0]
    pts = np.column_stack([z * r * np.cos(u), z * r * np.sin(u), z])
    nrm = _gcone_cross(u, slope, b, order)
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _gcone_cross(u: Array, slope: float, b: float, order: int) -> Array:
    """D'(u) × D(u), (m, 3): an outward normal of the generalised cone along the ruling D(u)."""
    r, r1, _ = _directrix_speed(u, slope, b, order)
    c, s = np.cos(u), np.sin(u)
    D = np.column_stack([r * c, r * s, np.ones_like(u)])
    D1 = np.column_stack([r1 * c - r * s, r1 * s + r * c, np.zeros_like(u)])
    return np.cross(D1, D)


def _gcyl_area(a: float, b: float, order: int, height: float, arc: tuple[float, float] = (0.0, TAU)) -> float:
    return _directrix_length(a, b, order, arc) * float(height)


def _gcone_area(slope: float, b: float, order: int, z_range: tuple[float, float],
                arc: tuple[float, float] = (0.0, TAU), m: int = 8192) -> float:
    u = np.linspace(arc[0], arc[1], m + 1)
    w = np.linalg.norm(_gcone_cross(u, slope, b, order), axis=1)
    return float(np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(u)) * (z_range[1] ** 2 - z_range[0] ** 2) / 2)


def _gcyl_local(a: float, b: float, order: int, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(_O), "axis": list(_Z), "ref_direction": [1.0, 0.0, 0.0], "a": float(a), "b": float(b),
            "n": int(order)}


def _gcone_local(slope: float, b: float, order: int, **_: Any) -> dict[str, Any]:
    return {"apex": list(_O), "axis": list(_Z), "ref_direction": [1.0, 0.0, 0.0], "a": float(slope), "b": float(b),
            "n": int(order), "A": 1.0, "B": 0.0}


def _directrix_random(rng: np.random.Generator) -> tuple[int, float]:
    """Order 2–12 and b in [0.05, b_hi(order)]: b_hi = clip(4 / (order² − 1), 0.07, 0.3) keeps the
    lobes' curvature radius a / (1 + b (order² − 1)) at least a / 5 (a / 9.5 for order ≥ 8), so that
    the shape stays resolvable at 4000 points and 0.5 % noise."""
    order = int(rng.integers(2, 13))
    b_hi = float(np.clip(4.0 / (order * order - 1), 0.07, 0.3))
    return order, float(rng.uniform(0.05, b_hi))


def _gcyl_random(rng: np.random.Generator) -> dict[str, Any]:
    order, b = _directrix_random(rng)
    a = float(rng.uniform(0.4, 1.0))
    return {"a": a, "b": b, "order": order, "height": a * float(rng.uniform(1.0, 3.0))}


def _gcone_random(rng: np.random.Generator) -> dict[str, Any]:
    order, b = _directrix_random(rng)
    slope = float(np.tan(np.deg2rad(rng.uniform(20.0, 45.0))))
    z1 = float(rng.uniform(0.6, 1.2)) / slope  # mean radius 0.6-1.2 at the wide end
    return {"slope": slope, "b": b, "order": order, "z_range": (z1 * float(rng.uniform(0.2, 0.5)), z1)}


def generalized_cone_part(
    seed: int = 0,
    n_points: int = 20000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Prism-like body on one n-convexity directrix (paper Fig. 9(c)): a generalised cylinder of
    size a1 for 0 ≤ z ≤ h1, a generalised cone tapering from a1 to a2 < a1 for h1 ≤ z ≤ h1 + hc, a
    second generalised cylinder of size a2 up to z = L, and flat ends (plane discs trimmed to the
    directrix by the solid). All three curved faces share order (3–6), b and phase.

    Primitives (5): 0 generalised cylinder a1, 1 generalised cone, 2 generalised cylinder a2,
    3 end plane z=0, 4 end plane z=L. Every label is one connected piece.
    """
    st = _Streams.from_seed(seed, "generalized_cone_part")
    g = st.shape
    order = int(g.integers(3, 7))  # a few marked convexities, as in the paper's part (n = 5)
    b = float(g.uniform(0.08, np.clip(4.0 / (order * order - 1), 0.1, 0.3)))
    a1 = g.uniform(0.8, 1.2)
    a2 = a1 * g.uniform(0.45, 0.7)
    h1, hc, h2 = a1 * g.uniform(1.0, 1.6), a1 * g.uniform(0.6, 1.0), a1 * g.uniform(0.8, 1.4)
    L = h1 + hc + h2
    slope = (a1 - a2) / hc
    za = h1 + a1 / slope  # apex above the cone, which opens downwards

    def solid(p: Array) -> Array:
        z = p[:, 2]
        size = np.where(z < h1, a1, np.where(z < h1 + hc, a1 - (z - h1) * slope, a2))
        gth = 1.0 + b * np.cos(order * np.arctan2(p[:, 1], p[:, 0]))
        return (z > 0) & (z < L) & (_radial(p) * gth < size)

    ex = (1.0, 0.0, 0.0)
    dshape = {"b": float(b), "order": order}
    faces = [
        _Face("gen. cylinder a1", "generalized_cylinder", {"a": float(a1), "height": float(h1), **dshape},
              _frame((0, 0, 1), ex), np.array([0, 0, h1 / 2])),
        _Face("gen. cone", "generalized_cone", {"slope": float(slope), "z_range": (za - h1 - hc, za - h1), **dshape},
              _frame((0, 0, -1), ex), np.array([0, 0, za])),
        _Face("gen. cylinder a2", "generalized_cylinder", {"a": float(a2), "height": float(h2), **dshape},
              _frame((0, 0, 1), ex), np.array([0, 0, h1 + hc + h2 / 2])),
        _disc_face("end z=0", (0, 0, 0), a1 / (1 - b), (0, 0, -1)),
        _disc_face("end z=L", (0, 0, L), a2 / (1 - b), (0, 0, 1)),
    ]
    return _part(st, f"generalized_cone_part-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


SAMPLERS.update({
    "generalized_cylinder": Sampler(sample_generalized_cylinder, _gcyl_area, _gcyl_local, _gcyl_random),
    "generalized_cone": Sampler(sample_generalized_cone, _gcone_area, _gcone_local, _gcone_random),
})
PARAM_KINDS.update({
    "ref_direction": "direction",
    "a": "length",  # generalised cylinder: directrix size
    "b": "invariant",
    "n": "invariant",
    "generalized_cone.a": "invariant",  # the paper's a with A = 1: ρ/z, no unit
    "A": "invariant",
    "B": "length",
})
PARTS.update({"generalized_cone_part": generalized_cone_part})
__all__ += ["generalized_cone_part", "sample_generalized_cone", "sample_generalized_cylinder"]


# --------------------------------------------------------------------------------------------
# Helical surface, helical strip, annulus (complex families of issue 3) and the screw part
# --------------------------------------------------------------------------------------------
#
# Conventions (world parameters, lengths in the cloud's units):
#
# - helical_surface: ``axis_point``, ``axis`` (unit), ``ref_direction`` (unit, orthogonal to the
#   axis: the direction of φ = 0), ``R1`` < ``R2`` (smallest and largest radius), ``n`` (integer
#   ≠ 0, its sign the handedness), ``k1`` > 0, ``k2`` (phase along the axis, in [0, 2π k1)). In
#   the frame (ref_direction, axis × ref_direction, axis) at axis_point the surface is
#   x = R(u) cos v, y = R(u) sin v, z = k1 (u + n v) + k2, R(u) = R1 + (R2 − R1)(cos u + 1)/2:
#   the crests (radius R2) in the half-plane of ref_direction sit at k2 + 2π k1 m along the axis.
# - helical_strip: ``axis_point``, ``axis``, ``ref_direction`` (the strip's ruling through
#   axis_point points along it), ``r_inner`` < ``r_outer``, ``pitch`` (> 0, axial advance per
#   turn), ``handedness`` (+1 right-handed, −1 left-handed): x = ρ cos v, y = ρ sin v,
#   z = handedness · pitch/(2π) · v, r_inner ≤ ρ ≤ r_outer.
# - annulus: ``center``, ``normal`` (unit), ``r_inner`` < ``r_outer``.


def _helical_R(R1: float, R2: float, u: Array) -> tuple[Array, Array]:
    """Radius R(u) = R1 + (R2 − R1)(cos u + 1)/2 and its derivative, shapes like u."""
    return R1 + 0.5 * (R2 - R1) * (np.cos(u) + 1.0), -0.5 * (R2 - R1) * np.sin(u)


def _helical_density(R1: float, R2: float, k1: float, starts: int, u: Array) -> Array:
    """Area element |S_u × S_v| of the helical surface (depends on u only), shape like u."""
    R, dR = _helical_R(R1, R2, u)
    return np.sqrt(k1 * k1 * (starts * starts * dR * dR + R * R) + R * R * dR * dR)


def _inverse_cdf(rng: np.random.Generator, n: int, x: Array, dens: Array) -> Array:
    """n samples with density ∝ ``dens`` tabulated at ``x`` (piecewise linear CDF), shape (n,)."""
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(x))])
    return np.interp(rng.random(n) * cdf[-1], cdf, x)


def sample_helical_surface(
    rng: np.random.Generator,
    n: int,
    R1: float,
    R2: float,
    k1: float,
    starts: int,
    periods: int,
    k2: float = 0.0,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the helical surface z = k1 (u + starts·v) + k2 (see the section header),
    cut to the slab 0 ≤ z < periods · 2π k1 and the azimuth range ``arc`` (rad).

    ``periods`` (integer) whole profile periods make every azimuth carry the same area, so v is
    uniform; u is drawn by inverse CDF of the area element over one period, then moved by whole
    periods into the slab. Returns points (n, 3) and outward unit normals (n, 3).
    """
    if not (R2 > R1 > 0 and k1 > 0 and int(starts) != 0 and int(periods) >= 1):
        raise ValueError("helical surface needs R2 > R1 > 0, k1 > 0, starts ≠ 0, periods ≥ 1")
    a0, a1 = _span(arc)
    starts, periods = int(starts), int(periods)
    v = a0 + (a1 - a0) * rng.random(n)
    g = np.linspace(0.0, TAU, 2049)
    s = _inverse_cdf(rng, n, g, _helical_density(R1, R2, k1, starts, g)) + TAU * rng.integers(0, periods, n)
    # Slab condition: 0 ≤ k1 (u + starts v) + k2 < L  ⇔  u + starts v + k2/k1 ∈ [0, 2π periods).
    lo = -starts * v - k2 / k1
    u = lo + np.mod(s - lo, TAU * periods)  # whole periods: the density of u is unchanged
    R, dR = _helical_R(R1, R2, u)
    cv, sv = np.cos(v), np.sin(v)
    pts = np.column_stack([R * cv, R * sv, k1 * (u + starts * v) + k2])
    # −(S_u × S_v) points away from the axis.
    nrm = -np.column_stack([k1 * (starts * dR * sv - R * cv), -k1 * (R * sv + starts * dR * cv), R * dR])
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _helical_surface_area(R1: float, R2: float, k1: float, starts: int, periods: int, k2: float = 0.0,
                          arc: tuple[float, float] = (0.0, TAU)) -> float:
    g = np.linspace(0.0, TAU, 4097)
    d = _helical_density(R1, R2, k1, int(starts), g)
    return float((arc[1] - arc[0]) * int(periods) * np.sum(0.5 * (d[1:] + d[:-1]) * np.diff(g)))


def _helical_surface_local(R1: float, R2: float, k1: float, starts: int, k2: float = 0.0, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(_O), "axis": list(_Z), "ref_direction": [1.0, 0.0, 0.0], "R1": float(R1),
            "R2": float(R2), "n": int(starts), "k1": float(k1), "k2": float(k2 % (TAU * k1))}


def _helical_surface_random(rng: np.random.Generator) -> dict[str, Any]:
    R2 = float(rng.uniform(0.7, 1.0))
    starts = int(rng.integers(1, 4)) * (1 if rng.random() < 0.7 else -1)
    # Profile period 0.6–0.9 R2: a few sampling neighbourhoods per period at a few thousand
    # points, so that estimated normals still follow the flanks.
    k1 = R2 * float(rng.uniform(0.6, 0.9)) / TAU
    return {"R1": R2 * float(rng.uniform(0.6, 0.75)), "R2": R2, "k1": k1, "starts": starts,
            "periods": int(rng.integers(3, 5)), "k2": float(rng.uniform(0.0, TAU * k1))}


def sample_helical_strip(
    rng: np.random.Generator,
    n: int,
    r_inner: float,
    r_outer: float,
    c: float,
    v_range: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the helicoid strip x = ρ cos v, y = ρ sin v, z = c v, r_inner ≤ ρ ≤ r_outer.

    The area element √(c² + ρ²) dρ dv: v uniform, ρ by inverse CDF. Returns points (n, 3) and unit
    normals (n, 3) ∝ (c sin v, −c cos v, ρ).
    """
    if not (r_outer > r_inner >= 0 and c != 0):
        raise ValueError("helical strip needs r_outer > r_inner ≥ 0 and c ≠ 0")
    v0, v1 = _span(v_range)
    v = v0 + (v1 - v0) * rng.random(n)
    g = np.linspace(r_inner, r_outer, 2049)
    rho = _inverse_cdf(rng, n, g, np.sqrt(c * c + g * g))
    cv, sv = np.cos(v), np.sin(v)
    pts = np.column_stack([rho * cv, rho * sv, c * v])
    nrm = np.column_stack([c * sv, -c * cv, rho])
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _helical_strip_area(r_inner: float, r_outer: float, c: float, v_range: tuple[float, float] = (0.0, TAU)) -> float:
    def F(r: float) -> float:  # ∫ √(c² + r²) dr
        return 0.5 * (r * np.hypot(c, r) + c * c * np.arcsinh(r / abs(c)))

    return float((v_range[1] - v_range[0]) * (F(r_outer) - F(r_inner)))


def _helical_strip_local(r_inner: float, r_outer: float, c: float, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(_O), "axis": list(_Z), "ref_direction": [1.0, 0.0, 0.0], "r_inner": float(r_inner),
            "r_outer": float(r_outer), "pitch": float(abs(c) * TAU), "handedness": float(np.sign(c))}


def _helical_strip_random(rng: np.random.Generator) -> dict[str, Any]:
    a = float(rng.uniform(0.7, 1.0))
    c = a * float(rng.uniform(0.5, 1.0)) / TAU * (1 if rng.random() < 0.7 else -1)
    return {"r_inner": a * float(rng.uniform(0.3, 0.6)), "r_outer": a, "c": c,
            "v_range": (0.0, TAU * float(rng.uniform(1.0, 3.0)))}


def sample_annulus(
    rng: np.random.Generator,
    n: int,
    r_inner: float,
    r_outer: float,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the planar annulus r_inner ≤ ρ ≤ r_outer of z = 0 (azimuth in ``arc``).

    ρ² is uniform. Returns points (n, 3) and normals (n, 3) (all +z).
    """
    if not r_outer > r_inner >= 0:
        raise ValueError("annulus needs r_outer > r_inner ≥ 0")
    a0, a1 = _span(arc)
    rho = np.sqrt(r_inner**2 + rng.random(n) * (r_outer**2 - r_inner**2))
    th = a0 + (a1 - a0) * rng.random(n)
    pts = np.column_stack([rho * np.cos(th), rho * np.sin(th), np.zeros(n)])
    nrm = np.zeros((n, 3))
    nrm[:, 2] = 1.0
    return pts, nrm


def _annulus_area(r_inner: float, r_outer: float, arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float(0.5 * (arc[1] - arc[0]) * (r_outer**2 - r_inner**2))


def _annulus_local(r_inner: float, r_outer: float, **_: Any) -> dict[str, Any]:
    return {"center": list(_O), "normal": list(_Z), "r_inner": float(r_inner), "r_outer": float(r_outer)}


def _annulus_random(rng: np.random.Generator) -> dict[str, Any]:
    a = float(rng.uniform(0.6, 1.2))
    return {"r_inner": a * float(rng.uniform(0.3, 0.7)), "r_outer": a, "arc": _partial(rng, 0.7, np.pi, 1.7 * np.pi)}


def screw_part(
    seed: int = 0,
    n_points: int = 20000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """The screw-like part of the paper (Fig. "viteggiante"): a threaded sector between two
    parallel helicoids.

    Solid (cylindrical coordinates about z): r_b < ρ < ρ_thread(φ, z), c φ < z − z0 < c φ + h,
    0 < φ < Φ, where ρ_thread is a helical surface of pitch c = k1 n and h a whole number of
    thread periods, so the thread meets both helicoids along helices of one radius and the two
    strips are equal up to a translation along the axis (by h).

    Primitives (6): 0 helical surface (the thread), 1 plane φ = 0, 2 plane φ = Φ, 3 helical strip
    (lower), 4 helical strip (upper), 5 cylinder ρ = r_b (the bore). Faces are trimmed against the
    solid like the other parts.
    """
    st = _Streams.from_seed(seed, "screw_part")
    g = st.shape
    R2 = g.uniform(0.9, 1.1)
    R1 = R2 * g.uniform(0.65, 0.75)
    starts = int(g.integers(1, 3))
    k1 = R2 * g.uniform(0.6, 0.8) / TAU
    T = TAU * k1
    k2 = g.uniform(0.0, T)
    c = k1 * starts
    h = T * int(g.integers(2, 4))
    rb = R2 * g.uniform(0.25, 0.4)
    Phi = np.pi * g.uniform(1.25, 1.6)
    z0 = 0.0
    a_edge = float(_helical_R(R1, R2, np.array((z0 - k2) / k1))[0])  # thread radius on the helicoids

    def thread_rho(phi: Array, z: Array) -> Array:
        return _helical_R(R1, R2, (z - k2) / k1 - starts * phi)[0]

    def solid(p: Array) -> Array:
        rho = _radial(p)
        phi = np.mod(np.arctan2(p[:, 1], p[:, 0]), TAU)
        w = p[:, 2] - z0 - c * phi
        return (phi > 0) & (phi < Phi) & (w > 0) & (w < h) & (rho > rb) & (rho < thread_rho(phi, p[:, 2]))

    periods = int(np.ceil((h + c * Phi) / T)) + 2
    z_lo = z0 - T
    ez = np.array([0.0, 0, 1])
    d_end = np.array([np.cos(Phi), np.sin(Phi), 0.0])
    plane_size = (R2 * 1.2, h * 1.2)
    faces = [
        _Face("thread", "helical_surface", {"R1": float(R1), "R2": float(R2), "k1": float(k1), "starts": starts,
                                            "periods": periods, "k2": float((k2 - z_lo) % T), "arc": (0.0, float(Phi))},
              np.eye(3), np.array([0.0, 0.0, z_lo])),
        _Face("side φ=0", "plane", {"size": plane_size}, _frame((0, -1, 0), (1, 0, 0)), np.array([0.55 * R2, 0, z0 + h / 2])),
        _Face("side φ=Φ", "plane", {"size": plane_size},
              _frame(np.cross(ez, d_end), d_end), 0.55 * R2 * d_end + np.array([0, 0, z0 + c * Phi + h / 2])),
        _Face("strip low", "helical_strip", {"r_inner": float(rb), "r_outer": a_edge, "c": float(c),
                                             "v_range": (0.0, float(Phi))}, np.eye(3), np.array([0.0, 0.0, z0])),
        _Face("strip high", "helical_strip", {"r_inner": float(rb), "r_outer": a_edge, "c": float(c),
                                              "v_range": (0.0, float(Phi))}, np.eye(3), np.array([0.0, 0.0, z0 + h])),
        _Face("bore", "cylinder", {"radius": float(rb), "height": float(h + c * Phi) * 1.1, "arc": (0.0, float(Phi))},
              np.eye(3), np.array([0.0, 0.0, z0 + (h + c * Phi) / 2])),
    ]
    return _part(st, f"screw_part-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


SAMPLERS.update({
    "helical_surface": Sampler(sample_helical_surface, _helical_surface_area, _helical_surface_local,
                               _helical_surface_random),
    "helical_strip": Sampler(sample_helical_strip, _helical_strip_area, _helical_strip_local, _helical_strip_random),
    "annulus": Sampler(sample_annulus, _annulus_area, _annulus_local, _annulus_random),
})
PARAM_KINDS.update({
    "ref_direction": "direction",
    "R1": "length",
    "R2": "length",
    "k1": "length",
    "k2": "length",
    "n": "invariant",
    "r_inner": "length",
    "r_outer": "length",
    "pitch": "length",
    "handedness": "invariant",
})
PARTS.update({"screw_part": screw_part})
__all__ += ["sample_helical_surface", "sample_helical_strip", "sample_annulus", "screw_part"]


# --------------------------------------------------------------------------------------------
# Issue 3, complex families: ellipsoid, surface_of_revolution (and the part "ellipsoid_part")
# --------------------------------------------------------------------------------------------


def _ellipsoid_grid(semi_axes: Any, polar_range: tuple[float, float], arc: tuple[float, float],
                    nu: int = 400, nt: int = 400) -> tuple[Array, Array]:
    """Midpoint grid of the unit-sphere patch (cos polar uniform, azimuth uniform) and the
    ellipsoid's area density per unit solid angle at each node, e0 e1 e2 · |s / e|."""
    e = np.asarray(semi_axes, float)
    c0, c1 = np.cos(polar_range[1]), np.cos(polar_range[0])
    uu = c0 + (c1 - c0) * (np.arange(nu) + 0.5) / nu
    tt = arc[0] + (arc[1] - arc[0]) * (np.arange(nt) + 0.5) / nt
    U, Tt = np.meshgrid(uu, tt, indexing="ij")
    rho = np.sqrt(np.clip(1 - U * U, 0, None))
    S = np.stack([rho * np.cos(Tt), rho * np.sin(Tt), U], -1).reshape(-1, 3)
    return S, float(np.prod(e)) * np.linalg.norm(S / e, axis=1)


def sample_ellipsoid(
    rng: np.random.Generator,
    n: int,
    semi_axes: Any = (1.0, 1.0, 0.5),
    polar_range: tuple[float, float] = (0.0, np.pi),
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Area-uniform points on the ellipsoid Σ (x_k / e_k)² = 1 centred at the origin, axes x, y, z.

    ``polar_range`` (rad) bounds the angle from +z of the unit-sphere point s that maps to
    x = e ∘ s, ``arc`` its azimuth. The map's area factor e0 e1 e2 |s / e| is honoured by importance
    resampling without replacement from a pool of 10 n uniform sphere points (the factor varies by
    at most max(e) / min(e), so the pool is far larger than needed; weighted sampling without
    replacement by the keys U^(1/w), Efraimidis–Spirakis). Returns points (n, 3) and outward unit
    normals (n, 3).
    """
    e = np.asarray(semi_axes, float)
    p0, p1 = _span(polar_range)
    a0, a1 = _span(arc)
    m = 10 * int(n)
    u = np.cos(p1) + (np.cos(p0) - np.cos(p1)) * rng.random(m)
    th = a0 + (a1 - a0) * rng.random(m)
    rho = np.sqrt(np.clip(1.0 - u * u, 0.0, None))
    S = np.column_stack([rho * np.cos(th), rho * np.sin(th), u])
    w = np.linalg.norm(S / e, axis=1)
    keys = np.log(rng.random(m)) / w
    pick = np.argpartition(-keys, int(n) - 1)[: int(n)] if n < m else np.arange(m)
    S = S[pick]
    nrm = S / e
    return S * e, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _ellipsoid_area(semi_axes: Any = (1.0, 1.0, 0.5), polar_range: tuple[float, float] = (0.0, np.pi),
                    arc: tuple[float, float] = (0.0, TAU)) -> float:
    """Area by the midpoint rule on a 400 × 400 grid of the sphere patch (deterministic)."""
    _, dens = _ellipsoid_grid(semi_axes, polar_range, arc)
    solid = (np.cos(polar_range[0]) - np.cos(polar_range[1])) * (arc[1] - arc[0])
    return float(dens.mean() * solid)


def _distinct_axis(e: Array) -> int:
    """Index of the semi-axis farthest from the other two (a revolution ellipsoid's axis)."""
    gaps = [min(abs(e[i] - e[j]) for j in range(3) if j != i) for i in range(3)]
    return int(np.argmax(gaps))


def _ellipsoid_local(semi_axes: Any = (1.0, 1.0, 0.5), **_: Any) -> dict[str, Any]:
    e = np.asarray(semi_axes, float)
    order = np.argsort(e, kind="stable")
    return {"center": list(_O), "axis": np.eye(3)[_distinct_axis(e)].tolist(),
            "semi_axes": e[order].tolist(), "axes": np.eye(3)[order].tolist()}


def _ellipsoid_random(rng: np.random.Generator) -> dict[str, Any]:
    """Of revolution (p, p, q) or with three axes; min/max semi-axis ≤ 0.8; whole or a cap."""
    if rng.random() < 0.5:
        p = float(rng.uniform(0.5, 1.0))
        ratio = float(rng.uniform(0.45, 0.8)) if rng.random() < 0.5 else 1.0 / float(rng.uniform(0.5, 0.8))
        e = [p, p, p * ratio]
    else:
        e0 = float(rng.uniform(0.5, 0.8))
        e1 = e0 * float(rng.uniform(1.2, 1.5))
        e = [e0, e1, e1 * float(rng.uniform(1.2, 1.5))]
        e = [e[k] for k in rng.permutation(3)]
    cap = (0.0, np.pi) if rng.random() < 0.6 else (0.0, float(rng.uniform(0.6 * np.pi, 0.85 * np.pi)))
    return {"semi_axes": tuple(e), "polar_range": cap}


def _profile(name: str):
    from .families.revolution import PROFILES  # the family's dictionary of meridian curves

    return PROFILES[name]


def _revolution_table(profile: str, params: Any, u_range: tuple[float, float], m: int = 4097):
    """u samples (m,), curve (2, m) and cumulative area-per-turn CDF (m,) (trapezoid on ρ ds)."""
    prof = _profile(profile)
    u = np.linspace(u_range[0], u_range[1], m)
    c = prof.curve(u, np.asarray(params, float))
    ds = np.linalg.norm(np.diff(c, axis=1), axis=0)
    dA = 0.5 * (np.abs(c[0, 1:]) + np.abs(c[0, :-1])) * ds
    return u, c, np.concatenate([[0.0], np.cumsum(dA)])


def sample_revolution(
    rng: np.random.Generator,
    n: int,
    profile: str = "paper",
    params: Any = (1.0,),
    u_range: tuple[float, float] = (1.0, 1.5),
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Area-uniform points on the surface of revolution of a profile of
    :data:`houghcad.families.revolution.PROFILES` about z: ``(f1 cos v, f1 sin v, f2)``.

    u is drawn by inverse CDF of the area element ρ ds (a dense table, then Newton-free linear
    interpolation on 4097 samples), v uniformly in ``arc``. Normals are the profile's normals
    turned about the axis (sign: (f2', −f1') in the meridian plane).
    """
    prof = _profile(profile)
    u_tab, _, cdf = _revolution_table(profile, params, u_range)
    a0, a1 = _span(arc)
    u = np.interp(rng.random(n) * cdf[-1], cdf, u_tab)
    v = a0 + (a1 - a0) * rng.random(n)
    th = np.asarray(params, float)
    c, d1, _ = prof.derivs(u, th)
    nm = np.stack([d1[1], -d1[0]])
    nm = nm / np.linalg.norm(nm, axis=0)
    cv, sv = np.cos(v), np.sin(v)
    pts = np.column_stack([c[0] * cv, c[0] * sv, c[1]])
    nrm = np.column_stack([nm[0] * cv, nm[0] * sv, nm[1]])
    return pts, nrm


def _revolution_area(profile: str = "paper", params: Any = (1.0,), u_range: tuple[float, float] = (1.0, 1.5),
                     arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float(_revolution_table(profile, params, u_range)[2][-1] * (arc[1] - arc[0]))


def _revolution_local(profile: str = "paper", params: Any = (1.0,), **_: Any) -> dict[str, Any]:
    prof = _profile(profile)
    out: dict[str, Any] = {"axis_point": list(_O), "axis": list(_Z), "profile": profile}
    out.update({k: float(v) for k, v in zip(prof.params, params)})
    return out


def _revolution_random(rng: np.random.Generator) -> dict[str, Any]:
    """The paper's profile (a u, a / u⁵), u in [0.78–0.85, 1.7–1.9], or an elliptic torus (ellipse
    centred at ρ = R, semi-axes p, q with q / p in [0.5, 0.7] or [1.4, 2]); full turn or part of
    one. Narrower ranges are tori within the noise (u in [0.95, 1.45]: a torus fits to 0.4 σ at
    noise 0.005), so they are not a test of this family."""
    if rng.random() < 0.5:
        a = float(rng.uniform(0.6, 1.0))
        return {"profile": "paper", "params": (a,),
                "u_range": (float(rng.uniform(0.78, 0.85)), float(rng.uniform(1.7, 1.9))),
                "arc": _partial(rng, 0.5, 0.9 * np.pi, 1.7 * np.pi)}
    R = float(rng.uniform(0.8, 1.2))
    p = R * float(rng.uniform(0.3, 0.5))
    q = p * (float(rng.uniform(1.4, 2.0)) if rng.random() < 0.5 else float(rng.uniform(0.5, 0.7)))
    return {"profile": "ellipse", "params": (R, p, q), "u_range": _partial(rng, 0.6, 1.2 * np.pi, 1.8 * np.pi),
            "arc": _partial(rng, 0.5, 0.9 * np.pi, 1.7 * np.pi)}


def ellipsoid_part(
    seed: int = 0,
    n_points: int = 20000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Block with an ellipsoidal dome on its top face and a cylindrical boss with a torus fillet.

    Part frame: block [-Lx/2, Lx/2] × [-Ly/2, Ly/2] × [0, H]. The dome is the upper half of an
    ellipsoid with three different semi-axes (min/max ≤ 0.75) centred on the top face; the boss
    (cylinder + top disc) stands beside it, blended into the top face by a concave torus fillet.
    The solid is trimmed like the other parts (see :func:`filleted_block`).

    Primitives (10): 0–5 box planes (-x, +x, -y, +y, -z, +z), 6 ellipsoid (dome), 7 boss cylinder,
    8 boss top plane, 9 fillet torus.
    """
    st = _Streams.from_seed(seed, "ellipsoid_part")
    g = st.shape
    Lx, Ly, H = g.uniform(4.0, 5.0), g.uniform(2.4, 3.0), g.uniform(0.8, 1.2)
    ex = g.uniform(0.9, 1.1)
    e = np.array([ex, ex * g.uniform(0.75, 0.85), ex * g.uniform(0.55, 0.7)])  # x, y, z semi-axes
    dc = np.array([Lx / 4, 0.0, H])  # dome centre on the top face
    rb, rt = g.uniform(0.35, 0.5), g.uniform(0.12, 0.2)
    hb = g.uniform(0.5, 0.8)
    bx, by = -Lx / 4, 0.0
    lo, hi = np.array([-Lx / 2, -Ly / 2, 0.0]), np.array([Lx / 2, Ly / 2, H])

    def solid(p: Array) -> Array:
        z = p[:, 2]
        rho = _radial(p, bx, by)
        boss = (rho < rb) & (z > 0) & (z < H + hb)
        blend = (rho >= rb) & (rho < rb + rt) & (z >= H) & (z < H + rt) & (np.hypot(rho - rb - rt, z - H - rt) > rt)
        dome = np.sum(((p - dc) / e) ** 2, axis=1) < 1.0
        return _in_box(p, lo, hi) | boss | blend | dome

    faces = _box_faces(lo, hi) + [
        _Face("dome", "ellipsoid", {"semi_axes": tuple(e), "polar_range": (0.0, np.pi / 2)}, np.eye(3), dc),
        _cyl_face("boss wall", (bx, by, H + hb / 2), rb, hb),
        _disc_face("boss top", (bx, by, H + hb), rb),
        _Face("boss fillet", "torus", {"major": float(rb + rt), "minor": float(rt), "v_range": (np.pi, 1.5 * np.pi)},
              np.eye(3), np.array([bx, by, H + rt])),
    ]
    return _part(st, f"ellipsoid_part-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


SAMPLERS.update({
    "ellipsoid": Sampler(sample_ellipsoid, _ellipsoid_area, _ellipsoid_local, _ellipsoid_random),
    "surface_of_revolution": Sampler(sample_revolution, _revolution_area, _revolution_local, _revolution_random),
})
PARAM_KINDS.update({
    "semi_axes": "lengths",
    "axes": "directions",
    "profile": "label",
    "a": "length",
    "ring_radius": "length",
    "radial_semi_axis": "length",
    "axial_semi_axis": "length",
    "slope": "invariant",
})
PARTS.update({"ellipsoid_part": ellipsoid_part})
__all__ += ["ellipsoid_part", "sample_ellipsoid", "sample_revolution"]


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
    u0, u1 = _span(u_range)
    v0, v1 = _span(v_range)

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


__all__ += ["sample_parametric"]
