"""scikit-learn's estimator API for :class:`houghcad.pipeline.Segmenter`: parameters by name,
``set_params``, and a repr of the arguments that differ from their defaults.

Written here rather than inherited from ``sklearn.base.BaseEstimator``: importing scikit-learn
costs a run about 0.3 s of start-up, and these three methods are all the API asks of us
(``sklearn.base.clone`` works with them).
"""

from __future__ import annotations

import inspect
from typing import Any

from .errors import InputError


class ParamsMixin:
    """``get_params``, ``set_params`` and ``__repr__`` from the constructor's signature; the
    arguments must be stored under their own names, as scikit-learn requires."""

    @classmethod
    def _param_defaults(cls) -> dict[str, Any]:
        return {n: p.default for n, p in inspect.signature(cls.__init__).parameters.items() if n != "self"}

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor's arguments by name (``deep`` is accepted for scikit-learn's API:
        no parameter is itself an estimator)."""
        return {name: getattr(self, name) for name in self._param_defaults()}

    def set_params(self, **params: Any) -> "ParamsMixin":
        """Set constructor arguments by name; an unknown name is an error."""
        known = self._param_defaults()
        for name, value in params.items():
            if name not in known:
                raise InputError(f"{type(self).__name__} has no parameter {name!r} "
                                 f"(parameters: {', '.join(known)})")
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        """The arguments that differ from their defaults, as scikit-learn prints an estimator."""
        defaults = self._param_defaults()
        changed = [f"{n}={v!r}" for n, v in self.get_params().items() if not _same_value(v, defaults[n])]
        return f"{type(self).__name__}({', '.join(changed)})"


def _same_value(a: Any, b: Any) -> bool:
    """Whether an argument equals its default (a value that does not compare plainly differs)."""
    try:
        return bool(a is b or a == b)
    except (TypeError, ValueError):
        return False
