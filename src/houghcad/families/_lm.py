"""Levenberg–Marquardt for the families' refits: Moré's trust-region method, as in MINPACK's
``lmder`` (J. J. Moré, *The Levenberg–Marquardt algorithm: implementation and theory*, 1978),
written in numba.

Why by hand, and not ``scipy.optimize.least_squares(method="lm")``, which runs the same method:

- **Reproducible.** scipy 1.17's MINPACK answers differently from identical inputs depending on
  the process's memory state (measured: a thin cone's refit, 1,500 calls after filling freed
  blocks with 0, 1e300 or NaN, gave 2–3 answers). An ill-conditioned fit amplifies those last bits
  into a different segment, so the same cloud gave two outputs run to run.
- **Not slower.** A refit of a few hundred points takes 10–40 evaluations, and scipy's Python
  wrappers per evaluation cost more than the numba residuals themselves: on random cone and torus
  refits this runs in 0.18 ms against scipy's 0.32 ms, though over a whole run the difference is
  within the timing noise.

The driver is *reverse communication*: numba cannot cache a function that takes another jitted
function as an argument, so the Python loop in :func:`solve` calls the family's jitted
``rows(*args, x, jacobian)`` and hands its output to two jitted steps, :func:`_accept_jacobian`
(QR, scaling, gradient test, first trial step) and :func:`_judge_trial` (the trust region's
update, the convergence tests and, if the trial failed, the next trial step).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..kernels import kernel

#: Step bound factor: the first trust region is FACTOR × the scaled norm of x0 (MINPACK's default).
FACTOR = 100.0
_EPS = np.finfo(np.float64).eps
_DWARF = np.finfo(np.float64).tiny

#: MINPACK's stop codes 1–8 (index) as scipy's ``status``; 6–8, tolerances below the machine's
#: precision, as the tolerance they stand for.
_STATUS = (-1, 2, 3, 4, 1, 0, 2, 3, 1)

# State vector slots (one float64 array so that a jitted step's arguments stay few).
_FNORM, _PAR, _DELTA, _XNORM, _ITER, _NFEV, _FTOL, _XTOL, _GTOL, _MAXFEV, _PNORM = range(11)


@dataclass(frozen=True)
class LMResult:
    """The end of a Levenberg–Marquardt run.

    Attributes
    ----------
    x : ndarray, shape (n,)
        The last accepted parameters.
    fun : ndarray, shape (m,)
        The residuals at ``x``.
    status : int
        scipy's code: 0 evaluations spent (``max_nfev``), 1 gradient ≤ gtol, 2 relative reduction
        ≤ ftol, 3 relative step ≤ xtol, 4 both of the last two.
    nfev : int
        Residual evaluations, the Jacobian's not counted.
    """

    x: np.ndarray
    fun: np.ndarray
    status: int
    nfev: int


def solve(rows: Callable, x0: np.ndarray, args: tuple = (), *, max_nfev: int | None = None,
          ftol: float = 1e-8, xtol: float = 1e-8, gtol: float = 1e-8) -> LMResult:
    """Minimise ||r(x)||² from ``x0``, where ``rows(*args, x, jacobian)`` returns the residuals
    r (m,) and, when ``jacobian``, their derivatives J (m, n) (else anything as second value).

    The same options and stopping rules as ``scipy.optimize.least_squares(method="lm",
    x_scale="jac")``, and the same answers up to rounding. Raises ``ValueError`` when m < n or the
    residuals at ``x0`` are not finite, as scipy does.
    """
    x = np.array(x0, dtype=np.float64)
    n = x.size
    r0, _ = rows(*args, x, False)
    r = np.array(r0, dtype=np.float64)  # a copy: accepted trials are written into it
    if r.size < n:
        raise ValueError(f"{r.size} residuals for {n} variables")
    if not np.isfinite(r).all():
        raise ValueError("residuals are not finite at the initial point")
    s = np.zeros(11)
    s[_FNORM] = _norm(r)  # not BLAS's dot, whose last bits may follow the memory's alignment
    s[_ITER], s[_NFEV] = 1, 1
    s[_FTOL], s[_XTOL], s[_GTOL] = ftol, xtol, gtol
    s[_MAXFEV] = 100 * n if max_nfev is None else max_nfev
    R = np.empty((n, n))
    W = np.zeros((6, n))          # diag, qtf, acnorm, step, sdiag, scratch
    ipvt = np.empty(n, np.int64)
    xt = np.empty(n)
    while True:
        _, J = rows(*args, x, True)
        code = _accept_jacobian(np.array(J, dtype=np.float64), r, x, R, W, ipvt, xt, s)
        while code == 0:
            rt, _ = rows(*args, xt, False)
            rt = np.ascontiguousarray(rt, dtype=np.float64)
            code = _judge_trial(rt, r, x, R, W, ipvt, xt, s)
        if code > 0:
            return LMResult(x=x, fun=r, status=_STATUS[code], nfev=int(s[_NFEV]))


def rows_of(fun: Callable[[np.ndarray], np.ndarray], jac: Callable[[np.ndarray], np.ndarray]) -> Callable:
    """The ``rows`` of :func:`solve` from scipy-style ``fun(x)`` (m,) and ``jac(x)`` (m, n)."""
    return lambda x, jacobian: (None, jac(x)) if jacobian else (fun(x), None)


def forward_difference_rows(fun: Callable[[np.ndarray], np.ndarray]) -> Callable:
    """The ``rows`` of :func:`solve` from ``fun(x)`` (m,) alone, its Jacobian by forward
    differences with scipy's steps (``least_squares``' default ``jac="2-point"``): column i is
    (fun(x + h e_i) − fun(x)) / h, h = √eps · max(1, |x_i|), signed as x_i (0 counts as positive).
    The residuals at the Jacobian's x are those of the last evaluation there, when it was last."""
    last: list = [None, None]  # the latest x (bytes) and its residuals

    def rows(x: np.ndarray, jacobian: bool):
        key = x.tobytes()
        if last[0] != key:
            last[0], last[1] = key, np.asarray(fun(x), dtype=np.float64)
        if not jacobian:
            return last[1], None
        f0 = last[1]
        h = np.sqrt(_EPS) * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        J = np.empty((f0.size, x.size))
        for i in range(x.size):  # one evaluation per parameter: a handful
            x1 = x.copy()
            x1[i] = x[i] + h[i]
            J[:, i] = (np.asarray(fun(x1), dtype=np.float64) - f0) / (x1[i] - x[i])
        return f0, J

    return rows


@kernel("f8[::1]")
def _norm(v):
    return np.sqrt(np.sum(v * v))


@kernel("f8[:, ::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], i8[::1], f8[::1], f8[::1]",
        "f8[::1, :], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], i8[::1], f8[::1], f8[::1]")
def _accept_jacobian(A, r, x, R, W, ipvt, xt, s):
    """Factor the Jacobian A (m, n) at x (A is overwritten), update the scaling, test the
    gradient, and put the first trial point in xt. Returns 0 (evaluate xt) or a stop code."""
    m, n = A.shape
    diag, qtf, acnorm = W[0], W[1], W[2]
    rdiag = np.empty(n)
    _qr_pivoted(A, ipvt, rdiag, acnorm)
    if s[_ITER] == 1:
        for j in range(n):
            diag[j] = acnorm[j] if acnorm[j] != 0 else 1.0
        s[_XNORM] = _norm(diag * x)
        s[_DELTA] = FACTOR * s[_XNORM] if s[_XNORM] != 0 else FACTOR
    # Q^T r, then R with its diagonal in place.
    wa = r.copy()
    for j in range(n):
        if A[j, j] != 0:
            t = 0.0
            for i in range(j, m):
                t += A[i, j] * wa[i]
            t = -t / A[j, j]
            for i in range(j, m):
                wa[i] += t * A[i, j]
        A[j, j] = rdiag[j]
        qtf[j] = wa[j]
    for j in range(n):
        for i in range(n):
            R[i, j] = A[i, j]
    # The scaled gradient's largest cosine with a column: the gradient test.
    fnorm = s[_FNORM]
    gnorm = 0.0
    if fnorm != 0:
        for j in range(n):
            l = ipvt[j]
            if acnorm[l] != 0:
                t = 0.0
                for i in range(j + 1):
                    t += R[i, j] * (qtf[i] / fnorm)
                gnorm = max(gnorm, abs(t / acnorm[l]))
    if gnorm <= s[_GTOL]:
        return 4
    if gnorm <= _EPS:
        return 8
    for j in range(n):
        diag[j] = max(diag[j], acnorm[j])
    _trial(x, R, W, ipvt, xt, s)
    return 0


@kernel()
def _trial(x, R, W, ipvt, xt, s):
    """The Levenberg–Marquardt step within the trust region: xt = x + step."""
    diag, qtf, step = W[0], W[1], W[3]
    s[_PAR] = _lmpar(R, ipvt, diag, qtf, s[_DELTA], s[_PAR], step, W[4], W[5])
    for j in range(x.size):
        step[j] = -step[j]
        xt[j] = x[j] + step[j]
    s[_PNORM] = _norm(diag * step)
    if s[_ITER] == 1:
        s[_DELTA] = min(s[_DELTA], s[_PNORM])


@kernel("f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], i8[::1], f8[::1], f8[::1]")
def _judge_trial(rt, r, x, R, W, ipvt, xt, s):
    """Compare the trial's actual reduction with the model's, move the trust region, accept or
    reject xt and test convergence. Returns 0 (evaluate the new xt), -1 (accepted: evaluate the
    Jacobian at x) or a stop code."""
    n = x.size
    diag, step = W[0], W[3]
    s[_NFEV] += 1
    fnorm, pnorm, par, delta = s[_FNORM], s[_PNORM], s[_PAR], s[_DELTA]
    fnorm1 = _norm(rt)
    actred = 1.0 - (fnorm1 / fnorm) ** 2 if 0.1 * fnorm1 < fnorm else -1.0
    # The model's predicted reduction and the directional derivative, from R P^T step.
    wa = np.zeros(n)
    for j in range(n):
        t = step[ipvt[j]]
        for i in range(j + 1):
            wa[i] += R[i, j] * t
    t1 = _norm(wa) / fnorm
    t2 = np.sqrt(par) * pnorm / fnorm
    prered = t1 * t1 + t2 * t2 / 0.5
    dirder = -(t1 * t1 + t2 * t2)
    ratio = actred / prered if prered != 0 else 0.0
    if ratio <= 0.25:
        t = 0.5 if actred >= 0 else 0.5 * dirder / (dirder + 0.5 * actred)
        if 0.1 * fnorm1 >= fnorm or t < 0.1:
            t = 0.1
        delta = t * min(delta, pnorm / 0.1)
        par = par / t
    elif par == 0 or ratio >= 0.75:
        delta = pnorm / 0.5
        par = 0.5 * par
    s[_PAR], s[_DELTA] = par, delta
    accepted = ratio >= 1e-4
    if accepted:
        x[:] = xt
        r[:] = rt
        s[_XNORM] = _norm(diag * x)
        s[_FNORM] = fnorm1
        s[_ITER] += 1
    code = 0
    if abs(actred) <= s[_FTOL] and prered <= s[_FTOL] and 0.5 * ratio <= 1:
        code = 1
    if delta <= s[_XTOL] * s[_XNORM]:
        code = 3 if code == 1 else 2
    if code:
        return code
    if s[_NFEV] >= s[_MAXFEV]:
        return 5
    if abs(actred) <= _EPS and prered <= _EPS and 0.5 * ratio <= 1:
        return 6
    if delta <= _EPS * s[_XNORM]:
        return 7
    if accepted:
        return -1
    _trial(x, R, W, ipvt, xt, s)
    return 0


@kernel()
def _qr_pivoted(A, ipvt, rdiag, acnorm):
    """Householder QR of A (m, n) with column pivoting, in place: the vectors below and on the
    diagonal, R's off-diagonal part above it, R's diagonal in rdiag; ipvt the permutation and
    acnorm the column norms of the input."""
    m, n = A.shape
    wa = np.empty(n)
    for j in range(n):
        acnorm[j] = _norm(A[:, j])
        rdiag[j] = acnorm[j]
        wa[j] = rdiag[j]
        ipvt[j] = j
    for j in range(min(m, n)):
        kmax = j
        for k in range(j, n):
            if rdiag[k] > rdiag[kmax]:
                kmax = k
        if kmax != j:
            for i in range(m):
                A[i, j], A[i, kmax] = A[i, kmax], A[i, j]
            rdiag[kmax] = rdiag[j]
            wa[kmax] = wa[j]
            ipvt[j], ipvt[kmax] = ipvt[kmax], ipvt[j]
        ajnorm = _norm(A[j:, j])
        if ajnorm != 0:
            if A[j, j] < 0:
                ajnorm = -ajnorm
            for i in range(j, m):
                A[i, j] /= ajnorm
            A[j, j] += 1.0
            for k in range(j + 1, n):
                t = 0.0
                for i in range(j, m):
                    t += A[i, j] * A[i, k]
                t /= A[j, j]
                for i in range(j, m):
                    A[i, k] -= t * A[i, j]
                if rdiag[k] != 0:
                    q = A[j, k] / rdiag[k]
                    rdiag[k] *= np.sqrt(max(0.0, 1.0 - q * q))
                    if 0.05 * (rdiag[k] / wa[k]) ** 2 <= _EPS:
                        rdiag[k] = _norm(A[j + 1:, k])
                        wa[k] = rdiag[k]
        rdiag[j] = -ajnorm


@kernel()
def _lmpar(R, ipvt, diag, qtb, delta, par, x, sdiag, wa2):
    """The Levenberg–Marquardt parameter: the par ≥ 0 whose solution x of
    min ||[R P^T; √par D] x − [qtb; 0]|| has ||D x|| within 10 % of delta (or par = 0 when the
    Gauss–Newton step already lies inside). R's strict lower triangle is overwritten."""
    n = R.shape[0]
    nsing = _gauss_newton_step(R, ipvt, qtb, x)
    for j in range(n):
        wa2[j] = diag[j] * x[j]
    dxnorm = _norm(wa2)
    fp = dxnorm - delta
    if fp <= 0.1 * delta:
        return 0.0
    parl, paru, gnorm = _par_bounds(R, ipvt, diag, qtb, delta, wa2, dxnorm, fp, nsing)
    par = min(max(par, parl), paru)
    if par == 0:
        par = gnorm / dxnorm
    wa1 = np.empty(n)
    it = 0
    while True:
        it += 1
        if par == 0:
            par = max(_DWARF, 0.001 * paru)
        sq = np.sqrt(par)
        for j in range(n):
            wa1[j] = sq * diag[j]
        _qrsolv(R, ipvt, wa1, qtb, x, sdiag)
        for j in range(n):
            wa2[j] = diag[j] * x[j]
        dxnorm = _norm(wa2)
        prev = fp
        fp = dxnorm - delta
        if abs(fp) <= 0.1 * delta or (parl == 0 and fp <= prev and prev < 0) or it == 10:
            return par
        # Newton's correction of par, through the triangle S that _qrsolv left.
        for j in range(n):
            l = ipvt[j]
            wa1[j] = diag[l] * (wa2[l] / dxnorm)
        for j in range(n):
            wa1[j] /= sdiag[j]
            t = wa1[j]
            for i in range(j + 1, n):
                wa1[i] -= R[i, j] * t
        t = _norm(wa1)
        parc = ((fp / delta) / t) / t
        if fp > 0:
            parl = max(parl, par)
        if fp < 0:
            paru = min(paru, par)
        par = max(parl, par + parc)


@kernel()
def _gauss_newton_step(R, ipvt, qtb, x):
    """x (n,) solving R P^T x = qtb, zero along R's singular tail; returns the rank used."""
    n = R.shape[0]
    wa1 = np.empty(n)
    nsing = n
    for j in range(n):
        wa1[j] = qtb[j]
        if R[j, j] == 0 and nsing == n:
            nsing = j
        if nsing < n:
            wa1[j] = 0.0
    for j in range(nsing - 1, -1, -1):
        wa1[j] /= R[j, j]
        t = wa1[j]
        for i in range(j):
            wa1[i] -= R[i, j] * t
    for j in range(n):
        x[ipvt[j]] = wa1[j]
    return nsing


@kernel()
def _par_bounds(R, ipvt, diag, qtb, delta, wa2, dxnorm, fp, nsing):
    """Bounds (parl, paru) on the parameter and the scaled gradient's norm: parl from Newton's
    step at par = 0 (0 when R is singular), paru from the gradient."""
    n = R.shape[0]
    wa1 = np.empty(n)
    parl = 0.0
    if nsing >= n:
        for j in range(n):
            l = ipvt[j]
            wa1[j] = diag[l] * (wa2[l] / dxnorm)
        for j in range(n):
            t = 0.0
            for i in range(j):
                t += R[i, j] * wa1[i]
            wa1[j] = (wa1[j] - t) / R[j, j]
        t = _norm(wa1)
        parl = ((fp / delta) / t) / t
    for j in range(n):
        t = 0.0
        for i in range(j + 1):
            t += R[i, j] * qtb[i]
        wa1[j] = t / diag[ipvt[j]]
    gnorm = _norm(wa1)
    paru = gnorm / delta
    if paru == 0:
        paru = _DWARF / min(delta, 0.1)
    return parl, paru, gnorm


@kernel()
def _qrsolv(R, ipvt, dg, qtb, x, sdiag):
    """Solve [R P^T; D] x ≈ [qtb; 0] for the diagonal D = dg (n,) by Givens rotations that
    eliminate D against R. The rotated triangle S goes to R's strict lower part (transposed) and
    its diagonal to sdiag; R's upper part and diagonal are kept."""
    n = R.shape[0]
    wa = np.empty(n)
    for j in range(n):
        for i in range(j, n):
            R[i, j] = R[j, i]
        x[j] = R[j, j]
        wa[j] = qtb[j]
    for j in range(n):
        l = ipvt[j]
        if dg[l] != 0:
            for k in range(j, n):
                sdiag[k] = 0.0
            sdiag[j] = dg[l]
            qtbpj = 0.0
            for k in range(j, n):
                if sdiag[k] == 0:
                    continue
                if abs(R[k, k]) < abs(sdiag[k]):
                    cot = R[k, k] / sdiag[k]
                    sn = 0.5 / np.sqrt(0.25 + 0.25 * cot * cot)
                    cs = sn * cot
                else:
                    tn = sdiag[k] / R[k, k]
                    cs = 0.5 / np.sqrt(0.25 + 0.25 * tn * tn)
                    sn = cs * tn
                R[k, k] = cs * R[k, k] + sn * sdiag[k]
                t = cs * wa[k] + sn * qtbpj
                qtbpj = -sn * wa[k] + cs * qtbpj
                wa[k] = t
                for i in range(k + 1, n):
                    t = cs * R[i, k] + sn * sdiag[i]
                    sdiag[i] = -sn * R[i, k] + cs * sdiag[i]
                    R[i, k] = t
        sdiag[j] = R[j, j]
        R[j, j] = x[j]
    nsing = n
    for j in range(n):
        if sdiag[j] == 0 and nsing == n:
            nsing = j
        if nsing < n:
            wa[j] = 0.0
    for j in range(nsing - 1, -1, -1):
        t = 0.0
        for i in range(j + 1, nsing):
            t += R[i, j] * wa[i]
        wa[j] = (wa[j] - t) / sdiag[j]
    for j in range(n):
        x[ipvt[j]] = wa[j]
