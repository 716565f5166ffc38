"""PCD reader [``pcd``] (Point Cloud Library files: ascii, binary, binary_compressed; via pypcd4).

The fields ``x, y, z`` are the points; ``normal_x, normal_y, normal_z`` (or
``nx, ny, nz``) the normals when present; the other scalar fields (intensity,
rgb ...) are kept as the cloud's ``fields``, each in its declared type (a packed ``F 4`` rgb
stays float32 bit for bit, a ``U 4`` label uint32). Organised clouds mark missing
points with NaN: such rows are refused unless ``read_points(..., drop_invalid=True)``.
"""

from __future__ import annotations

import io

import numpy as np

from ..errors import InputError
from .common import Parsed, one_line, pick_normals


def is_pcd(head: bytes, ext: str) -> bool:
    """A PCD header: comment lines, then ``VERSION`` and ``FIELDS`` lines."""
    lines = [ln.strip() for ln in head.split(b"\n")[:12]]
    lines = [ln for ln in lines if ln and not ln.startswith(b"#")]
    return len(lines) >= 2 and lines[0].startswith(b"VERSION") and lines[1].startswith(b"FIELDS")


def read_pcd(data: bytes, source: str) -> Parsed:
    """PCD via pypcd4: (points, normals or None, fields)."""
    from pypcd4 import PointCloud

    if not is_pcd(data[:4096], ".pcd"):
        raise InputError(f"{source}: not a PCD file (expected VERSION and FIELDS header lines)")
    try:
        with np.errstate(all="ignore"):
            pc = PointCloud.from_fileobj(io.BytesIO(data))
            names = list(pc.fields)
            # The structured rows, each field in its declared type (U4 label, packed F4 rgb):
            # pc.numpy() would stack them all into one float64 table.
            table = np.asarray(pc.pc_data)
    except Exception as exc:  # pypcd4 raises assorted types on malformed files
        raise InputError(f"{source}: cannot parse PCD file ({one_line(exc)})") from None
    if not all(k in names for k in "xyz"):
        raise InputError(f"{source}: PCD file lacks x, y, z fields")
    if table.ndim != 1 or table.dtype.names is None or not set(names) <= set(table.dtype.names):
        raise InputError(f"{source}: PCD fields with several values each are not supported")
    declared = getattr(getattr(pc, "metadata", None), "points", None)
    if isinstance(declared, int) and len(table) < declared:  # pypcd4 reads what an ascii body holds
        raise InputError(f"{source}: truncated PCD file ({len(table)} of the {declared} points its header declares)")
    col = {n: np.ascontiguousarray(table[n]) for n in names}
    if any(v.ndim != 1 for v in col.values()):
        raise InputError(f"{source}: PCD fields with several values each are not supported")
    points = np.column_stack([col[k] for k in "xyz"]).astype(np.float64)
    normals, names = pick_normals(col)
    used = {"x", "y", "z", *names}
    # Each field keeps its own type (a packed float rgb keeps its bits, a uint32 label stays
    # an integer) for the outputs.
    fields = {n: v for n, v in col.items() if n not in used and n.isidentifier() and v.dtype.kind in "iufb"}
    return points, normals, fields
