"""Composite parts: faces sampled in their own frames as untrimmed patches of
their family (:data:`~houghcad.synth.SAMPLERS`), placed in the part's frame and
trimmed against the part's solid."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ._poses import SAMPLERS, apply_transform, transform_params
from .primitives import SynthCloud, _bbox_diag, _finish, _Streams

Array = np.ndarray


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
