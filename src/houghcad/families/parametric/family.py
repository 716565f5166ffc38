"""The family class of user-defined parametric surfaces (built by
:func:`~houghcad.families.parametric.define_family`): (u, v) domain,
placement, region, geometry (feet, distance, normals), fit and output. The
vote is :class:`.vote.GammaSampling`."""

from __future__ import annotations

from collections import OrderedDict
from typing import Any, Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ...hough import Grid
from ..base import Family, Frame, Primitive, gauss_newton, unit
from .equations import Equations
from .guard import describe, user_code, user_error
from .placement import place
from .vote import GammaSampling, periodic

#: A free length coordinate spans [-2, 2] standard units in the distance
#: samples: the unit cube seen from any point in it.
LENGTH_SPAN = 2.0


class ParametricFamily(GammaSampling, Family):
    """A family given by x(u, v; a), y(u, v; a), z(u, v; a); see :mod:`houghcad.families.parametric`.

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

    def __init__(self, name: str, eq: Equations, names: Sequence[str], dims: Sequence[float],
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
            if periodic((lo, hi)):
                w = lo + np.mod(w - lo, hi - lo)
            else:
                tol = 1e-9 * (hi - lo)
                ok &= (w >= lo - tol) & (w <= hi + tol)
            out.append(w)
        return out[0], out[1], ok

    # --- standard form and voting ------------------------------------------------
    def placements(self, P, N, ctx):
        return place(self.placement, P, N, family=self.name)

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

    # gamma(): see GammaSampling

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
            g.append(np.linspace(lo, hi, n, endpoint=not periodic((lo, hi))))
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
                w[:] = lo + np.mod(w - lo, hi - lo) if periodic((lo, hi)) else np.clip(w, lo, hi)
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
        if self.user_valid is None:
            return True
        with user_code(self.name, "valid(...)"):
            ok = self.user_valid(dict(zip(self.names, a.tolist())))
        # None (a forgotten return) would reject every shape; an array fails in bool() or
        # (one element) hides a mistake.
        if ok is None or isinstance(ok, (list, tuple)) or (isinstance(ok, np.ndarray) and ok.ndim > 0):
            raise user_error(self.name, "valid(...)", f"returned {describe(ok)}, not True or False")
        with user_code(self.name, "valid(...)"):
            return bool(ok)

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
