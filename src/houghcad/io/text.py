"""Text readers: tables [``xyz``, ``txt``, ``csv``, ``pts``, ``asc``] and Fit4CAD [``fit4cad``].

Tables: whitespace, comma or semicolon separated, optional header line(s) of
column names (``x y z nx ny nz``, ``X,Y,Z,Nx,Ny,Nz``, ``normal_x`` ...,
case-insensitive, a leading ``#`` or ``//`` is allowed), an optional lone
integer count line (PTS). Columns beyond x, y, z are ignored unless a header
names them as normals. Without a header only the first three columns are
used: six numeric columns are *not* assumed to be normals, because many
exporters write colours or intensities there instead.

Fit4CAD: ``Points:=[`` then ``[x, y, z],`` lines, closing ``];``.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import InputError
from .common import SNIFF_BYTES, Parsed, decode_text, is_float, text_start

_FIT4CAD_PREFIX = "Points:=["

# Normalised header names (lowercase, alphanumerics only) -> coordinate slot.
_XYZ_NAMES = ({"x", "px", "posx", "pointx"}, {"y", "py", "posy", "pointy"}, {"z", "pz", "posz", "pointz"})
_NORMAL_NAMES = (
    {"nx", "normalx", "normx", "nrmx"},
    {"ny", "normaly", "normy", "nrmy"},
    {"nz", "normalz", "normz", "nrmz"},
)
_BRACKETS_TO_SPACE = str.maketrans("[],", "   ")


def is_fit4cad(head: bytes, ext: str) -> bool:
    """Fit4CAD signature: the text starts with ``Points:=[`` (whatever the extension)."""
    return text_start(head).startswith(_FIT4CAD_PREFIX.encode())


def looks_like_table(data: bytes) -> bool:
    """A text whose start is a numeric table (see :func:`_looks_like_numeric_table`)."""
    head = data[:SNIFF_BYTES]
    return b"\0" not in head and _looks_like_numeric_table(head.decode("utf-8", "replace"))


def _split_row(line: str, delimiter: str | None) -> list[str]:
    """Tokens of one table row (``delimiter`` None = whitespace)."""
    if delimiter is None:
        return line.split()
    return [t.strip() for t in line.split(delimiter)]


def _guess_delimiter(line: str) -> str | None:
    """The row's delimiter: comma, else semicolon, else None (whitespace)."""
    if "," in line:
        return ","
    if ";" in line:
        return ";"
    return None


def _strip_comment_marker(line: str) -> str:
    """The line without a leading ``//`` or ``#`` (header names may be commented out)."""
    s = line.strip()
    for marker in ("//", "#"):
        if s.startswith(marker):
            return s[len(marker):].strip()
    return s


def _looks_like_numeric_table(text: str) -> bool:
    """True when, after at most a few name-only header lines, a row of >= 3 numbers follows."""
    header_lines = 0
    for line in text.splitlines()[:50]:
        s = line.strip()
        if not s or s.startswith(("#", "//")):
            continue
        tokens = [t for t in _split_row(s, _guess_delimiter(s)) if t]
        if len(tokens) == 1 and tokens[0].isdigit():
            continue  # PTS count line
        numeric = [is_float(t) for t in tokens]
        if not any(numeric) and header_lines < 3:
            header_lines += 1
            continue
        return len(tokens) >= 3 and all(numeric)
    return False


def _header_columns(tokens: list[str]) -> tuple[list[int] | None, list[int] | None]:
    """Column indices of (x, y, z) and (nx, ny, nz) named in a header row."""
    norm = [re.sub(r"[^0-9a-z]", "", t.lower()) for t in tokens]

    def find(groups: tuple[set[str], ...]) -> list[int] | None:
        cols = []
        for names in groups:
            hits = [i for i, t in enumerate(norm) if t in names]
            if not hits:
                return None
            cols.append(hits[0])
        return cols

    return find(_XYZ_NAMES), find(_NORMAL_NAMES)


def _first_table_error(lines: list[str], start: int, delimiter: str | None, usecols: list[int], source: str) -> InputError:
    """Locate the first bad row of a table (slow path, only after a failure)."""
    need = max(usecols) + 1
    for lineno in range(start, len(lines)):
        s = lines[lineno].split("#", 1)[0].strip()
        if not s:
            continue
        tokens = _split_row(s, delimiter)
        if len(tokens) < need:
            return InputError(f"{source}: line {lineno + 1} has {len(tokens)} columns, expected at least {need}")
        for c in usecols:
            if not is_float(tokens[c]):
                return InputError(f"{source}: non-numeric value {tokens[c][:40]!r} on line {lineno + 1}")
    return InputError(f"{source}: cannot parse the numeric table")


def _table_from_lines(
    lines: list[str], start: int, delimiter: str | None, usecols: list[int], source: str
) -> np.ndarray:
    """Parse ``lines[start:]`` to a (rows, len(usecols)) float64 array."""
    try:
        arr = np.loadtxt(
            lines[start:], delimiter=delimiter, usecols=usecols, ndmin=2, dtype=np.float64, comments="#"
        )
    except ValueError:
        raise _first_table_error(lines, start, delimiter, usecols, source) from None
    return arr


def read_table(data: bytes, source: str) -> Parsed:
    """XYZ / TXT / CSV / PTS / ASC table with optional header and count lines."""
    text = decode_text(data, source)
    if text.lstrip().startswith(_FIT4CAD_PREFIX):
        return read_fit4cad(data, source)
    lines = text.splitlines()
    header: list[str] | None = None
    start = None
    for i, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        body = _strip_comment_marker(s)
        tokens = [t for t in _split_row(body, _guess_delimiter(body)) if t]
        if not tokens:
            continue
        numeric = [is_float(t) for t in tokens]
        if all(numeric) and not s.startswith(("#", "//")):
            if len(tokens) == 1 and tokens[0].isdigit():
                continue  # PTS point-count line
            start = i
            break
        if any(numeric) and not s.startswith(("#", "//")):
            bad = tokens[numeric.index(False)]
            raise InputError(f"{source}: non-numeric value {bad[:40]!r} on line {i + 1}")
        header = tokens  # names (or a comment); the last one before the data wins
    if start is None:
        raise InputError(f"{source}: no numeric point data found")

    delimiter = _guess_delimiter(lines[start])
    xyz_cols, normal_cols = _header_columns(header) if header else (None, None)
    # Without named columns only x, y, z are read (see module docstring).
    xyz_cols = xyz_cols or [0, 1, 2]
    usecols = xyz_cols + (normal_cols or [])
    arr = _table_from_lines(lines, start, delimiter, usecols, source)
    normals = arr[:, 3:6] if normal_cols else None
    return arr[:, :3], normals


def read_fit4cad(data: bytes, source: str) -> Parsed:
    """Fit4CAD ``Points:=[ [x, y, z], ... ];`` text, parsed in one vectorised pass."""
    text = decode_text(data, source).lstrip()
    if not text.startswith(_FIT4CAD_PREFIX):
        raise InputError(f"{source}: not a Fit4CAD point file (expected it to start with {_FIT4CAD_PREFIX!r})")
    close = re.search(r"\]\s*;", text)
    if close is None:
        raise InputError(f"{source}: Fit4CAD point list is not closed with '];'")
    body = text[len(_FIT4CAD_PREFIX):close.start()]
    tokens = body.translate(_BRACKETS_TO_SPACE).split()
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        raise _first_fit4cad_error(text, source) from None
    if values.size % 3:
        raise _first_fit4cad_error(text, source)
    return values.reshape(-1, 3), None


def _first_fit4cad_error(text: str, source: str) -> InputError:
    """Find the first malformed Fit4CAD line (slow path)."""
    lines = text.splitlines()
    for lineno, line in enumerate(lines[1:], start=2):
        s = line.strip()
        if not s or re.fullmatch(r"\]\s*;", s):
            continue
        tokens = s.translate(_BRACKETS_TO_SPACE).replace(";", " ").split()
        for t in tokens:
            if not is_float(t):
                return InputError(f"{source}: non-numeric value {t[:40]!r} on line {lineno}")
        if len(tokens) != 3:
            return InputError(f"{source}: line {lineno} has {len(tokens)} values, expected 3")
    return InputError(f"{source}: malformed Fit4CAD point list")
