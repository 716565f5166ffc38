"""Standard-form frames of a user family's cluster (:func:`place`), from the
normal-based estimators of the built-in families or a callable."""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...preprocess import rotation_to_z
from ..base import Placement, axis_from_normal_lines, lines_intersection, unit
from ..cone import cone_frame
from .guard import describe, user_code, user_error

#: Standard-form estimators a family can be placed with (or a callable, see :func:`define_family`).
PLACEMENTS = ("none", "plane", "axis", "extrusion", "centre", "apex")
#: Largest deviation of R Rᵀ from the identity in a user placement (float32 axes pass).
ROTATION_TOL = 1e-5


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


def _array(x) -> np.ndarray | None:
    """``x`` as a float array, None if it is not numbers."""
    try:
        return np.asarray(x, float)
    except (TypeError, ValueError):
        return None


def _user_frames(fn, P: np.ndarray, N: np.ndarray, family: str) -> list[Placement]:
    """The frames of a placement callable, checked: (R, origin) or a list of such pairs, R a
    3 × 3 rotation (its rows the local axes), origin a point (3,). A wrong answer would
    otherwise fail deep in the vote, or put every cluster in a frame no surface fits."""
    what = "placement(...)"
    with user_code(family, what):
        got = fn(P, N)
    want = "not (R, origin) or a list of such pairs"
    single = isinstance(got, (tuple, list)) and len(got) == 2 and getattr(_array(got[0]), "ndim", 0) == 2
    try:
        pairs = [got] if single else list(got)
    except TypeError:
        raise user_error(family, what, f"returned {describe(got)}, {want}") from None
    out = []
    for pair in pairs:
        if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
            raise user_error(family, what, f"returned {describe(pair)} where a pair (R, origin) belongs")
        R, o = _array(pair[0]), _array(pair[1])
        if R is None or o is None or R.shape != (3, 3) or o.shape != (3,):
            shapes = [None if x is None else x.shape for x in (R, o)]
            raise user_error(family, what, f"returned R and origin of shapes {shapes[0]} and {shapes[1]}: "
                             "(3, 3) and (3,) needed")
        if np.isfinite(R).all() and not np.allclose(R @ R.T, np.eye(3), atol=ROTATION_TOL):
            raise user_error(family, what, "returned an R whose rows are not orthonormal (they are the local axes)")
        out.append(Placement(R, o))
    return out


def place(mode, P: np.ndarray, N: np.ndarray, family: str = "unnamed") -> list[Placement]:
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
    - a callable ``(P, N) -> (R, origin)`` or a list of them: the user's
      (checked; ``family`` names it in errors).
    x is always the principal direction of the points across z.
    """
    m = P.mean(axis=0)
    if callable(mode):
        return _user_frames(mode, P, N, family)
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
