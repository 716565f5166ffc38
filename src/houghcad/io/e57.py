"""E57 reader [``e57``] (ASTM E2807 scanner files, via pye57).

Every scan of the file is read in the file's common frame (each scan's pose
applied) and merged, or only the scan chosen with ``scan=K`` (0-based; the
CLI's ``--scan K``). Intensity (float32) and colours (uint8) are kept as the cloud's
``fields``, and with several scans merged an int32 ``scan`` field. Rows that the scanner flags
as holding no point (``cartesianInvalidState`` or, for spherical scans, ``sphericalInvalidState``
not 0: no coordinates, or a direction without a range) are left out, and reported in the
:class:`~.common.Rows` the reader returns, so that indices can be mapped back to the file's rows.
pye57 reads files, not bytes: the data goes through a temporary file.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from ..errors import InputError
from .common import Parsed, Rows, one_line

_E57_MAGIC = b"ASTM-E57"


def is_e57(head: bytes, ext: str) -> bool:
    """E57 signature: the file starts with ``ASTM-E57``."""
    return head.startswith(_E57_MAGIC)


def read_e57(data: bytes, source: str, scan: int | None = None) -> Parsed:
    """All scans merged, or scan ``scan``: (points, None, fields, rows)."""
    import pye57

    fd, tmp = tempfile.mkstemp(suffix=".e57")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        try:
            e57 = pye57.E57(tmp, mode="r")
        except Exception as exc:  # libE57Format raises its own types on malformed files
            raise InputError(f"{source}: cannot parse E57 file ({one_line(exc)})") from None
        try:
            pieces = _read_scans(e57, source, scan)
        finally:
            e57.close()  # also when a scan fails: the temporary file is removed next
    finally:
        os.unlink(tmp)
    scans = [d for d, _ in pieces]
    points = np.concatenate([np.column_stack([d["cartesianX"], d["cartesianY"], d["cartesianZ"]])
                             for d in scans]).astype(np.float64)
    fields = {}
    for key, name in (("intensity", "intensity"), ("colorRed", "red"), ("colorGreen", "green"),
                      ("colorBlue", "blue")):
        if all(key in d and len(d[key]) for d in scans):
            fields[name] = np.concatenate([np.asarray(d[key]) for d in scans])
    if len(scans) > 1:
        fields["scan"] = np.concatenate([np.full(len(d["cartesianX"]), k, dtype=np.int32)
                                         for k, d in enumerate(scans)])
    flagged = [f for _, f in pieces]
    rows = Rows(np.concatenate(flagged), tuple(len(f) for f in flagged) if len(flagged) > 1 else ())
    return points, None, fields, rows


def _read_scans(e57, source: str, scan: int | None) -> list[tuple[dict[str, np.ndarray], np.ndarray]]:
    """Every scan of an open file, in its common frame, or scan ``scan`` only: each scan's valid
    points (pye57 leaves out the rows flagged invalid) and its rows' flags (True: invalid)."""
    try:
        count = e57.scan_count
    except Exception as exc:
        raise InputError(f"{source}: cannot parse E57 file ({one_line(exc)})") from None
    if count == 0:
        raise InputError(f"{source}: E57 file holds no scan")
    if scan is not None and not 0 <= scan < count:
        raise InputError(f"{source}: no scan {scan} (the file holds scans 0 to {count - 1})")
    pieces = []
    for k in range(count) if scan is None else [scan]:
        try:
            flagged = _flagged_rows(e57, k)
            d = e57.read_scan(k, intensity=True, colors=True, ignore_missing_fields=True, transform=True)
        except Exception as exc:
            raise InputError(f"{source}: cannot read scan {k} ({one_line(exc)})") from None
        if len(d["cartesianX"]) != len(flagged) - int(flagged.sum()):
            raise InputError(f"{source}: cannot read scan {k} ({len(d['cartesianX'])} valid points "
                             f"of {len(flagged)} rows, {int(flagged.sum())} flagged invalid)")
        pieces.append((d, flagged))
    return pieces


def _flagged_rows(e57, k: int) -> np.ndarray:
    """Scan ``k``'s rows flagged as holding no point, (rows,) bool: its invalid state, the
    cartesian one for a cartesian scan, else the spherical one (as pye57's read_scan filters)."""
    header = e57.get_header(k)
    n, names = header.point_count, set(header.point_fields)
    cartesian = {"cartesianX", "cartesianY", "cartesianZ"} <= names
    state = "cartesianInvalidState" if cartesian else "sphericalInvalidState"
    if state not in names or n == 0:
        return np.zeros(n, dtype=bool)
    data, buffers = e57.make_buffers([state], n)
    reader = header.points.reader(buffers)
    try:
        got = reader.read()
    finally:
        reader.close()
    if got != n:  # the rest of the buffer would be garbage
        raise ValueError(f"{got} of its {n} rows' invalid states read")
    return data[state] != 0
