"""Standard-form frames of a user family's cluster (:func:`place`), from the
normal-based estimators of the built-in families or a callable."""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...preprocess import rotation_to_z
from ..base import Placement, axis_from_normal_lines, lines_intersection, unit
from ..cone import cone_frame

#: Standard-form estimators a family can be placed with (or a callable, see :func:`define_family`).
PLACEMENTS = ("none", "plane", "axis", "extrusion", "centre", "apex")


def _x_axis(P: np.ndarray, origin: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Local x: the principal direction of the points across z, its sign set by
    the third moment (deterministic for a given shape)."""
    Q = P - origin
    Q = Q - np.outer(Q @ z, z)
    C = Q - Q.mean(axis=0)
    x = np.linalg.eigh(C.T @ C)[1][:, -1]
    t = C @ x
    if np.sum(t**3) < 0:
        x = -x
    return x


def _frame(P: np.ndarray, origin: np.ndarray, z: np.ndarray) -> Placement:
    """Placement with local z = ``z`` (sign: positive third moment of the points
    along it) and x from :func:`_x_axis`."""
    z = unit(z)
    h = (P - origin) @ z
    if np.sum((h - h.mean()) ** 3) < 0:
        z = -z
    R = rotation_to_z(z, _x_axis(P, origin, z))
    return Placement(R, np.asarray(origin, float))


def place(mode, P: np.ndarray, N: np.ndarray) -> list[Placement]:
    """Standard-form frames of a cluster (points P, normals N: (n, 3)).

    - ``"none"``: the cloud's own standard frame;
    - ``"plane"``: z the dominant normal direction, origin the centroid;
    - ``"axis"``: surfaces of revolution: the axis is the line meeting the
      normal lines; origin the centroid's foot on it;
    - ``"extrusion"``: z the direction least represented among the normals,
      origin the algebraic circle centre of the section, at the centroid;
    - ``"centre"``: origin where the normal lines meet, axes the principal
      axes of the points around it (x the widest);
    - ``"apex"``: origin where the tangent planes meet, z the cone axis;
    - a callable ``(P, N) -> (R, origin)`` or a list of them: the user's.
    x is always the principal direction of the points across z.
    """
    m = P.mean(axis=0)
    if callable(mode):
        got = mode(P, N)
        got = [got] if isinstance(got, tuple) and len(got) == 2 and np.ndim(got[0]) == 2 else list(got)
        return [Placement(np.asarray(R, float), np.asarray(o, float)) for R, o in got]
    if mode == "none":
        return [Placement(np.eye(3), np.zeros(3))]
    if mode == "plane":
        return [_frame(P, m, np.linalg.eigh(N.T @ N)[1][:, -1])]
    if mode == "axis":
        q, a, _, _ = axis_from_normal_lines(P, N)
        return [_frame(P, q + ((m - q) @ a) * a, a)]
    if mode == "extrusion":
        a = np.linalg.eigh(N.T @ N)[1][:, 0]
        R = rotation_to_z(a)
        Q = (P - m) @ R.T
        A = np.c_[2 * Q[:, :2], np.ones(len(Q))]
        c = np.linalg.lstsq(A, (Q[:, :2] ** 2).sum(1), rcond=None)[0]
        return [_frame(P, m + R.T @ np.array([c[0], c[1], 0.0]), a)]
    if mode == "centre":
        c, cond = lines_intersection(P, N)
        if cond < 1e-6:
            return []
        Q = P - c
        w, V = np.linalg.eigh(Q.T @ Q)
        return [_frame(P, c, V[:, 0])]
    if mode == "apex":
        fr = cone_frame(P, N)
        if fr is None:
            return []
        apex, a = fr
        R = rotation_to_z(a, _x_axis(P, apex, a))
        return [Placement(R, apex)]
    raise InputError(f"unknown placement {mode!r} (known: {', '.join(PLACEMENTS)}, or a callable)")
