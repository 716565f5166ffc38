"""What :func:`houghcad.batch` checks before it starts a cluster: its options, checked as
``houghcad segment`` and :class:`~houghcad.pipeline.Segmenter` check them (a mistake is one
error, not one ``error`` row per cloud), and that it is not being called by a worker process
that imports the main script.

Dask starts the workers of a local cluster with ``multiprocessing``'s *spawn* method: each one
runs the main script again (as ``__mp_main__``) before it becomes a worker. A script that calls
:func:`houghcad.batch` outside ``if __name__ == "__main__":`` would then start a cluster inside
every worker. :func:`refuse_in_a_worker` stops that call with one :class:`InputError`; the worker
says nothing more when the batch that started it is ours (:func:`watching_workers`), and that
batch fails with the same one line.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import numbers
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import fields
from pathlib import Path
from typing import Any

from .cliopts import SegmentOptions
from .errors import InputError

__all__ = ["UNGUARDED", "check_timeout", "refuse_in_a_worker", "segment_options", "watching_workers"]

UNGUARDED = ("houghcad.batch() was called while a worker process of its local cluster imported the main script "
             "(each worker runs the script again): put the call under `if __name__ == \"__main__\":`")
#: Environment variable naming the file a worker creates when it refused to run a batch.
MARKER = "HOUGHCAD_BATCH_UNGUARDED"
_OPTION_NAMES = {f.name for f in fields(SegmentOptions)}


# --------------------------------------------------------------------------- the main script's guard


def _importing_main() -> bool:
    """This process was started by ``multiprocessing`` and is running its parent's main script to
    set itself up. The flag is multiprocessing's own test (``spawn._check_not_importing_main``):
    ``parent_process()`` is still None at that point, and ``__main__`` not yet renamed."""
    return bool(getattr(multiprocessing.current_process(), "_inheriting", False))


def refuse_in_a_worker() -> None:
    """Raise InputError(:data:`UNGUARDED`) in a worker process that imports the main script."""
    if not _importing_main():
        return
    marker = os.environ.get(MARKER)
    if marker:  # a batch of ours is starting this worker: it fails with this message, once
        with contextlib.suppress(OSError):
            Path(marker).touch()
    previous = sys.excepthook

    def hook(kind: type[BaseException], value: BaseException, tb: Any) -> None:
        # The worker dies of it: one line (none when the parent says it), not the traceback
        # of multiprocessing's start-up machinery.
        if not (isinstance(value, InputError) and value.args == (UNGUARDED,)):
            previous(kind, value, tb)
        elif not marker:
            print(f"houghcad: error: {value}", file=sys.stderr)

    sys.excepthook = hook
    raise InputError(UNGUARDED)


@contextlib.contextmanager
def watching_workers() -> Iterator[Callable[[], bool]]:
    """While a local cluster starts: yields a function telling whether one of its workers
    refused to run a batch while importing the main script (its workers inherit
    :data:`MARKER`, the path of the file such a worker creates)."""
    saved = os.environ.get(MARKER)
    with tempfile.TemporaryDirectory(prefix="houghcad-batch-") as folder:
        marker = os.path.join(folder, "unguarded")
        os.environ[MARKER] = marker
        try:
            yield lambda: os.path.exists(marker)
        finally:
            if saved is None:
                os.environ.pop(MARKER, None)
            else:
                os.environ[MARKER] = saved


# --------------------------------------------------------------------------- options


def check_timeout(timeout: float | None) -> None:
    """``timeout``: None or a positive number of seconds."""
    if timeout is not None and not (isinstance(timeout, numbers.Real) and not isinstance(timeout, bool)
                                    and 0 < timeout < math.inf):
        raise InputError(f"timeout must be a positive number of seconds or None, got {timeout!r}")


def _whole_or_none(name: str, value: Any, least: int) -> None:
    if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least):
        raise InputError(f"{name} must be a whole number of at least {least} or None, got {value!r}")


def _tolerances(given: Any) -> tuple[tuple[str, float], ...]:
    """``{"stage.name": value}``, ``{"stage": {"name": value}}`` or a Tolerances (as Segmenter
    takes them), checked, as the ``("stage.name", value)`` pairs of the values that differ from
    the defaults."""
    from .tolerances import Tolerances

    if given is None:
        return ()
    if not isinstance(given, (Tolerances, dict)):
        raise InputError(f"tolerances must be a Tolerances, a dict or None, got {given!r}")
    try:
        checked = given if isinstance(given, Tolerances) else Tolerances.from_dict(dict(given))
    except (TypeError, ValueError) as exc:
        raise InputError(f"tolerances: {exc}") from None
    return tuple(sorted(checked.changed().items()))


def segment_options(options: dict[str, Any]) -> SegmentOptions:
    """Checked :class:`SegmentOptions` from ``batch``'s keyword options; families (with the
    ``family_files`` that define them) and the Segmenter's options are checked here, in this
    process."""
    from .batch import _user_families
    from .families import select
    from .options import MIN_MAX_POINTS, check_options
    from .pipeline import Segmenter
    from .preprocess import NORMALS_METHODS  # preprocess checks them only once a cloud is read

    unknown = set(options) - _OPTION_NAMES
    if unknown:
        raise InputError(f"batch(): unknown option{'s' if len(unknown) > 1 else ''} {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(_OPTION_NAMES))})")
    options = dict(options)
    given = options.pop("family_files", None) or ()
    given = [given] if isinstance(given, (str, os.PathLike)) else given  # one path, not its letters
    files = tuple(str(Path(p).absolute()) for p in given)
    opts = SegmentOptions(family_files=files, tolerances=_tolerances(options.pop("tolerances", None)), **options)
    if not isinstance(opts.families, str):
        raise InputError(f"families must be a string ('simple', 'all' or comma-separated names), "
                         f"got {opts.families!r}")
    if opts.normals_method not in NORMALS_METHODS:
        raise InputError(f"unknown normals method {opts.normals_method!r} ({', '.join(NORMALS_METHODS)})")
    _whole_or_none("max_points", opts.max_points, MIN_MAX_POINTS)
    _whole_or_none("scan", opts.scan, 0)
    for name in ("drop_invalid", "full_resolution"):
        if not isinstance(getattr(opts, name), bool):
            raise InputError(f"{name} must be True or False, got {getattr(opts, name)!r}")
    for name in ("epsilon", "persistence"):  # check_options reads them with float(): "0.1" would pass
        value = getattr(opts, name)
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise InputError(f"{name} must be a number or None, got {value!r}")
    # The checks a Segmenter makes before a run (epsilon, persistence, noise, min_points, seed, merge).
    check_options(Segmenter(**opts.segment_kwargs()))
    with _user_families(files):
        select(opts.families)
    return opts
