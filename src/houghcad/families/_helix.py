"""Helpers shared by the helical and annular families (not a family itself).

Cylindrical coordinates in a frame with a reference direction, the screw
axis of a point set from its normal lines, and the radial extent of a band
of points (helical strip, annulus) blurred by noise.
"""

from __future__ import annotations

import numpy as np

from ..preprocess import rotation_to_z
from .base import Placement, axis_from_normal_lines, unit


def frame_axes(axis: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal (e1, e2, a): a the unit axis, e1 the reference direction made
    orthogonal to it, e2 = a × e1 (so that φ grows right-handedly about a)."""
    a = unit(axis)
    e1 = unit(ref - (ref @ a) * a)
    return e1, np.cross(a, e1), a


def cylindrical(P: np.ndarray, point: np.ndarray, axis: np.ndarray, ref: np.ndarray):
    """Cylindrical coordinates of points P (n, 3) about the line (point, axis).

    Returns rho (n,), phi (n,) in (−π, π] measured from ``ref`` about the
    axis, z (n,) along the axis from ``point``, and the frame (e1, e2, a).
    """
    e1, e2, a = frame_axes(axis, ref)
    d = P - point
    x, y, z = d @ e1, d @ e2, d @ a
    return np.hypot(x, y), np.arctan2(y, x), z, (e1, e2, a)


#: Largest residual of the normal lines' complex fit, relative to the points'
#: mean squared distance from their centroid, for which a whole cloud counts as
#: screw-invariant in the global round. Measured (noise 0.5 % of the
#: diagonal): helical strips and surfaces 0.6-3e-3; the synthetic parts that
#: hold several surfaces 3e-2-1e-1.
GLOBAL_COMPLEX_RESIDUAL = 1e-2
#: Fraction of the normal lines left out of the whole-cloud complex fit on
#: noisy clouds (:func:`screw_placement`). There the simple families are voted
#: on the whole cloud and slice a thread into tori and cylinders before any
#: cluster round; the ends of a threaded part (about a tenth of it) must not
#: hide that the rest is one screw. Measured (noise 0.5 %): the screw part
#: 0.001 with it (0.047 without), the generalised-cone and ellipsoid parts
#: 0.024 and 0.040.
NOISY_TRIM = 0.2


def screw_placement(P: np.ndarray, N: np.ndarray, trim: float = 0.0) -> tuple[Placement, float, float]:
    """Standard frame of a screw-invariant point set from its normal lines.

    The normal lines of a helical surface (or helicoid) belong to a linear
    line complex whose axis is the helix axis and whose pitch p is the axial
    advance per radian (Pottmann & Randrup): :func:`axis_from_normal_lines`.
    The origin is the foot of the points' centroid on the axis.

    With ``trim`` > 0 the complex is fitted again, twice, on the lines it
    fits best, leaving out that fraction (the other faces of a part: the
    ends of a threaded sector), and the residual is theirs.

    Returns the placement (local z = axis), the pitch p (standard units per
    radian, signed: p > 0 right-handed) and the fit residual relative to the
    points' mean squared distance from their centroid.
    """
    q, a, p, res = axis_from_normal_lines(P, N)
    sel = np.arange(len(P))
    if trim > 0 and len(P) >= 20:
        m0 = P.mean(axis=0)
        L = np.cross(P - m0, N)
        for _ in range(2):
            # Each line's residual c·(p × n) + c̄·n with the complex (c, c̄) = (a, p a + (q − m0) × a).
            e = np.abs(L @ a + N @ (p * a + np.cross(q - m0, a)))
            sel = np.flatnonzero(e <= np.quantile(e, 1.0 - trim))
            q, a, p, res = axis_from_normal_lines(P[sel], N[sel])
    m = P[sel].mean(axis=0)
    q = q + ((m - q) @ a) * a
    return Placement(rotation_to_z(a), q), float(p), relative_complex_residual(P[sel], res)


def gated_screw_placement(P: np.ndarray, N: np.ndarray, ctx) -> tuple[Placement, float] | None:
    """:func:`screw_placement` behind the helical families' whole-cloud gate:
    in the global round (``ctx.local`` False) the cloud must be one
    screw-invariant surface (residual at most :data:`GLOBAL_COMPLEX_RESIDUAL`;
    on noisy clouds with :data:`NOISY_TRIM` of the lines left out), else None
    and the per-cluster rounds decide. Returns (placement, pitch)."""
    pl, p, res = screw_placement(P, N, NOISY_TRIM if not ctx.local and ctx.noisy else 0.0)
    if not ctx.local and res > GLOBAL_COMPLEX_RESIDUAL:
        return None
    return pl, p


def relative_complex_residual(P: np.ndarray, res: float) -> float:
    """The residual of :func:`axis_from_normal_lines` on the points P (n, 3),
    relative to their mean squared distance from their centroid: below
    :data:`GLOBAL_COMPLEX_RESIDUAL` the whole set is one screw-invariant (or
    revolution) surface."""
    spread = float(np.mean(((P - P.mean(axis=0)) ** 2).sum(axis=1)))
    return float(res / max(spread, 1e-300))


def band_edges(rho: np.ndarray, sigma: float) -> tuple[float, float]:
    """Ends (lo, hi) of the range of values rho (n,), sampled with a density that
    is about constant near each end and blurred by Gaussian noise ``sigma``.

    Blurring moves a mass f·σ/√(2π) past each end (f: the density there, a
    fraction per unit), so each end is the quantile of that mass: unbiased by
    the noise, unlike min / max, and robust to a few stray points.
    """
    r = np.sort(np.asarray(rho, float))
    n = len(r)
    if n < 10:
        return float(r[0]), float(r[-1])
    q = lambda f: float(np.quantile(r, min(max(f, 0.0), 1.0)))  # noqa: E731
    out = []
    for side in (0, 1):
        lo_f, hi_f = (0.02, 0.12) if side == 0 else (0.88, 0.98)
        span = abs(q(hi_f) - q(lo_f))
        dens = 0.1 / max(span, 1e-12)
        mass = min(dens * sigma / np.sqrt(2 * np.pi), 0.05)
        out.append(q(mass) if side == 0 else q(1.0 - mass))
    return out[0], out[1]
