"""PLY reader [``ply``]: ascii or binary (either endianness), normals from ``nx ny nz``.

The vertex element's ``x, y, z`` (any case) are the points; ``nx, ny, nz`` or
``normal_x, normal_y, normal_z`` the normals when present and numeric; its other
numeric scalar properties are kept as the cloud's ``fields``.
"""

from __future__ import annotations

import io

import numpy as np

from ..errors import InputError
from .common import Parsed


def is_ply(head: bytes, ext: str) -> bool:
    """PLY magic: the file starts with the line ``ply``."""
    return head.startswith(b"ply") and head[3:4] in (b"\n", b"\r")


def read_ply(data: bytes, source: str) -> Parsed:
    """PLY via plyfile; the vertex element's x, y, z (and nx, ny, nz)."""
    from plyfile import PlyData

    try:
        ply = PlyData.read(io.BytesIO(data))
    except Exception as exc:  # plyfile raises assorted types on malformed files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"{source}: cannot parse PLY file ({msg})") from None
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
        points = np.column_stack([arr[props[k]] for k in "xyz"]).astype(np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{source}: PLY x, y, z properties are not numeric") from None
    normals = None
    used = {"x", "y", "z"}
    for names in (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z")):
        if all(n in props for n in names):
            try:
                normals = np.column_stack([arr[props[n]] for n in names]).astype(np.float64)
                used |= set(names)
            except (TypeError, ValueError):
                normals = None
            break
    # The vertex's other scalar properties (intensity, colour ...) go through to the outputs.
    fields = {props[k]: np.asarray(arr[props[k]]) for k in props
              if k not in used and np.asarray(arr[props[k]]).dtype.kind in "iufb"}
    return points, normals, fields
