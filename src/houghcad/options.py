"""The :class:`~houghcad.pipeline.Segmenter`'s options, checked before a run: a bad one is an
:class:`~houghcad.errors.InputError` that names it, not a failure deep inside the pipeline."""

from __future__ import annotations

from typing import Any

from .errors import InputError
from .noise import NOISE_CHOICES

__all__ = ["MAX_EPSILON", "MIN_MAX_POINTS", "MIN_SEGMENT", "check_options"]

#: ε, as a fraction of the diagonal, must stay below this.
MAX_EPSILON = 0.5
#: The smallest segment a user may ask for: a plane through two points is any plane.
MIN_SEGMENT = 2
#: A subsample smaller than this no longer holds a mechanical part's small faces.
MIN_MAX_POINTS = 1000


def _whole(value: Any) -> bool:
    import numpy as np  # here: the command line imports this module before it can catch a Ctrl-C

    return not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, np.integer))


def check_options(seg: Any) -> None:
    """Raise InputError for the first bad option of the Segmenter ``seg``."""
    import numpy as np  # here: the command line imports this module before it can catch a Ctrl-C

    if seg.epsilon is not None and not (0 < float(seg.epsilon) < MAX_EPSILON):
        raise InputError(f"epsilon must be a fraction of the diagonal in (0, {MAX_EPSILON:g}), got {seg.epsilon}")
    if not (0 < float(seg.persistence) < 1):
        raise InputError(f"persistence must be in (0, 1), got {seg.persistence}")
    if seg.n_jobs is not None and not _whole(seg.n_jobs):
        raise InputError(f"n_jobs must be a whole number or None, got {seg.n_jobs!r}")
    if seg.noise not in NOISE_CHOICES:
        raise InputError(f"noise must be one of {', '.join(NOISE_CHOICES)}, got {seg.noise!r}")
    if seg.min_points is not None and not (_whole(seg.min_points) and seg.min_points >= MIN_SEGMENT):
        raise InputError(f"min_points must be a whole number of at least {MIN_SEGMENT} or None, "
                         f"got {seg.min_points!r}")
    if not (_whole(seg.seed) and seg.seed >= 0):
        raise InputError(f"seed must be a whole number >= 0, got {seg.seed!r}")
    if not isinstance(seg.merge, (bool, np.bool_)):
        raise InputError(f"merge must be True or False, got {seg.merge!r}")
