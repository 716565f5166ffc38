"""What the format readers of :mod:`houghcad.io` share: the reader signature and text helpers.

A reader is ``read(data, source) -> (points, normals)``, ``(points, normals, fields)`` or
``(points, normals, fields, rows)``: ``data`` the file's bytes, ``source`` its name for error
messages, ``points`` (N, 3) float64 in the file's units, ``normals`` (N, 3) or None, ``fields``
the file's other per-point attributes (intensity, colour ...), name -> (N,) array in the file's
own type (a PLY output writes them back so), and ``rows`` a :class:`Rows` when the points are not
simply the file's rows in order (rows the file flags as holding no point, several scans).
Validation (finite, count, degeneracy) happens afterwards in
:func:`houghcad.io.readers.validate_points`, so readers only parse.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np


from ..errors import InputError

#: (points (N, 3) float64, normals (N, 3) or None[, fields[, rows]]) as a reader returns them.
Parsed = tuple


@dataclass(frozen=True)
class Rows:
    """Where a reader's points come from among the rows of what it read.

    Attributes
    ----------
    flagged : ndarray of bool, shape (R,)
        One per row read (the file's, or the chosen scan's): True where the file itself marks the
        row as holding no point (E57 ``cartesianInvalidState`` / ``sphericalInvalidState``); the
        points are the other rows, in order.
    scans : tuple of int
        The rows of each scan when several were read, merged in this order (empty otherwise).
    """

    flagged: np.ndarray
    scans: tuple[int, ...] = ()

#: ``read(data, source) -> Parsed``.
Reader = Callable[[bytes, str], Parsed]

#: Column names of normals, in order of preference (PLY, LAS extra bytes, PCD).
NORMAL_COLUMNS = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"), ("NormalX", "NormalY", "NormalZ"))

#: Bytes of a file's start that format detection looks at.
SNIFF_BYTES = 4096

#: Longest parser message quoted in an error (the rest is cut).
MAX_DETAIL = 160
#: Digits of a header count quoted in an error.
MAX_COUNT_DIGITS = 24


def count_text(count: int) -> str:
    """A count read from a header, for a message: absurd ones (thousands of digits) stay short."""
    text = str(count)
    if len(text) <= MAX_COUNT_DIGITS:
        return text
    return f"{text[:MAX_COUNT_DIGITS]}... ({len(text)} digits)"


def one_line(exc: BaseException) -> str:
    """A (third-party) exception's message as one short line; its type name when it has none."""
    words = " ".join(str(exc).split())
    if len(words) > MAX_DETAIL:
        return words[:MAX_DETAIL] + " ..."
    return words or type(exc).__name__


def decode_text(data: bytes, source: str) -> str:
    """Bytes to str for the text formats; binary content is an InputError."""
    if b"\0" in data[:SNIFF_BYTES]:
        raise InputError(f"{source}: not a text file (binary content)")
    return data.decode("utf-8-sig", errors="replace")


def is_float(token: str) -> bool:
    """True when ``float(token)`` succeeds."""
    try:
        float(token)
    except ValueError:
        return False
    return True


def text_start(head: bytes) -> bytes:
    """``head`` without a UTF-8 byte-order mark and leading whitespace."""
    return head.lstrip(b"\xef\xbb\xbf").lstrip()


def first_word(head: bytes) -> str:
    """First whitespace-separated word of a file's start (ascii, "" when there is none)."""
    start = text_start(head)
    return start.split(None, 1)[0].decode("ascii", "replace") if start else ""


def pick_normals(columns: Mapping[str, Any]) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """The normals (N, 3) float64 from the first triple of :data:`NORMAL_COLUMNS` that ``columns``
    (name -> (N,) values) holds, and the names used; (None, ()) when there is none or its values
    are not numeric."""
    for names in NORMAL_COLUMNS:
        if all(n in columns for n in names):
            try:
                return np.column_stack([np.asarray(columns[n]) for n in names]).astype(np.float64), names
            except (TypeError, ValueError):
                return None, ()
    return None, ()
