"""Small geometric helpers shared by the families: unit vectors and frames, axial
coordinates, intersections of lines and planes, and a small Gauss–Newton solver."""

from __future__ import annotations

import numpy as np

from ..kernels import kernel


def unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def regular_indices(n: int, m: int) -> np.ndarray:
    """At most m regularly spaced indices of range(n) (all of them when n <= m),
    for deterministic subsamples of point sets."""
    return np.arange(n) if n <= m else np.linspace(0, n - 1, m).astype(np.int64)


#: Second principal spread of a point set, as a share of the first, at or below which the
#: points lie on one line: float64 rounding of coordinates is ~1e-16 of the extent, and a
#: face of any real width is many orders above this.
ROUNDING_SPREAD = 1e-9


def on_one_line(P: np.ndarray) -> bool:
    """Whether the points P (n, 3) lie on one line, or at one point, to rounding: their second
    principal spread is a rounding-sized fraction of the first. Such points determine no
    surface (every primitive through the line fits them)."""
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    return bool(s[1] <= ROUNDING_SPREAD * s[0])


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product of two 3-vectors, with np.cross's arithmetic (the same bits) without
    its broadcasting set-up, which costs tens of microseconds a call: the refits ask for
    tangent bases tens of thousands of times a cloud."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def tangent_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``a`` to an orthonormal basis."""
    a = unit(a)
    h = np.zeros(3)
    h[int(np.argmin(np.abs(a)))] = 1.0
    e1 = unit(cross3(a, h))
    return e1, cross3(a, e1)


def unit_derivatives(b: np.ndarray, dirs: tuple[np.ndarray, ...]) -> np.ndarray:
    """Derivatives (3, k) of ``unit(b)`` along the directions ``dirs`` (k vectors (3,)):
    ``(I - a a^T) e / |b|`` with ``a = unit(b)``; the chain rule of an axis fitted as
    ``unit(a0 + x1 e1 + x2 e2)``."""
    nb = float(np.linalg.norm(b))
    a = b / nb
    E = np.asarray(dirs, float)
    return ((E - np.outer(E @ a, a)) / nb).T


def radial(P: np.ndarray, point: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axial coordinate h (n,), radial distance rho (n,) and radial unit vectors (n, 3)."""
    h, rho = axial(P, point, axis)
    v = (P - point) - h[:, None] * axis
    return h, rho, v / np.where(rho > 1e-15, rho, 1.0)[:, None]


def axial(P: np.ndarray, point: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axial coordinate h (n,) and radial distance rho (n,) of the points P (n, 3) about the
    axis through ``point``: :func:`radial` without the unit vectors, which distances do not
    need (they are run on every candidate's points)."""
    P = np.asarray(P)
    if P.dtype not in (np.float32, np.float64):
        P = P.astype(np.float64)
    return _axial(P, np.asarray(point, np.float64), np.asarray(axis, np.float64))


@kernel(inline="always")
def axial_row(P, i, point, axis):
    """Point i of P (n, 3) about the axis through ``point`` (unit ``axis``): its offset
    (v0, v1, v2) from ``point``, axial coordinate h, radial offset (w0, w1, w2) and radial
    distance rho, in scalar arithmetic (numba)."""
    v0, v1, v2 = P[i, 0] - point[0], P[i, 1] - point[1], P[i, 2] - point[2]
    h = v0 * axis[0] + v1 * axis[1] + v2 * axis[2]
    w0, w1, w2 = v0 - h * axis[0], v1 - h * axis[1], v2 - h * axis[2]
    return v0, v1, v2, h, w0, w1, w2, np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)


# One pass in numba instead of four numpy temporaries: this runs on every candidate's points
# (a whole-cloud round evaluates hundreds of axes over 10^5 points). Written out in scalar
# arithmetic, it also gives the same bits on every CPU, where BLAS's dot kernels differ.
@kernel("f8[:, ::1], f8[::1], f8[::1]", "f8[:, ::1], f8[::1], f8[:]")
def _axial(P, point, axis):
    n = P.shape[0]
    h = np.empty(n)
    rho = np.empty(n)
    for i in range(n):
        _, _, _, h[i], _, _, _, rho[i] = axial_row(P, i, point, axis)
    return h, rho


@kernel()
def turned_axis(a0, e1, e2, x1, x2):
    """The axis ``unit(b)``, b = a0 + x1 e1 + x2 e2, of a refit that turns the axis a0 by two
    tangent parameters, and its derivatives U (3, 2) along e1 and e2 (as
    :func:`unit_derivatives`), for the families' refits written in numba."""
    b = a0 + x1 * e1 + x2 * e2
    nb = np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    a = b / nb
    d1 = e1[0] * a[0] + e1[1] * a[1] + e1[2] * a[2]
    d2 = e2[0] * a[0] + e2[1] * a[1] + e2[2] * a[2]
    U = np.empty((3, 2))
    for j in range(3):
        U[j, 0] = (e1[j] - d1 * a[j]) / nb
        U[j, 1] = (e2[j] - d2 * a[j]) / nb
    return a, U


def lines_intersection(P: np.ndarray, D: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Least-squares point closest to lines x = P_i + t D_i (unit D).

    Returns the point (3,) and the conditioning (smallest/largest eigenvalue of
    the normal matrix; near 0 when the lines are (nearly) parallel).
    """
    w = np.ones(len(P)) if w is None else w
    A = np.eye(3)[None] - D[:, :, None] * D[:, None, :]
    M = np.einsum("n,nij->ij", w, A)
    b = np.einsum("n,nij,nj->i", w, A, P)
    ev = np.linalg.eigvalsh(M)
    if ev[-1] <= 0:
        return np.zeros(3), 0.0
    return np.linalg.lstsq(M, b, rcond=None)[0], float(ev[0] / ev[-1])


def planes_intersection(P: np.ndarray, Nrm: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares point on all planes n_i·(x - p_i) = 0 (apex of a cone)."""
    M = Nrm.T @ Nrm
    b = Nrm.T @ np.einsum("ij,ij->i", Nrm, P)
    ev = np.linalg.eigvalsh(M)
    if ev[-1] <= 0:
        return np.zeros(3), 0.0
    return np.linalg.lstsq(M, b, rcond=None)[0], float(ev[0] / ev[-1])


def axis_from_normal_lines(P: np.ndarray, Nrm: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Axis of a surface of revolution: the line meeting all normal lines.

    Fits a linear line complex (c, c̄) to the normal lines (n_i, p_i × n_i) in
    Plücker coordinates (Pottmann & Randrup): minimise Σ (c·(p_i×n_i) + c̄·n_i)²
    with |c| = 1. For a surface of revolution the complex is singular (a line):
    the axis. Points are centred first for conditioning.

    Returns
    -------
    point : ndarray (3,), a point of the axis
    direction : ndarray (3,), unit
    pitch : float
        c·c̄ / |c|²; about 0 for a surface of revolution (helical surfaces: not).
    residual : float
        Smallest eigenvalue per line (how well a single axis explains them).
    """
    m = P.mean(axis=0)
    Q = P - m
    L = np.hstack([np.cross(Q, Nrm), Nrm])
    M = L.T @ L / len(P)
    M11, M12, M22 = M[:3, :3], M[:3, 3:], M[3:, 3:]
    try:
        K = np.linalg.solve(M22 + 1e-12 * np.eye(3), M12.T)
    except np.linalg.LinAlgError:
        return m, np.array([0, 0, 1.0]), 0.0, np.inf
    S = M11 - M12 @ K
    w, v = np.linalg.eigh(0.5 * (S + S.T))
    c = v[:, 0]
    cb = -K @ c
    pitch = float(c @ cb)
    # Axis of the complex: point = c × c̄_0 / |c|² with the pitch part removed.
    cb0 = cb - pitch * c
    point = np.cross(c, cb0) + m
    return point, c, pitch, float(max(w[0], 0.0))


@kernel("f8[::1], f8[:, ::1]")
def normal_equations(r, J):
    """Cost Σ r², JᵀJ (k, k) and Jᵀr (k,) of residuals r (n,) with Jacobian J (n, k), summed point
    by point in scalar loops: the same bits whatever the arrays' alignment, where BLAS's kernels
    sum in an order that depends on it."""
    k = J.shape[1]
    A = np.zeros((k, k))
    g = np.zeros(k)
    cost = 0.0
    for i in range(r.size):
        cost += r[i] * r[i]
        for j in range(k):
            g[j] += J[i, j] * r[i]
            for m in range(j + 1):
                A[j, m] += J[i, j] * J[i, m]
    for j in range(k):
        for m in range(j):
            A[m, j] = A[j, m]
    return cost, A, g


@kernel("f8[:, ::1], f8[::1], f8, f8[::1]")
def damped_step(A, g, mu, D):
    """The step h of (A + mu diag(D)) h = −g by Cholesky in scalar loops (k × k, k ≤ 10); ok is
    False when the matrix is not positive definite."""
    k = A.shape[0]
    L = np.zeros((k, k))
    for i in range(k):
        for j in range(i + 1):
            s = A[i, j] + (mu * D[i] if i == j else 0.0)
            for m in range(j):
                s -= L[i, m] * L[j, m]
            if i == j:
                if not s > 0.0:
                    return np.zeros(k), False
                L[i, i] = np.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    y = np.empty(k)
    for i in range(k):
        s = -g[i]
        for m in range(i):
            s -= L[i, m] * y[m]
        y[i] = s / L[i, i]
    h = np.empty(k)
    for i in range(k - 1, -1, -1):
        s = y[i]
        for m in range(i + 1, k):
            s -= L[m, i] * h[m]
        h[i] = s / L[i, i]
    return h, True


def gauss_newton(fun, x0: np.ndarray, iters: int = 8, tol: float = 1e-12) -> np.ndarray | None:
    """Damped Gauss–Newton on ``fun(x) -> (residuals (n,), jacobian (n, k))``.

    Hand-written because the families' analytic Jacobians make a few
    iterations cost microseconds, where a generic solver's overhead dominates.
    Its sums and solves run in scalar loops (:func:`normal_equations`,
    :func:`damped_step`), the same bits wherever the arrays sit in memory.
    """
    def system(x):
        r, J = fun(x)
        return normal_equations(np.ascontiguousarray(r, np.float64), np.ascontiguousarray(J, np.float64))

    x = np.asarray(x0, float)
    cost, A, g = system(x)
    lam = 1e-6
    for _ in range(iters):
        step, ok = damped_step(A, g, lam, np.diag(A) + 1e-15)
        if not ok:
            return None
        xn = x + step
        cn, An, gn = system(xn)
        if not np.isfinite(cn):
            return None
        if cn <= cost:
            x, A, g, cost = xn, An, gn, cn
            lam = max(lam / 10, 1e-12)
            if np.abs(step).max() < tol:
                break
        else:
            lam *= 10
    return x


def frame_turn_rows(frame, x: np.ndarray, v: np.ndarray, tilt: tuple[int, ...], h: float = 1e-7) -> np.ndarray:
    """Rows (3, k, m) of the derivatives of v @ f for each vector f of the
    frame ``frame(x)`` (a tuple of 3-vectors) with respect to the k
    parameters x; only the ``tilt`` columns turn the frame (finite
    differences on 3-vectors, cheap), the others are zero. ``v`` (m, 3)."""
    base = frame(x)
    out = np.zeros((len(base), len(x), len(v)))
    for j in tilt:
        xe = x.copy()
        xe[j] += h
        for i, (fe, f0) in enumerate(zip(frame(xe), base)):
            out[i, j] = v @ ((fe - f0) / h)
    return out
