"""Poses of synthetic clouds: random rotations and similarities, and how a
primitive's world parameters transform under them (:data:`PARAM_KINDS`, from the
families' samplers)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from ..families import FamilyTable, Sampler

Array = np.ndarray

#: Family name → :class:`~houghcad.families.Sampler` of every registered family that has one
#: (a live view of the registry: a family plugs in with its ``sampler`` attribute).
SAMPLERS: Mapping[str, Sampler] = FamilyTable("sampler")


def param_kinds() -> dict[str, str]:
    """How each parameter name transforms under x → s R x + t, from the samplers'
    ``param_kinds`` in registry order. Where a family gives a name another kind than an
    earlier family did, its entry is keyed ``"family.name"`` (looked up first)."""
    table: dict[str, str] = {}
    for fam, sampler in SAMPLERS.items():
        for key, kind in sampler.param_kinds.items():
            if table.setdefault(key, kind) != kind:
                table[f"{fam}.{key}"] = kind
    return table


class _ParamKinds(Mapping[str, str]):
    """Live read-only view of :func:`param_kinds`."""

    def __getitem__(self, key: str) -> str:
        return param_kinds()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(param_kinds())

    def __len__(self) -> int:
        return len(param_kinds())

    def __repr__(self) -> str:
        return repr(param_kinds())


#: How each parameter name transforms under x → s R x + t (:func:`param_kinds`). A
#: ``"family.name"`` key overrides ``"name"`` for that family (the same letter can be a length
#: in one family, a ratio in another).
PARAM_KINDS: Mapping[str, str] = _ParamKinds()


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
    rules come from :data:`PARAM_KINDS`, i.e. the families' samplers). Vectors come back as lists of floats.
    """
    R = np.asarray(R, float)
    t = np.asarray(t, float)
    kinds = param_kinds()
    out: dict[str, Any] = {}
    for key, val in params.items():
        kind = kinds.get(f"{type}.{key}", kinds.get(key))
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
            raise ValueError(f"{type}: don't know how parameter {key!r} transforms (add it to the family sampler's param_kinds)")
    return out
