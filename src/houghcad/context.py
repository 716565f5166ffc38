"""The shared data of one run: the preprocessed cloud and its derived scales."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .preprocess import Preprocessed


@dataclass
class Context:
    """Thresholds and data shared by a run (standard-frame units).

    Attributes
    ----------
    pre : Preprocessed
    tau : float
        Inlier distance for candidate evaluation.
    epsilon : float
        Removal distance around accepted primitives (paper: 1–3% of the diagonal).
    angle : float
        Normal compatibility tolerance (radians).
    link : float
        Neighbour distance that makes a subset connected (dense).
    cell : float
        Accumulator resolution for lengths.
    min_points : int
        Smallest segment.
    persistence : float
        Peak persistence threshold, fraction of max H.
    """

    pre: Preprocessed
    tau: float
    epsilon: float
    angle: float
    link: float
    cell: float
    min_points: int
    persistence: float = 0.1
    max_peaks: int = 24
    max_directions: int = 12
    max_radius: float = 2.0
    min_votes: float = 10.0
    seed: int = 0
    local: bool = False
    neighbors: np.ndarray | None = None

    @property
    def spacing(self) -> float:
        return self.pre.spacing

    @property
    def noisy(self) -> bool:
        """Noise of at least 0.15 spacings: the points scatter about their
        surface instead of lying on it (the 188 Fit4CAD training samples
        read at most 0.09, 99 % of them under 0.04)."""
        return self.pre.noise >= 0.15 * self.pre.spacing

    @property
    def cos_angle(self) -> float:
        return float(np.cos(self.angle))
