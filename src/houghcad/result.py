"""Result dataclasses shared by the pipeline, the writers and the evaluator.

Parameters are always in the input's own coordinates (world frame).
Parameter names per family (all vectors are lists of 3 floats, angles in radians):

- plane: ``normal`` (unit), ``offset`` (``normal · x = offset``), ``point``
- cylinder: ``axis_point``, ``axis`` (unit), ``radius``
- cone: ``apex``, ``axis`` (unit, from the apex into the opening), ``half_angle``
- sphere: ``center``, ``radius``
- torus: ``center``, ``axis`` (unit), ``major_radius``, ``minor_radius``
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Segment:
    """One recognised primitive.

    Attributes
    ----------
    id : int
        Position of the segment in :attr:`Result.segments`.
    type : str
        Lowercase family name (``"plane"``, ``"cylinder"`` ...).
    indices : ndarray of int64, shape (M,)
        0-based indices into the input's point order, sorted.
    params : dict
        Named parameters in world coordinates (see module docstring).
    mfe : float
        Mean fitting error, eq. (1) of the paper: mean distance to the primitive
        divided by the diagonal of the segment's axis-aligned bounding box.
    """

    id: int
    type: str
    indices: np.ndarray
    params: dict[str, Any]
    mfe: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": int(self.id),
            "type": self.type,
            "n_points": int(len(self.indices)),
            "mfe": float(self.mfe),
            "params": _jsonable(self.params),
            "indices": [int(i) for i in self.indices],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Segment":
        return cls(
            id=int(d["id"]),
            type=str(d["type"]),
            indices=np.asarray(d["indices"], dtype=np.int64),
            params=dict(d.get("params", {})),
            mfe=float(d.get("mfe", float("nan"))),
        )


@dataclass
class Result:
    """Decomposition of a point cloud into primitives.

    Attributes
    ----------
    n_points : int
        Number of input points.
    segments : list of Segment
    unsegmented : ndarray of int64
        Indices of the points no primitive explains.
    timing : dict
        Wall-clock seconds per stage.
    options : dict
        The options the run used.
    source : str or None
        Path of the input file, when there was one.
    """

    n_points: int
    segments: list[Segment]
    unsegmented: np.ndarray
    timing: dict[str, float] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)
    source: str | None = None

    def labels(self) -> np.ndarray:
        """Per-point segment id, shape (n_points,), -1 for unsegmented points."""
        lab = np.full(self.n_points, -1, dtype=np.int64)
        for s in self.segments:
            lab[s.indices] = s.id
        return lab

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "houghcad-result",
            "version": 1,
            "source": self.source,
            "n_points": int(self.n_points),
            "segments": [s.to_dict() for s in self.segments],
            "unsegmented": [int(i) for i in self.unsegmented],
            "timing": {k: float(v) for k, v in self.timing.items()},
            "options": _jsonable(self.options),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Result":
        return cls(
            n_points=int(d["n_points"]),
            segments=[Segment.from_dict(s) for s in d["segments"]],
            unsegmented=np.asarray(d.get("unsegmented", []), dtype=np.int64),
            timing=dict(d.get("timing", {})),
            options=dict(d.get("options", {})),
            source=d.get("source"),
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), separators=(",", ":"))


def _jsonable(x: Any) -> Any:
    """Convert numpy scalars and arrays inside nested containers to plain Python."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    return x
