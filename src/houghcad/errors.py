"""Exceptions raised for bad input, and warnings about input that degrades the result.

The CLI turns :class:`InputError` into a one-line message and exit code 2, and prints an
:class:`InputWarning` as one ``houghcad: warning:`` line.
"""


class InputError(ValueError):
    """The input cannot be processed; the message names the file and the problem."""


class InputWarning(UserWarning):
    """The input can be processed but limits the result (e.g. coordinates rounded to float32
    coarser than the point spacing); the message says why and what to do."""
