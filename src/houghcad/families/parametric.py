"""User-defined parametric families (paper §4–5.2: a family is any x(u, v; a)).

:func:`define_family` turns three coordinate functions of the surface
parameters ``u, v`` and at most three shape parameters ``a`` into a family
the pipeline recognises like the built-in ones::

    u, v, k, h = sympy.symbols("u v k h")
    define_family("paraboloid", x=u * sympy.cos(v), y=u * sympy.sin(v), z=k * u**2 + h,
                  params=[k, h], u_range=None, v_range=(0, 2 * sympy.pi),
                  lengths={"k": -1, "h": 1}, placement="axis")

The equations are sympy expressions (or strings sympy parses) in the symbols
``u``, ``v`` and the parameters, or numpy-vectorised callables
``f(u, v, **params)``.

How a family is recognised
--------------------------
- **Placement** (standard form): the cluster is put in a local frame by one
  of the normal-based estimators of the built-in families (see
  :data:`PLACEMENTS`); the user's equations are written in that frame.
- **Voting**: every parameter is a voted unknown (at most three). The ones
  that enter the equations linearly (found with sympy, or numerically for
  callables) are *solved*: for each point P, sweep u, v and the other
  parameters over their bins and solve ``A(u, v, a_N) a_L = P − b(u, v, a_N)``
  with the Moore–Penrose pseudo-inverse of A (one batched ``pinv`` per sweep
  sample, shared by all points). With three solved parameters the system is
  square and each (u, v) sample gives a point of Γ_P. With fewer, P pins
  (u, v) down (partly), and each sample is projected on Γ_P by a few
  minimum-norm Newton steps on (u, v, a_L). Samples whose surface normal
  disagrees with the point's normal do not vote.
- **Distance**: nearest of a dense (u, v) sample of the surface (cKDTree,
  cached per parameter vector), refined by vectorised Gauss–Newton steps on
  (u, v).
- **Fit**: ``scipy.optimize.least_squares`` on the parameters and the
  placement (rotation vector, translation), residuals the signed normal
  distances at the feet.

Units: the standard frame is the cloud's unit cube. ``lengths`` gives each
parameter's power of length (1 a length, −1 a curvature, 0 a number or an
angle); parameters are reported in world units accordingly. ``bounds`` are
multiples of the segment's size to that power, so they do not depend on the
cloud's scale. A coordinate range given as ``None`` makes u or v a free length
coordinate (e.g. ``z = v`` for an extrusion, ``x = u cos v`` for a profile of
revolution), swept over the segment's extent.
"""

from __future__ import annotations

import re
from collections import OrderedDict
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..hough import Grid
from ..preprocess import rotation_to_z
from .base import (REGISTRY, SEARCHES, SELECTION_WORDS, Family, Frame, Placement, Primitive, add,
                   axis_from_normal_lines, gauss_newton, lines_intersection, unit)
from .cone import cone_frame

__all__ = ["PLACEMENTS", "ParametricFamily", "define_family", "unregister_family", "user_families"]

TWO_PI = 2.0 * np.pi
#: Standard-form estimators a family can be placed with (or a callable, see :func:`define_family`).
PLACEMENTS = ("none", "plane", "axis", "extrusion", "centre", "apex")
#: A free length coordinate spans [-2, 2] standard units in the distance
#: samples: the unit cube seen from any point in it.
LENGTH_SPAN = 2.0
_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_USER: set[str] = set()


# --------------------------------------------------------------------------- evaluation


class _Equations:
    """x(u, v; a) on numpy arrays, with derivatives.

    ``X(u, v, a)``: u, v of shape (...,), a of shape (..., k) → (..., 3).
    ``jac(u, v, a, wrt)``: derivatives → (..., 3, len(wrt)); ``wrt`` holds
    ``"u"``, ``"v"`` or parameter indices.
    """

    def __init__(self, k: int):
        self.k = k

    def X(self, u, v, a) -> np.ndarray:
        raise NotImplementedError

    def jac(self, u, v, a, wrt) -> np.ndarray:
        raise NotImplementedError


def _stack(values, shape) -> np.ndarray:
    """Broadcast a list of scalars/arrays (constants from lambdify) to (..., len)."""
    return np.stack([np.broadcast_to(np.asarray(c, dtype=float), shape) for c in values], axis=-1)


class _SympyEquations(_Equations):
    def __init__(self, exprs, u, v, syms):
        import sympy as sp

        super().__init__(len(syms))
        args = [u, v, *syms]
        self._f = sp.lambdify(args, list(exprs), "numpy")
        self._d = {}
        for key, s in [("u", u), ("v", v)] + list(enumerate(syms)):
            self._d[key] = sp.lambdify(args, [sp.diff(e, s) for e in exprs], "numpy")

    def X(self, u, v, a):
        u, v, a = np.asarray(u, float), np.asarray(v, float), np.asarray(a, float)
        shape = np.broadcast_shapes(u.shape, v.shape, a.shape[:-1])
        with np.errstate(all="ignore"):
            return _stack(self._f(u, v, *np.moveaxis(a, -1, 0)), shape)

    def jac(self, u, v, a, wrt):
        u, v, a = np.asarray(u, float), np.asarray(v, float), np.asarray(a, float)
        shape = np.broadcast_shapes(u.shape, v.shape, a.shape[:-1])
        cols = np.moveaxis(a, -1, 0)
        with np.errstate(all="ignore"):
            return np.stack([_stack(self._d[w](u, v, *cols), shape) for w in wrt], axis=-1)


class _CallableEquations(_Equations):
    """Callables ``f(u, v, **params)``; derivatives by central differences
    (exact up to rounding for the linear parameters)."""

    def __init__(self, fx, fy, fz, names):
        super().__init__(len(names))
        self._fs = (fx, fy, fz)
        self._names = tuple(names)

    def X(self, u, v, a):
        u, v, a = np.asarray(u, float), np.asarray(v, float), np.asarray(a, float)
        shape = np.broadcast_shapes(u.shape, v.shape, a.shape[:-1])
        kw = {n: a[..., i] for i, n in enumerate(self._names)}
        with np.errstate(all="ignore"):
            return _stack([f(u, v, **kw) for f in self._fs], shape)

    def jac(self, u, v, a, wrt):
        u, v, a = np.asarray(u, float), np.asarray(v, float), np.asarray(a, float)
        cols = []
        for w in wrt:
            if w == "u":
                h = 1e-6 * np.maximum(1.0, np.abs(u))
                cols.append((self.X(u + h, v, a) - self.X(u - h, v, a)) / (2 * h)[..., None])
            elif w == "v":
                h = 1e-6 * np.maximum(1.0, np.abs(v))
                cols.append((self.X(u, v + h, a) - self.X(u, v - h, a)) / (2 * h)[..., None])
            else:
                h = 1e-6 * np.maximum(1.0, np.abs(a[..., w]))
                e = np.zeros(self.k)
                e[w] = 1.0
                ap = a + h[..., None] * e
                am = a - h[..., None] * e
                cols.append((self.X(u, v, ap) - self.X(u, v, am)) / (2 * h)[..., None])
        return np.stack(cols, axis=-1)


def _solve_sym3(M: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve symmetric 3 × 3 systems M y = b (M (m, 3, 3), b (m, 3)) by the
    adjugate: several times faster than a batched LAPACK call on millions of
    tiny systems. Singular systems give non-finite rows (discarded later)."""
    a, bb, c = M[:, 0, 0], M[:, 0, 1], M[:, 0, 2]
    d, e, f = M[:, 1, 1], M[:, 1, 2], M[:, 2, 2]
    A0, A1, A2 = d * f - e * e, c * e - bb * f, bb * e - c * d
    A4, A5, A8 = a * f - c * c, bb * c - a * e, a * d - bb * bb
    det = a * A0 + bb * A1 + c * A2
    with np.errstate(all="ignore"):
        y = np.stack([A0 * b[:, 0] + A1 * b[:, 1] + A2 * b[:, 2],
                      A1 * b[:, 0] + A4 * b[:, 1] + A5 * b[:, 2],
                      A2 * b[:, 0] + A5 * b[:, 1] + A8 * b[:, 2]], axis=1) / det[:, None]
    return y


# --------------------------------------------------------------------------- linear parameters


def linear_params_sympy(exprs, syms) -> list[int]:
    """Indices of parameters entering ``exprs`` linearly, with no products among them.

    A parameter is linear when every second derivative in it vanishes; a set
    is kept greedily (parameter order) while the mixed derivatives of its
    members vanish too (so that A does not depend on them).
    """
    import sympy as sp

    lin = [i for i, s in enumerate(syms) if all(sp.simplify(sp.diff(e, s, 2)) == 0 for e in exprs)]
    out: list[int] = []
    for i in lin:
        if all(sp.simplify(sp.diff(e, syms[i], syms[j])) == 0 for e in exprs for j in out):
            out.append(i)
    return out


def linear_params_numeric(eq: _Equations, u_span, v_span, rng: np.random.Generator, n: int = 64) -> list[int]:
    """Linear parameters of callables, by second differences at random samples.

    For each candidate i: X(a + 2t e_i) − 2 X(a + t e_i) + X(a) = 0; for a
    pair: X(a + s e_i + t e_j) − X(a + s e_i) − X(a + t e_j) + X(a) = 0, to a
    relative tolerance of 1e-7.
    """
    k = eq.k
    u = rng.uniform(*u_span, n)
    v = rng.uniform(*v_span, n)
    a = rng.uniform(0.3, 1.5, (n, k)) * rng.choice([-1.0, 1.0], (n, k))
    base = eq.X(u, v, a)
    scale = 1.0 + np.nanmax(np.abs(base))

    def zero(d):
        d = d[np.isfinite(d).all(axis=-1)]
        return len(d) > 0 and float(np.abs(d).max()) <= 1e-7 * scale

    E = np.eye(k)
    t = rng.uniform(0.5, 2.0, n)[:, None]
    s = rng.uniform(0.5, 2.0, n)[:, None]
    lin = [i for i in range(k)
           if zero(eq.X(u, v, a + 2 * t * E[i]) - 2 * eq.X(u, v, a + t * E[i]) + base)]
    out: list[int] = []
    for i in lin:
        if all(zero(eq.X(u, v, a + s * E[i] + t * E[j]) - eq.X(u, v, a + s * E[i]) - eq.X(u, v, a + t * E[j]) + base)
               for j in out):
            out.append(i)
    return out


def solvable_subset(eq: _Equations, linear: Sequence[int], u_span, v_span, rng: np.random.Generator,
                    n: int = 32) -> list[int]:
    """The linear parameters solved by the pseudo-inverse: greedily those whose
    columns of A raise its rank at most random samples (A has 3 rows, so at
    most three; dependent ones, e.g. two offsets along z, are swept instead)."""
    u = rng.uniform(*u_span, n)
    v = rng.uniform(*v_span, n)
    a = rng.uniform(0.3, 1.5, (n, eq.k)) * rng.choice([-1.0, 1.0], (n, eq.k))
    A = eq.jac(u, v, a, list(linear))
    ok = np.isfinite(A).all(axis=(1, 2))
    A = A[ok]
    chosen: list[int] = []
    for c, i in enumerate(linear):
        cols = [list(linear).index(j) for j in chosen] + [c]
        sub = A[:, :, cols]
        nrm = np.linalg.norm(sub, axis=1, keepdims=True)
        rk = np.linalg.matrix_rank(sub / np.where(nrm > 0, nrm, 1.0), tol=1e-6)
        if len(rk) and np.mean(rk == len(cols)) > 0.5:
            chosen.append(i)
        if len(chosen) == 3:
            break
    return chosen


# --------------------------------------------------------------------------- placements


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


# --------------------------------------------------------------------------- the family


def _snake(shape: Sequence[int]) -> list[tuple[int, ...]]:
    """Every index of a grid of ``shape``, consecutive ones differing by one
    step in one dimension (boustrophedon order), for continuation."""
    if not shape:
        return [()]
    inner = _snake(shape[1:])
    out = []
    for i in range(shape[0]):
        out += [(i,) + c for c in (inner if i % 2 == 0 else inner[::-1])]
    return out


def _periodic(span: tuple[float, float]) -> bool:
    w = span[1] - span[0]
    return w > 0 and abs(w / TWO_PI - round(w / TWO_PI)) < 1e-9


class ParametricFamily(Family):
    """A family given by x(u, v; a), y(u, v; a), z(u, v; a); see the module docstring.

    Build it with :func:`define_family`. Primitive parameters (standard
    frame): ``R`` (3, 3) and ``origin`` (3,) of the placement, ``values``
    (k,) of the shape parameters in declaration order.
    """

    role = "complex"
    search = "cluster"
    #: Above every built-in family: a simpler family wins equal fits.
    precedence = 10
    #: Points voting per cluster (a deterministic subsample; every point is
    #: still evaluated).
    max_voters = 600
    #: Largest step of the Γ_P samples in the square case, in cells.
    substep = 1.0
    #: Levels of quad splitting in the square case (a quad shrinks 2^depth times).
    max_depth = 3
    #: Residual of a Γ_P sample (fraction of tau) below which it votes.
    residual_tol = 0.25

    def __init__(self, name: str, eq: _Equations, names: Sequence[str], dims: Sequence[float],
                 u_range, v_range, solved: Sequence[int], bounds: Sequence[tuple[float, float]],
                 placement, samples: tuple[int, int] | None, valid: Callable[[dict], bool] | None):
        self.name = name
        self.eq = eq
        self.names = tuple(names)
        self.dims = np.asarray(dims, float)
        self.u_range = None if u_range is None else (float(u_range[0]), float(u_range[1]))
        self.v_range = None if v_range is None else (float(v_range[0]), float(v_range[1]))
        self.solved = list(solved)
        self.swept = [i for i in range(len(names)) if i not in self.solved]
        self.bounds = [tuple(map(float, b)) for b in bounds]
        self.placement = placement
        self.samples = samples
        self.user_valid = valid
        self.n_unknowns = len(names)
        self.param_names = ("origin", "frame") + self.names
        self.length_descriptors = tuple(n for n, d in zip(self.names, self.dims) if d == 1)
        self._trees: OrderedDict[bytes, tuple[cKDTree, np.ndarray, np.ndarray]] = OrderedDict()

    def __repr__(self) -> str:
        solved = [self.names[i] for i in self.solved]
        return f"ParametricFamily({self.name!r}, params={list(self.names)}, solved={solved})"

    # --- (u, v) domain -----------------------------------------------------------
    def _span(self, which: int, extent: float) -> tuple[float, float]:
        r = self.u_range if which == 0 else self.v_range
        return (-extent, extent) if r is None else r

    def _wrap(self, u: np.ndarray, v: np.ndarray, extent: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Periodic coordinates back into range; mask of samples inside the domain."""
        ok = np.ones(u.shape, bool)
        out = []
        for which, w in ((0, u), (1, v)):
            lo, hi = self._span(which, extent)
            if _periodic((lo, hi)):
                w = lo + np.mod(w - lo, hi - lo)
            else:
                tol = 1e-9 * (hi - lo)
                ok &= (w >= lo - tol) & (w <= hi + tol)
            out.append(w)
        return out[0], out[1], ok

    # --- standard form and voting ------------------------------------------------
    def placements(self, P, N, ctx):
        return place(self.placement, P, N)

    def _scale(self, L: float) -> np.ndarray:
        return np.power(max(L, 1e-9), self.dims)

    def region(self, Pl, Nl, ctx):
        L = float(np.linalg.norm(np.ptp(Pl, axis=0)))
        sc = self._scale(L)
        lo = np.array([b[0] for b in self.bounds]) * sc
        hi = np.array([b[1] for b in self.bounds]) * sc
        # A cell moves the surface by about one inlier cell: the surface moves
        # by Δa · ∂X/∂a, of order Δa · (L/2)^(1 − dim).
        width = max(ctx.cell, 1e-6) / np.power(max(L / 2, 1e-9), 1.0 - self.dims)
        nmax = {1: 160, 2: 96}.get(len(self.names), 40)
        bins = np.clip(np.ceil((hi - lo) / width), 12, nmax).astype(int)
        return Grid(tuple(lo), tuple(hi), tuple(int(b) for b in bins))

    def _uv_samples(self, extent: float) -> tuple[np.ndarray, np.ndarray]:
        if self.samples is not None:
            nu, nv = self.samples
        else:
            nu = nv = 10 if len(self.solved) == 2 else 4
        spans = [self._span(0, extent), self._span(1, extent)]
        g = []
        for (lo, hi), n in zip(spans, (nu, nv)):
            g.append(lo + (hi - lo) * (np.arange(n) + 0.5) / n if _periodic((lo, hi)) else np.linspace(lo, hi, n))
        U, V = np.meshgrid(g[0], g[1], indexing="ij")
        return U.ravel(), V.ravel()

    def gamma(self, Pl, Nl, grid, ctx):
        """Samples of Γ_P: (voter index (m,), parameter vectors (m, k)).

        Sweep (u, v) and the swept parameters, solve the linear ones with the
        pseudo-inverse; with fewer than three solved, project the samples on
        Γ_P by Newton steps. Samples outside the (u, v) domain, with a
        residual above a fraction of tau, or whose surface normal disagrees
        with the point's, do not vote.
        """
        rng = np.random.default_rng(ctx.seed)
        nvote = self.max_voters if len(self.solved) == 3 else (2 * self.max_voters) // 3
        sel = np.arange(len(Pl)) if len(Pl) <= nvote else np.sort(rng.choice(len(Pl), nvote, replace=False))
        P, Nn = Pl[sel], Nl[sel]
        extent = float(np.linalg.norm(Pl, axis=1).max()) + ctx.tau
        tol = max(self.residual_tol * ctx.tau, 1e-9)
        parts = self._gamma_square(P, Nn, grid, extent, ctx) if len(self.solved) == 3 else \
            self._gamma_continued(P, grid, extent, tol)
        voters, values = [], []
        for vid, u, v, a, *sn in parts:
            u, v, ok = self._wrap(u, v, extent)
            if sn:  # square case: exact solutions, normals known
                sn = sn[0][ok]
            else:
                F = self.eq.X(u, v, a) - P[vid]
                ok &= np.linalg.norm(F, axis=1) < tol
                J = self.eq.jac(u[ok], v[ok], a[ok], ["u", "v"])
                sn = unit(np.cross(J[..., 0], J[..., 1]))
            cos = np.abs(np.einsum("ij,ij->i", sn, Nn[vid[ok]]))
            idx = np.flatnonzero(ok)[cos >= ctx.cos_angle]
            voters.append(sel[vid[idx]])
            values.append(a[idx])
        if not voters:
            return np.zeros(0, np.int64), np.zeros((0, len(self.names)))
        return np.concatenate(voters), np.concatenate(values)

    def _solve_linear(self, P, U, V, aN):
        """Pseudo-inverse solution of A(u, v, a_N) a_L = P − b(u, v, a_N).

        P (n, 3); U, V (S,), aN (S, k) with the swept columns set. A⁺ is
        computed once per sweep sample (``np.linalg.pinv`` on the (S, 3, r)
        stack) and applied to every point. Returns a (n, S, k).
        """
        b = self.eq.X(U, V, aN)
        A = self.eq.jac(U, V, aN, self.solved)
        bad = ~(np.isfinite(A).all(axis=(1, 2)) & np.isfinite(b).all(axis=1))
        A[bad], b[bad] = 0.0, np.nan
        Ap = np.linalg.pinv(A)
        a = np.broadcast_to(aN, (len(P),) + aN.shape).copy()
        a[..., self.solved] = np.einsum("sij,nsj->nsi", Ap, P[:, None, :] - b[None])
        return a

    def _solve_at(self, Q: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Square case at per-sample (u, v): a (m, k) solving A a = Q − b by the
        normal equations (A⁺ = (AᵀA)⁻¹Aᵀ for a full-rank A), and the unit
        surface normals there (m, 3)."""
        k = len(self.names)
        z = np.zeros((len(u), k))
        Am = self.eq.jac(u, v, z, self.solved)
        M = np.matmul(np.swapaxes(Am, 1, 2), Am)
        z[:, self.solved] = _solve_sym3(M, np.einsum("mij,mi->mj", Am, Q - self.eq.X(u, v, z)))
        J = self.eq.jac(u, v, z, ["u", "v"])
        return z, unit(np.cross(J[..., 0], J[..., 1]))

    def _gamma_square(self, P, Nn, grid, extent, ctx):
        """Three solved parameters: every (u, v) gives a point of Γ_P.

        Γ_P must be sampled more finely than the cells, or the true cell is
        skipped by the points whose (u, v) falls between samples. A coarse
        (u, v) lattice is solved with the shared pseudo-inverses; then each
        quad of it whose corners' parameters meet the box and whose surface
        normals can match the point's is split in four (solved per sample)
        until its image spans at most :attr:`substep` cells, for at most
        :attr:`max_depth` levels. The leaves' corners vote.
        """
        nodes = []
        for w in (0, 1):
            lo, hi = self._span(w, extent)
            n = 16 if self.samples is None else self.samples[w]
            nodes.append(np.linspace(lo, hi, n + 1 if _periodic((lo, hi)) else n))
        nu, nv = len(nodes[0]), len(nodes[1])
        U, V = (m.ravel() for m in np.meshgrid(nodes[0], nodes[1], indexing="ij"))
        k = len(self.names)
        lower, upper, width = np.asarray(grid.lower), np.asarray(grid.upper), grid.width
        chunk = max(1, 100_000 // len(U))
        for c0 in range(0, len(P), chunk):
            Pc, Nc = P[c0:c0 + chunk], Nn[c0:c0 + chunk]
            n = len(Pc)
            a = self._solve_linear(Pc, U, V, np.zeros((len(U), k)))  # (n, nu*nv, k)
            J = self.eq.jac(np.broadcast_to(U, (n, len(U))), np.broadcast_to(V, (n, len(U))), a, ["u", "v"])
            sn = unit(np.cross(J[..., 0], J[..., 1])).reshape(n, nu, nv, 3)
            a = a.reshape(n, nu, nv, k)
            # Quads: point, lower-left (u, v), size, corner values (4, m, k) and normals (4, m, 3).
            pi, qi, qj = (g.ravel() for g in np.meshgrid(np.arange(n), np.arange(nu - 1), np.arange(nv - 1),
                                                         indexing="ij"))
            cu, cv = nodes[0][qi], nodes[1][qj]
            hu = np.full(len(pi), nodes[0][1] - nodes[0][0])
            hv = np.full(len(pi), nodes[1][1] - nodes[1][0])
            ca = np.stack([a[pi, qi + di, qj + dj] for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1))])
            cn = np.stack([sn[pi, qi + di, qj + dj] for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1))])
            for depth in range(self.max_depth + 1):
                with np.errstate(invalid="ignore"):
                    lo, hi = ca.min(axis=0), ca.max(axis=0)
                    keep = np.isfinite(lo).all(-1) & np.isfinite(hi).all(-1) & ((hi >= lower) & (lo <= upper)).all(-1)
                    # The normals inside a quad turn at most about as much as
                    # between its corners: allow that much on top of the angle.
                    turn = np.arccos(np.clip(np.minimum(np.abs(np.einsum("mi,mi->m", cn[0], cn[3])),
                                                        np.abs(np.einsum("mi,mi->m", cn[1], cn[2]))), 0, 1))
                    best = np.abs(np.einsum("cmi,mi->cm", cn, Nc[pi])).max(axis=0)
                    keep &= best >= np.cos(np.minimum(np.pi / 2, ctx.angle + turn))
                    fine = ((hi - lo) / width).max(axis=-1) <= self.substep
                leaf = keep & (fine | (depth == self.max_depth))
                if leaf.any():
                    # One corner per leaf: neighbouring leaves' corners are at
                    # most a leaf apart, so Γ_P is still sampled cell by cell.
                    L = np.flatnonzero(leaf)
                    yield c0 + pi[L], cu[L], cv[L], ca[0, L], cn[0, L]
                S = np.flatnonzero(keep & ~leaf)
                if len(S) == 0:
                    break
                # Split: five new nodes per quad (edge midpoints, centre).
                pi, cu, cv, hu, hv = pi[S], cu[S], cv[S], hu[S] / 2, hv[S] / 2
                mids = ((1, 0), (0, 1), (1, 1), (2, 1), (1, 2))
                nu_ = np.concatenate([cu + du * hu for du, _ in mids])
                nv_ = np.concatenate([cv + dv * hv for _, dv in mids])
                na, nn = self._solve_at(Pc[np.tile(pi, 5)], nu_, nv_)
                m = len(S)
                g = {(0, 0): (ca[0, S], cn[0, S]), (2, 0): (ca[1, S], cn[1, S]), (0, 2): (ca[2, S], cn[2, S]),
                     (2, 2): (ca[3, S], cn[3, S])}
                for t, key in enumerate(mids):
                    g[key] = (na[t * m:(t + 1) * m], nn[t * m:(t + 1) * m])
                kids = ((0, 0), (1, 0), (0, 1), (1, 1))
                ca = np.concatenate([np.stack([g[(i + di, j + dj)][0] for di, dj in kids]) for i, j in kids], axis=1)
                cn = np.concatenate([np.stack([g[(i + di, j + dj)][1] for di, dj in kids]) for i, j in kids], axis=1)
                cu = np.concatenate([cu + i * hu for i, _ in kids])
                cv = np.concatenate([cv + j * hv for _, j in kids])
                pi, hu, hv = np.tile(pi, 4), np.tile(hu, 4), np.tile(hv, 4)

    def _gamma_continued(self, P, grid, extent, tol):
        """Fewer than three solved parameters: the point pins (u, v) down
        (to isolated roots, or a curve with two solved). The swept values are
        visited in snake order; each root is continued from the previous
        value by a few Newton steps. Multi-start (pseudo-inverse start, then
        Newton) at a few evenly spread values finds the roots, deduplicated."""
        k = len(self.names)
        U0, V0 = self._uv_samples(extent)
        axes = [grid.centers(j) for j in self.swept]
        order = _snake([len(c) for c in axes])
        restart = set(np.linspace(0, len(order) - 1, min(len(order), 5)).round().astype(int).tolist())
        quant = np.array([np.ptp(self._span(w, extent)) / (4 * n) + 1e-12
                          for w, n in ((0, len(np.unique(U0))), (1, len(np.unique(V0))))])
        width = grid.width
        vid = np.zeros(0, np.int64)
        u = v = np.zeros(0)
        a = np.zeros((0, k))
        for t, combo in enumerate(order):
            aN = np.zeros(k)
            aN[self.swept] = [c[i] for c, i in zip(axes, combo)]
            if len(vid):
                prev = (u, v, a)
                a = a.copy()
                a[:, self.swept] = aN[self.swept]
                u, v, a, conv = self._project(u, v, a, P[vid], extent, tol, iters=3)
                vid, u, v, a = vid[conv], u[conv], v[conv], a[conv]
                fill = self._between([p[conv] for p in prev], (u, v, a), vid, width)
                if fill is not None:
                    yield fill
            if t in restart:
                an = self._solve_linear(P, U0, V0, np.broadcast_to(aN, (len(U0), k)))
                m = an.shape[1]
                nu, nv, na, conv = self._project(np.tile(U0, len(P)), np.tile(V0, len(P)), an.reshape(-1, k),
                                                 np.repeat(P, m, axis=0), extent, tol)
                nid = np.repeat(np.arange(len(P)), m)
                vid, u, v = np.r_[vid, nid[conv]], np.r_[u, nu[conv]], np.r_[v, nv[conv]]
                a = np.vstack([a, na[conv]])
                key = np.stack([vid, np.round(u / quant[0]), np.round(v / quant[1])], axis=1).astype(np.int64)
                _, first = np.unique(key, axis=0, return_index=True)
                first = np.sort(first)
                vid, u, v, a = vid[first], u[first], v[first], a[first]
            if len(vid):
                yield vid, u.copy(), v.copy(), a.copy()

    def _between(self, prev, cur, vid, width):
        """Samples between two consecutive swept values of each continued root.

        One swept cell may move the solved parameters by many cells (a point
        near the axis of a paraboloid: k = (z − h)/ρ²): the chord between the
        two roots, cut so that it steps by at most :attr:`substep` cells,
        fills the gap (the caller's residual check drops chords that leave
        Γ_P). Returns (vid, u, v, a) or None.
        """
        (u0, v0, a0), (u1, v1, a1) = prev, cur
        n = np.ceil(np.abs(a1 - a0) / width / self.substep).max(axis=1, initial=1.0)
        n = np.clip(np.nan_to_num(n, nan=1.0), 1, 16).astype(int)
        m = n - 1
        if m.sum() == 0:
            return None
        rep = np.repeat(np.arange(len(n)), m)
        t = (np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m) + 1) / n[rep]
        lerp = lambda x0, x1: x0[rep] + (x1[rep] - x0[rep]) * (t if x0.ndim == 1 else t[:, None])  # noqa: E731
        # (u, v) may have wrapped around a period between the two roots: take the short way.
        du = [x1 - x0 for x0, x1 in ((u0, u1), (v0, v1))]
        for w, d in enumerate(du):
            lo, hi = self._span(w, 1.0)
            if _periodic((lo, hi)):
                du[w] = d - (hi - lo) * np.round(d / (hi - lo))
        return (vid[rep], u0[rep] + du[0][rep] * t, v0[rep] + du[1][rep] * t, lerp(a0, a1))

    def _project(self, u, v, a, Q, extent, tol, iters: int = 8):
        """Minimum-norm Newton steps on (u, v, a_solved) towards X = Q.

        Each sample moves to the nearest solution of the underdetermined
        system (3 equations, 2 + r unknowns): a sample of Γ_P at the swept
        values. Shapes (m,), (m,), (m, k), (m, 3). Converged samples leave
        the iteration (quadratic convergence: most need three steps).
        Returns u, v, a and the mask of samples within ``tol``.
        """
        u, v, a = u.copy(), v.copy(), a.copy()
        wrt = ["u", "v"] + self.solved
        act = np.arange(len(u))
        done = 1e-3 * tol
        for _ in range(iters):
            F = self.eq.X(u[act], v[act], a[act]) - Q[act]
            nf = np.linalg.norm(F, axis=1)
            keep = ~(nf < done) & np.isfinite(nf)
            act, F = act[keep], F[keep]
            if len(act) == 0:
                break
            J = self.eq.jac(u[act], v[act], a[act], wrt)
            M = np.matmul(J, np.swapaxes(J, 1, 2))
            M += (1e-12 * np.trace(M, axis1=1, axis2=2) + 1e-300)[:, None, None] * np.eye(3)
            step = np.matmul(np.swapaxes(J, 1, 2), _solve_sym3(M, -F)[..., None])[..., 0]
            un, vn, _ = self._wrap(u[act] + step[:, 0], v[act] + step[:, 1], extent)
            u[act], v[act] = un, vn
            a[np.ix_(act, self.solved)] += step[:, 2:]
        F = self.eq.X(u, v, a) - Q
        nf = np.linalg.norm(F, axis=1)
        _, _, inside = self._wrap(u, v, extent)
        return u, v, a, inside & (nf < tol)

    def primitive(self, values, placement):
        return Primitive(self.name, {"R": placement.R.copy(), "origin": placement.origin.copy(),
                                     "values": np.asarray(values, float).copy()})

    # --- geometry ------------------------------------------------------------------
    def _tree(self, values: np.ndarray) -> tuple[cKDTree, np.ndarray, np.ndarray]:
        """KD-tree of a dense (u, v) sample of the surface (local frame), cached."""
        key = values.tobytes()
        hit = self._trees.get(key)
        if hit is not None:
            self._trees.move_to_end(key)
            return hit
        g = []
        for which in (0, 1):
            lo, hi = self._span(which, LENGTH_SPAN)
            n = 128 if (self.u_range if which == 0 else self.v_range) is None else 96
            g.append(np.linspace(lo, hi, n, endpoint=not _periodic((lo, hi))))
        U, V = (m.ravel() for m in np.meshgrid(g[0], g[1], indexing="ij"))
        X = self.eq.X(U, V, np.broadcast_to(values, (len(U), len(values))))
        ok = np.isfinite(X).all(axis=1)
        hit = (cKDTree(X[ok]), U[ok], V[ok])
        self._trees[key] = hit
        if len(self._trees) > 32:
            self._trees.popitem(last=False)
        return hit

    def _feet(self, values: np.ndarray, Q: np.ndarray, u=None, v=None, iters: int = 12):
        """Parameters (u, v) (n,) of the nearest surface points to local points Q (n, 3).

        From the nearest dense sample (or the given start), Levenberg–Marquardt
        steps on |X(u, v) − Q|², damped per point: a step is kept only where
        it gets closer, and the damping grows where it does not (far points
        see the curvature, where plain Gauss–Newton overshoots).
        """
        if u is None:
            tree, Ut, Vt = self._tree(values)
            if tree.n == 0:
                return np.zeros(len(Q)), np.zeros(len(Q))
            _, j = tree.query(Q)
            u, v = Ut[j], Vt[j]
        a = np.broadcast_to(values, (len(Q), len(values)))
        F = self.eq.X(u, v, a) - Q
        d = np.einsum("ij,ij->i", F, F)
        lam = np.full(len(Q), 1e-6)
        act = np.flatnonzero(np.isfinite(d))
        for _ in range(iters):
            if len(act) == 0:
                break
            J = self.eq.jac(u[act], v[act], a[act], ["u", "v"])
            M = np.einsum("mik,mil->mkl", J, J)
            g = np.einsum("mik,mi->mk", J, F[act])
            tr = M[:, 0, 0] + M[:, 1, 1]
            M[:, 0, 0] += lam[act] * tr + 1e-300
            M[:, 1, 1] += lam[act] * tr + 1e-300
            det = M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]
            det = np.where(np.abs(det) > 0, det, 1.0)
            du = -(M[:, 1, 1] * g[:, 0] - M[:, 0, 1] * g[:, 1]) / det
            dv = -(M[:, 0, 0] * g[:, 1] - M[:, 1, 0] * g[:, 0]) / det
            un, vn = u[act] + du, v[act] + dv
            for which, w in ((0, un), (1, vn)):
                lo, hi = self._span(which, LENGTH_SPAN)
                w[:] = lo + np.mod(w - lo, hi - lo) if _periodic((lo, hi)) else np.clip(w, lo, hi)
            Fn = self.eq.X(un, vn, a[act]) - Q[act]
            dn = np.einsum("ij,ij->i", Fn, Fn)
            better = np.isfinite(dn) & (dn < d[act])
            acc = act[better]
            u[acc], v[acc], F[acc], d[acc] = un[better], vn[better], Fn[better], dn[better]
            lam[acc] = np.maximum(lam[acc] / 10, 1e-9)
            lam[act[~better]] *= 10
            # Done: no longer moving (accepted steps tiny) or hopelessly damped.
            small = better & (np.abs(du) + np.abs(dv) < 1e-12 * (1 + np.abs(un) + np.abs(vn)))
            act = act[~small & (lam[act] < 1e6)]
        return u, v

    def _local(self, prim: Primitive, P: np.ndarray) -> np.ndarray:
        return (P - prim.params["origin"]) @ prim.params["R"].T

    def distance(self, prim, P):
        values = np.asarray(prim.params["values"], float)
        Q = self._local(prim, P)
        u, v = self._feet(values, Q)
        F = self.eq.X(u, v, np.broadcast_to(values, (len(Q), len(values)))) - Q
        d = np.linalg.norm(F, axis=1)
        return np.where(np.isfinite(d), d, np.inf)

    def _normals_at(self, values, u, v) -> np.ndarray:
        J = self.eq.jac(u, v, np.broadcast_to(values, (len(u), len(values))), ["u", "v"])
        return unit(np.cross(J[..., 0], J[..., 1]))

    def surface_normals(self, prim, P):
        values = np.asarray(prim.params["values"], float)
        u, v = self._feet(values, self._local(prim, P))
        return np.nan_to_num(self._normals_at(values, u, v)) @ prim.params["R"]

    def fit(self, prim, P, N):
        """Least squares on the shape parameters and the placement (rotation
        vector, translation; fixed with placement "none").

        Residuals are the signed normal distances r = n·(Q − X(u, v; a)) at the
        feet (warm-started from the initial ones at every evaluation). At a
        foot ∂r/∂(u, v) = 0, so the Jacobian is analytic: rows
        [Q × n, −n, −n·∂X/∂a] for a turn δw, a shift t (local frame) and the
        parameters. Damped Gauss–Newton (:func:`base.gauss_newton`): a few
        evaluations where a finite-difference Jacobian needs ten per step.
        """
        R0, o0 = prim.params["R"], prim.params["origin"]
        a0 = np.asarray(prim.params["values"], float)
        k = len(a0)
        Q0 = (P - o0) @ R0.T
        u0, v0 = self._feet(a0, Q0)
        pose = self.placement != "none"
        allp = list(range(k))

        def unpack(x):
            if not pose:
                return R0, o0, x
            return Rotation.from_rotvec(x[:3]).as_matrix() @ R0, o0 + R0.T @ x[3:6], x[6:]

        def fun(x):
            R, o, a = unpack(x)
            Q = (P - o) @ R.T
            u, v = self._feet(a, Q, u0.copy(), v0.copy(), iters=3)
            A = np.broadcast_to(a, (len(Q), k))
            X = self.eq.X(u, v, A)
            J = self.eq.jac(u, v, A, ["u", "v"] + allp)
            n = unit(np.cross(J[..., 0], J[..., 1]))
            r = np.einsum("ij,ij->i", n, Q - X)
            Ja = -np.einsum("mi,mij->mj", n, J[..., 2:])
            bad = ~(np.isfinite(r) & np.isfinite(Ja).all(axis=1))
            r[bad], Ja[bad], n[bad] = 0.0, 0.0, 0.0
            if not pose:
                return r, Ja
            # A faint pull to the start: directions the data leave free (a
            # turn about an axis of symmetry, a shift traded for an offset
            # parameter) stay put instead of drifting.
            Jp = np.hstack([np.cross(Q, n), -n @ R @ R0.T, Ja])
            reg = 1e-3 * np.eye(6, 6 + k)
            return np.r_[r, 1e-3 * x[:6]], np.vstack([Jp, reg])

        x0 = np.r_[np.zeros(6), a0] if pose else a0.copy()
        x = gauss_newton(fun, x0, iters=12)
        if x is None:
            return None
        R, o, a = unpack(x)
        if not (np.isfinite(a).all() and np.isfinite(o).all() and np.isfinite(R).all()):
            return None
        return Primitive(self.name, {"R": R, "origin": o, "values": np.asarray(a, float)})

    def valid(self, prim, ctx):
        a = np.asarray(prim.params["values"], float)
        if not np.isfinite(a).all():
            return False
        return True if self.user_valid is None else bool(self.user_valid(dict(zip(self.names, a.tolist()))))

    # --- output ----------------------------------------------------------------------
    def to_world(self, prim, T):
        R = prim.params["R"]
        out: dict[str, Any] = {"origin": T.inv_points(prim.params["origin"]).tolist(),
                               "frame": [unit(T.inv_dirs(R[i])).tolist() for i in range(3)]}
        for n, d, val in zip(self.names, self.dims, np.asarray(prim.params["values"], float)):
            out[n] = float(val / T.scale**d)
        return out

    def descriptors(self, prim):
        return {n: float(val) for n, d, val in zip(self.names, self.dims, prim.params["values"]) if d in (0, 1)}

    def frame(self, prim):
        o, z = np.asarray(prim.params["origin"], float), unit(prim.params["R"][2])
        kind = {"plane": "plane", "axis": "line", "extrusion": "line", "centre": "point", "apex": "point"}
        if not isinstance(self.placement, str) or self.placement not in kind:
            return None
        return Frame(kind[self.placement], o, z, oriented=self.placement == "apex")


# --------------------------------------------------------------------------- public API


def _range(r, what: str):
    if r is None:
        return None
    try:
        lo, hi = (float(x) for x in r)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be (low, high) or None, got {r!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise InputError(f"{what} must be finite with high > low, got {r!r}")
    return lo, hi


def define_family(name: str, x, y, z, params: Sequence, u_range, v_range, *,
                  linear: Sequence[str] | None = None,
                  bounds: Mapping[str, tuple[float, float]] | None = None,
                  lengths: Sequence[str] | Mapping[str, float] | None = None,
                  placement: str | Callable = "axis", samples: tuple[int, int] | None = None,
                  valid: Callable[[dict], bool] | None = None, search: str = "whole",
                  precedence: int = 10, register: bool = True) -> ParametricFamily:
    """Declare a parametric family x(u, v; a), y(u, v; a), z(u, v; a).

    Parameters
    ----------
    name : str
        Lower-case identifier (``[a-z][a-z0-9_]*``) used in ``families=...``
        and as the segments' ``type``. Redefining a user family replaces it;
        built-in names are refused.
    x, y, z : sympy expressions, strings, or callables
        Expressions in the symbols ``u``, ``v`` and the parameters (strings
        are parsed by sympy), or numpy-vectorised callables
        ``f(u, v, **params)``. Written in the local frame of ``placement``.
    params : sequence of sympy Symbols or str
        The shape parameters, at most three (the voted unknowns).
    u_range, v_range : (low, high) or None
        Domain of u and v. A range of length 2π is periodic. ``None`` makes
        the coordinate a free length, swept over the segment's extent.
    linear : sequence of str, optional
        Parameters entering linearly (default: detected, symbolically for
        sympy expressions, numerically for callables; a declared one that is
        not linear is an error).
    bounds : {param: (low, high)}, optional
        Range voted over, in multiples of the segment's size (bounding-box
        diagonal in the local frame) to the parameter's power of length
        (default (−2, 2)).
    lengths : sequence of str or {param: power}, optional
        Power of length of each parameter: listed names are lengths (power 1)
        and the others dimensionless; a mapping gives the powers (−1 for a
        curvature). Default: every parameter is a length.
    placement : str or callable
        One of :data:`PLACEMENTS` (see :func:`place`), or
        ``f(P, N) -> (R, origin)`` (or a list of such pairs) in the cloud's
        standard frame, R's rows the local axes.
    samples : (n_u, n_v), optional
        (u, v) samples per point in the vote: the starting lattice refined
        adaptively when three parameters are solved (default 16 × 16), the
        Newton starts otherwise (default 10 × 10 with two solved, 4 × 4 with
        one).
    valid : callable, optional
        ``valid({param: value}) -> bool`` on standard-frame values; rejects
        degenerate shapes a simpler family covers.
    search : {"whole", "cluster"}
        ``"whole"``: also seek the family on the whole cloud in the first
        round (placed from all the normals), not only per cluster in the
        splitting phase (``"cluster"``; see :attr:`Family.search`).
        On a cloud that is mostly one such surface this keeps the simple
        families from taking it band by band first; on a multi-surface part
        it costs one vote (about a second) for nothing: use ``"cluster"`` there.
    precedence : int
        Rank for ties (built-in: plane 0 … torus 4). A family more complex
        than its competitor must halve its fitting error to replace it
        (``recognize._better``); the default 10 puts it above every built-in
        family, so a shallow paraboloid that a sphere fits about as well
        under noise comes out as the sphere.
    register : bool
        Add the family to the registry (selectable by name; also in ``"all"``).

    Returns
    -------
    ParametricFamily
    """
    if not isinstance(name, str) or not _NAME.match(name):
        raise InputError(f"family name must match [a-z][a-z0-9_]*, got {name!r}")
    if name in SELECTION_WORDS or (name in REGISTRY and name not in _USER):
        raise InputError(f"family name {name!r} is taken by a built-in family")
    names = [str(p) for p in params]
    if not 1 <= len(names) <= 3:
        raise InputError(f"{name}: a family has one to three parameters (the voted unknowns), got {len(names)}")
    if len(set(names)) != len(names) or {"u", "v"} & set(names):
        raise InputError(f"{name}: parameter names must be distinct and not u or v, got {names}")
    ur, vr = _range(u_range, "u_range"), _range(v_range, "v_range")
    rng = np.random.default_rng(0)
    spans = [(-1.0, 1.0) if r is None else r for r in (ur, vr)]

    funcs = (x, y, z)
    if all(callable(f) for f in funcs) and not any(hasattr(f, "free_symbols") for f in funcs):
        eq: _Equations = _CallableEquations(x, y, z, names)
        try:
            detected = linear_params_numeric(eq, *spans, rng)
        except Exception as exc:
            raise InputError(f"{name}: evaluating the callables failed ({type(exc).__name__}: {exc})") from None
    else:
        import sympy as sp

        syms = [sp.Symbol(n) for n in names]
        su, sv = sp.Symbol("u"), sp.Symbol("v")
        try:
            exprs = [sp.sympify(f) for f in funcs]
        except (sp.SympifyError, TypeError) as exc:
            raise InputError(f"{name}: cannot read the equations ({exc})") from None
        # Parameters may have been created with assumptions: match by name.
        exprs = [e.subs({s: sp.Symbol(s.name) for s in e.free_symbols}) for e in exprs]
        extra = set().union(*(e.free_symbols for e in exprs)) - {su, sv, *syms}
        if extra:
            raise InputError(f"{name}: unknown symbols {sorted(map(str, extra))} in the equations "
                             f"(coordinates are u and v; parameters {names})")
        eq = _SympyEquations(exprs, su, sv, syms)
        detected = linear_params_sympy(exprs, syms)
    if linear is not None:
        declared = [names.index(str(p)) if str(p) in names else -1 for p in linear]
        if -1 in declared:
            raise InputError(f"{name}: linear names unknown parameters {list(linear)} (parameters {names})")
        wrong = [names[i] for i in declared if i not in detected]
        if wrong:
            raise InputError(f"{name}: parameters {wrong} are declared linear but the equations are not linear in them")
        detected = [i for i in detected if i in declared]
    solved = solvable_subset(eq, detected, *spans, rng) if detected else []

    if lengths is None:
        dims = [1.0] * len(names)
    elif isinstance(lengths, Mapping):
        unknown = set(map(str, lengths)) - set(names)
        if unknown:
            raise InputError(f"{name}: lengths names unknown parameters {sorted(unknown)}")
        powers = {str(s): float(d) for s, d in lengths.items()}
        dims = [powers.get(n, 0.0) for n in names]
    else:
        listed = {str(s) for s in lengths}
        if listed - set(names):
            raise InputError(f"{name}: lengths names unknown parameters {sorted(listed - set(names))}")
        dims = [1.0 if n in listed else 0.0 for n in names]
    bnds = []
    bounds = {str(k): v for k, v in (bounds or {}).items()}
    if set(bounds) - set(names):
        raise InputError(f"{name}: bounds name unknown parameters {sorted(set(bounds) - set(names))}")
    for n in names:
        bnds.append(_range(bounds.get(n, (-2.0, 2.0)), f"bounds[{n!r}]"))
    if not callable(placement) and placement not in PLACEMENTS:
        raise InputError(f"{name}: unknown placement {placement!r} (known: {', '.join(PLACEMENTS)}, or a callable)")
    if samples is not None:
        samples = (int(samples[0]), int(samples[1]))
    if not solved:
        raise InputError(f"{name}: no parameter enters the equations linearly (or none is solvable): the Hough "
                         "transform is sampled by solving for linear parameters")
    fam = ParametricFamily(name, eq, names, dims, ur, vr, solved, bnds, placement, samples, valid)
    if search not in SEARCHES:
        raise InputError(f"{name}: search must be one of {SEARCHES}, got {search!r}")
    fam.search = search
    fam.precedence = int(precedence)
    if register:
        add(fam)
        _USER.add(name)
    return fam


def unregister_family(name: str) -> None:
    """Remove a user-defined family from the registry (built-in ones stay)."""
    if name in _USER:
        _USER.discard(name)
        REGISTRY.pop(name, None)


def user_families() -> list[str]:
    """Names of the registered user-defined families."""
    return sorted(_USER)
