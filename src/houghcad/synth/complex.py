"""Composite parts with complex surfaces: the generalised-cone body (paper Fig. 9(c)),
the screw-like part and the block with an ellipsoidal dome.

World-parameter conventions of their complex faces (lengths in the cloud's units):

- helical_surface: ``axis_point``, ``axis`` (unit), ``ref_direction`` (unit, orthogonal to the
  axis: the direction of φ = 0), ``R1`` < ``R2`` (smallest and largest radius), ``n`` (integer
  ≠ 0, its sign the handedness), ``k1`` > 0, ``k2`` (phase along the axis, in [0, 2π k1)). In
  the frame (ref_direction, axis × ref_direction, axis) at axis_point the surface is
  x = R(u) cos v, y = R(u) sin v, z = k1 (u + n v) + k2, R(u) = R1 + (R2 − R1)(cos u + 1)/2:
  the crests (radius R2) in the half-plane of ref_direction sit at k2 + 2π k1 m along the axis.
- helical_strip: ``axis_point``, ``axis``, ``ref_direction`` (the strip's ruling through
  axis_point points along it), ``r_inner`` < ``r_outer``, ``pitch`` (> 0, axial advance per
  turn), ``handedness`` (+1 right-handed, −1 left-handed): x = ρ cos v, y = ρ sin v,
  z = handedness · pitch/(2π) · v, r_inner ≤ ρ ≤ r_outer.
- generalized_cylinder / generalized_cone: the directrix ρ(u) = a / (1 + b cos(n·u)) with
  ``ref_direction`` along u = 0 (see :mod:`houghcad.families.generalized_cylinder`).
- ellipsoid: ``center``, ``axis``, ``semi_axes`` (ascending), ``axes`` (rows, matching).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..families._sampling import TAU
from ..families.helical_surface import helical_radius
from ._faces import _box_faces, _cyl_face, _disc_face, _Face, _frame, _in_box, _part, _radial
from .primitives import SynthCloud, _Streams

Array = np.ndarray


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
    a_edge = float(helical_radius(R1, R2, np.array((z0 - k2) / k1))[0])  # thread radius on the helicoids

    def thread_rho(phi: Array, z: Array) -> Array:
        return helical_radius(R1, R2, (z - k2) / k1 - starts * phi)[0]

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


#: The complex parts (name → generator, like :data:`~houghcad.synth.PARTS`).
COMPLEX_PARTS: dict[str, Callable[..., SynthCloud]] = {
    "generalized_cone_part": generalized_cone_part,
    "screw_part": screw_part,
    "ellipsoid_part": ellipsoid_part,
}
