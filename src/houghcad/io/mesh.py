"""Mesh readers: the vertices of OBJ [``obj``], OFF [``off``] and STL [``stl``] files.

- OBJ: ``v`` lines; ``vn`` normals only when there is one per vertex;
- OFF: the vertices (``NOFF`` normals are used), ascii only;
- STL, ascii or binary: the distinct triangle vertices, in order of first appearance.

Faces are ignored: the vertices are the point cloud.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import InputError
from .common import SNIFF_BYTES, Parsed, count_text, decode_text, first_word, is_float

_OFF_KEYWORD = re.compile(r"(ST)?C?N?OFF")
_OBJ_KEYWORDS = frozenset({"v", "vn", "vt", "vp", "f", "l", "p", "o", "g", "s", "mtllib", "usemtl"})
_OBJ_V = re.compile(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.M)
_OBJ_VN = re.compile(r"^[ \t]*vn[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.M)
_OBJ_ANY_V = re.compile(r"^[ \t]*v[ \t]", re.M)
_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
_STL_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", re.I)


# --------------------------------------------------------------------------- content tests


def is_off(head: bytes, ext: str) -> bool:
    """OFF signature: the first word is ``OFF`` (``COFF``, ``NOFF``, ``STOFF`` ...).

    Not for ``.stl`` files: a binary STL's 80-byte header is free text and may start with it.
    """
    return ext != ".stl" and _OFF_KEYWORD.fullmatch(first_word(head)) is not None


def looks_like_stl(data: bytes) -> bool:
    """A binary STL of consistent size, or ascii text starting ``solid`` with a ``facet``."""
    head = data[:SNIFF_BYTES]
    return _is_binary_stl(data) or (first_word(head) == "solid" and b"facet" in head)


def looks_like_obj(data: bytes) -> bool:
    """Text whose first statement is an OBJ keyword, with a ``v`` line."""
    head = data[:SNIFF_BYTES]
    return b"\0" not in head and _looks_like_obj(head.decode("utf-8", "replace"))


# --------------------------------------------------------------------------- readers


def _looks_like_obj(text: str) -> bool:
    """True when the first statement is an OBJ keyword and some ``v`` line exists."""
    for line in text.splitlines()[:50]:
        tokens = line.split("#", 1)[0].split()
        if tokens:
            return tokens[0] in _OBJ_KEYWORDS and _OBJ_ANY_V.search(text) is not None
    return False


def read_obj(data: bytes, source: str) -> Parsed:
    """Wavefront OBJ vertices (``v``); ``vn`` normals if one per vertex."""
    text = decode_text(data, source)
    rows = _OBJ_V.findall(text)
    if len(rows) != len(_OBJ_ANY_V.findall(text)):
        raise _first_obj_error(text, source)
    if not rows:
        raise InputError(f"{source}: no 'v' vertex lines found")
    try:
        points = np.array(rows, dtype=np.float64)
    except ValueError:
        raise _first_obj_error(text, source) from None
    normals = None
    nrows = _OBJ_VN.findall(text)
    if len(nrows) == len(rows):
        try:
            normals = np.array(nrows, dtype=np.float64)
        except ValueError:
            normals = None  # bad normals are dropped, not fatal
    return points, normals


def _first_obj_error(text: str, source: str) -> InputError:
    """Locate the first malformed ``v`` line (slow path, only after a failure)."""
    for lineno, line in enumerate(text.splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if not tokens or tokens[0] != "v":
            continue
        if len(tokens) < 4:
            return InputError(f"{source}: vertex on line {lineno} has {len(tokens) - 1} coordinates, expected 3")
        for t in tokens[1:4]:
            if not is_float(t):
                return InputError(f"{source}: non-numeric value {t[:40]!r} on line {lineno}")
    return InputError(f"{source}: malformed OBJ vertex lines")


def read_off(data: bytes, source: str) -> Parsed:
    """OFF / COFF / NOFF / CNOFF vertices (ascii only)."""
    text = decode_text(data, source)
    lines = text.splitlines()
    # (line number, content) of non-blank lines with comments removed
    content = [(i, s) for i, s in ((i, l.split("#", 1)[0].strip()) for i, l in enumerate(lines)) if s]
    if not content:
        raise InputError(f"{source}: file is empty")
    first = content[0][1].split()
    keyword = first[0]
    if not _OFF_KEYWORD.fullmatch(keyword):
        raise InputError(f"{source}: not an OFF file (first keyword {keyword[:20]!r})")
    if "BINARY" in (t.upper() for t in first[1:]):
        raise InputError(f"{source}: binary OFF files are not supported")
    # Counts may follow the keyword on the same line ("OFF 8 6 0") or sit on the next one.
    if len(first) > 1:
        counts, k = first[1:], 1
    else:
        counts, k = (content[1][1].split() if len(content) > 1 else []), 2
    try:
        n_vertices = int(counts[0])
    except (IndexError, ValueError):
        raise InputError(f"{source}: OFF header lacks the vertex count") from None
    if n_vertices <= 0:
        raise InputError(f"{source}: no points")
    vertex_rows = content[k:k + n_vertices]
    if len(vertex_rows) < n_vertices:
        raise InputError(f"{source}: OFF header announces {count_text(n_vertices)} vertices, "
                         f"file has {len(vertex_rows)}")
    has_normals = "N" in keyword.replace("OFF", "")
    rows = [s for _, s in vertex_rows]
    usecols = [0, 1, 2, 3, 4, 5] if has_normals else [0, 1, 2]
    try:
        arr = np.loadtxt(rows, usecols=usecols, ndmin=2, dtype=np.float64)
    except ValueError:
        # Re-run the slow check against the real line numbers.
        for (lineno, s) in vertex_rows:
            tokens = s.split()
            if len(tokens) < len(usecols):
                raise InputError(
                    f"{source}: vertex on line {lineno + 1} has {len(tokens)} values, expected {len(usecols)}"
                ) from None
            for c in usecols:
                if not is_float(tokens[c]):
                    raise InputError(f"{source}: non-numeric value {tokens[c][:40]!r} on line {lineno + 1}") from None
        raise InputError(f"{source}: cannot parse OFF vertices") from None
    return arr[:, :3], (arr[:, 3:6] if has_normals else None)


def _is_binary_stl(data: bytes) -> bool:
    """Binary STL: 80-byte header, uint32 count, 50 bytes per triangle, exactly."""
    if len(data) < 84:
        return False
    n = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
    return len(data) == 84 + 50 * n


def read_stl(data: bytes, source: str) -> Parsed:
    """STL triangle vertices, deduplicated, in order of first appearance."""
    if _is_binary_stl(data):
        n = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        rec = np.frombuffer(data, dtype=_STL_RECORD, count=n, offset=84)
        vertices = rec["vertices"].reshape(-1, 3).astype(np.float64)
    elif data.lstrip()[:5].lower() == b"solid":
        rows = _STL_VERTEX.findall(data)
        try:
            vertices = np.array(rows, dtype=np.float64).reshape(-1, 3)
        except ValueError:
            bad = next(t for r in rows for t in r if not is_float(t.decode("ascii", "replace")))
            raise InputError(f"{source}: non-numeric vertex value {bad[:40].decode('ascii', 'replace')!r}") from None
    else:
        raise InputError(f"{source}: not a valid STL file (neither 'solid' ascii nor a consistent binary size)")
    if vertices.shape[0] == 0:
        raise InputError(f"{source}: STL file has no triangles")
    # +0.0 folds -0.0 into 0.0 so both spellings count as one vertex
    _, first = np.unique(vertices + 0.0, axis=0, return_index=True)
    return vertices[np.sort(first)], None
