"""The whole pipeline: preprocessing, recognition, splitting, refinement, output (paper §5)."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any, Callable

import numpy as np

from . import families as fam_mod
from .associate import Associator, Item, extent
from .blend import find_fillets
from .errors import InputError
from .preprocess import preprocess
from .boundaries import dissolve_redundant, settle_edges, settle_noisy_edges
from .consolidation import consolidate, prefer_planes, revisit_poor_fits
from .context import Context
from .growth import absorb, accept
from .recognize import recognize, refine
from .result import GROUP_KINDS, Group, Part, Result, Segment
from .splitting import splitting_phase
from .state import Candidate, mean_fitting_error


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
    merge : bool
        Merge segments lying on one surface into maximal primitives (their
        connected pieces are kept as ``parts``). Groups are found either way.
    association : dict, optional
        Options of :class:`houghcad.associate.Associator` (``angle_tol``,
        ``length_tol``, ``relative_tol``, ``extent_tol``, ``contact``).

    Attributes
    ----------
    result_ : Result
        Set by :meth:`fit`.
    """

    def __init__(self, families="simple", epsilon: float | None = None, normals_method: str = "auto",
                 persistence: float = 0.1, min_points: int | None = None, seed: int = 0,
                 progress: Callable[[str, float], None] | None = None, merge: bool = True,
                 association: dict[str, Any] | None = None):
        self.families = families
        self.epsilon = epsilon
        self.normals_method = normals_method
        self.persistence = persistence
        self.min_points = min_points
        self.seed = seed
        self.progress = progress
        self.merge = merge
        self.association = association

    def get_options(self) -> dict[str, Any]:
        return {"families": self.families if isinstance(self.families, str) else list(self.families),
                "epsilon": self.epsilon, "normals_method": self.normals_method,
                "persistence": self.persistence, "min_points": self.min_points, "seed": self.seed,
                "merge": bool(self.merge), "association": dict(self.association or {})}

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
        try:
            associator = Associator(merge=bool(self.merge), **(self.association or {}))
        except TypeError as exc:
            raise InputError(f"association options: {exc}") from None
        fams = fam_mod.select(self.families)
        # A family refining a selected one is not voted: it would tie with its
        # base family, which wins ties; the base's segments are offered to it
        # after recognition instead (see ``refine`` below).
        names = {f.name for f in fams}
        voted = [f for f in fams if f.refines not in names]
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
        found = recognize(np.arange(len(points)), voted, gctx, free)
        accept(found, free, ctx, segments)
        absorb(segments, free, ctx)
        timing["recognition"] = time.perf_counter() - t1

        t2 = time.perf_counter()
        n0 = max(int(free.sum()), 1)
        done = [0]

        def step(n):
            done[0] += n
            report("splitting", 0.3 + 0.6 * min(done[0] / n0, 1.0))

        splitting_phase(voted, ctx, free, segments, progress=step)
        consolidate(voted, ctx, free, segments)
        absorb(segments, free, ctx)
        delta = max(0.3 * pre.spacing, ctx.tau)
        dissolve_redundant(segments, ctx, delta, ctx.link)
        if ctx.noisy:
            settle_noisy_edges(segments, ctx, ctx.link)
            # Settled edges give each segment its whole face: one whose
            # surface the earlier rounds misread (a generalised cylinder on a
            # band of a cone) now fits it clearly worse than the noise.
            if revisit_poor_fits(voted, ctx, free, segments):
                absorb(segments, free, ctx)
                settle_noisy_edges(segments, ctx, ctx.link)
            # Fillets shallower than the inlier distance hide in their neighbours.
            if find_fillets(segments, fams, ctx, free):
                absorb(segments, free, ctx)
                settle_noisy_edges(segments, ctx, ctx.link)
            # Curved primitives flat within the noise are planes.
            prefer_planes(segments, fams, ctx)
        else:
            # On CAD samples the faces' boundary curves lie on both faces.
            settle_edges(segments, ctx, delta, ctx.link)
        # Families that specialise a recognised one (annulus: a plane bounded
        # by two circles) take the segments that have their shape.
        refine(segments, fams, ctx)
        timing["splitting"] = time.perf_counter() - t2

        self._recognised = (segments, pre, ctx, points, source, dict(timing), t0)
        self.result_ = self._associate(associator, report)
        report("done", 1.0)
        return self

    def reassociate(self, merge: bool | None = None, association: dict[str, Any] | None = None) -> Result:
        """Run the association step again on the segments of the last :meth:`fit`
        with other options (cheap: recognition is not repeated); returns a new Result."""
        if not hasattr(self, "_recognised"):
            raise RuntimeError("call fit() first")
        merge = self.merge if merge is None else merge
        try:
            associator = Associator(merge=bool(merge), **(association if association is not None
                                                          else (self.association or {})))
        except TypeError as exc:
            raise InputError(f"association options: {exc}") from None
        return self._associate(associator, lambda stage, frac: None)

    def _associate(self, associator: Associator, report) -> Result:
        segments, pre, ctx, points, source, timing, t0 = self._recognised
        timing = dict(timing)
        t3 = time.perf_counter()
        report("association", 0.92)
        associator.fit(segments, pre, ctx.tau, ctx.link)
        timing["association"] = time.perf_counter() - t3

        t4 = time.perf_counter()
        report("output", 0.96)
        out, groups = self._output(associator.items_, associator.groups_, pre, points)
        timing["output"] = time.perf_counter() - t4
        timing["total"] = sum(v for k, v in timing.items() if k != "total")
        assigned = np.zeros(len(points), bool)
        for s in out:
            assigned[s.indices] = True
        options = {**self.get_options(), "merge": bool(associator.merge), "normals_used": pre.normals_method}
        return Result(n_points=len(points), segments=out, unsegmented=np.flatnonzero(~assigned),
                      timing=timing, options=options, source=source, groups=groups)

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

    def _output(self, items: list[Item], raw_groups, pre, points: np.ndarray) -> tuple[list[Segment], list[Group]]:
        """Refit every segment (and part) on its own points, map it to world
        coordinates, and renumber the groups' members."""
        T = pre.transform
        order = sorted(range(len(items)), key=lambda k: (-len(items[k].indices), int(items[k].indices[0])))
        new_id = {k: i for i, k in enumerate(order)}
        # Final refits may reach any radius below 1e9 (standard units).
        check = Context(pre=pre, tau=0, epsilon=0, angle=0, link=0, cell=0, min_points=0, max_radius=1e9)
        rng = np.random.default_rng(self.seed)

        def fitted(fam, prim0, idx, fixed=False):
            P, N = pre.points[idx], pre.normals[idx]
            sel = np.arange(len(P)) if len(P) <= 4000 else np.sort(rng.choice(len(P), 4000, replace=False))
            prim = None if fixed else fam.fit(prim0, P[sel], N[sel])
            if prim is None or not fam.valid(prim, check):
                prim = prim0
            mfe = mean_fitting_error(fam.distance(prim, P) / T.scale, points[idx])
            return fam.to_world(prim, T), mfe

        out: list[Segment] = []
        for k in order:
            it = items[k]
            params, mfe = fitted(it.family, it.prim, it.indices, it.fixed)
            parts = []
            if len(it.parts) > 1:
                for p in sorted(it.parts, key=lambda a: (-len(a), int(a[0]))):
                    pp, pm = fitted(it.family, it.prim, p)
                    parts.append(Part(indices=p.astype(np.int64), params=pp, mfe=pm))
            desc = _world_descriptors(it.family, it.family.descriptors(it.prim), T)
            frame = it.family.frame(it.prim)
            axis = T.inv_dirs(frame.direction) if frame is not None and frame.direction is not None else None
            desc["extent"] = extent(points[it.indices], axis).tolist()
            out.append(Segment(id=len(out), type=it.family.name, indices=it.indices.astype(np.int64),
                               params=params, mfe=mfe, parts=parts, descriptors=desc))
        groups = []
        for g in raw_groups:
            fam = items[g.members[0]].family
            groups.append(Group(kind=g.kind, members=sorted(new_id[m] for m in g.members),
                                descriptors=_world_descriptors(fam, g.descriptors, T)))
        groups.sort(key=lambda g: (GROUP_KINDS.index(g.kind), g.members))
        return out, groups





def _world_descriptors(fam, d: dict[str, Any], T) -> dict[str, Any]:
    """Descriptors from the standard frame to world units and axes."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if k in fam.length_descriptors or k == "extent":
            out[k] = (np.asarray(v, float) / T.scale).tolist() if np.ndim(v) else T.inv_length(v)
        elif k in ("axis", "normal", "mirror_normal"):
            out[k] = T.inv_dirs(np.asarray(v, float)).tolist()
        elif k in ("axis_point", "mirror_point"):
            out[k] = T.inv_points(np.asarray(v, float)).tolist()
        elif isinstance(v, (np.floating, np.integer)):
            out[k] = v.item()
        else:
            out[k] = v
    return out


def segment(points: np.ndarray, normals: np.ndarray | None = None, *, families="simple",
            epsilon: float | None = None, seed: int = 0, normals_method: str = "auto",
            progress: Callable[[str, float], None] | None = None, source: str | None = None,
            merge: bool = True, **options) -> Result:
    """Decompose a point cloud into primitives.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        World coordinates.
    normals : ndarray, shape (n, 3), optional
    families, epsilon, seed, normals_method, progress, merge
        See :class:`Segmenter` (``**options`` too: persistence, min_points, association).
    source : str, optional
        Name of the input, used in messages and in the result.

    Returns
    -------
    Result
    """
    seg = Segmenter(families=families, epsilon=epsilon, seed=seed, normals_method=normals_method,
                    progress=progress, merge=merge, **options)
    return seg.fit(points, normals, source=source).result_
