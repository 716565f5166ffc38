"""E57 reader [``e57``] (ASTM E2807 scanner files, via pye57).

Every scan of the file is read in the file's common frame (each scan's pose
applied) and merged, or only the scan chosen with ``scan=K`` (0-based; the
CLI's ``--scan K``). Intensity and colours are kept as the cloud's ``fields``.
pye57 reads files, not bytes: the data goes through a temporary file.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from ..errors import InputError
from .common import Parsed, one_line

_E57_MAGIC = b"ASTM-E57"


def is_e57(head: bytes, ext: str) -> bool:
    """E57 signature: the file starts with ``ASTM-E57``."""
    return head.startswith(_E57_MAGIC)


def read_e57(data: bytes, source: str, scan: int | None = None) -> Parsed:
    """All scans merged, or scan ``scan``: (points, None, fields)."""
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
    points = np.concatenate([np.column_stack([d["cartesianX"], d["cartesianY"], d["cartesianZ"]])
                             for d in pieces]).astype(np.float64)
    fields = {}
    for key, name in (("intensity", "intensity"), ("colorRed", "red"), ("colorGreen", "green"),
                      ("colorBlue", "blue")):
        if all(key in d and len(d[key]) for d in pieces):
            fields[name] = np.concatenate([np.asarray(d[key]) for d in pieces])
    if len(pieces) > 1:
        fields["scan"] = np.concatenate([np.full(len(d["cartesianX"]), k) for k, d in enumerate(pieces)])
    return points, None, fields


def _read_scans(e57, source: str, scan: int | None) -> list[dict[str, np.ndarray]]:
    """Every scan of an open file, in its common frame, or scan ``scan`` only."""
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
            pieces.append(e57.read_scan(k, intensity=True, colors=True, ignore_missing_fields=True, transform=True))
        except Exception as exc:
            raise InputError(f"{source}: cannot read scan {k} ({one_line(exc)})") from None
    return pieces
