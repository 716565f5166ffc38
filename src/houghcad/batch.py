"""Segment many point clouds on a Dask cluster: the API behind ``houghcad batch``.

:func:`batch` expands the inputs (files, folders, glob patterns), decides which clouds need a
run (outputs missing or older than the input), runs :func:`segment_cloud` for each on the
:class:`~houghcad.engine.Engine` and writes ``summary.csv`` and ``index.html`` into the output
folder (:mod:`houghcad.batchreport`). Each cloud's outputs are those of ``houghcad segment`` with
the same options, written by the worker that segmented it:

======================  ===========================  ======================
output                  file in ``out_dir``           ``houghcad segment``
======================  ===========================  ======================
result (always)         ``<stem>_segments.json``      ``-o``
``fit4cad=True``        ``<stem>_primitives.txt``     ``--fit4cad DIR``
``ply=True``            ``<stem>_segments.ply``       ``--ply``
``png=True``            ``<stem>_segments.png``       ``--png``
``report=True``         ``<stem>_report.html``        ``--report``
======================  ===========================  ======================

Two inputs with one stem would write the same files: :func:`batch` refuses them before starting.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from .cliopts import SegmentOptions
from .errors import InputError

__all__ = ["BatchRow", "CloudJob", "SegmentOptions", "batch", "expand_inputs", "plan", "segment_cloud",
           "OUTPUT_NAMES", "MEASURES", "truth_beside"]

MEASURES = ("DSC", "PPV", "TPR", "TNR", "NPV", "ACC")
#: File name of each output, after the cloud's stem. "json" is always written.
OUTPUT_NAMES = {"fit4cad": "_primitives.txt", "ply": "_segments.ply", "png": "_segments.png",
                "report": "_report.html", "json": "_segments.json"}
#: Files that a folder or a pattern holds beside the clouds and that are not clouds: Fit4CAD
#: ground truth and houghcad's own coloured clouds.
COMPANIONS = ("_primitives.txt", "_implicit.txt", "_parametric.txt", "_segments.ply")
#: The batch's own table in its output folder (a CSV file, which the XYZ reader would read).
SUMMARY_NAME = "summary.csv"


@dataclass
class BatchRow:
    """One input's line of ``summary.csv``.

    Attributes
    ----------
    input : str
        The cloud's path as given (or as found in a given folder or pattern).
    status : str
        ``"ok"`` (segmented now), ``"error"`` (``error`` says why) or ``"skipped"`` (its outputs
        were already there and not older than the input; the counts and measures are those of
        its saved result, scored again against the ground truth beside the cloud, and
        ``seconds`` is the previous ``summary.csv``'s when it lists the cloud).
    n_points, n_segments, unsegmented : int or None
        Points of the cloud, segments found, points left unsegmented.
    seconds : float or None
        Wall time of the cloud on its worker: reading, segmenting and writing, in seconds.
    error : str or None
        One-line message of an ``error`` (or a ground-truth file that could not be read).
    DSC, PPV, TPR, TNR, NPV, ACC : float or None
        Fit4CAD classification measures in [0, 1] when ``NAME_primitives.txt`` sits beside the
        cloud (as ``houghcad evaluate``: a maximal primitive is scored by its faces); 0 for an
        ``error`` row that has a ground truth.
    outputs : tuple of str
        Names of the cloud's files in the output folder.
    peak_mb : float or None
        Peak resident memory of the worker process while it ran this cloud, MiB.
    """

    input: str
    status: str
    n_points: int | None = None
    n_segments: int | None = None
    unsegmented: int | None = None
    seconds: float | None = None
    error: str | None = None
    DSC: float | None = None
    PPV: float | None = None
    TPR: float | None = None
    TNR: float | None = None
    NPV: float | None = None
    ACC: float | None = None
    outputs: tuple[str, ...] = ()
    peak_mb: float | None = None

    def measures(self) -> dict[str, float]:
        """The classification measures that are known."""
        return {m: getattr(self, m) for m in MEASURES if getattr(self, m) is not None}


@dataclass(frozen=True)
class CloudJob:
    """Everything a worker needs to segment one cloud (absolute paths: workers may run elsewhere)."""

    path: str
    display: str
    out_dir: str
    stem: str
    outputs: tuple[str, ...]  # keys of OUTPUT_NAMES, "json" last
    options: SegmentOptions
    ground_truth: str | None = None

    def output_path(self, kind: str) -> Path:
        return Path(self.out_dir) / f"{self.stem}{OUTPUT_NAMES[kind]}"


class BatchProgress(Protocol):
    """What :func:`batch` tells a progress display (``houghcad.batchcli.Progress`` draws it)."""

    def begin(self, total: int, skipped: Sequence[BatchRow], dashboard: str | None) -> None: ...

    def started(self, row_input: str) -> None: ...

    def finished(self, row: BatchRow) -> None: ...


# --------------------------------------------------------------------------- inputs


def truth_beside(cloud: Path) -> Path | None:
    """The Fit4CAD ground truth ``NAME_primitives.txt`` beside the cloud ``NAME.<ext>``, if any."""
    gt = cloud.with_name(cloud.stem + COMPANIONS[0])
    return gt if gt.is_file() else None


def _is_cloud_name(path: Path) -> bool:
    from .io.readers import FORMAT_TABLE

    name = path.name.lower()
    extensions = {ext for f in FORMAT_TABLE for ext in f.extensions}
    return path.suffix.lower() in extensions and not name.endswith(COMPANIONS) and not name.startswith(".") \
        and name != SUMMARY_NAME


def expand_inputs(inputs: Sequence[str | os.PathLike[str]]) -> list[tuple[str, Path]]:
    """``(display, path)`` of every cloud named by ``inputs``: files as given; folders: every file
    of a point-cloud extension directly inside (not in subfolders), less the ground-truth and
    ``_segments.ply`` companions; glob patterns (``**`` recurses) the same way. Sorted within a
    folder or pattern; a file named twice counts once. Raises InputError for an input that names
    nothing."""
    found: list[tuple[str, Path]] = []
    for given in map(str, inputs):
        path = Path(given)
        if path.is_file():
            found.append((given, path))
        elif path.is_dir():
            inside = sorted(p for p in path.iterdir() if p.is_file() and _is_cloud_name(p))
            if not inside:
                raise InputError(f"{given}: no point-cloud file in this folder")
            found += [(os.path.join(given, p.name), p) for p in inside]
        elif glob.has_magic(given):
            matches = sorted(m for m in glob.glob(given, recursive=True)
                             if Path(m).is_file() and _is_cloud_name(Path(m)))
            if not matches:
                raise InputError(f"{given}: no point-cloud file matches this pattern")
            found += [(m, Path(m)) for m in matches]
        else:
            raise InputError(f"{given}: no such file or folder")
    seen: set[Path] = set()
    unique = []
    for display, path in found:
        if path.resolve() not in seen:
            seen.add(path.resolve())
            unique.append((display, path))
    return unique


def _check_stems(clouds: list[tuple[str, Path]], out_dir: Path, outputs: Sequence[str]) -> None:
    """Refuse two clouds that would write the same files, and outputs that would replace an input."""
    by_stem: dict[str, str] = {}
    for display, path in clouds:
        if path.stem in by_stem:
            raise InputError(f"{by_stem[path.stem]} and {display} would both write "
                             f"{out_dir / (path.stem + OUTPUT_NAMES['json'])}: rename one or run them in "
                             "separate batches")
        by_stem[path.stem] = display
    inputs = {path.resolve(): display for display, path in clouds}
    # A cloud's ground truth beside it is an input too: --fit4cad into the clouds' own folder
    # would replace it with the prediction, and then score the prediction against itself.
    for display, path in clouds:
        gt = truth_beside(path)
        if gt is not None:
            inputs[gt.resolve()] = os.path.join(os.path.dirname(display), gt.name)
    for _, path in clouds:
        for kind in outputs:
            out = (out_dir / f"{path.stem}{OUTPUT_NAMES[kind]}").resolve()
            if out in inputs:
                raise InputError(f"{inputs[out]}: refusing to overwrite an input with the outputs of {path.name}")


def _up_to_date(job: CloudJob) -> bool:
    """Every requested output exists and is not older than the input."""
    try:
        since = os.stat(job.path).st_mtime_ns
        return all(job.output_path(k).stat().st_mtime_ns >= since for k in job.outputs)
    except OSError:
        return False


def _saved_figures(job: CloudJob) -> tuple[dict[str, Any], str | None] | None:
    """Figures of a cloud's saved result (``<stem>_segments.json``): points, segments, unsegmented
    points and, when a ground truth sits beside the cloud, the measures scored against it as
    :func:`segment_cloud` scores a new result; with the message of a ground truth that cannot be
    used. None when the result cannot be read (the cloud then runs again)."""
    try:
        data = json.loads(job.output_path("json").read_text(encoding="utf-8"))
        figures: dict[str, Any] = {"n_points": int(data["n_points"]), "n_segments": len(data["segments"]),
                                   "unsegmented": len(data["unsegmented"])}
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if job.ground_truth is None:
        return figures, None
    from .result import Result  # numpy: only when there is something to score

    try:
        measures, gt_error = _measures(job, Result.from_dict(data))
    except (ValueError, KeyError, TypeError, IndexError, OverflowError):  # a result that is not whole
        return None
    return figures | measures, gt_error


def plan(inputs: Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str], options: SegmentOptions,
         outputs: Sequence[str] = (), *, force: bool = False,
         previous: dict[str, BatchRow] | None = None) -> list[tuple[CloudJob, BatchRow | None]]:
    """The batch's clouds in order, each with its ``skipped`` row when it needs no run.

    ``outputs`` are keys of :data:`OUTPUT_NAMES` besides ``"json"``; ``previous`` maps inputs to
    the rows of an earlier ``summary.csv``, whose ``seconds`` a skipped row keeps. A skipped row's
    counts and measures come from the cloud's saved result, scored again against the ground truth
    beside the cloud (whatever batch wrote that result, and whether or not a summary lists it); a
    saved result that cannot be read is not up to date.
    """
    unknown = set(outputs) - set(OUTPUT_NAMES)
    if unknown:
        raise ValueError(f"unknown outputs {sorted(unknown)} (known: {', '.join(OUTPUT_NAMES)})")
    kinds = tuple(k for k in OUTPUT_NAMES if k in outputs and k != "json") + ("json",)
    out = Path(out_dir).absolute()
    clouds = expand_inputs(inputs)
    _check_stems(clouds, out, kinds)
    planned = []
    for display, path in clouds:
        gt = truth_beside(path)
        job = CloudJob(str(path.absolute()), display, str(out), path.stem, kinds, options,
                       str(gt.absolute()) if gt is not None else None)
        skipped = None
        saved = _saved_figures(job) if not force and _up_to_date(job) else None
        if saved is not None:
            figures, gt_error = saved
            before = (previous or {}).get(display)
            skipped = BatchRow(display, "skipped", seconds=before.seconds if before else None, error=gt_error,
                               outputs=tuple(job.output_path(k).name for k in kinds), **figures)
        planned.append((job, skipped))
    return planned


# --------------------------------------------------------------------------- one cloud (on a worker)


@contextlib.contextmanager
def _user_families(paths: Sequence[str]) -> Iterator[None]:
    """Families defined by ``paths`` registered for one cloud; the registry is restored after,
    so that a worker's next cloud sees only its own batch's families."""
    if not paths:
        yield
        return
    from .cli import _load_family_files
    from .families.base import REGISTRY

    saved = dict(REGISTRY)
    try:
        _load_family_files(paths)
        yield
    finally:
        REGISTRY.clear()
        REGISTRY.update(saved)


def _measures(job: CloudJob, result: Any) -> tuple[dict[str, float], str | None]:
    """Fit4CAD measures of a result against the ground truth beside its cloud (scored by faces,
    as ``houghcad evaluate``), and the message of a ground truth that cannot be used."""
    if job.ground_truth is None:
        return {}, None
    from .evaluate import classification_measures, in_file_rows, read_fit4cad_segments

    try:
        result = in_file_rows(result)  # the truth numbers the file's rows, those left out included
        gt = read_fit4cad_segments(job.ground_truth)
        top = max((int(g.max()) for g in gt if g.size), default=-1)
        if top >= result.n_points:
            raise InputError(f"{Path(job.ground_truth).name}: index {top + 1} (1-based) exceeds the cloud's "
                             f"{result.n_points} points")
    except ValueError as exc:  # InputError is one
        return {}, f"ground truth not used: {exc}"
    m = classification_measures(result.faces(), gt, result.n_points)
    return {k: float(m[k]) for k in MEASURES}, None


def _write_outputs(job: CloudJob, cloud: Any, result: Any) -> tuple[str, ...]:
    """Write the cloud's outputs as ``houghcad segment`` does, the JSON last (atomic writes)."""
    from .cli import _write, _write_views
    from .io import write_fit4cad_primitives, write_json

    views = {k: job.output_path(k) if k in job.outputs else None for k in ("ply", "png", "report")}
    if "fit4cad" in job.outputs:
        _write(job.output_path("fit4cad"), write_fit4cad_primitives, result.faces())
    _write_views(cloud, result, views["ply"], views["png"], views["report"])
    _write(job.output_path("json"), write_json, result.to_dict())
    return tuple(job.output_path(k).name for k in job.outputs)


def load_libraries() -> None:
    """What :func:`segment_cloud` imports, loaded before a cloud starts on a worker (the engine's
    ``setup``): a fresh worker's imports are not charged to its first cloud's time and timeout."""
    from . import cli, evaluate, io, pipeline  # noqa: F401


def segment_cloud(job: CloudJob) -> BatchRow:
    """Segment one cloud and write its outputs (the task run on a worker).

    Bad input and failures of the pipeline give an ``error`` row with a one-line message; an
    ``OSError`` or ``MemoryError`` is raised for Dask to retry the cloud (a file system or a
    neighbour's peak may be to blame).
    """
    from .cli import _run_segmentation
    from .io import read_points

    t0 = time.perf_counter()
    try:
        with _user_families(job.options.family_files):
            cloud = read_points(job.path, **job.options.read_kwargs())
            cloud.source = job.display  # what `houghcad segment DISPLAY` records
            # One process per cloud: the batch spreads the clouds over the cores.
            result = _run_segmentation(cloud, quiet=True, n_jobs=1, **job.options.segment_kwargs())
            written = _write_outputs(job, cloud, result)
        measures, gt_error = _measures(job, result)
    except (OSError, MemoryError):
        raise
    except Exception as exc:  # one bad cloud must not stop the batch
        text = str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
        return error_row(job, text.replace(job.path, job.display), time.perf_counter() - t0)
    return BatchRow(job.display, "ok", n_points=int(result.n_points), n_segments=len(result.segments),
                    unsegmented=len(result.unsegmented), seconds=time.perf_counter() - t0, error=gt_error,
                    outputs=written, **measures)


def error_row(job: CloudJob, message: str, seconds: float | None = None) -> BatchRow:
    """An ``error`` row: one line; 0 on every measure when the cloud has a ground truth."""
    zeros = dict.fromkeys(MEASURES, 0.0) if job.ground_truth is not None else {}
    return BatchRow(job.display, "error", seconds=seconds, error=" ".join(message.split()), **zeros)


# --------------------------------------------------------------------------- the batch


def batch(inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str],
          client: Any = None, *, scheduler: str | None = None, workers: int | None = None, retries: int = 2,
          timeout: float | None = None, force: bool = False, fit4cad: bool = False, ply: bool = False,
          png: bool = False, report: bool = False, progress: BatchProgress | None = None,
          task: Callable[[CloudJob], BatchRow] = segment_cloud, **options: Any) -> list[BatchRow]:
    """Segment many point clouds on a Dask cluster; returns one :class:`BatchRow` per input, in order.

    In a script, call it under ``if __name__ == "__main__":``: the workers of a local cluster run
    the main script again (``multiprocessing``'s spawn) before they start, and a call outside the
    guard raises InputError there (the batch then fails with that one message).

    Parameters
    ----------
    inputs : path or sequence of paths
        Point-cloud files, folders (the clouds directly inside) and glob patterns.
    out_dir : path
        Output folder (created): the clouds' outputs, ``summary.csv`` and ``index.html``.
    client : distributed.Client, optional
        Run on this client's cluster (left open). Otherwise ``scheduler`` or a local cluster of
        ``workers`` single-threaded processes (default: one per core), stopped at the end.
    retries : int
        Extra attempts for a cloud whose worker died (local cluster) or that raised an OSError.
    timeout : float, optional
        Seconds one cloud may run on its worker, measured there from the moment the cloud starts
        (reading, segmenting, writing, scoring; time queued for a free worker does not count).
        A cloud still running past it is stopped within about 0.1 s (its worker restarts) and
        a cloud that returns having run longer is an ``error`` row as well (its outputs are
        removed, so that a re-run runs it again): an ``ok`` row always ran within the limit.
    force : bool
        Run every cloud, even those whose outputs are newer than the input.
    fit4cad, ply, png, report : bool
        Also write these outputs of each cloud (file names: :data:`OUTPUT_NAMES`).
    progress : BatchProgress, optional
        Told when the batch begins, and when each cloud starts and ends.
    task : callable
        The function run per cloud (``CloudJob -> BatchRow``), importable by the workers.
    **options
        Options of :func:`houghcad.segment`: ``families`` (a string), ``epsilon``, ``seed``,
        ``normals_method``, ``noise``, ``persistence``, ``min_points``, ``tolerances``
        (``{"stage.name": value}``, ``{"stage": {"name": value}}`` or a Tolerances), ``merge``,
        ``max_points``, ``full_resolution``, ``scan``, ``drop_invalid``, and ``family_files``
        (paths of files calling :func:`houghcad.define_family`); checked as Segmenter checks them.

    Raises
    ------
    InputError
        Before any cloud runs: an input names nothing, two inputs share a stem, a bad or unknown
        option, an unusable ``out_dir``, a call from a worker importing the main script.
    """
    from . import batchcheck, batchreport

    batchcheck.refuse_in_a_worker()  # first: a worker importing an unguarded script must not go on
    batchcheck.check_timeout(timeout)
    opts = batchcheck.segment_options(options)
    outputs = [k for k, on in (("fit4cad", fit4cad), ("ply", ply), ("png", png), ("report", report)) if on]
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: cannot write outputs (not a folder)")
    planned = plan([inputs] if isinstance(inputs, (str, os.PathLike)) else inputs, out, opts, outputs,
                   force=force, previous=batchreport.read_summary(out))
    rows: dict[int, BatchRow] = {i: row for i, (_, row) in enumerate(planned) if row is not None}
    todo = [i for i, (_, row) in enumerate(planned) if row is None]
    if not todo:  # nothing to run: no cluster to start
        batchreport.make_out_dir(out)
        if progress is not None:
            progress.begin(len(planned), list(rows.values()), None)
        batchreport.write_summary(out, [rows[i] for i in range(len(planned))], outputs)
        return [rows[i] for i in range(len(planned))]
    with _engine(client, scheduler, workers, retries, timeout) as engine:
        batchreport.make_out_dir(out)  # now: a batch refused or unable to start leaves nothing behind
        if progress is not None:
            progress.begin(len(planned), list(rows.values()), engine.dashboard_link)
        try:
            engine.run(task, [planned[i][0] for i in todo], setup=load_libraries,
                       on_event=lambda k, ev: _started(progress, planned[todo[k]][0], ev),
                       on_outcome=lambda o: _finished(progress, rows, todo[o.index], planned[todo[o.index]][0], o))
        finally:  # also when interrupted: the summary of the clouds finished so far
            done = [rows[i] for i in range(len(planned)) if i in rows]
            batchreport.write_summary(out, done, outputs)
    return done


@contextlib.contextmanager
def _engine(client: Any, scheduler: str | None, workers: int | None, retries: int,
            timeout: float | None) -> Iterator[Any]:
    """The started engine; a scheduler that cannot be reached is an InputError."""
    from .batchcheck import UNGUARDED, watching_workers
    from .engine import Engine

    engine = Engine(client, scheduler=scheduler, workers=workers, retries=retries, timeout=timeout)
    with watching_workers() as unguarded:
        try:
            engine.__enter__()
        except Exception as exc:
            if unguarded():  # the workers failed to start because the script runs batch() unguarded
                raise InputError(UNGUARDED) from None
            if not isinstance(exc, (OSError, TimeoutError, ValueError)):  # ValueError: an address Dask cannot parse
                raise
            raise InputError(f"{scheduler or 'local cluster'}: cannot start the batch ({exc})") from None
    try:
        yield engine
    finally:
        engine.__exit__(None, None, None)


def _started(progress: BatchProgress | None, job: CloudJob, event: dict[str, Any]) -> None:
    if progress is not None and event.get("kind") == "start":
        progress.started(job.display)


def _finished(progress: BatchProgress | None, rows: dict[int, BatchRow], i: int, job: CloudJob, outcome: Any) -> None:
    if outcome.status == "done":
        row = outcome.value
        row.peak_mb = outcome.peak_mb
    else:
        if outcome.status == "timeout" and isinstance(outcome.value, BatchRow):
            # It returned, past its time, having written its outputs: an error row leaves none
            # (the next run runs it again instead of skipping it).
            for name in outcome.value.outputs:
                with contextlib.suppress(OSError):
                    os.unlink(Path(job.out_dir) / name)
        row = error_row(job, outcome.error or outcome.status, outcome.seconds)
    rows[i] = row
    if progress is not None:
        progress.finished(row)
