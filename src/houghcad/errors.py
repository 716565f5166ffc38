"""Exceptions raised for bad input.

The CLI turns :class:`InputError` into a one-line message and exit code 2.
"""


class InputError(ValueError):
    """The input cannot be processed; the message names the file and the problem."""
