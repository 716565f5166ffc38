"""What :mod:`houghcad.synth` needs to know about a family (:class:`Sampler`),
and the small helpers the families' samplers share.

A family's sampler works in the family's *local standard frame* (axis z,
centre or apex at the origin) and draws points with a uniform area density
(area-correct sampling, no rejection); synth places, trims and poses the
patches. Every function takes its random generator explicitly.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

Array = np.ndarray
TAU = 2.0 * np.pi
#: Origin and z axis of the local frame, as the lists world parameters use.
ORIGIN: list[float] = [0.0, 0.0, 0.0]
Z_AXIS: list[float] = [0.0, 0.0, 1.0]


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
        Random but sensible ``shape`` keyword arguments, sizes of order 1 (used by
        :func:`houghcad.synth.single`).
    param_kinds : mapping
        How each parameter of ``local_params`` transforms under a similarity
        x → s R x + t: ``"point"``, ``"direction"``, ``"length"``, ``"invariant"``,
        ``"offset"`` (a plane's normal · x), ``"lengths"``, ``"directions"`` (rows) or
        ``"label"`` (see :func:`houghcad.synth.transform_params`).
    """

    sample: Callable[..., tuple[Array, Array]]
    area: Callable[..., float]
    local_params: Callable[..., dict[str, Any]]
    random_shape: Callable[[np.random.Generator], dict[str, Any]]
    param_kinds: Mapping[str, str] = field(default_factory=dict, hash=False)

    def __call__(self, rng: np.random.Generator, n: int, **shape: Any) -> tuple[Array, Array]:
        return self.sample(rng, n, **shape)


def span(r: tuple[float, float]) -> tuple[float, float]:
    """A non-empty range (lo, hi) as floats; ValueError when empty."""
    lo, hi = float(r[0]), float(r[1])
    if not hi > lo:
        raise ValueError(f"empty range {r!r}")
    return lo, hi


def partial(rng: np.random.Generator, p_full: float, min_span: float, max_span: float) -> tuple[float, float]:
    """A full turn with probability ``p_full``, otherwise a random sub-range (rad)."""
    if rng.random() < p_full:
        return (0.0, TAU)
    a0 = float(rng.uniform(0.0, TAU))
    return (a0, a0 + float(rng.uniform(min_span, max_span)))


def inverse_cdf(rng: np.random.Generator, n: int, x: Array, dens: Array) -> Array:
    """n samples with density ∝ ``dens`` tabulated at ``x`` (piecewise linear CDF), shape (n,)."""
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(x))])
    return np.interp(rng.random(n) * cdf[-1], cdf, x)


def draw_by_weight(rng: np.random.Generator, n: int, w_fun: Callable[[Array], Array], lo: float, hi: float,
                   m: int = 8192) -> Array:
    """``n`` draws of u in [lo, hi] with density ∝ w_fun(u) > 0 (inverse CDF on a fine grid, linear
    interpolation: the density error is O(1/m²))."""
    grid = np.linspace(lo, hi, m + 1)
    w = w_fun(grid)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(grid))])
    return np.interp(rng.random(n) * cdf[-1], cdf, grid)


# --- the n-convexity directrix of the generalised cylinder and cone --------------------------
#
# Directrix (local frame, phase 0): ρ(u) = a / (1 + b cos(order·u)), the point ρ(u)(cos u, sin u).
# The reference direction ``ref_direction`` is local x (u = 0, a point of smallest radius a / (1 + b)).
# Shape keyword ``order`` is the paper's n (the samplers' second argument is the point count).


def directrix_speed(u: Array, a: float, b: float, order: int) -> tuple[Array, Array, Array]:
    """Radius ρ(u), its derivative ρ'(u) and the speed |C'(u)| = sqrt(ρ² + ρ'²), each (m,)."""
    g = 1.0 + b * np.cos(order * u)
    r = a / g
    r1 = a * b * order * np.sin(order * u) / g**2
    return r, r1, np.hypot(r, r1)


def directrix_length(a: float, b: float, order: int, arc: tuple[float, float] = (0.0, TAU), m: int = 8192) -> float:
    u = np.linspace(arc[0], arc[1], m + 1)
    s = directrix_speed(u, a, b, order)[2]
    return float(np.sum(0.5 * (s[1:] + s[:-1]) * np.diff(u)))


def directrix_random(rng: np.random.Generator) -> tuple[int, float]:
    """Order 2–12 and b in [0.05, b_hi(order)]: b_hi = clip(4 / (order² − 1), 0.07, 0.3) keeps the
    lobes' curvature radius a / (1 + b (order² − 1)) at least a / 5 (a / 9.5 for order ≥ 8), so that
    the shape stays resolvable at 4000 points and 0.5 % noise."""
    order = int(rng.integers(2, 13))
    b_hi = float(np.clip(4.0 / (order * order - 1), 0.07, 0.3))
    return order, float(rng.uniform(0.05, b_hi))
