"""Meridian profiles of the ``surface_of_revolution`` family (:data:`PROFILES`,
:func:`register_profile`) and the helpers of its vote; see
:mod:`houghcad.families.revolution`, which re-exports the public names."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .base import Placement

# --- profiles -------------------------------------------------------------------

@dataclass
class Profile:
    """A family of meridian curves ``(f₁(u; θ), f₂(u; θ))``.

    Attributes
    ----------
    name : str
    params : tuple of str
        Names of θ (also the world parameter names).
    f1, f2 : callable ``(u (m,), *θ) -> (m,)``
        Radial and axial coordinate of the curve (numpy, vectorised in u).
    u_range : (float, float)
        Domain of u sampled for the vote and the distance.
    log_u : bool
        Sample u geometrically (scale-like parameters) rather than linearly.
    kinds : tuple of str
        ``"length"`` or ``"invariant"`` per parameter.
    bounds : tuple of (float, float)
        Search box per parameter; lengths in units of the cluster's extent.
    linear : tuple of bool
        Parameters in which the curve is affine (solved, not swept).
    vote_offset : bool
        Whether z₀ is voted; otherwise ``offset(rho, h)`` estimates it.
    symmetric : bool
        Whether the family is symmetric under z → −z (one axis orientation suffices).
    check : callable ``(dict θ) -> bool``, optional
        Rejects degenerate members (covered by simpler families).
    """

    name: str
    params: tuple[str, ...]
    f1: Callable[..., np.ndarray]
    f2: Callable[..., np.ndarray]
    u_range: tuple[float, float]
    log_u: bool = False
    kinds: tuple[str, ...] = ()
    bounds: tuple[tuple[float, float], ...] = ()
    linear: tuple[bool, ...] = ()
    vote_offset: bool = True
    offset: Callable[[np.ndarray, np.ndarray], float | None] | None = None
    symmetric: bool = False
    periodic: bool = False
    check: Callable[[dict[str, float]], bool] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def u_samples(self, m: int, lo: float | None = None, hi: float | None = None) -> np.ndarray:
        lo = self.u_range[0] if lo is None else lo
        hi = self.u_range[1] if hi is None else hi
        if self.periodic:
            return lo + (hi - lo) * np.arange(m) / m
        return np.geomspace(lo, hi, m) if self.log_u else np.linspace(lo, hi, m)

    def curve(self, u: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Curve points (2, m) at parameters u (m,)."""
        u = np.asarray(u, float)
        th = [float(t) for t in theta]
        # Called thousands of times per fit on a few hundred points: assign
        # into one array (a constant coordinate broadcasts) rather than stack.
        out = np.empty((2,) + u.shape)
        out[0] = self.f1(u, *th)
        out[1] = self.f2(u, *th)
        return out

    def derivs(self, u: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Curve, first and second u-derivatives, each (2, m) (central differences)."""
        u = np.asarray(u, float)
        h = 1e-4 * np.maximum(np.abs(u), 1.0)
        m = u.size
        c = self.curve(np.concatenate([u.ravel(), (u + h).ravel(), (u - h).ravel()]), theta)
        c0, cp, cm = (c[:, k * m:(k + 1) * m].reshape((2,) + u.shape) for k in range(3))
        return c0, (cp - cm) / (2 * h), (cp - 2 * c0 + cm) / (h * h)

    @property
    def n_voted(self) -> int:
        return len(self.params) + int(self.vote_offset)


#: Profile name → :class:`Profile`.
PROFILES: dict[str, Profile] = {}
#: Names of the profiles voted by the family.
ACTIVE: list[str] = []


def _affine_flags(f1, f2, n: int, u_range, log_u) -> tuple[bool, ...]:
    """Which parameters the curve is jointly affine in (numerical test at
    random parameters and u; a parameter that fails is swept instead)."""
    rng = np.random.default_rng(12345)
    lo, hi = u_range
    u = np.geomspace(lo, hi, 7) if log_u else np.linspace(lo, hi, 9)[1:-1]

    def F(th):
        with np.errstate(all="ignore"):
            return np.concatenate([np.broadcast_to(f1(u, *th), u.shape), np.broadcast_to(f2(u, *th), u.shape)])

    flags = []
    for k in range(n):
        ok = True
        for _ in range(3):
            th = rng.uniform(0.3, 1.3, n)
            e = np.zeros(n)
            e[k] = rng.uniform(0.2, 0.7)
            d2 = F(th) - 2 * F(th + e) + F(th + 2 * e)
            ok &= bool(np.all(np.abs(d2) <= 1e-7 * (1 + np.abs(F(th)))))
        flags.append(ok)
    # Joint affinity: no products between the affine parameters.
    lin = [k for k in range(n) if flags[k]]
    for j, k in itertools.combinations(lin, 2):
        th = rng.uniform(0.3, 1.3, n)
        ej, ek = np.zeros(n), np.zeros(n)
        ej[j], ek[k] = 0.5, 0.5
        d = F(th + ej + ek) - F(th + ej) - F(th + ek) + F(th)
        if not np.all(np.abs(d) <= 1e-7 * (1 + np.abs(F(th)))):
            flags[k] = False
    return tuple(flags)


def register_profile(name: str, f1, f2, params, bounds, kinds=None, u_range=(0.0, 1.0), log_u: bool = False,
                     periodic: bool = False, symmetric: bool = False, offset=None, check=None,
                     active: bool = True, u_symbol: str = "u") -> Profile:
    """Add a profile curve to the dictionary of the ``surface_of_revolution`` family.

    Parameters
    ----------
    name : str
        Profile name (reported as the ``profile`` world parameter).
    f1, f2 : callable ``(u, *params) -> array`` or sympy expression / string
        Radial and axial coordinates of the meridian curve. Sympy expressions
        (or strings sympy parses) use the symbol ``u_symbol`` and the names in
        ``params``; they are turned into numpy functions with ``lambdify``.
    params : sequence of str
        Parameter names, at most 2 (3 if ``offset`` estimates z₀).
    bounds : sequence of (lo, hi)
        Search box per parameter; lengths in units of the cluster's extent
        (its largest side in the cloud's standard frame), invariants absolute.
    kinds : sequence of "length" / "invariant", optional
        Default: all lengths.
    u_range, log_u, periodic, symmetric, offset, check
        See :class:`Profile`.
    active : bool
        Vote it with the family right away.

    Returns
    -------
    Profile
    """
    params = tuple(str(p) for p in params)
    if isinstance(f1, str) or isinstance(f2, str) or hasattr(f1, "free_symbols") or hasattr(f2, "free_symbols"):
        import sympy

        syms = sympy.symbols([u_symbol, *params])
        f1 = sympy.lambdify(syms, sympy.sympify(f1), "numpy")
        f2 = sympy.lambdify(syms, sympy.sympify(f2), "numpy")
    kinds = tuple(kinds) if kinds is not None else ("length",) * len(params)
    if len(bounds) != len(params) or len(kinds) != len(params):
        raise ValueError(f"profile {name!r}: one bound and one kind per parameter")
    prof = Profile(name, params, f1, f2, (float(u_range[0]), float(u_range[1])), bool(log_u), kinds,
                   tuple((float(a), float(b)) for a, b in bounds), (), offset is None, offset, bool(symmetric),
                   bool(periodic), check)
    prof.linear = _affine_flags(f1, f2, len(params), prof.u_range, prof.log_u)
    if prof.n_voted > 3:
        raise ValueError(f"profile {name!r}: {prof.n_voted} voted unknowns (at most 3; give `offset`)")
    PROFILES[name] = prof
    if active and name not in ACTIVE:
        ACTIVE.append(name)
    if not active and name in ACTIVE:
        ACTIVE.remove(name)
    return prof


def set_active_profiles(names) -> list[str]:
    """Choose the profiles the family votes (names of :data:`PROFILES`); returns the previous list."""
    names = list(names)
    unknown = [n for n in names if n not in PROFILES]
    if unknown:
        raise ValueError(f"unknown profiles {unknown} (known: {sorted(PROFILES)})")
    old = list(ACTIVE)
    ACTIVE[:] = names
    return old


def meridian_conic_offset(rho: np.ndarray, h: np.ndarray) -> float | None:
    """z₀ of the axis-aligned ellipse A ρ² + C h² + D ρ + E h + F = 0 fitted
    (algebraic least squares) to meridian points; None unless an ellipse."""
    s = max(float(np.abs(rho).max()), float(np.abs(h).max()), 1e-12)
    r, z = rho / s, h / s
    M = np.stack([r * r, z * z, r, z, np.ones_like(r)], axis=1)
    A, C, D, E, F = np.linalg.svd(M, full_matrices=False)[2][-1]
    if A * C <= 0:
        return None
    return float(-E / (2 * C) * s)


def _ellipse_ok(t: dict[str, float]) -> bool:
    # R ≈ 0 is an ellipsoid, p ≈ q a torus: the simpler families cover them.
    R, p, q = t["ring_radius"], t["radial_semi_axis"], t["axial_semi_axis"]
    return p > 0 and q > 0 and R > 0.25 * p and abs(p - q) > 0.03 * max(p, q)


register_profile("paper", lambda u, a: a * u, lambda u, a: a / u ** 5, ("a",), [(0.02, 2.0)],
                 u_range=(0.05, 20.0), log_u=True,
                 check=lambda t: t["a"] > 0)
register_profile("ellipse", lambda u, R, p, q: R + p * np.cos(u), lambda u, R, p, q: q * np.sin(u),
                 ("ring_radius", "radial_semi_axis", "axial_semi_axis"), [(0.0, 2.0), (0.02, 1.2), (0.02, 1.2)],
                 u_range=(0.0, 2 * np.pi), periodic=True, symmetric=True, offset=meridian_conic_offset,
                 check=_ellipse_ok)
register_profile("line", lambda u, k: k * u, lambda u, k: u, ("slope",), [(np.tan(np.radians(2)), np.tan(np.radians(80)))],
                 kinds=("invariant",), u_range=(1e-3, 4.0), check=lambda t: t["slope"] > 0, active=False)
register_profile("circle", lambda u, R, r: R + r * np.cos(u), lambda u, R, r: r * np.sin(u),
                 ("major_radius", "minor_radius"), [(0.0, 2.0), (0.02, 1.0)], u_range=(0.0, 2 * np.pi),
                 periodic=True, symmetric=True, check=lambda t: t["minor_radius"] > 0, active=False)


# --- voting helpers ---------------------------------------------------------------

class Tagged(np.ndarray):
    """Local points carrying their placement's info (profile, offset)."""

    info: dict = {}

    def __array_finalize__(self, obj):
        self.info = getattr(obj, "info", {})


@dataclass
class ProfilePlacement(Placement):
    def local(self, P, N):
        Pl, Nl = super().local(P, N)
        Pl = Pl.view(Tagged)
        Pl.info = self.info
        return Pl, Nl


def solve_batched(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares solutions of stacks of small systems A (..., r, c) x = b (..., r)
    through the pseudo-inverse; returns x (..., c) and a mask of well-posed ones.

    numpy's batched ``pinv`` (SVD per system) handles singular ones without
    raising, unlike a batched ``solve``. Square 3 × 3 systems (the vote's,
    hundreds of thousands per cluster) use the adjugate instead, twenty times
    faster than two SVDs; well-posed there means |det| > 1e-6 ‖A‖³ (Frobenius),
    which implies the SVD test's σ_min > 1e-6 σ_max.
    """
    if A.shape[-2:] == (3, 3):
        r0, r1, r2 = A[..., 0, :], A[..., 1, :], A[..., 2, :]
        c0, c1, c2 = np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)
        det = np.einsum("...i,...i->...", r0, c0)
        fro = np.sqrt(np.einsum("...ij,...ij->...", A, A))
        ok = np.abs(det) > 1e-6 * fro**3
        with np.errstate(all="ignore"):
            x = (c0 * b[..., 0:1] + c1 * b[..., 1:2] + c2 * b[..., 2:3]) / np.where(ok, det, 1.0)[..., None]
        return x, ok
    Ap = np.linalg.pinv(A, rcond=1e-8)
    x = np.einsum("...cr,...r->...c", Ap, b)
    s = np.linalg.svd(A, compute_uv=False)
    ok = s[..., -1] > 1e-6 * np.maximum(s[..., 0], 1e-300)
    return x, ok


def meridian_local(Pl, Nl):
    rho = np.hypot(Pl[:, 0], Pl[:, 1])
    rad = np.stack([Pl[:, 0], Pl[:, 1]], 1) / np.maximum(rho, 1e-12)[:, None]
    nr = np.einsum("ij,ij->i", Nl[:, :2], rad)
    return rho, np.asarray(Pl[:, 2]), nr, Nl[:, 2]


def theta_dict(prof: Profile, theta) -> dict[str, float]:
    return {k: float(v) for k, v in zip(prof.params, theta)}
