"""The options that shape a segmentation, shared by ``houghcad segment`` and ``houghcad batch``:
their argument types (a bad value is a one-line usage error), and the keyword arguments of the
reader and the segmentation they give."""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .errors import InputError
from .options import MIN_MAX_POINTS, MIN_SEGMENT


# --------------------------------------------------------------------------- argument types


def _number_in(text: str, hi: float, what: str) -> float:
    """``text`` as a finite number in (0, hi); otherwise an argparse error saying ``what`` it must be."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and 0.0 < value < hi):
        raise argparse.ArgumentTypeError(f"{text} is not {what}")
    return value


def _fraction(text: str) -> float:
    """``--epsilon``: a fraction of the part's bounding-box diagonal in its own frame, 0 < F < 0.5 (as Segmenter)."""
    return _number_in(text, 0.5, "a fraction of the diagonal in (0, 0.5), e.g. 0.01")


def _open_fraction(text: str) -> float:
    """``--persistence``: a number in (0, 1)."""
    return _number_in(text, 1.0, "in (0, 1)")


def path_text(text: str) -> str:
    """A path option: not empty (``-o ""`` silently wrote the default name in the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("empty path")
    return text


def _int_at_least(text: str, least: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < least:
        raise argparse.ArgumentTypeError(f"must be >= {least}, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """``--seed``, ``--retries``, ``--scan``: an integer >= 0 (a seed: numpy's requirement)."""
    return _int_at_least(text, 0)


def positive_int(text: str) -> int:
    """``--jobs``, ``--workers``: an integer >= 1."""
    return _int_at_least(text, 1)


def subsample_size(text: str) -> int:
    """``--max-points``: an integer >= :data:`houghcad.options.MIN_MAX_POINTS`."""
    return _int_at_least(text, MIN_MAX_POINTS)


def segment_size(text: str) -> int:
    """``--min-points``: an integer >= :data:`houghcad.options.MIN_SEGMENT`."""
    return _int_at_least(text, MIN_SEGMENT)


# --------------------------------------------------------------------------- parser


def add_segment_options(p: argparse.ArgumentParser) -> None:
    """The options that shape a result, shared by ``segment`` and ``batch``."""
    p.add_argument("--families", default="simple", metavar="LIST",
                   help="'simple', 'all' or comma-separated names, e.g. plane,cylinder (default: simple)")
    p.add_argument("--family-file", action="append", default=[], metavar="FILE.py", type=path_text,
                   help="run a Python file that defines families with houghcad.define_family before segmenting "
                   "(repeatable; it runs unsandboxed: only files you trust); name them in --families")
    p.add_argument("--epsilon", type=_fraction, default=None, metavar="F",
                   help="distance tolerance as a fraction of the diagonal of the part's bounding box in its own frame "
                        "(its most common face normals as axes: the same in any pose), below 0.5 "
                   "(default: from the point spacing and the estimated noise)")
    p.add_argument("--seed", type=non_negative_int, default=0, metavar="N", help="random seed (default: 0)")
    p.add_argument("--normals", choices=("auto", "pca", "voting"), default="auto",
                   help="normals: 'auto' uses the file's normals if any, else PCA (creases voted on clean clouds, "
                   "up to 64 neighbours on noisy ones); 'pca' and 'voting' always estimate them (default: auto)")
    p.add_argument("--no-merge", action="store_true",
                   help="keep segments lying on one surface apart instead of merging them into one "
                   "maximal primitive (groups are found either way)")
    p.add_argument("--noise", choices=("auto", "clean", "noisy"), default="auto",
                   help="noise policy: 'auto' reads the cloud as noisy when its estimated noise is at least 0.15 "
                   "point spacings; 'clean' and 'noisy' force it (default: auto)")
    p.add_argument("--persistence", type=_open_fraction, default=None, metavar="F",
                   help="peak persistence threshold, a fraction of the accumulator's maximum in (0, 1) (default: 0.1)")
    p.add_argument("--min-points", type=segment_size, default=None, metavar="N",
                   help="smallest segment in points (default: a patch 1.5 %% of the diagonal wide, at least 6, "
                        "8 on noisy clouds)")
    p.add_argument("--tolerance", action="append", default=[], metavar="STAGE.NAME=VALUE",
                   help="set a named tolerance (repeatable), e.g. recognition.keep_share=0.5; "
                   "`python -m houghcad.tolerances` lists them (docs/tolerances.md in the sources)")
    p.add_argument("--max-points", type=subsample_size, default=None, metavar="N",
                   help="clouds with more points are recognised on an even subsample of at most N points, then "
                   "every point is labelled from its subsample neighbours (default: 100000; at least 1000)")
    p.add_argument("--full-resolution", action="store_true",
                   help="recognise on every point, however many (slow and memory-hungry on big scans)")
    p.add_argument("--scan", type=non_negative_int, default=None, metavar="K",
                   help="E57 input: segment scan K only (0-based; default: every scan, merged in the file's frame); "
                   "indices are then the scan's rows (the result's options.input records K)")
    p.add_argument("--drop-invalid", action="store_true",
                   help="leave out points with a NaN or infinite coordinate (scanners mark missing points so) "
                   "instead of refusing the file, say how many, and record their rows in the result's "
                   "options.input.dropped_rows (E57 rows the scanner flags as invalid are left out either way)")


@dataclass(frozen=True)
class SegmentOptions:
    """The options of ``houghcad segment`` that shape a result (see :func:`houghcad.segment`)."""

    families: str = "simple"
    epsilon: float | None = None
    seed: int = 0
    normals_method: str = "auto"
    noise: str = "auto"
    persistence: float | None = None
    min_points: int | None = None
    tolerances: tuple[tuple[str, float], ...] = ()  # ("stage.name", value) pairs
    merge: bool = True
    family_files: tuple[str, ...] = ()  # absolute paths
    scan: int | None = None  # E57 only: the scan to read
    drop_invalid: bool = False  # leave out rows with NaN or inf coordinates
    max_points: int | None = None  # None: the pipeline's default subsample size
    full_resolution: bool = False

    def read_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`houghcad.io.read_points`."""
        return {"scan": self.scan, "drop_invalid": self.drop_invalid}

    def segment_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`houghcad.cli._run_segmentation`, as ``segment`` passes them."""
        kw: dict[str, Any] = {"families": self.families, "epsilon": self.epsilon, "seed": self.seed,
                              "normals_method": self.normals_method, "merge": self.merge, "noise": self.noise}
        if self.persistence is not None:
            kw["persistence"] = self.persistence
        if self.min_points is not None:
            kw["min_points"] = self.min_points
        if self.tolerances:
            kw["tolerances"] = dict(self.tolerances)
        if self.max_points is not None:
            kw["max_points"] = self.max_points
        if self.full_resolution:
            kw["full_resolution"] = True
        return kw


def segment_options(args: argparse.Namespace) -> SegmentOptions:
    """The options of :func:`add_segment_options` as :class:`SegmentOptions` (a bad
    ``--tolerance`` is an InputError; ``--family-file`` is left to the caller)."""
    tolerances = tuple(parse_tolerances(args.tolerance).items()) if args.tolerance else ()
    return SegmentOptions(families=args.families, epsilon=args.epsilon, seed=args.seed, normals_method=args.normals,
                          noise=args.noise, persistence=args.persistence, min_points=args.min_points,
                          tolerances=tolerances, merge=not args.no_merge, scan=args.scan,
                          drop_invalid=args.drop_invalid, max_points=args.max_points,
                          full_resolution=args.full_resolution)


def parse_tolerances(items: Sequence[str]) -> dict[str, float]:
    """``["stage.name=value", ...]`` as ``{"stage.name": value}``, checked
    (a bad one is a one-line InputError before the cloud is read)."""
    from .tolerances import Tolerances

    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        try:
            if not sep:
                raise ValueError("expected STAGE.NAME=VALUE")
            out[name.strip()] = float(text)
            Tolerances.from_dict(out)
        except ValueError as exc:
            raise InputError(f"--tolerance {item}: {exc}") from None
    return out
