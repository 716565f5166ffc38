"""Reading point clouds and writing results.

:mod:`.readers` detects the format and validates; one module per family of formats parses
(:mod:`.ply`, :mod:`.text`, :mod:`.mesh`, :mod:`.npy`, helpers in :mod:`.common`);
:mod:`.writers` writes.
"""

from __future__ import annotations

from .readers import MIN_POINTS, PointCloud, clean_normals, read_points, validate_points
from .writers import atomic_write, write_fit4cad_primitives, write_json, write_points_ply

__all__ = [
    "MIN_POINTS",
    "PointCloud",
    "read_points",
    "validate_points",
    "clean_normals",
    "atomic_write",
    "write_json",
    "write_fit4cad_primitives",
    "write_points_ply",
]
