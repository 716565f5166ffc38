"""Point cloud preprocessing (paper §5.1).

Barycentre to the origin, unoriented normals, the most voted normal direction
to the z-axis, scaling into the unit cube. The similarity is kept so that every
parameter can be mapped back to the input's coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError
from .hough import direction_accumulator, refine_direction
from .noise import NOISY_SPACINGS
from .scanrows import ROWS_SHARE, on_rows, spread_quadruples
from .noise import choose as choose_policy
from .normals import ROWS, by_rows, pca_normals, quadric_residuals, tree_query, voting_normals
from .scales import link_scale, off_surface

__all__ = ["ROWS", "Preprocessed", "Similarity", "by_rows", "pca_normals", "preprocess", "quadric_residuals",
           "rotation_to_z", "voting_normals"]

#: The normal estimation methods a run takes ("input": the file's normals, required).
NORMALS_METHODS = ("auto", "pca", "voting", "input")


@dataclass(frozen=True)
class Similarity:
    """``x_std = scale * R @ (x_world - center)``.

    Attributes
    ----------
    center : ndarray, shape (3,)
        Translation, world units.
    R : ndarray, shape (3, 3)
        Rotation (rows are the new axes in world coordinates).
    scale : float
        Uniform scale factor (world → standard units).
    """

    center: np.ndarray
    R: np.ndarray
    scale: float

    def points(self, x: np.ndarray) -> np.ndarray:
        """World points (n, 3) → standard frame."""
        return self.scale * (np.asarray(x, float) - self.center) @ self.R.T

    def dirs(self, v: np.ndarray) -> np.ndarray:
        """World directions (n, 3) → standard frame."""
        return np.asarray(v, float) @ self.R.T

    def inv_points(self, x: np.ndarray) -> np.ndarray:
        """Standard points (…, 3) → world."""
        return np.asarray(x, float) @ self.R / self.scale + self.center

    def inv_dirs(self, v: np.ndarray) -> np.ndarray:
        """Standard directions (…, 3) → world."""
        return np.asarray(v, float) @ self.R

    def inv_length(self, r: float) -> float:
        return float(r) / self.scale


def rotation_to_z(d: np.ndarray, x_hint: np.ndarray | None = None) -> np.ndarray:
    """Rotation matrix whose third row is the unit vector ``d``.

    ``x_hint`` (optional) fixes the first row as its component orthogonal to d,
    so that the frame is deterministic.
    """
    d = np.asarray(d, float) / np.linalg.norm(d)
    cands = [] if x_hint is None else [np.asarray(x_hint, float)]
    cands += [np.eye(3)[int(np.argmin(np.abs(d)))]]
    for x in cands:
        x = x - (x @ d) * d
        if np.linalg.norm(x) > 1e-6:
            break
    x /= np.linalg.norm(x)
    y = np.cross(d, x)
    return np.stack([x, y, d])


#: Quadric residual (spacings) above which a clean cloud's point is on a
#: crease and takes voted normals (``preprocess``, method ``auto``).
CREASE = 0.1


@dataclass
class Preprocessed:
    """A cloud in standard position, ready for recognition.

    Attributes
    ----------
    points : ndarray, shape (n, 3)
        Points in the standard frame (unit cube, barycentre at the origin,
        most voted normal along z).
    normals : ndarray, shape (n, 3)
        Unit unoriented normals in the standard frame.
    transform : Similarity
        World → standard frame.
    tree : cKDTree
        KD-tree on ``points``.
    spacing : float
        Median nearest-neighbour distance (standard units).
    noise : float
        Robust estimate of the noise σ (standard units): median RMS of the
        local PCA residual.
    diagonal : float
        Diagonal of the bounding box (standard units).
    normals_method : str
        ``"pca"``, ``"voting"`` or ``"input"``.
    reach : float
        Median distance to the 6th nearest neighbour (standard units): the
        scale at which the sampling is connected.
    crease : ndarray of bool, shape (n,), or None
        Points of a clean cloud on a crease (no local quadric fits them), whose normals were
        voted: there the normal may be a neighbouring face's. None when no point was voted.
    exact : bool
        The points lie on their surfaces to rounding (a quarter or more of the quadruples of a
        point and its 3 nearest neighbours are coplanar to 0.002 spacings, which noise does not
        give): ``noise`` then reads curvature and thin features, not a scatter of the points.
    link_scale : ndarray of float32, shape (n,), or None
        How much sparser the sampling is around each point than over the cloud (at least 1):
        :func:`houghcad.scales.link_scale`. The dense subsets link two points within the link
        times the smaller of their scales where these reach ``link_scale_from``
        (:meth:`Context.link_scales`). None (not read: :func:`preprocess`'s ``sampling_scales``)
        links every point at the cloud's link.
    off_surface : ndarray of float32, shape (n,), or None
        RMS residual of a local quadric through each point's 16-neighbourhood, over the
        neighbourhood's radius (:func:`houghcad.scales.off_surface`; 0 on a smooth face, 0.1-0.3
        for a point scattered in space). Read with ``link_scale``: two points off every surface
        never link farther than the cloud's link (:meth:`Context.link_scales`).
    """

    points: np.ndarray
    normals: np.ndarray
    transform: Similarity
    tree: cKDTree
    spacing: float
    noise: float
    diagonal: float
    normals_method: str
    reach: float = 0.0
    crease: np.ndarray | None = None
    exact: bool = False
    link_scale: np.ndarray | None = None
    off_surface: np.ndarray | None = None
    #: Neighbour tables read so far, by (k, radius) (see :meth:`neighbours_within`), and point
    #: pairs, by ("pairs", radius) (:meth:`pairs_within`); not carried over by
    #: ``dataclasses.replace``, which may change the points.
    _tables: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def neighbours_within(self, k: int, radius: float, workers: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Each point's ``k`` nearest points within ``radius`` (standard units): their indices
        (n, k) int32 (0 where there are fewer) and whether each is there (n, k) bool.

        Read once per (k, radius) and kept: the passes that ask again (the adjacency of every
        pass, each round of edge settling) read the same points at the same radius. A point's
        row is what a query of that point alone gives."""
        key = (int(k), float(radius))
        if key not in self._tables:
            n = len(self.points)
            dist, nb = tree_query(self.tree, self.points, workers, k=min(int(k), n), distance_upper_bound=radius)
            ok = np.isfinite(dist).reshape(n, -1)
            self._tables[key] = (np.where(ok, nb.reshape(n, -1), 0).astype(np.int32), ok)
        return self._tables[key]

    def pairs_within(self, radius: float) -> np.ndarray:
        """Every pair (i, j), i < j, of points closer than ``radius`` (standard units), (m, 2)
        int32, in the KD-tree's order. Read once per radius and kept: the segment graphs of a
        run (the fillet pass's, the association's) ask for the same pairs over other labels."""
        key = ("pairs", float(radius))
        if key not in self._tables:
            self._tables[key] = self.tree.query_pairs(radius, output_type="ndarray").astype(np.int32)
        return self._tables[key]


#: The 16-neighbour noise estimate (spacings) above which ``noise="auto"``
#: widens the normals' neighbourhood: sharp edges alone push it to ~0.2
#: spacings on clean parts.
WIDE_NORMALS_SPACINGS = 0.3
#: Neighbours of a widened normal per spacing of noise (the 16-neighbour estimate), between
#: the 16 of a clean cloud and 64: a PCA normal's error falls as the neighbourhood grows
#: against σ, so noisier clouds need more neighbours; but more than the noise needs reach
#: across narrow faces (a groove wall or a chamfer three spacings wide) and blend their
#: normals with their neighbours'. The estimate reads 0.44-0.54 spacings at σ = 0.2 % of the
#: diagonal on the synthetic parts (35-43 neighbours) and 0.7-0.85 at 0.5 %, on single
#: primitives at 1 % and on the paper's Table 5 block at every σ (56-64), where it saturates:
#: σ widens the spacing too, so the estimate cannot tell 0.5 % from 3 %; 40 per spacing
#: (half as many) helped the parts more but lost types on single primitives at 0.5-1 % and
#: DSC on the Table 5 block at σ = 0.1 and 0.2.
NOISE_NEIGHBOURS_PER_SPACING = 80
#: The widened neighbourhood's cap (neighbours): at 1 % of the diagonal 64 neighbours give ~5°
#: normal errors where 16 give 25° (synthetic cylinders).
WIDE_NORMALS_MAX = 64
#: Quantile of the 4-point plane residuals that bounds the noise (:func:`_noise_estimate`),
#: and the bound's factor: the quantile is 1 / 16 of σ under Gaussian noise up to 0.3 spacings.
QUADRUPLE_QUANTILE = 0.1
QUADRUPLE_SIGMAS = 16.0
#: On a cloud sampled in rows (:mod:`houghcad.scanrows`), below this share of points with a
#: quadruple across the rows the quadruple tests are left out: the rows lie further apart than
#: the 16 nearest reach, and no quadruple spans the surface.
QUADRUPLE_MIN_SPREAD = 0.05
#: Exact samples: a quarter or more of the 4-point plane residuals under this many spacings
#: (rounding; under noise the 25th percentile is above 0.01 spacings from σ = 0.07 spacings on).
EXACT_QUADRUPLE_SPACINGS = 0.002


def preprocess(points: np.ndarray, normals: np.ndarray | None = None, method: str = "auto",
               k: int = 16, seed: int = 0, noise: str = "auto", workers: int = 1,
               sampling_scales: bool = False) -> Preprocessed:
    """Put a world cloud in standard position and estimate its normals.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        World coordinates.
    normals : ndarray, shape (n, 3), optional
        Given normals (used as they are when ``method`` is ``"auto"`` or ``"input"``).
    method : {"auto", "pca", "voting", "input"}
        Normal estimation. ``auto`` uses the given normals if any, else PCA on
        clean clouds (points on creases, where no local quadric fits, voted
        by planes through the point: :func:`voting_normals` ``anchored``) and
        PCA on up to 64 neighbours when the cloud is noisy
        (``NOISE_NEIGHBOURS_PER_SPACING``). ``pca``: PCA only.
    k : int
        Neighbourhood size.
    seed : int
        Seed of the voting estimate.
    noise : {"auto", "clean", "noisy"}
        The noise policy (:mod:`houghcad.noise`): "noisy" always widens the
        PCA neighbourhood, "clean" never does, "auto" does when the
        16-neighbour noise estimate exceeds :data:`WIDE_NORMALS_SPACINGS`.
    workers : int
        Threads for the neighbour queries and the per-point fits (the result does not depend
        on it).
    sampling_scales : bool
        Also read each point's sampling scale and how far its neighbourhood is from a surface
        (:attr:`Preprocessed.link_scale` and :attr:`Preprocessed.off_surface`, None otherwise):
        only the own link (``scale.link_scale_max`` above 1) uses them.
    """
    noise_policy = noise
    points = np.asarray(points, dtype=np.float64)
    center, scale0, x = _unit_cube(points)
    hood = _neighbourhoods(x, k, workers)
    nrm, dist, noise, used, crease = _choose_normals(x, hood, normals, method, seed, noise_policy, workers)
    # From the neighbourhoods the normals came from (the widened ones on noisy clouds).
    spacing = float(np.median(dist[:, 1]))
    # Connectivity scale: the 6th neighbour's distance is about 1.5 spacings
    # on grid-like sampling but 3 on random (Poisson) sampling.
    reach = float(np.median(dist[:, min(6, dist.shape[1] - 1)]))

    R, x, nrm, s2 = _standard_frame(x, nrm, workers)
    tree = cKDTree(x)
    T = Similarity(center=center, R=R, scale=scale0 * s2)
    diag = float(np.linalg.norm(np.ptp(x, axis=0)))
    return Preprocessed(points=x, normals=nrm, transform=T, tree=tree, spacing=spacing * s2,
                        noise=noise * s2, diagonal=diag, normals_method=used, reach=reach * s2, crease=crease,
                        exact=hood.exact, link_scale=link_scale(hood.dist, hood.nbr) if sampling_scales else None,
                        off_surface=off_surface(hood.dist, hood.qres) if sampling_scales else None)


def _unit_cube(points: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Barycentre to the origin, largest extent to 1.

    Parameters
    ----------
    points : ndarray of float64, shape (n, 3)
        World coordinates.

    Returns
    -------
    center : ndarray, shape (3,)
        The barycentre (world units).
    scale : float
        World → unit-cube factor (1 for a single repeated point).
    x : ndarray, shape (n, 3)
        ``(points - center) * scale``.
    """
    center = points.mean(axis=0)
    x = points - center
    ext = np.ptp(x, axis=0).max()
    scale0 = 1.0 / ext if ext > 0 else 1.0
    x = x * scale0
    return center, scale0, x


@dataclass
class _Neighbourhoods:
    """The k-neighbourhoods of the unit-cube cloud and what they estimate (unit-cube units).

    Attributes
    ----------
    tree : cKDTree
        KD-tree on the points.
    k : int
        Neighbourhood size, at most the number of points.
    dist, nbr : ndarray, shape (n, k)
        Distances and indices of each point's k nearest points, the point itself first.
    normals : ndarray, shape (n, 3)
        Unit PCA normals of the neighbourhoods.
    noise : float
        Noise σ estimate (:func:`_noise_estimate`).
    spacing : float
        Median nearest-neighbour distance.
    qres : ndarray, shape (n,), or None
        Quadric residuals (:func:`quadric_residuals`), computed when k > 8.
    exact : bool
        The samples lie on their surfaces to rounding (:attr:`Preprocessed.exact`).
    """

    tree: cKDTree
    k: int
    dist: np.ndarray
    nbr: np.ndarray
    normals: np.ndarray
    noise: float
    spacing: float
    qres: np.ndarray | None
    exact: bool = False


def _neighbourhoods(x: np.ndarray, k: int, workers: int = 1) -> _Neighbourhoods:
    """k-neighbourhoods of the (n, 3) unit-cube points ``x``, their PCA normals and the noise."""
    tree = cKDTree(x)
    k = int(min(k, len(x)))
    dist, nbr = tree_query(tree, x, workers, k=k)
    nrm, ev = pca_normals(x, nbr, workers)
    spacing = float(np.median(dist[:, 1]))
    noise, qres, exact = _noise_estimate(x, nbr, ev, nrm, k, spacing, workers)
    return _Neighbourhoods(tree=tree, k=k, dist=dist, nbr=nbr, normals=nrm, noise=noise, spacing=spacing,
                           qres=qres, exact=exact)


def _noise_estimate(x: np.ndarray, nbr: np.ndarray, ev: np.ndarray, nrm: np.ndarray, k: int,
                    spacing: float, workers: int = 1) -> tuple[float, np.ndarray | None, bool]:
    """Robust noise σ of a cloud (its units), the quadric residuals (n,) when k > 8 (else None), and
    whether the samples are exact (:attr:`Preprocessed.exact`; tested when k > 4).

    ``nbr`` (n, k) are the neighbourhoods, ``ev`` (n, 3) their covariance eigenvalues (ascending),
    ``nrm`` (n, 3) their PCA normals and ``spacing`` the median nearest-neighbour distance. The
    k-neighbour PCA residual is bounded by smaller-neighbourhood estimates that sharp or thin
    clean features do not inflate.
    """
    noise = float(np.median(np.sqrt(np.maximum(ev[:, 0], 0))))
    qres, exact = None, False
    if k > 8:
        # Thin walls and tight curvature inflate the 16-neighbour residual of
        # clean CAD samples (both faces of a plate in one neighbourhood); the
        # 8-neighbour residual stays small there, while on real noise it is
        # 1.2-1.65 times smaller (measured on synthetic planes, cylinders,
        # spheres), so twice it bounds the noise without hiding it.
        ev8 = pca_normals(x, nbr[:, :8], workers)[1]
        noise = min(noise, 2.0 * float(np.median(np.sqrt(np.maximum(ev8[:, 0], 0)))))
        # Curvature alone (fillets, small tori) inflates the plane residual of
        # clean samples; a local quadric's residual is free of it and, on
        # noise, 1.11-1.17 times smaller than the plane's (synthetic planes,
        # cylinders, spheres, tori at 0.1-1% noise).
        qres = quadric_residuals(x, nbr, workers)
        noise = min(noise, 1.15 * float(np.median(qres)))
    if k > 4:
        # A plate one or two spacings thick, or a sparse random sampling of
        # thin features, puts two surfaces in even 8 neighbours (exact CAD
        # samples read up to 2 spacings of noise so). A point and its 3 nearest
        # neighbours rarely straddle them: on exact samples a quarter or more
        # of these quadruples are coplanar to rounding, which noise does not
        # give (their 25th percentile is above 0.01 spacing from sigma = 0.07
        # spacing on, synthetic planes to tori). There the median quadruple
        # residual, about a third of sigma, bounds the noise.
        quads, spread = nbr[:, :4], np.ones(len(x), dtype=bool)
        if on_rows(x, nbr, nrm).mean() >= ROWS_SHARE:
            quads, spread = spread_quadruples(x, nbr, nrm)
            if spread.mean() < QUADRUPLE_MIN_SPREAD:
                return noise, qres, False  # no quadruple spans the surface: none tells
        r4 = np.sqrt(np.maximum(pca_normals(x, quads[spread], workers)[1][:, 0], 0))
        q_low, q25, q50 = np.quantile(r4, [QUADRUPLE_QUANTILE, 0.25, 0.5])
        exact = bool(q25 < EXACT_QUADRUPLE_SPACINGS * spacing)
        if exact:
            noise = min(noise, 3.0 * float(q50))
        # Whether the cloud is noisy at all: on sparse samples the two faces
        # of a plate thinner than the spacing interleave, and so do the rows
        # of narrow faces, and fewer than a quarter of the quadruples lie on
        # one face. Straddling and curvature only add to a quadruple's
        # residual, so its low quantile bounds the noise: under Gaussian
        # noise the 10th percentile is 0.06 σ up to σ = 0.3 spacings
        # (synthetic planes and parts), less beyond, as the quadruple tilts
        # into the noise. The bound therefore decides only that a cloud the
        # estimates above read as noisy is clean.
        bound = QUADRUPLE_SIGMAS * float(q_low)
        if bound < NOISY_SPACINGS * spacing <= noise:
            noise = bound
    return noise, qres, exact


def _choose_normals(x: np.ndarray, hood: _Neighbourhoods, normals: np.ndarray | None, method: str, seed: int,
                    noise_policy: str, workers: int = 1) \
        -> tuple[np.ndarray, np.ndarray, float, str, np.ndarray | None]:
    """The normals :func:`preprocess` keeps (see its ``method`` and ``noise``).

    Parameters
    ----------
    x : ndarray, shape (n, 3)
        Unit-cube points.
    hood : _Neighbourhoods
        Their k-neighbourhoods.
    normals : ndarray, shape (n, 3), or None
        Given normals (world directions: rotations come later, the unit-cube scaling keeps them).

    Returns
    -------
    normals : ndarray, shape (n, 3), unit
    dist : ndarray, shape (n, k) or (n, kk), kk ≤ WIDE_NORMALS_MAX
        Neighbour distances of the neighbourhoods used (widened ones for noisy clouds).
    noise : float
        Noise estimate, re-estimated on widened neighbourhoods.
    method : str
        ``"input"``, ``"pca"``, ``"pca-k64"`` (``"pca-k<n>"``) or ``"voting"``.
    crease : ndarray of bool, shape (n,), or None
        The crease points whose normals were voted (``auto`` on clean clouds).
    """
    if normals is not None and method in ("auto", "input"):
        nrm = np.asarray(normals, float)
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        return nrm, hood.dist, hood.noise, "input", None
    if method == "input":
        raise InputError("normals method 'input' needs normals in the input")
    if method not in NORMALS_METHODS:
        raise InputError(f"unknown normals method {method!r} ({', '.join(NORMALS_METHODS)})")
    nrm, nbr, dist, noise, used = hood.normals, hood.nbr, hood.dist, hood.noise, "pca"
    widen = noise_policy == "noisy" or (noise_policy == "auto" and noise > WIDE_NORMALS_SPACINGS * hood.spacing)
    if method != "pca" and widen and len(x) > hood.k:
        # Noisy cloud: a wider neighbourhood averages the noise out, and the noise estimate
        # improves too; as wide as the noise needs, no wider (NOISE_NEIGHBOURS_PER_SPACING,
        # WIDE_NORMALS_MAX).
        want = round(NOISE_NEIGHBOURS_PER_SPACING * noise / hood.spacing)
        kk = int(min(np.clip(want, hood.k, WIDE_NORMALS_MAX), len(x)))
        dist, nbr = tree_query(hood.tree, x, workers, k=kk)
        nrm, ev = pca_normals(x, nbr, workers)
        # Bounded by the small-neighbourhood estimate: 64 neighbours reach
        # across the edges of thin walls and small features, whose geometry
        # then reads as noise (up to 4 times σ on parts of many small faces),
        # while on noise alone the 16-neighbour estimate reads 0.6-1.0 σ
        # (sparse single primitives at 1 % noise to synthetic parts): 1.6
        # times it leaves the wide estimate alone there.
        noise = min(float(np.median(np.sqrt(np.maximum(ev[:, 0], 0)))), 1.6 * noise)
        used = f"pca-k{kk}"
    if method == "voting":
        nrm = voting_normals(x, nbr, seed=seed, workers=workers)
        used = "voting"
    elif method == "auto" and used == "pca" and hood.qres is not None and \
            not choose_policy(noise_policy, noise, hood.spacing).noisy:
        # Clean cloud: PCA averages the two sides of a crease, and on a
        # face two or three spacings wide (a groove wall, a chamfer) its
        # neighbourhoods are mostly the neighbours' points. No local
        # quadric explains a crease, while curvature alone it does. On a
        # cloud the noise policy reads as noisy, noise keeps every
        # neighbourhood off its quadric: all its points would read as
        # crease points, and triples of noisy points vote worse normals
        # than PCA does.
        on_crease = hood.qres > CREASE * hood.spacing
        crease = np.flatnonzero(on_crease)
        if len(crease):
            nrm[crease] = voting_normals(x, nbr[crease], seed=seed, anchored=True, workers=workers)
            return nrm, dist, noise, used, on_crease
    return nrm, dist, noise, used, None


def _standard_frame(x: np.ndarray, nrm: np.ndarray, workers: int = 1) \
        -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Most voted normal direction to z (the second one fixes x), then back into the unit cube.

    Parameters
    ----------
    x, nrm : ndarray, shape (n, 3)
        Unit-cube points and their unit normals.

    Returns
    -------
    R : ndarray, shape (3, 3)
        The rotation (rows: new axes).
    x, nrm : ndarray, shape (n, 3)
        Rotated and rescaled points, rotated normals.
    scale : float
        The rescaling factor (the rotation changes the extents).
    """
    acc = direction_accumulator()
    H = acc.smooth(acc.vote(nrm, workers=workers))
    dirs, _ = acc.peaks(H, min_persistence=0.05, max_peaks=2)
    d = refine_direction(dirs[0], nrm, np.radians(5.0))
    hint = None
    if len(dirs) > 1:
        hint = refine_direction(dirs[1], nrm, np.radians(5.0))
    R = rotation_to_z(d, hint)
    x = x @ R.T
    nrm = nrm @ R.T
    ext2 = np.ptp(x, axis=0).max()
    s2 = 1.0 / ext2 if ext2 > 0 else 1.0
    x *= s2
    return R, x, nrm, s2

