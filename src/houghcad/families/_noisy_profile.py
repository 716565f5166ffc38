"""Maximum-likelihood radii of a thread's profile under Gaussian noise (helical surface).

Least squares on orthogonal distances is the maximum-likelihood fit only while the noise is small
against the surface's curvature radius. The root and crest of a deep thread of short period bend
far tighter than that: a noisy point beyond the crest lies nearer a flank than the crest's tip, so
the fit moves the tip out to meet it, and the root in. On the complex benchmark's deep threads
(root 0.41–0.58 of the outer radius, period 0.24–0.39 of it, σ = 0.5 % of the diagonal) the least
squares fit of the true points, started at the truth, reads the root radius 1.4–3.4 % low and the
outer radius 0.8–1.2 % high.

Here the points are modelled as what they are: the surface's points, drawn evenly over its area,
moved by isotropic Gaussian noise σ. In the meridian coordinates (ρ, w = z − k2 − p φ) of a screw
surface, the profile is one curve repeated with period 2π k1 in w, and a point's density is the
curve's area-weighted samples blurred by the noise: N(ρ; σ) along ρ and N(w; σ √(1 + (p/ρ)²))
along w (a tangential step δ moves w by p δ / ρ). The radii and σ maximise the likelihood; the
axis, pitch and phase stay as the least-squares fit left them (they are not biased: the profile is
symmetric about its crest and root).

Written by hand: the likelihood is a sum over the profile's samples for every point, which no
library's mixture or density fit expresses (the samples' weights and positions move with the
parameters).
"""

from __future__ import annotations

import numpy as np

from ..kernels import kernel

TAU = 2.0 * np.pi
#: Points the likelihood reads (a seeded subsample of larger sets): the radii's standard error at
#: 2,000 points is a few thousandths of their difference.
ML_POINTS = 2000
#: Share of the likelihood given to a uniform background over the points' (ρ, w) box: a few points
#: of a neighbouring face in the segment must not pull the profile out to reach them.
BACKGROUND = 0.01
#: Profile samples per noise σ of its arc length (at least 32 per period): the blurred curve is
#: smooth once its samples are closer than σ.
SAMPLES_PER_SIGMA = 2.0
#: Most profile samples per period. Beyond, σ is under a 256th of the profile's length: its bias on
#: the radii (of the order σ² times the curvature) is below the fit's own scatter.
MAX_SAMPLES = 512


@kernel("f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8, f8, f8", nogil=True)
def _nll(rho: np.ndarray, w: np.ndarray, wscale: np.ndarray, cr: np.ndarray, cw: np.ndarray,
         wt: np.ndarray, period: float, sigma: float, background: float) -> float:
    """Negative log-likelihood of the points (ρ, w) (m,) each, ``wscale`` (m,) the factor of σ
    along w, under the profile samples (cr, cw, wt) (K,) each (weights summing to 1) of one
    period, blurred by σ; ``background`` the uniform density mixed in."""
    inv = 0.5 / (sigma * sigma)
    norm = 1.0 / (TAU * sigma * sigma * period)
    total = 0.0
    for i in range(len(rho)):
        iw = inv / (wscale[i] * wscale[i])
        acc = 0.0
        for j in range(len(cr)):
            dr = rho[i] - cr[j]
            er = dr * dr * inv
            if er > 18.0:  # beyond 6 σ: nothing
                continue
            dw = w[i] - cw[j]
            dw -= period * np.floor(dw / period + 0.5)  # nearest repetition of the profile
            acc += wt[j] * np.exp(-er - dw * dw * iw)
        total -= np.log(acc * norm / wscale[i] + background)
    return total


def ml_radii(rho: np.ndarray, w: np.ndarray, pitch: float, k1: float, R1: float, R2: float,
             sigma0: float, density, seed: int = 0) -> tuple[float, float, float] | None:
    """Maximum-likelihood (R1, R2, σ) of the profile ρ = A + B cos(w / k1) (A, B the mean and
    half-difference of the radii) for points at meridian coordinates ``rho``, ``w`` (m,) each,
    ``w`` already reduced by the phase; started at the least-squares radii and ``sigma0``.

    ``density(R1, R2, u)`` is the surface's area element at the profile parameters u (K,), up to
    a constant. None when the noise is too small to bias least squares (:data:`MAX_SAMPLES`) or the
    optimum is degenerate (radii crossed).
    """
    if len(rho) > ML_POINTS:
        keep = np.sort(np.random.default_rng(seed).choice(len(rho), ML_POINTS, replace=False))
        rho, w = rho[keep], w[keep]
    period = TAU * k1
    w = np.mod(w, period)
    wscale = np.sqrt(1.0 + (pitch / np.maximum(rho, 1e-12)) ** 2)
    span = max(float(np.ptp(rho)), 1e-12)
    background = BACKGROUND / (span * period)
    arc = 2.0 * (R2 - R1) + period  # about the profile's length per period
    K = int(max(SAMPLES_PER_SIGMA * arc / sigma0, 32))
    if K > MAX_SAMPLES:
        return None  # noise this small bends nothing: least squares is unbiased there
    u = (np.arange(K) + 0.5) * (TAU / K)
    cu = np.cos(u)

    def nll(x: np.ndarray) -> float:
        r1, r2, ls = x
        if not 0.0 < r1 < r2:
            return 1e300
        wt = density(r1, r2, u)
        wt = wt / wt.sum()
        cr = r1 + 0.5 * (r2 - r1) * (cu + 1.0)
        return _nll(rho, w, wscale, cr, k1 * u, wt, period, float(np.exp(ls)), background)

    x0 = np.array([R1, R2, np.log(sigma0)])
    scale = 0.01 * (R2 - R1)  # the first steps; the radii are sought to a thousandth of the depth
    from scipy.optimize import minimize  # here: its import is 66 ms of every run's start

    sol = minimize(nll, x0, method="Nelder-Mead",
                   options={"xatol": 0.1 * scale, "fatol": 0.01, "maxiter": 400,
                            "initial_simplex": x0 + np.array([[0, 0, 0], [scale, 0, 0], [0, scale, 0], [0, 0, 0.1]])})
    r1, r2, ls = sol.x
    if not (np.isfinite(sol.x).all() and 0.0 < r1 < r2):
        return None
    return float(r1), float(r2), float(np.exp(ls))
