"""Both cores inside one cloud (our extension; the paper notes that families and clusters are
embarrassingly parallel).

A run forks its :class:`Workers` once, right after preprocessing. Each worker holds the run's
context as it was at the fork (the preprocessed cloud, its scales and thresholds), copy-on-write,
so a task is only a list of point indices and the families' names, and only the candidates come
back (a task over a segmentation state, :meth:`Workers.map_segments`, also carries its labels
and segment records). Why processes, and why written here rather than taken from a library: the
work is mostly Python-level (scipy's small least-squares fits, numpy on a few thousand points), so
threads serialise on the GIL; ``concurrent.futures`` and ``joblib`` would pickle the whole cloud into
every task, which costs more than a cluster's recognition.

Each task is a pure function of its points, so its result is the one this process would compute,
and results come back in task order: the output is the same for every number of jobs. Where
forking is impossible (no ``fork`` start method, or inside a daemonic worker such as a Dask
nanny's) there are no workers and everything runs in this process.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import multiprocessing.pool
import os
import signal
from dataclasses import dataclass, fields, is_dataclass, replace
from typing import TYPE_CHECKING, Any, Callable, Iterator

import numpy as np

if TYPE_CHECKING:  # the pipeline's modules import this one
    from .context import Context
    from .families import Family
    from .state import Candidate, Segmentation

#: A batch of tasks under this many points in all runs here: handing it out costs more.
PARALLEL_MIN_POINTS = 100
#: Evaluation tasks per worker: the peaks' costs vary, more tasks than workers even them out.
EVALUATE_TASKS_PER_JOB = 3
#: Seconds between checks, while results are awaited, that no worker has died.
POLL_SECONDS = 0.25


class WorkerDied(RuntimeError):
    """A worker process died in a task (a crash in native code: a Pool would wait for its task
    forever). A bug, not bad input: the message names the signal."""

#: In a worker: the run's context at the fork and its families by name.
_BASE: "tuple[Context, dict[str, Family]] | None" = None
_SCALARS = (bool, int, float, str, np.integer, np.floating)


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS says, else the CPU count)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return os.cpu_count() or 1


#: Workers per available core at most: more only share the cores (``--jobs 1000`` forked a
#: thousand processes); the result is the same for any number.
MAX_JOBS_PER_CORE = 4


def resolve_jobs(n_jobs: int | None) -> int:
    """``n_jobs`` as a count: None or 0 is every available core, -k is all but k - 1 (at least 1),
    and no more than :data:`MAX_JOBS_PER_CORE` per core."""
    if n_jobs is None or n_jobs == 0:
        return available_cores()
    n = int(n_jobs)
    return min(n, MAX_JOBS_PER_CORE * available_cores()) if n > 0 else max(available_cores() + 1 + n, 1)


@contextlib.contextmanager
def blas_one_thread() -> Iterator[None]:
    """Run the block with one BLAS thread (numpy's and scipy's OpenBLAS), restored after.

    Our linear algebra is small (3 x 3 eigenproblems, least squares over a few thousand rows,
    (n, 3) @ (3, 3)): BLAS's threads only hand such work around, and between calls they spin,
    taking the other core from whoever needs it, the forked workers (which inherit the limit)
    or this process's serial passes. Measured on every 4th Fit4CAD cloud: 48.6 -> 47.4 s with
    one job, 44.7 -> 41.5-43.6 s with two (the same output). threadpoolctl, not an environment
    variable: the libraries are loaded before a run starts, and a program calling us keeps its
    own setting."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency; without it the threads stay
        yield
        return
    with threadpool_limits(limits=1, user_api="blas"):
        yield


def can_fork() -> bool:
    """Whether this process can fork workers."""
    return "fork" in mp.get_all_start_methods() and not mp.current_process().daemon


def _task(job: tuple[str, np.ndarray, list[str], dict[str, Any], Any]) -> Any:
    """In a worker: ``what`` of the families ``names`` on the points ``idx``, every one of them
    free: a family's "propose"d primitives, the "evaluate"d candidates of its primitives
    ``extra`` (``[(primitive, coarse tolerance)]``), every family's "candidates", the
    "recognize"d ones, or a splitting-phase "cluster"'s."""
    from .recognize import candidates, evaluate, propose, recognize, voting_context
    from .splitting import recognise_cluster

    what, idx, names, overrides, extra = job
    assert _BASE is not None
    base, by_name = _BASE
    ctx = replace(base, **overrides)
    fams = [by_name[n] for n in names]
    if what in ("propose", "evaluate"):
        vctx = voting_context(idx, ctx)
        if what == "propose":
            return propose(fams[0], idx, vctx)
        return _swap_families([evaluate(fams[0], prim, idx, vctx, coarse) for prim, coarse in extra], _FamilyName)
    avail = np.ones(len(ctx.pre.points), bool)
    step = {"candidates": candidates, "recognize": recognize, "cluster": recognise_cluster}[what]
    return _swap_families(step(idx, fams, ctx, avail), _FamilyName)


@dataclass(frozen=True)
class _FamilyName:
    """Stands for a family in a worker's candidates on their way back: a family need not pickle
    (a user family built from sympy expressions does not)."""

    name: str


def _swap_families(x: Any, family_of: "Callable[[str], Any]") -> Any:
    """``x`` (dataclasses whose ``family`` is a family, such as candidates and segment records,
    in lists and tuples; anything else as it is) with each one's family replaced by
    ``family_of(its name)``. A primitive's ``family`` is a name already."""
    if isinstance(x, (list, tuple)):
        return type(x)(_swap_families(v, family_of) for v in x)
    if is_dataclass(x) and not isinstance(x, type) and hasattr(getattr(x, "family", None), "name"):
        return replace(x, family=family_of(x.family.name))
    return x


def _segmentation_task(job: tuple[Callable, np.ndarray, list, dict[str, Any], list[str], list, tuple]) -> list:
    """In a worker: ``func(seg, items, ctx, families, *args)`` on the segmentation whose labels
    and records (families named) came with the task."""
    from .state import Segmentation

    func, labels, records, overrides, names, items, args = job
    assert _BASE is not None
    base, by_name = _BASE
    seg = Segmentation(0)
    seg.labels = labels
    seg.records = _swap_families(records, by_name.__getitem__)
    fams = [by_name[n] for n in names]
    return _swap_families(func(seg, items, replace(base, **overrides), fams, *args), _FamilyName)


class Workers:
    """``n_jobs`` processes forked with the run's context ``ctx`` and ``families``; none when
    ``n_jobs`` is 1 or forking is impossible. Close it (or use it as a context manager)."""

    def __init__(self, ctx: "Context", families: "list[Family]", n_jobs: int):
        global _BASE
        self.base = ctx
        self.by_name = {f.name: f for f in families}
        self.pool = None
        self.n_jobs = n_jobs
        if n_jobs > 1 and can_fork():
            _BASE = (ctx, self.by_name)
            try:
                self.pool = mp.get_context("fork").Pool(n_jobs, initializer=_ignore_interrupts)
                self._procs = list(self.pool._pool)  # the Pool replaces a dead worker, silently
            finally:
                _BASE = None  # only the children need it

    def __enter__(self) -> "Workers":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.terminate()
            self.pool.join()
            self.pool = None

    def _get(self, pending: Any) -> Any:
        """``pending.get()`` (an AsyncResult, or an imap iterator's ``next``), checking that no
        worker died meanwhile: the Pool starts a new worker in a dead one's place, and its task
        never returns."""
        get = pending.get if hasattr(pending, "get") else pending.next
        while True:
            try:
                return get(POLL_SECONDS)
            except mp.TimeoutError:
                dead = [p.exitcode for p in self._procs if p.exitcode is not None]
                if dead:
                    code = dead[0]
                    how = f"signal {-code} ({signal.Signals(-code).name})" if code < 0 else f"exit code {code}"
                    raise WorkerDied(f"a worker process died ({how}); houghcad --jobs 1 runs without "
                                     "workers") from None

    def _overrides(self, ctx: "Context") -> dict[str, Any] | None:
        """The scalar fields in which ``ctx`` differs from the context at the fork, or None when
        another field differs (the workers could not rebuild it)."""
        out: dict[str, Any] = {}
        for f in fields(ctx):
            a, b = getattr(ctx, f.name), getattr(self.base, f.name)
            if f.name == "workers" or a is b:
                continue
            if isinstance(a, _SCALARS) and isinstance(b, _SCALARS):
                if a != b:
                    out[f.name] = a
                continue
            return None
        return out

    def _rebuilt(self, ctx: "Context", fams: "list[Family]") -> dict[str, Any] | None:
        """:meth:`_overrides` of ``ctx``, or None also when one of ``fams`` is not the run's own
        family of its name (the workers know the families by name only)."""
        if any(self.by_name.get(f.name) is not f for f in fams):
            return None
        return self._overrides(ctx)

    def _payload(self, what: str, jobs: "list[tuple[np.ndarray, list[Family], Any]]",
                 ctx: "Context", min_jobs: int = 2) -> list[tuple] | None:
        """The tasks of ``jobs`` for :func:`_task`, or None when they are not worth handing out
        (fewer than ``min_jobs``, or few points) or cannot be rebuilt in the workers."""
        if self.pool is None or len(jobs) < min_jobs or sum(len(j[0]) for j in jobs) < PARALLEL_MIN_POINTS:
            return None
        overrides = self._rebuilt(ctx, [f for j in jobs for f in j[1]])
        if overrides is None:
            return None
        return [(what, np.asarray(idx), [f.name for f in fams], overrides, extra) for idx, fams, extra in jobs]

    def run(self, what: str, jobs: "list[tuple[np.ndarray, list[Family], Any]]", ctx: "Context") -> list[Any] | None:
        """For each ``(idx, families, extra)``, what ``what`` (see :func:`_task`) gives on the points
        ``idx`` (all free), computed on the workers, in job order; None when the jobs are not worth
        handing out or ``ctx`` cannot be rebuilt there (the caller then runs them itself)."""
        wait = self.submit(what, jobs, ctx, min_jobs=2)
        return None if wait is None else wait()

    def submit(self, what: str, jobs: "list[tuple[np.ndarray, list[Family], Any]]", ctx: "Context",
               min_jobs: int = 1) -> "Callable[[], list[Any] | None] | None":
        """As :meth:`run`, without waiting (by default even one job is handed out: the caller works
        beside it): a function that waits for the results and returns them in job order, or None
        when they do not pickle. None as :meth:`run`."""
        payload = self._payload(what, jobs, ctx, min_jobs)
        if payload is None:
            return None
        assert self.pool is not None
        pending = self.pool.map_async(_task, payload, chunksize=1)

        def wait() -> list[Any] | None:
            try:
                return _swap_families(self._get(pending), self.by_name.__getitem__)
            except mp.pool.MaybeEncodingError:  # a user family's primitive that does not pickle
                return None

        return wait

    def map_segments(self, func: Callable, seg: "Segmentation", items: list, ctx: "Context",
                     fams: "list[Family]", *args: Any) -> list | None:
        """``func(seg, items, ctx, fams, *args)``, a list with one result per item, on the
        workers: the items dealt out in turn over one task per worker, the results back in item
        order. ``func`` must be a module-level function (it goes to the workers by name) and only
        read ``seg``. None as :meth:`run`, or when a family is not one of the run's."""
        if self.pool is None or len(items) < 2 * self.n_jobs:
            return None
        overrides = self._rebuilt(ctx, [*fams, *(r.family for r in seg.records)])
        if overrides is None:
            return None
        records = _swap_families(list(seg.records), _FamilyName)
        names = [f.name for f in fams]
        n = self.n_jobs
        payload = [(func, seg.labels, records, overrides, names, items[j::n], args) for j in range(n)]
        try:
            parts = _swap_families(self._get(self.pool.map_async(_segmentation_task, payload, chunksize=1)),
                                   self.by_name.__getitem__)
        except mp.pool.MaybeEncodingError:  # a user family's primitive that does not pickle
            return None
        out: list = [None] * len(items)
        for j, part in enumerate(parts):
            out[j::n] = part
        return out

    def candidates(self, idx: np.ndarray, fams: "list[Family]", ctx: "Context") -> "list[Candidate] | None":
        """``recognize.candidates`` of the families on the points ``idx`` (all free), on the
        workers: each family's vote, and as soon as a family's peaks are known, their evaluations,
        dealt out in turn over a few tasks (a costly vote, the cylinders' on a whole cloud, then
        runs beside the evaluation of the others' peaks). None as :meth:`run`."""
        # The later families (cones, tori, the complex ones) cost the most: handed out first.
        order = list(range(len(fams)))[::-1]
        payload = self._payload("propose", [(idx, [fams[i]], None) for i in order], ctx)
        if payload is None:
            return None
        assert self.pool is not None
        _, points, _, overrides, _ = payload[0]
        try:
            return _swap_families(self._vote_and_evaluate(list(zip(order, payload)), fams, points, overrides),
                                  self.by_name.__getitem__)
        except mp.pool.MaybeEncodingError:  # a user family's primitive that does not pickle
            return None

    def _vote_and_evaluate(self, tagged: list, fams: "list[Family]", idx: np.ndarray,
                           overrides: dict[str, Any]) -> list:
        assert self.pool is not None
        evaluations: dict[int, list[tuple[list[int], Any]]] = {}
        n_peaks: dict[int, int] = {}
        proposals = self.pool.imap_unordered(_tagged_task, tagged)
        for _ in tagged:
            i, props = self._get(proposals)
            pairs = list(props)
            n_peaks[i] = len(pairs)
            n = max(1, min(len(pairs), EVALUATE_TASKS_PER_JOB * self.n_jobs))
            evaluations[i] = [(list(range(j, len(pairs), n)),
                               self.pool.apply_async(_task, (("evaluate", idx, [fams[i].name], overrides, pairs[j::n]),)))
                              for j in range(n) if pairs[j::n]]
        out: list = []
        for i in range(len(fams)):
            per: list = [None] * n_peaks[i]
            for where, res in evaluations[i]:
                for k, cs in zip(where, self._get(res)):
                    per[k] = cs
            out += [c for cs in per for c in cs]
        return out


def _ignore_interrupts() -> None:
    """In a worker: Ctrl-C reaches the whole process group; the main process handles it (and
    terminates the workers), so a worker must not die of it with a traceback of its own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _tagged_task(tagged: tuple[int, tuple]) -> tuple[int, Any]:
    return tagged[0], _task(tagged[1])
