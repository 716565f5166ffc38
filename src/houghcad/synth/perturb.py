"""Perturbations of a synthetic cloud: what scans do to a surface (the SHREC 2022 primitive-fitting
track's kinds, and uniform outliers beyond it).

A :class:`Perturbation` is applied to a clean :class:`~houghcad.synth.SynthCloud` by
:func:`perturb`, which returns a new cloud (the input is not modified) with the ground truth kept in
step: removed points leave with their labels, outliers are added with label -1. The stages run in
the order a scanner would produce them: the surface is deformed (bumps), then sampled (uneven
density, scan rows, undersampling, holes), then measured (noise), then polluted (outliers).

Every stage draws from its own child stream of ``seed``, so switching one stage on does not move
what the others do.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, fields, replace

import numpy as np

from .primitives import SynthCloud, _bbox_diag, _check_fraction

Array = np.ndarray


@dataclass(frozen=True)
class Perturbation:
    """What to do to a clean cloud. Lengths are fractions of the clean cloud's bounding-box diagonal.

    Attributes
    ----------
    gaussian : float
        σ of isotropic Gaussian noise per coordinate (SHREC's "Gaussian noise").
    uniform : float
        Half-width of uniform noise per coordinate, in [-a, a] (SHREC's "uniform noise"; its σ is
        a / √3).
    n_points : int or None
        Undersampling: keep this many points, drawn at random (after ``uneven``).
    uneven : float
        Uneven density: a point is kept with a probability that falls linearly from 1 to
        ``1 - uneven`` along a random direction across the cloud (0 keeps all; 0.9 leaves one
        end ten times sparser than the other).
    missing : float in [0, 1)
        Fraction of the surface cut away as ``holes`` holes: the points nearest (in 3-D) to
        ``holes`` random surface points, the same radius around each.
    holes : int
        Number of holes ``missing`` is cut into.
    bumps : float
        Height of smooth local deformations: ``n_bumps`` Gaussian bumps along the true normals,
        of width ``bump_width``, centred on random surface points.
    n_bumps : int
    bump_width : float
        σ of each bump's Gaussian profile (fraction of the diagonal). The default keeps the bumps
        local: within 2σ of their centres, three of them cover an eighth of a square patch.
    outliers : float in [0, 1)
        Fraction of the final cloud made of uniform points in the bounding box grown by 10 % of
        the diagonal on every side (label -1).
    rows : float
        Scan rows (beyond SHREC): only the points within bands ``row_band`` × the gap wide are
        kept, the bands ``rows`` point spacings apart (the clean cloud's median nearest-neighbour
        distance, not the diagonal) across a random direction: a scanner's rows. Along a row the
        kept points are about ``1 / (row_band · rows)`` spacings apart, so a clean cloud sampled
        densely (10 times the points at the defaults below) gives rows closer along them than
        they are apart.
    row_band : float in (0, 1]
    normal_noise : float
        σ of Gaussian noise along each point's true normal (a range scanner's noise at normal
        incidence), fraction of the diagonal; unlike isotropic noise it leaves the rows rows.
    """

    gaussian: float = 0.0
    uniform: float = 0.0
    n_points: int | None = None
    uneven: float = 0.0
    missing: float = 0.0
    holes: int = 3
    bumps: float = 0.0
    n_bumps: int = 3
    bump_width: float = 0.04
    outliers: float = 0.0
    rows: float = 0.0
    row_band: float = 0.1
    normal_noise: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 < self.row_band <= 1.0:
            raise ValueError(f"row_band must be in (0, 1], got {self.row_band!r}")
        for name in ("gaussian", "uniform", "bumps", "bump_width", "rows", "normal_noise"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        _check_fraction("missing", self.missing)
        _check_fraction("outliers", self.outliers)
        _check_fraction("uneven", self.uneven)
        if self.n_points is not None and self.n_points < 1:
            raise ValueError(f"n_points must be >= 1, got {self.n_points!r}")
        if self.holes < 1 or self.n_bumps < 1:
            raise ValueError("holes and n_bumps must be >= 1")

    def describe(self) -> str:
        """The fields that differ from the clean default, e.g. ``"gaussian=0.005, missing=0.3"``."""
        clean = Perturbation()
        return ", ".join(f"{f.name}={getattr(self, f.name):g}" for f in fields(self)
                         if getattr(self, f.name) != getattr(clean, f.name)) or "clean"


def _streams(seed: int) -> list[np.random.Generator]:
    # A new stage takes a new child: the first ones, and what the older stages do, stay as they were.
    kids = np.random.SeedSequence([int(seed), zlib.crc32(b"perturb")]).spawn(7)
    return [np.random.default_rng(k) for k in kids]


def _bump(points: Array, normals: Array, height: float, width: float, n: int,
          rng: np.random.Generator) -> Array:
    """``points`` moved along ``normals`` by a sum of ``n`` Gaussian bumps (heights and widths in
    world units) centred on random points of the cloud."""
    centres = points[rng.choice(len(points), size=min(n, len(points)), replace=False)]
    d2 = ((points[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)  # (N, n): n is a handful
    lift = height * np.exp(-d2 / (2.0 * width * width)).sum(axis=1)
    return points + lift[:, None] * normals


def _holes(points: Array, fraction: float, n_holes: int, rng: np.random.Generator) -> Array:
    """Boolean keep-mask (N,) without the ``round(fraction · N)`` points nearest to ``n_holes``
    random surface points: holes of one radius around each centre."""
    n_cut = int(round(fraction * len(points)))
    centres = points[rng.choice(len(points), size=min(n_holes, len(points)), replace=False)]
    d = np.min(np.linalg.norm(points[:, None, :] - centres[None, :, :], axis=2), axis=1)
    keep = np.ones(len(points), bool)
    keep[np.argsort(d, kind="stable")[:n_cut]] = False
    return keep


def _rows(points: Array, gap: float, band: float, rng: np.random.Generator) -> Array:
    """Boolean keep-mask (N,) of the points within ``band`` × the gap of parallel planes ``gap``
    point spacings apart, across a direction (and at a phase) drawn from ``rng``."""
    from scipy.spatial import cKDTree

    spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1]))
    d = rng.standard_normal(3)
    t = points @ (d / np.linalg.norm(d)) / (gap * spacing) + rng.random()
    return np.abs(t - np.round(t)) <= band / 2.0


def uneven_keep(points: Array, uneven: float, rng: np.random.Generator) -> Array:
    """Which of the points (n, 3) an uneven sampling keeps, bool (n,): each with a probability
    falling linearly from 1 to ``1 - uneven`` along a direction drawn from ``rng`` across the
    points (0.9: one end ten times sparser than the other)."""
    d = rng.standard_normal(3)
    t = points @ (d / np.linalg.norm(d))
    t = (t - t.min()) / max(float(np.ptp(t)), 1e-300)
    return rng.random(len(points)) < 1.0 - uneven * t


def perturb(cloud: SynthCloud, p: Perturbation, seed: int = 0) -> SynthCloud:
    """A copy of ``cloud`` perturbed by ``p`` (see :class:`Perturbation`), seeded by ``seed``.

    The primitives (ground truth parameters) are the clean surface's; points removed take their
    labels along; outliers get label -1 and normal 0; the result is shuffled. ``sigma`` is the
    clean cloud's plus the standard deviation of the added noise (world units), combined in
    quadrature.
    """
    if len(cloud.points) == 0:
        raise ValueError("cannot perturb an empty cloud")
    g_bump, g_sample, g_holes, g_noise, g_out, g_perm, g_rows = _streams(seed)
    diag = _bbox_diag(cloud.points)
    pts = np.array(cloud.points, dtype=np.float64, copy=True)
    nrm = np.array(cloud.normals, dtype=np.float64, copy=True)
    lab = np.array(cloud.labels, dtype=np.int64, copy=True)
    if p.bumps > 0:
        on = lab >= 0
        pts[on] = _bump(pts[on], nrm[on], p.bumps * diag, p.bump_width * diag, p.n_bumps, g_bump)
    keep = np.ones(len(pts), bool)
    if p.uneven > 0:
        keep &= uneven_keep(pts, p.uneven, g_sample)
    if p.rows > 0:
        keep &= _rows(pts, p.rows, p.row_band, g_rows)
    if p.missing > 0:
        keep &= _holes(pts, p.missing, p.holes, g_holes)
    idx = np.flatnonzero(keep)
    if p.n_points is not None and p.n_points < len(idx):
        idx = np.sort(g_sample.choice(idx, size=p.n_points, replace=False))
    pts, nrm, lab = pts[idx], nrm[idx], lab[idx]
    var = 0.0
    if p.gaussian > 0:
        pts += g_noise.normal(0.0, p.gaussian * diag, pts.shape)
        var += (p.gaussian * diag) ** 2
    if p.uniform > 0:
        a = p.uniform * diag
        pts += g_noise.uniform(-a, a, pts.shape)
        var += a * a / 3.0
    if p.normal_noise > 0:
        pts += g_noise.normal(0.0, p.normal_noise * diag, (len(pts), 1)) * nrm
        var += (p.normal_noise * diag) ** 2
    if p.outliers > 0:
        n_out = int(round(p.outliers / (1.0 - p.outliers) * len(pts)))
        lo = pts.min(axis=0) - 0.1 * diag
        hi = pts.max(axis=0) + 0.1 * diag
        pts = np.vstack([pts, lo + (hi - lo) * g_out.random((n_out, 3))])
        nrm = np.vstack([nrm, np.zeros((n_out, 3))])
        lab = np.concatenate([lab, np.full(n_out, -1, np.int64)])
    perm = g_perm.permutation(len(pts))
    return replace(cloud, points=np.ascontiguousarray(pts[perm]), normals=np.ascontiguousarray(nrm[perm]),
                   labels=lab[perm], primitives=[dict(q) for q in cloud.primitives],
                   name=f"{cloud.name} [{p.describe()}]", sigma=float(np.hypot(cloud.sigma, np.sqrt(var))))
