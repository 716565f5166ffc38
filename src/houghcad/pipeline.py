"""The whole pipeline: preprocessing, recognition, splitting, output (paper §5)."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any, Callable

import numpy as np

from . import families as fam_mod
from .errors import InputError
from .preprocess import preprocess
from .recognize import Candidate, Context, mean_fitting_error, recognize
from .result import Result, Segment
from .split import absorb, accept, settle_edges, splitting_phase


class Segmenter:
    """Decompose a point cloud into primitives (scikit-learn style).

    Parameters
    ----------
    families : str or list of str
        ``"simple"`` (plane, cylinder, cone, sphere, torus), ``"all"``, or names.
    epsilon : float, optional
        Removal threshold ε as a fraction of the bounding-box diagonal
        (the paper uses 0.01–0.03). Default: adapted to the point spacing and
        the estimated noise.
    normals_method : {"auto", "pca", "voting", "input"}
        Normal estimation (see :func:`houghcad.preprocess.preprocess`).
    persistence : float
        Peak persistence threshold, a fraction of the accumulator's maximum.
    min_points : int, optional
        Smallest segment; default max(8, n / 5000).
    seed : int
        Seed of every random choice.
    progress : callable, optional
        Called as ``progress(stage: str, fraction: float)``.

    Attributes
    ----------
    result_ : Result
        Set by :meth:`fit`.
    """

    def __init__(self, families="simple", epsilon: float | None = None, normals_method: str = "auto",
                 persistence: float = 0.1, min_points: int | None = None, seed: int = 0,
                 progress: Callable[[str, float], None] | None = None):
        self.families = families
        self.epsilon = epsilon
        self.normals_method = normals_method
        self.persistence = persistence
        self.min_points = min_points
        self.seed = seed
        self.progress = progress

    def get_options(self) -> dict[str, Any]:
        return {"families": self.families if isinstance(self.families, str) else list(self.families),
                "epsilon": self.epsilon, "normals_method": self.normals_method,
                "persistence": self.persistence, "min_points": self.min_points, "seed": self.seed}

    def fit(self, points: np.ndarray, normals: np.ndarray | None = None, source: str | None = None) -> "Segmenter":
        """Segment ``points`` (n, 3), world units; ``normals`` (n, 3) optional."""
        from .io import validate_points

        points = validate_points(np.asarray(points), source)
        if normals is not None:
            normals = np.asarray(normals, dtype=np.float64)
            if normals.shape != points.shape or not np.isfinite(normals).all():
                normals = None
        if self.epsilon is not None and not (0 < float(self.epsilon) < 0.5):
            raise InputError(f"epsilon must be a fraction of the diagonal in (0, 0.5), got {self.epsilon}")
        if not (0 < float(self.persistence) < 1):
            raise InputError(f"persistence must be in (0, 1), got {self.persistence}")
        fams = fam_mod.select(self.families)
        timing: dict[str, float] = {}
        report = self.progress or (lambda stage, frac: None)

        t0 = time.perf_counter()
        report("preprocess", 0.0)
        pre = preprocess(points, normals, method=self.normals_method, seed=self.seed)
        timing["preprocess"] = time.perf_counter() - t0

        ctx = self._context(pre, len(points))
        free = np.ones(len(points), dtype=bool)
        segments: list[Candidate] = []

        t1 = time.perf_counter()
        report("recognition", 0.1)
        # The first round keeps only substantial segments: smaller ones, and the
        # families voted per cluster, are settled in the splitting phase where
        # every family competes for the same points.
        gctx = replace(ctx, min_points=max(ctx.min_points, len(points) // 100))
        found = recognize(np.arange(len(points)), fams, gctx, free)
        accept(found, free, ctx, segments)
        absorb(segments, free, ctx)
        timing["recognition"] = time.perf_counter() - t1

        t2 = time.perf_counter()
        n0 = max(int(free.sum()), 1)
        done = [0]

        def step(n):
            done[0] += n
            report("splitting", 0.3 + 0.6 * min(done[0] / n0, 1.0))

        splitting_phase(fams, ctx, free, segments, progress=step)
        absorb(segments, free, ctx)
        # On CAD samples the faces' boundary curves lie on both faces.
        settle_edges(segments, ctx, max(0.3 * pre.spacing, ctx.tau), ctx.link)
        timing["splitting"] = time.perf_counter() - t2

        t3 = time.perf_counter()
        report("output", 0.95)
        out = self._output(segments, pre, points)
        timing["output"] = time.perf_counter() - t3
        timing["total"] = time.perf_counter() - t0
        assigned = np.zeros(len(points), bool)
        for s in out:
            assigned[s.indices] = True
        self.result_ = Result(n_points=len(points), segments=out, unsegmented=np.flatnonzero(~assigned),
                              timing=timing, options={**self.get_options(), "normals_used": pre.normals_method},
                              source=source)
        report("done", 1.0)
        return self

    def _context(self, pre, n: int) -> Context:
        s = pre.spacing
        # Inliers within three noise sigmas: on exact CAD samples this is tight,
        # so tangent-continuous neighbours (a fillet beside a plane) stay apart.
        tau = max(0.1 * s, 3.0 * pre.noise)
        eps = 2.0 * tau if self.epsilon is None else float(self.epsilon) * pre.diagonal
        tau = min(tau, eps)
        angle = np.radians(min(45.0, 20.0 + 30.0 * pre.noise / max(s, 1e-12)))
        mp = self.min_points if self.min_points is not None else max(8, n // 5000)
        return Context(pre=pre, tau=tau, epsilon=eps, angle=float(angle),
                       link=max(2.0 * s, 1.5 * pre.reach) + 2.0 * pre.noise, cell=max(tau, 0.5 * s),
                       min_points=int(mp), max_radius=1.0, persistence=float(self.persistence),
                       min_votes=float(mp), seed=int(self.seed))

    def _output(self, segments: list[Candidate], pre, points: np.ndarray) -> list[Segment]:
        """Refit every segment on its own points and map it to world coordinates."""
        rng = np.random.default_rng(self.seed)
        T = pre.transform
        out: list[Segment] = []
        segments = sorted(segments, key=lambda c: (-len(c.indices), int(c.indices[0])))
        # Final refits may reach any radius below 1e9 (standard units).
        check = Context(pre=pre, tau=0, epsilon=0, angle=0, link=0, cell=0, min_points=0, max_radius=1e9)
        for c in segments:
            P, N = pre.points[c.indices], pre.normals[c.indices]
            sel = np.arange(len(P)) if len(P) <= 4000 else np.sort(rng.choice(len(P), 4000, replace=False))
            prim = c.family.fit(c.prim, P[sel], N[sel])
            if prim is None or not c.family.valid(prim, check):
                prim = c.prim
            d = c.family.distance(prim, P) / T.scale
            mfe = mean_fitting_error(d, points[c.indices])
            out.append(Segment(id=len(out), type=c.family.name, indices=np.sort(c.indices).astype(np.int64),
                               params=c.family.to_world(prim, T), mfe=mfe))
        return out


def segment(points: np.ndarray, normals: np.ndarray | None = None, *, families="simple",
            epsilon: float | None = None, seed: int = 0, normals_method: str = "auto",
            progress: Callable[[str, float], None] | None = None, source: str | None = None,
            **options) -> Result:
    """Decompose a point cloud into primitives.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        World coordinates.
    normals : ndarray, shape (n, 3), optional
    families, epsilon, seed, normals_method, progress
        See :class:`Segmenter`.
    source : str, optional
        Name of the input, used in messages and in the result.

    Returns
    -------
    Result
    """
    seg = Segmenter(families=families, epsilon=epsilon, seed=seed, normals_method=normals_method,
                    progress=progress, **options)
    return seg.fit(points, normals, source=source).result_
