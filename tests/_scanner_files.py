"""Small scanner files (LAS/LAZ, PCD, E57) as bytes, for the reader tests and the fuzz seeds."""

from __future__ import annotations

import contextlib
import io
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def las_bytes(pts: np.ndarray, normals: np.ndarray | None = None, intensity: np.ndarray | None = None,
              compressed: bool = False) -> bytes:
    """A LAS 1.2 (point format 3) file, LAZ when ``compressed``; normals as extra bytes ``nx ny nz``."""
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([1e-6] * 3)
    header.offsets = pts.min(axis=0)
    if normals is not None:
        header.add_extra_dims([laspy.ExtraBytesParams(name=k, type=np.float32) for k in ("nx", "ny", "nz")])
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts.T
    if normals is not None:
        las.nx, las.ny, las.nz = normals.T.astype(np.float32)
    if intensity is not None:
        las.intensity = intensity
    buf = io.BytesIO()
    las.write(buf, do_compress=compressed)
    return buf.getvalue()


def pcd_bytes(columns: dict[str, np.ndarray], encoding: str, types: dict[str, Any] | None = None) -> bytes:
    """A PCD file of ``columns`` (name -> (N,)) in ``encoding`` (ascii, binary, binary_compressed),
    each column of the type ``types`` gives it (float32 by default), its values stored as they are."""
    from pypcd4 import Encoding, PointCloud

    names = list(columns)
    dtypes = [np.dtype((types or {}).get(k, np.float32)) for k in names]
    # One array per field (a single table would pass every column through one common type).
    cols = [np.asarray(columns[k]).astype(t, copy=False) for k, t in zip(names, dtypes)]
    pc = PointCloud.from_points(cols, names, dtypes)
    with tempfile.TemporaryDirectory() as tmp:  # pypcd4 saves to paths
        path = Path(tmp) / "cloud.pcd"
        pc.save(str(path), encoding=Encoding(encoding))
        return path.read_bytes()


def e57_bytes(scans: list[tuple[np.ndarray, np.ndarray]], intensity: bool = True,
              invalid: list[np.ndarray | None] | None = None) -> bytes:
    """An E57 file with one scan per (points (N, 3), translation (3,)); scan k's intensity is k + 0.5.
    ``invalid[k]``: scan k's ``cartesianInvalidState`` (N,) (0 valid, 1 direction only, 2 no point)."""
    import pye57

    with tempfile.TemporaryDirectory() as tmp:  # pye57 writes paths
        path = Path(tmp) / "site.e57"
        with contextlib.closing(pye57.E57(str(path), mode="w")) as e57:
            for k, (pts, translation) in enumerate(scans):
                data = {"cartesianX": pts[:, 0], "cartesianY": pts[:, 1], "cartesianZ": pts[:, 2]}
                if intensity:
                    data["intensity"] = np.full(len(pts), k + 0.5)
                if invalid is not None and invalid[k] is not None:
                    data["cartesianInvalidState"] = np.asarray(invalid[k], dtype=np.int8)
                e57.write_scan_raw(data, name=f"scan {k}", translation=translation)
        return path.read_bytes()
