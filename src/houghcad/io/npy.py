"""NumPy ``.npy`` reader [``npy``].

``(N, 3)`` points or ``(N, 6)`` points + normals (other widths ``>= 3``: first
three columns only), or a structured array with ``x, y, z`` (and optionally
``nx, ny, nz``) fields. Never unpickles.
"""

from __future__ import annotations

import io
import math
import warnings

import numpy as np

from ..errors import InputError
from .common import Parsed, one_line

_NPY_MAGIC = b"\x93NUMPY"
#: Characters of an announced shape quoted in an error.
_MAX_SHAPE_TEXT = 60


def is_npy(head: bytes, ext: str) -> bool:
    """NPY magic: ``\\x93NUMPY``."""
    return head.startswith(_NPY_MAGIC)


def _check_size(data: bytes, source: str) -> None:
    """Fail fast when the header announces more data than the file holds.

    ``np.load`` allocates the announced array before reading it: a header claiming a shape of
    ``(10**9, 3)`` would reserve 24 GB for a file of a few hundred bytes. A header that cannot be
    parsed is left to ``np.load`` to report.
    """
    fmt = np.lib.format
    stream = io.BytesIO(data)
    try:
        version = fmt.read_magic(stream)
        read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, _, dtype = read_header(stream)
    except Exception:  # malformed: np.load says why
        return
    if dtype.hasobject:  # refused by np.load (no unpickling)
        return
    needed = math.prod(int(d) for d in shape) * dtype.itemsize
    room = len(data) - stream.tell()
    if needed > room:
        shape_text = str(tuple(int(d) for d in shape))
        if len(shape_text) > _MAX_SHAPE_TEXT:
            shape_text = shape_text[:_MAX_SHAPE_TEXT] + " ...)"
        raise InputError(f"{source}: .npy header announces shape {shape_text} of {dtype.str}, "
                         f"more than the file's {room} bytes of data")


def _field_problem(column: np.ndarray) -> str | None:
    """Why a structured array's field cannot be a coordinate (None when it can)."""
    if column.dtype.kind not in "iuf":
        return f"is not numeric (dtype {column.dtype.str})"
    if column.ndim != 1:
        return f"holds {int(np.prod(column.shape[1:]))} values per point, not one"
    return None


def read_npy(data: bytes, source: str) -> Parsed:
    """NumPy ``.npy``: (N, 3), (N, 6) or structured x, y, z[, nx, ny, nz]."""
    # numpy warns about headers it had to repair (Python 2 files): the data are read all the same.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _check_size(data, source)
        try:
            arr = np.load(io.BytesIO(data), allow_pickle=False)
        except ValueError as exc:
            raise InputError(f"{source}: cannot read .npy file ({one_line(exc)})") from None
        except Exception as exc:  # truncated/corrupt headers raise assorted types
            raise InputError(f"{source}: cannot read .npy file ({type(exc).__name__})") from None
    if arr.dtype.names:
        fields = {n.lower(): n for n in arr.dtype.names}
        if not all(k in fields for k in "xyz"):
            raise InputError(f"{source}: structured array lacks x, y, z fields")
        flat = arr.reshape(-1)
        for k in "xyz":
            problem = _field_problem(flat[fields[k]])
            if problem:
                raise InputError(f"{source}: structured field {fields[k][:40]!r} {problem}")
        points = np.column_stack([flat[fields[k]] for k in "xyz"])
        normals = None
        names = ("nx", "ny", "nz")
        if all(k in fields for k in names) and not any(_field_problem(flat[fields[k]]) for k in names):
            normals = np.column_stack([flat[fields[k]] for k in names])
        return points, normals
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{source}: non-numeric array (dtype {arr.dtype})")
    if arr.size == 0:
        raise InputError(f"{source}: no points")
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise InputError(f"{source}: expected an (N, 3) or (N, 6) array, got shape {arr.shape}")
    normals = arr[:, 3:6] if arr.shape[1] == 6 else None
    return arr[:, :3], normals
