"""Helical surfaces (threads): x = R(u) cos v, y = R(u) sin v,
z = k1 (u + n v) + k2, R(u) = R1 + (R2 − R1)(cos u + 1)/2, n ∈ ℤ \\ {0}.

In cylindrical coordinates the surface is ρ = A + B cos ψ with
ψ = (z − k2)/k1 − n φ, A = (R1 + R2)/2, B = (R2 − R1)/2: a cosine profile
of period 2π k1 along the axis, screwed with the pitch p = k1 n (axial
advance per radian; n is the number of thread starts, its sign the
handedness, k1 > 0).

Standard form: the axis along z through the origin, from the linear line
complex of the normal lines (its pitch is p). Voted: (A, B, log k1) — the
radii and the period — with n swept over 1–4 as windows of k1 around p/n,
and the phase k2 estimated per k1 by a linear least-squares fit of the
profile's first harmonic.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..hough import Grid
from .base import Frame, Family, Primitive, axis_from_normal_lines, register, tangent_basis, unit
from ._sampling import ORIGIN, Z_AXIS, Array, Sampler, inverse_cdf, span
from ._helix import cylindrical, frame_axes, gated_screw_placement
from ._noisy_profile import ml_radii
from . import _lm

TAU = 2.0 * np.pi
MAX_STARTS = 4
#: Half-width of each n's window of k1 around p/n (relative): the complex's
#: pitch comes out 1–6 % low on noisy clouds (smoothed normals).
K1_WINDOW = 0.14
#: Smallest quarter period of a thread, in inlier distances τ. Every point lies within a quarter
#: period of a flank, axially: a profile that fine explains any points near its band, as well as
#: the noise does, and the points cannot tell it apart. Measured at 0.5 % noise: ghost threads fitted
#: to the helical strips and bands of the screw part at 0.4-0.6; the random threads that are
#: recognised at 0.9 and above, those that are not at 0.8 and below (too fine for their sampling).
RESOLVED_QUARTER_TAUS = 0.75
#: Residual evaluations of the orthogonal-distance refinement after the Sampson fit (each
#: finds every point's foot): it starts close, a few Gauss–Newton steps.
ORTHOGONAL_EVALUATIONS = 20
#: The pitch search's span either side of the normal lines' pitch (factor). On a thread finer than
#: the normals' neighbourhood the normals average over both flanks towards a cylinder's, whose
#: normal lines meet the axis (pitch 0): measured 0.45-0.97 of the true pitch on noisy random
#: threads, the finest deep ones lowest.
PITCH_SPAN = 4.0
#: Relative steps of the pitch search, coarse then fine: the profile stays sharp within about
#: 1 % of the pitch over the three to four periods a thread of the benchmark spans.
PITCH_STEPS = (0.04, 0.01)
#: Points the pitch search sorts per trial pitch (a seeded subsample of larger sets).
PITCH_POINTS = 1500
#: The reported radii are the likelihood's while its noise σ and the least-squares residuals' RMS
#: agree within this factor either way: on a thread they do (1.00-1.01 on the complex benchmark's).
#: Points that are not the thread the segment claims (a wrong pitch or start count) read 0.45 or
#: 1.9 times: neither fit's radii mean anything there, and least squares at least keeps the
#: reported error its smallest.
ML_SIGMA_RATIO = 1.25


def harmonic_phase(rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Phase φ0 (K,) of the best fit ρ ≈ A + B cos(θ − φ0), B ≥ 0, by linear
    least squares in (A, B cos φ0, B sin φ0) for each column of θ (m, K);
    rho (m,)."""
    D = np.stack([np.ones_like(theta), np.cos(theta), np.sin(theta)], axis=-1)  # (m, K, 3)
    M = np.einsum("mki,mkj->kij", D, D) + 1e-12 * np.eye(3)
    b = np.einsum("mki,m->ki", D, rho)
    sol = np.linalg.solve(M, b[..., None])[..., 0]
    return np.arctan2(sol[:, 2], sol[:, 1])


def profile_pitch(Pl: np.ndarray, p0: float, seed: int = 0) -> float:
    """Pitch p (local units per radian) that makes the points' radius ρ one function of
    w = z − p φ, searched within a factor :data:`PITCH_SPAN` of ``p0`` (same sign).

    Points ``Pl`` (m, 3) in a frame whose z axis is the screw axis. On the helical surface
    ρ = A + B cos((w − k2)/k1) exactly when p = k1 n, so sorted by w the radii of neighbours
    differ only by the noise and the profile's slope (their mean absolute difference, the
    roughness); any other p smears the profile. It needs no normals, which a fine thread blurs:
    the normals' pitch ``p0`` only bounds the search.
    """
    if p0 == 0 or len(Pl) < 16:
        return p0
    if len(Pl) > PITCH_POINTS:
        Pl = Pl[np.sort(np.random.default_rng(seed).choice(len(Pl), PITCH_POINTS, replace=False))]
    rho, phi, z = np.hypot(Pl[:, 0], Pl[:, 1]), np.arctan2(Pl[:, 1], Pl[:, 0]), Pl[:, 2]

    def best(ps: np.ndarray) -> float:
        W = z[None, :] - ps[:, None] * phi[None, :]  # (k, m)
        roughness = np.mean(np.abs(np.diff(rho[np.argsort(W, axis=1)], axis=1)), axis=1)
        return float(ps[int(np.argmin(roughness))])

    coarse, fine = PITCH_STEPS
    k = int(np.ceil(np.log(PITCH_SPAN) / np.log1p(coarse)))
    p = best(p0 * (1 + coarse) ** np.arange(-k, k + 1))
    m = int(np.ceil(np.log1p(coarse) / np.log1p(fine)))
    return best(p * (1 + fine) ** np.arange(-m, m + 1))


def _pitch(Pl: np.ndarray, Nl: np.ndarray, seed: int) -> float:
    """The screw's pitch in the local frame: the normal lines' (invariant under rigid motions),
    sharpened on the profile (:func:`profile_pitch`)."""
    return profile_pitch(Pl, axis_from_normal_lines(Pl, Nl)[2], seed)


def _profile(A, B, psi):
    return A + B * np.cos(psi), -B * np.sin(psi)


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def helical_radius(R1: float, R2: float, u: Array) -> tuple[Array, Array]:
    """Radius R(u) = R1 + (R2 − R1)(cos u + 1)/2 and its derivative, shapes like u."""
    return R1 + 0.5 * (R2 - R1) * (np.cos(u) + 1.0), -0.5 * (R2 - R1) * np.sin(u)


def _helical_density(R1: float, R2: float, k1: float, starts: int, u: Array) -> Array:
    """Area element |S_u × S_v| of the helical surface (depends on u only), shape like u."""
    R, dR = helical_radius(R1, R2, u)
    return np.sqrt(k1 * k1 * (starts * starts * dR * dR + R * R) + R * R * dR * dR)


def sample_helical_surface(
    rng: np.random.Generator,
    n: int,
    R1: float,
    R2: float,
    k1: float,
    starts: int,
    periods: int,
    k2: float = 0.0,
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Uniform points on the helical surface z = k1 (u + starts·v) + k2 (see the module docstring),
    cut to the slab 0 ≤ z < periods · 2π k1 and the azimuth range ``arc`` (rad).

    ``periods`` (integer) whole profile periods make every azimuth carry the same area, so v is
    uniform; u is drawn by inverse CDF of the area element over one period, then moved by whole
    periods into the slab. Returns points (n, 3) and outward unit normals (n, 3).
    """
    if not (R2 > R1 > 0 and k1 > 0 and int(starts) != 0 and int(periods) >= 1):
        raise ValueError("helical surface needs R2 > R1 > 0, k1 > 0, starts ≠ 0, periods ≥ 1")
    a0, a1 = span(arc)
    starts, periods = int(starts), int(periods)
    v = a0 + (a1 - a0) * rng.random(n)
    g = np.linspace(0.0, TAU, 2049)
    s = inverse_cdf(rng, n, g, _helical_density(R1, R2, k1, starts, g)) + TAU * rng.integers(0, periods, n)
    # Slab condition: 0 ≤ k1 (u + starts v) + k2 < L  ⇔  u + starts v + k2/k1 ∈ [0, 2π periods).
    lo = -starts * v - k2 / k1
    u = lo + np.mod(s - lo, TAU * periods)  # whole periods: the density of u is unchanged
    R, dR = helical_radius(R1, R2, u)
    cv, sv = np.cos(v), np.sin(v)
    pts = np.column_stack([R * cv, R * sv, k1 * (u + starts * v) + k2])
    # −(S_u × S_v) points away from the axis.
    nrm = -np.column_stack([k1 * (starts * dR * sv - R * cv), -k1 * (R * sv + starts * dR * cv), R * dR])
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _helical_surface_area(R1: float, R2: float, k1: float, starts: int, periods: int, k2: float = 0.0,
                          arc: tuple[float, float] = (0.0, TAU)) -> float:
    g = np.linspace(0.0, TAU, 4097)
    d = _helical_density(R1, R2, k1, int(starts), g)
    return float((arc[1] - arc[0]) * int(periods) * np.sum(0.5 * (d[1:] + d[:-1]) * np.diff(g)))


def _helical_surface_local(R1: float, R2: float, k1: float, starts: int, k2: float = 0.0, **_: Any) -> dict[str, Any]:
    return {"axis_point": list(ORIGIN), "axis": list(Z_AXIS), "ref_direction": [1.0, 0.0, 0.0], "R1": float(R1),
            "R2": float(R2), "n": int(starts), "k1": float(k1), "k2": float(k2 % (TAU * k1))}


def _helical_surface_random(rng: np.random.Generator) -> dict[str, Any]:
    R2 = float(rng.uniform(0.7, 1.0))
    starts = int(rng.integers(1, MAX_STARTS + 1)) * (1 if rng.random() < 0.7 else -1)
    # Profile period 0.2–0.9 R2 and root radius 0.4–0.9 R2: from fine, deep threads, whose
    # flanks are a few sampling steps apart at a few thousand points, to coarse shallow ones.
    k1 = R2 * float(rng.uniform(0.2, 0.9)) / TAU
    return {"R1": R2 * float(rng.uniform(0.4, 0.9)), "R2": R2, "k1": k1, "starts": starts,
            "periods": int(rng.integers(3, 5)), "k2": float(rng.uniform(0.0, TAU * k1))}


@register
class HelicalSurface(Family):
    name = "helical_surface"
    param_names = ("axis_point", "axis", "ref_direction", "R1", "R2", "n", "k1", "k2")
    n_unknowns = 3
    role = "complex"
    precedence = 9
    #: Sought in the global round too, when the whole cloud's normal lines form
    #: one linear complex: otherwise planes and cylinders take the strip's bands
    #: there (5 noisy single instances: 0/5 recognised, 5/5 with it).
    search = "whole"
    order = 80
    color = (140, 80, 30)  # brown
    type_code = 10
    sampler = Sampler(sample_helical_surface, _helical_surface_area, _helical_surface_local,
                      _helical_surface_random,
                      {"axis_point": "point", "axis": "direction", "ref_direction": "direction",
                       "R1": "length", "R2": "length", "k1": "length", "k2": "length",
                       "n": "invariant"})

    # --- standard form and voting -------------------------------------------
    def placements(self, P, N, ctx):
        placed = gated_screw_placement(P, N, ctx)
        if placed is None:
            return []  # the whole cloud is not screw-invariant: leave it to the per-cluster rounds
        pl, p = placed
        Pl = pl.local(P, N)[0]
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        if abs(p) < 0.005 * max(float(np.median(rho)), 1e-9):
            return []  # no screw motion
        rng = np.random.default_rng(ctx.seed)
        sel = np.arange(len(Pl)) if len(Pl) <= 1500 else np.sort(rng.choice(len(Pl), 1500, replace=False))
        pl.info.update(p=profile_pitch(Pl, p, ctx.seed), local=Pl[sel])
        return [pl]

    @staticmethod
    def _k1_windows(p: float) -> list[tuple[int, float, float]]:
        """(n, k1_lo, k1_hi) for n = ±1…±MAX_STARTS (sign of p)."""
        s = 1 if p >= 0 else -1
        return [(s * m, abs(p) / m * (1 - K1_WINDOW), abs(p) / m * (1 + K1_WINDOW)) for m in range(1, MAX_STARTS + 1)]

    def region(self, Pl, Nl, ctx):
        p = _pitch(Pl, Nl, ctx.seed)
        rho = np.hypot(Pl[:, 0], Pl[:, 1])
        lo, hi = float(np.quantile(rho, 0.01)), float(np.quantile(rho, 0.99))
        wins = self._k1_windows(p)
        l0, l1 = np.log(max(wins[-1][1], 1e-9)), np.log(max(wins[0][2], 2e-9))
        nk = int(np.clip((l1 - l0) / 0.01, 8, 400))
        span = max(hi - lo, 1e-6)
        nr = int(np.clip(span / max(0.5 * ctx.cell, 1e-6), 12, 40))
        return Grid((lo, 0.0, l0), (hi, 0.6 * span, l1), (nr, nr, nk))

    def gamma(self, Pl, Nl, grid, ctx):
        p = _pitch(Pl, Nl, ctx.seed)
        rng = np.random.default_rng(ctx.seed)
        sel = np.arange(len(Pl)) if len(Pl) <= 800 else np.sort(rng.choice(len(Pl), 800, replace=False))
        X = Pl[sel]
        rho, phi, z = np.hypot(X[:, 0], X[:, 1]), np.arctan2(X[:, 1], X[:, 0]), X[:, 2]
        lk = grid.centers(2)
        k1, n = [], []
        for m, lo, hi in self._k1_windows(p):  # the sweep over n: a window of k1 each
            kk = np.exp(lk[(lk >= np.log(lo)) & (lk <= np.log(hi))])
            k1.append(kk)
            n.append(np.full(len(kk), m))
        k1, n = np.concatenate(k1), np.concatenate(n)
        if len(k1) == 0:
            return np.zeros(0, int), np.zeros((0, 3))
        theta = z[:, None] / k1[None, :] - n[None, :] * phi[:, None]  # (m, K)
        psi = theta - harmonic_phase(rho, theta)[None, :]
        cp = np.cos(psi)
        A = grid.centers(0)
        # Γ_P for each k1: the line ρ = A + B cos ψ in (A, B), sampled over A's bins.
        B = (rho[:, None, None] - A[None, None, :]) / np.where(np.abs(cp) > 0.3, cp, np.nan)[:, :, None]
        ok = np.isfinite(B) & (B > 0) & (B < grid.upper[1])
        vi, ki, ai = np.nonzero(ok)
        vals = np.stack([A[ai], B[vi, ki, ai], np.log(k1[ki])], axis=1)
        return sel[vi], vals

    def primitive(self, values, placement):
        A, B, k1 = float(values[0]), float(values[1]), float(np.exp(values[2]))
        p = placement.info.get("p", 0.0)
        n = int(np.sign(p)) * max(1, int(round(abs(p) / k1)))
        X = placement.info["local"]
        rho, phi = np.hypot(X[:, 0], X[:, 1]), np.arctan2(X[:, 1], X[:, 0])
        phase = float(harmonic_phase(rho, (X[:, 2] / k1 - n * phi)[:, None])[0])
        R = placement.R
        return Primitive(self.name, {"axis_point": placement.origin.copy(), "axis": R[2].copy(),
                                     "ref_direction": R[0].copy(), "R1": A - B, "R2": A + B, "n": n, "k1": k1,
                                     "k2": float(np.mod(k1 * phase, TAU * k1))})

    # --- geometry -----------------------------------------------------------
    def _foot(self, prim, P, iters: int = 6):
        """Foot of each point on the surface: Gauss–Newton on (ψ, δ) from the
        nearest sample of the profile in the point's meridian half-plane.

        Returns residual vectors in the point's meridian frame (n, 3), the
        tangents S_ψ, S_δ there (n, 3) each, the frame (φ (n,), e1, e2, a) and
        the foot's profile parameters (ψ (n,), δ (n,)).
        """
        p = prim.params
        A, B = 0.5 * (p["R1"] + p["R2"]), 0.5 * (p["R2"] - p["R1"])
        k1, n = p["k1"], int(p["n"])
        pitch = k1 * n
        rho, phi, z, (e1, e2, a) = cylindrical(P, p["axis_point"], p["axis"], p["ref_direction"])
        w = z - p["k2"] - pitch * phi
        # Profile (A + B cos ψ, k1 ψ): one period and its neighbours, densely sampled.
        per = TAU * k1
        m = np.floor(w / per)
        s = np.linspace(-np.pi, 3 * np.pi, 1025)
        curve = np.stack([_profile(A, B, s)[0], k1 * s], axis=1)
        j = cKDTree(curve).query(np.stack([rho, w - per * m], axis=1))[1]
        psi = s[j] + TAU * m
        dl = np.zeros_like(psi)
        X = np.stack([rho, np.zeros_like(rho), w], axis=1)
        for _ in range(iters):
            r_s, dr = _profile(A, B, psi)
            cd, sd = np.cos(dl), np.sin(dl)
            S = np.stack([r_s * cd, r_s * sd, k1 * psi + pitch * dl], axis=1)
            Jp = np.stack([dr * cd, dr * sd, np.full_like(psi, k1)], axis=1)
            Jd = np.stack([-r_s * sd, r_s * cd, np.full_like(psi, pitch)], axis=1)
            r = S - X
            a11, a12, a22 = (Jp * Jp).sum(1), (Jp * Jd).sum(1), (Jd * Jd).sum(1)
            g1, g2 = (Jp * r).sum(1), (Jd * r).sum(1)
            det = a11 * a22 - a12 * a12
            det = np.where(np.abs(det) > 1e-18, det, 1e-18)
            psi = psi - (a22 * g1 - a12 * g2) / det
            dl = dl - (a11 * g2 - a12 * g1) / det
        r_s, dr = _profile(A, B, psi)
        cd, sd = np.cos(dl), np.sin(dl)
        S = np.stack([r_s * cd, r_s * sd, k1 * psi + pitch * dl], axis=1)
        Jp = np.stack([dr * cd, dr * sd, np.full_like(psi, k1)], axis=1)
        Jd = np.stack([-r_s * sd, r_s * cd, np.full_like(psi, pitch)], axis=1)
        return S - X, Jp, Jd, (phi, e1, e2, a), (psi, dl)

    def distance(self, prim, P):
        return np.linalg.norm(self._foot(prim, P)[0], axis=1)

    def surface_normals(self, prim, P):
        _, Jp, Jd, (phi, e1, e2, a), _ = self._foot(prim, P)
        nl = unit(np.cross(Jp, Jd))  # in the meridian frame (e_ρ, e_φ, a)
        c, s = np.cos(phi), np.sin(phi)
        e_rho = c[:, None] * e1 + s[:, None] * e2
        e_phi = -s[:, None] * e1 + c[:, None] * e2
        return unit(nl[:, :1] * e_rho + nl[:, 1:2] * e_phi + nl[:, 2:] * a)

    def valid(self, prim, ctx):
        p = prim.params
        R1, R2, k1, n = p["R1"], p["R2"], p["k1"], int(p["n"])
        # A thread shallower than 4 % of its radius is a cylinder; a period beyond twice the
        # radius (k1 > R2, period > 2π R2) is a bulge of a surface of revolution, not a thread;
        # a profile whose quarter period is within about τ is unresolved (RESOLVED_QUARTER_TAUS).
        return (0 < R1 < R2 < ctx.max_radius and R2 - R1 >= 0.04 * R2 and 0 < k1 <= R2
                and 1 <= abs(n) <= MAX_STARTS + 2 and TAU * k1 / 4 >= RESOLVED_QUARTER_TAUS * ctx.tau)

    def fit(self, prim, P, N):
        if len(P) < 16:
            return None
        p0 = prim.params
        a0 = unit(p0["axis"])
        e1, e2 = tangent_basis(a0)
        n = int(p0["n"])

        def unpack(x):
            return unit(a0 + x[0] * e1 + x[1] * e2), p0["axis_point"] + x[2] * e1 + x[3] * e2, x[4], x[5], x[6], x[7]

        def res(x):
            a, q, A, B, k1, k2 = unpack(x)
            rho, phi, z, _ = cylindrical(P, q, a, p0["ref_direction"])
            psi = (z - k2) / k1 - n * phi
            # Sampson distance: F / |∇F| for F = ρ − A − B cos ψ.
            g = np.sqrt(1.0 + (B * np.sin(psi)) ** 2 * (1.0 / k1**2 + n * n / np.maximum(rho, 1e-9) ** 2))
            return (rho - A - B * np.cos(psi)) / g

        x0 = np.array([0, 0, 0, 0, 0.5 * (p0["R1"] + p0["R2"]), 0.5 * (p0["R2"] - p0["R1"]), p0["k1"], p0["k2"]])
        try:
            sol = _lm.solve(_lm.forward_difference_rows(res), x0, max_nfev=80)
        except Exception:
            return None
        if not np.isfinite(sol.x).all():
            return None
        a, q, A, B, k1, k2 = unpack(sol.x)
        if k1 < 0:  # (k1, n, ψ) → (−k1, −n, −ψ) describes the same surface
            return None
        if B < 0:  # ψ → ψ + π
            B, k2 = -B, k2 + np.pi * k1
        polished = self._orthogonal_fit(Primitive(self.name, {
            "axis_point": q, "axis": a, "ref_direction": frame_axes(a, p0["ref_direction"])[0],
            "R1": float(A - B), "R2": float(A + B), "n": n, "k1": float(k1), "k2": float(k2)}), P)
        if polished is not None:
            p1 = polished.params
            k1, k2 = p1["k1"], p1["k2"]
            A, B = 0.5 * (p1["R1"] + p1["R2"]), 0.5 * (p1["R2"] - p1["R1"])
        # Axis point at the foot of the centroid (k2 follows), reference kept orthogonal.
        s = (P.mean(axis=0) - q) @ a
        e1n = frame_axes(a, p0["ref_direction"])[0]
        return Primitive(self.name, {"axis_point": q + s * a, "axis": a, "ref_direction": e1n, "R1": float(A - B),
                                     "R2": float(A + B), "n": n, "k1": float(k1),
                                     "k2": float(np.mod(k2 - s, TAU * k1))})

    def final_fit(self, prim, P, N):
        """:meth:`fit`, then the profile's radii by maximum likelihood under the noise
        (:func:`~houghcad.families._noisy_profile.ml_radii`): where the root and crest bend within
        the noise, least squares deepens the profile. Least squares stays when the likelihood's σ
        and the residuals' RMS disagree (:data:`ML_SIGMA_RATIO`)."""
        fitted = self.fit(prim, P, N)
        if fitted is None:
            return None
        p = fitted.params
        k1, n = float(p["k1"]), int(p["n"])
        rho, phi, z, _ = cylindrical(P, p["axis_point"], p["axis"], p["ref_direction"])
        sigma0 = float(np.sqrt(np.mean(np.sum(self._foot(fitted, P)[0] ** 2, axis=1))))
        out = ml_radii(rho, z - p["k2"] - k1 * n * phi, k1 * n, k1, p["R1"], p["R2"], sigma0,
                       lambda r1, r2, u: _helical_density(r1, r2, k1, n, u))
        if out is None or not 1.0 / ML_SIGMA_RATIO <= out[2] / sigma0 <= ML_SIGMA_RATIO:
            return fitted
        return Primitive(self.name, {**p, "R1": out[0], "R2": out[1]})

    def _orthogonal_fit(self, prim: Primitive, P: np.ndarray) -> Primitive | None:
        """Refine the profile (R1, R2, k1, k2) by the signed orthogonal distances of P (m, 3) to
        the surface, the feet by :meth:`_foot`; the axis stays. None when it fails or ends on a
        degenerate profile.

        Sampson's distance F / |∇F| is first order: where the profile bends within the noise
        (the root and crest of a deep thread of short period) it reads the noisy points there as
        closer than they are, and the fit flattens the profile (measured: the root radius 1–2 %
        too large at σ = 1.2 % of the radius, periods 0.3–0.5 R2; within 1 % with the feet).
        """
        p0 = prim.params
        n = int(p0["n"])

        def make(x) -> Primitive:
            return Primitive(self.name, {**p0, "R1": x[0], "R2": x[1], "k1": x[2], "k2": x[3]})

        last: dict[bytes, tuple] = {}

        def foot(x):
            # The solver asks for the residuals and then the Jacobian at the same x: find the
            # feet once for both.
            key = np.asarray(x, float).tobytes()
            if key not in last:
                r, Jp, Jd, (phi, *_), (psi, dl) = self._foot(make(x), P)
                last.clear()
                last[key] = (r, unit(np.cross(Jp, Jd)), phi, psi, dl)
            return last[key]

        def res(x):
            r, nrm, *_ = foot(x)
            return np.einsum("ij,ij->i", r, nrm)

        def jac(x):
            # At a foot, S − X is along the normal and the foot's own motion is tangent: the
            # derivative of the signed distance is the normal's component of ∂(S − X)/∂θ.
            _, nrm, phi, psi, dl = foot(x)
            radial = nrm[:, 0] * np.cos(dl) + nrm[:, 1] * np.sin(dl)
            c = np.cos(psi)
            return np.column_stack([radial * 0.5 * (1.0 - c), radial * 0.5 * (1.0 + c),
                                    nrm[:, 2] * (psi + n * (dl + phi)), nrm[:, 2]])

        x0 = np.array([p0["R1"], p0["R2"], p0["k1"], p0["k2"]], float)
        try:
            sol = _lm.solve(_lm.rows_of(res, jac), x0, max_nfev=ORTHOGONAL_EVALUATIONS)
        except Exception:
            return None
        x = sol.x
        if not np.isfinite(x).all() or not (0 < x[0] < x[1]) or x[2] <= 0:
            return None
        return make(x)

    # --- output -------------------------------------------------------------
    def to_world(self, prim, T):
        p = prim.params
        return {"axis_point": T.inv_points(p["axis_point"]).tolist(),
                "axis": unit(T.inv_dirs(p["axis"])).tolist(),
                "ref_direction": unit(T.inv_dirs(p["ref_direction"])).tolist(),
                "R1": T.inv_length(p["R1"]), "R2": T.inv_length(p["R2"]), "n": int(p["n"]),
                "k1": T.inv_length(p["k1"]), "k2": T.inv_length(p["k2"])}

    length_descriptors = ("R1", "R2", "k1")
    integer_descriptors = ("n",)

    def descriptors(self, prim):
        p = prim.params
        return {"R1": float(p["R1"]), "R2": float(p["R2"]), "k1": float(p["k1"]), "n": int(p["n"])}

    def frame(self, prim):
        return Frame("line", np.asarray(prim.params["axis_point"], float), unit(prim.params["axis"]))


def from_world(params: dict) -> Primitive:
    """A Primitive from world-style parameters (synth's ground truth), same frame."""
    v = {k: (np.asarray(params[k], float) if k in ("axis_point", "axis", "ref_direction") else float(params[k]))
         for k in HelicalSurface.param_names}
    v["n"] = int(round(v["n"]))
    v["axis"] = unit(v["axis"])
    return Primitive("helical_surface", v)
