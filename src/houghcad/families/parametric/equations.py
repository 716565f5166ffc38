"""Evaluation of a user family's equations x(u, v; a) and their derivatives
(sympy lambdified, or callables with central differences), and which
parameters enter them linearly (solved by the pseudo-inverse in the vote)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .guard import describe, user_code, user_error


class Equations:
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


class SympyEquations(Equations):
    """Lambdified sympy expressions (``family`` names them in errors: an undefined function in
    an expression only fails when evaluated)."""

    def __init__(self, exprs, u, v, syms, family: str = "unnamed"):
        import sympy as sp

        super().__init__(len(syms))
        self._family = family
        args = [u, v, *syms]
        self._f = sp.lambdify(args, list(exprs), "numpy")
        self._d = {}
        for key, s in [("u", u), ("v", v)] + list(enumerate(syms)):
            self._d[key] = sp.lambdify(args, [sp.diff(e, s) for e in exprs], "numpy")

    def X(self, u, v, a):
        u, v, a = np.asarray(u, float), np.asarray(v, float), np.asarray(a, float)
        shape = np.broadcast_shapes(u.shape, v.shape, a.shape[:-1])
        with np.errstate(all="ignore"), user_code(self._family, "equations"):
            return _stack(self._f(u, v, *np.moveaxis(a, -1, 0)), shape)

    def jac(self, u, v, a, wrt):
        u, v, a = np.asarray(u, float), np.asarray(v, float), np.asarray(a, float)
        shape = np.broadcast_shapes(u.shape, v.shape, a.shape[:-1])
        cols = np.moveaxis(a, -1, 0)
        with np.errstate(all="ignore"), user_code(self._family, "equations"):
            return np.stack([_stack(self._d[w](u, v, *cols), shape) for w in wrt], axis=-1)


def _full(x: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return x if x.shape == shape else np.broadcast_to(x, shape)


class CallableEquations(Equations):
    """Callables ``f(u, v, **params)``; derivatives by central differences
    (exact up to rounding for the linear parameters). ``family`` names them in errors."""

    def __init__(self, fx, fy, fz, names, family: str = "unnamed"):
        super().__init__(len(names))
        self._fs = (fx, fy, fz)
        self._names = tuple(names)
        self._family = family

    def X(self, u, v, a):
        u, v, a = np.asarray(u, float), np.asarray(v, float), np.asarray(a, float)
        shape = np.broadcast_shapes(u.shape, v.shape, a.shape[:-1])
        # Every argument in the full shape: a vectorised function then answers in that shape.
        u, v = _full(u, shape), _full(v, shape)
        kw = {n: _full(a[..., i], shape) for i, n in enumerate(self._names)}
        with np.errstate(all="ignore"):
            return _stack([self._coordinate(w, f, u, v, kw, shape) for w, f in zip("xyz", self._fs)], shape)

    def _coordinate(self, which: str, f, u: np.ndarray, v: np.ndarray, kw: dict[str, np.ndarray],
                    shape: tuple[int, ...]) -> np.ndarray:
        """The values of the user's function ``f`` for coordinate ``which``, checked: an array in
        the arguments' shape, or one number (a constant coordinate). Anything else would be
        broadcast into another surface (an array of one value: a constant) or fail later."""
        what = f"{which}(...)"
        with user_code(self._family, what):
            got = f(u, v, **kw)
        try:
            out = np.asarray(got, float)
        except (TypeError, ValueError):
            raise user_error(self._family, what, f"returned {describe(got)}, not numbers") from None
        if out.ndim and out.shape != shape:
            raise user_error(self._family, what, f"returned shape {out.shape} for arguments of shape {shape} "
                             "(a vectorised function answers in its arguments' shape, or with one number)")
        return out

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


def solve_sym3(M: np.ndarray, b: np.ndarray) -> np.ndarray:
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


def linear_params_numeric(eq: Equations, u_span, v_span, rng: np.random.Generator, n: int = 64) -> list[int]:
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


def unused_params(eq: Equations, u_span, v_span, rng: np.random.Generator, n: int = 64) -> list[int]:
    """Parameters the equations do not depend on: moving one alone changes no coordinate (to
    rounding) at any of ``n`` random samples where they are finite. No such sample proves
    nothing: none is reported then."""
    k = eq.k
    u = rng.uniform(*u_span, n)
    v = rng.uniform(*v_span, n)
    a = rng.uniform(0.3, 1.5, (n, k)) * rng.choice([-1.0, 1.0], (n, k))
    t = rng.uniform(0.5, 2.0, n)[:, None]
    base = eq.X(u, v, a)
    scale = 1.0 + np.nanmax(np.abs(base), initial=0.0)
    out = []
    for i, e in enumerate(np.eye(k)):
        d = eq.X(u, v, a + t * e) - base
        d = d[np.isfinite(d).all(axis=-1)]
        if len(d) and float(np.abs(d).max()) <= 1e-12 * scale:
            out.append(i)
    return out


def solvable_subset(eq: Equations, linear: Sequence[int], u_span, v_span, rng: np.random.Generator,
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
