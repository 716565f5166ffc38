"""Point-cloud reading: format detection and dispatch, and input validation.

Every reader returns an ``(N, 3)`` float64 array of points in the file's own
units, plus optional ``(N, 3)`` unit normals.  All problems with the input are
reported as :class:`houghcad.errors.InputError` with a one-line message of the
form ``"<file>: <problem>"``.  Files are only ever opened for reading.

Supported formats (``fmt`` names in brackets), one module each:

- PLY [``ply``], ascii or binary (either endianness), normals from ``nx ny nz``
  (:mod:`.ply`);
- text tables [``xyz``, ``txt``, ``csv``, ``pts``, ``asc``]: whitespace,
  comma or semicolon separated, optional header line(s) of column names
  (``x y z nx ny nz``, ``X,Y,Z,Nx,Ny,Nz``, ``normal_x`` ..., case-insensitive,
  a leading ``#`` or ``//`` is allowed), an optional lone integer count line
  (PTS).  Columns beyond x, y, z are ignored unless a header names them as
  normals.  Without a header only the first three columns are used: six
  numeric columns are *not* assumed to be normals, because many exporters
  write colours or intensities there instead (:mod:`.text`);
- NumPy ``.npy`` [``npy``]: ``(N, 3)`` points or ``(N, 6)`` points + normals
  (other widths ``>= 3``: first three columns only), or a structured array
  with ``x, y, z`` (and optionally ``nx, ny, nz``) fields (:mod:`.npy`);
- OBJ [``obj``]: ``v`` lines; ``vn`` normals only when there is one per vertex;
- OFF [``off``]: the vertices (``NOFF`` normals are used);
- STL [``stl``], ascii or binary: the distinct triangle vertices, in order of
  first appearance (these three: :mod:`.mesh`);
- Fit4CAD [``fit4cad``]: ``Points:=[`` then ``[x, y, z],`` lines, closing ``];``
  (:mod:`.text`).

Adding a format: a module with ``read(data, source) -> (points, normals)`` (see
:mod:`.common`) and, when the format has a signature, a content test; then one
row in :data:`FORMAT_TABLE`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import InputError
from . import e57, las, mesh, npy, pcd, ply, text
from .common import SNIFF_BYTES, Reader, Rows

__all__ = [
    "MIN_POINTS",
    "FORMATS",
    "FORMAT_TABLE",
    "Format",
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


@dataclass(frozen=True)
class Format:
    """A readable file format: its name, reader, extensions and content tests.

    Attributes
    ----------
    name : str
        The ``fmt`` name of :func:`read_points`.
    read : callable
        ``read(data: bytes, source: str) -> (points (N, 3) float64, normals (N, 3) or None)``.
    extensions : tuple of str
        Lowercase extensions with the dot (``".ply"``) that select the format.
    magic : callable, optional
        ``magic(head: bytes, ext: str) -> bool`` on the file's first :data:`~.common.SNIFF_BYTES`
        bytes and lowercase extension: a signature, trusted before the extension.
    guess : callable, optional
        ``guess(data: bytes) -> bool``: a weaker content test, tried only when the extension is
        unknown.
    guess_rank : int
        Order of the guesses (lowest first): a weak test may accept another format's file too.
    scans : bool
        The file may hold several scans: ``read`` also takes ``scan=K`` (None: all, merged).
    """

    name: str
    read: Reader
    extensions: tuple[str, ...] = ()
    magic: Callable[[bytes, str], bool] | None = None
    guess: Callable[[bytes], bool] | None = None
    guess_rank: int = 0
    scans: bool = False


#: Every readable format; the order is that of :data:`FORMATS` (and of the error messages).
FORMAT_TABLE: tuple[Format, ...] = (
    Format("ply", ply.read_ply, (".ply",), magic=ply.is_ply),
    Format("xyz", text.read_table, (".xyz",), guess=text.looks_like_table, guess_rank=2),
    Format("txt", text.read_table, (".txt",)),
    Format("csv", text.read_table, (".csv",)),
    Format("pts", text.read_table, (".pts",)),
    Format("asc", text.read_table, (".asc",)),
    Format("npy", npy.read_npy, (".npy",), magic=npy.is_npy),
    Format("obj", mesh.read_obj, (".obj",), guess=mesh.looks_like_obj, guess_rank=1),
    Format("off", mesh.read_off, (".off",), magic=mesh.is_off),
    Format("stl", mesh.read_stl, (".stl",), guess=mesh.looks_like_stl, guess_rank=0),
    Format("fit4cad", text.read_fit4cad, magic=text.is_fit4cad),
    Format("las", las.read_las, (".las", ".laz"), magic=las.is_las),
    Format("e57", e57.read_e57, (".e57",), magic=e57.is_e57, scans=True),
    Format("pcd", pcd.read_pcd, (".pcd",), magic=pcd.is_pcd),
)

#: Format names accepted by ``read_points(fmt=...)``.
FORMATS: tuple[str, ...] = tuple(f.name for f in FORMAT_TABLE)


#: The names of the formats known by their content alone (no extension), as messages write them.
_CONTENT_ONLY_LABELS = {"fit4cad": "Fit4CAD text"}


def _label(f: Format) -> str:
    """How messages name format ``f``: its extensions (``"LAS/LAZ"``), else its content name."""
    return "/".join(e[1:].upper() for e in f.extensions) or _CONTENT_ONLY_LABELS.get(f.name, f.name)


def describe_formats() -> str:
    """The readable formats as a help text names them, from :data:`FORMAT_TABLE` (so that the
    text never misses one): formats one reader parses share a label (``"XYZ/TXT/CSV/PTS/ASC"``),
    a format known by its content alone is named by its name (``"Fit4CAD text"``)."""
    labels: list[str] = []
    last = None
    for f in FORMAT_TABLE:
        if f.read is last and labels:
            labels[-1] += "/" + _label(f)
        else:
            labels.append(_label(f))
        last = f.read
    return ", ".join(labels[:-1]) + " or " + labels[-1] if len(labels) > 1 else labels[0]


_BY_NAME = {f.name: f for f in FORMAT_TABLE}
_EXTENSIONS = {ext: f.name for f in FORMAT_TABLE for ext in f.extensions}
_MAGIC = tuple(f for f in FORMAT_TABLE if f.magic is not None)
_GUESSES = tuple(sorted((f for f in FORMAT_TABLE if f.guess is not None), key=lambda f: f.guess_rank))


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
    fields : dict of str to ndarray (N,)
        The file's other per-point attributes (intensity, colour ...), each in
        the file's own type, kept for the outputs.
    dropped : int
        Rows with a NaN or infinite coordinate left out (``drop_invalid``).
    flagged : int
        Rows that the file itself flags as holding no point, left out whatever
        ``drop_invalid`` says (E57 ``cartesianInvalidState``).
    rows : int or None
        Rows read: the file's, or with ``scan`` the scan's (with several scans
        merged, numbered through them in order); None: one per point.
    scan : int or None
        The scan read (``read_points(scan=K)``), None for the whole file.
    drop_invalid : bool
        Whether rows with a NaN or infinite coordinate were to be left out
        (``read_points(drop_invalid=True)``) rather than refused.
    scan_rows : tuple of int
        The rows of each scan when several were merged, in order (empty otherwise).
    dropped_rows : ndarray of int64, shape (K, 2)
        The rows left out (``flagged`` and ``dropped``), as ascending
        half-open ranges ``[start, stop)``: point ``i`` is the ``i``-th row
        outside them.
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    source: str | None = None
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    dropped: int = 0
    flagged: int = 0
    rows: int | None = None
    scan: int | None = None
    drop_invalid: bool = False
    scan_rows: tuple[int, ...] = ()
    dropped_rows: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def provenance(self) -> dict[str, Any]:
        """Which rows of the file the points are, as a result's ``options["input"]`` records it
        (docs/schema.md): ``rows``, ``scan``, ``drop_invalid``, ``dropped_rows`` (half-open ranges),
        ``dropped`` (``{"flagged_invalid": ..., "non_finite": ...}``) and, with several scans
        merged, ``scan_rows``."""
        out: dict[str, Any] = {
            "rows": int(self.rows if self.rows is not None else len(self) + self.dropped + self.flagged),
            "scan": self.scan,
            "drop_invalid": bool(self.drop_invalid),
            "dropped_rows": [[int(a), int(b)] for a, b in self.dropped_rows],
            "dropped": {"flagged_invalid": int(self.flagged), "non_finite": int(self.dropped)},
        }
        if self.scan_rows:
            out["scan_rows"] = [int(n) for n in self.scan_rows]
        return out


# --------------------------------------------------------------------------- public API


def read_points(path: str | os.PathLike[str], fmt: str | None = None, *, scan: int | None = None,
                drop_invalid: bool = False) -> PointCloud:
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
    scan : int, optional
        E57 only: read this scan (0-based) instead of merging them all.
    drop_invalid : bool
        Leave out the rows with a NaN or infinite coordinate (scanners and
        organised PCD clouds mark missing points so) instead of refusing the
        file; ``PointCloud.dropped`` says how many. Rows that the file flags as
        holding no point (E57 invalid state) are left out either way
        (``PointCloud.flagged``); ``PointCloud.dropped_rows`` lists both, and
        :meth:`PointCloud.provenance` records them for a result.

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
    if fmt is not None:
        fmt = fmt.lower().lstrip(".")
        if fmt not in FORMATS:
            raise InputError(f"{source}: unknown format {fmt!r} (expected one of {', '.join(FORMATS)})")
    # Arbitrary bytes make arbitrary floats (signalling NaNs, overflowing casts): NaN and inf are
    # reported by validate_points, not as numpy warnings on stderr.
    with np.errstate(all="ignore"):
        parsed = ply.read_ply_mapped(Path(path), source) if fmt in (None, "ply") and scan is None else None
        if parsed is None:
            parsed = _read_parsed(Path(path), source, fmt, scan)
        points, normals = parsed[0], parsed[1]
        fields = dict(parsed[2]) if len(parsed) > 2 else {}
        rows: Rows | None = parsed[3] if len(parsed) > 3 else None
        keep = _finite_rows(points) if drop_invalid else None
        if keep is not None:
            points, normals, fields = _take(points, normals, fields, keep)
        points, normals = validate_points(points, source, normals, return_normals=True, non_finite_hint=DROP_HINT)
    cloud = PointCloud(points=points, normals=normals, source=source, fields=fields, scan=scan,
                       drop_invalid=bool(drop_invalid))
    if keep is not None:
        cloud.dropped = int(len(keep) - np.count_nonzero(keep))
    cloud.rows = len(cloud) + cloud.dropped
    if rows is not None:
        cloud.rows, cloud.scan_rows = len(rows.flagged), tuple(rows.scans)
        cloud.flagged = int(np.count_nonzero(rows.flagged))
    if cloud.dropped or cloud.flagged:
        present = ~rows.flagged if rows is not None else np.ones(len(keep), dtype=bool)
        if keep is not None:
            held = np.flatnonzero(present)
            present[held[~keep]] = False
        cloud.dropped_rows = row_ranges(~present)
    return cloud


def _read_parsed(path: Path, source: str, fmt: str | None, scan: int | None) -> tuple:
    """The file's bytes through its format's reader (detected when ``fmt`` is None)."""
    data = _read_bytes(path, source)
    if not data.strip():
        raise InputError(f"{source}: file is empty")
    if fmt is None:
        fmt = detect_format(source, data)
    reader = _BY_NAME[fmt]
    if scan is not None and not reader.scans:
        kinds = ", ".join(f.name.upper() for f in FORMAT_TABLE if f.scans)
        raise InputError(f"{source}: a scan can be chosen in {kinds} files only")
    return reader.read(data, source, scan=scan) if reader.scans else reader.read(data, source)


def _finite_rows(points: np.ndarray) -> np.ndarray | None:
    """Which rows of the points (N, 3) have every coordinate finite, (N,) bool; None when they
    all do, or when the array is not (N, 3) numeric (validation reports it)."""
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.dtype.kind not in "iuf":
        return None
    keep = np.isfinite(pts.astype(np.float64)).all(axis=1)
    return None if keep.all() else keep


def _take(points: np.ndarray, normals: np.ndarray | None, fields: dict[str, np.ndarray], keep: np.ndarray) \
        -> tuple[np.ndarray, np.ndarray | None, dict[str, np.ndarray]]:
    """The rows ``keep`` (N,) bool of the points (N, 3), of their normals and of their fields
    (each in its own type)."""
    n = len(keep)
    nrm = np.asarray(normals)[keep] if normals is not None and np.shape(normals)[:1] == (n,) else normals
    kept = {k: np.asarray(v)[keep] for k, v in fields.items() if np.shape(v)[:1] == (n,)}
    return np.asarray(points)[keep], nrm, kept


def row_ranges(mask: np.ndarray) -> np.ndarray:
    """The runs of True in ``mask`` (R,) bool as ascending half-open ranges ``[start, stop)``,
    (K, 2) int64: compact for a scan's runs of missing points."""
    edges = np.diff(np.concatenate(([0], np.asarray(mask, dtype=np.int8), [0])))
    return np.column_stack([np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)]).astype(np.int64)


def detect_format(source: str, data: bytes) -> str:
    """Name of the format of a file's bytes, content first, then extension.

    Signatures (:attr:`Format.magic`) win over the extension; an unknown extension is resolved by
    the weaker content tests (:attr:`Format.guess`). Raises InputError when neither content nor
    extension is recognised.
    """
    head = data[:SNIFF_BYTES]
    ext = os.path.splitext(source)[1].lower()
    for fmt in _MAGIC:
        if fmt.magic(head, ext):
            return fmt.name
    if ext in _EXTENSIONS:
        return _EXTENSIONS[ext]
    for fmt in _GUESSES:
        if fmt.guess(data):
            return fmt.name
    raise InputError(
        f"{source}: unrecognised file format (extension {ext or 'none'!r}; "
        f"supported: {', '.join(sorted(set(_EXTENSIONS)))} and "
        f"{' and '.join(_label(f) for f in FORMAT_TABLE if not f.extensions)})"
    )


#: How a file's NaN or inf rows are left out, in the one-line error that refuses them: scanners
#: mark missing points so (an organised PCD's every empty cell), and the error reaches both the
#: CLI's user and a caller of :func:`read_points`, so it names the option for each.
DROP_HINT = "scanners mark missing points so; --drop-invalid, or drop_invalid=True in read_points, " \
    "leaves such rows out"


def validate_points(
    points: np.ndarray,
    source: str | None,
    normals: np.ndarray | None = None,
    *,
    return_normals: bool = False,
    non_finite_hint: str = "",
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
    non_finite_hint : str
        Appended in parentheses to the NaN or inf error: how the caller can leave such rows out
        (:func:`read_points` names its ``drop_invalid`` and the CLI's ``--drop-invalid``).

    Returns
    -------
    ndarray of float64, shape (N, 3)
        The validated points (and the cleaned normals or None).

    Raises
    ------
    InputError
        ``"<source>: <problem>"`` for: no points, non-numeric values, wrong
        shape, NaN or inf, fewer than :data:`MIN_POINTS` points, all points
        identical or collinear.  Duplicate points are allowed, and so is a flat cloud (one
        planar face is a surface like any other).
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
    with np.errstate(over="ignore", invalid="ignore"):  # float128 beyond float64: inf, reported below
        pts = np.ascontiguousarray(pts, dtype=np.float64)
    n = pts.shape[0]

    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        first = int(np.flatnonzero(~finite)[0])
        kind = "NaN" if np.isnan(pts[first]).any() else "infinite"
        hint = f" ({non_finite_hint})" if non_finite_hint else ""
        raise InputError(f"{name}: {kind} coordinate at point {first + 1} of {n}{hint}")
    if n < MIN_POINTS:
        raise InputError(f"{name}: only {n} point{'' if n == 1 else 's'}, at least {MIN_POINTS} are needed")

    problem = _degeneracy(pts)
    if problem:
        raise InputError(f"{name}: {problem}")
    if return_normals:
        return pts, clean_normals(normals, n, name)
    return pts


def clean_normals(normals: np.ndarray | None, n_points: int, source: str | None = None) -> np.ndarray | None:
    """Normals as (n_points, 3) unit float64, or None when they are unusable.

    Unusable means: wrong shape, non-numeric, any non-finite value or any
    (near) zero-length row.  Dropping them lets the pipeline estimate its own
    normals instead of failing on a cosmetic defect of the file; an
    :class:`~houghcad.errors.InputWarning` naming ``source`` says why.
    """
    unit, problem = _checked_normals(normals, n_points)
    if problem:
        import warnings

        from ..errors import InputWarning

        warnings.warn(f"{source or 'input'}: the normals given are not used ({problem}); houghcad estimates "
                      "its own", InputWarning, stacklevel=3)
    return unit


def _checked_normals(normals: np.ndarray | None, n_points: int) -> tuple[np.ndarray | None, str | None]:
    """(unit normals or None, why they are unusable or None): see :func:`clean_normals`."""
    if normals is None:
        return None, None
    nrm = np.asarray(normals)
    if nrm.dtype.kind not in "iuf":
        return None, f"non-numeric values (dtype {nrm.dtype})"
    if nrm.shape != (n_points, 3):
        return None, f"shape {nrm.shape} for {n_points} points"
    with np.errstate(over="ignore", invalid="ignore"):  # float128 beyond float64: inf, dropped below
        nrm = nrm.astype(np.float64)
    bad = ~np.isfinite(nrm).all(axis=1)
    if bad.any():
        return None, f"a NaN or infinite value at row {int(np.flatnonzero(bad)[0]) + 1}"
    # Each row scaled by its largest component first: squares of components near the float64
    # limit would overflow (a zero "unit" normal), those of tiny ones underflow.
    scale = np.abs(nrm).max(axis=1)
    safe = np.where(scale == 0.0, 1.0, scale)
    unit = nrm / safe[:, None]
    length = np.linalg.norm(unit, axis=1)  # in [1, sqrt(3)], 0 for a zero row
    zero = (scale == 0.0) | (scale < 1e-12 / np.maximum(length, 1.0))  # the normal's own length below 1e-12
    if zero.any():
        return None, f"a zero-length normal at row {int(np.flatnonzero(zero)[0]) + 1}"
    return np.ascontiguousarray(unit / length[:, None]), None


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


#: Rows per block of the degeneracy test's QR factorisations.
_QR_ROWS = 65536


def _degeneracy(pts: np.ndarray) -> str | None:
    """Describe a linear or point-like cloud, or None when it spans a surface (a flat cloud does:
    it comes out as one plane).

    Uses the singular values of the centred (N, 3) points: their ratios are
    scale-free, unlike the covariance eigenvalues (which square them).
    """
    # Copies of one point: the mean's rounding would leave a spread of ulps
    # whose singular values say nothing (50 copies of 0.1 read as collinear).
    if (pts == pts[0]).all():
        return "all points are identical"
    # Scaled to [-1, 1] first: near the float64 limit the sums, differences and LAPACK's own
    # squares would overflow (to a wrong answer and a LAPACK complaint on stderr).
    top = np.abs(pts).max()
    mean = sum(np.sum(pts[i:i + _QR_ROWS] / top, axis=0) for i in range(0, len(pts), _QR_ROWS)) / len(pts)
    # The singular values of the centred points, block by block (tall-skinny QR: those of the
    # stacked blocks' R factors are the whole matrix's), so that no (N, 3) copy is made.
    rs = [np.linalg.qr(pts[i:i + _QR_ROWS] / top - mean, mode="r") for i in range(0, len(pts), _QR_ROWS)]
    s = np.linalg.svd(np.linalg.qr(np.vstack(rs), mode="r") if len(rs) > 1 else rs[0],
                      compute_uv=False)  # descending, shape (3,)
    if s[0] == 0.0:
        return "all points are identical"
    if s[1] / s[0] < _DEGENERATE_RTOL:
        return "all points are collinear"
    return None
