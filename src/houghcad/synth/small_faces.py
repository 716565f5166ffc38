"""A part with many small faces: an L-bracket carrying chamfers, plain, counterbored and
countersunk holes and small bosses, 46 faces of which most hold 20–100 points at 8,000 points
(:func:`bracket`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ._faces import _cyl_face, _disc_face, _Face, _frame, _part, _radial
from .primitives import SynthCloud, _Streams

Array = np.ndarray

#: Base-plate feature kinds, one per grid slot: plain hole, counterbore, boss (4 of 20 slots empty).
_BASE_SLOTS = ("hole",) * 8 + ("counterbore",) * 4 + ("boss",) * 4 + ("",) * 4
#: Upright feature kinds, one per slot along y.
_UPRIGHT_SLOTS = ("hole", "hole", "countersink", "countersink")
#: Half-angle of the countersinks (rad).
_ALPHA = np.deg2rad(45.0)


def bracket(
    seed: int = 0,
    n_points: int = 8000,
    noise: float = 0.0,
    pose: bool = True,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """L-bracket with many small faces.

    Part frame: base plate [0, Lx] × [0, Ly] × [0, T], upright [0, W] × [0, Ly] × [T, T + Hu].
    Both end edges of the base (x = Lx) and both top edges of the upright are chamfered (45°, a
    few spacings wide). A 4 × 5 grid on the base top holds, in a seeded order, 8 through-holes,
    4 counterbored holes (narrow hole, wide bore, flat annular step) and 4 cylindrical bosses
    (wall and top disc); 4 slots along the upright hold 2 through-holes and 2 holes countersunk
    (45° cone) from its front face.

    Primitives (46): 0 back plane x = 0 (base and upright), 1 bottom, 2 base top, 3 base end
    x = Lx, 4 side y = 0, 5 side y = Ly, 6 upright front x = W, 7 upright top, 8–11 chamfers
    (base end top, base end bottom, upright back, upright front), then the base features in slot
    order and the upright features in slot order. At the default 8,000 points a hole wall holds
    about 30 points, a chamfer about 60, a counterbore's step or a boss top about 20. See :func:`~houghcad.synth.single` for
    ``noise``, ``outliers``, ``pose`` and ``scale``.
    """
    st = _Streams.from_seed(seed, "bracket")
    b = _Bracket.draw(st.shape)
    return _part(st, f"bracket-{seed}", b.faces(), b.solid, n_points, noise, outliers, pose, scale)


@dataclass(frozen=True)
class _Bracket:
    """The bracket's dimensions (part units) and feature layout (see :func:`bracket`)."""

    Lx: float
    Ly: float
    T: float  # base thickness
    W: float  # upright thickness
    Hu: float  # upright height
    c: float  # chamfer leg
    r: float  # hole radius
    r2: float  # counterbore and countersink radius at the face
    d: float  # counterbore depth
    rb: float  # boss radius
    hb: float  # boss height
    slots: tuple[tuple[float, float], ...]  # base feature centres (x, y)
    kinds: tuple[str, ...]
    uz: float  # height of the upright's holes
    uys: tuple[float, ...]  # their y
    ukinds: tuple[str, ...]

    @classmethod
    def draw(cls, g: np.random.Generator) -> "_Bracket":
        Lx, Ly = g.uniform(4.0, 5.0), g.uniform(3.0, 3.5)
        T, W, Hu = g.uniform(0.3, 0.4), g.uniform(0.3, 0.4), g.uniform(1.2, 1.6)
        c, r = g.uniform(0.08, 0.12), g.uniform(0.08, 0.11)
        r2, d = r * g.uniform(2.2, 2.5), T * g.uniform(0.4, 0.5)
        rb, hb = g.uniform(0.2, 0.26), g.uniform(0.15, 0.25)
        xs = np.linspace(W + 0.55, Lx - 0.45, 5)
        ys = np.linspace(0.45, Ly - 0.45, 4)
        slots = tuple((float(x), float(y)) for y in ys for x in xs)
        kinds = tuple(_BASE_SLOTS[i] for i in g.permutation(len(_BASE_SLOTS)))
        uz = T + Hu * g.uniform(0.4, 0.55)
        uys = tuple(float(y) for y in np.linspace(0.45, Ly - 0.45, len(_UPRIGHT_SLOTS)))
        ukinds = tuple(_UPRIGHT_SLOTS[i] for i in g.permutation(len(_UPRIGHT_SLOTS)))
        return cls(Lx, Ly, T, W, Hu, c, r, r2, d, rb, hb, slots, kinds, uz, uys, ukinds)

    @property
    def top(self) -> float:
        return self.T + self.Hu

    def solid(self, p: Array) -> Array:
        """Inside test (N,) of points (N, 3) in the part frame."""
        Lx, Ly, T, W, c, r, r2, d = self.Lx, self.Ly, self.T, self.W, self.c, self.r, self.r2, self.d
        top, ta = self.top, np.tan(_ALPHA)
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        base = (x > 0) & (x < Lx) & (z > 0) & (z < T)
        base &= ((x - Lx) + (z - T) < -c) & ((x - Lx) - z < -c)
        upright = (x > 0) & (x < W) & (z >= T) & (z < top)
        upright &= (-x + (z - top) < -c) & ((x - W) + (z - top) < -c)
        body = (base | upright) & (y > 0) & (y < Ly)
        for (sx, sy), kind in zip(self.slots, self.kinds):
            rho = _radial(p, sx, sy)
            if kind == "hole":
                body &= ~((rho < r) & (z < T))
            elif kind == "counterbore":
                body &= ~(((rho < r) & (z < T)) | ((rho < r2) & (z > T - d) & (z < T + 1e-9)))
            elif kind == "boss":
                body |= (rho < self.rb) & (z >= T) & (z < T + self.hb)
        for sy, kind in zip(self.uys, self.ukinds):
            rho = np.hypot(y - sy, z - self.uz)
            air = (rho < r) & (x < W + 1e-9)
            if kind == "countersink":
                air |= (rho < (x - (W - r2 / ta)) * ta) & (x < W + 1e-9)
            body &= ~air
        return body

    def faces(self) -> list[_Face]:
        """The 46 faces in the order of :func:`bracket`'s docstring."""
        Lx, Ly, T, W, Hu, c, top = self.Lx, self.Ly, self.T, self.W, self.Hu, self.c, self.top
        ex, ey = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
        s2 = np.sqrt(0.5)
        chamfer = {"size": (Ly, c * np.sqrt(2.0))}
        faces = [
            _Face("back", "plane", {"size": (Ly, top)}, _frame((-1, 0, 0), ey), np.array([0, Ly / 2, top / 2])),
            _Face("bottom", "plane", {"size": (Lx, Ly)}, _frame((0, 0, -1), ex), np.array([Lx / 2, Ly / 2, 0])),
            _Face("base top", "plane", {"size": (Lx, Ly)}, _frame((0, 0, 1), ex), np.array([Lx / 2, Ly / 2, T])),
            _Face("base end", "plane", {"size": (Ly, T)}, _frame((1, 0, 0), ey), np.array([Lx, Ly / 2, T / 2])),
            _Face("side -y", "plane", {"size": (Lx, top)}, _frame((0, -1, 0), ex), np.array([Lx / 2, 0, top / 2])),
            _Face("side +y", "plane", {"size": (Lx, top)}, _frame((0, 1, 0), ex), np.array([Lx / 2, Ly, top / 2])),
            _Face("upright front", "plane", {"size": (Ly, Hu)}, _frame((1, 0, 0), ey),
                  np.array([W, Ly / 2, T + Hu / 2])),
            _Face("upright top", "plane", {"size": (W, Ly)}, _frame((0, 0, 1), ex), np.array([W / 2, Ly / 2, top])),
            _Face("chamfer base end top", "plane", chamfer, _frame((s2, 0, s2), ey),
                  np.array([Lx - c / 2, Ly / 2, T - c / 2])),
            _Face("chamfer base end bottom", "plane", chamfer, _frame((s2, 0, -s2), ey),
                  np.array([Lx - c / 2, Ly / 2, c / 2])),
            _Face("chamfer upright back", "plane", chamfer, _frame((-s2, 0, s2), ey),
                  np.array([c / 2, Ly / 2, top - c / 2])),
            _Face("chamfer upright front", "plane", chamfer, _frame((s2, 0, s2), ey),
                  np.array([W - c / 2, Ly / 2, top - c / 2])),
        ]
        return faces + self._feature_faces()

    def _feature_faces(self) -> list[_Face]:
        T, W, r, r2, d, rb, hb = self.T, self.W, self.r, self.r2, self.d, self.rb, self.hb
        ta = np.tan(_ALPHA)
        faces = []
        for i, ((sx, sy), kind) in enumerate(zip(self.slots, self.kinds)):
            if kind == "hole":
                faces.append(_cyl_face(f"hole {i}", (sx, sy, T / 2), r, T))
            elif kind == "counterbore":
                faces += [
                    _cyl_face(f"counterbore {i} hole", (sx, sy, (T - d) / 2), r, T - d),
                    _cyl_face(f"counterbore {i} bore", (sx, sy, T - d / 2), r2, d),
                    _disc_face(f"counterbore {i} step", (sx, sy, T - d), r2),
                ]
            elif kind == "boss":
                faces += [_cyl_face(f"boss {i} wall", (sx, sy, T + hb / 2), rb, hb),
                          _disc_face(f"boss {i} top", (sx, sy, T + hb), rb)]
        for i, (sy, kind) in enumerate(zip(self.uys, self.ukinds)):
            faces.append(_cyl_face(f"upright hole {i}", (W / 2, sy, self.uz), r, W, axis=(1, 0, 0)))
            if kind == "countersink":
                faces.append(_Face(f"countersink {i}", "cone", {"half_angle": float(_ALPHA),
                                                                "z_range": (r / ta, r2 / ta)},
                                   _frame((1, 0, 0)), np.array([W - r2 / ta, sy, self.uz])))
        return faces


#: The parts with many small faces (name → generator, like :data:`~houghcad.synth.PARTS`).
SMALL_FACE_PARTS: dict[str, Callable[..., SynthCloud]] = {"bracket": bracket}
