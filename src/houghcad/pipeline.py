"""The whole pipeline (paper §5): preprocessing, a declared list of passes over
one :class:`~houghcad.state.Segmentation`, and the output.

:data:`PIPELINE` reads top to bottom like the paper: the recognition step on
the whole cloud (§5.2), the splitting phase on what it leaves (§5.3), then
our extensions, each labelled as one, and last the association (§5.4), which
reads the final segments. Every pass takes the state and returns it; each is
timed under its name in ``Result.timing``, and ``Segmenter(trace=...)``
(``houghcad segment --trace DIR``) records the labels after each.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from . import families as fam_mod
from .associate import Associator
from .blend import find_fillets
from .boundaries import dissolve_redundant, edge_points, settle_edges, settle_noisy_edges
from .consolidation import consolidate, revisit_poor_fits
from .context import DEFAULT_PERSISTENCE, Context, derive_context, on_surface
from .errors import InputError
from .estimator import ParamsMixin
from .parallel import Workers, blas_one_thread, resolve_jobs
from .planes import prefer_planes
from .growth import absorb, accept
from .multires import Subsample, copy_to_twins, distinct_points, propagate, voxel_subsample
from .output import build_segments
from .noise import choose
from .options import MIN_MAX_POINTS, check_options
from .preprocess import preprocess
from .rounding import warn_coarse_coordinates
from .recognize import recognize, refine
from .result import Result
from .splitting import splitting_phase
from .passes import EXTENSION, PAPER_5_2, PAPER_5_3, PAPER_5_4, Pass, Run, Runner, TraceFn, monotonic, quiet
from .state import SegmentRecord, Segmentation, checks_enabled
from .tolerances import Tolerances


# Progress: the splitting phase reports within its own span (it takes most
# of the time), the output last.
_SPLIT_START = 0.3
_SPLIT_SPAN = 0.6
_OUTPUT_AT = 0.96
_PROPAGATE_AT = 0.93
#: Clouds above this many points are recognised on an even subsample of this size (our
#: extension, :mod:`houghcad.multires`); the Fit4CAD clouds (at most 50k points) stay whole.
DEFAULT_MAX_POINTS = 100_000
#: Coordinates beyond this (units) are refused: the fits sum squared distances, which
#: overflow float64 (about 1.8e308) long before the coordinates themselves do.
MAX_COORDINATE = 1e100


def _nearest_edges(ctx: Context) -> bool:
    return ctx.policy.nearest_edges


def _shared_edges(ctx: Context) -> bool:
    return not ctx.policy.nearest_edges


def _absorb_after_recognition(ctx: Context) -> bool:
    return ctx.policy.absorb_after_recognition


# ---------------------------------------------------------------------------- the passes

def recognition(seg: Segmentation, run: Run) -> Segmentation:
    """The families voted on the whole cloud; accepted segments take the
    points within ε of their primitive (paper §5.2).

    The first round keeps only substantial segments (1 % of the cloud):
    smaller ones, and the families voted per cluster, are settled in the
    splitting phase where every family competes for the same points."""
    ctx = run.ctx
    share = ctx.tol.scale.first_round_share
    gctx = replace(ctx, min_points=max(ctx.min_points, int(seg.n_points * share)))
    accept(recognize(np.arange(seg.n_points), run.voted, gctx, seg.free), seg, ctx)
    return seg


def absorb_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Leftover points join the segment of their nearest assigned neighbour
    when they lie on its surface."""
    absorb(seg, run.ctx)
    return seg


def splitting(seg: Segmentation, run: Run) -> Segmentation:
    """What recognition leaves, clustered and recognised again; CGAL's RANSAC
    proposes regions where nothing is (paper §5.3)."""
    n0 = max(int(seg.free.sum()), 1)
    done = [0]

    def step(n: int) -> None:
        done[0] += n
        run.progress("splitting", _SPLIT_START + _SPLIT_SPAN * min(done[0] / n0, 1.0))

    splitting_phase(seg, run.voted, run.ctx, progress=step)
    return seg


def consolidation(seg: Segmentation, run: Run) -> Segmentation:
    """Complex families retake the surfaces simpler ones carved into pieces;
    pieces of one surface are voted again together."""
    consolidate(seg, run.voted, run.ctx)
    return seg


def dissolve_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Slivers that larger neighbours explain better are dissolved into them."""
    dissolve_redundant(seg, run.ctx, on_surface(run.ctx), run.ctx.link)
    return seg


def settle_noisy_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Noisy clouds: edge points go to the adjacent face whose surface is nearest."""
    settle_noisy_edges(seg, run.ctx, run.ctx.link)
    return seg


def revisit_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Noisy clouds: settled edges give each segment its whole face; one whose
    surface the earlier rounds misread now fits it clearly worse than the
    noise, and every family votes again on it."""
    revisit_poor_fits(seg, run.voted, run.ctx)
    return seg


def fillets_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Fillets are tested between each pair of adjacent segments: on noisy
    clouds those shallower than the inlier distance hide in their neighbours;
    on exact samples those a few spacings wide are too narrow to vote."""
    find_fillets(seg, run.families, run.ctx)
    return seg


def prefer_planes_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Curved primitives that a plane fits as well are planes (flat within
    the noise, or exact strips); loosely fitted ones that planes fit exactly
    go to the planes."""
    prefer_planes(seg, run.families, run.ctx)
    return seg


def settle_edges_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Clean clouds: the faces' boundary curves lie on both faces; their
    points go to the face with the smaller core."""
    settle_edges(seg, run.ctx, on_surface(run.ctx), run.ctx.link)
    return seg


def refine_pass(seg: Segmentation, run: Run) -> Segmentation:
    """Families that specialise a recognised one (an annulus: a plane bounded
    by two circles) take the segments that have their shape."""
    refine(seg, run.families, run.ctx)
    return seg


def association(seg: Segmentation, run: Run) -> Segmentation:
    """Maximal primitives and relations between segments (paper §5.4): the
    segments of one surface become one, with their connected pieces as
    ``parts``; groups record translations, rotations, reflections, coaxial
    and parallel sets."""
    a = run.associator.fit(list(seg), run.ctx.pre, run.ctx.tau, run.ctx.link)
    seg.rebuild([SegmentRecord(it.family, it.prim, fixed=it.fixed) for it in a.items_],
                [it.indices for it in a.items_])
    seg.parts = [list(it.parts) for it in a.items_]
    seg.groups = list(a.groups_)
    return seg


ABSORB = Pass("absorb", absorb_pass, EXTENSION)
SETTLE_NOISY = Pass("settle_noisy_edges", settle_noisy_pass, EXTENSION, when=_nearest_edges)
ASSOCIATION = Pass("association", association, PAPER_5_4)

#: The passes in order. Association comes last: it reads the final segments.
PIPELINE: tuple[Pass, ...] = (
    Pass("recognition", recognition, PAPER_5_2, after=(replace(ABSORB, when=_absorb_after_recognition),)),
    Pass("splitting", splitting, PAPER_5_3),
    Pass("consolidation", consolidation, EXTENSION, after=(ABSORB,)),
    Pass("dissolve_redundant", dissolve_pass, EXTENSION),
    Pass("settle_noisy_edges", settle_noisy_pass, EXTENSION, when=_nearest_edges),
    Pass("revisit_poor_fits", revisit_pass, EXTENSION, when=_nearest_edges, after=(ABSORB, SETTLE_NOISY),
         only_if_changed=True),
    Pass("fillets", fillets_pass, EXTENSION, after=(ABSORB, SETTLE_NOISY), only_if_changed=True),
    Pass("prefer_planes", prefer_planes_pass, EXTENSION),
    Pass("settle_edges", settle_edges_pass, EXTENSION, when=_shared_edges),
    Pass("refine", refine_pass, EXTENSION),
    ASSOCIATION,
)


@dataclass(frozen=True)
class _Saved:
    """The state before the association, kept for :meth:`Segmenter.reassociate`."""

    seg: Segmentation
    run: Run
    timing: dict[str, float]
    points: np.ndarray
    normals: np.ndarray | None
    source: str | None
    picked: Subsample | None


def pass_names() -> list[str]:
    """The names of every declared pass, follow-ups as ``pass.follow_up``."""
    def names(p: Pass, prefix: str = "") -> list[str]:
        return [prefix + p.name] + [n for q in p.after for n in names(q, prefix + p.name + ".")]

    return [n for p in PIPELINE for n in names(p)]


class Segmenter(ParamsMixin):
    """Decompose a point cloud into primitives (scikit-learn style).

    Parameters
    ----------
    families : str or list of str or Family
        ``"simple"`` (plane, cylinder, cone, sphere, torus), ``"all"``, or names.
    epsilon : float, optional
        Removal threshold ε as a fraction of the diagonal of the part's bounding box in its own frame
        (its most common face normals as axes: the same in any pose)
        (the paper uses 0.01–0.03). Default: adapted to the point spacing and
        the estimated noise.
    normals_method : {"auto", "pca", "voting", "input"}
        Normal estimation (see :func:`houghcad.preprocess.preprocess`).
    persistence : float
        Peak persistence threshold, a fraction of the accumulator's maximum.
    min_points : int, optional
        Smallest segment; default the points of a patch ``min_face_diagonals`` (1.5 %) of the
        diagonal wide at the cloud's density, at least 6, 8 on noisy clouds (see ``context.points_in_patch``).
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
    trace : str, path or callable, optional
        A folder: the labels after every pass are written there as a PLY per
        pass (see :func:`houghcad.io.writers.write_trace_ply`). A callable:
        called as ``trace(step, pass_name, state)``.
    check : bool, optional
        Check the state's invariants after every pass (default: when
        ``$HOUGHCAD_CHECK`` is set).
    noise : {"auto", "clean", "noisy"}
        The noise policy (:mod:`houghcad.noise`): "auto" reads the cloud as
        noisy when its estimated σ is at least 0.15 point spacings.
    tolerances : Tolerances or dict, optional
        Named thresholds of every stage (:mod:`houghcad.tolerances`), a
        :class:`~houghcad.tolerances.Tolerances` or ``{"stage": {"name":
        value}}``; the rest keep their defaults.
    skip : sequence of str
        Names of passes not to run (see :func:`pass_names`; a skipped pass's
        follow-ups are skipped with it), for ablation and debugging.
    max_points : int or None
        Clouds with more points are recognised on an even voxel subsample of
        at most this many points, then every point is labelled from its
        subsample neighbours (:mod:`houghcad.multires`). None: never.
    full_resolution : bool
        Recognise on every point whatever the size (``max_points`` ignored).
    n_jobs : int, optional
        Processes for the independent work of a run: the families of one
        round, the clusters of the splitting phase (:mod:`houghcad.parallel`).
        None: every available core; 1: this process only. The result is the
        same for every value.

    Attributes
    ----------
    result_ : Result
        Set by :meth:`fit`.
    segmentation_ : Segmentation
        The final state (standard frame), set by :meth:`fit`.
    context_ : Context
        The run's scales and thresholds, set by :meth:`fit`.
    """

    def __init__(self, families="simple", epsilon: float | None = None, normals_method: str = "auto",
                 persistence: float = DEFAULT_PERSISTENCE, min_points: int | None = None, seed: int = 0,
                 progress: Callable[[str, float], None] | None = None, merge: bool = True,
                 association: dict[str, Any] | None = None, trace: str | Path | TraceFn | None = None,
                 check: bool | None = None, noise: str = "auto",
                 tolerances: Tolerances | dict[str, Any] | None = None, skip: tuple[str, ...] = (),
                 max_points: int | None = DEFAULT_MAX_POINTS, full_resolution: bool = False,
                 n_jobs: int | None = None):
        self.families = families
        self.epsilon = epsilon
        self.normals_method = normals_method
        self.persistence = persistence
        self.min_points = min_points
        self.seed = seed
        self.progress = progress
        self.merge = merge
        self.association = association
        self.trace = trace
        self.check = check
        self.noise = noise
        self.tolerances = tolerances
        self.skip = skip
        self.max_points = max_points
        self.full_resolution = full_resolution
        self.n_jobs = n_jobs

    def get_options(self) -> dict[str, Any]:
        """The options a result records (``Result.options``): the constructor's arguments that
        shape the output, families by name, plain values (JSON)."""
        fams = self.families
        return {"families": fams if isinstance(fams, str) else [getattr(f, "name", f) for f in fams],
                "epsilon": self.epsilon, "normals_method": self.normals_method,
                "persistence": self.persistence, "min_points": self.min_points, "seed": self.seed,
                "merge": bool(self.merge), "association": dict(self.association or {}), "noise": self.noise,
                "tolerances": self._tolerances().to_dict(), "skip": self._skipped(),
                "max_points": self.max_points, "full_resolution": bool(self.full_resolution)}

    def _skipped(self) -> list[str]:
        """The passes not to run, by name (one name alone is that one pass, not its letters)."""
        return [self.skip] if isinstance(self.skip, str) else list(self.skip)

    def tolerances_dict(self) -> dict[str, Any]:
        """``tolerances`` as ``{stage: {name: value}}`` (without the ``association`` options)."""
        if isinstance(self.tolerances, Tolerances):
            return self.tolerances.to_dict()
        return dict(self.tolerances or {})

    def _tolerances(self) -> Tolerances:
        """The run's tolerances: ``tolerances`` with the ``association`` options over them."""
        if not isinstance(self.tolerances, (Tolerances, dict, type(None))):
            raise InputError(f"tolerances must be a Tolerances, a dict or None, got {self.tolerances!r}")
        try:
            t = self.tolerances if isinstance(self.tolerances, Tolerances) else \
                Tolerances.from_dict(self.tolerances)
            return t.updated({"association": dict(self.association)}) if self.association else t
        except (TypeError, ValueError) as exc:
            raise InputError(f"tolerances: {exc}") from None

    def _associator(self, merge: bool, tol: Tolerances) -> Associator:
        return Associator(merge=bool(merge), tol=tol.association)

    def fit(self, points: np.ndarray, normals: np.ndarray | None = None, source: str | None = None) -> "Segmenter":
        """Segment ``points`` (n, 3), world units; ``normals`` (n, 3) optional."""
        with blas_one_thread():
            return self._fit(points, normals, source)

    def _fit(self, points: np.ndarray, normals: np.ndarray | None, source: str | None) -> "Segmenter":
        from .io import validate_points
        from .io.readers import clean_normals

        points = validate_points(np.asarray(points), source)
        top = float(np.abs(points).max())
        if top > MAX_COORDINATE:
            raise InputError(f"{source or 'input'}: coordinates up to {top:.3g}; beyond "
                             f"{MAX_COORDINATE:g} the fits' squared distances overflow, so rescale the cloud")
        # Unusable normals (wrong shape, non-finite or zero-length rows) are estimated, as a file's.
        if normals is not None and clean_normals(normals, len(points), source) is None:
            if self.normals_method == "input":  # the warning said why; with "input" it is an error
                raise InputError(f"{source or 'input'}: normals method 'input' needs usable normals, and these "
                                 "are not (see the warning)")
            normals = None
        normals = None if normals is None else np.asarray(normals, dtype=np.float64)
        check_options(self)
        tol = self._tolerances()
        skip = self._skipped()
        unknown = sorted(set(skip) - set(pass_names()))
        if unknown:
            raise InputError(f"unknown pass {unknown[0]!r} to skip (passes: {', '.join(pass_names())})")
        associator = self._associator(self.merge, tol)
        fams = fam_mod.select(self.families)
        # A family refining a selected one is not voted: it would tie with its
        # base family, which wins ties; the base's segments are offered to it
        # after recognition instead (see ``refine_pass``).
        names = {f.name for f in fams}
        voted = [f for f in fams if f.refines not in names]
        report = monotonic(self.progress)

        t0 = time.perf_counter()
        picked = self._subsample(points)
        timing = {} if picked is None else {"subsample": time.perf_counter() - t0}
        work, work_normals = (points, normals) if picked is None else \
            (points[picked.indices], None if normals is None else normals[picked.indices])
        t0 = time.perf_counter()
        report("preprocess", 0.0)
        jobs = resolve_jobs(self.n_jobs)
        pre = preprocess(work, work_normals, method=self.normals_method, seed=self.seed, noise=self.noise,
                         workers=jobs, sampling_scales=tol.scale.link_scale_max > 1.0)
        ctx = self._context(pre, len(work), tol)
        warn_coarse_coordinates(points, ctx.spacing / pre.transform.scale, source)
        timing["preprocess"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        with Workers(ctx, fams, jobs) as workers:
            if workers.pool is not None:
                timing["workers"] = time.perf_counter() - t0
            run = Run(replace(ctx, workers=workers), fams, voted, associator, report)
            runner = Runner(run, timing, self._tracer(work, None if picked is None else picked.indices),
                            checks_enabled() if self.check is None else bool(self.check), total=len(PIPELINE),
                            skip=frozenset(skip))
            seg = Segmentation(len(work))
            for p in PIPELINE:
                if p is ASSOCIATION:
                    # Without the workers and the progress closure: a fitted Segmenter pickles.
                    self._before_association = _Saved(seg.copy(), replace(run, ctx=ctx, progress=quiet),
                                                      dict(runner.timing), points, normals, source, picked)
                seg = runner(p, seg)
        run = replace(run, ctx=ctx)  # the workers are gone
        self.context_ = ctx
        self.result_ = self._result(seg, run, runner.timing, self._before_association)
        report("done", 1.0)
        return self

    def reassociate(self, merge: bool | None = None, association: dict[str, Any] | None = None) -> Result:
        """Run the association again on the segments of the last :meth:`fit`
        with other options (cheap: recognition is not repeated); returns a new Result."""
        if not hasattr(self, "_before_association"):
            raise RuntimeError("call fit() first")
        saved = self._before_association
        seg, run, timing = saved.seg, saved.run, saved.timing
        merge = self.merge if merge is None else merge
        tol = run.ctx.tol
        if association is not None:  # these options replace the Segmenter's association options
            tol = replace(tol, association=replace(Tolerances.from_dict(self.tolerances_dict()).association))
            try:
                tol = tol.updated({"association": dict(association)})
            except ValueError as exc:
                raise InputError(f"tolerances: {exc}") from None
        run = replace(run, ctx=replace(run.ctx, tol=tol), associator=self._associator(merge, tol),
                      progress=lambda s, f: None)
        runner = Runner(run, dict(timing))
        # The fit's own state stays this object's (segmentation_ goes with result_); the new
        # result records the options it was made with.
        kept = self.segmentation_
        try:
            out = self._result(runner(ASSOCIATION, seg.copy()), run, runner.timing, saved)
        finally:
            self.segmentation_ = kept
        if association is not None:
            out.options["association"] = dict(association)
        return out

    def _subsample(self, points: np.ndarray) -> Subsample | None:
        """The even subsample recognition runs on, the distinct points of a cloud with exact
        copies, or None to run on every point."""
        if self.full_resolution or self.max_points is None:
            return distinct_points(points)
        if isinstance(self.max_points, bool) or int(self.max_points) != self.max_points \
                or self.max_points < MIN_MAX_POINTS:
            raise InputError(f"max_points must be a whole number of at least {MIN_MAX_POINTS}, got {self.max_points!r}")
        if len(points) <= self.max_points:
            return distinct_points(points)
        return voxel_subsample(points, int(self.max_points), self.seed)

    def _result(self, seg: Segmentation, run: Run, timing: dict[str, float], saved: _Saved) -> Result:
        points, source, picked = saved.points, saved.source, saved.picked
        copies = picked is not None and picked.twin is not None
        subsampled = picked is not None and not copies
        if copies:  # exact copies take their twins' labels
            full = copy_to_twins(seg, run.ctx.pre, picked.twin)
            seg, run = full.seg, replace(run, ctx=replace(run.ctx, pre=full.pre))
        elif subsampled:  # every input point from its subsample neighbours (multires)
            t = time.perf_counter()
            run.progress("propagate", _PROPAGATE_AT)
            full = propagate(seg, run.ctx, picked.indices, points, saved.normals, run.ctx.tol.resolution,
                             workers=resolve_jobs(self.n_jobs))
            seg, run = full.seg, replace(run, ctx=replace(run.ctx, pre=full.pre))
            timing = {**timing, "propagate": time.perf_counter() - t}
        self.segmentation_ = seg
        t = time.perf_counter()
        run.progress("output", _OUTPUT_AT)
        distances = np.full(len(points), np.nan)
        # Boundary curves on the cloud recognition ran on; a subsampled cloud's points are not
        # the CAD sample's own (nor on its curves).
        edges = None if subsampled else edge_points(seg, run.ctx)
        out, groups = build_segments(seg, seg.groups, run.ctx.pre, points, self.seed, distances, edges)
        timing = {**timing, "output": time.perf_counter() - t}
        timing["total"] = sum(v for k, v in timing.items() if k != "total")
        ctx = run.ctx
        options = {**self.get_options(), "merge": bool(run.associator.merge), "tolerances": ctx.tol.to_dict(),
                   "normals_used": ctx.pre.normals_method,
                   "derived": {"noise_policy": ctx.policy.name,
                               "sigma": float(ctx.pre.noise / ctx.pre.transform.scale),
                               "spacing": float(ctx.spacing / ctx.pre.transform.scale),
                               "tau": float(ctx.tau / ctx.pre.transform.scale),
                               "epsilon": float(ctx.epsilon / ctx.pre.transform.scale),
                               "link": float(ctx.link / ctx.pre.transform.scale),
                               "angle_deg": float(np.degrees(ctx.angle)), "min_points": ctx.min_points,
                               "subsample_points": len(picked.indices) if subsampled else None,
                               "voxel": float(picked.voxel) if subsampled else None,
                               "copies": len(points) - len(picked.indices) if copies else 0}}
        unsegmented = np.flatnonzero(seg.labels < 0).astype(np.int64)
        return Result(n_points=len(points), segments=out, unsegmented=unsegmented, timing=timing,
                      options=options, source=source, groups=groups,
                      normals=ctx.pre.transform.inv_dirs(ctx.pre.normals), distances=distances)

    def _tracer(self, points: np.ndarray, rows: np.ndarray | None) -> TraceFn | None:
        """The trace callback over the points the passes run on, ``points`` (m, 3): the cloud, or
        its subsample or distinct points, whose input rows ``rows`` (m,) the PLYs then carry."""
        if self.trace is None or callable(self.trace):
            return self.trace
        from .io.writers import write_trace_ply

        folder = Path(self.trace)
        folder.mkdir(parents=True, exist_ok=True)
        return lambda step, name, seg: write_trace_ply(folder / f"{step:02d}_{name}.ply", points, seg, name, rows)

    def _context(self, pre, n: int, tol: Tolerances | None = None) -> Context:
        """The run's context for the preprocessed cloud ``pre`` of n points."""
        tol = self._tolerances() if tol is None else tol
        try:
            policy = choose(self.noise, pre.noise, pre.spacing)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        return derive_context(pre, n, tol, policy, epsilon=self.epsilon, min_points=self.min_points,
                              persistence=self.persistence, seed=self.seed)


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
        See :class:`Segmenter` (``**options`` too: persistence, min_points,
        association, trace, check, n_jobs...).
    source : str, optional
        Name of the input, used in messages and in the result.

    Returns
    -------
    Result
    """
    seg = Segmenter(families=families, epsilon=epsilon, seed=seed, normals_method=normals_method,
                    progress=progress, merge=merge, **options)
    return seg.fit(points, normals, source=source).result_
