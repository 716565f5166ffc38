"""houghcad: recognise geometric primitives in 3-D point clouds with Hough transforms."""

from __future__ import annotations

from .errors import InputError

# Imported now (standard library only, cheap) so that the name ``houghcad.batch`` is the
# function: the submodule of that name stays reachable by ``from houghcad.batch import ...``.
from .batch import BatchRow, batch

__version__ = "0.1.0"

__all__ = ["InputError", "Result", "Segment", "segment", "Segmenter", "read_points", "define_family", "Tolerances",
           "batch", "BatchRow", "__version__"]


def __getattr__(name: str):
    # Lazy: importing the package must stay cheap, numpy's import included (0.15 s): the
    # ``houghcad`` command catches a Ctrl-C only once the package is imported.
    if name in ("Result", "Segment"):
        from . import result

        return getattr(result, name)
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
    if name in _SUBMODULES:  # ``import houghcad; houghcad.evaluate.…`` as the README writes it
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: Submodules reachable as attributes of the package after a plain ``import houghcad``.
_SUBMODULES = ("evaluate", "synth", "io", "families", "pipeline", "render", "htmlreport", "report", "result",
               "tolerances", "palette", "errors")
