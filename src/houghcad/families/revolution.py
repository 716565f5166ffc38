"""Surfaces of revolution with a dictionary of profile curves (a complex family).

A surface of revolution about the local z axis is the profile curve
``(ρ, z) = (f₁(u; θ), z₀ + f₂(u; θ))`` of the meridian plane turned about the
axis (paper §4, Table 2(c)). The axis is the line that meets the normal lines
(:func:`axis_from_normal_lines`); once it is the local z axis, the unknowns
are the profile's parameters θ and the offset z₀ along the axis: at most
three, voted in one accumulator.

The vote (Γ_P sampled): the curve parameter u is swept over samples and the
profile's nonlinear parameters over their bins; the remaining unknowns, in
which the profile is affine (found numerically at registration), are solved
with the pseudo-inverse of the equations ρ = f₁, h = z₀ + f₂ and, when three
unknowns are left, the normal condition n_ρ f₁' + n_h f₂' = 0. Samples whose
curve normal disagrees with the point's normal are dropped.

Profiles (:data:`PROFILES`): ``paper`` (a u, a/u⁵), ``ellipse`` (an
axis-aligned ellipse whose centre is off the axis: an elliptic torus),
``line`` (a cone) and ``circle`` (a torus), plus user profiles added with
:func:`register_profile` (numpy callables or sympy expressions). ``line`` and
``circle`` duplicate the simple ``cone`` and ``torus`` families: they exist
for completeness and are voted only once activated with
:func:`set_active_profiles` (see docs/family-revolution.md).

The protocol's ``region`` and ``gamma`` see only the local points; the profile
of a placement rides along on them (:class:`_Tagged`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from ..hough import Grid
from ..preprocess import rotation_to_z
from ._helix import GLOBAL_COMPLEX_RESIDUAL, relative_complex_residual
from .base import (Frame, Family, Placement, Primitive, axis_from_normal_lines, radial, register,
                   regular_indices, tangent_basis, unit)
from .ellipsoid import covered_by_simple


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

class _Tagged(np.ndarray):
    """Local points carrying their placement's info (profile, offset)."""

    info: dict = {}

    def __array_finalize__(self, obj):
        self.info = getattr(obj, "info", {})


@dataclass
class _ProfilePlacement(Placement):
    def local(self, P, N):
        Pl, Nl = super().local(P, N)
        Pl = Pl.view(_Tagged)
        Pl.info = self.info
        return Pl, Nl


def _solve_batched(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


def _meridian_local(Pl, Nl):
    rho = np.hypot(Pl[:, 0], Pl[:, 1])
    rad = np.stack([Pl[:, 0], Pl[:, 1]], 1) / np.maximum(rho, 1e-12)[:, None]
    nr = np.einsum("ij,ij->i", Nl[:, :2], rad)
    return rho, np.asarray(Pl[:, 2]), nr, Nl[:, 2]


def _theta_dict(prof: Profile, theta) -> dict[str, float]:
    return {k: float(v) for k, v in zip(prof.params, theta)}


# --- the family ---------------------------------------------------------------------

@register
class SurfaceOfRevolution(Family):
    name = "surface_of_revolution"
    param_names = ("axis_point", "axis", "profile")
    n_unknowns = 3
    complexity = 7
    simple = False
    global_search = True

    # --- standard form and voting -------------------------------------------
    def placements(self, P, N, ctx):
        q, a, _, res = axis_from_normal_lines(P, N)
        if not ctx.local:
            # Whole cloud: vote only when its normal lines meet one axis (a
            # turned part), as the helical families' gate; elsewhere the faces
            # are left to the per-cluster rounds (profile fits are costly).
            if relative_complex_residual(P, res) >= GLOBAL_COMPLEX_RESIDUAL:
                return []
        h = (P - q) @ a
        base = q + a * float(np.median(h))
        out = []
        for name in ACTIVE:
            prof = PROFILES[name]
            for sgn in ((1.0,) if prof.symmetric else (1.0, -1.0)):
                ax = sgn * a
                R = rotation_to_z(ax)
                origin = base.copy()
                info = {"profile": name, "z0": 0.0}
                if not prof.vote_offset:
                    _, rho, _ = radial(P, origin, ax)
                    hh = (P - origin) @ ax
                    z0 = prof.offset(rho, hh)
                    if z0 is None or not np.isfinite(z0):
                        continue
                    origin = origin + z0 * ax
                out.append(_ProfilePlacement(R, origin, info))
        return out

    def region(self, Pl, Nl, ctx):
        prof = PROFILES[Pl.info["profile"]]
        ext = max(float(np.ptp(np.asarray(Pl), axis=0).max()), 1e-6)
        lo, hi, nb = [], [], []
        d = prof.n_voted + 0  # dims: all params (+ z0)
        cap = {1: 400, 2: 128, 3: 40}[d]
        order = self._order(prof)
        for k in order:
            a, b = prof.bounds[k]
            if prof.kinds[k] == "length":
                a, b = a * ext, b * ext
            lo.append(a)
            hi.append(b)
            span = (b - a) / ext if prof.kinds[k] == "length" else 1.0
            nb.append(int(np.clip(span * ext / max(ctx.cell, 1e-6), 12, cap)))
        if prof.vote_offset:
            z = np.asarray(Pl[:, 2])
            lo.append(float(z.min()) - ext)
            hi.append(float(z.max()) + ext)
            nb.append(int(np.clip((3 * ext) / max(ctx.cell, 1e-6), 16, cap)))
        return Grid(tuple(lo), tuple(hi), tuple(nb))

    @staticmethod
    def _order(prof: Profile) -> list[int]:
        """Grid dimensions: swept (nonlinear) parameters first, then solved ones."""
        return [k for k in range(len(prof.params)) if not prof.linear[k]] + \
               [k for k in range(len(prof.params)) if prof.linear[k]]

    def gamma(self, Pl, Nl, grid, ctx):
        prof = PROFILES[Pl.info["profile"]]
        rng = np.random.default_rng(ctx.seed)
        idx = np.arange(len(Pl)) if len(Pl) <= 1500 else np.sort(rng.choice(len(Pl), 1500, replace=False))
        rho, h, nr, nh = _meridian_local(np.asarray(Pl)[idx], Nl[idx])
        order = self._order(prof)
        nl = [k for k in order if not prof.linear[k]]
        lin = [k for k in order if prof.linear[k]]
        r = len(lin) + int(prof.vote_offset)
        m = {1: 512, 2: 384, 3: 160}.get(r, 160) if not nl else 96
        u = prof.u_samples(m)
        sweeps = [grid.centers(i) for i in range(len(nl))]
        V, W = [], []
        for combo in itertools.product(*sweeps) if nl else [()]:
            th0 = np.zeros(len(prof.params))
            for k, v in zip(nl, combo):
                th0[k] = v
            with np.errstate(all="ignore"):
                c0, d0, _ = prof.derivs(u, th0)
                cols, dcols = [], []
                for k in lin:
                    e = th0.copy()
                    e[k] = 1.0
                    ck, dk, _ = prof.derivs(u, e)
                    cols.append(ck - c0)
                    dcols.append(dk - d0)
            if prof.vote_offset:
                cols.append(np.stack([np.zeros(m), np.ones(m)]))
                dcols.append(np.zeros((2, m)))
            C = np.stack(cols, -1) if cols else np.zeros((2, m, 0))  # (2, m, r)
            D = np.stack(dcols, -1) if dcols else np.zeros((2, m, 0))
            b1 = rho[:, None] - c0[0][None]  # (n, m)
            b2 = h[:, None] - c0[1][None]
            if r == 3:
                rown = nr[:, None, None] * D[0][None] + nh[:, None, None] * D[1][None]  # (n, m, r)
                bn = -(nr[:, None] * d0[0][None] + nh[:, None] * d0[1][None])
                A = np.stack([np.broadcast_to(C[0][None], rown.shape), np.broadcast_to(C[1][None], rown.shape),
                              rown], axis=-2)  # (n, m, 3, 3)
                x, ok = _solve_batched(A, np.stack([b1, b2, bn], -1))
            else:
                A = np.transpose(C, (1, 0, 2))  # (m, 2, r): one matrix per u, shared by the points
                Ap = np.linalg.pinv(A, rcond=1e-8)  # (m, r, 2)
                x = np.einsum("mcr,nmr->nmc", Ap, np.stack([b1, b2], -1))
                res = np.stack([b1, b2], -1) - np.einsum("mrc,nmc->nmr", A, x)
                ok = np.linalg.norm(res, axis=-1) <= max(ctx.cell, ctx.tau)
            # Normal consistency: the curve's normal at u with the solved θ.
            tan = d0[None] + np.einsum("jmc,nmc->njm", D, x) if r else np.broadcast_to(d0[None], (len(rho), 2, m))
            tn = np.hypot(tan[:, 0], tan[:, 1])
            cos = np.abs(tan[:, 1] * nr[:, None] - tan[:, 0] * nh[:, None]) / np.maximum(tn, 1e-300)
            ok &= np.isfinite(x).all(-1) & (cos >= ctx.cos_angle)
            n_i, u_i = np.nonzero(ok)
            vals = np.concatenate([np.broadcast_to(np.asarray(combo, float), (len(n_i), len(nl))),
                                   x[n_i, u_i]], axis=1)
            V.append(idx[n_i])
            W.append(vals)
        if not V:
            return np.zeros(0, np.int64), np.zeros((0, grid.ndim))
        return np.concatenate(V), np.concatenate(W)

    def primitive(self, values, placement):
        prof = PROFILES[placement.info["profile"]]
        order = self._order(prof)
        theta = np.zeros(len(prof.params))
        for j, k in enumerate(order):
            theta[k] = values[j]
        z0 = float(values[len(order)]) if prof.vote_offset else 0.0
        a = placement.R[2].copy()
        return Primitive(self.name, {"axis_point": placement.origin + z0 * a, "axis": a,
                                     "profile": prof.name, "theta": theta})

    # --- geometry -------------------------------------------------------------
    def foot(self, prim: Primitive, P: np.ndarray, u0: np.ndarray | None = None, newton: int = 5):
        """Nearest profile points in the meridian plane.

        Returns (u (n,), signed distance (n,), radial unit vectors (n, 3),
        meridian unit normals (n, 2) as (n_ρ, n_h)). With ``u0`` the search
        starts there (warm start) instead of the nearest dense sample.
        """
        prof = PROFILES[prim.params["profile"]]
        th = prim.params["theta"]
        h, rho, rad = radial(P, prim.params["axis_point"], prim.params["axis"])
        lo_u, hi_u = prof.u_range
        if u0 is None:
            u = prof.u_samples(2048)
            with np.errstate(all="ignore"):
                c = prof.curve(u, th)
            M = max(0.25 * max(float(np.ptp(rho)), float(np.ptp(h))), 0.05)
            keep = np.isfinite(c).all(0) & (c[0] <= rho.max() + M) & (c[0] >= rho.min() - M) & \
                (c[1] <= h.max() + M) & (c[1] >= h.min() - M)
            if not prof.periodic and 0 < keep.sum() < 1024:
                k = np.flatnonzero(keep)
                u = prof.u_samples(2048, u[max(k[0] - 1, 0)], u[min(k[-1] + 1, len(u) - 1)])
                with np.errstate(all="ignore"):
                    c = prof.curve(u, th)
                keep = np.isfinite(c).all(0)
            if not keep.any():
                keep = np.isfinite(c).all(0)
            if not keep.any():
                return np.zeros(len(P)), np.full(len(P), np.inf), rad, np.tile([1.0, 0.0], (len(P), 1))
            _, j = cKDTree(c[:, keep].T).query(np.stack([rho, h], 1))
            u = u[keep][j]
        else:
            u = np.asarray(u0, float).copy()
        q = np.stack([rho, h])
        with np.errstate(all="ignore"):
            for _ in range(newton):
                c, d1, d2 = prof.derivs(u, th)
                diff = c - q
                g = np.sum(d1 * diff, 0)
                gp = np.sum(d2 * diff, 0) + np.sum(d1 * d1, 0)
                step = np.where(gp > 1e-12, g / np.where(gp > 1e-12, gp, 1.0), 0.0)
                un = u - step
                if not prof.periodic:
                    un = np.clip(un, lo_u, hi_u)
                cn = prof.curve(un, th)
                better = np.sum((cn - q) ** 2, 0) <= np.sum(diff ** 2, 0)
                u = np.where(better & np.isfinite(un), un, u)
            c, d1, _ = prof.derivs(u, th)
        nrm = np.stack([d1[1], -d1[0]], 1)
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        sd = np.einsum("ij,ij->i", (q - c).T, nrm)
        dist = np.linalg.norm((q - c).T, axis=1)
        sd = np.where(np.isfinite(sd), np.sign(sd) * dist, np.inf)
        return u, sd, rad, nrm

    def distance(self, prim, P):
        d = np.abs(self.foot(prim, P)[1])
        return np.where(np.isfinite(d), d, 1e9)

    def surface_normals(self, prim, P):
        _, _, rad, nrm = self.foot(prim, P)
        return unit(rad * nrm[:, :1] + nrm[:, 1:] * np.asarray(prim.params["axis"])[None, :])

    def well_determined(self, prim, P, ctx):
        # Global round: cones and tori are not voted there; leave them the
        # surfaces they explain as well (the per-cluster rounds compare all).
        return not covered_by_simple(self, prim, P, ctx)

    def valid(self, prim, ctx):
        prof = PROFILES.get(prim.params["profile"])
        th = np.asarray(prim.params["theta"], float)
        if prof is None or not np.all(np.isfinite(th)):
            return False
        if any(k == "length" and abs(v) > 4.0 * ctx.max_radius for k, v in zip(prof.kinds, th)):
            return False
        if prof.check is not None and not prof.check(_theta_dict(prof, th)):
            return False
        if prof.periodic:
            # A closed meridian thinner than the inlier band is an envelope of
            # a noisy layer (a pancake ring round a disc), not a surface.
            u = np.linspace(*prof.u_range, 64)
            thin = min(np.ptp(prof.f1(u, *th)), np.ptp(prof.f2(u, *th)))
            return bool(thin >= ctx.tau)
        return True

    def fit(self, prim, P, N):
        # Residuals need foot points on the profile: a regular subsample of
        # at most 300 points keeps a fit cheap and the parameters as good.
        P = P[regular_indices(len(P), 300)]
        prof = PROFILES[prim.params["profile"]]
        c0, a0 = np.asarray(prim.params["axis_point"], float), unit(prim.params["axis"])
        e1, e2 = tangent_basis(a0)
        th0 = np.asarray(prim.params["theta"], float)

        def unpack(x):
            a = unit(a0 + x[2] * e1 + x[3] * e2)
            return Primitive(self.name, {"axis_point": c0 + x[0] * e1 + x[1] * e2 + x[4] * a0, "axis": a,
                                         "profile": prof.name, "theta": th0 + x[5:]})

        u_ref = [self.foot(prim, P)[0]]
        if not np.all(np.isfinite(u_ref[0])):
            return None
        state: dict[str, Any] = {}

        def res(x):
            pr = unpack(x)
            u, sd, _, nrm = self.foot(pr, P, u0=u_ref[0], newton=3)
            u_ref[0] = u
            state.update(x=x.copy(), u=u, nrm=nrm)
            return np.where(np.isfinite(sd), sd, 1e3)

        def jac(x):
            # At the foot the distance's gradient is n̂ · (∂q/∂x − ∂c/∂x) (the
            # foot's own motion is tangent): rigid parameters move the point's
            # meridian coordinates q, profile parameters the curve c at fixed u.
            if "x" not in state or not np.array_equal(state["x"], x):
                res(x)
            u, nrm = state["u"], state["nrm"]
            pr = unpack(x)
            h0, r0, _ = radial(P, pr.params["axis_point"], pr.params["axis"])
            th = pr.params["theta"]
            c0 = prof.curve(u, th)
            J = np.empty((len(P), len(x)))
            d = 1e-6
            for j in range(len(x)):
                xe = x.copy()
                xe[j] += d
                if j < 5:
                    pe = unpack(xe)
                    h1, r1, _ = radial(P, pe.params["axis_point"], pe.params["axis"])
                    J[:, j] = (nrm[:, 0] * (r1 - r0) + nrm[:, 1] * (h1 - h0)) / d
                else:
                    te = th.copy()
                    te[j - 5] += d
                    dc = (prof.curve(u, te) - c0) / d
                    J[:, j] = -(nrm[:, 0] * dc[0] + nrm[:, 1] * dc[1])
            return np.where(np.isfinite(J), J, 0.0)

        x0 = np.zeros(5 + len(th0))
        try:
            sol = least_squares(res, x0, jac=jac, method="lm", max_nfev=4 * len(x0))
        except Exception:
            return None
        # On its surface the fit settles in a few evaluations per unknown;
        # one that has not is on another surface (most of the cost of this
        # family on CAD parts was such fits running to the limit).
        if sol.status == 0:
            return None
        return unpack(sol.x)

    # --- output -------------------------------------------------------------------
    def to_world(self, prim, T):
        prof = PROFILES[prim.params["profile"]]
        out = {"axis_point": T.inv_points(prim.params["axis_point"]).tolist(),
               "axis": unit(T.inv_dirs(prim.params["axis"])).tolist(), "profile": prof.name}
        for k, kind, v in zip(prof.params, prof.kinds, prim.params["theta"]):
            out[k] = T.inv_length(float(v)) if kind == "length" else float(v)
        return out

    @property
    def length_descriptors(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(f"{p.name}.{k}" for p in PROFILES.values() for k, kind in zip(p.params, p.kinds)
                     if kind == "length")

    integer_descriptors = ("profile_id",)

    def descriptors(self, prim):
        # One key set for every profile, so that any two segments compare.
        d: dict[str, float] = {"profile_id": float(list(PROFILES).index(prim.params["profile"]))}
        for p in PROFILES.values():
            for k in p.params:
                d[f"{p.name}.{k}"] = 0.0
        prof = PROFILES[prim.params["profile"]]
        for k, v in zip(prof.params, prim.params["theta"]):
            d[f"{prof.name}.{k}"] = float(v)
        return d

    def frame(self, prim):
        oriented = not PROFILES[prim.params["profile"]].symmetric
        return Frame("point", np.asarray(prim.params["axis_point"], float), unit(prim.params["axis"]),
                     oriented=oriented)
