"""Calls into a user family's own code (its equations, placement and ``valid``).

Whatever that code raises, or returns in a form the family cannot use, stops the run with one
line naming the family and the function: a definition that fails mid-run is bad input (exit 2
on the command line), not a crash of houghcad, and the failure is not left to make the family
silently never found.
"""

from __future__ import annotations

import contextlib
from typing import Any, Iterator

import numpy as np

from ...errors import InputError

#: Longest text of the user's exception quoted (a message may hold a whole array's repr).
MAX_QUOTED = 300
#: Longest repr of a returned value quoted.
MAX_REPR = 60


class UserFamilyError(InputError):
    """A user family's function raised, or returned something it cannot use.

    The message is one line: ``family 'NAME': its FUNCTION raised/returned ...``. The error
    holds nothing but its message, so it pickles: it comes back from the worker processes.
    """


def user_error(family: str, what: str, problem: str) -> UserFamilyError:
    """The error for ``family``'s function ``what`` (e.g. ``"valid(...)"``) and its ``problem``."""
    text = " ".join(problem.split())
    if len(text) > MAX_QUOTED:
        text = text[:MAX_QUOTED] + "..."
    return UserFamilyError(f"family {family!r}: its {what} {text}")


def describe(value: Any) -> str:
    """A returned value in a few words: ``5 (type int)``, ``an array of shape (2,)``."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}"
    text = repr(value)
    return f"{text if len(text) <= MAX_REPR else text[:MAX_REPR] + '...'} (type {type(value).__name__})"


@contextlib.contextmanager
def user_code(family: str, what: str) -> Iterator[None]:
    """Run a call into ``family``'s function ``what``: an exception it raises becomes a
    :class:`UserFamilyError`. A MemoryError stays one (the machine's, not the definition's:
    a batch retries it)."""
    try:
        yield
    except (UserFamilyError, MemoryError):
        raise
    except Exception as exc:
        # Chained, not hidden: in Python the user's traceback shows where their function failed.
        raise user_error(family, what, f"raised {type(exc).__name__}: {exc}") from exc
