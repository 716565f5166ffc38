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
of a placement rides along on them (:class:`._meridian.Tagged`).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..hough import Grid
from ..preprocess import rotation_to_z
from ._helix import GLOBAL_COMPLEX_RESIDUAL, relative_complex_residual
from .base import (Frame, Family, Primitive, axis_from_normal_lines, axial, radial, register,
                   regular_indices, tangent_basis, unit)
from ._meridian import (ACTIVE, PROFILES, Profile, ProfilePlacement, meridian_conic_offset, meridian_local,
                        register_profile, set_active_profiles, solve_batched, theta_dict)
from ._sampling import ORIGIN, TAU, Z_AXIS, Array, Sampler, partial, span
from .ellipsoid import covered_by_simple
from . import _lm

__all__ = ["ACTIVE", "PROFILES", "Profile", "SurfaceOfRevolution", "meridian_conic_offset", "register_profile",
           "sample_revolution", "set_active_profiles"]


# --- synthetic sampler (houghcad.synth) ----------------------------------------

def _revolution_table(profile: str, params: Any, u_range: tuple[float, float], m: int = 4097):
    """u samples (m,), curve (2, m) and cumulative area-per-turn CDF (m,) (trapezoid on ρ ds)."""
    prof = PROFILES[profile]
    u = np.linspace(u_range[0], u_range[1], m)
    c = prof.curve(u, np.asarray(params, float))
    ds = np.linalg.norm(np.diff(c, axis=1), axis=0)
    dA = 0.5 * (np.abs(c[0, 1:]) + np.abs(c[0, :-1])) * ds
    return u, c, np.concatenate([[0.0], np.cumsum(dA)])


def sample_revolution(
    rng: np.random.Generator,
    n: int,
    profile: str = "paper",
    params: Any = (1.0,),
    u_range: tuple[float, float] = (1.0, 1.5),
    arc: tuple[float, float] = (0.0, TAU),
) -> tuple[Array, Array]:
    """Area-uniform points on the surface of revolution of a profile of
    :data:`houghcad.families.revolution.PROFILES` about z: ``(f1 cos v, f1 sin v, f2)``.

    u is drawn by inverse CDF of the area element ρ ds (a dense table, then Newton-free linear
    interpolation on 4097 samples), v uniformly in ``arc``. Normals are the profile's normals
    turned about the axis (sign: (f2', −f1') in the meridian plane).
    """
    prof = PROFILES[profile]
    u_tab, _, cdf = _revolution_table(profile, params, u_range)
    a0, a1 = span(arc)
    u = np.interp(rng.random(n) * cdf[-1], cdf, u_tab)
    v = a0 + (a1 - a0) * rng.random(n)
    th = np.asarray(params, float)
    c, d1, _ = prof.derivs(u, th)
    nm = np.stack([d1[1], -d1[0]])
    nm = nm / np.linalg.norm(nm, axis=0)
    cv, sv = np.cos(v), np.sin(v)
    pts = np.column_stack([c[0] * cv, c[0] * sv, c[1]])
    nrm = np.column_stack([nm[0] * cv, nm[0] * sv, nm[1]])
    return pts, nrm


def _revolution_area(profile: str = "paper", params: Any = (1.0,), u_range: tuple[float, float] = (1.0, 1.5),
                     arc: tuple[float, float] = (0.0, TAU)) -> float:
    return float(_revolution_table(profile, params, u_range)[2][-1] * (arc[1] - arc[0]))


def _revolution_local(profile: str = "paper", params: Any = (1.0,), **_: Any) -> dict[str, Any]:
    prof = PROFILES[profile]
    out: dict[str, Any] = {"axis_point": list(ORIGIN), "axis": list(Z_AXIS), "profile": profile}
    out.update({k: float(v) for k, v in zip(prof.params, params)})
    return out


def _revolution_random(rng: np.random.Generator) -> dict[str, Any]:
    """The paper's profile (a u, a / u⁵), u in [0.78–0.85, 1.7–1.9], or an elliptic torus (ellipse
    centred at ρ = R, semi-axes p, q with q / p in [0.5, 0.7] or [1.4, 2]); full turn or part of
    one. Narrower ranges are tori within the noise (u in [0.95, 1.45]: a torus fits to 0.4 σ at
    noise 0.005), so they are not a test of this family."""
    if rng.random() < 0.5:
        a = float(rng.uniform(0.6, 1.0))
        return {"profile": "paper", "params": (a,),
                "u_range": (float(rng.uniform(0.78, 0.85)), float(rng.uniform(1.7, 1.9))),
                "arc": partial(rng, 0.5, 0.9 * np.pi, 1.7 * np.pi)}
    R = float(rng.uniform(0.8, 1.2))
    p = R * float(rng.uniform(0.3, 0.5))
    q = p * (float(rng.uniform(1.4, 2.0)) if rng.random() < 0.5 else float(rng.uniform(0.5, 0.7)))
    return {"profile": "ellipse", "params": (R, p, q), "u_range": partial(rng, 0.6, 1.2 * np.pi, 1.8 * np.pi),
            "arc": partial(rng, 0.5, 0.9 * np.pi, 1.7 * np.pi)}


#: How the world parameters transform under a similarity (synth): the axis, the
#: profile's name, and the parameters of the built-in profiles by their kinds.
_PARAM_KINDS = {"axis_point": "point", "axis": "direction", "profile": "label",
                **{k: kind for prof in PROFILES.values() for k, kind in zip(prof.params, prof.kinds)}}


@register
class SurfaceOfRevolution(Family):
    name = "surface_of_revolution"
    param_names = ("axis_point", "axis", "profile")
    n_unknowns = 3
    role = "complex"
    precedence = 7
    search = "whole"
    order = 120
    color = (255, 110, 180)  # pink
    type_code = 9
    sampler = Sampler(sample_revolution, _revolution_area, _revolution_local, _revolution_random,
                      _PARAM_KINDS)

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
                    _, rho = axial(P, origin, ax)
                    hh = (P - origin) @ ax
                    z0 = prof.offset(rho, hh)
                    if z0 is None or not np.isfinite(z0):
                        continue
                    origin = origin + z0 * ax
                out.append(ProfilePlacement(R, origin, info))
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
        rho, h, nr, nh = meridian_local(np.asarray(Pl)[idx], Nl[idx])
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
                x, ok = solve_batched(A, np.stack([b1, b2, bn], -1))
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
        if prof.check is not None and not prof.check(theta_dict(prof, th)):
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
            h0, r0 = axial(P, pr.params["axis_point"], pr.params["axis"])
            th = pr.params["theta"]
            c0 = prof.curve(u, th)
            J = np.empty((len(P), len(x)))
            d = 1e-6
            for j in range(len(x)):
                xe = x.copy()
                xe[j] += d
                if j < 5:
                    pe = unpack(xe)
                    h1, r1 = axial(P, pe.params["axis_point"], pe.params["axis"])
                    J[:, j] = (nrm[:, 0] * (r1 - r0) + nrm[:, 1] * (h1 - h0)) / d
                else:
                    te = th.copy()
                    te[j - 5] += d
                    dc = (prof.curve(u, te) - c0) / d
                    J[:, j] = -(nrm[:, 0] * dc[0] + nrm[:, 1] * dc[1])
            return np.where(np.isfinite(J), J, 0.0)

        x0 = np.zeros(5 + len(th0))
        try:
            sol = _lm.solve(_lm.rows_of(res, jac), x0, max_nfev=4 * len(x0))
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
