"""Ellipsoids (a complex family, voted per cluster).

Standard forms
--------------
- of revolution: x²/p² + y²/p² + z²/q² = 1 (two unknowns p, q) once the
  axis is along z and the centre at the origin. The axis is the line that
  meets the normal lines (:func:`axis_from_normal_lines`); the centre along
  it comes from an axis-aligned conic fitted in the meridian plane.
- with three axes: x²/e₀² + y²/e₁² + z²/e₂² = 1 (three unknowns) once the
  centre is at the origin and the axes along x, y, z. Centre and axes come
  from a least-squares quadric fitted to the points *and* their normals
  (∇Q ∥ n is linear in the quadric's coefficients); the vote then fixes the
  semi-axes (e₀, e₁ swept over their bins, e₂ solved).

Near-spheres (all semi-axes equal within :data:`SPHERE_TOL`) are rejected by
``valid`` so that spheres stay spheres.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from ..hough import Grid
from ..preprocess import rotation_to_z
from .base import (Frame, Family, Placement, Primitive, axis_from_normal_lines, frame_turn_rows, axial,
                   register, regular_indices, tangent_basis, unit)
from ._sampling import ORIGIN, TAU, Array, Sampler, span
from . import _lm

#: Relative spread (max − min) / max of the semi-axes below which the shape is a sphere.
SPHERE_TOL = 0.05


# --- geometry ----------------------------------------------------------------

def ellipsoid_foot(Y: np.ndarray, e: np.ndarray, iters: int = 14) -> tuple[np.ndarray, np.ndarray]:
    """Nearest points on the axis-aligned ellipsoid Σ (x_k/e_k)² = 1.

    Parameters
    ----------
    Y : (n, 3) points in the ellipsoid's own frame
    e : (3,) semi-axes (> 0)

    Returns
    -------
    foot : (n, 3) nearest surface points, dist : (n,) Euclidean distances

    The foot is ``e_k² y_k / (t + e_k²)`` where t solves
    Σ (e_k y_k / (t + e_k²))² = 1 on (−e_min², ∞) (Eberly). Vectorised
    bisection then monotone Newton steps, hand-written because it runs on all
    points at once with no per-point solver calls; the bracket always holds
    the root.
    """
    e = np.asarray(e, float)
    A = np.abs(Y)
    e2 = e * e
    k = int(np.argmin(e))
    r = np.linalg.norm(A, axis=1)
    lo = -e2[k] + e[k] * A[:, k]
    hi = np.maximum(e.max() * r, lo + 1e-12)
    for _ in range(iters):
        t = 0.5 * (lo + hi)
        F = np.sum((e * A / (t[:, None] + e2)) ** 2, axis=1) - 1.0
        pos = F > 0
        lo = np.where(pos, t, lo)
        hi = np.where(pos, hi, t)
    # F is convex and decreasing there: Newton from the left end (F ≥ 0)
    # climbs monotonically to the root.
    t = lo
    for _ in range(8):
        q = e * A / (t[:, None] + e2)
        F = np.sum(q * q, axis=1) - 1.0
        dF = -2.0 * np.sum(q * q / (t[:, None] + e2), axis=1)
        t = np.where(dF < 0, np.minimum(t - F / np.where(dF < 0, dF, -1.0), hi), t)
    foot = e2 * A / np.maximum(t[:, None] + e2, 1e-300)
    # Points on the smallest axis' principal plane inside: the root sits at the
    # bracket's end; complete the foot on the ellipsoid there.
    s = np.sum((foot / e) ** 2, axis=1)
    bad = np.abs(s - 1.0) > 1e-6
    if bad.any():
        f = foot[bad]
        rest = 1.0 - np.sum(np.delete(f / e, k, axis=1) ** 2, axis=1)
        f[:, k] = e[k] * np.sqrt(np.clip(rest, 0.0, None))
        foot[bad] = f
    foot = np.sign(Y) * foot + (Y == 0) * 0.0
    return foot, np.linalg.norm(Y - foot, axis=1)


def quadric_fit(P: np.ndarray, N: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Least-squares ellipsoid from points (n, 3) and unit normals (n, 3).

    Rows: Q(x) = xᵀAx + 2bᵀx + c = 0 per point, and (Ax + b) × n = 0 (the
    gradient parallel to the normal; linear in the coefficients). The
    coefficient vector is the smallest right singular vector.

    Returns (centre (3,), axes (3, 3) rows, semi-axes (3,) ascending) or None
    when the quadric is not an ellipsoid.
    """
    m = P.mean(axis=0)
    s = float(np.abs(P - m).max()) or 1.0
    X = (P - m) / s
    x, y, z = X.T
    o, one = np.zeros(len(X)), np.ones(len(X))
    # Coefficients: A11 A22 A33 A12 A13 A23 b1 b2 b3 c.
    rows = [np.stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z, one], 1)]
    # g = A x + b as linear maps of the coefficients: g_i = G[i] @ coef.
    G = np.stack([np.stack([x, o, o, y, z, o, one, o, o, o], 1),
                  np.stack([o, y, o, x, o, z, o, one, o, o], 1),
                  np.stack([o, o, z, o, x, y, o, o, one, o], 1)])  # (3, n, 10)
    n1, n2, n3 = N.T
    rows += [G[1] * n3[:, None] - G[2] * n2[:, None], G[2] * n1[:, None] - G[0] * n3[:, None],
             G[0] * n2[:, None] - G[1] * n1[:, None]]
    M = np.vstack(rows)
    try:
        coef = np.linalg.svd(M, full_matrices=False)[2][-1]
    except np.linalg.LinAlgError:
        return None
    a11, a22, a33, a12, a13, a23, b1, b2, b3, c = coef
    A = np.array([[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]])
    b = np.array([b1, b2, b3])
    w, V = np.linalg.eigh(A)
    if w[0] * w[-1] <= 0:
        return None
    if w[0] < 0:
        A, b, c, w = -A, -b, -c, -w[::-1]
        V = V[:, ::-1]
    try:
        ctr = -np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return None
    k = float(b @ np.linalg.solve(A, b) - c)
    if k <= 0:
        return None
    semi = np.sqrt(k / w) * s
    order = np.argsort(semi)
    return ctr * s + m, V.T[order], semi[order]


def _proper(R: np.ndarray) -> np.ndarray:
    R = np.array(R, float)
    if np.linalg.det(R) < 0:
        R[2] = -R[2]
    return R


def distinguished_axis(semi: np.ndarray) -> int:
    """Index of the semi-axis farthest from the other two (the axis of an
    ellipsoid of revolution)."""
    semi = np.asarray(semi, float)
    gaps = np.array([min(abs(semi[i] - semi[j]) for j in range(3) if j != i) for i in range(3)])
    return int(np.argmax(gaps))


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def _ellipsoid_grid(semi_axes: Any, polar_range: tuple[float, float], arc: tuple[float, float],
                    nu: int = 400, nt: int = 400) -> tuple[Array, Array]:
    """Midpoint grid of the unit-sphere patch (cos polar uniform, azimuth uniform) and the
    ellipsoid's area density per unit solid angle at each node, e0 e1 e2 · |s / e|."""
    e = np.asarray(semi_axes, float)
    c0, c1 = np.cos(polar_range[1]), np.cos(polar_range[0])
    uu = c0 + (c1 - c0) * (np.arange(nu) + 0.5) / nu
    tt = arc[0] + (arc[1] - arc[0]) * (np.arange(nt) + 0.5) / nt
    U, Tt = np.meshgrid(uu, tt, indexing="ij")
    rho = np.sqrt(np.clip(1 - U * U, 0, None))
    S = np.stack([rho * np.cos(Tt), rho * np.sin(Tt), U], -1).reshape(-1, 3)
    return S, float(np.prod(e)) * np.linalg.norm(S / e, axis=1)


def sample_ellipsoid(
    rng: np.random.Generator,
    n: int,
    semi_axes: Any = (1.0, 1.0, 0.5),
    polar_range: tuple[float, float] = (0.0, np.pi),
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Area-uniform points on the ellipsoid Σ (x_k / e_k)² = 1 centred at the origin, axes x, y, z.

    ``polar_range`` (rad) bounds the angle from +z of the unit-sphere point s that maps to
    x = e ∘ s, ``arc`` its azimuth. The map's area factor e0 e1 e2 |s / e| is honoured by importance
    resampling without replacement from a pool of 10 n uniform sphere points (the factor varies by
    at most max(e) / min(e), so the pool is far larger than needed; weighted sampling without
    replacement by the keys U^(1/w), Efraimidis–Spirakis). Returns points (n, 3) and outward unit
    normals (n, 3).
    """
    e = np.asarray(semi_axes, float)
    p0, p1 = span(polar_range)
    a0, a1 = span(arc)
    m = 10 * int(n)
    u = np.cos(p1) + (np.cos(p0) - np.cos(p1)) * rng.random(m)
    th = a0 + (a1 - a0) * rng.random(m)
    rho = np.sqrt(np.clip(1.0 - u * u, 0.0, None))
    S = np.column_stack([rho * np.cos(th), rho * np.sin(th), u])
    w = np.linalg.norm(S / e, axis=1)
    keys = np.log(rng.random(m)) / w
    pick = np.argpartition(-keys, int(n) - 1)[: int(n)] if n < m else np.arange(m)
    S = S[pick]
    nrm = S / e
    return S * e, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _ellipsoid_area(semi_axes: Any = (1.0, 1.0, 0.5), polar_range: tuple[float, float] = (0.0, np.pi),
                    arc: tuple[float, float] = (0.0, TAU)) -> float:
    """Area by the midpoint rule on a 400 × 400 grid of the sphere patch (deterministic)."""
    _, dens = _ellipsoid_grid(semi_axes, polar_range, arc)
    solid = (np.cos(polar_range[0]) - np.cos(polar_range[1])) * (arc[1] - arc[0])
    return float(dens.mean() * solid)


def _ellipsoid_local(semi_axes: Any = (1.0, 1.0, 0.5), **_: Any) -> dict[str, Any]:
    e = np.asarray(semi_axes, float)
    order = np.argsort(e, kind="stable")
    return {"center": list(ORIGIN), "axis": np.eye(3)[distinguished_axis(e)].tolist(),
            "semi_axes": e[order].tolist(), "axes": np.eye(3)[order].tolist()}


def _ellipsoid_random(rng: np.random.Generator) -> dict[str, Any]:
    """Of revolution (p, p, q) or with three axes; min/max semi-axis ≤ 0.8; whole or a cap."""
    if rng.random() < 0.5:
        p = float(rng.uniform(0.5, 1.0))
        ratio = float(rng.uniform(0.45, 0.8)) if rng.random() < 0.5 else 1.0 / float(rng.uniform(0.5, 0.8))
        e = [p, p, p * ratio]
    else:
        e0 = float(rng.uniform(0.5, 0.8))
        e1 = e0 * float(rng.uniform(1.2, 1.5))
        e = [e0, e1, e1 * float(rng.uniform(1.2, 1.5))]
        e = [e[k] for k in rng.permutation(3)]
    cap = (0.0, np.pi) if rng.random() < 0.6 else (0.0, float(rng.uniform(0.6 * np.pi, 0.85 * np.pi)))
    return {"semi_axes": tuple(e), "polar_range": cap}


@register
class Ellipsoid(Family):
    name = "ellipsoid"
    param_names = ("center", "axis", "semi_axes", "axes")
    n_unknowns = 3
    role = "complex"
    precedence = 5
    search = "whole"
    order = 110
    color = (255, 140, 0)  # orange
    type_code = 6
    sampler = Sampler(sample_ellipsoid, _ellipsoid_area, _ellipsoid_local, _ellipsoid_random,
                      {"center": "point", "axis": "direction", "semi_axes": "lengths", "axes": "directions"})

    # --- standard form ------------------------------------------------------
    def placements(self, P, N, ctx):
        out = []
        fit = quadric_fit(P, N)
        if not ctx.local and not _mostly_on(fit, P, 3.0 * ctx.tau):
            # Whole cloud: vote only where one ellipsoid explains most of it;
            # elsewhere its faces are left to the per-cluster rounds (the fits
            # cost tens of milliseconds per candidate).
            return []
        # Of revolution: axis from the normal lines, centre from the conic
        # A ρ² + C h² + E h + F = 0 in the meridian plane.
        q, a, _, _ = axis_from_normal_lines(P, N)
        h, rho = axial(P, q, a)
        M = np.stack([rho * rho, h * h, h, np.ones_like(h)], axis=1)
        A_, C_, E_, _ = np.linalg.svd(M, full_matrices=False)[2][-1]
        if abs(C_) > 1e-12 and A_ * C_ > 0:
            out.append(Placement(rotation_to_z(a), q - E_ / (2 * C_) * a, {"kind": "revolution"}))
        if fit is not None:
            c, V, semi = fit
            out.append(Placement(_proper(V), c, {"kind": "triaxial", "semi": semi}))
        return out

    def region(self, Pl, Nl, ctx):
        # Every semi-axis is at least the points' reach along its axis (minus
        # noise); caps may belong to larger ellipsoids, hence the upper bound.
        m = np.abs(Pl).max(axis=0)
        lo = np.maximum(0.85 * m - ctx.tau, 1e-3)
        hi = np.minimum(np.maximum(1.8 * m.max(), lo + 4 * ctx.cell), 2.0 * ctx.max_radius)
        nb = np.clip((hi - lo) / max(ctx.cell, 1e-6), 12, 40).astype(int)
        return Grid(tuple(lo), tuple(hi), tuple(int(b) for b in nb))

    def gamma(self, Pl, Nl, grid, ctx):
        # Sweep e0, e1 over their bins; solve e2² = z² / (1 − x²/e0² − y²/e1²).
        # Keep the samples whose ellipsoid normal matches the point's normal.
        rng = np.random.default_rng(ctx.seed)
        idx = np.arange(len(Pl)) if len(Pl) <= 1500 else np.sort(rng.choice(len(Pl), 1500, replace=False))
        X, Nn = Pl[idx], Nl[idx]
        e0, e1 = np.meshgrid(grid.centers(0), grid.centers(1), indexing="ij")
        e0, e1 = e0.ravel(), e1.ravel()
        den = 1.0 - (X[:, 0, None] / e0) ** 2 - (X[:, 1, None] / e1) ** 2  # (n, k)
        ok = den > 1e-6
        e2sq = np.where(ok, X[:, 2, None] ** 2 / np.where(ok, den, 1.0), 0.0)
        g = np.stack([X[:, 0, None] / e0 ** 2, X[:, 1, None] / e1 ** 2,
                      np.where(ok, X[:, 2, None] / np.maximum(e2sq, 1e-12), 0.0)], axis=-1)
        cos = np.abs(np.einsum("nkj,nj->nk", g, Nn)) / np.maximum(np.linalg.norm(g, axis=-1), 1e-300)
        ok &= cos >= ctx.cos_angle
        n_i, k_i = np.nonzero(ok)
        vals = np.stack([e0[k_i], e1[k_i], np.sqrt(e2sq[n_i, k_i])], axis=1)
        return idx[n_i], vals

    def primitive(self, values, placement):
        R = placement.R
        semi = np.asarray(values, float).copy()
        if placement.info.get("kind") == "revolution":
            semi[:2] = 0.5 * (semi[0] + semi[1])
        order = np.argsort(semi, kind="stable")
        return Primitive("ellipsoid", {"center": placement.origin.copy(), "axes": R[order].copy(),
                                       "semi_axes": semi[order].copy(),
                                       "kind": placement.info.get("kind", "revolution")})

    # --- geometry -----------------------------------------------------------
    def _local(self, prim, P):
        return (P - prim.params["center"]) @ prim.params["axes"].T

    def distance(self, prim, P):
        return ellipsoid_foot(self._local(prim, P), prim.params["semi_axes"])[1]

    def surface_normals(self, prim, P):
        e = prim.params["semi_axes"]
        foot, _ = ellipsoid_foot(self._local(prim, P), e)
        return unit((foot / (e * e)) @ prim.params["axes"])

    def well_determined(self, prim, P, ctx):
        # Global round: cones and tori are not voted there; leave them the
        # surfaces they explain as well (the per-cluster rounds compare all).
        return not covered_by_simple(self, prim, P, ctx)

    def valid(self, prim, ctx):
        e = np.asarray(prim.params["semi_axes"], float)
        # Thinner than the inlier band, it envelops a noisy layer (a disc).
        if not (np.all(np.isfinite(e)) and e.min() >= 0.5 * ctx.tau and e.min() > 0 and e.max() < 2.0 * ctx.max_radius):
            return False
        # A pancake (min/max < 0.05) is a disc: the plane covers it.
        return SPHERE_TOL < (e.max() - e.min()) / e.max() and e.min() > 0.05 * e.max()

    def fit(self, prim, P, N):
        # Each residual is an iterative foot-point solve: a regular subsample
        # keeps a fit to milliseconds.
        P = P[regular_indices(len(P), 300)]
        c0 = np.asarray(prim.params["center"], float)
        V0 = np.asarray(prim.params["axes"], float)
        e0 = np.asarray(prim.params["semi_axes"], float)
        revolution = prim.params.get("kind") == "revolution"
        if revolution:
            k = distinguished_axis(e0)
            a0 = V0[k]
            t1, t2 = tangent_basis(a0)
            p0, q0 = 0.5 * (np.delete(e0, k).sum()), e0[k]

            def unpack(x):
                a = unit(a0 + x[3] * t1 + x[4] * t2)
                R = rotation_to_z(a)
                return c0 + x[:3], R, np.array([abs(x[5]), abs(x[5]), abs(x[6])])

            x0 = np.r_[0, 0, 0, 0, 0, p0, q0]
            turn = (3, 4)
        else:
            def unpack(x):
                R = Rotation.from_rotvec(x[3:6]).as_matrix() @ V0.T
                return c0 + x[:3], R.T, np.abs(x[6:9])

            x0 = np.r_[0, 0, 0, 0, 0, 0, e0]
            turn = (3, 4, 5)

        state: dict = {}

        def res(x):
            c, V, e = unpack(x)
            e = np.maximum(e, 1e-9)
            Y = (P - c) @ V.T
            foot, d = ellipsoid_foot(Y, e)
            inside = np.sum((Y / e) ** 2, axis=1) < 1
            state.update(x=x.copy(), c=c, V=V, e=e, foot=foot)
            return np.where(inside, -d, d)

        def jac(x):
            # The signed distance's gradient is the unit normal at the foot
            # (in Y) and −(f_k²/e_k³)/|f/e²| in e_k; only the frame's turn is
            # differenced (on 3-vectors). A numerical Jacobian costs a foot
            # solve per parameter.
            if "x" not in state or not np.array_equal(state["x"], x):
                res(x)
            c, V, e, foot = state["c"], state["V"], state["e"], state["foot"]
            grad = foot / e**2
            gn = np.maximum(np.linalg.norm(grad, axis=1), 1e-300)
            n = grad / gn[:, None]
            dY = frame_turn_rows(lambda z: tuple(unpack(z)[1]), x, P - c, turn)  # (3, k, m)
            J = np.einsum("mi,ikm->mk", n, dY)
            J[:, :3] = -(n @ V)
            de = -(foot**2 / e**3) / gn[:, None]
            if revolution:
                J[:, 5] = (de[:, 0] + de[:, 1]) * np.sign(x[5])
                J[:, 6] = de[:, 2] * np.sign(x[6])
            else:
                J[:, 6:9] = de * np.sign(x[6:9])
            return np.where(np.isfinite(J), J, 0.0)

        try:
            sol = _lm.solve(_lm.rows_of(res, jac), x0, max_nfev=8)
        except Exception:
            return None
        c, V, e = unpack(sol.x)
        order = np.argsort(e, kind="stable")
        return Primitive("ellipsoid", {"center": c, "axes": V[order], "semi_axes": e[order],
                                       "kind": prim.params.get("kind", "triaxial")})

    # --- output -------------------------------------------------------------
    def axis(self, prim) -> np.ndarray:
        return np.asarray(prim.params["axes"][distinguished_axis(prim.params["semi_axes"])], float)

    def to_world(self, prim, T):
        axes = unit(T.inv_dirs(np.asarray(prim.params["axes"], float)))
        return {"center": T.inv_points(prim.params["center"]).tolist(),
                "axis": unit(T.inv_dirs(self.axis(prim))).tolist(),
                "semi_axes": [T.inv_length(float(v)) for v in prim.params["semi_axes"]],
                "axes": axes.tolist()}

    length_descriptors = ("semi_axis_0", "semi_axis_1", "semi_axis_2")

    def descriptors(self, prim):
        e = np.sort(np.asarray(prim.params["semi_axes"], float))
        return {f"semi_axis_{k}": float(e[k]) for k in range(3)}

    def frame(self, prim):
        return Frame("point", np.asarray(prim.params["center"], float), unit(self.axis(prim)))


# --- the simpler families' shadow fits (global round) ------------------------------

def simple_fit_errors(P: np.ndarray, N: np.ndarray) -> dict[str, float]:
    """Mean distance of points P (n, 3) (unit normals N) to the sphere, cone and
    torus fitted to them from their standard-form estimates (no vote): what
    the simpler rotational families would explain, had they been voted.

    Used by the complex families in the global round, where cones and tori
    are not voted, so that a complex family does not take their surfaces.
    """
    from .base import REGISTRY, lines_intersection
    from .cone import cone_frame
    from .torus import torus_frame

    out: dict[str, float] = {}
    c, cond = lines_intersection(P, N)
    if cond > 1e-6:
        prims = [("sphere", Primitive("sphere", {"center": c, "radius": float(np.linalg.norm(P - c, axis=1).mean())}))]
    else:
        prims = []
    fr = cone_frame(P, N)
    if fr is not None:
        apex, a = fr
        h, rho = axial(P, apex, a)
        prims.append(("cone", Primitive("cone", {"apex": apex, "axis": a,
                                                 "half_angle": float(np.arctan2(rho.mean(), max(h.mean(), 1e-9)))})))
    ct, at, R0 = torus_frame(P, N)
    h, rho = axial(P, ct, at)
    prims.append(("torus", Primitive("torus", {"center": ct, "axis": at, "major_radius": float(abs(R0)),
                                               "minor_radius": float(np.hypot(rho - abs(R0), h).mean())})))
    for name, pr in prims:
        fam = REGISTRY[name]
        try:
            fit = fam.fit(pr, P, N)
        except Exception:
            fit = None
        if fit is not None:
            d = fam.distance(fit, P)
            if np.all(np.isfinite(d)):
                out[name] = float(d.mean())
    return out


def covered_by_simple(fam: Family, prim: Primitive, P: np.ndarray, ctx) -> bool:
    """Whether a sphere, cone or torus fits the segment P about as well as the
    complex primitive ``prim`` (mean distance within 5 % + 0.05 tau: on the
    complex family's own surfaces the simple ones stay ≥ 1.3 σ off)."""
    if ctx.pre is None or len(P) < 10:
        return False
    _, j = ctx.pre.tree.query(P)
    N = ctx.pre.normals[j]
    rng = np.random.default_rng(ctx.seed)
    sel = np.arange(len(P)) if len(P) <= 400 else rng.choice(len(P), 400, replace=False)
    P, N = P[sel], N[sel]
    d_cplx = float(fam.distance(prim, P).mean())
    errs = simple_fit_errors(P, N)
    return any(e <= 1.05 * d_cplx + 0.05 * ctx.tau for e in errs.values())


def _mostly_on(fit, P: np.ndarray, delta: float, share: float = 0.5) -> bool:
    """Whether at least ``share`` of the points P (n, 3) lie within ``delta``
    (Sampson distance) of the fitted ellipsoid ``fit`` = (centre, axes, semi-axes)."""
    if fit is None:
        return False
    c, V, semi = fit
    e = np.maximum(np.asarray(semi, float), 1e-9)
    Y = (P - c) @ np.asarray(V, float).T
    F = np.sum((Y / e) ** 2, axis=1) - 1.0
    g = 2.0 * np.linalg.norm(Y / e**2, axis=1)
    return bool(np.mean(np.abs(F) < delta * np.maximum(g, 1e-12)) >= share)
