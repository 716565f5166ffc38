"""The shared data of one run: the preprocessed cloud and its derived scales."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .noise import CLEAN, NoisePolicy
from .preprocess import Preprocessed
from .tolerances import ScaleTolerances, Tolerances
from .normals import tree_query

#: Guards divisions by a zero spacing (standard units).
_TINY = 1e-12
#: Neighbours within the reach (the median distance to the 6th nearest point, :class:`Preprocessed`).
REACH_NEIGHBOURS = 6
#: Rows per chunk of :func:`part_diagonal`'s neighbour query.
_PIECE_ROWS = 1 << 18
#: Peak persistence threshold, a fraction of the accumulator's maximum.
DEFAULT_PERSISTENCE = 0.1
_SCALE = ScaleTolerances()


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
    tol : Tolerances
        Every named threshold of the run.
    policy : NoisePolicy
        What the run does differently on a noisy cloud.
    local : bool
        Voting on a cluster (the splitting phase), not the whole cloud.
    neighbors : ndarray (m, k) or None
        A neighbour table for the axis votes, given (see :func:`neighbour_table`).
    voting : ndarray (m,) or None
        The points (global indices) of the vote under way, whose neighbour table among
        themselves the axis votes read (:func:`neighbour_table`); None outside a vote.
    workers : Workers or None
        The run's forked workers (:class:`houghcad.parallel.Workers`), None outside a run.
    """

    pre: Preprocessed
    tau: float
    epsilon: float
    angle: float
    link: float
    cell: float
    min_points: int
    persistence: float = DEFAULT_PERSISTENCE
    max_peaks: int = _SCALE.max_peaks
    max_directions: int = _SCALE.max_directions
    max_radius: float = _SCALE.max_radius
    min_votes: float = _SCALE.min_points_floor
    seed: int = 0
    local: bool = False
    neighbors: np.ndarray | None = None
    voting: np.ndarray | None = None
    tol: Tolerances = field(default_factory=Tolerances)
    policy: NoisePolicy = CLEAN
    workers: Any = None

    @property
    def spacing(self) -> float:
        return self.pre.spacing

    @property
    def noisy(self) -> bool:
        """Whether the run follows the noisy policy (see :mod:`houghcad.noise`)."""
        return self.policy.noisy

    @property
    def cos_angle(self) -> float:
        return float(np.cos(self.angle))

    def link_scales(self, idx: np.ndarray) -> np.ndarray | None:
        """The link scales (float32) of the points ``idx``: :attr:`Preprocessed.link_scale` where
        it reaches ``link_scale_from``, capped at ``link_scale_max``, else 1; None when every point
        links at :attr:`link` (as under the noisy policy's ``one_link``). The scale of a point whose
        neighbourhood no surface explains (``link_off_surface_max``: a scattered outlier, or a
        point beside a crease) is negative: :func:`houghcad.clusters.dbscan` links two such
        points at the cloud's link only."""
        t = self.tol.scale
        if self.pre.link_scale is None or self.policy.one_link or t.link_scale_max <= 1.0:
            return None
        s = self.pre.link_scale[idx]
        far = s >= t.link_scale_from
        if not far.any():
            return None
        s = np.minimum(np.where(far, s, np.float32(1.0)), np.float32(t.link_scale_max))
        if self.pre.off_surface is not None:
            s = np.where(far & (self.pre.off_surface[idx] > t.link_off_surface_max), -s, s)
        return s


def threads(ctx: Context) -> int:
    """Threads for a KD-tree query or per-point fit over a whole cloud: the run's jobs (1 inside a
    forked worker, and when a batch runs one job per cloud beside others). Results do not depend
    on it."""
    return max(int(getattr(ctx.workers, "n_jobs", 1)), 1)


#: The last table :func:`neighbour_table` built: [points, voting points' bytes, k, table].
_TABLE: list = []


def neighbour_table(ctx: Context) -> np.ndarray | None:
    """The neighbour table (m, k) of the vote's points ``ctx.voting`` among themselves (positions
    in it), which the axis votes read (:func:`houghcad.families.cylinder.axis_candidates`):
    ``ctx.neighbors`` when given; None outside a vote.

    Built on first read, not with the vote's context: of the families only the cylinders'
    placements read it, and a forked worker that only evaluates peaks never needs it. The last
    table is kept for the next read on the same points (a worker's next task on them)."""
    if ctx.neighbors is not None or ctx.voting is None:
        return ctx.neighbors
    idx = ctx.voting
    k = min(ctx.tol.recognition.neighbours, len(idx))
    key = idx.tobytes()
    if _TABLE and _TABLE[0] is ctx.pre.points and _TABLE[2] == k and _TABLE[1] == key:
        return _TABLE[3]
    P = ctx.pre.points[idx]
    table = tree_query(cKDTree(P), P, threads(ctx), k=k)[1]
    _TABLE[:] = [ctx.pre.points, key, k, table]
    return table


def points_in_patch(pre: Preprocessed, width: float) -> float:
    """About how many of the cloud's points a patch of surface ``width`` across holds (standard
    units): at the median density, where a point has 6 neighbours within ``pre.reach``."""
    return REACH_NEIGHBOURS / (np.pi * max(pre.reach, _TINY) ** 2) * width ** 2


def part_diagonal(pre: Preprocessed, link: float) -> float:
    """Bounding-box diagonal (standard units) of the cloud's largest connected piece: its points
    linked to their ``REACH_NEIGHBOURS`` nearest within ``link``.

    The smallest face is sized on the part, and the cloud's own box can span empty space: one
    stray point a hundred diagonals off made the smallest face larger than the whole part (and
    nothing was segmented), and so did a second part placed far away.
    """
    n = len(pre.points)
    k = min(REACH_NEIGHBOURS + 1, n)
    rows, cols = [], []
    for a in range(0, n, _PIECE_ROWS):  # in chunks: an (n, k) table of a full-resolution scan is GBs
        dist, nbr = pre.tree.query(pre.points[a:a + _PIECE_ROWS], k=k, distance_upper_bound=link)
        r, c = np.nonzero(np.isfinite(dist))
        rows.append((a + r).astype(np.int32))
        cols.append(nbr[r, c].astype(np.int32))
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(n, n))
    _, piece = connected_components(graph, directed=False)
    largest = piece == np.argmax(np.bincount(piece))
    return float(np.linalg.norm(np.ptp(pre.points[largest], axis=0)))


def derive_context(pre: Preprocessed, n_points: int, tol: Tolerances, policy: NoisePolicy,
                   epsilon: float | None = None, min_points: int | None = None,
                   persistence: float = DEFAULT_PERSISTENCE,
                   seed: int = 0) -> Context:
    """The run's scales from the point spacing and the estimated noise.

    ``epsilon``: the removal distance as a fraction of the diagonal (None:
    ``tol.scale.epsilon_taus`` × τ, or ``noisy_epsilon_taus`` × τ under the
    noisy policy); ``min_points``: the smallest segment
    (None: a patch ``tol.scale.min_face_diagonals`` wide at the cloud's density,
    see :func:`points_in_patch`).
    """
    t = tol.scale
    s = pre.spacing
    tau = max(t.tau_spacings * s, t.tau_sigmas * pre.noise)
    eps_taus = t.noisy_epsilon_taus if policy.wide_removal else t.epsilon_taus
    eps = eps_taus * tau if epsilon is None else float(epsilon) * pre.diagonal
    tau = min(tau, eps)
    angle = np.radians(min(t.angle_max_deg, t.angle_deg + t.angle_deg_per_noise * pre.noise / max(s, _TINY)))
    floor = t.noisy_min_points_floor if policy.larger_segments else t.min_points_floor
    link = max(t.link_spacings * s, t.link_reach * pre.reach) + t.link_sigmas * pre.noise
    mp = min_points
    if mp is None:
        mp = max(floor, int(points_in_patch(pre, t.min_face_diagonals * pre.diagonal)))
        if mp > floor:  # only then can the part's own width matter (never on clouds under ~50k points)
            mp = max(floor, int(points_in_patch(pre, t.min_face_diagonals * part_diagonal(pre, link))))
    return Context(pre=pre, tau=tau, epsilon=eps, angle=float(angle), link=link,
                   cell=max(tau, t.cell_spacings * s), min_points=int(mp), max_radius=t.max_radius,
                   persistence=float(persistence), max_peaks=t.max_peaks, max_directions=t.max_directions,
                   min_votes=float(mp), seed=int(seed), tol=tol, policy=policy)


def on_surface(ctx: Context) -> float:
    """Distance to a surface that counts as on it (standard units)."""
    return max(ctx.tol.scale.on_surface_spacings * ctx.spacing, ctx.tau)
