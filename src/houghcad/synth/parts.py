"""Synthetic mechanical parts with simple surfaces (block with a hole and a slot, plate with
holes, grooved shaft, double-tapered part, gear-like disc, filleted block), the table of
every part (:data:`PARTS`, the complex ones of :mod:`.complex` too), the Fit4CAD
ground-truth writer and the bundled demo cloud."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..families._sampling import TAU
from ._faces import _box_faces, _cyl_face, _disc_face, _Face, _frame, _in_box, _part, _radial
from .complex import COMPLEX_PARTS
from .primitives import SynthCloud, _Streams
from .paper import PAPER_PARTS
from .small_faces import SMALL_FACE_PARTS

Array = np.ndarray


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


def rounded_tube(
    seed: int = 0,
    n_points: int = 5000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Thick-walled tube whose top end is rounded on both edges, a narrow flat between them.

    Part frame: wall Ri < ρ < Ro about the z axis, 0 ≤ z ≤ H. The outer and inner top edges are
    rounded by quarter tori of one minor radius, which take most of the wall's thickness: the
    flat annulus left on top is a fifth of it. Its normal lines, like those of a single tube
    round the whole wall end, meet between the two fillets' centres.

    Primitives (6): 0 outer cylinder, 1 inner cylinder, 2 bottom annulus, 3 top flat annulus,
    4 outer fillet torus (outer-upper quarter of its tube), 5 inner fillet torus (inner-upper
    quarter).
    """
    st = _Streams.from_seed(seed, "rounded_tube")
    g = st.shape
    Ro, Ri, H = g.uniform(9.0, 10.0), g.uniform(3.0, 3.5), g.uniform(15.0, 20.0)
    rf = (Ro - Ri) * g.uniform(0.38, 0.42)
    zc = H - rf  # the fillets' tube centres

    def solid(p: Array) -> Array:
        rho, z = _radial(p), p[:, 2]
        top = z > zc
        outer_cut = top & (rho > Ro - rf) & (np.hypot(rho - (Ro - rf), z - zc) > rf)
        inner_cut = top & (rho < Ri + rf) & (np.hypot(rho - (Ri + rf), z - zc) > rf)
        return (rho > Ri) & (rho < Ro) & (z > 0) & (z < H) & ~outer_cut & ~inner_cut

    faces = [
        _cyl_face("outer wall", (0, 0, H / 2), Ro, H),
        _cyl_face("inner wall", (0, 0, H / 2), Ri, H),
        _disc_face("bottom", (0, 0, 0), Ro, (0, 0, -1)),
        _disc_face("top flat", (0, 0, H), Ro),
        _Face("outer fillet", "torus", {"major": float(Ro - rf), "minor": float(rf), "v_range": (0.0, np.pi / 2)},
              np.eye(3), np.array([0.0, 0.0, zc])),
        _Face("inner fillet", "torus", {"major": float(Ri + rf), "minor": float(rf), "v_range": (np.pi / 2, np.pi)},
              np.eye(3), np.array([0.0, 0.0, zc])),
    ]
    return _part(st, f"rounded_tube-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


def filleted_disc(
    seed: int = 0,
    n_points: int = 5000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """Flat disc with a central hole whose rim is rounded on both edges, a narrow band between.

    Part frame: Ri < ρ < Ro, 0 ≤ z ≤ H. The rim's top and bottom edges are rounded by quarter
    tori of one minor radius, which take most of the thickness: the cylinder band left between
    them is a fifth of it. The two tubes share the axis and both radii, and their centres lie at
    different heights: the normal lines of the whole rim meet between them.

    Primitives (6): 0 top annulus, 1 bottom annulus, 2 rim cylinder (the band), 3 hole cylinder,
    4 upper fillet torus (outer-upper quarter of its tube), 5 lower fillet torus (outer-lower).
    """
    st = _Streams.from_seed(seed, "filleted_disc")
    g = st.shape
    Ro, Ri, H = g.uniform(18.0, 20.0), g.uniform(4.0, 6.0), g.uniform(3.5, 4.5)
    rf = H * g.uniform(0.38, 0.42)
    Rc, z_lo, z_hi = Ro - rf, rf, H - rf  # the tubes' centre circles

    def solid(p: Array) -> Array:
        rho, z = _radial(p), p[:, 2]
        upper = (z > z_hi) & (rho > Rc) & (np.hypot(rho - Rc, z - z_hi) > rf)
        lower = (z < z_lo) & (rho > Rc) & (np.hypot(rho - Rc, z - z_lo) > rf)
        return (rho > Ri) & (rho < Ro) & (z > 0) & (z < H) & ~upper & ~lower

    faces = [
        _disc_face("top", (0, 0, H), Ro),
        _disc_face("bottom", (0, 0, 0), Ro, (0, 0, -1)),
        _cyl_face("rim", (0, 0, H / 2), Ro, H),
        _cyl_face("hole", (0, 0, H / 2), Ri, H),
        _Face("upper fillet", "torus", {"major": float(Rc), "minor": float(rf), "v_range": (0.0, np.pi / 2)},
              np.eye(3), np.array([0.0, 0.0, z_hi])),
        _Face("lower fillet", "torus", {"major": float(Rc), "minor": float(rf), "v_range": (1.5 * np.pi, 2 * np.pi)},
              np.eye(3), np.array([0.0, 0.0, z_lo])),
    ]
    return _part(st, f"filleted_disc-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


#: Part name → generator function (each takes ``seed=`` and returns a :class:`SynthCloud`).
PARTS: dict[str, Callable[..., SynthCloud]] = {
    "block_with_hole_and_slot": block_with_hole_and_slot,
    "plate_with_holes": plate_with_holes,
    "shaft_with_groove": shaft_with_groove,
    "mirrored_cones": mirrored_cones,
    "gear_like": gear_like,
    "filleted_block": filleted_block,
    "rounded_tube": rounded_tube,
    "filleted_disc": filleted_disc,
    **COMPLEX_PARTS,
    **SMALL_FACE_PARTS,
    **PAPER_PARTS,
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

    ply_path = Path(path) if path is not None else Path(__file__).parent.parent / "data" / "demo_part.ply"
    cloud = block_with_hole_and_slot(seed=7, n_points=12000, noise=0.001)
    vert = np.empty(len(cloud.points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    for j, c in enumerate("xyz"):
        vert[c] = cloud.points[:, j]
    ply = PlyData([PlyElement.describe(vert, "vertex")], text=False, byte_order="<")
    _atomic_write(ply_path, ply.write, "wb")
    write_fit4cad_segments(cloud, ply_path.with_name(ply_path.stem + "_primitives.txt"))
    return cloud
