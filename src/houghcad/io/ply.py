"""PLY reader [``ply``]: ascii or binary (either endianness), normals from ``nx ny nz``.

The vertex element's ``x, y, z`` (any case) are the points; ``nx, ny, nz`` or
``normal_x, normal_y, normal_z`` the normals when present and numeric; its other
numeric scalar properties are kept as the cloud's ``fields``.
"""

from __future__ import annotations

import io
import mmap
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError
from .common import Parsed, count_text, one_line, pick_normals


def is_ply(head: bytes, ext: str) -> bool:
    """PLY magic: the file starts with the line ``ply``."""
    return head.startswith(b"ply") and head[3:4] in (b"\n", b"\r")


def _check_counts(ply_data: type, data: bytes, source: str, size: int | None = None) -> None:
    """Fail fast when the header announces more rows than the body can hold.

    plyfile allocates the announced rows before reading them and loops over them one by one in
    binary files, so ``element vertex 1000000000000`` would allocate terabytes, and an element
    without properties would loop (nearly) forever on a few bytes. Every ascii row takes at
    least a line, every binary row at least its fixed-size properties and list lengths (and is
    counted as one byte when it has none). ``size``: the whole file's size in bytes when ``data``
    holds only its header.
    """
    from plyfile import PlyListProperty

    parse_header = getattr(ply_data, "_parse_header", None)  # plyfile's own header parser
    if parse_header is None:
        return
    stream = io.BytesIO(data)
    header = parse_header(stream)  # raises on a malformed header (reported by the caller)
    if size is not None:
        room, unit = size - stream.tell(), "bytes"  # binary: the mapped reader reads no ascii
    elif header.text:
        body = data[stream.tell():]
        room, unit = body.count(b"\n") + body.count(b"\r") + 1, "lines"
    else:
        room, unit = len(data) - stream.tell(), "bytes"
    needed = 0
    for element in header.elements:
        if element.count < 0:
            raise InputError(f"{source}: PLY element {element.name[:40]!r} has a negative count "
                             f"({count_text(element.count)})")
        if header.text:
            row = 1
        else:
            row = sum(np.dtype(p.list_dtype()[0] if isinstance(p, PlyListProperty) else p.dtype()).itemsize
                      for p in element.properties)
        needed += element.count * max(1, row)
        if needed > room:
            raise InputError(f"{source}: PLY header announces {count_text(element.count)} "
                             f"{element.name[:40]!r} elements, "
                             f"more than the file's {room} {unit} of data can hold")


def read_ply(data: bytes, source: str) -> Parsed:
    """PLY via plyfile; the vertex element's x, y, z (and nx, ny, nz)."""
    from plyfile import PlyData

    try:
        _check_counts(PlyData, data, source)
        with warnings.catch_warnings():  # e.g. numpy's "input contained no data" on an empty ascii list
            warnings.simplefilter("ignore")
            ply = PlyData.read(io.BytesIO(data))
    except InputError:
        raise
    except Exception as exc:  # plyfile raises assorted types on malformed files
        raise InputError(f"{source}: cannot parse PLY file ({one_line(exc)})") from None
    return _vertices(ply, source)


def read_ply_mapped(path: Path, source: str) -> Parsed | None:
    """A binary PLY file through a read-only memory map; None for ascii files and files that are
    not PLY (the caller reads their bytes).

    From bytes in memory plyfile parses a binary body row by row in Python (10 s for a million
    points); from a mapped file it views the rows as one array, and the body is not copied into
    memory first.
    """
    from plyfile import PlyData

    try:
        with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            if not is_ply(mm[:8], ""):
                return None
            end = mm.find(b"end_header", 0, 1 << 20)
            stop = mm.find(b"\n", end) if end >= 0 else -1
            header, size = mm[:stop + 1] if stop >= 0 else mm[:1 << 20], len(mm)
    except (OSError, ValueError):  # ValueError: an empty file cannot be mapped
        return None  # the bytes reader reports it
    if b"format ascii" in header:
        return None
    try:
        _check_counts(PlyData, header, source, size=size)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ply = PlyData.read(str(path), mmap="r")  # read-only: the input is never modified
    except InputError:
        raise
    except Exception as exc:  # plyfile raises assorted types on malformed files
        raise InputError(f"{source}: cannot parse PLY file ({one_line(exc)})") from None
    return _vertices(ply, source)


def _vertices(ply, source: str) -> Parsed:
    """Points (n, 3) float64, normals and the other numeric scalar fields (copies) of a parsed
    PLY's vertex element."""
    elements = {el.name: el for el in ply.elements}
    vertex = elements.get("vertex")
    if vertex is None:
        raise InputError(f"{source}: PLY file has no 'vertex' element")
    props = {p.name.lower(): p.name for p in vertex.properties}
    if not all(k in props for k in "xyz"):
        raise InputError(f"{source}: PLY vertex element lacks x, y, z properties")
    if vertex.count == 0:
        raise InputError(f"{source}: no points")
    arr = vertex.data
    try:
        points = np.column_stack([arr[props[k]] for k in "xyz"]).astype(np.float64, copy=False)
    except (TypeError, ValueError):
        raise InputError(f"{source}: PLY x, y, z properties are not numeric") from None
    normals, names = pick_normals({k: arr[v] for k, v in props.items()})
    used = {"x", "y", "z", *names}
    # The vertex's other scalar properties (intensity, colour ...) go through to the outputs.
    fields = {props[k]: np.array(arr[props[k]]) for k in props
              if k not in used and np.asarray(arr[props[k]]).dtype.kind in "iufb"}
    return points, normals, fields
