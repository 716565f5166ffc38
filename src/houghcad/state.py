"""The records of a segmentation: candidates and the mean fitting error."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .families import Family, Primitive


@dataclass
class Candidate:
    """A primitive with a dense subset X_i of the points it explains.

    ``indices`` index the whole cloud; ``mfe`` follows eq. (1) in the
    standard frame.
    """

    family: Family
    prim: Primitive
    indices: np.ndarray
    mfe: float
    extra: dict = field(default_factory=dict)

def mean_fitting_error(dist: np.ndarray, P: np.ndarray) -> float:
    """Eq. (1): mean distance / diagonal of the axis-aligned bounding box of P (n, 3)."""
    diag = float(np.linalg.norm(np.ptp(P, axis=0)))
    return float(dist.mean() / diag) if diag > 0 else float("inf")


def owners(segments: list[Candidate], n: int) -> np.ndarray:
    """Index (n,) of the segment that holds each of n points, -1 for none."""
    owner = np.full(n, -1, dtype=np.int64)
    for j, s in enumerate(segments):
        owner[s.indices] = j
    return owner
