"""NumPy ``.npy`` reader [``npy``].

``(N, 3)`` points or ``(N, 6)`` points + normals (other widths ``>= 3``: first
three columns only), or a structured array with ``x, y, z`` (and optionally
``nx, ny, nz``) fields. Never unpickles.
"""

from __future__ import annotations

import io

import numpy as np

from ..errors import InputError
from .common import Parsed

_NPY_MAGIC = b"\x93NUMPY"


def is_npy(head: bytes, ext: str) -> bool:
    """NPY magic: ``\\x93NUMPY``."""
    return head.startswith(_NPY_MAGIC)


def read_npy(data: bytes, source: str) -> Parsed:
    """NumPy ``.npy``: (N, 3), (N, 6) or structured x, y, z[, nx, ny, nz]."""
    try:
        arr = np.load(io.BytesIO(data), allow_pickle=False)
    except ValueError as exc:
        msg = str(exc).splitlines()[0]
        raise InputError(f"{source}: cannot read .npy file ({msg})") from None
    except Exception as exc:  # truncated/corrupt headers raise assorted types
        raise InputError(f"{source}: cannot read .npy file ({type(exc).__name__})") from None
    if arr.dtype.names:
        fields = {n.lower(): n for n in arr.dtype.names}
        if not all(k in fields for k in "xyz"):
            raise InputError(f"{source}: structured array lacks x, y, z fields")
        flat = arr.reshape(-1)
        points = np.column_stack([flat[fields[k]] for k in "xyz"])
        normals = None
        if all(k in fields for k in ("nx", "ny", "nz")):
            normals = np.column_stack([flat[fields[k]] for k in ("nx", "ny", "nz")])
        return points, normals
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{source}: non-numeric array (dtype {arr.dtype})")
    if arr.size == 0:
        raise InputError(f"{source}: no points")
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise InputError(f"{source}: expected an (N, 3) or (N, 6) array, got shape {arr.shape}")
    normals = arr[:, 3:6] if arr.shape[1] == 6 else None
    return arr[:, :3], normals
