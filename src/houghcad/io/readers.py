"""Point-cloud readers and input validation.

Every reader returns an ``(N, 3)`` float64 array of points in the file's own
units, plus optional ``(N, 3)`` unit normals.  All problems with the input are
reported as :class:`houghcad.errors.InputError` with a one-line message of the
form ``"<file>: <problem>"``.  Files are only ever opened for reading.

Supported formats (``fmt`` names in brackets):

- PLY [``ply``], ascii or binary (either endianness), normals from ``nx ny nz``;
- text tables [``xyz``, ``txt``, ``csv``, ``pts``, ``asc``]: whitespace,
  comma or semicolon separated, optional header line(s) of column names
  (``x y z nx ny nz``, ``X,Y,Z,Nx,Ny,Nz``, ``normal_x`` ..., case-insensitive,
  a leading ``#`` or ``//`` is allowed), an optional lone integer count line
  (PTS).  Columns beyond x, y, z are ignored unless a header names them as
  normals.  Without a header only the first three columns are used: six
  numeric columns are *not* assumed to be normals, because many exporters
  write colours or intensities there instead;
- NumPy ``.npy`` [``npy``]: ``(N, 3)`` points or ``(N, 6)`` points + normals
  (other widths ``>= 3``: first three columns only), or a structured array
  with ``x, y, z`` (and optionally ``nx, ny, nz``) fields;
- OBJ [``obj``]: ``v`` lines; ``vn`` normals only when there is one per vertex;
- OFF [``off``]: the vertices (``NOFF`` normals are used);
- STL [``stl``], ascii or binary: the distinct triangle vertices, in order of
  first appearance;
- Fit4CAD [``fit4cad``]: ``Points:=[`` then ``[x, y, z],`` lines, closing ``];``.
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = [
    "MIN_POINTS",
    "FORMATS",
    "PointCloud",
    "read_points",
    "detect_format",
    "validate_points",
    "clean_normals",
]

#: Fewer points than this cannot support any primitive fit.
MIN_POINTS = 20

#: Relative singular-value threshold below which the cloud is flat (or a line).
_DEGENERATE_RTOL = 1e-9

#: Format names accepted by ``read_points(fmt=...)``.
FORMATS = ("ply", "xyz", "txt", "csv", "pts", "asc", "npy", "obj", "off", "stl", "fit4cad")

_TEXT_TABLE_FORMATS = frozenset({"xyz", "txt", "csv", "pts", "asc"})
_EXTENSIONS = {
    ".ply": "ply",
    ".xyz": "xyz",
    ".txt": "txt",
    ".csv": "csv",
    ".pts": "pts",
    ".asc": "asc",
    ".npy": "npy",
    ".obj": "obj",
    ".off": "off",
    ".stl": "stl",
}
_NPY_MAGIC = b"\x93NUMPY"
_FIT4CAD_PREFIX = "Points:=["
_OFF_KEYWORD = re.compile(r"(ST)?C?N?OFF")
_SNIFF_BYTES = 4096

# Normalised header names (lowercase, alphanumerics only) -> coordinate slot.
_XYZ_NAMES = ({"x", "px", "posx", "pointx"}, {"y", "py", "posy", "pointy"}, {"z", "pz", "posz", "pointz"})
_NORMAL_NAMES = (
    {"nx", "normalx", "normx", "nrmx"},
    {"ny", "normaly", "normy", "nrmy"},
    {"nz", "normalz", "normz", "nrmz"},
)


@dataclass
class PointCloud:
    """A point cloud as read from a file.

    Attributes
    ----------
    points : ndarray of float64, shape (N, 3)
        Coordinates in the file's units.
    normals : ndarray of float64, shape (N, 3), or None
        Unit normals when the file carried valid ones.
    source : str or None
        Path the cloud was read from.
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    source: str | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])


# --------------------------------------------------------------------------- public API


def read_points(path: str | os.PathLike[str], fmt: str | None = None) -> PointCloud:
    """Read and validate a point cloud.

    Parameters
    ----------
    path : str or path-like
        File to read; it is opened read-only and never modified.
    fmt : str, optional
        One of :data:`FORMATS`.  By default the format is detected from the
        content (PLY/NPY magic, Fit4CAD ``Points:=[``, OFF keyword) and then
        the extension; files with an unknown extension holding a plain numeric
        table are read as XYZ.

    Returns
    -------
    PointCloud
        ``points`` (N, 3) float64; ``normals`` (N, 3) unit float64 or None.
        Normals of the wrong shape or with non-finite / zero-length rows are
        dropped (``None``) rather than treated as an error.

    Raises
    ------
    InputError
        Missing or unreadable file, unknown format, parse error, or points that
        fail :func:`validate_points`.
    """
    source = str(path)
    data = _read_bytes(Path(path), source)
    if not data.strip():
        raise InputError(f"{source}: file is empty")
    if fmt is None:
        fmt = detect_format(source, data)
    else:
        fmt = fmt.lower().lstrip(".")
        if fmt not in FORMATS:
            raise InputError(f"{source}: unknown format {fmt!r} (expected one of {', '.join(FORMATS)})")
    points, normals = _READERS[fmt](data, source)
    points, normals = validate_points(points, source, normals, return_normals=True)
    return PointCloud(points=points, normals=normals, source=source)


def detect_format(source: str, data: bytes) -> str:
    """Name of the format of a file's bytes, content first, then extension.

    Raises InputError when neither content nor extension is recognised.
    """
    head = data[:_SNIFF_BYTES]
    if head.startswith(b"ply") and head[3:4] in (b"\n", b"\r"):
        return "ply"
    if head.startswith(_NPY_MAGIC):
        return "npy"
    text_head = head.lstrip(b"\xef\xbb\xbf").lstrip()
    if text_head.startswith(_FIT4CAD_PREFIX.encode()):
        return "fit4cad"
    ext = os.path.splitext(source)[1].lower()
    if ext == ".stl":
        return "stl"
    first_word = text_head.split(None, 1)[0].decode("ascii", "replace") if text_head else ""
    if _OFF_KEYWORD.fullmatch(first_word):
        return "off"
    if ext in _EXTENSIONS:
        return _EXTENSIONS[ext]
    # Unknown extension: sniff the content.
    if _is_binary_stl(data) or (first_word == "solid" and b"facet" in head):
        return "stl"
    if b"\0" not in head:
        text = head.decode("utf-8", "replace")
        if _looks_like_obj(text):
            return "obj"
        if _looks_like_numeric_table(text):
            return "xyz"
    raise InputError(
        f"{source}: unrecognised file format (extension {ext or 'none'!r}; "
        f"supported: {', '.join(sorted(set(_EXTENSIONS)))} and Fit4CAD text)"
    )


def validate_points(
    points: np.ndarray,
    source: str | None,
    normals: np.ndarray | None = None,
    *,
    return_normals: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray | None]:
    """Check that ``points`` can be segmented.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Coordinates; converted to C-contiguous float64.
    source : str or None
        File name used in error messages (``"input"`` when None).
    normals : array_like, shape (N, 3), optional
        Only looked at when ``return_normals`` is true; see :func:`clean_normals`.
    return_normals : bool
        Return ``(points, normals)`` instead of just the points.

    Returns
    -------
    ndarray of float64, shape (N, 3)
        The validated points (and the cleaned normals or None).

    Raises
    ------
    InputError
        ``"<source>: <problem>"`` for: no points, non-numeric values, wrong
        shape, NaN or inf, fewer than :data:`MIN_POINTS` points, all points
        identical, collinear or coplanar.  Duplicate points are allowed.
    """
    name = source if source is not None else "input"
    try:
        pts = np.asarray(points)
    except (ValueError, TypeError) as exc:  # ragged nested lists
        raise InputError(f"{name}: points are not a numeric (N, 3) array ({exc})") from None
    if pts.size == 0:
        raise InputError(f"{name}: no points")
    if pts.dtype.kind not in "iuf":
        raise InputError(f"{name}: non-numeric point coordinates (dtype {pts.dtype})")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"{name}: expected an (N, 3) array of points, got shape {pts.shape}")
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    n = pts.shape[0]

    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        first = int(np.flatnonzero(~finite)[0])
        kind = "NaN" if np.isnan(pts[first]).any() else "infinite"
        raise InputError(f"{name}: {kind} coordinate at point {first + 1} of {n}")
    if n < MIN_POINTS:
        raise InputError(f"{name}: only {n} points, at least {MIN_POINTS} are needed")

    problem = _degeneracy(pts)
    if problem:
        raise InputError(f"{name}: {problem}")
    if return_normals:
        return pts, clean_normals(normals, n)
    return pts


def clean_normals(normals: np.ndarray | None, n_points: int) -> np.ndarray | None:
    """Normals as (n_points, 3) unit float64, or None when they are unusable.

    Unusable means: wrong shape, non-numeric, any non-finite value or any
    (near) zero-length row.  Dropping them lets the pipeline estimate its own
    normals instead of failing on a cosmetic defect of the file.
    """
    if normals is None:
        return None
    nrm = np.asarray(normals)
    if nrm.dtype.kind not in "iuf" or nrm.shape != (n_points, 3):
        return None
    nrm = nrm.astype(np.float64)
    if not np.isfinite(nrm).all():
        return None
    length = np.linalg.norm(nrm, axis=1)
    if (length < 1e-12).any():
        return None
    return np.ascontiguousarray(nrm / length[:, None])


# --------------------------------------------------------------------------- helpers


def _read_bytes(path: Path, source: str) -> bytes:
    """Whole file content; OS errors become one-line InputErrors."""
    try:
        with open(path, "rb") as f:  # read-only: the input is never modified
            return f.read()
    except FileNotFoundError:
        raise InputError(f"{source}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{source}: is a directory, not a file") from None
    except PermissionError:
        raise InputError(f"{source}: cannot read file (permission denied)") from None
    except OSError as exc:
        raise InputError(f"{source}: cannot read file ({exc.strerror or exc})") from None


def _degeneracy(pts: np.ndarray) -> str | None:
    """Describe a flat/linear/point-like cloud, or None when it spans 3-D.

    Uses the singular values of the centred (N, 3) points: their ratios are
    scale-free, unlike the covariance eigenvalues (which square them).
    """
    centred = pts - pts.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)  # descending, shape (3,)
    if s[0] == 0.0:
        return "all points are identical"
    if s[1] / s[0] < _DEGENERATE_RTOL:
        return "all points are collinear"
    if s[2] / s[0] < _DEGENERATE_RTOL:
        return "all points are coplanar"
    return None


def _decode_text(data: bytes, source: str) -> str:
    """Bytes to str for the text formats; binary content is an InputError."""
    if b"\0" in data[:_SNIFF_BYTES]:
        raise InputError(f"{source}: not a text file (binary content)")
    return data.decode("utf-8-sig", errors="replace")


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _split_row(line: str, delimiter: str | None) -> list[str]:
    """Tokens of one table row (``delimiter`` None = whitespace)."""
    if delimiter is None:
        return line.split()
    return [t.strip() for t in line.split(delimiter)]


def _guess_delimiter(line: str) -> str | None:
    if "," in line:
        return ","
    if ";" in line:
        return ";"
    return None


def _strip_comment_marker(line: str) -> str:
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
        numeric = [_is_float(t) for t in tokens]
        if not any(numeric) and header_lines < 3:
            header_lines += 1
            continue
        return len(tokens) >= 3 and all(numeric)
    return False


_OBJ_KEYWORDS = frozenset({"v", "vn", "vt", "vp", "f", "l", "p", "o", "g", "s", "mtllib", "usemtl"})


def _looks_like_obj(text: str) -> bool:
    """True when the first statement is an OBJ keyword and some ``v`` line exists."""
    for line in text.splitlines()[:50]:
        tokens = line.split("#", 1)[0].split()
        if tokens:
            return tokens[0] in _OBJ_KEYWORDS and _OBJ_ANY_V.search(text) is not None
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
            if not _is_float(tokens[c]):
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


# --------------------------------------------------------------------------- format readers
# Each reader: (data: bytes, source: str) -> (points (N,3) float64, normals (N,3) or None).
# Validation (finite, count, degeneracy) happens afterwards in validate_points.

_Parsed = tuple[np.ndarray, "np.ndarray | None"]


def _read_table(data: bytes, source: str) -> _Parsed:
    """XYZ / TXT / CSV / PTS / ASC table with optional header and count lines."""
    text = _decode_text(data, source)
    if text.lstrip().startswith(_FIT4CAD_PREFIX):
        return _read_fit4cad(data, source)
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
        numeric = [_is_float(t) for t in tokens]
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


def _read_fit4cad(data: bytes, source: str) -> _Parsed:
    """Fit4CAD ``Points:=[ [x, y, z], ... ];`` text, parsed in one vectorised pass."""
    text = _decode_text(data, source).lstrip()
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


_BRACKETS_TO_SPACE = str.maketrans("[],", "   ")


def _first_fit4cad_error(text: str, source: str) -> InputError:
    """Find the first malformed Fit4CAD line (slow path)."""
    lines = text.splitlines()
    for lineno, line in enumerate(lines[1:], start=2):
        s = line.strip()
        if not s or re.fullmatch(r"\]\s*;", s):
            continue
        tokens = s.translate(_BRACKETS_TO_SPACE).replace(";", " ").split()
        for t in tokens:
            if not _is_float(t):
                return InputError(f"{source}: non-numeric value {t[:40]!r} on line {lineno}")
        if len(tokens) != 3:
            return InputError(f"{source}: line {lineno} has {len(tokens)} values, expected 3")
    return InputError(f"{source}: malformed Fit4CAD point list")


def _read_ply(data: bytes, source: str) -> _Parsed:
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
    for names in (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z")):
        if all(n in props for n in names):
            try:
                normals = np.column_stack([arr[props[n]] for n in names]).astype(np.float64)
            except (TypeError, ValueError):
                normals = None
            break
    return points, normals


def _read_npy(data: bytes, source: str) -> _Parsed:
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


_OBJ_V = re.compile(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.M)
_OBJ_VN = re.compile(r"^[ \t]*vn[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.M)
_OBJ_ANY_V = re.compile(r"^[ \t]*v[ \t]", re.M)


def _read_obj(data: bytes, source: str) -> _Parsed:
    """Wavefront OBJ vertices (``v``); ``vn`` normals if one per vertex."""
    text = _decode_text(data, source)
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
    for lineno, line in enumerate(text.splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if not tokens or tokens[0] != "v":
            continue
        if len(tokens) < 4:
            return InputError(f"{source}: vertex on line {lineno} has {len(tokens) - 1} coordinates, expected 3")
        for t in tokens[1:4]:
            if not _is_float(t):
                return InputError(f"{source}: non-numeric value {t[:40]!r} on line {lineno}")
    return InputError(f"{source}: malformed OBJ vertex lines")


def _read_off(data: bytes, source: str) -> _Parsed:
    """OFF / COFF / NOFF / CNOFF vertices (ascii only)."""
    text = _decode_text(data, source)
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
        raise InputError(f"{source}: OFF header announces {n_vertices} vertices, file has {len(vertex_rows)}")
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
                if not _is_float(tokens[c]):
                    raise InputError(f"{source}: non-numeric value {tokens[c][:40]!r} on line {lineno + 1}") from None
        raise InputError(f"{source}: cannot parse OFF vertices") from None
    return arr[:, :3], (arr[:, 3:6] if has_normals else None)


_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
_STL_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", re.I)


def _is_binary_stl(data: bytes) -> bool:
    """Binary STL: 80-byte header, uint32 count, 50 bytes per triangle, exactly."""
    if len(data) < 84:
        return False
    n = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
    return len(data) == 84 + 50 * n


def _read_stl(data: bytes, source: str) -> _Parsed:
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
            bad = next(t for r in rows for t in r if not _is_float(t.decode("ascii", "replace")))
            raise InputError(f"{source}: non-numeric vertex value {bad[:40].decode('ascii', 'replace')!r}") from None
    else:
        raise InputError(f"{source}: not a valid STL file (neither 'solid' ascii nor a consistent binary size)")
    if vertices.shape[0] == 0:
        raise InputError(f"{source}: STL file has no triangles")
    # +0.0 folds -0.0 into 0.0 so both spellings count as one vertex
    _, first = np.unique(vertices + 0.0, axis=0, return_index=True)
    return vertices[np.sort(first)], None


_READERS = {
    "ply": _read_ply,
    "xyz": _read_table,
    "txt": _read_table,
    "csv": _read_table,
    "pts": _read_table,
    "asc": _read_table,
    "npy": _read_npy,
    "obj": _read_obj,
    "off": _read_off,
    "stl": _read_stl,
    "fit4cad": _read_fit4cad,
}
