"""houghcad: recognise geometric primitives in 3-D point clouds with Hough transforms."""

from __future__ import annotations

from .errors import InputError
from .result import Result, Segment

# Imported now (standard library only, cheap) so that the name ``houghcad.batch`` is the
# function: the submodule of that name stays reachable by ``from houghcad.batch import ...``.
from .batch import BatchRow, batch

__version__ = "0.1.0"

__all__ = ["InputError", "Result", "Segment", "segment", "Segmenter", "read_points", "define_family", "Tolerances",
           "batch", "BatchRow", "__version__"]


def __getattr__(name: str):
    # Lazy: importing the package must stay cheap (numba compiles on first use).
    if name in ("segment", "Segmenter"):
        from . import pipeline

        return getattr(pipeline, name)
    if name == "define_family":
        from .families import define_family

        return define_family
    if name == "Tolerances":
        from .tolerances import Tolerances

        return Tolerances
    if name == "read_points":
        from .io import read_points

        return read_points
    raise AttributeError(name)
