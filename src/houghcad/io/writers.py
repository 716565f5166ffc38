"""Atomic writers for results: JSON, Fit4CAD primitive lists and PLY.

Every writer goes through :func:`atomic_write`, so a file is either written
whole or not at all: an interrupted or failing run never leaves a truncated
output behind, and an existing file is only replaced once the new one is
complete.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import stat
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = ["atomic_write", "write_json", "write_fit4cad_primitives", "write_points_ply", "write_result_ply",
           "write_trace_ply"]


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file next to ``path``; move it over ``path`` on success.

    Parameters
    ----------
    path : str or path-like
        Final destination.  Its directory must exist.
    mode : {"w", "wb"}
        Text (UTF-8) or binary.

    Yields
    ------
    file object
        Write the whole content to it.  On normal exit the data are flushed,
        fsync'ed and the temporary file is renamed over ``path`` with
        :func:`os.replace` (atomic on POSIX and Windows); on an exception the
        temporary file is deleted and ``path`` is left untouched. An existing
        ``path`` that is a device or a pipe (``/dev/null``, a FIFO) is written
        directly: it has no content to keep whole.

    Raises
    ------
    OSError
        The directory is missing or not writable, ``path`` is a directory, ...
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write: mode must be 'w' or 'wb', not {mode!r}")
    dest = Path(path)
    if _is_special(dest):
        # A device or a pipe (/dev/null, /dev/stdout, a FIFO): there is nothing to replace
        # atomically, and a rename over it would replace the device node itself (as root).
        with open(dest, mode, **({"encoding": "utf-8", "newline": "\n"} if mode == "w" else {})) as f:
            yield f
        return
    directory = dest.parent
    # Same directory => same filesystem => os.replace is a rename, not a copy.
    tmp = directory / f".{dest.name}.{secrets.token_hex(6)}.tmp"
    # os.open with 0o666 lets the umask decide the final permissions
    # (tempfile.mkstemp would force 0o600 on the output).
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        if mode == "w":
            f: IO[Any] = os.fdopen(fd, "w", encoding="utf-8", newline="\n")
        else:
            f = os.fdopen(fd, "wb")
    except BaseException:
        os.close(fd)
        _unlink_quietly(tmp)
        raise
    try:
        with f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, dest)
    except BaseException:
        _unlink_quietly(tmp)
        raise
    _fsync_directory(directory)


def _is_special(path: Path) -> bool:
    """Whether ``path`` (links followed) exists and is neither a regular file nor a directory."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _unlink_quietly(path: Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def _fsync_directory(directory: Path) -> None:
    """Persist the rename itself (POSIX only; best effort)."""
    if os.name != "posix":
        return
    with contextlib.suppress(OSError):
        dfd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def _json_default(obj: Any) -> Any:
    """Serialise numpy scalars and arrays that slip into result dictionaries."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"Object of type {type(obj).__name__} is not JSON serializable")


def write_json(path: str | os.PathLike[str], obj: Any) -> None:
    """Write ``obj`` as compact JSON (``separators=(",", ":")``), atomically.

    Numpy scalars/arrays are converted.  Non-finite floats are written as
    ``NaN`` / ``Infinity`` (Python's :mod:`json` reads them back; strict JSON
    parsers do not), because :class:`houghcad.result.Segment` uses NaN for an
    unknown MFE.  The text is encoded before the file is opened, so a
    serialisation error never touches the disk.
    """
    text = json.dumps(obj, separators=(",", ":"), default=_json_default)
    with atomic_write(path, "w") as f:
        f.write(text)
        f.write("\n")


def write_fit4cad_primitives(path: str | os.PathLike[str], segments: Sequence[np.ndarray]) -> None:
    """Write segments in the Fit4CAD ground-truth layout, atomically.

    Parameters
    ----------
    path : str or path-like
        Destination (e.g. ``PC1_primitives.txt``).
    segments : sequence of int arrays, each shape (M_k,)
        0-based point indices per segment.  Written 1-based, sorted ascending
        (as in the benchmark files), one block ``PrimitiveK:=[i j k ...];``
        per segment, K counting from 1, each block followed by a blank line.
    """
    blocks = []
    for k, seg in enumerate(segments, start=1):
        idx = np.asarray(seg)
        if idx.size and (idx.dtype.kind not in "iu" or idx.ndim != 1 or idx.min() < 0):
            raise ValueError(f"segment {k - 1}: indices must be a 1-D array of non-negative integers")
        one_based = np.sort(idx.astype(np.int64, copy=False)) + 1
        blocks.append(f"Primitive{k}:=[{' '.join(map(str, one_based.tolist()))}];\n\n")
    text = "".join(blocks)
    with atomic_write(path, "w") as f:
        f.write(text)


def write_points_ply(
    path: str | os.PathLike[str],
    points: np.ndarray,
    fields: Mapping[str, np.ndarray] | None = None,
    colors: np.ndarray | None = None,
    binary: bool = True,
    comments: Sequence[str] = (),
) -> None:
    """Write points (and per-point attributes) as a PLY ``vertex`` element, atomically.

    Parameters
    ----------
    path : str or path-like
        Destination ``.ply`` file.
    points : array_like, shape (N, 3)
        Written as float64 ``x, y, z``.
    fields : mapping of name -> array_like, shape (N,), optional
        Extra scalar properties (e.g. ``{"segment": labels}``), in their own
        type where PLY has it (8 to 32-bit integers, float32, float64);
        booleans become ``uint8``, 64-bit integers ``int32`` / ``uint32``
        when their values fit, else ``float64`` (exact to 2^53), ``float16``
        ``float32``.
    colors : array_like, shape (N, 3), optional
        ``uchar red, green, blue``.  Integer arrays are taken as 0-255
        (clipped); floating arrays as 0-1 (scaled by 255, rounded, clipped).
    binary : bool
        Binary little-endian (default) or ascii PLY.
    comments : sequence of str
        Header comment lines (one line each).
    """
    from plyfile import PlyData, PlyElement

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    n = pts.shape[0]
    columns: list[tuple[str, np.ndarray]] = [("x", pts[:, 0]), ("y", pts[:, 1]), ("z", pts[:, 2])]
    reserved = {"x", "y", "z", "red", "green", "blue"}
    for name, values in (fields or {}).items():
        if not name.isidentifier() or name in reserved:
            raise ValueError(f"invalid or reserved PLY field name {name!r}")
        arr = np.asarray(values)
        if arr.shape != (n,):
            raise ValueError(f"field {name!r} must have shape ({n},), got {arr.shape}")
        if arr.dtype.kind not in "iubf":
            raise ValueError(f"field {name!r} must be numeric, got dtype {arr.dtype}")
        columns.append((name, arr.astype(_ply_dtype(arr), copy=False)))
    if colors is not None:
        rgb = _colors_to_uint8(colors, n)
        columns += [("red", rgb[:, 0]), ("green", rgb[:, 1]), ("blue", rgb[:, 2])]

    vertex = np.empty(n, dtype=[(name, arr.dtype.str.replace(">", "<")) for name, arr in columns])
    for name, arr in columns:
        vertex[name] = arr
    ply = PlyData([PlyElement.describe(vertex, "vertex")], text=not binary, byte_order="<",
                  comments=[c.replace("\n", " ") for c in comments])
    with atomic_write(path, "wb") as f:
        ply.write(f)


#: The scalar types a PLY property can have (plyfile's names: char ... double).
_PLY_TYPES = {np.dtype(t) for t in ("i1", "u1", "i2", "u2", "i4", "u4", "f4", "f8")}


def _ply_dtype(arr: np.ndarray) -> np.dtype:
    """The PLY type that holds the values of ``arr`` (numeric, 1-D) exactly where one can."""
    dt = arr.dtype.newbyteorder("=")
    if dt in _PLY_TYPES:
        return dt
    if dt.kind == "b":
        return np.dtype(np.uint8)
    if dt.kind == "f":  # float16 (or longer than double: rounded)
        return np.dtype(np.float32 if dt.itemsize < 4 else np.float64)
    narrow = np.dtype(np.int32 if dt.kind == "i" else np.uint32)
    info = np.iinfo(narrow)
    if arr.size == 0 or (int(arr.min()) >= info.min and int(arr.max()) <= info.max):
        return narrow
    return np.dtype(np.float64)


def write_result_ply(path: str | os.PathLike[str], points: np.ndarray, result: Any,
                     extra: Mapping[str, np.ndarray] | None = None) -> None:
    """Write a segmented cloud as a coloured binary PLY for CloudCompare, MeshLab ..., atomically.

    Parameters
    ----------
    path : str or path-like
        Destination ``.ply`` file.
    points : array_like, shape (N, 3)
        The input cloud in world coordinates (``N == result.n_points``).
    result : houghcad.result.Result
        Its segmentation.
    extra : mapping of name -> array (N,), optional
        The input's own per-point fields (intensity, colour ...), kept; one
        whose name the output uses gets the prefix ``input_``.

    The ``vertex`` element has ``x y z`` (float64); the input's own fields;
    ``nx ny nz``, the normals the run used (when the result has them);
    ``distance``, each point's distance to its segment's fitted surface in
    the input's units, and ``distance_sigma``, the same in estimated noise σ
    (NaN where unsegmented); the int32 fields ``segment`` (segment id, -1
    unsegmented), ``type`` (family code of :data:`houghcad.palette.TYPE_CODES`,
    -1 unsegmented, 0 unknown family) and ``group``
    (:meth:`~houghcad.result.Result.group_labels`, -1 none); and the uchar
    colours ``red green blue`` (:func:`houghcad.palette.point_colors` by
    segment: adjacent segments clearly apart).
    """
    from ..palette import point_colors, point_type_codes

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[0] != result.n_points:
        raise ValueError(f"points must have shape ({result.n_points}, 3), got {pts.shape}")
    ours: dict[str, np.ndarray] = {}
    if getattr(result, "normals", None) is not None:
        ours.update(nx=result.normals[:, 0], ny=result.normals[:, 1], nz=result.normals[:, 2])
    if getattr(result, "distances", None) is not None:
        ours["distance"] = result.distances
        sigma = (result.options.get("derived") or {}).get("sigma")
        if sigma:
            ours["distance_sigma"] = result.distances / sigma
    ours = {k: np.asarray(v, dtype=np.float32) for k, v in ours.items()}
    ours.update({k: np.asarray(v, dtype=np.int32) for k, v in
                 (("segment", result.labels()), ("type", point_type_codes(result)), ("group", result.group_labels()))})
    taken = set(ours) | {"x", "y", "z", "red", "green", "blue"}
    kept = {k: v for k, v in (extra or {}).items() if k.isidentifier() and np.asarray(v).shape == (len(pts),)}
    theirs = {}
    for k, v in kept.items():
        # A name the output uses gets "input_" in front, as often as it takes to be free: a
        # houghcad PLY read again holds both "red" and "input_red".
        name = k
        while name.lower() in taken or (name != k and name in kept):
            name = f"input_{name}"
        taken.add(name.lower())
        theirs[name] = v
    write_points_ply(path, pts, fields={**theirs, **ours}, colors=point_colors(result, "segment", pts))


def write_trace_ply(path: str | os.PathLike[str], points: np.ndarray, seg: Any, pass_name: str,
                    rows: np.ndarray | None = None) -> None:
    """Write the labels of a segmentation state after one pass, atomically.

    ``points`` (N, 3) are those the passes ran on (world coordinates): the
    input's, or its subsample or distinct points, whose input rows ``rows``
    (N,) then go in an ``input_index`` field; ``seg`` a
    :class:`houghcad.state.Segmentation`. The ``vertex`` element has
    ``x y z``, ``segment`` (-1 free) and ``type`` (family code, -1 free)
    and colours by type; the header comment names the pass.
    """
    from ..palette import UNSEGMENTED_COLOR, UNSEGMENTED_CODE, type_code, type_color

    lab = np.asarray(seg.labels, dtype=np.int64)
    names = [r.family.name for r in seg.records]
    codes = np.array([type_code(t) for t in names] + [UNSEGMENTED_CODE], dtype=np.int32)
    colors = np.array([type_color(t) for t in names] + [UNSEGMENTED_COLOR], dtype=np.uint8)
    fields = {"segment": lab, "type": codes[lab]}
    if rows is not None:
        fields["input_index"] = np.asarray(rows, dtype=np.int64)
    write_points_ply(path, points, fields=fields, colors=colors[lab],
                     comments=[f"houghcad pass {pass_name}", f"segments {len(names)}"])


def _colors_to_uint8(colors: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) colours to uint8: ints as 0-255, floats as 0-1."""
    c = np.asarray(colors)
    if c.shape != (n, 3):
        raise ValueError(f"colors must have shape ({n}, 3), got {c.shape}")
    if c.dtype.kind == "f":
        c = np.rint(c * 255.0)
    elif c.dtype.kind not in "iu":
        raise ValueError(f"colors must be numeric, got dtype {c.dtype}")
    return np.clip(c, 0, 255).astype(np.uint8)
