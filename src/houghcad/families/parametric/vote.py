"""The vote of a user family (Γ_P sampled by solving for the linear
parameters): the :class:`GammaSampling` part of
:class:`~houghcad.families.parametric.ParametricFamily`."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..base import unit
from .equations import solve_sym3

TWO_PI = 2.0 * np.pi


def snake(shape: Sequence[int]) -> list[tuple[int, ...]]:
    """Every index of a grid of ``shape``, consecutive ones differing by one
    step in one dimension (boustrophedon order), for continuation."""
    if not shape:
        return [()]
    inner = snake(shape[1:])
    out = []
    for i in range(shape[0]):
        out += [(i,) + c for c in (inner if i % 2 == 0 else inner[::-1])]
    return out


def periodic(span: tuple[float, float]) -> bool:
    w = span[1] - span[0]
    return w > 0 and abs(w / TWO_PI - round(w / TWO_PI)) < 1e-9


class GammaSampling:
    """Samples of Γ_P for :class:`~houghcad.families.parametric.ParametricFamily`
    (a mixin: it reads the family's equations ``eq``, its ``names``, ``solved``
    and ``swept`` parameters, ``samples``, the (u, v) domain ``_span``/``_wrap``
    and the tuning attributes ``max_voters``, ``substep``, ``max_depth``,
    ``residual_tol``)."""

    def _uv_samples(self, extent: float) -> tuple[np.ndarray, np.ndarray]:
        if self.samples is not None:
            nu, nv = self.samples
        else:
            nu = nv = 10 if len(self.solved) == 2 else 4
        spans = [self._span(0, extent), self._span(1, extent)]
        g = []
        for (lo, hi), n in zip(spans, (nu, nv)):
            g.append(lo + (hi - lo) * (np.arange(n) + 0.5) / n if periodic((lo, hi)) else np.linspace(lo, hi, n))
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
        z[:, self.solved] = solve_sym3(M, np.einsum("mij,mi->mj", Am, Q - self.eq.X(u, v, z)))
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
            nodes.append(np.linspace(lo, hi, n + 1 if periodic((lo, hi)) else n))
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
        order = snake([len(c) for c in axes])
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
            if periodic((lo, hi)):
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
            step = np.matmul(np.swapaxes(J, 1, 2), solve_sym3(M, -F)[..., None])[..., 0]
            un, vn, _ = self._wrap(u[act] + step[:, 0], v[act] + step[:, 1], extent)
            u[act], v[act] = un, vn
            a[np.ix_(act, self.solved)] += step[:, 2:]
        F = self.eq.X(u, v, a) - Q
        nf = np.linalg.norm(F, axis=1)
        _, _, inside = self._wrap(u, v, extent)
        return u, v, a, inside & (nf < tol)
